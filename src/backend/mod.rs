//! Stage 6: the nearest surface per beam. Given the posed triangles of one frame (sensor
//! frame, [`FrameGeometry`]), a backend answers, for every beam of the sensor's grid, the
//! range and the triangle of the first surface the beam meets ([`BeamHits`]). Two backends
//! implement the one [`Backend`] trait, and the generator, `crosscheck` and `bench` hold a
//! `Box<dyn Backend>` without knowing which:
//!
//! - [`raster`]: Vulkan rasterization (a GPU, or lavapipe on a CPU) into cube faces or a
//!   cylindrical panorama with an ID buffer, resampled to the beams and refined exactly;
//!   the people drawn as conservative proxies at beam resolution and cast exactly (on a
//!   GPU; on a CPU device the people are binned into the beams, as the ray caster does).
//! - [`RaycastBackend`]: the CPU ray caster (triangles binned into beams, or each beam traced
//!   through a BVH: the reference). It never touches Vulkan, so it runs where no driver is.
//!
//! Both call hits with the same watertight f64 ray/triangle test and tie rule. `auto` is
//! resolved once, per device, by [`resolve`].

mod exact;
pub mod raster;
pub mod raycast;
pub mod triangle;

pub use raycast::RaycastBackend;

use crate::config::{BackendChoice, Caster, Config};
use crate::error::{Error, Result};
use crate::geometry::FrameGeometry;
use crate::gpu::{Context, ContextOptions, DeviceChoice};
use crate::human::HumanModel;
use crate::sensor::Sensor;
use crate::human::proxy::ModelProxies;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

/// No triangle hit.
pub const NO_TRIANGLE: u32 = u32::MAX;

/// Per-beam result of a backend (row-major beam grid): range (0 = no hit) and global
/// triangle index ([`NO_TRIANGLE`] = no hit).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BeamHits {
    pub range_m: Vec<f32>,
    pub triangle: Vec<u32>,
}

impl BeamHits {
    /// `n` beams, none hit.
    pub fn clear_to(&mut self, n: usize) {
        self.range_m.clear();
        self.range_m.resize(n, 0.0);
        self.triangle.clear();
        self.triangle.resize(n, NO_TRIANGLE);
    }

    /// The hits of a cast (one per beam, row-major), ranges rounded to f32.
    pub fn set_from(&mut self, cast: &[raycast::Hit]) {
        self.clear_to(0);
        self.range_m.extend(cast.iter().map(|h| h.range_m as f32));
        self.triangle.extend(cast.iter().map(|h| h.triangle));
    }
}

/// One layer of a posed frame: what a backend casts at a time.
#[derive(Clone, Copy)]
pub enum Layer<'a> {
    /// The environment's triangles.
    Background(&'a FrameGeometry),
    /// The people, and (for a backend with [`Backend::proxies`]) their proxies: one mesh per
    /// person, in the order of the people's meshes, with the same instance ids.
    People { people: &'a FrameGeometry, proxies: &'a FrameGeometry },
}

/// Which layer of a posed frame (see [`Layer`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LayerKind {
    Background,
    People,
}

/// Seconds the casts of one frame took, per layer (what `--timings` reports as stages).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameSeconds {
    /// The background layer, less `build`; with overlapped layers, the host's own time on it.
    pub background: f64,
    /// The people layer, less `build`.
    pub people: f64,
    /// Building or refitting acceleration structures (see [`Backend::take_build_seconds`]).
    pub build: f64,
}

/// Finds the nearest surface per beam for the posed triangles of a frame.
pub trait Backend {
    /// Which backend this is (`raster` or `raycast`), as recorded in the outputs.
    fn choice(&self) -> BackendChoice;

    /// What runs the casts, for summaries: the Vulkan device's name, or the CPU ray caster.
    fn device_name(&self) -> String;

    /// The proxies (per model, per level of detail) the people layer is drawn with, when
    /// this backend draws them: the generator then poses them beside the people.
    fn proxies(&self) -> Option<&[ModelProxies]> {
        None
    }

