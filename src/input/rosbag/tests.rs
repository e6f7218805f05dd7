use super::cdr::{decode_tf, Cloud, Transform};
use super::tf::{Miss, Tree};
use super::*;
use glam::{DQuat, DVec3};
use std::collections::BTreeMap;

/// A CDR message built by hand in either byte order (independent of the writer's encoder).
struct Msg {
    v: Vec<u8>,
    le: bool,
}

impl Msg {
    fn new(le: bool) -> Msg {
        Msg { v: vec![0, le as u8, 0, 0], le }
    }
    fn align(&mut self, n: usize) {
        while (self.v.len() - 4) % n != 0 {
            self.v.push(0);
        }
    }
    fn raw<const N: usize>(&mut self, mut b: [u8; N]) -> &mut Self {
        self.align(N);
        if !self.le {
            b.reverse();
        }
        self.v.extend_from_slice(&b);
        self
    }
    fn u8(&mut self, x: u8) -> &mut Self {
        self.v.push(x);
        self
    }
    fn u32(&mut self, x: u32) -> &mut Self {
        self.raw(x.to_le_bytes())
    }
    fn f64(&mut self, x: f64) -> &mut Self {
        self.raw(x.to_le_bytes())
    }
    fn string(&mut self, s: &str) -> &mut Self {
        self.u32(s.len() as u32 + 1);
        self.v.extend_from_slice(s.as_bytes());
        self.v.push(0);
        self
    }
    fn header(&mut self, stamp_ns: i64, frame: &str) -> &mut Self {
        self.raw(((stamp_ns.div_euclid(1_000_000_000)) as i32).to_le_bytes());
        self.u32(stamp_ns.rem_euclid(1_000_000_000) as u32);
        self.string(frame)
    }
}

/// A field of a test cloud: name, datatype, and per point its value.
pub(crate) struct Col {
    name: &'static str,
    datatype: u8,
    values: Vec<f64>,
}

pub(crate) fn col(name: &'static str, datatype: u8, values: &[f64]) -> Col {
    Col { name, datatype, values: values.to_vec() }
}

/// A PointCloud2 of `height` rows with the given fields packed in order (each aligned to its
/// size), `pad` spare bytes a point, in byte order `le`.
pub(crate) fn cloud_msg(stamp_ns: i64, frame: &str, height: u32, cols: &[Col], le: bool, pad: u32) -> Vec<u8> {
    let n = cols[0].values.len();
    let mut offsets = Vec::new();
    let mut step = 0u32;
    for c in cols {
        let size = datatype_size(c.datatype).unwrap() as u32;
        step = step.div_ceil(size) * size;
        offsets.push(step);
        step += size;
    }
    step += pad;
    let mut data = vec![0u8; n * step as usize];
    for (c, &off) in cols.iter().zip(&offsets) {
        for (i, &x) in c.values.iter().enumerate() {
            let mut b: Vec<u8> = match c.datatype {
                1 => vec![x as i8 as u8],
                2 => vec![x as u8],
                3 => (x as i16).to_le_bytes().to_vec(),
                4 => (x as u16).to_le_bytes().to_vec(),
                5 => (x as i32).to_le_bytes().to_vec(),
                6 => (x as u32).to_le_bytes().to_vec(),
                7 => (x as f32).to_le_bytes().to_vec(),
                _ => x.to_le_bytes().to_vec(),
            };
            if !le {
                b.reverse();
            }
            let at = i * step as usize + off as usize;
            data[at..at + b.len()].copy_from_slice(&b);
        }
    }
    let mut m = Msg::new(le);
    m.header(stamp_ns, frame).u32(height).u32(n as u32 / height).u32(cols.len() as u32);
    for (c, &off) in cols.iter().zip(&offsets) {
        m.string(c.name).u32(off).u8(c.datatype).u32(1);
    }
    m.u8(!le as u8).u32(step).u32(step * (n as u32 / height)).u32(data.len() as u32);
    m.v.extend_from_slice(&data);
    m.u8(0);
    m.v
}

