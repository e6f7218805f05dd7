//! The fuzz targets, one function a reader of user input: pedscan's readers take paths, so each
//! input is written to a file in a folder made once per process, then read back by the real
//! reader. `fuzz_targets/` wraps each function for libFuzzer; the main crate's `cargo test`
//! replays every input kept in `fuzz/corpus/` through the same functions
//! (`tests/it/fuzz_corpus.rs`, which includes this file).
//!
//! A target treats `Err` as the right answer to bad input; only a panic, an abort, a timeout
//! or running out of memory is a finding (libFuzzer reports those).

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use pedscan::input::ouster::{decode, OusterMeta};
use pedscan::input::rosbag::{cdr, read_bag, to_scan, BagOptions};

/// This process's scratch folder under the system temporary folder (`TMPDIR`), made on first
/// use. `tools/fuzz.sh` points `TMPDIR` at a folder it removes after the run.
pub fn scratch_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("pedscan-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("cannot create the fuzzing scratch folder");
        dir
    })
}

/// Writes `data` to `name` in the scratch folder (replacing the last input) and returns the
/// path, for a reader to open.
pub fn input_file(name: &str, data: &[u8]) -> PathBuf {
    let path = scratch_dir().join(name);
    std::fs::write(&path, data).expect("cannot write the fuzz input to the scratch folder");
    path
}

/// Projects a scan onto the HDL-32E grid, as a recording does with every frame it reads.
pub fn project(scan: &pedscan::input::Scan) {
    static PROJECTOR: OnceLock<pedscan::input::project::Projector> = OnceLock::new();
    let projector = PROJECTOR.get_or_init(|| pedscan::input::project::Projector::new(&pedscan::sensor::Sensor::hdl32e()));
    let mut ranges = Vec::new();
    projector.project(scan, &mut ranges);
}

/// Reads a track file in `format` and samples every track that is long enough to be used, at
/// its start, middle and end, as the planner does.
pub fn tracks(data: &[u8], format: pedscan::input::tracks::TrackFormat) {
    use pedscan::input::tracks;
    let path = input_file("tracks.txt", data);
    if let Ok(all) = tracks::read_tracks(&path, format, &tracks::TrackOptions::default()) {
        for t in tracks::drop_short(all, 0.0) {
            let (first, last) = (t.times_s[0], *t.times_s.last().unwrap());
            for s in [first, 0.5 * (first + last), last] {
                let _ = t.sample(s);
            }
        }
    }
}

/// Every target by the name `tools/fuzz.sh` and `fuzz/corpus/` give it.
pub const TARGETS: &[(&str, fn(&[u8]))] = &[
    ("pcap", pcap),
    ("ouster_pcap", ouster_pcap),
    ("rosbag", rosbag),
    ("pcd", pcd),
    ("kitti_bin", kitti_bin),
    ("kitti_times", kitti_times),
    ("poses_kitti", poses_kitti),
    ("poses_tum", poses_tum),
    ("tracks_eth", tracks_eth),
    ("tracks_eth4", tracks_eth4),
    ("tracks_atc", tracks_atc),
    ("tracks_csv", tracks_csv),
    ("config_toml", config_toml),
    ("sensor_toml", sensor_toml),
    ("human_gltf", human_gltf),
    ("environment_gltf", environment_gltf),
];

/// Velodyne captures: `pedscan::input::pcap::read_pcap`, then every rotation projected and
/// its firings turned into column times.
pub fn pcap(data: &[u8]) {
    let path = input_file("capture.pcap", data);
    if let Ok(rec) = pedscan::input::pcap::read_pcap(&path) {
        for scan in &rec.scans {
            project(scan);
            if let Some(firings) = &scan.firing_times {
                if let Ok(times) = pedscan::input::sweep::boundary_times(firings, 1024) {
                    assert!(times.windows(2).all(|w| w[1] > w[0]), "column times increase strictly");
                }
            }
        }
    }
}

