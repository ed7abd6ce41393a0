//! The `sparse` sample: a CT scan of a thin, curved, branching structure in empty space, in the
//! spirit of the Kingsnake and Beechnut micro-CT data sets.
//!
//! A snake skeleton lies coiled in the middle of the field of view: the spine is a hollow bony
//! tube (a shell a few voxels thick around an empty canal) that spirals inwards and undulates
//! in z, tapering towards the tail; pairs of thin curved ribs branch off it at regular
//! intervals; a few small, very dense blobs (teeth, swallowed stones) sit near the head and
//! along the coil. Bone has a mottled texture. Faint soft tissue (flesh) wraps the spine and
//! fills its canal, as in a real CT: a bone window hides it, yet its bricks hold data. The air
//! around the specimen, most of the volume, is the scanner's faint noise floor (never 0), so
//! no brick is all fill value: a loader that does not know the transfer function fetches every
//! brick, while a renderer culling by min/max under a bone window fetches only the bone's.
//!
//! Extra channels are the same scan through different CT windows, like the paper's
//! "simulated channels" that duplicate one volume with different transfer functions: channel
//! `k` keeps only voxels at or above a threshold that rises with `k` (so later channels show
//! only the ribs and the dense blobs) and stretches them to the full 16-bit range.

use super::noise::{fbm3, hash, segment_distance, smoothstep, unit};
use super::ome_tiff::{ChannelSpec, PlaneData, Scene};
use crate::sample_format::SampleType;

/// Air: the scanner's noise floor, `1..AIR_MAX` (never 0, so no brick is all fill value).
pub(crate) const AIR_MAX: u16 = 60;
/// Soft tissue (flesh around the spine and the cord inside it): faint, below every bone value,
/// so a bone window hides it although its bricks are not empty.
const SOFT: (u16, u16) = (100, 400);
/// Values of the three bone materials (before any window): bone shell, ribs, dense blobs.
const SHELL: (u16, u16) = (1000, 2000);
const RIB: (u16, u16) = (2000, 3000);
const BLOB: (u16, u16) = (4000, 6000);
/// Largest value the scan holds.
pub(crate) const SPARSE_MAX: u16 = BLOB.1;
/// Ribs are polylines of this many points.
const RIB_POINTS: usize = 7;

struct Blob {
    centre: [f64; 3],
    radii: [f64; 3],
}

/// The coiled skeleton, in voxel coordinates (`z, y, x`, voxel centres at `i + 0.5`).
pub(crate) struct SparseScene {
    shape: [u64; 3],
    channels: usize,
    seed: u64,
    /// Spine centreline and the tube radius at each of its points.
    spine: Vec<([f64; 3], f64)>,
    wall: f64,
    /// Thickness of the soft tissue around the bone.
    flesh: f64,
    ribs: Vec<[[f64; 3]; RIB_POINTS]>,
    rib_radius: f64,
    blobs: Vec<Blob>,
}

/// The CT window of channel `k` of `channels`: voxels below `threshold` become 0.
pub(crate) fn window_threshold(k: usize, channels: usize) -> u16 {
    if k == 0 {
        1
    } else {
        (SHELL.0 as usize + 3500 * k / channels) as u16
    }
}

/// Applies channel `k`'s window to a scan value: identity for channel 0; otherwise values below
/// the threshold become 0 and the rest are stretched linearly onto `1..=60001`.
pub(crate) fn window(v: u16, k: usize, channels: usize) -> u16 {
    if k == 0 || v == 0 {
        return v;
    }
    let t = window_threshold(k, channels);
    if v < t {
        0
    } else {
        (1 + u64::from(v - t) * 60_000 / u64::from(SPARSE_MAX - t)) as u16
    }
}

