//! The street world: a straight street along world x. The road (z = [`ROAD_Z`], 12 cm below
//! the curbs) with parking lanes, lane markings and raised zebra crossings; sidewalks (z = 0,
//! where people walk) with a furniture strip by the curb (trees, lamp posts, sign posts,
//! bollards, bins, parking meters, utility cabinets, bike racks with bicycles, benches,
//! planters, hydrants, post boxes, ticket machines, bus shelters) and a frontage strip by the
//! facades (A-frame signs, planters, bicycles, bins, crates, café tables). Behind the
//! sidewalks, lot by lot: buildings (ground-floor walls with door recesses, piers, cornices,
//! set back or not), alleys, plazas furnished like the sidewalks, markets and beer gardens
//! (stalls, table sets, parasols), green slopes behind fences, and side streets
//! (`scene.side_streets`, none by default).
//! The sensor drives in a lane, in either direction, along the whole street; cars and cyclists
//! come the other way, and cars drive ahead of and behind it in its lane ([`super::movers`]).

use super::movers::{self, Ego, Lane, LaneTraffic};
use super::shapes::{Builder, Material, Place};
use super::things::{self, class, material};
use super::{chance, pick, uni, WorldParams};
use crate::scene::{Environment, Trajectory};
use glam::{DVec2, DVec3};
use rand::{Rng, RngExt};
use std::collections::BTreeMap;
use std::sync::Arc;
use std::f64::consts::{FRAC_PI_2, PI};

/// Height of the road below the sidewalks (the curb), m.
pub const ROAD_Z: f64 = -0.12;

/// Street beyond the sensor's run on either side, m (more than an HDL-64E sees of a person).
pub const MARGIN_M: f64 = 100.0;

/// Narrowest doorway people come out of, m (the walkable area keeps `humans.clearance_m` from
/// walls: a narrower one is no way out).
const DOORWAY_MIN_M: f64 = 1.3;
/// How far into a doorway (from the facade) one coming out of it starts at most, m.
const DOOR_IN_M: f64 = 0.3;

/// Width of a parking lane, m.
const PARKING_M: f64 = 2.2;

struct Layout {
    x0: f64,
    x1: f64,
    road_w: f64,
    /// Sidewalk width on the right (index 0, y < 0) and the left (1, y > 0).
    sidewalk: [f64; 2],
    parking: [bool; 2],
    /// Crossings: centre x and width.
    crossings: Vec<(f64, f64)>,
}

impl Layout {
    fn curb_y(&self, side: usize) -> f64 {
        sign(side) * self.road_w * 0.5
    }
    fn back_y(&self, side: usize) -> f64 {
        sign(side) * (self.road_w * 0.5 + self.sidewalk[side])
    }
    /// Whether `x` is within `pad` of a crossing.
    fn near_crossing(&self, x: f64, pad: f64) -> bool {
        self.crossings.iter().any(|&(c, w)| (x - c).abs() < w * 0.5 + pad)
    }
}

fn sign(side: usize) -> f64 {
    if side == 0 { -1.0 } else { 1.0 }
}

fn count(counts: &mut BTreeMap<&'static str, usize>, what: &'static str) {
    *counts.entry(what).or_insert(0) += 1;
}


