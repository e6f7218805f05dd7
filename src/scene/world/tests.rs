use super::street::ROAD_Z;
use std::path::Path;
use std::sync::Arc;
use super::*;

pub(super) fn params() -> WorldParams {
    WorldParams { duration_s: 3.0, sensor_height_m: 1.73, sensor_speed_mps: [2.0, 8.0], clearance_m: 0.35, markets: crate::config::DEFAULT_MARKETS, side_streets: crate::config::DEFAULT_SIDE_STREETS }
}

/// Obstacle triangles (between 5 cm and 2 m, as the walkable area counts them) as xy triangles.
pub(super) fn obstacles(env: &Environment) -> Vec<[DVec2; 3]> {
    env.triangles()
        .filter(|t| {
            let zmin = t.iter().map(|p| p.z).fold(f64::INFINITY, f64::min);
            let zmax = t.iter().map(|p| p.z).fold(f64::NEG_INFINITY, f64::max);
            let floor = zmax.abs() <= 0.05 && zmin.abs() <= 0.05;
            !floor && zmax > 0.05 && zmin < 2.0
        })
        .map(|t| t.map(|p| p.truncate()))
        .collect()
}

fn digest(env: &Environment) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for p in &env.positions {
        p.x.to_bits().hash(&mut h);
        p.y.to_bits().hash(&mut h);
        p.z.to_bits().hash(&mut h);
    }
    for m in &env.meshes {
        m.indices.hash(&mut h);
        m.class.hash(&mut h);
    }
    h.finish()
}

#[test]
fn layouts_differ_between_sequences_and_repeat_for_a_seed() {
    for kind in [WorldKind::Street, WorldKind::Indoor] {
        let a = World::build(kind, 7, 0, &params()).unwrap();
        let again = World::build(kind, 7, 0, &params()).unwrap();
        let other = World::build(kind, 7, 1, &params()).unwrap();
        let seed = World::build(kind, 8, 0, &params()).unwrap();
        assert_eq!(digest(&a.env), digest(&again.env), "{kind:?}: same seed and index");
        assert_eq!(a.sensor, again.sensor);
        assert_ne!(digest(&a.env), digest(&other.env), "{kind:?}: another sequence");
        assert_ne!(digest(&a.env), digest(&seed.env), "{kind:?}: another seed");
        assert_eq!(a, again);
        assert_ne!(a, other);
    }
}

/// Each material of a built world (a mesh, its things all over the world) draws a block of
/// vertices of its own: the draws' vertex ranges tile the world's positions once, so a frame
/// poses and copies each vertex once. With the vertices in the order the shapes were built,
/// each material's range spanned the whole world, and a frame posed it once per material.
#[test]
fn each_material_draws_a_block_of_vertices_of_its_own() {
    for kind in [WorldKind::Street, WorldKind::Indoor] {
        let w = World::build(kind, 7, 0, &params()).unwrap();
        let mut ranges: Vec<(usize, usize)> = w.env.draws().iter().map(|d| (d.first_vertex, d.first_vertex + d.vertex_count)).collect();
        assert!(ranges.len() >= 10, "{kind:?}: {} materials", ranges.len());
        ranges.sort_unstable();
        let mut end = 0;
        for (a, b) in ranges {
            assert_eq!(a, end, "{kind:?}: a draw's vertices start at {a}, the last ended at {end}");
            end = b;
        }
        assert_eq!(end, w.env.positions.len(), "{kind:?}: every vertex drawn once");
    }
}

#[test]
fn worlds_are_full_of_things_of_human_size_and_carry_classes() {
    let human_sized = ["bollard", "bin", "bush", "cabinet", "kiosk", "parking meter", "planter", "post box", "mannequin", "plant", "coat stand", "info stand", "display case", "shelf", "sculpture", "ticket machine", "vending machine"];
    let mut trucks = 0;
    for kind in [WorldKind::Street, WorldKind::Indoor] {
        for index in 0..4 {
            let w = World::build(kind, 3, index, &params()).unwrap();
            // Streets park box trucks among their cars, as SemanticKITTI's trucks.
            let parked = w.counts.get("parked truck").copied().unwrap_or(0);
            assert_eq!(parked > 0, w.env.meshes.iter().any(|m| m.class == 18), "{}", w.summary());
            trucks += parked;
            let n: usize = w.counts.iter().filter(|(k, _)| human_sized.contains(k)).map(|(_, n)| n).sum();
            assert!(n >= 20, "{kind:?} {index}: {n} things of human size: {}", w.summary());
            let known = [10, 11, 18, 40, 48, 49, 50, 51, 52, 60, 70, 71, 72, 80, 81, 99];
            for m in &w.env.meshes {
                assert!(known.contains(&m.class), "{}: class {}", m.name, m.class);
                assert!((0.04..=1.0).contains(&m.reflectance), "{}", m.name);
            }
            // Reflectances overlap people's (clothes 0.05-0.7): dark and bright things both.
            let r: Vec<f32> = w.env.meshes.iter().filter(|m| m.class == 99).map(|m| m.reflectance).collect();
            assert!(r.iter().any(|&x| x <= 0.2) && r.iter().any(|&x| x >= 0.6), "{kind:?} {index}: {r:?}");
        }
    }
    assert!(trucks >= 2, "{trucks} parked trucks in four streets");
}

