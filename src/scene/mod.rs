//! Stage 3: the scene of a sequence. A static environment (glTF, rendered as background),
//! its walkable area (floor minus obstacles, as a clearance grid), the sensor's trajectory and
//! the people's trajectories, all in the world frame (right-handed, metres, z up, floor z = 0).
//!
//! Trajectories are circular arcs at constant speed and yaw rate (a straight line when the yaw
//! rate is 0): smooth, with exact positions, velocities and headings at any time, so the
//! velocity labels need no numerical differentiation.


pub mod not_scored;
pub mod planner;
pub mod recorded;
pub mod sequence;
pub mod world;

use crate::error::{Error, Result};
use crate::human::checks;
use glam::{DMat4, DVec2, DVec3};
use rand::RngExt;
use std::path::Path;

/// Cell size of the walkable-area grid, metres.
pub const WALKABLE_CELL_M: f64 = 0.1;

/// The most cells a [`WalkableGrid`] may have (about 2 GB of working memory while it is built;
/// 0.5 km² at [`WALKABLE_CELL_M`]). A larger area is an input error, never an allocation.
pub const MAX_GRID_CELLS: usize = 50_000_000;

/// Most triangles an environment may instance, all its nodes together; vertices may be three
/// times as many.
pub const MAX_ENVIRONMENT_TRIANGLES: usize = 10_000_000;

/// A static environment in the world frame (f64).
#[derive(Clone, Debug, Default)]
pub struct Environment {
    pub positions: Vec<DVec3>,
    /// Per mesh: local indices (3 per triangle) into `positions`, and whether it is double-sided.
    pub meshes: Vec<EnvMesh>,
}

/// One mesh of an environment.
#[derive(Clone, Debug, Default)]
pub struct EnvMesh {
    pub name: String,
    pub indices: Vec<u32>,
    pub double_sided: bool,
    /// Near-infrared reflectance for the sensor model's intensity: the material's
    /// `extras.reflectance` when it has one (0..1), else the luminance of its base colour.
    pub reflectance: f32,
    /// SemanticKITTI class of its surfaces (`/class`): the material's `extras.class` when it
    /// has one (0..65535), else 0 (unlabeled).
    pub class: u16,
}

/// One non-empty environment mesh as the frames draw it: its vertex range in
/// [`Environment::positions`], its indices local to that range, and its triangle one-rings
/// (built once per run).
#[derive(Clone)]
pub struct EnvDraw {
    pub first_vertex: usize,
    pub vertex_count: usize,
    pub local_indices: Vec<u32>,
    pub double_sided: bool,
    pub adjacency: std::sync::Arc<crate::geometry::Adjacency>,
    /// The mesh's reflectance (the sensor model's intensity).
    pub reflectance: f32,
    /// The mesh's SemanticKITTI class (0: not given).
    pub class: u16,
}

/// A material's near-infrared reflectance: `extras.reflectance` (a number in 0..1) when given,
/// else the Rec. 709 luminance of its base colour factor (a visible-light stand-in).
fn material_reflectance(m: &gltf::Material) -> f32 {
    let extra = m.extras().as_ref().and_then(|raw| serde_json::from_str::<serde_json::Value>(raw.get()).ok());
    if let Some(r) = extra.as_ref().and_then(|v| v.get("reflectance")).and_then(|v| v.as_f64()) {
        if (0.0..=1.0).contains(&r) {
            return r as f32;
        }
    }
    let [r, g, b, _] = m.pbr_metallic_roughness().base_color_factor();
    (0.2126 * r + 0.7152 * g + 0.0722 * b).clamp(0.0, 1.0)
}

/// A material's SemanticKITTI class: `extras.class` (an integer in 0..65535) when given, else 0.
fn material_class(m: &gltf::Material) -> u16 {
    let extra = m.extras().as_ref().and_then(|raw| serde_json::from_str::<serde_json::Value>(raw.get()).ok());
    extra.as_ref().and_then(|v| v.get("class")).and_then(|v| v.as_u64()).and_then(|c| u16::try_from(c).ok()).unwrap_or(0)
}

/// The index in `0..n` (n > 0) that `u`, drawn evenly in [0, 1), picks evenly: every even choice
/// of a scene's things, people and paths draws this way, one number a choice.
pub fn even_index(u: f64, n: usize) -> usize {
    ((u * n as f64) as usize).min(n - 1)
}

