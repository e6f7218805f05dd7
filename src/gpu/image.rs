//! 2D images with one view that own their memory: colour / depth attachments that are
//! rendered and then copied out (`TRANSFER_SRC`).

use super::{alloc_err, vk_err, Context};
use crate::error::Result;
use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;
use std::sync::Arc;

/// A 2D single-sample, single-mip image.
#[derive(Clone, Debug)]
pub struct ImageDesc {
    pub name: &'static str,
    pub width: u32,
    pub height: u32,
    pub format: vk::Format,
    pub usage: vk::ImageUsageFlags,
    pub aspect: vk::ImageAspectFlags,
}

impl ImageDesc {
    /// A colour attachment that is copied to a buffer afterwards.
    pub fn color_readback(name: &'static str, width: u32, height: u32, format: vk::Format) -> Self {
        ImageDesc {
            name,
            width,
            height,
            format,
            usage: vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC,
            aspect: vk::ImageAspectFlags::COLOR,
        }
    }
    /// A depth attachment that is never read back.
    pub fn depth(name: &'static str, width: u32, height: u32, format: vk::Format) -> Self {
        ImageDesc {
            name,
            width,
            height,
            format,
            usage: vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT,
            aspect: vk::ImageAspectFlags::DEPTH,
        }
    }
}

/// An image, its memory and a view of the whole image.
pub struct Image {
    ctx: Arc<Context>,
    handle: vk::Image,
    view: vk::ImageView,
    allocation: Option<Allocation>,
    desc: ImageDesc,
}

impl Image {
    pub fn new(ctx: &Arc<Context>, desc: &ImageDesc) -> Result<Image> {
        let device = ctx.device();
        let info = vk::ImageCreateInfo::default()
            .image_type(vk::ImageType::TYPE_2D)
            .format(desc.format)
            .extent(vk::Extent3D { width: desc.width, height: desc.height, depth: 1 })
            .mip_levels(1)
            .array_layers(1)
            .samples(vk::SampleCountFlags::TYPE_1)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(desc.usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        // SAFETY: valid device and create info.
        let handle = unsafe { device.create_image(&info, None) }.map_err(vk_err("vkCreateImage"))?;
        // From here on `image`'s Drop cleans up whatever exists.
        let mut image =
            Image { ctx: ctx.clone(), handle, view: vk::ImageView::null(), allocation: None, desc: desc.clone() };
        // SAFETY: `handle` was just created on this device.
        let requirements = unsafe { device.get_image_memory_requirements(handle) };
        let allocation = ctx
            .allocator()
            .allocate(&AllocationCreateDesc {
                name: desc.name,
                requirements,
                location: MemoryLocation::GpuOnly,
                linear: false,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            })
            .map_err(alloc_err(desc.name))?;
        // SAFETY: compatible memory type and aligned offset from the allocator; the allocation
        // is kept (and freed) with the image.
        let bound = unsafe { device.bind_image_memory(handle, allocation.memory(), allocation.offset()) };
        image.allocation = Some(allocation);
        bound.map_err(vk_err("vkBindImageMemory"))?;
        let view_info = vk::ImageViewCreateInfo::default()
            .image(handle)
            .view_type(vk::ImageViewType::TYPE_2D)
            .format(desc.format)
            .subresource_range(Self::range(desc.aspect));
        // SAFETY: the image is bound to memory; the view matches its format and aspect.
        image.view = unsafe { device.create_image_view(&view_info, None) }.map_err(vk_err("vkCreateImageView"))?;
        Ok(image)
    }

    fn range(aspect: vk::ImageAspectFlags) -> vk::ImageSubresourceRange {
        vk::ImageSubresourceRange { aspect_mask: aspect, base_mip_level: 0, level_count: 1, base_array_layer: 0, layer_count: 1 }
    }

    pub fn handle(&self) -> vk::Image {
        self.handle
    }
    pub fn view(&self) -> vk::ImageView {
        self.view
    }
    pub fn desc(&self) -> &ImageDesc {
        &self.desc
    }
    pub fn extent(&self) -> vk::Extent2D {
        vk::Extent2D { width: self.desc.width, height: self.desc.height }
    }
}

impl Drop for Image {
    fn drop(&mut self) {
        // SAFETY: no pending device work uses the image (owners wait on their fences); view,
        // image and allocation belong to `ctx`; null handles are ignored by Vulkan.
        unsafe {
            self.ctx.device().destroy_image_view(self.view, None);
            self.ctx.device().destroy_image(self.handle, None);
        }
        if let Some(a) = self.allocation.take() {
            if let Err(e) = self.ctx.allocator().free(a) {
                eprintln!("pedscan: freeing image memory failed: {e}");
            }
        }
    }
}
