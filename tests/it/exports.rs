//! The SemanticKITTI export against the HDF5 of the same run: the same points, labels,
//! instances, velocities, poses and times, read the way the standard loaders read them, and
//! RangeNet++'s spherical projection putting every point back in its own cell.

use crate::common::{expect_input_error, ok, pedscan};
use std::path::Path;

fn f32s(path: &Path) -> Vec<f32> {
    let b = std::fs::read(path).unwrap();
    assert_eq!(b.len() % 4, 0, "{}", path.display());
    b.chunks(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect()
}

fn u32s(path: &Path) -> Vec<u32> {
    std::fs::read(path).unwrap().chunks(4).map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect()
}

fn numbers(path: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path).unwrap().lines().map(|l| l.split_whitespace().map(|x| x.parse().unwrap()).collect()).collect()
}

/// RangeNet++'s projection (its `laserscan.py`): the cell of a point for `fov_up` /
/// `fov_down` in degrees and an H x W image.
fn rangenet_cell(p: [f32; 3], fov_up: f64, fov_down: f64, h: usize, w: usize) -> (usize, usize) {
    let (x, y, z) = (p[0] as f64, p[1] as f64, p[2] as f64);
    let r = (x * x + y * y + z * z).sqrt();
    let (up, down) = (fov_up.to_radians(), fov_down.to_radians());
    let pitch = (z / r).asin();
    let px = 0.5 * (1.0 - y.atan2(x) / std::f64::consts::PI) * w as f64;
    let py = (1.0 - (pitch + down.abs()) / (up + down.abs())) * h as f64;
    ((py.floor().clamp(0.0, h as f64 - 1.0)) as usize, (px.floor().clamp(0.0, w as f64 - 1.0)) as usize)
}

