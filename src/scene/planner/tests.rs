use super::*;
use crate::geometry::wrap_pi as wrap;
use crate::scene::{EnvMesh, Environment};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// A `w` x `h` m floor from the origin with 1 m high box obstacles `[x0, y0, x1, y1]`.
pub(crate) fn grid(w: f64, h: f64, boxes: &[[f64; 4]], cell_m: f64) -> WalkableGrid {
    WalkableGrid::from_environment(&floor_with_boxes(w, h, boxes, 1.0), cell_m).unwrap()
}

/// The environment of [`grid`], its boxes `height_m` high.
pub(crate) fn floor_with_boxes(w: f64, h: f64, boxes: &[[f64; 4]], height_m: f64) -> Environment {
    let mut env = Environment::default();
    push_quad(&mut env, [0.0, 0.0, w, h]);
    for b in boxes {
        push_box(&mut env, *b, height_m);
    }
    env
}

/// Adds a floor rectangle `[x0, y0, x1, y1]` at z = 0.
fn push_quad(env: &mut Environment, q: [f64; 4]) {
    let b = env.positions.len() as u32;
    env.positions.extend([DVec3::new(q[0], q[1], 0.0), DVec3::new(q[2], q[1], 0.0), DVec3::new(q[2], q[3], 0.0), DVec3::new(q[0], q[3], 0.0)]);
    env.meshes.push(EnvMesh { name: "floor".into(), indices: vec![b, b + 1, b + 2, b, b + 2, b + 3], double_sided: true, reflectance: 0.5, class: 0 });
}

/// Adds a box `[x0, y0, x1, y1]` standing on z = 0, `height_m` high (sides and top).
fn push_box(env: &mut Environment, b: [f64; 4], height_m: f64) {
    let base = env.positions.len() as u32;
    for z in [0.0, height_m] {
        for (x, y) in [(b[0], b[1]), (b[2], b[1]), (b[2], b[3]), (b[0], b[3])] {
            env.positions.push(DVec3::new(x, y, z));
        }
    }
    let mut idx = Vec::new();
    for (a, c) in [(0, 1), (1, 2), (2, 3), (3, 0)] {
        idx.extend([base + a, base + c, base + c + 4, base + a, base + c + 4, base + a + 4]);
    }
    idx.extend([base + 4, base + 5, base + 6, base + 4, base + 6, base + 7]);
    let n = env.meshes.len() - 1;
    env.meshes.push(EnvMesh { name: format!("box{n}"), indices: idx, double_sided: true, reflectance: 0.5, class: 0 });
}

/// Two 10 x 10 m rooms side by side, split by a wall at x = 10 with a door of `door_m`.
fn two_rooms(door_m: f64) -> WalkableGrid {
    grid(20.0, 10.0, &[[9.9, 0.0, 10.1, 5.0 - 0.5 * door_m], [9.9, 5.0 + 0.5 * door_m, 10.1, 10.0]], 0.1)
}

/// A 36 x 24 m hall with a grid of pillars and two rows of shelves.
fn hall() -> WalkableGrid {
    let mut boxes = Vec::new();
    for i in 0..5 {
        for j in 0..3 {
            let (x, y) = (4.0 + 7.0 * i as f64, 4.0 + 8.0 * j as f64);
            boxes.push([x - 0.3, y - 0.3, x + 0.3, y + 0.3]);
        }
    }
    boxes.push([8.0, 9.0, 20.0, 10.0]);
    boxes.push([14.0, 14.0, 30.0, 15.0]);
    grid(36.0, 24.0, &boxes, 0.1)
}

/// Dense check of the whole walk (every cell/10 of arc length) against the clearance.
fn assert_clear(g: &WalkableGrid, path: &WalkPath, c: f64) {
    let ds = g.cell_m / 10.0;
    let n = (path.length_m() / ds).ceil() as usize;
    for k in 0..=n {
        let t = path.duration_s() * k as f64 / n as f64;
        let p = path.position(t).truncate();
        assert!(g.clearance(p) >= c && g.clearance(p) > 0.0, "clearance {} < {c} at {p} (t {t})", g.clearance(p));
    }
}

