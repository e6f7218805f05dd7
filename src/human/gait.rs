//! The gait: the walk sampled at a phase, the stride re-solved by two-bone IK, the stance foot
//! placed about its heel and toe.

use super::*;
use glam::{Mat4, Quat, Vec3, Vec4};

/// Gait events of the bundled people's walk (`tools/humans/README.md`), in cycles after a
/// foot's heel strike (the left foot strikes at phase 0, the right at 0.5): the toes leave
/// the ground.
pub const TOE_OFF: f32 = 0.62;
/// The stance ankle passes under the hip.
pub const UNDER_HIP: f32 = 0.25;

/// How a person walks, beside the phase: 1 / 1 is the model's own walk.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaitStyle {
    /// 1 = walking, 0 = the standing pose (blended in between).
    pub walking: f32,
    /// The arms' swing about their standing pose: 1 = the animation's, 0 = none.
    pub arm_swing: f32,
    /// Stride over the model's own ([`HumanModel::stride_scale_range`]): the ankles' fore-and-aft
    /// travel relative to the hips is scaled by it and the legs re-solved (two-bone IK), so the
    /// walk covers this times the model's stride per cycle with the feet still planted.
    pub stride: f32,
    /// Per foot (left, right): where the path's turns put it beside the straight walk, body
    /// frame (see [`FootShift`]); zero on a straight path.
    pub feet: [FootShift; 2],
    /// Seated on a seat this high above the floor, m: the standing pose lowered onto it where
    /// the model can sit ([`HumanModel::can_sit`]), else the standing pose; the walk and the
    /// rest of the style ignored. 0: not seated.
    pub seat_m: f32,
    /// Seated: how far ahead of the origin (the floor point under the hip joints) the feet may
    /// reach, toes included, m; the ankles are drawn back under the knees to keep them within
    /// it (a café table's foot ahead of its chair), though no nearer the hips than 0.4 of a
    /// thigh. Infinite: where the pose puts them.
    pub feet_room_m: f32,
    /// Pushing a stroller or a trolley: the arms held forward to its handle, not swinging,
    /// where the model can push ([`HumanModel::can_push`]); the walk as it is.
    pub pushing: bool,
}

impl GaitStyle {
    /// The model's own walk.
    pub const WALK: GaitStyle = GaitStyle { walking: 1.0, arm_swing: 1.0, stride: 1.0, feet: [FootShift::ZERO; 2], seat_m: 0.0, feet_room_m: f32::INFINITY, pushing: false };
}

/// A planar rigid move of one foot in the body frame (x forward, y left, yaw about z up),
/// applied after the walk has placed it: `p -> R(yaw) p + (forward, left)`. On a curved path a
/// planted foot has to move in the body frame, which turns under it; the sequence computes this
/// move so that the foot keeps the world place and heading it has mid-stance
/// (`crate::scene::sequence::HumanPlan::at`), and blends it over the swing.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FootShift {
    pub forward_m: f32,
    pub left_m: f32,
    pub yaw_rad: f32,
}

impl FootShift {
    pub const ZERO: FootShift = FootShift { forward_m: 0.0, left_m: 0.0, yaw_rad: 0.0 };
}

/// The nodes of one leg the stride scaling re-solves: hip (thigh bone), knee (shank bone),
/// ankle (foot bone); and where the foot pivots on the ground in the stance, model frame at
/// rest (the bundled people's walk, `tools/humans/README.md`): the heel contact point (the
/// rear-most point of the sole, under the ankle) during the heel rocker and the toe joint
/// (first metatarsophalangeal) during the forefoot rocker.
#[derive(Clone, Copy, Debug)]
pub(super) struct Leg {
    pub(super) thigh: usize,
    pub(super) shank: usize,
    pub(super) foot: usize,
    ankle: Vec3,
    heel: Vec3,
    mtp: Vec3,
    /// The sole's front-most point (the toes' tip) ahead of the ankle in the rest pose, m.
    pub(super) toes_m: f32,
    /// Forward (model z) translation of the flat foot from rest when its ankle passes under
    /// the hip (phase 0.25 after its heel strike).
    flat_under_hip: f32,
}
impl HumanModel {
    /// Joint matrices (model frame) of the walk sampled at `phase` in [0, 1).
    pub fn joint_matrices(&self, phase: f32, out: &mut Vec<Mat4>) {
        self.joint_matrices_styled(phase, GaitStyle::WALK, out);
    }

