//! A run's inputs, loaded and checked once: the sensor, the people's models, the environment
//! or the recording, the sensor's recorded poses, the pedestrian tracks, and what the stages
//! derive from them once (the environment's meshes as drawn, the people's body regions).

use crate::backend::Gpu;
use crate::config::{BackendChoice, Config};
use crate::error::{Error, Result};
use crate::human::proxy::ModelProxies;
use crate::human::{model_files, HumanModel};
use crate::input::recording::is_recording;
use crate::input::tracks::{read_tracks, Track, TrackOptions};
use crate::input::Recording;
use crate::pose::PoseInputs;
use crate::scene::not_scored::NotScored;
use crate::scene::world::WorldKind;
use crate::scene::{EnvDraw, Environment, WalkableGrid, WALKABLE_CELL_M};
use crate::sensor::Sensor;
use glam::{DMat4, DVec3};
use rayon::prelude::*;
use std::sync::Arc;

/// Everything a run reads, loaded once (see [`RunInputs::load`]).
pub struct RunInputs {
    pub sensor: Sensor,
    /// The sensor's beam directions (row-major).
    pub dirs: Vec<DVec3>,
    pub models: Vec<HumanModel>,
    pub environment: Option<Environment>,
    pub grid: Option<WalkableGrid>,
    /// A recorded background sequence (instead of an environment).
    pub recording: Option<Recording>,
    /// A built-in world, drawn for each sequence (instead of an environment).
    pub world: Option<WorldKind>,
    /// What makes the recording's own returns not scored (`scene.ignore_*`).
    pub not_scored: NotScored,
    /// Recorded sensor poses with their times (from `scene.poses`, or a static sensor under a
    /// recording without poses): the sensor follows them.
    pub sensor_poses: Option<(Vec<f64>, Vec<DMat4>)>,
    /// Recorded pedestrian tracks (world frame), when `humans.tracks` is set.
    pub tracks: Vec<Arc<Track>>,
    /// The environment's meshes as drawn (vertex ranges, local indices, one-rings, reflectance).
    pub env_meshes: Vec<EnvDraw>,
    /// Per model, per level of detail, per triangle: its body region (`crate::sensor_model`).
    pub regions: Vec<Vec<Vec<u8>>>,
    /// Intensity units (`sensor_model.intensity_scale`, resolved).
    pub intensity_scale: f64,
    /// Per row its beams' elevation, per column its azimuth, radians (the footprints' frame).
    pub elevation_rad: Vec<f64>,
    pub azimuth_rad: Vec<f64>,
}

