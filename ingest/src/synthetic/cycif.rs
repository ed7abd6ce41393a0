//! The `cycif` sample: a thin tissue section imaged by cyclic immunofluorescence (CyCIF), many
//! markers on the same cells.
//!
//! A section a few tens of micrometres thick (anisotropic voxels: 1 µm in z, 0.325 µm in x and
//! y, as a 20× objective gives) is packed with cells: nuclei laid out in the xy plane on a
//! jittered grid about 8 µm apart, with gaps where the tissue tore or a lumen opens. Each cell
//! has a type: epithelial cells grow in glandular patches, the stroma between them holds
//! fibroblasts, endothelial cells and immune cells (helper and cytotoxic T cells, B cells,
//! macrophages). Every channel is one antibody: DAPI stains every nucleus; the others stain
//! one compartment (nucleus, membrane or cytoplasm) of the cells whose type carries the marker,
//! and some only a random subset of them (Ki-67 marks the proliferating ones), so each channel
//! is bright in a different subset of cells. Between cells the background is near zero: a
//! camera offset with noise and a little autofluorescence in the tissue.
//!
//! The first 16 channels follow a typical panel (`dapi`, `keratin`, `cd45`, `cd3`, `cd8`,
//! `cd4`, `cd20`, `cd68`, `ki67`, `ecad`, `vimentin`, `sma`, `cd31`, `foxp3`, `pd1`, `pdl1`);
//! more channels are further markers (`marker16`, ...) on random subsets of cells.

use super::noise::{fbm2, hash, smoothstep, unit, value_noise3};
use super::ome_tiff::{ChannelSpec, PlaneData, Scene};
use crate::sample_format::SampleType;

/// Voxel size of the sample in micrometres, `z, y, x`.
pub const CYCIF_VOXEL_SIZE: [f64; 3] = [1.0, 0.325, 0.325];

/// Distance between neighbouring cell centres on the grid, in µm.
const SPACING: f64 = 8.0;
/// A cell reaches at most this far from its centre, in µm.
const CELL_RADIUS: f64 = 6.0;
/// Membrane thickness, in µm.
const MEMBRANE: f64 = 0.7;
/// Camera offset of every pixel.
const OFFSET: u16 = 60;
/// Camera noise: uniform in `0..=NOISE` above the offset.
const NOISE: u64 = 63;
/// Autofluorescence added inside cells.
const AUTOFLUORESCENCE: u16 = 40;
/// Largest background value: camera offset, its noise and tissue autofluorescence.
#[cfg(test)]
const BACKGROUND_MAX: u16 = OFFSET + NOISE as u16 + AUTOFLUORESCENCE;

/// The cell types of the tissue.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum CellType {
    /// Epithelium (glands).
    Epithelial,
    /// Fibroblasts and smooth muscle of the stroma.
    Stromal,
    /// Blood vessel lining.
    Endothelial,
    /// CD4 helper T cells.
    HelperT,
    /// CD8 cytotoxic T cells.
    CytotoxicT,
    /// B cells.
    B,
    /// Macrophages.
    Macrophage,
}

use CellType::{B, CytotoxicT, Endothelial, Epithelial, HelperT, Macrophage, Stromal};

/// Where in the cell a marker binds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Compartment {
    /// The nucleus (DNA stains, transcription factors, Ki-67).
    Nucleus,
    /// The cell membrane (CD antigens, E-cadherin).
    Membrane,
    /// The cytoplasm (keratins, vimentin, actin).
    Cytoplasm,
}

use Compartment::{Cytoplasm, Membrane, Nucleus};

/// One antibody of the panel.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Marker {
    /// Channel name.
    pub name: String,
    /// The stained compartment.
    pub compartment: Compartment,
    /// Cell types that carry the marker (`None`: any type).
    pub types: Option<&'static [CellType]>,
    /// Fraction of those cells that are positive.
    pub fraction: f64,
    /// Brightness of a fully positive cell.
    pub peak: f64,
}

const ALL: &[CellType] = &[
    Epithelial,
    Stromal,
    Endothelial,
    HelperT,
    CytotoxicT,
    B,
    Macrophage,
];

