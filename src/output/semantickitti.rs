//! The SemanticKITTI export (`--formats ...,semantickitti`): the layout most point-cloud
//! segmentation code reads unchanged (RangeNet++, SalsaNext, CENet, LMNet / LiDAR-MOS, 4DMOS),
//! under `OUT/semantickitti/`:
//!
//! ```text
//! pedscan.yaml                        labels, color_map, content, learning_map(_inv),
//!                                     learning_ignore, split (semantic-kitti-api's format)
//! sequences/SS/velodyne/NNNNNN.bin    f32 x y z remission per returned beam (sensor frame)
//! sequences/SS/labels/NNNNNN.label    u32 instance << 16 | class, same order
//! sequences/SS/velocity/NNNNNN.bin    f32 vx vy vz per point, same order (pedscan's sidecar)
//! sequences/SS/poses.txt              3x4 world_from_sensor per frame (row-major)
//! sequences/SS/calib.txt              P0..P3 and Tr = identity, so loaders that compute
//!                                     inv(Tr) pose Tr get world_from_sensor back
//! sequences/SS/times.txt              seconds from the sequence start
//! ```
//!
//! Points are the returned beams in row-major grid order (row 0 = highest beam), holes
//! skipped. Remission is `/intensity`. Classes: person 30, moving-person
//! 254 (the person walks faster than [`MOVING_SPEED_MPS`]); a background point takes `/class`
//! (a built-in world's road 40, sidewalk 48, building 50, car 10, vegetation 70, ...: the ids
//! of [`CLASS_NAMES`]), and 50 (SemanticKITTI's "building") where the background does not say
//! what it is (a glTF without `extras.class`, a recording: this class, unlike 0, 1, 52 or 99,
//! is one the common learning maps keep); a not-scored beam (`/label` 255, a recorded
//! background's own person) is 0, "unlabeled", which the learning maps ignore. A sequence is written into `SS.tmp/` and
//! renamed to `SS/` when complete.

use crate::error::{Error, Result};
use super::files::write_file;
use crate::output::{FrameOutput, SequenceMeta, NOT_SCORED};
use glam::DVec3;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// SemanticKITTI's class of a person.
pub const PERSON: u32 = 30;
/// SemanticKITTI's class of a moving person (LiDAR-MOS: classes >= 250 move).
pub const MOVING_PERSON: u32 = 254;
/// SemanticKITTI's "unlabeled": a not-scored point (`/label` 255).
pub const UNLABELED: u32 = 0;
/// The class pedscan gives every background point.
pub const BACKGROUND: u32 = 50;
/// SemanticKITTI's names and colours (BGR, semantic-kitti.yaml) of the classes pedscan writes.
pub const CLASS_NAMES: [(u16, &str, [u8; 3]); 24] = [
    (0, "unlabeled", [0, 0, 0]),
    (10, "car", [245, 150, 100]),
    (11, "bicycle", [245, 230, 100]),
    (18, "truck", [180, 30, 80]),
    (20, "other-vehicle", [255, 0, 0]),
    (30, "person", [30, 30, 255]),
    (31, "bicyclist", [200, 40, 255]),
    (40, "road", [255, 0, 255]),
    (48, "sidewalk", [75, 0, 75]),
    (49, "other-ground", [75, 0, 175]),
    (50, "building", [0, 200, 255]),
    (51, "fence", [50, 120, 255]),
    (52, "other-structure", [0, 150, 255]),
    (60, "lane-marking", [150, 255, 170]),
    (70, "vegetation", [0, 175, 0]),
    (71, "trunk", [0, 60, 135]),
    (72, "terrain", [80, 240, 150]),
    (80, "pole", [150, 240, 255]),
    (81, "traffic-sign", [0, 0, 255]),
    (99, "other-object", [255, 255, 50]),
    (252, "moving-car", [245, 150, 100]),
    (253, "moving-bicyclist", [255, 40, 200]),
    (254, "moving-person", [255, 30, 30]),
    (259, "moving-other-vehicle", [255, 0, 0]),
];