pub(crate) fn tf_msg(transforms: &[(i64, &str, &str, DQuat, DVec3)]) -> Vec<u8> {
    let mut m = Msg::new(true);
    m.u32(transforms.len() as u32);
    for &(t, parent, child, q, v) in transforms {
        m.header(t, parent).string(child);
        for c in [v.x, v.y, v.z, q.x, q.y, q.z, q.w] {
            m.f64(c);
        }
    }
    m.v
}

fn odometry_msg(t: i64, parent: &str, child: &str, q: DQuat, v: DVec3) -> Vec<u8> {
    let mut m = Msg::new(true);
    m.header(t, parent).string(child);
    for c in [v.x, v.y, v.z, q.x, q.y, q.z, q.w] {
        m.f64(c);
    }
    for _ in 0..36 + 6 + 36 {
        m.f64(0.0);
    }
    m.v
}

/// Writes an MCAP bag of `(topic, schema, log time ns, message)`.
pub(crate) fn write_bag(path: &Path, msgs: &[(&str, &str, i64, Vec<u8>)], compression: Option<mcap::Compression>) {
    let opts = mcap::WriteOptions::new().profile("ros2").compression(compression).chunk_size(Some(4096));
    let mut w = mcap::Writer::with_options(std::io::BufWriter::new(std::fs::File::create(path).unwrap()), opts).unwrap();
    let mut channels: BTreeMap<String, u16> = BTreeMap::new();
    for (k, (topic, schema, t, bytes)) in msgs.iter().enumerate() {
        let id = *channels.entry(topic.to_string()).or_insert_with(|| {
            let s = w.add_schema(schema, "ros2msg", b"").unwrap();
            w.add_channel(s, topic, "cdr", &BTreeMap::new()).unwrap()
        });
        let h = mcap::records::MessageHeader { channel_id: id, sequence: k as u32, log_time: *t as u64, publish_time: *t as u64 };
        w.write_to_known_channel(&h, bytes).unwrap();
    }
    w.finish().unwrap();
}

pub(crate) const S: i64 = 1_000_000_000;
pub(crate) const BASE: i64 = 1_700_000_000 * S;

pub(crate) fn yaw(deg: f64) -> DQuat {
    DQuat::from_rotation_z(deg.to_radians())
}

#[test]
fn a_cloud_reads_in_either_byte_order_with_each_vendors_time_field() {
    let stamp = BASE + 250_000_000;
    // Four points: a return, a NaN, an all-zero one, a return behind the sensor.
    let (x, y, z) = ([2.0, f64::NAN, 0.0, -4.0], [1.0, 0.0, 0.0, -0.5], [0.5, 0.0, 0.0, -1.0]);
    for le in [true, false] {
        for (time_col, offset_s) in [
            (col("t", 6, &[1000.0, 0.0, 0.0, 51_000_000.0]), [1e-6, 0.051]),
            (col("time", 7, &[0.001, 0.0, 0.0, 0.05]), [0.001, 0.05]),
            (col("timestamp", 8, &[BASE as f64 * 1e-9 + 0.26, 0.0, 0.0, BASE as f64 * 1e-9 + 0.3]), [0.01, 0.05]),
        ] {
            let cols = [
                col("x", 8, &x),
                col("y", 8, &y),
                col("z", 8, &z),
                col("intensity", 2, &[7.0, 0.0, 0.0, 200.0]),
                col("ring", 4, &[3.0, 0.0, 0.0, 30.0]),
                time_col,
            ];
            let bytes = cloud_msg(stamp, "lidar", 1, &cols, le, 3);
            let c = Cloud::decode(&bytes).unwrap();
            assert_eq!((c.frame_id.as_str(), c.stamp_ns, c.big_endian), ("lidar", stamp, !le));
            let s = to_scan(&c, BASE).unwrap();
            assert_eq!(s.points, vec![[2.0, 1.0, 0.5], [-4.0, -0.5, -1.0]]);
            assert_eq!(s.ring, Some(vec![3, 30]));
            assert_eq!(s.intensity, Some(vec![7.0, 200.0]));
            // Times after the epoch given (BASE), so they keep their nanoseconds.
            let t0 = 0.25;
            assert_eq!(s.time_s, Some(t0));
            let f = s.firing_times.unwrap();
            assert_eq!(f.len(), 2);
            // Azimuths as turns clockwise from straight behind: atan2(1, 2) and atan2(-0.5, -4).
            let turn = |x: f64, y: f64| (0.5 * (1.0 - f64::atan2(y, x) / std::f64::consts::PI)).rem_euclid(1.0);
            for (k, (&(px, py), off)) in [(2.0, 1.0), (-4.0, -0.5)].iter().zip(offset_s).enumerate() {
                assert!((f[k][0] - turn(px, py)).abs() < 1e-12, "{le} {k}");
                // f32 `time`: its own rounding; `timestamp`: an absolute f64 (0.2 us steps).
                assert!((f[k][1] - (t0 + off)).abs() < 5e-7, "{le} {k}: {} vs {}", f[k][1] - t0, off);
            }
        }
    }
}