#[test]
fn the_semantickitti_export_holds_what_the_hdf5_holds() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // A 20 m range limit leaves holes in the hall, which the export must skip.
    std::fs::write(dir.join("s.toml"), "elevation_deg = [10.67, 6.67, 2.67, -1.33, -5.33, -9.33, -13.33, -17.33]\ncolumns = 512\nmax_range_m = 20.0\n").unwrap();
    // Speeds either side of the 0.1 m/s that makes a person moving: both classes occur.
    std::fs::write(dir.join("c.toml"), "[humans]\nspeed_mps = [0.0, 0.2]\n").unwrap();
    let args = ["generate", "--config", "c.toml", "--backend", "raycast", "--sensor", "s.toml", "--sequences", "2", "--frames", "3", "--humans", "3..5", "--formats", "h5,semantickitti", "--out", "o"];
    ok(&pedscan(&args, dir));
    let (mut holes, mut moving, mut people, mut background) = (0, 0, 0, 0);
    for seq in 0..2 {
        let f = hdf5::File::open(dir.join(format!("o/seq_{seq:06}.h5"))).unwrap();
        let range: Vec<f32> = f.dataset("range").unwrap().read_raw().unwrap();
        let xyz: Vec<f32> = f.dataset("xyz").unwrap().read_raw().unwrap();
        let instance: Vec<u16> = f.dataset("instance").unwrap().read_raw().unwrap();
        let velocity: Vec<f32> = f.dataset("velocity").unwrap().read_raw().unwrap();
        let intensity: Vec<f32> = f.dataset("intensity").unwrap().read_raw().unwrap();
        let pose: Vec<f64> = f.dataset("sensor/world_from_sensor").unwrap().read_raw().unwrap();
        let time: Vec<f64> = f.dataset("sensor/time_s").unwrap().read_raw().unwrap();
        let speed: Vec<f32> = f.dataset("humans/velocity_mps").unwrap().read_raw().unwrap();
        let n = speed.len() / 3 / 3;
        let sk = dir.join(format!("o/semantickitti/sequences/{seq:02}"));
        let (beams, frames) = (8 * 512, 3);
        let poses = numbers(&sk.join("poses.txt"));
        let times = numbers(&sk.join("times.txt"));
        assert_eq!((poses.len(), times.len()), (frames, frames));
        for t in 0..frames {
            let name = format!("{t:06}");
            let pts = f32s(&sk.join(format!("velodyne/{name}.bin")));
            let labels = u32s(&sk.join(format!("labels/{name}.label")));
            let vel = f32s(&sk.join(format!("velocity/{name}.bin")));
            let returned: Vec<usize> = (0..beams).filter(|&b| range[t * beams + b] > 0.0).collect();
            holes += beams - returned.len();
            assert_eq!(pts.len(), 4 * returned.len(), "one x y z remission per returned beam");
            assert_eq!((labels.len(), vel.len()), (returned.len(), 3 * returned.len()));
            for (i, &b) in returned.iter().enumerate() {
                let g = t * beams + b;
                for a in 0..3 {
                    assert!((pts[4 * i + a] - xyz[3 * g + a]).abs() <= 1e-5 * range[g].max(1.0), "seq {seq} frame {t} beam {b}");
                    assert_eq!(vel[3 * i + a], velocity[3 * g + a]);
                }
                assert_eq!(pts[4 * i + 3], intensity[g], "remission is /intensity");
                let k = instance[g] as usize;
                assert_eq!((labels[i] >> 16) as usize, k);
                let class = labels[i] & 0xffff;
                if k == 0 {
                    assert_eq!(class, 50);
                    background += 1;
                } else {
                    let v = &speed[(t * n + k - 1) * 3..][..2];
                    let walking = (v[0] as f64).hypot(v[1] as f64) > 0.1;
                    assert_eq!(class, if walking { 254 } else { 30 }, "person {k}");
                    people += 1;
                    moving += walking as usize;
                }
            }
            for (a, want) in poses[t].iter().zip(pose[16 * t..16 * t + 12].iter()) {
                assert!((a - want).abs() <= 1e-12 * want.abs().max(1.0));
            }
            assert!((times[t][0] - time[t]).abs() < 1e-12);
        }
        assert!(std::fs::read_to_string(sk.join("calib.txt")).unwrap().contains("Tr: 1 0 0 0 0 1 0 0 0 0 1 0"));
    }
    assert!(holes > 0 && moving > 0 && people > moving, "holes {holes}, person points {people}, moving {moving}");
    let yaml = std::fs::read_to_string(dir.join("o/semantickitti/pedscan.yaml")).unwrap();
    assert!(yaml.contains("254: \"moving-person\"") && yaml.contains("30: \"person\"") && yaml.contains("train: [0, 1]"), "{yaml}");
    // Each class's share of the points of both sequences, as counted above.
    let total = (background + people) as f64;
    for (class, n) in [(30, people - moving), (50, background), (254, moving)] {
        let share = format!("  {class}: {:.9}\n", n as f64 / total);
        assert!(yaml.contains(&share), "{share:?} in\n{yaml}");
    }
    ok(&pedscan(&["verify", "o"], dir));
    expect_input_error(&["generate", "--formats", "h5,las", "--out", "x"], dir, "las");
}

#[test]
fn rangenet_projection_puts_every_hdl32e_point_in_its_own_cell() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    ok(&pedscan(&["generate", "--backend", "raycast", "--frames", "1", "--humans", "4..4", "--formats", "semantickitti", "--out", "o", "--sensor-model", "off"], dir));
    assert!(!dir.join("o/seq_000000.h5").exists(), "only the formats asked for");
    let pts = f32s(&dir.join("o/semantickitti/sequences/00/velodyne/000000.bin"));
    assert_eq!(pts.len(), 4 * 32 * 1024, "the hall returns every beam");
    // The parameters docs/outputs.md gives for the HDL-32E: fov_up 34/3, fov_down -94/3 deg, 32 x 1024.
    for (i, p) in pts.chunks(4).enumerate() {
        let cell = rangenet_cell([p[0], p[1], p[2]], 34.0 / 3.0, -94.0 / 3.0, 32, 1024);
        assert_eq!(cell, (i / 1024, i % 1024), "point {i}");
    }
}

