//! The residency state of one volume on the GPU: which bricks are where. The residency octree
//! (partial-residency masks and value ranges per node) and its node buffer, the page tables,
//! the brick cache, and the classes the ray caster culls with (after the nodes): per node for
//! ours, per brick for the baselines, each "empty" or "constant" per channel under the
//! transfer functions. It changes as bricks arrive and are evicted, each arrival filling the
//! aprons it completes (`apron`); a restyle only redoes the classes, the clear-brick
//! marks and the aprons that stood in for clear bricks (`ResidencyState::restyle`), so
//! every resident brick stays.

use super::apron::{self, Aprons, EntryKind, LowFaces, Part, PartSource};
use super::brick_cache::BrickCache;
use super::buffers::{check_binding, storage_buffer};
use super::contract::{CLASS_CONSTANT_SHIFT, IsoSide, RECORD_WORDS, SEGMENT_HEADS};
use super::device::Gpu;
use super::error::GpuError;
use super::method::Method;
use super::options::RenderOptions;
use super::page_table::{
    ENTRY_CLEAR, ENTRY_EMPTY, ENTRY_MISSING, PageTables, entry_slot, slot_entry,
};
use crate::octree::{OctreeGeometry, ResidencyOctree, f32_down, f32_up};
use crate::scene::{ChannelStyle, Filter, RenderMode};
use crate::source::{BrickKey, BrickVoxels, VolumeInfo};

/// Outcome of inserting one brick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Inserted {
    /// Uploaded into a cache slot, evicting the given brick if any.
    Uploaded {
        /// The brick evicted to make room.
        evicted: Option<BrickKey>,
    },
    /// Fill value everywhere: marked resident without a slot.
    Empty,
    /// Already resident.
    AlreadyResident,
    /// Every slot holds a brick the current frame used: nothing evicted, brick dropped.
    CacheFull,
}

/// Octree, page tables, cache and their GPU buffers for the channels one renderer draws.
pub(crate) struct ResidencyState {
    info: VolumeInfo,
    method: Method,
    /// The filter the classes and clear marks are widened for.
    filter: Filter,
    empty_space_skipping: bool,
    octree: ResidencyOctree,
    pages: PageTables,
    cache: BrickCache,
    /// What the slots' aprons hold.
    aprons: Aprons,
    /// The octree's nodes, then the per-node classes (ours) or per-brick classes (the
    /// baselines).
    nodes: wgpu::Buffer,
    /// Word offset of the classes in `nodes`.
    class_offset: u32,
    /// The node classes as uploaded (`node_class` of every node; empty for the baselines),
    /// kept for the CPU's own culling (SparseLeap's geometry, the rasterize cut).
    classes: Vec<u32>,
    /// Where the ray segment lists lie in `nodes` (SparseLeap and rasterize only).
    segments: Option<SegmentArea>,
    /// The baselines' per-brick value ranges, by page-table id (`f32`, rounded outward).
    brick_ranges: Vec<(f32, f32)>,
    /// Per channel slot of the octree, its style (`None`: not drawn, so empty).
    styles: Vec<Option<ChannelStyle>>,
    /// The mode the styles are drawn in (what "empty" means: [`ChannelStyle::hides`]).
    mode: RenderMode,
    /// What the next flush, or the next occupancy geometry, must redo.
    pending: Pending,
}

/// What a [`ResidencyState`] must redo.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Pending {
    /// Every class must be rewritten at the next flush (a restyle).
    classes: bool,
    /// Every slot's apron must be refilled at the next flush (a restyle emptied the parts that
    /// stood in for clear bricks).
    aprons: bool,
    /// Classes or residency masks changed since SparseLeap's occupancy geometry was last built
    /// ([`ResidencyState::take_occupancy_changed`]).
    occupancy: bool,
}

