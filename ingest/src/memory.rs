//! How much memory this machine has, for refusing work that cannot fit before allocating it.

/// Physical memory of this machine in bytes, or `None` where the system does not say.
pub fn physical_memory() -> Option<u64> {
    // SAFETY: `sysconf` only reads system configuration values.
    let (pages, page_size) = unsafe {
        (
            libc::sysconf(libc::_SC_PHYS_PAGES),
            libc::sysconf(libc::_SC_PAGESIZE),
        )
    };
    (pages > 0 && page_size > 0).then(|| (pages as u64).saturating_mul(page_size as u64))
}

#[cfg(test)]
mod tests {
    use super::*;

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
