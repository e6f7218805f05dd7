//! The exact beam raster: Vulkan draws the large triangles of a layer into an image with one
//! texel per beam (column x row of the sensor grid), as the triangle's conservative bound in
//! that grid ([`BeamCaster::bounds`], the bound the ray caster tests), and the fragment shader
//! tests the texel's beam against the triangle (`shaders/beam_exact.frag`). The depth test
//! keeps, per beam, the nearest triangle that survived; the CPU re-tests that one triangle with
//! the watertight f64 test the ray caster uses and takes its range. A triangle whose bound
//! holds at most `HOST_BEAMS` beams is not drawn: the host casts it through the beams of its
//! bound as the ray caster does ([`BeamCaster::cast_bounds`]), while the device draws the
//! others, and each beam keeps the nearer of the two answers. (`HOST_BEAMS` is the default of
//! `render.host_cast_beams`.)
//!
//! In: one layer's posed triangles (`FrameGeometry`, sensor frame). Out: per beam the range
//! and triangle of the nearest hit ([`BeamHits`]).
//!
//! **Exactness.** The bound holds every beam that can hit the triangle, and the shader drops a
//! beam only where it is certainly outside the triangle (two edge planes with opposite strict
//! signs, twice the caster's tolerance), certainly on a culled back side, or certainly behind
//! the sensor. So the true nearest triangle T of a beam reaches the depth test, and the winner
//! W is no farther than T up to the f32 rounding of the ranges (relative ~1e-6, a tenth of a
//! millimetre at 100 m). When the f64 test confirms W, its range is the answer (equal to the
//! reference's bit for bit when W = T; ties between triangles meeting at the beam give the
//! same point). When it does not (a beam within the tolerance band of W's edge), the beam is
//! cast exactly on the CPU through every triangle whose bound holds it: a few beams a frame,
//! counted in [`BeamExactStats::fallback_beams`]. The triangles cast on the host give the
//! exact nearest hit among them, and the nearer of that and the confirmed W (tie rule of the
//! reference) is the answer.
//!
//! **Why.** Lavapipe pays about a microsecond per drawn rectangle and ~7 ns per fragment, on
//! the host's own cores: for the hall (~415 triangles with a bound a frame) the binned cast of
//! every triangle whose bound holds at most 8,192 beams costs less than drawing it, and only
//! the ~24 triangles around the sensor (floor and ceiling, bounds of every column) are worth
//! drawing, on the device while the host casts the rest (and, in a frame, the people:
//! `RasterBackend::cast_frame`). A person's tens of thousands of tiny triangles are binned on
//! a CPU device, drawn as proxies on a GPU ([`super::people`]).

use crate::backend::raycast::{BeamCaster, GridBound};
use crate::backend::triangle::{better, intersect_pre, RayPre};
use crate::backend::{BeamHits, NO_TRIANGLE};
use crate::error::{Error, Result};
use crate::geometry::FrameGeometry;
use crate::gpu::{
    spirv_words, Buffer, BufferDesc, Commands, Context, Framebuffer, GraphicsPipeline, Image, ImageDesc, PipelineDesc,
    PipelineLayout, RenderPass, StorageSet,
};
use crate::sensor::Sensor;
use ash::vk;
use glam::DVec3;
use rayon::prelude::*;
use std::sync::Arc;

static BEAM_VERT: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/beam_exact.vert.spv"));
static BEAM_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/beam_exact.frag.spv"));

const ID_FORMAT: vk::Format = vk::Format::R32_UINT;
const DEPTH_FORMAT: vk::Format = vk::Format::D32_SFLOAT;
const MIN_INSTANCES: u64 = 1024;
/// Beams per tile of the coverage test (`BeamExact::stage`).
const TILE_ROWS: usize = 4;
const TILE_COLUMNS: usize = 8;
/// The default of `render.host_cast_beams`: a triangle whose bound holds at most this many
/// beams is cast on the host instead of drawn. Hall only, 32 frames x 5 casts on lavapipe,
/// medians: with nothing cast on the host 2.9 ms (3.7 ms of CPU) a cast, with at most 128
/// beams 2.5 ms, 512: 2.4, 8,192: 2.1 ms (2.9 ms of CPU; only the triangles around the
/// sensor are drawn).
pub const HOST_BEAMS: u64 = crate::config::DEFAULT_HOST_CAST_BEAMS;
/// Texel coordinates are packed into 16 bits per bound.
const MAX_GRID_SIDE: usize = 1 << 16;

