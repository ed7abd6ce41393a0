//! Keyboard and pointer control of the channel styles: visibility, colour from a palette,
//! and window/level of the opacity ramp, as pure functions of the [`Scene`] (tested
//! exactly).
//!
//! A channel's **window** is the value span of its opacity transfer function, from its first
//! control point (the ramp's low end, where it starts to rise) to its last (the high end,
//! where it tops out). Moving an end remaps every control point linearly from the old
//! window to the new one, so a multi-point transfer function keeps its shape.

use crate::defaults::{DEFAULT_COLOURS, default_channels, default_opacity};
use crate::scene::{ChannelStyle, OpacityPoint, Scene};
use crate::source::VolumeInfo;

/// The colours `c` cycles through: the default channel colours, then white (linear RGB).
pub const PALETTE: [[f64; 3]; 7] = [
    DEFAULT_COLOURS[0],
    DEFAULT_COLOURS[1],
    DEFAULT_COLOURS[2],
    DEFAULT_COLOURS[3],
    DEFAULT_COLOURS[4],
    DEFAULT_COLOURS[5],
    [1.0, 1.0, 1.0],
];

/// Fraction of a channel's default ramp width that one window/level key press moves an
/// end by.
pub const KEY_STEP: f64 = 0.05;

/// The end of the opacity ramp a key moves.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum End {
    /// The first control point (where the ramp starts to rise).
    Low,
    /// The last control point (where it tops out).
    High,
}

/// The window `(low, high)` of a transfer function: its first and last control values.
pub fn window(points: &[OpacityPoint]) -> Option<(f64, f64)> {
    Some((points.first()?.value, points.last()?.value))
}

/// Moves the window of `points` to `(lo, hi)`, remapping every control point linearly. A
/// degenerate window (one point, or all points at one value) is shifted by the low end's
/// motion instead.
pub fn set_window(points: &mut [OpacityPoint], lo: f64, hi: f64) {
    let Some((old_lo, old_hi)) = window(points) else {
        return;
    };
    if old_hi > old_lo {
        let scale = (hi - lo) / (old_hi - old_lo);
        for p in points.iter_mut() {
            p.value = lo + (p.value - old_lo) * scale;
        }
        // Exact ends, whatever the rounding of the remap.
        let n = points.len();
        points[0].value = lo;
        points[n - 1].value = hi;
    } else {
        for p in points.iter_mut() {
            p.value += lo - old_lo;
        }
    }
}

/// Moves one end of the window by `delta`, keeping the low end below the high end by at
/// least `min_width` (a one-value window just moves by `delta`).
pub fn move_end(points: &mut [OpacityPoint], end: End, delta: f64, min_width: f64) {
    let Some((lo, hi)) = window(points) else {
        return;
    };
    if hi <= lo {
        // One value only: the ramp is a step; move it.
        for p in points.iter_mut() {
            p.value += delta;
        }
        return;
    }
    match end {
        End::Low => set_window(points, (lo + delta).min(hi - min_width), hi),
        End::High => set_window(points, lo, (hi + delta).max(lo + min_width)),
    }
}

/// Window/level by dragging: `width_factor` scales the window about its centre, and the
/// centre moves by `level_delta`; the width never falls below `min_width`.
pub fn window_level(
    points: &mut [OpacityPoint],
    width_factor: f64,
    level_delta: f64,
    min_width: f64,
) {
    let Some((lo, hi)) = window(points) else {
        return;
    };
    let centre = 0.5 * (lo + hi) + level_delta;
    let half = 0.5 * ((hi - lo) * width_factor).max(min_width);
    set_window(points, centre - half, centre + half);
}

/// The palette colour after `current` (the first when `current` is not in the palette).
pub fn next_colour(current: [f64; 3]) -> [f64; 3] {
    match PALETTE.iter().position(|c| *c == current) {
        Some(i) => PALETTE[(i + 1) % PALETTE.len()],
        None => PALETTE[0],
    }
}

/// The variant after `current` in the order of its enum (the filter, the mode), the first
/// after the last.
pub fn next_variant<E: strum::VariantArray + PartialEq + Copy>(current: E) -> E {
    let i = E::VARIANTS.iter().position(|&v| v == current).unwrap_or(0);
    E::VARIANTS[(i + 1) % E::VARIANTS.len()]
}

/// Width of channel `channel`'s default ramp: the unit of the window/level steps.
pub fn reference_width(info: &VolumeInfo, channel: usize) -> f64 {
    let d = default_opacity(info, channel);
    match window(&d) {
        Some((lo, hi)) if hi > lo => hi - lo,
        _ => 1.0,
    }
}

/// Scales the opacity ramp `points` so that its highest point is `opacity` (every point set
/// to `opacity` where the ramp is zero everywhere).
pub fn set_top_opacity(points: &mut [OpacityPoint], opacity: f64) {
    let top = OpacityPoint::top(points);
    for p in points {
        p.opacity = if top > 0.0 {
            p.opacity / top * opacity
        } else {
            opacity
        };
    }
}

/// The style of `channel` in `scene`, added with its default (hidden) style when the scene
/// does not list it. `None` when the volume has no such channel.
pub fn style_mut<'a>(
    scene: &'a mut Scene,
    info: &VolumeInfo,
    channel: usize,
) -> Option<&'a mut ChannelStyle> {
    if channel >= info.channels.len() {
        return None;
    }
    let i = if let Some(i) = scene.channels.iter().position(|s| s.channel == channel) {
        i
    } else {
        let mut style = default_channels(info).swap_remove(channel);
        style.visible = false;
        scene.channels.push(style);
        scene.channels.sort_by_key(|s| s.channel);
        scene.channels.iter().position(|s| s.channel == channel)?
    };
    Some(&mut scene.channels[i])
}

