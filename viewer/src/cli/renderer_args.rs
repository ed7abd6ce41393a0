//! The renderer flags `viewer render` and `viewer view` share, and the [`RenderOptions`] they
//! make.

use std::sync::Arc;

use anyhow::{Result, ensure};

use super::scene_args::{SceneArgs, SourceArgs};
use residency_viewer::gpu::renderer::{Method, RenderOptions};
use residency_viewer::gpu::streaming::Budget;
use residency_viewer::scene::Scene;
use residency_viewer::source::BrickSource;

/// How long a view may take to converge (flattened into `viewer render`, `viewer vdi` and
/// `viewer serve`).
#[derive(clap::Args, Debug)]
pub struct ConvergeArgs {
    /// Most frames to render while a view converges.
    #[arg(long, default_value_t = 64)]
    pub max_frames: u32,
    /// Wall-clock budget in seconds for a view to converge.
    #[arg(long, value_name = "S")]
    pub time_budget_s: Option<f64>,
}

impl ConvergeArgs {
    /// The streaming budget of these flags, fetching with `workers` threads.
    pub fn budget(&self, workers: usize) -> Result<Budget> {
        if let Some(s) = self.time_budget_s {
            ensure!(
                s > 0.0 && s.is_finite(),
                "--time-budget-s {s} must be positive"
            );
        }
        Ok(Budget {
            max_frames: self.max_frames,
            time: self.time_budget_s.map(std::time::Duration::from_secs_f64),
            workers,
            ..Default::default()
        })
    }
}

/// Renderer flags (flattened into `viewer render` and `viewer view`).
#[derive(clap::Args, Debug)]
pub struct RendererArgs {
    /// Brick cache budget in bytes.
    #[arg(long, default_value_t = 256 << 20)]
    pub cache_bytes: u64,
    /// LOD bias (`log2` scale of the pixel footprint; positive is coarser). The default, −1,
    /// picks voxels of half a pixel's footprint: see docs/benchmarks/render-analysis.md
    /// (run time against error).
    #[arg(long, default_value_t = -1.0, allow_hyphen_values = true)]
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
    /// Never substitute a missing brick from another resident level: a brick not resident
    /// yet is a hole until it arrives (the page-table-only baseline's behaviour).
    #[arg(long)]
    pub no_substitution: bool,
    /// Traversal method: ours (`residency`), a baseline: `page-table` (MRMCPT: whole-brick
    /// skipping, no substitution) or `octree` (one node per brick, GigaVoxels style), or
    /// another paper's renderer: `sparseleap` (occupancy geometry rasterised into per-pixel
    /// ray segment lists) or `rasterize` (a cut of bricks by projected bounding sphere,
    /// rasterised into ray segment lists, with macrocell skipping).
    #[arg(long, default_value = Method::Residency.name(), value_parser = super::names_parser::<Method>())]
    pub method: Method,
    /// Brick fetch worker threads.
    #[arg(long, default_value_t = 8)]
    pub workers: usize,
}

impl RendererArgs {
    /// The options for a `width × height` image of a scene of `channels` channel styles over a
    /// volume of `levels` levels, after checking the flags: the level bounds apply to every
    /// channel.
    pub fn options(
        &self,
        width: u32,
        height: u32,
        levels: usize,
        channels: usize,
    ) -> Result<RenderOptions> {
        ensure!(
            self.step > 0.0 && self.step.is_finite(),
            "--step {} must be positive",
            self.step
        );
        let levels = levels as u32;
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
            level_bounds: vec![(self.min_level, max_level); channels],
            empty_space_skipping: !self.no_skipping,
            substitution: !self.no_substitution,
            method: self.method,
            ..Default::default()
        })
    }
}

/// Opens the source, builds its scene and checks the renderer flags for a `width × height`
/// image: the start `viewer render` and `viewer view` share.
pub fn open_scene(
    source: &SourceArgs,
    scene: &SceneArgs,
    renderer: &RendererArgs,
    width: u32,
    height: u32,
) -> Result<(Arc<dyn BrickSource>, Scene, RenderOptions)> {
    let source: Arc<dyn BrickSource> = Arc::from(source.open()?);
    let info = source.info();
    let scene = scene.scene(info)?;
    let options = renderer.options(width, height, info.levels.len(), scene.channels.len())?;
    Ok((source, scene, options))
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Parser)]
    struct Flags {
        #[command(flatten)]
        renderer: RendererArgs,
    }

    fn options(args: &[&str]) -> Result<RenderOptions> {
        let mut all = vec!["viewer"];
        all.extend(args);
        Flags::parse_from(all).renderer.options(64, 32, 4, 3)
    }

    #[test]
    fn flags_become_render_options() {
        let o = options(&[]).unwrap();
        assert_eq!((o.width, o.height, o.cache_bytes), (64, 32, 256 << 20));
        assert_eq!(o.level_bounds, vec![(0, 3); 3]);
        assert!(o.empty_space_skipping && o.substitution);
        assert_eq!(o.method, Method::Residency);
        // The defaults the benchmark's time-error sweep puts on the Pareto front.
        assert_eq!((o.lod_bias, o.step_factor), (-1.0, 0.5));
        assert_eq!(
            o,
            RenderOptions {
                width: 64,
                height: 32,
                level_bounds: vec![(0, 3); 3],
                ..Default::default()
            }
        );
        assert_eq!(
            options(&["--method", "page-table"]).unwrap().method,
            Method::PageTable
        );
        assert_eq!(
            options(&["--method", "octree"]).unwrap().method,
            Method::Octree
        );
        assert_eq!(
            options(&["--method", "sparseleap"]).unwrap().method,
            Method::SparseLeap
        );
        assert_eq!(
            options(&["--method", "rasterize"]).unwrap().method,
            Method::Rasterize
        );
        let o = options(&[
            "--min-level",
            "1",
            "--max-level",
            "9",
            "--no-skipping",
            "--no-substitution",
            "--lod-bias",
            "-1.5",
            "--step",
            "0.25",
        ])
        .unwrap();
        assert_eq!(o.level_bounds, vec![(1, 3); 3]);
        assert!(!o.empty_space_skipping && !o.substitution);
        assert_eq!((o.lod_bias, o.step_factor), (-1.5, 0.25));
        assert_eq!(
            options(&["--min-level", "2", "--max-level", "1"])
                .unwrap_err()
                .to_string(),
            "--min-level 2 is coarser than --max-level 1"
        );
        assert_eq!(
            options(&["--step", "0"]).unwrap_err().to_string(),
            "--step 0 must be positive"
        );
    }
}
