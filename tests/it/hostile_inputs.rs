//! Hostile inputs (glitched poses, lying headers, links to nothing, byte-order marks, absurd
//! transforms and durations): each run of the real binary is refused with exit code 2 and a
//! message naming the input (file and line where there is one), within a 1 GiB data segment
//! (a cap on the child, the same on every machine; no clock), and leaves no file in the
//! output folder. Every input is written by the test itself.

use crate::common::{ok, pedscan, pedscan_bounded, REFUSED_RUN_DATA_BYTES};
use std::path::Path;

/// Runs `pedscan generate --out out <args>` in `dir` (ray caster, one person unless `args`
/// says otherwise) and asserts it is refused as bad input: exit code 2, every one of
/// `needles` in the message, and no output folder. Returns the message.
fn refused(dir: &Path, args: &[&str], needles: &[&str]) -> String {
    let mut all = vec!["generate", "--out", "out", "--backend", "raycast", "--humans", "1"];
    all.extend_from_slice(args);
    let o = pedscan_bounded(&all, dir, REFUSED_RUN_DATA_BYTES);
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert_eq!(o.status.code(), Some(2), "exit code for {args:?}: {err}");
    for n in needles {
        assert!(err.contains(n), "the message for {args:?} should name `{n}`: {err}");
    }
    // The run created the output folder only to fail: it removes it again.
    let out = dir.join("out");
    let left: Vec<_> = std::fs::read_dir(&out).map(|r| r.map(|e| e.unwrap().path()).collect()).unwrap_or_default();
    assert!(!out.exists(), "{args:?} left the output folder, with {left:?}");
    err
}

/// A KITTI pose line (3x4 `[R | t]`, row-major) with the identity rotation and translation `t`.
fn kitti_pose(t: [f64; 3]) -> String {
    format!("1 0 0 {:e} 0 1 0 {:e} 0 0 1 {:e}\n", t[0], t[1], t[2])
}

/// Writes `n` KITTI `.bin` frames into `dir/velodyne`: a flat floor 1.7 m below the sensor,
/// returns every 0.5 m out to 15 m. Returns the bytes of one frame.
fn write_frames(dir: &Path, n: usize) -> Vec<u8> {
    let velo = dir.join("velodyne");
    std::fs::create_dir_all(&velo).unwrap();
    let mut bytes = Vec::new();
    for i in -30..=30 {
        for j in -30..=30 {
            let (x, y) = (i as f32 * 0.5, j as f32 * 0.5);
            if x.hypot(y) >= 2.0 {
                for v in [x, y, -1.7, 0.5] {
                    bytes.extend_from_slice(&v.to_le_bytes());
                }
            }
        }
    }
    for k in 0..n {
        std::fs::write(velo.join(format!("{k:06}.bin")), &bytes).unwrap();
    }
    bytes
}

/// Writes KITTI poses walking 0.1 m per frame along x, one line per translation of `glitch`
/// replacing the pose of its frame.
fn write_poses(path: &Path, n: usize, glitch: Option<(usize, [f64; 3])>) {
    let text: String = (0..n)
        .map(|k| match glitch {
            Some((g, t)) if g == k => kitti_pose(t),
            _ => kitti_pose([0.1 * k as f64, 0.0, 0.0]),
        })
        .collect();
    std::fs::write(path, text).unwrap();
}

#[test]
fn a_pose_far_from_the_origin_is_refused_naming_its_line() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    write_frames(dir, 4);
    for (t, shown) in [([0.3, 1e38, 0.0], "1e38"), ([0.3, 0.0, 4294967296.0], "4294967296"), ([1e6, 0.0, 0.0], "1000000")] {
        write_poses(&dir.join("poses.txt"), 4, Some((2, t)));
        refused(dir, &["--background", "velodyne", "--poses", "poses.txt", "--frames", "4"], &["poses.txt:3", shown, "1e5 m"]);
    }
    // TUM: the same bound on the translation.
    std::fs::write(dir.join("traj.txt"), "0 0 0 0 0 0 0 1\n0.1 0 1e6 0 0 0 0 1\n0.2 0 0 0 0 0 0 1\n0.3 0 0 0 0 0 0 1\n").unwrap();
    refused(dir, &["--background", "velodyne", "--poses", "traj.txt", "--frames", "4"], &["traj.txt:2", "1e5 m"]);
}

