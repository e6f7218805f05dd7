//! A sequence's built-in world (`scene.background = "street"` / `"indoor"`): what it is built
//! for, making it the environment the frames are drawn in, and the `/class` of each beam.

use super::Generator;
use crate::output::semantickitti::{BACKGROUND, MOVING_PERSON, MOVING_SPEED_MPS, PERSON};
use crate::output::{FrameOutput, NOT_SCORED};
use crate::scene::sequence::SequencePlan;
use crate::scene::world::things::class::{BICYCLIST, CAR, OTHER_VEHICLE};
use crate::scene::world::movers::PERSON_RADIUS_M;
use crate::scene::world::pushed::Walker;
use crate::scene::world::{World, WorldParams, NO_MOVER};
use glam::DVec2;
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

    /// Adds a planned sequence's movers to its world: the things its people push
    /// (`humans.pushing`: those the planner drew and kept clear; one whose thing does not fit
    /// between the frames pushes nothing), then the traffic, which keeps clear of the people
    /// and of the pushed things (each counted as people at its middle, its ends and its
    /// corners).
    pub(super) fn add_world_movers(&self, plan: &mut SequencePlan, w: &mut World) {
        let duration = plan.times_s.last().copied().unwrap_or(0.0);
        // Indoors the sensor's carrier walks where people do: the movers keep clear of it too.
        let carrier = w.sensor.is_none().then_some(&plan.sensor);
        let models = &self.inputs.models;
        let handles: Vec<_> = plan.humans.iter().map(|h| h.pushed.and_then(|_| models.get(h.model)?.push_handle())).collect();
        let humans = &plan.humans;
        let at = |i: usize, t: f64| {
            let h = &humans[i];
            let (position_m, heading_rad, speed_mps) = h.floor_pose(t);
            Walker { position_m, heading_rad, speed_mps, footprint_m: h.footprint_m(t) }
        };
        // Over the frames, the last one's sweep included.
        let swept = duration + 1.0 / self.inputs.sensor.rate_hz;
        let pushers = w.add_pushed(&handles, at, |i| humans[i].cuts(), swept, |t| carrier.map(|s| s.position(t).truncate()));
        let pushed = w.movers.clone();
        w.add_movers(duration, |t, out| {
            out.clear();
            out.extend(humans.iter().map(|h| h.position_m(t).truncate()));
            out.extend(carrier.map(|s| s.position(t).truncate()));
            for m in &pushed {
                let (c, h) = (m.position(t).truncate(), m.heading_rad(t));
                let along = DVec2::new(h.cos(), h.sin()) * (m.half.x - PERSON_RADIUS_M).max(0.0);
                out.extend([c - along, c, c + along]);
                out.extend(m.corners(t));
            }
        });
        for (i, h) in plan.humans.iter_mut().enumerate() {
            if !pushers.contains(&i) {
                h.pushed = None;
            }
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
    /// to the background's velocity (`R^T V`, in the sensor frame of the beam's column; with
    /// the rigid and limb models a turning mover's `V` at the hit, its turn included); and a
    /// rider's beams not scored (`/label` 255), as SemanticKITTI's riders are neither a hit
    /// nor a false alarm for a pedestrian network. `/clean/instance` and `/clean/label` the
    /// same on the clean returns.
    pub(super) fn movers(&self, people: usize, out: &mut FrameOutput) {
        let Some(w) = self.world.as_ref().filter(|w| !w.movers.is_empty()) else { return };
        let (bg, tri, meshes) = (&self.posed.background, &self.scratch.bg_hits.triangle, &self.inputs.env_meshes);
        let p = &self.posed;
        let columns = self.inputs.sensor.columns;
        let w_pos = |k: usize| w.movers[k].position(p.mover_time.get(k).copied().unwrap_or(0.0));
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
        // A turning mover's beams add its turn about its centre, w z x (hit - centre), the hit
        // placed in the world from the pose of its column (the rigid and limb models: the
        // paper's gives one velocity per object).
        let turns = self.cfg.output.velocity != crate::config::VelocityModel::Paper;
        let frame_pose = glam::DMat4::from_cols_array_2d(&out.world_from_sensor).transpose();
        let dirs = &self.inputs.dirs;
        for b in 0..out.range.len() {
            if out.range[b] <= 0.0 || out.instance[b] != 0 || out.label[b] != 0 {
                continue;
            }
            let Some((k, class)) = mover_of(b) else { continue };
            out.instance[b] = (people + 1 + k) as u16;
            if velocity {
                let m = &p.column_motion[if p.column_motion.len() == 1 { 0 } else { b % columns }];
                let mut v = p.mover_velocity[k];
                let wz = p.mover_yaw_rate.get(k).copied().unwrap_or(0.0);
                if wz != 0.0 && turns {
                    let pose = p.column_pose.get(b % columns).unwrap_or(&frame_pose);
                    let hit = pose.transform_point3(dirs[b] * f64::from(out.range[b]));
                    let r = hit - w_pos(k);
                    v += glam::DVec3::new(-wz * r.y, wz * r.x, 0.0);
                }
                let v = m.rot.transpose() * v;
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
