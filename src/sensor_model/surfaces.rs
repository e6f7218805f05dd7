//! The surfaces of a posed and cast frame as the sensor model sees them: per beam its
//! surface (reflectance, incidence, body region), the footprint rays cast among the triangles
//! near a beam ([`FootprintScene`]), and the rolling background refined in the world.

use super::{FootprintScene, Surface, FOOTPRINT_RAYS};
use crate::backend::BeamHits;
use crate::error::{Error, Result};
use crate::geometry::FrameGeometry;
use crate::human::HumanModel;
use crate::scene::EnvDraw;
use glam::{DMat3, DMat4, DVec3};
use rayon::prelude::*;

/// Rolling shutter with a moving sensor: each placed environment vertex is exact at its own
/// column's time, but a large triangle's interior is interpolated between vertices taken
/// at different times (centimetres off across a wall). Each beam's hit is therefore
/// recomputed in the world: the beam from the sensor's pose at its column's time, through
/// the triangle the cast found and that triangle's one-ring (watertight f64, nearest).
/// `bg_hits`, the hits of the placed `background` (drawn from `env` as `env_meshes`), are
/// refined in place; `column_pose` is the sensor's world pose per column (of `columns`),
/// empty when the sensor did not move during the sweep (then nothing changes).
pub fn refine_rolling_background(env: &EnvWorld, background: &FrameGeometry, dirs: &[DVec3], columns: usize, bg_hits: &mut BeamHits) {
    if env.column_pose.is_empty() {
        return;
    }
    let w = columns;
    let (poses, env_meshes) = (env.column_pose, env.meshes);
    bg_hits.range_m.par_iter_mut().zip(bg_hits.triangle.par_iter_mut()).enumerate().with_min_len(512).for_each(|(b, (r, t))| {
        if *t == crate::backend::NO_TRIANGLE {
            return;
        }
        let pose = poses[b % w];
        let origin = pose.w_axis.truncate();
        let dir = DMat3::from_mat4(pose) * dirs[b];
        let Some(ray) = crate::backend::triangle::RayPre::new(dir) else { return };
        // The triangle the cast found, and its one-ring, lie in one mesh.
        let k = background.mesh_index_of_triangle(*t);
        let test = |cand: u32| -> Option<f64> {
            let (tri, cull) = world_triangle_in_mesh(background, env.positions, env_meshes, k, cand, origin);
            crate::backend::triangle::intersect_pre(&ray, &tri, cull)
        };
        // The triangle the cast found holds the exact hit but near its edges; there, its
        // one-ring.
        let mut best = test(*t).map_or((f64::INFINITY, u32::MAX), |h| (h, *t));
        if best.1 == u32::MAX {
            for cand in background.neighbours_in_mesh(k, *t) {
                if let Some(h) = test(cand) {
                    if crate::backend::triangle::better(h, cand, best.0, best.1) {
                        best = (h, cand);
                    }
                }
            }
        }
        if best.1 != u32::MAX {
            (*r, *t) = (best.0 as f32, best.1);
        }
    });
}

/// The surfaces of a posed and cast frame, as the sensor model sees them.
pub struct SceneSurfaces<'a> {
    pub humans: &'a FrameGeometry,
    pub human_hits: &'a BeamHits,
    pub background: &'a FrameGeometry,
    pub bg_hits: &'a BeamHits,
    pub recorded: Option<&'a [f32]>,
    pub recorded_intensity: &'a [f32],
    pub intensity_scale: f64,
    pub columns: usize,
    pub layout: &'a [(u32, usize, usize)],
    pub regions: &'a [Vec<Vec<u8>>],
    /// The environment's meshes as drawn, for their reflectance.
    pub env_meshes: &'a [EnvDraw],
    pub reflectance: &'a [[f32; 4]],
    pub dirs: &'a [DVec3],
    /// Under a sensor that moves during the sweep: the environment in the world and each
    /// column's sensor pose, so footprint rays meet it exactly (as the beams themselves,
    /// `refine_rolling_background`); else the placed `background` is exact.
    pub env_world: Option<EnvWorld<'a>>,
}

pub struct EnvWorld<'a> {
    pub positions: &'a [DVec3],
    pub meshes: &'a [EnvDraw],
    pub column_pose: &'a [DMat4],
}

/// Background triangle `t` of mesh `k` (global in `background`, whose meshes are
/// `env_meshes`) in the world, relative to `origin`, from the environment's f64 `positions`;
/// and whether its back face is culled.
fn world_triangle_in_mesh(background: &FrameGeometry, positions: &[DVec3], env_meshes: &[EnvDraw], k: usize, t: u32, origin: DVec3) -> ([DVec3; 3], bool) {
    let mesh = &background.meshes[k];
    let first = env_meshes[k].first_vertex as u32;
    let idx = &background.indices[3 * t as usize..3 * t as usize + 3];
    ([0, 1, 2].map(|c| positions[(first + idx[c] - mesh.first_vertex) as usize] - origin), !mesh.double_sided)
}

/// The nearest of `triangles` (triangle, corners in the sensor frame, back culled) along
/// `dir`, with the casters' watertight test and tie rule.
fn nearest_hit(triangles: &[(u32, [DVec3; 3], bool)], dir: DVec3) -> Option<(f64, u32)> {
    let ray = crate::backend::triangle::RayPre::new(dir)?;
    let mut best = (f64::INFINITY, u32::MAX);
    for &(t, ref tri, cull) in triangles {
        if let Some(h) = crate::backend::triangle::intersect_pre(&ray, tri, cull) {
            if crate::backend::triangle::better(h, t, best.0, best.1) {
                best = (h, t);
            }
        }
    }
    (best.1 != u32::MAX).then_some(best)
}

/// The background near a beam ([`SceneSurfaces::near_background`]): nothing, a recorded
/// return, or the plane (unit normal `n`, zero for a degenerate triangle; `n_dot_hit` its
/// offset through the beam's hit at range `r`) of the triangle `t` it meets.
#[derive(Clone, Copy, Debug)]
enum NearBackground {
    Nothing,
    Recorded(f64),
    Plane { n: DVec3, n_dot_hit: f64, r: f64, t: u32 },
}

impl NearBackground {
    /// Where a ray along `dir` meets it: the plane's range along the ray (the beam's own
    /// range where the ray runs along the plane), None where the plane lies behind the ray.
    fn meet(self, dir: DVec3) -> Option<(f64, u32)> {
        match self {
            NearBackground::Nothing => None,
            NearBackground::Recorded(r) => Some((r, crate::backend::NO_TRIANGLE)),
            NearBackground::Plane { n, n_dot_hit, r, t } => {
                let denom = n.dot(dir);
                if n == DVec3::ZERO || denom.abs() <= 1e-12 {
                    return Some((r, t));
                }
                let along = n_dot_hit / denom;
                (along > 0.0).then_some((along, t))
            }
        }
    }
}

