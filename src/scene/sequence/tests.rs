//! Unit tests of sampling a sequence and of each person's state at an instant.

use super::*;
use rand::SeedableRng;

mod long;
mod push;

fn plan(motion: MotionMode) -> HumanPlan {
    HumanPlan {
        model: 0,
        trajectory: Trajectory { start_m: DVec2::new(1.0, 2.0), z_m: 0.0, heading0_rad: 0.3, speed_mps: 1.2, yaw_rate_rps: 0.1 }.into(),
        phase0: 0.25,
        stride_m: 1.2,
        motion,
        arm_swing: 1.0,
        stride_scale: 1.0,
        seat_m: 0.0,
        feet_room_m: f64::INFINITY,
        pushed: None,
    }
}

/// On a curve the shifts keep a stance foot's place and heading on the ground: a point of
/// the foot, moved straight back by the distance walked as the walk moves it in the body
/// frame, then by the foot's shift, then into the world by the body's pose, stays where it
/// is from heel strike to toe-off. On a straight path the shifts are zero; over the swing
/// they change continuously.
#[test]
fn foot_shifts_pin_a_stance_foot_on_a_curve() {
    let mut p = plan(MotionMode::Full);
    let world = |p: &HumanPlan, t: f64, foot: usize, q: DVec2| {
        let at = p.at(t);
        let f = at.feet[foot];
        let walked = q - DVec2::X * p.trajectory.distance(t);
        let body = DVec2::from_angle(f.yaw_rad as f64).rotate(walked) + DVec2::new(f.forward_m as f64, f.left_m as f64);
        let w = at.position_m.truncate() + DVec2::from_angle(at.heading_rad).rotate(body);
        (w, at.heading_rad + f.yaw_rad as f64)
    };
    for yaw_rate in [0.0, 0.8, -1.5] {
        if let HumanPath::Arc(a) = &mut p.trajectory {
            a.yaw_rate_rps = yaw_rate;
        }
        // The left foot's stance: phase 0 (heel strike) to 0.62, from t = 0.75 * 1.2 / 1.2.
        let (t0, t1) = (0.75, 0.75 + 0.62 - 1e-3);
        let q = DVec2::new(0.1, 0.09);
        let (w0, h0) = world(&p, t0, 0, q);
        let mut worst: f64 = 0.0;
        for k in 0..=40 {
            let t = t0 + (t1 - t0) * k as f64 / 40.0;
            let (w, h) = world(&p, t, 0, q);
            worst = worst.max((w - w0).length()).max((h - h0).abs());
        }
        assert!(worst < 1e-5, "yaw rate {yaw_rate}: the planted foot moved {worst} m / rad");
        let size = |t: f64| p.at(t).feet.iter().map(|f| f.forward_m.abs() + f.left_m.abs() + f.yaw_rad.abs()).sum::<f32>();
        if yaw_rate == 0.0 {
            assert!((0..50).all(|k| size(0.05 * k as f64) < 1e-6), "a straight path shifts no foot");
        } else {
            assert!(size(0.1) > 1e-3, "a curve shifts the feet");
            // Continuous over the whole cycle, the swing included.
            for k in 0..2000 {
                let (a, b) = (p.at(k as f64 * 1e-3).feet, p.at((k + 1) as f64 * 1e-3).feet);
                for (x, y) in a.iter().zip(&b) {
                    let jump = (x.forward_m - y.forward_m).abs() + (x.left_m - y.left_m).abs() + (x.yaw_rad - y.yaw_rad).abs();
                    assert!(jump < 5e-3, "t = {} ms: the shift jumps by {jump}", k);
                }
            }
        }
    }
    // A turn no walk makes (6 rad/s at 1.2 m/s: a 0.2 m radius) moves a foot 0.3 m and
    // turns it 1.2 rad at most.
    if let HumanPath::Arc(a) = &mut p.trajectory {
        a.yaw_rate_rps = 6.0;
    }
    for k in 0..200 {
        for f in p.at(k as f64 * 0.01).feet {
            assert!(f.forward_m.hypot(f.left_m) <= 0.3 + 1e-6 && f.yaw_rad.abs() <= 1.2 + 1e-6, "{f:?}");
        }
    }
    // A person who does not walk on (in place, standing) has no shifts.
    for motion in [MotionMode::InPlace, MotionMode::Static, MotionMode::Sliding] {
        assert_eq!(plan(motion).at(0.4).feet, [FootShift::ZERO; 2]);
    }
}

/// Over the swing the shift blends by smoothstep from the one the foot left the ground
/// with to the one its next stance lands it with: halfway (smoothstep 1/2) it is their mean.
/// On a track whose curvature changes (on a steady arc every stance's shift is the same,
/// wherever it lands); the left foot (strike at phase 0) leaves the ground at phase 0.62
/// and lands at phase 1, so halfway through its swing the phase is 0.81.
#[test]
fn a_swinging_foot_goes_halfway_between_toe_off_and_the_next_strike() {
    let times: Vec<f64> = (0..30).map(|k| k as f64 * 0.4).collect();
    let xy: Vec<DVec2> = times.iter().map(|t| DVec2::new(1.3 * t, (0.5 * t).sin() * 2.0)).collect();
    let track = Arc::new(Track { id: 1, times_s: times, xy_m: xy, heading_rad: None });
    let mut p = plan(MotionMode::Full);
    (p.trajectory, p.phase0) = (HumanPath::Track(TrackPath::new(track, 1.7, 0.0, 6.0)), 0.0);
    let at_phase = |phase: f64| p.trajectory.time_at_distance(phase * p.stride_m).unwrap();
    let (off, mid, on) = (at_phase(0.62) - 1e-9, at_phase(0.81), at_phase(1.0) + 1e-9);
    assert!((p.at(mid).gait_phase - 0.81).abs() < 1e-5, "{}", p.at(mid).gait_phase);
    let (a, m, b) = (p.at(off).feet[0], p.at(mid).feet[0], p.at(on).feet[0]);
    assert!((a.forward_m - b.forward_m).abs() + (a.left_m - b.left_m).abs() + (a.yaw_rad - b.yaw_rad).abs() > 0.05, "{a:?} {b:?}");
    for (x, y, z) in [(a.forward_m, m.forward_m, b.forward_m), (a.left_m, m.left_m, b.left_m), (a.yaw_rad, m.yaw_rad, b.yaw_rad)] {
        assert!((y - 0.5 * (x + z)).abs() < 1e-4, "mid-swing {m:?} is not the mean of {a:?} and {b:?}");
    }
}