/// Exact kinematics: derivative, speed, heading, distance, C1 at every join, extrapolation.
fn assert_kinematics(path: &WalkPath) {
    let v = path.speed_mps();
    let h = 1e-6;
    // Central difference error: rounding (~1e-16 * |p| / h, under 1e-8 here), h^2 v^3 k^2 / 6
    // inside an arc, and h v^2 k / 2 where the curvature jumps (at a join or an end).
    let tolerance = |t: f64| {
        let (s0, s1) = (v * (t - h), v * (t + h));
        let near: Vec<&PathPiece> =
            path.pieces().iter().filter(|p| p.start_s_m <= s1 && p.start_s_m + p.length_m >= s0).collect();
        let k = near.iter().map(|p| p.curvature_per_m.abs()).fold(0.0, f64::max);
        let jump = near.len() > 1 || s0 < 0.0 || s1 > path.length_m();
        1e-7 + h * h * v.powi(3) * k * k / 6.0 + if jump { h * v * v * k } else { 0.0 }
    };
    let mut times: Vec<f64> = (0..=400).map(|k| -1.0 + (path.duration_s() + 2.0) * k as f64 / 400.0).collect();
    for p in path.pieces() {
        let t0 = p.start_s_m / v;
        let t1 = (p.start_s_m + p.length_m) / v;
        times.extend([t0, t0 + 1e-9, t0 + 0.5 * (t1 - t0), t1 - 1e-9]);
    }
    for &t in &times {
        let num = (path.position(t + h) - path.position(t - h)) / (2.0 * h);
        let vel = path.velocity(t);
        let tol = tolerance(t);
        assert!((num - vel).length() < tol, "t {t}: d/dt position {num} vs velocity {vel} (tol {tol})");
        assert!((vel.length() - v).abs() < 1e-12, "t {t}: |v| {}", vel.length());
        assert_eq!(vel.z, 0.0);
        assert_eq!(path.position(t).z, 0.0);
        assert!(wrap(path.heading_rad(t) - vel.y.atan2(vel.x)).abs() < 1e-12, "t {t}: heading");
        assert!((path.distance(t) - v * t).abs() < 1e-12);
    }
    // C1 at every join: position and heading continuous across it.
    let pieces = path.pieces();
    for w in pieces.windows(2) {
        let (a, b) = (w[0], w[1]);
        assert!((a.start_s_m + a.length_m - b.start_s_m).abs() < 1e-12);
        assert!(a.end().distance(b.start_m) < 1e-9, "position jump {} at s {}", a.end().distance(b.start_m), b.start_s_m);
        let jump = a.heading(a.length_m) - b.heading0_rad;
        assert!(jump.abs() < 1e-9, "heading jump {jump} at s {}", b.start_s_m);
        let t = b.start_s_m / v;
        let eps = 1e-9;
        let turn = 2.0 * eps * v * a.curvature_per_m.abs().max(b.curvature_per_m.abs());
        assert!((path.heading_rad(t - eps) - path.heading_rad(t + eps)).abs() < turn + 1e-9);
        assert!(path.position(t - eps).distance(path.position(t + eps)) < 3.0 * v * eps);
    }
    // The ends: exact start and goal, then straight lines along the end tangents.
    assert_eq!(path.position(0.0).truncate(), path.start_m());
    assert!(path.position(path.duration_s()).truncate().distance(path.goal_m()) < 1e-12);
    let before = path.position(-2.0) - path.position(0.0);
    assert!((before + 2.0 * path.velocity(0.0)).length() < 1e-12);
    let te = path.duration_s();
    let after = path.position(te + 3.0) - path.position(te);
    assert!((after - 3.0 * path.velocity(te)).length() < 1e-9);
    assert_eq!(path.velocity(-5.0), path.velocity(0.0));
    assert!((path.velocity(te + 5.0) - path.velocity(te)).length() < 1e-12);
}

