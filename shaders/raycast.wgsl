// The ray caster, part 7 of 7: the ray loop, the compute entry point. viewer/src/gpu/contract.rs
// joins shaders/raycast/{resources,sampling,traversal,segment_lists,channels,vdi}.wgsl, then
// this.

// ---- the ray ----

// MODE_MIP, MODE_ISO: the texels of `out_color` after the image that keep one pixel's state
// between passes (state_texels in viewer/src/gpu/contract.rs): per channel a value (MIP: its
// maximum; ISO: its last sample), then (ISO) one texel of IsoState.
fn state_texels() -> u32 {
    return (P.channel_count + 3u) / 4u + select(0u, 1u, MODE == MODE_ISO);
}

// The texel holding pixel `pixel`'s value of channel c (lane c % 4).
fn channel_texel(pixel: u32, c: u32) -> u32 {
    return P.width * P.height + pixel * state_texels() + c / 4u;
}

// MODE_ISO: the texel holding pixel `pixel`'s IsoState.
fn iso_texel(pixel: u32) -> u32 {
    return P.width * P.height + pixel * state_texels() + state_texels() - 1u;
}

// MODE_ISO: where a ray's last samples were taken (or its last skip ended), and bits per
// channel: its side of the iso value is known, it is at or above it, and its last value is a
// sample's (not only a skipped region's side).
struct IsoState {
    at: f32,
    known: u32,
    above: u32,
    valued: u32,
}

const NO_CHANNEL: u32 = 0xffffffffu;

// MODE_ISO: takes the samples `values` of the channels `have` at ray distance `t` against the
// last ones (`last`, `iso`). Returns the channel whose surface the ray crossed first since
// then, at `*hit` (linear interpolation between the two samples; where a skip ended when the
// last value is only a side; at `t` for a ray's first sample at or above the iso value), or
// NO_CHANNEL.
fn iso_take(
    have: u32,
    values: ptr<function, array<f32, MAX_CHANNELS>>,
    last: ptr<function, array<f32, MAX_CHANNELS>>,
    iso: ptr<function, IsoState>,
    t: f32,
    hit: ptr<function, f32>,
) -> u32 {
    var found = NO_CHANNEL;
    var left = have;
    loop {
        if left == 0u {
            break;
        }
        let c = take_channel(&left);
        let v = (*values)[c];
        if v != v {
            continue;
        }
        let level = S.channels[c].iso;
        let bit = 1u << c;
        let above = v >= level;
        var crossed = false;
        var at = t;
        if ((*iso).known & bit) == 0u {
            crossed = above;
        } else if above != (((*iso).above & bit) != 0u) {
            crossed = true;
            at = (*iso).at;
            if ((*iso).valued & bit) != 0u {
                let u = (*last)[c];
                at = (*iso).at + (level - u) / (v - u) * (t - (*iso).at);
            }
        }
        if crossed && (found == NO_CHANNEL || at < *hit) {
            found = c;
            *hit = at;
        }
        (*last)[c] = v;
        (*iso).known |= bit;
        (*iso).valued |= bit;
        (*iso).above = select((*iso).above & ~bit, (*iso).above | bit, above);
    }
    (*iso).at = t;
    return found;
}

// MODE_ISO: the channels with data in node `node` (their ranges not empty).
fn node_data_channels(node: u32) -> u32 {
    var data = 0u;
    for (var c = 0u; c < P.channel_count; c++) {
        if node_iso_side(node, c) != ISO_NOTHING {
            data |= 1u << c;
        }
    }
    return data;
}

// MODE_ISO: after a skip that ended at ray distance `t`, each channel of `data` (those with
// data where the ray skipped) is known on the skipped region's side, its last value no
// sample's. The sides agreed (iso_sides_agree, iso_side_agrees): a known side stays, and an
// unknown one is below, which its clear `above` bit already says.
fn iso_skipped(iso: ptr<function, IsoState>, data: u32, t: f32) {
    (*iso).known |= data;
    (*iso).valued &= ~data;
    (*iso).at = t;
}