/// Push constants, mirrored from `shaders/beam_exact.glsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct BeamPush {
    ndc_per_texel: [f32; 2],
    columns: u32,
    _pad: u32,
}
const _: () = assert!(std::mem::size_of::<BeamPush>() == 16);

/// One drawn bound, mirrored from the inputs of `shaders/beam_exact.vert`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct Instance {
    /// Edge planes through the origin, `a x b`, `b x c`, `c x a` (computed in f64).
    n: [[f32; 3]; 3],
    /// Unit normal of `(b - a) x (c - a)` and its offset `dot(normal, a)` (f64, rounded).
    plane: [f32; 4],
    /// `c0 | c1 << 16`, `r0 | (r1 - 1) << 16` (inclusive texel rows and columns, wrapped).
    rect: [u32; 2],
    /// Global triangle + 1, and bit 0: back faces culled.
    id_flags: [u32; 2],
    /// Per edge plane, the tolerance of the sign tests: twice the ray caster's.
    tol: [f32; 3],
}
const _: () = assert!(std::mem::size_of::<Instance>() == 80);

fn instance_attributes() -> [vk::VertexInputAttributeDescription; 7] {
    let f3 = vk::Format::R32G32B32_SFLOAT;
    let a = |location, format, offset| vk::VertexInputAttributeDescription { location, binding: 0, format, offset };
    [
        a(0, f3, 0),
        a(1, f3, 12),
        a(2, f3, 24),
        a(3, vk::Format::R32G32B32A32_SFLOAT, 36),
        a(4, vk::Format::R32G32_UINT, 52),
        a(5, vk::Format::R32G32_UINT, 60),
        a(6, f3, 68),
    ]
}

/// What the last cast did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BeamExactStats {
    /// Triangles some beam may hit (their bounds were drawn).
    pub triangles_drawn: u64,
    /// Instances drawn (a bound across the azimuth wrap is two).
    pub instances: u64,
    /// Texels covered by the bounds (fragments shaded).
    pub texels: u64,
    /// Beams whose drawn triangle the f64 test did not confirm, cast on the CPU instead.
    pub fallback_beams: u64,
    /// Seconds: bounding, staging and submitting on the CPU; from the submit until the draw
    /// and read-back had completed (whatever the host did meanwhile); the f64 tests of the
    /// drawn triangles.
    pub stage_s: f64,
    pub draw_s: f64,
    pub resolve_s: f64,
}

/// The exact beam raster for one sensor grid: its Vulkan objects, the caster that bounds the
/// triangles, and the per-frame scratch (nothing is allocated in steady state).
pub struct BeamExact {
    // Field order is drop order: GPU objects first, the context last.
    framebuffer: Framebuffer,
    id: Image,
    _depth: Image,
    readback: Buffer,
    instances: Buffer,
    set: StorageSet,
    _dirs: Buffer,
    pipeline: GraphicsPipeline,
    layout: PipelineLayout,
    pass: RenderPass,
    commands: Commands,
    caster: BeamCaster,
    bounds: Vec<GridBound>,
    /// Per tile (row-major, `TILE_ROWS` x `TILE_COLUMNS` beams): a unit axis and a radius
    /// bounding `|d - axis|` over its beams' f32 directions.
    tiles: Vec<[f32; 4]>,
    staged: Vec<Instance>,
    /// Triangles whose bound holds at most this many beams are cast on the host.
    host_beams: u64,
    /// The bounds of the triangles cast on the host (at most `host_beams` beams), and the
    /// hits (beam, range, triangle) and per-beam nearest of that cast.
    host: Vec<GridBound>,
    host_hits: Vec<(u32, f64, u32)>,
    host_best: Vec<(f64, u32)>,
    ids: Vec<u32>,
    /// When the draw in flight (between `begin` and `finish`) was submitted.
    submitted: Option<std::time::Instant>,
    stats: BeamExactStats,
    ctx: Arc<Context>,
}

