#![no_main]
//! The `tracks_atc` target: `pedscan_fuzz::tracks_atc` (fuzz/src/lib.rs) says what it reads.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| pedscan_fuzz::tracks_atc(data));
