//! Raster backend, cylinder: the CPU half of drawing one frame into the [`Panorama`]. It decides,
//! per mesh, how the GPU may draw it, so that no triangle is lost at the azimuth wrap or
//! smeared across the image, and no straight panorama edge strays far from the true curve.
//!
//! - **Direct** (people, as a rule): the mesh's bounding sphere keeps off the sensor's vertical
//!   axis, so all its points lie within `asin(r / rho)` (< 90 deg) of the centre's azimuth, and
//!   its triangles are small enough (longest edge over the nearest distance, as an angle, under
//!   `Panorama::max_extent_rad`). The GPU draws the mesh from the shared vertex and index
//!   buffers with the azimuth wrapped into a window of +-180 deg around the mesh's own azimuth
//!   (no triangle of it can straddle that window's edge); a mesh whose azimuth interval crosses
//!   the image's left or right edge is drawn a second time shifted by 360 deg. No per-triangle
//!   work on the CPU.
//! - **Soup** (the background, a person around the axis or very near): every triangle is
//!   handled here, in f64. Triangles wholly above or below the band are dropped; a triangle is
//!   cut at the 3D midpoints of its edges that are "too long" (the pieces are exact parts of
//!   the original plane), until none is or it lies outside the band. An edge is too long when
//!   the projection of its midpoint strays more than `PANORAMA_EDGE_TOLERANCE_TEXELS` from the
//!   straight panorama edge (vertical edges never do, horizontal ones near the horizon hardly),
//!   when it is wider or taller than `Panorama::max_piece_rad`, or when an end lies on the
//!   vertical axis (azimuth undefined); a triangle winding around the axis always has such an
//!   edge. The decision depends on the edge alone, so pieces of neighbouring triangles meet
//!   without cracks. What is left is written as a triangle list of (position, global triangle
//!   id). Pieces within `WRAP_GUARD_RAD` of the image's azimuth wrap are drawn twice, in
//!   windows centred on 0 and on 360 deg. A piece still winding around the axis after
//!   `MAX_SPLIT_DEPTH` levels lies within micrometres of the sensor (below any range limit) and
//!   is dropped; one still too long but off the axis is drawn as it is.
//!
//! The ID buffer always holds the ORIGINAL global triangle + 1, so refinement works on the
//! posed triangles exactly as for the cube faces.

use crate::geometry::{FrameGeometry, MeshRange};
use super::projection::{Panorama, NEAR_M, PANORAMA_EDGE_TOLERANCE_TEXELS};
use glam::{DVec3, Vec3};
use std::f64::consts::{PI, TAU};

/// Levels of splitting at most (each halves the edges it cuts): 2^-24 of a 100 m edge is 6 um.
pub const MAX_SPLIT_DEPTH: u32 = 24;

/// Soup triangles closer than this (radians of phi) to the image's wrap are drawn on both
/// sides, so f32 rounding in the shader can never put one vertex across the wrap alone.
pub const WRAP_GUARD_RAD: f64 = 1e-3;

/// One vertex of the soup: sensor-frame position and the original global triangle index.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SoupVertex {
    pub pos: [f32; 3],
    pub triangle: u32,
}

/// A direct draw: mesh `mesh` wrapped into the phi window `[window - pi, window + pi)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DirectDraw {
    pub mesh: usize,
    pub window: f32,
}

/// Which soup list: wrap-straddling or not, back-face culled or double-sided.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SoupList {
    Culled = 0,
    DoubleSided = 1,
    WrapCulled = 2,
    WrapDoubleSided = 3,
}

/// Counters of one `prepare` (for tests and benchmarks).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PrepStats {
    pub direct_meshes: u32,
    pub soup_meshes: u32,
    /// Input triangles of the soup meshes.
    pub soup_input_triangles: u64,
    /// Triangles written to the soup (wrap-straddling ones once).
    pub soup_triangles: u64,
    pub wrap_triangles: u64,
    /// Triangles split.
    pub splits: u64,
    /// Pieces dropped wholly outside the band or nearer than `NEAR_M`.
    pub culled: u64,
    /// Pieces dropped still winding around the axis at `MAX_SPLIT_DEPTH`.
    pub dropped_at_axis: u64,
}

