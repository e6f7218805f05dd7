//! Stage 2: recorded inputs. Backgrounds as per-frame point clouds from the formats people
//! have (KITTI `.bin`, PCD, raw Velodyne `.pcap`), sensor poses (KITTI `poses.txt`, TUM),
//! the projection of a recorded frame onto the target sensor's beam grid, a capture's own
//! column times ([`sweep`]), and recorded pedestrian tracks ([`tracks`]: ETH/UCY, ATC, CSV).
//!
//! Every reader returns [`Scan`]s in the *recording* sensor's frame (x forward, y left, z up,
//! metres). Bad input is an [`crate::Error::input`] naming the file and the line or record.
//!
//! # Files and limits shared by every reader
//!
//! * A path the user names that does not exist, is a dangling or looping symbolic link, or is
//!   not a regular file (a folder, a device) is bad input naming the path ([`open_file`]);
//!   only a failure while reading an opened file is an I/O error.
//! * Text files (poses, `times.txt`, tracks, PCD headers) may start with a UTF-8 byte-order
//!   mark; it is skipped.
//! * Every world coordinate read (pose translations, track positions after their transform)
//!   must be within [`MAX_COORDINATE_M`] of the origin on each axis, and every time (pose,
//!   frame and track times) within [`MAX_TIME_S`] of 0; anything beyond is an error naming
//!   the file and line. pedscan's world is a local frame: shift georeferenced poses or tracks
//!   (UTM, say) to a local origin first.

pub mod kitti;
pub mod labels;
pub mod ouster;
pub mod pcap;
pub mod pcd;
pub mod poses;
pub mod project;
pub mod recording;
pub mod rosbag;
pub mod sweep;
pub mod tracks;

pub use recording::Recording;

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// The largest absolute value of a world coordinate read from a file (pose translations,
/// transformed track positions), m: 100 km, far beyond any single recording. Capping it keeps
/// extents, grids and floating-point steps meaningful (a glitched pose at 1e38 m is refused
/// here, not met as an allocation later).
pub const MAX_COORDINATE_M: f64 = 1e5;

/// The largest absolute value of a time read from a file, s: 1e10 s, Unix time in seconds
/// until the year 2286. Times in nanoseconds (about 1.7e18 today) are refused by it, and at
/// this magnitude a time still resolves steps of 2 µs.
pub const MAX_TIME_S: f64 = 1e10;

/// The UTF-8 byte-order mark some editors write at the start of a text file.
const BOM: &str = "\u{feff}";

/// The entries of folder `dir` that `keep` takes, sorted by path: how pedscan lists a folder
/// of inputs the user names (models, recordings, bags, scans, sequences to summarize). A
/// folder that cannot be listed, or an entry of it that cannot be read, is an
/// [`Error::input`] naming the folder (never a listing with files missing).
pub fn folder_files(dir: &Path, keep: impl Fn(&Path) -> bool) -> Result<Vec<PathBuf>> {
    let cannot = |e: std::io::Error| Error::input(dir.display(), format!("cannot list the folder: {e}"));
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(cannot)? {
        let path = entry.map_err(cannot)?.path();
        if keep(&path) {
            files.push(path);
        }
    }
    files.sort();
    Ok(files)
}

/// The size of a file the user named. A path that does not exist, a dangling or looping
/// symbolic link, a folder or another non-file is an [`Error::input`] naming `path`.
pub fn file_len(path: &Path) -> Result<u64> {
    let cannot = |what: String| Error::input(path.display(), what);
    let meta = std::fs::metadata(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound if std::fs::symlink_metadata(path).is_ok() => {
            cannot("is a symbolic link to nothing (its target does not exist)".into())
        }
        std::io::ErrorKind::NotFound => cannot("does not exist".into()),
        _ => cannot(format!("cannot open: {e}")),
    })?;
    if meta.is_dir() {
        return Err(cannot("is a folder, not a file".into()));
    }
    if !meta.is_file() {
        return Err(cannot("is not a regular file".into()));
    }
    Ok(meta.len())
}

/// Opens a file the user named ([`file_len`]), with its size.
pub fn open_file(path: &Path) -> Result<(std::fs::File, u64)> {
    let len = file_len(path)?;
    let file = std::fs::File::open(path).map_err(|e| Error::input(path.display(), format!("cannot open: {e}")))?;
    Ok((file, len))
}

/// The bytes of a file the user named ([`open_file`]); a failure while reading is an I/O error.
pub fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    let (mut file, len) = open_file(path)?;
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    std::io::Read::read_to_end(&mut file, &mut bytes).map_err(|e| Error::io(path, e))?;
    Ok(bytes)
}