    /// Joint matrices of the walk at `phase` in `style`: the arm bones' rotations scaled
    /// about their standing pose by `arm_swing`, then everything blended with the standing
    /// pose by `walking` (1 = the walk, 0 = standing; rotations slerped, translations
    /// interpolated).
    pub fn joint_matrices_styled(&self, phase: f32, style: GaitStyle, out: &mut Vec<Mat4>) {
        self.joint_globals(phase.rem_euclid(1.0) * self.cycle_s, style, out);
        for (m, inverse_bind) in out.iter_mut().zip(&self.inverse_bind) {
            *m *= *inverse_bind;
        }
    }

    /// Global transforms (model frame) of the joints at time `t` (s) of the walk in `style`.
    pub(super) fn joint_globals(&self, t: f32, style: GaitStyle, out: &mut Vec<Mat4>) {
        // Asked to sit, a model stands (and sits where it can).
        let seated = style.seat_m > 0.0 && self.can_sit();
        let walk = if style.seat_m > 0.0 { 0.0 } else { style.walking.clamp(0.0, 1.0) };
        out.clear();
        if self.joint_nodes.is_empty() {
            return;
        }
        let mut local: Vec<(Vec3, Quat, Vec3)> =
            self.nodes.iter().map(|n| (n.translation, n.rotation, n.scale)).collect();
        let pushing = style.pushing && !seated && self.can_push();
        for ch in &self.channels {
            // A person pushing holds the arms still (then turns them to the handle, below).
            let mut v = if walk > 0.0 && !(pushing && ch.arm) { sample(ch, t) } else { ch.stand };
            if ch.arm && walk > 0.0 && style.arm_swing != 1.0 {
                // stand * (stand^-1 v)^a: the swing's angle scaled, its axis kept.
                let stand = Quat::from_vec4(ch.stand).normalize();
                let swing = (stand.inverse() * Quat::from_vec4(v).normalize()).normalize();
                v = Vec4::from(stand * Quat::from_scaled_axis(swing.to_scaled_axis() * style.arm_swing));
            }
            if walk > 0.0 && walk < 1.0 {
                v = if ch.property == Property::Rotation {
                    Vec4::from(Quat::from_vec4(ch.stand).normalize().slerp(Quat::from_vec4(v).normalize(), walk))
                } else {
                    ch.stand.lerp(v, walk)
                };
            }
            let l = &mut local[ch.node];
            match ch.property {
                Property::Translation => l.0 = v.truncate(),
                Property::Rotation => l.1 = Quat::from_vec4(v).normalize(),
                Property::Scale => l.2 = v.truncate(),
            }
        }
        let mut global: Vec<Option<Mat4>> = vec![None; self.nodes.len()];
        if let (Some((legs, root)), true) = (self.legs, walk > 0.0 && self.stride_length_m.is_some() && self.cycle_s > 0.0) {
            let phase = t / self.cycle_s;
            self.place_feet(&mut local, &mut global, legs, root, phase, 1.0 + walk * (style.stride - 1.0), walk, style.feet);
        }
        if seated {
            self.seat(&mut local, &mut global, style.seat_m, style.feet_room_m);
        }
        if pushing {
            self.push_arms(&mut local, &mut global);
        }
        out.extend(self.joint_nodes.iter().map(|&node| global_of(&self.nodes, &local, &mut global, node)));
    }

