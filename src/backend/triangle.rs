//! The one ray/triangle test of the crate: the watertight test of Woop, Benthin and Wald
//! (JCGT 2(1), 2013) for rays from the origin, in f64 on the f32 vertices widened exactly,
//! with exact-sign edge functions (`exact.rs`), so that a ray through a shared edge or vertex
//! of a closed mesh never slips between its triangles. Also the first-hit result [`Hit`]
//! and the tie rule `better` (smaller range, then smaller triangle index).
//!
//! Every caster of `raycast` (the BVH traversal, the brute force, the beam and cluster
//! casters) calls this test and this tie rule, which is why their results agree bit for bit.
//! It is meant to stay the single triangle test of the crate: the raster refinement
//! (`src/resample.rs`, through `intersect_triangle` today) is to use it too, so that the
//! raster and ray-cast backends cannot drift apart on an edge or a tie.

use super::exact::{certainly_nonzero, diff_of_products};
use crate::geometry::FrameGeometry;
use glam::DVec3;

// ---------------------------------------------------------------------------------------------
// Watertight ray/triangle intersection
// ---------------------------------------------------------------------------------------------

/// Per-ray constants of the watertight test (axis permutation and shear).
#[derive(Clone, Copy, Debug)]
pub(crate) struct RayPre {
    kx: usize,
    ky: usize,
    kz: usize,
    sx: f64,
    sy: f64,
    sz: f64,
}

impl RayPre {
    /// None for a zero or non-finite direction (such a ray hits nothing).
    pub(crate) fn new(dir: DVec3) -> Option<RayPre> {
        if !dir.is_finite() {
            return None;
        }
        let d = dir.to_array();
        let a = dir.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        if d[kz] == 0.0 {
            return None;
        }
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        // Keep the winding: with this swap, det > 0 <=> dot(normal, dir) < 0 (front face).
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        Some(RayPre { kx, ky, kz, sx: d[kx] / d[kz], sy: d[ky] / d[kz], sz: 1.0 / d[kz] })
    }
}

/// True when the triangle has exactly zero area (collinear or repeated vertices).
#[inline]
fn is_degenerate(tri: &[DVec3; 3]) -> bool {
    let e1 = tri[1] - tri[0];
    let e2 = tri[2] - tri[0];
    let normal = [(e1.y, e2.z, e1.z, e2.y), (e1.z, e2.x, e1.x, e2.z), (e1.x, e2.y, e1.y, e2.x)];
    // One component the plain product proves nonzero settles it, before any exact expansion:
    // an axis-aligned triangle (a floor, a wall) has two components exactly 0, and the exact
    // sign of those is what the test spent its time on.
    if normal.iter().any(|&(p, q, r, s)| certainly_nonzero(p, q, r, s)) {
        return false;
    }
    normal.iter().all(|&(p, q, r, s)| diff_of_products(p, q, r, s) == 0.0)
}

#[inline(always)]
pub(crate) fn intersect_pre(r: &RayPre, tri: &[DVec3; 3], cull_back: bool) -> Option<f64> {
    let a = tri[0].to_array();
    let b = tri[1].to_array();
    let c = tri[2].to_array();
    let (kx, ky, kz) = (r.kx, r.ky, r.kz);
    // Vertices relative to the origin (= the vertices), sheared into ray space.
    let ax = a[kx] - r.sx * a[kz];
    let ay = a[ky] - r.sy * a[kz];
    let bx = b[kx] - r.sx * b[kz];
    let by = b[ky] - r.sy * b[kz];
    let cx = c[kx] - r.sx * c[kz];
    let cy = c[ky] - r.sy * c[kz];
    // Scaled barycentrics; exact signs, shared edges give exactly opposite values.
    let u = diff_of_products(cx, by, cy, bx);
    let v = diff_of_products(ax, cy, ay, cx);
    let w = diff_of_products(bx, ay, by, ax);
    let neg = u < 0.0 || v < 0.0 || w < 0.0;
    if cull_back {
        if neg {
            return None;
        }
    } else if neg && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 || det.is_nan() {
        return None; // edge-on (or degenerate) in ray space
    }
    let az = r.sz * a[kz];
    let bz = r.sz * b[kz];
    let cz = r.sz * c[kz];
    let t = (u * az + v * bz + w * cz) / det;
    if !(t > 0.0 && t.is_finite()) {
        return None;
    }
    if is_degenerate(tri) {
        return None;
    }
    Some(t)
}

