//! Other movers: cars driving and cyclists riding the street's oncoming lane, one after the
//! other, and cars ahead of and behind the sensor's own vehicle in its lane; delivery robots and
//! motorised carts along the indoor hall's service aisle; and the strollers and trolleys people
//! push ([`super::pushed`], [`MoverPath::Pushed`]). Each is a rigid mesh of its own (a
//! cyclist's rider and bicycle together), held level, with its own instance id and per-beam
//! velocity in the frames; the lanes' movers follow the ground under them (the raised
//! crossings' ramps), a pushed thing its pusher's floor.
//!
//! A lane's movers drive by the Intelligent Driver Model (Treiber, Hennecke and Helbing 2000):
//! each keeps a time gap to the one ahead and stops at a crossing while somebody is on it or
//! about to step on it; the people's plans are known before the movers drive. Speeds and
//! positions come from one table per mover of constant-acceleration steps, so a position and
//! its velocity are exact derivatives of each other. Indoors (a lane with [`Lane::yield_m`]) a
//! mover also stops behind anybody in its path, the sensor's carrier included. In the sensor's
//! lane the sensor's vehicle is one more to keep a time gap to; it keeps its own speed, so a
//! car that it would still run into (one slower ahead of it) is left out, as is a mover that
//! would still touch a person (somebody stepping out under its bumper). The lane wraps: a mover driving off one end of
//! the street comes back in at the other, farther from the sensor than it sees
//! (`street::MARGIN_M`), so a long sequence keeps its traffic.

use super::shapes::Builder;
use super::things::{self, class, material};
use super::{chance, uni};
use crate::scene::Environment;
use glam::{DVec2, DVec3};
use rand::{Rng, RngExt};
use std::sync::Arc;

/// What a mover is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum MoverKind {
    Car,
    Cyclist,
    /// A delivery robot (SemanticKITTI's other-vehicle, 20).
    Robot,
    /// A motorised service cart with its load (other-vehicle, 20).
    Cart,
    /// A stroller a person pushes along the street (other-object, 99).
    Stroller,
    /// A trolley a person pushes indoors (other-object, 99).
    Trolley,
}

impl MoverKind {
    pub fn name(self) -> &'static str {
        match self {
            MoverKind::Car => "car",
            MoverKind::Cyclist => "cyclist",
            MoverKind::Robot => "robot",
            MoverKind::Cart => "cart",
            MoverKind::Stroller => "stroller",
            MoverKind::Trolley => "trolley",
        }
    }
}

/// A lane the movers follow one another along: world x from `x0` to `x1` at `y`, toward +x
/// (`dir` 1) or -x (-1); leaving one end a mover comes back in at the other.
#[derive(Clone, Debug)]
pub struct Lane {
    pub y: f64,
    pub dir: f64,
    pub x0: f64,
    pub x1: f64,
    /// Height of the road, m.
    pub road_z: f64,
    /// Raised crossings across the road: centre x and width; their ramps' length and the
    /// height they rise to above the road.
    pub crossings: Vec<(f64, f64)>,
    pub ramp_m: f64,
    pub rise_m: f64,
    /// Half the road's width: somebody within it (or [`WAITING_M`] of its curbs) by a
    /// crossing is on it.
    pub half_road_m: f64,
    /// Where cyclists ride: this far beside the lane's centre (toward its curb), m.
    pub bike_offset_m: f64,
    /// Indoors: somebody within this distance of the lane's centre line ahead of a mover is
    /// an obstacle it stops behind (0: nobody, as in the street, where people cross at the
    /// crossings), m.
    pub yield_m: f64,
    /// How far from the sensor, along the lane, the first mover of each kind passes it
    /// halfway through the sequence (in a lane without the sensor's vehicle), m.
    pub pass_m: (f64, f64),
}

/// How far beside a crossing or its curbs a person counts as about to step on it, m.
pub const WAITING_M: f64 = 1.0;

/// Where a mover stops before a crossing it yields at: its front this far from the crossing, m.
const STOP_LINE_M: f64 = 1.5;

/// A person's radius in the movers' check, m (a mover's footprint grown by it never holds a
/// person's position).
pub const PERSON_RADIUS_M: f64 = 0.35;

/// The sensor's own vehicle in its lane: the half of its footprint (its centre under the
/// sensor) and its constant speed.
#[derive(Clone, Copy, Debug)]
pub struct Ego {
    pub half: DVec2,
    pub speed_mps: f64,
}

/// The sensor's vehicle's half length and half width, m (a car's, the sensor over its middle).
pub const EGO_HALF_M: DVec2 = DVec2::new(2.3, 0.95);

