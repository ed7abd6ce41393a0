//! How the programs that read and write stores (`ingest`, `brickserver`) set up mimalloc, their
//! allocator: arenas are committed page by page, not up front, and memory that is freed and
//! not reused goes back to the kernel after a delay that suits the program.
//!
//! - `brickserver` ([`return_freed_memory_for_serving`]): within 10 ms (mimalloc v3 waits a
//!   second), so its resident set is what it holds: under load it stays near nginx's size
//!   (`benchmarks/server_bench.py`; 61 MB peak with mimalloc's defaults, 22 MB with these, on
//!   2 cores at 16 and 256 connections).
//! - `ingest` ([`return_freed_memory_for_converting`]): after a second. A conversion frees and
//!   needs again the same large buffers once per slab (zarrs' encoded chunks and shards, a few
//!   hundred milliseconds apart at 1024² planes); returned after 10 ms, each came back as fresh
//!   pages that the kernel faulted in and zeroed again: a 2 GiB TIFF took 60,000–71,000 minor
//!   faults, and takes 24,000–29,000 (`/usr/bin/time`, 2-core VM, 2026-11-28), for 10 MB more
//!   peak RSS. `--memory-limit` still bounds the peak RSS (`tests/python/test_memory_limit.py`:
//!   the same 0.61–0.68× of the limit, partitions 0.49× against 0.42×). A delay of 0 cost
//!   far more: 4.9 s of system time against 1.9 s on a 64 × 3000² tiled zlib BigTIFF.
//!
//! Each binary runs its function before `main`, from `.init_array`, so that it comes before
//! mimalloc reserves its first arena:
//!
//! ```ignore
//! #[used]
//! #[cfg_attr(target_os = "linux", unsafe(link_section = ".init_array"))]
//! static RETURN_FREED_MEMORY: extern "C" fn() =
//!     residency_store::allocator::return_freed_memory_for_serving;
//! ```

use std::ffi::{c_int, c_long};

// The C library whose options are set here (linked by the feature that enables this module).
use libmimalloc_sys as _;

/// mimalloc's number for `mi_option_arena_eager_commit` (`mi_option_t` in `mimalloc.h`: the
/// same in v2 and v3, which keep retired numbers as `deprecated_` entries).
const ARENA_EAGER_COMMIT: c_int = 4;
/// mimalloc's number for `mi_option_purge_delay`.
const PURGE_DELAY: c_int = 15;
/// Milliseconds before a server's freed memory goes back to the kernel.
const SERVING_PURGE_DELAY_MS: c_long = 10;
/// Milliseconds before a conversion's freed memory goes back to the kernel: mimalloc v3's own
/// default, set here because v2 (which `libmimalloc-sys` builds today) waits 10 ms.
const CONVERTING_PURGE_DELAY_MS: c_long = 1000;

unsafe extern "C" {
    fn mi_option_set(option: c_int, value: c_long);
}

/// Sets mimalloc's options for a server (see the module's documentation). Meant to run
/// before `main`.
pub extern "C" fn return_freed_memory_for_serving() {
    set_options(SERVING_PURGE_DELAY_MS);
}

/// Sets mimalloc's options for a conversion (see the module's documentation). Meant to run
/// before `main`.
pub extern "C" fn return_freed_memory_for_converting() {
    set_options(CONVERTING_PURGE_DELAY_MS);
}

/// Commits arenas page by page and returns freed memory after `purge_delay_ms`, unless
/// mimalloc's own environment variables (`MIMALLOC_ARENA_EAGER_COMMIT`,
/// `MIMALLOC_PURGE_DELAY`) set them.
fn set_options(purge_delay_ms: c_long) {
    for (option, name, value) in [
        (ARENA_EAGER_COMMIT, "MIMALLOC_ARENA_EAGER_COMMIT", 0),
        (PURGE_DELAY, "MIMALLOC_PURGE_DELAY", purge_delay_ms),
    ] {
        if std::env::var_os(name).is_none() {
            // SAFETY: `mi_option_set` only stores the value of an option that takes an
            // integer.
            unsafe { mi_option_set(option, value) };
        }
    }
}