/// Markets: stalls, pavilions and table sets (class 52 and 99) whose roofs and parasols are above 2 m, so
/// that people stand under them, close by the counters and benches (the band
/// `humans.by_things` draws from).
#[test]
fn markets_have_stalls_and_room_to_stand_among_them_under_their_roofs() {
    let mut markets = 0;
    let mut under = 0;
    for index in 0..12 {
        let w = World::build(WorldKind::Street, 5, index, &params()).unwrap();
        if w.counts.get("market").is_none() {
            continue;
        }
        markets += 1;
        assert!(["stall", "booth", "table set", "pavilion"].iter().any(|k| w.counts.contains_key(k)), "{}", w.summary());
        let roofs: Vec<[DVec2; 3]> = w
            .env
            .meshes
            .iter()
            .filter(|m| m.class == things::class::OTHER_STRUCTURE)
            .flat_map(|m| m.indices.chunks(3).map(|t| t.iter().map(|&i| w.env.positions[i as usize]).collect::<Vec<_>>()))
            .filter(|t| t.iter().all(|p| p.z >= 2.0))
            .map(|t| [t[0].truncate(), t[1].truncate(), t[2].truncate()])
            .collect();
        assert!(!roofs.is_empty(), "{}", w.summary());
        let g = &w.grid;
        let band = 0.35..=0.35 + crate::config::BY_THING_M;
        for j in 0..g.ny {
            for i in 0..g.nx {
                let c = g.clearance_m[j * g.nx + i] as f64;
                if !band.contains(&c) {
                    continue;
                }
                let p = g.origin + DVec2::new((i as f64 + 0.5) * g.cell_m, (j as f64 + 0.5) * g.cell_m);
                if roofs.iter().any(|t| crate::scene::dist_point_triangle_2d(p, t) == 0.0) {
                    under += 1;
                }
            }
        }
    }
    assert!(markets >= 2, "{markets} streets of twelve with a market");
    assert!(under > 50, "{under} cells to stand in by things, under roofs and parasols");
    // `scene.markets` is the share of lots: none, or every one.
    for (share, want) in [(0.0, false), (1.0, true)] {
        let w = World::build(WorldKind::Street, 5, 0, &WorldParams { markets: share, ..params() }).unwrap();
        assert_eq!(w.counts.contains_key("market"), want, "{}", w.summary());
        let others = ["building", "alley", "plaza", "green slope"].iter().any(|k| w.counts.contains_key(k));
        assert_eq!(others, !want, "{}", w.summary());
    }
}

#[test]
fn people_have_room_and_the_walkable_area_is_clear_of_every_obstacle() {
    let side_streets = WorldParams { side_streets: 0.4, ..params() };
    for (kind, p) in [(WorldKind::Street, params()), (WorldKind::Indoor, params()), (WorldKind::Street, side_streets)] {
        let w = World::build(kind, 11, 2, &p).unwrap();
        let obs = obstacles(&w.env);
        assert!(w.grid.free_fraction(0.35) > 0.02, "{kind:?}: {}", w.grid.free_fraction(0.35));
        // Every cell with clearance c is at least c - one cell from every obstacle triangle.
        let g = &w.grid;
        let mut checked = 0;
        for j in (0..g.ny).step_by(7) {
            for i in (0..g.nx).step_by(7) {
                let c = g.clearance_m[j * g.nx + i] as f64;
                if c < 0.35 {
                    continue;
                }
                let p = g.origin + DVec2::new((i as f64 + 0.5) * g.cell_m, (j as f64 + 0.5) * g.cell_m);
                let d = obs.iter().map(|t| crate::scene::dist_point_triangle_2d(p, t)).fold(f64::INFINITY, f64::min);
                assert!(d >= c - g.cell_m, "{kind:?}: clearance {c} at {p} but an obstacle at {d}");
                checked += 1;
            }
        }
        assert!(checked > 100, "{kind:?}: {checked}");
    }
}

