//! Closed-form checks of the estimator: planes at known incidence, with known noise and known
//! holes, measured back.

use super::*;
use crate::sensor::Sensor;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A wall `x = WALL_M` in front of an HDL-32E: every beam with `dir.x > 0.05` hits it.
const WALL_M: f64 = 6.0;

fn wall(s: &Sensor) -> (Vec<DVec3>, Vec<f32>) {
    let dirs = s.beam_dirs();
    let range = dirs.iter().map(|d| if d.x > 0.05 { (WALL_M / d.x) as f32 } else { 0.0 }).collect();
    (dirs, range)
}

fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let (u1, u2): (f64, f64) = (rng.random(), rng.random());
    (-2.0 * (1.0 - u1).ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

#[test]
fn eigen_decomposition_of_a_known_matrix() {
    // diag(1, 4, 9) turned by a rotation: eigenvalues 1, 4, 9, eigenvectors the rotated axes.
    let rot = glam::DMat3::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 1.1);
    let m = rot * glam::DMat3::from_diagonal(DVec3::new(4.0, 1.0, 9.0)) * rot.transpose();
    let a = [m.x_axis.to_array(), m.y_axis.to_array(), m.z_axis.to_array()];
    let (vals, vecs) = eigen_sym3(a);
    for (v, want) in vals.iter().zip([1.0, 4.0, 9.0]) {
        assert!((v - want).abs() < 1e-12, "{vals:?}");
    }
    assert!((vecs[0].dot(rot.y_axis).abs() - 1.0).abs() < 1e-12);
    assert!((vecs[1].dot(rot.x_axis).abs() - 1.0).abs() < 1e-12);
    assert!((vecs[2].dot(rot.z_axis).abs() - 1.0).abs() < 1e-12);
}

#[test]
fn a_plane_gives_every_beam_its_incidence_and_range() {
    let s = Sensor::hdl32e();
    let (dirs, range) = wall(&s);
    let mut out = Vec::new();
    estimate_frame(s.rows(), s.columns, &dirs, &range, &mut out);
    let (mut on, mut found) = (0, 0);
    for (i, d) in dirs.iter().enumerate() {
        // Inside the wall's silhouette by more than the window (5 columns of 0.35 deg).
        if d.x < 0.2 {
            continue;
        }
        on += 1;
        let Some(e) = out[i] else { continue };
        found += 1;
        let want = d.x.acos().to_degrees();
        // Ranges are f32 (7 digits, 0.4 um at 6 m) over a window 7 cm wide: ~3e-4 deg.
        assert!((e.incidence_deg - want).abs() < 1e-3, "beam {i}: incidence {} want {want}", e.incidence_deg);
        assert!((e.expected_range_m - WALL_M / d.x).abs() < 1e-5 * e.expected_range_m, "beam {i}");
        assert!(e.residual_m.unwrap().abs() < 1e-5 * e.expected_range_m);
    }
    // Only the top and bottom rows (whose windows still span two rows) and nothing else may
    // lack a surface: every beam inside the silhouette has one.
    assert_eq!(found, on, "{found} of {on} beams found their surface");
    // Beyond the silhouette (no return and no neighbour) nothing is made up.
    for (i, d) in dirs.iter().enumerate() {
        if d.x < 0.0 {
            assert!(out[i].is_none(), "beam {i} behind the sensor has a surface");
        }
    }
}

#[test]
fn known_range_noise_is_measured_back() {
    // sd 2 cm along each beam; the robust sd of n residuals has a standard error of about
    // 1.65 sd / sqrt(2 n) (the MAD's efficiency): with n ~ 300k below 60 deg, 0.2 % of the sd;
    // the bound (1.5 %) is 7 standard errors, and a noise 2 % off fails it.
    let s = Sensor::hdl32e();
    let (dirs, clean) = wall(&s);
    let sd = 0.02;
    let mut m = Measure::new(s.rows());
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for _ in 0..30 {
        let noisy: Vec<f32> = clean.iter().map(|&r| if r > 0.0 { (r as f64 + sd * gaussian(&mut rng)) as f32 } else { 0.0 }).collect();
        m.add_frame(s.columns, &dirs, &noisy, &[]);
    }
    let all: Vec<f32> = m.residuals.concat();
    assert!(all.len() > 200_000, "{} residuals", all.len());
    let got = robust_sd(&all).unwrap();
    assert!((got / sd - 1.0).abs() < 0.015, "measured {got}, true {sd}");
    // Per range bin too, where a bin holds enough residuals.
    for (k, r) in m.residuals.iter().enumerate() {
        if r.len() >= 20_000 {
            let got = robust_sd(r).unwrap();
            assert!((got / sd - 1.0).abs() < 0.03, "bin {k}: {got}");
        }
    }
}

