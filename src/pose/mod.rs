//! The pose stage: the sensor and the people of a frame at its time, the environment placed
//! in the sensor frame, each person in view skinned at its level of detail, and under the
//! rolling shutter every vertex moved to the time its column is fired
//! ([`crate::sensor_model::shutter`]). Also the per-beam surface velocities of `velocity =
//! "limb"`, which skin the people again about the frame's time.

use crate::backend::BeamHits;
use crate::error::Result;
use crate::geometry::FrameGeometry;
use crate::human::proxy::ModelProxies;
use crate::human::{GaitStyle, HumanModel, MODEL_TO_BODY};
use crate::input::Recording;
use crate::output::HumanState;
use crate::post::ColumnMotion;
use crate::scene::not_scored::NotScored;
use crate::scene::sequence::SequencePlan;
use crate::scene::{EnvDraw, Environment};
use crate::sensor::Sensor;
use crate::sensor_model::shutter::Sweep;
use glam::{DMat3, DMat4, DVec3, Mat4};
use rayon::prelude::*;

/// Rolling shutter: a person is posed at key times at most this far apart over the columns
/// it spans, and each vertex interpolated between the two around its own time (see
/// [`Sweep::warp_keys`]); 12 ms keeps the interpolation's error (acceleration x step^2 / 8)
/// near 0.2 mm at walking accelerations.
const KEY_STEP_S: f64 = 0.012;

/// Rolling shutter: the horizontal reach of a person about its centre line, as a fraction
/// of height (a hand or a foot mid-swing); its columns span this. A vertex beyond takes the
/// pose at the span's end (clamped), so the bound needs to be generous, not tight.
const BODY_HALF_WIDTH_PER_HEIGHT: f64 = 0.45;

/// Bounding-sphere radius of a person as a fraction of height (arms and legs mid-swing).
const BODY_RADIUS_PER_HEIGHT: f64 = 0.75;

/// The sensor and people at one frame (world frame).
#[derive(Clone, Debug)]
pub struct FrameState {
    /// Frame index within the sequence.
    pub frame: usize,
    pub t_s: f64,
    pub world_from_sensor: DMat4,
    pub sensor_velocity_mps: DVec3,
    pub sensor_yaw_rate_rps: f64,
    pub humans: Vec<HumanState>,
    pub human_velocity_mps: Vec<DVec3>,
    /// Per person: how it walks (standing blend, arm swing).
    pub human_style: Vec<GaitStyle>,
    /// Index of the recorded background frame shown at this frame.
    pub recorded_frame: Option<usize>,
}

/// Sensor and people of frame `k` of a plan, as they are at time `t` (s).
pub fn frame_state_at(plan: &SequencePlan, k: usize, t: f64) -> FrameState {
    let mut humans = Vec::with_capacity(plan.humans.len());
    let mut vel = Vec::with_capacity(plan.humans.len());
    let mut style = Vec::with_capacity(plan.humans.len());
    for h in &plan.humans {
        let s = h.at(t);
        humans.push(HumanState {
            position_m: s.position_m.into(),
            heading_rad: s.heading_rad as f32,
            velocity_mps: s.velocity_mps.as_vec3().into(),
            // Rounding to f32 can turn 1 - 1e-9 into 1.0: wrap again to keep [0, 1).
            gait_phase: (s.gait_phase as f32).rem_euclid(1.0),
        });
        vel.push(s.velocity_mps);
        style.push(s.style());
    }
    FrameState {
        frame: k,
        t_s: t,
        world_from_sensor: plan.sensor.pose(t),
        sensor_velocity_mps: plan.sensor.velocity(t),
        sensor_yaw_rate_rps: plan.sensor.yaw_rate_rps(t),
        humans,
        human_velocity_mps: vel,
        human_style: style,
        recorded_frame: plan.recording_start.map(|s| s + k),
    }
}