#[test]
fn kinematics_are_exact_and_c1() {
    let g = hall();
    let mut planner = Planner::new();
    let mut arcs = 0;
    for seed in 0..20 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let path = planner.plan_walk(&mut rng, &g, 0.3, 1.3, 12.0, None).expect("a path in the hall");
        arcs += path.pieces().iter().filter(|p| p.curvature_per_m != 0.0).count();
        assert_kinematics(&path);
    }
    assert!(arcs > 5, "the paths should turn ({arcs} arcs)");
}

/// With a least turn radius (a pusher's walk) every corner is rounded at least that wide and
/// the walk's kinematics stay exact; without it the same hall's walks hold tighter corners.
#[test]
fn a_least_turn_radius_rounds_every_corner_at_least_that_wide() {
    let g = hall();
    let mut planner = Planner::new();
    // The tightest corner of twenty walks' and how many walks were found.
    let tightest = |planner: &mut Planner| {
        let (mut r, mut found) = (f64::INFINITY, 0);
        for seed in 0..20 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            if let Some(path) = planner.plan_walk(&mut rng, &g, 0.3, 1.3, 12.0, None) {
                assert_kinematics(&path);
                found += 1;
                r = path.pieces().iter().filter(|p| p.curvature_per_m != 0.0).map(|p| 1.0 / p.curvature_per_m.abs()).fold(r, f64::min);
            }
        }
        (r, found)
    };
    let (free, _) = tightest(&mut planner);
    assert!(free < 1.2, "the hall's walks round a corner at {free} m");
    planner.min_turn_radius_m = 1.2;
    let (r, found) = tightest(&mut planner);
    assert!(found >= 10 && r >= 1.2 - 1e-9, "{found} walks, a corner of radius {r} m");
}

/// A planner keeps its search grid while it is asked of the same grid and clearance, and
/// builds it anew for another grid of the same size (two doors' widths) or another clearance:
/// each walk is the one a fresh planner plans, whatever was planned before.
#[test]
fn a_reused_planner_plans_what_a_fresh_one_plans_over_any_grid() {
    let (narrow, wide) = (two_rooms(0.9), two_rooms(3.0));
    let mut planner = Planner::new();
    let start = DVec2::new(3.0, 2.0);
    for (k, (g, c)) in [(&narrow, 0.3), (&wide, 0.3), (&wide, 0.4), (&narrow, 0.3), (&narrow, 0.4)].into_iter().enumerate() {
        for seed in 0..3 {
            let reused = planner.plan_walk(&mut ChaCha8Rng::seed_from_u64(seed), g, c, 1.2, 10.0, Some(start));
            let fresh = plan_walk(&mut ChaCha8Rng::seed_from_u64(seed), g, c, 1.2, 10.0, Some(start));
            assert_eq!(reused, fresh, "walk {k}, seed {seed}");
        }
    }
    // The two grids plan differently (through the narrow door or the wide one): the check above
    // would see a search grid kept for the wrong one.
    let through = |g: &WalkableGrid| plan_walk(&mut ChaCha8Rng::seed_from_u64(0), g, 0.3, 1.2, 10.0, Some(start));
    assert_ne!(through(&narrow), through(&wide));
}

#[test]
fn a_door_in_a_wall_is_walked_through_with_clearance() {
    let g = two_rooms(1.2);
    let c = 0.3;
    let start = DVec2::new(3.0, 2.0);
    // 12 m from (3, 2) is outside the left room: every goal is in the right one.
    for seed in 0..8 {
        let path = plan_walk(&mut ChaCha8Rng::seed_from_u64(seed), &g, c, 1.2, 10.0, Some(start)).expect("through the door");
        assert_eq!(path.start_m(), start);
        assert!(path.goal_m().x > 10.0);
        assert!(path.length_m() >= 12.0);
        assert_clear(&g, &path, c);
        assert_kinematics(&path);
        // It crosses the wall's plane inside the door.
        let n = 2000;
        let crossing = (0..n)
            .map(|k| path.position(path.duration_s() * k as f64 / n as f64))
            .find(|p| p.x >= 10.0)
            .unwrap();
        assert!((4.4..5.6).contains(&crossing.y), "crossed at {crossing}");
    }
}

