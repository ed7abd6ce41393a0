//! How much memory this machine has, for refusing work that cannot fit before allocating it,
//! and large buffers filled in huge pages ([`filled`]).

/// Physical memory of this machine in bytes, or `None` where the system does not say.
pub fn physical_memory() -> Option<u64> {
    // SAFETY: `sysconf` only reads a system configuration value.
    let pages = unsafe { libc::sysconf(libc::_SC_PHYS_PAGES) };
    let page_size = page_size()?;
    (pages > 0).then(|| (pages as u64).saturating_mul(page_size))
}

/// The size of a memory page in bytes, or `None` where the system does not say.
pub fn page_size() -> Option<u64> {
    // SAFETY: `sysconf` only reads a system configuration value.
    let size = unsafe { libc::sysconf(libc::_SC_PAGESIZE) };
    u64::try_from(size).ok().filter(|&s| s > 0)
}

/// Buffers at least this large are asked to live in huge pages.
const HUGE_BUFFER: usize = 8 << 20;

/// Makes `v` hold `len` copies of `value`, reusing its memory. A buffer that grows to at least
/// 8 MiB asks the kernel for transparent huge pages before its first write (Linux,
/// `MADV_HUGEPAGE`): one fault per 2 MiB instead of one per 4 KiB, which for the slabs and
/// the pyramid's sums was a fifth of `ingest`'s time.
pub fn filled<T: Clone>(v: &mut Vec<T>, len: usize, value: T) {
    v.clear();
    if v.capacity() < len {
        *v = Vec::with_capacity(len);
        if len * size_of::<T>() >= HUGE_BUFFER {
            advise_huge_pages(v.spare_capacity_mut());
        }
    }
    v.resize(len, value);
}

/// Makes `v` hold `len` values whose contents the caller is about to overwrite: unchanged
/// when it already holds that many, else [`filled`] with defaults.
pub fn sized<T: Clone + Default>(v: &mut Vec<T>, len: usize) {
    if v.len() != len {
        filled(v, len, T::default());
    }
}

/// Advises the kernel to back the whole 2 MiB pages inside `memory` with huge pages; a
/// refusal (no transparent huge pages) changes nothing but speed.
fn advise_huge_pages<T>(memory: &mut [std::mem::MaybeUninit<T>]) {
    #[cfg(target_os = "linux")]
    {
        const HUGE_PAGE: usize = 2 << 20;
        let start = memory.as_mut_ptr() as usize;
        let end = start + size_of_val(memory);
        let (first, last) = (
            start.next_multiple_of(HUGE_PAGE),
            end / HUGE_PAGE * HUGE_PAGE,
        );
        if first < last {
            // SAFETY: the range lies inside `memory`, which this process owns; the advice
            // changes how the kernel backs it, never its contents.
            unsafe {
                libc::madvise(
                    first as *mut libc::c_void,
                    last - first,
                    libc::MADV_HUGEPAGE,
                )
            };
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = memory;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn filled_holds_the_value_and_reuses_memory() {
        let mut v = vec![7u64; 3];
        filled(&mut v, 2 << 20, 0);
        assert_eq!((v.len(), v.iter().all(|&x| x == 0)), (2 << 20, true));
        let at = v.as_ptr();
        filled(&mut v, 1 << 20, 5);
        assert_eq!(
            (v.len(), v.iter().all(|&x| x == 5), v.as_ptr()),
            (1 << 20, true, at)
        );
    }

    #[test]
    fn physical_memory_is_known_and_plausible() {
        let bytes = physical_memory().expect("sysconf gives the physical memory");
        // More than 64 MiB and less than 64 TiB.
        assert!(bytes > 64 << 20 && bytes < 64 << 40, "{bytes}");
        let meminfo = std::fs::read_to_string("/proc/meminfo").unwrap();
        let kib: u64 = meminfo
            .lines()
            .find_map(|l| l.strip_prefix("MemTotal:"))
            .and_then(|v| v.trim().strip_suffix("kB"))
            .and_then(|v| v.trim().parse().ok())
            .unwrap();
        // The kernel reserves a little memory before MemTotal counts it.
        assert!(
            kib * 1024 <= bytes && bytes - kib * 1024 < bytes / 10,
            "{kib} kiB vs {bytes}"
        );
    }
}
