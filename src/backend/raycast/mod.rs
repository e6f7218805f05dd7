//! The ray-cast backend and the CPU reference: an independent path over the same posed
//! triangles as the Vulkan raster path, used to check it frame by frame. Correctness first,
//! then speed.
//!
//! * Rays start at the sensor origin (the geometry is already in the sensor frame).
//! * Ray/triangle test: the watertight algorithm of Woop, Benthin and Wald (JCGT 2(1), 2013),
//!   in f64 on the f32 vertices widened exactly to f64. The three 2D edge functions are
//!   evaluated with an exact sign (FMA two-product + Shewchuk two-two-diff expansion when the
//!   fast f64 value is within its rounding error bound), so a ray through a shared edge or
//!   vertex of a closed mesh never slips between the triangles (it may hit both; the smaller
//!   range, then the smaller triangle index, wins). Exactness of the sign holds while the
//!   products of sheared coordinates stay in the normal f64 range (|coordinates| well inside
//!   1e-140 .. 1e140, i.e. always for metres).
//! * Front face (shared with the rasterizer): triangle (a, b, c) faces the sensor iff
//!   `dot((b - a) x (c - a), a) < 0` (counter-clockwise seen from the sensor). Meshes with
//!   `double_sided == false` cull back faces; `true` hits both sides.
//! * Zero-area triangles (exactly collinear or repeated vertices) never hit; NaN/inf
//!   vertices never hit and never produce NaN.
//! * Precision: f32 in, f64 intersection (the only mode; widening is exact). `Hit::range_m`
//!   is the f64 ray parameter `t`, which is the Euclidean range for unit directions (for a
//!   non-unit `dir` the range is `t * |dir|`).
//! * Determinism: each ray returns the lexicographic minimum of (range, triangle index) over
//!   all hits with `range <= max_range_m`; it does not depend on thread count or traversal
//!   order, and the BVH build itself is deterministic.
//! * Two casters share the intersection test and the tie rule, so they return the same hits
//!   bit for bit: [`cast`] traces each ray through the BVH (the reference for `crosscheck`
//!   and `bench`, and for arbitrary ray sets); [`BeamCaster`] casts a whole sensor grid by
//!   binning the triangles into beams, with no BVH to build or refit (the ray-cast backend's
//!   caster for generation: ~4x less time per frame for posed people, see `beams.rs`).
//!
//! The ray/triangle test and its exact arithmetic are shared with the raster backend's
//! refinement and live one level up (`backend/triangle.rs`, `backend/exact.rs`). The files
//! here, each with its own tests:
//! * `backend.rs`: [`RaycastBackend`], this caster as a [`crate::backend::Backend`].
//! * `bvh.rs`: the two-level BVH ([`Bvh`]): node layout, binned SAH and Morton (LBVH)
//!   builds of the per-mesh trees, the top level over the meshes.
//! * `refit.rs`: [`BvhCache`], which keeps the per-mesh trees across frames and refits their
//!   boxes instead of rebuilding them.
//! * `traverse.rs`: the traversal and the casts through the BVH ([`cast`],
//!   [`cast_with_filter`], [`cast_frame`]), and [`cast_brute_force`], their referee.
//! * `beams.rs`: [`BeamCaster`], the whole-grid caster without a BVH.
//! * `test_support.rs` (tests only): the seeded RNG, meshes and soups the tests share.

mod backend;
mod beams;
mod bvh;
mod refit;
#[cfg(test)]
pub(crate) mod test_support;
mod traverse;

pub use backend::RaycastBackend;
pub use beams::{BeamCaster, GridBound};
pub use bvh::Bvh;
pub use refit::{BvhCache, BvhCacheStats};
pub use traverse::{cast, cast_brute_force, cast_frame, cast_with_filter};
pub use crate::backend::triangle::{intersect_triangle, Hit};
