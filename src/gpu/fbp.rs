//! FBP and FDK on the GPU: the backprojection of `crate::cpu::fbp` as a WGSL compute
//! shader (`shaders/fbp_backproject.wgsl`), one invocation per voxel looping over a
//! chunk of views (several dispatches keep each one short on software drivers).
//!
//! The view matrices are uploaded as `ViewMatrix<f32>` (WGSL `CtView`), the filtered
//! projections as one f32 storage buffer. [`fbp`] runs the whole reconstruction on
//! the GPU: ramp filtering with [`crate::gpu::ramp::filter_projections`] (cosine
//! pre-weighting, batched FFTs, the response, cropping), then [`backproject`].

use crate::cpu::fbp::{backprojection_scale, Grid, Reconstruction};
use crate::cpu::ramp::RampFilter;
use crate::ct::{Geometry, Projections};
use crate::error::{Error, Result};
use crate::gpu::GpuContext;
use crate::volume::check_dims;
use wgpu::util::DeviceExt;

/// The shader's uniform block.
///
/// WGSL twin: shaders/shared/fbp_params.wgsl: FbpParams
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct FbpParams {
    pub origin: [f32; 4],
    pub step_i: [f32; 4],
    pub step_j: [f32; 4],
    pub step_k: [f32; 4],
    pub dims: [u32; 4],
    pub det: [u32; 4],
    pub scale: [f32; 4],
}

const WORKGROUP: u32 = 64;
/// Views per dispatch: bounded work per invocation.
const VIEWS_PER_DISPATCH: usize = 32;

/// The shader source: `shaders/fbp_backproject.wgsl` and its imports (the shared CT
/// geometry and `FbpParams`).
pub fn shader_source() -> String {
    super::shaders::resolve("fbp_backproject")
}

/// Backprojects filtered projections onto `grid` on the GPU (f32); the same sum as
/// `cpu::fbp::backproject`.
pub fn backproject(
    ctx: &GpuContext,
    filtered: &Projections<f32>,
    g: &Geometry,
    grid: &Grid,
) -> Result<Reconstruction<f32>> {
    g.validate()?;
    filtered.check_against(g)?;
    let n = check_dims(grid.dims)?;
    let dev = &ctx.device;
    let limit = ctx.limits.max_storage_buffer_binding_size;
    if (filtered.data.len() as u64) * 4 > limit {
        return Err(Error::too_large(
            "GPU projections",
            format!("{} values exceed one storage binding", filtered.data.len()),
        ));
    }
    let views = g.view_matrices::<f32>();
    let vbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("fbp views"),
        contents: bytemuck::cast_slice(&views),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let pbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("fbp projections"),
        contents: bytemuck::cast_slice(&filtered.data),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let out = ctx.storage_buffer("fbp volume", (n * 4) as u64)?;
    let module = ctx.shader("fbp_backproject.wgsl", &shader_source())?;
    let pipeline = dev.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("backproject_point"),
        layout: None,
        module: &module,
        entry_point: Some("backproject_point"),
        compilation_options: Default::default(),
        cache: None,
    });
    let groups = (n as u32).div_ceil(WORKGROUP).max(1);
    let gx = groups.min(ctx.limits.max_compute_workgroups_per_dimension.max(1));
    let gy = groups.div_ceil(gx);
    let a = grid.affine;
    let v4 = |v: glam::DVec3| [v.x as f32, v.y as f32, v.z as f32, 0.0];
    let scale = backprojection_scale(g.n_angles()) as f32;
    let mut start = 0;
    while start < g.n_angles() {
        let count = VIEWS_PER_DISPATCH.min(g.n_angles() - start);
        let params = FbpParams {
            origin: v4(a.w_axis.truncate()),
            step_i: v4(a.x_axis.truncate()),
            step_j: v4(a.y_axis.truncate()),
            step_k: v4(a.z_axis.truncate()),
            dims: [
                grid.dims[0] as u32,
                grid.dims[1] as u32,
                grid.dims[2] as u32,
                gx * WORKGROUP,
            ],
            det: [g.cols as u32, g.rows as u32, start as u32, count as u32],
            scale: [scale, 0.0, 0.0, 0.0],
        };
        let ubuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("fbp params"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let bind = ctx.bind_group(
            "fbp",
            &pipeline.get_bind_group_layout(0),
            &[
                ubuf.as_entire_binding(),
                vbuf.as_entire_binding(),
                pbuf.as_entire_binding(),
                out.as_entire_binding(),
            ],
        );
        let mut enc = dev.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("backproject_point"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(gx, gy, 1);
        }
        ctx.queue.submit([enc.finish()]);
        ctx.wait()?;
        start += count;
    }
    let bytes = ctx.read_buffer(&out, (n * 4) as u64)?;
    Ok(Reconstruction {
        grid: *grid,
        data: bytemuck::cast_slice(&bytes).to_vec(),
    })
}

/// FBP/FDK on the GPU in f32: [`crate::gpu::ramp::filter_projections`], then
/// [`backproject`]; the same reconstruction as `cpu::fbp::fbp`.
pub fn fbp(
    ctx: &GpuContext,
    projections: &Projections<f32>,
    g: &Geometry,
    filter: RampFilter,
    grid: &Grid,
) -> Result<Reconstruction<f32>> {
    let q = crate::gpu::ramp::filter_projections(ctx, projections, g, filter)?;
    backproject(ctx, &q, g, grid)
}
