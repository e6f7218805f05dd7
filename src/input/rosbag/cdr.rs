//! The ROS 2 messages a background needs, decoded from CDR (XCDR1, either byte order):
//! `sensor_msgs/msg/PointCloud2`, `tf2_msgs/msg/TFMessage` and `nav_msgs/msg/Odometry`.
//! Every read is bounds-checked; a message that ends early or holds a length past its end is
//! an error saying which field, never a panic or an allocation of the claimed size.

use glam::{DQuat, DVec3};

/// A CDR payload being read: the 4-byte encapsulation header, then fields aligned to their
/// size relative to the end of the header.
pub struct Cdr<'a> {
    b: &'a [u8],
    at: usize,
    le: bool,
}

/// Why a message cannot be read.
pub type Why = String;

impl<'a> Cdr<'a> {
    /// Starts reading `b`: plain CDR, big (`00 00`) or little (`00 01`) endian.
    pub fn new(b: &'a [u8]) -> Result<Cdr<'a>, Why> {
        if b.len() < 4 {
            return Err(format!("{} bytes: too short for a CDR message", b.len()));
        }
        let le = match [b[0], b[1]] {
            [0, 0] => false,
            [0, 1] => true,
            e => return Err(format!("encapsulation {:02x}{:02x} is not plain CDR (00 00 or 00 01)", e[0], e[1])),
        };
        Ok(Cdr { b, at: 4, le })
    }

    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], Why> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.b.len());
        let Some(end) = end else {
            return Err(format!("ends inside {what} (byte {} of {}, {n} more wanted)", self.at, self.b.len()));
        };
        let s = &self.b[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn align(&mut self, n: usize) {
        let rel = self.at - 4;
        self.at += (n - rel % n) % n;
    }

    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N], Why> {
        self.align(N);
        let s = self.take(N, what)?;
        let mut a = [0; N];
        a.copy_from_slice(s);
        if !self.le {
            a.reverse();
        }
        Ok(a)
    }

    pub fn u8(&mut self, what: &str) -> Result<u8, Why> {
        Ok(self.take(1, what)?[0])
    }
    pub fn u32(&mut self, what: &str) -> Result<u32, Why> {
        self.array::<4>(what).map(u32::from_le_bytes)
    }
    pub fn i32(&mut self, what: &str) -> Result<i32, Why> {
        self.array::<4>(what).map(i32::from_le_bytes)
    }
    pub fn f64(&mut self, what: &str) -> Result<f64, Why> {
        self.array::<8>(what).map(f64::from_le_bytes)
    }
    /// A string: u32 length with its terminating NUL, the bytes, the NUL.
    pub fn string(&mut self, what: &str) -> Result<String, Why> {
        let n = self.u32(what)? as usize;
        let s = self.take(n, what)?;
        let s = s.strip_suffix(&[0]).unwrap_or(s);
        std::str::from_utf8(s).map(str::to_string).map_err(|_| format!("{what} is not UTF-8"))
    }
    /// A sequence's element count, checked against the bytes left (each element at least
    /// `min_bytes`), so a lying count cannot make the caller allocate.
    pub fn count(&mut self, what: &str, min_bytes: usize) -> Result<usize, Why> {
        let n = self.u32(what)? as usize;
        let left = self.b.len() - self.at;
        if n.saturating_mul(min_bytes.max(1)) > left {
            return Err(format!("{what} claims {n} elements but {left} bytes are left"));
        }
        Ok(n)
    }
    /// A `uint8[]`.
    pub fn bytes(&mut self, what: &str) -> Result<&'a [u8], Why> {
        let n = self.count(what, 1)?;
        self.take(n, what)
    }
    /// `std_msgs/Header`: stamp (ns since the epoch) and frame id.
    pub fn header(&mut self) -> Result<(i64, String), Why> {
        let sec = self.i32("header.stamp.sec")? as i64;
        let nsec = self.u32("header.stamp.nanosec")?;
        if nsec >= 1_000_000_000 {
            return Err(format!("header.stamp.nanosec {nsec} is not below 1e9"));
        }
        Ok((sec * 1_000_000_000 + nsec as i64, self.string("header.frame_id")?))
    }
    /// `geometry_msgs/Vector3` or `Point`.
    pub fn vec3(&mut self, what: &str) -> Result<DVec3, Why> {
        Ok(DVec3::new(self.f64(what)?, self.f64(what)?, self.f64(what)?))
    }
    /// `geometry_msgs/Quaternion` (x y z w), which must be finite and near unit length.
    pub fn quat(&mut self, what: &str) -> Result<DQuat, Why> {
        let q = DQuat::from_xyzw(self.f64(what)?, self.f64(what)?, self.f64(what)?, self.f64(what)?);
        let n = q.length();
        if !(n.is_finite() && (n - 1.0).abs() < 1e-3) {
            return Err(format!("{what} {q} is not a unit quaternion (length {n})"));
        }
        Ok(q.normalize())
    }
}

