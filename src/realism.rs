//! Real against simulated: one estimator measures a recording and a pedscan output the same
//! way, so their curves can be laid side by side (`pedscan realism`) and the sensor model's
//! terms fitted to a recording (`pedscan sensor-fit`).
//!
//! # The estimator
//!
//! Every beam of a frame on the sensor grid, returned or not, gets the surface its
//! *neighbours* define: the returns in the window of rows `r - 1 ..= r + 1` and columns
//! `c - 2 ..= c + 2` (azimuth wraps), the beam itself left out. A plane is fitted to those
//! points (least squares: the eigenvector of the smallest eigenvalue of their covariance);
//! while the farthest point lies more than `PLANE_TOL_M + PLANE_TOL_REL * mean range` off the
//! plane it is dropped and the plane refitted (a window across a depth step keeps its larger
//! side). The beam has a surface when at least [`MIN_NEIGHBOURS`] points from two rows or
//! more remain, they span a plane (not a line), the beam meets the plane in front of the
//! sensor within a factor [`REACH_FACTOR`] of the neighbours' ranges, and not parallel to it.
//! Then:
//!
//! * its **incidence** is the angle between the beam and the plane's normal;
//! * its **expected range** is where the beam meets the plane;
//! * for a return, its **range residual** is the measured range minus the expected one,
//!   divided by `sqrt(1 + 1/k)` for a plane fitted to `k` points (the plane's own error at the
//!   window's centre), so that on a plane with independent range noise of sd `s` the residuals'
//!   sd is `s`.
//!
//! A beam's own return never decides whether it has a surface or at what incidence, so the
//! hole rate per incidence bin is not biased by the holes themselves; holes with no surface
//! around them (the sky, beyond the range limit, a wide dropout patch) are counted apart.
//! Beams that are neither a return nor a hole (a pedscan output's people, `EXCLUDED`) are left
//! out of every statistic and of every plane.
//!
//! # The statistics
//!
//! Hole rate per incidence bin (5 deg, 0-90) and per expected-range bin ([`RANGE_BIN_M`]);
//! range noise per range bin: the robust sd (1.4826 x the median absolute deviation) of the
//! residuals of returns at incidence below [`NOISE_MAX_INCIDENCE_DEG`] (beyond it a plane's
//! own error grows as 1 / cos); the intensity of returns; the hole rate per row (every beam).

use glam::DVec3;
use serde::Serialize;
use std::fmt;

/// A beam to leave out of every statistic (e.g. a pedscan output's people).
pub const EXCLUDED: f32 = -1.0;
/// Rows either side of the beam in its window.
pub const ROW_REACH: usize = 1;
/// Columns either side of the beam in its window.
pub const COL_REACH: usize = 2;
/// Fewest neighbouring returns that define a surface.
pub const MIN_NEIGHBOURS: usize = 6;
/// Plane tolerance: absolute part, metres.
pub const PLANE_TOL_M: f64 = 0.06;
/// Plane tolerance: part proportional to the window's mean range.
pub const PLANE_TOL_REL: f64 = 0.01;
/// The beam must meet the plane between the neighbours' nearest range / this and their
/// farthest x this.
pub const REACH_FACTOR: f64 = 2.0;
/// Width of the incidence bins, degrees.
pub const INCIDENCE_BIN_DEG: f64 = 5.0;
/// Width of the range bins, metres.
pub const RANGE_BIN_M: f64 = 5.0;
/// Range bins (the last takes everything beyond).
pub const RANGE_BINS: usize = 20;
/// Range noise is measured on returns seen at less than this incidence, degrees.
pub const NOISE_MAX_INCIDENCE_DEG: f64 = 60.0;
/// A bin is compared only when both sides have at least this many beams.
pub const MIN_BEAMS: u64 = 1000;
/// A range-noise bin is compared only when both sides have at least this many residuals.
pub const MIN_RESIDUALS: usize = 200;
/// Bins of the intensity histogram.
pub const INTENSITY_BINS: usize = 25;

