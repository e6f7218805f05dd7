//! Built-in procedural worlds (`scene.background = "street"` or `"indoor"`): each sequence gets
//! its own layout, drawn from the seed and the sequence's index alone, full of things of human
//! height and width that are not people (trees, bushes, bollards, bins, cabinets, poles, parked
//! bicycles and cars; mannequins, plants, shelves, display cases), so that "an upright thing of
//! human size" does not give a person away. Surfaces carry their SemanticKITTI class and a
//! near-infrared reflectance spread over the range that people's clothes and skin cover.
//!
//! A world is built once per sequence ([`World::build`]): its triangles (an [`Environment`],
//! rendered like a glTF background), its walkable area (sidewalks, crossings, plazas; halls and
//! corridors) and, in the street, the sensor's path (a vehicle in its lane). Once the
//! sequence's people are planned, the things some of them push are added ([`World::add_pushed`]),
//! then the street's traffic and the hall's robots and carts drive around them
//! ([`World::add_movers`]).

pub mod indoor;
pub mod movers;
pub mod pushed;
pub mod shapes;
pub mod street;
pub mod things;

use crate::error::{Error, Result};
use crate::scene::{EnvDraw, Environment, Trajectory, WalkableGrid, WALKABLE_CELL_M};
use glam::{DVec2, DVec3};
use rand::RngExt;
use rand::SeedableRng;
use std::collections::BTreeMap;

pub use crate::config::WorldKind;
pub use movers::{Mover, MoverKind};
pub use shapes::{Place, Seat};

/// What a world is built for besides its random stream.
#[derive(Clone, Copy, Debug)]
pub struct WorldParams {
    /// Length of the sequence, s (the street is made long enough for the sensor to drive it).
    pub duration_s: f64,
    /// Sensor height above the ground it moves on, m.
    pub sensor_height_m: f64,
    /// Sensor speed range, m/s.
    pub sensor_speed_mps: [f64; 2],
    /// People's clearance from obstacles, m (the walkable area keeps room for them).
    pub clearance_m: f64,
    /// The street's share of lots that are markets (`scene.markets`).
    pub markets: f64,
    /// The street's share of lots that are side streets (`scene.side_streets`).
    pub side_streets: f64,
}

/// One sequence's world.
pub struct World {
    pub kind: WorldKind,
    /// The stream it was drawn from (the run's seed, the sequence's index).
    pub seed: u64,
    pub index: usize,
    pub env: Environment,
    /// The environment's meshes as drawn.
    pub draws: Vec<EnvDraw>,
    pub grid: WalkableGrid,
    /// The sensor's path when the world sets it (a vehicle in the street's lane); None: sampled
    /// in the walkable area like in any environment.
    pub sensor: Option<Trajectory>,
    /// How many of each kind of thing it holds (the sequence's XML records them).
    pub counts: BTreeMap<&'static str, usize>,
    /// Places people stand at: behind a market stall's or booth's counter and in front of it,
    /// beside a beer-garden table (`humans.at_places`), each with the way a person there
    /// faces. Each had room for a person (`clearance_m`) where it was made; the walkable area
    /// has the last word.
    pub places: Vec<Place>,
    /// Doorways people come out of in a long sequence (the street's buildings): a point of
    /// the doorway's floor, in from the facade, and the way out.
    pub doors: Vec<Place>,
    /// Seats people sit on (`humans.sitting`): the benches' (two or three each, 0.46 m), the
    /// chairs at tables (0.47 m) and the beer-garden benches (0.45 m); the walkable area marks
    /// them as obstacles, so a seated person is placed on one without it.
    pub seats: Vec<Seat>,
    /// Its footprint (xy bounds), m.
    pub bounds: (DVec2, DVec2),
    /// The things people push ([`World::add_pushed`]), then the movers driving through it
    /// ([`World::add_movers`]); their meshes are the last of `env` and `draws`.
    pub movers: Vec<Mover>,
    /// Per draw: the mover it belongs to, or [`NO_MOVER`].
    pub mover_of_draw: Vec<u32>,
    /// The traffic drawn with the layout, lane by lane, until it drives.
    traffic: Vec<movers::LaneTraffic>,
}