// MODE_ISO: the colour of channel c's surface at ray distance `t`: its colour times
// 0.25 + 0.75·|n·l| (crate::scene's module doc), the gradient n by central differences half a
// level-0 voxel either side along each axis at level l, l the ray's world direction.
fn iso_shade(c: u32, l: u32, ray: Ray, dir: vec3<f32>, t: f32, world_dir: vec3<f32>) -> vec3<f32> {
    var at = ray;
    advance(&at, dir, t - ray.t);
    let half = vec3<f32>(0.5) / exp2(vec3<f32>(P.unit_shift));
    let voxel = vec3<f32>(1.0) / (P.world_to_leaf * exp2(vec3<f32>(P.fine + P.unit_shift)));
    var g = vec3<f32>(0.0);
    for (var a = 0u; a < 3u; a++) {
        var e = vec3<f32>(0.0);
        e[a] = half[a];
        var plus = at;
        advance(&plus, e, 1.0);
        var minus = at;
        advance(&minus, -e, 1.0);
        let sp = sample_filtered(c, l, plus.cell, plus.local, false, t);
        let sm = sample_filtered(c, l, minus.cell, minus.local, false, t);
        if sp.ok && sm.ok && !sp.clear && !sm.clear {
            g[a] = (sp.value - sm.value) / voxel[a];
        }
    }
    var lit = 1.0;
    if dot(g, g) > 0.0 {
        lit = abs(dot(normalize(g), world_dir));
    }
    return S.channels[c].color * (0.25 + 0.75 * lit);
}

