//! Groups (`humans.groups`): a person joining the one placed before.

use super::{HumanPath, HumanPlan};
use crate::human::HumanModel;
use crate::scene::Trajectory;
use glam::DVec2;
use rand::RngExt;

/// A companion for `leader` of model `model`: face to face 0.8-1.4 m away when the leader
/// stands, else side by side 0.75-0.95 m to its left or right, at its pace.
pub(super) fn companion(rng: &mut impl rand::Rng, leader: &HumanPlan, model: usize, m: &HumanModel) -> HumanPlan {
    let still = leader.trajectory.velocity(0.0).length() == 0.0 && !matches!(leader.trajectory, HumanPath::Paused(..));
    let trajectory = if still {
        let c = leader.trajectory.position(0.0);
        let a = rng.random::<f64>() * std::f64::consts::TAU;
        let d = 0.8 + 0.6 * rng.random::<f64>();
        let p = c.truncate() + d * DVec2::new(a.cos(), a.sin());
        // Facing the leader, give or take 20 degrees.
        let heading = a + std::f64::consts::PI + (rng.random::<f64>() - 0.5) * 0.7;
        HumanPath::Arc(Trajectory::fixed(p, c.z, heading))
    } else {
        let side = if rng.random::<f64>() < 0.5 { -1.0 } else { 1.0 };
        HumanPath::Beside(Box::new(leader.trajectory.clone()), side * (0.75 + 0.2 * rng.random::<f64>()))
    };
    HumanPlan {
        model,
        // The leader's walking speed, also when it starts the sequence stopped.
        stride_m: match &leader.trajectory {
            _ if still => m.gait_stride_m(0.0),
            HumanPath::Paused(p, _) => m.gait_stride_m(p.velocity(0.0).length()),
            t => m.gait_stride_m(t.velocity(0.0).length()),
        },
        trajectory,
        phase0: rng.random::<f64>(),
        motion: leader.motion,
        arm_swing: 1.0,
        stride_scale: 1.0,
        seat_m: 0.0,
        feet_room_m: f64::INFINITY,
        pushed: None,
    }
}
