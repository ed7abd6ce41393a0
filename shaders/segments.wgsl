// Ray segment lists: the boxes of SparseLeap's occupancy geometry, or of the rasterize
// method's cut of bricks, rasterised into one linked list per pixel of the intervals where the
// pixel's ray is inside each box (SegmentRecord). The ray caster (raycast.wgsl) then walks
// its pixel's list instead of a hierarchy.
//
// Each box is drawn as 12 triangles with its front faces culled, so a pixel whose ray meets the
// box gets one fragment, from the face where the ray leaves it (or none where the ray misses
// it), whether the eye is outside the box or inside. The fragment does not interpolate a
// depth: it intersects its pixel's ray with the box (box_span, as the ray caster's volume test
// does), so boxes that share a face give the same distance on both sides. No depth or colour
// is written.
//
// The records go into the ray segment area of the node buffer (Params.segment_offset; layout
// at SEGMENT_HEADS in viewer/src/gpu/contract.rs): a record is allocated with one atomic add
// and pushed on its pixel's list with one exchange. When the area is full, the pixel's
// overflow flag is set and the ray caster marches that ray whole.

struct SegmentBox {
    lo: vec3<f32>, // leaf units
    payload: u32, // segment_payload: occupancy class, octree depth, level
    hi: vec3<f32>,
    pad0: u32,
}

@group(0) @binding(0) var<uniform> P: Params;
@group(0) @binding(1) var<storage, read> boxes: array<SegmentBox>;
@group(0) @binding(2) var<storage, read_write> area: array<atomic<u32>>;

// The 36 corners of a unit cube's 12 triangles, counter-clockwise seen from outside.
const CUBE = array<vec3<f32>, 36>(
    // -x
    vec3<f32>(0.0, 0.0, 0.0), vec3<f32>(0.0, 0.0, 1.0), vec3<f32>(0.0, 1.0, 1.0),
    vec3<f32>(0.0, 0.0, 0.0), vec3<f32>(0.0, 1.0, 1.0), vec3<f32>(0.0, 1.0, 0.0),
    // +x
    vec3<f32>(1.0, 0.0, 0.0), vec3<f32>(1.0, 1.0, 0.0), vec3<f32>(1.0, 1.0, 1.0),
    vec3<f32>(1.0, 0.0, 0.0), vec3<f32>(1.0, 1.0, 1.0), vec3<f32>(1.0, 0.0, 1.0),
    // -y
    vec3<f32>(0.0, 0.0, 0.0), vec3<f32>(1.0, 0.0, 0.0), vec3<f32>(1.0, 0.0, 1.0),
    vec3<f32>(0.0, 0.0, 0.0), vec3<f32>(1.0, 0.0, 1.0), vec3<f32>(0.0, 0.0, 1.0),
    // +y
    vec3<f32>(0.0, 1.0, 0.0), vec3<f32>(0.0, 1.0, 1.0), vec3<f32>(1.0, 1.0, 1.0),
    vec3<f32>(0.0, 1.0, 0.0), vec3<f32>(1.0, 1.0, 1.0), vec3<f32>(1.0, 1.0, 0.0),
    // -z
    vec3<f32>(0.0, 0.0, 0.0), vec3<f32>(0.0, 1.0, 0.0), vec3<f32>(1.0, 1.0, 0.0),
    vec3<f32>(0.0, 0.0, 0.0), vec3<f32>(1.0, 1.0, 0.0), vec3<f32>(1.0, 0.0, 0.0),
    // +z
    vec3<f32>(0.0, 0.0, 1.0), vec3<f32>(1.0, 0.0, 1.0), vec3<f32>(1.0, 1.0, 1.0),
    vec3<f32>(0.0, 0.0, 1.0), vec3<f32>(1.0, 1.0, 1.0), vec3<f32>(0.0, 1.0, 1.0),
);

struct Fragment {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) box: u32,
}

// Projects a corner of box `instance` with the ray caster's pinhole camera: a point at
// z·(forward + nx·right + ny·up) from the eye lands on NDC (nx, ny). Depth is constant inside
// the clip volume from a hair in front of the eye to infinity, so nothing is clipped but what
// lies behind the eye.
@vertex
fn box_vertex(@builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> Fragment {
    let b = boxes[instance];
    let corner = mix(b.lo, b.hi, CUBE[vertex]);
    // Relative to the view point V = eye + D·forward; right and up are orthogonal to forward,
    // so D enters the depth only (a far camera keeps the corner's precision).
    let from_view = (corner - vec3<f32>(P.view_cell) - P.view_frac) / P.world_to_leaf;
    let w = dot(from_view, P.forward) + P.view_distance;
    let near = 1e-4 * P.leaf_edge;
    var out: Fragment;
    out.position = vec4<f32>(
        dot(from_view, P.right) / dot(P.right, P.right),
        dot(from_view, P.up) / dot(P.up, P.up),
        w - near,
        w,
    );
    out.box = instance;
    return out;
}

// Records where this pixel's ray is inside the box, clipped to the volume.
@fragment
fn box_fragment(in: Fragment) -> @location(0) vec4<f32> {
    let px = u32(in.position.x);
    let py = u32(in.position.y);
    if px < P.width && py < P.height {
        let r = pixel_ray(px, py);
        let b = boxes[in.box];
        let span = box_span(r, b.lo, b.hi);
        let volume = volume_span(r);
        let t_in = max(span.x, volume.x);
        let t_out = min(span.y, volume.y);
        if t_out > t_in {
            let pixel = py * P.width + px;
            let pixels = P.width * P.height;
            let i = atomicAdd(&area[0], 1u);
            if i < P.segment_capacity {
                let at = SEGMENT_HEADS + 2u * pixels + i * RECORD_WORDS;
                let record = SegmentRecord(t_in, t_out, b.payload, 0u);
                atomicStore(&area[at], bitcast<u32>(record.t_in));
                atomicStore(&area[at + 1u], bitcast<u32>(record.t_out));
                atomicStore(&area[at + 2u], record.payload);
                let next = atomicExchange(&area[SEGMENT_HEADS + pixel], i + 1u);
                atomicStore(&area[at + 3u], next);
            } else {
                atomicStore(&area[SEGMENT_HEADS + pixels + pixel], 1u);
            }
        }
    }
    return vec4<f32>(0.0);
}
