//! Raster backend, views. The sensor's beams are covered either by the 4 side faces of a
//! cube (face k looks along azimuth k * 90 deg: +x, +y, -x, -y), each with an off-centre
//! frustum that covers only the sensor's elevation band, or by one cylindrical panorama
//! ([`Panorama`], `render.projection = "cylinder"`). This module owns the exact texel <->
//! direction mappings that the GPU (through `clip_from_sensor` / `Panorama::shader_map`) and
//! the resampler share.
//!
//! Face camera: `xc = p.right`, `yc = p.up`, `zc = p.forward`; tangent-plane coordinates
//! `sx = xc / zc` in [-1, 1], `sy = yc / zc` in [bottom, top]. Texel column
//! `u = floor((sx + 1) / 2 * width)`, row `v = floor((top - sy) / (top - bottom) * height)`
//! (row 0 at the top). Depth is reversed-Z with an infinite far plane: `z_ndc = NEAR_M / zc`.

use crate::sensor::Sensor;
use glam::{DMat4, DVec3, DVec4, Mat4, Vec3};

/// Near plane of every face, metres. Reversed-Z float depth keeps precision far beyond it.
pub const NEAR_M: f64 = 0.01;

/// Extra texels beyond the outermost beam on each side of the band, so a 3x3 neighbourhood
/// around any beam's texel stays inside the image.
pub const BAND_MARGIN_TEXELS: f64 = 2.0;

/// One cube side face with its band frustum and raster size.
#[derive(Clone, Debug, PartialEq)]
pub struct Face {
    /// 0..4; the face looks along azimuth `index * 90` degrees.
    pub index: usize,
    pub forward: DVec3,
    pub right: DVec3,
    pub up: DVec3,
    /// Tangent-plane bounds of the band (sy at the top and bottom image edges).
    pub top: f64,
    pub bottom: f64,
    pub width: u32,
    pub height: u32,
}

impl Face {
    /// Column-major clip matrix for `gl_Position = clip_from_sensor * vec4(p_sensor, 1)`.
    /// Gives x_ndc = sx, y_ndc = -1 + 2 (top - sy) / (top - bottom) (Vulkan y down),
    /// z_ndc = NEAR_M / zc (reversed-Z: compare GREATER, clear 0), w = zc.
    pub fn clip_from_sensor(&self) -> Mat4 {
        let (f, r, u) = (self.forward, self.right, self.up);
        let k = 2.0 / (self.top - self.bottom);
        let row1 = k * (self.top * f - u) - f;
        // DMat4::from_cols takes columns; build from rows via transpose.
        let rows = DMat4::from_cols(
            DVec4::new(r.x, r.y, r.z, 0.0),
            DVec4::new(row1.x, row1.y, row1.z, 0.0),
            DVec4::new(0.0, 0.0, 0.0, NEAR_M),
            DVec4::new(f.x, f.y, f.z, 0.0),
        );
        rows.transpose().as_mat4()
    }

    /// Tangent-plane coordinates (sx, sy) of a sensor-frame direction, or None if it does not
    /// point into the face's half-space.
    pub fn tangent(&self, d: DVec3) -> Option<(f64, f64)> {
        let zc = d.dot(self.forward);
        if zc <= 0.0 {
            return None;
        }
        Some((d.dot(self.right) / zc, d.dot(self.up) / zc))
    }

    /// Continuous pixel coordinates (px, py) of a direction (texel centres at +0.5).
    pub fn pixel(&self, d: DVec3) -> Option<(f64, f64)> {
        let (sx, sy) = self.tangent(d)?;
        let px = (sx + 1.0) * 0.5 * self.width as f64;
        let py = (self.top - sy) / (self.top - self.bottom) * self.height as f64;
        Some((px, py))
    }

