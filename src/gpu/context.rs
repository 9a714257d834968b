//! Device selection and set-up.
//!
//! - Backends: Vulkan, Metal and DX12. The GL backend is left out on purpose: on
//!   llvmpipe it writes only slice 0 of a 3D storage texture.
//! - Adapter choice: `VOXLAB_ADAPTER=<substring>` picks the first adapter whose name
//!   contains the substring (case-insensitive); otherwise discrete GPUs come first,
//!   then integrated, then virtual, then CPU (lavapipe).
//! - Limits: the adapter's own (`adapter.limits()`), not wgpu's conservative defaults
//!   (which cap storage bindings at 128 MiB). The device is opened with them; the
//!   context's [`GpuContext::limits`], which every job plans against, are those lowered
//!   by `VOXLAB_GPU_MAX_BINDING` and `VOXLAB_GPU_MAX_TEXTURE_3D` ([`super::plan`]).
//! - Optional features requested when present ([`OPTIONAL_FEATURES`]):
//!   `FLOAT32_FILTERABLE` (hardware filtering of R32Float textures),
//!   `TEXTURE_FORMAT_16BIT_NORM` (16-bit volume textures), `TIMESTAMP_QUERY` (kernel
//!   times). `VOXLAB_GPU_WITHOUT=NAME,…` ([`WITHOUT_ENV`]) withholds some of them, so
//!   that an adapter that has them (lavapipe has all three) also runs the paths of one
//!   that lacks them: the refusals and the fallbacks.
//! - No adapter ⇒ [`Error::NoAdapter`] whose message says how to get one.
//!
//! Also the plumbing every family shares, so that families import it from here and
//! never from each other: [`GpuContext::program`] and [`GpuContext::kernel`] (compiled
//! pipelines the device keeps for every job, their validation errors typed), the
//! bind-group-layout entries [`buffer_entry`] and
//! [`texture_entry`], [`LLVMPIPE_LOOP_LIMIT`], and the row-band loop of the per-pixel
//! casters (`render_bands`: the ray caster, the adaptive and the multi-volume casters).
//! The WGSL itself is assembled by `gpu::shaders`.

use crate::camera::PixelRect;
use crate::error::{Error, Result};
use crate::frame::Frame;
use std::sync::OnceLock;
use std::time::Instant;

/// The backends voxlab uses.
pub const BACKENDS: wgpu::Backends = wgpu::Backends::VULKAN
    .union(wgpu::Backends::METAL)
    .union(wgpu::Backends::DX12);

/// What to tell a user who has no adapter.
pub const NO_ADAPTER_HELP: &str = "voxlab needs a Vulkan, Metal or DX12 adapter. \
On Linux without a GPU, install Mesa's software Vulkan driver (lavapipe): \
`apt-get install mesa-vulkan-drivers` (Debian/Ubuntu). \
Set VOXLAB_ADAPTER=<name substring> to choose among several adapters.";

/// The optional features voxlab asks for where the adapter offers them, by the names
/// [`WITHOUT_ENV`] takes. Each has a fallback or a clear refusal where it is missing.
pub const OPTIONAL_FEATURES: [(&str, wgpu::Features); 3] = [
    ("FLOAT32_FILTERABLE", wgpu::Features::FLOAT32_FILTERABLE),
    (
        "TEXTURE_FORMAT_16BIT_NORM",
        wgpu::Features::TEXTURE_FORMAT_16BIT_NORM,
    ),
    ("TIMESTAMP_QUERY", wgpu::Features::TIMESTAMP_QUERY),
];

/// The environment variable that withholds optional features from the device: names
/// of [`OPTIONAL_FEATURES`], separated by commas or spaces.
pub const WITHOUT_ENV: &str = "VOXLAB_GPU_WITHOUT";

/// The optional features `text` (a [`WITHOUT_ENV`] value) names: case-insensitive,
/// separated by commas or spaces; empty for an empty text.
///
/// # Errors
/// [`Error::Invalid`] naming the variable and the known names, for any other word.
pub fn withheld_features(text: &str) -> Result<wgpu::Features> {
    let mut withheld = wgpu::Features::empty();
    for word in text.split([',', ' ']).filter(|w| !w.trim().is_empty()) {
        let word = word.trim();
        let (_, f) = OPTIONAL_FEATURES
            .iter()
            .find(|(name, _)| name.eq_ignore_ascii_case(word))
            .ok_or_else(|| {
                let names: Vec<&str> = OPTIONAL_FEATURES.iter().map(|(n, _)| *n).collect();
                Error::invalid(
                    WITHOUT_ENV,
                    format!("'{word}' is not one of {}", names.join(", ")),
                )
            })?;
        withheld |= *f;
    }
    Ok(withheld)
}

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
    /// The limits jobs plan against: the adapter's, lowered by the planner's
    /// environment variables ([`super::plan::lowered_limits`]).
    pub limits: wgpu::Limits,
    /// The adapter's own limits, which the device was opened with.
    pub adapter_limits: wgpu::Limits,
    /// One line per limit the environment lowered or feature it withheld (empty when
    /// none).
    pub lowered: Vec<String>,
    /// The optional features the device was opened with: the adapter's, less those
    /// [`WITHOUT_ENV`] withholds.
    pub features: wgpu::Features,
    /// The device memory a job may fill at once, where known
    /// ([`super::plan::DeviceMemory`]).
    pub memory: Option<super::plan::DeviceMemory>,
    /// Whether the shaders' parameter blocks are bound as read-only storage buffers
    /// instead of uniform buffers: on a CPU adapter (see [`GpuContext::shader`]).
    pub params_in_storage: bool,
    /// Objects costly to make that every job on the device may share
    /// ([`GpuContext::kept`]).
    kept: std::sync::Mutex<(Vec<(String, Kept)>, usize)>,
}

