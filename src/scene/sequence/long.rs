//! Long sequences: people (and, where no arc fits, the sensor) walking goal after goal for as
//! long as the sequence lasts ([`long_walk`]).

use super::{push, HumanPath, HumanPlan, Leg, Pauses, SensorPath};
use crate::scene::world::pushed::Held;
use crate::config::Config;
use crate::scene::{Trajectory, WalkableGrid};
use glam::DVec2;
use rand::RngExt;
use std::sync::Arc;

/// A long sequence's sensor walked through the walkable area goal after goal (see
/// [`long_walk`]) at a speed drawn from `scene.sensor_speed_mps` (at least 0.3 m/s), keeping
/// `scene.sensor_clearance_m` from obstacles; None when no walk keeps it.
pub(super) fn walk_the_sensor(rng: &mut impl rand::Rng, cfg: &Config, grid: &WalkableGrid, times_s: &[f64]) -> Option<SensorPath> {
    let sc = &cfg.scene;
    let duration = *times_s.last()?;
    let crowd = Crowd { grid, clearance_m: sc.sensor_clearance_m, separation_m: 0.0, sensor: None, others: &[], times_s, doors: &[], world: None, held: None, thing_times: &[] };
    let mut planner = crate::scene::planner::Planner::new();
    let [lo, hi] = sc.sensor_speed_mps;
    for _ in 0..LONG_TRIES {
        let start = DVec2::new(grid.origin.x + rng.random::<f64>() * grid.nx as f64 * grid.cell_m, grid.origin.y + rng.random::<f64>() * grid.ny as f64 * grid.cell_m);
        if grid.clearance(start) < sc.sensor_clearance_m {
            continue;
        }
        let speed = (lo + (hi - lo) * rng.random::<f64>()).max(0.3);
        if let Some(path) = long_walk(rng, &mut planner, &crowd, start, speed, false, 0.0, 0.0, duration) {
            return Some(SensorPath::Walk(Box::new(path), sc.sensor_height_m));
        }
    }
    None
}

/// Sequences longer than this, s, walk goal after goal (see [`long_walk`]) where one walk to
/// one goal would have to last them.
pub const LONG_SEQUENCE_S: f64 = 30.0;
/// A long sequence's walk to its next goal takes at least this long, s (drawn), and the wait
/// at the goal before the next this long.
const LEG_S: [f64; 2] = [8.0, 25.0];
/// A leg's goal lies at most this many times as far from its start as that least walk (the
/// next goal is somewhere near, and planning it costs the neighbourhood, not the whole world).
const LEG_REACH: f64 = 2.0;
const WAIT_S: [f64; 2] = [0.5, 5.0];
/// A person who waits at the start (`humans.standing`) of a long sequence waits this long
/// before walking on, s.
const LONG_STAND_S: [f64; 2] = [10.0, 60.0];
/// Somebody farther than this from the sensor, m, leaves (beyond what a sensor sees of a
/// person) and comes back in near it.
pub const LEAVE_M: f64 = 100.0;
/// Tries at planning a leg, and at placing a whole long walk.
const LEG_TRIES: usize = 20;
pub(super) const LONG_TRIES: usize = 40;
/// Tries at a place to come back in, the first half of them out of the sensor's sight.
const ARRIVAL_TRIES: usize = 200;
/// How far from the sensor, in spawn radii, a place out of its sight to come back in may be
/// (one farther than a spawn radius walks back toward the sensor); in view: 0.3-1.
const HIDDEN_ARRIVAL_RADII: f64 = 2.0;
/// Share of those coming back in who come out of a doorway where one is free within a spawn
/// radius of the sensor (0.3-1 spawn radii away, as the places in view).
const DOOR_ARRIVALS: f64 = 0.5;
/// Share of the walks of somebody within a spawn radius of the sensor that go in through a
/// doorway where one is free within a short walk ([`DOOR_WALK_S`] at their speed, 2 m at
/// least): they walk to it, stop in it and are gone (a building takes them in), and come back
/// in elsewhere as those left far behind do.
const DOOR_DEPARTURES: f64 = 0.2;
/// A doorway one goes in through is at most this long a walk away (in a straight line), s.
const DOOR_WALK_S: f64 = 8.0;