/// Builds one street; the sensor's trajectory along it, its traffic: 2-6 cars and 1-3
/// cyclists for the oncoming lane and 1-3 cars for the sensor's (drawn after everything else,
/// in that order, so the layout of a seed is the same with or without them, and the oncoming
/// traffic with or without the sensor's lane's), the places people stand at
/// ([`World::places`]) and the doorways they come out of ([`World::doors`]), in that order,
/// and the seats people sit on ([`World::seats`]).
///
/// [`World::places`]: super::World::places
/// [`World::doors`]: super::World::doors
/// [`World::seats`]: super::World::seats
pub fn build(rng: &mut impl Rng, p: &WorldParams, counts: &mut BTreeMap<&'static str, usize>) -> (Environment, Option<Trajectory>, Vec<LaneTraffic>, [Vec<super::Place>; 2], Vec<super::Seat>) {
    let mut b = Builder::default();
    let speed = uni(rng, p.sensor_speed_mps[0], p.sensor_speed_mps[1]);
    let run = speed * p.duration_s.max(0.0);
    let half = run * 0.5 + MARGIN_M;
    let road_w = uni(rng, 8.0, 13.0);
    let parking = [chance(rng, 0.6), chance(rng, 0.6)];
    let sidewalk = [uni(rng, 3.5, 6.5), uni(rng, 3.5, 6.5)];
    let mut crossings = Vec::new();
    let mut x = -half + uni(rng, 10.0, 40.0);
    while x < half - 10.0 {
        crossings.push((x, uni(rng, 3.0, 5.0)));
        x += uni(rng, 35.0, 80.0);
    }
    let l = Layout { x0: -half, x1: half, road_w, sidewalk, parking, crossings };

    ground(&mut b, rng, &l);
    for side in 0..2 {
        let mouths = lots(&mut b, rng, &l, side, p.markets, p.side_streets, counts);
        curb_strip(&mut b, rng, &l, side, &mouths, counts);
        frontage(&mut b, rng, &l, side, &mouths, counts);
        if l.parking[side] {
            parked_cars(&mut b, rng, &l, side, &mouths, counts);
        }
    }

    // The sensor: in the right-hand lane of its direction of travel, over the whole run.
    let dir = if chance(rng, 0.5) { 1.0 } else { -1.0 };
    let lo = -road_w * 0.5 + if parking[0] { PARKING_M } else { 0.3 };
    let hi = road_w * 0.5 - if parking[1] { PARKING_M } else { 0.3 };
    let mid = 0.5 * (lo + hi);
    let y = if dir > 0.0 { 0.5 * (lo + mid) } else { 0.5 * (mid + hi) };
    let sensor = Trajectory {
        start_m: DVec2::new(-dir * run * 0.5, y),
        z_m: ROAD_Z + p.sensor_height_m,
        heading0_rad: if dir > 0.0 { 0.0 } else { PI },
        speed_mps: speed,
        yaw_rate_rps: 0.0,
    };
    // Oncoming traffic in the other half of the road, cyclists by its curb.
    let (oy, half_lane, curb_side) = if dir > 0.0 { (0.5 * (mid + hi), 0.5 * (hi - mid), 1.0) } else { (0.5 * (lo + mid), 0.5 * (mid - lo), -1.0) };
    let lane = Arc::new(Lane {
        y: oy,
        dir: -dir,
        x0: l.x0,
        x1: l.x1,
        road_z: ROAD_Z,
        crossings: l.crossings.clone(),
        ramp_m: RAMP_M,
        rise_m: -ROAD_Z,
        half_road_m: road_w * 0.5,
        bike_offset_m: curb_side * (half_lane - 0.6).max(0.0),
        yield_m: 0.0,
        pass_m: (8.0, 40.0),
    });
    let cars = 2 + (rng.random::<f64>() * 5.0) as usize;
    let cyclists = 1 + (rng.random::<f64>() * 3.0) as usize;
    let mut movers = vec![movers::car(rng), movers::cyclist(rng)];
    let mut rest: Vec<bool> = std::iter::repeat_n(true, cars - 1).chain(std::iter::repeat_n(false, cyclists - 1)).collect();
    while !rest.is_empty() {
        let k = crate::scene::even_index(rng.random::<f64>(), rest.len());
        movers.push(if rest.swap_remove(k) { movers::car(rng) } else { movers::cyclist(rng) });
    }
    // Cars ahead of and behind the sensor's vehicle in its lane.
    let own_lane = Arc::new(Lane { y, dir, bike_offset_m: 0.0, ..(*lane).clone() });
    let own = 1 + (rng.random::<f64>() * 3.0) as usize;
    // They drive a little faster than the sensor (or at town speed where it stands), so those
    // ahead of it stay in view a while and those behind catch up with it.
    let own_movers = (0..own)
        .map(|_| {
            let mut car = movers::car(rng);
            car.driver.speed_mps = (speed + uni(rng, 0.3, 2.5)).max(uni(rng, 5.0, 9.0));
            car
        })
        .collect();
    let ego = Ego { half: movers::EGO_HALF_M, speed_mps: speed };
    let places = [std::mem::take(&mut b.places), std::mem::take(&mut b.doors)];
    let traffic = vec![
        LaneTraffic { lane, movers, ego: None, count_as: None },
        LaneTraffic { lane: own_lane, movers: own_movers, ego: Some(ego), count_as: Some("car in the sensor lane") },
    ];
    let seats = std::mem::take(&mut b.seats);
    (b.finish(), Some(sensor), traffic, places, seats)
}

/// Length of a raised crossing's ramps, m.
const RAMP_M: f64 = 0.9;

/// Road, lane markings, curbs, sidewalks and raised crossings.
fn ground(b: &mut Builder, rng: &mut impl Rng, l: &Layout) {
    let (x0, x1, w) = (l.x0, l.x1, l.road_w * 0.5);
    let road = material(rng, class::ROAD);
    b.quad(road, [DVec3::new(x0, -w, ROAD_Z), DVec3::new(x1, -w, ROAD_Z), DVec3::new(x1, w, ROAD_Z), DVec3::new(x0, w, ROAD_Z)]);
    let paint = material(rng, class::LANE_MARKING);
    let z = ROAD_Z + 0.004;
    let lo = -w + if l.parking[0] { PARKING_M } else { 0.0 };
    let hi = w - if l.parking[1] { PARKING_M } else { 0.0 };
    let mid = 0.5 * (lo + hi);
    let mut x = x0;
    while x < x1 {
        if !l.near_crossing(x + 1.5, 2.5) {
            b.quad(paint, [DVec3::new(x, mid - 0.06, z), DVec3::new(x + 3.0, mid - 0.06, z), DVec3::new(x + 3.0, mid + 0.06, z), DVec3::new(x, mid + 0.06, z)]);
        }
        x += 9.0;
    }
    for (side, y) in [(0, lo), (1, hi)] {
        if l.parking[side] {
            b.quad(paint, [DVec3::new(x0, y - 0.05, z), DVec3::new(x1, y - 0.05, z), DVec3::new(x1, y + 0.05, z), DVec3::new(x0, y + 0.05, z)]);
        }
    }
    for side in 0..2 {
        let walk = material(rng, class::SIDEWALK);
        let (c, bk) = (l.curb_y(side), l.back_y(side));
        b.quad(walk, [DVec3::new(x0, c, 0.0), DVec3::new(x1, c, 0.0), DVec3::new(x1, bk, 0.0), DVec3::new(x0, bk, 0.0)]);
        b.quad(walk, [DVec3::new(x0, c, ROAD_Z), DVec3::new(x1, c, ROAD_Z), DVec3::new(x1, c, 0.0), DVec3::new(x0, c, 0.0)]);
    }
    for &(cx, cw) in &l.crossings {
        let slab = material(rng, class::ROAD);
        let (a, c) = (cx - cw * 0.5, cx + cw * 0.5);
        b.quad(slab, [DVec3::new(a, -w, 0.0), DVec3::new(c, -w, 0.0), DVec3::new(c, w, 0.0), DVec3::new(a, w, 0.0)]);
        for (e, out) in [(a, a - RAMP_M), (c, c + RAMP_M)] {
            b.quad(slab, [DVec3::new(e, -w, 0.0), DVec3::new(out, -w, ROAD_Z), DVec3::new(out, w, ROAD_Z), DVec3::new(e, w, 0.0)]);
        }
        let mut y = -w + 0.3;
        while y + 0.5 < w {
            b.quad(paint, [DVec3::new(a + 0.3, y, 0.003), DVec3::new(c - 0.3, y, 0.003), DVec3::new(c - 0.3, y + 0.5, 0.003), DVec3::new(a + 0.3, y + 0.5, 0.003)]);
            y += 1.0;
        }
    }
}