    /// Texel (u, v) of a direction, nearest by integer index with clamp-to-edge.
    pub fn texel(&self, d: DVec3) -> Option<(u32, u32)> {
        let (px, py) = self.pixel(d)?;
        let u = (px.floor().max(0.0) as u32).min(self.width - 1);
        let v = (py.floor().max(0.0) as u32).min(self.height - 1);
        Some((u, v))
    }

    /// Sensor-frame direction (not normalised) through the centre of texel (u, v).
    pub fn texel_dir(&self, u: u32, v: u32) -> DVec3 {
        let sx = (u as f64 + 0.5) / self.width as f64 * 2.0 - 1.0;
        let sy = self.top - (v as f64 + 0.5) / self.height as f64 * (self.top - self.bottom);
        self.forward + sx * self.right + sy * self.up
    }

    /// Could a sphere (sensor frame) cover any texel of this face? Conservative test against
    /// the four side planes of the frustum and the near plane.
    pub fn sees_sphere(&self, centre: Vec3, radius: f32) -> bool {
        let c = centre.as_dvec3();
        let r = radius as f64;
        let f = self.forward;
        if c.dot(f) < NEAR_M - r {
            return false;
        }
        // Inward normals of the planes sx = -1, sx = 1, sy = top, sy = bottom.
        let planes = [f + self.right, f - self.right, self.top * f - self.up, self.up - self.bottom * f];
        planes.iter().all(|n| c.dot(*n) >= -r * n.length())
    }
}

/// The set of faces that covers a sensor, at a given oversampling.
#[derive(Clone, Debug, PartialEq)]
pub struct CubeFaces {
    pub faces: Vec<Face>,
    /// Texels per beam spacing at the face centre (horizontally); 1.0 = as fine as the beams.
    pub oversample: f64,
}

impl CubeFaces {
    /// The 4 side faces with band frusta for `sensor`. Width: `oversample` texels per beam
    /// spacing at the face centre; height: square texels in tangent space.
    pub fn new(sensor: &Sensor, oversample: f64) -> CubeFaces {
        let el_max = sensor.elevation_deg.iter().cloned().fold(f64::MIN, f64::max).to_radians();
        let el_min = sensor.elevation_deg.iter().cloned().fold(f64::MAX, f64::min).to_radians();
        let s2 = std::f64::consts::SQRT_2;
        // Highest sy: a positive elevation peaks at the face edge (|az| = 45 deg).
        let top = if el_max > 0.0 { el_max.tan() * s2 } else { el_max.tan() };
        let bottom = if el_min < 0.0 { el_min.tan() * s2 } else { el_min.tan() };
        let beam_spacing = std::f64::consts::TAU / sensor.columns as f64;
        let width = ((oversample * 2.0 / beam_spacing).ceil() as u32).clamp(16, 8192);
        let texel = 2.0 / width as f64;
        let top = top + BAND_MARGIN_TEXELS * texel;
        let bottom = bottom - BAND_MARGIN_TEXELS * texel;
        let height = (((top - bottom) / texel).ceil() as u32).clamp(4, 8192);
        let faces = (0..4)
            .map(|index| {
                let yaw = index as f64 * std::f64::consts::FRAC_PI_2;
                let forward = DVec3::new(yaw.cos(), yaw.sin(), 0.0).round_small();
                let right = DVec3::new(yaw.sin(), -yaw.cos(), 0.0).round_small();
                Face { index, forward, right, up: DVec3::Z, top, bottom, width, height }
            })
            .collect();
        CubeFaces { faces, oversample }
    }

    /// The face a direction belongs to: the one whose forward axis is nearest in azimuth.
    /// Ties (exactly on a seam) go to the face with the higher index (mod 4), deterministically.
    pub fn face_of(&self, d: DVec3) -> usize {
        let az = d.y.atan2(d.x); // (-pi, pi]
        let k = (az / std::f64::consts::FRAC_PI_2 + 0.5).floor() as i64;
        k.rem_euclid(4) as usize
    }
}