/// Per thread, the footprints' candidate lists, reused from beam to beam.
#[derive(Default)]
struct Scratch {
    /// Seed triangles and their one-rings, each with its mesh.
    triangles: Vec<(u32, usize)>,
    people: Vec<(u32, [DVec3; 3], bool)>,
    env: Vec<(u32, [DVec3; 3], bool)>,
    /// The one-ring of [`SceneSurfaces::footprint_on_own_surface`].
    surface: Vec<(u32, [DVec3; 3], bool)>,
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// The candidates of one layer for a footprint: the triangles `hits` gives for `beams` and
/// their one-rings, each once and in triangle order, those the footprint's pyramid may hold
/// (`outside` false on their corners from `corners`), into `out` with their corners in the
/// sensor frame (`place` of those). A beam that meets a triangle an earlier one met adds
/// nothing; `corners` may give another frame than the sensor's (the world, about the beam's
/// origin: the pyramid turned with it), so that the many triangles outside it are never moved.
#[allow(clippy::too_many_arguments)]
fn footprint_candidates(
    geom: &FrameGeometry,
    hits: &BeamHits,
    beams: &[usize],
    outside: &dyn Fn(&[DVec3; 3]) -> bool,
    corners: &dyn Fn(usize, u32) -> [DVec3; 3],
    place: &dyn Fn([DVec3; 3]) -> [DVec3; 3],
    triangles: &mut Vec<(u32, usize)>,
    out: &mut Vec<(u32, [DVec3; 3], bool)>,
) {
    triangles.clear();
    out.clear();
    let mut seeds = [crate::backend::NO_TRIANGLE; 5];
    for (i, &nb) in beams.iter().enumerate() {
        let t = hits.triangle.get(nb).copied().unwrap_or(crate::backend::NO_TRIANGLE);
        if t != crate::backend::NO_TRIANGLE && t < geom.triangle_count() && !seeds[..i.min(5)].contains(&t) {
            // A one-ring lies in its triangle's mesh.
            let k = geom.mesh_index_of_triangle(t);
            triangles.push((t, k));
            triangles.extend(geom.neighbours_in_mesh(k, t).map(|n| (n, k)));
        }
        if i < 5 {
            seeds[i] = t;
        }
    }
    triangles.sort_unstable();
    triangles.dedup();
    for &(t, k) in triangles.iter() {
        let tri = corners(k, t);
        if !outside(&tri) {
            out.push((t, place(tri), !geom.meshes[k].double_sided));
        }
    }
}

/// |cos| of the angle between `dir` and the normal of triangle `t` (1 for a degenerate one),
/// and the unit normal (zero for a degenerate one).
fn cos_incidence(geom: &FrameGeometry, t: u32, dir: DVec3) -> (f32, glam::Vec3) {
    let [a, b, c] = geom.triangle_f64(t);
    let n = (b - a).cross(c - a);
    let len = n.length();
    if len > 0.0 && len.is_finite() { ((n.dot(dir).abs() / len) as f32, (n / len).as_vec3()) } else { (1.0, glam::Vec3::ZERO) }
}

/// Reflectance of a recorded return whose intensity is unknown (for the footprint's power).
const RECORDED_REFLECTANCE: f32 = 0.3;

impl SceneSurfaces<'_> {
    fn human_surface(&self, t: u32, range_m: f64, dir: DVec3) -> Surface {
        let k = self.humans.mesh_index_of_triangle(t);
        let mesh = &self.humans.meshes[k];
        let (instance, m, lod) = self.layout[k];
        let region = self.regions[m][lod].get((t - mesh.first_triangle) as usize).copied().unwrap_or(crate::sensor_model::UPPER);
        let reflectance = self.reflectance.get(instance as usize - 1).map_or(0.3, |r| r[region as usize]);
        let (cos_incidence, normal) = cos_incidence(self.humans, t, dir);
        Surface { range_m, instance: instance as u16, reflectance, cos_incidence, rendered: true, normal }
    }

    fn background_surface(&self, b: usize, t: u32, range_m: f64, dir: DVec3) -> Surface {
        if self.recorded.is_some() {
            // The recording's intensity (already with its incidence) in reflectance units, for
            // the footprint's power; unknown: a typical reflectance.
            let reflectance = match self.recorded_intensity.get(b) {
                Some(&i) if self.recorded_intensity.len() == self.dirs.len() => (i as f64 / self.intensity_scale).clamp(0.0, 1.0) as f32,
                _ => RECORDED_REFLECTANCE,
            };
            return Surface { range_m, instance: 0, reflectance, cos_incidence: 1.0, rendered: false, normal: glam::Vec3::ZERO };
        }
        let (reflectance, (cos, normal)) = if t == crate::backend::NO_TRIANGLE || t >= self.background.triangle_count() {
            (0.5, (1.0, glam::Vec3::ZERO))
        } else {
            let k = self.background.mesh_index_of_triangle(t);
            (self.env_meshes.get(k).map_or(0.5, |m| m.reflectance), cos_incidence(self.background, t, dir))
        };
        Surface { range_m, instance: 0, reflectance, cos_incidence: cos, rendered: true, normal }
    }

    /// The composited beam `b` (range, instance) as a surface.
    pub fn clean(&self, b: usize, range_m: f32, instance: u16) -> Option<Surface> {
        if range_m <= 0.0 {
            return None;
        }
        let dir = self.dirs[b];
        Some(if instance > 0 {
            self.human_surface(self.human_hits.triangle[b], range_m as f64, dir)
        } else {
            self.background_surface(b, self.bg_hits.triangle.get(b).copied().unwrap_or(crate::backend::NO_TRIANGLE), range_m as f64, dir)
        })
    }
}

