//! Things people push (`humans.pushing`): a stroller along the street, a trolley indoors. Each
//! is a rigid mesh of its own, its handle at the pusher's hands ([`PushHandle`]), held ahead
//! of the pusher at the pusher's heading as the pusher walks, stops and turns; like the other
//! movers it has its own instance id and its beams their own velocity (the centre's and the
//! turn's: `v + w z x r`), and it is not a person (SemanticKITTI's other-object, 99). The
//! sequence's planner draws who pushes and plans their walks so the thing fits
//! (`crate::scene::sequence`, with [`World::pushed_spec`] and [`World::pushed_clear`]); this
//! module checks it between the frames too: a thing is added only where it stays clear all
//! through of the walkable area's obstacles, the other people, the sensor's carrier or
//! vehicle and the other pushed things, and nobody who stands all through turns one on the
//! spot (a walker who stops and turns pivots it). A person who leaves and comes back in (a
//! long sequence) takes the thing along. The traffic then keeps clear of the things as of the
//! people.

use super::movers::{Footprint, Mover, MoverKind, MoverPath, PushedPath, EGO_HALF_M, PERSON_RADIUS_M, STEP_S};
use super::shapes::Builder;
use super::things::{class, material};
use super::{uni, World, WorldKind};
use crate::human::push::PushHandle;
use crate::scene::Environment;
use glam::{DVec2, DVec3};
use rand::{Rng, SeedableRng};

/// Keys the choice of who pushes apart from the world's other streams.
const PUSHED_STREAM_KEY: u64 = 0x5055_5348_5f76_3031; // "PUSH_v01"

/// How far before time 0 and past the sequence's end the table reaches, s (a rolling sweep
/// places a mover at the time its column fires, after the frame's). The table's rows are half
/// a step off the multiples of [`STEP_S`], so frames (at multiples of 0.05 s at the usual
/// rates) fall in the middle of a step, where the rates are the central difference about them.
const MARGIN_S: f64 = 1.0 + 0.5 * STEP_S;
/// The fastest a pushed thing goes and turns, m/s and rad/s: a person pushing one walks and
/// pivots it slower (a person taken from one place to another is a cut, not a move).
const MAX_SPEED_MPS: f64 = 3.0;
const MAX_TURN_RPS: f64 = 2.0;
/// Below this speed a person stands, m/s; one who stands the whole sequence may not turn the
/// thing (the idle turning on the spot of those who stand), rad/s. A walker who stops and
/// turns toward the next goal pivots it.
const STANDING_MPS: f64 = 0.1;
const STANDING_TURN_RPS: f64 = 0.05;
/// Room kept between a thing and the walkable area's obstacles, beside its half width, m.
const ROOM_M: f64 = 0.05;
/// Room a planner keeps besides these rules between a pushed thing and the people, whom it
/// places checking the frames only, m: about as far as a person or a thing moves in the
/// quarter of a frame (at 10 Hz) between a frame and the nearest time the world checks.
pub const PLANNED_ROOM_M: f64 = 0.1;

/// A thing to push, not yet pushed: its mesh (body frame: x forward, z up from the ground, the
/// origin its footprint's centre), half its footprint's length and width, and how far behind
/// the centre its handle is, m.
pub struct PushedSpec {
    pub kind: MoverKind,
    pub mesh: Environment,
    pub half: DVec2,
    pub handle_behind_m: f64,
}

impl PushedSpec {
    /// Where it is held for a pusher whose hands are at `handle`.
    pub fn held(&self, handle: &PushHandle) -> Held {
        Held { ahead_m: handle.forward_m as f64 + self.handle_behind_m, half: self.half }
    }
}

/// Where a pushed thing is, seen from its pusher: its footprint's centre `ahead_m` ahead of
/// the pusher's hips along the heading, and half its footprint's length and width, m. What a
/// sequence's planner keeps clear while it plans a pusher's walk.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Held {
    /// From the pusher's hips to its footprint's centre along the heading, m.
    pub ahead_m: f64,
    /// Half its footprint's length and width, m.
    pub half: DVec2,
}

