//! Device selection and set-up.
//!
//! - Backends: Vulkan, Metal and DX12. The GL backend is left out on purpose: on
//!   llvmpipe it writes only slice 0 of a 3D storage texture.
//! - Adapter choice: `VOXLAB_ADAPTER=<substring>` picks the first adapter whose name
//!   contains the substring (case-insensitive); otherwise discrete GPUs come first,
//!   then integrated, then virtual, then CPU (lavapipe).
//! - Limits: the adapter's own (`adapter.limits()`), not wgpu's conservative defaults
//!   (which cap storage bindings at 128 MiB).
//! - Optional features requested when present: `FLOAT32_FILTERABLE` (hardware
//!   filtering of R32Float textures), `TEXTURE_FORMAT_16BIT_NORM`, `TIMESTAMP_QUERY`.
//! - No adapter ⇒ [`Error::NoAdapter`] whose message says how to get one.

use crate::error::{Error, Result};

/// The backends voxlab uses.
pub const BACKENDS: wgpu::Backends = wgpu::Backends::VULKAN
    .union(wgpu::Backends::METAL)
    .union(wgpu::Backends::DX12);

/// What to tell a user who has no adapter.
pub const NO_ADAPTER_HELP: &str = "voxlab needs a Vulkan, Metal or DX12 adapter. \
On Linux without a GPU, install Mesa's software Vulkan driver (lavapipe): \
`apt-get install mesa-vulkan-drivers` (Debian/Ubuntu). \
Set VOXLAB_ADAPTER=<name substring> to choose among several adapters.";

/// A printable description of an adapter.
#[derive(Clone, Debug, serde::Serialize)]
pub struct AdapterSummary {
    pub name: String,
    pub backend: String,
    pub device_type: String,
    pub driver: String,
    pub driver_info: String,
    pub vendor: u32,
    pub device: u32,
}

impl AdapterSummary {
    fn from_info(i: &wgpu::AdapterInfo) -> Self {
        AdapterSummary {
            name: i.name.clone(),
            backend: format!("{:?}", i.backend),
            device_type: format!("{:?}", i.device_type),
            driver: i.driver.clone(),
            driver_info: i.driver_info.clone(),
            vendor: i.vendor,
            device: i.device,
        }
    }
    /// Whether this is a CPU implementation (lavapipe, SwiftShader, WARP).
    pub fn is_cpu(&self) -> bool {
        self.device_type == "Cpu"
    }
}

/// An open device, its queue, and what the adapter offers.
pub struct GpuContext {
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub summary: AdapterSummary,
    pub limits: wgpu::Limits,
    pub features: wgpu::Features,
}

fn instance() -> wgpu::Instance {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = BACKENDS;
    wgpu::Instance::new(desc)
}

fn type_rank(t: wgpu::DeviceType) -> u8 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Other => 3,
        wgpu::DeviceType::Cpu => 4,
    }
}

/// Every adapter on the voxlab backends, best first.
pub fn list_adapters() -> Vec<AdapterSummary> {
    let mut adapters = pollster::block_on(instance().enumerate_adapters(BACKENDS));
    adapters.sort_by_key(|a| type_rank(a.get_info().device_type));
    adapters
        .iter()
        .map(|a| AdapterSummary::from_info(&a.get_info()))
        .collect()
}

