#![no_main]
//! TUM trajectories (8 values per line): `pedscan::input::poses::read_poses`, seeded with
//! TUM files (the KITTI target shares the reader with other seeds).
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = pedscan_fuzz::input_file("trajectory.txt", data);
    let _ = pedscan::input::poses::read_poses(&path);
});
