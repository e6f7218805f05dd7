//! Synthetic pedestrian paths for environments without recorded tracks: a person walks from a
//! start to a goal through the walkable area, on a smooth path, at constant speed.
//!
//! # Method
//!
//! 1. **Start and goal.** The start is given, or drawn uniformly over the cells of the
//!    [`WalkableGrid`] whose clearance is at least `clearance_m` (uniform within the cell). The
//!    goal is drawn the same way among the points at straight-line distance at least
//!    `speed * duration` (and at least one cell) from the start, so the path, which is never
//!    shorter than that distance, lasts the whole sequence and nobody stops mid-sequence.
//!    Draws and searches are bounded; when a search finds the goal unreachable, its closed set
//!    is exactly the start's connected region, and later goals are drawn from that region only.
//! 2. **A\*** on the grid: 8-connected over cells with clearance >= `clearance_m` (a diagonal
//!    step also needs both cells beside it, so no corner is cut), the octile heuristic, and a
//!    step cost raised by up to 50 % within 0.6 m of the clearance limit so that people keep off
//!    the walls where there is room. Ties are broken deterministically (lower f, then lower
//!    heuristic, then lower cell index).
//! 3. **Line-of-sight shortcut**, greedy from the start: each vertex connects to the farthest
//!    later vertex of the cell path it can see. A shortcut must keep clearance of at least
//!    `min(clearance_m + 0.25 m, the lowest clearance of the A\* cells it replaces)`, so it
//!    does not run closer to the walls than the A\* path did (up to that comfort margin). Lines
//!    are checked exactly, on every grid cell they touch (a grid traversal, not samples).
//! 4. **Fillets.** Each corner is rounded by a circular arc tangent to both segments, of radius
//!    up to [`MAX_FILLET_RADIUS_M`], limited so the tangent points stay within half of each
//!    interior segment (the whole of the first and last segments). Each arc is checked against
//!    the clearance along chords at most `min(cell/4, radius/4)` long (each chord checked
//!    exactly, as the lines); an arc that fails is halved in radius until it passes (an arc
//!    shrinks towards its corner, which is clear), and the attempt fails if that needs a
//!    radius under [`MIN_FILLET_RADIUS_M`], or under [`Planner::min_turn_radius_m`] where that
//!    is larger (the walks of people pushing something; the last try then at that radius).
//!
//! [`Planner::plan_to`] runs steps 2 to 4 between a given start and goal, without randomness.
//! [`Planner::plan_leg`] (a long sequence's next walk) draws its goal within a given distance
//! of a given start and gives its searches up past a path costing [`LEG_DETOUR`] times that
//! distance (a cell's step costs 1 to 1.5 cells of length, so a path along walls is given up
//! at about twice it), so its cost is the neighbourhood's, not the grid's;
//! [`Planner::plan_to_within`] bounds [`Planner::plan_to`]'s search the same way.
//! A [`Planner`] keeps the search buffers between calls; [`plan_walk`] is the one-off form.
//!
//! # Guarantees
//!
//! For `0 <= t <= WalkPath::duration_s()`, with clearance as the grid gives it (one value per
//! cell):
//! - every point of every straight piece lies in a cell with clearance >= `clearance_m`; every
//!   arc is checked the same way along chords at most `min(cell/4, radius/4)` long, so no
//!   point of an arc is farther than 1/128 of a cell from a checked chord;
//! - the path is C1: position and direction of motion are continuous at every join (the
//!   curvature jumps there, as for any line-arc path);
//! - position, velocity, heading and distance are closed form (exact for lines and arcs, with
//!   no numerical differentiation): `|velocity| == speed`, `heading == atan2(velocity)` (up to
//!   whole turns), `distance == speed * t`;
//! - the path runs exactly from the start to the goal and is at least `speed * duration` long
//!   (the arguments of [`plan_walk`]).
//!
//! # The ends
//!
//! Before `t = 0` and after the end (`t > length / speed`) the person keeps walking straight
//! along the first / last tangent at the same speed: position extrapolates, velocity and
//! heading stay those of the first / last instant, distance keeps growing as `speed * t`
//! (negative before 0), so the gait keeps its cadence. Those extrapolated parts are not checked
//! against the clearance.

use crate::scene::WalkableGrid;
use glam::{DMat4, DVec2, DVec3};
use rand::RngExt;
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// Largest radius of the arc that rounds a corner, m.
pub const MAX_FILLET_RADIUS_M: f64 = 1.5;
/// Smallest radius a corner may need; a path that needs a sharper fillet is rejected, m.
pub const MIN_FILLET_RADIUS_M: f64 = 1e-3;
/// A shortcut keeps this much more than the required clearance where the A* path did, m.
const COMFORT_MARGIN_M: f64 = 0.25;
/// Within this distance of the clearance limit, A* steps cost more, m.
const WALL_BAND_M: f64 = 0.6;
/// Extra step cost right at the clearance limit (fraction of the step length).
const WALL_COST: f64 = 0.5;
/// Starts drawn when none is given.
const START_TRIES: usize = 8;
/// A* searches per start.
const SEARCHES_PER_START: usize = 8;
/// Goal draws per start (rejection of points too close to the start).
const GOAL_DRAWS_PER_START: usize = 256;
/// Goal draws of a leg ([`Planner::plan_leg`]): points of the square around the start,
/// rejected outside the ring or off the walkable area.
const LEG_GOAL_DRAWS: usize = 1024;
/// A leg's search gives up past a path costing this many times the distance to its farthest
/// goal (a step's cost is its length, up to 1.5 times it near walls).
pub const LEG_DETOUR: f64 = 3.0;

