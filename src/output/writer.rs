//! [`SequenceWriter`]: one sequence's file set, written frame by frame under temporary names
//! (`seq_NNNNNN.h5.tmp`, `seq_NNNNNN.xml.tmp`, `seq_NNNNNN_png.tmp/`) and renamed to the
//! final names only by [`SequenceWriter::finish`]. Dropping a writer that was not finished
//! (an error mid-sequence) deletes every temporary it created, so `out_dir` only ever holds
//! complete sequences.

use super::h5::{Compression, H5Writer};
use super::png::{bev_png, ego_velocity, label_png, range_png, save_png, velocity_png, PNG_MAX_SPEED_MPS, PNG_ROW_SCALE};
use super::ros2bag::Ros2BagWriter;
use super::semantickitti::SemanticKittiWriter;
use super::files::{rename, replace_dir, sequence_stem, tmp_name};
use super::xml::XmlWriter;
use super::{FrameOutput, SequenceMeta};
use crate::debug::{kill_at, KillStage};
use crate::error::{Error, Result};
use std::path::{Path, PathBuf};

/// How a sequence is written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WriterOptions {
    /// Also write debug PNGs per frame into `seq_NNNNNN_png/`.
    pub png: bool,
    pub compression: Compression,
    /// Write the HDF5 file and the XML annotation (`seq_NNNNNN.h5`, `.xml`).
    pub h5: bool,
    /// Write the SemanticKITTI export (`semantickitti/sequences/SS/`).
    pub semantickitti: bool,
    /// Write a ROS 2 bag (`seq_NNNNNN_bag/`).
    pub mcap: bool,
    /// Kill the process with SIGKILL at this stage of the sequence (`debug.kill`).
    pub kill: Option<KillStage>,
}

impl Default for WriterOptions {
    fn default() -> Self {
        WriterOptions { png: false, compression: Compression::default(), h5: true, semantickitti: false, mcap: false, kill: None }
    }
}

/// What [`SequenceWriter::finish`] wrote.
#[derive(Clone, Debug, Default)]
pub struct Finished {
    /// The final paths: the HDF5 file, the XML file, the PNG folder, the SemanticKITTI
    /// sequence folder (those written).
    pub files: Vec<PathBuf>,
    /// Points per class of the SemanticKITTI export, when written.
    pub class_points: Option<super::semantickitti::ClassPoints>,
}

/// Writes one sequence; see the module docs.
pub struct SequenceWriter {
    meta: SequenceMeta,
    h5: Option<H5Writer>,
    xml: Option<XmlWriter>,
    /// (temporary, final) for the HDF5 file, the XML file and the PNG directory.
    h5_path: (PathBuf, PathBuf),
    xml_path: (PathBuf, PathBuf),
    png_dir: Option<(PathBuf, PathBuf)>,
    semantickitti: Option<SemanticKittiWriter>,
    bag: Option<Ros2BagWriter>,
    frames_written: usize,
    /// Set once everything is renamed; `Drop` then leaves the files alone.
    done: bool,
    /// `debug.kill` for this sequence.
    kill: Option<KillStage>,
    /// The sensor's unit beam directions, shared by the formats that write points.
    beam_dirs: std::sync::Arc<[glam::DVec3]>,
    beams: Vec<u32>,
}

