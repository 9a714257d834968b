//! The fast tricubic B-spline on the GPU (`shaders/shared/tricubic.wgsl`, the twin of
//! `cpu::tricubic`), evaluated at a list of points: what the ray caster does per sample
//! with `cubic-bspline-fast`, exposed so that both of its paths can be measured point
//! by point against the f64 oracle.
//!
//! - the *manual* path does each of the 8 trilinear fetches with 8 `textureLoad`s and
//!   f32 weights: the oracle's arithmetic in f32;
//! - the *hardware* path asks the texture unit for the 8 trilinear fetches
//!   (`textureSampleLevel`, linear `ClampToEdge` sampler; needs `FLOAT32_FILTERABLE`).
//!   Real GPUs compute the sampler's lerp fractions in fixed point with
//!   `subTexelPrecisionBits` (8 on NVIDIA) fractional bits; lavapipe lerps in f32.
//!
//! Shader: `shaders/tricubic_points.wgsl`, importing `shaders/shared/tricubic.wgsl`.

use super::context::GpuContext;
use crate::cpu::grid::Grid;
use crate::error::{Error, Result};
use wgpu::util::DeviceExt;

/// The most points one call takes (one dispatch of 64-wide workgroups).
pub const MAX_POINTS: usize = 65535 * 64;

/// The fast cubic B-spline of `grid` (values, or prefiltered coefficients) at
/// index-space `points`, on the GPU: through the texture unit when `hardware`, by hand
/// otherwise. Mirrors `src/cpu/tricubic.rs: sample_fast`.
///
/// # Errors
/// [`Error::Invalid`] for an empty grid, [`Error::TooLarge`] past [`MAX_POINTS`] or the
/// adapter's limits, [`Error::Gpu`] without `FLOAT32_FILTERABLE` for `hardware`, or on
/// device failure.
pub fn sample_fast(
    ctx: &GpuContext,
    grid: &Grid<f32>,
    points: &[[f32; 3]],
    hardware: bool,
) -> Result<Vec<f32>> {
    if grid.data.is_empty() || grid.data.len() != grid.dims.iter().product::<usize>() {
        return Err(Error::invalid(
            "grid",
            "needs dims[0]·dims[1]·dims[2] > 0 values",
        ));
    }
    if points.is_empty() {
        return Ok(Vec::new());
    }
    if points.len() > MAX_POINTS {
        return Err(Error::too_large(
            "points",
            format!("{} points exceed one dispatch's {MAX_POINTS}", points.len()),
        ));
    }
    if hardware {
        ctx.require_float32_filtering()?;
    }
    let dev = &ctx.device;
    let entry = if hardware {
        "sample_points_hw"
    } else {
        "sample_points_exact"
    };
    let super::context::Kernel { layout, pipeline } = ctx.kernel(
        "tricubic_points.wgsl",
        &super::shaders::resolve("tricubic_points"),
        None,
        entry,
    )?;
    let n = points.len();
    let count = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("tricubic count"),
        contents: bytemuck::cast_slice(&[n as u32, 0, 0, 0]),
        usage: super::context::PARAMS_USAGE,
    });
    let tex = ctx.upload_volume_r32(grid.dims, &grid.data)?;
    let view = tex.create_view(&Default::default());
    let padded: Vec<[f32; 4]> = points.iter().map(|p| [p[0], p[1], p[2], 0.0]).collect();
    let pbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("tricubic points"),
        contents: bytemuck::cast_slice(&padded),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let out = ctx.storage_buffer("tricubic values", 4 * n as u64)?;
    let sampler = ctx.clamp_sampler("linear clamp", wgpu::FilterMode::Linear);
    let mut resources = vec![
        count.as_entire_binding(),
        wgpu::BindingResource::TextureView(&view),
        pbuf.as_entire_binding(),
        out.as_entire_binding(),
    ];
    if hardware {
        resources.push(wgpu::BindingResource::Sampler(&sampler));
    }
    let bind = ctx.bind_group("tricubic points", &layout, &resources);
    let mut enc = dev.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups((n as u32).div_ceil(64), 1, 1);
    }
    ctx.queue.submit([enc.finish()]);
    let bytes = ctx.read_buffer(&out, 4 * n as u64)?;
    Ok(bytemuck::cast_slice(&bytes).to_vec())
}
