//! PCD files (Point Cloud Library format, header `VERSION` 0.6 or 0.7).
//!
//! # What is read
//!
//! * Header keys `VERSION FIELDS SIZE TYPE COUNT WIDTH HEIGHT VIEWPOINT POINTS DATA`, one per
//!   line, `DATA` last; lines starting with `#` are comments; a UTF-8 byte-order mark before
//!   the first line is skipped. `FIELDS SIZE TYPE WIDTH HEIGHT
//!   POINTS DATA` are required; `VERSION` (when present it must be 0.6 or 0.7), `COUNT`
//!   (default 1 per field) and `VIEWPOINT` (default identity) are optional. Any other key, a
//!   key given twice or a missing required key is an error.
//! * `DATA ascii` (one point per line, `#`-free, blank lines ignored), `DATA binary` (records of
//!   little-endian values, point after point) and `DATA binary_compressed` (`u32` compressed
//!   size, `u32` uncompressed size, then LZF-compressed data that holds the fields column-wise:
//!   every point's first field, then every point's second field, ...).
//! * Fields `x y z` must exist with `TYPE F`, `SIZE 4` or `8` and `COUNT 1`. An optional
//!   `ring` field (`TYPE U` or `I`, `SIZE 1 2 4 8`, `COUNT 1`, values 0..=65535) goes to
//!   [`Scan::ring`]; a PCD carries no ring elevations, so [`Scan::ring_elevation_deg`] stays
//!   `None`. An optional `intensity` field of one number (`TYPE F` of `SIZE 4` or `8`, or an
//!   integer of `SIZE 1 2 4 8`) goes to [`Scan::intensity`] (a non-finite value as 0); an
//!   intensity of another shape is passed over. Every other field (`t`, `rgb`, padding `_`,
//!   normals, any `COUNT`) is skipped by its size.
//!
//! # Frame
//!
//! `VIEWPOINT tx ty tz qw qx qy qz` is the acquisition pose: the sensor's position `t` and
//! orientation `q` in the frame the points are stored in (PCL keeps it as `sensor_origin_` /
//! `sensor_orientation_` and does not apply it on load). A [`Scan`] is in the sensor frame, so
//! when the viewpoint is not the identity every point is mapped as `p_sensor = R(q)^T (p - t)`
//! (in `f64`, before rounding to `f32`). The quaternion must have a norm within 1 % of 1; it is
//! normalised.
//!
//! Points with a non-finite coordinate (organised clouds mark holes with NaN) and points stored
//! as all zero (no return) are dropped, together with their ring.
//!
//! # Errors
//!
//! Bad input is an [`Error::input`] naming the file, and `FILE:LINE` for header lines and ascii
//! data lines: unknown, repeated or missing header keys, unsupported `VERSION` or `DATA`,
//! `SIZE`/`TYPE`/`COUNT` lists whose length differs from `FIELDS`, an unsupported `TYPE` or
//! `SIZE` for `x y z ring`, `POINTS` != `WIDTH` × `HEIGHT`, data of another size than the header
//! says (a binary body must be exactly `POINTS` records, a compressed body exactly its declared
//! compressed size, an ascii body exactly `POINTS` data lines), an ascii line with the wrong number of values or an unparsable value, LZF data that does not
//! decompress to the declared size, and a ring value outside 0..=65535.

use super::Scan;
use crate::error::{Error, Result};
use glam::{DMat3, DQuat, DVec3};
use std::path::Path;

/// Reads one PCD file into a [`Scan`] in the sensor frame (see the module docs).
pub fn read_pcd(path: &Path) -> Result<Scan> {
    let bytes = super::read_bytes(path)?;
    parse_pcd(&bytes, &path.display().to_string())
}

/// How the data section is stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum DataKind {
    Ascii,
    Binary,
    BinaryCompressed,
}

/// One header field.
#[derive(Clone, Debug)]
struct Field {
    name: String,
    size: usize,
    ty: u8,
    count: usize,
}

