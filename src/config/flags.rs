//! Command-line flags over the config file: `generate` and `crosscheck` take the same set,
//! each flag replacing its key (or, for switches, turning it on). The binary only parses
//! them; [`Flags::config`] applies them here, so every caller gets the same configuration.

use super::{BackendChoice, CompressionChoice, Config, Format, Projection, Refine, VelocityModel, WalkMode};
use crate::error::{Error, Result};
use crate::human::MotionMode;
use clap::Args;
use std::path::{Path, PathBuf};

/// Flags override the config file, which overrides the defaults.
#[derive(Args, Clone, Debug, Default)]
pub struct Flags {
    /// A TOML configuration (see docs/usage.md for every key).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Number of sequences.
    #[arg(long)]
    pub sequences: Option<usize>,
    /// Index of the first sequence (to split a job across machines with one seed).
    #[arg(long)]
    pub first_sequence: Option<usize>,
    /// Frames per sequence.
    #[arg(long)]
    pub frames: Option<usize>,
    /// People per sequence: `MIN..MAX` (uniform, inclusive) or one number.
    #[arg(long, value_parser = parse_count)]
    pub humans: Option<[usize; 2]>,
    #[arg(long)]
    pub seed: Option<u64>,
    /// Output folder.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also write debug PNG range / label / velocity images per frame.
    #[arg(long)]
    pub png: bool,
    /// Print the time spent per stage (ms per frame) at the end.
    #[arg(long)]
    pub timings: bool,
    /// Vulkan device: `auto`, an index or part of a name (see `pedscan devices`).
    #[arg(long)]
    pub device: Option<String>,
    /// Keep background holes where a person stands in front of them (the paper's choice).
    #[arg(long)]
    pub keep_holes: bool,
    /// Sensor preset (`hdl32e`, `vlp16`, `hdl64e`, `vlp32c`, `os1-64`, `os1-128`, `os0-128`, `pandar64`), a sensor file (TOML, Ouster metadata JSON), or `background`: the recorded background's own grid (a ROS 2 bag's rings, an Ouster capture's metadata).
    #[arg(long)]
    pub sensor: Option<String>,
    /// The sensor's height over the floor in metres (`scene.sensor_height_m`) in a built
    /// world: the hall, `street`, `indoor`, an environment. A recording keeps its own.
    #[arg(long, allow_hyphen_values = true)]
    pub sensor_height: Option<f64>,
    /// Background: `street` or `indoor` (built-in worlds, a new layout per sequence), an
    /// environment glTF (.glb/.gltf, rendered), a Velodyne .pcap, or a folder of KITTI .bin /
    /// PCD frames, a ROS 2 bag (.mcap or its folder) (recorded); `none` for an empty world.
    #[arg(long, visible_alias = "environment")]
    pub background: Option<PathBuf>,
    /// Sensor poses, KITTI poses.txt (3x4 per line) or TUM (t x y z qx qy qz qw).
    #[arg(long)]
    pub poses: Option<PathBuf>,
    /// An Ouster capture's sensor metadata JSON (default: the .json beside the .pcap, same stem).
    #[arg(long)]
    pub ouster_metadata: Option<PathBuf>,
    /// A ROS 2 bag background's PointCloud2 topic (default: the bag's only one).
    #[arg(long)]
    pub topic: Option<String>,
    /// A ROS 2 bag background's world frame for the poses from /tf (default: the first of odom, map, world that reaches the clouds' frame).
    #[arg(long)]
    pub world_frame: Option<String>,
    /// A ROS 2 bag background's nav_msgs/msg/Odometry topic giving the sensor's poses instead of /tf.
    #[arg(long)]
    pub poses_topic: Option<String>,
    /// Recorded pedestrian tracks to walk along (see --tracks-format).
    #[arg(long)]
    pub tracks: Option<PathBuf>,
    /// Format of --tracks: eth (obsmat.txt), eth4 (frame id x y), atc (CSV), csv (pedscan).
    #[arg(long, value_enum)]
    pub tracks_format: Option<crate::input::tracks::TrackFormat>,
    /// Seconds per frame number of eth / eth4 tracks (default 0.04).
    #[arg(long)]
    pub tracks_frame_period: Option<f64>,
    /// Places the tracks in the world: `X,Y,YAW_DEG[,SCALE]` (p_world = (X,Y) + SCALE R(YAW) p).
    #[arg(long, value_parser = parse_transform, allow_hyphen_values = true)]
    pub tracks_transform: Option<crate::input::tracks::Transform2>,
    /// Synthetic people walk to goals through the walkable area, or on arcs.
    #[arg(long, value_enum)]
    pub walk: Option<WalkMode>,
    /// Human models: a folder of .glb files or files (repeatable).
    #[arg(long)]
    pub models: Vec<PathBuf>,
    /// How people move: full, sliding, in-place, static (the paper's Table 5 ablations).
    #[arg(long, value_enum)]
    pub motion: Option<MotionMode>,
    /// How beams find surfaces: Vulkan raster (default) or the CPU ray caster.
    #[arg(long, value_enum)]
    pub backend: Option<BackendChoice>,
    /// Raster views: cube faces or one cylindrical panorama.
    #[arg(long, value_enum)]
    pub projection: Option<Projection>,
    /// Per-beam refinement of the raster result.
    #[arg(long, value_enum)]
    pub refine: Option<Refine>,
    /// Texels per beam spacing at a cube-face centre (cylinder: per column and elevation gap).
    #[arg(long)]
    pub oversample: Option<f64>,
    /// Velocity definition written to /velocity.
    #[arg(long, value_enum)]
    pub velocity: Option<VelocityModel>,
    /// HDF5 compression.
    #[arg(long, value_enum)]
    pub compression: Option<CompressionChoice>,
    /// Formats to write, comma separated: h5 (with the XML), semantickitti, mcap (a ROS 2 bag).
    #[arg(long, value_enum, value_delimiter = ',')]
    pub formats: Option<Vec<Format>>,
    /// Per-beam outputs to compute and store: range, label and instance always, plus any of
    /// xyz, velocity, background, class (comma separated, e.g. `range,label,instance,velocity`).
    #[arg(long, value_delimiter = ',')]
    pub outputs: Option<Vec<String>>,
    /// Turn on the Vulkan validation layer (slow; for debugging).
    #[arg(long)]
    pub validation: bool,
    /// The sensor model (rolling shutter, noise, dropout, divergence): `on` (default) or
    /// `off` for the paper's clean, instantaneous frames.
    #[arg(long, value_parser = parse_on_off)]
    pub sensor_model: Option<bool>,
    /// Each column at its own time over the sweep (`on`, default) or every column at the
    /// frame's time (`off`).
    #[arg(long, value_parser = parse_on_off)]
    pub rolling_shutter: Option<bool>,
    /// Also write each frame's posed human triangles (sensor frame) as PLY under this folder.
    #[arg(long)]
    pub export_geometry: Option<PathBuf>,
}