/// Where the ray segment lists of one renderer lie in its node buffer, after the nodes and
/// classes: the layout of [`super::contract::SEGMENT_HEADS`], for one image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct SegmentArea {
    /// Word offset in the node buffer (a multiple of 64 words, so the segment pass can bind
    /// it with the offset alignment WebGPU guarantees).
    pub offset_words: u64,
    /// Pixels of the image.
    pub pixels: u64,
    /// Records the pool holds.
    pub capacity: u64,
}

/// Records per pixel the pool holds when the device allows. SparseLeap's paper sizes its pool
/// for an average depth complexity of 4 to 8; a cut of small bricks (the rasterize method with
/// bricks of 8³ to 32³) puts more on a ray, so the pool holds twice the paper's largest.
const RECORDS_PER_PIXEL: u64 = 16;

impl SegmentArea {
    /// The area for `options` after `words_before` words, or `None` for a method without
    /// segment lists. The pool holds [`RECORDS_PER_PIXEL`] records per pixel, fewer where
    /// the device's largest binding is smaller (a ray whose list does not fit is marched
    /// whole).
    ///
    /// # Errors
    /// [`GpuError::BindingTooLarge`] when not even one record per pixel fits.
    fn plan(
        gpu: &Gpu,
        options: &RenderOptions,
        words_before: u64,
    ) -> Result<Option<Self>, GpuError> {
        if !options.method.uses_segment_lists() {
            return Ok(None);
        }
        let pixels = u64::from(options.width) * u64::from(options.height);
        let offset_words = words_before.div_ceil(64) * 64;
        let fixed = offset_words + u64::from(SEGMENT_HEADS) + 2 * pixels;
        let limit_words = gpu
            .limits
            .max_storage_buffer_binding_size
            .min(gpu.limits.max_buffer_size)
            / 4;
        let room = limit_words.saturating_sub(fixed) / u64::from(RECORD_WORDS);
        let capacity = (RECORDS_PER_PIXEL * pixels)
            .min(room)
            .min(u64::from(u32::MAX / 4));
        let area = Self {
            offset_words,
            pixels,
            capacity,
        };
        if capacity < pixels {
            check_binding(
                gpu,
                "the ray segment lists",
                (fixed + pixels * u64::from(RECORD_WORDS)) * 4,
                "render a smaller image",
            )?;
        }
        Ok(Some(area))
    }

    /// Bytes of the node buffer up to the end of the area.
    pub fn end_bytes(&self) -> u64 {
        (self.offset_words
            + u64::from(SEGMENT_HEADS)
            + 2 * self.pixels
            + self.capacity * u64::from(RECORD_WORDS))
            * 4
    }

    /// Bytes from the start of the area to the first record: the counter, heads and overflow
    /// flags, cleared before each frame's lists are drawn.
    pub fn header_bytes(&self) -> u64 {
        (u64::from(SEGMENT_HEADS) + 2 * self.pixels) * 4
    }
}

/// What the ray caster needs to know of a node's or brick's value range in one channel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RangeClass {
    /// The transfer function is transparent over the range, the range holds no data, or the
    /// channel is not drawn: nothing to sample.
    pub empty: bool,
    /// The range is one value: integrated in closed form.
    pub constant: bool,
}

/// The class of a value range `[lo, hi]` (`f32`, as the shader sees it) under `style` in
/// `mode`, by the exact rule of [`ChannelStyle::hides`]; the clear bricks ([`is_clear`])
/// follow it too.
pub fn range_class(style: Option<&ChannelStyle>, mode: RenderMode, lo: f32, hi: f32) -> RangeClass {
    let empty = match style {
        None => true,
        // No data (an empty range, or NaN only) shows nothing.
        Some(s) => {
            lo.partial_cmp(&hi).is_none_or(std::cmp::Ordering::is_gt)
                || s.hides(mode, f64::from(lo), f64::from(hi))
        }
    };
    RangeClass {
        empty,
        constant: lo == hi,
    }
}

/// The class words of every node of `octree` under `styles` in `mode` (`node_class` of
/// each), as a renderer of our method uploads them.
pub fn node_classes(
    octree: &ResidencyOctree,
    styles: &[Option<ChannelStyle>],
    mode: RenderMode,
) -> Vec<u32> {
    (0..octree.geometry().node_count())
        .map(|n| node_class(octree, styles, mode, n))
        .collect()
}

