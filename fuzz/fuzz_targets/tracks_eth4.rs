#![no_main]
//! Trajectron++ 4-column text: `pedscan::input::tracks::read_tracks` with `TrackFormat::Eth4`, then sampled.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    pedscan_fuzz::tracks(data, pedscan::input::tracks::TrackFormat::Eth4);
});
