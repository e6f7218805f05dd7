//! Stage 1: the beam model (pure math). A sensor is a list of elevations (row 0 = highest),
//! a column count and range limits. Directions are unit vectors in the sensor frame
//! (x forward, y left, z up). Column convention (RangeNet++ / SemanticKITTI):
//! `col = floor(0.5 * (1 - atan2(y, x) / pi) * W)`; a cell's beam is its centre,
//! azimuth `pi * (1 - 2 * (col + 0.5) / W)`.

pub mod presets;

use crate::error::{Error, Result};
use glam::DVec3;
use serde::Deserialize;
use std::path::Path;

/// A spinning multi-beam LiDAR on a regular azimuth grid.
#[derive(Clone, Debug, PartialEq)]
pub struct Sensor {
    /// Preset or file name, recorded in the outputs.
    pub name: String,
    /// Beam elevations in degrees, strictly descending (row 0 = highest).
    pub elevation_deg: Vec<f64>,
    /// Number of columns (azimuth cells) per revolution.
    pub columns: usize,
    /// Revolutions per second (frame rate).
    pub rate_hz: f64,
    /// Returns nearer than this are dropped (no return), metres.
    pub min_range_m: f64,
    /// Returns farther than this are dropped (no return), metres.
    pub max_range_m: f64,
}

/// The TOML form of a custom sensor (`--sensor FILE.toml` or `[sensor]` in a config).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorFile {
    pub name: Option<String>,
    /// Explicit elevation list in degrees; any order (sorted descending on load).
    pub elevation_deg: Vec<f64>,
    pub columns: usize,
    pub rate_hz: Option<f64>,
    pub min_range_m: Option<f64>,
    pub max_range_m: Option<f64>,
}

impl Sensor {
    /// Velodyne HDL-32E as in the paper (Table 1): 32 rows from +10.67 to -30.67 degrees in
    /// 4/3 degree steps rounded to 0.01 deg as in Velodyne's calibration table
    /// (`round(k * 4/3, 2)` for k = 8 down to -23), 1024 columns, 10 Hz, 0.5 to 100 m.
    pub fn hdl32e() -> Sensor {
        let elevation_deg =
            (-23..=8).rev().map(|k: i32| (k as f64 * 4.0 / 3.0 * 100.0).round() / 100.0).collect();
        Sensor {
            name: "hdl32e".into(),
            elevation_deg,
            columns: 1024,
            rate_hz: 10.0,
            min_range_m: 0.5,
            max_range_m: 100.0,
        }
    }

    /// Velodyne VLP-16 (Puck): 16 rows from +15 to -15 degrees in 2 degree steps, 1024
    /// columns, 10 Hz, 0.5 to 100 m.
    pub fn vlp16() -> Sensor {
        let elevation_deg = (0..16).map(|i| 15.0 - (i as f64) * 2.0).collect();
        Sensor {
            name: "vlp16".into(),
            elevation_deg,
            columns: 1024,
            rate_hz: 10.0,
            min_range_m: 0.5,
            max_range_m: 100.0,
        }
    }

