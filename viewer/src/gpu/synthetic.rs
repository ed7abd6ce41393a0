//! An in-memory [`BrickSource`] over a synthetic volume, for tests and benchmarks: a pyramid
//! built by mean downsampling, haloed min/max grids like the server's, a log of every brick
//! fetched, and injectable failures (errors and corrupt bricks).

use std::collections::HashSet;
use std::sync::Mutex;

use crate::source::{
    BrickKey, BrickSource, BrickVoxels, ChannelDisplay, LevelInfo, MinMaxGrid, SampleType,
    SourceError, VolumeInfo,
};

/// A synthetic multi-channel volume held in memory.
pub struct SyntheticSource {
    info: VolumeInfo,
    /// `data[channel][level]`: stored values as `f64`, `z`-major.
    data: Vec<Vec<Vec<f64>>>,
    log: Mutex<Vec<BrickKey>>,
    failing: HashSet<BrickKey>,
    corrupt: HashSet<BrickKey>,
}

impl std::fmt::Debug for SyntheticSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SyntheticSource")
            .field("info", &self.info)
            .finish_non_exhaustive()
    }
}

fn quantize(t: SampleType, v: f64) -> f64 {
    match t {
        SampleType::U8 => v.round().clamp(0.0, 255.0),
        SampleType::U16 => v.round().clamp(0.0, 65535.0),
        SampleType::I16 => v.round().clamp(-32768.0, 32767.0),
        SampleType::U32 => v.round().clamp(0.0, u32::MAX as f64),
        SampleType::I32 => v.round().clamp(i32::MIN as f64, i32::MAX as f64),
        SampleType::F32 => v as f32 as f64,
    }
}

impl SyntheticSource {
    /// A volume of `shape` voxels (`z, y, x`), `channels` channels whose level-0 value at voxel
    /// `(x, y, z)` of channel `c` is `value(c, [x, y, z])` (quantised to `sample_type`), stored
    /// in bricks of `brick` voxels, with min/max cells of `cell` voxels. Coarser levels halve
    /// every axis longer than one voxel (mean of the voxels that exist) until the level fits
    /// in one brick.
    pub fn new(
        sample_type: SampleType,
        shape: [u64; 3],
        voxel_size: [f64; 3],
        brick: [u64; 3],
        cell: u64,
        channels: usize,
        value: impl Fn(usize, [u64; 3]) -> f64,
    ) -> Self {
        let mut levels = vec![LevelInfo {
            shape,
            factor: [1, 1, 1],
        }];
        loop {
            let last = levels.last().expect("level 0").clone();
            if (0..3).all(|a| last.shape[a] <= brick[a]) {
                break;
            }
            let halve: [bool; 3] = std::array::from_fn(|a| last.shape[a] > 1);
            levels.push(LevelInfo {
                shape: std::array::from_fn(|a| {
                    if halve[a] {
                        last.shape[a].div_ceil(2)
                    } else {
                        last.shape[a]
                    }
                }),
                factor: std::array::from_fn(|a| last.factor[a] * if halve[a] { 2 } else { 1 }),
            });
        }
        let mut data = Vec::new();
        for c in 0..channels {
            let mut per_level: Vec<Vec<f64>> = Vec::new();
            let [nz, ny, nx] = shape;
            let mut l0 = Vec::with_capacity((nx * ny * nz) as usize);
            for z in 0..nz {
                for y in 0..ny {
                    for x in 0..nx {
                        l0.push(quantize(sample_type, value(c, [x, y, z])));
                    }
                }
            }
            per_level.push(l0);
            for l in 1..levels.len() {
                let (ps, s) = (levels[l - 1].shape, levels[l].shape);
                let ratio: [u64; 3] =
                    std::array::from_fn(|a| levels[l].factor[a] / levels[l - 1].factor[a]);
                let prev = &per_level[l - 1];
                let mut out = Vec::with_capacity((s[0] * s[1] * s[2]) as usize);
                for z in 0..s[0] {
                    for y in 0..s[1] {
                        for x in 0..s[2] {
                            let (mut sum, mut n) = (0.0, 0.0);
                            for dz in 0..ratio[0] {
                                for dy in 0..ratio[1] {
                                    for dx in 0..ratio[2] {
                                        let (pz, py, px) = (
                                            z * ratio[0] + dz,
                                            y * ratio[1] + dy,
                                            x * ratio[2] + dx,
                                        );
                                        if pz < ps[0] && py < ps[1] && px < ps[2] {
                                            sum += prev[((pz * ps[1] + py) * ps[2] + px) as usize];
                                            n += 1.0;
                                        }
                                    }
                                }
                            }
                            out.push(quantize(sample_type, sum / n));
                        }
                    }
                }
                per_level.push(out);
            }
            data.push(per_level);
        }
        let mut minmax = Vec::new();
        for per_level in &data {
            let mut grids = Vec::new();
            for (l, values) in per_level.iter().enumerate() {
                grids.push(vec![haloed_grid(values, levels[l].shape, cell)]);
            }
            minmax.push(grids);
        }
        let info = VolumeInfo {
            name: "synthetic".into(),
            sample_type,
            channels: (0..channels).map(|c| format!("c{c}")).collect(),
            display: vec![ChannelDisplay::default(); channels],
            voxel_size,
            unit: None,
            brick_shape: brick,
            levels,
            minmax: Some(minmax),
        };
        Self {
            info,
            data,
            log: Mutex::new(Vec::new()),
            failing: HashSet::new(),
            corrupt: HashSet::new(),
        }
    }