/// An object [`GpuContext::kept`] holds.
type Kept = std::sync::Arc<dyn std::any::Any + Send + Sync>;

/// How many objects [`GpuContext::kept`] holds; the least recently used goes first.
pub const KEPT_OBJECTS: usize = 64;

/// A WGSL module and the bind group (group 0) its entry points bind, kept by the device
/// for every job ([`GpuContext::program`]); each entry point's pipeline is compiled on
/// its first use and kept with it ([`Program::kernel`]). A job asks for its program
/// every time it runs and compiles only what no job on the device compiled before.
pub struct Program {
    label: String,
    module: wgpu::ShaderModule,
    /// The listed layout every entry point binds; `None`: each pipeline's layout is
    /// derived from its entry point's bindings.
    layout: Option<wgpu::BindGroupLayout>,
    kernels: std::sync::Mutex<Vec<(String, Kernel)>>,
}

/// One entry point's compute pipeline and the layout its bind groups are made over.
#[derive(Clone, Debug)]
pub struct Kernel {
    pub pipeline: wgpu::ComputePipeline,
    pub layout: wgpu::BindGroupLayout,
}

impl Program {
    /// The pipeline of `entry` and its bind group layout, compiled now when no job
    /// asked for it before (then `true`).
    ///
    /// # Errors
    /// [`Error::Gpu`] when the pipeline fails validation (a missing entry point, a
    /// binding the layout lacks).
    pub fn kernel(&self, ctx: &GpuContext, entry: &str) -> Result<(Kernel, bool)> {
        let mut kernels = self.kernels.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, k)) = kernels.iter().find(|(e, _)| e == entry) {
            return Ok((k.clone(), false));
        }
        let label = format!("{} {entry}", self.label);
        let kernel = compute_pipeline(ctx, &label, &self.module, entry, self.layout.as_ref())?;
        ctx.kept.lock().unwrap_or_else(|e| e.into_inner()).1 += 1;
        kernels.push((entry.to_string(), kernel.clone()));
        Ok((kernel, true))
    }
}

/// The usage of every parameter block's buffer: bound as a uniform buffer, or as a
/// read-only storage buffer where [`GpuContext::params_in_storage`].
pub const PARAMS_USAGE: wgpu::BufferUsages =
    wgpu::BufferUsages::UNIFORM.union(wgpu::BufferUsages::STORAGE);