    /// The presets' names, as `--sensor` takes them.
    pub const PRESETS: [&'static str; 8] = ["hdl32e", "vlp16", "hdl64e", "vlp32c", "os1-64", "os1-128", "os0-128", "pandar64"];

    /// A preset by name ([`Sensor::PRESETS`], or the HDL-32E's and VLP-16's product names):
    /// the tables and their sources are in [`presets`]; columns at 10 Hz, near the sensor's
    /// firings a turn and never more (HDL-64E ~2,083 -> 2,048; VLP-32C and Pandar64 ~1,800;
    /// Ouster's 1024x10 mode), range limits 0.5 to 100 m as for a sensor file, 120 m for the
    /// HDL-64E and Ouster OS1 (their datasheets' reach at 80 % reflectivity), 200 m for the
    /// VLP-32C and Pandar64.
    pub fn preset(name: &str) -> Option<Sensor> {
        let s = |name: &str, elevation_deg: Vec<f64>, columns: usize, max_range_m: f64| Sensor {
            name: name.into(),
            elevation_deg,
            columns,
            rate_hz: 10.0,
            min_range_m: 0.5,
            max_range_m,
        };
        Some(match name {
            "hdl32e" | "HDL-32E" => Sensor::hdl32e(),
            "vlp16" | "VLP-16" => Sensor::vlp16(),
            "hdl64e" => s("hdl64e", presets::HDL64E_ELEVATION_DEG.to_vec(), 2048, 120.0),
            "vlp32c" => s("vlp32c", presets::VLP32C_ELEVATION_DEG.to_vec(), 1800, 200.0),
            "os1-64" => s("os1-64", presets::OS1_64_ELEVATION_DEG.to_vec(), 1024, 120.0),
            "os1-128" => s("os1-128", presets::OS1_128_ELEVATION_DEG.to_vec(), 1024, 120.0),
            "os0-128" => s("os0-128", presets::os0_128_elevation_deg(), 1024, 100.0),
            "pandar64" => s("pandar64", presets::PANDAR64_ELEVATION_DEG.to_vec(), 1800, 200.0),
            _ => return None,
        })
    }

    /// A preset by name ([`Sensor::preset`]) or a sensor file: TOML, or an Ouster metadata JSON.
    pub fn from_name_or_file(spec: &str) -> Result<Sensor> {
        if let Some(s) = Sensor::preset(spec) {
            return Ok(s);
        }
        let path = spec;
        let p = Path::new(path);
        if !p.exists() {
            return Err(Error::input(
                format!("--sensor {path}"),
                format!(
                    "neither a preset ({}) nor an existing TOML file or Ouster metadata JSON",
                    Sensor::PRESETS.join(", ")
                ),
            ));
        }
        let text = std::fs::read_to_string(p).map_err(|e| Error::input(p.display(), format!("cannot read: {e}")))?;
        if p.extension().is_some_and(|e| e.eq_ignore_ascii_case("json")) {
            return Sensor::from_ouster_json(&text, &p.display().to_string());
        }
        let file: SensorFile =
            toml::from_str(&text).map_err(|e| Error::input(p.display(), e))?;
        let name = file.name.clone().unwrap_or_else(|| {
            p.file_stem().map(|s| s.to_string_lossy().into()).unwrap_or_default()
        });
        Sensor::from_file(file, name, &p.display().to_string())
    }

    /// A sensor from an Ouster sensor metadata JSON (what `ouster-cli` and the sensor's HTTP
    /// API write): the rows from `beam_altitude_angles`, the columns from
    /// `data_format.columns_per_frame` (or `lidar_data_format`), the rate from `lidar_mode`
    /// (`"1024x10"`), the name from `prod_line`; both the flat layout (firmware 2.x) and the
    /// nested one (`beam_intrinsics`, `config_params`). The grid is Ouster's destaggered image:
    /// each row's beams take their column's azimuth (`beam_azimuth_angles` and the lidar
    /// origin's offset are not modelled). Range limits 0.5 to 100 m, as for a TOML sensor.
    pub fn from_ouster_json(text: &str, input: &str) -> Result<Sensor> {
        let bad = |m: String| Error::input(input, m);
        let v: serde_json::Value = serde_json::from_str(text).map_err(|e| bad(format!("not JSON: {e}")))?;
        let find = |path: &[&[&str]]| path.iter().find_map(|p| p.iter().try_fold(&v, |x, k| x.get(*k)));
        let angles = find(&[&["beam_altitude_angles"], &["beam_intrinsics", "beam_altitude_angles"]])
            .and_then(|a| a.as_array())
            .ok_or_else(|| bad("no beam_altitude_angles: not an Ouster sensor metadata file".into()))?;
        let elevation_deg = angles
            .iter()
            .enumerate()
            .map(|(k, a)| a.as_f64().ok_or_else(|| bad(format!("beam_altitude_angles[{k}] is not a number"))))
            .collect::<Result<Vec<f64>>>()?;
        let mode = find(&[&["lidar_mode"], &["config_params", "lidar_mode"]]).and_then(|m| m.as_str());
        let from_mode = |i: usize| mode.and_then(|m| m.split('x').nth(i)).and_then(|x| x.parse::<f64>().ok());
        let columns = find(&[&["data_format", "columns_per_frame"], &["lidar_data_format", "columns_per_frame"]])
            .and_then(|c| c.as_u64())
            .map(|c| c as f64)
            .or_else(|| from_mode(0))
            .ok_or_else(|| bad("no data_format.columns_per_frame and no lidar_mode: the columns are unknown".into()))?;
        if !(columns >= 1.0 && columns <= 65536.0 && columns.fract() == 0.0) {
            return Err(bad(format!("columns_per_frame = {columns} is not a column count")));
        }
        let name = find(&[&["prod_line"], &["sensor_info", "prod_line"]]).and_then(|n| n.as_str()).unwrap_or("ouster");
        let file = SensorFile {
            name: Some(name.into()),
            elevation_deg,
            columns: columns as usize,
            rate_hz: from_mode(1),
            min_range_m: None,
            max_range_m: None,
        };
        Sensor::from_file(file, name.to_ascii_lowercase(), input)
    }

    /// Builds and checks a sensor from its TOML form; `input` names the source in errors.
    pub fn from_file(file: SensorFile, name: String, input: &str) -> Result<Sensor> {
        // Every number is checked before the elevations are sorted: a NaN has no place in an
        // order.
        check_elevations(&file.elevation_deg, input)?;
        let mut elevation_deg = file.elevation_deg;
        elevation_deg.sort_by(|a, b| b.total_cmp(a));
        let s = Sensor {
            name,
            elevation_deg,
            columns: file.columns,
            rate_hz: file.rate_hz.unwrap_or(10.0),
            min_range_m: file.min_range_m.unwrap_or(0.5),
            max_range_m: file.max_range_m.unwrap_or(100.0),
        };
        s.validate(input)?;
        Ok(s)
    }

    /// Rejects impossible sensors with a message naming `input`.
    pub fn validate(&self, input: &str) -> Result<()> {
        let bad = |m: String| Err(Error::input(input, m));
        check_elevations(&self.elevation_deg, input)?;
        for w in self.elevation_deg.windows(2) {
            if w[0] == w[1] {
                return bad(format!("elevation {} deg appears twice", w[0]));
            }
            if w[0] < w[1] {
                return bad(format!("elevations {} and {} deg are not in descending order", w[0], w[1]));
            }
        }
        if self.columns < 8 || self.columns > 65536 {
            return bad(format!("columns = {} must be in 8..=65536", self.columns));
        }
        // The name is written into every output (HDF5 strings, XML, bags).
        if self.name.is_empty() || self.name.len() > 256 || self.name.chars().any(char::is_control) {
            return bad(format!("name {:?} must be 1-256 bytes without control characters", self.name.chars().take(64).collect::<String>()));
        }
        // At least a sweep every 10 s: a frame's interval bounds the people's planning (at
        // 1e-12 Hz one frame's walk never ended).
        if !(self.rate_hz.is_finite() && (0.1..=1000.0).contains(&self.rate_hz)) {
            return bad(format!("rate_hz = {} must be in [0.1, 1000]", self.rate_hz));
        }
        if !(self.min_range_m.is_finite() && self.min_range_m >= 0.0) {
            return bad(format!("min_range_m = {} must be >= 0", self.min_range_m));
        }
        if !(self.max_range_m.is_finite() && self.max_range_m > self.min_range_m) {
            return bad(format!(
                "max_range_m = {} must be finite and greater than min_range_m = {}",
                self.max_range_m, self.min_range_m
            ));
        }
        Ok(())
    }

    /// Number of rows (beams per column).
    pub fn rows(&self) -> usize {
        self.elevation_deg.len()
    }

    /// Azimuth of the centre of column `col`, radians, in (-pi, pi].
    pub fn azimuth_rad(&self, col: usize) -> f64 {
        std::f64::consts::PI * (1.0 - 2.0 * (col as f64 + 0.5) / self.columns as f64)
    }

    /// Unit beam direction of cell (`row`, `col`) in the sensor frame.
    pub fn beam_dir(&self, row: usize, col: usize) -> DVec3 {
        let az = self.azimuth_rad(col);
        let el = self.elevation_deg[row].to_radians();
        DVec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin())
    }

