//! Sensor poses of a recording, one per frame: KITTI `poses.txt` and TUM trajectories, plus
//! KITTI `times.txt`.
//!
//! # Which pose
//!
//! Every pose read here is taken to be the **LiDAR's** pose, `world_from_sensor`: it maps a
//! point from the LiDAR frame (x forward, y left, z up) of that frame into a fixed world frame
//! whose z axis points up. Nothing is converted on the way in.
//!
//! The KITTI odometry ground truth `poses.txt` is *not* such a file: it holds the pose of the
//! left camera (camera 0, z forward, y down) in the first camera frame. Convert it first with
//! the calibration `Tr` (velodyne to camera 0, from the sequence's `calib.txt`):
//! `world_from_velo = Tr⁻¹ · cam0_pose · Tr` (what SemanticKITTI does); that world is the first
//! LiDAR frame, z up. Likewise a TUM file of camera (optical frame) poses must be turned into
//! LiDAR poses with the camera-to-LiDAR extrinsics before it is used here.
//!
//! # Formats (detected per file)
//!
//! Blank lines and lines starting with `#` are skipped. Every other line must have the same
//! number of whitespace-separated numbers:
//!
//! * 12 — KITTI: the top 3×4 rows `[R | t]` of the 4×4 pose, row-major. No times. `R` must be
//!   a rotation (`RᵀR = I` and `det R = +1`, each within 1e-3: files are written with few
//!   digits); it is re-orthonormalised (nearest rotation).
//! * 8 — TUM: `t x y z qx qy qz qw`, time in seconds. The quaternion's norm must be within 1 %
//!   of 1; it is normalised. Times must be strictly increasing.
//!
//! Any other count, a line whose count differs from the first pose line's, a value that is not
//! a finite number, a bad rotation or quaternion, a translation farther than
//! [`MAX_COORDINATE_M`] from the origin on an axis, a time beyond [`MAX_TIME_S`] or times out of
//! order is an [`Error::input`] naming `FILE:LINE`. A file without a pose is an error. A UTF-8
//! byte-order mark at the start of the file is skipped.

use super::{read_text, MAX_COORDINATE_M, MAX_TIME_S};
use crate::error::{Error, Result};
use glam::{DMat3, DMat4, DQuat, DVec3, DVec4};
use std::path::Path;

/// Tolerance on `RᵀR - I` (largest entry) and on `det R - 1` for KITTI rotations.
pub const ROTATION_TOLERANCE: f64 = 1e-3;

/// Tolerance on `|q| - 1` for TUM quaternions.
pub const QUATERNION_NORM_TOLERANCE: f64 = 0.01;

/// The poses of a recording, one per frame, in file order.
#[derive(Clone, Debug, PartialEq)]
pub struct Poses {
    /// LiDAR pose per frame: maps sensor-frame points into the world (z up).
    pub world_from_sensor: Vec<DMat4>,
    /// Time of each pose, seconds, strictly increasing (TUM files); `None` for KITTI files,
    /// whose times are in a separate `times.txt` ([`read_times`]).
    pub times_s: Option<Vec<f64>>,
}

/// Reads a KITTI or TUM pose file (format detected from the number of values per line).
pub fn read_poses(path: &Path) -> Result<Poses> {
    let mut poses = Vec::new();
    let mut times: Vec<f64> = Vec::new();
    // (values per line, line it was first seen on)
    let mut format: Option<(usize, usize)> = None;
    let mut prev_time_line = 0usize;
    let name = for_each_number_line(path, |line, here, vals| {
        let n = vals.len();
        match format {
            None => {
                if n != 12 && n != 8 {
                    return Err(Error::input(
                        here,
                        format!("{n} values: expected 12 (KITTI 3x4 [R|t]) or 8 (TUM t x y z qx qy qz qw)"),
                    ));
                }
                format = Some((n, line));
            }
            Some((want, first)) if n != want => {
                return Err(Error::input(here, format!("{n} values, but line {first} has {want}: one file holds one format")));
            }
            Some(_) => {}
        }
        if n == 12 {
            poses.push(kitti_pose(vals).map_err(|m| Error::input(here, m))?);
        } else {
            push_later_time(&mut times, &mut prev_time_line, vals[0], line, here)?;
            poses.push(tum_pose(vals).map_err(|m| Error::input(here, m))?);
        }
        Ok(())
    })?;
    match format {
        None => Err(Error::input(name, "holds no pose")),
        Some((12, _)) => Ok(Poses { world_from_sensor: poses, times_s: None }),
        Some(_) => Ok(Poses { world_from_sensor: poses, times_s: Some(times) }),
    }
}