impl Drop for BeamExact {
    fn drop(&mut self) {
        // A draw still in flight reads the buffers dropped below.
        let _ = self.commands.wait();
    }
}

impl BeamExact {
    /// The raster for `sensor`'s beam grid on `ctx`; triangles whose bound holds at most
    /// `host_beams` beams are cast on the host (`render.host_cast_beams`, default
    /// [`HOST_BEAMS`]).
    pub fn new(ctx: &Arc<Context>, sensor: &Sensor, host_beams: u64) -> Result<BeamExact> {
        let (rows, columns) = (sensor.rows(), sensor.columns);
        let limits = ctx.limits();
        let side = (limits.max_image_dimension2_d.min(limits.max_framebuffer_width).min(limits.max_framebuffer_height) as usize)
            .min(MAX_GRID_SIDE);
        if rows > side || columns > side {
            return Err(Error::input(
                "sensor",
                format!(
                    "a {rows} x {columns} beam grid is larger than {} draws ({side} texels a side); use --backend raycast",
                    ctx.device_name()
                ),
            ));
        }
        let dirs = sensor.beam_dirs();
        let caster = BeamCaster::new(&dirs, rows, columns);
        let tiles = tiles(&caster, rows, columns);
        let (w, h) = (columns as u32, rows as u32);
        let pass = RenderPass::new_for_readback(ctx, &[ID_FORMAT], DEPTH_FORMAT)?;
        let id = Image::new(ctx, &ImageDesc::color_readback("beam id", w, h, ID_FORMAT))?;
        let depth = Image::new(ctx, &ImageDesc::depth("beam depth", w, h, DEPTH_FORMAT))?;
        let framebuffer = Framebuffer::new(ctx, &pass, &[&id, &depth])?;
        let readback = Buffer::new(ctx, &BufferDesc::readback("beam id readback", 4 * w as u64 * h as u64))?;
        // The directions exactly as the caster's f32 pre-test has them.
        let table: Vec<[f32; 4]> = (0..rows * columns)
            .map(|b| {
                let [x, y, z] = caster.dir32(b);
                [x, y, z, 0.0]
            })
            .collect();
        let mut dirs_buffer =
            Buffer::new(ctx, &BufferDesc::upload("beam directions", 16 * table.len() as u64, vk::BufferUsageFlags::STORAGE_BUFFER))?;
        dirs_buffer.write(&table)?;
        let set = StorageSet::new(ctx, vk::ShaderStageFlags::FRAGMENT, &dirs_buffer)?;
        let layout = PipelineLayout::with_sets(
            ctx,
            &[set.layout()],
            vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT,
            std::mem::size_of::<BeamPush>() as u32,
        )?;
        let (vert, frag) = (spirv_words(BEAM_VERT)?, spirv_words(BEAM_FRAG)?);
        let attributes = instance_attributes();
        let pipeline = GraphicsPipeline::new(
            ctx,
            &layout,
            &pass,
            &PipelineDesc {
                vertex_spirv: &vert,
                fragment_spirv: &frag,
                vertex_stride: std::mem::size_of::<Instance>() as u32,
                id_attribute: false,
                instance_attributes: Some(&attributes),
                color_attachments: 1,
                // Quads: the winding of a bound means nothing; the shader culls.
                cull_mode: vk::CullModeFlags::NONE,
                front_face: vk::FrontFace::COUNTER_CLOCKWISE,
                // Depth 1 / (1 + range): nearer is greater; cleared to 0.
                depth_compare: vk::CompareOp::GREATER,
            },
        )?;
        let instances = Buffer::new(
            ctx,
            &BufferDesc::upload("beam bounds", MIN_INSTANCES * std::mem::size_of::<Instance>() as u64, vk::BufferUsageFlags::VERTEX_BUFFER),
        )?;
        Ok(BeamExact {
            framebuffer,
            id,
            _depth: depth,
            readback,
            instances,
            set,
            _dirs: dirs_buffer,
            pipeline,
            layout,
            pass,
            commands: Commands::new(ctx)?,
            caster,
            bounds: Vec::new(),
            tiles,
            staged: Vec::new(),
            host_beams,
            host: Vec::new(),
            host_hits: Vec::new(),
            host_best: vec![(f64::INFINITY, NO_TRIANGLE); rows * columns],
            ids: vec![0; rows * columns],
            submitted: None,
            stats: BeamExactStats::default(),
            ctx: ctx.clone(),
        })
    }

