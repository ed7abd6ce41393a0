//! The `dense` and `mixing` samples: a float field that fills the whole volume, in the spirit
//! of the Rayleigh–Taylor instability simulation.
//!
//! A heavy fluid (density about 1) lies above a light one (about 0.25) and the two are
//! mixing: the interface between them, around mid-depth, is pushed up and down by large
//! bubbles and spikes, and inside the mixing layer the density is stirred by turbulence at
//! every scale (multi-octave value noise), strongest where the two fluids are half mixed.
//!
//! - `dense` ([`Fluids::Stratified`]): both fluids are also faintly stratified in smooth
//!   low-frequency bands and grained everywhere, so every voxel holds a positive density and
//!   every small region varies: the worst case for empty-space skipping.
//! - `mixing` ([`Fluids::Pure`]): as in a simulation of two miscible fluids, where the density
//!   follows the fluids' mass fraction, the fluids away from the mixing layer are pure: exactly
//!   1 above and exactly 0.25 below, so whole regions are constant.
//!
//! Extra channels are the same field through different transfer functions (like the paper's
//! "simulated channels"): a power that emphasises the heavy fluid, an inversion that
//! emphasises the light one, and a bump around the interface density; past three they repeat
//! with stronger parameters.

use std::f64::consts::TAU;

use super::noise::{NoisePlane, smoothstep};
use super::ome_tiff::{ChannelSpec, PlaneData, Scene};
use crate::sample_format::SampleType;

/// Densities are clamped to this range, so every channel stays positive.
pub(crate) const DENSITY_RANGE: (f64, f64) = (0.05, 1.2);

/// What the fluids outside the mixing layer are like.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Fluids {
    /// Faintly stratified and grained: no region is constant (the `dense` sample).
    Stratified,
    /// Pure: exactly uniform outside the mixing layer (the `mixing` sample).
    Pure,
}

/// The mixing fluids.
pub(crate) struct DenseScene {
    shape: [u64; 3],
    channels: usize,
    seed: u64,
    fluids: Fluids,
    /// The largest extent: noise coordinates are in its units, so features are isotropic.
    scale: f64,
}

/// What channel `k ≥ 1` shows, and its repeat index.
fn transfer(k: usize) -> (&'static str, usize) {
    (["heavy", "light", "interface"][(k - 1) % 3], (k - 1) / 3)
}

/// Channel `k`'s transfer function of a density in [`DENSITY_RANGE`]; every result is
/// positive and finite.
pub(crate) fn map_density(rho: f64, k: usize) -> f64 {
    if k == 0 {
        return rho;
    }
    let (kind, repeat) = transfer(k);
    let r = repeat as f64;
    match kind {
        "heavy" => rho.powf(2.0 + r),
        "light" => 1.25 + 0.25 * r - rho,
        _ => {
            let centre = 0.52 + 0.1 * (r % 3.0);
            0.05 + (-((rho - centre) / 0.15).powi(2)).exp()
        }
    }
}

impl DenseScene {
    /// The field for a volume of `shape` voxels with `channels` transfer functions, with
    /// `fluids` outside the mixing layer.
    pub(crate) fn new(shape: [u64; 3], channels: usize, seed: u64, fluids: Fluids) -> Self {
        Self {
            shape,
            channels,
            seed,
            fluids,
            scale: shape.iter().copied().max().unwrap_or(1) as f64,
        }
    }

    /// The noise coordinate of the centre of voxel `i` along any axis.
    fn coordinate(&self, i: u64) -> f64 {
        (i as f64 + 0.5) / self.scale
    }

