//! The generator: runs the stages of every frame of every sequence, in data-flow order:
//! sample the sequence -> pose people and background in the sensor frame (f64 -> f32) ->
//! nearest surface per beam (a [`Backend`]: raster or ray cast) -> composite, label,
//! velocity -> write. Its state is private; commands drive it through a few methods.
//!
//! Each sequence draws from its own random stream (ChaCha8, stream = sequence index), so a
//! sequence's content depends only on the seed, the configuration and its index: never on
//! thread count, on which other sequences ran, or on the GPU.

use crate::backend::{self, Backend, BeamHits, Gpu, Layer, LayerKind};
use crate::input::recording::is_recording;
use crate::input::Recording;
use crate::config::{CompressionChoice, Config, Format};
use crate::error::{Error, Result};
use crate::geometry::{Adjacency, FrameGeometry};
use crate::human::{model_files, GaitStyle, HumanModel, MODEL_TO_BODY};
use crate::output::{Compression, FrameOutput, HumanMeta, HumanState, OutputSet, SequenceMeta, SequenceWriter, WriterOptions};
use crate::post::{composite, PostParams};
use crate::scene::{Environment, WalkableGrid, WALKABLE_CELL_M};
use crate::sensor::Sensor;
use crate::scene::sequence::{sample_plan, PlanInputs, PoseTrack, SequencePlan};
use crate::input::tracks::{read_tracks, Track, TrackOptions};
use glam::{DMat3, DMat4, DVec3, Mat4};
use rand::SeedableRng;
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Bounding-sphere radius of a person as a fraction of height (arms and legs mid-swing).
const BODY_RADIUS_PER_HEIGHT: f64 = 0.75;

/// What [`Generator::write_sequence`] wrote.
#[derive(Clone, Debug)]
pub struct WrittenSequence {
    /// The final paths: the HDF5 file, the XML file and, with PNGs, the PNG folder.
    pub files: Vec<PathBuf>,
    /// People in the sequence.
    pub people: usize,
    /// Frames written.
    pub frames: usize,
    /// Points per class of the SemanticKITTI export, when written.
    pub class_points: Option<crate::output::semantickitti::ClassPoints>,
}

/// Everything loaded once for a run, and the per-frame buffers.
pub struct Generator {
    cfg: Config,
    sensor: Sensor,
    /// The sensor's beam directions (row-major).
    dirs: Vec<DVec3>,
    models: Vec<HumanModel>,
    environment: Option<Environment>,
    grid: Option<WalkableGrid>,
    /// A recorded background sequence (instead of an environment).
    recording: Option<Recording>,
    /// Recorded sensor poses with their times (from `scene.poses`, or a static sensor under a
    /// recording without poses): the sensor follows them.
    sensor_poses: Option<(Vec<f64>, Vec<DMat4>)>,
    /// Recorded pedestrian tracks (world frame), when `humans.tracks` is set.
    tracks: Vec<Arc<Track>>,
    /// The nearest surface per beam: raster or ray cast (`render.backend`, `auto` resolved).
    backend: Box<dyn Backend>,
    scratch: Scratch,
    /// Per environment mesh: its vertex range in `environment.positions`, local indices and
    /// triangle one-rings (computed once).
    env_meshes: Vec<EnvDraw>,
    /// Write each frame's posed humans as PLY under this folder (`--export-geometry`).
    export_geometry: Option<PathBuf>,
    /// Seconds spent per stage so far (see `--timings`).
    timings: StageTimes,
}

/// One posed frame as the backends see it (see [`Generator::posed`]).
pub struct Posed<'a> {
    pub background: &'a FrameGeometry,
    pub people: &'a FrameGeometry,
    /// The people's proxies, one mesh per person (empty unless the backend draws proxies).
    pub proxies: &'a FrameGeometry,
}

fn layer_of(s: &Scratch, kind: LayerKind) -> Layer<'_> {
    match kind {
        LayerKind::Background => Layer::Background(&s.background),
        LayerKind::People => Layer::People { people: &s.humans, proxies: &s.proxies },
    }
}

