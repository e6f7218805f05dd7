//! Command recording: [`Commands`] owns a pool, one primary command buffer and a fence;
//! [`CommandRecorder`] records into it with methods that take the owning wrappers (so every
//! handle is alive) and borrows them until [`CommandRecorder::submit_and_wait`] returns.
//! [`CommandRecorder::submit`] returns at once instead, and the work stays in flight until
//! [`Commands::wait`]: until then the owner of what was recorded must neither write, free nor
//! read back any of it (the owner's `Drop` waits first).

use super::{vk_err, Buffer, Context, Framebuffer, GraphicsPipeline, Image, PipelineLayout, RenderPass};
use crate::error::{Error, Result};
use ash::vk;
use std::sync::Arc;

/// A command pool with one resettable primary command buffer and its fence.
pub struct Commands {
    ctx: Arc<Context>,
    pool: vk::CommandPool,
    buffer: vk::CommandBuffer,
    fence: vk::Fence,
    /// Submitted by [`CommandRecorder::submit`] and not yet waited for.
    in_flight: bool,
}

impl Commands {
    pub fn new(ctx: &Arc<Context>) -> Result<Self> {
        let device = ctx.device();
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(ctx.queue_family())
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        // SAFETY: valid device and create info.
        let pool = unsafe { device.create_command_pool(&pool_info, None) }.map_err(vk_err("vkCreateCommandPool"))?;
        let mut commands =
            Commands { ctx: ctx.clone(), pool, buffer: vk::CommandBuffer::null(), fence: vk::Fence::null(), in_flight: false };
        let alloc_info = vk::CommandBufferAllocateInfo::default()
            .command_pool(pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: `pool` belongs to this device.
        commands.buffer = unsafe { device.allocate_command_buffers(&alloc_info) }
            .map_err(vk_err("vkAllocateCommandBuffers"))?[0];
        // SAFETY: valid device; the fence starts unsignalled.
        commands.fence = unsafe { device.create_fence(&vk::FenceCreateInfo::default(), None) }
            .map_err(vk_err("vkCreateFence"))?;
        Ok(commands)
    }

    /// Starts recording (implicitly resets the command buffer, whose last submission has
    /// completed: `submit_and_wait` waits for it, and so does this for a `submit`).
    pub fn begin(&mut self) -> Result<CommandRecorder<'_>> {
        self.wait()?;
        let info = vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: the buffer is not pending (every submission is waited for) and its pool
        // allows individual resets.
        unsafe { self.ctx.device().begin_command_buffer(self.buffer, &info) }
            .map_err(vk_err("vkBeginCommandBuffer"))?;
        Ok(CommandRecorder { commands: self, in_pass: false, vertex_count: 0, index_count: 0 })
    }

    /// Waits for the work of the last [`CommandRecorder::submit`], if it is still in flight.
    pub fn wait(&mut self) -> Result<()> {
        if !self.in_flight {
            return Ok(());
        }
        self.in_flight = false;
        wait_and_reset(&self.ctx, self.fence)
    }

    /// Whether submitted work has not been waited for yet.
    pub fn in_flight(&self) -> bool {
        self.in_flight
    }
}

/// Waits for `fence` and resets it.
fn wait_and_reset(ctx: &Context, fence: vk::Fence) -> Result<()> {
    let device = ctx.device();
    // SAFETY: the fence belongs to this device and was submitted.
    unsafe { device.wait_for_fences(&[fence], true, u64::MAX) }.map_err(vk_err("vkWaitForFences"))?;
    // SAFETY: the fence is signalled and no longer in use.
    unsafe { device.reset_fences(&[fence]) }.map_err(vk_err("vkResetFences"))
}

impl Drop for Commands {
    fn drop(&mut self) {
        // Nothing may be pending when the pool goes.
        if self.wait().is_err() {
            let _ = self.ctx.wait_idle();
        }
        // SAFETY: every submission has been waited for, so nothing is pending; destroying
        // the pool frees its command buffer.
        unsafe {
            self.ctx.device().destroy_fence(self.fence, None);
            self.ctx.device().destroy_command_pool(self.pool, None);
        }
    }
}

/// Records into a [`Commands`]; everything passed in stays borrowed for `'a`, i.e. until
/// the recorder is consumed by `submit_and_wait` (or dropped unsubmitted).
pub struct CommandRecorder<'a> {
    commands: &'a mut Commands,
    in_pass: bool,
    /// Vertices / indices of the bound buffers, to bounds-check draws.
    vertex_count: u64,
    index_count: u64,
}

