//! Fourier volume rendering on the GPU: the port of [`crate::cpu::fvr::fvr_project`].
//!
//! The centred 3-D spectrum is made once and stays on the GPU for every view, in one of
//! two ways:
//! - [`GpuFvrSpectrum::compute`] makes it on the GPU: the host fills the padded cube
//!   in complex f32 (the volume's values at [`FvrLayout::cube_index`], the `ifftshift`
//!   of the padded cube, times `(−1)^(x+y+z)` so that the transform comes out centred,
//!   the `fftshift` folded into an exact sign), uploads it, and the forward 3-D FFT
//!   ([`GpuFftPlan`], Stockham; Bluestein's algorithm for a side that is not a power of
//!   two) transforms it in place on the device. `voxlab fvr --backend gpu` does this.
//! - [`GpuFvrSpectrum::upload`] uploads the CPU's f64 spectrum ([`FvrSpectrum::new`])
//!   rounded to complex f32 (the parity tests hold both to the CPU oracle).
//!
//! **Spectra larger than one storage binding.** `M³` complex f32 values take `8·M³`
//! bytes: 128 MiB for `M = 256`, 1 GiB for `M = 512`, beyond what many adapters bind at
//! once (lavapipe: 128 MiB per binding). The spectrum is therefore kept as up to
//! [`MAX_SLABS`] *z-slabs*, each a storage buffer of `depth` whole `M × M` planes
//! (`depth = ⌊limit / 8M²⌋`, the last slab shorter), bound at bindings 2, 3, …; the
//! shader's `spectrum_at` picks the slab with a `switch` on `z / depth`
//! ([`slab_bindings_wgsl`] generates the bindings and the switch for the slab count).
//! One slab — the whole spectrum in one binding — is the common case.
//! [`GpuFvrSpectrum::upload_in_slabs`] and [`GpuFvrSpectrum::compute_in_slabs`] take
//! the per-slab limit explicitly (tests force several slabs on small spectra with
//! them). The upload converts and sends one slab at a time; a computed spectrum that
//! needs several slabs (or whose cube exceeds one binding) is transformed by the GPU
//! FFT in slabs through the host ([`crate::gpu::fft::fft_nd_timed`]), then uploaded
//! slab by slab.
//!
//! Per view:
//! 1. `shaders/fvr_slice.wgsl: extract_slice` interpolates the central slice, one
//!    invocation per frequency sample (nearest, trilinear, Lanczos-2/3/4; the same taps,
//!    per-axis weight normalisation and phase ramp as the CPU's per-sample closure, and
//!    the CPU's kernels: `shaders/shared/filters.wgsl`, whose `sinc` reduces the
//!    argument as `cpu::filter::sin_pi` does; like the CPU it samples the rows
//!    `k_u ≤ 0` and writes the rows `k_u > 0` as their Hermitian conjugates);
//! 2. the inverse 2-D FFT of the slice, in place in the slice's buffer (no host round
//!    trip), with a [`GpuFftPlan`] made once at upload (Stockham; Bluestein's
//!    algorithm where `M` is not a power of two), and the readback of the `M²` result;
//! 3. the host crops, scales and optionally de-apodises exactly as the CPU does
//!    (the shared `SlicePlan::crop`, in f64).
//!
//! The Dirichlet kernel reads the volume, not the spectrum: `dirichlet` in the shader
//! sums every voxel's value times `e^{−2πi κ·r/M}` for each sample, separably (the x
//! phases kept per invocation, the angles reduced to a fraction of a turn), in f32 —
//! the port of `FvrSpectrum::sample_exact`, under the CPU's work limit. The volume's
//! f32 values are kept on the device beside the spectrum for it.
//!
//! Everything that does not depend on the view (the slice pipeline, the slice buffer,
//! the parameter buffer and bind group, the inverse FFT's pipelines, twiddle tables and
//! ping-pong buffer) is built once with the spectrum; a view only writes
//! 48 bytes of parameters and records the dispatches.

