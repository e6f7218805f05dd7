#![no_main]
//! The sensor TOML: `pedscan::sensor::Sensor::from_name_or_file`, then the projection onto it.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = pedscan_fuzz::input_file("sensor.toml", data);
    if let Ok(sensor) = pedscan::sensor::Sensor::from_name_or_file(path.to_str().unwrap()) {
        let _ = pedscan::input::project::Projector::new(&sensor);
    }
});
