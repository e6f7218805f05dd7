//! Stage 3: sampling one sequence. From a seeded RNG, a configuration and the walkable area:
//! the sensor's trajectory, the people (model, trajectory, initial gait phase, stride) and the
//! frame times. Everything here is f64 in the world frame; nothing touches the GPU.

use crate::config::{Config, WalkMode};
use crate::error::{Error, Result};
use crate::human::{stride_length_m, FootShift, GaitStyle, HumanModel, MotionMode, TOE_OFF};
use crate::scene::planner::WalkPath;
use crate::scene::{Trajectory, WalkableGrid};
use crate::input::tracks::Track;
use glam::{DMat4, DQuat, DVec2, DVec3};
use rand::RngExt;
use std::sync::Arc;

use long::{long_walk, walk_the_sensor, Crowd, LONG_TRIES};
use together::companion;
pub use long::{LEAVE_M, LONG_SEQUENCE_S};
pub use pauses::Pauses;

/// How a person moves through the world (floor plane, world frame).
#[derive(Clone, Debug, PartialEq)]
pub enum HumanPath {
    /// A circular arc at constant speed and yaw rate.
    Arc(Trajectory),
    /// A planned walk from a start to a goal through the walkable area, on a floor at z (m).
    Walk(WalkPath, f64),
    /// A recorded track; sequence time 0 is track time `t0_s`.
    Track(TrackPath),
    /// Another path walked with stops: the same places, the walk held still while stopped.
    Paused(Box<HumanPath>, Pauses),
    /// Beside another path, `lateral_m` to its left (negative: right) of it, at its pace: a
    /// companion walking side by side. Its distance (the gait's) is the other path's.
    Beside(Box<HumanPath>, f64),
    /// Paths one after another (a long sequence's walks to goal after goal, waits between
    /// them, leaving and coming back near the sensor): each holds from its start time to the
    /// next one's, in its own time from there; the distances add up, so the gait goes on.
    Legs(Arc<Vec<Leg>>),
}

/// One of [`HumanPath::Legs`]: `path` from sequence time `t0_s` on (its own time 0 there),
/// having walked `d0_m` before it.
#[derive(Clone, Debug, PartialEq)]
pub struct Leg {
    pub t0_s: f64,
    pub d0_m: f64,
    pub path: HumanPath,
}

/// The leg that holds at `t_s` (the first before the first leg starts).
fn leg_at(legs: &[Leg], t_s: f64) -> &Leg {
    &legs[legs.partition_point(|l| l.t0_s <= t_s).max(1) - 1]
}

impl From<Trajectory> for HumanPath {
    fn from(t: Trajectory) -> Self {
        HumanPath::Arc(t)
    }
}

impl HumanPath {
    /// Position at sequence time `t_s` (z = the floor the person stands on).
    pub fn position(&self, t_s: f64) -> DVec3 {
        match self {
            HumanPath::Arc(a) => a.position(t_s),
            HumanPath::Walk(w, z) => w.position(t_s) + DVec3::Z * *z,
            HumanPath::Track(k) => k.state(t_s).0.extend(k.z_m),
            HumanPath::Paused(p, s) => p.position(s.walked_time(t_s)),
            HumanPath::Beside(p, lateral) => {
                let h = p.heading_rad(t_s);
                p.position(t_s) + *lateral * DVec3::new(-h.sin(), h.cos(), 0.0)
            }
            HumanPath::Legs(l) => {
                let leg = leg_at(l, t_s);
                leg.path.position(t_s - leg.t0_s)
            }
        }
    }
    pub fn velocity(&self, t_s: f64) -> DVec3 {
        match self {
            HumanPath::Arc(a) => a.velocity(t_s),
            HumanPath::Walk(w, _) => w.velocity(t_s),
            HumanPath::Track(k) => k.state(t_s).1.extend(0.0),
            HumanPath::Paused(p, s) => p.velocity(s.walked_time(t_s)) * s.pace(t_s),
            HumanPath::Beside(p, lateral) => {
                let h = p.heading_rad(t_s);
                p.velocity(t_s) - *lateral * p.heading_rate(t_s) * DVec3::new(h.cos(), h.sin(), 0.0)
            }
            HumanPath::Legs(l) => {
                let leg = leg_at(l, t_s);
                leg.path.velocity(t_s - leg.t0_s)
            }
        }
    }
    /// Facing direction, radians counter-clockwise from +x.
    pub fn heading_rad(&self, t_s: f64) -> f64 {
        match self {
            HumanPath::Arc(a) => a.heading_rad(t_s),
            HumanPath::Walk(w, _) => w.heading_rad(t_s),
            HumanPath::Track(k) => k.state(t_s).2,
            HumanPath::Paused(p, s) => p.heading_rad(s.walked_time(t_s)),
            HumanPath::Beside(p, _) => p.heading_rad(t_s),
            HumanPath::Legs(l) => {
                let leg = leg_at(l, t_s);
                leg.path.heading_rad(t_s - leg.t0_s)
            }
        }
    }
    /// Rate of turn of the heading, rad/s: exact on arcs, a central difference over 1 ms
    /// elsewhere (lines joined by fillets and recorded tracks are smooth at that scale).
    pub fn heading_rate(&self, t_s: f64) -> f64 {
        match self {
            HumanPath::Arc(a) => a.yaw_rate_rps,
            HumanPath::Paused(p, s) => p.heading_rate(s.walked_time(t_s)) * s.pace(t_s),
            HumanPath::Beside(p, _) => p.heading_rate(t_s),
            HumanPath::Legs(l) => {
                let leg = leg_at(l, t_s);
                leg.path.heading_rate(t_s - leg.t0_s)
            }
            _ => {
                let h = 5e-4;
                (self.heading_rad(t_s + h) - self.heading_rad(t_s - h)) / (2.0 * h)
            }
        }
    }
    /// Distance walked since time 0, m (drives the gait phase).
    pub fn distance(&self, t_s: f64) -> f64 {
        match self {
            HumanPath::Arc(a) => a.distance(t_s),
            HumanPath::Walk(w, _) => w.distance(t_s),
            HumanPath::Track(k) => k.distance(t_s),
            HumanPath::Paused(p, s) => p.distance(s.walked_time(t_s)),
            HumanPath::Beside(p, _) => p.distance(t_s),
            HumanPath::Legs(l) => {
                let leg = leg_at(l, t_s);
                leg.d0_m + leg.path.distance(t_s - leg.t0_s)
            }
        }
    }
    /// The first time at which the distance walked is `d_m` (before 0 or past a track's
    /// table: at the speed there); None where the path does not get there (standing still).
    pub fn time_at_distance(&self, d_m: f64) -> Option<f64> {
        let at_speed = |t0: f64, d0: f64, v: f64| (v > 1e-9).then(|| t0 + (d_m - d0) / v);
        match self {
            HumanPath::Paused(p, s) => p.time_at_distance(d_m).and_then(|u| s.time_walked(u)),
            HumanPath::Beside(p, _) => p.time_at_distance(d_m),
            HumanPath::Legs(l) => {
                // The last leg that starts short of the distance, or an earlier one where
                // that one stands.
                let i = l.partition_point(|g| g.d0_m < d_m).max(1) - 1;
                l[..=i].iter().rev().find_map(|g| g.path.time_at_distance(d_m - g.d0_m).map(|u| g.t0_s + u))
            }
            HumanPath::Arc(a) => at_speed(0.0, 0.0, a.speed_mps),
            HumanPath::Walk(w, _) => at_speed(0.0, 0.0, w.speed_mps()),
            HumanPath::Track(k) => k.time_at_distance(d_m),
        }
    }
}

