//! A recorded background sequence: the frames of a capture or of a folder, their times and
//! (optionally) the sensor's poses, projected onto the target sensor's beam grid.
//!
//! # Sources
//! * a Velodyne `.pcap` (HDL-32E / VLP-16): decoded whole when the run starts and kept as
//!   projected range images (rows x columns x 4 bytes per frame), times from the capture;
//! * a folder of KITTI `.bin` or `.pcd` frames (one kind per folder, in file-name order): read
//!   and projected when a window uses them, so a folder may hold any number of frames. The
//!   `.bin` sizes are checked when the run starts. The window's images, read once to find the
//!   floor and walkable area, are kept for its frames (up to 256 MiB), so each file is read
//!   once per sequence.
//!
//! # Times
//! In order of preference: the poses file's (TUM), the capture's (pcap), a KITTI `times.txt`
//! in the frame folder or its parent, else `k / rate_hz` of the target sensor. The output
//! frames of a sequence are consecutive recorded frames, so the sequence runs at the
//! recording's own frame rate with its own (possibly uneven) steps: people and sensor are
//! posed at the recorded times. The target sensor's `rate_hz` is not used.
//!
//! # Poses
//! With a poses file (one pose per frame, same count), the sensor's world pose of frame k is
//! pose k, and its velocity and yaw rate come from the poses (see
//! [`crate::sequence::PoseTrack::from_poses`]). Without one, the sensor is taken as static at
//! the origin: background velocities are then 0, wrong for a moving recording, and the run
//! says so on stderr.
//!
//! # Where people may walk
//! The floor height is estimated per window (or set by `scene.floor_z_m`): the most
//! populated 5 cm height bin of the window's returns below the sensor, refined by the median
//! of the returns within 5 cm of it. The walkable area is a 10 cm grid: cells with a floor
//! return, grown by 1 m to bridge the gaps between rings, minus cells with a return between
//! 25 cm and 2 m above the floor (anything standing there at any frame of the window, moving
//! objects included), largest connected region only.

use super::pcap::read_pcap;
use super::poses::{read_poses, read_times};
use super::project::Projector;
use super::{kitti, pcd, Scan};
use crate::error::{Error, Result};
use crate::scene::WalkableGrid;
use crate::sensor::Sensor;
use glam::{DMat4, DVec2, DVec3};
use std::path::{Path, PathBuf};

/// The frames of a recording.
enum Frames {
    /// Projected range images (pcap).
    Images(Vec<Vec<f32>>),
    /// Frame files, read on demand.
    Files(Vec<PathBuf>),
}

/// A recorded background sequence.
pub struct Recording {
    pub source: PathBuf,
    frames: Frames,
    /// Frame times, s, strictly increasing.
    pub times_s: Vec<f64>,
    /// `world_from_sensor` per frame, when a poses file was given.
    pub poses: Option<Vec<DMat4>>,
    /// One line about the source (format, counts, skipped packets), for logs and metadata;
    /// names no path, so outputs do not depend on where the data lies.
    pub description: String,
    projector: Projector,
    dirs: Vec<DVec3>,
    /// Frame files only: the range images of the last window `walkable` read (first frame,
    /// images), so the frames of the sequence are not read and projected a second time.
    /// Kept only while the window's images fit in `WINDOW_CACHE_BYTES`.
    window: std::sync::Mutex<Option<(usize, Vec<Vec<f32>>)>>,
    /// Frame files read and projected so far (to check the window cache).
    pub files_read: std::sync::atomic::AtomicUsize,
}

/// The most memory the window cache of a frame folder may hold.
const WINDOW_CACHE_BYTES: usize = 256 << 20;

/// What a frame file is.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum FileKind {
    Bin,
    Pcd,
}

fn kind_of(p: &Path) -> Option<FileKind> {
    match p.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).as_deref() {
        Some("bin") => Some(FileKind::Bin),
        Some("pcd") => Some(FileKind::Pcd),
        _ => None,
    }
}

/// True when `path` names a recorded background (a `.pcap` or a folder), not an environment.
pub fn is_recording(path: &Path) -> bool {
    path.is_dir() || path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("pcap"))
}

