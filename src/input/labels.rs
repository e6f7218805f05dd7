//! SemanticKITTI point labels of a recorded background (`scene.ignore_labels`): a folder of
//! `.label` files, one per KITTI `.bin` frame of the background with the same stem
//! (`labels/NNNNNN.label` beside `velodyne/NNNNNN.bin`), each a little-endian `u32` per record
//! of its scan (the scan's points in the file's order, all-zero and non-finite records
//! included), `instance << 16 | class`.
//!
//! The cells of a frame that points of the chosen classes (lower 16 bits) project to, by the
//! very projection of the background's images ([`Projector::project_points`] over
//! [`kitti::read_bin_records`]), are the frame's labeled cells: `generate` makes them not
//! scored ([`crate::scene::not_scored`]). Every label file is checked when the run starts
//! (there, a regular file, four bytes per record of its scan), so a missing or cut one is
//! named before anything is written.

use super::project::{Projector, NO_CELL};
use super::{file_len, kitti, read_bytes};
use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// SemanticKITTI's people and riders: person 30, bicyclist 31, motorcyclist 32 and their
/// moving classes 254, 253, 255 (`scene.ignore_classes`' default).
pub const PEOPLE_CLASSES: [u32; 6] = [30, 31, 32, 253, 254, 255];

/// Bytes per label: one `u32`.
const LABEL_BYTES: u64 = 4;
/// Bytes per `.bin` record: four `f32`.
const RECORD_BYTES: u64 = 16;

/// The label file of each frame of a KITTI background, checked, and the classes marked.
#[derive(Clone, Debug)]
pub struct FrameLabels {
    scans: Vec<PathBuf>,
    labels: Vec<PathBuf>,
    classes: Vec<u32>,
}

impl FrameLabels {
    /// The label files in `dir` for the frame files `scans` (a KITTI `.bin` background's, in
    /// frame order): each `dir/<stem>.label`, a regular file of four bytes per record of its
    /// scan. `classes`: the lower 16 bits that mark a point.
    pub fn open(scans: &[PathBuf], dir: &Path, classes: &[u32]) -> Result<FrameLabels> {
        if !dir.is_dir() {
            return Err(Error::input(dir.display(), "is not a folder of SemanticKITTI .label files (scene.ignore_labels)"));
        }
        let mut labels = Vec::with_capacity(scans.len());
        for scan in scans {
            if !scan.extension().is_some_and(|e| e.eq_ignore_ascii_case("bin")) {
                return Err(Error::input(scan.display(), "label files (scene.ignore_labels) go with KITTI .bin frames only"));
            }
            let stem = scan.file_stem().unwrap_or_default();
            let label = dir.join(stem).with_extension("label");
            let points = file_len(scan)? / RECORD_BYTES;
            let len = file_len(&label)?;
            if len != points * LABEL_BYTES {
                return Err(Error::input(label.display(), wrong_length(len, points, scan)));
            }
            labels.push(label);
        }
        Ok(FrameLabels { scans: scans.to_vec(), labels, classes: classes.to_vec() })
    }

    /// Frames with labels.
    pub fn len(&self) -> usize {
        self.labels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.labels.is_empty()
    }

    /// The cells of frame `k` on `projector`'s grid that a point of the marked classes
    /// projects to (also where a nearer point keeps the cell), ascending, each once.
    pub fn cells(&self, k: usize, projector: &Projector) -> Result<Vec<u32>> {
        let (scan, label) = (&self.scans[k], &self.labels[k]);
        let bin = kitti::read_bin_records(scan)?;
        let bytes = read_bytes(label)?;
        // Checked when the run started; a file changed since is named all the same.
        if bytes.len() as u64 != bin.records as u64 * LABEL_BYTES {
            return Err(Error::input(label.display(), wrong_length(bytes.len() as u64, bin.records as u64, scan)));
        }
        let (mut range, mut intensity, mut cells) = (Vec::new(), Vec::new(), Vec::new());
        projector.project_points(&bin.scan, &mut range, &mut intensity, &mut cells);
        let class_of = |record: u32| {
            let at = record as usize * LABEL_BYTES as usize;
            u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]) & 0xFFFF
        };
        let mut out: Vec<u32> = cells
            .iter()
            .zip(&bin.record_of_point)
            .filter(|(&c, &r)| c != NO_CELL && self.classes.contains(&class_of(r)))
            .map(|(&c, _)| c)
            .collect();
        out.sort_unstable();
        out.dedup();
        Ok(out)
    }
}