/// The per-frame plan: direct draws and the soup, reused across frames.
#[derive(Debug, Default)]
pub struct PanoramaPrep {
    pub direct: Vec<DirectDraw>,
    /// Indexed by `SoupList`.
    pub soup: [Vec<SoupVertex>; 4],
    pub stats: PrepStats,
    stack: Vec<([Vert; 3], u32)>,
    /// Projected vertices of the soup mesh at hand (each computed once, not per triangle).
    verts: Vec<Vert>,
}

#[derive(Clone, Copy, Debug)]
struct Vert {
    p: DVec3,
    phi: f64,
    el: f64,
    /// On the vertical axis (azimuth undefined).
    axis: bool,
}

fn vert(pano: &Panorama, p: DVec3) -> Vert {
    let rho = p.x.hypot(p.y);
    Vert { p, phi: pano.phi(p), el: p.z.atan2(rho), axis: rho <= 1e-12 * p.z.abs() || rho == 0.0 }
}

/// `a` wrapped into [-pi, pi), in its own `floor` form rather than
/// [`crate::geometry::wrap_pi`]'s: the raster path's bits were fixed with it.
fn wrap_pi(a: f64) -> f64 {
    a - TAU * ((a + PI) / TAU).floor()
}

impl PanoramaPrep {
    /// Plans `geom` for `pano`: fills `direct` and `soup`. Meshes the panorama cannot see are
    /// left out entirely.
    pub fn prepare(&mut self, pano: &Panorama, geom: &FrameGeometry) {
        self.direct.clear();
        for s in &mut self.soup {
            s.clear();
        }
        self.stats = PrepStats::default();
        for (k, m) in geom.meshes.iter().enumerate() {
            if m.triangle_count == 0 || !pano.sees_sphere(Vec3::from(m.centre), m.radius) {
                continue;
            }
            if let Some(windows) = direct_windows(pano, geom, m) {
                self.stats.direct_meshes += 1;
                for w in windows.into_iter().flatten() {
                    self.direct.push(DirectDraw { mesh: k, window: w as f32 });
                }
            } else {
                self.stats.soup_meshes += 1;
                self.stats.soup_input_triangles += m.triangle_count as u64;
                let first = 3 * m.first_triangle as usize;
                let idx = &geom.indices[first..first + 3 * m.triangle_count as usize];
                let lo = idx.iter().copied().min().unwrap_or(0) as usize;
                let hi = idx.iter().copied().max().unwrap_or(0) as usize;
                let mut verts = std::mem::take(&mut self.verts);
                verts.clear();
                verts.extend(geom.positions[lo..=hi].iter().map(|p| vert(pano, Vec3::from(*p).as_dvec3())));
                for (k, t) in idx.chunks_exact(3).enumerate() {
                    let v = [0, 1, 2].map(|c| verts[t[c] as usize - lo]);
                    self.add_projected(pano, v, m.first_triangle + k as u32, m.double_sided);
                }
                self.verts = verts;
            }
        }
    }

    /// Whether there is anything to draw.
    pub fn is_empty(&self) -> bool {
        self.direct.is_empty() && self.soup.iter().all(|s| s.is_empty())
    }

    /// Splits, culls and classifies one triangle into the soup.
    ///
    /// Splitting is decided per EDGE, from the edge's own end points (`edge_too_long`), and a
    /// triangle is cut at the midpoints of exactly the edges that need it (4, 3 or 2 pieces).
    /// Two triangles that share an edge therefore split it at the same f64 midpoint: the pieces
    /// meet without T-junctions, so no crack opens between the straight panorama edges.
    #[cfg(test)]
    fn add_triangle(&mut self, pano: &Panorama, tri: [DVec3; 3], id: u32, double_sided: bool) {
        self.add_projected(pano, tri.map(|p| vert(pano, p)), id, double_sided);
    }

