//! `residency.render(...)`: a converged image of a store or of a served dataset, as
//! `viewer render` draws it with the same scene and size and writes it as PNG.

use std::sync::Arc;

use residency_store::location::{LocationError, ObjectStoreOptions, StoreLocation};
use residency_viewer::defaults::{SceneError, check_channel, default_scene};
use residency_viewer::gpu::GpuError;
use residency_viewer::gpu::device::Gpu;
use residency_viewer::gpu::renderer::RenderOptions;
use residency_viewer::gpu::streaming::{Budget, render_progressive};
use residency_viewer::image::linear_to_srgb8;
use residency_viewer::scene::Scene;
use residency_viewer::source::{BrickSource, HttpSource, LocalSource, SourceError};

/// Where the volume comes from.
pub enum Volume {
    /// An OME-Zarr store: a folder or `s3://BUCKET/PREFIX`.
    Store(StoreLocation, ObjectStoreOptions),
    /// A dataset `brickserver` serves at a URL.
    Served {
        /// The server's base URL.
        url: String,
        /// The dataset's name.
        dataset: String,
    },
}

/// Why an image cannot be rendered: the messages `viewer render` prints.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The store's location cannot be used.
    #[error(transparent)]
    Location(#[from] LocationError),
    /// The volume cannot be opened.
    #[error(transparent)]
    Source(#[from] SourceError),
    /// The scene is not a scene of this volume.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// The GPU refused the render.
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// The frames `viewer render` renders at most while a view converges (its `--max-frames`).
const MAX_FRAMES: u32 = 64;
/// The brick fetch threads of `viewer render` (its `--workers`).
const WORKERS: usize = 8;

/// `volume` rendered with `scene` (scene-file JSON; `None`: the volume's default scene) at
/// `width × height` with `viewer render`'s default settings until it converges (or 64
/// frames): the 8-bit sRGB RGB pixels, row-major from the top, that its PNG holds.
///
/// # Errors
/// A [`RenderError`]: the volume cannot be opened, the scene is not one of it, or the GPU
/// fails.
pub fn render(
    volume: &Volume,
    scene: Option<&str>,
    width: u32,
    height: u32,
) -> Result<Vec<u8>, RenderError> {
    let source: Arc<dyn BrickSource> = match volume {
        Volume::Store(location, options) => {
            Arc::new(LocalSource::open_location(location, options)?)
        }
        Volume::Served { url, dataset } => Arc::new(HttpSource::open(url, dataset)?),
    };
    let info = source.info();
    let scene = match scene {
        Some(json) => Scene::from_json(json.as_bytes(), "scene").map_err(SceneError::from)?,
        None => default_scene(info),
    };
    for s in &scene.channels {
        check_channel(info, s.channel, "scene file")?;
    }
    let options = RenderOptions {
        width,
        height,
        level_bounds: vec![(0, info.levels.len() as u32 - 1); scene.channels.len()],
        ..Default::default()
    };
    let budget = Budget {
        max_frames: MAX_FRAMES,
        workers: WORKERS,
        ..Default::default()
    };
    let gpu = Gpu::new()?;
    let result = render_progressive(&gpu, source, &scene, options, &budget)?;
    Ok(result
        .pixels
        .iter()
        .flat_map(|p| [p[0], p[1], p[2]].map(linear_to_srgb8))
        .collect())
}
