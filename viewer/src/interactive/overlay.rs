//! Putting a rendered frame on screen: linear RGB to 8-bit sRGB (`0x00RRGGBB` pixels, as
//! `softbuffer` takes them), nearest-neighbour scaling to the window, and a statistics panel
//! drawn with the `font8x8` bitmap font over a darkened backdrop.

use font8x8::UnicodeFonts;

use crate::gpu::present::{SRGB_TABLE_ENTRIES as TABLE, srgb_table};

/// Linear light to 8-bit sRGB through a table (4096 entries: under one 8-bit step of error),
/// the one the GPU's present pass uses too ([`srgb_table`]).
pub struct SrgbTable(Vec<u8>);

impl Default for SrgbTable {
    fn default() -> Self {
        Self(srgb_table())
    }
}

impl SrgbTable {
    /// The 8-bit sRGB code of linear value `v` (clamped to `[0, 1]`; NaN is 0).
    pub fn encode(&self, v: f32) -> u8 {
        let i = (v.clamp(0.0, 1.0) * (TABLE - 1) as f32 + 0.5) as usize;
        self.0[i.min(TABLE - 1)]
    }

    /// A linear RGB(A) pixel as `0x00RRGGBB`.
    pub fn pixel(&self, p: &[f32; 4]) -> u32 {
        let [r, g, b] = [0, 1, 2].map(|i| self.encode(p[i]) as u32);
        (r << 16) | (g << 8) | b
    }
}

/// A `0x00RRGGBB` pixel buffer, row-major from the top.
pub struct Canvas<'a> {
    /// Pixels.
    pub pixels: &'a mut [u32],
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
}

/// Height in pixels of one text line at scale 1 (8-pixel glyphs and 2 pixels of leading).
pub const LINE_HEIGHT: usize = 10;

impl Canvas<'_> {
    /// Fills the canvas with `image` (`iw × ih` linear RGBA), scaled to fit by nearest
    /// neighbour.
    pub fn blit(&mut self, image: &[[f32; 4]], iw: usize, ih: usize, srgb: &SrgbTable) {
        if iw == 0 || ih == 0 || image.len() < iw * ih {
            self.pixels.fill(0);
            return;
        }
        let cols: Vec<usize> = (0..self.width)
            .map(|x| (x * iw / self.width.max(1)).min(iw - 1))
            .collect();
        for y in 0..self.height {
            let sy = (y * ih / self.height.max(1)).min(ih - 1);
            let src = &image[sy * iw..(sy + 1) * iw];
            let dst = &mut self.pixels[y * self.width..(y + 1) * self.width];
            for (d, &sx) in dst.iter_mut().zip(&cols) {
                *d = srgb.pixel(&src[sx]);
            }
        }
    }

    /// Darkens the rectangle `(x, y, w, h)` (clipped) to a quarter of its brightness.
    pub fn shade(&mut self, x: usize, y: usize, w: usize, h: usize) {
        for row in y..(y + h).min(self.height) {
            for col in x..(x + w).min(self.width) {
                let p = &mut self.pixels[row * self.width + col];
                *p = (*p >> 2) & 0x003f_3f3f;
            }
        }
    }

    /// Draws `text` with its top-left corner at `(x, y)`, glyphs `8·scale` pixels square, in
    /// colour `rgb` (`0x00RRGGBB`); clipped to the canvas. Characters the font lacks are
    /// drawn as `?`.
    pub fn text(&mut self, x: usize, y: usize, text: &str, rgb: u32, scale: usize) {
        let scale = scale.max(1);
        for (i, ch) in text.chars().enumerate() {
            let glyph = font8x8::BASIC_FONTS
                .get(ch)
                .or_else(|| font8x8::LATIN_FONTS.get(ch))
                .or_else(|| font8x8::BASIC_FONTS.get('?'))
                .unwrap_or([0; 8]);
            let gx = x + i * 8 * scale;
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..8 {
                    if bits & (1 << col) == 0 {
                        continue;
                    }
                    for dy in 0..scale {
                        for dx in 0..scale {
                            let (px, py) = (gx + col * scale + dx, y + row * scale + dy);
                            if px < self.width && py < self.height {
                                self.pixels[py * self.width + px] = rgb;
                            }
                        }
                    }
                }
            }
        }
    }

    /// Draws `lines` (text and colour) in a shaded panel at the top-left corner.
    pub fn panel(&mut self, lines: &[(String, u32)], scale: usize) {
        let (w, h) = panel_size(lines, scale);
        self.shade(0, 0, w, h);
        self.panel_text(lines, scale);
    }

    /// The text of [`Canvas::panel`], without the shading.
    fn panel_text(&mut self, lines: &[(String, u32)], scale: usize) {
        let scale = scale.max(1);
        let margin = 4 * scale;
        for (i, (t, rgb)) in lines.iter().enumerate() {
            self.text(margin, margin + i * LINE_HEIGHT * scale, t, *rgb, scale);
        }
    }
}

