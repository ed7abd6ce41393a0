//! `viewer view`: the interactive window ([`crate::interactive`]).

use std::sync::Arc;
use std::time::Duration;

use anyhow::{Result, ensure};

use super::scene_args::{SceneArgs, SourceArgs};
use crate::gpu::device::Gpu;
use crate::gpu::renderer::RenderOptions;
use crate::interactive::session::Session;
use crate::interactive::window::{self, ViewConfig};
use crate::source::BrickSource;

/// The mouse and key controls, shown by `viewer view --help`.
pub const CONTROLS: &str = "\
Mouse:
  left drag                     orbit about the target
  right or middle drag,
  shift + left drag             pan
  wheel                         zoom (4 steps halve or double the distance)
  ctrl + left drag              window/level of the selected channel's opacity ramp:
                                right/left widens/narrows it, down/up moves it to
                                higher/lower values (applied on release)
Keys:
  1 .. 9                        show/hide channel 0 .. 8 (and select it)
  Tab, shift + Tab              select the next/previous channel
  c                             cycle the selected channel's colour through the palette
                                (cyan, magenta, yellow, green, red, blue, white)
  [  ]                          move the selected ramp's low end down/up
  {  }                          move the selected ramp's high end down/up
                                (by 5% of the channel's default ramp width)
  r                             reset the camera
  h                             hide/show the statistics panel
  q, Esc                        quit
The panel and the window title show the frame number, samples, bricks requested, fetched
and substituted, bytes fetched and the GPU time of the last frame. A change of channel
styles or window size restarts streaming (the renderer is rebuilt); camera changes reuse
the bricks already resident.";

/// Arguments of `viewer view`.
#[derive(clap::Args, Debug)]
#[command(after_help = CONTROLS)]
pub struct Args {
    /// Where the volume comes from.
    #[command(flatten)]
    pub source: SourceArgs,
    /// What to draw first.
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Initial window width in pixels.
    #[arg(long, default_value_t = 640)]
    pub width: u32,
    /// Initial window height in pixels.
    #[arg(long, default_value_t = 480)]
    pub height: u32,
    /// Rendered image size relative to the window (below 1 renders faster, scaled up).
    #[arg(long, default_value_t = 1.0)]
    pub render_scale: f64,
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
    /// For tests and demos: once the view settles (converged, or N frames shown since the
    /// last input), print a summary line on standard output, and quit if no input comes
    /// within `--exit-delay-ms` (input starts over).
    #[arg(long, value_name = "N")]
    pub exit_after_frames: Option<u64>,
    /// With `--exit-after-frames`: how long the settled window waits for input before
    /// quitting.
    #[arg(long, value_name = "MS", default_value_t = 0)]
    pub exit_delay_ms: u64,
}

/// Runs `viewer view`.
pub fn run(args: Args) -> Result<()> {
    ensure!(
        args.step > 0.0 && args.step.is_finite(),
        "--step {} must be positive",
        args.step
    );
    ensure!(
        args.render_scale > 0.0 && args.render_scale <= 4.0,
        "--render-scale {} must lie in (0, 4]",
        args.render_scale
    );
    ensure!(
        args.width > 0 && args.height > 0,
        "the window size {}×{} is empty",
        args.width,
        args.height
    );
    let source: Arc<dyn BrickSource> = Arc::from(args.source.open()?);
    let info = source.info().clone();
    let scene = args.scene.scene(&info)?;
    let levels = info.levels.len() as u32;
    let max_level = args.max_level.unwrap_or(levels - 1).min(levels - 1);
    ensure!(
        args.min_level <= max_level,
        "--min-level {} is coarser than --max-level {max_level}",
        args.min_level
    );
    let options = RenderOptions {
        width: args.width,
        height: args.height,
        cache_bytes: args.cache_bytes,
        lod_bias: args.lod_bias,
        step_factor: args.step,
        octree_depth: args.octree_depth,
        level_bounds: vec![(args.min_level, max_level)],
        empty_space_skipping: !args.no_skipping,
        ..Default::default()
    };
    let gpu = Gpu::new()?;
    tracing::info!(
        "{}: {} channels, GPU {} ({:?})",
        info.name,
        info.channels.len(),
        gpu.adapter_info.name,
        gpu.adapter_info.backend
    );
    let session = Session::new(gpu, source, scene, options, args.workers, 16);
    window::run(
        session,
        ViewConfig {
            window_size: (args.width, args.height),
            render_scale: args.render_scale,
            exit_after_frames: args.exit_after_frames,
            exit_delay: Duration::from_millis(args.exit_delay_ms),
        },
    )
}