/// [`World::mover_of_draw`] of a draw of the still world.
pub const NO_MOVER: u32 = u32::MAX;

impl std::fmt::Debug for World {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "World {{ seed {}, sequence {}: {} }}", self.seed, self.index, self.summary())
    }
}

impl PartialEq for World {
    /// Worlds are equal when drawn from the same stream (their content follows from it).
    fn eq(&self, o: &World) -> bool {
        (self.kind, self.seed, self.index) == (o.kind, o.seed, o.index)
    }
}

/// Keys the world's random stream apart from the people's (same seed and index).
const WORLD_STREAM_KEY: u64 = 0x5752_4c44_5f76_3031; // "WRLD_v01"
/// Keys the traffic's placing apart from both.
const MOVERS_STREAM_KEY: u64 = 0x4d4f_5652_5f76_3031; // "MOVR_v01"

/// The random stream of sequence `index`'s world: its own, so the layout does not change when
/// anything about the people does.
pub fn world_rng(seed: u64, index: usize) -> rand_chacha::ChaCha8Rng {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ WORLD_STREAM_KEY);
    rng.set_stream(index as u64);
    rng
}

impl World {
    /// Builds sequence `index`'s world of `kind` from the run's `seed`.
    pub fn build(kind: WorldKind, seed: u64, index: usize, p: &WorldParams) -> Result<World> {
        let mut rng = world_rng(seed, index);
        let mut counts = BTreeMap::new();
        let (env, sensor, traffic, [places, doors], seats) = match kind {
            WorldKind::Street => street::build(&mut rng, p, &mut counts),
            WorldKind::Indoor => {
                let (env, traffic, seats) = indoor::build(&mut rng, p, &mut counts);
                (env, None, traffic, [Vec::new(), Vec::new()], seats)
            }
        };
        let what = || format!("scene.background = \"{}\" (sequence {index})", kind.name());
        if env.positions.iter().any(|v| !v.is_finite()) {
            return Err(Error::Internal(format!("{}: a vertex is not finite", what())));
        }
        // The walkable area's grid spans the floor only (the street's buildings and road reach
        // far beyond it).
        let (mut flo, mut fhi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
        for t in env.triangles().filter(|t| t.iter().all(|v| v.z.abs() <= 0.05)) {
            for v in t {
                flo = flo.min(v.truncate());
                fhi = fhi.max(v.truncate());
            }
        }
        let grid = WalkableGrid::from_environment_within(&env, WALKABLE_CELL_M, flo, fhi).map_err(|e| Error::input(what(), e.to_string()))?;
        if grid.free_fraction(p.clearance_m) <= 0.0 {
            return Err(Error::input(what(), format!("no walkable floor with humans.clearance_m = {}", p.clearance_m)));
        }
        let mut lo = DVec2::splat(f64::INFINITY);
        let mut hi = DVec2::splat(f64::NEG_INFINITY);
        for v in &env.positions {
            lo = lo.min(v.truncate());
            hi = hi.max(v.truncate());
        }
        // The walkable area has the last word on a doorway: one too shallow to stand in, or
        // with something on the sidewalk before it, is no way out.
        let mut doors = doors;
        doors.retain(|d| grid.clearance(d.at) >= p.clearance_m);
        if !doors.is_empty() {
            counts.insert("doorway", doors.len());
        }
        let draws = env.draws();
        let mover_of_draw = vec![NO_MOVER; draws.len()];
        Ok(World { kind, seed, index, env, draws, grid, sensor, counts, places, doors, seats, bounds: (lo, hi), movers: Vec::new(), mover_of_draw, traffic })
    }

    /// Drives the world's traffic over `duration_s` around the people at their floor
    /// positions (`people(t, out)`; in a world that does not set the sensor's path, the
    /// sensor's position among them: indoors it walks or rolls where people do), on a random
    /// stream of its own (the run's seed and the sequence's index), lane by lane, and adds the
    /// movers kept to the environment. Does nothing in a world without traffic or a second
    /// time.
    pub fn add_movers(&mut self, duration_s: f64, people: impl Fn(f64, &mut Vec<DVec2>)) {
        let traffic = std::mem::take(&mut self.traffic);
        if traffic.is_empty() {
            return;
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(self.seed ^ MOVERS_STREAM_KEY);
        rng.set_stream(self.index as u64);
        let sensor = self.sensor;
        let sensor_x = |t: f64| sensor.map_or(0.0, |s| s.position(t).x);
        let driven: Vec<_> = traffic.iter().map(|lt| movers::drive(&mut rng, &lt.movers, &lt.lane, duration_s, sensor_x, lt.ego, &people)).collect();
        for (lt, kept) in traffic.iter().zip(driven) {
            for (i, u0, table) in kept {
                let spec = &lt.movers[i];
                let m = movers::mover(spec, &lt.lane, u0, table, self.env.positions.len());
                let what = lt.count_as.unwrap_or(match m.kind {
                    MoverKind::Car => "car driving",
                    MoverKind::Cyclist => "cyclist riding",
                    MoverKind::Robot => "robot driving",
                    MoverKind::Cart => "cart driving",
                    MoverKind::Stroller => "stroller pushed",
                    MoverKind::Trolley => "trolley pushed",
                });
                self.add_mover(m, &spec.mesh, what);
            }
        }
    }

    /// Adds mover `m` (its vertices to come at the end of the environment's) with its mesh,
    /// placed where it is at time 0, counted as `what`.
    fn add_mover(&mut self, m: Mover, mesh: &Environment, what: &'static str) {
        let first = self.env.positions.len();
        debug_assert_eq!(m.first_vertex, first);
        let mut placed = vec![DVec3::ZERO; m.local.len()];
        m.place(0.0, &mut placed);
        self.env.positions.extend_from_slice(&placed);
        let mut added = Environment::default();
        for mesh in &mesh.meshes {
            let mut mesh = mesh.clone();
            mesh.indices.iter_mut().for_each(|k| *k += first as u32);
            mesh.name = format!("mover {} {} {}", self.movers.len(), m.kind.name(), mesh.name);
            added.meshes.push(mesh.clone());
            self.env.meshes.push(mesh);
        }
        let draws = added.draws();
        self.mover_of_draw.extend(std::iter::repeat_n(self.movers.len() as u32, draws.len()));
        self.draws.extend(draws);
        *self.counts.entry(what).or_insert(0) += 1;
        self.movers.push(m);
    }

    /// One line for the sequence's XML: triangles and the things placed, by kind.
    pub fn summary(&self) -> String {
        let things: Vec<String> = self.counts.iter().map(|(k, n)| format!("{k} {n}")).collect();
        format!(
            "{} ({} triangles, {:.0} x {:.0} m): {}",
            self.kind.name(),
            self.env.triangle_count(),
            self.bounds.1.x - self.bounds.0.x,
            self.bounds.1.y - self.bounds.0.y,
            things.join(", ")
        )
    }
}

/// Uniform in `[lo, hi)`.
pub(crate) fn uni(rng: &mut impl rand::Rng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.random::<f64>()
}

/// True with probability `p`.
pub(crate) fn chance(rng: &mut impl rand::Rng, p: f64) -> bool {
    rng.random::<f64>() < p
}

/// An index drawn with the given weights.
pub(crate) fn pick(rng: &mut impl rand::Rng, weights: &[f64]) -> usize {
    let total: f64 = weights.iter().sum();
    let mut u = rng.random::<f64>() * total;
    for (i, w) in weights.iter().enumerate() {
        if u < *w {
            return i;
        }
        u -= w;
    }
    // Rounding left `u` past the end: the last index that can be drawn (never a zero weight).
    weights.iter().rposition(|&w| w > 0.0).unwrap_or(weights.len() - 1)
}

/// A point `d` along direction `yaw` from `p` (xy), at height `z`.
pub(crate) fn at(p: DVec2, yaw: f64, d: f64, z: f64) -> DVec3 {
    (p + d * DVec2::new(yaw.cos(), yaw.sin())).extend(z)
}

#[cfg(test)]
mod tests;
