//! Fitting the sensor model's detection terms to the beams of a recording (`pedscan
//! sensor-fit`), by maximum likelihood over every beam the estimator gives a surface.
//!
//! The model ([`crate::sensor_model`]): a beam returns with probability
//! `(1 - dropout) * g(incidence) * d(power)`, where
//! `g = 1 - loss * clamp((cos a - cos i) / cos a, 0, 1)` falls linearly in `cos i` from 1 at
//! incidence `a` to `1 - loss` at 90 deg, and `d = 1 / (1 + exp(-ln(power / p50) / softness))`
//! with `power = reflectance * cos i / range^2` and `p50 = 0.1 / detection_range^2`.
//! In a recording the model's intensity is `scale * reflectance * cos i`, so a beam's
//! `reflectance * cos i` is the median intensity of the neighbours that define its surface
//! divided by the intensity scale (100 for a Velodyne capture, whose intensity is its
//! calibrated reflectivity in percent): known for holes too, from the surface around them.
//!
//! Beams are grouped in cells of 0.5 deg of incidence and 0.1 of ln(power); the negative
//! log-likelihood of the cells' hole counts is minimised by Nelder-Mead over the five
//! parameters, each mapped onto its allowed range.

use super::{Sample, INCIDENCE_BIN_DEG};
use serde::Serialize;

/// What a fit found.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DetectionFit {
    pub dropout_rate: f64,
    /// Incidence where detection starts to fall, deg.
    pub grazing_start_deg: f64,
    /// Fraction of returns lost at 90 deg of incidence.
    pub grazing_loss: f64,
    pub detection_range_m: f64,
    pub detection_softness: f64,
    /// Beams fitted and the holes among them.
    pub beams: u64,
    pub holes: u64,
    /// Mean negative log-likelihood per beam at the fit.
    pub nll_per_beam: f64,
    /// Per incidence bin: lower edge (deg), beams, observed and predicted hole rate.
    pub by_incidence: Vec<(f64, u64, f64, f64)>,
}

/// The model's parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Detection {
    pub dropout_rate: f64,
    pub grazing_start_deg: f64,
    pub grazing_loss: f64,
    pub detection_range_m: f64,
    pub detection_softness: f64,
}

impl Detection {
    /// Probability that a beam at incidence cosine `cos` with `ln(reflectance * cos / r^2)`
    /// `ln_power` returns.
    pub fn p_return(&self, cos: f64, ln_power: f64) -> f64 {
        let ca = self.grazing_start_deg.to_radians().cos();
        let g = if cos >= ca { 1.0 } else { 1.0 - self.grazing_loss * ((ca - cos) / ca.max(1e-12)).clamp(0.0, 1.0) };
        let ln_p50 = (0.1 / (self.detection_range_m * self.detection_range_m)).ln();
        let d = 1.0 / (1.0 + (-(ln_power - ln_p50) / self.detection_softness).exp());
        (1.0 - self.dropout_rate) * g * d
    }

    fn from_free(x: &[f64; 5]) -> Detection {
        let sig = |v: f64| 1.0 / (1.0 + (-v).exp());
        Detection {
            dropout_rate: 0.5 * sig(x[0]),
            grazing_start_deg: 30.0 + 60.0 * sig(x[1]),
            grazing_loss: sig(x[2]),
            detection_range_m: x[3].clamp(0.0, 7.0).exp(),
            detection_softness: x[4].clamp(-4.0, 1.6).exp(),
        }
    }

    fn to_free(&self) -> [f64; 5] {
        let logit = |p: f64| (p / (1.0 - p)).ln();
        [
            logit((self.dropout_rate / 0.5).clamp(1e-6, 1.0 - 1e-6)),
            logit(((self.grazing_start_deg - 30.0) / 60.0).clamp(1e-6, 1.0 - 1e-6)),
            logit(self.grazing_loss.clamp(1e-6, 1.0 - 1e-6)),
            self.detection_range_m.ln(),
            self.detection_softness.ln(),
        ]
    }
}

/// Beams of one cell: mean incidence cosine and ln(power), beams and holes.
#[derive(Clone, Copy, Debug)]
struct Cell {
    cos: f64,
    ln_power: f64,
    n: f64,
    holes: f64,
}

