//! Stage 4, for the raster backend on a GPU: conservative proxies of the people. A proxy is a coarse
//! level of detail of a person pushed outward along its normals, so that in every pose its
//! closed surface encloses the mesh the person is measured with. The raster backend draws
//! the proxies (a few hundred to a few thousand triangles a person instead of 26,756) into a
//! panorama whose texel centres are the beams: a beam no proxy covers hits no person; a beam
//! a proxy covers is cast exactly, starting with the person drawn there
//! (`crate::backend::raster::people`).
//!
//! In: a [`HumanModel`] and its levels of detail (bind pose, model frame, with the recorded
//! geometric error of each against LOD 0). Out: per level of detail the person can be drawn
//! at, a skinned mesh ([`Lod`], same skeleton) to rasterise in its place.
//!
//! What the raster backend needs of a proxy is *coverage*: every beam that hits the person
//! meets the proxy somewhere (the covered beam is then cast exactly against every person, so
//! where along the beam the proxy lies does not matter). Why the offset covers: every point
//! of LOD `t` lies within `e_t` of LOD 0's surface, which lies within `e_s` of LOD `s`'s
//! (two-sided Hausdorff estimates over the rest pose and 16 gait phases, recorded with a 10 %
//! margin by the model builder). Pushing LOD `s` outward by `e_s + e_t` (more at a vertex whose
//! neighbouring faces turn away from its normal, so every face plane moves by at least that
//! much) encloses LOD `t` where those estimates hold. [`PROXY_MARGIN_M`] is added for what
//! they do not see: skinning of the offset itself, poses between the sampled phases, thin
//! parts a coarse level collapses. `tests/it/proxy.rs` checks coverage for every bundled person
//! at 16 gait phases from six views (about a million hit rays: with a 5 mm margin 5 rays
//! missed the proxy, with 15 mm one, with 25 mm none), and that it fails when the offset is
//! shrunk. The raster adds one texel of slack on top (`crate::backend::raster::people`).

use crate::geometry::Adjacency;
use crate::human::{HumanModel, Lod};
use glam::Vec3;
use std::sync::Arc;

/// Added to every proxy's offset, metres (the smallest margin of 5, 15 and 25 mm with which
/// `tests/it/proxy.rs` finds no uncovered ray).
pub const PROXY_MARGIN_M: f32 = 0.025;

/// A vertex is pushed at most this many times the offset (where its faces turn sharply
/// away from its normal, e.g. finger tips of a coarse level).
const MAX_OFFSET_FACTOR: f32 = 3.0;

/// The proxies of one model, indexed by the level of detail the person is measured with.
#[derive(Clone, Debug)]
pub struct ModelProxies {
    /// `lods[t]`: the proxy drawn for a person measured with LOD `t`.
    pub lods: Vec<Lod>,
    /// The level of detail each proxy was built from.
    pub source_lod: Vec<usize>,
    /// The outward offset of each proxy, metres.
    pub offset_m: Vec<f32>,
}

impl ModelProxies {
    /// Proxies of every level of detail of `model`, built from its coarsest level whose
    /// recorded error is at most `max_error_m` (or the level itself where that is coarser),
    /// offset outward by `scale` times the covering distance (1 in use; tests shrink it to
    /// show that coverage then fails).
    pub fn build(model: &HumanModel, max_error_m: f32, scale: f32) -> ModelProxies {
        let coarse = model.lod_for_error(max_error_m);
        let mut out = ModelProxies { lods: Vec::new(), source_lod: Vec::new(), offset_m: Vec::new() };
        for t in 0..model.lods.len() {
            let s = coarse.max(t);
            let cover = if s == t { 0.0 } else { model.lods[s].error_m + model.lods[t].error_m };
            let offset = scale * (cover + PROXY_MARGIN_M);
            out.lods.push(offset_lod(&model.lods[s], offset));
            out.source_lod.push(s);
            out.offset_m.push(offset);
        }
        out
    }
}

/// `lod` with every vertex pushed along its area-weighted normal so that each face plane
/// around it moves outward by at least `offset_m` (up to [`MAX_OFFSET_FACTOR`] times it).
pub fn offset_lod(lod: &Lod, offset_m: f32) -> Lod {
    let n = lod.positions.len();
    let mut normals = vec![Vec3::ZERO; n];
    let face_normal = |t: &[u32]| {
        let [a, b, c] = [0, 1, 2].map(|k| lod.positions[t[k] as usize]);
        (b - a).cross(c - a)
    };
    for t in lod.indices.chunks_exact(3) {
        let f = face_normal(t);
        for &i in t {
            normals[i as usize] += f;
        }
    }
    for v in &mut normals {
        *v = v.normalize_or_zero();
    }
    // The smallest cosine between a vertex normal and the unit normals of its faces.
    let mut min_cos = vec![1.0f32; n];
    for t in lod.indices.chunks_exact(3) {
        let f = face_normal(t).normalize_or_zero();
        if f == Vec3::ZERO {
            continue;
        }
        for &i in t {
            let c = normals[i as usize].dot(f);
            min_cos[i as usize] = min_cos[i as usize].min(c);
        }
    }
    let positions = lod
        .positions
        .iter()
        .zip(normals.iter().zip(&min_cos))
        .map(|(&p, (&nv, &c))| p + nv * offset_m * (1.0 / c.max(1.0 / MAX_OFFSET_FACTOR)))
        .collect();
    Lod {
        positions,
        joints: lod.joints.clone(),
        weights: lod.weights.clone(),
        indices: lod.indices.clone(),
        error_m: lod.error_m,
        adjacency: Arc::new(Adjacency::default()),
    }
}
