//! `pedscan shutter-check`: the rolling shutter's default (each person posed at the two ends
//! of its column span and every vertex moved to its own column's time) against the reference
//! (the whole frame posed at each column's time, that column cast alone), beam by beam. The
//! issue's target: on walking people, range error median <= 1 mm and p99 <= 5 mm.

use crate::commands::crosscheck::ErrorStats;
use crate::config::{BackendChoice, Config};
use crate::error::Result;
use crate::generator::Generator;
use serde::Serialize;

/// What the check measured.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ShutterReport {
    pub frames: usize,
    /// Columns compared per frame.
    pub columns: usize,
    /// Beams on which either side sees a person.
    pub human_beams: usize,
    /// Of those, beams both see the same person on.
    pub agreeing: usize,
    /// Beams one side calls a person and the other not, or another person.
    pub disagreeing: usize,
    /// |range error| on agreeing beams, m.
    pub human_error_m: ErrorStats,
    /// |range error| of the environment on beams both see it, m (a moving sensor).
    pub background_error_m: ErrorStats,
}

impl std::fmt::Display for ShutterReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let h = &self.human_error_m;
        let b = &self.background_error_m;
        writeln!(f, "rolling shutter, default against posing per column: {} frames x {} columns", self.frames, self.columns)?;
        writeln!(
            f,
            "people: {} beams, {} agree ({:.4} %), {} disagree",
            self.human_beams,
            self.agreeing,
            100.0 * self.agreeing as f64 / self.human_beams.max(1) as f64,
            self.disagreeing
        )?;
        writeln!(f, "people range error: median {:.3} mm, p99 {:.3} mm, max {:.3} mm", 1e3 * h.median, 1e3 * h.p99, 1e3 * h.max)?;
        write!(f, "environment range error: median {:.3} mm, p99 {:.3} mm, max {:.3} mm ({} beams)", 1e3 * b.median, 1e3 * b.p99, 1e3 * b.max, b.count)
    }
}

/// Runs the check over `cfg.sequences` sequences of `cfg.frames` frames (on the ray caster;
/// both sides see the same geometry), every `column_stride`-th column.
pub fn shutter_check(mut cfg: Config, column_stride: usize) -> Result<ShutterReport> {
    cfg.render.backend = BackendChoice::Raycast;
    cfg.sensor_model.enabled = true;
    cfg.sensor_model.rolling_shutter = true;
    let mut gen = Generator::new(cfg.clone())?;
    let w = gen.sensor().columns;
    let stride = column_stride.max(1);
    let mut report = ShutterReport { columns: w.div_ceil(stride), ..Default::default() };
    let (mut human_err, mut bg_err) = (Vec::new(), Vec::new());
    for index in cfg.first_sequence..cfg.first_sequence + cfg.sequences {
        let plan = gen.plan(index)?;
        for k in 0..plan.times_s.len() {
            let state = gen.frame_state(&plan, k);
            gen.pose_frame(&plan, &state)?;
            gen.render_posed()?;
            let fast: Vec<_> = (0..w).step_by(stride).flat_map(|c| (0..gen.sensor().rows()).map(move |r| r * w + c)).collect();
            let fast: Vec<_> = fast.into_iter().map(|b| (b, gen.layer_hits(b))).collect();
            let reference = gen.reference_rolling_hits(&plan, k, (0..w).step_by(stride))?;
            let mut fast_by_beam = std::collections::HashMap::with_capacity(fast.len());
            fast_by_beam.extend(fast);
            for (b, h_ref, bg_ref) in reference {
                let (h_fast, bg_fast) = fast_by_beam[&b];
                match (h_ref, h_fast) {
                    (None, None) => {}
                    (Some((r0, i0)), Some((r1, i1))) if i0 == i1 => {
                        report.human_beams += 1;
                        report.agreeing += 1;
                        human_err.push((r0 - r1).abs());
                    }
                    _ => {
                        report.human_beams += 1;
                        report.disagreeing += 1;
                    }
                }
                if bg_ref > 0.0 && bg_fast > 0.0 {
                    bg_err.push((bg_ref - bg_fast).abs());
                }
            }
            report.frames += 1;
        }
    }
    report.human_error_m = ErrorStats::from(&mut human_err);
    report.background_error_m = ErrorStats::from(&mut bg_err);
    gen.finish()?;
    Ok(report)
}