/// One piece of a [`WalkPath`]: a straight line (curvature 0) or a circular arc, walked from
/// `start_m` with heading `heading0_rad` for `length_m` metres of arc length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathPiece {
    /// Arc length along the path at which this piece starts, m.
    pub start_s_m: f64,
    pub length_m: f64,
    pub start_m: DVec2,
    /// Heading at the start of the piece (unwrapped: continuous along the path).
    pub heading0_rad: f64,
    /// Signed curvature, 1/m: positive turns left (counter-clockwise), 0 is a line.
    pub curvature_per_m: f64,
}

impl PathPiece {
    /// Point at arc length `sigma` from the piece's start. The chord form
    /// `2 sin(k sigma / 2) / k` along the mean heading is exact for lines and arcs alike.
    fn point(&self, sigma: f64) -> DVec2 {
        let k = self.curvature_per_m;
        let half = 0.5 * k * sigma;
        let chord = if k == 0.0 { sigma } else { 2.0 * half.sin() / k };
        let h = self.heading0_rad + half;
        self.start_m + chord * DVec2::new(h.cos(), h.sin())
    }

    fn heading(&self, sigma: f64) -> f64 {
        self.heading0_rad + self.curvature_per_m * sigma
    }

    fn end(&self) -> DVec2 {
        self.point(self.length_m)
    }
}

/// A C1 path in the floor plane (lines joined by circular fillets) walked at constant speed
/// from time 0. See the module docs for the guarantees and for what happens outside
/// `[0, duration_s()]`.
#[derive(Clone, Debug, PartialEq)]
pub struct WalkPath {
    speed_mps: f64,
    length_m: f64,
    pieces: Vec<PathPiece>,
    end_m: DVec2,
    end_heading_rad: f64,
}

impl WalkPath {
    /// Builds the path from its pieces (non-empty, each of positive length, joined C1, with
    /// `start_s_m` set to the running arc length).
    fn from_pieces(pieces: Vec<PathPiece>, speed_mps: f64) -> WalkPath {
        let last = *pieces.last().expect("a path has at least one piece");
        WalkPath {
            speed_mps,
            length_m: last.start_s_m + last.length_m,
            end_m: last.end(),
            end_heading_rad: last.heading(last.length_m),
            pieces,
        }
    }

    pub fn speed_mps(&self) -> f64 {
        self.speed_mps
    }

    /// Arc length from start to goal, m.
    pub fn length_m(&self) -> f64 {
        self.length_m
    }

    /// Time at which the goal is reached, s.
    pub fn duration_s(&self) -> f64 {
        self.length_m / self.speed_mps
    }

    /// Position at time 0 (the start), z = 0.
    pub fn start_m(&self) -> DVec2 {
        self.pieces[0].start_m
    }

    /// Position at `duration_s()` (the goal).
    pub fn goal_m(&self) -> DVec2 {
        self.end_m
    }

    /// The lines and arcs, in walking order.
    pub fn pieces(&self) -> &[PathPiece] {
        &self.pieces
    }

    /// The piece walked at arc length `s` (0 <= s <= length) and the arc length within it.
    fn locate(&self, s: f64) -> (&PathPiece, f64) {
        let i = self.pieces.partition_point(|p| p.start_s_m <= s).max(1) - 1;
        let p = &self.pieces[i];
        (p, (s - p.start_s_m).clamp(0.0, p.length_m))
    }

    /// Arc length walked since time 0, m: `speed * t` (negative before 0, growing past the
    /// goal along the extrapolated line).
    pub fn distance(&self, t_s: f64) -> f64 {
        self.speed_mps * t_s
    }

    /// World position at time `t_s` (z = 0), exact.
    pub fn position(&self, t_s: f64) -> DVec3 {
        let s = self.distance(t_s);
        let p = if s <= 0.0 {
            let first = &self.pieces[0];
            let h = first.heading0_rad;
            first.start_m + s * DVec2::new(h.cos(), h.sin())
        } else if s >= self.length_m {
            let h = self.end_heading_rad;
            self.end_m + (s - self.length_m) * DVec2::new(h.cos(), h.sin())
        } else {
            let (piece, sigma) = self.locate(s);
            piece.point(sigma)
        };
        p.extend(0.0)
    }