#[test]
fn a_window_too_wide_for_the_walkable_grid_is_refused_naming_it() {
    // A glitch within the coordinate bound: the window's grid would need 5e8 cells.
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    write_frames(dir, 4);
    write_poses(&dir.join("poses.txt"), 4, Some((2, [5e4, 0.0, 0.0])));
    refused(
        dir,
        &["--background", "velodyne", "--poses", "poses.txt", "--frames", "4"],
        &["velodyne (frames 0..4)", "cells, more than the supported 50000000"],
    );
}

#[test]
fn a_track_transform_out_of_range_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let mut csv = String::from("t_s,id,x_m,y_m\n");
    for k in 0..40 {
        csv.push_str(&format!("{},1,{},0\n", k as f64 * 0.1, 150.0 + 0.1 * k as f64));
    }
    std::fs::write(dir.join("tracks.csv"), csv).unwrap();
    let tracks = ["--background", "none", "--tracks", "tracks.csv", "--frames", "4"];
    fn with<'a>(tracks: &[&'a str], tf: &'a str) -> Vec<&'a str> {
        [tracks, &["--tracks-transform", tf]].concat()
    }
    refused(dir, &with(&tracks, "0,0,0,1e308"), &["humans.tracks_transform", "scale 1e308"]);
    refused(dir, &with(&tracks, "1e6,0,0"), &["humans.tracks_transform", "translation"]);
    // In range, but it sends the first record 150 km away: named by its line.
    refused(dir, &with(&tracks, "0,0,0,1000"), &["tracks.csv:2", "150000", "1e5 m"]);
}

/// A binary PCD frame (`x y z` as f32) holding `points`, whose header says `declared` points.
fn pcd_binary(points: &[[f32; 3]], declared: usize) -> Vec<u8> {
    let mut b = format!(
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {declared}\nHEIGHT 1\nPOINTS {declared}\nDATA binary\n"
    )
    .into_bytes();
    for p in points {
        for v in p {
            b.extend_from_slice(&v.to_le_bytes());
        }
    }
    b
}

#[test]
fn a_lying_pcd_header_and_an_unreadable_times_file_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let floor: Vec<[f32; 3]> = (0..400).map(|i| [3.0 + (i % 20) as f32 * 0.5, (i / 20) as f32 * 0.5 - 5.0, -1.7]).collect();
    let pcd = dir.join("pcd");
    std::fs::create_dir(&pcd).unwrap();
    let frames = |second: &[u8]| {
        std::fs::write(pcd.join("000000.pcd"), pcd_binary(&floor, floor.len())).unwrap();
        std::fs::write(pcd.join("000001.pcd"), second).unwrap();
    };
    let args = ["--background", "pcd", "--frames", "2"];
    // POINTS half the records the body holds.
    frames(&pcd_binary(&floor, floor.len() / 2));
    refused(dir, &args, &["000001.pcd", "POINTS 200 x 12-byte records is 2400 bytes of data but 4800 follow"]);
    // A binary header over an ascii body.
    let mut text = pcd_binary(&[], 3);
    text.extend_from_slice(b"1.0 2.0 -1.7\n1.5 2.0 -1.7\n2.0 2.0 -1.7\n");
    frames(&text);
    refused(dir, &args, &["000001.pcd", "DATA ascii?"]);
    // times.txt that is a folder, then a looping link: named, not replaced by 10 Hz.
    frames(&pcd_binary(&floor, floor.len()));
    std::fs::create_dir(pcd.join("times.txt")).unwrap();
    refused(dir, &args, &["times.txt", "is a folder"]);
    std::fs::remove_dir(pcd.join("times.txt")).unwrap();
    std::os::unix::fs::symlink("times.txt", pcd.join("times.txt")).unwrap();
    refused(dir, &args, &["times.txt", "cannot open"]);
}