/// Steepest beam a panorama takes, degrees: its straight edges stay within
/// [`PANORAMA_EDGE_TOLERANCE_TEXELS`] of the true projected curves up to here (and 5 degrees
/// beyond, for the band's margin; `panorama_straight_edges_stay_within_the_tolerance`).
pub const PANORAMA_MAX_ELEVATION_DEG: f64 = 45.0;

/// Widest panorama image, texels (lavapipe's and most GPUs' `maxImageDimension2D`).
pub const MAX_PANORAMA_TEXELS: u32 = 16384;

/// Largest deviation, in (horizontal) texels, that the straight edges the GPU draws between
/// projected vertices may have from the true projected curve; triangles whose panorama extent
/// could exceed it are split on the CPU (`Panorama::max_extent_rad`).
pub const PANORAMA_EDGE_TOLERANCE_TEXELS: f64 = 0.25;

/// Widest or tallest piece of a triangle the panorama draws from the CPU list, radians (7.2 deg).
pub const MAX_PIECE_RAD: f64 = 0.125;

/// One cylindrical (equirectangular) panorama around the sensor: 360 deg of azimuth across,
/// the sensor's elevation band (plus `BAND_MARGIN_TEXELS` rows above and below) down.
///
/// Horizontal: `phi = az0 - azimuth` (clockwise from the left edge, wrapped into [0, 2 pi)),
/// `px = phi * width / (2 pi)`, texel column `u = floor(px)`. `width` is `columns x k`
/// (k = the rounded oversample, at least 1) and `az0` is `pi` plus half a texel when k is
/// even, so every beam azimuth (`Sensor::azimuth_rad`) lies on a texel centre: column c's
/// beams are in texel column `c k + (k - 1) / 2` (k odd) or `c k + k / 2` (k even).
///
/// Vertical: uniform in elevation, `py = (el_top - el) / el_step`, row `v = floor(py)` (row 0
/// at the top). `el_step` is the sensor's elevation gap / k: for a table that is uniform to
/// within 5 % of its gap (HDL-32E, VLP-16) the mean gap, so every beam lies within 5 % of a
/// gap from a texel-row centre (HDL-32E: 0.005 deg); otherwise the smallest gap.
///
/// Depth is reversed-Z in range: `z_ndc = NEAR_M / range`, `w = range` (so interpolation
/// across a triangle is perspective-correct to second order in its angular size).
#[derive(Clone, Debug, PartialEq)]
pub struct Panorama {
    pub width: u32,
    pub height: u32,
    /// Texels per sensor column (k).
    pub texels_per_column: u32,
    /// Azimuth of the left image edge, radians (`phi = az0 - azimuth`).
    pub az0: f64,
    /// Elevation of the top image edge, radians.
    pub el_top: f64,
    /// Elevation per texel row, radians.
    pub el_step: f64,
    /// A triangle whose extent in phi and elevation is within this needs no check: `2
    /// sqrt(tolerance)`, as an edge whose extents are at most `e` deviates from its chord by at
    /// most `e^2 / 4` radians at elevations within +-45 deg (worst case a diagonal edge;
    /// `panorama_straight_edges_stay_within_the_tolerance`). The direct draws use this bound.
    pub max_extent_rad: f64,
    /// Pieces of the CPU list are at most this wide or tall (radians), however straight their
    /// edges: the raw range is interpolated across a piece, exactly only to second order.
    pub max_piece_rad: f64,
    pub oversample: f64,
}