    /// The stride scales a model's own stride takes without strain: its walk re-solved for
    /// 0.75 to 1.2 times the recorded stride.
    pub fn stride_scale_range(&self) -> (f32, f32) {
        if self.legs.is_some() && self.stride_length_m.is_some() {
            (0.75, 1.2)
        } else {
            (1.0, 1.0)
        }
    }

    /// The legs' rest pivots, as the builder of the bundled people takes them: the heel contact
    /// point is the rear-most vertex of the sole (the full mesh's lowest centimetre, more than
    /// 2 cm to the foot's side of the midline) under the ankle, the toe pivot the toe joint.
    /// The flat foot's forward translation under the hip follows the builder's placement too
    /// (both heels strike where the left one's ankle passes under the left hip a quarter of a
    /// stride later). None where a foot has no sole.
    pub(super) fn plant_legs(&self, legs: [[usize; 4]; 2]) -> Option<[Leg; 2]> {
        let at = |n: usize| global_rest(&self.nodes, n).w_axis.truncate();
        let rest = &self.lods.first()?.positions;
        let mut out = Vec::with_capacity(2);
        for ([thigh, shank, foot, toe], side) in legs.into_iter().zip([1.0f32, -1.0]) {
            let ankle = at(foot);
            let sole = || rest.iter().filter(|p| p.y < 0.01 && side * p.x > 0.02).map(|p| p.z);
            let (back, front) = (sole().fold(f32::INFINITY, f32::min), sole().fold(f32::NEG_INFINITY, f32::max));
            if !back.is_finite() {
                return None;
            }
            let toes_m = front - ankle.z;
            out.push(Leg { thigh, shank, foot, ankle, heel: Vec3::new(ankle.x, 0.0, back), mtp: at(toe), toes_m, flat_under_hip: 0.0 });
        }
        let (hip_l, ankle_l, heel_l) = (at(out[0].thigh).z, out[0].ankle.z, out[0].heel.z);
        for leg in &mut out {
            leg.flat_under_hip = hip_l - ankle_l + heel_l - leg.heel.z;
        }
        Some([out[0], out[1]])
    }

    /// Global transform of node `i` at time `t` of the walk (the model's own walk, as
    /// [`HumanModel::joint_globals`] gives it in [`GaitStyle::WALK`]), from its chain alone.
    fn walk_global(&self, i: usize, t: f32) -> Mat4 {
        let n = &self.nodes[i];
        let (mut tr, mut rot, mut scale) = (n.translation, n.rotation, n.scale);
        for ch in self.channels.iter().filter(|c| c.node == i) {
            let v = sample(ch, t);
            match ch.property {
                Property::Translation => tr = v.truncate(),
                Property::Rotation => rot = Quat::from_vec4(v).normalize(),
                Property::Scale => scale = v.truncate(),
            }
        }
        let m = Mat4::from_scale_rotation_translation(scale, rot, tr);
        match n.parent {
            Some(p) => self.walk_global(p, t) * m,
            None => m,
        }
    }

