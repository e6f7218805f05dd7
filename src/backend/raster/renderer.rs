//! Raster backend, drawing: rasterise one frame's triangles ([`FrameGeometry`], sensor frame, f32) into the
//! cube side faces of [`CubeFaces`] on the GPU and read back, per face and texel, the
//! Euclidean range (metres, of the nearest surface; 0 = nothing) and the global triangle
//! index plus one (0 = nothing). Texel layout and face frusta are those of `projection.rs`
//! (row-major, row 0 = top).
//!
//! Per face only the meshes whose bounding sphere the face can see are drawn; a face with
//! none is not rendered, and a frame where no face sees anything costs no GPU work at all.
//! All rendered faces go into one command buffer and one submit.
//!
//! With a [`Panorama`] (`Renderer::new_panorama`) the frame has ONE image, the cylindrical
//! panorama; [`PanoramaPrep`](crate::backend::raster::panorama::PanoramaPrep) decides per mesh between a direct
//! draw from the shared buffers and the CPU-prepared triangle list (azimuth wrap, vertical
//! axis, large triangles). Nothing visible: no GPU work, as for the cube.

use crate::error::{Error, Result};
use crate::geometry::FrameGeometry;
use crate::gpu::{
    spirv_words, Buffer, BufferDesc, CommandRecorder, Commands, Context, Framebuffer, GraphicsPipeline, Image, ImageDesc,
    PipelineDesc, PipelineLayout, RenderPass,
};
use super::panorama::{PanoramaPrep, PrepStats, SoupList, SoupVertex};
use super::projection::{CubeFaces, Face, Panorama};
use ash::vk;
use glam::Vec3;
use std::sync::Arc;

static RANGE_VERT: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/range.vert.spv"));
static RANGE_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/range.frag.spv"));
static PANORAMA_VERT: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/panorama.vert.spv"));
static PANORAMA_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/panorama.frag.spv"));
static PANORAMA_SOUP_VERT: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/panorama_soup.vert.spv"));
static PANORAMA_SOUP_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/panorama_soup.frag.spv"));

/// Front face of single-sided meshes. Geometry convention: triangle (a, b, c) faces the
/// sensor when `dot((b - a) x (c - a), a) < 0` (counter-clockwise seen from the viewer).
/// The face camera (right, up, forward) is left-handed and Vulkan's framebuffer y points
/// down; the two flips cancel, so the viewer's counter-clockwise stays Vulkan's
/// `COUNTER_CLOCKWISE`. Proven by `tests/it/gpu_raster.rs::back_face_culling_keeps_the_near_side`.
pub const FRONT_FACE: vk::FrontFace = vk::FrontFace::COUNTER_CLOCKWISE;

pub const RANGE_FORMAT: vk::Format = vk::Format::R32_SFLOAT;
pub const ID_FORMAT: vk::Format = vk::Format::R32_UINT;
pub const DEPTH_FORMAT: vk::Format = vk::Format::D32_SFLOAT;

/// Push constants, mirrored from `shaders/common.glsl` (std430 push-constant layout: mat4 at
/// 0, uint at 64; the CPU struct pads to 80 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PushConstants {
    /// Column-major `Face::clip_from_sensor()`.
    pub clip_from_sensor: [f32; 16],
    /// `MeshRange::first_triangle`.
    pub base_triangle: u32,
    pub _pad: [u32; 3],
}
const _: () = assert!(std::mem::size_of::<PushConstants>() == 80);
const _: () = assert!(std::mem::offset_of!(PushConstants, base_triangle) == 64);

/// Push constants of the panorama shaders, mirrored from `shaders/panorama.glsl` (std430:
/// vec4 at 0, float at 16, uint at 20).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct PanoramaPush {
    /// `Panorama::shader_map()`.
    pub map: [f32; 4],
    /// Centre of the phi window of this draw.
    pub window: f32,
    pub base_triangle: u32,
}
const _: () = assert!(std::mem::size_of::<PanoramaPush>() == 24);
const _: () = assert!(std::mem::offset_of!(PanoramaPush, base_triangle) == 20);