impl RunInputs {
    /// Reads and checks every input of a checked configuration. A backend that needs the
    /// Vulkan device opens it on `gpu` meanwhile, on its own thread.
    pub fn load(cfg: &Config, gpu: &mut Gpu) -> Result<RunInputs> {
        let sensor = if cfg.sensor == crate::input::recording::BACKGROUND_SENSOR {
            let s = crate::input::recording::own_sensor(&cfg.scene.background, &cfg.scene.recording_options())?;
            eprintln!(
                "sensor: the background's own grid, {} rows from {:.2} to {:.2} deg, {} columns, {:.2} Hz",
                s.rows(),
                s.elevation_deg[0],
                s.elevation_deg[s.rows() - 1],
                s.columns,
                s.rate_hz
            );
            s
        } else {
            Sensor::from_name_or_file(&cfg.sensor)?
        };
        let needs_animation = cfg.humans.motion.animates();
        // The people load in parallel (~13 ms of CPU each, the bundled 15 in ~200 ms on one
        // core), and a backend that needs the Vulkan device opens it meanwhile on its own
        // thread. The first failing file in the list's order is the one reported.
        let files = if cfg.humans.count[1] > 0 { model_files(&cfg.humans.models)? } else { Vec::new() };
        let opens_device = cfg.render.backend == BackendChoice::Raster;
        let models = std::thread::scope(|scope| {
            let opening = opens_device.then(|| scope.spawn(|| gpu.open_early()));
            let loaded: Vec<Result<HumanModel>> = files.par_iter().map(|f| HumanModel::load(f, needs_animation)).collect();
            let opened = opening.map(|h| h.join());
            let dressed = crate::human::clothes::dress(loaded.into_iter().collect::<Result<Vec<_>>>()?, cfg.humans.clothes_m);
            let models = crate::human::carry::equip(dressed, cfg.humans.carrying);
            match opened {
                Some(Err(_)) => Err(Error::Internal("opening the Vulkan device panicked".into())),
                _ => Ok(models),
            }
        })?;
        let bg = &cfg.scene.background;
        let world = WorldKind::of_background(bg);
        let (environment, grid, recording) = if bg.as_os_str().is_empty() || world.is_some() {
            (None, None, None)
        } else if is_recording(bg) {
            let options = cfg.scene.recording_options();
            (None, None, Some(Recording::open_with(bg, &options, &sensor)?))
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
        let not_scored = not_scored_of(cfg, recording.as_ref())?;
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
            for w in rec.sweep_warning.iter().chain(&rec.coverage_warning) {
                eprintln!("warning: {}: {w}", bg.display());
            }
            if rec.poses.is_none() {
                eprintln!("warning: {}: no poses given (--poses, or a bag's /tf or --poses-topic), so the sensor is taken as static; background velocities are 0", bg.display());
            }
        }
        let regions = models.iter().map(crate::sensor_model::surfaces::body_regions).collect::<Result<Vec<_>>>()?;
        let pcap = crate::input::recording::is_pcap(bg);
        let intensity_scale = cfg.sensor_model.intensity_scale.unwrap_or(if recording.is_some() && pcap { 100.0 } else { 1.0 });
        let env_meshes = environment.as_ref().map_or_else(Vec::new, Environment::draws);
        let elevation_rad = sensor.elevation_deg.iter().map(|e| e.to_radians()).collect();
        let azimuth_rad = (0..sensor.columns).map(|c| sensor.azimuth_rad(c)).collect();
        Ok(RunInputs {
            dirs: sensor.beam_dirs(),
            sensor,
            models,
            environment,
            grid,
            recording,
            world,
            not_scored,
            sensor_poses,
            tracks,
            env_meshes,
            regions,
            intensity_scale,
            elevation_rad,
            azimuth_rad,
        })
    }

    /// What the pose stage reads; `proxies` are the backend's, when it draws them.
    pub fn pose<'a>(&'a self, proxies: Option<&'a [ModelProxies]>) -> PoseInputs<'a> {
        PoseInputs {
            sensor: &self.sensor,
            dirs: &self.dirs,
            models: &self.models,
            environment: self.environment.as_ref(),
            env_meshes: &self.env_meshes,
            recording: self.recording.as_ref(),
            not_scored: &self.not_scored,
            proxies,
        }
    }
}

/// The not-scored sources of the configuration (`scene.ignore_moving`, `scene.ignore_labels`),
/// checked against the background: both need a recording, labels a folder of KITTI `.bin`
/// frames with a label file each.
fn not_scored_of(cfg: &Config, recording: Option<&Recording>) -> Result<NotScored> {
    let scene = &cfg.scene;
    let labels_dir = (!scene.ignore_labels.as_os_str().is_empty()).then_some(scene.ignore_labels.as_path());
    let key = match (scene.ignore_moving, labels_dir) {
        (false, None) => return Ok(NotScored::default()),
        (true, _) => "scene.ignore_moving",
        (false, Some(_)) => "scene.ignore_labels",
    };
    let Some(rec) = recording else {
        return Err(Error::input(format!("config key `{key}`"), "needs a recorded background (a capture, a bag or a folder of frames)"));
    };
    let labels = match labels_dir {
        None => None,
        Some(dir) => {
            let Some(files) = rec.frame_files() else {
                return Err(Error::input(rec.source.display(), "scene.ignore_labels needs a folder of KITTI .bin frames as the background"));
            };
            Some(crate::input::labels::FrameLabels::open(files, dir, &scene.ignore_classes)?)
        }
    };
    Ok(NotScored { moving: scene.ignore_moving, labels })
}