/// What the estimator finds at one beam.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    /// Angle between the beam and the surface normal, degrees, 0..=90.
    pub incidence_deg: f64,
    /// Where the beam meets the neighbours' plane, metres.
    pub expected_range_m: f64,
    /// Measured minus expected range, normalised for the plane's own error (returns only).
    pub residual_m: Option<f64>,
    /// The median intensity of the neighbours that define the plane (when the source has
    /// intensities): what the surface returns around the beam, whether or not it returned.
    pub intensity: Option<f32>,
}

/// Symmetric 3x3 eigen decomposition (cyclic Jacobi): eigenvalues ascending, with their unit
/// eigenvectors.
fn eigen_sym3(m: [[f64; 3]; 3]) -> ([f64; 3], [DVec3; 3]) {
    let mut a = m;
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..32 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        let scale = a[0][0].abs() + a[1][1].abs() + a[2][2].abs();
        if off <= 1e-15 * scale.max(1e-300) {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q].abs() < 1e-300 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = c * akp - s * akq;
                a[k][q] = s * akp + c * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = c * apk - s * aqk;
                a[q][k] = s * apk + c * aqk;
            }
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    let mut idx = [0, 1, 2];
    idx.sort_by(|&i, &j| a[i][i].total_cmp(&a[j][j]));
    let vals = idx.map(|i| a[i][i]);
    let vecs = idx.map(|i| DVec3::new(v[0][i], v[1][i], v[2][i]).normalize_or_zero());
    (vals, vecs)
}

/// A fitted plane: centroid, unit normal, the middle eigenvalue (in-plane spread), points.
struct Plane {
    centroid: DVec3,
    normal: DVec3,
    spread: f64,
}

fn fit_plane(pts: &[(DVec3, usize)]) -> Plane {
    let n = pts.len() as f64;
    let c = pts.iter().map(|p| p.0).sum::<DVec3>() / n;
    let mut m = [[0.0; 3]; 3];
    for (p, _) in pts {
        let d = (*p - c).to_array();
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += d[i] * d[j] / n;
            }
        }
    }
    let (vals, vecs) = eigen_sym3(m);
    Plane { centroid: c, normal: vecs[0], spread: vals[1].max(0.0) }
}

/// The estimator over one frame: `range` row-major (`rows * cols`), `> 0` a return, `0` a
/// hole, [`EXCLUDED`] (or any negative or non-finite value) left out; `dirs` the unit beam
/// directions, row-major. Writes one entry per beam into `out`.
pub fn estimate_frame(rows: usize, cols: usize, dirs: &[DVec3], range: &[f32], out: &mut Vec<Option<Surface>>) {
    estimate_frame_with(rows, cols, dirs, range, &[], out)
}

/// [`estimate_frame`] with each beam's intensity (empty: none), for [`Surface::intensity`].
pub fn estimate_frame_with(rows: usize, cols: usize, dirs: &[DVec3], range: &[f32], intensity: &[f32], out: &mut Vec<Option<Surface>>) {
    assert_eq!(dirs.len(), rows * cols);
    assert_eq!(range.len(), rows * cols);
    out.clear();
    out.resize(rows * cols, None);
    // The neighbouring returns: point and beam index.
    let mut pts: Vec<(DVec3, usize)> = Vec::with_capacity((2 * ROW_REACH + 1) * (2 * COL_REACH + 1));
    let mut scratch = Vec::new();
    for r in 0..rows {
        for c in 0..cols {
            let i = r * cols + c;
            let own = range[i];
            if !(own >= 0.0) {
                continue;
            }
            pts.clear();
            for rr in r.saturating_sub(ROW_REACH)..=(r + ROW_REACH).min(rows - 1) {
                for dc in -(COL_REACH as i64)..=COL_REACH as i64 {
                    let cc = (c as i64 + dc).rem_euclid(cols as i64) as usize;
                    let j = rr * cols + cc;
                    if j == i {
                        continue;
                    }
                    let rj = range[j];
                    if rj > 0.0 && rj.is_finite() {
                        pts.push((dirs[j] * rj as f64, j));
                    }
                }
            }
            out[i] = surface_at(&mut pts, cols, dirs[i], own).map(|mut s| {
                if !intensity.is_empty() {
                    scratch.clear();
                    scratch.extend(pts.iter().map(|p| intensity[p.1] as f64).filter(|v| v.is_finite()));
                    s.intensity = (!scratch.is_empty()).then(|| median_in_place(&mut scratch) as f32);
                }
                s
            });
        }
    }
}