/// The lots behind one sidewalk, one after another: buildings, alleys, plazas and green slopes
/// in proportions 0.6 : 0.11 : 0.16 : 0.13, markets, a share `markets` of them, and side
/// streets, a share `side_streets`; the side streets' mouths where they meet the sidewalk,
/// kept clear of the curb's furniture and parked cars (their roads) and of the frontage's
/// things (their lots).
fn lots(b: &mut Builder, rng: &mut impl Rng, l: &Layout, side: usize, markets: f64, side_streets: f64, counts: &mut BTreeMap<&'static str, usize>) -> Vec<Mouth> {
    let rest = (1.0 - markets - side_streets).max(0.0);
    let weights = [0.6 * rest, 0.11 * rest, 0.16 * rest, 0.13 * rest, markets, side_streets];
    let mut mouths = Vec::new();
    let s = sign(side);
    let y0 = l.back_y(side);
    let mut x = l.x0;
    while x < l.x1 {
        match pick(rng, &weights) {
            0 => {
                let w = uni(rng, 8.0, 30.0);
                building(b, rng, x, x + w, y0, s);
                count(counts, "building");
                x += w;
            }
            1 => {
                let w = uni(rng, 2.0, 4.0);
                let depth = uni(rng, 6.0, 14.0);
                let floor = material(rng, class::SIDEWALK);
                b.quad(floor, [DVec3::new(x, y0, 0.0), DVec3::new(x + w, y0, 0.0), DVec3::new(x + w, y0 + s * depth, 0.0), DVec3::new(x, y0 + s * depth, 0.0)]);
                let wall = material(rng, class::BUILDING);
                b.aabb(wall, DVec3::new(x, (y0 + s * depth).min(y0 + s * (depth + 8.0)), 0.0), DVec3::new(x + w, (y0 + s * depth).max(y0 + s * (depth + 8.0)), uni(rng, 6.0, 18.0)));
                if chance(rng, 0.6) {
                    let q = DVec2::new(x + w * 0.5, y0 + s * uni(rng, 1.0, depth - 1.0));
                    if chance(rng, 0.5) { things::bin(b, rng, q, 0.0, 0.0) } else { things::crates(b, rng, q, 0.0, 0.0) };
                }
                count(counts, "alley");
                x += w;
            }
            2 => {
                let w = uni(rng, 12.0, 30.0);
                plaza(b, rng, x, x + w, y0, s, counts);
                x += w;
            }
            3 => {
                let w = uni(rng, 10.0, 30.0);
                green(b, rng, x, x + w, y0, s, counts);
                x += w;
            }
            4 => {
                let w = uni(rng, 12.0, 30.0);
                market(b, rng, x, x + w, y0, s, counts);
                x += w;
            }
            _ => {
                let mouth = side_street(b, rng, x, y0, s, counts);
                x = mouth.lot.1;
                mouths.push(mouth);
            }
        }
    }
    mouths
}

/// Where a side street meets the street's sidewalk: its lot's span along x, and its road's.
struct Mouth {
    lot: (f64, f64),
    road: (f64, f64),
}

/// Whether `[a, c]` comes within `pad` of one of `mouths`' roads (`lot`: their whole lots).
fn in_mouth(mouths: &[Mouth], a: f64, c: f64, pad: f64, lot: bool) -> bool {
    mouths.iter().any(|m| {
        let (lo, hi) = if lot { m.lot } else { m.road };
        c > lo - pad && a < hi + pad
    })
}

/// Thickness of a side street's walls, m: they stand on its own lot.
const SIDE_WALL_M: f64 = 0.4;