#[test]
fn a_u_shaped_obstacle_forces_a_detour() {
    // A U open towards -x: base at x = 12, arms along y = 6 and y = 14.
    let g = grid(20.0, 20.0, &[[11.8, 6.0, 12.0, 14.0], [6.0, 5.8, 12.0, 6.0], [6.0, 14.0, 12.0, 14.2]], 0.1);
    let c = 0.35;
    let (start, goal) = (DVec2::new(10.0, 10.0), DVec2::new(15.0, 10.0));
    let path = Planner::new().plan_to(&g, c, 1.4, start, goal).expect("around the U");
    assert_eq!(path.start_m(), start);
    assert!(path.goal_m().distance(goal) < 1e-9);
    // Out of the opening (x < 6 - c), round an arm (|y - 10| > 4 + c) and back: over three
    // times the 5 m straight line.
    assert!(path.length_m() > 15.0, "length {}", path.length_m());
    assert!(path.pieces().iter().any(|p| p.start_m.x < 6.0 - c), "leaves through the opening");
    assert!(path.pieces().iter().filter(|p| p.curvature_per_m != 0.0).count() >= 3);
    assert_clear(&g, &path, c);
    assert_kinematics(&path);
    // Sampled walks in the same room keep their clearance too.
    for seed in 0..10 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let path = plan_walk(&mut rng, &g, c, 1.4, 8.0, Some(start)).expect("a walk from inside the U");
        assert!(path.length_m() >= 1.4 * 8.0);
        assert_clear(&g, &path, c);
    }
}

#[test]
fn walks_keep_clearance_in_a_cluttered_hall() {
    let g = hall();
    let mut planner = Planner::new();
    for seed in 0..30 {
        let mut rng = ChaCha8Rng::seed_from_u64(100 + seed);
        let (speed, duration) = (0.8 + 0.05 * seed as f64, 15.0);
        let path = planner.plan_walk(&mut rng, &g, 0.3, speed, duration, None).expect("a walk");
        assert!(path.length_m() >= speed * duration, "{} < {}", path.length_m(), speed * duration);
        assert!(path.start_m().distance(path.goal_m()) >= speed * duration);
        assert_clear(&g, &path, 0.3);
    }
}

#[test]
fn planning_is_reproducible_for_a_seed() {
    let g = hall();
    let a = plan_walk(&mut ChaCha8Rng::seed_from_u64(5), &g, 0.3, 1.2, 10.0, None).unwrap();
    let b = plan_walk(&mut ChaCha8Rng::seed_from_u64(5), &g, 0.3, 1.2, 10.0, None).unwrap();
    // A reused planner gives the same path as a fresh one.
    let mut planner = Planner::new();
    planner.plan_walk(&mut ChaCha8Rng::seed_from_u64(9), &g, 0.3, 1.2, 10.0, None).unwrap();
    let c = planner.plan_walk(&mut ChaCha8Rng::seed_from_u64(5), &g, 0.3, 1.2, 10.0, None).unwrap();
    let d = plan_walk(&mut ChaCha8Rng::seed_from_u64(6), &g, 0.3, 1.2, 10.0, None).unwrap();
    assert_eq!(a, b);
    assert_eq!(a, c);
    assert_ne!(a, d);
}