    /// Direction of motion at `t_s`, counter-clockwise from +x. Unwrapped: continuous in time
    /// (a path that turns twice around counter-clockwise ends 4 pi above where it started), so
    /// it equals `atan2(velocity)` up to whole turns.
    pub fn heading_rad(&self, t_s: f64) -> f64 {
        let s = self.distance(t_s);
        if s <= 0.0 {
            self.pieces[0].heading0_rad
        } else if s >= self.length_m {
            self.end_heading_rad
        } else {
            let (piece, sigma) = self.locate(s);
            piece.heading(sigma)
        }
    }

    /// World velocity at `t_s`, m/s: `speed` along the heading (exact).
    pub fn velocity(&self, t_s: f64) -> DVec3 {
        let h = self.heading_rad(t_s);
        DVec3::new(self.speed_mps * h.cos(), self.speed_mps * h.sin(), 0.0)
    }

    /// `world_from_local` pose at `t_s`: translation to the position, yaw to the heading.
    pub fn pose(&self, t_s: f64) -> DMat4 {
        DMat4::from_translation(self.position(t_s)) * DMat4::from_rotation_z(self.heading_rad(t_s))
    }
}

/// A path planner holding the scratch buffers of its searches, so that planning many people
/// (or sequences) does not reallocate. [`plan_walk`] is the one-off form.
#[derive(Debug, Default)]
pub struct Planner {
    /// The search grid: the walkable grid with a ring of blocked cells around it (so no
    /// neighbour needs a bounds check), row length `nx + 2`. Per cell, the cost of crossing it
    /// in thousandths (1000 far from walls up to 1500 at the clearance limit), 0 = blocked.
    cost: Vec<u16>,
    /// Per search cell: the cost from the start, the parent (search indices).
    g: Vec<u64>,
    parent: Vec<u32>,
    /// `seen[k] == generation`: `g[k]` and `parent[k]` belong to the current search.
    seen: Vec<u32>,
    /// `closed[k] == generation`: cell k was expanded by the current search.
    closed: Vec<u32>,
    generation: u32,
    /// Open cells keyed by [`open_key`]: the lowest f first, then the lowest h, then the
    /// lowest cell index. Integer costs make equal-cost alternatives tie exactly, so the
    /// tie-break (not rounding noise) decides and the search stays narrow.
    heap: BinaryHeap<Reverse<u128>>,
    /// Grid cells (grid indices) with enough clearance.
    free: Vec<u32>,
    candidates: Vec<u32>,
    cells: Vec<u32>,
    vertices: Vec<DVec2>,
    vertex_clearance: Vec<f64>,
    shortcut: Vec<DVec2>,
    /// What `cost` and `free` were built for ([`grid_key`]): a planner keeps them while it is
    /// asked of the same grid and clearance (a long sequence plans hundreds of walks over one
    /// street of millions of cells).
    prepared: Option<GridKey>,
    /// The least radius a corner may be rounded with, m (a path that needs less is rejected;
    /// below [`MIN_FILLET_RADIUS_M`], that): the planned walks of people who push something
    /// turn no faster than their speed over it.
    pub min_turn_radius_m: f64,
}

/// A grid and a clearance as [`Planner::prepare`] tells them apart: where its clearances lie
/// and how many, its shape, origin and cell, 64 of its clearances spread over it, and the
/// clearance asked. A planner is meant for one grid at a time (the sequence it plans);
/// changing a grid's clearances in place between two walks of one planner is not.
type GridKey = (usize, usize, [usize; 2], [u64; 3], u64, u64);

fn grid_key(grid: &WalkableGrid, c: f64) -> GridKey {
    let n = grid.clearance_m.len();
    let mut sampled = 0xcbf2_9ce4_8422_2325u64;
    for k in 0..64usize.min(n) {
        sampled = (sampled ^ u64::from(grid.clearance_m[k * n / 64.min(n)].to_bits())).wrapping_mul(0x0100_0000_01b3);
    }
    (grid.clearance_m.as_ptr() as usize, n, [grid.nx, grid.ny], [grid.origin.x.to_bits(), grid.origin.y.to_bits(), grid.cell_m.to_bits()], sampled, c.to_bits())
}

/// Plans one walk; see the module docs. `clearance_m`: the least distance from the person's
/// centre to any obstacle. `start`: given (it must have that clearance), or None to draw one.
/// Cells of clearance 0 (where one cannot stand) are never walked, even with `clearance_m = 0`.
/// Returns None when the inputs are invalid (non-finite, speed <= 0, negative duration or
/// clearance) or when no start-goal pair within the bounded tries gives a valid path.
/// All randomness comes from `rng`: the same seed gives the same path.
pub fn plan_walk(
    rng: &mut impl rand::Rng,
    grid: &WalkableGrid,
    clearance_m: f64,
    speed_mps: f64,
    duration_s: f64,
    start: Option<DVec2>,
) -> Option<WalkPath> {
    Planner::new().plan_walk(rng, grid, clearance_m, speed_mps, duration_s, start)
}

impl Planner {
    pub fn new() -> Planner {
        Planner::default()
    }