impl<'a> CommandRecorder<'a> {
    fn device(&self) -> &ash::Device {
        self.commands.ctx.device()
    }
    fn cmd(&self) -> vk::CommandBuffer {
        self.commands.buffer
    }

    /// Begins `pass` on `framebuffer` with the given clear values, and sets viewport and
    /// scissor to the whole framebuffer (depth range 0..1).
    pub fn begin_render_pass(&mut self, pass: &'a RenderPass, framebuffer: &'a Framebuffer, clear: &[vk::ClearValue]) {
        assert!(!self.in_pass, "render pass already begun");
        let extent = framebuffer.extent();
        let area = vk::Rect2D { offset: vk::Offset2D::default(), extent };
        let info = vk::RenderPassBeginInfo::default()
            .render_pass(pass.handle())
            .framebuffer(framebuffer.handle())
            .render_area(area)
            .clear_values(clear);
        let viewport = vk::Viewport {
            x: 0.0,
            y: 0.0,
            width: extent.width as f32,
            height: extent.height as f32,
            min_depth: 0.0,
            max_depth: 1.0,
        };
        // SAFETY: recording state; pass and framebuffer are alive for 'a and compatible
        // (the framebuffer was created for this pass by the caller).
        unsafe {
            self.device().cmd_begin_render_pass(self.cmd(), &info, vk::SubpassContents::INLINE);
            self.device().cmd_set_viewport(self.cmd(), 0, &[viewport]);
            self.device().cmd_set_scissor(self.cmd(), 0, &[area]);
        }
        self.in_pass = true;
    }

    pub fn end_render_pass(&mut self) {
        assert!(self.in_pass, "no render pass to end");
        // SAFETY: inside a render pass begun by this recorder.
        unsafe { self.device().cmd_end_render_pass(self.cmd()) };
        self.in_pass = false;
    }

    pub fn bind_pipeline(&mut self, pipeline: &'a GraphicsPipeline) {
        // SAFETY: recording state; the pipeline is alive for 'a.
        unsafe { self.device().cmd_bind_pipeline(self.cmd(), vk::PipelineBindPoint::GRAPHICS, pipeline.handle()) };
    }

    /// Binds `buffer` as vertex buffer 0 holding `vertex_count` vertices.
    pub fn bind_vertex_buffer(&mut self, buffer: &'a Buffer, vertex_count: u64) {
        self.vertex_count = vertex_count;
        // SAFETY: recording state; the buffer has VERTEX_BUFFER usage and is alive for 'a.
        unsafe { self.device().cmd_bind_vertex_buffers(self.cmd(), 0, &[buffer.handle()], &[0]) };
    }

    /// Binds `buffer` as a u32 index buffer holding `index_count` indices, each of which the
    /// caller has checked to be below the bound vertex count.
    pub fn bind_index_buffer_u32(&mut self, buffer: &'a Buffer, index_count: u64) {
        assert!(index_count * 4 <= buffer.size(), "index count exceeds the index buffer");
        self.index_count = index_count;
        // SAFETY: recording state; the buffer has INDEX_BUFFER usage and is alive for 'a.
        unsafe { self.device().cmd_bind_index_buffer(self.cmd(), buffer.handle(), 0, vk::IndexType::UINT32) };
    }

    pub fn push_constants(&mut self, layout: &'a PipelineLayout, bytes: &[u8]) {
        // SAFETY: recording state; the range lies within the layout's push-constant range
        // (validated by the layer in tests).
        unsafe { self.device().cmd_push_constants(self.cmd(), layout.handle(), layout.push_stages(), 0, bytes) };
    }

    /// `vkCmdDrawIndexed(index_count, 1, first_index, 0, 0)`, bounds-checked against the bound
    /// index buffer.
    pub fn draw_indexed(&mut self, index_count: u32, first_index: u32) {
        assert!(self.in_pass, "draw outside a render pass");
        assert!(
            first_index as u64 + index_count as u64 <= self.index_count && self.vertex_count > 0,
            "draw exceeds the bound buffers"
        );
        // SAFETY: inside a render pass with pipeline, vertex and index buffers bound; the
        // index range is in bounds (checked) and index values are below the vertex count
        // (checked by the caller when it filled the buffer).
        unsafe { self.device().cmd_draw_indexed(self.cmd(), index_count, 1, first_index, 0, 0) };
    }

