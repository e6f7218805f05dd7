//! Closed low-polygon solids (boxes, prisms, cylinders, cones, ellipsoids) and open quads, added
//! to an [`Environment`] grouped into one mesh per material: a SemanticKITTI class and a
//! near-infrared reflectance rounded to [`REFLECTANCE_STEP`], so a world of a thousand things
//! draws as a few dozen meshes.

use crate::scene::{EnvMesh, Environment};
use glam::{DVec2, DVec3};
use std::collections::HashMap;

/// Reflectances are rounded to multiples of this (a material per class and step).
pub const REFLECTANCE_STEP: f32 = 0.05;

/// What a surface is: its SemanticKITTI class (`/class`) and its near-infrared reflectance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    pub class: u16,
    pub reflectance: f32,
}

impl Material {
    pub fn new(class: u16, reflectance: f64) -> Material {
        let r = ((reflectance as f32 / REFLECTANCE_STEP).round() * REFLECTANCE_STEP).clamp(REFLECTANCE_STEP, 1.0);
        Material { class, reflectance: r }
    }

    fn key(&self) -> (u16, u32) {
        (self.class, (self.reflectance / REFLECTANCE_STEP).round() as u32)
    }
}

/// The triangles of two rings of `n` vertices (the first ring 0..n, the second n..2n, both
/// counter-clockwise seen from the second's side): the walls between them and a cap on each
/// (fanned from its first vertex), all facing outward.
fn ring_pair(n: u32) -> Vec<[u32; 3]> {
    let mut tris = Vec::with_capacity(4 * n as usize);
    for i in 0..n {
        let j = (i + 1) % n;
        tris.push([i, j, n + j]);
        tris.push([i, n + j, n + i]);
    }
    for i in 1..n - 1 {
        tris.push([0, i + 1, i]);
        tris.push([n, n + i, n + i + 1]);
    }
    tris
}

/// An environment under construction, one mesh per [`Material`] (all double-sided).
#[derive(Default)]
pub struct Builder {
    positions: Vec<DVec3>,
    meshes: Vec<(Material, Vec<u32>)>,
    by_key: HashMap<(u16, u32), usize>,
    /// Places people stand at (behind a stall's counter, at a table).
    pub places: Vec<Place>,
    /// Doorways people come out of (a building's ground floor).
    pub doors: Vec<Place>,
    /// Seats people sit on (benches, chairs).
    pub seats: Vec<Seat>,
}

/// A place a person stands at ([`super::World::places`]): floor xy, and the way they face
/// there (out over a counter, towards a stall, towards a table), radians from +x.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Place {
    pub at: DVec2,
    pub facing_rad: f64,
}

/// A seat a person sits on ([`super::World::seats`]): the floor point under a seated
/// person's hip joints, the way they face, the seat's top, world z, and how far ahead of `at`
/// the floor is free for the feet (infinite where nothing stands there).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Seat {
    pub at: DVec2,
    pub facing_rad: f64,
    pub top_z_m: f64,
    pub feet_room_m: f64,
}

impl Builder {
    /// Triangles `tris` (indices into `verts`) of material `m`.
    pub fn triangles(&mut self, m: Material, verts: &[DVec3], tris: &[[u32; 3]]) {
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(verts);
        let k = *self.by_key.entry(m.key()).or_insert_with(|| {
            self.meshes.push((m, Vec::new()));
            self.meshes.len() - 1
        });
        let idx = &mut self.meshes[k].1;
        for t in tris {
            idx.extend(t.iter().map(|i| base + i));
        }
    }

    /// A quad `a b c d` (in order around it).
    pub fn quad(&mut self, m: Material, q: [DVec3; 4]) {
        self.triangles(m, &q, &[[0, 1, 2], [0, 2, 3]]);
    }

    /// A prism: the polygon `outline` (counter-clockwise, convex or not, xy) from `z0` to
    /// `z1`, walls and both caps (the caps fanned from the first corner: convex outlines only
    /// get exact caps).
    pub fn prism(&mut self, m: Material, outline: &[DVec2], z0: f64, z1: f64) {
        let n = outline.len() as u32;
        let mut verts: Vec<DVec3> = outline.iter().map(|p| p.extend(z0)).collect();
        verts.extend(outline.iter().map(|p| p.extend(z1)));
        let tris = ring_pair(n);
        self.triangles(m, &verts, &tris);
    }