impl GpuContext {
    /// Opens the best adapter (or the one `VOXLAB_ADAPTER` names).
    pub fn new() -> Result<Self> {
        let wanted = std::env::var("VOXLAB_ADAPTER")
            .ok()
            .filter(|s| !s.is_empty());
        let mut adapters = pollster::block_on(instance().enumerate_adapters(BACKENDS));
        adapters.sort_by_key(|a| type_rank(a.get_info().device_type));
        let adapter = match &wanted {
            Some(w) => {
                let needle = w.to_lowercase();
                let names: Vec<String> = adapters.iter().map(|a| a.get_info().name).collect();
                adapters
                    .into_iter()
                    .find(|a| a.get_info().name.to_lowercase().contains(&needle))
                    .ok_or_else(|| {
                        Error::NoAdapter(format!(
                            "VOXLAB_ADAPTER='{w}' matches none of {names:?}. {NO_ADAPTER_HELP}"
                        ))
                    })?
            }
            None => adapters
                .into_iter()
                .next()
                .ok_or_else(|| Error::NoAdapter(NO_ADAPTER_HELP.to_string()))?,
        };
        let offered = adapter.features();
        let features = offered
            & (wgpu::Features::FLOAT32_FILTERABLE
                | wgpu::Features::TEXTURE_FORMAT_16BIT_NORM
                | wgpu::Features::TIMESTAMP_QUERY);
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("voxlab"),
            required_features: features,
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| Error::Gpu(format!("could not open the device: {e}")))?;
        let summary = AdapterSummary::from_info(&adapter.get_info());
        Ok(GpuContext {
            adapter,
            device,
            queue,
            summary,
            limits,
            features,
        })
    }

    /// A multi-line report: adapter, backend, driver, the limits that matter to
    /// voxlab, and the optional features.
    pub fn describe(&self) -> String {
        let s = &self.summary;
        let l = &self.limits;
        let f = |x: wgpu::Features| {
            if self.features.contains(x) {
                "yes"
            } else {
                "no"
            }
        };
        format!(
            "adapter:      {}\nbackend:      {}\ntype:         {}{}\ndriver:       {} ({})\n\
             vendor/device: {:#06x}/{:#06x}\n\
             limits:       3D texture {} per axis, storage binding {} MiB, buffer {} MiB,\n              \
             workgroup {} invocations ({}×{}×{}), {} KiB workgroup memory\n\
             features:     FLOAT32_FILTERABLE {}, TEXTURE_FORMAT_16BIT_NORM {}, TIMESTAMP_QUERY {}",
            s.name,
            s.backend,
            s.device_type,
            if s.is_cpu() { " (a CPU emulating a GPU)" } else { "" },
            s.driver,
            s.driver_info,
            s.vendor,
            s.device,
            l.max_texture_dimension_3d,
            l.max_storage_buffer_binding_size >> 20,
            l.max_buffer_size >> 20,
            l.max_compute_invocations_per_workgroup,
            l.max_compute_workgroup_size_x,
            l.max_compute_workgroup_size_y,
            l.max_compute_workgroup_size_z,
            l.max_compute_workgroup_storage_size >> 10,
            f(wgpu::Features::FLOAT32_FILTERABLE),
            f(wgpu::Features::TEXTURE_FORMAT_16BIT_NORM),
            f(wgpu::Features::TIMESTAMP_QUERY),
        )
    }

    /// Compiles WGSL, turning validation errors into [`Error::Gpu`] with the message.
    pub fn shader(&self, label: &str, source: &str) -> Result<wgpu::ShaderModule> {
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = self
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            });
        match pollster::block_on(scope.pop()) {
            None => Ok(module),
            Some(e) => Err(Error::Gpu(format!("shader {label} failed to compile: {e}"))),
        }
    }

    /// Waits for all submitted work; device loss becomes [`Error::Gpu`].
    pub fn wait(&self) -> Result<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| Error::Gpu(format!("waiting for the device failed: {e}")))
    }

    /// Copies a buffer back to the host (the buffer needs `COPY_SRC`).
    pub fn read_buffer(&self, src: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>> {
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(src, 0, &staging, 0, bytes);
        self.queue.submit([enc.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        self.wait()?;
        rx.recv()
            .map_err(|_| Error::Gpu("readback callback never ran".into()))?
            .map_err(|e| Error::Gpu(format!("mapping the readback buffer failed: {e}")))?;
        let view = staging
            .get_mapped_range(..)
            .map_err(|e| Error::Gpu(format!("reading the mapped buffer failed: {e}")))?;
        let out = view.to_vec();
        drop(view);
        staging.unmap();
        Ok(out)
    }
}
