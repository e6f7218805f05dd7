#![no_main]
//! The `poses_kitti` target: `pedscan_fuzz::poses_kitti` (fuzz/src/lib.rs) says what it reads.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| pedscan_fuzz::poses_kitti(data));
