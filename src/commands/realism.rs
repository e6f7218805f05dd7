//! `pedscan realism REC SIM`: a recording against a pedscan output, measured by one estimator
//! on the output's sensor grid ([`crate::realism`]): hole rate per incidence, range and row,
//! range noise per range, intensity; a table, and optionally a JSON report and a PNG of the
//! curves.

use crate::error::{Error, Result};
use crate::input::recording::{is_recording, Recording};
use crate::plot::{Draw, Marker, Plot, Series, PALETTE};
use crate::realism::{compare, Curve, Measure, Report, EXCLUDED};
use crate::sensor::Sensor;
use glam::DVec3;
use std::path::{Path, PathBuf};

/// Fewest returns a side must have to be measured.
pub const MIN_RETURNS: u64 = 10_000;

/// `pedscan realism`'s arguments.
#[derive(clap::Args, Debug, Clone)]
pub struct RealismRequest {
    /// The recording: a Velodyne .pcap, a folder of KITTI .bin or .pcd frames, or a pedscan
    /// output (a folder of seq_*.h5 or one file; its people are left out).
    pub rec: PathBuf,
    /// A pedscan output: a folder written by `generate` (every seq_*.h5) or one sequence file;
    /// its people are left out (`--humans 0..0` measures the scene alone).
    pub sim: PathBuf,
    /// Write the curves, real against simulated, as a PNG.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Write the report as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Measure at most this many frames of each side, evenly spaced (default: all).
    #[arg(long)]
    pub max_frames: Option<usize>,
}

/// The grid both sides are measured on: the pedscan output's sensor.
pub struct Grid {
    pub sensor: Sensor,
    pub dirs: Vec<DVec3>,
}

/// A source's frames as (file or recording index, frame) pairs, `max` of them evenly spaced.
fn spaced(total: usize, max: Option<usize>) -> Vec<usize> {
    match max {
        Some(m) if m < total => (0..m).map(|k| k * total / m).collect(),
        _ => (0..total).collect(),
    }
}

fn is_output(path: &Path) -> bool {
    if path.is_file() {
        return path.extension().is_some_and(|e| e == "h5");
    }
    std::fs::read_dir(path).is_ok_and(|mut d| {
        d.any(|e| e.is_ok_and(|e| e.file_name().to_string_lossy().starts_with("seq_") && e.path().extension().is_some_and(|x| x == "h5")))
    })
}

fn open_h5(path: &Path) -> Result<hdf5::File> {
    hdf5::File::open(path).map_err(|e| Error::input(path.display(), format!("not a readable HDF5 file ({e})")))
}

/// The sensor of a pedscan sequence file, from its `sensor` attribute and `/sensor/elevation_deg`.
pub fn output_grid(path: &Path) -> Result<Grid> {
    let file = open_h5(path)?;
    let bad = |m: String| Error::input(path.display(), m);
    let shape = file.dataset("range").map_err(|_| bad("no /range: not a pedscan sequence".into()))?.shape();
    let [_, h, w] = shape[..] else { return Err(bad(format!("/range has shape {shape:?}, expected [frames, rows, columns]"))) };
    let el: Vec<f32> = file
        .dataset("sensor/elevation_deg")
        .and_then(|d| d.read_raw())
        .map_err(|_| bad("no /sensor/elevation_deg: not a pedscan sequence".into()))?;
    if el.len() != h || w == 0 {
        return Err(bad(format!("/sensor/elevation_deg has {} rows, /range {h} x {w}", el.len())));
    }
    let name = file
        .attr("sensor")
        .and_then(|a| a.read_scalar::<hdf5::types::VarLenUnicode>())
        .map(|v| v.as_str().to_string())
        .unwrap_or_else(|_| "sensor".into());
    let elevation_deg: Vec<f64> = el.iter().map(|&e| e as f64).collect();
    // The preset's range limits where the name is one (they decide what a recording keeps).
    let base = Sensor::from_name_or_file(&name).ok().filter(|s| s.rows() == h).unwrap_or_else(Sensor::hdl32e);
    let sensor = Sensor { name, elevation_deg, columns: w, ..base };
    sensor.validate(&path.display().to_string())?;
    let dirs = sensor.beam_dirs();
    Ok(Grid { sensor, dirs })
}

