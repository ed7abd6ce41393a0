// The ray caster, part 2 of 7 (joined in order by viewer/src/gpu/contract.rs): reading the
// atlas through the page tables, brick requests, filtered samples and the level of detail.

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

