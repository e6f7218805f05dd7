//! `pedscan project SCANS --out DIR`: KITTI `.bin` scans put on a sensor's grid by the very
//! projection `generate` gives a recorded background ([`crate::input::project::Projector`]
//! over [`crate::input::kitti::read_bin`]), so a network trained on pedscan's frames is run
//! and scored on real scans on the grid it was trained on, and its per-cell answers taken back
//! to the scan's points.
//!
//! # In
//! `SCANS`: a folder holding `velodyne/*.bin` (KITTI odometry, SemanticKITTI), or the
//! `velodyne` folder itself; the `.bin` files in file-name order (other files are ignored).
//! The grid is `--sensor` (a preset or a sensor file), or the `sensor` of `--config`, as
//! `generate` takes them.
//!
//! # Out
//! `DIR` is written whole or not at all (a temporary sibling, renamed at the end; an earlier
//! `project` output there is replaced, any other non-empty folder refused):
//!
//! * `grid.json`: `{"sensor", "rows", "cols", "intensity_units", "ring_mapped", "scans":
//!   [{"file", "points", "kept", "outside_band", "replaced", "ring_mapped"}, ...]}`. `points`
//!   counts the file's records; `kept + outside_band + replaced = points` (`outside_band`
//!   includes the records dropped as not finite or at the origin). A scan is `ring_mapped`
//!   when the lasers of its point order chose the rows ([`crate::input::kitti::lasers_of`];
//!   else each point's elevation did); the top-level `ring_mapped` is true when every scan was.
//!   `intensity_units` is `"remission"`: the `.bin`'s fourth value as recorded, what `generate`
//!   keeps as `/intensity` on a KITTI background's beams.
//! * per scan `NNNNNN` (the `.bin`'s stem): `NNNNNN.cell`, a little-endian `u32` per record in
//!   the file's order, the cell `row * cols + col` the point projects to (also when a nearer
//!   return keeps that cell) or `0xFFFFFFFF` for a point dropped (outside every row's band,
//!   not finite, at the origin); `NNNNNN.range` and `NNNNNN.intensity`, little-endian `f32`
//!   `rows x cols` row-major, 0 = no return: the background `generate` composites into for
//!   that scan.

use crate::config::Flags;
use crate::error::{Error, Result};
use crate::input::kitti::{self, read_bin_records};
use crate::input::project::{Projector, NO_CELL};
use crate::input::recording::{own_sensor, RecordingOptions, BACKGROUND_SENSOR};
use crate::output::files::{fresh_tmp_dir, replace_dir, write_file};
use crate::sensor::Sensor;
use std::path::{Path, PathBuf};

/// What `grid.json` calls the intensity images' units.
pub const INTENSITY_UNITS: &str = "remission";

/// `pedscan project`'s arguments.
#[derive(clap::Args, Debug, Clone)]
pub struct ProjectRequest {
    /// A folder holding velodyne/*.bin (KITTI odometry, SemanticKITTI), or the velodyne folder
    /// itself.
    pub scans: PathBuf,
    /// The folder to write: grid.json and per scan NNNNNN.cell, .range, .intensity.
    #[arg(long)]
    pub out: PathBuf,
    /// The grid: a sensor preset or file, as for `generate`.
    #[arg(long)]
    pub sensor: Option<String>,
    /// A TOML configuration whose `sensor` is the grid.
    #[arg(long)]
    pub config: Option<PathBuf>,
}

/// `grid.json`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GridFile {
    pub sensor: String,
    pub rows: usize,
    pub cols: usize,
    pub intensity_units: String,
    /// Every scan's rows came from its lasers.
    pub ring_mapped: bool,
    pub scans: Vec<ScanEntry>,
}

/// One scan of `grid.json`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ScanEntry {
    /// The `.bin`'s file name.
    pub file: String,
    /// Records in the file.
    pub points: usize,
    pub kept: usize,
    pub outside_band: usize,
    pub replaced: usize,
    pub ring_mapped: bool,
}

impl std::fmt::Display for GridFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.scans.len();
        let rings = self.scans.iter().filter(|s| s.ring_mapped).count();
        let (points, kept) = self.scans.iter().fold((0, 0), |(p, k), s| (p + s.points, k + s.kept));
        write!(
            f,
            "projected {n} scans onto {} ({} x {}): {rings} of them row for laser (the lasers of their point order), {} by \
             elevation; {kept} of {points} points hold a cell",
            self.sensor,
            self.rows,
            self.cols,
            n - rings
        )
    }
}