#[test]
fn track_distance_is_the_arc_length_inside_and_past_its_table() {
    // A curved walk sampled at 0.4 s; the interpolant's arc length by a fine chord sum.
    let times: Vec<f64> = (0..30).map(|k| k as f64 * 0.4).collect();
    let xy: Vec<DVec2> = times.iter().map(|t| DVec2::new(1.3 * t, (0.5 * t).sin() * 2.0)).collect();
    let track = Arc::new(Track { id: 1, times_s: times, xy_m: xy, heading_rad: None });
    let path = TrackPath::new(track, 1.7, 0.0, 3.0);
    let chord = |t: f64| {
        let n = 200_000;
        (0..n)
            .map(|i| {
                let (a, b) = (t * i as f64 / n as f64, t * (i + 1) as f64 / n as f64);
                path.state(b).0.distance(path.state(a).0)
            })
            .sum::<f64>()
    };
    for t in [0.0, 0.005, 0.3, 1.234, 3.0, 4.56] {
        let (d, want) = (path.distance(t), chord(t));
        assert!((d - want).abs() < 1e-6 * (1.0 + want), "t {t}: {d} vs {want}");
    }
    assert_eq!(path.distance(0.0), 0.0);
}

/// The path passes through the track's samples (sequence time t is track time t0 + t),
/// and `time_at_distance` inverts `distance`: inside the 10 ms table to well under a
/// millisecond, before 0 and past the table at the speed there.
#[test]
fn track_time_at_distance_inverts_the_distance() {
    let times: Vec<f64> = (0..30).map(|k| k as f64 * 0.4).collect();
    let xy: Vec<DVec2> = times.iter().map(|t| DVec2::new(1.3 * t, (0.5 * t).sin() * 2.0)).collect();
    let track = Arc::new(Track { id: 1, times_s: times, xy_m: xy, heading_rad: None });
    let path = HumanPath::Track(TrackPath::new(track, 1.7, 0.0, 3.0));
    let HumanPath::Track(tp) = &path else { unreachable!() };
    for (t, k) in [(0.3, 5), (2.3, 10)] {
        let (p, v, _) = tp.state(t);
        assert!(p.distance(DVec2::new(1.3 * 0.4 * k as f64, (0.2 * k as f64).sin() * 2.0)) < 1e-9, "t {t}: {p}");
        assert!(v.length() > 1.0, "walking at t {t}: {v}");
    }
    for t in [0.004, 0.25, 1.0, 2.345, 2.99] {
        let d = path.distance(t);
        let back = path.time_at_distance(d).unwrap();
        assert!((back - t).abs() < 1e-4, "t {t}: distance {d} gives back {back}");
    }
    // Before 0 and past the table (3 s): at the speed at 0 and at the table's end.
    let v0 = tp.state(0.0).1.length();
    assert!((path.time_at_distance(-0.5).unwrap() - (-0.5 / v0)).abs() < 1e-12);
    let (end, d_end) = (3.0, path.distance(3.0));
    let v_end = tp.state(end).1.length();
    let past = path.time_at_distance(d_end + 0.8).unwrap();
    assert!((past - (end + 0.8 / v_end)).abs() < 1e-6, "{past}");
}

/// The heading of [`turning_parabola`]'s poses at time t (crossing +-pi at t = 0.125).
fn turning_angle(t: f64) -> f64 {
    std::f64::consts::PI - 0.1 + 0.8 * t
}

/// Poses at uneven times along x = t^2 (y = 1, z = 0.5), turning steadily at 0.8 rad/s.
fn turning_parabola() -> ([f64; 5], Vec<DMat4>) {
    let times = [0.0, 0.1, 0.25, 0.3, 0.5];
    let poses = times.iter().map(|&t| DMat4::from_rotation_translation(DQuat::from_rotation_z(turning_angle(t)), DVec3::new(t * t, 1.0, 0.5))).collect();
    (times, poses)
}

/// Recorded poses' velocities: the three-point derivative for uneven steps is exact on a
/// parabola (x = t^2: 2t) inside, one-sided at the ends; the yaw rate is exact on a steady
/// turn, across the +-pi wrap too; a window's times start at its first pose.
#[test]
fn pose_velocities_are_exact_on_a_parabola_and_a_steady_turn() {
    let (times, poses) = turning_parabola();
    let all = PoseTrack::from_poses(&times, &poses, 0..5);
    for k in 1..4 {
        assert!((all.velocity_mps[k] - DVec3::new(2.0 * times[k], 0.0, 0.0)).length() < 1e-12, "pose {k}: {}", all.velocity_mps[k]);
    }
    assert!((all.velocity_mps[0].x - 0.1).abs() < 1e-12, "one-sided at the start: {}", all.velocity_mps[0]);
    assert!((all.velocity_mps[4].x - (0.25 - 0.09) / 0.2).abs() < 1e-12, "one-sided at the end: {}", all.velocity_mps[4]);
    for (k, w) in all.yaw_rate_rps.iter().enumerate() {
        assert!((w - 0.8).abs() < 1e-9, "yaw rate at pose {k}: {w}");
    }
    let window = PoseTrack::from_poses(&times, &poses, 1..3);
    assert_eq!(window.times_s, vec![0.0, 0.25 - 0.1]);
    assert!((window.velocity_mps[0] - all.velocity_mps[1]).length() < 1e-15, "a window uses the poses just outside it");
    // A sensor path gives the same velocity as its poses, and an arc's is its position's
    // derivative.
    let path = SensorPath::Poses(all.clone());
    assert!((path.velocity(times[2]) - all.velocity_mps[2]).length() < 1e-12);
    let arc = SensorPath::Arc(Trajectory { start_m: DVec2::new(1.0, 2.0), z_m: 1.7, heading0_rad: 0.3, speed_mps: 1.2, yaw_rate_rps: 0.4 });
    let h = 1e-6;
    let numeric = (arc.position(0.8 + h) - arc.position(0.8 - h)) / (2.0 * h);
    assert!((arc.velocity(0.8) - numeric).length() < 1e-6 && arc.velocity(0.8).length() > 1.0, "{}", arc.velocity(0.8));
}