#[test]
fn disconnected_goals_give_none() {
    // A 0.6 m door (0.15 m clearance at its middle, on this grid) is closed to a person
    // needing 0.4 m, open at 0.1 m.
    let g = two_rooms(0.6);
    let start = DVec2::new(3.0, 5.0);
    for seed in 0..4 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        // Every point 12 m from the start is in the other room.
        assert!(plan_walk(&mut rng, &g, 0.4, 1.2, 10.0, Some(start)).is_none());
        // No start in either room reaches 15 m.
        assert!(plan_walk(&mut rng, &g, 0.4, 1.5, 10.0, None).is_none());
    }
    assert!(Planner::new().plan_to(&g, 0.4, 1.2, start, DVec2::new(16.0, 5.0)).is_none());
    let through = plan_walk(&mut ChaCha8Rng::seed_from_u64(0), &g, 0.1, 1.2, 10.0, Some(start)).expect("open at 0.1 m");
    assert_clear(&g, &through, 0.1);
    // Goals farther than the floor reaches, a blocked start, bad inputs.
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    assert!(plan_walk(&mut rng, &g, 0.2, 1.2, 100.0, None).is_none());
    assert!(plan_walk(&mut rng, &g, 0.2, 1.2, 5.0, Some(DVec2::new(10.0, 1.0))).is_none(), "start in the wall");
    assert!(plan_walk(&mut rng, &g, 0.2, 0.0, 5.0, None).is_none());
    assert!(plan_walk(&mut rng, &g, f64::NAN, 1.0, 5.0, None).is_none());
}

#[test]
fn segment_check_sees_every_touched_cell() {
    // A single blocked cell at (5, 5) in a 10 x 10 grid of 1 m cells.
    let mut clearance_m = vec![1.0f32; 100];
    clearance_m[55] = 0.0;
    let g = WalkableGrid { origin: DVec2::ZERO, cell_m: 1.0, nx: 10, ny: 10, clearance_m, top_cm: Vec::new() };
    assert!(!segment_clear(&g, DVec2::new(0.5, 0.5), DVec2::new(9.5, 9.5), 0.5), "through the cell's centre");
    assert!(!segment_clear(&g, DVec2::new(4.5, 5.99), DVec2::new(9.5, 5.2), 0.5), "clipping its corner");
    assert!(!segment_clear(&g, DVec2::new(4.0, 4.0), DVec2::new(7.0, 7.0), 0.5), "through the corners");
    assert!(!segment_clear(&g, DVec2::new(6.0, 4.0), DVec2::new(4.0, 6.0), 0.5), "a corner diagonal beside it");
    assert!(segment_clear(&g, DVec2::new(0.5, 6.5), DVec2::new(9.5, 6.2), 0.5));
    assert!(segment_clear(&g, DVec2::new(6.5, 0.5), DVec2::new(6.5, 9.5), 0.5));
    assert!(!segment_clear(&g, DVec2::new(0.5, 0.5), DVec2::new(10.5, 0.5), 0.5), "leaves the grid");
    assert!(!segment_clear(&g, DVec2::new(5.5, 5.5), DVec2::new(5.5, 5.5), 0.0), "clearance 0 is never walkable");
    assert!(segment_clear(&g, DVec2::new(4.5, 5.5), DVec2::new(4.5, 5.5), 0.0));
}

#[test]
fn planning_time_in_a_36_by_24_m_hall() {
    let g = hall();
    let mut planner = Planner::new();
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let mut times = Vec::new();
    for _ in 0..50 {
        let t0 = std::time::Instant::now();
        let path = planner.plan_walk(&mut rng, &g, 0.3, 1.4, 15.0, None);
        times.push(t0.elapsed().as_secs_f64() * 1e3);
        assert!(path.is_some());
    }
    times.sort_by(f64::total_cmp);
    let mean = times.iter().sum::<f64>() / times.len() as f64;
    println!(
        "planning in a {} x {} cell hall ({} cells): mean {mean:.2} ms, median {:.2} ms, max {:.2} ms",
        g.nx,
        g.ny,
        g.nx * g.ny,
        times[times.len() / 2],
        times[times.len() - 1]
    );
}