/// The first channels: name, compartment, cell types, positive fraction, peak.
const PANEL: [(&str, Compartment, &[CellType], f64, f64); 16] = [
    ("dapi", Nucleus, ALL, 1.0, 12000.0),
    ("keratin", Cytoplasm, &[Epithelial], 0.9, 6000.0),
    (
        "cd45",
        Membrane,
        &[HelperT, CytotoxicT, B, Macrophage],
        1.0,
        5000.0,
    ),
    ("cd3", Membrane, &[HelperT, CytotoxicT], 1.0, 6000.0),
    ("cd8", Membrane, &[CytotoxicT], 1.0, 5000.0),
    ("cd4", Membrane, &[HelperT], 1.0, 4500.0),
    ("cd20", Membrane, &[B], 1.0, 6000.0),
    ("cd68", Cytoplasm, &[Macrophage], 1.0, 5000.0),
    (
        "ki67",
        Nucleus,
        &[Epithelial, HelperT, CytotoxicT, B],
        0.25,
        7000.0,
    ),
    ("ecad", Membrane, &[Epithelial], 0.95, 5500.0),
    (
        "vimentin",
        Cytoplasm,
        &[Stromal, Endothelial, Macrophage],
        1.0,
        4000.0,
    ),
    ("sma", Cytoplasm, &[Stromal], 0.6, 5000.0),
    ("cd31", Membrane, &[Endothelial], 1.0, 6000.0),
    ("foxp3", Nucleus, &[HelperT], 0.3, 6000.0),
    ("pd1", Membrane, &[HelperT, CytotoxicT], 0.4, 4000.0),
    ("pdl1", Membrane, &[Epithelial, Macrophage], 0.3, 3500.0),
];

/// The marker of channel `k`: the panel, then random markers.
pub(crate) fn marker(k: usize, seed: u64) -> Marker {
    if let Some(&(name, compartment, types, fraction, peak)) = PANEL.get(k) {
        return Marker {
            name: name.to_string(),
            compartment,
            types: Some(types),
            fraction,
            peak,
        };
    }
    let h = hash(seed ^ 0x3A4C_0000 ^ k as u64);
    Marker {
        name: format!("marker{k}"),
        compartment: [Nucleus, Membrane, Cytoplasm][(h % 3) as usize],
        types: None,
        fraction: 0.15 + 0.35 * unit(hash(h)),
        peak: 3000.0 + 4000.0 * unit(hash(h ^ 1)),
    }
}

/// One cell, in micrometres.
struct Cell {
    centre: [f64; 2],
    z: f64,
    half_height: f64,
    nucleus: [f64; 3],
    kind: CellType,
}

/// The tissue section.
pub(crate) struct CycifScene {
    shape: [u64; 3],
    seed: u64,
    markers: Vec<Marker>,
    grid: [usize; 2],
    /// One optional cell per grid square, row-major.
    cells: Vec<Option<Cell>>,
    /// Brightness of each cell in each channel (0: negative), `[cell][channel]`.
    expression: Vec<f32>,
}

impl CycifScene {
    /// The section for a volume of `shape` voxels with `channels` markers.
    pub(crate) fn new(shape: [u64; 3], channels: usize, seed: u64) -> Self {
        let [nz, ny, nx] = shape;
        let [pz, py, px] = CYCIF_VOXEL_SIZE;
        let thickness = nz as f64 * pz;
        let grid = [
            (ny as f64 * py / SPACING).ceil() as usize,
            (nx as f64 * px / SPACING).ceil() as usize,
        ];
        let markers: Vec<Marker> = (0..channels).map(|k| marker(k, seed)).collect();
        let mut cells = Vec::with_capacity(grid[0] * grid[1]);
        let mut expression = Vec::with_capacity(grid[0] * grid[1] * channels);
        for gy in 0..grid[0] {
            for gx in 0..grid[1] {
                let id = (gy * grid[1] + gx) as u64;
                let r = |i: u64| unit(hash(seed ^ 0xCE11_0000_0000 ^ (id << 8) ^ i));
                let centre = [
                    (gy as f64 + 0.25 + 0.5 * r(0)) * SPACING,
                    (gx as f64 + 0.25 + 0.5 * r(1)) * SPACING,
                ];
                // Gaps: tears and lumens where a coarse tissue field is low.
                let tissue = fbm2(seed ^ 0x7155, centre.map(|v| v / 40.0), 2);
                let present = tissue > 0.3 && r(2) < 0.95;
                let cell = present.then(|| {
                    let glands = fbm2(seed ^ 0x61A4, centre.map(|v| v / 50.0), 2);
                    let kind = if glands > 0.5 && r(3) < 0.9 {
                        Epithelial
                    } else {
                        let t = r(4);
                        match t {
                            t if t < 0.35 => Stromal,
                            t if t < 0.43 => Endothelial,
                            t if t < 0.60 => HelperT,
                            t if t < 0.77 => CytotoxicT,
                            t if t < 0.88 => B,
                            _ => Macrophage,
                        }
                    };
                    Cell {
                        centre,
                        z: thickness * (0.3 + 0.4 * r(5)),
                        half_height: 4.0 + 2.0 * r(6),
                        nucleus: [2.2 + r(7), 2.5 + r(8), 2.5 + r(9)],
                        kind,
                    }
                });
                for (k, m) in markers.iter().enumerate() {
                    let level = match &cell {
                        Some(c) if m.types.is_none_or(|t| t.contains(&c.kind)) => {
                            let h = hash(seed ^ 0xE4B2 ^ (id << 16) ^ k as u64);
                            if unit(h) < m.fraction {
                                (m.peak * (0.5 + 0.5 * unit(hash(h)))) as f32
                            } else {
                                0.0
                            }
                        }
                        _ => 0.0,
                    };
                    expression.push(level);
                }
                cells.push(cell);
            }
        }
        // A marker no cell happens to carry still stains one cell of its types, when there
        // is one (the one with the smallest hash), so small fields of view show every marker.
        let n = markers.len();
        for (k, m) in markers.iter().enumerate() {
            if (0..cells.len()).any(|c| expression[c * n + k] > 0.0) {
                continue;
            }
            let chosen = cells
                .iter()
                .enumerate()
                .filter(|(_, c)| {
                    c.as_ref()
                        .is_some_and(|c| m.types.is_none_or(|t| t.contains(&c.kind)))
                })
                .min_by_key(|&(c, _)| hash(seed ^ 0xF1C5 ^ ((c as u64) << 16) ^ k as u64));
            if let Some((c, _)) = chosen {
                expression[c * n + k] = (0.75 * m.peak) as f32;
            }
        }
        Self {
            shape,
            seed,
            markers,
            grid,
            cells,
            expression,
        }
    }

