//! Exact nearest hit of ONE beam over a whole [`FrameGeometry`], for the few beams the raster
//! path cannot settle from its ID buffer (silhouettes, depth steps, holes next to surfaces).
//!
//! Each mesh is cut into clusters of [`CLUSTER_TRIANGLES`] consecutive triangles with a
//! bounding sphere (f64, from the frame's f32 vertices, widened to stay conservative under
//! rounding). A beam visits the meshes whose sphere it crosses, then their clusters whose
//! sphere it crosses, nearest entry first, and stops when the next entry lies beyond the best
//! hit. Every triangle it tests goes through the reference's watertight test with the
//! reference's tie rule (smaller range, then smaller triangle), and a cluster is skipped only
//! when the beam misses a sphere holding all of its vertices, so the result equals the BVH
//! reference and brute force bit for bit.
//!
//! Clusters are built per mesh on first use within a frame ([`MeshClusters::reset`] starts a
//! frame), from any thread: a frame whose people are all settled by the raster builds none.

use super::{better, intersect_pre, RayPre};
use crate::geometry::FrameGeometry;
use glam::DVec3;
use std::sync::OnceLock;

/// Triangles per cluster: consecutive in the mesh's index order (spatially coherent for the
/// bundled people and simplified levels of detail).
pub const CLUSTER_TRIANGLES: usize = 32;

#[derive(Clone, Copy, Debug)]
struct Sphere {
    centre: DVec3,
    radius: f64,
}

impl Sphere {
    /// Conservative bounding sphere of `points` (f32 vertices, exact in f64) in one pass: the
    /// centre and half diagonal of their box, widened by a relative 1e-9 and an absolute 1e-9
    /// m for the rounding of the box and of the beam test.
    fn of(points: impl Iterator<Item = [f32; 3]>) -> Sphere {
        let (mut lo, mut hi) = (glam::Vec3::splat(f32::INFINITY), glam::Vec3::splat(f32::NEG_INFINITY));
        for p in points {
            let p = glam::Vec3::from(p);
            lo = lo.min(p);
            hi = hi.max(p);
        }
        let (lo, hi) = (lo.as_dvec3(), hi.as_dvec3());
        Sphere::widened(0.5 * (lo + hi), 0.5 * (hi - lo).length())
    }

    /// A sphere holding every sphere of `parts`.
    fn around(parts: &[Sphere]) -> Sphere {
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for s in parts {
            lo = lo.min(s.centre);
            hi = hi.max(s.centre);
        }
        let centre = 0.5 * (lo + hi);
        Sphere::widened(centre, parts.iter().map(|s| (s.centre - centre).length() + s.radius).fold(0.0, f64::max))
    }

    fn widened(centre: DVec3, radius: f64) -> Sphere {
        Sphere { centre, radius: radius * (1.0 + 1e-9) + 1e-9 * (1.0 + centre.length()) }
    }

    /// Entry distance of the ray from the origin along unit `dir`, or None when it misses.
    /// Any point of the sphere on the ray lies at or beyond the returned distance; a sphere
    /// whose bound is not finite is always entered (at 0).
    #[inline]
    fn entry(&self, dir: DVec3) -> Option<f64> {
        if !(self.radius.is_finite() && self.centre.is_finite()) {
            return Some(0.0);
        }
        let along = self.centre.dot(dir);
        if along + self.radius < 0.0 {
            return None;
        }
        let perp2 = (self.centre - along * dir).length_squared();
        let r2 = self.radius * self.radius;
        if perp2 > r2 {
            return None;
        }
        Some((along - (r2 - perp2).sqrt()).max(0.0))
    }
}

/// The vertices named by `indices`.
fn vertices_of<'a>(geom: &'a FrameGeometry, indices: &'a [u32]) -> impl Iterator<Item = [f32; 3]> + 'a {
    indices.iter().map(move |&i| geom.positions[i as usize])
}

/// Clusters per group: a beam tests a group's sphere before its clusters' spheres.
const GROUP_CLUSTERS: usize = 16;

/// One mesh's spheres: the whole mesh, its groups, its clusters.
#[derive(Clone, Debug)]
struct MeshSpheres {
    mesh: Sphere,
    groups: Vec<Sphere>,
    clusters: Vec<Sphere>,
}

/// Per-mesh clusters of one frame, built on demand.
#[derive(Debug, Default)]
pub struct MeshClusters {
    /// Per mesh of the frame, once built.
    meshes: Vec<OnceLock<MeshSpheres>>,
}

impl MeshClusters {
    /// Starts a new frame of `geom` (forgets every cluster; keeps nothing of the last frame).
    pub fn reset(&mut self, geom: &FrameGeometry) {
        self.meshes.clear();
        self.meshes.resize_with(geom.meshes.len(), OnceLock::new);
    }

