//! The workspace-level integration tests, in one test binary: they run the real release
//! binaries (`cargo build --release --workspace --bins` first), each test in its own temporary
//! folder and with its own `brickserver` on a free port. Filter on a module name, e.g.
//! `cargo test --release -p residency-tests --test integration served_render::`.

mod sample_pipeline;
mod served_render;