fn same_grid(a: &Sensor, b: &Sensor, tol_deg: f64) -> bool {
    a.columns == b.columns && a.rows() == b.rows() && a.elevation_deg.iter().zip(&b.elevation_deg).all(|(x, y)| (x - y).abs() <= tol_deg)
}

fn describe(s: &Sensor) -> String {
    format!("{}: {} rows x {} columns, {:+.2} to {:+.2} deg", s.name, s.rows(), s.columns, s.elevation_deg[0], s.elevation_deg[s.rows() - 1])
}

/// The intensity units of a pedscan sequence file (intensity = scale * reflectance * cos):
/// its configuration's `sensor_model.intensity_scale`, else 100 over a Velodyne capture and 1
/// over anything else (the rule `generate` follows).
pub fn output_intensity_scale(path: &Path) -> Result<f64> {
    let file = open_h5(path)?;
    let text = file
        .attr("config")
        .and_then(|a| a.read_scalar::<hdf5::types::VarLenUnicode>())
        .map(|v| v.as_str().to_string())
        .map_err(|_| Error::input(path.display(), "no `config` attribute: not a pedscan sequence"))?;
    let cfg: toml::Value = toml::from_str(&text).map_err(|e| Error::input(path.display(), format!("its `config` attribute is not TOML: {e}")))?;
    if let Some(s) = cfg.get("sensor_model").and_then(|m| m.get("intensity_scale")).and_then(|v| v.as_float()) {
        return Ok(s);
    }
    let bg = cfg.get("scene").and_then(|s| s.get("background")).and_then(|v| v.as_str()).unwrap_or("");
    Ok(if bg.to_ascii_lowercase().ends_with(".pcap") { 100.0 } else { 1.0 })
}

/// The intensity units of a source: a pedscan output's ([`output_intensity_scale`]), 100 for
/// a Velodyne capture, 1 for anything else.
pub fn intensity_scale_of(path: &Path) -> Result<f64> {
    if is_output(path) {
        output_intensity_scale(&crate::commands::stats::sequence_files(path)?[0])
    } else {
        Ok(if crate::input::recording::is_pcap(path) { 100.0 } else { 1.0 })
    }
}

/// Measures the frames of pedscan sequence files on `grid` (every file must be of that
/// sensor); beams labelled human are left out.
pub fn measure_output(files: &[PathBuf], grid: &Grid, max_frames: Option<usize>, samples: bool) -> Result<Measure> {
    let mut m = Measure::new(grid.sensor.rows());
    if samples {
        m = m.keep_samples();
    }
    let mut frames = Vec::new();
    for f in files {
        let g = output_grid(f)?;
        // The file's elevations are f32: equal to the grid's within their rounding.
        if !same_grid(&g.sensor, &grid.sensor, 1e-4) {
            return Err(Error::input(
                f.display(),
                format!("another sensor ({}) than the one measured on ({})", describe(&g.sensor), describe(&grid.sensor)),
            ));
        }
        let t = open_h5(f)?.dataset("range").map(|d| d.shape()[0]).unwrap_or(0);
        frames.extend((0..t).map(|k| (f, k)));
    }
    let beams = grid.dirs.len();
    let mut current: Option<(&PathBuf, Vec<f32>, Vec<f32>, Vec<u8>)> = None;
    let mut range = Vec::with_capacity(beams);
    for k in spaced(frames.len(), max_frames) {
        let (f, t) = frames[k];
        if current.as_ref().is_none_or(|c| c.0 != f) {
            let file = open_h5(f)?;
            let bad = |m: String| Error::input(f.display(), m);
            let r: Vec<f32> = file.dataset("range").and_then(|d| d.read_raw()).map_err(|e| bad(format!("/range: {e}")))?;
            let i: Vec<f32> = match file.dataset("intensity") {
                Ok(d) => d.read_raw().map_err(|e| bad(format!("/intensity: {e}")))?,
                Err(_) => Vec::new(),
            };
            let l: Vec<u8> = match file.dataset("label") {
                Ok(d) => d.read_raw().map_err(|e| bad(format!("/label: {e}")))?,
                Err(_) => Vec::new(),
            };
            if (!i.is_empty() && i.len() != r.len()) || (!l.is_empty() && l.len() != r.len()) {
                return Err(bad("/intensity or /label does not match /range's shape".into()));
            }
            current = Some((f, r, i, l));
        }
        let (_, r, i, l) = current.as_ref().expect("read above");
        let span = t * beams..(t + 1) * beams;
        range.clear();
        range.extend(r[span.clone()].iter().enumerate().map(|(b, &x)| {
            let human = l.get(span.start + b).is_some_and(|&v| v == 1);
            if human || !x.is_finite() || x < 0.0 {
                EXCLUDED
            } else {
                x
            }
        }));
        let intensity = if i.is_empty() { &[][..] } else { &i[span] };
        m.add_frame(grid.sensor.columns, &grid.dirs, &range, intensity);
    }
    Ok(m)
}