/// Between recorded poses: the translation linear, the rotation by slerp (about one axis:
/// the angle linear), velocity and yaw rate linear; at a recorded time the recorded pose;
/// before the first and after the last, held.
#[test]
fn poses_between_records_are_interpolated_and_held_outside() {
    let (times, poses) = turning_parabola();
    let track = PoseTrack::from_poses(&times, &poses, 0..5);
    for (t, (i, f)) in [(0.05, (0, 0.5)), (0.175, (1, 0.5)), (0.26, (2, 0.2)), (0.45, (3, 0.75))] {
        let (pose, v, w) = track.sample(t);
        let (_, r, p) = pose.to_scale_rotation_translation();
        let want_p = DVec3::new(times[i] * times[i], 1.0, 0.5).lerp(DVec3::new(times[i + 1] * times[i + 1], 1.0, 0.5), f);
        assert!((p - want_p).length() < 1e-12, "t {t}: {p} against {want_p}");
        assert!(r.dot(DQuat::from_rotation_z(turning_angle(t))).abs() > 1.0 - 1e-12, "t {t}: rotation");
        assert!((v - track.velocity_mps[i].lerp(track.velocity_mps[i + 1], f)).length() < 1e-12, "t {t}: velocity");
        let want_w = track.yaw_rate_rps[i] * (1.0 - f) + track.yaw_rate_rps[i + 1] * f;
        assert!((w - want_w).abs() < 1e-12, "t {t}: yaw rate");
        assert_eq!(track.pose(t), pose);
    }
    assert_eq!(track.pose(0.25), poses[2], "a recorded time gives the recorded pose");
    assert_eq!(track.sample(0.25).1, track.velocity_mps[2]);
    assert_eq!(track.pose(-1.0), poses[0]);
    assert_eq!(track.pose(9.0), poses[4]);
    assert_eq!(track.sample(9.0).1, track.velocity_mps[4]);
}

/// With recorded tracks a sequence takes only tracks that cover its whole window (a track
/// exactly as long as the sequence included, one that ends early never), starts the
/// sensor within the spawn radius of their mean position, and draws each person's arm
/// swing within its range.
#[test]
fn track_windows_take_only_tracks_that_cover_them() {
    let mut cfg = Config::default();
    cfg.humans.count = [3, 3];
    cfg.humans.spawn_radius_m = 1.5;
    cfg.humans.arm_swing = [0.5, 0.6];
    let model = crate::human::tests_support::tiny_model();
    let walk = |id: i64, y: f64, samples: usize| {
        let times: Vec<f64> = (0..samples).map(|k| k as f64 * 0.1).collect();
        let xy = times.iter().map(|&t| DVec2::new(t, y)).collect();
        Arc::new(Track { id, times_s: times, xy_m: xy, heading_rad: None })
    };
    // 32 frames at 10 Hz; tracks of 32 samples span the same 3.1 s, one of 21 ends early.
    let tracks = [walk(1, 0.0, 32), walk(2, 8.0, 32), walk(3, -8.0, 21)];
    let inp = PlanInputs { rate_hz: 10.0, grid: None, models: std::slice::from_ref(&model), tracks: &tracks, sensor: None, floor_z_m: 0.0, sensor_arc: None, places: &[], doors: &[], seats: &[], world: None };
    for seed in 0..5 {
        let plan = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed), &cfg, &inp).unwrap();
        let mut ids: Vec<i64> = plan
            .humans
            .iter()
            .map(|h| match &h.trajectory {
                HumanPath::Track(p) => {
                    assert!(p.t0_s.abs() < 1e-9, "the only window starts with the tracks: {}", p.t0_s);
                    p.track.id
                }
                other => panic!("not a track: {other:?}"),
            })
            .collect();
        ids.sort();
        assert_eq!(ids, vec![1, 2], "seed {seed}");
        let start = plan.sensor.position(0.0).truncate();
        assert!(start.distance(DVec2::new(0.0, 4.0)) <= 1.5 + 1e-9, "seed {seed}: the sensor starts at {start}");
        for h in &plan.humans {
            assert!((0.5..=0.6).contains(&h.arm_swing) && h.stride_m > 0.0, "seed {seed}: {h:?}");
        }
    }
    // Tracks longer than the sequence: its window starts anywhere they all cover it, and
    // a person's stride is the model's for the track's mean speed (1 m/s).
    let long = [walk(1, 0.0, 100), walk(2, 8.0, 100)];
    let inp_long = PlanInputs { rate_hz: 10.0, grid: None, models: std::slice::from_ref(&model), tracks: &long, sensor: None, floor_z_m: 0.0, sensor_arc: None, places: &[], doors: &[], seats: &[], world: None };
    let starts: Vec<f64> = (0..30)
        .map(|seed| {
            let plan = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed), &cfg, &inp_long).unwrap();
            let HumanPath::Track(p) = &plan.humans[0].trajectory else { panic!("not a track") };
            for h in &plan.humans {
                assert!((h.stride_m - model.gait_stride_m(1.0)).abs() < 1e-6, "seed {seed}: stride {}", h.stride_m);
            }
            p.t0_s
        })
        .collect();
    let (a, b) = (starts.iter().copied().fold(f64::INFINITY, f64::min), starts.iter().copied().fold(f64::NEG_INFINITY, f64::max));
    assert!(a >= 0.0 && b <= 9.9 - 3.1 + 1e-9 && b - a > 4.0, "windows start within {a}..{b}");
    // No person is asked for: a window without people is a plan.
    let mut none = cfg.clone();
    none.humans.count = [0, 0];
    assert!(sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(1), &none, &inp).unwrap().humans.is_empty());
    // People are asked for but no track keeps clear of the sensor in any window: refused.
    let mut crowded = cfg.clone();
    crowded.humans.min_separation_m = 50.0;
    let e = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(1), &crowded, &inp).unwrap_err().to_string();
    assert!(e.contains("humans.tracks") && e.contains("walks clear of obstacles and the sensor"), "{e}");
}

