//! Stage 2a: the raster views. The sensor's beams are covered by the 4 side faces of a cube
//! (face k looks along azimuth k * 90 deg: +x, +y, -x, -y), each with an off-centre frustum
//! that covers only the sensor's elevation band. This module owns the exact texel <-> direction
//! mapping that the GPU (through `clip_from_sensor`) and the resampler share.
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
