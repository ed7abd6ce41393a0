//! Brick aprons. Every cache slot holds its brick and one more voxel layer on the brick's high
//! `x`, `y` and `z` sides: the first voxels of the seven neighbouring bricks of the same
//! channel and level that follow it (three faces, three edges, one corner; the *parts* of the
//! apron). A trilinear sample reads voxels `i` and `i + 1` per axis; with a complete apron the
//! brick holding voxel `i` holds both, so the shader looks the page table up once per sample
//! instead of once per brick its footprint crosses. A slot's page-table entry carries
//! one bit of [`super::page_table::ENTRY_APRON`] for each *crossing* (the set of axes along
//! which a footprint leaves the brick) whose parts are all filled; a sample whose crossing
//! is not served takes the per-corner path, which is exact whatever the apron holds.
//!
//! A part is filled from:
//! - a neighbour in a cache slot: its low faces, which are kept while it is resident (three
//!   faces of `B²` voxels, `3/B` of the brick);
//! - a neighbour equal to the fill value everywhere ([`super::page_table::ENTRY_EMPTY`]): the
//!   fill value 0;
//! - a clear neighbour ([`ENTRY_CLEAR`]): the least value of its haloed range. Any footprint
//!   that reaches a clear brick lies in that range, as the part's value does, so the sample's
//!   value does too and its opacity is 0, as the per-corner path takes it. The fill depends on
//!   the style, so a restyle empties these parts ([`Aprons::drop_stand_ins`]).
//!
//! A part written stays valid after its neighbour is evicted (bricks do not change); a slot's
//! parts are forgotten when the slot takes another brick.

use std::collections::HashMap;

use super::page_table::{ENTRY_CLEAR, ENTRY_EMPTY, ENTRY_MISSING};
use crate::source::SampleType;

/// Voxels of apron on a slot's high side, per axis.
pub const APRON_VOXELS: u32 = 1;

/// A neighbour offset `(dx, dy, dz)`, each 0 or 1 and not all 0, as the bit index
/// `dx | dy << 1 | dz << 2` (1 to 7).
pub type Part = u32;

/// The apron parts, as neighbour offsets `x, y, z`.
pub fn part_offset(part: Part) -> [u64; 3] {
    [
        u64::from(part & 1),
        u64::from((part >> 1) & 1),
        u64::from((part >> 2) & 1),
    ]
}

/// Where part `part` lies in a slot of bricks of `brick` voxels (`x, y, z`): its origin and
/// extent in voxels, `x, y, z`. Along an axis where the neighbour is offset, one voxel just
/// past the brick; along the others, the brick's whole edge.
pub fn part_box(part: Part, brick: [u32; 3]) -> ([u32; 3], [u32; 3]) {
    let o = part_offset(part);
    let origin = std::array::from_fn(|a| if o[a] == 1 { brick[a] } else { 0 });
    let extent = std::array::from_fn(|a| if o[a] == 1 { APRON_VOXELS } else { brick[a] });
    (origin, extent)
}

/// The three low faces of a brick (`x = 0`, `y = 0`, `z = 0`), raw samples, each `x`-fastest
/// over its two other axes: everything its lower neighbours' aprons take from it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LowFaces {
    /// `x = 0`: `y` fastest, then `z`.
    x: Vec<u8>,
    /// `y = 0`: `x` fastest, then `z`.
    y: Vec<u8>,
    /// `z = 0`: `x` fastest, then `y`.
    z: Vec<u8>,
}

impl LowFaces {
    /// The low faces of a brick of `brick` voxels (`x, y, z`) whose samples (`z`-major, `x`
    /// fastest) are `bytes`, `sample` bytes each.
    pub fn of(bytes: &[u8], brick: [u32; 3], sample: usize) -> Self {
        let [bx, by, bz] = brick.map(|b| b as usize);
        let at = |x: usize, y: usize, z: usize| {
            let i = ((z * by + y) * bx + x) * sample;
            &bytes[i..i + sample]
        };
        let mut faces = Self {
            x: Vec::with_capacity(by * bz * sample),
            y: Vec::with_capacity(bx * bz * sample),
            z: Vec::with_capacity(bx * by * sample),
        };
        for z in 0..bz {
            for y in 0..by {
                faces.x.extend_from_slice(at(0, y, z));
            }
            for x in 0..bx {
                faces.y.extend_from_slice(at(x, 0, z));
            }
        }
        faces.z.extend_from_slice(&bytes[..bx * by * sample]);
        faces
    }

