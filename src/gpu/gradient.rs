//! The precomputed gradient volume on the GPU: the port of
//! [`cpu::gradient::precompute_gradients`](crate::cpu::gradient::precompute_gradients).
//!
//! Each voxel's index-space gradient by central differences, forward differences or the
//! 3D Sobel stencil, with clamped neighbours at the border, exactly as the CPU defines
//! it (`shaders/shared/gradient_voxel.wgsl: gradient_at_voxel`, the stencil the ray
//! caster's set-up pass uses too). The volume goes up once as an `R32Float` 3D texture;
//! the gradients come back in slabs of z-slices small enough for one storage binding
//! (`shaders/gradient.wgsl`, one invocation per voxel, component-planar output), so any
//! volume the texture holds can be processed, also on adapters whose storage bindings
//! stop at 128 MiB.
//!
//! Parity: every tap is one f32 subtraction of two voxel values and a multiplication by
//! a power of two (or, for Sobel, nine weighted terms), so the GPU result equals the
//! CPU's f32 result up to the order of the Sobel sums (`tests/gpu_gradient.rs`).

use super::context::{buffer_entry, texture_entry, GpuContext, Kernel};
use crate::cpu::grid::Grid;
use crate::error::{Error, Result};
use crate::settings::GradientMethod;
use std::time::Instant;
use wgpu::util::DeviceExt;

/// `shaders/shared/gradient_params.wgsl`: the WGSL twin of [`GradientParams`].
pub const PARAMS_WGSL: &str = super::shaders::GRADIENT_PARAMS;

/// Parameters of one slab dispatch; twin of `shaders/shared/gradient_params.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GradientParams {
    /// nx, ny, nz; w = gradient method (0 central, 1 forward, 2 Sobel).
    pub dims: [u32; 4],
    /// First z-slice of the slab, slices in the slab.
    pub slab: [u32; 4],
}

/// The complete shader source: `shaders/gradient.wgsl` and its imports.
pub fn shader_source() -> String {
    super::shaders::resolve("gradient")
}

/// The code of a gradient method in `shaders/shared/gradient_voxel.wgsl:
/// gradient_at_voxel` (`GradientParams::dims.w`, `RaycastParams::flags2.x`).
pub(crate) fn gradient_method_id(m: GradientMethod) -> u32 {
    match m {
        GradientMethod::Central => 0,
        GradientMethod::Forward => 1,
        GradientMethod::Sobel => 2,
    }
}

/// Where the time went, in seconds.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GradientTimings {
    /// Shader and pipeline creation.
    pub setup: f64,
    /// The volume's upload (waited for).
    pub upload: f64,
    /// The slab dispatches alone: summed timestamp-query intervals when the adapter
    /// has them (`kernel_from_timestamps`), else waited wall time of the submissions.
    pub kernel: f64,
    pub kernel_from_timestamps: bool,
    /// Copies back to the host.
    pub readback: f64,
    /// Everything, set-up included.
    pub total: f64,
}

/// The three gradient components and the timings.
pub struct GpuGradients {
    pub components: [Grid<f32>; 3],
    pub timings: GradientTimings,
}

/// The gradient volume of `grid`: the x, y and z components (index space, value per
/// voxel). See [`precompute_gradients_timed`].
///
/// # Errors
/// As [`precompute_gradients_timed`].
pub fn precompute_gradients(
    ctx: &GpuContext,
    grid: &Grid<f32>,
    method: GradientMethod,
) -> Result<[Grid<f32>; 3]> {
    Ok(precompute_gradients_timed(ctx, grid, method)?.components)
}

/// [`precompute_gradients`] with the time of each stage.
///
/// # Errors
/// [`Error::Invalid`] when the grid's data do not fill its dimensions;
/// [`Error::TooLarge`] when the volume exceeds the adapter's 3D texture size or one
/// slice's three components exceed a storage binding; [`Error::Gpu`] on device failure.
pub fn precompute_gradients_timed(
    ctx: &GpuContext,
    grid: &Grid<f32>,
    method: GradientMethod,
) -> Result<GpuGradients> {
    precompute_gradients_in_slabs(ctx, grid, method, u64::MAX)
}