impl Held {
    /// Its footprint with the pusher's hips over `p`, heading `heading_rad`.
    pub fn footprint(&self, p: DVec2, heading_rad: f64) -> Footprint {
        Footprint { centre: p + self.ahead_m * DVec2::new(heading_rad.cos(), heading_rad.sin()), heading_rad, half: self.half }
    }
}

/// A stroller for hands at `h`: four wheels (the rear ones larger), a frame, a seat or
/// carrycot and its hood, the handle bar across at the hands, 10-20 cm behind the rear wheels.
pub fn stroller(rng: &mut impl Rng, h: &PushHandle) -> PushedSpec {
    let (frame, fabric) = (material(rng, class::OTHER_OBJECT), material(rng, class::OTHER_OBJECT));
    let (len, half_w) = (uni(rng, 0.7, 0.9), uni(rng, 0.26, 0.31));
    let (r_back, r_front) = (uni(rng, 0.12, 0.16), uni(rng, 0.08, 0.11));
    let mut b = Builder::default();
    let side = DVec3::new(0.0, 0.02, 0.0);
    let wheel_y = half_w - 0.03;
    for y in [-wheel_y, wheel_y] {
        let back = DVec3::new(-0.5 * len + r_back, y, r_back);
        let front = DVec3::new(0.5 * len - r_front, y, r_front);
        b.rod(frame, back - side, back + side, r_back, 10);
        b.rod(frame, front - side, front + side, r_front, 8);
        b.rod(frame, back, front + DVec3::new(0.0, 0.0, 0.1), 0.015, 6);
    }
    let seat_z = uni(rng, 0.38, 0.5);
    let seat_len = uni(rng, 0.5, 0.7).min(len);
    let seat_x = uni(rng, -0.05, 0.05);
    let seat_top = seat_z + uni(rng, 0.22, 0.35);
    b.cuboid(fabric, DVec3::new(seat_x, 0.0, seat_z), DVec3::new(seat_len, 2.0 * half_w - 0.08, seat_top - seat_z), 0.0);
    b.ellipsoid(fabric, DVec3::new(seat_x - 0.2 * seat_len, 0.0, seat_top), DVec3::new(0.22, half_w - 0.05, uni(rng, 0.12, 0.22)), 4, 0.0, || 0.0);
    let handle_x = -0.5 * len - uni(rng, 0.1, 0.2);
    let hz = h.height_m as f64;
    let bar = (h.half_width_m as f64 + 0.06).min(half_w);
    b.rod(frame, DVec3::new(handle_x, -bar, hz), DVec3::new(handle_x, bar, hz), 0.015, 6);
    for y in [-bar, bar] {
        b.rod(frame, DVec3::new(handle_x, y, hz), DVec3::new(-0.5 * len + r_back, y.signum() * wheel_y, r_back), 0.015, 6);
    }
    PushedSpec { kind: MoverKind::Stroller, mesh: b.finish(), half: DVec2::new(0.5 * len, half_w), handle_behind_m: -handle_x }
}