impl Panorama {
    pub fn new(sensor: &Sensor, oversample: f64) -> Panorama {
        let tau = std::f64::consts::TAU;
        let k = (oversample.round().max(1.0) as u32).min((MAX_PANORAMA_TEXELS / sensor.columns as u32).max(1));
        let width = (sensor.columns as u32 * k).min(MAX_PANORAMA_TEXELS);
        // Column 0's beam centre at px = 0.5 (mod 1): shift = 0.5 - frac(0.5 width / columns).
        let centre = 0.5 * width as f64 / sensor.columns as f64;
        let shift = 0.5 - (centre - centre.floor());
        let az0 = std::f64::consts::PI + shift * tau / width as f64;

        let el: Vec<f64> = sensor.elevation_deg.iter().map(|e| e.to_radians()).collect();
        let el_max = el.iter().cloned().fold(f64::MIN, f64::max);
        let el_min = el.iter().cloned().fold(f64::MAX, f64::min);
        let rows = el.len();
        let gap = if rows < 2 {
            tau / sensor.columns as f64
        } else {
            let mean = (el_max - el_min) / (rows - 1) as f64;
            let min_gap = el.windows(2).map(|w| (w[0] - w[1]).abs()).fold(f64::MAX, f64::min);
            let uniform = el.iter().enumerate().all(|(r, e)| (e - (el_max - r as f64 * mean)).abs() <= 0.05 * mean);
            if uniform {
                mean
            } else {
                min_gap
            }
        };
        let el_step = gap / k as f64;
        let margin = BAND_MARGIN_TEXELS + 0.5;
        let el_top = el_max + margin * el_step;
        let height = ((((el_max - el_min) / el_step).round() as u32) + 1 + 2 * BAND_MARGIN_TEXELS as u32)
            .max((((el_max - el_min) / el_step + 2.0 * margin).ceil()) as u32)
            .clamp(4, MAX_PANORAMA_TEXELS);
        let texel = (tau / width as f64).min(el_step);
        let max_extent_rad = 2.0 * (PANORAMA_EDGE_TOLERANCE_TEXELS * texel).sqrt().min(0.125);
        Panorama { width, height, texels_per_column: k, az0, el_top, el_step, max_extent_rad, max_piece_rad: MAX_PIECE_RAD, oversample }
    }

    /// Distance, in texels, of the projection of a point `m` from the straight panorama edge
    /// between the projections (phi, elevation) of `a` and `b` (phi of `b` taken within +-pi of
    /// `a`'s). With `m` the 3D midpoint of `ab`, this is how far the drawn edge strays from the
    /// true projected curve (its bulge peaks near the middle).
    pub fn chord_deviation_texels(&self, (a_phi, a_el): (f64, f64), (b_phi, b_el): (f64, f64), (m_phi, m_el): (f64, f64)) -> f64 {
        let tau = std::f64::consts::TAU;
        let wrap = |x: f64| x - tau * ((x + std::f64::consts::PI) / tau).floor();
        let (sx, sy) = (self.width as f64 / tau, 1.0 / self.el_step);
        let (ex, ey) = (wrap(b_phi - a_phi) * sx, (b_el - a_el) * sy);
        let (mx, my) = (wrap(m_phi - a_phi) * sx, (m_el - a_el) * sy);
        let len = ex.hypot(ey);
        if len == 0.0 {
            return mx.hypot(my);
        }
        (mx * ey - my * ex).abs() / len
    }

    /// `PANORAMA_EDGE_TOLERANCE_TEXELS` in radians, in the finer of the two texel directions.
    pub fn edge_tolerance_rad(&self) -> f64 {
        PANORAMA_EDGE_TOLERANCE_TEXELS * (std::f64::consts::TAU / self.width as f64).min(self.el_step)
    }

    /// Elevation of the bottom image edge, radians.
    pub fn el_bottom(&self) -> f64 {
        self.el_top - self.height as f64 * self.el_step
    }

    /// `phi` (clockwise angle from the left image edge, [0, 2 pi)) of a sensor-frame direction.
    pub fn phi(&self, d: DVec3) -> f64 {
        let tau = std::f64::consts::TAU;
        let p = (self.az0 - d.y.atan2(d.x)).rem_euclid(tau);
        if p >= tau {
            0.0
        } else {
            p
        }
    }

    /// Elevation of a direction, radians.
    pub fn elevation(d: DVec3) -> f64 {
        d.z.atan2(d.x.hypot(d.y))
    }