    /// The density of every voxel of plane `z` (`y, x` in C order).
    pub(crate) fn density_plane(&self, z: u64) -> Vec<f64> {
        let [nz, ny, nx] = self.shape;
        let s = self.seed;
        let pz = self.coordinate(z);
        let (ymax, xmax) = (self.coordinate(ny - 1), self.coordinate(nx - 1));
        let height = (z as f64 + 0.5) / nz as f64;
        // Bubbles and spikes: large-scale displacement of the interface, varying across the
        // horizontal plane, plus 3-D turbulence that folds it.
        let bubbles = NoisePlane::new(s ^ 0xB0BB, None, ymax * 3.0, xmax * 3.0, 3);
        let turbulence = NoisePlane::new(s ^ 0x7B7B, Some(pz * 8.0), ymax * 8.0, xmax * 8.0, 4);
        let bands = NoisePlane::new(s ^ 0xBA4D, Some(pz * 2.0), ymax * 2.0, xmax * 2.0, 1);
        let fine = NoisePlane::new(s ^ 0xF14E, Some(pz * 32.0), ymax * 32.0, xmax * 32.0, 2);
        // The pure fluids' grain fades out with the mixing layer; the stratified ones keep some.
        let (band_amplitude, grain_floor) = match self.fluids {
            Fluids::Stratified => (0.04, 0.15),
            Fluids::Pure => (0.0, 0.0),
        };
        let mut out = Vec::with_capacity((ny * nx) as usize);
        for y in 0..ny {
            let py = self.coordinate(y);
            for x in 0..nx {
                let px = self.coordinate(x);
                let d = (height - 0.5)
                    + 0.45 * (bubbles.at(py * 3.0, px * 3.0) - 0.5)
                    + 0.2 * (turbulence.at(py * 8.0, px * 8.0) - 0.5);
                let mix = smoothstep(-0.12, 0.12, d);
                let layer = 4.0 * mix * (1.0 - mix);
                let band = band_amplitude
                    * (TAU * (4.0 * height + 0.6 * bands.at(py * 2.0, px * 2.0))).sin();
                let grain = 0.12 * (fine.at(py * 32.0, px * 32.0) - 0.5) * (grain_floor + layer);
                out.push(
                    (0.25 + 0.75 * mix + band + grain).clamp(DENSITY_RANGE.0, DENSITY_RANGE.1),
                );
            }
        }
        out
    }
}

impl Scene for DenseScene {
    fn shape(&self) -> [u64; 3] {
        self.shape
    }

    fn voxel_size(&self) -> [f64; 3] {
        [1.0; 3]
    }

    fn channels(&self) -> Vec<ChannelSpec> {
        let stem = match self.fluids {
            Fluids::Stratified => "dense",
            Fluids::Pure => "mixing",
        };
        ChannelSpec::transfer_channels(stem, SampleType::F32, self.channels, |k| {
            match transfer(k) {
                (kind, 0) => kind.to_string(),
                (kind, r) => format!("{kind}{}", r + 1),
            }
        })
    }

    fn render_plane(&self, z: u64) -> Vec<PlaneData> {
        let density = self.density_plane(z);
        (0..self.channels)
            .map(|k| {
                PlaneData::F32(
                    density
                        .iter()
                        .map(|&rho| map_density(rho, k) as f32)
                        .collect(),
                )
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transfer_functions_stay_positive_and_differ() {
        for k in 0..crate::synthetic::error::MAX_SAMPLE_CHANNELS {
            for i in 0..=100 {
                let rho = DENSITY_RANGE.0 + (DENSITY_RANGE.1 - DENSITY_RANGE.0) * i as f64 / 100.0;
                let v = map_density(rho, k) as f32;
                assert!(v.is_finite() && v > 0.0, "channel {k}: {v} at {rho}");
            }
        }
        assert_eq!(map_density(0.5, 0), 0.5);
        assert_eq!(map_density(0.5, 1), 0.25);
        assert_eq!(map_density(0.5, 2), 0.75);
        assert_eq!(map_density(0.52, 3), 1.05);
        assert_eq!(map_density(0.5, 4), 0.125);
        assert_eq!(transfer(4), ("heavy", 1));
    }

    #[test]
    fn heavy_fluid_lies_above_the_light_one() {
        let scene = DenseScene::new([64, 32, 32], 1, 1, Fluids::Stratified);
        let mean = |z: u64| scene.density_plane(z).iter().sum::<f64>() / 1024.0;
        assert!(mean(1) < 0.45, "bottom {}", mean(1));
        assert!(mean(62) > 0.8, "top {}", mean(62));
    }

    #[test]
    fn pure_fluids_are_exactly_uniform_outside_the_mixing_layer() {
        let pure = DenseScene::new([64, 32, 32], 1, 1, Fluids::Pure);
        // The interface moves at most 0.325 of the height from mid-depth and the layer is
        // 0.12 thick on each side: the bottom and top planes are pure everywhere.
        assert!(pure.density_plane(0).iter().all(|&rho| rho == 0.25));
        assert!(pure.density_plane(63).iter().all(|&rho| rho == 1.0));
        let middle = pure.density_plane(32);
        let distinct: std::collections::BTreeSet<u64> =
            middle.iter().map(|r| r.to_bits()).collect();
        assert!(
            distinct.len() > 500,
            "{} distinct densities",
            distinct.len()
        );
        // The stratified fluids vary on the same planes.
        let stratified = DenseScene::new([64, 32, 32], 1, 1, Fluids::Stratified);
        let bottom = stratified.density_plane(0);
        assert!(bottom.iter().any(|&rho| rho != bottom[0]));
    }
}
