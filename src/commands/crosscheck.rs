//! `pedscan crosscheck`: holds the raster path against the CPU ray-cast reference on the same
//! posed triangles, frame by frame. One render per frame is resampled three ways (no
//! refinement, plane, exact) so every mode is measured on identical input.
//!
//! Metrics on the human layer (people only, before compositing): beams both paths call human,
//! beams only one does, mask IoU, instance mix-ups, and the range error on beams both call
//! human; broken down by reference range (0-4, 4-8, 8+ m as in the paper's tables) and by
//! closeness to a cube-face seam (for the cylinder: to the azimuth wrap). The background
//! layer's range error is reported too.

use crate::config::{Config, Refine};
use crate::error::{Error, Result};
use crate::geometry::FrameGeometry;
use crate::output::png::{save_png, turbo};
use crate::backend::{self, Backend, BeamHits, Gpu, LayerKind, NO_TRIANGLE};
use crate::config::BackendChoice;
use crate::generator::Generator;
use crate::backend::raycast::{self, Bvh, Hit};
use image::RgbImage;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Distance bins of the paper's tables, metres.
pub const DISTANCE_BINS: [(&str, f64, f64); 3] = [("0-4", 0.0, 4.0), ("4-8", 4.0, 8.0), ("8+", 8.0, f64::INFINITY)];
/// A beam within this many face texels of a cube-face seam (the panorama's azimuth wrap)
/// counts as "near a seam".
pub const SEAM_TEXELS: f64 = 2.0;

/// Options of a cross-check run.
#[derive(Clone, Debug, Default)]
pub struct CrosscheckOptions {
    pub json: Option<PathBuf>,
    pub png: Option<PathBuf>,
    pub export_geometry: Option<PathBuf>,
}

/// Range-error statistics, metres.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct ErrorStats {
    pub count: usize,
    pub median: f64,
    pub p99: f64,
    pub max: f64,
    pub rms: f64,
    /// Fraction of the beams whose error exceeds 1 mm (a nearer part missed, a wrong surface).
    pub over_1mm: f64,
}

impl ErrorStats {
    pub fn from(errors: &mut [f64]) -> ErrorStats {
        if errors.is_empty() {
            return ErrorStats::default();
        }
        errors.sort_by(|a, b| a.total_cmp(b));
        let q = |p: f64| quantile_sorted(errors, p);
        let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
        let over = errors.iter().filter(|e| **e > 1e-3).count() as f64 / errors.len() as f64;
        ErrorStats { count: errors.len(), median: q(0.5), p99: q(0.99), max: *errors.last().unwrap(), rms, over_1mm: over }
    }
}

/// Agreement and range error of one refinement mode on one subset of beams.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct Agreement {
    pub both_human: usize,
    pub raster_only: usize,
    pub reference_only: usize,
    pub instance_mixups: usize,
    /// both / (both + raster only + reference only).
    pub human_beam_agreement: f64,
    pub range_error_m: ErrorStats,
}

#[derive(Default)]
struct Acc {
    both: usize,
    raster_only: usize,
    ref_only: usize,
    mixups: usize,
    errors: Vec<f64>,
}

impl Acc {
    fn finish(&mut self) -> Agreement {
        let union = self.both + self.raster_only + self.ref_only;
        Agreement {
            both_human: self.both,
            raster_only: self.raster_only,
            reference_only: self.ref_only,
            instance_mixups: self.mixups,
            human_beam_agreement: if union == 0 { 1.0 } else { self.both as f64 / union as f64 },
            range_error_m: ErrorStats::from(&mut self.errors),
        }
    }
}

/// One refinement mode over the whole run.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct ModeReport {
    pub human_beam_agreement: f64,
    /// Mean over frames with any human beam of |raster AND reference| / |raster OR reference|.
    pub mask_iou: f64,
    pub range_error_m: ErrorStats,
    pub overall: Agreement,
    pub by_distance: std::collections::BTreeMap<String, Agreement>,
    pub near_seam: Agreement,
    pub away_from_seam: Agreement,
}

