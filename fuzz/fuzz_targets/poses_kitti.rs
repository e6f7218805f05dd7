#![no_main]
//! KITTI pose files (12 values per line): `pedscan::input::poses::read_poses`.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = pedscan_fuzz::input_file("poses.txt", data);
    let _ = pedscan::input::poses::read_poses(&path);
});
