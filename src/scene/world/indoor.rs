//! The indoor world: a building's floor. A main hall (24-45 x 16-30 m, ceiling 3.5-7 m) with
//! pillars and a flight of stairs, two to four corridors leaving it, some ending in a second
//! room; walls, floors and ceilings. The rooms are furnished by zone (a shop: shelves, display
//! cases, mannequins; a café: tables, chairs, plants; a lobby: kiosks, information stands,
//! benches, coat stands, bins, plants, a counter; storage: crates, shelves), the corridors along
//! their walls. A service aisle crosses the hall from end wall to end wall, kept clear of
//! pillars, stairs and furniture, with a strip curtain over a doorway at either end: delivery
//! robots and motorised carts drive along it, out through one curtain and back in through the
//! other ([`super::movers`]). The sensor walks or rolls through the walkable area as in any
//! environment.

use super::movers::{self, Lane, LaneTraffic};
use super::shapes::Builder;
use super::things::{self, class, material};
use super::{chance, pick, uni, WorldParams};
use crate::scene::Environment;
use glam::{DVec2, DVec3};
use rand::{Rng, RngExt};
use std::collections::BTreeMap;
use std::f64::consts::{FRAC_PI_2, PI};
use std::sync::Arc;

/// Wall thickness, m.
pub(super) const WALL_M: f64 = 0.2;

/// Half the service aisle's width, m (a cart's half width and room beside it).
pub(super) const AISLE_HALF_M: f64 = 0.75;
/// How far beyond the end walls the aisle's lane runs before it wraps, m (a cart's length and
/// more: a mover leaves through one curtain wholly before it comes back through the other).
pub(super) const BEHIND_WALL_M: f64 = 2.5;
/// The doorways' curtains: width and height, m.
const CURTAIN_M: (f64, f64) = (2.0, 2.3);

#[derive(Clone, Debug)]
struct Room {
    lo: DVec2,
    hi: DVec2,
    ceiling: f64,
    /// Openings per edge (0: y = lo.y, 1: x = hi.x, 2: y = hi.y, 3: x = lo.x) as intervals
    /// along the edge's axis.
    openings: [Vec<(f64, f64)>; 4],
    corridor: bool,
}

impl Room {
    fn new(lo: DVec2, hi: DVec2, ceiling: f64, corridor: bool) -> Room {
        Room { lo, hi, ceiling, openings: Default::default(), corridor }
    }
    fn overlaps(&self, o: &Room, pad: f64) -> bool {
        self.lo.x < o.hi.x + pad && o.lo.x < self.hi.x + pad && self.lo.y < o.hi.y + pad && o.lo.y < self.hi.y + pad
    }
    fn area(&self) -> f64 {
        let d = self.hi - self.lo;
        d.x * d.y
    }
}

fn count(counts: &mut BTreeMap<&'static str, usize>, what: &'static str) {
    *counts.entry(what).or_insert(0) += 1;
}

