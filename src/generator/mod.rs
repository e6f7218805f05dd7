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
use crate::config::{BackendChoice, CompressionChoice, Config, Format};
use crate::error::{Error, Result};
use crate::geometry::{Adjacency, FrameGeometry};
use crate::human::{model_files, GaitStyle, HumanModel, MODEL_TO_BODY};
use crate::output::{Compression, FrameOutput, HumanMeta, HumanState, OutputSet, SequenceMeta, SequenceWriter, WriterOptions};
use crate::post::{derive, select, ColumnMotion, PostParams};
use crate::sensor_model::shutter::Sweep;
use crate::sensor_model::{FootprintScene, SequenceDraws, Surface};
use crate::scene::{Environment, WalkableGrid, WALKABLE_CELL_M};
use crate::sensor::Sensor;
use crate::scene::sequence::{sample_plan, PlanInputs, PoseTrack, SequencePlan};
use crate::input::tracks::{read_tracks, Track, TrackOptions};
use glam::{DMat3, DMat4, DVec3, Mat4};
use rand::SeedableRng;
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// One beam of [`Generator::reference_rolling_hits`]: (beam, nearest person's (range,
/// instance), environment's range or 0).
pub type ReferenceHit = (usize, Option<(f64, u16)>, f64);

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
    /// The configuration every output records (inputs by name and content digest).
    recorded_config: String,
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
    /// Per model, per level of detail, per triangle: its body region (`crate::sensor_model`).
    regions: Vec<Vec<Vec<u8>>>,
    /// Per environment mesh (as `env_meshes`): its reflectance.
    env_reflectance: Vec<f32>,
    /// Intensity units (`sensor_model.intensity_scale`, resolved).
    intensity_scale: f64,
    /// Per row its beams' elevation, per column its azimuth, radians (the footprints' frame).
    elevation_rad: Vec<f64>,
    azimuth_rad: Vec<f64>,
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
    /// Its intensity per beam, in the recording's units (empty when it has none).
    recorded_intensity: Vec<f32>,
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
    /// The sweep of the frame posed last, and per drawn person (as `layout`) the span of
    /// times its vertices were posed over: `(ta, tb, u_centre)` (rolling shutter).
    sweep: Option<Sweep>,
    spans: Vec<(f64, f64, f64)>,
    /// Rolling shutter, per drawn person: its placements at the later key times of its span
    /// (the first is in `placements`).
    placements_b: Vec<Vec<(Mat4, f32, GaitStyle)>>,
    /// The sensor's motion per column of the frame posed last (one entry without rolling
    /// shutter), and each person's world velocity and time at the columns that see it.
    column_motion: Vec<ColumnMotion>,
    person_velocity: Vec<DVec3>,
    person_time: Vec<f64>,
    /// Rolling shutter with a moving sensor and an environment: `world_from_sensor` per
    /// column (the background's hits are refined against it); empty otherwise.
    column_pose: Vec<DMat4>,
    /// The sensor model's per-sequence draws, for sequence `draws_for`.
    draws: SequenceDraws,
    draws_for: Option<(usize, usize)>,
    /// The clean surface per beam and the model's result.
    clean: Vec<Option<Surface>>,
    beams_out: Vec<crate::sensor_model::BeamOut>,
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
        // The people load in parallel (~13 ms of CPU each, the bundled 15 in ~200 ms on one
        // core), and a backend that needs the Vulkan device opens it meanwhile on its own
        // thread. The first failing file in the list's order is the one reported.
        let files = if cfg.humans.count[1] > 0 { model_files(&cfg.humans.models)? } else { Vec::new() };
        let opens_device = cfg.render.backend != BackendChoice::Raycast;
        let models = std::thread::scope(|scope| {
            let opening = opens_device.then(|| scope.spawn(|| gpu.open_early()));
            let loaded: Vec<Result<HumanModel>> = files.par_iter().map(|f| HumanModel::load(f, needs_animation)).collect();
            let opened = opening.map(|h| h.join());
            let models = loaded.into_iter().collect::<Result<Vec<_>>>()?;
            match opened {
                Some(Err(_)) => Err(Error::Internal("opening the Vulkan device panicked".into())),
                _ => Ok(models),
            }
        })?;
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
            if let Some(w) = &rec.sweep_warning {
                eprintln!("warning: {}: {w}", bg.display());
            }
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
        let regions = models.iter().map(body_regions).collect::<Result<Vec<_>>>()?;
        let env_reflectance = environment.as_ref().map_or_else(Vec::new, |env| {
            env.meshes.iter().filter(|m| !m.indices.is_empty()).map(|m| m.reflectance).collect()
        });
        let pcap = bg.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("pcap"));
        let intensity_scale = cfg.sensor_model.intensity_scale.unwrap_or(if recording.is_some() && pcap { 100.0 } else { 1.0 });
        let elevation_rad = sensor.elevation_deg.iter().map(|e| e.to_radians()).collect();
        let azimuth_rad = (0..sensor.columns).map(|c| sensor.azimuth_rad(c)).collect();
        // Every input was read above, so each one is there to be digested.
        let recorded_config = cfg.to_recorded_toml_with_inputs()?;
        Ok(Generator {
            dirs: sensor.beam_dirs(),
            recorded_config,
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
            regions,
            env_reflectance,
            intensity_scale,
            elevation_rad,
            azimuth_rad,
        })
    }

    /// The checked configuration.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// The configuration every output records: [`Config::to_recorded_toml_with_inputs`].
    pub fn recorded_config(&self) -> &str {
        &self.recorded_config
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
        OutputSet {
            xyz: self.cfg.output.xyz,
            velocity: self.cfg.output.velocity_field,
            background: self.cfg.output.background,
            clean: self.cfg.sensor_model.enabled,
        }
    }

    /// Sensor and people at frame `k` of a plan.
    pub fn frame_state(&self, plan: &SequencePlan, k: usize) -> FrameState {
        self.frame_state_at(plan, k, plan.times_s[k])
    }

    /// Sensor and people of frame `k` of a plan, as they are at time `t` (s).
    pub fn frame_state_at(&self, plan: &SequencePlan, k: usize, t: f64) -> FrameState {
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

    /// Poses the background and the people of a frame into the sensor frame (f64 -> f32),
    /// skipping people no beam can reach. Fills `scratch.background` and `scratch.humans`, and
    /// `scratch.recorded` with the recorded background frame, if any. With the rolling
    /// shutter on, every vertex is placed at the time its column is fired
    /// ([`crate::sensor_model::shutter`]).
    pub fn pose_frame(&mut self, plan: &SequencePlan, state: &FrameState) -> Result<()> {
        self.pose_frame_at(plan, state, self.cfg.render.lod_max_error_mrad, self.rolls())
    }

    /// [`Generator::pose_frame`] with every person at full detail (the reference of `bench`).
    pub fn pose_frame_full_detail(&mut self, plan: &SequencePlan, state: &FrameState) -> Result<()> {
        self.pose_frame_at(plan, state, 0.0, self.rolls())
    }

    /// Whether frames are taken column by column over the sweep (`sensor_model`).
    pub fn rolls(&self) -> bool {
        self.cfg.sensor_model.enabled && self.cfg.sensor_model.rolling_shutter
    }

    /// The sweep of frame `k` of a plan starting at `t_s`: one revolution of the sensor, or
    /// under a recording its own: the capture's column times where it has them (a pcap,
    /// [`Recording::column_offsets`]), else uniform over the recording's frame step (its
    /// sensor turned once per frame).
    fn sweep(&self, plan: &SequencePlan, k: usize, t_s: f64, rolling: bool) -> Sweep {
        let w = self.sensor.columns;
        let own = match (&self.recording, plan.recording_start) {
            (Some(rec), Some(start)) if rolling => rec.column_offsets(start + k).filter(|o| o.len() == w + 1),
            _ => None,
        };
        if let Some(offsets) = own {
            return Sweep::recorded(t_s, offsets.iter().map(|o| t_s + o).collect());
        }
        let t = &plan.times_s;
        let period = match (&self.recording, t.len()) {
            (Some(_), n) if n >= 2 => {
                let step = if k + 1 < n { t[k + 1] - t[k] } else { t[n - 1] - t[n - 2] };
                if step > 0.0 && step.is_finite() { step } else { 1.0 / self.sensor.rate_hz }
            }
            _ => 1.0 / self.sensor.rate_hz,
        };
        Sweep::uniform(t_s, if rolling { period } else { 0.0 }, w)
    }

    fn pose_frame_at(&mut self, plan: &SequencePlan, state: &FrameState, lod_max_error_mrad: f64, rolling: bool) -> Result<()> {
        let sensor_from_world = state.world_from_sensor.inverse();
        let sweep = self.sweep(plan, state.frame, state.t_s, rolling);
        let s = &mut self.scratch;
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
        match (&self.recording, state.recorded_frame) {
            (Some(rec), Some(k)) => rec.frame(k, s.recorded.get_or_insert_with(Vec::new), &mut s.recorded_intensity)?,
            _ => {
                s.recorded = None;
                s.recorded_intensity.clear();
            }
        }
        s.background.clear();
        if let Some(env) = &self.environment {
            // A sensor that moves during the sweep sees each vertex from where it is when the
            // vertex's column is fired; a still one from one place.
            let end = plan.sensor.pose(sweep.time_at(sweep.columns as f64));
            let moves = rolling && end != state.world_from_sensor;
            s.column_pose.clear();
            if moves {
                sweep.place_static(&env.positions, |t| plan.sensor.pose(t).inverse(), &mut s.env_sensor);
                s.column_pose.extend((0..sweep.columns).map(|c| plan.sensor.pose(sweep.column_time(c))));
            } else {
                s.env_sensor.clear();
                s.env_sensor.extend(env.positions.iter().map(|p| sensor_from_world.transform_point3(*p).as_vec3().to_array()));
            }
            for m in &self.env_meshes {
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
            let model = &self.models[h.model];
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
            if !self.sensor.may_see_sphere(centre, r) {
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
        let models = &self.models;
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

    /// The rolling shutter's reference for frame `k` of a plan: for each of `columns`, the
    /// whole frame posed at that column's time (every vertex at one instant) and the column's
    /// beams cast exactly (watertight f64, nearest hit) through the people and the
    /// environment. Returns, per beam of those columns, `(beam, people, background)`: the
    /// nearest person's (range, instance) and the environment's range (0 = none). Slow by
    /// design: a pose per column.
    pub fn reference_rolling_hits(
        &mut self,
        plan: &SequencePlan,
        k: usize,
        columns: impl Iterator<Item = usize>,
    ) -> Result<Vec<ReferenceHit>> {
        let sweep = self.sweep(plan, k, plan.times_s[k], true);
        let w = self.sensor.columns;
        let mut out = Vec::new();
        let mut people = crate::backend::raster::clusters::MeshClusters::default();
        let mut background = crate::backend::raster::clusters::MeshClusters::default();
        let mut scratch = Vec::new();
        for c in columns {
            let state = self.frame_state_at(plan, k, sweep.column_time(c));
            self.pose_frame_at(plan, &state, self.cfg.render.lod_max_error_mrad, false)?;
            let s = &self.scratch;
            people.reset(&s.humans);
            background.reset(&s.background);
            for row in 0..self.sensor.rows() {
                let b = row * w + c;
                let dir = self.dirs[b];
                let h = people.cast(&s.humans, dir, &mut scratch).map(|(r, t)| (r, s.humans.mesh_of_triangle(t).instance as u16));
                let bg = background.cast(&s.background, dir, &mut scratch).map_or(0.0, |(r, _)| r);
                out.push((b, h, bg));
            }
        }
        Ok(out)
    }

    /// The people and background layers' hits of the frame cast last (see
    /// [`Generator::render_posed`]): per beam, the nearest person's (range, instance) and the
    /// background's range (0 = none).
    pub fn layer_hits(&self, b: usize) -> (Option<(f64, u16)>, f64) {
        let s = &self.scratch;
        let t = s.human_hits.triangle[b];
        let h = (t != crate::backend::NO_TRIANGLE).then(|| (s.human_hits.range_m[b] as f64, s.humans.mesh_of_triangle(t).instance as u16));
        (h, s.bg_hits.range_m[b] as f64)
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
        let t0 = std::time::Instant::now();
        self.refine_rolling_background();
        self.timings.background_s += t0.elapsed().as_secs_f64();
        Ok(())
    }

    /// Rolling shutter with a moving sensor: each placed environment vertex is exact at its own
    /// column's time, but a large triangle's interior is interpolated between vertices taken
    /// at different times (centimetres off across a wall). Each beam's hit is therefore
    /// recomputed in the world: the beam from the sensor's pose at its column's time, through
    /// the triangle the cast found and that triangle's one-ring (watertight f64, nearest).
    fn refine_rolling_background(&mut self) {
        let s = &mut self.scratch;
        let (Some(env), false) = (&self.environment, s.column_pose.is_empty()) else { return };
        let w = self.sensor.columns;
        let (background, poses, dirs, env_meshes) = (&s.background, &s.column_pose, &self.dirs, &self.env_meshes);
        s.bg_hits.range_m.par_iter_mut().zip(s.bg_hits.triangle.par_iter_mut()).enumerate().with_min_len(512).for_each(|(b, (r, t))| {
            if *t == crate::backend::NO_TRIANGLE {
                return;
            }
            let pose = poses[b % w];
            let origin = pose.w_axis.truncate();
            let dir = DMat3::from_mat4(pose) * dirs[b];
            let Some(ray) = crate::backend::triangle::RayPre::new(dir) else { return };
            let test = |cand: u32| -> Option<f64> {
                let (tri, cull) = world_triangle(background, &env.positions, env_meshes, cand, origin);
                crate::backend::triangle::intersect_pre(&ray, &tri, cull)
            };
            // The triangle the cast found holds the exact hit but near its edges; there, its
            // one-ring.
            let mut best = test(*t).map_or((f64::INFINITY, u32::MAX), |h| (h, *t));
            if best.1 == u32::MAX {
                for cand in background.neighbours(*t) {
                    if let Some(h) = test(cand) {
                        if crate::backend::triangle::better(h, cand, best.0, best.1) {
                            best = (h, cand);
                        }
                    }
                }
            }
            if best.1 != u32::MAX {
                (*r, *t) = (best.0 as f32, best.1);
            }
        });
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
                let model = &self.models[m];
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

    /// Sets the sequence the next frames belong to (the sensor model's per-sequence draws:
    /// laser biases, the people's reflectances). [`Generator::write_sequence`] calls it; a
    /// caller driving [`Generator::frame`] itself may (else sequence 0's draws are used).
    pub fn begin_sequence(&mut self, index: usize, plan: &SequencePlan) {
        self.draws_for(index, plan.humans.len());
    }

    /// The sensor model's draws for sequence `index` with `people` people, drawn unless held.
    fn draws_for(&mut self, index: usize, people: usize) {
        let key = (index, people);
        if self.scratch.draws_for != Some(key) {
            let m = &self.cfg.sensor_model;
            self.scratch.draws = SequenceDraws::draw(m, self.cfg.seed, index, self.sensor.rows(), people);
            self.scratch.draws_for = Some(key);
        }
    }

    fn post_params<'a>(&'a self, state: &'a FrameState) -> PostParams<'a> {
        let s = &self.scratch;
        PostParams {
            dirs: &self.dirs,
            columns: self.sensor.columns,
            min_range_m: self.sensor.min_range_m,
            max_range_m: self.sensor.max_range_m,
            keep_holes: self.cfg.render.keep_holes,
            velocity_model: self.cfg.output.velocity,
            outputs: self.outputs(),
            column_motion: &s.column_motion,
            human_velocity_mps: if s.person_velocity.len() == state.human_velocity_mps.len() { &s.person_velocity } else { &state.human_velocity_mps },
            point_velocity_mps: &s.point_velocity,
        }
    }

    /// Composites the rendered frame into `out` and applies the sensor model; with
    /// `velocity = "limb"` call [`Generator::point_velocities`] first.
    pub fn post(&mut self, state: &FrameState, out: &mut FrameOutput) {
        {
            let s = &self.scratch;
            select(&self.post_params(state), &s.human_hits, &s.humans, &s.bg_hits.range_m, out);
        }
        self.apply_sensor_model(state, out);
        {
            let s = &self.scratch;
            derive(&self.post_params(state), &s.human_hits, &s.humans, out);
        }
        let still = || Sweep::uniform(state.t_s, 0.0, self.sensor.columns);
        let sweep = self.scratch.sweep.as_ref().map_or_else(still, Sweep::clone);
        out.column_time_s.clear();
        out.column_time_s.extend((0..self.sensor.columns).map(|c| sweep.column_time(c)));
        out.time_s = state.t_s;
        out.world_from_sensor = state.world_from_sensor.transpose().to_cols_array_2d();
        out.sensor_velocity_mps = state.sensor_velocity_mps.to_array();
        out.sensor_yaw_rate_rps = state.sensor_yaw_rate_rps;
        out.humans.clone_from(&state.humans);
    }

    /// The clean surface per beam of the composited `out` (its reflectance and incidence),
    /// then the sensor model: `out`'s range, label and instance become the returned ones,
    /// `/clean/*` keeps the others, and `/intensity` is filled.
    fn apply_sensor_model(&mut self, state: &FrameState, out: &mut FrameOutput) {
        // A caller that never said which sequence this is gets sequence 0's draws.
        let index = self.scratch.draws_for.map_or(0, |k| k.0);
        self.draws_for(index, state.humans.len());
        let s = &mut self.scratch;
        let scene = SceneSurfaces {
            humans: &s.humans,
            human_hits: &s.human_hits,
            background: &s.background,
            bg_hits: &s.bg_hits,
            recorded: s.recorded.as_deref(),
            recorded_intensity: &s.recorded_intensity,
            intensity_scale: self.intensity_scale,
            columns: self.sensor.columns,
            layout: &s.layout,
            regions: &self.regions,
            env_reflectance: &self.env_reflectance,
            reflectance: &s.draws.reflectance,
            dirs: &self.dirs,
            env_world: match &self.environment {
                Some(env) if !s.column_pose.is_empty() => {
                    Some(EnvWorld { positions: &env.positions, meshes: &self.env_meshes, column_pose: &s.column_pose })
                }
                _ => None,
            },
        };
        let n = self.dirs.len();
        // In parallel: each beam's surface (its triangle's normal, region, reflectance) is
        // ~1 ms a frame on one core.
        (0..n).into_par_iter().with_min_len(1024).map(|b| scene.clean(b, out.range[b], out.instance[b])).collect_into_vec(&mut s.clean);
        let frame = crate::sensor_model::FrameIn {
            cfg: &self.cfg.sensor_model,
            dirs: &self.dirs,
            columns: self.sensor.columns,
            elevation_rad: &self.elevation_rad,
            azimuth_rad: &self.azimuth_rad,
            min_range_m: self.sensor.min_range_m,
            max_range_m: self.sensor.max_range_m,
            clean: &s.clean,
            draws: &s.draws,
            intensity_scale: self.intensity_scale,
            recorded_intensity: (s.recorded.is_some() && s.recorded_intensity.len() == n).then_some(s.recorded_intensity.as_slice()),
            seed: self.cfg.seed,
            sequence: s.draws_for.map_or(0, |k| k.0),
            frame: state.frame,
        };
        let mut beams = std::mem::take(&mut s.beams_out);
        crate::sensor_model::apply(&frame, &scene, &mut beams);
        if self.cfg.sensor_model.enabled {
            out.clean_range.clone_from(&out.range);
            out.clean_label.clone_from(&out.label);
            out.clean_instance.clone_from(&out.instance);
        } else {
            out.clean_range.clear();
            out.clean_label.clear();
            out.clean_instance.clear();
        }
        out.intensity.clear();
        out.intensity.extend(beams.iter().map(|b| b.intensity));
        for (b, o) in beams.iter().enumerate() {
            out.range[b] = o.range_m;
            out.instance[b] = o.instance;
            out.label[b] = (o.instance > 0) as u8;
        }
        s.beams_out = beams;
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
            config_toml: self.recorded_config.clone(),
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
        self.begin_sequence(index, &plan);
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
            kill: self.cfg.debug.kill.filter(|k| k.sequence == index).map(|k| k.at),
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
        // A frame's buffers are a few hundred bytes of Vec headers, moved once per frame.
        #[allow(clippy::large_enum_variant)]
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

/// The surfaces of a posed and cast frame, as the sensor model sees them.
struct SceneSurfaces<'a> {
    humans: &'a FrameGeometry,
    human_hits: &'a BeamHits,
    background: &'a FrameGeometry,
    bg_hits: &'a BeamHits,
    recorded: Option<&'a [f32]>,
    recorded_intensity: &'a [f32],
    intensity_scale: f64,
    columns: usize,
    layout: &'a [(u32, usize, usize)],
    regions: &'a [Vec<Vec<u8>>],
    env_reflectance: &'a [f32],
    reflectance: &'a [[f32; 4]],
    dirs: &'a [DVec3],
    /// Under a sensor that moves during the sweep: the environment in the world and each
    /// column's sensor pose, so footprint rays meet it exactly (as the beams themselves,
    /// `refine_rolling_background`); else the placed `background` is exact.
    env_world: Option<EnvWorld<'a>>,
}

struct EnvWorld<'a> {
    positions: &'a [DVec3],
    meshes: &'a [EnvDraw],
    column_pose: &'a [DMat4],
}

/// Background triangle `t` (global in `background`, whose meshes are `env_meshes`) in the
/// world, relative to `origin`, from the environment's f64 `positions`; and whether its back
/// face is culled.
fn world_triangle(background: &FrameGeometry, positions: &[DVec3], env_meshes: &[EnvDraw], t: u32, origin: DVec3) -> ([DVec3; 3], bool) {
    let k = background.mesh_index_of_triangle(t);
    let mesh = &background.meshes[k];
    let first = env_meshes[k].first_vertex as u32;
    let idx = &background.indices[3 * t as usize..3 * t as usize + 3];
    ([0, 1, 2].map(|c| positions[(first + idx[c] - mesh.first_vertex) as usize] - origin), !mesh.double_sided)
}

/// The nearest of `triangles` (triangle, corners in the sensor frame, back culled) along
/// `dir`, with the casters' watertight test and tie rule.
fn nearest_hit(triangles: &[(u32, [DVec3; 3], bool)], dir: DVec3) -> Option<(f64, u32)> {
    let ray = crate::backend::triangle::RayPre::new(dir)?;
    let mut best = (f64::INFINITY, u32::MAX);
    for &(t, ref tri, cull) in triangles {
        if let Some(h) = crate::backend::triangle::intersect_pre(&ray, tri, cull) {
            if crate::backend::triangle::better(h, t, best.0, best.1) {
                best = (h, t);
            }
        }
    }
    (best.1 != u32::MAX).then_some(best)
}

/// |cos| of the angle between `dir` and the normal of triangle `t` (1 for a degenerate one),
/// and the unit normal (zero for a degenerate one).
fn cos_incidence(geom: &FrameGeometry, t: u32, dir: DVec3) -> (f32, glam::Vec3) {
    let [a, b, c] = geom.triangle_f64(t);
    let n = (b - a).cross(c - a);
    let len = n.length();
    if len > 0.0 && len.is_finite() { ((n.dot(dir).abs() / len) as f32, (n / len).as_vec3()) } else { (1.0, glam::Vec3::ZERO) }
}

/// Reflectance of a recorded return whose intensity is unknown (for the footprint's power).
const RECORDED_REFLECTANCE: f32 = 0.3;

impl SceneSurfaces<'_> {
    fn human_surface(&self, t: u32, range_m: f64, dir: DVec3) -> Surface {
        let k = self.humans.mesh_index_of_triangle(t);
        let mesh = &self.humans.meshes[k];
        let (instance, m, lod) = self.layout[k];
        let region = self.regions[m][lod].get((t - mesh.first_triangle) as usize).copied().unwrap_or(crate::sensor_model::UPPER);
        let reflectance = self.reflectance.get(instance as usize - 1).map_or(0.3, |r| r[region as usize]);
        let (cos_incidence, normal) = cos_incidence(self.humans, t, dir);
        Surface { range_m, instance: instance as u16, reflectance, cos_incidence, rendered: true, normal }
    }

    fn background_surface(&self, b: usize, t: u32, range_m: f64, dir: DVec3) -> Surface {
        if self.recorded.is_some() {
            // The recording's intensity (already with its incidence) in reflectance units, for
            // the footprint's power; unknown: a typical reflectance.
            let reflectance = match self.recorded_intensity.get(b) {
                Some(&i) if self.recorded_intensity.len() == self.dirs.len() => (i as f64 / self.intensity_scale).clamp(0.0, 1.0) as f32,
                _ => RECORDED_REFLECTANCE,
            };
            return Surface { range_m, instance: 0, reflectance, cos_incidence: 1.0, rendered: false, normal: glam::Vec3::ZERO };
        }
        let (reflectance, (cos, normal)) = if t == crate::backend::NO_TRIANGLE || t >= self.background.triangle_count() {
            (0.5, (1.0, glam::Vec3::ZERO))
        } else {
            let k = self.background.mesh_index_of_triangle(t);
            (self.env_reflectance.get(k).copied().unwrap_or(0.5), cos_incidence(self.background, t, dir))
        };
        Surface { range_m, instance: 0, reflectance, cos_incidence: cos, rendered: true, normal }
    }

    /// The composited beam `b` (range, instance) as a surface.
    fn clean(&self, b: usize, range_m: f32, instance: u16) -> Option<Surface> {
        if range_m <= 0.0 {
            return None;
        }
        let dir = self.dirs[b];
        Some(if instance > 0 {
            self.human_surface(self.human_hits.triangle[b], range_m as f64, dir)
        } else {
            self.background_surface(b, self.bg_hits.triangle.get(b).copied().unwrap_or(crate::backend::NO_TRIANGLE), range_m as f64, dir)
        })
    }
}

impl SceneSurfaces<'_> {
    /// Environment triangle `t` in the sensor frame of column `col`, and whether its back face
    /// is culled: under a sensor that moves during the sweep from the world at the column's
    /// pose (the placed triangles are interpolated between their vertices' times, centimetres
    /// off across a wall), else as placed.
    fn env_triangle(&self, t: u32, col: usize) -> ([DVec3; 3], bool) {
        match &self.env_world {
            Some(e) => {
                let pose = e.column_pose[col];
                let (tri, cull) = world_triangle(self.background, e.positions, e.meshes, t, pose.w_axis.truncate());
                let rot_t = DMat3::from_mat4(pose).transpose();
                (tri.map(|p| rot_t * p), cull)
            }
            None => (self.background.triangle_f64(t), !self.background.mesh_of_triangle(t).double_sided),
        }
    }

    /// The nearest range beam `b` sees over both layers (infinite: nothing).
    fn nearest_range(&self, b: usize) -> f64 {
        let human = match self.human_hits.triangle.get(b) {
            Some(&t) if t != crate::backend::NO_TRIANGLE => self.human_hits.range_m[b] as f64,
            _ => f64::INFINITY,
        };
        let background = match self.recorded {
            Some(r) => r[b] as f64,
            None => self.bg_hits.range_m.get(b).copied().unwrap_or(0.0) as f64,
        };
        human.min(if background > 0.0 { background } else { f64::INFINITY })
    }

    /// The common case of a footprint, cheaply: when every neighbour across the silhouette
    /// sees something farther (or nothing) and every footprint ray meets the rendered triangle
    /// the beam itself meets or one of its one-ring, the footprint lies on that surface
    /// (nothing nearer can cover part of it, but a feature thinner than the beam spacing, as
    /// for the candidates of `cast_footprint`). Fills `out[1..]` and returns true then.
    fn footprint_on_own_surface(&self, b: usize, across: &[usize], dirs: &[DVec3; crate::sensor_model::FOOTPRINT_RAYS], out: &mut [Option<Surface>; crate::sensor_model::FOOTPRINT_RAYS]) -> bool {
        let Some(own) = out[0].filter(|s| s.rendered) else { return false };
        if across.iter().any(|&nb| self.nearest_range(nb) <= own.range_m) {
            return false;
        }
        let person = own.instance > 0;
        let (geom, t) = if person {
            (self.humans, self.human_hits.triangle[b])
        } else {
            (self.background, self.bg_hits.triangle.get(b).copied().unwrap_or(crate::backend::NO_TRIANGLE))
        };
        if t == crate::backend::NO_TRIANGLE || t >= geom.triangle_count() {
            return false;
        }
        let col = b % self.columns;
        let surface: Vec<(u32, [DVec3; 3], bool)> = std::iter::once(t)
            .chain(geom.neighbours(t))
            .map(|c| {
                let (tri, cull) = if person { (geom.triangle_f64(c), !geom.mesh_of_triangle(c).double_sided) } else { self.env_triangle(c, col) };
                (c, tri, cull)
            })
            .collect();
        let mut hits = [(0.0, 0u32); crate::sensor_model::FOOTPRINT_RAYS];
        for (hit, &dir) in hits.iter_mut().zip(dirs).skip(1) {
            let Some(best) = nearest_hit(&surface, dir) else { return false };
            *hit = best;
        }
        for ((o, &dir), &(h, c)) in out.iter_mut().zip(dirs).zip(&hits).skip(1) {
            *o = Some(if person { self.human_surface(c, h, dir) } else { self.background_surface(b, c, h, dir) });
        }
        true
    }

    /// The background behind the people along `dir`, near beam `b`: the plane of the
    /// background triangle beam `b` meets, through its exact hit (its footprint is millimetres
    /// across; under a moving sensor the triangle's normal from the world, at the column's
    /// pose), or its recorded return. None where the plane lies behind the ray.
    fn background_near(&self, b: usize, dir: DVec3) -> Option<(f64, u32)> {
        if let Some(r) = self.recorded {
            return (r[b] > 0.0).then(|| (r[b] as f64, crate::backend::NO_TRIANGLE));
        }
        let t = self.bg_hits.triangle.get(b).copied().unwrap_or(crate::backend::NO_TRIANGLE);
        let r = self.bg_hits.range_m.get(b).copied().unwrap_or(0.0) as f64;
        if t == crate::backend::NO_TRIANGLE || t >= self.background.triangle_count() || r <= 0.0 {
            return None;
        }
        let n = match &self.env_world {
            Some(_) => {
                let [p, q, u] = self.env_triangle(t, b % self.columns).0;
                (q - p).cross(u - p).normalize_or_zero()
            }
            None => cos_incidence(self.background, t, self.dirs[b]).1.as_dvec3(),
        };
        let denom = n.dot(dir);
        if n == DVec3::ZERO || denom.abs() <= 1e-12 {
            return Some((r, t));
        }
        let along = n.dot(self.dirs[b] * r) / denom;
        (along > 0.0).then_some((along, t))
    }
}

/// The footprint's surfaces are searched among the triangles the beam and its grid neighbours
/// across the silhouette hit, and those triangles' one-rings (watertight test, as the
/// casters): the footprint (a few millimetres to centimetres across) lies between those beams,
/// so its surfaces are there but for a limb, a post or a table's edge thinner than the beam
/// spacing that no neighbour hits. Where the environment is continuous around the beam (the
/// beam and its neighbours meet one triangle and its one-ring) or is a recording, a ray's
/// background is the plane the beam itself meets ([`SceneSurfaces::background_near`]); else
/// only the candidates count, and a ray that meets none of them meets nothing (past a wall's
/// top, say).
impl FootprintScene for SceneSurfaces<'_> {
    fn cast_footprint(&self, b: usize, across: &[usize], dirs: &[DVec3; crate::sensor_model::FOOTPRINT_RAYS], out: &mut [Option<Surface>; crate::sensor_model::FOOTPRINT_RAYS]) {
        let col = b % self.columns;
        if self.footprint_on_own_surface(b, across, dirs, out) {
            return;
        }
        // The beam and its neighbours across the silhouette.
        let mut beams = [b; 5];
        beams[1..1 + across.len().min(4)].copy_from_slice(&across[..across.len().min(4)]);
        // The pyramid through the origin that holds every footprint ray (widened by 1 %): a
        // triangle with all three corners outside one of its faces meets none of the rays.
        let d = dirs[0];
        let e_az = DVec3::new(-d.y, d.x, 0.0).normalize_or_zero();
        let e_el = d.cross(e_az);
        let (mut hx, mut hy) = (0.0f64, 0.0f64);
        for r in &dirs[1..] {
            let along = r.dot(d);
            hx = hx.max(r.dot(e_az).abs() / along);
            hy = hy.max(r.dot(e_el).abs() / along);
        }
        let (hx, hy) = (1.01 * hx + 1e-9, 1.01 * hy + 1e-9);
        let outside = |tri: &[DVec3; 3]| {
            // Per corner: which faces it lies beyond (bits), ANDed over the corners.
            let beyond = |p: DVec3| -> u8 {
                let (a, x, y) = (p.dot(d), p.dot(e_az), p.dot(e_el));
                (a <= 0.0) as u8 | ((x > hx * a) as u8) << 1 | ((x < -hx * a) as u8) << 2 | ((y > hy * a) as u8) << 3 | ((y < -hy * a) as u8) << 4
            };
            beyond(tri[0]) & beyond(tri[1]) & beyond(tri[2]) != 0
        };
        // The candidates of one layer: the triangles the beams hit and their one-rings, those
        // the pyramid may hold, each as `corners` gives it in the sensor frame.
        let candidates = |geom: &FrameGeometry, hits: &BeamHits, corners: &dyn Fn(u32) -> [DVec3; 3]| -> Vec<(u32, [DVec3; 3], bool)> {
            let mut ts: Vec<u32> = Vec::with_capacity(64);
            for &nb in &beams {
                let t = hits.triangle.get(nb).copied().unwrap_or(crate::backend::NO_TRIANGLE);
                if t != crate::backend::NO_TRIANGLE && t < geom.triangle_count() {
                    ts.push(t);
                    ts.extend(geom.neighbours(t));
                }
            }
            ts.sort_unstable();
            ts.dedup();
            ts.iter()
                .map(|&t| (t, corners(t)))
                .filter(|(_, tri)| !outside(tri))
                .map(|(t, tri)| (t, tri, !geom.mesh_of_triangle(t).double_sided))
                .collect()
        };
        let people = candidates(self.humans, self.human_hits, &|t| self.humans.triangle_f64(t));
        // A rendered environment's candidates. Under a moving sensor they are taken from the
        // world into the sensor frame of the beam's column (the placed triangles are
        // interpolated between their vertices' times, centimetres off across a wall).
        // Where the beam and its neighbours meet one triangle and its one-ring, the surface is
        // continuous there and the beam's own plane holds the footprint.
        let bg_triangle = |nb: usize| self.bg_hits.triangle.get(nb).copied().unwrap_or(crate::backend::NO_TRIANGLE);
        let own = bg_triangle(b);
        let continuous = own != crate::backend::NO_TRIANGLE
            && own < self.background.triangle_count()
            && beams.iter().all(|&nb| {
                let t = bg_triangle(nb);
                t == own || self.background.neighbours(own).any(|n| n == t)
            });
        let searched = self.recorded.is_none() && !continuous;
        let env = if searched { candidates(self.background, self.bg_hits, &|t| self.env_triangle(t, col).0) } else { Vec::new() };
        for (o, &dir) in out.iter_mut().zip(dirs).skip(1) {
            let human = nearest_hit(&people, dir);
            let background = if searched { nearest_hit(&env, dir) } else { self.background_near(b, dir) };
            *o = match (human, background) {
                (Some((h, t)), bg) if bg.is_none_or(|(r, _)| h < r) => Some(self.human_surface(t, h, dir)),
                (_, Some((r, t))) => Some(self.background_surface(b, t, r, dir)),
                _ => None,
            };
        }
    }
}

/// Per level of detail, per triangle: the body region of a model's triangles (the region of
/// the joint that weighs most on the majority of its corners), from the skin's joint names.
fn body_regions(model: &HumanModel) -> Result<Vec<Vec<u8>>> {
    let names: Vec<String> = if model.lods.iter().all(|l| l.joints.is_empty()) {
        Vec::new()
    } else {
        let doc = gltf::Gltf::open(&model.path).map_err(|e| Error::input(model.path.display(), e))?;
        doc.skins().next().map_or_else(Vec::new, |s| s.joints().map(|n| n.name().unwrap_or("").to_string()).collect())
    };
    let joint_region: Vec<u8> = names.iter().map(|n| crate::sensor_model::region_of_joint(n)).collect();
    Ok(model
        .lods
        .iter()
        .map(|l| {
            let vertex = |i: u32| -> u8 {
                let i = i as usize;
                let (Some(j), Some(w)) = (l.joints.get(i), l.weights.get(i)) else { return crate::sensor_model::UPPER };
                let k = (0..4).max_by(|&a, &b| w[a].total_cmp(&w[b])).unwrap_or(0);
                joint_region.get(j[k] as usize).copied().unwrap_or(crate::sensor_model::UPPER)
            };
            l.indices
                .chunks_exact(3)
                .map(|t| {
                    let (a, b, c) = (vertex(t[0]), vertex(t[1]), vertex(t[2]));
                    if b == c { b } else { a }
                })
                .collect()
        })
        .collect())
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
