//! `viewer compare A B`: PSNR, SSIM and max abs error between two images (PNG or EXR), and
//! optionally an EXR map of the per-pixel absolute difference.

use std::path::PathBuf;

use anyhow::{Context, Result};

use residency_viewer::image::RgbImage;
use residency_viewer::metrics::{self, Metrics};

/// Arguments of `viewer compare`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// First image (`.png` or `.exr`), usually the render.
    pub a: PathBuf,
    /// Second image (`.png` or `.exr`), usually the reference.
    pub b: PathBuf,
    /// Write the per-pixel absolute difference here (`.exr`, or `.png`).
    #[arg(long, value_name = "FILE")]
    pub error_map: Option<PathBuf>,
    /// Print the metrics as JSON (`psnr_db` is `null` for identical images).
    #[arg(long)]
    pub json: bool,
}

/// Reads both images and compares them.
pub fn compare_files(args: &Args) -> Result<(Metrics, RgbImage, RgbImage)> {
    let a = RgbImage::read(&args.a)?;
    let b = RgbImage::read(&args.b)?;
    let m = metrics::compare(&a, &b)
        .with_context(|| format!("{} vs {}", args.a.display(), args.b.display()))?;
    Ok((m, a, b))
}

/// Runs `viewer compare`.
pub fn run(args: Args) -> Result<()> {
    let (m, a, b) = compare_files(&args)?;
    if let Some(path) = &args.error_map {
        metrics::error_map(&a, &b)?.write(path)?;
    }
    if args.json {
        super::report(format_args!("{}\n", serde_json::to_string_pretty(&m)?))?;
    } else {
        super::report(format_args!(
            "PSNR {:.3} dB\nSSIM {:.6}\nmax abs error {:.6}\n",
            m.psnr_db, m.ssim, m.max_abs_error
        ))?;
    }
    Ok(())
}