    /// What the last `cast` did.
    pub fn stats(&self) -> BeamExactStats {
        self.stats
    }

    /// The nearest hit of every beam over all meshes of `geom`, into `out` (row-major).
    pub fn cast(&mut self, geom: &FrameGeometry, out: &mut BeamHits) -> Result<()> {
        self.begin(geom)?;
        self.finish(geom, out)
    }

    /// The first half of [`Self::cast`]: bounds `geom`'s triangles and submits their draw,
    /// which runs on the device until [`Self::finish`] (with the same `geom`) waits for it.
    /// The host is free in between: on lavapipe the draw keeps about one core busy, and the
    /// caller can cast another layer on the others.
    pub fn begin(&mut self, geom: &FrameGeometry) -> Result<()> {
        self.submit_draw(geom)?;
        self.cast_host(geom);
        Ok(())
    }

    /// The first part of [`Self::begin`]: bounds `geom`'s triangles and submits the draw of
    /// the large ones. [`Self::cast_host`] (the small ones) must follow before
    /// [`Self::finish`], with the same `geom`; the caller may run other work beside it.
    pub fn submit_draw(&mut self, geom: &FrameGeometry) -> Result<()> {
        self.commands.wait()?;
        self.submitted = None;
        self.stats = BeamExactStats::default();
        self.host_hits.clear();
        let t0 = std::time::Instant::now();
        self.caster.bounds(geom, &mut self.bounds);
        if self.bounds.is_empty() {
            return Ok(());
        }
        self.stage(geom);
        if !self.staged.is_empty() {
            self.submit()?;
        }
        self.stats.stage_s = t0.elapsed().as_secs_f64();
        self.submitted = Some(std::time::Instant::now());
        Ok(())
    }

    /// The second part of [`Self::begin`]: casts the small triangles (bounds of at most
    /// `host_beams` beams) on the host, while the device draws the others. One task: in
    /// parallel jobs it only took the cores the device draws on.
    pub fn cast_host(&mut self, geom: &FrameGeometry) {
        if self.submitted.is_some() {
            let t0 = std::time::Instant::now();
            self.caster.cast_bounds(geom, &self.host, &mut self.host_hits);
            self.stats.stage_s += t0.elapsed().as_secs_f64();
        }
    }

    /// The second half of [`Self::cast`]: waits for the draw [`Self::begin`] submitted for
    /// `geom`, and confirms every beam's triangle into `out` (row-major).
    pub fn finish(&mut self, geom: &FrameGeometry, out: &mut BeamHits) -> Result<()> {
        let (rows, columns) = self.caster.shape();
        out.clear_to(rows * columns);
        let Some(submitted) = self.submitted.take() else { return Ok(()) };
        if self.staged.is_empty() {
            self.ids.fill(0);
        } else {
            self.commands.wait()?;
            self.read_ids()?;
        }
        for &(b, r, t) in &self.host_hits {
            let best = &mut self.host_best[b as usize];
            if better(r, t, best.0, best.1) {
                *best = (r, t);
            }
        }
        let t2 = std::time::Instant::now();
        self.resolve(geom, out);
        for &(b, _, _) in &self.host_hits {
            self.host_best[b as usize] = (f64::INFINITY, NO_TRIANGLE);
        }
        self.stats.draw_s = (t2 - submitted).as_secs_f64();
        self.stats.resolve_s = t2.elapsed().as_secs_f64();
        Ok(())
    }

