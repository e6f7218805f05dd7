//! The generator: loads a run's inputs once ([`RunInputs`]) and runs the stages for every
//! frame of every sequence: sample the sequence's plan (`scene`), pose the frame
//! ([`crate::pose`]), cast the beams into the background and the people (`backend`),
//! composite and label them (`post`), apply the sensor model (`sensor_model`), and hand the
//! frame to the sequence's writer (`output`), which writes while the next frame is computed.

mod checks;
mod inputs;
mod meta;
mod model;
mod timings;
mod world;

pub use crate::pose::FrameState;
pub use checks::{Posed, ReferenceHit};
pub use inputs::RunInputs;
pub use timings::StageTimes;

use crate::backend::{self, Backend, BeamHits, Gpu, Layer};
use crate::config::{CompressionChoice, Config, Format};
use crate::error::Result;
use crate::human::HumanModel;
use crate::output::{write_frames, Compression, FrameOutput, OutputSet, SequenceWriter, WriterOptions};
use crate::pose::PoseStage;
use crate::post::{derive, select, PostParams};
use crate::scene::sequence::{sample_plan, PlanInputs, PoseTrack, SequencePlan};
use crate::scene::world::World;
use std::sync::Arc;
use crate::sensor::Sensor;
use crate::sensor_model::shutter::Sweep;
use crate::sensor_model::surfaces::{refine_rolling_background, EnvWorld};
use crate::sensor_model::SequenceDraws;
use glam::DVec3;
use rand::SeedableRng;
use std::path::{Path, PathBuf};

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
    inputs: RunInputs,
    /// The nearest surface per beam: raster or ray cast (`render.backend`, `auto` resolved).
    backend: Box<dyn Backend>,
    /// The frame posed last (the pose stage's buffers).
    posed: PoseStage,
    scratch: Scratch,
    /// Write each frame's posed people as PLY under this folder (`--export-geometry`).
    export_geometry: Option<PathBuf>,
    /// Seconds spent per stage so far (see `--timings`).
    timings: StageTimes,
    /// The built-in world the environment holds now (see [`Generator::enter_world`]).
    world: Option<Arc<World>>,
}

