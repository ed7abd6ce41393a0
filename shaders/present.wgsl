// The present pass (`viewer/src/gpu/present.rs`): a full-screen triangle that puts a
// rendered image (linear RGBA `vec4<f32>` per pixel, row-major from the top, composited over
// the background already) on a surface or texture, scaled to it by nearest neighbour, with the
// 8-bit sRGB encoding of the CPU path (`interactive::overlay::SrgbTable`: the same table) and
// the statistics panel over its top-left corner (text in its colour, the rest of the panel
// darkened to a quarter, as `Canvas::panel` does on the CPU) and the orientation strip along
// its bottom edge (marks in their colour, the image showing through elsewhere, as
// `Canvas::orientation` draws on the CPU).

struct PresentParams {
    // The image's size in pixels.
    image_width: u32,
    image_height: u32,
    // The target's size in pixels.
    target_width: u32,
    target_height: u32,
    // The panel's size in pixels (0 × 0: no panel).
    panel_width: u32,
    panel_height: u32,
    // 1: the target stores what it is given (a `*Unorm` format): write the sRGB codes.
    // 0: the target encodes linear light itself (a `*Srgb` format): write linear light.
    encode: u32,
    // Entries of the sRGB table.
    table_entries: u32,
    // The orientation strip's size in pixels (0 × 0: none), its bottom-left corner at the
    // target's.
    footer_width: u32,
    footer_height: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<uniform> params: PresentParams;
@group(0) @binding(1) var<storage, read> image: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> srgb_table: array<u32>;
@group(0) @binding(3) var panel: texture_2d<u32>;
@group(0) @binding(4) var footer: texture_2d<u32>;

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    // (-1, -1), (3, -1), (-1, 3): one triangle covering the target.
    let x = f32(i32(i & 1u) * 4 - 1);
    let y = f32(i32(i >> 1u) * 4 - 1);
    return vec4<f32>(x, y, 0.0, 1.0);
}

// The table's code of linear value `v`: clamped to [0, 1], NaN as 0, rounded to the nearest
// entry (as `SrgbTable::encode`).
fn code(v: f32) -> u32 {
    let last = params.table_entries - 1u;
    if !(v > 0.0) {
        return srgb_table[0];
    }
    let i = u32(min(v, 1.0) * f32(last) + 0.5);
    return srgb_table[min(i, last)];
}

// The sRGB decoding of an 8-bit code to linear light (a `*Srgb` target encodes it back to
// the same code).
fn decode(c: f32) -> f32 {
    let v = c / 255.0;
    if v <= 0.04045 {
        return v / 12.92;
    }
    return pow((v + 0.055) / 1.055, 2.4);
}

@fragment
fn fs_main(@builtin(position) position: vec4<f32>) -> @location(0) vec4<f32> {
    let p = vec2<u32>(floor(position.xy));
    let sx = min(p.x * params.image_width / max(params.target_width, 1u), params.image_width - 1u);
    let sy = min(p.y * params.image_height / max(params.target_height, 1u), params.image_height - 1u);
    let c = image[sy * params.image_width + sx];
    var rgb = vec3<u32>(code(c.r), code(c.g), code(c.b));
    if p.x < params.panel_width && p.y < params.panel_height {
        let t = textureLoad(panel, p, 0);
        if t.a != 0u {
            rgb = t.rgb;
        } else {
            rgb = rgb >> vec3<u32>(2u);
        }
    }
    let footer_top = params.target_height - min(params.footer_height, params.target_height);
    if p.x < params.footer_width && p.y >= footer_top && params.footer_height != 0u {
        let t = textureLoad(footer, vec2<u32>(p.x, p.y - footer_top), 0);
        if t.a != 0u {
            rgb = t.rgb;
        }
    }
    let codes = vec3<f32>(rgb);
    if params.encode != 0u {
        return vec4<f32>(codes / 255.0, 1.0);
    }
    return vec4<f32>(decode(codes.r), decode(codes.g), decode(codes.b), 1.0);
}
