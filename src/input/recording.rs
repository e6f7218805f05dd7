//! A recorded background sequence: the frames of a capture or of a folder, their times and
//! (optionally) the sensor's poses, projected onto the target sensor's beam grid.
//!
//! # Sources
//! * a Velodyne `.pcap` (HDL-32E / VLP-16): decoded whole when the run starts and kept as
//!   projected range images (rows x columns x 4 bytes per frame), times from the capture;
//! * an Ouster `.pcap` ([`super::ouster`]), the same way: a capture whose first UDP packets
//!   hold no 1206-byte Velodyne payload but payloads of the size its metadata predicts, the
//!   metadata being the `.json` beside it with the same stem (`x.pcap`, `x.json`);
//! * a folder of KITTI `.bin` or `.pcd` frames (one kind per folder, in file-name order): read
//!   and projected when a window uses them, so a folder may hold any number of frames. The
//!   `.bin` sizes are checked when the run starts. The window's images, read once to find the
//!   floor and walkable area, are kept for its frames (up to 256 MiB), so each file is read
//!   once per sequence.
//!
//! # Times
//! In order of preference: the poses file's (TUM), the capture's (pcap), a KITTI `times.txt`
//! in the frame folder or its parent, else `k / rate_hz` of the target sensor. A `times.txt`
//! that is there in any form but cannot be read as a file (a folder, a dangling or looping
//! link) is an error naming it, never a silent fall back to the sensor's rate. The output
//! frames of a sequence are consecutive recorded frames, so the sequence runs at the
//! recording's own frame rate with its own (possibly uneven) steps: people and sensor are
//! posed at the recorded times. The target sensor's `rate_hz` is not used.
//!
//! # Sweeps
//! A frame's columns are fired over its sweep (the rolling shutter,
//! [`crate::sensor_model::shutter`]). A pcap carries its own: each frame's column times on the
//! target grid come from its packets ([`Scan::firing_times`] through
//! [`crate::input::sweep::boundary_times`]), as offsets from the capture's frame time,
//! so they follow the frame's time from whichever source gives it (a poses file's clock too).
//! A frame whose capture times are refused (a clock that steps back or jumps, too few
//! firings) and every frame of a KITTI or PCD folder take the uniform sweep over the recorded
//! frame step; [`Recording::sweep_warning`] says how many frames fell back and why.
//!
//! # Poses
//! With a poses file (one pose per frame, same count), the sensor's world pose of frame k is
//! pose k, and its velocity and yaw rate come from the poses (see
//! [`crate::scene::sequence::PoseTrack::from_poses`]). Without one, the sensor is taken as static at
//! the origin: background velocities are then 0, wrong for a moving recording, and the run
//! says so on stderr.

//!
//! Where people may walk in a recording is the scene's business ([`crate::scene::recorded`]);
//! this module gives it the window's returns ([`Recording::window_points`]).

use super::ouster::{ouster_metadata_for, read_ouster_pcap};
use super::pcap::read_pcap;
use super::poses::{read_poses, read_times};
use super::rosbag::{is_bag, read_bag, BagOptions};
use super::project::Projector;
use super::{file_len, kitti, pcd, Scan};
use crate::error::{Error, Result};
use crate::sensor::Sensor;
use glam::{DMat4, DVec3};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// One projected frame: range per beam and, when the source has intensity, the kept return's
/// intensity per beam (else empty).
type Image = (Vec<f32>, Vec<f32>);

/// The frames of a recording.
enum Frames {
    /// Projected range and intensity images (pcap).
    Images(Vec<Image>),
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
    window: std::sync::Mutex<Option<(usize, Vec<Image>)>>,
    /// Frame files read and projected so far (to check the window cache).
    pub files_read: std::sync::atomic::AtomicUsize,
    /// Per frame when the source carries its own sweep (pcap): the time of each column
    /// boundary of the target grid (W + 1, strictly increasing), s after the frame's capture
    /// time; `None` for a frame that takes the uniform sweep. Empty for other sources.
    column_offsets: Vec<ColumnOffsets>,
    /// Why frames of a capture take the uniform sweep instead of their own, once for the
    /// whole recording (how many, and the first frame's reason).
    pub sweep_warning: Option<String>,
    /// A capture that fires fewer times a turn than the grid has columns leaves columns with
    /// no return of its own (holes the sensor did not make): how many, and the grid that fits.
    pub coverage_warning: Option<String>,
    /// The recording sensor's beam elevations, degrees, descending, when the source says
    /// which sensor it is (a Velodyne capture; an Ouster capture's `beam_altitude_angles`);
    /// `None` for frame folders.
    pub source_elevation_deg: Option<Vec<f64>>,
}

