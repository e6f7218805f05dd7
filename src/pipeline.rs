//! The generator: runs the stages of every frame of every sequence, in data-flow order:
//! sample the sequence -> pose people and background in the sensor frame (f64 -> f32) ->
//! rasterize (Vulkan) -> resample to the beam grid -> composite, label, velocity -> write.
//!
//! Each sequence draws from its own random stream (ChaCha8, stream = sequence index), so a
//! sequence's content depends only on the seed, the configuration and its index: never on
//! thread count, on which other sequences ran, or on the GPU.

use crate::config::{Backend, CompressionChoice, Config, Projection};
use crate::error::{Error, Result};
use crate::geometry::{Adjacency, FrameGeometry};
use crate::gpu::{Context, ContextOptions, DeviceChoice};
use crate::human::{HumanModel, MODEL_TO_BODY};
use crate::output::{Compression, FrameOutput, HumanMeta, HumanState, OutputSet, SequenceMeta, SequenceWriter, WriterOptions};
use crate::post::{composite, PostParams};
use crate::projection::{CubeFaces, Panorama};
use crate::raster::Renderer;
use crate::raycast::BvhCache;
use crate::resample::{resample, BeamHits, BeamLookup};
use crate::scene::{Environment, WalkableGrid};
use crate::sensor::Sensor;
use crate::sequence::{sample_plan, SequencePlan};
use glam::{DMat3, DMat4, DVec3, Mat4};
use rand::SeedableRng;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Cell size of the walkable-area grid, metres.
pub const WALKABLE_CELL_M: f64 = 0.1;

/// Bounding-sphere radius of a person as a fraction of height (arms and legs mid-swing).
const BODY_RADIUS_PER_HEIGHT: f64 = 0.75;

/// Everything loaded once for a run.
pub struct Generator {
    pub cfg: Config,
    pub sensor: Sensor,
    pub models: Vec<HumanModel>,
    pub environment: Option<Environment>,
    pub grid: Option<WalkableGrid>,
    pub cube: CubeFaces,
    pub lookup: BeamLookup,
    pub renderer: Renderer,
    pub scratch: Scratch,
    /// Per environment mesh: its vertex range in `environment.positions`, local indices and
    /// triangle one-rings (computed once).
    env_meshes: Vec<EnvDraw>,
    /// Write each frame's posed humans as PLY under this folder (`--export-geometry`).
    pub export_geometry: Option<PathBuf>,
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
pub struct Scratch {
    pub background: FrameGeometry,
    pub humans: FrameGeometry,
    pub bg_hits: BeamHits,
    pub human_hits: BeamHits,
    joints: Vec<Mat4>,
    skinned: Vec<[f32; 3]>,
    env_sensor: Vec<[f32; 3]>,
    /// Ray-cast backend: bottom-level BVHs kept across frames (refit to each pose), one
    /// cache for the background and one for the people.
    bvh_background: BvhCache,
    bvh_humans: BvhCache,
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
}

/// Lists model files: a folder gives its `.glb` / `.gltf` files in name order.
pub fn model_files(paths: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(p)
                .map_err(|e| Error::io(p, e))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| matches!(f.extension().and_then(|e| e.to_str()), Some("glb") | Some("gltf")))
                .collect();
            found.sort();
            if found.is_empty() {
                return Err(Error::input(p.display(), "folder holds no .glb or .gltf human"));
            }
            files.extend(found);
        } else if p.is_file() {
            files.push(p.clone());
        } else {
            return Err(Error::input(p.display(), "human model file or folder does not exist"));
        }
    }
    Ok(files)
}

/// Picks the Vulkan device from the config's `device` string.
pub fn device_choice(s: &str) -> DeviceChoice {
    match s {
        "" | "auto" => DeviceChoice::Auto,
        s => match s.parse::<usize>() {
            Ok(i) => DeviceChoice::Index(i),
            Err(_) => DeviceChoice::Name(s.to_string()),
        },
    }
}