/// Measures a recording (a capture or a frame folder) projected onto `grid`; a capture of
/// another sensor than the grid's is refused.
pub fn measure_recording(path: &Path, grid: &Grid, max_frames: Option<usize>, samples: bool) -> Result<Measure> {
    let rec = Recording::open(path, None, &grid.sensor)?;
    if let Some(el) = &rec.source_elevation_deg {
        let source = Sensor { name: rec.description.split(' ').next().unwrap_or("capture").into(), elevation_deg: el.clone(), ..grid.sensor.clone() };
        if !same_grid(&source, &grid.sensor, 0.05) {
            return Err(Error::input(
                path.display(),
                format!(
                    "a capture of another sensor ({}) than the grid it is measured on ({}); measure it on its own \
                     sensor's (sensor-fit --sensor; realism: a pedscan output generated with that sensor)",
                    describe(&source),
                    describe(&grid.sensor)
                ),
            ));
        }
    }
    if let Some(w) = &rec.coverage_warning {
        eprintln!("warning: {}: {w}", path.display());
    }
    let mut m = Measure::new(grid.sensor.rows());
    if samples {
        m = m.keep_samples();
    }
    let (mut range, mut intensity) = (Vec::new(), Vec::new());
    for k in spaced(rec.len(), max_frames) {
        rec.frame(k, &mut range, &mut intensity)?;
        m.add_frame(grid.sensor.columns, &grid.dirs, &range, &intensity);
    }
    Ok(m)
}

/// Measures `path` on `grid`: a pedscan output or a recording.
pub fn measure(path: &Path, grid: &Grid, max_frames: Option<usize>) -> Result<Measure> {
    measure_with(path, grid, max_frames, false)
}

/// [`measure`], keeping every beam's sample when `samples`.
pub fn measure_with(path: &Path, grid: &Grid, max_frames: Option<usize>, samples: bool) -> Result<Measure> {
    let m = if is_output(path) {
        measure_output(&crate::commands::stats::sequence_files(path)?, grid, max_frames, samples)?
    } else if is_recording(path) {
        measure_recording(path, grid, max_frames, samples)?
    } else if path.exists() {
        return Err(Error::input(path.display(), "neither a pedscan output (seq_*.h5) nor a recording (.pcap, a ROS 2 bag, a folder of .bin or .pcd frames)"));
    } else {
        return Err(Error::input(path.display(), "no such file or folder"));
    };
    let returns = m.beams() - m.holes();
    if returns < MIN_RETURNS {
        return Err(Error::input(
            path.display(),
            format!("{returns} returns in {} frames: too few to measure (want at least {MIN_RETURNS})", m.frames),
        ));
    }
    Ok(m)
}

/// Runs `pedscan realism`: measures both sides, writes the files asked for (each whole or
/// not at all), returns the report.
pub fn realism(req: &RealismRequest) -> Result<Report> {
    if req.max_frames == Some(0) {
        return Err(Error::input("--max-frames", "must be at least 1"));
    }
    let sim_files = crate::commands::stats::sequence_files(&req.sim)?;
    let grid = output_grid(&sim_files[0])?;
    let mut sim = measure(&req.sim, &grid, req.max_frames)?;
    let mut rec = measure(&req.rec, &grid, req.max_frames)?;
    // Both sides' intensities in the model's units, reflectance * cos(incidence).
    let scales = (intensity_scale_of(&req.rec)?, intensity_scale_of(&req.sim)?);
    rec.intensity.iter_mut().for_each(|v| *v /= scales.0 as f32);
    sim.intensity.iter_mut().for_each(|v| *v /= scales.1 as f32);
    let mut report = compare(&req.rec.display().to_string(), &rec, &req.sim.display().to_string(), &sim, &grid.sensor.elevation_deg);
    if report.intensity.is_some() {
        report.notes.push(format!("intensities in reflectance x cos(incidence): rec's divided by {}, sim's by {}", scales.0, scales.1));
    }
    if let Some(p) = &req.json {
        let text = serde_json::to_string_pretty(&report).map_err(|e| Error::io(p, std::io::Error::other(e)))?;
        crate::output::files::write_file(p, text)?;
    }
    if let Some(p) = &req.png {
        crate::plot::save_image(&plot(&report), p)?;
    }
    Ok(report)
}

