//! `viewer render`: a progressive GPU render ([`residency_viewer::gpu::streaming`]) until no brick is
//! outstanding or a frame/time budget runs out, written as PNG or EXR, with per-frame
//! statistics as JSON; or, with `--vdi`, a volumetric depth image ray cast from the scene's
//! camera ([`residency_viewer::gpu::vdi_render`]).

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result};

use super::renderer_args::{ConvergeArgs, RendererArgs, open_scene};
use super::scene_args::{SceneArgs, SourceArgs};
use residency_viewer::gpu::device::Gpu;
use residency_viewer::gpu::streaming::{RenderStats, render_progressive};
use residency_viewer::gpu::vdi_filter::VdiFilter;
use residency_viewer::gpu::vdi_render::VdiRenderer;
use residency_viewer::image::{ImageFormat, RgbImage};
use residency_viewer::vdi_filter_choice::VdiFilterChoice;

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
    /// How long the view may take to converge.
    #[command(flatten)]
    pub converge: ConvergeArgs,
    /// Renderer settings.
    #[command(flatten)]
    pub renderer: RendererArgs,
    /// Ray cast this volumetric depth image (`viewer vdi`) instead of a volume: the camera is
    /// the scene's (`--scene`, `--camera`, `--fov`), else the VDI's own.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["server", "dataset", "store"])]
    pub vdi: Option<PathBuf>,
    /// With `--vdi`: cross the VDI's empty tiles of lists one by one instead of in one step (a
    /// baseline).
    #[arg(long)]
    pub vdi_no_skipping: bool,
    /// With `--vdi`: how rays read the VDI between its lists: `auto` (the default: a single
    /// image is a frame at rest, so `linear`), `nearest` (the paper's: the list whose cell holds
    /// each point, the fastest) or `linear` (the bilinear mix of the four lists around each
    /// point: closer to DVR away from the VDI's camera, several times slower).
    #[arg(long, value_name = "FILTER", value_parser = super::names_parser::<VdiFilterChoice>())]
    pub vdi_filter: Option<VdiFilterChoice>,
    /// With `--vdi --vdi-filter nearest`: sample along the rays, reading about this share `D_R`
    /// of the lists each crosses (the paper's preview sampling, Sec. 4.4: faster, coarser
    /// across the VDI's lists), in [0.01, 1]; 1 (the default) reads every list.
    #[arg(long, value_name = "D_R", value_parser = super::ray_sampling)]
    pub vdi_ray_sampling: Option<f64>,
}

/// Runs `viewer render`.
pub fn run(args: Args) -> Result<()> {
    ImageFormat::of(&args.out)?;
    if let Some(path) = &args.vdi {
        return render_vdi(&args, path);
    }
    // (clap's `requires` does not hold it here: the flag is refused by hand, as `view`'s.)
    anyhow::ensure!(
        !args.vdi_no_skipping,
        "--vdi-no-skipping applies to a VDI only (with --vdi)"
    );
    anyhow::ensure!(
        args.vdi_filter.is_none(),
        "--vdi-filter applies to a VDI only (with --vdi)"
    );
    anyhow::ensure!(
        args.vdi_ray_sampling.is_none(),
        "--vdi-ray-sampling applies to a VDI only (with --vdi)"
    );
    let (source, scene, options) = open_scene(
        &args.source,
        &args.scene,
        &args.renderer,
        args.width,
        args.height,
    )?;
    let budget = args.converge.budget(args.renderer.workers)?;
    let (method, empty_space_skipping) = (options.method, options.empty_space_skipping);
    let start = Instant::now();
    let gpu = Gpu::new()?;
    let result = render_progressive(&gpu, Arc::clone(&source), &scene, options, &budget)?;
    let wall_s = start.elapsed().as_secs_f64();
    let image = RgbImage::from_rgba(result.width, result.height, &result.pixels);
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

/// `viewer render --vdi`: the VDI at `path` ray cast from the scene's camera.
fn render_vdi(args: &Args, path: &std::path::Path) -> Result<()> {
    let (vdi, camera) = args.scene.open_vdi(path)?;
    let start = Instant::now();
    let gpu = Gpu::new()?;
    let mut renderer = VdiRenderer::new(&gpu, &vdi, args.width, args.height)?;
    // A single image is a frame at rest.
    let filter = args.vdi_filter.unwrap_or_default().filter(false);
    if let Some(d_r) = args.vdi_ray_sampling {
        anyhow::ensure!(
            filter == VdiFilter::Nearest,
            "--vdi-ray-sampling samples the nearest filter's lists: add --vdi-filter nearest \
             (this image would be drawn with the {} filter)",
            filter.name()
        );
        renderer.set_ray_sampling(d_r);
    }
    renderer.set_filter(&gpu, filter);
    let frame = renderer.render(&gpu, &camera, !args.vdi_no_skipping)?;
    let image = RgbImage::from_rgba(args.width, args.height, &frame.pixels);
    image.write(&args.out)?;
    tracing::info!(
        "wrote {} ({}×{}) from {} with the {} filter in {:.2} s{}",
        args.out.display(),
        args.width,
        args.height,
        path.display(),
        filter.name(),
        start.elapsed().as_secs_f64(),
        frame
            .gpu_time_ms
            .map(|ms| format!(" ({ms:.3} ms on the GPU)"))
            .unwrap_or_default()
    );
    Ok(())
}
