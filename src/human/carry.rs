//! Things people carry: real people in a street or a market carry backpacks and bags, which
//! widen and deepen what a sensor sees of them and hang at their hands beside their legs.
//! `humans.carrying` gives that share of the people one of [`CARRIED`] (a backpack, a bag in
//! the right hand, bags in both hands): each model gets a variant per kind, the thing added
//! to every level of detail as a closed box skinned to one place of the body, so it moves
//! with that place (the back, a hand) as the person walks, turns and stands, and is the
//! person's: its beams are human, of the person's instance, with the velocity of the point
//! hit. The boxes are placed in the standing pose (arms down beside the body) and carried
//! into the bind pose through the inverse of the skinning matrix of the body's vertex nearest
//! to where each is held, so a model's bind pose (T, A or other) does not matter.

use super::{GaitStyle, HumanModel, Lod};
use crate::geometry::Adjacency;
use glam::{Mat4, Vec3};
use rayon::prelude::*;
use std::sync::Arc;

/// What a person can carry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Carried {
    /// On the back, between the waist and the shoulders.
    Backpack,
    /// Hanging from the right hand.
    Bag,
    /// Hanging from each hand.
    Bags,
}

/// The kinds, in the order of the models' carrying variants.
pub const CARRIED: [Carried; 3] = [Carried::Backpack, Carried::Bag, Carried::Bags];

impl Carried {
    pub fn name(self) -> &'static str {
        match self {
            Carried::Backpack => "backpack",
            Carried::Bag => "bag",
            Carried::Bags => "bags",
        }
    }
}

/// Sizes for a person 1.7 m tall (scaled with the height): width across, height, depth front
/// to back, metres.
const BACKPACK_M: [f32; 3] = [0.30, 0.42, 0.17];
const BAG_M: [f32; 3] = [0.12, 0.30, 0.34];
/// The backpack's top as a share of the height (the shoulders are at about 0.82).
const BACKPACK_TOP: f32 = 0.79;
/// Gap between the body and the thing, and between the fingertips and a bag's top, metres.
const GAP_M: f32 = 0.01;
const HANDLE_M: f32 = 0.03;

/// The models people are drawn from: `models` as they are where `carrying` is 0; else them,
/// then for each of [`CARRIED`] in its order each of them carrying it (a person's drawn by
/// `crate::scene::pick_model`).
pub fn equip(models: Vec<HumanModel>, carrying: f64) -> Vec<HumanModel> {
    if carrying <= 0.0 {
        return models;
    }
    // Each model's variants on its own thread (its standing pose found once for all kinds);
    // the order is the kinds' and then the models'.
    let variants: Vec<Vec<HumanModel>> = models.par_iter().map(HumanModel::carrying_all).collect();
    let mut per_kind: Vec<Vec<HumanModel>> = CARRIED.iter().map(|_| Vec::with_capacity(models.len())).collect();
    for each in variants {
        for (kind, v) in per_kind.iter_mut().zip(each) {
            kind.push(v);
        }
    }
    let mut out = models;
    out.extend(per_kind.into_iter().flatten());
    out
}

/// A closed box in the standing pose (model frame): its lower and upper corners.
struct Held {
    lo: Vec3,
    hi: Vec3,
    /// Where it is held: the body's vertex nearest to it gives its skinning.
    at: Vec3,
}

/// A model standing, as the things it carries are placed: its joint matrices, LOD 0 skinned,
/// and how far the walk swings each vertex ([`swings`]).
struct Standing {
    joints: Vec<Mat4>,
    body: Vec<Vec3>,
    swing: Vec<f32>,
}

impl HumanModel {
    /// This model carrying `kind`, named `NAME+KIND`.
    pub fn carrying(&self, kind: Carried) -> HumanModel {
        self.carrying_from(&self.standing(), kind)
    }

    /// This model carrying each of [`CARRIED`], in its order.
    pub fn carrying_all(&self) -> Vec<HumanModel> {
        let standing = self.standing();
        CARRIED.iter().map(|&kind| self.carrying_from(&standing, kind)).collect()
    }

    fn standing(&self) -> Standing {
        let mut joints = Vec::new();
        let stand = GaitStyle { walking: 0.0, ..GaitStyle::WALK };
        self.joint_matrices_styled(0.0, stand, &mut joints);
        let mut body = Vec::new();
        self.skin_into(0, &joints, &Mat4::IDENTITY, &mut body);
        let body: Vec<Vec3> = body.into_iter().map(Vec3::from).collect();
        let swing = swings(self, &body);
        Standing { joints, body, swing }
    }

    fn carrying_from(&self, standing: &Standing, kind: Carried) -> HumanModel {
        let Standing { joints, body, swing } = standing;
        let h = self.height_m.max(1e-3);
        let s = h / 1.7;
        let held = match kind {
            Carried::Backpack => vec![backpack(body, h, s)],
            Carried::Bag => vec![bag(body, swing, h, s, -1.0)],
            Carried::Bags => vec![bag(body, swing, h, s, -1.0), bag(body, swing, h, s, 1.0)],
        };
        let mut m = self.clone();
        m.name = format!("{}+{}", self.name, kind.name());
        let lod0 = &self.lods[0];
        for thing in held {
            // The skinning of the body's vertex nearest to where the thing is held, and the
            // matrix it blends in the standing pose (the identity without a skin).
            let near = (0..body.len()).min_by(|&a, &b| body[a].distance_squared(thing.at).total_cmp(&body[b].distance_squared(thing.at))).unwrap_or(0);
            let (j, w) = (lod0.joints[near], lod0.weights[near]);
            let blend = if joints.is_empty() { Mat4::IDENTITY } else { (0..4).fold(Mat4::ZERO, |acc, k| acc + joints[j[k] as usize] * w[k]) };
            if !(blend.determinant().abs() > 1e-9) {
                // A vertex bound to nothing (weights summing to 0): nowhere to hold it.
                continue;
            }
            let to_bind = blend.inverse();
            let corners: Vec<Vec3> = (0..8).map(|k| to_bind.transform_point3(Vec3::select(glam::BVec3::new(k & 1 != 0, k & 2 != 0, k & 4 != 0), thing.hi, thing.lo))).collect();
            for lod in &mut m.lods {
                add_box(lod, &corners, j, w);
            }
        }
        m
    }
}

