//! Exact nearest hit of ONE beam over a whole [`FrameGeometry`], for the few beams the raster
//! path cannot settle from its ID buffer (silhouettes, depth steps, holes next to surfaces).
//!
//! Each mesh is cut into clusters of [`CLUSTER_TRIANGLES`] consecutive triangles with a
//! bounding box (f64, from the frame's f32 vertices, widened to stay conservative under
//! rounding), grouped by [`GROUP_CLUSTERS`]. A beam visits the meshes and groups whose box it
//! crosses, then their clusters whose box it crosses, nearest entry first, and stops when the
//! next entry lies beyond the best hit. Every triangle it tests goes through the reference's
//! watertight test with the reference's tie rule (smaller range, then smaller triangle), and
//! a cluster is skipped only when the beam misses a box holding all of its vertices, so the
//! result equals the BVH reference and brute force bit for bit.
//!
//! Clusters are built per mesh on first use within a frame ([`MeshClusters::reset`] starts a
//! frame), from any thread: a frame whose people are all settled by the raster builds none.

use crate::backend::triangle::{better, intersect_pre, RayPre};
use crate::geometry::FrameGeometry;
use glam::DVec3;
use std::sync::OnceLock;

/// Triangles per cluster: consecutive in the mesh's index order (spatially coherent for the
/// bundled people and simplified levels of detail).
pub const CLUSTER_TRIANGLES: usize = 16;

/// An axis-aligned box (f64; built from f32 vertices, so exact), widened for the rounding of
/// the slab test. Boxes, not spheres: the background's long flat triangles (a floor, a wall)
/// have thin boxes that a beam enters only where it reaches them, while their spheres would
/// hold the sensor and be entered at 0 by every beam.
#[derive(Clone, Copy, Debug)]
struct Bounds {
    lo: DVec3,
    hi: DVec3,
}

impl Bounds {
    const EMPTY: Bounds = Bounds { lo: DVec3::splat(f64::INFINITY), hi: DVec3::splat(f64::NEG_INFINITY) };

    /// The box of `points`, widened (see [`Bounds::widened`]).
    fn of(points: impl Iterator<Item = [f32; 3]>) -> Bounds {
        let (mut lo, mut hi) = (glam::Vec3::splat(f32::INFINITY), glam::Vec3::splat(f32::NEG_INFINITY));
        for p in points {
            let p = glam::Vec3::from(p);
            lo = lo.min(p);
            hi = hi.max(p);
        }
        Bounds { lo: lo.as_dvec3(), hi: hi.as_dvec3() }.widened()
    }

    /// The box around `parts` (already widened).
    fn around(parts: &[Bounds]) -> Bounds {
        parts.iter().fold(Bounds::EMPTY, |a, b| Bounds { lo: a.lo.min(b.lo), hi: a.hi.max(b.hi) })
    }

    /// Widened by a relative 1e-9 of its coordinates' size and an absolute 1e-12 m, far above
    /// the rounding of the slab test below.
    fn widened(self) -> Bounds {
        let eps = DVec3::splat(1e-9 * self.lo.abs().max(self.hi.abs()).max_element() + 1e-12);
        Bounds { lo: self.lo - eps, hi: self.hi + eps }
    }

    /// Entry distance of the ray from the origin along unit `dir` into the box (0 when it
    /// starts inside), or None when it misses. A box with a non-finite corner is always
    /// entered (at 0).
    /// [`Self::entry`] with the beam's reciprocal direction precomputed (`Beam`): the same
    /// answer without a division.
    #[inline]
    fn entry_beam(&self, beam: &Beam) -> Option<f64> {
        if !beam.all_nonzero {
            return self.entry(beam.dir);
        }
        if !(self.lo.is_finite() && self.hi.is_finite()) {
            return Some(0.0);
        }
        let a = self.lo * beam.inv;
        let b = self.hi * beam.inv;
        let t0 = a.min(b).max_element().max(0.0);
        let t1 = a.max(b).min_element();
        (t0 <= t1).then_some(t0)
    }

    #[inline]
    fn entry(&self, dir: DVec3) -> Option<f64> {
        if !(self.lo.is_finite() && self.hi.is_finite()) {
            return Some(0.0);
        }
        let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
        for k in 0..3 {
            let (d, lo, hi) = (dir[k], self.lo[k], self.hi[k]);
            if d == 0.0 {
                if lo > 0.0 || hi < 0.0 {
                    return None;
                }
                continue;
            }
            let (a, b) = (lo / d, hi / d);
            let (near, far) = if a <= b { (a, b) } else { (b, a) };
            t0 = t0.max(near);
            t1 = t1.min(far);
        }
        (t0 <= t1).then_some(t0)
    }
}