/// Who a new person must keep clear of over a long sequence: obstacles, the sensor, the people
/// placed before.
pub(super) struct Crowd<'a> {
    pub grid: &'a WalkableGrid,
    pub clearance_m: f64,
    pub separation_m: f64,
    /// The sensor (None: placing the sensor's own walk).
    pub sensor: Option<&'a SensorPath>,
    pub others: &'a [HumanPlan],
    pub times_s: &'a [f64],
    /// Doorways one who comes back in may come out of ([`crate::scene::world::World::doors`]).
    pub doors: &'a [crate::scene::world::Place],
    /// The built-in world (what people push is kept clear of it and of the others: [`push`]).
    pub world: Option<&'a crate::scene::world::World>,
    /// What the new person pushes, held where this says (`humans.pushing`); None: nothing.
    pub held: Option<Held>,
    /// The times the world checks a pushed thing at
    /// ([`crate::scene::world::pushed::checked_times`]); empty where nobody pushes.
    pub thing_times: &'a [f64],
}

impl Crowd<'_> {
    /// Whether `path` (its own time 0 at `t0`) keeps clear at every frame in `[t0, t1)`.
    /// What the new person pushes is clear too, at the world's times for it in `[t0, t1)`
    /// (from the first of them where `t0` is the sequence's start).
    fn clear(&self, path: &HumanPath, t0: f64, t1: f64) -> bool {
        let a = self.times_s.partition_point(|&t| t < t0);
        let b = if t0 <= 0.0 { 0 } else { self.thing_times.partition_point(|&t| t < t0) };
        let at = |t: f64| (path.position(t - t0).truncate(), path.heading_rad(t - t0));
        self.times_s[a..].iter().take_while(|&&t| t < t1).all(|&t| self.clear_at(at(t).0, t))
            && (self.held.is_none() || self.thing_times[b..].iter().take_while(|&&t| t < t1).all(|&t| self.thing_fits(at(t).0, at(t).1, t)))
    }

    /// Whether what the new person pushes, with the person at `p` heading `h`, is clear at
    /// `t` ([`push::thing_clear`]); true for one who pushes nothing.
    pub(super) fn thing_fits(&self, p: DVec2, h: f64, t: f64) -> bool {
        self.held.is_none_or(|held| self.world.is_none_or(|w| push::thing_clear(w, self.others, self.sensor, &held.footprint(p, h), t)))
    }

    /// Whether somebody at `p` is clear at time `t`, a frame's or any other (one coming back in
    /// after a walk comes back between frames: [`Crowd::clear`] would check nothing there).
    pub(super) fn clear_at(&self, p: DVec2, t: f64) -> bool {
        self.grid.clearance(p) >= self.clearance_m
            && self.sensor.is_none_or(|s| p.distance(s.position(t).truncate()) >= self.separation_m)
            && self.others.iter().all(|h| h.footprint_m(t).distance(p) >= self.separation_m)
            && push::others_clear(self.world, self.others, p, t)
    }
}