impl SparseScene {
    /// The scene for a volume of `shape` voxels with `channels` windows.
    pub(crate) fn new(shape: [u64; 3], channels: usize, seed: u64) -> Self {
        let [nz, ny, nx] = shape.map(|v| v as f64);
        let m = ny.min(nx);
        let centre = [nz / 2.0, ny / 2.0, nx / 2.0];
        let coil = 0.36 * m;
        let tube = (0.04 * m).max(1.5);
        let wall = (0.25 * tube).max(0.75);
        let flesh = tube;
        let turns = 2.5;
        let r = |i: u64| unit(hash(seed ^ 0x5EA5_0000 ^ i));
        let phase = std::f64::consts::TAU * r(1);
        let z_phase = std::f64::consts::TAU * r(2);
        let hand = if r(3) < 0.5 { 1.0 } else { -1.0 };
        let z_amp = 0.22 * nz;
        let point = |t: f64| -> [f64; 3] {
            let angle = phase + hand * std::f64::consts::TAU * turns * t;
            let wobble = 1.0 + 0.12 * (fbm3(seed ^ 0x3071, [0.0, 0.0, 6.0 * t], 2) - 0.5);
            let rho = coil * (1.0 - 0.55 * t) * wobble;
            [
                centre[0] + z_amp * (std::f64::consts::TAU * 1.25 * t + z_phase).sin(),
                centre[1] + rho * angle.sin(),
                centre[2] + rho * angle.cos(),
            ]
        };
        // Segments about a voxel and a half long.
        let steps = ((std::f64::consts::TAU * turns * coil / 1.5).ceil() as usize).max(32);
        let radius = |t: f64| tube * (0.5 + 0.5 * smoothstep(0.0, 0.25, t));
        let spine: Vec<([f64; 3], f64)> = (0..=steps)
            .map(|i| {
                let t = i as f64 / steps as f64;
                (point(t), radius(t))
            })
            .collect();
        let length: f64 = spine
            .windows(2)
            .map(|w| segment_distance(w[0].0, w[1].0, w[1].0))
            .sum();

        // Pairs of ribs every 2.2 tube radii along the body (not on the tail tip or the head).
        let rib_radius = (0.18 * tube).max(0.7);
        let pairs = (length * 0.85 / (2.2 * tube)) as usize;
        let mut ribs = Vec::with_capacity(2 * pairs);
        for i in 0..pairs {
            let t = 0.08 + 0.85 * (i as f64 + 0.5) / pairs as f64;
            let (p, q) = (point(t), point(t + 1e-4));
            let (ty, tx) = (q[1] - p[1], q[2] - p[2]);
            let len = (ty * ty + tx * tx).sqrt().max(1e-12);
            let outward = [0.0, -tx / len, ty / len];
            let reach = 2.2 * radius(t);
            for side in [1.0, -1.0] {
                let n = outward.map(|v| v * side);
                ribs.push(std::array::from_fn(|j| {
                    let s = j as f64 / (RIB_POINTS - 1) as f64;
                    let out = 0.9 * radius(t) + s * reach;
                    [
                        p[0] - s * s * reach * 0.7,
                        p[1] + out * n[1],
                        p[2] + out * n[2],
                    ]
                }));
            }
        }

        // Two dense blobs at the head, two more along the coil.
        let blob_size = (0.012 * m).max(1.0);
        let blobs = [0.97, 0.985, 0.3 + 0.3 * r(4), 0.62 + 0.2 * r(5)]
            .iter()
            .enumerate()
            .map(|(j, &t)| {
                let c = point(t);
                let j = j as u64;
                let offset: [f64; 3] =
                    std::array::from_fn(|a| (r(10 + 3 * j + a as u64) - 0.5) * radius(t));
                Blob {
                    centre: std::array::from_fn(|a| c[a] + offset[a]),
                    radii: std::array::from_fn(|a| {
                        blob_size * (1.0 + unit(hash(seed ^ 0xB10B ^ (j << 8) ^ a as u64)))
                    }),
                }
            })
            .collect();
        Self {
            shape,
            channels,
            seed,
            spine,
            wall,
            flesh,
            ribs,
            rib_radius,
            blobs,
        }
    }

    /// Pixel bounds `[y0, y1) × [x0, x1)` of the box around points `pts` grown by `reach`, or
    /// `None` when plane `wz` is farther than `reach` from them in z.
    fn bounds(&self, wz: f64, pts: &[[f64; 3]], reach: f64) -> Option<[u64; 4]> {
        let lo = |a: usize| pts.iter().map(|p| p[a]).fold(f64::INFINITY, f64::min) - reach;
        let hi = |a: usize| pts.iter().map(|p| p[a]).fold(f64::NEG_INFINITY, f64::max) + reach;
        if wz < lo(0) || wz > hi(0) {
            return None;
        }
        let [_, ny, nx] = self.shape;
        let clip = |v: f64, n: u64| v.floor().clamp(0.0, n as f64) as u64;
        let b = [
            clip(lo(1), ny),
            clip(hi(1) + 1.0, ny),
            clip(lo(2), nx),
            clip(hi(2) + 1.0, nx),
        ];
        (b[0] < b[1] && b[2] < b[3]).then_some(b)
    }