/// Where a used field sits in a point: byte offset within a binary record, value index within
/// an ascii line, the field's size and type.
#[derive(Clone, Copy, Debug)]
struct Slot {
    field: usize,
    byte_offset: usize,
    value_index: usize,
    size: usize,
    ty: u8,
}

/// The parsed header.
struct Header {
    fields: Vec<Field>,
    points: usize,
    /// Sensor pose in the stored frame: `(t, R)`, `None` when it is the identity.
    viewpoint: Option<(DVec3, DMat3)>,
    data: DataKind,
    /// Line number (1-based) of the `DATA` line.
    data_line: usize,
    /// Byte offset of the first data byte.
    data_offset: usize,
}

/// The parsed header key values, with the line each came from.
#[derive(Default)]
struct RawHeader {
    fields: Option<(usize, Vec<String>)>,
    size: Option<(usize, Vec<usize>)>,
    ty: Option<(usize, Vec<u8>)>,
    count: Option<(usize, Vec<usize>)>,
    width: Option<(usize, usize)>,
    height: Option<(usize, usize)>,
    points: Option<(usize, usize)>,
    viewpoint: Option<(usize, [f64; 7])>,
    version: Option<usize>,
}

fn parse_header(bytes: &[u8], name: &str) -> Result<Header> {
    let at = |line: usize| format!("{name}:{line}");
    let mut raw = RawHeader::default();
    // A byte-order mark before the first line is skipped.
    let mut pos = bytes.len() - super::strip_bom(bytes).len();
    let mut line_no = 0usize;
    loop {
        if pos >= bytes.len() {
            return Err(Error::input(name, "header ends without a DATA line"));
        }
        let end = bytes[pos..].iter().position(|&b| b == b'\n').map_or(bytes.len(), |i| pos + i);
        line_no += 1;
        let line_bytes = &bytes[pos..end];
        pos = (end + 1).min(bytes.len());
        let line = std::str::from_utf8(line_bytes)
            .map_err(|_| Error::input(at(line_no), "header line is not text"))?
            .trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut tok = line.split_whitespace();
        let key = tok.next().unwrap_or_default();
        let vals: Vec<&str> = tok.collect();
        let l = line_no;
        let dup = |set: bool| -> Result<()> {
            if set {
                Err(Error::input(at(l), format!("header key {key} appears twice")))
            } else {
                Ok(())
            }
        };
        let one = || one_value(&vals, key, &at(l));
        let uint = |v: &str, what: &str| -> Result<usize> {
            v.parse::<usize>().map_err(|_| {
                Error::input(at(l), format!("{what} `{v}` is not a non-negative integer"))
            })
        };
        // The values of a SIZE or COUNT line: integers, none of them 0.
        let positive = |what: &str| -> Result<Vec<usize>> {
            vals.iter()
                .map(|s| match uint(s, key)? {
                    0 => Err(Error::input(at(l), format!("{key} 0 is not a {what}"))),
                    n => Ok(n),
                })
                .collect()
        };
        match key {
            "VERSION" => {
                dup(raw.version.is_some())?;
                let v = one()?;
                if !matches!(v, "0.7" | ".7" | "0.6" | ".6") {
                    return Err(Error::input(
                        at(l),
                        format!("VERSION {v} is not supported (0.6 or 0.7)"),
                    ));
                }
                raw.version = Some(l);
            }
            "FIELDS" => {
                dup(raw.fields.is_some())?;
                if vals.is_empty() {
                    return Err(Error::input(at(l), "FIELDS lists no field"));
                }
                raw.fields = Some((l, vals.iter().map(|s| s.to_string()).collect()));
            }
            "SIZE" => {
                dup(raw.size.is_some())?;
                raw.size = Some((l, positive("field size")?));
            }
            "TYPE" => {
                dup(raw.ty.is_some())?;
                let mut v = Vec::with_capacity(vals.len());
                for s in &vals {
                    match *s {
                        "F" | "I" | "U" => v.push(s.as_bytes()[0]),
                        _ => {
                            return Err(Error::input(
                                at(l),
                                format!("TYPE `{s}` is not one of F, I, U"),
                            ))
                        }
                    }
                }
                raw.ty = Some((l, v));
            }
            "COUNT" => {
                dup(raw.count.is_some())?;
                raw.count = Some((l, positive("field count")?));
            }
            "WIDTH" => {
                dup(raw.width.is_some())?;
                raw.width = Some((l, uint(one()?, "WIDTH")?));
            }
            "HEIGHT" => {
                dup(raw.height.is_some())?;
                raw.height = Some((l, uint(one()?, "HEIGHT")?));
            }
            "POINTS" => {
                dup(raw.points.is_some())?;
                raw.points = Some((l, uint(one()?, "POINTS")?));
            }
            "VIEWPOINT" => {
                dup(raw.viewpoint.is_some())?;
                if vals.len() != 7 {
                    return Err(Error::input(
                        at(l),
                        format!(
                            "VIEWPOINT takes 7 values (tx ty tz qw qx qy qz), found {}",
                            vals.len()
                        ),
                    ));
                }
                let mut v = [0.0; 7];
                for (d, s) in v.iter_mut().zip(&vals) {
                    *d = s.parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| {
                        Error::input(at(l), format!("VIEWPOINT value `{s}` is not a finite number"))
                    })?;
                }
                raw.viewpoint = Some((l, v));
            }
            "DATA" => {
                let data = match one()? {
                    "ascii" => DataKind::Ascii,
                    "binary" => DataKind::Binary,
                    "binary_compressed" => DataKind::BinaryCompressed,
                    other => {
                        return Err(Error::input(
                            at(l),
                            format!("DATA {other} is not one of ascii, binary, binary_compressed"),
                        ))
                    }
                };
                return finish_header(raw, name, data, l, pos);
            }
            _ => return Err(Error::input(at(l), format!("unknown header key `{key}`"))),
        }
    }
}

