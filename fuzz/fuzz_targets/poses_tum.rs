#![no_main]
//! The `poses_tum` target: `pedscan_fuzz::poses_tum` (fuzz/src/lib.rs) says what it reads.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| pedscan_fuzz::poses_tum(data));
