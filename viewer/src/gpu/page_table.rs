//! Page tables per (channel, level) (paper Sec. 5.1), flattened into one `u32` buffer. The
//! entry of a brick is `0` when it is not resident, `1` when it equals the fill value 0
//! everywhere (it takes no cache slot), [`ENTRY_CLEAR`] when it is never needed (it is
//! transparent under the transfer function by its haloed range), and `slot + 2` when it is in
//! cache slot `slot`, with a bit of [`ENTRY_APRON`] set for each way a sample's footprint can
//! leave the brick that the slot's apron serves (the `apron` module). A brick's *id* is its
//! entry's index; the shader reports misses by id.

use super::error::GpuError;
use crate::octree::OctreeGeometry;
use crate::source::BrickKey;

/// Entry of a brick that is not resident.
pub const ENTRY_MISSING: u32 = 0;
/// Entry of a brick equal to the fill value 0 everywhere.
pub const ENTRY_EMPTY: u32 = 1;
/// Entry of a brick the residency method never fetches: its conservative (haloed) range is
/// transparent under the channel's transfer function. That range holds every voxel of any
/// trilinear footprint that reaches the brick, so such a sample has opacity exactly 0 and
/// the shader takes it as clear without reading a voxel.
pub const ENTRY_CLEAR: u32 = u32::MAX;
/// First bit of [`ENTRY_APRON`] in a slot's entry.
pub(crate) const APRON_SHIFT: u32 = 23;
/// The apron bits of a slot's entry: bit `APRON_SHIFT + m - 1` is set when a sample whose
/// first voxel lies in the brick, and whose footprint crosses into the next bricks along the
/// axes of *crossing* `m` (bit 0 `x`, 1 `y`, 2 `z`; 1 to 7), finds all eight voxels in the
/// slot (`apron::servable_crossings`). All seven: the apron is complete.
pub const ENTRY_APRON: u32 = 0x7f << APRON_SHIFT;
/// Most cache slots an entry can name: `slot + 2` must stay below [`ENTRY_APRON`]'s bits.
pub(crate) const MAX_SLOTS: u32 = (1 << APRON_SHIFT) - 2;

/// The entry of a brick in cache slot `slot` whose apron serves `crossings` (bit `m - 1`:
/// crossing `m`).
pub(crate) fn slot_entry(slot: u32, crossings: u8) -> u32 {
    (slot + 2) | (u32::from(crossings & 0x7f) << APRON_SHIFT)
}

/// Whether a slot's entry serves crossing `m` (1 to 7) from its apron.
pub fn entry_serves(entry: u32, m: u32) -> bool {
    entry != ENTRY_CLEAR && (1..8).contains(&m) && entry & (1 << (APRON_SHIFT + m - 1)) != 0
}

/// The cache slot of an entry (`None`: the brick is in no slot).
pub fn entry_slot(entry: u32) -> Option<u32> {
    match entry {
        ENTRY_MISSING | ENTRY_EMPTY | ENTRY_CLEAR => None,
        e => Some((e & !ENTRY_APRON) - 2),
    }
}

/// The page tables of the rendered channels and all levels, with a CPU mirror.
pub struct PageTables {
    /// Source channel of each channel slot.
    channels: Vec<usize>,
    /// Bricks per axis (`x, y, z`) of each level.
    grids: Vec<[u64; 3]>,
    /// First id of (slot, level), `slot · levels + level`.
    offsets: Vec<u32>,
    entries: Vec<u32>,
    dirty: Vec<u32>,
    buffer: wgpu::Buffer,
    /// Two `u32` per id: the last frame the brick was requested, and substituted.
    flags: wgpu::Buffer,
}

impl PageTables {
    /// Page tables for `channels` (source indices) over the pyramid of `geometry`, all empty.
    ///
    /// # Errors
    /// [`GpuError::TooManyBricks`] when the bricks of all channels and levels need more than
    /// 31-bit ids.
    pub fn new(
        device: &wgpu::Device,
        geometry: &OctreeGeometry,
        channels: &[usize],
    ) -> Result<Self, GpuError> {
        let grids: Vec<[u64; 3]> = geometry
            .level_shape
            .iter()
            .map(|s| std::array::from_fn(|a| s[a].div_ceil(geometry.brick[a])))
            .collect();
        let mut offsets = Vec::new();
        let mut total = 0u64;
        for _ in channels {
            for g in &grids {
                offsets.push(total as u32);
                total += g[0] * g[1] * g[2];
            }
        }
        if total >= u32::MAX as u64 / 2 {
            return Err(GpuError::TooManyBricks { total });
        }
        let total = total.max(1);
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("page tables"),
            size: total * 4,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let flags = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("request flags"),
            size: total * 8,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Ok(Self {
            channels: channels.to_vec(),
            grids,
            offsets,
            entries: vec![ENTRY_MISSING; total as usize],
            dirty: Vec::new(),
            buffer,
            flags,
        })
    }