/// A person's model among `n` loaded by [`crate::human::carry::equip`] with share `carrying`:
/// a body drawn evenly, then, with probability `carrying`, a kind of
/// [`crate::human::carry::CARRIED`] drawn evenly. With `carrying` 0 it draws exactly what an
/// even draw over the models drew before (one number).
pub fn pick_model(rng: &mut impl rand::Rng, n: usize, carrying: f64) -> usize {
    let kinds = if carrying > 0.0 { crate::human::carry::CARRIED.len() } else { 0 };
    let bodies = n / (kinds + 1);
    let body = even_index(rng.random::<f64>(), bodies);
    if kinds > 0 && rng.random::<f64>() < carrying {
        body + bodies * (1 + even_index(rng.random::<f64>(), kinds))
    } else {
        body
    }
}

/// glTF (y up) -> world (z up): `(x, y, z)_world = (x, -z, y)_gltf`, as Blender exports.
pub fn world_from_gltf() -> DMat4 {
    DMat4::from_cols_array(&[1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
}

impl Environment {
    /// Its non-empty meshes as the frames draw them.
    pub fn draws(&self) -> Vec<EnvDraw> {
        self.meshes
            .iter()
            .filter(|m| !m.indices.is_empty())
            .map(|m| {
                let lo = *m.indices.iter().min().unwrap_or(&0);
                let hi = *m.indices.iter().max().unwrap_or(&0);
                let local_indices: Vec<u32> = m.indices.iter().map(|i| i - lo).collect();
                let adjacency = std::sync::Arc::new(crate::geometry::Adjacency::build(&local_indices));
                EnvDraw {
                    first_vertex: lo as usize,
                    vertex_count: (hi - lo + 1) as usize,
                    local_indices,
                    double_sided: m.double_sided,
                    adjacency,
                    reflectance: m.reflectance,
                    class: m.class,
                }
            })
            .collect()
    }

    /// Loads every mesh of the default scene of a glTF/GLB file, with node transforms applied.
    /// The nodes must form strict trees, every accessor read must be what its reader assumes
    /// and fit in its buffer, and the instanced meshes together hold at most
    /// [`MAX_ENVIRONMENT_TRIANGLES`] triangles; all of it is checked before anything is copied.
    pub fn load(path: &Path) -> Result<Environment> {
        let bad = |m: String| Error::input(path.display(), m);
        let bytes = std::fs::read(path).map_err(|e| bad(format!("cannot read: {e}")))?;
        let gltf = checks::parse(&bytes).map_err(bad)?;
        let base = path.parent().map(Path::to_path_buf);
        let buffers = gltf::import_buffers(&gltf.document, base.as_deref(), gltf.blob.clone())
            .map_err(|e| bad(format!("cannot read buffers: {e}")))?;
        let doc = &gltf.document;
        let scene = doc
            .default_scene()
            .or_else(|| doc.scenes().next())
            .ok_or_else(|| bad("has no scene".into()))?;
        let parents = checks::node_parents(path, doc)?;
        checks::scene_roots(path, &scene, &parents)?;
        // The nodes in walk order with their global transforms: strict trees, so each node
        // once.
        let mut placed: Vec<(gltf::Node, DMat4)> = Vec::new();
        let mut stack: Vec<(gltf::Node, DMat4)> = scene.nodes().map(|n| (n, world_from_gltf())).collect();
        while let Some((node, parent)) = stack.pop() {
            let local = DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(|v| v as f64)));
            let m = parent * local;
            stack.extend(node.children().map(|c| (c, m)));
            placed.push((node, m));
        }
        // Every accessor checked and the instanced copies counted before any is made.
        let (mut vertices, mut triangles) = (0usize, 0usize);
        for mesh in placed.iter().filter_map(|(node, _)| node.mesh()) {
            for prim in mesh.primitives() {
                if let Some((n, corners)) = checks::primitive(path, &mesh, &prim, &buffers, false)? {
                    vertices += n;
                    triangles += corners / 3;
                }
            }
        }
        if triangles > MAX_ENVIRONMENT_TRIANGLES || vertices > 3 * MAX_ENVIRONMENT_TRIANGLES {
            return Err(bad(format!(
                "its nodes instance {triangles} triangles ({vertices} vertices); at most {MAX_ENVIRONMENT_TRIANGLES} triangles and {} vertices are supported",
                3 * MAX_ENVIRONMENT_TRIANGLES
            )));
        }
        let mut env = Environment::default();
        for (node, m) in placed {
            let Some(mesh) = node.mesh() else { continue };
            for prim in mesh.primitives() {
                if prim.mode() != gltf::mesh::Mode::Triangles {
                    continue;
                }
                let reader = prim.reader(|b| Some(&buffers[b.index()]));
                let Some(pos) = reader.read_positions() else { continue };
                let base = env.positions.len() as u32;
                let before = env.positions.len();
                env.positions.extend(pos.map(|p| m.transform_point3(DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64))));
                let n = (env.positions.len() - before) as u32;
                let indices: Vec<u32> = match reader.read_indices() {
                    Some(idx) => idx.into_u32().collect(),
                    None => (0..n).collect(),
                };
                if indices.iter().any(|&i| i >= n) || indices.len() % 3 != 0 {
                    return Err(bad(format!("mesh '{}' has bad indices", mesh.name().unwrap_or("?"))));
                }
                // A mirroring transform flips the winding; keep triangles front-facing.
                let flip = m.determinant() < 0.0;
                let mut local: Vec<u32> = indices.iter().map(|i| i + base).collect();
                if flip {
                    for t in local.chunks_exact_mut(3) {
                        t.swap(1, 2);
                    }
                }
                env.meshes.push(EnvMesh {
                    name: mesh.name().unwrap_or("").to_string(),
                    indices: local,
                    double_sided: prim.material().double_sided(),
                    reflectance: material_reflectance(&prim.material()),
                    class: material_class(&prim.material()),
                });
            }
        }
        if env.meshes.is_empty() {
            return Err(bad("environment has no triangles".into()));
        }
        if env.positions.iter().any(|p| !p.is_finite()) {
            return Err(bad("a vertex position is not finite".into()));
        }
        Ok(env)
    }

    pub fn triangle_count(&self) -> usize {
        self.meshes.iter().map(|m| m.indices.len() / 3).sum()
    }

    /// Triangles as world-frame vertex triples.
    pub fn triangles(&self) -> impl Iterator<Item = [DVec3; 3]> + '_ {
        self.meshes.iter().flat_map(move |m| {
            m.indices.chunks_exact(3).map(move |t| [0, 1, 2].map(|k| self.positions[t[k] as usize]))
        })
    }
}

