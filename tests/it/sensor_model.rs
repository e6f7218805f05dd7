//! The sensor model (`pedscan::sensor_model`): its statistics over large samples against the
//! configured values, the footprint's mixed and strongest returns in closed form, and the
//! rolling shutter's default against posing per column.

use glam::DVec3;
use pedscan::config::{BackendChoice, Config, SensorModelConfig};
use pedscan::sensor::Sensor;
use pedscan::sensor_model::{apply, combine, BeamOut, FootprintScene, FrameIn, SequenceDraws, Surface, FOOTPRINT_RAYS};

/// A scene whose people are a vertical half-plane at `near_m` (x > 0 side, azimuth above
/// `edge_az`) in front of a wall at `far_m`: a footprint ray left of the edge meets the person.
struct Edge {
    edge_az: f64,
    near_m: f64,
    far_m: f64,
}

impl Edge {
    fn surface(&self, dir: DVec3) -> Surface {
        let az = dir.y.atan2(dir.x);
        let (range_m, instance, reflectance) = if az > self.edge_az { (self.near_m, 1, 0.4) } else { (self.far_m, 0, 0.6) };
        Surface { range_m, instance, reflectance, cos_incidence: 1.0, rendered: true, normal: glam::Vec3::X }
    }
}

impl FootprintScene for Edge {
    fn cast_footprint(&self, _beam: usize, dirs: &[DVec3; FOOTPRINT_RAYS], out: &mut [Option<Surface>; FOOTPRINT_RAYS]) {
        for (o, d) in out.iter_mut().zip(dirs).skip(1) {
            *o = Some(self.surface(*d));
        }
    }
}

struct Frame {
    sensor: Sensor,
    dirs: Vec<DVec3>,
    el: Vec<f64>,
    az: Vec<f64>,
}

fn frame() -> Frame {
    let sensor = Sensor::hdl32e();
    let dirs = sensor.beam_dirs();
    let el = sensor.elevation_deg.iter().map(|e| e.to_radians()).collect();
    let az = (0..sensor.columns).map(|c| sensor.azimuth_rad(c)).collect();
    Frame { sensor, dirs, el, az }
}

fn run(f: &Frame, cfg: &SensorModelConfig, clean: &[Option<Surface>], draws: &SequenceDraws, scene: &dyn FootprintScene, index: usize) -> Vec<BeamOut> {
    let input = FrameIn {
        cfg,
        dirs: &f.dirs,
        columns: f.sensor.columns,
        elevation_rad: &f.el,
        azimuth_rad: &f.az,
        min_range_m: f.sensor.min_range_m,
        max_range_m: f.sensor.max_range_m,
        clean,
        draws,
        intensity_scale: 1.0,
        recorded_intensity: None,
        seed: 7,
        sequence: 0,
        frame: index,
    };
    let mut out = Vec::new();
    apply(&input, scene, &mut out);
    out
}