/// Wall-clock seconds spent per stage of the frames generated so far. The writer runs on its
/// own thread, overlapping the next frame, so `write_s` is not part of the frame's critical
/// path unless it is the longer of the two.
#[derive(Clone, Copy, Debug, Default)]
pub struct StageTimes {
    pub frames: u64,
    /// Plan and sample sequences (walkable area, walks, tracks).
    pub plan_s: f64,
    /// Load a recorded frame, pose the background, skin and place the people.
    pub pose_s: f64,
    /// Ray caster with `debug.caster = "bvh"`: refit or build the trees (both layers).
    pub bvh_s: f64,
    /// Render (raster) or cast (ray caster) the background and resample it.
    pub background_s: f64,
    /// Render or cast the people and resample them.
    pub humans_s: f64,
    /// Composite, labels, instance ids, velocities.
    pub post_s: f64,
    /// Compress and write (HDF5, PNG), on the writer thread.
    pub write_s: f64,
}

impl std::fmt::Display for StageTimes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.frames.max(1) as f64;
        let main = self.plan_s + self.pose_s + self.bvh_s + self.background_s + self.humans_s + self.post_s;
        writeln!(f, "stage           ms/frame   share of frame thread")?;
        for (name, s) in [
            ("plan", self.plan_s),
            ("pose + skin", self.pose_s),
            ("bvh refit", self.bvh_s),
            ("background", self.background_s),
            ("people", self.humans_s),
            ("post", self.post_s),
        ] {
            // The BVH stage exists only with `debug.caster = "bvh"`.
            if name == "bvh refit" && s == 0.0 {
                continue;
            }
            writeln!(f, "{name:<14} {:>9.3}   {:>5.1} %", 1e3 * s / n, 100.0 * s / main.max(1e-12))?;
        }
        writeln!(f, "{:<14} {:>9.3}", "frame thread", 1e3 * main / n)?;
        write!(f, "{:<14} {:>9.3}   (writer thread, overlaps the next frame)", "write", 1e3 * self.write_s / n)
    }
}

struct EnvDraw {
    first_vertex: usize,
    vertex_count: usize,
    local_indices: Vec<u32>,
    double_sided: bool,
    adjacency: Arc<Adjacency>,
}

/// Per-frame buffers, reused (no per-frame allocation in steady state).
#[derive(Default)]
struct Scratch {
    background: FrameGeometry,
    humans: FrameGeometry,
    /// The people's proxies, one mesh per person in `humans` order (when the backend draws
    /// proxies).
    proxies: FrameGeometry,
    bg_hits: BeamHits,
    human_hits: BeamHits,
    /// The recorded background of the current frame (target grid ranges), when there is one.
    recorded: Option<Vec<f32>>,
    /// The people in `humans` (instance, model, level of detail), last frame and this one,
    /// and this frame's placements (sensor from model, gait phase).
    layout: Vec<(u32, usize, usize)>,
    layout_next: Vec<(u32, usize, usize)>,
    placements: Vec<(Mat4, f32, GaitStyle)>,
    /// Per drawn person: joint matrices, placed joints and bounding sphere (in-place poses).
    person_scratch: Vec<PersonScratch>,
    env_sensor: Vec<[f32; 3]>,
    /// `limb` velocities: per beam, the world velocity of the human surface point it hits,
    /// sensor frame (see [`Generator::point_velocities`]).
    point_velocity: Vec<DVec3>,
}

/// Per drawn person, reused across frames: joint matrices, placed joints, bounding sphere.
#[derive(Default)]
struct PersonScratch {
    joints: Vec<Mat4>,
    placed: Vec<glam::Affine3A>,
    bounds: ([f32; 3], f32),
    proxy_bounds: ([f32; 3], f32),
}

/// The sensor and people at one frame (world frame).
#[derive(Clone, Debug)]
pub struct FrameState {
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

impl Generator {
    /// Checks the configuration, loads sensor, people and environment, creates the backend
    /// (which, for raster, opens the Vulkan device).
    pub fn new(cfg: Config) -> Result<Generator> {
        let mut gpu = Gpu::new(&cfg.device, cfg.debug.validation);
        Generator::with_gpu(cfg, &mut gpu)
    }