/// Heights (m) between which a triangle counts as an obstacle for walking people.
const OBSTACLE_Z: (f64, f64) = (0.05, 2.0);
/// A triangle whose vertices are all within this of z = 0 is floor.
const FLOOR_Z_TOLERANCE: f64 = 0.05;

/// Obstacles reaching this high stand behind a person over most of its height
/// ([`WalkableGrid::obstacle_behind`]: a parked car, a stall, a wall; not a bench or a bollard), m.
pub(crate) const TALL_Z: f64 = 1.2;
/// Obstacles reaching this high, and lower than [`TALL_Z`], hide a person's legs from a sensor
/// they stand between ([`WalkableGrid::low_obstacle_before`]: a counter, a bench's back, a bin, a
/// hedge, a table), m.
pub(crate) const LOW_Z: f64 = 0.7;
/// A height over the floor, m, as [`WalkableGrid::top_cm`] keeps it: whole cm, 0-255.
pub(crate) fn height_cm(z_m: f64) -> u8 {
    (z_m * 100.0).floor().clamp(0.0, 255.0) as u8
}
/// Obstacles reaching this high hide a whole person from a sensor at a person's height
/// ([`WalkableGrid::hidden_from`]: a wall, a booth, a parked truck; a recording's returns reach
/// 2 m at most), m.
pub(crate) const HIDES_Z: f64 = 1.9;
/// Half the width [`WalkableGrid::hidden_from`] hides: a person's shoulders, m.
const HIDDEN_HALF_M: f64 = 0.3;
/// `humans.before_things`: how far behind a person's centre, along the line of sight, m.
pub const BEFORE_THING_M: f64 = 2.0;
/// `humans.behind_things`: how far in front of a person's centre, along the line of sight, m.
pub const BEHIND_THING_M: f64 = 1.5;

/// Which connected regions of walkable cells a grid keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Regions {
    /// The largest only (an environment: the rest is floor nobody can reach, inside closed
    /// things).
    Largest,
    /// Every region of at least this many cells (a recording: its floor is what the sensor
    /// saw, parked cars and fences split it, and people stand on every side of them).
    AtLeast(usize),
}