#[test]
fn the_street_sensor_drives_its_lane_clear_of_parked_cars() {
    for index in 0..6 {
        let w = World::build(WorldKind::Street, 5, index, &params()).unwrap();
        let s = w.sensor.expect("the street sets the sensor's path");
        assert!((s.z_m - (ROAD_Z + 1.73)).abs() < 1e-12);
        assert!((2.0..8.0).contains(&s.speed_mps) && s.yaw_rate_rps == 0.0);
        // Nothing of the world higher than a raised crossing (z = 0, driven over) and lower
        // than the sensor within 1 m of its path, over the whole run.
        let solid: Vec<[DVec3; 3]> = w.env.triangles().filter(|t| t.iter().any(|p| p.z > 0.05)).collect();
        for k in 0..=10 {
            let p = s.position(3.0 * k as f64 / 10.0).truncate();
            for t in &solid {
                let d = crate::scene::dist_point_triangle_2d(p, &t.map(|v| v.truncate()));
                let low = t.iter().map(|v| v.z).fold(f64::INFINITY, f64::min);
                assert!(d > 1.0 || low > s.z_m, "sequence {index}: something at {d:.2} m of the sensor at {p}");
            }
        }
        // The street runs at least MARGIN_M past both ends of the run.
        let (a, b) = (s.position(0.0).x, s.position(3.0).x);
        assert!(w.bounds.0.x <= a.min(b) - street::MARGIN_M + 1e-9 && w.bounds.1.x >= a.max(b) + street::MARGIN_M - 1e-9);
    }
}

#[test]
fn both_sidewalks_are_one_walkable_area() {
    // The crossings join them: free cells on both sides of the road.
    for index in 0..4 {
        let w = World::build(WorldKind::Street, 9, index, &params()).unwrap();
        let g = &w.grid;
        let (mut left, mut right) = (0, 0);
        for j in 0..g.ny {
            for i in 0..g.nx {
                if g.clearance_m[j * g.nx + i] >= 0.35 {
                    let y = g.origin.y + (j as f64 + 0.5) * g.cell_m;
                    if y > 0.0 { left += 1 } else { right += 1 }
                }
            }
        }
        assert!(left > 1000 && right > 1000, "sequence {index}: {left} free cells left, {right} right");
    }
}

/// `scene.side_streets` opens side streets off the street: sidewalks reaching farther from the
/// road than any other lot's floor (none past 38 m from the street's middle without them),
/// part of the one walkable area (it keeps its largest connected region only), floored at the
/// sidewalks' level; a share of 1 makes every lot a side street.
#[test]
fn side_streets_lead_off_the_street_with_sidewalks_to_walk() {
    let far = |w: &World| {
        let g = &w.grid;
        let mut cells = Vec::new();
        for j in (0..g.ny).step_by(3) {
            for i in (0..g.nx).step_by(3) {
                let p = g.origin + DVec2::new((i as f64 + 0.5) * g.cell_m, (j as f64 + 0.5) * g.cell_m);
                if p.y.abs() > 38.0 && g.clearance_m[j * g.nx + i] >= 0.35 {
                    cells.push(p);
                }
            }
        }
        cells
    };
    let (mut streets, mut deep) = (0, 0);
    for index in 0..4 {
        let plain = World::build(WorldKind::Street, 13, index, &params()).unwrap();
        assert!(!plain.counts.contains_key("side street"), "{}", plain.summary());
        assert!(far(&plain).is_empty(), "sequence {index}: floor {:?} far from the road", far(&plain).first());
        let w = World::build(WorldKind::Street, 13, index, &WorldParams { side_streets: 0.4, ..params() }).unwrap();
        streets += w.counts.get("side street").copied().unwrap_or(0);
        let cells = far(&w);
        for p in cells.iter().step_by(97) {
            let chest = p.extend(1.3);
            assert_eq!(first_hit(&w.env, chest, DVec3::NEG_Z, 2.0).map(|h| (h * 1e6).round() / 1e6), Some(1.3), "sequence {index}: {p}: not on the sidewalk's level");
        }
        deep += cells.len();
    }
    assert!(streets >= 4 && deep > 1000, "{streets} side streets, {deep} walkable cells past 38 m");
    let w = World::build(WorldKind::Street, 13, 0, &WorldParams { markets: 0.0, side_streets: 1.0, ..params() }).unwrap();
    assert!(w.counts["side street"] >= 10, "{}", w.summary());
    for other in ["alley", "plaza", "green slope", "market"] {
        assert!(!w.counts.contains_key(other), "{other}: {}", w.summary());
    }
}

#[test]
fn world_names_are_exact() {
    assert_eq!(WorldKind::of_background(Path::new("street")), Some(WorldKind::Street));
    assert_eq!(WorldKind::of_background(Path::new("indoor")), Some(WorldKind::Indoor));
    for p in ["./street", "street.glb", "Street", "", "data/street"] {
        assert_eq!(WorldKind::of_background(Path::new(p)), None, "{p}");
    }
}

