//! Linear-blend skinning (4 influences) of a level of detail, on the CPU.

use super::*;
use glam::{Affine3A, Mat4, Vec3A};
use rayon::prelude::*;

impl HumanModel {
    /// Skins LOD `lod` with `joints` and maps it through `transform` (model -> target frame),
    /// writing f32 positions into `out` (resized). Without a skin the bind pose is used.
    pub fn skin_into(&self, lod: usize, joints: &[Mat4], transform: &Mat4, out: &mut Vec<[f32; 3]>) {
        out.resize(self.lods[lod].positions.len(), [0.0; 3]);
        self.skin_into_slice(lod, joints, transform, &mut Vec::new(), out);
    }

    /// Like `skin_into`, into a slice of exactly the LOD's vertex count (e.g. the person's
    /// vertices in last frame's geometry); `placed` is scratch for the placed joint matrices.
    pub fn skin_into_slice(
        &self,
        lod: usize,
        joints: &[Mat4],
        transform: &Mat4,
        placed: &mut Vec<Affine3A>,
        out: &mut [[f32; 3]],
    ) {
        self.skin_lod_into_slice(&self.lods[lod], joints, transform, placed, out);
    }

    /// `skin_into_slice` for any mesh skinned to this model's skeleton (one of its LODs, or a
    /// proxy built from one: `crate::human::proxy`).
    pub fn skin_lod_into_slice(
        &self,
        l: &Lod,
        joints: &[Mat4],
        transform: &Mat4,
        placed: &mut Vec<Affine3A>,
        out: &mut [[f32; 3]],
    ) {
        assert_eq!(out.len(), l.positions.len(), "skinning into a slice of another size");
        if joints.is_empty() {
            out.par_iter_mut().zip(l.positions.par_iter()).for_each(|(o, p)| *o = transform.transform_point3(*p).into());
            return;
        }
        // The placement folded into each joint once (affine 3x4, SIMD), instead of once per
        // vertex: sum_k w_k (T J_k) p.
        placed.clear();
        placed.extend(joints.iter().map(|j| Affine3A::from_mat4(*transform * *j)));
        let placed = &placed[..];
        out.par_chunks_mut(2048).enumerate().for_each(|(c, chunk)| {
            let first = c * 2048;
            for (k, o) in chunk.iter_mut().enumerate() {
                *o = skin_vertex(l, placed, first + k).into();
            }
        });
    }
}

/// Vertex `i` of `l` skinned with the placed joint matrices `placed` (linear blend); the bind
/// pose where `placed` is empty (a model without a skin).
#[inline(always)]
pub fn skin_vertex(l: &Lod, placed: &[Affine3A], i: usize) -> Vec3A {
    let p = Vec3A::from(l.positions[i]);
    if placed.is_empty() {
        return p;
    }
    let j = l.joints[i];
    let w = l.weights[i];
    let mut acc = Vec3A::ZERO;
    for k in 0..4 {
        if w[k] != 0.0 {
            acc += w[k] * placed[j[k] as usize].transform_point3a(p);
        }
    }
    acc
}
