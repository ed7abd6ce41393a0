// What raycast.wgsl and probe.wgsl share, put between the generated prelude and each
// shader's own code (viewer/src/gpu/contract.rs): the scene uniforms' structs, transfer
// functions, opacity correction, and compositing. It reads the including shader's `P.channel_count` and
// `P.reference_step`, the scene uniforms `S` and the table buffer `tables`.

// ---- the scene uniforms (SceneUniforms in viewer/src/gpu/contract.rs) ----

struct LevelEntry {
    shift: vec3<i32>, // log2 of the downsampling factor relative to level 0
    voxel_edge: f32, // smallest edge of a voxel of this level (world)
    shape: vec3<i32>, // voxels
    pad0: u32,
    bricks: vec3<u32>, // bricks per axis
    pad1: u32,
}

struct ChannelEntry {
    color: vec3<f32>, // linear RGB
    point_count: u32, // opacity control points
    min_level: u32, // level bounds of the LOD choice
    max_level: u32,
    points_offset: u32, // (value, opacity) pairs in `tables`
    opacity_top: f32, // the highest opacity of the points: MIP's scale
    saturation: f32, // MIP: from this value on the intensity no longer changes (±f32 max)
    iso: f32, // MODE_ISO: the surface's value (f32 max: none)
    pad1: u32,
    pad2: u32,
}

struct SceneUniforms {
    levels: array<LevelEntry, MAX_LEVELS>,
    channels: array<ChannelEntry, MAX_CHANNELS>,
}

// ---- transfer functions ----

fn tf32(i: u32) -> f32 {
    return bitcast<f32>(tables[i]);
}

// Opacity at the reference step (piecewise linear, end values held; NaN is transparent).
fn tf_opacity(c: u32, v: f32) -> f32 {
    let off = S.channels[c].points_offset;
    let n = S.channels[c].point_count;
    if n == 0u || v != v {
        return 0.0;
    }
    if v <= tf32(off) {
        return tf32(off + 1u);
    }
    for (var i = 1u; i < n; i++) {
        let a = vec2<f32>(tf32(off + 2u * (i - 1u)), tf32(off + 2u * (i - 1u) + 1u));
        let b = vec2<f32>(tf32(off + 2u * i), tf32(off + 2u * i + 1u));
        if v <= b.x {
            if b.x == a.x {
                return b.y;
            }
            return a.y + (v - a.x) / (b.x - a.x) * (b.y - a.y);
        }
    }
    return tf32(off + 2u * (n - 1u) + 1u);
}

// Opacity of a sample of per-reference-step opacity `a` taken over a step of `step` (world):
// α' = 1 − (1 − α)^(step/Δ0).
fn corrected(a: f32, step: f32) -> f32 {
    if a >= 1.0 {
        return 1.0;
    }
    return 1.0 - pow(1.0 - max(a, 0.0), step / P.reference_step);
}

// ---- compositing ----

// One step's mixture of the channels: opacity-weighted colour and summed opacity.
struct Mixture {
    color: vec3<f32>,
    alpha: f32,
}

// Bits: every channel drawn.
fn drawn_channels() -> u32 {
    return (1u << P.channel_count) - 1u;
}

// The lowest channel of `bits`, taken out of it. Loops over the channels a step needs run
// `loop { if bits == 0u { break; } let c = take_channel(&bits); ... }`: as often as the most
// such channels any ray of a warp (or of a CPU driver's SIMD lanes) has, not once per channel.
fn take_channel(bits: ptr<function, u32>) -> u32 {
    let c = firstTrailingBit(*bits);
    *bits &= *bits - 1u;
    return c;
}

// The mixture of the channels in `have` with `values`, each opacity corrected to `step`.
// Channels mix additively (DESIGN.md: colours weighted by opacity, opacities summed).
// Arrays go by pointer and live outside the ray loops: on a CPU Vulkan driver a copied or
// loop-local array is written lane by lane on every iteration.
fn mixture(have: u32, values: ptr<function, array<f32, MAX_CHANNELS>>, step: f32) -> Mixture {
    var m = Mixture(vec3<f32>(0.0), 0.0);
    // The channels in `have` only (take_channel).
    var left = have;
    loop {
        if left == 0u {
            break;
        }
        let c = take_channel(&left);
        let a = corrected(tf_opacity(c, (*values)[c]), step);
        m.color += a * S.channels[c].color;
        m.alpha += a;
    }
    return m;
}

// ---- maximum intensity projection ----

// A channel's maximum before the ray has met a value of it.
const NO_MAXIMUM: f32 = -3.4028234e38; // -f32::MAX (Tint refuses a literal past it)

// Channel c's intensity for its largest value m along the ray: its transfer function scaled so
// that its highest point is 1; 0 where the ray met no value, or the function is 0 everywhere.
fn mip_intensity(c: u32, m: f32) -> f32 {
    let top = S.channels[c].opacity_top;
    if m == NO_MAXIMUM || top <= 0.0 {
        return 0.0;
    }
    return tf_opacity(c, m) / top;
}

// The pixel of a ray whose channels' maxima are `maxima`: Σ w_c·colour_c over the background
// weighted by 1 − a, a = min(1, Σ w_c) (crate::scene's module doc).
fn mip_pixel(maxima: ptr<function, array<f32, MAX_CHANNELS>>, background: vec3<f32>) -> vec4<f32> {
    var color = vec3<f32>(0.0);
    var sum = 0.0;
    for (var c = 0u; c < P.channel_count; c++) {
        let w = mip_intensity(c, (*maxima)[c]);
        color += w * S.channels[c].color;
        sum += w;
    }
    let a = min(sum, 1.0);
    return vec4<f32>(color + (1.0 - a) * background, a);
}

// Front-to-back emission–absorption of `steps` steps of mixture `m` (its opacity clamped to
// 1): one step for a sample; seg/Δ steps for a homogeneous node, integrated in closed form.
// The only place colour and transmittance change.
fn composite(color: ptr<function, vec3<f32>>, trans: ptr<function, f32>, m: Mixture, steps: f32) {
    let alpha = min(m.alpha, 1.0);
    if alpha <= 0.0 {
        return;
    }
    if steps == 1.0 {
        *color += *trans * m.color;
        *trans *= 1.0 - alpha;
        return;
    }
    let keep = pow(1.0 - alpha, steps);
    *color += *trans * m.color / alpha * (1.0 - keep);
    *trans *= keep;
}
