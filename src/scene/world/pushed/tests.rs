use super::*;
use crate::scene::world::tests::{obstacles, params};
use crate::human::HumanModel;
use crate::scene::Trajectory;
use std::f64::consts::TAU;

fn bundled(name: &str) -> HumanModel {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/humans").join(name);
    HumanModel::load(&path, true).unwrap()
}

fn inside(p: DVec2, t: &[DVec2; 3]) -> bool {
    let s = |a: DVec2, b: DVec2| (b - a).perp_dot(p - a);
    let (d0, d1, d2) = (s(t[0], t[1]), s(t[1], t[2]), s(t[2], t[0]));
    (d0 >= 0.0 && d1 >= 0.0 && d2 >= 0.0) || (d0 <= 0.0 && d1 <= 0.0 && d2 <= 0.0)
}

/// The path's velocity and turning rate are the derivatives of its pose (central differences
/// inside a step), and the pose is held outside the rows with both rates 0; at a cut the pose
/// jumps, the rates on either side are their segments'. A heading read back into (-pi, pi] (a
/// recorded track's) is unwrapped: a walk around a circle turns the thing on smoothly; a walker
/// taken to another place takes it along.
#[test]
fn a_pushed_path_moves_as_its_rates_say() {
    let f = |t: f64| [t.sin(), 0.5 * t * t, 0.1 * t, 3.0 - 2.0 * t];
    let mut table: Vec<[f64; 5]> = Vec::new();
    for k in 0..40 {
        let t = -0.5 + k as f64 * STEP_S;
        let g = f(t);
        // A cut at row 20: 10 m further on from there.
        table.push([t, g[0] + if k > 20 { 10.0 } else { 0.0 }, g[1], g[2], g[3]]);
        if k == 20 {
            table.push([t, g[0] + 10.0, g[1], g[2], g[3]]);
        }
    }
    let shift = |t: f64| if t >= -0.5 + 20.0 * STEP_S { 10.0 } else { 0.0 };
    let p = PushedPath::new(0, table);
    for k in 0..200 {
        let t = -0.49 + k as f64 * 0.0097;
        let u = (t + 0.5) / STEP_S;
        if u.fract() < 0.02 || u.fract() > 0.98 {
            continue;
        }
        let h = 1e-5;
        let ((a, ha), (b, hb)) = (p.pose(t - h), p.pose(t + h));
        let (v, w) = p.rates(t);
        assert!(((b - a) / (2.0 * h) - v).length() < 1e-6 && ((hb - ha) / (2.0 * h) - w).abs() < 1e-6, "t {t}: {v} {w}");
        let g = f(t);
        assert!((p.pose(t).0.x - shift(t) - g[0]).abs() < 0.01, "t {t}: off the curve");
    }
    let cut = -0.5 + 20.0 * STEP_S;
    assert_eq!(p.pose(cut).0.x, f(cut)[0] + 10.0, "from the cut on, the later row");
    assert!((p.pose(cut - 1e-9).0.x - f(cut)[0]).abs() < 1e-6, "before it, the earlier");
    assert!(p.rates(cut).0.length() < 5.0 && p.rates(cut - 1e-9).0.length() < 5.0, "no rate across the cut");
    assert_eq!(p.pose(-3.0), p.pose(-0.5));
    assert_eq!(p.pose(30.0), p.pose(-0.5 + 39.0 * STEP_S));
    assert_eq!(p.rates(-3.0), (DVec3::ZERO, 0.0));
    assert_eq!(p.rates(30.0), (DVec3::ZERO, 0.0));
    let handle = PushHandle { forward_m: 0.3, height_m: 1.0, half_width_m: 0.2 };
    let spec = stroller(&mut rand_chacha::ChaCha8Rng::seed_from_u64(1), &handle);
    // Around a circle of 3 m at 1.5 m/s, the heading given wrapped.
    let at = |_: usize, t: f64| {
        let a = 0.5 * t;
        let h = crate::geometry::wrap_pi(a + std::f64::consts::FRAC_PI_2);
        Walker { position_m: DVec3::new(3.0 * a.cos(), 3.0 * a.sin(), 0.0), heading_rad: h, speed_mps: 1.5, footprint_m: DVec2::ZERO }
    };
    let path = push_path(0, &at, &[], &handle, &spec, 0.0, 400);
    for k in 0..399 {
        let (v, w) = path.segment_rates(k);
        assert!((w - 0.5).abs() < 1e-9 && (v.length() - 0.5 * (9.0 + (0.3 + spec.handle_behind_m).powi(2)).sqrt()).abs() < 1e-3, "row {k}: {v} {w}");
    }
    // Taken 40 m along x at 7.3 s: the rows there twice, the thing with the walker on both sides.
    let jump = |_: usize, t: f64| {
        let mut w = at(0, t);
        if t >= 7.3 {
            w.position_m.x += 40.0;
        }
        w
    };
    let path = push_path(0, &jump, &[7.3], &handle, &spec, 0.0, 400);
    assert_eq!(path.rows(), 401, "the step at the cut replaced by its two rows");
    let ahead = 0.3 + spec.handle_behind_m;
    for t in [7.2, 7.3 - 1e-3, 7.3, 7.31, 9.0] {
        let (c, h) = path.pose(t);
        let w = jump(0, t);
        let want = w.position_m.truncate() + ahead * DVec2::new(w.heading_rad.cos(), w.heading_rad.sin());
        assert!(c.truncate().distance(want) < 1e-3 && (h - w.heading_rad).sin().abs() < 1e-3, "t {t}: {c} against {want}");
    }
    assert!((0..path.rows() - 1).all(|k| path.segment_rates(k).0.length() < 2.0), "no segment across the cut moves it");
}