    /// As [`plan_walk`], reusing this planner's buffers.
    pub fn plan_walk(
        &mut self,
        rng: &mut impl rand::Rng,
        grid: &WalkableGrid,
        clearance_m: f64,
        speed_mps: f64,
        duration_s: f64,
        start: Option<DVec2>,
    ) -> Option<WalkPath> {
        let c = clearance_m;
        let need = least_walk_m(grid, c, speed_mps, duration_s)?;
        self.prepare(grid, c);
        if self.free.is_empty() {
            return None;
        }
        let start_tries = if start.is_some() { 1 } else { START_TRIES };
        for _ in 0..start_tries {
            let s = match start {
                Some(s) => s,
                None => {
                    let k = self.free[rng.random_range(0..self.free.len())];
                    point_in_cell(rng, grid, k as usize)
                }
            };
            let start_cell = cell_of(grid, s).filter(|&k| walkable(grid.clearance_m[k], c))?;
            // Cells with some point far enough from the start (the draw below rejects the rest).
            let reach = (need - grid.cell_m * std::f64::consts::FRAC_1_SQRT_2).max(0.0);
            self.candidates.clear();
            let far = |k: &u32| centre(grid, *k as usize).distance_squared(s) >= reach * reach;
            self.candidates.extend(self.free.iter().copied().filter(far));
            let mut searches = 0;
            for _ in 0..GOAL_DRAWS_PER_START {
                if searches >= SEARCHES_PER_START || self.candidates.is_empty() {
                    break;
                }
                let k = self.candidates[rng.random_range(0..self.candidates.len())] as usize;
                let goal = point_in_cell(rng, grid, k);
                if goal.distance(s) < need {
                    continue;
                }
                searches += 1;
                if !self.astar(grid, start_cell, k) {
                    // The search exhausted the start's connected region: keep only goals in it.
                    let (closed, generation, w) = (&self.closed, self.generation, grid.nx + 2);
                    self.candidates.retain(|&k| closed[search_index(w, grid.nx, k as usize)] == generation);
                    continue;
                }
                if let Some(path) = self.walk_long_enough(grid, c, speed_mps, duration_s, s, goal) {
                    return Some(path);
                }
            }
        }
        None
    }

    /// A walk from `start` for a long sequence's next leg: as [`Planner::plan_walk`] with a
    /// given start, its goal drawn uniformly over the walkable points at straight-line
    /// distance `speed * duration` (one cell at least) to `within_m` from the start, and its
    /// search given up past a path costing [`LEG_DETOUR`] times `within_m`. The walk's cost
    /// so stays bounded by the neighbourhood it walks in, not the whole grid's size (a long
    /// street of tens of millions of cells); the draw keeps to the start's connected region
    /// once a search has found a goal outside it. None as for [`Planner::plan_walk`], and when
    /// `within_m` is not finite or is shorter than that distance.
    #[allow(clippy::too_many_arguments)]
    pub fn plan_leg(
        &mut self,
        rng: &mut impl rand::Rng,
        grid: &WalkableGrid,
        clearance_m: f64,
        speed_mps: f64,
        duration_s: f64,
        start: DVec2,
        within_m: f64,
    ) -> Option<WalkPath> {
        let c = clearance_m;
        let need = least_walk_m(grid, c, speed_mps, duration_s)?;
        if !(within_m.is_finite() && within_m >= need) {
            return None;
        }
        let start_cell = cell_of(grid, start).filter(|&k| walkable(grid.clearance_m[k], c))?;
        self.prepare(grid, c);
        if self.generation > u32::MAX - SEARCHES_PER_START as u32 {
            // The generations wrap within this leg's searches: start them again now, so the
            // region's generation below stays valid.
            self.seen.fill(0);
            self.closed.fill(0);
            self.generation = 0;
        }
        let w = grid.nx + 2;
        let limit = search_limit(grid, within_m);
        // Set once a search has exhausted the start's region: the generation it ran as (every
        // later search from this start closes only cells of the same region).
        let mut region = None;
        let mut searches = 0;
        for _ in 0..LEG_GOAL_DRAWS {
            if searches >= SEARCHES_PER_START {
                break;
            }
            let u = DVec2::new(rng.random::<f64>(), rng.random::<f64>()) * 2.0 - DVec2::ONE;
            let goal = start + u * within_m;
            let d = goal.distance(start);
            if !(need..=within_m).contains(&d) {
                continue;
            }
            let Some(k) = cell_of(grid, goal).filter(|&k| walkable(grid.clearance_m[k], c)) else { continue };
            if region.is_some_and(|g| self.closed[search_index(w, grid.nx, k)] < g) {
                continue;
            }
            searches += 1;
            match self.astar_within(grid, start_cell, k, limit) {
                Search::Found => {}
                Search::Unreachable => {
                    region.get_or_insert(self.generation);
                    continue;
                }
                Search::TooLong => continue,
            }
            if let Some(path) = self.walk_long_enough(grid, c, speed_mps, duration_s, start, goal) {
                return Some(path);
            }
        }
        None
    }