/// A long sequence's walk: from `start`, goal after goal through the walkable area (each leg
/// planned like a short sequence's walk, 8-25 s long at least, its goal at most [`LEG_REACH`]
/// times that walk away: [`crate::scene::planner::Planner::plan_leg`]), waiting 0.5-5 s at each goal,
/// and after 10-60 s of waiting first for one who stands. Each walk slows to a stop at its
/// goal, and one that begins after a wait gets going, over [`Pauses::RAMP_S`] (the speed never
/// steps). Somebody left more than [`LEAVE_M`] from the sensor (a vehicle drives on), or gone
/// in through a doorway ([`DOOR_DEPARTURES`]), leaves and comes back in near where the sensor
/// is then: for a share [`DOOR_ARRIVALS`] out of a doorway of the world 0.3-1 spawn radii away
/// where one is free, else out of its sight 0.3-2 spawn radii away where there is such a place
/// ([`WalkableGrid::hidden_from`]), else in view 0.3-1 spawn radii away, so the people stay
/// around it to the end. Each leg keeps clear of the
/// obstacles, the sensor and the people placed before at every frame; None when a leg finds
/// no way to.
#[allow(clippy::too_many_arguments)]
pub(super) fn long_walk(
    rng: &mut impl rand::Rng,
    planner: &mut crate::scene::planner::Planner,
    crowd: &Crowd,
    start: DVec2,
    speed: f64,
    stands_first: bool,
    spawn_radius_m: f64,
    floor_z: f64,
    duration: f64,
) -> Option<HumanPath> {
    fn u(rng: &mut impl rand::Rng, r: [f64; 2]) -> f64 {
        r[0] + (r[1] - r[0]) * rng.random::<f64>()
    }
    let mut legs: Vec<Leg> = Vec::new();
    let (mut t, mut d, mut pos) = (0.0, 0.0, start);
    let mut heading = u(rng, [-std::f64::consts::PI, std::f64::consts::PI]);
    let stand = |p: DVec2, h: f64| HumanPath::Arc(Trajectory::fixed(p, floor_z, h));
    // The turn from heading `a` to `b`, the shorter way, rad.
    let shorter = |a: f64, b: f64| crate::geometry::wrap_pi(b - a);
    // Standing at `p` for `w` s, turning at a constant rate from heading `a` to `b` (the
    // shorter way).
    let turning = |p: DVec2, a: f64, b: f64, w: f64| {
        let rate = if w > 0.0 { shorter(a, b) / w } else { 0.0 };
        HumanPath::Arc(Trajectory { start_m: p, z_m: floor_z, heading0_rad: a, speed_mps: 0.0, yaw_rate_rps: rate })
    };
    // Somebody a vehicle leaves far behind (none for the sensor's own walk).
    let far = |p: DVec2, t: f64| crowd.sensor.is_some_and(|s| p.distance(s.position(t).truncate()) > LEAVE_M);
    // Standing at `p` from `a` to `b`: until the first frame the sensor has left one far
    // behind by, or `b`.
    let until_left = |p: DVec2, a: f64, b: f64| {
        let k = crowd.times_s.partition_point(|&x| x < a);
        crowd.times_s[k..].iter().take_while(|&&x| x < b).find(|&&x| far(p, x)).copied().unwrap_or(b)
    };
    if stands_first {
        let w = u(rng, LONG_STAND_S);
        if !crowd.clear(&stand(pos, heading), 0.0, w) {
            return None;
        }
        legs.push(Leg { t0_s: 0.0, d0_m: 0.0, path: stand(pos, heading) });
        t = until_left(pos, 0.0, w);
    }
    // Standing (after a walk, a wait or at the start): the next walk begins with a wait that
    // turns toward it, and gets going from rest.
    let mut at_rest = stands_first;
    // Gone in through a doorway (at `pos`) at the end of the last walk.
    let mut gone_in = false;
    while t <= duration {
        // Left far behind, or gone in: come back in near the sensor, out of a doorway
        // ([`DOOR_ARRIVALS`]; not the one gone in through) or out of its sight where the first
        // half of the tries find such a place (a side street, behind a booth or a parked
        // truck), so arrivals walk into view.
        if let Some(sensor) = crowd.sensor.filter(|_| gone_in || far(pos, t)) {
            let here = sensor.position(t).truncate();
            // Out of a doorway, facing out, for a share of them: one of those free within
            // reach, drawn evenly.
            let mut door = None;
            if !crowd.doors.is_empty() && rng.random::<f64>() < DOOR_ARRIVALS {
                let reach = 0.3 * spawn_radius_m..=spawn_radius_m;
                let free: Vec<_> = crowd
                    .doors
                    .iter()
                    .filter(|d| reach.contains(&d.at.distance(here)) && d.at.distance(pos) > 1.0 && crowd.clear_at(d.at, t) && crowd.thing_fits(d.at, d.facing_rad, t))
                    .collect();
                door = drawn(rng, &free);
            }
            if let Some(d) = door {
                (pos, heading) = (d.at, d.facing_rad);
            } else {
                let back = (0..ARRIVAL_TRIES)
                    .map(|k| {
                        let reach = if k < ARRIVAL_TRIES / 2 { HIDDEN_ARRIVAL_RADII } else { 1.0 };
                        let (r, a) = (spawn_radius_m * u(rng, [0.3, reach]), u(rng, [0.0, std::f64::consts::TAU]));
                        (k, here + r * DVec2::new(a.cos(), a.sin()))
                    })
                    .find(|&(k, p)| {
                        (k >= ARRIVAL_TRIES / 2 || crowd.grid.hidden_from(here, p)) && crowd.clear_at(p, t) && crowd.thing_fits(p, (here - p).to_angle(), t)
                    });
                pos = back?.1;
                // One who pushes something comes in facing the sensor, the thing ahead.
                if crowd.held.is_some() {
                    heading = (here - pos).to_angle();
                }
            }
            at_rest = false;
            gone_in = false;
        }
        // After a walk, a wait at its goal, turning on the spot toward the next walk.
        let wait = if at_rest { u(rng, WAIT_S) } else { 0.0 };
        let leg_s = u(rng, LEG_S);
        // One who has drifted farther than the spawn radius from the sensor walks back toward
        // where it will be (first try), so the people stay around it (walls hide the rest).
        let toward = crowd.sensor.filter(|s| pos.distance(s.position(t).truncate()) > spawn_radius_m).map(|s| {
            let (r, a) = (spawn_radius_m * u(rng, [0.0, 1.0]).sqrt(), u(rng, [0.0, std::f64::consts::TAU]));
            s.position(t + wait + leg_s).truncate() + r * DVec2::new(a.cos(), a.sin())
        });
        // Near the sensor, a share of the walks go in through a doorway within a short walk
        // (first try), drawn evenly among those free now.
        let mut door_goal = None;
        if toward.is_none() && !crowd.doors.is_empty() && crowd.sensor.is_some() && rng.random::<f64>() < DOOR_DEPARTURES {
            let reach = 2.0..=(speed * DOOR_WALK_S).max(2.0);
            let near: Vec<DVec2> = crowd.doors.iter().map(|d| d.at).filter(|d| reach.contains(&d.distance(pos)) && crowd.clear_at(*d, t)).collect();
            door_goal = drawn(rng, &near);
        }
        let mut walked = None;
        // Every search is bounded by the neighbourhood it walks in (a goal that only a long
        // detour reaches is given up).
        let reach = LEG_REACH * (speed * leg_s).max(crowd.grid.cell_m);
        for k in 0..LEG_TRIES {
            let w = match (toward.or(door_goal)).filter(|_| k == 0) {
                Some(goal) => planner.plan_to_within(crowd.grid, crowd.clearance_m, speed, pos, goal, pos.distance(goal).max(reach)),
                None => planner.plan_leg(rng, crowd.grid, crowd.clearance_m, speed, leg_s, pos, reach),
            };
            let Some(w) = w else { continue };
            let walk_s = w.duration_s();
            let (path, arrive) = eased(HumanPath::Walk(w, floor_z), walk_s, at_rest);
            // One who pushes something waits long enough to turn it at [`push::TURN_RPS`].
            let wait = if crowd.held.is_some() && at_rest { wait.max(shorter(heading, path.heading_rad(0.0)).abs() / push::TURN_RPS) } else { wait };
            let turn = turning(pos, heading, path.heading_rad(0.0), wait);
            if crowd.clear(&turn, t, t + wait) && crowd.clear(&path, t + wait, t + wait + arrive) {
                walked = Some((arrive, path, turn, wait, k == 0 && door_goal.is_some()));
                break;
            }
        }
        let Some((arrive, path, turn, wait, to_door)) = walked else {
            // Nowhere to walk now: wait where one is, or give up the person.
            if !crowd.clear(&stand(pos, heading), t, t + 2.0) {
                return None;
            }
            legs.push(Leg { t0_s: t, d0_m: d, path: stand(pos, heading) });
            t = until_left(pos, t, t + 2.0);
            at_rest = true;
            continue;
        };
        if wait > 0.0 {
            legs.push(Leg { t0_s: t, d0_m: d, path: turn });
            let left = until_left(pos, t, t + wait);
            if left < t + wait {
                // Left behind while waiting: comes back in (above) instead of walking on.
                t = left;
                continue;
            }
            t += wait;
        }
        // The walk ends at its goal, or where it has left the sensor far behind.
        let mut end = arrive;
        let a = crowd.times_s.partition_point(|&x| x < t);
        if let Some(&x) = crowd.times_s[a..].iter().take_while(|&&x| x < t + end).find(|&&x| far(path.position(x - t).truncate(), x)) {
            end = x - t;
        }
        legs.push(Leg { t0_s: t, d0_m: d, path: path.clone() });
        t += end;
        d += path.distance(end);
        pos = path.position(end).truncate();
        heading = path.heading_rad(end);
        // Arrived (a walk cut short leaves, and comes back in walking); at a doorway, gone in.
        at_rest = end >= arrive;
        gone_in = to_door && at_rest;
    }
    Some(HumanPath::Legs(Arc::new(legs)))
}

/// One of `items` drawn evenly (None, and nothing drawn, when there are none).
fn drawn<T: Copy>(rng: &mut impl rand::Rng, items: &[T]) -> Option<T> {
    (!items.is_empty()).then(|| items[crate::scene::even_index(rng.random::<f64>(), items.len())])
}

/// A walk of `walk_s` seconds that slows to a stop at its end, and with `from_rest` gets going
/// at its start, each over [`Pauses::RAMP_S`] (a ramp costs half of it); and the time it then
/// takes to arrive. A walk shorter than two ramps keeps its speed.
fn eased(walk: HumanPath, walk_s: f64, from_rest: bool) -> (HumanPath, f64) {
    let r = Pauses::RAMP_S;
    if walk_s < 2.0 * r {
        return (walk, walk_s);
    }
    let arrive = walk_s + if from_rest { r } else { 0.5 * r };
    let mut stops = vec![(arrive, f64::INFINITY)];
    if from_rest {
        stops.push((f64::NEG_INFINITY, 0.0));
    }
    (HumanPath::Paused(Box::new(walk), Pauses::new(stops)), arrive)
}