use super::context::{GpuContext, TimestampPair};
use super::fft::{GpuFftPlan, GpuFftVariant};
use crate::cpu::dft::{Direction, Normalization};
use crate::cpu::fvr::{FvrLayout, FvrSpectrum, FvrView, Kernel, SlicePlan};
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::volume::Volume;
use std::time::Instant;
use wgpu::util::DeviceExt;

/// `shaders/shared/fvr_params.wgsl`: the WGSL twin of [`FvrParams`].
pub const PARAMS_WGSL: &str = super::shaders::FVR_PARAMS;

/// Invocations per workgroup (`WORKGROUP` in `shaders/fvr_slice.wgsl`).
const WORKGROUP: u32 = 64;

/// The most voxels along x the GPU's Dirichlet sum takes (it keeps the x phases per
/// invocation; `DIRICHLET_MAX_NX` in `shaders/fvr_slice.wgsl`). The work limit
/// [`crate::cpu::fvr::MAX_DIRICHLET_WORK`] keeps every cube it admits below it
/// (`N³·M² ≤ 4e9` with `M ≥ N`: `N ≤ 83`); a longer, thin volume is refused.
pub const DIRICHLET_MAX_NX: usize = 128;

/// The most z-slabs a spectrum may be split into (storage bindings 2 … 9; the slice is
/// binding 1). An adapter offering fewer storage buffers per shader stage lowers it.
pub const MAX_SLABS: usize = 8;

/// The generated module `fvr_slabs`: the storage bindings of `slabs` z-slabs
/// (`spectrum0` … at bindings 2, 3, …) and `spectrum_at(slab, i)`, element `i` of slab
/// `slab`, for `shaders/fvr_slice.wgsl: at`.
pub fn slab_bindings_wgsl(slabs: usize) -> String {
    assert!((1..=MAX_SLABS).contains(&slabs), "1 … {MAX_SLABS} slabs");
    let mut s = String::from(
        "// Generated by src/gpu/fvr.rs: slab_bindings_wgsl. The centred spectrum in\n\
         // z-slabs of FvrParams::slab_depth planes, [z][y][x] within each: (re, im).\n",
    );
    for k in 0..slabs {
        s += &format!(
            "@group(0) @binding({}) var<storage, read> spectrum{k}: array<vec2<f32>>;\n",
            k + 2
        );
    }
    s += &format!(
        "// The volume's values, [z][y][x] (the Dirichlet kernel's sum).\n\
         @group(0) @binding({}) var<storage, read> values: array<f32>;\n",
        slabs + 2
    );
    s += "fn spectrum_at(slab: u32, i: u32) -> vec2<f32> {\n";
    if slabs == 1 {
        s += "    return spectrum0[i];\n";
    } else {
        s += "    switch slab {\n";
        for k in 0..slabs - 1 {
            s += &format!("        case {k}u: {{ return spectrum{k}[i]; }}\n");
        }
        s += &format!("        default: {{ return spectrum{}[i]; }}\n", slabs - 1);
        s += "    }\n";
    }
    s += "}\n";
    s
}

/// The complete WGSL module of the slice extraction for a spectrum in `slabs` z-slabs:
/// `shaders/fvr_slice.wgsl` and its imports, with [`slab_bindings_wgsl`].
pub fn shader_source(slabs: usize) -> String {
    super::shaders::resolve_with("fvr_slice", &[("fvr_slabs", &slab_bindings_wgsl(slabs))])
}

