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
    fn cast_footprint(&self, _beam: usize, _across: &[usize], dirs: &[DVec3; FOOTPRINT_RAYS], out: &mut [Option<Surface>; FOOTPRINT_RAYS]) {
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
/// biases and the dropout rate come out as configured. The sample (300 frames, 9.8 M beams, 9.3 M
/// returns) is sized so a parameter 1 % off fails: each bound is 4 standard errors, and 1 % of
/// the parameter is at least 7 of them.
#[test]
fn noise_bias_and_dropout_match_their_configuration() {
    const FRAMES: usize = 300;
    let f = frame();
    // Detection certain (a bright wall far inside the detection range), so only the dropout
    // loses returns.
    let cfg = SensorModelConfig {
        range_noise_m: 0.02,
        laser_bias_m: 0.01,
        dropout_rate: 0.05,
        divergence_mrad: [0.0, 0.0],
        detection_range_m: 1e4,
        detection_softness: 0.3,
        ..SensorModelConfig::on()
    };
    let rows = f.sensor.rows();
    let draws = SequenceDraws::draw(&cfg, 3, 0, rows, 0);
    let wall = Surface { range_m: 10.0, instance: 0, reflectance: 0.5, cos_incidence: 1.0, rendered: true, normal: glam::Vec3::X };
    let clean = vec![Some(wall); f.dirs.len()];
    let scene = Edge { edge_az: 10.0, near_m: 1.0, far_m: 1.0 };
    let (mut n, mut kept, mut sum, mut sum2) = (0usize, 0usize, 0.0f64, 0.0f64);
    let mut per_row = vec![(0.0f64, 0usize); rows];
    for k in 0..FRAMES {
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
    // Standard errors: a binomial rate sqrt(p (1 - p) / n); a mean sd / sqrt(n); a Gaussian's
    // standard deviation sd / sqrt(2 n). (f32 storage of 10 m adds < 1e-6 m.)
    let rate = 1.0 - kept as f64 / n as f64;
    let se_rate = (0.05f64 * 0.95 / n as f64).sqrt();
    let mean = sum / kept as f64;
    let sd = (sum2 / kept as f64 - mean * mean).sqrt();
    let (se_mean, se_sd) = (0.02 / (kept as f64).sqrt(), 0.02 / (2.0 * kept as f64).sqrt());
    eprintln!("dropout {rate} (se {se_rate:.2e}), noise mean {mean:.2e} (se {se_mean:.2e}), sd {sd} (se {se_sd:.2e})");
    assert!(0.01 * 0.05 >= 7.0 * se_rate && 0.01 * 0.02 >= 7.0 * se_sd, "the sample is too small to catch a 1 % error");
    assert!((rate - 0.05).abs() < 4.0 * se_rate, "dropout rate {rate}");
    assert!(mean.abs() < 4.0 * se_mean, "noise mean {mean}");
    assert!((sd - 0.02).abs() < 4.0 * se_sd, "noise sd {sd}");
    // Each laser's mean error is its bias.
    for (row, (s, c)) in per_row.iter().enumerate() {
        let se = 0.02 / (*c as f64).sqrt();
        assert!((s / *c as f64 - draws.bias_m[row]).abs() < 4.0 * se, "row {row}");
    }
    // The biases spread as configured: over 10,000 sequences' 32 lasers (mean 0, so the sd
    // is the root mean square; se 0.01 / sqrt(2 x 320,000) = 1.25e-5, 1 % = 8 se).
    let biases: Vec<f64> = (0..10_000).flat_map(|i| SequenceDraws::draw(&cfg, 3, i, rows, 0).bias_m).collect();
    let bias_sd = (biases.iter().map(|b| b * b).sum::<f64>() / biases.len() as f64).sqrt();
    let se_bias = 0.01 / (2.0 * biases.len() as f64).sqrt();
    assert!((bias_sd - 0.01).abs() < 4.0 * se_bias, "bias spread {bias_sd} (se {se_bias:.2e})");
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
    let cfg = SensorModelConfig {
        range_noise_m: 0.0,
        laser_bias_m: 0.0,
        dropout_rate: 0.0,
        divergence_mrad: [0.0, 0.0],
        detection_range_m: 70.0,
        detection_softness: 0.3,
        grazing_deg: [75.0, 89.0],
        grazing_loss: 1.0,
        ..SensorModelConfig::on()
    };
    let draws = SequenceDraws::draw(&cfg, 1, 0, f.sensor.rows(), 0);
    let scene = Edge { edge_az: 10.0, near_m: 1.0, far_m: 1.0 };
    let kept_with = |cfg: &SensorModelConfig, s: Surface| {
        let clean = vec![Some(s); f.dirs.len()];
        run(&f, cfg, &clean, &draws, &scene, 0).iter().filter(|o| o.range_m > 0.0).count() as f64 / f.dirs.len() as f64
    };
    let kept = |s: Surface| kept_with(&cfg, s);
    let at = |range_m, reflectance, cos_incidence| Surface { range_m, instance: 0, reflectance, cos_incidence, rendered: true, normal: glam::Vec3::X };
    let half = kept(at(cfg.detection_range_m, 0.1, 1.0));
    assert!((half - 0.5).abs() < 0.02, "{half}");
    assert_eq!(kept(at(10.0, 0.5, 1.0)), 1.0);
    assert_eq!(kept(at(10.0, 0.5, 0.01)), 0.0, "past the grazing angle");
    let mid_cos = (0.5 * (cfg.grazing_deg[0].to_radians().cos() + cfg.grazing_deg[1].to_radians().cos())) as f32;
    let mid = kept(at(10.0, 0.5, mid_cos));
    assert!((mid - 0.5).abs() < 0.02, "halfway through the grazing band: {mid}");
    // With a partial loss: 1 - loss past the band, 1 - loss / 2 halfway, at 2 m where the
    // received power leaves detection at 1 - 1e-6. 32,768 beams: a standard error of 0.27 %
    // (past) and 0.22 % (halfway); the bounds are 4 of them, under a 2 % error in the loss.
    let partial = SensorModelConfig { grazing_loss: 0.4, ..cfg.clone() };
    let past = kept_with(&partial, at(2.0, 0.5, 0.01));
    assert!((past - 0.6).abs() < 0.011, "past the band with loss 0.4: {past}");
    let mid = kept_with(&partial, at(2.0, 0.5, mid_cos));
    assert!((mid - 0.8).abs() < 0.009, "halfway with loss 0.4: {mid}");
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

/// Silhouettes between rows and depth steps inside a rendered environment are footprint
/// edges too; a fold (a floor meeting a wall, continuous) and one plane seen at a grazing angle
/// (neighbouring rows metres apart in range) are not. Closed form: the mock scenes below, each
/// with the beam of interest at row 8, column 300.
#[test]
fn footprint_edges_between_rows_and_inside_the_environment() {
    let f = frame();
    let cfg = SensorModelConfig { range_noise_m: 0.0, laser_bias_m: 0.0, dropout_rate: 0.0, ..SensorModelConfig::on() };
    let draws = SequenceDraws::draw(&cfg, 1, 0, f.sensor.rows(), 1);
    let w = f.sensor.columns;
    // The column straight ahead (+x), at elevation 0.
    let col = (0..w).min_by(|&a, &c| f.az[a].abs().total_cmp(&f.az[c].abs())).unwrap();
    let b = 8 * w + col;
    let plane = |range_m: f64, instance: u16, normal: glam::Vec3| Surface { range_m, instance, reflectance: 0.5, cos_incidence: 1.0, rendered: true, normal };
    let flagged = |clean: &[Option<Surface>]| run(&f, &cfg, clean, &draws, &Edge { edge_az: 10.0, near_m: 1.0, far_m: 1.0 }, 0)[b].from_footprint;
    // A wall at 10 m facing the sensor everywhere (normal along x, on the plane x = 10).
    let wall = |d: &DVec3| plane(10.0 / d.x.abs().max(1e-3), 0, glam::Vec3::X);
    let base: Vec<Option<Surface>> = f.dirs.iter().map(|d| Some(wall(d))).collect();
    assert!(!flagged(&base), "one plane is no edge");
    // The row below sees a person: a silhouette between rows.
    let mut between = base.clone();
    between[b + w] = Some(plane(5.0, 1, glam::Vec3::X));
    assert!(flagged(&between), "a person in the next row");
    // The row below sees a pillar 2 m before the wall (parallel faces): a depth step.
    let mut step = base.clone();
    step[b + w] = Some(plane(8.0 / f.dirs[b + w].x, 0, glam::Vec3::X));
    assert!(flagged(&step), "a pillar in the next row");
    // Only 0.3 m before the wall: within one mixed return, no step.
    let mut shallow = base.clone();
    shallow[b + w] = Some(plane(9.7 / f.dirs[b + w].x, 0, glam::Vec3::X));
    assert!(!flagged(&shallow), "a step shallower than mixed_return_m");
    // The row below sees a floor 0.2 m below the beam meeting the wall (a concave corner): a
    // fold, though that beam's point is 1.4 m before the wall's plane.
    let mut fold = base.clone();
    let d = f.dirs[b + w];
    fold[b + w] = Some(plane(0.2 / -d.z, 0, glam::Vec3::Z));
    assert!(fold[b + w].unwrap().range_m < 9.0 && f.dirs[b].z.abs() < 1e-9, "the floor is met before the wall");
    assert!(!flagged(&fold), "a fold");
    // A floor seen at a grazing angle, whole: rows far apart in range, one plane.
    let floor: Vec<Option<Surface>> = f.dirs.iter().map(|d| (d.z < -1e-3).then(|| plane(-1.7 / d.z, 0, glam::Vec3::Z))).collect();
    // A beam whose neighbours above and below also meet the floor, the one below metres nearer.
    let low = (1..f.sensor.rows() - 1).find(|&r| {
        let (up, a, o) = (floor[(r - 1) * w + col], floor[r * w + col], floor[(r + 1) * w + col]);
        up.is_some() && a.zip(o).is_some_and(|(a, o)| (a.range_m - o.range_m).abs() > 1.0)
    });
    let r = low.expect("a grazing row pair");
    let grazing = run(&f, &cfg, &floor, &draws, &Edge { edge_az: 10.0, near_m: 1.0, far_m: 1.0 }, 0);
    assert!(!grazing[r * w + col].from_footprint, "a grazing floor, row {r}");
    // Nothing beside an environment's surface (the top of a wall against the sky).
    let mut open = base.clone();
    open[b - w] = None;
    assert!(flagged(&open), "nothing in the next row");
    // A recorded background carries its own edges.
    let recorded: Vec<Option<Surface>> = step.iter().map(|s| s.map(|s| Surface { rendered: false, ..s })).collect();
    assert!(!flagged(&recorded), "recorded beams are never re-modelled");
    // Nor is a recorded beam beside one with no return (the recording's own dropout).
    let mut recorded_open = recorded.clone();
    recorded_open[b - w] = None;
    assert!(!flagged(&recorded_open), "a recorded beam beside no return");
}

/// Depth steps in the hall (tables, a pillar before a wall): every beam whose footprint holds
/// surfaces farther apart than `mixed_return_m` returns what the whole footprint returns
/// (range and intensity, the footprint's share) against every triangle of the environment, with the sensor moving and turning over a
/// rolling sweep (each column's rays from its own pose). The reference casts each column's
/// 7 x 32 footprint rays through a BVH of the environment placed at that column's pose.
#[test]
fn environment_steps_return_their_whole_footprint() {
    use pedscan::backend::raycast::cast_frame;
    use pedscan::geometry::FrameGeometry;
    use pedscan::sensor_model::footprint_dirs;
    let mut cfg = Config::default();
    cfg.render.backend = BackendChoice::Raycast;
    cfg.humans.count = [0, 0];
    cfg.frames = 1;
    cfg.scene.sensor_speed_mps = [1.0, 1.0];
    cfg.scene.sensor_yaw_rate_rps = [0.2, 0.2];
    cfg.sensor_model = SensorModelConfig {
        range_noise_m: 0.0,
        laser_bias_m: 0.0,
        dropout_rate: 0.0,
        detection_softness: 0.0,
        detection_range_m: 1e4,
        grazing_deg: [90.0, 90.0],
        ..SensorModelConfig::on()
    };
    let env = pedscan::scene::Environment::load(&cfg.scene.background).expect("the bundled hall");
    let mut gen = pedscan::generator::Generator::new(cfg.clone()).expect("generator");
    let plan = gen.plan(0).expect("plan");
    let mut out = pedscan::output::FrameOutput::default();
    gen.frame(&plan, 0, &mut out).expect("frame");
    let sensor = gen.sensor().clone();
    let (rows, w) = (sensor.rows(), sensor.columns);
    let el: Vec<f64> = sensor.elevation_deg.iter().map(|e| e.to_radians()).collect();
    let mut steps = 0;
    let mut agree = 0;
    let mut worst = (0.0f64, 0usize);
    for c in 0..w {
        // The environment in this column's sensor frame.
        let pose = plan.sensor.pose(out.column_time_s[c]).inverse();
        let verts: Vec<[f32; 3]> = env.positions.iter().map(|p| pose.transform_point3(*p).as_vec3().to_array()).collect();
        let mut geom = FrameGeometry::default();
        for m in &env.meshes {
            geom.push_mesh(&verts, &m.indices, 0, m.double_sided);
        }
        let dirs: Vec<DVec3> = (0..rows).flat_map(|r| footprint_dirs(sensor.azimuth_rad(c), el[r], cfg.sensor_model.divergence_mrad)).collect();
        let hits = cast_frame(&geom, &dirs, sensor.max_range_m);
        for r in 0..rows {
            let mut surfaces: Vec<Surface> = (0..FOOTPRINT_RAYS)
                .filter_map(|k| {
                    let (h, dir) = (hits[r * FOOTPRINT_RAYS + k], dirs[r * FOOTPRINT_RAYS + k]);
                    h.is_hit().then(|| {
                        let tri = geom.triangle_f64(h.triangle);
                        let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]).normalize();
                        let reflectance = env.meshes[geom.mesh_index_of_triangle(h.triangle)].reflectance;
                        Surface { range_m: h.range_m, instance: 0, reflectance, cos_incidence: n.dot(dir).abs() as f32, rendered: true, normal: n.as_vec3() }
                    })
                })
                .collect();
            let mut sorted: Vec<f64> = surfaces.iter().map(|s| s.range_m).collect();
            sorted.sort_by(f64::total_cmp);
            let step = sorted.len() < FOOTPRINT_RAYS && !sorted.is_empty() || sorted.windows(2).any(|p| p[1] - p[0] > cfg.sensor_model.mixed_return_m);
            if !step || !hits[r * FOOTPRINT_RAYS].is_hit() {
                continue;
            }
            steps += 1;
            let (want, share) = combine(&mut surfaces, cfg.sensor_model.mixed_return_m).expect("a return");
            let got = out.range[r * w + c] as f64;
            let err = (got - want.range_m).abs();
            // The intensity is the footprint's share (scale 1 without a capture): rays that meet
            // nothing or another surface lower it.
            let intensity_err = (out.intensity[r * w + c] - share).abs();
            if err < 2e-3 && intensity_err < 1e-3 {
                agree += 1;
            } else {
                eprintln!(
                    "beam {} (row {r}, column {c}): got {got:.3}, clean {:.3}, want {:.3}, intensity {} want {share}, rays {:?}",
                    r * w + c,
                    out.clean_range[r * w + c],
                    want.range_m,
                    out.intensity[r * w + c],
                    sorted
                );
                if err > worst.0 {
                    worst = (err, r * w + c);
                }
            }
        }
    }
    eprintln!("{steps} footprints over a depth step, {agree} agree; worst {:.3} m at beam {}", worst.0, worst.1);
    assert!(steps >= 50, "the hall must have depth steps in view: {steps}");
    // The misses are features thinner than the beam spacing that no neighbouring beam meets
    // (a post a few centimetres wide at 11 m, a table top edge-on): 80 of 90 agree in range and
    // intensity (88 in range alone); without the environment's edges 29 did in range.
    assert!(agree as f64 >= 0.85 * steps as f64, "{agree} of {steps} agree; worst {:.3} m at beam {}", worst.0, worst.1);
}

/// The platform hides exactly the rendered beams whose surface lies behind one of its boxes,
/// never a recorded beam; a box that holds the sensor is refused.
#[test]
fn the_platform_hides_what_lies_behind_it() {
    use pedscan::config::PlatformBox;
    let f = frame();
    let boxes = vec![PlatformBox { min_m: [-3.0, -0.5, -2.0], max_m: [-0.5, 0.5, -0.3] }, PlatformBox { min_m: [0.2, 2.0, -1.0], max_m: [0.4, 2.2, 1.0] }];
    let cfg = SensorModelConfig {
        range_noise_m: 0.0,
        laser_bias_m: 0.0,
        dropout_rate: 0.0,
        divergence_mrad: [0.0, 0.0],
        detection_range_m: 1e4,
        grazing_loss: 0.0,
        platform: boxes.clone(),
        ..SensorModelConfig::on()
    };
    let draws = SequenceDraws::draw(&cfg, 1, 0, f.sensor.rows(), 0);
    let scene = Edge { edge_az: 10.0, near_m: 1.0, far_m: 1.0 };
    let at = |rendered| Surface { range_m: 10.0, instance: 0, reflectance: 0.5, cos_incidence: 1.0, rendered, normal: glam::Vec3::X };
    let out = run(&f, &cfg, &vec![Some(at(true)); f.dirs.len()], &draws, &scene, 0);
    let mut hidden = 0;
    for (b, o) in out.iter().enumerate() {
        let behind = boxes.iter().any(|x| x.entry(f.dirs[b]).is_some_and(|t| t < 10.0));
        assert_eq!(o.range_m == 0.0, behind, "beam {b}");
        hidden += behind as usize;
    }
    assert!(hidden > 500, "{hidden} beams hidden");
    // A recorded background carries its own platform: untouched.
    let rec = run(&f, &cfg, &vec![Some(at(false)); f.dirs.len()], &draws, &scene, 0);
    assert!(rec.iter().all(|o| o.range_m == 10.0));
    // A surface on a box's face (the mount itself) is not behind it: kept, at its range.
    let entry = |d: glam::DVec3| boxes.iter().filter_map(|x| x.entry(d)).fold(f64::INFINITY, f64::min);
    let on_face: Vec<_> = f.dirs.iter().map(|&d| Some(Surface { range_m: entry(d).min(10.0), ..at(true) })).collect();
    let kept = run(&f, &cfg, &on_face, &draws, &scene, 0);
    let mut on_a_face = 0;
    for (b, (o, s)) in kept.iter().zip(&on_face).enumerate() {
        let r = s.unwrap().range_m;
        if r >= f.sensor.min_range_m && r < 10.0 {
            assert_eq!(o.range_m, r as f32, "beam {b}: a surface on the platform's face");
            on_a_face += 1;
        }
    }
    assert!(on_a_face > 500, "{on_a_face} beams end on a face");
    // A box around the sensor, or an empty one, is refused by name.
    for (b, needle) in [
        (PlatformBox { min_m: [-1.0, -1.0, -1.0], max_m: [1.0, 1.0, 1.0] }, "holds the sensor"),
        (PlatformBox { min_m: [1.0, -1.0, -1.0], max_m: [1.0, 1.0, 1.0] }, "min < max"),
    ] {
        let text = format!("[sensor_model]\n[[sensor_model.platform]]\nmin_m = {:?}\nmax_m = {:?}\n", b.min_m, b.max_m);
        let file = tempfile::Builder::new().suffix(".toml").tempfile().unwrap();
        std::fs::write(file.path(), text).unwrap();
        let err = pedscan::config::Config::from_file(file.path()).and_then(|c| c.validate()).unwrap_err().to_string();
        assert!(err.contains("sensor_model.platform[0]") && err.contains(needle), "{err}");
    }
}

/// Each triangle's body region, checked against where it lies on the rest mesh: the soles are
/// shoes, the crown is skin, the middle of the chest upper clothing, the thighs below the crotch
/// lower clothing (MakeHuman's rest pose is an A pose: the hands hang wider than the band the
/// thighs are taken from). Every level of detail has a region per triangle.
#[test]
fn body_regions_follow_the_rest_mesh() {
    use pedscan::sensor_model::{surfaces::body_regions, LOWER, SHOES, SKIN, UPPER};
    for name in ["h1700_w50", "h1200_w20"] {
        let path = pedscan::config::data_dir().join("humans").join(format!("{name}.glb"));
        let m = pedscan::human::HumanModel::load(&path, true).unwrap();
        let regions = body_regions(&m).unwrap();
        assert_eq!(regions.len(), m.lods.len());
        for (l, r) in m.lods.iter().zip(&regions) {
            assert_eq!(r.len(), l.triangle_count(), "{name}");
        }
        let l = &m.lods[0];
        let (lo, hi) = l.positions.iter().fold((f32::MAX, f32::MIN), |(a, b), p| (a.min(p.y), b.max(p.y)));
        let h = hi - lo;
        // Share of the triangles wholly inside a box (heights as fractions of the body's) that
        // have region `want`, and how many there are.
        let share = |y0: f32, y1: f32, half_width_m: f32, want: u8| {
            let (mut n, mut hit) = (0usize, 0usize);
            for (t, tri) in l.indices.chunks_exact(3).enumerate() {
                let inside = tri.iter().all(|&i| {
                    let p = l.positions[i as usize];
                    let f = (p.y - lo) / h;
                    f >= y0 && f <= y1 && p.x.abs() <= half_width_m
                });
                if inside {
                    n += 1;
                    hit += (regions[0][t] == want) as usize;
                }
            }
            assert!(n >= 20, "{name}: {n} triangles in the box");
            hit as f64 / n as f64
        };
        let soles = share(0.0, 0.03, 1.0, SHOES);
        let crown = share(0.94, 1.0, 1.0, SKIN);
        let chest = share(0.68, 0.74, 0.06 * h, UPPER);
        let thighs = share(0.30, 0.38, 0.10 * h, LOWER);
        for (what, s) in [("soles", soles), ("crown", crown), ("chest", chest), ("thighs", thighs)] {
            assert!(s >= 0.95, "{name}: {:.1} % of the {what} in their region", 100.0 * s);
        }
    }
}
