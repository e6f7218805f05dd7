#![no_main]
//! Velodyne captures: `pedscan::input::pcap::read_pcap`, then every rotation projected.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = pedscan_fuzz::input_file("capture.pcap", data);
    if let Ok(rec) = pedscan::input::pcap::read_pcap(&path) {
        for scan in &rec.scans {
            pedscan_fuzz::project(scan);
        }
    }
});
