//! The things the worlds are furnished with, each a few boxes, cylinders and lumpy ellipsoids at
//! its real size (street furniture after common municipal catalogue sizes; indoor furniture
//! after common retail and office sizes), each with its SemanticKITTI class and a reflectance
//! drawn per thing. Every function places one thing standing on ground height `g` at `p`, facing
//! `yaw`, and returns its footprint's radius (m) for spacing.

use super::shapes::{Builder, Material, Place, Seat};
use super::{at, chance, uni};
use glam::{DVec2, DVec3};
use rand::{Rng, RngExt};

/// SemanticKITTI classes (`semantic-kitti.yaml`).
pub mod class {
    pub const CAR: u16 = 10;
    pub const BICYCLE: u16 = 11;
    pub const TRUCK: u16 = 18;
    /// Indoor robots and carts.
    pub const OTHER_VEHICLE: u16 = 20;
    /// A person riding a bicycle (the bicycle itself is [`BICYCLE`]).
    pub const BICYCLIST: u16 = 31;
    pub const ROAD: u16 = 40;
    pub const SIDEWALK: u16 = 48;
    pub const OTHER_GROUND: u16 = 49;
    pub const BUILDING: u16 = 50;
    pub const FENCE: u16 = 51;
    /// Stalls, booths, awnings and parasols: what SemanticKITTI labels other-structure.
    pub const OTHER_STRUCTURE: u16 = 52;
    pub const LANE_MARKING: u16 = 60;
    pub const VEGETATION: u16 = 70;
    pub const TRUNK: u16 = 71;
    pub const TERRAIN: u16 = 72;
    pub const POLE: u16 = 80;
    pub const TRAFFIC_SIGN: u16 = 81;
    pub const OTHER_OBJECT: u16 = 99;
}

/// A material of `class` with a reflectance drawn from the range typical of it (near
/// infrared, 905 nm: vegetation bright, asphalt dark, paint and plastics anywhere between,
/// retro-reflective signs brightest).
pub fn material(rng: &mut impl Rng, class: u16) -> Material {
    let (lo, hi) = match class {
        class::ROAD => (0.06, 0.2),
        class::SIDEWALK | class::OTHER_GROUND => (0.12, 0.45),
        class::BUILDING => (0.1, 0.8),
        class::FENCE | class::OTHER_STRUCTURE => (0.1, 0.6),
        class::LANE_MARKING => (0.5, 0.8),
        class::VEGETATION => (0.35, 0.7),
        class::TRUNK => (0.15, 0.4),
        class::TERRAIN => (0.25, 0.6),
        class::POLE => (0.1, 0.6),
        class::TRAFFIC_SIGN => (0.5, 0.95),
        class::CAR | class::TRUCK => (0.05, 0.8),
        class::BICYCLE => (0.05, 0.6),
        _ => (0.05, 0.8),
    };
    Material::new(class, uni(rng, lo, hi))
}

fn lumps(rng: &mut impl Rng) -> impl FnMut() -> f64 + '_ {
    move || uni(rng, -1.0, 1.0)
}

/// A tree: trunk and canopy; now and then a young one whose canopy starts at head height.
pub fn tree(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64) -> f64 {
    let young = chance(rng, 0.3);
    let r_trunk = if young { uni(rng, 0.05, 0.1) } else { uni(rng, 0.12, 0.28) };
    let clear = if young { uni(rng, 1.4, 2.0) } else { uni(rng, 2.2, 3.8) };
    let rc = if young { uni(rng, 0.6, 1.1) } else { uni(rng, 1.4, 3.0) };
    let rz = rc * uni(rng, 0.8, 1.3);
    let trunk = material(rng, class::TRUNK);
    b.frustum(trunk, p.extend(g), r_trunk, r_trunk * 0.7, clear + rz, 8);
    let leaves = material(rng, class::VEGETATION);
    let rings = if young { 4 } else { 5 };
    b.ellipsoid(leaves, p.extend(g + clear + rz), DVec3::new(rc, rc * uni(rng, 0.8, 1.2), rz), rings, 0.18, lumps(rng));
    r_trunk.max(0.3)
}

/// A bush or hedge piece, 0.5-2 m tall.
pub fn bush(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64) -> f64 {
    let rx = uni(rng, 0.25, 0.7);
    let ry = rx * uni(rng, 0.7, 1.3);
    let h = uni(rng, 0.5, 2.0);
    let m = material(rng, class::VEGETATION);
    b.ellipsoid(m, p.extend(g + h * 0.5), DVec3::new(rx, ry, h * 0.5), 4, 0.2, lumps(rng));
    rx.max(ry)
}

/// A planter (box or tub) with a bush in it.
pub fn planter(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let s = uni(rng, 0.5, 1.1);
    let h = uni(rng, 0.35, 0.7);
    let m = material(rng, class::OTHER_OBJECT);
    if chance(rng, 0.5) {
        b.cuboid(m, p.extend(g), DVec3::new(s, s, h), yaw);
    } else {
        b.frustum(m, p.extend(g), s * 0.4, s * 0.5, h, 10);
    }
    let rx = s * uni(rng, 0.35, 0.6);
    let hb = uni(rng, 0.4, 1.3);
    let leaves = material(rng, class::VEGETATION);
    b.ellipsoid(leaves, p.extend(g + h + hb * 0.45), DVec3::new(rx, rx, hb * 0.5), 4, 0.2, lumps(rng));
    s * 0.75
}