/// How the sensor moves: a sampled arc, or recorded poses.
#[derive(Clone, Debug, PartialEq)]
pub enum SensorPath {
    Arc(Trajectory),
    Poses(PoseTrack),
    /// Walked through the walkable area like a person (a long sequence's goal after goal,
    /// turning on the spot between walks), at height `z` above its floor, facing its way.
    Walk(Box<HumanPath>, f64),
}

impl From<Trajectory> for SensorPath {
    fn from(t: Trajectory) -> Self {
        SensorPath::Arc(t)
    }
}

impl SensorPath {
    /// `world_from_sensor` at sequence time `t_s`.
    pub fn pose(&self, t_s: f64) -> DMat4 {
        match self {
            SensorPath::Arc(a) => a.pose(t_s),
            SensorPath::Poses(p) => p.pose(t_s),
            SensorPath::Walk(w, z) => DMat4::from_translation(w.position(t_s) + DVec3::Z * *z) * DMat4::from_rotation_z(w.heading_rad(t_s)),
        }
    }
    pub fn position(&self, t_s: f64) -> DVec3 {
        self.pose(t_s).w_axis.truncate()
    }
    /// World velocity, m/s.
    pub fn velocity(&self, t_s: f64) -> DVec3 {
        match self {
            SensorPath::Arc(a) => a.velocity(t_s),
            SensorPath::Poses(p) => p.sample(t_s).1,
            SensorPath::Walk(w, _) => w.velocity(t_s),
        }
    }
    /// Yaw rate about the world z axis, rad/s.
    pub fn yaw_rate_rps(&self, t_s: f64) -> f64 {
        match self {
            SensorPath::Arc(a) => a.yaw_rate_rps,
            SensorPath::Poses(p) => p.sample(t_s).2,
            SensorPath::Walk(w, _) => w.heading_rate(t_s),
        }
    }
    /// Heading of the sensor's x axis, radians counter-clockwise from world +x.
    pub fn heading_rad(&self, t_s: f64) -> f64 {
        match self {
            SensorPath::Arc(a) => a.heading_rad(t_s),
            SensorPath::Walk(w, _) => w.heading_rad(t_s),
            SensorPath::Poses(p) => {
                let x = p.pose(t_s).x_axis;
                x.y.atan2(x.x)
            }
        }
    }
    /// The start position in the floor plane.
    pub fn start_xy(&self) -> DVec2 {
        self.position(0.0).truncate()
    }
}

/// Recorded sensor poses of a window, with velocities and yaw rates from the poses.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseTrack {
    /// Sequence times of the poses, s (the first is 0), strictly increasing.
    pub times_s: Vec<f64>,
    pub world_from_sensor: Vec<DMat4>,
    pub velocity_mps: Vec<DVec3>,
    pub yaw_rate_rps: Vec<f64>,
}

impl PoseTrack {
    /// Velocities and yaw rates by the three-point derivative for uneven steps over each pose's
    /// neighbours (one-sided at the ends), so a window cut from a longer recording can use the
    /// poses just outside it: pass them as `before` / `after`.
    pub fn from_poses(times_s: &[f64], poses: &[DMat4], window: std::ops::Range<usize>) -> PoseTrack {
        let n = poses.len();
        let pos = |k: usize| poses[k].w_axis.truncate();
        let yaw = |k: usize| {
            let x = poses[k].x_axis;
            x.y.atan2(x.x)
        };
        let wrap = crate::geometry::wrap_pi;
        let deriv = |k: usize| -> (DVec3, f64) {
            if n < 2 {
                return (DVec3::ZERO, 0.0);
            }
            let (a, b) = if k == 0 { (0, 1) } else if k + 1 == n { (n - 2, n - 1) } else { (k - 1, k + 1) };
            if k == 0 || k + 1 == n {
                let dt = times_s[b] - times_s[a];
                return ((pos(b) - pos(a)) / dt, wrap(yaw(b) - yaw(a)) / dt);
            }
            // f'(t_k) of the parabola through (a, k, b).
            let (h1, h2) = (times_s[k] - times_s[a], times_s[b] - times_s[k]);
            let (wa, wk, wb) = (-h2 / (h1 * (h1 + h2)), (h2 - h1) / (h1 * h2), h1 / (h2 * (h1 + h2)));
            let v = pos(a) * wa + pos(k) * wk + pos(b) * wb;
            // Yaw differences relative to frame k, so the wrap at +-pi never enters.
            let (ya, yb) = (wrap(yaw(a) - yaw(k)), wrap(yaw(b) - yaw(k)));
            (v, ya * wa + yb * wb)
        };
        let t0 = times_s[window.start];
        let mut out = PoseTrack { times_s: Vec::new(), world_from_sensor: Vec::new(), velocity_mps: Vec::new(), yaw_rate_rps: Vec::new() };
        for k in window {
            let (v, w) = deriv(k);
            out.times_s.push(times_s[k] - t0);
            out.world_from_sensor.push(poses[k]);
            out.velocity_mps.push(v);
            out.yaw_rate_rps.push(w);
        }
        out
    }

