// The ray caster, part 1 of 7 (joined in order by viewer/src/gpu/contract.rs): its constants,
// pipeline constants, the ray state kept between passes, the bindings, and reading the scene
// tables and the octree's nodes.

// Residency-octree ray caster: Algorithm 1 of the residency octree paper, extended to
// multi-channel traversal (Sec. 6.1). One thread per pixel.
//
// Positions are cell-local: a ray's position is an integer cell (i32) plus an f32 offset in
// [0, 1) inside it, so precision does not depend on the volume's width. Cells are "fine
// units", 2^-F of an octree leaf per axis (F = P.fine): a level-0 voxel wherever leaves
// are at least a voxel, so a step of a fraction of a voxel is resolved to f32 precision
// however large the leaves are. The eye and the entry point are computed in leaf units.
// Everything about layout (words per node, table offsets) is documented in viewer/src/gpu/.

// The constants shared with Rust (ENTRY_EMPTY, ENTRY_CLEAR, MAX_LEVELS, MAX_CHANNELS, TF_BINS,
// the METHOD_* and ATLAS_* numbers, the FLAG_* bits) come from the prelude that
// viewer/src/gpu/contract.rs generates and puts before this file. Every struct below that the
// CPU also reads or writes (Params, LevelEntry, ChannelEntry, SceneUniforms, FrameCounters,
// RayState) has a #[repr(C)] twin of the same name and fields there; the viewer's test
// `gpu_contract` checks that naga lays each out as Rust does.

const T_MIN: f32 = 0.003921569; // early ray termination: transmittance below 1/255
const MAX_ITERATIONS: u32 = 1000000u; // loop guard per ray (steps plus skips)
// Sample format of the atlas (ATLAS_UINT, ATLAS_SINT or ATLAS_FLOAT), fixed when the pipeline
// is built so that only one atlas is read.
override SAMPLE_KIND: u32 = 0u;
// Traversal method: METHOD_RESIDENCY (the residency octree), METHOD_PAGE_TABLE (MRMCPT),
// METHOD_OCTREE (one node per brick, GigaVoxels style), METHOD_SPARSELEAP (ray segment lists of
// occupancy geometry) or METHOD_RASTERIZE (ray segment lists of a cut of bricks).
override METHOD: u32 = 0u;
// Reconstruction filter: FILTER_TRILINEAR or FILTER_TRICUBIC (the cubic B-spline as 8
// trilinear samples).
override FILTER: u32 = 0u;
// The resident-only pass, a frame's first: it samples only what one cache slot serves whole,
// and carries no requests, no substitution of missing bricks and no per-corner sampling. A
// ray that needs any of them stops where it stands (suspended, before that step), and the
// full pass resumes it there, so the image is the full pass's. A converged frame is then one
// pass of the smaller loop: on a CPU Vulkan driver every branch of the loop body runs on
// every iteration, taken or not, so what a converged frame never needs still costs it.
override RESIDENT_ONLY: bool = false;
// What a ray makes of its samples: MODE_DVR (emission–absorption), MODE_MIP (maximum
// intensity projection: each channel's largest value, kept between passes after the image in
// `out_color`, see channel_texel) or MODE_ISO (iso-surfaces: the nearest crossing of a
// channel's iso value, shaded).
override MODE: u32 = 0u;
const NO_LEVEL: u32 = 0xffffffffu;

// A ray between passes. A frame runs passes until no ray is suspended: a CPU Vulkan driver
// ends every loop of an invocation after 65535 iterations in all, so long rays are marched a
// bounded number of steps per pass and resumed from here.
struct RayState {
    cell: vec3<i32>,
    status: u32, // RAY_FRESH (the buffer is cleared per frame), RAY_SUSPENDED, RAY_DONE, RAY_RESTART
    local: vec3<f32>,
    t: f32,
    color: vec3<f32>,
    trans: f32,
    last_depth: u32,
    iterations: u32,
    pad0: u32,
    pad1: u32,
}

const RAY_FRESH: u32 = 0u;
const RAY_SUSPENDED: u32 = 1u;
const RAY_DONE: u32 = 2u;
const RAY_RESTART: u32 = 3u; // VDI: marches again from the start (vdi.wgsl)

