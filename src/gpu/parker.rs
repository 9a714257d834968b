//! Parker's short-scan weights on the GPU: the port of
//! [`cpu::parker::weigh`](crate::cpu::parker::weigh) (`shaders/parker.wgsl`, one
//! invocation per projection pixel, in chunks of whole views that fit one storage
//! binding). The scan's parameters (`δ`, the scale, the first angle) come from
//! [`cpu::parker::short_scan`](crate::cpu::parker::short_scan), the same checks and
//! errors as on the CPU. Each view's `β` and each column's fan angle `γ` are computed
//! in f64 on the host and rounded once (WGSL's `atan` may be off by 4096 ulp); the
//! weight itself is evaluated in f32 on the device, with a polynomial sine (WGSL's
//! `sin` may be off by 2⁻¹¹).

use super::context::{buffer_entry, GpuContext, Kernel};
use crate::cpu::parker::{fan_angle, short_scan};
use crate::ct::{Geometry, Projections};
use crate::error::{Error, Result};
use wgpu::util::DeviceExt;

/// `shaders/shared/parker_params.wgsl`: the WGSL twin of [`ParkerParams`].
pub const PARAMS_WGSL: &str = super::shaders::PARKER_PARAMS;

const WORKGROUP: u32 = 64;

/// Parameters of one chunk; twin of `shaders/shared/parker_params.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ParkerParams {
    /// Columns, rows, views in this chunk, first view of the chunk.
    pub dims: [u32; 4],
    /// Unused ×3, δ (radians).
    pub detector: [f32; 4],
    /// Scale `A·Δβ/π`, unused ×3.
    pub scan: [f32; 4],
    /// x extent of the dispatch in invocations, unused ×3.
    pub work: [u32; 4],
}

/// The complete shader source: `shaders/parker.wgsl` and its imports.
pub fn shader_source() -> String {
    super::shaders::resolve("parker")
}

/// The projections multiplied by Parker's weights and the short-scan scale, on the GPU
/// in f32.
///
/// # Errors
/// As `cpu::parker::weigh`; [`Error::TooLarge`] when one view exceeds a storage
/// binding; [`Error::Gpu`] on device failure.
pub fn weigh(ctx: &GpuContext, p: &Projections<f32>, g: &Geometry) -> Result<Projections<f32>> {
    p.check_against(g)?;
    if p.data.iter().any(|v| !v.is_finite()) {
        return Err(Error::invalid(
            "projections",
            "contain NaN or infinite values",
        ));
    }
    let s = short_scan(g)?;
    let (rows, cols, views) = (g.rows, g.cols, g.n_angles());
    let per_view = rows * cols;
    let mut out = p.data.clone();
    if per_view == 0 {
        return Projections::new(views, rows, cols, out);
    }
    let limit = crate::gpu::plan::binding_limit(&ctx.limits);
    let view_bytes = (per_view * 4) as u64;
    if view_bytes > limit {
        return Err(Error::too_large(
            "Parker weights",
            format!("one view ({view_bytes} bytes) exceeds one storage binding ({limit} bytes)"),
        ));
    }
    // Views per chunk: the binding limit, and at most 2²² invocations per dispatch.
    let per_chunk = ((limit / view_bytes) as usize)
        .min((1 << 22) / per_view)
        .clamp(1, views);
    let dev = &ctx.device;
    let Kernel { layout, pipeline } = ctx.kernel(
        "parker.wgsl",
        &shader_source(),
        Some(&[
            buffer_entry(0, wgpu::BufferBindingType::Uniform),
            buffer_entry(1, wgpu::BufferBindingType::Storage { read_only: true }),
            buffer_entry(2, wgpu::BufferBindingType::Storage { read_only: false }),
            buffer_entry(3, wgpu::BufferBindingType::Storage { read_only: true }),
        ]),
        "parker_weigh",
    )?;
    // β of every view, computed in f64 and rounded once.
    let betas: Vec<f32> = g
        .angles_deg
        .iter()
        .map(|&a| (a - s.first_deg).to_radians() as f32)
        .collect();
    let abuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("parker betas"),
        contents: bytemuck::cast_slice(&betas),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let gammas: Vec<f32> = (0..cols)
        .map(|c| fan_angle(g, s.sdd, c as f64) as f32)
        .collect();
    let gbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("parker gammas"),
        contents: bytemuck::cast_slice(&gammas),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let max_x = ctx.limits.max_compute_workgroups_per_dimension.max(1);
    for (c, chunk) in out.chunks_mut(per_chunk * per_view).enumerate() {
        let n_views = chunk.len() / per_view;
        let groups = ((chunk.len() as u32).div_ceil(WORKGROUP)).max(1);
        let gx = groups.min(max_x);
        let gy = groups.div_ceil(gx);
        let params = ParkerParams {
            dims: [
                cols as u32,
                rows as u32,
                n_views as u32,
                (c * per_chunk) as u32,
            ],
            detector: [0.0, 0.0, 0.0, s.delta as f32],
            scan: [s.scale as f32, 0.0, 0.0, 0.0],
            work: [gx * WORKGROUP, 0, 0, 0],
        };
        let pbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("parker params"),
            contents: bytemuck::bytes_of(&params),
            usage: super::context::PARAMS_USAGE,
        });
        let dbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("parker views"),
            contents: bytemuck::cast_slice(chunk),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        });
        let bind = ctx.bind_group(
            "parker",
            &layout,
            &[
                pbuf.as_entire_binding(),
                abuf.as_entire_binding(),
                dbuf.as_entire_binding(),
                gbuf.as_entire_binding(),
            ],
        );
        let mut enc = dev.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(gx, gy, 1);
        }
        ctx.queue.submit([enc.finish()]);
        let bytes = ctx.read_buffer(&dbuf, (chunk.len() * 4) as u64)?;
        chunk.copy_from_slice(bytemuck::cast_slice(&bytes));
    }
    Projections::new(views, rows, cols, out)
}