/// The walkable area as a grid of clearances: distance (m) from each cell centre to the nearest
/// obstacle or non-floor cell; 0 where one cannot stand.
#[derive(Clone, Debug)]
pub struct WalkableGrid {
    pub origin: DVec2,
    pub cell_m: f64,
    pub nx: usize,
    pub ny: usize,
    pub clearance_m: Vec<f32>,
    /// Per cell, how high the obstacles touching it reach over the floor, in whole cm up to
    /// 255 (0: none; a byte a cell, as the grid's other masks): in an environment the highest
    /// point of a triangle 5 cm-2 m high, in a recording the highest return up to 2 m; empty
    /// for a grid made of clearances alone.
    pub top_cm: Vec<u8>,
}

impl WalkableGrid {
    /// Derives the walkable area of an environment: cells covered by floor triangles (z ~ 0)
    /// and not touched by any triangle between 5 cm and 2 m height.
    pub fn from_environment(env: &Environment, cell_m: f64) -> Result<WalkableGrid> {
        let mut lo = DVec2::splat(f64::INFINITY);
        let mut hi = DVec2::splat(f64::NEG_INFINITY);
        for p in &env.positions {
            lo = lo.min(p.truncate());
            hi = hi.max(p.truncate());
        }
        WalkableGrid::from_environment_within(env, cell_m, lo, hi)
    }

    /// [`WalkableGrid::from_environment`] over the area from `lo` to `hi` only (plus a ring of
    /// cells): a grid no larger than where one can stand (an environment whose buildings and
    /// roads reach far beyond its floor).
    pub fn from_environment_within(env: &Environment, cell_m: f64, lo: DVec2, hi: DVec2) -> Result<WalkableGrid> {
        // One ring of cells beyond the environment: never floor, so the edge of the floor is
        // an obstacle for the clearance.
        let lo = lo - DVec2::splat(cell_m);
        let (nx, ny) = WalkableGrid::dims(lo, hi + DVec2::splat(cell_m), cell_m).map_err(|m| Error::input("environment", m))?;
        let mut floor = vec![false; nx * ny];
        let mut blocked = vec![false; nx * ny];
        let mut top = vec![0u8; nx * ny];
        let centre = |i: usize, j: usize| lo + DVec2::new((i as f64 + 0.5) * cell_m, (j as f64 + 0.5) * cell_m);
        for t in env.triangles() {
            let zmin = t.iter().map(|p| p.z).fold(f64::INFINITY, f64::min);
            let zmax = t.iter().map(|p| p.z).fold(f64::NEG_INFINITY, f64::max);
            let is_floor = zmax.abs() <= FLOOR_Z_TOLERANCE && zmin.abs() <= FLOOR_Z_TOLERANCE;
            let is_obstacle = !is_floor && zmax > OBSTACLE_Z.0 && zmin < OBSTACLE_Z.1;
            if !is_floor && !is_obstacle {
                continue;
            }
            let tri = t.map(|p| p.truncate());
            let tlo = tri[0].min(tri[1]).min(tri[2]);
            let thi = tri[0].max(tri[1]).max(tri[2]);
            let half_diag = cell_m * std::f64::consts::FRAC_1_SQRT_2;
            let pad = if is_obstacle { half_diag } else { 0.0 };
            let i0 = (((tlo.x - pad - lo.x) / cell_m).floor().max(0.0)) as usize;
            let j0 = (((tlo.y - pad - lo.y) / cell_m).floor().max(0.0)) as usize;
            let i1 = ((((thi.x + pad - lo.x) / cell_m).ceil()) as usize).min(nx);
            let j1 = ((((thi.y + pad - lo.y) / cell_m).ceil()) as usize).min(ny);
            for j in j0..j1 {
                for i in i0..i1 {
                    let c = centre(i, j);
                    let d = dist_point_triangle_2d(c, &tri);
                    if is_floor && d <= 1e-9 {
                        floor[j * nx + i] = true;
                    } else if is_obstacle && d <= half_diag {
                        blocked[j * nx + i] = true;
                        top[j * nx + i] = top[j * nx + i].max(height_cm(zmax));
                    }
                }
            }
        }
        Ok(WalkableGrid { top_cm: top, ..WalkableGrid::from_cells(lo, cell_m, nx, ny, &floor, blocked) })
    }

    /// The cells (nx, ny) of a grid from corner `lo` to `hi`, at least one each way; the error
    /// (the message only) when the area needs more than [`MAX_GRID_CELLS`] or is not finite.
    /// Counted in f64 before anything is allocated, so no extent overflows.
    pub fn dims(lo: DVec2, hi: DVec2, cell_m: f64) -> std::result::Result<(usize, usize), String> {
        // Not `max` first: it would turn a NaN into 1.
        let n = ((hi - lo) / cell_m).ceil();
        if !n.is_finite() || n.x * n.y > MAX_GRID_CELLS as f64 {
            let size = hi - lo;
            return Err(format!(
                "the area spans {:.0} x {:.0} m: a {cell_m} m grid of it would have {:.3e} cells, more than the supported {MAX_GRID_CELLS}",
                size.x,
                size.y,
                n.x * n.y
            ));
        }
        let n = n.max(DVec2::ONE);
        Ok((n.x as usize, n.y as usize))
    }