    /// Index and fraction of `t_s` between poses (clamped to the window).
    fn locate(&self, t_s: f64) -> (usize, f64) {
        let n = self.times_s.len();
        if n < 2 || t_s <= self.times_s[0] {
            return (0, 0.0);
        }
        if t_s >= self.times_s[n - 1] {
            return (n - 1, 0.0);
        }
        let i = self.times_s.partition_point(|&t| t <= t_s) - 1;
        (i, (t_s - self.times_s[i]) / (self.times_s[i + 1] - self.times_s[i]))
    }

    /// Pose at `t_s`: the recorded pose at a recorded time, else translation interpolated
    /// linearly and rotation by slerp.
    pub fn pose(&self, t_s: f64) -> DMat4 {
        let (i, f) = self.locate(t_s);
        if f == 0.0 {
            return self.world_from_sensor[i];
        }
        let (s0, r0, p0) = self.world_from_sensor[i].to_scale_rotation_translation();
        let (_, r1, p1) = self.world_from_sensor[i + 1].to_scale_rotation_translation();
        let r: DQuat = r0.slerp(r1, f);
        DMat4::from_scale_rotation_translation(s0, r, p0.lerp(p1, f))
    }

    /// (pose, velocity, yaw rate) at `t_s`; velocity and yaw rate interpolated linearly.
    fn sample(&self, t_s: f64) -> (DMat4, DVec3, f64) {
        let (i, f) = self.locate(t_s);
        if f == 0.0 {
            return (self.world_from_sensor[i], self.velocity_mps[i], self.yaw_rate_rps[i]);
        }
        let v = self.velocity_mps[i].lerp(self.velocity_mps[i + 1], f);
        let w = self.yaw_rate_rps[i] + f * (self.yaw_rate_rps[i + 1] - self.yaw_rate_rps[i]);
        (self.pose(t_s), v, w)
    }
}

/// One person of a sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct HumanPlan {
    /// Index into the loaded models.
    pub model: usize,
    pub trajectory: HumanPath,
    /// Gait phase at t = 0, in [0, 1).
    pub phase0: f64,
    /// Stride length used to advance the gait, m.
    pub stride_m: f64,
    pub motion: MotionMode,
    /// Arm swing of this person's walk: 1 = the model's own, 0 = still (`humans.arm_swing`).
    pub arm_swing: f64,
    /// Stride over the model's own (the legs re-solved for it; `stride_m` is this times the
    /// model's stride), 1 = the animation as built.
    pub stride_scale: f64,
    /// Seated on a seat this high above the floor the whole sequence (`humans.sitting`), m; 0:
    /// not seated.
    pub seat_m: f64,
    /// Seated: how far ahead of the position the feet may reach, m; infinite otherwise.
    pub feet_room_m: f64,
    /// Pushing a stroller or a trolley the whole sequence (`humans.pushing`), held where this
    /// says: the arms held to its handle ([`GaitStyle::pushing`]); the thing is the world's
    /// (`crate::scene::world::World::add_pushed`). None: pushing nothing.
    pub pushed: Option<crate::scene::world::pushed::Held>,
}

/// A person's state at one instant (world frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HumanAt {
    pub position_m: DVec3,
    pub heading_rad: f64,
    pub velocity_mps: DVec3,
    pub gait_phase: f64,
    /// The person's arm swing ([`HumanPlan::arm_swing`]).
    pub arm_swing: f64,
    /// The person's stride over its model's ([`HumanPlan::stride_scale`]).
    pub stride_scale: f64,
    /// 1 = the walk at `gait_phase`, 0 = the standing pose; in between below
    /// [`STAND_BELOW_MPS`] (a walking person who stops comes to stand; `in-place` walks on).
    pub walking: f64,
    /// Where the path's turns move each foot (left, right) in the body frame so that a planted
    /// foot keeps its place and heading on the ground (see [`HumanPlan::foot_shifts`]).
    pub feet: [FootShift; 2],
    /// The person's seat and the room for its feet ([`HumanPlan::seat_m`], `feet_room_m`).
    pub seat_m: f64,
    pub feet_room_m: f64,
    /// Whether the person pushes something ([`HumanPlan::pushed`]).
    pub pushing: bool,
}

impl HumanAt {
    /// How the person walks at this instant (for posing its model).
    pub fn style(&self) -> GaitStyle {
        GaitStyle { walking: self.walking as f32, arm_swing: self.arm_swing as f32, stride: self.stride_scale as f32, feet: self.feet, seat_m: self.seat_m as f32, feet_room_m: self.feet_room_m as f32, pushing: self.pushing }
    }
}

/// Where a stance foot is pinned: the place and heading it has halfway through the stance.
const PINNED_AT: f64 = 0.5 * TOE_OFF as f64;

/// The largest move and turn of a planted foot for a curve, m and rad: a walk round a 0.5 m
/// radius moves it ~0.16 m and turns it ~0.8 rad between heel strike and mid-stance.
const MAX_FOOT_SHIFT_M: f64 = 0.3;
const MAX_FOOT_YAW_RAD: f64 = 1.2;

/// Below this speed a walking person blends toward the standing pose (linearly, standing at 0).
pub const STAND_BELOW_MPS: f64 = 0.1;

impl HumanPlan {
    /// Position at time `t_s` (that of [`HumanPlan::at`], without the gait's cost: sampling
    /// checks it at every frame against every other person).
    pub fn position_m(&self, t_s: f64) -> DVec3 {
        self.trajectory.position(if self.motion.moves() { t_s } else { 0.0 })
    }

