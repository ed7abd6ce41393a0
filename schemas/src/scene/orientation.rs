//! What a view shows to orient its reader: a scale bar of a round length in the store's
//! physical unit, and the screen directions of the world axes, both from the scene's camera
//! ([`Orientation::of`]). `viewer view` draws them with the statistics panel; the web page
//! reads them from the WebAssembly module and draws them on its overlay canvas.

use serde::Serialize;

use super::Camera;

/// The length in pixels a scale bar aims for; its length is the round one nearest to it.
pub const SCALE_BAR_TARGET_PIXELS: f64 = 100.0;

/// A scale bar: a round length, its unit's symbol and how many pixels it spans at the
/// camera's target.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ScaleBar {
    /// The length: 1, 2 or 5 times a power of ten, in `unit`.
    pub length: f64,
    /// The unit's symbol (`µm`, `nm`, ...), or `units` where the store names none.
    pub unit: String,
    /// The bar's length in pixels of a view `height` pixels high.
    pub pixels: f64,
}

/// The scale bar and the axes of one view.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Orientation {
    /// The scale bar.
    pub scale: ScaleBar,
    /// The screen direction `[right, down]` of each world axis's unit vector (`x`, `y`, `z`),
    /// of length 1 for an axis across the view and 0 for one along the view direction.
    pub axes: Axes,
}

/// The screen direction `[right, down]` of each world axis.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Axes {
    /// World `x`.
    pub x: [f64; 2],
    /// World `y`.
    pub y: [f64; 2],
    /// World `z`.
    pub z: [f64; 2],
}

impl Axes {
    /// The axes with their names, `x`, `y`, `z`.
    pub fn named(&self) -> [(&'static str, [f64; 2]); 3] {
        [("x", self.x), ("y", self.y), ("z", self.z)]
    }
}

/// The symbol of an OME-Zarr spatial unit name (the UDUNITS-2 names OME-Zarr lists), the name
/// itself for one not listed, and `units` for none.
pub fn unit_symbol(unit: Option<&str>) -> String {
    let symbol = match unit {
        None => "units",
        Some("angstrom") => "Å",
        Some("nanometer") => "nm",
        Some("micrometer" | "micron") => "µm",
        Some("millimeter") => "mm",
        Some("centimeter") => "cm",
        Some("meter") => "m",
        Some("kilometer") => "km",
        Some("inch") => "in",
        Some("foot") => "ft",
        Some(other) => other,
    };
    symbol.to_string()
}

/// The round length (1, 2, 5 or 10 times a power of ten) nearest `want` in ratio; `want`
/// positive and finite.
fn round_length(want: f64) -> f64 {
    let power = 10f64.powf(want.log10().floor());
    let best = [1.0, 2.0, 5.0, 10.0]
        .map(|m| m * power)
        .into_iter()
        .min_by(|a, b| (a / want).ln().abs().total_cmp(&(b / want).ln().abs()))
        .unwrap_or(power);
    // One significant digit: 0.30000000000000004 is 0.3.
    format!("{best:.0e}").parse().unwrap_or(best)
}

impl Orientation {
    /// The orientation of `camera`'s view, `height` pixels high, of a store in `unit`. The scale
    /// bar is measured at the camera's target (perspective makes nearer things larger). `None`
    /// for a camera at its target or a view with no height.
    pub fn of(camera: &Camera, height: f64, unit: Option<&str>) -> Option<Self> {
        let d = super::sub(camera.target, camera.eye);
        let distance = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let tan_half = (camera.fov_y_degrees.to_radians() / 2.0).tan();
        let per_pixel = 2.0 * distance * tan_half / height;
        if !(per_pixel > 0.0 && per_pixel.is_finite()) {
            return None;
        }
        let length = round_length(SCALE_BAR_TARGET_PIXELS * per_pixel);
        let (_, right, up) = camera.basis();
        let screen = |axis: usize| [right[axis], -up[axis]];
        Some(Self {
            scale: ScaleBar {
                length,
                unit: unit_symbol(unit),
                pixels: length / per_pixel,
            },
            axes: Axes {
                x: screen(0),
                y: screen(1),
                z: screen(2),
            },
        })
    }