#[test]
fn fields_that_do_not_fit_their_points_are_named() {
    let cols = |xt: u8| vec![col("x", xt, &[1.0, 2.0]), col("y", 7, &[0.0, 0.0]), col("z", 7, &[0.0, 0.0])];
    let ok = cloud_msg(BASE, "l", 1, &cols(7), true, 0);
    assert_eq!(to_scan(&Cloud::decode(&ok).unwrap(), BASE).unwrap().points.len(), 2);
    // point_step 12 with a field at offset 10: "smaller than its fields".
    let mut c = Cloud::decode(&ok).unwrap();
    c.fields[2].offset = 10;
    let e = to_scan(&c, BASE).unwrap_err();
    assert!(e.contains("point_step 12 is smaller than its fields: 'z' ends at byte 14"), "{e}");
    let mut c = Cloud::decode(&ok).unwrap();
    c.data = &c.data[..23];
    let e = to_scan(&c, BASE).unwrap_err();
    assert!(e.contains("data holds 23 bytes") && e.contains("need 24"), "{e}");
    let mut c = Cloud::decode(&ok).unwrap();
    c.row_step = 12;
    assert!(to_scan(&c, BASE).unwrap_err().contains("row_step 12 is shorter than 2 points"));
    let e = to_scan(&Cloud::decode(&cloud_msg(BASE, "l", 1, &cols(5), true, 0)).unwrap(), BASE).unwrap_err();
    assert!(e.contains("field 'x' has datatype 5; want FLOAT32 (7) or FLOAT64 (8)"), "{e}");
    let mut c = Cloud::decode(&ok).unwrap();
    c.fields.retain(|f| f.name != "y");
    assert_eq!(to_scan(&c, BASE).unwrap_err(), "has no x, y and z fields");
    let neg = [col("x", 7, &[1.0]), col("y", 7, &[0.0]), col("z", 7, &[0.0]), col("ring", 1, &[-1.0])];
    assert!(to_scan(&Cloud::decode(&cloud_msg(BASE, "l", 1, &neg, true, 0)).unwrap(), BASE).unwrap_err().contains("point 0 has ring -1"));
}

