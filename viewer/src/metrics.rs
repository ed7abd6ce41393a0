//! Image error metrics between two linear-RGB images: PSNR, SSIM, maximum absolute error, and
//! the per-pixel error map.
//!
//! - **PSNR** (dB) over all pixels and the three channels, with a peak of 1 (linear RGB in
//!   `[0, 1]`): `10·log10(1 / MSE)`; `+∞` for identical images.
//! - **SSIM** (Wang et al. 2004) on luminance `Y = 0.2126 R + 0.7152 G + 0.0722 B`, with the
//!   standard 11×11 Gaussian window of σ = 1.5 (normalised), `C1 = (0.01·L)²`,
//!   `C2 = (0.03·L)²`, `L = 1`, averaged over every position where the window fits inside
//!   the image (images must be at least 11×11).
//! - **Max abs error**: the largest `|a − b|` over pixels and channels.

use schemars::JsonSchema;
use serde::Serialize;

use crate::image::RgbImage;

/// Edge of the SSIM window.
pub const SSIM_WINDOW: usize = 11;
/// Standard deviation of the SSIM Gaussian window, pixels.
pub const SSIM_SIGMA: f64 = 1.5;
/// SSIM constant `K1`.
pub const SSIM_K1: f64 = 0.01;
/// SSIM constant `K2`.
pub const SSIM_K2: f64 = 0.03;

/// Why two images cannot be compared: different sizes, a non-finite pixel, or images smaller
/// than the SSIM window.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MetricsError {
    /// Images of different sizes.
    #[error(
        "images differ in size: {}×{} and {}×{}",
        first[0], first[1], second[0], second[1]
    )]
    SizeMismatch {
        /// The first image's width and height.
        first: [usize; 2],
        /// The second image's width and height.
        second: [usize; 2],
    },
    /// A NaN or infinite pixel (its error would be NaN).
    #[error(
        "the {which} image has a non-finite pixel {pixel:?} at ({x}, {y}); metrics need finite \
         images"
    )]
    NonFinite {
        /// `first` or `second`.
        which: &'static str,
        /// The pixel.
        pixel: [f32; 3],
        /// Its column.
        x: usize,
        /// Its row.
        y: usize,
    },
    /// Images smaller than the SSIM window.
    #[error(
        "images of {width}×{height} are smaller than the {}×{} SSIM window",
        SSIM_WINDOW,
        SSIM_WINDOW
    )]
    TooSmall {
        /// Width.
        width: usize,
        /// Height.
        height: usize,
    },
}

/// The metrics of one comparison.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, JsonSchema)]
#[schemars(title = "Image comparison", deny_unknown_fields)]
pub struct Metrics {
    /// Peak signal-to-noise ratio in dB (`+∞` for identical images; `null` in JSON).
    #[schemars(with = "Option<f64>")]
    pub psnr_db: f64,
    /// Mean structural similarity on luminance, in `[-1, 1]`.
    #[schemars(range(max = 1))]
    pub ssim: f64,
    /// Largest absolute difference over pixels and channels.
    #[schemars(range(min = 0))]
    pub max_abs_error: f64,
    /// Mean squared error over pixels and channels.
    #[schemars(range(min = 0))]
    pub mse: f64,
}

/// Refuses images holding NaN or infinite values: their errors would be NaN, which PSNR would
/// turn into `null` (read as "identical") and the maximum would skip.
fn check_finite(a: &RgbImage, b: &RgbImage) -> Result<(), MetricsError> {
    for (which, img) in [("first", a), ("second", b)] {
        if let Some(i) = img
            .pixels
            .iter()
            .position(|p| p.iter().any(|v| !v.is_finite()))
        {
            return Err(MetricsError::NonFinite {
                which,
                pixel: img.pixels[i],
                x: i % img.width.max(1),
                y: i / img.width.max(1),
            });
        }
    }
    Ok(())
}

fn check_sizes(a: &RgbImage, b: &RgbImage) -> Result<(), MetricsError> {
    if a.width == b.width && a.height == b.height {
        Ok(())
    } else {
        Err(MetricsError::SizeMismatch {
            first: [a.width, a.height],
            second: [b.width, b.height],
        })
    }
}

