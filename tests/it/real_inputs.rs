//! End to end with the inputs users have: a recorded background (a folder of KITTI `.bin`
//! frames with KITTI poses and `times.txt`), recorded pedestrian tracks, and their broken
//! variants. Every input is written by the test itself.

use crate::common::{expect_input_error, ok, pedscan};
use glam::{DMat4, DVec3};
use pedscan::sensor::Sensor;
use std::path::Path;

const RATE_HZ: f64 = 10.0;
const SPEED: f64 = 1.0;
const YAW_RATE: f64 = 0.2;
const SENSOR_Z: f64 = 1.7;
const HALF_ROOM: f64 = 20.0;

/// The recording sensor's pose at time t: an arc at 1 m/s turning at 0.2 rad/s, 1.7 m above
/// the floor (world z = 0).
fn pose_at(t: f64) -> DMat4 {
    let h = YAW_RATE * t;
    let (x, y) = (SPEED / YAW_RATE * h.sin(), SPEED / YAW_RATE * (1.0 - h.cos()));
    DMat4::from_translation(DVec3::new(x - 3.0, y - 2.0, SENSOR_Z)) * DMat4::from_rotation_z(h)
}

/// Frame k's time in the recording: 10 Hz with a 0-8 ms jitter, as a real capture's clock has,
/// so a reader that replaced `times.txt` by `k / rate_hz` would be off by up to 8 ms.
fn frame_time(k: usize) -> f64 {
    k as f64 / RATE_HZ + 0.004 * (k % 3) as f64
}

fn velocity_at(t: f64) -> DVec3 {
    let h = YAW_RATE * t;
    DVec3::new(SPEED * h.cos(), SPEED * h.sin(), 0.0)
}

/// Range of a world ray in the closed room: the floor z = 0, the walls |x|, |y| = 20 m; the
/// ceiling is open (no return).
fn room_range(o: DVec3, d: DVec3) -> Option<f64> {
    let mut best = f64::INFINITY;
    let mut plane = |num: f64, den: f64| {
        if den.abs() > 1e-12 {
            let t = num / den;
            if t > 0.0 && t < best {
                best = t;
            }
        }
    };
    plane(-o.z, d.z);
    for s in [-1.0, 1.0] {
        plane(s * HALF_ROOM - o.x, d.x);
        plane(s * HALF_ROOM - o.y, d.y);
    }
    (best.is_finite() && best < 100.0).then_some(best)
}

/// Writes `n` KITTI frames of the room seen by the HDL-32E beams, the poses and times.
/// Returns the per-frame ranges on the HDL-32E grid (row-major, 0 = no return).
fn write_recording(dir: &Path, n: usize) -> Vec<Vec<f32>> {
    let velo = dir.join("velodyne");
    std::fs::create_dir_all(&velo).unwrap();
    let sensor = Sensor::hdl32e();
    let dirs = sensor.beam_dirs();
    let mut poses = String::new();
    let mut times = String::new();
    let mut all = Vec::new();
    for k in 0..n {
        let t = frame_time(k);
        let pose = pose_at(t);
        let o = pose.w_axis.truncate();
        let mut bytes = Vec::new();
        let mut ranges = vec![0.0f32; dirs.len()];
        for (b, d) in dirs.iter().enumerate() {
            if let Some(r) = room_range(o, pose.transform_vector3(*d)) {
                let p = (*d * r).as_vec3();
                // The range the target grid will see is |p| of the stored f32 point.
                ranges[b] = p.length();
                for v in [p.x, p.y, p.z, 0.5] {
                    bytes.extend_from_slice(&v.to_le_bytes());
                }
            }
        }
        std::fs::write(velo.join(format!("{k:06}.bin")), bytes).unwrap();
        let m = pose.transpose().to_cols_array(); // rows of the 4x4
        poses.push_str(&m[..12].iter().map(|v| format!("{v:.12e}")).collect::<Vec<_>>().join(" "));
        poses.push('\n');
        times.push_str(&format!("{t:.6e}\n"));
        all.push(ranges);
    }
    std::fs::write(dir.join("poses.txt"), poses).unwrap();
    std::fs::write(dir.join("times.txt"), times).unwrap();
    all
}

fn attr(f: &hdf5::File, key: &str) -> String {
    f.attr(key).unwrap().read_scalar::<hdf5::types::VarLenUnicode>().unwrap().to_string()
}

fn provenance(f: &hdf5::File, key: &str) -> String {
    attr(f, "provenance")
        .lines()
        .find_map(|l| l.strip_prefix(&format!("{key}=")).map(str::to_string))
        .unwrap_or_else(|| panic!("no {key} in provenance"))
}

