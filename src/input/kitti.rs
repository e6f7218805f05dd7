//! KITTI velodyne scans (`velodyne/NNNNNN.bin`, also SemanticKITTI): a flat array of
//! little-endian `f32` records `x y z intensity`, metres, in the LiDAR frame (x forward, y left,
//! z up). No header, no ring, no time: the frame's time comes from `times.txt`
//! ([`super::poses::read_times`]).
//!
//! Intensity (remission) is kept per point; a non-finite one is read as 0. Points with a non-finite coordinate
//! and all-zero points (no return) are dropped.
//!
//! # Lasers from the point order
//!
//! KITTI's scans (odometry, raw, SemanticKITTI; HDL-64E) store their points laser by laser,
//! highest laser first, each laser one turn counter-clockwise seen from above, starting
//! straight ahead. So the turn angle `atan2(y, x)` taken in `[0, 2 pi)` rises through each
//! laser and drops by almost a whole turn from one laser to the next. Measured on the
//! SemanticKITTI sequence 07 and odometry sequences 01, 02, 03, 06, 09 and 10 (ten scans
//! each): every scan falls into exactly 64 such runs, at most 2 % of the steps inside a run
//! go backwards (by up to 15 deg), and the runs' median elevations fall strictly from the
//! first run to the last.
//!
//! [`lasers_of`] recovers the lasers when a scan shows that order: runs cut where the turn
//! angle drops by more than half a turn, at most [`MAX_BACKWARD_SHARE`] of all steps
//! backwards, at least two runs and their median elevations strictly falling. The scan then
//! carries them as [`Scan::ring`] (ring 0 = the lowest run, the ROS convention) without
//! elevations, so a target with as many rows as the scan has lasers, each near its laser's
//! elevation, takes row for laser ([`super::project`]); a scan that fails any check (another order, a laser with no return
//! at all, a scan whose runs cannot be told apart) has no rings and is projected by the
//! elevation of each point.
//!
//! Rows by elevation are wrong for KITTI: an HDL-64E's lasers sit about 20 cm (upper block)
//! and 0 to 12 cm (lower block) above the origin of its points, so a point's elevation seen
//! from the origin is its laser's angle plus `atan(offset / distance)`: 0.8 deg more at 15 m,
//! two row gaps. Projected by elevation onto `hdl64e`, a scan leaves its lowest rows empty
//! and splits each laser over two rows.

use super::Scan;
use crate::error::{Error, Result};
use std::path::Path;

/// Bytes per record: four `f32`.
const RECORD_BYTES: usize = 16;

/// The most steps of a scan, as a share of its points, whose turn angle may go backwards
/// inside a laser's run for [`lasers_of`] to take the order as laser by laser (KITTI: 2 %
/// at most; a scan stored column by column, clockwise, has nearly all its steps backwards).
pub const MAX_BACKWARD_SHARE: f64 = 0.1;

/// A `.bin` scan with the place of each point among the file's records.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BinScan {
    /// The scan as [`read_bin`] gives it.
    pub scan: Scan,
    /// Records in the file (points kept and dropped).
    pub records: usize,
    /// The record of each kept point, ascending.
    pub record_of_point: Vec<u32>,
}

/// Reads one KITTI `.bin` scan. A file whose size is not a whole number of 16-byte records
/// is rejected (a truncated copy); an empty file is a scan without points.
pub fn read_bin(path: &Path) -> Result<Scan> {
    read_bin_records(path).map(|b| b.scan)
}

/// [`read_bin`], with the record each point came from.
pub fn read_bin_records(path: &Path) -> Result<BinScan> {
    let bytes = super::read_bytes(path)?;
    parse_bin(&bytes).map_err(|m| Error::input(path.display(), m))
}

/// Checks that `path` is a file of whole records, without reading it (a folder of scans is
/// checked before any is read).
pub fn check_bin_len(path: &Path) -> Result<()> {
    let len = super::file_len(path)?;
    if len % RECORD_BYTES as u64 != 0 {
        return Err(Error::input(path.display(), truncated(len)));
    }
    Ok(())
}

/// What is wrong with a file of `len` bytes that is not a whole number of records.
fn truncated(len: u64) -> String {
    format!("truncated: {len} bytes is not a whole number of {RECORD_BYTES}-byte points")
}

/// Parses the bytes of a `.bin` file; the error is the message only.
fn parse_bin(bytes: &[u8]) -> std::result::Result<BinScan, String> {
    if bytes.len() % RECORD_BYTES != 0 {
        return Err(truncated(bytes.len() as u64));
    }
    let records = bytes.len() / RECORD_BYTES;
    if u32::try_from(records).is_err() {
        return Err(format!("{records} points is more than a scan may hold ({})", u32::MAX));
    }
    let mut points = Vec::with_capacity(records);
    let mut intensity = Vec::with_capacity(records);
    let mut record_of_point = Vec::with_capacity(records);
    for (k, rec) in bytes.chunks_exact(RECORD_BYTES).enumerate() {
        // One unaligned 16-byte load; the values are little-endian on disk whatever the host.
        let raw: [u32; 4] = bytemuck::pod_read_unaligned(rec);
        let p = [
            f32::from_bits(u32::from_le(raw[0])),
            f32::from_bits(u32::from_le(raw[1])),
            f32::from_bits(u32::from_le(raw[2])),
        ];
        if keep(p) {
            points.push(p);
            record_of_point.push(k as u32);
            // A non-finite remission says nothing: 0.
            let i = f32::from_bits(u32::from_le(raw[3]));
            intensity.push(if i.is_finite() { i } else { 0.0 });
        }
    }
    let ring = lasers_of(&points);
    Ok(BinScan { scan: Scan { points, intensity: Some(intensity), ring, ..Scan::default() }, records, record_of_point })
}