/// One face's (or the panorama's) read-back images.
#[derive(Clone, Debug, Default)]
pub struct FaceImage {
    /// Index into `CubeFaces::faces` (0 for the panorama).
    pub index: usize,
    pub width: u32,
    pub height: u32,
    /// Whether this face was rendered for the last frame. When false, `range_m` and `id`
    /// are STALE (an earlier frame's data, or all zeros before the first render of this
    /// face) and must be read as "nothing visible": no mesh's bounding sphere touches
    /// the face.
    pub rendered: bool,
    /// Row-major (row 0 = top) Euclidean range of the nearest surface, metres; 0 = nothing.
    pub range_m: Vec<f32>,
    /// Row-major global triangle index + 1 of the nearest surface; 0 = nothing.
    pub id: Vec<u32>,
}

impl FaceImage {
    /// Range at column `u`, row `v`.
    pub fn range_at(&self, u: u32, v: u32) -> f32 {
        self.range_m[(v * self.width + u) as usize]
    }
    /// Id (triangle + 1, 0 = nothing) at column `u`, row `v`.
    pub fn id_at(&self, u: u32, v: u32) -> u32 {
        self.id[(v * self.width + u) as usize]
    }
}

/// The rasterised faces of one frame, in `CubeFaces::faces` order (the panorama: one image).
#[derive(Clone, Debug, Default)]
pub struct RasterFrame {
    pub faces: Vec<FaceImage>,
}

/// What the last `render` did (for benchmarks and tests).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RenderStats {
    pub faces_rendered: u32,
    /// `vkCmdDrawIndexed` calls (one per visible mesh per face).
    pub draws: u32,
    /// Triangles submitted over all draws (a mesh seen by two faces counts twice).
    pub triangles_submitted: u64,
    /// Whether any GPU work was submitted.
    pub submitted: bool,
    /// Panorama only: what the CPU preparation did (direct meshes, soup, splits).
    pub panorama: PrepStats,
}

/// Per-face (or panorama) GPU resources, allocated once.
struct FaceTarget {
    framebuffer: Framebuffer,
    range: Image,
    id: Image,
    _depth: Image,
    /// Range (w*h f32) followed by id (w*h u32).
    readback: Buffer,
    push: PushConstants,
}

impl FaceTarget {
    fn new(ctx: &Arc<Context>, pass: &RenderPass, w: u32, h: u32, push: PushConstants) -> Result<FaceTarget> {
        let range = Image::new(ctx, &ImageDesc::color_readback("face range", w, h, RANGE_FORMAT))?;
        let id = Image::new(ctx, &ImageDesc::color_readback("face id", w, h, ID_FORMAT))?;
        let depth = Image::new(ctx, &ImageDesc::depth("face depth", w, h, DEPTH_FORMAT))?;
        let framebuffer = Framebuffer::new(ctx, pass, &[&range, &id, &depth])?;
        let texels = w as u64 * h as u64;
        let readback = Buffer::new(ctx, &BufferDesc::readback("face readback", 8 * texels))?;
        Ok(FaceTarget { framebuffer, range, id, _depth: depth, readback, push })
    }

    /// Records the copy of the range and id images into `readback` (range, then id).
    fn record_readback<'a>(&'a self, rec: &mut CommandRecorder<'a>) {
        let texels = self.range.extent().width as u64 * self.range.extent().height as u64;
        rec.copy_image_to_buffer(&self.range, &self.readback, 0);
        rec.copy_image_to_buffer(&self.id, &self.readback, 4 * texels);
    }
}

/// The panorama's own state: its mapping, the per-frame CPU plan, the triangle-list buffer
/// and the pipelines that draw it.
struct PanoramaState {
    soup_culled: GraphicsPipeline,
    soup_double_sided: GraphicsPipeline,
    soup: Buffer,
    pano: Panorama,
    prep: PanoramaPrep,
    /// The four soup lists back to back (upload staging), and where each starts (vertices).
    soup_all: Vec<SoupVertex>,
    soup_first: [u32; 5],
}

/// The Vulkan rasteriser for one set of cube faces, or for one panorama. Resources are created
/// in `new`; `render` allocates nothing in steady state (buffers grow geometrically).
pub struct Renderer {
    // Field order is drop order: GPU objects first, the context last.
    targets: Vec<FaceTarget>,
    panorama: Option<PanoramaState>,
    vertices: Buffer,
    indices: Buffer,
    commands: Commands,
    /// Cube: `range.vert` / `range.frag`; panorama: the direct-draw `panorama.*` shaders.
    culled: GraphicsPipeline,
    double_sided: GraphicsPipeline,
    layout: PipelineLayout,
    pass: RenderPass,
    faces: Vec<Face>,
    visible: Vec<Vec<usize>>,
    frame: RasterFrame,
    stats: RenderStats,
    renders: u64,
    ctx: Arc<Context>,
}