/// The vertices named by `indices`.
/// Distance along unit `dir` (from the origin) at which it enters the sphere, if it does
/// (0 from inside). The radius is padded so f32 rounding of the centre never loses a hit.
fn sphere_entry(centre: [f32; 3], radius: f32, dir: DVec3) -> Option<f64> {
    let c = glam::Vec3::from(centre).as_dvec3();
    let r = radius as f64 * (1.0 + 1e-6) + 1e-6;
    let tc = c.dot(dir);
    let d2 = c.length_squared() - tc * tc;
    if d2 > r * r {
        return None;
    }
    Some((tc - (r * r - d2).max(0.0).sqrt()).max(0.0))
}

/// A beam direction with its reciprocal, for box entries without divisions.
struct Beam {
    dir: DVec3,
    dir32: glam::Vec3,
    inv: DVec3,
    all_nonzero: bool,
}

impl Beam {
    fn new(dir: DVec3) -> Beam {
        Beam { dir, dir32: dir.as_vec3(), inv: dir.recip(), all_nonzero: dir.x != 0.0 && dir.y != 0.0 && dir.z != 0.0 }
    }

    /// Whether the beam certainly misses triangle `[a, b, c]`: it lies strictly outside one of
    /// the planes through the origin and an edge, and strictly inside another (a beam through
    /// the triangle, either winding, lies on one side of all three). Computed in f32 with a
    /// tolerance of 1e-5 |p|_1 |q|_1 per edge (p, q), far above the rounding of the f32 cross
    /// and dot products (a few f32 epsilons times |p| |q|), so a beam the exact test hits is
    /// never dropped; the exact test decides the rest.
    #[inline]
    fn misses(&self, [a, b, c]: [glam::Vec3; 3]) -> bool {
        let d = self.dir32;
        let l1 = |v: glam::Vec3| v.x.abs() + v.y.abs() + v.z.abs();
        let (la, lb, lc) = (l1(a), l1(b), l1(c));
        let e = [(d.dot(a.cross(b)), la * lb), (d.dot(b.cross(c)), lb * lc), (d.dot(c.cross(a)), lc * la)];
        let (mut out, mut inside) = (false, false);
        for (v, scale) in e {
            let tol = 1e-5 * scale + 1e-30;
            out |= v < -tol;
            inside |= v > tol;
        }
        out && inside
    }
}

fn vertices_of<'a>(geom: &'a FrameGeometry, indices: &'a [u32]) -> impl Iterator<Item = [f32; 3]> + 'a {
    indices.iter().map(move |&i| geom.positions[i as usize])
}

/// Clusters per group: a beam tests a group's box before its clusters' boxes.
const GROUP_CLUSTERS: usize = 32;

/// One mesh's boxes: the whole mesh, its groups, its clusters.
#[derive(Clone, Debug)]
struct MeshBounds {
    mesh: Bounds,
    groups: Vec<Bounds>,
    clusters: Vec<Bounds>,
}

/// Per-mesh clusters of one frame, built on demand.
#[derive(Debug, Default)]
pub struct MeshClusters {
    /// Per mesh of the frame, once built.
    meshes: Vec<OnceLock<MeshBounds>>,
}

impl MeshClusters {
    /// Starts a new frame of `geom` (forgets every cluster; keeps nothing of the last frame).
    pub fn reset(&mut self, geom: &FrameGeometry) {
        self.meshes.clear();
        self.meshes.resize_with(geom.meshes.len(), OnceLock::new);
    }

    /// Builds the boxes of every mesh now, one mesh per task, instead of on first use.
    pub fn build_all(&self, geom: &FrameGeometry) {
        use rayon::prelude::*;
        (0..self.meshes.len()).into_par_iter().for_each(|k| {
            self.mesh(geom, k);
        });
    }

    fn mesh(&self, geom: &FrameGeometry, k: usize) -> &MeshBounds {
        self.meshes[k].get_or_init(|| {
            let m = &geom.meshes[k];
            let first = 3 * m.first_triangle as usize;
            let idx = &geom.indices[first..first + 3 * m.triangle_count as usize];
            let clusters: Vec<Bounds> = idx.chunks(3 * CLUSTER_TRIANGLES).map(|c| Bounds::of(vertices_of(geom, c))).collect();
            let groups: Vec<Bounds> = clusters.chunks(GROUP_CLUSTERS).map(Bounds::around).collect();
            MeshBounds { mesh: Bounds::around(&groups), groups, clusters }
        })
    }

    /// The nearest hit of `dir` over every mesh of `geom` (ties: smaller triangle), exactly the
    /// brute-force answer.
    pub fn cast(&self, geom: &FrameGeometry, dir: DVec3, clusters: &mut Vec<(f64, u32, u32)>) -> Option<(f64, u32)> {
        self.cast_seeded(geom, dir, &[], clusters)
    }

