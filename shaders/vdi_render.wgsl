// Ray casting a volumetric depth image (VDI) from a new viewpoint (Gupta et al., "Efficient
// Raycasting of Volumetric Depth Images", Sec. 4). viewer/src/gpu/contract.rs puts the
// generated prelude before this file; viewer/src/gpu/vdi_render.rs drives it.
//
// A VDI holds, per pixel of the camera that generated it (V_O), a list of supersegments:
// premultiplied colour and opacity between a front and a back distance from V_O's eye along
// the pixel's ray. Seen in V_O's normalised device coordinates (ndc_x, ndc_y) the lists are
// the cells of a regular grid; a ray from the new camera crosses them along a straight line
// (a projection keeps lines straight), so it walks the grid cell by cell (Amanatides and Woo),
// each crossing found exactly where the ray meets the plane of a grid line through V_O's eye.
// In each list it meets the supersegments whose depth span overlaps its own, found by a
// search that starts from the previous list's index (the data are smooth from list to list),
// and composites each with its opacity corrected to the length the ray spends in it.
// Empty-space skipping (the paper's Sec. 4.3) uses a grid over V_O's frustum: tiles of lists
// by bins of depth along V_O's forward (planes, so a ray meets each bin's faces once). A cell
// that no supersegment reaches is crossed in one step, to the first face of its tile or bin
// the ray meets. The ray stops once transmittance falls below 1/255.
//
// Positions are relative to V_O's eye, in world units.

struct VdiView {
    width: u32, // the rays cast: the new image at D_I (preview rendering, Sec. 4.4)
    height: u32,
    lists_x: u32, // the VDI's lists (V_O's pixels)
    lists_y: u32,
    eye: vec3<f32>, // the new camera's eye
    pad0: u32, // padding: lists are indexed by their starts
    forward: vec3<f32>, // the new camera: forward (unit)
    tile: u32, // lists per tile edge of the skipping grid
    right: vec3<f32>, // right · tan(fov/2) · aspect
    tiles_x: u32, // tiles per row of the skipping grid
    up: vec3<f32>, // up · tan(fov/2)
    flags: u32, // VDI_FLAG_SKIPPING
    o_forward: vec3<f32>, // V_O's forward (unit)
    o_tan_x: f32, // V_O's tan(fov/2) · aspect
    o_right: vec3<f32>, // V_O's right (unit)
    o_tan_y: f32, // V_O's tan(fov/2)
    o_up: vec3<f32>, // V_O's up (unit)
    out_width: u32, // the displayed image (the rays' image upsampled when smaller)
    box_min: vec3<f32>, // the volume's box
    out_height: u32,
    box_max: vec3<f32>,
    grid_near: f32, // the skipping grid's nearest depth along V_O's forward
    background: vec3<f32>, // linear RGB
    grid_bin: f32, // depth per bin of the skipping grid
}

const T_MIN: f32 = 0.003921569; // early ray termination: transmittance below 1/255
const MAX_LIST_STEPS: u32 = 65535u; // loop guard per ray

@group(0) @binding(0) var<uniform> V: VdiView;
// Where each list's supersegments begin in `slots`, lists row-major from the top; one more
// entry than lists (the last is the total), so list i holds starts[i + 1] − starts[i].
@group(0) @binding(1) var<storage, read> starts: array<u32>;
// The lists' supersegments one list after the other, each list's front to back:
// vec4(pack2x16float(r, g), pack2x16float(b, a), front, back).
@group(0) @binding(2) var<storage, read> slots: array<vec4<f32>>;
// Per tile of V.tile × V.tile lists, bit b set where a supersegment of its lists reaches depth
// bin b: [grid_near + b·grid_bin, grid_near + (b + 1)·grid_bin] (VDI_DEPTH_BINS bins).
@group(0) @binding(3) var<storage, read> tiles: array<u32>;
@group(0) @binding(4) var<storage, read_write> image: array<vec4<f32>>;
// The displayed image, out_width × out_height, upsampled from `image` (entry `upsample`).
@group(0) @binding(5) var<storage, read_write> display: array<vec4<f32>>;

// The ray in V_O's view: position p(t) = o + t·d relative to V_O's eye; its projection's
// numerators and depth as linear functions of t.
struct OriginRay {
    o: vec3<f32>,
    d: vec3<f32>,
}