/// A lamp post (4-8 m) with its arm over `yaw`.
pub fn lamp_post(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let h = uni(rng, 4.0, 8.0);
    let r = uni(rng, 0.06, 0.12);
    let m = material(rng, class::POLE);
    b.frustum(m, p.extend(g), r, r * 0.7, h, 8);
    let arm = uni(rng, 0.6, 1.8);
    b.rod(m, p.extend(g + h - 0.1), at(p, yaw, arm, g + h), 0.04, 5);
    b.cuboid(m, at(p, yaw, arm, g + h - 0.25), DVec3::new(0.5, 0.25, 0.2), yaw);
    0.3
}

/// A sign post (2-3.2 m) with a plate or two.
pub fn sign_post(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let h = uni(rng, 2.0, 3.2);
    let pole = material(rng, class::POLE);
    b.cylinder(pole, p.extend(g), uni(rng, 0.03, 0.05), h, 6);
    let sign = material(rng, class::TRAFFIC_SIGN);
    let w = uni(rng, 0.4, 0.8);
    let plates = if chance(rng, 0.3) { 2 } else { 1 };
    for k in 0..plates {
        let top = h - k as f64 * (w + 0.1);
        b.cuboid(sign, at(p, yaw, 0.06, g + top - w), DVec3::new(0.03, w, w), yaw);
    }
    0.3
}

/// A bollard, 0.8-1.2 m.
pub fn bollard(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64) -> f64 {
    let h = uni(rng, 0.8, 1.2);
    let r = uni(rng, 0.06, 0.15);
    let m = material(rng, class::OTHER_OBJECT);
    if chance(rng, 0.3) {
        b.cuboid(m, p.extend(g), DVec3::new(2.0 * r, 2.0 * r, h), uni(rng, 0.0, 1.6));
    } else {
        b.cylinder(m, p.extend(g), r, h, 8);
    }
    r.max(0.2)
}

/// A litter bin (round or square), 0.8-1.3 m.
pub fn bin(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let h = uni(rng, 0.8, 1.3);
    let r = uni(rng, 0.2, 0.4);
    let m = material(rng, class::OTHER_OBJECT);
    if chance(rng, 0.5) {
        b.cylinder(m, p.extend(g), r, h, 10);
    } else {
        b.cuboid(m, p.extend(g), DVec3::new(2.0 * r, 1.6 * r, h), yaw);
    }
    r
}

/// A parking meter or ticket pillar, 1.2-1.7 m.
pub fn meter(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let m = material(rng, class::OTHER_OBJECT);
    let h = uni(rng, 1.2, 1.7);
    if chance(rng, 0.5) {
        b.cylinder(m, p.extend(g), 0.05, h - 0.4, 6);
        b.cuboid(m, p.extend(g + h - 0.45), DVec3::new(0.25, 0.3, 0.45), yaw);
    } else {
        b.cuboid(m, p.extend(g), DVec3::new(0.35, 0.5, h), yaw);
    }
    0.3
}

/// A utility cabinet, 1.0-1.7 m tall, 0.5-1.1 m wide.
pub fn cabinet(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let (w, d, h) = (uni(rng, 0.5, 1.1), uni(rng, 0.3, 0.55), uni(rng, 1.0, 1.7));
    let m = material(rng, class::OTHER_OBJECT);
    b.cuboid(m, p.extend(g), DVec3::new(d, w, h), yaw);
    0.5 * w.max(d)
}

/// A bench facing `yaw` (seat 0.45 m, back 0.85 m).
pub fn bench(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let len = uni(rng, 1.4, 2.2);
    let m = material(rng, class::OTHER_OBJECT);
    b.cuboid(m, p.extend(g + 0.4), DVec3::new(0.45, len, 0.06), yaw);
    if chance(rng, 0.7) {
        b.cuboid(m, at(p, yaw + std::f64::consts::PI, 0.22, g + 0.45), DVec3::new(0.05, len, 0.4), yaw);
    }
    for s in [-0.4, 0.4] {
        let q = p + s * len * DVec2::new(-yaw.sin(), yaw.cos());
        b.cuboid(m, q.extend(g), DVec3::new(0.4, 0.06, 0.4), yaw);
    }
    // Seats: one every 0.7 m or more along it (people keep that apart), the hips 0.05 m ahead
    // of the seat's middle.
    let n = (len / 0.7) as usize;
    for k in 0..n {
        let along = ((k as f64 + 0.5) / n as f64 - 0.5) * len;
        let q = at(p, yaw, 0.05, 0.0).truncate() + along * DVec2::new(-yaw.sin(), yaw.cos());
        b.seats.push(Seat { at: q, facing_rad: yaw, top_z_m: g + 0.46, feet_room_m: f64::INFINITY });
    }
    0.5 * len
}

/// A bicycle standing along `yaw` (wheels 0.33-0.36 m radius, saddle and bars near 1 m).
pub fn bicycle(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let m = material(rng, class::BICYCLE);
    let r = uni(rng, 0.31, 0.36);
    let base = uni(rng, 1.0, 1.15);
    let side = DVec3::new(-yaw.sin(), yaw.cos(), 0.0) * 0.02;
    let rear = at(p, yaw, -base * 0.5, g + r);
    let front = at(p, yaw, base * 0.5, g + r);
    for c in [rear, front] {
        b.rod(m, c - side, c + side, r, 10);
    }
    let crank = at(p, yaw, -0.05, g + 0.3);
    let seat = at(p, yaw, -0.2, g + uni(rng, 0.85, 1.0));
    let head = at(p, yaw, base * 0.5 - 0.1, g + uni(rng, 0.9, 1.05));
    for (a, c) in [(rear, crank), (crank, seat), (seat, head), (crank, head), (rear, seat), (head, front)] {
        b.rod(m, a, c, 0.02, 4);
    }
    let half = DVec3::new(-yaw.sin(), yaw.cos(), 0.0) * 0.3;
    b.rod(m, head - half, head + half, 0.015, 4);
    b.cuboid(m, seat, DVec3::new(0.25, 0.12, 0.05), yaw);
    0.6
}