/// A wall at 10 m everywhere, head-on: the range noise's standard deviation, the per-laser
/// biases and the dropout rate come out as configured, within the sampling error of ~330k
/// returns.
#[test]
fn noise_bias_and_dropout_match_their_configuration() {
    let f = frame();
    let cfg = SensorModelConfig { range_noise_m: 0.02, laser_bias_m: 0.01, dropout_rate: 0.05, divergence_mrad: [0.0, 0.0], ..SensorModelConfig::on() };
    let rows = f.sensor.rows();
    let draws = SequenceDraws::draw(&cfg, 3, 0, rows, 0);
    let wall = Surface { range_m: 10.0, instance: 0, reflectance: 0.5, cos_incidence: 1.0, rendered: true, normal: glam::Vec3::X };
    let clean = vec![Some(wall); f.dirs.len()];
    let scene = Edge { edge_az: 10.0, near_m: 1.0, far_m: 1.0 };
    let (mut n, mut kept, mut sum, mut sum2) = (0usize, 0usize, 0.0f64, 0.0f64);
    let mut per_row = vec![(0.0f64, 0usize); rows];
    for k in 0..10 {
        let out = run(&f, &cfg, &clean, &draws, &scene, k);
        for (b, o) in out.iter().enumerate() {
            n += 1;
            if o.range_m == 0.0 {
                continue;
            }
            kept += 1;
            let row = b / f.sensor.columns;
            let e = o.range_m as f64 - 10.0 - draws.bias_m[row];
            sum += e;
            sum2 += e * e;
            per_row[row].0 += o.range_m as f64 - 10.0;
            per_row[row].1 += 1;
        }
    }
    let rate = 1.0 - kept as f64 / n as f64;
    assert!((rate - 0.05).abs() < 0.003, "dropout rate {rate}");
    let mean = sum / kept as f64;
    let sd = (sum2 / kept as f64 - mean * mean).sqrt();
    assert!(mean.abs() < 2e-4, "noise mean {mean}");
    assert!((sd - 0.02).abs() < 4e-4, "noise sd {sd}");
    // Each laser's mean error is its bias; the biases spread as configured (32 draws: loose).
    for (row, (s, c)) in per_row.iter().enumerate() {
        assert!((s / *c as f64 - draws.bias_m[row]).abs() < 1e-3, "row {row}");
    }
    let bias_sd = (draws.bias_m.iter().map(|b| b * b).sum::<f64>() / rows as f64).sqrt();
    assert!(bias_sd > 0.005 && bias_sd < 0.016, "bias spread {bias_sd}");
    // Same seed, same frame: the same draws.
    assert_eq!(run(&f, &cfg, &clean, &draws, &scene, 3), run(&f, &cfg, &clean, &draws, &scene, 3));
    // Off: the clean ranges, nothing dropped.
    let off = SensorModelConfig::off();
    assert!(run(&f, &off, &clean, &SequenceDraws::draw(&off, 3, 0, rows, 0), &scene, 0).iter().all(|o| o.range_m == 10.0));
}

/// Detection: half of the returns of reflectance 0.1 head-on at the detection range; none at
/// grazing incidence past the configured angle; every return of a bright near surface.
#[test]
fn detection_follows_power_and_incidence() {
    let f = frame();
    let cfg = SensorModelConfig { range_noise_m: 0.0, laser_bias_m: 0.0, dropout_rate: 0.0, divergence_mrad: [0.0, 0.0], ..SensorModelConfig::on() };
    let draws = SequenceDraws::draw(&cfg, 1, 0, f.sensor.rows(), 0);
    let scene = Edge { edge_az: 10.0, near_m: 1.0, far_m: 1.0 };
    let kept = |s: Surface| {
        let clean = vec![Some(s); f.dirs.len()];
        run(&f, &cfg, &clean, &draws, &scene, 0).iter().filter(|o| o.range_m > 0.0).count() as f64 / f.dirs.len() as f64
    };
    let at = |range_m, reflectance, cos_incidence| Surface { range_m, instance: 0, reflectance, cos_incidence, rendered: true, normal: glam::Vec3::X };
    let half = kept(at(cfg.detection_range_m, 0.1, 1.0));
    assert!((half - 0.5).abs() < 0.02, "{half}");
    assert_eq!(kept(at(10.0, 0.5, 1.0)), 1.0);
    assert_eq!(kept(at(10.0, 0.5, 0.01)), 0.0, "past the grazing angle");
    let mid = kept(at(10.0, 0.5, (0.5 * (cfg.grazing_deg[0].to_radians().cos() + cfg.grazing_deg[1].to_radians().cos())) as f32));
    assert!((mid - 0.5).abs() < 0.02, "halfway through the grazing band: {mid}");
}