    /// [`Self::cast`], with the meshes in `seeds` cast first: their nearest hit bounds the
    /// rest, and any other mesh whose bounding sphere the beam enters only beyond that hit is
    /// skipped without building its boxes. The answer is the same as `cast`'s whatever the
    /// seeds; good seeds (the person a proxy shows on the beam) only make it cheaper.
    pub fn cast_seeded(
        &self,
        geom: &FrameGeometry,
        dir: DVec3,
        seeds: &[u32],
        clusters: &mut Vec<(f64, u32, u32)>,
    ) -> Option<(f64, u32)> {
        let ray = RayPre::new(dir)?;
        let beam = Beam::new(dir);
        let mut best = (f64::INFINITY, u32::MAX);
        for &k in seeds {
            self.cast_mesh(geom, &beam, &ray, k as usize, &mut best, clusters);
        }
        for (k, m) in geom.meshes.iter().enumerate() {
            if m.triangle_count == 0 || seeds.contains(&(k as u32)) {
                continue;
            }
            if sphere_entry(m.centre, m.radius, dir).is_some_and(|e| e <= best.0) {
                self.cast_mesh(geom, &beam, &ray, k, &mut best, clusters);
            }
        }
        (best.1 != u32::MAX).then_some(best)
    }

    /// Folds the nearest hit of mesh `k` into `best` (ties: smaller triangle), visiting its
    /// clusters nearest entry first and stopping at the first one that enters beyond `best`.
    fn cast_mesh(&self, geom: &FrameGeometry, beam: &Beam, ray: &RayPre, k: usize, best: &mut (f64, u32), clusters: &mut Vec<(f64, u32, u32)>) {
        let m = &geom.meshes[k];
        if m.triangle_count == 0 {
            return;
        }
        let s = self.mesh(geom, k);
        if s.mesh.entry_beam(beam).is_none_or(|e| e > best.0) {
            return;
        }
        // Front to back: the groups the beam enters, nearest first; within each, its clusters
        // nearest first; anything entered beyond the best hit so far is skipped.
        clusters.clear();
        for (g, group) in s.groups.iter().enumerate() {
            if let Some(e) = group.entry_beam(beam) {
                if e <= best.0 {
                    clusters.push((e, k as u32, g as u32));
                }
            }
        }
        let groups = clusters.len();
        clusters[..groups].sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.2.cmp(&b.2)));
        for gi in 0..groups {
            let (g_entry, _, g) = clusters[gi];
            if g_entry > best.0 {
                break;
            }
            let first = g as usize * GROUP_CLUSTERS;
            let end = (first + GROUP_CLUSTERS).min(s.clusters.len());
            for c in first..end {
                if let Some(e) = s.clusters[c].entry_beam(beam) {
                    if e <= best.0 {
                        clusters.push((e, k as u32, c as u32));
                    }
                }
            }
            clusters[groups..].sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.2.cmp(&b.2)));
            for ci in groups..clusters.len() {
                let (entry, _, c) = clusters[ci];
                if entry > best.0 {
                    break;
                }
                let first = m.first_triangle + c * CLUSTER_TRIANGLES as u32;
                let end = (first + CLUSTER_TRIANGLES as u32).min(m.first_triangle + m.triangle_count);
                for t in first..end {
                    if beam.misses(geom.triangle(t)) {
                        continue;
                    }
                    if let Some(r) = intersect_pre(ray, &geom.triangle_f64(t), !m.double_sided) {
                        if better(r, t, best.0, best.1) {
                            *best = (r, t);
                        }
                    }
                }
            }
            clusters.truncate(groups);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::raycast::cast_brute_force;

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
            // Whatever meshes seed the cast, the answer is the same.
            let seeds: Vec<u32> = (0..6u32).filter(|m| (k as u32 >> m) & 1 == 1).take(k % 4).collect();
            let seeded = clusters.cast_seeded(&geom, dir, &seeds, &mut scratch);
            assert_eq!(seeded, want.is_hit().then_some((want.range_m, want.triangle)), "beam {k}, seeds {seeds:?}");
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
    fn a_box_entry_is_never_beyond_its_surface() {
        let s = Bounds::of([[10.0f32, 0.0, 0.0], [12.0, 0.0, 0.0], [11.0, 1.0, 0.0]].into_iter());
        assert!(Bounds::around(&[s]).lo.cmple(s.lo).all());
        let e = s.entry(DVec3::X).unwrap();
        assert!(e <= 10.0 && e > 9.99, "{e}");
        assert!(s.entry(-DVec3::X).is_none());
        assert!(s.entry(DVec3::Y).is_none());
        // A flat box around the sensor (a floor under it): entered only where the beam reaches it.
        let floor = Bounds::of([[-20.0f32, -20.0, -1.0], [20.0, 20.0, -1.0]].into_iter());
        let down = DVec3::new(1.0, 0.0, -1.0).normalize();
        let e = floor.entry(down).unwrap();
        assert!((e - 2f64.sqrt()).abs() < 1e-6, "{e}");
        assert!(floor.entry(DVec3::X).is_none());
    }
}
