//! Compiles every `shaders/*.{vert,frag,comp}` to SPIR-V with shaderc and leaves it in OUT_DIR,
//! where `src/gpu` embeds it with `include_bytes!`. No SPIR-V is committed.
extern crate glslang_link;

use std::path::Path;

fn main() {
    let out_dir = std::env::var("OUT_DIR").expect("OUT_DIR");
    let compiler = shaderc::Compiler::new().expect("shaderc compiler");
    let shader_dir = Path::new("shaders");
    println!("cargo:rerun-if-changed=shaders");
    let mut entries: Vec<_> = std::fs::read_dir(shader_dir)
        .expect("shaders/ directory")
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .collect();
    entries.sort();
    for path in entries {
        println!("cargo:rerun-if-changed={}", path.display());
        let kind = match path.extension().and_then(|e| e.to_str()) {
            Some("vert") => shaderc::ShaderKind::Vertex,
            Some("frag") => shaderc::ShaderKind::Fragment,
            Some("comp") => shaderc::ShaderKind::Compute,
            _ => continue,
        };
        let source = std::fs::read_to_string(&path).expect("read shader");
        let mut options = shaderc::CompileOptions::new().expect("shaderc options");
        options.set_target_env(shaderc::TargetEnv::Vulkan, shaderc::EnvVersion::Vulkan1_1 as u32);
        options.set_optimization_level(shaderc::OptimizationLevel::Performance);
        options.set_include_callback(|name, _ty, _src, _depth| {
            let p = shader_dir.join(name);
            std::fs::read_to_string(&p)
                .map(|content| shaderc::ResolvedInclude {
                    resolved_name: p.display().to_string(),
                    content,
                })
                .map_err(|e| format!("{}: {e}", p.display()))
        });
        let file_name = path.file_name().unwrap().to_string_lossy().to_string();
        let artifact = compiler
            .compile_into_spirv(&source, kind, &file_name, "main", Some(&options))
            .unwrap_or_else(|e| panic!("{file_name}: {e}"));
        std::fs::write(Path::new(&out_dir).join(format!("{file_name}.spv")), artifact.as_binary_u8())
            .expect("write spv");
    }
}