const MIN_BUFFER_BYTES: u64 = 64 * 1024;

fn upload_desc(name: &'static str, size: u64, usage: vk::BufferUsageFlags) -> BufferDesc {
    BufferDesc::upload(name, size, usage)
}

/// A culled and a double-sided pipeline from one pair of shaders.
fn pipeline_pair(
    ctx: &Arc<Context>,
    layout: &PipelineLayout,
    pass: &RenderPass,
    vert: &[u8],
    frag: &[u8],
    id_attribute: bool,
) -> Result<(GraphicsPipeline, GraphicsPipeline)> {
    let vert = spirv_words(vert)?;
    let frag = spirv_words(frag)?;
    let desc = |cull_mode| PipelineDesc {
        vertex_spirv: &vert,
        fragment_spirv: &frag,
        vertex_stride: if id_attribute { 16 } else { 12 },
        id_attribute,
        instance_attributes: None,
        color_attachments: 2,
        cull_mode,
        front_face: FRONT_FACE,
        // Reversed-Z: nearer is greater; cleared to 0.
        depth_compare: vk::CompareOp::GREATER,
    };
    Ok((
        GraphicsPipeline::new(ctx, layout, pass, &desc(vk::CullModeFlags::BACK))?,
        GraphicsPipeline::new(ctx, layout, pass, &desc(vk::CullModeFlags::NONE))?,
    ))
}

/// The render pass (range + id colour targets, depth, read back) and a pipeline layout with
/// `push_bytes` of push constants for both stages: the same for cube faces and panorama.
fn pass_and_layout(ctx: &Arc<Context>, push_bytes: usize) -> Result<(RenderPass, PipelineLayout)> {
    let pass = RenderPass::new_for_readback(ctx, &[RANGE_FORMAT, ID_FORMAT], DEPTH_FORMAT)?;
    let layout =
        PipelineLayout::with_push_constants(ctx, vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT, push_bytes as u32)?;
    Ok((pass, layout))
}

fn empty_image(index: usize, w: u32, h: u32) -> FaceImage {
    let texels = w as usize * h as usize;
    FaceImage { index, width: w, height: h, rendered: false, range_m: vec![0.0; texels], id: vec![0; texels] }
}

impl Renderer {
    pub fn new(ctx: &Arc<Context>, faces: &CubeFaces) -> Result<Renderer> {
        let (pass, layout) = pass_and_layout(ctx, std::mem::size_of::<PushConstants>())?;
        let (culled, double_sided) = pipeline_pair(ctx, &layout, &pass, RANGE_VERT, RANGE_FRAG, false)?;
        let mut targets = Vec::with_capacity(faces.faces.len());
        let mut frame = RasterFrame { faces: Vec::with_capacity(faces.faces.len()) };
        for face in &faces.faces {
            let push = PushConstants { clip_from_sensor: face.clip_from_sensor().to_cols_array(), ..Default::default() };
            targets.push(FaceTarget::new(ctx, &pass, face.width, face.height, push)?);
            frame.faces.push(empty_image(face.index, face.width, face.height));
        }
        Self::assemble(ctx, targets, None, (culled, double_sided), layout, pass, faces.faces.clone(), frame)
    }

    /// A renderer into one cylindrical panorama (`render.projection = "cylinder"`): the frame
    /// has one image, index 0, `pano.width` x `pano.height`.
    pub fn new_panorama(ctx: &Arc<Context>, pano: &Panorama) -> Result<Renderer> {
        let (pass, layout) = pass_and_layout(ctx, std::mem::size_of::<PanoramaPush>())?;
        let direct = pipeline_pair(ctx, &layout, &pass, PANORAMA_VERT, PANORAMA_FRAG, false)?;
        let (soup_culled, soup_double_sided) = pipeline_pair(ctx, &layout, &pass, PANORAMA_SOUP_VERT, PANORAMA_SOUP_FRAG, true)?;
        let targets = vec![FaceTarget::new(ctx, &pass, pano.width, pano.height, PushConstants::default())?];
        let frame = RasterFrame { faces: vec![empty_image(0, pano.width, pano.height)] };
        let soup = Buffer::new(ctx, &upload_desc("panorama soup", MIN_BUFFER_BYTES, vk::BufferUsageFlags::VERTEX_BUFFER))?;
        let state = PanoramaState {
            soup_culled,
            soup_double_sided,
            soup,
            pano: pano.clone(),
            prep: PanoramaPrep::default(),
            soup_all: Vec::new(),
            soup_first: [0; 5],
        };
        Self::assemble(ctx, targets, Some(state), direct, layout, pass, Vec::new(), frame)
    }