    /// Places both feet of the pose `local` at `phase` and re-solves the legs, for `k` times
    /// the model's stride, `walk` of the way from the animation to the planted feet, each foot
    /// moved by `feet` (scaled by `walk`). Model frame: y up, the person faces +z.
    ///
    /// Over the stance a foot is placed as the builder placed it, but exactly rather than as
    /// the animation's keys interpolate it: rotated by its animated orientation (the heel and
    /// forefoot rockers) about its ground pivot (the heel contact point until the foot is flat,
    /// the toe joint after), the pivot moving backwards at `k` strides per cycle through the
    /// place where the flat foot has its ankle under the hip a quarter of a cycle after heel
    /// strike. Every point of the planted foot then moves at `k` times `stride / cycle`, which
    /// the phase (advanced per `k` strides) matches, so it stays where it is on the ground. Over
    /// the swing the foot follows the animation, moved fore or aft by `(k - 1) c(phase)`, `c`
    /// a cubic from where the stance leaves it to where the next one starts with the stance's
    /// slope at both ends (so at any `k` the foot leaves and meets the ground with no
    /// horizontal speed in the world, as the animation does at `k = 1`), and what the exact
    /// stance differed from the animation at toe-off fades out. The gait
    /// events are the bundled people's contract (`tools/humans/README.md`): left heel strike at
    /// phase 0, right at 0.5, toe-off 0.62 of the cycle after, foot flat from 0.10 to 0.31,
    /// ankle under the hip at 0.25.
    ///
    /// The pelvis moves up or down so that the more stretched leg is exactly as stretched as in
    /// the animation at this phase (a shorter stride stands taller), then each leg is a two-bone
    /// chain (hip -> knee -> ankle) bent in the plane of its animated knee.
    /// `cache` holds the globals of `local` (or `None`s) and is left consistent with the result.
    #[allow(clippy::too_many_arguments)]
    fn place_feet(
        &self,
        local: &mut [(Vec3, Quat, Vec3)],
        cache: &mut [Option<Mat4>],
        legs: [Leg; 2],
        root: usize,
        phase: f32,
        k: f32,
        walk: f32,
        feet: [FootShift; 2],
    ) {
        // Halfway through the flat foot: the pivot changes from the heel to the toe joint.
        const HEEL_TO_TOE: f32 = 0.205;
        let stride = self.stride_length_m.unwrap_or(0.0);
        // Over the swing the stance's line `c(u) = -stride (u - 0.25)` continues as a cubic
        // back to where the next stance starts, with the stance's slope at both ends: the foot
        // leaves and meets the ground at the speed the stance has (none, in the world).
        let swing_line = |u: f32| {
            let (back, front) = (-stride * (TOE_OFF - UNDER_HIP), stride * UNDER_HIP);
            let slope = -stride * (1.0 - TOE_OFF);
            let x = (u - TOE_OFF) / (1.0 - TOE_OFF);
            let (x2, x3) = (x * x, x * x * x);
            let c = (2.0 * x3 - 3.0 * x2 + 1.0) * back + (x3 - 2.0 * x2 + x) * slope + (3.0 * x2 - 2.0 * x3) * front + (x3 - x2) * slope;
            (k - 1.0) * c
        };
        // The ankle and orientation of the stance foot at its own phase u, placed exactly.
        let planted = |leg: &Leg, u: f32, rot: Quat| {
            let pivot = if u < HEEL_TO_TOE { leg.heel } else { leg.mtp };
            pivot + Vec3::Z * (leg.flat_under_hip - k * stride * (u - UNDER_HIP)) + rot * (leg.ankle - pivot)
        };
        let pos = |m: Mat4| m.w_axis.truncate();
        // Animated hips, knees, ankles and foot orientations; the targets.
        let anim = self.leg_joints(local, cache, legs);
        let stretch = anim.iter().map(|&(h, _, a, _)| (a - h).length()).fold(0.0f32, f32::max);
        let mut targets = [(Vec3::ZERO, Quat::IDENTITY); 2];
        for (i, (leg, &(_, _, ankle, rot))) in legs.iter().zip(&anim).enumerate() {
            let u = (phase - 0.5 * i as f32).rem_euclid(1.0);
            let moved = if u < TOE_OFF {
                planted(leg, u, rot) - ankle
            } else {
                // The animation at toe-off, where the exact stance handed over.
                let t_off = (phase + TOE_OFF - u).rem_euclid(1.0) * self.cycle_s;
                let off = self.walk_global(leg.foot, t_off);
                let handover = planted(leg, TOE_OFF, Quat::from_mat4(&off).normalize()) - pos(off) - Vec3::Z * swing_line(TOE_OFF);
                let fade = 1.0 - smoothstep((u - TOE_OFF) / (1.0 - TOE_OFF));
                Vec3::Z * swing_line(u) + handover * fade
            };
            // The turn's move, in the model frame (body x forward = model z, body y left =
            // model x, body yaw = model yaw about y).
            let f = feet[i];
            let turn = Quat::from_rotation_y(walk * f.yaw_rad);
            let target = ankle + walk * moved;
            targets[i] = (turn * target + walk * Vec3::new(f.left_m, 0.0, f.forward_m), turn * rot);
        }
        // Pelvis height: the highest at which no leg reaches further than `stretch`.
        let lift = anim
            .iter()
            .zip(&targets)
            .map(|(&(h, _, _, _), &(t, _))| {
                let flat = Vec3::new(t.x - h.x, 0.0, t.z - h.z).length_squared();
                (stretch * stretch - flat).max(0.0).sqrt() - (h.y - t.y)
            })
            .fold(f32::INFINITY, f32::min);
        if lift.is_finite() {
            local[root].0.y += lift;
            cache.fill(None);
        }
        for (leg, (&(_, knee0, _, _), &(target, foot_rot))) in legs.iter().zip(anim.iter().zip(&targets)) {
            // The knee in the plane of the hip, the target and the animated knee; the foot in
            // its animated orientation, turned with the path.
            self.solve_leg(local, cache, leg, target, knee0, foot_rot);
        }
    }