#[test]
fn people_are_composited_into_a_recorded_kitti_sequence() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let frames_total = 12;
    let recorded = write_recording(dir, frames_total);
    let o = pedscan(
        &[
            "generate", "--out", "out", "--sensor-model", "off", "--background", "velodyne", "--poses", "poses.txt", "--frames", "6", "--humans", "3",
            "--seed", "5", "--backend", "raster",
        ],
        dir,
    );
    ok(&o);
    let f = hdf5::File::open(dir.join("out/seq_000000.h5")).unwrap();
    let start: usize = provenance(&f, "recording_first_frame").parse().unwrap();
    assert!(start + 6 <= frames_total);
    assert_eq!(provenance(&f, "recording"), "12 KITTI .bin frames");
    assert_eq!(provenance(&f, "backend"), "raster");
    let floor: f64 = provenance(&f, "floor_z_m").parse().unwrap();
    assert!(floor.abs() < 1e-3, "estimated floor {floor}");
    let range: Vec<f32> = f.dataset("range").unwrap().read_raw().unwrap();
    let bg: Vec<f32> = f.dataset("background/range").unwrap().read_raw().unwrap();
    let label: Vec<u8> = f.dataset("label").unwrap().read_raw().unwrap();
    let velocity: Vec<f32> = f.dataset("velocity").unwrap().read_raw().unwrap();
    let time: Vec<f64> = f.dataset("sensor/time_s").unwrap().read_raw().unwrap();
    let pose: Vec<f64> = f.dataset("sensor/world_from_sensor").unwrap().read_raw().unwrap();
    let humans: Vec<f64> = f.dataset("humans/position_m").unwrap().read_raw().unwrap();
    let hw = 32 * 1024;
    let mut human_beams = 0;
    for k in 0..6 {
        let t_rec = frame_time(start + k);
        // Frame times are the recording's, from the sequence's first frame.
        let want_t = t_rec - frame_time(start);
        assert!((time[k] - want_t).abs() < 1e-9, "time {} vs {want_t}", time[k]);
        // The sensor's pose is the recorded pose.
        let want = pose_at(t_rec).transpose().to_cols_array();
        for i in 0..16 {
            assert!((pose[k * 16 + i] - want[i]).abs() < 1e-9, "pose {k} [{i}]: {} vs {}", pose[k * 16 + i], want[i]);
        }
        // -R^T V_s from the poses' known velocity: the three-point derivative of the arc is
        // off by O(w^2 dt^2 v) = 4e-4 m/s inside the recording, the one-sided one at its ends by O(w dt v).
        let r = pose_at(t_rec);
        let vs = r.inverse().transform_vector3(velocity_at(t_rec));
        let frame_idx = start + k;
        let tol = if frame_idx == 0 || frame_idx + 1 == frames_total { 2.5e-2 } else { 1e-3 };
        for b in 0..hw {
            let i = k * hw + b;
            // The recorded frame is the background, beam for beam.
            assert!((bg[i] - recorded[start + k][b]).abs() <= 1e-5 * bg[i].max(1.0), "background beam {b} of frame {k}: {} vs {}", bg[i], recorded[start + k][b]);
            if label[i] == 1 {
                human_beams += 1;
                assert!(range[i] < bg[i] || bg[i] == 0.0);
            } else {
                assert_eq!(range[i], bg[i]);
                if range[i] > 0.0 {
                    for c in 0..3 {
                        let v = velocity[3 * i + c] as f64;
                        assert!((v + vs[c]).abs() < tol, "frame {k} beam {b}: background velocity {v} vs {}", -vs[c]);
                    }
                }
            }
        }
    }
    assert!(human_beams > 50, "people are visible in the recorded scene: {human_beams} beams");
    // People stand on the estimated floor, inside the room.
    for p in humans.chunks(3) {
        assert!(p[2].abs() < 1e-3, "person at height {}", p[2]);
        assert!(p[0].abs() < HALF_ROOM - 0.3 && p[1].abs() < HALF_ROOM - 0.3, "person outside the room: {p:?}");
    }
    // The XML names the window.
    let xml = std::fs::read_to_string(dir.join("out/seq_000000.xml")).unwrap();
    assert!(xml.contains(&format!("recording_first_frame=\"{start}\"")), "{xml}");
}