/// A bike rack of 2-5 hoops at spacing 0.8 m along `yaw`, with bicycles in some, across it.
pub fn bike_rack(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64, bikes: &mut usize) -> f64 {
    let n = 2 + (rng.random::<f64>() * 4.0) as usize;
    let m = material(rng, class::OTHER_OBJECT);
    let along = DVec2::new(yaw.cos(), yaw.sin());
    let across = yaw + std::f64::consts::FRAC_PI_2;
    for k in 0..n {
        let q = p + (k as f64 - (n as f64 - 1.0) * 0.5) * 0.8 * along;
        let a = at(q, across, -0.35, g);
        let c = at(q, across, 0.35, g);
        b.rod(m, a, a + DVec3::Z * 0.8, 0.025, 5);
        b.rod(m, c, c + DVec3::Z * 0.8, 0.025, 5);
        b.rod(m, a + DVec3::Z * 0.8, c + DVec3::Z * 0.8, 0.025, 5);
        if chance(rng, 0.6) {
            let facing = across + if chance(rng, 0.5) { 0.0 } else { std::f64::consts::PI };
            bicycle(b, rng, q + 0.1 * along, g, facing);
            *bikes += 1;
        }
    }
    0.4 * n as f64 + 0.4
}

/// A fire hydrant, 0.6-0.9 m.
pub fn hydrant(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64) -> f64 {
    let m = material(rng, class::OTHER_OBJECT);
    let h = uni(rng, 0.6, 0.9);
    b.cylinder(m, p.extend(g), 0.12, h, 8);
    b.ellipsoid(m, p.extend(g + h), DVec3::new(0.1, 0.1, 0.08), 3, 0.0, || 0.0);
    0.2
}

/// A post box or newspaper box, 1.0-1.5 m.
pub fn post_box(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let m = material(rng, class::OTHER_OBJECT);
    let h = uni(rng, 1.0, 1.5);
    if chance(rng, 0.5) {
        b.cylinder(m, p.extend(g), uni(rng, 0.25, 0.35), h, 10);
    } else {
        b.cuboid(m, p.extend(g), DVec3::new(uni(rng, 0.4, 0.6), uni(rng, 0.4, 0.6), h), yaw);
    }
    0.35
}

/// A ticket machine, vending machine or kiosk terminal: 1.5-1.95 m, 0.5-1.0 m wide.
pub fn kiosk(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let m = material(rng, class::OTHER_OBJECT);
    let (w, d, h) = (uni(rng, 0.5, 1.0), uni(rng, 0.35, 0.8), uni(rng, 1.5, 1.95));
    b.cuboid(m, p.extend(g), DVec3::new(d, w, h), yaw);
    0.5 * w.max(d)
}

/// A folding sign board (A-frame), 0.8-1.1 m.
pub fn a_frame(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let m = material(rng, class::OTHER_OBJECT);
    let (w, h) = (uni(rng, 0.5, 0.7), uni(rng, 0.8, 1.1));
    let side = DVec2::new(-yaw.sin(), yaw.cos()) * w * 0.5;
    for s in [-1.0, 1.0] {
        let foot = at(p, yaw, s * 0.25, g);
        let top = p.extend(g + h);
        b.quad(m, [foot - side.extend(0.0), foot + side.extend(0.0), top + side.extend(0.0), top - side.extend(0.0)]);
    }
    0.4
}

/// A bus shelter facing `yaw`: roof, back panel, one side panel.
pub fn shelter(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let m = material(rng, class::OTHER_OBJECT);
    let (len, d, h) = (uni(rng, 3.0, 5.0), uni(rng, 1.2, 1.6), uni(rng, 2.3, 2.6));
    b.cuboid(m, at(p, yaw, 0.0, g + h), DVec3::new(d, len, 0.1), yaw);
    b.cuboid(m, at(p, yaw, -d * 0.5, g + 0.1), DVec3::new(0.04, len, h - 0.1), yaw);
    let side = DVec2::new(-yaw.sin(), yaw.cos()) * (len * 0.5);
    b.cuboid(m, (p + side).extend(g + 0.1), DVec3::new(d, 0.04, h - 0.1), yaw);
    for s in [-1.0, 1.0] {
        b.cylinder(m, at(p + s * side, yaw, d * 0.45, g), 0.04, h, 6);
    }
    if chance(rng, 0.6) {
        bench(b, rng, at(p, yaw, -d * 0.2, 0.0).truncate(), g, yaw);
    }
    // Places: under the roof before the bench, facing the road (people waiting for the bus,
    // the roof over their heads and the panels behind them).
    counter_places(b, p, yaw, len, d * 0.3, yaw);
    0.5 * len
}