/// A street's lane and a person standing in the middle of its first crossing ahead of the
/// oncoming traffic, for the whole of `duration` s, and the world with its movers driven.
fn street_with_a_person_on_a_crossing(seed: u64, index: usize, duration: f64) -> (World, DVec2) {
    let p = WorldParams { duration_s: duration, ..params() };
    let mut w = World::build(WorldKind::Street, seed, index, &p).unwrap();
    let lane = w.traffic[0].lane.clone();
    let s = w.sensor.unwrap().position(0.5 * duration).x;
    // The crossing nearest the sensor halfway through.
    let c = lane.crossings.iter().min_by(|a, b| (a.0 - s).abs().total_cmp(&(b.0 - s).abs())).unwrap();
    let person = DVec2::new(c.0, lane.y);
    w.add_movers(duration, |_, out| {
        out.clear();
        out.push(person);
    });
    (w, person)
}

/// Mover `i` and each later one in its lane have their footprints apart along it at `t_s`.
fn assert_apart_in_lane(movers: &[Mover], i: usize, t_s: f64, sequence: usize) {
    let m = &movers[i];
    let lane = &m.lane().unwrap().lane;
    for o in movers[i + 1..].iter().filter(|o| o.lane().is_some_and(|l| Arc::ptr_eq(&l.lane, lane))) {
        let gap = (lane.u_of(o.position(t_s).x) - lane.u_of(m.position(t_s).x)).rem_euclid(lane.length());
        let gap = gap.min(lane.length() - gap);
        assert!(gap > m.half.x + o.half.x, "sequence {sequence}: movers {gap:.2} m apart at {t_s} s");
    }
}

/// An indoor world with a service aisle, its hall's x range and a person standing in the
/// aisle in the middle of the hall for the whole of `duration` s, the movers driven; None for
/// a hall without an aisle.
fn hall_with_a_person_in_the_aisle(seed: u64, index: usize, duration: f64) -> Option<(World, (f64, f64), DVec2)> {
    let p = WorldParams { duration_s: duration, ..params() };
    let mut w = World::build(WorldKind::Indoor, seed, index, &p).unwrap();
    let lane = w.traffic.first()?.lane.clone();
    let end = indoor::WALL_M + indoor::BEHIND_WALL_M;
    let hall = (lane.x0 + end, lane.x1 - end);
    let person = DVec2::new(0.5 * (hall.0 + hall.1), lane.y);
    w.add_movers(duration, |_, out| {
        out.clear();
        out.push(person);
    });
    Some((w, hall, person))
}

#[test]
fn movers_velocities_are_the_derivatives_of_their_positions() {
    let (w, _) = street_with_a_person_on_a_crossing(4, 1, 30.0);
    assert!(w.movers.len() >= 2, "{}", w.summary());
    let (indoor, _, _) = hall_with_a_person_in_the_aisle(4, 0, 30.0).unwrap();
    assert!(!indoor.movers.is_empty(), "{}", indoor.summary());
    let h = 1e-4;
    let mut checked = 0;
    for m in w.movers.iter().chain(&indoor.movers) {
        for k in 0..600 {
            let t = 0.05 * k as f64 + 0.0123;
            let (a, b) = (m.position(t - h), m.position(t + h));
            // Not across the lane's wrap or a ramp's edge (where the slope, and so the
            // vertical speed, changes).
            if (b - a).length() > 1.0 || m.lane().unwrap().lane.ground(a.x).1 != m.lane().unwrap().lane.ground(b.x).1 {
                continue;
            }
            let fd = (b - a) / (2.0 * h);
            let v = m.velocity(t);
            assert!((fd - v).length() < 1e-4 * (1.0 + v.length()), "{:?} at {t}: {fd} vs {v}", m.kind);
            // Level, along the lane, and on the ground under it.
            assert!(v.y == 0.0 && (m.position(t).z - m.lane().unwrap().lane.ground(m.position(t).x).0).abs() < 1e-12);
            checked += 1;
        }
    }
    assert!(checked > 1000, "{checked}");
}

#[test]
fn movers_stop_for_a_person_on_a_crossing_and_keep_their_distance() {
    let mut stopped = 0;
    for index in 0..4 {
        let (w, person) = street_with_a_person_on_a_crossing(6, index, 40.0);
        assert!(w.movers.iter().any(|m| m.kind == MoverKind::Car) && w.movers.iter().any(|m| m.kind == MoverKind::Cyclist), "{}", w.summary());
        for k in 0..=800 {
            let t = 0.05 * k as f64;
            for (i, m) in w.movers.iter().enumerate() {
                let c = m.position(t).truncate();
                // Never over the person (a footprint grown by the person's radius).
                let d = (person - c).abs();
                assert!(d.x >= m.half.x + movers::PERSON_RADIUS_M || d.y >= m.half.y + movers::PERSON_RADIUS_M, "sequence {index}: {:?} {i} on the person at {t} s", m.kind);
                // Never into the one ahead in its lane: footprints apart along the lane.
                assert_apart_in_lane(&w.movers, i, t, index);
            }
        }
        // Traffic queues before the blocked crossing: somebody stands still there at the end.
        if w.movers.iter().any(|m| m.velocity(40.0).length() == 0.0) {
            stopped += 1;
        }
    }
    assert!(stopped >= 3, "movers that stopped for the person: {stopped} of 4 streets");
}

