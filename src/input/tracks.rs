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
use std::f64::consts::{PI, TAU};
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
        (a + PI).rem_euclid(TAU) - PI
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
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> PathBuf {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    fn read(p: &Path, f: TrackFormat) -> Result<Vec<Track>> {
        read_tracks(p, f, &TrackOptions::default())
    }

    /// The error is an input error naming `FILE:LINE`.
    fn expect_err(p: &Path, f: TrackFormat, line: usize, needle: &str) {
        let e = read(p, f).expect_err("must fail");
        assert!(e.is_input(), "{e}");
        let msg = e.to_string();
        assert!(
            msg.starts_with(&format!("{}:{line}:", p.display())),
            "{msg}"
        );
        assert!(msg.contains(needle), "{msg} lacks {needle}");
    }

    const ETH: &str = "\
   7.8000000e+02   1.0000000e+00   8.4568443e+00   0.0000000e+00   3.5880664e+00   1.6717144e+00   0.0000000e+00   1.7629183e-01
   7.8000000e+02   2.0000000e+00   1.0000000e+00   0.0000000e+00   2.0000000e+00   0.0   0.0   0.0
   7.9000000e+02   1.0000000e+00   9.1255301e+00   0.0000000e+00   3.6585832e+00   1.6628772e+00   0.0000000e+00   3.2672255e-01
   8.0000000e+02   1.0000000e+00   9.7871460e+00   0.0000000e+00   3.8494445e+00   1.6833339e+00   0.0000000e+00   3.7108399e-01
   7.7000000e+02   1.0000000e+00   7.8000000e+00   0.0000000e+00   3.5000000e+00   1.6   0.0   0.2
";

    #[test]
    fn eth_reader_groups_sorts_and_scales_frames() {
        let d = tempfile::tempdir().unwrap();
        let p = write(&d, "obsmat.txt", ETH);
        let tr = read(&p, TrackFormat::Eth).unwrap();
        assert_eq!(tr.len(), 2);
        assert_eq!(tr[0].id, 1);
        assert_eq!(
            tr[0].times_s,
            vec![770.0 * 0.04, 780.0 * 0.04, 790.0 * 0.04, 800.0 * 0.04]
        );
        assert_eq!(tr[0].xy_m[0], DVec2::new(7.8, 3.5));
        assert_eq!(
            tr[0].xy_m[1],
            DVec2::new(8.4568443, 3.5880664),
            "x and y, not z"
        );
        assert!(tr[0].heading_rad.is_none());
        assert_eq!(tr[1].id, 2);
        assert_eq!(tr[1].times_s.len(), 1);
        assert!((tr[0].duration_s() - 1.2).abs() < 1e-12);
        // seq_eth: 6 frame numbers per 0.4 s.
        let o = TrackOptions {
            frame_period_s: 0.4 / 6.0,
            ..Default::default()
        };
        let tr = read_tracks(&p, TrackFormat::Eth, &o).unwrap();
        assert!((tr[0].times_s[1] - 52.0).abs() < 1e-9);
    }

    #[test]
    fn eth4_reader_tabs_and_spaces() {
        let d = tempfile::tempdir().unwrap();
        let p = write(
            &d,
            "biwi.txt",
            "0\t1.0\t1.41\t-5.68\n0\t2.0\t0.51\t-6.94\n\n10 1.0  1.5 -5.0\n20.0\t1.0\t1.6\t-4.5\n",
        );
        let tr = read(&p, TrackFormat::Eth4).unwrap();
        assert_eq!(tr.len(), 2);
        assert_eq!(tr[0].times_s, vec![0.0, 0.4, 0.8]);
        assert_eq!(
            tr[0].xy_m,
            vec![
                DVec2::new(1.41, -5.68),
                DVec2::new(1.5, -5.0),
                DVec2::new(1.6, -4.5)
            ]
        );
        assert_eq!(tr[1].xy_m, vec![DVec2::new(0.51, -6.94)]);
    }

    #[test]
    fn atc_reader_mm_to_m_and_facing() {
        let d = tempfile::tempdir().unwrap();
        let text = "1351065600.025,9315700,-10000,2000,1650,1200,0.5,1.0\n\
                    1351065600.055,9315700,-9964,2019,1650,1200,0.5,1.1\n\
                    1351065600.085,9315700,-9928,2038,1650,1200,0.5,1.2\n\
                    1351065600.025,9315800,100,200,1600,0,0,\n\
                    1351065600.055,9315800,100,200,1600,0,0,\n";
        let p = write(&d, "atc-20121024.csv", text);
        let tr = read(&p, TrackFormat::Atc).unwrap();
        assert_eq!(tr.len(), 2);
        assert_eq!(tr[0].id, 9315700);
        assert_eq!(tr[0].xy_m[0], DVec2::new(-10.0, 2.0));
        assert!((tr[0].xy_m[1] - DVec2::new(-9.964, 2.019)).length() < 1e-12);
        assert_eq!(tr[0].heading_rad.as_deref(), Some(&[1.0, 1.1, 1.2][..]));
        assert!((tr[0].times_s[1] - tr[0].times_s[0] - 0.03).abs() < 1e-6);
        assert!(tr[1].heading_rad.is_none(), "empty facing angle");
        let mid = 0.5 * (tr[0].times_s[0] + tr[0].times_s[1]);
        let h = tr[0].sample(mid).unwrap().heading_rad;
        assert!((h - 1.05).abs() < 1e-3, "facing angle interpolated: {h}");
    }

    #[test]
    fn csv_reader_with_and_without_heading() {
        let d = tempfile::tempdir().unwrap();
        let p = write(
            &d,
            "a.csv",
            "# pedscan tracks\nt_s,id,x_m,y_m\n0.0,7,1,2\n0.5, 7, 2, 2\n",
        );
        let tr = read(&p, TrackFormat::Csv).unwrap();
        assert_eq!(tr[0].id, 7);
        assert_eq!(tr[0].xy_m, vec![DVec2::new(1.0, 2.0), DVec2::new(2.0, 2.0)]);
        assert!(tr[0].heading_rad.is_none());
        let p = write(
            &d,
            "b.csv",
            "t_s,id,x_m,y_m,heading_rad\n0.0,1,0,0,3.0\n1.0,1,1,0,-3.0\n",
        );
        let tr = read(&p, TrackFormat::Csv).unwrap();
        assert_eq!(tr[0].heading_rad.as_deref(), Some(&[3.0, -3.0][..]));
        // Interpolated across ±π along the short arc.
        let h = tr[0].sample(0.5).unwrap().heading_rad;
        assert!((wrap_angle(h - PI)).abs() < 1e-9, "{h}");
    }

    #[test]
    fn bad_input_names_file_and_line() {
        let d = tempfile::tempdir().unwrap();
        let eth_ok = "1 1 0 0 0 0 0 0\n";
        let cases: &[(TrackFormat, &str, usize, &str)] = &[
            (
                TrackFormat::Eth,
                "1 1 0 0 0 0 0 0\n2 1 0 0 0 0 0\n",
                2,
                "expected 8 columns",
            ),
            (
                TrackFormat::Eth,
                "1 1 0 0 0 0 0 0\n\n2 1 0 0 x 0 0 0\n",
                3,
                "column 5: `x` is not a number",
            ),
            (TrackFormat::Eth, "1 1 nan 0 0 0 0 0\n", 1, "not finite"),
            (TrackFormat::Eth, "1 1.5 0 0 0 0 0 0\n", 1, "not an integer"),
            (TrackFormat::Eth4, "0 1 0 0\n10 1 inf 0\n", 2, "not finite"),
            (TrackFormat::Eth4, "0 1 0 0 5\n", 1, "expected 4 columns"),
            (
                TrackFormat::Eth4,
                "0 1 0 0\n10 1 1 0\n0 1 2 0\n",
                3,
                "duplicate timestamp",
            ),
            (
                TrackFormat::Atc,
                "1.0,5,0,0,0,0,0,0\n1.0,5,0,0,0,0,0\n",
                2,
                "expected 8 comma-separated",
            ),
            (
                TrackFormat::Atc,
                "1.0,5,0,0,0,0,0,0\n2.0,5,0,0,0,0,0,NaN\n",
                2,
                "not finite",
            ),
            (
                TrackFormat::Atc,
                "1.0,5,0,0,0,0,0,0\n2.0,5,1e3,0,0,0,0,0\n1.0,5,0,0,0,0,0,0\n",
                3,
                "duplicate",
            ),
            (TrackFormat::Csv, "t,id,x,y\n", 1, "expected the header"),
            (
                TrackFormat::Csv,
                "t_s,id,x_m,y_m\n0,1,0,0\n1,1,0\n",
                3,
                "expected 4 columns",
            ),
            (
                TrackFormat::Csv,
                "t_s,id,x_m,y_m,heading_rad\n0,1,0,0,1\n1,1,0,0,abc\n",
                3,
                "column 5",
            ),
            (TrackFormat::Csv, "t_s,id,x_m,y_m\n0,a,0,0\n", 2, "column 2"),
        ];
        for (k, (f, text, line, needle)) in cases.iter().enumerate() {
            let p = write(&d, &format!("bad{k}.txt"), text);
            expect_err(&p, *f, *line, needle);
        }
        let p = write(&d, "ok.txt", eth_ok);
        assert!(read(&p, TrackFormat::Eth).is_ok());
        // Empty and record-less files.
        for (k, text) in ["", "\n# only a comment\n"].iter().enumerate() {
            let p = write(&d, &format!("empty{k}.txt"), text);
            let e = read(&p, TrackFormat::Eth4).unwrap_err();
            assert!(
                e.is_input() && e.to_string().contains(&p.display().to_string()),
                "{e}"
            );
            assert!(e.to_string().contains("no track record"), "{e}");
        }
        let p = write(&d, "header_only.csv", "t_s,id,x_m,y_m\n");
        assert!(read(&p, TrackFormat::Csv)
            .unwrap_err()
            .to_string()
            .contains("no track record"));
        // Missing file, bad options.
        assert!(read(&d.path().join("missing.txt"), TrackFormat::Eth)
            .unwrap_err()
            .is_input());
        let p = write(&d, "ok2.txt", eth_ok);
        let o = TrackOptions {
            frame_period_s: 0.0,
            ..Default::default()
        };
        assert!(read_tracks(&p, TrackFormat::Eth, &o)
            .unwrap_err()
            .is_input());
    }

    #[test]
    fn duplicate_timestamp_names_both_lines() {
        let d = tempfile::tempdir().unwrap();
        let p = write(
            &d,
            "dup.csv",
            "t_s,id,x_m,y_m\n0,1,0,0\n0.4,1,1,0\n0.4,2,5,5\n0.4,1,1.1,0\n",
        );
        let e = read(&p, TrackFormat::Csv).unwrap_err().to_string();
        assert!(e.starts_with(&format!("{}:5:", p.display())), "{e}");
        assert!(e.contains("id 1") && e.contains("line 3"), "{e}");
    }

    /// A wiggly track with non-uniform times.
    fn wiggly() -> Track {
        let times_s: Vec<f64> = (0..12)
            .map(|i| i as f64 * 0.4 + if i % 3 == 1 { 0.07 } else { 0.0 })
            .collect();
        let xy_m = times_s
            .iter()
            .map(|&t| DVec2::new(1.3 * t + 0.2 * (2.0 * t).sin(), 0.5 * (0.7 * t).cos()))
            .collect();
        Track {
            id: 3,
            times_s,
            xy_m,
            heading_rad: None,
        }
    }

    #[test]
    fn reproduces_samples_and_velocity_is_the_derivative() {
        let d = tempfile::tempdir().unwrap();
        let tr = wiggly();
        let mut text = String::from("t_s,id,x_m,y_m\n");
        for (t, p) in tr.times_s.iter().zip(&tr.xy_m) {
            text += &format!("{t:?},3,{:?},{:?}\n", p.x, p.y);
        }
        let p = write(&d, "w.csv", &text);
        let tr = read(&p, TrackFormat::Csv).unwrap().remove(0);
        assert_eq!(tr.times_s, wiggly().times_s);
        for (t, p) in tr.times_s.iter().zip(&tr.xy_m) {
            let s = tr.sample(*t).unwrap();
            assert!((s.position_m - *p).length() <= 1e-9);
        }
        assert!(tr.sample(tr.times_s[0] - 1e-6).is_none());
        assert!(tr.sample(tr.times_s[11] + 1e-6).is_none());
        assert!(tr.sample(f64::NAN).is_none());
        // Velocity vs central differences of position (cubic: error O(eps^2) within a segment).
        let eps = 1e-5;
        let (t0, t1) = (tr.times_s[0], tr.times_s[11]);
        let mut worst = 0.0f64;
        for k in 1..400 {
            let t = t0 + (t1 - t0) * k as f64 / 400.0;
            // Acceleration jumps at the samples (C1, not C2): difference within one segment.
            if tr.times_s.iter().any(|&ts| (ts - t).abs() < 3.0 * eps) {
                continue;
            }
            let v = tr.sample(t).unwrap().velocity_mps;
            let fd = (tr.sample(t + eps).unwrap().position_m
                - tr.sample(t - eps).unwrap().position_m)
                / (2.0 * eps);
            worst = worst.max((v - fd).length());
        }
        assert!(worst < 1e-6, "velocity vs finite difference: {worst} m/s");
        // C1 at the samples: velocity from both sides agrees.
        for &t in &tr.times_s[1..11] {
            let a = tr.sample(t - 1e-9).unwrap().velocity_mps;
            let b = tr.sample(t + 1e-9).unwrap().velocity_mps;
            assert!((a - b).length() < 1e-6);
        }
    }

    #[test]
    fn straight_constant_speed_gives_constant_velocity_exactly() {
        // Exactly representable samples: 0.5 s apart, 0.75 m along x and -0.25 m along y per step.
        let times_s: Vec<f64> = (0..8).map(|i| i as f64 * 0.5).collect();
        let xy_m: Vec<DVec2> = (0..8)
            .map(|i| DVec2::new(2.0 + 0.75 * i as f64, 1.0 - 0.25 * i as f64))
            .collect();
        let tr = Track {
            id: 0,
            times_s,
            xy_m,
            heading_rad: None,
        };
        let v = DVec2::new(1.5, -0.5);
        for k in 0..=350 {
            let t = k as f64 * 0.01;
            let s = tr.sample(t).unwrap();
            assert_eq!(s.velocity_mps, v, "t = {t}");
            assert!((s.position_m - (DVec2::new(2.0, 1.0) + v * t)).length() < 1e-12);
            assert_eq!(s.heading_rad, v.y.atan2(v.x));
        }
    }

    #[test]
    fn heading_from_motion_is_held_while_standing() {
        // Walk +x, stand still (three equal positions), then walk +y.
        let times_s = vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        let xy_m = [
            (0.0, 0.0),
            (1.0, 0.0),
            (2.0, 0.0),
            (2.0, 0.0),
            (2.0, 0.0),
            (2.0, 1.0),
            (2.0, 2.0),
        ]
        .iter()
        .map(|&(x, y)| DVec2::new(x, y))
        .collect();
        let tr = Track {
            id: 1,
            times_s,
            xy_m,
            heading_rad: None,
        };
        assert!((tr.sample(0.5).unwrap().heading_rad).abs() < 1e-9);
        let standing = tr.sample(3.0).unwrap();
        assert!(standing.velocity_mps.length() < 1e-12);
        // Standing: the last moving direction, +x (the limited tangents do not overshoot).
        let h = standing.heading_rad;
        assert!(h.abs() < 1e-9, "held heading {h}");
        assert_eq!(
            tr.sample(2.5).unwrap().position_m,
            DVec2::new(2.0, 0.0),
            "stays put"
        );
        for k in 0..=20 {
            let t = 2.5 + k as f64 * 0.05;
            let s = tr.sample(t).unwrap();
            if s.velocity_mps.length() < HEADING_HOLD_SPEED_MPS {
                assert!(s.heading_rad.abs() < 1e-9, "t = {t}: {}", s.heading_rad);
            }
        }
        assert!((tr.sample(5.5).unwrap().heading_rad - PI / 2.0).abs() < 1e-9);
        // Never moving: 0; standing first, then walking -y: the first direction of motion.
        let still = Track {
            id: 2,
            times_s: vec![0.0, 1.0],
            xy_m: vec![DVec2::ONE; 2],
            heading_rad: None,
        };
        assert_eq!(still.sample(0.5).unwrap().heading_rad, 0.0);
        let late = Track {
            id: 3,
            times_s: vec![0.0, 1.0, 2.0, 3.0],
            xy_m: vec![
                DVec2::ZERO,
                DVec2::ZERO,
                DVec2::new(0.0, -1.0),
                DVec2::new(0.0, -2.0),
            ],
            heading_rad: None,
        };
        assert!((late.sample(0.0).unwrap().heading_rad + PI / 2.0).abs() < 1e-6);
    }

    #[test]
    fn heading_from_facing_angle_ignores_motion() {
        let tr = Track {
            id: 1,
            times_s: vec![0.0, 1.0, 2.0],
            xy_m: vec![DVec2::ZERO, DVec2::X, DVec2::new(2.0, 0.0)],
            heading_rad: Some(vec![1.0, 1.2, 1.6]),
        };
        assert_eq!(tr.sample(1.0).unwrap().heading_rad, 1.2);
        assert!((tr.sample(1.5).unwrap().heading_rad - 1.4).abs() < 1e-12);
    }

    #[test]
    fn transform_is_applied_to_points_and_headings() {
        let d = tempfile::tempdir().unwrap();
        let p = write(
            &d,
            "t.csv",
            "t_s,id,x_m,y_m,heading_rad\n0,1,1,0,0\n1,1,1,1,0.5\n",
        );
        let o = TrackOptions {
            transform: Transform2 {
                rotation_deg: 90.0,
                translation_m: [10.0, -5.0],
                scale: 2.0,
            },
            ..Default::default()
        };
        let tr = read_tracks(&p, TrackFormat::Csv, &o).unwrap().remove(0);
        assert!(
            (tr.xy_m[0] - DVec2::new(10.0, -3.0)).length() < 1e-12,
            "{:?}",
            tr.xy_m
        );
        assert!(
            (tr.xy_m[1] - DVec2::new(8.0, -3.0)).length() < 1e-12,
            "{:?}",
            tr.xy_m
        );
        let h = tr.heading_rad.unwrap();
        assert!((h[0] - PI / 2.0).abs() < 1e-12 && (h[1] - (PI / 2.0 + 0.5)).abs() < 1e-12);
        let bad = TrackOptions {
            transform: Transform2 {
                scale: -1.0,
                ..Default::default()
            },
            ..Default::default()
        };
        assert!(read_tracks(&p, TrackFormat::Csv, &bad)
            .unwrap_err()
            .is_input());
    }

    #[test]
    fn transforms_positions_and_times_out_of_range_are_refused() {
        let tf = |rotation_deg: f64, t: f64, scale: f64| Transform2 { rotation_deg, translation_m: [t, 0.0], scale };
        assert!(tf(90.0, -1e5, 1e-6).check().is_ok() && tf(-360.0, 0.0, 1e6).check().is_ok());
        for (bad, needle) in [
            (tf(0.0, 0.0, 1e308), "scale 1e308"),
            (tf(0.0, 0.0, 0.0), "scale 0.0"),
            (tf(0.0, 2e5, 1.0), "translation (200000.0, 0.0)"),
            (tf(f64::NAN, 0.0, 1.0), "rotation NaN"),
            (tf(400.0, 0.0, 1.0), "rotation 400.0"),
        ] {
            let m = bad.check().unwrap_err();
            assert!(m.contains(needle), "{m}");
        }
        // Positions that the transform sends beyond the bound, named by their line before
        // anything is sorted.
        let d = tempfile::tempdir().unwrap();
        let p = write(&d, "far.csv", "t_s,id,x_m,y_m\n1,1,0,0\n0,1,150,0\n");
        let o = TrackOptions { transform: tf(0.0, 0.0, 1000.0), ..Default::default() };
        let e = read_tracks(&p, TrackFormat::Csv, &o).unwrap_err();
        assert!(e.is_input() && e.to_string().starts_with(&format!("{}:3:", p.display())), "{e}");
        assert!(e.to_string().contains("150000.0"), "{e}");
        let p = write(&d, "raw.csv", "t_s,id,x_m,y_m\n0,1,0,1e300\n");
        expect_err(&p, TrackFormat::Csv, 2, "1e300");
        // Times: an ETH frame number that the frame period puts at 4e10 s, an ATC time of 1e11 s.
        let p = write(&d, "eth4.txt", "0 1 0 0\n1e12 1 1 0\n");
        expect_err(&p, TrackFormat::Eth4, 2, "time 40000000000.0 s is beyond the supported 1e10 s");
        let p = write(&d, "atc.csv", "1e11,1,0,0,0,0,0,\n");
        expect_err(&p, TrackFormat::Atc, 1, "1e10 s");
    }

    #[test]
    fn a_byte_order_mark_is_skipped() {
        let d = tempfile::tempdir().unwrap();
        let p = write(&d, "bom.csv", "\u{feff}t_s,id,x_m,y_m\n0,1,0,0\n0.4,1,0.5,0\n");
        assert_eq!(read(&p, TrackFormat::Csv).unwrap()[0].xy_m, vec![DVec2::ZERO, DVec2::new(0.5, 0.0)]);
        let p = write(&d, "bom.txt", "\u{feff}10 1 0.5 2.0\n");
        assert_eq!(read(&p, TrackFormat::Eth4).unwrap()[0].times_s, vec![0.4]);
    }

    #[test]
    fn windows_and_drop_short() {
        let a = Track {
            id: 1,
            times_s: vec![0.0, 2.0],
            xy_m: vec![DVec2::ZERO; 2],
            heading_rad: None,
        };
        let b = Track {
            id: 2,
            times_s: vec![5.0],
            xy_m: vec![DVec2::ZERO],
            heading_rad: None,
        };
        assert!(a.windows(2.0) && !a.windows(2.1));
        assert!(b.windows(0.0) && !b.windows(0.1));
        assert_eq!(b.sample(5.0).unwrap().velocity_mps, DVec2::ZERO);
        assert!(b.sample(5.1).is_none());
        let kept = drop_short(vec![a, b], 1.0);
        assert_eq!(kept.len(), 1);
        assert_eq!(kept[0].id, 1);
    }

    #[test]
    fn format_names_are_kebab_case() {
        use clap::ValueEnum;
        assert_eq!(
            serde_json::to_string(&TrackFormat::Eth4).unwrap(),
            "\"eth4\""
        );
        assert_eq!(
            TrackFormat::from_str("atc", false).unwrap(),
            TrackFormat::Atc
        );
    }
}