/// Parameters of one slice extraction, shared with
/// `shaders/shared/fvr_params.wgsl: FvrParams` (80 bytes, twenty 4-byte scalars, no
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
    /// The `M × M` planes per z-slab of the spectrum (`M` when it is one slab).
    pub slab_depth: u32,
    pub right_x: f32,
    pub right_y: f32,
    pub right_z: f32,
    pub up_x: f32,
    pub up_y: f32,
    pub up_z: f32,
    /// Sub-voxel offsets of the phase ramp.
    pub dr: f32,
    pub du: f32,
    /// The volume's size in voxels and its placement offset in the cube (the
    /// Dirichlet kernel's sum).
    pub nx: u32,
    pub ny: u32,
    pub nz: u32,
    pub ox: u32,
    pub oy: u32,
    pub oz: u32,
    /// Padding to a multiple of 16 bytes.
    pub pad0: u32,
    pub pad1: u32,
}

/// The kernel code and radius of [`FvrParams`].
fn kernel_code(kernel: Kernel) -> (u32, u32) {
    match kernel {
        Kernel::Nearest => (0, 0),
        Kernel::Trilinear => (1, 1),
        Kernel::Dirichlet => (3, 0),
        k => (2, k.lanczos_order().expect("a Lanczos kernel") as u32),
    }
}

/// A spectrum uploaded once (complex f32, `M³`, in one or more z-slabs), with the slice
/// pipeline, the slice and parameter buffers, and the inverse 2-D FFT plan made once,
/// reused by every view. Views share the slice and parameter buffers: render the views
/// of one `GpuFvrSpectrum` one after another, not from several threads at once.
pub struct GpuFvrSpectrum {
    /// The cube and the volume's place in it (the view's frame, crop and scale).
    layout: FvrLayout,
    /// `M × M` planes per slab.
    slab_depth: usize,
    /// The slabs, each ≤ the per-binding limit; kept alive for the bind group.
    slabs: Vec<wgpu::Buffer>,
    pipeline: wgpu::ComputePipeline,
    /// [`FvrParams`], rewritten per view.
    params: wgpu::Buffer,
    /// The `M²` slice, transformed in place.
    slice: wgpu::Buffer,
    bind: wgpu::BindGroup,
    /// The inverse `M × M` FFT (Bluestein's algorithm when `M` is not a power of two).
    fft: GpuFftPlan,
    /// The volume's values in f32, `[z][y][x]` (the Dirichlet kernel's sum), or a
    /// placeholder when they exceed one binding ([`check_dirichlet`] refuses those).
    _values: wgpu::Buffer,
    /// Times the slice dispatch on the device, where the adapter has timestamps (made
    /// once, read per view).
    query: Option<TimestampPair>,
}

/// How an `M³` spectrum is bound: `slabs` z-slabs of `depth` whole `M × M` planes
/// (the last shorter), one storage binding each (module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SpectrumSlabs {
    pub depth: usize,
    pub slabs: usize,
}

impl SpectrumSlabs {
    /// The slabs of an `m³` spectrum with at most `max_slab_bytes` per slab (and at most
    /// the adapter's limits in `limits`).
    ///
    /// # Errors
    /// [`Error::TooLarge`] when one plane exceeds a slab, or the spectrum needs more
    /// slabs than [`MAX_SLABS`] (or than the adapter's storage buffers per shader stage,
    /// less those of the slice and the volume's values).
    pub fn new(limits: &wgpu::Limits, m: usize, max_slab_bytes: u64) -> Result<Self> {
        let limit = max_slab_bytes
            .min(limits.max_storage_buffer_binding_size)
            .min(limits.max_buffer_size);
        let plane = (m * m) as u64 * 8;
        let max_slabs =
            MAX_SLABS.min((limits.max_storage_buffers_per_shader_stage as usize).saturating_sub(2));
        let depth = (limit / plane.max(1)).min(m as u64) as usize;
        let slabs = if depth == 0 {
            usize::MAX
        } else {
            m.div_ceil(depth)
        };
        if slabs > max_slabs {
            let bytes = (m as u64).pow(3).saturating_mul(8);
            return Err(Error::too_large(
                "GPU FVR spectrum",
                format!(
                    "{m}³ complex f32 values ({bytes} bytes) need more than {max_slabs} \
                     storage bindings of at most {limit} bytes \
                     (max_storage_buffer_binding_size): use a smaller --padding or \
                     volume, or --backend cpu"
                ),
            ));
        }
        Ok(SpectrumSlabs { depth, slabs })
    }