/// The surface of a beam from its neighbouring returns `pts` (point, beam index) on a grid of
/// `cols` columns.
fn surface_at(pts: &mut Vec<(DVec3, usize)>, cols: usize, dir: DVec3, own: f32) -> Option<Surface> {
    let plane = loop {
        if pts.len() < MIN_NEIGHBOURS {
            return None;
        }
        let first_row = pts[0].1 / cols;
        if pts.iter().all(|p| p.1 / cols == first_row) {
            return None;
        }
        let plane = fit_plane(pts);
        let mean_range = pts.iter().map(|p| p.0.length()).sum::<f64>() / pts.len() as f64;
        let tol = PLANE_TOL_M + PLANE_TOL_REL * mean_range;
        let (worst, dist) = pts
            .iter()
            .enumerate()
            .map(|(k, p)| (k, (p.0 - plane.centroid).dot(plane.normal).abs()))
            .fold((0, -1.0), |a, b| if b.1 > a.1 { b } else { a });
        if dist <= tol {
            // Points on a line (or a point) span no plane.
            if plane.spread.sqrt() < 1e-3 * mean_range.max(1e-3) {
                return None;
            }
            break plane;
        }
        pts.swap_remove(worst);
    };
    let along = plane.normal.dot(dir);
    if along.abs() < 1e-3 {
        return None;
    }
    let t = plane.normal.dot(plane.centroid) / along;
    let (near, far) = pts.iter().fold((f64::MAX, 0.0f64), |(n, f), p| {
        let l = p.0.length();
        (n.min(l), f.max(l))
    });
    if !(t > 0.0 && t >= near / REACH_FACTOR && t <= far * REACH_FACTOR) {
        return None;
    }
    let k = pts.len() as f64;
    let residual_m = (own > 0.0).then(|| (own as f64 - t) / (1.0 + 1.0 / k).sqrt());
    Some(Surface { incidence_deg: along.abs().min(1.0).acos().to_degrees(), expected_range_m: t, residual_m, intensity: None })
}

/// Beams and holes in one bin.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Count {
    pub beams: u64,
    pub holes: u64,
}

impl Count {
    fn add(&mut self, hole: bool) {
        self.beams += 1;
        self.holes += u64::from(hole);
    }
    /// Holes / beams, `None` for an empty bin.
    pub fn rate(&self) -> Option<f64> {
        (self.beams > 0).then(|| self.holes as f64 / self.beams as f64)
    }
}

/// The statistics of one source (a recording or a pedscan output), accumulated frame by frame.
#[derive(Clone, Debug)]
pub struct Measure {
    pub frames: usize,
    /// Per incidence bin, beams with a surface.
    pub by_incidence: Vec<Count>,
    /// Per expected-range bin, beams with a surface.
    pub by_range: Vec<Count>,
    /// Rows of the grid (see [`Measure::by_row`]).
    pub rows: usize,
    /// Beams with no surface around them.
    pub no_surface: Count,
    /// Range residuals per range bin (returns below [`NOISE_MAX_INCIDENCE_DEG`]).
    pub residuals: Vec<Vec<f32>>,
    /// Intensity of every return, when the source has one.
    pub intensity: Vec<f32>,
    /// Whether the source records an intensity.
    pub has_intensity: bool,
    /// Every beam with a surface, when kept ([`Measure::keep_samples`]): what a fit needs.
    pub samples: Option<Vec<Sample>>,
    /// Per beam of the grid: frames in which it was a hole, and frames it was counted.
    pub beam_holes: Vec<u32>,
    pub beam_frames: Vec<u32>,
    surfaces: Vec<Option<Surface>>,
}

/// One beam with a surface, for fitting.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    pub incidence_deg: f32,
    pub expected_range_m: f32,
    /// The neighbours' median intensity (NaN without one).
    pub intensity: f32,
    pub hole: bool,
}

/// The bin of a value on bins of `width` from 0, the last bin open.
fn bin_of(x: f64, width: f64, bins: usize) -> usize {
    ((x / width).max(0.0) as usize).min(bins - 1)
}

