//! Render passes, pipeline layouts, graphics pipelines and framebuffers, each owning its
//! handle. Pipelines are created once (no per-frame creation); viewport and scissor are
//! dynamic state.

use super::{vk_err, Context, Image};
use crate::error::Result;
use ash::vk;
use std::sync::Arc;

/// A single-subpass render pass: colour attachments cleared and stored, left in
/// `TRANSFER_SRC_OPTIMAL` for a copy; a depth attachment cleared and discarded.
pub struct RenderPass {
    ctx: Arc<Context>,
    handle: vk::RenderPass,
}

impl RenderPass {
    pub fn new_for_readback(ctx: &Arc<Context>, color_formats: &[vk::Format], depth_format: vk::Format) -> Result<Self> {
        let mut attachments: Vec<vk::AttachmentDescription> = color_formats
            .iter()
            .map(|&format| {
                vk::AttachmentDescription::default()
                    .format(format)
                    .samples(vk::SampleCountFlags::TYPE_1)
                    .load_op(vk::AttachmentLoadOp::CLEAR)
                    .store_op(vk::AttachmentStoreOp::STORE)
                    .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
                    .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
                    .initial_layout(vk::ImageLayout::UNDEFINED)
                    .final_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL)
            })
            .collect();
        attachments.push(
            vk::AttachmentDescription::default()
                .format(depth_format)
                .samples(vk::SampleCountFlags::TYPE_1)
                .load_op(vk::AttachmentLoadOp::CLEAR)
                .store_op(vk::AttachmentStoreOp::DONT_CARE)
                .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
                .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
                .initial_layout(vk::ImageLayout::UNDEFINED)
                .final_layout(vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL),
        );
        let color_refs: Vec<vk::AttachmentReference> = (0..color_formats.len() as u32)
            .map(|attachment| vk::AttachmentReference { attachment, layout: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL })
            .collect();
        let depth_ref = vk::AttachmentReference {
            attachment: color_formats.len() as u32,
            layout: vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL,
        };
        let subpasses = [vk::SubpassDescription::default()
            .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
            .color_attachments(&color_refs)
            .depth_stencil_attachment(&depth_ref)];
        let attachment_stages = vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT
            | vk::PipelineStageFlags::EARLY_FRAGMENT_TESTS
            | vk::PipelineStageFlags::LATE_FRAGMENT_TESTS;
        let attachment_writes =
            vk::AccessFlags::COLOR_ATTACHMENT_WRITE | vk::AccessFlags::DEPTH_STENCIL_ATTACHMENT_WRITE;
        let dependencies = [
            // The previous use of the attachments (copy out, depth writes) before this clear.
            vk::SubpassDependency::default()
                .src_subpass(vk::SUBPASS_EXTERNAL)
                .dst_subpass(0)
                .src_stage_mask(vk::PipelineStageFlags::TRANSFER | vk::PipelineStageFlags::LATE_FRAGMENT_TESTS)
                .dst_stage_mask(attachment_stages)
                .src_access_mask(vk::AccessFlags::DEPTH_STENCIL_ATTACHMENT_WRITE)
                .dst_access_mask(attachment_writes | vk::AccessFlags::DEPTH_STENCIL_ATTACHMENT_READ),
            // The colour writes before the copy to the readback buffers.
            vk::SubpassDependency::default()
                .src_subpass(0)
                .dst_subpass(vk::SUBPASS_EXTERNAL)
                .src_stage_mask(vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT)
                .dst_stage_mask(vk::PipelineStageFlags::TRANSFER)
                .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                .dst_access_mask(vk::AccessFlags::TRANSFER_READ),
        ];
        let info = vk::RenderPassCreateInfo::default()
            .attachments(&attachments)
            .subpasses(&subpasses)
            .dependencies(&dependencies);
        // SAFETY: the create info points at locals alive for the call.
        let handle = unsafe { ctx.device().create_render_pass(&info, None) }.map_err(vk_err("vkCreateRenderPass"))?;
        Ok(RenderPass { ctx: ctx.clone(), handle })
    }

    pub fn handle(&self) -> vk::RenderPass {
        self.handle
    }
}

impl Drop for RenderPass {
    fn drop(&mut self) {
        // SAFETY: owners drop pipelines/framebuffers first and wait for their work to finish.
        unsafe { self.ctx.device().destroy_render_pass(self.handle, None) };
    }
}

/// A pipeline layout with one push-constant range and, optionally, descriptor set layouts.
pub struct PipelineLayout {
    ctx: Arc<Context>,
    handle: vk::PipelineLayout,
    push_stages: vk::ShaderStageFlags,
}