// MODE_MIP: raises each channel's maximum in `have` to its value (NaN is no value); returns
// whether every channel drawn has reached the value from which its intensity stays 1.
fn take_maxima(
    have: u32,
    values: ptr<function, array<f32, MAX_CHANNELS>>,
    maxima: ptr<function, array<f32, MAX_CHANNELS>>,
) -> bool {
    var left = have;
    loop {
        if left == 0u {
            break;
        }
        let c = take_channel(&left);
        let v = (*values)[c];
        if v == v && v > (*maxima)[c] {
            (*maxima)[c] = v;
        }
    }
    var saturated = true;
    for (var c = 0u; c < P.channel_count; c++) {
        saturated = saturated && (*maxima)[c] >= S.channels[c].saturation;
    }
    return saturated;
}

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
    // A fresh ray, or (VDI) one starting another march.
    let fresh = st.status == RAY_FRESH || st.status == RAY_RESTART;
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
    if fresh {
        color = vec3<f32>(0.0);
        trans = 1.0;
    }
    var vdi = vdi_fresh();
    if VDI && st.status != RAY_FRESH {
        vdi = vdi_load(pixel);
    }
    // MODE_MIP: each channel's largest value so far; MODE_ISO: its last value, and the
    // IsoState. Kept between passes.
    var kept: array<f32, MAX_CHANNELS>;
    var iso = IsoState(0.0, 0u, 0u, 0u);
    if MODE == MODE_MIP || MODE == MODE_ISO {
        for (var c = 0u; c < P.channel_count; c++) {
            kept[c] = NO_MAXIMUM;
            if !fresh {
                kept[c] = out_color[channel_texel(pixel, c)][c % 4u];
            }
        }
    }
    if MODE == MODE_ISO && !fresh {
        let words = bitcast<vec4<u32>>(out_color[iso_texel(pixel)]);
        iso = IsoState(bitcast<f32>(words.x), words.y, words.z, words.w);
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
        if fresh {
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
                        v = visit_octree(ray, last_depth, desired_step, dir, skipping, &kept, iso);
                        last_depth = v.depth;
                        held = v;
                        held_step = desired_step;
                        held_cell = ray.cell >> node_shift(v.depth);
                    }
                } else if METHOD == METHOD_PAGE_TABLE {
                    v = visit_page_table(ray, chosen, &pt_brick, &pt_empty, dir, skipping, iso);
                } else if METHOD == METHOD_OCTREE {
                    v = visit_brick_octree(ray, &chosen, dir, skipping, ray.t + t_plane, iso);
                }
                if RESIDENT_ONLY && needs_full {
                    suspended = true;
                    stop = true;
                    break;
                }
                if v.action == ACTION_SKIP {
                    skipped++;
                    advance(&ray, dir, v.skip + nudge);
                    if MODE == MODE_ISO {
                        var data = v.empty;
                        if METHOD == METHOD_RESIDENCY {
                            data = node_data_channels(v.node);
                        }
                        iso_skipped(&iso, data, ray.t);
                    }
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
            if MODE == MODE_MIP {
                if take_maxima(s.have, &values, &kept) {
                    trans = 0.0; // every channel saturated: nothing can change (ends the ray)
                }
            } else if MODE == MODE_ISO {
                if v.action == ACTION_REQUEST {
                    // Nothing sampled over the unmapped node: its values are not known.
                    iso.valued = 0u;
                    iso.at = ray.t + move_by;
                } else {
                    var hit = 0.0;
                    let c = iso_take(s.have, &values, &kept, &iso, ray.t, &hit);
                    if c != NO_CHANNEL {
                        var l = level_of(chosen, c);
                        if l == NO_LEVEL {
                            l = 0u;
                        }
                        color = iso_shade(c, l, ray, dir, hit, pray.world_dir);
                        trans = 0.0; // an opaque surface ends the ray
                    }
                }
            } else {
                let m = mixture(s.have, &values, step);
                if VDI {
                    // A step may end past the volume's face: the supersegment ends there.
                    let t1 = min(ray.t + move_by, t_exit);
                    vdi_step(&vdi, pixel, m, steps, ray.t, t1, color, trans, t_plane);
                }
                composite(&color, &trans, m, steps);
            }
            advance(&ray, dir, move_by);
            if VDI && vdi_over(vdi) {
                break;
            }
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
    if VDI {
        if !suspended {
            vdi_close(&vdi, pixel, color, trans, t_plane);
            if vdi_next_march(&vdi) {
                st.status = RAY_RESTART;
                atomicAdd(&requests.counters.rays_suspended, 1u);
            } else {
                vdi_finish(pixel, vdi, vec4<f32>(color + trans * P.background, 1.0 - trans));
            }
        }
        if st.status != RAY_DONE {
            vdi_store(pixel, vdi);
        }
    }
    rays[pixel] = st;
    if suspended {
        atomicAdd(&requests.counters.rays_suspended, 1u);
        if RESIDENT_ONLY && needs_full {
            atomicAdd(&requests.counters.rays_need_full, 1u);
        }
    } else if MODE == MODE_MIP {
        out_color[pixel] = mip_pixel(&kept, P.background);
    } else if MODE == MODE_ISO {
        out_color[pixel] = select(vec4<f32>(P.background, 0.0), vec4<f32>(color, 1.0), trans == 0.0);
    } else if !VDI {
        out_color[pixel] = vec4<f32>(color + trans * P.background, 1.0 - trans);
    }
    if (MODE == MODE_MIP || MODE == MODE_ISO) && suspended {
        for (var c = 0u; c < P.channel_count; c++) {
            out_color[channel_texel(pixel, c)][c % 4u] = kept[c];
        }
        if MODE == MODE_ISO {
            out_color[iso_texel(pixel)] = bitcast<vec4<f32>>(vec4<u32>(bitcast<u32>(iso.at), iso.known, iso.above, iso.valued));
        }
    }
    atomicAdd(&requests.counters.samples, samples);
    atomicAdd(&requests.counters.empty_nodes_skipped, skipped);
    atomicAdd(&requests.counters.homogeneous_nodes, homogeneous);
    atomicAdd(&requests.counters.samples_without_data, nodata);
}
