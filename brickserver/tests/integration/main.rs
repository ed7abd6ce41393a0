//! The `brickserver` integration tests, in one test binary. Each module is one topic; filter
//! on its name, e.g. `cargo test --release -p residency-brickserver --test integration
//! viewer::`. Requests go to the router in process (`tower::ServiceExt::oneshot`), except in
//! `binary`, which runs the real `brickserver` to check that its flags reach the library.

mod common;

mod binary;
mod connections;
mod listing;
mod loads;
mod object_store;
mod openapi;
mod viewer;
