//! `residency-viewer`: residency-octree volume rendering on wgpu (the renderer of
//! `../shared/papers/residency-octree.txt`), streamed from a `brickserver` or read from a local
//! OME-Zarr store, plus an f64 CPU reference ray caster and image comparison.
//!
//! - [`scene`]: camera, per-channel transfer functions and the compositing rule shared by the
//!   GPU renderer and the reference;
//! - [`source`]: where volume metadata and bricks come from (HTTP brick server or local store);
//! - [`reference`](mod@reference): the f64 CPU reference ray caster;
//! - [`image`]: linear-RGB images, PNG and EXR; [`metrics`]: PSNR, SSIM, max abs error;
//! - [`octree`]: the residency octree (partial-residency masks and value ranges per node);
//! - [`gpu`]: the wgpu renderer: device, brick cache, page tables, the `raycast.wgsl` pass and
//!   the progressive streaming loop;
//! - [`defaults`]: the default view of a volume (camera, colours, transfer functions);
//! - [`interactive`]: the `viewer view` window (orbit, pan, zoom, channel controls, statistics);
//! - [`bench`]: the renderer benchmark suite (`viewer bench`);
//! - `web` (WebAssembly only): the browser driver, `fetch` and `requestAnimationFrame` over
//!   the same renderer, with the `window.residency` automation hook.
//!
//! One renderer, two drivers: everything but [`bench`], [`reference`], the window and the local
//! and blocking-HTTP sources also compiles for `wasm32-unknown-unknown`. Command-line
//! flags live in the `viewer` binary only.

// Fallible functions here return `anyhow` errors whose messages name the file, key or brick at
// fault; they get `# Errors` sections as they move to typed errors (the format model, wire
// decoding and the server's parsers already have both).
#![allow(clippy::missing_errors_doc)]

#[cfg(not(target_arch = "wasm32"))]
pub mod bench;
pub mod defaults;
pub mod gpu;
pub mod image;
pub mod interactive;
pub mod metrics;
pub mod octree;
#[cfg(not(target_arch = "wasm32"))]
pub mod reference;
pub mod scene;
pub mod source;
#[cfg(target_arch = "wasm32")]
pub mod web;