/// What the pose stage reads, loaded once for a run.
pub struct PoseInputs<'a> {
    pub sensor: &'a Sensor,
    /// The sensor's beam directions (row-major).
    pub dirs: &'a [DVec3],
    pub models: &'a [HumanModel],
    pub environment: Option<&'a Environment>,
    /// The environment's meshes as drawn (see [`EnvDraw`]).
    pub env_meshes: &'a [EnvDraw],
    pub recording: Option<&'a Recording>,
    /// What makes the recording's own returns not scored.
    pub not_scored: &'a NotScored,
    /// The people's proxies, when the backend draws them.
    pub proxies: Option<&'a [ModelProxies]>,
}

impl PoseInputs<'_> {
    /// The sweep of frame `k` of a plan starting at `t_s`: one revolution of the sensor, or
    /// under a recording its own: the capture's column times where it has them (a pcap,
    /// [`Recording::column_offsets`]), else uniform over the recording's frame step (its
    /// sensor turned once per frame).
    pub fn sweep(&self, plan: &SequencePlan, k: usize, t_s: f64, rolling: bool) -> Sweep {
        let w = self.sensor.columns;
        let own = match (self.recording, plan.recording_start) {
            (Some(rec), Some(start)) if rolling => rec.column_offsets(start + k).filter(|o| o.len() == w + 1),
            _ => None,
        };
        if let Some(offsets) = own {
            return Sweep::recorded(t_s, offsets.iter().map(|o| t_s + o).collect());
        }
        let t = &plan.times_s;
        let period = match (self.recording, t.len()) {
            (Some(_), n) if n >= 2 => {
                let step = if k + 1 < n { t[k + 1] - t[k] } else { t[n - 1] - t[n - 2] };
                if step > 0.0 && step.is_finite() { step } else { 1.0 / self.sensor.rate_hz }
            }
            _ => 1.0 / self.sensor.rate_hz,
        };
        Sweep::uniform(t_s, if rolling { period } else { 0.0 }, w)
    }
}

/// The pose stage's buffers, reused from frame to frame (no per-frame allocation in steady
/// state): what it posed last, which the later stages read, and its own scratch.
#[derive(Default)]
pub struct PoseStage {
    pub background: FrameGeometry,
    pub humans: FrameGeometry,
    /// The people's proxies, one mesh per person in `humans` order (when the backend draws
    /// proxies).
    pub proxies: FrameGeometry,
    /// The recorded background of the current frame (target grid ranges), when there is one.
    pub recorded: Option<Vec<f32>>,
    /// Its intensity per beam, in the recording's units (empty when it has none).
    pub recorded_intensity: Vec<f32>,
    /// The cells of the current frame whose recorded return is not scored, ascending.
    pub not_scored: Vec<u32>,
    /// The window (first recorded frame, frames) they were found for, and its cells per frame.
    not_scored_window: Option<(usize, usize, Vec<Vec<u32>>)>,
    /// The people in `humans`: (instance, model, level of detail).
    pub layout: Vec<(u32, usize, usize)>,
    /// The sweep of the frame posed last.
    pub sweep: Option<Sweep>,
    /// The sensor's motion per column of the frame posed last (one entry without rolling
    /// shutter), and each person's world velocity and time at the columns that see it.
    pub column_motion: Vec<ColumnMotion>,
    pub person_velocity: Vec<DVec3>,
    pub person_time: Vec<f64>,
    /// Rolling shutter with a moving sensor and an environment: `world_from_sensor` per
    /// column (the background's hits are refined against it); empty otherwise.
    pub column_pose: Vec<DMat4>,
    /// This frame's people (as `layout`, which holds last frame's until the swap) and their
    /// placements (sensor from model, gait phase).
    layout_next: Vec<(u32, usize, usize)>,
    placements: Vec<(Mat4, f32, GaitStyle)>,
    /// Rolling shutter, per drawn person: its placements at the later key times of its span
    /// (the first is in `placements`), and the span of times its vertices were posed over:
    /// `(ta, tb, u_centre)`.
    placements_b: Vec<Vec<(Mat4, f32, GaitStyle)>>,
    spans: Vec<(f64, f64, f64)>,
    /// Per drawn person: joint matrices, placed joints and bounding sphere (in-place poses).
    person_scratch: Vec<PersonScratch>,
    env_sensor: Vec<[f32; 3]>,
    /// With movers in the world: the environment's world positions this frame (the still
    /// part as built, each mover where it is at its own time); empty without movers.
    pub env_world: Vec<DVec3>,
    /// Per mover of the world: the time it was placed at, and its world velocity then.
    pub mover_time: Vec<f64>,
    pub mover_velocity: Vec<DVec3>,
    /// Per mover: its turning rate then, rad/s (a pushed thing's; 0 in a lane).
    pub mover_yaw_rate: Vec<f64>,
}

