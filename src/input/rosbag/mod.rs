//! ROS 2 bags as recorded backgrounds: a rosbag2 folder (`metadata.yaml` and its `.mcap`
//! files) or one `.mcap` file.
//!
//! * **Clouds**: `sensor_msgs/msg/PointCloud2` messages (CDR) on one topic (`scene.topic`;
//!   by default the bag's only PointCloud2 topic, else an error listing them), organized or
//!   not, either byte order. Fields: `x y z` (FLOAT32 or FLOAT64), when present `intensity`
//!   (any numeric type, the source's units), `ring` (an integer type: 0 = the lowest beam, the
//!   ROS drivers' convention) and a per-point time, in each vendor's convention:
//!   `t` (UINT32, ns after the header stamp: Ouster), `time` (FLOAT32, s after the header
//!   stamp: Velodyne, pedscan's own bags), `timestamp` (FLOAT64, absolute s: Hesai). Points
//!   that are not finite or all zero are no returns.
//! * **Times**: each cloud's header stamp. Clouds are taken in stamp order; a cloud with the
//!   stamp of an earlier one is dropped (counted in the description).
//! * **Sweeps**: with a per-point time, each cloud carries its firings
//!   ([`crate::input::Scan::firing_times`]): its points in time order, one per distinct time,
//!   with their azimuth.
//! * **Rings**: with a `ring` field, each ring's elevation is measured as the median
//!   elevation of its points in the first cloud that has them, so rings choose the target
//!   grid's rows as a capture's lasers do ([`crate::input::project`]).
//! * **Poses**, when no poses file is given: `world_from_cloud` at each cloud's stamp from
//!   the transform tree of `/tf` and `/tf_static` (`tf2_msgs/msg/TFMessage`), from the world
//!   frame (`scene.world_frame`; by default the first of `odom`, `map`, `world` connected to
//!   the cloud's frame) to the cloud's `header.frame_id`; or, with `scene.poses_topic`, from
//!   a `nav_msgs/msg/Odometry` topic (its `header.frame_id` is the world, composed with the
//!   tree from its `child_frame_id` to the cloud's frame). Transforms are interpolated, never
//!   extrapolated: clouds before the first or after the last transform of their chain are
//!   dropped (counted). A bag with no transforms at all and no odometry gives no poses (the
//!   sensor is then taken as static, and the run says so).
//!
//! Bad input names the file and, for a message, its index and topic: a bag without
//! PointCloud2, a topic that does not exist, a cloud whose frame has no transform chain to the
//! world, a point step smaller than its fields, a truncated or lying record. Records are read
//! one at a time, each at most [`RECORD_LIMIT`] bytes, and each cloud is handed to the caller
//! as it is read, so memory stays bounded by what the caller keeps.

pub mod cdr;
pub mod records;
pub mod tf;

use super::Scan;
use crate::error::{Error, Result};
use cdr::{datatype_size, Cloud, Field, Transform};
use glam::DMat4;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

pub use records::RECORD_LIMIT;
/// The most points one cloud may hold.
pub const MAX_POINTS: u64 = 1 << 24;
/// The world frames tried, in order, when none is given.
pub const DEFAULT_WORLD_FRAMES: [&str; 3] = ["odom", "map", "world"];

const POINT_CLOUD2: &str = "sensor_msgs/msg/PointCloud2";
const TF_MESSAGE: &str = "tf2_msgs/msg/TFMessage";
const ODOMETRY: &str = "nav_msgs/msg/Odometry";

/// What to read from a bag.
#[derive(Clone, Debug, Default)]
pub struct BagOptions {
    /// The PointCloud2 topic; `None`: the bag's only one.
    pub topic: Option<String>,
    /// The world frame of the poses; `None`: the first of [`DEFAULT_WORLD_FRAMES`] connected.
    pub world_frame: Option<String>,
    /// An Odometry topic giving the poses instead of `/tf`.
    pub poses_topic: Option<String>,
    /// Poses come from elsewhere (a poses file): the transforms are not needed.
    pub no_poses: bool,
    /// Stop after this many clouds of the topic (a look at the data, not a background).
    pub max_clouds: Option<usize>,
}