#[test]
fn paths_that_cannot_be_opened_are_bad_input() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    write_frames(dir, 4);
    refused(dir, &["--background", "nothere.pcap"], &["nothere.pcap: does not exist"]);
    std::os::unix::fs::symlink("loop.pcap", dir.join("loop.pcap")).unwrap();
    refused(dir, &["--background", "loop.pcap"], &["loop.pcap: cannot open"]);
    std::fs::remove_file(dir.join("velodyne/000002.bin")).unwrap();
    std::os::unix::fs::symlink("gone.bin", dir.join("velodyne/000002.bin")).unwrap();
    refused(dir, &["--background", "velodyne", "--frames", "2"], &["000002.bin: is a symbolic link to nothing"]);
    std::fs::remove_file(dir.join("velodyne/000002.bin")).unwrap();
    std::fs::create_dir(dir.join("velodyne/000002.bin")).unwrap();
    refused(dir, &["--background", "velodyne", "--frames", "2"], &["000002.bin: is a folder"]);
    refused(dir, &["--background", "none", "--poses", "none.txt"], &["none.txt: does not exist"]);
}

#[test]
fn a_pcap_record_longer_than_the_file_is_refused_before_it_is_read() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // Classic pcap header (Ethernet), one record header that claims 16,000,000 bytes.
    let mut b = Vec::new();
    for v in [0xA1B2_C3D4u32, 0x0004_0002, 0, 0, 65535, 1] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for v in [1u32, 0, 16_000_000, 16_000_000] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b.extend_from_slice(&[0u8; 100]);
    std::fs::write(dir.join("cut.pcap"), b).unwrap();
    refused(dir, &["--background", "cut.pcap"], &["cut.pcap: packet 1 (byte 24)", "the record says 16000000 bytes but only 100 are left in the file"]);
}

#[test]
fn times_beyond_the_range_name_their_input() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    write_frames(dir, 2);
    // A TUM time in nanoseconds, or just absurd: named by its line, not met as "could place
    // only 0 of 2 people" later.
    std::fs::write(dir.join("traj.txt"), "0 0 0 0 0 0 0 1\n1.8e19 0.1 0 0 0 0 0 1\n").unwrap();
    refused(dir, &["--background", "velodyne", "--poses", "traj.txt", "--frames", "2"], &["traj.txt:2", "1.8e19", "1e10 s"]);
}

#[test]
fn byte_order_marks_are_skipped() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    write_frames(dir, 3);
    let bom = |path: &Path, text: &str| std::fs::write(path, format!("\u{feff}{text}")).unwrap();
    let poses: String = (0..3).map(|k| kitti_pose([0.1 * k as f64, 0.0, 0.0])).collect();
    bom(&dir.join("poses.txt"), &poses);
    bom(&dir.join("times.txt"), "0.0\n0.1\n0.2\n");
    ok(&pedscan(
        &["generate", "--out", "out", "--backend", "raycast", "--humans", "0", "--background", "velodyne", "--poses", "poses.txt", "--frames", "2"],
        dir,
    ));
}

/// A config echoing a huge value (a 1 MB string where `frames` takes a number) is refused with
/// a message of a few kilobytes that still names the file, the key and the reason, exit 2,
/// and nothing written.
#[test]
fn a_huge_value_is_named_in_a_clipped_message() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    std::fs::write(dir.join("huge.toml"), format!("frames = \"{}\"\n", "a".repeat(1 << 20))).unwrap();
    let o = pedscan(&["generate", "--config", "huge.toml", "--out", "o"], dir);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{}", &err[..err.len().min(300)]);
    assert!(err.len() < 3 * pedscan::error::MAX_MESSAGE_BYTES && err.contains("bytes left out"), "{} bytes", err.len());
    assert!(err.contains("huge.toml") && err.contains("frames") && err.contains("expected"), "{}", &err[err.len().saturating_sub(600)..]);
    assert!(!dir.join("o").exists());
}