    /// A box of `size` (x length, y width, z height) whose bottom centre is `base`, turned by
    /// `yaw` about z.
    pub fn cuboid(&mut self, m: Material, base: DVec3, size: DVec3, yaw: f64) {
        let (s, c) = yaw.sin_cos();
        let h = size.truncate() * 0.5;
        let corner = |x: f64, y: f64| base.truncate() + DVec2::new(c * x - s * y, s * x + c * y);
        let outline = [corner(-h.x, -h.y), corner(h.x, -h.y), corner(h.x, h.y), corner(-h.x, h.y)];
        self.prism(m, &outline, base.z, base.z + size.z);
    }

    /// An axis-aligned box from corner `lo` to corner `hi`.
    pub fn aabb(&mut self, m: Material, lo: DVec3, hi: DVec3) {
        let c = (lo + hi) * 0.5;
        self.cuboid(m, DVec3::new(c.x, c.y, lo.z), hi - lo, 0.0);
    }

    /// A cone frustum about the vertical through `base`: radius `r0` at the bottom, `r1` at the
    /// top (0: a cone), `sides` faces.
    pub fn frustum(&mut self, m: Material, base: DVec3, r0: f64, r1: f64, height: f64, sides: u32) {
        let ring = |r: f64, z: f64| -> Vec<DVec3> {
            (0..sides).map(|k| {
                let a = k as f64 * std::f64::consts::TAU / sides as f64;
                base + DVec3::new(r * a.cos(), r * a.sin(), z)
            }).collect()
        };
        let mut verts = ring(r0, 0.0);
        verts.extend(ring(r1.max(1e-4), height));
        let n = sides;
        let tris = ring_pair(n);
        self.triangles(m, &verts, &tris);
    }

    /// A vertical cylinder.
    pub fn cylinder(&mut self, m: Material, base: DVec3, r: f64, height: f64, sides: u32) {
        self.frustum(m, base, r, r, height, sides);
    }

    /// A cylinder between two points (any direction), radius `r`.
    pub fn rod(&mut self, m: Material, a: DVec3, b: DVec3, r: f64, sides: u32) {
        let axis = (b - a).normalize_or_zero();
        if axis == DVec3::ZERO {
            return;
        }
        let u = axis.any_orthonormal_vector();
        let v = axis.cross(u);
        let mut verts = Vec::with_capacity(2 * sides as usize);
        for end in [a, b] {
            for k in 0..sides {
                let t = k as f64 * std::f64::consts::TAU / sides as f64;
                verts.push(end + r * (t.cos() * u + t.sin() * v));
            }
        }
        let n = sides;
        let tris = ring_pair(n);
        self.triangles(m, &verts, &tris);
    }

