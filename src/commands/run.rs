//! The `generate` job: the sequences of a configuration (or of one shard of it), one after
//! the other, each written completely (temporary names, renamed at the end) and recorded in
//! `manifest.jsonl` before the next starts, so a failure in a later sequence never loses an
//! earlier one.
//!
//! Production runs: a sequence is locked while it is written (`seq_NNNNNN.lock`), so two runs
//! in one folder never touch each other's temporaries; a sequence already there is never
//! replaced without `--overwrite` (or, from the same configuration, `--resume`); `--resume` skips sequences whose files verify
//! against the manifest, so a killed run continues where it stopped and ends byte-identical to
//! an uninterrupted one; `--shard I/N` takes every N-th sequence, so N machines together write
//! exactly what one would; a stop request (SIGINT, SIGTERM) ends the run between frames with
//! the sequence in flight discarded.

use crate::config::Config;
use crate::error::{Error, Result};
use crate::generator::Generator;
use crate::output::lock::SequenceLock;
use crate::output::manifest::{check_entry, config_hash, file_records, Manifest, ManifestEntry};
use crate::output::sequence_stem;
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// What a run produced.
#[derive(Clone, Debug)]
pub struct Summary {
    /// Sequences written by this run.
    pub sequences: usize,
    /// Sequences skipped because they were already complete (`--resume`).
    pub skipped: usize,
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
        )?;
        if self.skipped > 0 {
            write!(f, "; {} already complete, skipped", self.skipped)?;
        }
        Ok(())
    }
}

/// One part of a job split across machines: the sequences whose index is `index` modulo
/// `count` (round robin, so every shard gets a share of every kind of sequence).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Default for Shard {
    fn default() -> Self {
        Shard { index: 0, count: 1 }
    }
}

impl Shard {
    /// `I/N` (0 <= I < N); `auto`: a Slurm array task (`SLURM_ARRAY_TASK_ID` minus
    /// `SLURM_ARRAY_TASK_MIN`, of `SLURM_ARRAY_TASK_COUNT`); `auto/N`: the task id of Slurm or
    /// of a Kubernetes Indexed Job (`JOB_COMPLETION_INDEX`), of N. `env` reads a variable.
    pub fn parse(spec: &str, env: impl Fn(&str) -> Option<String>) -> Result<Shard> {
        let bad = |msg: String| Error::input(format!("--shard {spec}"), msg);
        let number = |what: &str, text: &str| text.trim().parse::<usize>().map_err(|_| bad(format!("{what} `{text}` is not a whole number")));
        let (index, count) = match spec.split_once('/') {
            Some(("auto", n)) => (auto_index(&env).ok_or_else(|| bad("neither SLURM_ARRAY_TASK_ID nor JOB_COMPLETION_INDEX is set".into()))??, number("count", n)?),
            Some((i, n)) => (number("index", i)?, number("count", n)?),
            None if spec == "auto" => {
                let index = auto_index(&env).ok_or_else(|| bad("SLURM_ARRAY_TASK_ID is not set (outside Slurm, give the count: auto/N)".into()))??;
                let count = env("SLURM_ARRAY_TASK_COUNT").ok_or_else(|| bad("SLURM_ARRAY_TASK_COUNT is not set; give the count: auto/N".into()))?;
                (index, number("SLURM_ARRAY_TASK_COUNT", &count)?)
            }
            None => return Err(bad("expected I/N (e.g. 0/8), auto or auto/N".into())),
        };
        if count == 0 || index >= count {
            return Err(bad(format!("shard {index} of {count}: need 0 <= index < count")));
        }
        Ok(Shard { index, count })
    }

    /// Whether sequence `index` belongs to this shard.
    pub fn takes(&self, sequence: usize) -> bool {
        sequence % self.count == self.index
    }
}

/// The array task index of Slurm (0-based) or Kubernetes, if either is set.
fn auto_index(env: &impl Fn(&str) -> Option<String>) -> Option<Result<usize>> {
    let parse = |name: &str, v: String| v.trim().parse::<usize>().map_err(|_| Error::input(name, format!("`{v}` is not a whole number")));
    if let Some(id) = env("SLURM_ARRAY_TASK_ID") {
        return Some((|| {
            let id = parse("SLURM_ARRAY_TASK_ID", id)?;
            let min = env("SLURM_ARRAY_TASK_MIN").map(|m| parse("SLURM_ARRAY_TASK_MIN", m)).transpose()?.unwrap_or(0);
            id.checked_sub(min).ok_or_else(|| Error::input("SLURM_ARRAY_TASK_ID", format!("{id} is below SLURM_ARRAY_TASK_MIN {min}")))
        })());
    }
    env("JOB_COMPLETION_INDEX").map(|v| parse("JOB_COMPLETION_INDEX", v))
}