/// What is wrong with a label file of `len` bytes for a scan of `points` records.
fn wrong_length(len: u64, points: u64, scan: &Path) -> String {
    format!(
        "{len} bytes of labels for the {points} points of {}: want {} (one 4-byte label per point)",
        scan.display(),
        points * LABEL_BYTES
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::Sensor;

    /// A scan of `points` (x y z) and its labels, as `dir/velodyne/NAME.bin` and
    /// `dir/labels/NAME.label`.
    fn write(dir: &Path, name: &str, points: &[([f32; 3], u32)]) -> PathBuf {
        let (velo, lab) = (dir.join("velodyne"), dir.join("labels"));
        std::fs::create_dir_all(&velo).unwrap();
        std::fs::create_dir_all(&lab).unwrap();
        let bin: Vec<u8> = points.iter().flat_map(|(p, _)| [p[0], p[1], p[2], 0.5]).flat_map(f32::to_le_bytes).collect();
        let labels: Vec<u8> = points.iter().flat_map(|(_, l)| l.to_le_bytes()).collect();
        std::fs::write(velo.join(format!("{name}.bin")), bin).unwrap();
        std::fs::write(lab.join(format!("{name}.label")), labels).unwrap();
        velo.join(format!("{name}.bin"))
    }

    #[test]
    fn the_cells_of_marked_points_are_found_by_the_backgrounds_projection() {
        let d = tempfile::tempdir().unwrap();
        let s = Sensor::hdl32e();
        let proj = Projector::new(&s);
        // A person (30) ahead, a moving person (254, instance 3) to the left, a car (10)
        // behind, a dropped all-zero record labeled person between them, and a person point
        // behind a nearer car point in the same cell.
        let scan = write(
            d.path(),
            "000000",
            &[
                ([10.0, 0.0, 0.0], 30),
                ([0.0, 8.0, 0.0], (3 << 16) | 254),
                ([0.0, 0.0, 0.0], 30),
                ([-6.0, 0.0, 0.0], 10),
                ([0.0, -5.0, 0.0], 10),
                ([0.0, -9.0, 0.0], 30),
            ],
        );
        let labels = FrameLabels::open(std::slice::from_ref(&scan), &d.path().join("labels"), &PEOPLE_CLASSES).unwrap();
        assert_eq!(labels.len(), 1);
        let cell = |x: f64, y: f64| {
            let mut range = Vec::new();
            let mut cells = Vec::new();
            let p = crate::input::Scan { points: vec![[x as f32, y as f32, 0.0]], ..Default::default() };
            proj.project_points(&p, &mut range, &mut Vec::new(), &mut cells);
            cells[0]
        };
        let mut want = vec![cell(10.0, 0.0), cell(0.0, 8.0), cell(0.0, -9.0)];
        want.sort_unstable();
        assert_eq!(labels.cells(0, &proj).unwrap(), want);
        // Only the car's class: its two cells (the one it shares with a person too).
        let cars = FrameLabels::open(&[scan], &d.path().join("labels"), &[10]).unwrap();
        let mut want = vec![cell(-6.0, 0.0), cell(0.0, -5.0)];
        want.sort_unstable();
        assert_eq!(cars.cells(0, &proj).unwrap(), want);
    }

    #[test]
    fn missing_or_cut_label_files_are_named() {
        let d = tempfile::tempdir().unwrap();
        let a = write(d.path(), "000000", &[([10.0, 0.0, 0.0], 30), ([0.0, 0.0, 0.0], 0)]);
        let b = write(d.path(), "000001", &[([10.0, 0.0, 0.0], 30)]);
        let dir = d.path().join("labels");
        let err = |scans: &[PathBuf], dir: &Path| FrameLabels::open(scans, dir, &PEOPLE_CLASSES).unwrap_err();
        // One label per record, the dropped all-zero record's too.
        std::fs::write(dir.join("000000.label"), [0u8; 4]).unwrap();
        let e = err(&[a.clone(), b.clone()], &dir);
        assert!(e.is_input(), "{e}");
        assert_eq!(e.to_string(), format!("{}: 4 bytes of labels for the 2 points of {}: want 8 (one 4-byte label per point)", dir.join("000000.label").display(), a.display()));
        std::fs::write(dir.join("000000.label"), [0u8; 8]).unwrap();
        std::fs::remove_file(dir.join("000001.label")).unwrap();
        let e = err(&[a.clone(), b.clone()], &dir);
        assert_eq!(e.to_string(), format!("{}: does not exist", dir.join("000001.label").display()));
        // Not a folder; a PCD frame.
        let e = err(std::slice::from_ref(&a), &d.path().join("nowhere"));
        assert!(e.to_string().contains("is not a folder of SemanticKITTI .label files"), "{e}");
        let e = err(&[d.path().join("x.pcd")], &dir);
        assert!(e.to_string().contains("KITTI .bin frames only"), "{e}");
    }
}