/// The floor in three parts, leaving a 1 m gap (a road) at y 10-11 over x 30-40; a 2 m high
/// box at y 20-21 over x 10-14, a 0.9 m high one at y 20-21 over x 26-30, a 2 m high wall at
/// y 12-12.5 over x 32-38 and a 0.8 m high box there over x 30.5-31.5, just past the road.
fn boxes_and_a_road() -> WalkableGrid {
    let mut env = Environment::default();
    for q in [[0.0, 0.0, 30.0, 40.0], [30.0, 0.0, 40.0, 10.0], [30.0, 11.0, 40.0, 40.0]] {
        push_quad(&mut env, q);
    }
    push_box(&mut env, [10.0, 20.0, 14.0, 21.0], 2.0);
    push_box(&mut env, [26.0, 20.0, 30.0, 21.0], 0.9);
    push_box(&mut env, [32.0, 12.0, 38.0, 12.5], 2.0);
    push_box(&mut env, [30.5, 12.0, 31.5, 12.5], 0.8);
    WalkableGrid::from_environment(&env, 0.1).unwrap()
}

/// `obstacle_behind` sees a tall obstacle behind a point along the line of sight, within the
/// distance asked; not a low one (a bench), not one off the line, not one past a gap in the
/// floor (a road), and nothing in a grid made of clearances alone.
#[test]
fn an_obstacle_behind_is_a_tall_one_on_the_line_of_sight() {
    let g = boxes_and_a_road();
    let eye = DVec2::new(12.0, 2.0);
    assert!(g.obstacle_behind(eye, DVec2::new(12.0, 18.5), 2.0), "1.5 m before the tall box");
    assert!(!g.obstacle_behind(eye, DVec2::new(12.0, 17.0), 2.0), "3 m before it, 2 m asked");
    assert!(g.obstacle_behind(eye, DVec2::new(12.0, 17.0), 3.5), "3 m before it, 3.5 m asked");
    assert!(!g.obstacle_behind(DVec2::new(12.0, 38.0), DVec2::new(12.0, 18.5), 2.0), "the box in front, seen from behind");
    assert!(!g.obstacle_behind(DVec2::new(28.0, 2.0), DVec2::new(28.0, 18.5), 2.0), "1.5 m before the low box");
    assert!(!g.obstacle_behind(DVec2::new(35.0, 2.0), DVec2::new(35.0, 9.5), 3.5), "the road between the person and the wall");
    assert!(g.obstacle_behind(DVec2::new(35.0, 2.0), DVec2::new(35.0, 11.6), 2.0), "past the road, before the wall");
    assert!(!g.obstacle_behind(eye, eye, 2.0), "at the eye itself");
    let bare = WalkableGrid { top_cm: Vec::new(), ..g.clone() };
    assert!(!bare.obstacle_behind(eye, DVec2::new(12.0, 18.5), 2.0), "a grid of clearances alone");
}

/// `low_obstacle_before` sees a low obstacle between a point and the eye, within the distance
/// asked (what hides a person's legs); not a tall one (that hides all of them), not one behind
/// the point, not one past a road, and nothing in a grid made of clearances alone.
#[test]
fn a_low_obstacle_before_is_one_between_the_point_and_the_eye() {
    let g = boxes_and_a_road();
    let eye = DVec2::new(28.0, 2.0);
    assert!(g.low_obstacle_before(eye, DVec2::new(28.0, 22.0), 1.5), "1 m behind the low box");
    assert!(!g.low_obstacle_before(eye, DVec2::new(28.0, 23.0), 1.5), "2 m behind it, 1.5 m asked");
    assert!(g.low_obstacle_before(eye, DVec2::new(28.0, 23.0), 2.5), "2 m behind it, 2.5 m asked");
    assert!(!g.low_obstacle_before(eye, DVec2::new(28.0, 19.0), 1.5), "1 m before it, the box behind");
    assert!(!g.low_obstacle_before(DVec2::new(12.0, 2.0), DVec2::new(12.0, 22.0), 1.5), "1 m behind the tall box");
    assert!(!g.low_obstacle_before(DVec2::new(31.0, 40.0), DVec2::new(31.0, 9.5), 3.5), "the 0.8 m box past the road");
    assert!(g.low_obstacle_before(DVec2::new(31.0, 2.0), DVec2::new(31.0, 13.5), 1.5), "1 m behind the 0.8 m box");
    let bare = WalkableGrid { top_cm: Vec::new(), ..g.clone() };
    assert!(!bare.low_obstacle_before(eye, DVec2::new(28.0, 22.0), 1.5), "a grid of clearances alone");
}