impl PipelineLayout {
    pub fn with_push_constants(ctx: &Arc<Context>, stages: vk::ShaderStageFlags, size: u32) -> Result<Self> {
        Self::with_sets(ctx, &[], stages, size)
    }

    /// Set `k` of the layout is `sets[k]`; push constants as `with_push_constants`.
    pub fn with_sets(
        ctx: &Arc<Context>,
        sets: &[vk::DescriptorSetLayout],
        stages: vk::ShaderStageFlags,
        size: u32,
    ) -> Result<Self> {
        let ranges = [vk::PushConstantRange { stage_flags: stages, offset: 0, size }];
        let info = vk::PipelineLayoutCreateInfo::default().set_layouts(sets).push_constant_ranges(&ranges);
        // SAFETY: the create info points at locals alive for the call.
        let handle =
            unsafe { ctx.device().create_pipeline_layout(&info, None) }.map_err(vk_err("vkCreatePipelineLayout"))?;
        Ok(PipelineLayout { ctx: ctx.clone(), handle, push_stages: stages })
    }

    pub fn handle(&self) -> vk::PipelineLayout {
        self.handle
    }
    pub fn push_stages(&self) -> vk::ShaderStageFlags {
        self.push_stages
    }
}

impl Drop for PipelineLayout {
    fn drop(&mut self) {
        // SAFETY: no pipeline or command buffer in flight uses the layout any more.
        unsafe { self.ctx.device().destroy_pipeline_layout(self.handle, None) };
    }
}

/// Fixed-function choices of a triangle pipeline with one `vec3` vertex attribute (and,
/// optionally, a `uint` after it), or with per-instance attributes only.
#[derive(Clone, Debug)]
pub struct PipelineDesc<'a> {
    pub vertex_spirv: &'a [u32],
    pub fragment_spirv: &'a [u32],
    /// Bytes per vertex; attribute 0 is `R32G32B32_SFLOAT` at offset 0.
    pub vertex_stride: u32,
    /// Attribute 1 is `R32_UINT` at offset 12 (a per-vertex id).
    pub id_attribute: bool,
    /// When set, binding 0 advances per instance (stride `vertex_stride`) and carries these
    /// attributes instead of the position (and id) above.
    pub instance_attributes: Option<&'a [vk::VertexInputAttributeDescription]>,
    pub color_attachments: u32,
    pub cull_mode: vk::CullModeFlags,
    pub front_face: vk::FrontFace,
    pub depth_compare: vk::CompareOp,
}

/// A graphics pipeline (dynamic viewport and scissor).
pub struct GraphicsPipeline {
    ctx: Arc<Context>,
    handle: vk::Pipeline,
}

struct ShaderModule<'a> {
    device: &'a ash::Device,
    handle: vk::ShaderModule,
}

impl<'a> ShaderModule<'a> {
    fn new(device: &'a ash::Device, code: &[u32]) -> Result<Self> {
        let info = vk::ShaderModuleCreateInfo::default().code(code);
        // SAFETY: `code` is SPIR-V compiled by build.rs.
        let handle = unsafe { device.create_shader_module(&info, None) }.map_err(vk_err("vkCreateShaderModule"))?;
        Ok(ShaderModule { device, handle })
    }
}

impl Drop for ShaderModule<'_> {
    fn drop(&mut self) {
        // SAFETY: modules may be destroyed once the pipelines using them are created.
        unsafe { self.device.destroy_shader_module(self.handle, None) };
    }
}

