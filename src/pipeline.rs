//! The generator: runs the stages of every frame of every sequence, in data-flow order:
//! sample the sequence -> pose people and background in the sensor frame (f64 -> f32) ->
//! rasterize (Vulkan) -> resample to the beam grid -> composite, label, velocity -> write.
//!
//! Each sequence draws from its own random stream (ChaCha8, stream = sequence index), so a
//! sequence's content depends only on the seed, the configuration and its index: never on
//! thread count, on which other sequences ran, or on the GPU.

use crate::config::{Backend, CompressionChoice, Config, Projection};
use crate::error::{Error, Result};
use crate::geometry::{Adjacency, FrameGeometry, MeshLayout};
use crate::gpu::{Context, ContextOptions, DeviceChoice};
use crate::human::{HumanModel, MODEL_TO_BODY};
use crate::output::{Compression, FrameOutput, HumanMeta, HumanState, OutputSet, SequenceMeta, SequenceWriter, WriterOptions};
use crate::post::{composite, PostParams};
use crate::people::PeopleRaster;
use crate::projection::{CubeFaces, Panorama};
use crate::proxy::ModelProxies;
use crate::raster::Renderer;
use crate::raycast::{BeamCaster, BvhCache};
use crate::resample::{resample, BeamHits, BeamLookup};
use crate::scene::{Environment, WalkableGrid};
use crate::sensor::Sensor;
use crate::background::recording::is_recording;
use crate::background::Recording;
use crate::sequence::{sample_plan, PlanInputs, PoseTrack, SequencePlan};
use crate::tracks::{read_tracks, Track, TrackOptions};
use glam::{DMat3, DMat4, DVec3, Mat4};
use rand::SeedableRng;
use rayon::prelude::*;
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
    /// A recorded background sequence (instead of an environment).
    pub recording: Option<Recording>,
    /// Recorded sensor poses with their times (from `scene.poses`, or a static sensor under a
    /// recording without poses): the sensor follows them.
    pub sensor_poses: Option<(Vec<f64>, Vec<DMat4>)>,
    /// Recorded pedestrian tracks (world frame), when `humans.tracks` is set.
    pub tracks: Vec<Arc<Track>>,
    /// The backend that runs: `render.backend` with `auto` resolved for the device.
    pub backend: Backend,
    pub cube: CubeFaces,
    pub lookup: BeamLookup,
    pub renderer: Renderer,
    /// Raster backend, exact refinement: the people drawn as proxies at beam resolution and
    /// cast exactly (`crate::people`); `None` otherwise.
    pub people: Option<PeopleRaster>,
    /// Per model, the proxies of its levels of detail (with `people`).
    proxies: Vec<ModelProxies>,
    pub scratch: Scratch,
    /// Per environment mesh: its vertex range in `environment.positions`, local indices and
    /// triangle one-rings (computed once).
    env_meshes: Vec<EnvDraw>,
    /// Write each frame's posed humans as PLY under this folder (`--export-geometry`).
    pub export_geometry: Option<PathBuf>,
    /// Seconds spent per stage so far (see `--timings`).
    pub timings: StageTimes,
    /// Ray-cast backend: trace every beam through a BVH refit per frame instead of binning
    /// the triangles into beams (same hits; `PEDSCAN_CASTER=bvh`, to compare their speed).
    bvh_caster: bool,
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
    /// Ray caster: refit or build the bottom-level trees (background and people).
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
            // The BVH stage exists only with PEDSCAN_CASTER=bvh.
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
pub struct Scratch {
    pub background: FrameGeometry,
    pub humans: FrameGeometry,
    /// The people's proxies, one mesh per person in `humans` order (with `Generator::people`).
    pub proxies: FrameGeometry,
    pub bg_hits: BeamHits,
    pub human_hits: BeamHits,
    /// The recorded background of the current frame (target grid ranges), when there is one.
    pub recorded: Option<Vec<f32>>,
    /// The people in `humans` (instance, model, level of detail), last frame and this one,
    /// and this frame's placements (sensor from model, gait phase).
    layout: Vec<(u32, usize, usize)>,
    layout_next: Vec<(u32, usize, usize)>,
    placements: Vec<(Mat4, f32)>,
    /// Per drawn person: joint matrices, placed joints and bounding sphere (in-place poses).
    person_scratch: Vec<PersonScratch>,
    env_sensor: Vec<[f32; 3]>,
    /// Ray-cast backend: bottom-level BVHs kept across frames (refit to each pose), one
    /// cache for the background and one for the people.
    bvh_background: BvhCache,
    bvh_humans: BvhCache,
    /// Ray-cast backend: the binned beam-grid caster and its output.
    beams: Option<BeamCaster>,
    cast: Vec<crate::raycast::Hit>,
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
    /// Index of the recorded background frame shown at this frame.
    pub recorded_frame: Option<usize>,
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
        let bg = &cfg.scene.background;
        let (environment, grid, recording) = if bg.as_os_str().is_empty() {
            (None, None, None)
        } else if is_recording(bg) {
            let poses = (!cfg.scene.poses.as_os_str().is_empty()).then_some(cfg.scene.poses.as_path());
            (None, None, Some(Recording::open(bg, poses, &sensor)?))
        } else {
            let env = Environment::load(bg)?;
            let grid = WalkableGrid::from_environment(&env, WALKABLE_CELL_M)?;
            if grid.free_fraction(cfg.humans.clearance_m) <= 0.0 {
                return Err(Error::input(bg.display(), "environment has no walkable floor at z = 0"));
            }
            (Some(env), Some(grid), None)
        };
        let sensor_poses = match &recording {
            Some(rec) => Some((rec.times_s.clone(), (0..rec.len()).map(|k| rec.pose(k)).collect::<Vec<_>>())),
            None if !cfg.scene.poses.as_os_str().is_empty() => {
                let p = crate::background::poses::read_poses(&cfg.scene.poses)?;
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
            let kept = crate::tracks::drop_short(all, duration);
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
        let backend = match cfg.render.backend {
            Backend::Auto if ctx.is_cpu() => Backend::Raycast,
            Backend::Auto => Backend::Raster,
            b => b,
        };
        let (people, proxies) = if backend == Backend::Raster && cfg.render.refine == crate::config::Refine::Exact {
            let max_error = cfg.render.proxy_max_error_m as f32;
            let proxies: Vec<ModelProxies> = models.par_iter().map(|m| ModelProxies::build(m, max_error, 1.0)).collect();
            (Some(PeopleRaster::new(&ctx, &sensor)?), proxies)
        } else {
            (None, Vec::new())
        };
        let mut scratch = Scratch::default();
        // PEDSCAN_BVH_REFIT=0 rebuilds every BVH every frame (for comparison).
        if std::env::var("PEDSCAN_BVH_REFIT").is_ok_and(|v| v == "0") {
            scratch.bvh_background = BvhCache::disabled();
            scratch.bvh_humans = BvhCache::disabled();
        }
        if backend == Backend::Raycast {
            scratch.beams = Some(BeamCaster::new(&lookup.dirs, lookup.rows, lookup.columns));
        }
        Ok(Generator {
            cfg,
            sensor,
            models,
            environment,
            grid,
            recording,
            sensor_poses,
            tracks,
            backend,
            cube,
            lookup,
            renderer,
            people,
            proxies,
            scratch,
            env_meshes,
            export_geometry: None,
            timings: StageTimes::default(),
            bvh_caster: std::env::var("PEDSCAN_CASTER").is_ok_and(|v| v == "bvh"),
        })
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
                let (z, g) = rec.walkable(s..s + frames, self.cfg.scene.floor_z_m)?;
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
            sensor_yaw_rate_rps: plan.sensor.yaw_rate_rps(t),
            humans,
            human_velocity_mps: vel,
            recorded_frame: plan.recording_start.map(|s| s + k),
        }
    }

