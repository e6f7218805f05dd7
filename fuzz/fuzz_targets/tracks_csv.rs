#![no_main]
//! pedscan track CSV: `pedscan::input::tracks::read_tracks` with `TrackFormat::Csv`, then sampled.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    pedscan_fuzz::tracks(data, pedscan::input::tracks::TrackFormat::Csv);
});
