//! Importers for recorded pedestrian tracks (ETH/UCY, Trajectron++, ATC, pedscan CSV) and a
//! smooth, time-continuous model of one imported track.
//!
//! # Formats
//!
//! All readers skip blank lines and lines starting with `#`. Every bad record is reported as
//! [`Error::input`] with `FILE:LINE` as the input, so the user can go straight to it.
//!
//! * [`TrackFormat::Eth`] — ETH/UCY `obsmat.txt` (as in OpenTraj): 8 whitespace separated
//!   floats per line, `frame ped_id pos_x pos_z pos_y v_x v_z v_y`, metres and m/s in the
//!   dataset's world frame. `pos_z`/`v_z` are unused (always 0). The annotated velocities are
//!   parsed and checked for being finite but not used: velocity comes from the interpolant of the
//!   positions, so position and velocity stay consistent. Time = frame number ×
//!   [`TrackOptions::frame_period_s`]. The annotation is at 2.5 Hz (0.4 s, see the sequences'
//!   `info.txt`); in `seq_hotel` and UCY `zara01` the frame numbers step by 10 per annotation
//!   (25 fps video) → 0.04 s per frame number, the default; in `seq_eth` they step by 6
//!   (15 fps video) → use `frame_period_s = 0.4 / 6` (≈ 0.0667 s).
//! * [`TrackFormat::Eth4`] — the 4-column Trajectron++ / Social-GAN text files
//!   (`biwi_hotel.txt`, `crowds_zara01.txt`, …): `frame ped_id x y`, tab or space separated,
//!   metres. Their frame numbers step by 10 per 0.4 s annotation interval → 0.04 s per frame
//!   number, the same default [`TrackOptions::frame_period_s`].
//! * [`TrackFormat::Atc`] — ATC shopping-centre CSV (one file per day): `time, id, x, y, z,
//!   velocity, motion_angle, facing_angle` with time in seconds (unix time with millisecond
//!   decimals, used as is), positions in mm (converted to m; z, the height, is unused), velocity
//!   in mm/s and both angles in rad. Velocity and motion angle are checked but unused (velocity
//!   comes from the interpolant). The facing angle is kept as the heading; it may be left empty,
//!   and a track whose every record has one gets [`Track::heading_rad`] = `Some`.
//! * [`TrackFormat::Csv`] — pedscan's own CSV. The first non-comment line is the header, exactly
//!   `t_s,id,x_m,y_m` or `t_s,id,x_m,y_m,heading_rad`; then one record per line: time (s),
//!   integer id, position (m), and with the 5-column header the facing heading (rad,
//!   counter-clockwise from +x). Spaces around fields are allowed.
//!
//! Records are grouped by id and sorted by time; two records of one id at the same time (closer
//! than [`MIN_DT_S`]) are rejected, naming both lines, since they would give infinite
//! velocities. Ids must be integers (the ETH files write them as floats such as `1.0e+00`).
//! An empty file, or one with no record, is an error. Positions and headings are mapped to the
//! world frame by [`TrackOptions::transform`] (whose values must be within the ranges of
//! [`Transform2::check`]).
//!
//! Every record is checked before any is grouped or sorted: its time must be within
//! [`MAX_TIME_S`](super::MAX_TIME_S) of 0 (after the frame period) and its position, mapped to
//! the world frame, within [`MAX_COORDINATE_M`](super::MAX_COORDINATE_M) of the origin on each
//! axis; else the error names `FILE:LINE`. A UTF-8 byte-order mark at the start of the file is
//! skipped.

use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::path::Path;

use glam::DVec2;
use serde::{Deserialize, Serialize};

use super::{read_text, MAX_COORDINATE_M, MAX_TIME_S};
use crate::error::{Error, Result};

/// Two timestamps of one id closer than this (s) are duplicates.
pub const MIN_DT_S: f64 = 1e-6;

