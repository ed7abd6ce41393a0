//! A volumetric depth image as the ray caster's buffers hold it ([`VdiBuffers`]): its list
//! starts, its supersegments packed as the generator's pass writes them, and its skipping
//! grid (the paper's Sec. 4.3). Building them is the CPU's share of putting a VDI on the GPU;
//! it is apart from the upload ([`super::vdi_render::VdiRenderer::create`]) so that the page
//! builds them off its main thread, in the worker that reads the render service's answers.

use residency_schemas::vdi::{VdiHeader, VolumetricDepthImage};

use super::contract::{VDI_DEPTH_BINS, vdi_slot};
use super::vdi_filter::VdiFilter;

/// A VDI's buffers for the ray caster, built by [`VdiBuffers::of`] (or taken back from their
/// parts, checked, by [`VdiBuffers::from_parts`]). Its slots are held as `S` ([`VdiSlots`]):
/// a `Vec`, or on the page the array its VDI reader transferred.
#[derive(Clone, Debug, PartialEq)]
pub struct VdiBuffers<S = Vec<[f32; 4]>> {
    /// The VDI's header.
    pub header: VdiHeader,
    /// Per list, row-major from the top, the index of its first slot; then the number of
    /// supersegments (`width × height + 1` values).
    pub starts: Vec<u32>,
    /// The supersegments, lists one after the other, each packed as [`vdi_slot`]; one zero
    /// slot for a VDI without any (a binding is never empty).
    pub slots: S,
    /// The skipping grid of the nearest filter, then the linear filter's ([`tile_masks`]):
    /// [`VdiBuffers::tiles_x`] tiles a row each.
    pub tiles: Vec<u32>,
}

/// Why parts are not the buffers of one VDI ([`VdiBuffers::from_parts`]).
#[derive(Debug, PartialEq, Eq, thiserror::Error)]
pub enum VdiBuffersError {
    /// A buffer has another length than the header implies.
    #[error("its {buffer} hold {got} values; a {width} × {height} VDI's hold {want}")]
    Length {
        /// Which buffer.
        buffer: &'static str,
        /// The values it holds.
        got: u64,
        /// The values it should hold.
        want: u64,
        /// The header's width.
        width: u32,
        /// The header's height.
        height: u32,
    },
    /// The list starts do not run from 0 to the number of slots, never falling.
    #[error(
        "its list starts are not a running count from 0 to its {slots} supersegments \
         (list {list} starts at {start})"
    )]
    Starts {
        /// The first list out of order.
        list: usize,
        /// Where it starts.
        start: u32,
        /// The supersegments held.
        slots: usize,
    },
}

/// Where a VDI's supersegment slots are held until the ray caster uploads them, as they are.
pub trait VdiSlots {
    /// The slots held.
    fn count(&self) -> u64;

    /// Writes the slots to the start of `buffer` (at least 16 bytes a slot) on `queue`.
    ///
    /// # Errors
    /// A message where the write is refused.
    fn write_to(&self, queue: &wgpu::Queue, buffer: &wgpu::Buffer) -> Result<(), String>;
}

impl VdiSlots for Vec<[f32; 4]> {
    fn count(&self) -> u64 {
        self.len() as u64
    }

    fn write_to(&self, queue: &wgpu::Queue, buffer: &wgpu::Buffer) -> Result<(), String> {
        queue.write_buffer(buffer, 0, bytemuck::cast_slice(self));
        Ok(())
    }
}

impl VdiBuffers {
    /// The buffers of `vdi`: its slots packed, its skipping grids built (native builds on
    /// rayon's threads).
    pub fn of(vdi: &VolumetricDepthImage) -> Self {
        let list_starts = vdi.starts();
        let masks = list_masks(vdi, &list_starts);
        let width = vdi.header.width;
        let (mut tiles, _) = tile_masks(&masks, width, VdiFilter::Nearest);
        tiles.extend(tile_masks(&masks, width, VdiFilter::Linear).0);
        Self {
            header: vdi.header.clone(),
            // Σ counts ≤ MAX_VDI_SLOTS fits a u32.
            starts: list_starts.iter().map(|&s| s as u32).collect(),
            slots: packed_slots(vdi),
            tiles,
        }
    }
}

