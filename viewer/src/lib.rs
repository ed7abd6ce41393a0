//! `residency-viewer`: residency-octree volume rendering on wgpu (the renderer of Herzberger et
//! al., "Residency Octree: A Hybrid Approach for Scalable Web-Based Multi-Volume Rendering"),
//! streamed from a `brickserver` or read from a local OME-Zarr store, plus an f64 CPU reference
//! ray caster and image comparison. The repository's `docs/viewer.md` describes the renderer and
//! its command line, `docs/architecture.md` where it sits among the crates.
//!
//! - [`scene`]: camera, per-channel transfer functions and the compositing rule shared by the
//!   GPU renderer and the reference (in `residency_schemas`, re-exported here);
//! - [`source`]: where volume metadata and bricks come from (HTTP brick server or local store);
//! - [`reference`](mod@reference): the f64 CPU reference ray caster;
//! - [`image`]: linear-RGB images, PNG and EXR; [`metrics`]: PSNR, SSIM, max abs error;
//! - [`octree`]: the residency octree (partial-residency masks and value ranges per node);
//! - [`gpu`]: the wgpu renderer: device, brick cache, page tables, the `raycast.wgsl` pass and
//!   the progressive streaming loop;
//! - [`defaults`]: the default view of a volume (camera, colours, transfer functions);
//! - [`frame_rate`]: the PI controller that holds a frame time by the image-space sampling;
//! - [`vdi_filter_choice`]: which filter a VDI's frames use, as the user picks it (by default
//!   the linear filter at rest, and while the camera moves where the device has time for it);
//! - [`vdi_frame_plan`]: each VDI frame's filter and image-space sampling, moving or at rest;
//! - [`vdi_compression_choice`]: which compression the page asks the render service for (by
//!   default zstd over a link slower than the time it costs, else LZ4);
//! - [`interactive`]: the `viewer view` window (orbit, pan, zoom, channel controls, statistics);
//! - [`bench`](mod@bench): the renderer benchmark suite (`viewer bench`);
//! - `service` (native, `serve` feature): the render service of `viewer serve`, VDIs of a
//!   dataset's views over HTTP for a page far away;
//! - `web` (WebAssembly only): the browser driver, `fetch` and `requestAnimationFrame` over
//!   the same renderer, with the `window.residency` automation hook.
//!
//! One renderer, two drivers: everything but [`bench`](mod@bench),
//! [`reference`](mod@reference), the window and the local
//! and blocking-HTTP sources also compiles for `wasm32-unknown-unknown`. Command-line
//! flags live in the `viewer` binary only.
//!
//! Errors are `thiserror` enums, one per concept ([`source::SourceError`],
//! [`gpu::GpuError`], [`octree::OctreeError`], [`defaults::SceneError`], ...), whose messages
//! name the file, key, brick or parameter at fault; a wrapped error is their `source`, so
//! [`error_chain`] (or the binary's `{:#}` error line) prints the whole story.

#[cfg(not(target_arch = "wasm32"))]
pub mod bench;
pub mod defaults;
pub mod frame_rate;
pub mod gpu;
pub mod image;
pub mod interactive;
pub mod metrics;
pub mod octree;
#[cfg(not(target_arch = "wasm32"))]
pub mod reference;
/// The scene (camera, transfer functions, compositing rule), in `residency-schemas` since its
/// file is a document the viewer reads.
pub use residency_schemas::scene;
#[cfg(all(feature = "serve", not(target_arch = "wasm32")))]
pub mod service;
pub mod source;
pub mod vdi_compression_choice;
pub mod vdi_filter_choice;
pub mod vdi_frame_plan;
pub mod vdi_service;
#[cfg(target_arch = "wasm32")]
pub mod web;

/// `error` and its sources on one line, as the binary's `error: …` line prints it (and the web
/// page, and failed-brick messages): a cause the message already names is printed once.
pub use residency_schemas::error_chain::error_chain;

#[cfg(test)]
mod tests {
    use super::{defaults, error_chain};

    #[test]
    fn the_chain_is_every_source_joined_as_the_binary_prints_it() {
        let e = defaults::read_scene(std::path::Path::new("/nonexistent/scene.json")).unwrap_err();
        assert_eq!(e.to_string(), "/nonexistent/scene.json: cannot read");
        assert_eq!(
            error_chain(&e),
            "/nonexistent/scene.json: cannot read: No such file or directory (os error 2)"
        );
    }
}