    /// The times the person is taken from one place to another, s: a long sequence's legs that
    /// start more than half a metre from where the leg before ends (leaving and coming back in).
    pub fn cuts(&self) -> Vec<f64> {
        let HumanPath::Legs(legs) = &self.trajectory else { return Vec::new() };
        if !self.motion.moves() {
            return Vec::new();
        }
        let ends = |w: &[Leg]| w[0].path.position(w[1].t0_s - w[0].t0_s).truncate().distance(w[1].path.position(0.0).truncate());
        legs.windows(2).filter(|w| ends(w) > 0.5).map(|w| w[1].t0_s).collect()
    }

    /// Floor position, heading and speed at `t_s`, as [`HumanPlan::at`] gives them (without
    /// the gait's work).
    pub fn floor_pose(&self, t_s: f64) -> (DVec3, f64, f64) {
        let moves = self.motion.moves();
        let speed = if moves { self.trajectory.velocity(t_s).truncate().length() } else { 0.0 };
        (self.position_m(t_s), self.trajectory.heading_rad(if moves { t_s } else { 0.0 }), speed)
    }

    /// State at time `t_s` according to the motion mode (the paper's Table 5 ablations).
    pub fn at(&self, t_s: f64) -> HumanAt {
        let tr = &self.trajectory;
        let moves = self.motion.moves();
        let tm = if moves { t_s } else { 0.0 };
        let phase = if self.motion.animates() {
            (self.phase0 + tr.distance(t_s) / self.stride_m).rem_euclid(1.0)
        } else {
            self.phase0
        };
        let velocity_mps = if moves { tr.velocity(t_s) } else { DVec3::ZERO };
        let walking = if moves && self.motion.animates() {
            (velocity_mps.truncate().length() / STAND_BELOW_MPS).min(1.0)
        } else {
            1.0
        };
        let feet = if self.motion == MotionMode::Full { self.foot_shifts(t_s, phase) } else { [FootShift::ZERO; 2] };
        HumanAt {
            position_m: self.position_m(t_s),
            heading_rad: tr.heading_rad(tm),
            velocity_mps,
            gait_phase: phase,
            arm_swing: self.arm_swing,
            stride_scale: self.stride_scale,
            walking,
            feet,
            seat_m: self.seat_m,
            feet_room_m: self.feet_room_m,
            pushing: self.pushed.is_some(),
        }
    }

    /// Each foot's move in the body frame at `t_s` (gait phase `phase`) that keeps it planted
    /// where the path turns. The walk places a stance foot as on a straight path: in the body
    /// frame it moves straight back by the distance walked. On a curve the body also turns and
    /// moves sideways, so the foot is pinned instead where that straight walk puts it halfway
    /// through its stance, with that instant's heading: at time t the foot is moved by
    /// `B(t)^-1 B(t_pin) X(d(t) - d(t_pin))` (B the body's pose, X a move straight forward,
    /// d the distance walked), which is the identity on a straight line. Over the swing the
    /// move blends (smoothstep) from the one the foot left the ground with to the one the next
    /// stance lands it with. Zero for a person who does not walk.
    pub fn foot_shifts(&self, t_s: f64, phase: f64) -> [FootShift; 2] {
        let tr = &self.trajectory;
        let d = tr.distance(t_s);
        let pose = |t: f64| (tr.position(t).truncate(), tr.heading_rad(t));
        // The move at the instant `t_at` (distance `d_at`) of the stance pinned at `d_pin`.
        let shift = |at: (DVec2, f64), d_at: f64, d_pin: f64| -> Option<DVec3> {
            let (p_pin, h_pin) = pose(tr.time_at_distance(d_pin)?);
            let (p, h) = at;
            let pinned = p_pin + DVec2::from_angle(h_pin) * (d_at - d_pin);
            let local = DVec2::from_angle(-h).rotate(pinned - p);
            let yaw = crate::geometry::wrap_pi(h_pin - h);
            Some(local.extend(yaw))
        };
        let toe_off = TOE_OFF as f64;
        let stride = self.stride_m;
        [0.0, 0.5].map(|strike| {
            let u = (phase - strike).rem_euclid(1.0);
            let m = if u < toe_off {
                shift(pose(t_s), d, d + (PINNED_AT - u) * stride)
            } else {
                // From the stance the foot left (pinned (u - PINNED_AT) strides back) to the next.
                let (d_off, d_on) = (d - (u - toe_off) * stride, d + (1.0 - u) * stride);
                let at = |d_at: f64| tr.time_at_distance(d_at).map(pose);
                let left = at(d_off).and_then(|p| shift(p, d_off, d - (u - PINNED_AT) * stride));
                let next = at(d_on).and_then(|p| shift(p, d_on, d_on + PINNED_AT * stride));
                let x = ((u - toe_off) / (1.0 - toe_off)).clamp(0.0, 1.0);
                let w = x * x * (3.0 - 2.0 * x);
                left.zip(next).map(|(a, b)| a.lerp(b, w))
            };
            // A turn tighter than a walk makes (a recorded heading that swings round on the
            // spot) would pull the foot beyond the leg's reach: scaled back, continuously.
            let fit = m.map_or(0.0, |m| (MAX_FOOT_SHIFT_M / m.truncate().length()).min(MAX_FOOT_YAW_RAD / m.z.abs()).min(1.0));
            m.map_or(FootShift::ZERO, |m| FootShift { forward_m: (fit * m.x) as f32, left_m: (fit * m.y) as f32, yaw_rad: (fit * m.z) as f32 })
        })
    }
}

/// Everything sampled for one sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct SequencePlan {
    pub sensor: SensorPath,
    pub humans: Vec<HumanPlan>,
    /// Frame times, seconds from the start of the sequence.
    pub times_s: Vec<f64>,
    /// Index of the recorded background frame shown at frame 0, under a recording.
    pub recording_start: Option<usize>,
    /// World z of the floor the people stand on.
    pub floor_z_m: f64,
    /// The sequence's own built-in world, when the background is one.
    pub world: Option<Arc<crate::scene::world::World>>,
}

