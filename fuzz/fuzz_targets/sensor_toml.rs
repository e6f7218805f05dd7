#![no_main]
//! The `sensor_toml` target: `pedscan_fuzz::sensor_toml` (fuzz/src/lib.rs) says what it reads.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| pedscan_fuzz::sensor_toml(data));
