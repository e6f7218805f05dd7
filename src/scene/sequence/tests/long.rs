//! Long sequences' people: goal after goal to the end, left behind and coming back in,
//! through doorways.

use super::*;

/// The checks of a long sequence's people: clear of the walls, of each other and of the
/// sensor at every frame; within a leg the velocity is the positions' derivative; the speed
/// never steps (walks get going and slow down over [`Pauses::RAMP_S`]) save where somebody
/// comes back in; the gait's distance never jumps or goes back; and the people walk to the end.
fn check_long(plan: &SequencePlan, grid: &crate::scene::WalkableGrid, cfg: &Config) {
    let hc = &cfg.humans;
    let times = &plan.times_s;
    let duration = *times.last().unwrap();
    let mut late_walk = 0.0;
    for (i, p) in plan.humans.iter().enumerate() {
        let HumanPath::Legs(legs) = &p.trajectory else { panic!("person {i}: {:?}", p.trajectory) };
        assert!(legs.len() >= 4, "person {i}: {} legs", legs.len());
        assert!(legs.windows(2).all(|w| w[1].t0_s > w[0].t0_s && w[1].d0_m >= w[0].d0_m));
        let speed = legs.iter().map(|g| g.path.velocity(1.0).length()).fold(0.0, f64::max);
        // Where one leg hands over to the next in place, the velocity goes on.
        for w in legs.windows(2) {
            let span = w[1].t0_s - w[0].t0_s;
            if w[0].path.position(span).distance(w[1].path.position(0.0)) < 1e-9 {
                let (a, b) = (w[0].path.velocity(span), w[1].path.velocity(0.0));
                assert!((a - b).length() < 1e-9, "person {i} at {} s: {a} then {b}", w[1].t0_s);
            }
        }
        for (k, &t) in times.iter().enumerate() {
            let q = p.position_m(t).truncate();
            assert!(grid.clearance(q) >= hc.clearance_m, "person {i} off the floor at {t} s");
            assert!(q.distance(plan.sensor.position(t).truncate()) >= hc.min_separation_m, "person {i} on the sensor at {t} s");
            for g in &plan.humans[i + 1..] {
                assert!(g.position_m(t).truncate().distance(q) >= hc.min_separation_m, "person {i}: collision at {t} s");
            }
            if k > 0 {
                let step = p.trajectory.distance(t) - p.trajectory.distance(times[k - 1]);
                assert!((-1e-9..=speed * 0.1 + 1e-9).contains(&step), "person {i}: the gait's distance steps {step} m at {t} s");
                // From one frame to the next the speed changes by a ramp's 0.1 s at most.
                let dv = p.trajectory.velocity(t).length() - p.trajectory.velocity(times[k - 1]).length();
                let moved = p.position_m(t).distance(p.position_m(times[k - 1]));
                assert!(dv.abs() <= speed * 0.1 / Pauses::RAMP_S + 1e-9 || moved > speed * 0.1 + 1e-6, "person {i}: the speed steps {dv} m/s at {t} s");
            }
            // Not within 10 ms of a leg's start (where somebody comes back in, the position jumps).
            let h = 1e-4;
            if legs.iter().all(|g| (g.t0_s - t).abs() > 0.01) {
                let fd = (p.trajectory.position(t + h) - p.trajectory.position(t - h)) / (2.0 * h);
                assert!((fd - p.trajectory.velocity(t)).length() < 1e-3, "person {i} at {t} s: {fd} vs {}", p.trajectory.velocity(t));
            }
        }
        late_walk += p.trajectory.distance(duration) - p.trajectory.distance(duration - 30.0);
    }
    // Over the last 30 s they walk on: 5 m or more each, on average.
    assert!(late_walk / plan.humans.len() as f64 > 5.0, "walked {late_walk:.1} m in all in the last 30 s");
}