/// `hidden_from` needs a tall obstacle across the lines of sight to a person's middle and both
/// shoulders: behind a 2 m box yes, even past a road; before it, behind a 0.9 m one or half
/// behind the box's edge no; nothing in a grid made of clearances alone.
#[test]
fn hidden_is_behind_something_tall_and_wide() {
    let g = boxes_and_a_road();
    let eye = DVec2::new(12.0, 2.0);
    assert!(g.hidden_from(eye, DVec2::new(12.0, 22.0)), "1 m behind the tall box");
    assert!(g.hidden_from(eye, DVec2::new(12.0, 35.0)), "14 m behind it");
    assert!(!g.hidden_from(eye, DVec2::new(12.0, 18.5)), "before it");
    assert!(!g.hidden_from(eye, DVec2::new(14.2, 23.0)), "half behind its edge");
    assert!(g.hidden_from(eye, DVec2::new(13.7, 23.0)), "all but a hand behind it");
    assert!(!g.hidden_from(DVec2::new(28.0, 2.0), DVec2::new(28.0, 22.0)), "behind the low box");
    assert!(g.hidden_from(DVec2::new(35.0, 2.0), DVec2::new(35.0, 13.5)), "behind the wall past the road");
    assert!(!g.hidden_from(DVec2::new(35.0, 2.0), DVec2::new(35.0, 9.5)), "before the road");
    let bare = WalkableGrid { top_cm: Vec::new(), ..g.clone() };
    assert!(!bare.hidden_from(eye, DVec2::new(12.0, 22.0)), "a grid of clearances alone");
}

#[test]
fn a_leg_walks_to_a_goal_within_its_reach() {
    let g = hall();
    let start = DVec2::new(2.0, 2.0);
    let mut planner = Planner::new();
    for seed in 0..20 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let path = planner.plan_leg(&mut rng, &g, 0.3, 1.2, 5.0, start, 12.0).expect("a goal 6-12 m away");
        let d = path.goal_m().distance(start);
        assert!((6.0..=12.0).contains(&d), "seed {seed}: goal {d} m away");
        assert!(path.length_m() >= 6.0 && path.start_m() == start);
        assert_clear(&g, &path, 0.3);
        assert_kinematics(&path);
        let again = Planner::new().plan_leg(&mut ChaCha8Rng::seed_from_u64(seed), &g, 0.3, 1.2, 5.0, start, 12.0);
        assert_eq!(again.as_ref(), Some(&path), "seed {seed}: a fresh planner plans the same");
    }
    // A reach shorter than the walk, or not finite, and a start in an obstacle give none.
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    assert!(planner.plan_leg(&mut rng, &g, 0.3, 1.2, 5.0, start, 5.9).is_none());
    assert!(planner.plan_leg(&mut rng, &g, 0.3, 1.2, 5.0, start, f64::INFINITY).is_none());
    assert!(planner.plan_leg(&mut rng, &g, 0.3, 1.2, 5.0, DVec2::new(4.0, 4.0), 12.0).is_none(), "start in a pillar");
}

#[test]
fn a_leg_keeps_to_the_start_s_region() {
    // The door is closed to a person needing 0.4 m: from (8, 5) most of the ring of 4-12 m is
    // in the other room. A search for a goal there searches the start's room whole (its cost
    // limit, 36 m of path, is past any cell of the room); after it the goals are drawn in the
    // start's room only, so the next search finds its goal.
    let g = two_rooms(0.6);
    let start = DVec2::new(8.0, 5.0);
    let mut planner = Planner::new();
    let mut failed_first = 0;
    for seed in 0..20 {
        let before = planner.generation;
        let path = planner.plan_leg(&mut ChaCha8Rng::seed_from_u64(seed), &g, 0.4, 1.0, 4.0, start, 12.0).expect("goals in the start's room");
        let searches = planner.generation - before;
        assert!(path.goal_m().x < 10.0, "seed {seed}: goal {} in the other room", path.goal_m());
        assert!(searches <= 2, "seed {seed}: {searches} searches");
        failed_first += usize::from(searches == 2);
        assert_clear(&g, &path, 0.4);
    }
    assert!(failed_first >= 5, "{failed_first} of 20 legs drew a goal in the other room first");
}

