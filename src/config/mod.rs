//! Stage 1: the run configuration: a TOML file (every key optional, unknown keys rejected) merged with
//! command-line flags, then checked once into values the pipeline can use without re-checking.
//! The resolved configuration is written into every output file as TOML text.

mod checks;
mod flags;
pub use flags::Flags;

use checks::{non_negative, positive, range_ok};
pub(crate) use checks::usable_sensor_height;
use crate::debug::KillPoint;
use crate::error::{Error, Result};
use crate::human::MotionMode;
use crate::input::recording::RecordingOptions;
use crate::input::rosbag::BagOptions;
use crate::input::tracks::{TrackFormat, Transform2};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Where the bundled data (humans, default scene) lives, found at run time: the first
/// `data/` folder holding `humans/` and `scene/hall.glb` beside the binary or up to three
/// folders above it (an install's `bin/../data`, a clone's `target/release/../../data`), else
/// the `data/` of the source tree the binary was built from. A copied clone or install finds
/// its own data wherever it lies (`humans.models` and `scene.background` point elsewhere).
pub fn data_dir() -> PathBuf {
    static DIR: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    DIR.get_or_init(|| {
        let holds_data = |d: &Path| d.join("humans").is_dir() && d.join("scene").join("hall.glb").is_file();
        let exe = std::env::current_exe().ok().and_then(|e| e.canonicalize().ok());
        exe.iter()
            .flat_map(|e| e.ancestors().skip(1).take(4))
            .map(|d| d.join("data"))
            .find(|d| holds_data(d))
            .unwrap_or_else(|| PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/data")))
    })
    .clone()
}

/// The prefix of a bundled input's recorded name: `bundled:humans` is [`data_dir`]`/humans`.
pub const BUNDLED: &str = "bundled:";

/// The largest sequence index (`first_sequence` + `sequences` - 1): a billion sequences.
pub const MAX_SEQUENCE_INDEX: usize = 999_999_999;

/// How an input path is recorded in outputs: a path inside the bundled data as
/// `bundled:<path inside data/>`, so the record does not depend on where pedscan lies; any
/// other path as given.
pub fn recorded_path(p: &Path) -> PathBuf {
    let named = |rel: &Path| PathBuf::from(format!("{BUNDLED}{}", rel.display()));
    let data = data_dir();
    if let Ok(rel) = p.strip_prefix(&data) {
        return named(rel);
    }
    // The same folder reached another way (a symbolic link, `..`).
    if let (Ok(d), Ok(c)) = (data.canonicalize(), p.canonicalize()) {
        if let Ok(rel) = c.strip_prefix(&d) {
            return named(rel);
        }
    }
    p.to_path_buf()
}

/// The inverse of [`recorded_path`]: `bundled:<rel>` is `<data_dir>/<rel>`; anything else is
/// returned as it is.
pub fn resolve_bundled(p: &Path) -> PathBuf {
    match p.to_str().and_then(|s| s.strip_prefix(BUNDLED)) {
        Some(rel) => data_dir().join(rel.trim_start_matches('/')),
        None => p.to_path_buf(),
    }
}

/// How synthetic people choose where to walk.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum WalkMode {
    /// From a start to a goal through the walkable area, on smooth planned paths.
    Goals,
    /// Circular arcs at constant speed and yaw rate (`humans.yaw_rate_rps`).
    Arcs,
}

/// How the raster result is refined per beam.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Refine {
    /// The nearest texel's range as rendered.
    None,
    /// Intersect the beam with the plane of the nearest texel's triangle.
    Plane,
    /// Intersect the beam exactly with the triangles of the 3x3 texels around it (nearest hit);
    /// the plane of the centre triangle where none is hit.
    Exact,
}

/// How beams find the surfaces of a frame (`crate::backend`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum BackendChoice {
    /// The ray caster, on every device: the benchmark measures it faster than the raster
    /// backend on lavapipe and on a GPU alike (docs/performance.md).
    Auto,
    /// Vulkan rasterization into cube faces, resampled and refined (GPU or lavapipe).
    Raster,
    /// The CPU ray caster (BVH, watertight f64): exact by construction; the faster of the two
    /// on a 2-core machine with lavapipe and on an H200 with 16 host cores (docs/performance.md).
    Raycast,
}

/// Which raster views the Vulkan backend draws into.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Projection {
    /// The 4 side faces of a cube, each a band-limited perspective frustum.
    Cube,
    /// One cylindrical (equirectangular) panorama: 360 deg of azimuth x the sensor's band,
    /// beam directions on texel centres.
    Cylinder,
    /// The beam grid itself, one texel per beam: the background's triangles are drawn as their
    /// conservative beam-grid bounds and every beam is tested exactly in the fragment shader
    /// (`src/backend/raster/beam_exact.rs`). Exact by construction, whatever `refine` says;
    /// with `refine = "exact"` the people are drawn as proxies (as with the other views), else
    /// the same way as the background.
    Beams,
}

/// Which velocity definition is written.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum VelocityModel {
    /// The paper's eq. 1: human `V_h - V_s`, background `-V_s`, rotated into the sensor frame.
    Paper,
    /// Rigid-body motion relative to the rotating sensor: adds `-w x p` for the sensor's yaw
    /// rate w and the point p (sensor frame).
    Rigid,
    /// As `rigid`, with a human beam's `V_h` replaced by the world velocity of the skinned
    /// surface point the beam hits (a swinging leg and a planted foot differ), from the posed
    /// mesh's motion (central difference over +-1 ms of the walk).
    Limb,
}