/// Tracks of three people walking straight lines at different speeds (pedscan CSV).
fn write_tracks(path: &Path) {
    let mut s = String::from("# three straight walks\nt_s,id,x_m,y_m\n");
    for (id, (x0, y0, vx, vy)) in [(-6.0, 4.0, 1.2, 0.0), (6.0, -5.0, 0.0, 1.0), (-4.0, -4.0, 0.7, 0.7)].iter().enumerate() {
        for k in 0..=25 {
            let t = k as f64 * 0.4;
            s.push_str(&format!("{t},{},{},{}\n", id + 7, x0 + vx * t, y0 + vy * t));
        }
    }
    std::fs::write(path, s).unwrap();
}

#[test]
fn imported_tracks_are_walked_at_the_frame_times() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    write_tracks(&dir.join("tracks.csv"));
    let o = pedscan(
        &[
            "generate", "--out", "out", "--background", "none", "--tracks", "tracks.csv", "--tracks-format", "csv",
            "--tracks-transform", "1.5,-2,90", "--frames", "8", "--humans", "3", "--seed", "2",
        ],
        dir,
    );
    ok(&o);
    let f = hdf5::File::open(dir.join("out/seq_000000.h5")).unwrap();
    let t0: f64 = provenance(&f, "tracks_window_start_s").parse().unwrap();
    let ids: Vec<i64> = provenance(&f, "track_ids").split(',').map(|s| s.parse().unwrap()).collect();
    assert_eq!(ids.len(), 3, "all three tracks cover the window");
    let pos: Vec<f64> = f.dataset("humans/position_m").unwrap().read_raw().unwrap();
    let vel: Vec<f64> = f.dataset("humans/velocity_mps").unwrap().read_raw::<f32>().unwrap().into_iter().map(f64::from).collect();
    let heading: Vec<f64> = f.dataset("humans/heading_rad").unwrap().read_raw::<f32>().unwrap().into_iter().map(f64::from).collect();
    let time: Vec<f64> = f.dataset("sensor/time_s").unwrap().read_raw().unwrap();
    let lines = [(-6.0, 4.0, 1.2, 0.0), (6.0, -5.0, 0.0, 1.0), (-4.0, -4.0, 0.7, 0.7)];
    for (k, t) in time.iter().enumerate() {
        for (h, id) in ids.iter().enumerate() {
            let (x0, y0, vx, vy) = lines[(*id - 7) as usize];
            let tt = t0 + t;
            // world = (1.5, -2) + R(90 deg) p.
            let (px, py) = (x0 + vx * tt, y0 + vy * tt);
            let want = [1.5 - py, -2.0 + px];
            let i = (k * 3 + h) * 3;
            assert!((pos[i] - want[0]).abs() < 1e-4 && (pos[i + 1] - want[1]).abs() < 1e-4, "frame {k} track {id}: {:?} vs {want:?}", &pos[i..i + 2]);
            let wv = [-vy, vx];
            assert!((vel[i] - wv[0]).abs() < 1e-5 && (vel[i + 1] - wv[1]).abs() < 1e-5, "velocity {:?} vs {wv:?}", &vel[i..i + 2]);
            let dh = pedscan::geometry::wrap_pi(heading[k * 3 + h] - wv[1].atan2(wv[0]));
            assert!(dh.abs() < 1e-5, "heading faces the motion");
        }
    }
}

#[test]
fn broken_recordings_and_tracks_are_named_and_exit_2() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    write_recording(dir, 8);
    // A truncated frame.
    std::fs::create_dir(dir.join("cut")).unwrap();
    for k in 0..8 {
        let mut b = std::fs::read(dir.join(format!("velodyne/{k:06}.bin"))).unwrap();
        if k == 5 {
            b.truncate(b.len() - 3);
        }
        std::fs::write(dir.join(format!("cut/{k:06}.bin")), b).unwrap();
    }
    expect_input_error(&["generate", "--out", "o1", "--background", "cut", "--frames", "4"], dir, "000005.bin");
    // Poses that do not match the frames.
    let poses = std::fs::read_to_string(dir.join("poses.txt")).unwrap();
    std::fs::write(dir.join("short_poses.txt"), poses.lines().take(5).collect::<Vec<_>>().join("\n")).unwrap();
    expect_input_error(&["generate", "--out", "o2", "--background", "velodyne", "--poses", "short_poses.txt", "--frames", "4"], dir, "short_poses.txt");
    // More frames per sequence than recorded.
    expect_input_error(&["generate", "--out", "o3", "--background", "velodyne", "--frames", "9"], dir, "velodyne");
    // A track with a NaN, and one with a duplicate time.
    std::fs::write(dir.join("nan.csv"), "t_s,id,x_m,y_m\n0,1,0,0\n0.4,1,NaN,0\n").unwrap();
    expect_input_error(&["generate", "--out", "o4", "--background", "none", "--tracks", "nan.csv"], dir, "nan.csv:3");
    std::fs::write(dir.join("dup.csv"), "t_s,id,x_m,y_m\n0,1,0,0\n0,1,1,0\n").unwrap();
    expect_input_error(&["generate", "--out", "o5", "--background", "none", "--tracks", "dup.csv"], dir, "dup.csv");
    // Tracks too short for a sequence.
    std::fs::write(dir.join("short.csv"), "t_s,id,x_m,y_m\n0,1,0,0\n0.4,1,0.5,0\n").unwrap();
    expect_input_error(&["generate", "--out", "o6", "--background", "none", "--tracks", "short.csv"], dir, "short.csv");
    // A background that is neither a recording nor an environment.
    std::fs::write(dir.join("scan.txt"), "1 2 3\n").unwrap();
    expect_input_error(&["generate", "--out", "o7", "--background", "scan.txt"], dir, "scan.txt");
    for o in ["o1", "o2", "o3", "o4", "o5", "o6", "o7"] {
        assert!(!dir.join(o).exists(), "{o} was created for a run that failed on its input");
    }
}