    /// Each leg's hip, knee and ankle and its foot's global orientation in the pose `local`
    /// (`cache` its globals).
    pub(super) fn leg_joints(&self, local: &[(Vec3, Quat, Vec3)], cache: &mut [Option<Mat4>], legs: [Leg; 2]) -> [(Vec3, Vec3, Vec3, Quat); 2] {
        let pos = |m: Mat4| m.w_axis.truncate();
        let nodes = &self.nodes;
        legs.map(|l| {
            let f = global_of(nodes, local, cache, l.foot);
            (pos(global_of(nodes, local, cache, l.thigh)), pos(global_of(nodes, local, cache, l.shank)), pos(f), Quat::from_mat4(&f).normalize())
        })
    }

    /// Re-solves one leg of the pose `local` as a two-bone chain (hip -> knee -> ankle): the
    /// ankle onto `target` (or as near as the leg reaches), the knee bent in the plane of the
    /// hip, the target and `knee_toward`, then the foot turned to the global `foot_rot`.
    pub(super) fn solve_leg(
        &self,
        local: &mut [(Vec3, Quat, Vec3)],
        cache: &mut [Option<Mat4>],
        leg: &Leg,
        target: Vec3,
        knee_toward: Vec3,
        foot_rot: Quat,
    ) {
        let pos = |m: Mat4| m.w_axis.truncate();
        let nodes = &self.nodes;
        let (hip_m, knee_m, ankle_m) =
            (global_of(nodes, local, cache, leg.thigh), global_of(nodes, local, cache, leg.shank), global_of(nodes, local, cache, leg.foot));
        let (hip, knee, ankle) = (pos(hip_m), pos(knee_m), pos(ankle_m));
        let (l1, l2) = ((knee - hip).length(), (ankle - knee).length());
        let to = target - hip;
        let shortest = (l1 - l2).abs() + 1e-4;
        let d = to.length().clamp(shortest, ((l1 + l2) * 0.9999).max(shortest));
        let dir = to.normalize_or_zero();
        let pole = knee_toward - hip - dir * (knee_toward - hip).dot(dir);
        let side = pole.normalize_or_zero();
        let cos_a = ((l1 * l1 + d * d - l2 * l2) / (2.0 * l1 * d)).clamp(-1.0, 1.0);
        let new_knee = hip + l1 * (cos_a * dir + (1.0 - cos_a * cos_a).sqrt() * side);
        // Thigh: turn the hip->knee direction onto the new one.
        let turn1 = arc((knee - hip).normalize_or_zero(), (new_knee - hip).normalize_or_zero());
        self.set_global_rotation(local, cache, leg.thigh, turn1 * Quat::from_mat4(&hip_m).normalize());
        // Shank: with the thigh turned, turn the knee->ankle direction onto the target.
        let knee_m = global_of(nodes, local, cache, leg.shank);
        let (knee_now, ankle_now) = (pos(knee_m), pos(global_of(nodes, local, cache, leg.foot)));
        let turn2 = arc((ankle_now - knee_now).normalize_or_zero(), (target - knee_now).normalize_or_zero());
        self.set_global_rotation(local, cache, leg.shank, turn2 * Quat::from_mat4(&knee_m).normalize());
        self.set_global_rotation(local, cache, leg.foot, foot_rot);
    }