/// What a sequence is sampled from besides the configuration.
pub struct PlanInputs<'a> {
    /// Frame rate of a synthetic sensor path, Hz.
    pub rate_hz: f64,
    /// The walkable area (None: an empty, unbounded floor).
    pub grid: Option<&'a WalkableGrid>,
    pub models: &'a [HumanModel],
    /// Recorded pedestrian tracks (world frame); empty: synthetic people.
    pub tracks: &'a [Arc<Track>],
    /// The recorded sensor path of this window (its times are the frame times); None: an arc.
    pub sensor: Option<PoseTrack>,
    /// Height of the floor people stand on, world z, m.
    pub floor_z_m: f64,
    /// The sensor's path when the background sets it (a built-in street's lane); None: a
    /// sampled arc (or the recorded `sensor`, which wins).
    pub sensor_arc: Option<Trajectory>,
    /// Places people stand at and doorways they come out of (a built-in world's
    /// [`crate::scene::world::World::places`] and [`crate::scene::world::World::doors`]).
    pub places: &'a [crate::scene::world::Place],
    pub doors: &'a [crate::scene::world::Place],
    /// Seats people sit on (`humans.sitting`; [`crate::scene::world::World::seats`]).
    pub seats: &'a [crate::scene::world::Seat],
    /// The built-in world the sequence is planned in (what its people push, `humans.pushing`,
    /// is drawn from it and kept clear of it); None: none.
    pub world: Option<&'a crate::scene::world::World>,
}

/// Tries at joining the person placed before (`humans.groups`) before placing one alone.
const JOIN_TRIES: usize = 20;

/// How far a person standing at a place turns from its way (`humans.at_places`), either side.
const PLACE_FACING_RAD: f64 = std::f64::consts::FRAC_PI_6;

/// One or two stops of 1-6 s anywhere in a sequence of `duration` s (one may be under way at
/// its start).
fn sample_pauses(rng: &mut impl rand::Rng, duration: f64) -> Pauses {
    let n = if rng.random::<f64>() < 0.4 { 2 } else { 1 };
    let stops = (0..n)
        .map(|_| {
            let a = -2.0 + (duration + 2.0) * rng.random::<f64>();
            (a, a + 1.0 + 5.0 * rng.random::<f64>())
        })
        .collect();
    Pauses::new(stops)
}

/// Tries per person (synthetic) or per window (tracks) before giving up.
const TRIES: usize = 2000;
const TRACK_WINDOW_TRIES: usize = 200;

/// Samples the sensor trajectory and the people of one sequence.
pub fn sample_plan(rng: &mut impl rand::Rng, cfg: &Config, inp: &PlanInputs) -> Result<SequencePlan> {
    let mut plan = sample_paths(rng, cfg, inp)?;
    // Each person's style, drawn after the paths so that they do not depend on it: arm swing,
    // and a stride near the natural one for the person's mean speed (Alexander's relation,
    // times a personal factor), within what the model's legs can be re-solved for. The phase
    // then advances per that stride, and the legs cover it.
    let [lo, hi] = cfg.humans.arm_swing;
    let [s_lo, s_hi] = cfg.humans.stride_variation;
    let duration = plan.times_s.last().copied().unwrap_or(0.0);
    for h in &mut plan.humans {
        h.arm_swing = lo + (hi - lo) * rng.random::<f64>();
        let personal = s_lo + (s_hi - s_lo) * rng.random::<f64>();
        let model = &inp.models[h.model];
        let (k_lo, k_hi) = model.stride_scale_range();
        if let (Some(own), true) = (model.stride_length_m, k_lo < k_hi && h.motion.animates()) {
            let speed = match &h.trajectory {
                // A long sequence's walker waits between walks: its walking speed.
                HumanPath::Legs(l) => l.iter().map(|g| g.path.velocity(0.0).length()).fold(0.0, f64::max),
                _ if duration > 0.0 => h.trajectory.distance(duration) / duration,
                _ => 0.0,
            };
            let natural = stride_length_m(model.height_m as f64, speed.max(0.1)) * personal;
            h.stride_scale = (natural / own as f64).clamp(k_lo as f64, k_hi as f64);
            h.stride_m = h.stride_scale * own as f64;
        }
    }
    Ok(plan)
}

