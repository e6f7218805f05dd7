//! Stage 2b: rasterise one frame's triangles ([`FrameGeometry`], sensor frame, f32) into the
//! cube side faces of [`CubeFaces`] on the GPU and read back, per face and texel, the
//! Euclidean range (metres, of the nearest surface; 0 = nothing) and the global triangle
//! index plus one (0 = nothing). Texel layout and face frusta are those of `projection.rs`
//! (row-major, row 0 = top).
//!
//! Per face only the meshes whose bounding sphere the face can see are drawn; a face with
//! none is not rendered, and a frame where no face sees anything costs no GPU work at all.
//! All rendered faces go into one command buffer and one submit.

use crate::error::{Error, Result};
use crate::geometry::FrameGeometry;
use crate::gpu::{
    spirv_words, Buffer, BufferDesc, Commands, Context, Framebuffer, GraphicsPipeline, Image, ImageDesc,
    PipelineDesc, PipelineLayout, RenderPass,
};
use crate::projection::{CubeFaces, Face};
use ash::vk;
use glam::Vec3;
use std::sync::Arc;

static RANGE_VERT: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/range.vert.spv"));
static RANGE_FRAG: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/range.frag.spv"));

/// Front face of single-sided meshes. Geometry convention: triangle (a, b, c) faces the
/// sensor when `dot((b - a) x (c - a), a) < 0` (counter-clockwise seen from the viewer).
/// The face camera (right, up, forward) is left-handed and Vulkan's framebuffer y points
/// down; the two flips cancel, so the viewer's counter-clockwise stays Vulkan's
/// `COUNTER_CLOCKWISE`. Proven by `tests/gpu_raster.rs::back_face_culling_keeps_the_near_side`.
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

/// One face's read-back images.
#[derive(Clone, Debug, Default)]
pub struct FaceImage {
    /// Index into `CubeFaces::faces`.
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

/// The rasterised faces of one frame, in `CubeFaces::faces` order.
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
}

/// Per-face GPU resources, allocated once.
struct FaceTarget {
    framebuffer: Framebuffer,
    range: Image,
    id: Image,
    _depth: Image,
    /// Range (w*h f32) followed by id (w*h u32).
    readback: Buffer,
    push: PushConstants,
}

/// The Vulkan rasteriser for one set of cube faces. Resources for all faces are created in
/// `new`; `render` allocates nothing in steady state (buffers grow geometrically).
pub struct Renderer {
    // Field order is drop order: GPU objects first, the context last.
    targets: Vec<FaceTarget>,
    vertices: Buffer,
    indices: Buffer,
    commands: Commands,
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

impl Renderer {
    pub fn new(ctx: &Arc<Context>, faces: &CubeFaces) -> Result<Renderer> {
        let vert = spirv_words(RANGE_VERT)?;
        let frag = spirv_words(RANGE_FRAG)?;
        let pass = RenderPass::new_for_readback(ctx, &[RANGE_FORMAT, ID_FORMAT], DEPTH_FORMAT)?;
        let layout = PipelineLayout::with_push_constants(
            ctx,
            vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT,
            std::mem::size_of::<PushConstants>() as u32,
        )?;
        let desc = |cull_mode| PipelineDesc {
            vertex_spirv: &vert,
            fragment_spirv: &frag,
            vertex_stride: 12,
            color_attachments: 2,
            cull_mode,
            front_face: FRONT_FACE,
            // Reversed-Z: nearer is greater; cleared to 0.
            depth_compare: vk::CompareOp::GREATER,
        };
        let culled = GraphicsPipeline::new(ctx, &layout, &pass, &desc(vk::CullModeFlags::BACK))?;
        let double_sided = GraphicsPipeline::new(ctx, &layout, &pass, &desc(vk::CullModeFlags::NONE))?;

        let mut targets = Vec::with_capacity(faces.faces.len());
        let mut frame = RasterFrame { faces: Vec::with_capacity(faces.faces.len()) };
        for face in &faces.faces {
            let (w, h) = (face.width, face.height);
            let range = Image::new(ctx, &ImageDesc::color_readback("face range", w, h, RANGE_FORMAT))?;
            let id = Image::new(ctx, &ImageDesc::color_readback("face id", w, h, ID_FORMAT))?;
            let depth = Image::new(ctx, &ImageDesc::depth("face depth", w, h, DEPTH_FORMAT))?;
            let framebuffer = Framebuffer::new(ctx, &pass, &[&range, &id, &depth])?;
            let texels = w as u64 * h as u64;
            let readback = Buffer::new(ctx, &BufferDesc::readback("face readback", 8 * texels))?;
            let push = PushConstants {
                clip_from_sensor: face.clip_from_sensor().to_cols_array(),
                ..Default::default()
            };
            targets.push(FaceTarget { framebuffer, range, id, _depth: depth, readback, push });
            frame.faces.push(FaceImage {
                index: face.index,
                width: w,
                height: h,
                rendered: false,
                range_m: vec![0.0; texels as usize],
                id: vec![0; texels as usize],
            });
        }
        let vertices =
            Buffer::new(ctx, &upload_desc("vertices", MIN_BUFFER_BYTES, vk::BufferUsageFlags::VERTEX_BUFFER))?;
        let indices =
            Buffer::new(ctx, &upload_desc("indices", MIN_BUFFER_BYTES, vk::BufferUsageFlags::INDEX_BUFFER))?;
        Ok(Renderer {
            targets,
            vertices,
            indices,
            commands: Commands::new(ctx)?,
            culled,
            double_sided,
            layout,
            pass,
            faces: faces.faces.clone(),
            visible: vec![Vec::new(); faces.faces.len()],
            frame,
            stats: RenderStats::default(),
            renders: 0,
            ctx: ctx.clone(),
        })
    }

    pub fn context(&self) -> &Arc<Context> {
        &self.ctx
    }

    /// The faces this renderer draws.
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

    /// Rasterises `geom` into every face that sees at least one mesh and reads it back.
    pub fn render(&mut self, geom: &FrameGeometry) -> Result<&RasterFrame> {
        self.stats = RenderStats::default();
        let triangles = check_geometry(geom)?;
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
            let texels = target.range.extent().width as u64 * target.range.extent().height as u64;
            rec.copy_image_to_buffer(&target.range, &target.readback, 0);
            rec.copy_image_to_buffer(&target.id, &target.readback, 4 * texels);
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