    /// Sets node `i`'s local rotation so that its global rotation is `rotation` (its parent's
    /// global transform as `local` has it; scales are 1 in a walking skeleton); `cache` holds
    /// the globals of `local` before and after.
    pub(super) fn set_global_rotation(&self, local: &mut [(Vec3, Quat, Vec3)], cache: &mut [Option<Mat4>], i: usize, rotation: Quat) {
        let parent = match self.nodes[i].parent {
            Some(p) => Quat::from_mat4(&global_of(&self.nodes, local, cache, p)).normalize(),
            None => Quat::IDENTITY,
        };
        local[i].1 = (parent.inverse() * rotation).normalize();
        cache.fill(None);
    }
}

pub(super) fn global_rest(nodes: &[NodeRest], i: usize) -> Mat4 {
    let n = &nodes[i];
    let m = Mat4::from_scale_rotation_translation(n.scale, n.rotation, n.translation);
    match n.parent {
        Some(p) => global_rest(nodes, p) * m,
        None => m,
    }
}

pub(super) fn global_of(nodes: &[NodeRest], local: &[(Vec3, Quat, Vec3)], cache: &mut [Option<Mat4>], i: usize) -> Mat4 {
    if let Some(m) = cache[i] {
        return m;
    }
    let (t, r, s) = local[i];
    let m = Mat4::from_scale_rotation_translation(s, r, t);
    let g = match nodes[i].parent {
        Some(p) => global_of(nodes, local, cache, p) * m,
        None => m,
    };
    cache[i] = Some(g);
    g
}