/// The sensor path, the people and their paths of a sequence (see [`sample_plan`]).
fn sample_paths(rng: &mut impl rand::Rng, cfg: &Config, inp: &PlanInputs) -> Result<SequencePlan> {
    let times_s: Vec<f64> = match &inp.sensor {
        Some(p) => p.times_s.clone(),
        None => (0..cfg.frames).map(|k| k as f64 / inp.rate_hz).collect(),
    };
    let duration = *times_s.last().unwrap_or(&0.0);
    let hc = &cfg.humans;
    let [lo, hi] = hc.count;
    let count = lo + (rng.random::<f64>() * (hi - lo + 1) as f64).floor().min((hi - lo) as f64) as usize;
    if inp.tracks.is_empty() {
        let sensor = match (&inp.sensor, inp.sensor_arc) {
            (Some(p), _) => SensorPath::Poses(p.clone()),
            (None, Some(a)) => SensorPath::Arc(a),
            (None, None) => match sample_sensor_arc(rng, cfg, inp.grid, &times_s, None) {
                // A long sequence where no arc fits: the sensor walks, goal after goal.
                Err(e) => match (duration > LONG_SEQUENCE_S, inp.grid) {
                    (true, Some(grid)) => walk_the_sensor(rng, cfg, grid, &times_s).ok_or(e)?,
                    _ => return Err(e),
                },
                ok => ok?,
            },
        };
        let humans = sample_synthetic_people(rng, cfg, inp, &sensor, &times_s, count)?;
        return Ok(SequencePlan { sensor, humans, times_s, recording_start: None, floor_z_m: inp.floor_z_m, world: None });
    }

    // Recorded tracks: a random window of the tracks' time span, the tracks that cover it
    // (and keep clear of obstacles and the sensor), `count` of them at random.
    let t_lo = inp.tracks.iter().map(|t| t.times_s[0]).fold(f64::INFINITY, f64::min);
    let t_hi = inp.tracks.iter().map(|t| *t.times_s.last().unwrap_or(&t.times_s[0])).fold(f64::NEG_INFINITY, f64::max);
    let mut best: Option<(SensorPath, Vec<HumanPlan>)> = None;
    for _ in 0..TRACK_WINDOW_TRIES {
        let t0 = t_lo + rng.random::<f64>() * (t_hi - duration - t_lo).max(0.0);
        let mut covering: Vec<usize> = (0..inp.tracks.len())
            .filter(|&i| {
                let t = &inp.tracks[i].times_s;
                t[0] <= t0 && *t.last().unwrap_or(&t[0]) >= t0 + duration
            })
            .collect();
        if covering.is_empty() {
            continue;
        }
        // A fixed-order shuffle (Fisher-Yates) so the choice depends only on the stream.
        for i in (1..covering.len()).rev() {
            let j = crate::scene::even_index(rng.random::<f64>(), i + 1);
            covering.swap(i, j);
        }
        let paths: Vec<TrackPath> =
            covering.iter().map(|&i| TrackPath::new(inp.tracks[i].clone(), t0, inp.floor_z_m, duration)).collect();
        let sensor = match (&inp.sensor, inp.sensor_arc) {
            (Some(p), _) => SensorPath::Poses(p.clone()),
            (None, Some(a)) => SensorPath::Arc(a),
            (None, None) => {
                // The sensor starts among the people of the window.
                let c = paths.iter().map(|p| p.state(0.0).0).fold(DVec2::ZERO, |a, b| a + b) / paths.len() as f64;
                match sample_sensor_arc(rng, cfg, inp.grid, &times_s, Some(c)) {
                    Ok(s) => s,
                    Err(_) => continue,
                }
            }
        };
        let mut humans = Vec::new();
        for path in paths {
            if humans.len() == count {
                break;
            }
            let path = HumanPath::Track(path);
            let clear = times_s.iter().all(|&t| {
                let p = path.position(t).truncate();
                inp.grid.is_none_or(|g| g.clearance(p) >= hc.clearance_m)
                    && p.distance(sensor.position(t).truncate()) >= hc.min_separation_m
            });
            if !clear {
                continue;
            }
            let model = crate::scene::pick_model(rng, inp.models.len(), hc.carrying);
            let mean_speed = if duration > 0.0 { path.distance(duration) / duration } else { 0.0 };
            // Pushing (drawn only where asked for, in a built-in world): a recorded walk is not
            // planned for it, the world keeps the thing only where it fits.
            let pushed = push::draw(rng, hc.pushing, inp.world, humans.len(), &inp.models[model]);
            humans.push(HumanPlan {
                model,
                trajectory: path,
                phase0: rng.random::<f64>(),
                stride_m: inp.models[model].gait_stride_m(mean_speed),
                motion: hc.motion,
                arm_swing: 1.0,
                stride_scale: 1.0,
                seat_m: 0.0,
                feet_room_m: f64::INFINITY,
                pushed,
            });
        }
        let enough = humans.len() >= lo.max(1).min(count.max(1));
        if best.as_ref().is_none_or(|b| humans.len() > b.1.len()) {
            best = Some((sensor, humans));
        }
        if enough {
            break;
        }
    }
    match best {
        Some((sensor, humans)) if !humans.is_empty() || count == 0 => Ok(SequencePlan { sensor, humans, times_s, recording_start: None, floor_z_m: inp.floor_z_m, world: None }),
        _ => Err(Error::input(
            "humans.tracks",
            format!(
                "no window of {duration:.2} s in which any track walks clear of obstacles and the sensor \
                 ({TRACK_WINDOW_TRIES} tries); check humans.tracks_transform and the frame period"
            ),
        )),
    }
}

/// A sensor arc that stays clear of obstacles for the whole window, starting anywhere free or
/// within `humans.spawn_radius_m` of `near`.
fn sample_sensor_arc(
    rng: &mut impl rand::Rng,
    cfg: &Config,
    grid: Option<&WalkableGrid>,
    times_s: &[f64],
    near: Option<DVec2>,
) -> Result<SensorPath> {
    let sc = &cfg.scene;
    let uniform = |rng: &mut dyn FnMut() -> f64, r: [f64; 2]| r[0] + (r[1] - r[0]) * rng();
    let mut u01 = || rng.random::<f64>();
    for _ in 0..TRIES {
        let start = match (near, grid) {
            (Some(c), _) => {
                let r = cfg.humans.spawn_radius_m * u01().sqrt();
                let a = u01() * std::f64::consts::TAU;
                c + r * DVec2::new(a.cos(), a.sin())
            }
            (None, Some(g)) => DVec2::new(g.origin.x + u01() * g.nx as f64 * g.cell_m, g.origin.y + u01() * g.ny as f64 * g.cell_m),
            (None, None) => DVec2::ZERO,
        };
        if grid.is_some_and(|g| g.clearance(start) < sc.sensor_clearance_m) {
            continue;
        }
        let tr = Trajectory {
            start_m: start,
            z_m: sc.sensor_height_m,
            heading0_rad: (u01() * 2.0 - 1.0) * std::f64::consts::PI,
            speed_mps: uniform(&mut u01, sc.sensor_speed_mps),
            yaw_rate_rps: uniform(&mut u01, sc.sensor_yaw_rate_rps),
        };
        if grid.is_none_or(|g| times_s.iter().all(|&t| g.clearance(tr.position(t).truncate()) >= sc.sensor_clearance_m)) {
            return Ok(SensorPath::Arc(tr));
        }
    }
    Err(Error::input(
        "scene.background",
        format!(
            "no room for the sensor's trajectory (tried {TRIES} starts); lower scene.sensor_speed_mps or scene.sensor_clearance_m"
        ),
    ))
}