    /// The walkable area from per-cell observations: `floor` cells one can stand on, minus
    /// `blocked` cells, its largest connected region only (the hollow inside of a closed
    /// obstacle, a box or a pillar, is floor but nobody can get there). Cell (i, j) has its
    /// corner at `origin + cell_m * (i, j)`, index j * nx + i. Its tall obstacles
    /// ([`WalkableGrid::obstacle`]) are the caller's to set: none here.
    pub fn from_cells(lo: DVec2, cell_m: f64, nx: usize, ny: usize, floor: &[bool], blocked: Vec<bool>) -> WalkableGrid {
        Self::from_cells_keeping(lo, cell_m, nx, ny, floor, blocked, Regions::Largest)
    }

    /// As [`WalkableGrid::from_cells`], keeping the connected regions `keep` says.
    pub fn from_cells_keeping(lo: DVec2, cell_m: f64, nx: usize, ny: usize, floor: &[bool], mut blocked: Vec<bool>, keep: Regions) -> WalkableGrid {
        let open: Vec<bool> = (0..nx * ny).map(|k| floor[k] && !blocked[k]).collect();
        let mut component = vec![u32::MAX; nx * ny];
        let mut sizes: Vec<usize> = Vec::new();
        for start in 0..nx * ny {
            if !open[start] || component[start] != u32::MAX {
                continue;
            }
            let id = sizes.len() as u32;
            let mut size = 0;
            let mut queue = vec![start];
            component[start] = id;
            while let Some(k) = queue.pop() {
                size += 1;
                let (i, j) = (k % nx, k / nx);
                let mut visit = |n: usize| {
                    if open[n] && component[n] == u32::MAX {
                        component[n] = id;
                        queue.push(n);
                    }
                };
                if i > 0 { visit(k - 1); }
                if i + 1 < nx { visit(k + 1); }
                if j > 0 { visit(k - nx); }
                if j + 1 < ny { visit(k + nx); }
            }
            sizes.push(size);
        }
        let largest = (0..sizes.len()).max_by_key(|&c| (sizes[c], std::cmp::Reverse(c))).map(|c| c as u32);
        let kept = |c: u32| match keep {
            Regions::Largest => Some(c) == largest,
            Regions::AtLeast(n) => sizes[c as usize] >= n,
        };
        for k in 0..nx * ny {
            if open[k] && !kept(component[k]) {
                blocked[k] = true;
            }
        }
        // Clearance: exact Euclidean distance to the nearest blocked cell centre, by a
        // brute-force-free two-pass sweep of nearest-seed propagation (8-neighbour). Seeds are
        // compared by squared distance in whole cells (exact integers; the square root is
        // monotone and distinct integers below 2^52 keep distinct roots, so the choice is the
        // one distances would make), and the root is taken once per cell at the end.
        const NONE: (i32, i32) = (i32::MIN, i32::MIN);
        let mut seed: Vec<(i32, i32)> = vec![NONE; nx * ny];
        for j in 0..ny {
            for i in 0..nx {
                if blocked[j * nx + i] || !floor[j * nx + i] {
                    seed[j * nx + i] = (i as i32, j as i32);
                }
            }
        }
        let dist2 = |i: i64, j: i64, s: (i32, i32)| -> i64 {
            if s == NONE {
                i64::MAX
            } else {
                let (dx, dy) = (i - s.0 as i64, j - s.1 as i64);
                dx * dx + dy * dy
            }
        };
        for pass in 0..2 {
            let order: Box<dyn Iterator<Item = usize>> =
                if pass == 0 { Box::new(0..nx * ny) } else { Box::new((0..nx * ny).rev()) };
            for k in order {
                let (i, j) = ((k % nx) as i64, (k / nx) as i64);
                let mut best = seed[k];
                let mut bd = dist2(i, j, best);
                for (di, dj) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1), (-1, -1), (1, -1), (-1, 1), (1, 1)] {
                    let (ni, nj) = (i + di, j + dj);
                    if ni < 0 || nj < 0 || ni >= nx as i64 || nj >= ny as i64 {
                        continue;
                    }
                    let s = seed[nj as usize * nx + ni as usize];
                    let d = dist2(i, j, s);
                    if d < bd {
                        bd = d;
                        best = s;
                    }
                }
                seed[k] = best;
            }
        }
        let clearance_m = (0..nx * ny)
            .map(|k| {
                let d2 = dist2((k % nx) as i64, (k / nx) as i64, seed[k]);
                // The nearest blocked cell is itself half a cell wide; distances at the grid
                // edge (outside = not floor) are measured to the first outside cell.
                if d2 == i64::MAX { f32::INFINITY } else { (((d2 as f64).sqrt() - 0.5).max(0.0) * cell_m) as f32 }
            })
            .collect();
        WalkableGrid { origin: lo, cell_m, nx, ny, clearance_m, top_cm: Vec::new() }
    }

    /// Clearance at a world xy point (0 outside the grid).
    pub fn clearance(&self, p: DVec2) -> f64 {
        let q = (p - self.origin) / self.cell_m;
        if q.x < 0.0 || q.y < 0.0 {
            return 0.0;
        }
        let (i, j) = (q.x as usize, q.y as usize);
        if i >= self.nx || j >= self.ny {
            return 0.0;
        }
        self.clearance_m[j * self.nx + i] as f64
    }

    /// Whether, looking from `eye` through `at`, a tall obstacle's cell (one reaching [`TALL_Z`])
    /// lies within `far_m` past `at`, before any other cell one cannot stand on (a road, the
    /// floor's edge): something a sensor at `eye` sees behind a person standing at `at`
    /// (`humans.before_things`).
    pub fn obstacle_behind(&self, eye: DVec2, at: DVec2, far_m: f64) -> bool {
        self.march(at, at - eye, far_m, |top| (top >= TALL_Z).then_some(true))
    }

    /// Whether, looking from `at` back toward `eye`, a low obstacle's cell (one reaching
    /// [`LOW_Z`] but not [`TALL_Z`]) lies within `far_m` of `at`, before a tall one (which would
    /// hide the whole person) or any other cell one cannot stand on: something that hides the
    /// legs of a person standing at `at` from a sensor at `eye` (`humans.behind_things`).
    pub fn low_obstacle_before(&self, eye: DVec2, at: DVec2, far_m: f64) -> bool {
        self.march(at, eye - at, far_m, |top| {
            if top >= TALL_Z {
                Some(false)
            } else {
                (top >= LOW_Z).then_some(true)
            }
        })
    }

    /// Whether a sensor at `eye` cannot see a person at `at`: the lines of sight to its middle
    /// and to either shoulder ([`HIDDEN_HALF_M`] aside) each cross a cell whose obstacles reach
    /// [`HIDES_Z`] (a wall, a booth, a parked truck; not a car, a bench or a pole, which hide
    /// one line at most) before leaving the grid. A road between hides nothing. Where long
    /// sequences bring people back in: from doorways, side streets and corners.
    pub fn hidden_from(&self, eye: DVec2, at: DVec2) -> bool {
        let d = at - eye;
        if d.length() < 1e-9 {
            return false;
        }
        let side = d.perp() / d.length() * HIDDEN_HALF_M;
        [DVec2::ZERO, side, -side].iter().all(|&s| {
            let from = at + s;
            self.march_over(from, eye - from, eye.distance(from), false, |top| (top >= HIDES_Z).then_some(true))
        })
    }

    /// Walks from `from` along `dir` in half-cell steps up to `far_m`: at each cell, `seen` of how
    /// high its obstacles reach decides when it says so, else a cell one cannot stand on, the
    /// grid's edge or the end of the walk gives false.
    fn march(&self, from: DVec2, dir: DVec2, far_m: f64, seen: impl FnMut(f64) -> Option<bool>) -> bool {
        self.march_over(from, dir, far_m, true, seen)
    }

    /// [`WalkableGrid::march`], going on over cells one cannot stand on unless `floor_only`.
    fn march_over(&self, from: DVec2, dir: DVec2, far_m: f64, floor_only: bool, mut seen: impl FnMut(f64) -> Option<bool>) -> bool {
        if self.top_cm.is_empty() || dir.length() < 1e-9 {
            return false;
        }
        let dir = dir / dir.length();
        let step = self.cell_m * 0.5;
        for k in 0..=(far_m / step).ceil() as usize {
            let q = (from + dir * (k as f64 * step).min(far_m) - self.origin) / self.cell_m;
            if q.x < 0.0 || q.y < 0.0 || q.x as usize >= self.nx || q.y as usize >= self.ny {
                return false;
            }
            let c = q.y as usize * self.nx + q.x as usize;
            if let Some(v) = seen(self.top_cm[c] as f64 * 0.01) {
                return v;
            }
            if floor_only && self.clearance_m[c] <= 0.0 {
                return false;
            }
        }
        false
    }

    /// Fraction of cells with at least `r` clearance.
    pub fn free_fraction(&self, r: f64) -> f64 {
        self.clearance_m.iter().filter(|c| **c as f64 >= r).count() as f64 / self.clearance_m.len() as f64
    }

    /// The longest straight distance between two points with at least `r` clearance: at
    /// most the diagonal of the bounding box of those cells (0 when there is none), so no walk
    /// that must end this far from its start fits in the area.
    pub fn free_span_m(&self, r: f64) -> f64 {
        let (mut lo, mut hi) = ([usize::MAX; 2], [0usize; 2]);
        for (k, c) in self.clearance_m.iter().enumerate() {
            if *c as f64 >= r {
                let ij = [k % self.nx, k / self.nx];
                for a in 0..2 {
                    lo[a] = lo[a].min(ij[a]);
                    hi[a] = hi[a].max(ij[a] + 1);
                }
            }
        }
        if lo[0] == usize::MAX {
            return 0.0;
        }
        DVec2::new((hi[0] - lo[0]) as f64, (hi[1] - lo[1]) as f64).length() * self.cell_m
    }

    /// A uniformly random point with at least `r` clearance (rejection sampling).
    pub fn sample_free(&self, rng: &mut impl rand::Rng, r: f64) -> Option<DVec2> {
        for _ in 0..10_000 {
            let p = self.origin
                + DVec2::new(
                    rng.random_range(0.0..self.nx as f64 * self.cell_m),
                    rng.random_range(0.0..self.ny as f64 * self.cell_m),
                );
            if self.clearance(p) >= r {
                return Some(p);
            }
        }
        None
    }
}