/// The whole report (`--json`).
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub frames: usize,
    pub sensor: String,
    /// The raster views: `cube` or `cylinder`.
    pub projection: String,
    pub oversample: f64,
    pub lod_max_error_mrad: f64,
    pub device: String,
    /// How the checked backend cast the people with exact refinement: `proxies` (drawn into
    /// the beam panorama, covered beams cast exactly: a GPU's path, or `debug.people`) or
    /// `cpu` (binned or ray cast on the CPU).
    pub people_path: String,
    /// Top level (flattened): no refinement.
    #[serde(flatten)]
    pub unrefined: ModeReport,
    pub plane: ModeReport,
    /// Exact re-intersection (the default of `generate`).
    pub refined: ModeReport,
    /// Background layer, exact refinement against the reference.
    pub background_range_error_m: ErrorStats,
    pub background_beam_agreement: f64,
    pub timing_ms: Timing,
    /// One row per frame.
    pub per_frame: Vec<FrameRow>,
}

/// Per-frame agreement and median range error, unrefined and exact.
#[derive(Clone, Debug, Serialize)]
pub struct FrameRow {
    pub sequence: usize,
    pub frame: usize,
    /// Beams either path calls human (exact mode).
    pub human_beams: usize,
    pub agreement_none: f64,
    pub agreement_exact: f64,
    pub median_error_none_m: f64,
    pub median_error_exact_m: f64,
}

/// Counts of one comparison of raster hits against the reference, accumulated over frames.
#[derive(Clone, Debug, Default)]
pub struct Tally {
    /// Beams both paths call a hit.
    pub both: usize,
    /// Beams either path calls a hit.
    pub either: usize,
    /// |raster - reference| range on the beams both call a hit, metres.
    pub errors: Vec<f64>,
}

impl Tally {
    /// Adds one frame: `raster` hits against the `reference` cast of the same beams.
    pub fn add(&mut self, raster: &BeamHits, reference: &[Hit]) {
        for (b, r) in reference.iter().enumerate() {
            let rh = raster.triangle[b] != NO_TRIANGLE && raster.range_m[b] > 0.0;
            if rh || r.is_hit() {
                self.either += 1;
            }
            if rh && r.is_hit() {
                self.both += 1;
                self.errors.push((raster.range_m[b] as f64 - r.range_m).abs());
            }
        }
    }

    /// both / either (1 when neither path hit anything).
    pub fn agreement(&self) -> f64 {
        if self.either == 0 { 1.0 } else { self.both as f64 / self.either as f64 }
    }
}

/// Beams either path calls human, agreement and median error of one frame.
fn frame_stats(raster: &BeamHits, reference: &[Hit]) -> (usize, f64, f64) {
    let mut t = Tally::default();
    t.add(raster, reference);
    (t.either, t.agreement(), median(&mut t.errors))
}

/// Median milliseconds per frame of each path.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Timing {
    pub pose: f64,
    /// The people layer through the unrefined backend (render + nearest texel).
    pub raster_render: f64,
    /// The people layer through the checked backend (exact refinement), all of it.
    pub resample_exact: f64,
    pub raycast_build: f64,
    pub raycast_cast: f64,
}

struct ModeAcc {
    overall: Acc,
    bins: [Acc; 3],
    near_seam: Acc,
    away: Acc,
    iou_sum: f64,
    iou_frames: usize,
}

impl ModeAcc {
    fn new() -> ModeAcc {
        ModeAcc { overall: Acc::default(), bins: Default::default(), near_seam: Acc::default(), away: Acc::default(), iou_sum: 0.0, iou_frames: 0 }
    }