/// A side street from `xa` off the sidewalk whose back is `y0`, going away from the road
/// (`s`) 20-45 m: a road 5.5-8 m wide between sidewalks 2-3.5 m wide, reached over the
/// sidewalk (a continuous footway: people walk across its mouth, a ramp takes the road down
/// to its own level behind it), between the walls of buildings 4-20 m tall on its own lot
/// (with gaps, some with a cornice). Along its curbs lamp posts, sign posts, bollards, bins
/// and bicycles; a sidewalk of 3.1 m or more also has trees by its curb or, one in two,
/// bicycles, bins, planters, crates and signs by its wall (not both, so people pass between);
/// cars parked along one side or both where the road is 6.5 m wide or more; a building with
/// doorways across its end.
fn side_street(b: &mut Builder, rng: &mut impl Rng, xa: f64, y0: f64, s: f64, counts: &mut BTreeMap<&'static str, usize>) -> Mouth {
    let road_w = uni(rng, 5.5, 8.0);
    let walk = [uni(rng, 2.0, 3.5), uni(rng, 2.0, 3.5)];
    let depth = uni(rng, 20.0, 45.0);
    let xb = xa + SIDE_WALL_M + walk[0] + road_w + walk[1] + SIDE_WALL_M;
    let (wa, wb) = (xa + SIDE_WALL_M, xb - SIDE_WALL_M);
    let (ra, rb) = (wa + walk[0], wb - walk[1]);
    let (near, far) = (y0 + s * RAMP_M, y0 + s * depth);
    count(counts, "side street");
    let pave = material(rng, class::SIDEWALK);
    for (a, c) in [(xa, ra), (rb, xb)] {
        b.quad(pave, [DVec3::new(a, y0, 0.0), DVec3::new(c, y0, 0.0), DVec3::new(c, far, 0.0), DVec3::new(a, far, 0.0)]);
    }
    let road = material(rng, class::ROAD);
    b.quad(road, [DVec3::new(ra, y0, 0.0), DVec3::new(rb, y0, 0.0), DVec3::new(rb, near, ROAD_Z), DVec3::new(ra, near, ROAD_Z)]);
    b.quad(road, [DVec3::new(ra, near, ROAD_Z), DVec3::new(rb, near, ROAD_Z), DVec3::new(rb, far, ROAD_Z), DVec3::new(ra, far, ROAD_Z)]);
    // The curbs, beside the ramp the curb's face down to it, and the road's end.
    for x in [ra, rb] {
        b.quad(pave, [DVec3::new(x, near, ROAD_Z), DVec3::new(x, far, ROAD_Z), DVec3::new(x, far, 0.0), DVec3::new(x, near, 0.0)]);
        b.triangles(pave, &[DVec3::new(x, y0, 0.0), DVec3::new(x, near, 0.0), DVec3::new(x, near, ROAD_Z)], &[[0, 1, 2]]);
    }
    b.quad(pave, [DVec3::new(ra, far, ROAD_Z), DVec3::new(rb, far, ROAD_Z), DVec3::new(rb, far, 0.0), DVec3::new(ra, far, 0.0)]);
    // The walls: stretches of 6-20 m from the lot's edges to the sidewalks'.
    for (x, out) in [(wa, -1.0), (wb, 1.0)] {
        let wall = material(rng, class::BUILDING);
        let mut d = uni(rng, 0.0, 3.0);
        while d < depth - 1.0 {
            let len = uni(rng, 6.0, 20.0).min(depth - d);
            let h = uni(rng, 4.0, 20.0);
            slab(b, wall, x, x + out * SIDE_WALL_M, y0 + s * d, y0 + s * (d + len), 0.0, h);
            if h > 5.0 && chance(rng, 0.5) {
                let z = uni(rng, 3.0, 4.5).min(h - 0.5);
                slab(b, wall, x, x - out * uni(rng, 0.15, 0.35), y0 + s * d, y0 + s * (d + len), z, z + uni(rng, 0.2, 0.5));
            }
            d += len + if chance(rng, 0.3) { uni(rng, 2.0, 6.0) } else { 0.0 };
        }
    }
    let along = s * FRAC_PI_2;
    for (k, curb_x, wall_x, inward) in [(0, ra - 0.5, wa + 0.45, -1.0), (1, rb + 0.5, wb - 0.45, 1.0)] {
        let wide = walk[k] >= 3.1;
        let by_wall = wide && chance(rng, 0.5);
        // Things along the curb, from 2 m in; trees only where nothing stands by the wall.
        let trees = if wide && !by_wall { 0.25 } else { 0.0 };
        let toward_road = if inward < 0.0 { 0.0 } else { PI };
        let mut d = uni(rng, 2.0, 6.0);
        while d < depth - 1.5 {
            let q = DVec2::new(curb_x, y0 + s * d);
            let (what, r) = match pick(rng, &[trees, 0.2, 0.15, 0.1, 0.15, 0.15]) {
                0 => ("tree", things::tree(b, rng, q, 0.0)),
                1 => ("lamp post", things::lamp_post(b, rng, q, 0.0, toward_road)),
                2 => ("sign post", things::sign_post(b, rng, q, 0.0, toward_road + FRAC_PI_2)),
                3 => ("bollard", things::bollard(b, rng, q, 0.0)),
                4 => ("bin", things::bin(b, rng, q + DVec2::new(inward * 0.1, 0.0), 0.0, along)),
                _ => ("bicycle", things::bicycle(b, rng, q + DVec2::new(inward * 0.15, 0.0), 0.0, along)),
            };
            count(counts, what);
            d += r + uni(rng, 3.0, 10.0);
        }
        if !by_wall {
            continue;
        }
        let mut d = uni(rng, 1.0, 4.0);
        while d < depth - 1.5 {
            if chance(rng, 0.6) {
                let q = DVec2::new(wall_x, y0 + s * d);
                let (what, r) = match pick(rng, &[0.25, 0.25, 0.2, 0.15, 0.15]) {
                    0 => ("bicycle", things::bicycle(b, rng, q, 0.0, along)),
                    1 => ("bin", things::bin(b, rng, q, 0.0, along)),
                    2 => ("planter", things::planter(b, rng, q - DVec2::new(inward * 0.1, 0.0), 0.0, 0.0)),
                    3 => ("crates", things::crates(b, rng, q, 0.0, 0.0)),
                    _ => ("a-frame sign", things::a_frame(b, rng, q, 0.0, toward_road)),
                };
                count(counts, what);
                d += r;
            }
            d += uni(rng, 1.5, 5.0);
        }
    }
    // Cars parked along one side or both, their length (up to 6 m) along the side street and
    // clear of its end.
    if road_w >= 6.5 {
        for x in [ra + 1.1, rb - 1.1] {
            if !chance(rng, 0.6) {
                continue;
            }
            let mut d = RAMP_M + uni(rng, 4.0, 8.0);
            while d + 6.3 < depth {
                if chance(rng, 0.3) {
                    d += uni(rng, 3.0, 10.0);
                    continue;
                }
                let yaw = if chance(rng, 0.5) { FRAC_PI_2 } else { -FRAC_PI_2 };
                things::car(b, rng, DVec2::new(x, y0 + s * (d + 3.0)), ROAD_Z, yaw);
                count(counts, "parked car");
                d += 6.0 + uni(rng, 0.6, 3.0);
            }
        }
    }
    building(b, rng, xa, xb, far, s);
    count(counts, "building");
    Mouth { lot: (xa, xb), road: (ra, rb) }
}