struct FrameCounters {
    requests: atomic<u32>, // distinct missing bricks (before the cap)
    samples: atomic<u32>,
    empty_nodes_skipped: atomic<u32>,
    bricks_substituted: atomic<u32>,
    homogeneous_nodes: atomic<u32>,
    requests_over_cap: atomic<u32>,
    samples_without_data: atomic<u32>,
    rays_suspended: atomic<u32>, // by the latest pass
    rays_overflowed: atomic<u32>, // ray segment lists that did not fit (marched whole)
    rays_need_full: atomic<u32>, // by the latest pass (resident-only): stopped for the full pass
}

struct Requests {
    counters: FrameCounters,
    entries: array<vec2<u32>>, // (page-table id, ray distance bits)
}

@group(0) @binding(0) var<uniform> P: Params;
// The octree's nodes, then from P.class_offset the node classes (ours) or brick classes.
@group(0) @binding(1) var<storage, read> nodes: array<u32>;
// Page-table offsets (channel · levels + level), then each channel's control points.
@group(0) @binding(2) var<storage, read> tables: array<u32>;
@group(0) @binding(3) var<storage, read> page_table: array<u32>;
@group(0) @binding(4) var<storage, read_write> flags: array<atomic<u32>>;
@group(0) @binding(5) var<storage, read_write> requests: Requests;
@group(0) @binding(6) var<storage, read_write> usage: array<u32>;
@group(0) @binding(7) var<storage, read_write> out_color: array<vec4<f32>>;
@group(0) @binding(8) var atlas_u: texture_3d<u32>;
@group(0) @binding(9) var atlas_i: texture_3d<i32>;
@group(0) @binding(10) var atlas_f: texture_3d<f32>;
@group(0) @binding(11) var<storage, read_write> rays: array<RayState>;
@group(0) @binding(12) var<uniform> S: SceneUniforms;

// ---- tables ----

fn level_shift(l: u32) -> vec3<i32> {
    return S.levels[l].shift;
}

fn level_shape(l: u32) -> vec3<i32> {
    return S.levels[l].shape;
}

fn level_bricks(l: u32) -> vec3<u32> {
    return S.levels[l].bricks;
}

// Smallest edge of a voxel of level l, world units.
fn level_voxel(l: u32) -> f32 {
    return S.levels[l].voxel_edge;
}

fn page_offset(c: u32, l: u32) -> u32 {
    return tables[c * P.level_count + l];
}

// Whether brick pid is empty under its channel's transfer function (the baselines' class,
// written by the CPU with the style; ours has one class word per node instead). MODE_DVR and
// MODE_MIP only.
fn brick_empty(pid: u32) -> bool {
    return nodes[P.class_offset + pid] != 0u;
}

// MODE_ISO: where brick pid's range lies against its channel's iso value (the baselines'
// class in this mode: ISO_CROSSES, ISO_BELOW, ISO_ABOVE or ISO_NOTHING).
fn brick_iso_side(pid: u32) -> u32 {
    return nodes[P.class_offset + pid];
}

// MODE_ISO: whether a brick of channel c on `side` of its iso value may be skipped by a ray
// that knows what `iso` says: it holds nothing drawn, or lies below the value where the ray
// is not known above it, or above it where the ray is (iso_sides_agree for a node).
fn iso_side_agrees(side: u32, c: u32, iso: IsoState) -> bool {
    let known_above = (iso.known & iso.above & (1u << c)) != 0u;
    return side == ISO_NOTHING || (side == ISO_BELOW && !known_above)
        || (side == ISO_ABOVE && known_above);
}

// ---- octree ----

fn fine_shift() -> vec3<u32> {
    return vec3<u32>(P.fine);
}

// Shift from fine cells to the node of depth d holding them: `cell >> node_shift(d)`.
fn node_shift(d: u32) -> vec3<u32> {
    return vec3<u32>(P.leaf_depth - d) + fine_shift();
}

// Node of depth d holding the fine cell `cell`.
fn node_index(d: u32, cell: vec3<i32>) -> u32 {
    let n = vec3<u32>(cell >> node_shift(d));
    let offset = ((1u << (3u * d)) - 1u) / 7u;
    return offset + (((n.z << d) + n.y) << d) + n.x;
}

fn node_word(node: u32, c: u32, k: u32) -> u32 {
    return nodes[(node * P.channel_count + c) * 3u + k];
}