/// How the ray-cast backend casts (`debug.caster`): the same hits either way.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Caster {
    /// Triangles binned into the beams they can reach (the fast default).
    #[default]
    Beams,
    /// Every beam traced through a BVH per layer, refit to each pose (the reference).
    Bvh,
}

/// How the raster backend casts the people with exact refinement (`debug.people`): the same
/// hits either way; the choice only moves the work.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PeoplePath {
    /// Proxies on a GPU, the binned CPU caster on a CPU device (lavapipe).
    #[default]
    Auto,
    /// The binned CPU caster on any device.
    Binned,
    /// Conservative proxies drawn into the beam panorama, covered beams cast exactly, on any
    /// device: the GPU's path, so a CPU device (lavapipe, in CI) can check it.
    Proxies,
}

/// HDF5 compression of the per-frame chunks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum CompressionChoice {
    None,
    /// Deflate level 1 with the shuffle filter (every HDF5 reader opens it).
    Deflate,
}

/// A file format a sequence is written in (`output.formats`, `--formats`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// `seq_NNNNNN.h5` with the XML annotation `seq_NNNNNN.xml`.
    H5,
    /// `semantickitti/sequences/SS/` (velodyne, labels, velocity, poses, calib, times).
    Semantickitti,
    /// `seq_NNNNNN_bag/`: a ROS 2 bag (MCAP, `metadata.yaml`).
    Mcap,
}

/// The whole configuration (TOML form; every field has a default).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    pub seed: u64,
    pub sequences: usize,
    /// Index of the first sequence: split one job across machines with the same seed.
    pub first_sequence: usize,
    /// Frames per sequence.
    pub frames: usize,
    pub out: PathBuf,
    pub png: bool,
    /// `auto`, a device index, or a substring of the device name.
    pub device: String,
    /// A preset (`hdl32e`, `vlp16`, `hdl64e`, `vlp32c`, `os1-64`, `os1-128`, `os0-128`, `pandar64`) or a sensor file (TOML, Ouster metadata JSON).
    pub sensor: String,
    pub humans: HumansConfig,
    pub scene: SceneConfig,
    pub render: RenderConfig,
    pub output: OutputConfig,
    /// The sensor's own effects (rolling shutter, noise, dropout, beam divergence, intensity).
    pub sensor_model: SensorModelConfig,
    /// Knobs for measuring and debugging; they never change what is written, so they are
    /// not recorded in the outputs.
    #[serde(skip_serializing_if = "DebugConfig::is_default")]
    pub debug: DebugConfig,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct HumansConfig {
    /// Number of people per sequence, uniform in [min, max].
    pub count: [usize; 2],
    /// A folder of `.glb` / `.gltf` humans, or a list of files.
    pub models: Vec<PathBuf>,
    pub motion: MotionMode,
    /// Walking speed, uniform in [min, max], m/s.
    pub speed_mps: [f64; 2],
    /// Yaw rate of the walked arc, uniform in [min, max], rad/s.
    pub yaw_rate_rps: [f64; 2],
    /// Arm swing per person, uniform in [min, max]: the amplitude of the arms' walk about
    /// their standing pose, 1 = the model's own (+-16 deg shoulder flexion for the bundled
    /// people).
    pub arm_swing: [f64; 2],
    /// Stride per person over the natural stride for its mean speed (Alexander's relation),
    /// uniform in [min, max]; the legs are re-solved for it within 0.6-1.2 times the model's
    /// own stride (models named like the bundled ones; others walk their own stride).
    pub stride_variation: [f64; 2],
    /// Share of synthetic people who stand (waiting, looking around; a third of them turn on
    /// the spot at 0.15-0.5 rad/s), 0..1.
    pub standing: f64,
    /// Share of the standing people who stand by something: within `clearance_m` +
    /// [`BY_THING_M`] of an obstacle (a wall, a pole, a parked car, a tree), as people wait at
    /// a stop, by a shop window or beside a car, 0..1.
    pub by_things: f64,
    /// Share of people (not joining a group, not at a place) who start with a tall obstacle at
    /// most [`crate::scene::BEFORE_THING_M`] behind them as the sensor sees them midway, 0..1.
    pub before_things: f64,
    /// Share of people (as `before_things`) who start with a low obstacle (a counter, a bench)
    /// at most [`crate::scene::BEHIND_THING_M`] in front of them, hiding their legs, 0..1.
    pub behind_things: f64,
    /// Clothes over the unclothed bodies, thickness uniform in [min, max], m (0..0.15): each
    /// model dressed in [`crate::human::clothes::CLOTHES_VARIANTS`] thicknesses over the range;
    /// [0, 0], the default, leaves the bodies unclothed.
    pub clothes_m: [f64; 2],
    /// Share of people who carry something: a backpack, a bag in the right hand or bags in
    /// both hands (each kind a third of them), skinned to the back or the hands
    /// ([`crate::human::carry`]); part of the person (human beams, the person's instance),
    /// 0..1.
    pub carrying: f64,
    /// Share of the people who sit on a seat a built-in world makes: a bench (the street's, a
    /// bus shelter's, a lobby's), a chair at a table (the café's), a beer-garden bench, one
    /// within `spawn_radius_m` of the sensor's start, the others `min_separation_m` from the
    /// middle of the seated body; seated the whole sequence, facing the seat's way, the
    /// standing pose lowered onto it with the thighs forward and the hands over them
    /// ([`crate::human::GaitStyle::seat_m`]). Where the world has no free seat, or the model
    /// cannot sit ([`crate::human::HumanModel::can_sit`]), the person is placed as one not
    /// drawn to sit. 0..1.
    pub sitting: f64,
    /// Share of the people who push a stroller (the street) or a trolley (indoors) the whole
    /// sequence, its handle at their hands, their arms held to it
    /// ([`crate::scene::world::pushed`]): a mover of its own (SemanticKITTI's other-object,
    /// 99), not a person. Kept only where it stays clear of everything all through; an adult
    /// model with nothing in its hands ([`crate::human::HumanModel::can_push`]); nobody pushes
    /// where the background is not a built-in world. 0..1.
    pub pushing: f64,
    /// Share of the standing people who stand at a place a built-in world makes for it:
    /// behind a market stall's counter or in front of it, beside a beer-garden table, under a
    /// pavilion (the street's markets, `scene.markets`) or a bus shelter, where one within
    /// `spawn_radius_m` is free; the
    /// others, and everyone where there is none, are placed as before, 0..1.
    pub at_places: f64,
    /// Share of synthetic people who join the person placed before them: face to face 0.8-1.4 m
    /// away when that one stands (talking), side by side 0.75-0.95 m apart when it walks, 0..1.
    pub groups: f64,
    /// Share of walkers who stop once or twice for 1-6 s and walk on, 0..1.
    pub stop_and_go: f64,
    /// People start within this distance of the sensor's start, m.
    pub spawn_radius_m: f64,
    /// People keep at least this distance from each other and from the sensor, m.
    pub min_separation_m: f64,
    /// People keep at least this clearance from obstacles, m.
    pub clearance_m: f64,
    /// Synthetic people: `goals` (planned start-to-goal walks through the walkable area) or
    /// `arcs` (constant yaw rate). Without a walkable area (no environment) people walk arcs.
    pub walk: WalkMode,
    /// Recorded pedestrian tracks to walk along instead of synthetic paths; empty = none.
    pub tracks: PathBuf,
    pub tracks_format: TrackFormat,
    /// Seconds per frame number of `eth` / `eth4` track files.
    pub tracks_frame_period_s: f64,
    /// `world_from_track`: places the tracks in the background's world frame (ranges:
    /// [`Transform2::check`]).
    pub tracks_transform: Transform2,
}

