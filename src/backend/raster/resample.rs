//! Raster backend, resampling: from the rendered cube faces (or the panorama) to the sensor's beam grid. A lookup
//! computed once per sensor maps every beam to its face and texel (nearest by integer index,
//! clamp-to-edge, deterministic at seams: see `CubeFaces::face_of`). For the panorama the
//! lookup is direct: one image, column from azimuth (beams on texel centres), row from
//! elevation, and the 3x3 neighbourhood wraps around in azimuth. No ranges are ever blended
//! across texels.
//!
//! Refinement uses the ID buffer: with the triangle that covers the beam's texel (and those of
//! the 3x3 texels around it) the beam is re-intersected exactly, in f64, with the same
//! watertight test as the ray-cast reference. `exact` settles a beam from the ID buffer only
//! where its 3x3 texels all show one object (a person, or the background) with no nearer
//! fold; a beam at a silhouette, a hole or a depth step is cast exactly through the layer's
//! triangle clusters ([`MeshClusters`]), so it gets the reference's own hit, never the
//! surface behind the one the raster missed.

use crate::config::Refine;
use crate::geometry::FrameGeometry;
use super::projection::{CubeFaces, Face, Panorama};
use super::renderer::RasterFrame;
use crate::backend::BeamHits;
use super::clusters::MeshClusters;
use crate::backend::triangle::intersect_triangle;
use crate::sensor::Sensor;
use glam::DVec3;
use rayon::prelude::*;

/// How many one-rings around the rendered triangles exact refinement searches when the beam
/// hits none of them (triangles up to ~4x smaller than a texel).
pub const MAX_RINGS: usize = 4;

/// Per-beam face and texel, computed once per sensor and face set.
#[derive(Clone, Debug)]
pub struct BeamLookup {
    pub rows: usize,
    pub columns: usize,
    /// Unit beam directions, row-major.
    pub dirs: Vec<DVec3>,
    /// Face of each beam.
    pub face: Vec<u8>,
    /// Texel (u, v) of each beam in its face.
    pub texel: Vec<(u32, u32)>,
    /// Width and height of each face.
    pub face_size: Vec<(u32, u32)>,
    /// The faces (or the panorama) themselves: texel directions for the exact refinement.
    pub images: Vec<ImageMap>,
    /// Per beam: whether it lies on its texel's centre (within `CENTRED_TEXELS`), i.e. the
    /// texel was rasterised along the beam itself (the panorama; never a cube face).
    pub centred: Vec<bool>,
}

/// A beam this close to its texel centre (texels, each axis) counts as on it.
pub const CENTRED_TEXELS: f64 = 0.02;

/// The texel mapping of one raster image.
#[derive(Clone, Debug, PartialEq)]
pub enum ImageMap {
    Face(Face),
    Panorama(Panorama),
}

impl ImageMap {
    /// Direction (not necessarily unit) through the centre of texel (u, v).
    pub fn texel_dir(&self, u: u32, v: u32) -> DVec3 {
        match self {
            ImageMap::Face(f) => f.texel_dir(u, v),
            ImageMap::Panorama(p) => p.texel_dir(u, v),
        }
    }

    /// Whether the image wraps around horizontally (the panorama's 360 deg).
    pub fn wraps(&self) -> bool {
        matches!(self, ImageMap::Panorama(_))
    }

    /// Continuous horizontal pixel coordinate of a direction and the image width.
    fn px(&self, d: DVec3) -> (f64, f64) {
        match self {
            ImageMap::Face(f) => (f.pixel(d).map_or(0.0, |p| p.0), f.width as f64),
            ImageMap::Panorama(p) => (p.pixel(d).0, p.width as f64),
        }
    }
}