/// Cars in the sensor's lane drive its way on its lane's centre line, and never into the
/// sensor's vehicle: those behind it keep their distance (the ones that catch up follow it),
/// one it would run into is left out; over eight streets some are kept, ahead and behind.
#[test]
fn cars_in_the_sensors_lane_keep_clear_of_its_vehicle() {
    let (mut ahead, mut behind, mut following) = (0, 0, 0);
    for index in 0..8 {
        let duration = 20.0;
        let mut w = World::build(WorldKind::Street, 21, index, &WorldParams { duration_s: duration, ..params() }).unwrap();
        let own = w.traffic[1].lane.clone();
        let sensor = w.sensor.unwrap();
        assert_eq!(own.y, sensor.position(0.0).y);
        assert_eq!(own.dir, sensor.velocity(0.0).x.signum());
        w.add_movers(duration, |_, out| out.clear());
        let mine: Vec<_> = w.movers.iter().filter(|m| m.lane().is_some_and(|l| Arc::ptr_eq(&l.lane, &own))).collect();
        assert_eq!(mine.len(), w.counts.get("car in the sensor lane").copied().unwrap_or(0), "{}", w.summary());
        for m in &mine {
            assert_eq!((m.kind, m.lane().unwrap().y), (MoverKind::Car, own.y));
            for k in 0..=400 {
                let t = 0.05 * k as f64;
                let s = sensor.position(t).truncate();
                assert!(!m.overlaps(t, s, movers::EGO_HALF_M), "sequence {index}: a car on the sensor's vehicle at {t} s");
                assert!(m.velocity(t).x * own.dir >= 0.0);
            }
            // Where they start: ahead of the sensor's vehicle or behind it, within view.
            let d0 = (m.position(0.0).x - sensor.position(0.0).x) * own.dir;
            if d0.abs() < 60.0 {
                if d0 > 0.0 { ahead += 1 } else { behind += 1 }
            }
            let d = (m.position(duration).x - sensor.position(duration).x) * own.dir;
            if d.abs() < 60.0 {
                // Caught up: within a few seconds' gap behind, at the sensor's speed.
                if d < 0.0 && d > -(movers::EGO_HALF_M.x + m.half.x + 2.0 + 2.0 * sensor.speed_mps) - 4.0 && (m.velocity(duration).x.abs() - sensor.speed_mps).abs() < 0.3 {
                    following += 1;
                }
            }
        }
    }
    assert!(ahead >= 2 && behind >= 2 && following >= 1, "ahead {ahead}, behind {behind}, following {following}");
}

#[test]
fn a_car_and_a_cyclist_pass_the_sensor_in_every_street() {
    for index in 0..8 {
        let mut w = World::build(WorldKind::Street, 13, index, &params()).unwrap();
        w.add_movers(3.0, |_, out| out.clear());
        let s = w.sensor.unwrap().position(1.5).truncate();
        for kind in [MoverKind::Car, MoverKind::Cyclist] {
            let near = w.movers.iter().filter(|m| m.kind == kind).map(|m| m.position(1.5).truncate().distance(s)).fold(f64::INFINITY, f64::min);
            assert!(near < 45.0, "sequence {index}: the nearest {kind:?} {near:.1} m from the sensor");
        }
        // Their meshes are the environment's last, each draw naming its mover.
        let movers: Vec<u32> = w.mover_of_draw.iter().copied().filter(|&k| k != NO_MOVER).collect();
        assert_eq!(movers.first(), Some(&0));
        assert_eq!(*movers.last().unwrap() as usize + 1, w.movers.len());
        assert!(movers.windows(2).all(|p| p[1] == p[0] || p[1] == p[0] + 1));
        for (d, &k) in w.draws.iter().zip(&w.mover_of_draw) {
            if k != NO_MOVER {
                let m = &w.movers[k as usize];
                assert!(d.first_vertex >= m.first_vertex && d.first_vertex + d.vertex_count <= m.first_vertex + m.local.len());
                let classes: &[u16] = if m.kind == MoverKind::Car { &[10] } else { &[11, 31] };
                assert!(classes.contains(&d.class), "{:?}: class {}", m.kind, d.class);
            }
        }
        // A second call adds nothing.
        let n = w.movers.len();
        w.add_movers(3.0, |_, out| out.clear());
        assert_eq!(w.movers.len(), n);
    }
}

