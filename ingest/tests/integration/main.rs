//! The `ingest` integration tests, in one test binary. Each module is one former test file;
//! filter on its name, e.g. `cargo test --release -p residency-ingest --test integration
//! tiff_claims::`. The tests run the real `ingest` binary in per-test temporary folders, so
//! they share nothing but the binary.

mod common;

mod fuzz_regressions;

mod sample_kinds;
mod store_bytes;
mod tiff_claims;