    /// Creates the storage buffers of the slabs of an `m³` spectrum, each filled from
    /// `planes(range)`: the complex f32 values (`[re, im]`) of that range of `M × M`
    /// planes, made one slab at a time (the host holds at most one slab in f32).
    fn upload(
        &self,
        ctx: &GpuContext,
        m: usize,
        planes: impl Fn(std::ops::Range<usize>) -> Vec<[f32; 2]>,
    ) -> Vec<wgpu::Buffer> {
        (0..self.slabs)
            .map(|k| {
                let host = planes(k * self.depth..((k + 1) * self.depth).min(m));
                ctx.device
                    .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                        label: Some("fvr spectrum slab"),
                        contents: bytemuck::cast_slice(&host),
                        usage: wgpu::BufferUsages::STORAGE,
                    })
            })
            .collect()
    }

    /// One line for the user ("FVR spectrum in 3 z-slabs of 96 planes (one storage
    /// binding each)"); `None` when it is one binding.
    pub fn describe(&self) -> Option<String> {
        (self.slabs > 1).then(|| {
            format!(
                "FVR spectrum in {} z-slabs of {} planes (one storage binding each)",
                self.slabs, self.depth
            )
        })
    }
}

impl GpuFvrSpectrum {
    /// Uploads the centred spectrum (rounded to f32), in as few z-slabs as the adapter's
    /// per-binding limit (`max_storage_buffer_binding_size`, `max_buffer_size`) allows.
    ///
    /// # Errors
    /// As [`GpuFvrSpectrum::upload_in_slabs`].
    pub fn upload(ctx: &GpuContext, spectrum: &FvrSpectrum) -> Result<Self> {
        let limit = crate::gpu::plan::binding_limit(&ctx.limits);
        Self::upload_in_slabs(ctx, spectrum, limit)
    }

    /// [`GpuFvrSpectrum::upload`] with at most `max_slab_bytes` per slab (at most the
    /// adapter's limits): `depth = ⌊max_slab_bytes / 8M²⌋` planes per slab.
    ///
    /// # Errors
    /// [`Error::TooLarge`] when one `M × M` plane exceeds a slab, or the spectrum needs
    /// more slabs than [`MAX_SLABS`] (or than the adapter's storage buffers per shader
    /// stage, less the slice's).
    pub fn upload_in_slabs(
        ctx: &GpuContext,
        spectrum: &FvrSpectrum,
        max_slab_bytes: u64,
    ) -> Result<Self> {
        let data = spectrum.spectrum();
        let m = spectrum.side();
        let plan = SpectrumSlabs::new(&ctx.limits, m, max_slab_bytes)?;
        let buffers = plan.upload(ctx, m, |planes| {
            data[planes.start * m * m..planes.end * m * m]
                .iter()
                .map(|v| [v.re as f32, v.im as f32])
                .collect()
        });
        let values: Vec<f32> = spectrum.values().iter().map(|&v| v as f32).collect();
        Self::with_slabs(ctx, *spectrum.layout(), plan.depth, buffers, &values)
    }