/// The places a market makes for people (behind and before the counters, by the tables) have
/// room for one: nearly all of them are walkable with `clearance_m` to spare.
#[test]
fn market_places_have_room_for_a_person() {
    let p = WorldParams { markets: 1.0, ..params() };
    let (mut roomy, mut total) = (0, 0);
    for index in 0..3 {
        let w = World::build(WorldKind::Street, 9, index, &p).unwrap();
        for q in &w.places {
            roomy += usize::from(w.grid.clearance(q.at) >= p.clearance_m);
            total += 1;
        }
    }
    assert!(total > 100, "{total} places");
    assert!(roomy * 10 >= total * 9, "{roomy} of {total} places with room for a person");
}

/// The buildings' doorways have floors (no hole at a facade's foot) and are ways out: people
/// coming back in stand just inside them, facing the street, with room to, and see the street
/// ahead at chest height.
#[test]
fn doorways_are_floored_and_people_come_out_of_them_facing_the_street() {
    let side_streets = WorldParams { side_streets: 0.5, ..params() };
    for (index, p) in [(0, params()), (1, params()), (2, params()), (0, side_streets)] {
        let w = World::build(WorldKind::Street, 11, index, &p).unwrap();
        assert!(w.doors.len() >= 5, "sequence {index}: {} doorways", w.doors.len());
        for d in &w.doors {
            // Facing the road, which runs along x at y = 0.
            let ahead = DVec2::from_angle(d.facing_rad);
            assert!(ahead.x.abs() < 1e-9 && ahead.y * d.at.y < 0.0, "{d:?}");
            let chest = d.at.extend(1.3);
            assert_eq!(first_hit(&w.env, chest, DVec3::NEG_Z, 2.0).map(|h| (h * 1e6).round() / 1e6), Some(1.3), "{d:?}: no floor");
            // Nothing before them for 0.5 m at chest height (no wall piece, no door).
            assert!(first_hit(&w.env, chest, ahead.extend(0.0), 0.5).is_none(), "{d:?}: blocked");
            assert!(w.grid.clearance(d.at) >= p.clearance_m, "{d:?}: no room to stand");
        }
    }
}

/// The floor ahead of every seat is free where a seated person's feet go: nothing 1.5 cm above
/// it meets a ray along the seat's way under either foot within its feet's room, or 0.6 m
/// where the room is unbounded (the tallest bundled person's toes reach 0.57 m); the café
/// chairs' room ends short of their table's foot and still leaves 0.4 m.
#[test]
fn seats_leave_the_floor_free_for_the_feet() {
    let markets = WorldParams { markets: 1.0, ..params() };
    let side_streets = WorldParams { markets: 0.1, side_streets: 0.5, ..params() };
    let (mut seats, mut cafe) = (0, 0);
    for (kind, p) in [(WorldKind::Street, &markets), (WorldKind::Indoor, &markets), (WorldKind::Street, &side_streets)] {
        for index in 0..3 {
            let w = World::build(kind, 5, index, p).unwrap();
            // Those within 80 m of the middle: the sensor drives the middle and people sit
            // within a spawn radius of it (the lots' last furniture can overhang the street's ends).
            for s in w.seats.iter().filter(|s| s.at.x.abs() < 80.0) {
                let ahead = DVec2::from_angle(s.facing_rad);
                let room = s.feet_room_m.min(0.6);
                // The floor, 0.3 m ahead under the seat's front.
                let above = (s.at + 0.3 * ahead).extend(s.top_z_m - 0.1);
                let floor_z = above.z - first_hit(&w.env, above, DVec3::NEG_Z, 1.0).unwrap_or_else(|| panic!("{kind:?} {index}: {s:?}: no floor"));
                assert!((0.44..0.48).contains(&(s.top_z_m - floor_z)), "{s:?}: the floor at {floor_z}");
                for side in [-0.1, 0.1] {
                    let o = (s.at + side * ahead.perp()).extend(floor_z + 0.015);
                    let hit = first_hit(&w.env, o, ahead.extend(0.0), room);
                    assert!(hit.is_none(), "{kind:?} {index}: {s:?}: something {hit:?} m ahead at the floor, within {room} m");
                }
                if s.feet_room_m.is_finite() {
                    assert!(s.feet_room_m >= 0.4, "{s:?}");
                    // The table's foot is there, just past the room.
                    assert!(first_hit(&w.env, s.at.extend(floor_z + 0.015), ahead.extend(0.0), s.feet_room_m + 0.1).is_some(), "{s:?}");
                    cafe += 1;
                }
                seats += 1;
            }
        }
    }
    assert!(seats > 50 && cafe > 5, "{seats} seats, {cafe} at café tables");
}