/// Long sequences walk goal after goal: in a room more than one walk can last, people keep
/// walking to the end, waiting at their goals while turning toward the next.
#[test]
fn long_sequences_keep_their_people_walking_to_the_end() {
    let model = crate::human::tests_support::tiny_model();
    let grid = crate::scene::planner::tests::grid(30.0, 20.0, &[], 0.25);
    let inp = PlanInputs { rate_hz: 10.0, grid: Some(&grid), models: std::slice::from_ref(&model), tracks: &[], sensor: None, floor_z_m: 0.0, sensor_arc: None, places: &[], doors: &[], seats: &[], world: None };
    let mut cfg = Config::default();
    cfg.frames = 1201;
    cfg.humans.count = [6, 6];
    cfg.humans.speed_mps = [1.0, 1.5];
    cfg.humans.standing = 0.3;
    cfg.scene.sensor_speed_mps = [0.0, 0.0];
    let plan = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(5), &cfg, &inp).unwrap();
    check_long(&plan, &grid, &cfg);
    // Waits turn at a constant rate from one walk's end heading to the next's start.
    let HumanPath::Legs(legs) = &plan.humans[0].trajectory else { unreachable!() };
    let walk = |p: &HumanPath| match p {
        HumanPath::Paused(w, _) => match &**w {
            HumanPath::Walk(w, _) => Some(w.clone()),
            _ => None,
        },
        _ => None,
    };
    let mut turns = 0;
    for w in legs.windows(3) {
        if let (Some(a), HumanPath::Arc(turn), Some(b)) = (walk(&w[0].path), &w[1].path, walk(&w[2].path)) {
            turns += 1;
            let span = w[2].t0_s - w[1].t0_s;
            let end = turn.heading_rad(span);
            let gap = |x: f64, y: f64| crate::geometry::wrap_pi(x - y).abs();
            assert!(gap(turn.heading0_rad, a.heading_rad(a.duration_s())) < 1e-9 && gap(end, b.heading_rad(0.0)) < 1e-9);
        }
    }
    assert!(turns >= 3, "{turns} waits between walks");
}

/// Where no arc of the sensor fits a long sequence, the sensor walks too, clear of the walls,
/// its velocity and yaw rate the derivatives of its pose; and people a sensor drives away
/// from come back near it, never farther than [`LEAVE_M`] (plus a frame's motion).
#[test]
fn a_long_sequences_sensor_walks_and_a_driving_one_keeps_its_people() {
    let model = crate::human::tests_support::tiny_model();
    let grid = crate::scene::planner::tests::grid(30.0, 20.0, &[], 0.25);
    let inp = PlanInputs { rate_hz: 10.0, grid: Some(&grid), models: std::slice::from_ref(&model), tracks: &[], sensor: None, floor_z_m: 0.0, sensor_arc: None, places: &[], doors: &[], seats: &[], world: None };
    let mut cfg = Config::default();
    cfg.frames = 601;
    cfg.humans.count = [3, 3];
    cfg.scene.sensor_speed_mps = [0.8, 1.2];
    cfg.scene.sensor_yaw_rate_rps = [0.0, 0.0];
    let plan = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(2), &cfg, &inp).unwrap();
    assert!(matches!(plan.sensor, SensorPath::Walk(..)), "{:?}", plan.sensor);
    for &t in &plan.times_s {
        let p = plan.sensor.position(t);
        assert!(grid.clearance(p.truncate()) >= cfg.scene.sensor_clearance_m && (p.z - cfg.scene.sensor_height_m).abs() < 1e-12);
        let h = 1e-4;
        let fd = (plan.sensor.position(t + h) - plan.sensor.position(t - h)) / (2.0 * h);
        let yaw = (plan.sensor.heading_rad(t + h) - plan.sensor.heading_rad(t - h)) / (2.0 * h);
        if (fd - plan.sensor.velocity(t)).length() > 1e-3 || (yaw - plan.sensor.yaw_rate_rps(t)).abs() > 1e-3 {
            // Only where one leg hands over to the next (the speed steps there).
            let SensorPath::Walk(w, _) = &plan.sensor else { unreachable!() };
            let HumanPath::Legs(legs) = &**w else { panic!("{w:?}") };
            assert!(legs.iter().any(|g| (g.t0_s - t).abs() < 2.0 * h), "sensor at {t} s: {fd} vs {}", plan.sensor.velocity(t));
        }
    }
    check_long(&plan, &grid, &cfg);

    // A vehicle driving 8 m/s down a 600 m street for 60 s.
    let street = crate::scene::planner::tests::grid(600.0, 12.0, &[], 0.25);
    let arc = Trajectory { start_m: DVec2::new(20.0, 6.0), z_m: 1.7, heading0_rad: 0.0, speed_mps: 8.0, yaw_rate_rps: 0.0 };
    let inp = PlanInputs { grid: Some(&street), sensor_arc: Some(arc), ..inp };
    cfg.humans.count = [4, 4];
    let plan = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(3), &cfg, &inp).unwrap();
    let mut came_back = 0;
    for p in &plan.humans {
        let far = plan.times_s.iter().map(|&t| p.position_m(t).truncate().distance(plan.sensor.position(t).truncate())).fold(0.0, f64::max);
        assert!(far <= LEAVE_M + 1.0, "a person {far:.1} m from the sensor");
        let HumanPath::Legs(legs) = &p.trajectory else { panic!() };
        came_back += legs.windows(2).filter(|w| w[0].path.position(w[1].t0_s - w[0].t0_s).truncate().distance(w[1].path.position(0.0).truncate()) > 1.0).count();
    }
    assert!(came_back >= 4, "{came_back} returns");
    // Those who stand first (10-60 s) and who wait at a goal are taken out too once the
    // vehicle has left them behind.
    cfg.humans.standing = 1.0;
    let plan = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(3), &cfg, &inp).unwrap();
    for p in &plan.humans {
        let far = plan.times_s.iter().map(|&t| p.position_m(t).truncate().distance(plan.sensor.position(t).truncate())).fold(0.0, f64::max);
        assert!(far <= LEAVE_M + 1.0, "one who stood first {far:.1} m from the sensor");
    }
}

