//! The viewer's integration tests, in one test binary (every file directly under `tests/` is
//! a binary of its own, and each would link wgpu again). Each module is one former test
//! file; filter on its name, e.g.
//! `cargo test --release -p residency-viewer --test integration render_streaming::`.
//!
//! The tests share one process and run on parallel threads: the GPU is opened through
//! [`render_common::gpu`] (one shared device) or [`render_common::new_gpu`] (a device of the
//! test's own), which set `XDG_RUNTIME_DIR` once; stores go to per-test temporary folders;
//! servers and Xvfb pick free ports and displays; log capture is scoped to the test's thread.

mod render_common;
mod source_common;

mod compare_cli;
mod gpu_cache;
mod gpu_contract;
mod gpu_octree;
mod gpu_probe;
mod gpu_shaders;
mod json_schemas;
mod present;
mod reference_cli;
mod render_baselines;
mod render_cli;
mod render_filters;
mod render_modes;
mod render_precision;
mod render_reference;
mod render_segments;
mod render_streaming;
mod render_stress;
mod serve_cli;
mod source_http;
mod source_local;
mod vdi_cli;
mod vdi_generation;
mod view_present;
mod view_session;
mod view_xvfb;