/// A backpack on the back of `body` (standing pose), `h` tall, sizes scaled by `s`.
fn backpack(body: &[Vec3], h: f32, s: f32) -> Held {
    let [w, tall, d] = BACKPACK_M.map(|v| v * s);
    let top = BACKPACK_TOP * h;
    // The back: the rearmost point of the torso (not the arms) over the pack's height.
    let back = body.iter().filter(|p| p.y >= top - tall && p.y <= top && p.x.abs() <= w / 2.0).map(|p| p.z).fold(f32::INFINITY, f32::min);
    let back = if back.is_finite() { back } else { -0.1 * s };
    let (z1, z0) = (back - GAP_M, back - GAP_M - d);
    Held { lo: Vec3::new(-w / 2.0, top - tall, z0), hi: Vec3::new(w / 2.0, top, z1), at: Vec3::new(0.0, top - tall / 2.0, back) }
}

/// A bag hanging from the hand on side `side` (+1 the person's left, model +x) of `body`;
/// `swing` per vertex, how far the walk moves it against the body's mean (empty without a
/// walk).
fn bag(body: &[Vec3], swing: &[f32], h: f32, s: f32, side: f32) -> Held {
    let [t, tall, w] = BAG_M.map(|v| v * s);
    // The hand: on that side, between 0.3 and 0.7 of the height, the point the walk swings
    // furthest (the arms swing, the hands most; the feet are lower); without a walk the
    // outermost point there. The bag hangs below the fingertips: the lowest point within
    // 0.12 m of it.
    let band = |p: &Vec3| p.y >= 0.3 * h && p.y <= 0.7 * h && p.x * side > 0.0;
    let score = |i: usize| if swing.is_empty() { body[i].x * side } else { swing[i] };
    let hand = (0..body.len()).filter(|&i| band(&body[i])).max_by(|&a, &b| score(a).total_cmp(&score(b))).map(|i| body[i]).unwrap_or(Vec3::new(0.25 * s * side, 0.45 * h, 0.0));
    let tip = body.iter().copied().filter(|p| p.distance(hand) <= 0.12 * s).fold(hand, |a, b| if b.y < a.y { b } else { a });
    let top = tip.y - HANDLE_M;
    // Beside the leg: outward of every point of the body over the bag's height and depth.
    let leg = body.iter().filter(|p| p.y >= top - tall && p.y <= top && (p.z - tip.z).abs() <= w / 2.0).map(|p| p.x * side).fold(f32::NEG_INFINITY, f32::max);
    let x = side * (tip.x * side).max(leg + GAP_M + t / 2.0);
    Held { lo: Vec3::new(x - t / 2.0, top - tall, tip.z - w / 2.0), hi: Vec3::new(x + t / 2.0, top, tip.z + w / 2.0), at: tip }
}

/// Per vertex of `body` (LOD 0 standing), how far the walk of `m` moves it between two
/// phases half a cycle apart (a quarter past each heel strike), the mean of all vertices'
/// moves taken off; empty where `m` has no walk.
fn swings(m: &HumanModel, body: &[Vec3]) -> Vec<f32> {
    if m.cycle_s <= 0.0 || m.channels.is_empty() {
        return Vec::new();
    }
    let at = |phase: f32| {
        let mut joints = Vec::new();
        m.joint_matrices(phase, &mut joints);
        let mut out = Vec::new();
        m.skin_into(0, &joints, &Mat4::IDENTITY, &mut out);
        out.into_iter().map(Vec3::from).collect::<Vec<_>>()
    };
    let (a, b) = (at(0.25), at(0.75));
    let moved: Vec<Vec3> = a.iter().zip(&b).map(|(p, q)| *p - *q).collect();
    let mean = moved.iter().copied().sum::<Vec3>() / body.len().max(1) as f32;
    moved.iter().map(|d| (*d - mean).length()).collect()
}

/// Appends to `lod` a closed box (12 triangles wound outward) of `corners` (corner k at bit 0
/// = x high, bit 1 = y high, bit 2 = z high, bind pose), skinned with joints `j`, weights `w`.
fn add_box(lod: &mut Lod, corners: &[Vec3], j: [u16; 4], w: [f32; 4]) {
    let base = lod.positions.len() as u32;
    lod.positions.extend_from_slice(corners);
    lod.joints.extend(std::iter::repeat_n(j, 8));
    lod.weights.extend(std::iter::repeat_n(w, 8));
    // Faces as quads (a, b, c, d) counter-clockwise seen from outside.
    const QUADS: [[u32; 4]; 6] = [[0, 4, 6, 2], [1, 3, 7, 5], [0, 1, 5, 4], [2, 6, 7, 3], [0, 2, 3, 1], [4, 5, 7, 6]];
    let local: Vec<u32> = QUADS.iter().flat_map(|&[a, b, c, d]| [a, b, c, a, c, d]).collect();
    lod.indices.extend(local.iter().map(|k| base + k));
    // The box shares no vertex with the body: its one-rings go after the body's.
    lod.adjacency = Arc::new(lod.adjacency.with_disjoint(&Adjacency::build(&local)));
}

#[cfg(test)]
mod tests;