/// Runs `pedscan project`; the summary of what was written.
pub fn project(req: &ProjectRequest) -> Result<GridFile> {
    let cfg = Flags { config: req.config.clone(), sensor: req.sensor.clone(), ..Flags::default() }.config()?;
    let sensor = if cfg.sensor == BACKGROUND_SENSOR {
        own_sensor(&req.scans, &RecordingOptions::default())?
    } else {
        Sensor::from_name_or_file(&cfg.sensor)?
    };
    let files = scan_files(&req.scans)?;
    check_out(&req.out)?;
    let tmp = fresh_tmp_dir(&req.out)?;
    let written = write_scans(&files, &sensor, &tmp).and_then(|grid| {
        let json = serde_json::to_string_pretty(&grid).expect("plain fields serialize");
        write_file(&tmp.join("grid.json"), json + "\n")?;
        replace_dir(&tmp, &req.out)?;
        Ok(grid)
    });
    if written.is_err() {
        // Best effort: the error that stopped the run is the one to report.
        let _ = std::fs::remove_dir_all(&tmp);
    }
    written
}

/// The `.bin` scans of `scans` (or of its `velodyne` folder) in file-name order, each a whole
/// number of records.
pub fn scan_files(scans: &Path) -> Result<Vec<PathBuf>> {
    let velodyne = scans.join("velodyne");
    let dir = if velodyne.is_dir() { velodyne } else { scans.to_path_buf() };
    if !dir.is_dir() {
        let what = if dir.exists() { "is not a folder (want one holding velodyne/*.bin)" } else { "does not exist" };
        return Err(Error::input(scans.display(), what));
    }
    let files = crate::input::folder_files(&dir, |f| f.extension().is_some_and(|e| e.eq_ignore_ascii_case("bin")))?;
    if files.is_empty() {
        return Err(Error::input(dir.display(), "holds no .bin scan (KITTI velodyne/NNNNNN.bin)"));
    }
    for (a, b) in files.iter().zip(&files[1..]) {
        if a.file_stem() == b.file_stem() {
            return Err(Error::input(dir.display(), format!("{} and {} would write the same outputs", a.display(), b.display())));
        }
    }
    for f in &files {
        kitti::check_bin_len(f)?;
    }
    Ok(files)
}

/// Refuses an output folder that holds something other than an earlier `project` output.
fn check_out(out: &Path) -> Result<()> {
    if !out.exists() {
        return Ok(());
    }
    let empty = std::fs::read_dir(out).map(|mut d| d.next().is_none());
    match empty {
        Ok(true) => Ok(()),
        Ok(false) if out.join("grid.json").is_file() => Ok(()),
        Ok(false) => Err(Error::input(out.display(), "holds other files (no grid.json of an earlier `pedscan project`): choose an empty or new folder")),
        Err(_) => Err(Error::input(out.display(), "exists and is not a folder")),
    }
}

/// Projects every scan and writes its three files into `dir`.
fn write_scans(files: &[PathBuf], sensor: &Sensor, dir: &Path) -> Result<GridFile> {
    use rayon::prelude::*;
    let projector = Projector::new(sensor);
    let scans = files.par_iter().map(|f| write_scan(f, &projector, dir)).collect::<Result<Vec<ScanEntry>>>()?;
    Ok(GridFile {
        sensor: sensor.name.clone(),
        rows: sensor.rows(),
        cols: sensor.columns,
        intensity_units: INTENSITY_UNITS.into(),
        ring_mapped: scans.iter().all(|s| s.ring_mapped),
        scans,
    })
}

fn write_scan(file: &Path, projector: &Projector, dir: &Path) -> Result<ScanEntry> {
    let bin = read_bin_records(file)?;
    let (mut range, mut intensity, mut point_cells) = (Vec::new(), Vec::new(), Vec::new());
    let stats = projector.project_points(&bin.scan, &mut range, &mut intensity, &mut point_cells);
    let mut cells = vec![NO_CELL; bin.records];
    for (&record, &cell) in bin.record_of_point.iter().zip(&point_cells) {
        cells[record as usize] = cell;
    }
    let stem = file.file_stem().unwrap_or_default().to_string_lossy().into_owned();
    let le = |v: &[u32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    write_file(&dir.join(format!("{stem}.cell")), le(&cells))?;
    write_file(&dir.join(format!("{stem}.range")), le(&bits(&range)))?;
    write_file(&dir.join(format!("{stem}.intensity")), le(&bits(&intensity)))?;
    Ok(ScanEntry {
        file: file.file_name().unwrap_or_default().to_string_lossy().into_owned(),
        points: bin.records,
        kept: stats.kept,
        outside_band: stats.outside_band + (bin.records - bin.scan.points.len()),
        replaced: stats.replaced,
        ring_mapped: stats.ring_mapped,
    })
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}
