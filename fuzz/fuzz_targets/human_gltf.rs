#![no_main]
//! Human models (glTF/GLB, skinned, animated): `pedscan::human::HumanModel::load`, then one
//! posed frame of every level of detail.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = pedscan_fuzz::input_file("human.glb", data);
    if let Ok(model) = pedscan::human::HumanModel::load(&path, false) {
        let mut joints = Vec::new();
        model.joint_matrices(0.3, &mut joints);
        let mut out = Vec::new();
        for lod in 0..model.lods.len() {
            model.skin_into(lod, &joints, &glam::Mat4::IDENTITY, &mut out);
        }
    }
});