/// The process's one wgpu instance. It is created once and never dropped: on NVIDIA's
/// Vulkan driver, destroying an instance on one thread while another thread opens or
/// uses a device crashed the process (the driver library was unloaded under it).
fn instance() -> &'static wgpu::Instance {
    static INSTANCE: OnceLock<wgpu::Instance> = OnceLock::new();
    INSTANCE.get_or_init(|| {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = BACKENDS;
        wgpu::Instance::new(desc)
    })
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
    /// The process's wgpu instance, which every context's adapter comes from: for a
    /// window that presents on the same device (`voxlab view`).
    pub fn instance() -> &'static wgpu::Instance {
        instance()
    }

    /// The process-wide context: opened on first use, then shared by every caller and
    /// never closed. Prefer it to [`GpuContext::new`] where many computations run in
    /// one process (tests, benchmarks): drivers cap how many devices a process may
    /// open, and NVIDIA's refused new ones after a few dozen had been opened and
    /// closed.
    pub fn shared() -> Result<&'static GpuContext> {
        static SHARED: OnceLock<std::result::Result<GpuContext, Error>> = OnceLock::new();
        match SHARED.get_or_init(GpuContext::new) {
            Ok(ctx) => Ok(ctx),
            Err(Error::NoAdapter(m)) => Err(Error::NoAdapter(m.clone())),
            Err(e) => Err(Error::Gpu(e.to_string())),
        }
    }

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
        let optional = OPTIONAL_FEATURES
            .iter()
            .fold(wgpu::Features::empty(), |all, (_, f)| all | *f);
        let offered = adapter.features() & optional;
        let withheld = withheld_features(&std::env::var(WITHOUT_ENV).unwrap_or_default())?;
        let features = offered - withheld;
        let adapter_limits = adapter.limits();
        let (limits, mut lowered) =
            super::plan::lowered_limits(&adapter_limits, |k| std::env::var(k).ok())?;
        for (name, f) in OPTIONAL_FEATURES {
            if offered.contains(f) && withheld.contains(f) {
                lowered.push(format!(
                    "{name} withheld by {WITHOUT_ENV} (the adapter has it)"
                ));
            }
        }
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("voxlab"),
            required_features: features,
            required_limits: adapter_limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| Error::Gpu(format!("could not open the device: {e}")))?;
        let summary = AdapterSummary::from_info(&adapter.get_info());
        let summary_is_cpu = summary.is_cpu();
        let sheet = super::peak::peak_of(&summary.name).map(|p| (p.part, p.memory_gb));
        let (memory, note) = super::plan::device_memory(sheet, |k| std::env::var(k).ok())?;
        lowered.extend(note);
        let (limits, note) = super::plan::binding_within_memory(limits, memory.as_ref());
        lowered.extend(note);
        Ok(GpuContext {
            adapter,
            device,
            queue,
            summary,
            limits,
            adapter_limits,
            lowered,
            features,
            memory,
            params_in_storage: summary_is_cpu,
            kept: Default::default(),
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
             limits:       3D texture {} per axis, storage binding {}, buffer {},\n              \
             workgroup {} invocations ({}×{}×{}), {} KiB workgroup memory\n\
             memory:       {}\n\
             features:     FLOAT32_FILTERABLE {}, TEXTURE_FORMAT_16BIT_NORM {}, TIMESTAMP_QUERY {}",
            s.name,
            s.backend,
            s.device_type,
            if s.is_cpu() {
                " (a CPU emulating a GPU)"
            } else {
                ""
            },
            s.driver,
            s.driver_info,
            s.vendor,
            s.device,
            l.max_texture_dimension_3d,
            super::plan::human_bytes(l.max_storage_buffer_binding_size),
            super::plan::human_bytes(l.max_buffer_size),
            l.max_compute_invocations_per_workgroup,
            l.max_compute_workgroup_size_x,
            l.max_compute_workgroup_size_y,
            l.max_compute_workgroup_size_z,
            l.max_compute_workgroup_storage_size >> 10,
            match &self.memory {
                Some(m) => format!(
                    "{} for a job ({})",
                    super::plan::human_bytes(m.bytes),
                    m.source
                ),
                None => format!(
                    "not known (wgpu does not report it; {} sets what a job may fill)",
                    super::plan::MEMORY_ENV
                ),
            },
            f(wgpu::Features::FLOAT32_FILTERABLE),
            f(wgpu::Features::TEXTURE_FORMAT_16BIT_NORM),
            f(wgpu::Features::TIMESTAMP_QUERY),
        ) + &self
            .lowered
            .iter()
            .map(|l| format!("\nplanner:      {l}"))
            .collect::<String>()
    }

    /// A sampler that clamps to the edge on every axis and filters with `filter`
    /// (the texture unit's trilinear or bilinear filter with `Linear`).
    pub fn clamp_sampler(&self, label: &str, filter: wgpu::FilterMode) -> wgpu::Sampler {
        self.device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some(label),
            address_mode_u: wgpu::AddressMode::ClampToEdge,
            address_mode_v: wgpu::AddressMode::ClampToEdge,
            address_mode_w: wgpu::AddressMode::ClampToEdge,
            mag_filter: filter,
            min_filter: filter,
            ..Default::default()
        })
    }

    /// Refuses, with [`Error::Gpu`], an adapter whose texture unit cannot filter f32
    /// textures (`FLOAT32_FILTERABLE`): every hardware-filtering path asks first, in its
    /// run and in its job's `--dry-run` plan.
    pub fn require_float32_filtering(&self) -> Result<()> {
        self.require_filtering(
            super::plan::Sampling::Hardware,
            wgpu::TextureFormat::R32Float,
        )
    }

    /// Refuses, with [`Error::Gpu`], [`Sampling::Hardware`](super::plan::Sampling) of
    /// `format` texels on a device that cannot filter them: `R32Float` needs
    /// `FLOAT32_FILTERABLE`; `R16Float` filters everywhere. The exact sampling reads
    /// storage buffers and needs nothing.
    pub fn require_filtering(
        &self,
        sampling: super::plan::Sampling,
        format: wgpu::TextureFormat,
    ) -> Result<()> {
        let filterable = wgpu::TextureSampleType::Float { filterable: true };
        if sampling == super::plan::Sampling::Exact
            || format.sample_type(None, Some(self.features)) == Some(filterable)
        {
            return Ok(());
        }
        Err(Error::Gpu(format!(
            "hardware filtering of {format:?} textures needs the FLOAT32_FILTERABLE \
             feature, which this device lacks{}",
            if self
                .lowered
                .iter()
                .any(|l| l.starts_with("FLOAT32_FILTERABLE withheld"))
            {
                format!(" ({WITHOUT_ENV} withholds it)")
            } else {
                String::new()
            }
        )))
    }

    /// Compiles WGSL, turning validation errors into [`Error::Gpu`] with the message.
    ///
    /// Where [`GpuContext::params_in_storage`], every `var<uniform>` becomes a
    /// `var<storage, read>` (the same layout: WGSL lays a struct out alike in both
    /// address spaces, the uniform one only adds rules, which naga checks on the
    /// shaders as written). Lavapipe compiles a shader again, with the values inlined,
    /// whenever a uniform block its loops read is bound, and keeps every such copy
    /// (about 1.5 MiB for the ray caster) until the process ends: one per frame of a
    /// renderer session, one per band of rows. It does not do that for storage
    /// buffers. Layouts made by [`GpuContext::bind_group_layout`] and buffers made with
    /// [`PARAMS_USAGE`] follow.
    pub fn shader(&self, label: &str, source: &str) -> Result<wgpu::ShaderModule> {
        let source = if self.params_in_storage {
            source.replace("var<uniform>", "var<storage, read>")
        } else {
            source.to_string()
        };
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

    /// The object kept under `key` for every job on this device, made by `make` when
    /// it is not there (then `true`); at most [`KEPT_OBJECTS`] are kept, the least
    /// recently used dropped first (those in use live on). For what is costly to make
    /// and the same for every job that asks: the compiled programs
    /// ([`GpuContext::program`]), so that a second job (a one-shot render, a brick, a
    /// call from Python) compiles nothing the first did, and the ray caster's sampler
    /// and placeholder texture. The key must name everything the object depends on,
    /// [`GpuContext::params_in_storage`] included. One thread makes at a time.
    pub fn kept<T: std::any::Any + Send + Sync>(
        &self,
        key: &str,
        make: impl FnOnce() -> Result<T>,
    ) -> Result<(std::sync::Arc<T>, bool)> {
        let mut guard = self.kept.lock().unwrap_or_else(|e| e.into_inner());
        let (kept, made) = &mut *guard;
        if let Some(i) = kept.iter().position(|(k, _)| k == key) {
            let hit = kept.remove(i);
            kept.push(hit);
            if let Ok(t) = kept[kept.len() - 1].1.clone().downcast::<T>() {
                return Ok((t, false));
            }
            kept.pop();
        }
        let t = std::sync::Arc::new(make()?);
        *made += 1;
        if kept.len() >= KEPT_OBJECTS {
            kept.remove(0);
        }
        kept.push((key.to_string(), t.clone()));
        Ok((t, true))
    }

    /// The program of the WGSL `source` (see [`GpuContext::shader`]) over the bind
    /// group layout of `entries` ([`GpuContext::bind_group_layout`]), or, with `None`,
    /// over the layouts its entry points' bindings imply; kept by the device
    /// ([`GpuContext::kept`], keyed by `label`, the layout and the whole source), its
    /// pipelines compiled by [`Program::kernel`] as they are first asked for.
    ///
    /// # Errors
    /// [`Error::Gpu`] when the shader does not compile.
    pub fn program(
        &self,
        label: &str,
        source: &str,
        entries: Option<&[wgpu::BindGroupLayoutEntry]>,
    ) -> Result<std::sync::Arc<Program>> {
        let key = format!(
            "program {label}, {}, {entries:?}\n{source}",
            self.params_in_storage
        );
        let (program, _) = self.kept(&key, || {
            Ok(Program {
                label: label.to_string(),
                module: self.shader(label, source)?,
                layout: entries.map(|entries| {
                    self.bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                        label: Some(label),
                        entries,
                    })
                }),
                kernels: Default::default(),
            })
        })?;
        Ok(program)
    }

    /// The pipeline of `entry` in [`GpuContext::program`]`(label, source, entries)`,
    /// and the layout its bind groups are made over.
    ///
    /// # Errors
    /// [`Error::Gpu`] when the shader does not compile or the pipeline fails
    /// validation.
    pub fn kernel(
        &self,
        label: &str,
        source: &str,
        entries: Option<&[wgpu::BindGroupLayoutEntry]>,
        entry: &str,
    ) -> Result<Kernel> {
        Ok(self.program(label, source, entries)?.kernel(self, entry)?.0)
    }

    /// How many objects [`GpuContext::kept`] has made on this device so far (those it
    /// found kept are not counted), with the pipelines kept programs compiled
    /// ([`Program::kernel`]).
    pub fn kept_made(&self) -> usize {
        self.kept.lock().unwrap_or_else(|e| e.into_inner()).1
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

/// A pair of timestamp queries around one compute pass, resolved into a buffer.
pub struct TimestampPair {
    pub set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
}

impl TimestampPair {
    /// The writes that put the first timestamp at the start of a compute pass and the
    /// second at its end.
    pub fn pass_writes(&self) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            query_set: &self.set,
            beginning_of_pass_write_index: Some(0),
            end_of_pass_write_index: Some(1),
        }
    }

    /// Resolves the two timestamps (call after the pass, in the same encoder).
    pub fn resolve(&self, enc: &mut wgpu::CommandEncoder) {
        enc.resolve_query_set(&self.set, 0..2, &self.resolved, 0);
    }
    /// The time between the two timestamps, once the submission has completed.
    pub fn seconds(&self, ctx: &GpuContext) -> Result<f64> {
        let bytes = ctx.read_buffer(&self.resolved, 16)?;
        let t: &[u64] = bytemuck::cast_slice(&bytes);
        let ticks = t[1].saturating_sub(t[0]);
        Ok(ticks as f64 * ctx.queue.get_timestamp_period() as f64 * 1e-9)
    }
}

