//! Casting through the BVH of `bvh.rs`: iterative traversal of the two levels with a fixed
//! stack, near child first, pruning by the current best range (ties kept, so that the result
//! equals brute force bit for bit); the casts over ray sets (`cast`, `cast_with_filter`,
//! `cast_frame`), parallel over rays; and `cast_brute_force`, the referee that tests every
//! triangle with the same intersection test and tie rule (`triangle.rs`) and no tree at all.

use super::bvh::{Bvh, Node, Tlas, COUNT_MASK, CULL_BIT};
use crate::backend::triangle::{better, intersect_pre, Hit, RayPre};
use crate::geometry::{FrameGeometry, MeshRange};
use glam::DVec3;
use rayon::prelude::*;

/// Marks a stack entry / node reference as bottom-level.
const BLAS_BIT: u32 = 1 << 31;
/// Traversal stack: top + bottom depth is at most 2 * (48 + 32).
const STACK_SIZE: usize = 192;

impl Bvh {
    /// First hit of one ray (unit `dir`) within `max_range_m`, over the meshes of `tlas`.
    fn trace(&self, tlas: &Tlas, dir: DVec3, max_range_m: f64) -> Hit {
        let Some(ray) = Ray::new(dir) else { return Hit::NONE };
        if !(max_range_m > 0.0) || tlas.nodes.is_empty() {
            return Hit::NONE;
        }
        let mut best_t = max_range_m;
        let mut best_tri = u32::MAX;
        if ray.entry(&tlas.nodes[0], best_t) == f64::INFINITY {
            return Hit::NONE;
        }
        let mut stack = [(0u32, 0f64); STACK_SIZE];
        let mut sp = 0usize;
        let mut cur = 0u32;
        loop {
            let blas = cur & BLAS_BIT != 0;
            let arr: &[Node] = if blas { &self.nodes } else { &tlas.nodes };
            let node = &arr[(cur & !BLAS_BIT) as usize];
            if node.b == 0 {
                let c = node.a as usize;
                let t0 = ray.entry(&arr[c], best_t);
                let t1 = ray.entry(&arr[c + 1], best_t);
                let flag = cur & BLAS_BIT;
                let (near, tn, far, tf) =
                    if t0 <= t1 { (c, t0, c + 1, t1) } else { (c + 1, t1, c, t0) };
                if tn != f64::INFINITY {
                    if tf != f64::INFINITY {
                        stack[sp] = (far as u32 | flag, tf);
                        sp += 1;
                    }
                    cur = near as u32 | flag;
                    continue;
                }
            } else if !blas {
                cur = self.meshes[node.a as usize].root | BLAS_BIT;
                continue;
            } else {
                let first = node.a as usize;
                let count = (node.b & COUNT_MASK) as usize;
                let cull = node.b & CULL_BIT != 0;
                for s in first..first + count {
                    let v = &self.verts[s];
                    let tri = [
                        DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64),
                        DVec3::new(v[3] as f64, v[4] as f64, v[5] as f64),
                        DVec3::new(v[6] as f64, v[7] as f64, v[8] as f64),
                    ];
                    if let Some(t) = intersect_pre(&ray.pre, &tri, cull) {
                        let id = self.ids[s];
                        if better(t, id, best_t, best_tri) {
                            best_t = t;
                            best_tri = id;
                        }
                    }
                }
            }
            // Pop the next node still in reach.
            loop {
                if sp == 0 {
                    return Hit::from_best(best_t, best_tri);
                }
                sp -= 1;
                let (n, t) = stack[sp];
                if t <= best_t {
                    cur = n;
                    break;
                }
            }
        }
    }

    /// First hit of a single ray over all meshes (see `cast`).
    pub fn trace_ray(&self, dir: DVec3, max_range_m: f64) -> Hit {
        self.trace(&self.tlas, dir, max_range_m)
    }
}

/// A ray from the origin: watertight constants and slab-test reciprocals.
struct Ray {
    pre: RayPre,
    inv: [f64; 3],
    neg: [bool; 3],
}

impl Ray {
    fn new(dir: DVec3) -> Option<Ray> {
        let pre = RayPre::new(dir)?;
        let inv = [1.0 / dir.x, 1.0 / dir.y, 1.0 / dir.z];
        let neg = [inv[0] < 0.0, inv[1] < 0.0, inv[2] < 0.0];
        Some(Ray { pre, inv, neg })
    }