fn dist_point_segment_2d(p: DVec2, a: DVec2, b: DVec2) -> f64 {
    let ab = b - a;
    let l2 = ab.length_squared();
    let t = if l2 > 0.0 { ((p - a).dot(ab) / l2).clamp(0.0, 1.0) } else { 0.0 };
    (a + t * ab).distance(p)
}

/// Distance from a point to a 2D triangle (0 inside); degenerate triangles are segments.
pub(crate) fn dist_point_triangle_2d(p: DVec2, t: &[DVec2; 3]) -> f64 {
    let cross = |a: DVec2, b: DVec2, c: DVec2| (b - a).perp_dot(c - a);
    let area = cross(t[0], t[1], t[2]);
    if area.abs() > 1e-12 {
        let s = area.signum();
        let inside = (0..3).all(|k| s * cross(t[k], t[(k + 1) % 3], p) >= 0.0);
        if inside {
            return 0.0;
        }
    }
    (0..3).map(|k| dist_point_segment_2d(p, t[k], t[(k + 1) % 3])).fold(f64::INFINITY, f64::min)
}

/// A planar trajectory at constant speed and yaw rate (a circular arc or a line), starting at
/// time 0. Height `z_m` is constant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trajectory {
    pub start_m: DVec2,
    pub z_m: f64,
    pub heading0_rad: f64,
    pub speed_mps: f64,
    pub yaw_rate_rps: f64,
}

