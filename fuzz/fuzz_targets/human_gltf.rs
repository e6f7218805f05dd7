#![no_main]
//! The `human_gltf` target: `pedscan_fuzz::human_gltf` (fuzz/src/lib.rs) says what it reads.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| pedscan_fuzz::human_gltf(data));