/// A fence from `a` to `c` (posts every 2-2.5 m, two or three rails, or solid panels).
pub fn fence(b: &mut Builder, rng: &mut impl Rng, a: DVec2, c: DVec2, g: f64) {
    let m = material(rng, class::FENCE);
    let h = uni(rng, 0.9, 1.6);
    let len = a.distance(c);
    if len < 0.1 {
        return;
    }
    let dir = (c - a) / len;
    if chance(rng, 0.3) {
        let n = DVec2::new(-dir.y, dir.x) * 0.02;
        b.quad(m, [(a + n).extend(g), (c + n).extend(g), (c + n).extend(g + h), (a + n).extend(g + h)]);
        return;
    }
    let posts = (len / uni(rng, 2.0, 2.5)).ceil() as usize;
    for k in 0..=posts {
        let q = a + dir * (len * k as f64 / posts as f64);
        b.cuboid(m, q.extend(g), DVec3::new(0.06, 0.06, h), dir.y.atan2(dir.x));
    }
    let rails = if chance(rng, 0.5) { 2 } else { 3 };
    for k in 0..rails {
        let z = g + h * (0.25 + 0.7 * k as f64 / (rails - 1) as f64);
        b.rod(m, a.extend(z), c.extend(z), 0.025, 4);
    }
}