/// Builds one floor, the traffic of its service aisle (none where the hall has no room for
/// one) and the seats people sit on (benches, the café's chairs).
pub fn build(rng: &mut impl Rng, _p: &WorldParams, counts: &mut BTreeMap<&'static str, usize>) -> (Environment, Vec<LaneTraffic>, Vec<super::Seat>) {
    let mut b = Builder::default();
    let (w, d) = (uni(rng, 24.0, 45.0), uni(rng, 16.0, 30.0));
    let mut rooms = vec![Room::new(DVec2::new(-w * 0.5, -d * 0.5), DVec2::new(w * 0.5, d * 0.5), uni(rng, 3.5, 7.0), false)];
    let corridors = 2 + (rng.random::<f64>() * 3.0) as usize;
    for _ in 0..corridors {
        for _ in 0..20 {
            let edge = (rng.random::<f64>() * 4.0) as usize % 4;
            let cw = uni(rng, 2.5, 4.5);
            let len = uni(rng, 12.0, 35.0);
            let hall = rooms[0].clone();
            let (axis_lo, axis_hi) = if edge % 2 == 0 { (hall.lo.x, hall.hi.x) } else { (hall.lo.y, hall.hi.y) };
            let t = uni(rng, axis_lo + cw * 0.5 + 1.0, axis_hi - cw * 0.5 - 1.0);
            let (lo, hi) = match edge {
                0 => (DVec2::new(t - cw * 0.5, hall.lo.y - len), DVec2::new(t + cw * 0.5, hall.lo.y)),
                1 => (DVec2::new(hall.hi.x, t - cw * 0.5), DVec2::new(hall.hi.x + len, t + cw * 0.5)),
                2 => (DVec2::new(t - cw * 0.5, hall.hi.y), DVec2::new(t + cw * 0.5, hall.hi.y + len)),
                _ => (DVec2::new(hall.lo.x - len, t - cw * 0.5), DVec2::new(hall.lo.x, t + cw * 0.5)),
            };
            let mut c = Room::new(lo, hi, uni(rng, 2.7, 3.5), true);
            if rooms.iter().skip(1).any(|r| r.overlaps(&c, 1.0)) {
                continue;
            }
            // The corridor's edge against the hall is all open; the hall's edge open there.
            let back = (edge + 2) % 4;
            let (a, z) = if edge % 2 == 0 { (lo.x, hi.x) } else { (lo.y, hi.y) };
            c.openings[back].push((a, z));
            rooms[0].openings[edge].push((a, z));
            // A room at the far end, now and then.
            let mut end_room = None;
            if chance(rng, 0.5) {
                let (rw, rd) = (uni(rng, 8.0, 20.0), uni(rng, 8.0, 15.0));
                let mid = 0.5 * (a + z);
                let s = uni(rng, -0.3, 0.3);
                let (rlo, rhi) = match edge {
                    0 => (DVec2::new(mid - rw * (0.5 + s), lo.y - rd), DVec2::new(mid + rw * (0.5 - s), lo.y)),
                    1 => (DVec2::new(hi.x, mid - rw * (0.5 + s)), DVec2::new(hi.x + rd, mid + rw * (0.5 - s))),
                    2 => (DVec2::new(mid - rw * (0.5 + s), hi.y), DVec2::new(mid + rw * (0.5 - s), hi.y + rd)),
                    _ => (DVec2::new(lo.x - rd, mid - rw * (0.5 + s)), DVec2::new(lo.x, mid + rw * (0.5 - s))),
                };
                let mut r = Room::new(rlo, rhi, uni(rng, 3.0, 5.0), false);
                if !rooms.iter().any(|o| r.overlaps(o, 0.5)) {
                    r.openings[back].push((a, z));
                    c.openings[edge].push((a, z));
                    end_room = Some(r);
                }
            }
            rooms.push(c);
            count(counts, "corridor");
            if let Some(r) = end_room {
                rooms.push(r);
                count(counts, "room");
            }
            break;
        }
    }
    let floor = material(rng, class::OTHER_GROUND);
    let wall = material(rng, class::BUILDING);
    for r in &rooms {
        b.quad(floor, [r.lo.extend(0.0), DVec3::new(r.hi.x, r.lo.y, 0.0), r.hi.extend(0.0), DVec3::new(r.lo.x, r.hi.y, 0.0)]);
        b.quad(wall, [r.lo.extend(r.ceiling), DVec3::new(r.hi.x, r.lo.y, r.ceiling), r.hi.extend(r.ceiling), DVec3::new(r.lo.x, r.hi.y, r.ceiling)]);
        walls(&mut b, r, wall);
    }
    // The hall's pillars and stairs, then every room's furniture.
    let mut placed: Vec<(DVec2, f64)> = Vec::new();
    let hall = rooms[0].clone();
    if chance(rng, 0.8) {
        let step = uni(rng, 6.0, 9.0);
        let round = chance(rng, 0.5);
        let r = uni(rng, 0.25, 0.5);
        let m = material(rng, class::BUILDING);
        let mut x = hall.lo.x + step;
        while x < hall.hi.x - step * 0.5 {
            let mut y = hall.lo.y + step;
            while y < hall.hi.y - step * 0.5 {
                let q = DVec2::new(x, y);
                if round {
                    b.cylinder(m, q.extend(0.0), r, hall.ceiling, 12);
                } else {
                    b.cuboid(m, q.extend(0.0), DVec3::new(2.0 * r, 2.0 * r, hall.ceiling), 0.0);
                }
                placed.push((q, r + 0.3));
                count(counts, "pillar");
                y += step;
            }
            x += step;
        }
    }
    if chance(rng, 0.7) {
        stairs(&mut b, rng, &hall, &mut placed);
        count(counts, "stairs");
    }
    let aisle = service_aisle(&mut b, rng, &hall, &placed);
    if aisle.is_some() {
        count(counts, "service aisle");
    }
    for (k, r) in rooms.iter().enumerate() {
        furnish(&mut b, rng, r, &mut placed, if k == 0 { aisle } else { None }, counts);
    }
    // Its robots and carts, drawn last.
    let traffic = aisle.map_or_else(Vec::new, |(y, dir)| {
        let lane = Arc::new(Lane {
            y,
            dir,
            x0: hall.lo.x - WALL_M - BEHIND_WALL_M,
            x1: hall.hi.x + WALL_M + BEHIND_WALL_M,
            road_z: 0.0,
            crossings: Vec::new(),
            ramp_m: 1.0,
            rise_m: 0.0,
            half_road_m: AISLE_HALF_M,
            bike_offset_m: 0.0,
            yield_m: AISLE_HALF_M + movers::PERSON_RADIUS_M,
            pass_m: (2.0, 12.0),
        });
        let n = 1 + (rng.random::<f64>() * 3.0) as usize;
        let specs = (0..n).map(|_| if chance(rng, 0.6) { movers::robot(rng) } else { movers::cart(rng) }).collect();
        vec![LaneTraffic { lane, movers: specs, ego: None, count_as: None }]
    });
    let seats = std::mem::take(&mut b.seats);
    (b.finish(), traffic, seats)
}