const FALLBACK: &str = r#"{"prod_line":"OS-1-16","data_format":{"columns_per_frame":8,"pixels_per_column":4,
"columns_per_packet":4,"column_window":[0,7],"udp_profile_lidar":"RNG19_RFL8_SIG16_NIR16"},
"beam_altitude_angles":[3,1,-1,-3],"beam_azimuth_angles":[1,-1,1,-1],"lidar_origin_to_beam_origin_mm":15.8,
"lidar_to_sensor_transform":[-1,0,0,0,0,-1,0,0,0,0,1,36.18,0,0,0,1]}"#;

/// Ouster captures: the input's first two bytes (u16 LE) give the length of the metadata JSON
/// that follows, the rest is the capture. Metadata that does not parse falls back to a small
/// fixed sensor (RNG19_RFL8_SIG16_NIR16, 8 columns of 4 pixels, 4 columns per packet) so the
/// packet decoder is reached; then every frame is projected and its firings turned into column
/// times, as a recording does.
pub fn ouster_pcap(data: &[u8]) {
    if data.len() < 2 {
        return;
    }
    let n = (u16::from_le_bytes([data[0], data[1]]) as usize).min(data.len() - 2);
    let (json, capture) = data[2..].split_at(n);
    let meta = std::str::from_utf8(json)
        .ok()
        .and_then(|t| OusterMeta::parse(t, "fuzz.json").ok())
        .unwrap_or_else(|| OusterMeta::parse(FALLBACK, "fallback.json").expect("the fallback metadata parses"));
    let path = input_file("capture.pcap", capture);
    if let Ok(rec) = decode(&path, meta) {
        for scan in &rec.scans {
            project(scan);
            if let Some(firings) = &scan.firing_times {
                if let Ok(times) = pedscan::input::sweep::boundary_times(firings, 1024) {
                    assert!(times.windows(2).all(|w| w[1] > w[0]), "column times increase strictly");
                }
            }
        }
    }
}

/// A bag's scan projected, its firings turned into column times.
fn bag_scan(scan: &pedscan::input::Scan) {
    project(scan);
    if let (Some(firings), Some(t0)) = (&scan.firing_times, scan.time_s) {
        let relative: Vec<[f64; 2]> = firings.iter().map(|&[a, t]| [a, t - t0]).collect();
        if let Ok(times) = pedscan::input::sweep::boundary_times(&relative, 1024) {
            assert!(times.windows(2).all(|w| w[1] > w[0]), "column times increase strictly");
        }
    }
}

/// ROS 2 bags: the input's first byte (mod 5) picks what the rest is. 0 and 4: an MCAP file,
/// read as a background is (the only PointCloud2 topic; poses from `/tf`, or with 4 from an
/// `/odom` Odometry topic), every cloud projected and its firings turned into column times.
/// 1, 2, 3: one CDR payload of a PointCloud2 (then its scan), a TFMessage or an Odometry.
pub fn rosbag(data: &[u8]) {
    let Some((&mode, rest)) = data.split_first() else {
        return;
    };
    match mode % 5 {
        0 | 4 => {
            let path = input_file("bag.mcap", rest);
            let odometry = mode % 5 == 4;
            let opts = BagOptions { poses_topic: odometry.then(|| "/odom".to_string()), ..Default::default() };
            if let Ok(bag) = read_bag(&path, &opts, |s, _| {
                bag_scan(s);
                Ok(s.points.len())
            }) {
                assert!(bag.times_s.windows(2).all(|w| w[1] > w[0]), "frame times increase strictly");
                assert_eq!(bag.frames.len(), bag.times_s.len());
                if let Some(p) = &bag.poses {
                    assert_eq!(p.len(), bag.frames.len());
                }
            }
        }
        1 => {
            if let Ok(c) = cdr::Cloud::decode(rest) {
                if let Ok(scan) = to_scan(&c, c.stamp_ns) {
                    bag_scan(&scan);
                }
            }
        }
        2 => {
            let _ = cdr::decode_tf(rest);
        }
        3 => {
            let _ = cdr::decode_odometry(rest);
        }
        _ => unreachable!(),
    }
}

