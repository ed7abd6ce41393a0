//! Every WGSL file in `shaders/` parses and validates with naga, as compiled
//! (`gpu::contract::sources`: the generated prelude, the shared `transfer.wgsl` and
//! `view.wgsl` where the shader uses them, then the shader), and every file there is part of a
//! compiled source.

use residency_viewer::gpu::contract;

#[test]
fn every_wgsl_file_validates() {
    let sources = contract::sources();
    for (name, src) in &sources {
        let module = naga::front::wgsl::parse_str(src)
            .unwrap_or_else(|e| panic!("{}", e.emit_to_string_with_path(src, name)));
        // Nothing beyond WebGPU: `pack2x16float` (the VDI's half-float colour) is core WGSL,
        // which naga counts as this capability and every WebGPU device has.
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::SHADER_FLOAT16_IN_FLOAT32,
        )
        .validate(&module)
        .unwrap_or_else(|e| panic!("{}", e.emit_to_string_with_path(src, name)));
    }
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shaders");
    let mut files: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("wgsl"))
        })
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    files.sort();
    assert_eq!(
        files,
        [
            "present.wgsl",
            "probe.wgsl",
            "raycast.wgsl",
            "segments.wgsl",
            "transfer.wgsl",
            "vdi_compact.wgsl",
            "vdi_render.wgsl",
            "view.wgsl"
        ]
    );
    let read = |name: &str| std::fs::read_to_string(dir.join(name)).unwrap();
    let (transfer, view) = (read("transfer.wgsl"), read("view.wgsl"));
    for (name, src) in &sources {
        assert!(src.ends_with(&read(name)), "{name}");
    }
    let with = |part: &str| -> Vec<&str> {
        sources
            .iter()
            .filter(|(_, src)| src.contains(part))
            .map(|(name, _)| *name)
            .collect()
    };
    assert_eq!(with(&transfer), ["raycast.wgsl", "probe.wgsl"]);
    assert_eq!(with(&view), ["raycast.wgsl", "segments.wgsl"]);
}

/// Every file in `shaders/raycast/` is one of `contract::RAYCAST_PARTS` (read from disk as
/// the part holds it), and the compiled ray caster holds each part's text.
#[test]
fn every_raycast_part_is_compiled() {
    let shaders = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shaders");
    let parts: Vec<&str> = contract::RAYCAST_PARTS
        .iter()
        .map(|(name, _)| *name)
        .collect();
    let mut files: Vec<String> = std::fs::read_dir(shaders.join("raycast"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    files.sort();
    for file in &files {
        let name = format!("raycast/{file}");
        assert!(
            parts.contains(&name.as_str()),
            "shaders/{name} is not in contract::RAYCAST_PARTS"
        );
    }
    let source = contract::raycast_source();
    for (name, text) in contract::RAYCAST_PARTS {
        assert_eq!(
            std::fs::read_to_string(shaders.join(name)).unwrap(),
            text,
            "{name}"
        );
        assert!(source.contains(text), "raycast_source() lacks {name}");
    }
}
