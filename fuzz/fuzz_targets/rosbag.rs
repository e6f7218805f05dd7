#![no_main]
//! The `rosbag` target: `pedscan_fuzz::rosbag` (fuzz/src/lib.rs) says what it reads.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| pedscan_fuzz::rosbag(data));