    fn add(&mut self, raster: &BeamHits, reference: &[Hit], geom: &FrameGeometry, seam: &[bool]) {
        let (mut inter, mut union) = (0usize, 0usize);
        for (b, r) in reference.iter().enumerate() {
            let rh = raster.triangle[b] != NO_TRIANGLE && raster.range_m[b] > 0.0;
            let fh = r.is_hit();
            if !rh && !fh {
                continue;
            }
            union += 1;
            let dist = if fh { r.range_m } else { raster.range_m[b] as f64 };
            let bin = DISTANCE_BINS.iter().position(|(_, lo, hi)| dist >= *lo && dist < *hi).unwrap_or(2);
            let accs: [&mut Acc; 3] = {
                let (a, b2) = (&mut self.overall, &mut self.bins[bin]);
                let s = if seam[b] { &mut self.near_seam } else { &mut self.away };
                [a, b2, s]
            };
            for acc in accs {
                match (rh, fh) {
                    (true, true) => {
                        acc.both += 1;
                        acc.errors.push((raster.range_m[b] as f64 - r.range_m).abs());
                        let ri = geom.mesh_of_triangle(raster.triangle[b]).instance;
                        if ri != r.instance(geom) {
                            acc.mixups += 1;
                        }
                    }
                    (true, false) => acc.raster_only += 1,
                    (false, true) => acc.ref_only += 1,
                    (false, false) => {}
                }
            }
            if rh && fh {
                inter += 1;
            }
        }
        if union > 0 {
            self.iou_sum += inter as f64 / union as f64;
            self.iou_frames += 1;
        }
    }

    fn finish(mut self) -> ModeReport {
        let overall = self.overall.finish();
        let mut by_distance = std::collections::BTreeMap::new();
        for (k, (name, _, _)) in DISTANCE_BINS.iter().enumerate() {
            by_distance.insert(name.to_string(), self.bins[k].finish());
        }
        ModeReport {
            human_beam_agreement: overall.human_beam_agreement,
            mask_iou: if self.iou_frames == 0 { 1.0 } else { self.iou_sum / self.iou_frames as f64 },
            range_error_m: overall.range_error_m.clone(),
            overall,
            by_distance,
            near_seam: self.near_seam.finish(),
            away_from_seam: self.away.finish(),
        }
    }
}

/// The `p`-quantile of ascending `sorted`, interpolated linearly between the two order
/// statistics around position `p (n - 1)` (numpy's default, so the Python tools agree): the
/// median of an even count is the mean of the middle two. NaN when empty.
pub fn quantile_sorted(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let pos = p.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let (lo, frac) = (pos.floor() as usize, pos.fract());
    match sorted.get(lo + 1) {
        Some(hi) if frac > 0.0 => sorted[lo] + frac * (hi - sorted[lo]),
        _ => sorted[lo],
    }
}

/// The median of `v` (the mean of the middle two for an even count), sorting it; 0 when
/// empty (a run with nothing to time or compare).
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    quantile_sorted(v, 0.5)
}

