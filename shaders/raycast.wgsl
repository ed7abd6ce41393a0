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
const NO_LEVEL: u32 = 0xffffffffu;

// A ray between passes. A frame runs passes until no ray is suspended: a CPU Vulkan driver
// ends every loop of an invocation after 65535 iterations in all, so long rays are marched a
// bounded number of steps per pass and resumed from here.
struct RayState {
    cell: vec3<i32>,
    status: u32, // RAY_FRESH (the buffer is cleared per frame), RAY_SUSPENDED, RAY_DONE
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
// written by the CPU with the style; ours has one class word per node instead).
fn brick_empty(pid: u32) -> bool {
    return nodes[P.class_offset + pid] != 0u;
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

// ---- sampling ----

fn scaled_int(cell: i32, sh: i32) -> i32 {
    if sh >= 0 {
        return cell << u32(sh);
    }
    return cell >> u32(-sh);
}

fn scaled_frac(cell: i32, local: f32, sh: i32) -> f32 {
    if sh >= 0 {
        return ldexp(local, sh);
    }
    let rem = cell & ((1 << u32(-sh)) - 1);
    return ldexp(f32(rem) + local, sh);
}

// Atlas texel at p, in whichever atlas holds the sample format.
fn texel(p: vec3<i32>) -> f32 {
    switch SAMPLE_KIND {
        case ATLAS_UINT: {
            return f32(textureLoad(atlas_u, p, 0).x);
        }
        case ATLAS_SINT: {
            return f32(textureLoad(atlas_i, p, 0).x);
        }
        default: {
            return textureLoad(atlas_f, p, 0).x;
        }
    }
}

// Atlas origin of the slot of a resident page-table entry; records the slot's use (LRU, and
// the bricks a frame needs resident). Slots per x and y are powers of two (P.slots_x_log2y: log2).
// A slot holds the brick and its apron: APRON_VOXELS more voxels per axis.
fn slot_origin(entry: u32) -> vec3<i32> {
    let slot = (entry & ~ENTRY_APRON) - 2u;
    usage[slot] = P.frame;
    let lx = P.slots_x_log2;
    let ly = P.slots_y_log2;
    let sc = vec3<u32>(slot & ((1u << lx) - 1u), (slot >> lx) & ((1u << ly) - 1u), slot >> (lx + ly));
    return vec3<i32>(sc * (P.brick + vec3<u32>(APRON_VOXELS)));
}

fn request(pid: u32, t: f32) {
    let old = atomicExchange(&flags[2u * pid], P.frame);
    if old != P.frame {
        let i = atomicAdd(&requests.counters.requests, 1u);
        if i < P.request_cap {
            requests.entries[i] = vec2<u32>(pid, bitcast<u32>(t));
        } else {
            atomicAdd(&requests.counters.requests_over_cap, 1u);
        }
    }
}

// Set in the resident-only pass when the ray's step needs the full pass.
var<private> needs_full: bool;

fn note_substituted(pid: u32) {
    let old = atomicExchange(&flags[2u * pid + 1u], P.frame);
    if old != P.frame {
        atomicAdd(&requests.counters.bricks_substituted, 1u);
    }
}

// A ray position in voxels of level l: integer part plus offset (node-local precision).
struct LevelPos {
    ip: vec3<i32>,
    fp: vec3<f32>,
}

fn level_pos(l: u32, cell: vec3<i32>, local: vec3<f32>) -> LevelPos {
    let sh = P.unit_shift - level_shift(l);
    return LevelPos(
        vec3<i32>(scaled_int(cell.x, sh.x), scaled_int(cell.y, sh.y), scaled_int(cell.z, sh.z)),
        vec3<f32>(
            scaled_frac(cell.x, local.x, sh.x),
            scaled_frac(cell.y, local.y, sh.y),
            scaled_frac(cell.z, local.z, sh.z),
        ),
    );
}

// The brick of level-voxel v (v / P.brick), through f32 division corrected by one step each
// way: a CPU driver has no vector integer division and divides lane by lane. The f32 quotient
// is within one of the true one while it is below 2^23 (relative error 2^-23 at most), so the
// result is exact for levels of fewer than 2^23 bricks per axis.
fn voxel_brick(v: vec3<u32>) -> vec3<u32> {
    let bs = P.brick;
    var q = vec3<u32>(vec3<f32>(v) / vec3<f32>(bs));
    let r = vec3<i32>(v - q * bs);
    q = select(q, q - vec3<u32>(1u), r < vec3<i32>(0));
    q = select(q, q + vec3<u32>(1u), r >= vec3<i32>(bs));
    return q;
}

// Page-table id of brick b of channel c at level l.
fn brick_id(c: u32, l: u32, b: vec3<u32>) -> u32 {
    let nb = level_bricks(l);
    return page_offset(c, l) + (b.z * nb.y + b.y) * nb.x + b.x;
}

// The brick of level l holding a position (not its trilinear footprint).
fn point_brick(l: u32, pos: LevelPos) -> vec3<u32> {
    let v = clamp(pos.ip + vec3<i32>(floor(pos.fp)), vec3<i32>(0), level_shape(l) - vec3<i32>(1));
    return voxel_brick(vec3<u32>(v));
}

// World distance from a position to the exit of the box of brick b of level l, along a ray
// of `dir` fine units per world unit.
fn brick_exit(l: u32, b: vec3<u32>, pos: LevelPos, dir: vec3<f32>) -> f32 {
    let sh = P.unit_shift - level_shift(l);
    let rel = vec3<f32>(pos.ip - vec3<i32>(b * P.brick)) + pos.fp;
    let d = dir * vec3<f32>(ldexp(1.0, sh.x), ldexp(1.0, sh.y), ldexp(1.0, sh.z));
    let far = select(-rel, vec3<f32>(P.brick) - rel, d > vec3<f32>(0.0));
    let tt = far / d;
    return max(min(tt.x, min(tt.y, tt.z)), 0.0);
}

struct Sampled {
    value: f32,
    ok: bool,
    missing: u32, // page-table id + 1 of a missing brick, 0 when none
    clear: bool, // a brick of the footprint is ENTRY_CLEAR: opacity exactly 0, no voxels read
}

// Trilinear sample of channel c at level l (voxel centres at i + ½, clamped to the edge
// voxels). The 8 voxels lie in at most 8 bricks. The brick of the first voxel is looked up;
// when the footprint stays in it, or its apron serves the footprint's crossing (ENTRY_APRON:
// the slot holds the next bricks' first voxels there too), its slot serves all 8. Otherwise
// each brick is looked up once per run of corners in it, with a single texel-fetch site (a
// CPU Vulkan driver runs every branch's code, so the shader keeps few). With `want`, every
// missing brick is requested; without it the first miss returns. A clear brick (ENTRY_CLEAR)
// in the footprint makes the sample clear.
fn sample_level(c: u32, l: u32, pos: LevelPos, want: bool, t: f32) -> Sampled {
    let fp = pos.fp - vec3<f32>(0.5);
    let fl = floor(fp);
    let w = fp - fl;
    let i0 = pos.ip + vec3<i32>(fl);
    let hi = level_shape(l) - vec3<i32>(1);
    let c0 = vec3<u32>(clamp(i0, vec3<i32>(0), hi));
    let c1 = vec3<u32>(clamp(i0 + vec3<i32>(1), vec3<i32>(0), hi));
    let bs = P.brick;
    let b0 = voxel_brick(c0);
    let r0 = c0 - b0 * bs;
    let r0n = r0 + (c1 - c0);
    let wrap = r0n == bs;
    let b1 = b0 + select(vec3<u32>(0u), vec3<u32>(1u), wrap);
    let r1 = select(r0n, vec3<u32>(0u), wrap);
    var result = Sampled(0.0, true, 0u, false);
    // Fast path, the common case: all 8 voxels in one slot (one lookup, unrolled fetches).
    let pid = brick_id(c, l, b0);
    let entry = page_table[pid];
    // The slot serves the whole footprint where it stays in the brick, where the brick is clear
    // (the sample is), or where the apron parts it crosses into are filled (ENTRY_APRON: a
    // bit per crossing, the axes along which the footprint leaves the brick).
    let crossing = select(0u, 1u, wrap.x) | select(0u, 2u, wrap.y) | select(0u, 4u, wrap.z);
    let one_slot = crossing == 0u || entry == ENTRY_CLEAR
        || ((entry >> (APRON_SHIFT + crossing - 1u)) & 1u) != 0u;
    if RESIDENT_ONLY && (entry == 0u || !one_slot) {
        needs_full = true;
        result.ok = false;
        return result;
    }
    // `RESIDENT_ONLY ||` and `&& !RESIDENT_ONLY` restate what the return above implies, as
    // pipeline constants, so the resident-only pipeline compiles without the per-corner path
    // and the request: a CPU driver would run their code masked on every sample.
    if RESIDENT_ONLY || one_slot {
        if entry == 0u {
            result.ok = false;
            result.missing = pid + 1u;
            if want && !RESIDENT_ONLY {
                request(pid, t);
            }
            return result;
        }
        if entry == ENTRY_EMPTY {
            return result;
        }
        if entry == ENTRY_CLEAR {
            result.clear = true;
            return result;
        }
        let o = slot_origin(entry);
        let l0 = o + vec3<i32>(r0);
        let l1 = o + vec3<i32>(r0n);
        let x00 = mix(texel(l0), texel(vec3<i32>(l1.x, l0.y, l0.z)), w.x);
        let x10 = mix(texel(vec3<i32>(l0.x, l1.y, l0.z)), texel(vec3<i32>(l1.x, l1.y, l0.z)), w.x);
        let x01 = mix(texel(vec3<i32>(l0.x, l0.y, l1.z)), texel(vec3<i32>(l1.x, l0.y, l1.z)), w.x);
        let x11 = mix(texel(vec3<i32>(l0.x, l1.y, l1.z)), texel(l1), w.x);
        result.value = mix(mix(x00, x10, w.y), mix(x01, x11, w.y), w.z);
        return result;
    }
    var acc = 0.0;
    var last = 0xffffffffu;
    var entry_k = 0u;
    var origin = vec3<i32>(0);
    for (var k = 0u; k < 8u; k++) {
        let bits = vec3<bool>((k & 1u) != 0u, (k & 2u) != 0u, (k & 4u) != 0u);
        let pid_k = brick_id(c, l, select(b0, b1, bits));
        if pid_k != last {
            last = pid_k;
            entry_k = page_table[pid_k];
            if entry_k == 0u {
                result.ok = false;
                result.missing = pid_k + 1u;
                if !want {
                    return result;
                }
                request(pid_k, t);
            } else if entry_k == ENTRY_CLEAR {
                return Sampled(0.0, true, 0u, true);
            } else if entry_k != ENTRY_EMPTY {
                origin = slot_origin(entry_k);
            }
        }
        if entry_k > ENTRY_EMPTY {
            let wk = select(vec3<f32>(1.0) - w, w, bits);
            acc += wk.x * wk.y * wk.z * texel(origin + vec3<i32>(select(r0, r1, bits)));
        }
    }
    if result.ok {
        result.value = acc;
    }
    return result;
}

// The filtered sample of channel c at level l. Trilinear: one sample_level, returned at once
// (FILTER is a pipeline constant, so the driver drops the other path; measured on lavapipe,
// going through the tricubic loop with one fetch instead cost 18% of our frame time). Tricubic: the
// cubic B-spline over the 4³ voxels around the sample (Sigg and Hadwiger's fast form): per axis
// the weights w0..w3 of voxels i-1..i+2 are folded into two trilinear fetches, at i-1+w1/g0
// with weight g0 = w0+w1 and at i+1+w3/g1 with weight g1 = w2+w3; 8 fetches in all, each
// clamped to the edge voxels as a trilinear sample is, so the result is the clamped tricubic
// sum. A clear fetch makes the sample clear: with the classes widened by the filter's reach
// (Filter::reach), every voxel of a footprint that reaches a clear brick lies in its range.
// Missing bricks are handled as sample_level does.
fn sample_filtered(c: u32, l: u32, cell: vec3<i32>, local: vec3<f32>, want: bool, t: f32) -> Sampled {
    let pos = level_pos(l, cell, local);
    if FILTER == FILTER_TRILINEAR {
        return sample_level(c, l, pos, want, t);
    }
    let x = pos.fp - vec3<f32>(0.5);
    let fl = floor(x);
    let a = x - fl;
    let a2 = a * a;
    let a3 = a2 * a;
    let one = vec3<f32>(1.0) - a;
    let w0 = one * one * one / 6.0;
    let w1 = (3.0 * a3 - 6.0 * a2 + vec3<f32>(4.0)) / 6.0;
    let w2 = (-3.0 * a3 + 3.0 * a2 + 3.0 * a + vec3<f32>(1.0)) / 6.0;
    let w3 = a3 / 6.0;
    let g0 = w0 + w1;
    let g1 = w2 + w3;
    // Positions in LevelPos form (voxel centres at i + 1/2).
    let fp0 = fl - vec3<f32>(0.5) + w1 / g0;
    let fp1 = fl + vec3<f32>(1.5) + w3 / g1;
    var out = Sampled(0.0, true, 0u, false);
    for (var k = 0u; k < 8u; k++) {
        let bits = vec3<bool>((k & 1u) != 0u, (k & 2u) != 0u, (k & 4u) != 0u);
        let s = sample_level(c, l, LevelPos(pos.ip, select(fp0, fp1, bits)), want, t);
        if s.clear {
            return Sampled(0.0, true, 0u, true);
        }
        if !s.ok {
            out.ok = false;
            if out.missing == 0u {
                out.missing = s.missing;
            }
            if !want {
                return out;
            }
        }
        let g = select(g0, g1, bits);
        out.value += g.x * g.y * g.z * s.value;
    }
    if !out.ok {
        out.value = 0.0;
    }
    return out;
}

// Next level to try for a missing sample at level `first`, having just tried `k`: coarser
// levels the node maps first (ascending), then finer ones (descending); NO_LEVEL when none.
fn next_candidate(mask: u32, first: u32, k: u32) -> u32 {
    if k >= first {
        let up = mask & ~((2u << k) - 1u);
        if up != 0u {
            return firstTrailingBit(up);
        }
        let down = mask & ((1u << first) - 1u);
        if down != 0u {
            return firstLeadingBit(down);
        }
        return NO_LEVEL;
    }
    let down = mask & ((1u << k) - 1u);
    if down != 0u {
        return firstLeadingBit(down);
    }
    return NO_LEVEL;
}

// Finest level whose voxel is at least the pixel footprint at distance t (scaled by the LOD
// bias), looking from level `first` up. Voxels grow with the level and the footprint with t,
// so along a ray the level only coarsens: the ray carries it from step to step.
fn footprint_level(first: u32, t: f32) -> u32 {
    let target_size = max(t, 0.0) * P.pixel_footprint * exp2(P.lod_bias);
    var l = first;
    loop {
        if l + 1u >= P.level_count || level_voxel(l) >= target_size {
            break;
        }
        l++;
    }
    return l;
}

// Each channel's level at a step, packed 8 bits a channel, four to a word (0xff: NO_LEVEL):
// a value, not an array, so a CPU driver keeps it in registers instead of storing it lane by
// lane. The word is picked by selects, not by a dynamic index, for the same reason.
fn level_of(levels: ChannelLevels, c: u32) -> u32 {
    let w = c >> 2u;
    let word = select(select(levels.x, levels.y, w == 1u), select(levels.z, levels.w, w == 3u), w >= 2u);
    let l = (word >> (8u * (c & 3u))) & 0xffu;
    return select(l, NO_LEVEL, l == 0xffu);
}

// `levels` with channel c's level set to l (NO_LEVEL allowed).
fn with_level(levels: ChannelLevels, c: u32, l: u32) -> ChannelLevels {
    let sh = 8u * (c & 3u);
    let updated = (levels & ChannelLevels(~(0xffu << sh))) | ChannelLevels(min(l, 0xffu) << sh);
    return select(levels, updated, ChannelLevels(c >> 2u) == ChannelLevels(0u, 1u, 2u, 3u));
}

// Channel c's level for the footprint's level l: l within the channel's level bounds.
fn channel_level(c: u32, l: u32) -> u32 {
    let lmax = min(S.channels[c].max_level, P.level_count - 1u);
    return min(max(l, S.channels[c].min_level), lmax);
}

// ---- ray state ----

struct Ray {
    cell: vec3<i32>,
    local: vec3<f32>,
    t: f32,
}

fn advance(ray: ptr<function, Ray>, dir: vec3<f32>, dt: f32) {
    var local = (*ray).local + dir * dt;
    let f = floor(local);
    (*ray).cell += vec3<i32>(f);
    (*ray).local = local - f;
    (*ray).t += dt;
}

// World distance from the ray's position to the exit of the node of depth d holding it
// (`dir`: fine units per world unit). The distance to the far face is taken in integers
// first, so it stays exact near the face however large the node.
fn node_exit(ray: Ray, d: u32, dir: vec3<f32>) -> f32 {
    let s = node_shift(d);
    let lo = (ray.cell >> s) << s;
    let far_cells = select(lo - ray.cell, lo + (vec3<i32>(1) << s) - ray.cell, dir > vec3<f32>(0.0));
    let far = vec3<f32>(far_cells) - ray.local;
    let tt = far / dir;
    return max(min(tt.x, min(tt.y, tt.z)), 0.0);
}

// ---- traversal: what a step does where the ray is ----

const ACTION_SAMPLE: u32 = 0u; // sample the channels not empty here
const ACTION_SKIP: u32 = 1u; // every channel empty under its TF: skip `skip`
const ACTION_HOMOGENEOUS: u32 = 2u; // every channel constant over the node: integrate it
const ACTION_REQUEST: u32 = 3u; // no needed channel mapped: request its bricks and skip

struct Visit {
    action: u32,
    node: u32, // the node reached (residency method)
    depth: u32, // its depth
    empty: u32, // bits: the channels empty under their TF here
    skip: f32, // world distance to the exit of the node or brick (ACTION_SKIP, ACTION_REQUEST)
}

// The residency octree (Algorithm 1, multi-channel): from just above the depth of the last
// node visited, down to the deepest node whose edge is at least the step, stopping where every
// channel is empty, or constant, under its TF.
fn visit_octree(ray: Ray, last_depth: u32, desired_step: f32, dir: vec3<f32>, skipping: bool) -> Visit {
    let depth = P.leaf_depth;
    var max_depth = depth;
    var edge = P.leaf_edge;
    loop {
        if max_depth == 0u || edge >= desired_step {
            break;
        }
        max_depth--;
        edge *= 2.0;
    }
    var v = Visit(ACTION_SAMPLE, 0u, 0u, 0u, 0.0);
    var d = min(clamp(last_depth, P.start_depth + 1u, depth + 1u) - 1u, max_depth);
    let all = drawn_channels();
    var homogeneous = 0u;
    loop {
        v.node = node_index(d, ray.cell);
        // The node's class under the transfer functions, one word for every channel (written
        // by the CPU on a restyle): bit c empty, bit CLASS_CONSTANT_SHIFT + c constant.
        if skipping {
            let word = nodes[P.class_offset + v.node];
            v.empty = word & all;
            homogeneous = (word >> CLASS_CONSTANT_SHIFT) & all;
        }
        if skipping && v.empty == all {
            v.action = ACTION_SKIP;
            break;
        }
        if skipping && (v.empty | homogeneous) == all {
            v.action = ACTION_HOMOGENEOUS;
            break;
        }
        if d >= max_depth {
            break;
        }
        d++;
    }
    // Unmapped: no channel that needs data here has a level resident (judged once, after the
    // descent: on a CPU driver a loop inside the descent would run at every depth).
    if v.action == ACTION_SAMPLE {
        var need = all & ~(v.empty | homogeneous);
        var all_unmapped = true;
        loop {
            if need == 0u {
                break;
            }
            let c = take_channel(&need);
            if node_word(v.node, c, 0u) != 0u {
                all_unmapped = false;
            }
        }
        if all_unmapped {
            v.action = ACTION_REQUEST;
            // The resident-only pass neither requests nor substitutes.
            if RESIDENT_ONLY {
                needs_full = true;
            }
        }
    }
    v.depth = d;
    if v.action == ACTION_SKIP || v.action == ACTION_REQUEST {
        v.skip = node_exit(ray, d, dir);
    }
    return v;
}

// The page-table baseline (MRMCPT): per channel, whether the brick of its chosen level at the
// sample is empty under its TF, judged once per brick the ray enters, as a page-table
// renderer would (`seen`: the brick of each channel's last sample; `seen_empty`: its bits).
fn visit_page_table(
    ray: Ray,
    chosen: ChannelLevels,
    seen: ptr<function, array<u32, MAX_CHANNELS>>,
    seen_empty: ptr<function, u32>,
    dir: vec3<f32>,
    skipping: bool,
) -> Visit {
    var v = Visit(ACTION_SAMPLE, 0u, 0u, 0u, 3.0e38);
    var all_empty = true;
    for (var c = 0u; c < P.channel_count; c++) {
        let l = level_of(chosen, c);
        let pos = level_pos(l, ray.cell, ray.local);
        let b = point_brick(l, pos);
        let pid = brick_id(c, l, b);
        let bit = 1u << c;
        if pid != (*seen)[c] {
            (*seen)[c] = pid;
            *seen_empty = select(*seen_empty & ~bit, *seen_empty | bit, skipping && brick_empty(pid));
        }
        if (*seen_empty & bit) != 0u {
            v.empty |= bit;
            v.skip = min(v.skip, brick_exit(l, b, pos, dir));
        } else {
            all_empty = false;
        }
    }
    if all_empty {
        v.action = ACTION_SKIP;
    }
    return v;
}

// The octree-of-bricks baseline (GigaVoxels style): per channel, descend from the coarsest
// level; every ancestor must be resident, the first missing one is requested, and the finest
// resident one is sampled (`chosen` becomes that level, or NO_LEVEL).
fn visit_brick_octree(
    ray: Ray,
    chosen: ptr<function, ChannelLevels>,
    dir: vec3<f32>,
    skipping: bool,
    t: f32,
) -> Visit {
    var v = Visit(ACTION_SAMPLE, 0u, 0u, 0u, 3.0e38);
    var all_empty = true;
    for (var c = 0u; c < P.channel_count; c++) {
        let l = level_of(*chosen, c);
        var k = min(S.channels[c].max_level, P.level_count - 1u);
        var resident = NO_LEVEL;
        var missing = 0u;
        loop {
            let pos = level_pos(k, ray.cell, ray.local);
            let b = point_brick(k, pos);
            let pid = brick_id(c, k, b);
            if skipping && brick_empty(pid) {
                v.empty |= 1u << c;
                v.skip = min(v.skip, brick_exit(k, b, pos, dir));
                break;
            }
            let entry = page_table[pid];
            if entry == 0u {
                if RESIDENT_ONLY {
                    needs_full = true;
                } else {
                    request(pid, t);
                }
                missing = pid + 1u;
                break;
            }
            if entry != ENTRY_EMPTY {
                _ = slot_origin(entry);
            }
            resident = k;
            if k <= l {
                break;
            }
            k--;
        }
        if (v.empty & (1u << c)) == 0u {
            all_empty = false;
            *chosen = with_level(*chosen, c, resident);
            if !RESIDENT_ONLY && missing != 0u && resident != NO_LEVEL {
                note_substituted(missing - 1u);
            }
        }
    }
    if all_empty {
        v.action = ACTION_SKIP;
    }
    return v;
}

// ---- ray segment lists (SparseLeap, rasterize): segments.wgsl wrote them ----

// Where a ray stands on its pixel's segment list: what holds up to `end` (a distance t).
struct Segment {
    occupancy: u32, // SparseLeap: occupancy class; rasterize: OCCUPANCY_EMPTY outside every brick
    level: u32, // rasterize: the brick's level (NO_LEVEL: the ray's own LOD, the list overflowed)
    end: f32, // where the next record starts or ends: look again there
}

fn segment_word(k: u32) -> u32 {
    return nodes[P.segment_offset + k];
}

fn segment_overflowed(pixel: u32) -> bool {
    return segment_word(SEGMENT_HEADS + P.width * P.height + pixel) != 0u;
}

fn segment_record(i: u32) -> SegmentRecord {
    let at = SEGMENT_HEADS + 2u * P.width * P.height + i * RECORD_WORDS;
    return SegmentRecord(
        bitcast<f32>(segment_word(at)),
        bitcast<f32>(segment_word(at + 1u)),
        segment_word(at + 2u),
        segment_word(at + 3u),
    );
}

// SparseLeap: the occupancy class at distance t, that of the deepest box holding t (boxes are
// nested octree nodes, a child's class overriding its parent's; at equal depth, the class
// that is not empty), and the next distance where a record starts or ends. Unknown where no
// box holds t or the list overflowed.
fn occupancy_at(pixel: u32, t: f32) -> Segment {
    var seg = Segment(OCCUPANCY_UNKNOWN, NO_LEVEL, 3.0e38);
    if segment_overflowed(pixel) {
        return seg;
    }
    var best = -1;
    var i = segment_word(SEGMENT_HEADS + pixel);
    for (var guard = 0u; i != 0u && guard < P.segment_capacity; guard++) {
        let r = segment_record(i - 1u);
        if r.t_in <= t && t < r.t_out {
            let depth = i32((r.payload >> 4u) & 15u);
            let cls = r.payload & 3u;
            if depth > best || (depth == best && cls != OCCUPANCY_EMPTY) {
                best = depth;
                seg.occupancy = cls;
            }
        }
        if r.t_in > t {
            seg.end = min(seg.end, r.t_in);
        }
        if r.t_out > t {
            seg.end = min(seg.end, r.t_out);
        }
        i = r.next;
    }
    return seg;
}

// Rasterize: the brick holding distance t (bricks of the cut do not overlap but by a hair at
// shared faces) and where it ends; outside every brick, OCCUPANCY_EMPTY up to the next brick.
// A list that overflowed holds everywhere, at the ray's own level of detail.
fn brick_at(pixel: u32, t: f32) -> Segment {
    if segment_overflowed(pixel) {
        return Segment(OCCUPANCY_NONEMPTY, NO_LEVEL, 3.0e38);
    }
    var seg = Segment(OCCUPANCY_EMPTY, NO_LEVEL, 3.0e38);
    var i = segment_word(SEGMENT_HEADS + pixel);
    for (var guard = 0u; i != 0u && guard < P.segment_capacity; guard++) {
        let r = segment_record(i - 1u);
        if r.t_in <= t && t < r.t_out {
            return Segment(OCCUPANCY_NONEMPTY, (r.payload >> 8u) & 15u, r.t_out);
        }
        if r.t_in > t {
            seg.end = min(seg.end, r.t_in);
        }
        i = r.next;
    }
    return seg;
}

// Rasterize inside a brick of level l: whether the macrocell holding the ray (the octree node
// of 8³ voxels of level l, whose range is the region metadata's) is empty in every channel, and
// then where it ends.
fn macrocell_skip(ray: Ray, l: u32, dir: vec3<f32>) -> f32 {
    let d = P.leaf_depth - min(l, P.leaf_depth);
    let all = drawn_channels();
    let word = nodes[P.class_offset + node_index(d, ray.cell)];
    if (word & all) == all {
        return node_exit(ray, d, dir);
    }
    return -1.0;
}

// ---- sampling every channel ----

struct ChannelSamples {
    have: u32, // bits: the channels with a value (not clear)
    used: u32, // finest level sampled
    any_value: bool, // some channel had data (a clear sample counts)
}

// Samples every channel not empty here at its chosen level, substituting missing bricks from
// the levels the node maps, into `values` (only where `have` says). For ACTION_REQUEST this
// only requests the bricks.
fn sample_channels(
    ray: Ray,
    v: Visit,
    chosen: ChannelLevels,
    values: ptr<function, array<f32, MAX_CHANNELS>>,
    t: f32,
    skipping: bool,
    substitute: bool,
) -> ChannelSamples {
    var out = ChannelSamples(0u, P.level_count - 1u, false);
    // Only the channels not empty here (take_channel).
    var need = drawn_channels() & ~v.empty;
    loop {
        if need == 0u {
            break;
        }
        let c = take_channel(&need);
        let l = level_of(chosen, c);
        if l == NO_LEVEL {
            continue;
        }
        var k = l;
        var s = Sampled(0.0, false, 0u, false);
        var first_missing = 0u;
        if RESIDENT_ONLY {
            s = sample_filtered(c, l, ray.cell, ray.local, false, t);
        } else {
            var mask = 0u;
            if METHOD == METHOD_RESIDENCY {
                if v.action == ACTION_REQUEST && skipping {
                    let lo = bitcast<f32>(node_word(v.node, c, 1u));
                    let hi = bitcast<f32>(node_word(v.node, c, 2u));
                    if lo == hi {
                        continue; // homogeneous: known without its bricks
                    }
                }
            }
            // Coarse first: where nothing of this channel is resident (ACTION_REQUEST), ask for
            // its coarsest allowed level first. Once that stands in, rays gather opacity and
            // stop early, so the finer bricks behind opaque matter are never requested. Where
            // the coarsest level is clear (averaging can take thin bright structures below the
            // TF), it says nothing of finer ones: then the wanted level is asked for. (One
            // sample_filtered call site: on lavapipe every inlined copy costs every sample.)
            var coarse_first = false;
            if METHOD == METHOD_RESIDENCY && v.action == ACTION_REQUEST && substitute {
                k = min(S.channels[c].max_level, P.level_count - 1u);
                coarse_first = k != l;
            }
            loop {
                s = sample_filtered(c, k, ray.cell, ray.local, k == l || coarse_first, t);
                if coarse_first {
                    coarse_first = false;
                    if !s.clear {
                        s.ok = false; // requested: nothing to sample in ACTION_REQUEST
                        break;
                    }
                    k = l;
                    continue;
                }
                if s.ok {
                    break;
                }
                if k == l {
                    first_missing = s.missing;
                    // The levels the node maps for this channel, read only once a sample misses.
                    if METHOD == METHOD_RESIDENCY && substitute && v.action == ACTION_SAMPLE {
                        mask = node_word(v.node, c, 0u);
                    }
                    // The segment methods keep no residency masks: every level may stand in,
                    // coarser first, as its page table says.
                    if (METHOD == METHOD_SPARSELEAP || METHOD == METHOD_RASTERIZE) && substitute {
                        mask = (1u << P.level_count) - 1u;
                    }
                }
                k = next_candidate(mask, l, k);
                if k == NO_LEVEL {
                    break;
                }
            }
        }
        if s.ok {
            if !RESIDENT_ONLY && k != l {
                note_substituted(first_missing - 1u);
            }
            if !s.clear {
                (*values)[c] = s.value;
                out.have |= 1u << c;
            }
            out.used = min(out.used, k);
            out.any_value = true;
        }
    }
    return out;
}

// ---- the ray ----

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= P.width || gid.y >= P.height {
        return;
    }
    let pixel = gid.y * P.width + gid.x;
    var st = rays[pixel];
    if st.status == RAY_DONE {
        return;
    }
    let pray = pixel_ray(gid.x, gid.y);
    let t_plane = pray.t_plane;
    let start = pray.start;
    let dir_leaf = pray.dir_leaf; // leaf units per world unit
    let fine = vec3<f32>(ldexp(1.0, P.fine.x), ldexp(1.0, P.fine.y), ldexp(1.0, P.fine.z));
    let dir = dir_leaf * fine; // fine units per world unit
    let span = volume_span(pray);
    let t_enter = span.x;
    let t_exit = span.y;

    var color = st.color;
    var trans = st.trans;
    if st.status == RAY_FRESH {
        color = vec3<f32>(0.0);
        trans = 1.0;
    }
    var samples = 0u;
    var skipped = 0u;
    var homogeneous = 0u;
    var nodata = 0u;
    // A skip goes this far (1e-4 fine unit) past a node's face; the entry 1e-4 leaf.
    let nudge = 1e-4 / max(abs(dir.x), max(abs(dir.y), abs(dir.z)));
    let entry_nudge = 1e-4 / max(abs(dir_leaf.x), max(abs(dir_leaf.y), abs(dir_leaf.z)));

    var suspended = false;
    if t_exit > t_enter {
        let leaves = 1 << P.leaf_depth;
        let end_cell = vec3<i32>(leaves) << fine_shift(); // the root's far faces, fine units
        var ray = Ray(st.cell, st.local, st.t);
        var last_depth = st.last_depth;
        var iterations = st.iterations;
        if st.status == RAY_FRESH {
            last_depth = P.start_depth + 1u;
            iterations = 0u;
            ray = Ray(P.view_cell, P.view_frac, 0.0);
            advance(&ray, start + dir_leaf * (t_enter + entry_nudge), 1.0);
            ray.t = t_enter + entry_nudge;
            // Far from the volume the f32 entry point can round to just outside the octree's
            // root: clamp it onto the face it entered through.
            let top = vec3<i32>(leaves - 1);
            let inside = clamp(ray.cell, vec3<i32>(0), top);
            let moved = inside != ray.cell;
            ray.local = select(ray.local, select(vec3<f32>(0.0), vec3<f32>(0.99999994), ray.cell > top), moved);
            ray.cell = inside;
            // From leaf units to fine units (scaling by 2^F is exact in f32).
            let scaled = ray.local * fine;
            let whole = floor(scaled);
            ray.cell = (ray.cell << fine_shift()) + vec3<i32>(whole);
            ray.local = scaled - whole;
        }
        let skipping = (P.flags & FLAG_SKIPPING) != 0u;
        let substitute = (P.flags & FLAG_SUBSTITUTION) != 0u;
        var budget = P.steps_per_pass;
        // Page-table baseline: the brick each channel's last sample was in, and whether it
        // is empty under the channel's TF.
        var pt_brick: array<u32, MAX_CHANNELS>;
        var pt_empty = 0u;
        for (var c = 0u; c < P.channel_count; c++) {
            pt_brick[c] = 0xffffffffu;
        }
        // Residency: the last visit that said "sample here", kept while the ray stays in its
        // node with the same step, so the octree is descended once per node, not per sample
        // (a visit is a function of the node and the step alone: the same answer again).
        var held = Visit(ACTION_SKIP, 0u, 0u, 0u, 0.0);
        // Each step's channel values, declared once per ray: an array declared in the loop
        // is zeroed on every iteration, lane by lane on a CPU driver.
        var values: array<f32, MAX_CHANNELS>;
        // The footprint's level at the last step (it only coarsens along the ray).
        var lod = 0u;
        // Each channel's level and the finest of them, for the level `levels_for`.
        var levels_for = NO_LEVEL;
        var level_levels = ChannelLevels(0xffffffffu);
        var finest = 0u;
        var held_step = 0.0;
        var held_cell = vec3<i32>(0);
        // SparseLeap and rasterize: what the pixel's segment list says up to seg.end (looked
        // up again from the list there, also after a resume).
        let segments = (METHOD == METHOD_SPARSELEAP || METHOD == METHOD_RASTERIZE) && skipping;
        var seg = Segment(OCCUPANCY_UNKNOWN, NO_LEVEL, -3.0e38);
        if segments && st.status == RAY_FRESH && segment_overflowed(pixel) {
            atomicAdd(&requests.counters.rays_overflowed, 1u);
        }
        loop {
            // While-while (Aila and Laine 2009): the inner loop moves the ray through empty
            // nodes until it stands where it samples or integrates, so a skip costs the
            // traversal's code and not the whole step's (on a CPU driver every branch of a
            // loop body runs on every iteration; on a GPU, rays of a warp that skip wait less
            // for those that sample).
            var stop = false;
            var v = Visit(ACTION_SAMPLE, 0u, 0u, 0u, 0.0);
            var chosen = ChannelLevels(0xffffffffu);
            var desired_step = 0.0;
            loop {
                iterations++;
                if ray.t >= t_exit || trans < T_MIN || iterations > MAX_ITERATIONS {
                    stop = true;
                    break;
                }
                if any(ray.cell < vec3<i32>(0)) || any(ray.cell >= end_cell) {
                    stop = true;
                    break;
                }
                if budget == 0u {
                    suspended = true;
                    stop = true;
                    break;
                }
                budget--;
                lod = footprint_level(lod, ray.t + t_plane);
                var level = lod;
                // SparseLeap and rasterize: where the ray stands on its segment list; rasterize
                // samples at the level of the brick it is in, not at the footprint's.
                if segments {
                    if ray.t >= seg.end {
                        if METHOD == METHOD_SPARSELEAP {
                            seg = occupancy_at(pixel, ray.t);
                        } else {
                            seg = brick_at(pixel, ray.t);
                        }
                    }
                    if METHOD == METHOD_RASTERIZE && seg.level != NO_LEVEL {
                        level = seg.level;
                    }
                }
                // Desired level per channel, and step: the finest over channels. They follow
                // from the level alone, which changes a few times along a ray: the loop runs
                // only then (a bound of 0, not an `if`, since a CPU driver runs an `if` body
                // masked on every iteration).
                let changed = level != levels_for;
                let to_set = select(0u, P.channel_count, changed);
                finest = select(finest, P.level_count - 1u, changed);
                level_levels = select(level_levels, ChannelLevels(0xffffffffu), changed);
                for (var c = 0u; c < to_set; c++) {
                    let l = channel_level(c, level);
                    level_levels = with_level(level_levels, c, l);
                    finest = min(finest, l);
                }
                levels_for = level;
                chosen = level_levels;
                desired_step = P.step_fraction * level_voxel(finest);
                v = Visit(ACTION_SAMPLE, 0u, 0u, 0u, 0.0);
                if segments {
                    if seg.occupancy == OCCUPANCY_EMPTY {
                        v.action = ACTION_SKIP;
                        v.skip = min(seg.end, t_exit) - ray.t;
                    } else if METHOD == METHOD_RASTERIZE && seg.level != NO_LEVEL {
                        // Empty macrocells inside the brick are skipped.
                        let macro_end = macrocell_skip(ray, seg.level, dir);
                        if macro_end >= 0.0 {
                            v.action = ACTION_SKIP;
                            v.skip = min(macro_end, seg.end - ray.t);
                        }
                    }
                } else if METHOD == METHOD_RESIDENCY {
                    if held.action == ACTION_SAMPLE && desired_step == held_step
                        && all((ray.cell >> node_shift(held.depth)) == held_cell) {
                        v = held;
                    } else {
                        v = visit_octree(ray, last_depth, desired_step, dir, skipping);
                        last_depth = v.depth;
                        held = v;
                        held_step = desired_step;
                        held_cell = ray.cell >> node_shift(v.depth);
                    }
                } else if METHOD == METHOD_PAGE_TABLE {
                    v = visit_page_table(ray, chosen, &pt_brick, &pt_empty, dir, skipping);
                } else if METHOD == METHOD_OCTREE {
                    v = visit_brick_octree(ray, &chosen, dir, skipping, ray.t + t_plane);
                }
                if RESIDENT_ONLY && needs_full {
                    suspended = true;
                    stop = true;
                    break;
                }
                if v.action == ACTION_SKIP {
                    skipped++;
                    advance(&ray, dir, v.skip + nudge);
                    continue;
                }
                break;
            }
            if stop {
                break;
            }
            // One compositing site for both kinds of step (on a CPU driver every inlined copy
            // costs every iteration): a homogeneous node is seg/Δ steps of its constant
            // values' per-step opacity, in closed form; a sample is one step.
            var s = ChannelSamples(0u, 0u, false);
            var step = desired_step; // the step the mixture's opacities are corrected to
            var steps = 1.0; // steps of it composited
            var move_by = 0.0;
            if v.action == ACTION_HOMOGENEOUS {
                let seg = min(node_exit(ray, v.depth, dir) + nudge, t_exit - ray.t);
                s.have = drawn_channels() & ~v.empty;
                var left = s.have;
                loop {
                    if left == 0u {
                        break;
                    }
                    let c = take_channel(&left);
                    values[c] = bitcast<f32>(node_word(v.node, c, 1u));
                }
                homogeneous++;
                samples++;
                steps = seg / desired_step;
                move_by = seg + nudge;
            } else {
                s = sample_channels(ray, v, chosen, &values, ray.t + t_plane, skipping, substitute);
                if RESIDENT_ONLY && needs_full {
                    suspended = true;
                    break;
                }
                if v.action == ACTION_REQUEST {
                    nodata++;
                    s.have = 0u;
                    move_by = v.skip + nudge;
                } else {
                    step = select(desired_step, P.step_fraction * level_voxel(s.used), s.any_value);
                    if !s.any_value {
                        nodata++;
                    }
                    samples++;
                    move_by = step;
                }
            }
            composite(&color, &trans, mixture(s.have, &values, step), steps);
            advance(&ray, dir, move_by);
        }
        st.cell = ray.cell;
        st.local = ray.local;
        st.t = ray.t;
        st.last_depth = last_depth;
        st.iterations = iterations;
    }
    st.color = color;
    st.trans = trans;
    st.status = select(RAY_DONE, RAY_SUSPENDED, suspended);
    rays[pixel] = st;
    if suspended {
        atomicAdd(&requests.counters.rays_suspended, 1u);
        if RESIDENT_ONLY && needs_full {
            atomicAdd(&requests.counters.rays_need_full, 1u);
        }
    } else {
        out_color[pixel] = vec4<f32>(color + trans * P.background, 1.0 - trans);
    }
    atomicAdd(&requests.counters.samples, samples);
    atomicAdd(&requests.counters.empty_nodes_skipped, skipped);
    atomicAdd(&requests.counters.homogeneous_nodes, homogeneous);
    atomicAdd(&requests.counters.samples_without_data, nodata);
}