fn parse_on_off(s: &str) -> Result<bool, String> {
    match s {
        "on" | "true" => Ok(true),
        "off" | "false" => Ok(false),
        other => Err(format!("`{other}`: expected on or off")),
    }
}

fn parse_count(s: &str) -> Result<[usize; 2], String> {
    let parse = |t: &str| t.trim().parse::<usize>().map_err(|_| format!("`{s}` is not MIN..MAX or a number"));
    match s.split_once("..") {
        Some((a, b)) => Ok([parse(a)?, parse(b.trim_start_matches('='))?]),
        None => {
            let n = parse(s)?;
            Ok([n, n])
        }
    }
}

fn parse_transform(s: &str) -> Result<crate::input::tracks::Transform2, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>().map_err(|_| format!("`{s}`: `{t}` is not a number (want X,Y,YAW_DEG[,SCALE])")))
        .collect::<Result<_, _>>()?;
    if !(v.len() == 3 || v.len() == 4) || v.iter().any(|x| !x.is_finite()) {
        return Err(format!("`{s}`: want 3 or 4 finite numbers X,Y,YAW_DEG[,SCALE]"));
    }
    let scale = v.get(3).copied().unwrap_or(1.0);
    if scale <= 0.0 {
        return Err(format!("`{s}`: scale {scale} must be positive"));
    }
    Ok(crate::input::tracks::Transform2 { rotation_deg: v[2], translation_m: [v[0], v[1]], scale })
}