impl Trajectory {
    /// A trajectory that stays at `p` facing `heading`.
    pub fn fixed(p: DVec2, z_m: f64, heading: f64) -> Trajectory {
        Trajectory { start_m: p, z_m, heading0_rad: heading, speed_mps: 0.0, yaw_rate_rps: 0.0 }
    }

    pub fn heading_rad(&self, t_s: f64) -> f64 {
        self.heading0_rad + self.yaw_rate_rps * t_s
    }

    /// World position at time `t_s` (exact, closed form). The chord form
    /// `2 v / w sin(w t / 2)` along the mean heading `h0 + w t / 2` has no cancellation, so it
    /// stays exact for tiny yaw rates and long times (the `sin(h1) - sin(h0)` form lost 0.1 mm
    /// at w t = 1e-9 after 1000 s).
    pub fn position(&self, t_s: f64) -> DVec3 {
        let (h0, w, v) = (self.heading0_rad, self.yaw_rate_rps, self.speed_mps);
        let chord = if w == 0.0 { v * t_s } else { 2.0 * v / w * (0.5 * w * t_s).sin() };
        let h = h0 + 0.5 * w * t_s;
        (self.start_m + chord * DVec2::new(h.cos(), h.sin())).extend(self.z_m)
    }

    /// World velocity at time `t_s`, m/s (exact).
    pub fn velocity(&self, t_s: f64) -> DVec3 {
        let h = self.heading_rad(t_s);
        DVec3::new(self.speed_mps * h.cos(), self.speed_mps * h.sin(), 0.0)
    }