/// The single value of a header line.
fn one_value<'a>(vals: &[&'a str], key: &str, at: &str) -> Result<&'a str> {
    match vals {
        [v] => Ok(v),
        _ => Err(Error::input(at, format!("{key} takes one value, found {}", vals.len()))),
    }
}

fn finish_header(
    raw: RawHeader,
    name: &str,
    data: DataKind,
    data_line: usize,
    data_offset: usize,
) -> Result<Header> {
    let at = |line: usize| format!("{name}:{line}");
    let missing = |k: &str| Error::input(name, format!("header has no {k} line"));
    let (_, names) = raw.fields.ok_or_else(|| missing("FIELDS"))?;
    let (size_line, sizes) = raw.size.ok_or_else(|| missing("SIZE"))?;
    let (type_line, types) = raw.ty.ok_or_else(|| missing("TYPE"))?;
    let (_, width) = raw.width.ok_or_else(|| missing("WIDTH"))?;
    let (_, height) = raw.height.ok_or_else(|| missing("HEIGHT"))?;
    let (points_line, points) = raw.points.ok_or_else(|| missing("POINTS"))?;
    let n = names.len();
    let counts = match raw.count {
        Some((l, c)) => {
            if c.len() != n {
                return Err(Error::input(
                    at(l),
                    format!("COUNT has {} entries but FIELDS has {n}", c.len()),
                ));
            }
            c
        }
        None => vec![1; n],
    };
    if sizes.len() != n {
        return Err(Error::input(
            at(size_line),
            format!("SIZE has {} entries but FIELDS has {n}", sizes.len()),
        ));
    }
    if types.len() != n {
        return Err(Error::input(
            at(type_line),
            format!("TYPE has {} entries but FIELDS has {n}", types.len()),
        ));
    }
    if width.checked_mul(height) != Some(points) {
        return Err(Error::input(
            at(points_line),
            format!("POINTS {points} is not WIDTH {width} x HEIGHT {height}"),
        ));
    }
    let viewpoint = match raw.viewpoint {
        None => None,
        Some((l, [tx, ty, tz, qw, qx, qy, qz])) => {
            let q = DQuat::from_xyzw(qx, qy, qz, qw);
            let norm = q.length();
            if (norm - 1.0).abs() > 0.01 {
                return Err(Error::input(
                    at(l),
                    format!("VIEWPOINT quaternion (qw qx qy qz) has norm {norm}, not 1"),
                ));
            }
            let t = DVec3::new(tx, ty, tz);
            if t == DVec3::ZERO && qx == 0.0 && qy == 0.0 && qz == 0.0 {
                None
            } else {
                Some((t, DMat3::from_quat(q / norm)))
            }
        }
    };
    let fields = names
        .into_iter()
        .zip(sizes)
        .zip(types)
        .zip(counts)
        .map(|(((name, size), ty), count)| Field { name, size, ty, count })
        .collect();
    Ok(Header { fields, points, viewpoint, data, data_line, data_offset })
}