    /// The instances of this frame's bounds: each bound cut into tiles of `TILE_ROWS` x
    /// `TILE_COLUMNS` beams, the tiles the triangle certainly misses dropped, the rest drawn as
    /// one rectangle per run of tiles in a tile row, split at the azimuth wrap.
    fn stage(&mut self, geom: &FrameGeometry) {
        let columns = self.caster.shape().1 as i64;
        let tiles_per_row = (columns as usize).div_ceil(TILE_COLUMNS);
        self.staged.clear();
        self.host.clear();
        let mut mesh = 0;
        let mut texels = 0u64;
        for g in &self.bounds {
            while geom.meshes[mesh].first_triangle + geom.meshes[mesh].triangle_count <= g.triangle {
                mesh += 1;
            }
            if u64::from(g.r1 - g.r0) * (g.c1 - g.c0 + 1) as u64 <= self.host_beams {
                self.host.push(*g);
                continue;
            }
            let cull = !geom.meshes[mesh].double_sided;
            let [a, b, c] = geom.triangle_f64(g.triangle);
            let normal = (b - a).cross(c - a);
            let unit = normal.normalize_or_zero();
            let f = |v: DVec3| v.as_vec3().to_array();
            let n = [f(a.cross(b)), f(b.cross(c)), f(c.cross(a))];
            // The caster's tolerance (`beams.rs`) doubled: 1e-6 |n|_1 + 1e-30.
            let tol = n.map(|v| 2e-6 * (v[0].abs() + v[1].abs() + v[2].abs()) + 1e-30);
            let base = Instance {
                n,
                tol,
                plane: [unit.x as f32, unit.y as f32, unit.z as f32, unit.dot(a) as f32],
                rect: [0, 0],
                id_flags: [g.triangle + 1, cull as u32],
            };
            let staged = &mut self.staged;
            // Columns lo..=hi (unwrapped, at most one turn), rows r0..=r1, in at most two
            // pieces inside the grid.
            let mut piece = |lo: i64, hi: i64, r0: u32, r1: u32| {
                texels += (r1 - r0 + 1) as u64 * (hi - lo + 1) as u64;
                let rows = r0 | (r1 << 16);
                let start = lo.rem_euclid(columns);
                let end = start + (hi - lo);
                let mut push = |l: i64, h: i64| staged.push(Instance { rect: [l as u32 | ((h as u32) << 16), rows], ..base });
                if end < columns {
                    push(start, end);
                } else {
                    push(start, columns - 1);
                    push(0, end - columns);
                }
            };
            let (c0, c1) = if g.c1 - g.c0 >= columns - 1 { (0, columns - 1) } else { (g.c0, g.c1) };
            if (g.r1 - g.r0) as i64 * (c1 - c0 + 1) <= (TILE_ROWS * TILE_COLUMNS) as i64 {
                piece(c0, c1, g.r0, g.r1 - 1);
                continue;
            }
            // A tile is skipped when all its beams are strictly outside one edge plane and
            // strictly inside another (the caster's block test): |n.d - n.axis| <= |n| radius.
            let norms = n.map(|v| glam::Vec3::from(v).length() * (1.0 + 1e-6));
            let misses = |tile: [f32; 4]| {
                let axis = glam::Vec3::new(tile[0], tile[1], tile[2]);
                let (mut out, mut inside) = (false, false);
                for k in 0..3 {
                    let e = glam::Vec3::from(n[k]).dot(axis);
                    let spread = norms[k] * tile[3];
                    out |= e + spread < -tol[k];
                    inside |= e - spread > tol[k];
                }
                out && inside
            };
            let tr0 = g.r0 as usize / TILE_ROWS;
            let tr1 = (g.r1 as usize - 1) / TILE_ROWS;
            for tr in tr0..=tr1 {
                let ra = g.r0.max((tr * TILE_ROWS) as u32);
                let rb = (g.r1 - 1).min((tr * TILE_ROWS + TILE_ROWS - 1) as u32);
                let mut run: Option<(i64, i64)> = None;
                let mut s = c0;
                while s <= c1 {
                    let w = s.rem_euclid(columns) as usize;
                    let tc = w / TILE_COLUMNS;
                    let e = (s + ((tc * TILE_COLUMNS + TILE_COLUMNS).min(columns as usize) - 1 - w) as i64).min(c1);
                    if misses(self.tiles[tr * tiles_per_row + tc]) {
                        if let Some((lo, hi)) = run.take() {
                            piece(lo, hi, ra, rb);
                        }
                    } else {
                        run = Some(match run {
                            Some((lo, _)) => (lo, e),
                            None => (s, e),
                        });
                    }
                    s = e + 1;
                }
                if let Some((lo, hi)) = run {
                    piece(lo, hi, ra, rb);
                }
            }
        }
        self.stats.triangles_drawn = self.bounds.len() as u64;
        self.stats.instances = self.staged.len() as u64;
        self.stats.texels = texels;
    }

