//! `viewer view`: the interactive window ([`residency_viewer::interactive`]), of a volume or,
//! with `--vdi`, of a volumetric depth image.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Result, bail, ensure};

use super::renderer_args::{RendererArgs, open_scene};
use super::scene_args::{SceneArgs, SourceArgs};
use residency_viewer::gpu::device::Gpu;
use residency_viewer::interactive::display::PresentPath;
use residency_viewer::interactive::session::Session;
use residency_viewer::interactive::vdi_window::{self, VdiViewConfig};
use residency_viewer::interactive::window::{self, ViewConfig};
use residency_viewer::vdi_filter_choice::VdiFilterChoice;

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
  m                             switch the mode: dvr, mip, iso (rebuilds the renderer)
  r                             reset the camera
  h                             hide/show the statistics panel and the orientation
  q, Esc                        quit
The panel and the window title show the frame number, samples, bricks requested, fetched
and substituted, bytes fetched and the GPU time of the last frame. Along the bottom: a
scale bar of a round length in the store's unit, and the x (red), y (green) and z (blue)
axes as the camera sees them. A change of channel
styles or window size restarts streaming (the renderer is rebuilt); camera changes reuse
the bricks already resident.
With --vdi: orbit, pan, zoom, r, h, q and Esc as above (the VDI's colours are fixed); the
panel shows D_I, the rays cast and the frame time.";

/// The frame rate `view --vdi` holds while the camera moves, unless `--target-fps` says.
const DEFAULT_TARGET_FPS: f64 = 60.0;

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
    /// How frames reach the window: `gpu` (a surface, presented with no readback), `cpu` (each
    /// frame read back and blitted, as under an X server the GPU cannot present to), or
    /// `auto` (the GPU where a surface can be made, else the CPU).
    #[arg(long, value_name = "PATH", default_value_t = PresentPath::Auto)]
    pub present: PresentPath,
    /// Show this volumetric depth image (`viewer vdi`) instead of a volume, ray cast on the
    /// GPU for the window's camera: first the scene's (`--scene`, `--camera`, `--fov`), else
    /// the VDI's own.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["server", "dataset", "store"])]
    pub vdi: Option<PathBuf>,
    /// With `--vdi`: the frame rate to hold while the camera moves, by rendering a fraction
    /// `D_I` of the rays (at least a quarter of each side) and upsampling; at rest, full
    /// resolution. Default: 60.
    #[arg(long, value_name = "FPS")]
    pub target_fps: Option<f64>,
    /// With `--vdi`: cross the VDI's empty tiles of lists one by one (a baseline).
    #[arg(long)]
    pub vdi_no_skipping: bool,
    /// With `--vdi`: how rays read the VDI between its lists: `auto` (the default: `linear`
    /// once the camera rests, and while it moves where the last linear frame held the target
    /// frame rate, else `nearest`), `nearest` (the paper's: the list whose
    /// cell holds each point, the fastest) or `linear` (the bilinear mix of the four lists
    /// around each point: closer to DVR away from the VDI's camera, several times slower).
    #[arg(long, value_name = "FILTER", value_parser = super::names_parser::<VdiFilterChoice>())]
    pub vdi_filter: Option<VdiFilterChoice>,
    /// With `--vdi`: sample along the rays of the frames drawn while the camera moves at a
    /// reduced `D_I` (the nearest filter's), reading about this share `D_R` of the lists each
    /// crosses (the paper's preview sampling, Sec. 4.4), in [0.01, 1]. Default: 1, every list.
    #[arg(long, value_name = "D_R", value_parser = super::ray_sampling)]
    pub vdi_ray_sampling: Option<f64>,
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
    if let Some(path) = &args.vdi {
        return view_vdi(&args, path);
    }
    let vdi_only = [
        (args.target_fps.is_some(), "--target-fps"),
        (args.vdi_no_skipping, "--vdi-no-skipping"),
        (args.vdi_filter.is_some(), "--vdi-filter"),
        (args.vdi_ray_sampling.is_some(), "--vdi-ray-sampling"),
    ];
    if let Some((_, flag)) = vdi_only.iter().find(|(given, _)| *given) {
        bail!("{flag} applies to a VDI only (with --vdi)");
    }
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
            present: args.present,
        },
    )?;
    Ok(())
}

/// `viewer view --vdi`: the VDI at `path` in a window.
fn view_vdi(args: &Args, path: &Path) -> Result<()> {
    let fps = args.target_fps.unwrap_or(DEFAULT_TARGET_FPS);
    ensure!(
        fps > 0.0 && fps.is_finite(),
        "--target-fps {fps} must be positive"
    );
    let (vdi, camera) = args.scene.open_vdi(path)?;
    let h = &vdi.header;
    let gpu = Gpu::new()?;
    let name = path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into(),
    );
    tracing::info!(
        "{name}: {}×{} lists of {} supersegments, GPU {} ({:?})",
        h.width,
        h.height,
        h.supersegments,
        gpu.adapter_info.name,
        gpu.adapter_info.backend
    );
    vdi_window::run(
        gpu,
        vdi,
        name,
        camera,
        VdiViewConfig {
            window_size: (args.width, args.height),
            render_scale: args.render_scale,
            target_ms: 1000.0 / fps,
            skipping: !args.vdi_no_skipping,
            filter: args.vdi_filter.unwrap_or_default(),
            ray_sampling: args.vdi_ray_sampling.unwrap_or(1.0),
            exit_after_frames: args.exit_after_frames,
            exit_delay: Duration::from_millis(args.exit_delay_ms),
            present: args.present,
        },
    )?;
    Ok(())
}
