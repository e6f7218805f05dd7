//! A recording's own people, not scored: under a recorded background, the returns that a
//! label file marks (`scene.ignore_labels`) or that the window's other frames see through
//! (`scene.ignore_moving`) get `/label` 255, and a person composited in front of one keeps its
//! label. Every recording is written by the test: a KITTI folder whose points lie on the
//! HDL-32E's beams, so each point's cell is its beam.

use crate::common::{expect_input_error, ok, pedscan};
use glam::{DMat4, DVec3};
use pedscan::sensor::Sensor;
use std::path::Path;

const NOT_SCORED: u8 = 255;
const FRAMES: usize = 6;
const HALF_ROOM_M: f64 = 15.0;
const SENSOR_Z_M: f64 = 1.7;

/// The sensor's world pose at frame k: 0.3 m a frame along x, 1.7 m above the floor.
fn pose(k: usize) -> DMat4 {
    DMat4::from_translation(DVec3::new(0.3 * k as f64 - 2.0, 0.0, SENSOR_Z_M))
}

/// The world box of the thing at frame k: 0.6 x 0.6 x 1.8 m at (3, y), standing (y = -1
/// every frame) or walking (0.6 m a frame along y).
fn thing(k: usize, walks: bool) -> (DVec3, DVec3) {
    let y = if walks { 0.6 * k as f64 - 1.5 } else { -1.0 };
    (DVec3::new(2.7, y - 0.3, 0.0), DVec3::new(3.3, y + 0.3, 1.8))
}

/// Range along the world ray (o, d) to the floor, the room's walls, or the box, and whether
/// the box is what it hits.
fn cast(o: DVec3, d: DVec3, b: (DVec3, DVec3)) -> Option<(f64, bool)> {
    let mut best = f64::INFINITY;
    for (axis, at) in [(0, HALF_ROOM_M), (0, -HALF_ROOM_M), (1, HALF_ROOM_M), (1, -HALF_ROOM_M), (2, 0.0)] {
        let t = (at - o[axis]) / d[axis];
        if t > 0.0 {
            best = best.min(t);
        }
    }
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    for a in 0..3 {
        let (u, v) = ((b.0[a] - o[a]) / d[a], (b.1[a] - o[a]) / d[a]);
        t0 = t0.max(u.min(v));
        t1 = t1.min(u.max(v));
    }
    let on_box = t0 <= t1 && t0 > 0.0 && t0 < best;
    let r = if on_box { t0 } else { best };
    (r < 100.0).then_some((r, on_box))
}

/// Writes `FRAMES` KITTI frames of the room with the box (walking or not), their poses and
/// the SemanticKITTI labels (the box: person 30, instance 1; the rest: building 50); each scan
/// also holds an all-zero record labeled person, which is no point. Returns per frame the
/// beams that see the box and those with a return.
fn write(dir: &Path, walks: bool) -> Vec<(Vec<bool>, Vec<bool>)> {
    let (velo, labels) = (dir.join("velodyne"), dir.join("labels"));
    std::fs::create_dir_all(&velo).unwrap();
    std::fs::create_dir_all(&labels).unwrap();
    let dirs = Sensor::hdl32e().beam_dirs();
    let mut poses = String::new();
    let mut out = Vec::new();
    for k in 0..FRAMES {
        let (mut points, mut classes) = (Vec::new(), Vec::new());
        let (mut on_box, mut returned) = (vec![false; dirs.len()], vec![false; dirs.len()]);
        for (b, d) in dirs.iter().enumerate() {
            if b == 1000 {
                points.extend([0.0f32; 4].iter().flat_map(|v| v.to_le_bytes()));
                classes.extend(((1u32 << 16) | 30).to_le_bytes());
            }
            let Some((r, hit)) = cast(pose(k).w_axis.truncate(), *d, thing(k, walks)) else { continue };
            let p = (*d * r).as_vec3();
            points.extend([p.x, p.y, p.z, 0.5].iter().flat_map(|v| v.to_le_bytes()));
            classes.extend(if hit { (1u32 << 16) | 30 } else { 50 }.to_le_bytes());
            (on_box[b], returned[b]) = (hit, true);
        }
        std::fs::write(velo.join(format!("{k:06}.bin")), points).unwrap();
        std::fs::write(labels.join(format!("{k:06}.label")), classes).unwrap();
        let m = pose(k).transpose().to_cols_array();
        poses.push_str(&m[..12].iter().map(|v| format!("{v:.12e}")).collect::<Vec<_>>().join(" "));
        poses.push('\n');
        out.push((on_box, returned));
    }
    std::fs::write(dir.join("poses.txt"), poses).unwrap();
    out
}

/// `/label`, `/instance`, `/range` and the recorded frame of the sequence's first frame.
fn read(path: &Path) -> (Vec<u8>, Vec<u16>, Vec<f32>, usize) {
    let f = hdf5::File::open(path).unwrap();
    let p: String = f.attr("provenance").unwrap().read_scalar::<hdf5::types::VarLenUnicode>().unwrap().to_string();
    let start = p.lines().find_map(|l| l.strip_prefix("recording_first_frame=")).unwrap().parse().unwrap();
    (f.dataset("label").unwrap().read_raw().unwrap(), f.dataset("instance").unwrap().read_raw().unwrap(), f.dataset("range").unwrap().read_raw().unwrap(), start)
}

fn generate(dir: &Path, config: &str, extra: &[&str]) {
    std::fs::write(dir.join("run.toml"), config).unwrap();
    let mut args = vec!["generate", "--config", "run.toml", "--out", "out", "--background", "velodyne", "--poses", "poses.txt", "--backend", "raycast"];
    args.extend(extra);
    ok(&pedscan(&args, dir));
}