impl Generator {
    /// Checks the configuration, loads sensor, people and environment, starts the GPU.
    pub fn new(cfg: Config, validation: bool) -> Result<Generator> {
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
        let (environment, grid) = if cfg.scene.environment.as_os_str().is_empty() {
            (None, None)
        } else {
            let env = Environment::load(&cfg.scene.environment)?;
            let grid = WalkableGrid::from_environment(&env, WALKABLE_CELL_M)?;
            if grid.free_fraction(cfg.humans.clearance_m) <= 0.0 {
                return Err(Error::input(cfg.scene.environment.display(), "environment has no walkable floor at z = 0"));
            }
            (Some(env), Some(grid))
        };
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
        // The cube faces also cull people no beam can reach (`pose_frame`), whatever the views.
        let cube = CubeFaces::new(&sensor, cfg.render.oversample);
        let ctx = Arc::new(Context::new(&ContextOptions { validation, device: device_choice(&cfg.device) })?);
        let (lookup, renderer) = match cfg.render.projection {
            Projection::Cube => (BeamLookup::new(&sensor, &cube), Renderer::new(&ctx, &cube)?),
            Projection::Cylinder => {
                let pano = Panorama::new(&sensor, cfg.render.oversample);
                (BeamLookup::new_panorama(&sensor, &pano), Renderer::new_panorama(&ctx, &pano)?)
            }
        };
        let mut scratch = Scratch::default();
        // PEDSCAN_BVH_REFIT=0 rebuilds every BVH every frame (for comparison).
        if std::env::var("PEDSCAN_BVH_REFIT").is_ok_and(|v| v == "0") {
            scratch.bvh_background = BvhCache::disabled();
            scratch.bvh_humans = BvhCache::disabled();
        }
        Ok(Generator { cfg, sensor, models, environment, grid, cube, lookup, renderer, scratch, env_meshes, export_geometry: None })
    }

    /// The random stream of sequence `index`.
    pub fn rng(&self, index: usize) -> rand_chacha::ChaCha8Rng {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(self.cfg.seed);
        rng.set_stream(index as u64);
        rng
    }

