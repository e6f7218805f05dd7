//! The ROS 2 bag export (`--formats ...,mcap`): per sequence a rosbag2 folder
//! `OUT/seq_NNNNNN_bag/` holding `seq_NNNNNN.mcap` and the `metadata.yaml` that `ros2 bag
//! info` and `ros2 bag play` read (the `.mcap` also opens on its own in Foxglove, `mcap`
//! and rosbag2's MCAP plugin). MCAP with the `ros2` profile, `ros2msg` schemas, CDR messages,
//! chunks with message indexes and a summary. Topics, one message per frame each:
//!
//! - `/pedscan/points`, `sensor_msgs/msg/PointCloud2`, frame `pedscan_sensor`, organized
//!   H x W (row 0 = highest beam, as the grid), 40-byte points: `x y z intensity` f32
//!   (`/intensity`), `ring` u16 (0 = lowest beam, as Velodyne's driver), `instance` u16,
//!   `time` f32 (seconds after the stamp: the column's time, `/sensor/column_time_s`, minus
//!   the frame's), `vx vy vz` f32 (`/velocity`), `label` u8 (`/label`: 255 = not scored);
//!   a beam without return has x = y = z = NaN (`is_dense` false when a frame has one).
//! - `/tf`, `tf2_msgs/msg/TFMessage`: `world` -> `pedscan_sensor` (`world_from_sensor`).
//!
//! Stamps are the sequence's time plus [`STAMP_BASE_S`], so every stamp is a plausible
//! positive ROS time. The bag is written into `seq_NNNNNN_bag.tmp/` and renamed when complete.

use crate::error::{Error, Result};
use crate::output::{FrameOutput, SequenceMeta};
use glam::{DMat3, DQuat, DVec3};
use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Seconds added to the sequence time for ROS stamps (2001-09-09T01:46:40Z).
pub const STAMP_BASE_S: u64 = 1_000_000_000;
/// Frame ids.
pub const SENSOR_FRAME: &str = "pedscan_sensor";
pub const WORLD_FRAME: &str = "world";
/// Topics.
pub const POINTS_TOPIC: &str = "/pedscan/points";
pub const TF_TOPIC: &str = "/tf";
/// Bytes per point of `/pedscan/points`.
pub const POINT_STEP: u32 = 40;

/// The bag folder of sequence `index`.
pub fn bag_dir(out_dir: &Path, index: usize) -> PathBuf {
    out_dir.join(format!("{}_bag", super::sequence_stem(index)))
}

const SEPARATOR: &str = "================================================================================\n";

fn time_msg() -> String {
    "int32 sec\nuint32 nanosec\n".into()
}

fn header_deps() -> String {
    format!("{SEPARATOR}MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n{SEPARATOR}MSG: builtin_interfaces/Time\n{}", time_msg())
}

/// `sensor_msgs/msg/PointCloud2` in the ros2msg schema encoding (dependencies appended).
pub(crate) fn point_cloud2_schema() -> String {
    format!(
        "std_msgs/Header header\nuint32 height\nuint32 width\nsensor_msgs/PointField[] fields\nbool is_bigendian\n\
         uint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n{}{SEPARATOR}MSG: sensor_msgs/PointField\n\
         uint8 INT8=1\nuint8 UINT8=2\nuint8 INT16=3\nuint8 UINT16=4\nuint8 INT32=5\nuint8 UINT32=6\nuint8 FLOAT32=7\nuint8 FLOAT64=8\n\
         string name\nuint32 offset\nuint8 datatype\nuint32 count\n",
        header_deps()
    )
}

/// `tf2_msgs/msg/TFMessage` in the ros2msg schema encoding.
pub(crate) fn tf_message_schema() -> String {
    format!(
        "geometry_msgs/TransformStamped[] transforms\n{SEPARATOR}MSG: geometry_msgs/TransformStamped\n\
         std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n\
         {SEPARATOR}MSG: geometry_msgs/Transform\ngeometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n\
         {SEPARATOR}MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n\
         {SEPARATOR}MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n{}",
        header_deps()
    )
}

/// A little-endian CDR (XCDR1) message: the encapsulation header, then fields aligned to
/// their size relative to the end of the header.
pub(crate) struct Cdr(pub(crate) Vec<u8>);