#[test]
fn lying_and_truncated_messages_are_errors() {
    let cols = [col("x", 7, &[1.0; 4]), col("y", 7, &[0.0; 4]), col("z", 7, &[0.0; 4])];
    let ok = cloud_msg(BASE, "lidar", 2, &cols, true, 0);
    // Every truncation is an error, never a panic.
    for n in 0..ok.len() - 1 {
        assert!(Cloud::decode(&ok[..n]).is_err(), "{n} bytes");
    }
    // A data length of 4 GB in a short message.
    let at = ok.len() - 1 - 48 - 4;
    let mut lying = ok.clone();
    lying[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    let e = Cloud::decode(&lying).unwrap_err();
    assert!(e.contains("data claims 4294967295 elements but"), "{e}");
    let mut xcdr2 = ok.clone();
    xcdr2[1] = 7;
    assert!(Cloud::decode(&xcdr2).unwrap_err().contains("encapsulation 0007 is not plain CDR"));
    let tf = tf_msg(&[(BASE, "odom", "base", DQuat::from_xyzw(0.0, 0.0, 0.0, 2.0), DVec3::ZERO)]);
    assert!(decode_tf(&tf).unwrap_err().contains("is not a unit quaternion"));
}

#[test]
fn transforms_interpolate_compose_and_never_extrapolate() {
    let mut tree = Tree::default();
    let t = |s: i64, p: &str, c: &str, q: DQuat, v: DVec3| Transform { stamp_ns: s, parent: p.into(), child: c.into(), rotation: q, translation: v };
    // base turns 90 degrees and moves 10 m along x over 10 s; the lidar sits 1 m above and
    // 0.5 m ahead of it, turned 180 degrees; map -> odom is a static shift.
    tree.add(&t(10 * S, "odom", "base", yaw(90.0), DVec3::new(10.0, 0.0, 0.0)), false).unwrap();
    tree.add(&t(0, "/odom", "base", yaw(0.0), DVec3::ZERO), false).unwrap();
    tree.add(&t(0, "base", "lidar", yaw(180.0), DVec3::new(0.5, 0.0, 1.0)), true).unwrap();
    tree.add(&t(0, "map", "odom", yaw(0.0), DVec3::new(0.0, 3.0, 0.0)), true).unwrap();
    tree.finish();
    let m = tree.lookup("odom", "lidar", 5 * S).unwrap();
    // At 5 s: base at (5, 0, 0) turned 45 degrees; the lidar 0.5 m ahead along the turned x.
    let h = 0.5 * std::f64::consts::FRAC_1_SQRT_2;
    let origin = m.transform_point3(DVec3::ZERO);
    assert!((origin - DVec3::new(5.0 + h, h, 1.0)).length() < 1e-12, "{origin}");
    // The lidar's x axis points back along the base's: at 225 degrees.
    let x = m.transform_vector3(DVec3::X);
    assert!((x - DVec3::new(-std::f64::consts::FRAC_1_SQRT_2, -std::f64::consts::FRAC_1_SQRT_2, 0.0)).length() < 1e-12, "{x}");
    // Through the static root, and the other way round.
    let in_map = tree.lookup("map", "lidar", 5 * S).unwrap();
    assert!((in_map.transform_point3(DVec3::ZERO) - (origin + DVec3::new(0.0, 3.0, 0.0))).length() < 1e-12);
    let back = tree.lookup("lidar", "map", 5 * S).unwrap();
    assert!((back * in_map - DMat4::IDENTITY).abs_diff_eq(DMat4::ZERO, 1e-12));
    // Exactly at a stamp, and outside the stamps.
    assert!((tree.lookup("odom", "base", 10 * S).unwrap().transform_point3(DVec3::ZERO) - DVec3::new(10.0, 0.0, 0.0)).length() < 1e-12);
    assert_eq!(tree.lookup("odom", "lidar", 10 * S + 1).unwrap_err(), Miss::OutsideTime);
    assert_eq!(tree.lookup("odom", "lidar", -1).unwrap_err(), Miss::OutsideTime);
    assert_eq!(tree.lookup("odom", "camera", 0).unwrap_err(), Miss::NoChain);
    assert!(tree.connected("map", "lidar") && !tree.connected("map", "camera"));
    let e = tree.add(&t(0, "map", "base", yaw(0.0), DVec3::ZERO), false).unwrap_err();
    assert_eq!(e, "frame 'base' has two parents, 'odom' and 'map'");
    assert!(tree.add(&t(0, "a", "a", yaw(0.0), DVec3::ZERO), true).is_err());
    assert!(tree.add(&t(0, "a", "b", yaw(0.0), DVec3::new(1e6, 0.0, 0.0)), true).is_err());
}

/// A cloud of four returns in frame `frame` at `stamp`, two rings, fired clockwise from behind
/// the sensor over 75 ms (`time` after the stamp), as a spinning lidar does.
pub(crate) fn small_cloud(stamp: i64, frame: &str) -> Vec<u8> {
    let cols = [
        col("x", 7, &[-4.0, 0.0, 4.0, 0.0]),
        col("y", 7, &[0.0, 4.0, 0.0, -4.0]),
        col("z", 7, &[-1.0, -1.0, 1.0, 1.0]),
        col("ring", 4, &[0.0, 0.0, 1.0, 1.0]),
        col("time", 7, &[0.0, 0.025, 0.05, 0.075]),
    ];
    cloud_msg(stamp, frame, 1, &cols, true, 0)
}

/// A bag: clouds at 0.05, 1, 2, 3 s in `lidar`, base moving 1 m/s along x from 0.1 s to 3 s,
/// lidar 1 m above base, map -> odom static.
pub(crate) fn moving_bag() -> Vec<(&'static str, &'static str, i64, Vec<u8>)> {
    let mut msgs = vec![(
        "/tf_static",
        "tf2_msgs/msg/TFMessage",
        BASE,
        tf_msg(&[(BASE, "base", "lidar", yaw(0.0), DVec3::Z), (BASE, "map", "odom", yaw(0.0), DVec3::ZERO)]),
    )];
    for k in 1..=30 {
        let t = BASE + k * S / 10;
        msgs.push(("/tf", "tf2_msgs/msg/TFMessage", t, tf_msg(&[(t, "odom", "base", yaw(0.0), DVec3::new(k as f64 / 10.0, 0.0, 0.0))])));
    }
    for t in [S / 20, S, 2 * S, 3 * S] {
        msgs.push(("/points", "sensor_msgs/msg/PointCloud2", BASE + t, small_cloud(BASE + t, "lidar")));
    }
    msgs
}

fn points_of(bag: &Path, opts: &BagOptions) -> Result<Bag<Vec<[f32; 3]>>> {
    read_bag(bag, opts, |s, _| Ok(s.points.clone()))
}

#[test]
fn poses_come_from_the_transform_tree_at_each_stamp() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("b.mcap");
    write_bag(&p, &moving_bag(), None);
    let bag = points_of(&p, &BagOptions::default()).unwrap();
    // The cloud at 0.05 s comes before the first /tf: dropped.
    assert_eq!((&bag.times_s, bag.start_ns), (&vec![0.0, 1.0, 2.0], BASE + S));
    let poses = bag.poses.unwrap();
    for (k, m) in poses.iter().enumerate() {
        let o = m.transform_point3(DVec3::ZERO);
        assert!((o - DVec3::new(1.0 + k as f64, 0.0, 1.0)).length() < 1e-9, "{k}: {o}");
    }
    assert_eq!(bag.frames[0], vec![[-4.0, 0.0, -1.0], [0.0, 4.0, -1.0], [4.0, 0.0, 1.0], [0.0, -4.0, 1.0]]);
    // Ring elevations measured: atan(-1/4) and atan(1/4).
    let e = bag.ring_elevation_deg.unwrap();
    assert!((e[0] + 14.036243467926479).abs() < 1e-9 && (e[1] - 14.036243467926479).abs() < 1e-9, "{e:?}");
    assert!(bag.description.contains("3 clouds on /points in frame 'lidar'"), "{}", bag.description);
    assert!(bag.description.contains("poses from /tf, 'odom' -> 'lidar'") && bag.description.contains("1 clouds outside"), "{}", bag.description);
    // The same bag in zstd-compressed chunks reads the same.
    let z = d.path().join("z.mcap");
    write_bag(&z, &moving_bag(), Some(mcap::Compression::Zstd));
    assert!(std::fs::metadata(&z).unwrap().len() < std::fs::metadata(&p).unwrap().len());
    let bz = points_of(&z, &BagOptions::default()).unwrap();
    assert_eq!((bz.frames, bz.times_s, bz.poses.unwrap()), (bag.frames, bag.times_s, poses));
    // The world frame by name; one that does not reach the clouds is an error listing frames.
    let in_map = points_of(&p, &BagOptions { world_frame: Some("map".into()), ..Default::default() }).unwrap();
    assert!(in_map.description.contains("'map' -> 'lidar'"));
    let e = points_of(&p, &BagOptions { world_frame: Some("earth".into()), ..Default::default() }).err().unwrap().to_string();
    assert!(
        e.contains("no transform chain from the world frame 'earth' to the clouds' frame 'lidar' (frames in /tf and /tf_static: base, lidar, map, odom)"),
        "{e}"
    );
    // A poses file replaces the transforms: every cloud is kept.
    let all = points_of(&p, &BagOptions { no_poses: true, ..Default::default() }).unwrap();
    assert_eq!((all.frames.len(), all.poses.is_none()), (4, true));
}