/// Watertight ray/triangle intersection (Woop, Benthin, Wald 2013) for the ray from the
/// origin along `dir`, in f64. Returns the ray parameter `t > 0` of the hit (the distance for
/// a unit `dir`). A ray through a shared edge or vertex hits at least one of the triangles
/// sharing it. With `cull_back`, triangles whose front face (`dot((b-a) x (c-a), a) < 0`,
/// counter-clockwise seen from the origin) does not face the origin are ignored.
/// Zero-area triangles, a zero or non-finite `dir` and non-finite vertices never hit.
pub fn intersect_triangle(dir: DVec3, tri: &[DVec3; 3], cull_back: bool) -> Option<f64> {
    RayPre::new(dir).and_then(|r| intersect_pre(&r, tri, cull_back))
}

// ---------------------------------------------------------------------------------------------
// Results
// ---------------------------------------------------------------------------------------------

/// The first hit of one ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Range along the ray in metres (f64 ray parameter; exact widening of f32 vertices);
    /// 0 when there is no hit.
    pub range_m: f64,
    /// Global triangle index in the `FrameGeometry`; `u32::MAX` when there is no hit.
    pub triangle: u32,
}

impl Hit {
    /// No return.
    pub const NONE: Hit = Hit { range_m: 0.0, triangle: u32::MAX };

    /// True when the ray hit a triangle.
    pub fn is_hit(&self) -> bool {
        self.triangle != u32::MAX
    }

    /// Instance of the hit mesh (0 = background or no hit).
    pub fn instance(&self, geom: &FrameGeometry) -> u32 {
        if self.is_hit() {
            geom.mesh_of_triangle(self.triangle).instance
        } else {
            0
        }
    }

    pub(crate) fn from_best(t: f64, tri: u32) -> Hit {
        if tri == u32::MAX {
            Hit::NONE
        } else {
            Hit { range_m: t, triangle: tri }
        }
    }
}

