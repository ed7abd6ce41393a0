//! The Rust ↔ WGSL contract (`residency_viewer::gpu::contract`): naga's layout of each WGSL
//! struct the renderer shares with the shader equals the Rust twin's, field by field, and the
//! shader binds no more buffers than WebGPU's default limits allow.

use residency_viewer::gpu::contract::{
    self, ChannelEntry, FrameCounters, GpuStruct, LevelEntry, Params, ProbeParams, RayState,
    SceneUniforms, SegmentBox, SegmentRecord, VdiView,
};

fn parse(source: &str) -> naga::Module {
    naga::front::wgsl::parse_str(source)
        .unwrap_or_else(|e| panic!("{}", e.emit_to_string_with_path(source, "raycast.wgsl")))
}

/// `(name, offset, size)` of one struct member.
type Member = (String, usize, usize);

/// The members of WGSL struct `name`, and its size.
fn wgsl_layout(module: &naga::Module, name: &str) -> Option<(Vec<Member>, usize)> {
    let mut layouter = naga::proc::Layouter::default();
    layouter.update(module.to_ctx()).expect("layout");
    let (_, ty) = module
        .types
        .iter()
        .find(|(_, t)| t.name.as_deref() == Some(name))?;
    let naga::TypeInner::Struct { members, span } = &ty.inner else {
        return None;
    };
    let fields = members
        .iter()
        .map(|m| {
            (
                m.name.clone().unwrap_or_default(),
                m.offset as usize,
                layouter[m.ty].size as usize,
            )
        })
        .collect();
    Some((fields, *span as usize))
}

/// Where `T` and its WGSL twin in `module` disagree, one line each.
fn disagreements<T: GpuStruct>(module: &naga::Module) -> Vec<String> {
    let name = T::WGSL_NAME;
    let Some((wgsl, span)) = wgsl_layout(module, name) else {
        return vec![format!("{name}: no such struct in the shader")];
    };
    let rust = T::fields();
    let mut out = Vec::new();
    for (i, &(field, offset, size)) in rust.iter().enumerate() {
        match wgsl.get(i) {
            Some((w, wo, ws)) if w == field && *wo == offset && *ws == size => {}
            Some((w, wo, ws)) => out.push(format!(
                "{name} member {i}: Rust {field} at {offset} ({size} bytes), WGSL {w} at {wo} \
                 ({ws} bytes)"
            )),
            None => out.push(format!("{name}.{field}: not in the shader")),
        }
    }
    for (w, _, _) in wgsl.iter().skip(rust.len()) {
        out.push(format!("{name}.{w}: not in Rust"));
    }
    if span != size_of::<T>() {
        out.push(format!(
            "{name}: {span} bytes in WGSL, {} in Rust",
            size_of::<T>()
        ));
    }
    out
}

fn all_disagreements(module: &naga::Module) -> Vec<String> {
    [
        disagreements::<Params>(module),
        disagreements::<LevelEntry>(module),
        disagreements::<ChannelEntry>(module),
        disagreements::<SceneUniforms>(module),
        disagreements::<FrameCounters>(module),
        disagreements::<RayState>(module),
        disagreements::<SegmentRecord>(module),
    ]
    .concat()
}

#[test]
fn every_shared_struct_matches_its_wgsl_twin() {
    let module = parse(&contract::raycast_source());
    assert_eq!(all_disagreements(&module), Vec::<String>::new());
    let probe = parse(&contract::probe_source());
    assert_eq!(
        [
            disagreements::<ProbeParams>(&probe),
            disagreements::<SceneUniforms>(&probe),
            disagreements::<ChannelEntry>(&probe),
        ]
        .concat(),
        Vec::<String>::new()
    );
    let vdi = parse(&contract::vdi_render_source());
    assert_eq!(disagreements::<VdiView>(&vdi), Vec::<String>::new());
    let compact = parse(&contract::vdi_compact_source());
    assert_eq!(
        disagreements::<contract::VdiCompactParams>(&compact),
        Vec::<String>::new()
    );
    let segments = parse(&contract::segments_source());
    assert_eq!(
        [
            disagreements::<Params>(&segments),
            disagreements::<SegmentBox>(&segments),
            disagreements::<SegmentRecord>(&segments),
        ]
        .concat(),
        Vec::<String>::new()
    );
    // The uniform structs fit the default uniform binding size.
    let limit = wgpu::Limits::default().max_uniform_buffer_binding_size as usize;
    assert!(size_of::<Params>() + size_of::<SceneUniforms>() <= limit);
}