/// A track that walks 7.8 m and then stands: its last distance is first reached when it
/// stops (about 6 s in), not at the end of the table; a distance it never walks has no time.
#[test]
fn a_track_that_stops_reaches_its_last_distance_when_it_stops() {
    let times: Vec<f64> = (0..30).map(|k| k as f64 * 0.4).collect();
    let xy: Vec<DVec2> = times.iter().map(|&t| DVec2::new(1.3 * t.min(6.0), 0.0)).collect();
    let track = Arc::new(Track { id: 1, times_s: times, xy_m: xy, heading_rad: None });
    let path = HumanPath::Track(TrackPath::new(track, 0.0, 0.0, 10.0));
    let d_end = path.distance(10.0);
    assert!((d_end - 7.8).abs() < 0.05, "{d_end}");
    let t = path.time_at_distance(d_end).expect("reached when it stops");
    assert!((5.5..6.5).contains(&t), "reached at {t} s");
    assert!((path.distance(t) - d_end).abs() < 1e-9, "{} vs {d_end}", path.distance(t));
    assert_eq!(path.time_at_distance(d_end + 0.1), None, "it never walks further");
}

/// On a walkable floor people walk planned start-to-goal paths at speeds drawn within
/// `humans.speed_mps`, the sensor starts anywhere on the floor, and a sequence too long to
/// walk in the free area is refused naming `frames`.
#[test]
fn synthetic_people_walk_planned_paths_on_a_floor() {
    let (w, h) = (30.0, 30.0);
    let grid = crate::scene::planner::tests::grid(w, h, &[], 0.25);
    let mut cfg = Config::default();
    cfg.humans.count = [4, 4];
    cfg.humans.speed_mps = [0.8, 1.5];
    let model = crate::human::tests_support::tiny_model();
    let inp = PlanInputs { rate_hz: 10.0, grid: Some(&grid), models: std::slice::from_ref(&model), tracks: &[], sensor: None, floor_z_m: 0.0, sensor_arc: None, places: &[], doors: &[], seats: &[], world: None };
    let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
    for seed in 0..12 {
        let plan = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed), &cfg, &inp).unwrap();
        for p in &plan.humans {
            let HumanPath::Walk(walk, _) = &p.trajectory else { panic!("seed {seed}: not a planned walk: {:?}", p.trajectory) };
            assert!((0.8..=1.5).contains(&walk.speed_mps()), "seed {seed}: {} m/s", walk.speed_mps());
        }
        let s = plan.sensor.start_xy();
        (lo, hi) = (lo.min(s), hi.max(s));
    }
    assert!(lo.cmpge(DVec2::ZERO).all() && hi.cmple(DVec2::new(w, h)).all() && (hi - lo).min_element() > 10.0, "sensor starts within {lo}..{hi}");
    // People walk on the floor's height.
    let raised = PlanInputs { rate_hz: 10.0, grid: Some(&grid), models: std::slice::from_ref(&model), tracks: &[], sensor: None, floor_z_m: 0.75, sensor_arc: None, places: &[], doors: &[], seats: &[], world: None };
    let plan = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(3), &cfg, &raised).unwrap();
    for p in &plan.humans {
        assert!(matches!(p.trajectory, HumanPath::Walk(..)) && p.trajectory.position(1.0).z == 0.75, "{:?}", p.trajectory);
    }
    // The sensor's heading is drawn over the whole circle.
    use std::f64::consts::PI;
    let headings: Vec<f64> = (0..40)
        .map(|seed| match sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed), &cfg, &inp).unwrap().sensor {
            SensorPath::Arc(t) => t.heading0_rad,
            other => panic!("{other:?}"),
        })
        .collect();
    for quadrant in 0..4 {
        let (a, b) = (-PI + quadrant as f64 * PI / 2.0, -PI / 2.0 + quadrant as f64 * PI / 2.0);
        assert!(headings.iter().any(|&h| (a..b).contains(&h)), "no heading in [{a}, {b}): {headings:?}");
    }
    // Its speed and turn rate are drawn over their whole ranges, and only within them.
    cfg.scene.sensor_speed_mps = [0.5, 1.0];
    cfg.scene.sensor_yaw_rate_rps = [-0.2, 0.3];
    let arcs: Vec<Trajectory> = (0..40)
        .map(|seed| match sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed), &cfg, &inp).unwrap().sensor {
            SensorPath::Arc(t) => t,
            other => panic!("{other:?}"),
        })
        .collect();
    for (what, v, [lo, hi]) in [
        ("speed", arcs.iter().map(|t| t.speed_mps).collect::<Vec<_>>(), [0.5, 1.0]),
        ("yaw rate", arcs.iter().map(|t| t.yaw_rate_rps).collect(), [-0.2, 0.3]),
    ] {
        let (a, b) = (v.iter().copied().fold(f64::INFINITY, f64::min), v.iter().copied().fold(f64::NEG_INFINITY, f64::max));
        assert!(lo <= a && b <= hi && b - a > 0.7 * (hi - lo), "sensor {what} drawn within {a}..{b}");
    }
    // Longer than one walk can last in the free area: goal after goal.
    cfg.frames = 600;
    let plan = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(1), &cfg, &inp).unwrap();
    assert!(plan.humans.iter().all(|p| matches!(p.trajectory, HumanPath::Legs(..))), "{:?}", plan.humans[0].trajectory);
    cfg.humans.count = [0, 0];
    assert!(sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(1), &cfg, &inp).unwrap().humans.is_empty());
}