impl GpuContext {
    /// Refuses a storage buffer of `bytes` (called `label` in the error) that exceeds
    /// one binding under the planner's limits ([`crate::gpu::plan::binding_limit`]),
    /// before anything is allocated; plans call it too.
    ///
    /// # Errors
    /// [`Error::TooLarge`] naming `label`, the bytes and the limit.
    pub fn check_storage(&self, label: &str, bytes: u64) -> Result<()> {
        let limit = crate::gpu::plan::binding_limit(&self.limits);
        if bytes > limit {
            // Where the planner lowered the limit, the line saying why.
            let lowered = match self
                .lowered
                .iter()
                .find(|l| l.starts_with("storage binding lowered"))
            {
                Some(why) => format!(" ({why})"),
                None => String::new(),
            };
            return Err(Error::too_large(
                label,
                format!(
                    "{bytes} bytes exceed the adapter's storage-binding limit of {limit} \
                     bytes{lowered}"
                ),
            ));
        }
        Ok(())
    }

    /// Refuses `bytes` held on the device at once (called `label` in the error) past the
    /// device memory the planner lets a job fill ([`GpuContext::memory`]), before
    /// anything is allocated; nothing is refused where the memory is not known.
    ///
    /// # Errors
    /// [`Error::TooLarge`] naming `label`, the bytes, the memory and where its figure
    /// comes from.
    pub fn check_memory(&self, label: &str, bytes: u64) -> Result<()> {
        match &self.memory {
            Some(m) if bytes > m.bytes => Err(Error::too_large(
                label,
                format!(
                    "{} on the device exceed the {} of device memory a job may fill ({})",
                    crate::gpu::plan::human_bytes(bytes),
                    crate::gpu::plan::human_bytes(m.bytes),
                    m.source
                ),
            )),
            _ => Ok(()),
        }
    }

