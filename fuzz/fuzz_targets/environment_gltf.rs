#![no_main]
//! Environments (glTF/GLB): `pedscan::scene::Environment::load`, then its triangles.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = pedscan_fuzz::input_file("environment.glb", data);
    if let Ok(env) = pedscan::scene::Environment::load(&path) {
        let _ = env.triangles().count();
    }
});
