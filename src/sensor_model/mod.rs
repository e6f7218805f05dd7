//! Stage 7b: the sensor's own effects on a composited frame, after Velodyne's manuals and
//! the usual simulator models (see docs/sensor-model.md for every default and its
//! source). Applied per beam to what pedscan renders (people, an environment), never to a
//! recorded background's beams, which carry their own:
//!
//! - **Intensity** `I = scale * reflectance * cos(incidence)` (calibrated, no range falloff,
//!   like Velodyne's calibrated reflectivity and KITTI's remission); written always.
//! - **Beam divergence**: a beam near a silhouette (a neighbour on the grid sees another
//!   person or nothing, or lies across a depth step of the environment: [`across_silhouette`])
//!   is cast as [`FOOTPRINT_RAYS`] rays over its elliptical footprint;
//!   hits closer together than `mixed_return_m` form one return at their power-weighted range
//!   (a mixed pixel), and of several such returns the strongest is kept (Velodyne's default
//!   return mode). Its power and intensity are the footprint's share.
//! - **Dropout**: a return is detected with probability `(1 - dropout_rate) * g(incidence) *
//!   d(power)`: `d` a logistic in the log of the received power `reflectance * cos / r^2`
//!   against that of reflectance 0.1 head-on at `detection_range_m`, `g` falling linearly in
//!   cos(incidence) from 1 to `1 - grazing_loss` over `grazing_deg`. A lost return is a hole:
//!   range 0, label 0, instance 0.
//! - **Range noise**: a per-laser bias (drawn per sequence) plus Gaussian noise per return.
//! - **Platform**: a rendered surface behind one of `platform`'s boxes (the mount, in the
//!   sensor frame) returns nothing.
//!
//! The rolling shutter (each column at its own time) is not a post effect: the frame is posed
//! over the sweep ([`shutter`]).
//!
//! Random numbers: a ChaCha8 stream per (sequence, frame, row), the same number of draws per
//! beam whatever happens to it, so every output is the same at any thread count.

