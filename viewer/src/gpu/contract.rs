//! The contract between the renderer and its shaders (`shaders/raycast.wgsl`, and
//! `shaders/segments.wgsl` for the methods that rasterise ray segment lists), written once:
//!
//! - every struct the CPU and the shader share, as a `#[repr(C)]` [`bytemuck`] type here with a
//!   WGSL struct of the same name and fields in the shader ([`GpuStruct`]; the viewer's
//!   integration test `gpu_contract` compares naga's layout of each WGSL struct with the Rust
//!   offsets and sizes, so a disagreement fails the build's tests);
//! - the constants both sides use, which the shader gets as a generated prelude
//!   ([`wgsl_prelude`]), so the shader has no copy of them;
//! - the bindings of its bind group ([`binding`]).

use bytemuck::Pod;

use super::apron::APRON_VOXELS;
use super::brick_cache::AtlasKind;
use super::method::Method;
use super::page_table::{APRON_SHIFT, ENTRY_APRON, ENTRY_CLEAR, ENTRY_EMPTY};
use crate::scene::{ChannelStyle, Filter, MAX_CLIP_PLANES, RenderMode};

// The capacities the prelude gives the shader (see `wgsl_prelude`).
pub use super::limits::{MAX_CHANNELS, MAX_LEVELS};

/// Where a node's class word keeps its constant bits: bit `c` says channel slot `c` is empty
/// under its transfer function, bit `CLASS_CONSTANT_SHIFT + c` that it is constant over the
/// node (`residency::node_class`).
pub const CLASS_CONSTANT_SHIFT: u32 = MAX_CHANNELS as u32;

/// The WGSL type of a step's channel levels: 8 bits a channel, four channels a word.
pub const CHANNEL_LEVELS: &str = "vec4<u32>";

// The class word's two bits a channel fill one u32; the levels fill the four words of a
// `vec4<u32>` (the shader's `level_of` and `with_level` pick among exactly four).
const _: () = assert!(2 * MAX_CHANNELS == 32 && MAX_CHANNELS == 4 * 4);

/// What the shaders share: transfer functions, opacity correction, compositing.
const TRANSFER: &str = include_str!("../../../shaders/transfer.wgsl");

/// The per-frame uniforms and the pixel rays, shared by the ray caster and the segment lists.
const VIEW: &str = include_str!("../../../shaders/view.wgsl");

/// The ray segment lists' rasteriser as written.
const SEGMENTS_BODY: &str = include_str!("../../../shaders/segments.wgsl");

/// The ray caster as written, in its parts (by path under `shaders/`), joined in this order:
/// module-scope declarations and table reads, sampling, octree and page-table traversal, ray
/// segment lists, per-channel sampling, volumetric depth images, then the ray loop and entry
/// point in `raycast.wgsl`.
pub const RAYCAST_PARTS: [(&str, &str); 7] = [
    (
        "raycast/resources.wgsl",
        include_str!("../../../shaders/raycast/resources.wgsl"),
    ),
    (
        "raycast/sampling.wgsl",
        include_str!("../../../shaders/raycast/sampling.wgsl"),
    ),
    (
        "raycast/traversal.wgsl",
        include_str!("../../../shaders/raycast/traversal.wgsl"),
    ),
    (
        "raycast/segment_lists.wgsl",
        include_str!("../../../shaders/raycast/segment_lists.wgsl"),
    ),
    (
        "raycast/channels.wgsl",
        include_str!("../../../shaders/raycast/channels.wgsl"),
    ),
    (
        "raycast/vdi.wgsl",
        include_str!("../../../shaders/raycast/vdi.wgsl"),
    ),
    (
        "raycast.wgsl",
        include_str!("../../../shaders/raycast.wgsl"),
    ),
];

/// The VDI ray caster as written.
const VDI_RENDER_BODY: &str = include_str!("../../../shaders/vdi_render.wgsl");

/// The VDI compaction as written (it needs no prelude).
const VDI_COMPACT_BODY: &str = include_str!("../../../shaders/vdi_compact.wgsl");

/// The present pass as written (it needs no prelude).
const PRESENT_BODY: &str = include_str!("../../../shaders/present.wgsl");

/// The limit probe as written.
const PROBE_BODY: &str = include_str!("../../../shaders/probe.wgsl");