/// A bag read: per kept cloud, what the caller made of it, its stamp and pose.
pub struct Bag<T> {
    /// In stamp order.
    pub frames: Vec<T>,
    /// Stamps, s after the first kept cloud's, strictly increasing.
    pub times_s: Vec<f64>,
    /// The first kept cloud's stamp, ns since the epoch.
    pub start_ns: i64,
    /// `world_from_cloud` per frame, when the bag has transforms.
    pub poses: Option<Vec<DMat4>>,
    /// Ring elevations measured from the data (degrees, indexed by ring), when clouds have rings.
    pub ring_elevation_deg: Option<Vec<f64>>,
    /// One line: files, topic, frame, counts, where the poses come from.
    pub description: String,
}

/// True when `path` is a ROS 2 bag: an `.mcap` file or a folder with a `metadata.yaml`.
pub fn is_bag(path: &Path) -> bool {
    if path.is_dir() {
        std::fs::symlink_metadata(path.join("metadata.yaml")).is_ok()
    } else {
        path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
    }
}

/// The `.mcap` files of a bag, in order: a file itself; a folder's `relative_file_paths` from
/// its `metadata.yaml`, else its `.mcap` files by name.
pub fn mcap_files(path: &Path) -> Result<Vec<PathBuf>> {
    if !path.is_dir() {
        super::file_len(path)?;
        return Ok(vec![path.to_path_buf()]);
    }
    let meta = path.join("metadata.yaml");
    let yaml = super::read_text(&meta)?;
    let mut listed = Vec::new();
    let mut in_list = false;
    for line in yaml.lines() {
        let t = line.trim();
        if let Some(s) = t.strip_prefix("storage_identifier:") {
            let s = s.trim().trim_matches(|c| c == '"' || c == '\'');
            if s != "mcap" {
                return Err(Error::input(
                    meta.display(),
                    format!("the bag is stored as '{s}'; pedscan reads MCAP bags (convert it: ros2 bag convert, storage_id: mcap)"),
                ));
            }
        }
        if in_list {
            match t.strip_prefix("- ") {
                Some(f) if line.starts_with(' ') || line.starts_with('-') => {
                    listed.push(path.join(f.trim().trim_matches(|c| c == '"' || c == '\'')));
                    continue;
                }
                _ => in_list = false,
            }
        }
        if t == "relative_file_paths:" {
            in_list = true;
        }
    }
    if listed.is_empty() {
        listed = super::folder_files(path, |f| !f.is_dir() && is_bag(f))?;
    }
    if listed.is_empty() {
        return Err(Error::input(meta.display(), "lists no .mcap file and the folder holds none"));
    }
    for f in &listed {
        super::file_len(f)?;
    }
    Ok(listed)
}

/// Where a message came from, for errors.
fn at(file: &Path, index: usize, topic: &str) -> String {
    format!("{}: message {index} on {topic}", file.display())
}