    /// The nearest surface of `layer` per beam, into `hits` (row-major, `rows x columns`).
    fn cast(&mut self, layer: Layer<'_>, hits: &mut BeamHits) -> Result<()>;

    /// Both layers of a frame, `background` into `background_hits` and `people` into
    /// `people_hits`, as [`Self::cast`] would; returns the seconds of each. By default one
    /// after the other ([`cast_in_turn`]); a backend may overlap them (the raster backend on a
    /// CPU device draws the background while the host casts the people).
    fn cast_frame(
        &mut self,
        background: Layer<'_>,
        people: Layer<'_>,
        background_hits: &mut BeamHits,
        people_hits: &mut BeamHits,
    ) -> Result<FrameSeconds> {
        cast_in_turn(self, [(background, background_hits), (people, people_hits)])
    }

    /// Seconds the casts since the last call spent building or refitting acceleration
    /// structures (reported as a stage of its own by `--timings`), then zero.
    fn take_build_seconds(&mut self) -> f64 {
        0.0
    }

    /// Per beam: whether it lies within `texels` texels of a seam of the backend's views (a
    /// cube-face edge, the panorama's azimuth wrap); all false for a backend without views.
    fn near_seam(&self, texels: f64) -> Vec<bool>;

    /// With the Vulkan validation layer on: the count of the messages it reported, which
    /// outlives the backend (messages at device destruction count too; see [`finish`]).
    fn validation_counter(&self) -> Option<Arc<AtomicUsize>> {
        None
    }
}

/// [`Backend::cast_frame`] one layer after the other: the background, then the people.
pub fn cast_in_turn<B: Backend + ?Sized>(backend: &mut B, layers: [(Layer<'_>, &mut BeamHits); 2]) -> Result<FrameSeconds> {
    let mut seconds = FrameSeconds::default();
    let mut stage = [0.0; 2];
    for (k, (layer, hits)) in layers.into_iter().enumerate() {
        let t0 = std::time::Instant::now();
        backend.cast(layer, hits)?;
        let build = backend.take_build_seconds();
        seconds.build += build;
        stage[k] = t0.elapsed().as_secs_f64() - build;
    }
    [seconds.background, seconds.people] = stage;
    Ok(seconds)
}

/// The Vulkan context of a run, opened on first use (or ahead of it, [`Gpu::open_early`]) and
/// shared by its backends.
pub struct Gpu {
    options: ContextOptions,
    context: Option<Arc<Context>>,
    /// Why an early open failed: returned by the next [`Gpu::context`] instead of trying again.
    failed: Option<Error>,
}

impl Gpu {
    /// `device`: `auto`, an index or part of a name (see `pedscan devices`).
    pub fn new(device: &str, validation: bool) -> Gpu {
        Gpu { options: ContextOptions { validation, device: device_choice(device) }, context: None, failed: None }
    }

    /// The context, opened now if it is not yet. After a failed [`Gpu::open_early`], its error.
    pub fn context(&mut self) -> Result<Arc<Context>> {
        if let Some(e) = self.failed.take() {
            return Err(e);
        }
        if let Some(c) = &self.context {
            return Ok(c.clone());
        }
        let c = Arc::new(Context::new(&self.options)?);
        self.context = Some(c.clone());
        Ok(c)
    }

    /// Opens the context ahead of its first use (beside other start-up work: on lavapipe the
    /// driver's libraries and threads take ~40 ms); a failure is kept for the next
    /// [`Gpu::context`], where the backend that needs the device reports it (or `auto` falls
    /// back to the ray caster).
    pub fn open_early(&mut self) {
        if self.context.is_none() && self.failed.is_none() {
            if let Err(e) = self.context() {
                self.failed = Some(e);
            }
        }
    }
}

/// Picks the Vulkan device from the config's `device` string.
pub fn device_choice(s: &str) -> DeviceChoice {
    match s {
        "" | "auto" => DeviceChoice::Auto,
        s => match s.parse::<usize>() {
            Ok(i) => DeviceChoice::Index(i),
            Err(_) => DeviceChoice::Name(s.to_string()),
        },
    }
}

/// The backend that runs for `choice`: `auto` is the ray caster on every device. `pedscan
/// bench` measures it faster than the raster backend at the same exactness on lavapipe and on
/// a real GPU too (an NVIDIA H200 with 16 host cores: 77 against 60 frames/s end to end; the
/// raster path's cost there is per-frame submission and read-back, not drawing: docs/performance.md),
/// so `auto` never opens the Vulkan device. Only `raster` does.
pub fn resolve(choice: BackendChoice) -> BackendChoice {
    match choice {
        BackendChoice::Auto => BackendChoice::Raycast,
        c => c,
    }
}

/// Creates the backend `cfg.render.backend` names (`auto` resolved by [`resolve`]) for
/// `sensor` and the people `models`.
pub fn create(cfg: &Config, sensor: &Sensor, models: &[HumanModel], gpu: &mut Gpu) -> Result<Box<dyn Backend>> {
    Ok(match resolve(cfg.render.backend) {
        BackendChoice::Raycast => Box::new(RaycastBackend::new(sensor, cfg.debug.caster == Caster::Bvh, cfg.debug.bvh_refit)),
        _ => {
            let ctx = gpu.context().map_err(|e| {
                Error::Gpu(format!("the raster backend needs a Vulkan device ({e}); install a driver (mesa-vulkan-drivers for lavapipe) or run --backend raycast"))
            })?;
            Box::new(raster::RasterBackend::new(ctx, sensor, &cfg.render, cfg.debug.people, models)?)
        }
    })
}

/// Ends a backend: drops it (and with it the Vulkan device, when it holds the last
/// reference), then fails if the validation layer, when on, reported anything, leaks at
/// device destruction included.
pub fn finish(backend: Box<dyn Backend>) -> Result<()> {
    let counter = backend.validation_counter();
    drop(backend);
    match counter.map(|c| c.load(Ordering::SeqCst)) {
        Some(n) if n > 0 => Err(Error::Gpu(format!("{n} Vulkan validation errors (see the messages above)"))),
        _ => Ok(()),
    }
}