fn depth_at(r: OriginRay, t: f32) -> f32 {
    return dot(r.o + t * r.d, V.o_forward);
}

// V_O's normalised device coordinates of p(t) (y up).
fn ndc_at(r: OriginRay, t: f32) -> vec2<f32> {
    let p = r.o + t * r.d;
    let z = dot(p, V.o_forward);
    return vec2<f32>(dot(p, V.o_right) / (V.o_tan_x * z), dot(p, V.o_up) / (V.o_tan_y * z));
}

// Where the ray crosses the plane through V_O's eye of ndc coordinate `k` along `axis` (unit
// vector of V_O: right or up, with its tangent): k·tan·depth = that component.
fn crossing(r: OriginRay, axis: vec3<f32>, tangent: f32, k: f32) -> f32 {
    let n = axis - k * tangent * V.o_forward;
    let denom = dot(r.d, n);
    let t = -dot(r.o, n) / denom;
    return select(3.0e38, t, abs(denom) > 1e-30);
}

// The part [t0, t1] of the ray inside the half-space dot(p, n) >= 0.
fn clip_half(r: OriginRay, n: vec3<f32>, span: vec2<f32>) -> vec2<f32> {
    let a = dot(r.o, n);
    let b = dot(r.d, n);
    if abs(b) < 1e-30 {
        return select(vec2<f32>(1.0, 0.0), span, a >= 0.0);
    }
    let t = -a / b;
    if b > 0.0 {
        return vec2<f32>(max(span.x, t), span.y);
    }
    return vec2<f32>(span.x, min(span.y, t));
}

// The unpacked slot `i`: premultiplied colour and opacity, and [front, back].
struct Supersegment {
    color: vec3<f32>,
    alpha: f32,
    front: f32,
    back: f32,
}

fn supersegment(i: u32) -> Supersegment {
    let s = slots[i];
    let rg = unpack2x16float(bitcast<u32>(s.x));
    let ba = unpack2x16float(bitcast<u32>(s.y));
    return Supersegment(vec3<f32>(rg, ba.x), ba.y, s.z, s.w);
}

fn tile_mask(ix: i32, iy: i32) -> u32 {
    let tx = u32(ix) / V.tile;
    let ty = u32(iy) / V.tile;
    return tiles[ty * V.tiles_x + tx];
}