fn curve_series(c: &Curve, x: impl Fn(f64, f64) -> f64, scale: f64) -> [Series; 2] {
    let pts = |f: &dyn Fn(&crate::realism::Point) -> Option<f64>| -> Vec<(f64, f64)> {
        c.points.iter().filter_map(|p| f(p).map(|v| (x(p.lo, p.hi), v * scale))).collect()
    };
    let min = if c.unit == "m" { crate::realism::MIN_RESIDUALS as u64 } else { crate::realism::MIN_BEAMS };
    let enough = |n: u64| n >= min;
    [
        Series { name: "recording".into(), points: pts(&|p| p.rec.filter(|_| enough(p.rec_n))), colour: PALETTE[0], draw: Draw::Line(Marker::Circle) },
        Series { name: "pedscan".into(), points: pts(&|p| p.sim.filter(|_| enough(p.sim_n))), colour: PALETTE[1], draw: Draw::Line(Marker::Square) },
    ]
}

/// The report's curves as one picture: hole rate by incidence, by range and by row, range
/// noise by range, and the intensity histograms as bars side by side (bins with too few beams
/// left out).
pub fn plot(r: &Report) -> image::RgbImage {
    let mid = |lo: f64, hi: f64| if hi.is_finite() { 0.5 * (lo + hi) } else { lo + 0.5 * crate::realism::RANGE_BIN_M };
    let tile = |title: &str, x: &str, y: &str, series: Vec<Series>| Plot { title: title.into(), x_label: x.into(), y_label: y.into(), series, width: 640, height: 380, ..Plot::default() };
    let mut tiles = vec![
        tile("hole rate by incidence", "incidence, deg", "holes, %", curve_series(&r.hole_rate_by_incidence, mid, 100.0).to_vec()),
        tile("hole rate by range", "expected range, m", "holes, %", curve_series(&r.hole_rate_by_range, mid, 100.0).to_vec()),
        tile("range noise (returns below 60 deg)", "range, m", "robust sd, mm", curve_series(&r.range_noise_by_range, mid, 1000.0).to_vec()),
        tile("hole rate by row", "row elevation, deg", "holes, %", curve_series(&r.hole_rate_by_row, |lo, _| lo, 100.0).to_vec()),
    ];
    if let Some(i) = &r.intensity {
        // Each bin's two bars share its width: the recording's left of its centre, pedscan's right.
        let bars = |name: &str, v: &[f64], k: usize, side: f64| {
            let points = i.edges.windows(2).zip(v).map(|(e, &y)| (0.5 * (e[0] + e[1]) + side * 0.25 * (e[1] - e[0]), y)).collect();
            let width = i.edges.windows(2).map(|e| 0.45 * (e[1] - e[0])).fold(f64::INFINITY, f64::min);
            Series { name: name.into(), points, colour: PALETTE[k], draw: Draw::Bars { width: if width.is_finite() { width } else { 0.0 } } }
        };
        tiles.push(tile("intensity of returns", "reflectance x cos(incidence)", "fraction of returns", vec![bars("recording", &i.rec, 0, -1.0), bars("pedscan", &i.sim, 1, 1.0)]));
    }
    crate::plot::render_grid(&tiles, 2)
}

/// Fewest beams with a surface and an intensity for a fit of the detection terms.
pub const MIN_FIT_BEAMS: u64 = 20_000;
/// Fewest of them beyond 70 deg of incidence, for the grazing terms.
pub const MIN_GRAZING_BEAMS: u64 = 2_000;
/// Fewest residuals in a range bin for its noise to count.
pub const MIN_NOISE_RESIDUALS: usize = 2_000;

