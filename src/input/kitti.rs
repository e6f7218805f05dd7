//! KITTI velodyne scans (`velodyne/NNNNNN.bin`, also SemanticKITTI): a flat array of
//! little-endian `f32` records `x y z intensity`, metres, in the LiDAR frame (x forward, y left,
//! z up). No header, no ring, no time: the frame's time comes from `times.txt`
//! ([`super::poses::read_times`]).
//!
//! Intensity (remission) is kept per point; a non-finite one is read as 0. Points with a non-finite coordinate
//! and all-zero points (no return) are dropped.

use super::Scan;
use crate::error::{Error, Result};
use std::path::Path;

/// Bytes per record: four `f32`.
const RECORD_BYTES: usize = 16;

/// Reads one KITTI `.bin` scan. A file whose size is not a whole number of 16-byte records
/// is rejected (a truncated copy); an empty file is a scan without points.
pub fn read_bin(path: &Path) -> Result<Scan> {
    let bytes = super::read_bytes(path)?;
    parse_bin(&bytes).map_err(|m| Error::input(path.display(), m))
}

/// Parses the bytes of a `.bin` file; the error is the message only.
fn parse_bin(bytes: &[u8]) -> std::result::Result<Scan, String> {
    if bytes.len() % RECORD_BYTES != 0 {
        return Err(format!(
            "truncated: {} bytes is not a whole number of {RECORD_BYTES}-byte points",
            bytes.len()
        ));
    }
    let mut points = Vec::with_capacity(bytes.len() / RECORD_BYTES);
    let mut intensity = Vec::with_capacity(bytes.len() / RECORD_BYTES);
    for rec in bytes.chunks_exact(RECORD_BYTES) {
        // One unaligned 16-byte load; the values are little-endian on disk whatever the host.
        let raw: [u32; 4] = bytemuck::pod_read_unaligned(rec);
        let p = [
            f32::from_bits(u32::from_le(raw[0])),
            f32::from_bits(u32::from_le(raw[1])),
            f32::from_bits(u32::from_le(raw[2])),
        ];
        if keep(p) {
            points.push(p);
            // A non-finite remission says nothing: 0.
            let i = f32::from_bits(u32::from_le(raw[3]));
            intensity.push(if i.is_finite() { i } else { 0.0 });
        }
    }
    Ok(Scan { points, intensity: Some(intensity), ..Scan::default() })
}

/// A point is kept when all coordinates are finite and it is not the origin.
fn keep(p: [f32; 3]) -> bool {
    p.iter().all(|v| v.is_finite()) && p != [0.0; 3]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_bin(dir: &tempfile::TempDir, name: &str, recs: &[[f32; 4]]) -> std::path::PathBuf {
        let mut bytes = Vec::with_capacity(recs.len() * 16);
        for r in recs {
            for v in r {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    #[test]
    fn round_trip_keeps_order_and_values() {
        let d = tempfile::tempdir().unwrap();
        let recs: Vec<[f32; 4]> = (0..1000)
            .map(|i| {
                let f = i as f32;
                [f * 0.01 - 3.0, -f * 0.02 + 1.5, (f * 0.37).sin(), f / 1000.0]
            })
            .collect();
        let p = write_bin(&d, "000000.bin", &recs);
        let s = read_bin(&p).unwrap();
        assert_eq!(s.points.len(), recs.len());
        for (a, r) in s.points.iter().zip(&recs) {
            assert_eq!(*a, [r[0], r[1], r[2]]);
        }
        assert!(s.ring.is_none() && s.ring_elevation_deg.is_none() && s.time_s.is_none());
    }

    #[test]
    fn truncated_file_is_an_error_naming_file_and_size() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("cut.bin");
        std::fs::write(&p, vec![0u8; 1000]).unwrap();
        let e = read_bin(&p).unwrap_err();
        assert!(e.is_input());
        let m = e.to_string();
        assert!(m.contains("cut.bin"), "{m}");
        assert!(m.contains("1000 bytes is not a whole number of 16-byte points"), "{m}");
    }

    #[test]
    fn missing_file_is_an_input_error() {
        let d = tempfile::tempdir().unwrap();
        let e = read_bin(&d.path().join("nope.bin")).unwrap_err();
        assert!(e.is_input() && e.to_string().contains("nope.bin"), "{e}");
    }

    #[test]
    fn nan_inf_and_zero_points_are_dropped() {
        let d = tempfile::tempdir().unwrap();
        let recs = [
            [1.0, 2.0, 3.0, 0.5],
            [f32::NAN, 2.0, 3.0, 0.5],
            [0.0, 0.0, 0.0, 0.9],
            [1.0, f32::INFINITY, 3.0, 0.5],
            [0.0, 0.0, -0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [4.0, 5.0, 6.0, f32::NAN], // a bad intensity does not matter
        ];
        let p = write_bin(&d, "x.bin", &recs);
        let s = read_bin(&p).unwrap();
        assert_eq!(s.points, vec![[1.0, 2.0, 3.0], [0.0, 0.0, 1.0], [4.0, 5.0, 6.0]]);
        // The kept points' remission; a non-finite one reads as 0.
        assert_eq!(s.intensity, Some(vec![0.5, 0.0, 0.0]));
    }

    #[test]
    fn empty_file_is_an_empty_scan() {
        let d = tempfile::tempdir().unwrap();
        let p = write_bin(&d, "e.bin", &[]);
        assert!(read_bin(&p).unwrap().points.is_empty());
    }
}