/// The class word of node `node` of `octree` under `styles` (one per channel slot): bit `c`
/// where channel slot `c` is empty, bit [`CLASS_CONSTANT_SHIFT`]` + c` where it is constant.
pub(crate) fn node_class(
    octree: &ResidencyOctree,
    styles: &[Option<ChannelStyle>],
    mode: RenderMode,
    node: usize,
) -> u32 {
    let mut word = 0;
    for (c, style) in styles.iter().enumerate() {
        let (lo, hi) = octree.range(node, c);
        let class = range_class(style.as_ref(), mode, f32_down(lo), f32_up(hi));
        word |= u32::from(class.empty) << c
            | u32::from(class.constant) << (CLASS_CONSTANT_SHIFT as usize + c);
    }
    word
}

impl ResidencyState {
    /// Empty residency for `channels` of `info` sampled with `filter`: the octree (ranges from
    /// the volume's region metadata, widened by the filter's reach), page tables with every
    /// brick missing, a cache of `options.cache_bytes`, and (for the baselines) each brick's
    /// value range.
    ///
    /// # Errors
    /// The octree's refusal of the volume or channels, or a [`GpuError`] where the page
    /// tables, the cache or the octree buffer exceed the device's limits.
    pub fn new(
        gpu: &Gpu,
        info: &VolumeInfo,
        channels: &[usize],
        filter: Filter,
        options: &RenderOptions,
    ) -> Result<Self, GpuError> {
        let depth = match options.octree_depth {
            Some(d) => d,
            None => OctreeGeometry::depth_for(info, options.leaf_voxels, 7),
        };
        let octree = ResidencyOctree::for_filter(info, channels, depth, filter.reach())?;
        let geometry = octree.geometry();
        let pages = PageTables::new(&gpu.device, geometry, channels)?;
        let cache = BrickCache::new(
            &gpu.device,
            &gpu.limits,
            info.sample_type,
            geometry.brick.map(|b| b as u32),
            options.cache_bytes,
        )?;
        let node_words = geometry.node_count() * octree.words_per_node();
        // Per-brick value ranges, for the baselines' classes: the page table culls the brick
        // it samples, the octree a brick and its subtree.
        let brick_ranges: Vec<(f32, f32)> = if options.method.uses_node_classes() {
            Vec::new()
        } else {
            (0..pages.len() as u32)
                .map(|id| {
                    let (lo, hi) = pages
                        .key(id)
                        .map_or((f64::INFINITY, f64::NEG_INFINITY), |k| {
                            match options.method {
                                // Culling a brick of the octree culls its subtree.
                                Method::Octree => info.widened_subtree_range(&k, filter.reach()),
                                _ => info.widened_brick_range(&k, filter.reach()),
                            }
                        });
                    (f32_down(lo), f32_up(hi))
                })
                .collect()
        };
        // One class word per node (ours) or per brick (the baselines) after the nodes.
        let class_words = if options.method.uses_node_classes() {
            geometry.node_count()
        } else {
            brick_ranges.len()
        };
        let segments = SegmentArea::plan(gpu, options, (node_words + class_words) as u64)?;
        let bytes = segments.map_or((node_words + class_words) as u64 * 4, |a| a.end_bytes());
        let hint = if brick_ranges.is_empty() {
            "use a smaller --octree-depth"
        } else {
            "use a smaller --octree-depth, or the residency method"
        };
        check_binding(gpu, "the octree", bytes, hint)?;
        let nodes = storage_buffer(gpu, "octree nodes", bytes, wgpu::BufferUsages::empty());
        let styles = vec![None; octree.channels().len()];
        let aprons = Aprons::new(cache.capacity());
        Ok(Self {
            info: info.clone(),
            method: options.method,
            filter,
            empty_space_skipping: options.empty_space_skipping,
            octree,
            pages,
            cache,
            aprons,
            nodes,
            class_offset: node_words as u32,
            classes: if options.method.uses_node_classes() {
                vec![0; class_words]
            } else {
                Vec::new()
            },
            segments,
            brick_ranges,
            styles,
            mode: RenderMode::Dvr,
            pending: Pending {
                classes: true,
                aprons: false,
                occupancy: true,
            },
        })
    }