    /// Samples sequence `index`.
    pub fn plan(&self, index: usize) -> Result<SequencePlan> {
        sample_plan(&mut self.rng(index), &self.cfg, self.sensor.rate_hz, self.grid.as_ref(), &self.models)
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
        }
        FrameState {
            t_s: t,
            world_from_sensor: plan.sensor.pose(t),
            sensor_velocity_mps: plan.sensor.velocity(t),
            sensor_yaw_rate_rps: plan.sensor.yaw_rate_rps,
            humans,
            human_velocity_mps: vel,
        }
    }

    /// Poses the background and the people of a frame into the sensor frame (f64 -> f32),
    /// skipping people no beam can reach. Fills `scratch.background` and `scratch.humans`.
    pub fn pose_frame(&mut self, plan: &SequencePlan, state: &FrameState) {
        let sensor_from_world = state.world_from_sensor.inverse();
        let s = &mut self.scratch;
        s.background.clear();
        if let Some(env) = &self.environment {
            s.env_sensor.clear();
            s.env_sensor.extend(env.positions.iter().map(|p| sensor_from_world.transform_point3(*p).as_vec3().to_array()));
            for m in &self.env_meshes {
                let verts = &s.env_sensor[m.first_vertex..m.first_vertex + m.vertex_count];
                s.background.push_mesh_with_adjacency(verts, &m.local_indices, 0, m.double_sided, Some(m.adjacency.clone()));
            }
        }
        s.humans.clear();
        let lod_rad = self.cfg.render.lod_max_error_mrad * 1e-3;
        for (k, h) in plan.humans.iter().enumerate() {
            let model = &self.models[h.model];
            let st = &state.humans[k];
            let world_from_body = DMat4::from_translation(DVec3::from(st.position_m)) * DMat4::from_rotation_z(st.heading_rad as f64);
            let sensor_from_body = sensor_from_world * world_from_body;
            let height = model.height_m as f64;
            let r = BODY_RADIUS_PER_HEIGHT * height;
            let centre = sensor_from_body.transform_point3(DVec3::new(0.0, 0.0, 0.5 * height));
            let dist = centre.length();
            if dist - r > self.sensor.max_range_m {
                continue;
            }
            if !self.cube.faces.iter().any(|f| f.sees_sphere(centre.as_vec3(), r as f32)) {
                continue;
            }
            let near = (dist - r).max(0.1);
            let lod = model.lod_for_error((lod_rad * near) as f32);
            model.joint_matrices(st.gait_phase, &mut s.joints);
            let transform = (sensor_from_body * MODEL_TO_BODY.as_dmat4()).as_mat4();
            model.skin_into(lod, &s.joints, &transform, &mut s.skinned);
            let l = &model.lods[lod];
            s.humans.push_mesh_with_adjacency(&s.skinned, &l.indices, k as u32 + 1, false, Some(l.adjacency.clone()));
        }
    }

    /// Renders and resamples the posed frame into `scratch.bg_hits` / `scratch.human_hits`.
    pub fn render_posed(&mut self) -> Result<()> {
        let refine = self.cfg.render.refine;
        let backend = self.cfg.render.backend;
        let n = self.lookup.dirs.len();
        let s = &mut self.scratch;
        for (geom, hits, cache) in
            [(&s.background, &mut s.bg_hits, &mut s.bvh_background), (&s.humans, &mut s.human_hits, &mut s.bvh_humans)]
        {
            if geom.meshes.is_empty() {
                hits.clear_to(n);
                continue;
            }
            match backend {
                Backend::Raster => {
                    let frame = self.renderer.render(geom)?;
                    resample(&self.lookup, frame, geom, refine, hits);
                }
                Backend::Raycast => {
                    // Ranges are limited later, in the post-pass, as for the raster path.
                    let bvh = cache.build_or_refit(geom);
                    let cast = crate::raycast::cast(geom, bvh, &self.lookup.dirs, f64::MAX);
                    hits.clear_to(0);
                    hits.range_m.extend(cast.iter().map(|h| h.range_m as f32));
                    hits.triangle.extend(cast.iter().map(|h| h.triangle));
                }
            }
        }
        Ok(())
    }

    /// Composites the rendered frame into `out`.
    pub fn post(&self, state: &FrameState, out: &mut FrameOutput) {
        let rot = DMat3::from_mat4(state.world_from_sensor);
        let params = PostParams {
            dirs: &self.lookup.dirs,
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
        };
        composite(&params, &self.scratch.human_hits, &self.scratch.humans, &self.scratch.bg_hits.range_m, out);
        out.time_s = state.t_s;
        out.world_from_sensor = state.world_from_sensor.transpose().to_cols_array_2d();
        out.humans.clone_from(&state.humans);
    }

    /// Everything of one frame: pose, render, resample, composite.
    pub fn frame(&mut self, plan: &SequencePlan, k: usize, out: &mut FrameOutput) -> Result<FrameState> {
        let state = self.frame_state(plan, k);
        self.pose_frame(plan, &state);
        self.render_posed()?;
        self.post(&state, out);
        Ok(state)
    }

    /// Metadata of sequence `index`.
    pub fn meta(&self, index: usize, plan: &SequencePlan) -> SequenceMeta {
        SequenceMeta {
            index,
            seed: self.cfg.seed,
            sensor: self.sensor.clone(),
            config_toml: self.cfg.to_recorded_toml(),
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
        }
    }

    /// Generates and writes sequence `index` into `out_dir`; returns the files written.
    /// On failure nothing of this sequence is left behind.
    pub fn write_sequence(&mut self, index: usize, out_dir: &Path, mut on_frame: impl FnMut()) -> Result<Vec<PathBuf>> {
        let plan = self.plan(index)?;
        let meta = self.meta(index, &plan);
        let opts = WriterOptions {
            png: self.cfg.png,
            compression: match self.cfg.output.compression {
                CompressionChoice::None => Compression::None,
                CompressionChoice::Deflate => Compression::Deflate(1),
            },
        };
        let mut writer = SequenceWriter::create(out_dir, &meta, &opts)?;
        let mut out = FrameOutput::default();
        for k in 0..plan.times_s.len() {
            self.frame(&plan, k, &mut out)?;
            writer.write_frame(&out)?;
            if let Some(dir) = &self.export_geometry {
                let path = dir.join(crate::output::sequence_stem(index)).join(format!("frame_{k:06}.ply"));
                crate::output::ply::write_humans_ply(&path, &self.scratch.humans)?;
            }
            on_frame();
        }
        writer.finish()
    }
}
