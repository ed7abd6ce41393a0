//! The resource limits of every fuzz target.
//!
//! libFuzzer enforces `-malloc_limit_mb` only through a sanitizer's allocator hooks, so with
//! `-s none` a single huge allocation would go unnoticed until it failed or the RSS check
//! (once a second) caught it. [`LimitAlloc`] makes the limit hold in every build: an
//! allocation above [`MAX_ALLOCATION`] prints its size and aborts, which libFuzzer reports as a
//! crash and saves the input.

use std::alloc::{GlobalAlloc, Layout, System};

/// libFuzzer `-rss_limit_mb`: the whole process.
pub const RSS_LIMIT_MB: usize = 2048;
/// libFuzzer `-malloc_limit_mb`: one allocation.
pub const MALLOC_LIMIT_MB: usize = 1024;
/// libFuzzer `-timeout`: seconds one input may take.
pub const TIMEOUT_S: u64 = 10;
/// Largest single allocation, in bytes, before [`LimitAlloc`] aborts.
pub const MAX_ALLOCATION: usize = MALLOC_LIMIT_MB << 20;

/// The system allocator, aborting on any single allocation above [`MAX_ALLOCATION`].
pub struct LimitAlloc;

#[cold]
fn refuse(size: usize) -> ! {
    // No allocation here: format into a stack buffer and write it with one syscall.
    let mut buf = [0u8; 128];
    let head = b"residency-fuzz: allocation of ";
    let tail = b" bytes exceeds the per-allocation limit (MALLOC_LIMIT_MB)\n";
    let mut n = 0;
    buf[..head.len()].copy_from_slice(head);
    n += head.len();
    let mut digits = [0u8; 20];
    let mut d = 0;
    let mut v = size;
    loop {
        digits[d] = b'0' + (v % 10) as u8;
        d += 1;
        v /= 10;
        if v == 0 {
            break;
        }
    }
    for i in (0..d).rev() {
        buf[n] = digits[i];
        n += 1;
    }
    let t = tail.len().min(buf.len() - n);
    buf[n..n + t].copy_from_slice(&tail[..t]);
    n += t;
    // SAFETY: writes `n` initialised bytes of `buf` to stderr.
    unsafe {
        libc_write(2, buf.as_ptr(), n);
    }
    std::process::abort()
}

unsafe extern "C" {
    #[link_name = "write"]
    fn libc_write(fd: i32, buf: *const u8, count: usize) -> isize;
}

// SAFETY: forwards to `System`, only refusing some sizes first.
unsafe impl GlobalAlloc for LimitAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if layout.size() > MAX_ALLOCATION {
            refuse(layout.size());
        }
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if layout.size() > MAX_ALLOCATION {
            refuse(layout.size());
        }
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if new_size > MAX_ALLOCATION {
            refuse(new_size);
        }
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}