    /// The path a successful search just found from `start` to `goal`, shortcut and filleted,
    /// when it is long enough to walk for `duration_s` at `speed_mps`; the tail of
    /// [`Planner::plan_walk`]'s and [`Planner::plan_leg`]'s goal draws.
    fn walk_long_enough(
        &mut self,
        grid: &WalkableGrid,
        c: f64,
        speed_mps: f64,
        duration_s: f64,
        start: DVec2,
        goal: DVec2,
    ) -> Option<WalkPath> {
        self.path_from_cells(grid, c, speed_mps, start, goal).filter(|path| path.length_m() >= speed_mps * duration_s)
    }

    /// A path from `start` to `goal` (both with clearance >= `clearance_m`), by the same
    /// search, shortcut and fillets as [`Planner::plan_walk`], without randomness. None when
    /// the goal is unreachable or no valid fillet exists.
    pub fn plan_to(
        &mut self,
        grid: &WalkableGrid,
        clearance_m: f64,
        speed_mps: f64,
        start: DVec2,
        goal: DVec2,
    ) -> Option<WalkPath> {
        self.plan_to_within(grid, clearance_m, speed_mps, start, goal, f64::INFINITY)
    }

    /// [`Planner::plan_to`], its search given up (None) past a path costing [`LEG_DETOUR`]
    /// times `reach_m` (infinite: never).
    pub fn plan_to_within(
        &mut self,
        grid: &WalkableGrid,
        clearance_m: f64,
        speed_mps: f64,
        start: DVec2,
        goal: DVec2,
        reach_m: f64,
    ) -> Option<WalkPath> {
        let c = clearance_m;
        if !valid_inputs(grid, c, speed_mps) || start.distance(goal) <= 0.0 || reach_m.is_nan() {
            return None;
        }
        let free = |p: DVec2| cell_of(grid, p).filter(|&k| walkable(grid.clearance_m[k], c));
        let (s, g) = (free(start)?, free(goal)?);
        self.prepare(grid, c);
        if self.astar_within(grid, s, g, search_limit(grid, reach_m)) != Search::Found {
            return None;
        }
        self.path_from_cells(grid, c, speed_mps, start, goal)
    }

    /// Builds the search grid's costs and the list of free cells for clearance `c`, and sizes
    /// the search buffers.
    fn prepare(&mut self, grid: &WalkableGrid, c: f64) {
        let (nx, ny) = (grid.nx, grid.ny);
        let w = nx + 2;
        let n = w * (ny + 2);
        let key = grid_key(grid, c);
        if self.prepared == Some(key) && self.g.len() == n {
            return;
        }
        self.prepared = Some(key);
        self.cost.clear();
        self.cost.resize(n, 0);
        self.free.clear();
        // `walkable(clr, c)` in f32: the smallest positive f32 at or above c.
        let mut c32 = c as f32;
        if (c32 as f64) < c {
            c32 = f32::from_bits(c32.to_bits() + 1);
        }
        let c32 = c32.max(f32::from_bits(1));
        let band_end = c32 + WALL_BAND_M as f32;
        for j in 0..ny {
            let row = &grid.clearance_m[j * nx..(j + 1) * nx];
            let out = &mut self.cost[(j + 1) * w + 1..(j + 1) * w + 1 + nx];
            for (i, (&clr, cost)) in row.iter().zip(out).enumerate() {
                if clr >= c32 {
                    // A small extra cost near walls keeps people off them where there is room.
                    *cost = if clr >= band_end {
                        1000
                    } else {
                        let extra = WALL_COST * (1.0 - (clr as f64 - c) / WALL_BAND_M).clamp(0.0, 1.0);
                        (1000.0 * (1.0 + extra) + 0.5) as u16
                    };
                    self.free.push((j * nx + i) as u32);
                }
            }
        }
        if self.g.len() != n {
            self.g = vec![0; n];
            self.parent = vec![0; n];
            self.seen = vec![0; n];
            self.closed = vec![0; n];
            self.generation = 0;
        }
    }

    /// A* from grid cell `s` to grid cell `goal` over the prepared search grid; on success the
    /// cell path (grid indices) is in `self.cells`. On failure, the closed set is the start's
    /// whole connected region.
    fn astar(&mut self, grid: &WalkableGrid, s: usize, goal: usize) -> bool {
        self.astar_within(grid, s, goal, u64::MAX) == Search::Found
    }