    /// `add_triangle` for a triangle whose vertices are projected already.
    fn add_projected(&mut self, pano: &Panorama, tri: [Vert; 3], id: u32, double_sided: bool) {
        let tol = pano.edge_tolerance_rad();
        // Thresholds for "wholly below / above the band": only across the horizon is the
        // vertex test conservative (a triangle in one half-space has its elevation extreme
        // towards the horizon at a vertex).
        let lo = pano.el_bottom().min(0.0);
        let hi = pano.el_top.max(0.0);
        self.stack.clear();
        self.stack.push((tri, 0));
        while let Some((v, depth)) = self.stack.pop() {
            if v.iter().all(|v| v.p.length() < NEAR_M) || v.iter().all(|v| v.el < lo) || v.iter().all(|v| v.el > hi) {
                self.stats.culled += 1;
                continue;
            }
            let mids = [0, 1, 2].map(|e| split_edge(pano, tol, &v[e], &v[(e + 1) % 3]));
            let split = mids.map(|m| m.is_some());
            let n = split.iter().filter(|s| **s).count();
            if n == 0 || depth >= MAX_SPLIT_DEPTH {
                // Winding around the axis (azimuth undefined at a vertex, or the phi steps
                // around the triangle add up to +-2 pi): only possible here at the depth cap.
                let wound = v.iter().any(|v| v.axis) || {
                    let s = wrap_pi(v[1].phi - v[0].phi) + wrap_pi(v[2].phi - v[1].phi) + wrap_pi(v[0].phi - v[2].phi);
                    s.abs() > PI
                };
                if wound {
                    self.stats.dropped_at_axis += 1;
                    continue;
                }
                let p0 = v[0].phi;
                let p1 = p0 + wrap_pi(v[1].phi - v[0].phi);
                let p2 = p1 + wrap_pi(v[2].phi - v[1].phi);
                let (pmin, pmax) = (p0.min(p1).min(p2), p0.max(p1).max(p2));
                let wrap = pmin < WRAP_GUARD_RAD || pmax > TAU - WRAP_GUARD_RAD;
                let list = match (wrap, double_sided) {
                    (false, false) => SoupList::Culled,
                    (false, true) => SoupList::DoubleSided,
                    (true, false) => SoupList::WrapCulled,
                    (true, true) => SoupList::WrapDoubleSided,
                };
                let out = &mut self.soup[list as usize];
                for v in &v {
                    out.push(SoupVertex { pos: v.p.as_vec3().to_array(), triangle: id });
                }
                self.stats.soup_triangles += 1;
                self.stats.wrap_triangles += wrap as u64;
                continue;
            }
            self.stats.splits += 1;
            let mid = |e: usize| mids[e].expect("split edge");
            let d = depth + 1;
            match n {
                3 => {
                    let (m0, m1, m2) = (mid(0), mid(1), mid(2));
                    self.stack.extend([([v[0], m0, m2], d), ([m0, v[1], m1], d), ([m2, m1, v[2]], d), ([m0, m1, m2], d)]);
                }
                1 => {
                    let e = split.iter().position(|s| *s).expect("one edge");
                    let (a, b, c, m) = (v[e], v[(e + 1) % 3], v[(e + 2) % 3], mid(e));
                    self.stack.extend([([a, m, c], d), ([m, b, c], d)]);
                }
                _ => {
                    // Edge u = AB is kept; BC and CA are split at m1 and m2.
                    let u = split.iter().position(|s| !*s).expect("one edge kept");
                    let (a, b, c) = (v[u], v[(u + 1) % 3], v[(u + 2) % 3]);
                    let (m1, m2) = (mid((u + 1) % 3), mid((u + 2) % 3));
                    self.stack.extend([([a, b, m1], d), ([a, m1, m2], d), ([m2, m1, c], d)]);
                }
            }
        }
    }
}

/// The midpoint at which an edge must be split, or None. It must be when an end lies on the
/// vertical axis (azimuth undefined), when it is wider or taller than `max_piece_rad`, or when
/// the projection of its 3D midpoint strays more than `PANORAMA_EDGE_TOLERANCE_TEXELS` from the
/// straight panorama edge (a vertical edge never does; a horizontal one near the horizon
/// hardly). An edge whose extent `e` gives `e^2 / 4` within the tolerance (elevations within
/// +-45 deg) cannot stray that far and is kept without computing its midpoint. Depends on the
/// edge alone, evaluated in a canonical order of its ends, so both triangles that share an edge
/// decide alike.
fn split_edge(pano: &Panorama, tol_rad: f64, a: &Vert, b: &Vert) -> Option<Vert> {
    let (a, b) = if a.p.to_array() <= b.p.to_array() { (a, b) } else { (b, a) };
    let bound = pano.max_piece_rad;
    let (dphi, del) = (wrap_pi(b.phi - a.phi).abs(), (b.el - a.el).abs());
    let mid = || vert(pano, 0.5 * (a.p + b.p));
    if a.axis || b.axis || dphi > bound || del > bound {
        return Some(mid());
    }
    let e = dphi.max(del);
    if e * e / 4.0 <= tol_rad && a.el.abs().max(b.el.abs()) <= std::f64::consts::FRAC_PI_4 {
        return None;
    }
    let m = mid();
    (m.axis || pano.chord_deviation_texels((a.phi, a.el), (b.phi, b.el), (m.phi, m.el)) > PANORAMA_EDGE_TOLERANCE_TEXELS).then_some(m)
}

