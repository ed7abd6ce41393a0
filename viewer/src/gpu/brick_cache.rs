//! The brick cache: one 3D texture atlas of equal-size slots in the source's sample format,
//! read by the shader with `textureLoad` and manual trilinear filtering so that 16-bit and
//! float data stay exact. Format per sample type: `u8 → R8Uint`, `u16 → R16Uint`,
//! `i16 → R16Sint`, `u32 → R32Uint`, `i32 → R32Sint`, `f32 → R32Float` (the shader converts
//! to `f32`; `u32`/`i32` above 2²⁴ lose low bits there). A slot holds a brick and its apron
//! (`apron`): `APRON_VOXELS` more voxels per axis. Slots are replaced least
//! recently used first, where "used" is the shader's per-slot usage feedback.

use super::apron::APRON_VOXELS;
use super::error::GpuError;
use super::page_table::MAX_SLOTS;
use crate::source::{BrickVoxels, SampleType};

/// Edge of a slot, voxels (`x, y, z`): a brick of `brick` voxels and its apron.
fn slot_edge(brick: [u32; 3]) -> [u32; 3] {
    brick.map(|b| b + APRON_VOXELS)
}

/// Which of the shader's three atlas bindings holds the data.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AtlasKind {
    /// Unsigned integer texels (`texture_3d<u32>`).
    Uint = 0,
    /// Signed integer texels (`texture_3d<i32>`).
    Sint = 1,
    /// Float texels (`texture_3d<f32>`).
    Float = 2,
}

/// Texture format and atlas binding of a sample type.
pub(crate) fn atlas_format(t: SampleType) -> (wgpu::TextureFormat, AtlasKind) {
    use wgpu::TextureFormat as F;
    match t {
        SampleType::U8 => (F::R8Uint, AtlasKind::Uint),
        SampleType::U16 => (F::R16Uint, AtlasKind::Uint),
        SampleType::I16 => (F::R16Sint, AtlasKind::Sint),
        SampleType::U32 => (F::R32Uint, AtlasKind::Uint),
        SampleType::I32 => (F::R32Sint, AtlasKind::Sint),
        SampleType::F32 => (F::R32Float, AtlasKind::Float),
    }
}

/// The atlas, its slot bookkeeping and the usage-feedback buffer.
pub struct BrickCache {
    sample_type: SampleType,
    kind: AtlasKind,
    brick: [u32; 3],
    slots_per_axis: [u32; 3],
    capacity: u32,
    atlas: wgpu::Texture,
    dummies: [wgpu::Texture; 2],
    /// Page-table id held by each slot.
    owner: Vec<Option<u32>>,
    /// Last frame each slot was used in (or filled).
    last_used: Vec<u32>,
    free: Vec<u32>,
    usage: wgpu::Buffer,
}