    /// The voxels the lower neighbour at `-offset(part)` takes into its apron part `part`,
    /// in the order of [`part_box`]'s box (`x` fastest).
    pub fn part(&self, part: Part, brick: [u32; 3], sample: usize) -> Vec<u8> {
        let [bx, by, _] = brick.map(|b| b as usize);
        let (_, extent) = part_box(part, brick);
        let [ex, ey, ez] = extent.map(|e| e as usize);
        let o = part_offset(part);
        let mut out = Vec::with_capacity(ex * ey * ez * sample);
        let mut take = |face: &[u8], i: usize| out.extend_from_slice(&face[i * sample..][..sample]);
        for z in 0..ez {
            for y in 0..ey {
                for x in 0..ex {
                    if o[0] == 1 {
                        take(&self.x, z * by + y);
                    } else if o[1] == 1 {
                        take(&self.y, z * bx + x);
                    } else {
                        take(&self.z, y * bx + x);
                    }
                }
            }
        }
        out
    }
}

/// What a neighbouring brick offers an apron part.
pub enum PartSource<'a> {
    /// A resident brick's low faces.
    Faces(&'a LowFaces),
    /// One value everywhere (raw sample bytes); `stand_in` when it stands for a clear brick
    /// (valid for the current style only).
    Constant {
        /// The sample.
        sample: Vec<u8>,
        /// Whether it stands in for a clear brick's voxels.
        stand_in: bool,
    },
}

/// The raw bytes of `value` as a sample of `t`, where `value` is one exactly.
pub fn sample_bytes(t: SampleType, value: f64) -> Option<Vec<u8>> {
    fn exact<T: Copy + Into<f64>>(v: T, value: f64, b: impl Fn(T) -> Vec<u8>) -> Option<Vec<u8>> {
        (v.into() == value).then(|| b(v))
    }
    match t {
        SampleType::U8 => exact(value as u8, value, |v| vec![v]),
        SampleType::U16 => exact(value as u16, value, |v| v.to_le_bytes().to_vec()),
        SampleType::I16 => exact(value as i16, value, |v| v.to_le_bytes().to_vec()),
        SampleType::U32 => exact(value as u32, value, |v| v.to_le_bytes().to_vec()),
        SampleType::I32 => exact(value as i32, value, |v| v.to_le_bytes().to_vec()),
        SampleType::F32 => exact(value as f32, value, |v| v.to_le_bytes().to_vec()),
    }
}

/// The parts of a brick's apron that exist (bit `part` set): those whose neighbour lies in
/// the level's grid of `grid` bricks (`x, y, z`). A brick last along an axis needs no apron
/// there: the sample clamps to the volume's edge voxel.
pub fn needed_parts(brick: [u64; 3], grid: [u64; 3]) -> u8 {
    (1..8u32)
        .filter(|&p| {
            let o = part_offset(p);
            (0..3).all(|a| brick[a] + o[a] < grid[a])
        })
        .fold(0, |m, p| m | 1 << p)
}

/// The crossings a slot serves, given the parts `present` in it (bit `part`: filled, or not
/// needed because that neighbour lies outside the level's grid, where no footprint reaches):
/// bit `m - 1` for each crossing `m` (1 to 7: bit 0 `x`, 1 `y`, 2 `z`) whose parts (every
/// non-empty `p ⊆ m`) are all present.
pub fn servable_crossings(present: u8) -> u8 {
    (1..8u8)
        .filter(|&m| {
            (1..8u8)
                .filter(|&p| p & !m == 0)
                .all(|p| present & (1 << p) != 0)
        })
        .fold(0, |acc, m| acc | 1 << (m - 1))
}