/// A frame's column boundary times after its own time, when it has its own sweep.
type ColumnOffsets = Option<Arc<[f64]>>;

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

/// True when `path` names a recorded background (a `.pcap`, a ROS 2 bag or a folder), not an
/// environment.
pub fn is_recording(path: &Path) -> bool {
    path.is_dir() || is_pcap(path) || is_bag(path)
}

/// What a recording is read with besides its path (a run's: built by the configuration,
/// [`crate::config::SceneConfig::recording_options`]).
#[derive(Clone, Debug, Default)]
pub struct RecordingOptions<'a> {
    /// A poses file (one pose per frame); it wins over a bag's transforms.
    pub poses: Option<&'a Path>,
    /// An Ouster capture's metadata JSON (`None`: the `.json` beside the `.pcap`).
    pub ouster_metadata: Option<&'a Path>,
    /// A ROS 2 bag's topic, world frame and odometry topic.
    pub bag: BagOptions,
}

/// True when `path` has the `.pcap` extension (any case): a Velodyne or Ouster capture.
pub fn is_pcap(path: &Path) -> bool {
    path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("pcap"))
}

/// The value of `sensor` that takes the recorded background's own grid.
pub const BACKGROUND_SENSOR: &str = "background";

/// The grid a recorded background was taken on, when the recording says it: a ROS 2 bag's from
/// its clouds' rings ([`super::rosbag::sensor_of_bag`]), an Ouster capture's from its metadata.
/// Any other background is an error naming it and asking for `--sensor`.
pub fn own_sensor(path: &Path, options: &RecordingOptions) -> Result<Sensor> {
    if path.as_os_str().is_empty() {
        return Err(Error::input("config key `sensor`", "`background` takes the recorded background's grid, and there is no background"));
    }
    if is_bag(path) {
        return super::rosbag::sensor_of_bag(path, &options.bag);
    }
    if is_pcap(path) {
        if let Some(json) = ouster_metadata_for(path, options.ouster_metadata)? {
            return Sensor::from_ouster_json(&super::read_text(&json)?, &json.display().to_string());
        }
    }
    Err(Error::input(
        path.display(),
        "does not say the grid it was taken on (sensor = \"background\" reads it from a ROS 2 bag with a `ring` field or an Ouster \
         capture's metadata): name the sensor (--sensor, a preset such as hdl32e or vlp16)",
    ))
}

impl Recording {
    /// Opens a recording and its optional poses; checks counts and times.
    pub fn open(path: &Path, poses_file: Option<&Path>, target: &Sensor) -> Result<Recording> {
        Recording::open_with(path, &RecordingOptions { poses: poses_file, ..Default::default() }, target)
    }

