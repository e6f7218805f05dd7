//! Stage 5: the posed triangles of one frame, in the sensor frame (f32), as both render paths see them:
//! the Vulkan raster path draws them, the CPU ray-cast reference intersects them.
//!
//! Triangles are numbered globally in the order they are pushed; the raster ID buffer stores
//! `triangle + 1` (0 = no hit), so the CPU finds the mesh (and its instance) of any hit.

use glam::{DVec3, Vec3};
use std::sync::Arc;

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
    /// The mesh's vertices in `FrameGeometry::positions`.
    pub first_vertex: u32,
    pub vertex_count: u32,
}

/// One mesh's first vertex, vertices and absolute indices (see
/// [`FrameGeometry::mesh_slices_mut`]).
pub type MeshSlices<'a> = (u32, &'a mut [[f32; 3]], &'a mut [u32]);

/// The size and kind of one mesh, for [`FrameGeometry::lay_out`].
#[derive(Clone, Debug)]
pub struct MeshLayout {
    pub vertex_count: u32,
    pub triangle_count: u32,
    pub instance: u32,
    pub double_sided: bool,
    pub adjacency: Option<Arc<Adjacency>>,
}

/// Triangles of one frame in the sensor frame: positions, absolute indices, meshes.
#[derive(Clone, Debug, Default)]
pub struct FrameGeometry {
    pub positions: Vec<[f32; 3]>,
    /// Three absolute indices into `positions` per triangle.
    pub indices: Vec<u32>,
    pub meshes: Vec<MeshRange>,
    /// Per mesh (parallel to `meshes`): triangle neighbourhoods, when known.
    pub adjacency: Vec<Option<Arc<Adjacency>>>,
}

/// For each triangle of a mesh, the triangles that share a vertex with it (its one-ring),
/// as local triangle indices. Topology only: computed once per mesh, valid for every pose.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Adjacency {
    offsets: Vec<u32>,
    neighbours: Vec<u32>,
}

impl Adjacency {
    /// Builds the one-rings of a triangle list (`indices` local, 3 per triangle).
    pub fn build(indices: &[u32]) -> Adjacency {
        let tris = indices.len() / 3;
        let nv = indices.iter().copied().max().map_or(0, |m| m as usize + 1);
        // vertex -> triangles (CSR)
        let mut vcount = vec![0u32; nv + 1];
        for &i in indices {
            vcount[i as usize + 1] += 1;
        }
        for k in 0..nv {
            vcount[k + 1] += vcount[k];
        }
        let mut vtris = vec![0u32; indices.len()];
        let mut fill = vcount.clone();
        for (t, tri) in indices.chunks_exact(3).enumerate() {
            for &i in tri {
                vtris[fill[i as usize] as usize] = t as u32;
                fill[i as usize] += 1;
            }
        }
        let mut offsets = Vec::with_capacity(tris + 1);
        let mut neighbours = Vec::with_capacity(tris * 12);
        offsets.push(0);
        // Each vertex's triangles are listed in ascending order (filled in triangle order), so
        // a one-ring is the three lists merged, without sorting: the smallest head is taken,
        // its copies at every head skipped.
        let list = |i: u32| &vtris[vcount[i as usize] as usize..vcount[i as usize + 1] as usize];
        for (t, tri) in indices.chunks_exact(3).enumerate() {
            let mut heads = [list(tri[0]), list(tri[1]), list(tri[2])];
            while let Some(next) = heads.iter().filter_map(|h| h.first().copied()).min() {
                for h in &mut heads {
                    // A triangle that repeats a vertex is listed twice for it.
                    while h.first() == Some(&next) {
                        *h = &h[1..];
                    }
                }
                if next != t as u32 {
                    neighbours.push(next);
                }
            }
            offsets.push(neighbours.len() as u32);
        }
        Adjacency { offsets, neighbours }
    }

    /// This adjacency with `other`'s after it: the one-rings of a mesh whose first triangles
    /// are `self`'s and whose last are `other`'s, sharing no vertex with them (their indices
    /// shifted by `self`'s triangle count): what [`Adjacency::build`] gives for the joined
    /// mesh, without building it again.
    pub fn with_disjoint(&self, other: &Adjacency) -> Adjacency {
        // `build` starts the offsets with 0 and adds one a triangle.
        let tris = (self.offsets.len() - 1) as u32;
        let base = self.offsets[self.offsets.len() - 1];
        let mut offsets = self.offsets.clone();
        offsets.extend(other.offsets.iter().skip(1).map(|o| o + base));
        let mut neighbours = self.neighbours.clone();
        neighbours.extend(other.neighbours.iter().map(|t| t + tris));
        Adjacency { offsets, neighbours }
    }

    /// Local triangles sharing a vertex with local triangle `t`.
    pub fn of(&self, t: u32) -> &[u32] {
        let t = t as usize;
        if t + 1 >= self.offsets.len() {
            return &[];
        }
        &self.neighbours[self.offsets[t] as usize..self.offsets[t + 1] as usize]
    }

    pub fn triangle_count(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }
}