impl Cdr {
    pub(crate) fn new() -> Cdr {
        Cdr(vec![0, 1, 0, 0])
    }
    pub(crate) fn align(&mut self, n: usize) {
        while (self.0.len() - 4) % n != 0 {
            self.0.push(0);
        }
    }
    pub(crate) fn u8(&mut self, v: u8) {
        self.0.push(v);
    }
    pub(crate) fn u32(&mut self, v: u32) {
        self.align(4);
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn i32(&mut self, v: i32) {
        self.align(4);
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn f64(&mut self, v: f64) {
        self.align(8);
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.0.extend_from_slice(s.as_bytes());
        self.0.push(0);
    }
    pub(crate) fn header(&mut self, stamp_ns: u64, frame: &str) {
        self.i32((stamp_ns / 1_000_000_000) as i32);
        self.u32((stamp_ns % 1_000_000_000) as u32);
        self.string(frame);
    }
}

/// The PointField table: (name, offset, datatype).
const FIELDS: [(&str, u32, u8); 11] = [
    ("x", 0, 7),
    ("y", 4, 7),
    ("z", 8, 7),
    ("intensity", 12, 7),
    ("ring", 16, 4),
    ("instance", 18, 4),
    ("time", 20, 7),
    ("vx", 24, 7),
    ("vy", 28, 7),
    ("vz", 32, 7),
    ("label", 36, 2),
];

/// Writes one sequence's bag.
pub struct Ros2BagWriter {
    tmp: PathBuf,
    fin: PathBuf,
    mcap_name: String,
    writer: Option<mcap::Writer<BufWriter<std::fs::File>>>,
    points: u16,
    tf: u16,
    dirs: Arc<[DVec3]>,
    rows: usize,
    columns: usize,
    velocity: bool,
    stamps: Vec<u64>,
    data: Vec<u8>,
}

fn mcap_err(path: &Path) -> impl Fn(mcap::McapError) -> Error + '_ {
    move |e| match e {
        mcap::McapError::Io(io) => Error::io(path, io),
        other => Error::Internal(format!("{}: MCAP: {other}", path.display())),
    }
}

impl Ros2BagWriter {
    /// Creates `OUT/seq_NNNNNN_bag.tmp/seq_NNNNNN.mcap` (an older temporary is replaced).
    /// `dirs`: the sensor's unit beam directions.
    pub fn create(out_dir: &Path, meta: &SequenceMeta, dirs: Arc<[DVec3]>) -> Result<Ros2BagWriter> {
        let fin = bag_dir(out_dir, meta.index);
        let tmp = super::files::fresh_tmp_dir(&fin)?;
        let mcap_name = format!("{}.mcap", super::sequence_stem(meta.index));
        let path = tmp.join(&mcap_name);
        let file = std::fs::File::create(&path).map_err(|e| Error::io(&path, e))?;
        let opts = mcap::WriteOptions::new().profile("ros2").library(format!("pedscan {}", env!("CARGO_PKG_VERSION"))).compression(None);
        let mut w = mcap::Writer::with_options(BufWriter::new(file), opts).map_err(mcap_err(&path))?;
        let pc2 = w.add_schema("sensor_msgs/msg/PointCloud2", "ros2msg", point_cloud2_schema().as_bytes()).map_err(mcap_err(&path))?;
        let tfm = w.add_schema("tf2_msgs/msg/TFMessage", "ros2msg", tf_message_schema().as_bytes()).map_err(mcap_err(&path))?;
        let none = BTreeMap::new();
        let points = w.add_channel(pc2, POINTS_TOPIC, "cdr", &none).map_err(mcap_err(&path))?;
        let tf = w.add_channel(tfm, TF_TOPIC, "cdr", &none).map_err(mcap_err(&path))?;
        Ok(Ros2BagWriter {
            tmp,
            fin,
            mcap_name,
            writer: Some(w),
            points,
            tf,
            dirs,
            rows: meta.sensor.rows(),
            columns: meta.sensor.columns,
            velocity: meta.outputs.velocity,
            stamps: Vec::new(),
            data: Vec::new(),
        })
    }

    /// The bag folder when complete.
    pub fn final_dir(&self) -> &Path {
        &self.fin
    }

    /// The temporary folder (removed by the owner when the sequence fails).
    pub fn tmp_dir(&self) -> &Path {
        &self.tmp
    }

    fn path(&self) -> PathBuf {
        self.tmp.join(&self.mcap_name)
    }