#[test]
fn gait_phase_advances_by_distance_over_stride() {
    let p = plan(MotionMode::Full);
    // 1.2 m/s for 0.5 s = 0.6 m = half a 1.2 m stride.
    assert!((p.at(0.5).gait_phase - 0.75).abs() < 1e-12);
    assert!((p.at(1.0).gait_phase - 0.25).abs() < 1e-12, "wraps after a whole stride");
    assert!((p.at(0.0).gait_phase - 0.25).abs() < 1e-12);
}

#[test]
fn motion_modes_follow_the_papers_ablations() {
    let t = 0.7;
    let full = plan(MotionMode::Full).at(t);
    let sliding = plan(MotionMode::Sliding).at(t);
    let in_place = plan(MotionMode::InPlace).at(t);
    let fixed = plan(MotionMode::Static).at(t);
    let start = plan(MotionMode::Full).at(0.0);
    assert_eq!(sliding.position_m, full.position_m);
    assert_eq!(sliding.gait_phase, 0.25);
    assert_eq!(in_place.position_m, start.position_m);
    assert_eq!(in_place.velocity_mps, DVec3::ZERO);
    assert_eq!(in_place.gait_phase, full.gait_phase);
    assert_eq!(fixed.position_m, start.position_m);
    assert_eq!(fixed.gait_phase, 0.25);
    assert_eq!(fixed.velocity_mps, DVec3::ZERO);
}

#[test]
fn sampling_is_reproducible_and_respects_counts() {
    let mut cfg = Config::default();
    cfg.humans.count = [3, 5];
    let model = crate::human::tests_support::tiny_model();
    let inp = PlanInputs { rate_hz: 10.0, grid: None, models: std::slice::from_ref(&model), tracks: &[], sensor: None, floor_z_m: 0.0, sensor_arc: None, places: &[], doors: &[], seats: &[], world: None };
    let a = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(7), &cfg, &inp).unwrap();
    let b = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(7), &cfg, &inp).unwrap();
    assert_eq!(a, b);
    assert!((3..=5).contains(&a.humans.len()));
    let mut seen: Vec<usize> = (0..30).map(|seed| sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed), &cfg, &inp).unwrap().humans.len()).collect();
    seen.sort_unstable();
    seen.dedup();
    assert_eq!(seen, vec![3, 4, 5], "every count in humans.count and only those");
    assert_eq!(a.times_s.len(), 32);
    for t in &a.times_s {
        for (i, h) in a.humans.iter().enumerate() {
            let p = h.at(*t).position_m.truncate();
            assert!(p.distance(a.sensor.position(*t).truncate()) >= cfg.humans.min_separation_m);
            for g in &a.humans[i + 1..] {
                assert!(g.at(*t).position_m.truncate().distance(p) >= cfg.humans.min_separation_m);
            }
        }
    }
}

/// Every kind of path's velocity is the derivative of its position, and its heading rate the
/// derivative of its heading (central differences), through stops and beside a turning walk.
#[test]
fn paused_and_companion_paths_move_as_their_velocities_say() {
    let arc: HumanPath = Trajectory { start_m: DVec2::new(1.0, 2.0), z_m: 0.0, heading0_rad: 0.3, speed_mps: 1.3, yaw_rate_rps: 0.4 }.into();
    let paused = HumanPath::Paused(Box::new(arc.clone()), Pauses::new(vec![(1.0, 2.5), (4.0, 4.5)]));
    let beside = HumanPath::Beside(Box::new(paused.clone()), -0.85);
    let rest_to_rest = HumanPath::Paused(Box::new(arc.clone()), Pauses::new(vec![(f64::NEG_INFINITY, 0.0), (4.0, f64::INFINITY)]));
    for path in [&paused, &beside, &HumanPath::Beside(Box::new(arc.clone()), 0.8), &rest_to_rest] {
        for k in 0..140 {
            let t = -0.5 + 0.05 * k as f64 + 0.013;
            let h = 1e-5;
            let num = (path.position(t + h) - path.position(t - h)) / (2.0 * h);
            assert!((num - path.velocity(t)).length() < 1e-6, "{path:?} at {t}: {num} vs {}", path.velocity(t));
            let rate = (path.heading_rad(t + h) - path.heading_rad(t - h)) / (2.0 * h);
            assert!((rate - path.heading_rate(t)).abs() < 1e-6, "at {t}: {rate} vs {}", path.heading_rate(t));
        }
    }
    // Stopped: still, facing where the walk left off; the walk resumes where it stopped.
    let stopped = paused.position(1.7);
    assert_eq!(paused.velocity(2.0), DVec3::ZERO);
    assert_eq!(paused.position(2.4), stopped);
    let walked = Pauses::new(vec![(1.0, 2.5), (4.0, 4.5)]).walked_time(6.0);
    assert!((walked - (6.0 - 1.5 - 0.6 - 0.5 - 0.6)).abs() < 1e-12, "{walked}");
    // Side by side: 0.85 m to the right of the paused walker at every instant.
    for t in [0.0, 1.2, 2.0, 3.3, 5.0] {
        let (a, b) = (paused.position(t), beside.position(t));
        let right = DVec2::from_angle(paused.heading_rad(t) - std::f64::consts::FRAC_PI_2);
        assert!((b - a).truncate().distance(right * 0.85) < 1e-12, "at {t}");
    }
    // The gait: distance held while stopped, and the time a distance is reached found back.
    assert_eq!(paused.distance(1.6), paused.distance(2.4));
    for d in [0.3, 1.0, 2.0, 4.0] {
        let t = paused.time_at_distance(d).unwrap();
        assert!((paused.distance(t) - d).abs() < 1e-5, "{d}: at {t} walked {}", paused.distance(t));
        assert!(paused.distance(t - 0.01) < d);
    }
}

