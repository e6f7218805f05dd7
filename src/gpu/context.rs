//! The Vulkan context: loader entry, instance (optionally with the Khronos validation layer
//! and a counting debug messenger), the chosen physical device, a logical device with one
//! graphics queue, and the memory allocator. `Drop` waits idle, then drops the allocator
//! before the device, then the messenger, then the instance.

use super::{alloc_err, vk_err};
use crate::error::{Error, Result};
use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};
use std::ffi::{c_void, CStr};
use std::mem::ManuallyDrop;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// Which physical device to use.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum DeviceChoice {
    /// Discrete, then integrated, then virtual GPU, then CPU (lavapipe), then anything.
    #[default]
    Auto,
    /// The n-th device in `Context::list_devices()` order.
    Index(usize),
    /// The first device whose name contains this (case-insensitive).
    Name(String),
}

/// How to create a [`Context`].
#[derive(Clone, Debug, Default)]
pub struct ContextOptions {
    /// Enable `VK_LAYER_KHRONOS_validation` with a counting messenger (`--validation`,
    /// `debug.validation`). A missing layer is an error.
    pub validation: bool,
    pub device: DeviceChoice,
}

/// Counters the debug messenger writes into. Boxed, so its address is stable for the
/// callback's user-data pointer; freed after the instance (and messenger) are destroyed.
struct Counters {
    errors: Arc<AtomicUsize>,
    warnings: Arc<AtomicUsize>,
}

struct Debug {
    loader: ash::ext::debug_utils::Instance,
    messenger: vk::DebugUtilsMessengerEXT,
}

/// Instance, device, queue and allocator. Share it as `Arc<Context>`.
pub struct Context {
    _entry: ash::Entry,
    instance: ash::Instance,
    debug: Option<Debug>,
    counters: Box<Counters>,
    physical_device: vk::PhysicalDevice,
    device_name: String,
    device_type: vk::PhysicalDeviceType,
    limits: vk::PhysicalDeviceLimits,
    device: ash::Device,
    queue_family: u32,
    queue: Mutex<vk::Queue>,
    allocator: ManuallyDrop<Mutex<Allocator>>,
}

unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: `user` is the `Counters` box owned by the context, alive until after the
    // messenger and instance are destroyed; `data` is valid for the duration of the call.
    let (counters, message) = unsafe {
        let counters = &*(user as *const Counters);
        let message = data
            .as_ref()
            .and_then(|d| d.message_as_c_str())
            .map(|m| m.to_string_lossy().into_owned())
            .unwrap_or_default();
        (counters, message)
    };
    let label = if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::ERROR) {
        counters.errors.fetch_add(1, Ordering::SeqCst);
        "error"
    } else if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::WARNING) {
        counters.warnings.fetch_add(1, Ordering::SeqCst);
        "warning"
    } else {
        "info"
    };
    eprintln!("[vulkan {label} {types:?}] {message}");
    vk::FALSE
}

fn load_entry() -> Result<ash::Entry> {
    // SAFETY: loading the system Vulkan loader library; its initialisers are trusted.
    unsafe { ash::Entry::load() }.map_err(|_| {
        Error::Gpu("no Vulkan loader (libvulkan.so.1); install libvulkan1 and mesa-vulkan-drivers".into())
    })
}

fn device_type_rank(t: vk::PhysicalDeviceType) -> u32 {
    match t {
        vk::PhysicalDeviceType::DISCRETE_GPU => 0,
        vk::PhysicalDeviceType::INTEGRATED_GPU => 1,
        vk::PhysicalDeviceType::VIRTUAL_GPU => 2,
        vk::PhysicalDeviceType::CPU => 3,
        _ => 4,
    }
}

struct DeviceInfo {
    handle: vk::PhysicalDevice,
    name: String,
    props: vk::PhysicalDeviceProperties,
}

