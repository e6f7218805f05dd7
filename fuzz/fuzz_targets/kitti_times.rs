#![no_main]
//! KITTI `times.txt`: `pedscan::input::poses::read_times`.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = pedscan_fuzz::input_file("times.txt", data);
    let _ = pedscan::input::poses::read_times(&path);
});
