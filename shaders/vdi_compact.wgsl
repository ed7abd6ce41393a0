// Compacting a volumetric depth image on the GPU before it is read back
// (viewer/src/gpu/vdi.rs drives it). The VDI pass (shaders/raycast/vdi.wgsl) leaves, per
// pixel, N_S slots of which only the first `count` are used, then the ray's state: the DVR
// pixel, then (count, γ, marches) as bits and a float. `gather` copies every pixel's two state
// slots into one dense array, which the CPU reads and sums into each pixel's start; `scatter`
// copies each pixel's used slots to its start in one packed array, the only supersegments the
// CPU reads. At 1920×1080 and N_S = 20 that is 32 bytes a pixel plus 16 per supersegment used,
// against 384 bytes a pixel for the whole target.

struct VdiCompactParams {
    pixels: u32, // pixels of the target
    supersegments: u32, // N_S
    stride: u32, // slots per pixel in the target: N_S, then the state
    row: u32, // pixels per row of the dispatch grid (workgroups along x × 256)
}

@group(0) @binding(0) var<uniform> P: VdiCompactParams;
// The VDI pass's target, `stride` slots per pixel.
@group(0) @binding(1) var<storage, read> vdi: array<vec4<f32>>;
// Per pixel: the DVR pixel, then (count bits, γ, marches bits, 0).
@group(0) @binding(2) var<storage, read_write> state: array<vec4<f32>>;
// Per pixel, where its supersegments begin in `packed` (prefix sums of the counts).
@group(0) @binding(3) var<storage, read> starts: array<u32>;
// The used slots, one pixel after the other, as the target holds them.
@group(0) @binding(4) var<storage, read_write> packed: array<vec4<f32>>;

fn pixel_of(gid: vec3<u32>) -> u32 {
    return gid.y * P.row + gid.x;
}

@compute @workgroup_size(256, 1, 1)
fn gather(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = pixel_of(gid);
    if p >= P.pixels {
        return;
    }
    let at = p * P.stride + P.supersegments;
    state[2u * p] = vdi[at];
    state[2u * p + 1u] = vdi[at + 1u];
}

@compute @workgroup_size(256, 1, 1)
fn scatter(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = pixel_of(gid);
    if p >= P.pixels {
        return;
    }
    let base = p * P.stride;
    let count = min(bitcast<u32>(vdi[base + P.supersegments + 1u].x), P.supersegments);
    let start = starts[p];
    for (var s = 0u; s < count; s++) {
        packed[start + s] = vdi[base + s];
    }
}