/// A walk from standing to standing: held at its start, getting going over a ramp, slowing
/// to a stop over another, held at its end; the walked time found back from either side.
#[test]
fn a_walk_from_rest_to_rest_ramps_at_both_ends() {
    let r = Pauses::RAMP_S;
    let p = Pauses::new(vec![(10.0 + r, f64::INFINITY), (f64::NEG_INFINITY, 0.0)]);
    assert_eq!(p.stops().len(), 2);
    for (t, pace, walked) in [(-1.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.5 * r, 0.5, r / 8.0), (r, 1.0, r / 2.0), (5.0, 1.0, 5.0 - r / 2.0), (10.0 + r, 0.0, 10.0), (99.0, 0.0, 10.0)] {
        assert!((p.pace(t) - pace).abs() < 1e-12 && (p.walked_time(t) - walked).abs() < 1e-12, "at {t}: {} {}", p.pace(t), p.walked_time(t));
    }
    assert!((p.walked_time(10.0 + 0.5 * r) - (10.0 - r / 8.0)).abs() < 1e-12);
    for u in [0.0, 0.01, r / 2.0, 3.0, 9.99, 10.0] {
        let t = p.time_walked(u).unwrap();
        assert!((p.walked_time(t) - u).abs() < 1e-5 && t <= 10.0 + r + 1e-9, "{u}: {t}");
    }
    assert_eq!(p.time_walked(10.01), None);
    // A stop from minus infinity that ends before 0 would hold the walk before its start.
    assert!(Pauses::new(vec![(f64::NEG_INFINITY, -1.0)]).stops().is_empty());
}

/// Overlapping or empty stops are dropped; a stop begins with a walk slowing down.
#[test]
fn pauses_keep_apart_and_ramp() {
    // (3, 4) would begin slowing at 2.4, while the walk is still getting going after 2.
    let p = Pauses::new(vec![(3.0, 4.0), (1.0, 2.0), (4.5, 6.0), (f64::NAN, 1.0), (7.0, 7.0)]);
    assert_eq!(p.stops(), &[(1.0, 2.0), (4.5, 6.0)]);
    assert_eq!(p.pace(0.0), 1.0);
    assert!((p.pace(0.7) - 0.5).abs() < 1e-12);
    assert_eq!(p.pace(1.5), 0.0);
    assert!((p.pace(2.3) - 0.5).abs() < 1e-12);
    assert_eq!(p.pace(2.7), 1.0);
}

/// `humans.standing`, `groups` and `stop_and_go`: the shares come out near what is asked;
/// standing people stand (a share of them turning), companions stand face to face or walk
/// side by side, and stop-and-go walkers stop; nobody collides. With every share at 0 the
/// people are drawn exactly as before.
#[test]
fn behaviours_come_in_the_shares_asked_for() {
    let model = crate::human::tests_support::tiny_model();
    let (w, h) = (40.0, 40.0);
    let grid = crate::scene::planner::tests::grid(w, h, &[], 0.25);
    let inp = PlanInputs { rate_hz: 10.0, grid: Some(&grid), models: std::slice::from_ref(&model), tracks: &[], sensor: None, floor_z_m: 0.0, sensor_arc: None, places: &[], doors: &[], seats: &[], world: None };
    let mut cfg = Config::default();
    cfg.humans.count = [10, 10];
    cfg.humans.spawn_radius_m = 18.0;
    let plain = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(4), &cfg, &inp).unwrap();
    cfg.humans.standing = 0.4;
    cfg.humans.groups = 0.3;
    cfg.humans.stop_and_go = 0.5;
    let (mut still, mut turning, mut facing, mut beside, mut paused, mut total) = (0, 0, 0, 0, 0, 0);
    for seed in 0..20 {
        let plan = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed), &cfg, &inp).unwrap();
        for (i, p) in plan.humans.iter().enumerate() {
            total += 1;
            match &p.trajectory {
                HumanPath::Arc(a) if a.speed_mps == 0.0 => {
                    still += 1;
                    turning += usize::from(a.yaw_rate_rps != 0.0);
                    // Face to face: a companion looks at the one placed before it.
                    if i > 0 {
                        let other = plan.humans[i - 1].trajectory.position(0.0).truncate();
                        let to = other - a.start_m;
                        let off = crate::geometry::wrap_pi(to.y.atan2(to.x) - a.heading0_rad);
                        if (0.8..=1.4).contains(&to.length()) && off.abs() <= 0.36 {
                            facing += 1;
                        }
                    }
                }
                HumanPath::Beside(..) => beside += 1,
                HumanPath::Paused(..) => paused += 1,
                _ => {}
            }
            for t in &plan.times_s {
                let q = p.position_m(*t).truncate();
                assert!(grid.clearance(q) >= cfg.humans.clearance_m, "seed {seed}: person {i} off the floor");
                for g in &plan.humans[i + 1..] {
                    assert!(g.position_m(*t).truncate().distance(q) >= cfg.humans.min_separation_m, "seed {seed}: collision");
                }
            }
        }
    }
    let share = |n: usize| n as f64 / total as f64;
    assert!((0.3..0.65).contains(&share(still)), "standing {still} of {total}");
    assert!(turning > 0 && turning < still, "turning {turning} of {still}");
    assert!(facing > 5 && beside > 5, "face to face {facing}, side by side {beside}");
    assert!((0.15..0.45).contains(&share(paused)), "paused {paused} of {total}");
    // Shares of 0 draw nothing: the same plan as a configuration without the keys.
    cfg.humans.standing = 0.0;
    cfg.humans.groups = 0.0;
    cfg.humans.stop_and_go = 0.0;
    assert_eq!(sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(4), &cfg, &inp).unwrap(), plain);
}

