//! What the page cache holds of a chunk file, and reading a chunk into it. A serving thread
//! sends a chunk with `sendfile` only when the page cache holds all of it, so that it never
//! waits for the disk while other connections wait for it; a chunk it does not hold is first
//! read into the cache on a blocking thread ([`fill`]), through a small buffer on that thread's
//! stack: nothing is allocated for it, so the blocking threads that come and go with the disk's
//! reads leave no memory behind.

use std::fs::File;
use std::io;
use std::os::fd::AsRawFd;
use std::os::unix::fs::FileExt;

/// The `cachestat` system call's number (the same on every architecture; Linux 6.5).
const SYS_CACHESTAT: libc::c_long = 451;

/// The bytes [`fill`] reads at a time, into a buffer on the blocking thread's stack (the
/// kernel was asked for the whole range first, so small reads cost no extra trips to the
/// disk).
const FILL_PIECE: usize = 16 << 10;

/// `struct cachestat_range`: the bytes asked about.
#[repr(C)]
struct CachestatRange {
    off: u64,
    len: u64,
}

/// `struct cachestat`: what the page cache holds of them (the kernel's field names).
#[repr(C)]
#[derive(Default)]
#[allow(clippy::struct_field_names)]
struct Cachestat {
    nr_cache: u64,
    nr_dirty: u64,
    nr_writeback: u64,
    nr_evicted: u64,
    nr_recently_evicted: u64,
}

/// The system's page size, the unit `cachestat` counts in (read once).
fn page_size() -> u64 {
    static PAGE: std::sync::OnceLock<u64> = std::sync::OnceLock::new();
    // SAFETY: `sysconf` only reads a system constant.
    *PAGE
        .get_or_init(|| u64::try_from(unsafe { libc::sysconf(libc::_SC_PAGESIZE) }).unwrap_or(4096))
}

/// Whether bytes `start..end` of `file` are all in the page cache (`cachestat`, one system
/// call), so that sending them cannot wait for the disk. Kernels without `cachestat` (before
/// 6.5) say yes: the file is sent as nginx sends it, reading the disk if it must.
pub(crate) fn holds(file: &File, start: u64, end: u64) -> bool {
    if end <= start {
        return true;
    }
    let page = page_size();
    let range = CachestatRange {
        off: start / page * page,
        len: end.div_ceil(page) * page - start / page * page,
    };
    let mut stat = Cachestat::default();
    // SAFETY: an open descriptor, and pointers to structs of the layout the kernel reads
    // and writes.
    let done = unsafe {
        libc::syscall(
            SYS_CACHESTAT,
            file.as_raw_fd(),
            &raw const range,
            &raw mut stat,
            0,
        )
    };
    done != 0 || stat.nr_cache >= range.len / page
}

/// Reads bytes `start..end` of `file` into the page cache, waiting for the disk: meant for a
/// blocking thread. The whole range is asked of the disk at once (`POSIX_FADV_WILLNEED`);
/// then the bytes pass through a small buffer on the stack and are dropped.
///
/// # Errors
/// The read's error, or `UnexpectedEof` when the file is shorter than `end`.
pub(crate) fn fill(file: &File, start: u64, end: u64) -> io::Result<()> {
    if let (Ok(offset), Ok(len)) = (
        libc::off_t::try_from(start),
        libc::off_t::try_from(end.saturating_sub(start)),
    ) {
        // SAFETY: an open descriptor; only advice, whose failure changes nothing read.
        unsafe { libc::posix_fadvise(file.as_raw_fd(), offset, len, libc::POSIX_FADV_WILLNEED) };
    }
    let mut piece = [0u8; FILL_PIECE];
    let mut at = start;
    while at < end {
        let want = usize::try_from(end - at).map_or(FILL_PIECE, |rest| rest.min(FILL_PIECE));
        match file.read_at(&mut piece[..want], at) {
            Ok(0) => {
                return Err(io::Error::new(
                    io::ErrorKind::UnexpectedEof,
                    "the file is shorter than when it was opened",
                ));
            }
            Ok(n) => at += n as u64,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

#[cfg(test)]
pub(crate) mod tests {
    use std::io::Write;

    use super::*;

    /// Drops `file`'s pages from the page cache.
    pub(crate) fn drop_pages(file: &File) {
        // SAFETY: an open descriptor.
        let dropped =
            unsafe { libc::posix_fadvise(file.as_raw_fd(), 0, 0, libc::POSIX_FADV_DONTNEED) };
        assert_eq!(dropped, 0);
    }

    #[test]
    fn pages_dropped_from_the_cache_are_seen_as_not_cached_until_filled() {
        // Beside the sources, not in a /tmp that may be memory (where pages cannot drop).
        let mut file = tempfile::tempfile_in(env!("CARGO_MANIFEST_DIR")).unwrap();
        file.write_all(&vec![1u8; 200 << 10]).unwrap();
        file.sync_all().unwrap();
        assert!(holds(&file, 0, 200 << 10));
        drop_pages(&file);
        assert!(!holds(&file, 0, 200 << 10));
        assert!(!holds(&file, 5000, 5001));
        assert!(holds(&file, 7, 7));
        let mut byte = [0u8];
        file.read_exact_at(&mut byte, 5000).unwrap();
        assert!(holds(&file, 5000, 5001));
        // More than one piece, from an offset that is not a page's.
        fill(&file, 70_000, 200 << 10).unwrap();
        assert!(holds(&file, 70_000, 200 << 10));
        drop_pages(&file);
        fill(&file, 0, 200 << 10).unwrap();
        assert!(holds(&file, 0, 200 << 10));
    }

    #[test]
    fn filling_past_the_end_of_the_file_is_an_error() {
        let mut file = tempfile::tempfile_in(env!("CARGO_MANIFEST_DIR")).unwrap();
        file.write_all(&[1u8; 100]).unwrap();
        fill(&file, 0, 100).unwrap();
        let short = fill(&file, 50, 101).unwrap_err();
        assert_eq!(short.kind(), io::ErrorKind::UnexpectedEof);
        assert_eq!(
            short.to_string(),
            "the file is shorter than when it was opened"
        );
    }
}