impl SequenceWriter {
    /// Creates the temporary files of sequence `meta.index` in `out_dir` (created if missing).
    pub fn create(
        out_dir: &Path,
        meta: &SequenceMeta,
        opts: &WriterOptions,
    ) -> Result<SequenceWriter> {
        if let Compression::Deflate(level) = opts.compression {
            if level > 9 {
                return Err(Error::input(
                    "compression",
                    format!("deflate level {level} is not in 0..=9"),
                ));
            }
        }
        if meta.frames == 0 {
            return Err(Error::input("frames", "a sequence needs at least one frame"));
        }
        if meta.sensor.rows() == 0 || meta.sensor.columns == 0 {
            return Err(Error::Internal("sensor grid has no beams".into()));
        }
        if meta.humans.len() > u16::MAX as usize {
            return Err(Error::Internal(format!(
                "{} humans do not fit u16 instance ids",
                meta.humans.len()
            )));
        }
        std::fs::create_dir_all(out_dir).map_err(|e| Error::io(out_dir, e))?;
        let stem = sequence_stem(meta.index);
        let h5_final = out_dir.join(format!("{stem}.h5"));
        let xml_final = out_dir.join(format!("{stem}.xml"));
        let png_final = out_dir.join(format!("{stem}_png"));
        let mut w = SequenceWriter {
            meta: meta.clone(),
            h5: None,
            xml: None,
            h5_path: (tmp_name(&h5_final), h5_final),
            xml_path: (tmp_name(&xml_final), xml_final),
            png_dir: None,
            semantickitti: None,
            bag: None,
            frames_written: 0,
            done: false,
            kill: opts.kill,
            beam_dirs: if opts.png || opts.semantickitti || opts.mcap { meta.sensor.beam_dirs().into() } else { Vec::new().into() },
            beams: vec![0; meta.humans.len()],
        };
        // From here on, an early return drops `w`, which removes whatever was created.
        if opts.png {
            let tmp = tmp_name(&png_final);
            if tmp.exists() {
                std::fs::remove_dir_all(&tmp).map_err(|e| Error::io(&tmp, e))?;
            }
            w.png_dir = Some((tmp.clone(), png_final));
            std::fs::create_dir(&tmp).map_err(|e| Error::io(&tmp, e))?;
        }
        if !opts.h5 && !opts.semantickitti && !opts.mcap {
            return Err(Error::input("formats", "no output format: give at least one of h5, semantickitti, mcap"));
        }
        if opts.h5 {
            w.xml = Some(XmlWriter::create(&w.xml_path.0, meta)?);
            w.h5 = Some(H5Writer::create(&w.h5_path.0, &w.h5_path.1, meta, opts.compression)?);
        }
        if opts.semantickitti {
            w.semantickitti = Some(SemanticKittiWriter::create(out_dir, meta, w.beam_dirs.clone())?);
        }
        if opts.mcap {
            w.bag = Some(Ros2BagWriter::create(out_dir, meta, w.beam_dirs.clone())?);
        }
        Ok(w)
    }

    /// Number of frames written so far.
    pub fn frames_written(&self) -> usize {
        self.frames_written
    }

    /// Writes the next frame. Grids must have `rows * columns` entries (optional ones only
    /// when enabled in `meta.outputs`) and `humans` one entry per person of the sequence.
    pub fn write_frame(&mut self, frame: &FrameOutput) -> Result<()> {
        let index = self.frames_written;
        self.validate(index, frame)?;
        self.count_beams(index, frame)?;
        if let Some(xml) = self.xml.as_mut() {
            xml.frame(index, frame, &self.beams)?;
        }
        if let Some(h5) = self.h5.as_mut() {
            h5.write_frame(index, frame)?;
        }
        if let Some(sk) = self.semantickitti.as_mut() {
            sk.write_frame(index, frame)?;
        }
        if let Some(bag) = self.bag.as_mut() {
            bag.write_frame(index, frame)?;
        }
        if let Some((dir, _)) = &self.png_dir {
            self.write_pngs(dir, index, frame)?;
        }
        self.frames_written += 1;
        kill_at(self.kill, KillStage::Frame(index));
        Ok(())
    }

    fn validate(&self, index: usize, f: &FrameOutput) -> Result<()> {
        let m = &self.meta;
        if index >= m.frames {
            return Err(Error::Internal(format!(
                "sequence {}: frame {index} is beyond the announced {} frames",
                m.index, m.frames
            )));
        }
        let n = m.sensor.rows() * m.sensor.columns;
        let bad = |what: &str, len: usize| {
            Err(Error::Internal(format!(
                "sequence {} frame {index}: {what} has {len} entries, expected {n} ({} x {})",
                m.index,
                m.sensor.rows(),
                m.sensor.columns
            )))
        };
        let checks = [
            ("range", f.range.len(), true),
            ("label", f.label.len(), true),
            ("instance", f.instance.len(), true),
            ("xyz", f.xyz.len(), m.outputs.xyz),
            ("velocity", f.velocity.len(), m.outputs.velocity),
            ("background_range", f.background_range.len(), m.outputs.background),
            ("intensity", f.intensity.len(), true),
            ("class", f.class.len(), m.outputs.class),
            ("clean_range", f.clean_range.len(), m.outputs.clean),
            ("clean_label", f.clean_label.len(), m.outputs.clean),
            ("clean_instance", f.clean_instance.len(), m.outputs.clean),
        ];
        for (what, len, needed) in checks {
            if needed && len != n {
                return bad(what, len);
            }
        }
        if f.column_time_s.len() != m.sensor.columns {
            return Err(Error::Internal(format!(
                "sequence {} frame {index}: {} column times for {} columns",
                m.index,
                f.column_time_s.len(),
                m.sensor.columns
            )));
        }
        if f.movers.len() != m.movers.len() {
            return Err(Error::Internal(format!(
                "sequence {} frame {index}: {} mover states for {} movers",
                m.index,
                f.movers.len(),
                m.movers.len()
            )));
        }
        if f.humans.len() != m.humans.len() {
            return Err(Error::Internal(format!(
                "sequence {} frame {index}: {} human states for {} humans",
                m.index,
                f.humans.len(),
                m.humans.len()
            )));
        }
        Ok(())
    }