    /// The scale bar's label, e.g. `50 µm`.
    pub fn label(&self) -> String {
        format!("{} {}", self.scale.length, self.scale.unit)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera(eye: [f64; 3], target: [f64; 3], fov: f64) -> Camera {
        Camera {
            eye,
            target,
            up: [0.0, -1.0, 0.0],
            fov_y_degrees: fov,
        }
    }

    #[test]
    fn the_scale_bar_is_the_round_length_nearest_100_pixels() {
        // 90° of view over 2·100 = 200 units on 400 pixels: 0.5 units a pixel, so 100
        // pixels are 50 units.
        let o = Orientation::of(
            &camera([0.0, 0.0, -100.0], [0.0; 3], 90.0),
            400.0,
            Some("micrometer"),
        )
        .unwrap();
        assert!((o.scale.length - 50.0).abs() < 1e-12, "{o:?}");
        assert_eq!(o.scale.unit, "µm");
        assert!((o.scale.pixels - 100.0).abs() < 1e-9, "{o:?}");
        assert_eq!(o.label(), "50 µm");
        // 0.7 units a pixel: 70 wanted, 50 (ratio 1.4) beats 100 (ratio 1.43).
        let o = Orientation::of(
            &camera([0.0, 0.0, -140.0], [0.0; 3], 90.0),
            400.0,
            Some("nanometer"),
        )
        .unwrap();
        assert_eq!(o.label(), "50 nm");
        assert!((o.scale.pixels - 50.0 / 0.7).abs() < 1e-9);
        // Tiny and huge views keep one significant digit.
        assert_eq!(round_length(0.29), 0.2);
        assert_eq!(round_length(0.31), 0.2);
        assert_eq!(round_length(0.33), 0.5);
        assert_eq!(round_length(7.5e6), 1e7);
        assert_eq!(round_length(1.0), 1.0);
        assert_eq!(
            Orientation::of(&camera([0.0; 3], [0.0; 3], 30.0), 400.0, None),
            None
        );
        assert_eq!(
            Orientation::of(&camera([0.0, 0.0, 1.0], [0.0; 3], 30.0), 0.0, None),
            None
        );
    }

    #[test]
    fn axes_turn_with_the_camera() {
        // Looking toward +z with up −y: x runs right, y down, z into the screen.
        let o = Orientation::of(&camera([0.0, 0.0, -10.0], [0.0; 3], 30.0), 100.0, None).unwrap();
        assert_eq!(o.scale.unit, "units");
        let close = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).abs() + (a[1] - b[1]).abs() < 1e-12;
        assert!(close(o.axes.x, [1.0, 0.0]), "{o:?}");
        assert!(close(o.axes.y, [0.0, 1.0]), "{o:?}");
        assert!(close(o.axes.z, [0.0, 0.0]), "{o:?}");
        // From the side (looking toward −x): z runs right, y still down, x into the screen.
        let o = Orientation::of(&camera([10.0, 0.0, 0.0], [0.0; 3], 30.0), 100.0, None).unwrap();
        assert!(close(o.axes.z, [1.0, 0.0]), "{o:?}");
        assert!(close(o.axes.y, [0.0, 1.0]), "{o:?}");
        assert!(close(o.axes.x, [0.0, 0.0]), "{o:?}");
        assert_eq!(o.axes.named().map(|(n, _)| n), ["x", "y", "z"]);
    }

    #[test]
    fn units_are_written_as_symbols() {
        assert_eq!(unit_symbol(Some("micron")), "µm");
        assert_eq!(unit_symbol(Some("angstrom")), "Å");
        assert_eq!(unit_symbol(Some("parsec")), "parsec");
        assert_eq!(unit_symbol(None), "units");
    }
}