    /// Submits the draw of the staged instances and the read-back of the id image.
    fn submit(&mut self) -> Result<()> {
        let (rows, columns) = self.caster.shape();
        let bytes = (std::mem::size_of::<Instance>() * self.staged.len()) as u64;
        if bytes > self.instances.size() {
            let size = bytes.max(2 * self.instances.size()).next_power_of_two();
            // The old buffer is idle: `begin` waited for the last draw.
            self.instances = Buffer::new(&self.ctx, &BufferDesc::upload("beam bounds", size, vk::BufferUsageFlags::VERTEX_BUFFER))?;
        }
        self.instances.write(&self.staged)?;
        let clear = [
            vk::ClearValue { color: vk::ClearColorValue { uint32: [0; 4] } },
            vk::ClearValue { depth_stencil: vk::ClearDepthStencilValue { depth: 0.0, stencil: 0 } },
        ];
        let push = BeamPush { ndc_per_texel: [2.0 / columns as f32, 2.0 / rows as f32], columns: columns as u32, _pad: 0 };
        let mut rec = self.commands.begin()?;
        rec.begin_render_pass(&self.pass, &self.framebuffer, &clear);
        rec.bind_pipeline(&self.pipeline);
        rec.bind_storage_set(&self.layout, &self.set);
        rec.push_constants(&self.layout, bytemuck::bytes_of(&push));
        rec.bind_vertex_buffer(&self.instances, self.staged.len() as u64);
        rec.draw_instanced(6, self.staged.len() as u32);
        rec.end_render_pass();
        rec.copy_image_to_buffer(&self.id, &self.readback, 0);
        rec.transfer_to_host_barrier();
        rec.submit()
    }

    /// Copies the read-back id image (the draw has completed) into `ids`.
    fn read_ids(&mut self) -> Result<()> {
        let src = &self.readback.read_bytes()?[..4 * self.ids.len()];
        match bytemuck::try_cast_slice::<u8, u32>(src) {
            Ok(s) => self.ids.copy_from_slice(s),
            Err(_) => bytemuck::cast_slice_mut::<u32, u8>(&mut self.ids).copy_from_slice(src),
        }
        Ok(())
    }