    fn count_beams(&mut self, index: usize, f: &FrameOutput) -> Result<()> {
        let n = self.beams.len();
        let mut counts = vec![0u32; n + 1];
        let mut max = 0u16;
        for &k in &f.instance {
            max = max.max(k);
            if (k as usize) <= n {
                counts[k as usize] += 1;
            }
        }
        let movers = self.meta.movers.len();
        if max as usize > n + movers {
            return Err(Error::Internal(format!(
                "sequence {} frame {index}: instance {max} but only {n} humans and {movers} movers",
                self.meta.index
            )));
        }
        self.beams.copy_from_slice(&counts[1..]);
        Ok(())
    }

    fn write_pngs(&self, dir: &Path, index: usize, f: &FrameOutput) -> Result<()> {
        let (rows, cols) = (self.meta.sensor.rows(), self.meta.sensor.columns);
        let max_r = self.meta.sensor.max_range_m as f32;
        let velocity = self.meta.outputs.velocity;
        let point = |i: usize| f.point(&self.beam_dirs, i).unwrap_or([0.0; 3]);
        let m = &f.world_from_sensor;
        // Sensor frame of a world vector: R^T v.
        let to_sensor = |v: [f64; 3]| -> [f64; 3] { std::array::from_fn(|j| m[0][j] * v[0] + m[1][j] * v[1] + m[2][j] * v[2]) };
        let range = || {
            save_png(
                &range_png(&f.range, rows, cols, max_r, PNG_ROW_SCALE),
                &dir.join(format!("range_{index:04}.png")),
            )
        };
        let label = || {
            save_png(
                &label_png(&f.range, &f.instance, rows, cols, max_r, PNG_ROW_SCALE),
                &dir.join(format!("label_{index:04}.png")),
            )
        };
        let vel = || {
            if !velocity {
                return Ok(());
            }
            let ego = |i: usize| ego_velocity(m, f.sensor_velocity_mps, f.sensor_yaw_rate_rps, self.meta.rigid_velocity, point(i));
            save_png(
                &velocity_png(&f.range, &f.velocity, ego, rows, cols, PNG_MAX_SPEED_MPS, PNG_ROW_SCALE),
                &dir.join(format!("velocity_{index:04}.png")),
            )
        };
        let bev = || {
            let xyz: Vec<[f32; 3]> = (0..f.range.len()).map(point).collect();
            let t = [m[0][3], m[1][3], m[2][3]];
            let people: Vec<([f64; 3], [f64; 3])> = f
                .humans
                .iter()
                .map(|h| {
                    let p = h.position_m;
                    let v = h.velocity_mps.map(|c| c as f64);
                    (to_sensor([p[0] - t[0], p[1] - t[1], p[2] - t[2]]), to_sensor(v))
                })
                .collect();
            save_png(
                &bev_png(&xyz, &f.range, &f.instance, &people, to_sensor(f.sensor_velocity_mps)),
                &dir.join(format!("bev_{index:04}.png")),
            )
        };
        let intensity = || {
            save_png(
                &crate::output::png::intensity_png(&f.intensity, &f.range, rows, cols, PNG_ROW_SCALE),
                &dir.join(format!("intensity_{index:04}.png")),
            )
        };
        let ((a, b), ((c, d), e)) = rayon::join(|| rayon::join(range, label), || rayon::join(|| rayon::join(vel, bev), intensity));
        a.and(b).and(c).and(d).and(e)
    }