/// Below this speed (m/s) the heading from motion is held, so standing people do not spin.
pub const HEADING_HOLD_SPEED_MPS: f64 = 0.05;

/// Frame period of the ETH-hotel / UCY / Trajectron++ files: 0.4 s per 10 frame numbers.
pub const DEFAULT_FRAME_PERIOD_S: f64 = 0.04;

/// The file format of a track file; see the module documentation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum TrackFormat {
    /// ETH/UCY `obsmat.txt`: `frame ped_id x z y vx vz vy`.
    Eth,
    /// Trajectron++ 4-column text: `frame ped_id x y`.
    Eth4,
    /// ATC CSV: `time_s, id, x_mm, y_mm, z_mm, v_mm_s, motion_angle, facing_angle`.
    Atc,
    /// pedscan CSV with header `t_s,id,x_m,y_m[,heading_rad]`.
    Csv,
}

/// A 2-D similarity `world_from_track`: `p_world = translation + scale * R(rotation) * p_track`;
/// headings are rotated by `rotation_deg`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Transform2 {
    /// Counter-clockwise rotation, degrees.
    pub rotation_deg: f64,
    /// Translation `[x, y]`, m (applied after rotation and scale).
    pub translation_m: [f64; 2],
    /// Uniform scale, > 0.
    pub scale: f64,
}

impl Default for Transform2 {
    fn default() -> Self {
        Transform2 {
            rotation_deg: 0.0,
            translation_m: [0.0, 0.0],
            scale: 1.0,
        }
    }
}

/// Bounds of [`Transform2::scale`]: from micrometres to kilometres per unit either way.
pub const TRANSFORM_SCALE_RANGE: [f64; 2] = [1e-6, 1e6];

impl Transform2 {
    /// Checks the documented ranges: a finite rotation of at most one turn either way
    /// (|`rotation_deg`| <= 360), a translation within [`MAX_COORDINATE_M`] on each axis and a
    /// scale within [`TRANSFORM_SCALE_RANGE`]; the error is the message only.
    pub fn check(&self) -> std::result::Result<(), String> {
        let [lo, hi] = TRANSFORM_SCALE_RANGE;
        if !(self.rotation_deg.is_finite() && self.rotation_deg.abs() <= 360.0) {
            return Err(format!("rotation {:?} deg must be a finite number in [-360, 360]", self.rotation_deg));
        }
        if !self.translation_m.iter().all(|v| v.is_finite() && v.abs() <= MAX_COORDINATE_M) {
            let [x, y] = self.translation_m;
            return Err(format!("translation ({x:?}, {y:?}) m must be finite and within {MAX_COORDINATE_M:e} m of the origin"));
        }
        if !(self.scale >= lo && self.scale <= hi) {
            return Err(format!("scale {:?} must be in [{lo:e}, {hi:e}]", self.scale));
        }
        Ok(())
    }

    /// Maps a point of the track file to the world frame.
    pub fn point(&self, p: DVec2) -> DVec2 {
        let r = DVec2::from_angle(self.rotation_deg.to_radians());
        DVec2::from(self.translation_m) + self.scale * r.rotate(p)
    }
    /// Maps a heading of the track file to the world frame, wrapped to [-π, π).
    pub fn heading(&self, h: f64) -> f64 {
        wrap_angle(h + self.rotation_deg.to_radians())
    }
}

/// How to read a track file.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackOptions {
    /// Seconds per frame-number unit for `eth` and `eth4` (default 0.04 s: 0.4 s per 10 frame
    /// numbers; ETH `seq_eth` needs 0.4 / 6 s). Unused by `atc` and `csv`.
    pub frame_period_s: f64,
    /// `world_from_track`.
    pub transform: Transform2,
}

impl Default for TrackOptions {
    fn default() -> Self {
        TrackOptions {
            frame_period_s: DEFAULT_FRAME_PERIOD_S,
            transform: Transform2::default(),
        }
    }
}

