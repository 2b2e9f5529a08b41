//! Every WGSL source compiles and validates with naga (the compiler wgpu itself uses), with
//! no adapter needed: a shader error fails `cargo test`, not a user's run.

#[test]
fn every_shader_parses_and_validates() {
    assert!(!lucent_gpu::shaders::ALL.is_empty());
    for (name, source) in lucent_gpu::shaders::ALL {
        let module = naga::front::wgsl::parse_str(source)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(source)));
        // The f64 kernels are compiled only on devices with SHADER_F64.
        let capabilities = if name.ends_with("_f64.wgsl") {
            naga::valid::Capabilities::FLOAT64
        } else {
            naga::valid::Capabilities::empty()
        };
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), capabilities)
            .validate(&module)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(source)));
    }
}

#[test]
fn every_file_in_the_shaders_folder_is_compiled_in() {
    let folder = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shaders");
    for entry in std::fs::read_dir(folder).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        if name.ends_with(".wgsl") {
            assert!(
                lucent_gpu::shaders::ALL
                    .iter()
                    .any(|(n, _)| n.split(" + ").any(|part| part == name)),
                "{name} is in shaders/ but not in lucent_gpu::shaders::ALL"
            );
        }
    }
}
