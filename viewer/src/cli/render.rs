//! `viewer render`: a progressive GPU render ([`residency_viewer::gpu::streaming`]) until no brick is
//! outstanding or a frame/time budget runs out, written as PNG or EXR, with per-frame
//! statistics as JSON.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};

use super::renderer_args::{RendererArgs, open_scene};
use super::scene_args::{SceneArgs, SourceArgs};
use residency_viewer::gpu::device::Gpu;
use residency_viewer::gpu::streaming::{Budget, RenderStats, render_progressive};
use residency_viewer::image::{ImageFormat, RgbImage};

/// Arguments of `viewer render`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Where the volume comes from.
    #[command(flatten)]
    pub source: SourceArgs,
    /// What to draw.
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Image width in pixels.
    #[arg(long, default_value_t = 256)]
    pub width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 256)]
    pub height: u32,
    /// Output image: `.png` (8-bit sRGB) or `.exr` (32-bit float linear RGB).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Write per-frame statistics here as JSON.
    #[arg(long, value_name = "FILE")]
    pub stats: Option<PathBuf>,
    /// Most frames to render.
    #[arg(long, default_value_t = 64)]
    pub max_frames: u32,
    /// Wall-clock budget in seconds.
    #[arg(long, value_name = "S")]
    pub time_budget_s: Option<f64>,
    /// Renderer settings.
    #[command(flatten)]
    pub renderer: RendererArgs,
}

/// Runs `viewer render`.
pub fn run(args: Args) -> Result<()> {
    ImageFormat::of(&args.out)?;
    let (source, scene, options) = open_scene(
        &args.source,
        &args.scene,
        &args.renderer,
        args.width,
        args.height,
    )?;
    let budget = Budget {
        max_frames: args.max_frames,
        time: args.time_budget_s.map(Duration::from_secs_f64),
        workers: args.renderer.workers,
        ..Default::default()
    };
    let (method, empty_space_skipping) = (options.method, options.empty_space_skipping);
    let start = Instant::now();
    let gpu = Gpu::new()?;
    let result = render_progressive(&gpu, Arc::clone(&source), &scene, options, &budget)?;
    let wall_s = start.elapsed().as_secs_f64();
    let image = RgbImage {
        width: result.width as usize,
        height: result.height as usize,
        pixels: result.pixels.iter().map(|p| [p[0], p[1], p[2]]).collect(),
    };
    image.write(&args.out)?;
    tracing::info!(
        "wrote {} ({}×{}) after {} frames in {wall_s:.2} s: {}",
        args.out.display(),
        result.width,
        result.height,
        result.frames.len(),
        result.stop_reason
    );
    if let Some(path) = &args.stats {
        let stats = RenderStats::new(
            &source.info().name,
            &gpu,
            (method, empty_space_skipping),
            &result,
            wall_s,
        );
        let json = serde_json::to_string_pretty(&stats)?;
        std::fs::write(path, json + "\n")
            .with_context(|| format!("{}: cannot write statistics", path.display()))?;
    }
    Ok(())
}