impl Measure {
    pub fn new(rows: usize) -> Measure {
        Measure {
            frames: 0,
            by_incidence: vec![Count::default(); (90.0 / INCIDENCE_BIN_DEG) as usize],
            by_range: vec![Count::default(); RANGE_BINS],
            rows,
            no_surface: Count::default(),
            residuals: vec![Vec::new(); RANGE_BINS],
            intensity: Vec::new(),
            has_intensity: false,
            samples: None,
            beam_holes: Vec::new(),
            beam_frames: Vec::new(),
            surfaces: Vec::new(),
        }
    }

    /// The same, keeping every beam with a surface as a [`Sample`].
    pub fn keep_samples(mut self) -> Measure {
        self.samples = Some(Vec::new());
        self
    }

    /// Adds a frame: `range` as for [`estimate_frame`]; `intensity` per beam (empty when the
    /// source has none).
    pub fn add_frame(&mut self, cols: usize, dirs: &[DVec3], range: &[f32], intensity: &[f32]) {
        let rows = self.rows;
        estimate_frame_with(rows, cols, dirs, range, intensity, &mut self.surfaces);
        self.frames += 1;
        self.has_intensity |= !intensity.is_empty();
        let n_inc = self.by_incidence.len();
        if self.beam_frames.len() != range.len() {
            self.beam_holes = vec![0; range.len()];
            self.beam_frames = vec![0; range.len()];
        }
        for (i, (&r, s)) in range.iter().zip(&self.surfaces).enumerate() {
            if !(r >= 0.0) {
                continue;
            }
            let hole = r == 0.0;
            self.beam_frames[i] += 1;
            self.beam_holes[i] += u32::from(hole);
            if !hole {
                if let Some(&v) = intensity.get(i) {
                    if v.is_finite() {
                        self.intensity.push(v);
                    }
                }
            }
            match s {
                None => self.no_surface.add(hole),
                Some(s) => {
                    if let Some(v) = &mut self.samples {
                        v.push(Sample {
                            incidence_deg: s.incidence_deg as f32,
                            expected_range_m: s.expected_range_m as f32,
                            intensity: s.intensity.unwrap_or(f32::NAN),
                            hole,
                        });
                    }
                    self.by_incidence[bin_of(s.incidence_deg, INCIDENCE_BIN_DEG, n_inc)].add(hole);
                    let rb = bin_of(s.expected_range_m, RANGE_BIN_M, RANGE_BINS);
                    self.by_range[rb].add(hole);
                    if let Some(res) = s.residual_m {
                        if s.incidence_deg < NOISE_MAX_INCIDENCE_DEG {
                            self.residuals[bin_of(r as f64, RANGE_BIN_M, RANGE_BINS)].push(res as f32);
                        }
                    }
                }
            }
        }
    }

    /// Per row, every beam that is not excluded: the per-beam counts summed along the row.
    pub fn by_row(&self) -> Vec<Count> {
        let cols = self.beam_frames.len() / self.rows.max(1);
        (0..self.rows)
            .map(|r| {
                let span = r * cols..(r + 1) * cols;
                Count {
                    beams: self.beam_frames.get(span.clone()).map_or(0, |v| v.iter().map(|&n| n as u64).sum()),
                    holes: self.beam_holes.get(span).map_or(0, |v| v.iter().map(|&n| n as u64).sum()),
                }
            })
            .collect()
    }

    /// Every beam counted (not excluded).
    pub fn beams(&self) -> u64 {
        self.beam_frames.iter().map(|&n| n as u64).sum()
    }

    /// Every hole counted.
    pub fn holes(&self) -> u64 {
        self.beam_holes.iter().map(|&n| n as u64).sum()
    }
}

/// Robust sd: 1.4826 x the median absolute deviation from the median.
pub fn robust_sd(values: &[f32]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut v: Vec<f64> = values.iter().map(|&x| x as f64).collect();
    let med = median_in_place(&mut v);
    let mut dev: Vec<f64> = v.iter().map(|x| (x - med).abs()).collect();
    Some(1.4826 * median_in_place(&mut dev))
}

