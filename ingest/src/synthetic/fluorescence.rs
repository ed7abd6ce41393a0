//! The `fluorescence` sample: a cleared-tissue light-sheet acquisition.
//!
//! An ellipsoidal piece of tissue in mostly empty space, with nuclei (a 16-bit channel), cell
//! membranes around them and thin filaments (8-bit channels), camera noise inside the tissue
//! and anisotropic voxels (z spacing 4× the xy spacing).

use super::noise::{hash, unit};
use super::ome_tiff::{ChannelSpec, PlaneData, Scene};
use crate::sample_format::SampleType;

/// Voxel size of the sample in micrometres, `z, y, x`.
pub const SAMPLE_VOXEL_SIZE: [f64; 3] = [2.0, 0.5, 0.5];

/// Channel file names of the sample, in channel order.
pub const SAMPLE_CHANNELS: [&str; 3] = ["nuclei", "membranes", "filaments"];

struct Nucleus {
    centre: [f64; 3],
    radius: f64,
    brightness: f64,
}

struct Filament {
    a: [f64; 3],
    b: [f64; 3],
    radius: f64,
}

/// The synthetic scene, in micrometres.
pub struct SampleScene {
    shape: [u64; 3],
    extent: [f64; 3],
    nuclei: Vec<Nucleus>,
    filaments: Vec<Filament>,
    seed: u64,
}

impl SampleScene {
    /// The scene for a stack of `shape` (`z, y, x`) voxels.
    pub fn new(shape: [u64; 3], seed: u64) -> Self {
        let extent: [f64; 3] = std::array::from_fn(|i| shape[i] as f64 * SAMPLE_VOXEL_SIZE[i]);
        let volume = extent.iter().product::<f64>();
        // Roughly one nucleus per 6000 µm³ of tissue; the tissue fills about a third.
        let target = ((volume * 0.33 / 6000.0) as usize).clamp(4, 2_000_000);
        let mut nuclei = Vec::with_capacity(target);
        let mut i = 0u64;
        while nuclei.len() < target && i < 50 * target as u64 {
            let p: [f64; 3] = std::array::from_fn(|a| unit(hash(seed ^ (i * 3 + a as u64))));
            i += 1;
            let q: [f64; 3] = std::array::from_fn(|a| 2.0 * p[a] - 1.0);
            if q.iter().map(|v| v * v).sum::<f64>() > 0.3 {
                continue;
            }
            let h = hash(seed ^ 0xA5A5 ^ i);
            nuclei.push(Nucleus {
                centre: std::array::from_fn(|a| p[a] * extent[a]),
                radius: 3.0 + 2.5 * unit(h),
                brightness: 0.4 + 0.6 * unit(hash(h)),
            });
        }
        let count = (target / 8).max(2);
        let filaments = (0..count as u64)
            .map(|j| {
                let h = hash(seed ^ 0xF11A ^ j);
                let a: [f64; 3] =
                    std::array::from_fn(|k| (0.3 + 0.4 * unit(hash(h ^ k as u64))) * extent[k]);
                let dir: [f64; 3] = std::array::from_fn(|k| unit(hash(h ^ (10 + k as u64))) - 0.5);
                let len = (dir.iter().map(|d| d * d).sum::<f64>()).sqrt().max(1e-6);
                let reach = 15.0 + 40.0 * unit(hash(h ^ 0x63));
                Filament {
                    a,
                    b: std::array::from_fn(|k| a[k] + dir[k] / len * reach),
                    radius: 0.5 + 0.4 * unit(hash(h ^ 7)),
                }
            })
            .collect();
        Self {
            shape,
            extent,
            nuclei,
            filaments,
            seed,
        }
    }

    fn inside_tissue(&self, p: [f64; 3]) -> bool {
        let q: [f64; 3] = std::array::from_fn(|a| 2.0 * p[a] / self.extent[a] - 1.0);
        q.iter().map(|v| v * v).sum::<f64>() <= 0.5
    }