#[test]
fn odometry_gives_the_poses_composed_with_the_tree() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("o.mcap");
    let mut msgs = vec![("/tf_static", "tf2_msgs/msg/TFMessage", BASE, tf_msg(&[(BASE, "base", "lidar", yaw(90.0), DVec3::new(0.0, 0.0, 2.0))]))];
    for k in 0..=4 {
        let t = BASE + k * S;
        msgs.push(("/odom", "nav_msgs/msg/Odometry", t, odometry_msg(t, "odom", "base", yaw(0.0), DVec3::new(0.0, 2.0 * k as f64, 0.0))));
    }
    msgs.push(("/points", "sensor_msgs/msg/PointCloud2", BASE + S / 2, small_cloud(BASE + S / 2, "lidar")));
    msgs.push(("/points", "sensor_msgs/msg/PointCloud2", BASE + 5 * S, small_cloud(BASE + 5 * S, "lidar")));
    write_bag(&p, &msgs, None);
    let opts = BagOptions { poses_topic: Some("/odom".into()), ..Default::default() };
    let bag = points_of(&p, &opts).unwrap();
    assert_eq!((bag.times_s, bag.start_ns), (vec![0.0], BASE + S / 2));
    let m = bag.poses.unwrap()[0];
    assert!((m.transform_point3(DVec3::ZERO) - DVec3::new(0.0, 1.0, 2.0)).length() < 1e-12);
    assert!((m.transform_vector3(DVec3::X) - DVec3::Y).length() < 1e-12);
    assert!(bag.description.contains("odometry on /odom, 'odom' -> 'base' -> 'lidar'"), "{}", bag.description);
    let e = points_of(&p, &BagOptions { poses_topic: Some("/gps".into()), ..Default::default() }).err().unwrap().to_string();
    assert!(e.ends_with("has no nav_msgs/msg/Odometry message on '/gps' (scene.poses_topic)"), "{e}");
}

