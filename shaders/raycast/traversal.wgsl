// The ray caster, part 3 of 7 (joined in order by viewer/src/gpu/contract.rs): a ray's
// position, and what a step does where the ray is under each hierarchy-traversing method.

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
    // bits: the channels empty under their TF here (MODE_ISO, a baseline's ACTION_SKIP: the
    // channels with data in the bricks skipped, whose sides the ray now knows)
    empty: u32,
    skip: f32, // world distance to the exit of the node or brick (ACTION_SKIP, ACTION_REQUEST)
}

// The residency octree (Algorithm 1, multi-channel): from just above the depth of the last
// node visited, down to the deepest node whose edge is at least the step, stopping where every
// channel is empty, or constant, under its TF. In MODE_MIP a channel is also empty in a node
// whose largest value is at most the ray's maximum so far (`maxima`): it cannot raise it. In
// MODE_ISO a node is skipped only when every channel's range excludes its iso value and lies
// on the side of it the ray knows the channel on (below it, before the ray knows), and is
// otherwise sampled in every channel (`iso`: what the ray knows).
fn visit_octree(
    ray: Ray,
    last_depth: u32,
    desired_step: f32,
    dir: vec3<f32>,
    skipping: bool,
    maxima: ptr<function, array<f32, MAX_CHANNELS>>,
    iso: IsoState,
) -> Visit {
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
            if MODE == MODE_ISO {
                homogeneous = 0u;
                if v.empty != all || !iso_sides_agree(v.node, iso) {
                    v.empty = 0u;
                }
            }
            if MODE == MODE_MIP {
                var left = all & ~v.empty;
                loop {
                    if left == 0u {
                        break;
                    }
                    let c = take_channel(&left);
                    if bitcast<f32>(node_word(v.node, c, 2u)) <= (*maxima)[c] {
                        v.empty |= 1u << c;
                    }
                }
            }
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

// MODE_ISO: whether every channel with data in `node` lies on the side of its iso value that
// `iso` knows it on (below, where the ray knows nothing yet), so that skipping the node loses
// no crossing.
fn iso_sides_agree(node: u32, iso: IsoState) -> bool {
    var agree = true;
    for (var c = 0u; c < P.channel_count; c++) {
        agree = agree && iso_side_agrees(node_iso_side(node, c), c, iso);
    }
    return agree;
}

// MODE_ISO: where channel c's range in node `node` lies against its iso value, for skipping
// a node every channel's class already says holds no surface: ISO_NOTHING (no data),
// ISO_ABOVE, else ISO_BELOW.
fn node_iso_side(node: u32, c: u32) -> u32 {
    let lo = bitcast<f32>(node_word(node, c, 1u));
    let hi = bitcast<f32>(node_word(node, c, 2u));
    if !(lo <= hi) {
        return ISO_NOTHING;
    }
    return select(ISO_BELOW, ISO_ABOVE, lo > S.channels[c].iso);
}

// The page-table baseline (MRMCPT): per channel, whether the brick of its chosen level at the
// sample is empty under its TF, judged once per brick the ray enters, as a page-table
// renderer would (`seen`: the brick of each channel's last sample; `seen_empty`: its bits).
// MODE_ISO: visit_page_table_iso.
fn visit_page_table(
    ray: Ray,
    chosen: ChannelLevels,
    seen: ptr<function, array<u32, MAX_CHANNELS>>,
    seen_empty: ptr<function, u32>,
    dir: vec3<f32>,
    skipping: bool,
    iso: IsoState,
) -> Visit {
    if MODE == MODE_ISO {
        return visit_page_table_iso(ray, chosen, dir, skipping, iso);
    }
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

// MODE_ISO, the page-table baseline: the ray skips to the nearest exit of the bricks of its
// channels' chosen levels when every one lies on the side of its iso value that the ray knows
// its channel on (iso_side_agrees), else samples every channel. Judged at every step (the
// ray's sides change as it samples). On a skip, `empty` holds the channels with data there.
fn visit_page_table_iso(
    ray: Ray,
    chosen: ChannelLevels,
    dir: vec3<f32>,
    skipping: bool,
    iso: IsoState,
) -> Visit {
    var v = Visit(ACTION_SAMPLE, 0u, 0u, 0u, 3.0e38);
    if !skipping {
        return v;
    }
    var data = 0u;
    for (var c = 0u; c < P.channel_count; c++) {
        let l = level_of(chosen, c);
        let pos = level_pos(l, ray.cell, ray.local);
        let b = point_brick(l, pos);
        let side = brick_iso_side(brick_id(c, l, b));
        if !iso_side_agrees(side, c, iso) {
            return Visit(ACTION_SAMPLE, 0u, 0u, 0u, 3.0e38);
        }
        if side != ISO_NOTHING {
            data |= 1u << c;
        }
        v.skip = min(v.skip, brick_exit(l, b, pos, dir));
    }
    v.action = ACTION_SKIP;
    v.empty = data;
    return v;
}

// One channel's descent of the octree-of-bricks baseline: the brick it stopped at where it
// skips (`exit`: world distance to its exit; `data`: MODE_ISO, the brick has data), else the
// finest resident level (`resident`, or NO_LEVEL) and the first missing brick plus one
// (`missing`, or 0).
struct BrickDescent {
    skip: bool,
    exit: f32,
    data: bool,
    resident: u32,
    missing: u32,
}

// The octree-of-bricks baseline's descent for channel c down to level l: from the coarsest
// level, a brick that can be skipped (with `skipping`: empty under the TF, or in MODE_ISO on
// the side of the iso value the ray knows) ends it; every ancestor must be resident, the first
// missing one is requested, and the finest resident one is sampled.
fn descend_brick_octree(
    ray: Ray,
    c: u32,
    l: u32,
    dir: vec3<f32>,
    skipping: bool,
    iso: IsoState,
    t: f32,
) -> BrickDescent {
    var d = BrickDescent(false, 3.0e38, false, NO_LEVEL, 0u);
    var k = min(S.channels[c].max_level, P.level_count - 1u);
    loop {
        let pos = level_pos(k, ray.cell, ray.local);
        let b = point_brick(k, pos);
        let pid = brick_id(c, k, b);
        if skipping {
            if MODE == MODE_ISO {
                let side = brick_iso_side(pid);
                d.skip = iso_side_agrees(side, c, iso);
                d.data = side != ISO_NOTHING;
            } else {
                d.skip = brick_empty(pid);
            }
            if d.skip {
                d.exit = brick_exit(k, b, pos, dir);
                break;
            }
        }
        let entry = page_table[pid];
        if entry == 0u {
            if RESIDENT_ONLY {
                needs_full = true;
            } else {
                request(pid, t);
            }
            d.missing = pid + 1u;
            break;
        }
        if entry != ENTRY_EMPTY {
            _ = slot_origin(entry);
        }
        d.resident = k;
        if k <= l {
            break;
        }
        k--;
    }
    return d;
}

// The octree-of-bricks baseline (GigaVoxels style): per channel, descend from the coarsest
// level (descend_brick_octree); `chosen` becomes each sampled channel's finest resident level,
// or NO_LEVEL. MODE_ISO skips only where every channel can be skipped (each channel's values
// must be followed at every sample); a channel that could, where another cannot, is descended
// again to be sampled.
fn visit_brick_octree(
    ray: Ray,
    chosen: ptr<function, ChannelLevels>,
    dir: vec3<f32>,
    skipping: bool,
    t: f32,
    iso: IsoState,
) -> Visit {
    var v = Visit(ACTION_SAMPLE, 0u, 0u, 0u, 3.0e38);
    var all_empty = true;
    var data = 0u;
    for (var c = 0u; c < P.channel_count; c++) {
        let l = level_of(*chosen, c);
        // MODE_ISO: once a channel is sampled, every channel is.
        let skip_test = skipping && (MODE != MODE_ISO || all_empty);
        let d = descend_brick_octree(ray, c, l, dir, skip_test, iso, t);
        if d.skip {
            v.empty |= 1u << c;
            v.skip = min(v.skip, d.exit);
            data |= select(0u, 1u << c, d.data);
            continue;
        }
        if MODE == MODE_ISO && all_empty && c > 0u {
            // The channels before c could be skipped, c cannot: descend them to be sampled.
            for (var e = 0u; e < c; e++) {
                let again = descend_brick_octree(ray, e, level_of(*chosen, e), dir, false, iso, t);
                *chosen = with_level(*chosen, e, again.resident);
                if !RESIDENT_ONLY && again.missing != 0u && again.resident != NO_LEVEL {
                    note_substituted(again.missing - 1u);
                }
            }
            v.empty = 0u;
        }
        all_empty = false;
        *chosen = with_level(*chosen, c, d.resident);
        if !RESIDENT_ONLY && d.missing != 0u && d.resident != NO_LEVEL {
            note_substituted(d.missing - 1u);
        }
    }
    if all_empty {
        v.action = ACTION_SKIP;
        if MODE == MODE_ISO {
            v.empty = data;
        }
    }
    return v;
}