/// An axis-aligned box given by x and y ranges in either order.
fn slab(b: &mut Builder, m: super::shapes::Material, xa: f64, xb: f64, ya: f64, yb: f64, z0: f64, z1: f64) {
    b.aabb(m, DVec3::new(xa.min(xb), ya.min(yb), z0), DVec3::new(xa.max(xb), ya.max(yb), z1));
}

/// A building from `xa` to `xb` whose facade line is `y0`, extending away from the road (`s`).
fn building(b: &mut Builder, rng: &mut impl Rng, xa: f64, xb: f64, y0: f64, s: f64) {
    let m = material(rng, class::BUILDING);
    let setback = [0.0, 0.0, 0.0, 0.0, 0.5, 1.0, 2.0][(rng.random::<f64>() * 7.0) as usize % 7];
    let front = y0 + s * setback;
    if setback > 0.0 {
        let floor = material(rng, class::SIDEWALK);
        b.quad(floor, [DVec3::new(xa, y0, 0.0), DVec3::new(xb, y0, 0.0), DVec3::new(xb, front, 0.0), DVec3::new(xa, front, 0.0)]);
    }
    let h = uni(rng, 6.0, 24.0);
    let recess = uni(rng, 0.4, 1.2);
    let ground_h = uni(rng, 3.0, 4.5);
    // The body behind the door recesses, the floors above them flush with the facade.
    slab(b, m, xa, xb, front + s * recess, front + s * 12.0, 0.0, h);
    slab(b, m, xa, xb, front, front + s * recess, ground_h, h);
    // Ground floor: wall pieces with doorways between them (the body's face shows through),
    // each doorway floored, and one wide enough to walk through a way out for people.
    let mut x = xa;
    let mut doors = Vec::new();
    let mut door = chance(rng, 0.5);
    while x < xb - 0.01 {
        let w = if door { uni(rng, 1.0, 2.4) } else { uni(rng, 1.0, 5.0) }.min(xb - x);
        if !door {
            slab(b, m, x, x + w, front, front + s * recess, 0.0, ground_h);
        } else {
            let back = front + s * recess;
            b.quad(Material::new(class::SIDEWALK, m.reflectance as f64), [DVec3::new(x, front, 0.0), DVec3::new(x + w, front, 0.0), DVec3::new(x + w, back, 0.0), DVec3::new(x, back, 0.0)]);
            if w >= DOORWAY_MIN_M {
                let inside = (0.5 * recess - 0.3).clamp(0.0, DOOR_IN_M);
                doors.push((x, x + w, Place { at: DVec2::new(x + 0.5 * w, front + s * inside), facing_rad: -s * FRAC_PI_2 }));
            }
        }
        x += w;
        door = !door;
    }
    let trim = material(rng, class::BUILDING);
    if chance(rng, 0.6) {
        slab(b, trim, xa, xb, front - s * uni(rng, 0.15, 0.4), front, ground_h, ground_h + uni(rng, 0.2, 0.5));
    }
    if chance(rng, 0.5) {
        let step = uni(rng, 3.0, 5.0);
        let (pw, pd) = (uni(rng, 0.3, 0.6), uni(rng, 0.12, 0.3));
        let mut x = xa + 0.5 * pw;
        while x < xb - 0.5 * pw {
            let z0 = if chance(rng, 0.5) { 0.0 } else { ground_h };
            slab(b, trim, x - 0.5 * pw, x + 0.5 * pw, front - s * pd, front, z0, h);
            // A pier down to the ground before a doorway leaves no way out through it.
            if z0 == 0.0 {
                doors.retain(|&(a, e, _)| x + 0.5 * pw <= a || x - 0.5 * pw >= e);
            }
            x += step;
        }
    }
    b.doors.extend(doors.into_iter().map(|(_, _, d)| d));
    // Window sills on the floors above.
    if chance(rng, 0.6) {
        let mut z = ground_h + 1.0;
        while z < h - 1.5 {
            slab(b, trim, xa, xb, front - s * 0.1, front, z, z + 0.12);
            z += 3.0;
        }
    }
}