/// Reads `path` and calls `each(line, "file:line", numbers)` for every line that is not blank
/// or a `#` comment, its values parsed as finite numbers. Returns the file's name for
/// messages about the whole file.
fn for_each_number_line(path: &Path, mut each: impl FnMut(usize, &str, &[f64]) -> Result<()>) -> Result<String> {
    let text = read_text(path)?;
    let name = path.display().to_string();
    let mut vals = Vec::with_capacity(12);
    for (i, raw) in text.lines().enumerate() {
        let s = raw.trim();
        if s.is_empty() || s.starts_with('#') {
            continue;
        }
        let here = format!("{name}:{}", i + 1);
        parse_numbers(s, &here, &mut vals)?;
        each(i + 1, &here, &vals)?;
    }
    Ok(name)
}

/// Appends time `t` read on `line` (named `here`), which must be within [`MAX_TIME_S`] and
/// come after the last one (read on `prev_line`).
fn push_later_time(times: &mut Vec<f64>, prev_line: &mut usize, t: f64, line: usize, here: &str) -> Result<()> {
    if t.abs() > MAX_TIME_S {
        return Err(Error::input(
            here,
            format!("time {t:?} s is beyond the supported {MAX_TIME_S:e} s (times are seconds, not nanoseconds)"),
        ));
    }
    if let Some(&prev) = times.last() {
        if t <= prev {
            return Err(Error::input(here, format!("time {t} is not after time {prev} on line {prev_line}")));
        }
    }
    times.push(t);
    *prev_line = line;
    Ok(())
}

/// Reads a KITTI `times.txt`: one time in seconds per line, finite and strictly increasing.
/// Blank lines and `#` lines are skipped; a file without a time is an error.
pub fn read_times(path: &Path) -> Result<Vec<f64>> {
    let mut times: Vec<f64> = Vec::new();
    let mut prev_line = 0usize;
    let name = for_each_number_line(path, |line, here, vals| {
        if vals.len() != 1 {
            return Err(Error::input(here, format!("{} values: expected one time per line", vals.len())));
        }
        push_later_time(&mut times, &mut prev_line, vals[0], line, here)
    })?;
    if times.is_empty() {
        return Err(Error::input(name, "holds no time"));
    }
    Ok(times)
}

/// Parses every whitespace-separated value of a line as a finite `f64` into `out`.
fn parse_numbers(s: &str, at: &str, out: &mut Vec<f64>) -> Result<()> {
    out.clear();
    for (k, tok) in s.split_whitespace().enumerate() {
        let v: f64 = tok
            .parse()
            .map_err(|_| Error::input(at, format!("value {} `{tok}` is not a number", k + 1)))?;
        if !v.is_finite() {
            return Err(Error::input(at, format!("value {} `{tok}` is not finite", k + 1)));
        }
        out.push(v);
    }
    Ok(())
}

/// A KITTI row-major `[R | t]` as a 4x4 pose, with `R` checked and re-orthonormalised.
fn kitti_pose(v: &[f64]) -> std::result::Result<DMat4, String> {
    // Row-major on disk; glam is column-major.
    let r = DMat3::from_cols(
        DVec3::new(v[0], v[4], v[8]),
        DVec3::new(v[1], v[5], v[9]),
        DVec3::new(v[2], v[6], v[10]),
    );
    let t = translation(DVec3::new(v[3], v[7], v[11]))?;
    let r = orthonormalise(r)?;
    Ok(DMat4::from_cols(
        r.x_axis.extend(0.0),
        r.y_axis.extend(0.0),
        r.z_axis.extend(0.0),
        DVec4::new(t.x, t.y, t.z, 1.0),
    ))
}

/// Checks that `r` is a rotation within [`ROTATION_TOLERANCE`] and returns the nearest exact
/// rotation (the orthogonal polar factor, by Newton iteration `R <- (R + R⁻ᵀ) / 2`).
fn orthonormalise(r: DMat3) -> std::result::Result<DMat3, String> {
    let rtr = r.transpose() * r;
    let mut dev = 0.0f64;
    for c in 0..3 {
        for k in 0..3 {
            let want = if c == k { 1.0 } else { 0.0 };
            dev = dev.max((rtr.col(c)[k] - want).abs());
        }
    }
    let det = r.determinant();
    if dev > ROTATION_TOLERANCE || (det - 1.0).abs() > ROTATION_TOLERANCE {
        return Err(format!(
            "the 3x3 part is not a rotation: |R^T R - I| = {dev:.3e}, det = {det:.6} \
             (both must be within {ROTATION_TOLERANCE} of a rotation's)"
        ));
    }
    let mut q = r;
    for _ in 0..4 {
        q = (q + q.inverse().transpose()) * 0.5;
    }
    Ok(q)
}