/// A box on the floor turned to a heading: a mover's footprint at an instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    /// Its centre, world frame, m.
    pub centre: DVec2,
    /// The way its length points, radians counter-clockwise from +x.
    pub heading_rad: f64,
    /// Half its length (along the heading) and half its width, m.
    pub half: DVec2,
}

impl Footprint {
    /// Its unit axes: along the heading, and to the left of it.
    fn axes(&self) -> (DVec2, DVec2) {
        let (s, c) = self.heading_rad.sin_cos();
        (DVec2::new(c, s), DVec2::new(-s, c))
    }
    /// Its corners.
    pub fn corners(&self) -> [DVec2; 4] {
        let (ax, ay) = self.axes();
        [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)].map(|(a, b)| self.centre + ax * (a * self.half.x) + ay * (b * self.half.y))
    }
    /// How far `p` is from it, m; 0 inside.
    pub fn gap(&self, p: DVec2) -> f64 {
        let (ax, ay) = self.axes();
        let d = p - self.centre;
        let local = DVec2::new(ax.dot(d), ay.dot(d)).abs();
        (local - self.half).max(DVec2::ZERO).length()
    }
    /// Whether it overlaps an axis-aligned box of half size `half` centred at `p`: the two
    /// boxes apart along none of their four axes.
    pub fn overlaps(&self, p: DVec2, half: DVec2) -> bool {
        let d = p - self.centre;
        let (u, v) = self.axes();
        [DVec2::X, DVec2::Y, u, v].iter().all(|a| {
            let own = self.half.x * u.dot(*a).abs() + self.half.y * v.dot(*a).abs();
            d.dot(*a).abs() < own + half.x * a.x.abs() + half.y * a.y.abs()
        })
    }
    /// Whether it and `other` are apart by their circumscribed circles and `room_m` more (the
    /// pushed things' rule among themselves: no room where the world checks it).
    pub fn apart(&self, other: &Footprint, room_m: f64) -> bool {
        self.centre.distance(other.centre) > self.half.length() + other.half.length() + room_m
    }
}

/// The drive table's step, and a pushed thing's pose table's, s.
pub const STEP_S: f64 = 0.05;

impl Lane {
    pub fn length(&self) -> f64 {
        self.x1 - self.x0
    }
    /// World x of lane position `u` (m along the direction of travel from the lane's start).
    pub fn x_of(&self, u: f64) -> f64 {
        let w = u.rem_euclid(self.length());
        if self.dir > 0.0 { self.x0 + w } else { self.x1 - w }
    }
    /// Lane position of world x.
    pub fn u_of(&self, x: f64) -> f64 {
        if self.dir > 0.0 { x - self.x0 } else { self.x1 - x }
    }
    /// Height of the ground at world x, and its slope dz/dx.
    pub fn ground(&self, x: f64) -> (f64, f64) {
        for &(c, w) in &self.crossings {
            let d = (x - c).abs() - w * 0.5;
            if d <= 0.0 {
                return (self.road_z + self.rise_m, 0.0);
            }
            if d < self.ramp_m {
                let slope = self.rise_m / self.ramp_m;
                return (self.road_z + self.rise_m - slope * d, -slope * (x - c).signum());
            }
        }
        (self.road_z, 0.0)
    }
    /// Whether somebody at `p` is on crossing `c` (or waiting at its curbs).
    fn on_crossing(&self, c: (f64, f64), p: DVec2) -> bool {
        (p.x - c.0).abs() < c.1 * 0.5 + WAITING_M && p.y.abs() < self.half_road_m + WAITING_M
    }
}

/// How a mover drives (the Intelligent Driver Model's parameters).
#[derive(Clone, Copy, Debug)]
pub struct Driver {
    /// Desired speed, m/s.
    pub speed_mps: f64,
    /// Comfortable acceleration and deceleration, m/s^2.
    pub accel: f64,
    pub decel: f64,
    /// Time gap to the one ahead, s, and the gap kept when stopped, m.
    pub headway_s: f64,
    pub min_gap_m: f64,
}

/// A mover not yet in a sequence: its mesh (body frame: x forward, z up from the ground under
/// it) and how it drives.
#[derive(Clone, Debug)]
pub struct MoverSpec {
    pub kind: MoverKind,
    pub mesh: Environment,
    /// Half its length and half its width, m.
    pub half: DVec2,
    pub driver: Driver,
}