fn median_in_place(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// The 1-Wasserstein distance between two samples (the mean absolute difference of their
/// quantile functions, on 1,000 quantiles).
pub fn wasserstein1(a: &[f32], b: &[f32]) -> Option<f64> {
    if a.is_empty() || b.is_empty() {
        return None;
    }
    let sorted = |x: &[f32]| {
        let mut v: Vec<f64> = x.iter().map(|&x| x as f64).collect();
        v.sort_by(f64::total_cmp);
        v
    };
    let (a, b) = (sorted(a), sorted(b));
    let q = |v: &[f64], u: f64| v[((u * v.len() as f64) as usize).min(v.len() - 1)];
    let n = 1000;
    Some((0..n).map(|k| (k as f64 + 0.5) / n as f64).map(|u| (q(&a, u) - q(&b, u)).abs()).sum::<f64>() / n as f64)
}

/// One bin of a curve, real against simulated.
#[derive(Clone, Debug, Serialize)]
pub struct Point {
    /// The bin's lower and upper edge (incidence deg, range m, or a row's elevation twice).
    pub lo: f64,
    pub hi: f64,
    pub rec_n: u64,
    pub rec: Option<f64>,
    pub sim_n: u64,
    pub sim: Option<f64>,
    /// sim - rec, where both sides have enough beams.
    pub gap: Option<f64>,
}

/// A curve and its largest gap.
#[derive(Clone, Debug, Serialize)]
pub struct Curve {
    pub name: String,
    pub unit: String,
    pub points: Vec<Point>,
    /// The point with the largest |gap| (index into `points`).
    pub largest_gap: Option<usize>,
}

impl Curve {
    fn new(name: &str, unit: &str, points: Vec<Point>) -> Curve {
        let largest_gap = points
            .iter()
            .enumerate()
            .filter_map(|(k, p)| p.gap.map(|g| (k, g.abs())))
            .fold(None, |best: Option<(usize, f64)>, (k, g)| if best.is_none_or(|b| g > b.1) { Some((k, g)) } else { best });
        Curve { name: name.into(), unit: unit.into(), points, largest_gap: largest_gap.map(|b| b.0) }
    }
}

/// Summary of one side.
#[derive(Clone, Debug, Serialize)]
pub struct Side {
    pub source: String,
    pub frames: usize,
    pub beams: u64,
    pub holes: u64,
    /// Beams with no surface around them, and the holes among them.
    pub no_surface: Count,
    pub intensity_returns: usize,
    pub intensity_median: Option<f64>,
    pub intensity_p99: Option<f64>,
}

/// The intensity comparison.
#[derive(Clone, Debug, Serialize)]
pub struct IntensityReport {
    /// Histogram bin edges (up to the larger 99.5th percentile of the two sides).
    pub edges: Vec<f64>,
    /// Fraction of returns per bin.
    pub rec: Vec<f64>,
    pub sim: Vec<f64>,
    /// 1-Wasserstein distance in the intensities' units.
    pub wasserstein: Option<f64>,
    /// The same after dividing each side by its own median (the shape of the distributions,
    /// whatever their units).
    pub wasserstein_over_median: Option<f64>,
}

/// `pedscan realism`'s report.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub rec: Side,
    pub sim: Side,
    pub rows: Vec<f64>,
    pub hole_rate_by_incidence: Curve,
    pub hole_rate_by_range: Curve,
    pub range_noise_by_range: Curve,
    pub hole_rate_by_row: Curve,
    /// `None` when either side records no intensity (and why in `notes`).
    pub intensity: Option<IntensityReport>,
    pub notes: Vec<String>,
    pub min_beams: u64,
    pub min_residuals: usize,
}

fn count_curve(name: &str, rec: &[Count], sim: &[Count], edges: impl Fn(usize) -> (f64, f64), min: u64) -> Curve {
    let points = rec
        .iter()
        .zip(sim)
        .enumerate()
        .map(|(k, (a, b))| {
            let (lo, hi) = edges(k);
            let gap = (a.beams >= min && b.beams >= min).then(|| b.rate().unwrap_or(0.0) - a.rate().unwrap_or(0.0));
            Point { lo, hi, rec_n: a.beams, rec: a.rate(), sim_n: b.beams, sim: b.rate(), gap }
        })
        .collect();
    Curve::new(name, "fraction", points)
}

