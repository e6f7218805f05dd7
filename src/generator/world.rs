//! A sequence's built-in world (`scene.background = "street"` / `"indoor"`): what it is built
//! for, making it the environment the frames are drawn in, and the `/class` of each beam.

use super::Generator;
use crate::output::semantickitti::{BACKGROUND, MOVING_PERSON, MOVING_SPEED_MPS, PERSON};
use crate::output::{FrameOutput, NOT_SCORED};
use crate::scene::sequence::SequencePlan;
use crate::scene::world::things::class::{BICYCLIST, CAR, OTHER_VEHICLE};
use crate::scene::world::{WorldParams, NO_MOVER};
use std::sync::Arc;

/// SemanticKITTI's moving car, moving bicyclist and moving other-vehicle.
const MOVING_CAR: u16 = 252;
const MOVING_BICYCLIST: u16 = 253;
const MOVING_OTHER_VEHICLE: u16 = 259;

impl Generator {
    /// Triangles of the environment the frames are drawn in now (0 under a recording).
    pub fn background_triangles(&self) -> usize {
        self.inputs.environment.as_ref().map_or(0, |e| e.triangle_count())
    }

    /// What a built-in world is built for: the sequence's length, the sensor's height and
    /// speed, the people's clearance, the street's shares of markets and side streets.
    pub(super) fn world_params(&self) -> WorldParams {
        let sc = &self.cfg.scene;
        WorldParams {
            duration_s: self.cfg.frames.saturating_sub(1) as f64 / self.inputs.sensor.rate_hz,
            sensor_height_m: sc.sensor_height_m,
            sensor_speed_mps: sc.sensor_speed_mps,
            clearance_m: self.cfg.humans.clearance_m,
            markets: sc.markets,
            side_streets: sc.side_streets,
        }
    }

    /// Makes `plan`'s built-in world the environment the next frames are drawn in (kept while
    /// the frames are of the same world).
    pub(super) fn enter_world(&mut self, plan: &SequencePlan) {
        let Some(w) = &plan.world else { return };
        if self.world.as_ref().is_some_and(|cur| Arc::ptr_eq(cur, w) || **cur == **w) {
            return;
        }
        self.inputs.environment = Some(w.env.clone());
        self.inputs.env_meshes = w.draws.clone();
        self.world = Some(w.clone());
    }

    /// `/class` of a composited frame: a person's beams 30, or 254 while the person walks
    /// faster than [`MOVING_SPEED_MPS`]; a background beam the class of the environment mesh
    /// its hit triangle belongs to (50 where the background does not say); 0 without a return
    /// or where not scored.
    pub(super) fn classes(&self, out: &mut FrameOutput) {
        let n = out.range.len();
        let (bg, tri, meshes) = (&self.posed.background, &self.scratch.bg_hits.triangle, &self.inputs.env_meshes);
        let fast = |v: [f64; 3]| v[0].hypot(v[1]) > MOVING_SPEED_MPS;
        let moving: Vec<bool> = out.humans.iter().map(|h| fast(h.velocity_mps.map(f64::from))).collect();
        let people = out.humans.len();
        let movers_moving: Vec<bool> = self.posed.mover_velocity.iter().map(|v| fast(v.to_array())).collect();
        out.class.clear();
        out.class.extend((0..n).map(|b| {
            let k = out.instance[b] as usize;
            if out.range[b] <= 0.0 {
                0
            } else if k > people {
                // A mover: its mesh's class, a car, a rider or a robot or cart moving when it
                // goes faster than a person walking.
                let c = tri.get(b).map_or(0, |&t| meshes.get(bg.mesh_index_of_triangle(t)).map_or(0, |m| m.class));
                match (c, movers_moving.get(k - people - 1).copied().unwrap_or(false)) {
                    (CAR, true) => MOVING_CAR,
                    (BICYCLIST, true) => MOVING_BICYCLIST,
                    (OTHER_VEHICLE, true) => MOVING_OTHER_VEHICLE,
                    (c, _) => c,
                }
            } else if out.label[b] == NOT_SCORED {
                0
            } else if k > 0 {
                if moving.get(k - 1).copied().unwrap_or(false) { MOVING_PERSON as u16 } else { PERSON as u16 }
            } else {
                match tri.get(b) {
                    Some(&t) if self.posed.recorded.is_none() && t != crate::backend::NO_TRIANGLE && t < bg.triangle_count() => {
                        match meshes.get(bg.mesh_index_of_triangle(t)).map_or(0, |m| m.class) {
                            0 => BACKGROUND as u16,
                            c => c,
                        }
                    }
                    _ => BACKGROUND as u16,
                }
            }
        }));
    }

    /// The beams whose return is a mover's (the background's return, on a mover's mesh): the
    /// mover's instance, after the people's (people + 1 + its index); its world velocity added
    /// to the background's velocity (`R^T V`, in the sensor frame of the beam's column); and a
    /// rider's beams not scored (`/label` 255), as SemanticKITTI's riders are neither a hit
    /// nor a false alarm for a pedestrian network. `/clean/instance` and `/clean/label` the
    /// same on the clean returns.
    pub(super) fn movers(&self, people: usize, out: &mut FrameOutput) {
        let Some(w) = self.world.as_ref().filter(|w| !w.movers.is_empty()) else { return };
        let (bg, tri, meshes) = (&self.posed.background, &self.scratch.bg_hits.triangle, &self.inputs.env_meshes);
        let p = &self.posed;
        let columns = self.inputs.sensor.columns;
        let mover_of = |b: usize| -> Option<(usize, u16)> {
            let t = *tri.get(b)?;
            if t == crate::backend::NO_TRIANGLE || t >= bg.triangle_count() {
                return None;
            }
            let d = bg.mesh_index_of_triangle(t);
            let k = *w.mover_of_draw.get(d)?;
            (k != NO_MOVER).then(|| (k as usize, meshes.get(d).map_or(0, |m| m.class)))
        };
        let velocity = out.velocity.len() == out.range.len();
        for b in 0..out.range.len() {
            if out.range[b] <= 0.0 || out.instance[b] != 0 || out.label[b] != 0 {
                continue;
            }
            let Some((k, class)) = mover_of(b) else { continue };
            out.instance[b] = (people + 1 + k) as u16;
            if velocity {
                let m = &p.column_motion[if p.column_motion.len() == 1 { 0 } else { b % columns }];
                let v = m.rot.transpose() * p.mover_velocity[k];
                for (o, dv) in out.velocity[b].iter_mut().zip(v.to_array()) {
                    *o += dv as f32;
                }
            }
            if class == BICYCLIST {
                out.label[b] = NOT_SCORED;
            }
        }
        if out.clean_range.len() == out.range.len() {
            for b in 0..out.range.len() {
                if out.clean_range[b] <= 0.0 || out.clean_instance[b] != 0 || out.clean_label[b] != 0 {
                    continue;
                }
                let Some((k, class)) = mover_of(b) else { continue };
                out.clean_instance[b] = (people + 1 + k) as u16;
                if class == BICYCLIST {
                    out.clean_label[b] = NOT_SCORED;
                }
            }
        }
    }
}
