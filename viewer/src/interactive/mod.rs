//! The interactive window of `viewer view`: the progressive GPU render of
//! [`crate::gpu::streaming`] driven one step at a time behind a winit window, with orbit, pan
//! and zoom, per-channel visibility, colour and window/level, and on-screen statistics.
//!
//! - [`camera_control`]: orbit, pan and zoom as pure functions of the camera (the web viewer
//!   uses them too);
//! - [`controls`]: channel visibility, palette colours and opacity-ramp window/level (also
//!   the web viewer's);
//! - [`overlay`]: sRGB conversion, scaling to the window and the bitmap-font statistics panel;
//! - [`session`]: the non-blocking progressive loop (render, fetch, insert, repeat);
//! - [`display`]: frames to the window, on the GPU through a surface (no readback), else by a
//!   `softbuffer` CPU blit;
//! - [`window`]: the winit event loop of `viewer view`;
//! - [`vdi_window`]: `viewer view --vdi`, a volumetric depth image ray cast for the window's
//!   camera on the GPU at the rate a frame-rate controller holds.

pub mod camera_control;
pub mod controls;
#[cfg(not(target_arch = "wasm32"))]
pub mod display;
#[cfg(not(target_arch = "wasm32"))]
pub mod overlay;
#[cfg(not(target_arch = "wasm32"))]
pub mod session;
#[cfg(not(target_arch = "wasm32"))]
pub mod vdi_window;
#[cfg(not(target_arch = "wasm32"))]
pub mod window;
