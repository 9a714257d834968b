//! Fourier volume rendering on the GPU: the port of [`crate::cpu::fvr::fvr_project`].
//!
//! The CPU builds the centred 3-D spectrum in f64 ([`FvrSpectrum::new`]); it is
//! uploaded once as complex f32 ([`GpuFvrSpectrum::upload`]) and stays on the GPU for
//! every view. Per view:
//! 1. `shaders/fvr_slice.wgsl: extract_slice` interpolates the central slice, one
//!    invocation per frequency sample (nearest, trilinear, Lanczos-2/3/4; the same taps,
//!    per-axis weight normalisation and phase ramp as the CPU's per-sample closure);
//! 2. the inverse 2-D FFT of the slice, in place in the slice's buffer (no host round
//!    trip), with a [`GpuFftPlan`] made once at upload (Stockham; `M` must be a power
//!    of two), and the readback of the `M²` result;
//! 3. the host crops, scales and optionally de-apodises exactly as the CPU does
//!    (the shared `SlicePlan::crop`, in f64).
//!
//! The Dirichlet kernel stays on the CPU (refused here with a clear error).
//!
//! Everything that does not depend on the view (the slice pipeline, the slice buffer,
//! the parameter buffer and bind group, the inverse FFT's pipelines, twiddle tables and
//! ping-pong buffer) is built once by [`GpuFvrSpectrum::upload`]; a view only writes
//! 48 bytes of parameters and records the dispatches.

use super::context::GpuContext;
use super::fft::{GpuFftPlan, GpuFftVariant};
use crate::cpu::dft::{Direction, Normalization};
use crate::cpu::fvr::{FvrSpectrum, FvrView, Kernel, SlicePlan};
use crate::error::{Error, Result};
use crate::frame::Frame;
use std::time::Instant;
use wgpu::util::DeviceExt;

/// `shaders/shared/fvr_params.wgsl`: the WGSL twin of [`FvrParams`].
pub const PARAMS_WGSL: &str = include_str!("../../shaders/shared/fvr_params.wgsl");
/// `shaders/fvr_slice.wgsl`.
pub const SLICE_WGSL: &str = include_str!("../../shaders/fvr_slice.wgsl");

/// Invocations per workgroup (`WORKGROUP` in `shaders/fvr_slice.wgsl`).
const WORKGROUP: u32 = 64;

/// The complete WGSL module of the slice extraction.
pub fn shader_source() -> String {
    format!("{PARAMS_WGSL}\n{SLICE_WGSL}")
}

/// Parameters of one slice extraction, shared with
/// `shaders/shared/fvr_params.wgsl: FvrParams` (48 bytes, twelve 4-byte scalars, no
/// padding; `tests/gpu_fvr.rs` checks the layout).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct FvrParams {
    /// The cube side `M`.
    pub m: u32,
    /// 0 nearest, 1 trilinear, 2 Lanczos.
    pub kernel: u32,
    /// Half the taps per axis: 1 (trilinear) or the Lanczos order.
    pub radius: u32,
    /// Always 0.
    pub pad: u32,
    pub right_x: f32,
    pub right_y: f32,
    pub right_z: f32,
    pub up_x: f32,
    pub up_y: f32,
    pub up_z: f32,
    /// Sub-voxel offsets of the phase ramp.
    pub dr: f32,
    pub du: f32,
}

/// The kernel code and radius of [`FvrParams`], or an error for the Dirichlet kernel.
fn kernel_code(kernel: Kernel) -> Result<(u32, u32)> {
    match kernel {
        Kernel::Nearest => Ok((0, 0)),
        Kernel::Trilinear => Ok((1, 1)),
        Kernel::Dirichlet => Err(Error::invalid(
            "FVR kernel",
            "dirichlet runs on the CPU only (use --backend cpu, or a truncated kernel \
             such as lanczos3 on the GPU)",
        )),
        k => Ok((2, k.lanczos_order().expect("a Lanczos kernel") as u32)),
    }
}

/// A spectrum uploaded once (complex f32, `M³`), with the slice pipeline, the slice
/// and parameter buffers, and the inverse 2-D FFT plan made once, reused by every view.
/// Views share the slice and parameter buffers: render the views of one
/// `GpuFvrSpectrum` one after another, not from several threads at once.
pub struct GpuFvrSpectrum<'a> {
    cpu: &'a FvrSpectrum,
    pipeline: wgpu::ComputePipeline,
    /// [`FvrParams`], rewritten per view.
    params: wgpu::Buffer,
    /// The `M²` slice, transformed in place.
    slice: wgpu::Buffer,
    bind: wgpu::BindGroup,
    /// The inverse `M × M` FFT (`None` when `M` is not a power of two).
    fft: Option<GpuFftPlan>,
}