    /// Plane `z` of the scan, before any window.
    pub(crate) fn scan_plane(&self, z: u64) -> Vec<u16> {
        let [_, ny, nx] = self.shape;
        let n = (ny * nx) as usize;
        let wz = z as f64 + 0.5;
        let mut value = vec![0u16; n];
        // Signed distance to the spine's surface (negative inside the tube), as the minimum
        // over its capsules.
        let mut surface = vec![f64::INFINITY; n];
        let mut touched = false;
        for w in self.spine.windows(2) {
            let ((a, ra), (b, rb)) = (w[0], w[1]);
            let r = 0.5 * (ra + rb);
            let Some([y0, y1, x0, x1]) = self.bounds(wz, &[a, b], r + self.flesh + 1.0) else {
                continue;
            };
            touched = true;
            for y in y0..y1 {
                for x in x0..x1 {
                    let p = [wz, y as f64 + 0.5, x as f64 + 0.5];
                    let i = (y * nx + x) as usize;
                    surface[i] = surface[i].min(segment_distance(p, a, b) - r);
                }
            }
        }
        if touched {
            for y in 0..ny {
                for x in 0..nx {
                    let i = (y * nx + x) as usize;
                    let d = surface[i];
                    if d < self.flesh {
                        let p = [wz, y as f64 + 0.5, x as f64 + 0.5];
                        let texture = fbm3(self.seed ^ 0x7E47, p.map(|v| v / 4.0), 2);
                        let (lo, hi) = if d.abs() < self.wall { SHELL } else { SOFT };
                        value[i] = lo + (f64::from(hi - lo) * texture) as u16;
                    }
                }
            }
        }
        for rib in &self.ribs {
            let reach = self.rib_radius + 1.0;
            if self.bounds(wz, rib, reach).is_none() {
                continue;
            }
            for w in rib.windows(2) {
                let Some([y0, y1, x0, x1]) = self.bounds(wz, w, reach) else {
                    continue;
                };
                for y in y0..y1 {
                    for x in x0..x1 {
                        let p = [wz, y as f64 + 0.5, x as f64 + 0.5];
                        let d = segment_distance(p, w[0], w[1]);
                        if d < self.rib_radius {
                            let span = f64::from(RIB.1 - RIB.0);
                            let v = RIB.0 + (span * (1.0 - d / self.rib_radius)) as u16;
                            let i = (y * nx + x) as usize;
                            value[i] = value[i].max(v);
                        }
                    }
                }
            }
        }
        for blob in &self.blobs {
            let reach = blob.radii.iter().copied().fold(0.0, f64::max) + 1.0;
            let Some([y0, y1, x0, x1]) = self.bounds(wz, &[blob.centre], reach) else {
                continue;
            };
            for y in y0..y1 {
                for x in x0..x1 {
                    let p = [wz, y as f64 + 0.5, x as f64 + 0.5];
                    let q: f64 = (0..3)
                        .map(|a| ((p[a] - blob.centre[a]) / blob.radii[a]).powi(2))
                        .sum();
                    if q < 1.0 {
                        let span = f64::from(BLOB.1 - BLOB.0);
                        let v = BLOB.0 + (span * (1.0 - q)) as u16;
                        let i = (y * nx + x) as usize;
                        value[i] = value[i].max(v);
                    }
                }
            }
        }
        // Air: per-voxel noise, a function of the voxel's position and the seed alone.
        for (i, v) in value.iter_mut().enumerate() {
            if *v == 0 {
                let h = hash(self.seed ^ 0xA1F0_0000_0000 ^ (z * ny * nx + i as u64));
                *v = 1 + (unit(h) * f64::from(AIR_MAX - 1)) as u16;
            }
        }
        value
    }
}

impl Scene for SparseScene {
    fn shape(&self) -> [u64; 3] {
        self.shape
    }

    fn voxel_size(&self) -> [f64; 3] {
        [1.0; 3]
    }

    fn channels(&self) -> Vec<ChannelSpec> {
        ChannelSpec::transfer_channels("sparse", SampleType::U16, self.channels, |k| {
            format!("above{}", window_threshold(k, self.channels))
        })
    }

    fn render_plane(&self, z: u64) -> Vec<PlaneData> {
        let scan = self.scan_plane(z);
        (0..self.channels)
            .map(|k| PlaneData::U16(scan.iter().map(|&v| window(v, k, self.channels)).collect()))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_keep_zero_and_rise_with_the_channel() {
        assert_eq!(window(0, 3, 4), 0);
        assert_eq!(window(1234, 0, 4), 1234);
        assert_eq!(window_threshold(1, 4), 1875);
        assert_eq!(window_threshold(3, 4), 3625);
        assert_eq!(window(1874, 1, 4), 0);
        assert_eq!(window(1875, 1, 4), 1);
        assert_eq!(window(SPARSE_MAX, 1, 4), 60_001);
        assert_eq!(window(3624, 3, 4), 0);
        assert_eq!(window(SPARSE_MAX, 3, 4), 60_001);
    }

    #[test]
    fn scan_holds_every_material_and_is_mostly_empty() {
        let scene = SparseScene::new([48, 96, 96], 1, 3);
        let (mut soft, mut shell, mut rib, mut blob, mut air, mut total) = (0, 0, 0, 0, 0, 0);
        for z in 0..48 {
            for v in scene.scan_plane(z) {
                total += 1;
                match v {
                    v if v < AIR_MAX => air += 1,
                    v if v < SOFT.1 => soft += 1,
                    v if v < SHELL.1 => shell += 1,
                    v if v <= RIB.1 => rib += 1,
                    v if v >= BLOB.0 => blob += 1,
                    v => panic!("value {v} of no material"),
                }
            }
        }
        assert!(
            soft > shell && shell > 0 && rib > 0 && blob > 0,
            "{soft} {shell} {rib} {blob}"
        );
        assert!(air * 100 > total * 80, "{air} of {total} voxels are air");
    }
}