/// Finds field `want` and lays out where it sits; checks it appears at most once.
fn slot(fields: &[Field], want: &str, name: &str) -> Result<Option<Slot>> {
    let mut found = None;
    let (mut byte_offset, mut value_index) = (0usize, 0usize);
    for (i, f) in fields.iter().enumerate() {
        if f.name == want {
            if found.is_some() {
                return Err(Error::input(name, format!("field {want} appears twice in FIELDS")));
            }
            found = Some(Slot { field: i, byte_offset, value_index, size: f.size, ty: f.ty });
        }
        byte_offset = f
            .size
            .checked_mul(f.count)
            .and_then(|b| b.checked_add(byte_offset))
            .ok_or_else(|| Error::input(name, "the point record size overflows"))?;
        value_index += f.count;
    }
    Ok(found)
}

fn parse_pcd(bytes: &[u8], name: &str) -> Result<Scan> {
    let h = parse_header(bytes, name)?;
    let mut xyz = [None; 3];
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        let s = slot(&h.fields, axis, name)?.ok_or_else(|| {
            Error::input(name, format!("FIELDS has no {axis}; x, y and z are required"))
        })?;
        let f = &h.fields[s.field];
        if f.ty != b'F' || !(f.size == 4 || f.size == 8) {
            return Err(Error::input(
                name,
                format!(
                    "field {axis} has TYPE {} SIZE {}; only TYPE F with SIZE 4 or 8 is supported",
                    f.ty as char, f.size
                ),
            ));
        }
        if f.count != 1 {
            return Err(Error::input(
                name,
                format!("field {axis} has COUNT {}; it must be 1", f.count),
            ));
        }
        xyz[k] = Some(s);
    }
    let xyz = xyz.map(|s| s.expect("set above"));
    let ring = slot(&h.fields, "ring", name)?;
    if let Some(s) = ring {
        let f = &h.fields[s.field];
        if f.ty == b'F' || !matches!(f.size, 1 | 2 | 4 | 8) {
            return Err(Error::input(
                name,
                format!(
                    "field ring has TYPE {} SIZE {}; only an integer TYPE (U or I) of SIZE 1, 2, 4 or 8 is supported",
                    f.ty as char, f.size
                ),
            ));
        }
        if f.count != 1 {
            return Err(Error::input(
                name,
                format!("field ring has COUNT {}; it must be 1", f.count),
            ));
        }
    }
    // An intensity field is read when it is one number of a supported type; any other is
    // passed over like the fields pedscan does not use.
    let intensity = slot(&h.fields, "intensity", name)?.filter(|s| {
        let f = &h.fields[s.field];
        f.count == 1 && if f.ty == b'F' { matches!(f.size, 4 | 8) } else { matches!(f.ty, b'U' | b'I') && matches!(f.size, 1 | 2 | 4 | 8) }
    });
    let value = |s: &Slot, b: &[u8]| if s.ty == b'F' { float(b) } else { int(b, s.ty) as f64 };
    let mut out = Collector::new(h.viewpoint, ring.is_some(), intensity.is_some());
    let data = &bytes[h.data_offset.min(bytes.len())..];
    match h.data {
        DataKind::Ascii => read_ascii(data, &h, xyz, ring, intensity, name, &mut out)?,
        DataKind::Binary => {
            let step = record_bytes(&h.fields, name)?;
            let need = need_bytes(h.points, step, name)?;
            if data.len() != need {
                return Err(lying(name, &h, step, need, data));
            }
            let get = |s: &Slot, i: usize| &data[i * step + s.byte_offset..][..s.size];
            for i in 0..h.points {
                let p = [get(&xyz[0], i), get(&xyz[1], i), get(&xyz[2], i)].map(float);
                let r = ring.map(|s| int(get(&s, i), s.ty));
                let v = intensity.map(|s| value(&s, get(&s, i)));
                out.push(p, r, v).map_err(|m| Error::input(name, format!("point {i}: {m}")))?;
            }
        }
        DataKind::BinaryCompressed => {
            let step = record_bytes(&h.fields, name)?;
            let need = need_bytes(h.points, step, name)?;
            if data.len() < 8 {
                return Err(Error::input(
                    name,
                    format!("lying header: DATA binary_compressed but only {} data bytes follow, not even the 8-byte size prefix", data.len()),
                ));
            }
            let comp = u32::from_le_bytes(data[0..4].try_into().expect("4 bytes")) as usize;
            let uncomp = u32::from_le_bytes(data[4..8].try_into().expect("4 bytes")) as usize;
            let body = &data[8..];
            if body.len() != comp {
                return Err(Error::input(
                    name,
                    format!("lying header: compressed size is {comp} bytes but {} bytes follow", body.len()),
                ));
            }
            if uncomp != need {
                return Err(Error::input(
                    name,
                    format!(
                        "lying header: uncompressed size is {uncomp} bytes but POINTS {} x {step}-byte records is {need} bytes",
                        h.points
                    ),
                ));
            }
            if uncomp > comp.saturating_mul(LZF_MAX_RATIO) {
                return Err(Error::input(
                    name,
                    format!(
                        "{comp} bytes of LZF data cannot decompress to the declared {uncomp} bytes"
                    ),
                ));
            }
            let mut raw = Vec::new();
            lzf_decompress(&body[..comp], uncomp, &mut raw)
                .map_err(|m| Error::input(name, format!("LZF data: {m}")))?;
            // Column-wise: field f's column starts at POINTS x (offset of f in a record).
            let n = h.points;
            let col = |s: &Slot, i: usize| {
                let stride = h.fields[s.field].size * h.fields[s.field].count;
                &raw[n * s.byte_offset + i * stride..][..s.size]
            };
            for i in 0..n {
                let p = [col(&xyz[0], i), col(&xyz[1], i), col(&xyz[2], i)].map(float);
                let r = ring.map(|s| int(col(&s, i), s.ty));
                let v = intensity.map(|s| value(&s, col(&s, i)));
                out.push(p, r, v).map_err(|m| Error::input(name, format!("point {i}: {m}")))?;
            }
        }
    }
    Ok(out.finish())
}