    /// The volume.
    pub fn info(&self) -> &VolumeInfo {
        &self.info
    }

    /// The residency octree.
    pub fn octree(&self) -> &ResidencyOctree {
        &self.octree
    }

    /// The page tables.
    pub fn pages(&self) -> &PageTables {
        &self.pages
    }

    /// The brick cache.
    pub fn cache(&self) -> &BrickCache {
        &self.cache
    }

    /// The cache, for folding in the shader's usage feedback.
    pub fn cache_mut(&mut self) -> &mut BrickCache {
        &mut self.cache
    }

    /// The octree's node buffer; the classes (one word per node for ours, per page-table id
    /// for the baselines) follow the nodes.
    pub fn nodes(&self) -> &wgpu::Buffer {
        &self.nodes
    }

    /// Word offset of the classes in [`ResidencyState::nodes`].
    pub fn class_offset(&self) -> u32 {
        self.class_offset
    }

    /// Where the ray segment lists lie in [`ResidencyState::nodes`] (SparseLeap and
    /// rasterize; `None` for the other methods).
    pub fn segment_area(&self) -> Option<SegmentArea> {
        self.segments
    }

    /// Whether classes or residency changed since the last call (SparseLeap rebuilds its
    /// occupancy geometry then).
    pub fn take_occupancy_changed(&mut self) -> bool {
        std::mem::take(&mut self.pending.occupancy)
    }

    /// The node classes the shader culls with, as of the last flush (`node_class` of every
    /// node; empty for the baselines, which cull per brick).
    pub fn classes(&self) -> &[u32] {
        &self.classes
    }

    /// Takes the channel `styles` (one per channel drawn): the node or brick classes are
    /// rewritten at the next [`ResidencyState::flush`], and the [`ENTRY_CLEAR`] marks redone: a
    /// missing brick that [`is_clear`] under its channel's style is never fetched, and a
    /// sample whose footprint reaches it is clear. Only the residency method with empty-space
    /// skipping marks bricks clear.
    pub fn restyle(&mut self, styles: &[&ChannelStyle], mode: RenderMode) {
        self.mode = mode;
        self.styles = self
            .octree
            .channels()
            .iter()
            .map(|&c| styles.iter().find(|s| s.channel == c).map(|s| (*s).clone()))
            .collect();
        self.pending.classes = true;
        if !self.method.uses_node_classes() || !self.empty_space_skipping {
            return;
        }
        for slot in self.aprons.drop_stand_ins() {
            if let Some(id) = self.cache.owner(slot) {
                self.pages.set(id, slot_entry(slot, 0));
            }
        }
        self.pending.aprons = true;
        for id in 0..self.pages.len() as u32 {
            let Some(key) = self.pages.key(id) else {
                continue;
            };
            let entry = self.pages.entry(id);
            if entry != ENTRY_MISSING && entry != ENTRY_CLEAR {
                // A resident brick keeps its slot: a restyle that makes it transparent still
                // finds it when it is shown again.
                continue;
            }
            let clear = self
                .style_of(&key)
                .is_some_and(|style| is_clear(&self.info, style, self.mode, &key, self.filter));
            let wanted = if clear { ENTRY_CLEAR } else { ENTRY_MISSING };
            if entry != wanted {
                self.pages.set(id, wanted);
            }
        }
    }

    /// The style of `key`'s channel (`None`: not drawn).
    fn style_of(&self, key: &BrickKey) -> Option<&ChannelStyle> {
        let slot = self.octree.slot_of(key.channel as usize)?;
        self.styles[slot].as_ref()
    }