/// A service aisle along the hall's length (world x): its centre line's y, 3 m or more from
/// the long walls (the stairs) and clear of the pillars, where neither end wall has an
/// opening; a strip curtain over a doorway in each end wall (opaque to the sensor, so the wall
/// behind it stays whole: the movers pass through both out of sight). Returns its y and the way its
/// movers drive (+1: toward +x), or None where no such line was found.
fn service_aisle(b: &mut Builder, rng: &mut impl Rng, hall: &Room, pillars: &[(DVec2, f64)]) -> Option<(f64, f64)> {
    if hall.hi.y - hall.lo.y < 6.0 + 2.0 * AISLE_HALF_M {
        return None;
    }
    let free_end = |edge: usize, y: f64| hall.openings[edge].iter().all(|&(a, z)| y + CURTAIN_M.0 * 0.5 + 0.5 < a || y - CURTAIN_M.0 * 0.5 - 0.5 > z);
    let y = (0..40).map(|_| uni(rng, hall.lo.y + 3.0, hall.hi.y - 3.0)).find(|&y| {
        pillars.iter().all(|(c, r)| (c.y - y).abs() > r + AISLE_HALF_M + 0.2) && free_end(1, y) && free_end(3, y)
    })?;
    let dir = if chance(rng, 0.5) { 1.0 } else { -1.0 };
    let m = material(rng, class::OTHER_OBJECT);
    for x in [hall.lo.x + 0.01, hall.hi.x - 0.01] {
        b.cuboid(m, DVec3::new(x, y, 0.0), DVec3::new(0.02, CURTAIN_M.0, CURTAIN_M.1), 0.0);
    }
    Some((y, dir))
}

/// The room's walls, outside its rectangle, with its openings left out.
fn walls(b: &mut Builder, r: &Room, m: super::shapes::Material) {
    for edge in 0..4 {
        let (a, z) = if edge % 2 == 0 { (r.lo.x - WALL_M, r.hi.x + WALL_M) } else { (r.lo.y - WALL_M, r.hi.y + WALL_M) };
        let mut gaps = r.openings[edge].clone();
        gaps.sort_by(|p, q| p.0.total_cmp(&q.0));
        let mut pieces = Vec::new();
        let mut start = a;
        for (g0, g1) in gaps {
            if g0 > start {
                pieces.push((start, g0));
            }
            start = start.max(g1);
        }
        if z > start {
            pieces.push((start, z));
        }
        for (p0, p1) in pieces {
            let (lo, hi) = match edge {
                0 => (DVec3::new(p0, r.lo.y - WALL_M, 0.0), DVec3::new(p1, r.lo.y, r.ceiling)),
                1 => (DVec3::new(r.hi.x, p0, 0.0), DVec3::new(r.hi.x + WALL_M, p1, r.ceiling)),
                2 => (DVec3::new(p0, r.hi.y, 0.0), DVec3::new(p1, r.hi.y + WALL_M, r.ceiling)),
                _ => (DVec3::new(r.lo.x - WALL_M, p0, 0.0), DVec3::new(r.lo.x, p1, r.ceiling)),
            };
            b.aabb(m, lo, hi);
        }
    }
}