/// Whether an entry is a brick whose voxels are somewhere an apron can take them from, and
/// how (`None`: not yet known, so the part waits).
pub fn entry_offers(entry: u32) -> Option<EntryKind> {
    match entry {
        ENTRY_MISSING => None,
        ENTRY_EMPTY => Some(EntryKind::FillValue),
        ENTRY_CLEAR => Some(EntryKind::Clear),
        _ => Some(EntryKind::Resident),
    }
}

/// The kinds of page-table entry an apron part can be filled from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EntryKind {
    /// In a cache slot: its low faces.
    Resident,
    /// The fill value everywhere.
    FillValue,
    /// Clear under the transfer function: a stand-in from its range.
    Clear,
}

/// The apron bookkeeping of a brick cache: the low faces of the bricks in slots, and per slot
/// which parts are filled and which of them hold stand-ins.
pub struct Aprons {
    /// Low faces of each brick in a slot, by page-table id.
    faces: HashMap<u32, LowFaces>,
    /// Per slot: the parts filled (bit `part`).
    filled: Vec<u8>,
    /// Per slot: the parts filled with a clear neighbour's stand-in.
    stand_ins: Vec<u8>,
    /// Whether complete aprons are marked in the page tables (the default), or every brick
    /// of a footprint is looked up.
    used: bool,
}

impl Aprons {
    /// Nothing filled, for a cache of `capacity` slots.
    pub fn new(capacity: u32) -> Self {
        Self {
            faces: HashMap::new(),
            filled: vec![0; capacity as usize],
            stand_ins: vec![0; capacity as usize],
            used: true,
        }
    }

    /// Whether complete aprons are marked in the page tables.
    pub fn used(&self) -> bool {
        self.used
    }

    /// Marks complete aprons in the page tables (`true`) or not.
    pub fn set_used(&mut self, used: bool) {
        self.used = used;
    }

    /// Slot `slot` takes brick `id` with low faces `faces`: its parts are empty.
    pub fn take_slot(&mut self, slot: u32, id: u32, faces: LowFaces) {
        self.filled[slot as usize] = 0;
        self.stand_ins[slot as usize] = 0;
        self.faces.insert(id, faces);
    }

    /// Brick `id` left its slot: its faces are dropped (the parts already copied stay).
    pub fn forget(&mut self, id: u32) {
        self.faces.remove(&id);
    }

    /// The low faces of the resident brick `id`.
    pub fn faces(&self, id: u32) -> Option<&LowFaces> {
        self.faces.get(&id)
    }

    /// The parts of `slot` filled so far.
    pub fn filled(&self, slot: u32) -> u8 {
        self.filled[slot as usize]
    }

    /// Records part `part` of `slot` as filled (with a stand-in or not).
    pub fn mark(&mut self, slot: u32, part: Part, stand_in: bool) {
        self.filled[slot as usize] |= 1 << part;
        if stand_in {
            self.stand_ins[slot as usize] |= 1 << part;
        } else {
            self.stand_ins[slot as usize] &= !(1 << part);
        }
    }