/// A trolley for hands at `h`: a basket up to a little below the hands, a tray under it, four
/// castors and the uprights to them, the handle bar across the basket's back at the hands.
pub fn trolley(rng: &mut impl Rng, h: &PushHandle) -> PushedSpec {
    let (frame, basket) = (material(rng, class::OTHER_OBJECT), material(rng, class::OTHER_OBJECT));
    let (len, half_w) = (uni(rng, 0.75, 0.95), uni(rng, 0.25, 0.3));
    let hz = h.height_m as f64;
    let top = (hz - uni(rng, 0.03, 0.12)).max(0.7);
    let bottom = top - uni(rng, 0.3, 0.45);
    let mut b = Builder::default();
    b.aabb(basket, DVec3::new(-0.5 * len, -half_w, bottom), DVec3::new(0.5 * len, half_w, top));
    b.aabb(frame, DVec3::new(-0.5 * len + 0.05, -half_w + 0.04, 0.14), DVec3::new(0.5 * len - 0.05, half_w - 0.04, 0.17));
    let r = uni(rng, 0.05, 0.07);
    for x in [-0.5 * len + 0.06, 0.5 * len - 0.06] {
        for y in [-half_w + 0.04, half_w - 0.04] {
            b.rod(frame, DVec3::new(x, y - 0.015, r), DVec3::new(x, y + 0.015, r), r, 8);
            b.rod(frame, DVec3::new(x, y, 2.0 * r), DVec3::new(x, y, bottom), 0.012, 6);
        }
    }
    let handle_x = -0.5 * len - uni(rng, 0.04, 0.1);
    let bar = half_w - 0.02;
    b.rod(frame, DVec3::new(handle_x, -bar, hz), DVec3::new(handle_x, bar, hz), 0.015, 6);
    for y in [-bar, bar] {
        b.rod(frame, DVec3::new(handle_x, y, hz), DVec3::new(-0.5 * len, y, top), 0.012, 6);
    }
    PushedSpec { kind: MoverKind::Trolley, mesh: b.finish(), half: DVec2::new(0.5 * len, half_w), handle_behind_m: -handle_x }
}

/// How long before a cut the person is read for the row that ends there, s.
const BEFORE_CUT_S: f64 = 1e-6;

/// The path of a thing with `spec`'s handle at the hands of person `pusher` (`handle` ahead of
/// them; `at`: the person's floor position and heading at a time, first) over `rows` rows from
/// `t0_s`, [`STEP_S`] apart, and two rows at each of `cuts` (the times the person is taken from
/// one place to another: the row before read just before it).
fn push_path(pusher: usize, at: &impl Fn(usize, f64) -> Walker, cuts: &[f64], handle: &PushHandle, spec: &PushedSpec, t0_s: f64, rows: usize) -> PushedPath {
    let ahead = handle.forward_m as f64 + spec.handle_behind_m;
    let t1 = t0_s + (rows.max(1) - 1) as f64 * STEP_S;
    let cuts: Vec<f64> = cuts.iter().copied().filter(|&c| c > t0_s && c < t1).collect();
    // The steps' rows, but for one at a cut's time (or within a millisecond of it).
    let mut times: Vec<(f64, f64, bool)> = (0..rows)
        .map(|k| t0_s + k as f64 * STEP_S)
        .filter(|t| cuts.iter().all(|c| (t - c).abs() >= 1e-3))
        .map(|t| (t, t, false))
        .collect();
    for &c in &cuts {
        times.push((c, c - BEFORE_CUT_S, false));
        times.push((c, c, true));
    }
    times.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.2.cmp(&b.2)));
    let mut table: Vec<[f64; 5]> = Vec::with_capacity(times.len());
    for (t, read, after_cut) in times {
        let w = at(pusher, read);
        let (p, mut h) = (w.position_m, w.heading_rad);
        if let (Some(prev), false) = (table.last(), after_cut) {
            // Unwrapped: the nearest turn of the heading to the last one.
            h = prev[4] + crate::geometry::wrap_pi(h - prev[4]);
        }
        table.push([t, p.x + ahead * h.cos(), p.y + ahead * h.sin(), p.z, h]);
    }
    PushedPath::new(pusher, table)
}

/// A person at one instant, as [`World::add_pushed`] asks: where the hips are over the floor
/// and the heading (a pushed thing is held ahead of them), the speed, and the middle of the
/// body on the floor that others keep clear of (a seated person's, ahead of the hips).
#[derive(Clone, Copy, Debug)]
pub struct Walker {
    pub position_m: DVec3,
    pub heading_rad: f64,
    pub speed_mps: f64,
    pub footprint_m: DVec2,
}