/// The later stages' per-frame buffers, reused (no per-frame allocation in steady state).
#[derive(Default)]
struct Scratch {
    bg_hits: BeamHits,
    human_hits: BeamHits,
    /// `limb` velocities: per beam, the world velocity of the human surface point it hits,
    /// sensor frame (see [`Generator::point_velocities`]).
    point_velocity: Vec<DVec3>,
    /// The sensor model's per-sequence draws, for sequence `draws_for`.
    draws: SequenceDraws,
    draws_for: Option<(usize, usize)>,
    /// The clean surface per beam and the model's result.
    clean: Vec<Option<crate::sensor_model::Surface>>,
    beams_out: Vec<crate::sensor_model::BeamOut>,
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
        let inputs = RunInputs::load(&cfg, gpu)?;
        let backend = backend::create(&cfg, &inputs.sensor, &inputs.models, gpu)?;
        // Every input was read above, so each one is there to be digested.
        let recorded_config = cfg.to_recorded_toml_with_inputs()?;
        Ok(Generator {
            recorded_config,
            cfg,
            inputs,
            backend,
            posed: PoseStage::default(),
            scratch: Scratch::default(),
            export_geometry: None,
            timings: StageTimes::default(),
            world: None,
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
        &self.inputs.sensor
    }

    /// The people's models, in the order plans index them.
    pub fn models(&self) -> &[HumanModel] {
        &self.inputs.models
    }

    /// The sensor's beam directions (row-major).
    pub fn beam_dirs(&self) -> &[DVec3] {
        &self.inputs.dirs
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
        let (sensor, start) = match &self.inputs.sensor_poses {
            Some((times, poses)) => {
                let starts = times.len() - frames + 1;
                let start = crate::scene::even_index(rand::RngExt::random::<f64>(&mut rng), starts);
                (Some(PoseTrack::from_poses(times, poses, start..start + frames)), Some(start))
            }
            None => (None, None),
        };
        let recorded_grid;
        let (grid, floor_z_m) = match (&self.inputs.recording, start) {
            (Some(rec), Some(s)) if self.cfg.humans.count[1] > 0 => {
                let (z, g) = crate::scene::recorded::walkable(rec, s..s + frames, self.cfg.scene.floor_z_m)?;
                recorded_grid = g;
                (Some(&recorded_grid), z)
            }
            _ => (self.inputs.grid.as_ref(), self.cfg.scene.floor_z_m.unwrap_or(0.0)),
        };
        let mut world = match self.inputs.world {
            Some(kind) => Some(World::build(kind, self.cfg.seed, index, &self.world_params())?),
            None => None,
        };
        let (grid, sensor_arc, places, doors, seats) = match &world {
            Some(w) => (Some(&w.grid), w.sensor, &w.places[..], &w.doors[..], &w.seats[..]),
            None => (grid, None, &[][..], &[][..], &[][..]),
        };
        let inputs = PlanInputs { rate_hz: self.inputs.sensor.rate_hz, grid, models: &self.inputs.models, tracks: &self.inputs.tracks, sensor, floor_z_m, sensor_arc, places, doors, seats, world: world.as_ref() };
        let mut plan = sample_plan(&mut rng, &self.cfg, &inputs)?;
        plan.recording_start = if self.inputs.recording.is_some() { start } else { None };
        plan.floor_z_m = floor_z_m;
        if let Some(w) = &mut world {
            self.add_world_movers(&mut plan, w);
        }
        plan.world = world.map(Arc::new);
        Ok(plan)
    }

    /// Which outputs are computed.
    pub fn outputs(&self) -> OutputSet {
        OutputSet {
            xyz: self.cfg.output.xyz,
            velocity: self.cfg.output.velocity_field,
            background: self.cfg.output.background,
            clean: self.cfg.sensor_model.enabled,
            class: self.cfg.output.class,
        }
    }

    /// Sensor and people at frame `k` of a plan.
    pub fn frame_state(&self, plan: &SequencePlan, k: usize) -> FrameState {
        self.frame_state_at(plan, k, plan.times_s[k])
    }

    /// Sensor and people of frame `k` of a plan, as they are at time `t` (s).
    pub fn frame_state_at(&self, plan: &SequencePlan, k: usize, t: f64) -> FrameState {
        crate::pose::frame_state_at(plan, k, t)
    }

    /// Poses the background and the people of a frame into the sensor frame (f64 -> f32),
    /// skipping people no beam can reach. See [`PoseStage::pose`]. With the rolling
    /// shutter on, every vertex is placed at the time its column is fired
    /// ([`crate::sensor_model::shutter`]).
    pub fn pose_frame(&mut self, plan: &SequencePlan, state: &FrameState) -> Result<()> {
        self.pose_frame_at(plan, state, self.cfg.render.lod_max_error_mrad, self.rolls())
    }

    /// Whether frames are taken column by column over the sweep (`sensor_model`).
    pub fn rolls(&self) -> bool {
        self.cfg.sensor_model.enabled && self.cfg.sensor_model.rolling_shutter
    }

    fn pose_frame_at(&mut self, plan: &SequencePlan, state: &FrameState, lod_max_error_mrad: f64, rolling: bool) -> Result<()> {
        self.enter_world(plan);
        let inputs = self.inputs.pose(self.backend.proxies());
        self.posed.pose(&inputs, plan, state, lod_max_error_mrad, rolling)
    }

    /// Finds the nearest surface per beam of the posed frame, layer by layer, into
    /// `scratch.bg_hits` / `scratch.human_hits` (a recorded background replaces the first).
    pub fn render_posed(&mut self) -> Result<()> {
        let (s, p) = (&mut self.scratch, &self.posed);
        let t = &mut self.timings;
        let people = Layer::People { people: &p.humans, proxies: &p.proxies };
        let seconds = self.backend.cast_frame(Layer::Background(&p.background), people, &mut s.bg_hits, &mut s.human_hits)?;
        t.bvh_s += seconds.build;
        t.background_s += seconds.background;
        t.humans_s += seconds.people;
        if let Some(r) = &p.recorded {
            s.bg_hits.range_m.clone_from(r);
        }
        let t0 = std::time::Instant::now();
        if let Some(env) = &self.inputs.environment {
            let world = EnvWorld { positions: p.env_positions(env), meshes: &self.inputs.env_meshes, column_pose: &p.column_pose };
            refine_rolling_background(&world, &p.background, &self.inputs.dirs, self.inputs.sensor.columns, &mut s.bg_hits);
        }
        self.timings.background_s += t0.elapsed().as_secs_f64();
        Ok(())
    }

    /// Per beam with a human hit of the frame cast last: the world velocity of the surface
    /// point it hits, in the sensor frame, which `post` reads for `velocity = "limb"` (see
    /// [`PoseStage::point_velocities`]).
    pub fn point_velocities(&mut self, plan: &SequencePlan, state: &FrameState) {
        let inputs = self.inputs.pose(None);
        self.posed.point_velocities(&inputs, plan, state, &self.scratch.human_hits, &mut self.scratch.point_velocity);
    }

    /// Sets the sequence the next frames belong to (the sensor model's per-sequence draws:
    /// laser biases, the people's reflectances). [`Generator::write_sequence`] calls it; a
    /// caller driving [`Generator::frame`] itself may (else sequence 0's draws are used).
    pub fn begin_sequence(&mut self, index: usize, plan: &SequencePlan) {
        self.draws_for(index, plan.humans.len());
    }

    fn post_params<'a>(&'a self, state: &'a FrameState) -> PostParams<'a> {
        let (s, p) = (&self.scratch, &self.posed);
        PostParams {
            dirs: &self.inputs.dirs,
            columns: self.inputs.sensor.columns,
            min_range_m: self.inputs.sensor.min_range_m,
            max_range_m: self.inputs.sensor.max_range_m,
            keep_holes: self.cfg.render.keep_holes,
            velocity_model: self.cfg.output.velocity,
            outputs: self.outputs(),
            column_motion: &p.column_motion,
            human_velocity_mps: if p.person_velocity.len() == state.human_velocity_mps.len() { &p.person_velocity } else { &state.human_velocity_mps },
            point_velocity_mps: &s.point_velocity,
        }
    }

    /// Composites the rendered frame into `out` and applies the sensor model; with
    /// `velocity = "limb"` call [`Generator::point_velocities`] first.
    pub fn post(&mut self, state: &FrameState, out: &mut FrameOutput) {
        {
            let s = &self.scratch;
            select(&self.post_params(state), &s.human_hits, &self.posed.humans, &s.bg_hits.range_m, out);
        }
        self.apply_sensor_model(state, out);
        crate::post::mark_not_scored(&self.posed.not_scored, out);
        {
            derive(&self.post_params(state), &self.scratch.human_hits, &self.posed.humans, out);
        }
        let still = || Sweep::uniform(state.t_s, 0.0, self.inputs.sensor.columns);
        let sweep = self.posed.sweep.as_ref().map_or_else(still, Sweep::clone);
        out.column_time_s.clear();
        out.column_time_s.extend((0..self.inputs.sensor.columns).map(|c| sweep.column_time(c)));
        out.time_s = state.t_s;
        out.world_from_sensor = state.world_from_sensor.transpose().to_cols_array_2d();
        out.sensor_velocity_mps = state.sensor_velocity_mps.to_array();
        out.sensor_yaw_rate_rps = state.sensor_yaw_rate_rps;
        out.humans.clone_from(&state.humans);
        out.movers.clear();
        if let Some(w) = &self.world {
            out.movers.extend(w.movers.iter().map(|m| crate::output::MoverState {
                position_m: m.position(state.t_s).to_array(),
                heading_rad: m.heading_rad(state.t_s) as f32,
                velocity_mps: m.velocity(state.t_s).as_vec3().to_array(),
                yaw_rate_rps: m.yaw_rate_rps(state.t_s) as f32,
            }));
        }
        self.movers(state.humans.len(), out);
        if self.cfg.output.class {
            self.classes(out);
        }
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
            crate::output::ply::write_humans_ply(&path, &self.posed.humans)?;
        }
        Ok(())
    }

    /// Generates and writes sequence `index` into `out_dir`; returns the files written.
    /// `on_frame` runs after each frame; an error from it (a stop request) ends the sequence
    /// like any failure: nothing of this sequence is left behind.
    pub fn write_sequence(&mut self, index: usize, out_dir: &Path, on_frame: impl FnMut() -> Result<()>) -> Result<WrittenSequence> {
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
        let writer = SequenceWriter::create(out_dir, &meta, &opts)?;
        let overlap = self.cfg.debug.overlap_write;
        let (done, write_s) =
            write_frames(writer, frames, overlap, |k, out| self.frame_and_export(&plan, index, k, out), on_frame)?;
        self.timings.write_s += write_s;
        Ok(WrittenSequence { files: done.files, class_points: done.class_points, people, frames })
    }
}