#[test]
fn bags_that_cannot_give_a_background_say_why() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("e.mcap");
    let err = |msgs: &[(&str, &str, i64, Vec<u8>)], opts: &BagOptions| {
        write_bag(&p, msgs, None);
        let e = points_of(&p, opts).err().expect("an error");
        assert!(e.is_input(), "{e}");
        e.to_string()
    };
    let tf_only = moving_bag().into_iter().filter(|m| m.0 != "/points").collect::<Vec<_>>();
    assert!(err(&tf_only, &BagOptions::default()).ends_with("holds no sensor_msgs/msg/PointCloud2 message"));
    let mut two = moving_bag();
    two.push(("/front", "sensor_msgs/msg/PointCloud2", BASE + S, small_cloud(BASE + S, "lidar")));
    let e = err(&two, &BagOptions::default());
    assert!(e.ends_with("holds 2 PointCloud2 topics (/front, /points): choose one with --topic"), "{e}");
    let e = err(&two, &BagOptions { topic: Some("/rear".into()), ..Default::default() });
    assert!(e.ends_with("has no PointCloud2 topic '/rear' (it has: /front, /points)"), "{e}");
    let front = points_of(&p, &BagOptions { topic: Some("/front".into()), ..Default::default() }).unwrap();
    assert_eq!(front.frames.len(), 1);
    let mut other_frame = moving_bag();
    other_frame.retain(|m| m.0 != "/points");
    other_frame.push(("/points", "sensor_msgs/msg/PointCloud2", BASE + S, small_cloud(BASE + S, "velodyne")));
    let e = err(&other_frame, &BagOptions::default());
    assert!(e.contains("no transform chain from odom, map or world to the clouds' frame 'velodyne'"), "{e}");
    let mut bad = moving_bag();
    bad.push(("/points", "sensor_msgs/msg/PointCloud2", BASE + 4 * S, small_cloud(BASE + 4 * S, "lidar")[..40].to_vec()));
    let e = err(&bad, &BagOptions::default());
    assert!(e.starts_with(&format!("{}: message 35 on /points: fields claims 5 elements", p.display())), "{e}");
    // Not an MCAP file, and a bag cut short.
    std::fs::write(&p, b"not a bag at all, just text").unwrap();
    let e = points_of(&p, &BagOptions::default()).err().unwrap();
    assert_eq!(e.to_string(), format!("{} (byte 0): does not start with the MCAP magic (not an MCAP file)", p.display()));
    write_bag(&p, &moving_bag(), None);
    let whole = std::fs::read(&p).unwrap();
    // Cut inside a record: an error naming the file and the record's byte.
    for cut in [whole.len() / 3, whole.len() / 2] {
        std::fs::write(&p, &whole[..cut]).unwrap();
        let e = points_of(&p, &BagOptions::default()).err().unwrap_or_else(|| panic!("{cut} bytes read"));
        assert!(e.is_input() && e.to_string().starts_with(&format!("{} (byte ", p.display())) && e.to_string().contains("(cut short?)"), "{e}");
    }
    // The data section whole and the summary cut: every cloud is there.
    std::fs::write(&p, &whole[..whole.len() - 9]).unwrap();
    assert_eq!(points_of(&p, &BagOptions::default()).unwrap().frames.len(), 3);
    // Cut at a record boundary before the data end (a recorder stopped): read up to there.
    let data_end = (8..whole.len() - 9).find(|&i| whole[i] == 0x0F && whole[i + 1..i + 9] == 4u64.to_le_bytes()).expect("a data end record");
    std::fs::write(&p, &whole[..data_end]).unwrap();
    let bag = points_of(&p, &BagOptions::default()).unwrap();
    assert!(bag.frames.len() == 3 && bag.description.ends_with("1 file(s) end without their data end record (read up to there)"), "{}", bag.description);
}