    /// The nearest and second-nearest cell centres to `(wy, wx)` (µm) among the 3×3 grid
    /// squares around it: `(index, distance²)`.
    fn nearest(&self, wy: f64, wx: f64) -> [Option<(usize, f64)>; 2] {
        let gy = (wy / SPACING).floor() as isize;
        let gx = (wx / SPACING).floor() as isize;
        let mut best: [Option<(usize, f64)>; 2] = [None, None];
        for y in gy - 1..=gy + 1 {
            for x in gx - 1..=gx + 1 {
                if y < 0 || x < 0 || y as usize >= self.grid[0] || x as usize >= self.grid[1] {
                    continue;
                }
                let i = y as usize * self.grid[1] + x as usize;
                let Some(c) = &self.cells[i] else { continue };
                let d2 = (wy - c.centre[0]).powi(2) + (wx - c.centre[1]).powi(2);
                if best[0].is_none_or(|(_, b)| d2 < b) {
                    best[1] = best[0];
                    best[0] = Some((i, d2));
                } else if best[1].is_none_or(|(_, b)| d2 < b) {
                    best[1] = Some((i, d2));
                }
            }
        }
        best
    }

    /// Plane `z` of every channel.
    pub(crate) fn plane(&self, z: u64) -> Vec<Vec<u16>> {
        let [_, ny, nx] = self.shape;
        let [pz, py, px] = CYCIF_VOXEL_SIZE;
        let channels = self.markers.len();
        let n = (ny * nx) as usize;
        let mut out = vec![vec![0u16; n]; channels];
        let wz = (z as f64 + 0.5) * pz;
        for y in 0..ny {
            let wy = (y as f64 + 0.5) * py;
            for x in 0..nx {
                let wx = (x as f64 + 0.5) * px;
                let i = (y * nx + x) as usize;
                // Compartment profiles (0..1) of the cell this pixel belongs to.
                let mut profile = [0.0f64; 3];
                let mut cell_index = None;
                let mut in_tissue = false;
                if let [Some((c1, d1)), second] = self.nearest(wy, wx) {
                    let cell = self.cells[c1].as_ref().expect("present cell");
                    let d1 = d1.sqrt();
                    // Distance to the cell's edge: the bisector with the next cell, or its
                    // largest reach.
                    let mut edge = CELL_RADIUS - d1;
                    if let Some((c2, d2_squared)) = second {
                        let other = self.cells[c2].as_ref().expect("present cell");
                        let gap = ((cell.centre[0] - other.centre[0]).powi(2)
                            + (cell.centre[1] - other.centre[1]).powi(2))
                        .sqrt();
                        edge = edge.min((d2_squared - d1 * d1) / (2.0 * gap));
                    }
                    let dz = wz - cell.z;
                    let height =
                        1.0 - smoothstep(cell.half_height - 1.0, cell.half_height, dz.abs());
                    if edge > 0.0 && height > 0.0 {
                        in_tissue = true;
                        cell_index = Some(c1);
                        let [rz, ry, rx] = cell.nucleus;
                        let e = (dz / rz).powi(2)
                            + ((wy - cell.centre[0]) / ry).powi(2)
                            + ((wx - cell.centre[1]) / rx).powi(2);
                        let p = [wz, wy, wx];
                        if e < 1.0 {
                            let chromatin =
                                0.8 + 0.2 * value_noise3(self.seed ^ 0xD4A, p.map(|v| v / 0.8));
                            profile[0] = (1.0 - e).sqrt() * chromatin;
                        } else {
                            if edge < MEMBRANE {
                                profile[1] = (1.0 - edge / MEMBRANE) * height;
                            }
                            if edge > 0.5 * MEMBRANE {
                                let granules = 0.6
                                    + 0.4 * value_noise3(self.seed ^ 0xC470, p.map(|v| v / 1.5));
                                profile[2] = granules * height;
                            }
                        }
                    }
                }
                let noise = hash(self.seed ^ 0xBAC6_0000_0000_0000 ^ (z << 40) ^ (y << 20) ^ x);
                for (k, m) in self.markers.iter().enumerate() {
                    let background = OFFSET
                        + (hash(noise ^ k as u64) & NOISE) as u16
                        + if in_tissue { AUTOFLUORESCENCE } else { 0 };
                    let signal = match cell_index {
                        Some(c) => {
                            let level = f64::from(self.expression[c * channels + k]);
                            let shape = match m.compartment {
                                Nucleus => profile[0],
                                Membrane => profile[1],
                                Cytoplasm => profile[2],
                            };
                            level * shape
                        }
                        None => 0.0,
                    };
                    out[k][i] = background.saturating_add(signal as u16);
                }
            }
        }
        out
    }
}