impl Recording {
    /// Opens a recording and its optional poses; checks counts and times.
    pub fn open(path: &Path, poses_file: Option<&Path>, target: &Sensor) -> Result<Recording> {
        let projector = Projector::new(target);
        let (frames, capture_times, description) = if path.is_dir() {
            let mut files: Vec<PathBuf> = std::fs::read_dir(path)
                .map_err(|e| Error::io(path, e))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| kind_of(f).is_some())
                .collect();
            files.sort();
            let Some(first) = files.first() else {
                return Err(Error::input(path.display(), "folder holds no .bin or .pcd frame"));
            };
            let kind = kind_of(first);
            if let Some(other) = files.iter().find(|f| kind_of(f) != kind) {
                return Err(Error::input(
                    path.display(),
                    format!("mixes .bin and .pcd frames ({} and {}); use one kind per folder", first.display(), other.display()),
                ));
            }
            if kind == Some(FileKind::Bin) {
                for f in &files {
                    let len = std::fs::metadata(f).map_err(|e| Error::io(f, e))?.len();
                    if len % 16 != 0 {
                        return Err(Error::input(
                            f.display(),
                            format!("truncated: {len} bytes is not a whole number of 16-byte points"),
                        ));
                    }
                }
            }
            let d = format!("{} {} frames", files.len(), if kind == Some(FileKind::Bin) { "KITTI .bin" } else { "PCD" });
            (Frames::Files(files), None, d)
        } else if is_recording(path) {
            let rec = read_pcap(path)?;
            let d = format!(
                "{} capture: {} rotations from {} data packets ({} foreign packets skipped, {} partial rotations dropped)",
                rec.model.name(),
                rec.scans.len(),
                rec.data_packets,
                rec.foreign_packets,
                rec.partial_rotations
            );
            let times: Vec<f64> = rec.scans.iter().map(|s| s.time_s.unwrap_or(f64::NAN)).collect();
            let mut images = Vec::with_capacity(rec.scans.len());
            for s in &rec.scans {
                let mut img = Vec::new();
                projector.project(s, &mut img);
                images.push(img);
            }
            (Frames::Images(images), Some(times), d)
        } else if path.exists() {
            return Err(Error::input(path.display(), "not a recorded background: want a .pcap file or a folder of .bin / .pcd frames"));
        } else {
            return Err(Error::input(path.display(), "background does not exist"));
        };
        let n = match &frames {
            Frames::Images(v) => v.len(),
            Frames::Files(v) => v.len(),
        };
        let poses = match poses_file {
            Some(p) => Some(read_poses(p)?),
            None => None,
        };
        if let Some(p) = &poses {
            if p.world_from_sensor.len() != n {
                return Err(Error::input(
                    poses_file.unwrap_or(Path::new("poses")).display(),
                    format!("{} poses for {n} frames of {}: want one pose per frame", p.world_from_sensor.len(), path.display()),
                ));
            }
        }
        let times_file = [path.join("times.txt"), path.parent().map(|p| p.join("times.txt")).unwrap_or_default()]
            .into_iter()
            .find(|f| path.is_dir() && f.is_file());
        let times = if let Some(t) = poses.as_ref().and_then(|p| p.times_s.clone()) {
            t
        } else if let Some(t) = capture_times {
            t
        } else if let Some(f) = times_file {
            let t = read_times(&f)?;
            if t.len() != n {
                return Err(Error::input(f.display(), format!("{} times for {n} frames of {}", t.len(), path.display())));
            }
            t
        } else {
            (0..n).map(|k| k as f64 / target.rate_hz).collect()
        };
        check_times(&times, path)?;
        Ok(Recording {
            source: path.to_path_buf(),
            frames,
            times_s: times,
            poses: poses.map(|p| p.world_from_sensor),
            description,
            projector,
            dirs: target.beam_dirs(),
            window: std::sync::Mutex::new(None),
            files_read: std::sync::atomic::AtomicUsize::new(0),
        })
    }

    /// Number of recorded frames.
    pub fn len(&self) -> usize {
        self.times_s.len()
    }

    pub fn is_empty(&self) -> bool {
        self.times_s.is_empty()
    }

    /// Recorded frame `k` on the target grid: range per beam, row-major, 0 = no return.
    pub fn frame_ranges(&self, k: usize, out: &mut Vec<f32>) -> Result<()> {
        match &self.frames {
            Frames::Images(v) => {
                out.clear();
                out.extend_from_slice(&v[k]);
            }
            Frames::Files(files) => {
                if let Some((first, images)) = &*self.window.lock().unwrap_or_else(|e| e.into_inner()) {
                    if let Some(img) = k.checked_sub(*first).and_then(|i| images.get(i)) {
                        out.clear();
                        out.extend_from_slice(img);
                        return Ok(());
                    }
                }
                let f = &files[k];
                let scan: Scan = match kind_of(f) {
                    Some(FileKind::Bin) => kitti::read_bin(f)?,
                    _ => pcd::read_pcd(f)?,
                };
                self.projector.project(&scan, out);
                self.files_read.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            }
        }
        Ok(())
    }

    /// `world_from_sensor` of frame `k` (identity without poses).
    pub fn pose(&self, k: usize) -> DMat4 {
        self.poses.as_ref().map_or(DMat4::IDENTITY, |p| p[k])
    }

    /// Floor height (world z) and walkable area of the window `frames`, from its returns.
    /// `floor_z` overrides the estimate.
    pub fn walkable(&self, frames: std::ops::Range<usize>, floor_z: Option<f64>) -> Result<(f64, WalkableGrid)> {
        // World points of the window with their sensor's position.
        let mut pts: Vec<(DVec3, DVec3)> = Vec::new();
        let mut ranges = Vec::new();
        // Frame files: keep the window's images for the frames that follow (when they fit).
        let keep = matches!(self.frames, Frames::Files(_))
            && frames.len().saturating_mul(self.dirs.len() * 4) <= WINDOW_CACHE_BYTES;
        *self.window.lock().unwrap_or_else(|e| e.into_inner()) = None;
        // Kept frames are read in parallel (files are independent); the first failing
        // frame, in order, is the one reported.
        let kept: Vec<Vec<f32>> = if keep {
            use rayon::prelude::*;
            let read: Vec<Result<Vec<f32>>> = frames
                .clone()
                .into_par_iter()
                .map(|k| {
                    let mut img = Vec::new();
                    self.frame_ranges(k, &mut img).map(|()| img)
                })
                .collect();
            read.into_iter().collect::<Result<_>>()?
        } else {
            Vec::new()
        };
        for k in frames.clone() {
            let ranges = if keep {
                &kept[k - frames.start]
            } else {
                self.frame_ranges(k, &mut ranges)?;
                &ranges
            };
            let pose = self.pose(k);
            let origin = pose.w_axis.truncate();
            for (d, &r) in self.dirs.iter().zip(ranges) {
                if r > 0.0 {
                    pts.push((pose.transform_point3(*d * r as f64), origin));
                }
            }
        }
        let name = || format!("{} (frames {}..{})", self.source.display(), frames.start, frames.end);
        let floor = match floor_z {
            Some(z) => z,
            None => estimate_floor(&pts).ok_or_else(|| {
                Error::input(name(), "cannot find the floor: no returns below the sensor; set scene.floor_z_m")
            })?,
        };
        let grid = walkable_from_points(&pts, floor, crate::pipeline::WALKABLE_CELL_M)
            .ok_or_else(|| Error::input(name(), format!("no walkable floor near z = {floor:.2} m in the recorded returns")))?;
        if keep {
            *self.window.lock().unwrap_or_else(|e| e.into_inner()) = Some((frames.start, kept));
        }
        Ok((floor, grid))
    }
}