/// A parked car, van or small truck along `yaw` (its body's centre at `p`).
pub fn car(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> (f64, f64) {
    let m = material(rng, class::CAR);
    let kind = rng.random::<f64>();
    // (length, width, body bottom, body height, cabin height, cabin length share, cabin offset)
    let (l, w, z0, hb, hc, share, off) = if kind < 0.45 {
        (uni(rng, 4.0, 4.9), uni(rng, 1.7, 1.85), 0.3, uni(rng, 0.5, 0.65), uni(rng, 0.45, 0.6), uni(rng, 0.45, 0.55), uni(rng, -0.3, 0.0))
    } else if kind < 0.7 {
        (uni(rng, 3.6, 4.2), uni(rng, 1.65, 1.8), 0.3, uni(rng, 0.5, 0.65), uni(rng, 0.5, 0.65), uni(rng, 0.5, 0.6), uni(rng, -0.5, -0.3))
    } else if kind < 0.88 {
        (uni(rng, 4.4, 4.9), uni(rng, 1.8, 1.95), 0.4, uni(rng, 0.6, 0.75), uni(rng, 0.55, 0.7), uni(rng, 0.55, 0.65), uni(rng, -0.3, -0.1))
    } else {
        (uni(rng, 4.8, 6.0), uni(rng, 1.9, 2.1), 0.4, uni(rng, 1.2, 1.7), 0.0, 0.0, 0.0)
    };
    b.cuboid(m, p.extend(g + z0), DVec3::new(l, w, hb), yaw);
    if hc > 0.0 {
        b.cuboid(m, at(p, yaw, off, g + z0 + hb), DVec3::new(l * share, w * 0.88, hc), yaw);
    }
    let tyre = material(rng, class::CAR);
    let side = DVec2::new(-yaw.sin(), yaw.cos());
    for fx in [-0.33, 0.33] {
        for s in [-1.0, 1.0] {
            let c = (p + DVec2::new(yaw.cos(), yaw.sin()) * (fx * l) + side * (s * (w * 0.5 - 0.12))).extend(g + 0.32);
            b.rod(tyre, c - (side * 0.11).extend(0.0), c + (side * 0.11).extend(0.0), 0.32, 10);
        }
    }
    (l, w)
}

/// A parked box truck along `yaw` (its centre at `p`): a cab (2.4-2.9 m tall) and a cargo box
/// (3.0-3.6 m tall) on a frame, 6-8.5 m long and 2.05-2.2 m wide (a delivery truck that fits a
/// parking lane), on its wheels; SemanticKITTI's truck.
pub fn truck(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> (f64, f64) {
    let m = material(rng, class::TRUCK);
    let (l, w) = (uni(rng, 6.0, 8.5), uni(rng, 2.05, 2.2));
    let cab = uni(rng, 1.7, 2.2);
    let (cab_h, box_h, floor) = (uni(rng, 2.4, 2.9), uni(rng, 3.0, 3.6), uni(rng, 0.9, 1.2));
    // The cab at the front (+x along yaw), the box behind it with a gap, a frame under both.
    b.cuboid(m, at(p, yaw, 0.5 * l - 0.5 * cab, g + 0.45), DVec3::new(cab, w, cab_h - 0.45), yaw);
    let box_l = l - cab - 0.15;
    b.cuboid(material(rng, class::TRUCK), at(p, yaw, -0.5 * l + 0.5 * box_l, g + floor), DVec3::new(box_l, w, box_h - floor), yaw);
    b.cuboid(m, at(p, yaw, 0.0, g + 0.5), DVec3::new(l - 0.3, w * 0.6, floor - 0.5), yaw);
    let tyre = material(rng, class::TRUCK);
    let side = DVec2::new(-yaw.sin(), yaw.cos());
    for fx in [0.5 * l - 0.6 * cab, -0.5 * l + 1.2] {
        for s in [-1.0, 1.0] {
            let c = (p + DVec2::new(yaw.cos(), yaw.sin()) * fx + side * (s * (w * 0.5 - 0.15))).extend(g + 0.45);
            b.rod(tyre, c - (side * 0.14).extend(0.0), c + (side * 0.14).extend(0.0), 0.45, 10);
        }
    }
    (l, w)
}

/// A mannequin (1.65-1.9 m): legs, hips, torso, arms, neck and head, on a stand now and then.
pub fn mannequin(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let m = material(rng, class::OTHER_OBJECT);
    let s = uni(rng, 0.93, 1.07);
    let g = if chance(rng, 0.3) {
        b.cylinder(m, p.extend(g), 0.25, 0.05, 10);
        g + 0.05
    } else {
        g
    };
    let side = DVec2::new(-yaw.sin(), yaw.cos());
    for k in [-1.0, 1.0] {
        let hip = (p + side * 0.1 * k * s).extend(g + 0.88 * s);
        let foot = (p + side * 0.12 * k * s).extend(g + 0.05);
        b.rod(m, foot, hip, 0.065 * s, 6);
        let shoulder = (p + side * 0.2 * k * s).extend(g + 1.4 * s);
        let hand = (p + side * 0.24 * k * s).extend(g + 0.78 * s);
        b.rod(m, shoulder, hand, 0.04 * s, 6);
    }
    b.ellipsoid(m, p.extend(g + 0.95 * s), DVec3::new(0.13, 0.18, 0.12) * s, 4, 0.0, || 0.0);
    b.ellipsoid(m, p.extend(g + 1.2 * s), DVec3::new(0.12, 0.2, 0.24) * s, 5, 0.0, || 0.0);
    b.ellipsoid(m, p.extend(g + 1.62 * s), DVec3::new(0.09, 0.08, 0.12) * s, 4, 0.0, || 0.0);
    0.35
}

/// A shelf unit along `yaw`: sides, back and 4-6 boards; 1.4-2.2 m tall.
pub fn shelf(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let m = material(rng, class::OTHER_OBJECT);
    let (len, d, h) = (uni(rng, 0.8, 2.4), uni(rng, 0.35, 0.6), uni(rng, 1.4, 2.2));
    let along = DVec2::new(yaw.cos(), yaw.sin());
    let across = yaw + std::f64::consts::FRAC_PI_2;
    b.cuboid(m, at(p, across, -d * 0.5 + 0.01, g), DVec3::new(len, 0.02, h), yaw);
    for s in [-0.5, 0.5] {
        b.cuboid(m, (p + along * (s * len)).extend(g), DVec3::new(0.03, d, h), yaw);
    }
    let boards = 4 + (rng.random::<f64>() * 3.0) as usize;
    for k in 0..boards {
        let z = g + 0.1 + (h - 0.15) * k as f64 / (boards - 1) as f64;
        b.cuboid(m, p.extend(z), DVec3::new(len, d, 0.025), yaw);
        if chance(rng, 0.6) && k + 1 < boards {
            let goods = material(rng, class::OTHER_OBJECT);
            let gh = (h - 0.15) / (boards - 1) as f64 * uni(rng, 0.4, 0.85);
            b.cuboid(goods, p.extend(z + 0.025), DVec3::new(len * uni(rng, 0.5, 0.95), d * 0.8, gh), yaw);
        }
    }
    0.5 * len
}

/// A display case: a cabinet with a box of goods on it, 0.9-1.9 m.
pub fn display_case(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let m = material(rng, class::OTHER_OBJECT);
    let (w, d) = (uni(rng, 0.5, 1.6), uni(rng, 0.5, 0.9));
    let base = uni(rng, 0.7, 1.0);
    b.cuboid(m, p.extend(g), DVec3::new(w, d, base), yaw);
    if chance(rng, 0.6) {
        let top = material(rng, class::OTHER_OBJECT);
        b.cuboid(top, p.extend(g + base), DVec3::new(w * 0.9, d * 0.9, uni(rng, 0.2, 0.9)), yaw);
    }
    0.5 * w.max(d)
}

/// The radius of a café table's foot plate (3 cm high), m.
const TABLE_FOOT_M: f64 = 0.25;

/// A table (0.72-0.76 m, or a standing table 1.05-1.15 m) with 0-4 chairs.
pub fn table(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let m = material(rng, class::OTHER_OBJECT);
    let standing = chance(rng, 0.3);
    let h = if standing { uni(rng, 1.05, 1.15) } else { uni(rng, 0.72, 0.76) };
    let r = if standing { uni(rng, 0.3, 0.4) } else { uni(rng, 0.4, 0.6) };
    b.cylinder(m, p.extend(g + h - 0.04), r, 0.04, 10);
    b.cylinder(m, p.extend(g), 0.04, h - 0.04, 6);
    b.cylinder(m, p.extend(g), TABLE_FOOT_M, 0.03, 8);
    if !standing {
        let chairs = (rng.random::<f64>() * 5.0) as usize;
        let cm = material(rng, class::OTHER_OBJECT);
        for k in 0..chairs {
            let a = yaw + k as f64 * std::f64::consts::FRAC_PI_2;
            let q = at(p, a, r + 0.3, 0.0).truncate();
            // Its seat: the hips over the middle, facing the table, the feet kept 3 cm short of
            // the table's foot.
            let feet_room_m = r + 0.3 - TABLE_FOOT_M - 0.03;
            b.seats.push(Seat { at: q, facing_rad: a + std::f64::consts::PI, top_z_m: g + 0.47, feet_room_m });
            b.cuboid(cm, q.extend(g + 0.43), DVec3::new(0.42, 0.42, 0.04), a);
            b.cuboid(cm, at(q, a, 0.2, g + 0.47), DVec3::new(0.03, 0.42, 0.42), a);
            for (dx, dy) in [(-0.18, -0.18), (0.18, -0.18), (0.18, 0.18), (-0.18, 0.18)] {
                let (s, c) = a.sin_cos();
                b.cylinder(cm, (q + DVec2::new(c * dx - s * dy, s * dx + c * dy)).extend(g), 0.015, 0.43, 4);
            }
        }
        return r + 0.55;
    }
    r
}

/// A coat stand or standing lamp, 1.6-1.9 m: a pole on a foot with a head.
pub fn coat_stand(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64) -> f64 {
    let m = material(rng, class::OTHER_OBJECT);
    let h = uni(rng, 1.6, 1.9);
    b.cylinder(m, p.extend(g), 0.22, 0.03, 8);
    b.cylinder(m, p.extend(g), 0.025, h, 6);
    if chance(rng, 0.5) {
        b.frustum(m, p.extend(g + h - 0.25), 0.2, 0.08, 0.25, 8);
    } else {
        let coat = material(rng, class::OTHER_OBJECT);
        b.ellipsoid(coat, p.extend(g + h - 0.45), DVec3::new(0.2, 0.25, 0.4), 4, 0.15, lumps(rng));
    }
    0.25
}

/// A sign or information stand: a panel on legs, 1.4-2.1 m.
pub fn info_stand(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let m = material(rng, class::OTHER_OBJECT);
    let (w, h) = (uni(rng, 0.5, 1.0), uni(rng, 1.4, 2.1));
    let ph = uni(rng, 0.6, 1.0);
    b.cuboid(m, p.extend(g + h - ph), DVec3::new(0.04, w, ph), yaw);
    let side = DVec2::new(-yaw.sin(), yaw.cos());
    for s in [-0.4, 0.4] {
        b.cylinder(m, (p + side * (s * w)).extend(g), 0.02, h - ph, 4);
    }
    0.5 * w
}

/// A stack of 1-4 crates or boxes, 0.3-1.6 m.
pub fn crates(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let mut z = g;
    let s = uni(rng, 0.4, 0.8);
    let n = 1 + (rng.random::<f64>() * 4.0) as usize;
    for _ in 0..n {
        let m = material(rng, class::OTHER_OBJECT);
        let h = uni(rng, 0.3, 0.45);
        b.cuboid(m, (p + DVec2::new(uni(rng, -0.05, 0.05), uni(rng, -0.05, 0.05))).extend(z), DVec3::new(s, s * uni(rng, 0.7, 1.0), h), yaw + uni(rng, -0.2, 0.2));
        z += h;
    }
    s * 0.7
}

/// A market stall `len` long facing `yaw`: a counter 0.85-1.0 m high (goods on it now and
/// then), a roof at 2.25-2.55 m on four posts with a valance hanging no lower than 2 m (people
/// walk under it), and a back panel in one stall of two. Who stands behind the counter shows
/// only above it, with the roof and the posts around them at their own range.
pub fn stall(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64, len: f64) -> f64 {
    let m = material(rng, class::OTHER_STRUCTURE);
    let d = uni(rng, 0.6, 0.9);
    let counter = uni(rng, 0.85, 1.0);
    let h = uni(rng, 2.25, 2.55);
    // The counter at the front; the stall reaches 1.8-2.4 m back from its front edge, room for
    // someone behind the counter.
    let depth = uni(rng, 1.8, 2.4);
    let front = at(p, yaw, depth * 0.5 - d * 0.5, g);
    b.cuboid(m, front, DVec3::new(d, len, counter), yaw);
    // Along the counter, to the stall's left.
    let side = DVec2::new(-yaw.sin(), yaw.cos());
    if chance(rng, 0.6) {
        let goods = material(rng, class::OTHER_OBJECT);
        let mut y = -len * 0.5 + 0.1;
        while y < len * 0.5 - 0.4 {
            let w = uni(rng, 0.3, 0.7).min(len * 0.5 - 0.1 - y);
            b.cuboid(goods, (front.truncate() + side * (y + w * 0.5)).extend(g + counter), DVec3::new(d * 0.8, w * 0.9, uni(rng, 0.05, 0.35)), yaw);
            y += w + uni(rng, 0.0, 0.3);
        }
    }
    for (f, l) in [(0.5, -0.5), (0.5, 0.5), (-0.5, -0.5), (-0.5, 0.5)] {
        b.cylinder(m, (at(p, yaw, f * depth, g).truncate() + side * (l * len)).extend(g), 0.03, h, 6);
    }
    let roof = material(rng, class::OTHER_STRUCTURE);
    b.cuboid(roof, p.extend(g + h), DVec3::new(depth + uni(rng, 0.2, 0.6), len + 0.2, 0.05), yaw);
    let valance = uni(rng, 0.0, h - 2.0).min(0.3);
    if valance > 0.05 {
        b.cuboid(roof, at(p, yaw, depth * 0.5 + 0.1, g + h - valance), DVec3::new(0.02, len + 0.2, valance), yaw);
    }
    if chance(rng, 0.5) {
        b.cuboid(m, at(p, yaw, -depth * 0.5, g + 0.9), DVec3::new(0.03, len, h - 0.9), yaw);
    }
    // Places: just behind the counter, facing out over it, and 0.55 m in front of it, facing
    // it.
    counter_places(b, p, yaw, len, depth * 0.5 - d - SERVING_M.min((depth - d) * 0.5), yaw);
    counter_places(b, p, yaw, len, depth * 0.5 + 0.55, yaw + std::f64::consts::PI);
    0.5 * len.max(depth)
}

/// How far behind a counter's back edge someone serving stands (their centre; midway to the
/// back where that is nearer): as close as the default `humans.clearance_m` (0.35 m) and the
/// walkable grid's cells let them, so the counter's top reaches almost to them in the range
/// image, as at a real market.
const SERVING_M: f64 = 0.55;

/// Places along a line `len` long across `yaw` through `p`, one every 0.9 m, `ahead` along
/// `yaw` from it, facing `facing_rad`.
fn counter_places(b: &mut Builder, p: DVec2, yaw: f64, len: f64, ahead: f64, facing_rad: f64) {
    let side = DVec2::new(-yaw.sin(), yaw.cos());
    let k = ((len - 0.2) / 0.9).floor().max(1.0) as usize;
    for i in 0..k {
        let y = (i as f64 + 0.5) / k as f64 - 0.5;
        b.places.push(Place { at: at(p, yaw, ahead, 0.0).truncate() + side * (y * len), facing_rad });
    }
}

/// A market booth facing `yaw`, `len` (at least 2 m) wide: a hut of boards, walls on three
/// sides up to its roof at 2.3-2.7 m, a door 0.8 m wide at one end of the back wall, its front
/// open from a counter 0.9-1.05 m high to a fascia at 1.95-2.15 m; 1.8-2.5 m deep, room
/// behind the counter for someone serving. Seen from the front, who serves shows between the
/// counter and the fascia, the back wall 0.5-1.4 m behind them and the side walls beside them,
/// as at a real market's huts.
pub fn booth(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64, len: f64) -> f64 {
    const WALL: f64 = 0.05;
    const DOOR: f64 = 0.8;
    let m = material(rng, class::OTHER_STRUCTURE);
    let depth = uni(rng, 1.8, 2.5);
    let h = uni(rng, 2.3, 2.7);
    let counter = uni(rng, 0.9, 1.05);
    let top = uni(rng, 1.95, 2.15);
    let d = uni(rng, 0.5, 0.7);
    let side = DVec2::new(-yaw.sin(), yaw.cos());
    // The back wall, the door at the end `door` (-1 or 1) across, a lintel above it at 2.05 m.
    let door = if chance(rng, 0.5) { -1.0 } else { 1.0 };
    let back = at(p, yaw, WALL * 0.5 - depth * 0.5, 0.0).truncate();
    b.cuboid(m, (back - side * (door * (WALL + DOOR) * 0.5)).extend(g), DVec3::new(WALL, len - WALL - DOOR, h), yaw);
    b.cuboid(m, (back + side * (door * (len - DOOR) * 0.5)).extend(g + 2.05), DVec3::new(WALL, DOOR, h - 2.05), yaw);
    for s in [-1.0, 1.0] {
        b.cuboid(m, (p + side * (s * (len - WALL) * 0.5)).extend(g), DVec3::new(depth, WALL, h), yaw);
    }
    let front = at(p, yaw, (depth - d) * 0.5, g);
    b.cuboid(m, front, DVec3::new(d, len - 2.0 * WALL, counter), yaw);
    b.cuboid(m, at(p, yaw, (depth - WALL) * 0.5, g + top), DVec3::new(WALL, len, h - top), yaw);
    // The roof overhangs the front.
    let over = uni(rng, 0.2, 0.6);
    let roof = material(rng, class::OTHER_STRUCTURE);
    b.cuboid(roof, at(p, yaw, over * 0.5, g + h), DVec3::new(depth + over, len + 0.2, 0.05), yaw);
    if chance(rng, 0.6) {
        let goods = material(rng, class::OTHER_OBJECT);
        let mut y = -len * 0.5 + WALL + 0.1;
        while y < len * 0.5 - WALL - 0.4 {
            let w = uni(rng, 0.3, 0.7).min(len * 0.5 - WALL - 0.1 - y);
            b.cuboid(goods, (front.truncate() + side * (y + w * 0.5)).extend(g + counter), DVec3::new(d * 0.8, w * 0.9, uni(rng, 0.05, 0.3)), yaw);
            y += w + uni(rng, 0.1, 0.5);
        }
    }
    // Places: just behind the counter (where the wall is), facing out, and 0.55 m in front,
    // facing in.
    counter_places(b, p - side * (door * DOOR * 0.5), yaw, len - 2.0 * WALL - DOOR, depth * 0.5 - d - SERVING_M.min((depth - d - WALL) * 0.5), yaw);
    counter_places(b, p, yaw, len, depth * 0.5 + 0.55, yaw + std::f64::consts::PI);
    0.5 * len.max(depth)
}

/// A beer-garden table set facing `yaw`: a table 1.8-2.2 m long, 0.72-0.78 m high, a bench
/// 0.45 m high on each side (one side now and then left out).
pub fn table_set(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64) -> f64 {
    let m = material(rng, class::OTHER_OBJECT);
    let len = uni(rng, 1.8, 2.2);
    let w = uni(rng, 0.5, 0.7);
    let h = uni(rng, 0.72, 0.78);
    let side = DVec2::new(-yaw.sin(), yaw.cos());
    // Top and two trestle legs across the table.
    b.cuboid(m, at(p, yaw, 0.0, g + h - 0.03), DVec3::new(len, w, 0.03), yaw);
    for s in [-0.4, 0.4] {
        b.cuboid(m, at(p, yaw, s * len, g), DVec3::new(0.04, w * 0.9, h - 0.03), yaw);
    }
    let off = w * 0.5 + uni(rng, 0.25, 0.35);
    for s in [-1.0, 1.0] {
        if chance(rng, 0.15) {
            continue;
        }
        let q = p + side * (s * off);
        b.cuboid(m, q.extend(g + 0.42), DVec3::new(len, 0.25, 0.03), yaw);
        // Seats on it, where the places are behind it, facing the table.
        for e in [-0.25, 0.25] {
            b.seats.push(Seat { at: at(q, yaw, e * len, 0.0).truncate(), facing_rad: (-s * side.y).atan2(-s * side.x), top_z_m: g + 0.45, feet_room_m: f64::INFINITY });
        }
        for e in [-0.4, 0.4] {
            b.cuboid(m, at(q, yaw, e * len, g), DVec3::new(0.04, 0.22, 0.42), yaw);
        }
    }
    // Places: behind each bench (half a metre off it), at a quarter of the table from its
    // middle, facing the table.
    for s in [-1.0, 1.0] {
        for e in [-0.25, 0.25] {
            let facing_rad = (-s * side.y).atan2(-s * side.x);
            b.places.push(Place { at: at(p, yaw, e * len, 0.0).truncate() + side * (s * (off + 0.125 + 0.5)), facing_rad });
        }
    }
    0.5 * len
}

/// A pavilion (a market's or beer garden's party tent) facing `yaw`, `len` along its front and
/// `depth` deep (3 m or more each): a flat roof 2.3-2.8 m up on posts at its corners and every
/// 2-3 m between, a valance round its edge; its back and ends each open, closed to rail height
/// (a low panel or a rail at 0.9-1.1 m) or walled up to the roof; now and then a high table
/// or two inside. Places under the roof, 0.6 m in from its front and its back, facing across
/// it, one every 0.9 m: people standing among its posts with the roof over their heads and
/// its sides around them at their own range, as under a real market's tents.
pub fn pavilion(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64, yaw: f64, len: f64, depth: f64) -> f64 {
    let m = material(rng, class::OTHER_STRUCTURE);
    let h = uni(rng, 2.3, 2.8);
    let (fwd, side) = (DVec2::new(yaw.cos(), yaw.sin()), DVec2::new(-yaw.sin(), yaw.cos()));
    let point = |f: f64, l: f64| p + fwd * (f * depth * 0.5) + side * (l * len * 0.5);
    let r = uni(rng, 0.025, 0.05);
    let (along, across) = ((len / uni(rng, 2.0, 3.0)).ceil().max(1.0) as usize, (depth / 3.0).ceil().max(1.0) as usize);
    for i in 0..=along {
        let l = -1.0 + 2.0 * i as f64 / along as f64;
        for f in [-1.0, 1.0] {
            b.cylinder(m, point(f, l).extend(g), r, h, 6);
        }
    }
    for j in 1..across {
        let f = -1.0 + 2.0 * j as f64 / across as f64;
        for l in [-1.0, 1.0] {
            b.cylinder(m, point(f, l).extend(g), r, h, 6);
        }
    }
    b.cuboid(m, p.extend(g + h), DVec3::new(depth + 0.1, len + 0.1, 0.05), yaw);
    let valance = uni(rng, 0.1, 0.35);
    for f in [-1.0, 1.0] {
        b.cuboid(m, (p + fwd * (f * (depth * 0.5 + 0.05))).extend(g + h - valance), DVec3::new(0.02, len + 0.1, valance), yaw);
    }
    for l in [-1.0, 1.0] {
        b.cuboid(m, (p + side * (l * (len * 0.5 + 0.05))).extend(g + h - valance), DVec3::new(depth + 0.1, 0.02, valance), yaw);
    }
    // The back and the two ends: open, to rail height or to the roof.
    let low = uni(rng, 0.9, 1.1);
    for (centre, size) in [(point(-1.0, 0.0), DVec2::new(0.03, len)), (point(0.0, -1.0), DVec2::new(depth, 0.03)), (point(0.0, 1.0), DVec2::new(depth, 0.03))] {
        match uni(rng, 0.0, 1.0) {
            u if u < 0.3 => {}
            u if u < 0.55 => b.cuboid(m, centre.extend(g), size.extend(low), yaw),
            u if u < 0.8 => {
                let half = if size.x > size.y { fwd * (size.x * 0.5) } else { side * (size.y * 0.5) };
                b.rod(m, (centre - half).extend(g + low), (centre + half).extend(g + low), 0.02, 4);
            }
            _ => b.cuboid(m, centre.extend(g), size.extend(h), yaw),
        }
    }
    if chance(rng, 0.5) {
        let t = material(rng, class::OTHER_OBJECT);
        let n = if len > 4.5 && chance(rng, 0.5) { 2 } else { 1 };
        for k in 0..n {
            let q = p + side * (len * ((k as f64 + 0.5) / n as f64 - 0.5));
            b.cylinder(t, q.extend(g), 0.03, 1.05, 6);
            b.cylinder(t, q.extend(g + 1.05), 0.3, 0.03, 10);
        }
    }
    for f in [-1.0, 1.0] {
        counter_places(b, p, yaw, len, f * (depth * 0.5 - 0.6), if f > 0.0 { yaw + std::f64::consts::PI } else { yaw });
    }
    0.5 * len.max(depth)
}

/// A parasol 2.35-2.6 m high: a pole and a shallow cone 2.4-3.2 m across whose rim is above
/// 2 m (people walk under it).
pub fn parasol(b: &mut Builder, rng: &mut impl Rng, p: DVec2, g: f64) -> f64 {
    let m = material(rng, class::OTHER_STRUCTURE);
    let h = uni(rng, 2.35, 2.6);
    let r = uni(rng, 1.2, 1.6);
    b.cylinder(m, p.extend(g), 0.025, h, 6);
    b.frustum(m, p.extend(g + h - 0.3), r, 0.05, 0.3, 12);
    0.1
}