#[test]
fn a_window_of_frame_files_is_read_once() {
    // Finding the floor and walkable area reads the window's frames; the frames of the
    // sequence then come from those images, equal to reading the files again.
    let tmp = tempfile::tempdir().unwrap();
    write_recording(tmp.path(), 12);
    let velo = tmp.path().join("velodyne");
    let poses = tmp.path().join("poses.txt");
    let open = || pedscan::input::Recording::open(&velo, Some(&poses), &Sensor::hdl32e()).unwrap();
    let (rec, fresh) = (open(), open());
    let read = |r: &pedscan::input::Recording| r.files_read.load(std::sync::atomic::Ordering::Relaxed);
    pedscan::scene::recorded::walkable(&rec, 3..9, None).unwrap();
    assert_eq!(read(&rec), 6);
    let (mut img, mut expected) = (Vec::new(), Vec::new());
    for k in (3..9).chain([10, 4]) {
        rec.frame_ranges(k, &mut img).unwrap();
        fresh.frame_ranges(k, &mut expected).unwrap();
        assert!(img == expected && img.iter().any(|&r| r > 0.0), "frame {k} differs from the file");
    }
    // Only frame 10, outside the window, was read again.
    assert_eq!(read(&rec), 7, "the window's frames must not be read twice");
    assert_eq!(read(&fresh), 8);
}