/// Of the people planned with seeds 0-9, how many `test` holds for, and how many there are.
fn count_over_seeds(cfg: &Config, inp: &PlanInputs, test: impl Fn(&SequencePlan, &HumanPlan) -> bool) -> (usize, usize) {
    let (mut n, mut total) = (0, 0);
    for seed in 0..10 {
        let plan = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed), cfg, inp).unwrap();
        for p in &plan.humans {
            n += usize::from(test(&plan, p));
            total += 1;
        }
    }
    (n, total)
}

/// `humans.by_things`: a person standing by something stands with an obstacle within
/// `clearance_m` + `BY_THING_M` (and never nearer than `clearance_m`); without it, people stand
/// anywhere (most of them in the open here).
#[test]
fn people_asked_to_stand_by_things_stand_beside_them() {
    let model = crate::human::tests_support::tiny_model();
    let boxes: Vec<[f64; 4]> = (0..4).map(|k| [6.0 + 8.0 * k as f64, 18.0, 6.6 + 8.0 * k as f64, 18.6]).collect();
    let grid = crate::scene::planner::tests::grid(40.0, 40.0, &boxes, 0.1);
    let inp = PlanInputs { rate_hz: 10.0, grid: Some(&grid), models: std::slice::from_ref(&model), tracks: &[], sensor: None, floor_z_m: 0.0, sensor_arc: None, places: &[], doors: &[], seats: &[], world: None };
    let mut cfg = Config::default();
    cfg.humans.count = [6, 6];
    cfg.humans.spawn_radius_m = 18.0;
    cfg.humans.standing = 1.0;
    let near = crate::config::BY_THING_M + cfg.humans.clearance_m;
    let count_near = |cfg: &Config| {
        count_over_seeds(cfg, &inp, |_, p| {
            let c = grid.clearance(p.position_m(0.0).truncate());
            assert!(c >= cfg.humans.clearance_m, "a person inside an obstacle's clearance ({c} m)");
            c <= near
        })
    };
    let (anywhere, total) = count_near(&cfg);
    assert!(anywhere * 4 < total, "{anywhere} of {total} by a thing without being asked");
    cfg.humans.by_things = 1.0;
    let (by, total) = count_near(&cfg);
    assert_eq!(by, total, "{by} of {total} by a thing");
    cfg.humans.by_things = 1.5;
    assert!(cfg.validate().is_err());
}

/// Over a field of sixteen `height_m` high boxes (3 x 0.6 m, 9 m apart), six people a sequence
/// of whom half stand: how many people `holds` (given the grid, the sensor halfway through and
/// the person) without `share`, and with it at 1; each as (holding, all).
fn placed_by_a_share(height_m: f64, share: fn(&mut Config) -> &mut f64, holds: fn(&WalkableGrid, DVec2, &HumanPlan) -> bool) -> [(usize, usize); 2] {
    let model = crate::human::tests_support::tiny_model();
    let boxes: Vec<[f64; 4]> = (0..16).map(|k| [4.0 + 9.0 * (k % 4) as f64, 6.0 + 9.0 * (k / 4) as f64, 7.0 + 9.0 * (k % 4) as f64, 6.6 + 9.0 * (k / 4) as f64]).collect();
    let env = crate::scene::planner::tests::floor_with_boxes(40.0, 40.0, &boxes, height_m);
    let grid = WalkableGrid::from_environment(&env, 0.1).unwrap();
    let inp = PlanInputs { rate_hz: 10.0, grid: Some(&grid), models: std::slice::from_ref(&model), tracks: &[], sensor: None, floor_z_m: 0.0, sensor_arc: None, places: &[], doors: &[], seats: &[], world: None };
    let mut cfg = Config::default();
    cfg.humans.count = [6, 6];
    cfg.humans.spawn_radius_m = 18.0;
    cfg.humans.standing = 0.5;
    let count = |cfg: &Config| {
        count_over_seeds(cfg, &inp, |plan, p| {
            let mid = plan.sensor.position(plan.times_s.last().unwrap() * 0.5).truncate();
            holds(&grid, mid, p)
        })
    };
    let without = count(&cfg);
    *share(&mut cfg) = 1.0;
    let with = count(&cfg);
    *share(&mut cfg) = -0.5;
    assert!(cfg.validate().is_err(), "a share below 0");
    *share(&mut cfg) = 1.5;
    assert!(cfg.validate().is_err(), "a share above 1");
    [without, with]
}

/// `humans.before_things`: a person asked to stand before something starts with a tall
/// obstacle (2 m boxes) at most `BEFORE_THING_M` behind it as the sensor sees it halfway
/// through; without it, few do (most stand in the open here).
#[test]
fn people_asked_to_stand_before_things_have_one_behind_them() {
    let [(anywhere, total), (asked, all)] = placed_by_a_share(2.0, |c| &mut c.humans.before_things, |g, mid, p| g.obstacle_behind(mid, p.position_m(0.0).truncate(), crate::scene::BEFORE_THING_M));
    assert!(anywhere * 4 < total, "{anywhere} of {total} before a thing without being asked");
    assert_eq!(asked, all, "{asked} of {all} before a thing");
}

/// `humans.behind_things`: a person asked to stand behind something starts with a low
/// obstacle (0.9 m boxes: counters) at most `BEHIND_THING_M` in front of it as the sensor sees
/// it halfway through, and one who stands faces it (the sensor) within 30 degrees; without
/// it, few do.
#[test]
fn people_asked_to_stand_behind_things_have_one_before_them() {
    let [(anywhere, total), (asked, all)] = placed_by_a_share(0.9, |c| &mut c.humans.behind_things, |g, mid, p| {
        let at = p.position_m(0.0).truncate();
        let off = crate::geometry::wrap_pi(p.trajectory.heading_rad(0.0) - (mid - at).to_angle());
        let walks = p.trajectory.velocity(0.0).length() > 0.0;
        g.low_obstacle_before(mid, at, crate::scene::BEHIND_THING_M) && (walks || off.abs() <= std::f64::consts::FRAC_PI_6 + 1e-9)
    });
    assert!(anywhere * 4 < total, "{anywhere} of {total} behind a thing without being asked");
    assert_eq!(asked, all, "{asked} of {all} behind a thing");
}

