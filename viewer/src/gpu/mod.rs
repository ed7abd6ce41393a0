//! The GPU side of the renderer, one concept per module, listed so that each uses only modules
//! listed before it (no module uses one that uses it back; `GpuError` is defined below every
//! module that returns it):
//!
//! - [`limits`]: the renderer's fixed capacities (channels drawn at once, pyramid levels);
//! - [`error`]: [`GpuError`], why the GPU side failed;
//! - [`method`]: [`method::Method`], how the ray caster finds data and skips empty space (ours
//!   or a baseline), with its names;
//! - [`options`]: [`options::RenderOptions`], the renderer's settings;
//! - [`page_table`]: page tables per (channel, level) and the brick ids the shader reports;
//! - `apron` (internal): each slot's one-voxel apron of its neighbours' first voxels, so a
//!   trilinear sample reads one slot;
//! - [`brick_cache`]: the brick cache atlas per sample format, with LRU eviction driven by the
//!   shader's usage feedback;
//! - [`contract`]: every struct and constant the renderer shares with the shaders, written
//!   once (`#[repr(C)]` types with WGSL twins checked against naga's layout; a generated WGSL
//!   prelude of constants; the binding numbers), and the shader sources as compiled;
//! - [`occupancy`]: SparseLeap's occupancy geometry, built on the CPU from the residency
//!   octree;
//! - [`brick_cut`]: the rasterize method's cut of bricks, chosen on the CPU each frame;
//! - [`pipeline`]: the long-lived part, `raycast.wgsl` compiled for one atlas format and one
//!   method, shared by every renderer on the device;
//! - [`device`]: adapter and device creation (lavapipe works), timestamp-query support, and
//!   the pipelines built on the device;
//! - `buffers` (internal): storage, uniform and readback buffers made one way, the
//!   storage-binding limit check, and mapping for reading;
//! - `timer` (internal): GPU time of compute passes from timestamp queries;
//! - [`residency`]: the residency state of one volume (octree, page tables, cache), which
//!   changes as bricks arrive and are evicted;
//! - `tables` (internal): the scene tables the shader consults (levels, channels, transfer
//!   functions), rewritten in place when the style changes;
//! - `segments` (internal): the ray segment lists of the SparseLeap and rasterize methods,
//!   rasterised on the GPU before the ray caster runs;
//! - [`probe`] (native): the limit probe of `viewer bench`, the same rays through one resident
//!   level-0 texture with no traversal, for the renderer's fraction of what sampling costs;
//! - [`present`]: the present pass, the rendered image put on a surface or texture on the
//!   GPU with the CPU path's sRGB encoding and the statistics panel, without a readback;
//! - [`renderer`]: one volume and scene: pipeline, residency state, scene tables and the
//!   per-frame buffers, with one frame's dispatch and readback (image, capped request list,
//!   usage, statistics);
//! - [`stop_reason`]: why a progressive render stopped, written as a sentence;
//! - [`streaming`]: worker threads fetching bricks, and the progressive loop
//!   render → read requests → fetch → upload → insert into the octree → repeat;
//! - [`synthetic`] (native): an in-memory brick source for tests and benchmarks.

pub(crate) mod apron;
pub mod brick_cache;
pub mod brick_cut;
pub(crate) mod buffers;
mod clipping;
pub mod contract;
pub mod device;
pub mod error;
pub mod limits;
pub mod method;
pub mod occupancy;
pub mod options;
pub mod page_table;
pub mod pipeline;
pub mod present;
#[cfg(not(target_arch = "wasm32"))]
pub mod probe;
pub mod renderer;
pub mod residency;
pub(crate) mod segments;
pub mod stop_reason;
pub mod streaming;
#[cfg(not(target_arch = "wasm32"))]
pub mod synthetic;
pub(crate) mod tables;
pub(crate) mod timer;
pub mod vdi;
pub mod vdi_render;

pub use error::GpuError;