    /// All beam directions, row-major (`row * columns + col`).
    pub fn beam_dirs(&self) -> Vec<DVec3> {
        let mut v = Vec::with_capacity(self.rows() * self.columns);
        for r in 0..self.rows() {
            for c in 0..self.columns {
                v.push(self.beam_dir(r, c));
            }
        }
        v
    }

    /// Could any beam meet a sphere (sensor frame)? Every azimuth is swept, so only the
    /// sphere's cone of elevations is held against the band of the rows (with 1e-9 rad for
    /// rounding), and the range limit; conservative, exact up to that margin.
    pub fn may_see_sphere(&self, centre: DVec3, radius: f64) -> bool {
        let dist = centre.length();
        if dist - radius > self.max_range_m {
            return false;
        }
        if dist <= radius {
            return true;
        }
        let half = (radius / dist).asin() + 1e-9;
        let el = centre.z.atan2(centre.x.hypot(centre.y));
        let top = self.elevation_deg.iter().cloned().fold(f64::MIN, f64::max).to_radians();
        let bottom = self.elevation_deg.iter().cloned().fold(f64::MAX, f64::min).to_radians();
        el - half <= top && el + half >= bottom
    }

    /// Column of a sensor-frame direction (x, y): `floor(turn_of(x, y) * W)`, wrapped into `0..W`.
    pub fn column_of(&self, x: f64, y: f64) -> usize {
        let w = self.columns as f64;
        let c = (turn_of(x, y) * w).floor();
        (c as i64).rem_euclid(self.columns as i64) as usize
    }