    /// [`Planner::astar`], given up (`TooLong`) once the cheapest open cell's f exceeds
    /// `limit`; `Unreachable` only when the start's whole region was searched.
    fn astar_within(&mut self, grid: &WalkableGrid, s: usize, goal: usize, limit: u64) -> Search {
        if self.generation == u32::MAX {
            self.seen.fill(0);
            self.closed.fill(0);
            self.generation = 0;
        }
        self.generation += 1;
        self.heap.clear();
        let gen = self.generation;
        let w = grid.nx + 2;
        let (s, goal) = (search_index(w, grid.nx, s), search_index(w, grid.nx, goal));
        let (gi, gj) = ((goal % w) as i64, (goal / w) as i64);
        // Octile distance in thousandths of a cell: a lower bound of the step costs below.
        let heuristic = |i: i64, j: i64| {
            let (dx, dy) = ((i - gi).unsigned_abs(), (j - gj).unsigned_abs());
            1000 * dx.max(dy) + 414 * dx.min(dy)
        };
        let wi = w as isize;
        // (offset, di, dj, base cost); the diagonal steps come last and need both cells beside.
        let steps: [(isize, i64, i64, u64); 8] = [
            (1, 1, 0, 1000),
            (-1, -1, 0, 1000),
            (wi, 0, 1, 1000),
            (-wi, 0, -1, 1000),
            (wi + 1, 1, 1, 1414),
            (wi - 1, -1, 1, 1414),
            (-wi + 1, 1, -1, 1414),
            (-wi - 1, -1, -1, 1414),
        ];
        let cost = &self.cost;
        self.g[s] = 0;
        self.parent[s] = s as u32;
        self.seen[s] = gen;
        let h = heuristic((s % w) as i64, (s / w) as i64);
        self.heap.push(Reverse(open_key(h, h, s)));
        while let Some(Reverse(key)) = self.heap.pop() {
            let k = key as u32 as usize;
            if self.closed[k] == gen {
                continue;
            }
            if (key >> 64) as u64 > limit {
                return Search::TooLong;
            }
            self.closed[k] = gen;
            if k == goal {
                self.cells.clear();
                let mut at = goal;
                loop {
                    self.cells.push(((at / w - 1) * grid.nx + at % w - 1) as u32);
                    if at == s {
                        break;
                    }
                    at = self.parent[at] as usize;
                }
                self.cells.reverse();
                return Search::Found;
            }
            let (i, j) = ((k % w) as i64, (k / w) as i64);
            let (gk, ck) = (self.g[k], cost[k] as u64);
            for (off, di, dj, base) in steps {
                // The ring of blocked cells keeps m inside the search grid.
                let m = (k as isize + off) as usize;
                let cm = cost[m] as u64;
                if cm == 0 || self.closed[m] == gen {
                    continue;
                }
                if di != 0 && dj != 0 {
                    let beside_x = cost[(k as isize + di as isize) as usize];
                    let beside_y = cost[(k as isize + dj as isize * wi) as usize];
                    if beside_x == 0 || beside_y == 0 {
                        continue;
                    }
                }
                // Step cost: base times the mean of the two cells' costs, rounded.
                let ng = gk + (base * (ck + cm) + 1000) / 2000;
                if self.seen[m] != gen || ng < self.g[m] {
                    self.seen[m] = gen;
                    self.g[m] = ng;
                    self.parent[m] = k as u32;
                    let h = heuristic(i + di, j + dj);
                    self.heap.push(Reverse(open_key(ng + h, h, m)));
                }
            }
        }
        Search::Unreachable
    }

    /// Shortcut and fillets of the cell path in `self.cells`, from the exact `start` to the
    /// exact `goal`.
    fn path_from_cells(&mut self, grid: &WalkableGrid, c: f64, speed: f64, start: DVec2, goal: DVec2) -> Option<WalkPath> {
        let n = self.cells.len();
        self.vertices.clear();
        self.vertex_clearance.clear();
        for (idx, &k) in self.cells.iter().enumerate() {
            let p = if idx == 0 {
                start
            } else if idx + 1 == n {
                goal
            } else {
                centre(grid, k as usize)
            };
            self.vertices.push(p);
            self.vertex_clearance.push(grid.clearance_m[k as usize] as f64);
        }
        if n == 1 {
            // Start and goal share a cell.
            self.vertices.push(goal);
            self.vertex_clearance.push(self.vertex_clearance[0]);
        }
        // Greedy line of sight: from each kept vertex, the farthest later vertex it sees.
        let v = &self.vertices;
        self.shortcut.clear();
        self.shortcut.push(v[0]);
        let mut i = 0;
        while i + 1 < v.len() {
            // The next vertex is always reachable: A* made that step (or it is the start or
            // goal point within its own cell); the final check below covers the exact line.
            let mut best = i + 1;
            let mut lowest = self.vertex_clearance[i].min(self.vertex_clearance[i + 1]);
            for j in i + 2..v.len() {
                lowest = lowest.min(self.vertex_clearance[j]);
                if segment_clear(grid, v[i], v[j], (c + COMFORT_MARGIN_M).min(lowest)) {
                    best = j;
                } else {
                    break;
                }
            }
            self.shortcut.push(v[best]);
            i = best;
        }
        self.shortcut.dedup_by(|a, b| a.distance(*b) < 1e-9);
        if self.shortcut.len() < 2 {
            return None;
        }
        let path = fillet(grid, c, &self.shortcut, speed, self.min_turn_radius_m.max(MIN_FILLET_RADIUS_M))?;
        // Final check of every line exactly (arcs were checked when they were made).
        let lines_clear = path
            .pieces
            .iter()
            .filter(|p| p.curvature_per_m == 0.0)
            .all(|p| segment_clear(grid, p.start_m, p.end(), c));
        lines_clear.then_some(path)
    }
}