/// One person's recorded track in the world frame, sorted by time with strictly increasing times.
#[derive(Clone, Debug, PartialEq)]
pub struct Track {
    pub id: i64,
    pub times_s: Vec<f64>,
    pub xy_m: Vec<DVec2>,
    /// Facing heading per sample (rad, world frame) when the file gives one.
    pub heading_rad: Option<Vec<f64>>,
}

/// A track's state at one instant (world frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackState {
    pub position_m: DVec2,
    pub velocity_mps: DVec2,
    pub heading_rad: f64,
}

/// One parsed record.
struct Rec {
    line: usize,
    t: f64,
    id: i64,
    xy: DVec2,
    heading: Option<f64>,
}

/// Reads all tracks of `path`, grouped by id (ascending) and sorted by time.
pub fn read_tracks(path: &Path, format: TrackFormat, opts: &TrackOptions) -> Result<Vec<Track>> {
    let fp = opts.frame_period_s;
    if matches!(format, TrackFormat::Eth | TrackFormat::Eth4) && !(fp.is_finite() && fp > 0.0) {
        return Err(Error::input(
            "track frame period",
            format!("{fp} s must be positive and finite"),
        ));
    }
    let tf = &opts.transform;
    tf.check().map_err(|m| Error::input("track transform", m))?;
    let text = read_text(path)?;
    let at = |line: usize| format!("{}:{}", path.display(), line);

    let mut recs = Vec::new();
    let mut csv_cols: Option<usize> = None;
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let s = raw.trim();
        if s.is_empty() || s.starts_with('#') {
            continue;
        }
        let rec = match format {
            TrackFormat::Eth | TrackFormat::Eth4 => {
                let f: Vec<&str> = s.split_whitespace().collect();
                let want = if format == TrackFormat::Eth { 8 } else { 4 };
                if f.len() != want {
                    return Err(Error::input(
                        at(line),
                        format!("expected {want} columns, found {}", f.len()),
                    ));
                }
                let v = parse_all(&f, &at(line))?;
                let (x, y) = if format == TrackFormat::Eth {
                    (v[2], v[4])
                } else {
                    (v[2], v[3])
                };
                Rec {
                    line,
                    t: v[0] * fp,
                    id: to_id(v[1], &at(line))?,
                    xy: DVec2::new(x, y),
                    heading: None,
                }
            }
            TrackFormat::Atc => {
                let f: Vec<&str> = s.split(',').map(str::trim).collect();
                if f.len() != 8 {
                    return Err(Error::input(
                        at(line),
                        format!("expected 8 comma-separated columns, found {}", f.len()),
                    ));
                }
                let v = parse_all(&f[..7], &at(line))?;
                let heading = if f[7].is_empty() {
                    None
                } else {
                    Some(parse_num(f[7], 8, &at(line))?)
                };
                let id = parse_int_id(f[1], &at(line))?;
                Rec {
                    line,
                    t: v[0],
                    id,
                    xy: DVec2::new(v[2], v[3]) * 1e-3,
                    heading,
                }
            }
            TrackFormat::Csv => {
                let f: Vec<&str> = s.split(',').map(str::trim).collect();
                let Some(cols) = csv_cols else {
                    csv_cols = match f.as_slice() {
                        ["t_s", "id", "x_m", "y_m"] => Some(4),
                        ["t_s", "id", "x_m", "y_m", "heading_rad"] => Some(5),
                        _ => {
                            return Err(Error::input(
                                at(line),
                                format!("expected the header `t_s,id,x_m,y_m` or `t_s,id,x_m,y_m,heading_rad`, found `{s}`"),
                            ))
                        }
                    };
                    continue;
                };
                if f.len() != cols {
                    return Err(Error::input(
                        at(line),
                        format!("expected {cols} columns (as the header), found {}", f.len()),
                    ));
                }
                let t = parse_num(f[0], 1, &at(line))?;
                let id = parse_int_id(f[1], &at(line))?;
                let x = parse_num(f[2], 3, &at(line))?;
                let y = parse_num(f[3], 4, &at(line))?;
                let heading = if cols == 5 {
                    Some(parse_num(f[4], 5, &at(line))?)
                } else {
                    None
                };
                Rec {
                    line,
                    t,
                    id,
                    xy: DVec2::new(x, y),
                    heading,
                }
            }
        };
        if !rec.t.is_finite() || rec.t.abs() > MAX_TIME_S {
            return Err(Error::input(at(line), format!("time {:?} s is beyond the supported {MAX_TIME_S:e} s", rec.t)));
        }
        // In the world frame from here on; checked before anything is grouped or sorted.
        let xy = tf.point(rec.xy);
        if !xy.is_finite() || xy.abs().max_element() > MAX_COORDINATE_M {
            return Err(Error::input(
                at(line),
                format!(
                    "position ({:?}, {:?}) m in the world (after the track transform) is farther than the supported \
                     {MAX_COORDINATE_M:e} m from the origin",
                    xy.x, xy.y
                ),
            ));
        }
        recs.push(Rec { xy, ..rec });
    }
    if recs.is_empty() {
        return Err(Error::input(path.display(), "holds no track record"));
    }

    let mut by_id: BTreeMap<i64, Vec<Rec>> = BTreeMap::new();
    for r in recs {
        by_id.entry(r.id).or_default().push(r);
    }
    let mut tracks = Vec::with_capacity(by_id.len());
    for (id, mut rs) in by_id {
        rs.sort_by(|a, b| a.t.total_cmp(&b.t).then(a.line.cmp(&b.line)));
        for w in rs.windows(2) {
            if w[1].t - w[0].t < MIN_DT_S {
                return Err(Error::input(
                    at(w[1].line),
                    format!(
                        "duplicate timestamp {} s for id {id} (also on line {})",
                        w[1].t, w[0].line
                    ),
                ));
            }
        }
        let heading = if rs.iter().all(|r| r.heading.is_some()) {
            Some(
                rs.iter()
                    .map(|r| tf.heading(r.heading.unwrap_or(0.0)))
                    .collect(),
            )
        } else {
            None
        };
        tracks.push(Track {
            id,
            times_s: rs.iter().map(|r| r.t).collect(),
            xy_m: rs.iter().map(|r| r.xy).collect(),
            heading_rad: heading,
        });
    }
    Ok(tracks)
}