/// A straight flight of stairs along one of the hall's long walls, with its side wall.
fn stairs(b: &mut Builder, rng: &mut impl Rng, hall: &Room, placed: &mut Vec<(DVec2, f64)>) {
    let m = material(rng, class::BUILDING);
    let (rise, run) = (uni(rng, 0.15, 0.18), uni(rng, 0.28, 0.32));
    let steps = ((hall.ceiling.min(4.0) - 0.5) / rise) as usize;
    let width = uni(rng, 1.2, 2.0);
    let len = steps as f64 * run;
    let x0 = uni(rng, hall.lo.x + 1.0, (hall.hi.x - len - 1.0).max(hall.lo.x + 1.0));
    let (y0, y1) = if chance(rng, 0.5) { (hall.lo.y, hall.lo.y + width) } else { (hall.hi.y - width, hall.hi.y) };
    for k in 0..steps {
        let x = x0 + k as f64 * run;
        b.aabb(m, DVec3::new(x, y0, 0.0), DVec3::new(x + run, y1, (k + 1) as f64 * rise));
    }
    let inner = if y0 == hall.lo.y { y1 } else { y0 };
    b.aabb(m, DVec3::new(x0, inner - 0.025, 0.0), DVec3::new(x0 + len, inner + 0.025, 0.9 + steps as f64 * rise));
    let c = DVec2::new(x0 + len * 0.5, 0.5 * (y0 + y1));
    placed.push((c, 0.5 * len + 0.5));
}

/// The farthest each kind of [`furnish`]'s things reaches from where it stands, m (shelf,
/// display case, mannequin, table, plant, kiosk, info stand, bench, coat stand, bin, crates,
/// counter: half their longest diagonal at the largest size drawn, a table with its chairs).
const REACH_M: [f64; 12] = [1.3, 0.95, 0.35, 1.25, 0.85, 0.65, 0.55, 1.15, 0.25, 0.4, 0.6, 1.55];