/// `sensor_msgs/msg/PointField`.
#[derive(Clone, Debug, PartialEq)]
pub struct Field {
    pub name: String,
    pub offset: u32,
    pub datatype: u8,
    pub count: u32,
}

/// Bytes of a PointField datatype (1 INT8 ... 8 FLOAT64), `None` for an unknown one.
pub fn datatype_size(t: u8) -> Option<usize> {
    match t {
        1 | 2 => Some(1),
        3 | 4 => Some(2),
        5..=7 => Some(4),
        8 => Some(8),
        _ => None,
    }
}

/// `sensor_msgs/msg/PointCloud2`, its data borrowed from the message.
#[derive(Debug)]
pub struct Cloud<'a> {
    pub stamp_ns: i64,
    pub frame_id: String,
    pub height: u32,
    pub width: u32,
    pub fields: Vec<Field>,
    pub big_endian: bool,
    pub point_step: u32,
    pub row_step: u32,
    pub data: &'a [u8],
}

impl<'a> Cloud<'a> {
    pub fn decode(b: &'a [u8]) -> Result<Cloud<'a>, Why> {
        let mut c = Cdr::new(b)?;
        let (stamp_ns, frame_id) = c.header()?;
        let height = c.u32("height")?;
        let width = c.u32("width")?;
        let n = c.count("fields", 13)?;
        let mut fields = Vec::with_capacity(n);
        for _ in 0..n {
            fields.push(Field {
                name: c.string("fields[].name")?,
                offset: c.u32("fields[].offset")?,
                datatype: c.u8("fields[].datatype")?,
                count: c.u32("fields[].count")?,
            });
        }
        let big_endian = c.u8("is_bigendian")? != 0;
        let point_step = c.u32("point_step")?;
        let row_step = c.u32("row_step")?;
        let data = c.bytes("data")?;
        Ok(Cloud { stamp_ns, frame_id, height, width, fields, big_endian, point_step, row_step, data })
    }

    /// The field named `name`.
    pub fn field(&self, name: &str) -> Option<&Field> {
        self.fields.iter().find(|f| f.name == name)
    }
}

/// One `geometry_msgs/TransformStamped`: `parent_from_child` at a time.
#[derive(Clone, Debug, PartialEq)]
pub struct Transform {
    pub stamp_ns: i64,
    pub parent: String,
    pub child: String,
    pub rotation: DQuat,
    pub translation: DVec3,
}

/// A `TransformStamped`'s fields (or an Odometry's header, child and pose), `what` naming the
/// translation and rotation fields in errors.
fn stamped(c: &mut Cdr, what: [&str; 2]) -> Result<Transform, Why> {
    let (stamp_ns, parent) = c.header()?;
    let child = c.string("child_frame_id")?;
    let translation = c.vec3(what[0])?;
    let rotation = c.quat(what[1])?;
    Ok(Transform { stamp_ns, parent, child, rotation, translation })
}

/// `tf2_msgs/msg/TFMessage`.
pub fn decode_tf(b: &[u8]) -> Result<Vec<Transform>, Why> {
    let mut c = Cdr::new(b)?;
    // header (>= 13 bytes) + child id (>= 4) + 7 doubles.
    let n = c.count("transforms", 13 + 4 + 56)?;
    (0..n).map(|_| stamped(&mut c, ["transform.translation", "transform.rotation"])).collect()
}

/// `nav_msgs/msg/Odometry`'s pose: `header.frame_id` from `child_frame_id` (its covariance
/// and twist are not needed).
pub fn decode_odometry(b: &[u8]) -> Result<Transform, Why> {
    stamped(&mut Cdr::new(b)?, ["pose.pose.position", "pose.pose.orientation"])
}
