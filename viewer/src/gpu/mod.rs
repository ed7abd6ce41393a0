//! The GPU side of the renderer, one concept per module:
//!
//! - [`buffers`]: storage, uniform and readback buffers made one way, and the storage-binding
//!   limit check;
//! - [`contract`]: every struct and constant the renderer shares with `raycast.wgsl`, written
//!   once (`#[repr(C)]` types with WGSL twins checked against naga's layout; a generated WGSL
//!   prelude of constants; the binding numbers);
//! - [`device`]: adapter and device creation (lavapipe works), timestamp-query support;
//! - [`page_table`]: page tables per (channel, level) and the brick ids the shader reports;
//! - [`brick_cache`]: the brick cache atlas per sample format, with LRU eviction driven by the
//!   shader's usage feedback;
//! - [`tables`]: the scene tables the shader consults (levels, channels, transfer
//!   functions with their prefix tables for O(1) emptiness tests), rewritten in place when the
//!   style changes;
//! - [`pipeline`]: the long-lived part, `raycast.wgsl` compiled for one atlas format and one
//!   method, shared by every renderer on the device;
//! - [`residency`]: the residency state of one volume (octree, page tables, cache), which
//!   changes as bricks arrive and are evicted;
//! - [`probe`] (native): the limit probe of `viewer bench`, the same rays through one resident
//!   level-0 texture with no traversal, for the renderer's fraction of what sampling costs;
//! - [`renderer`]: one volume and scene: pipeline, residency state, scene tables and the
//!   per-frame buffers, with one frame's dispatch and readback (image, capped request list,
//!   usage, statistics);
//! - [`streaming`]: worker threads fetching bricks, and the progressive loop
//!   render → read requests → fetch → upload → insert into the octree → repeat;
//! - [`timer`]: GPU time of compute passes from timestamp queries;
//! - [`synthetic`]: an in-memory brick source for tests and benchmarks.

pub mod brick_cache;
pub mod buffers;
pub mod contract;
pub mod device;
pub mod page_table;
pub mod pipeline;
#[cfg(not(target_arch = "wasm32"))]
pub mod probe;
pub mod renderer;
pub mod residency;
pub mod streaming;
#[cfg(not(target_arch = "wasm32"))]
pub mod synthetic;
pub mod tables;
pub mod timer;