fn side(source: &str, m: &Measure) -> Side {
    let mut v: Vec<f64> = m.intensity.iter().map(|&x| x as f64).collect();
    v.sort_by(f64::total_cmp);
    let q = |u: f64| (!v.is_empty()).then(|| v[((u * v.len() as f64) as usize).min(v.len() - 1)]);
    Side {
        source: source.into(),
        frames: m.frames,
        beams: m.beams(),
        holes: m.holes(),
        no_surface: m.no_surface,
        intensity_returns: m.intensity.len(),
        intensity_median: q(0.5),
        intensity_p99: q(0.99),
    }
}

fn over_median(v: &[f32]) -> Vec<f32> {
    let mut s: Vec<f64> = v.iter().map(|&x| x as f64).collect();
    let med = if s.is_empty() { 0.0 } else { median_in_place(&mut s) };
    if med > 0.0 {
        v.iter().map(|&x| (x as f64 / med) as f32).collect()
    } else {
        Vec::new()
    }
}

/// Compares a recording's statistics (`rec`) with a pedscan output's (`sim`) measured on the
/// same grid; `elevation_deg` names the rows.
pub fn compare(rec_source: &str, rec: &Measure, sim_source: &str, sim: &Measure, elevation_deg: &[f64]) -> Report {
    let inc = |k: usize| (k as f64 * INCIDENCE_BIN_DEG, (k + 1) as f64 * INCIDENCE_BIN_DEG);
    let rng = |k: usize| (k as f64 * RANGE_BIN_M, if k + 1 == RANGE_BINS { f64::INFINITY } else { (k + 1) as f64 * RANGE_BIN_M });
    let noise = (0..RANGE_BINS)
        .map(|k| {
            let (lo, hi) = rng(k);
            let (a, b) = (&rec.residuals[k], &sim.residuals[k]);
            let (sa, sb) = (robust_sd(a), robust_sd(b));
            let gap = match (sa, sb) {
                (Some(x), Some(y)) if a.len() >= MIN_RESIDUALS && b.len() >= MIN_RESIDUALS && x > 0.0 => Some(y / x - 1.0),
                _ => None,
            };
            Point { lo, hi, rec_n: a.len() as u64, rec: sa, sim_n: b.len() as u64, sim: sb, gap }
        })
        .collect();
    let mut notes = Vec::new();
    let intensity = if !rec.has_intensity || !sim.has_intensity {
        let which = if !rec.has_intensity { rec_source } else { sim_source };
        notes.push(format!("{which}: records no intensity, so the intensities are not compared"));
        None
    } else {
        let mut all: Vec<f64> = rec.intensity.iter().chain(&sim.intensity).map(|&x| x as f64).collect();
        all.sort_by(f64::total_cmp);
        let top = if all.is_empty() { 1.0 } else { all[((0.995 * all.len() as f64) as usize).min(all.len() - 1)].max(1e-9) };
        let hist = |v: &[f32]| {
            let mut h = vec![0.0; INTENSITY_BINS];
            for &x in v {
                h[bin_of(x as f64, top / INTENSITY_BINS as f64, INTENSITY_BINS)] += 1.0;
            }
            let n = v.len().max(1) as f64;
            h.iter().map(|c| c / n).collect::<Vec<f64>>()
        };
        Some(IntensityReport {
            edges: (0..=INTENSITY_BINS).map(|k| k as f64 * top / INTENSITY_BINS as f64).collect(),
            rec: hist(&rec.intensity),
            sim: hist(&sim.intensity),
            wasserstein: wasserstein1(&rec.intensity, &sim.intensity),
            wasserstein_over_median: wasserstein1(&over_median(&rec.intensity), &over_median(&sim.intensity)),
        })
    };
    Report {
        rec: side(rec_source, rec),
        sim: side(sim_source, sim),
        rows: elevation_deg.to_vec(),
        hole_rate_by_incidence: count_curve("hole rate by incidence", &rec.by_incidence, &sim.by_incidence, inc, MIN_BEAMS),
        hole_rate_by_range: count_curve("hole rate by range", &rec.by_range, &sim.by_range, rng, MIN_BEAMS),
        range_noise_by_range: Curve::new("range noise (robust sd) by range", "m", noise),
        hole_rate_by_row: count_curve("hole rate by row", &rec.by_row(), &sim.by_row(), |k| (elevation_deg[k], elevation_deg[k]), MIN_BEAMS),
        intensity,
        notes,
        min_beams: MIN_BEAMS,
        min_residuals: MIN_RESIDUALS,
    }
}

