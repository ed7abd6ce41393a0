//! `viewer view`: the interactive window ([`residency_viewer::interactive`]).

use std::time::Duration;

use anyhow::{Result, ensure};

use super::renderer_args::{RendererArgs, open_scene};
use super::scene_args::{SceneArgs, SourceArgs};
use residency_viewer::gpu::device::Gpu;
use residency_viewer::interactive::session::Session;
use residency_viewer::interactive::window::{self, ViewConfig};

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
  f                             switch the filter: trilinear, tricubic (rebuilds the renderer)
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
    /// Renderer settings.
    #[command(flatten)]
    pub renderer: RendererArgs,
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
    let (source, scene, options) = open_scene(
        &args.source,
        &args.scene,
        &args.renderer,
        args.width,
        args.height,
    )?;
    let info = source.info();
    let gpu = Gpu::new()?;
    tracing::info!(
        "{}: {} channels, GPU {} ({:?})",
        info.name,
        info.channels.len(),
        gpu.adapter_info.name,
        gpu.adapter_info.backend
    );
    let session = Session::new(gpu, source, scene, options, args.renderer.workers, 16);
    window::run(
        session,
        ViewConfig {
            window_size: (args.width, args.height),
            render_scale: args.render_scale,
            exit_after_frames: args.exit_after_frames,
            exit_delay: Duration::from_millis(args.exit_delay_ms),
        },
    )?;
    Ok(())
}