    /// Drops the region metadata, as a store without it would.
    pub fn without_minmax(mut self) -> Self {
        self.info.minmax = None;
        self
    }

    /// Makes `key` fail to fetch with an error (as a 404 would).
    pub fn fail(mut self, key: BrickKey) -> Self {
        self.failing.insert(key);
        self
    }

    /// Makes `key` return a brick of the wrong size (as a corrupt chunk would decode).
    pub fn corrupt(mut self, key: BrickKey) -> Self {
        self.corrupt.insert(key);
        self
    }

    /// Every key fetched so far, in order.
    pub fn fetch_log(&self) -> Vec<BrickKey> {
        self.log.lock().expect("log lock").clone()
    }

    /// Stored value of voxel `(x, y, z)` of `channel` at `level`.
    pub fn value(&self, channel: usize, level: usize, xyz: [u64; 3]) -> f64 {
        let s = self.info.levels[level].shape;
        self.data[channel][level][((xyz[2] * s[1] + xyz[1]) * s[2] + xyz[0]) as usize]
    }

    fn brick(&self, key: &BrickKey) -> Result<BrickVoxels, SourceError> {
        self.info.check_key(key)?;
        if self.failing.contains(key) {
            return Err(SourceError::InjectedFailure { key: *key });
        }
        let b = self.info.brick_shape;
        let s = self.info.levels[key.level as usize].shape;
        let values = &self.data[key.channel as usize][key.level as usize];
        let mut out = Vec::with_capacity((b[0] * b[1] * b[2]) as usize);
        for z in 0..b[0] {
            for y in 0..b[1] {
                for x in 0..b[2] {
                    let (gz, gy, gx) = (
                        key.brick[0] * b[0] + z,
                        key.brick[1] * b[1] + y,
                        key.brick[2] * b[2] + x,
                    );
                    out.push(if gz < s[0] && gy < s[1] && gx < s[2] {
                        values[((gz * s[1] + gy) * s[2] + gx) as usize]
                    } else {
                        0.0
                    });
                }
            }
        }
        if self.corrupt.contains(key) {
            out.truncate(out.len() / 2);
        } else if out.iter().all(|&v| v == 0.0) {
            return Ok(BrickVoxels::Empty);
        }
        Ok(match self.info.sample_type {
            SampleType::U8 => BrickVoxels::U8(out.iter().map(|&v| v as u8).collect()),
            SampleType::U16 => BrickVoxels::U16(out.iter().map(|&v| v as u16).collect()),
            SampleType::I16 => BrickVoxels::I16(out.iter().map(|&v| v as i16).collect()),
            SampleType::U32 => BrickVoxels::U32(out.iter().map(|&v| v as u32).collect()),
            SampleType::I32 => BrickVoxels::I32(out.iter().map(|&v| v as i32).collect()),
            SampleType::F32 => BrickVoxels::F32(out.iter().map(|&v| v as f32).collect()),
        })
    }
}

/// Haloed min/max over cells of `cell³` voxels: each cell covers the voxels a trilinear sample
/// inside it can read (one more voxel on each side, clamped to the level).
fn haloed_grid(values: &[f64], shape: [u64; 3], cell: u64) -> MinMaxGrid {
    let grid: [u64; 3] = shape.map(|s| s.div_ceil(cell));
    let (mut min, mut max) = (Vec::new(), Vec::new());
    for gz in 0..grid[0] {
        for gy in 0..grid[1] {
            for gx in 0..grid[2] {
                let g = [gz, gy, gx];
                let r: [(u64, u64); 3] = std::array::from_fn(|a| {
                    (
                        (g[a] * cell).saturating_sub(1),
                        ((g[a] + 1) * cell + 1).min(shape[a]),
                    )
                });
                let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
                for z in r[0].0..r[0].1 {
                    for y in r[1].0..r[1].1 {
                        for x in r[2].0..r[2].1 {
                            let v = values[((z * shape[1] + y) * shape[2] + x) as usize];
                            if !v.is_nan() {
                                lo = lo.min(v);
                                hi = hi.max(v);
                            }
                        }
                    }
                }
                if lo > hi {
                    (lo, hi) = (f64::NAN, f64::NAN);
                }
                min.push(lo);
                max.push(hi);
            }
        }
    }
    MinMaxGrid {
        cell_shape: [cell; 3],
        grid_shape: grid,
        min,
        max,
    }
}

impl BrickSource for SyntheticSource {
    fn info(&self) -> &VolumeInfo {
        &self.info
    }

    fn fetch(&self, keys: &[BrickKey]) -> Vec<Result<BrickVoxels, SourceError>> {
        self.log.lock().expect("log lock").extend_from_slice(keys);
        keys.iter().map(|k| self.brick(k)).collect()
    }
}
