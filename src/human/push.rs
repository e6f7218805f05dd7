//! Pushing: a person pushing a stroller or a trolley walks with the arms held forward, the
//! upper arms turned forward from the standing pose and the elbows bent, the hands on the
//! handle ahead of the body at about the waist; the arms do not swing. The handle is where the
//! hands come to in the standing pose ([`HumanModel::push_handle`]), so the pushed thing is
//! placed for each model.

use super::gait::global_of;
use super::*;

/// The upper arms' turn forward from the standing pose, and the forearms' beyond it (rad): the
/// elbows bent, the hands 0.26-0.35 m ahead of the body at 0.6 of the height (1.02 m for the
/// bundled 1.7 m body), where a stroller's handle is.
const UPPER_ARM_RAD: f32 = 0.3;
const FOREARM_RAD: f32 = 0.5;

/// The least height of a model that pushes, m (children do not).
pub const PUSH_MIN_HEIGHT_M: f32 = 1.5;

/// Where a model's hands hold a handle it pushes, body frame (x forward, z up, the origin the
/// floor point under the hips), m.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PushHandle {
    /// How far ahead of the origin the hands are.
    pub forward_m: f32,
    /// How high above the floor.
    pub height_m: f32,
    /// Half the distance between the hands.
    pub half_width_m: f32,
}

impl HumanModel {
    /// Whether the model can push ([`GaitStyle::pushing`]): an adult ([`PUSH_MIN_HEIGHT_M`] or
    /// taller) whose skeleton names its legs and arms like the bundled people's, with nothing
    /// in the hands (a bag hangs from a hand).
    pub fn can_push(&self) -> bool {
        let in_hand = [super::carry::Carried::Bag, super::carry::Carried::Bags].iter().any(|c| self.name.ends_with(&format!("+{}", c.name())));
        self.legs.is_some() && self.arms.is_some() && !in_hand && self.nominal_height_m() >= PUSH_MIN_HEIGHT_M
    }

    /// Where the hands are in the standing pose pushing (the wrists, their mean ahead and
    /// above the floor, half their distance apart); None where the model cannot push.
    pub fn push_handle(&self) -> Option<PushHandle> {
        let arms = self.arms.filter(|_| self.can_push())?;
        let mut g = Vec::new();
        self.joint_globals(0.0, GaitStyle { walking: 0.0, pushing: true, ..GaitStyle::WALK }, &mut g);
        let at = |node: usize| self.joint_nodes.iter().position(|&n| n == node).map(|j| g[j].w_axis.truncate());
        let (l, r) = (at(arms[0][2])?, at(arms[1][2])?);
        let mid = 0.5 * (l + r);
        Some(PushHandle { forward_m: mid.z, height_m: mid.y, half_width_m: 0.5 * (l.x - r.x).abs() })
    }

    /// Holds the arms of the pose `local` forward to the handle (where the skeleton names them
    /// like the bundled people's): each upper arm turned [`UPPER_ARM_RAD`] forward about the
    /// body's left-right axis, its forearm [`FOREARM_RAD`] beyond. `cache` holds the globals
    /// of `local` before and after.
    pub(super) fn push_arms(&self, local: &mut [(Vec3, Quat, Vec3)], cache: &mut [Option<Mat4>]) {
        for [upper, lower, _] in self.arms.into_iter().flatten() {
            for (node, rad) in [(upper, UPPER_ARM_RAD), (lower, FOREARM_RAD)] {
                let g = Quat::from_mat4(&global_of(&self.nodes, local, cache, node)).normalize();
                self.set_global_rotation(local, cache, node, Quat::from_rotation_x(-rad) * g);
            }
        }
    }
}

#[cfg(test)]
mod tests;