    /// Highest absolute elevation of any beam, degrees.
    pub fn max_abs_elevation_deg(&self) -> f64 {
        self.elevation_deg.iter().fold(0.0f64, |m, e| m.max(e.abs()))
    }
}

/// Where a sensor-frame direction (x, y) lies in a turn: `0.5 * (1 - atan2(y, x) / pi)`, 0 straight
/// behind, growing clockwise seen from above (0.5 straight ahead), in `[0, 1]` (1 only straight
/// behind with y = -0). Every column coordinate of the grid is this times the columns.
#[inline]
pub fn turn_of(x: f64, y: f64) -> f64 {
    0.5 * (1.0 - y.atan2(x) / std::f64::consts::PI)
}

/// `atan2(y, x)` in f32 from the Abramowitz-Stegun 4.4.49-style minimax polynomial on
/// [0, 1] (max error 1e-5 rad before rounding; 1e-5 rad of azimuth is 0.2 microseconds of a
/// 10 Hz sweep); result in [-pi, pi], on the same side of the cut as `atan2` but for y = -0,
/// taken as +0 (straight behind is +pi).
#[inline(always)]
pub fn atan2_fast(y: f32, x: f32) -> f32 {
    let ax = x.abs();
    let ay = y.abs();
    let (num, den) = if ay > ax { (ax, ay) } else { (ay, ax) };
    let a = if den > 0.0 { num / den } else { 0.0 };
    let s = a * a;
    let mut r = ((((0.020_835_1 * s - 0.085_133) * s + 0.180_141) * s - 0.330_299_5) * s + 0.999_866) * a;
    if ay > ax {
        r = 0.5 * std::f32::consts::PI - r;
    }
    if x < 0.0 {
        r = std::f32::consts::PI - r;
    }
    if y < 0.0 {
        -r
    } else {
        r
    }
}

/// Most rows a sensor may have.
pub const MAX_ROWS: usize = 4096;

/// Checks a list of elevations in any order: not empty, at most [`MAX_ROWS`], every one finite
/// and inside +-[`MAX_ELEVATION_DEG`]; `input` names the source in errors.
fn check_elevations(elevation_deg: &[f64], input: &str) -> Result<()> {
    let bad = |m: String| Err(Error::input(input, m));
    if elevation_deg.is_empty() {
        return bad("sensor has no beams (elevation_deg is empty)".into());
    }
    if elevation_deg.len() > MAX_ROWS {
        return bad(format!("{} rows is more than the supported {MAX_ROWS}", elevation_deg.len()));
    }
    for (k, e) in elevation_deg.iter().enumerate() {
        if !e.is_finite() {
            return bad(format!("elevation_deg[{k}] = {e} is not a finite number"));
        }
        if e.abs() > MAX_ELEVATION_DEG {
            return bad(format!(
                "elevation_deg[{k}] = {e} deg is outside +-{MAX_ELEVATION_DEG} deg (a beam at the pole has no azimuth)"
            ));
        }
    }
    Ok(())
}

/// Steepest beam any sensor may have, degrees: the ray caster and the beam-grid raster take
/// any elevation short of the poles, where a column has no azimuth.
pub const MAX_ELEVATION_DEG: f64 = 89.0;

/// Steepest beam the raster backend's cube faces cover: the 4 side faces of a cube see up to
/// atan(1 / sqrt 2) above and below the horizon at their corners.
pub const CUBE_MAX_ELEVATION_DEG: f64 = 35.26;

#[cfg(test)]
mod tests {
    use super::*;