/// A lane's traffic before it drives: the lane, the movers for it in placing order, the
/// sensor's vehicle where the lane is the sensor's, and what the sequence's XML counts its
/// movers as (None: by kind, "car driving", "robot driving").
pub struct LaneTraffic {
    pub lane: Arc<Lane>,
    pub movers: Vec<MoverSpec>,
    pub ego: Option<Ego>,
    pub count_as: Option<&'static str>,
}

/// A mover of a sequence.
#[derive(Clone, Debug)]
pub struct Mover {
    pub kind: MoverKind,
    /// Body-frame vertices, and where they start in the world's environment.
    pub local: Vec<DVec3>,
    pub first_vertex: usize,
    pub half: DVec2,
    /// How it moves.
    pub path: MoverPath,
}

/// How a mover moves: along a lane, or pushed by a person.
#[derive(Clone, Debug)]
pub enum MoverPath {
    Lane(LanePath),
    Pushed(PushedPath),
}

/// A drive along a lane.
#[derive(Clone, Debug)]
pub struct LanePath {
    pub lane: Arc<Lane>,
    /// World y of its centre line (cyclists ride by the curb), m.
    pub y: f64,
    /// Lane position of its centre at time 0, m.
    pub u0: f64,
    /// The drive: per step of [`STEP_S`] from time 0, distance since time 0, speed and the
    /// step's constant acceleration.
    table: Vec<[f64; 3]>,
}

impl LanePath {
    /// Distance driven since time 0 and speed at `t_s` (at the table's end speeds held
    /// before 0 and after its last step).
    pub fn travel(&self, t_s: f64) -> (f64, f64) {
        let Some(first) = self.table.first() else { return (0.0, 0.0) };
        if t_s <= 0.0 {
            return (first[1] * t_s, first[1]);
        }
        let k = ((t_s / STEP_S) as usize).min(self.table.len() - 1);
        let [s, v, a] = self.table[k];
        let tau = t_s - k as f64 * STEP_S;
        if k + 1 == self.table.len() && tau > STEP_S {
            // Past the table: its last step, then the speed it ends with.
            let (s1, v1) = (s + v * STEP_S + 0.5 * a * STEP_S * STEP_S, (v + a * STEP_S).max(0.0));
            return (s1 + v1 * (tau - STEP_S), v1);
        }
        (s + v * tau + 0.5 * a * tau * tau, v + a * tau)
    }
    fn position(&self, t_s: f64) -> DVec3 {
        let x = self.lane.x_of(self.u0 + self.travel(t_s).0);
        DVec3::new(x, self.y, self.lane.ground(x).0)
    }
    fn velocity(&self, t_s: f64) -> DVec3 {
        let (s, v) = self.travel(t_s);
        let x = self.lane.x_of(self.u0 + s);
        let vx = self.lane.dir * v;
        DVec3::new(vx, 0.0, self.lane.ground(x).1 * vx)
    }
}