/// How an A* search ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Search {
    Found,
    /// The start's whole connected region was searched (it is the closed set).
    Unreachable,
    /// Given up at the cost limit.
    TooLong,
}

/// One heap key for an open cell, ordered as `(f, h, cell)`: f in the top 64 bits, then h
/// (saturated at 2^32 - 1, past 4 million cells of distance: only the tie-break weakens), then
/// the cell index.
fn open_key(f: u64, h: u64, cell: usize) -> u128 {
    ((f as u128) << 64) | ((h.min(u32::MAX as u64) as u128) << 32) | cell as u32 as u128
}

/// The search-grid index (with its ring of blocked cells, row length `w`) of grid cell `k`.
fn search_index(w: usize, nx: usize, k: usize) -> usize {
    (k / nx + 1) * w + k % nx + 1
}

/// The cost past which a search for a goal within `reach_m` gives up, in thousandths of a
/// cell ([`LEG_DETOUR`]; saturating, so an infinite reach never gives up).
fn search_limit(grid: &WalkableGrid, reach_m: f64) -> u64 {
    (LEG_DETOUR * reach_m / grid.cell_m * 1000.0) as u64
}

/// The least straight-line distance of a walk's goal from its start: `speed * duration`, one
/// cell at least; None for invalid inputs.
fn least_walk_m(grid: &WalkableGrid, c: f64, speed: f64, duration_s: f64) -> Option<f64> {
    (valid_inputs(grid, c, speed) && duration_s.is_finite() && duration_s >= 0.0).then(|| (speed * duration_s).max(grid.cell_m))
}

fn valid_inputs(grid: &WalkableGrid, c: f64, speed: f64) -> bool {
    c.is_finite()
        && c >= 0.0
        && speed.is_finite()
        && speed > 0.0
        && grid.cell_m.is_finite()
        && grid.cell_m > 0.0
        && grid.clearance_m.len() == grid.nx * grid.ny
        && !grid.clearance_m.is_empty()
        // Search indices (with the ring of blocked cells) fit in u32.
        && (grid.nx as u64 + 2) * (grid.ny as u64 + 2) < u32::MAX as u64
}

/// A cell of clearance `clr` is walkable for a person needing `c`: at least `c`, and never a
/// cell where one cannot stand (clearance 0), even for `c = 0`.
fn walkable(clr: f32, c: f64) -> bool {
    clr > 0.0 && clr as f64 >= c
}

/// The cell index containing `p`, or None outside the grid (same rule as
/// [`WalkableGrid::clearance`]).
fn cell_of(grid: &WalkableGrid, p: DVec2) -> Option<usize> {
    let q = (p - grid.origin) / grid.cell_m;
    if q.x.is_nan() || q.y.is_nan() || q.x < 0.0 || q.y < 0.0 {
        return None;
    }
    let (i, j) = (q.x as usize, q.y as usize);
    (i < grid.nx && j < grid.ny).then_some(j * grid.nx + i)
}

fn centre(grid: &WalkableGrid, k: usize) -> DVec2 {
    let (i, j) = (k % grid.nx, k / grid.nx);
    grid.origin + DVec2::new((i as f64 + 0.5) * grid.cell_m, (j as f64 + 0.5) * grid.cell_m)
}

/// A uniformly random point of cell `k` (its centre if rounding lands it in a neighbour).
fn point_in_cell(rng: &mut impl rand::Rng, grid: &WalkableGrid, k: usize) -> DVec2 {
    let (i, j) = (k % grid.nx, k / grid.nx);
    let u = DVec2::new(rng.random::<f64>(), rng.random::<f64>());
    let p = grid.origin + (DVec2::new(i as f64, j as f64) + u) * grid.cell_m;
    if cell_of(grid, p) == Some(k) {
        p
    } else {
        centre(grid, k)
    }
}

