//! Every WGSL file in `shaders/` parses and validates with naga, as compiled: `raycast.wgsl`
//! after the prelude of constants that `gpu::contract` generates.

#[test]
fn every_wgsl_file_validates() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shaders");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "wgsl") {
            let mut src = std::fs::read_to_string(&path).unwrap();
            if path.file_name().is_some_and(|n| n == "raycast.wgsl") {
                src = residency_viewer::gpu::contract::wgsl_prelude() + &src;
            }
            let module = naga::front::wgsl::parse_str(&src).unwrap_or_else(|e| {
                panic!(
                    "{}",
                    e.emit_to_string_with_path(&src, &path.display().to_string())
                )
            });
            naga::valid::Validator::new(
                naga::valid::ValidationFlags::all(),
                naga::valid::Capabilities::empty(),
            )
            .validate(&module)
            .unwrap_or_else(|e| {
                panic!(
                    "{}",
                    e.emit_to_string_with_path(&src, &path.display().to_string())
                )
            });
            checked += 1;
        }
    }
    assert!(checked >= 1, "no WGSL files in {}", dir.display());
}
