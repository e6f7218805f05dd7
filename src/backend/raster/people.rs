//! The raster backend's people layer (with `render.refine = "exact"`, on a GPU; on a CPU
//! device the backend bins the people into the beams instead): conservative proxies
//! ([`crate::human::proxy`]) are rasterised into a cylindrical panorama at beam resolution, whose
//! texel centres are the beams, with an ID buffer naming the proxy triangle drawn at each
//! texel; then every beam a proxy covers is cast exactly through the people's triangle
//! clusters, the person drawn there first ([`MeshClusters::cast_seeded`]).
//!
//! In: the posed people (`FrameGeometry`, sensor frame: the triangles people are measured
//! with) and their posed proxies (one mesh per person, same order). Out: per beam the exact
//! nearest hit over all people (range, global triangle), equal to the ray-cast reference's,
//! or none.
//!
//! What the raster decides: which beams can hit a person at all (a beam whose texel shows no
//! proxy hits nobody, since every proxy encloses its person's mesh), and which person to cast
//! first. The cast then proves the answer: the drawn person's nearest hit bounds the others,
//! and any other person whose bounding sphere the beam enters before that hit is cast too.
//! Lavapipe draws 400 to 1,500 triangles a person (`render.proxy_max_error_m`) instead of
//! 26,756, and no beam away from people is touched on the CPU.

use crate::error::Result;
use crate::geometry::FrameGeometry;
use crate::gpu::Context;
use super::projection::Panorama;
use super::renderer::{RasterFrame, Renderer};
use crate::backend::raster::clusters::MeshClusters;
use super::resample::{texels_3x3, BeamLookup};
use crate::backend::BeamHits;
use crate::sensor::Sensor;
use rayon::prelude::*;
use std::sync::Arc;

/// The people's proxy renderer, its beam lookup and its scratch.
pub struct PeopleRaster {
    renderer: Renderer,
    lookup: BeamLookup,
    clusters: MeshClusters,
}

impl PeopleRaster {
    /// A panorama at beam resolution (oversample 1: one texel per column and per elevation
    /// gap, beams on texel centres) for `sensor`.
    pub fn new(ctx: &Arc<Context>, sensor: &Sensor) -> Result<PeopleRaster> {
        let pano = Panorama::new(sensor, 1.0);
        Ok(PeopleRaster {
            renderer: Renderer::new_panorama(ctx, &pano)?,
            lookup: BeamLookup::new_panorama(sensor, &pano),
            clusters: MeshClusters::default(),
        })
    }

    /// The renderer (statistics, device).
    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    /// Draws `proxies` and casts every covered beam exactly against `people` into `out`.
    pub fn render(&mut self, proxies: &FrameGeometry, people: &FrameGeometry, out: &mut BeamHits) -> Result<()> {
        debug_assert_eq!(proxies.meshes.len(), people.meshes.len());
        let frame = self.renderer.render(proxies)?;
        self.clusters.reset(people);
        // Every drawn person is cast: build their boxes one person per task.
        self.clusters.build_all(people);
        cast_covered(&self.lookup, frame, proxies, people, &self.clusters, out);
        Ok(())
    }
}

/// Per beam: the people whose proxy the panorama shows on it (the beam's own texel when the
/// beam lies on its centre, else the 3x3 texels around it) seed an exact cluster cast.
pub fn cast_covered(
    lookup: &BeamLookup,
    frame: &RasterFrame,
    proxies: &FrameGeometry,
    people: &FrameGeometry,
    clusters: &MeshClusters,
    out: &mut BeamHits,
) {
    let n = lookup.rows * lookup.columns;
    out.clear_to(n);
    let img = &frame.faces[0];
    if !img.rendered {
        return;
    }
    let w = lookup.columns;
    let (fw, fh) = (img.width, img.height);
    out.range_m
        .par_chunks_mut(w)
        .zip(out.triangle.par_chunks_mut(w))
        .enumerate()
        .for_each(|(row, (ranges, tris))| {
            let mut scratch = Vec::new();
            let mut seeds: Vec<u32> = Vec::with_capacity(9);
            for col in 0..w {
                let b = row * w + col;
                let (u, v) = lookup.texel[b];
                seeds.clear();
                let mut add = |id: u32| {
                    if id != 0 {
                        let k = proxies.mesh_index_of_triangle(id - 1) as u32;
                        if !seeds.contains(&k) {
                            seeds.push(k);
                        }
                    }
                };
                // The beam's own texel first (the person drawn on it seeds the cast), then the
                // 8 around it: a proxy drawn within a texel of the beam may still cover it (a
                // beam off its texel centre, the straight panorama chord of a curved proxy
                // edge, the rasteriser's sub-texel snapping).
                add(img.id[(v * fw + u) as usize]);
                for (uu, vv) in texels_3x3((u, v), (fw, fh), true) {
                    add(img.id[(vv * fw + uu) as usize]);
                }
                if seeds.is_empty() {
                    continue;
                }
                if let Some((r, t)) = clusters.cast_seeded(people, lookup.dirs[b], &seeds, &mut scratch) {
                    ranges[col] = r as f32;
                    tris[col] = t;
                }
            }
        });
}
