//! Stateless pseudo-random numbers and value noise shared by every synthetic sample.
//!
//! Everything here is a pure function of a seed and integer or real coordinates, so any voxel
//! can be generated independently of every other one: planes are rendered in parallel, in any
//! order, and come out bit for bit the same on every run.

/// A stateless hash of a 64-bit value (SplitMix64 finaliser), used for noise and placement.
pub(crate) fn hash(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Uniform in `[0, 1)` from a hash.
pub(crate) fn unit(h: u64) -> f64 {
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Uniform in `[0, 1)` at an integer lattice point.
fn lattice(seed: u64, z: i64, y: i64, x: i64) -> f64 {
    unit(hash(
        seed ^ (z as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
            ^ (x as u64).wrapping_mul(0x1656_67B1_9E37_79F9),
    ))
}

/// Quintic fade `6t⁵ − 15t⁴ + 10t³`: zero first and second derivatives at 0 and 1.
fn fade(t: f64) -> f64 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

fn lerp(a: f64, b: f64, t: f64) -> f64 {
    a + (b - a) * t
}

/// Smooth 3-D value noise in `[0, 1)`: random values on the integer lattice, interpolated
/// with the quintic fade. `p` is `z, y, x` in lattice units.
pub(crate) fn value_noise3(seed: u64, p: [f64; 3]) -> f64 {
    let f = p.map(f64::floor);
    let [z, y, x] = f.map(|v| v as i64);
    let [tz, ty, tx] = std::array::from_fn(|a| fade(p[a] - f[a]));
    let plane = |z: i64| {
        let row = |y: i64| lerp(lattice(seed, z, y, x), lattice(seed, z, y, x + 1), tx);
        lerp(row(y), row(y + 1), ty)
    };
    lerp(plane(z), plane(z + 1), tz)
}

/// Smooth 2-D value noise in `[0, 1)` (`y, x` in lattice units).
pub(crate) fn value_noise2(seed: u64, p: [f64; 2]) -> f64 {
    let f = p.map(f64::floor);
    let [y, x] = f.map(|v| v as i64);
    let [ty, tx] = std::array::from_fn(|a| fade(p[a] - f[a]));
    let row = |y: i64| lerp(lattice(seed, 0, y, x), lattice(seed, 0, y, x + 1), tx);
    lerp(row(y), row(y + 1), ty)
}

/// The seed of octave `o` of fractal noise with `seed`.
fn octave_seed(seed: u64, o: u32) -> u64 {
    hash(seed ^ u64::from(o).wrapping_mul(0xA24B_AED4_963E_E407))
}

/// Fractal (multi-octave) value noise in `[0, 1)` over `N` dimensions: `octaves` layers of
/// `noise`, each at twice the frequency and half the amplitude of the previous one, normalised
/// by the total amplitude.
fn fractal<const N: usize>(
    seed: u64,
    p: [f64; N],
    octaves: u32,
    noise: fn(u64, [f64; N]) -> f64,
) -> f64 {
    let (mut sum, mut total, mut amp, mut freq) = (0.0, 0.0, 1.0, 1.0);
    for o in 0..octaves {
        sum += amp * noise(octave_seed(seed, o), p.map(|v| v * freq));
        total += amp;
        amp *= 0.5;
        freq *= 2.0;
    }
    sum / total
}

/// Fractal 3-D value noise in `[0, 1)`: [`fractal`] layers of [`value_noise3`].
pub(crate) fn fbm3(seed: u64, p: [f64; 3], octaves: u32) -> f64 {
    fractal(seed, p, octaves, value_noise3)
}

/// Fractal 2-D value noise in `[0, 1)`, as [`fbm3`].
pub(crate) fn fbm2(seed: u64, p: [f64; 2], octaves: u32) -> f64 {
    fractal(seed, p, octaves, value_noise2)
}

/// Fractal value noise over one plane of constant z, with the lattice values the plane needs
/// computed once: [`NoisePlane::at`] equals [`fbm3`] (or [`fbm2`] for a 2-D plane) at the same
/// point, bit for bit, for a fraction of the hashing.
pub(crate) struct NoisePlane {
    octaves: Vec<OctavePlane>,
    total: f64,
}

/// One octave's lattice values over the plane: `layers` z-layers of `rows × width` values.
struct OctavePlane {
    amp: f64,
    freq: f64,
    /// Fade weight between the two z-layers (3-D), or `None` (2-D, one layer).
    tz: Option<f64>,
    y0: i64,
    x0: i64,
    rows: usize,
    width: usize,
    values: Vec<f64>,
}

impl NoisePlane {
    /// The noise of `fbm3(seed, [z, y, x], octaves)` (or of `fbm2(seed, [y, x], octaves)` when
    /// `z` is `None`) for `y` in `0..=y_max` and `x` in `0..=x_max`.
    pub(crate) fn new(seed: u64, z: Option<f64>, y_max: f64, x_max: f64, octaves: u32) -> Self {
        let (mut amp, mut freq, mut total) = (1.0, 1.0, 0.0);
        let octaves = (0..octaves)
            .map(|o| {
                let s = octave_seed(seed, o);
                let (iz, tz) = match z {
                    Some(z) => {
                        let zf = z * freq;
                        let f = zf.floor();
                        (f as i64, Some(fade(zf - f)))
                    }
                    None => (0, None),
                };
                let (y0, x0) = (0i64, 0i64);
                let rows = (y_max * freq).floor() as usize + 2;
                let width = (x_max * freq).floor() as usize + 2;
                let layers = if tz.is_some() { 2 } else { 1 };
                let mut values = Vec::with_capacity(layers * rows * width);
                for l in 0..layers as i64 {
                    for y in 0..rows as i64 {
                        for x in 0..width as i64 {
                            values.push(lattice(s, iz + l, y0 + y, x0 + x));
                        }
                    }
                }
                let octave = OctavePlane {
                    amp,
                    freq,
                    tz,
                    y0,
                    x0,
                    rows,
                    width,
                    values,
                };
                total += amp;
                amp *= 0.5;
                freq *= 2.0;
                octave
            })
            .collect();
        Self { octaves, total }
    }

    /// The noise at `(y, x)` of the plane.
    pub(crate) fn at(&self, y: f64, x: f64) -> f64 {
        let mut sum = 0.0;
        for o in &self.octaves {
            let (py, px) = (y * o.freq, x * o.freq);
            let (fy, fx) = (py.floor(), px.floor());
            let iy = (fy as i64 - o.y0) as usize;
            let ix = (fx as i64 - o.x0) as usize;
            debug_assert!(iy + 1 < o.rows && ix + 1 < o.width);
            let (ty, tx) = (fade(py - fy), fade(px - fx));
            let layer = |l: usize| {
                let row = |r: usize| {
                    let i = (l * o.rows + r) * o.width + ix;
                    lerp(o.values[i], o.values[i + 1], tx)
                };
                lerp(row(iy), row(iy + 1), ty)
            };
            let v = match o.tz {
                Some(tz) => lerp(layer(0), layer(1), tz),
                None => layer(0),
            };
            sum += o.amp * v;
        }
        sum / self.total
    }
}

/// Hermite smoothstep: 0 below `a`, 1 above `b`, smooth in between.
pub(crate) fn smoothstep(a: f64, b: f64, v: f64) -> f64 {
    let t = ((v - a) / (b - a)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Distance from `p` to the segment `a`–`b` (all `z, y, x`).
pub(crate) fn segment_distance(p: [f64; 3], a: [f64; 3], b: [f64; 3]) -> f64 {
    let ab: [f64; 3] = std::array::from_fn(|k| b[k] - a[k]);
    let ap: [f64; 3] = std::array::from_fn(|k| p[k] - a[k]);
    let ab2 = ab.iter().map(|v| v * v).sum::<f64>();
    let t = if ab2 > 0.0 {
        (ap.iter().zip(&ab).map(|(a, b)| a * b).sum::<f64>() / ab2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (0..3)
        .map(|k| (ap[k] - t * ab[k]).powi(2))
        .sum::<f64>()
        .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_continuous_bounded_and_hits_the_lattice_values() {
        let seed = 7;
        // On lattice points the noise is the lattice value itself.
        assert_eq!(
            value_noise3(seed, [2.0, -3.0, 5.0]),
            lattice(seed, 2, -3, 5)
        );
        assert_eq!(value_noise2(seed, [-1.0, 4.0]), lattice(seed, 0, -1, 4));
        let mut previous = value_noise3(seed, [0.3, 0.7, 0.0]);
        for i in 1..2000 {
            let p = [0.3, 0.7, i as f64 * 0.01];
            let v = value_noise3(seed, p);
            assert!((0.0..1.0).contains(&v), "{v} at {p:?}");
            // The fade's slope is at most 15/8, so 0.01 apart moves at most 0.019.
            assert!((v - previous).abs() <= 0.019, "jump at {p:?}");
            previous = v;
            let f = fbm3(seed, p, 4);
            assert!((0.0..1.0).contains(&f));
            let g = fbm2(seed, [p[1], p[2]], 3);
            assert!((0.0..1.0).contains(&g));
        }
        assert_ne!(value_noise3(1, [0.5; 3]), value_noise3(2, [0.5; 3]));
    }

    #[test]
    fn noise_planes_equal_the_direct_noise_bit_for_bit() {
        for (z, octaves) in [(Some(3.7), 4), (Some(0.0), 1), (None, 3)] {
            let plane = NoisePlane::new(11, z, 5.0, 7.5, octaves);
            for i in 0..=50 {
                for j in 0..=75 {
                    let (y, x) = (i as f64 * 0.1, j as f64 * 0.1);
                    let direct = match z {
                        Some(z) => fbm3(11, [z, y, x], octaves),
                        None => fbm2(11, [y, x], octaves),
                    };
                    assert_eq!(plane.at(y, x).to_bits(), direct.to_bits(), "{z:?} {y} {x}");
                }
            }
        }
    }

    #[test]
    fn segment_distance_is_exact_on_simple_cases() {
        let (a, b) = ([0.0, 0.0, 0.0], [0.0, 0.0, 10.0]);
        assert_eq!(segment_distance([0.0, 3.0, 5.0], a, b), 3.0);
        assert_eq!(segment_distance([0.0, 0.0, -4.0], a, b), 4.0);
        assert_eq!(segment_distance([0.0, 4.0, 13.0], a, b), 5.0);
        assert_eq!(segment_distance([1.0, 0.0, 0.0], a, a), 1.0);
        assert_eq!(smoothstep(0.0, 1.0, -1.0), 0.0);
        assert_eq!(smoothstep(0.0, 1.0, 0.5), 0.5);
        assert_eq!(smoothstep(0.0, 1.0, 2.0), 1.0);
    }
}