/// People walking and turning through built worlds, a child and standing people among them:
/// every stroller or trolley kept is an adult's (one who can push), the only pushed thing of
/// its pusher, held the same distance ahead at the pusher's heading, and at every tenth of a
/// second its footprint (checked densely) is off every obstacle of the world and off every
/// other person and the street's sensor vehicle, the other things apart; nobody turning on the
/// spot pushes. Both outcomes occur (the rules bite), and the same seed keeps the same.
#[test]
fn pushed_things_keep_clear_of_the_world_the_people_and_each_other() {
    let (adult, child) = (bundled("h1700_w60.glb"), bundled("h1200_w20.glb"));
    let duration = 8.0;
    let (mut kept, mut dropped) = (0, 0);
    for kind in [WorldKind::Street, WorldKind::Indoor] {
        for index in 0..3 {
            let make = || {
                let mut w = World::build(kind, 5, index, &params()).unwrap();
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(index as u64 + 10);
                let people: Vec<Trajectory> = (0..14)
                    .map(|n| {
                        let start = w.grid.sample_free(&mut rng, 0.5).unwrap();
                        let (speed, yaw) = match n % 7 {
                            5 => (0.0, 0.3),
                            6 => (0.0, 0.0),
                            _ => (uni(&mut rng, 0.8, 1.5), uni(&mut rng, -0.25, 0.25)),
                        };
                        Trajectory { start_m: start, z_m: 0.0, heading0_rad: uni(&mut rng, 0.0, TAU), speed_mps: speed, yaw_rate_rps: yaw }
                    })
                    .collect();
                let handles: Vec<_> = (0..people.len()).map(|n| if n % 4 == 3 { child.push_handle() } else { adult.push_handle() }).collect();
                let before = obstacles(&w.env);
                let at = |i: usize, t: f64| {
                    let p = &people[i];
                    Walker { position_m: p.position(t), heading_rad: p.heading_rad(t), speed_mps: p.speed_mps, footprint_m: p.position(t).truncate() }
                };
                let pushers = w.add_pushed(&handles, at, |_| Vec::new(), duration, |_| None);
                (w, people, handles, before, pushers)
            };
            let (w, people, handles, before, pushers) = make();
            let (again, _, _, _, pushers_again) = make();
            assert_eq!(pushers, pushers_again);
            assert_eq!(w.env.positions, again.env.positions, "{kind:?} {index}: the same seed, the same things");
            assert_eq!(w.movers.len(), pushers.len(), "{kind:?} {index}");
            let movers_kind = if kind == WorldKind::Street { MoverKind::Stroller } else { MoverKind::Trolley };
            for (m, &i) in w.movers.iter().zip(&pushers) {
                let MoverPath::Pushed(path) = &m.path else { panic!("only pushed things") };
                assert!(m.kind == movers_kind && path.pusher == i && handles[i].is_some() && i % 7 != 5, "{kind:?} {index}: mover of {i}");
                let p = &people[i];
                let ahead = m.position(0.0).truncate().distance(p.position(0.0).truncate());
                // The obstacles whose bounds come within a metre of where the thing goes.
                let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
                for k in 0..=80 {
                    lo = lo.min(m.position(k as f64 * 0.1).truncate());
                    hi = hi.max(m.position(k as f64 * 0.1).truncate());
                }
                let near: Vec<&[DVec2; 3]> = before
                    .iter()
                    .filter(|t| {
                        let (a, b) = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
                        a.x < hi.x + 1.0 && a.y < hi.y + 1.0 && b.x > lo.x - 1.0 && b.y > lo.y - 1.0
                    })
                    .collect();
                for k in 0..=80 {
                    let t = k as f64 * 0.1;
                    let (c, h) = (m.position(t).truncate(), m.heading_rad(t));
                    let want = p.position(t).truncate() + ahead * DVec2::new(p.heading_rad(t).cos(), p.heading_rad(t).sin());
                    assert!(c.distance(want) < 1e-3 && crate::geometry::wrap_pi(h - p.heading_rad(t)).abs() < 1e-6, "{kind:?} {index} t {t}: not at the hands");
                    let (ax, ay) = (DVec2::new(h.cos(), h.sin()), DVec2::new(-h.sin(), h.cos()));
                    for a in -10..=10 {
                        for b in -6..=6 {
                            let q = c + ax * (m.half.x * a as f64 / 10.0) + ay * (m.half.y * b as f64 / 6.0);
                            assert!(!near.iter().any(|tri| inside(q, tri)), "{kind:?} {index} t {t}: the footprint of {i}'s thing on an obstacle at {q}");
                        }
                    }
                    for (j, o) in people.iter().enumerate().filter(|&(j, _)| j != i) {
                        assert!(!m.touches(t, o.position(t).truncate()), "{kind:?} {index} t {t}: {i}'s thing touches {j}");
                    }
                    if let Some(s) = w.sensor {
                        let ego = crate::scene::world::movers::EGO_HALF_M;
                        assert!(!m.overlaps(t, s.position(t).truncate(), ego), "{kind:?} {index} t {t}: {i}'s thing on the sensor's vehicle");
                    }
                    for o in w.movers.iter().filter(|o| !std::ptr::eq(*o, m)) {
                        assert!(o.position(t).distance(m.position(t)) > o.half.length() + m.half.length());
                    }
                }
            }
            kept += pushers.len();
            let walking = |i: &usize| handles[*i].is_some() && i % 7 < 5;
            dropped += (0..people.len()).filter(|i| walking(i) && !pushers.contains(i)).count();
        }
    }
    assert!(kept >= 4 && dropped >= 4, "kept {kept}, dropped {dropped}");
}