#[test]
fn a_search_gives_up_at_its_cost_limit() {
    let open = two_rooms(1.0);
    let cell = |g: &WalkableGrid, p: DVec2| cell_of(g, p).unwrap();
    let (s, goal) = (cell(&open, DVec2::new(3.0, 5.0)), cell(&open, DVec2::new(16.0, 5.0)));
    let mut planner = Planner::new();
    planner.prepare(&open, 0.1);
    // 13 m through the door is 130 cells: at least 130,000 of cost.
    assert_eq!(planner.astar_within(&open, s, goal, 100_000), Search::TooLong);
    assert_eq!(planner.astar_within(&open, s, goal, 200_000), Search::Found);
    let cells = planner.cells.len();
    assert!((130..=150).contains(&cells), "{cells} cells");
    // A closed door: the start's room searched whole, whatever the limit.
    let closed = two_rooms(0.6);
    planner.prepare(&closed, 0.4);
    assert_eq!(planner.astar_within(&closed, s, goal, u64::MAX), Search::Unreachable);
    let searched = planner.closed.iter().filter(|&&c| c == planner.generation).count();
    assert!(searched > 4000 && searched < 10_000, "{searched} cells searched in a 10 x 10 m room");
}

/// A square spiral of 0.1 m walls 0.6 m apart round (5, 5), out to 2.1 m from it, open at
/// its outer end: from its middle every point 3 m away or more is outside it, 29 m of
/// corridor away.
fn spiral() -> WalkableGrid {
    let (mut p, mut boxes) = (DVec2::new(0.3, -0.3), Vec::new());
    let dirs = [DVec2::Y, DVec2::NEG_X, DVec2::NEG_Y, DVec2::X];
    for k in 0..13 {
        let q = p + dirs[k % 4] * 0.6 * (k / 2 + 1) as f64;
        let (lo, hi) = (p.min(q) + DVec2::splat(5.0 - 0.05), p.max(q) + DVec2::splat(5.0 + 0.05));
        boxes.push([lo.x, lo.y, hi.x, hi.y]);
        p = q;
    }
    grid(10.0, 10.0, &boxes, 0.1)
}

#[test]
fn a_leg_gives_up_a_goal_only_a_long_detour_reaches() {
    let g = spiral();
    let middle = DVec2::new(5.0, 5.0);
    let outside = DVec2::new(8.5, 5.0);
    let mut planner = Planner::new();
    // Unbounded, the way out is found: far longer than the straight line.
    let out = planner.plan_to(&g, 0.1, 1.0, middle, outside).expect("the spiral's corridor leads out");
    assert!(out.length_m() > 20.0, "{} m", out.length_m());
    assert_clear(&g, &out, 0.1);
    // Bounded by 3.5 m (a search up to a path costing 10.5 m), it is given up.
    assert!(planner.plan_to_within(&g, 0.1, 1.0, middle, outside, 3.5).is_none());
    assert!(planner.plan_to_within(&g, 0.1, 1.0, middle, outside, 12.0).is_some(), "36 m of search reaches it");
    // Every goal of a leg of 3-3.5 m lies outside: no leg, where a walk without bound has one.
    for seed in 0..5 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        assert!(planner.plan_leg(&mut rng, &g, 0.1, 1.0, 3.0, middle, 3.5).is_none(), "seed {seed}");
        let walk = planner.plan_walk(&mut ChaCha8Rng::seed_from_u64(seed), &g, 0.1, 1.0, 3.0, Some(middle)).expect("a walk out");
        assert!(walk.length_m() > 20.0);
    }
}