/// Reads the bag at `path`; `per_cloud` turns each kept cloud (as a [`Scan`] in the cloud's
/// frame, `time_s` its stamp, beside the message) into what the caller keeps, as it is read.
pub fn read_bag<T>(path: &Path, opts: &BagOptions, mut per_cloud: impl FnMut(&Scan, &Cloud) -> Result<T>) -> Result<Bag<T>> {
    let files = mcap_files(path)?;
    let mut clouds_topics: BTreeSet<String> = BTreeSet::new();
    let mut chosen: Option<String> = opts.topic.clone();
    let mut kept: Vec<(i64, String, T)> = Vec::new();
    let mut tree = tf::Tree::default();
    let mut odometry: Vec<Transform> = Vec::new();
    let mut ring_elevation: Option<Vec<f64>> = None;
    let mut total_points = 0u64;
    let mut first_layout = String::new();
    let mut epoch_ns: Option<i64> = None;
    let mut cut_short = 0;
    'files: for file in &files {
        let (f, len) = super::open_file(file)?;
        let named = |b: records::Bad| Error::input(format!("{} (byte {})", file.display(), b.at), b.why);
        let mut reader = records::Reader::new(std::io::BufReader::new(f), Some(len)).map_err(named)?;
        let mut index = 0;
        while let Some((channel, data)) = reader.next_message().map_err(named)? {
            index += 1;
            let index = index - 1;
            let topic = channel.topic.as_str();
            let schema = channel.schema.as_str();
            let encoding = channel.message_encoding.as_str();
            let wanted = schema == POINT_CLOUD2 || schema == TF_MESSAGE || schema == ODOMETRY;
            if wanted && encoding != "cdr" {
                return Err(Error::input(at(file, index, topic), format!("{schema} in encoding '{encoding}'; pedscan reads CDR")));
            }
            let bad = |why: String| Error::input(at(file, index, topic), why);
            match schema {
                POINT_CLOUD2 => {
                    clouds_topics.insert(topic.to_string());
                    let chosen = chosen.get_or_insert_with(|| topic.to_string());
                    if chosen != topic {
                        continue;
                    }
                    let cloud = Cloud::decode(&data).map_err(bad)?;
                    if first_layout.is_empty() {
                        first_layout = layout(&cloud);
                    }
                    let epoch = *epoch_ns.get_or_insert(cloud.stamp_ns);
                    let mut scan = to_scan(&cloud, epoch).map_err(bad)?;
                    total_points += scan.points.len() as u64;
                    if ring_elevation.is_none() {
                        ring_elevation = measure_rings(&scan);
                    }
                    if scan.ring.is_some() {
                        scan.ring_elevation_deg = ring_elevation.clone();
                    }
                    let made = per_cloud(&scan, &cloud)?;
                    kept.push((cloud.stamp_ns, cloud.frame_id, made));
                    if opts.max_clouds.is_some_and(|n| kept.len() >= n) {
                        break 'files;
                    }
                }
                TF_MESSAGE if (topic == "/tf" || topic == "/tf_static") && !opts.no_poses => {
                    for t in cdr::decode_tf(&data).map_err(bad)? {
                        tree.add(&t, topic == "/tf_static").map_err(bad)?;
                    }
                }
                ODOMETRY if opts.poses_topic.as_deref() == Some(topic) && !opts.no_poses => {
                    odometry.push(cdr::decode_odometry(&data).map_err(bad)?);
                }
                _ => {}
            }
        }
        cut_short += reader.cut_short as usize;
    }
    tree.finish();
    let name = path.display();
    if clouds_topics.is_empty() {
        return Err(Error::input(name, format!("holds no {POINT_CLOUD2} message")));
    }
    let topic = chosen.expect("a PointCloud2 topic was seen");
    if opts.topic.is_none() && clouds_topics.len() > 1 {
        let list: Vec<&str> = clouds_topics.iter().map(String::as_str).collect();
        return Err(Error::input(name, format!("holds {} PointCloud2 topics ({}): choose one with --topic", list.len(), list.join(", "))));
    }
    if !clouds_topics.contains(&topic) {
        let list: Vec<&str> = clouds_topics.iter().map(String::as_str).collect();
        return Err(Error::input(name, format!("has no PointCloud2 topic '{topic}' (it has: {})", list.join(", "))));
    }
    if let Some(p) = &opts.poses_topic {
        if odometry.is_empty() && !opts.no_poses {
            return Err(Error::input(name, format!("has no {ODOMETRY} message on '{p}' (scene.poses_topic)")));
        }
    }
    // Stamp order; a repeated stamp keeps its first cloud.
    kept.sort_by_key(|k| k.0);
    let before = kept.len();
    kept.dedup_by_key(|k| k.0);
    let repeated = before - kept.len();
    if let Some((_, f, _)) = kept.iter().find(|k| k.1 != kept[0].1) {
        return Err(Error::input(name, format!("clouds on {topic} come in two frames, '{}' and '{f}'", kept[0].1)));
    }
    let frame = kept[0].1.clone();
    let (poses, pose_note) = if opts.no_poses {
        (None, "poses from the poses file".to_string())
    } else if opts.poses_topic.is_some() {
        let (p, n) = odometry_poses(&odometry, &tree, &frame, &kept, opts).map_err(|w| Error::input(name.to_string(), w))?;
        (Some(p), n)
    } else if tree.is_empty() {
        (None, "no transforms: no poses".to_string())
    } else {
        let world = world_frame(&tree, &frame, opts).map_err(|w| Error::input(name.to_string(), w))?;
        let poses = kept.iter().map(|k| tree.lookup(&world, &frame, k.0).ok()).collect();
        (Some(poses), format!("poses from /tf, '{world}' -> '{frame}'"))
    };
    let mut times_s = Vec::with_capacity(kept.len());
    let mut frames = Vec::with_capacity(kept.len());
    let mut kept_poses = Vec::with_capacity(kept.len());
    let mut outside = 0;
    let clouds = kept.len();
    let mut start_ns = None;
    let poses_per_cloud: Vec<Option<Option<DMat4>>> = match poses {
        Some(p) => p.into_iter().map(Some).collect(),
        None => (0..clouds).map(|_| None).collect(),
    };
    for ((stamp, _, made), pose) in kept.into_iter().zip(poses_per_cloud) {
        match pose {
            Some(None) => outside += 1,
            pose => {
                let start = *start_ns.get_or_insert(stamp);
                kept_poses.extend(pose.flatten());
                times_s.push((stamp - start) as f64 * 1e-9);
                frames.push(made);
            }
        }
    }
    if frames.is_empty() {
        return Err(Error::input(name, format!("none of its {clouds} clouds on {topic} lies within the time its transforms cover")));
    }
    let has_poses = !kept_poses.is_empty();
    let description = format!(
        "ROS 2 bag ({} MCAP file{}): {} clouds on {topic} in frame '{frame}' ({first_layout}; {:.0} points a cloud), {pose_note}{}{}{}",
        files.len(),
        if files.len() == 1 { "" } else { "s" },
        frames.len(),
        total_points as f64 / clouds as f64,
        if outside > 0 { format!(", {outside} clouds outside the transforms' times dropped") } else { String::new() },
        if repeated > 0 { format!(", {repeated} clouds repeating a stamp dropped") } else { String::new() },
        if cut_short > 0 { format!(", {cut_short} file(s) end without their data end record (read up to there)") } else { String::new() },
    );
    let start_ns = start_ns.expect("a frame was kept");
    Ok(Bag { frames, times_s, start_ns, poses: has_poses.then_some(kept_poses), ring_elevation_deg: ring_elevation, description })
}