    /// [`Generator::new`] on a Vulkan context shared with other backends of the run.
    pub fn with_gpu(cfg: Config, gpu: &mut Gpu) -> Result<Generator> {
        cfg.validate()?;
        let sensor = Sensor::from_name_or_file(&cfg.sensor)?;
        let needs_animation = cfg.humans.motion.animates();
        let models = if cfg.humans.count[1] > 0 {
            model_files(&cfg.humans.models)?
                .iter()
                .map(|f| HumanModel::load(f, needs_animation))
                .collect::<Result<Vec<_>>>()?
        } else {
            Vec::new()
        };
        let bg = &cfg.scene.background;
        let (environment, grid, recording) = if bg.as_os_str().is_empty() {
            (None, None, None)
        } else if is_recording(bg) {
            let poses = (!cfg.scene.poses.as_os_str().is_empty()).then_some(cfg.scene.poses.as_path());
            (None, None, Some(Recording::open(bg, poses, &sensor)?))
        } else {
            let env = Environment::load(bg)?;
            let grid = WalkableGrid::from_environment(&env, WALKABLE_CELL_M).map_err(|e| match e {
                Error::Input { message, .. } => Error::input(bg.display(), message),
                other => other,
            })?;
            if grid.free_fraction(cfg.humans.clearance_m) <= 0.0 {
                return Err(Error::input(bg.display(), "environment has no walkable floor at z = 0"));
            }
            (Some(env), Some(grid), None)
        };
        let sensor_poses = match &recording {
            Some(rec) => Some((rec.times_s.clone(), (0..rec.len()).map(|k| rec.pose(k)).collect::<Vec<_>>())),
            None if !cfg.scene.poses.as_os_str().is_empty() => {
                let p = crate::input::poses::read_poses(&cfg.scene.poses)?;
                let times = match p.times_s {
                    Some(t) => t,
                    None => (0..p.world_from_sensor.len()).map(|k| k as f64 / sensor.rate_hz).collect(),
                };
                Some((times, p.world_from_sensor))
            }
            None => None,
        };
        if let Some((times, _)) = &sensor_poses {
            if times.len() < cfg.frames {
                let what = if recording.is_some() { bg.display().to_string() } else { cfg.scene.poses.display().to_string() };
                return Err(Error::input(
                    what,
                    format!("{} recorded frames are fewer than frames = {} per sequence", times.len(), cfg.frames),
                ));
            }
        }
        let tracks: Vec<Arc<Track>> = if cfg.humans.tracks.as_os_str().is_empty() {
            Vec::new()
        } else {
            let opts = TrackOptions { frame_period_s: cfg.humans.tracks_frame_period_s, transform: cfg.humans.tracks_transform };
            let all = read_tracks(&cfg.humans.tracks, cfg.humans.tracks_format, &opts)?;
            // Only tracks that can cover a whole sequence (frames at the recording's or the
            // sensor's rate) are kept.
            let duration = match &sensor_poses {
                Some((t, _)) => (0..=t.len() - cfg.frames).map(|s| t[s + cfg.frames - 1] - t[s]).fold(f64::INFINITY, f64::min),
                None => (cfg.frames - 1) as f64 / sensor.rate_hz,
            };
            let n = all.len();
            let kept = crate::input::tracks::drop_short(all, duration);
            if kept.is_empty() && cfg.humans.count[1] > 0 {
                return Err(Error::input(
                    cfg.humans.tracks.display(),
                    format!("none of its {n} tracks lasts {duration:.2} s, the length of a sequence; lower frames"),
                ));
            }
            kept.into_iter().map(Arc::new).collect()
        };
        if let Some(rec) = &recording {
            eprintln!("background {}: {}", bg.display(), rec.description);
            if rec.poses.is_none() {
                eprintln!("warning: {}: no poses given (--poses), so the sensor is taken as static; background velocities are 0", bg.display());
            }
        }
        let env_meshes = environment.as_ref().map_or_else(Vec::new, |env| {
            env.meshes
                .iter()
                .filter(|m| !m.indices.is_empty())
                .map(|m| {
                    let lo = *m.indices.iter().min().unwrap_or(&0);
                    let hi = *m.indices.iter().max().unwrap_or(&0);
                    let local_indices: Vec<u32> = m.indices.iter().map(|i| i - lo).collect();
                    let adjacency = Arc::new(Adjacency::build(&local_indices));
                    EnvDraw { first_vertex: lo as usize, vertex_count: (hi - lo + 1) as usize, local_indices, double_sided: m.double_sided, adjacency }
                })
                .collect()
        });
        let backend = backend::create(&cfg, &sensor, &models, gpu)?;
        Ok(Generator {
            dirs: sensor.beam_dirs(),
            cfg,
            sensor,
            models,
            environment,
            grid,
            recording,
            sensor_poses,
            tracks,
            backend,
            scratch: Scratch::default(),
            env_meshes,
            export_geometry: None,
            timings: StageTimes::default(),
        })
    }