impl PoseStage {
    /// The world positions of `env` as this frame placed them: with movers, where they are
    /// now; else `env`'s own.
    pub fn env_positions<'a>(&'a self, env: &'a Environment) -> &'a [DVec3] {
        if self.env_world.len() == env.positions.len() { &self.env_world } else { &env.positions }
    }

    /// Poses the background and the people of a frame into the sensor frame (f64 -> f32),
    /// skipping people no beam can reach, and loads the recorded background frame, if any.
    /// With `rolling`, every vertex is placed at the time its column is fired.
    pub fn pose(&mut self, inp: &PoseInputs, plan: &SequencePlan, state: &FrameState, lod_max_error_mrad: f64, rolling: bool) -> Result<()> {
        let sensor_from_world = state.world_from_sensor.inverse();
        let sweep = inp.sweep(plan, state.frame, state.t_s, rolling);
        let s = self;
        s.sweep = Some(sweep.clone());
        // The sensor's motion per column (one entry when every column is the frame's instant).
        s.column_motion.clear();
        let motion_at = |t: f64| ColumnMotion {
            rot: DMat3::from_mat4(plan.sensor.pose(t)),
            velocity_mps: plan.sensor.velocity(t),
            yaw_rate_rps: plan.sensor.yaw_rate_rps(t),
        };
        if rolling {
            s.column_motion.extend((0..sweep.columns).map(|c| motion_at(sweep.column_time(c))));
        } else {
            s.column_motion.push(ColumnMotion {
                rot: DMat3::from_mat4(state.world_from_sensor),
                velocity_mps: state.sensor_velocity_mps,
                yaw_rate_rps: state.sensor_yaw_rate_rps,
            });
        }
        match (inp.recording, state.recorded_frame) {
            (Some(rec), Some(k)) => rec.frame(k, s.recorded.get_or_insert_with(Vec::new), &mut s.recorded_intensity)?,
            _ => {
                s.recorded = None;
                s.recorded_intensity.clear();
            }
        }
        s.not_scored.clear();
        if let (Some(rec), Some(start), true) = (inp.recording, plan.recording_start, inp.not_scored.is_on()) {
            let frames = plan.times_s.len();
            if s.not_scored_window.as_ref().is_none_or(|w| (w.0, w.1) != (start, frames)) {
                s.not_scored_window = Some((start, frames, inp.not_scored.window(rec, start..start + frames)?));
            }
            if let Some((_, _, cells)) = &s.not_scored_window {
                s.not_scored.extend_from_slice(&cells[state.frame]);
            }
        }
        s.background.clear();
        s.env_world.clear();
        s.mover_time.clear();
        s.mover_velocity.clear();
        s.mover_yaw_rate.clear();
        if let Some(env) = inp.environment {
            // Movers: each placed whole at its own time (under a rolling sweep, when the
            // column of its centre is fired), into this frame's copy of the environment.
            let movers = plan.world.as_deref().map_or(&[][..], |w| &w.movers[..]);
            if !movers.is_empty() {
                s.env_world.extend_from_slice(&env.positions);
                for m in movers {
                    let mut t = state.t_s;
                    if rolling {
                        // Two fixed-point steps from the frame's start, as for a person.
                        let c0 = sensor_from_world.transform_point3(m.position(t));
                        let u0 = sweep.u_of(c0.x, c0.y);
                        t = sweep.time_at(u0);
                        for _ in 0..2 {
                            let c = plan.sensor.pose(t).inverse().transform_point3(m.position(t));
                            t = sweep.time_at(sweep.unwrap_near(sweep.u_of(c.x, c.y), u0));
                        }
                    }
                    m.place(t, &mut s.env_world[m.first_vertex..m.first_vertex + m.local.len()]);
                    s.mover_time.push(t);
                    s.mover_velocity.push(m.velocity(t));
                    s.mover_yaw_rate.push(m.yaw_rate_rps(t));
                }
            }
            let positions = if s.env_world.is_empty() { &env.positions } else { &s.env_world };
            // A sensor that moves during the sweep sees each vertex from where it is when the
            // vertex's column is fired; a still one from one place.
            let end = plan.sensor.pose(sweep.time_at(sweep.columns as f64));
            let moves = rolling && end != state.world_from_sensor;
            s.column_pose.clear();
            if moves {
                sweep.place_static(positions, |t| plan.sensor.pose(t).inverse(), &mut s.env_sensor);
                s.column_pose.extend((0..sweep.columns).map(|c| plan.sensor.pose(sweep.column_time(c))));
            } else {
                s.env_sensor.clear();
                s.env_sensor.extend(positions.iter().map(|p| sensor_from_world.transform_point3(*p).as_vec3().to_array()));
            }
            for m in inp.env_meshes {
                let verts = &s.env_sensor[m.first_vertex..m.first_vertex + m.vertex_count];
                s.background.push_mesh_with_adjacency(verts, &m.local_indices, 0, m.double_sided, Some(m.adjacency.clone()));
            }
        }
        // Who is drawn, at which level of detail: (instance, model, lod), and where.
        let lod_rad = lod_max_error_mrad * 1e-3;
        s.layout_next.clear();
        s.placements.clear();
        s.placements_b.clear();
        s.spans.clear();
        s.person_velocity.clear();
        s.person_velocity.extend(state.human_velocity_mps.iter().copied());
        s.person_time.clear();
        s.person_time.resize(plan.humans.len(), state.t_s);
        let place = |h: &crate::scene::sequence::HumanPlan, t: f64, sensor_from_world: DMat4| {
            let st = h.at(t);
            let world_from_body = DMat4::from_translation(st.position_m) * DMat4::from_rotation_z(st.heading_rad);
            let m = (sensor_from_world * world_from_body * MODEL_TO_BODY.as_dmat4()).as_mat4();
            ((m, (st.gait_phase as f32).rem_euclid(1.0), st.style()), st.velocity_mps)
        };
        for (k, h) in plan.humans.iter().enumerate() {
            let model = &inp.models[h.model];
            let st = &state.humans[k];
            let world_from_body = DMat4::from_translation(DVec3::from(st.position_m)) * DMat4::from_rotation_z(st.heading_rad as f64);
            let sensor_from_body = sensor_from_world * world_from_body;
            let height = model.height_m as f64;
            // Over a rolling sweep the person and the sensor move: a margin for both.
            let sweep_margin = if rolling {
                (state.human_velocity_mps[k].length() + state.sensor_velocity_mps.length()) * sweep.period_s
                    + state.sensor_yaw_rate_rps.abs() * sweep.period_s * (sensor_from_body.w_axis.truncate().length())
            } else {
                0.0
            };
            let r = BODY_RADIUS_PER_HEIGHT * height + sweep_margin;
            let centre = sensor_from_body.transform_point3(DVec3::new(0.0, 0.0, 0.5 * height));
            let dist = centre.length();
            if !inp.sensor.may_see_sphere(centre, r) {
                continue;
            }
            let near = (dist - r).max(0.1);
            let lod = model.lod_for_error((lod_rad * near) as f32);
            s.layout_next.push((k as u32 + 1, h.model, lod));
            if rolling {
                // The person's own column time: where its centre is when its column is fired
                // (two fixed-point steps from the frame's start: the person and the sensor
                // move over the sweep by several columns).
                let mut t_c = sweep.time_at(sweep.u_of(centre.x, centre.y));
                for _ in 0..2 {
                    let st = h.at(t_c);
                    let c = plan.sensor.pose(t_c).inverse().transform_point3(st.position_m + DVec3::new(0.0, 0.0, 0.5 * height));
                    t_c = sweep.time_at(sweep.unwrap_near(sweep.u_of(c.x, c.y), sweep.u_of(centre.x, centre.y)));
                }
                let st = h.at(t_c);
                let centre = plan.sensor.pose(t_c).inverse().transform_point3(st.position_m + DVec3::new(0.0, 0.0, 0.5 * height));
                let (ta, tb, u_c) = sweep.span_of_sphere(centre, BODY_HALF_WIDTH_PER_HEIGHT * height);
                // Key times at most KEY_STEP_S apart: a near person spans much of the sweep.
                let keys = ((tb - ta) / KEY_STEP_S).ceil().clamp(1.0, 64.0) as usize;
                let key_time = |j: usize| ta + (tb - ta) * j as f64 / keys as f64;
                let (a, _) = place(h, ta, plan.sensor.pose(ta).inverse());
                s.placements.push(a);
                s.placements_b.push((1..=keys).map(|j| place(h, key_time(j), plan.sensor.pose(key_time(j)).inverse()).0).collect());
                s.spans.push((ta, tb, u_c));
                let t_c = sweep.time_at(u_c);
                s.person_time[k] = t_c;
                s.person_velocity[k] = h.at(t_c).velocity_mps;
            } else {
                s.placements.push(((sensor_from_body * MODEL_TO_BODY.as_dmat4()).as_mat4(), st.gait_phase, state.human_style[k]));
            }
        }
        // The same people at the same levels of detail as last frame: the triangles stay and
        // only the vertices move. Otherwise the meshes are laid out anew (sizes from the
        // levels of detail) and each person also writes its indices.
        let in_place = s.layout_next == s.layout && s.humans.meshes.len() == s.layout.len();
        let models = inp.models;
        if !in_place {
            s.humans.lay_out(s.layout_next.iter().map(|&(instance, m, lod)| {
                let l = &models[m].lods[lod];
                l.layout(instance, false, Some(l.adjacency.clone()))
            }));
        }
        // One person per task: joint matrices, skinning into its own vertices, its indices
        // when laid out anew, its bounding sphere. Rolling: skinned at both ends of its span
        // and each vertex moved to its own time.
        s.person_scratch.resize_with(s.layout_next.len(), Default::default);
        let (placements_b, spans) = (&s.placements_b, &s.spans);
        s.humans
            .mesh_slices_mut()
            .into_par_iter()
            .zip(s.person_scratch.par_iter_mut())
            .zip(s.layout_next.par_iter().zip(s.placements.par_iter()))
            .enumerate()
            .for_each(|(i, (((first, out, indices), p), (&(_, m, lod), &(transform, phase, style))))| {
                let model = &models[m];
                model.joint_matrices_styled(phase, style, &mut p.joints);
                model.skin_into_slice(lod, &p.joints, &transform, &mut p.placed, out);
                if rolling {
                    let keys = &placements_b[i];
                    let (ta, tb, u_c) = spans[i];
                    p.joints_b.resize_with(keys.len(), Vec::new);
                    p.b.resize_with(keys.len(), Vec::new);
                    for (j, &(transform_b, phase_b, style_b)) in keys.iter().enumerate() {
                        model.joint_matrices_styled(phase_b, style_b, &mut p.joints_b[j]);
                        p.b[j].resize(out.len(), [0.0; 3]);
                        model.skin_into_slice(lod, &p.joints_b[j], &transform_b, &mut p.placed, &mut p.b[j]);
                    }
                    sweep.warp_keys(out, &p.b, ta, tb, u_c);
                }
                if !in_place {
                    for (d, &i) in indices.iter_mut().zip(&model.lods[lod].indices) {
                        *d = i + first;
                    }
                }
                p.bounds = crate::geometry::bounding_sphere(out);
            });
        for (m, p) in s.humans.meshes.iter_mut().zip(&s.person_scratch) {
            (m.centre, m.radius) = p.bounds;
        }
        if let Some(proxies) = inp.proxies {
            if !in_place {
                // Drawn from both sides: a beam that meets a proxy, whatever the winding of
                // the face it meets, may hit that person.
                s.proxies.lay_out(
                    s.layout_next.iter().map(|&(instance, m, lod)| proxies[m].lods[lod].layout(instance, true, None)),
                );
            }
            s.proxies
                .mesh_slices_mut()
                .into_par_iter()
                .zip(s.person_scratch.par_iter_mut())
                .zip(s.layout_next.par_iter().zip(s.placements.par_iter()))
                .enumerate()
                .for_each(|(i, (((first, out, indices), p), (&(_, m, lod), &(transform, _, _))))| {
                    let proxy = &proxies[m].lods[lod];
                    models[m].skin_lod_into_slice(proxy, &p.joints, &transform, &mut p.placed, out);
                    if rolling {
                        let (ta, tb, u_c) = spans[i];
                        for (j, key) in placements_b[i].iter().enumerate() {
                            p.b[j].resize(out.len(), [0.0; 3]);
                            models[m].skin_lod_into_slice(proxy, &p.joints_b[j], &key.0, &mut p.placed, &mut p.b[j]);
                        }
                        sweep.warp_keys(out, &p.b, ta, tb, u_c);
                    }
                    if !in_place {
                        for (d, &i) in indices.iter_mut().zip(&proxy.indices) {
                            *d = i + first;
                        }
                    }
                    p.proxy_bounds = crate::geometry::bounding_sphere(out);
                });
            for (m, p) in s.proxies.meshes.iter_mut().zip(&s.person_scratch) {
                (m.centre, m.radius) = p.proxy_bounds;
            }
        }
        std::mem::swap(&mut s.layout, &mut s.layout_next);
        Ok(())
    }