/// The text of a file the user named ([`open_file`]), without a leading byte-order mark. Text
/// that is not UTF-8 is an error naming the file and the line.
pub fn read_text(path: &Path) -> Result<String> {
    let bytes = read_bytes(path)?;
    let text = strip_bom(&bytes);
    match std::str::from_utf8(text) {
        Ok(s) => Ok(s.to_string()),
        Err(e) => {
            let line = 1 + text[..e.valid_up_to()].iter().filter(|&&b| b == b'\n').count();
            Err(Error::input(format!("{}:{line}", path.display()), "is not UTF-8 text"))
        }
    }
}

/// `bytes` without a leading UTF-8 byte-order mark.
pub fn strip_bom(bytes: &[u8]) -> &[u8] {
    bytes.strip_prefix(BOM.as_bytes()).unwrap_or(bytes)
}

/// One recorded frame (one rotation) in the recording sensor's frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scan {
    /// Returns, metres, sensor frame. Readers drop non-finite and all-zero points.
    pub points: Vec<[f32; 3]>,
    /// Laser ring per point, when the source has one (pcap, PCD with a `ring` field, a KITTI
    /// `.bin` stored laser by laser: [`kitti::lasers_of`]).
    pub ring: Option<Vec<u16>>,
    /// Elevation of each ring, degrees, indexed by ring, when known (pcap: the sensor's
    /// vertical angle table). A PCD `ring` field comes without one.
    pub ring_elevation_deg: Option<Vec<f64>>,
    /// Capture time of the frame, seconds (pcap: first packet of the rotation), when known.
    pub time_s: Option<f64>,
    /// Intensity per point, in the source's own units, when it has one (pcap: the calibrated
    /// reflectivity byte, 0-255; KITTI `.bin`: remission, 0-1).
    pub intensity: Option<Vec<f32>>,
    /// The recording's own sweep, when it has one (pcap): per firing in capture order, its
    /// azimuth as a fraction of a turn clockwise from straight behind the sensor (pedscan's
    /// column coordinate over the column count, in `[0, 1)`) and the time it was fired, s (the
    /// clock of `time_s`). [`crate::input::sweep::boundary_times`] turns it into
    /// column times.
    pub firing_times: Option<Vec<[f64; 2]>>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_that_cannot_be_opened_are_input_errors_naming_them() {
        let d = tempfile::tempdir().unwrap();
        let p = |name: &str| d.path().join(name);
        std::os::unix::fs::symlink("gone", p("dangling")).unwrap();
        std::os::unix::fs::symlink("looping", p("looping")).unwrap();
        std::fs::create_dir(p("folder")).unwrap();
        for (name, what) in [
            ("missing", "does not exist"),
            ("dangling", "is a symbolic link to nothing"),
            ("looping", "cannot open"),
            ("folder", "is a folder, not a file"),
        ] {
            let e = read_text(&p(name)).unwrap_err();
            assert!(e.is_input(), "{e}");
            assert!(e.to_string().starts_with(&format!("{}: {what}", p(name).display())), "{e}");
        }
        let e = read_bytes(Path::new("/dev/null")).unwrap_err();
        assert!(e.is_input() && e.to_string().contains("not a regular file"), "{e}");
    }

    #[test]
    fn a_folder_lists_the_files_kept_in_path_order_or_names_itself() {
        let d = tempfile::tempdir().unwrap();
        for name in ["b.bin", "a.bin", "c.txt", "10.bin"] {
            std::fs::write(d.path().join(name), b"").unwrap();
        }
        std::fs::create_dir(d.path().join("d.bin")).unwrap();
        let names = |files: Vec<PathBuf>| files.iter().map(|f| f.file_name().unwrap().to_string_lossy().into_owned()).collect::<Vec<_>>();
        let bins = folder_files(d.path(), |f| f.is_file() && f.extension().is_some_and(|e| e == "bin")).unwrap();
        assert_eq!(names(bins), ["10.bin", "a.bin", "b.bin"]);
        assert_eq!(names(folder_files(d.path(), |_| true).unwrap()), ["10.bin", "a.bin", "b.bin", "c.txt", "d.bin"]);
        for bad in [d.path().join("missing"), d.path().join("a.bin")] {
            let e = folder_files(&bad, |_| true).unwrap_err();
            assert!(e.is_input() && e.to_string().starts_with(&format!("{}: cannot list the folder: ", bad.display())), "{e}");
        }
    }

    #[test]
    fn text_loses_its_byte_order_mark_and_must_be_utf8() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("t.txt");
        std::fs::write(&p, "\u{feff}1 2\n").unwrap();
        assert_eq!(read_text(&p).unwrap(), "1 2\n");
        std::fs::write(&p, b"1\n2\n\xff\n").unwrap();
        let e = read_text(&p).unwrap_err();
        assert!(e.is_input() && e.to_string() == format!("{}:3: is not UTF-8 text", p.display()), "{e}");
    }
}
