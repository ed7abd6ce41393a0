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
// by bins of depth along V_O's forward (planes, so a ray meets each bin's faces once). From a
// cell that no supersegment reaches, the ray crosses the tile's whole run of empty bins ahead of
// it in one step, to the first face of its tile or of that run it meets. The ray stops once
// transmittance falls below 1/255.
//
// Subsampling along the ray (the paper's D_R, Sec. 4.4, for preview rendering; the nearest
// filter only): with V.ray_sampling = D_R < 1, where the grid's next crossing is closer than
// the ray's length over which it crosses 1/D_R lists (columns and rows together, found exactly:
// a projection keeps lines straight), the ray takes one step of that length instead and
// composites it exactly as if it all lay in the list that holds the step's middle, so it reads
// one list in 1/D_R of those it crosses. A ray that stays in its list (the camera of generation) is drawn as
// without it. Unlike the paper's point samples, each step keeps every supersegment boundary
// of its list along the depth it spans.
//
// That is the paper's nearest-list filter: each point takes the list whose cell holds it, so a
// surface that V_O sees edge-on (a cell wall along its rays) is as wide as whole lists, and from
// the side its lists show as stripes. With the linear filter (the pipeline constant LINEAR)
// the VDI is read as a medium whose extinction and emission at a point are the bilinear mix,
// over V_O's image plane, of the four lists whose centres surround the point; each
// supersegment holds its extinction (−ln(1 − α) over its own length) and its colour per
// opacity constant over [front, back]. The ray then walks the grid of list centres (one cell
// more each way, the half lists at the edges) and merges the four lists by depth, so that
// between two consecutive supersegment ends of any of them the medium is homogeneous and
// composited exactly, with the weights of the middle of that part (ends a small fraction of a
// list apart, of the lists that weigh little there, taken as one: END_MERGE). Its skipping
// grid is over tiles of those cells: each mask holds the bins of the lists the tile's cells
// read, its own and the one before its first in x and in y.
//
// Positions are relative to V_O's eye, in world units.