fn enumerate(instance: &ash::Instance) -> Result<Vec<DeviceInfo>> {
    // SAFETY: `instance` is a valid instance.
    let devices = unsafe { instance.enumerate_physical_devices() }
        .map_err(vk_err("vkEnumeratePhysicalDevices"))?;
    Ok(devices
        .into_iter()
        .map(|handle| {
            // SAFETY: `handle` was just enumerated from `instance`.
            let props = unsafe { instance.get_physical_device_properties(handle) };
            let name = props
                .device_name_as_c_str()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|_| "<unnamed>".into());
            DeviceInfo { handle, name, props }
        })
        .collect())
}

fn choose<'a>(devices: &'a [DeviceInfo], choice: &DeviceChoice) -> Result<&'a DeviceInfo> {
    let listing = || {
        devices
            .iter()
            .enumerate()
            .map(|(i, d)| format!("{i}: {} ({:?})", d.name, d.props.device_type))
            .collect::<Vec<_>>()
            .join(", ")
    };
    if devices.is_empty() {
        return Err(Error::Gpu("no Vulkan device found; install mesa-vulkan-drivers for lavapipe".into()));
    }
    let found = match choice {
        DeviceChoice::Auto => devices.iter().min_by_key(|d| device_type_rank(d.props.device_type)),
        DeviceChoice::Index(i) => devices.get(*i),
        DeviceChoice::Name(n) => {
            let n = n.to_lowercase();
            devices.iter().find(|d| d.name.to_lowercase().contains(&n))
        }
    };
    found.ok_or_else(|| Error::Gpu(format!("no Vulkan device matches {choice:?}; available: {}", listing())))
}