/// Groups the samples that have an intensity > 0 into cells.
fn cells(samples: &[Sample], scale: f64) -> Vec<Cell> {
    let mut map: std::collections::BTreeMap<(i64, i64), (f64, f64, f64, f64)> = std::collections::BTreeMap::new();
    for s in samples {
        if !(s.intensity > 0.0) || !(s.expected_range_m > 0.0) {
            continue;
        }
        let r = s.expected_range_m as f64;
        let lp = (s.intensity as f64 / scale / (r * r)).ln();
        let cos = (s.incidence_deg as f64).to_radians().cos();
        let key = (((s.incidence_deg as f64) / 0.5) as i64, (lp / 0.1).floor() as i64);
        let e = map.entry(key).or_insert((0.0, 0.0, 0.0, 0.0));
        e.0 += cos;
        e.1 += lp;
        e.2 += 1.0;
        e.3 += s.hole as u8 as f64;
    }
    map.values().map(|&(c, l, n, h)| Cell { cos: c / n, ln_power: l / n, n, holes: h }).collect()
}

fn nll(d: &Detection, cells: &[Cell]) -> f64 {
    cells
        .iter()
        .map(|c| {
            let p = d.p_return(c.cos, c.ln_power).clamp(1e-12, 1.0 - 1e-12);
            -(c.n - c.holes) * p.ln() - c.holes * (1.0 - p).ln()
        })
        .sum()
}

/// Nelder-Mead minimisation of `f` from `x0` with initial steps `step`.
fn nelder_mead<const N: usize>(f: impl Fn(&[f64; N]) -> f64, x0: [f64; N], step: f64, iterations: usize) -> [f64; N] {
    let mut simplex: Vec<([f64; N], f64)> = (0..=N)
        .map(|k| {
            let mut x = x0;
            if k > 0 {
                x[k - 1] += step;
            }
            (x, f(&x))
        })
        .collect();
    let lerp = |a: &[f64; N], b: &[f64; N], t: f64| -> [f64; N] { std::array::from_fn(|i| a[i] + t * (b[i] - a[i])) };
    for _ in 0..iterations {
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        let centroid: [f64; N] = std::array::from_fn(|i| simplex[..N].iter().map(|s| s.0[i]).sum::<f64>() / N as f64);
        let worst = simplex[N];
        let xr = lerp(&centroid, &worst.0, -1.0);
        let fr = f(&xr);
        if fr < simplex[0].1 {
            let xe = lerp(&centroid, &worst.0, -2.0);
            let fe = f(&xe);
            simplex[N] = if fe < fr { (xe, fe) } else { (xr, fr) };
        } else if fr < simplex[N - 1].1 {
            simplex[N] = (xr, fr);
        } else {
            let xc = lerp(&centroid, &worst.0, 0.5);
            let fc = f(&xc);
            if fc < worst.1 {
                simplex[N] = (xc, fc);
            } else {
                let best = simplex[0].0;
                for s in simplex.iter_mut().skip(1) {
                    s.0 = lerp(&best, &s.0, 0.5);
                    s.1 = f(&s.0);
                }
            }
        }
    }
    simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
    simplex[0].0
}

/// Fits the detection terms to `samples` whose intensity is `scale * reflectance * cos`.
/// `None` when fewer than `min_beams` samples have an intensity.
pub fn fit_detection(samples: &[Sample], scale: f64, min_beams: u64) -> Option<DetectionFit> {
    let cells = cells(samples, scale);
    let beams: f64 = cells.iter().map(|c| c.n).sum();
    let holes: f64 = cells.iter().map(|c| c.holes).sum();
    if beams < min_beams as f64 {
        return None;
    }
    let start = Detection { dropout_rate: (holes / beams).clamp(1e-3, 0.4), grazing_start_deg: 70.0, grazing_loss: 0.5, detection_range_m: 70.0, detection_softness: 0.3 };
    let f = |x: &[f64; 5]| nll(&Detection::from_free(x), &cells);
    // Restarts from the best point so far shake the simplex out of a collapsed corner.
    let mut x = start.to_free();
    for _ in 0..4 {
        x = nelder_mead(f, x, 0.5, 400);
    }
    let d = Detection::from_free(&x);
    let nbins = (90.0 / INCIDENCE_BIN_DEG) as usize;
    let mut obs = vec![(0.0, 0.0, 0.0); nbins];
    for c in &cells {
        let deg = c.cos.clamp(-1.0, 1.0).acos().to_degrees();
        let k = ((deg / INCIDENCE_BIN_DEG) as usize).min(nbins - 1);
        obs[k].0 += c.n;
        obs[k].1 += c.holes;
        obs[k].2 += c.n * (1.0 - d.p_return(c.cos, c.ln_power));
    }
    let by_incidence = obs
        .iter()
        .enumerate()
        .filter(|(_, o)| o.0 > 0.0)
        .map(|(k, o)| (k as f64 * INCIDENCE_BIN_DEG, o.0 as u64, o.1 / o.0, o.2 / o.0))
        .collect();
    Some(DetectionFit {
        dropout_rate: d.dropout_rate,
        grazing_start_deg: d.grazing_start_deg,
        grazing_loss: d.grazing_loss,
        detection_range_m: d.detection_range_m,
        detection_softness: d.detection_softness,
        beams: beams as u64,
        holes: holes as u64,
        nll_per_beam: nll(&d, &cells) / beams,
        by_incidence,
    })
}