impl Mover {
    /// Its lane, where it drives one.
    pub fn lane(&self) -> Option<&LanePath> {
        match &self.path {
            MoverPath::Lane(l) => Some(l),
            MoverPath::Pushed(_) => None,
        }
    }
    /// Centre of its footprint on the ground at `t_s`, world frame.
    pub fn position(&self, t_s: f64) -> DVec3 {
        match &self.path {
            MoverPath::Lane(l) => l.position(t_s),
            MoverPath::Pushed(p) => p.pose(t_s).0,
        }
    }
    /// Velocity of its centre at `t_s`, world frame, m/s (up and down the crossings' ramps
    /// included); the exact derivative of [`Mover::position`].
    pub fn velocity(&self, t_s: f64) -> DVec3 {
        match &self.path {
            MoverPath::Lane(l) => l.velocity(t_s),
            MoverPath::Pushed(p) => p.rates(t_s).0,
        }
    }
    /// Heading at `t_s`, radians counter-clockwise from +x.
    pub fn heading_rad(&self, t_s: f64) -> f64 {
        match &self.path {
            MoverPath::Lane(l) => {
                if l.lane.dir > 0.0 { 0.0 } else { std::f64::consts::PI }
            }
            MoverPath::Pushed(p) => p.pose(t_s).1,
        }
    }
    /// Its turning rate about the vertical at `t_s`, rad/s (the derivative of the heading; 0
    /// in a lane).
    pub fn yaw_rate_rps(&self, t_s: f64) -> f64 {
        match &self.path {
            MoverPath::Lane(_) => 0.0,
            MoverPath::Pushed(p) => p.rates(t_s).1,
        }
    }
    /// Its vertices in the world at `t_s`, into `out` (as many as `local`).
    pub fn place(&self, t_s: f64, out: &mut [DVec3]) {
        let p = self.position(t_s);
        let (s, c) = self.heading_rad(t_s).sin_cos();
        for (o, l) in out.iter_mut().zip(&self.local) {
            *o = p + DVec3::new(c * l.x - s * l.y, s * l.x + c * l.y, l.z);
        }
    }
    /// Whether a person at `p` (floor plane) touches its footprint at `t_s`: within
    /// [`PERSON_RADIUS_M`] of a pushed thing's, or its box that far around overlapping a lane
    /// mover's.
    pub fn touches(&self, t_s: f64, p: DVec2) -> bool {
        match &self.path {
            MoverPath::Lane(_) => self.overlaps(t_s, p, DVec2::splat(PERSON_RADIUS_M)),
            MoverPath::Pushed(_) => self.gap(t_s, p) < PERSON_RADIUS_M,
        }
    }
    /// The person pushing it, where it is pushed: their index in the sequence's plan.
    pub fn pusher(&self) -> Option<usize> {
        match &self.path {
            MoverPath::Pushed(p) => Some(p.pusher),
            MoverPath::Lane(_) => None,
        }
    }
    /// Its footprint at `t_s`: its box turned to its heading, floor plane.
    pub fn footprint(&self, t_s: f64) -> Footprint {
        Footprint { centre: self.position(t_s).truncate(), heading_rad: self.heading_rad(t_s), half: self.half }
    }
    /// Its footprint's corners at `t_s` (turned to its heading), floor plane.
    pub fn corners(&self, t_s: f64) -> [DVec2; 4] {
        self.footprint(t_s).corners()
    }
    /// How far `p` is from its footprint at `t_s` (turned to its heading), m; 0 inside.
    fn gap(&self, t_s: f64, p: DVec2) -> f64 {
        self.footprint(t_s).gap(p)
    }
    /// Whether its footprint at `t_s` overlaps a box of half size `half` centred at `p`,
    /// axis-aligned (a lane runs along x; a pushed thing's footprint is turned to its heading).
    pub fn overlaps(&self, t_s: f64, p: DVec2, half: DVec2) -> bool {
        match &self.path {
            MoverPath::Lane(_) => {
                let d = (p - self.position(t_s).truncate()).abs();
                d.x < self.half.x + half.x && d.y < self.half.y + half.y
            }
            MoverPath::Pushed(_) => self.footprint(t_s).overlaps(p, half),
        }
    }
}

/// A pushed thing's path: its footprint's centre on the ground and its heading at rows of
/// increasing time, linear in between (so the velocity and turning rate are the exact
/// derivatives of the pose); held before the first row and after the last. Two rows at the same
/// time are a cut: the thing is taken from one place to another with its pusher (a person who
/// leaves and comes back in), the later row holding from that time on.
#[derive(Clone, Debug)]
pub struct PushedPath {
    /// The person pushing it: their index in the sequence's plan.
    pub pusher: usize,
    /// Time, centre x, y, z and heading (unwrapped but across a cut: no jumps of 2 pi).
    table: Vec<[f64; 5]>,
}

impl PushedPath {
    /// A path from its rows (time, centre x, y, z, heading), at least one, in time order.
    pub fn new(pusher: usize, table: Vec<[f64; 5]>) -> PushedPath {
        debug_assert!(!table.is_empty() && table.windows(2).all(|w| w[0][0] <= w[1][0]));
        PushedPath { pusher, table }
    }
    /// The row `t_s` is at or after (its segment to the next row of a later time), and how far
    /// into the segment, or None before the first row or from the last on.
    fn step(&self, t_s: f64) -> Option<(usize, f64)> {
        let k = self.table.partition_point(|r| r[0] <= t_s).checked_sub(1)?;
        let (a, b) = (self.table[k], *self.table.get(k + 1)?);
        Some((k, (t_s - a[0]) / (b[0] - a[0])))
    }
    /// Centre and heading at `t_s`.
    pub fn pose(&self, t_s: f64) -> (DVec3, f64) {
        let row = match self.step(t_s) {
            Some((k, f)) => {
                let (a, b) = (self.table[k], self.table[k + 1]);
                [1, 2, 3, 4].map(|i| a[i] + f * (b[i] - a[i]))
            }
            None if t_s < self.table[0][0] => [1, 2, 3, 4].map(|i| self.table[0][i]),
            None => {
                let r = self.table[self.table.len() - 1];
                [1, 2, 3, 4].map(|i| r[i])
            }
        };
        (DVec3::new(row[0], row[1], row[2]), row[3])
    }
    /// The centre's velocity and the turning rate at `t_s` (0 outside the rows).
    pub fn rates(&self, t_s: f64) -> (DVec3, f64) {
        self.step(t_s).map_or((DVec3::ZERO, 0.0), |(k, _)| self.segment_rates(k))
    }
    /// How many rows it has.
    pub fn rows(&self) -> usize {
        self.table.len()
    }
    /// Row `k`'s time, centre and heading.
    pub fn row(&self, k: usize) -> (f64, DVec3, f64) {
        let r = self.table[k];
        (r[0], DVec3::new(r[1], r[2], r[3]), r[4])
    }
    /// The centre's velocity and the turning rate from row `k` to row `k + 1` (0 across a cut).
    pub fn segment_rates(&self, k: usize) -> (DVec3, f64) {
        let (a, b) = (self.table[k], self.table[k + 1]);
        let dt = b[0] - a[0];
        if dt <= 0.0 {
            return (DVec3::ZERO, 0.0);
        }
        let d = [1, 2, 3, 4].map(|i| (b[i] - a[i]) / dt);
        (DVec3::new(d[0], d[1], d[2]), d[3])
    }
}

