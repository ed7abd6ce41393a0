//! Linear-RGB `f32` images, as the renderers produce them and `viewer compare` reads them,
//! written and read as PNG (8-bit sRGB) or OpenEXR (32-bit float, linear) by file extension.

use std::path::{Path, PathBuf};

/// Why an image cannot be written or read: a file name of no known format, pixels that do
/// not fill the image, or the PNG or OpenEXR encoder's or decoder's error. Messages name the
/// file.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    /// A file name other than `.png` or `.exr`.
    #[error("{}: unknown image format (use a .png or .exr file name)", path.display())]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// An image whose pixels do not fill its size.
    #[error("{}: image has {pixels} pixels for {width}×{height}", path.display())]
    PixelCount {
        /// The file.
        path: PathBuf,
        /// Pixels held.
        pixels: usize,
        /// Width.
        width: usize,
        /// Height.
        height: usize,
    },
    /// A PNG that cannot be written.
    #[error("{}: cannot write PNG", path.display())]
    WritePng {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: ::image::ImageError,
    },
    /// An OpenEXR file that cannot be written.
    #[error("{}: cannot write OpenEXR", path.display())]
    WriteExr {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: exr::error::Error,
    },
    /// A PNG that cannot be read.
    #[error("{}: cannot read PNG", path.display())]
    ReadPng {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: ::image::ImageError,
    },
    /// An OpenEXR file that cannot be read as RGB.
    #[error("{}: cannot read OpenEXR RGB", path.display())]
    ReadExr {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: exr::error::Error,
    },
}

/// A linear-RGB image, rows top to bottom, pixels left to right.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbImage {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width · height` pixels, row-major from the top-left.
    pub pixels: Vec<[f32; 3]>,
}

impl RgbImage {
    /// The RGB of `width × height` linear RGBA pixels (a frame as the renderers read it back;
    /// alpha dropped: the background is composited already).
    pub fn from_rgba(width: u32, height: u32, pixels: &[[f32; 4]]) -> Self {
        Self {
            width: width as usize,
            height: height as usize,
            pixels: pixels.iter().map(|p| [p[0], p[1], p[2]]).collect(),
        }
    }
}

/// File formats of [`RgbImage::write`] and [`RgbImage::read`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageFormat {
    /// PNG, 8-bit sRGB (linear values clamped to `[0, 1]` and encoded).
    Png,
    /// OpenEXR, 32-bit float linear RGB.
    Exr,
}

impl ImageFormat {
    /// The format named by `path`'s extension (`.png` or `.exr`, any case).
    ///
    /// # Errors
    /// [`ImageError::UnknownFormat`] for any other name.
    pub fn of(path: &Path) -> Result<Self, ImageError> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        match ext.as_deref() {
            Some("png") => Ok(Self::Png),
            Some("exr") => Ok(Self::Exr),
            _ => Err(ImageError::UnknownFormat {
                path: path.to_path_buf(),
            }),
        }
    }
}