/// A paved lot from `xa` to `xb`, `depth` deep behind the sidewalk's back `y0`, a building at
/// its back.
fn paved_lot(b: &mut Builder, rng: &mut impl Rng, xa: f64, xb: f64, y0: f64, s: f64, depth: f64) {
    let floor = material(rng, class::SIDEWALK);
    b.quad(floor, [DVec3::new(xa, y0, 0.0), DVec3::new(xb, y0, 0.0), DVec3::new(xb, y0 + s * depth, 0.0), DVec3::new(xa, y0 + s * depth, 0.0)]);
    building(b, rng, xa, xb, y0 + s * depth, s);
}

/// A paved plaza behind the sidewalk, a building at its back, furnished.
fn plaza(b: &mut Builder, rng: &mut impl Rng, xa: f64, xb: f64, y0: f64, s: f64, counts: &mut BTreeMap<&'static str, usize>) {
    let depth = uni(rng, 8.0, 20.0);
    paved_lot(b, rng, xa, xb, y0, s, depth);
    count(counts, "plaza");
    let n = ((xb - xa) * depth / uni(rng, 12.0, 30.0)) as usize;
    let mut placed: Vec<(DVec2, f64)> = Vec::new();
    for _ in 0..n {
        for _ in 0..20 {
            let q = DVec2::new(uni(rng, xa + 1.0, xb - 1.0), y0 + s * uni(rng, 1.0, depth - 1.0));
            if placed.iter().any(|(c, r)| c.distance(q) < r + 1.6) {
                continue;
            }
            let yaw = uni(rng, -PI, PI);
            let (what, r) = match pick(rng, &[0.15, 0.12, 0.1, 0.12, 0.1, 0.08, 0.1, 0.08, 0.08, 0.07]) {
                0 => ("tree", things::tree(b, rng, q, 0.0)),
                1 => ("bench", things::bench(b, rng, q, 0.0, yaw)),
                2 => ("planter", things::planter(b, rng, q, 0.0, yaw)),
                3 => ("bollard", things::bollard(b, rng, q, 0.0)),
                4 => ("table", things::table(b, rng, q, 0.0, yaw)),
                5 => ("kiosk", things::kiosk(b, rng, q, 0.0, yaw)),
                6 => ("bush", things::bush(b, rng, q, 0.0)),
                7 => ("info stand", things::info_stand(b, rng, q, 0.0, yaw)),
                8 => ("bin", things::bin(b, rng, q, 0.0, yaw)),
                _ => ("sculpture", sculpture(b, rng, q, yaw)),
            };
            count(counts, what);
            placed.push((q, r));
            break;
        }
    }
}

/// A market or beer garden behind the sidewalk, a building at its back: rows of open stalls
/// under their roofs, of booths (huts open at the front above a counter) side by side, of
/// table sets under parasols, or of pavilions (party tents on posts), with aisles 1-2.5 m wide
/// between them. They make places to stand at (`humans.at_places`: behind and before the
/// counters, by the tables, under the pavilions), where people show above a counter or a
/// table with the stall's roof and posts, the booth's walls or the pavilion's sides around
/// them at their own range, as the real people of a market do.
fn market(b: &mut Builder, rng: &mut impl Rng, xa: f64, xb: f64, y0: f64, s: f64, counts: &mut BTreeMap<&'static str, usize>) {
    let depth = uni(rng, 8.0, 16.0);
    paved_lot(b, rng, xa, xb, y0, s, depth);
    count(counts, "market");
    #[derive(PartialEq)]
    enum Row {
        Stalls,
        Booths,
        Tables,
        Pavilions,
    }
    // Rows along the street. Stalls face the street or away; booths mostly face it.
    let mut y = uni(rng, 1.0, 2.0);
    loop {
        let row = match uni(rng, 0.0, 1.0) {
            u if u < 0.3 => Row::Stalls,
            u if u < 0.6 => Row::Booths,
            u if u < 0.8 => Row::Tables,
            _ => Row::Pavilions,
        };
        let across = match row {
            Row::Stalls => 2.2,
            Row::Booths => 2.6,
            Row::Tables => 1.6,
            Row::Pavilions => uni(rng, 3.0, 4.5),
        };
        if y + across > depth - 1.0 {
            break;
        }
        let towards = chance(rng, if row == Row::Booths { 0.8 } else { 0.5 });
        let facing = if towards { -s * FRAC_PI_2 } else { s * FRAC_PI_2 };
        let mut x = xa + uni(rng, 0.5, 2.0);
        loop {
            let len = match row {
                Row::Stalls => uni(rng, 2.0, 3.5),
                Row::Booths => uni(rng, 2.0, 4.0),
                Row::Tables => 2.2,
                Row::Pavilions => uni(rng, 3.0, 6.0),
            };
            if x + len > xb - 0.5 {
                break;
            }
            let q = DVec2::new(x + len * 0.5, y0 + s * (y + across * 0.5));
            match row {
                Row::Stalls => {
                    things::stall(b, rng, q, 0.0, facing, len);
                    count(counts, "stall");
                }
                Row::Booths => {
                    things::booth(b, rng, q, 0.0, facing, len);
                    count(counts, "booth");
                }
                Row::Pavilions => {
                    things::pavilion(b, rng, q, 0.0, facing, len, across);
                    count(counts, "pavilion");
                }
                Row::Tables => {
                    things::table_set(b, rng, q, 0.0, 0.0);
                    count(counts, "table set");
                    if chance(rng, 0.6) {
                        things::parasol(b, rng, q, 0.0);
                        count(counts, "parasol");
                    }
                }
            }
            // Booths stand side by side, an aisle now and then.
            x += len + if row == Row::Booths && chance(rng, 0.7) { uni(rng, 0.0, 0.3) } else { uni(rng, 1.0, 2.5) };
        }
        y += across + uni(rng, 1.0, 2.5);
    }
}

