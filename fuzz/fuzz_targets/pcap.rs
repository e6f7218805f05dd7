#![no_main]
//! Velodyne captures: `pedscan::input::pcap::read_pcap`, then every rotation projected and
//! its firings turned into column times.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = pedscan_fuzz::input_file("capture.pcap", data);
    if let Ok(rec) = pedscan::input::pcap::read_pcap(&path) {
        for scan in &rec.scans {
            pedscan_fuzz::project(scan);
            if let Some(firings) = &scan.firing_times {
                if let Ok(times) = pedscan::input::sweep::boundary_times(firings, 1024) {
                    assert!(times.windows(2).all(|w| w[1] > w[0]), "column times increase strictly");
                }
            }
        }
    }
});