impl BeamLookup {
    pub fn new(sensor: &Sensor, cube: &CubeFaces) -> BeamLookup {
        let dirs = sensor.beam_dirs();
        let mut face = Vec::with_capacity(dirs.len());
        let mut texel = Vec::with_capacity(dirs.len());
        for d in &dirs {
            let f = cube.face_of(*d);
            face.push(f as u8);
            // Every beam points into its own face's half-space (|azimuth offset| <= 45 deg).
            texel.push(cube.faces[f].texel(*d).expect("beam in front of its own face"));
        }
        BeamLookup {
            rows: sensor.rows(),
            columns: sensor.columns,
            centred: vec![false; dirs.len()],
            dirs,
            face,
            texel,
            face_size: cube.faces.iter().map(|f| (f.width, f.height)).collect(),
            images: cube.faces.iter().cloned().map(ImageMap::Face).collect(),
        }
    }

    /// The direct lookup into one panorama: every beam in image 0, texel from its azimuth and
    /// elevation (`Panorama::texel`).
    pub fn new_panorama(sensor: &Sensor, pano: &Panorama) -> BeamLookup {
        let dirs = sensor.beam_dirs();
        let texel: Vec<(u32, u32)> = dirs.iter().map(|d| pano.texel(*d)).collect();
        let centred = dirs
            .iter()
            .zip(&texel)
            .map(|(d, &(u, v))| {
                let (px, py) = pano.pixel(*d);
                (px - (u as f64 + 0.5)).abs() < CENTRED_TEXELS && (py - (v as f64 + 0.5)).abs() < CENTRED_TEXELS
            })
            .collect();
        BeamLookup {
            centred,
            rows: sensor.rows(),
            columns: sensor.columns,
            face: vec![0; dirs.len()],
            dirs,
            texel,
            face_size: vec![(pano.width, pano.height)],
            images: vec![ImageMap::Panorama(pano.clone())],
        }
    }

    /// Horizontal distance, in texels, of beam `b` from the nearest left or right edge of its
    /// image: a cube-face seam, or the panorama's azimuth wrap.
    pub fn seam_distance_texels(&self, b: usize) -> f64 {
        let (px, w) = self.images[self.face[b] as usize].px(self.dirs[b]);
        px.min(w - px)
    }

    /// Which faces any beam uses.
    pub fn faces_used(&self) -> [bool; 4] {
        let mut used = [false; 4];
        for f in &self.face {
            used[*f as usize] = true;
        }
        used
    }
}

/// The 3x3 texels around `(u, v)` in an image of `size`, row by row: columns wrap around
/// when `wraps` (the panorama) and clamp to the edge otherwise; rows clamp.
pub fn texels_3x3((u, v): (u32, u32), (w, h): (u32, u32), wraps: bool) -> impl Iterator<Item = (u32, u32)> {
    (-1i64..=1).flat_map(move |dv| {
        (-1i64..=1).map(move |du| {
            let uu = if wraps { (u as i64 + du).rem_euclid(w as i64) } else { (u as i64 + du).clamp(0, w as i64 - 1) };
            (uu as u32, (v as i64 + dv).clamp(0, h as i64 - 1) as u32)
        })
    })
}

/// Intersection of the beam with the plane of a triangle (f64), if in front.
fn plane_hit(dir: DVec3, tri: &[DVec3; 3]) -> Option<f64> {
    let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
    let denom = n.dot(dir);
    if denom == 0.0 || !denom.is_finite() {
        return None;
    }
    let t = n.dot(tri[0]) / denom;
    (t > 0.0 && t.is_finite()).then_some(t)
}