/// A car of [`things::car`]'s shapes and a driver for it.
pub fn car(rng: &mut impl Rng) -> MoverSpec {
    let mut b = Builder::default();
    let (l, w) = things::car(&mut b, rng, DVec2::ZERO, 0.0, 0.0);
    let driver = Driver { speed_mps: uni(rng, 7.0, 14.0), accel: 1.5, decel: 2.5, headway_s: uni(rng, 1.0, 1.8), min_gap_m: 2.0 };
    MoverSpec { kind: MoverKind::Car, mesh: b.finish(), half: DVec2::new(l * 0.5, w * 0.5), driver }
}

/// A cyclist: a bicycle ([`things::bicycle`]) and its rider (SemanticKITTI's bicyclist, 31),
/// seated, hands on the bar, one foot down; and a rider's pace.
pub fn cyclist(rng: &mut impl Rng) -> MoverSpec {
    let mut b = Builder::default();
    things::bicycle(&mut b, rng, DVec2::ZERO, 0.0, 0.0);
    let m = material(rng, class::BICYCLIST);
    let s = uni(rng, 0.92, 1.08);
    let seat = DVec3::new(-0.2, 0.0, 0.95 * s);
    let shoulder_x = uni(rng, 0.05, 0.2);
    let shoulder = DVec3::new(shoulder_x, 0.0, seat.z + 0.55 * s);
    for k in [-1.0, 1.0] {
        let hip = seat + DVec3::new(0.0, 0.1 * k, 0.05);
        // One pedal forward and up, the other back and down.
        let foot = DVec3::new(-0.05 + 0.15 * k, 0.12 * k, 0.3 - 0.15 * k);
        let knee = DVec3::new(0.25 + 0.05 * k, 0.12 * k, 0.55 * s - 0.1 * k);
        b.rod(m, hip, knee, 0.07 * s, 6);
        b.rod(m, knee, foot, 0.055 * s, 6);
        let sh = shoulder + DVec3::new(0.0, 0.2 * k * s, 0.0);
        let hand = DVec3::new(0.42, 0.28 * k, 0.98);
        b.rod(m, sh, hand, 0.04 * s, 6);
    }
    b.rod(m, seat + DVec3::new(0.0, 0.0, 0.05), shoulder, 0.17 * s, 8);
    b.ellipsoid(m, shoulder + DVec3::new(0.05, 0.0, 0.2 * s), DVec3::new(0.11, 0.09, 0.13) * s, 4, 0.0, || 0.0);
    let driver = Driver { speed_mps: uni(rng, 3.5, 7.0), accel: 1.0, decel: 2.0, headway_s: 1.0, min_gap_m: 1.5 };
    MoverSpec { kind: MoverKind::Cyclist, mesh: b.finish(), half: DVec2::new(0.95, 0.35), driver }
}

/// How robots and carts drive indoors: at walking pace, keeping a second to the one ahead,
/// stopping 0.6 m short of somebody in their path.
fn indoor_driver(rng: &mut impl Rng, lo: f64, hi: f64) -> Driver {
    Driver { speed_mps: uni(rng, lo, hi), accel: 0.8, decel: 1.5, headway_s: 1.0, min_gap_m: 0.6 }
}