    /// Whether `key` is resident (in a slot, or as a fill-value brick).
    pub fn is_resident(&self, key: &BrickKey) -> bool {
        self.octree.is_resident(key)
    }

    /// Inserts a fetched brick at frame `frame`: takes a slot (evicting the least recently
    /// used brick not used by that frame), uploads it, and updates the page table and the
    /// octree.
    ///
    /// # Errors
    /// [`GpuError::NotRendered`] for a brick of another channel or volume, and
    /// [`GpuError::Upload`] (naming the brick) for one of the wrong size or type, which
    /// changes nothing.
    pub fn insert(
        &mut self,
        gpu: &Gpu,
        key: BrickKey,
        voxels: &BrickVoxels,
        frame: u32,
    ) -> Result<Inserted, GpuError> {
        let id = self.pages.id(&key).ok_or(GpuError::NotRendered { key })?;
        if self.pages.entry(id) != ENTRY_MISSING {
            return Ok(Inserted::AlreadyResident);
        }
        if let BrickVoxels::Empty = voxels {
            self.pages.set(id, ENTRY_EMPTY);
            self.octree.insert(key)?;
            self.octree.refine_ranges(&key, voxels);
            self.fill_lower_aprons(gpu, &key);
            return Ok(Inserted::Empty);
        }
        let bytes = self
            .cache
            .brick_bytes(voxels)
            .map_err(|e| GpuError::Upload {
                key,
                source: Box::new(e),
            })?;
        let Some((slot, evicted_id)) = self.cache.allocate(frame) else {
            return Ok(Inserted::CacheFull);
        };
        let evicted = match evicted_id {
            Some(old) => {
                let old_key = self.pages.key(old).ok_or(GpuError::SlotWithoutKey)?;
                self.pages.set(old, ENTRY_MISSING);
                self.octree.evict(old_key)?;
                self.aprons.forget(old);
                Some(old_key)
            }
            None => None,
        };
        self.cache.upload(&gpu.queue, slot, bytes);
        let faces = LowFaces::of(bytes, self.cache.brick(), self.cache.sample_type().bytes());
        self.aprons.take_slot(slot, id, faces);
        self.cache.assign(slot, id);
        self.fill_apron(gpu, id, slot);
        self.octree.insert(key)?;
        // Without region metadata, level-0 bricks give ranges (the fallback).
        self.octree.refine_ranges(&key, voxels);
        self.fill_lower_aprons(gpu, &key);
        Ok(Inserted::Uploaded { evicted })
    }

    /// The neighbour of `key` at `offset` (`x, y, z` bricks; `sign` ±1) in its level's grid.
    fn neighbour(&self, key: &BrickKey, offset: [u64; 3], sign: i64) -> Option<u32> {
        let mut brick = key.brick;
        for a in 0..3 {
            let b = &mut brick[2 - a];
            *b = b.checked_add_signed(sign * offset[a] as i64)?;
        }
        self.pages.id(&BrickKey { brick, ..*key })
    }