    /// A storage buffer the host can read back (and write), refused with a clear error
    /// when it exceeds the adapter's limits.
    pub fn storage_buffer(&self, label: &str, bytes: u64) -> Result<wgpu::Buffer> {
        self.check_storage(label, bytes)?;
        Ok(self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes.max(4),
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        }))
    }

    fn texture_3d(
        &self,
        label: &str,
        dims: [usize; 3],
        format: wgpu::TextureFormat,
        usage: wgpu::TextureUsages,
    ) -> Result<wgpu::Texture> {
        self.check_texture_3d(label, dims)?;
        self.new_texture(label, dims, wgpu::TextureDimension::D3, format, usage)
    }

    /// Refuses a 3-D texture of `dims` texels (called `label` in the error) past the
    /// planner's 3-D texture limit, before anything is allocated; plans call it too.
    ///
    /// # Errors
    /// [`Error::TooLarge`] naming `label`, the dimensions and the limit.
    pub fn check_texture_3d(&self, label: &str, dims: [usize; 3]) -> Result<()> {
        let max = self.limits.max_texture_dimension_3d as usize;
        if dims.iter().any(|&n| n == 0 || n > max) {
            return Err(Error::too_large(
                label,
                format!("{dims:?}: a 3D texture holds 1 … {max} texels per axis on this adapter"),
            ));
        }
        Ok(())
    }

    /// Reads a 3-D texture of `dims` texels of `texel` bytes back to the host (x fastest,
    /// rows unpadded). The texture needs `COPY_SRC`.
    ///
    /// # Errors
    /// [`Error::Gpu`] when the readback fails.
    pub fn read_texture_3d(
        &self,
        tex: &wgpu::Texture,
        dims: [usize; 3],
        texel: usize,
    ) -> Result<Vec<u8>> {
        let row = dims[0] * texel;
        let padded = row.div_ceil(256) * 256;
        let bytes = (padded * dims[1] * dims[2]) as u64;
        let buf = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("texture readback"),
            size: bytes.max(4),
            usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: tex,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &buf,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded as u32),
                    rows_per_image: Some(dims[1] as u32),
                },
            },
            wgpu::Extent3d {
                width: dims[0] as u32,
                height: dims[1] as u32,
                depth_or_array_layers: dims[2] as u32,
            },
        );
        self.queue.submit([enc.finish()]);
        let data = self.read_buffer(&buf, bytes)?;
        Ok(data
            .chunks(padded)
            .flat_map(|r| &r[..row])
            .copied()
            .collect())
    }

    /// A texture of one mip level, refused with [`Error::Gpu`] when the device is out
    /// of memory (the caller checked the size limits).
    fn new_texture(
        &self,
        label: &str,
        dims: [usize; 3],
        dimension: wgpu::TextureDimension,
        format: wgpu::TextureFormat,
        usage: wgpu::TextureUsages,
    ) -> Result<wgpu::Texture> {
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let tex = self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d {
                width: dims[0] as u32,
                height: dims[1] as u32,
                depth_or_array_layers: dims[2] as u32,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension,
            format,
            usage,
            view_formats: &[],
        });
        match pollster::block_on(scope.pop()) {
            None => Ok(tex),
            Some(e) => Err(Error::Gpu(format!(
                "out of GPU memory for {label} {dims:?}: {e}"
            ))),
        }
    }

    /// A 2-D texture array of `format` (`R32Float`, `R16Float`) and `[width, height,
    /// layers]` texels the host writes ([`Self::write_layers`]) and shaders sample; wgpu
    /// hands it out zeroed.
    ///
    /// # Errors
    /// [`Error::TooLarge`] past the adapter's 2-D texture size or array layers;
    /// [`Error::Gpu`] out of GPU memory.
    pub fn texture_layers(
        &self,
        label: &str,
        format: wgpu::TextureFormat,
        dims: [usize; 3],
    ) -> Result<wgpu::Texture> {
        let side = self.limits.max_texture_dimension_2d as usize;
        let layers = self.limits.max_texture_array_layers as usize;
        if dims[0] == 0 || dims[1] == 0 || dims[0] > side || dims[1] > side {
            return Err(Error::too_large(
                label,
                format!(
                    "{} × {} texels: a 2-D texture holds 1 … {side} texels per axis on this \
                     adapter",
                    dims[0], dims[1]
                ),
            ));
        }
        if dims[2] == 0 || dims[2] > layers {
            return Err(Error::too_large(
                label,
                format!(
                    "{} layers: a texture array holds 1 … {layers} on this adapter",
                    dims[2]
                ),
            ));
        }
        self.new_texture(
            label,
            dims,
            wgpu::TextureDimension::D2,
            format,
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        )
    }

    /// Writes `data` (`extent[0]` texels fastest, then `extent[1]` rows, then
    /// `extent[2]` layers; `T` of the texel's size: `f32` for `R32Float`, the `u16`
    /// bits for `R16Float`) into the texture array `tex` at texel `origin` (x, y, first
    /// layer).
    pub fn write_layers<T: bytemuck::Pod>(
        &self,
        tex: &wgpu::Texture,
        origin: [usize; 3],
        extent: [usize; 3],
        data: &[T],
    ) {
        debug_assert_eq!(data.len(), extent.iter().product::<usize>());
        self.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: tex,
                mip_level: 0,
                origin: wgpu::Origin3d {
                    x: origin[0] as u32,
                    y: origin[1] as u32,
                    z: origin[2] as u32,
                },
                aspect: wgpu::TextureAspect::All,
            },
            bytemuck::cast_slice(data),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some((extent[0] * std::mem::size_of::<T>()) as u32),
                rows_per_image: Some(extent[1] as u32),
            },
            wgpu::Extent3d {
                width: extent[0] as u32,
                height: extent[1] as u32,
                depth_or_array_layers: extent[2] as u32,
            },
        );
    }

    fn write_texture_3d(&self, tex: &wgpu::Texture, dims: [usize; 3], bytes: &[u8], texel: usize) {
        self.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: tex,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            bytes,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some((dims[0] * texel) as u32),
                rows_per_image: Some(dims[1] as u32),
            },
            wgpu::Extent3d {
                width: dims[0] as u32,
                height: dims[1] as u32,
                depth_or_array_layers: dims[2] as u32,
            },
        );
    }

    /// Uploads voxels (x fastest) of a one-channel `format` (`R8Unorm`, `R16Unorm`, …),
    /// given as their texel bytes, into a 3D texture.
    ///
    /// # Errors
    /// As [`Self::upload_volume_r32`]; [`Error::Invalid`] when `bytes` is not one texel
    /// per voxel.
    pub fn upload_volume_texels(
        &self,
        dims: [usize; 3],
        format: wgpu::TextureFormat,
        bytes: &[u8],
    ) -> Result<wgpu::Texture> {
        let texel = format.block_copy_size(None).unwrap_or(0) as usize;
        if texel == 0 || bytes.len() != dims.iter().product::<usize>() * texel {
            return Err(Error::invalid(
                "volume texels",
                format!("{} bytes for {dims:?} voxels of {format:?}", bytes.len()),
            ));
        }
        let tex = self.texture_3d(
            "volume",
            dims,
            format,
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        )?;
        self.write_texture_3d(&tex, dims, bytes, texel);
        Ok(tex)
    }

    /// Uploads f32 voxels (x fastest) into an `R32Float` 3D texture.
    pub fn upload_volume_r32(&self, dims: [usize; 3], data: &[f32]) -> Result<wgpu::Texture> {
        let tex = self.texture_3d(
            "volume",
            dims,
            wgpu::TextureFormat::R32Float,
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        )?;
        self.write_texture_3d(&tex, dims, bytemuck::cast_slice(data), 4);
        Ok(tex)
    }

    /// An `Rgba32Float` 3D texture, writable from shaders (and readable back) when
    /// `storage`.
    pub fn rgba_texture(&self, dims: [usize; 3], storage: bool) -> Result<wgpu::Texture> {
        let mut usage = wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST;
        if storage {
            usage |= wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC;
        }
        self.texture_3d("rgba volume", dims, wgpu::TextureFormat::Rgba32Float, usage)
    }

    /// Uploads RGBA texels (x fastest) into an `Rgba32Float` 3D texture.
    pub fn upload_rgba(&self, dims: [usize; 3], data: &[[f32; 4]]) -> Result<wgpu::Texture> {
        let tex = self.rgba_texture(dims, false)?;
        self.write_texture_3d(&tex, dims, bytemuck::cast_slice(data), 16);
        Ok(tex)
    }

    /// A bind group whose entries are `resources` at bindings 0, 1, 2, … in order.
    /// The bind group layout `desc` describes; a uniform buffer's entry becomes a read-only
    /// storage buffer's where [`GpuContext::params_in_storage`] (as [`GpuContext::shader`]
    /// declares it).
    pub fn bind_group_layout(
        &self,
        desc: &wgpu::BindGroupLayoutDescriptor<'_>,
    ) -> wgpu::BindGroupLayout {
        let entries: Vec<wgpu::BindGroupLayoutEntry> = desc
            .entries
            .iter()
            .map(|e| match e.ty {
                wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset,
                    min_binding_size,
                } if self.params_in_storage => wgpu::BindGroupLayoutEntry {
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset,
                        min_binding_size,
                    },
                    ..*e
                },
                _ => *e,
            })
            .collect();
        self.device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: desc.label,
                entries: &entries,
            })
    }

    pub fn bind_group(
        &self,
        label: &str,
        layout: &wgpu::BindGroupLayout,
        resources: &[wgpu::BindingResource<'_>],
    ) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = resources
            .iter()
            .enumerate()
            .map(|(i, r)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: r.clone(),
            })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout,
            entries: &entries,
        })
    }

    /// Two timestamp queries where the adapter has `TIMESTAMP_QUERY`, else `None`.
    pub fn timestamps(&self) -> Option<TimestampPair> {
        self.features
            .contains(wgpu::Features::TIMESTAMP_QUERY)
            .then(|| self.timestamp_pair())
    }

    /// Records one compute pass of `pipeline` that dispatches `extent` workgroups once
    /// per bind group of `binds`, in order (the device runs them one after another and
    /// makes each one's writes visible to the next), submits it and waits. With `query`
    /// the pass is timed on the device: the seconds between its two timestamps.
    ///
    /// # Errors
    /// [`Error::Gpu`] when the device fails.
    pub fn run_pass(
        &self,
        (pipeline, label): (&wgpu::ComputePipeline, &str),
        binds: &[wgpu::BindGroup],
        extent: [u32; 3],
        query: Option<&TimestampPair>,
    ) -> Result<Option<f64>> {
        let mut enc = self.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(label),
                timestamp_writes: query.map(TimestampPair::pass_writes),
            });
            pass.set_pipeline(pipeline);
            for bind in binds {
                pass.set_bind_group(0, bind, &[]);
                pass.dispatch_workgroups(extent[0], extent[1], extent[2]);
            }
        }
        if let Some(q) = query {
            q.resolve(&mut enc);
        }
        self.queue.submit([enc.finish()]);
        self.wait()?;
        query.map(|q| q.seconds(self)).transpose()
    }

    /// Two timestamp queries (needs `TIMESTAMP_QUERY`).
    pub fn timestamp_pair(&self) -> TimestampPair {
        let set = self.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("timestamps"),
            ty: wgpu::QueryType::Timestamp,
            count: 2,
        });
        let resolved = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("timestamps"),
            size: 16,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        TimestampPair { set, resolved }
    }
}