/// A TUM `t x y z qx qy qz qw` line as a 4x4 pose, the quaternion checked and normalised.
fn tum_pose(v: &[f64]) -> std::result::Result<DMat4, String> {
    let q = DQuat::from_xyzw(v[4], v[5], v[6], v[7]);
    let norm = q.length();
    if (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
        return Err(format!(
            "quaternion (qx qy qz qw) has norm {norm}; it must be within {QUATERNION_NORM_TOLERANCE} of 1"
        ));
    }
    Ok(DMat4::from_rotation_translation(q / norm, translation(DVec3::new(v[1], v[2], v[3]))?))
}

/// A pose's translation, checked to lie within [`MAX_COORDINATE_M`] of the origin on each axis.
fn translation(t: DVec3) -> std::result::Result<DVec3, String> {
    if t.abs().max_element() > MAX_COORDINATE_M {
        return Err(format!(
            "translation ({:?}, {:?}, {:?}) m is farther than the supported {MAX_COORDINATE_M:e} m from the origin \
             (shift the poses to a local origin)",
            t.x, t.y, t.z
        ));
    }
    Ok(t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> PathBuf {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    fn err(dir: &tempfile::TempDir, name: &str, text: &str) -> String {
        let e = read_poses(&write(dir, name, text)).unwrap_err();
        assert!(e.is_input(), "{e}");
        e.to_string()
    }

    fn close(a: &DMat4, b: &DMat4, tol: f64) -> bool {
        a.to_cols_array().iter().zip(b.to_cols_array()).all(|(x, y)| (x - y).abs() <= tol)
    }

    fn test_poses() -> Vec<DMat4> {
        (0..20)
            .map(|i| {
                let f = i as f64;
                let q = DQuat::from_euler(glam::EulerRot::ZYX, 0.3 * f, 0.02 * f, -0.01 * f);
                DMat4::from_rotation_translation(q, DVec3::new(f * 1.5, -f * 0.3, 0.1 * f))
            })
            .collect()
    }

    #[test]
    fn kitti_round_trip() {
        let d = tempfile::tempdir().unwrap();
        let poses = test_poses();
        let mut text = String::from("# KITTI poses\n");
        for m in &poses {
            let rows: Vec<String> =
                (0..3).flat_map(|r| (0..4).map(move |c| format!("{:.9e}", m.col(c)[r]))).collect();
            text.push_str(&rows.join(" "));
            text.push('\n');
        }
        text.push('\n');
        let got = read_poses(&write(&d, "poses.txt", &text)).unwrap();
        assert!(got.times_s.is_none());
        assert_eq!(got.world_from_sensor.len(), poses.len());
        for (a, b) in got.world_from_sensor.iter().zip(&poses) {
            assert!(close(a, b, 1e-8), "{a} vs {b}");
        }
        // The identity, as KITTI writes it, and a translation: x = 1, y = 2, z = 3.
        let p = write(&d, "id.txt", "1 0 0 1 0 1 0 2 0 0 1 3\n");
        let got = read_poses(&p).unwrap();
        assert_eq!(got.world_from_sensor[0], DMat4::from_translation(DVec3::new(1.0, 2.0, 3.0)));
    }

    #[test]
    fn kitti_rotation_is_reorthonormalised_within_tolerance() {
        let d = tempfile::tempdir().unwrap();
        // A 90 deg yaw written with 4 digits and a small skew (5e-4).
        let p = write(&d, "p.txt", "0.0005 -1.0 0 0 1.0 0.0003 0 0 0 0 1.0002 0\n");
        let m = read_poses(&p).unwrap().world_from_sensor[0];
        let r = DMat3::from_mat4(m);
        assert!((r.determinant() - 1.0).abs() < 1e-12);
        let e = r.transpose() * r - DMat3::IDENTITY;
        assert!(e.to_cols_array().iter().all(|v| v.abs() < 1e-12), "{e}");
        assert!((r * DVec3::X - DVec3::Y).length() < 1e-3);
    }

    #[test]
    fn tum_round_trip() {
        let d = tempfile::tempdir().unwrap();
        let poses = test_poses();
        let mut text = String::from("# timestamp tx ty tz qx qy qz qw\n");
        for (i, m) in poses.iter().enumerate() {
            let (_, q, t) = m.to_scale_rotation_translation();
            text.push_str(&format!(
                "{:.6} {} {} {} {} {} {} {}\n",
                1_317_000_000.0 + 0.1 * i as f64,
                t.x,
                t.y,
                t.z,
                q.x,
                q.y,
                q.z,
                q.w
            ));
        }
        let got = read_poses(&write(&d, "traj.tum", &text)).unwrap();
        let times = got.times_s.unwrap();
        assert_eq!(times.len(), poses.len());
        assert!((times[3] - (1_317_000_000.0 + 0.3)).abs() < 1e-6);
        for (a, b) in got.world_from_sensor.iter().zip(&poses) {
            assert!(close(a, b, 1e-9), "{a} vs {b}");
        }
        // A quaternion written with few digits (norm 1.0001) is normalised.
        let p = write(&d, "q.txt", "0 1 2 3 0 0 0.7072 0.7072\n");
        let m = read_poses(&p).unwrap().world_from_sensor[0];
        let r = DMat3::from_mat4(m);
        assert!((r.determinant() - 1.0).abs() < 1e-12);
        assert!((r * DVec3::X - DVec3::Y).length() < 1e-9);
        assert_eq!(m.w_axis, DVec4::new(1.0, 2.0, 3.0, 1.0));
    }

    #[test]
    fn errors_name_file_and_line() {
        let d = tempfile::tempdir().unwrap();
        let k = "1 0 0 0 0 1 0 0 0 0 1 0\n";
        let t0 = "0.0 0 0 0 0 0 0 1\n";
        let t1 = "0.1 0 0 0 0 0 0 1\n";
        // Empty (or only comments).
        let m = err(&d, "e.txt", "");
        assert!(m.contains("e.txt") && m.contains("no pose"), "{m}");
        assert!(err(&d, "c.txt", "# nothing\n\n").contains("no pose"));
        // Wrong count, mixed counts.
        let m = err(&d, "w.txt", "1 2 3\n");
        assert!(m.contains("w.txt:1") && m.contains("3 values"), "{m}");
        let m = err(&d, "mix.txt", &format!("{k}\n{t0}"));
        assert!(m.contains("mix.txt:3") && m.contains("line 1 has 12"), "{m}");
        // Non-number, non-finite.
        let m = err(&d, "n.txt", &format!("{k}1 0 0 x 0 1 0 0 0 0 1 0\n"));
        assert!(m.contains("n.txt:2") && m.contains("`x` is not a number"), "{m}");
        let m = err(&d, "f.txt", &format!("{t0}0.2 nan 0 0 0 0 0 1\n"));
        assert!(m.contains("f.txt:2") && m.contains("not finite"), "{m}");
        let m = err(&d, "inf.txt", "1 0 0 inf 0 1 0 0 0 0 1 0\n");
        assert!(m.contains("inf.txt:1") && m.contains("not finite"), "{m}");
        // Not a rotation: scaled, and a reflection.
        let m = err(&d, "s.txt", &format!("{k}{k}2 0 0 0 0 1 0 0 0 0 1 0\n"));
        assert!(m.contains("s.txt:3") && m.contains("not a rotation"), "{m}");
        let m = err(&d, "r.txt", "1 0 0 0 0 1 0 0 0 0 -1 0\n");
        assert!(m.contains("r.txt:1") && m.contains("det = -1"), "{m}");
        // A shear with det 1: only the orthonormality check can refuse it.
        let m = err(&d, "sh.txt", "1 0.5 0 0 0 1 0 0 0 0 1 0\n");
        assert!(m.contains("sh.txt:1") && m.contains("not a rotation") && m.contains("det = 1.000000"), "{m}");
        // Just outside the tolerance.
        let m = err(&d, "tol.txt", "1.002 0 0 0 0 1 0 0 0 0 1 0\n");
        assert!(m.contains("tol.txt:1") && m.contains("not a rotation"), "{m}");
        // TUM quaternion norm.
        let m = err(&d, "q.txt", &format!("{t0}0.1 0 0 0 0 0 0 0.9\n"));
        assert!(m.contains("q.txt:2") && m.contains("norm 0.9"), "{m}");
        let m = err(&d, "q0.txt", "0 0 0 0 0 0 0 0\n");
        assert!(m.contains("q0.txt:1") && m.contains("norm"), "{m}");
        // TUM times: equal and decreasing, naming both lines.
        let m = err(&d, "t.txt", &format!("{t0}# c\n{t1}{t1}"));
        assert!(m.contains("t.txt:4") && m.contains("on line 3"), "{m}");
        let m = err(&d, "t2.txt", &format!("{t1}{t0}"));
        assert!(
            m.contains("t2.txt:2") && m.contains("time 0 is not after time 0.1 on line 1"),
            "{m}"
        );
        // A missing file.
        let e = read_poses(&d.path().join("none.txt")).unwrap_err();
        assert!(e.is_input() && e.to_string().contains("none.txt"));
    }

    #[test]
    fn far_translations_and_times_are_refused_naming_the_line() {
        let d = tempfile::tempdir().unwrap();
        let k = "1 0 0 0 0 1 0 0 0 0 1 0\n";
        // KITTI ty = 1e38, tz = 2^32; TUM y = 1e6 (one past the bound: 1e5 is accepted).
        let m = err(&d, "ty.txt", &format!("{k}{k}1 0 0 0 0 1 0 1e38 0 0 1 0\n"));
        assert!(m.contains("ty.txt:3") && m.contains("1e38") && m.contains("1e5 m"), "{m}");
        let m = err(&d, "tz.txt", &format!("{k}1 0 0 0 0 1 0 0 0 0 1 4294967296\n"));
        assert!(m.contains("tz.txt:2") && m.contains("4294967296"), "{m}");
        let m = err(&d, "tum.txt", "0 0 0 0 0 0 0 1\n0.1 0 1e6 0 0 0 0 1\n");
        assert!(m.contains("tum.txt:2") && m.contains("1000000"), "{m}");
        assert!(read_poses(&write(&d, "edge.txt", "0 -1e5 1e5 0 0 0 0 1\n")).is_ok());
        // A time in nanoseconds, or absurd, in a TUM file or times.txt.
        let m = err(&d, "ns.txt", "1.7e18 0 0 0 0 0 0 1\n");
        assert!(m.contains("ns.txt:1") && m.contains("1.7e18") && m.contains("nanoseconds"), "{m}");
        let e = read_times(&write(&d, "times.txt", "0\n0.1\n-1.8e19\n")).unwrap_err();
        assert!(e.is_input() && e.to_string().contains("times.txt:3"), "{e}");
    }

    #[test]
    fn a_byte_order_mark_is_skipped() {
        let d = tempfile::tempdir().unwrap();
        let p = write(&d, "bom.txt", "\u{feff}1 0 0 1 0 1 0 2 0 0 1 3\n");
        assert_eq!(read_poses(&p).unwrap().world_from_sensor[0], DMat4::from_translation(DVec3::new(1.0, 2.0, 3.0)));
        let p = write(&d, "tum.txt", "\u{feff}# t x y z qx qy qz qw\n5 1 2 3 0 0 0 1\n");
        assert_eq!(read_poses(&p).unwrap().times_s, Some(vec![5.0]));
        assert_eq!(read_times(&write(&d, "times.txt", "\u{feff}0.5\n")).unwrap(), vec![0.5]);
    }

    #[test]
    fn times_file() {
        let d = tempfile::tempdir().unwrap();
        let p = write(&d, "times.txt", "0.000000e+00\n1.038330e-01\n2.073690e-01\n\n");
        assert_eq!(read_times(&p).unwrap(), vec![0.0, 0.103833, 0.207369]);
        let e = |name: &str, text: &str| {
            let e = read_times(&write(&d, name, text)).unwrap_err();
            assert!(e.is_input());
            e.to_string()
        };
        assert!(e("e.txt", "\n").contains("no time"));
        let m = e("o.txt", "0.1\n0.2\n0.2\n");
        assert!(m.contains("o.txt:3") && m.contains("on line 2"), "{m}");
        let m = e("n.txt", "0.1\nnan\n");
        assert!(m.contains("n.txt:2") && m.contains("not finite"), "{m}");
        let m = e("two.txt", "0.1 0.2\n");
        assert!(m.contains("two.txt:1") && m.contains("one time per line"), "{m}");
        let m = e("x.txt", "zero\n");
        assert!(m.contains("x.txt:1") && m.contains("not a number"), "{m}");
    }
}
