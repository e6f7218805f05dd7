//! One descriptor set holding one storage buffer (binding 0), with its layout and pool: what
//! a shader needs to read a table the CPU wrote once (the beam directions of the exact beam
//! raster).

use super::{vk_err, Buffer, Context};
use crate::error::Result;
use ash::vk;
use std::sync::Arc;

/// A set layout, a pool and one set whose binding 0 is a storage buffer.
pub struct StorageSet {
    ctx: Arc<Context>,
    layout: vk::DescriptorSetLayout,
    pool: vk::DescriptorPool,
    set: vk::DescriptorSet,
}

impl StorageSet {
    /// A set for `stages` with binding 0 = the whole of `buffer` (STORAGE_BUFFER usage).
    pub fn new(ctx: &Arc<Context>, stages: vk::ShaderStageFlags, buffer: &Buffer) -> Result<StorageSet> {
        let device = ctx.device();
        let bindings = [vk::DescriptorSetLayoutBinding::default()
            .binding(0)
            .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
            .descriptor_count(1)
            .stage_flags(stages)];
        let info = vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings);
        // SAFETY: valid device; the create info points at locals alive for the call.
        let layout = unsafe { device.create_descriptor_set_layout(&info, None) }
            .map_err(vk_err("vkCreateDescriptorSetLayout"))?;
        let sizes = [vk::DescriptorPoolSize { ty: vk::DescriptorType::STORAGE_BUFFER, descriptor_count: 1 }];
        let info = vk::DescriptorPoolCreateInfo::default().max_sets(1).pool_sizes(&sizes);
        // SAFETY: as above.
        let pool = match unsafe { device.create_descriptor_pool(&info, None) } {
            Ok(p) => p,
            Err(e) => {
                // SAFETY: the layout was created above and is used by nothing.
                unsafe { device.destroy_descriptor_set_layout(layout, None) };
                return Err(vk_err("vkCreateDescriptorPool")(e));
            }
        };
        let mut set = StorageSet { ctx: ctx.clone(), layout, pool, set: vk::DescriptorSet::null() };
        let layouts = [layout];
        let info = vk::DescriptorSetAllocateInfo::default().descriptor_pool(pool).set_layouts(&layouts);
        // SAFETY: the pool has room for this one set of this layout.
        set.set = unsafe { device.allocate_descriptor_sets(&info) }.map_err(vk_err("vkAllocateDescriptorSets"))?[0];
        let buffers = [vk::DescriptorBufferInfo { buffer: buffer.handle(), offset: 0, range: vk::WHOLE_SIZE }];
        let write = vk::WriteDescriptorSet::default()
            .dst_set(set.set)
            .dst_binding(0)
            .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
            .buffer_info(&buffers);
        // SAFETY: the set is not in use by any command buffer yet; the buffer is alive (the
        // owner keeps it as long as this set).
        unsafe { device.update_descriptor_sets(&[write], &[]) };
        Ok(set)
    }

    pub fn layout(&self) -> vk::DescriptorSetLayout {
        self.layout
    }

    pub fn handle(&self) -> vk::DescriptorSet {
        self.set
    }
}

impl Drop for StorageSet {
    fn drop(&mut self) {
        // SAFETY: no command buffer in flight uses the set (every submit is waited for);
        // destroying the pool frees the set.
        unsafe {
            self.ctx.device().destroy_descriptor_pool(self.pool, None);
            self.ctx.device().destroy_descriptor_set_layout(self.layout, None);
        }
    }
}