impl SceneSurfaces<'_> {
    /// Environment triangle `t` in the sensor frame of column `col`, and whether its back face
    /// is culled: under a sensor that moves during the sweep from the world at the column's
    /// pose (the placed triangles are interpolated between their vertices' times, centimetres
    /// off across a wall), else as placed.
    fn env_triangle(&self, t: u32, col: usize) -> ([DVec3; 3], bool) {
        let k = self.background.mesh_index_of_triangle(t);
        (self.env_corners(self.column_frame(col), k, t), !self.background.meshes[k].double_sided)
    }

    /// Under a sensor that moves during the sweep: column `col`'s pose as the rotation from
    /// the world into its sensor frame and its origin (once per beam, for
    /// [`SceneSurfaces::env_corners`]).
    fn column_frame(&self, col: usize) -> Option<(DMat3, DVec3)> {
        self.env_world.as_ref().map(|e| {
            let pose = e.column_pose[col];
            (DMat3::from_mat4(pose).transpose(), pose.w_axis.truncate())
        })
    }

    /// [`SceneSurfaces::env_triangle`]'s corners of triangle `t` of mesh `k`, in the sensor
    /// frame of the column whose [`SceneSurfaces::column_frame`] is `frame`.
    fn env_corners(&self, frame: Option<(DMat3, DVec3)>, k: usize, t: u32) -> [DVec3; 3] {
        match (&self.env_world, frame) {
            (Some(e), Some((rot_t, origin))) => world_triangle_in_mesh(self.background, e.positions, e.meshes, k, t, origin).0.map(|p| rot_t * p),
            _ => self.background.triangle_f64(t),
        }
    }

    /// The nearest range beam `b` sees over both layers (infinite: nothing).
    fn nearest_range(&self, b: usize) -> f64 {
        let human = match self.human_hits.triangle.get(b) {
            Some(&t) if t != crate::backend::NO_TRIANGLE => self.human_hits.range_m[b] as f64,
            _ => f64::INFINITY,
        };
        let background = match self.recorded {
            Some(r) => r[b] as f64,
            None => self.bg_hits.range_m.get(b).copied().unwrap_or(0.0) as f64,
        };
        human.min(if background > 0.0 { background } else { f64::INFINITY })
    }

    /// The common case of a footprint, cheaply: when every neighbour across the silhouette
    /// sees something farther (or nothing) and every footprint ray meets the rendered triangle
    /// the beam itself meets or one of its one-ring, the footprint lies on that surface
    /// (nothing nearer can cover part of it, but a feature thinner than the beam spacing, as
    /// for the candidates of `cast_footprint`). Fills `out[1..]` and returns true then.
    fn footprint_on_own_surface(&self, b: usize, across: &[usize], dirs: &[DVec3; FOOTPRINT_RAYS], out: &mut [Option<Surface>; FOOTPRINT_RAYS]) -> bool {
        let Some(own) = out[0].filter(|s| s.rendered) else { return false };
        if across.iter().any(|&nb| self.nearest_range(nb) <= own.range_m) {
            return false;
        }
        let person = own.instance > 0;
        let (geom, t) = if person {
            (self.humans, self.human_hits.triangle[b])
        } else {
            (self.background, self.bg_hits.triangle.get(b).copied().unwrap_or(crate::backend::NO_TRIANGLE))
        };
        if t == crate::backend::NO_TRIANGLE || t >= geom.triangle_count() {
            return false;
        }
        // The one-ring is of the triangle's own mesh.
        let k = geom.mesh_index_of_triangle(t);
        let cull = !geom.meshes[k].double_sided;
        let frame = if person { None } else { self.column_frame(b % self.columns) };
        let found = SCRATCH.with_borrow_mut(|s| {
            s.surface.clear();
            s.surface.extend(std::iter::once(t).chain(geom.neighbours_in_mesh(k, t)).map(|c| {
                let tri = if person { geom.triangle_f64(c) } else { self.env_corners(frame, k, c) };
                (c, tri, cull)
            }));
            let mut hits = [(0.0, 0u32); FOOTPRINT_RAYS];
            for (hit, &dir) in hits.iter_mut().zip(dirs).skip(1) {
                *hit = nearest_hit(&s.surface, dir)?;
            }
            Some(hits)
        });
        let Some(hits) = found else { return false };
        for ((o, &dir), &(h, c)) in out.iter_mut().zip(dirs).zip(&hits).skip(1) {
            *o = Some(if person { self.human_surface(c, h, dir) } else { self.background_surface(b, c, h, dir) });
        }
        true
    }

    /// The background behind the people along `dir`, near beam `b`: the plane of the
    /// background triangle beam `b` meets, through its exact hit (its footprint is millimetres
    /// across; under a moving sensor the triangle's normal from the world, at the column's
    /// pose), or its recorded return. None where the plane lies behind the ray.
    #[cfg(test)]
    fn background_near(&self, b: usize, dir: DVec3) -> Option<(f64, u32)> {
        self.near_background(b).meet(dir)
    }

    /// What [`SceneSurfaces::background_near`] needs of beam `b`, once for all its rays.
    fn near_background(&self, b: usize) -> NearBackground {
        if let Some(r) = self.recorded {
            return if r[b] > 0.0 { NearBackground::Recorded(r[b] as f64) } else { NearBackground::Nothing };
        }
        let t = self.bg_hits.triangle.get(b).copied().unwrap_or(crate::backend::NO_TRIANGLE);
        let r = self.bg_hits.range_m.get(b).copied().unwrap_or(0.0) as f64;
        if t == crate::backend::NO_TRIANGLE || t >= self.background.triangle_count() || r <= 0.0 {
            return NearBackground::Nothing;
        }
        let n = match &self.env_world {
            Some(_) => {
                let [p, q, u] = self.env_triangle(t, b % self.columns).0;
                (q - p).cross(u - p).normalize_or_zero()
            }
            None => cos_incidence(self.background, t, self.dirs[b]).1.as_dvec3(),
        };
        NearBackground::Plane { n, n_dot_hit: n.dot(self.dirs[b] * r), r, t }
    }
}

/// The pyramid through the origin that holds every footprint ray of `dirs` (widened by 1 %),
/// as a test of whether a triangle (sensor frame) lies wholly outside one of its faces or
/// behind the origin, and so meets none of the rays.
fn outside_footprint(dirs: &[DVec3; FOOTPRINT_RAYS]) -> impl Fn(&[DVec3; 3]) -> bool {
    let d = dirs[0];
    let e_az = DVec3::new(-d.y, d.x, 0.0).normalize_or_zero();
    let e_el = d.cross(e_az);
    let (mut hx, mut hy) = (0.0f64, 0.0f64);
    for r in &dirs[1..] {
        let along = r.dot(d);
        hx = hx.max(r.dot(e_az).abs() / along);
        hy = hy.max(r.dot(e_el).abs() / along);
    }
    let (hx, hy) = (1.01 * hx + 1e-9, 1.01 * hy + 1e-9);
    move |tri: &[DVec3; 3]| {
        // Per corner: which faces it lies beyond (bits), ANDed over the corners.
        let beyond = |p: DVec3| -> u8 {
            let (a, x, y) = (p.dot(d), p.dot(e_az), p.dot(e_el));
            (a <= 0.0) as u8 | ((x > hx * a) as u8) << 1 | ((x < -hx * a) as u8) << 2 | ((y > hy * a) as u8) << 3 | ((y < -hy * a) as u8) << 4
        };
        beyond(tri[0]) & beyond(tri[1]) & beyond(tri[2]) != 0
    }
}

