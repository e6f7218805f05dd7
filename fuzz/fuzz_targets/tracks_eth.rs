#![no_main]
//! ETH/UCY `obsmat.txt`: `pedscan::input::tracks::read_tracks` with `TrackFormat::Eth`, then sampled.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    pedscan_fuzz::tracks(data, pedscan::input::tracks::TrackFormat::Eth);
});