impl Scene for CycifScene {
    fn shape(&self) -> [u64; 3] {
        self.shape
    }

    fn voxel_size(&self) -> [f64; 3] {
        CYCIF_VOXEL_SIZE
    }

    fn channels(&self) -> Vec<ChannelSpec> {
        self.markers
            .iter()
            .enumerate()
            .map(|(k, m)| ChannelSpec {
                file_stem: format!("cycif-{k:02}-{}", m.name),
                name: m.name.clone(),
                format: SampleType::U16,
            })
            .collect()
    }

    fn render_plane(&self, z: u64) -> Vec<PlaneData> {
        self.plane(z).into_iter().map(PlaneData::U16).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cells positive for channel `k`.
    fn positive(scene: &CycifScene, k: usize) -> Vec<usize> {
        let n = scene.markers.len();
        (0..scene.cells.len())
            .filter(|&c| scene.expression[c * n + k] > 0.0)
            .collect()
    }

    #[test]
    fn every_marker_labels_its_own_subset_of_cells() {
        let scene = CycifScene::new([8, 1024, 1024], 20, 1);
        let sets: Vec<Vec<usize>> = (0..20).map(|k| positive(&scene, k)).collect();
        let present = scene.cells.iter().filter(|c| c.is_some()).count();
        assert_eq!(sets[0].len(), present, "DAPI stains every nucleus");
        for (k, s) in sets.iter().enumerate() {
            assert!(!s.is_empty(), "channel {k} stains no cell");
            for (j, t) in sets.iter().enumerate().skip(k + 1) {
                assert_ne!(s, t, "channels {k} and {j} stain the same cells");
            }
        }
        let disjoint = |a: usize, b: usize| sets[a].iter().all(|c| !sets[b].contains(c));
        assert!(disjoint(3, 6), "T cells (cd3) are not B cells (cd20)");
        assert!(disjoint(4, 5), "cd8 and cd4 T cells are distinct");
        assert!(disjoint(1, 2), "epithelium (keratin) is not immune (cd45)");
        // Subsets: every CD8 cell is a CD3 cell, every CD3 cell a CD45 cell.
        assert!(sets[4].iter().all(|c| sets[3].contains(c)));
        assert!(sets[3].iter().all(|c| sets[2].contains(c)));
    }

    #[test]
    fn background_stays_below_its_bound_and_signal_rises_above_it() {
        let scene = CycifScene::new([4, 128, 128], 3, 2);
        let planes = scene.plane(2);
        for p in &planes {
            assert!(p.iter().all(|&v| v >= OFFSET));
            assert!(p.iter().any(|&v| v > 4 * BACKGROUND_MAX));
        }
        // Outside tissue and between cells the value is background only.
        assert!(planes[0].iter().filter(|&&v| v <= BACKGROUND_MAX).count() > 128 * 128 / 4);
    }
}
