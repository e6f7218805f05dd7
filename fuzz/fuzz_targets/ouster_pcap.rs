#![no_main]
//! Ouster captures: the input's first two bytes (u16 LE) give the length of the metadata JSON
//! that follows, the rest is the capture. Metadata that does not parse falls back to a small
//! fixed sensor (RNG19_RFL8_SIG16_NIR16, 8 columns of 4 pixels, 4 columns per packet) so the
//! packet decoder is reached; then every frame is projected and its firings turned into column
//! times, as a recording does.
use libfuzzer_sys::fuzz_target;
use pedscan::input::ouster::{decode, OusterMeta};

const FALLBACK: &str = r#"{"prod_line":"OS-1-16","data_format":{"columns_per_frame":8,"pixels_per_column":4,
"columns_per_packet":4,"column_window":[0,7],"udp_profile_lidar":"RNG19_RFL8_SIG16_NIR16"},
"beam_altitude_angles":[3,1,-1,-3],"beam_azimuth_angles":[1,-1,1,-1],"lidar_origin_to_beam_origin_mm":15.8,
"lidar_to_sensor_transform":[-1,0,0,0,0,-1,0,0,0,0,1,36.18,0,0,0,1]}"#;

fuzz_target!(|data: &[u8]| {
    if data.len() < 2 {
        return;
    }
    let n = (u16::from_le_bytes([data[0], data[1]]) as usize).min(data.len() - 2);
    let (json, capture) = data[2..].split_at(n);
    let meta = std::str::from_utf8(json)
        .ok()
        .and_then(|t| OusterMeta::parse(t, "fuzz.json").ok())
        .unwrap_or_else(|| OusterMeta::parse(FALLBACK, "fallback.json").expect("the fallback metadata parses"));
    let path = pedscan_fuzz::input_file("capture.pcap", capture);
    if let Ok(rec) = decode(&path, meta) {
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