/// `count` synthetic people around the sensor's start, clear of obstacles, of the sensor and
/// of each other at every frame.
fn sample_synthetic_people(
    rng: &mut impl rand::Rng,
    cfg: &Config,
    inp: &PlanInputs,
    sensor: &SensorPath,
    times_s: &[f64],
    count: usize,
) -> Result<Vec<HumanPlan>> {
    let hc = &cfg.humans;
    let duration = *times_s.last().unwrap_or(&0.0);
    let uniform = |rng: &mut dyn FnMut() -> f64, r: [f64; 2]| r[0] + (r[1] - r[0]) * rng();
    let mut humans: Vec<HumanPlan> = Vec::with_capacity(count);
    // A planned walk ends at least `speed * duration` from its start, so the free area's span
    // bounds how long people can walk in it: too long a sequence is the setting to name.
    let free_span = match (hc.walk, inp.grid) {
        (WalkMode::Goals, Some(g)) if count > 0 => Some(g.free_span_m(hc.clearance_m)),
        _ => None,
    };
    let recorded = if inp.sensor.is_some() { " of the recording" } else { "" };
    let walk_length = |speed: f64| {
        free_span.filter(|&span| speed * duration > span).map(|span| {
            format!(
                "{} frames{recorded} last {duration:.1} s: a person walking at {speed} m/s (humans.speed_mps) goes {:.1} m, \
                 but the free walkable area is at most {span:.1} m across",
                times_s.len(),
                speed * duration
            )
        })
    };
    // Long sequences, and those one walk to one goal cannot last in the free area, walk goal
    // after goal (`long_walk`).
    let long = free_span.is_some_and(|span| duration > LONG_SEQUENCE_S || hc.speed_mps[1] * duration > span);
    let s0 = sensor.start_xy();
    // Where the sensor is halfway through (`humans.before_things`, `behind_things`).
    let mid = sensor.position(duration * 0.5).truncate();
    let mut planner = inp.grid.map(|_| crate::scene::planner::Planner::new());
    // The world's places within reach (`humans.at_places`).
    let places: Vec<crate::scene::world::Place> = inp.places.iter().copied().filter(|q| q.at.distance(s0) <= hc.spawn_radius_m).collect();
    let seats: Vec<crate::scene::world::Seat> = inp.seats.iter().copied().filter(|q| q.at.distance(s0) <= hc.spawn_radius_m).collect();
    // The times the world checks a pushed thing at, the last frame's sweep included.
    let thing_times: Vec<f64> = match inp.world {
        Some(_) if hc.pushing > 0.0 => crate::scene::world::pushed::checked_times(duration + 1.0 / inp.rate_hz).collect(),
        _ => Vec::new(),
    };
    // People are placed in turn; one who finds no room because of the things pushed before
    // them (a long sequence's crowd has to keep clear of them for minutes) takes the things
    // from the pushers placed before (their walks keep clear without them) and is placed again.
    let mut k = 0;
    while k < count {
        let model = crate::scene::pick_model(rng, inp.models.len(), hc.carrying);
        let joining = hc.groups > 0.0 && k > 0 && rng.random::<f64>() < hc.groups;
        let stands = hc.standing > 0.0 && rng.random::<f64>() < hc.standing;
        // Drawn only where asked for, as the other behaviours.
        let by_thing = stands && hc.by_things > 0.0 && rng.random::<f64>() < hc.by_things;
        let at_place = stands && hc.at_places > 0.0 && !places.is_empty() && rng.random::<f64>() < hc.at_places;
        let before = hc.before_things > 0.0 && rng.random::<f64>() < hc.before_things;
        let behind = hc.behind_things > 0.0 && rng.random::<f64>() < hc.behind_things;
        // Pushing something (drawn only where asked for, in a built-in world), for the first
        // half of the tries (it may fit nowhere): the walk then turns gently enough for it,
        // and the thing is kept clear as the person is.
        let push = push::draw(rng, hc.pushing, inp.world, k, &inp.models[model]);
        let mut placed = None;
        let mut tries = 0;
        // Clear of the sensor and the others at every frame; placeable where it stands on free
        // floor too (a seat is an obstacle of the walkable area).
        let clear = |plan: &HumanPlan| {
            times_s.iter().all(|&t| {
                let p = plan.footprint_m(t);
                p.distance(sensor.position(t).truncate()) >= hc.min_separation_m
                    && humans.iter().all(|h| h.footprint_m(t).distance(p) >= hc.min_separation_m)
                    && push::others_clear(inp.world, &humans, p, t)
            }) && (plan.pushed.is_none() || thing_times.iter().all(|&t| plan.pushed_at(t).is_none_or(|f| inp.world.is_none_or(|w| push::thing_clear(w, &humans, Some(sensor), &f, t)))))
        };
        let placeable = |plan: &HumanPlan| {
            times_s.iter().all(|&t| inp.grid.is_none_or(|g| g.clearance(plan.position_m(t).truncate()) >= hc.clearance_m)) && clear(plan)
        };
        // Seated on a free seat, where drawn to (drawn only where asked for).
        if hc.sitting > 0.0 && rng.random::<f64>() < hc.sitting {
            if let Some(p) = seats::seat(rng, &seats, (model, &inp.models[model]), inp.floor_z_m, hc.motion, clear) {
                humans.push(p);
                k += 1;
                continue;
            }
        }
        for attempt in 0..TRIES {
            let mut u01 = || rng.random::<f64>();
            let r = hc.spawn_radius_m * u01().sqrt();
            let a = u01() * std::f64::consts::TAU;
            let mut start = s0 + r * DVec2::new(a.cos(), a.sin());
            // At a place for the first half of the tries (the places may all be taken), then
            // anywhere.
            let at_place = at_place && attempt < TRIES / 2;
            let held = push.filter(|_| attempt < TRIES / 2);
            let mut facing = None;
            if at_place {
                let q = places[crate::scene::even_index(u01(), places.len())];
                start = q.at;
                facing = Some(q.facing_rad);
            }
            let mut speed = uniform(&mut u01, hc.speed_mps);
            // Behaviours (drawn only where asked for, so a run without them draws as before):
            // joining the person placed last, standing.
            let joins = tries < JOIN_TRIES && k > 0 && hc.groups > 0.0 && joining;
            if joins {
                let leader = &humans[k - 1];
                let plan = companion(rng, leader, model, &inp.models[model]);
                if placeable(&plan) {
                    placed = Some(plan);
                    break;
                }
                tries += 1;
                continue;
            }
            if inp.grid.is_some_and(|g| g.clearance(start) < hc.clearance_m) {
                continue;
            }
            if by_thing && !at_place && inp.grid.is_some_and(|g| g.clearance(start) > hc.clearance_m + crate::config::BY_THING_M) {
                continue;
            }
            // Before something tall, behind something low, for the first half of the tries
            // (there may be no such spot).
            let wanted = |g: &WalkableGrid| (!before || g.obstacle_behind(mid, start, crate::scene::BEFORE_THING_M)) && (!behind || g.low_obstacle_before(mid, start, crate::scene::BEHIND_THING_M));
            if (before || behind) && !at_place && attempt < TRIES / 2 && inp.grid.is_some_and(|g| !wanted(g)) {
                continue;
            }
            // One standing behind something faces it, as at a counter (at a place: the place's way).
            facing = facing.or((behind && attempt < TRIES / 2 && inp.grid.is_some()).then(|| (mid - start).to_angle()));
            if long {
                if tries >= LONG_TRIES {
                    break;
                }
                let held = push.filter(|_| tries < LONG_TRIES / 2);
                tries += 1;
                let (Some(grid), Some(planner)) = (inp.grid, planner.as_mut()) else { unreachable!("long sequences have a walkable area") };
                let crowd = Crowd { grid, clearance_m: hc.clearance_m, separation_m: hc.min_separation_m, sensor: Some(sensor), others: &humans, times_s, doors: inp.doors, world: inp.world, held, thing_times: &thing_times };
                planner.min_turn_radius_m = held.map_or(0.0, |_| speed.max(0.1) / push::TURN_RPS);
                let Some(path) = long_walk(rng, planner, &crowd, start, speed.max(0.1), stands, hc.spawn_radius_m, inp.floor_z_m, duration) else { continue };
                placed = Some(HumanPlan {
                    model,
                    trajectory: path,
                    phase0: rng.random::<f64>(),
                    stride_m: inp.models[model].gait_stride_m(speed),
                    motion: hc.motion,
                    arm_swing: 1.0,
                    stride_scale: 1.0,
                    seat_m: 0.0,
                    feet_room_m: f64::INFINITY,
                    pushed: held,
                });
                break;
            }
            if stands {
                speed = 0.0;
            }
            let path: HumanPath = match (hc.walk, inp.grid, planner.as_mut()) {
                // A person who does not walk (speed 0) stands: no path to plan.
                (WalkMode::Goals, Some(grid), Some(planner)) if speed > 0.0 => {
                    planner.min_turn_radius_m = held.map_or(0.0, |_| speed / push::TURN_RPS);
                    match planner.plan_walk(rng, grid, hc.clearance_m, speed, duration, Some(start)) {
                        Some(w) => HumanPath::Walk(w, inp.floor_z_m),
                        None => continue,
                    }
                }
                _ if stands => {
                    // Waiting or looking around: a third turn on the spot. At a place or
                    // behind something, facing its way give or take 30 degrees.
                    let mut u01 = || rng.random::<f64>();
                    let heading = match facing {
                        Some(f) => f + (u01() * 2.0 - 1.0) * PLACE_FACING_RAD,
                        None => (u01() * 2.0 - 1.0) * std::f64::consts::PI,
                    };
                    let turn = if u01() < 1.0 / 3.0 { (0.15 + 0.35 * u01()) * if u01() < 0.5 { -1.0 } else { 1.0 } } else { 0.0 };
                    // One with something to push stands still with it.
                    let turn = if held.is_some() { 0.0 } else { turn };
                    HumanPath::Arc(Trajectory { start_m: start, z_m: inp.floor_z_m, heading0_rad: heading, speed_mps: 0.0, yaw_rate_rps: turn })
                }
                _ => {
                    let mut u01 = || rng.random::<f64>();
                    let heading0_rad = (u01() * 2.0 - 1.0) * std::f64::consts::PI;
                    let yaw = uniform(&mut u01, hc.yaw_rate_rps);
                    // One who pushes turns it gently.
                    let yaw_rate_rps = if held.is_some() { yaw.clamp(-push::TURN_RPS, push::TURN_RPS) } else { yaw };
                    HumanPath::Arc(Trajectory { start_m: start, z_m: inp.floor_z_m, heading0_rad, speed_mps: speed, yaw_rate_rps })
                }
            };
            let path = if speed > 0.0 && hc.stop_and_go > 0.0 && rng.random::<f64>() < hc.stop_and_go {
                HumanPath::Paused(Box::new(path), sample_pauses(rng, duration))
            } else {
                path
            };
            let plan = HumanPlan {
                model,
                trajectory: path,
                phase0: rng.random::<f64>(),
                stride_m: inp.models[model].gait_stride_m(speed),
                motion: hc.motion,
                arm_swing: 1.0,
                stride_scale: 1.0,
                seat_m: 0.0,
                feet_room_m: f64::INFINITY,
                pushed: held,
            };
            if placeable(&plan) {
                placed = Some(plan);
                break;
            }
        }
        match placed {
            Some(p) => {
                humans.push(p);
                k += 1;
            }
            None if humans.iter().any(|h| h.pushed.is_some()) => {
                for h in &mut humans {
                    h.pushed = None;
                }
            }
            None => {
                // Only the faster walkers may be too long for the area: say so too.
                let long = walk_length(hc.speed_mps[1])
                    .map(|m| format!("; also, {m}: lower --frames (config key `frames`) or humans.speed_mps"))
                    .unwrap_or_default();
                return Err(Error::input(
                    "humans",
                    format!(
                        "could place only {k} of {count} people without collisions ({TRIES} tries each); \
                         lower humans.count, humans.min_separation_m or raise humans.spawn_radius_m{long}"
                    ),
                ));
            }
        }
    }
    Ok(humans)
}

mod long;
mod pauses;
mod push;
mod seats;
mod together;
mod track;
pub use track::TrackPath;

#[cfg(test)]
mod tests;