/// An edge in front of a wall: within `mixed_return_m` the footprint gives one mixed return at
/// the power-weighted range of its rays; farther, the strongest group wins. The proportion of
/// rays on each side is known from the edge's angle, so every edge beam's range is predicted.
#[test]
fn divergence_gives_mixed_and_strongest_returns_at_an_edge() {
    let f = frame();
    let cfg = SensorModelConfig { range_noise_m: 0.0, laser_bias_m: 0.0, dropout_rate: 0.0, ..SensorModelConfig::on() };
    let draws = SequenceDraws::draw(&cfg, 1, 0, f.sensor.rows(), 1);
    let row = 8; // elevation 0
    let w = f.sensor.columns;
    for (far_m, mixed) in [(5.3, true), (20.0, false)] {
        let mut mixed_beams = 0;
        // The edge at several offsets from column 300's centre, inside its footprint.
        for k in 0..=12 {
            let offset = (k as f64 / 12.0 - 0.5) * 1.6e-3;
            let scene = Edge { edge_az: f.az[300] + offset, near_m: 5.0, far_m };
            let clean: Vec<Option<Surface>> = f.dirs.iter().map(|d| Some(scene.surface(*d))).collect();
            let out = run(&f, &cfg, &clean, &draws, &scene, 0);
            let b = row * w + 300;
            assert!(out[b].from_footprint, "the edge beam is cast over its footprint");
            assert!(!out[row * w + 100].from_footprint && !out[row * w + 302].from_footprint, "beams away from the edge are not");
            // The prediction: the rays of the footprint, each on its side of the edge.
            let dirs = pedscan::sensor_model::footprint_dirs(f.az[300], f.el[row], cfg.divergence_mrad);
            let mut hits: Vec<Surface> = dirs.iter().map(|d| scene.surface(*d)).collect();
            let near = hits.iter().filter(|s| s.instance == 1).count();
            let (want, _) = combine(&mut hits, cfg.mixed_return_m).unwrap();
            assert!((out[b].range_m as f64 - want.range_m).abs() < 1e-5, "offset {offset}: {} vs {}", out[b].range_m, want.range_m);
            if mixed {
                // Power-weighted: near rays weigh 0.4 / 25, far ones 0.6 / 5.3^2.
                let (pn, pf) = (0.4 / 25.0, 0.6 / (far_m * far_m));
                let expect = (near as f64 * pn * 5.0 + (7 - near) as f64 * pf * far_m) / (near as f64 * pn + (7 - near) as f64 * pf);
                assert!((out[b].range_m as f64 - expect).abs() < 1e-4, "{near} near rays: {} vs {expect}", out[b].range_m);
                mixed_beams += (near > 0 && near < 7) as usize;
            } else {
                // Strongest: the person's share of power against the wall's.
                let person = near as f64 * 0.4 / 25.0 > (7 - near) as f64 * 0.6 / 400.0;
                assert_eq!(out[b].instance == 1, person, "{near} near rays");
                assert_eq!(out[b].range_m, if person { 5.0 } else { 20.0 });
            }
        }
        if mixed {
            assert!(mixed_beams >= 8, "the edge must cross the footprint: {mixed_beams}");
        }
    }
}

/// The rolling shutter's default against posing the whole frame at every column's time, on
/// walking people with a moving, turning sensor in the hall: the target (median <= 1
/// mm, p99 <= 5 mm) with room, and the environment refined exactly.
#[test]
fn rolling_shutter_default_matches_posing_per_column() {
    let mut cfg = Config::default();
    cfg.render.backend = BackendChoice::Raycast;
    cfg.humans.count = [16, 16];
    cfg.frames = 2;
    cfg.scene.sensor_speed_mps = [1.0, 1.0];
    cfg.scene.sensor_yaw_rate_rps = [0.15, 0.15];
    let report = pedscan::commands::shutter::shutter_check(cfg, 4).expect("shutter check");
    eprintln!("{report}");
    assert!(report.human_beams > 100, "the people must be seen: {report}");
    assert!(report.agreeing as f64 >= 0.99 * report.human_beams as f64, "{report}");
    assert!(report.human_error_m.median <= 1e-3 && report.human_error_m.p99 <= 5e-3, "{report}");
    assert!(report.background_error_m.p99 <= 1e-4, "{report}");
}