#[test]
fn a_rosbag2_folder_reads_its_listed_files_in_order() {
    let d = tempfile::tempdir().unwrap();
    let all = moving_bag();
    let (first, second): (Vec<_>, Vec<_>) = all.into_iter().partition(|m| m.2 < BASE + 3 * S / 2);
    let mut second_with_static = vec![first[0].clone()];
    second_with_static.extend(second);
    write_bag(&d.path().join("run_0.mcap"), &first, None);
    write_bag(&d.path().join("run_1.mcap"), &second_with_static, None);
    std::fs::write(
        d.path().join("metadata.yaml"),
        "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: mcap\n  relative_file_paths:\n    - run_0.mcap\n    - run_1.mcap\n  files:\n    - path: run_0.mcap\n",
    )
    .unwrap();
    assert!(is_bag(d.path()));
    assert_eq!(mcap_files(d.path()).unwrap(), vec![d.path().join("run_0.mcap"), d.path().join("run_1.mcap")]);
    let bag = points_of(d.path(), &BagOptions::default()).unwrap();
    assert_eq!(bag.times_s.len(), 3);
    assert!(bag.description.starts_with("ROS 2 bag (2 MCAP files)"), "{}", bag.description);
    std::fs::write(d.path().join("metadata.yaml"), "rosbag2_bagfile_information:\n  storage_identifier: sqlite3\n").unwrap();
    let e = points_of(d.path(), &BagOptions::default()).err().unwrap().to_string();
    assert!(e.contains("the bag is stored as 'sqlite3'; pedscan reads MCAP bags"), "{e}");
}