fn pct(x: Option<f64>) -> String {
    x.map_or("-".into(), |v| format!("{:.1}", 100.0 * v))
}

impl Report {
    fn curve_table(f: &mut fmt::Formatter<'_>, c: &Curve, x: &str, value: impl Fn(Option<f64>) -> String, gap: impl Fn(f64) -> String) -> fmt::Result {
        writeln!(f, "\n{} ({}):", c.name, x)?;
        writeln!(f, "{:>14} {:>10} {:>9} {:>10} {:>9} {:>9}", "bin", "rec beams", "rec", "sim beams", "sim", "gap")?;
        for p in &c.points {
            if p.rec_n == 0 && p.sim_n == 0 {
                continue;
            }
            let bin = if p.lo == p.hi { format!("{:.2}", p.lo) } else if p.hi.is_infinite() { format!("{:.0}+", p.lo) } else { format!("{:.0}-{:.0}", p.lo, p.hi) };
            writeln!(f, "{bin:>14} {:>10} {:>9} {:>10} {:>9} {:>9}", p.rec_n, value(p.rec), p.sim_n, value(p.sim), p.gap.map_or("-".into(), &gap))?;
        }
        match c.largest_gap {
            Some(k) => {
                let p = &c.points[k];
                let bin = if p.lo == p.hi { format!("{:.2}", p.lo) } else { format!("{:.0}-{:.0}", p.lo, p.hi) };
                writeln!(f, "largest gap: {} at {bin}", gap(p.gap.unwrap_or(0.0)))
            }
            None => writeln!(f, "largest gap: no bin with enough beams on both sides"),
        }
    }
}

impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (name, s) in [("rec", &self.rec), ("sim", &self.sim)] {
            writeln!(
                f,
                "{name}: {} ({} frames, {} beams, holes {:.1} %; {:.1} % of beams have no surface around them, {:.1} % of those holes)",
                s.source,
                s.frames,
                s.beams,
                100.0 * s.holes as f64 / s.beams.max(1) as f64,
                100.0 * s.no_surface.beams as f64 / s.beams.max(1) as f64,
                100.0 * s.no_surface.rate().unwrap_or(0.0)
            )?;
        }
        let pp = |g: f64| format!("{:+.1} pp", 100.0 * g);
        Self::curve_table(f, &self.hole_rate_by_incidence, "deg, beams with a surface; holes %", pct, pp)?;
        Self::curve_table(f, &self.hole_rate_by_range, "m, expected range; holes %", pct, pp)?;
        Self::curve_table(
            f,
            &self.range_noise_by_range,
            &format!("m; mm, returns below {NOISE_MAX_INCIDENCE_DEG} deg of incidence"),
            |v| v.map_or("-".into(), |x| format!("{:.1}", 1000.0 * x)),
            |g| format!("{:+.0} %", 100.0 * g),
        )?;
        Self::curve_table(f, &self.hole_rate_by_row, "row elevation deg; holes %", pct, pp)?;
        match &self.intensity {
            Some(i) => {
                writeln!(
                    f,
                    "\nintensity: rec median {}, p99 {}; sim median {}, p99 {}",
                    self.rec.intensity_median.map_or("-".into(), |v| format!("{v:.3}")),
                    self.rec.intensity_p99.map_or("-".into(), |v| format!("{v:.3}")),
                    self.sim.intensity_median.map_or("-".into(), |v| format!("{v:.3}")),
                    self.sim.intensity_p99.map_or("-".into(), |v| format!("{v:.3}"))
                )?;
                writeln!(
                    f,
                    "Wasserstein-1 distance: {}, {} (each over its median)",
                    i.wasserstein.map_or("-".into(), |v| format!("{v:.3}")),
                    i.wasserstein_over_median.map_or("-".into(), |v| format!("{v:.3}"))
                )?;
            }
            None => writeln!(f, "\nintensity: not compared")?,
        }
        for n in &self.notes {
            writeln!(f, "note: {n}")?;
        }
        write!(f, "(bins compared with >= {} beams, >= {} residuals on each side)", self.min_beams, self.min_residuals)
    }
}

pub mod fit;
#[cfg(test)]
mod tests;