/// Things placed in a room: by zone in the halls and rooms, along the walls in corridors; along
/// a service aisle (its centre line's y) up to its edge, none reaching into it.
fn furnish(b: &mut Builder, rng: &mut impl Rng, r: &Room, placed: &mut Vec<(DVec2, f64)>, aisle: Option<(f64, f64)>, counts: &mut BTreeMap<&'static str, usize>) {
    let n = (r.area() / if r.corridor { uni(rng, 4.0, 10.0) } else { uni(rng, 3.0, 6.0) }) as usize;
    // A zone's weights over: shelf, display case, mannequin, table, plant, kiosk, info stand,
    // bench, coat stand, bin, crates, counter.
    let zone: [f64; 12] = if r.corridor {
        [0.05, 0.05, 0.08, 0.0, 0.22, 0.06, 0.17, 0.08, 0.1, 0.12, 0.07, 0.0]
    } else {
        match pick(rng, &[0.3, 0.3, 0.3, 0.1]) {
            0 => [0.14, 0.16, 0.36, 0.0, 0.1, 0.04, 0.08, 0.0, 0.06, 0.04, 0.01, 0.01],
            1 => [0.02, 0.04, 0.08, 0.2, 0.24, 0.04, 0.1, 0.04, 0.14, 0.08, 0.01, 0.01],
            2 => [0.02, 0.04, 0.15, 0.02, 0.2, 0.12, 0.18, 0.05, 0.12, 0.09, 0.005, 0.005],
            _ => [0.3, 0.02, 0.05, 0.02, 0.05, 0.02, 0.02, 0.02, 0.02, 0.08, 0.4, 0.0],
        }
    };
    for _ in 0..n {
        for _ in 0..30 {
            let q = if r.corridor {
                // Along a wall.
                let along_x = r.hi.x - r.lo.x > r.hi.y - r.lo.y;
                let side = chance(rng, 0.5);
                if along_x {
                    DVec2::new(uni(rng, r.lo.x + 1.0, r.hi.x - 1.0), if side { r.lo.y + 0.45 } else { r.hi.y - 0.45 })
                } else {
                    DVec2::new(if side { r.lo.x + 0.45 } else { r.hi.x - 0.45 }, uni(rng, r.lo.y + 1.0, r.hi.y - 1.0))
                }
            } else {
                DVec2::new(uni(rng, r.lo.x + 0.7, r.hi.x - 0.7), uni(rng, r.lo.y + 0.7, r.hi.y - 0.7))
            };
            if placed.iter().any(|(c, rr)| c.distance(q) < rr + 1.1) || near_opening(r, q, 2.0) {
                continue;
            }
            // Against a wall things face into the room; elsewhere anywhere.
            let yaw = if r.corridor { wall_facing(r, q) } else { (rng.random::<f64>() * 4.0).floor() * FRAC_PI_2 + uni(rng, -0.2, 0.2) };
            let kind = pick(rng, &zone);
            // Things line the aisle, none reaching into it.
            if aisle.is_some_and(|(y, _)| (q.y - y).abs() < AISLE_HALF_M + REACH_M[kind] + 0.1) {
                continue;
            }
            let (what, rad) = match kind {
                0 => ("shelf", things::shelf(b, rng, q, 0.0, yaw + FRAC_PI_2)),
                1 => ("display case", things::display_case(b, rng, q, 0.0, yaw)),
                2 => ("mannequin", things::mannequin(b, rng, q, 0.0, yaw)),
                3 => ("table", things::table(b, rng, q, 0.0, yaw)),
                4 => ("plant", things::planter(b, rng, q, 0.0, yaw)),
                5 => ("kiosk", things::kiosk(b, rng, q, 0.0, yaw)),
                6 => ("info stand", things::info_stand(b, rng, q, 0.0, yaw)),
                7 => ("bench", things::bench(b, rng, q, 0.0, yaw)),
                8 => ("coat stand", things::coat_stand(b, rng, q, 0.0)),
                9 => ("bin", things::bin(b, rng, q, 0.0, yaw)),
                10 => ("crates", things::crates(b, rng, q, 0.0, yaw)),
                _ => ("counter", counter(b, rng, q, yaw)),
            };
            count(counts, what);
            placed.push((q, rad));
            break;
        }
    }
}

/// The direction from a corridor's nearest long wall into the corridor.
fn wall_facing(r: &Room, q: DVec2) -> f64 {
    let along_x = r.hi.x - r.lo.x > r.hi.y - r.lo.y;
    if along_x {
        if q.y - r.lo.y < r.hi.y - q.y { FRAC_PI_2 } else { -FRAC_PI_2 }
    } else if q.x - r.lo.x < r.hi.x - q.x {
        0.0
    } else {
        PI
    }
}

/// Whether `q` is within `pad` of one of the room's openings (kept clear to pass through).
fn near_opening(r: &Room, q: DVec2, pad: f64) -> bool {
    (0..4).any(|edge| {
        r.openings[edge].iter().any(|&(a, z)| {
            let (along, off) = match edge {
                0 => (q.x, q.y - r.lo.y),
                1 => (q.y, r.hi.x - q.x),
                2 => (q.x, r.hi.y - q.y),
                _ => (q.y, q.x - r.lo.x),
            };
            off < pad && along > a - pad && along < z + pad
        })
    })
}

/// A reception or shop counter, 1.0-1.15 m tall, 1.5-3 m long.
fn counter(b: &mut Builder, rng: &mut impl Rng, q: DVec2, yaw: f64) -> f64 {
    let m = material(rng, class::OTHER_OBJECT);
    let len = uni(rng, 1.5, 3.0);
    b.cuboid(m, q.extend(0.0), DVec3::new(0.6, len, uni(rng, 1.0, 1.15)), yaw);
    0.5 * len
}