/// The size in pixels of the panel [`Canvas::panel`] draws for `lines` at `scale`.
pub fn panel_size(lines: &[(String, u32)], scale: usize) -> (usize, usize) {
    let scale = scale.max(1);
    let margin = 4 * scale;
    let chars = lines
        .iter()
        .map(|(t, _)| t.chars().count())
        .max()
        .unwrap_or(0);
    let w = chars * 8 * scale + 2 * margin;
    let h = lines.len() * LINE_HEIGHT * scale + 2 * margin - 2 * scale;
    (w, h)
}

/// The panel [`Canvas::panel`] draws, as the GPU's present pass takes it
/// ([`crate::gpu::present::Presenter::set_panel`]): `(width, height, RGBA bytes)`, the text
/// pixels in their colour with alpha 255, the shaded rest all 0.
pub fn panel_rgba(lines: &[(String, u32)], scale: usize) -> (u32, u32, Vec<u8>) {
    /// A value no text colour (`0x00RRGGBB`) has.
    const SHADED: u32 = 0xff00_0000;
    let (w, h) = panel_size(lines, scale);
    let mut pixels = vec![SHADED; w * h];
    Canvas {
        pixels: &mut pixels,
        width: w,
        height: h,
    }
    .panel_text(lines, scale);
    let rgba = pixels
        .iter()
        .flat_map(|&p| match p {
            SHADED => [0; 4],
            p => [(p >> 16) as u8, (p >> 8) as u8, p as u8, 255],
        })
        .collect();
    (w as u32, h as u32, rgba)
}

/// A linear RGB colour as a bright `0x00RRGGBB` text colour (at least a third grey, so a
/// dark channel colour stays readable).
pub fn text_colour(rgb: [f64; 3]) -> u32 {
    let c = rgb.map(|v| ((v.clamp(0.0, 1.0) * 2.0 + 1.0) / 3.0 * 255.0).round() as u32);
    (c[0] << 16) | (c[1] << 8) | c[2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_table_matches_the_transfer_function() {
        let t = SrgbTable::default();
        assert_eq!(t.encode(0.0), 0);
        assert_eq!(t.encode(1.0), 255);
        assert_eq!(t.encode(2.0), 255);
        assert_eq!(t.encode(-1.0), 0);
        assert_eq!(t.encode(f32::NAN), 0);
        assert_eq!(t.encode(0.5), 188);
        for i in 0..=1000 {
            let v = i as f32 / 1000.0;
            let exact = crate::image::linear_to_srgb(v) * 255.0;
            assert!((t.encode(v) as f32 - exact).abs() <= 1.0, "{v}");
        }
        assert_eq!(t.pixel(&[1.0, 0.0, 0.5, 1.0]), 0x00ff_00bc);
    }

    #[test]
    fn blit_scales_by_nearest_neighbour() {
        let t = SrgbTable::default();
        let image = [[1.0, 0.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0]];
        let mut px = vec![0u32; 4 * 2];
        Canvas {
            pixels: &mut px,
            width: 4,
            height: 2,
        }
        .blit(&image, 2, 1, &t);
        assert_eq!(
            px,
            [0xff0000, 0xff0000, 0x0000ff, 0x0000ff].repeat(2),
            "{px:x?}"
        );
    }

    #[test]
    fn text_sets_the_glyph_pixels() {
        let mut px = vec![0u32; 20 * 10];
        let mut c = Canvas {
            pixels: &mut px,
            width: 20,
            height: 10,
        };
        c.text(1, 1, "I", 0xffffff, 1);
        let glyph = font8x8::BASIC_FONTS.get('I').unwrap();
        let bits: u32 = glyph.iter().map(|b| b.count_ones()).sum();
        assert!(bits > 0);
        assert_eq!(px.iter().filter(|&&p| p == 0xffffff).count() as u32, bits);
        // Scale 2 quadruples the pixels; clipping at the edge drops the rest.
        let mut px = vec![0u32; 40 * 40];
        Canvas {
            pixels: &mut px,
            width: 40,
            height: 40,
        }
        .text(0, 0, "I", 0x123456, 2);
        assert_eq!(
            px.iter().filter(|&&p| p == 0x123456).count() as u32,
            4 * bits
        );
        let mut px = vec![0u32; 4 * 4];
        Canvas {
            pixels: &mut px,
            width: 4,
            height: 4,
        }
        .text(0, 0, "II", 1, 1);
        assert!(px.iter().filter(|&&p| p == 1).count() as u32 <= bits);
    }

    #[test]
    fn panel_shades_behind_the_text() {
        let mut px = vec![0x00ff_ffffu32; 100 * 40];
        Canvas {
            pixels: &mut px,
            width: 100,
            height: 40,
        }
        .panel(&[("ab".into(), 0x00ff_0000)], 1);
        // Shaded corner, untouched far corner, red glyph pixels.
        assert_eq!(px[0], 0x003f_3f3f);
        assert_eq!(px[39 * 100 + 99], 0x00ff_ffff);
        assert!(px.contains(&0x00ff_0000));
        assert_eq!(text_colour([0.0, 1.0, 0.0]), 0x0055_ff55);
    }
}