// The skipping grid's depth bin of depth `z`, clamped to the grid.
fn depth_bin(z: f32) -> i32 {
    return clamp(i32(floor((z - V.grid_near) / V.grid_bin)), 0, i32(VDI_DEPTH_BINS) - 1);
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= V.width || gid.y >= V.height {
        return;
    }
    let ndc_px = vec2<f32>(
        (f32(gid.x) + 0.5) / f32(V.width) * 2.0 - 1.0,
        1.0 - (f32(gid.y) + 0.5) / f32(V.height) * 2.0,
    );
    let r = OriginRay(V.eye, normalize(V.forward + ndc_px.x * V.right + ndc_px.y * V.up));
    // The ray inside the volume's box, in front of the eye.
    let inv = 1.0 / select(r.d, vec3<f32>(1e-30), abs(r.d) < vec3<f32>(1e-30));
    let ta = (V.box_min - r.o) * inv;
    let tb = (V.box_max - r.o) * inv;
    let tmin = min(ta, tb);
    let tmax = max(ta, tb);
    var span = vec2<f32>(max(0.0, max(tmin.x, max(tmin.y, tmin.z))), min(tmax.x, min(tmax.y, tmax.z)));
    // And inside V_O's frustum: |ndc| <= 1 on both axes.
    span = clip_half(r, V.o_forward * V.o_tan_x - V.o_right, span);
    span = clip_half(r, V.o_forward * V.o_tan_x + V.o_right, span);
    span = clip_half(r, V.o_forward * V.o_tan_y - V.o_up, span);
    span = clip_half(r, V.o_forward * V.o_tan_y + V.o_up, span);

    var color = vec3<f32>(0.0);
    var trans = 1.0;
    if span.y > span.x {
        let w = i32(V.lists_x);
        let h = i32(V.lists_y);
        // Which way the ray's ndc move (monotonic along a line: the sign of the derivative
        // of a ratio of linear functions is constant).
        let mid = 0.5 * (span.x + span.y);
        let probe = ndc_at(r, mid + 1e-3 * (span.y - span.x)) - ndc_at(r, mid);
        let step_x = select(-1, 1, probe.x >= 0.0);
        let step_y = select(1, -1, probe.y >= 0.0); // list rows grow downwards
        let dz = dot(r.d, V.o_forward);
        let step_z = select(-1, 1, dz >= 0.0);
        let skipping = (V.flags & VDI_FLAG_SKIPPING) != 0u;
        var t = span.x;
        let first = ndc_at(r, t);
        var ix = clamp(i32(floor((first.x + 1.0) * 0.5 * f32(w))), 0, w - 1);
        var iy = clamp(i32(floor((1.0 - first.y) * 0.5 * f32(h))), 0, h - 1);
        var iz = depth_bin(depth_at(r, t));
        var previous = 0u;
        for (var n = 0u; n < MAX_LIST_STEPS; n++) {
            // The cell the ray crosses next: a list, or (skipping) a cell of the grid that
            // no supersegment reaches: a tile of lists over one bin of depth, or over every
            // bin when the tile holds none.
            var lo_x = ix;
            var hi_x = ix + 1;
            var lo_y = iy;
            var hi_y = iy + 1;
            var mask = 0xffffffffu;
            if skipping {
                mask = tile_mask(ix, iy);
            }
            let empty_tile = (mask & (1u << u32(iz))) == 0u;
            // Where the ray leaves the cell's bin of depth (none for a tile without
            // supersegments, or past the grid's last bin).
            var tz = 3.0e38;
            if empty_tile {
                let e = i32(V.tile);
                lo_x = ix / e * e;
                hi_x = min(lo_x + e, w);
                lo_y = iy / e * e;
                hi_y = min(lo_y + e, h);
                let next_z = iz + step_z;
                if mask != 0u && next_z >= 0 && next_z < i32(VDI_DEPTH_BINS) && abs(dz) > 1e-30 {
                    let face = V.grid_near + f32(select(iz, iz + 1, step_z > 0)) * V.grid_bin;
                    tz = (face - dot(r.o, V.o_forward)) / dz;
                    if tz <= t {
                        // Already on the face (rounding): into the next bin without a step.
                        iz = next_z;
                        continue;
                    }
                }
            }
            let edge_x = select(lo_x, hi_x, step_x > 0);
            let edge_y = select(lo_y, hi_y, step_y > 0);
            let kx = f32(edge_x) / f32(w) * 2.0 - 1.0;
            let ky = 1.0 - f32(edge_y) / f32(h) * 2.0;
            var tx = crossing(r, V.o_right, V.o_tan_x, kx);
            var ty = crossing(r, V.o_up, V.o_tan_y, ky);
            tx = select(3.0e38, tx, tx > t);
            ty = select(3.0e38, ty, ty > t);
            let t_next = min(min(min(tx, ty), tz), span.y);
            if !empty_tile {
                let list = u32(iy) * V.lists_x + u32(ix);
                let base = starts[list];
                let count = starts[list + 1u] - base;
                if count > 0u {
                    // The list's ray: depth = distance · cos, its angle off V_O's forward.
                    let centre = vec2<f32>(
                        (f32(ix) + 0.5) / f32(w) * 2.0 - 1.0,
                        1.0 - (f32(iy) + 0.5) / f32(h) * 2.0,
                    );
                    let off = centre * vec2<f32>(V.o_tan_x, V.o_tan_y);
                    let cos_list = inverseSqrt(1.0 + dot(off, off));
                    let za = depth_at(r, t);
                    let zb = depth_at(r, t_next);
                    let z_lo = min(za, zb);
                    let z_hi = max(za, zb);
                    let forward = dz >= 0.0;
                    // Start from the previous list's index, then walk to the first
                    // supersegment the ray meets here, in the order it meets them.
                    var j = min(previous, count - 1u);
                    if forward {
                        loop {
                            if j == 0u || supersegment(base + j - 1u).back * cos_list < z_lo {
                                break;
                            }
                            j--;
                        }
                    } else {
                        loop {
                            if j + 1u >= count || supersegment(base + j + 1u).front * cos_list > z_hi {
                                break;
                            }
                            j++;
                        }
                    }
                    // A ray (nearly) at right angles to V_O's view keeps its depth.
                    let flat = z_hi - z_lo <= 1e-6 * z_hi;
                    loop {
                        let s = supersegment(base + j);
                        let f = s.front * cos_list;
                        let b = s.back * cos_list;
                        if (forward && f > z_hi) || (!forward && b < z_lo) {
                            break;
                        }
                        // The ray's length inside the supersegment.
                        var inside = t_next - t;
                        if !flat {
                            inside = min(max(min(b, z_hi) - max(f, z_lo), 0.0) / abs(dz), inside);
                        } else if f > z_lo || z_lo > b {
                            inside = 0.0;
                        }
                        if inside > 0.0 && s.alpha > 0.0 {
                            // Opacity corrected to that length against the supersegment's own
                            // along its list's ray; its colour per opacity kept.
                            let own = max(s.back - s.front, 1e-30);
                            let alpha = 1.0 - pow(1.0 - min(s.alpha, 0.999999), inside / own);
                            color += trans * s.color * (alpha / s.alpha);
                            trans *= 1.0 - alpha;
                        }
                        previous = j;
                        if trans < T_MIN {
                            break;
                        }
                        if forward {
                            if j + 1u >= count {
                                break;
                            }
                            j++;
                        } else {
                            if j == 0u {
                                break;
                            }
                            j--;
                        }
                    }
                }
            }
            if trans < T_MIN || t_next >= span.y {
                break;
            }
            t = t_next;
            // Across a skipped cell the ray moved over several lists: the list it reached,
            // found a little past the face it left by, so that rounding never puts it in a
            // list it has already left.
            var reached = vec2<i32>(ix, iy);
            if empty_tile {
                let at = ndc_at(r, t + 1e-3 * (min(min(tx, ty), span.y) - t));
                reached = vec2<i32>(
                    clamp(i32(floor((at.x + 1.0) * 0.5 * f32(w))), lo_x, hi_x - 1),
                    clamp(i32(floor((1.0 - at.y) * 0.5 * f32(h))), lo_y, hi_y - 1),
                );
            }
            if tz < min(tx, ty) {
                // Into the next bin of depth, in the same tile.
                iz += step_z;
                ix = reached.x;
                iy = reached.y;
                continue;
            }
            if tx <= ty {
                ix = select(lo_x - 1, hi_x, step_x > 0);
                iy = reached.y;
            } else {
                iy = select(lo_y - 1, hi_y, step_y > 0);
                ix = reached.x;
            }
            if ix < 0 || ix >= w || iy < 0 || iy >= h {
                break;
            }
            if skipping && (!empty_tile || mask == 0u) {
                // Across a list, or a tile skipped at every depth, the depth moved on by any
                // amount: its bin again.
                iz = depth_bin(depth_at(r, t));
            }
        }
    }
    image[gid.y * V.width + gid.x] = vec4<f32>(color + trans * V.background, 1.0 - trans);
}

// Preview rendering: the image of V.width × V.height rays upsampled to the displayed
// out_width × out_height, bilinearly between the rays' pixel centres (clamped at the edges).
@compute @workgroup_size(8, 8, 1)
fn upsample(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= V.out_width || gid.y >= V.out_height {
        return;
    }
    let scale = vec2<f32>(f32(V.width) / f32(V.out_width), f32(V.height) / f32(V.out_height));
    let at = (vec2<f32>(gid.xy) + 0.5) * scale - 0.5;
    let hi = vec2<f32>(f32(V.width - 1u), f32(V.height - 1u));
    let p = clamp(at, vec2<f32>(0.0), hi);
    let p0 = vec2<u32>(floor(p));
    let p1 = min(p0 + 1u, vec2<u32>(V.width - 1u, V.height - 1u));
    let f = p - floor(p);
    let top = mix(image[p0.y * V.width + p0.x], image[p0.y * V.width + p1.x], f.x);
    let bottom = mix(image[p1.y * V.width + p0.x], image[p1.y * V.width + p1.x], f.x);
    display[gid.y * V.out_width + gid.x] = mix(top, bottom, f.y);
}