/// Where a horizontal ray from `o` along `dir` first meets `env` within `max_m`, m (None: clear).
fn first_hit(env: &crate::scene::Environment, o: DVec3, dir: DVec3, max_m: f64) -> Option<f64> {
    let mut best: Option<f64> = None;
    for m in &env.meshes {
        for t in m.indices.chunks(3) {
            let [a, b, c] = [0, 1, 2].map(|k| env.positions[t[k] as usize]);
            // Moller-Trumbore, both sides.
            let (e1, e2) = (b - a, c - a);
            let pv = dir.cross(e2);
            let det = e1.dot(pv);
            if det.abs() < 1e-12 {
                continue;
            }
            let tv = o - a;
            let u = tv.dot(pv) / det;
            let qv = tv.cross(e1);
            let v = dir.dot(qv) / det;
            let d = e2.dot(qv) / det;
            if u >= 0.0 && v >= 0.0 && u + v <= 1.0 && d > 0.0 && d <= max_m && best.is_none_or(|x| d < x) {
                best = Some(d);
            }
        }
    }
    best
}

/// A booth is a hut someone serves from: just behind its counter a person has the counter
/// before their legs and the back wall a metre or so behind, and looks out through the
/// opening above it; before the counter a customer faces it, nothing behind. Side by side,
/// booths make a market's frontage of walls.
#[test]
fn booths_are_huts_open_above_their_counters() {
    use rand::SeedableRng;
    for (k, yaw) in [0.3, 2.0, -1.2].into_iter().enumerate() {
        let mut b = shapes::Builder::default();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(k as u64);
        things::booth(&mut b, &mut rng, DVec2::new(1.0, -2.0), 0.0, yaw, 3.0);
        let places = std::mem::take(&mut b.places);
        let env = b.finish();
        let (inside, outside): (Vec<&shapes::Place>, Vec<_>) = places.iter().partition(|q| (q.facing_rad - yaw).abs() < 1e-9);
        assert!(!inside.is_empty() && outside.len() >= inside.len(), "{places:?}");
        for q in inside {
            let out = DVec3::new(yaw.cos(), yaw.sin(), 0.0);
            let side = DVec3::new(-yaw.sin(), yaw.cos(), 0.0);
            let chest = q.at.extend(1.5);
            let back = first_hit(&env, chest, -out, 5.0).expect("a back wall");
            assert!((0.5..=1.6).contains(&back), "back wall {back} m behind");
            let counter = first_hit(&env, q.at.extend(0.6), out, 5.0).expect("a counter before the legs");
            assert!((0.5..=0.6).contains(&counter), "counter {counter} m ahead");
            assert_eq!(first_hit(&env, chest, out, 5.0), None, "the opening above the counter");
            assert!(first_hit(&env, q.at.extend(2.2), out, 5.0).is_some(), "the fascia above the opening");
            for s in [-1.0, 1.0] {
                assert!(first_hit(&env, chest, side * s, 3.0).is_some(), "walls either side");
            }
        }
        for q in outside {
            let dir = DVec3::new(q.facing_rad.cos(), q.facing_rad.sin(), 0.0);
            assert!(first_hit(&env, q.at.extend(0.6), dir, 0.8).is_some(), "a customer faces the counter");
            assert_eq!(first_hit(&env, q.at.extend(1.0), -dir, 5.0), None, "nothing behind a customer");
        }
    }
    // In a street of markets, booths stand in rows of them.
    let w = World::build(WorldKind::Street, 3, 0, &WorldParams { markets: 1.0, ..params() }).unwrap();
    assert!(w.counts.get("booth").is_some_and(|&n| n >= 4), "{}", w.summary());
}

