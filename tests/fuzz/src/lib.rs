//! Helpers shared by the fuzz targets in `fuzz_targets/`: the allocation limit, a scratch
//! folder for parsers that only take paths, a small TIFF writer for structured inputs, and
//! reading every plane a volume source agrees to read.
//!
//! The limits every target runs under (see `docs/fuzzing.md` and `scripts/fuzz.sh`):
//! one allocation of more than [`limits::MAX_ALLOCATION`] bytes aborts (a finding, whatever
//! the sanitizer), libFuzzer's `-malloc_limit_mb` and `-rss_limit_mb` are
//! [`limits::MALLOC_LIMIT_MB`] and [`limits::RSS_LIMIT_MB`], and one input may take at most
//! [`limits::TIMEOUT_S`] seconds.

pub mod known;
pub mod limits;
pub mod planes;
pub mod scratch;
pub mod tiffgen;

#[global_allocator]
static ALLOCATOR: limits::LimitAlloc = limits::LimitAlloc;
