//! The renderer flags `viewer render` and `viewer view` share, and the [`RenderOptions`] they
//! make.

use anyhow::{Result, ensure};

use crate::gpu::renderer::RenderOptions;
use crate::scene::Scene;
use crate::source::VolumeInfo;

/// Renderer flags (flattened into `viewer render` and `viewer view`).
#[derive(clap::Args, Debug)]
pub struct RendererArgs {
    /// Brick cache budget in bytes.
    #[arg(long, default_value_t = 256 << 20)]
    pub cache_bytes: u64,
    /// LOD bias (`log2` scale of the pixel footprint; positive is coarser).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub lod_bias: f32,
    /// Step as a fraction of the smallest voxel edge of the level sampled.
    #[arg(long, default_value_t = 0.5)]
    pub step: f32,
    /// Finest level any channel may use.
    #[arg(long, default_value_t = 0)]
    pub min_level: u32,
    /// Coarsest level any channel may use [default: the coarsest].
    #[arg(long)]
    pub max_level: Option<u32>,
    /// Octree leaf depth [default: leaves of about 8 level-0 voxels, at most depth 7].
    #[arg(long)]
    pub octree_depth: Option<u32>,
    /// Disable empty-space skipping and homogeneous-node integration (a baseline).
    #[arg(long)]
    pub no_skipping: bool,
    /// Brick fetch worker threads.
    #[arg(long, default_value_t = 8)]
    pub workers: usize,
}

impl RendererArgs {
    /// The options for a `width × height` image of `scene` over the volume `info`, after
    /// checking the flags: the level bounds apply to every channel of the scene.
    pub fn options(
        &self,
        width: u32,
        height: u32,
        info: &VolumeInfo,
        scene: &Scene,
    ) -> Result<RenderOptions> {
        ensure!(
            self.step > 0.0 && self.step.is_finite(),
            "--step {} must be positive",
            self.step
        );
        let levels = info.levels.len() as u32;
        let max_level = self.max_level.unwrap_or(levels - 1).min(levels - 1);
        ensure!(
            self.min_level <= max_level,
            "--min-level {} is coarser than --max-level {max_level}",
            self.min_level
        );
        Ok(RenderOptions {
            width,
            height,
            cache_bytes: self.cache_bytes,
            lod_bias: self.lod_bias,
            step_factor: self.step,
            octree_depth: self.octree_depth,
            level_bounds: vec![(self.min_level, max_level); scene.channels.len()],
            empty_space_skipping: !self.no_skipping,
            ..Default::default()
        })
    }
}