/// 0 below 0, 1 above 1, smooth (zero slope at both ends) in between.
fn smoothstep(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// Samples a channel at time `t` (clamped to its key range), glTF interpolation rules.
pub(super) fn sample(ch: &Channel, t: f32) -> Vec4 {
    let times = &ch.times;
    let n = times.len();
    let value = |k: usize| if ch.interp == Interp::CubicSpline { ch.values[3 * k + 1] } else { ch.values[k] };
    if n == 1 || t <= times[0] {
        return value(0);
    }
    if t >= times[n - 1] {
        return value(n - 1);
    }
    let k = times.partition_point(|&x| x <= t) - 1;
    let (t0, t1) = (times[k], times[k + 1]);
    let dt = t1 - t0;
    let u = (t - t0) / dt;
    match ch.interp {
        Interp::Step => value(k),
        Interp::Linear => {
            if ch.property == Property::Rotation {
                let a = Quat::from_vec4(value(k)).normalize();
                let b = Quat::from_vec4(value(k + 1)).normalize();
                Vec4::from(a.slerp(b, u))
            } else {
                value(k).lerp(value(k + 1), u)
            }
        }
        Interp::CubicSpline => {
            let p0 = ch.values[3 * k + 1];
            let m0 = ch.values[3 * k + 2] * dt;
            let p1 = ch.values[3 * (k + 1) + 1];
            let m1 = ch.values[3 * (k + 1)] * dt;
            let (u2, u3) = (u * u, u * u * u);
            let v = (2.0 * u3 - 3.0 * u2 + 1.0) * p0
                + (u3 - 2.0 * u2 + u) * m0
                + (-2.0 * u3 + 3.0 * u2) * p1
                + (u3 - u2) * m1;
            if ch.property == Property::Rotation {
                Vec4::from(Quat::from_vec4(v).normalize())
            } else {
                v
            }
        }
    }
}

/// Hip (leg) height as a fraction of stature (Winter, Biomechanics and Motor Control of Human
/// Movement, anthropometric segment lengths: greater trochanter at 0.530 H).
pub const LEG_LENGTH_FRACTION: f64 = 0.530;

impl HumanModel {
    /// The stride the gait phase advances by (distance per cycle): the model's recorded stride
    /// (feet planted at every speed), else Alexander's for its height at `speed_mps`.
    pub fn gait_stride_m(&self, speed_mps: f64) -> f64 {
        match self.stride_length_m {
            Some(s) => s as f64,
            None => stride_length_m(self.height_m as f64, speed_mps.max(0.1)),
        }
    }
}

/// The rotation taking unit `from` onto unit `to`; none where either is zero (a degenerate
/// chain keeps its pose rather than turning into NaN). Small turns are kept:
/// `Quat::from_rotation_arc` returns the identity below ~7e-4 rad (cos within 2 ulp of 1),
/// which froze the re-solved legs for a few frames around each instant where the stride
/// scaling moves a foot by less than a few tenths of a millimetre (the stance foot then slid
/// at (k - 1) / k of the walking speed).
fn arc(from: Vec3, to: Vec3) -> Quat {
    if from == Vec3::ZERO || to == Vec3::ZERO {
        return Quat::IDENTITY;
    }
    // (from x to, 1 + from . to), normalised: the rotation by the angle between them about
    // their normal, exact down to zero; only near-opposite vectors need the general form.
    let w = 1.0 + from.dot(to);
    if w < 1e-4 {
        return Quat::from_rotation_arc(from, to);
    }
    let c = from.cross(to);
    Quat::from_xyzw(c.x, c.y, c.z, w).normalize()
}

/// Whether a node name names a leg bone (the standing pose keeps those at rest): `leg`,
/// `thigh`, `shin`, `calf`, `knee`, `foot`, `ankle`, `toe`, any case.
pub(super) fn is_leg_name(name: &str) -> bool {
    let n = name.to_ascii_lowercase();
    ["leg", "thigh", "shin", "calf", "knee", "foot", "ankle", "toe"].iter().any(|k| n.contains(k))
}

/// Whether a node name names an arm bone (its swing scales with the person's arm swing):
/// `arm`, `shoulder`, `clavicle`, `elbow`, `hand`, `wrist`, any case (not `armature`, the
/// usual name of an exported skeleton's root).
pub(super) fn is_arm_name(name: &str) -> bool {
    let n = name.to_ascii_lowercase().replace("armature", "");
    ["arm", "shoulder", "clavicle", "elbow", "hand", "wrist"].iter().any(|k| n.contains(k))
}

/// Stride length (heel strike to heel strike of the same foot) of a person of `height_m`
/// walking at `speed_mps`, from Alexander's relation between relative stride length and the
/// Froude number (R. McN. Alexander, "Estimates of speeds of dinosaurs", Nature 261:129-130,
/// 1976): `stride / h = 2.3 * (v^2 / (g h))^0.3`, with h the leg length. At 1.3 m/s a 1.70 m
/// person strides 1.26 m, a 1.20 m child 0.99 m. Speeds near 0 give a floor of 0.2 h.
pub fn stride_length_m(height_m: f64, speed_mps: f64) -> f64 {
    let h = LEG_LENGTH_FRACTION * height_m;
    let froude = speed_mps * speed_mps / (9.81 * h);
    (2.3 * h * froude.powf(0.3)).max(0.2 * h)
}