/// How a `generate` run treats the output folder and the terminal.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Draw a progress bar on a terminal.
    pub progress: bool,
    /// Also write each frame's posed human triangles as PLY under this folder.
    pub export_geometry: Option<PathBuf>,
    /// Skip sequences whose files verify against the manifest. A manifest whose entry for one
    /// of this run's sequences names a file outside the folder is refused (bad input) before
    /// anything is written ([`Manifest::check_inside`]).
    pub resume: bool,
    /// Replace sequences that another configuration wrote (otherwise a bad-input error).
    pub overwrite: bool,
    pub shard: Shard,
    /// Set to a signal number to stop between frames (see [`Error::Interrupted`]).
    pub stop: Option<Arc<AtomicUsize>>,
}

/// What the output folder already holds of one sequence.
enum Existing {
    /// No final file of it.
    None,
    /// Complete from this configuration: its files verify against its manifest entry.
    Complete,
    /// From this configuration, not verified: writing it again gives the same bytes.
    Same,
    /// Not in the manifest (a run killed between its renames and its manifest line, or
    /// files from elsewhere); which.
    Unlisted(String),
    /// From another configuration; why.
    Foreign(String),
}

fn existing(out: &Path, manifest: &Manifest, index: usize, hash: &str, verify: bool) -> Existing {
    let stem = sequence_stem(index);
    let sk = crate::output::semantickitti::sequence_dir(Path::new(""), index).to_string_lossy().into_owned();
    let present: Vec<String> = [format!("{stem}.h5"), format!("{stem}.xml"), format!("{stem}_png"), format!("{stem}_bag"), sk]
        .into_iter()
        .filter(|n| std::fs::symlink_metadata(out.join(n)).is_ok())
        .collect();
    if present.is_empty() {
        return Existing::None;
    }
    match manifest.latest.get(&index) {
        None => Existing::Unlisted(format!("{} not in {}", present.join(" and "), crate::output::manifest::MANIFEST)),
        Some(e) if e.config_hash != hash => {
            Existing::Foreign(format!("written by another configuration: config hash {}, this run {hash}", e.config_hash))
        }
        Some(e) if verify && check_entry(out, e).is_none() => Existing::Complete,
        Some(_) => Existing::Same,
    }
}

/// Runs a whole `generate` job (or its shard). An output folder this run created is removed
/// again if the run fails before writing anything into it.
pub fn generate(cfg: Config, opts: &RunOptions) -> Result<Summary> {
    let out = cfg.out.clone();
    if out.exists() && !out.is_dir() {
        return Err(Error::input(out.display(), "output path exists and is not a folder"));
    }
    let created = !out.exists();
    let result = run(cfg, opts);
    if result.is_err() && created {
        // Only if empty: remove_dir refuses a folder with anything in it.
        let _ = std::fs::remove_dir(&out);
    }
    result
}