#[test]
fn a_disagreement_fails_the_contract() {
    let source = contract::raycast_source();
    // Two fields swapped in the shader's Params.
    let swapped = source.replacen(
        "    width: u32,\n    height: u32,",
        "    height: u32,\n    width: u32,",
        1,
    );
    assert_ne!(swapped, source);
    assert_eq!(
        disagreements::<Params>(&parse(&swapped)),
        [
            "Params member 0: Rust width at 0 (4 bytes), WGSL height at 0 (4 bytes)",
            "Params member 1: Rust height at 4 (4 bytes), WGSL width at 4 (4 bytes)",
        ]
    );
    // A field the shader lacks.
    let dropped = source.replacen("    pad0: u32,\n    pad1: u32,\n}", "    pad0: u32,\n}", 1);
    assert_ne!(dropped, source);
    assert_eq!(
        disagreements::<RayState>(&parse(&dropped)),
        ["RayState.pad1: not in the shader"]
    );
    // A wider type in the shader moves everything after it.
    let wider = source.replacen("    voxel_edge: f32,", "    voxel_edge: vec2<f32>,", 1);
    let found = disagreements::<LevelEntry>(&parse(&wider));
    assert_eq!(
        found.first().map(String::as_str),
        Some(
            "LevelEntry member 1: Rust voxel_edge at 12 (4 bytes), WGSL voxel_edge at 16 (8 bytes)"
        )
    );
}

#[test]
fn the_shader_binds_within_webgpu_default_limits() {
    let limits = wgpu::Limits::default();
    // The VDI pass writes into the image's binding, so the ray caster binds no more than the
    // image pass.
    for (name, source, expected) in [
        ("raycast.wgsl", contract::raycast_source(), (8, 2, 3)),
        ("vdi_render.wgsl", contract::vdi_render_source(), (5, 1, 0)),
    ] {
        let module = parse(&source);
        let count = |space: fn(&naga::AddressSpace) -> bool| {
            module
                .global_variables
                .iter()
                .filter(|(_, g)| space(&g.space))
                .count() as u32
        };
        let storage = count(|s| matches!(s, naga::AddressSpace::Storage { .. }));
        let uniform = count(|s| matches!(s, naga::AddressSpace::Uniform));
        let textures = module
            .global_variables
            .iter()
            .filter(|(_, g)| matches!(module.types[g.ty].inner, naga::TypeInner::Image { .. }))
            .count() as u32;
        assert_eq!((storage, uniform, textures), expected, "{name}");
        assert!(storage <= limits.max_storage_buffers_per_shader_stage);
        assert!(uniform <= limits.max_uniform_buffers_per_shader_stage);
        assert!(textures <= limits.max_sampled_textures_per_shader_stage);
    }
}

#[test]
fn the_prelude_carries_the_rust_constants() {
    let prelude = contract::wgsl_prelude();
    for line in [
        "const ENTRY_EMPTY: u32 = 1u;",
        "const ENTRY_CLEAR: u32 = 4294967295u;",
        "const MAX_LEVELS: u32 = 16u;",
        "const MAX_CHANNELS: u32 = 16u;",
        "const CLASS_CONSTANT_SHIFT: u32 = 16u;",
        "alias ChannelLevels = vec4<u32>;",
        "const METHOD_RESIDENCY: u32 = 0u;",
        "const METHOD_PAGE_TABLE: u32 = 1u;",
        "const METHOD_OCTREE: u32 = 2u;",
        "const FILTER_TRILINEAR: u32 = 0u;",
        "const FILTER_TRICUBIC: u32 = 1u;",
        "const ATLAS_FLOAT: u32 = 2u;",
        "const FLAG_SUBSTITUTION: u32 = 2u;",
        "const FILTER_HARDWARE: u32 = 1u;",
        "const VDI_STATE_SLOTS: u32 = 4u;",
        "const VDI_FLAG_SKIPPING: u32 = 1u;",
    ] {
        assert!(
            prelude.lines().any(|l| l == line),
            "{line} not in\n{prelude}"
        );
    }
}

#[test]
fn the_present_pass_uniforms_match_their_wgsl_twin() {
    use residency_viewer::gpu::present::PresentParams;
    let source = contract::present_source();
    let module = parse(&source);
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::empty(),
    )
    .validate(&module)
    .unwrap_or_else(|e| panic!("{}", e.emit_to_string_with_path(&source, "present.wgsl")));
    assert_eq!(
        disagreements::<PresentParams>(&module),
        Vec::<String>::new()
    );
    assert_eq!(size_of::<PresentParams>(), 48);
    // Checked the other way too: a twin of another layout disagrees.
    let wrong = source.replace("    encode: u32,\n", "    encode: vec2<u32>,\n");
    assert_ne!(
        disagreements::<PresentParams>(&parse(&wrong)),
        Vec::<String>::new()
    );
}

/// A VDI slot's colour as WGSL's `pack2x16float` lays it out: two half floats a word, the
/// first in the low 16 bits; read back to the same half floats and depths.
#[test]
fn a_vdi_slot_packs_its_half_floats_as_pack2x16float_does() {
    use half::f16;
    let colour = [1.0, 2.0, 0.5, 0.25].map(f16::from_f32);
    let slot = contract::vdi_slot(colour, [3.0, 4.5]);
    assert_eq!(
        slot.map(f32::to_bits),
        [0x4000_3c00, 0x3400_3800, 3.0f32.to_bits(), 4.5f32.to_bits()]
    );
    assert_eq!(contract::vdi_slot_parts(&slot), (colour, [3.0, 4.5]));
}