/// True when every grid cell the segment `a`-`b` touches has clearance >= `req` (an exact grid
/// traversal; where the segment passes exactly through a cell corner, both cells beside it
/// count).
fn segment_clear(grid: &WalkableGrid, a: DVec2, b: DVec2, req: f64) -> bool {
    let (nx, ny) = (grid.nx as i64, grid.ny as i64);
    let ok = |i: i64, j: i64| i >= 0 && j >= 0 && i < nx && j < ny && walkable(grid.clearance_m[(j * nx + i) as usize], req);
    let qa = (a - grid.origin) / grid.cell_m;
    let qb = (b - grid.origin) / grid.cell_m;
    if !(qa.is_finite() && qb.is_finite()) {
        return false;
    }
    let (mut i, mut j) = (qa.x.floor() as i64, qa.y.floor() as i64);
    let (ie, je) = (qb.x.floor() as i64, qb.y.floor() as i64);
    if !ok(i, j) {
        return false;
    }
    let d = qb - qa;
    let (si, sj) = ((ie - i).signum(), (je - j).signum());
    // Parameter (0..1 along the segment) of the next vertical / horizontal grid line.
    let (mut tx, dtx) = match si {
        1 => ((i as f64 + 1.0 - qa.x) / d.x, 1.0 / d.x),
        -1 => ((qa.x - i as f64) / -d.x, 1.0 / -d.x),
        _ => (f64::INFINITY, f64::INFINITY),
    };
    let (mut ty, dty) = match sj {
        1 => ((j as f64 + 1.0 - qa.y) / d.y, 1.0 / d.y),
        -1 => ((qa.y - j as f64) / -d.y, 1.0 / -d.y),
        _ => (f64::INFINITY, f64::INFINITY),
    };
    while i != ie || j != je {
        // Only step towards the end cell, so rounding can never overshoot it.
        let step_x = j == je || (i != ie && tx < ty);
        let step_y = i == ie || (j != je && ty < tx);
        if step_x && !step_y {
            i += si;
            tx += dtx;
        } else if step_y && !step_x {
            j += sj;
            ty += dty;
        } else {
            // Through a cell corner: both side cells, then the diagonal one.
            if !ok(i + si, j) || !ok(i, j + sj) {
                return false;
            }
            i += si;
            j += sj;
            tx += dtx;
            ty += dty;
        }
        if !ok(i, j) {
            return false;
        }
    }
    true
}

/// True when the arc keeps clearance >= `c` along chords at most `min(cell/4, radius/4)` long.
fn arc_clear(grid: &WalkableGrid, arc: &PathPiece, c: f64) -> bool {
    let radius = 1.0 / arc.curvature_per_m.abs();
    let step = (0.25 * grid.cell_m).min(0.25 * radius);
    let n = ((arc.length_m / step).ceil() as usize).max(1);
    let mut prev = arc.start_m;
    for k in 1..=n {
        let q = arc.point(arc.length_m * k as f64 / n as f64);
        if !segment_clear(grid, prev, q, c) {
            return false;
        }
        prev = q;
    }
    true
}

/// Rounds every interior corner of the polyline `v` (no repeated vertices) with a checked
/// circular fillet and returns the walked path, or None when a corner needs a radius under
/// `min_r` (m).
fn fillet(grid: &WalkableGrid, c: f64, v: &[DVec2], speed: f64, min_r: f64) -> Option<WalkPath> {
    let m = v.len();
    let len: Vec<f64> = v.windows(2).map(|w| w[0].distance(w[1])).collect();
    let dir: Vec<DVec2> = v.windows(2).zip(&len).map(|(w, l)| (w[1] - w[0]) / l).collect();
    // Unwrapped heading of each segment, and the tangent length cut off at each vertex.
    let mut heading = vec![dir[0].y.atan2(dir[0].x); m - 1];
    let mut tangent = vec![0.0; m];
    let mut arcs: Vec<Option<PathPiece>> = vec![None; m];
    for i in 1..m - 1 {
        let (din, dout) = (dir[i - 1], dir[i]);
        let theta = din.perp_dot(dout).atan2(din.dot(dout));
        heading[i] = heading[i - 1] + theta;
        if theta == 0.0 {
            continue;
        }
        let tan_half = (0.5 * theta.abs()).tan();
        let room_in = len[i - 1] * if i == 1 { 1.0 } else { 0.5 };
        let room_out = len[i] * if i == m - 2 { 1.0 } else { 0.5 };
        let mut r = MAX_FILLET_RADIUS_M.max(min_r).min(room_in.min(room_out) / tan_half);
        loop {
            if r.is_nan() || r < min_r {
                return None;
            }
            let t = r * tan_half;
            let arc = PathPiece {
                start_s_m: 0.0,
                length_m: r * theta.abs(),
                start_m: v[i] - din * t,
                heading0_rad: heading[i - 1],
                curvature_per_m: theta.signum() / r,
            };
            if arc_clear(grid, &arc, c) {
                tangent[i] = t;
                arcs[i] = Some(arc);
                break;
            }
            // Halved, but tried once at the least radius where halving would skip it (a
            // least radius above the default: a pusher's walk).
            r = if min_r > MIN_FILLET_RADIUS_M && r > min_r { (0.5 * r).max(min_r) } else { 0.5 * r };
        }
    }
    let mut pieces = Vec::with_capacity(2 * m);
    for i in 0..m - 1 {
        let l = len[i] - tangent[i] - tangent[i + 1];
        if l > 1e-12 {
            pieces.push(PathPiece {
                start_s_m: 0.0,
                length_m: l,
                start_m: v[i] + dir[i] * tangent[i],
                heading0_rad: heading[i],
                curvature_per_m: 0.0,
            });
        }
        if let Some(arc) = arcs[i + 1] {
            pieces.push(arc);
        }
    }
    if pieces.is_empty() {
        return None;
    }
    let mut s = 0.0;
    for p in &mut pieces {
        p.start_s_m = s;
        s += p.length_m;
    }
    Some(WalkPath::from_pieces(pieces, speed))
}

#[cfg(test)]
pub(crate) mod tests;