/// The grid a bag's clouds were taken on, from their `ring` field and its first clouds: a row
/// per ring at its measured elevation, as many columns as an organized cloud's width (when its
/// height is the ring count) or else the most returns one ring gave in one cloud, the rate
/// from the median step of their stamps (10 Hz from a single cloud), the range limits of a
/// sensor file (0.5 to 100 m).
pub fn sensor_of_bag(path: &Path, opts: &BagOptions) -> Result<crate::sensor::Sensor> {
    /// Clouds looked at.
    const CLOUDS: usize = 10;
    let look = BagOptions { no_poses: true, max_clouds: Some(CLOUDS), ..opts.clone() };
    let bag = read_bag(path, &look, |scan, cloud| {
        let Some(rings) = &scan.ring else { return Ok((0, 0, 0)) };
        let mut per = vec![0usize; rings.iter().map(|&r| r as usize + 1).max().unwrap_or(0)];
        for &r in rings {
            per[r as usize] += 1;
        }
        let most = per.iter().copied().max().unwrap_or(0);
        Ok((most, cloud.height as usize, cloud.width as usize))
    })?;
    let name = path.display();
    let Some(elevation) = bag.ring_elevation_deg else {
        return Err(Error::input(name, "its clouds have no `ring` field (or no returns), so the data does not give the grid: name the sensor (--sensor)"));
    };
    if let Some(r) = elevation.iter().position(|e| !e.is_finite()) {
        return Err(Error::input(name, format!("ring {r} has no return in the first cloud, so its elevation is unknown: name the sensor (--sensor)")));
    }
    let rows = elevation.len();
    let organized = bag.frames.iter().find(|f| f.1 == rows).map(|f| f.2);
    let columns = organized.unwrap_or_else(|| bag.frames.iter().map(|f| f.0).max().unwrap_or(0));
    let mut steps: Vec<f64> = bag.times_s.windows(2).map(|w| w[1] - w[0]).collect();
    steps.sort_by(f64::total_cmp);
    let rate_hz = steps.get(steps.len() / 2).map_or(10.0, |s| 1.0 / s);
    let file = crate::sensor::SensorFile { name: None, elevation_deg: elevation, columns, rate_hz: Some(rate_hz), min_range_m: None, max_range_m: None };
    crate::sensor::Sensor::from_file(file, "background".into(), &format!("{name} (the grid of its clouds)"))
}