fn check_times(t: &[f64], path: &Path) -> Result<()> {
    for (k, w) in t.windows(2).enumerate() {
        if !(w[0].is_finite() && w[1].is_finite() && w[1] > w[0]) {
            return Err(Error::input(
                path.display(),
                format!("frame times must be finite and increasing: frame {k} at {} s, frame {} at {} s", w[0], k + 1, w[1]),
            ));
        }
    }
    Ok(())
}

/// Horizontal distances (m) of the returns used for the floor.
const FLOOR_RING_M: [f64; 2] = [1.0, 30.0];
/// Heights above the floor that block a cell, m.
const BLOCK_Z_M: [f64; 2] = [0.25, 2.0];
/// Floor returns count within this height of the floor, m.
const FLOOR_TOLERANCE_M: f64 = 0.1;
/// Floor cells are grown by this much to bridge the gaps between rings, m.
const FLOOR_GROW_M: f64 = 1.0;

/// The floor: the most populated 5 cm bin of the returns at least 30 cm below their sensor,
/// refined to the median of the returns within 5 cm of it.
pub fn estimate_floor(pts: &[(DVec3, DVec3)]) -> Option<f64> {
    let below: Vec<f64> = pts
        .iter()
        .filter(|(p, o)| {
            let d = (p.truncate() - o.truncate()).length();
            p.z < o.z - 0.3 && d >= FLOOR_RING_M[0] && d <= FLOOR_RING_M[1]
        })
        .map(|(p, _)| p.z)
        .collect();
    if below.len() < 50 {
        return None;
    }
    let lo = below.iter().copied().fold(f64::INFINITY, f64::min);
    let bin = 0.05;
    let mut counts: Vec<usize> = Vec::new();
    for z in &below {
        let b = ((z - lo) / bin) as usize;
        if b >= counts.len() {
            counts.resize(b + 1, 0);
        }
        counts[b] += 1;
    }
    // Ties go to the lower bin (deterministic).
    let best = (0..counts.len()).max_by_key(|&b| (counts[b], std::cmp::Reverse(b)))?;
    let centre = lo + (best as f64 + 0.5) * bin;
    let mut near: Vec<f64> = below.into_iter().filter(|z| (z - centre).abs() <= bin).collect();
    near.sort_by(f64::total_cmp);
    Some(near[near.len() / 2])
}