/// `pedscan sensor-fit`'s arguments.
#[derive(clap::Args, Debug, Clone)]
pub struct SensorFitRequest {
    /// Recordings of one sensor: Velodyne or Ouster .pcap files (Ouster: its metadata .json beside it), folders of KITTI .bin or .pcd frames,
    /// or pedscan outputs (their people left out).
    #[arg(required = true)]
    pub recs: Vec<PathBuf>,
    /// Where to write the fitted `[sensor_model]` (TOML, the fit's figures as comments).
    #[arg(long)]
    pub out: PathBuf,
    /// The recordings' sensor: a preset or a TOML file.
    #[arg(long, default_value = "hdl32e")]
    pub sensor: String,
    /// The recordings' intensity units (intensity = this * reflectance * cos(incidence));
    /// default 100 for a Velodyne capture (calibrated reflectivity, percent), a pedscan
    /// output's own, else 1.
    #[arg(long)]
    pub intensity_scale: Option<f64>,
    /// Measure at most this many frames of each recording, evenly spaced (default: all).
    #[arg(long)]
    pub max_frames: Option<usize>,
}

/// What `sensor-fit` found, and the TOML it wrote.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SensorFit {
    pub detection: crate::realism::fit::DetectionFit,
    /// The range noise taken (the smallest robust sd of a range bin) and every bin's.
    pub range_noise_m: f64,
    pub noise_by_range: Vec<(f64, usize, f64)>,
    pub platform: Option<crate::realism::fit::PlatformFit>,
    pub toml: String,
}

/// The `[sensor_model]` terms a recording cannot tell, and why.
pub const NOT_FITTED: [(&str, &str); 6] = [
    ("laser_bias_m", "each laser's bias needs the true range of what it saw"),
    ("divergence_mrad, mixed_return_m", "footprints show at silhouettes, which the plane estimator leaves out"),
    ("*_reflectance", "recordings hold no labeled people"),
    ("intensity_scale", "the intensity's units are the source's definition (--intensity-scale)"),
    ("rolling_shutter", "a capture's own sweep is read from its packets"),
    ("enabled", "a switch"),
];