    /// Distance travelled since time 0.
    pub fn distance(&self, t_s: f64) -> f64 {
        self.speed_mps * t_s
    }

    /// `world_from_local` pose at time `t_s`: translation to the position, yaw to the heading.
    pub fn pose(&self, t_s: f64) -> DMat4 {
        DMat4::from_translation(self.position(t_s)) * DMat4::from_rotation_z(self.heading_rad(t_s))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arc_velocity_is_the_derivative_of_position() {
        for w in [0.0, 1e-12, 0.2, -0.7] {
            let tr = Trajectory { start_m: DVec2::new(3.0, -2.0), z_m: 0.8, heading0_rad: 0.4, speed_mps: 1.3, yaw_rate_rps: w };
            for t in [0.0, 0.5, 3.1] {
                let h = 1e-5;
                let num = (tr.position(t + h) - tr.position(t - h)) / (2.0 * h);
                assert!((num - tr.velocity(t)).length() < 1e-7, "w {w} t {t}: {num} vs {}", tr.velocity(t));
                assert!((tr.velocity(t).length() - 1.3).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn walkable_grid_excludes_a_box_and_the_outside() {
        // A 10 x 10 m floor (two triangles) with a 1 x 1 m box in the middle.
        let mut env = Environment::default();
        env.positions = vec![
            DVec3::new(-5.0, -5.0, 0.0),
            DVec3::new(5.0, -5.0, 0.0),
            DVec3::new(5.0, 5.0, 0.0),
            DVec3::new(-5.0, 5.0, 0.0),
        ];
        env.meshes.push(EnvMesh { name: "floor".into(), indices: vec![0, 1, 2, 0, 2, 3], double_sided: true, reflectance: 0.5, class: 0 });
        let b = env.positions.len() as u32;
        for z in [0.0, 1.0] {
            for (x, y) in [(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)] {
                env.positions.push(DVec3::new(x, y, z));
            }
        }
        let side = |a: u32, c: u32, d: u32, e: u32| vec![b + a, b + c, b + d, b + a, b + d, b + e];
        let mut idx = Vec::new();
        for (a, c) in [(0, 1), (1, 2), (2, 3), (3, 0)] {
            idx.extend(side(a, c, c + 4, a + 4));
        }
        env.meshes.push(EnvMesh { name: "box".into(), indices: idx, double_sided: false, reflectance: 0.5, class: 0 });
        let g = WalkableGrid::from_environment(&env, 0.1).unwrap();
        assert_eq!(g.clearance(DVec2::new(0.0, 0.0)), 0.0, "inside the box");
        assert!(g.clearance(DVec2::new(0.55, 0.0)) < 0.1);
        let c = g.clearance(DVec2::new(2.0, 0.0));
        assert!((c - 1.5).abs() < 0.15, "{c}");
        assert!(g.clearance(DVec2::new(4.8, 0.0)) < 0.3, "near the floor's edge");
        assert_eq!(g.clearance(DVec2::new(7.0, 0.0)), 0.0, "off the floor");
        // Cells with 0.5 m clearance span 9 x 9 m: no straight walk is longer than their
        // diagonal.
        let span = g.free_span_m(0.5);
        assert!((span - 9.0 * std::f64::consts::SQRT_2).abs() < 0.3, "{span}");
        assert_eq!(g.free_span_m(100.0), 0.0);
    }

    #[test]
    fn grid_dimensions_are_capped_before_anything_is_allocated() {
        assert_eq!(WalkableGrid::dims(DVec2::ZERO, DVec2::new(1.05, 0.0), 0.1), Ok((11, 1)));
        let m = WalkableGrid::dims(DVec2::ZERO, DVec2::new(1e5, 1e3), 0.1).unwrap_err();
        assert!(m.contains("1.000e10 cells") && m.contains(&MAX_GRID_CELLS.to_string()), "{m}");
        for hi in [DVec2::new(1e38, 1e38), DVec2::new(f64::INFINITY, 1.0), DVec2::new(f64::NAN, 1.0)] {
            assert!(WalkableGrid::dims(DVec2::ZERO, hi, 0.1).is_err(), "{hi}");
        }
    }
}