/// PCD frames (ascii, binary, binary_compressed): `pedscan::input::pcd::read_pcd`, then projected.
pub fn pcd(data: &[u8]) {
    let path = input_file("frame.pcd", data);
    if let Ok(scan) = pedscan::input::pcd::read_pcd(&path) {
        project(&scan);
    }
}

/// KITTI `.bin` frames: `pedscan::input::kitti::read_bin`, then projected.
pub fn kitti_bin(data: &[u8]) {
    let path = input_file("000000.bin", data);
    if let Ok(scan) = pedscan::input::kitti::read_bin(&path) {
        project(&scan);
    }
}

/// KITTI `times.txt`: `pedscan::input::poses::read_times`.
pub fn kitti_times(data: &[u8]) {
    let path = input_file("times.txt", data);
    let _ = pedscan::input::poses::read_times(&path);
}

/// KITTI pose files (12 values per line): `pedscan::input::poses::read_poses`.
pub fn poses_kitti(data: &[u8]) {
    let path = input_file("poses.txt", data);
    let _ = pedscan::input::poses::read_poses(&path);
}

/// TUM trajectories (8 values per line): `pedscan::input::poses::read_poses`, seeded with
/// TUM files (the KITTI target shares the reader with other seeds).
pub fn poses_tum(data: &[u8]) {
    let path = input_file("trajectory.txt", data);
    let _ = pedscan::input::poses::read_poses(&path);
}

/// ETH/UCY `obsmat.txt`: `pedscan::input::tracks::read_tracks` with `TrackFormat::Eth`, then sampled.
pub fn tracks_eth(data: &[u8]) {
    tracks(data, pedscan::input::tracks::TrackFormat::Eth);
}

/// Trajectron++ 4-column text: `pedscan::input::tracks::read_tracks` with `TrackFormat::Eth4`, then sampled.
pub fn tracks_eth4(data: &[u8]) {
    tracks(data, pedscan::input::tracks::TrackFormat::Eth4);
}

/// ATC CSV: `pedscan::input::tracks::read_tracks` with `TrackFormat::Atc`, then sampled.
pub fn tracks_atc(data: &[u8]) {
    tracks(data, pedscan::input::tracks::TrackFormat::Atc);
}

/// pedscan track CSV: `pedscan::input::tracks::read_tracks` with `TrackFormat::Csv`, then sampled.
pub fn tracks_csv(data: &[u8]) {
    tracks(data, pedscan::input::tracks::TrackFormat::Csv);
}

/// The config TOML: `pedscan::config::Config::from_file`, then `Config::validate`.
pub fn config_toml(data: &[u8]) {
    let path = input_file("config.toml", data);
    if let Ok(cfg) = pedscan::config::Config::from_file(&path) {
        let _ = cfg.validate();
        let _ = cfg.to_toml();
    }
}

/// The sensor TOML: `pedscan::sensor::Sensor::from_name_or_file`, then the projection onto it.
pub fn sensor_toml(data: &[u8]) {
    let path = input_file("sensor.toml", data);
    if let Ok(sensor) = pedscan::sensor::Sensor::from_name_or_file(path.to_str().unwrap()) {
        let _ = pedscan::input::project::Projector::new(&sensor);
    }
}

/// Human models (glTF/GLB, skinned, animated): `pedscan::human::HumanModel::load`, then one
/// posed frame of every level of detail.
pub fn human_gltf(data: &[u8]) {
    let path = input_file("human.glb", data);
    if let Ok(model) = pedscan::human::HumanModel::load(&path, false) {
        let mut joints = Vec::new();
        model.joint_matrices(0.3, &mut joints);
        let mut out = Vec::new();
        for lod in 0..model.lods.len() {
            model.skin_into(lod, &joints, &glam::Mat4::IDENTITY, &mut out);
        }
    }
}

/// Environments (glTF/GLB): `pedscan::scene::Environment::load`, then its triangles.
pub fn environment_gltf(data: &[u8]) {
    let path = input_file("environment.glb", data);
    if let Ok(env) = pedscan::scene::Environment::load(&path) {
        let _ = env.triangles().count();
    }
}
