//! Stage 8: writers. One sequence = one file set (`seq_NNNNNN.h5`, `seq_NNNNNN.xml`, optional
//! PNGs), each written under a temporary name and renamed when complete, so a failure never
//! leaves a partial file and never touches sequences written before.
//!
//! The pipeline hands over plain structs: [`SequenceMeta`] once, then one [`FrameOutput`] per
//! frame, in order. Grids are row-major `row * columns + col`, row 0 = highest beam.

use crate::sensor::Sensor;

pub(crate) mod files;
mod h5;
mod info;
pub mod lock;
pub mod manifest;
mod pipeline;
pub mod ply;
pub mod png;
pub mod ros2bag;
pub mod semantickitti;
mod writer;
mod xml;

pub use info::info;
pub use pipeline::write_frames;
pub use png::{label_png, range_png, velocity_png};
pub use files::sequence_stem;
pub(crate) use files::write_file;
pub use h5::Compression;
pub use writer::{Finished, SequenceWriter, WriterOptions};

/// What a sequence is about; written once per sequence.
#[derive(Clone, Debug)]
pub struct SequenceMeta {
    /// Sequence number: files are named `seq_{index:06}`.
    pub index: usize,
    /// The seed that produced this sequence.
    pub seed: u64,
    pub sensor: Sensor,
    /// The full, resolved configuration as TOML text (root attribute `config`).
    pub config_toml: String,
    /// Number of frames that will be written.
    pub frames: usize,
    /// The people of the sequence; instance k (1-based) is `humans[k - 1]`.
    pub humans: Vec<HumanMeta>,
    /// The other movers (a built-in street's cars and cyclists); instance `N + 1 + j` is
    /// `movers[j]`, N people.
    pub movers: Vec<MoverMeta>,
    /// Which optional per-beam outputs are present in every frame.
    pub outputs: OutputSet,
    /// `/velocity` follows the `rigid` model (the sensor's yaw rate subtracted as well).
    pub rigid_velocity: bool,
    /// Where the background and the people come from, as `key=value` lines (root attribute
    /// `provenance`, XML element `<provenance>`): the recorded frames used, the floor, the
    /// window of the tracks.
    pub provenance: Vec<(String, String)>,
}

/// One person of a sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct HumanMeta {
    pub height_m: f32,
    pub weight_kg: f32,
    /// Model name (file stem of the glTF, e.g. `h1700_w60`).
    pub model: String,
    /// Seated the whole sequence on a seat this high, m (`humans.sitting`); None: not seated.
    pub seat_m: Option<f32>,
    /// What the person pushes the whole sequence (`stroller`, `trolley`; `humans.pushing`).
    pub pushing: Option<String>,
}

/// One mover of a sequence (a car, a cyclist).
#[derive(Clone, Debug, PartialEq)]
pub struct MoverMeta {
    /// What it is: `car`, `cyclist`.
    pub kind: String,
    /// Its footprint's length and width, m.
    pub length_m: f32,
    pub width_m: f32,
    /// The person pushing it: their id (instance, 1..N); 0 for a mover nobody pushes.
    pub pushed_by: u32,
}

/// State of one mover at one frame (world frame): the centre of its footprint on the ground.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MoverState {
    pub position_m: [f64; 3],
    pub heading_rad: f32,
    pub velocity_mps: [f32; 3],
    /// Its turning rate, rad/s: a point `r` from the centre moves at `velocity + w z x r`.
    pub yaw_rate_rps: f32,
}

/// The `/label` of a beam that is not scored: its return is a recorded background's that
/// `scene.ignore_moving` or `scene.ignore_labels` marks (the recording's own people); the
/// training loss and `evaluate` skip it.
pub const NOT_SCORED: u8 = 255;

/// Which optional datasets are computed and written (range, label and instance always are).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OutputSet {
    pub xyz: bool,
    pub velocity: bool,
    pub background: bool,
    /// `/clean/*`: range, label and instance before the sensor model (written when it is on).
    pub clean: bool,
    /// `/class`: each beam's SemanticKITTI class.
    pub class: bool,
}

impl Default for OutputSet {
    fn default() -> Self {
        OutputSet { xyz: true, velocity: true, background: true, clean: false, class: false }
    }
}

/// State of one person at one frame (world frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HumanState {
    pub position_m: [f64; 3],
    pub heading_rad: f32,
    pub velocity_mps: [f32; 3],
    /// Gait phase in [0, 1).
    pub gait_phase: f32,
}

/// Everything of one frame. Per-beam vectors have `rows * columns` entries.
#[derive(Clone, Debug, Default)]
pub struct FrameOutput {
    /// Metres, 0 = no return.
    pub range: Vec<f32>,
    /// 0 background / no return, 1 human, [`NOT_SCORED`] a recorded background's own
    /// person (or other return) that is not scored.
    pub label: Vec<u8>,
    /// 0 none, k <= N: the k-th person, k > N: mover k - N (N people).
    pub instance: Vec<u16>,
    /// Sensor frame xyz, metres (present iff `OutputSet::xyz`).
    pub xyz: Vec<[f32; 3]>,
    /// Sensor-frame velocity of the surface point relative to the sensor, m/s
    /// (present iff `OutputSet::velocity`).
    pub velocity: Vec<[f32; 3]>,
    /// Range of the background alone, metres, 0 = no return (present iff `OutputSet::background`).
    pub background_range: Vec<f32>,
    /// Return intensity per beam (see `crate::sensor_model`), 0 = no return.
    pub intensity: Vec<f32>,
    /// SemanticKITTI class per beam, 0 = no return or not scored (present iff
    /// `OutputSet::class`).
    pub class: Vec<u16>,
    /// Range, label and instance before the sensor model (present iff `OutputSet::clean`).
    pub clean_range: Vec<f32>,
    pub clean_label: Vec<u8>,
    pub clean_instance: Vec<u16>,
    /// Per column: the time its beams were fired, seconds since the start of the sequence.
    pub column_time_s: Vec<f64>,
    /// Seconds since the start of the sequence.
    pub time_s: f64,
    /// Row-major 4x4 pose of the sensor in the world.
    pub world_from_sensor: [[f64; 4]; 4],
    /// The sensor's own velocity, world frame, m/s (the exact derivative of its trajectory).
    pub sensor_velocity_mps: [f64; 3],
    /// The sensor's yaw rate about the world z axis, rad/s.
    pub sensor_yaw_rate_rps: f64,
    /// One entry per person of the sequence (same order as `SequenceMeta::humans`).
    pub humans: Vec<HumanState>,
    /// One entry per mover (same order as `SequenceMeta::movers`).
    pub movers: Vec<MoverState>,
}

impl FrameOutput {
    /// The sensor-frame point of beam `b` (None without a return): `/xyz` when the frame has
    /// it, else its range along `dirs[b]`, the sensor's unit beam direction. Every format
    /// writes its points through this, so they agree with `/xyz`.
    pub fn point(&self, dirs: &[glam::DVec3], b: usize) -> Option<[f32; 3]> {
        let r = self.range[b];
        if r <= 0.0 {
            None
        } else if self.xyz.len() == self.range.len() {
            Some(self.xyz[b])
        } else {
            Some((dirs[b] * r as f64).as_vec3().to_array())
        }
    }
}
