//! A sequence's built-in world (`scene.background = "street"` / `"indoor"`): what it is built
//! for, making it the environment the frames are drawn in, and the `/class` of each beam.

use super::Generator;
use crate::output::semantickitti::{BACKGROUND, MOVING_PERSON, MOVING_SPEED_MPS, PERSON};
use crate::output::{FrameOutput, NOT_SCORED};
use crate::scene::sequence::SequencePlan;
use crate::scene::world::WorldParams;
use std::sync::Arc;

impl Generator {
    /// Triangles of the environment the frames are drawn in now (0 under a recording).
    pub fn background_triangles(&self) -> usize {
        self.inputs.environment.as_ref().map_or(0, |e| e.triangle_count())
    }

    /// What a built-in world is built for: the sequence's length, the sensor's height and
    /// speed, the people's clearance.
    pub(super) fn world_params(&self) -> WorldParams {
        let sc = &self.cfg.scene;
        WorldParams {
            duration_s: self.cfg.frames.saturating_sub(1) as f64 / self.inputs.sensor.rate_hz,
            sensor_height_m: sc.sensor_height_m,
            sensor_speed_mps: sc.sensor_speed_mps,
            clearance_m: self.cfg.humans.clearance_m,
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
        let moving: Vec<bool> = out.humans.iter().map(|h| (h.velocity_mps[0] as f64).hypot(h.velocity_mps[1] as f64) > MOVING_SPEED_MPS).collect();
        out.class.clear();
        out.class.extend((0..n).map(|b| {
            let k = out.instance[b] as usize;
            if out.range[b] <= 0.0 || out.label[b] == NOT_SCORED {
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
}