/// [`precompute_gradients_timed`] with each slab's output held to at most
/// `max_slab_bytes` (besides the adapter's storage-binding limit): bounds the device
/// memory used, and lets a small volume exercise the many-slab path.
///
/// # Errors
/// As [`precompute_gradients_timed`]; [`Error::TooLarge`] also when one slice's three
/// components exceed `max_slab_bytes`.
pub fn precompute_gradients_in_slabs(
    ctx: &GpuContext,
    grid: &Grid<f32>,
    method: GradientMethod,
    max_slab_bytes: u64,
) -> Result<GpuGradients> {
    let t0 = Instant::now();
    let [nx, ny, nz] = grid.dims;
    let voxels = nx * ny * nz;
    if grid.data.len() != voxels || voxels == 0 {
        return Err(Error::invalid(
            "gradient volume",
            format!("{} values for dimensions {:?}", grid.data.len(), grid.dims),
        ));
    }
    // Slices per slab: three f32 components of a slab must fit one storage binding.
    let slice_bytes = (3 * 4 * nx * ny) as u64;
    let binding = crate::gpu::plan::binding_limit(&ctx.limits).min(max_slab_bytes);
    let per_slab = (binding / slice_bytes).min(nz as u64) as usize;
    if per_slab == 0 {
        return Err(Error::too_large(
            "gradient volume",
            format!(
                "one {nx} × {ny} slice's three components ({slice_bytes} bytes) exceed the \
                 storage-binding limit of {binding} bytes"
            ),
        ));
    }
    let dev = &ctx.device;
    let Kernel { layout, pipeline } = ctx.kernel(
        "gradient.wgsl",
        &shader_source(),
        Some(&[
            buffer_entry(0, wgpu::BufferBindingType::Uniform),
            texture_entry(1, false),
            buffer_entry(2, wgpu::BufferBindingType::Storage { read_only: false }),
        ]),
        "gradient_slab",
    )?;
    let out = ctx.storage_buffer("gradient slab", per_slab as u64 * slice_bytes)?;
    let query = ctx.timestamps();
    ctx.wait()?;
    let setup = t0.elapsed().as_secs_f64();

    let t_up = Instant::now();
    let volume = ctx.upload_volume_r32(grid.dims, &grid.data)?;
    ctx.wait()?;
    let upload = t_up.elapsed().as_secs_f64();
    let view = volume.create_view(&Default::default());

    let mut comps: [Vec<f32>; 3] = std::array::from_fn(|_| Vec::with_capacity(voxels));
    let (mut kernel, mut readback) = (0.0, 0.0);
    let mut z0 = 0;
    while z0 < nz {
        let slices = per_slab.min(nz - z0);
        let params = GradientParams {
            dims: [nx as u32, ny as u32, nz as u32, gradient_method_id(method)],
            slab: [z0 as u32, slices as u32, 0, 0],
        };
        let pbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("gradient params"),
            contents: bytemuck::bytes_of(&params),
            usage: super::context::PARAMS_USAGE,
        });
        let bind = ctx.bind_group(
            "gradient",
            &layout,
            &[
                pbuf.as_entire_binding(),
                wgpu::BindingResource::TextureView(&view),
                out.as_entire_binding(),
            ],
        );
        let t_k = Instant::now();
        let extent = [
            (nx as u32).div_ceil(4),
            (ny as u32).div_ceil(4),
            (slices as u32).div_ceil(4),
        ];
        let device = ctx.run_pass(
            (&pipeline, "gradient_slab"),
            &[bind],
            extent,
            query.as_ref(),
        )?;
        kernel += device.unwrap_or_else(|| t_k.elapsed().as_secs_f64());
        let t_r = Instant::now();
        let n = slices * nx * ny;
        let bytes = ctx.read_buffer(&out, (3 * n * 4) as u64)?;
        let vals: &[f32] = bytemuck::cast_slice(&bytes);
        for (c, comp) in comps.iter_mut().enumerate() {
            comp.extend_from_slice(&vals[c * n..(c + 1) * n]);
        }
        readback += t_r.elapsed().as_secs_f64();
        z0 += slices;
    }
    let components = comps.map(|data| Grid {
        dims: grid.dims,
        data,
    });
    Ok(GpuGradients {
        components,
        timings: GradientTimings {
            setup,
            upload,
            kernel,
            kernel_from_timestamps: query.is_some(),
            readback,
            total: t0.elapsed().as_secs_f64(),
        },
    })
}