fn record_bytes(fields: &[Field], name: &str) -> Result<usize> {
    fields
        .iter()
        .try_fold(0usize, |a, f| f.size.checked_mul(f.count).and_then(|b| a.checked_add(b)))
        .ok_or_else(|| Error::input(name, "the point record size overflows"))
}

fn need_bytes(points: usize, step: usize, name: &str) -> Result<usize> {
    points.checked_mul(step).ok_or_else(|| {
        Error::input(name, format!("lying header: POINTS {points} x {step}-byte records overflows"))
    })
}

/// The error for a binary body of the wrong size, with a hint when the body is text.
fn lying(name: &str, h: &Header, step: usize, need: usize, data: &[u8]) -> Error {
    let text = !data.is_empty() && data.iter().all(|&b| b.is_ascii_graphic() || b.is_ascii_whitespace());
    Error::input(
        name,
        format!(
            "lying header: POINTS {} x {step}-byte records is {need} bytes of data but {} follow{}",
            h.points,
            data.len(),
            if text { " (the data is text: DATA ascii?)" } else { "" }
        ),
    )
}

/// An `f32` or `f64` little-endian value (the caller checked the size is 4 or 8).
fn float(b: &[u8]) -> f64 {
    match b.len() {
        4 => f32::from_le_bytes(b.try_into().expect("4 bytes")) as f64,
        _ => f64::from_le_bytes(b.try_into().expect("8 bytes")),
    }
}