impl BrickCache {
    /// A cache of as many slots for `brick`-voxel bricks (`x, y, z`) and their aprons as fit
    /// in `cache_bytes` and in the device's 3D texture limit.
    ///
    /// # Errors
    /// [`GpuError::BrickOverTextureLimit`] or [`GpuError::CacheTooSmall`] when not even one
    /// slot fits.
    pub fn new(
        device: &wgpu::Device,
        limits: &wgpu::Limits,
        sample_type: SampleType,
        brick: [u32; 3],
        cache_bytes: u64,
    ) -> Result<Self, GpuError> {
        let (format, kind) = atlas_format(sample_type);
        let slot = slot_edge(brick);
        let brick_bytes = sample_type.block_bytes(slot.map(u64::from));
        let wanted = (cache_bytes / brick_bytes).min(u64::from(MAX_SLOTS)) as u32;
        let max_dim = limits.max_texture_dimension_3d;
        let fit: [u32; 3] = std::array::from_fn(|a| max_dim / slot[a]);
        if fit.contains(&0) {
            return Err(GpuError::BrickOverTextureLimit {
                brick,
                limit: max_dim,
            });
        }
        if wanted == 0 {
            return Err(GpuError::CacheTooSmall {
                cache_bytes,
                brick_bytes,
            });
        }
        // Slots per x and y axis are powers of two, so the shader finds a slot's atlas
        // position with shifts rather than integer division.
        let pow2_floor = |v: u32| 1u32 << v.max(1).ilog2();
        let sx = pow2_floor(wanted.min(fit[0]));
        let sy = pow2_floor(wanted.div_ceil(sx).min(fit[1]));
        let sz = wanted.div_ceil(sx * sy).min(fit[2]);
        let capacity = wanted.min(sx * sy * sz);
        if capacity < wanted {
            tracing::warn!(
                "brick cache capped at {capacity} slots by the device's 3D texture limit {max_dim}"
            );
        }
        let texture = |label, size: [u32; 3], format| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width: size[0],
                    height: size[1],
                    depth_or_array_layers: size[2],
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D3,
                format,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            })
        };
        let atlas = texture(
            "brick cache",
            [sx * slot[0], sy * slot[1], sz * slot[2]],
            format,
        );
        use wgpu::TextureFormat as F;
        let others: Vec<F> = [F::R32Uint, F::R32Sint, F::R32Float]
            .into_iter()
            .enumerate()
            .filter(|(i, _)| *i != kind as usize)
            .map(|(_, f)| f)
            .collect();
        let dummies = [
            texture("unused atlas", [1, 1, 1], others[0]),
            texture("unused atlas", [1, 1, 1], others[1]),
        ];
        let usage = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("slot usage"),
            size: capacity as u64 * 4,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Ok(Self {
            sample_type,
            kind,
            brick,
            slots_per_axis: [sx, sy, sz],
            capacity,
            atlas,
            dummies,
            owner: vec![None; capacity as usize],
            last_used: vec![0; capacity as usize],
            free: (0..capacity).rev().collect(),
            usage,
        })
    }

    /// Number of slots.
    pub fn capacity(&self) -> u32 {
        self.capacity
    }

    /// Slots per atlas axis (`x, y, z`).
    pub fn slots_per_axis(&self) -> [u32; 3] {
        self.slots_per_axis
    }

    /// The atlas binding kind.
    pub fn kind(&self) -> AtlasKind {
        self.kind
    }

    /// Bytes of one slot (a brick and its apron).
    pub fn slot_bytes(&self) -> u64 {
        self.sample_type
            .block_bytes(slot_edge(self.brick).map(u64::from))
    }

    /// Edge of a brick, voxels (`x, y, z`).
    pub fn brick(&self) -> [u32; 3] {
        self.brick
    }

    /// The sample type of the atlas.
    pub fn sample_type(&self) -> SampleType {
        self.sample_type
    }

    /// Views of the `u32`, `i32` and `f32` atlas bindings (two of them 1-texel placeholders).
    pub fn views(&self) -> [wgpu::TextureView; 3] {
        let v = |t: &wgpu::Texture| t.create_view(&wgpu::TextureViewDescriptor::default());
        let mut it = self.dummies.iter();
        std::array::from_fn(|i| {
            if i == self.kind as usize {
                v(&self.atlas)
            } else {
                v(it.next().expect("two placeholders"))
            }
        })
    }

    /// The usage-feedback buffer (one `u32` per slot: the last frame it was sampled in).
    pub fn usage_buffer(&self) -> &wgpu::Buffer {
        &self.usage
    }

    /// Folds the shader's usage feedback into the LRU order.
    pub fn note_usage(&mut self, usage: &[u32]) {
        for (last, &u) in self.last_used.iter_mut().zip(usage) {
            *last = (*last).max(u);
        }
    }

    /// Slots not used since before frame `frame` (candidates for eviction) plus free ones.
    pub fn available(&self, frame: u32) -> usize {
        self.free.len()
            + self
                .owner
                .iter()
                .zip(&self.last_used)
                .filter(|(o, u)| o.is_some() && **u < frame)
                .count()
    }

    /// A slot for a new brick: a free one, else the least recently used one not used in
    /// `frame` or later, whose previous owner (a page-table id) is returned for eviction.
    /// `None` when every slot is in use by the current working set.
    pub fn allocate(&mut self, frame: u32) -> Option<(u32, Option<u32>)> {
        let slot = if let Some(s) = self.free.pop() {
            s
        } else {
            let (s, _) = self
                .last_used
                .iter()
                .enumerate()
                .filter(|(_, u)| **u < frame)
                .min_by_key(|(_, u)| **u)?;
            s as u32
        };
        let evicted = self.owner[slot as usize].take();
        self.last_used[slot as usize] = frame;
        Some((slot, evicted))
    }

    /// Records that `slot` now holds page-table id `id`.
    pub fn assign(&mut self, slot: u32, id: u32) {
        self.owner[slot as usize] = Some(id);
    }

    /// The page-table id `slot` holds.
    pub fn owner(&self, slot: u32) -> Option<u32> {
        self.owner[slot as usize]
    }

    /// The raw samples of `voxels`, checked to be a full brick of the cache's sample type.
    ///
    /// # Errors
    /// [`GpuError::EmptyBrickUpload`] or [`GpuError::WrongBrick`].
    pub fn brick_bytes<'a>(&self, voxels: &'a BrickVoxels) -> Result<&'a [u8], GpuError> {
        let n = self.brick.iter().map(|&b| b as usize).product::<usize>();
        Ok(match (self.sample_type, voxels) {
            (SampleType::U8, BrickVoxels::U8(v)) if v.len() == n => v,
            (SampleType::U16, BrickVoxels::U16(v)) if v.len() == n => bytemuck::cast_slice(v),
            (SampleType::I16, BrickVoxels::I16(v)) if v.len() == n => bytemuck::cast_slice(v),
            (SampleType::U32, BrickVoxels::U32(v)) if v.len() == n => bytemuck::cast_slice(v),
            (SampleType::I32, BrickVoxels::I32(v)) if v.len() == n => bytemuck::cast_slice(v),
            (SampleType::F32, BrickVoxels::F32(v)) if v.len() == n => bytemuck::cast_slice(v),
            (_, BrickVoxels::Empty) => return Err(GpuError::EmptyBrickUpload),
            _ => {
                return Err(GpuError::WrongBrick {
                    samples: voxels.len(),
                    expected: n,
                    sample_type: self.sample_type,
                });
            }
        })
    }

    /// Writes a brick's raw samples (from [`BrickCache::brick_bytes`]) to `slot`.
    pub fn upload(&self, queue: &wgpu::Queue, slot: u32, bytes: &[u8]) {
        self.write_box(queue, slot, [0; 3], self.brick, bytes);
    }

    /// Writes `bytes` (`x` fastest) to the box of `extent` voxels at `origin` within `slot`
    /// (an apron part, or the whole brick).
    pub fn write_box(
        &self,
        queue: &wgpu::Queue,
        slot: u32,
        origin: [u32; 3],
        extent: [u32; 3],
        bytes: &[u8],
    ) {
        let [sx, sy, _] = self.slots_per_axis;
        let s = [slot % sx, (slot / sx) % sy, slot / (sx * sy)];
        let edge = slot_edge(self.brick);
        let at = |a: usize| s[a] * edge[a] + origin[a];
        queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &self.atlas,
                mip_level: 0,
                origin: wgpu::Origin3d {
                    x: at(0),
                    y: at(1),
                    z: at(2),
                },
                aspect: wgpu::TextureAspect::All,
            },
            bytes,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(extent[0] * self.sample_type.bytes() as u32),
                rows_per_image: Some(extent[1]),
            },
            wgpu::Extent3d {
                width: extent[0],
                height: extent[1],
                depth_or_array_layers: extent[2],
            },
        );
    }
}