impl GraphicsPipeline {
    pub fn new(ctx: &Arc<Context>, layout: &PipelineLayout, pass: &RenderPass, desc: &PipelineDesc) -> Result<Self> {
        let device = ctx.device();
        let vert = ShaderModule::new(device, desc.vertex_spirv)?;
        let frag = ShaderModule::new(device, desc.fragment_spirv)?;
        let stages = [
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::VERTEX)
                .module(vert.handle)
                .name(c"main"),
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::FRAGMENT)
                .module(frag.handle)
                .name(c"main"),
        ];
        let bindings = [vk::VertexInputBindingDescription {
            binding: 0,
            stride: desc.vertex_stride,
            input_rate: if desc.instance_attributes.is_some() {
                vk::VertexInputRate::INSTANCE
            } else {
                vk::VertexInputRate::VERTEX
            },
        }];
        let all_attributes = [
            vk::VertexInputAttributeDescription { location: 0, binding: 0, format: vk::Format::R32G32B32_SFLOAT, offset: 0 },
            vk::VertexInputAttributeDescription { location: 1, binding: 0, format: vk::Format::R32_UINT, offset: 12 },
        ];
        let attributes = match desc.instance_attributes {
            Some(a) => a,
            None => &all_attributes[..if desc.id_attribute { 2 } else { 1 }],
        };
        let vertex_input = vk::PipelineVertexInputStateCreateInfo::default()
            .vertex_binding_descriptions(&bindings)
            .vertex_attribute_descriptions(attributes);
        let input_assembly =
            vk::PipelineInputAssemblyStateCreateInfo::default().topology(vk::PrimitiveTopology::TRIANGLE_LIST);
        let viewport = vk::PipelineViewportStateCreateInfo::default().viewport_count(1).scissor_count(1);
        let raster = vk::PipelineRasterizationStateCreateInfo::default()
            .polygon_mode(vk::PolygonMode::FILL)
            .cull_mode(desc.cull_mode)
            .front_face(desc.front_face)
            .line_width(1.0);
        let multisample =
            vk::PipelineMultisampleStateCreateInfo::default().rasterization_samples(vk::SampleCountFlags::TYPE_1);
        let depth = vk::PipelineDepthStencilStateCreateInfo::default()
            .depth_test_enable(true)
            .depth_write_enable(true)
            .depth_compare_op(desc.depth_compare);
        // Integer attachments forbid blending; every attachment writes its R channel only.
        let blend_attachments: Vec<_> = (0..desc.color_attachments)
            .map(|_| {
                vk::PipelineColorBlendAttachmentState::default()
                    .blend_enable(false)
                    .color_write_mask(vk::ColorComponentFlags::R)
            })
            .collect();
        let blend = vk::PipelineColorBlendStateCreateInfo::default().attachments(&blend_attachments);
        let dynamic_states = [vk::DynamicState::VIEWPORT, vk::DynamicState::SCISSOR];
        let dynamic = vk::PipelineDynamicStateCreateInfo::default().dynamic_states(&dynamic_states);
        let info = vk::GraphicsPipelineCreateInfo::default()
            .stages(&stages)
            .vertex_input_state(&vertex_input)
            .input_assembly_state(&input_assembly)
            .viewport_state(&viewport)
            .rasterization_state(&raster)
            .multisample_state(&multisample)
            .depth_stencil_state(&depth)
            .color_blend_state(&blend)
            .dynamic_state(&dynamic)
            .layout(layout.handle())
            .render_pass(pass.handle())
            .subpass(0);
        // SAFETY: all state structs and modules are alive for the call.
        let pipelines = unsafe { device.create_graphics_pipelines(vk::PipelineCache::null(), &[info], None) }
            .map_err(|(_, e)| vk_err("vkCreateGraphicsPipelines")(e))?;
        Ok(GraphicsPipeline { ctx: ctx.clone(), handle: pipelines[0] })
    }

    pub fn handle(&self) -> vk::Pipeline {
        self.handle
    }
}

impl Drop for GraphicsPipeline {
    fn drop(&mut self) {
        // SAFETY: no command buffer in flight uses the pipeline any more.
        unsafe { self.ctx.device().destroy_pipeline(self.handle, None) };
    }
}

/// A framebuffer over a set of image views (all the same size).
pub struct Framebuffer {
    ctx: Arc<Context>,
    handle: vk::Framebuffer,
    extent: vk::Extent2D,
}

impl Framebuffer {
    pub fn new(ctx: &Arc<Context>, pass: &RenderPass, attachments: &[&Image]) -> Result<Self> {
        let extent = attachments.first().map(|i| i.extent()).unwrap_or_default();
        let views: Vec<vk::ImageView> = attachments.iter().map(|i| i.view()).collect();
        let info = vk::FramebufferCreateInfo::default()
            .render_pass(pass.handle())
            .attachments(&views)
            .width(extent.width)
            .height(extent.height)
            .layers(1);
        // SAFETY: the views are alive; the caller keeps the images alive as long as this.
        let handle = unsafe { ctx.device().create_framebuffer(&info, None) }.map_err(vk_err("vkCreateFramebuffer"))?;
        Ok(Framebuffer { ctx: ctx.clone(), handle, extent })
    }

    pub fn handle(&self) -> vk::Framebuffer {
        self.handle
    }
    pub fn extent(&self) -> vk::Extent2D {
        self.extent
    }
}

impl Drop for Framebuffer {
    fn drop(&mut self) {
        // SAFETY: no command buffer in flight uses the framebuffer any more.
        unsafe { self.ctx.device().destroy_framebuffer(self.handle, None) };
    }
}