    /// Empties every part filled with a stand-in (the style changed, so a clear neighbour
    /// may no longer be clear); returns the slots that lost a part.
    pub fn drop_stand_ins(&mut self) -> Vec<u32> {
        let mut touched = Vec::new();
        for (slot, (filled, stand_ins)) in
            self.filled.iter_mut().zip(&mut self.stand_ins).enumerate()
        {
            if *stand_ins != 0 {
                *filled &= !*stand_ins;
                *stand_ins = 0;
                touched.push(slot as u32);
            }
        }
        touched
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn part_boxes_and_offsets() {
        let b = [4, 3, 2];
        assert_eq!(part_box(1, b), ([4, 0, 0], [1, 3, 2]));
        assert_eq!(part_box(2, b), ([0, 3, 0], [4, 1, 2]));
        assert_eq!(part_box(4, b), ([0, 0, 2], [4, 3, 1]));
        assert_eq!(part_box(3, b), ([4, 3, 0], [1, 1, 2]));
        assert_eq!(part_box(7, b), ([4, 3, 2], [1, 1, 1]));
        assert_eq!(part_offset(6), [0, 1, 1]);
    }

    #[test]
    fn faces_give_each_part_the_neighbours_first_voxels() {
        // A 4×3×2 brick of u16 whose voxel (x, y, z) is 100z + 10y + x.
        let b = [4u32, 3, 2];
        let mut bytes = Vec::new();
        for z in 0..2u16 {
            for y in 0..3u16 {
                for x in 0..4u16 {
                    bytes.extend_from_slice(&(100 * z + 10 * y + x).to_le_bytes());
                }
            }
        }
        let faces = LowFaces::of(&bytes, b, 2);
        let values = |part| -> Vec<u16> {
            faces
                .part(part, b, 2)
                .chunks(2)
                .map(|c| u16::from_le_bytes([c[0], c[1]]))
                .collect()
        };
        assert_eq!(values(1), [0, 10, 20, 100, 110, 120]);
        assert_eq!(values(2), [0, 1, 2, 3, 100, 101, 102, 103]);
        assert_eq!(values(4), [0, 1, 2, 3, 10, 11, 12, 13, 20, 21, 22, 23]);
        assert_eq!(values(3), [0, 100]);
        assert_eq!(values(5), [0, 10, 20]);
        assert_eq!(values(6), [0, 1, 2, 3]);
        assert_eq!(values(7), [0]);
    }

    #[test]
    fn needed_parts_stop_at_the_grid() {
        assert_eq!(needed_parts([0, 0, 0], [2, 2, 2]), 0b1111_1110);
        assert_eq!(needed_parts([1, 0, 0], [2, 2, 2]), 0b0101_0100);
        assert_eq!(needed_parts([1, 1, 1], [2, 2, 2]), 0);
        assert_eq!(needed_parts([0, 0, 0], [1, 1, 1]), 0);
    }

    #[test]
    fn a_crossing_is_served_once_all_its_parts_are_present() {
        assert_eq!(servable_crossings(0b1111_1110), 0b111_1111);
        assert_eq!(servable_crossings(0), 0);
        // x alone: only the crossing along x.
        assert_eq!(servable_crossings(0b10), 0b1);
        // x and y but not the xy edge: x or y alone, not both at once.
        assert_eq!(servable_crossings(0b110), 0b11);
        assert_eq!(servable_crossings(0b1110), 0b111);
        // Everything but the z face: no crossing along z.
        assert_eq!(servable_crossings(0b1110_1110), 0b111);
        // Everything but the corner: every crossing but all three axes at once.
        assert_eq!(servable_crossings(0b0111_1110), 0b011_1111);
    }

    #[test]
    fn samples_are_exact_or_none() {
        assert_eq!(sample_bytes(SampleType::U16, 513.0), Some(vec![1, 2]));
        assert_eq!(sample_bytes(SampleType::U8, 256.0), None);
        assert_eq!(sample_bytes(SampleType::I16, -2.0), Some(vec![0xfe, 0xff]));
        assert_eq!(sample_bytes(SampleType::F32, 0.1), None);
        assert_eq!(
            sample_bytes(SampleType::F32, 0.5),
            Some(0.5f32.to_le_bytes().to_vec())
        );
    }

    #[test]
    fn stand_ins_are_dropped_and_real_parts_kept() {
        let mut a = Aprons::new(2);
        a.mark(1, 1, false);
        a.mark(1, 2, true);
        a.mark(0, 4, false);
        assert_eq!(a.drop_stand_ins(), [1]);
        assert_eq!((a.filled(0), a.filled(1)), (1 << 4, 1 << 1));
        a.mark(1, 2, true);
        a.mark(1, 2, false);
        assert_eq!(a.drop_stand_ins(), Vec::<u32>::new());
    }
}
