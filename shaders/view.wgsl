// What the ray caster (raycast.wgsl) and the ray segment lists (segments.wgsl) share, put
// after the generated prelude: the per-frame uniforms and each pixel's ray, so that a box's
// interval on a pixel's ray is computed with the same arithmetic on both sides.

// Per frame. Positions are in leaf units (octree leaves) or fine units; axes x, y, z.
struct Params {
    width: u32,
    height: u32,
    frame: u32, // >= 1: the mark of usage feedback and request flags
    channel_count: u32,
    leaf_depth: u32,
    level_count: u32,
    request_cap: u32,
    start_depth: u32,
    class_offset: u32, // word offset of the node (ours) or brick (baselines) classes in `nodes`
    steps_per_pass: u32, // then the ray is suspended and resumed by the next pass
    flags: u32, // FLAG_SKIPPING, FLAG_SUBSTITUTION
    segment_offset: u32, // word offset of the ray segment area in `nodes` (SEGMENT_HEADS)
    // The view point V = eye + D·forward (D = view_distance), leaf units: integer part. Rays
    // start from the plane through V facing the camera, so a far camera keeps voxel
    // precision (D = 0, V the eye, for a camera near the volume).
    view_cell: vec3<i32>,
    slots_z: u32, // atlas slots per z
    view_frac: vec3<f32>, // V, leaf units: fraction
    reference_step: f32, // Δ0 of the opacity correction (world)
    right: vec3<f32>, // camera right · tan(fov/2) · aspect
    lod_bias: f32, // log2
    up: vec3<f32>, // camera up · tan(fov/2)
    pixel_footprint: f32, // per unit distance (world)
    forward: vec3<f32>, // camera forward (unit)
    step_fraction: f32, // step as a fraction of a voxel of the level in use
    world_to_leaf: vec3<f32>, // leaf units per world unit
    leaf_edge: f32, // world, smallest axis
    volume_leaf: vec3<f32>, // volume extent in leaf units
    view_distance: f32, // D (world)
    background: vec3<f32>,
    slots_x_log2: u32, // log2 of atlas slots per x
    unit_shift: vec3<i32>, // log2 of a fine unit's edge in level-0 voxels (leaf shift - fine)
    slots_y_log2: u32, // log2 of atlas slots per y
    fine: vec3<i32>, // F: log2 of fine units per leaf
    segment_capacity: u32, // records the ray segment area holds
    brick: vec3<u32>, // brick edge in voxels
    supersegments: u32, // most per pixel of a volumetric depth image (raycast/vdi.wgsl)
    clip_lo: vec3<f32>, // the box kept (the volume's when the scene clips none), leaf units
    clip_plane_count: u32,
    clip_hi: vec3<f32>,
    pad0: u32,
    clip_planes: array<vec4<f32>, CLIP_PLANE_SLOTS>, // (n, d): kept where n·p >= d, leaf units
}

// One record of a pixel's ray segment list (segments.wgsl writes them, raycast.wgsl walks
// them): where the pixel's ray is inside one box, as RECORD_WORDS words in this order.
struct SegmentRecord {
    t_in: f32,
    t_out: f32,
    payload: u32,
    next: u32, // next record + 1; 0 ends the list
}

// A pixel's ray. Positions are leaf units; distances `t` are world units from the view plane
// (the ray caster's ray.t), and t_plane is the view plane's distance from the eye.
struct PixelRay {
    world_dir: vec3<f32>, // unit
    dir_leaf: vec3<f32>, // leaf units per world unit, no component exactly 0
    start: vec3<f32>, // where the ray meets the view plane, relative to V
    origin: vec3<f32>, // minus the ray's origin (V + start), relative to the volume's corner
    t_plane: f32,
}

// The ray through the centre of pixel (px, py) (schemas/src/scene.rs: the projection).
fn pixel_ray(px: u32, py: u32) -> PixelRay {
    let ndc = vec2<f32>(
        (f32(px) + 0.5) / f32(P.width) * 2.0 - 1.0,
        1.0 - (f32(py) + 0.5) / f32(P.height) * 2.0,
    );
    let across = ndc.x * P.right + ndc.y * P.up;
    let ray_forward = P.forward + across;
    var r: PixelRay;
    r.world_dir = normalize(ray_forward);
    // The ray meets the view plane at V + D·across (leaf units: `start`), at distance t_plane
    // from the eye; `t` counts from there, and t_plane is added back for the LOD rule.
    r.t_plane = P.view_distance * length(ray_forward);
    r.start = P.view_distance * across * P.world_to_leaf;
    let dir_leaf = r.world_dir * P.world_to_leaf;
    r.dir_leaf = select(dir_leaf, vec3<f32>(1e-20), abs(dir_leaf) < vec3<f32>(1e-20));
    r.origin = -vec3<f32>(P.view_cell) - P.view_frac - r.start;
    return r;
}

// Where ray r is inside the box [lo, hi] (leaf units): (t_in, t_out), empty when t_out <= t_in.
fn box_span(r: PixelRay, lo: vec3<f32>, hi: vec3<f32>) -> vec2<f32> {
    let ta = (lo + r.origin) / r.dir_leaf;
    let tb = (hi + r.origin) / r.dir_leaf;
    let tmin = min(ta, tb);
    let tmax = max(ta, tb);
    return vec2<f32>(max(tmin.x, max(tmin.y, tmin.z)), min(tmax.x, min(tmax.y, tmax.z)));
}

// Where ray r is inside the part of the volume the scene keeps (its clip box, within the
// volume, and the kept side of every clip plane): (t_enter, t_exit), starting no nearer than
// the eye; empty when t_exit <= t_enter. residency_schemas::scene::Clip::clip_span is the f64
// rule.
fn volume_span(r: PixelRay) -> vec2<f32> {
    let span = box_span(r, P.clip_lo, P.clip_hi);
    var t0 = max(span.x, -r.t_plane);
    var t1 = span.y;
    let at0 = -r.origin; // the ray at t = 0, leaf units from the volume's corner
    for (var i = 0u; i < P.clip_plane_count; i++) {
        let plane = P.clip_planes[i];
        let s0 = dot(plane.xyz, at0) - plane.w;
        let dn = dot(plane.xyz, r.dir_leaf);
        if dn > 0.0 {
            t0 = max(t0, -s0 / dn);
        } else if dn < 0.0 {
            t1 = min(t1, -s0 / dn);
        } else if s0 < 0.0 {
            t1 = t0; // parallel, on the cut side
        }
    }
    return vec2<f32>(t0, t1);
}