pub mod shutter;
pub mod surfaces;

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
/// `dirs[1..]` into `out[1..]`; `dirs[0]` is the beam itself, whose surface `out[0]` holds.
/// `across` are the beam's grid neighbours that see another surface (the silhouette lies
/// between them and the beam).
pub trait FootprintScene: Sync {
    fn cast_footprint(&self, beam: usize, across: &[usize], dirs: &[DVec3; FOOTPRINT_RAYS], out: &mut [Option<Surface>; FOOTPRINT_RAYS]);
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
    // Per beam, whether a silhouette lies between it and its right (bit 0) and lower (bit 1)
    // neighbour: each pair once (the relation is symmetric).
    let pairs: Vec<u8> = if divergence {
        let rows = n / w;
        (0..n)
            .into_par_iter()
            .with_min_len(w)
            .map(|b| {
                let (row, col) = (b / w, b % w);
                let right = across_silhouette(f, b, row * w + (col + 1) % w) as u8;
                let below = (row + 1 < rows && across_silhouette(f, b, b + w)) as u8;
                right | below << 1
            })
            .collect()
    } else {
        Vec::new()
    };
    // The footprints: per row at azimuth 0, per column the azimuth's sine and cosine.
    let (ahead, sin_cos): (Vec<[DVec3; FOOTPRINT_RAYS]>, Vec<(f64, f64)>) = if divergence {
        (f.elevation_rad.iter().map(|&el| footprint_ahead(el, cfg.divergence_mrad)).collect(), f.azimuth_rad.iter().map(|a| a.sin_cos()).collect())
    } else {
        (Vec::new(), Vec::new())
    };
    // Where each beam enters the platform (infinity: it does not).
    let platform: Vec<f64> = if on && !cfg.platform.is_empty() {
        f.dirs.iter().map(|&d| cfg.platform.iter().filter_map(|b| b.entry(d)).fold(f64::INFINITY, f64::min)).collect()
    } else {
        Vec::new()
    };
    out.par_chunks_mut(w).enumerate().for_each(|(row, outs)| {
        let mut rng = stream(f.seed, f.sequence as u64, f.frame as u64);
        rng.set_stream(row as u64);
        for (col, o) in outs.iter_mut().enumerate() {
            let b = row * w + col;
            // Every beam draws the same three numbers, used or not.
            let u_drop: f64 = rng.random::<f64>();
            let z = gaussian(&mut rng);
            let clean = f.clean[b];
            let (across, count) = if divergence { edge_neighbours(&pairs, b, w) } else { ([0; 4], 0) };
            let edge = count > 0;
            let ret = if edge { footprint_return(f, scene, b, &across[..count], &ahead[row], sin_cos[col]) } else { clean.map(|s| (s, s.reflectance * s.cos_incidence)) };
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
            // Behind the platform: hidden.
            if platform.get(b).is_some_and(|&t| s.range_m > t) {
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
            // Linear in cos(incidence) from 1 at grazing_deg[0] to 1 - grazing_loss at [1].
            let loss = cfg.grazing_loss;
            let g = if c >= g0 { 1.0 } else if c <= g1 || g0 <= g1 { 1.0 - loss } else { 1.0 - loss * (g0 - c) / (g0 - g1) };
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

/// The grid neighbours of beam `b` (left and right, columns wrapping; above and below) across
/// a silhouette from it ([`across_silhouette`], from `pairs`), and how many there are (0: not
/// an edge).
fn edge_neighbours(pairs: &[u8], b: usize, w: usize) -> ([usize; 4], usize) {
    let (row, col) = (b / w, b % w);
    let left = row * w + (col + w - 1) % w;
    let mut across = [0; 4];
    let mut count = 0;
    let mut add = |yes: bool, nb: usize| {
        if yes {
            across[count] = nb;
            count += 1;
        }
    };
    add(pairs[left] & 1 != 0, left);
    add(pairs[b] & 1 != 0, row * w + (col + 1) % w);
    add(row > 0 && pairs[b - w] & 2 != 0, b.wrapping_sub(w));
    add(pairs[b] & 2 != 0, b + w);
    (across, count)
}

/// Whether a silhouette may lie between beams `b` and `nb` (grid neighbours), so that either's
/// footprint may hold it: one sees another person than the other, or nothing where the other
/// sees a person; or, in a rendered environment, they lie across a depth step (a pillar before
/// a wall, a table's edge over the floor) or one sees nothing. A step is told from a fold (a
/// floor meeting a wall, a box's corner: continuous, so a footprint's rays stay within a few
/// centimetres of its centre's range) by the two surfaces' planes: over the directions between
/// the two beams a fold's planes cross, a step's stay apart, here by more than
/// `mixed_return_m` at both beams. A recorded background carries its own edges. Symmetric.
fn across_silhouette(f: &FrameIn, b: usize, nb: usize) -> bool {
    match (f.clean[b], f.clean[nb]) {
        (None, None) => false,
        (Some(a), Some(o)) if a.instance != o.instance => true,
        (Some(a), Some(o)) => a.instance == 0 && a.rendered && o.rendered && is_step(&a, f.dirs[b], &o, f.dirs[nb], f.cfg.mixed_return_m),
        (Some(a), None) | (None, Some(a)) => a.instance > 0 || a.rendered,
    }
}

/// Whether surfaces `a` (met along `da`) and `o` (along `db`) are a depth step rather than
/// one continuous surface (see [`across_silhouette`]): `a`'s plane against `o`'s at both directions,
/// with one sign and farther apart than `mixed_m`. A plane a direction does not meet is
/// infinitely far; a surface without a normal is taken at its own range.
fn is_step(a: &Surface, da: DVec3, o: &Surface, db: DVec3, mixed_m: f64) -> bool {
    let along = |s: &Surface, d_own: DVec3, d: DVec3| -> f64 {
        if s.normal == glam::Vec3::ZERO {
            return s.range_m;
        }
        let n = s.normal.as_dvec3();
        let t = n.dot(d_own * s.range_m) / n.dot(d);
        if t > 0.0 && t.is_finite() { t } else { f64::INFINITY }
    };
    let at_a = a.range_m - along(o, db, da);
    let at_b = along(a, da, db) - o.range_m;
    at_a.signum() == at_b.signum() && at_a.abs().min(at_b.abs()) > mixed_m
}

/// The footprint ray directions of a beam at (azimuth, elevation): the centre first.
pub fn footprint_dirs(az: f64, el: f64, divergence_mrad: [f64; 2]) -> [DVec3; FOOTPRINT_RAYS] {
    turned(&footprint_ahead(el, divergence_mrad), az.sin_cos())
}

/// The footprint ray directions of a beam at elevation `el` and azimuth 0: the centre first.
fn footprint_ahead(el: f64, divergence_mrad: [f64; 2]) -> [DVec3; FOOTPRINT_RAYS] {
    let (ha, he) = (0.5e-3 * divergence_mrad[0], 0.5e-3 * divergence_mrad[1]);
    let dir = |a: f64, e: f64| DVec3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin());
    let mut d = [dir(0.0, el); FOOTPRINT_RAYS];
    for (k, v) in d.iter_mut().enumerate().skip(1) {
        let phi = std::f64::consts::TAU * (k - 1) as f64 / (FOOTPRINT_RAYS - 1) as f64;
        // Horizontal divergence is an angle in the cone's own plane: divided by cos(el) in
        // azimuth.
        *v = dir(RING * ha * phi.cos() / el.cos(), el + RING * he * phi.sin());
    }
    d
}

/// `d` turned about the vertical by the azimuth whose (sine, cosine) is `sin_cos`.
fn turned(d: &[DVec3; FOOTPRINT_RAYS], (s, c): (f64, f64)) -> [DVec3; FOOTPRINT_RAYS] {
    d.map(|v| DVec3::new(c * v.x - s * v.y, s * v.x + c * v.y, v.z))
}

/// The return of beam `b` over its footprint: the surfaces its rays meet grouped by range
/// (closer than `mixed_return_m` = one return), the strongest group kept; returns the group's
/// power-weighted surface and its share `sum(reflectance * cos) / rays`. `ahead` is the
/// footprint of the beam's row at azimuth 0 and `sin_cos` its column's azimuth.
fn footprint_return(f: &FrameIn, scene: &dyn FootprintScene, b: usize, across: &[usize], ahead: &[DVec3; FOOTPRINT_RAYS], sin_cos: (f64, f64)) -> Option<(Surface, f32)> {
    let dirs = turned(ahead, sin_cos);
    let mut hits: [Option<Surface>; FOOTPRINT_RAYS] = [None; FOOTPRINT_RAYS];
    hits[0] = f.clean[b];
    scene.cast_footprint(b, across, &dirs, &mut hits);
    let mut met = [hits[0].unwrap_or(Surface { range_m: 0.0, instance: 0, reflectance: 0.0, cos_incidence: 0.0, rendered: false, normal: glam::Vec3::ZERO }); FOOTPRINT_RAYS];
    let mut count = 0;
    for h in hits.into_iter().flatten() {
        met[count] = h;
        count += 1;
    }
    combine(&mut met[..count], f.cfg.mixed_return_m)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Every (sequence, frame) has its own stream for every seed: the key is a bijection of the
    /// frame for a fixed seed and sequence (xor with a constant, a rotation, a multiplication by
    /// an odd number), so no seed makes two frames share one. Checked at the seed that cancels
    /// sequence 0's term to all ones, where a key that merely set the frame's bits would not
    /// change with the frame at all.
    #[test]
    fn no_seed_makes_two_frames_share_a_random_stream() {
        let all_ones = !0x5e75_0a3d_e1ed_0001u64;
        for seed in [0, 7, all_ones] {
            assert!(all_distinct((0..64u64).chain([u64::MAX]).map(|frame| (seed, 0, frame))), "seed {seed:#x}: frames share a stream");
        }
    }

    /// Whether the streams of `keys` (seed, sequence, frame) all start differently.
    fn all_distinct(keys: impl Iterator<Item = (u64, u64, u64)>) -> bool {
        let mut firsts: Vec<u64> = keys.map(|(seed, sequence, frame)| stream(seed, sequence, frame).next_u64()).collect();
        let n = firsts.len();
        firsts.sort_unstable();
        firsts.dedup();
        firsts.len() == n
    }

    /// Nor do two sequences: every (sequence, frame) pair of a run, the sequences' own streams
    /// (`frame = u64::MAX`) included, starts its own stream (frame 0 of every sequence too).
    #[test]
    fn no_two_sequences_share_a_random_stream() {
        for seed in [0, 7, !0x5e75_0a3d_e1ed_0001u64] {
            let pairs = (0..8u64).flat_map(|sequence| (0..16u64).chain([u64::MAX]).map(move |frame| (seed, sequence, frame)));
            assert!(all_distinct(pairs), "seed {seed:#x}: two (sequence, frame) pairs share a stream");
        }
    }

    /// Nor do two seeds: for a given (sequence, frame), every seed starts its own stream (a
    /// run's seed is what makes its data differ from another run's).
    #[test]
    fn no_two_seeds_share_a_random_stream() {
        for (sequence, frame) in [(0, 0), (3, 17), (1, u64::MAX)] {
            let seeds = (0..64u64).chain([u64::MAX, u64::MAX - 1, 1 << 63]).map(|seed| (seed, sequence, frame));
            assert!(all_distinct(seeds), "sequence {sequence}, frame {frame}: two seeds share a stream");
        }
    }

    /// The draws behind a frame, as documented: a sequence's laser biases are its own stream's
    /// first normal draws, one per row, times `laser_bias_m`; row r of frame k draws from
    /// frame k's stream set to stream r, three numbers per beam in column order (the dropout's
    /// uniform, then the noise's normal from two uniforms), and the range is the surface's
    /// plus the row's bias plus `range_noise_m` times that normal. The same seed gives the
    /// same bytes from one version to the next only while this order holds.
    #[test]
    fn a_beams_noise_is_its_rows_stream_drawn_in_column_order() {
        struct NoFootprint;
        impl FootprintScene for NoFootprint {
            fn cast_footprint(&self, _: usize, _: &[usize], _: &[DVec3; FOOTPRINT_RAYS], _: &mut [Option<Surface>; FOOTPRINT_RAYS]) {}
        }
        let (rows, columns) = (3, 8);
        let cfg = SensorModelConfig {
            range_noise_m: 0.05,
            laser_bias_m: 0.02,
            dropout_rate: 0.0,
            detection_softness: 0.0,
            detection_range_m: 1e4,
            divergence_mrad: [0.0, 0.0],
            ..SensorModelConfig::on()
        };
        let (seed, sequence, frame) = (11u64, 2usize, 5usize);
        let draws = SequenceDraws::draw(&cfg, seed, sequence, rows, 0);
        let mut rng = stream(seed, sequence as u64, u64::MAX);
        for r in 0..rows {
            assert_eq!(draws.bias_m[r], 0.02 * gaussian(&mut rng), "row {r}'s bias");
        }
        let dirs = vec![DVec3::X; rows * columns];
        let el = vec![0.0; rows];
        let az: Vec<f64> = (0..columns).map(|c| c as f64 * 0.01).collect();
        let clean = vec![Some(Surface { range_m: 10.0, instance: 0, reflectance: 0.5, cos_incidence: 1.0, rendered: true, normal: glam::Vec3::X }); rows * columns];
        let input = FrameIn {
            cfg: &cfg,
            dirs: &dirs,
            columns,
            elevation_rad: &el,
            azimuth_rad: &az,
            min_range_m: 0.5,
            max_range_m: 100.0,
            clean: &clean,
            draws: &draws,
            intensity_scale: 1.0,
            recorded_intensity: None,
            seed,
            sequence,
            frame,
        };
        let mut out = Vec::new();
        apply(&input, &NoFootprint, &mut out);
        for r in 0..rows {
            let mut rng = stream(seed, sequence as u64, frame as u64);
            rng.set_stream(r as u64);
            for c in 0..columns {
                let _dropout: f64 = rng.random();
                let z = gaussian(&mut rng);
                let want = (10.0 + draws.bias_m[r] + 0.05 * z) as f32;
                assert_eq!(out[r * columns + c].range_m, want, "row {r}, column {c}");
            }
        }
    }

    /// The bundled people's MakeHuman joint names, region by region as the doc comment gives
    /// them; the match ignores case and any side or number suffix.
    #[test]
    fn joint_names_fall_into_their_body_regions() {
        for (names, want) in [
            (&["foot.L", "toe1-1.R", "Foot_R", "LeftToeBase"][..], SHOES),
            (&["root", "pelvis.L", "upperleg01.L", "upperleg02.R", "lowerleg01.L", "lowerleg02.R", "LeftUpLeg_thigh", "knee", "shin.R", "calf"], LOWER),
            (
                &[
                    "head", "neck01", "neck03", "jaw", "eye.L", "tongue05.R", "oris06", "oculi02.L", "levator05.R", "temporalis01.L", "risorius03.R",
                    "orbicularis04.L", "special06.R", "wrist.L", "finger3-2.R", "metacarpal4.L", "LeftHand", "thumb_01",
                ],
                SKIN,
            ),
            (&["spine05", "spine01", "breast.L", "clavicle.R", "shoulder01.L", "upperarm02.L", "lowerarm01.R", "", "chest"], UPPER),
        ] {
            for n in names {
                assert_eq!(region_of_joint(n), want, "{n:?}");
            }
        }
    }

    /// The footprint's outer rays sit on an ellipse of semi-axes `RING` times half the
    /// divergence: half the horizontal divergence measured in the cone's own plane (not in
    /// azimuth), half the vertical in elevation; six rays 60 deg apart, the first in the
    /// horizontal plane of the beam.
    #[test]
    fn footprint_rays_sit_on_the_divergence_ellipse() {
        let (az, el, div) = (0.7, -0.3, [3.0, 5.0]);
        let d = footprint_dirs(az, el, div);
        let centre = DVec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
        assert!((d[0] - centre).length() < 1e-15);
        // Horizontal and square to the beam: its dot with a ray is the sine of the ray's angle
        // off the beam's vertical plane.
        let right = DVec3::new(-az.sin(), az.cos(), 0.0);
        for (k, v) in d.iter().enumerate().skip(1) {
            assert!((v.length() - 1.0).abs() < 1e-12);
            let phi = std::f64::consts::TAU * (k - 1) as f64 / 6.0;
            // Elevation offset, closed form; the horizontal offset in the cone's plane (the
            // angle off the beam's vertical plane) to first order: the rest is tan(el) times
            // the two half-angles' product, under 6e-7 rad here.
            let de = v.z.asin() - el;
            assert!((de - RING * 2.5e-3 * phi.sin()).abs() < 1e-12, "ray {k}: {de}");
            let across = v.dot(right).asin();
            assert!((across - RING * 1.5e-3 * phi.cos()).abs() < 1e-6, "ray {k}: {across}");
        }
    }

    fn surface(range_m: f64, instance: u16, reflectance: f32, cos_incidence: f32) -> Surface {
        Surface { range_m, instance, reflectance, cos_incidence, rendered: instance > 0, normal: glam::Vec3::X }
    }

    /// `combine` in closed form: groups split where neighbours are more than `mixed_m` apart;
    /// the group of most power (reflectance x cos / r^2, summed, over all seven rays) wins; its
    /// range is power-weighted, its instance and reflectance the strongest ray's, its cosine the
    /// group's mean, its share sum(reflectance x cos) / 7.
    #[test]
    fn combine_keeps_the_strongest_group_as_written() {
        let mut hits = vec![surface(12.0, 0, 0.9, 0.8), surface(10.02, 3, 0.6, 1.0), surface(10.0, 3, 0.5, 0.9), surface(12.05, 0, 0.9, 0.7), surface(10.04, 2, 0.3, 0.5)];
        let (s, share) = combine(&mut hits, 0.1).unwrap();
        let near = [(10.0, 0.5, 0.9), (10.02, 0.6, 1.0), (10.04, 0.3, 0.5)];
        // The surfaces hold f32 reflectances and cosines.
        let f = |x: f64| x as f32 as f64;
        let p = |(r, re, c): (f64, f64, f64)| f(re) * f(c) / (r * r);
        let power: f64 = near.iter().map(|&x| p(x)).sum();
        let range = near.iter().map(|&x| p(x) * x.0).sum::<f64>() / power;
        assert!((s.range_m - range).abs() < 1e-12, "{}", s.range_m);
        assert_eq!((s.instance, s.reflectance, s.rendered), (3, 0.6, true));
        assert!((s.cos_incidence as f64 - 2.4 / 3.0).abs() < 1e-6);
        assert!((share as f64 - (0.45 + 0.6 + 0.15) / 7.0).abs() < 1e-6, "{share}");
        // Pushed beyond 12 m, the near group loses to the far one (0.72 + 0.63 over 12 m^2).
        let mut hits = vec![surface(12.0, 0, 0.9, 0.8), surface(15.02, 3, 0.6, 1.0), surface(12.05, 0, 0.9, 0.7), surface(15.0, 3, 0.5, 0.9)];
        let (s, share) = combine(&mut hits, 0.1).unwrap();
        assert_eq!((s.instance, s.rendered), (0, false));
        let far = [(12.0, 0.9, 0.8), (12.05, 0.9, 0.7)];
        let range = far.iter().map(|&x| p(x) * x.0).sum::<f64>() / far.iter().map(|&x| p(x)).sum::<f64>();
        assert!((s.range_m - range).abs() < 1e-12, "{}", s.range_m);
        assert!((share as f64 - 1.35 / 7.0).abs() < 1e-6, "{share}");
        // A farther group wins where it holds more power: one dark ray at 10 m (0.05 / 100)
        // against two bright ones at 12 m (2 x 0.81 / 144).
        let (s, _) = combine(&mut [surface(12.02, 0, 0.9, 0.9), surface(10.0, 3, 0.1, 0.5), surface(12.0, 0, 0.9, 0.9)], 0.1).unwrap();
        assert_eq!(s.instance, 0);
        assert!((s.range_m - 12.01).abs() < 1e-3, "{}", s.range_m);
        // Nothing met: no return.
        assert!(combine(&mut [], 0.1).is_none());
        // A group of no power (black surfaces) is at its rays' mean range.
        let (s, share) = combine(&mut [surface(10.0, 1, 0.0, 0.5), surface(10.06, 1, 0.0, 0.5)], 0.1).unwrap();
        assert!((s.range_m - 10.03).abs() < 1e-12 && share == 0.0, "{}", s.range_m);
        // Rays of equal power: the first in range order gives the instance (the input's order
        // at equal ranges), so the choice does not depend on anything but the rays.
        let (s, _) = combine(&mut [surface(10.0, 1, 0.5, 0.5), surface(10.0, 2, 0.5, 0.5)], 0.1).unwrap();
        assert_eq!(s.instance, 1);
    }

    /// `is_step` on a concave corner seen across rows: the upper beam (2 degrees up) meets a
    /// wall 10 m ahead, the lower (2 degrees down) the floor 0.2 m below, 5.7 m out. The
    /// floor's plane lies behind the upper beam (infinitely far along it), the wall's 10 m
    /// along the lower one: the two differences have opposite signs, so a fold, not a step.
    /// Lifted 0.3 m off the floor the lower surface is a table before the wall: a step.
    #[test]
    fn a_plane_behind_a_beam_is_infinitely_far_along_it() {
        let dir = |deg: f64| DVec3::new(deg.to_radians().cos(), 0.0, deg.to_radians().sin());
        let (up, down) = (dir(2.0), dir(-2.0));
        let wall = Surface { range_m: 10.0 / up.x, instance: 0, reflectance: 0.5, cos_incidence: 1.0, rendered: true, normal: glam::Vec3::X };
        let floor = Surface { range_m: 0.2 / -down.z, normal: glam::Vec3::Z, ..wall };
        assert!(floor.range_m * down.x < 6.0);
        assert!(!is_step(&wall, up, &floor, down, 0.5));
        assert!(!is_step(&floor, down, &wall, up, 0.5), "symmetric");
        // A table top facing the lower beam (normal along x): both planes stay apart.
        let table = Surface { range_m: floor.range_m, normal: glam::Vec3::X, ..wall };
        assert!(is_step(&wall, up, &table, down, 0.5));
    }

    /// A beam's neighbours across a silhouette, from the pair bits (bit 0: a silhouette between
    /// a beam and its right neighbour, columns wrapping; bit 1: between it and the one below),
    /// on a 3 x 4 grid: each neighbour is listed once, left, right, above, below.
    #[test]
    fn edge_neighbours_read_each_pair_from_the_beam_that_holds_it() {
        let w = 4;
        let mut pairs = vec![0u8; 12];
        let none = |pairs: &[u8], b: usize| edge_neighbours(pairs, b, w).1 == 0;
        assert!((0..12).all(|b| none(&pairs, b)));
        // Beam 5 (row 1, column 1): a silhouette to its right and below.
        pairs[5] = 0b11;
        assert_eq!(edge_neighbours(&pairs, 5, w), ([6, 9, 0, 0], 2));
        assert_eq!(edge_neighbours(&pairs, 6, w), ([5, 0, 0, 0], 1), "its right neighbour sees it on its left");
        assert_eq!(edge_neighbours(&pairs, 9, w), ([5, 0, 0, 0], 1), "the one below sees it above");
        assert!([0, 1, 2, 3, 4, 7, 8, 10, 11].iter().all(|&b| none(&pairs, b)));
        // The last column's right neighbour is the first column of its row, and back.
        pairs.fill(0);
        pairs[7] = 0b01;
        assert_eq!(edge_neighbours(&pairs, 7, w), ([4, 0, 0, 0], 1));
        assert_eq!(edge_neighbours(&pairs, 4, w), ([7, 0, 0, 0], 1));
        // All four at once, for a beam inside the grid.
        pairs.fill(0);
        (pairs[4], pairs[5], pairs[1]) = (0b01, 0b11, 0b10);
        assert_eq!(edge_neighbours(&pairs, 5, w), ([4, 6, 1, 9], 4));
    }
}