/// Walkable area from world points (see the module docs); None when no cell is walkable.
pub fn walkable_from_points(pts: &[(DVec3, DVec3)], floor: f64, cell_m: f64) -> Option<WalkableGrid> {
    let mut lo = DVec2::splat(f64::INFINITY);
    let mut hi = DVec2::splat(f64::NEG_INFINITY);
    for (p, o) in pts {
        if (p.truncate() - o.truncate()).length() <= FLOOR_RING_M[1] {
            lo = lo.min(p.truncate());
            hi = hi.max(p.truncate());
        }
    }
    if !lo.is_finite() {
        return None;
    }
    let lo = lo - DVec2::splat(cell_m);
    let hi = hi + DVec2::splat(cell_m);
    let nx = ((hi.x - lo.x) / cell_m).ceil() as usize;
    let ny = ((hi.y - lo.y) / cell_m).ceil() as usize;
    let mut seen = vec![false; nx * ny];
    let mut blocked = vec![false; nx * ny];
    for (p, o) in pts {
        if (p.truncate() - o.truncate()).length() > FLOOR_RING_M[1] {
            continue;
        }
        let q = (p.truncate() - lo) / cell_m;
        let (i, j) = (q.x as usize, q.y as usize);
        if i >= nx || j >= ny {
            continue;
        }
        let h = p.z - floor;
        if h.abs() <= FLOOR_TOLERANCE_M {
            seen[j * nx + i] = true;
        } else if h >= BLOCK_Z_M[0] && h <= BLOCK_Z_M[1] {
            blocked[j * nx + i] = true;
        }
    }
    // Grow the floor cells (a separable square dilation: rows, then columns).
    let g = (FLOOR_GROW_M / cell_m).round() as usize;
    let mut rows = vec![false; nx * ny];
    for j in 0..ny {
        dilate_line(&seen, &mut rows, j * nx, 1, nx, g);
    }
    let mut floor_cells = vec![false; nx * ny];
    for i in 0..nx {
        dilate_line(&rows, &mut floor_cells, i, nx, ny, g);
    }
    if !floor_cells.iter().zip(&blocked).any(|(f, b)| *f && !*b) {
        return None;
    }
    Some(WalkableGrid::from_cells(lo, cell_m, nx, ny, &floor_cells, blocked))
}