/// The world frame: the one given, which must connect to `frame`, or the first default that does.
fn world_frame(tree: &tf::Tree, frame: &str, opts: &BagOptions) -> std::result::Result<String, String> {
    let known = || tree.frames().into_iter().collect::<Vec<_>>().join(", ");
    if let Some(w) = &opts.world_frame {
        if !tree.connected(w, frame) {
            return Err(format!("no transform chain from the world frame '{w}' to the clouds' frame '{frame}' (frames in /tf and /tf_static: {})", known()));
        }
        return Ok(tf::frame_name(w).to_string());
    }
    DEFAULT_WORLD_FRAMES.iter().find(|w| tree.connected(w, frame) && tree.frames().contains(*w)).map(|w| w.to_string()).ok_or_else(|| {
        format!(
            "no transform chain from odom, map or world to the clouds' frame '{frame}' (frames in /tf and /tf_static: {}); \
             name the world frame with --world-frame, or give the poses (--poses-topic, --poses)",
            known()
        )
    })
}

/// Poses from an odometry topic: `world_from_child(t)`, interpolated, composed with the
/// tree's `child_from_cloud(t)`. Clouds outside either's time get `None`.
fn odometry_poses<T>(
    odom: &[Transform],
    tree: &tf::Tree,
    frame: &str,
    clouds: &[(i64, String, T)],
    opts: &BagOptions,
) -> std::result::Result<(Vec<Option<DMat4>>, String), String> {
    let topic = opts.poses_topic.as_deref().unwrap_or_default();
    let first = &odom[0];
    let (world, child) = (tf::frame_name(&first.parent), tf::frame_name(&first.child));
    if let Some(o) = odom.iter().find(|o| tf::frame_name(&o.parent) != world || tf::frame_name(&o.child) != child) {
        return Err(format!("odometry on {topic} changes frames, from '{world}' -> '{child}' to '{}' -> '{}'", o.parent, o.child));
    }
    if let Some(w) = &opts.world_frame {
        if tf::frame_name(w) != world {
            return Err(format!("the world frame '{w}' is not the odometry's frame '{world}' (on {topic})"));
        }
    }
    let mut track = tf::Tree::default();
    for o in odom {
        track.add(o, false)?;
    }
    track.finish();
    if !tree.connected(child, frame) {
        return Err(format!("no transform chain from the odometry's child frame '{child}' to the clouds' frame '{frame}' in /tf and /tf_static"));
    }
    let poses = clouds.iter().map(|c| Some(track.lookup(world, child, c.0).ok()? * tree.lookup(child, frame, c.0).ok()?)).collect();
    Ok((poses, format!("poses from odometry on {topic}, '{world}' -> '{child}' -> '{frame}'")))
}

