//! Clothes: the bundled bodies are unclothed, and real people wear coats, jackets and
//! trousers over theirs (a street's adults measure 0.46-0.53 m across in a real HDL-64E scan
//! at 11-16 m, pedscan's 0.38 m). `humans.clothes_m` dresses each model in
//! [`CLOTHES_VARIANTS`] thicknesses spread over the range asked: every level of detail pushed
//! out along its bind pose's normals, fully from the shins to the shoulders
//! ([`FULL_FROM`]..[`FULL_TO`] of the height), fading to nothing at the soles and at the neck,
//! so a person's height and where it stands do not change. The skin weights are kept, so the
//! clothes move with the body.

use super::{HumanModel, Lod};
use glam::Vec3;
use rayon::prelude::*;
use std::collections::HashMap;

/// Dressed variants of each model, one thickness each.
pub const CLOTHES_VARIANTS: usize = 4;
/// Share of the height below which nothing is pushed out (the soles), and from which the
/// full thickness is.
const NONE_BELOW: f32 = 0.03;
const FULL_FROM: f32 = 0.10;
/// Share of the height up to which the full thickness is (the shoulders), and above which
/// nothing (the neck and the head).
const FULL_TO: f32 = 0.80;
const NONE_ABOVE: f32 = 0.86;

/// The models people are drawn from: `models` as they are where `range_m` is [0, 0], else
/// [`CLOTHES_VARIANTS`] dressed variants of each, at thicknesses spread evenly over
/// `range_m` (the middles of its equal parts), in the models' order.
pub fn dress(models: Vec<HumanModel>, range_m: [f64; 2]) -> Vec<HumanModel> {
    if range_m[1] <= 0.0 {
        return models;
    }
    let n = CLOTHES_VARIANTS as f64;
    let thicknesses: Vec<f32> = (0..CLOTHES_VARIANTS).map(|k| (range_m[0] + (range_m[1] - range_m[0]) * (k as f64 + 0.5) / n) as f32).collect();
    // Each model on its own thread (its push directions found once for all its thicknesses);
    // the order is the models' and then the thicknesses'.
    models.par_iter().flat_map_iter(|m| m.dressed_in(&thicknesses)).collect()
}

impl HumanModel {
    /// This model in clothes `thickness_m` thick (see the module), named `NAME+clothesMM`
    /// (whole mm).
    pub fn dressed(&self, thickness_m: f32) -> HumanModel {
        self.dressed_in(&[thickness_m]).remove(0)
    }

    /// [`HumanModel::dressed`] at each of `thicknesses`.
    fn dressed_in(&self, thicknesses: &[f32]) -> Vec<HumanModel> {
        let h = self.height_m.max(1e-3);
        let pushes: Vec<Vec<(Vec3, f32)>> = self.lods.iter().map(|lod| pushes(lod, h)).collect();
        thicknesses
            .iter()
            .map(|&thickness_m| {
                let mut m = self.clone();
                m.name = format!("{}+clothes{}", self.name, (thickness_m * 1000.0).round() as u32);
                for (lod, push) in m.lods.iter_mut().zip(&pushes) {
                    for (p, &(n, share)) in lod.positions.iter_mut().zip(push) {
                        *p += n * thickness_m * share;
                    }
                }
                m
            })
            .collect()
    }
}

/// How much of the thickness a bind-pose point `y_m` over the soles gets, of a body `h` tall.
fn share(y_m: f32, h: f32) -> f32 {
    let f = y_m / h;
    let ramp = |a: f32, b: f32, x: f32| ((x - a) / (b - a)).clamp(0.0, 1.0);
    ramp(NONE_BELOW, FULL_FROM, f).min(1.0 - ramp(FULL_TO, NONE_ABOVE, f))
}

/// Per vertex of `lod`, the way clothes push it out and the share of their thickness it gets:
/// its normal (area-weighted face normals, shared by all vertices at one position, so seams
/// stay closed) and [`share`] of its height in a body `h` tall.
fn pushes(lod: &Lod, h: f32) -> Vec<(Vec3, f32)> {
    let key = |p: Vec3| ((p.x * 1e5).round() as i64, (p.y * 1e5).round() as i64, (p.z * 1e5).round() as i64);
    let mut welded: HashMap<(i64, i64, i64), Vec3> = HashMap::new();
    for t in lod.indices.chunks_exact(3) {
        let [a, b, c] = [t[0], t[1], t[2]].map(|i| lod.positions[i as usize]);
        let n = (b - a).cross(c - a);
        for p in [a, b, c] {
            *welded.entry(key(p)).or_insert(Vec3::ZERO) += n;
        }
    }
    lod.positions.iter().map(|p| (welded.get(&key(*p)).copied().unwrap_or(Vec3::ZERO).normalize_or_zero(), share(p.y, h))).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Dressed 5 cm thick, a bundled body grows by about 10 cm through its chest and at its
    /// hips, keeps its height and its soles, and its head stays as it was; the names say the
    /// thickness; [0, 0] leaves the models alone.
    #[test]
    fn clothes_widen_the_body_not_its_height() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/humans/h1700_w60.glb");
        let m = HumanModel::load(&path, false).unwrap();
        let d = m.dressed(0.05);
        let h = m.height_m;
        // Extent along x (across) or z (front to back) of the points between two shares of the height.
        let extent = |m: &HumanModel, lo: f32, hi: f32, axis: usize| {
            let v: Vec<f32> = m.lods[0].positions.iter().filter(|p| p.y >= lo * h && p.y <= hi * h).map(|p| p.to_array()[axis]).collect();
            v.iter().copied().fold(f32::NEG_INFINITY, f32::max) - v.iter().copied().fold(f32::INFINITY, f32::min)
        };
        for (lo, hi, axis, what) in [(0.68, 0.74, 2, "chest, front to back"), (0.5, 0.56, 2, "hips, front to back")] {
            let grew = extent(&d, lo, hi, axis) - extent(&m, lo, hi, axis);
            assert!((0.07..=0.13).contains(&grew), "{what}: grew {grew} m");
        }
        assert!((extent(&d, 0.9, 1.0, 0) - extent(&m, 0.9, 1.0, 0)).abs() < 1e-4, "the head");
        let span = |m: &HumanModel| {
            let y = m.lods[0].positions.iter().map(|p| p.y);
            (y.clone().fold(f32::INFINITY, f32::min), y.fold(f32::NEG_INFINITY, f32::max))
        };
        assert_eq!(span(&d), span(&m));
        assert!(d.lods.iter().zip(&m.lods).all(|(a, b)| a.positions.len() == b.positions.len() && a.indices == b.indices));
        assert_eq!(d.name, "h1700_w60+clothes50");
        let names: Vec<String> = dress(vec![m.clone()], [0.02, 0.06]).into_iter().map(|m| m.name).collect();
        assert_eq!(names, ["h1700_w60+clothes25", "h1700_w60+clothes35", "h1700_w60+clothes45", "h1700_w60+clothes55"]);
        assert_eq!(dress(vec![m], [0.0, 0.0]).len(), 1);
    }
}