/// A compute-stage buffer binding.
pub const fn buffer_entry(binding: u32, ty: wgpu::BufferBindingType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// A compute-stage 3D float texture binding (`texture_3d<f32>`), filterable or not.
pub const fn texture_entry(binding: u32, filterable: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable },
            view_dimension: wgpu::TextureViewDimension::D3,
            multisampled: false,
        },
        count: None,
    }
}

/// A write-only `Rgba32Float` 3D storage texture at `binding`, for compute.
pub const fn rgba_storage_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::StorageTexture {
            access: wgpu::StorageTextureAccess::WriteOnly,
            format: wgpu::TextureFormat::Rgba32Float,
            view_dimension: wgpu::TextureViewDimension::D3,
        },
        count: None,
    }
}

/// The compute pipeline of `entry` in `module` over the one bind group `layout`, or,
/// with `None`, over the layout its entry point's bindings imply, and the layout its
/// bind groups are made over; validation errors become [`Error::Gpu`] naming `label`.
/// [`Program::kernel`] calls it once per entry point and device.
fn compute_pipeline(
    ctx: &GpuContext,
    label: &str,
    module: &wgpu::ShaderModule,
    entry: &str,
    layout: Option<&wgpu::BindGroupLayout>,
) -> Result<Kernel> {
    let dev = &ctx.device;
    let scope = dev.push_error_scope(wgpu::ErrorFilter::Validation);
    let pl = layout.map(|l| {
        dev.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &[Some(l)],
            immediate_size: 0,
        })
    });
    let pipeline = dev.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: pl.as_ref(),
        module,
        entry_point: Some(entry),
        compilation_options: Default::default(),
        cache: None,
    });
    let layout = match layout {
        Some(l) => l.clone(),
        None => pipeline.get_bind_group_layout(0),
    };
    match pollster::block_on(scope.pop()) {
        None => Ok(Kernel { pipeline, layout }),
        Some(e) => Err(Error::Gpu(format!("pipeline {label} failed: {e}"))),
    }
}