/// A beam counted in at least this many frames and lost in this share of them is blind.
pub const PLATFORM_MIN_FRAMES: u32 = 4;
pub const PLATFORM_BLIND: f64 = 0.95;
/// Fewest blind beams behind and below the sensor for a platform to be fitted.
pub const PLATFORM_MIN_BEAMS: usize = 20;
/// The fitted box's top face lies this far below the sensor: the beams tell angles only, so
/// the box is placed at this depth and scaled to match them, m.
pub const PLATFORM_TOP_M: f64 = 0.5;

/// A platform fitted to the blind beams of recordings.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PlatformFit {
    pub platform: crate::config::PlatformBox,
    /// Blind beams behind and below the sensor, and the fit's intersection over union with
    /// the beams the box hides.
    pub blind: usize,
    pub iou: f64,
}

/// Fits one box behind and below the sensor (top face [`PLATFORM_TOP_M`] down, 2 m deep,
/// symmetric across; its near edge, length and half-width searched) to the beams that are
/// blind in the recordings (`beam_holes` of `beam_frames`, per beam of `dirs`): the largest
/// intersection over union on a log grid, then a finer grid around the best. `None` when
/// fewer than [`PLATFORM_MIN_BEAMS`] beams behind and below are blind.
pub fn fit_platform(beam_holes: &[u32], beam_frames: &[u32], dirs: &[glam::DVec3]) -> Option<PlatformFit> {
    let rear: Vec<usize> = (0..dirs.len()).filter(|&i| dirs[i].z < 0.0 && dirs[i].x < 0.0).collect();
    let blind = |i: usize| beam_frames.get(i).is_some_and(|&n| n >= PLATFORM_MIN_FRAMES && beam_holes[i] as f64 >= PLATFORM_BLIND * n as f64);
    let observed: Vec<bool> = rear.iter().map(|&i| blind(i)).collect();
    let count = observed.iter().filter(|&&b| b).count();
    if count < PLATFORM_MIN_BEAMS {
        return None;
    }
    let boxed = |[near, length, half]: [f64; 3]| crate::config::PlatformBox {
        min_m: [-near - length, -half, -PLATFORM_TOP_M - 2.0],
        max_m: [-near, half, -PLATFORM_TOP_M],
    };
    let iou = |p: [f64; 3]| {
        let b = boxed(p);
        let (mut inter, mut union) = (0usize, 0usize);
        for (k, &i) in rear.iter().enumerate() {
            let hidden = b.entry(dirs[i]).is_some();
            inter += (hidden && observed[k]) as usize;
            union += (hidden || observed[k]) as usize;
        }
        inter as f64 / union.max(1) as f64
    };
    // A log grid from 5 cm to 10 m (ratio 1.26 a step), then quarter steps around the best.
    let ratio = 200f64.powf(1.0 / 23.0);
    let mut best = ([0.0; 3], -1.0);
    let search = |centre: [f64; 3], steps: i32, r: f64, best: &mut ([f64; 3], f64)| {
        for i in -steps..=steps {
            for j in -steps..=steps {
                for k in -steps..=steps {
                    let p = [centre[0] * r.powi(i), centre[1] * r.powi(j), centre[2] * r.powi(k)];
                    let v = iou(p);
                    if v > best.1 {
                        *best = (p, v);
                    }
                }
            }
        }
    };
    let mid = 0.05 * ratio.powi(12);
    search([mid; 3], 12, ratio, &mut best);
    let coarse = best.0;
    search(coarse, 4, ratio.powf(0.25), &mut best);
    Some(PlatformFit { platform: boxed(best.0), blind: count, iou: best.1 })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    #[test]
    fn known_detection_terms_are_fitted_back_from_their_beams() {
        let truth = Detection { dropout_rate: 0.015, grazing_start_deg: 72.0, grazing_loss: 0.12, detection_range_m: 40.0, detection_softness: 0.4 };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let samples: Vec<Sample> = (0..600_000)
            .map(|_| {
                let inc: f64 = rng.random::<f64>() * 89.5;
                let r: f64 = 1.0 + 59.0 * rng.random::<f64>();
                let refl: f64 = 0.02 + 0.6 * rng.random::<f64>();
                let cos = inc.to_radians().cos();
                let intensity = (100.0 * refl * cos) as f32;
                let lp = (intensity as f64 / 100.0 / (r * r)).ln();
                let hole = rng.random::<f64>() >= truth.p_return(cos, lp);
                Sample { incidence_deg: inc as f32, expected_range_m: r as f32, intensity, hole }
            })
            .collect();
        let fit = fit_detection(&samples, 100.0, 1000).unwrap();
        assert_eq!(fit.beams, 600_000);
        assert!((fit.dropout_rate - truth.dropout_rate).abs() < 0.003, "{fit:?}");
        assert!((fit.grazing_start_deg - truth.grazing_start_deg).abs() < 3.0, "{fit:?}");
        assert!((fit.grazing_loss - truth.grazing_loss).abs() < 0.03, "{fit:?}");
        assert!((fit.detection_range_m / truth.detection_range_m - 1.0).abs() < 0.05, "{fit:?}");
        assert!((fit.detection_softness / truth.detection_softness - 1.0).abs() < 0.1, "{fit:?}");
        for &(lo, n, obs, pred) in &fit.by_incidence {
            let se = (pred * (1.0 - pred) / n as f64).sqrt();
            assert!((obs - pred).abs() < 5.0 * se + 1e-3, "bin {lo}: observed {obs}, predicted {pred}");
        }
        // Too few beams with an intensity: no fit.
        assert!(fit_detection(&samples[..500], 100.0, 1000).is_none());
    }

    #[test]
    fn a_known_platform_is_fitted_back_from_its_blind_beams() {
        // The beams a known box hides, blind in every one of 5 frames (one other beam lost in
        // 4 of 5: not blind): the fit hides the same beams.
        let s = crate::sensor::Sensor::hdl32e();
        let dirs = s.beam_dirs();
        let truth = crate::config::PlatformBox { min_m: [-1.7, -0.3, -2.5], max_m: [-0.6, 0.3, -PLATFORM_TOP_M] };
        let hidden: Vec<bool> = dirs.iter().map(|&d| truth.entry(d).is_some()).collect();
        let frames = vec![5u32; dirs.len()];
        let mut holes: Vec<u32> = hidden.iter().map(|&h| if h { 5 } else { 0 }).collect();
        let lone = dirs.iter().position(|d| d.z < 0.0 && d.x < 0.0 && truth.entry(*d).is_none()).unwrap();
        holes[lone] = 4;
        assert!(hidden.iter().filter(|&&h| h).count() >= PLATFORM_MIN_BEAMS);
        let fit = fit_platform(&holes, &frames, &dirs).unwrap();
        assert_eq!(fit.blind, hidden.iter().filter(|&&h| h).count());
        assert!(fit.iou > 0.97, "{fit:?}");
        // Too few blind beams: no platform.
        let few: Vec<u32> = (0..dirs.len()).map(|i| if i == lone { 5 } else { 0 }).collect();
        assert!(fit_platform(&few, &frames, &dirs).is_none());
    }

    #[test]
    fn a_ray_enters_a_box_where_the_slabs_say() {
        let b = crate::config::PlatformBox { min_m: [1.0, -1.0, -1.0], max_m: [3.0, 1.0, 1.0] };
        assert_eq!(b.entry(glam::DVec3::X), Some(1.0));
        let d = glam::DVec3::new(1.0, 0.5, 0.0).normalize();
        assert!((b.entry(d).unwrap() - 1.0 / d.x).abs() < 1e-12);
        // Along y at x = 0: outside the x slab, parallel to it: a miss.
        assert_eq!(b.entry(glam::DVec3::Y), None);
        assert_eq!(b.entry(-glam::DVec3::X), None);
        // Through the corner region outside the y slab.
        assert_eq!(b.entry(glam::DVec3::new(1.0, 1.2, 0.0).normalize()), None);
    }
}