    /// The centred spectrum of `volume` zero-padded by `padding` (as
    /// [`FvrSpectrum::new`]), computed on the GPU in f32 and kept there, in as few
    /// z-slabs as the adapter's per-binding limit allows: the padded cube is filled on
    /// the host (the volume's values at [`FvrLayout::cube_index`], times
    /// `(−1)^(x+y+z)`, which makes the transform come out centred: for an even side
    /// `M`, `fftshift(X)_k = Σ_n x_n·(−1)^n·exp(−2πi·nk/M)`, and the sign is exact),
    /// uploaded, and transformed by the forward 3-D Stockham FFT ([`GpuFftPlan`];
    /// Bluestein's algorithm where `M` is not a power of two) in place on the device.
    /// A cube that fits no single binding (or needs several slabs) is transformed in
    /// slabs through the host ([`crate::gpu::fft::fft_nd_timed`]) and uploaded in
    /// z-slabs. The CPU's f64 spectrum is never made.
    ///
    /// # Errors
    /// As [`FvrSpectrum::new`] (anisotropic voxels, non-finite values, a cube past the
    /// volume limit) and [`GpuFvrSpectrum::upload_in_slabs`]; [`Error::Gpu`] on device
    /// failure.
    pub fn compute(ctx: &GpuContext, volume: &Volume<f32>, padding: usize) -> Result<Self> {
        let limit = crate::gpu::plan::binding_limit(&ctx.limits);
        Self::compute_in_slabs(ctx, volume, padding, limit)
    }

    /// [`GpuFvrSpectrum::compute`] with at most `max_slab_bytes` per slab of the
    /// spectrum (as [`GpuFvrSpectrum::upload_in_slabs`]).
    ///
    /// # Errors
    /// As [`GpuFvrSpectrum::compute`].
    pub fn compute_in_slabs(
        ctx: &GpuContext,
        volume: &Volume<f32>,
        padding: usize,
        max_slab_bytes: u64,
    ) -> Result<Self> {
        let layout = FvrLayout::new(volume, padding)?;
        volume.check_finite("volume for Fourier volume rendering")?;
        let m = layout.side();
        let plan = SpectrumSlabs::new(&ctx.limits, m, max_slab_bytes)?;
        let cube = centred_cube(&layout, volume.data());
        let shape = [m, m, m];
        let (dir, norm) = (Direction::Forward, Normalization::Unnormalized);
        let variant = GpuFftVariant::Stockham;
        if plan.slabs == 1 && super::fft::split_plan(ctx, &shape)?.is_none() {
            // One binding: transform in place on the device and keep the result.
            let bytes = (cube.len() * 8) as u64;
            let buffer = ctx
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("fvr spectrum slab"),
                    contents: bytemuck::cast_slice(&cube),
                    usage: wgpu::BufferUsages::STORAGE
                        | wgpu::BufferUsages::COPY_SRC
                        | wgpu::BufferUsages::COPY_DST,
                });
            drop(cube);
            let fft = GpuFftPlan::new(ctx, &shape, dir, norm, variant)?;
            let mut enc = ctx.device.create_command_encoder(&Default::default());
            let out = fft.encode_in_place(ctx, &mut enc, &buffer);
            if !std::ptr::eq(out, &buffer) {
                enc.copy_buffer_to_buffer(out, 0, &buffer, 0, bytes);
            }
            ctx.queue.submit([enc.finish()]);
            ctx.wait()?;
            drop(fft);
            return Self::with_slabs(ctx, layout, plan.depth, vec![buffer], volume.data());
        }
        // Past one binding: the FFT in slabs through the host, then the z-slabs.
        let x: Vec<rustfft::num_complex::Complex<f32>> = cube
            .iter()
            .map(|v| rustfft::num_complex::Complex::new(v[0], v[1]))
            .collect();
        drop(cube);
        let data = super::fft::fft_nd_timed(ctx, &x, &shape, dir, norm, variant)?.data;
        drop(x);
        let buffers = plan.upload(ctx, m, |planes| {
            data[planes.start * m * m..planes.end * m * m]
                .iter()
                .map(|v| [v.re, v.im])
                .collect()
        });
        Self::with_slabs(ctx, layout, plan.depth, buffers, volume.data())
    }

    /// The slice pipeline, buffers, bind group and inverse FFT around the spectrum's
    /// z-slabs of `depth` planes, with the volume's `values` for the Dirichlet kernel.
    fn with_slabs(
        ctx: &GpuContext,
        layout: FvrLayout,
        depth: usize,
        buffers: Vec<wgpu::Buffer>,
        values: &[f32],
    ) -> Result<Self> {
        let m = layout.side();
        let slabs = buffers.len();
        let super::context::Kernel {
            layout: bind_layout,
            pipeline,
        } = ctx.kernel(
            &format!("fvr_slice.wgsl ({slabs} slabs)"),
            &shader_source(slabs),
            None,
            "extract_slice",
        )?;
        let params = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("fvr params"),
            size: std::mem::size_of::<FvrParams>() as u64,
            usage: super::context::PARAMS_USAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let slice = ctx.storage_buffer("fvr slice", (m * m * 8) as u64)?;
        let values_bound =
            (values.len() as u64 * 4) <= crate::gpu::plan::binding_limit(&ctx.limits);
        let values_buffer = ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("fvr volume values"),
                contents: if values_bound && !values.is_empty() {
                    bytemuck::cast_slice(values)
                } else {
                    &[0; 4]
                },
                usage: wgpu::BufferUsages::STORAGE,
            });
        let mut resources = vec![params.as_entire_binding(), slice.as_entire_binding()];
        resources.extend(buffers.iter().map(|b| b.as_entire_binding()));
        resources.push(values_buffer.as_entire_binding());
        let bind = ctx.bind_group("fvr slice", &bind_layout, &resources);
        let fft = GpuFftPlan::new(
            ctx,
            &[m, m],
            Direction::Inverse,
            Normalization::Unnormalized,
            GpuFftVariant::Stockham,
        )?;
        ctx.wait()?;
        Ok(GpuFvrSpectrum {
            layout,
            slab_depth: depth,
            slabs: buffers,
            pipeline,
            params,
            slice,
            bind,
            fft,
            _values: values_buffer,
            query: ctx.timestamps(),
        })
    }

    /// The cube and the volume's place in it.
    pub fn layout(&self) -> &FvrLayout {
        &self.layout
    }

    /// How many z-slabs (storage buffers) hold the spectrum.
    pub fn slab_count(&self) -> usize {
        self.slabs.len()
    }

    /// The `M × M` planes per slab (the last may hold fewer).
    pub fn slab_depth(&self) -> usize {
        self.slab_depth
    }
}