impl<S: VdiSlots> VdiBuffers<S> {
    /// The buffers from their parts, as [`VdiBuffers::of`] built them (the page's worker
    /// sends them to its main thread as typed arrays).
    ///
    /// # Errors
    /// [`VdiBuffersError`] where a part's length does not fit the header, or the starts are
    /// not a running count of the slots. (The slots' and the tiles' values are not checked
    /// again: WebGPU bounds every read of them.)
    pub fn from_parts(
        header: VdiHeader,
        starts: Vec<u32>,
        slots: S,
        tiles: Vec<u32>,
    ) -> Result<Self, VdiBuffersError> {
        let (width, height) = (header.width, header.height);
        // In u64: a header's width × height overflows a wasm32 usize.
        let length = |buffer, got: u64, want: u64| {
            if got == want {
                Ok(())
            } else {
                Err(VdiBuffersError::Length {
                    buffer,
                    got,
                    want,
                    width,
                    height,
                })
            }
        };
        let lists = u64::from(width) * u64::from(height);
        length("list starts", starts.len() as u64, lists + 1)?;
        let (tiles_x, tiles_y) = tile_grid(width, height);
        length(
            "skipping tiles",
            tiles.len() as u64,
            2 * u64::from(tiles_x) * u64::from(tiles_y),
        )?;
        let used = starts.last().map_or(0, |&s| s as usize);
        // A VDI without supersegments holds one zero slot.
        length("slots", slots.count(), used.max(1) as u64)?;
        let mut previous = 0;
        for (list, &start) in starts.iter().enumerate() {
            if start < previous || (list == 0 && start != 0) {
                return Err(VdiBuffersError::Starts {
                    list,
                    start,
                    slots: used,
                });
            }
            previous = start;
        }
        Ok(Self {
            header,
            starts,
            slots,
            tiles,
        })
    }

    /// Tiles per row of each skipping grid.
    pub fn tiles_x(&self) -> u32 {
        tile_grid(self.header.width, self.header.height).0
    }
}

/// Lists per tile edge of the skipping grid.
pub const SKIP_TILE: u32 = 8;

/// The tiles a row and the rows of tiles of the skipping grid over `width × height` cells.
pub fn tile_grid(width: u32, height: u32) -> (u32, u32) {
    (width.div_ceil(SKIP_TILE), height.div_ceil(SKIP_TILE))
}

/// The skipping grid of `vdi` for `filter` (the paper's Sec. 4.3): per `SKIP_TILE × SKIP_TILE`
/// tile of the cells a ray walks, row-major, a mask whose bit `b` is set where a supersegment
/// of a list those cells read reaches depth bin `b` of [`grid_bins`]; and the tiles per row.
/// See [`tile_masks`] for the cells of each filter.
pub fn skipping_grid(vdi: &VolumetricDepthImage, filter: VdiFilter) -> (Vec<u32>, u32) {
    tile_masks(&list_masks(vdi, &vdi.starts()), vdi.header.width, filter)
}