/// Compares `a` with `b` (same size, at least 11×11).
///
/// # Errors
/// [`MetricsError::SizeMismatch`], [`MetricsError::NonFinite`] or
/// [`MetricsError::TooSmall`].
pub fn compare(a: &RgbImage, b: &RgbImage) -> Result<Metrics, MetricsError> {
    check_sizes(a, b)?;
    check_finite(a, b)?;
    let mut sum_sq = 0.0;
    let mut max = 0.0f64;
    for (p, q) in a.pixels.iter().zip(&b.pixels) {
        for i in 0..3 {
            let d = (p[i] as f64 - q[i] as f64).abs();
            sum_sq += d * d;
            max = max.max(d);
        }
    }
    let mse = sum_sq / (3 * a.pixels.len()).max(1) as f64;
    let psnr_db = if mse == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (1.0 / mse).log10()
    };
    Ok(Metrics {
        psnr_db,
        ssim: ssim(a, b)?,
        max_abs_error: max,
        mse,
    })
}

/// Luminance of a linear-RGB pixel.
pub fn luminance(p: [f32; 3]) -> f64 {
    0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64
}

/// The normalised 1-D Gaussian of the SSIM window (the 2-D window is its outer product).
pub fn gaussian_window() -> [f64; SSIM_WINDOW] {
    let r = (SSIM_WINDOW / 2) as f64;
    let mut w: [f64; SSIM_WINDOW] = std::array::from_fn(|i| {
        (-((i as f64 - r).powi(2)) / (2.0 * SSIM_SIGMA * SSIM_SIGMA)).exp()
    });
    let sum: f64 = w.iter().sum();
    for v in &mut w {
        *v /= sum;
    }
    w
}