/// A delivery robot: a lidded box on wheels 0.6-0.8 m long, 0.5-0.6 m wide and 0.7-1.25 m
/// tall, half of them with a screen or a mast with a flag on top, and its pace, 0.8-1.5 m/s.
pub fn robot(rng: &mut impl Rng) -> MoverSpec {
    let mut b = Builder::default();
    let m = material(rng, class::OTHER_VEHICLE);
    let (l, w, h) = (uni(rng, 0.6, 0.8), uni(rng, 0.5, 0.6), uni(rng, 0.7, 1.25));
    let clearance = 0.08;
    b.cuboid(m, DVec3::new(0.0, 0.0, clearance), DVec3::new(l, w, h - clearance - 0.06), 0.0);
    // A lid, a little narrower.
    b.cuboid(m, DVec3::new(0.0, 0.0, h - 0.06), DVec3::new(l - 0.06, w - 0.06, 0.06), 0.0);
    let tyre = material(rng, class::OTHER_VEHICLE);
    for (x, y) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
        b.cylinder(tyre, DVec3::new(x * (l * 0.5 - 0.1), y * (w * 0.5 - 0.05), 0.0), 0.07, clearance + 0.02, 8);
    }
    if chance(rng, 0.5) {
        // A screen leaning back at the front, or a mast with a flag.
        if chance(rng, 0.5) {
            b.cuboid(material(rng, class::OTHER_VEHICLE), DVec3::new(l * 0.3, 0.0, h), DVec3::new(0.05, w * 0.7, uni(rng, 0.2, 0.35)), 0.0);
        } else {
            let top = DVec3::new(-l * 0.35, 0.0, h + uni(rng, 0.5, 0.9));
            b.rod(tyre, DVec3::new(-l * 0.35, 0.0, h), top, 0.01, 4);
            b.cuboid(material(rng, class::OTHER_VEHICLE), top - DVec3::new(0.12, 0.0, 0.2), DVec3::new(0.22, 0.01, 0.18), 0.0);
        }
    }
    MoverSpec { kind: MoverKind::Robot, mesh: b.finish(), half: DVec2::new(l * 0.5, w * 0.5), driver: indoor_driver(rng, 0.8, 1.5) }
}

/// A motorised service cart: a low platform 1.2-1.9 m long and 0.7-0.9 m wide with a push
/// handle, a stack of boxes or a roll cage of goods on it (1-1.8 m tall in all); 0.6-1.2 m/s.
pub fn cart(rng: &mut impl Rng) -> MoverSpec {
    let mut b = Builder::default();
    let m = material(rng, class::OTHER_VEHICLE);
    let (l, w) = (uni(rng, 1.2, 1.9), uni(rng, 0.7, 0.9));
    let deck = uni(rng, 0.25, 0.4);
    b.cuboid(m, DVec3::new(0.0, 0.0, deck - 0.08), DVec3::new(l, w, 0.08), 0.0);
    let tyre = material(rng, class::OTHER_VEHICLE);
    for (x, y) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
        b.cylinder(tyre, DVec3::new(x * (l * 0.5 - 0.12), y * (w * 0.5 - 0.08), 0.0), 0.09, deck - 0.08, 8);
    }
    // The handle at the back.
    let handle = deck + uni(rng, 0.75, 0.95);
    for y in [-1.0, 1.0] {
        b.rod(tyre, DVec3::new(-l * 0.5 + 0.03, y * (w * 0.5 - 0.04), deck), DVec3::new(-l * 0.5 + 0.03, y * (w * 0.5 - 0.04), handle), 0.015, 6);
    }
    b.rod(tyre, DVec3::new(-l * 0.5 + 0.03, -(w * 0.5 - 0.04), handle), DVec3::new(-l * 0.5 + 0.03, w * 0.5 - 0.04, handle), 0.015, 6);
    let load = l - 0.15;
    if chance(rng, 0.5) {
        // Boxes stacked in two or three layers.
        let layers = if chance(rng, 0.5) { 2 } else { 3 };
        let mut z = deck;
        for _ in 0..layers {
            let hz = uni(rng, 0.25, 0.45);
            let n = if chance(rng, 0.5) { 1 } else { 2 };
            for k in 0..n {
                let bl = load / n as f64;
                let x = 0.05 - load * 0.5 + bl * (k as f64 + 0.5);
                b.cuboid(material(rng, class::OTHER_VEHICLE), DVec3::new(x, 0.0, z), DVec3::new(bl * uni(rng, 0.85, 0.98), w * uni(rng, 0.8, 0.98), hz), uni(rng, -0.05, 0.05));
            }
            z += hz;
        }
    } else {
        // A roll cage: a box of goods inside four posts.
        let top = deck + uni(rng, 1.1, 1.4);
        for (x, y) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
            b.rod(tyre, DVec3::new(0.05 + x * load * 0.45, y * (w * 0.5 - 0.05), deck), DVec3::new(0.05 + x * load * 0.45, y * (w * 0.5 - 0.05), top), 0.015, 4);
        }
        b.cuboid(material(rng, class::OTHER_VEHICLE), DVec3::new(0.05, 0.0, deck), DVec3::new(load * 0.85, w * 0.8, (top - deck) * uni(rng, 0.4, 0.9)), 0.0);
    }
    MoverSpec { kind: MoverKind::Cart, mesh: b.finish(), half: DVec2::new(l * 0.5, w * 0.5), driver: indoor_driver(rng, 0.6, 1.2) }
}