    /// Entry parameter of the (padded) box, or infinity when the ray misses it before
    /// `t_best`. A zero direction component gives 0 * inf = NaN on a slab boundary through
    /// the origin; `f64::max`/`min` drop NaN, which treats the boundary as inside (closed).
    #[inline(always)]
    fn entry(&self, n: &Node, t_best: f64) -> f64 {
        let mut tn = 0.0f64;
        let mut tf = t_best;
        for k in 0..3 {
            let (near, far) = if self.neg[k] { (n.hi[k], n.lo[k]) } else { (n.lo[k], n.hi[k]) };
            tn = tn.max(near as f64 * self.inv[k]);
            tf = tf.min(far as f64 * self.inv[k]);
        }
        if tn <= tf * (1.0 + 4.0 * f64::EPSILON) {
            tn
        } else {
            f64::INFINITY
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Casting
// ---------------------------------------------------------------------------------------------

/// Casts `dirs` (unit directions from the sensor origin, e.g. `Sensor::beam_dirs()`) against
/// all meshes of `geom` with the prebuilt `bvh`: the nearest hit per ray with range
/// `<= max_range_m` (ties: smaller triangle index). Parallel over rays (rayon); the result
/// does not depend on the thread count. Panics if `bvh` was built for another geometry.
pub fn cast(geom: &FrameGeometry, bvh: &Bvh, dirs: &[DVec3], max_range_m: f64) -> Vec<Hit> {
    bvh.check(geom);
    cast_tlas(bvh, &bvh.tlas, dirs, max_range_m)
}

/// Like `cast`, restricted to the meshes for which `filter` is true, e.g. humans only
/// (`|m| m.instance > 0`) or background only (`|m| m.instance == 0`). Reuses `bvh`; only
/// the small top level over the kept meshes is rebuilt.
pub fn cast_with_filter(
    geom: &FrameGeometry,
    bvh: &Bvh,
    dirs: &[DVec3],
    max_range_m: f64,
    filter: impl Fn(&MeshRange) -> bool,
) -> Vec<Hit> {
    bvh.check(geom);
    let tlas = bvh.build_tlas(|k| filter(&geom.meshes[k as usize]));
    cast_tlas(bvh, &tlas, dirs, max_range_m)
}

fn cast_tlas(bvh: &Bvh, tlas: &Tlas, dirs: &[DVec3], max_range_m: f64) -> Vec<Hit> {
    dirs.par_iter().with_min_len(64).map(|&d| bvh.trace(tlas, d, max_range_m)).collect()
}

/// Builds the BVH of `geom` and casts `dirs` (see `cast`).
pub fn cast_frame(geom: &FrameGeometry, dirs: &[DVec3], max_range_m: f64) -> Vec<Hit> {
    let bvh = Bvh::build(geom);
    cast(geom, &bvh, dirs, max_range_m)
}

/// Brute force over every triangle of the meshes kept by `filter` (no BVH): the referee of
/// the referee. Same intersection function and tie rule as `cast`, so the results are equal
/// bit for bit. Parallel over rays.
pub fn cast_brute_force(
    geom: &FrameGeometry,
    dirs: &[DVec3],
    max_range_m: f64,
    filter: impl Fn(&MeshRange) -> bool + Sync,
) -> Vec<Hit> {
    dirs.par_iter()
        .map(|&d| {
            let Some(r) = RayPre::new(d) else { return Hit::NONE };
            if !(max_range_m > 0.0) {
                return Hit::NONE;
            }
            let mut best_t = max_range_m;
            let mut best_tri = u32::MAX;
            for m in geom.meshes.iter().filter(|m| filter(m)) {
                for t in m.first_triangle..m.first_triangle + m.triangle_count {
                    if let Some(x) = intersect_pre(&r, &geom.triangle_f64(t), !m.double_sided) {
                        if better(x, t, best_t, best_tri) {
                            best_t = x;
                            best_tri = t;
                        }
                    }
                }
            }
            Hit::from_best(best_t, best_tri)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::raycast::test_support::{geom_of, same, soup};

    /// The BVH returns exactly (bit for bit, incl. ties) what the brute force returns, for
    /// all meshes and with mesh filters, for several seeds and max ranges.
    #[test]
    fn bvh_equals_brute_force() {
        for seed in 10..14 {
            let (g, dirs) = soup(seed, 1200);
            let bvh = Bvh::build(&g);
            assert_eq!(bvh.triangle_count(), g.triangle_count() as usize);
            for max in [1e9, 15.0] {
                let a = cast(&g, &bvh, &dirs, max);
                let b = cast_brute_force(&g, &dirs, max, |_| true);
                same(&a, &b).unwrap_or_else(|e| panic!("seed {seed} max {max}: {e}"));
                assert!(a.iter().filter(|h| h.is_hit()).count() > dirs.len() / 10);
                let pred = |m: &MeshRange| m.instance % 2 == 0;
                let a = cast_with_filter(&g, &bvh, &dirs, max, pred);
                let b = cast_brute_force(&g, &dirs, max, pred);
                same(&a, &b).unwrap_or_else(|e| panic!("seed {seed} filtered: {e}"));
            }
        }
    }

    /// Humans-only and background-only casts compose to the full cast.
    #[test]
    fn filters_compose() {
        let (g, dirs) = soup(20, 2000);
        let bvh = Bvh::build(&g);
        let all = cast(&g, &bvh, &dirs, 1e9);
        let hum = cast_with_filter(&g, &bvh, &dirs, 1e9, |m| m.instance > 0);
        let bg = cast_with_filter(&g, &bvh, &dirs, 1e9, |m| m.instance == 0);
        for k in 0..dirs.len() {
            let pick = match (hum[k].is_hit(), bg[k].is_hit()) {
                (false, _) => bg[k],
                (true, false) => hum[k],
                (true, true) => {
                    if better(hum[k].range_m, hum[k].triangle, bg[k].range_m, bg[k].triangle) {
                        hum[k]
                    } else {
                        bg[k]
                    }
                }
            };
            assert_eq!(pick, all[k]);
            if hum[k].is_hit() {
                assert!(hum[k].instance(&g) > 0);
            }
        }
        let none = cast_with_filter(&g, &bvh, &dirs, 1e9, |_| false);
        assert!(none.iter().all(|h| *h == Hit::NONE));
    }

    #[test]
    fn empty_geometry_and_empty_meshes() {
        let g = FrameGeometry::default();
        assert_eq!(cast_frame(&g, &[DVec3::X], 100.0), vec![Hit::NONE]);
        let p = [[4.0, 1.0, -1.0], [4.0, 0.0, 1.0], [4.0, -1.0, -1.0]];
        let g = geom_of(&[(&p, &[], 0, true), (&p, &[0, 1, 2], 3, true), (&p, &[], 0, true)]);
        let h = cast_frame(&g, &[DVec3::X, -DVec3::X], 100.0);
        assert_eq!(h, vec![Hit { range_m: 4.0, triangle: 0 }, Hit::NONE]);
        assert_eq!(h[0].instance(&g), 3);
    }
}