/// The phi windows of a mesh the GPU may draw directly (one, or two across the wrap), or None
/// when it must go through the soup.
fn direct_windows(pano: &Panorama, geom: &FrameGeometry, m: &MeshRange) -> Option<[Option<f64>; 2]> {
    let c = Vec3::from(m.centre).as_dvec3();
    let r = m.radius as f64;
    let rho = c.x.hypot(c.y);
    // Off the vertical axis with room to spare (azimuth half-width below ~89.4 deg).
    if rho <= r * 1.0001 + 1e-4 {
        return None;
    }
    let dist = c.length();
    let near = dist - r;
    let half_az = (r / rho).asin();
    // Extents in phi stretch by 1 / cos(elevation) away from the horizon.
    let el_far = (Panorama::elevation(c).abs() + (r / dist).asin()).min(80f64.to_radians());
    let stretch = 1.0 / el_far.cos();
    let small = 2.0 * (r / dist).asin() * stretch <= pano.max_extent_rad
        || (max_edge(geom, m).sqrt() / near) * stretch <= pano.max_extent_rad;
    if !small {
        return None;
    }
    let centre = pano.phi(c);
    let second = if centre - half_az < WRAP_GUARD_RAD {
        Some(centre + TAU)
    } else if centre + half_az > TAU - WRAP_GUARD_RAD {
        Some(centre - TAU)
    } else {
        None
    };
    Some([Some(centre), second])
}