/// Where the time of one GPU view went, in seconds (wall clock, each step waited for;
/// `kernel` from the device's timestamps).
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
    /// The slice dispatch and the inverse FFT's passes on the device, from timestamp
    /// queries; `None` where the adapter has none.
    pub kernel: Option<f64>,
}

/// The padded cube of [`GpuFvrSpectrum::compute`] as complex f32 (`[re, im]`): voxel
/// `(i, j, k)`'s value at [`FvrLayout::cube_index`] `(x, y, z)`, negated when
/// `x + y + z` is odd, zero elsewhere.
fn centred_cube(layout: &FvrLayout, values: &[f32]) -> Vec<[f32; 2]> {
    let m = layout.side();
    let [nx, ny, nz] = layout.dims();
    let mut cube = vec![[0.0f32; 2]; m * m * m];
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let v = values[(k * ny + j) * nx + i];
                let [x, y, z] = layout.cube_index([i, j, k]);
                let sign = if (x + y + z) % 2 == 1 { -1.0 } else { 1.0 };
                cube[(z * m + y) * m + x] = [sign * v, 0.0];
            }
        }
    }
    cube
}

/// [`crate::cpu::fvr::fvr_project`] on the GPU: the same image within the f32
/// tolerance `tests/gpu_fvr.rs` states.
///
/// # Errors
/// As the CPU version; also [`Error::Invalid`] for the Dirichlet kernel,
/// [`Error::Gpu`] on device failure.
pub fn fvr_project(
    ctx: &GpuContext,
    spectrum: &GpuFvrSpectrum,
    view: FvrView,
    kernel: Kernel,
    deapodize: bool,
) -> Result<Frame> {
    Ok(fvr_project_timed(ctx, spectrum, view, kernel, deapodize)?.0)
}

