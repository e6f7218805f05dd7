//! People who push (`humans.pushing`): who is drawn to, and what they push kept clear while
//! their walks are planned, so the thing the world then adds to them
//! ([`crate::scene::world::World::add_pushed`]) fits all through the sequence.

use super::HumanPlan;
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

/// Whether, at `t_s`, somebody whose footprint is at `p` and who pushes `own` (its footprint
/// then) keeps clear of what `others` push (the world's rule: a person's footprint 0.35 m from
/// a thing's, things apart by their circles), and `own` of the world (its obstacles and the
/// sensor's vehicle: [`World::pushed_clear`]), of the sensor's carrier `carrier` and of the
/// others; each with [`PLANNED_ROOM_M`] to spare, as the world checks between the frames too.
pub(super) fn clear(world: Option<&World>, others: &[HumanPlan], carrier: Option<DVec2>, p: DVec2, own: Option<Footprint>, t_s: f64) -> bool {
    let Some(world) = world else { return true };
    let (room, gap) = (PLANNED_ROOM_M, PERSON_RADIUS_M + PLANNED_ROOM_M);
    let mine = |f: &Footprint| {
        world.pushed_clear(f, t_s, room) && carrier.is_none_or(|q| f.gap(q) >= gap) && others.iter().all(|o| f.gap(o.footprint_m(t_s)) >= gap)
    };
    own.as_ref().is_none_or(mine)
        && others.iter().filter_map(|o| o.pushed_at(t_s)).all(|f| f.gap(p) >= gap && own.is_none_or(|g| g.centre.distance(f.centre) > g.half.length() + f.half.length() + room))
}