/// The laser of each point (ring 0 = the lowest) when `points` come laser by laser, each
/// laser one counter-clockwise turn, highest laser first (see the module docs); `None` when
/// the order does not show it.
pub fn lasers_of(points: &[[f32; 3]]) -> Option<Vec<u16>> {
    use std::f64::consts::TAU;
    let turn = |p: &[f32; 3]| (p[1] as f64).atan2(p[0] as f64).rem_euclid(TAU);
    // Run starts (the first at 0) and backward steps inside the runs.
    let mut starts = vec![0];
    let mut backward = 0usize;
    for (i, w) in points.windows(2).enumerate() {
        let step = turn(&w[1]) - turn(&w[0]);
        if step < -TAU / 2.0 {
            starts.push(i + 1);
        } else if step < 0.0 {
            backward += 1;
        }
    }
    let runs = starts.len();
    if runs < 2 || runs > u16::MAX as usize + 1 || backward as f64 > MAX_BACKWARD_SHARE * points.len() as f64 {
        return None;
    }
    starts.push(points.len());
    let mut previous = f64::INFINITY;
    let mut elevation = Vec::new();
    for w in starts.windows(2) {
        elevation.clear();
        elevation.extend(points[w[0]..w[1]].iter().map(|p| (p[2] as f64).atan2((p[0] as f64).hypot(p[1] as f64))));
        let mid = elevation.len() / 2;
        let median = *elevation.select_nth_unstable_by(mid, f64::total_cmp).1;
        if !(median < previous) {
            return None;
        }
        previous = median;
    }
    let mut ring = Vec::with_capacity(points.len());
    for (s, w) in starts.windows(2).enumerate() {
        ring.resize(w[1], (runs - 1 - s) as u16);
    }
    Some(ring)
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

    /// Points of `lasers` (elevations, deg) stored laser by laser as KITTI stores them: each
    /// one turn counter-clockwise from straight ahead, `n` points a turn, at ranges from 3 to
    /// 40 m seen from lasers 20 cm above the origin (so a point's own elevation strays from
    /// its laser's by up to 3.8 deg, more than a row gap).
    fn laser_order(lasers: &[f64], n: usize) -> Vec<[f32; 3]> {
        let mut pts = Vec::new();
        for (l, el) in lasers.iter().enumerate() {
            for k in 0..n {
                let az = (k as f64 + 0.5) / n as f64 * std::f64::consts::TAU;
                let r = 3.0 + 37.0 * (((k * 7 + l * 3) % 11) as f64 / 10.0);
                let (h, z) = (r * el.to_radians().cos(), 0.2 + r * el.to_radians().sin());
                pts.push([(h * az.cos()) as f32, (h * az.sin()) as f32, z as f32]);
            }
        }
        pts
    }

    const LASERS: [f64; 5] = [2.0, 1.6, -3.0, -8.0, -15.0];

    #[test]
    fn a_scan_stored_laser_by_laser_gets_its_lasers_lowest_first() {
        let pts = laser_order(&LASERS, 200);
        let ring = lasers_of(&pts).expect("laser by laser");
        let want: Vec<u16> = (0..5u16).rev().flat_map(|r| std::iter::repeat_n(r, 200)).collect();
        assert_eq!(ring, want);
        // Steps back inside a laser (up to 10 % of them) are taken as jitter.
        let mut jittered = pts.clone();
        for k in (3..jittered.len()).step_by(11) {
            jittered.swap(k, k - 1);
        }
        assert_eq!(lasers_of(&jittered), Some(want));
        // Read from a file, the same; the dropped records do not count.
        let d = tempfile::tempdir().unwrap();
        let mut recs: Vec<[f32; 4]> = pts.iter().map(|p| [p[0], p[1], p[2], 0.5]).collect();
        recs.insert(250, [f32::NAN, 0.0, 0.0, 0.5]);
        recs.insert(0, [0.0; 4]);
        let b = read_bin_records(&write_bin(&d, "l.bin", &recs)).unwrap();
        assert_eq!((b.records, b.scan.points.len()), (1002, 1000));
        assert_eq!(b.record_of_point[..3], [1, 2, 3]);
        assert_eq!(b.record_of_point[249..251], [250, 252]);
        assert_eq!(b.scan.ring.as_ref().map(|r| (r[0], r[999])), Some((4, 0)));
    }

    #[test]
    fn other_orders_get_no_lasers() {
        let n = 200;
        let pts = laser_order(&LASERS, n);
        // Lowest laser first: the runs' elevations rise.
        let up: Vec<[f32; 3]> = pts.chunks(n).rev().flatten().copied().collect();
        assert_eq!(lasers_of(&up), None);
        // Each laser clockwise, from behind (pedscan's own row-major order): no run is cut.
        let clockwise: Vec<[f32; 3]> = pts.chunks(n).flat_map(|c| c[n / 2..].iter().chain(&c[..n / 2]).rev()).copied().collect();
        assert_eq!(lasers_of(&clockwise), None);
        // Over 10 % of the steps backwards.
        let mut shuffled = pts.clone();
        for k in (1..shuffled.len()).step_by(4) {
            shuffled.swap(k, k - 1);
        }
        assert_eq!(lasers_of(&shuffled), None);
        // One laser, one point, none.
        assert_eq!(lasers_of(&pts[..n]), None);
        assert_eq!(lasers_of(&pts[..1]), None);
        assert_eq!(lasers_of(&[]), None);
    }

    #[test]
    fn empty_file_is_an_empty_scan() {
        let d = tempfile::tempdir().unwrap();
        let p = write_bin(&d, "e.bin", &[]);
        assert!(read_bin(&p).unwrap().points.is_empty());
    }
}