/// A little-endian integer of 1, 2, 4 or 8 bytes, signed when `ty` is `I`.
fn int(b: &[u8], ty: u8) -> i128 {
    let signed = ty == b'I';
    match b.len() {
        1 if signed => b[0] as i8 as i128,
        1 => b[0] as i128,
        2 if signed => i16::from_le_bytes([b[0], b[1]]) as i128,
        2 => u16::from_le_bytes([b[0], b[1]]) as i128,
        4 if signed => i32::from_le_bytes(b.try_into().expect("4 bytes")) as i128,
        4 => u32::from_le_bytes(b.try_into().expect("4 bytes")) as i128,
        _ if signed => i64::from_le_bytes(b.try_into().expect("8 bytes")) as i128,
        _ => u64::from_le_bytes(b.try_into().expect("8 bytes")) as i128,
    }
}

fn read_ascii(
    data: &[u8],
    h: &Header,
    xyz: [Slot; 3],
    ring: Option<Slot>,
    intensity: Option<Slot>,
    name: &str,
    out: &mut Collector,
) -> Result<()> {
    let values_per_point: usize = h.fields.iter().map(|f| f.count).sum();
    let mut read = 0usize;
    for (i, raw_line) in data.split(|&b| b == b'\n').enumerate() {
        let line_no = h.data_line + 1 + i;
        let at = || format!("{name}:{line_no}");
        let line = std::str::from_utf8(raw_line)
            .map_err(|_| Error::input(at(), "data line is not text"))?;
        if line.trim().is_empty() {
            continue;
        }
        if read == h.points {
            return Err(Error::input(at(), format!("more data lines than POINTS {}", h.points)));
        }
        let mut p = [0.0f64; 3];
        let mut r = None;
        let mut v_intensity = None;
        let mut n = 0usize;
        for (k, tok) in line.split_whitespace().enumerate() {
            n += 1;
            if k >= values_per_point {
                continue; // counted, reported below
            }
            let v: f64 = tok.parse().map_err(|_| {
                Error::input(at(), format!("value {} `{tok}` is not a number", k + 1))
            })?;
            for (a, s) in xyz.iter().enumerate() {
                if s.value_index == k {
                    p[a] = v;
                }
            }
            if ring.is_some_and(|s| s.value_index == k) {
                r = Some(v);
            }
            if intensity.is_some_and(|s| s.value_index == k) {
                v_intensity = Some(v);
            }
        }
        if n != values_per_point {
            return Err(Error::input(
                at(),
                format!("expected {values_per_point} values (the FIELDS x COUNT of the header), found {n}"),
            ));
        }
        let r = match r {
            None => None,
            Some(v) if v.fract() == 0.0 && v.abs() < 1e30 => Some(v as i128),
            // Not an integer: passed on as out of range (reported only for a kept point).
            Some(_) => Some(-1),
        };
        out.push(p, r, v_intensity).map_err(|m| Error::input(at(), m))?;
        read += 1;
    }
    if read < h.points {
        return Err(Error::input(
            name,
            format!("lying header: POINTS {} but only {read} data lines follow", h.points),
        ));
    }
    Ok(())
}

/// Accumulates kept points (and rings) in the sensor frame.
struct Collector {
    viewpoint: Option<(DVec3, DMat3)>,
    points: Vec<[f32; 3]>,
    ring: Option<Vec<u16>>,
    intensity: Option<Vec<f32>>,
}