impl FrameGeometry {
    /// Empties the geometry, keeping the allocations (no per-frame allocation in steady state).
    pub fn clear(&mut self) {
        self.positions.clear();
        self.indices.clear();
        self.meshes.clear();
        self.adjacency.clear();
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> u32 {
        (self.indices.len() / 3) as u32
    }

    /// Appends a mesh whose `positions` are already in the sensor frame and whose `indices`
    /// are local to `positions`. The bounding sphere is computed here.
    pub fn push_mesh(&mut self, positions: &[[f32; 3]], indices: &[u32], instance: u32, double_sided: bool) {
        self.push_mesh_with_adjacency(positions, indices, instance, double_sided, None);
    }

    /// Like `push_mesh`, with the mesh's triangle neighbourhoods (built from the same `indices`)
    /// so exact refinement can search around the rendered triangle.
    pub fn push_mesh_with_adjacency(
        &mut self,
        positions: &[[f32; 3]],
        indices: &[u32],
        instance: u32,
        double_sided: bool,
        adjacency: Option<Arc<Adjacency>>,
    ) {
        debug_assert!(adjacency.as_ref().map_or(true, |a| a.triangle_count() == indices.len() / 3));
        self.adjacency.push(adjacency);
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
            first_vertex: base,
            vertex_count: positions.len() as u32,
        });
    }

    /// Replaces all meshes by meshes of the given sizes, one after the other, for the caller
    /// to fill in place (see [`FrameGeometry::mesh_slices_mut`]): positions and indices are
    /// resized (their contents are stale until filled), bounding spheres are zero.
    pub fn lay_out(&mut self, meshes: impl IntoIterator<Item = MeshLayout>) {
        self.meshes.clear();
        self.adjacency.clear();
        let (mut vertices, mut triangles) = (0u32, 0u32);
        for m in meshes {
            debug_assert!(m.adjacency.as_ref().map_or(true, |a| a.triangle_count() == m.triangle_count as usize));
            self.meshes.push(MeshRange {
                first_triangle: triangles,
                triangle_count: m.triangle_count,
                instance: m.instance,
                centre: [0.0; 3],
                radius: 0.0,
                double_sided: m.double_sided,
                first_vertex: vertices,
                vertex_count: m.vertex_count,
            });
            self.adjacency.push(m.adjacency);
            vertices += m.vertex_count;
            triangles += m.triangle_count;
        }
        self.positions.resize(vertices as usize, [0.0; 3]);
        self.indices.resize(3 * triangles as usize, 0);
    }

    /// Per mesh, its first vertex, its vertices and its (absolute) indices, as disjoint
    /// mutable slices, so the meshes can be filled in parallel.
    pub fn mesh_slices_mut(&mut self) -> Vec<MeshSlices<'_>> {
        let mut pos = &mut self.positions[..];
        let mut idx = &mut self.indices[..];
        let mut out = Vec::with_capacity(self.meshes.len());
        for m in &self.meshes {
            let (p, p_rest) = std::mem::take(&mut pos).split_at_mut(m.vertex_count as usize);
            let (i, i_rest) = std::mem::take(&mut idx).split_at_mut(3 * m.triangle_count as usize);
            out.push((m.first_vertex, p, i));
            pos = p_rest;
            idx = i_rest;
        }
        out
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
        &self.meshes[self.mesh_index_of_triangle(t)]
    }

    /// Index (into `meshes`) of the mesh that owns global triangle `t`.
    pub fn mesh_index_of_triangle(&self, t: u32) -> usize {
        let k = self.meshes.partition_point(|m| m.first_triangle <= t);
        debug_assert!(k > 0, "triangle {t} before the first mesh");
        k - 1
    }

    /// Global triangles sharing a vertex with global triangle `t` (empty without adjacency).
    pub fn neighbours(&self, t: u32) -> impl Iterator<Item = u32> + '_ {
        self.neighbours_in_mesh(self.mesh_index_of_triangle(t), t)
    }

    /// [`FrameGeometry::neighbours`] of triangle `t` of mesh `k` (its
    /// [`FrameGeometry::mesh_index_of_triangle`], known to the caller).
    pub fn neighbours_in_mesh(&self, k: usize, t: u32) -> impl Iterator<Item = u32> + '_ {
        let first = self.meshes[k].first_triangle;
        let ring: &[u32] = match self.adjacency.get(k) {
            Some(Some(a)) => a.of(t - first),
            _ => &[],
        };
        ring.iter().map(move |n| n + first)
    }
}

/// `a` wrapped into [-π, π), as `(a + π) mod 2π - π`: the signed turn an angle difference
/// stands for, the shorter way.
pub fn wrap_pi(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
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
    fn adjacency_is_the_vertex_one_ring() {
        // A fan of 4 triangles around vertex 0, plus one far triangle.
        let idx = [0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 5, 6, 7, 8];
        let a = Adjacency::build(&idx);
        assert_eq!(a.triangle_count(), 5);
        assert_eq!(a.of(0), &[1, 2, 3]);
        assert_eq!(a.of(4), &[] as &[u32]);
        let mut g = FrameGeometry::default();
        g.push_mesh(&[[0.0; 3]; 3], &[0, 1, 2], 0, true);
        g.push_mesh_with_adjacency(&[[0.0; 3]; 9], &idx, 2, false, Some(Arc::new(a)));
        assert_eq!(g.neighbours(2).collect::<Vec<_>>(), vec![1, 3, 4]);
    }

    /// The merged one-rings equal the definition, checked by brute force over every pair of
    /// triangles, on a random mesh with shared vertices and triangles that repeat a vertex.
    #[test]
    fn adjacency_equals_the_brute_force_one_rings() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let idx: Vec<u32> = (0..3 * 400).map(|_| rng.random_range(0..150u32)).collect();
        let a = Adjacency::build(&idx);
        let tri = |t: usize| &idx[3 * t..3 * t + 3];
        for t in 0..400 {
            let expected: Vec<u32> =
                (0..400).filter(|&u| u != t && tri(u).iter().any(|v| tri(t).contains(v))).map(|u| u as u32).collect();
            assert_eq!(a.of(t as u32), expected.as_slice(), "triangle {t}");
        }
    }

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
        assert_eq!(g.neighbours(0).count(), 0, "no adjacency given");
        let m = g.meshes[1];
        for p in &quad[..3] {
            assert!(Vec3::from(*p).distance(Vec3::from(m.centre)) <= m.radius);
        }
    }
}