    #[allow(clippy::too_many_arguments)]
    fn assemble(
        ctx: &Arc<Context>,
        targets: Vec<FaceTarget>,
        panorama: Option<PanoramaState>,
        (culled, double_sided): (GraphicsPipeline, GraphicsPipeline),
        layout: PipelineLayout,
        pass: RenderPass,
        faces: Vec<Face>,
        frame: RasterFrame,
    ) -> Result<Renderer> {
        let vertices =
            Buffer::new(ctx, &upload_desc("vertices", MIN_BUFFER_BYTES, vk::BufferUsageFlags::VERTEX_BUFFER))?;
        let indices =
            Buffer::new(ctx, &upload_desc("indices", MIN_BUFFER_BYTES, vk::BufferUsageFlags::INDEX_BUFFER))?;
        let visible = vec![Vec::new(); faces.len()];
        Ok(Renderer {
            targets,
            panorama,
            vertices,
            indices,
            commands: Commands::new(ctx)?,
            culled,
            double_sided,
            layout,
            pass,
            faces,
            visible,
            frame,
            stats: RenderStats::default(),
            renders: 0,
            ctx: ctx.clone(),
        })
    }

    /// The panorama this renderer draws into, if it is a panorama renderer.
    pub fn panorama(&self) -> Option<&Panorama> {
        self.panorama.as_ref().map(|p| &p.pano)
    }

    pub fn context(&self) -> &Arc<Context> {
        &self.ctx
    }

    /// The faces this renderer draws (none for a panorama renderer).
    pub fn faces(&self) -> &[Face] {
        &self.faces
    }

    /// What the last `render` did.
    pub fn stats(&self) -> RenderStats {
        self.stats
    }

    /// Number of `render` calls that submitted GPU work.
    pub fn render_count(&self) -> u64 {
        self.renders
    }

    /// The last rendered frame (see [`FaceImage::rendered`]).
    pub fn frame(&self) -> &RasterFrame {
        &self.frame
    }

    /// Rasterises `geom` into every face that sees at least one mesh (or into the panorama)
    /// and reads it back.
    pub fn render(&mut self, geom: &FrameGeometry) -> Result<&RasterFrame> {
        self.stats = RenderStats::default();
        let triangles = check_geometry(geom)?;
        if self.panorama.is_some() {
            return self.render_panorama(geom, triangles);
        }
        let mut any = false;
        for (face, visible) in self.faces.iter().zip(self.visible.iter_mut()) {
            visible.clear();
            for (k, m) in geom.meshes.iter().enumerate() {
                if m.triangle_count > 0 && face.sees_sphere(Vec3::from(m.centre), m.radius) {
                    visible.push(k);
                }
            }
            any |= !visible.is_empty();
        }
        for (image, visible) in self.frame.faces.iter_mut().zip(&self.visible) {
            image.rendered = !visible.is_empty();
        }
        if !any {
            return Ok(&self.frame);
        }

        check_indices(geom)?;
        ensure_capacity(&self.ctx, &mut self.vertices, "vertices", vk::BufferUsageFlags::VERTEX_BUFFER, 12 * geom.positions.len() as u64)?;
        ensure_capacity(&self.ctx, &mut self.indices, "indices", vk::BufferUsageFlags::INDEX_BUFFER, 4 * geom.indices.len() as u64)?;
        self.vertices.write(&geom.positions)?;
        self.indices.write(&geom.indices)?;

        let clear = [
            vk::ClearValue { color: vk::ClearColorValue { float32: [0.0; 4] } },
            vk::ClearValue { color: vk::ClearColorValue { uint32: [0; 4] } },
            vk::ClearValue { depth_stencil: vk::ClearDepthStencilValue { depth: 0.0, stencil: 0 } },
        ];
        let mut stats = RenderStats { submitted: true, ..Default::default() };
        let mut rec = self.commands.begin()?;
        rec.bind_vertex_buffer(&self.vertices, geom.positions.len() as u64);
        rec.bind_index_buffer_u32(&self.indices, 3 * triangles as u64);
        for (target, visible) in self.targets.iter_mut().zip(&self.visible) {
            if visible.is_empty() {
                continue;
            }
            stats.faces_rendered += 1;
            rec.begin_render_pass(&self.pass, &target.framebuffer, &clear);
            let mut bound: Option<bool> = None;
            for &k in visible {
                let m = &geom.meshes[k];
                if bound != Some(m.double_sided) {
                    rec.bind_pipeline(if m.double_sided { &self.double_sided } else { &self.culled });
                    bound = Some(m.double_sided);
                }
                target.push.base_triangle = m.first_triangle;
                rec.push_constants(&self.layout, bytemuck::bytes_of(&target.push));
                rec.draw_indexed(3 * m.triangle_count, 3 * m.first_triangle);
                stats.draws += 1;
                stats.triangles_submitted += m.triangle_count as u64;
            }
            rec.end_render_pass();
            target.record_readback(&mut rec);
        }
        rec.transfer_to_host_barrier();
        rec.submit_and_wait()?;
        self.renders += 1;
        self.stats = stats;

        for (target, image) in self.targets.iter().zip(self.frame.faces.iter_mut()) {
            if !image.rendered {
                continue;
            }
            let bytes = target.readback.read_bytes()?;
            let n = image.range_m.len() * 4;
            copy_pod(&bytes[..n], &mut image.range_m);
            copy_pod(&bytes[n..2 * n], &mut image.id);
        }
        Ok(&self.frame)
    }
}

