//! `viewer reference`: the scene's ground truth from the f64 CPU ray caster
//! ([`residency_viewer::reference`]), written as PNG or EXR.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;

use super::scene_args::{SceneArgs, SourceArgs};
use residency_viewer::reference::{self, DEFAULT_STEP_FRACTION, ReferenceOptions};

/// Arguments of `viewer reference`.
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
    pub width: usize,
    /// Image height in pixels.
    #[arg(long, default_value_t = 256)]
    pub height: usize,
    /// Step, as a fraction of the finest level-0 voxel spacing.
    #[arg(long, default_value_t = DEFAULT_STEP_FRACTION)]
    pub step: f64,
    /// Stop a ray once its transmittance falls below this (0: never stop early).
    #[arg(long, default_value_t = 0.0)]
    pub min_transmittance: f64,
    /// Output image: `.png` (8-bit sRGB) or `.exr` (32-bit float linear RGB).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
}

/// Runs `viewer reference`.
pub fn run(args: Args) -> Result<()> {
    // Refuse a bad output name before the render, not after.
    residency_viewer::image::ImageFormat::of(&args.out)?;
    let source = args.source.open()?;
    let scene = args.scene.scene(source.info())?;
    let options = ReferenceOptions {
        width: args.width,
        height: args.height,
        step_fraction: args.step,
        min_transmittance: args.min_transmittance,
    };
    let start = Instant::now();
    let image = reference::render(source.as_ref(), &scene, &options)?;
    image.write(&args.out)?;
    tracing::info!(
        "wrote {} ({}×{}) in {:.2} s",
        args.out.display(),
        args.width,
        args.height,
        start.elapsed().as_secs_f64()
    );
    Ok(())
}