#[test]
fn known_holes_are_counted_in_the_right_bins() {
    let s = Sensor::hdl32e();
    let (dirs, clean) = wall(&s);
    let mut m = Measure::new(s.rows());
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let p = 0.2;
    for _ in 0..10 {
        // Every beam beyond 70 deg of incidence lost; elsewhere 20 % at random.
        let r: Vec<f32> = clean
            .iter()
            .zip(&dirs)
            .map(|(&r, d)| if r > 0.0 && d.x.acos().to_degrees() < 70.0 && rng.random::<f64>() >= p { r } else { 0.0 })
            .collect();
        m.add_frame(s.columns, &dirs, &r, &[]);
    }
    for (k, c) in m.by_incidence.iter().enumerate() {
        let lo = k as f64 * INCIDENCE_BIN_DEG;
        if c.beams < 2000 {
            continue;
        }
        let rate = c.rate().unwrap();
        if lo >= 70.0 {
            assert_eq!(rate, 1.0, "bin {lo} deg");
        } else {
            // Standard error sqrt(p (1 - p) / n) <= 0.9 pp at n >= 2000; bound 4 of them.
            let se = (p * (1.0 - p) / c.beams as f64).sqrt();
            assert!((rate - p).abs() < 4.0 * se, "bin {lo} deg: {rate} of {} beams", c.beams);
        }
    }
    let counted: u64 = m.by_incidence.iter().map(|c| c.beams).sum();
    assert_eq!(counted, m.by_range.iter().map(|c| c.beams).sum::<u64>());
    assert_eq!(counted + m.no_surface.beams, m.beams());
}

#[test]
fn excluded_beams_count_nowhere_and_define_no_surface() {
    let s = Sensor::hdl32e();
    let (dirs, mut range) = wall(&s);
    let mut m = Measure::new(s.rows());
    m.add_frame(s.columns, &dirs, &range, &[]);
    let before = m.beams();
    // Mark every beam of column 512 (straight ahead, on the wall) excluded: 32 beams fewer,
    // no hole more, and its neighbours still find the wall from the other columns.
    for r in 0..s.rows() {
        range[r * s.columns + 512] = EXCLUDED;
    }
    let mut m2 = Measure::new(s.rows());
    m2.add_frame(s.columns, &dirs, &range, &[]);
    assert_eq!(m2.beams(), before - s.rows() as u64);
    assert_eq!(m2.holes(), m.holes());
    let mut out = Vec::new();
    estimate_frame(s.rows(), s.columns, &dirs, &range, &mut out);
    for r in 0..s.rows() {
        assert!(out[r * s.columns + 512].is_none());
        assert!(out[r * s.columns + 511].is_some() && out[r * s.columns + 513].is_some());
    }
}

#[test]
fn the_comparison_finds_the_largest_gap_and_the_intensity_distance() {
    let rows = 2;
    let mut rec = Measure::new(rows);
    let mut sim = Measure::new(rows);
    rec.by_incidence[16] = Count { beams: 5000, holes: 250 };
    sim.by_incidence[16] = Count { beams: 4000, holes: 1200 };
    rec.by_incidence[10] = Count { beams: 5000, holes: 0 };
    sim.by_incidence[10] = Count { beams: 4000, holes: 400 };
    // Too few beams on one side: no gap however large.
    rec.by_incidence[17] = Count { beams: 999, holes: 0 };
    sim.by_incidence[17] = Count { beams: 4000, holes: 4000 };
    rec.has_intensity = true;
    sim.has_intensity = true;
    rec.intensity = (0..1000).map(|k| k as f32).collect();
    sim.intensity = (0..1000).map(|k| k as f32 + 5.0).collect();
    let rep = compare("rec", &rec, "sim", &sim, &[1.0, -1.0]);
    let c = &rep.hole_rate_by_incidence;
    assert_eq!(c.largest_gap, Some(16));
    assert!((c.points[16].gap.unwrap() - 0.25).abs() < 1e-12);
    assert!((c.points[10].gap.unwrap() - 0.10).abs() < 1e-12);
    assert!(c.points[17].gap.is_none());
    let i = rep.intensity.as_ref().unwrap();
    assert!((i.wasserstein.unwrap() - 5.0).abs() < 1e-9);
    assert!((i.rec.iter().sum::<f64>() - 1.0).abs() < 1e-9);
    let text = rep.to_string();
    assert!(text.contains("largest gap: +25.0 pp at 80-85"), "{text}");
    // Without intensity on one side, the rest is compared and a note says why not that.
    sim.has_intensity = false;
    sim.intensity.clear();
    let rep = compare("rec", &rec, "sim", &sim, &[1.0, -1.0]);
    assert!(rep.intensity.is_none() && rep.notes[0].contains("sim: records no intensity"));
}