    /// Per beam with a human hit: the world velocity of the surface point it hits, rotated
    /// into the sensor frame (`R^T V`), into `point_velocity`, which `post` reads for `velocity = "limb"`;
    /// `hits` are the people layer's hits of the frame posed last.
    /// The point keeps its barycentric coordinates in the hit triangle, and the triangle's
    /// vertices are skinned and placed as `pose_frame` does at `t - dt` and `t + dt` (the
    /// walk's phase and the trajectory both move; the sensor's pose stays that of `t`):
    /// `V = (p(t + dt) - p(t - dt)) / 2 dt`, dt = 1 ms, skinning in the model frame (f32,
    /// ~1 m) and placing in f64, so rounding stays near 1e-4 m/s.
    pub fn point_velocities(&self, inp: &PoseInputs, plan: &SequencePlan, state: &FrameState, hits: &BeamHits, point_velocity: &mut Vec<DVec3>) {
        const DT_S: f64 = 1e-3;
        let s = self;
        let n = inp.dirs.len();
        point_velocity.clear();
        point_velocity.resize(n, DVec3::ZERO);
        let geom = &s.humans;
        let mut seen = vec![false; geom.meshes.len()];
        for &t in &hits.triangle {
            if t != crate::backend::NO_TRIANGLE {
                seen[geom.mesh_index_of_triangle(t)] = true;
            }
        }
        let rolling = s.sweep.as_ref().is_some_and(|w| w.rolls());
        let person_time = &s.person_time;
        let model_to_body = MODEL_TO_BODY.as_dmat4();
        // Per person seen: (placed joints, sensor from model) at t - dt and t + dt.
        type Motion = [(Vec<glam::Affine3A>, DMat4); 2];
        let motions: Vec<Option<Motion>> = s
            .layout
            .par_iter()
            .zip(seen.par_iter())
            .map(|(&(instance, m, _), &seen)| {
                if !seen {
                    return None;
                }
                let h = &plan.humans[instance as usize - 1];
                let model = &inp.models[m];
                // The person's time: that of the columns that see it (rolling shutter).
                let t = person_time.get(instance as usize - 1).copied().unwrap_or(state.t_s);
                let sensor_from_world = if rolling { plan.sensor.pose(t).inverse() } else { state.world_from_sensor.inverse() };
                let at = |dt: f64| {
                    let st = h.at(t + dt);
                    let world_from_body = DMat4::from_translation(st.position_m) * DMat4::from_rotation_z(st.heading_rad);
                    let mut joints = Vec::new();
                    model.joint_matrices_styled((st.gait_phase as f32).rem_euclid(1.0), st.style(), &mut joints);
                    (joints.iter().map(|j| glam::Affine3A::from_mat4(*j)).collect(), sensor_from_world * world_from_body * model_to_body)
                };
                Some([at(-DT_S), at(DT_S)])
            })
            .collect();
        let layout = &s.layout;
        let models = inp.models;
        let dirs = inp.dirs;
        point_velocity.par_iter_mut().enumerate().for_each(|(b, v)| {
            let t = hits.triangle[b];
            if t == crate::backend::NO_TRIANGLE {
                return;
            }
            let k = geom.mesh_index_of_triangle(t);
            let (Some(motion), mesh) = (&motions[k], &geom.meshes[k]) else { return };
            let (_, m, lod) = layout[k];
            let lod = &models[m].lods[lod];
            let i = &geom.indices[3 * t as usize..3 * t as usize + 3];
            let lambda = barycentric(dirs[b] * hits.range_m[b] as f64, geom.triangle_f64(t));
            let mut p = [DVec3::ZERO; 2];
            for (side, (placed, sensor_from_model)) in motion.iter().enumerate() {
                let q: DVec3 = (0..3)
                    .map(|c| lambda[c] * crate::human::skin_vertex(lod, placed, (i[c] - mesh.first_vertex) as usize).as_dvec3())
                    .sum();
                p[side] = sensor_from_model.transform_point3(q);
            }
            *v = (p[1] - p[0]) / (2.0 * DT_S);
        });
    }
}