    /// Checks that every announced frame was written, closes the files and renames them to
    /// their final names (replacing those of an earlier run). Returns the final paths: the
    /// HDF5 file, the XML file and, with PNGs, the PNG directory.
    pub fn finish(mut self) -> Result<Finished> {
        if self.frames_written != self.meta.frames {
            return Err(Error::Internal(format!(
                "sequence {}: finished after {} of {} frames",
                self.meta.index, self.frames_written, self.meta.frames
            )));
        }
        let h5 = self.h5.is_some();
        if let Some(xml) = self.xml.take() {
            xml.finish()?;
        }
        if let Some(file) = self.h5.take() {
            file.finish(&self.meta)?;
            let tmp = &self.h5_path.0;
            std::fs::File::open(tmp).and_then(|f| f.sync_all()).map_err(|e| Error::io(tmp, e))?;
        }

        // Every final name must be free or a file of an earlier run (never a folder, which
        // a rename cannot replace) before the first rename, so that the files of a sequence
        // appear together or not at all.
        if h5 {
            for fin in [&self.xml_path.1, &self.h5_path.1] {
                if std::fs::symlink_metadata(fin).is_ok_and(|m| !m.is_file()) {
                    return Err(Error::input(fin.display(), "exists and is not a file; cannot replace it with the sequence's file"));
                }
            }
        }
        let sk_final = self.semantickitti.as_ref().map(|sk| sk.final_dir().to_path_buf());
        let bag_final = self.bag.as_ref().map(|b| b.final_dir().to_path_buf());
        // Their temporaries: a writer taken out below and failing in its own finish (a full
        // disk) is gone before `Drop` could remove them.
        let tmps: Vec<PathBuf> =
            self.semantickitti.as_ref().map(|sk| sk.tmp_dir().to_path_buf()).into_iter().chain(self.bag.as_ref().map(|b| b.tmp_dir().to_path_buf())).collect();
        for fin in self.png_dir.iter().map(|(_, f)| f).chain(sk_final.iter()).chain(bag_final.iter()) {
            if std::fs::symlink_metadata(fin).is_ok_and(|m| !m.is_dir()) {
                return Err(Error::input(fin.display(), "exists and is not a folder; cannot replace it with the sequence's files"));
            }
        }
        // PNGs, SemanticKITTI and XML first, the HDF5 file last. If a later rename fails,
        // the earlier ones are undone.
        let mut done = Finished::default();
        let mut undo: Vec<PathBuf> = Vec::new();
        let kill = self.kill;
        let mut renames = 0;
        let mut renamed_one = || {
            renames += 1;
            kill_at(kill, KillStage::Rename(renames));
        };
        let renamed = (|| -> Result<()> {
            if let Some((tmp, fin)) = &self.png_dir {
                replace_dir(tmp, fin)?;
                undo.push(fin.clone());
                renamed_one();
            }
            if let Some(sk) = self.semantickitti.take() {
                let (fin, counts) = sk.finish()?;
                undo.push(fin);
                done.class_points = Some(counts);
                renamed_one();
            }
            if let Some(bag) = self.bag.take() {
                undo.push(bag.finish()?);
                renamed_one();
            }
            if h5 {
                rename(&self.xml_path.0, &self.xml_path.1)?;
                undo.push(self.xml_path.1.clone());
                renamed_one();
                rename(&self.h5_path.0, &self.h5_path.1)?;
                renamed_one();
            }
            Ok(())
        })();
        if let Err(e) = renamed {
            for p in undo.iter().chain(&tmps) {
                let _ = if p.is_dir() { std::fs::remove_dir_all(p) } else { std::fs::remove_file(p) };
            }
            return Err(e);
        }
        self.done = true;
        if h5 {
            done.files.push(self.h5_path.1.clone());
            done.files.push(self.xml_path.1.clone());
        }
        if let Some((_, fin)) = &self.png_dir {
            done.files.push(fin.clone());
        }
        done.files.extend(sk_final);
        done.files.extend(bag_final);
        Ok(done)
    }
}

impl Drop for SequenceWriter {
    fn drop(&mut self) {
        if self.done {
            return;
        }
        // Close the handles first, then remove what exists; errors are ignored (best effort
        // while already failing).
        drop(self.h5.take());
        drop(self.xml.take());
        let _ = std::fs::remove_file(&self.h5_path.0);
        let _ = std::fs::remove_file(&self.xml_path.0);
        if let Some((tmp, _)) = &self.png_dir {
            let _ = std::fs::remove_dir_all(tmp);
        }
        if let Some(sk) = self.semantickitti.take() {
            let _ = std::fs::remove_dir_all(sk.tmp_dir());
        }
        if let Some(bag) = self.bag.take() {
            let tmp = bag.tmp_dir().to_path_buf();
            drop(bag);
            let _ = std::fs::remove_dir_all(tmp);
        }
    }
}