/// Per list of `vdi` (row-major from the top; `starts` its [`VolumetricDepthImage::starts`]),
/// the mask of the depth bins of [`grid_bins`] its supersegments reach.
///
/// A supersegment's depth is its distance along its list's ray times the cosine of that ray
/// off `V_O`'s forward, as the shader computes it; each reaches the bins of its depth span
/// widened by a hundredth of a bin, so that rounding in the shader never skips it.
fn list_masks(vdi: &VolumetricDepthImage, starts: &[usize]) -> Vec<u32> {
    let h = &vdi.header;
    let (w, rows) = (h.width, h.height);
    let (near, bin) = grid_bins(h);
    let tan_x = glam::Vec3::from(h.rays.right).length();
    let tan_y = glam::Vec3::from(h.rays.up).length();
    let last = VDI_DEPTH_BINS as f32 - 1.0;
    let bin_of = |z: f32| ((z - near) / bin).floor().clamp(0.0, last) as u32;
    let mut masks = vec![0u32; (w * rows) as usize];
    let fill_row = |(y, row): (usize, &mut [u32])| {
        let oy = (1.0 - (y as f32 + 0.5) / rows as f32 * 2.0) * tan_y;
        for (x, mask) in row.iter_mut().enumerate() {
            let list = y * w as usize + x;
            let ox = ((x as f32 + 0.5) / w as f32 * 2.0 - 1.0) * tan_x;
            let cos = (1.0 + ox * ox + oy * oy).sqrt().recip();
            for [front, back] in &vdi.depth[starts[list]..starts[list + 1]] {
                let lo = bin_of(front * cos - 0.01 * bin);
                let hi = bin_of(back * cos + 0.01 * bin).max(lo);
                *mask |= (u32::MAX >> (31 - (hi - lo))) << lo;
            }
        }
    };
    // Rows on rayon's threads natively, one after the other in the page.
    #[cfg(not(target_arch = "wasm32"))]
    {
        use rayon::prelude::*;
        masks
            .par_chunks_mut(w as usize)
            .enumerate()
            .for_each(fill_row);
    }
    #[cfg(target_arch = "wasm32")]
    masks.chunks_mut(w as usize).enumerate().for_each(fill_row);
    masks
}

/// The skipping grid from per-list masks (`width` lists a row): per tile of `SKIP_TILE ×
/// SKIP_TILE` cells of the grid a ray walks with `filter`, the OR of the masks of the lists
/// those cells read; and the tiles per row.
///
/// With the nearest filter a cell is a list. With the linear filter cell `c` (in x or y) lies
/// between the centres of lists `c − 1` and `c`, clamped to the image, and cell `width` goes
/// with the tile of cell `width − 1` (as `vdi_render.wgsl`'s `tile_mask` looks it up): so a
/// tile of cells reads its own lists and the one before its first, and list `x` is read by
/// the tiles of cells `x` and `x + 1`.
pub fn tile_masks(masks: &[u32], width: u32, filter: VdiFilter) -> (Vec<u32>, u32) {
    let rows = masks.len() as u32 / width.max(1);
    let (tiles_x, tiles_y) = tile_grid(width, rows);
    let mut tiles = vec![0u32; (tiles_x * tiles_y) as usize];
    let reach = u32::from(filter == VdiFilter::Linear);
    // The tiles whose cells read list `i` of `n`.
    let tiles_of = |i: u32, n: u32| i / SKIP_TILE..=(i + reach).min(n - 1) / SKIP_TILE;
    for y in 0..rows {
        for x in 0..width {
            let mask = masks[(y * width + x) as usize];
            if mask == 0 {
                continue;
            }
            for ty in tiles_of(y, rows) {
                for tx in tiles_of(x, width) {
                    tiles[(ty * tiles_x + tx) as usize] |= mask;
                }
            }
        }
    }
    (tiles, tiles_x)
}

/// The skipping grid's depth bins for a VDI of `header`: the nearest depth and the depth per
/// bin, [`VDI_DEPTH_BINS`] bins from the header's `near` to its `far`.
pub fn grid_bins(header: &VdiHeader) -> (f32, f32) {
    let span = (header.far - header.near)
        .max(header.far * 1e-6)
        .max(f32::MIN_POSITIVE);
    (header.near, span / VDI_DEPTH_BINS as f32)
}

/// The supersegments of `vdi`, lists one after the other as the file holds them, each as the
/// generator's pass writes a slot ([`vdi_slot`]); one zero slot for a VDI without any (a
/// binding is never empty). Native builds pack on rayon's threads.
fn packed_slots(vdi: &VolumetricDepthImage) -> Vec<[f32; 4]> {
    let slot = |(&c, &d): (&[half::f16; 4], &[f32; 2])| vdi_slot(c, d);
    if vdi.colour.is_empty() {
        return vec![[0.0; 4]];
    }
    #[cfg(not(target_arch = "wasm32"))]
    return {
        use rayon::prelude::*;
        vdi.colour.par_iter().zip(&vdi.depth).map(slot).collect()
    };
    #[cfg(target_arch = "wasm32")]
    return vdi.colour.iter().zip(&vdi.depth).map(slot).collect();
}