/// Mean SSIM of the luminance of `a` and `b` over every window position.
///
/// # Errors
/// [`MetricsError::SizeMismatch`] or [`MetricsError::TooSmall`] (images smaller than the
/// SSIM window).
pub fn ssim(a: &RgbImage, b: &RgbImage) -> Result<f64, MetricsError> {
    check_sizes(a, b)?;
    if a.width < SSIM_WINDOW || a.height < SSIM_WINDOW {
        return Err(MetricsError::TooSmall {
            width: a.width,
            height: a.height,
        });
    }
    let (w, h) = (a.width, a.height);
    let x: Vec<f64> = a.pixels.iter().map(|&p| luminance(p)).collect();
    let y: Vec<f64> = b.pixels.iter().map(|&p| luminance(p)).collect();
    let g = gaussian_window();
    let (c1, c2) = (SSIM_K1 * SSIM_K1, SSIM_K2 * SSIM_K2);
    let (ow, oh) = (w - SSIM_WINDOW + 1, h - SSIM_WINDOW + 1);
    let mut total = 0.0;
    for oy in 0..oh {
        for ox in 0..ow {
            let (mut mx, mut my, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for (j, gj) in g.iter().enumerate() {
                for (i, gi) in g.iter().enumerate() {
                    let k = (oy + j) * w + ox + i;
                    let wt = gj * gi;
                    mx += wt * x[k];
                    my += wt * y[k];
                    sxx += wt * x[k] * x[k];
                    syy += wt * y[k] * y[k];
                    sxy += wt * x[k] * y[k];
                }
            }
            let vx = sxx - mx * mx;
            let vy = syy - my * my;
            let cov = sxy - mx * my;
            total += (2.0 * (mx * my) + c1) * (2.0 * cov + c2)
                / ((mx * mx + my * my + c1) * (vx + vy + c2));
        }
    }
    Ok(total / (ow * oh) as f64)
}

/// The per-pixel, per-channel absolute difference `|a − b|`.
///
/// # Errors
/// [`MetricsError::SizeMismatch`].
pub fn error_map(a: &RgbImage, b: &RgbImage) -> Result<RgbImage, MetricsError> {
    check_sizes(a, b)?;
    Ok(RgbImage {
        width: a.width,
        height: a.height,
        pixels: a
            .pixels
            .iter()
            .zip(&b.pixels)
            .map(|(p, q)| std::array::from_fn(|i| (p[i] - q[i]).abs()))
            .collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_pixels_are_refused_not_averaged_away() {
        let a = RgbImage::filled(12, 12, [0.5; 3]);
        let mut b = a.clone();
        b.pixels[12 * 3 + 5] = [0.5, f32::NAN, 0.5];
        let e = compare(&a, &b).unwrap_err();
        assert_eq!(
            e.to_string(),
            "the second image has a non-finite pixel [0.5, NaN, 0.5] at (5, 3); metrics need finite images"
        );
        b.pixels[12 * 3 + 5] = [0.5; 3];
        b.pixels[0] = [f32::INFINITY, 0.0, 0.0];
        assert!(
            compare(&b, &a)
                .unwrap_err()
                .to_string()
                .starts_with("the first image")
        );
    }

    #[test]
    fn identical_images_are_perfect() {
        let mut a = RgbImage::filled(16, 12, [0.2, 0.4, 0.6]);
        a.pixels[37] = [0.9, 0.0, 0.1];
        let m = compare(&a, &a).unwrap();
        assert_eq!(m.psnr_db, f64::INFINITY);
        assert_eq!(m.ssim, 1.0);
        assert_eq!(m.max_abs_error, 0.0);
        assert_eq!(m.mse, 0.0);
        assert!(
            error_map(&a, &a)
                .unwrap()
                .pixels
                .iter()
                .all(|p| *p == [0.0; 3])
        );
    }

    #[test]
    fn constant_offset_gives_known_values() {
        let a = RgbImage::filled(11, 11, [0.25; 3]);
        let b = RgbImage::filled(11, 11, [0.5; 3]);
        let m = compare(&a, &b).unwrap();
        assert_eq!(m.mse, 0.0625);
        assert_eq!(m.max_abs_error, 0.25);
        // 10·log10(1 / 0.0625) = 10·log10(16)
        assert!(
            (m.psnr_db - 12.041_199_826_559_248).abs() < 1e-12,
            "{}",
            m.psnr_db
        );
        // Flat images: no variance, so SSIM is the luminance term alone.
        let (x, y) = (luminance([0.25; 3]), luminance([0.5; 3]));
        let expected = (2.0 * x * y + 1e-4) / (x * x + y * y + 1e-4);
        assert!((m.ssim - expected).abs() < 1e-12);
        assert!((m.ssim - 0.2501 / 0.3126).abs() < 1e-9);
        assert_eq!(error_map(&a, &b).unwrap().pixels[0], [0.25; 3]);
    }

    #[test]
    fn one_changed_pixel() {
        let a = RgbImage::filled(20, 20, [0.0; 3]);
        let mut b = a.clone();
        b.pixels[0] = [1.0, 0.0, 0.0];
        let m = compare(&a, &b).unwrap();
        assert_eq!(m.mse, 1.0 / 1200.0);
        assert!((m.psnr_db - 10.0 * 1200f64.log10()).abs() < 1e-12);
        assert_eq!(m.max_abs_error, 1.0);
        assert!(m.ssim < 1.0 && m.ssim > 0.9, "{}", m.ssim);
    }

    #[test]
    fn window_is_a_normalised_gaussian_and_bad_sizes_are_refused() {
        let g = gaussian_window();
        assert!((g.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        assert_eq!(g[0], g[10]);
        assert!((g[5] / g[4] - (1.0 / 4.5f64).exp()).abs() < 1e-12);
        let small = RgbImage::filled(10, 20, [0.0; 3]);
        assert_eq!(
            compare(&small, &small).unwrap_err().to_string(),
            "images of 10×20 are smaller than the 11×11 SSIM window"
        );
        let other = RgbImage::filled(20, 10, [0.0; 3]);
        assert_eq!(
            compare(&small, &other).unwrap_err().to_string(),
            "images differ in size: 10×20 and 20×10"
        );
    }
}
