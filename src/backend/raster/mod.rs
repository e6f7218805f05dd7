//! The raster backend: Vulkan draws the posed triangles into views whose texels map to the
//! beams, with an ID buffer naming the triangle drawn at each texel; the CPU resamples the
//! views to the beam grid and refines each beam's range. In data-flow order:
//!
//! - `projection`: the views (4 cube side faces with band frusta, or one cylindrical
//!   panorama) and their exact texel <-> direction mappings.
//! - `panorama`: the CPU half of drawing into the panorama (the azimuth wrap, curved edges).
//! - `renderer`: the Vulkan pipelines and per-frame draw + read-back.
//! - `resample`: views -> beam grid, with no refinement, the triangle's plane, or exact
//!   re-intersection of the triangles around the texel (the default).
//! - `beam_exact`: `projection = "beams"`: no views; the background's triangles drawn as
//!   their beam-grid bounds into one texel per beam and tested exactly per beam on the device.
//! - `people`: with exact refinement on a GPU, the people are drawn as conservative proxies
//!   ([`crate::human::proxy`]) at beam resolution and every beam a proxy covers is cast
//!   exactly through the people's triangle clusters. On a CPU device (lavapipe) the people
//!   are binned into the beams instead ([`BeamCaster`], see [`People`]).

pub mod beam_exact;
pub mod clusters;
pub mod panorama;
pub mod people;
pub mod projection;
pub mod renderer;
pub mod resample;

use super::{cast_in_turn, Backend, BeamHits, FrameSeconds, Layer};
use crate::backend::raycast::{BeamCaster, Hit};
use crate::config::{BackendChoice, PeoplePath, Projection, Refine, RenderConfig};
use crate::error::{Error, Result};
use crate::gpu::Context;
use crate::human::HumanModel;
use beam_exact::BeamExact;
use people::PeopleRaster;
use projection::{CubeFaces, Panorama, PANORAMA_MAX_ELEVATION_DEG};
use crate::human::proxy::ModelProxies;
use rayon::prelude::*;
use renderer::Renderer;
use resample::{resample, BeamLookup};
use std::sync::atomic::AtomicUsize;
use std::sync::Arc;

/// How the background layer is drawn.
enum Views {
    /// Cube faces or the panorama, resampled to the beams and refined.
    Resampled { lookup: BeamLookup, renderer: Renderer },
    /// The beam grid, exact per beam (`projection = "beams"`).
    Beams(BeamExact),
}

/// How the people layer is cast with exact refinement.
///
/// On a CPU device the proxy draw costs more than it saves: lavapipe draws the proxies on the
/// same cores that then cast every covered beam through the people's clusters, while the
/// binned caster settles all 32,768 beams with integer tests on most triangles (paper
/// scenario, per frame: proxy draw ~9 ms and cluster casts ~11 ms against ~8 ms binned, and no
/// proxies to skin). There the people are binned; on a GPU the draw is nearly free.
/// `debug.people` forces either path on any device (the proxies' path is tested on lavapipe).
// One per backend: the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
enum People {
    /// Proxies drawn at beam resolution and every covered beam cast exactly.
    Proxies(PeopleRaster),
    /// Every beam binned on the CPU ([`BeamCaster`], the same hits bit for bit).
    Binned { caster: BeamCaster, cast: Vec<Hit> },
}

/// The Vulkan raster path as a [`Backend`].
pub struct RasterBackend {
    refine: Refine,
    views: Views,
    beams: usize,
    /// With exact refinement: how the people are cast exactly.
    people: Option<People>,
    /// Per model, the proxies of its levels of detail (with `People::Proxies`).
    proxies: Vec<ModelProxies>,
    ctx: Arc<Context>,
}

impl RasterBackend {
    /// The views of `render.projection` at `render.oversample` for `sensor` on `ctx`; with
    /// exact refinement on a GPU, the people's proxies (`render.proxy_max_error_m`) for
    /// `models`, on a CPU device the binned caster (see [`People`]); `people` overrides the
    /// device's choice (`debug.people`).
    pub fn new(
        ctx: Arc<Context>,
        sensor: &crate::sensor::Sensor,
        render: &RenderConfig,
        people: PeoplePath,
        models: &[HumanModel],
    ) -> Result<RasterBackend> {
        let band = sensor.max_abs_elevation_deg();
        let too_steep = |limit: f64, what: &str, instead: String| {
            Error::input(format!("sensor {}", sensor.name), format!("its beams reach +-{band} deg, past the +-{limit} deg {what}; {instead}"))
        };
        let other_views = || {
            format!(
                "projection = \"beams\" (render.projection) or the ray caster (--backend raycast) take any elevation up to +-{} deg{}",
                crate::sensor::MAX_ELEVATION_DEG,
                if band <= PANORAMA_MAX_ELEVATION_DEG { ", projection = \"cylinder\" up to +-45 deg" } else { "" }
            )
        };
        match render.projection {
            Projection::Cube if band > crate::sensor::CUBE_MAX_ELEVATION_DEG => {
                return Err(too_steep(crate::sensor::CUBE_MAX_ELEVATION_DEG, "the cube faces cover", other_views()));
            }
            Projection::Cylinder if band > PANORAMA_MAX_ELEVATION_DEG => {
                return Err(too_steep(PANORAMA_MAX_ELEVATION_DEG, "a cylindrical panorama covers", other_views()));
            }
            _ => {}
        }
        let views = match render.projection {
            Projection::Cube => {
                let cube = CubeFaces::new(sensor, render.oversample);
                Views::Resampled { lookup: BeamLookup::new(sensor, &cube), renderer: Renderer::new(&ctx, &cube)? }
            }
            Projection::Cylinder => {
                let pano = Panorama::new(sensor, render.oversample);
                Views::Resampled { lookup: BeamLookup::new_panorama(sensor, &pano), renderer: Renderer::new_panorama(&ctx, &pano)? }
            }
            // Exact by construction: `refine` only decides how the people are drawn.
            Projection::Beams => Views::Beams(BeamExact::new(&ctx, sensor, render.host_cast_beams)?),
        };
        // The people's proxies are drawn into a panorama: past its band they are binned.
        let binned = match people {
            PeoplePath::Auto => ctx.is_cpu() || band > PANORAMA_MAX_ELEVATION_DEG,
            PeoplePath::Binned => true,
            PeoplePath::Proxies if render.refine == Refine::Exact && band > PANORAMA_MAX_ELEVATION_DEG => {
                return Err(too_steep(
                    PANORAMA_MAX_ELEVATION_DEG,
                    "the people's proxy panorama (debug.people = \"proxies\") covers",
                    "debug.people = \"binned\" (or \"auto\") casts the people on the CPU at any elevation".into(),
                ));
            }
            PeoplePath::Proxies => false,
        };
        let (people, proxies) = match render.refine {
            Refine::Exact if binned => {
                let caster = BeamCaster::new(&sensor.beam_dirs(), sensor.rows(), sensor.columns);
                (Some(People::Binned { caster, cast: Vec::new() }), Vec::new())
            }
            Refine::Exact => {
                let max_error = render.proxy_max_error_m as f32;
                let proxies: Vec<ModelProxies> = models.par_iter().map(|m| ModelProxies::build(m, max_error, 1.0)).collect();
                (Some(People::Proxies(PeopleRaster::new(&ctx, sensor)?)), proxies)
            }
            _ => (None, Vec::new()),
        };
        let beams = sensor.rows() * sensor.columns;
        Ok(RasterBackend { refine: render.refine, views, beams, people, proxies, ctx })
    }

