// The limit probe of `viewer bench` (viewer/src/gpu/probe.rs): the same rays, step, transfer
// functions and compositing as raycast.wgsl, through one resident 3D texture holding level 0
// of every drawn channel, with no traversal, page tables, residency or substitution. What
// sampling alone costs on this device: the renderer's samples per second are reported as a
// fraction of the probe's. One thread per pixel; rays end at T < 1/255 as in raycast.wgsl.

const T_MIN: f32 = 0.003921569;
// FILTER_MANUAL: 8 textureLoads and the same trilinear weights as raycast.wgsl;
// FILTER_HARDWARE: one filtered textureSampleLevel (needs a filterable format).
override FILTER: u32 = 0u;

struct ProbeParams {
    width: u32,
    height: u32,
    channel_count: u32,
    slab_depth: u32, // z voxels of one channel: channel c lies at z in [c·slab_depth, (c+1)·slab_depth)
    eye: vec3<f32>, // world
    reference_step: f32, // Δ0 of the opacity correction (world)
    right: vec3<f32>, // camera right · tan(fov/2) · aspect
    step: f32, // world: the step raycast.wgsl takes at level 0
    up: vec3<f32>, // camera up · tan(fov/2)
    pad0: u32,
    forward: vec3<f32>,
    pad1: u32,
    world_to_voxel: vec3<f32>,
    pad2: u32,
    volume: vec3<f32>, // level-0 extent in voxels
    pad3: u32,
    background: vec3<f32>,
    pad4: u32,
}

@group(0) @binding(0) var<uniform> P: ProbeParams;
@group(0) @binding(1) var<storage, read> tables: array<u32>;
@group(0) @binding(2) var<uniform> S: SceneUniforms;
@group(0) @binding(3) var level0: texture_3d<f32>;
@group(0) @binding(4) var volume_sampler: sampler;
@group(0) @binding(5) var<storage, read_write> out_color: array<vec4<f32>>;
// Samples per image row (a frame's total can pass 2^32 at 1080p; a row's cannot).
@group(0) @binding(6) var<storage, read_write> row_samples: array<atomic<u32>>;

// Trilinear sample of channel c at voxel coordinates p (voxel centres at i + ½), clamped to
// the edge voxels as raycast.wgsl and the reference do.
fn probe_sample(c: u32, p: vec3<f32>) -> f32 {
    let size = vec3<f32>(P.volume);
    let q = clamp(p, vec3<f32>(0.5), size - vec3<f32>(0.5));
    let slab = f32(c * P.slab_depth);
    if FILTER == FILTER_HARDWARE {
        let dims = vec3<f32>(textureDimensions(level0));
        return textureSampleLevel(level0, volume_sampler, (q + vec3<f32>(0.0, 0.0, slab)) / dims, 0.0).x;
    }
    let u = q - vec3<f32>(0.5);
    let f = floor(u);
    let w = u - f;
    let hi = vec3<i32>(P.volume) - vec3<i32>(1);
    let i0 = vec3<i32>(f);
    let i1 = min(i0 + vec3<i32>(1), hi);
    let o = vec3<i32>(0, 0, i32(c * P.slab_depth));
    let a = o + i0;
    let b = o + i1;
    let x00 = mix(textureLoad(level0, a, 0).x, textureLoad(level0, vec3<i32>(b.x, a.y, a.z), 0).x, w.x);
    let x10 = mix(textureLoad(level0, vec3<i32>(a.x, b.y, a.z), 0).x, textureLoad(level0, vec3<i32>(b.x, b.y, a.z), 0).x, w.x);
    let x01 = mix(textureLoad(level0, vec3<i32>(a.x, a.y, b.z), 0).x, textureLoad(level0, vec3<i32>(b.x, a.y, b.z), 0).x, w.x);
    let x11 = mix(textureLoad(level0, vec3<i32>(a.x, b.y, b.z), 0).x, textureLoad(level0, b, 0).x, w.x);
    return mix(mix(x00, x10, w.y), mix(x01, x11, w.y), w.z);
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= P.width || gid.y >= P.height {
        return;
    }
    let ndc = vec2<f32>(
        (f32(gid.x) + 0.5) / f32(P.width) * 2.0 - 1.0,
        1.0 - (f32(gid.y) + 0.5) / f32(P.height) * 2.0,
    );
    let dir = normalize(P.forward + ndc.x * P.right + ndc.y * P.up);
    // Slab test against the volume box, in voxels.
    let o = P.eye * P.world_to_voxel;
    var d = dir * P.world_to_voxel;
    d = select(d, vec3<f32>(1e-20), abs(d) < vec3<f32>(1e-20));
    let ta = -o / d;
    let tb = (P.volume - o) / d;
    let t_enter = max(max(max(min(ta.x, tb.x), min(ta.y, tb.y)), min(ta.z, tb.z)), 0.0);
    let t_exit = min(min(max(ta.x, tb.x), max(ta.y, tb.y)), max(ta.z, tb.z));
    var color = vec3<f32>(0.0);
    var trans = 1.0;
    var samples = 0u;
    let all = drawn_channels();
    var t = t_enter + 0.5 * P.step;
    var values: array<f32, MAX_CHANNELS>;
    loop {
        if t >= t_exit || trans < T_MIN {
            break;
        }
        let p = o + t * d;
        for (var c = 0u; c < P.channel_count; c++) {
            values[c] = probe_sample(c, p);
        }
        composite(&color, &trans, mixture(all, &values, P.step), 1.0);
        samples++;
        t += P.step;
    }
    out_color[gid.y * P.width + gid.x] = vec4<f32>(color + trans * P.background, 1.0 - trans);
    atomicAdd(&row_samples[gid.y], samples);
}