/// The footprint's surfaces are searched among the triangles the beam and its grid neighbours
/// across the silhouette hit, and those triangles' one-rings (watertight test, as the
/// casters): the footprint (a few millimetres to centimetres across) lies between those beams,
/// so its surfaces are there but for a limb, a post or a table's edge thinner than the beam
/// spacing that no neighbour hits. Where the environment is continuous around the beam (the
/// beam and its neighbours meet one triangle and its one-ring) or is a recording, a ray's
/// background is the plane the beam itself meets ([`SceneSurfaces::near_background`]); else
/// only the candidates count, and a ray that meets none of them meets nothing (past a wall's
/// top, say).
impl FootprintScene for SceneSurfaces<'_> {
    fn cast_footprint(&self, b: usize, across: &[usize], dirs: &[DVec3; FOOTPRINT_RAYS], out: &mut [Option<Surface>; FOOTPRINT_RAYS]) {
        let col = b % self.columns;
        if self.footprint_on_own_surface(b, across, dirs, out) {
            return;
        }
        // The beam and its neighbours across the silhouette.
        let mut beams = [b; 5];
        beams[1..1 + across.len().min(4)].copy_from_slice(&across[..across.len().min(4)]);
        let outside = outside_footprint(dirs);
        let frame = self.column_frame(col);
        // A rendered environment's candidates. Under a moving sensor they are taken from the
        // world into the sensor frame of the beam's column (the placed triangles are
        // interpolated between their vertices' times, centimetres off across a wall).
        // Where the beam and its neighbours meet one triangle and its one-ring, the surface is
        // continuous there and the beam's own plane holds the footprint.
        let bg_triangle = |nb: usize| self.bg_hits.triangle.get(nb).copied().unwrap_or(crate::backend::NO_TRIANGLE);
        let own = bg_triangle(b);
        let continuous = own != crate::backend::NO_TRIANGLE && own < self.background.triangle_count() && {
            let k = self.background.mesh_index_of_triangle(own);
            beams.iter().all(|&nb| {
                let t = bg_triangle(nb);
                t == own || self.background.neighbours_in_mesh(k, own).any(|n| n == t)
            })
        };
        let searched = self.recorded.is_none() && !continuous;
        let near = if searched { NearBackground::Nothing } else { self.near_background(b) };
        SCRATCH.with_borrow_mut(|s| {
            let Scratch { triangles, people, env, .. } = s;
            let same = |tri: [DVec3; 3]| tri;
            footprint_candidates(self.humans, self.human_hits, &beams, &outside, &|_, t| self.humans.triangle_f64(t), &same, triangles, people);
            if searched {
                match (&self.env_world, frame) {
                    // Under a moving sensor the environment's triangles are culled in the world
                    // (about the column's origin, the pyramid turned into the world), and only
                    // those it may hold are turned into the column's sensor frame.
                    (Some(e), Some((rot_t, origin))) => {
                        let outside_world = outside_footprint(&dirs.map(|d| rot_t.transpose() * d));
                        let world = |k: usize, t: u32| world_triangle_in_mesh(self.background, e.positions, e.meshes, k, t, origin).0;
                        let turn = |tri: [DVec3; 3]| tri.map(|p| rot_t * p);
                        footprint_candidates(self.background, self.bg_hits, &beams, &outside_world, &world, &turn, triangles, env);
                    }
                    _ => footprint_candidates(self.background, self.bg_hits, &beams, &outside, &|k, t| self.env_corners(frame, k, t), &same, triangles, env),
                }
            }
            for (o, &dir) in out.iter_mut().zip(dirs).skip(1) {
                let human = nearest_hit(people, dir);
                let background = if searched { nearest_hit(env, dir) } else { near.meet(dir) };
                *o = match (human, background) {
                    (Some((h, t)), bg) if bg.is_none_or(|(r, _)| h < r) => Some(self.human_surface(t, h, dir)),
                    (_, Some((r, t))) => Some(self.background_surface(b, t, r, dir)),
                    _ => None,
                };
            }
        });
    }
}