    /// Continuous pixel coordinates (px in [0, width), py) of a direction (texel centres at
    /// +0.5).
    pub fn pixel(&self, d: DVec3) -> (f64, f64) {
        let px = self.phi(d) * self.width as f64 / std::f64::consts::TAU;
        let px = if px >= self.width as f64 { 0.0 } else { px };
        let py = (self.el_top - Self::elevation(d)) / self.el_step;
        (px, py)
    }

    /// Texel (u, v) of a direction: u wraps around, v is clamped to the image.
    pub fn texel(&self, d: DVec3) -> (u32, u32) {
        let (px, py) = self.pixel(d);
        let u = (px.floor() as i64).rem_euclid(self.width as i64) as u32;
        let v = (py.floor().max(0.0) as u32).min(self.height - 1);
        (u, v)
    }

    /// Unit sensor-frame direction through the centre of texel (u, v).
    pub fn texel_dir(&self, u: u32, v: u32) -> DVec3 {
        let az = self.az0 - (u as f64 + 0.5) * std::f64::consts::TAU / self.width as f64;
        let el = self.el_top - (v as f64 + 0.5) * self.el_step;
        DVec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin())
    }

    /// The mapping constants of `shaders/panorama.glsl` (`map`): `az0`, `el_top`, the NDC scale
    /// in y (`2 / (height el_step)`) and `NEAR_M`. x_ndc = phi / pi - 1, y_ndc = (el_top - el)
    /// * scale - 1, clip = (x_ndc w, y_ndc w, NEAR_M, w) with w = range.
    pub fn shader_map(&self) -> [f32; 4] {
        [self.az0 as f32, self.el_top as f32, (2.0 / (self.height as f64 * self.el_step)) as f32, NEAR_M as f32]
    }

    /// Could a sphere (sensor frame) cover any texel? Its elevation cone against the band, and
    /// the near limit.
    pub fn sees_sphere(&self, centre: Vec3, radius: f32) -> bool {
        let c = centre.as_dvec3();
        let r = radius as f64;
        let dist = c.length();
        if dist + r < NEAR_M {
            return false;
        }
        if dist <= r {
            return true;
        }
        let half = (r / dist).asin();
        let el = Self::elevation(c);
        el - half <= self.el_top && el + half >= self.el_bottom()
    }
}

