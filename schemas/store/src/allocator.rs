//! How the programs that read and write stores (`ingest`, `brickserver`) set up mimalloc, their
//! allocator: memory that is freed and not reused goes back to the kernel within 10 ms (mimalloc
//! v3 waits a second), and arenas are committed page by page, not up front. So the resident set
//! is what the program holds: `ingest --memory-limit` bounds the peak RSS
//! (`tests/python/test_memory_limit.py`; a 64 × 3000² tiled zlib BigTIFF at 256M peaked at
//! 178 MiB with mimalloc's defaults, 128–132 MiB with these), and `brickserver` under load stays
//! near nginx's size (`benchmarks/server_bench.py`; 61 MB peak with the defaults, 22 MB with
//! these, on 2 cores at 16 and 256 connections).
//!
//! Each binary runs [`return_freed_memory`] before `main`, from `.init_array`, so that it
//! comes before mimalloc reserves its first arena:
//!
//! ```ignore
//! #[used]
//! #[cfg_attr(target_os = "linux", unsafe(link_section = ".init_array"))]
//! static RETURN_FREED_MEMORY: extern "C" fn() = residency_store::allocator::return_freed_memory;
//! ```

use std::ffi::{c_int, c_long};

// The C library whose options are set here (linked by the feature that enables this module).
use libmimalloc_sys as _;

/// mimalloc's number for `mi_option_arena_eager_commit` (`mi_option_t` in `mimalloc.h`: the
/// same in v2 and v3, which keep retired numbers as `deprecated_` entries).
const ARENA_EAGER_COMMIT: c_int = 4;
/// mimalloc's number for `mi_option_purge_delay`.
const PURGE_DELAY: c_int = 15;
/// Milliseconds before freed memory goes back to the kernel (0 costs measurably more system
/// time in `ingest`: 4.9 s against 1.9 s on the BigTIFF above).
const PURGE_DELAY_MS: c_long = 10;

unsafe extern "C" {
    fn mi_option_set(option: c_int, value: c_long);
}

/// Sets mimalloc's options as this module says, unless mimalloc's own environment variables
/// (`MIMALLOC_ARENA_EAGER_COMMIT`, `MIMALLOC_PURGE_DELAY`) set them. Meant to run before
/// `main` (see the module's documentation).
pub extern "C" fn return_freed_memory() {
    for (option, name, value) in [
        (ARENA_EAGER_COMMIT, "MIMALLOC_ARENA_EAGER_COMMIT", 0),
        (PURGE_DELAY, "MIMALLOC_PURGE_DELAY", PURGE_DELAY_MS),
    ] {
        if std::env::var_os(name).is_none() {
            // SAFETY: `mi_option_set` only stores the value of an option that takes an
            // integer.
            unsafe { mi_option_set(option, value) };
        }
    }
}
