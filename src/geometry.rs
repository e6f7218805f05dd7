//! The posed triangles of one frame, in the sensor frame (f32), as both render paths see them:
//! the Vulkan raster path draws them, the CPU ray-cast reference intersects them.
//!
//! Triangles are numbered globally in the order they are pushed; the raster ID buffer stores
//! `triangle + 1` (0 = no hit), so the CPU finds the mesh (and its instance) of any hit.

use glam::{DVec3, Vec3};

/// A contiguous run of triangles that belong to one drawn object.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshRange {
    /// Global index of the first triangle of this mesh.
    pub first_triangle: u32,
    pub triangle_count: u32,
    /// 0 = background, k = k-th human of the sequence (1-based).
    pub instance: u32,
    /// Bounding sphere in the sensor frame (metres).
    pub centre: [f32; 3],
    pub radius: f32,
    /// Draw both sides (no back-face culling), e.g. walls seen from inside.
    pub double_sided: bool,
}

/// Triangles of one frame in the sensor frame: positions, absolute indices, meshes.
#[derive(Clone, Debug, Default)]
pub struct FrameGeometry {
    pub positions: Vec<[f32; 3]>,
    /// Three absolute indices into `positions` per triangle.
    pub indices: Vec<u32>,
    pub meshes: Vec<MeshRange>,
}

impl FrameGeometry {
    /// Empties the geometry, keeping the allocations (no per-frame allocation in steady state).
    pub fn clear(&mut self) {
        self.positions.clear();
        self.indices.clear();
        self.meshes.clear();
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> u32 {
        (self.indices.len() / 3) as u32
    }

    /// Appends a mesh whose `positions` are already in the sensor frame and whose `indices`
    /// are local to `positions`. The bounding sphere is computed here.
    pub fn push_mesh(&mut self, positions: &[[f32; 3]], indices: &[u32], instance: u32, double_sided: bool) {
        let base = self.positions.len() as u32;
        let first_triangle = self.triangle_count();
        self.positions.extend_from_slice(positions);
        self.indices.extend(indices.iter().map(|i| i + base));
        let (centre, radius) = bounding_sphere(positions);
        self.meshes.push(MeshRange {
            first_triangle,
            triangle_count: (indices.len() / 3) as u32,
            instance,
            centre,
            radius,
            double_sided,
        });
    }

    /// The three vertices of global triangle `t`.
    pub fn triangle(&self, t: u32) -> [Vec3; 3] {
        let i = 3 * t as usize;
        let p = |k: usize| Vec3::from(self.positions[self.indices[i + k] as usize]);
        [p(0), p(1), p(2)]
    }

    /// The three vertices of global triangle `t`, widened to f64.
    pub fn triangle_f64(&self, t: u32) -> [DVec3; 3] {
        let [a, b, c] = self.triangle(t);
        [a.as_dvec3(), b.as_dvec3(), c.as_dvec3()]
    }

    /// The mesh that owns global triangle `t`.
    pub fn mesh_of_triangle(&self, t: u32) -> &MeshRange {
        let k = self.meshes.partition_point(|m| m.first_triangle <= t);
        debug_assert!(k > 0, "triangle {t} before the first mesh");
        &self.meshes[k - 1]
    }
}

/// A bounding sphere: centre of the axis-aligned box, radius to the farthest vertex.
pub fn bounding_sphere(positions: &[[f32; 3]]) -> ([f32; 3], f32) {
    if positions.is_empty() {
        return ([0.0; 3], 0.0);
    }
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for p in positions {
        let p = Vec3::from(*p);
        lo = lo.min(p);
        hi = hi.max(p);
    }
    let c = 0.5 * (lo + hi);
    let r = positions.iter().map(|p| Vec3::from(*p).distance(c)).fold(0.0f32, f32::max);
    // Pad by a relative epsilon so f32 rounding never puts a vertex outside.
    (c.into(), r * (1.0 + 1e-5) + 1e-6)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangles_are_numbered_globally_and_map_back_to_their_mesh() {
        let mut g = FrameGeometry::default();
        let quad = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        g.push_mesh(&quad, &[0, 1, 2, 0, 2, 3], 0, true);
        g.push_mesh(&quad, &[0, 1, 2], 7, false);
        assert_eq!(g.triangle_count(), 3);
        assert_eq!(g.mesh_of_triangle(0).instance, 0);
        assert_eq!(g.mesh_of_triangle(1).instance, 0);
        assert_eq!(g.mesh_of_triangle(2).instance, 7);
        assert_eq!(g.triangle(2)[1], Vec3::new(1.0, 0.0, 0.0));
        assert_eq!(g.indices[6..9], [4, 5, 6]);
        let m = g.meshes[1];
        for p in &quad[..3] {
            assert!(Vec3::from(*p).distance(Vec3::from(m.centre)) <= m.radius);
        }
    }
}
