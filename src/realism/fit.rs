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
}
