//! Simulated channels: one volume duplicated, each copy drawn with its own transfer function.

use crate::scene::Scene;

/// Gives the visible channels after the first distinct transfer functions, as the paper does
/// for simulated channels ("duplicating the volume n times, rendering channels with different
/// transfer functions"): channel `i`'s ramp starts `i/(2n)` of the way further up its range.
pub fn vary_transfer_functions(scene: &mut Scene) {
    let n = scene.channels.len().max(1) as f64;
    for (i, style) in scene.channels.iter_mut().enumerate().skip(1) {
        if let (Some(first), Some(last)) = (style.opacity.first(), style.opacity.last()) {
            let (lo, hi) = (first.value, last.value);
            let shift = (hi - lo) * i as f64 / (2.0 * n);
            for p in &mut style.opacity {
                if p.value < hi {
                    p.value = (p.value + shift).min(hi);
                }
            }
        }
    }
}