/// Resamples the rendered faces to the beam grid, refining as asked.
pub fn resample(lookup: &BeamLookup, frame: &RasterFrame, geom: &FrameGeometry, refine: Refine, out: &mut BeamHits) {
    let n = lookup.rows * lookup.columns;
    out.clear_to(n);
    let w = lookup.columns;
    // Beams the ID buffer cannot settle are cast exactly through the layer's clusters, built
    // on first use (a layer with none such builds nothing).
    let mut clusters = MeshClusters::default();
    if refine == Refine::Exact {
        clusters.reset(geom);
    }
    let clusters = &clusters;
    out.range_m
        .par_chunks_mut(w)
        .zip(out.triangle.par_chunks_mut(w))
        .enumerate()
        .for_each(|(row, (ranges, tris))| {
            let mut bufs = RingBuffers::default();
            for col in 0..w {
                let b = row * w + col;
                let f = lookup.face[b] as usize;
                let img = &frame.faces[f];
                if !img.rendered {
                    continue;
                }
                let (u, v) = lookup.texel[b];
                let (fw, fh) = (img.width, img.height);
                let wraps = lookup.images[f].wraps();
                let at = |u: u32, v: u32| (v * fw + u) as usize;
                let centre_id = img.id[at(u, v)];
                let dir = lookup.dirs[b];
                let (range, tri) = match refine {
                    Refine::None => {
                        if centre_id == 0 {
                            continue;
                        }
                        (img.range_m[at(u, v)] as f64, centre_id - 1)
                    }
                    Refine::Plane => {
                        if centre_id == 0 {
                            continue;
                        }
                        let t = centre_id - 1;
                        let r = plane_hit(dir, &geom.triangle_f64(t)).unwrap_or(img.range_m[at(u, v)] as f64);
                        (r, t)
                    }
                    Refine::Exact => {
                        // The interior of one drawn triangle: its 3x3 texels all show it, and
                        // the beam hits it. The general path below would settle the same hit
                        // (the only candidate, never drawn in front of its own plane).
                        if centre_id != 0
                            && texels_3x3((u, v), (fw, fh), wraps).all(|(uu, vv)| img.id[at(uu, vv)] == centre_id)
                        {
                            let mut hit = None;
                            test_triangle(dir, geom, centre_id - 1, &mut hit);
                            if let Some((r, t)) = hit {
                                ranges[col] = r as f32;
                                tris[col] = t;
                                continue;
                            }
                        }
                        let mut cand = [Cand::default(); 9];
                        let mut nc = 0;
                        let mut any_empty = false;
                        for (uu, vv) in texels_3x3((u, v), (fw, fh), wraps) {
                            let id = img.id[at(uu, vv)];
                            let r = img.range_m[at(uu, vv)];
                            if id == 0 {
                                any_empty = true;
                            } else if let Some(c) = cand[..nc].iter_mut().find(|c| c.triangle == id - 1) {
                                if r < c.range_m {
                                    (c.range_m, c.u, c.v) = (r, uu, vv);
                                }
                            } else {
                                cand[nc] = Cand { triangle: id - 1, range_m: r, u: uu, v: vv };
                                nc += 1;
                            }
                        }
                        if nc == 0 {
                            continue;
                        }
                        cand[..nc].sort_unstable_by_key(|c| c.triangle);
                        let centred = lookup.centred[b].then(|| (centre_id != 0).then(|| centre_id - 1));
                        // A hole or another object in the 3x3 (another person; for the
                        // background, whose meshes share instance 0, depth steps between its
                        // meshes are left to the fold test): straight to the exact cast.
                        let instance = geom.mesh_of_triangle(cand[0].triangle).instance;
                        let one_object =
                            !any_empty && cand[1..nc].iter().all(|c| geom.mesh_of_triangle(c.triangle).instance == instance);
                        let settled = one_object
                            .then(|| refine_exact(dir, geom, &lookup.images[f], &cand[..nc], centred, &mut bufs))
                            .flatten()
                            // Off the texel centres (cube faces), a hit found only by the
                            // ring search is a triangle no texel saw: not settled either.
                            .filter(|&(_, t)| lookup.centred[b] || cand[..nc].iter().any(|c| c.triangle == t))
                            .filter(|&hit| no_nearer_fold(geom, &lookup.images[f], hit, &cand[..nc]));
                        match settled.or_else(|| clusters.cast(geom, dir, &mut bufs.clusters)) {
                            Some(hit) => hit,
                            None => continue,
                        }
                    }
                };
                ranges[col] = range as f32;
                tris[col] = tri;
            }
        });
}