/// Where nobody finds a walk (a street walled into pockets shorter than any leg), people wait
/// 2 s at a time; one left 100 m behind by a driving sensor while waiting is taken out at that
/// frame, not at the end of the wait, and comes back in near the sensor.
#[test]
fn one_waiting_for_a_way_is_taken_out_once_left_behind() {
    let model = crate::human::tests_support::tiny_model();
    // Open for the first 60 m (where people are placed), then pockets 2.6 m x 6 m: the
    // longest straight line in one (about 5.6 m with the clearance) is shorter than the least
    // leg (8 s at 0.8 m/s). A gap of 0.5 m under the walls joins them into one walkable area
    // that nobody fits through; the vehicle drives beside them, where nobody walks.
    let mut walls: Vec<[f64; 4]> = (20..200).map(|k| [3.0 * k as f64, 0.5, 3.0 * k as f64 + 0.4, 6.0]).collect();
    walls.push([60.0, 6.0, 600.0, 12.0]);
    let street = crate::scene::planner::tests::grid(600.0, 12.0, &walls, 0.25);
    let arc = Trajectory { start_m: DVec2::new(20.0, 9.0), z_m: 1.7, heading0_rad: 0.0, speed_mps: 8.0, yaw_rate_rps: 0.0 };
    let inp = PlanInputs { rate_hz: 10.0, grid: Some(&street), models: std::slice::from_ref(&model), tracks: &[], sensor: None, floor_z_m: 0.0, sensor_arc: Some(arc), places: &[], doors: &[], seats: &[], world: None };
    let mut cfg = Config::default();
    cfg.frames = 601;
    cfg.humans.count = [4, 4];
    cfg.humans.standing = 1.0;
    let plan = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(3), &cfg, &inp).unwrap();
    let mut waits = 0;
    for p in &plan.humans {
        let far = plan.times_s.iter().map(|&t| p.position_m(t).truncate().distance(plan.sensor.position(t).truncate())).fold(0.0, f64::max);
        assert!(far <= LEAVE_M + 1.0, "one waiting for a way {far:.1} m from the sensor");
        let HumanPath::Legs(legs) = &p.trajectory else { panic!() };
        // In the pockets nobody walks: a wait, then another, or back in near the sensor.
        let pocketed: Vec<_> = legs.iter().filter(|g| g.path.position(0.0).x > 60.5).collect();
        assert!(pocketed.iter().all(|g| g.path.velocity(0.5).length() == 0.0), "a walk in a pocket");
        waits += pocketed.len();
    }
    // Each person waits in turn after turn there (60 s at 8 m/s).
    assert!(waits >= 4 * 10, "{waits} waits");
}