    /// On the axes and the diagonals `atan2_fast` is `atan2` to within its error, without
    /// wrapping: straight behind (y = 0, x < 0) is +pi, as `atan2` has it for y = +0; unlike
    /// `atan2` it takes y = -0 as +0.
    #[test]
    fn atan2_fast_takes_atan2s_side_of_the_cut() {
        for (y, x) in [(0.0f32, 1.0f32), (1.0, 0.0), (0.0, -1.0), (-1.0, 0.0), (1.0, 1.0), (-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (0.0, 0.0)] {
            let (fast, exact) = (atan2_fast(y, x), y.atan2(x));
            assert!((fast - exact).abs() < 1.2e-5, "atan2({y}, {x}) = {exact}, fast {fast}");
        }
        assert_eq!(atan2_fast(-0.0, -1.0), atan2_fast(0.0, -1.0));
    }

    #[test]
    fn every_preset_is_a_valid_sensor_with_its_sources_rows() {
        // (preset, rows, top, bottom, columns) as the sources give them (`presets`).
        let want = [
            ("hdl32e", 32, 10.67, -30.67, 1024),
            ("vlp16", 16, 15.0, -15.0, 1024),
            ("hdl64e", 64, 1.96, -24.555, 2048),
            ("vlp32c", 32, 15.0, -25.0, 1800),
            ("os1-64", 64, 21.02, -21.41, 1024),
            ("os1-128", 128, 21.476, -21.476, 1024),
            ("os0-128", 128, 45.0, -45.0, 1024),
            ("pandar64", 64, 14.882, -24.897, 1800),
        ];
        assert_eq!(want.map(|w| w.0), Sensor::PRESETS);
        for (name, rows, top, bottom, columns) in want {
            let s = Sensor::from_name_or_file(name).unwrap();
            s.validate(name).unwrap();
            assert_eq!((s.name.as_str(), s.rows(), s.columns), (name, rows, columns), "{name}");
            assert!((s.elevation_deg[0] - top).abs() < 1e-9 && (s.elevation_deg[rows - 1] - bottom).abs() < 1e-9, "{name}");
        }
        // The VLP-32C's fine band: 1/3 deg from +1.667 down to -4 (the manual's table).
        let v = Sensor::preset("vlp32c").unwrap().elevation_deg;
        let fine: Vec<f64> = v.windows(2).filter(|w| w[0] <= 1.7 && w[1] >= -4.01).map(|w| w[0] - w[1]).collect();
        assert_eq!(fine.len(), 17);
        assert!(fine.iter().all(|g| (g - 1.0 / 3.0).abs() < 0.002), "{fine:?}");
        let e = Sensor::from_name_or_file("os2-128").unwrap_err().to_string();
        assert!(e.contains("neither a preset (hdl32e, vlp16, hdl64e, vlp32c, os1-64, os1-128, os0-128, pandar64)"), "{e}");
    }

    #[test]
    fn an_ouster_metadata_file_gives_its_grid() {
        // Firmware 2.x's flat layout: 4 beams given out of order, 1024 x 10.
        let flat = r#"{"prod_line": "OS-1-128", "lidar_mode": "1024x10", "beam_altitude_angles": [20.95, -21.3, 0.4, 6.1],
                       "beam_azimuth_angles": [4.2, 1.4, -1.4, -4.2], "data_format": {"columns_per_frame": 1024, "pixels_per_column": 4}}"#;
        let s = Sensor::from_ouster_json(flat, "os.json").unwrap();
        assert_eq!((s.name.as_str(), s.columns, s.rate_hz), ("os-1-128", 1024, 10.0));
        assert_eq!(s.elevation_deg, vec![20.95, 6.1, 0.4, -21.3]);
        // The nested layout (newer firmware), 2048 x 10 from the mode alone.
        let nested = r#"{"sensor_info": {"prod_line": "OS-0-128"}, "config_params": {"lidar_mode": "2048x10"},
                         "beam_intrinsics": {"beam_altitude_angles": [30.0, 10.0, -10.0, -30.0]}}"#;
        let s = Sensor::from_ouster_json(nested, "os0.json").unwrap();
        assert_eq!((s.name.as_str(), s.columns, s.rows()), ("os-0-128", 2048, 4));
        // An OS0's +-45 deg is a sensor (the cube faces refuse it, the other views take it);
        // a beam at the pole is not.
        let wide = r#"{"lidar_mode": "1024x10", "beam_altitude_angles": [45.0, 0.0, -45.0]}"#;
        assert_eq!(Sensor::from_ouster_json(wide, "os0.json").unwrap().max_abs_elevation_deg(), 45.0);
        let pole = r#"{"lidar_mode": "1024x10", "beam_altitude_angles": [89.5, 0.0]}"#;
        assert!(Sensor::from_ouster_json(pole, "os0.json").unwrap_err().to_string().contains("outside +-89 deg"));
        for (text, needle) in [
            ("{", "os.json: not JSON"),
            (r#"{"lidar_mode": "1024x10"}"#, "no beam_altitude_angles"),
            (r#"{"beam_altitude_angles": [1.0, 0.0]}"#, "the columns are unknown"),
            (r#"{"lidar_mode": "1024x10", "beam_altitude_angles": [1.0, "x"]}"#, "beam_altitude_angles[1] is not a number"),
            (r#"{"lidar_mode": "0.5x10", "beam_altitude_angles": [1.0, 0.0]}"#, "is not a column count"),
        ] {
            let e = Sensor::from_ouster_json(text, "os.json").unwrap_err().to_string();
            assert!(e.contains(needle), "{text}: {e}");
        }
    }

    #[test]
    fn may_see_sphere_holds_every_sphere_a_beam_meets_and_drops_those_off_the_band() {
        let s = Sensor::hdl32e();
        let dirs = s.beam_dirs();
        // Spheres on a spiral of directions and distances: whenever a beam passes within the
        // radius of the centre (in front of the sensor), the sphere must be seen.
        let (mut seen_by_beam, mut culled) = (0, 0);
        for k in 0..4000 {
            let t = k as f64 * 0.618_034;
            let el = (-60.0 + 120.0 * (t.fract())).to_radians();
            let az = t * 2.399_963;
            let dist = 0.5 + 150.0 * ((k as f64 * 0.371).fract());
            let r = 0.05 + 1.5 * ((k as f64 * 0.113).fract());
            let c = dist * DVec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            let met = dirs.iter().any(|d| {
                let along = c.dot(*d);
                along > 0.0 && along - r <= s.max_range_m && (c - along * *d).length() <= r
            });
            let may = s.may_see_sphere(c, r);
            assert!(!met || may, "sphere {k} at {c:?} r {r} is met by a beam but culled");
            seen_by_beam += met as usize;
            culled += (!may) as usize;
        }
        assert!(seen_by_beam > 500 && culled > 500, "the test must see both cases: {seen_by_beam} met, {culled} culled");
        // Far beyond the range, and high above the band: not seen; containing the sensor: seen.
        assert!(!s.may_see_sphere(DVec3::new(200.0, 0.0, 0.0), 1.0));
        assert!(!s.may_see_sphere(DVec3::new(1.0, 0.0, 5.0), 0.5));
        assert!(s.may_see_sphere(DVec3::new(0.1, 0.0, 0.3), 0.5));
    }

    #[test]
    fn hdl32e_table() {
        let s = Sensor::hdl32e();
        assert_eq!(s.rows(), 32);
        assert!((s.elevation_deg[0] - 10.67).abs() < 1e-12);
        assert!((s.elevation_deg[31] - (-30.67)).abs() < 1e-9);
        assert!((s.elevation_deg[1] - 9.33).abs() < 1e-12);
        assert_eq!(s.elevation_deg[8], 0.0);
        for w in s.elevation_deg.windows(2) {
            assert!((w[0] - w[1] - 4.0 / 3.0).abs() < 0.011);
        }
        s.validate("hdl32e").unwrap();
    }

    #[test]
    fn column_zero_looks_backwards_and_columns_go_clockwise() {
        let s = Sensor::hdl32e();
        // Column 0's centre is just below +180 deg azimuth: it looks backwards.
        let az0 = s.azimuth_rad(0).to_degrees();
        assert!((az0 - (180.0 - 180.0 / 1024.0)).abs() < 1e-9, "{az0}");
        // Azimuth decreases with the column: clockwise seen from above (z up).
        assert!(s.azimuth_rad(1) < s.azimuth_rad(0));
        // Forward (+x) is the middle column boundary; left (+y) is a quarter in.
        assert_eq!(s.column_of(1.0, 1e-9), 511);
        assert_eq!(s.column_of(1.0, -1e-9), 512);
        assert_eq!(s.column_of(0.0, 1.0), 256);
        assert_eq!(s.column_of(-1.0, -1e-12), 1023);
    }

    #[test]
    fn column_of_inverts_beam_centre() {
        for s in [Sensor::hdl32e(), Sensor::vlp16()] {
            for c in 0..s.columns {
                let d = s.beam_dir(3, c);
                assert_eq!(s.column_of(d.x, d.y), c, "column {c}");
            }
        }
    }

    #[test]
    fn beam_dirs_are_unit_and_have_their_elevation() {
        let s = Sensor::hdl32e();
        for r in 0..s.rows() {
            let d = s.beam_dir(r, 100);
            assert!((d.length() - 1.0).abs() < 1e-12);
            assert!((d.z.asin().to_degrees() - s.elevation_deg[r]).abs() < 1e-9);
        }
    }

    #[test]
    fn impossible_sensors_are_rejected_with_the_input_named() {
        let bad = SensorFile {
            name: None,
            elevation_deg: vec![10.0, 89.5],
            columns: 1024,
            rate_hz: None,
            min_range_m: None,
            max_range_m: None,
        };
        let e = Sensor::from_file(bad, "x".into(), "my.toml").unwrap_err();
        assert!(e.is_input());
        assert!(e.to_string().contains("my.toml: elevation_deg[1] = 89.5 deg is outside +-89 deg"), "{e}");
        let bad_cols = SensorFile {
            name: None,
            elevation_deg: vec![1.0],
            columns: 0,
            rate_hz: Some(10.0),
            min_range_m: None,
            max_range_m: None,
        };
        assert!(Sensor::from_file(bad_cols, "x".into(), "c.toml").is_err());
    }

    /// A name the outputs cannot hold (a NUL byte broke the HDF5 string after the frames were
    /// made) and a huge one are refused as the sensor file's error.
    #[test]
    fn names_the_outputs_cannot_hold_are_refused() {
        for name in ["a\0b", "line\nbreak", &"x".repeat(300)] {
            let f = SensorFile { name: Some(name.into()), elevation_deg: vec![2.0, -2.0, -6.0, -10.0], columns: 1024, rate_hz: None, min_range_m: None, max_range_m: None };
            let e = Sensor::from_file(f, name.into(), "named.toml").unwrap_err();
            assert!(e.is_input() && e.to_string().contains("named.toml") && e.to_string().contains("name"), "{name:?}: {e}");
        }
    }

    /// A NaN among unsorted elevations used to reach the sort (which panicked: "does not
    /// correctly implement a total order"); every number is now checked first.
    #[test]
    fn non_finite_numbers_are_rejected_before_sorting() {
        // 32 unsorted elevations with `elevation` at index 17, and the other numbers.
        let file = |elevation: f64, rate_hz: f64, min_range_m: f64, max_range_m: f64| {
            let mut elevation_deg: Vec<f64> = (0..32).map(|k| ((k * 7) % 32) as f64 - 20.0).collect();
            elevation_deg[17] = elevation;
            let (rate_hz, min_range_m, max_range_m) = (Some(rate_hz), Some(min_range_m), Some(max_range_m));
            SensorFile { name: None, elevation_deg, columns: 1024, rate_hz, min_range_m, max_range_m }
        };
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300] {
            let e = Sensor::from_file(file(bad, 10.0, 0.5, 100.0), "x".into(), "nan.toml").unwrap_err();
            assert!(e.is_input());
            assert!(e.to_string().contains("nan.toml") && e.to_string().contains("elevation_deg[17]"), "{e}");
        }
        for (f, field) in [
            (file(3.5, f64::NAN, 0.5, 100.0), "rate_hz"),
            (file(3.5, 1e-12, 0.5, 100.0), "rate_hz"),
            (file(3.5, 0.05, 0.5, 100.0), "rate_hz"),
            (file(3.5, 10.0, f64::NAN, 100.0), "min_range_m"),
            (file(3.5, 10.0, 0.5, f64::INFINITY), "max_range_m"),
        ] {
            let e = Sensor::from_file(f, "x".into(), "n.toml").unwrap_err();
            assert!(e.to_string().contains("n.toml") && e.to_string().contains(field), "{e}");
        }
        let s = Sensor::from_file(file(3.5, 10.0, 0.5, 100.0), "x".into(), "ok.toml").unwrap();
        assert!(s.elevation_deg.windows(2).all(|w| w[0] > w[1]));
        let mut ascending = Sensor::vlp16();
        ascending.elevation_deg.reverse();
        assert!(ascending.validate("up").unwrap_err().to_string().contains("descending"));
    }
}