/// Binding numbers of `raycast.wgsl`'s group 0.
pub mod binding {
    /// [`super::Params`], uniform.
    pub const PARAMS: u32 = 0;
    /// The residency octree's nodes, then the per-brick ranges of the baselines.
    pub const NODES: u32 = 1;
    /// Page-table offsets and transfer-function control points.
    pub const TABLES: u32 = 2;
    /// The page tables.
    pub const PAGES: u32 = 3;
    /// Per-brick request and substitution flags.
    pub const PAGE_FLAGS: u32 = 4;
    /// [`super::FrameCounters`], then the capped request list.
    pub const REQUESTS: u32 = 5;
    /// Per-slot usage feedback.
    pub const USAGE: u32 = 6;
    /// The image, linear RGBA `f32` per pixel.
    pub const IMAGE: u32 = 7;
    /// The atlas of unsigned samples.
    pub const ATLAS_UINT: u32 = 8;
    /// The atlas of signed samples.
    pub const ATLAS_SINT: u32 = 9;
    /// The atlas of float samples.
    pub const ATLAS_FLOAT: u32 = 10;
    /// [`super::RayState`] per pixel.
    pub const RAYS: u32 = 11;
    /// [`super::SceneUniforms`], uniform.
    pub const SCENE: u32 = 12;
}

/// Binding numbers of `segments.wgsl`'s group 0.
pub mod segment_binding {
    /// [`super::Params`], uniform (the ray caster's, shared).
    pub const PARAMS: u32 = 0;
    /// The boxes, [`super::SegmentBox`] each.
    pub const BOXES: u32 = 1;
    /// The ray segment area of the node buffer (see [`super::SEGMENT_HEADS`]).
    pub const AREA: u32 = 2;
}