/// Drops the tracks shorter than `length_s` (see [`Track::windows`]).
pub fn drop_short(tracks: Vec<Track>, length_s: f64) -> Vec<Track> {
    tracks.into_iter().filter(|t| t.windows(length_s)).collect()
}

fn parse_num(s: &str, column: usize, at: &str) -> Result<f64> {
    let v: f64 = s
        .parse()
        .map_err(|_| Error::input(at, format!("column {column}: `{s}` is not a number")))?;
    if !v.is_finite() {
        return Err(Error::input(
            at,
            format!("column {column}: `{s}` is not finite"),
        ));
    }
    Ok(v)
}

fn parse_all(f: &[&str], at: &str) -> Result<Vec<f64>> {
    f.iter()
        .enumerate()
        .map(|(i, s)| parse_num(s, i + 1, at))
        .collect()
}

/// An id written as a float (ETH: `1.0000000e+00`) must be an integer.
fn to_id(v: f64, at: &str) -> Result<i64> {
    if v.fract() != 0.0 || v.abs() > 9.0e15 {
        return Err(Error::input(
            at,
            format!("column 2: id {v} is not an integer"),
        ));
    }
    Ok(v as i64)
}

fn parse_int_id(s: &str, at: &str) -> Result<i64> {
    match s.parse::<i64>() {
        Ok(v) => Ok(v),
        Err(_) => to_id(parse_num(s, 2, at)?, at),
    }
}

