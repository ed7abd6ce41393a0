// The ray caster, part 6 of 7 (joined in order by viewer/src/gpu/contract.rs): volumetric
// depth images (VDIs; Gupta et al., "Efficient Raycasting of Volumetric Depth Images", Sec.
// 2.3 and 3). With the pipeline constant VDI the ray loop of raycast.wgsl marches and
// composites exactly as for an image, and also cuts what it composites into at most
// P.supersegments supersegments per pixel: runs of steps whose premultiplied colour stays
// within γ of the run's mean (Eq. 1), each stored as the colour and opacity that compositing
// its steps gives, with its front and back distance from the eye. Transparent steps and
// skipped space end a supersegment, so no supersegment holds empty space.
//
// γ is found per ray (ray-adaptive termination, Sec. 3): a first march with γ = 1e-5 writes
// the supersegments as it counts them; a ray that needs no more than N_S (empty, homogeneous
// or simple) is then done. Otherwise γ is bisected in [1e-5, √3] by marches that only count,
// until a march gives between (1 − 15 %)·N_S and N_S supersegments (or VDI_BISECTIONS marches
// have run: then the smallest γ known, or assumed, to fit), and a last march writes them. A
// march that counts stops as soon as it passes N_S. In that last march the last slot takes
// everything after it, so a list never holds more than N_S. The bisection is geometric (the
// next γ is √(lo·hi), the midpoint of ln γ): the γ that suit a ray lie within a factor of a few
// of each other anywhere in those five and a quarter decades, where halving [lo, hi] spends its
// first marches above them (on the VDI bench's mixing volume at 640×360, 3.82 marches a ray
// with a fifth of the rays reaching the 13th, against 2.24 and none past the 9th, the same
// images). Rays the bisection has not placed in the window by then are mostly those whose count
// jumps over it at one γ: on the bench, 12 bisections instead of 8 gave the same images.
//
// The VDI target buffer (binding IMAGE, `out_color`) holds per pixel P.supersegments slots,
// then VDI_STATE_SLOTS slots of the ray's VDI state between passes (`VdiRay`); a finished
// ray leaves there its DVR colour (slot 0) and its supersegment count and γ (slot 1), which
// viewer/src/gpu/vdi.rs reads back. A slot is vec4<f32>(pack2x16float(r, g),
// pack2x16float(b, a), front, back) with r, g, b premultiplied by the supersegment's
// opacity a, and front and back the distances from the eye (world units).

override VDI: bool = false;

const VDI_COUNTING: u32 = 0u; // marches that count supersegments for a trial γ
const VDI_WRITING: u32 = 1u; // the march that writes them
const VDI_FIRST: u32 = 2u; // the first march: writes up to N_S, counts on, never merges
const VDI_GAMMA_FIRST: f32 = 1e-5;
const VDI_GAMMA_MAX: f32 = 1.7320508; // √3: the largest L2 distance of two RGB colours in [0, 1]
const VDI_TOLERANCE: f32 = 0.15; // a count down to (1 − this)·N_S is accepted
const VDI_BISECTIONS: u32 = 8u; // marches before the writing one, at most (a ray's 9 in all)

// A ray's VDI state: the open supersegment, the bisection of γ, and the march's count.
struct VdiRay {
    mean: vec3<f32>, // running mean of the open supersegment's per-step premultiplied colour
    steps: f32, // steps in the open supersegment (0: none is open)
    front_color: vec3<f32>, // the ray's composited colour where the open one begins
    front_trans: f32, // and its transmittance there
    gamma: f32,
    lo: f32, // largest γ known to give too many supersegments
    hi: f32, // smallest γ known (or assumed, √3) to give few enough
    front: f32, // ray distance (view plane) where the open one begins
    back: f32, // and where its last step ended
    count: u32, // supersegments closed in this march
    phase: u32, // VDI_FIRST, VDI_COUNTING or VDI_WRITING
    iteration: u32, // marches run
}

// The first slot of a pixel in the VDI target.
fn vdi_base(pixel: u32) -> u32 {
    return pixel * (P.supersegments + VDI_STATE_SLOTS);
}

// The state of a ray starting its first march.
fn vdi_fresh() -> VdiRay {
    return VdiRay(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 1.0, VDI_GAMMA_FIRST, VDI_GAMMA_FIRST,
        VDI_GAMMA_MAX, 0.0, 0.0, 0u, VDI_FIRST, 0u);
}

fn vdi_load(pixel: u32) -> VdiRay {
    let b = vdi_base(pixel) + P.supersegments;
    let s0 = out_color[b];
    let s1 = out_color[b + 1u];
    let s2 = out_color[b + 2u];
    let s3 = out_color[b + 3u];
    return VdiRay(s0.xyz, s0.w, s1.xyz, s1.w, s2.x, s2.y, s2.z, s2.w, s3.x, bitcast<u32>(s3.y),
        bitcast<u32>(s3.z), bitcast<u32>(s3.w));
}