    /// Binds `set` as descriptor set 0 of `layout` for graphics.
    pub fn bind_storage_set(&mut self, layout: &'a PipelineLayout, set: &'a super::StorageSet) {
        // SAFETY: recording state; layout and set are alive for 'a and the set's layout is
        // set 0 of `layout` (the caller created them together).
        unsafe {
            self.device().cmd_bind_descriptor_sets(
                self.cmd(),
                vk::PipelineBindPoint::GRAPHICS,
                layout.handle(),
                0,
                &[set.handle()],
                &[],
            )
        };
    }

    /// `vkCmdDraw(vertices_per_instance, instance_count, 0, 0)` with the bound vertex buffer
    /// holding per-instance data: the instances must lie within it.
    pub fn draw_instanced(&mut self, vertices_per_instance: u32, instance_count: u32) {
        assert!(self.in_pass, "draw outside a render pass");
        assert!(instance_count as u64 <= self.vertex_count, "draw exceeds the bound instance buffer");
        // SAFETY: inside a render pass with pipeline and instance buffer bound; the instance
        // range is in bounds (checked); the vertex shader reads no per-vertex attribute.
        unsafe { self.device().cmd_draw(self.cmd(), vertices_per_instance, instance_count, 0, 0) };
    }

    /// `vkCmdDraw(vertex_count, 1, first_vertex, 0)`, bounds-checked against the bound vertex
    /// buffer.
    pub fn draw(&mut self, vertex_count: u32, first_vertex: u32) {
        assert!(self.in_pass, "draw outside a render pass");
        assert!(first_vertex as u64 + vertex_count as u64 <= self.vertex_count, "draw exceeds the bound vertex buffer");
        // SAFETY: inside a render pass with pipeline and vertex buffer bound; the vertex range
        // is in bounds (checked).
        unsafe { self.device().cmd_draw(self.cmd(), vertex_count, 1, first_vertex, 0) };
    }

    /// Copies a whole single-channel 32-bit colour image (in `TRANSFER_SRC_OPTIMAL`) to
    /// `buffer` at byte `offset`, tightly packed, row-major.
    pub fn copy_image_to_buffer(&mut self, image: &'a Image, buffer: &'a Buffer, offset: u64) {
        assert!(!self.in_pass, "copy inside a render pass");
        let extent = image.extent();
        assert!(offset + 4 * extent.width as u64 * extent.height as u64 <= buffer.size(), "copy exceeds the buffer");
        let region = vk::BufferImageCopy {
            buffer_offset: offset,
            buffer_row_length: 0,
            buffer_image_height: 0,
            image_subresource: vk::ImageSubresourceLayers {
                aspect_mask: image.desc().aspect,
                mip_level: 0,
                base_array_layer: 0,
                layer_count: 1,
            },
            image_offset: vk::Offset3D::default(),
            image_extent: vk::Extent3D { width: extent.width, height: extent.height, depth: 1 },
        };
        // SAFETY: recording state outside a pass; image and buffer alive for 'a, with
        // TRANSFER_SRC / TRANSFER_DST usage; the region is in bounds (checked).
        unsafe {
            self.device().cmd_copy_image_to_buffer(
                self.cmd(),
                image.handle(),
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                buffer.handle(),
                &[region],
            )
        };
    }

    /// Makes all transfer writes so far visible to host reads (after the fence).
    pub fn transfer_to_host_barrier(&mut self) {
        let barrier = vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ);
        // SAFETY: recording state outside a render pass.
        unsafe {
            self.device().cmd_pipeline_barrier(
                self.cmd(),
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::HOST,
                vk::DependencyFlags::empty(),
                &[barrier],
                &[],
                &[],
            )
        };
    }

    /// Ends recording, submits, and waits for completion.
    pub fn submit_and_wait(self) -> Result<()> {
        let commands = self.submit_only()?;
        wait_and_reset(&commands.ctx, commands.fence)
    }

    /// Ends recording and submits without waiting: the work is in flight until
    /// [`Commands::wait`] (or the next [`Commands::begin`]). Everything recorded must stay
    /// alive and untouched by the host until then (see the module notes).
    pub fn submit(self) -> Result<()> {
        let commands = self.submit_only()?;
        commands.in_flight = true;
        Ok(())
    }

    fn submit_only(self) -> Result<&'a mut Commands> {
        if self.in_pass {
            return Err(Error::Internal("submit inside a render pass".into()));
        }
        let (cmd, fence) = (self.cmd(), self.commands.fence);
        // SAFETY: recording state, outside a render pass.
        unsafe { self.device().end_command_buffer(cmd) }.map_err(vk_err("vkEndCommandBuffer"))?;
        self.commands.ctx.submit(cmd, fence)?;
        Ok(self.commands)
    }
}
