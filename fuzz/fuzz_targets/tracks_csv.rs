#![no_main]
//! The `tracks_csv` target: `pedscan_fuzz::tracks_csv` (fuzz/src/lib.rs) says what it reads.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| pedscan_fuzz::tracks_csv(data));
