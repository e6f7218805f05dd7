//! `pedscan project`: KITTI scans on a sensor's grid by the projection `generate` gives a
//! recorded background. A pedscan output's returns written as `.bin` scans come back to their
//! own beams' cells, whichever order they are stored in; dropped points have no cell; bad
//! scans are named, exit 2, and nothing is written.

use crate::common::{expect_input_error, ok, pedscan};
use std::path::Path;

/// An 8 x 256 grid, quick to render.
const SENSOR: &str = "elevation_deg = [10.0, 6.0, 2.0, -2.0, -6.0, -10.0, -14.0, -18.0]\ncolumns = 256\n";
const ROWS: usize = 8;
const COLS: usize = 256;

fn le_u32(path: &Path) -> Vec<u32> {
    let b = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(b.len() % 4, 0, "{}", path.display());
    b.chunks(4).map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect()
}

fn le_f32(path: &Path) -> Vec<f32> {
    le_u32(path).into_iter().map(f32::from_bits).collect()
}

fn grid(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("grid.json")).unwrap()).unwrap()
}

/// Writes `points` (x y z remission) as a KITTI `.bin`.
fn write_bin(path: &Path, points: &[[f32; 4]]) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, points.iter().flatten().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>()).unwrap();
}

#[test]
fn a_pedscan_outputs_points_written_as_scans_project_back_onto_their_cells() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("s.toml"), SENSOR).unwrap();
    ok(&pedscan(&["generate", "--backend", "raycast", "--sensor", "s.toml", "--frames", "2", "--humans", "2..2", "--out", "o"], dir));
    let f = hdf5::File::open(dir.join("o/seq_000000.h5")).unwrap();
    let range: Vec<f32> = f.dataset("range").unwrap().read_raw().unwrap();
    let xyz: Vec<f32> = f.dataset("xyz").unwrap().read_raw().unwrap();
    let intensity: Vec<f32> = f.dataset("intensity").unwrap().read_raw().unwrap();
    let beams = ROWS * COLS;
    // Each frame's returned beams, twice: row by row from behind, clockwise (the order of
    // pedscan's SemanticKITTI export), and laser by laser, highest first, each one turn
    // counter-clockwise from straight ahead (KITTI's order: its lasers are recovered).
    let ccw_from_ahead: Vec<usize> = (0..COLS).map(|k| (COLS / 2 + COLS - 1 - k) % COLS).collect();
    let orders: [(&str, Vec<usize>); 2] = [
        ("rows", (0..beams).collect()),
        ("lasers", (0..ROWS).flat_map(|r| ccw_from_ahead.iter().map(move |c| r * COLS + c)).collect()),
    ];
    for (name, order) in &orders {
        let mut written = Vec::new();
        for t in 0..2 {
            let returned: Vec<usize> = order.iter().copied().filter(|&b| range[t * beams + b] > 0.0).collect();
            let g = |b: usize| t * beams + b;
            let pts: Vec<[f32; 4]> = returned.iter().map(|&b| [xyz[3 * g(b)], xyz[3 * g(b) + 1], xyz[3 * g(b) + 2], intensity[g(b)]]).collect();
            write_bin(&dir.join(format!("{name}/velodyne/{t:06}.bin")), &pts);
            written.push(returned);
        }
        // Every row returns somewhere in the hall, so the lasers of the second order are all there.
        assert!((0..ROWS).all(|r| written[0].iter().any(|&b| b / COLS == r)));
        let out = format!("{name}-p");
        ok(&pedscan(&["project", name, "--out", &out, "--sensor", "s.toml"], dir));
        let p = dir.join(&out);
        let g = grid(&p);
        let ring_mapped = *name == "lasers";
        assert_eq!((g["sensor"].as_str(), g["rows"].as_u64(), g["cols"].as_u64()), (Some("s"), Some(ROWS as u64), Some(COLS as u64)));
        assert_eq!((g["intensity_units"].as_str(), g["ring_mapped"].as_bool()), (Some("remission"), Some(ring_mapped)));
        for (t, returned) in written.iter().enumerate() {
            let entry = &g["scans"][t];
            let n = returned.len() as u64;
            assert_eq!(entry["file"].as_str(), Some(format!("{t:06}.bin").as_str()));
            assert_eq!([&entry["points"], &entry["kept"], &entry["outside_band"], &entry["replaced"]].map(|v| v.as_u64()), [Some(n), Some(n), Some(0), Some(0)]);
            assert_eq!(entry["ring_mapped"].as_bool(), Some(ring_mapped));
            // Every point on its own beam's cell: the points are the beams' centres, a row gap
            // and half a column from any band's edge, so none may stray.
            let cells = le_u32(&p.join(format!("{t:06}.cell")));
            let want: Vec<u32> = returned.iter().map(|&b| b as u32).collect();
            assert_eq!(cells, want, "{name} frame {t}");
            // The images are the frame: its range (|xyz| of the f32 point) and intensity.
            let (r, i) = (le_f32(&p.join(format!("{t:06}.range"))), le_f32(&p.join(format!("{t:06}.intensity"))));
            assert_eq!((r.len(), i.len()), (beams, beams));
            for b in 0..beams {
                let want = range[t * beams + b];
                assert!((r[b] - want).abs() <= 1e-5 * want.max(1.0), "{name} frame {t} beam {b}: {} vs {want}", r[b]);
                assert_eq!(i[b], if want > 0.0 { intensity[t * beams + b] } else { 0.0 });
            }
        }
    }
}