#[test]
fn robust_sd_and_wasserstein_of_known_samples() {
    // MAD of 1..=9 around 5 is 2: sd 2.9652.
    let v: Vec<f32> = (1..=9).map(|k| k as f32).collect();
    assert!((robust_sd(&v).unwrap() - 1.4826 * 2.0).abs() < 1e-12);
    assert_eq!(robust_sd(&[]), None);
    let a: Vec<f32> = (0..100).map(|k| k as f32).collect();
    let b: Vec<f32> = a.iter().map(|x| 2.0 * x).collect();
    // Quantile functions k and 2k at 1,000 quantiles: mean |k| over u of floor(100 u).
    let want = (0..1000).map(|k| ((k as f64 + 0.5) / 1000.0 * 100.0).floor()).sum::<f64>() / 1000.0;
    assert!((wasserstein1(&a, &b).unwrap() - want).abs() < 1e-9);
}

#[test]
fn a_surface_needs_six_points_from_two_rows_that_span_a_plane() {
    // Straight at a wall 6 m ahead: six neighbours (three above, three below) define it,
    // five do not (the mutation tests' survivors: `<` made `<=`, the row check, the spread).
    let at = |x: f64, y: f64, z: f64, row: usize, col: usize| (DVec3::new(x, y, z), row * 100 + col);
    let wall = |y: f64, z: f64, row: usize, col: usize| at(6.0, y, z, row, col);
    let six = vec![wall(-0.1, 0.2, 0, 1), wall(0.0, 0.2, 0, 2), wall(0.1, 0.2, 0, 3), wall(-0.1, -0.2, 2, 1), wall(0.0, -0.2, 2, 2), wall(0.1, -0.2, 2, 3)];
    let s = surface_at(&mut six.clone(), 100, DVec3::X, 6.0).expect("six points on two rows define the wall");
    assert!(s.incidence_deg.abs() < 1e-9 && (s.expected_range_m - 6.0).abs() < 1e-9);
    assert!(surface_at(&mut six[..5].to_vec(), 100, DVec3::X, 6.0).is_none(), "five points");
    // Six points all tagged as one row, on the wall and spanning it: no surface (a row alone
    // cannot tell a plane's tilt across rows).
    let one_row: Vec<_> = (0..6).map(|k| wall(-0.25 + 0.1 * k as f64, 0.1 * (k % 3) as f64 - 0.1, 1, k)).collect();
    assert!(surface_at(&mut one_row.clone(), 100, DVec3::X, 6.0).is_none(), "one row");
    // Seven points on a line across two rows (a wire): no plane, no surface.
    let line: Vec<_> = (0..7).map(|k| at(6.0, -0.3 + 0.1 * k as f64, -0.3 + 0.1 * k as f64, k / 4, k)).collect();
    assert!(surface_at(&mut line.clone(), 100, DVec3::X, 6.0).is_none(), "a line");
}

#[test]
fn the_plane_tolerance_grows_with_range() {
    // At 20 m the tolerance is 6 cm + 1 % of the range = 26 cm: a point 15 cm off the wall
    // (at the window's centre, so the fit moves little towards it) stays, one 40 cm off goes.
    let p = |x: f64, y: f64, z: f64, i: usize| (DVec3::new(x, y, z), i);
    let base: Vec<_> = [(-0.4, 0.5), (0.0, 0.5), (0.4, 0.5), (-0.4, -0.5), (0.0, -0.5), (0.4, -0.5), (-0.8, 0.0)]
        .iter()
        .enumerate()
        .map(|(k, &(y, z))| p(20.0, y, z, [0, 0, 0, 200, 200, 200, 100][k] + k))
        .collect();
    let mut near = base.clone();
    near.push(p(20.15, 0.0, 0.0, 101));
    surface_at(&mut near, 100, DVec3::X, 20.0).unwrap();
    assert_eq!(near.len(), 8, "15 cm off at 20 m is within the tolerance");
    let mut far = base.clone();
    far.push(p(20.4, 0.0, 0.0, 101));
    surface_at(&mut far, 100, DVec3::X, 20.0).unwrap();
    assert_eq!(far.len(), 7, "40 cm off at 20 m is dropped");
}