    /// The checked configuration.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// The sensor.
    pub fn sensor(&self) -> &Sensor {
        &self.sensor
    }

    /// The people's models, in the order plans index them.
    pub fn models(&self) -> &[HumanModel] {
        &self.models
    }

    /// The sensor's beam directions (row-major).
    pub fn beam_dirs(&self) -> &[DVec3] {
        &self.dirs
    }

    /// The backend that runs.
    pub fn backend(&self) -> &dyn Backend {
        &*self.backend
    }

    /// Seconds spent per stage so far.
    pub fn timings(&self) -> StageTimes {
        self.timings
    }

    /// Also write each frame's posed people as PLY under `dir` (`--export-geometry`).
    pub fn set_export_geometry(&mut self, dir: Option<PathBuf>) {
        self.export_geometry = dir;
    }

    /// The frame [`Generator::pose_frame`] posed last.
    pub fn posed(&self) -> Posed<'_> {
        Posed { background: &self.scratch.background, people: &self.scratch.humans, proxies: &self.scratch.proxies }
    }

    /// The point velocities [`Generator::point_velocities`] computed last (per beam).
    pub fn point_velocity(&self) -> &[DVec3] {
        &self.scratch.point_velocity
    }

    /// The people layer's hits of the frame [`Generator::render_posed`] cast last.
    pub fn human_hits(&self) -> &BeamHits {
        &self.scratch.human_hits
    }

    /// Ends the run: releases the backend and reports Vulkan validation errors, if on.
    pub fn finish(self) -> Result<()> {
        backend::finish(self.backend)
    }

    /// The random stream of sequence `index`.
    pub fn rng(&self, index: usize) -> rand_chacha::ChaCha8Rng {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(self.cfg.seed);
        rng.set_stream(index as u64);
        rng
    }

    /// Samples sequence `index`.
    pub fn plan(&self, index: usize) -> Result<SequencePlan> {
        let mut rng = self.rng(index);
        let frames = self.cfg.frames;
        // A recorded sensor path: a window of `frames` consecutive poses at a random start.
        let (sensor, start) = match &self.sensor_poses {
            Some((times, poses)) => {
                let starts = times.len() - frames + 1;
                let start = ((rand::RngExt::random::<f64>(&mut rng) * starts as f64) as usize).min(starts - 1);
                (Some(PoseTrack::from_poses(times, poses, start..start + frames)), Some(start))
            }
            None => (None, None),
        };
        let recorded_grid;
        let (grid, floor_z_m) = match (&self.recording, start) {
            (Some(rec), Some(s)) if self.cfg.humans.count[1] > 0 => {
                let (z, g) = crate::scene::recorded::walkable(rec, s..s + frames, self.cfg.scene.floor_z_m)?;
                recorded_grid = g;
                (Some(&recorded_grid), z)
            }
            _ => (self.grid.as_ref(), self.cfg.scene.floor_z_m.unwrap_or(0.0)),
        };
        let inputs = PlanInputs { rate_hz: self.sensor.rate_hz, grid, models: &self.models, tracks: &self.tracks, sensor, floor_z_m };
        let mut plan = sample_plan(&mut rng, &self.cfg, &inputs)?;
        plan.recording_start = if self.recording.is_some() { start } else { None };
        plan.floor_z_m = floor_z_m;
        Ok(plan)
    }

    /// Which outputs are computed.
    pub fn outputs(&self) -> OutputSet {
        OutputSet { xyz: self.cfg.output.xyz, velocity: self.cfg.output.velocity_field, background: self.cfg.output.background }
    }