/// Per level of detail, per triangle: the body region of a model's triangles (the region of
/// the joint that weighs most on the majority of its corners), from the skin's joint names.
pub fn body_regions(model: &HumanModel) -> Result<Vec<Vec<u8>>> {
    let names: Vec<String> = if model.lods.iter().all(|l| l.joints.is_empty()) {
        Vec::new()
    } else {
        let doc = gltf::Gltf::open(&model.path).map_err(|e| Error::input(model.path.display(), e))?;
        doc.skins().next().map_or_else(Vec::new, |s| s.joints().map(|n| n.name().unwrap_or("").to_string()).collect())
    };
    let joint_region: Vec<u8> = names.iter().map(|n| crate::sensor_model::region_of_joint(n)).collect();
    Ok(model
        .lods
        .iter()
        .map(|l| {
            let vertex = |i: u32| -> u8 {
                let i = i as usize;
                let (Some(j), Some(w)) = (l.joints.get(i), l.weights.get(i)) else { return crate::sensor_model::UPPER };
                let k = (0..4).max_by(|&a, &b| w[a].total_cmp(&w[b])).unwrap_or(0);
                joint_region.get(j[k] as usize).copied().unwrap_or(crate::sensor_model::UPPER)
            };
            l.indices
                .chunks_exact(3)
                .map(|t| {
                    let (a, b, c) = (vertex(t[0]), vertex(t[1]), vertex(t[2]));
                    if b == c { b } else { a }
                })
                .collect()
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor_model::{LOWER, SHOES, SKIN, UPPER};

    /// The environment's one mesh as drawn: four vertices, `indices`, reflectance 0.25.
    fn quad_draw(indices: &[u32]) -> EnvDraw {
        EnvDraw {
            first_vertex: 0,
            vertex_count: 4,
            local_indices: indices.to_vec(),
            double_sided: false,
            adjacency: std::sync::Arc::new(crate::geometry::Adjacency::build(indices)),
            reflectance: 0.25,
            class: 0,
        }
    }

    /// Two triangles facing the sensor (normal -x) at `x`, side by side.
    fn quad(x: f32) -> (Vec<[f32; 3]>, Vec<u32>) {
        (vec![[x, -1.0, -1.0], [x, 1.0, -1.0], [x, 1.0, 1.0], [x, -1.0, 1.0]], vec![0, 2, 1, 0, 3, 2])
    }

    /// The incidence on a triangle: |cos| against its normal whichever way it faces, and for a
    /// triangle of no area (no normal) head-on with a zero normal, not NaN.
    #[test]
    fn incidence_is_the_cosine_to_the_normal_and_head_on_without_one() {
        let mut g = FrameGeometry::default();
        g.push_mesh(&[[2.0, 0.0, 0.0], [2.0, 1.0, 0.0], [2.0, 0.0, 1.0], [3.0, 0.0, 0.0], [3.0, 1.0, 1.0], [3.0, 2.0, 2.0]], &[0, 1, 2, 3, 4, 5], 1, false);
        let dir = DVec3::new(3.0, 4.0, 0.0) / 5.0;
        let (cos, n) = cos_incidence(&g, 0, dir);
        assert!((cos - 0.6).abs() < 1e-6 && (n.x.abs() - 1.0).abs() < 1e-6 && n.y == 0.0 && n.z == 0.0, "{cos} {n}");
        assert_eq!(cos_incidence(&g, 1, dir), (1.0, glam::Vec3::ZERO));
    }

    /// Each beam's surface takes the reflectance its person drew for the region of the very
    /// triangle it hit, counted within that person's own mesh (the second person's triangles
    /// come after the first's in the frame); the background's comes from its mesh, and a
    /// triangle index the frame does not hold gets the typical 0.5, not a panic.
    #[test]
    fn a_beams_surface_has_the_reflectance_of_its_triangles_region_and_mesh() {
        let mut humans = FrameGeometry::default();
        let (p, i) = quad(3.0);
        humans.push_mesh(&p, &i, 1, false);
        let (p, i) = quad(4.0);
        humans.push_mesh(&p, &i, 2, false);
        let mut background = FrameGeometry::default();
        let (p, i) = quad(9.0);
        background.push_mesh(&p, &i, 0, false);
        let env_meshes = vec![quad_draw(&i)];
        // Person 1 (model 0) and person 2 (model 1), each model's one level of detail.
        let layout = [(1u32, 0usize, 0usize), (2, 1, 0)];
        let regions = [vec![vec![SKIN, SHOES]], vec![vec![LOWER, UPPER]]];
        let reflectance = [[0.1f32, 0.2, 0.3, 0.4], [0.5, 0.6, 0.7, 0.8]];
        let dirs = vec![DVec3::X; 7];
        let human_hits = BeamHits { range_m: vec![3.0, 3.0, 4.0, 4.0, 0.0, 0.0, 0.0], triangle: vec![0, 1, 2, 3, u32::MAX, u32::MAX, u32::MAX] };
        let bg_hits = BeamHits { range_m: vec![9.0; 7], triangle: vec![0, 0, 0, 0, 1, crate::backend::NO_TRIANGLE, 2] };
        let s = SceneSurfaces {
            humans: &humans,
            human_hits: &human_hits,
            background: &background,
            bg_hits: &bg_hits,
            recorded: None,
            recorded_intensity: &[],
            intensity_scale: 1.0,
            columns: 7,
            layout: &layout,
            regions: &regions,
            env_meshes: &env_meshes,
            reflectance: &reflectance,
            dirs: &dirs,
            env_world: None,
        };
        for (b, instance, want) in [(0, 1, 0.1), (1, 1, 0.4), (2, 2, 0.7), (3, 2, 0.6), (4, 0, 0.25), (5, 0, 0.5), (6, 0, 0.5)] {
            let surface = s.clean(b, 5.0, instance).expect("a return");
            assert_eq!((surface.reflectance, surface.instance, surface.rendered), (want, instance, true), "beam {b}");
            assert_eq!(surface.cos_incidence, 1.0, "beam {b}: head on");
        }
        assert!(s.clean(0, 0.0, 1).is_none(), "no return, no surface");
    }

    /// A person's edge at 3 m in front of a tilted wall (the plane x + y / 2 = 9): the person
    /// a quad facing the sensor over y in [-0.001, 1]; the wall two triangles over y in
    /// [-10, 12], z in [-10, 10]. Beam 0 looks along +x (the person's edge), beam 1 slightly
    /// to the right (-y: the wall only).
    struct EdgeScene {
        humans: FrameGeometry,
        background: FrameGeometry,
        env_meshes: Vec<EnvDraw>,
        wall: Vec<DVec3>,
        human_hits: BeamHits,
        bg_hits: BeamHits,
        dirs: Vec<DVec3>,
        poses: Vec<DMat4>,
        regions: Vec<Vec<Vec<u8>>>,
    }

    const WALL: DVec3 = DVec3::new(1.0, 0.5, 0.0);

    /// The tilted wall's four corners over y in [-10, `y_max`], z in [-10, 10], and the wall as
    /// a frame's background: two triangles, wound (as [`quad`]'s) to face the sensor.
    fn tilted_wall(y_max: f64) -> (Vec<DVec3>, FrameGeometry) {
        let wall: Vec<DVec3> = [(-10.0, -10.0), (y_max, -10.0), (y_max, 10.0), (-10.0, 10.0)].iter().map(|&(y, z)| DVec3::new(9.0 - 0.5 * y, y, z)).collect();
        let mut background = FrameGeometry::default();
        background.push_mesh(&wall.iter().map(|p| p.as_vec3().to_array()).collect::<Vec<_>>(), &quad(0.0).1, 0, false);
        (wall, background)
    }

    /// Where the plane `n . p = n . (dir0 * r0)` meets the ray along `dir`.
    fn on_plane(n: DVec3, dir0: DVec3, r0: f64, dir: DVec3) -> f64 {
        n.dot(dir0 * r0) / n.dot(dir)
    }

    impl EdgeScene {
        fn new() -> EdgeScene {
            let mut humans = FrameGeometry::default();
            let person = [[3.0, -0.001, -1.0], [3.0, 1.0, -1.0], [3.0, 1.0, 1.0], [3.0, -0.001, 1.0]];
            humans.push_mesh(&person, &quad(0.0).1, 1, false);
            let (wall, background) = tilted_wall(12.0);
            let env_meshes = vec![quad_draw(&quad(0.0).1)];
            let dirs = vec![DVec3::X, DVec3::new(0.01f64.cos(), -(0.01f64.sin()), 0.0)];
            let wall_range = |d: DVec3| on_plane(WALL, DVec3::X, 9.0, d);
            // Both beams meet the wall's upper-left triangle (1) behind; beam 0 the person's 1.
            let human_hits = BeamHits { range_m: vec![3.0, 0.0], triangle: vec![1, crate::backend::NO_TRIANGLE] };
            let bg_hits = BeamHits { range_m: vec![9.0, wall_range(dirs[1]) as f32], triangle: vec![1, 1] };
            EdgeScene { humans, background, env_meshes, wall, human_hits, bg_hits, dirs, poses: Vec::new(), regions: vec![vec![vec![UPPER; 2]]] }
        }

        fn scene(&self) -> SceneSurfaces<'_> {
            SceneSurfaces {
                humans: &self.humans,
                human_hits: &self.human_hits,
                background: &self.background,
                bg_hits: &self.bg_hits,
                recorded: None,
                recorded_intensity: &[],
                intensity_scale: 1.0,
                columns: 2,
                layout: &[(1, 0, 0)],
                regions: &self.regions,
                env_meshes: &self.env_meshes,
                reflectance: &[[0.6; 4]],
                dirs: &self.dirs,
                env_world: (!self.poses.is_empty()).then(|| EnvWorld { positions: &self.wall, meshes: &self.env_meshes, column_pose: &self.poses }),
            }
        }
    }

    /// A footprint across the person's edge: the rays left of it meet the person, the others
    /// the wall's plane through the beam's own hit (the wall is continuous around the beam and
    /// its neighbour across the silhouette), each at its own range along its own direction.
    #[test]
    fn a_footprint_across_an_edge_meets_the_person_and_the_wall_plane_behind() {
        let e = EdgeScene::new();
        let s = e.scene();
        let dirs = crate::sensor_model::footprint_dirs(0.0, 0.0, [20.0, 20.0]);
        let mut out = [None; FOOTPRINT_RAYS];
        out[0] = s.clean(0, 3.0, 1);
        s.cast_footprint(0, &[1], &dirs, &mut out);
        let (mut person, mut wall) = (0, 0);
        for (k, (o, &d)) in out.iter().zip(&dirs).enumerate().skip(1) {
            let o = o.expect("every ray meets something");
            if d.y > 0.0 {
                assert_eq!(o.instance, 1, "ray {k}");
                assert!((o.range_m - 3.0 / d.x).abs() < 1e-9, "ray {k}: {}", o.range_m);
                person += 1;
            } else {
                assert_eq!((o.instance, o.reflectance), (0, 0.25), "ray {k}");
                assert!((o.range_m - on_plane(WALL, DVec3::X, 9.0, d)).abs() < 1e-9, "ray {k}: {}", o.range_m);
                wall += 1;
            }
        }
        assert_eq!((person, wall), (3, 3));
        // A hit naming no triangle of the frame (past its last) counts as no hit: the same
        // footprint as with the neighbour's miss.
        let mut stale = EdgeScene::new();
        stale.human_hits.triangle[1] = 7;
        let mut again = [None; FOOTPRINT_RAYS];
        again[0] = out[0];
        stale.scene().cast_footprint(0, &[1], &dirs, &mut again);
        assert_eq!(again, out);
        // The same for the background behind a ray.
        stale.bg_hits.triangle[1] = 7;
        assert_eq!(stale.scene().background_near(1, dirs[1]), None);
    }

    /// A recording's intensities are read only when they cover the grid: one of another
    /// length (another sensor's) gives the typical reflectance, as none does.
    #[test]
    fn recorded_intensities_of_another_grid_are_not_read() {
        let e = EdgeScene::new();
        let recorded = [7.0f32, 7.0];
        for (intensity, want) in [(&[0.9f32, 0.8][..], 0.9), (&[0.9][..], RECORDED_REFLECTANCE), (&[][..], RECORDED_REFLECTANCE)] {
            let s = SceneSurfaces { recorded: Some(&recorded), recorded_intensity: intensity, ..e.scene() };
            let surface = s.clean(0, 7.0, 0).expect("a return");
            assert_eq!((surface.reflectance, surface.rendered), (want, false), "{} intensities", intensity.len());
        }
    }

    /// Under a moving sensor each beam's hit is refined in the world, from its column's pose:
    /// on a double-sided wall seen from its back (wound away from the sensor) too, at the
    /// range of the plane x = 5 along the beam from where the sensor is at that column.
    #[test]
    fn a_double_sided_wall_seen_from_behind_is_refined_in_the_world() {
        let world = [DVec3::new(5.0, -10.0, -10.0), DVec3::new(5.0, 0.0, 10.0), DVec3::new(5.0, 10.0, -10.0)];
        for (indices, double_sided, refined) in [([0u32, 1, 2], false, true), ([0, 2, 1], true, true), ([0, 2, 1], false, false)] {
            let mut background = FrameGeometry::default();
            background.push_mesh(&world.map(|p| p.as_vec3().to_array()), &indices, 0, double_sided);
            let env_meshes = vec![EnvDraw { first_vertex: 0, vertex_count: 3, local_indices: indices.to_vec(), double_sided, adjacency: std::sync::Arc::new(crate::geometry::Adjacency::build(&indices)), reflectance: 0.5, class: 0 }];
            let columns = 4;
            let dirs: Vec<DVec3> = (0..columns).map(|c| DVec3::new(1.0, 0.1 * (c as f64 - 1.5), 0.05).normalize()).collect();
            let poses: Vec<DMat4> = (0..columns).map(|c| DMat4::from_translation(DVec3::new(0.3 * c as f64, 0.02 * c as f64, 0.0))).collect();
            let mut hits = BeamHits { range_m: vec![1.0; columns], triangle: vec![0; columns] };
            refine_rolling_background(&EnvWorld { positions: &world, meshes: &env_meshes, column_pose: &poses }, &background, &dirs, columns, &mut hits);
            for (c, d) in dirs.iter().enumerate() {
                // Refined: the plane's range to f32 rounding; else the cast's range, kept.
                let want = if refined { (5.0 - 0.3 * c as f64) / d.x } else { 1.0 };
                assert!((hits.range_m[c] as f64 - want).abs() < 1e-5, "column {c}, indices {indices:?}, double-sided {double_sided}: {}", hits.range_m[c]);
            }
        }
    }

    /// Under a sensor that turns during the sweep, the wall's plane behind beam 1 has the
    /// normal of beam 1's own column (turned 0.2 rad), not column 0's.
    #[test]
    fn under_a_turning_sensor_the_wall_plane_is_taken_at_the_beams_own_column() {
        let mut e = EdgeScene::new();
        let turn = DMat3::from_rotation_z(0.2);
        e.poses = vec![DMat4::IDENTITY, DMat4::from_mat3(turn)];
        let s = e.scene();
        let dirs = crate::sensor_model::footprint_dirs(-0.01, 0.0, [20.0, 20.0]);
        let n = turn.transpose() * WALL;
        for (k, &d) in dirs.iter().enumerate().skip(1) {
            let (r, t) = s.background_near(1, d).expect("the plane lies ahead");
            assert_eq!(t, 1);
            let want = on_plane(n, e.dirs[1], e.bg_hits.range_m[1] as f64, d);
            assert!((r - want).abs() < 1e-6, "ray {k}: {r} vs {want}");
            let unturned = on_plane(WALL, e.dirs[1], e.bg_hits.range_m[1] as f64, d);
            assert!((want - unturned).abs() > 1e-4, "ray {k}: the turn shows");
        }
    }

    /// Under a sensor that moves and turns during the sweep, a footprint at an edge (the beam
    /// on a near wall, its neighbour across the silhouette on a far one: a search) meets, ray
    /// by ray, what the nearest of all the environment's triangles placed in the beam's own
    /// column frame gives: the candidates culled in the world lose none that a ray meets.
    #[test]
    fn under_a_moving_sensor_a_searched_footprint_meets_the_nearest_of_all_triangles() {
        // Two quads of one mesh, not touching: a near wall ending at y = 0 and a far one, each
        // narrower than the sensor's turn (a pyramid turned the wrong way would miss both).
        let world: Vec<DVec3> = [(5.0, -0.3, -1.0), (5.0, 0.0, -1.0), (5.0, 0.0, 1.0), (5.0, -0.3, 1.0), (8.0, -0.5, -1.0), (8.0, 0.5, -1.0), (8.0, 0.5, 1.0), (8.0, -0.5, 1.0)]
            .iter()
            .map(|&(x, y, z)| DVec3::new(x, y, z))
            .collect();
        let indices = [0u32, 2, 1, 0, 3, 2, 4, 6, 5, 4, 7, 6];
        let adjacency = std::sync::Arc::new(crate::geometry::Adjacency::build(&indices));
        let mut background = FrameGeometry::default();
        background.push_mesh_with_adjacency(&world.iter().map(|p| p.as_vec3().to_array()).collect::<Vec<_>>(), &indices, 0, false, Some(adjacency.clone()));
        let env_meshes = vec![EnvDraw { first_vertex: 0, vertex_count: 8, local_indices: indices.to_vec(), double_sided: false, adjacency, reflectance: 0.25, class: 0 }];
        let poses = vec![
            DMat4::from_rotation_translation(glam::DQuat::from_rotation_z(0.3), DVec3::new(0.2, 0.03, 0.01)),
            DMat4::from_rotation_translation(glam::DQuat::from_rotation_z(0.305), DVec3::new(0.25, 0.035, 0.01)),
        ];
        let mut e = EdgeScene::new();
        e.background = background;
        e.env_meshes = env_meshes;
        e.wall = world;
        e.poses = poses;
        // Beam 0 just left of the near wall's edge as its column sees it, beam 1 past it.
        let edge = {
            let p = e.poses[0].inverse().transform_point3(DVec3::new(5.0, 0.0, 0.0));
            p.y.atan2(p.x)
        };
        e.dirs = vec![DVec3::new((edge - 0.002).cos(), (edge - 0.002).sin(), 0.0), DVec3::new((edge + 0.01).cos(), (edge + 0.01).sin(), 0.0)];
        e.human_hits = BeamHits { range_m: vec![0.0; 2], triangle: vec![crate::backend::NO_TRIANGLE; 2] };
        // Every triangle in column `col`'s sensor frame, and the nearest along `dir`.
        let all = |e: &EdgeScene, col: usize| -> Vec<(u32, [DVec3; 3], bool)> {
            let s = e.scene();
            (0..4u32).map(|t| (t, s.env_triangle(t, col).0, true)).collect()
        };
        let hit0 = nearest_hit(&all(&e, 0), e.dirs[0]).expect("beam 0 meets the near wall");
        let hit1 = nearest_hit(&all(&e, 1), e.dirs[1]).expect("beam 1 meets the far wall");
        assert!(hit0.1 < 2 && hit1.1 >= 2, "{hit0:?} {hit1:?}");
        e.bg_hits = BeamHits { range_m: vec![hit0.0 as f32, hit1.0 as f32], triangle: vec![hit0.1, hit1.1] };
        let s = e.scene();
        let dirs = crate::sensor_model::footprint_dirs(edge - 0.002, 0.0, [6.0, 6.0]);
        let mut out = [None; FOOTPRINT_RAYS];
        out[0] = s.clean(0, hit0.0 as f32, 0);
        s.cast_footprint(0, &[1], &dirs, &mut out);
        let (mut near, mut far) = (0, 0);
        for (k, (o, &d)) in out.iter().zip(&dirs).enumerate().skip(1) {
            let (r, t) = nearest_hit(&all(&e, 0), d).expect("every ray meets a wall");
            let o = o.unwrap_or_else(|| panic!("ray {k} meets a wall"));
            assert_eq!(o.range_m, r, "ray {k}");
            if t < 2 { near += 1 } else { far += 1 }
        }
        assert!(near > 0 && far > 0, "the footprint straddles the edge: {near} near, {far} far");
    }

    /// In the middle of the wall, every footprint ray meets the beam's own triangle or its
    /// one-ring: the footprint is settled there, without a search, at the wall's plane.
    #[test]
    fn a_footprint_inside_one_surface_is_settled_on_it() {
        let e = EdgeScene::new();
        let s = e.scene();
        let dirs = crate::sensor_model::footprint_dirs(-0.01, 0.0, [3.0, 3.0]);
        let mut out = [None; FOOTPRINT_RAYS];
        out[0] = s.clean(1, e.bg_hits.range_m[1], 0);
        assert!(s.footprint_on_own_surface(1, &[], &dirs, &mut out));
        for (k, (o, &d)) in out.iter().zip(&dirs).enumerate().skip(1) {
            let o = o.expect("the wall");
            assert!((o.range_m - on_plane(WALL, DVec3::X, 9.0, d)).abs() < 1e-9, "ray {k}");
        }
        // A neighbour seeing something nearer (the person) may cover part of it: not settled.
        out[1..].fill(None);
        assert!(!s.footprint_on_own_surface(1, &[0], &dirs, &mut out));
        // Inside the person (0.1 rad left of its edge), its neighbour across the silhouette
        // sees the wall, farther: settled on the person's plane.
        let dirs = crate::sensor_model::footprint_dirs(0.1, 0.0, [3.0, 3.0]);
        let mut out = [None; FOOTPRINT_RAYS];
        out[0] = s.clean(0, 3.0, 1);
        assert!(s.footprint_on_own_surface(0, &[1], &dirs, &mut out));
        for (k, (o, &d)) in out.iter().zip(&dirs).enumerate().skip(1) {
            let o = o.expect("the person");
            assert!(o.instance == 1 && (o.range_m - 3.0 / d.x).abs() < 1e-9, "ray {k}: {o:?}");
        }
    }

    /// A person's surface folded over itself: a triangle facing the sensor at x = 3 and, over
    /// its left edge, a neighbour folded back in front of it (x = 2.75 on the beam) that faces
    /// away. A person's triangles are one-sided, as the casters see them: the footprint is
    /// settled on the front triangle's plane; the back face in front of it is not met.
    #[test]
    fn a_persons_back_face_in_a_footprint_is_not_met() {
        let mut e = EdgeScene::new();
        let verts = [[3.0, -2.0, -2.0], [3.0, 0.0, 2.0], [3.0, 2.0, -2.0], [2.5, 0.5, -1.0]];
        e.humans = FrameGeometry::default();
        let indices = [0, 1, 2, 0, 3, 1];
        e.humans.push_mesh_with_adjacency(&verts, &indices, 1, false, Some(std::sync::Arc::new(crate::geometry::Adjacency::build(&indices))));
        assert_eq!(e.humans.neighbours(0).collect::<Vec<_>>(), [1], "the fold is in the front triangle's one-ring");
        e.human_hits = BeamHits { range_m: vec![3.0, 0.0], triangle: vec![0, crate::backend::NO_TRIANGLE] };
        let s = e.scene();
        let dirs = crate::sensor_model::footprint_dirs(0.0, 0.0, [3.0, 3.0]);
        // The fold's plane crosses every ray in front of the front triangle.
        let (fold, corner) = (DVec3::new(8.0, 2.0, -1.0), DVec3::from(verts[0].map(f64::from)));
        assert!(dirs.iter().all(|&d| on_plane(fold, corner.normalize(), corner.length(), d) < 3.0 / d.x));
        let mut out = [None; FOOTPRINT_RAYS];
        out[0] = s.clean(0, 3.0, 1);
        assert!(s.footprint_on_own_surface(0, &[], &dirs, &mut out));
        for (k, (o, &d)) in out.iter().zip(&dirs).enumerate().skip(1) {
            let o = o.expect("the front triangle");
            assert!((o.range_m - 3.0 / d.x).abs() < 1e-9, "ray {k}: {}", o.range_m);
        }
    }

    /// Over a recorded background, a footprint ray off the person meets the beam's recorded
    /// return, and nothing where the recording has none there (range 0).
    #[test]
    fn a_recorded_beam_without_a_return_gives_the_footprint_no_background() {
        let e = EdgeScene::new();
        let dirs = crate::sensor_model::footprint_dirs(0.0, 0.0, [20.0, 20.0]);
        for (recorded, want) in [([7.0f32, 7.0], Some(7.0)), ([0.0, 7.0], None)] {
            let s = SceneSurfaces { recorded: Some(&recorded), ..e.scene() };
            let mut out = [None; FOOTPRINT_RAYS];
            out[0] = s.clean(0, 3.0, 1);
            s.cast_footprint(0, &[1], &dirs, &mut out);
            for (k, (o, &d)) in out.iter().zip(&dirs).enumerate().skip(1) {
                if d.y > 0.0 {
                    assert_eq!(o.map(|o| o.instance), Some(1), "ray {k}");
                } else {
                    assert_eq!(o.map(|o| (o.range_m, o.instance, o.rendered)), want.map(|r| (r, 0, false)), "ray {k}");
                }
            }
        }
    }

    /// The footprint's pyramid excludes a triangle only when it lies wholly beyond one face or
    /// behind the sensor; a triangle around any ray, or across the pyramid, stays.
    #[test]
    fn the_footprint_pyramid_excludes_only_what_lies_beyond_a_face() {
        let dirs = crate::sensor_model::footprint_dirs(0.4, -0.2, [3.0, 3.0]);
        let outside = outside_footprint(&dirs);
        let d = dirs[0];
        let e_az = DVec3::new(-d.y, d.x, 0.0).normalize();
        let e_el = d.cross(e_az);
        // A small triangle around the point at `r` along `dir`, shifted by (x, y) in metres.
        let tri = |dir: DVec3, r: f64, x: f64, y: f64| {
            let c = dir * r + e_az * x + e_el * y;
            [c + e_az * 0.001, c - e_az * 0.001 + e_el * 0.001, c - e_el * 0.001]
        };
        for (k, &ray) in dirs.iter().enumerate() {
            assert!(!outside(&tri(ray, 10.0, 0.0, 0.0)), "ray {k}");
        }
        // 10 m away the footprint is ~2 cm across: 5 cm to any side is beyond that face.
        for (x, y) in [(0.05, 0.0), (-0.05, 0.0), (0.0, 0.05), (0.0, -0.05)] {
            assert!(outside(&tri(d, 10.0, x, y)), "({x}, {y})");
        }
        assert!(outside(&tri(-d, 10.0, 0.0, 0.0)), "behind the sensor");
        // A long sliver from one side to the other crosses every ray's plane: it stays.
        let across = [d * 10.0 + e_az * 0.05 + e_el * 0.0005, d * 10.0 - e_az * 0.05 + e_el * 0.0005, d * 10.0 - e_az * 0.05 - e_el * 0.0005];
        assert!(!outside(&across));
        // Without divergence along one axis every ray lies in one plane (level, or upright
        // straight ahead, so exactly): a triangle that reaches a few nanometres past that plane
        // still crosses the rays.
        for (az, el, divergence, across) in [(0.4, 0.0, [3.0, 0.0], DVec3::Z), (0.0, 0.3, [0.0, 3.0], DVec3::Y)] {
            let fan = crate::sensor_model::footprint_dirs(az, el, divergence);
            let d = fan[0];
            let along = d.cross(across).normalize();
            let near = d * 10.0 - across * 5e-9;
            let grazing = [near + along * 0.001, near - along * 0.001, d * 10.0 + across * 0.001];
            assert!(!outside_footprint(&fan)(&grazing), "divergence {divergence:?}");
        }
    }

    /// A beam at the wall's edge with no neighbour across a silhouette: the wall is continuous
    /// around the beam, so every footprint ray meets its plane, also the rays that pass just
    /// beyond the edge (the footprint is millimetres across; the cast only found the edge's
    /// triangles).
    #[test]
    fn at_a_continuous_surfaces_edge_the_footprint_stays_on_its_plane() {
        let mut e = EdgeScene::new();
        // The wall ends 2 mm right of beam 0 (at y = 0.002 m, 9 m away).
        e.background = tilted_wall(0.002).1;
        e.human_hits = BeamHits { range_m: vec![0.0; 2], triangle: vec![crate::backend::NO_TRIANGLE; 2] };
        let s = e.scene();
        let dirs = crate::sensor_model::footprint_dirs(0.0, 0.0, [3.0, 3.0]);
        let mut out = [None; FOOTPRINT_RAYS];
        out[0] = s.clean(0, 9.0, 0);
        s.cast_footprint(0, &[], &dirs, &mut out);
        let beyond = dirs.iter().filter(|d| 9.0 * d.y / d.x > 0.002).count();
        assert!(beyond >= 2, "{beyond} rays pass beyond the edge");
        for (k, (o, &d)) in out.iter().zip(&dirs).enumerate().skip(1) {
            let o = o.unwrap_or_else(|| panic!("ray {k} meets the plane"));
            assert!((o.range_m - on_plane(WALL, DVec3::X, 9.0, d)).abs() < 1e-9, "ray {k}");
        }
    }
}