/// Wraps to [-π, π); angles already in range are returned unchanged (bit for bit).
fn wrap_angle(a: f64) -> f64 {
    if (-PI..PI).contains(&a) {
        a
    } else {
        crate::geometry::wrap_pi(a)
    }
}

// Cubic Hermite basis functions and their derivatives (in s).
fn h10(s: f64) -> f64 {
    s * (s - 1.0) * (s - 1.0)
}
fn h11(s: f64) -> f64 {
    s * s * (s - 1.0)
}
fn dh10(s: f64) -> f64 {
    (3.0 * s - 1.0) * (s - 1.0)
}
fn dh11(s: f64) -> f64 {
    s * (3.0 * s - 2.0)
}

impl Track {
    /// Time from the first to the last sample, s.
    pub fn duration_s(&self) -> f64 {
        match (self.times_s.first(), self.times_s.last()) {
            (Some(a), Some(b)) => b - a,
            _ => 0.0,
        }
    }

    /// True when the track covers a window of `length_s` seconds.
    pub fn windows(&self, length_s: f64) -> bool {
        !self.times_s.is_empty() && self.duration_s() >= length_s
    }

    /// Slope of the chord from sample `k` to `k + 1`, m/s.
    fn chord(&self, k: usize) -> DVec2 {
        (self.xy_m[k + 1] - self.xy_m[k]) / (self.times_s[k + 1] - self.times_s[k])
    }

    /// Tangent (m/s) at sample `i`: the central finite difference over the two neighbours
    /// (Catmull-Rom for non-uniform times), one-sided at the ends, limited per component as
    /// Fritsch-Carlson: 0 where the neighbouring chords differ in sign or one is 0 (a local
    /// extremum or a standstill), else at most 3 × the smaller chord slope. This keeps the
    /// interpolant from overshooting, so a person who stops stays put instead of swinging back.
    /// Equal chords are not limited, so a straight constant-speed track keeps its exact slope.
    fn tangent(&self, i: usize) -> DVec2 {
        let n = self.times_s.len();
        if n < 2 {
            return DVec2::ZERO;
        }
        if i == 0 {
            return self.chord(0);
        }
        if i == n - 1 {
            return self.chord(n - 2);
        }
        let (dl, dr) = (self.chord(i - 1), self.chord(i));
        let cr =
            (self.xy_m[i + 1] - self.xy_m[i - 1]) / (self.times_s[i + 1] - self.times_s[i - 1]);
        let limit = |m: f64, a: f64, b: f64| {
            if a * b <= 0.0 {
                0.0
            } else {
                let cap = 3.0 * a.abs().min(b.abs());
                m.clamp(-cap, cap)
            }
        };
        DVec2::new(limit(cr.x, dl.x, dr.x), limit(cr.y, dl.y, dr.y))
    }

    /// Segment index `i` (t_i <= t <= t_{i+1}) and its parameter s in [0, 1].
    fn locate(&self, t_s: f64) -> Option<(usize, f64)> {
        let ts = &self.times_s;
        let n = ts.len();
        if n < 2 || !(t_s >= ts[0] && t_s <= ts[n - 1]) {
            return None;
        }
        let i = ts
            .partition_point(|&x| x <= t_s)
            .saturating_sub(1)
            .min(n - 2);
        Some((i, ((t_s - ts[i]) / (ts[i + 1] - ts[i])).clamp(0.0, 1.0)))
    }