/// "organized 32 x 1024, fields x y z ..." for the description.
fn layout(c: &Cloud) -> String {
    let names: Vec<&str> = c.fields.iter().map(|f| f.name.as_str()).collect();
    let shape = if c.height > 1 { format!("organized {} x {}", c.height, c.width) } else { "unorganized".to_string() };
    format!("{shape}, fields {}", names.join(" "))
}

/// A numeric field's reader: its offset and datatype, checked against the point step.
#[derive(Clone, Copy)]
struct Reader {
    offset: usize,
    datatype: u8,
    big: bool,
}

impl Reader {
    fn new(c: &Cloud, f: &Field) -> std::result::Result<Reader, String> {
        let Some(size) = datatype_size(f.datatype) else {
            return Err(format!("field '{}' has datatype {}, not one of PointField's 1-8", f.name, f.datatype));
        };
        let end = f.offset as u64 + size as u64 * f.count.max(1) as u64;
        if end > c.point_step as u64 {
            return Err(format!("point_step {} is smaller than its fields: '{}' ends at byte {end}", c.point_step, f.name));
        }
        Ok(Reader { offset: f.offset as usize, datatype: f.datatype, big: c.big_endian })
    }

    fn get(&self, p: &[u8]) -> f64 {
        let o = self.offset;
        macro_rules! num {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&p[o..o + $n]);
                if self.big {
                    <$t>::from_be_bytes(a) as f64
                } else {
                    <$t>::from_le_bytes(a) as f64
                }
            }};
        }
        match self.datatype {
            1 => p[o] as i8 as f64,
            2 => p[o] as f64,
            3 => num!(i16, 2),
            4 => num!(u16, 2),
            5 => num!(i32, 4),
            6 => num!(u32, 4),
            7 => num!(f32, 4),
            _ => num!(f64, 8),
        }
    }
}

/// How a cloud's per-point time reads.
enum PointTime {
    /// ns after the stamp (`t`, UINT32).
    AfterStampNs(Reader),
    /// s after the stamp (`time`, FLOAT32 or FLOAT64).
    AfterStampS(Reader),
    /// absolute s (`timestamp`, FLOAT64).
    AbsoluteS(Reader),
}

