//! Stage 7b: the sensor's own effects on a composited frame, after Velodyne's manuals and
//! the usual simulator models (see the README, "Sensor model", for every default and its
//! source). Applied per beam to what pedscan renders (people, an environment), never to a
//! recorded background's beams, which carry their own:
//!
//! - **Intensity** `I = scale * reflectance * cos(incidence)` (calibrated, no range falloff,
//!   like Velodyne's calibrated reflectivity and KITTI's remission); written always.
//! - **Beam divergence**: a beam near a silhouette (a neighbour on the grid sees another
//!   surface or nothing) is cast as [`FOOTPRINT_RAYS`] rays over its elliptical footprint;
//!   hits closer together than `mixed_return_m` form one return at their power-weighted range
//!   (a mixed pixel), and of several such returns the strongest is kept (Velodyne's default
//!   return mode). Its power and intensity are the footprint's share.
//! - **Dropout**: a return is detected with probability `(1 - dropout_rate) * g(incidence) *
//!   d(power)`: `d` a logistic in the log of the received power `reflectance * cos / r^2`
//!   against that of reflectance 0.1 head-on at `detection_range_m`, `g` falling linearly from
//!   1 to 0 over `grazing_deg`. A lost return is a hole: range 0, label 0, instance 0.
//! - **Range noise**: a per-laser bias (drawn per sequence) plus Gaussian noise per return.
//!
//! The rolling shutter (each column at its own time) is not a post effect: the frame is posed
//! over the sweep ([`shutter`]).
//!
//! Random numbers: a ChaCha8 stream per (sequence, frame, row), the same number of draws per
//! beam whatever happens to it, so every output is the same at any thread count.

pub mod shutter;

use crate::config::SensorModelConfig;
use glam::DVec3;
use rand::{Rng, RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// Rays cast over a beam's footprint near a silhouette: the centre and six around it.
pub const FOOTPRINT_RAYS: usize = 7;

/// Where the six outer rays sit, as a fraction of the footprint's semi-axes: the ring that
/// splits a uniform disc into equal-area centre and outer parts would be 0.65-0.75; 0.7 is
/// used.
const RING: f64 = 0.7;

/// A surface a ray meets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    pub range_m: f64,
    /// 0 = background, k = k-th person.
    pub instance: u16,
    /// Near-infrared reflectance, 0..1.
    pub reflectance: f32,
    /// |cos| of the angle between the ray and the surface normal.
    pub cos_incidence: f32,
    /// Rendered by pedscan (a person, an environment), not a recorded return.
    pub rendered: bool,
    /// Unit normal of the surface (sensor frame; either side), zero where unknown (a
    /// recorded return).
    pub normal: glam::Vec3,
}

impl Surface {
    /// Received power relative to a unit-reflectance head-on surface at 1 m.
    fn power(&self) -> f64 {
        self.reflectance as f64 * self.cos_incidence as f64 / (self.range_m * self.range_m).max(1e-6)
    }
}

/// What the sensor model needs to cast a beam's footprint: the nearest surface along each of
/// `dirs[1..]` (`dirs[0]` is the beam itself, whose surface is known) into `out[1..]`.
pub trait FootprintScene: Sync {
    fn cast_footprint(&self, beam: usize, dirs: &[DVec3; FOOTPRINT_RAYS], out: &mut [Option<Surface>; FOOTPRINT_RAYS]);
}

/// The sensor model's draws for one sequence: per-laser biases and each person's
/// reflectances.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SequenceDraws {
    /// Per row (laser), m.
    pub bias_m: Vec<f64>,
    /// Per person (instance - 1): skin, upper, lower, shoes.
    pub reflectance: Vec<[f32; 4]>,
}

/// Which body region a person's triangle belongs to (index into [`SequenceDraws::reflectance`]).
pub const SKIN: u8 = 0;
pub const UPPER: u8 = 1;
pub const LOWER: u8 = 2;
pub const SHOES: u8 = 3;

/// The region a skin joint's name belongs to (the bundled people's MakeHuman names; anything
/// unknown is upper clothing).
pub fn region_of_joint(name: &str) -> u8 {
    let n = name.to_ascii_lowercase();
    let any = |keys: &[&str]| keys.iter().any(|k| n.contains(k));
    if any(&["foot", "toe"]) {
        SHOES
    } else if any(&["pelvis", "upperleg", "lowerleg", "root", "hip", "thigh", "knee", "shin", "calf"]) {
        LOWER
    } else if any(&[
        "head", "neck", "jaw", "eye", "tongue", "oris", "oculi", "levator", "temporalis", "risorius", "orbicularis",
        "special", "wrist", "finger", "metacarpal", "hand", "thumb",
    ]) {
        SKIN
    } else {
        UPPER
    }
}