#[test]
fn the_cells_a_label_file_marks_are_not_scored_and_a_person_in_front_keeps_its_label() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let truth = write(dir, false);
    let hw = 32 * 1024;
    // No people: exactly the labeled cells are 255.
    generate(dir, "[scene]\nignore_labels = \"labels\"\n", &["--humans", "0..0", "--sensor-model", "off", "--frames", "4"]);
    let (label, _, _, start) = read(&dir.join("out/seq_000000.h5"));
    for k in 0..4 {
        let (on_box, _) = &truth[start + k];
        assert!(on_box.iter().filter(|&&b| b).count() > 100);
        for b in 0..hw {
            assert_eq!(label[k * hw + b] == NOT_SCORED, on_box[b], "frame {k} beam {b}: label {}", label[k * hw + b]);
        }
    }
    // Only the building's class marks everything but the box.
    std::fs::remove_dir_all(dir.join("out")).unwrap();
    generate(dir, "[scene]\nignore_labels = \"labels\"\nignore_classes = [50]\n", &["--humans", "0..0", "--sensor-model", "off", "--seed", "3", "--frames", "4"]);
    let (label, _, _, start) = read(&dir.join("out/seq_000000.h5"));
    let (on_box, returned) = &truth[start];
    assert!((0..hw).all(|b| (label[b] == NOT_SCORED) == (returned[b] && !on_box[b])));
    // With people and the sensor model: a person in front of a marked return keeps label 1;
    // every 255 is a marked return with no person; the clean labels follow the same rule.
    std::fs::remove_dir_all(dir.join("out")).unwrap();
    generate(dir, "[scene]\nignore_labels = \"labels\"\nignore_classes = [30, 50]\n", &["--humans", "4..4", "--seed", "2", "--frames", "4"]);
    let (label, instance, range, start) = read(&dir.join("out/seq_000000.h5"));
    let f = hdf5::File::open(dir.join("out/seq_000000.h5")).unwrap();
    let clean: Vec<u8> = f.dataset("clean/label").unwrap().read_raw().unwrap();
    let mut people = 0;
    for k in 0..4 {
        let (_, returned) = &truth[start + k];
        for (b, &recorded) in returned.iter().enumerate() {
            let i = k * hw + b;
            match label[i] {
                NOT_SCORED => assert!(recorded && instance[i] == 0 && range[i] > 0.0, "frame {k} beam {b}"),
                1 => people += 1,
                0 => assert!(range[i] == 0.0 || !recorded, "frame {k} beam {b}: a marked return scored as background"),
                l => panic!("label {l}"),
            }
            assert!(clean[i] == 0 || clean[i] == 1 || clean[i] == NOT_SCORED);
        }
    }
    assert!(people > 50, "people in front of marked returns keep label 1: {people} beams");
}

#[test]
fn what_moves_against_the_other_frames_is_not_scored_and_the_still_room_is() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let hw = 32 * 1024;
    for walks in [true, false] {
        let truth = write(dir, walks);
        generate(dir, "[scene]\nignore_moving = true\n", &["--humans", "0..0", "--sensor-model", "off", "--frames", &FRAMES.to_string()]);
        let (label, _, _, start) = read(&dir.join("out/seq_000000.h5"));
        assert_eq!(start, 0);
        for (k, (on_box, _)) in truth.iter().enumerate() {
            let flagged = |b: usize| label[k * hw + b] == NOT_SCORED;
            let (box_beams, box_flagged) = ((0..hw).filter(|&b| on_box[b]).count(), (0..hw).filter(|&b| on_box[b] && flagged(b)).count());
            let others = (0..hw).filter(|&b| !on_box[b] && flagged(b)).count();
            assert_eq!(others, 0, "frame {k}: the still room is not scored at {others} beams");
            if walks {
                // All but the feet, where the floor just behind is within the margin.
                assert!(box_flagged * 10 >= box_beams * 8, "frame {k}: {box_flagged} of {box_beams} beams of the walker");
            } else {
                assert_eq!(box_flagged, 0, "frame {k}: the box that stands still is scored");
            }
        }
        std::fs::remove_dir_all(dir.join("out")).unwrap();
    }
}

#[test]
fn a_missing_or_cut_label_file_is_named_and_nothing_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    write(dir, false);
    let run = |out: &str, needle: &str| {
        std::fs::write(dir.join("run.toml"), "[scene]\nignore_labels = \"labels\"\n").unwrap();
        expect_input_error(&["generate", "--config", "run.toml", "--out", out, "--background", "velodyne", "--frames", "4", "--humans", "0..0"], dir, needle);
        assert!(!dir.join(out).exists(), "{out} was created for a run that failed on its input");
    };
    let cut = dir.join("labels/000003.label");
    let bytes = std::fs::read(&cut).unwrap();
    std::fs::write(&cut, &bytes[..bytes.len() - 4]).unwrap();
    run("o1", "000003.label: ");
    std::fs::remove_file(&cut).unwrap();
    run("o2", &format!("{}: does not exist", Path::new("labels").join("000003.label").display()));
    // Neither key without a recording.
    std::fs::write(dir.join("run.toml"), "[scene]\nignore_moving = true\n").unwrap();
    expect_input_error(&["generate", "--config", "run.toml", "--out", "o3", "--background", "none", "--frames", "1"], dir, "scene.ignore_moving");
    assert!(!dir.join("o3").exists());
}