    /// An ellipsoid of semi-axes `radii` about `centre`: `rings` latitude bands of `2 rings`
    /// longitudes, each vertex pushed in or out by up to `bumps` of its radius (a canopy's or a
    /// bush's lumps; `jitter` gives one number in -1..1 per vertex).
    pub fn ellipsoid(&mut self, m: Material, centre: DVec3, radii: DVec3, rings: u32, bumps: f64, mut jitter: impl FnMut() -> f64) {
        let lon = 2 * rings;
        let mut verts = vec![centre + DVec3::new(0.0, 0.0, -radii.z)];
        for i in 1..rings {
            let th = std::f64::consts::PI * i as f64 / rings as f64;
            for k in 0..lon {
                let ph = std::f64::consts::TAU * k as f64 / lon as f64;
                let d = DVec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), -th.cos());
                verts.push(centre + d * radii * (1.0 + bumps * jitter()));
            }
        }
        verts.push(centre + DVec3::new(0.0, 0.0, radii.z));
        let top = verts.len() as u32 - 1;
        let at = |i: u32, k: u32| 1 + (i - 1) * lon + k % lon;
        let mut tris = Vec::new();
        for k in 0..lon {
            tris.push([0, at(1, k + 1), at(1, k)]);
            tris.push([top, at(rings - 1, k), at(rings - 1, k + 1)]);
        }
        for i in 1..rings - 1 {
            for k in 0..lon {
                tris.push([at(i, k), at(i, k + 1), at(i + 1, k + 1)]);
                tris.push([at(i, k), at(i + 1, k + 1), at(i + 1, k)]);
            }
        }
        self.triangles(m, &verts, &tris);
    }

    /// Triangles so far.
    pub fn triangle_count(&self) -> usize {
        self.meshes.iter().map(|(_, i)| i.len() / 3).sum()
    }

    /// The environment: a mesh per material, named `class-<id>-r<reflectance>`, in the order
    /// the materials were first used, each over a block of vertices of its own (in the order
    /// its triangles first use them). Shapes of every material are built one after another, so
    /// a material's vertices would otherwise be spread over the whole world, and every frame
    /// would pose and copy the whole world's vertices once per material.
    pub fn finish(self) -> Environment {
        let mut new_of = vec![u32::MAX; self.positions.len()];
        let mut positions = Vec::with_capacity(self.positions.len());
        let meshes = self
            .meshes
            .into_iter()
            .map(|(m, mut indices)| {
                for i in &mut indices {
                    let n = &mut new_of[*i as usize];
                    if *n == u32::MAX {
                        *n = positions.len() as u32;
                        positions.push(self.positions[*i as usize]);
                    }
                    *i = *n;
                }
                EnvMesh { name: format!("class-{}-r{:.2}", m.class, m.reflectance), indices, double_sided: true, reflectance: m.reflectance, class: m.class }
            })
            .collect();
        Environment { positions, meshes }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Twice the signed volume enclosed by a mesh's triangles (divergence theorem): exact for
    /// a closed, consistently wound solid.
    fn volume(env: &Environment) -> f64 {
        env.triangles().map(|[a, b, c]| a.dot(b.cross(c)) / 6.0).sum()
    }

    #[test]
    fn solids_are_closed_and_have_their_volume() {
        let m = Material::new(99, 0.3);
        let mut b = Builder::default();
        b.cuboid(m, DVec3::new(1.0, 2.0, 0.5), DVec3::new(2.0, 3.0, 4.0), 0.7);
        let v = volume(&b.finish());
        assert!((v - 24.0).abs() < 1e-9, "{v}");
        let mut b = Builder::default();
        b.cylinder(m, DVec3::new(-3.0, 1.0, 0.0), 0.5, 2.0, 64);
        let v = volume(&b.finish());
        let exact = std::f64::consts::PI * 0.25 * 2.0;
        assert!((v - exact).abs() / exact < 0.005, "{v} vs {exact}");
        let mut b = Builder::default();
        b.ellipsoid(m, DVec3::new(0.0, 0.0, 3.0), DVec3::new(1.0, 2.0, 1.5), 24, 0.0, || 0.0);
        let v = volume(&b.finish());
        let exact = 4.0 / 3.0 * std::f64::consts::PI * 3.0;
        assert!((v - exact).abs() / exact < 0.02, "{v} vs {exact}");
        let mut b = Builder::default();
        b.rod(m, DVec3::new(0.0, 0.0, 1.0), DVec3::new(1.0, 1.0, 2.0), 0.1, 32);
        let v = volume(&b.finish());
        let exact = std::f64::consts::PI * 0.01 * 3f64.sqrt();
        assert!((v - exact).abs() / exact < 0.01, "{v} vs {exact}");
    }

    #[test]
    fn materials_group_into_meshes_by_class_and_rounded_reflectance() {
        let mut b = Builder::default();
        b.aabb(Material::new(50, 0.31), DVec3::ZERO, DVec3::ONE);
        b.aabb(Material::new(50, 0.29), DVec3::splat(2.0), DVec3::splat(3.0));
        b.aabb(Material::new(70, 0.3), DVec3::splat(4.0), DVec3::splat(5.0));
        b.aabb(Material::new(50, 0.5), DVec3::splat(6.0), DVec3::splat(7.0));
        let env = b.finish();
        let names: Vec<&str> = env.meshes.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(names, ["class-50-r0.30", "class-70-r0.30", "class-50-r0.50"]);
        assert_eq!(env.meshes[0].indices.len(), 2 * 36);
        assert_eq!(env.meshes.iter().map(|m| m.class).collect::<Vec<_>>(), [50, 70, 50]);
        assert_eq!(Material::new(1, -3.0).reflectance, REFLECTANCE_STEP, "never black");
    }
}