/// Runs the cross-check over `cfg.sequences` x `cfg.frames` frames. What is checked is the
/// backend `render.backend` names, the raster backend for `auto` (the backend the check is
/// for; `auto` generates with the ray caster): three of them, with no refinement, the plane and exact refinement (the
/// generator's); for the ray caster the three are the same.
pub fn crosscheck(mut cfg: Config, opts: &CrosscheckOptions) -> Result<Report> {
    if cfg.render.backend == BackendChoice::Auto {
        cfg.render.backend = BackendChoice::Raster;
    }
    cfg.render.refine = Refine::Exact;
    let mut gpu = Gpu::new(&cfg.device, cfg.debug.validation);
    let mut gen = Generator::with_gpu(cfg.clone(), &mut gpu)?;
    let mut others: Vec<Box<dyn Backend>> = Vec::new();
    for refine in [Refine::None, Refine::Plane] {
        let mut c = cfg.clone();
        c.render.refine = refine;
        others.push(backend::create(&c, gen.sensor(), &[], &mut gpu)?);
    }
    drop(gpu);
    let seam = gen.backend().near_seam(SEAM_TEXELS);
    let dirs = gen.beam_dirs().to_vec();
    let max_range = gen.sensor().max_range_m;
    let mut modes = [ModeAcc::new(), ModeAcc::new(), ModeAcc::new()];
    let mut hits = [BeamHits::default(), BeamHits::default(), BeamHits::default()];
    let mut bg_hits = BeamHits::default();
    let mut bg_errors = Vec::new();
    let (mut bg_both, mut bg_union) = (0usize, 0usize);
    let (mut t_pose, mut t_render, mut t_resample, mut t_build, mut t_cast) = (vec![], vec![], vec![], vec![], vec![]);
    let mut strip: Option<Strip> = None;
    let mut best_strip_beams = 0usize;
    let mut frames = 0usize;
    let mut per_frame = Vec::new();
    for index in cfg.first_sequence..cfg.first_sequence + cfg.sequences {
        let plan = gen.plan(index)?;
        for k in 0..plan.times_s.len() {
            let t0 = Instant::now();
            let state = gen.frame_state(&plan, k);
            gen.pose_frame(&plan, &state)?;
            t_pose.push(t0.elapsed().as_secs_f64() * 1e3);
            // Humans: each mode's backend on the same posed people.
            for (m, other) in others.iter_mut().enumerate() {
                let t1 = Instant::now();
                gen.cast_with(&mut **other, LayerKind::People, &mut hits[m])?;
                if m == 0 {
                    t_render.push(t1.elapsed().as_secs_f64() * 1e3);
                }
            }
            let t2 = Instant::now();
            gen.cast_layer(LayerKind::People, &mut hits[2])?;
            t_resample.push(t2.elapsed().as_secs_f64() * 1e3);
            let humans = gen.posed().people;
            let t3 = Instant::now();
            let bvh = Bvh::build(humans);
            t_build.push(t3.elapsed().as_secs_f64() * 1e3);
            let t4 = Instant::now();
            let reference = raycast::cast(humans, &bvh, &dirs, max_range);
            t_cast.push(t4.elapsed().as_secs_f64() * 1e3);
            for (m, acc) in modes.iter_mut().enumerate() {
                acc.add(&hits[m], &reference, humans, &seam);
            }
            let (_, agreement_none, median_error_none_m) = frame_stats(&hits[0], &reference);
            let (human_beams, agreement_exact, median_error_exact_m) = frame_stats(&hits[2], &reference);
            per_frame.push(FrameRow { sequence: index, frame: k, human_beams, agreement_none, agreement_exact, median_error_none_m, median_error_exact_m });
            let human_beams = reference.iter().filter(|h| h.is_hit()).count();
            if human_beams > best_strip_beams {
                best_strip_beams = human_beams;
                let rr: Vec<f32> = reference.iter().map(|h| h.range_m as f32).collect();
                let ri: Vec<u32> = reference.iter().map(|h| h.instance(humans)).collect();
                let xi: Vec<u32> = hits[2].triangle.iter().map(|&t| if t == NO_TRIANGLE { 0 } else { humans.mesh_of_triangle(t).instance }).collect();
                let xu: Vec<u32> = hits[0].triangle.iter().map(|&t| if t == NO_TRIANGLE { 0 } else { humans.mesh_of_triangle(t).instance }).collect();
                strip = Some(Strip { raster_range: hits[2].range_m.clone(), raster_instance: xi, reference_range: rr, reference_instance: ri, unrefined_instance: xu });
            }
            // Background: the generator's backend (exact refinement) against the reference.
            if !gen.posed().background.meshes.is_empty() {
                gen.cast_layer(LayerKind::Background, &mut bg_hits)?;
                let reference = raycast::cast_frame(gen.posed().background, &dirs, max_range);
                for (b, r) in reference.iter().enumerate() {
                    let rh = bg_hits.triangle[b] != NO_TRIANGLE;
                    if rh || r.is_hit() {
                        bg_union += 1;
                    }
                    if rh && r.is_hit() {
                        bg_both += 1;
                        bg_errors.push((bg_hits.range_m[b] as f64 - r.range_m).abs());
                    }
                }
            }
            if let Some(dir) = &opts.export_geometry {
                let path = dir.join(crate::output::sequence_stem(index)).join(format!("frame_{k:06}.ply"));
                crate::output::ply::write_humans_ply(&path, gen.posed().people)?;
            }
            frames += 1;
        }
    }
    let [none, plane, exact] = modes;
    let report = Report {
        frames,
        sensor: gen.sensor().name.clone(),
        projection: format!("{:?}", cfg.render.projection).to_lowercase(),
        oversample: cfg.render.oversample,
        lod_max_error_mrad: cfg.render.lod_max_error_mrad,
        device: gen.backend().device_name(),
        people_path: if gen.backend().proxies().is_some() { "proxies" } else { "cpu" }.into(),
        unrefined: none.finish(),
        plane: plane.finish(),
        refined: exact.finish(),
        background_range_error_m: ErrorStats::from(&mut bg_errors),
        background_beam_agreement: if bg_union == 0 { 1.0 } else { bg_both as f64 / bg_union as f64 },
        timing_ms: Timing {
            pose: median(&mut t_pose),
            raster_render: median(&mut t_render),
            resample_exact: median(&mut t_resample),
            raycast_build: median(&mut t_build),
            raycast_cast: median(&mut t_cast),
        },
        per_frame,
    };
    if let Some(p) = &opts.json {
        let text = serde_json::to_string_pretty(&report).map_err(|e| Error::Internal(e.to_string()))?;
        write_atomic(p, text.as_bytes())?;
    }
    if let (Some(p), Some(s)) = (&opts.png, &strip) {
        save_png(&strip_png(gen.sensor().rows(), gen.sensor().columns, s), p)?;
    }
    for other in others {
        backend::finish(other)?;
    }
    gen.finish()?;
    Ok(report)
}

fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, bytes).map_err(|e| Error::io(&tmp, e))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}

/// The human layer of the frame with the most human beams, for the PNG strip.
struct Strip {
    raster_range: Vec<f32>,
    raster_instance: Vec<u32>,
    reference_range: Vec<f32>,
    reference_instance: Vec<u32>,
    unrefined_instance: Vec<u32>,
}

/// Four bands, each rows x 4 px high: raster range (exact), reference range, per-beam error of
/// the exact mode (turbo over 0..5 mm; red = raster-only human, blue = reference-only), and
/// the unrefined mask disagreement (red / blue as above, grey = agree).
fn strip_png(rows: usize, cols: usize, s: &Strip) -> RgbImage {
    let (rr, ri, fr, fi, xu) = (&s.raster_range, &s.raster_instance, &s.reference_range, &s.reference_instance, &s.unrefined_instance);
    const S: u32 = 4;
    let band = rows as u32 * S;
    let max = rr.iter().chain(fr).cloned().fold(0.0f32, f32::max).max(1.0);
    let mut img = RgbImage::new(cols as u32, 4 * band + 3 * 2);
    for row in 0..rows {
        for col in 0..cols {
            let b = row * cols + col;
            let rng = |r: f32, hit: bool| if hit { turbo(1.0 - r / max) } else { [0, 0, 0] };
            let err = match (ri[b] > 0, fi[b] > 0) {
                (true, true) => turbo(((rr[b] - fr[b]).abs() / 0.005).min(1.0)),
                (true, false) => [255, 0, 0],
                (false, true) => [0, 80, 255],
                _ => [0, 0, 0],
            };
            let unref = match (xu[b] > 0, fi[b] > 0) {
                (true, true) => [128, 128, 128],
                (true, false) => [255, 0, 0],
                (false, true) => [0, 80, 255],
                _ => [0, 0, 0],
            };
            let px = [rng(rr[b], ri[b] > 0), rng(fr[b], fi[b] > 0), err, unref];
            for (k, c) in px.iter().enumerate() {
                for dy in 0..S {
                    img.put_pixel(col as u32, k as u32 * (band + 2) + row as u32 * S + dy, image::Rgb(*c));
                }
            }
        }
    }
    img
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "crosscheck: {} frames, {} on {}, {} projection, oversample {}, LOD bound {} mrad",
            self.frames, self.sensor, self.device, self.projection, self.oversample, self.lod_max_error_mrad
        )?;
        writeln!(f, "{:<10} {:>10} {:>9} {:>12} {:>12} {:>12} {:>12} {:>9} {:>8}", "mode", "agreement", "mask IoU", "median mm", "p99 mm", "max mm", "rms mm", "> 1 mm", "mixups")?;
        for (name, m) in [("none", &self.unrefined), ("plane", &self.plane), ("exact", &self.refined)] {
            let e = &m.range_error_m;
            writeln!(
                f,
                "{:<10} {:>9.4}% {:>9.4} {:>12.4} {:>12.4} {:>12.4} {:>12.4} {:>8.3}% {:>8}",
                name,
                100.0 * m.human_beam_agreement,
                m.mask_iou,
                e.median * 1e3,
                e.p99 * 1e3,
                e.max * 1e3,
                e.rms * 1e3,
                100.0 * e.over_1mm,
                m.overall.instance_mixups
            )?;
        }
        for (name, _, _) in DISTANCE_BINS {
            let a = &self.unrefined.by_distance[name];
            let r = &self.refined.by_distance[name];
            writeln!(
                f,
                "  {:>4} m: {:>7} beams, agreement none {:.4}% exact {:.4}%, median error none {:.3} mm exact {:.4} mm",
                name,
                r.both_human + r.raster_only + r.reference_only,
                100.0 * a.human_beam_agreement,
                100.0 * r.human_beam_agreement,
                a.range_error_m.median * 1e3,
                r.range_error_m.median * 1e3
            )?;
        }
        writeln!(
            f,
            "  near a face seam (cylinder: the azimuth wrap): agreement exact {:.4}% ({} beams); away: {:.4}%",
            100.0 * self.refined.near_seam.human_beam_agreement,
            self.refined.near_seam.both_human + self.refined.near_seam.raster_only + self.refined.near_seam.reference_only,
            100.0 * self.refined.away_from_seam.human_beam_agreement
        )?;
        writeln!(
            f,
            "background: agreement {:.4}%, median error {:.4} mm, max {:.4} mm",
            100.0 * self.background_beam_agreement,
            self.background_range_error_m.median * 1e3,
            self.background_range_error_m.max * 1e3
        )?;
        let t = &self.timing_ms;
        write!(
            f,
            "median ms/frame: pose {:.2}, people unrefined {:.2}, people exact {:.2}, ray-cast BVH build {:.2}, cast {:.2}",
            t.pose, t.raster_render, t.resample_exact, t.raycast_build, t.raycast_cast
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_stats_are_order_statistics() {
        let mut v: Vec<f64> = (1..=100).map(|k| k as f64).collect();
        let s = ErrorStats::from(&mut v);
        assert_eq!(s.count, 100);
        assert_eq!(s.max, 100.0);
        // numpy.quantile(range(1, 101), [0.5, 0.99]) = 50.5, 99.01.
        assert_eq!(s.median, 50.5);
        assert!((s.p99 - 99.01).abs() < 1e-12, "{}", s.p99);
        assert!((s.rms - (338350.0f64 / 100.0).sqrt()).abs() < 1e-9);
        assert_eq!(s.over_1mm, 1.0);
        assert_eq!(ErrorStats::from(&mut [0.0, 0.002]).over_1mm, 0.5);
        assert_eq!(ErrorStats::from(&mut []), ErrorStats::default());
    }

    #[test]
    fn medians_and_quantiles_match_numpy() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
        assert_eq!(median(&mut [7.0]), 7.0);
        assert_eq!(median(&mut []), 0.0);
        let v = [0.0, 10.0, 20.0, 40.0];
        // numpy.quantile([0, 10, 20, 40], [0, 0.25, 0.9, 1]) = 0, 7.5, 34, 40.
        for (p, want) in [(0.0, 0.0), (0.25, 7.5), (0.9, 34.0), (1.0, 40.0)] {
            assert!((quantile_sorted(&v, p) - want).abs() < 1e-12, "p {p}: {}", quantile_sorted(&v, p));
        }
        assert!(quantile_sorted(&[], 0.5).is_nan());
    }
}