impl Renderer {
    /// The panorama path of `render`: plan on the CPU, then one render pass.
    fn render_panorama(&mut self, geom: &FrameGeometry, triangles: u32) -> Result<&RasterFrame> {
        let state = self.panorama.as_mut().expect("panorama renderer");
        state.prep.prepare(&state.pano, geom);
        let prep = &state.prep;
        self.frame.faces[0].rendered = !prep.is_empty();
        self.stats.panorama = prep.stats;
        if prep.is_empty() {
            return Ok(&self.frame);
        }
        // The soup lists back to back.
        state.soup_all.clear();
        for (k, list) in prep.soup.iter().enumerate() {
            state.soup_first[k] = state.soup_all.len() as u32;
            state.soup_all.extend_from_slice(list);
        }
        state.soup_first[4] = state.soup_all.len() as u32;
        if !prep.direct.is_empty() {
            check_indices(geom)?;
            ensure_capacity(&self.ctx, &mut self.vertices, "vertices", vk::BufferUsageFlags::VERTEX_BUFFER, 12 * geom.positions.len() as u64)?;
            ensure_capacity(&self.ctx, &mut self.indices, "indices", vk::BufferUsageFlags::INDEX_BUFFER, 4 * geom.indices.len() as u64)?;
            self.vertices.write(&geom.positions)?;
            self.indices.write(&geom.indices)?;
        }
        if !state.soup_all.is_empty() {
            let bytes = std::mem::size_of::<SoupVertex>() as u64 * state.soup_all.len() as u64;
            ensure_capacity(&self.ctx, &mut state.soup, "panorama soup", vk::BufferUsageFlags::VERTEX_BUFFER, bytes)?;
            state.soup.write(&state.soup_all)?;
        }

        let clear = [
            vk::ClearValue { color: vk::ClearColorValue { float32: [0.0; 4] } },
            vk::ClearValue { color: vk::ClearColorValue { uint32: [0; 4] } },
            vk::ClearValue { depth_stencil: vk::ClearDepthStencilValue { depth: 0.0, stencil: 0 } },
        ];
        let mut stats = RenderStats { submitted: true, faces_rendered: 1, panorama: prep.stats, ..Default::default() };
        let target = &self.targets[0];
        let map = state.pano.shader_map();
        let mut rec = self.commands.begin()?;
        rec.begin_render_pass(&self.pass, &target.framebuffer, &clear);
        if !prep.direct.is_empty() {
            rec.bind_vertex_buffer(&self.vertices, geom.positions.len() as u64);
            rec.bind_index_buffer_u32(&self.indices, 3 * triangles as u64);
            let mut bound: Option<bool> = None;
            for d in &prep.direct {
                let m = &geom.meshes[d.mesh];
                if bound != Some(m.double_sided) {
                    rec.bind_pipeline(if m.double_sided { &self.double_sided } else { &self.culled });
                    bound = Some(m.double_sided);
                }
                let push = PanoramaPush { map, window: d.window, base_triangle: m.first_triangle };
                rec.push_constants(&self.layout, bytemuck::bytes_of(&push));
                rec.draw_indexed(3 * m.triangle_count, 3 * m.first_triangle);
                stats.draws += 1;
                stats.triangles_submitted += m.triangle_count as u64;
            }
        }
        if !state.soup_all.is_empty() {
            rec.bind_vertex_buffer(&state.soup, state.soup_all.len() as u64);
            let tau = std::f32::consts::TAU;
            let pi = std::f32::consts::PI;
            let lists: [(SoupList, &[f32]); 4] = [
                (SoupList::Culled, &[pi]),
                (SoupList::DoubleSided, &[pi]),
                (SoupList::WrapCulled, &[0.0, tau]),
                (SoupList::WrapDoubleSided, &[0.0, tau]),
            ];
            for (list, windows) in lists {
                let (first, end) = (state.soup_first[list as usize], state.soup_first[list as usize + 1]);
                if first == end {
                    continue;
                }
                let double = matches!(list, SoupList::DoubleSided | SoupList::WrapDoubleSided);
                rec.bind_pipeline(if double { &state.soup_double_sided } else { &state.soup_culled });
                for &window in windows {
                    let push = PanoramaPush { map, window, base_triangle: 0 };
                    rec.push_constants(&self.layout, bytemuck::bytes_of(&push));
                    rec.draw(end - first, first);
                    stats.draws += 1;
                    stats.triangles_submitted += (end - first) as u64 / 3;
                }
            }
        }
        rec.end_render_pass();
        target.record_readback(&mut rec);
        rec.transfer_to_host_barrier();
        rec.submit_and_wait()?;
        self.renders += 1;
        self.stats = stats;
        let image = &mut self.frame.faces[0];
        let bytes = self.targets[0].readback.read_bytes()?;
        let n = image.range_m.len() * 4;
        copy_pod(&bytes[..n], &mut image.range_m);
        copy_pod(&bytes[n..2 * n], &mut image.id);
        Ok(&self.frame)
    }
}

