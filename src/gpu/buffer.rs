//! Buffers that own their memory: created from a [`BufferDesc`], freed in `Drop`.

use super::{alloc_err, vk_err, Context};
use crate::error::{Error, Result};
use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;
use std::sync::Arc;

/// What a buffer is for.
#[derive(Clone, Debug)]
pub struct BufferDesc {
    pub name: &'static str,
    pub size: u64,
    pub usage: vk::BufferUsageFlags,
    pub location: MemoryLocation,
}

impl BufferDesc {
    /// Host-written, device-read (vertex / index data uploaded every frame).
    pub fn upload(name: &'static str, size: u64, usage: vk::BufferUsageFlags) -> Self {
        BufferDesc { name, size, usage, location: MemoryLocation::CpuToGpu }
    }
    /// Device-written (transfer destination), host-read.
    pub fn readback(name: &'static str, size: u64) -> Self {
        BufferDesc { name, size, usage: vk::BufferUsageFlags::TRANSFER_DST, location: MemoryLocation::GpuToCpu }
    }
}

/// A buffer with its own allocation.
pub struct Buffer {
    ctx: Arc<Context>,
    handle: vk::Buffer,
    allocation: Option<Allocation>,
    size: u64,
}

impl Buffer {
    pub fn new(ctx: &Arc<Context>, desc: &BufferDesc) -> Result<Buffer> {
        let device = ctx.device();
        let info = vk::BufferCreateInfo::default()
            .size(desc.size.max(4))
            .usage(desc.usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        // SAFETY: valid device and create info.
        let handle = unsafe { device.create_buffer(&info, None) }.map_err(vk_err("vkCreateBuffer"))?;
        // SAFETY: `handle` was just created on this device.
        let requirements = unsafe { device.get_buffer_memory_requirements(handle) };
        let allocation = ctx.allocator().allocate(&AllocationCreateDesc {
            name: desc.name,
            requirements,
            location: desc.location,
            linear: true,
            allocation_scheme: AllocationScheme::GpuAllocatorManaged,
        });
        let allocation = match allocation {
            Ok(a) => a,
            Err(e) => {
                // SAFETY: unused, unbound buffer of this device.
                unsafe { device.destroy_buffer(handle, None) };
                return Err(alloc_err(desc.name)(e));
            }
        };
        let buffer = Buffer { ctx: ctx.clone(), handle, allocation: Some(allocation), size: desc.size };
        let a = buffer.allocation.as_ref().expect("allocation just set");
        // SAFETY: the memory comes from a compatible type (requirements above) and the
        // offset is aligned by the allocator; on failure `buffer`'s Drop cleans up.
        unsafe { device.bind_buffer_memory(handle, a.memory(), a.offset()) }
            .map_err(vk_err("vkBindBufferMemory"))?;
        Ok(buffer)
    }

    pub fn handle(&self) -> vk::Buffer {
        self.handle
    }

    /// Requested size in bytes.
    pub fn size(&self) -> u64 {
        self.size
    }

    fn allocation(&self) -> &Allocation {
        self.allocation.as_ref().expect("buffer allocation lives until Drop")
    }

    /// Copies `data` to the start of a host-visible buffer.
    pub fn write<T: bytemuck::Pod>(&mut self, data: &[T]) -> Result<()> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        if bytes.len() as u64 > self.size {
            return Err(Error::Internal(format!("{} bytes do not fit a {}-byte buffer", bytes.len(), self.size)));
        }
        let a = self.allocation.as_mut().expect("buffer allocation lives until Drop");
        let map = a.mapped_slice_mut().ok_or_else(|| Error::Internal("buffer is not host-visible".into()))?;
        map[..bytes.len()].copy_from_slice(bytes);
        if !a.memory_properties().contains(vk::MemoryPropertyFlags::HOST_COHERENT) {
            // SAFETY: the allocator keeps the whole block mapped; WHOLE_SIZE covers it, and the
            // memory handle is only used for this call while the allocation is alive.
            unsafe {
                let range = vk::MappedMemoryRange::default().memory(a.memory()).offset(0).size(vk::WHOLE_SIZE);
                self.ctx.device().flush_mapped_memory_ranges(&[range])
            }
                .map_err(vk_err("vkFlushMappedMemoryRanges"))?;
        }
        Ok(())
    }

    /// The mapped bytes of a host-visible buffer, made visible to the host first. Call only
    /// after the device work that wrote them has completed (fence waited).
    pub fn read_bytes(&self) -> Result<&[u8]> {
        let a = self.allocation();
        if !a.memory_properties().contains(vk::MemoryPropertyFlags::HOST_COHERENT) {
            // SAFETY: the allocator keeps the whole block mapped; WHOLE_SIZE covers it, and the
            // memory handle is only used for this call while the allocation is alive.
            unsafe {
                let range = vk::MappedMemoryRange::default().memory(a.memory()).offset(0).size(vk::WHOLE_SIZE);
                self.ctx.device().invalidate_mapped_memory_ranges(&[range])
            }
                .map_err(vk_err("vkInvalidateMappedMemoryRanges"))?;
        }
        let map = a.mapped_slice().ok_or_else(|| Error::Internal("buffer is not host-visible".into()))?;
        Ok(&map[..self.size as usize])
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        // SAFETY: the owner guarantees no pending device work uses the buffer (renderers wait
        // on their fence before returning); buffer and allocation belong to `ctx`.
        unsafe { self.ctx.device().destroy_buffer(self.handle, None) };
        if let Some(a) = self.allocation.take() {
            if let Err(e) = self.ctx.allocator().free(a) {
                eprintln!("pedscan: freeing buffer memory failed: {e}");
            }
        }
    }
}
