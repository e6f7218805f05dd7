//! The per-sequence XML summary (stage 5): the people of the sequence, then per frame the
//! number of humans in the scene, how many are visible, and each one's world position,
//! heading, speed, gait phase, height, weight and number of beams that hit it.
//!
//! Streamed: the header is written at creation, one `<frame>` element per frame, the closing
//! tag at [`XmlWriter::finish`]. Numbers use fixed decimals so reruns are byte-identical.

use super::{FrameOutput, SequenceMeta};
use crate::error::{Error, Result};
use quick_xml::events::{BytesDecl, BytesEnd, BytesStart, Event};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

pub(crate) struct XmlWriter {
    w: quick_xml::Writer<BufWriter<File>>,
    path: PathBuf,
    /// (height, weight) text per human, repeated in every frame.
    human_text: Vec<(String, String)>,
}

impl XmlWriter {
    /// Creates `path` and writes the header and the `<human>` list.
    pub(crate) fn create(path: &Path, meta: &SequenceMeta) -> Result<XmlWriter> {
        let file = File::create(path).map_err(|e| Error::io(path, e))?;
        let mut x = XmlWriter {
            w: quick_xml::Writer::new_with_indent(BufWriter::with_capacity(1 << 16, file), b' ', 2),
            path: path.to_path_buf(),
            human_text: meta
                .humans
                .iter()
                .map(|h| (format!("{:.3}", h.height_m), format!("{:.1}", h.weight_kg)))
                .collect(),
        };
        let io = |e| Error::io(path, e);
        x.w.write_event(Event::Decl(BytesDecl::new("1.0", Some("UTF-8"), None))).map_err(io)?;
        let mut seq = BytesStart::new("sequence");
        seq.push_attribute(("index", meta.index.to_string().as_str()));
        seq.push_attribute(("seed", meta.seed.to_string().as_str()));
        seq.push_attribute(("sensor", meta.sensor.name.as_str()));
        seq.push_attribute(("frames", meta.frames.to_string().as_str()));
        seq.push_attribute(("rows", meta.sensor.rows().to_string().as_str()));
        seq.push_attribute(("columns", meta.sensor.columns.to_string().as_str()));
        seq.push_attribute(("humans", meta.humans.len().to_string().as_str()));
        seq.push_attribute(("pedscan_version", crate::version()));
        x.w.write_event(Event::Start(seq)).map_err(io)?;
        if !meta.provenance.is_empty() {
            let mut e = BytesStart::new("provenance");
            for (k, v) in &meta.provenance {
                e.push_attribute((k.as_str(), v.as_str()));
            }
            x.w.write_event(Event::Empty(e)).map_err(io)?;
        }
        for (k, h) in meta.humans.iter().enumerate() {
            let mut e = BytesStart::new("human");
            e.push_attribute(("id", (k + 1).to_string().as_str()));
            e.push_attribute(("model", h.model.as_str()));
            e.push_attribute(("height_m", x.human_text[k].0.as_str()));
            e.push_attribute(("weight_kg", x.human_text[k].1.as_str()));
            if let Some(s) = h.seat_m {
                e.push_attribute(("seated_m", format!("{s:.3}").as_str()));
            }
            if let Some(p) = &h.pushing {
                e.push_attribute(("pushing", p.as_str()));
            }
            x.w.write_event(Event::Empty(e)).map_err(io)?;
        }
        Ok(x)
    }

    /// Appends one `<frame>`; `beams[k]` = number of beams of instance `k + 1`.
    pub(crate) fn frame(&mut self, index: usize, f: &FrameOutput, beams: &[u32]) -> Result<()> {
        let path = &self.path;
        let io = |e| Error::io(path, e);
        let mut fr = BytesStart::new("frame");
        fr.push_attribute(("index", index.to_string().as_str()));
        fr.push_attribute(("time_s", format!("{:.6}", f.time_s).as_str()));
        fr.push_attribute(("humans", f.humans.len().to_string().as_str()));
        let visible = beams.iter().filter(|&&b| b > 0).count();
        fr.push_attribute(("visible_humans", visible.to_string().as_str()));
        if f.humans.is_empty() {
            return self.w.write_event(Event::Empty(fr)).map_err(io);
        }
        self.w.write_event(Event::Start(fr)).map_err(io)?;
        for (k, h) in f.humans.iter().enumerate() {
            let [vx, vy, vz] = h.velocity_mps;
            let speed = (vx * vx + vy * vy + vz * vz).sqrt();
            let mut e = BytesStart::new("human");
            e.push_attribute(("id", (k + 1).to_string().as_str()));
            e.push_attribute(("x", format!("{:.4}", h.position_m[0]).as_str()));
            e.push_attribute(("y", format!("{:.4}", h.position_m[1]).as_str()));
            e.push_attribute(("z", format!("{:.4}", h.position_m[2]).as_str()));
            e.push_attribute(("heading_rad", format!("{:.4}", h.heading_rad).as_str()));
            e.push_attribute(("speed_mps", format!("{speed:.3}").as_str()));
            e.push_attribute(("gait_phase", format!("{:.3}", h.gait_phase).as_str()));
            e.push_attribute(("height_m", self.human_text[k].0.as_str()));
            e.push_attribute(("weight_kg", self.human_text[k].1.as_str()));
            e.push_attribute(("beams", beams[k].to_string().as_str()));
            self.w.write_event(Event::Empty(e)).map_err(io)?;
        }
        self.w.write_event(Event::End(BytesEnd::new("frame"))).map_err(io)
    }

    /// Closes `<sequence>`, flushes and fsyncs the file.
    pub(crate) fn finish(mut self) -> Result<()> {
        let path = self.path.clone();
        let io = |e| Error::io(&path, e);
        self.w.write_event(Event::End(BytesEnd::new("sequence"))).map_err(io)?;
        let mut buf = self.w.into_inner();
        buf.write_all(b"\n").map_err(io)?;
        let file = buf.into_inner().map_err(|e| Error::io(&path, e.into_error()))?;
        file.sync_all().map_err(io)
    }
}
