// The ray caster, part 4 of 7 (joined in order by viewer/src/gpu/contract.rs): reading the
// ray segment lists that segments.wgsl wrote (SparseLeap, rasterize).

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