    /// What brick `id` offers its lower neighbours' aprons now (`None`: not yet known).
    fn part_source(&self, id: u32) -> Option<PartSource<'_>> {
        match apron::entry_offers(self.pages.entry(id))? {
            EntryKind::Resident => self.aprons.faces(id).map(PartSource::Faces),
            EntryKind::FillValue => Some(PartSource::Constant {
                sample: vec![0; self.cache.sample_type().bytes()],
                stand_in: false,
            }),
            EntryKind::Clear => {
                let (lo, _) = clear_range(&self.info, &self.pages.key(id)?, self.filter);
                apron::sample_bytes(self.cache.sample_type(), lo).map(|sample| {
                    PartSource::Constant {
                        sample,
                        stand_in: true,
                    }
                })
            }
        }
    }

    /// Fills the parts of the apron of brick `id` (in `slot`) that its neighbours can fill
    /// now, and rewrites its entry with the crossings its apron serves
    /// ([`super::page_table::ENTRY_APRON`]).
    fn fill_apron(&mut self, gpu: &Gpu, id: u32, slot: u32) {
        let Some(key) = self.pages.key(id) else {
            return;
        };
        let xyz = [key.brick[2], key.brick[1], key.brick[0]];
        let needed = apron::needed_parts(xyz, self.pages.grid(key.level));
        let brick = self.cache.brick();
        for part in 1..8 as Part {
            if needed & !self.aprons.filled(slot) & (1 << part) == 0 {
                continue;
            }
            let Some(n) = self.neighbour(&key, apron::part_offset(part), 1) else {
                continue;
            };
            let (origin, extent) = apron::part_box(part, brick);
            let (bytes, stand_in) = match self.part_source(n) {
                None => continue,
                Some(PartSource::Faces(f)) => {
                    (f.part(part, brick, self.cache.sample_type().bytes()), false)
                }
                Some(PartSource::Constant { sample, stand_in }) => (
                    sample.repeat(extent.iter().product::<u32>() as usize),
                    stand_in,
                ),
            };
            self.cache
                .write_box(&gpu.queue, slot, origin, extent, &bytes);
            self.aprons.mark(slot, part, stand_in);
        }
        let crossings = if self.aprons.used() {
            apron::servable_crossings(self.aprons.filled(slot) | !needed)
        } else {
            0
        };
        self.pages.set(id, slot_entry(slot, crossings));
    }

    /// Whether the shader may read complete aprons (the default) or must look up every brick
    /// a sample's footprint reaches. Without them a frame's usage feedback names every brick
    /// whose voxels the image reads, the neighbours an apron copied included (the
    /// benchmark's "bricks read"); the aprons stay filled either way.
    pub fn use_aprons(&mut self, gpu: &Gpu, used: bool) {
        self.aprons.set_used(used);
        self.refill_aprons(gpu);
    }

    /// Fills what can be filled of every occupied slot's apron, and rewrites its entry.
    fn refill_aprons(&mut self, gpu: &Gpu) {
        for slot in 0..self.cache.capacity() {
            if let Some(id) = self.cache.owner(slot) {
                self.fill_apron(gpu, id, slot);
            }
        }
    }

    /// Fills what brick `key` (just resident, or known to be the fill value) completes of the
    /// aprons of the bricks below it.
    fn fill_lower_aprons(&mut self, gpu: &Gpu, key: &BrickKey) {
        for part in 1..8 as Part {
            let Some(m) = self.neighbour(key, apron::part_offset(part), -1) else {
                continue;
            };
            if let Some(slot) = entry_slot(self.pages.entry(m))
                && self.aprons.filled(slot) & (1 << part) == 0
            {
                self.fill_apron(gpu, m, slot);
            }
        }
    }

    /// Uploads changed page-table entries, octree nodes and classes.
    pub fn flush(&mut self, gpu: &Gpu) {
        if std::mem::take(&mut self.pending.aprons) {
            self.refill_aprons(gpu);
        }
        self.pages.flush(&gpu.queue);
        let dirty = self.octree.take_dirty();
        if let Some(range) = &dirty {
            let words = self.octree.gpu_words(range.clone());
            let offset = (range.start * self.octree.words_per_node() * 4) as u64;
            gpu.queue
                .write_buffer(&self.nodes, offset, bytemuck::cast_slice(&words));
        }
        let stale = std::mem::take(&mut self.pending.classes);
        self.pending.occupancy |= stale || dirty.is_some();
        if self.method.uses_node_classes() {
            // Without region metadata, node ranges refined from arriving bricks change those
            // nodes' classes (otherwise only masks changed, and classes stand).
            let range = if stale {
                Some(0..self.octree.geometry().node_count())
            } else {
                dirty.filter(|_| self.octree.unknown_ranges())
            };
            if let Some(range) = range {
                for n in range.clone() {
                    self.classes[n] = node_class(&self.octree, &self.styles, self.mode, n);
                }
                let offset = (u64::from(self.class_offset) + range.start as u64) * 4;
                gpu.queue.write_buffer(
                    &self.nodes,
                    offset,
                    bytemuck::cast_slice(&self.classes[range]),
                );
            }
        } else if stale {
            let words: Vec<u32> = (0..self.brick_ranges.len() as u32)
                .map(|id| {
                    let style = self.pages.key(id).and_then(|k| self.style_of(&k));
                    let (lo, hi) = self.brick_ranges[id as usize];
                    match self.mode {
                        RenderMode::Iso => IsoSide::of(style, lo, hi) as u32,
                        _ => u32::from(range_class(style, self.mode, lo, hi).empty),
                    }
                })
                .collect();
            gpu.queue.write_buffer(
                &self.nodes,
                u64::from(self.class_offset) * 4,
                bytemuck::cast_slice(&words),
            );
        }
    }
}

