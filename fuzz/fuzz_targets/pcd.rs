#![no_main]
//! The `pcd` target: `pedscan_fuzz::pcd` (fuzz/src/lib.rs) says what it reads.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| pedscan_fuzz::pcd(data));
