//! Seated people (`humans.sitting`): a free seat of the world's, sat on the whole sequence.

use super::{HumanPath, HumanPlan};
use crate::human::{HumanModel, MotionMode};
use crate::scene::world::Seat;
use crate::scene::Trajectory;
use glam::DVec2;
use rand::RngExt;

/// How far ahead of a seated person's hips the middle of its folded body is (hips to toes,
/// about 0.65 m), m: where others keep their distance from ([`HumanPlan::footprint_m`]).
pub const SEATED_REACH_M: f64 = 0.3;

impl HumanPlan {
    /// The floor point others keep `humans.min_separation_m` from at `t_s`: the position, or a
    /// seated person's [`SEATED_REACH_M`] ahead of it (the legs reach forward off the seat).
    pub fn footprint_m(&self, t_s: f64) -> DVec2 {
        let p = self.position_m(t_s).truncate();
        if self.seat_m > 0.0 {
            let h = self.trajectory.heading_rad(0.0);
            p + SEATED_REACH_M * DVec2::new(h.cos(), h.sin())
        } else {
            p
        }
    }
}

/// Seats lower than this above the floor are not sat on, m.
const LOWEST_SEAT_M: f64 = 0.2;

/// A plan for a person of `model` (`m`) seated on one of `seats` where `apart` holds (the
/// others and the sensor far enough at every frame): the seats tried in turn from one drawn
/// evenly, the person facing the seat's way on the floor `floor_z_m`, seated
/// ([`HumanPlan::seat_m`]) at the seat's top. None, and no number drawn, where there are no
/// seats or the model cannot sit; None where no seat is free.
pub(super) fn seat(
    rng: &mut impl rand::Rng,
    seats: &[Seat],
    (model, m): (usize, &HumanModel),
    floor_z_m: f64,
    motion: MotionMode,
    apart: impl Fn(&HumanPlan) -> bool,
) -> Option<HumanPlan> {
    if seats.is_empty() || !m.can_sit() {
        return None;
    }
    let first = crate::scene::even_index(rng.random::<f64>(), seats.len());
    let phase0 = rng.random::<f64>();
    (0..seats.len()).map(|i| seats[(first + i) % seats.len()]).filter(|s| s.top_z_m - floor_z_m >= LOWEST_SEAT_M).find_map(|s| {
        let plan = HumanPlan {
            model,
            trajectory: HumanPath::Arc(Trajectory::fixed(s.at, floor_z_m, s.facing_rad)),
            phase0,
            stride_m: m.gait_stride_m(0.0),
            motion,
            arm_swing: 1.0,
            stride_scale: 1.0,
            seat_m: s.top_z_m - floor_z_m,
            feet_room_m: s.feet_room_m,
            pushed: None,
        };
        apart(&plan).then_some(plan)
    })
}

#[cfg(test)]
mod tests;
