#![no_main]
//! PCD frames (ascii, binary, binary_compressed): `pedscan::input::pcd::read_pcd`, then projected.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = pedscan_fuzz::input_file("frame.pcd", data);
    if let Ok(scan) = pedscan::input::pcd::read_pcd(&path) {
        pedscan_fuzz::project(&scan);
    }
});