/// A ROS 2 bag pedscan writes, read back as a background with no people and no sensor model,
/// gives its frames back on the grid: the same returns at the same beams (ranges to f32
/// rounding of the bag's x y z), the same sensor poses from its `/tf`, the same frame steps
/// and each frame's column times from its points' `time` field.
#[test]
fn a_ros2_bag_pedscan_wrote_is_read_back_as_its_own_background() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    ok(&pedscan(&["generate", "--backend", "raycast", "--frames", "4", "--humans", "2..2", "--seed", "3", "--formats", "h5,mcap", "--out", "a"], dir));
    let o = pedscan(
        &[
            "generate", "--backend", "raycast", "--frames", "4", "--humans", "0..0", "--sensor-model", "off", "--background", "a/seq_000000_bag",
            "--out", "b",
        ],
        dir,
    );
    ok(&o);
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(log.contains("ROS 2 bag (1 MCAP file): 4 clouds on /pedscan/points in frame 'pedscan_sensor' (organized 32 x 1024"), "{log}");
    assert!(log.contains("poses from /tf, 'world' -> 'pedscan_sensor'") && !log.contains("taken as static"), "{log}");
    let a = hdf5::File::open(dir.join("a/seq_000000.h5")).unwrap();
    let b = hdf5::File::open(dir.join("b/seq_000000.h5")).unwrap();
    let read_f32 = |f: &hdf5::File, n: &str| -> Vec<f32> { f.dataset(n).unwrap().read_raw().unwrap() };
    let read_f64 = |f: &hdf5::File, n: &str| -> Vec<f64> { f.dataset(n).unwrap().read_raw().unwrap() };
    let (ra, rb) = (read_f32(&a, "range"), read_f32(&b, "range"));
    assert_eq!(ra.len(), rb.len());
    let returns = ra.iter().filter(|&&r| r > 0.0).count();
    assert!(returns > ra.len() / 2, "{returns} returns");
    for (k, (&x, &y)) in ra.iter().zip(&rb).enumerate() {
        assert!((x == 0.0) == (y == 0.0) && (x - y).abs() <= 2e-6 * x, "beam {k}: {x} written, {y} read back");
    }
    let (pa, pb) = (read_f64(&a, "sensor/world_from_sensor"), read_f64(&b, "sensor/world_from_sensor"));
    assert!(pa.iter().zip(&pb).all(|(x, y)| (x - y).abs() < 1e-9), "poses {pa:?} {pb:?}");
    let (ta, tb) = (read_f64(&a, "sensor/time_s"), read_f64(&b, "sensor/time_s"));
    for k in 1..4 {
        assert!(((ta[k] - ta[0]) - (tb[k] - tb[0])).abs() < 2e-9, "frame {k}: {ta:?} {tb:?}");
    }
    // Each frame's sweep from its points' `time` field (a run with the sensor model off
    // takes every column at the frame's time, so the recording is asked directly): each
    // column's written time lies at the middle of its boundaries.
    let rec = pedscan::input::Recording::open(&dir.join("a/seq_000000_bag"), None, &Sensor::hdl32e()).unwrap();
    let ca = read_f64(&a, "sensor/column_time_s");
    let columns = ca.len() / 4;
    for k in 0..4 {
        let bounds = rec.column_offsets(k).expect("the frame's own sweep");
        let worst = (0..columns).map(|c| (0.5 * (bounds[c] + bounds[c + 1]) - (ca[k * columns + c] - ta[k])).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-6, "frame {k}: column times differ by up to {worst} s");
    }
    // The bag's own grid (`--sensor background`): its 32 rings at their measured elevations,
    // the organized clouds' 1024 columns, 10 Hz; the same returns on the same beams.
    let o = pedscan(
        &[
            "generate", "--backend", "raycast", "--frames", "4", "--humans", "0..0", "--sensor-model", "off", "--background", "a/seq_000000_bag",
            "--sensor", "background", "--out", "c",
        ],
        dir,
    );
    ok(&o);
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(log.contains("sensor: the background's own grid, 32 rows from 10.67 to -30.67 deg, 1024 columns, 10.00 Hz"), "{log}");
    let c = hdf5::File::open(dir.join("c/seq_000000.h5")).unwrap();
    assert_eq!(read_f32(&c, "range"), rb);
    let elevation = read_f32(&c, "sensor/elevation_deg");
    let hdl = Sensor::hdl32e().elevation_deg;
    assert!(elevation.len() == 32 && elevation.iter().zip(&hdl).all(|(&a, b)| (a as f64 - b).abs() < 1e-4), "{elevation:?}");
    expect_input_error(&["generate", "--out", "e0", "--sensor", "background", "--frames", "2"], dir, "does not say the grid it was taken on");
    // What cannot be read from it is named, exits 2 and writes nothing.
    let bag = ["--background", "a/seq_000000_bag", "--frames", "4", "--humans", "0..0"];
    let run = |out: &str, more: &[&str], needle: &str| {
        let mut args = vec!["generate", "--out", out];
        args.extend(bag);
        args.extend(more);
        expect_input_error(&args, dir, needle);
        assert!(!dir.join(out).exists(), "{out} was created for a run that failed on its input");
    };
    run("e1", &["--topic", "/nope"], "has no PointCloud2 topic '/nope' (it has: /pedscan/points)");
    run("e2", &["--world-frame", "map"], "no transform chain from the world frame 'map' to the clouds' frame 'pedscan_sensor'");
    run("e3", &["--poses-topic", "/odom"], "has no nav_msgs/msg/Odometry message on '/odom'");
    let mcap = std::fs::read(dir.join("a/seq_000000_bag/seq_000000.mcap")).unwrap();
    std::fs::write(dir.join("cut.mcap"), &mcap[..mcap.len() / 2]).unwrap();
    expect_input_error(&["generate", "--out", "e4", "--background", "cut.mcap", "--frames", "2"], dir, "cut.mcap");
    // A record claiming 2^62 bytes: refused within a bounded memory.
    let mut lying = mcap[..8].to_vec();
    lying.extend([0x05]);
    lying.extend((1u64 << 62).to_le_bytes());
    lying.extend([0u8; 64]);
    std::fs::write(dir.join("lying.mcap"), &lying).unwrap();
    let o = crate::common::pedscan_bounded(&["generate", "--out", "e5", "--background", "lying.mcap", "--frames", "2"], dir, 1 << 30);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.code() == Some(2) && err.contains("lying.mcap"), "{:?}: {err}", o.status.code());
    assert!(!dir.join("e4").exists() && !dir.join("e5").exists());
}