/// Linear light in `[0, 1]` to the sRGB encoding.
pub fn linear_to_srgb(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Linear light to an 8-bit sRGB value, rounded to nearest (PNG's encoding).
pub fn linear_to_srgb8(v: f32) -> u8 {
    (linear_to_srgb(v) * 255.0).round() as u8
}

/// The sRGB encoding in `[0, 1]` to linear light.
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

impl RgbImage {
    /// An image of one colour.
    pub fn filled(width: usize, height: usize, colour: [f32; 3]) -> Self {
        Self {
            width,
            height,
            pixels: vec![colour; width * height],
        }
    }

    /// Pixel `(x, y)`.
    pub fn get(&self, x: usize, y: usize) -> [f32; 3] {
        self.pixels[y * self.width + x]
    }

    /// Writes the image, in the format of `path`'s extension.
    ///
    /// # Errors
    /// An [`ImageError`] naming `path`: an unknown format, pixels that do not fill the image,
    /// or the encoder's error.
    pub fn write(&self, path: &Path) -> Result<(), ImageError> {
        if self.pixels.len() != self.width * self.height {
            return Err(ImageError::PixelCount {
                path: path.to_path_buf(),
                pixels: self.pixels.len(),
                width: self.width,
                height: self.height,
            });
        }
        match ImageFormat::of(path)? {
            ImageFormat::Png => {
                let bytes: Vec<u8> = self
                    .pixels
                    .iter()
                    .flat_map(|p| p.map(linear_to_srgb8))
                    .collect();
                image::save_buffer_with_format(
                    path,
                    &bytes,
                    self.width as u32,
                    self.height as u32,
                    image::ColorType::Rgb8,
                    image::ImageFormat::Png,
                )
                .map_err(|source| ImageError::WritePng {
                    path: path.to_path_buf(),
                    source,
                })
            }
            ImageFormat::Exr => {
                exr::prelude::write_rgb_file(path, self.width, self.height, |x, y| {
                    let p = self.get(x, y);
                    (p[0], p[1], p[2])
                })
                .map_err(|source| ImageError::WriteExr {
                    path: path.to_path_buf(),
                    source,
                })
            }
        }
    }

    /// Reads an image written by [`RgbImage::write`] (or any 8/16-bit PNG, taken as sRGB, or
    /// OpenEXR with RGB channels, taken as linear).
    ///
    /// # Errors
    /// An [`ImageError`] naming `path`: an unknown format, or the decoder's error.
    pub fn read(path: &Path) -> Result<Self, ImageError> {
        match ImageFormat::of(path)? {
            ImageFormat::Png => {
                let img = image::open(path).map_err(|source| ImageError::ReadPng {
                    path: path.to_path_buf(),
                    source,
                })?;
                let rgb = img.to_rgb32f();
                Ok(Self {
                    width: rgb.width() as usize,
                    height: rgb.height() as usize,
                    pixels: rgb
                        .pixels()
                        .map(|p| [0, 1, 2].map(|i| srgb_to_linear(p.0[i])))
                        .collect(),
                })
            }
            ImageFormat::Exr => {
                let image = exr::prelude::read_first_rgba_layer_from_file(
                    path,
                    |size, _| Self::filled(size.width(), size.height(), [0.0; 3]),
                    |img: &mut Self, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                        let w = img.width;
                        img.pixels[pos.y() * w + pos.x()] = [r, g, b];
                    },
                )
                .map_err(|source| ImageError::ReadExr {
                    path: path.to_path_buf(),
                    source,
                })?;
                Ok(image.layer_data.channel_data.pixels)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gradient() -> RgbImage {
        let (w, h) = (5, 3);
        RgbImage {
            width: w,
            height: h,
            pixels: (0..w * h)
                .map(|i| [i as f32 / 14.0, 0.25, 1.0 - i as f32 / 14.0])
                .collect(),
        }
    }

    #[test]
    fn exr_round_trips_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.exr");
        let mut img = gradient();
        img.pixels[3] = [2.5, -0.125, 1e-7];
        img.write(&path).unwrap();
        assert_eq!(RgbImage::read(&path).unwrap(), img);
    }

    #[test]
    fn png_round_trips_within_8_bit_srgb() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.PNG");
        let img = gradient();
        img.write(&path).unwrap();
        let back = RgbImage::read(&path).unwrap();
        assert_eq!((back.width, back.height), (5, 3));
        for (a, b) in img.pixels.iter().zip(&back.pixels) {
            for i in 0..3 {
                // Half an 8-bit step of the sRGB encoding, in the encoded domain.
                let d = (linear_to_srgb(a[i]) - linear_to_srgb(b[i])).abs();
                assert!(d <= 0.5 / 255.0 + 1e-6, "{a:?} vs {b:?}");
            }
        }
        assert_eq!(back.get(0, 0)[0], 0.0);
        assert_eq!(back.get(4, 2)[0], 1.0);
    }

    #[test]
    fn srgb_round_trips_and_bad_names_are_refused() {
        for v in [0.0, 0.001, 0.2, 0.5, 1.0] {
            assert!((srgb_to_linear(linear_to_srgb(v)) - v).abs() < 1e-6);
        }
        assert!((linear_to_srgb(0.5) - 0.735_357).abs() < 1e-6);
        let e = gradient().write(Path::new("out.tiff")).unwrap_err();
        assert_eq!(
            e.to_string(),
            "out.tiff: unknown image format (use a .png or .exr file name)"
        );
        let e = RgbImage::read(Path::new("/nonexistent/x.exr")).unwrap_err();
        let e = crate::error_chain(&e);
        assert!(
            e.starts_with("/nonexistent/x.exr: cannot read OpenEXR RGB: "),
            "{e}"
        );
    }
}
