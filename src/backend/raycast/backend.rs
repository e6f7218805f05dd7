//! The ray-cast backend: every beam cast on the CPU through the posed triangles with the
//! watertight f64 test. By default the triangles are binned into the beams they can reach
//! ([`BeamCaster`]: no acceleration structure per frame); `debug.caster = "bvh"` traces each
//! beam through a bottom-level BVH per layer, refit to each pose (the reference; the same
//! hits, bit for bit). No Vulkan anywhere.

use crate::backend::{Backend, BeamHits, Layer};
use crate::config::BackendChoice;
use crate::error::Result;
use crate::backend::raycast::{BeamCaster, BvhCache, Hit};
use crate::sensor::Sensor;
use glam::DVec3;

/// How the beams are cast.
enum Caster {
    Beams(BeamCaster),
    /// One BVH cache per layer (background, people), refit across frames.
    Bvh([BvhCache; 2]),
}

/// The CPU ray caster as a [`Backend`].
pub struct RaycastBackend {
    dirs: Vec<DVec3>,
    caster: Caster,
    cast: Vec<Hit>,
    build_s: f64,
}

impl RaycastBackend {
    /// A caster for `sensor`'s beams: binned (`bvh = false`) or through BVHs, refit across
    /// frames unless `bvh_refit` is false (then rebuilt every frame, for comparison).
    pub fn new(sensor: &Sensor, bvh: bool, bvh_refit: bool) -> RaycastBackend {
        let dirs = sensor.beam_dirs();
        let caster = if bvh {
            let cache = || if bvh_refit { BvhCache::new() } else { BvhCache::disabled() };
            Caster::Bvh([cache(), cache()])
        } else {
            Caster::Beams(BeamCaster::new(&dirs, sensor.rows(), sensor.columns))
        };
        RaycastBackend { dirs, caster, cast: Vec::new(), build_s: 0.0 }
    }
}

impl Backend for RaycastBackend {
    fn choice(&self) -> BackendChoice {
        BackendChoice::Raycast
    }

    fn device_name(&self) -> String {
        "the CPU ray caster".into()
    }

    fn cast(&mut self, layer: Layer<'_>, hits: &mut BeamHits) -> Result<()> {
        let (geom, slot) = match layer {
            Layer::Background(g) => (g, 0),
            Layer::People { people, .. } => (people, 1),
        };
        if geom.meshes.is_empty() {
            hits.clear_to(self.dirs.len());
            return Ok(());
        }
        // Ranges are limited later, in the post-pass, as for the raster backend.
        match &mut self.caster {
            Caster::Beams(caster) => caster.cast(geom, f64::MAX, &mut self.cast),
            Caster::Bvh(caches) => {
                let t0 = std::time::Instant::now();
                let bvh = caches[slot].build_or_refit(geom);
                self.build_s += t0.elapsed().as_secs_f64();
                self.cast = crate::backend::raycast::cast(geom, bvh, &self.dirs, f64::MAX);
            }
        }
        hits.set_from(&self.cast);
        Ok(())
    }

    fn take_build_seconds(&mut self) -> f64 {
        std::mem::take(&mut self.build_s)
    }

    fn near_seam(&self, _texels: f64) -> Vec<bool> {
        vec![false; self.dirs.len()]
    }
}