impl SequenceDraws {
    /// Draws for sequence `index` of a run seeded `seed`, with `people` people and `rows` lasers.
    pub fn draw(cfg: &SensorModelConfig, seed: u64, index: usize, rows: usize, people: usize) -> SequenceDraws {
        let mut rng = stream(seed, index as u64, u64::MAX);
        let noise = cfg.enabled;
        let bias_m = (0..rows).map(|_| if noise { cfg.laser_bias_m * gaussian(&mut rng) } else { 0.0 }).collect();
        let mut uniform = |r: [f64; 2]| (r[0] + (r[1] - r[0]) * rng.random::<f64>()) as f32;
        let reflectance = (0..people)
            .map(|_| {
                [
                    uniform(cfg.skin_reflectance),
                    uniform(cfg.upper_reflectance),
                    uniform(cfg.lower_reflectance),
                    uniform(cfg.shoe_reflectance),
                ]
            })
            .collect();
        SequenceDraws { bias_m, reflectance }
    }
}

/// The random stream of (sequence, frame, row): `frame = u64::MAX` is the sequence's own.
fn stream(seed: u64, sequence: u64, frame: u64) -> ChaCha8Rng {
    // A stream per (sequence, frame): the seed mixed with both, so no two share a key.
    let key = seed ^ 0x5e75_0a3d_e1ed_0001u64.wrapping_mul(sequence.wrapping_add(1)) ^ frame.rotate_left(32).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    ChaCha8Rng::seed_from_u64(key)
}

/// A standard normal draw (Box-Muller; two uniforms, always).
fn gaussian(rng: &mut impl Rng) -> f64 {
    let u1: f64 = rng.random::<f64>();
    let u2: f64 = rng.random::<f64>();
    (-2.0 * (1.0 - u1).ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// One frame's beams before the model: the clean surface per beam (None = no return).
pub struct FrameIn<'a> {
    pub cfg: &'a SensorModelConfig,
    pub dirs: &'a [DVec3],
    pub columns: usize,
    /// Per row: elevation; per column: azimuth (radians), to place footprint rays.
    pub elevation_rad: &'a [f64],
    pub azimuth_rad: &'a [f64],
    pub min_range_m: f64,
    pub max_range_m: f64,
    pub clean: &'a [Option<Surface>],
    pub draws: &'a SequenceDraws,
    /// Intensity units (see `SensorModelConfig::intensity_scale`).
    pub intensity_scale: f64,
    /// The recording's own intensity per beam, when the background is a recording that has
    /// one (else a recorded beam's intensity is 0: unknown).
    pub recorded_intensity: Option<&'a [f32]>,
    pub seed: u64,
    pub sequence: usize,
    pub frame: usize,
}

/// One beam after the model.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BeamOut {
    /// 0 = no return.
    pub range_m: f32,
    pub instance: u16,
    pub intensity: f32,
    /// The return came from the beam's footprint (a silhouette beam cast as several rays),
    /// not from its centre ray alone.
    pub from_footprint: bool,
}

/// Applies the model to every beam into `out` (one entry per beam).
pub fn apply(f: &FrameIn, scene: &dyn FootprintScene, out: &mut Vec<BeamOut>) {
    let n = f.dirs.len();
    out.clear();
    out.resize(n, BeamOut::default());
    let cfg = f.cfg;
    let w = f.columns;
    let on = cfg.enabled;
    let divergence = on && cfg.divergence_mrad.iter().any(|&d| d > 0.0);
    // Received power of reflectance 0.1 head-on at the detection range: the 50 % point.
    let p50 = 0.1 / (cfg.detection_range_m * cfg.detection_range_m);
    let [g0, g1] = [cfg.grazing_deg[0].to_radians().cos(), cfg.grazing_deg[1].to_radians().cos()];
    out.par_chunks_mut(w).enumerate().for_each(|(row, outs)| {
        let mut rng = stream(f.seed, f.sequence as u64, f.frame as u64);
        rng.set_stream(row as u64);
        for (col, o) in outs.iter_mut().enumerate() {
            let b = row * w + col;
            // Every beam draws the same three numbers, used or not.
            let u_drop: f64 = rng.random::<f64>();
            let z = gaussian(&mut rng);
            let clean = f.clean[b];
            let edge = divergence && is_edge(f.clean, b, w);
            let ret = if edge { footprint_return(f, scene, b) } else { clean.map(|s| (s, s.reflectance * s.cos_incidence)) };
            let Some((s, share)) = ret else { continue };
            if !s.rendered || !on {
                let range = s.range_m;
                if range >= f.min_range_m && range <= f.max_range_m {
                    let intensity = if s.rendered {
                        (f.intensity_scale * share as f64) as f32
                    } else {
                        f.recorded_intensity.map_or(0.0, |r| r[b])
                    };
                    *o = BeamOut { range_m: range as f32, instance: s.instance, intensity, from_footprint: edge };
                }
                continue;
            }
            // Detection: power (the footprint's share), incidence, and chance.
            let power = share as f64 / (s.range_m * s.range_m).max(1e-6);
            let d = if cfg.detection_softness > 0.0 {
                1.0 / (1.0 + (-(power / p50).ln() / cfg.detection_softness).exp())
            } else {
                (power >= p50) as u8 as f64
            };
            let c = s.cos_incidence as f64;
            let g = if c >= g0 { 1.0 } else if c <= g1 || g0 <= g1 { 0.0 } else { (c - g1) / (g0 - g1) };
            if u_drop >= (1.0 - cfg.dropout_rate) * g * d {
                continue;
            }
            let range = s.range_m + f.draws.bias_m[row] + cfg.range_noise_m * z;
            if range >= f.min_range_m && range <= f.max_range_m {
                *o = BeamOut { range_m: range as f32, instance: s.instance, intensity: (f.intensity_scale * share as f64) as f32, from_footprint: edge };
            }
        }
    });
}

