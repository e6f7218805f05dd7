//! Refit across frames (`BvhCache::build_or_refit`): a mesh with a topology key (its
//! `Arc<Adjacency>` identity, with its instance and rank) keeps the bottom-level tree built
//! at its first sight (`bvh.rs`); later frames only rewrite its triangles and recompute its
//! boxes bottom-up (O(n), parallel over meshes), and rebuild it when the summed box area has
//! more than doubled. The hits never depend on the tree shape, so they stay bit-identical to
//! a fresh build and to brute force; only the per-frame build time changes.

use super::bvh::{pad_hi, pad_lo, slot_arrays, slot_jobs, Aabb, Blas, Bvh, Node, COUNT_MASK};
use crate::geometry::{Adjacency, FrameGeometry};
use glam::Vec3A;
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::Arc;

impl Blas {
    /// Recomputes every box bottom-up from the slot vertices `verts` (this mesh's slots);
    /// returns the sum of the node half areas. Children always follow their parent in the
    /// node array, so one reverse sweep sees every child before its parent. Boxes are the
    /// same (incl. padding) as a fresh build of the same layout would give.
    fn refit(&mut self, verts: &[[f32; 9]]) -> f64 {
        let n = self.nodes.len();
        if self.boxes.len() != n {
            self.boxes.clear();
            self.boxes.resize(n, Aabb::EMPTY); // every entry is written below before it is read
        }
        let mut area = 0.0f64;
        for i in (0..n).rev() {
            let node = self.nodes[i];
            let b = if node.b == 0 {
                let c = node.a as usize;
                debug_assert!(c > i);
                self.boxes[c].union(self.boxes[c + 1])
            } else {
                let first = node.a as usize;
                let count = (node.b & COUNT_MASK) as usize;
                let mut b = Aabb::EMPTY;
                for v in &verts[first..first + count] {
                    let a = Vec3A::new(v[0], v[1], v[2]);
                    let bb = Vec3A::new(v[3], v[4], v[5]);
                    let c = Vec3A::new(v[6], v[7], v[8]);
                    b.grow(a.min(bb).min(c), a.max(bb).max(c));
                }
                b
            };
            self.boxes[i] = b;
            let nd = &mut self.nodes[i];
            nd.lo = pad_lo(b.lo);
            nd.hi = pad_hi(b.hi);
            area += b.half_area() as f64;
        }
        area
    }
}

/// A refit tree is rebuilt when its summed node area grows beyond this factor of the
/// area right after its build (bounds the quality loss; never affects the result).
const REFIT_MAX_AREA_GROWTH: f64 = 2.0;
/// A cached tree not used for this many `build_or_refit` calls is dropped.
const CACHE_MAX_AGE: u64 = 64;

/// Cache key of a mesh: the identity of its topology (`Arc<Adjacency>` pointer; the entry
/// holds a clone of the `Arc`, so the pointer cannot be reused while the entry lives), its
/// instance and its rank among the meshes of the frame with the same pointer and instance.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
struct CacheKey {
    topology: usize,
    instance: u32,
    rank: u32,
}

struct CacheEntry {
    _topology: Arc<Adjacency>,
    triangle_count: u32,
    double_sided: bool,
    blas: Blas,
    last_used: u64,
}

/// Counters of `BvhCache::build_or_refit` (bottom-level trees).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BvhCacheStats {
    /// Trees built for a keyed mesh (first sight, changed topology, or quality rebuild).
    pub builds: u64,
    /// Trees reused with only their boxes recomputed.
    pub refits: u64,
    /// Of `builds`: rebuilds because a refit tree's area grew too much.
    pub quality_rebuilds: u64,
    /// Trees built for meshes without a topology key (not cached).
    pub uncached: u64,
}

/// Bottom-level trees kept across frames: a mesh with a topology key (its
/// `FrameGeometry::adjacency` entry, whose `Arc` identity stands for its index buffer) reuses
/// the tree built at its first sight, and only its boxes are recomputed from the new vertices
/// (O(n)). Meshes without adjacency are built fresh each time; the top level is always
/// rebuilt. The result of `cast` does not depend on the cache state (traversal is exact for
/// any tree shape); the tree quality may degrade with the pose, and a tree whose summed box
/// area more than doubles is rebuilt.
pub struct BvhCache {
    entries: HashMap<CacheKey, CacheEntry>,
    bvh: Bvh,
    calls: u64,
    stats: BvhCacheStats,
    enabled: bool,
}

impl Default for BvhCache {
    fn default() -> Self {
        BvhCache::new()
    }
}