    /// Position and velocity of the cubic Hermite interpolant on segment `i` at `s`.
    /// Written around the chord slope `d` so a straight constant-speed track (tangents equal to
    /// `d`) gives exactly `d` as velocity.
    fn hermite(&self, i: usize, s: f64) -> (DVec2, DVec2) {
        let (p0, p1) = (self.xy_m[i], self.xy_m[i + 1]);
        let h = self.times_s[i + 1] - self.times_s[i];
        let d = (p1 - p0) / h;
        let (e0, e1) = (self.tangent(i) - d, self.tangent(i + 1) - d);
        let p = if s == 0.0 {
            p0
        } else if s == 1.0 {
            p1
        } else {
            p0 + s * (p1 - p0) + h * (h10(s) * e0 + h11(s) * e1)
        };
        (p, d + dh10(s) * e0 + dh11(s) * e1)
    }

    /// The latest heading of motion (speed >= the hold speed) in segment `i` at or before `s`,
    /// searched on 16 sub-steps and refined by bisection.
    fn last_moving_heading(&self, i: usize, s: f64) -> Option<f64> {
        let moving = |s: f64| self.hermite(i, s).1.length() >= HEADING_HOLD_SPEED_MPS;
        const STEPS: usize = 16;
        let mut hi = s; // not moving at `hi` unless found below
        for k in (0..=STEPS).rev() {
            let lo = s * k as f64 / STEPS as f64;
            if moving(lo) {
                let (mut a, mut b) = (lo, hi);
                if moving(b) {
                    a = b;
                }
                for _ in 0..40 {
                    let m = 0.5 * (a + b);
                    if moving(m) {
                        a = m;
                    } else {
                        b = m;
                    }
                }
                let v = self.hermite(i, a).1;
                return Some(v.y.atan2(v.x));
            }
            hi = lo;
        }
        None
    }

    /// Heading from motion while standing: the last moving direction before (segment `i`, `s`),
    /// else the first moving direction after it, else 0.
    fn held_heading(&self, i: usize, s: f64) -> f64 {
        if let Some(h) = self.last_moving_heading(i, s) {
            return h;
        }
        for j in (0..i).rev() {
            if let Some(h) = self.last_moving_heading(j, 1.0) {
                return h;
            }
        }
        let n = self.times_s.len();
        for j in i..n.saturating_sub(1) {
            for k in 0..=16 {
                let v = self.hermite(j, k as f64 / 16.0).1;
                if v.length() >= HEADING_HOLD_SPEED_MPS {
                    return v.y.atan2(v.x);
                }
            }
        }
        0.0
    }

    /// State at `t_s`, or `None` outside [first time, last time].
    ///
    /// Position: cubic Hermite interpolation of the samples with finite-difference (Catmull-Rom)
    /// tangents, limited against overshoot (see `tangent`) — C1, exact at the samples. Velocity: the derivative of that interpolant.
    /// Heading: the given facing heading interpolated along the shorter arc when the track has
    /// one, else the direction of motion, held at its last value while the speed is below
    /// [`HEADING_HOLD_SPEED_MPS`] (before the first motion: the first direction of motion).
    /// A single-sample track is defined only at its time, with zero velocity.
    pub fn sample(&self, t_s: f64) -> Option<TrackState> {
        let n = self.times_s.len();
        if n == 1 && t_s == self.times_s[0] {
            let heading = self.heading_rad.as_ref().map_or(0.0, |h| h[0]);
            return Some(TrackState {
                position_m: self.xy_m[0],
                velocity_mps: DVec2::ZERO,
                heading_rad: heading,
            });
        }
        let (i, s) = self.locate(t_s)?;
        let (p, v) = self.hermite(i, s);
        let heading = match &self.heading_rad {
            Some(h) => {
                if s == 0.0 {
                    h[i]
                } else if s == 1.0 {
                    h[i + 1]
                } else {
                    wrap_angle(h[i] + s * wrap_angle(h[i + 1] - h[i]))
                }
            }
            None if v.length() >= HEADING_HOLD_SPEED_MPS => v.y.atan2(v.x),
            None => self.held_heading(i, s),
        };
        Some(TrackState {
            position_m: p,
            velocity_mps: v,
            heading_rad: heading,
        })
    }
}

#[cfg(test)]
mod tests;