    /// Per beam: the f64 test of the drawn triangle, or the exact CPU cast where it fails.
    fn resolve(&mut self, geom: &FrameGeometry, out: &mut BeamHits) {
        let columns = self.caster.shape().1;
        let caster = &self.caster;
        let ids = &self.ids;
        let bounds = &self.bounds;
        let host = &self.host_best;
        let n = columns as i64;
        let fallback: u64 = out
            .range_m
            .par_chunks_mut(columns)
            .zip(out.triangle.par_chunks_mut(columns))
            .enumerate()
            .map(|(row, (ranges, tris))| {
                let mut missed = 0;
                // The last drawn triangle of the row, its vertices and cull flag: neighbouring
                // beams mostly show the same one.
                let mut last = (NO_TRIANGLE, [DVec3::ZERO; 3], false);
                for col in 0..columns {
                    let b = row * columns + col;
                    let id = ids[b];
                    // The nearest of the triangles cast on the host, if any.
                    let (hr, ht) = host[b];
                    if ht != NO_TRIANGLE {
                        ranges[col] = hr as f32;
                        tris[col] = ht;
                    }
                    if id == 0 {
                        continue;
                    }
                    let t = id - 1;
                    if last.0 != t {
                        last = (t, geom.triangle_f64(t), !geom.mesh_of_triangle(t).double_sided);
                    }
                    let confirmed = caster.ray_pre(b).and_then(|pre| intersect_pre(pre, &last.1, last.2));
                    let hit = match confirmed {
                        Some(r) => Some((r, t)),
                        None => {
                            missed += 1;
                            caster.ray_pre(b).and_then(|pre| cast_bounded(geom, bounds, pre, (row as u32, col as i64), n))
                        }
                    };
                    if let Some((r, t)) = hit.filter(|&(r, t)| better(r, t, hr, ht)) {
                        ranges[col] = r as f32;
                        tris[col] = t;
                    }
                }
                missed
            })
            .sum();
        self.stats.fallback_beams = fallback;
        debug_assert!(out.triangle.iter().all(|&t| t == NO_TRIANGLE || (t as usize) < geom.indices.len() / 3));
    }
}

/// The tiles of a grid (see `BeamExact::tiles`).
fn tiles(caster: &BeamCaster, rows: usize, columns: usize) -> Vec<[f32; 4]> {
    let mut v = Vec::new();
    for r0 in (0..rows).step_by(TILE_ROWS) {
        for c0 in (0..columns).step_by(TILE_COLUMNS) {
            let beams: Vec<DVec3> = (r0..(r0 + TILE_ROWS).min(rows))
                .flat_map(|r| (c0..(c0 + TILE_COLUMNS).min(columns)).map(move |c| r * columns + c))
                .map(|b| DVec3::from(caster.dir32(b).map(f64::from)))
                .collect();
            let axis = beams.iter().copied().sum::<DVec3>().normalize().as_vec3();
            // Measured in f64 between the f32 values the tests use, then widened for the f32
            // dot products (as the caster's blocks).
            let radius = beams.iter().map(|d| (*d - axis.as_dvec3()).length()).fold(0.0f64, f64::max);
            v.push([axis.x, axis.y, axis.z, (radius * (1.0 + 1e-5) + 1e-6) as f32]);
        }
    }
    v
}

/// The nearest hit of the beam at (`row`, `col`) (ray constants `pre`) over the triangles
/// whose bound holds it: every triangle it can hit (the reference's test and tie rule).
fn cast_bounded(geom: &FrameGeometry, bounds: &[GridBound], pre: &RayPre, (row, col): (u32, i64), columns: i64) -> Option<(f64, u32)> {
    let mut best: Option<(f64, u32)> = None;
    let mut mesh = 0;
    for g in bounds {
        if !(g.r0 <= row && row < g.r1 && (col - g.c0).rem_euclid(columns) <= g.c1 - g.c0) {
            continue;
        }
        while geom.meshes[mesh].first_triangle + geom.meshes[mesh].triangle_count <= g.triangle {
            mesh += 1;
        }
        if let Some(r) = intersect_pre(pre, &geom.triangle_f64(g.triangle), !geom.meshes[mesh].double_sided) {
            if best.map_or(true, |(br, bt)| better(r, g.triangle, br, bt)) {
                best = Some((r, g.triangle));
            }
        }
    }
    best
}
