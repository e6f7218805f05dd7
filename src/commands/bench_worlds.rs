//! `pedscan bench`'s worlds table: frames/s of each built-in world against the bundled hall,
//! same sensor, people and backend, whole frames (pose, cast, post; no writing), rounds
//! interleaved over the worlds, medians; and what building each sequence's world costs.

use crate::commands::crosscheck::median;
use crate::config::Config;
use crate::error::Result;
use serde::Serialize;
use std::path::PathBuf;
use std::time::Instant;

/// One row of [`world_costs`].
#[derive(Clone, Debug, Serialize)]
pub struct WorldRow {
    /// `hall` (the configuration's own background) or a built-in world's name.
    pub world: String,
    pub ms_per_frame: f64,
    /// Frames per second over the hall's (1 for the hall).
    pub over_hall: f64,
    /// Building sequence 0's world and sampling its plan, ms (once per sequence).
    pub plan_ms: f64,
    /// Triangles of the background.
    pub triangles: usize,
}

/// The worlds timed: the base configuration's background, then `street` and `indoor`.
pub fn world_costs(base: &Config, frames: usize, repeats: usize) -> Result<Vec<WorldRow>> {
    let names = ["hall", "street", "indoor"];
    let mut gens = Vec::new();
    let mut plan_ms = vec![Vec::new(); names.len()];
    for name in names {
        let mut cfg = base.clone();
        cfg.frames = frames;
        if name != "hall" {
            cfg.scene.background = PathBuf::from(name);
        }
        gens.push(crate::generator::Generator::new(cfg)?);
    }
    let mut times = vec![Vec::new(); names.len()];
    let mut triangles = vec![0; names.len()];
    let mut out = crate::output::FrameOutput::default();
    for _ in 0..repeats.max(1) {
        for (v, gen) in gens.iter_mut().enumerate() {
            let t = Instant::now();
            let plan = gen.plan(0)?;
            plan_ms[v].push(t.elapsed().as_secs_f64() * 1e3);
            triangles[v] = match &plan.world {
                Some(w) => w.env.triangle_count(),
                None => gen.background_triangles(),
            };
            gen.begin_sequence(0, &plan);
            let t = Instant::now();
            for k in 0..plan.times_s.len() {
                gen.frame(&plan, k, &mut out)?;
            }
            times[v].push(t.elapsed().as_secs_f64() * 1e3 / plan.times_s.len() as f64);
        }
    }
    for gen in gens {
        gen.finish()?;
    }
    let ms: Vec<f64> = times.iter_mut().map(|t| median(t)).collect();
    Ok(names
        .iter()
        .enumerate()
        .map(|(v, n)| WorldRow {
            world: n.to_string(),
            ms_per_frame: ms[v],
            over_hall: ms[0] / ms[v],
            plan_ms: median(&mut plan_ms[v]),
            triangles: triangles[v],
        })
        .collect())
}

/// The table.
pub fn worlds_markdown(rows: &[WorldRow], frames: usize, repeats: usize) -> String {
    let mut s = format!(
        "\nFrames/s per world (sequence 0, {frames} frames x {repeats} interleaved rounds, medians; whole frames without writing; a sequence's world is built with its plan):\n\n\
         | world | triangles | ms/frame | frames/s | over the hall | plan + world, ms per sequence |\n|---|---|---|---|---|---|\n"
    );
    for r in rows {
        s += &format!(
            "| {} | {} | {:.1} | {:.2} | {:.2} | {:.1} |\n",
            r.world,
            r.triangles,
            r.ms_per_frame,
            1e3 / r.ms_per_frame,
            r.over_hall,
            r.plan_ms
        );
    }
    s
}