    /// Writes frame `index`: its point cloud and its transform.
    pub fn write_frame(&mut self, index: usize, f: &FrameOutput) -> Result<()> {
        let stamp = STAMP_BASE_S * 1_000_000_000 + (f.time_s * 1e9).round().max(0.0) as u64;
        self.stamps.push(stamp);
        let (rows, cols) = (self.rows, self.columns);
        self.data.clear();
        self.data.resize(rows * cols * POINT_STEP as usize, 0);
        for (b, p) in self.data.chunks_exact_mut(POINT_STEP as usize).enumerate() {
            let r = f.range[b];
            let xyz = f.point(&self.dirs, b).unwrap_or([f32::NAN; 3]);
            let v = if self.velocity && r > 0.0 { f.velocity[b] } else { [0.0; 3] };
            let ring = (rows - 1 - b / cols) as u16;
            let put = |p: &mut [u8], at: usize, bytes: &[u8]| p[at..at + bytes.len()].copy_from_slice(bytes);
            for (k, c) in xyz.iter().enumerate() {
                put(p, 4 * k, &c.to_le_bytes());
            }
            put(p, 12, &f.intensity[b].to_le_bytes());
            put(p, 16, &ring.to_le_bytes());
            put(p, 18, &f.instance[b].to_le_bytes());
            put(p, 20, &((f.column_time_s[b % cols] - f.time_s) as f32).to_le_bytes());
            for (k, c) in v.iter().enumerate() {
                put(p, 24 + 4 * k, &c.to_le_bytes());
            }
            p[36] = f.label[b];
        }
        let mut m = Cdr::new();
        m.header(stamp, SENSOR_FRAME);
        m.u32(rows as u32);
        m.u32(cols as u32);
        m.u32(FIELDS.len() as u32);
        for (name, offset, datatype) in FIELDS {
            m.string(name);
            m.u32(offset);
            m.u8(datatype);
            m.u32(1);
        }
        m.u8(0);
        m.u32(POINT_STEP);
        m.u32(POINT_STEP * cols as u32);
        m.u32(self.data.len() as u32);
        m.0.extend_from_slice(&self.data);
        m.u8(f.range.iter().all(|&r| r > 0.0) as u8);
        let path = self.path();
        let w = self.writer.as_mut().expect("open until finish");
        let header = |channel_id| mcap::records::MessageHeader { channel_id, sequence: index as u32, log_time: stamp, publish_time: stamp };
        w.write_to_known_channel(&header(self.points), &m.0).map_err(mcap_err(&path))?;

        let pose = f.world_from_sensor;
        let rot = DMat3::from_cols_array_2d(&[
            [pose[0][0], pose[1][0], pose[2][0]],
            [pose[0][1], pose[1][1], pose[2][1]],
            [pose[0][2], pose[1][2], pose[2][2]],
        ]);
        let q = DQuat::from_mat3(&rot).normalize();
        let mut t = Cdr::new();
        t.u32(1);
        t.header(stamp, WORLD_FRAME);
        t.string(SENSOR_FRAME);
        for c in [pose[0][3], pose[1][3], pose[2][3], q.x, q.y, q.z, q.w] {
            t.f64(c);
        }
        w.write_to_known_channel(&header(self.tf), &t.0).map_err(mcap_err(&path))?;
        Ok(())
    }

    /// Finishes the MCAP file, writes `metadata.yaml` and renames the folder into place.
    pub fn finish(mut self) -> Result<PathBuf> {
        let path = self.path();
        if let Some(mut w) = self.writer.take() {
            w.finish().map_err(mcap_err(&path))?;
        }
        let yaml = self.metadata();
        let meta = self.tmp.join("metadata.yaml");
        std::fs::write(&meta, yaml).map_err(|e| Error::io(&meta, e))?;
        super::files::replace_dir(&self.tmp, &self.fin)?;
        Ok(self.fin.clone())
    }

    /// rosbag2's `metadata.yaml` (version 5) for the one MCAP file.
    fn metadata(&self) -> String {
        let start = self.stamps.iter().copied().min().unwrap_or(0);
        let duration = self.stamps.iter().copied().max().unwrap_or(0) - start;
        let n = self.stamps.len();
        let topic = |name: &str, ty: &str| {
            format!(
                "    - topic_metadata:\n        name: {name}\n        type: {ty}\n        serialization_format: cdr\n        offered_qos_profiles: \"\"\n      message_count: {n}\n"
            )
        };
        format!(
            "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: mcap\n  duration:\n    nanoseconds: {duration}\n  starting_time:\n    nanoseconds_since_epoch: {start}\n  message_count: {}\n  topics_with_message_count:\n{}{}  compression_format: \"\"\n  compression_mode: \"\"\n  relative_file_paths:\n    - {}\n  files:\n    - path: {}\n      starting_time:\n        nanoseconds_since_epoch: {start}\n      duration:\n        nanoseconds: {duration}\n      message_count: {}\n",
            2 * n,
            topic(POINTS_TOPIC, "sensor_msgs/msg/PointCloud2"),
            topic(TF_TOPIC, "tf2_msgs/msg/TFMessage"),
            self.mcap_name,
            self.mcap_name,
            2 * n
        )
    }
}