/// Sets `dst` at every cell of the line `first + k * stride` (k < n) within `g` cells of a
/// set cell of `src` on the same line.
fn dilate_line(src: &[bool], dst: &mut [bool], first: usize, stride: usize, n: usize, g: usize) {
    let at = |k: usize| first + k * stride;
    let mut last: Option<usize> = None;
    for k in 0..n {
        if src[at(k)] {
            last = Some(k);
        }
        if last.is_some_and(|l| k - l <= g) {
            dst[at(k)] = true;
        }
    }
    let mut next: Option<usize> = None;
    for k in (0..n).rev() {
        if src[at(k)] {
            next = Some(k);
        }
        if next.is_some_and(|l| l - k <= g) {
            dst[at(k)] = true;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points of a flat floor at z = -1.7 around a sensor at the origin, with a 1 x 1 m pillar
    /// at (5, 0).
    fn floor_scene() -> Vec<(DVec3, DVec3)> {
        let o = DVec3::ZERO;
        let mut pts = Vec::new();
        for i in -150..150 {
            for j in -150..150 {
                let (x, y) = (i as f64 * 0.1, j as f64 * 0.1);
                pts.push((DVec3::new(x, y, -1.7), o));
            }
        }
        for k in 0..20 {
            for z in 0..10 {
                let (x, y) = (4.5 + k as f64 * 0.05, -0.5 + k as f64 * 0.05);
                pts.push((DVec3::new(x, -0.5, -1.5 + z as f64 * 0.15), o));
                pts.push((DVec3::new(x, 0.5, -1.5 + z as f64 * 0.15), o));
                pts.push((DVec3::new(4.5, y, -1.5 + z as f64 * 0.15), o));
                pts.push((DVec3::new(5.5, y, -1.5 + z as f64 * 0.15), o));
            }
        }
        pts
    }

    #[test]
    fn the_floor_is_found_under_obstacles_and_noise() {
        let mut pts = floor_scene();
        // A few low outliers (multipath) below the floor must not win.
        for k in 0..40 {
            pts.push((DVec3::new(3.0 + k as f64 * 0.1, 2.0, -3.0), DVec3::ZERO));
        }
        let z = estimate_floor(&pts).unwrap();
        assert!((z + 1.7).abs() < 1e-9, "{z}");
    }

    #[test]
    fn the_walkable_area_excludes_what_stands_on_the_floor() {
        let pts = floor_scene();
        let g = walkable_from_points(&pts, -1.7, 0.1).unwrap();
        assert_eq!(g.clearance(DVec2::new(5.0, -0.5)), 0.0, "on the pillar's wall");
        assert!(g.clearance(DVec2::new(3.5, 0.0)) > 0.7 && g.clearance(DVec2::new(3.5, 0.0)) < 1.1);
        assert!(g.clearance(DVec2::new(-5.0, 0.0)) > 3.0, "open floor");
        assert_eq!(g.clearance(DVec2::new(40.0, 0.0)), 0.0, "never seen");
    }

    #[test]
    fn floor_gaps_between_rings_are_bridged() {
        // Rings of floor returns 0.8 m apart: the cells between them are floor too.
        let mut pts = Vec::new();
        for ring in 1..12 {
            let r = ring as f64 * 0.8;
            for a in 0..2000 {
                let t = a as f64 / 2000.0 * std::f64::consts::TAU;
                pts.push((DVec3::new(r * t.cos(), r * t.sin(), -1.0), DVec3::ZERO));
            }
        }
        let g = walkable_from_points(&pts, -1.0, 0.1).unwrap();
        assert!(g.clearance(DVec2::new(2.0, 0.0)) > 1.5, "between rings: {}", g.clearance(DVec2::new(2.0, 0.0)));
    }
}