/// A sculpture or monument: a plinth and a figure-sized block or column, 1.2-3 m.
fn sculpture(b: &mut Builder, rng: &mut impl Rng, q: DVec2, yaw: f64) -> f64 {
    let m = material(rng, class::OTHER_OBJECT);
    let plinth = uni(rng, 0.0, 0.8);
    if plinth > 0.2 {
        b.cuboid(m, q.extend(0.0), DVec3::new(0.9, 0.9, plinth), yaw);
    }
    let h = uni(rng, 1.0, 2.2);
    if chance(rng, 0.5) {
        b.frustum(m, q.extend(plinth), uni(rng, 0.15, 0.35), uni(rng, 0.1, 0.3), h, 8);
    } else {
        b.ellipsoid(m, q.extend(plinth + h * 0.5), DVec3::new(uni(rng, 0.2, 0.4), uni(rng, 0.2, 0.4), h * 0.5), 5, 0.25, || 0.0);
    }
    0.5
}

/// A green slope behind the sidewalk (terrain rising away from the road), fenced or walled,
/// with bushes and trees on it.
fn green(b: &mut Builder, rng: &mut impl Rng, xa: f64, xb: f64, y0: f64, s: f64, counts: &mut BTreeMap<&'static str, usize>) {
    let depth = uni(rng, 8.0, 20.0);
    let slope = uni(rng, 0.1, 0.5);
    let m = material(rng, class::TERRAIN);
    b.quad(m, [DVec3::new(xa, y0, 0.0), DVec3::new(xb, y0, 0.0), DVec3::new(xb, y0 + s * depth, depth * slope), DVec3::new(xa, y0 + s * depth, depth * slope)]);
    count(counts, "green slope");
    match pick(rng, &[0.5, 0.25, 0.25]) {
        0 => {
            things::fence(b, rng, DVec2::new(xa, y0 + s * 0.1), DVec2::new(xb, y0 + s * 0.1), 0.0);
            count(counts, "fence");
        }
        1 => {
            let wall = material(rng, class::BUILDING);
            slab(b, wall, xa, xb, y0, y0 + s * 0.3, 0.0, uni(rng, 0.3, 0.8));
        }
        _ => {}
    }
    let n = ((xb - xa) / uni(rng, 2.0, 5.0)) as usize;
    for _ in 0..n {
        let d = uni(rng, 0.8, depth - 0.5);
        let q = DVec2::new(uni(rng, xa + 0.5, xb - 0.5), y0 + s * d);
        let g = d * slope - 0.05;
        if chance(rng, 0.65) {
            things::bush(b, rng, q, g);
            count(counts, "bush");
        } else {
            things::tree(b, rng, q, g);
            count(counts, "tree");
        }
    }
}

/// The furniture strip by the curb.
fn curb_strip(b: &mut Builder, rng: &mut impl Rng, l: &Layout, side: usize, mouths: &[Mouth], counts: &mut BTreeMap<&'static str, usize>) {
    let s = sign(side);
    let toward_road = -s * FRAC_PI_2;
    let along = 0.0;
    let mut x = l.x0 + uni(rng, 0.0, 3.0);
    while x < l.x1 {
        // Clear of a side street's road by 1 m, with the room the longest thing (a bus shelter,
        // up to 5 m, centred where it is drawn) takes along the curb.
        if in_mouth(mouths, x - 2.5, x + 2.5, 1.0, false) {
            x += 1.0;
            continue;
        }
        let y = l.curb_y(side) + s * uni(rng, 0.35, 0.75);
        let q = DVec2::new(x, y);
        let at_crossing = l.near_crossing(x, 1.0);
        let k = if at_crossing {
            if chance(rng, 0.5) { 3 } else { 99 }
        } else {
            pick(rng, &[0.12, 0.05, 0.08, 0.08, 0.1, 0.08, 0.08, 0.05, 0.04, 0.12, 0.02, 0.05, 0.05, 0.02, 0.06])
        };
        let (what, r) = match k {
            0 => ("tree", things::tree(b, rng, q, 0.0)),
            1 => ("lamp post", things::lamp_post(b, rng, q, 0.0, toward_road)),
            2 => ("sign post", things::sign_post(b, rng, q, 0.0, toward_road + FRAC_PI_2)),
            3 => {
                // A row of 2-5 bollards along the curb.
                let n = 2 + (rng.random::<f64>() * 4.0) as usize;
                let gap = uni(rng, 1.2, 1.8);
                for i in 0..n {
                    let at = q + DVec2::X * (i as f64 * gap);
                    if in_mouth(mouths, at.x, at.x, 1.0, false) {
                        continue;
                    }
                    things::bollard(b, rng, at, 0.0);
                    count(counts, "bollard");
                }
                x += (n - 1) as f64 * gap;
                ("", 0.2)
            }
            4 => ("bin", things::bin(b, rng, q, 0.0, along)),
            5 => ("parking meter", things::meter(b, rng, q, 0.0, toward_road)),
            6 => ("cabinet", things::cabinet(b, rng, q, 0.0, along)),
            7 => {
                let mut bikes = 0;
                let r = things::bike_rack(b, rng, q + DVec2::new(0.0, s * 0.25), 0.0, along, &mut bikes);
                for _ in 0..bikes {
                    count(counts, "bicycle");
                }
                ("bike rack", r)
            }
            8 => ("bench", things::bench(b, rng, q + DVec2::new(0.0, s * 0.2), 0.0, s * FRAC_PI_2)),
            9 => {
                if chance(rng, 0.5) { ("bush", things::bush(b, rng, q + DVec2::new(0.0, s * 0.2), 0.0)) } else { ("planter", things::planter(b, rng, q + DVec2::new(0.0, s * 0.2), 0.0, along)) }
            }
            10 => ("hydrant", things::hydrant(b, rng, q, 0.0)),
            11 => ("post box", things::post_box(b, rng, q, 0.0, along)),
            12 => ("ticket machine", things::kiosk(b, rng, q + DVec2::new(0.0, s * 0.1), 0.0, toward_road)),
            13 if l.sidewalk[side] >= 4.0 => ("bus shelter", things::shelter(b, rng, q + DVec2::new(0.0, s * 0.5), 0.0, toward_road)),
            14 => ("bicycle", things::bicycle(b, rng, q + DVec2::new(0.0, s * 0.2), 0.0, along)),
            _ => ("", 0.0),
        };
        if !what.is_empty() {
            count(counts, what);
        }
        x += r + uni(rng, 1.0, 4.0);
    }
}

