//! The `generate` job: every sequence of a configuration, one after the other, each written
//! completely (temporary names, renamed at the end) before the next starts, so a failure in a
//! later sequence never loses an earlier one.

use crate::config::Config;
use crate::error::{Error, Result};
use crate::generator::Generator;
use std::fmt;
use std::path::PathBuf;
use std::time::Instant;

/// What a run produced.
#[derive(Clone, Debug)]
pub struct Summary {
    pub sequences: usize,
    pub frames: usize,
    pub files: Vec<PathBuf>,
    pub seconds: f64,
    pub device: String,
    /// Seconds per stage (`--timings` prints them).
    pub timings: crate::generator::StageTimes,
}

impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "wrote {} sequences ({} frames, {} files) in {:.1} s ({:.1} frames/s) on {}",
            self.sequences,
            self.frames,
            self.files.len(),
            self.seconds,
            self.frames as f64 / self.seconds.max(1e-9),
            self.device
        )
    }
}

/// Runs a whole `generate` job. `progress`: draw a progress bar on a terminal.
pub fn generate(cfg: Config, progress: bool, export_geometry: Option<PathBuf>) -> Result<Summary> {
    let out = cfg.out.clone();
    if out.exists() && !out.is_dir() {
        return Err(Error::input(out.display(), "output path exists and is not a folder"));
    }
    // Inputs are checked (and the GPU started) before anything is created on disk.
    let mut gen = Generator::new(cfg)?;
    std::fs::create_dir_all(&out).map_err(|e| Error::input(out.display(), format!("cannot create output folder: {e}")))?;
    gen.set_export_geometry(export_geometry);
    let cfg = gen.config().clone();
    let total = (cfg.sequences * cfg.frames) as u64;
    let bar = if progress { indicatif::ProgressBar::new(total) } else { indicatif::ProgressBar::hidden() };
    bar.set_style(
        indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:40}] {pos}/{len} frames, {per_sec}, eta {eta} {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let start = Instant::now();
    let mut files = Vec::new();
    for index in cfg.first_sequence..cfg.first_sequence + cfg.sequences {
        bar.set_message(format!("seq_{index:06}"));
        let written = gen.write_sequence(index, &out, || bar.inc(1))?;
        files.extend(written);
    }
    bar.finish_and_clear();
    let summary = Summary {
        sequences: cfg.sequences,
        frames: cfg.sequences * cfg.frames,
        files,
        seconds: start.elapsed().as_secs_f64(),
        timings: gen.timings(),
        device: gen.backend().device_name(),
    };
    // With validation on, any validation error (leaks at device destruction included) fails
    // the run, so tests of the binary see them.
    gen.finish()?;
    Ok(summary)
}