fn vdi_store(pixel: u32, v: VdiRay) {
    let b = vdi_base(pixel) + P.supersegments;
    out_color[b] = vec4<f32>(v.mean, v.steps);
    out_color[b + 1u] = vec4<f32>(v.front_color, v.front_trans);
    out_color[b + 2u] = vec4<f32>(v.gamma, v.lo, v.hi, v.front);
    out_color[b + 3u] = vec4<f32>(v.back, bitcast<f32>(v.count), bitcast<f32>(v.phase),
        bitcast<f32>(v.iteration));
}

// Ends the open supersegment, if any, where the ray's colour is `color` and its transmittance
// `trans`; the writing march stores it (`t_plane`: the view plane's distance from the eye).
fn vdi_close(v: ptr<function, VdiRay>, pixel: u32, color: vec3<f32>, trans: f32, t_plane: f32) {
    if (*v).steps == 0.0 {
        return;
    }
    if (*v).phase != VDI_COUNTING && (*v).count < P.supersegments {
        // What compositing the supersegment's steps alone gives, from the ray's totals at
        // its two ends.
        let alpha = clamp(1.0 - trans / (*v).front_trans, 0.0, 1.0);
        // Channels mix additively, so a premultiplied colour may pass 1; never below 0.
        let rgb = max((color - (*v).front_color) / (*v).front_trans, vec3<f32>(0.0));
        out_color[vdi_base(pixel) + (*v).count] = vec4<f32>(
            bitcast<f32>(pack2x16float(rgb.xy)),
            bitcast<f32>(pack2x16float(vec2<f32>(rgb.z, alpha))),
            (*v).front + t_plane,
            (*v).back + t_plane,
        );
    }
    (*v).count = min((*v).count + 1u, 255u);
    (*v).steps = 0.0;
}

// One composited step from ray distance t0 to t1 (`steps` steps of mixture m, integrated in
// closed form for a homogeneous node), with the ray's colour and transmittance before the
// step (`color`, `trans`).
fn vdi_step(v: ptr<function, VdiRay>, pixel: u32, m: Mixture, steps: f32, t0: f32, t1: f32,
    color: vec3<f32>, trans: f32, t_plane: f32) {
    // The writing march's last slot takes the rest of the ray.
    let last = (*v).phase == VDI_WRITING && (*v).count + 1u >= P.supersegments;
    if min(m.alpha, 1.0) <= 0.0 {
        if !last {
            vdi_close(v, pixel, color, trans, t_plane);
        }
        return;
    }
    if (*v).steps > 0.0 {
        let gap = t0 > (*v).back; // skipped space between the two
        let differs = distance(m.color, (*v).mean) > (*v).gamma;
        if (gap || differs) && !last {
            vdi_close(v, pixel, color, trans, t_plane);
        }
    }
    if (*v).steps == 0.0 {
        (*v).mean = vec3<f32>(0.0);
        (*v).front_color = color;
        (*v).front_trans = trans;
        (*v).front = t0;
    }
    let total = (*v).steps + steps;
    (*v).mean += (m.color - (*v).mean) * (steps / total);
    (*v).steps = total;
    (*v).back = t1;
}

// Whether a counting march (or the first) can stop now: it has passed N_S, so γ is too
// small.
fn vdi_over(v: VdiRay) -> bool {
    return v.phase != VDI_WRITING && v.count > P.supersegments;
}

// After a march: the next γ, or the writing march, or done. Returns whether the ray marches
// again.
fn vdi_next_march(v: ptr<function, VdiRay>) -> bool {
    (*v).iteration++;
    let n = (*v).count;
    // The first march (γ = 1e-5) wrote what it found: a ray that fits is done.
    if (*v).phase == VDI_WRITING || ((*v).phase == VDI_FIRST && n <= P.supersegments) {
        return false;
    }
    (*v).phase = VDI_COUNTING;
    let enough = u32(ceil((1.0 - VDI_TOLERANCE) * f32(P.supersegments)));
    if n <= P.supersegments && n >= enough {
        (*v).phase = VDI_WRITING;
    } else {
        if n > P.supersegments {
            (*v).lo = (*v).gamma;
        } else {
            (*v).hi = (*v).gamma;
        }
        if (*v).iteration >= VDI_BISECTIONS {
            (*v).gamma = (*v).hi;
            (*v).phase = VDI_WRITING;
        } else {
            (*v).gamma = sqrt((*v).lo * (*v).hi);
        }
    }
    (*v).count = 0u;
    (*v).steps = 0.0;
    return true;
}

// What a finished ray leaves for the host: its DVR colour, and its supersegment count and γ.
fn vdi_finish(pixel: u32, v: VdiRay, dvr: vec4<f32>) {
    let b = vdi_base(pixel) + P.supersegments;
    out_color[b] = dvr;
    out_color[b + 1u] = vec4<f32>(bitcast<f32>(min(v.count, P.supersegments)), v.gamma,
        bitcast<f32>(v.iteration), 0.0);
}