/// People a driving sensor leaves behind come back in out of its sight where the street has
/// such places (behind a row of kiosks), where places drawn as before are mostly in view.
#[test]
fn people_come_back_in_from_out_of_sight() {
    let (street, cfg, plan, arrivals) = coming_back(&[], 8.0, 4, 60);
    let hidden = arrivals.iter().filter(|(t, at, _)| street.hidden_from(plan.sensor.position(*t).truncate(), *at)).count();
    let arrivals = arrivals.len();
    assert!(arrivals >= 4 && hidden * 10 >= arrivals * 9, "{hidden} of {arrivals} arrivals out of sight");
    // Places drawn around the sensor as before this (0.3-1 spawn radii) are mostly in view.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
    let (mut free, mut out_of_sight) = (0, 0);
    for _ in 0..2000 {
        let eye = DVec2::new(rng.random_range(50.0..550.0), 4.0);
        let (r, a) = (cfg.humans.spawn_radius_m * rng.random_range(0.3..1.0), rng.random_range(0.0..std::f64::consts::TAU));
        let p = eye + r * DVec2::new(a.cos(), a.sin());
        if street.clearance(p) >= cfg.humans.clearance_m {
            free += 1;
            out_of_sight += street.hidden_from(eye, p) as usize;
        }
    }
    assert!(out_of_sight * 3 < free, "{out_of_sight} of {free} drawn places out of sight");
}

/// People near the sensor go in through the street's doorways now and then: they walk to one,
/// stop in it and come back in elsewhere; without doorways nobody leaves but those left far
/// behind.
#[test]
fn people_go_in_through_doorways() {
    let doors: Vec<crate::scene::world::Place> =
        (0..70).map(|k| crate::scene::world::Place { at: DVec2::new(16.0 + 8.0 * k as f64, 14.0), facing_rad: -std::f64::consts::FRAC_PI_2 }).collect();
    let departures = |doors: &[crate::scene::world::Place], sensor_mps: f64, people: usize, seconds: usize| {
        let (_, _, plan, _) = coming_back(doors, sensor_mps, people, seconds);
        let mut gone = Vec::new();
        for p in &plan.humans {
            let HumanPath::Legs(legs) = &p.trajectory else { panic!() };
            for w in legs.windows(2) {
                let dt = w[1].t0_s - w[0].t0_s;
                let from = w[0].path.position(dt).truncate();
                if from.distance(w[1].path.position(0.0).truncate()) > 1.0 {
                    let sensor = plan.sensor.position(w[1].t0_s).truncate();
                    // Stopped there: 2 cm in its last tenth of a second.
                    let stopped = w[0].path.position(dt - 0.1).truncate().distance(from) < 0.02;
                    gone.push((from, from.distance(sensor), stopped));
                }
            }
        }
        gone
    };
    let with = departures(&doors, 0.3, 20, 600);
    let in_doors: Vec<_> = with.iter().filter(|(from, ..)| doors.iter().any(|d| d.at.distance(*from) < 1e-6)).collect();
    assert!(in_doors.len() >= 3, "{} of {} departures through doorways", in_doors.len(), with.len());
    for (from, sensor_m, stopped) in &in_doors {
        assert!(*stopped && *sensor_m < LEAVE_M, "gone in at {from}, {sensor_m} m from the sensor, stopped {stopped}");
    }
    // Without doorways, in a sensor's wake that leaves people far behind.
    let without = departures(&[], 8.0, 4, 60);
    assert!(!without.is_empty() && without.iter().all(|(_, sensor_m, ..)| *sensor_m > LEAVE_M), "{without:?}");
}

