//! People who push (`humans.pushing`): who is drawn to, and what they push kept clear while
//! their walks are planned, so the thing the world then adds to them
//! ([`crate::scene::world::World::add_pushed`]) fits all through the sequence.

use super::{HumanPlan, SensorPath};
use crate::human::HumanModel;
use crate::scene::world::movers::{Footprint, PERSON_RADIUS_M};
use crate::scene::world::pushed::{Held, PLANNED_ROOM_M};
use crate::scene::world::World;
use glam::DVec2;
use rand::RngExt;

/// The fastest a pusher's planned walk turns, rad/s: on its curves (no corner rounded tighter
/// than its speed over this) and on the spot at its goals (the wait there long enough). Below
/// the 2 rad/s the world allows a pushed thing, so a path sampled between frames keeps to it.
pub(super) const TURN_RPS: f64 = 1.5;

/// Whether person `k` (of `model`) pushes something, drawn with probability `share` where
/// asked for (`share` > 0, a built-in `world`: nothing is drawn otherwise), and where it is
/// held if so; None for those not drawn and those who cannot push (a child, a bag in a hand).
pub(super) fn draw(rng: &mut impl rand::Rng, share: f64, world: Option<&World>, k: usize, model: &HumanModel) -> Option<Held> {
    let world = world.filter(|_| share > 0.0)?;
    let drawn = rng.random::<f64>() < share;
    let handle = model.push_handle().filter(|_| drawn)?;
    Some(world.pushed_spec(k, &handle).held(&handle))
}

impl HumanPlan {
    /// The footprint of what the person pushes at `t_s`, as the world holds it (ahead of the
    /// hips at the heading); None for one who pushes nothing.
    pub fn pushed_at(&self, t_s: f64) -> Option<Footprint> {
        let held = self.pushed?;
        let (p, h, _) = self.floor_pose(t_s);
        Some(held.footprint(p.truncate(), h))
    }
}

/// Whether, at `t_s`, somebody whose footprint is at `p` keeps clear of what `others` push:
/// 0.35 m from its footprint (the world's rule), and [`PLANNED_ROOM_M`] more, as it is
/// checked at the frames only and the world checks between them too.
pub(super) fn others_clear(world: Option<&World>, others: &[HumanPlan], p: DVec2, t_s: f64) -> bool {
    world.is_none() || others.iter().filter_map(|o| o.pushed_at(t_s)).all(|f| f.gap(p) >= PERSON_RADIUS_M + PLANNED_ROOM_M)
}

/// Whether a pushed thing's footprint `f` keeps clear at `t_s` of the world (its obstacles
/// and the sensor's vehicle: [`World::pushed_clear`]), of the sensor's carrier where it walks
/// among the people (on `sensor`'s path, in a world without a sensor vehicle: indoors), of
/// `others` and of what they push (things apart by their circles): the world's rules, checked
/// at the world's times ([`crate::scene::world::pushed::checked_times`]); with
/// [`PLANNED_ROOM_M`] to spare from the others, who were placed at the frames only.
pub(super) fn thing_clear(world: &World, others: &[HumanPlan], sensor: Option<&SensorPath>, f: &Footprint, t_s: f64) -> bool {
    let gap = PERSON_RADIUS_M + PLANNED_ROOM_M;
    let carrier = sensor.filter(|_| world.sensor.is_none()).map(|s| s.position(t_s).truncate());
    world.pushed_clear(f, t_s)
        && carrier.is_none_or(|q| f.gap(q) >= PERSON_RADIUS_M)
        && others.iter().all(|o| {
            f.gap(o.footprint_m(t_s)) >= gap && o.pushed_at(t_s).is_none_or(|g| g.apart(f, PLANNED_ROOM_M))
        })
}
