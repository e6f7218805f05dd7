#![no_main]
//! The `environment_gltf` target: `pedscan_fuzz::environment_gltf` (fuzz/src/lib.rs) says what it reads.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| pedscan_fuzz::environment_gltf(data));