/// Scratch vectors of the ring search, one set per worker.
#[derive(Default)]
struct RingBuffers {
    clusters: Vec<(f64, u32, u32)>,
    ring: Vec<u32>,
    seen: Vec<u32>,
    frontier: Vec<u32>,
}

/// Nearest hit of `dir` with triangle `t` folded into `best` (ties: smaller triangle).
fn test_triangle(dir: DVec3, geom: &FrameGeometry, t: u32, best: &mut Option<(f64, u32)>) {
    let cull = !geom.mesh_of_triangle(t).double_sided;
    if let Some(r) = intersect_triangle(dir, &geom.triangle_f64(t), cull) {
        if best.map_or(true, |(br, bt)| r < br || (r == br && t < bt)) {
            *best = Some((r, t));
        }
    }
}

/// Searches outwards from `seeds` (already tested) ring by ring, up to `MAX_RINGS`, and
/// returns the nearest hit nearer than `before` found by the first ring that has one.
fn ring_search(dir: DVec3, geom: &FrameGeometry, seeds: impl Iterator<Item = u32>, before: f64, b: &mut RingBuffers) -> Option<(f64, u32)> {
    b.seen.clear();
    b.seen.extend(seeds);
    b.seen.sort_unstable();
    b.frontier.clear();
    b.frontier.extend_from_slice(&b.seen);
    let mut best = None;
    for _ in 0..MAX_RINGS {
        b.ring.clear();
        for &t in b.frontier.iter() {
            b.ring.extend(geom.neighbours(t));
        }
        b.ring.sort_unstable();
        b.ring.dedup();
        let seen = &b.seen;
        b.ring.retain(|t| seen.binary_search(t).is_err());
        if b.ring.is_empty() {
            break;
        }
        for &t in b.ring.iter() {
            test_triangle(dir, geom, t, &mut best);
        }
        if best.is_some_and(|(r, _)| r < before) {
            break;
        }
        best = None;
        b.seen.extend_from_slice(&b.ring);
        b.seen.sort_unstable();
        std::mem::swap(&mut b.frontier, &mut b.ring);
    }
    best
}

/// A triangle rendered in a beam's 3x3 texels, with the nearest texel it was rendered at.
#[derive(Clone, Copy, Debug, Default)]
struct Cand {
    triangle: u32,
    range_m: f32,
    u: u32,
    v: u32,
}