trait RoundSmall {
    fn round_small(self) -> Self;
}
impl RoundSmall for DVec3 {
    /// Snaps cos/sin rounding noise (1e-16) to exact 0 so faces are exactly axis-aligned.
    fn round_small(self) -> Self {
        let s = |v: f64| if v.abs() < 1e-12 { 0.0 } else { v };
        DVec3::new(s(self.x), s(self.y), s(self.z))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_beam_lands_inside_its_face_with_margin() {
        for sensor in [Sensor::hdl32e(), Sensor::vlp16()] {
            let cube = CubeFaces::new(&sensor, 1.5);
            for r in 0..sensor.rows() {
                for c in 0..sensor.columns {
                    let d = sensor.beam_dir(r, c);
                    let face = &cube.faces[cube.face_of(d)];
                    let (px, py) = face.pixel(d).expect("beam in front of its face");
                    assert!(px >= 0.0 && px <= face.width as f64, "px {px}");
                    assert!(py >= 1.0 && py <= face.height as f64 - 1.0, "py {py} h {}", face.height);
                }
            }
        }
    }

    #[test]
    fn clip_matrix_matches_the_texel_mapping() {
        let sensor = Sensor::hdl32e();
        let cube = CubeFaces::new(&sensor, 1.0);
        for face in &cube.faces {
            let m = face.clip_from_sensor().as_dmat4();
            for (u, v) in [(0, 0), (17, 5), (face.width - 1, face.height - 1)] {
                let d = face.texel_dir(u, v) * 3.7;
                let clip = m * d.extend(1.0);
                let ndc = clip.truncate() / clip.w;
                let px = (ndc.x + 1.0) * 0.5 * face.width as f64;
                let py = (ndc.y + 1.0) * 0.5 * face.height as f64;
                assert!((px - (u as f64 + 0.5)).abs() < 1e-4, "{px} {u}");
                assert!((py - (v as f64 + 0.5)).abs() < 1e-4, "{py} {v}");
                let zc = d.dot(face.forward);
                assert!((ndc.z - NEAR_M / zc).abs() < 1e-6);
                assert_eq!(face.texel(d), Some((u, v)));
            }
        }
    }

    #[test]
    fn seams_are_deterministic() {
        let cube = CubeFaces::new(&Sensor::hdl32e(), 1.0);
        // Exactly on the seam between face 0 (+x) and face 1 (+y): goes to face 1.
        assert_eq!(cube.face_of(DVec3::new(1.0, 1.0, 0.0)), 1);
        assert_eq!(cube.face_of(DVec3::new(1.0, -1.0, 0.0)), 0);
        assert_eq!(cube.face_of(DVec3::new(-1.0, 0.0, 0.0)), 2);
        assert_eq!(cube.face_of(DVec3::new(-1.0, -1e-300, 0.0)), 2);
        assert_eq!(cube.face_of(DVec3::new(0.0, -1.0, 0.3)), 3);
    }

    #[test]
    fn panorama_beams_lie_on_texel_centres() {
        for (sensor, k) in [(Sensor::hdl32e(), 1.0), (Sensor::hdl32e(), 2.0), (Sensor::vlp16(), 3.0), (Sensor::hdl32e(), 2.4)] {
            let p = Panorama::new(&sensor, k);
            let k = p.texels_per_column;
            assert_eq!(p.width, sensor.columns as u32 * k);
            for r in 0..sensor.rows() {
                for c in 0..sensor.columns {
                    let d = sensor.beam_dir(r, c);
                    let (px, py) = p.pixel(d);
                    let (u, v) = p.texel(d);
                    assert_eq!(u, c as u32 * k + k / 2, "column {c}");
                    assert!((px - (u as f64 + 0.5)).abs() < 1e-6, "px {px} u {u}");
                    // HDL-32E's table is uniform to 0.005 deg: within 1 % of a row of a centre.
                    assert!((py - (v as f64 + 0.5)).abs() < 0.01 * k as f64, "py {py} v {v}");
                    assert!(v >= 2 && v + 2 < p.height, "v {v} of {}", p.height);
                    assert!(p.texel_dir(u, v).angle_between(d) < 2e-4, "row {r} column {c}");
                }
            }
        }
    }

    #[test]
    fn panorama_texels_round_trip_and_wrap() {
        let p = Panorama::new(&Sensor::hdl32e(), 2.0);
        for (u, v) in [(0, 0), (1, 3), (p.width - 1, p.height - 1), (777, 40)] {
            assert_eq!(p.texel(p.texel_dir(u, v) * 3.0), (u, v));
        }
        // The wrap (azimuth az0, just past straight behind) sits between the last and the
        // first texel column.
        let at = |az: f64| DVec3::new(az.cos(), az.sin(), 0.0);
        assert_eq!(p.texel(at(p.az0 - 1e-9)).0, 0);
        assert_eq!(p.texel(at(p.az0 + 1e-9)).0, p.width - 1);
        assert_eq!(p.texel(DVec3::new(-1.0, 0.0, 0.0)).0, 0);
        // Column convention: +y (left) is a quarter of the way across, +x the middle (with 2
        // texels per column, the texel centred on +x lies between columns 511 and 512's beams).
        assert_eq!(p.texel(DVec3::new(0.0, 1.0, 0.0)).0, p.width / 4);
        assert_eq!(p.texel(DVec3::new(1.0, 0.0, 0.0)).0, p.width / 2);
        assert_eq!(p.texel(Sensor::hdl32e().beam_dir(0, 511)).0, p.width / 2 - 1);
    }

    /// The bound behind `max_extent_rad`: the projected curve of any segment whose extent in
    /// phi and elevation is within the bound deviates from the straight panorama edge by at
    /// most `PANORAMA_EDGE_TOLERANCE_TEXELS`, at elevations within the band's reach.
    #[test]
    fn panorama_straight_edges_stay_within_the_tolerance() {
        // The HDL-32E, and the steepest band a panorama takes (an OS0-128's +-45 deg).
        let wide = Sensor { elevation_deg: (0..128).map(|r| PANORAMA_MAX_ELEVATION_DEG - r as f64 * 90.0 / 127.0).collect(), ..Sensor::hdl32e() };
        for (sensor, oversample) in [(Sensor::hdl32e(), 1.0), (Sensor::hdl32e(), 2.0), (Sensor::hdl32e(), 3.0), (wide.clone(), 1.0), (wide, 2.0)] {
            let reach = sensor.max_abs_elevation_deg() + 5.0;
            let p = Panorama::new(&sensor, oversample);
            let texel_x = std::f64::consts::TAU / p.width as f64;
            let b = p.max_extent_rad;
            let mut worst = 0f64;
            let mut seed = 1u64;
            let mut rnd = || {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (seed >> 11) as f64 / (1u64 << 53) as f64
            };
            for _ in 0..20000 {
                // Endpoints: elevation within the band plus 5 deg (its margin and one extent),
                // the other within the bound in both phi and elevation.
                let el0 = (rnd() - 0.5) * 2.0 * reach.to_radians();
                let (dphi, del) = ((rnd() * 2.0 - 1.0) * b, (rnd() * 2.0 - 1.0) * b);
                let dir = |phi: f64, el: f64| DVec3::new(el.cos() * (p.az0 - phi).cos(), el.cos() * (p.az0 - phi).sin(), el.sin());
                let (a, c) = (dir(1.0, el0) * (1.0 + rnd() * 9.0), dir(1.0 + dphi, el0 + del) * (1.0 + rnd() * 9.0));
                for k in 1..16 {
                    let t = k as f64 / 16.0;
                    let q = a + t * (c - a);
                    // Distance in texels from the chord between the endpoints' (phi, el).
                    let (x0, y0) = (1.0 / texel_x, el0 / texel_x);
                    let (x1, y1) = ((1.0 + dphi) / texel_x, (el0 + del) / texel_x);
                    let (x, y) = (p.phi(q).min(6.0) / texel_x, Panorama::elevation(q) / texel_x);
                    let (ex, ey) = (x1 - x0, y1 - y0);
                    let dist = ((x - x0) * ey - (y - y0) * ex).abs() / ex.hypot(ey).max(1e-12);
                    worst = worst.max(dist);
                }
            }
            assert!(worst <= PANORAMA_EDGE_TOLERANCE_TEXELS, "+-{reach} deg, oversample {oversample}: {worst} texels");
        }
    }

    #[test]
    fn sphere_culling_is_conservative() {
        let cube = CubeFaces::new(&Sensor::hdl32e(), 1.0);
        let f0 = &cube.faces[0];
        assert!(f0.sees_sphere(Vec3::new(5.0, 0.0, 0.0), 0.5));
        assert!(!f0.sees_sphere(Vec3::new(-5.0, 0.0, 0.0), 0.5));
        // Far above the band (+10.67 deg): invisible; straddling the top edge: visible.
        assert!(!f0.sees_sphere(Vec3::new(5.0, 0.0, 4.0), 0.5));
        assert!(f0.sees_sphere(Vec3::new(5.0, 0.0, 1.6), 0.5));
        // Straddling the seam with face 1.
        assert!(f0.sees_sphere(Vec3::new(5.0, 5.2, 0.0), 0.5));
        assert!(cube.faces[1].sees_sphere(Vec3::new(5.0, 5.2, 0.0), 0.5));
    }
}