/// A person walking faster than this (horizontal world speed, m/s) is a moving person.
pub const MOVING_SPEED_MPS: f64 = 0.1;
/// The export's folder under the output folder.
pub const FOLDER: &str = "semantickitti";

/// The folder name of sequence `index`: at least two digits, like SemanticKITTI's.
pub fn sequence_dir_name(index: usize) -> String {
    format!("{index:02}")
}

/// The final folder of sequence `index` under `out_dir`.
pub fn sequence_dir(out_dir: &Path, index: usize) -> PathBuf {
    out_dir.join(FOLDER).join("sequences").join(sequence_dir_name(index))
}

/// Points per class of one sequence: background, person, moving person, unlabeled (not
/// scored; left out of a manifest entry while 0, as it was before such points existed).
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ClassPoints {
    pub background: u64,
    pub person: u64,
    pub moving_person: u64,
    #[serde(default, skip_serializing_if = "is_zero")]
    pub unlabeled: u64,
    /// The background points by class (`/class`), when the frames carry classes.
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub background_classes: std::collections::BTreeMap<u16, u64>,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

impl ClassPoints {
    pub fn add(&mut self, o: &ClassPoints) {
        self.background += o.background;
        self.person += o.person;
        self.moving_person += o.moving_person;
        self.unlabeled += o.unlabeled;
        for (c, n) in &o.background_classes {
            *self.background_classes.entry(*c).or_insert(0) += n;
        }
    }
}

/// Writes one sequence of the export.
pub struct SemanticKittiWriter {
    tmp: PathBuf,
    fin: PathBuf,
    dirs: Arc<[DVec3]>,
    velocity: bool,
    poses: String,
    times: String,
    counts: ClassPoints,
    /// Per-frame scratch: points, labels, velocities as bytes.
    points: Vec<u8>,
    labels: Vec<u8>,
    velocities: Vec<u8>,
}

fn create_dir(p: &Path) -> Result<()> {
    std::fs::create_dir_all(p).map_err(|e| Error::io(p, e))
}


impl SemanticKittiWriter {
    /// Creates `OUT/semantickitti/sequences/SS.tmp/` (an older one is replaced).
    /// `dirs`: the sensor's unit beam directions.
    pub fn create(out_dir: &Path, meta: &SequenceMeta, dirs: Arc<[DVec3]>) -> Result<SemanticKittiWriter> {
        let fin = sequence_dir(out_dir, meta.index);
        let tmp = super::files::fresh_tmp_dir(&fin)?;
        create_dir(&tmp.join("velodyne"))?;
        create_dir(&tmp.join("labels"))?;
        if meta.outputs.velocity {
            create_dir(&tmp.join("velocity"))?;
        }
        Ok(SemanticKittiWriter {
            tmp,
            fin,
            dirs,
            velocity: meta.outputs.velocity,
            poses: String::new(),
            times: String::new(),
            counts: ClassPoints::default(),
            points: Vec::new(),
            labels: Vec::new(),
            velocities: Vec::new(),
        })
    }

    /// The folder the sequence gets when complete.
    pub fn final_dir(&self) -> &Path {
        &self.fin
    }

    /// The temporary folder (removed by the owner when the sequence fails).
    pub fn tmp_dir(&self) -> &Path {
        &self.tmp
    }

    /// Writes frame `index`: its point, label and velocity files; keeps its pose and time.
    pub fn write_frame(&mut self, index: usize, f: &FrameOutput) -> Result<()> {
        self.points.clear();
        self.labels.clear();
        self.velocities.clear();
        for b in 0..f.range.len() {
            let Some([x, y, z]) = f.point(&self.dirs, b) else { continue };
            for c in [x, y, z, f.intensity[b]] {
                self.points.extend_from_slice(&c.to_le_bytes());
            }
            let k = f.instance[b] as usize;
            let class_of = f.class.get(b).copied().filter(|&c| c != 0);
            let class = if f.label.get(b) == Some(&NOT_SCORED) && class_of.is_none() {
                self.counts.unlabeled += 1;
                UNLABELED
            } else if f.label.get(b) != Some(&1) {
                // The background, a mover (its instance above the people's), or a rider (not
                // scored, but of its own class).
                self.counts.background += 1;
                match class_of {
                    Some(c) => {
                        *self.counts.background_classes.entry(c).or_insert(0) += 1;
                        c as u32
                    }
                    _ => BACKGROUND,
                }
            } else {
                let v = f.humans.get(k - 1).map_or([0.0; 3], |h| h.velocity_mps);
                if (v[0] as f64).hypot(v[1] as f64) > MOVING_SPEED_MPS {
                    self.counts.moving_person += 1;
                    MOVING_PERSON
                } else {
                    self.counts.person += 1;
                    PERSON
                }
            };
            self.labels.extend_from_slice(&(((k as u32) << 16) | class).to_le_bytes());
            if self.velocity {
                for c in f.velocity[b] {
                    self.velocities.extend_from_slice(&c.to_le_bytes());
                }
            }
        }
        let name = format!("{index:06}");
        write_file(&self.tmp.join("velodyne").join(format!("{name}.bin")), &self.points)?;
        write_file(&self.tmp.join("labels").join(format!("{name}.label")), &self.labels)?;
        if self.velocity {
            write_file(&self.tmp.join("velocity").join(format!("{name}.bin")), &self.velocities)?;
        }
        let m = f.world_from_sensor;
        let row = |r: [f64; 4]| format!("{:e} {:e} {:e} {:e}", r[0], r[1], r[2], r[3]);
        let _ = writeln!(self.poses, "{} {} {}", row(m[0]), row(m[1]), row(m[2]));
        let _ = writeln!(self.times, "{:e}", f.time_s);
        Ok(())
    }

    /// Writes poses, times and calibration, then renames `SS.tmp/` to `SS/` (replacing an
    /// older one). Returns the final folder and the points per class.
    pub fn finish(self) -> Result<(PathBuf, ClassPoints)> {
        write_file(&self.tmp.join("poses.txt"), self.poses.as_bytes())?;
        write_file(&self.tmp.join("times.txt"), self.times.as_bytes())?;
        let eye = "1 0 0 0 0 1 0 0 0 0 1 0";
        let calib: String = ["P0", "P1", "P2", "P3", "Tr"].iter().map(|k| format!("{k}: {eye}\n")).collect();
        write_file(&self.tmp.join("calib.txt"), calib.as_bytes())?;
        super::files::replace_dir(&self.tmp, &self.fin)?;
        Ok((self.fin, self.counts))
    }
}

/// `pedscan.yaml`: the export's label configuration in semantic-kitti-api's format. Learning
/// classes: 0 ignored (unlabeled), 1 background, 2 person (moving or not); `content` is each
/// class's share of the points in `counts`; the split puts sequences with index 8 modulo 10 in
/// `valid`, 9 in `test`, the rest in `train`.
pub fn yaml(counts: &ClassPoints, sequences: &[usize]) -> String {
    let total = (counts.background + counts.person + counts.moving_person + counts.unlabeled).max(1) as f64;
    let list = |keep: &dyn Fn(usize) -> bool| {
        let v: Vec<String> = sequences.iter().filter(|&&s| keep(s)).map(|&s| s.to_string()).collect();
        format!("[{}]", v.join(", "))
    };
    // Background points by class: those the frames gave a class, the rest under 50.
    let classed: u64 = counts.background_classes.values().sum();
    let mut background = counts.background_classes.clone();
    *background.entry(BACKGROUND as u16).or_insert(0) += counts.background.saturating_sub(classed);
    let named = !counts.background_classes.is_empty();
    let mut rows: Vec<(u16, String, [u8; 3], u64, u8)> = vec![(0, "unlabeled".into(), [0, 0, 0], counts.unlabeled, 0)];
    rows.push((PERSON as u16, "person".into(), [30, 30, 255], counts.person, 2));
    for (&c, &n) in &background {
        let known = CLASS_NAMES.iter().find(|k| k.0 == c);
        let name = match known {
            // An export without classes keeps calling its one background class so.
            _ if c == BACKGROUND as u16 && !named => "background".to_string(),
            Some(k) => k.1.to_string(),
            None => format!("class-{c}"),
        };
        rows.push((c, name, known.map_or([200, 200, 200], |k| k.2), n, 1));
    }
    rows.push((MOVING_PERSON as u16, "moving-person".into(), [255, 30, 30], counts.moving_person, 2));
    rows.sort_by_key(|r| r.0);
    rows.dedup_by_key(|r| r.0);
    let mut out = String::from("# pedscan's SemanticKITTI export: labels in semantic-kitti-api's config format.\nname: \"pedscan\"\nlabels:\n");
    for r in &rows {
        let _ = writeln!(out, "  {}: \"{}\"", r.0, r.1);
    }
    out.push_str("color_map: # bgr\n");
    for r in &rows {
        let _ = writeln!(out, "  {}: [{}, {}, {}]", r.0, r.2[0], r.2[1], r.2[2]);
    }
    out.push_str("content: # share of all points\n");
    for r in &rows {
        let _ = writeln!(out, "  {}: {:.9}", r.0, r.3 as f64 / total);
    }
    out.push_str("learning_map:\n");
    for r in &rows {
        let _ = writeln!(out, "  {}: {}", r.0, r.4);
    }
    let _ = write!(
        out,
        "learning_map_inv:\n  0: 0\n  1: {BACKGROUND}\n  2: {PERSON}\n\
         learning_ignore:\n  0: True\n  1: False\n  2: False\n\
         split:\n  train: {}\n  valid: {}\n  test: {}\n",
        list(&|s| s % 10 < 8),
        list(&|s| s % 10 == 8),
        list(&|s| s % 10 == 9),
    );
    out
}

/// Writes `OUT/semantickitti/pedscan.yaml` atomically.
pub fn write_yaml(out_dir: &Path, counts: &ClassPoints, sequences: &[usize]) -> Result<()> {
    let dir = out_dir.join(FOLDER);
    create_dir(&dir)?;
    let fin = dir.join("pedscan.yaml");
    let tmp = super::files::tmp_name(&fin);
    write_file(&tmp, yaml(counts, sequences).as_bytes())?;
    std::fs::rename(&tmp, &fin).map_err(|e| Error::io(&fin, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_yaml_splits_sequences_and_shares_points() {
        let y = yaml(&ClassPoints { background: 6, person: 1, moving_person: 3, ..Default::default() }, &[0, 1, 8, 9, 18]);
        assert!(y.contains("train: [0, 1]") && y.contains("valid: [8, 18]") && y.contains("test: [9]"), "{y}");
        assert!(y.contains("30: 0.100000000") && y.contains("50: 0.600000000") && y.contains("254: 0.300000000"), "{y}");
        assert!(y.contains("50: \"background\"") && !y.contains("building"), "{y}");
    }

    #[test]
    fn the_yaml_names_every_background_class_and_maps_it_to_background() {
        let classes = [(40, 2), (10, 1), (50, 1)].into_iter().collect();
        // Six background points: four with a class, two without (written as 50).
        let y = yaml(&ClassPoints { background: 6, person: 2, moving_person: 2, background_classes: classes, ..Default::default() }, &[0]);
        for line in ["10: \"car\"", "40: \"road\"", "50: \"building\"", "  40: 0.200000000", "  50: 0.300000000", "  10: 0.100000000"] {
            assert!(y.contains(line), "{line}: {y}");
        }
        let map = &y[y.find("learning_map:").unwrap()..y.find("learning_map_inv:").unwrap()];
        assert_eq!(map, "learning_map:\n  0: 0\n  10: 1\n  30: 2\n  40: 1\n  50: 1\n  254: 2\n");
    }
}