    /// Sensor and people at frame `k` of a plan.
    pub fn frame_state(&self, plan: &SequencePlan, k: usize) -> FrameState {
        let t = plan.times_s[k];
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

    /// Poses the background and the people of a frame into the sensor frame (f64 -> f32),
    /// skipping people no beam can reach. Fills `scratch.background` and `scratch.humans`, and
    /// `scratch.recorded` with the recorded background frame, if any.
    pub fn pose_frame(&mut self, plan: &SequencePlan, state: &FrameState) -> Result<()> {
        self.pose_frame_at(plan, state, self.cfg.render.lod_max_error_mrad)
    }

    /// [`Generator::pose_frame`] with every person at full detail (the reference of `bench`).
    pub fn pose_frame_full_detail(&mut self, plan: &SequencePlan, state: &FrameState) -> Result<()> {
        self.pose_frame_at(plan, state, 0.0)
    }

    fn pose_frame_at(&mut self, plan: &SequencePlan, state: &FrameState, lod_max_error_mrad: f64) -> Result<()> {
        let sensor_from_world = state.world_from_sensor.inverse();
        let s = &mut self.scratch;
        match (&self.recording, state.recorded_frame) {
            (Some(rec), Some(k)) => rec.frame_ranges(k, s.recorded.get_or_insert_with(Vec::new))?,
            _ => s.recorded = None,
        }
        s.background.clear();
        if let Some(env) = &self.environment {
            s.env_sensor.clear();
            s.env_sensor.extend(env.positions.iter().map(|p| sensor_from_world.transform_point3(*p).as_vec3().to_array()));
            for m in &self.env_meshes {
                let verts = &s.env_sensor[m.first_vertex..m.first_vertex + m.vertex_count];
                s.background.push_mesh_with_adjacency(verts, &m.local_indices, 0, m.double_sided, Some(m.adjacency.clone()));
            }
        }
        // Who is drawn, at which level of detail: (instance, model, lod), and where.
        let lod_rad = lod_max_error_mrad * 1e-3;
        s.layout_next.clear();
        s.placements.clear();
        for (k, h) in plan.humans.iter().enumerate() {
            let model = &self.models[h.model];
            let st = &state.humans[k];
            let world_from_body = DMat4::from_translation(DVec3::from(st.position_m)) * DMat4::from_rotation_z(st.heading_rad as f64);
            let sensor_from_body = sensor_from_world * world_from_body;
            let height = model.height_m as f64;
            let r = BODY_RADIUS_PER_HEIGHT * height;
            let centre = sensor_from_body.transform_point3(DVec3::new(0.0, 0.0, 0.5 * height));
            let dist = centre.length();
            if !self.sensor.may_see_sphere(centre, r) {
                continue;
            }
            let near = (dist - r).max(0.1);
            let lod = model.lod_for_error((lod_rad * near) as f32);
            s.layout_next.push((k as u32 + 1, h.model, lod));
            s.placements.push(((sensor_from_body * MODEL_TO_BODY.as_dmat4()).as_mat4(), st.gait_phase, state.human_style[k]));
        }
        // The same people at the same levels of detail as last frame: the triangles stay and
        // only the vertices move. Otherwise the meshes are laid out anew (sizes from the
        // levels of detail) and each person also writes its indices.
        let in_place = s.layout_next == s.layout && s.humans.meshes.len() == s.layout.len();
        let models = &self.models;
        if !in_place {
            s.humans.lay_out(s.layout_next.iter().map(|&(instance, m, lod)| {
                let l = &models[m].lods[lod];
                l.layout(instance, false, Some(l.adjacency.clone()))
            }));
        }
        // One person per task: joint matrices, skinning into its own vertices, its indices
        // when laid out anew, its bounding sphere.
        s.person_scratch.resize_with(s.layout_next.len(), Default::default);
        s.humans
            .mesh_slices_mut()
            .into_par_iter()
            .zip(s.person_scratch.par_iter_mut())
            .zip(s.layout_next.par_iter().zip(s.placements.par_iter()))
            .for_each(|(((first, out, indices), p), (&(_, m, lod), &(transform, phase, style)))| {
                let model = &models[m];
                model.joint_matrices_styled(phase, style, &mut p.joints);
                model.skin_into_slice(lod, &p.joints, &transform, &mut p.placed, out);
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
        if let Some(proxies) = self.backend.proxies() {
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
                .for_each(|(((first, out, indices), p), (&(_, m, lod), &(transform, _, _)))| {
                    let proxy = &proxies[m].lods[lod];
                    models[m].skin_lod_into_slice(proxy, &p.joints, &transform, &mut p.placed, out);
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

    /// Finds the nearest surface per beam of the posed frame, layer by layer, into
    /// `scratch.bg_hits` / `scratch.human_hits` (a recorded background replaces the first).
    pub fn render_posed(&mut self) -> Result<()> {
        let s = &mut self.scratch;
        let t = &mut self.timings;
        let people = Layer::People { people: &s.humans, proxies: &s.proxies };
        let seconds = self.backend.cast_frame(Layer::Background(&s.background), people, &mut s.bg_hits, &mut s.human_hits)?;
        t.bvh_s += seconds.build;
        t.background_s += seconds.background;
        t.humans_s += seconds.people;
        if let Some(r) = &s.recorded {
            s.bg_hits.range_m.clone_from(r);
        }
        Ok(())
    }

    /// One layer of the posed frame through the generator's backend, into `hits`.
    pub fn cast_layer(&mut self, kind: LayerKind, hits: &mut BeamHits) -> Result<()> {
        let s = &self.scratch;
        self.backend.cast(layer_of(s, kind), hits)
    }

    /// One layer of the posed frame through another backend (`crosscheck` holds several).
    pub fn cast_with(&self, backend: &mut dyn Backend, kind: LayerKind, hits: &mut BeamHits) -> Result<()> {
        backend.cast(layer_of(&self.scratch, kind), hits)
    }

    /// Per beam with a human hit: the world velocity of the surface point it hits, rotated
    /// into the sensor frame (`R^T V`), into the scratch `post` reads for `velocity = "limb"`.
    /// The point keeps its barycentric coordinates in the hit triangle, and the triangle's
    /// vertices are skinned and placed as `pose_frame` does at `t - dt` and `t + dt` (the
    /// walk's phase and the trajectory both move; the sensor's pose stays that of `t`):
    /// `V = (p(t + dt) - p(t - dt)) / 2 dt`, dt = 1 ms, skinning in the model frame (f32,
    /// ~1 m) and placing in f64, so rounding stays near 1e-4 m/s.
    pub fn point_velocities(&mut self, plan: &SequencePlan, state: &FrameState) {
        const DT_S: f64 = 1e-3;
        let s = &mut self.scratch;
        let n = self.dirs.len();
        s.point_velocity.clear();
        s.point_velocity.resize(n, DVec3::ZERO);
        let geom = &s.humans;
        let hits = &s.human_hits;
        let mut seen = vec![false; geom.meshes.len()];
        for &t in &hits.triangle {
            if t != crate::backend::NO_TRIANGLE {
                seen[geom.mesh_index_of_triangle(t)] = true;
            }
        }
        let sensor_from_world = state.world_from_sensor.inverse();
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
                let model = &self.models[m];
                let at = |dt: f64| {
                    let st = h.at(state.t_s + dt);
                    let world_from_body = DMat4::from_translation(st.position_m) * DMat4::from_rotation_z(st.heading_rad);
                    let mut joints = Vec::new();
                    model.joint_matrices_styled((st.gait_phase as f32).rem_euclid(1.0), st.style(), &mut joints);
                    (joints.iter().map(|j| glam::Affine3A::from_mat4(*j)).collect(), sensor_from_world * world_from_body * model_to_body)
                };
                Some([at(-DT_S), at(DT_S)])
            })
            .collect();
        let layout = &s.layout;
        let models = &self.models;
        let dirs = &self.dirs;
        s.point_velocity.par_iter_mut().enumerate().for_each(|(b, v)| {
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

    /// Composites the rendered frame into `out`; with `velocity = "limb"` call
    /// [`Generator::point_velocities`] first.
    pub fn post(&self, state: &FrameState, out: &mut FrameOutput) {
        let rot = DMat3::from_mat4(state.world_from_sensor);
        let params = PostParams {
            dirs: &self.dirs,
            columns: self.sensor.columns,
            min_range_m: self.sensor.min_range_m,
            max_range_m: self.sensor.max_range_m,
            keep_holes: self.cfg.render.keep_holes,
            velocity_model: self.cfg.output.velocity,
            outputs: self.outputs(),
            world_from_sensor_rot: rot,
            sensor_velocity_mps: state.sensor_velocity_mps,
            sensor_yaw_rate_rps: state.sensor_yaw_rate_rps,
            human_velocity_mps: &state.human_velocity_mps,
            point_velocity_mps: &self.scratch.point_velocity,
        };
        composite(&params, &self.scratch.human_hits, &self.scratch.humans, &self.scratch.bg_hits.range_m, out);
        out.time_s = state.t_s;
        out.world_from_sensor = state.world_from_sensor.transpose().to_cols_array_2d();
        out.sensor_velocity_mps = state.sensor_velocity_mps.to_array();
        out.sensor_yaw_rate_rps = state.sensor_yaw_rate_rps;
        out.humans.clone_from(&state.humans);
    }

    /// Everything of one frame: pose, render, resample, composite.
    pub fn frame(&mut self, plan: &SequencePlan, k: usize, out: &mut FrameOutput) -> Result<FrameState> {
        let t0 = std::time::Instant::now();
        let state = self.frame_state(plan, k);
        self.pose_frame(plan, &state)?;
        let t1 = std::time::Instant::now();
        self.render_posed()?;
        let t2 = std::time::Instant::now();
        if self.cfg.output.velocity == crate::config::VelocityModel::Limb && self.outputs().velocity {
            self.point_velocities(plan, &state);
        }
        self.post(&state, out);
        self.timings.pose_s += (t1 - t0).as_secs_f64();
        self.timings.post_s += t2.elapsed().as_secs_f64();
        self.timings.frames += 1;
        Ok(state)
    }

    /// One frame, and its posed people as PLY with `--export-geometry`.
    fn frame_and_export(&mut self, plan: &SequencePlan, index: usize, k: usize, out: &mut FrameOutput) -> Result<()> {
        self.frame(plan, k, out)?;
        if let Some(dir) = &self.export_geometry {
            let path = dir.join(crate::output::sequence_stem(index)).join(format!("frame_{k:06}.ply"));
            crate::output::ply::write_humans_ply(&path, &self.scratch.humans)?;
        }
        Ok(())
    }

    /// Metadata of sequence `index`.
    pub fn meta(&self, index: usize, plan: &SequencePlan) -> SequenceMeta {
        SequenceMeta {
            index,
            seed: self.cfg.seed,
            sensor: self.sensor.clone(),
            config_toml: self.cfg.to_recorded_toml(),
            rigid_velocity: self.cfg.output.velocity != crate::config::VelocityModel::Paper,
            frames: plan.times_s.len(),
            humans: plan
                .humans
                .iter()
                .map(|h| {
                    let m = &self.models[h.model];
                    HumanMeta { height_m: m.nominal_height_m(), weight_kg: m.weight_kg.unwrap_or(0.0), model: m.name.clone() }
                })
                .collect(),
            outputs: self.outputs(),
            provenance: self.provenance(plan),
        }
    }

    /// Where the background and the people of a plan come from (see [`SequenceMeta`]).
    pub fn provenance(&self, plan: &SequencePlan) -> Vec<(String, String)> {
        let name = |p: &Path| p.file_name().map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into_owned());
        let bg = &self.cfg.scene.background;
        let backend = if self.backend.choice() == crate::config::BackendChoice::Raycast { "raycast" } else { "raster" };
        let mut v = vec![("backend".to_string(), backend.to_string()), (
            "background".to_string(),
            match (&self.recording, &self.environment) {
                (Some(_), _) => format!("recording {}", name(bg)),
                (None, Some(_)) => format!("environment {}", name(bg)),
                _ => "none".into(),
            },
        )];
        if let (Some(rec), Some(s)) = (&self.recording, plan.recording_start) {
            v.push(("recording_first_frame".into(), s.to_string()));
            v.push(("recording_frames".into(), rec.len().to_string()));
            v.push(("recording".into(), rec.description.clone()));
        }
        if !self.cfg.scene.poses.as_os_str().is_empty() {
            v.push(("poses".into(), name(&self.cfg.scene.poses)));
        }
        v.push(("floor_z_m".into(), format!("{:.4}", plan.floor_z_m)));
        if !self.cfg.humans.tracks.as_os_str().is_empty() {
            v.push(("tracks".into(), name(&self.cfg.humans.tracks)));
            let mut ids = Vec::new();
            for h in &plan.humans {
                if let crate::scene::sequence::HumanPath::Track(t) = &h.trajectory {
                    ids.push(t.track.id.to_string());
                    if ids.len() == 1 {
                        v.push(("tracks_window_start_s".into(), format!("{}", t.t0_s)));
                    }
                }
            }
            v.push(("track_ids".into(), ids.join(",")));
        }
        v
    }

    /// Generates and writes sequence `index` into `out_dir`; returns the files written.
    /// `on_frame` runs after each frame; an error from it (a stop request) ends the sequence
    /// like any failure: nothing of this sequence is left behind.
    pub fn write_sequence(&mut self, index: usize, out_dir: &Path, mut on_frame: impl FnMut() -> Result<()>) -> Result<WrittenSequence> {
        let t0 = std::time::Instant::now();
        let plan = self.plan(index)?;
        self.timings.plan_s += t0.elapsed().as_secs_f64();
        let meta = self.meta(index, &plan);
        let (people, frames) = (meta.humans.len(), meta.frames);
        let opts = WriterOptions {
            png: self.cfg.png,
            compression: match self.cfg.output.compression {
                CompressionChoice::None => Compression::None,
                CompressionChoice::Deflate => Compression::Deflate(1),
            },
            h5: self.cfg.output.formats.contains(&Format::H5),
            semantickitti: self.cfg.output.formats.contains(&Format::Semantickitti),
            mcap: self.cfg.output.formats.contains(&Format::Mcap),
        };
        let mut writer = SequenceWriter::create(out_dir, &meta, &opts)?;
        // `debug.overlap_write = false` writes each frame on this thread (to measure the
        // overlap).
        if !self.cfg.debug.overlap_write {
            let mut out = FrameOutput::default();
            for k in 0..plan.times_s.len() {
                self.frame_and_export(&plan, index, k, &mut out)?;
                let t0 = std::time::Instant::now();
                writer.write_frame(&out)?;
                self.timings.write_s += t0.elapsed().as_secs_f64();
                on_frame()?;
            }
            let done = writer.finish()?;
            return Ok(WrittenSequence { files: done.files, class_points: done.class_points, people, frames });
        }
        // The writer runs on its own thread, one frame behind: frame k+1 is posed, rendered
        // and composited while frame k is compressed and written. Two frame buffers travel
        // between the threads (no per-frame allocation). The writer finishes the files only
        // on `Done`; if this thread fails first, the channel closes, the writer is dropped
        // and removes its temporary files.
        enum Msg {
            Frame(FrameOutput),
            Done,
        }
        let (to_writer, from_main) = std::sync::mpsc::sync_channel::<Msg>(1);
        let (to_main, spare) = std::sync::mpsc::channel::<FrameOutput>();
        to_main.send(FrameOutput::default()).ok();
        to_main.send(FrameOutput::default()).ok();
        std::thread::scope(|scope| {
            let write = scope.spawn(move || -> Result<(Option<crate::output::Finished>, f64)> {
                let mut write_s = 0.0;
                let mut writer = writer;
                for msg in from_main {
                    match msg {
                        Msg::Frame(out) => {
                            let t0 = std::time::Instant::now();
                            writer.write_frame(&out)?;
                            write_s += t0.elapsed().as_secs_f64();
                            let _ = to_main.send(out);
                        }
                        Msg::Done => return writer.finish().map(|f| (Some(f), write_s)),
                    }
                }
                Ok((None, write_s))
            });
            let computed = (|| -> Result<()> {
                for k in 0..plan.times_s.len() {
                    // A buffer comes back once the writer is done with it; none means the
                    // writer stopped on an error, reported below.
                    let Ok(mut out) = spare.recv() else { return Ok(()) };
                    self.frame_and_export(&plan, index, k, &mut out)?;
                    if to_writer.send(Msg::Frame(out)).is_err() {
                        return Ok(());
                    }
                    on_frame()?;
                }
                let _ = to_writer.send(Msg::Done);
                Ok(())
            })();
            drop(to_writer);
            let written = write.join().map_err(|_| Error::Internal("the writer thread panicked".into()))?;
            computed?;
            let (written, write_s) = written?;
            self.timings.write_s += write_s;
            let done = written.ok_or_else(|| Error::Internal("the writer stopped before the last frame".into()))?;
            Ok(WrittenSequence { files: done.files, class_points: done.class_points, people, frames })
        })
    }
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