    /// First id of each (slot, level), `slot · levels + level`, for the shader's tables.
    pub fn offsets(&self) -> &[u32] {
        &self.offsets
    }

    /// The id of `key`, if its channel is rendered and it lies in its level's grid.
    pub fn id(&self, key: &BrickKey) -> Option<u32> {
        let slot = self
            .channels
            .iter()
            .position(|&c| c == key.channel as usize)?;
        let l = key.level as usize;
        let g = self.grids.get(l)?;
        let b = [key.brick[2], key.brick[1], key.brick[0]];
        if (0..3).any(|a| b[a] >= g[a]) {
            return None;
        }
        let local = (b[2] * g[1] + b[1]) * g[0] + b[0];
        Some(self.offsets[slot * self.grids.len() + l] + local as u32)
    }

    /// The brick of id `id`.
    pub fn key(&self, id: u32) -> Option<BrickKey> {
        let i = self.offsets.partition_point(|&o| o <= id).checked_sub(1)?;
        let (slot, l) = (i / self.grids.len(), i % self.grids.len());
        let g = self.grids[l];
        let local = (id - self.offsets[i]) as u64;
        if local >= g[0] * g[1] * g[2] {
            return None;
        }
        let (x, y, z) = (local % g[0], (local / g[0]) % g[1], local / (g[0] * g[1]));
        Some(BrickKey {
            level: l as u32,
            channel: self.channels[slot] as u32,
            brick: [z, y, x],
        })
    }

    /// Bricks per axis (`x, y, z`) of level `level`.
    pub fn grid(&self, level: u32) -> [u64; 3] {
        self.grids[level as usize]
    }

    /// Number of ids (bricks of every rendered channel and level).
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether there are no ids at all.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The entry of `id`.
    pub fn entry(&self, id: u32) -> u32 {
        self.entries[id as usize]
    }

    /// Sets the entry of `id` (uploaded by [`Self::flush`]).
    pub fn set(&mut self, id: u32, entry: u32) {
        if self.entries[id as usize] != entry {
            self.entries[id as usize] = entry;
            self.dirty.push(id);
        }
    }

    /// Uploads changed entries, coalescing runs of consecutive ids.
    pub fn flush(&mut self, queue: &wgpu::Queue) {
        if self.dirty.is_empty() {
            return;
        }
        self.dirty.sort_unstable();
        self.dirty.dedup();
        let mut i = 0;
        while i < self.dirty.len() {
            let start = self.dirty[i];
            let mut end = start + 1;
            while i + 1 < self.dirty.len() && self.dirty[i + 1] == end {
                end += 1;
                i += 1;
            }
            i += 1;
            queue.write_buffer(
                &self.buffer,
                start as u64 * 4,
                bytemuck::cast_slice(&self.entries[start as usize..end as usize]),
            );
        }
        self.dirty.clear();
    }

    /// The GPU page-table buffer.
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// The GPU request/substitution flag buffer.
    pub fn flags(&self) -> &wgpu::Buffer {
        &self.flags
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slot_entries_carry_their_slot_and_crossings() {
        let e = slot_entry(5, 0b101);
        assert_eq!(e, 7 | 0b101 << APRON_SHIFT);
        assert_eq!(entry_slot(e), Some(5));
        assert_eq!(entry_slot(slot_entry(5, 0x7f)), Some(5));
        assert_eq!(
            (1..8).map(|m| entry_serves(e, m)).collect::<Vec<_>>(),
            [true, false, true, false, false, false, false]
        );
        assert!(!entry_serves(ENTRY_CLEAR, 1));
        assert!(!entry_serves(ENTRY_EMPTY, 1));
        assert!(!entry_serves(e, 0));
        assert_eq!(slot_entry(3, 0x7f) & ENTRY_APRON, ENTRY_APRON);
    }
}
