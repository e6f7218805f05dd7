use super::super::*;
use super::SEATED_REACH_M;
use crate::scene::world::{World, WorldKind, WorldParams};
use rand::SeedableRng;

fn bundled(name: &str) -> HumanModel {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/humans").join(name);
    HumanModel::load(&path, true).unwrap()
}

/// `humans.sitting`: in a street of markets (benches, beer gardens) and indoors (benches, a
/// café's chairs), everyone drawn to sit sits on one of the world's seats: on its hip point,
/// facing its way, seated at its height, still, each seat to one person and everyone the
/// separation apart; half of them drawn, about half sit; a model that cannot sit is placed
/// as before; and a share out of 0..1 is refused.
#[test]
fn people_drawn_to_sit_sit_on_the_worlds_seats() {
    let models = [bundled("h1700_w60.glb"), bundled("h1200_w20.glb")];
    let params = WorldParams { duration_s: 0.3, sensor_height_m: 1.73, sensor_speed_mps: [0.0, 2.0], clearance_m: 0.35, markets: 1.0, side_streets: 0.0 };
    for kind in [WorldKind::Street, WorldKind::Indoor] {
        let mut cfg = Config::default();
        cfg.frames = 4;
        cfg.humans.count = [6, 6];
        cfg.humans.spawn_radius_m = 35.0;
        cfg.humans.sitting = 1.0;
        let (mut seated, mut total, mut half) = (0, 0, 0);
        for index in 0..4 {
            let w = World::build(kind, 3, index, &params).unwrap();
            assert!(w.seats.len() >= 4, "{}: {} seats", w.summary(), w.seats.len());
            let inp = PlanInputs { rate_hz: 10.0, grid: Some(&w.grid), models: &models, tracks: &[], sensor: None, floor_z_m: 0.0, sensor_arc: w.sensor, places: &w.places, doors: &w.doors, seats: &w.seats, world: None };
            let plan = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(index as u64), &cfg, &inp).unwrap();
            let s0 = plan.sensor.position(0.0).truncate();
            for (i, p) in plan.humans.iter().enumerate() {
                let at = p.at(0.2);
                let Some(s) = w.seats.iter().find(|s| s.at.distance(at.position_m.truncate()) < 1e-9) else {
                    // Placed as if not drawn: no seat within reach was free of the people
                    // before it and the sensor.
                    let taken = |s: &crate::scene::world::Seat| {
                        plan.times_s.iter().any(|&t| {
                            let mid = s.at + SEATED_REACH_M * DVec2::new(s.facing_rad.cos(), s.facing_rad.sin());
                            mid.distance(plan.sensor.position(t).truncate()) < cfg.humans.min_separation_m
                                || plan.humans[..i].iter().any(|q| q.footprint_m(t).distance(mid) < cfg.humans.min_separation_m)
                        })
                    };
                    let free = w.seats.iter().filter(|s| s.at.distance(s0) <= cfg.humans.spawn_radius_m && !taken(s)).count();
                    assert_eq!(free, 0, "{kind:?} {index}: person {i} at {} on no seat, {free} free", at.position_m);
                    assert_eq!(p.seat_m, 0.0);
                    continue;
                };
                assert_eq!((at.heading_rad, at.seat_m, at.velocity_mps), (s.facing_rad, s.top_z_m, glam::DVec3::ZERO));
                assert_eq!((at.style().seat_m, at.style().feet_room_m), (s.top_z_m as f32, s.feet_room_m as f32));
                // The others keep their distance from the middle of its folded body.
                for q in &plan.humans[..i] {
                    for &t in &plan.times_s {
                        assert!(q.footprint_m(t).distance(p.footprint_m(t)) >= cfg.humans.min_separation_m);
                    }
                }
                seated += 1;
            }
            total += plan.humans.len();
            let mut c = cfg.clone();
            c.humans.sitting = 0.5;
            let plan = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(index as u64), &c, &inp).unwrap();
            half += plan.humans.iter().filter(|p| p.seat_m > 0.0).count();
            // A model that cannot sit is placed as if not drawn to.
            let tiny = [crate::human::tests_support::tiny_model()];
            let plan = sample_plan(&mut rand_chacha::ChaCha8Rng::seed_from_u64(index as u64), &cfg, &PlanInputs { models: &tiny, ..inp }).unwrap();
            assert!(plan.humans.len() == 6 && plan.humans.iter().all(|p| p.seat_m == 0.0));
        }
        assert!(seated * 10 >= total * 9, "{kind:?}: {seated} of {total} seated");
        assert!((6..=18).contains(&half), "{kind:?}: {half} of 24 seated at 0.5");
    }
    for bad in [1.5, -0.1, f64::NAN] {
        let mut cfg = Config::default();
        cfg.humans.sitting = bad;
        assert!(cfg.validate().is_err(), "{bad}");
    }
}