impl BvhCache {
    pub fn new() -> BvhCache {
        BvhCache { entries: HashMap::new(), bvh: Bvh::default(), calls: 0, stats: BvhCacheStats::default(), enabled: true }
    }

    /// A cache that never reuses trees (every call builds like `Bvh::build`), for comparison.
    pub fn disabled() -> BvhCache {
        BvhCache { enabled: false, ..BvhCache::new() }
    }

    pub fn stats(&self) -> BvhCacheStats {
        self.stats
    }

    /// The BVH of the last `build_or_refit`.
    pub fn bvh(&self) -> &Bvh {
        &self.bvh
    }

    /// The BVH of `geom`: cached bottom-level trees refit, others built (parallel over meshes).
    pub fn build_or_refit(&mut self, geom: &FrameGeometry) -> &Bvh {
        self.calls += 1;
        let now = self.calls;
        // Keys, and the cached entries taken out of the map (reinserted below).
        let mut seen: HashMap<(usize, u32), u32> = HashMap::new();
        let mut taken: Vec<Option<(CacheKey, Option<CacheEntry>)>> = Vec::with_capacity(geom.meshes.len());
        for (k, m) in geom.meshes.iter().enumerate() {
            let topo = geom.adjacency.get(k).and_then(|a| a.as_ref());
            match topo {
                Some(a) if self.enabled && m.triangle_count > 0 => {
                    let p = Arc::as_ptr(a) as usize;
                    let rank = seen.entry((p, m.instance)).or_insert(0);
                    let key = CacheKey { topology: p, instance: m.instance, rank: *rank };
                    *rank += 1;
                    let e = self.entries.remove(&key).filter(|e| {
                        e.triangle_count == m.triangle_count && e.double_sided == m.double_sided
                    });
                    taken.push(Some((key, e)));
                }
                _ => taken.push(None),
            }
        }
        // Reuse the last frame's arrays (no page faults, no zeroing in steady state).
        let old = std::mem::take(&mut self.bvh);
        let (mut verts, mut ids) = slot_arrays(geom, old.verts, old.ids);
        let jobs = slot_jobs(geom, &mut verts, &mut ids);
        // (mesh, tree, key, how: 0 built uncached, 1 built, 2 refit, 3 quality rebuild)
        let done: Vec<(usize, Blas, Option<CacheKey>, u8)> = jobs
            .into_par_iter()
            .zip(taken)
            .filter(|((_, v, _), _)| !v.is_empty())
            .map(|((k, v, i), t)| match t {
                None => {
                    let blas = Blas::build(geom, k);
                    blas.fill_slots(geom, k, v, i);
                    (k, blas, None, 0)
                }
                Some((key, Some(e))) => {
                    let mut blas = e.blas;
                    blas.fill_slots(geom, k, v, i);
                    let area = blas.refit(v);
                    if area <= REFIT_MAX_AREA_GROWTH * blas.built_area {
                        return (k, blas, Some(key), 2);
                    }
                    let mut blas = Blas::build(geom, k);
                    blas.fill_slots(geom, k, v, i);
                    blas.built_area = blas.refit(v);
                    (k, blas, Some(key), 3)
                }
                Some((key, None)) => {
                    let mut blas = Blas::build(geom, k);
                    blas.fill_slots(geom, k, v, i);
                    blas.built_area = blas.refit(v);
                    (k, blas, Some(key), 1)
                }
            })
            .collect();
        let trees: Vec<(usize, &[Node])> = done.iter().map(|(k, b, _, _)| (*k, &b.nodes[..])).collect();
        self.bvh = Bvh::assemble(geom, &trees, verts, ids, old.nodes);
        for (k, blas, key, how) in done {
            match how {
                0 => self.stats.uncached += 1,
                1 => self.stats.builds += 1,
                2 => self.stats.refits += 1,
                _ => {
                    self.stats.builds += 1;
                    self.stats.quality_rebuilds += 1;
                }
            }
            if let Some(key) = key {
                let m = &geom.meshes[k];
                let topology = geom.adjacency[k].clone().expect("keyed mesh has adjacency");
                self.entries.insert(
                    key,
                    CacheEntry {
                        _topology: topology,
                        triangle_count: m.triangle_count,
                        double_sided: m.double_sided,
                        blas,
                        last_used: now,
                    },
                );
            }
        }
        self.entries.retain(|_, e| e.last_used + CACHE_MAX_AGE > now);
        &self.bvh
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::raycast::test_support::{dv, f32v, octasphere, rotation, same, tess_cube, Rng};
    use crate::backend::raycast::{cast, cast_brute_force, cast_with_filter};
    use glam::DVec3;

    /// A smooth non-rigid deformation (twist about z, bend, travelling wave), step `s`.
    fn deform(p: &[[f32; 3]], centre: DVec3, s: f64) -> Vec<[f32; 3]> {
        p.iter()
            .map(|&v| {
                let q = dv(v) - centre;
                let ang = 0.6 * s.sin() * q.z;
                let (sn, cs) = ang.sin_cos();
                let mut r = DVec3::new(cs * q.x - sn * q.y, sn * q.x + cs * q.y, q.z);
                r.x += 0.3 * (1.3 * s).cos() * q.z * q.z;
                r += DVec3::new(0.15, 0.1, 0.2) * (3.0 * q.y + 2.0 * q.x + s).sin();
                r *= 1.0 + 0.2 * (s + q.z).sin();
                f32v(r + centre)
            })
            .collect()
    }

    /// Rays at random plus ones aimed exactly at vertices and edge midpoints of `g`.
    fn refit_rays(g: &FrameGeometry, rng: &mut Rng, n: usize) -> Vec<DVec3> {
        let mut dirs: Vec<DVec3> = (0..n).map(|_| rng.unit()).collect();
        for _ in 0..n {
            let t = rng.below(g.triangle_count() as usize) as u32;
            let tri = g.triangle_f64(t);
            let a = match rng.below(3) {
                0 => tri[0],
                1 => (tri[0] + tri[1]) * 0.5,
                _ => (tri[0] + tri[1] + tri[2]) / 3.0,
            };
            dirs.push(a);
            dirs.push(a.normalize());
        }
        dirs
    }

    /// Deformed meshes, refit frame after frame: the cast equals the brute force (and a
    /// fresh build) bit for bit; keyed meshes are built once and refit after.
    #[test]
    fn refit_equals_brute_force_under_deformation() {
        let mut rng = Rng(77);
        let rot = rotation(&mut rng);
        let c1 = DVec3::new(6.0, 1.0, -0.5);
        let c2 = DVec3::new(-5.0, 3.0, 0.5);
        let c3 = DVec3::new(1.0, -7.0, 0.0);
        let (p1, i1) = octasphere(40, DVec3::new(1.0, 0.7, 1.8), c1); // 12,800 (parallel build)
        let (p2, i2) = tess_cube(24, rot, c2);
        let (p3, i3) = octasphere(12, DVec3::splat(1.2), c3);
        let a1 = Arc::new(Adjacency::build(&i1));
        let a2 = Arc::new(Adjacency::build(&i2));
        let mut cache = BvhCache::new();
        for step in 0..6 {
            let s = step as f64 * 0.9;
            let q1 = deform(&p1, c1, s);
            let q2 = deform(&p2, c2, -s);
            let q3 = deform(&p3, c3, 2.0 * s);
            let mut g = FrameGeometry::default();
            g.push_mesh_with_adjacency(&q1, &i1, 1, false, Some(a1.clone()));
            g.push_mesh_with_adjacency(&q2, &i2, 0, true, Some(a2.clone()));
            g.push_mesh(&q3, &i3, 2, false); // no key: built fresh
            let dirs = refit_rays(&g, &mut rng, 4000);
            let bvh = cache.build_or_refit(&g);
            assert_eq!(bvh.triangle_count(), g.triangle_count() as usize);
            for max in [1e9, 7.0] {
                let a = cast(&g, bvh, &dirs, max);
                let b = cast_brute_force(&g, &dirs, max, |_| true);
                same(&a, &b).unwrap_or_else(|e| panic!("step {step} max {max}: {e}"));
                same(&a, &cast(&g, &Bvh::build(&g), &dirs, max)).unwrap();
                if max > 1e3 {
                    assert!(a.iter().filter(|h| h.is_hit()).count() > dirs.len() / 2);
                }
            }
            let f = cast_with_filter(&g, cache.bvh(), &dirs, 1e9, |m| m.instance == 1);
            same(&f, &cast_brute_force(&g, &dirs, 1e9, |m| m.instance == 1)).unwrap();
            let st = cache.stats();
            assert_eq!(st.builds, 2, "step {step}: {st:?}");
            assert_eq!(st.refits, 2 * step as u64, "step {step}: {st:?}");
            assert_eq!(st.uncached, step as u64 + 1);
        }
    }

    /// A wild deformation (vertices scrambled): still exact; the tree is rebuilt once its
    /// area has grown too much.
    #[test]
    fn refit_survives_scrambled_vertices() {
        let mut rng = Rng(78);
        let (p, i) = octasphere(20, DVec3::new(1.0, 1.0, 1.0), DVec3::new(4.0, 0.0, 0.0));
        let a = Arc::new(Adjacency::build(&i));
        // One frame: the sphere as built (step 0) or with its vertices scrambled, cast through
        // the cache and checked against brute force.
        let frame = |step: u32, double_sided: bool, cache: &mut BvhCache, rng: &mut Rng| {
            let q: Vec<[f32; 3]> = if step == 0 {
                p.clone()
            } else {
                p.iter().map(|_| f32v(DVec3::new(4.0, 0.0, 0.0) + rng.unit() * 1.5 * rng.f())).collect()
            };
            let mut g = FrameGeometry::default();
            g.push_mesh_with_adjacency(&q, &i, 1, double_sided, Some(a.clone()));
            let dirs = refit_rays(&g, rng, 3000);
            let hits = cast(&g, cache.build_or_refit(&g), &dirs, 1e9);
            same(&hits, &cast_brute_force(&g, &dirs, 1e9, |_| true)).unwrap();
        };
        let mut cache = BvhCache::new();
        for step in 0..4 {
            frame(step, step % 2 == 1, &mut cache, &mut rng);
        }
        // double_sided changes every step: every step rebuilds (the cull flag lives in the leaves).
        assert_eq!(cache.stats().builds, 4);
        let mut cache = BvhCache::new();
        for step in 0..3 {
            frame(step, false, &mut cache, &mut rng);
        }
        let st = cache.stats();
        assert!(st.quality_rebuilds >= 1, "{st:?}");
        assert_eq!(st.builds + st.refits, 3);
    }

    /// A new topology key (another `Arc<Adjacency>`, or another instance) is built, not refit;
    /// two meshes with the same key in one frame get separate trees; unused trees age out.
    #[test]
    fn changed_topology_key_rebuilds() {
        let (p, i) = octasphere(10, DVec3::splat(1.0), DVec3::new(5.0, 0.0, 0.0));
        let (p2, _) = octasphere(10, DVec3::splat(1.0), DVec3::new(-5.0, 0.0, 0.0));
        let a = Arc::new(Adjacency::build(&i));
        let b = Arc::new(Adjacency::build(&i));
        let mut rng = Rng(79);
        let mut cache = BvhCache::new();
        let mut check = |meshes: &[(&[[f32; 3]], &Arc<Adjacency>, u32)], cache: &mut BvhCache| {
            let mut g = FrameGeometry::default();
            for (q, adj, inst) in meshes {
                g.push_mesh_with_adjacency(q, &i, *inst, false, Some((*adj).clone()));
            }
            let dirs = refit_rays(&g, &mut rng, 1000);
            let hits = cast(&g, cache.build_or_refit(&g), &dirs, 1e9);
            same(&hits, &cast_brute_force(&g, &dirs, 1e9, |_| true)).unwrap();
            cache.stats()
        };
        let s = check(&[(&p, &a, 1)], &mut cache);
        assert_eq!((s.builds, s.refits), (1, 0));
        let s = check(&[(&p, &a, 1)], &mut cache);
        assert_eq!((s.builds, s.refits), (1, 1));
        let s = check(&[(&p, &b, 1)], &mut cache); // new key
        assert_eq!((s.builds, s.refits), (2, 1));
        let s = check(&[(&p, &b, 2)], &mut cache); // other instance
        assert_eq!((s.builds, s.refits), (3, 1));
        // Same key twice in a frame (same model, same instance): the second is a new tree,
        // and the far sphere refits the tree of the near one's first appearance.
        let s = check(&[(&p2, &b, 2), (&p, &b, 2)], &mut cache);
        assert_eq!((s.builds, s.refits), (4, 2));
        let s = check(&[(&p, &b, 2), (&p2, &b, 2)], &mut cache);
        assert_eq!((s.builds, s.refits), (4, 4));
        // Disabled: always built, never cached.
        let mut off = BvhCache::disabled();
        check(&[(&p, &a, 1)], &mut off);
        let s = check(&[(&p, &a, 1)], &mut off);
        assert_eq!((s.builds, s.refits, s.uncached), (0, 0, 2));
        // Aging: an entry unused for CACHE_MAX_AGE calls is dropped.
        let mut g = FrameGeometry::default();
        g.push_mesh_with_adjacency(&p, &i, 1, false, Some(a.clone()));
        for _ in 0..CACHE_MAX_AGE {
            cache.build_or_refit(&g);
        }
        assert_eq!(cache.entries.len(), 1);
    }
}