/// The frontage strip by the facades.
fn frontage(b: &mut Builder, rng: &mut impl Rng, l: &Layout, side: usize, mouths: &[Mouth], counts: &mut BTreeMap<&'static str, usize>) {
    let s = sign(side);
    let mut x = l.x0 + uni(rng, 0.0, 5.0);
    while x < l.x1 {
        if in_mouth(mouths, x - 1.0, x + 2.0, 0.0, true) {
            x += 1.0;
            continue;
        }
        if chance(rng, 0.7) {
            let y = l.back_y(side) - s * uni(rng, 0.35, 0.6);
            let q = DVec2::new(x, y);
            let facing = -s * FRAC_PI_2;
            let (what, r) = match pick(rng, &[0.14, 0.16, 0.12, 0.1, 0.08, 0.08, 0.1, 0.06, 0.08, 0.08]) {
                0 => ("a-frame sign", things::a_frame(b, rng, q, 0.0, facing)),
                1 => ("planter", things::planter(b, rng, q, 0.0, 0.0)),
                2 => ("bicycle", things::bicycle(b, rng, q, 0.0, 0.0)),
                3 => ("bin", things::bin(b, rng, q, 0.0, 0.0)),
                4 => ("crates", things::crates(b, rng, q, 0.0, 0.0)),
                5 if l.sidewalk[side] >= 4.5 => ("table", things::table(b, rng, q - DVec2::new(0.0, s * 0.5), 0.0, 0.0)),
                7 => ("mannequin", things::mannequin(b, rng, q, 0.0, facing)),
                8 => ("info stand", things::info_stand(b, rng, q, 0.0, facing + FRAC_PI_2)),
                9 => ("vending machine", things::kiosk(b, rng, q - DVec2::new(0.0, s * 0.1), 0.0, facing)),
                _ => ("bush", things::bush(b, rng, q, 0.0)),
            };
            count(counts, what);
            x += r;
        }
        x += uni(rng, 1.5, 5.0);
    }
}

/// Cars parked along one curb, with gaps, clear of the crossings; one in eight a box truck.
fn parked_cars(b: &mut Builder, rng: &mut impl Rng, l: &Layout, side: usize, mouths: &[Mouth], counts: &mut BTreeMap<&'static str, usize>) {
    let s = sign(side);
    let y = l.curb_y(side) - s * PARKING_M * 0.48;
    let mut x = l.x0 + uni(rng, 0.0, 6.0);
    while x < l.x1 {
        if chance(rng, 0.35) {
            x += uni(rng, 4.0, 25.0);
            continue;
        }
        let truck = chance(rng, 0.125);
        let len_guess = if truck { 8.5 } else { 5.2 };
        if l.near_crossing(x + len_guess * 0.5, len_guess * 0.5 + 1.5) || in_mouth(mouths, x, x + len_guess, 1.0, false) {
            x += 2.0;
            continue;
        }
        let yaw = if chance(rng, 0.5) { 0.0 } else { PI };
        let len = if truck {
            // Its side 0.05 m from the curb.
            let centre = DVec2::new(x + len_guess * 0.5, l.curb_y(side) - s * 1.15);
            count(counts, "parked truck");
            things::truck(b, rng, centre, ROAD_Z, yaw).0
        } else {
            count(counts, "parked car");
            things::car(b, rng, DVec2::new(x + len_guess * 0.5, y), ROAD_Z, yaw).0
        };
        x += len_guess.max(len) + uni(rng, 0.6, 3.0);
    }
}