/// The most loop iterations one llvmpipe invocation may run in total (Mesa's
/// `LP_MAX_TGSI_LOOP_ITERATIONS`); past it every loop silently stops. The casters
/// refuse, on a CPU adapter, work whose rays could run longer.
pub const LLVMPIPE_LOOP_LIMIT: usize = 65535;

/// Where the time of [`render_bands`] went, in seconds.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct BandTimes {
    /// The dispatches: timestamp queries when `from_timestamps`, else waited wall time.
    pub kernel: f64,
    pub from_timestamps: bool,
    /// Copying pixels and sample counts back.
    pub readback: f64,
}

/// The row bands of a per-pixel caster over the pixels `rect` of a `frame` (width,
/// height): `image` (RGBA f32 pixels on the device, its own channel count on the
/// host) and `counts` (one u32 per pixel), both the size of `rect`, in bands of at most
/// `rows_per_band` of its rows. For each band `bind(band, pixels, samples)` makes the
/// band's bind group around two new storage buffers, the band's pixels (`vec4<f32>`)
/// and sample counts (`u32`), row-major over `band` (frame coordinates); the band is
/// dispatched in 8 × 8 workgroups (one invocation per pixel), waited for and read back,
/// and `progress(rows done, rows of rect)` is called. Shared by `gpu::raycast` (a
/// brick's rectangle, `Camera::pixels_seen`), `gpu::adaptive` and `gpu::multi` (whole
/// frames).
///
/// With `carry` (`k` vec4 per pixel of the whole frame, row-major) the pixel buffer
/// holds each pixel's `k` vec4, filled from `carry` before the dispatch and read back
/// into it (a ray's state handed from one brick to the next); `image` is left as it is,
/// and so are the states of pixels outside `rect`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn render_bands(
    ctx: &GpuContext,
    (pipeline, label): (&wgpu::ComputePipeline, &str),
    rows_per_band: usize,
    (rect, frame): (&PixelRect, [usize; 2]),
    (image, counts): (&mut Frame, &mut [u32]),
    mut carry: Option<&mut [[f32; 4]]>,
    progress: &(dyn Fn(usize, usize) + Sync),
    mut bind: impl FnMut(&PixelRect, &wgpu::Buffer, &wgpu::Buffer) -> Result<wgpu::BindGroup>,
) -> Result<BandTimes> {
    let (w, h) = (rect.width(), rect.height());
    if image.width != w || image.height != h || counts.len() != w * h {
        return Err(Error::Gpu(format!(
            "a {}×{} image with {} counts for a {w}×{h} tile",
            image.width,
            image.height,
            counts.len()
        )));
    }
    let query = ctx.timestamps();
    let mut times = BandTimes {
        from_timestamps: query.is_some(),
        ..Default::default()
    };
    let frame_width = frame[0];
    let per_pixel = carry
        .as_ref()
        .map_or(1, |c| c.len() / (frame[0] * frame[1]).max(1));
    // Where row `row` (frame coordinates) of the tile lies in `carry`.
    let carried_row = |row: usize| {
        let start = (row * frame_width + rect.cols.start) * per_pixel;
        start..start + w * per_pixel
    };
    let mut done = 0;
    while done < h {
        let rows = rows_per_band.min(h - done);
        let band = PixelRect {
            cols: rect.cols.clone(),
            rows: rect.rows.start + done..rect.rows.start + done + rows,
        };
        let pix_bytes = (rows * w * 16 * per_pixel) as u64;
        let cnt_bytes = (rows * w * 4) as u64;
        let out_buf = ctx.storage_buffer("pixels", pix_bytes)?;
        if let Some(c) = carry.as_ref() {
            let mut state = Vec::with_capacity(rows * w * per_pixel);
            for row in band.rows.clone() {
                state.extend_from_slice(&c[carried_row(row)]);
            }
            ctx.queue
                .write_buffer(&out_buf, 0, bytemuck::cast_slice(&state));
        }
        let cnt_buf = ctx.storage_buffer("samples", cnt_bytes)?;
        let group = bind(&band, &out_buf, &cnt_buf)?;
        let t_k = Instant::now();
        let extent = [(w as u32).div_ceil(8), (rows as u32).div_ceil(8), 1];
        let device = ctx.run_pass((pipeline, label), &[group], extent, query.as_ref())?;
        times.kernel += device.unwrap_or_else(|| t_k.elapsed().as_secs_f64());
        let t_r = Instant::now();
        let px: Vec<[f32; 4]> =
            bytemuck::cast_slice(&ctx.read_buffer(&out_buf, pix_bytes)?).to_vec();
        let cn: Vec<u32> = bytemuck::cast_slice(&ctx.read_buffer(&cnt_buf, cnt_bytes)?).to_vec();
        times.readback += t_r.elapsed().as_secs_f64();
        let ch = image.channels;
        match carry.as_mut() {
            Some(c) => {
                for (i, row) in band.rows.clone().enumerate() {
                    c[carried_row(row)].copy_from_slice(&px[i * w * per_pixel..][..w * per_pixel]);
                }
            }
            None => {
                for (i, p) in px.iter().enumerate() {
                    let dst = (done * w + i) * ch;
                    image.data[dst..dst + ch].copy_from_slice(&p.map(|v| v as f64)[..ch]);
                }
            }
        }
        counts[done * w..(done + rows) * w].copy_from_slice(&cn);
        done += rows;
        progress(done, h);
    }
    Ok(times)
}