/// A pavilion is a roof on posts that people stand under: over each of its places the roof
/// 0.8-1.3 m above their chest, the way they face open across it; a bus shelter's places have
/// its roof overhead and its back panel behind them, facing the road. A street of markets has
/// pavilions.
#[test]
fn people_stand_under_pavilions_and_bus_shelters() {
    use rand::SeedableRng;
    for (k, yaw) in [0.3, 2.0, -1.2].into_iter().enumerate() {
        let mut b = shapes::Builder::default();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(k as u64);
        things::pavilion(&mut b, &mut rng, DVec2::new(1.0, -2.0), 0.0, yaw, 4.0, 3.5);
        let places = std::mem::take(&mut b.places);
        let env = b.finish();
        // Two lines of four (4 m long, one every 0.9 m), facing each other across it.
        assert_eq!(places.len(), 8, "{places:?}");
        assert_eq!(places.iter().filter(|q| (q.facing_rad - yaw).abs() < 1e-9).count(), 4, "{places:?}");
        for q in &places {
            let chest = q.at.extend(1.5);
            let roof = first_hit(&env, chest, DVec3::Z, 3.0).expect("a roof overhead");
            assert!((0.8..=1.3).contains(&roof), "roof {roof} m above the chest");
            let dir = DVec3::new(q.facing_rad.cos(), q.facing_rad.sin(), 0.0);
            assert_eq!(first_hit(&env, chest, dir, 1.5), None, "open across the pavilion");
        }
        let mut b = shapes::Builder::default();
        things::shelter(&mut b, &mut rng, DVec2::new(1.0, -2.0), 0.0, yaw);
        let places = std::mem::take(&mut b.places);
        let env = b.finish();
        assert!(places.len() >= 3, "{places:?}");
        for q in &places {
            assert!((q.facing_rad - yaw).abs() < 1e-9, "{q:?} faces the road");
            let chest = q.at.extend(1.5);
            assert!(first_hit(&env, chest, DVec3::Z, 1.2).is_some(), "the shelter's roof overhead");
            let back = DVec3::new(-yaw.cos(), -yaw.sin(), 0.0);
            assert!(first_hit(&env, chest, back, 1.5).is_some(), "its back panel behind");
            assert_eq!(first_hit(&env, chest, -back, 3.0), None, "the road ahead");
        }
    }
    let w = World::build(WorldKind::Street, 3, 0, &WorldParams { markets: 1.0, ..params() }).unwrap();
    assert!(w.counts.get("pavilion").is_some_and(|&n| n >= 2), "{}", w.summary());
}

/// Indoors, robots and carts drive the hall's service aisle: nothing of the still world stands
/// in it between the end walls, they stay on its centre line, never run into each other or
/// into somebody standing in it (they queue behind them), and carry SemanticKITTI's
/// other-vehicle class.
#[test]
fn robots_and_carts_keep_to_the_aisle_and_stop_for_people() {
    let (mut aisles, mut queued, mut kinds) = (0, 0, std::collections::BTreeSet::new());
    for index in 0..8 {
        let Some((w, hall, person)) = hall_with_a_person_in_the_aisle(5, index, 30.0) else { continue };
        aisles += 1;
        let lane = w.movers.first().map(|m| m.lane().unwrap().lane.clone()).expect("a hall with an aisle keeps a mover");
        // The still world (built again, without its movers): nothing in the aisle.
        let bare = World::build(WorldKind::Indoor, 5, index, &WorldParams { duration_s: 30.0, ..params() }).unwrap();
        for t in obstacles(&bare.env) {
            let (lo, hi) = t.iter().fold((DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)), |(lo, hi), v| (lo.min(*v), hi.max(*v)));
            let inside = hi.x > hall.0 + 0.05 && lo.x < hall.1 - 0.05 && hi.y > lane.y - indoor::AISLE_HALF_M && lo.y < lane.y + indoor::AISLE_HALF_M;
            assert!(!inside, "hall {index}: an obstacle in the aisle: {t:?}");
        }
        assert_eq!(w.movers.len(), ["robot driving", "cart driving"].iter().map(|k| w.counts.get(k).copied().unwrap_or(0)).sum::<usize>(), "{}", w.summary());
        for k in 0..=600 {
            let t = 0.05 * k as f64;
            for (i, m) in w.movers.iter().enumerate() {
                assert!(Arc::ptr_eq(&m.lane().unwrap().lane, &lane) && m.lane().unwrap().y == lane.y);
                assert!(!m.touches(t, person), "hall {index}: {:?} {i} on the person at {t} s", m.kind);
                assert_apart_in_lane(&w.movers, i, t, index);
            }
        }
        // The one nearest behind the person has stopped there by the end.
        let behind = |m: &Mover| (lane.u_of(person.x) - lane.u_of(m.position(30.0).x)).rem_euclid(lane.length());
        let first = w.movers.iter().min_by(|a, b| behind(a).total_cmp(&behind(b))).unwrap();
        if first.velocity(30.0).length() == 0.0 && behind(first) < first.half.x + movers::PERSON_RADIUS_M + 1.5 {
            queued += 1;
        }
        for (d, &k) in w.draws.iter().zip(&w.mover_of_draw) {
            if k != NO_MOVER {
                kinds.insert(w.movers[k as usize].kind);
                assert_eq!(d.class, things::class::OTHER_VEHICLE);
            }
        }
    }
    assert!(aisles >= 6, "{aisles} of 8 halls with a service aisle");
    assert!(queued * 2 >= aisles, "{queued} of {aisles} halls with a mover stopped behind the person");
    assert_eq!(kinds.into_iter().collect::<Vec<_>>(), [MoverKind::Robot, MoverKind::Cart]);
}