/// Copies raw bytes into a slice of 4-byte plain values (no alignment assumption on `src`).
fn copy_pod<T: bytemuck::Pod>(src: &[u8], dst: &mut [T]) {
    match bytemuck::try_cast_slice::<u8, T>(src) {
        Ok(s) => dst.copy_from_slice(s),
        Err(_) => bytemuck::cast_slice_mut::<T, u8>(dst).copy_from_slice(src),
    }
}

/// Grows a host-visible buffer geometrically so `needed` bytes fit.
fn ensure_capacity(
    ctx: &Arc<Context>,
    buffer: &mut Buffer,
    name: &'static str,
    usage: vk::BufferUsageFlags,
    needed: u64,
) -> Result<()> {
    if needed <= buffer.size() {
        return Ok(());
    }
    let size = needed.max(2 * buffer.size()).next_power_of_two();
    // The old buffer is idle (every render waits for its fence), so replacing it is safe.
    *buffer = Buffer::new(ctx, &upload_desc(name, size, usage))?;
    Ok(())
}

/// Mesh ranges must lie within the triangles; returns the triangle count.
fn check_geometry(geom: &FrameGeometry) -> Result<u32> {
    if geom.indices.len() % 3 != 0 {
        return Err(Error::Internal(format!("{} indices is not a whole number of triangles", geom.indices.len())));
    }
    let triangles = geom.triangle_count();
    for (k, m) in geom.meshes.iter().enumerate() {
        if m.first_triangle as u64 + m.triangle_count as u64 > triangles as u64 {
            return Err(Error::Internal(format!(
                "mesh {k} covers triangles {}..{} of {triangles}",
                m.first_triangle,
                m.first_triangle as u64 + m.triangle_count as u64
            )));
        }
    }
    Ok(triangles)
}

/// Every index must name a vertex (the GPU would read out of bounds otherwise).
fn check_indices(geom: &FrameGeometry) -> Result<()> {
    let n = geom.positions.len() as u32;
    match geom.indices.iter().copied().max() {
        Some(max) if max >= n => Err(Error::Internal(format!("index {max} out of {n} vertices"))),
        _ => Ok(()),
    }
}