fn run(cfg: Config, opts: &RunOptions) -> Result<Summary> {
    let out = cfg.out.clone();
    // Inputs are checked (and the GPU started) before anything is created on disk.
    let mut gen = Generator::new(cfg)?;
    std::fs::create_dir_all(&out).map_err(|e| Error::input(out.display(), format!("cannot create output folder: {e}")))?;
    gen.set_export_geometry(opts.export_geometry.clone());
    let cfg = gen.config().clone();
    let hash = config_hash(gen.recorded_config());
    let mut manifest = Manifest::load(&out)?;
    let indices: Vec<usize> = (cfg.first_sequence..cfg.first_sequence + cfg.sequences).filter(|&i| opts.shard.takes(i)).collect();
    if opts.resume {
        manifest.check_inside(&out, &indices)?;
    }
    let total = (indices.len() * cfg.frames) as u64;
    let bar = if opts.progress { indicatif::ProgressBar::new(total) } else { indicatif::ProgressBar::hidden() };
    bar.set_style(
        indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:40}] {pos}/{len} frames, {per_sec}, eta {eta} {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let stopped = || match opts.stop.as_ref().map(|s| s.load(Ordering::SeqCst)) {
        Some(signal) if signal != 0 => Err(Error::Interrupted { signal: signal as i32 }),
        _ => Ok(()),
    };
    let start = Instant::now();
    let (mut files, mut written, mut skipped, mut frames) = (Vec::new(), 0, 0, 0);
    for index in indices {
        stopped()?;
        let lock = SequenceLock::acquire(&out, index)?;
        let mut found = existing(&out, &manifest, index, &hash, opts.resume);
        if matches!(found, Existing::Same | Existing::Unlisted(_) | Existing::Foreign(_)) {
            // Another run in this folder may have completed the sequence since the manifest
            // was read (it appends its line before releasing the lock we now hold).
            manifest = Manifest::load(&out)?;
            found = existing(&out, &manifest, index, &hash, opts.resume);
        }
        match found {
            Existing::None => {}
            Existing::Complete => {
                skipped += 1;
                bar.inc(cfg.frames as u64);
                continue;
            }
            // With --resume, a sequence of this configuration that does not verify is
            // written again; anything else already there only with --overwrite.
            Existing::Same if opts.resume => {}
            // The files of a run that died before recording them: its lock file was left
            // behind, so it was writing this very sequence; --resume writes it again.
            Existing::Unlisted(_) if opts.resume && lock.taken_over() => {}
            Existing::Same if !opts.overwrite => return Err(replace_refused(&out, index, "from this configuration")),
            Existing::Unlisted(why) | Existing::Foreign(why) if !opts.overwrite => return Err(replace_refused(&out, index, &why)),
            Existing::Same | Existing::Unlisted(_) | Existing::Foreign(_) => {}
        }
        bar.set_message(sequence_stem(index));
        let t0 = Instant::now();
        let seq = gen.write_sequence(index, &out, || {
            bar.inc(1);
            stopped()
        })?;
        let entry = ManifestEntry {
            sequence: index,
            files: file_records(&out, &seq.files)?,
            frames: seq.frames,
            people: seq.people,
            seconds: t0.elapsed().as_secs_f64(),
            version: env!("CARGO_PKG_VERSION").to_string(),
            device: gen.backend().device_name(),
            config_hash: hash.clone(),
            class_points: seq.class_points,
        };
        crate::debug::kill_at(cfg.debug.kill.filter(|k| k.sequence == index).map(|k| k.at), crate::debug::KillStage::Manifest);
        Manifest::append(&out, &entry)?;
        frames += seq.frames;
        files.extend(seq.files);
        written += 1;
    }
    bar.finish_and_clear();
    if cfg.output.formats.contains(&crate::config::Format::Semantickitti) {
        write_semantickitti_yaml(&out, &hash)?;
    }
    let summary = Summary {
        sequences: written,
        skipped,
        frames,
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

/// `semantickitti/pedscan.yaml` over every sequence of this configuration in the manifest
/// (shards and resumed runs included: the last run to finish writes the whole picture).
fn write_semantickitti_yaml(out: &Path, hash: &str) -> Result<()> {
    let m = Manifest::load(out)?;
    let mut counts = crate::output::semantickitti::ClassPoints::default();
    let mut sequences = Vec::new();
    for e in m.latest.values().filter(|e| e.config_hash == hash) {
        if let Some(c) = &e.class_points {
            counts.add(c);
            sequences.push(e.sequence);
        }
    }
    crate::output::semantickitti::write_yaml(out, &counts, &sequences)
}

fn replace_refused(out: &Path, index: usize, why: &str) -> Error {
    Error::input(
        out.join(sequence_stem(index)).display(),
        format!(
            "sequence {index} is already there ({why}); refusing to replace it: use another --out, \
             --resume with the same configuration (keeps complete sequences, writes the rest), or --overwrite"
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |k| vars.iter().find(|(n, _)| *n == k).map(|(_, v)| v.to_string())
    }

    #[test]
    fn shards_split_the_sequences_round_robin_and_together_cover_each_once() {
        let shards: Vec<Shard> = (0..3).map(|i| Shard::parse(&format!("{i}/3"), env(&[])).unwrap()).collect();
        for seq in 0..20 {
            assert_eq!(shards.iter().filter(|s| s.takes(seq)).count(), 1);
        }
        assert!(shards[1].takes(4) && !shards[1].takes(5));
    }

    #[test]
    fn auto_shards_read_slurm_and_kubernetes() {
        let slurm = [("SLURM_ARRAY_TASK_ID", "5"), ("SLURM_ARRAY_TASK_MIN", "1"), ("SLURM_ARRAY_TASK_COUNT", "8")];
        assert_eq!(Shard::parse("auto", env(&slurm)).unwrap(), Shard { index: 4, count: 8 });
        assert_eq!(Shard::parse("auto/4", env(&[("JOB_COMPLETION_INDEX", "3")])).unwrap(), Shard { index: 3, count: 4 });
        for (spec, vars) in [
            ("auto", &[("JOB_COMPLETION_INDEX", "3")][..]),
            ("auto/4", &[][..]),
            ("3/3", &[][..]),
            ("1/0", &[][..]),
            ("x/2", &[][..]),
            ("2", &[][..]),
            ("auto/2", &[("JOB_COMPLETION_INDEX", "2")][..]),
        ] {
            let e = Shard::parse(spec, env(vars)).unwrap_err();
            assert!(e.is_input() && e.to_string().contains("--shard"), "{spec}: {e}");
        }
    }
}

/// Installs the handlers of a `generate` run: SIGINT and SIGTERM ask the run to stop between
/// frames (the returned flag holds the signal's number, for [`RunOptions::stop`]); a second
/// one ends the process at once (temporaries may then remain; `--resume` cleans them up).
pub fn stop_on_signals() -> Result<Arc<AtomicUsize>> {
    let stop = Arc::new(AtomicUsize::new(0));
    let asked = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        // In this order: the first signal finds `asked` still false.
        signal_hook::flag::register_conditional_shutdown(signal, 128 + signal, asked.clone())
            .and_then(|_| signal_hook::flag::register(signal, asked.clone()))
            .and_then(|_| signal_hook::flag::register_usize(signal, stop.clone(), signal as usize))
            .map_err(|e| Error::Internal(format!("installing a signal handler: {e}")))?;
    }
    Ok(stop)
}