    /// Renders plane `z` of the three channels: nuclei (u16), membranes and filaments (u8).
    pub fn plane(&self, z: u64) -> (Vec<u16>, Vec<u8>, Vec<u8>) {
        let [_, ny, nx] = self.shape;
        let [sz, sy, sx] = SAMPLE_VOXEL_SIZE;
        let n = (ny * nx) as usize;
        let mut nuclei = vec![0u16; n];
        let mut membranes = vec![0u8; n];
        let mut filaments = vec![0u8; n];
        let wz = (z as f64 + 0.5) * sz;
        for (k, nu) in self.nuclei.iter().enumerate() {
            let shell = nu.radius * 1.9;
            let dz = wz - nu.centre[0];
            if dz.abs() > shell + 0.5 {
                continue;
            }
            let reach = (shell + 0.5).powi(2) - dz * dz;
            let r = reach.max(0.0).sqrt();
            let y0 = ((nu.centre[1] - r) / sy).floor().max(0.0) as u64;
            let y1 = (((nu.centre[1] + r) / sy).ceil() as u64).min(ny);
            let x0 = ((nu.centre[2] - r) / sx).floor().max(0.0) as u64;
            let x1 = (((nu.centre[2] + r) / sx).ceil() as u64).min(nx);
            for y in y0..y1 {
                let dy = (y as f64 + 0.5) * sy - nu.centre[1];
                for x in x0..x1 {
                    let dx = (x as f64 + 0.5) * sx - nu.centre[2];
                    let d = (dx * dx + dy * dy + dz * dz).sqrt();
                    let i = (y * nx + x) as usize;
                    if d < nu.radius {
                        let t = 1.0 - (d / nu.radius).powi(2);
                        let texture =
                            0.8 + 0.2 * unit(hash(self.seed ^ (k as u64) << 20 ^ i as u64));
                        let v = 600.0 + 3200.0 * nu.brightness * t.sqrt() * texture;
                        nuclei[i] = nuclei[i].max(v as u16);
                    }
                    let m = (d - shell).abs();
                    if m < 0.6 {
                        let v = 40.0 + 160.0 * (1.0 - m / 0.6);
                        membranes[i] = membranes[i].max(v as u8);
                    }
                }
            }
        }
        for f in &self.filaments {
            let (zmin, zmax) = (f.a[0].min(f.b[0]) - f.radius, f.a[0].max(f.b[0]) + f.radius);
            if wz < zmin || wz > zmax {
                continue;
            }
            let ymin = f.a[1].min(f.b[1]) - f.radius;
            let ymax = f.a[1].max(f.b[1]) + f.radius;
            let xmin = f.a[2].min(f.b[2]) - f.radius;
            let xmax = f.a[2].max(f.b[2]) + f.radius;
            let y0 = (ymin / sy).floor().max(0.0) as u64;
            let y1 = ((ymax / sy).ceil().max(0.0) as u64).min(ny);
            let x0 = (xmin / sx).floor().max(0.0) as u64;
            let x1 = ((xmax / sx).ceil().max(0.0) as u64).min(nx);
            let ab: [f64; 3] = std::array::from_fn(|k| f.b[k] - f.a[k]);
            let ab2 = ab.iter().map(|v| v * v).sum::<f64>();
            for y in y0..y1 {
                for x in x0..x1 {
                    let p = [wz, (y as f64 + 0.5) * sy, (x as f64 + 0.5) * sx];
                    let ap: [f64; 3] = std::array::from_fn(|k| p[k] - f.a[k]);
                    let t =
                        (ap.iter().zip(&ab).map(|(a, b)| a * b).sum::<f64>() / ab2).clamp(0.0, 1.0);
                    let d2 = (0..3).map(|k| (ap[k] - t * ab[k]).powi(2)).sum::<f64>();
                    if d2 < f.radius * f.radius && self.inside_tissue(p) {
                        let i = (y * nx + x) as usize;
                        let v = 60.0 + 190.0 * (1.0 - d2 / (f.radius * f.radius));
                        filaments[i] = filaments[i].max(v as u8);
                    }
                }
            }
        }
        // Camera noise and autofluorescence, inside the tissue only.
        for y in 0..ny {
            let wy = (y as f64 + 0.5) * sy;
            for x in 0..nx {
                let p = [wz, wy, (x as f64 + 0.5) * sx];
                if !self.inside_tissue(p) {
                    continue;
                }
                let i = (y * nx + x) as usize;
                let h = hash(self.seed ^ (z << 40) ^ (y << 20) ^ x);
                nuclei[i] = nuclei[i].saturating_add(100 + (h & 63) as u16);
                membranes[i] = membranes[i].saturating_add(((h >> 8) & 7) as u8);
                filaments[i] = filaments[i].saturating_add(((h >> 16) & 3) as u8);
            }
        }
        (nuclei, membranes, filaments)
    }
}

impl Scene for SampleScene {
    fn shape(&self) -> [u64; 3] {
        self.shape
    }

    fn voxel_size(&self) -> [f64; 3] {
        SAMPLE_VOXEL_SIZE
    }

    fn channels(&self) -> Vec<ChannelSpec> {
        let formats = [SampleType::U16, SampleType::U8, SampleType::U8];
        SAMPLE_CHANNELS
            .iter()
            .zip(formats)
            .map(|(name, format)| ChannelSpec {
                file_stem: name.to_string(),
                name: name.to_string(),
                format,
            })
            .collect()
    }

    fn render_plane(&self, z: u64) -> Vec<PlaneData> {
        let (nuclei, membranes, filaments) = self.plane(z);
        vec![
            PlaneData::U16(nuclei),
            PlaneData::U8(membranes),
            PlaneData::U8(filaments),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sample_is_deterministic_sparse_and_has_signal() {
        let s = SampleScene::new([16, 64, 64], 1);
        let (a, b, c) = s.plane(8);
        let (a2, _, _) = SampleScene::new([16, 64, 64], 1).plane(8);
        assert_eq!(a, a2);
        let zeros = a.iter().filter(|&&v| v == 0).count();
        assert!(
            zeros > a.len() / 10,
            "mostly-empty space expected, {zeros} zeros"
        );
        assert!(a.iter().any(|&v| v > 1000), "bright nuclei expected");
        assert!(b.iter().any(|&v| v > 100));
        let _ = c;
    }
}
