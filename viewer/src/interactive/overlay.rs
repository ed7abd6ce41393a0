//! Putting a rendered frame on screen: linear RGB to 8-bit sRGB (`0x00RRGGBB` pixels, as
//! `softbuffer` takes them), nearest-neighbour scaling to the window, and a statistics panel
//! drawn with the `font8x8` bitmap font over a darkened backdrop, and the orientation (a scale
//! bar and the world axes, [`crate::scene::orientation`]) along the bottom edge.

use font8x8::UnicodeFonts;

use crate::scene::orientation::Orientation;

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

/// Height in pixels at scale 1 of the strip along the bottom edge that
/// [`Canvas::orientation`] draws in.
pub const ORIENTATION_HEIGHT: usize = 80;

/// The colours of the world axes `x`, `y`, `z` (red, green, blue, as the page draws them).
const AXIS_COLOURS: [u32; 3] = [0x00ff_5555, 0x0055_ff55, 0x0055_99ff];

/// The colour of the orientation's shadow (the scale bar and axes readable on a bright image).
const SHADOW: u32 = 0x0000_0000;

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

    /// Sets pixel `(x, y)` to `rgb` where it is on the canvas.
    fn put(&mut self, x: i64, y: i64, rgb: u32) {
        if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
            self.pixels[y as usize * self.width + x as usize] = rgb;
        }
    }

    /// Draws a line `width` pixels thick from `from` to `to` (pixel coordinates, may lie off
    /// the canvas) in `rgb`: a `width × width` square at each step along the longer axis.
    pub fn line(&mut self, from: (f64, f64), to: (f64, f64), rgb: u32, width: usize) {
        let steps = (to.0 - from.0)
            .abs()
            .max((to.1 - from.1).abs())
            .ceil()
            .max(1.0) as usize;
        let half = (width as f64 - 1.0) / 2.0;
        for i in 0..=steps {
            let t = i as f64 / steps as f64;
            let x = (from.0 + (to.0 - from.0) * t - half).round() as i64;
            let y = (from.1 + (to.1 - from.1) * t - half).round() as i64;
            for dy in 0..width as i64 {
                for dx in 0..width as i64 {
                    self.put(x + dx, y + dy, rgb);
                }
            }
        }
    }

    /// Draws `o` in the strip [`ORIENTATION_HEIGHT`]` · scale` pixels high along the bottom
    /// edge, each mark over a black shadow one `scale` down and right: the scale bar (a bar with
    /// end ticks, its label above) at the left, the axes (`x` red, `y` green, `z` blue, each
    /// with its name) at the right.
    pub fn orientation(&mut self, o: &Orientation, scale: usize) {
        let s = scale.max(1) as f64;
        let bottom = self.height as f64;
        let (w, h) = (self.width as f64, ORIENTATION_HEIGHT as f64 * s);
        let top = bottom - h;
        let thick = 2 * scale.max(1);
        for (shift, shadow) in [(s, true), (0.0, false)] {
            let colour = |rgb: u32| if shadow { SHADOW } else { rgb };
            // The scale bar, bottom left.
            let (x0, y) = (12.0 * s + shift, bottom - 14.0 * s + shift);
            let x1 = x0 + o.scale.pixels.min(w);
            let white = colour(0x00ff_ffff);
            self.line((x0, y - 4.0 * s), (x0, y), white, thick);
            self.line((x0, y), (x1, y), white, thick);
            self.line((x1, y - 4.0 * s), (x1, y), white, thick);
            let label_y = (y - 8.0 * s - 8.0 * s).max(0.0);
            self.text(x0 as usize, label_y as usize, &o.label(), white, scale);
            // The axes, bottom right.
            let origin = (w - 44.0 * s + shift, top + 40.0 * s + shift);
            for ((name, d), rgb) in o.axes.named().into_iter().zip(AXIS_COLOURS) {
                let tip = (origin.0 + 24.0 * s * d[0], origin.1 + 24.0 * s * d[1]);
                self.line(origin, tip, colour(rgb), thick);
                let at = (
                    origin.0 + 32.0 * s * d[0] - 4.0 * s,
                    origin.1 + 32.0 * s * d[1] - 4.0 * s,
                );
                self.text(
                    at.0.max(0.0) as usize,
                    at.1.max(0.0) as usize,
                    name,
                    colour(rgb),
                    scale,
                );
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
    let (w, h) = panel_size(lines, scale);
    overlay_rgba(w, h, |canvas| canvas.panel_text(lines, scale))
}

/// The orientation strip [`Canvas::orientation`] draws across a window `width` pixels wide,
/// as the GPU's present pass takes it ([`crate::gpu::present::Presenter::set_footer`]):
/// `(width, height, RGBA bytes)`, the marks in their colour with alpha 255, the rest all 0
/// (the image shows through).
pub fn orientation_rgba(o: &Orientation, width: usize, scale: usize) -> (u32, u32, Vec<u8>) {
    let height = ORIENTATION_HEIGHT * scale.max(1);
    overlay_rgba(width, height, |canvas| canvas.orientation(o, scale))
}

/// What `draw` draws on a `width × height` canvas as an overlay texture: `(width, height,
/// RGBA bytes)`, each pixel drawn in its colour with alpha 255, every other all 0.
fn overlay_rgba(
    width: usize,
    height: usize,
    draw: impl FnOnce(&mut Canvas),
) -> (u32, u32, Vec<u8>) {
    /// A value no colour drawn (`0x00RRGGBB`) has.
    const UNDRAWN: u32 = 0xff00_0000;
    let mut pixels = vec![UNDRAWN; width * height];
    draw(&mut Canvas {
        pixels: &mut pixels,
        width,
        height,
    });
    let rgba = pixels
        .iter()
        .flat_map(|&p| match p {
            UNDRAWN => [0; 4],
            p => [(p >> 16) as u8, (p >> 8) as u8, p as u8, 255],
        })
        .collect();
    (width as u32, height as u32, rgba)
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

    #[test]
    fn orientation_draws_the_scale_bar_and_axes_along_the_bottom() {
        use crate::scene::Camera;
        // Looking toward +z: x right, y down, z along the view (drawn as a point).
        let camera = Camera {
            eye: [0.0, 0.0, -100.0],
            target: [0.0; 3],
            up: [0.0, -1.0, 0.0],
            fov_y_degrees: 90.0,
        };
        let (w, h) = (300usize, 200usize);
        let o = Orientation::of(&camera, h as f64, Some("micrometer")).unwrap();
        // 1 unit a pixel: a 100 µm bar of 100 pixels.
        assert_eq!(o.label(), "100 µm");
        const GREY: u32 = 0x0080_8080;
        let mut px = vec![GREY; w * h];
        Canvas {
            pixels: &mut px,
            width: w,
            height: h,
        }
        .orientation(&o, 1);
        let at = |x: usize, y: usize| px[y * w + x];
        // Above the strip nothing changed.
        assert!(
            px[..(h - ORIENTATION_HEIGHT) * w]
                .iter()
                .all(|&p| p == GREY)
        );
        // The bar: two rows (y 186 and 187) white from x 12 to 113, its shadow below.
        for x in 15..=111 {
            assert_eq!(at(x, 186), 0x00ff_ffff, "bar at {x}");
            assert_eq!(at(x, 187), 0x00ff_ffff, "bar at {x}");
        }
        assert_eq!(at(60, 188), SHADOW);
        assert_eq!(at(116, 186), GREY);
        // The ticks rise 4 pixels at both ends (columns 12-13 and 112-113), shadowed right.
        for x in [12, 13, 112, 113] {
            assert_eq!(at(x, 182), 0x00ff_ffff, "tick at {x}");
        }
        assert_eq!(at(114, 183), SHADOW);
        assert_eq!(at(60, 182), GREY);
        // The x axis runs right from the origin (256, 160), red; the y axis down, green.
        assert_eq!(at(270, 160), AXIS_COLOURS[0]);
        assert_eq!(at(256, 174), AXIS_COLOURS[1]);
        assert_eq!(at(242, 160), GREY);
        // The strip as RGBA: the same marks, alpha 0 where the image shows through.
        let (sw, sh, rgba) = orientation_rgba(&o, w, 1);
        assert_eq!((sw, sh), (w as u32, ORIENTATION_HEIGHT as u32));
        let strip = &px[(h - ORIENTATION_HEIGHT) * w..];
        for (p, c) in strip.iter().zip(rgba.chunks_exact(4)) {
            if *p == GREY {
                assert_eq!(c, [0, 0, 0, 0]);
            } else {
                assert_eq!(c, [(p >> 16) as u8, (p >> 8) as u8, *p as u8, 255]);
            }
        }
    }
}