impl Collector {
    fn new(viewpoint: Option<(DVec3, DMat3)>, has_ring: bool, has_intensity: bool) -> Self {
        Collector { viewpoint, points: Vec::new(), ring: has_ring.then(Vec::new), intensity: has_intensity.then(Vec::new) }
    }

    /// Adds one stored point; NaN and all-zero points are dropped. A ring value outside
    /// 0..=65535 of a kept point is an error (the message only); a non-finite intensity is
    /// read as 0.
    fn push(&mut self, p: [f64; 3], ring: Option<i128>, intensity: Option<f64>) -> std::result::Result<(), String> {
        if p == [0.0; 3] || !p.iter().all(|v| v.is_finite()) {
            return Ok(());
        }
        let q = match self.viewpoint {
            None => DVec3::from(p),
            Some((t, r)) => r.transpose() * (DVec3::from(p) - t),
        };
        let q = [q.x as f32, q.y as f32, q.z as f32];
        if !q.iter().all(|v| v.is_finite()) {
            return Ok(());
        }
        if let (Some(rings), Some(r)) = (self.ring.as_mut(), ring) {
            let r = u16::try_from(r)
                .map_err(|_| "ring value is not an integer in 0..=65535".to_string())?;
            rings.push(r);
        }
        if let (Some(values), Some(v)) = (self.intensity.as_mut(), intensity) {
            values.push(if v.is_finite() { v as f32 } else { 0.0 });
        }
        self.points.push(q);
        Ok(())
    }

    fn finish(self) -> Scan {
        Scan { points: self.points, ring: self.ring, intensity: self.intensity, ..Scan::default() }
    }
}

/// The most output bytes one LZF input byte can give: a 3-byte back-reference copies up to
/// 7 + 255 + 2 = 264 bytes.
const LZF_MAX_RATIO: usize = 88;

/// Decompresses LZF (liblzf's format, as written by PCL) into `out`, which must come out at
/// exactly `expected` bytes. A control byte below 32 starts a literal run of `ctrl + 1` bytes;
/// otherwise its top 3 bits are a length (7 = read one more length byte), and its low 5 bits
/// with the next byte are a distance back into the output: copy `length + 2` bytes from
/// `distance + 1` bytes back (the copy may overlap itself).
fn lzf_decompress(
    input: &[u8],
    expected: usize,
    out: &mut Vec<u8>,
) -> std::result::Result<(), String> {
    out.clear();
    out.reserve_exact(expected);
    let mut ip = 0usize;
    let too_long = || format!("decompresses past the declared {expected} bytes");
    while ip < input.len() {
        let ctrl = input[ip] as usize;
        ip += 1;
        if ctrl < 32 {
            let len = ctrl + 1;
            let lit = input.get(ip..ip + len).ok_or_else(|| {
                format!("a literal run at byte {} runs past the end of the data", ip - 1)
            })?;
            if out.len() + len > expected {
                return Err(too_long());
            }
            out.extend_from_slice(lit);
            ip += len;
        } else {
            let mut len = ctrl >> 5;
            if len == 7 {
                len += *input.get(ip).ok_or("the data ends inside a back-reference")? as usize;
                ip += 1;
            }
            let low = *input.get(ip).ok_or("the data ends inside a back-reference")? as usize;
            ip += 1;
            let back = ((ctrl & 0x1f) << 8) + low + 1;
            len += 2;
            if back > out.len() {
                return Err(format!(
                    "a back-reference at byte {} points {back} bytes back but only {} bytes are decompressed",
                    ip - 2,
                    out.len()
                ));
            }
            if out.len() + len > expected {
                return Err(too_long());
            }
            let start = out.len() - back;
            if back >= len {
                out.extend_from_within(start..start + len);
            } else {
                for k in 0..len {
                    let b = out[start + k];
                    out.push(b);
                }
            }
        }
    }
    if out.len() != expected {
        return Err(format!("decompresses to {} bytes, not the declared {expected}", out.len()));
    }
    Ok(())
}

#[cfg(test)]
mod tests;