/// Per drawn person, reused across frames: joint matrices, placed joints, bounding sphere.
#[derive(Default)]
struct PersonScratch {
    joints: Vec<Mat4>,
    /// Rolling shutter: the joints at the later key times of the person's span, and its
    /// vertices (or its proxy's) posed there.
    joints_b: Vec<Vec<Mat4>>,
    b: Vec<Vec<[f32; 3]>>,
    placed: Vec<glam::Affine3A>,
    bounds: ([f32; 3], f32),
    proxy_bounds: ([f32; 3], f32),
}

/// Barycentric coordinates of `p` (on or near the triangle's plane) in triangle `t`, by
/// projection onto the plane; a degenerate triangle gives its centroid.
fn barycentric(p: DVec3, t: [DVec3; 3]) -> [f64; 3] {
    let (e0, e1, e2) = (t[1] - t[0], t[2] - t[0], p - t[0]);
    let (d00, d01, d11) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
    let (d20, d21) = (e2.dot(e0), e2.dot(e1));
    let denom = d00 * d11 - d01 * d01;
    if !(denom.abs() > 1e-12 * d00 * d11) {
        return [1.0 / 3.0; 3];
    }
    let l1 = (d11 * d20 - d01 * d21) / denom;
    let l2 = (d00 * d21 - d01 * d20) / denom;
    [1.0 - l1 - l2, l1, l2]
}
