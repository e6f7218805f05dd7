#![no_main]
//! KITTI `.bin` frames: `pedscan::input::kitti::read_bin`, then projected.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = pedscan_fuzz::input_file("000000.bin", data);
    if let Ok(scan) = pedscan::input::kitti::read_bin(&path) {
        pedscan_fuzz::project(&scan);
    }
});