    /// [`Recording::open`] with every option.
    pub fn open_with(path: &Path, options: &RecordingOptions, target: &Sensor) -> Result<Recording> {
        let (poses_file, ouster_metadata) = (options.poses, options.ouster_metadata);
        let mut bag_poses = None;
        let projector = Projector::new(target);
        let mut column_offsets = Vec::new();
        let mut sweep_warning = None;
        let mut coverage_warning = None;
        let mut source_elevation_deg = None;
        let (frames, capture_times, description) = if is_bag(path) {
            let opts = BagOptions { no_poses: poses_file.is_some(), ..options.bag.clone() };
            let bag = read_bag(path, &opts, |scan, _| {
                let mut img = (Vec::new(), Vec::new());
                projector.project_with_intensity(scan, &mut img.0, &mut img.1);
                Ok((img, scan.firing_times.is_some().then(|| sweep_of(scan, target.columns))))
            })?;
            let mut images = Vec::with_capacity(bag.frames.len());
            let mut refused = Vec::new();
            for (k, (img, sweep)) in bag.frames.into_iter().enumerate() {
                images.push(img);
                column_offsets.push(match sweep {
                    Some(Ok(b)) => Some(b),
                    Some(Err(why)) => {
                        refused.push((k, why));
                        None
                    }
                    None => None,
                });
            }
            sweep_warning = sweeps_warning(&refused, images.len());
            source_elevation_deg = bag.ring_elevation_deg.map(|e| {
                let mut e: Vec<f64> = e.into_iter().filter(|x| x.is_finite()).collect();
                e.sort_by(|a, b| b.total_cmp(a));
                e
            });
            bag_poses = bag.poses;
            (Frames::Images(images), Some(bag.times_s), bag.description)
        } else if path.is_dir() {
            let files = super::folder_files(path, |f| kind_of(f).is_some())?;
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
            for f in &files {
                // Every frame must be a readable file (a dangling link is named now, not when
                // a window reaches it); .bin sizes must be whole points.
                if kind == Some(FileKind::Bin) {
                    kitti::check_bin_len(f)?;
                } else {
                    file_len(f)?;
                }
            }
            let d = format!("{} {} frames", files.len(), if kind == Some(FileKind::Bin) { "KITTI .bin" } else { "PCD" });
            (Frames::Files(files), None, d)
        } else if let Some(json) = is_recording(path).then(|| ouster_metadata_for(path, ouster_metadata)).transpose()?.flatten() {
            let rec = read_ouster_pcap(path, &json)?;
            let m = &rec.meta;
            let d = format!(
                "{} capture (Ouster, {}): {} frames of {} columns x {} pixels from {} lidar packets ({} other packets \
                 skipped, {} partial frames dropped, {} invalid columns skipped)",
                m.prod_line,
                m.profile.name(),
                rec.scans.len(),
                m.columns_per_frame,
                m.pixels_per_column,
                rec.data_packets,
                rec.foreign_packets,
                rec.partial_frames,
                rec.invalid_columns
            );
            let times: Vec<f64> = rec.scans.iter().map(|s| s.time_s.unwrap_or(f64::NAN)).collect();
            source_elevation_deg = Some(m.elevation_deg_descending());
            (column_offsets, sweep_warning) = capture_sweeps(&rec.scans, target.columns);
            // One firing per column of the column window.
            coverage_warning = coverage(m.window_len(), target.columns, &m.prod_line);
            let images = project_scans(&projector, &rec.scans);
            (Frames::Images(images), Some(times), d)
        } else if is_recording(path) {
            let rec = read_pcap(path)?;
            let relabelled = rec.relabelled.map_or(String::new(), |(claimed, us)| {
                format!(" (its packets claim the {}'s product id but come every {us:.1} us, as a {}'s do)", claimed.name(), rec.model.name())
            });
            let d = format!(
                "{} capture{relabelled}: {} rotations from {} data packets ({} foreign packets skipped, {} partial rotations dropped)",
                rec.model.name(),
                rec.scans.len(),
                rec.data_packets,
                rec.foreign_packets,
                rec.partial_rotations
            );
            let times: Vec<f64> = rec.scans.iter().map(|s| s.time_s.unwrap_or(f64::NAN)).collect();
            let mut el = rec.model.elevation_deg().to_vec();
            el.sort_by(|a, b| b.total_cmp(a));
            source_elevation_deg = Some(el);
            (column_offsets, sweep_warning) = capture_sweeps(&rec.scans, target.columns);
            let fired = turn_firings(&rec.scans) * rec.model.sequences_per_block();
            coverage_warning = coverage(fired, target.columns, rec.model.name());
            let images = project_scans(&projector, &rec.scans);
            (Frames::Images(images), Some(times), d)
        } else if path.exists() {
            return Err(Error::input(
                path.display(),
                "not a recorded background: want a .pcap file, a ROS 2 bag (.mcap, or a folder with metadata.yaml) or a folder of .bin / .pcd frames",
            ));
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
        // A times.txt that exists in any form (a folder, a dangling or looping link) is read,
        // so what is wrong with it is reported instead of falling back to the sensor's rate.
        let times_file = [path.join("times.txt"), path.parent().map(|p| p.join("times.txt")).unwrap_or_default()]
            .into_iter()
            .find(|f| path.is_dir() && std::fs::symlink_metadata(f).is_ok());
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
            poses: poses.map(|p| p.world_from_sensor).or(bag_poses),
            description,
            projector,
            dirs: target.beam_dirs(),
            window: std::sync::Mutex::new(None),
            files_read: std::sync::atomic::AtomicUsize::new(0),
            column_offsets,
            sweep_warning,
            coverage_warning,
            source_elevation_deg,
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
        self.frame(k, out, &mut Vec::new())
    }

    /// [`Recording::frame_ranges`], and the intensity of each beam's return into `intensity`
    /// (the source's units; left empty when the source has none).
    pub fn frame(&self, k: usize, out: &mut Vec<f32>, intensity: &mut Vec<f32>) -> Result<()> {
        match &self.frames {
            Frames::Images(v) => {
                out.clone_from(&v[k].0);
                intensity.clone_from(&v[k].1);
            }
            Frames::Files(files) => {
                if let Some((first, images)) = &*self.window.lock().unwrap_or_else(|e| e.into_inner()) {
                    if let Some(img) = k.checked_sub(*first).and_then(|i| images.get(i)) {
                        out.clone_from(&img.0);
                        intensity.clone_from(&img.1);
                        return Ok(());
                    }
                }
                let f = &files[k];
                let scan: Scan = match kind_of(f) {
                    Some(FileKind::Bin) => kitti::read_bin(f)?,
                    _ => pcd::read_pcd(f)?,
                };
                self.projector.project_with_intensity(&scan, out, intensity);
                self.files_read.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            }
        }
        Ok(())
    }

    /// The time of each column boundary of frame `k` on the target grid (W + 1, strictly
    /// increasing), s after the frame's time, when the recording carries its own sweep there;
    /// `None`: the uniform sweep over the recorded frame step.
    pub fn column_offsets(&self, k: usize) -> Option<&Arc<[f64]>> {
        self.column_offsets.get(k).and_then(Option::as_ref)
    }

    /// `world_from_sensor` of frame `k` (identity without poses).
    pub fn pose(&self, k: usize) -> DMat4 {
        self.poses.as_ref().map_or(DMat4::IDENTITY, |p| p[k])
    }

    /// The returns of the window `frames` in the world frame, each with its sensor's
    /// position; keeps the window's images for the frames that follow (when they fit).
    pub fn window_points(&self, frames: std::ops::Range<usize>) -> Result<Vec<(DVec3, DVec3)>> {
        // World points of the window with their sensor's position.
        let mut pts: Vec<(DVec3, DVec3)> = Vec::new();
        let mut ranges = Vec::new();
        // Frame files: keep the window's images for the frames that follow (when they fit).
        let keep = matches!(self.frames, Frames::Files(_))
            && frames.len().saturating_mul(self.dirs.len() * 8) <= WINDOW_CACHE_BYTES;
        *self.window.lock().unwrap_or_else(|e| e.into_inner()) = None;
        let kept: Vec<Image> = if keep { self.read_window(frames.clone())? } else { Vec::new() };
        for k in frames.clone() {
            let ranges = if keep {
                &kept[k - frames.start].0
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
        if keep {
            *self.window.lock().unwrap_or_else(|e| e.into_inner()) = Some((frames.start, kept));
        }
        Ok(pts)
    }

    /// The range images of the window `frames` (as [`Recording::frame_ranges`]); a frame
    /// folder's window is kept for the frames that follow, as [`Recording::window_points`]
    /// keeps it.
    pub fn window_ranges(&self, frames: std::ops::Range<usize>) -> Result<Vec<Vec<f32>>> {
        let images = self.read_window(frames.clone())?;
        let ranges = images.iter().map(|i| i.0.clone()).collect();
        if matches!(self.frames, Frames::Files(_)) && frames.len().saturating_mul(self.dirs.len() * 8) <= WINDOW_CACHE_BYTES {
            *self.window.lock().unwrap_or_else(|e| e.into_inner()) = Some((frames.start, images));
        }
        Ok(ranges)
    }

    /// The images of the window `frames`, read in parallel (files are independent); the
    /// first failing frame, in order, is the one reported.
    fn read_window(&self, frames: std::ops::Range<usize>) -> Result<Vec<Image>> {
        use rayon::prelude::*;
        let read: Vec<Result<Image>> = frames
            .into_par_iter()
            .map(|k| {
                let mut img = (Vec::new(), Vec::new());
                self.frame(k, &mut img.0, &mut img.1).map(|()| img)
            })
            .collect();
        read.into_iter().collect()
    }

    /// The frame files of a folder of frames, in frame order; `None` for a capture or a bag.
    pub fn frame_files(&self) -> Option<&[PathBuf]> {
        match &self.frames {
            Frames::Files(f) => Some(f),
            Frames::Images(_) => None,
        }
    }

    /// The projection of the recording's frames onto the target grid.
    pub fn projector(&self) -> &Projector {
        &self.projector
    }

    /// The target grid's beam directions (row-major), sensor frame.
    pub fn beam_dirs(&self) -> &[DVec3] {
        &self.dirs
    }

    /// The recording's name and the window `frames`, for messages.
    pub fn window_name(&self, frames: std::ops::Range<usize>) -> String {
        format!("{} (frames {}..{})", self.source.display(), frames.start, frames.end)
    }
}

/// Each scan's column boundary times on a grid of `columns` (offsets from the scan's time) from
/// its firings, and a warning naming how many scans fell back to the uniform sweep and why.
/// The firings of a capture's turn: the median over its turns (a turn's list holds the firing
/// where it is cut twice, closing one turn and opening the next); 0 without firing times.
fn turn_firings(scans: &[Scan]) -> usize {
    let mut n: Vec<usize> = scans.iter().filter_map(|s| s.firing_times.as_ref().map(Vec::len)).collect();
    if n.is_empty() {
        return 0;
    }
    n.sort_unstable();
    n[n.len() / 2].saturating_sub(1)
}

/// The warning for a capture that fires fewer times a turn (`fired` azimuths) than the grid
/// has columns: at least that share of the columns gets none of its returns.
fn coverage(fired: usize, columns: usize, sensor: &str) -> Option<String> {
    (fired > 0 && fired < columns).then(|| {
        format!(
            "the {sensor} fired {fired} times a turn, fewer than the grid's {columns} columns: at least {:.1} % of \
             the columns get no return of its own (holes the sensor did not make); a sensor of at most {fired} \
             columns fits it",
            100.0 * (columns - fired) as f64 / columns as f64
        )
    })
}

/// Each scan projected onto the grid (range and intensity images).
fn project_scans(projector: &Projector, scans: &[Scan]) -> Vec<Image> {
    scans
        .iter()
        .map(|s| {
            let mut img = (Vec::new(), Vec::new());
            projector.project_with_intensity(s, &mut img.0, &mut img.1);
            img
        })
        .collect()
}

fn capture_sweeps(scans: &[Scan], columns: usize) -> (Vec<ColumnOffsets>, Option<String>) {
    let mut refused: Vec<(usize, String)> = Vec::new();
    let offsets = scans
        .iter()
        .enumerate()
        .map(|(k, s)| sweep_of(s, columns).map_err(|why| refused.push((k, why))).ok())
        .collect();
    (offsets, sweeps_warning(&refused, scans.len()))
}

/// A scan's column boundary times on a grid of `columns`, offsets from the scan's time, from
/// its firings; why not, when it must take the uniform sweep.
fn sweep_of(s: &Scan, columns: usize) -> std::result::Result<Arc<[f64]>, String> {
    let (Some(firings), Some(t0)) = (&s.firing_times, s.time_s) else {
        return Err("no firing times".into());
    };
    // Relative to the frame's time, so a Unix-time clock keeps its microseconds.
    let relative: Vec<[f64; 2]> = firings.iter().map(|&[a, t]| [a, t - t0]).collect();
    crate::input::sweep::boundary_times(&relative, columns).map(Into::into)
}

/// The warning naming how many of `frames` fell back to the uniform sweep (`refused`: frame
/// and why) and the first one's reason.
fn sweeps_warning(refused: &[(usize, String)], frames: usize) -> Option<String> {
    refused.first().map(|(k, why)| {
        format!(
            "{} of {frames} frames take the uniform sweep over their recorded step instead of their own recorded column times (frame {k}: {why})",
            refused.len(),
        )
    })
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


#[cfg(test)]
mod tests {
    use super::*;
    use crate::input::rosbag::tests::{moving_bag, write_bag};

    /// A KITTI `.bin` of one return straight ahead at `range` metres.
    fn bin(path: &Path, range: f32) {
        let rec: Vec<u8> = [range, 0.0, 0.0, 0.5].iter().flat_map(|v| v.to_le_bytes()).collect();
        std::fs::write(path, rec).unwrap();
    }

    /// The range of the beam straight ahead in the row nearest the horizon.
    fn ahead(rec: &Recording, k: usize) -> f32 {
        let s = Sensor::hdl32e();
        let row = (0..s.rows()).min_by(|&a, &b| s.elevation_deg[a].abs().total_cmp(&s.elevation_deg[b].abs())).unwrap();
        let mut r = Vec::new();
        rec.frame_ranges(k, &mut r).unwrap();
        r[row * s.columns + s.column_of(1.0, 0.0)]
    }

    #[test]
    fn a_folder_of_frames_reads_in_name_order_at_its_times() {
        let d = tempfile::tempdir().unwrap();
        // Written out of order, one in capitals; other files are not frames.
        for (name, range) in [("000002.BIN", 7.0), ("000000.bin", 5.0), ("000001.bin", 6.0)] {
            bin(&d.path().join(name), range);
        }
        std::fs::write(d.path().join("README.txt"), "not a frame").unwrap();
        std::fs::write(d.path().join("times.txt"), "0.0\n0.11\n0.19\n").unwrap();
        let rec = Recording::open(d.path(), None, &Sensor::hdl32e()).unwrap();
        assert_eq!((rec.len(), rec.is_empty(), rec.description.as_str()), (3, false, "3 KITTI .bin frames"));
        assert_eq!(rec.times_s, vec![0.0, 0.11, 0.19]);
        assert_eq!([ahead(&rec, 0), ahead(&rec, 1), ahead(&rec, 2)], [5.0, 6.0, 7.0]);
        assert!(rec.poses.is_none() && rec.column_offsets(0).is_none() && rec.source_elevation_deg.is_none());
        // With a poses file (KITTI: no times), its poses; the times still from times.txt.
        std::fs::write(d.path().join("poses.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 1 0 1 0 0 0 0 1 0\n1 0 0 2 0 1 0 0 0 0 1 0\n").unwrap();
        let rec = Recording::open(d.path(), Some(&d.path().join("poses.txt")), &Sensor::hdl32e()).unwrap();
        assert_eq!(rec.pose(2).w_axis.truncate(), DVec3::new(2.0, 0.0, 0.0));
        assert_eq!(rec.times_s, vec![0.0, 0.11, 0.19]);
        // A window's returns in the world, beside their sensor's position; its frames are
        // read once, then served from the window's images.
        let before = rec.files_read.load(std::sync::atomic::Ordering::Relaxed);
        let pts = rec.window_points(1..3).unwrap();
        // (The beam's centre is half a column, 0.18 degrees, off straight ahead.)
        let from = |k: usize| pts.iter().filter(|(_, o)| *o == DVec3::new(k as f64, 0.0, 0.0)).map(|(p, _)| p.x.round()).collect::<Vec<_>>();
        assert_eq!((pts.len(), from(1), from(2)), (2, vec![1.0 + 6.0], vec![2.0 + 7.0]));
        assert_eq!((ahead(&rec, 1), ahead(&rec, 2)), (6.0, 7.0));
        assert_eq!(rec.files_read.load(std::sync::atomic::Ordering::Relaxed) - before, 2);
        assert_eq!(rec.window_name(1..3), format!("{} (frames 1..3)", d.path().display()));
        // Without times.txt, the sensor's rate.
        std::fs::remove_file(d.path().join("times.txt")).unwrap();
        let rec = Recording::open(d.path(), None, &Sensor { rate_hz: 20.0, ..Sensor::hdl32e() }).unwrap();
        assert_eq!(rec.times_s, vec![0.0, 0.05, 0.1]);
    }

    #[test]
    fn folders_that_are_not_one_kind_of_whole_frames_are_refused() {
        let d = tempfile::tempdir().unwrap();
        let err = |p: &Path| Recording::open(p, None, &Sensor::hdl32e()).err().expect("refused").to_string();
        assert!(err(d.path()).ends_with("folder holds no .bin or .pcd frame"));
        bin(&d.path().join("a.bin"), 5.0);
        std::fs::write(d.path().join("b.pcd"), "not read").unwrap();
        assert!(err(d.path()).contains("mixes .bin and .pcd frames"));
        std::fs::remove_file(d.path().join("b.pcd")).unwrap();
        std::fs::write(d.path().join("b.bin"), [0u8; 17]).unwrap();
        assert_eq!(err(d.path()), format!("{}: truncated: 17 bytes is not a whole number of 16-byte points", d.path().join("b.bin").display()));
        std::fs::write(d.path().join("b.bin"), [0u8; 32]).unwrap();
        assert_eq!(Recording::open(d.path(), None, &Sensor::hdl32e()).unwrap().len(), 2);
    }

    #[test]
    fn recordings_are_told_from_environments_by_their_names() {
        let d = tempfile::tempdir().unwrap();
        for (name, recording, pcap) in
            [("x.pcap", true, true), ("X.PCAP", true, true), ("x.mcap", true, false), ("x.glb", false, false), ("x.gltf", false, false), ("x.txt", false, false)]
        {
            let p = d.path().join(name);
            assert_eq!((is_recording(&p), is_pcap(&p)), (recording, pcap), "{name}");
        }
        assert!(is_recording(d.path()) && !is_pcap(d.path()));
    }

    #[test]
    fn a_bags_poses_come_from_its_transforms_unless_a_poses_file_is_given() {
        let d = tempfile::tempdir().unwrap();
        let bag = d.path().join("b.mcap");
        write_bag(&bag, &moving_bag(), None);
        // From /tf: the cloud before the first transform is dropped; the others' poses follow it.
        let rec = Recording::open(&bag, None, &Sensor::hdl32e()).unwrap();
        assert_eq!(rec.times_s, vec![0.0, 1.0, 2.0]);
        assert_eq!(rec.pose(1).w_axis.truncate(), DVec3::new(2.0, 0.0, 1.0));
        // Rings measured: the recording's two elevations, highest first.
        let e = rec.source_elevation_deg.clone().unwrap();
        assert!(e.len() == 2 && e[0] > 14.0 && e[1] < -14.0, "{e:?}");
        // Its points' `time` gives every frame its own sweep.
        assert!(rec.column_offsets(0).is_some());
        // A poses file wins: every cloud is kept, at its pose, at the bag's times.
        let poses = d.path().join("poses.txt");
        std::fs::write(&poses, "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 5 0 1 0 0 0 0 1 0\n1 0 0 6 0 1 0 0 0 0 1 0\n1 0 0 7 0 1 0 0 0 0 1 0\n").unwrap();
        let rec = Recording::open(&bag, Some(&poses), &Sensor::hdl32e()).unwrap();
        assert!(rec.times_s.iter().zip([0.0, 0.95, 1.95, 2.95]).all(|(a, b)| (a - b).abs() < 1e-12), "{:?}", rec.times_s);
        assert_eq!(rec.pose(1).w_axis.truncate(), DVec3::new(5.0, 0.0, 0.0));
    }

    #[test]
    fn frame_times_must_be_finite_and_rise_strictly() {
        let path = Path::new("times.txt");
        assert!(check_times(&[], path).is_ok());
        assert!(check_times(&[3.0], path).is_ok());
        assert!(check_times(&[0.0, 0.1, 0.25, 0.3], path).is_ok());
        for (bad, at) in [
            (vec![0.0, 0.1, 0.1], "frame 1 at 0.1 s, frame 2 at 0.1 s"),
            (vec![0.0, 0.2, 0.1, 0.3], "frame 1 at 0.2 s, frame 2 at 0.1 s"),
            (vec![f64::NAN, 0.1], "frame 0 at NaN s"),
            (vec![0.0, f64::NAN], "frame 1 at NaN s"),
            (vec![0.0, f64::INFINITY], "frame 1 at inf s"),
            (vec![f64::NEG_INFINITY, 0.0], "frame 0 at -inf s"),
        ] {
            let e = check_times(&bad, path).unwrap_err().to_string();
            assert!(e.contains("times.txt") && e.contains(at), "{bad:?}: {e}");
        }
    }

    #[test]
    fn a_turns_firings_are_the_median_captures_count_less_the_closing_one() {
        let scan = |n: Option<usize>| Scan { firing_times: n.map(|n| vec![[0.0, 0.0]; n]), ..Scan::default() };
        assert_eq!(turn_firings(&[]), 0);
        assert_eq!(turn_firings(&[scan(None), scan(None)]), 0);
        assert_eq!(turn_firings(&[scan(Some(7))]), 6);
        // Sorted 10, 20, 30, 40, 50 (and a scan without times, not counted): the median is 30.
        let scans: Vec<Scan> = [50, 10, 40, 30, 20].map(Some).into_iter().chain([None]).map(scan).collect();
        assert_eq!(turn_firings(&scans), 29);
        // An even count takes the upper middle: 10, 20, 30, 40 -> 30.
        assert_eq!(turn_firings(&[40, 10, 30, 20].map(|n| scan(Some(n)))), 29);
    }
}