/// Which built-in world (`crate::scene::world`) a background value names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WorldKind {
    /// A city street: road with parked cars, sidewalks with street furniture and trees,
    /// facades with doors and recesses, plazas, alleys, green slopes, raised crossings.
    Street,
    /// A building's floor: halls and corridors with pillars, furniture, plants, shelves,
    /// display cases, mannequins, kiosks and stairs.
    Indoor,
}

impl WorldKind {
    /// The names `scene.background` takes for the built-in worlds.
    pub const NAMES: [&'static str; 2] = ["street", "indoor"];

    /// The world a background value names: exactly `street` or `indoor` (a file or folder of
    /// that name must be given as `./street`).
    pub fn of_background(p: &Path) -> Option<WorldKind> {
        match p.to_str()? {
            "street" => Some(WorldKind::Street),
            "indoor" => Some(WorldKind::Indoor),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            WorldKind::Street => "street",
            WorldKind::Indoor => "indoor",
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SceneConfig {
    /// The background: a built-in world drawn anew for each sequence (`street`, `indoor`), an
    /// environment glTF (`.glb` / `.gltf`, rendered), a Velodyne `.pcap`, or a folder of
    /// `.bin` / `.pcd` frames (recorded); empty = none (an empty world).
    #[serde(alias = "environment")]
    pub background: PathBuf,
    /// Sensor poses (KITTI `poses.txt` or TUM): the sensor follows them; required to know the
    /// motion of a recorded background (without, it is taken as static).
    pub poses: PathBuf,
    /// An Ouster capture's sensor metadata JSON; empty = the `.json` beside the `.pcap` with
    /// the same stem.
    #[serde(skip_serializing_if = "path_is_empty")]
    pub ouster_metadata: PathBuf,
    /// A ROS 2 bag's PointCloud2 topic; empty = the bag's only one.
    #[serde(skip_serializing_if = "String::is_empty")]
    pub topic: String,
    /// A ROS 2 bag's world frame for the poses from `/tf`; empty = the first of `odom`, `map`,
    /// `world` connected to the clouds' frame.
    #[serde(skip_serializing_if = "String::is_empty")]
    pub world_frame: String,
    /// A ROS 2 bag's `nav_msgs/msg/Odometry` topic giving the poses instead of `/tf`; empty = `/tf`.
    #[serde(skip_serializing_if = "String::is_empty")]
    pub poses_topic: String,
    /// World z of the floor people stand on under a recorded background; unset = estimated
    /// from the recorded points of each window.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub floor_z_m: Option<f64>,
    /// Under a recorded background: its returns that the window's other frames see through
    /// (people and things that move) get `/label` 255, not scored ([`crate::scene::not_scored`]).
    #[serde(skip_serializing_if = "is_false")]
    pub ignore_moving: bool,
    /// Under a KITTI `.bin` background: a folder of SemanticKITTI `.label` files, one per frame
    /// with the same stem; the cells that points of `ignore_classes` project to get `/label`
    /// 255, not scored. Empty = none.
    #[serde(skip_serializing_if = "path_is_empty")]
    pub ignore_labels: PathBuf,
    /// The classes (the labels' lower 16 bits) `ignore_labels` marks: by default SemanticKITTI's
    /// people and riders.
    #[serde(skip_serializing_if = "SceneConfig::ignore_classes_is_default")]
    pub ignore_classes: Vec<u32>,
    pub sensor_height_m: f64,
    pub sensor_speed_mps: [f64; 2],
    pub sensor_yaw_rate_rps: [f64; 2],
    /// The sensor keeps at least this clearance from obstacles, m.
    pub sensor_clearance_m: f64,
    /// The street world: share of the lots behind the sidewalks that are markets or beer
    /// gardens (stalls, table sets, parasols); the others are buildings, alleys, plazas and
    /// green slopes in fixed proportions.
    pub markets: f64,
    /// The street world: share of the lots behind the sidewalks that are side streets (a road
    /// going off the street between two sidewalks, lined with buildings); with `markets` at
    /// most 1. Recorded only when not the default, so the configuration hash of every run
    /// without side streets (and of every run written before the key existed) stays the same.
    #[serde(skip_serializing_if = "SceneConfig::side_streets_is_default")]
    pub side_streets: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct RenderConfig {
    /// Raster (default) or CPU ray cast.
    pub backend: BackendChoice,
    /// Raster views: the beam grid (default, exact), cube faces, or one cylindrical panorama.
    pub projection: Projection,
    /// Texels per beam spacing: at a cube-face centre; for the cylinder, texels per column and
    /// per elevation gap, rounded to a whole number (at least 1) so beams sit on texel centres.
    pub oversample: f64,
    pub refine: Refine,
    /// Level of detail: the coarsest level whose geometric error, seen from the sensor, stays
    /// under this angle (milliradians). 0 = always the full mesh.
    pub lod_max_error_mrad: f64,
    /// Raster backend with exact refinement: the people are drawn as proxies built from
    /// their coarsest level of detail whose recorded error is at most this (metres), pushed
    /// outward to enclose the measured mesh (`src/human/proxy.rs`). 0 = the measured mesh itself.
    pub proxy_max_error_m: f64,
    /// Raster backend, `projection = "beams"`: a background triangle whose beam-grid bound
    /// holds at most this many beams is cast on the host beside the device's draw of the
    /// others (`src/backend/raster/beam_exact.rs`); 0: the device draws every triangle; the
    /// grid's beams or more (32,768 for the HDL-32E): the host casts them all and the device
    /// draws nothing. Recorded only when not the default, so the configuration hash of every
    /// run that keeps it (and of every run written before the key existed) stays the same.
    #[serde(skip_serializing_if = "RenderConfig::host_cast_beams_is_default")]
    pub host_cast_beams: u64,
    /// Keep background holes (no return) even where a person stands in front (the paper's
    /// choice); by default the person is measured.
    pub keep_holes: bool,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct OutputConfig {
    /// The formats each sequence is written in, from the same frame data.
    pub formats: Vec<Format>,
    pub compression: CompressionChoice,
    pub velocity: VelocityModel,
    pub xyz: bool,
    pub velocity_field: bool,
    pub background: bool,
    /// `/class`: each beam's SemanticKITTI class (person 30 or moving person 254, else the
    /// class of the background surface it hits).
    pub class: bool,
}

/// `[sensor_model]`: what a real spinning LiDAR adds to the perfect geometry
/// (`crate::sensor_model`). Every term applies to what pedscan renders (people, an environment),
/// never to a recorded background, which carries its own. Defaults and their sources:
/// docs/sensor-model.md.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SensorModelConfig {
    /// Master switch (`--sensor-model on|off`): off gives the paper's clean, instantaneous
    /// frames (intensity is still written: it is data, not an effect).
    pub enabled: bool,
    /// Each column is taken at its own time over the sweep (`--rolling-shutter off`: every
    /// column at the frame's time).
    pub rolling_shutter: bool,
    /// Gaussian range noise per return, standard deviation, m.
    pub range_noise_m: f64,
    /// Per-laser range bias, drawn once per sequence and laser from N(0, this), m.
    pub laser_bias_m: f64,
    /// Returns lost at random, whatever the surface (fraction).
    pub dropout_rate: f64,
    /// Range at which a surface of reflectance 0.1 seen head-on is detected half the time, m;
    /// detection follows the received power `reflectance * cos(incidence) / range^2`.
    pub detection_range_m: f64,
    /// Width of the detection curve in natural-log units of received power (0 = a hard
    /// threshold).
    pub detection_softness: f64,
    /// Incidence angles (from the surface normal) over which detection falls linearly in
    /// cos(incidence) from all to `1 - grazing_loss`, degrees.
    pub grazing_deg: [f64; 2],
    /// Fraction of returns lost at `grazing_deg[1]` and beyond (1: none return there).
    pub grazing_loss: f64,
    /// Full beam divergence, horizontal and vertical, mrad (0 = a knife-edge beam).
    pub divergence_mrad: [f64; 2],
    /// Surfaces closer together than this within one beam's footprint give one mixed return
    /// (their range weighted by returned power); farther apart, the strongest wins, m.
    pub mixed_return_m: f64,
    /// Per person, uniform in [min, max]: reflectance (near infrared) of skin (head, hands),
    /// upper clothing (torso, arms), lower clothing (hips, legs) and shoes.
    pub skin_reflectance: [f64; 2],
    pub upper_reflectance: [f64; 2],
    pub lower_reflectance: [f64; 2],
    pub shoe_reflectance: [f64; 2],
    /// Intensity units: intensity = this * reflectance * cos(incidence); unset = the units of
    /// the background (a Velodyne capture: 100, its calibrated reflectivity in percent; KITTI
    /// remission and everything else: 1).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub intensity_scale: Option<f64>,
    /// What the sensor is mounted on, as boxes in the sensor frame (`[[sensor_model.platform]]`):
    /// a rendered surface behind a box returns nothing (the mount hides it; a sensor blanks
    /// or a driver crops its own vehicle). Empty: none.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub platform: Vec<PlatformBox>,
}

/// One box of the sensor's platform, sensor frame (x forward, y left, z up), metres.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PlatformBox {
    pub min_m: [f64; 3],
    pub max_m: [f64; 3],
}

impl PlatformBox {
    /// Where a ray from the sensor along unit `dir` enters the box (slab test), `None` when
    /// it misses.
    pub fn entry(&self, dir: glam::DVec3) -> Option<f64> {
        let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
        for k in 0..3 {
            let d = dir[k];
            let (lo, hi) = (self.min_m[k], self.max_m[k]);
            if d.abs() < 1e-15 {
                if 0.0 < lo || 0.0 > hi {
                    return None;
                }
                continue;
            }
            let (a, b) = ((lo / d), (hi / d));
            let (a, b) = if a <= b { (a, b) } else { (b, a) };
            t0 = t0.max(a);
            t1 = t1.min(b);
            if t0 > t1 {
                return None;
            }
        }
        Some(t0)
    }
}

/// Most boxes a platform may have.
pub const MAX_PLATFORM_BOXES: usize = 64;

/// `humans.by_things`: a person standing by something has an obstacle within `clearance_m` +
/// this, m (a body's half depth and a hand's breadth: its back or side a few centimetres off).
pub const BY_THING_M: f64 = 0.25;

impl Default for SensorModelConfig {
    fn default() -> Self {
        SensorModelConfig {
            enabled: true,
            rolling_shutter: true,
            // Fitted to the two HDL-32E captures (`pedscan sensor-fit`; docs/sensor-model.md).
            range_noise_m: 0.012,
            laser_bias_m: 0.005,
            dropout_rate: 0.0025,
            detection_range_m: 72.0,
            detection_softness: 0.84,
            grazing_deg: [78.5, 90.0],
            grazing_loss: 0.07,
            platform: Vec::new(),
            divergence_mrad: [3.0, 1.5],
            mixed_return_m: 0.5,
            skin_reflectance: [0.25, 0.55],
            upper_reflectance: [0.05, 0.7],
            lower_reflectance: [0.05, 0.6],
            shoe_reflectance: [0.03, 0.3],
            intensity_scale: None,
        }
    }
}

impl SensorModelConfig {
    /// The same with every effect off (`--sensor-model off`).
    pub fn off() -> SensorModelConfig {
        SensorModelConfig { enabled: false, ..SensorModelConfig::default() }
    }

    /// The same with every effect on (`--sensor-model on`).
    pub fn on() -> SensorModelConfig {
        SensorModelConfig { enabled: true, ..SensorModelConfig::default() }
    }
}

/// `[debug]`: switches that change how a run computes, never what it writes.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct DebugConfig {
    /// Ray-cast backend: `beams` (binned, default) or `bvh` (the reference caster).
    pub caster: Caster,
    /// With `caster = "bvh"`: refit the BVHs across frames (default) or rebuild them.
    pub bvh_refit: bool,
    /// Compress and write frame k on a thread of its own while frame k+1 is computed
    /// (default); off writes on the frame thread (to measure the overlap).
    pub overlap_write: bool,
    /// The Vulkan validation layer (slow; also `--validation`).
    pub validation: bool,
    /// Raster backend, exact refinement: how the people are cast (`auto`, `binned`, `proxies`).
    pub people: PeoplePath,
    /// Kill the run with SIGKILL at this stage of a sequence ([`KillPoint`]; unset: never).
    pub kill: Option<KillPoint>,
}

impl Default for DebugConfig {
    fn default() -> Self {
        DebugConfig { caster: Caster::Beams, bvh_refit: true, overlap_write: true, validation: false, people: PeoplePath::Auto, kill: None }
    }
}

impl DebugConfig {
    fn is_default(&self) -> bool {
        *self == DebugConfig::default()
    }
}

impl Default for Config {
    fn default() -> Self {
        Config {
            seed: 0,
            sequences: 1,
            first_sequence: 0,
            frames: 32,
            out: PathBuf::from("out"),
            png: false,
            device: "auto".into(),
            sensor: "hdl32e".into(),
            humans: HumansConfig::default(),
            scene: SceneConfig::default(),
            render: RenderConfig::default(),
            output: OutputConfig::default(),
            sensor_model: SensorModelConfig::default(),
            debug: DebugConfig::default(),
        }
    }
}

impl Default for HumansConfig {
    fn default() -> Self {
        HumansConfig {
            count: [1, 30],
            models: vec![data_dir().join("humans")],
            motion: MotionMode::Full,
            speed_mps: [0.8, 1.6],
            arm_swing: [0.6, 1.4],
            stride_variation: [0.9, 1.1],
            yaw_rate_rps: [-0.3, 0.3],
            standing: 0.0,
            by_things: 0.0,
            before_things: 0.0,
            behind_things: 0.0,
            clothes_m: [0.0, 0.0],
            carrying: 0.0,
            sitting: 0.0,
            pushing: 0.0,
            at_places: 0.0,
            groups: 0.0,
            stop_and_go: 0.0,
            spawn_radius_m: 12.0,
            min_separation_m: 0.7,
            clearance_m: 0.35,
            walk: WalkMode::Goals,
            tracks: PathBuf::new(),
            tracks_format: TrackFormat::Csv,
            tracks_frame_period_s: crate::input::tracks::DEFAULT_FRAME_PERIOD_S,
            tracks_transform: Transform2::default(),
        }
    }
}

impl Default for SceneConfig {
    fn default() -> Self {
        SceneConfig {
            background: data_dir().join("scene").join("hall.glb"),
            poses: PathBuf::new(),
            ouster_metadata: PathBuf::new(),
            topic: String::new(),
            world_frame: String::new(),
            poses_topic: String::new(),
            floor_z_m: None,
            ignore_moving: false,
            ignore_labels: PathBuf::new(),
            ignore_classes: crate::input::labels::PEOPLE_CLASSES.to_vec(),
            sensor_height_m: 0.8,
            sensor_speed_mps: [0.3, 1.0],
            sensor_yaw_rate_rps: [-0.15, 0.15],
            sensor_clearance_m: 0.8,
            markets: DEFAULT_MARKETS,
            side_streets: DEFAULT_SIDE_STREETS,
        }
    }
}

/// The default of `scene.markets`: one lot in ten.
pub const DEFAULT_MARKETS: f64 = 0.1;

/// The default of `scene.side_streets`.
pub const DEFAULT_SIDE_STREETS: f64 = 0.0;

/// The default of `render.host_cast_beams` (the raster backend's `HOST_BEAMS`, where the
/// measurements that chose it are).
pub const DEFAULT_HOST_CAST_BEAMS: u64 = 8192;

impl SceneConfig {
    fn ignore_classes_is_default(c: &[u32]) -> bool {
        c == crate::input::labels::PEOPLE_CLASSES
    }

    fn side_streets_is_default(share: &f64) -> bool {
        *share == DEFAULT_SIDE_STREETS
    }

    /// What the recorded background is read with besides its path: the poses file, an Ouster
    /// capture's metadata, a ROS 2 bag's topics and world frame (an empty key: `None`).
    pub fn recording_options(&self) -> RecordingOptions<'_> {
        let text = |s: &str| (!s.is_empty()).then(|| s.to_string());
        RecordingOptions {
            poses: (!path_is_empty(&self.poses)).then_some(self.poses.as_path()),
            ouster_metadata: (!path_is_empty(&self.ouster_metadata)).then_some(self.ouster_metadata.as_path()),
            bag: BagOptions {
                topic: text(&self.topic),
                world_frame: text(&self.world_frame),
                poses_topic: text(&self.poses_topic),
                ..BagOptions::default()
            },
        }
    }
}

impl RenderConfig {
    fn host_cast_beams_is_default(n: &u64) -> bool {
        *n == DEFAULT_HOST_CAST_BEAMS
    }
}

impl Default for RenderConfig {
    fn default() -> Self {
        RenderConfig {
            backend: BackendChoice::Auto,
            projection: Projection::Beams,
            oversample: 2.0,
            refine: Refine::Exact,
            lod_max_error_mrad: 1.0,
            proxy_max_error_m: 0.04,
            host_cast_beams: DEFAULT_HOST_CAST_BEAMS,
            keep_holes: false,
        }
    }
}

impl Default for OutputConfig {
    fn default() -> Self {
        OutputConfig {
            formats: vec![Format::H5],
            compression: CompressionChoice::Deflate,
            velocity: VelocityModel::Paper,
            xyz: true,
            velocity_field: true,
            background: true,
            class: true,
        }
    }
}

impl Config {
    /// Reads a TOML config; relative paths inside it are taken relative to the file's folder.
    pub fn from_file(path: &Path) -> Result<Config> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::input(path.display(), format!("cannot read: {e}")))?;
        let mut cfg: Config = toml::from_str(&text).map_err(|e| Error::input(path.display(), e))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let fix = |p: &mut PathBuf| {
            if WorldKind::of_background(p).is_some() {
                // A built-in world's name, not a path.
            } else if p.to_str().is_some_and(|s| s.starts_with(BUNDLED)) {
                *p = resolve_bundled(p);
            } else if p.is_relative() && !p.as_os_str().is_empty() {
                *p = dir.join(&*p);
            }
        };
        // Only paths the file itself set are relative to it; defaults are absolute already.
        cfg.input_paths_mut().for_each(fix);
        fix(&mut cfg.out);
        if cfg.sensor.ends_with(".toml") || cfg.sensor.ends_with(".json") {
            let mut p = PathBuf::from(&cfg.sensor);
            fix(&mut p);
            cfg.sensor = p.display().to_string();
        }
        Ok(cfg)
    }