/// `humans.at_places`: in a street of markets, every person asked to stand at a place stands
/// on one of the world's places (behind a counter, before it, by a table), each on their own
/// and facing the place's way; without it, hardly anybody does.
#[test]
fn people_asked_to_stand_at_places_stand_on_them() {
    use crate::scene::world::{World, WorldKind, WorldParams};
    let model = crate::human::tests_support::tiny_model();
    let params = WorldParams { duration_s: 0.3, sensor_height_m: 1.73, sensor_speed_mps: [0.0, 2.0], clearance_m: 0.35, markets: 1.0, side_streets: 0.0 };
    let w = World::build(WorldKind::Street, 2, 0, &params).unwrap();
    assert!(w.places.len() > 20, "{} places: {}", w.places.len(), w.summary());
    let inp = PlanInputs { rate_hz: 10.0, grid: Some(&w.grid), models: std::slice::from_ref(&model), tracks: &[], sensor: None, floor_z_m: 0.0, sensor_arc: w.sensor, places: &w.places, doors: &w.doors, seats: &w.seats, world: None };
    let mut cfg = Config::default();
    cfg.frames = 4;
    cfg.humans.count = [8, 8];
    cfg.humans.spawn_radius_m = 35.0;
    cfg.humans.standing = 1.0;
    let on_places = |cfg: &Config| {
        let (mut n, mut total) = (0, 0);
        for seed in 0..4 {
            let plan = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed), cfg, &inp).unwrap();
            for p in &plan.humans {
                let at = p.position_m(0.0).truncate();
                n += usize::from(w.places.iter().any(|q| q.at.distance(at) < 1e-9));
                total += 1;
            }
        }
        (n, total)
    };
    let (anywhere, total) = on_places(&cfg);
    assert!(total >= 24 && anywhere * 10 < total, "{anywhere} of {total} on a place without being asked");
    cfg.humans.at_places = 1.0;
    let (at, total) = on_places(&cfg);
    assert_eq!(at, total, "{at} of {total} on a place");
    // Each faces the place's way (out over a counter, towards a stall or a table) within 30
    // degrees; drawn anyhow, a third would not.
    for seed in 0..4 {
        let plan = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(seed), &cfg, &inp).unwrap();
        for p in &plan.humans {
            let q = w.places.iter().find(|q| q.at.distance(p.position_m(0.0).truncate()) < 1e-9).unwrap();
            let off = crate::geometry::wrap_pi(p.trajectory.heading_rad(0.0) - q.facing_rad);
            assert!(off.abs() <= std::f64::consts::FRAC_PI_6 + 1e-9, "faces {off} rad off its place's way");
        }
    }
    cfg.humans.at_places = -0.1;
    assert!(cfg.validate().is_err());
}

/// `pick_model` draws exactly the even index of one number at `carrying` 0 (the draws that
/// follow unchanged), and at 0.4 gives 40 % of the people something, the kinds and bodies
/// evenly (`humans.carrying`).
#[test]
fn a_share_of_the_people_carry_each_kind_evenly() {
    let mut a = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let mut b = a.clone();
    for _ in 0..1000 {
        assert_eq!(crate::scene::pick_model(&mut a, 7, 0.0), crate::scene::even_index(b.random::<f64>(), 7));
    }
    assert_eq!(a.random::<u64>(), b.random::<u64>());
    let (bodies, draws) = (5, 40_000);
    let mut counts = vec![0usize; bodies * 4];
    for _ in 0..draws {
        counts[crate::scene::pick_model(&mut a, bodies * 4, 0.4)] += 1;
    }
    let share = |from: usize, to: usize| counts[from..to].iter().sum::<usize>() as f64 / draws as f64;
    assert!((share(bodies, 4 * bodies) - 0.4).abs() < 0.01, "{counts:?}");
    for k in 1..4 {
        assert!((share(k * bodies, (k + 1) * bodies) - 0.4 / 3.0).abs() < 0.01, "kind {k}: {counts:?}");
    }
    for body in 0..bodies {
        let s = (0..4).map(|k| counts[k * bodies + body]).sum::<usize>() as f64 / draws as f64;
        assert!((s - 0.2).abs() < 0.01, "body {body}: {counts:?}");
    }
}

/// A long sequence's legs that start where the leg before ends are one walk; one that starts
/// more than half a metre away (leaving and coming back in) is a cut at its start. A path of
/// one piece, or a person who does not move, has none.
#[test]
fn a_leg_that_starts_elsewhere_is_a_cut() {
    let arc = |x: f64, y: f64| HumanPath::from(Trajectory { start_m: DVec2::new(x, y), z_m: 0.0, heading0_rad: 0.0, speed_mps: 1.0, yaw_rate_rps: 0.0 });
    let legs = vec![
        Leg { t0_s: 0.0, d0_m: 0.0, path: arc(0.0, 0.0) },
        Leg { t0_s: 5.0, d0_m: 5.0, path: arc(5.0, 0.0) },
        Leg { t0_s: 9.0, d0_m: 9.0, path: arc(60.0, 3.0) },
        // 0.3 m on from where the leg before ends: the same walk, not a cut.
        Leg { t0_s: 12.0, d0_m: 12.0, path: arc(63.3, 3.0) },
    ];
    let mut p = plan(MotionMode::Full);
    p.trajectory = HumanPath::Legs(Arc::new(legs));
    assert_eq!(p.cuts(), vec![9.0]);
    p.motion = MotionMode::Static;
    assert!(p.cuts().is_empty());
    assert!(plan(MotionMode::Full).cuts().is_empty());
}