    fn mesh(&self, geom: &FrameGeometry, k: usize) -> &MeshSpheres {
        self.meshes[k].get_or_init(|| {
            let m = &geom.meshes[k];
            let first = 3 * m.first_triangle as usize;
            let idx = &geom.indices[first..first + 3 * m.triangle_count as usize];
            let clusters: Vec<Sphere> = idx.chunks(3 * CLUSTER_TRIANGLES).map(|c| Sphere::of(vertices_of(geom, c))).collect();
            let groups: Vec<Sphere> = clusters.chunks(GROUP_CLUSTERS).map(Sphere::around).collect();
            MeshSpheres { mesh: Sphere::around(&groups), groups, clusters }
        })
    }

    /// The exact nearest hit `(range, triangle)` of the beam along unit `dir` over every mesh
    /// of `geom` (the layer the raster drew), equal to the reference's. `clusters` is scratch.
    pub fn cast(&self, geom: &FrameGeometry, dir: DVec3, clusters: &mut Vec<(f64, u32, u32)>) -> Option<(f64, u32)> {
        let ray = RayPre::new(dir)?;
        let (mut best_t, mut best_tri) = (f64::INFINITY, u32::MAX);
        // Candidate clusters of every mesh the beam enters: (entry, mesh, cluster).
        clusters.clear();
        for (k, m) in geom.meshes.iter().enumerate() {
            if m.triangle_count == 0 {
                continue;
            }
            let s = self.mesh(geom, k);
            if s.mesh.entry(dir).is_none() {
                continue;
            }
            for (g, group) in s.groups.iter().enumerate() {
                if group.entry(dir).is_none() {
                    continue;
                }
                let first = g * GROUP_CLUSTERS;
                let end = (first + GROUP_CLUSTERS).min(s.clusters.len());
                for c in first..end {
                    if let Some(e) = s.clusters[c].entry(dir) {
                        clusters.push((e, k as u32, c as u32));
                    }
                }
            }
        }
        clusters.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
        for &(entry, k, c) in clusters.iter() {
            if entry > best_t {
                break;
            }
            let m = &geom.meshes[k as usize];
            let first = m.first_triangle + c * CLUSTER_TRIANGLES as u32;
            let end = (first + CLUSTER_TRIANGLES as u32).min(m.first_triangle + m.triangle_count);
            for t in first..end {
                if let Some(r) = intersect_pre(&ray, &geom.triangle_f64(t), !m.double_sided) {
                    if better(r, t, best_t, best_tri) {
                        (best_t, best_tri) = (r, t);
                    }
                }
            }
        }
        (best_tri != u32::MAX).then_some((best_t, best_tri))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raycast::cast_brute_force;

    /// Random little triangles around the sensor, in several meshes (one double-sided), some
    /// far, some on the beam grid's rows: every beam's cluster cast equals brute force.
    #[test]
    fn cluster_cast_equals_brute_force() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut geom = FrameGeometry::default();
        for mesh in 0..6u32 {
            let centre = DVec3::new(rng.random_range(-20.0..20.0), rng.random_range(-20.0..20.0), rng.random_range(-3.0..3.0));
            let mut p = Vec::new();
            let mut i = Vec::new();
            for t in 0..700u32 {
                let c = centre + DVec3::new(rng.random_range(-2.0..2.0), rng.random_range(-2.0..2.0), rng.random_range(-2.0..2.0));
                for _ in 0..3 {
                    let v = c + DVec3::new(rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3));
                    p.push(v.as_vec3().to_array());
                }
                i.extend([3 * t, 3 * t + 1, 3 * t + 2]);
            }
            // Exact duplicates of a few triangles (ties go to the smaller index).
            for t in 0..20u32 {
                i.extend([3 * t, 3 * t + 1, 3 * t + 2]);
            }
            geom.push_mesh(&p, &i, mesh, mesh == 3);
        }
        let mut clusters = MeshClusters::default();
        clusters.reset(&geom);
        let mut scratch = Vec::new();
        let dirs: Vec<DVec3> = (0..20_000)
            .map(|k| {
                let az = std::f64::consts::TAU * k as f64 / 20_000.0 * 7.0;
                let el = ((k % 97) as f64 / 97.0 - 0.5) * 0.6;
                DVec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin())
            })
            .collect();
        let want = cast_brute_force(&geom, &dirs, f64::MAX, |_| true);
        let mut hits = 0;
        for (k, (&dir, want)) in dirs.iter().zip(&want).enumerate() {
            match clusters.cast(&geom, dir, &mut scratch) {
                Some((r, t)) => {
                    hits += 1;
                    assert_eq!((r, t), (want.range_m, want.triangle), "beam {k}");
                }
                None => assert!(!want.is_hit(), "beam {k}: missed {want:?}"),
            }
        }
        assert!(hits > 500, "the test must hit something ({hits} hits)");
    }

    #[test]
    fn a_sphere_entry_is_never_beyond_its_surface() {
        let s = Sphere::of([[10.0f32, 0.0, 0.0], [12.0, 0.0, 0.0], [11.0, 1.0, 0.0]].into_iter());
        assert!(Sphere::around(&[s]).radius >= s.radius);
        let e = s.entry(DVec3::X).unwrap();
        assert!(e <= 10.0 && e > 9.8, "{e}");
        assert!(s.entry(-DVec3::X).is_none());
        assert!(s.entry(DVec3::Y).is_none());
    }
}