    /// The input paths the configuration holds (models, background, poses, tracks; the
    /// sensor is a name or a file, handled beside them), for the places that map them all.
    fn input_paths_mut(&mut self) -> impl Iterator<Item = &mut PathBuf> {
        self.humans.models.iter_mut().chain([
            &mut self.scene.background,
            &mut self.scene.poses,
            &mut self.scene.ouster_metadata,
            &mut self.scene.ignore_labels,
            &mut self.humans.tracks,
        ])
    }

    /// The resolved configuration as TOML text.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_else(|e| format!("# cannot serialise config: {e}\n"))
    }

    /// The configuration recorded in every output: everything that decides the content, not
    /// where it is written, which device ran it or how many sequences the job has (`out`,
    /// `device`, `sequences` and `first_sequence` are left at their defaults: a sequence
    /// depends on the seed and its own index only), so the same seed and config give the same
    /// bytes wherever they run, whether one run writes the job or many shards of it.
    /// Inputs inside the bundled data are recorded by name (`bundled:humans`), not by where
    /// this copy of pedscan keeps them.
    pub fn to_recorded_toml(&self) -> String {
        let mut c = self.clone();
        let d = Config::default();
        (c.out, c.device, c.sequences, c.first_sequence) = (d.out, d.device, d.sequences, d.first_sequence);
        c.debug = DebugConfig::default();
        for p in c.input_paths_mut().filter(|p| !p.as_os_str().is_empty()) {
            *p = recorded_path(p);
        }
        if c.sensor.ends_with(".toml") || c.sensor.ends_with(".json") {
            c.sensor = recorded_path(Path::new(&c.sensor)).display().to_string();
        }
        c.to_toml()
    }

    /// Every input file this configuration reads, by its recorded name ([`recorded_path`]),
    /// with the SHA-256 of its content, in name order: the human models (unless no person is
    /// asked for), the background (a file, or a folder's files and the KITTI `times.txt`
    /// beside it; a `.pcap`'s Ouster metadata, given or the `.json` beside it), the label
    /// files of `scene.ignore_labels`, the poses, the tracks and a sensor file (TOML or Ouster
    /// JSON).
    pub fn input_digests(&self) -> Result<Vec<(String, String)>> {
        // A folder's files, sorted; a folder that cannot be read is the user's to fix.
        let files_in = |dir: &Path| crate::input::folder_files(dir, Path::is_file);
        let mut files: Vec<PathBuf> = Vec::new();
        if self.humans.count[1] > 0 {
            files.extend(crate::human::model_files(&self.humans.models)?);
        }
        let bg = &self.scene.background;
        if WorldKind::of_background(bg).is_some() {
            // A built-in world: no file; the version of pedscan that built it is recorded.
        } else if bg.is_dir() {
            files.extend(files_in(bg)?);
            files.extend(bg.parent().map(|p| p.join("times.txt")).filter(|t| t.is_file()));
        } else if !bg.as_os_str().is_empty() {
            files.push(bg.clone());
            // An Ouster capture's metadata decides its points: given, or the one beside it.
            let beside = bg.with_extension("json");
            if self.scene.ouster_metadata.as_os_str().is_empty() && crate::input::recording::is_pcap(bg) && beside.is_file() {
                files.push(beside);
            }
        }
        if !self.scene.ouster_metadata.as_os_str().is_empty() {
            files.push(self.scene.ouster_metadata.clone());
        }
        let labels = &self.scene.ignore_labels;
        if labels.is_dir() {
            files.extend(files_in(labels)?);
        }
        for p in [&self.scene.poses, &self.humans.tracks] {
            if !p.as_os_str().is_empty() {
                files.push(p.clone());
            }
        }
        if self.sensor.ends_with(".toml") || self.sensor.ends_with(".json") {
            files.push(PathBuf::from(&self.sensor));
        }
        // A recording folder can hold gigabytes: its files are hashed in parallel.
        use rayon::prelude::*;
        let mut out = files
            .par_iter()
            .map(|f| {
                // An input that cannot be read is the user's to fix (exit 2), as where it is read.
                let (digest, _) = crate::output::manifest::sha256_file(f).map_err(|e| Error::input(f.display(), format!("cannot read: {e}")))?;
                Ok((recorded_path(f).display().to_string(), digest))
            })
            .collect::<Result<Vec<_>>>()?;
        out.sort();
        out.dedup();
        Ok(out)
    }

    /// [`Config::to_recorded_toml`] with the inputs' content digests ([`Config::input_digests`])
    /// as closing comments: what every output records and what the manifest's config hash
    /// covers, so a changed model or recording is another configuration, and the same inputs
    /// are the same configuration wherever they lie.
    pub fn to_recorded_toml_with_inputs(&self) -> Result<String> {
        let mut text = self.to_recorded_toml();
        text.push_str("\n# inputs, SHA-256 of their content\n");
        for (name, digest) in self.input_digests()? {
            text.push_str(&format!("# {name} {digest}\n"));
        }
        Ok(text)
    }

    /// Rejects impossible values with a message naming the key.
    pub fn validate(&self) -> Result<()> {
        let bad = |key: &str, msg: String| Err(Error::input(format!("config key `{key}`"), msg));
        if self.sequences == 0 {
            return bad("sequences", "must be at least 1".into());
        }
        // Sequence indices name files and seed draws: bounded, and their range cannot wrap.
        if self.first_sequence.checked_add(self.sequences).is_none_or(|end| end > MAX_SEQUENCE_INDEX + 1) {
            return bad(
                "first_sequence",
                format!("{} sequences from index {} reach past the last supported index, {MAX_SEQUENCE_INDEX}", self.sequences, self.first_sequence),
            );
        }
        if self.output.formats.is_empty() {
            return bad("output.formats", "needs at least one format (h5, semantickitti, mcap)".into());
        }
        if self.frames == 0 {
            return bad("frames", "must be at least 1".into());
        }
        if self.frames > 1_000_000 {
            return bad("frames", format!("{} frames in one sequence is more than the supported 1,000,000", self.frames));
        }
        let [lo, hi] = self.humans.count;
        if lo > hi {
            return bad("humans.count", format!("min {lo} is greater than max {hi}"));
        }
        if hi > 1000 {
            return bad("humans.count", format!("max {hi} is more than the supported 1000"));
        }
        range_ok("humans.speed_mps", self.humans.speed_mps, 0.0, 10.0)?;
        for (key, v) in [("humans.standing", self.humans.standing), ("humans.by_things", self.humans.by_things), ("humans.before_things", self.humans.before_things), ("humans.behind_things", self.humans.behind_things), ("humans.at_places", self.humans.at_places), ("humans.groups", self.humans.groups), ("humans.stop_and_go", self.humans.stop_and_go), ("humans.carrying", self.humans.carrying), ("humans.sitting", self.humans.sitting), ("humans.pushing", self.humans.pushing), ("scene.markets", self.scene.markets), ("scene.side_streets", self.scene.side_streets)] {
            if !(0.0..=1.0).contains(&v) {
                return bad(key, format!("{v} is not a share in 0..1"));
            }
        }
        if self.scene.markets + self.scene.side_streets > 1.0 {
            return bad("scene.side_streets", format!("{} with scene.markets = {}: the two shares of the lots add up to more than 1", self.scene.side_streets, self.scene.markets));
        }
        range_ok("humans.yaw_rate_rps", self.humans.yaw_rate_rps, -10.0, 10.0)?;
        range_ok("humans.arm_swing", self.humans.arm_swing, 0.0, 2.0)?;
        range_ok("humans.clothes_m", self.humans.clothes_m, 0.0, 0.15)?;
        range_ok("humans.stride_variation", self.humans.stride_variation, 0.5, 1.5)?;
        range_ok("scene.sensor_speed_mps", self.scene.sensor_speed_mps, 0.0, 100.0)?;
        range_ok("scene.sensor_yaw_rate_rps", self.scene.sensor_yaw_rate_rps, -10.0, 10.0)?;
        positive("humans.spawn_radius_m", self.humans.spawn_radius_m)?;
        non_negative("humans.min_separation_m", self.humans.min_separation_m)?;
        non_negative("humans.clearance_m", self.humans.clearance_m)?;
        non_negative("scene.sensor_clearance_m", self.scene.sensor_clearance_m)?;
        if !usable_sensor_height(self.scene.sensor_height_m) {
            return bad("scene.sensor_height_m", format!("{} is not a usable height (metres over the floor, above 0)", self.scene.sensor_height_m));
        }
        if !(self.render.oversample.is_finite() && self.render.oversample >= 0.25 && self.render.oversample <= 16.0) {
            return bad("render.oversample", format!("{} must be in [0.25, 16]", self.render.oversample));
        }
        non_negative("render.lod_max_error_mrad", self.render.lod_max_error_mrad)?;
        if self.render.host_cast_beams > i64::MAX as u64 {
            return bad("render.host_cast_beams", format!("{} is more than {} (a TOML integer)", self.render.host_cast_beams, i64::MAX));
        }
        if !(self.render.proxy_max_error_m.is_finite() && (0.0..=0.5).contains(&self.render.proxy_max_error_m)) {
            return bad("render.proxy_max_error_m", format!("{} must be in [0, 0.5]", self.render.proxy_max_error_m));
        }
        positive("humans.tracks_frame_period_s", self.humans.tracks_frame_period_s)?;
        // The documented ranges of `Transform2::check`: a huge scale would send every track
        // position to infinity.
        if let Err(m) = self.humans.tracks_transform.check() {
            return bad("humans.tracks_transform", m);
        }
        if let Some(z) = self.scene.floor_z_m {
            if !(z.is_finite() && z.abs() < 1e4) {
                return bad("scene.floor_z_m", format!("{z} is not a usable height"));
            }
        }
        if let Some(c) = self.scene.ignore_classes.iter().find(|&&c| c > 0xFFFF) {
            return bad("scene.ignore_classes", format!("{c} is not a SemanticKITTI class (the labels' lower 16 bits: 0 to 65535)"));
        }
        if self.scene.ignore_classes.is_empty() && !path_is_empty(&self.scene.ignore_labels) {
            return bad("scene.ignore_classes", "is empty: scene.ignore_labels would mark nothing".into());
        }
        self.sensor_model.validate()?;
        if self.humans.models.is_empty() && hi > 0 {
            return bad("humans.models", "no model given but people are requested".into());
        }
        Ok(())
    }
}

/// Serde: a switch that is off is left out of the written configuration.
fn is_false(b: &bool) -> bool {
    !*b
}

/// Serde: an unset path (empty) is left out of the written configuration.
fn path_is_empty(p: &Path) -> bool {
    p.as_os_str().is_empty()
}

#[cfg(test)]
mod tests;