/// What a Dirichlet slice of a volume laid out as `layout` needs on the GPU: the work
/// within [`FvrLayout::check_dirichlet_work`]'s limit, at most [`DIRICHLET_MAX_NX`]
/// voxels along x, and the volume's f32 values in one storage binding. Each view
/// checks it, and so does `voxlab fvr --dry-run`, before the spectrum is made.
///
/// # Errors
/// [`Error::TooLarge`] saying which, and that the CPU has none of the last two limits.
pub fn check_dirichlet(limits: &wgpu::Limits, layout: &FvrLayout) -> Result<()> {
    layout.check_dirichlet_work()?;
    let dims = layout.dims();
    if dims[0] > DIRICHLET_MAX_NX {
        return Err(Error::too_large(
            "GPU Dirichlet slice",
            format!(
                "{} voxels along x exceed the {DIRICHLET_MAX_NX} the GPU's sum keeps: \
                 use --backend cpu",
                dims[0]
            ),
        ));
    }
    if dims.iter().product::<usize>() as u64 * 4 > crate::gpu::plan::binding_limit(limits) {
        return Err(Error::too_large(
            "GPU Dirichlet slice",
            "the volume's f32 values exceed one storage binding: use --backend cpu",
        ));
    }
    Ok(())
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
    let (code, radius) = kernel_code(kernel);
    let layout = &spectrum.layout;
    if kernel == Kernel::Dirichlet {
        check_dirichlet(&ctx.limits, layout)?;
    }
    let m = layout.side();
    let plan = SlicePlan::new(layout, view)?;
    let g = &plan.geometry;
    let params = FvrParams {
        m: m as u32,
        kernel: code,
        radius,
        slab_depth: spectrum.slab_depth as u32,
        right_x: g.right.x as f32,
        right_y: g.right.y as f32,
        right_z: g.right.z as f32,
        up_x: g.up.x as f32,
        up_y: g.up.y as f32,
        up_z: g.up.z as f32,
        dr: plan.dr as f32,
        du: plan.du as f32,
        nx: layout.dims()[0] as u32,
        ny: layout.dims()[1] as u32,
        nz: layout.dims()[2] as u32,
        ox: layout.offset()[0] as u32,
        oy: layout.offset()[1] as u32,
        oz: layout.offset()[2] as u32,
        pad0: 0,
        pad1: 0,
    };

    let fft_plan = &spectrum.fft;
    ctx.queue
        .write_buffer(&spectrum.params, 0, bytemuck::bytes_of(&params));
    let invocations = (m * m) as u32;
    let groups = invocations.div_ceil(WORKGROUP).max(1);
    let x = groups.min(ctx.limits.max_compute_workgroups_per_dimension.max(1));
    let y = groups.div_ceil(x);
    let setup = t0.elapsed().as_secs_f64();

    let t = Instant::now();
    let binds = std::slice::from_ref(&spectrum.bind);
    let pass = (&spectrum.pipeline, "extract_slice");
    let slice_kernel = ctx.run_pass(pass, binds, [x, y, 1], spectrum.query.as_ref())?;
    let slice_s = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let out = fft_plan.execute_buffer(ctx, &spectrum.slice)?;
    let fft = t.elapsed().as_secs_f64();
    let fft_kernel = out
        .timings
        .kernel_from_timestamps
        .then_some(out.timings.kernel);
    let image = out.data;

    let t = Instant::now();
    let frame = plan.crop(layout, kernel, deapodize, |i| image[i].re as f64);
    let crop = t.elapsed().as_secs_f64();
    Ok((
        frame,
        FvrTimings {
            setup,
            slice: slice_s,
            fft,
            crop,
            total: t0.elapsed().as_secs_f64(),
            kernel: slice_kernel.zip(fft_kernel).map(|(a, b)| a + b),
        },
    ))
}