/// Number of visible channels.
pub fn visible_count(scene: &Scene) -> usize {
    scene.channels.iter().filter(|s| s.visible).count()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Camera, Filter, RenderMode};
    use crate::source::{ChannelDisplay, LevelInfo, SampleType};

    fn ramp(lo: f64, hi: f64) -> Vec<OpacityPoint> {
        vec![
            OpacityPoint {
                value: lo,
                opacity: 0.0,
            },
            OpacityPoint {
                value: hi,
                opacity: 0.05,
            },
        ]
    }

    fn values(p: &[OpacityPoint]) -> Vec<f64> {
        p.iter().map(|p| p.value).collect()
    }

    #[test]
    fn keys_move_the_ramp_ends() {
        let mut p = ramp(100.0, 900.0);
        move_end(&mut p, End::Low, -40.0, 1.0);
        assert_eq!(values(&p), [60.0, 900.0]);
        move_end(&mut p, End::High, 40.0, 1.0);
        assert_eq!(values(&p), [60.0, 940.0]);
        // The low end stops just below the high end, and the other way round.
        move_end(&mut p, End::Low, 5000.0, 1.0);
        assert_eq!(values(&p), [939.0, 940.0]);
        move_end(&mut p, End::High, -5000.0, 2.0);
        assert_eq!(values(&p), [939.0, 941.0]);
        // Opacities are untouched.
        assert_eq!(p[1].opacity, 0.05);
    }

    #[test]
    fn a_multi_point_function_keeps_its_shape() {
        let mut p = vec![
            OpacityPoint {
                value: 0.0,
                opacity: 0.0,
            },
            OpacityPoint {
                value: 10.0,
                opacity: 0.5,
            },
            OpacityPoint {
                value: 40.0,
                opacity: 0.2,
            },
        ];
        set_window(&mut p, 100.0, 180.0);
        assert_eq!(values(&p), [100.0, 120.0, 180.0]);
        window_level(&mut p, 0.5, 10.0, 1.0);
        // Centre 140 + 10, half width 20.
        assert_eq!(values(&p), [130.0, 140.0, 170.0]);
        window_level(&mut p, 0.0, 0.0, 4.0);
        assert_eq!(values(&p), [148.0, 149.0, 152.0]);
        // A single point just moves.
        let mut one = vec![OpacityPoint {
            value: 5.0,
            opacity: 0.3,
        }];
        move_end(&mut one, End::Low, 2.0, 1.0);
        assert_eq!(values(&one), [7.0]);
        let mut none: Vec<OpacityPoint> = Vec::new();
        move_end(&mut none, End::High, 1.0, 1.0);
        assert!(none.is_empty());
    }

    #[test]
    fn colours_cycle_through_the_palette() {
        assert_eq!(next_colour([0.0, 1.0, 1.0]), [1.0, 0.0, 1.0]);
        assert_eq!(next_colour([1.0, 1.0, 1.0]), [0.0, 1.0, 1.0]);
        assert_eq!(next_colour([0.3, 0.2, 0.1]), [0.0, 1.0, 1.0]);
        let mut c = [0.3, 0.2, 0.1];
        for _ in 0..PALETTE.len() + 2 {
            c = next_colour(c);
        }
        assert_eq!(c, PALETTE[1]);
    }

    #[test]
    fn filters_alternate() {
        assert_eq!(next_variant(Filter::Trilinear), Filter::Tricubic);
        assert_eq!(next_variant(Filter::Tricubic), Filter::Trilinear);
        assert_eq!(next_variant(RenderMode::Dvr), RenderMode::Mip);
        assert_eq!(next_variant(RenderMode::Mip), RenderMode::Iso);
        assert_eq!(next_variant(RenderMode::Iso), RenderMode::Dvr);
    }

    #[test]
    fn styles_are_added_for_unlisted_channels() {
        let info = VolumeInfo {
            name: "v".into(),
            sample_type: SampleType::U8,
            channels: vec!["a".into(), "b".into()],
            display: vec![ChannelDisplay::default(), ChannelDisplay::default()],
            voxel_size: [1.0; 3],
            unit: None,
            brick_shape: [8; 3],
            levels: vec![LevelInfo {
                shape: [8, 8, 8],
                factor: [1, 1, 1],
            }],
            minmax: None,
        };
        let mut scene = Scene {
            camera: Camera {
                eye: [0.0, 0.0, -10.0],
                target: [0.0; 3],
                up: [0.0, -1.0, 0.0],
                fov_y_degrees: 30.0,
            },
            channels: vec![],
            background: [0.0; 3],
            filter: Filter::Trilinear,
            mode: RenderMode::Dvr,
            clip: crate::scene::Clip::default(),
        };
        assert!(style_mut(&mut scene, &info, 2).is_none());
        let s = style_mut(&mut scene, &info, 1).unwrap();
        assert_eq!((s.channel, s.visible), (1, false));
        s.visible = true;
        assert_eq!(visible_count(&scene), 1);
        assert_eq!(reference_width(&info, 0), 255.0);
        style_mut(&mut scene, &info, 0).unwrap();
        assert_eq!(
            scene.channels.iter().map(|s| s.channel).collect::<Vec<_>>(),
            [0, 1]
        );
    }
}