struct VdiView {
    width: u32, // the rays cast: the new image at D_I (preview rendering, Sec. 4.4)
    height: u32,
    lists_x: u32, // the VDI's lists (V_O's pixels)
    lists_y: u32,
    eye: vec3<f32>, // the new camera's eye
    ray_sampling: f32, // D_R: 1 reads every list a ray crosses, less reads one every 1/D_R
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

// The linear filter across lists (a pipeline constant: each filter compiles only its own code).
override LINEAR: bool = false;
// A measure of the work instead of a colour (VdiRenderer::work): each pixel gets (the ray's
// steps through the grid, the steps into a cell its skipping grid could not skip, the
// supersegments read, 1). The same counts on any device, for a device without a GPU's clock.
override COUNT_WORK: bool = false;

const T_MIN: f32 = 0.003921569; // early ray termination: transmittance below 1/255
const MAX_LIST_STEPS: u32 = 65535u; // loop guard per ray
// The linear filter takes an end of one of its four lists as at the turn's start when it lies
// closer past it than this fraction of a list's height at that depth, times one minus the
// list's weight at the turn's start: a supersegment's front as begun there, the back of one
// that has begun as ended there (never both ends of one not yet begun: a thin supersegment is
// shifted, never dropped). Fewer turns (neighbouring lists end at nearly the same depths), and
// a list that weighs all there (a ray along its own list's ray) keeps its ends exactly. Measured on
// lavapipe (the VDI bench's three scenes, 128×128, N_S 20, at 10° and 30°): 10-25 % less time
// than merging every end exactly (0), SSIM against DVR within 0.001 of it.
const END_MERGE: f32 = 0.125;

@group(0) @binding(0) var<uniform> V: VdiView;
// Where each list's supersegments begin in `slots`, lists row-major from the top; one more
// entry than lists (the last is the total), so list i holds starts[i + 1] − starts[i].
@group(0) @binding(1) var<storage, read> starts: array<u32>;
// The lists' supersegments one list after the other, each list's front to back:
// vec4(pack2x16float(r, g), pack2x16float(b, a), front, back).
@group(0) @binding(2) var<storage, read> slots: array<vec4<f32>>;
// Per tile of V.tile × V.tile lists, bit b set where a supersegment of its lists reaches depth
// bin b: [grid_near + b·grid_bin, grid_near + (b + 1)·grid_bin] (VDI_DEPTH_BINS bins); then the
// linear filter's, per tile of cells between list centres: the bins of the lists they read.
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

// Supersegments read by this invocation (COUNT_WORK).
var<private> reads: u32 = 0u;

fn supersegment(i: u32) -> Supersegment {
    reads++;
    let s = slots[i];
    let rg = unpack2x16float(bitcast<u32>(s.x));
    let ba = unpack2x16float(bitcast<u32>(s.y));
    return Supersegment(vec3<f32>(rg, ba.x), ba.y, s.z, s.w);
}

// The cosine of list (x, y)'s ray off V_O's forward: its depth = distance · cos.
fn list_cos(x: i32, y: i32) -> f32 {
    let centre = vec2<f32>(
        (f32(x) + 0.5) / f32(V.lists_x) * 2.0 - 1.0,
        1.0 - (f32(y) + 0.5) / f32(V.lists_y) * 2.0,
    );
    let off = centre * vec2<f32>(V.o_tan_x, V.o_tan_y);
    return inverseSqrt(1.0 + dot(off, off));
}

// How many list edges the ray crosses per unit of length at distance `t` (columns and rows
// together): the derivative of its position in lists (`in_lists` of `ndc_at`).
fn lists_per_length(r: OriginRay, t: f32) -> f32 {
    let p = r.o + t * r.d;
    let z = dot(p, V.o_forward);
    let dz = dot(r.d, V.o_forward);
    let dx = (dot(r.d, V.o_right) * z - dot(p, V.o_right) * dz) / (V.o_tan_x * z * z);
    let dy = (dot(r.d, V.o_up) * z - dot(p, V.o_up) * dz) / (V.o_tan_y * z * z);
    return abs(dx) * 0.5 * f32(V.lists_x) + abs(dy) * 0.5 * f32(V.lists_y);
}

// V_O's normalised device coordinates `m` in lists from the top left: list (x, y) spans
// [x, x + 1] × [y, y + 1].
fn in_lists(m: vec2<f32>) -> vec2<f32> {
    return vec2<f32>((m.x + 1.0) * 0.5 * f32(V.lists_x), (1.0 - m.y) * 0.5 * f32(V.lists_y));
}

// The mask of the tile that holds the ray's cell (ix, iy): a list, or with the linear filter a
// cell of the grid of centres (its lists ix − 1 and ix, iy − 1 and iy, clamped to the image).
fn tile_mask(ix: i32, iy: i32) -> u32 {
    let tx = u32(min(ix, i32(V.lists_x) - 1)) / V.tile;
    let ty = u32(min(iy, i32(V.lists_y) - 1)) / V.tile;
    let tiles_y = (V.lists_y + V.tile - 1u) / V.tile;
    return tiles[select(0u, V.tiles_x * tiles_y, LINEAR) + ty * V.tiles_x + tx];
}

// The skipping grid's depth bin of depth `z`, clamped to the grid.
fn depth_bin(z: f32) -> i32 {
    return clamp(i32(floor((z - V.grid_near) / V.grid_bin)), 0, i32(VDI_DEPTH_BINS) - 1);
}

// One of the four lists of the linear filter.
struct Corner {
    base: u32,
    count: u32,
    cos_list: f32, // the cosine of its ray off V_O's forward: depth = distance · cos
}

// List (x, y), clamped to the image.
fn corner(x: i32, y: i32) -> Corner {
    let cx = clamp(x, 0, i32(V.lists_x) - 1);
    let cy = clamp(y, 0, i32(V.lists_y) - 1);
    let list = u32(cy) * V.lists_x + u32(cx);
    let base = starts[list];
    return Corner(base, starts[list + 1u] - base, list_cos(cx, cy));
}

// A supersegment as a homogeneous medium, its depth span in the ray's order: [near, far] in
// depth going forward, in minus depth going backward.
struct Medium {
    near: f32,
    far: f32,
    extinction: f32, // per unit of length
    color: vec3<f32>, // colour per opacity
}

// The index in `slots` of corner `c`'s `j`-th supersegment in the ray's order.
fn ordered(c: Corner, j: u32, forward: bool) -> u32 {
    return c.base + select(c.count - 1u - j, j, forward);
}

// Where corner `c`'s `j`-th supersegment in the ray's order ends, in that order.
fn far_end(c: Corner, j: u32, forward: bool) -> f32 {
    reads++;
    let s = slots[ordered(c, j, forward)];
    return select(-s.z, s.w, forward) * c.cos_list;
}

fn medium(c: Corner, j: u32, forward: bool) -> Medium {
    let s = supersegment(ordered(c, j, forward));
    let f = s.front * c.cos_list;
    let b = s.back * c.cos_list;
    let own = max(s.back - s.front, 1e-30);
    let extinction = -log(1.0 - min(s.alpha, 0.999999)) / own;
    let color = select(vec3<f32>(0.0), s.color / s.alpha, s.alpha > 0.0);
    return Medium(select(-b, f, forward), select(-f, b, forward), extinction, color);
}

// The first of corner `c`'s supersegments in the ray's order that ends past `q`.
fn first_past(c: Corner, q: f32, forward: bool) -> u32 {
    var lo = 0u;
    var hi = c.count;
    loop {
        if lo >= hi {
            break;
        }
        let mid = (lo + hi) / 2u;
        if far_end(c, mid, forward) <= q {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return lo;
}

// Where the ray is at distance `t` within cell (ix, iy) of the grid of list centres: 0 at
// the centres of lists ix − 1 and iy − 1, 1 at those of ix and iy.
fn in_cell(r: OriginRay, ix: i32, iy: i32, t: f32) -> vec2<f32> {
    return in_lists(ndc_at(r, t)) + 0.5 - vec2<f32>(f32(ix), f32(iy));
}

// The bilinear weights at `f` (`in_cell`) of the four lists, in the order of
// `composite_linear`'s corners.
fn weights(f: vec2<f32>) -> vec4<f32> {
    let c = clamp(f, vec2<f32>(0.0), vec2<f32>(1.0));
    return vec4<f32>((1.0 - c.x) * (1.0 - c.y), c.x * (1.0 - c.y), (1.0 - c.x) * c.y, c.x * c.y);
}

// A corner's list as the linear filter reads it along the ray: its next supersegment (in the
// ray's order) that ends past the ray's depth, held as a medium. Four of these live in
// separate variables, not an array, so that a GPU keeps them in registers.
struct Reader {
    c: Corner,
    next: u32,
    held: Medium,
}

fn reader(c: Corner, q: f32, forward: bool) -> Reader {
    let next = first_past(c, q, forward);
    var held = Medium(3.0e38, 3.0e38, 0.0, vec3<f32>(0.0));
    if next < c.count {
        held = medium(c, next, forward);
    }
    return Reader(c, next, held);
}

// What a reader's list holds at depth `q` (in the ray's order): the medium there (its
// extinction 0 in a gap), and where that ends. A supersegment that begins less than `merge`
// past `q` is taken as begun at `q`, and one that has begun and ends less than `merge` past `q`
// as ended there (END_MERGE); one not yet begun is never passed. Moves the reader on by at most
// one supersegment (an `if`, not a loop: lanes that loop different numbers of times wait for
// each other): `q` is where the previous turn ended, at the nearest end of the four lists', so
// the supersegment a reader holds ends at or past it, but for rounding (a reader carried from
// the previous cell across a skipped bin of depth); one left behind is passed one supersegment
// a turn, on turns of no length.
fn read_at(rd: ptr<function, Reader>, q: f32, forward: bool, merge: f32) -> Medium {
    let held = (*rd).held;
    if (*rd).next < (*rd).c.count && held.near <= q && held.far <= q + merge {
        (*rd).next++;
        if (*rd).next < (*rd).c.count {
            (*rd).held = medium((*rd).c, (*rd).next, forward);
        }
    }
    if (*rd).next >= (*rd).c.count {
        return Medium(q, 3.0e38, 0.0, vec3<f32>(0.0));
    }
    let s = (*rd).held;
    if s.near <= q + merge {
        return s;
    }
    return Medium(q, s.near, 0.0, vec3<f32>(0.0));
}

// The linear filter over the ray's part [t, t_next] in cell (ix, iy) of the grid of list
// centres (`dz`: the ray's depth per unit of length), composited into `acc` (colour,
// transmittance). The weights are taken in the middle of each homogeneous part: exact for the
// optical depth where they vary linearly along the ray, so that where the ray's parts are cut
// (skipping's bins of depth) changes next to nothing.
//
// `r0` to `r3` read the cell's lists (ix − 1, iy − 1), (ix, iy − 1), (ix − 1, iy) and (ix, iy)
// (clamped to the image); `held` is the cell they read for before: a neighbour's two readers
// shared with this cell go on from where they stopped (the ray's depth only grows in its own
// order), so that a step to the next cell starts two lists instead of four.
fn composite_linear(r: OriginRay, ix: i32, iy: i32, t: f32, t_next: f32, dz: f32,
    acc: ptr<function, vec4<f32>>, held: ptr<function, vec2<i32>>, r0: ptr<function, Reader>,
    r1: ptr<function, Reader>, r2: ptr<function, Reader>, r3: ptr<function, Reader>) {
    let forward = dz >= 0.0;
    let za = depth_at(r, t);
    let zb = depth_at(r, t_next);
    var q = select(-max(za, zb), min(za, zb), forward);
    let q_end = select(-min(za, zb), max(za, zb), forward);
    // A ray (nearly) at right angles to V_O's view keeps its depth.
    let flat = q_end - q <= 1e-6 * abs(q_end);
    let moved = vec2<i32>(ix, iy) - *held;
    if moved.x != 0 || moved.y != 0 {
        // The lists new to this cell: after a step, the column or row on the side it moved
        // to; after a jump (or at the ray's first cell), all four. Each lane reads its two
        // lists at the same place in the code, whichever way it moved (on a GPU lanes that
        // took different branches would each wait for the others' reads).
        let step = abs(moved.x) + abs(moved.y) == 1;
        let along_x = step && moved.x != 0;
        let along_y = step && moved.y != 0;
        let col = select(ix - 1, ix, moved.x > 0);
        let row = select(iy - 1, iy, moved.y > 0);
        // a and b: (col, iy − 1) and (col, iy) after a step along x, (ix − 1, row) and
        // (ix, row) after one along y, (ix − 1, iy − 1) and (ix, iy − 1) after a jump.
        let first_row = select(iy - 1, row, along_y);
        let a_at = select(vec2<i32>(ix - 1, first_row), vec2<i32>(col, iy - 1), along_x);
        let b_at = select(vec2<i32>(ix, first_row), vec2<i32>(col, iy), along_x);
        let a = reader(corner(a_at.x, a_at.y), q, forward);
        let b = reader(corner(b_at.x, b_at.y), q, forward);
        if !step {
            *r0 = a;
            *r1 = b;
            *r2 = reader(corner(ix - 1, iy), q, forward);
            *r3 = reader(corner(ix, iy), q, forward);
        } else if moved.x == 1 {
            *r0 = *r1;
            *r2 = *r3;
            *r1 = a;
            *r3 = b;
        } else if moved.x == -1 {
            *r1 = *r0;
            *r3 = *r2;
            *r0 = a;
            *r2 = b;
        } else if moved.y == 1 {
            *r0 = *r2;
            *r1 = *r3;
            *r2 = a;
            *r3 = b;
        } else {
            *r2 = *r0;
            *r3 = *r1;
            *r0 = a;
            *r1 = b;
        }
    }
    *held = vec2<i32>(ix, iy);
    var color = (*acc).xyz;
    var trans = (*acc).w;
    let q_start = q;
    // END_MERGE's distance per unit of depth: a list's height there, an eighth of it.
    let merge_per_depth = END_MERGE * 2.0 * V.o_tan_y / f32(V.lists_y);
    // Each turn ends where a supersegment begins or ends: at most two a supersegment of each
    // list (N_S ≤ VDI_MAX_SUPERSEGMENTS), and the part's end.
    for (var turn = 0u; turn <= 8u * VDI_MAX_SUPERSEGMENTS; turn++) {
        // Each list's merging distance (END_MERGE), by its weight at the turn's start.
        var start = t;
        if !flat {
            start = t + (q - q_start) / abs(dz);
        }
        // (None at V_O's eye, depth 0, where the weights are 0/0.)
        let merge = select(vec4<f32>(0.0),
            merge_per_depth * abs(q) * (1.0 - weights(in_cell(r, ix, iy, start))),
            q != 0.0);
        let m0 = read_at(r0, q, forward, merge.x);
        let m1 = read_at(r1, q, forward, merge.y);
        let m2 = read_at(r2, q, forward, merge.z);
        let m3 = read_at(r3, q, forward, merge.w);
        // Never behind q: a reader left behind by rounding holds what ended there (read_at).
        let q_next = max(q, min(min(min(m0.far, m1.far), min(m2.far, m3.far)), q_end));
        // The turn's length along the ray, and its middle's distance from t.
        var length = t_next - t;
        var middle = 0.5 * length;
        if !flat {
            length = (q_next - q) / abs(dz);
            middle = (0.5 * (q + q_next) - q_start) / abs(dz);
        }
        let weighted = vec4<f32>(m0.extinction, m1.extinction, m2.extinction, m3.extinction)
            * weights(in_cell(r, ix, iy, t + middle));
        let sigma = weighted.x + weighted.y + weighted.z + weighted.w;
        if sigma > 0.0 && length > 0.0 {
            let emission = weighted.x * m0.color + weighted.y * m1.color + weighted.z * m2.color
                + weighted.w * m3.color;
            let alpha = 1.0 - exp(-sigma * length);
            color += trans * (emission / sigma) * alpha;
            trans *= 1.0 - alpha;
        }
        if flat || q_next >= q_end || trans < T_MIN {
            break;
        }
        q = q_next;
    }
    *acc = vec4<f32>(color, trans);
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
    // COUNT_WORK's counts.
    var steps = 0u;
    var cells = 0u;
    if span.y > span.x {
        let w = i32(V.lists_x);
        let h = i32(V.lists_y);
        // The cells the ray walks: the lists, or with the linear filter the cells between
        // list centres, whose edges lie half a list off the lists' (one more each way).
        let linear = LINEAR;
        let half = select(0.0, 0.5, linear);
        let gw = w + select(0, 1, linear);
        let gh = h + select(0, 1, linear);
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
        let first_cell = vec2<i32>(floor(in_lists(first) + half));
        var ix = clamp(first_cell.x, 0, gw - 1);
        var iy = clamp(first_cell.y, 0, gh - 1);
        var iz = depth_bin(depth_at(r, t));
        var previous = 0u;
        // The linear filter's readers of four lists, and the cell they read for (none yet).
        var readers_of = vec2<i32>(-2, -2);
        var r0: Reader;
        var r1: Reader;
        var r2: Reader;
        var r3: Reader;
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
            // Where the ray leaves the cell's run of empty bins of depth, the bin it enters
            // there (none for a tile without supersegments, or with none ahead in the ray's
            // direction of depth).
            var tz = 3.0e38;
            var bin_ahead = iz;
            if empty_tile {
                let e = i32(V.tile);
                lo_x = ix / e * e;
                hi_x = min(lo_x + e, gw);
                lo_y = iy / e * e;
                hi_y = min(lo_y + e, gh);
                // The tile's bins ahead of this one in the ray's direction of depth.
                let ahead = select(mask & ((1u << u32(iz)) - 1u), (mask >> u32(iz)) >> 1u, step_z > 0);
                if ahead != 0u && abs(dz) > 1e-30 {
                    // The nearest of them: every bin up to it is empty in the whole tile, so
                    // the ray crosses them in one step, to that bin's face.
                    bin_ahead = select(i32(firstLeadingBit(ahead)),
                        iz + 1 + i32(firstTrailingBit(ahead)), step_z > 0);
                    let face = V.grid_near + f32(select(bin_ahead + 1, bin_ahead, step_z > 0)) * V.grid_bin;
                    tz = (face - dot(r.o, V.o_forward)) / dz;
                    if tz <= t {
                        // Already on the face (rounding): into that bin without a step.
                        iz = bin_ahead;
                        continue;
                    }
                }
            }
            let edge_x = select(lo_x, hi_x, step_x > 0);
            let edge_y = select(lo_y, hi_y, step_y > 0);
            let kx = (f32(edge_x) - half) / f32(w) * 2.0 - 1.0;
            let ky = 1.0 - (f32(edge_y) - half) / f32(h) * 2.0;
            var tx = crossing(r, V.o_right, V.o_tan_x, kx);
            var ty = crossing(r, V.o_up, V.o_tan_y, ky);
            // A crossing a rounding error behind t is where the ray is now (it passes through
            // a corner of its cell: both edges at once): crossed with a step of no length, so
            // that neither index is left behind. One further behind lies behind V_O's eye.
            let tie = t - 1e-5 * max(abs(t), 1.0);
            tx = select(3.0e38, max(tx, t), tx > tie);
            ty = select(3.0e38, max(ty, t), ty > tie);
            var t_next = min(min(min(tx, ty), tz), span.y);
            // Subsampling along the ray (D_R): one step of 1/D_R lists' worth, read in the list
            // at its middle, where the grid's next crossing is closer than that.
            var list_at = vec2<i32>(ix, iy);
            var sampled = false;
            if !linear && !empty_tile && V.ray_sampling < 1.0 {
                // The length s over which the ray crosses k = 1/D_R lists' worth: both list
                // coordinates move by (their rate at t)·s·z / (z + dz·s) along a line, so
                // s = k·z / (rate·z − k·dz); none (the rest of the ray) where the ray never
                // crosses that many (forward in depth, towards the vanishing point).
                let k = 1.0 / V.ray_sampling;
                let z = depth_at(r, t);
                let rate_z = lists_per_length(r, t) * z;
                let den = rate_z - k * dz;
                let far = select(3.0e38, t + k * z / den, den > 1e-30 * max(rate_z, 1.0));
                if far > t_next && t_next < span.y {
                    t_next = min(far, span.y);
                    sampled = true;
                    let middle = in_lists(ndc_at(r, 0.5 * (t + t_next)));
                    list_at = clamp(vec2<i32>(floor(middle)), vec2<i32>(0), vec2<i32>(w - 1, h - 1));
                }
            }
            steps++;
            cells += select(0u, 1u, !empty_tile);
            if !empty_tile && linear {
                var acc = vec4<f32>(color, trans);
                composite_linear(r, ix, iy, t, t_next, dz, &acc, &readers_of, &r0, &r1, &r2, &r3);
                color = acc.xyz;
                trans = acc.w;
            } else if !empty_tile {
                let list = u32(list_at.y) * V.lists_x + u32(list_at.x);
                let base = starts[list];
                let count = starts[list + 1u] - base;
                if count > 0u {
                    let cos_list = list_cos(list_at.x, list_at.y);
                    let za = depth_at(r, t);
                    let zb = depth_at(r, t_next);
                    let z_lo = min(za, zb);
                    let z_hi = max(za, zb);
                    let forward = dz >= 0.0;
                    // Start from the previous list's index, then walk to the first
                    // supersegment the ray meets here, in the order it meets them. A list's
                    // supersegments follow each other (each begins at or past where the one
                    // before it ends), so one that reaches past the ray's span here rules its
                    // neighbour on that side out unread: most lists take one or two reads.
                    var j = min(previous, count - 1u);
                    var s = supersegment(base + j);
                    if forward {
                        loop {
                            if j == 0u || s.front * cos_list < z_lo {
                                break;
                            }
                            let before = supersegment(base + j - 1u);
                            if before.back * cos_list < z_lo {
                                break;
                            }
                            j--;
                            s = before;
                        }
                    } else {
                        loop {
                            if j + 1u >= count || s.back * cos_list > z_hi {
                                break;
                            }
                            let after = supersegment(base + j + 1u);
                            if after.front * cos_list > z_hi {
                                break;
                            }
                            j++;
                            s = after;
                        }
                    }
                    // A ray (nearly) at right angles to V_O's view keeps its depth.
                    let flat = z_hi - z_lo <= 1e-6 * z_hi;
                    loop {
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
                        // Done at the end of the list, or past the span's far end.
                        if trans < T_MIN || (forward && (j + 1u >= count || b > z_hi))
                            || (!forward && (j == 0u || f < z_lo)) {
                            break;
                        }
                        if forward {
                            j++;
                        } else {
                            j--;
                        }
                        s = supersegment(base + j);
                    }
                }
            }
            if trans < T_MIN || t_next >= span.y {
                break;
            }
            // A thousandth of the step past its end (after a sampled step).
            let past = t_next + 1e-3 * (t_next - t);
            t = t_next;
            if sampled {
                // On from the list that holds the step's end, found a little past it so that
                // rounding never puts the ray back in a list it has left (inside V_O's
                // frustum, which bounds the span, but for rounding), in its bin of depth.
                let reached = vec2<i32>(floor(in_lists(ndc_at(r, past))));
                ix = clamp(reached.x, 0, w - 1);
                iy = clamp(reached.y, 0, h - 1);
                iz = depth_bin(depth_at(r, t));
                continue;
            }
            // Across a skipped cell the ray moved over several lists: the list it reached,
            // found a little past the face it left by, so that rounding never puts it in a
            // list it has already left.
            var reached = vec2<i32>(ix, iy);
            if empty_tile {
                let at = ndc_at(r, t + 1e-3 * (min(min(tx, ty), span.y) - t));
                reached = clamp(
                    vec2<i32>(floor(in_lists(at) + half)),
                    vec2<i32>(lo_x, lo_y),
                    vec2<i32>(hi_x - 1, hi_y - 1),
                );
            }
            if tz < min(tx, ty) {
                // Into the bin ahead, in the same tile.
                iz = bin_ahead;
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
            if ix < 0 || ix >= gw || iy < 0 || iy >= gh {
                break;
            }
            if skipping {
                // Across a list, or across a tile's empty bins (any number of them, up to the
                // run's far face), the depth moved on by any amount: its bin again.
                iz = depth_bin(depth_at(r, t));
            }
        }
    }
    if COUNT_WORK {
        image[gid.y * V.width + gid.x] = vec4<f32>(f32(steps), f32(cells), f32(reads), 1.0);
        return;
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