/// Places the movers in their lane and drives them over `duration_s`. In a lane of its own
/// (`ego` None) the first car and the first cyclist pass the sensor (at `sensor_x(t)`) 8-40 m
/// from it halfway through the sequence and the others start anywhere along the lane; in the
/// sensor's lane (`ego`: its vehicle, at `sensor_x(t)` on the lane's centre line) each starts
/// 10-60 m ahead of or behind it. All start clear of each other (and of the sensor's vehicle).
/// People (their floor positions at a time, from `people`) make the movers stop before the
/// crossings they are on; a mover that still touches somebody, or the sensor's vehicle, is
/// left out, and the others drive again without it. Returns the movers kept, with their index
/// in `specs`.
pub fn drive(
    rng: &mut impl Rng,
    specs: &[MoverSpec],
    lane: &Arc<Lane>,
    duration_s: f64,
    sensor_x: impl Fn(f64) -> f64,
    ego: Option<Ego>,
    people: impl Fn(f64, &mut Vec<DVec2>),
) -> Vec<(usize, f64, Vec<[f64; 3]>)> {
    let len = lane.length();
    let mid = 0.5 * duration_s.max(0.0);
    // Lane positions at time 0.
    let mut placed: Vec<(usize, f64)> = Vec::new();
    let apart = |u: f64, v: f64, room: f64| {
        let d = (u - v).rem_euclid(len);
        d.min(len - d) > room
    };
    let ego_u = |t: f64| lane.u_of(sensor_x(t));
    let clear = |placed: &[(usize, f64)], i: usize, u: f64| {
        let (half, gap) = (specs[i].half.x, specs[i].driver.min_gap_m);
        placed.iter().all(|&(j, v)| apart(u, v, half + specs[j].half.x + gap.max(specs[j].driver.min_gap_m) + 2.0))
            && ego.is_none_or(|e| apart(u, ego_u(0.0), half + e.half.x + gap + 2.0))
    };
    let mut firsts = [false; 6];
    for (i, sp) in specs.iter().enumerate() {
        let kind = sp.kind as usize;
        for _ in 0..40 {
            let u = if ego.is_some() {
                let side = if rng.random::<f64>() < 0.5 { -1.0 } else { 1.0 };
                ego_u(0.0) + side * uni(rng, 10.0, 60.0)
            } else if !firsts[kind] {
                let side = if rng.random::<f64>() < 0.5 { -1.0 } else { 1.0 };
                let x = sensor_x(mid) + side * uni(rng, lane.pass_m.0, lane.pass_m.1);
                lane.u_of(x) - sp.driver.speed_mps * mid
            } else {
                uni(rng, 0.0, len)
            };
            if clear(&placed, i, u) {
                placed.push((i, u));
                firsts[kind] = true;
                break;
            }
        }
    }
    let mut who = Vec::new();
    let steps = (duration_s.max(0.0) / STEP_S).ceil() as usize + 1;
    let ego_at = |t: f64| ego.map(|e| (ego_u(t), e));
    loop {
        let tables = simulate(specs, &placed, lane, steps, &ego_at, &people);
        // The first mover (in placing order) that touches somebody or the sensor's vehicle is
        // left out; the rest drive again.
        let mut hit = None;
        'check: for (n, &(i, u0)) in placed.iter().enumerate() {
            let m = mover(&specs[i], lane, u0, tables[n].clone(), 0);
            for k in 0..=steps {
                let t = k as f64 * STEP_S;
                people(t, &mut who);
                let on_ego = ego.is_some_and(|e| m.overlaps(t, DVec2::new(sensor_x(t), lane.y), e.half));
                if on_ego || who.iter().any(|&p| m.touches(t, p)) {
                    hit = Some(n);
                    break 'check;
                }
            }
        }
        match hit {
            Some(n) => {
                placed.remove(n);
            }
            None => return placed.iter().zip(tables).map(|(&(i, u0), t)| (i, u0, t)).collect(),
        }
    }
}