/// Runs `pedscan sensor-fit`: measures every recording on the sensor's grid, fits the
/// detection terms and the range noise, writes the TOML (whole or not at all).
pub fn sensor_fit(req: &SensorFitRequest) -> Result<SensorFit> {
    if req.max_frames == Some(0) {
        return Err(Error::input("--max-frames", "must be at least 1"));
    }
    let sensor = Sensor::from_name_or_file(&req.sensor)?;
    let grid = Grid { dirs: sensor.beam_dirs(), sensor };
    let mut samples = Vec::new();
    let mut residuals: Vec<Vec<f32>> = vec![Vec::new(); crate::realism::RANGE_BINS];
    let mut scale = None;
    let beams = grid.dirs.len();
    let (mut beam_holes, mut beam_frames) = (vec![0u32; beams], vec![0u32; beams]);
    let mut lines = vec!["# pedscan sensor-fit: the [sensor_model] terms these recordings tell, fitted by maximum".to_string(), "# likelihood over every beam whose neighbours define a surface (pedscan realism's estimator).".into()];
    for rec in &req.recs {
        let m = measure_with(rec, &grid, req.max_frames, true)?;
        if !m.has_intensity {
            return Err(Error::input(
                rec.display(),
                "records no intensity: the detection terms follow the received power (reflectance), which it cannot tell",
            ));
        }
        let s = match req.intensity_scale {
            Some(s) => s,
            None => intensity_scale_of(rec)?,
        };
        if !(s > 0.0 && s.is_finite()) {
            return Err(Error::input("--intensity-scale", format!("{s} must be a positive number")));
        }
        if scale.is_some_and(|x| x != s) {
            return Err(Error::input(rec.display(), "another intensity scale than the recordings before it: fit recordings of one kind together"));
        }
        scale = Some(s);
        lines.push(format!("# {}: {} frames, {} beams, {:.1} % holes", rec.display(), m.frames, m.beams(), 100.0 * m.holes() as f64 / m.beams().max(1) as f64));
        for (k, r) in m.residuals.iter().enumerate() {
            residuals[k].extend_from_slice(r);
        }
        for i in 0..m.beam_frames.len().min(beams) {
            beam_holes[i] += m.beam_holes[i];
            beam_frames[i] += m.beam_frames[i];
        }
        samples.extend(m.samples.unwrap_or_default());
    }
    let scale = scale.unwrap_or(1.0);
    let all = req.recs.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ");
    let fit = crate::realism::fit::fit_detection(&samples, scale, MIN_FIT_BEAMS).ok_or_else(|| {
        Error::input(&all, format!("{} beams with a surface and an intensity: too few to fit the detection terms (want {MIN_FIT_BEAMS})", samples.iter().filter(|s| s.intensity > 0.0).count()))
    })?;
    let grazing = samples.iter().filter(|s| s.intensity > 0.0 && s.incidence_deg >= 70.0).count() as u64;
    if grazing < MIN_GRAZING_BEAMS {
        return Err(Error::input(&all, format!("{grazing} beams beyond 70 deg of incidence: too few to fit the grazing terms (want {MIN_GRAZING_BEAMS})")));
    }
    let noise_by_range: Vec<(f64, usize, f64)> = residuals
        .iter()
        .enumerate()
        .filter(|(_, r)| r.len() >= MIN_NOISE_RESIDUALS)
        .filter_map(|(k, r)| crate::realism::robust_sd(r).map(|sd| (k as f64 * crate::realism::RANGE_BIN_M, r.len(), sd)))
        .collect();
    let Some(&(_, _, noise)) = noise_by_range.iter().min_by(|a, b| a.2.total_cmp(&b.2)) else {
        return Err(Error::input(&all, format!("no range bin with {MIN_NOISE_RESIDUALS} residuals below 60 deg of incidence: too few to fit the range noise")));
    };
    lines.push(format!("# intensity scale {scale}; {} beams fitted, {} holes; mean -log-likelihood per beam {:.4}", fit.beams, fit.holes, fit.nll_per_beam));
    lines.push("# hole rate by incidence, observed / fitted (beams):".into());
    for &(lo, n, obs, pred) in fit.by_incidence.iter().filter(|b| b.1 >= crate::realism::MIN_BEAMS) {
        lines.push(format!("#   {lo:>4.0}-{:<4.0} deg  {:5.1} % / {:5.1} %  ({n})", lo + crate::realism::INCIDENCE_BIN_DEG, 100.0 * obs, 100.0 * pred));
    }
    lines.push(format!("# range noise, robust sd per range bin below 60 deg (the smallest taken: a surface's roughness adds to the sensor's own):"));
    for &(lo, n, sd) in &noise_by_range {
        lines.push(format!("#   {lo:>4.0}-{:<4.0} m  {:6.1} mm  ({n} residuals)", lo + crate::realism::RANGE_BIN_M, 1000.0 * sd));
    }
    let platform = crate::realism::fit::fit_platform(&beam_holes, &beam_frames, &grid.dirs);
    match &platform {
        Some(p) => lines.push(format!(
            "# platform: {} beams behind and below the sensor are blind in {:.0} % of their frames or more; one box \
             {} m below the sensor (the beams tell angles, not size) hides them with intersection over union {:.2}",
            p.blind,
            100.0 * crate::realism::fit::PLATFORM_BLIND,
            crate::realism::fit::PLATFORM_TOP_M,
            p.iou
        )),
        None => lines.push(format!(
            "# platform: none (fewer than {} beams behind and below the sensor are blind)",
            crate::realism::fit::PLATFORM_MIN_BEAMS
        )),
    }
    lines.push("# not fitted (the recordings cannot tell):".into());
    for (k, why) in NOT_FITTED {
        lines.push(format!("#   {k}: {why}"));
    }
    lines.push("[sensor_model]".into());
    lines.push(format!("dropout_rate = {:.4}", fit.dropout_rate));
    lines.push(format!("grazing_deg = [{:.1}, 90.0]", fit.grazing_start_deg));
    lines.push(format!("grazing_loss = {:.3}", fit.grazing_loss));
    lines.push(format!("detection_range_m = {:.1}", fit.detection_range_m));
    lines.push(format!("detection_softness = {:.3}", fit.detection_softness));
    lines.push(format!("range_noise_m = {:.4}", noise));
    if let Some(p) = &platform {
        let v = |a: [f64; 3]| format!("[{:.3}, {:.3}, {:.3}]", a[0], a[1], a[2]);
        lines.push("[[sensor_model.platform]]".into());
        lines.push(format!("min_m = {}", v(p.platform.min_m)));
        lines.push(format!("max_m = {}", v(p.platform.max_m)));
    }
    let toml = lines.join("\n") + "\n";
    crate::output::files::write_file(&req.out, &toml)?;
    Ok(SensorFit { detection: fit, range_noise_m: noise, noise_by_range, platform, toml })
}