    /// The Vulkan context it draws with.
    pub fn context(&self) -> &Arc<Context> {
        &self.ctx
    }
}

impl Backend for RasterBackend {
    fn choice(&self) -> BackendChoice {
        BackendChoice::Raster
    }

    fn device_name(&self) -> String {
        self.context().device_name()
    }

    fn proxies(&self) -> Option<&[ModelProxies]> {
        matches!(self.people, Some(People::Proxies(_))).then_some(&self.proxies[..])
    }

    fn cast(&mut self, layer: Layer<'_>, hits: &mut BeamHits) -> Result<()> {
        let geom = match layer {
            Layer::Background(g) => g,
            Layer::People { people, .. } => people,
        };
        if geom.meshes.is_empty() {
            hits.clear_to(self.beams);
            return Ok(());
        }
        match (layer, self.people.as_mut(), &mut self.views) {
            (Layer::People { people, proxies }, Some(People::Proxies(raster)), _) => raster.render(proxies, people, hits),
            (Layer::People { people, .. }, Some(People::Binned { caster, cast }), _) => {
                cast_binned(caster, cast, people, hits);
                Ok(())
            }
            (_, _, Views::Beams(beams)) => beams.cast(geom, hits),
            (_, _, Views::Resampled { lookup, renderer }) => {
                let frame = renderer.render(geom)?;
                resample(lookup, frame, geom, self.refine, hits);
                Ok(())
            }
        }
    }

    /// With the background in the beam grid and the people binned (a CPU device), the
    /// background's draw runs on the device while the host casts the people and, beside them,
    /// the background's small triangles: on lavapipe the draw keeps about one core busy and
    /// would leave the other idle. The background's seconds are then the host's own:
    /// bounding and submitting, the rest of the wait, and the confirmation; the people's
    /// include the small triangles cast beside them.
    fn cast_frame(
        &mut self,
        background: Layer<'_>,
        people: Layer<'_>,
        background_hits: &mut BeamHits,
        people_hits: &mut BeamHits,
    ) -> Result<FrameSeconds> {
        let (Layer::Background(bg), Layer::People { people: geom, .. }, Views::Beams(beams), Some(People::Binned { caster, cast })) =
            (background, people, &mut self.views, self.people.as_mut())
        else {
            return cast_in_turn(self, [(background, background_hits), (people, people_hits)]);
        };
        let t0 = std::time::Instant::now();
        beams.submit_draw(bg)?;
        let t1 = std::time::Instant::now();
        // The background's small triangles in one task beside the people's jobs: cast on this
        // thread before the people, they left the other cores idle for ~1 ms a frame.
        rayon::join(|| beams.cast_host(bg), || cast_binned(caster, cast, geom, people_hits));
        let t2 = std::time::Instant::now();
        beams.finish(bg, background_hits)?;
        Ok(FrameSeconds {
            background: (t1 - t0).as_secs_f64() + t2.elapsed().as_secs_f64(),
            people: (t2 - t1).as_secs_f64(),
            build: 0.0,
        })
    }

    fn near_seam(&self, texels: f64) -> Vec<bool> {
        match &self.views {
            Views::Resampled { lookup, .. } => {
                (0..lookup.dirs.len()).map(|b| lookup.seam_distance_texels(b) < texels).collect()
            }
            // One texel per beam: no seams.
            Views::Beams(_) => vec![false; self.beams],
        }
    }

    fn validation_counter(&self) -> Option<Arc<AtomicUsize>> {
        let ctx = self.context();
        ctx.validation_enabled().then(|| ctx.validation_counter())
    }
}

/// The people binned into every beam (`hits`, through the caster's `cast`); ranges are
/// limited later, in the post-pass, as for the ray-cast backend.
fn cast_binned(caster: &mut BeamCaster, cast: &mut Vec<Hit>, people: &crate::geometry::FrameGeometry, hits: &mut BeamHits) {
    caster.cast(people, f64::MAX, cast);
    hits.set_from(cast);
}