impl Context {
    /// Creates the context, with the validation layer if `options.validation`.
    pub fn new(options: &ContextOptions) -> Result<Context> {
        let validation = options.validation;
        let entry = load_entry()?;
        let counters = Box::new(Counters {
            errors: Arc::new(AtomicUsize::new(0)),
            warnings: Arc::new(AtomicUsize::new(0)),
        });

        let mut layers = Vec::new();
        let mut extensions = Vec::new();
        if validation {
            // SAFETY: plain query on a loaded entry.
            let available = unsafe { entry.enumerate_instance_layer_properties() }
                .map_err(vk_err("vkEnumerateInstanceLayerProperties"))?;
            let has_layer = available
                .iter()
                .any(|l| l.layer_name_as_c_str().map(|n| n == VALIDATION_LAYER).unwrap_or(false));
            if !has_layer {
                return Err(Error::Gpu(
                    "validation requested but VK_LAYER_KHRONOS_validation is not installed \
                     (Debian: apt install vulkan-validationlayers)"
                        .into(),
                ));
            }
            layers.push(VALIDATION_LAYER.as_ptr());
            extensions.push(ash::ext::debug_utils::NAME.as_ptr());
        }

        let severity = vk::DebugUtilsMessageSeverityFlagsEXT::ERROR | vk::DebugUtilsMessageSeverityFlagsEXT::WARNING;
        let types = vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
            | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
            | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE;
        let user_data = &*counters as *const Counters as *mut c_void;
        let mut messenger_info = vk::DebugUtilsMessengerCreateInfoEXT::default()
            .message_severity(severity)
            .message_type(types)
            .pfn_user_callback(Some(debug_callback))
            .user_data(user_data);

        let app = vk::ApplicationInfo::default()
            .application_name(c"pedscan")
            .engine_name(c"pedscan")
            .api_version(vk::API_VERSION_1_1);
        let mut instance_info = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_layer_names(&layers)
            .enabled_extension_names(&extensions);
        if validation {
            // Also catches messages from vkCreateInstance / vkDestroyInstance themselves.
            instance_info = instance_info.push_next(&mut messenger_info);
        }
        // SAFETY: all pointers in `instance_info` point at locals alive for the call.
        let instance = unsafe { entry.create_instance(&instance_info, None) }.map_err(vk_err("vkCreateInstance"))?;

        // From here on, a failure must destroy what exists: a partial context does it.
        let mut partial = Partial { instance: Some(instance.clone()), debug: None, device: None };
        let debug = if validation {
            let loader = ash::ext::debug_utils::Instance::new(&entry, &instance);
            let info = vk::DebugUtilsMessengerCreateInfoEXT::default()
                .message_severity(severity)
                .message_type(types)
                .pfn_user_callback(Some(debug_callback))
                .user_data(user_data);
            // SAFETY: the instance was created with VK_EXT_debug_utils enabled.
            let messenger = unsafe { loader.create_debug_utils_messenger(&info, None) }
                .map_err(vk_err("vkCreateDebugUtilsMessengerEXT"))?;
            partial.debug = Some(Debug { loader: loader.clone(), messenger });
            Some(Debug { loader, messenger })
        } else {
            None
        };

        let devices = enumerate(&instance)?;
        let chosen = choose(&devices, &options.device)?;
        let physical_device = chosen.handle;
        let device_name = chosen.name.clone();
        let device_type = chosen.props.device_type;
        let limits = chosen.props.limits;

        // SAFETY: valid physical device of `instance`.
        let families = unsafe { instance.get_physical_device_queue_family_properties(physical_device) };
        let queue_family = families
            .iter()
            .position(|f| f.queue_flags.contains(vk::QueueFlags::GRAPHICS))
            .ok_or_else(|| Error::Gpu(format!("{device_name} has no graphics queue")))? as u32;
        // SAFETY: valid physical device of `instance`.
        let supported = unsafe { instance.get_physical_device_features(physical_device) };
        if supported.geometry_shader == vk::FALSE {
            // gl_PrimitiveID in a fragment shader needs the Geometry capability.
            return Err(Error::Gpu(format!("{device_name} lacks the geometryShader feature (gl_PrimitiveID)")));
        }
        let features = vk::PhysicalDeviceFeatures::default().geometry_shader(true);
        let priorities = [1.0f32];
        let queue_infos =
            [vk::DeviceQueueCreateInfo::default().queue_family_index(queue_family).queue_priorities(&priorities)];
        let device_info =
            vk::DeviceCreateInfo::default().queue_create_infos(&queue_infos).enabled_features(&features);
        // SAFETY: the create info points at locals alive for the call.
        let device = unsafe { instance.create_device(physical_device, &device_info, None) }
            .map_err(vk_err("vkCreateDevice"))?;
        partial.device = Some(device.clone());
        // SAFETY: queue 0 of a family requested above.
        let queue = unsafe { device.get_device_queue(queue_family, 0) };

        let allocator = Allocator::new(&AllocatorCreateDesc {
            instance: instance.clone(),
            device: device.clone(),
            physical_device,
            debug_settings: Default::default(),
            buffer_device_address: false,
            allocation_sizes: Default::default(),
        })
        .map_err(alloc_err("the memory allocator"))?;

        // Success: ownership moves to the context.
        std::mem::forget(partial);
        Ok(Context {
            _entry: entry,
            instance,
            debug,
            counters,
            physical_device,
            device_name,
            device_type,
            limits,
            device,
            queue_family,
            queue: Mutex::new(queue),
            allocator: ManuallyDrop::new(Mutex::new(allocator)),
        })
    }