/// The lane's movers driven together, step by step; one table per placed mover. `ego(t)`: the
/// sensor's vehicle in the lane (its centre's lane position, and what it is), if it is there.
fn simulate(
    specs: &[MoverSpec],
    placed: &[(usize, f64)],
    lane: &Lane,
    steps: usize,
    ego: &impl Fn(f64) -> Option<(f64, Ego)>,
    people: &impl Fn(f64, &mut Vec<DVec2>),
) -> Vec<Vec<[f64; 3]>> {
    let len = lane.length();
    let n = placed.len();
    let mut s = vec![0.0; n];
    let mut v: Vec<f64> = placed.iter().map(|&(i, _)| specs[i].driver.speed_mps).collect();
    let mut tables = vec![Vec::with_capacity(steps); n];
    let mut who = Vec::new();
    // Crossings where somebody is, by step.
    let mut blocked = vec![false; lane.crossings.len()];
    for k in 0..steps {
        let t = k as f64 * STEP_S;
        people(t, &mut who);
        for (c, b) in lane.crossings.iter().zip(blocked.iter_mut()) {
            *b = who.iter().any(|&p| lane.on_crossing(*c, p));
        }
        let front: Vec<f64> = (0..n).map(|a| placed[a].1 + s[a] + specs[placed[a].0].half.x).collect();
        let back: Vec<f64> = (0..n).map(|a| placed[a].1 + s[a] - specs[placed[a].0].half.x).collect();
        let mut acc = vec![0.0; n];
        for a in 0..n {
            let d = &specs[placed[a].0].driver;
            // The nearest obstacle ahead: the mover ahead, or a crossing somebody is on.
            let mut gap = f64::INFINITY;
            let mut lead_v = 0.0;
            for b in (0..n).filter(|&b| b != a) {
                let g = (back[b] - front[a]).rem_euclid(len);
                if g < gap {
                    (gap, lead_v) = (g, v[b]);
                }
            }
            if let Some((u, e)) = ego(t) {
                let g = (u - e.half.x - front[a]).rem_euclid(len);
                if g < gap {
                    (gap, lead_v) = (g, e.speed_mps);
                }
            }
            // Indoors, anybody in its path ahead (within half the lane).
            if lane.yield_m > 0.0 {
                for p in who.iter().filter(|p| (p.y - lane.y).abs() < lane.yield_m) {
                    let g = (lane.u_of(p.x) - PERSON_RADIUS_M - front[a]).rem_euclid(len);
                    if g < len * 0.5 && g < gap {
                        (gap, lead_v) = (g, 0.0);
                    }
                }
            }
            for (c, _) in lane.crossings.iter().zip(&blocked).filter(|(_, &b)| b) {
                let near = if lane.dir > 0.0 { c.0 - c.1 * 0.5 } else { c.0 + c.1 * 0.5 };
                let g = (lane.u_of(near) - STOP_LINE_M - front[a]).rem_euclid(len);
                // A stop line already crossed (more than a lap away) is not ahead.
                if g < len * 0.5 && g < gap {
                    (gap, lead_v) = (g, 0.0);
                }
            }
            let free = 1.0 - (v[a] / d.speed_mps).powi(4);
            let a_idm = if gap.is_finite() {
                let want = d.min_gap_m + (v[a] * d.headway_s + v[a] * (v[a] - lead_v) / (2.0 * (d.accel * d.decel).sqrt())).max(0.0);
                d.accel * (free - (want / gap.max(0.01)).powi(2))
            } else {
                d.accel * free
            };
            acc[a] = a_idm.clamp(-9.0, d.accel);
        }
        for a in 0..n {
            // A stop within the step stops exactly (no backing up).
            if v[a] + acc[a] * STEP_S < 0.0 {
                acc[a] = -v[a] / STEP_S;
            }
            tables[a].push([s[a], v[a], acc[a]]);
            s[a] += v[a] * STEP_S + 0.5 * acc[a] * STEP_S * STEP_S;
            v[a] = (v[a] + acc[a] * STEP_S).max(0.0);
        }
    }
    tables
}

/// A mover of a sequence from its spec, placement and drive.
pub fn mover(spec: &MoverSpec, lane: &Arc<Lane>, u0: f64, table: Vec<[f64; 3]>, first_vertex: usize) -> Mover {
    let y = lane.y + if spec.kind == MoverKind::Cyclist { lane.bike_offset_m } else { 0.0 };
    let path = MoverPath::Lane(LanePath { lane: lane.clone(), y, u0, table });
    Mover { kind: spec.kind, local: spec.mesh.positions.clone(), first_vertex, half: spec.half, path }
}