impl<'a> GpuFvrSpectrum<'a> {
    /// Uploads the centred spectrum (rounded to f32).
    ///
    /// # Errors
    /// [`Error::TooLarge`] when `M³` complex f32 values exceed one storage binding
    /// (`max_storage_buffer_binding_size`) or buffer of the adapter.
    pub fn upload(ctx: &GpuContext, spectrum: &'a FvrSpectrum) -> Result<Self> {
        let data = spectrum.spectrum();
        let bytes = (data.len() as u64).saturating_mul(8);
        let limit = ctx
            .limits
            .max_storage_buffer_binding_size
            .min(ctx.limits.max_buffer_size);
        if bytes > limit {
            let m = spectrum.side();
            return Err(Error::too_large(
                "GPU FVR spectrum",
                format!(
                    "{m}³ complex f32 values ({bytes} bytes) exceed the adapter's \
                     storage-binding limit of {limit} bytes (max_storage_buffer_binding_size): \
                     use a smaller --padding or volume, or --backend cpu"
                ),
            ));
        }
        let host: Vec<[f32; 2]> = data.iter().map(|v| [v.re as f32, v.im as f32]).collect();
        let buffer = ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("fvr spectrum"),
                contents: bytemuck::cast_slice(&host),
                usage: wgpu::BufferUsages::STORAGE,
            });
        let module = ctx.shader("fvr_slice.wgsl", &shader_source())?;
        let pipeline = ctx
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some("extract_slice"),
                layout: None,
                module: &module,
                entry_point: Some("extract_slice"),
                compilation_options: Default::default(),
                cache: None,
            });
        let m = spectrum.side();
        let params = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("fvr params"),
            size: std::mem::size_of::<FvrParams>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let slice = ctx.storage_buffer("fvr slice", (m * m * 8) as u64)?;
        let bind = ctx.bind_group(
            "fvr slice",
            &pipeline.get_bind_group_layout(0),
            &[
                params.as_entire_binding(),
                buffer.as_entire_binding(),
                slice.as_entire_binding(),
            ],
        );
        let fft = if m.is_power_of_two() {
            Some(GpuFftPlan::new(
                ctx,
                &[m, m],
                Direction::Inverse,
                Normalization::Unnormalized,
                GpuFftVariant::Stockham,
            )?)
        } else {
            None
        };
        ctx.wait()?;
        Ok(GpuFvrSpectrum {
            cpu: spectrum,
            pipeline,
            params,
            slice,
            bind,
            fft,
        })
    }

    /// The CPU spectrum this was uploaded from.
    pub fn cpu(&self) -> &FvrSpectrum {
        self.cpu
    }
}

/// Where the time of one GPU view went, in seconds (wall clock, each step waited for).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FvrTimings {
    /// Resolving the view and writing its parameters (pipelines, buffers and the FFT
    /// plan are made at upload).
    pub setup: f64,
    /// The slice extraction dispatch.
    pub slice: f64,
    /// The inverse 2-D FFT on the slice's buffer (set-up, passes, readback).
    pub fft: f64,
    /// Crop and scale on the host.
    pub crop: f64,
    /// Everything.
    pub total: f64,
}

/// [`crate::cpu::fvr::fvr_project`] on the GPU: the same image within the f32
/// tolerance `tests/gpu_fvr.rs` states.
///
/// # Errors
/// As the CPU version; also [`Error::Invalid`] for the Dirichlet kernel or a cube side
/// that is not a power of two (the GPU FFT's limit), [`Error::Gpu`] on device failure.
pub fn fvr_project(
    ctx: &GpuContext,
    spectrum: &GpuFvrSpectrum,
    view: FvrView,
    kernel: Kernel,
    deapodize: bool,
) -> Result<Frame> {
    Ok(fvr_project_timed(ctx, spectrum, view, kernel, deapodize)?.0)
}

/// [`fvr_project`] with timings.
///
/// # Errors
/// As [`fvr_project`].
pub fn fvr_project_timed(
    ctx: &GpuContext,
    spectrum: &GpuFvrSpectrum,
    view: FvrView,
    kernel: Kernel,
    deapodize: bool,
) -> Result<(Frame, FvrTimings)> {
    let t0 = Instant::now();
    let (code, radius) = kernel_code(kernel)?;
    let cpu = spectrum.cpu;
    let m = cpu.side();
    if !m.is_power_of_two() {
        return Err(Error::invalid(
            "FVR cube side",
            format!(
                "{m} is not a power of two, which the GPU FFT needs: choose --padding and \
                 the volume size so that padding × max(dims) is one (e.g. a 32³ volume with padding 2: 64), \
                 or use --backend cpu"
            ),
        ));
    }
    let plan = SlicePlan::new(cpu, view)?;
    let g = &plan.geometry;
    let params = FvrParams {
        m: m as u32,
        kernel: code,
        radius,
        pad: 0,
        right_x: g.right.x as f32,
        right_y: g.right.y as f32,
        right_z: g.right.z as f32,
        up_x: g.up.x as f32,
        up_y: g.up.y as f32,
        up_z: g.up.z as f32,
        dr: plan.dr as f32,
        du: plan.du as f32,
    };

    let Some(fft_plan) = &spectrum.fft else {
        return Err(Error::invalid(
            "FVR cube side",
            format!("{m} is not a power of two"),
        ));
    };
    let dev = &ctx.device;
    ctx.queue
        .write_buffer(&spectrum.params, 0, bytemuck::bytes_of(&params));
    let invocations = (m * m) as u32;
    let groups = invocations.div_ceil(WORKGROUP).max(1);
    let x = groups.min(ctx.limits.max_compute_workgroups_per_dimension.max(1));
    let y = groups.div_ceil(x);
    let setup = t0.elapsed().as_secs_f64();

    let t = Instant::now();
    let mut enc = dev.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("extract_slice"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&spectrum.pipeline);
        pass.set_bind_group(0, &spectrum.bind, &[]);
        pass.dispatch_workgroups(x, y, 1);
    }
    ctx.queue.submit([enc.finish()]);
    ctx.wait()?;
    let slice_s = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let image = fft_plan.execute_buffer(ctx, &spectrum.slice)?.data;
    let fft = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let frame = plan.crop(cpu, kernel, deapodize, |i| image[i].re as f64);
    let crop = t.elapsed().as_secs_f64();
    Ok((
        frame,
        FvrTimings {
            setup,
            slice: slice_s,
            fft,
            crop,
            total: t0.elapsed().as_secs_f64(),
        },
    ))
}