/// Where somebody comes back in is checked where they stand at that moment, between frames too
/// (a check over the frames of an instant between two frames would check nothing).
#[test]
fn a_place_to_come_back_in_between_frames_is_checked() {
    let env = crate::scene::planner::tests::floor_with_boxes(40.0, 16.0, &[[10.0, 4.0, 14.0, 8.0]], 2.5);
    let grid = crate::scene::WalkableGrid::from_environment(&env, 0.25).unwrap();
    let times_s: Vec<f64> = (0..20).map(|k| k as f64 * 0.1).collect();
    let crowd = Crowd { grid: &grid, clearance_m: 0.3, separation_m: 0.5, sensor: None, others: &[], times_s: &times_s, doors: &[], world: None, held: None, thing_times: &[] };
    let (inside, open) = (DVec2::new(12.0, 6.0), DVec2::new(30.0, 6.0));
    for t in [0.1, 0.15, 0.1 + 1e-12] {
        assert!(!crowd.clear_at(inside, t) && crowd.clear_at(open, t), "at {t} s");
    }
}

/// `people` around a sensor driving `sensor_mps` for `seconds` down a street with a row of 2.5 m
/// kiosks (and `doors`): the walkable area, the configuration, the plan, and each arrival (somebody
/// coming back in): its time, where, and the walk it starts.
fn coming_back(doors: &[crate::scene::world::Place], sensor_mps: f64, people: usize, seconds: usize) -> (crate::scene::WalkableGrid, Config, SequencePlan, Vec<(f64, DVec2, HumanPath)>) {
    let model = crate::human::tests_support::tiny_model();
    let kiosks: Vec<[f64; 4]> = (0..49).map(|k| 10.0 + 12.0 * k as f64).map(|x| [x, 9.0, x + 2.5, 10.5]).collect();
    let env = crate::scene::planner::tests::floor_with_boxes(600.0, 16.0, &kiosks, 2.5);
    let street = crate::scene::WalkableGrid::from_environment(&env, 0.25).unwrap();
    let arc = Trajectory { start_m: DVec2::new(20.0, 4.0), z_m: 1.7, heading0_rad: 0.0, speed_mps: sensor_mps, yaw_rate_rps: 0.0 };
    let inp = PlanInputs { rate_hz: 10.0, grid: Some(&street), models: std::slice::from_ref(&model), tracks: &[], sensor: None, floor_z_m: 0.0, sensor_arc: Some(arc), places: &[], doors, seats: &[], world: None };
    let mut cfg = Config::default();
    cfg.frames = 10 * seconds + 1;
    cfg.humans.count = [people, people];
    let plan = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(3), &cfg, &inp).unwrap();
    let mut arrivals = Vec::new();
    for p in &plan.humans {
        let HumanPath::Legs(legs) = &p.trajectory else { panic!() };
        for w in legs.windows(2) {
            let at = w[1].path.position(0.0).truncate();
            if w[0].path.position(w[1].t0_s - w[0].t0_s).truncate().distance(at) > 1.0 {
                arrivals.push((w[1].t0_s, at, w[1].path.clone()));
            }
        }
    }
    (street, cfg, plan, arrivals)
}

/// Where the world has doorways, about half of those coming back in come out of one within
/// a spawn radius of the sensor, and walk off; without doorways none do (above). The doorways
/// stand 10 m apart, so one is always within reach (3.6-12 m from the sensor, which drives
/// 10 m from their row).
#[test]
fn people_come_back_in_out_of_doorways() {
    let doors: Vec<crate::scene::world::Place> =
        (0..60).map(|k| crate::scene::world::Place { at: DVec2::new(16.0 + 10.0 * k as f64, 14.0), facing_rad: -std::f64::consts::FRAC_PI_2 }).collect();
    let (_, cfg, plan, arrivals) = coming_back(&doors, 8.0, 8, 60);
    let mut out_of_doors = 0;
    for (t, at, walk) in &arrivals {
        let Some(d) = doors.iter().find(|d| d.at.distance(*at) < 1e-9) else { continue };
        out_of_doors += 1;
        let here = plan.sensor.position(*t).truncate();
        assert!(d.at.distance(here) <= cfg.humans.spawn_radius_m + 1e-9, "{d:?} from {here}");
        // And walk off (not stand in it).
        assert!(walk.position(3.0).truncate().distance(d.at) > 1.0, "{:?}", walk.position(3.0));
    }
    let n = arrivals.len();
    assert!(n >= 20 && out_of_doors * 4 >= n && out_of_doors * 4 <= n * 3, "{out_of_doors} of {n} out of doorways");
}
