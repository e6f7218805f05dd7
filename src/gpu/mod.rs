//! The Vulkan back end: the only module with `unsafe` Vulkan calls. It owns every handle
//! through small RAII types (one file per Vulkan concept): [`Context`] (instance, device,
//! queue, allocator, validation messenger), [`Buffer`], [`Image`], render pass / pipelines /
//! framebuffers ([`pipeline`]), a storage-buffer descriptor set ([`descriptor`]), command recording and fences ([`command`]). Everything that
//! holds a device object keeps an `Arc<Context>`, so the context outlives it and its `Drop`
//! (wait idle, allocator, device, messenger, instance) runs last.

pub mod buffer;
pub mod command;
pub mod context;
pub mod descriptor;
pub mod image;
pub mod pipeline;

pub use buffer::{Buffer, BufferDesc};
pub use command::{CommandRecorder, Commands};
pub use context::{Context, ContextOptions, DeviceChoice};
pub use descriptor::StorageSet;
pub use image::{Image, ImageDesc};
pub use pipeline::{Framebuffer, GraphicsPipeline, PipelineDesc, PipelineLayout, RenderPass};

use crate::error::Error;
use ash::vk;

/// Maps a failed Vulkan call to the library error naming it.
pub(crate) fn vk_err(call: &'static str) -> impl Fn(vk::Result) -> Error {
    move |result| Error::Vulkan { call, result }
}

/// Maps a gpu-allocator failure to the library error.
pub(crate) fn alloc_err(what: &str) -> impl Fn(gpu_allocator::AllocationError) -> Error + '_ {
    move |e| Error::Gpu(format!("allocating {what}: {e}"))
}

/// SPIR-V words from embedded bytes (copies, so the byte slice need not be 4-aligned).
pub fn spirv_words(bytes: &[u8]) -> crate::Result<Vec<u32>> {
    ash::util::read_spv(&mut std::io::Cursor::new(bytes))
        .map_err(|e| Error::Internal(format!("embedded SPIR-V is malformed: {e}")))
}