    /// Names of all Vulkan devices, in `DeviceChoice::Index` order.
    pub fn list_devices() -> Result<Vec<String>> {
        let entry = load_entry()?;
        let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_1);
        let info = vk::InstanceCreateInfo::default().application_info(&app);
        // SAFETY: the create info points at locals alive for the call.
        let instance = unsafe { entry.create_instance(&info, None) }.map_err(vk_err("vkCreateInstance"))?;
        let names = enumerate(&instance).map(|d| d.into_iter().map(|d| d.name).collect());
        // SAFETY: nothing was created from this instance.
        unsafe { instance.destroy_instance(None) };
        names
    }

    /// The chosen device's name, e.g. `llvmpipe (LLVM 15.0.6, 256 bits)`.
    pub fn device_name(&self) -> String {
        self.device_name.clone()
    }

    /// True when the device is a CPU implementation (lavapipe, SwiftShader).
    pub fn is_cpu(&self) -> bool {
        self.device_type == vk::PhysicalDeviceType::CPU
    }

    /// Whether the validation layer is on.
    pub fn validation_enabled(&self) -> bool {
        self.debug.is_some()
    }

    /// Validation errors reported so far (0 when validation is off).
    pub fn validation_errors(&self) -> usize {
        self.counters.errors.load(Ordering::SeqCst)
    }

    /// Validation warnings reported so far.
    pub fn validation_warnings(&self) -> usize {
        self.counters.warnings.load(Ordering::SeqCst)
    }

    /// The error counter itself; still counts while the context is dropped (leaks reported at
    /// `vkDestroyDevice` are errors too), so tests read it after dropping everything.
    pub fn validation_counter(&self) -> Arc<AtomicUsize> {
        self.counters.errors.clone()
    }

    /// The warning counter (see [`Context::validation_counter`]).
    pub fn validation_warning_counter(&self) -> Arc<AtomicUsize> {
        self.counters.warnings.clone()
    }

    pub fn device(&self) -> &ash::Device {
        &self.device
    }

    pub fn physical_device(&self) -> vk::PhysicalDevice {
        self.physical_device
    }

    pub fn limits(&self) -> &vk::PhysicalDeviceLimits {
        &self.limits
    }

    pub fn queue_family(&self) -> u32 {
        self.queue_family
    }

    /// The allocator, locked.
    pub fn allocator(&self) -> MutexGuard<'_, Allocator> {
        self.allocator.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Submits one command buffer to the queue, signalling `fence`.
    pub fn submit(&self, commands: vk::CommandBuffer, fence: vk::Fence) -> Result<()> {
        let queue = self.queue.lock().unwrap_or_else(|e| e.into_inner());
        let buffers = [commands];
        let submit = [vk::SubmitInfo::default().command_buffers(&buffers)];
        // SAFETY: the queue is externally synchronised by the mutex; the caller passes a
        // recorded command buffer and an unsignalled fence of this device.
        unsafe { self.device.queue_submit(*queue, &submit, fence) }.map_err(vk_err("vkQueueSubmit"))
    }

    /// Waits until the device is idle.
    pub fn wait_idle(&self) -> Result<()> {
        let _queue = self.queue.lock().unwrap_or_else(|e| e.into_inner());
        // SAFETY: the device is valid; queue access is serialised by holding the queue lock.
        unsafe { self.device.device_wait_idle() }.map_err(vk_err("vkDeviceWaitIdle"))
    }
}

impl Drop for Context {
    fn drop(&mut self) {
        // SAFETY: every object created from this context holds an `Arc<Context>`, so none is
        // alive any more; the order is: idle, allocator, device, messenger, instance.
        unsafe {
            let _ = self.device.device_wait_idle();
            ManuallyDrop::drop(&mut self.allocator);
            self.device.destroy_device(None);
            if let Some(debug) = self.debug.take() {
                debug.loader.destroy_debug_utils_messenger(debug.messenger, None);
            }
            self.instance.destroy_instance(None);
        }
        // `counters` is dropped after this body, i.e. after the instance is gone.
    }
}

/// Cleans up a half-built context when `Context::new` fails part-way.
struct Partial {
    instance: Option<ash::Instance>,
    debug: Option<Debug>,
    device: Option<ash::Device>,
}

impl Drop for Partial {
    fn drop(&mut self) {
        // SAFETY: these handles were created by `Context::new` and nothing else uses them.
        unsafe {
            if let Some(device) = self.device.take() {
                device.destroy_device(None);
            }
            if let Some(debug) = self.debug.take() {
                debug.loader.destroy_debug_utils_messenger(debug.messenger, None);
            }
            if let Some(instance) = self.instance.take() {
                instance.destroy_instance(None);
            }
        }
    }
}