/// Whether beam `b`'s footprint may hold a person's silhouette: its left or right neighbour
/// (columns wrap) sees another instance, or nothing where this beam sees a person (or the
/// reverse). Rows are a few times farther apart than columns (HDL-32E: 23 against 6 mrad)
/// while the footprint is half as tall as wide, so a silhouette between rows (a shoulder, the
/// top of a head) falls inside a footprint a few times in a hundred; those, and silhouettes
/// within the environment (a pillar before a wall), stay knife edges.
fn is_edge(clean: &[Option<Surface>], b: usize, w: usize) -> bool {
    let (row, col) = (b / w, b % w);
    let here = clean[b];
    let neighbours = [row * w + (col + w - 1) % w, row * w + (col + 1) % w];
    neighbours.iter().any(|&nb| match (here, clean[nb]) {
        (None, None) => false,
        (Some(a), Some(o)) => a.instance != o.instance,
        (Some(a), None) | (None, Some(a)) => a.instance > 0,
    })
}

/// The footprint ray directions of a beam at (azimuth, elevation): the centre first.
pub fn footprint_dirs(az: f64, el: f64, divergence_mrad: [f64; 2]) -> [DVec3; FOOTPRINT_RAYS] {
    let (ha, he) = (0.5e-3 * divergence_mrad[0], 0.5e-3 * divergence_mrad[1]);
    let dir = |a: f64, e: f64| DVec3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin());
    let mut d = [dir(az, el); FOOTPRINT_RAYS];
    for (k, v) in d.iter_mut().enumerate().skip(1) {
        let phi = std::f64::consts::TAU * (k - 1) as f64 / (FOOTPRINT_RAYS - 1) as f64;
        // Horizontal divergence is an angle in the cone's own plane: divided by cos(el) in
        // azimuth.
        *v = dir(az + RING * ha * phi.cos() / el.cos(), el + RING * he * phi.sin());
    }
    d
}

/// The return of beam `b` over its footprint: the surfaces its rays meet grouped by range
/// (closer than `mixed_return_m` = one return), the strongest group kept; returns the group's
/// power-weighted surface and its share `sum(reflectance * cos) / rays`.
fn footprint_return(f: &FrameIn, scene: &dyn FootprintScene, b: usize) -> Option<(Surface, f32)> {
    let (row, col) = (b / f.columns, b % f.columns);
    let dirs = footprint_dirs(f.azimuth_rad[col], f.elevation_rad[row], f.cfg.divergence_mrad);
    let mut hits: [Option<Surface>; FOOTPRINT_RAYS] = [None; FOOTPRINT_RAYS];
    scene.cast_footprint(b, &dirs, &mut hits);
    hits[0] = f.clean[b];
    let mut hits: Vec<Surface> = hits.into_iter().flatten().collect();
    combine(&mut hits, f.cfg.mixed_return_m)
}

/// Groups footprint hits by range and keeps the strongest group (see [`footprint_return`]).
/// `hits` are the rays that met something, of [`FOOTPRINT_RAYS`] cast.
pub fn combine(hits: &mut [Surface], mixed_m: f64) -> Option<(Surface, f32)> {
    hits.sort_by(|a, b| a.range_m.total_cmp(&b.range_m));
    let mut best: Option<(f64, Surface, f32)> = None;
    let mut start = 0;
    while start < hits.len() {
        let mut end = start + 1;
        while end < hits.len() && hits[end].range_m - hits[end - 1].range_m <= mixed_m {
            end += 1;
        }
        let group = &hits[start..end];
        let (mut power, mut weighted_range, mut share, mut cos_sum) = (0.0, 0.0, 0.0f64, 0.0f64);
        let mut strongest = group[0];
        for s in group {
            let p = s.power();
            power += p;
            weighted_range += p * s.range_m;
            share += s.reflectance as f64 * s.cos_incidence as f64;
            cos_sum += s.cos_incidence as f64;
            if p > strongest.power() {
                strongest = *s;
            }
        }
        let range_m = if power > 0.0 { weighted_range / power } else { group.iter().map(|s| s.range_m).sum::<f64>() / group.len() as f64 };
        let share = share / FOOTPRINT_RAYS as f64;
        let surface = Surface {
            range_m,
            instance: strongest.instance,
            reflectance: strongest.reflectance,
            cos_incidence: (cos_sum / group.len() as f64) as f32,
            rendered: group.iter().any(|s| s.rendered),
            normal: strongest.normal,
        };
        let power = power / FOOTPRINT_RAYS as f64;
        if best.as_ref().is_none_or(|(p, _, _)| power > *p) {
            best = Some((power, surface, share as f32));
        }
        start = end;
    }
    best.map(|(_, s, share)| (s, share))
}