/// A ros2msg schema as ROS 2 defines its messages (`ros2 interface show`): the message's
/// fields, then a section per type it uses (a line of 80 `=`, `MSG: package/Type`, its
/// fields), every type used defined, and the fields of the types pedscan writes as in ROS 2.
fn check_ros2msg_schema(name: &str, text: &str) {
    let separator = "=".repeat(80);
    let mut sections: Vec<(String, Vec<String>)> = vec![(name.replace("/msg/", "/"), Vec::new())];
    for line in text.lines() {
        if line == separator {
            sections.push((String::new(), Vec::new()));
        } else if let Some(t) = line.strip_prefix("MSG: ") {
            let last = sections.last_mut().unwrap();
            assert!(last.0.is_empty() && last.1.is_empty(), "{name}: MSG line {line:?} not after a separator");
            last.0 = t.to_string();
        } else if !line.is_empty() {
            sections.last_mut().unwrap().1.push(line.to_string());
        }
    }
    let defined: std::collections::BTreeMap<&str, &Vec<String>> = sections.iter().map(|(t, f)| (t.as_str(), f)).collect();
    assert_eq!(defined.len(), sections.len(), "{name}: a type defined twice");
    for (t, fields) in &sections {
        assert!(!t.is_empty() && !fields.is_empty(), "{name}: an empty section");
        for f in fields.iter() {
            let ty = f.split_whitespace().next().unwrap().trim_end_matches("[]");
            if ty.contains('/') {
                assert!(defined.contains_key(ty), "{name}: {t} uses {ty}, not defined");
            }
        }
    }
    let want: &[(&str, &[&str])] = &[
        ("std_msgs/Header", &["builtin_interfaces/Time stamp", "string frame_id"]),
        ("builtin_interfaces/Time", &["int32 sec", "uint32 nanosec"]),
        ("tf2_msgs/TFMessage", &["geometry_msgs/TransformStamped[] transforms"]),
        ("geometry_msgs/TransformStamped", &["std_msgs/Header header", "string child_frame_id", "geometry_msgs/Transform transform"]),
        ("geometry_msgs/Transform", &["geometry_msgs/Vector3 translation", "geometry_msgs/Quaternion rotation"]),
        ("geometry_msgs/Vector3", &["float64 x", "float64 y", "float64 z"]),
        ("geometry_msgs/Quaternion", &["float64 x 0", "float64 y 0", "float64 z 0", "float64 w 1"]),
        (
            "sensor_msgs/PointCloud2",
            &["std_msgs/Header header", "uint32 height", "uint32 width", "sensor_msgs/PointField[] fields", "bool is_bigendian", "uint32 point_step", "uint32 row_step", "uint8[] data", "bool is_dense"],
        ),
    ];
    for (t, fields) in want {
        if let Some(got) = defined.get(t) {
            assert_eq!(got.as_slice(), *fields, "{name}: the fields of {t}");
        }
    }
    assert!(defined.contains_key("std_msgs/Header"), "{name}: no header");
}

#[test]
fn the_ros2_bag_is_read_back_by_the_mcap_crate() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    ok(&pedscan(&["generate", "--backend", "raycast", "--frames", "3", "--humans", "2..2", "--formats", "mcap", "--out", "o"], dir));
    assert!(!dir.join("o/seq_000000.h5").exists(), "only the formats asked for");
    let bag = dir.join("o/seq_000000_bag");
    let bytes = std::fs::read(bag.join("seq_000000.mcap")).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary section");
    let stats = summary.stats.as_ref().expect("statistics");
    assert_eq!((stats.message_count, stats.channel_count, stats.schema_count), (6, 2, 2));
    assert!(!summary.chunk_indexes.is_empty(), "chunked, with chunk indexes");
    let mut topics = std::collections::BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let schema = m.channel.schema.as_ref().unwrap();
        assert_eq!((schema.encoding.as_str(), m.channel.message_encoding.as_str()), ("ros2msg", "cdr"));
        check_ros2msg_schema(&schema.name, std::str::from_utf8(&schema.data).unwrap());
        *topics.entry((m.channel.topic.clone(), schema.name.clone())).or_insert(0) += 1;
        // CDR little endian, and for the cloud: 32 x 1024 points of 40 bytes after the header.
        assert_eq!(&m.data[..4], &[0, 1, 0, 0]);
        if m.channel.topic == "/pedscan/points" {
            assert!(m.data.len() > 32 * 1024 * 40);
        }
    }
    let want: std::collections::BTreeMap<_, _> = [
        (("/pedscan/points".to_string(), "sensor_msgs/msg/PointCloud2".to_string()), 3),
        (("/tf".to_string(), "tf2_msgs/msg/TFMessage".to_string()), 3),
    ]
    .into();
    assert_eq!(topics, want);
    let meta = std::fs::read_to_string(bag.join("metadata.yaml")).unwrap();
    assert!(meta.contains("storage_identifier: mcap") && meta.contains("- seq_000000.mcap") && meta.contains("message_count: 6"), "{meta}");
    ok(&pedscan(&["verify", "o"], dir));
}