#[test]
fn a_bags_own_grid_comes_from_its_rings() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("g.mcap");
    // Unorganized clouds of two rings at +2 and -3 degrees, 12 and 10 returns a turn, 20 Hz.
    let cloud = |stamp: i64, with_ring: bool| {
        let mut x = Vec::new();
        let mut y = Vec::new();
        let mut z = Vec::new();
        let mut ring = Vec::new();
        for (r, (el, n)) in [(-3.0f64, 10), (2.0, 12)].into_iter().enumerate() {
            for k in 0..n {
                let az = std::f64::consts::TAU * k as f64 / n as f64;
                x.push(10.0 * az.cos());
                y.push(10.0 * az.sin());
                z.push(10.0 * el.to_radians().tan());
                ring.push(r as f64);
            }
        }
        let mut cols = vec![col("x", 7, &x), col("y", 7, &y), col("z", 7, &z)];
        if with_ring {
            cols.push(col("ring", 2, &ring));
        }
        cloud_msg(stamp, "lidar", 1, &cols, true, 0)
    };
    let msgs: Vec<_> = (0..3).map(|k| ("/p", "sensor_msgs/msg/PointCloud2", BASE + k * S / 20, cloud(BASE + k * S / 20, true))).collect();
    write_bag(&p, &msgs, None);
    let s = sensor_of_bag(&p, &BagOptions::default()).unwrap();
    assert_eq!((s.rows(), s.columns, s.name.as_str()), (2, 12, "background"));
    assert!((s.rate_hz - 20.0).abs() < 1e-9, "{}", s.rate_hz);
    assert!((s.elevation_deg[0] - 2.0).abs() < 1e-5 && (s.elevation_deg[1] + 3.0).abs() < 1e-5, "{:?}", s.elevation_deg);
    let msgs: Vec<_> = (0..3).map(|k| ("/p", "sensor_msgs/msg/PointCloud2", BASE + k * S / 20, cloud(BASE + k * S / 20, false))).collect();
    write_bag(&p, &msgs, None);
    let e = sensor_of_bag(&p, &BagOptions::default()).unwrap_err().to_string();
    assert!(e.contains("its clouds have no `ring` field"), "{e}");
}

/// Records the `mcap` crate's reader panics on (what the fuzzer found): an uncompressed chunk
/// whose inner record claims more bytes than the chunk holds is an input error naming the
/// file; an attachment shorter than its own header is skipped, as every record a background
/// does not need.
#[test]
fn a_chunk_whose_record_overruns_it_is_an_input_error() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("overrun.mcap");
    let record = |op: u8, body: &[u8]| [&[op][..], &(body.len() as u64).to_le_bytes(), body].concat();
    let string = |s: &str| [&(s.len() as u32).to_le_bytes()[..], s.as_bytes()].concat();
    // Inside the chunk: a message record claiming 100 bytes, 20 given.
    let inner = [&[0x05u8][..], &100u64.to_le_bytes(), &[0u8; 20]].concat();
    let chunk = [
        &0u64.to_le_bytes()[..],
        &0u64.to_le_bytes(),
        &(inner.len() as u64).to_le_bytes(),
        &0u32.to_le_bytes(),
        &string(""),
        &(inner.len() as u64).to_le_bytes(),
        &inner,
    ]
    .concat();
    let magic = b"\x89MCAP0\r\n";
    let bytes = [&magic[..], &record(0x01, &[string("ros2"), string("x")].concat()), &record(0x06, &chunk), &[0u8; 200], magic].concat();
    std::fs::write(&p, bytes).unwrap();
    let e = points_of(&p, &BagOptions::default()).err().unwrap();
    assert!(e.is_input() && e.to_string().starts_with(&format!("{} (byte 30): chunk: inner record runs past", p.display())), "{e}");
    write_bag(&p, &moving_bag(), None);
    let good = std::fs::read(&p).unwrap();
    // A 3-byte attachment record right after the header record.
    let after_header = 8 + 9 + u64::from_le_bytes(good[9..17].try_into().unwrap()) as usize;
    let with_attachment = [&good[..after_header], &record(0x09, &[1, 2, 3]), &good[after_header..]].concat();
    std::fs::write(&p, with_attachment).unwrap();
    assert_eq!(points_of(&p, &BagOptions::default()).unwrap().frames.len(), 3);
}