/// Longest squared edge length of a mesh's triangles, metres^2.
fn max_edge(geom: &FrameGeometry, m: &MeshRange) -> f64 {
    let first = 3 * m.first_triangle as usize;
    let idx = &geom.indices[first..first + 3 * m.triangle_count as usize];
    let pos = &geom.positions;
    let mut best = 0f32;
    for t in idx.chunks_exact(3) {
        let [a, b, c] = [pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]].map(Vec3::from);
        best = best.max(a.distance_squared(b)).max(b.distance_squared(c)).max(c.distance_squared(a));
    }
    best as f64 * (1.0 + 1e-5)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::Sensor;

    fn pano() -> Panorama {
        Panorama::new(&Sensor::hdl32e(), 2.0)
    }

    /// One triangle through the soup (as part of a mesh drawn that way), double-sided.
    fn soup_of(tri: [DVec3; 3]) -> PanoramaPrep {
        let mut prep = PanoramaPrep::default();
        prep.add_triangle(&pano(), tri, 0, true);
        prep
    }

    fn pieces(prep: &PanoramaPrep) -> Vec<[DVec3; 3]> {
        prep.soup
            .iter()
            .flat_map(|s| s.chunks_exact(3).map(|t| [0, 1, 2].map(|k| Vec3::from(t[k].pos).as_dvec3())))
            .collect()
    }

    #[test]
    fn a_small_triangle_behind_the_sensor_straddling_the_wrap_goes_to_both_sides() {
        let prep = soup_of([DVec3::new(-5.0, 0.05, 0.0), DVec3::new(-5.0, -0.05, 0.0), DVec3::new(-5.0, 0.0, 0.05)]);
        assert_eq!(prep.stats.soup_triangles, 1);
        assert_eq!(prep.stats.wrap_triangles, 1);
        assert_eq!(prep.soup[SoupList::WrapDoubleSided as usize].len(), 3);
    }

    #[test]
    fn a_large_floor_is_split_into_straight_enough_pieces_and_loses_no_area_in_the_band() {
        let p = pano();
        // A floor 0.8 m below the sensor, 40 m across, with the sensor's axis inside.
        let tri = [DVec3::new(-20.0, -20.0, -0.8), DVec3::new(30.0, -5.0, -0.8), DVec3::new(-10.0, 25.0, -0.8)];
        let prep = soup_of(tri);
        assert!(prep.stats.splits > 100, "{:?}", prep.stats);
        assert_eq!(prep.stats.dropped_at_axis, 0, "the axis point is far below the band");
        let mut area = 0.0;
        for t in pieces(&prep) {
            let v = t.map(|q| vert(&p, q));
            let p0 = v[0].phi;
            let p1 = p0 + wrap_pi(v[1].phi - v[0].phi);
            let p2 = p1 + wrap_pi(v[2].phi - v[1].phi);
            assert!(p0.max(p1).max(p2) - p0.min(p1).min(p2) <= 2.0 * p.max_piece_rad + 1e-9);
            let (lo, hi) = (v[0].el.min(v[1].el).min(v[2].el), v[0].el.max(v[1].el).max(v[2].el));
            assert!(hi - lo <= 2.0 * p.max_piece_rad + 1e-9);
            for e in 0..3 {
                let (a, b) = (v[e], v[(e + 1) % 3]);
                let m = vert(&p, 0.5 * (a.p + b.p));
                assert!(p.chord_deviation_texels((a.phi, a.el), (b.phi, b.el), (m.phi, m.el)) <= PANORAMA_EDGE_TOLERANCE_TEXELS + 1e-9);
            }
            area += 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length();
        }
        // Every point of the floor at elevation >= the image's bottom edge is kept: the floor
        // beyond the radius where it meets the bottom edge, inside the triangle.
        let r_min = 0.8 / (-p.el_bottom()).tan();
        let full = 0.5 * (tri[1] - tri[0]).cross(tri[2] - tri[0]).length();
        assert!(area <= full + 1e-6);
        assert!(area >= full - std::f64::consts::PI * r_min * r_min * 1.5, "area {area} of {full}");
    }

    #[test]
    fn a_triangle_through_the_axis_overhead_is_culled_not_smeared() {
        // A ceiling piece right above the sensor, far above the band: nothing drawn.
        let prep = soup_of([DVec3::new(-1.0, -1.0, 3.0), DVec3::new(1.0, -1.0, 3.0), DVec3::new(0.0, 1.5, 3.0)]);
        assert_eq!(prep.stats.soup_triangles, 0);
        assert!(prep.stats.culled > 0);
        // A wall crossing the axis line at 0.01 m (through the band): split many times, but
        // never a piece spanning the wrap.
        let prep = soup_of([DVec3::new(0.01, -5.0, -3.0), DVec3::new(0.01, 5.0, -3.0), DVec3::new(0.01, 0.0, 3.0)]);
        assert!(prep.stats.soup_triangles > 0);
        for t in pieces(&prep) {
            let v = t.map(|q| vert(&pano(), q));
            assert!(!v.iter().any(|v| v.axis));
            let s = wrap_pi(v[1].phi - v[0].phi) + wrap_pi(v[2].phi - v[1].phi) + wrap_pi(v[0].phi - v[2].phi);
            assert!(s.abs() < PI);
        }
    }

    #[test]
    fn people_away_from_the_axis_are_drawn_directly_and_twice_across_the_wrap() {
        let p = pano();
        let mut g = FrameGeometry::default();
        // A "person": small triangles in a 0.4 m ball, 5 m ahead.
        let ball = |c: DVec3| -> Vec<[f32; 3]> {
            (0..30).map(|k| (c + 0.1 * DVec3::new((k as f64).cos(), (k as f64 * 1.7).sin(), ((k % 7) as f64 / 7.0) - 0.5).normalize()).as_vec3().to_array()).collect()
        };
        let idx: Vec<u32> = (0..28).flat_map(|k| [k, k + 1, k + 2]).collect();
        g.push_mesh(&ball(DVec3::new(5.0, 0.0, 0.0)), &idx, 1, false);
        g.push_mesh(&ball(DVec3::new(-5.0, 0.05, 0.0)), &idx, 2, false);
        // Around the axis: soup.
        g.push_mesh(&ball(DVec3::new(0.05, 0.0, 0.0)), &idx, 3, false);
        let mut prep = PanoramaPrep::default();
        prep.prepare(&p, &g);
        assert_eq!(prep.stats.direct_meshes, 2);
        assert_eq!(prep.stats.soup_meshes, 1);
        assert_eq!(prep.direct.iter().filter(|d| d.mesh == 0).count(), 1);
        assert_eq!(prep.direct.iter().filter(|d| d.mesh == 1).count(), 2);
    }
}
