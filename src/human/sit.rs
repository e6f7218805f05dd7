//! Seated: the standing pose lowered onto a seat, the thighs forward and about level, the
//! shanks down to the floor, the hands forward onto the thighs.

use super::gait::global_of;
use super::*;

/// How far the hip joints sit above the seat, as a share of their standing height: the flesh
/// under them (0.10 m for an adult whose hips stand 0.9 m high).
pub const HIP_OVER_SEAT: f32 = 0.11;

/// How far forward of the hips the ankles are put, as a share of the thigh's length (a little
/// short of the knee: the shanks lean back a little, as people sit).
const FEET_FORWARD: f32 = 0.9;

/// The ankles are drawn back no nearer the hips than this share of the thigh (the shins about
/// 45 degrees back): a room shorter than that leaves the toes past it rather than fold the
/// thighs down through the seat's front.
const FEET_BACK_MOST: f32 = 0.4;

/// The upper arms' turn forward from the standing pose, and the forearms' beyond it (rad): the
/// hands come to rest on the thighs.
const UPPER_ARM_RAD: f32 = 0.2;
const FOREARM_RAD: f32 = 0.45;

impl HumanModel {
    /// Whether the model can sit ([`GaitStyle::seat_m`]): its skeleton names its legs and arms
    /// like the bundled people's (hanging arms would reach into the seat), and it carries
    /// nothing on its back (a backpack would go through a seat's back).
    pub fn can_sit(&self) -> bool {
        self.legs.is_some() && self.arms.is_some() && !self.name.ends_with(&format!("+{}", super::carry::Carried::Backpack.name()))
    }

    /// Seats the pose `local` (the standing pose) on a seat `seat_m` above the floor: the
    /// pelvis lowered so that the hip joints are [`HIP_OVER_SEAT`] of their standing height above
    /// the seat, each leg re-solved (two-bone IK, the knee forward) with its ankle
    /// [`FEET_FORWARD`] of the thigh ahead of the hip and hanging a shank's length below the
    /// level thigh's knee, or on the floor where that is lower; the feet flat as they stand;
    /// the ankles drawn back, though no nearer the hips than [`FEET_BACK_MOST`] of the thigh,
    /// where the toes would reach more than `feet_room_m` ahead of the origin; the arms (where
    /// the skeleton names them like the bundled people's) turned forward so the hands rest on
    /// the thighs. `cache` holds the globals of `local` before and after.
    pub(super) fn seat(&self, local: &mut [(Vec3, Quat, Vec3)], cache: &mut [Option<Mat4>], seat_m: f32, feet_room_m: f32) {
        let Some((legs, root)) = self.legs else { return };
        let nodes = &self.nodes;
        let pos = |m: Mat4| m.w_axis.truncate();
        let stand = self.leg_joints(local, cache, legs);
        let hip_y = 0.5 * (stand[0].0.y + stand[1].0.y);
        local[root].0.y -= hip_y - (seat_m + HIP_OVER_SEAT * hip_y);
        cache.fill(None);
        for (leg, &(hip0, knee0, ankle0, foot_rot)) in legs.iter().zip(&stand) {
            let (l1, l2) = ((knee0 - hip0).length(), (ankle0 - knee0).length());
            let hip = pos(global_of(nodes, local, cache, leg.thigh));
            let knee = hip + Vec3::Z * l1;
            let ahead = (hip.z + FEET_FORWARD * l1).min(feet_room_m - leg.toes_m).max(hip.z + FEET_BACK_MOST * l1);
            let target = Vec3::new(ankle0.x, (knee.y - l2).max(ankle0.y), ahead);
            self.solve_leg(local, cache, leg, target, knee + Vec3::Y * l1, foot_rot);
        }
        for [upper, lower, _] in self.arms.into_iter().flatten() {
            for (node, rad) in [(upper, UPPER_ARM_RAD), (lower, FOREARM_RAD)] {
                let g = Quat::from_mat4(&global_of(nodes, local, cache, node)).normalize();
                self.set_global_rotation(local, cache, node, Quat::from_rotation_x(-rad) * g);
            }
        }
    }
}

#[cfg(test)]
mod tests;