/// The rows of a pushed thing's table ([`STEP_S`] apart from `-MARGIN_S`) that
/// [`World::add_pushed`] checks over `duration_s` (the frames' sweeps included): from the one
/// before time 0 to the one after `duration_s` (the rest only carry the table on either side).
fn checked_rows(duration_s: f64) -> [usize; 2] {
    [(MARGIN_S / STEP_S).floor() as usize, ((duration_s.max(0.0) + MARGIN_S) / STEP_S).ceil() as usize]
}

/// The times [`World::add_pushed`] checks a thing at over `duration_s` ([`checked_rows`]): a
/// planner that checks these with the same rules plans what the world keeps.
pub fn checked_times(duration_s: f64) -> impl Iterator<Item = f64> {
    let [first, last] = checked_rows(duration_s);
    (first..=last).map(|k| -MARGIN_S + k as f64 * STEP_S)
}

impl World {
    /// The thing person `person` of the sequence pushes where they do, for hands at `handle`:
    /// a stroller (the street) or a trolley (indoors), drawn from a stream of its own (the
    /// world's seed and sequence, the person), so the planner that keeps it clear and
    /// [`World::add_pushed`] that adds it see the same thing.
    pub fn pushed_spec(&self, person: usize, handle: &PushHandle) -> PushedSpec {
        let key = self.seed ^ PUSHED_STREAM_KEY ^ (person as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(key);
        rng.set_stream(self.index as u64);
        match self.kind {
            WorldKind::Street => stroller(&mut rng, handle),
            WorldKind::Indoor => trolley(&mut rng, handle),
        }
    }

    /// Whether a pushed thing's footprint `f` keeps clear of the world at `t_s`: the walkable
    /// area's obstacles (clearance at the middle and the ends of its long axis at least its
    /// half width and [`ROOM_M`], at its corners [`ROOM_M`]) and the sensor's vehicle (an
    /// exact test of the two boxes).
    pub fn pushed_clear(&self, f: &Footprint, t_s: f64) -> bool {
        let axis = DVec2::new(f.heading_rad.cos(), f.heading_rad.sin()) * (f.half.x - f.half.y).max(0.0);
        [-1.0, 0.0, 1.0].iter().all(|&s| self.grid.clearance(f.centre + s * axis) >= f.half.y + ROOM_M)
            && f.corners().iter().all(|&q| self.grid.clearance(q) >= ROOM_M)
            && self.sensor.as_ref().is_none_or(|s| !f.overlaps(s.position(t_s).truncate(), EGO_HALF_M))
    }

    /// Adds the things a sequence's people push over its `duration_s` (from its first frame
    /// to the end of its last frame's sweep): to each person with a `handles` entry (where
    /// their hands hold it; None: they push nothing) the thing of [`World::pushed_spec`], held
    /// ahead of them, where it stays clear of everything (the module's rules) at every one of
    /// [`checked_times`]; the things are added to the world as movers (before its traffic),
    /// their meshes to the environment. `at`: a person at a time; `cuts`: the times a person
    /// is taken from one place to another (a long sequence's, leaving and coming back in), the
    /// thing with them. `carrier`: the sensor's carrier's floor position at a time, where it
    /// walks among the people (the world's own sensor vehicle, the street's, is kept clear of
    /// too). The sequence's planner has kept the things clear already (`crate::scene::sequence`);
    /// this checks what it checked at the frames only (the people placed after a pusher) and
    /// the things' speeds. Returns who pushes, in order.
    pub fn add_pushed(
        &mut self,
        handles: &[Option<PushHandle>],
        at: impl Fn(usize, f64) -> Walker,
        cuts: impl Fn(usize) -> Vec<f64>,
        duration_s: f64,
        carrier: impl Fn(f64) -> Option<DVec2>,
    ) -> Vec<usize> {
        if handles.iter().all(Option::is_none) {
            return Vec::new();
        }
        let t0 = -MARGIN_S;
        let rows = ((duration_s.max(0.0) + 2.0 * MARGIN_S) / STEP_S).ceil() as usize + 1;
        let [first, last] = checked_rows(duration_s);
        let mut drawn: Vec<(usize, PushedSpec, Mover)> = Vec::new();
        for (i, handle) in handles.iter().enumerate() {
            let Some(handle) = handle else { continue };
            let spec = self.pushed_spec(i, handle);
            let path = push_path(i, &at, &cuts(i), handle, &spec, t0, rows);
            // Its speed and turning, segment by segment (none across a cut); somebody who never
            // walks does not turn it.
            let walks = (0..path.rows()).any(|k| at(i, path.row(k).0).speed_mps >= STANDING_MPS);
            let checked = |k: &usize| path.row(k + 1).0 > t0 + first as f64 * STEP_S && path.row(*k).0 < t0 + last as f64 * STEP_S;
            let moves = (0..path.rows() - 1).filter(checked).all(|k| {
                let (v, w) = path.segment_rates(k);
                v.truncate().length() <= MAX_SPEED_MPS && w.abs() <= MAX_TURN_RPS && (walks || w.abs() <= STANDING_TURN_RPS)
            });
            if moves {
                let m = Mover { kind: spec.kind, local: spec.mesh.positions.clone(), first_vertex: 0, half: spec.half, path: MoverPath::Pushed(path) };
                drawn.push((i, spec, m));
            }
        }
        // Step by step (the people's positions one step at a time), each thing against the
        // world, the people and the sensor; a thing that fails once is out.
        let mut clear = vec![true; drawn.len()];
        let mut by_x: Vec<(f64, usize)> = Vec::with_capacity(handles.len());
        let mut people: Vec<Walker> = Vec::with_capacity(handles.len());
        for k in first..=last {
            let t = t0 + k as f64 * STEP_S;
            people.clear();
            people.extend((0..handles.len()).map(|j| at(j, t)));
            by_x.clear();
            by_x.extend(people.iter().enumerate().map(|(j, w)| (w.footprint_m.x, j)));
            by_x.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let carried = carrier(t);
            for ((i, _, m), ok) in drawn.iter().zip(clear.iter_mut()).filter(|(_, ok)| **ok) {
                let f = m.footprint(t);
                // Only somebody this near its centre can touch it.
                let reach = m.half.length() + PERSON_RADIUS_M;
                let lo = by_x.partition_point(|e| e.0 < f.centre.x - reach);
                let near = by_x[lo..].iter().take_while(|e| e.0 <= f.centre.x + reach).map(|e| e.1);
                *ok = self.pushed_clear(&f, t)
                    && near.filter(|&j| j != *i).all(|j| !m.touches(t, people[j].footprint_m))
                    && carried.is_none_or(|q| !m.touches(t, q));
            }
        }
        // In order, each thing still clear against the things kept before it.
        let mut kept: Vec<usize> = Vec::new();
        for (n, (_, _, m)) in drawn.iter().enumerate().filter(|(n, _)| clear[*n]) {
            let apart = |o: &Mover| (first..=last).map(|k| t0 + k as f64 * STEP_S).all(|t| o.footprint(t).apart(&m.footprint(t), 0.0));
            if kept.iter().all(|&o| apart(&drawn[o].2)) {
                kept.push(n);
            }
        }
        let mut pushers = Vec::with_capacity(kept.len());
        for n in kept {
            let (i, spec, mut m) = (drawn[n].0, &drawn[n].1, drawn[n].2.clone());
            m.first_vertex = self.env.positions.len();
            let what = if spec.kind == MoverKind::Stroller { "stroller pushed" } else { "trolley pushed" };
            self.add_mover(m, &spec.mesh, what);
            pushers.push(i);
        }
        pushers
    }
}

#[cfg(test)]
mod tests;