#[test]
fn dropped_points_have_no_cell_and_a_rerun_replaces_the_output() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let nan = f32::NAN;
    // Ahead 10 m; not finite; the origin; straight up (outside every band); ahead 4 m (nearer:
    // it takes the cell, the first point keeps its cell number).
    write_bin(&dir.join("s/velodyne/000007.bin"), &[[10.0, 0.0, 0.0, 0.25], [nan, 1.0, 1.0, 0.5], [0.0; 4], [0.0, 0.0, 3.0, 0.5], [4.0, 0.0, 0.0, 0.75]]);
    ok(&pedscan(&["project", "s", "--out", "p", "--sensor", "hdl32e"], dir));
    let p = dir.join("p");
    let cells = le_u32(&p.join("000007.cell"));
    let none = 0xFFFF_FFFF;
    assert_eq!(cells[1..4], [none; 3]);
    assert_eq!(cells[0], cells[4]);
    // hdl32e: the row nearest the horizon (-0.0 deg is row 8), the column straight ahead.
    assert_eq!(cells[0] as usize, 8 * 1024 + 512);
    let (r, i) = (le_f32(&p.join("000007.range")), le_f32(&p.join("000007.intensity")));
    assert_eq!((r[cells[0] as usize], i[cells[0] as usize]), (4.0, 0.75));
    assert_eq!(r.iter().filter(|v| **v > 0.0).count(), 1);
    let e = &grid(&p)["scans"][0];
    assert_eq!([&e["points"], &e["kept"], &e["outside_band"], &e["replaced"]].map(|v| v.as_u64()), [Some(5), Some(1), Some(3), Some(1)]);
    // The velodyne folder itself is taken too; a rerun replaces the earlier output whole.
    std::fs::remove_file(dir.join("s/velodyne/000007.bin")).unwrap();
    write_bin(&dir.join("s/velodyne/000008.bin"), &[[0.0, 5.0, 0.0, 0.5]]);
    ok(&pedscan(&["project", "s/velodyne", "--out", "p", "--sensor", "hdl32e"], dir));
    let mut names: Vec<String> = std::fs::read_dir(&p).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    names.sort();
    assert_eq!(names, ["000008.cell", "000008.intensity", "000008.range", "grid.json"]);
}

#[test]
fn bad_scans_are_named_exit_2_and_nothing_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let written = |out: &str| dir.join(out).exists() || dir.join(format!("{out}.tmp")).exists();
    write_bin(&dir.join("s/velodyne/000000.bin"), &[[5.0, 0.0, 0.0, 0.5]]);
    std::fs::write(dir.join("s/velodyne/000001.bin"), [0u8; 17]).unwrap();
    expect_input_error(&["project", "s", "--out", "p", "--sensor", "hdl32e"], dir, "000001.bin: truncated: 17 bytes is not a whole number of 16-byte points");
    assert!(!written("p"));
    std::fs::create_dir_all(dir.join("empty/velodyne")).unwrap();
    std::fs::write(dir.join("empty/velodyne/README"), "no scans").unwrap();
    expect_input_error(&["project", "empty", "--out", "p"], dir, "velodyne: holds no .bin scan");
    expect_input_error(&["project", "missing", "--out", "p"], dir, "missing: does not exist");
    expect_input_error(&["project", "s/velodyne/000000.bin", "--out", "p"], dir, "000000.bin: is not a folder");
    expect_input_error(&["project", "empty", "--out", "p", "--sensor", "nope"], dir, "--sensor nope");
    assert!(!written("p"));
    // An output folder holding anything but an earlier `project` output is left alone.
    std::fs::remove_file(dir.join("s/velodyne/000001.bin")).unwrap();
    std::fs::create_dir(dir.join("mine")).unwrap();
    std::fs::write(dir.join("mine/notes.txt"), "keep").unwrap();
    expect_input_error(&["project", "s", "--out", "mine"], dir, "mine: holds other files");
    assert_eq!(std::fs::read_to_string(dir.join("mine/notes.txt")).unwrap(), "keep");
}