/// A struct shared with the shader: its WGSL name and each field's name, byte offset and
/// size, as Rust lays it out.
pub trait GpuStruct: Pod {
    /// The name of the WGSL twin.
    const WGSL_NAME: &'static str;
    /// `(name, offset, size)` of every field, in order.
    fn fields() -> Vec<(&'static str, usize, usize)>;
}

/// Defines a `#[repr(C)]` `Pod` struct and its [`GpuStruct`] description.
macro_rules! gpu_struct {
    (
        $(#[$meta:meta])*
        pub struct $name:ident {
            $( $(#[$field_meta:meta])* pub $field:ident : $ty:ty ),* $(,)?
        }
    ) => {
        $(#[$meta])*
        #[repr(C)]
        #[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
        pub struct $name {
            $( $(#[$field_meta])* pub $field: $ty ),*
        }

        impl $crate::gpu::contract::GpuStruct for $name {
            const WGSL_NAME: &'static str = stringify!($name);
            fn fields() -> Vec<(&'static str, usize, usize)> {
                vec![$(
                    (
                        stringify!($field),
                        std::mem::offset_of!($name, $field),
                        size_of::<$ty>(),
                    )
                ),*]
            }
        }
    };
}

/// [`gpu_struct!`] for the other GPU modules (each struct beside the pass that uses it).
pub(crate) use gpu_struct;

gpu_struct! {
    /// The per-frame uniforms. Positions are in "leaf units" (octree leaves) or fine units
    /// (`2^-fine` of a leaf per axis); axes are `x, y, z`.
    pub struct Params {
        /// Image width in pixels.
        pub width: u32,
        /// Image height in pixels.
        pub height: u32,
        /// Frame number (from 1): the mark of usage feedback and request flags.
        pub frame: u32,
        /// Channels drawn.
        pub channel_count: u32,
        /// Depth of the octree's leaves.
        pub leaf_depth: u32,
        /// Pyramid levels.
        pub level_count: u32,
        /// Most requests the list holds.
        pub request_cap: u32,
        /// Depth traversal starts at.
        pub start_depth: u32,
        /// Word offset of the classes in the node buffer: for ours, per node, bit `c` where
        /// channel `c` is empty under its transfer function and bit `8 + c` where it is one
        /// value (`residency::node_class`); for the baselines, per page-table id, 1
        /// where the brick is empty.
        pub class_offset: u32,
        /// Steps a ray may take per pass (then it is suspended and resumed).
        pub steps_per_pass: u32,
        /// 1: skip empty and homogeneous nodes; 2: substitute missing bricks from other levels.
        pub flags: u32,
        /// Word offset of the ray segment area in the node buffer (SparseLeap and rasterize;
        /// 0 for the other methods): see [`SEGMENT_HEADS`].
        pub segment_offset: u32,
        /// The view point `V = eye + D·forward` (`D = view_distance`), leaf units: integer
        /// part. Rays start from the plane through V facing the camera, so a far camera keeps
        /// voxel precision (`D = 0`, V the eye, for a camera near the volume).
        pub view_cell: [i32; 3],
        /// Atlas slots per z (any count; per x and y they are powers of two).
        pub slots_z: u32,
        /// V, leaf units: fraction.
        pub view_frac: [f32; 3],
        /// The reference step `Δ0` of the opacity correction (world units).
        pub reference_step: f32,
        /// Camera right · tan(fov/2) · aspect.
        pub right: [f32; 3],
        /// Level-of-detail bias (`log2`).
        pub lod_bias: f32,
        /// Camera up · tan(fov/2).
        pub up: [f32; 3],
        /// Pixel footprint per unit distance (world).
        pub pixel_footprint: f32,
        /// Camera forward (unit).
        pub forward: [f32; 3],
        /// Step as a fraction of a voxel of the level in use.
        pub step_fraction: f32,
        /// Leaf units per world unit, per axis.
        pub world_to_leaf: [f32; 3],
        /// A leaf's edge (world, smallest axis).
        pub leaf_edge: f32,
        /// Volume extent in leaf units.
        pub volume_leaf: [f32; 3],
        /// `D`, the view point's distance from the eye (world).
        pub view_distance: f32,
        /// Background colour, linear RGB.
        pub background: [f32; 3],
        /// `log2` of atlas slots per x.
        pub slots_x_log2: u32,
        /// `log2` of a fine unit's edge in level-0 voxels, per axis (leaf shift − fine).
        pub unit_shift: [i32; 3],
        /// `log2` of atlas slots per y.
        pub slots_y_log2: u32,
        /// `log2` of fine units per leaf, per axis.
        pub fine: [i32; 3],
        /// Records the ray segment area holds (0 where unused).
        pub segment_capacity: u32,
        /// Brick edge in voxels, per axis.
        pub brick: [u32; 3],
        /// Most supersegments per pixel of a volumetric depth image (the VDI pipeline; 0
        /// otherwise): see [`VDI_STATE_SLOTS`].
        pub supersegments: u32,
        /// What each ray keeps of the volume (`crate::scene::Clip`), leaf units from the
        /// volume's corner: the low corner of the box kept, the volume's own where the scene
        /// clips none (`volume_span` in `shaders/view.wgsl`).
        pub clip_lo: [f32; 3],
        /// Planes of `clip_planes` in use.
        pub clip_plane_count: u32,
        /// The high corner of the box kept.
        pub clip_hi: [f32; 3],
        /// Unused (alignment).
        pub pad0: u32,
        /// Clip planes `(n, d)`, leaf units from the volume's corner, `n` of unit length:
        /// what is kept has `n · p ≥ d` (the scene's planes, then `near`'s).
        pub clip_planes: [[f32; 4]; CLIP_PLANE_SLOTS],
    }
}

/// Slots for clip planes in [`Params`]: the scene's ([`MAX_CLIP_PLANES`]) and `near`'s.
pub const CLIP_PLANE_SLOTS: usize = MAX_CLIP_PLANES + 1;

/// Slots of a pixel's VDI state after its `supersegments` slots in the VDI target
/// (`shaders/raycast/vdi.wgsl`): the ray's VDI state between passes, then, once it is done,
/// its DVR colour (slot 0) and its supersegment count, `γ` and marches (slot 1).
pub const VDI_STATE_SLOTS: u32 = 4;

/// A supersegment as the VDI shaders hold it (`shaders/raycast/vdi.wgsl` writes it,
/// `shaders/vdi_render.wgsl` reads it): `vec4<f32>(pack2x16float(r, g), pack2x16float(b, a),
/// front, back)`, the premultiplied colour's half floats two to a word, the first in the low
/// half.
pub fn vdi_slot(colour: [half::f16; 4], depth: [f32; 2]) -> [f32; 4] {
    let pack = |lo: half::f16, hi: half::f16| {
        f32::from_bits(u32::from(lo.to_bits()) | u32::from(hi.to_bits()) << 16)
    };
    [
        pack(colour[0], colour[1]),
        pack(colour[2], colour[3]),
        depth[0],
        depth[1],
    ]
}

/// The colour and depth of a [`vdi_slot`].
pub fn vdi_slot_parts(slot: &[f32; 4]) -> ([half::f16; 4], [f32; 2]) {
    let halves = |word: f32| {
        let bits = word.to_bits();
        [
            half::f16::from_bits(bits as u16),
            half::f16::from_bits((bits >> 16) as u16),
        ]
    };
    let ([r, g], [b, a]) = (halves(slot[0]), halves(slot[1]));
    ([r, g, b, a], [slot[2], slot[3]])
}

gpu_struct! {
    /// One pyramid level in the scene uniforms.
    pub struct LevelEntry {
        /// `log2` of the downsampling factor relative to level 0, per axis.
        pub shift: [i32; 3],
        /// Smallest edge of a voxel of this level (world units).
        pub voxel_edge: f32,
        /// Shape in voxels.
        pub shape: [i32; 3],
        /// Unused (alignment).
        pub pad0: u32,
        /// Bricks per axis.
        pub bricks: [u32; 3],
        /// Unused (alignment).
        pub pad1: u32,
    }
}

gpu_struct! {
    /// One drawn channel in the scene uniforms: colour, level bounds and where its transfer
    /// function lies in the table buffer.
    pub struct ChannelEntry {
        /// Colour, linear RGB.
        pub color: [f32; 3],
        /// Opacity control points.
        pub point_count: u32,
        /// Finest level the LOD choice may pick.
        pub min_level: u32,
        /// Coarsest level the LOD choice may pick.
        pub max_level: u32,
        /// Word offset of the control points `(value, opacity)` in the table buffer.
        pub points_offset: u32,
        /// The highest opacity of the control points: maximum intensity projection's scale
        /// ([`crate::scene::ChannelStyle::opacity_top`]).
        pub opacity_top: f32,
        /// The value from which maximum intensity projection's intensity no longer changes
        /// ([`crate::scene::ChannelStyle::saturation_value`], clamped to `±f32::MAX`).
        pub saturation: f32,
        /// The iso-surface's value ([`crate::scene::ChannelStyle::iso_value`]; `f32::MAX`
        /// for none, a value no sample reaches).
        pub iso: f32,
        /// Unused (alignment).
        pub pad1: u32,
        /// Unused (alignment).
        pub pad2: u32,
    }
}

gpu_struct! {
    /// The scene uniforms: one entry per level and per drawn channel. Rewritten in place
    /// when the style changes.
    pub struct SceneUniforms {
        /// Per level (the first `level_count`).
        pub levels: [LevelEntry; MAX_LEVELS],
        /// Per drawn channel (the first `channel_count`).
        pub channels: [ChannelEntry; MAX_CHANNELS],
    }
}

gpu_struct! {
    /// The counters at the head of the request buffer (atomics in the shader), then the
    /// capped request list of `(page-table id, ray distance bits)` pairs.
    pub struct FrameCounters {
        /// Distinct missing bricks requested (before the cap).
        pub requests: u32,
        /// Samples taken.
        pub samples: u32,
        /// Octree nodes skipped as empty in every channel.
        pub empty_nodes_skipped: u32,
        /// Distinct missing bricks for which another level was substituted.
        pub bricks_substituted: u32,
        /// Homogeneous nodes integrated analytically.
        pub homogeneous_nodes: u32,
        /// Requests over the cap.
        pub requests_over_cap: u32,
        /// Samples with no resident data in any channel.
        pub samples_without_data: u32,
        /// Rays the latest pass suspended.
        pub rays_suspended: u32,
        /// Rays whose ray segment list overflowed the pool (SparseLeap, rasterize): they
        /// march their whole length.
        pub rays_overflowed: u32,
        /// Rays the latest pass, a resident-only one, stopped for the full pass (a request,
        /// a substitute or the per-corner path needed).
        pub rays_need_full: u32,
    }
}

gpu_struct! {
    /// One box the segment lists rasterise, in leaf units (`x, y, z`): a node of SparseLeap's
    /// occupancy geometry, or a brick of the rasterize method's cut. Read by the vertex and
    /// fragment stages of `segments.wgsl` from a storage buffer, one per instance.
    pub struct SegmentBox {
        /// Low corner.
        pub lo: [f32; 3],
        /// What a record of this box carries: [`segment_payload`].
        pub payload: u32,
        /// High corner.
        pub hi: [f32; 3],
        /// Unused (alignment).
        pub pad0: u32,
    }
}

gpu_struct! {
    /// One record of a pixel's ray segment list: where the pixel's ray is inside one box.
    /// Stored as [`RECORD_WORDS`] words in the ray segment area, in this order.
    pub struct SegmentRecord {
        /// Distance (the ray caster's `t`) where the ray enters the box (or starts).
        pub t_in: f32,
        /// Distance where it leaves the box (or the volume).
        pub t_out: f32,
        /// The box's payload.
        pub payload: u32,
        /// The next record of the pixel's list, plus 1 (0 ends the list).
        pub next: u32,
    }
}

/// Words of one [`SegmentRecord`].
pub const RECORD_WORDS: u32 = (size_of::<SegmentRecord>() / 4) as u32;

/// Layout of the ray segment area (words from [`Params::segment_offset`]): word 0 counts the
/// records allocated (atomic); from `SEGMENT_HEADS`, one head per pixel (the first record
/// plus 1; 0: none); then one overflow flag per pixel (1: a record did not fit, so the list is
/// incomplete); then the records, [`RECORD_WORDS`] each.
pub const SEGMENT_HEADS: u32 = 4;

/// Occupancy class of a SparseLeap box: transparent under every transfer function.
pub const OCCUPANCY_EMPTY: u32 = 0;
/// Occupancy class of a SparseLeap box: some channel visible and data resident.
pub const OCCUPANCY_NONEMPTY: u32 = 1;
/// Occupancy class of a SparseLeap box: not known to be empty, and some visible channel has
/// no level resident there yet (or the store has no region metadata).
pub const OCCUPANCY_UNKNOWN: u32 = 2;

/// The payload of a segment box: its occupancy class (bits 0–1), its octree depth (bits 4–7)
/// and the pyramid level to sample (bits 8–11; the rasterize method's brick level).
pub fn segment_payload(class: u32, depth: u32, level: u32) -> u32 {
    class | (depth & 15) << 4 | (level & 15) << 8
}

gpu_struct! {
    /// A ray between passes. A frame runs passes until no ray is suspended: a CPU Vulkan
    /// driver ends every loop of an invocation after 65535 iterations in all, so long rays
    /// are marched a bounded number of steps per pass and resumed from here.
    pub struct RayState {
        /// Fine cell.
        pub cell: [i32; 3],
        /// Fresh (the buffer is cleared per frame), suspended or done.
        pub status: u32,
        /// Offset in the cell, `[0, 1)`.
        pub local: [f32; 3],
        /// Distance travelled (world).
        pub t: f32,
        /// Colour so far.
        pub color: [f32; 3],
        /// Transmittance so far.
        pub trans: f32,
        /// Depth of the last node visited.
        pub last_depth: u32,
        /// Loop iterations so far.
        pub iterations: u32,
        /// Unused (alignment).
        pub pad0: u32,
        /// Unused (alignment).
        pub pad1: u32,
    }
}

gpu_struct! {
    /// The limit probe's uniforms (`shaders/probe.wgsl`), world units unless said.
    pub struct ProbeParams {
        /// Image width in pixels.
        pub width: u32,
        /// Image height in pixels.
        pub height: u32,
        /// Channels drawn.
        pub channel_count: u32,
        /// Depth (z voxels) of one channel's slab in the texture.
        pub slab_depth: u32,
        /// The eye.
        pub eye: [f32; 3],
        /// The reference step `Δ0` of the opacity correction.
        pub reference_step: f32,
        /// Camera right · tan(fov/2) · aspect.
        pub right: [f32; 3],
        /// The step, as the renderer's at level 0.
        pub step: f32,
        /// Camera up · tan(fov/2).
        pub up: [f32; 3],
        /// Unused (alignment).
        pub pad0: u32,
        /// Camera forward (unit).
        pub forward: [f32; 3],
        /// Unused (alignment).
        pub pad1: u32,
        /// Level-0 voxels per world unit, per axis.
        pub world_to_voxel: [f32; 3],
        /// Unused (alignment).
        pub pad2: u32,
        /// Level-0 extent in voxels.
        pub volume: [f32; 3],
        /// Unused (alignment).
        pub pad3: u32,
        /// Background colour, linear RGB.
        pub background: [f32; 3],
        /// Unused (alignment).
        pub pad4: u32,
    }
}

/// The constants the shader shares with Rust, as WGSL: page-table entries, limits, the
/// method and atlas numbers of its pipeline constants.
pub fn wgsl_prelude() -> String {
    let u = |name: &str, v: u32| format!("const {name}: u32 = {v}u;\n");
    [
        "// Generated by viewer/src/gpu/contract.rs: the constants shared with Rust.\n".into(),
        u("ENTRY_EMPTY", ENTRY_EMPTY),
        u("ENTRY_CLEAR", ENTRY_CLEAR),
        u("ENTRY_APRON", ENTRY_APRON),
        u("APRON_SHIFT", APRON_SHIFT),
        u("APRON_VOXELS", APRON_VOXELS),
        u("MAX_LEVELS", MAX_LEVELS as u32),
        u("MAX_CHANNELS", MAX_CHANNELS as u32),
        u("CLASS_CONSTANT_SHIFT", CLASS_CONSTANT_SHIFT),
        format!("alias ChannelLevels = {CHANNEL_LEVELS};\n"),
        u("METHOD_RESIDENCY", Method::Residency as u32),
        u("METHOD_PAGE_TABLE", Method::PageTable as u32),
        u("METHOD_OCTREE", Method::Octree as u32),
        u("METHOD_SPARSELEAP", Method::SparseLeap as u32),
        u("METHOD_RASTERIZE", Method::Rasterize as u32),
        u("OCCUPANCY_EMPTY", OCCUPANCY_EMPTY),
        u("OCCUPANCY_NONEMPTY", OCCUPANCY_NONEMPTY),
        u("OCCUPANCY_UNKNOWN", OCCUPANCY_UNKNOWN),
        u("SEGMENT_HEADS", SEGMENT_HEADS),
        u("RECORD_WORDS", RECORD_WORDS),
        u("FILTER_TRILINEAR", Filter::Trilinear as u32),
        u("FILTER_TRICUBIC", Filter::Tricubic as u32),
        u("MODE_DVR", RenderMode::Dvr as u32),
        u("MODE_MIP", RenderMode::Mip as u32),
        u("MODE_ISO", RenderMode::Iso as u32),
        u("ISO_CROSSES", IsoSide::Crosses as u32),
        u("ISO_BELOW", IsoSide::Below as u32),
        u("ISO_ABOVE", IsoSide::Above as u32),
        u("ISO_NOTHING", IsoSide::Nothing as u32),
        u("CLIP_PLANE_SLOTS", CLIP_PLANE_SLOTS as u32),
        u("ATLAS_UINT", AtlasKind::Uint as u32),
        u("ATLAS_SINT", AtlasKind::Sint as u32),
        u("ATLAS_FLOAT", AtlasKind::Float as u32),
        u("FLAG_SKIPPING", FLAG_SKIPPING),
        u("FLAG_SUBSTITUTION", FLAG_SUBSTITUTION),
        u("VDI_STATE_SLOTS", VDI_STATE_SLOTS),
        u("VDI_FLAG_SKIPPING", VDI_FLAG_SKIPPING),
        u(
            "VDI_MAX_SUPERSEGMENTS",
            residency_schemas::vdi::MAX_SUPERSEGMENTS,
        ),
        u("VDI_DEPTH_BINS", VDI_DEPTH_BINS),
        u("FILTER_MANUAL", FILTER_MANUAL),
        u("FILTER_HARDWARE", FILTER_HARDWARE),
    ]
    .concat()
}

/// `style`'s iso value as the shader's channel table holds it ([`ChannelEntry::iso`]): `f32`,
/// clamped to `±f32::MAX`; `f32::MAX` for none (a value no sample reaches).
pub fn gpu_iso_value(style: &ChannelStyle) -> f32 {
    style
        .iso_value()
        .map_or(f32::MAX, |v| (v as f32).clamp(-f32::MAX, f32::MAX))
}

/// Where a brick's value range lies against its channel's iso value: the page-table and
/// octree-of-bricks baselines' class word of a brick in [`RenderMode::Iso`] (`ISO_*` in the
/// shaders). A ray skips a brick below the value while it is not known above it, and one above
/// it while it is; a brick holding the value is sampled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum IsoSide {
    /// The range holds the iso value: a surface may be inside.
    Crosses = 0,
    /// Every value is below the iso value.
    Below = 1,
    /// Every value is above the iso value.
    Above = 2,
    /// No data, or the channel is not drawn: nothing to follow.
    Nothing = 3,
}

impl IsoSide {
    /// The side of a value range `[lo, hi]` (`f32`, as the shader sees it) against `style`'s
    /// iso value (`f32`, as the shader's channel table holds it; none is above every value).
    pub fn of(style: Option<&ChannelStyle>, lo: f32, hi: f32) -> Self {
        let Some(style) = style.filter(|s| s.visible) else {
            return Self::Nothing;
        };
        if lo.partial_cmp(&hi).is_none_or(std::cmp::Ordering::is_gt) {
            return Self::Nothing;
        }
        let iso = gpu_iso_value(style);
        if hi < iso {
            Self::Below
        } else if lo > iso {
            Self::Above
        } else {
            Self::Crosses
        }
    }
}

/// The limit probe's pipeline constant `FILTER`: 8 texel loads and manual weights.
pub const FILTER_MANUAL: u32 = 0;
/// The limit probe's pipeline constant `FILTER`: one hardware-filtered sample.
pub const FILTER_HARDWARE: u32 = 1;

/// Texels (`vec4<f32>`) of the ray caster's image buffer for `pixels` pixels: the image, then
/// each pixel's per-channel state kept between passes (`shaders/raycast.wgsl`'s
/// `channel_texel`): in [`RenderMode::Mip`] its running maxima, in [`RenderMode::Iso`] its
/// channels' last values and then one texel of where they were taken and their sides. Pixel
/// `p`'s channel `c` is lane `c % 4` of texel `pixels + p·K + c / 4`, `K` the texels per pixel
/// ([`state_texels`]).
pub fn image_texels(pixels: u64, mode: RenderMode, channels: usize) -> u64 {
    pixels * (1 + state_texels(mode, channels))
}

/// Texels of one pixel's state between passes in `mode` with `channels` channels drawn: none
/// for [`RenderMode::Dvr`] (the ray state holds it), `⌈channels / 4⌉` for
/// [`RenderMode::Mip`], one more for [`RenderMode::Iso`].
pub fn state_texels(mode: RenderMode, channels: usize) -> u64 {
    let values = channels.div_ceil(4) as u64;
    match mode {
        RenderMode::Dvr => 0,
        RenderMode::Mip => values,
        RenderMode::Iso => values + 1,
    }
}

/// [`Params::flags`] bit: skip empty and homogeneous nodes.
pub const FLAG_SKIPPING: u32 = 1;
/// [`Params::flags`] bit: substitute missing bricks from other levels.
pub const FLAG_SUBSTITUTION: u32 = 2;

/// The ray caster as compiled: [`wgsl_prelude`], `shaders/transfer.wgsl`,
/// `shaders/view.wgsl`, then the parts of [`RAYCAST_PARTS`] in order (`shaders/raycast/*.wgsl`,
/// ending with `shaders/raycast.wgsl`).
pub fn raycast_source() -> String {
    let mut source = [wgsl_prelude().as_str(), TRANSFER, VIEW].concat();
    for (_, part) in RAYCAST_PARTS {
        source.push_str(part);
    }
    source
}

/// The segment lists' rasteriser as compiled: [`wgsl_prelude`], `shaders/view.wgsl`, then
/// `shaders/segments.wgsl`.
pub fn segments_source() -> String {
    [wgsl_prelude().as_str(), VIEW, SEGMENTS_BODY].concat()
}

/// The limit probe as compiled: [`wgsl_prelude`], `shaders/transfer.wgsl`, then
/// `shaders/probe.wgsl`.
pub fn probe_source() -> String {
    [wgsl_prelude().as_str(), TRANSFER, PROBE_BODY].concat()
}

/// The VDI ray caster as compiled: [`wgsl_prelude`], then `shaders/vdi_render.wgsl`.
pub fn vdi_render_source() -> String {
    [wgsl_prelude().as_str(), VDI_RENDER_BODY].concat()
}

/// The VDI compaction (`shaders/vdi_compact.wgsl`, `crate::gpu::vdi`) as compiled.
pub fn vdi_compact_source() -> String {
    VDI_COMPACT_BODY.to_owned()
}

/// The present pass (`shaders/present.wgsl`, `crate::gpu::present`) as compiled.
pub fn present_source() -> String {
    PRESENT_BODY.to_owned()
}

/// The WGSL files of `shaders/` as compiled, by file name: every file is part of at least one.
pub fn sources() -> [(&'static str, String); 6] {
    [
        ("raycast.wgsl", raycast_source()),
        ("segments.wgsl", segments_source()),
        ("probe.wgsl", probe_source()),
        ("vdi_render.wgsl", vdi_render_source()),
        ("vdi_compact.wgsl", vdi_compact_source()),
        ("present.wgsl", present_source()),
    ]
}

/// [`VdiView::flags`] bit: cross cells of the skipping grid (a tile of lists over a bin of
/// depth) that no supersegment reaches in one step.
pub const VDI_FLAG_SKIPPING: u32 = 1;

/// Bins of depth per tile of the skipping grid: the bits of one `u32` mask.
pub const VDI_DEPTH_BINS: u32 = 32;

gpu_struct! {
    /// The VDI ray caster's uniforms (`shaders/vdi_render.wgsl`): the new camera, and the
    /// camera that generated the VDI (`V_O`), positions relative to `V_O`'s eye.
    pub struct VdiView {
        /// Rays cast per row: the new image's width at `D_I` (preview rendering).
        pub width: u32,
        /// Rows of rays cast.
        pub height: u32,
        /// The VDI's lists per row (`V_O`'s width in pixels).
        pub lists_x: u32,
        /// Its rows of lists.
        pub lists_y: u32,
        /// The new camera's eye.
        pub eye: [f32; 3],
        /// Subsampling along the ray (the paper's `D_R`, in `(0, 1]`): the share of the lists
        /// a ray crosses that it reads; 1 reads each one.
        pub ray_sampling: f32,
        /// The new camera's forward (unit).
        pub forward: [f32; 3],
        /// Lists per tile edge of the skipping grid.
        pub tile: u32,
        /// The new camera's right · tan(fov/2) · aspect.
        pub right: [f32; 3],
        /// Tiles per row of the skipping grid.
        pub tiles_x: u32,
        /// The new camera's up · tan(fov/2).
        pub up: [f32; 3],
        /// [`VDI_FLAG_SKIPPING`].
        pub flags: u32,
        /// `V_O`'s forward (unit).
        pub o_forward: [f32; 3],
        /// `V_O`'s tan(fov/2) · aspect.
        pub o_tan_x: f32,
        /// `V_O`'s right (unit).
        pub o_right: [f32; 3],
        /// `V_O`'s tan(fov/2).
        pub o_tan_y: f32,
        /// `V_O`'s up (unit).
        pub o_up: [f32; 3],
        /// The displayed image's width (the rays' image upsampled when smaller).
        pub out_width: u32,
        /// The volume's box: lowest corner.
        pub box_min: [f32; 3],
        /// The displayed image's height.
        pub out_height: u32,
        /// The volume's box: highest corner.
        pub box_max: [f32; 3],
        /// The skipping grid's nearest depth along `V_O`'s forward (the header's `near`).
        pub grid_near: f32,
        /// Background colour, linear RGB.
        pub background: [f32; 3],
        /// Depth along `V_O`'s forward per bin of the skipping grid.
        pub grid_bin: f32,
    }
}

/// Binding numbers of `vdi_render.wgsl`'s group 0.
pub mod vdi_binding {
    /// [`super::VdiView`], uniform.
    pub const VIEW: u32 = 0;
    /// Where each list's supersegments begin in `SLOTS` (`width·height + 1` prefix sums of
    /// the counts).
    pub const STARTS: u32 = 1;
    /// The lists' supersegments, one list after the other.
    pub const SLOTS: u32 = 2;
    /// The skipping grid: per tile of lists, a mask of the depth bins its supersegments reach.
    pub const TILES: u32 = 3;
    /// The rays' image, linear RGBA `f32` per pixel.
    pub const IMAGE: u32 = 4;
    /// The displayed image, upsampled from the rays' image (preview rendering).
    pub const DISPLAY: u32 = 5;
}

gpu_struct! {
    /// The uniforms of the VDI compaction (`shaders/vdi_compact.wgsl`).
    pub struct VdiCompactParams {
        /// Pixels of the VDI target.
        pub pixels: u32,
        /// Most supersegments per pixel (`N_S`).
        pub supersegments: u32,
        /// Slots per pixel in the target: `N_S`, then [`VDI_STATE_SLOTS`].
        pub stride: u32,
        /// Pixels per row of the dispatch grid (workgroups along x × 256).
        pub row: u32,
    }
}

/// Binding numbers of `vdi_compact.wgsl`'s group 0.
pub mod vdi_compact_binding {
    /// [`super::VdiCompactParams`], uniform.
    pub const PARAMS: u32 = 0;
    /// The VDI pass's target.
    pub const TARGET: u32 = 1;
    /// Per pixel its two state slots (`gather` writes them).
    pub const STATE: u32 = 2;
    /// Per pixel where its supersegments begin in `PACKED`.
    pub const STARTS: u32 = 3;
    /// The used slots, one pixel after the other (`scatter` writes them).
    pub const PACKED: u32 = 4;
}

/// Binding numbers of `probe.wgsl`'s group 0.
pub mod probe_binding {
    /// [`super::ProbeParams`], uniform.
    pub const PARAMS: u32 = 0;
    /// Control points of the transfer functions.
    pub const TABLES: u32 = 1;
    /// [`super::SceneUniforms`], uniform.
    pub const SCENE: u32 = 2;
    /// Level 0 of every drawn channel, stacked in z.
    pub const LEVEL0: u32 = 3;
    /// The sampler of the hardware-filtered path.
    pub const SAMPLER: u32 = 4;
    /// The image, linear RGBA `f32` per pixel.
    pub const IMAGE: u32 = 5;
    /// Samples per image row.
    pub const ROW_SAMPLES: u32 = 6;
}
