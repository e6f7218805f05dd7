#![no_main]
//! The `kitti_bin` target: `pedscan_fuzz::kitti_bin` (fuzz/src/lib.rs) says what it reads.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| pedscan_fuzz::kitti_bin(data));