    /// Poses the background and the people of a frame into the sensor frame (f64 -> f32),
    /// skipping people no beam can reach. Fills `scratch.background` and `scratch.humans`, and
    /// `scratch.recorded` with the recorded background frame, if any.
    pub fn pose_frame(&mut self, plan: &SequencePlan, state: &FrameState) -> Result<()> {
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
        let lod_rad = self.cfg.render.lod_max_error_mrad * 1e-3;
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
            if dist - r > self.sensor.max_range_m {
                continue;
            }
            if !self.cube.faces.iter().any(|f| f.sees_sphere(centre.as_vec3(), r as f32)) {
                continue;
            }
            let near = (dist - r).max(0.1);
            let lod = model.lod_for_error((lod_rad * near) as f32);
            s.layout_next.push((k as u32 + 1, h.model, lod));
            s.placements.push(((sensor_from_body * MODEL_TO_BODY.as_dmat4()).as_mat4(), st.gait_phase));
        }
        // The same people at the same levels of detail as last frame: the triangles stay and
        // only the vertices move. Otherwise the meshes are laid out anew (sizes from the
        // levels of detail) and each person also writes its indices.
        let in_place = s.layout_next == s.layout && s.humans.meshes.len() == s.layout.len();
        let models = &self.models;
        if !in_place {
            s.humans.lay_out(s.layout_next.iter().map(|&(instance, m, lod)| {
                let l = &models[m].lods[lod];
                MeshLayout::of_lod(l, instance, false, Some(l.adjacency.clone()))
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
            .for_each(|(((first, out, indices), p), (&(_, m, lod), &(transform, phase)))| {
                let model = &models[m];
                model.joint_matrices(phase, &mut p.joints);
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
        if self.people.is_some() {
            let proxies = &self.proxies;
            if !in_place {
                // Drawn from both sides: a beam that meets a proxy, whatever the winding of
                // the face it meets, may hit that person.
                s.proxies.lay_out(
                    s.layout_next.iter().map(|&(instance, m, lod)| MeshLayout::of_lod(&proxies[m].lods[lod], instance, true, None)),
                );
            }
            s.proxies
                .mesh_slices_mut()
                .into_par_iter()
                .zip(s.person_scratch.par_iter_mut())
                .zip(s.layout_next.par_iter().zip(s.placements.par_iter()))
                .for_each(|(((first, out, indices), p), (&(_, m, lod), &(transform, _)))| {
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

    /// Renders and resamples the posed frame into `scratch.bg_hits` / `scratch.human_hits`.
    pub fn render_posed(&mut self) -> Result<()> {
        let refine = self.cfg.render.refine;
        let backend = self.backend;
        let n = self.lookup.dirs.len();
        let s = &mut self.scratch;
        let t = &mut self.timings;
        for (is_people, geom, hits, cache, stage) in [
            (false, &s.background, &mut s.bg_hits, &mut s.bvh_background, &mut t.background_s),
            (true, &s.humans, &mut s.human_hits, &mut s.bvh_humans, &mut t.humans_s),
        ] {
            let t0 = std::time::Instant::now();
            if geom.meshes.is_empty() {
                hits.clear_to(n);
                continue;
            }
            match backend {
                Backend::Raster | Backend::Auto if is_people && self.people.is_some() => {
                    let people = self.people.as_mut().expect("checked");
                    people.render(&s.proxies, geom, hits)?;
                }
                Backend::Raster | Backend::Auto => {
                    let frame = self.renderer.render(geom)?;
                    resample(&self.lookup, frame, geom, refine, hits);
                }
                Backend::Raycast => {
                    // Ranges are limited later, in the post-pass, as for the raster path.
                    let t1;
                    let cast = if self.bvh_caster {
                        let bvh = cache.build_or_refit(geom);
                        t.bvh_s += t0.elapsed().as_secs_f64();
                        t1 = std::time::Instant::now();
                        s.cast = crate::raycast::cast(geom, bvh, &self.lookup.dirs, f64::MAX);
                        &s.cast
                    } else {
                        t1 = std::time::Instant::now();
                        let caster = s.beams.as_mut().expect("the ray-cast backend has a beam caster");
                        caster.cast(geom, f64::MAX, &mut s.cast);
                        &s.cast
                    };
                    hits.clear_to(0);
                    hits.range_m.extend(cast.iter().map(|h| h.range_m as f32));
                    hits.triangle.extend(cast.iter().map(|h| h.triangle));
                    *stage += t1.elapsed().as_secs_f64();
                    continue;
                }
            }
            *stage += t0.elapsed().as_secs_f64();
        }
        if let Some(r) = &s.recorded {
            s.bg_hits.range_m.clone_from(r);
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
        let t0 = std::time::Instant::now();
        let state = self.frame_state(plan, k);
        self.pose_frame(plan, &state)?;
        let t1 = std::time::Instant::now();
        self.render_posed()?;
        let t2 = std::time::Instant::now();
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
        let backend = if self.backend == Backend::Raycast { "raycast" } else { "raster" };
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
                if let crate::sequence::HumanPath::Track(t) = &h.trajectory {
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
    /// On failure nothing of this sequence is left behind.
    pub fn write_sequence(&mut self, index: usize, out_dir: &Path, mut on_frame: impl FnMut()) -> Result<Vec<PathBuf>> {
        let t0 = std::time::Instant::now();
        let plan = self.plan(index)?;
        self.timings.plan_s += t0.elapsed().as_secs_f64();
        let meta = self.meta(index, &plan);
        let opts = WriterOptions {
            png: self.cfg.png,
            compression: match self.cfg.output.compression {
                CompressionChoice::None => Compression::None,
                CompressionChoice::Deflate => Compression::Deflate(1),
            },
        };
        let mut writer = SequenceWriter::create(out_dir, &meta, &opts)?;
        // PEDSCAN_OVERLAP_WRITE=0 writes each frame on this thread (to measure the overlap).
        if std::env::var("PEDSCAN_OVERLAP_WRITE").is_ok_and(|v| v == "0") {
            let mut out = FrameOutput::default();
            for k in 0..plan.times_s.len() {
                self.frame_and_export(&plan, index, k, &mut out)?;
                let t0 = std::time::Instant::now();
                writer.write_frame(&out)?;
                self.timings.write_s += t0.elapsed().as_secs_f64();
                on_frame();
            }
            return writer.finish();
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
            let write = scope.spawn(move || -> Result<(Option<Vec<PathBuf>>, f64)> {
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
                    on_frame();
                }
                let _ = to_writer.send(Msg::Done);
                Ok(())
            })();
            drop(to_writer);
            let written = write.join().map_err(|_| Error::Internal("the writer thread panicked".into()))?;
            computed?;
            let (written, write_s) = written?;
            self.timings.write_s += write_s;
            written.ok_or_else(|| Error::Internal("the writer stopped before the last frame".into()))
        })
    }
}