impl Flags {
    /// The configuration these flags give: the config file (or the defaults), each flag given
    /// over it, checked.
    pub fn config(&self) -> Result<Config> {
        let a = self;
        let mut cfg = match &a.config {
            Some(p) => Config::from_file(p)?,
            None => Config::default(),
        };
        if let Some(v) = a.sequences {
            cfg.sequences = v;
        }
        if let Some(v) = a.first_sequence {
            cfg.first_sequence = v;
        }
        if let Some(v) = a.frames {
            cfg.frames = v;
        }
        if let Some(v) = a.humans {
            cfg.humans.count = v;
        }
        if let Some(v) = a.seed {
            cfg.seed = v;
        }
        if let Some(v) = &a.out {
            cfg.out = v.clone();
        }
        cfg.png |= a.png;
        if let Some(v) = &a.device {
            cfg.device = v.clone();
        }
        cfg.render.keep_holes |= a.keep_holes;
        if let Some(v) = &a.sensor {
            cfg.sensor = v.clone();
        }
        if let Some(v) = a.sensor_height {
            if !super::usable_sensor_height(v) {
                return Err(Error::input("--sensor-height", format!("{v} is not a usable height (metres over the floor)")));
            }
            cfg.scene.sensor_height_m = v;
        }
        if let Some(v) = &a.background {
            cfg.scene.background = if v.as_os_str() == "none" { PathBuf::new() } else { v.clone() };
        }
        if let Some(v) = &a.poses {
            cfg.scene.poses = v.clone();
        }
        if let Some(v) = &a.ouster_metadata {
            cfg.scene.ouster_metadata = v.clone();
        }
        if let Some(v) = &a.topic {
            cfg.scene.topic = v.clone();
        }
        if let Some(v) = &a.world_frame {
            cfg.scene.world_frame = v.clone();
        }
        if let Some(v) = &a.poses_topic {
            cfg.scene.poses_topic = v.clone();
        }
        if let Some(v) = &a.tracks {
            cfg.humans.tracks = v.clone();
        }
        if let Some(v) = a.tracks_format {
            cfg.humans.tracks_format = v;
        }
        if let Some(v) = a.tracks_frame_period {
            cfg.humans.tracks_frame_period_s = v;
        }
        if let Some(v) = a.tracks_transform {
            cfg.humans.tracks_transform = v;
        }
        if let Some(v) = a.walk {
            cfg.humans.walk = v;
        }
        if !a.models.is_empty() {
            cfg.humans.models = a.models.clone();
        }
        if let Some(v) = a.motion {
            cfg.humans.motion = v;
        }
        if let Some(v) = a.backend {
            cfg.render.backend = v;
        }
        if let Some(v) = a.projection {
            cfg.render.projection = v;
        }
        if let Some(v) = a.refine {
            cfg.render.refine = v;
        }
        if let Some(v) = a.oversample {
            cfg.render.oversample = v;
        }
        if let Some(v) = a.velocity {
            cfg.output.velocity = v;
        }
        if let Some(v) = a.compression {
            cfg.output.compression = v;
        }
        if let Some(v) = &a.formats {
            cfg.output.formats = v.clone();
            cfg.output.formats.dedup();
        }
        if let Some(list) = &a.outputs {
            cfg.output.xyz = false;
            cfg.output.velocity_field = false;
            cfg.output.background = false;
            cfg.output.class = false;
            for o in list {
                match o.trim() {
                    "range" | "label" | "instance" => {}
                    "xyz" => cfg.output.xyz = true,
                    "velocity" => cfg.output.velocity_field = true,
                    "background" => cfg.output.background = true,
                    "class" => cfg.output.class = true,
                    other => {
                        return Err(Error::input(
                            "--outputs",
                            format!("unknown output `{other}` (range, label, instance, xyz, velocity, background, class)"),
                        ))
                    }
                }
            }
        }
        if let Some(on) = a.sensor_model {
            cfg.sensor_model.enabled = on;
        }
        if let Some(on) = a.rolling_shutter {
            cfg.sensor_model.rolling_shutter = on;
        }
        cfg.debug.validation |= a.validation;
        cfg.validate()?;
        // `bundled:<name>` given as a flag names the bundled data as it does in a file.
        for p in cfg.input_paths_mut() {
            *p = super::resolve_bundled(p);
        }
        if cfg.sensor.starts_with(super::BUNDLED) {
            cfg.sensor = super::resolve_bundled(Path::new(&cfg.sensor)).display().to_string();
        }
        Ok(cfg)
    }
}