/// Exact refinement of one beam from the triangles rendered in its 3x3 texels (`cand`, sorted
/// by triangle).
///
/// 0. A beam on its texel's centre (`centred` is `Some(centre triangle)`, the panorama): that
///    texel was rasterised along the beam itself, so depth testing there already chose the
///    nearest surface; when the beam hits that triangle exactly, that is the answer unless a
///    candidate rendered clearly in front of its plane (step 3's test) holds the beam itself
///    (a large triangle whose drawn edge strays up to `PANORAMA_EDGE_TOLERANCE_TEXELS` from
///    the true one); no ring search: a nearer small triangle holding the beam but not the
///    texel centre would need its silhouette within `CENTRED_TEXELS` of the beam, for which
///    neighbouring texels, a whole (tall) texel away, are no evidence, and searching around
///    each nearer neighbour cost more than it found (`pedscan crosscheck --projection
///    cylinder`). Otherwise steps 1 to 3.
/// 1. The nearest exact hit among the candidates.
/// 2. None: triangles smaller than a texel can hold the beam without covering a texel centre,
///    so search the rings around the candidates.
/// 3. A hit (from 1 or 2), but some candidate was rendered clearly in front of the hit
///    triangle's plane (along that candidate's own texel direction): the beam may pass through
///    a small triangle of that nearer surface (an arm over the torso, a silhouette over a
///    person behind), so search the rings around those candidates for a nearer hit. Comparing
///    with the plane, not with the hit's range, keeps a floor seen at grazing incidence (whose
///    neighbouring texels are nearer simply because the floor is slanted) out of this search.
fn refine_exact(
    dir: DVec3,
    geom: &FrameGeometry,
    image: &ImageMap,
    cand: &[Cand],
    centred: Option<Option<u32>>,
    b: &mut RingBuffers,
) -> Option<(f64, u32)> {
    let in_front = |hit: (f64, u32), c: &Cand| drawn_in_front(geom, image, hit, c);
    let mut best = None;
    if let Some(Some(t)) = centred {
        test_triangle(dir, geom, t, &mut best);
        if let Some(hit) = best {
            for c in cand.iter().filter(|c| in_front(hit, c)) {
                test_triangle(dir, geom, c.triangle, &mut best);
            }
            return best;
        }
    }
    for c in cand {
        test_triangle(dir, geom, c.triangle, &mut best);
    }
    if best.is_none() {
        best = ring_search(dir, geom, cand.iter().map(|c| c.triangle), f64::INFINITY, b);
    }
    let hit = best?;
    let r = hit.0;
    let in_front = |c: &&Cand| in_front(hit, c);
    if cand.iter().any(|c| in_front(&c)) {
        if let Some(alt) = ring_search(dir, geom, cand.iter().filter(in_front).map(|c| c.triangle), r, b) {
            return Some(alt);
        }
    }
    best
}

/// A rendered candidate counts as a nearer surface when its texel range is this fraction
/// nearer than the hit triangle's plane along the candidate's texel direction.
const OCCLUDER_MARGIN: f64 = 0.005;

/// Whether candidate `c` was rendered clearly in front of the plane of hit `(r, t)`, along the
/// candidate's own texel direction.
fn drawn_in_front(geom: &FrameGeometry, image: &ImageMap, (r, t): (f64, u32), c: &Cand) -> bool {
    let d = image.texel_dir(c.u, c.v).normalize();
    let expected = plane_hit(d, &geom.triangle_f64(t)).unwrap_or(r);
    (c.range_m as f64) < expected * (1.0 - OCCLUDER_MARGIN)
}

/// Whether the ID buffer alone settles a beam whose refined hit is `hit`, given that every
/// texel of its 3x3 neighbourhood shows the hit's own object (no silhouette, no hole, no
/// other person): none of them was drawn clearly in front of the hit's plane (no nearer fold
/// or nearer part of the same object). Anything else sends the beam to the exact cluster
/// cast: the nearest surface along a beam at a depth step need not be drawn at its texel,
/// which is where metre-scale errors came from.
fn no_nearer_fold(geom: &FrameGeometry, image: &ImageMap, hit: (f64, u32), cand: &[Cand]) -> bool {
    !cand.iter().any(|c| drawn_in_front(geom, image, hit, c))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_hit_is_exact_for_an_axis_plane() {
        let tri = [DVec3::new(5.0, -1.0, -1.0), DVec3::new(5.0, 1.0, -1.0), DVec3::new(5.0, 0.0, 1.0)];
        let d = DVec3::new(1.0, 3.0, 0.2).normalize();
        let t = plane_hit(d, &tri).unwrap();
        assert!((t - 5.0 / d.x).abs() < 1e-12);
        assert!(plane_hit(-d, &tri).is_none(), "behind the sensor");
    }

    #[test]
    fn every_hdl32e_beam_has_a_texel_inside_its_face() {
        let s = Sensor::hdl32e();
        let cube = CubeFaces::new(&s, 2.0);
        let l = BeamLookup::new(&s, &cube);
        assert_eq!(l.faces_used(), [true; 4]);
        for b in 0..l.dirs.len() {
            let (w, h) = l.face_size[l.face[b] as usize];
            let (u, v) = l.texel[b];
            assert!(u < w && v > 0 && v + 1 < h);
        }
    }
}