/// The cloud as a scan in its own frame, its times (`time_s`, the firings') in seconds after
/// `epoch_ns` (an absolute time in seconds has only 0.2 us steps in an f64).
pub fn to_scan(c: &Cloud, epoch_ns: i64) -> std::result::Result<Scan, String> {
    let field = |n: &str| c.field(n).map(|f| Reader::new(c, f)).transpose();
    let xyz = [field("x")?, field("y")?, field("z")?];
    let [Some(x), Some(y), Some(z)] = xyz else {
        return Err("has no x, y and z fields".into());
    };
    for (r, n) in [(x, "x"), (y, "y"), (z, "z")] {
        if r.datatype != 7 && r.datatype != 8 {
            return Err(format!("field '{n}' has datatype {}; want FLOAT32 (7) or FLOAT64 (8)", r.datatype));
        }
    }
    let intensity = field("intensity")?;
    let ring = field("ring")?;
    if let Some(r) = ring {
        if r.datatype > 6 {
            return Err(format!("field 'ring' has datatype {}; want an integer type", r.datatype));
        }
    }
    let time = if let Some(r) = field("t")? {
        Some(PointTime::AfterStampNs(r))
    } else if let Some(r) = field("time")? {
        Some(PointTime::AfterStampS(r))
    } else {
        field("timestamp")?.map(PointTime::AbsoluteS)
    };
    let n = c.width as u64 * c.height as u64;
    if n > MAX_POINTS {
        return Err(format!("{} x {} points: more than {MAX_POINTS}", c.height, c.width));
    }
    let step = c.point_step as u64;
    if c.width > 0 && c.row_step as u64 / step.max(1) < c.width as u64 {
        return Err(format!("row_step {} is shorter than {} points of {} bytes", c.row_step, c.width, c.point_step));
    }
    let need = if n == 0 { 0 } else { (c.height as u64 - 1) * c.row_step as u64 + c.width as u64 * step };
    if (c.data.len() as u64) < need {
        return Err(format!("data holds {} bytes; {} x {} points of {} bytes in rows of {} need {need}", c.data.len(), c.height, c.width, step, c.row_step));
    }
    let stamp_s = c.stamp_ns.saturating_sub(epoch_ns) as f64 * 1e-9;
    let epoch_s = epoch_ns as f64 * 1e-9;
    let mut scan = Scan { time_s: Some(stamp_s), ..Scan::default() };
    let mut rings = Vec::new();
    let mut intensities = Vec::new();
    let mut timed: Vec<[f64; 2]> = Vec::new();
    // Rows of no points are not visited (a width of 0 may come with any height).
    let rows = if c.width == 0 { 0 } else { c.height as usize };
    for row in 0..rows {
        let base = row * c.row_step as usize;
        for col in 0..c.width as usize {
            let p = &c.data[base + col * step as usize..][..step as usize];
            let v = [x.get(p), y.get(p), z.get(p)];
            let pf = v.map(|a| a as f32);
            if !pf.iter().all(|a| a.is_finite()) || pf == [0.0; 3] {
                continue;
            }
            if let Some(r) = ring {
                let k = r.get(p);
                if !(0.0..=u16::MAX as f64).contains(&k) {
                    return Err(format!("point {} has ring {k}", row * c.width as usize + col));
                }
                rings.push(k as u16);
            }
            if let Some(i) = intensity {
                intensities.push(i.get(p) as f32);
            }
            if let Some(t) = &time {
                let abs = match t {
                    PointTime::AfterStampNs(r) => stamp_s + r.get(p) * 1e-9,
                    PointTime::AfterStampS(r) => stamp_s + r.get(p),
                    PointTime::AbsoluteS(r) => r.get(p) - epoch_s,
                };
                if !abs.is_finite() || (abs - stamp_s).abs() > 10.0 {
                    return Err(format!("point {} has time {abs} s, more than 10 s from its stamp {stamp_s} s", row * c.width as usize + col));
                }
                let turn = crate::sensor::turn_of(v[0], v[1]).rem_euclid(1.0);
                timed.push([turn, abs]);
            }
            scan.points.push(pf);
        }
    }
    if ring.is_some() {
        scan.ring = Some(rings);
    }
    if intensity.is_some() {
        scan.intensity = Some(intensities);
    }
    if time.is_some() {
        // One firing per distinct time, in time order.
        timed.sort_by(|a, b| a[1].total_cmp(&b[1]));
        timed.dedup_by(|b, a| a[1] == b[1]);
        scan.firing_times = Some(timed);
    }
    Ok(scan)
}

/// Each ring's elevation (degrees): the median over its points; `None` without rings or points.
pub fn measure_rings(scan: &Scan) -> Option<Vec<f64>> {
    let rings = scan.ring.as_ref()?;
    let count = *rings.iter().max()? as usize + 1;
    let mut per: Vec<Vec<f64>> = vec![Vec::new(); count];
    for (p, &r) in scan.points.iter().zip(rings) {
        let (x, y, z) = (p[0] as f64, p[1] as f64, p[2] as f64);
        per[r as usize].push(z.atan2(x.hypot(y)).to_degrees());
    }
    Some(
        per.into_iter()
            .map(|mut v| {
                if v.is_empty() {
                    return f64::NAN;
                }
                let mid = v.len() / 2;
                *v.select_nth_unstable_by(mid, f64::total_cmp).1
            })
            .collect(),
    )
}

#[cfg(test)]
pub(crate) mod tests;
