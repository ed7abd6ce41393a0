//! `ingest sample`: a deterministic synthetic fluorescence stack, generated plane by plane.
//!
//! It looks like a cleared-tissue light-sheet acquisition: an ellipsoidal piece of tissue in
//! mostly empty space, with nuclei (a 16-bit channel), cell membranes around them and thin
//! filaments (8-bit channels), camera noise inside the tissue and anisotropic voxels
//! (z spacing 4× the xy spacing). Each channel is written as a BigTIFF OME-TIFF with its
//! physical voxel size, so the sample exercises the TIFF path of `ingest convert`.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use rayon::prelude::*;
use tiff::encoder::{TiffEncoder, colortype};
use tiff::tags::Tag;

/// Voxel size of the sample in micrometres, `z, y, x`.
pub const SAMPLE_VOXEL_SIZE: [f64; 3] = [2.0, 0.5, 0.5];

/// Channel file names of the sample, in channel order.
pub const SAMPLE_CHANNELS: [&str; 3] = ["nuclei", "membranes", "filaments"];

/// A stateless hash of a 64-bit value (SplitMix64 finaliser), used for noise and placement.
fn hash(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Uniform in `[0, 1)` from a hash.
fn unit(h: u64) -> f64 {
    (h >> 11) as f64 / (1u64 << 53) as f64
}

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
                let reach = 15.0 + 40.0 * unit(hash(h ^ 99));
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

fn ome_xml(shape: [u64; 3], name: &str, kind: &str) -> String {
    let [z, y, x] = shape;
    let [pz, py, px] = SAMPLE_VOXEL_SIZE;
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?><OME xmlns="http://www.openmicroscopy.org/Schemas/OME/2016-06"><Image ID="Image:0" Name="{name}"><Pixels ID="Pixels:0" DimensionOrder="XYZCT" Type="{kind}" SizeX="{x}" SizeY="{y}" SizeZ="{z}" SizeC="1" SizeT="1" PhysicalSizeX="{px}" PhysicalSizeY="{py}" PhysicalSizeZ="{pz}" PhysicalSizeXUnit="&#xB5;m" PhysicalSizeYUnit="&#xB5;m" PhysicalSizeZUnit="&#xB5;m"><Channel ID="Channel:0:0" Name="{name}" SamplesPerPixel="1"/><TiffData/></Pixels></Image></OME>"#
    )
}

/// Writes the sample stack of `shape` into `dir`, one OME-TIFF per channel, and returns the
/// file paths in channel order.
pub fn write_sample(
    dir: &Path,
    shape: [u64; 3],
    seed: u64,
    progress: bool,
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create folder", dir.display()))?;
    let scene = SampleScene::new(shape, seed);
    let paths: Vec<PathBuf> = SAMPLE_CHANNELS
        .iter()
        .map(|c| dir.join(format!("{c}.ome.tif")))
        .collect();
    let partial: Vec<PathBuf> = paths
        .iter()
        .map(|p| p.with_extension("tif.partial"))
        .collect();
    let open = |p: &PathBuf| -> Result<TiffEncoder<BufWriter<File>, tiff::encoder::TiffKindBig>> {
        let f = File::create(p).with_context(|| format!("{}: cannot create", p.display()))?;
        TiffEncoder::new_big(BufWriter::with_capacity(1 << 20, f))
            .with_context(|| format!("{}: cannot start TIFF", p.display()))
    };
    let mut enc: Vec<_> = partial.iter().map(open).collect::<Result<_>>()?;
    let [depth, ny, nx] = shape;
    let bar = if progress {
        ProgressBar::with_draw_target(Some(depth), ProgressDrawTarget::stderr())
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("{spinner} sample [{elapsed_precise}] [{wide_bar}] {pos}/{len} planes {per_sec} ETA {eta}")
            .expect("template"),
    );
    let batch = 16u64;
    let mut z0 = 0;
    while z0 < depth {
        let planes: Vec<_> = (z0..(z0 + batch).min(depth))
            .into_par_iter()
            .map(|z| scene.plane(z))
            .collect();
        for (dz, (nuc, mem, fil)) in planes.into_iter().enumerate() {
            let first = z0 == 0 && dz == 0;
            let write = |e: &mut TiffEncoder<_, _>,
                         name: &str,
                         kind: &str,
                         data: Plane<'_>|
             -> Result<()> {
                macro_rules! image {
                    ($ct:ty, $d:expr) => {{
                        let mut img = e.new_image::<$ct>(nx as u32, ny as u32)?;
                        if first {
                            img.encoder().write_tag(
                                Tag::ImageDescription,
                                ome_xml(shape, name, kind).as_str(),
                            )?;
                        }
                        img.write_data($d)?;
                    }};
                }
                match data {
                    Plane::U16(d) => image!(colortype::Gray16, d),
                    Plane::U8(d) => image!(colortype::Gray8, d),
                }
                Ok(())
            };
            write(&mut enc[0], SAMPLE_CHANNELS[0], "uint16", Plane::U16(&nuc))
                .with_context(|| format!("{}: cannot write", paths[0].display()))?;
            write(&mut enc[1], SAMPLE_CHANNELS[1], "uint8", Plane::U8(&mem))
                .with_context(|| format!("{}: cannot write", paths[1].display()))?;
            write(&mut enc[2], SAMPLE_CHANNELS[2], "uint8", Plane::U8(&fil))
                .with_context(|| format!("{}: cannot write", paths[2].display()))?;
            bar.inc(1);
        }
        z0 += batch;
    }
    drop(enc);
    for (p, f) in partial.iter().zip(&paths) {
        std::fs::rename(p, f)
            .with_context(|| format!("{}: cannot move into place", f.display()))?;
    }
    bar.finish_and_clear();
    Ok(paths)
}

enum Plane<'a> {
    U16(&'a [u16]),
    U8(&'a [u8]),
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