/// The range that decides whether brick `key` is clear under `filter`: its conservative
/// (haloed) range, widened by twice the filter's reach, so that it holds every voxel of any
/// footprint of the filter that reaches the brick.
pub(crate) fn clear_range(info: &VolumeInfo, key: &BrickKey, filter: Filter) -> (f64, f64) {
    info.widened_brick_range(key, 2 * filter.reach())
}

/// Whether brick `key` is clear under `style`, `mode` and `filter`: its `clear_range`, rounded
/// outward to `f32` as the shader sees values, holds data and shows nothing in the mode
/// ([`ChannelStyle::hides`]). No brick is clear for iso-surfaces, whose crossings need every
/// sample's value. The rule behind [`ENTRY_CLEAR`], and the benchmark's "empty under the
/// TF".
pub fn is_clear(
    info: &VolumeInfo,
    style: &ChannelStyle,
    mode: RenderMode,
    key: &BrickKey,
    filter: Filter,
) -> bool {
    // An iso-surface's crossings need each sample's value, even one far from the iso value.
    if mode == RenderMode::Iso {
        return false;
    }
    let (lo, hi) = clear_range(info, key, filter);
    let (lo, hi) = (f32_down(lo), f32_up(hi));
    lo <= hi && range_class(Some(style), mode, lo, hi).empty
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::OpacityPoint;

    #[test]
    fn iso_sides_place_a_range_against_the_iso_value() {
        // A ramp from 100 (transparent) to 300 (opacity 0.4): the iso value is its middle, 200.
        let style = ChannelStyle {
            channel: 0,
            visible: true,
            color: [1.0; 3],
            opacity: vec![
                OpacityPoint {
                    value: 100.0,
                    opacity: 0.0,
                },
                OpacityPoint {
                    value: 300.0,
                    opacity: 0.4,
                },
            ],
        };
        let side = |lo, hi| IsoSide::of(Some(&style), lo, hi);
        assert_eq!(side(0.0, 199.0), IsoSide::Below);
        assert_eq!(side(201.0, 250.0), IsoSide::Above);
        assert_eq!(side(150.0, 200.0), IsoSide::Crosses);
        assert_eq!(side(200.0, 200.0), IsoSide::Crosses);
        // No data, NaN, no style or a hidden channel: nothing to follow.
        assert_eq!(side(5.0, 4.0), IsoSide::Nothing);
        assert_eq!(side(f32::NAN, 4.0), IsoSide::Nothing);
        assert_eq!(IsoSide::of(None, 0.0, 1.0), IsoSide::Nothing);
        let hidden = ChannelStyle {
            visible: false,
            ..style.clone()
        };
        assert_eq!(IsoSide::of(Some(&hidden), 0.0, 1.0), IsoSide::Nothing);
        // A transparent channel has no iso value: every range lies below it.
        let clear = ChannelStyle {
            opacity: vec![],
            ..style
        };
        assert_eq!(IsoSide::of(Some(&clear), 0.0, 3.0e38), IsoSide::Below);
        assert_eq!(
            [
                IsoSide::Crosses,
                IsoSide::Below,
                IsoSide::Above,
                IsoSide::Nothing
            ]
            .map(|s| s as u32),
            [0, 1, 2, 3]
        );
    }
}