/// The deterministic order of hits: smaller range, then smaller triangle index.
#[inline(always)]
pub(crate) fn better(t: f64, tri: u32, best_t: f64, best_tri: u32) -> bool {
    t < best_t || (t == best_t && tri < best_tri)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::raycast::test_support::{dv, f32v, geom_of, octasphere, rotation, same, tess_cube, Rng};
    use crate::backend::raycast::{cast, cast_brute_force, cast_frame, cast_with_filter, Bvh};
    use std::collections::HashMap;

    /// Whether `intersect_pre` (no culling) gets as far as its zero-area test for this ray and
    /// triangle: the signs, the ray-space determinant and the range all let it through.
    fn reaches_area_test(r: &RayPre, tri: &[DVec3; 3]) -> bool {
        let p = |v: DVec3| (v[r.kx] - r.sx * v[r.kz], v[r.ky] - r.sy * v[r.kz], r.sz * v[r.kz]);
        let ((ax, ay, az), (bx, by, bz), (cx, cy, cz)) = (p(tri[0]), p(tri[1]), p(tri[2]));
        let (u, v, w) = (diff_of_products(cx, by, cy, bx), diff_of_products(ax, cy, ay, cx), diff_of_products(bx, ay, by, ax));
        let mixed = (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0);
        let det = u + v + w;
        let t = (u * az + v * bz + w * cz) / det;
        !mixed && det != 0.0 && !det.is_nan() && t > 0.0 && t.is_finite()
    }

    fn flip(idx: &[u32]) -> Vec<u32> {
        idx.chunks(3).flat_map(|t| [t[0], t[2], t[1]]).collect()
    }

    fn front_facing(tri: &[DVec3; 3]) -> bool {
        (tri[1] - tri[0]).cross(tri[2] - tri[0]).dot(tri[0]) < 0.0
    }

    // ---- intersection: closed forms ------------------------------------------------------

    /// Plane x = 5 (two triangles, 2 km wide, facing the origin): range = 5 / dir.x within
    /// 1e-9 relative; from behind (x = -5, facing away) culled, hit when double-sided.
    #[test]
    fn plane_closed_form() {
        let s = 1000.0f32;
        let p = [[5.0, -s, -s], [5.0, s, -s], [5.0, s, s], [5.0, -s, s]];
        let mut idx = vec![0, 1, 2, 0, 2, 3];
        let tri0 = [dv(p[0]), dv(p[1]), dv(p[2])];
        if !front_facing(&tri0) {
            idx = flip(&idx);
        }
        let g = geom_of(&[(&p, &idx, 0, false)]);
        assert!(front_facing(&g.triangle_f64(0)) && front_facing(&g.triangle_f64(1)));
        let mut rng = Rng(1);
        let dirs: Vec<DVec3> = (0..20_000)
            .map(|_| loop {
                let d = rng.unit();
                if d.x > 0.05 {
                    break d;
                }
            })
            .collect();
        let hits = cast_frame(&g, &dirs, 1e9);
        for (d, h) in dirs.iter().zip(&hits) {
            let want = 5.0 / d.x;
            assert!(h.is_hit(), "{d:?}");
            assert!(((h.range_m - want) / want).abs() < 1e-9, "{d:?}: {} vs {want}", h.range_m);
            assert_eq!(intersect_triangle(*d, &g.triangle_f64(h.triangle), true), Some(h.range_m));
        }
        // Exactly along +x through the shared diagonal: hits.
        assert_eq!(cast_frame(&g, &[DVec3::X], 1e9)[0].range_m, 5.0);
        // Mirrored to x = -5 with the same winding: it faces away from the origin.
        let q: Vec<[f32; 3]> = p.iter().map(|v| [-v[0], v[1], v[2]]).collect();
        let back = geom_of(&[(&q, &idx, 0, false)]);
        assert!(cast_frame(&back, &[-DVec3::X], 1e9)[0] == Hit::NONE);
        let both = geom_of(&[(&q, &idx, 0, true)]);
        assert_eq!(cast_frame(&both, &[-DVec3::X], 1e9)[0].range_m, 5.0);
    }

    /// Box [-2,3]x[-1.5,2.5]x[-1,4] around the origin, wound inward (culled) and outward
    /// (double-sided): range = min over axes of the slab exit, within 1e-9 relative.
    #[test]
    fn box_closed_form() {
        let lo = DVec3::new(-2.0, -1.5, -1.0);
        let hi = DVec3::new(3.0, 2.5, 4.0);
        let rot = [DVec3::X, DVec3::Y, DVec3::Z];
        let (mut p, idx) = tess_cube(1, rot, DVec3::ZERO);
        for v in p.iter_mut() {
            for k in 0..3 {
                v[k] = if v[k] < 0.0 { lo[k] as f32 } else { hi[k] as f32 };
            }
        }
        let inward = flip(&idx);
        let g_in = geom_of(&[(&p, &inward, 0, false)]);
        let g_out_ds = geom_of(&[(&p, &idx, 0, true)]);
        let g_out_cull = geom_of(&[(&p, &idx, 0, false)]);
        let mut rng = Rng(2);
        let dirs: Vec<DVec3> = (0..20_000).map(|_| rng.unit()).collect();
        let a = cast_frame(&g_in, &dirs, 1e9);
        let b = cast_frame(&g_out_ds, &dirs, 1e9);
        let c = cast_frame(&g_out_cull, &dirs, 1e9);
        for (k, d) in dirs.iter().enumerate() {
            let mut want = f64::INFINITY;
            for ax in 0..3 {
                let t = if d[ax] > 0.0 { hi[ax] / d[ax] } else { lo[ax] / d[ax] };
                want = want.min(t);
            }
            for h in [a[k], b[k]] {
                assert!(((h.range_m - want) / want).abs() < 1e-9, "{d:?}: {h:?} vs {want}");
            }
            assert_eq!(c[k], Hit::NONE, "outward box seen from inside must be culled");
        }
    }

    #[test]
    fn back_face_culling() {
        // Counter-clockwise seen from the origin (looking along +x): front.
        // (y, z) seen looking along +x (y left, z up): right-bottom, top, left-bottom.
        let front = [DVec3::new(4.0, -1.0, -1.0), DVec3::new(4.0, 0.0, 1.0), DVec3::new(4.0, 1.0, -1.0)];
        assert!(front_facing(&front));
        assert_eq!(intersect_triangle(DVec3::X, &front, true), Some(4.0));
        assert_eq!(intersect_triangle(DVec3::X, &front, false), Some(4.0));
        let back = [front[0], front[2], front[1]];
        assert!(!front_facing(&back));
        assert_eq!(intersect_triangle(DVec3::X, &back, true), None);
        assert_eq!(intersect_triangle(DVec3::X, &back, false), Some(4.0));
        // Same through the BVH with the mesh flag.
        let p = [f32v(back[0]), f32v(back[1]), f32v(back[2])];
        let g = geom_of(&[(&p, &[0, 1, 2], 1, false)]);
        assert_eq!(cast_frame(&g, &[DVec3::X], 100.0)[0], Hit::NONE);
        let g = geom_of(&[(&p, &[0, 1, 2], 1, true)]);
        assert_eq!(cast_frame(&g, &[DVec3::X], 100.0)[0], Hit { range_m: 4.0, triangle: 0 });
        // Behind the origin or beyond max range: no hit.
        assert_eq!(intersect_triangle(-DVec3::X, &front, false), None);
        assert_eq!(cast_frame(&g, &[DVec3::X], 3.9)[0], Hit::NONE);
        assert_eq!(cast_frame(&g, &[DVec3::X], 4.0)[0].range_m, 4.0);
    }

    #[test]
    fn degenerate_triangles_never_hit() {
        let a = DVec3::new(4.0, -1.0, -1.0);
        let c = DVec3::new(4.0, 1.0, 1.0);
        let m = (a + c) * 0.5; // exactly collinear (dyadic)
        let cases = [
            [a, a, c],
            [a, c, c],
            [a, a, a],
            [a, m, c],
            [m, a, c],
            [DVec3::new(4.0, 0.0, -2.0), DVec3::new(4.0, 0.0, 0.0), DVec3::new(4.0, 0.0, 2.0)],
        ];
        // Rays through the degenerate triangle's points and around it.
        let mut dirs = vec![DVec3::X, a.normalize(), c.normalize(), m.normalize()];
        let mut rng = Rng(3);
        for _ in 0..2000 {
            dirs.push((DVec3::new(4.0, 0.0, 0.0) + rng.unit() * rng.range(0.0, 2.0)).normalize());
        }
        for tri in &cases {
            for d in &dirs {
                for cull in [false, true] {
                    assert_eq!(intersect_triangle(*d, tri, cull), None, "{tri:?} {d:?}");
                }
            }
        }
        // Exactly collinear triangles (dyadic vertices on a line) met by rays through a point of
        // their segment, from directions that are not: the shear into ray space rounds, so the
        // projected triangle can get a nonzero area and an edge-on test alone would let the ray
        // hit it; only the exact zero-area test refuses every one.
        let mut reached_area_test = 0;
        for _ in 0..20000 {
            let q = |rng: &mut Rng, lo: f64, hi: f64| (rng.range(lo, hi) * 1024.0).round() / 1024.0;
            let a = DVec3::new(q(&mut rng, 2.0, 9.0), q(&mut rng, -4.0, 4.0), q(&mut rng, -3.0, 3.0));
            let step = DVec3::new(q(&mut rng, -1.0, 1.0), q(&mut rng, -1.0, 1.0), q(&mut rng, -1.0, 1.0));
            let tri = [a, a + step, a + step * 3.0];
            let dir = (a + step * rng.range(0.1, 2.9)).normalize();
            let r = RayPre::new(dir).unwrap();
            for cull in [false, true] {
                assert_eq!(intersect_pre(&r, &tri, cull), None, "{tri:?} {dir:?}");
            }
            reached_area_test += usize::from(is_degenerate(&tri) && reaches_area_test(&r, &tri));
        }
        assert!(reached_area_test > 100, "only {reached_area_test} rays got past the edge-on test");
        // NaN / infinite vertices and zero / NaN directions: no hit, no NaN.
        let good = [DVec3::new(4.0, 1.0, -1.0), DVec3::new(4.0, 0.0, 1.0), DVec3::new(4.0, -1.0, -1.0)];
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            for k in 0..3 {
                let mut t = good;
                t[k].y = bad;
                for d in &dirs {
                    assert_eq!(intersect_triangle(*d, &t, false), None);
                }
            }
        }
        for d in [DVec3::ZERO, DVec3::NAN, DVec3::new(f64::INFINITY, 0.0, 0.0)] {
            assert_eq!(intersect_triangle(d, &good, false), None);
        }
        // Random degenerate soups through the BVH: nothing hits, ranges are never NaN.
        let mut pos = Vec::new();
        let mut idx = Vec::new();
        for _ in 0..500 {
            let p = DVec3::new(rng.range(1.0, 5.0), rng.range(-2.0, 2.0), rng.range(-2.0, 2.0));
            let q = p + DVec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), 0.0).round() * 0.25;
            let base = pos.len() as u32;
            pos.extend([f32v(p), f32v(q), f32v((p + q) * 0.5), f32v(p * 2.0 - q)]);
            idx.extend([base, base + 1, base + 2, base + 3, base, base + 1, base, base, base + 1]);
        }
        let g = geom_of(&[(&pos, &idx, 0, true)]);
        let hits = cast_frame(&g, &dirs, 100.0);
        assert!(hits.iter().all(|h| *h == Hit::NONE));
        let mut g2 = g.clone();
        g2.positions[0] = [f32::NAN, 1.0, 1.0];
        g2.positions[5] = [f32::INFINITY, 1.0, 1.0];
        let hits = cast_frame(&g2, &dirs, 100.0);
        assert!(hits.iter().all(|h| *h == Hit::NONE && !h.range_m.is_nan()));
    }

    // ---- watertightness ------------------------------------------------------------------

    /// Directions through every vertex, every edge midpoint (exact in f64) and every
    /// centroid of a mesh, relative to the origin; `keep` selects by the incident triangles.
    fn aimed_dirs(
        g: &FrameGeometry,
        keep: impl Fn(&[[DVec3; 3]]) -> bool,
    ) -> Vec<DVec3> {
        let mut by_vertex: HashMap<u32, Vec<u32>> = HashMap::new();
        let mut by_edge: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
        for t in 0..g.triangle_count() {
            let i = &g.indices[3 * t as usize..3 * t as usize + 3];
            for k in 0..3 {
                by_vertex.entry(i[k]).or_default().push(t);
                let (a, b) = (i[k], i[(k + 1) % 3]);
                by_edge.entry((a.min(b), a.max(b))).or_default().push(t);
            }
        }
        let tris = |ts: &[u32]| -> Vec<[DVec3; 3]> { ts.iter().map(|&t| g.triangle_f64(t)).collect() };
        let mut dirs = Vec::new();
        let mut vs: Vec<_> = by_vertex.into_iter().collect();
        vs.sort();
        for (v, ts) in vs {
            if keep(&tris(&ts)) {
                dirs.push(dv(g.positions[v as usize]));
            }
        }
        let mut es: Vec<_> = by_edge.into_iter().collect();
        es.sort();
        for ((a, b), ts) in es {
            assert_eq!(ts.len(), 2, "mesh not closed");
            if keep(&tris(&ts)) {
                dirs.push((dv(g.positions[a as usize]) + dv(g.positions[b as usize])) * 0.5);
            }
        }
        for t in 0..g.triangle_count() {
            let tri = g.triangle_f64(t);
            if keep(&[tri]) {
                dirs.push((tri[0] + tri[1] + tri[2]) / 3.0);
            }
        }
        dirs
    }

    /// Origin inside closed meshes (octasphere 32768 triangles centred and off-centre, wound
    /// inward and culled; rotated tessellated cube 24576 triangles): 100k random rays plus
    /// rays through every vertex, edge midpoint and centroid (non-unit, so t = 1 at the
    /// aimed point), rays in the coordinate planes (exactly through equator edges) and
    /// along the axes (exactly through vertices). Zero misses; aimed rays have t = 1 within
    /// 1e-9; random rays hit within the analytic shell.
    #[test]
    fn watertight_from_inside() {
        let mut rng = Rng(4);
        let rot = rotation(&mut rng);
        let cases: Vec<(&str, Vec<[f32; 3]>, Vec<u32>, f64, f64)> = vec![
            {
                let (p, i) = octasphere(64, DVec3::ONE, DVec3::ZERO);
                ("centred sphere", p, i, 0.9995, 1.0 + 1e-6)
            },
            {
                let (p, i) = octasphere(64, DVec3::new(2.0, 1.0, 0.5), DVec3::new(0.3, -0.2, 0.1));
                ("off-centre ellipsoid", p, i, 0.05, 3.0)
            },
            {
                let (p, i) = tess_cube(64, rot, DVec3::new(0.1, 0.2, -0.3));
                ("rotated cube", p, i, 0.3, 2.5)
            },
        ];
        for (name, p, i, rmin, rmax) in cases {
            let inward = flip(&i);
            let g = geom_of(&[(&p, &inward, 1, false)]);
            let bvh = Bvh::build(&g);
            let mut dirs: Vec<DVec3> = (0..100_000).map(|_| rng.unit()).collect();
            for k in 0..20_000 {
                let a = k as f64 * 0.000_314_159_3;
                let (s, c) = a.sin_cos();
                dirs.push(DVec3::new(c, s, 0.0));
                dirs.push(DVec3::new(0.0, c, s));
                dirs.push(DVec3::new(s, 0.0, c));
            }
            for ax in [DVec3::X, DVec3::Y, DVec3::Z] {
                dirs.push(ax);
                dirs.push(-ax);
            }
            let n_random = dirs.len();
            let aimed = aimed_dirs(&g, |_| true);
            assert!(aimed.len() > 3 * g.triangle_count() as usize);
            dirs.extend(aimed);
            let hits = cast(&g, &bvh, &dirs, 1e9);
            let misses = hits.iter().filter(|h| !h.is_hit()).count();
            assert_eq!(misses, 0, "{name}: {misses} misses of {}", dirs.len());
            for (k, (d, h)) in dirs.iter().zip(&hits).enumerate() {
                if k < n_random {
                    assert!(h.range_m >= rmin && h.range_m <= rmax, "{name} {d:?} {h:?}");
                } else {
                    assert!((h.range_m - 1.0).abs() < 1e-9, "{name} aimed {d:?} {h:?}");
                }
            }
            // The brute force agrees on a sample of the aimed rays (same function, no BVH).
            let sample: Vec<usize> = (n_random..dirs.len()).step_by(97).collect();
            let sd: Vec<DVec3> = sample.iter().map(|&k| dirs[k]).collect();
            let sh: Vec<Hit> = sample.iter().map(|&k| hits[k]).collect();
            same(&cast_brute_force(&g, &sd, 1e9, |_| true), &sh).unwrap();
        }
    }

    /// Closed meshes in front of the origin, wound outward and culled: every ray through a
    /// vertex / edge midpoint / centroid whose incident triangles all face the origin (with
    /// margin) hits at t = 1 within 1e-9; random rays through the inscribed sphere hit.
    #[test]
    fn watertight_from_outside() {
        let mut rng = Rng(5);
        let rot = rotation(&mut rng);
        let cases = vec![
            ("sphere", octasphere(48, DVec3::splat(1.5), DVec3::new(6.0, 1.0, -0.5)), 1.5 * 0.999),
            ("cube", tess_cube(48, rot, DVec3::new(-5.0, 2.0, 1.0)), 0.999),
        ];
        for (name, (p, i), r_in) in cases {
            let g = geom_of(&[(&p, &i, 2, false)]);
            let bvh = Bvh::build(&g);
            let margin = |ts: &[[DVec3; 3]]| {
                ts.iter().all(|t| {
                    let n = (t[1] - t[0]).cross(t[2] - t[0]);
                    n.dot(t[0]) < -0.05 * n.length() * t[0].length()
                })
            };
            let aimed = aimed_dirs(&g, margin);
            assert!(aimed.len() > g.triangle_count() as usize / 2, "{name}: {}", aimed.len());
            let hits = cast(&g, &bvh, &aimed, 1e9);
            for (d, h) in aimed.iter().zip(&hits) {
                assert!(h.is_hit() && (h.range_m - 1.0).abs() < 1e-9, "{name} aimed {d:?} {h:?}");
            }
            // Random rays that pass inside the inscribed sphere must hit.
            let centre = dv(g.meshes[0].centre);
            let dirs: Vec<DVec3> = (0..100_000)
                .map(|_| (centre + rng.unit() * r_in * rng.f().sqrt()).normalize())
                .collect();
            let hits = cast(&g, &bvh, &dirs, 1e9);
            assert_eq!(hits.iter().filter(|h| !h.is_hit()).count(), 0, "{name}");
        }
    }

    /// A double-sided mesh seen from behind is as watertight as one seen from the front: the
    /// sphere and the cube wound outward, double-sided, cast from inside (every triangle
    /// faces away); rays through every vertex, edge midpoint and centroid all hit at t = 1.
    #[test]
    fn watertight_from_behind_when_double_sided() {
        let mut rng = Rng(6);
        let rot = rotation(&mut rng);
        for (name, (p, i)) in [("sphere", octasphere(32, DVec3::ONE, DVec3::ZERO)), ("cube", tess_cube(32, rot, DVec3::new(0.1, 0.2, -0.3)))] {
            let g = geom_of(&[(&p, &i, 1, true)]);
            let aimed = aimed_dirs(&g, |_| true);
            assert!(aimed.len() > 3 * g.triangle_count() as usize);
            let hits = cast(&g, &Bvh::build(&g), &aimed, 1e9);
            for (d, h) in aimed.iter().zip(&hits) {
                assert!(h.is_hit() && (h.range_m - 1.0).abs() < 1e-9, "{name} aimed {d:?} {h:?}");
            }
        }
    }

    /// The ray starts at the origin and hits only at t > 0: a triangle through the origin
    /// (t = 0 exactly) is not hit, from either side, while the same triangle moved 1 m out is.
    #[test]
    fn a_triangle_through_the_origin_is_not_hit() {
        let at = |z: f64| [DVec3::new(-1.0, -1.0, z), DVec3::new(1.0, -1.0, z), DVec3::new(0.0, 1.0, z)];
        for (dir, cull) in [(DVec3::Z, false), (-DVec3::Z, false), (-DVec3::Z, true), (DVec3::new(0.3, 0.2, 1.0), false)] {
            assert_eq!(intersect_triangle(dir, &at(0.0), cull), None, "{dir} {cull}");
        }
        assert_eq!(intersect_triangle(DVec3::Z, &at(1.0), false), Some(1.0));
    }

    /// Ties: an exact duplicate always loses to the smaller triangle index.
    #[test]
    fn ties_pick_the_smaller_triangle() {
        let p = [[4.0, 1.0, -1.0], [4.0, 0.0, 1.0], [4.0, -1.0, -1.0]];
        let g = geom_of(&[(&p, &[0, 1, 2], 0, true), (&p, &[0, 1, 2, 0, 1, 2], 1, true)]);
        let hits = cast_frame(&g, &[DVec3::X], 100.0);
        assert_eq!(hits[0], Hit { range_m: 4.0, triangle: 0 });
        let h = cast_with_filter(&g, &Bvh::build(&g), &[DVec3::X], 100.0, |m| m.instance == 1);
        assert_eq!(h[0], Hit { range_m: 4.0, triangle: 1 });
        assert_eq!(h[0].instance(&g), 1);
    }
}
