//! The min/max grid of empty-space skipping, built on the GPU: a port of
//! `cpu::skip::min_max_grid` (see `cpu::skip` for the grid, the footprint and the
//! emptiness test). One workgroup per cell: 64 invocations stride through the cell's
//! footprint of `(B + 2r + 2)³` voxels and reduce in workgroup memory
//! (`shaders/skip_minmax.wgsl`). Min and max are exact, so the grid equals the CPU's
//! f32 grid bit for bit. The per-ray walk runs inside the ray caster
//! (`shaders/shared/skip.wgsl`).

use super::context::{buffer_entry, texture_entry, GpuContext, Kernel};
use crate::cpu::grid::Grid;
use crate::cpu::skip::{cell_count, MinMaxGrid};
use crate::error::Result;
use wgpu::util::DeviceExt;

/// The grid-building shader, `shaders/skip_minmax.wgsl` (it imports nothing). The
/// per-ray helpers are `shaders/shared/skip.wgsl`, imported by the ray caster.
pub const MINMAX_WGSL: &str = super::shaders::SKIP_MINMAX;

/// Parameters of the grid build; twin of `SkipGridParams` in `shaders/skip_minmax.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SkipGridParams {
    pub dims: [u32; 4],
    pub cells: [u32; 4],
    pub misc: [u32; 4],
}

/// The most footprint voxels one invocation may visit on a CPU Vulkan driver
/// (llvmpipe stops every loop of an invocation after 65535 iterations in total).
const MAX_PER_INVOCATION: usize = 60_000;

/// Builds the grid of `volume` (an `R32Float` texture of `dims`) into a storage buffer
/// of `[min, max]` pairs (x fastest). Falls back to the CPU build (identical values)
/// when a cell's footprint is too large for one workgroup's loop on a CPU adapter.
pub fn min_max_buffer(
    ctx: &GpuContext,
    volume: &wgpu::Texture,
    values: &Grid<f32>,
    block: usize,
    radius: usize,
) -> Result<wgpu::Buffer> {
    let kernel = &mut || Ok(minmax_kernel(ctx)?.0);
    min_max_buffer_with(ctx, Some(volume), values, (block, radius), kernel)
}

/// The bindings of `shaders/skip_minmax.wgsl`.
const MINMAX_BINDINGS: [wgpu::BindGroupLayoutEntry; 3] = [
    buffer_entry(0, wgpu::BufferBindingType::Uniform),
    texture_entry(1, false),
    buffer_entry(2, wgpu::BufferBindingType::Storage { read_only: false }),
];

/// The grid's pipeline (`shaders/skip_minmax.wgsl: skip_minmax`) from the device's kept
/// programs, and whether it was compiled now ([`super::context::Program::kernel`]).
pub(crate) fn minmax_kernel(ctx: &GpuContext) -> Result<(Kernel, bool)> {
    ctx.program(
        "skip_minmax.wgsl",
        &super::shaders::resolve("skip_minmax"),
        Some(&MINMAX_BINDINGS),
    )?
    .kernel(ctx, "skip_minmax")
}

/// [`min_max_buffer`] of `(block, radius)`, built on the CPU without `volume` (no
/// `R32Float` texture of the values on the device); `kernel` gives the pipeline when
/// the device builds it (a renderer session's own, [`minmax_kernel`]).
pub(crate) fn min_max_buffer_with(
    ctx: &GpuContext,
    volume: Option<&wgpu::Texture>,
    values: &Grid<f32>,
    (block, radius): (usize, usize),
    kernel: &mut dyn FnMut() -> Result<Kernel>,
) -> Result<wgpu::Buffer> {
    let dims = values.dims;
    let cells = cell_count(dims, block);
    let n_cells = cells[0] * cells[1] * cells[2];
    let foot = (block + 2 * radius + 2).min(dims.into_iter().max().unwrap_or(1));
    let too_long = ctx.summary.is_cpu() && foot.pow(3) / 64 > MAX_PER_INVOCATION;
    let Some(volume) = volume.filter(|_| !too_long) else {
        let g = crate::cpu::skip::min_max_grid(values, block, radius);
        let buffer = ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("skip minmax"),
                contents: bytemuck::cast_slice(&g.minmax),
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            });
        return Ok(buffer);
    };
    let dev = &ctx.device;
    let Kernel { layout, pipeline } = kernel()?;
    let out = ctx.storage_buffer("skip minmax", (n_cells * 8) as u64)?;
    let view = volume.create_view(&Default::default());
    // Slabs of cell rows per submission keep each dispatch short on slow adapters.
    let per_slab = ((1usize << 24) / (foot.pow(3) * cells[0] * cells[1]).max(1)).max(1);
    let mut z0 = 0;
    while z0 < cells[2] {
        let nz = per_slab.min(cells[2] - z0);
        let p = SkipGridParams {
            dims: [dims[0] as u32, dims[1] as u32, dims[2] as u32, 0],
            cells: [
                cells[0] as u32,
                cells[1] as u32,
                cells[2] as u32,
                block as u32,
            ],
            misc: [radius as u32, z0 as u32, 0, 0],
        };
        let pbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("skip grid params"),
            contents: bytemuck::bytes_of(&p),
            usage: super::context::PARAMS_USAGE,
        });
        let bind = ctx.bind_group(
            "skip minmax",
            &layout,
            &[
                pbuf.as_entire_binding(),
                wgpu::BindingResource::TextureView(&view),
                out.as_entire_binding(),
            ],
        );
        let mut enc = dev.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(cells[0] as u32, cells[1] as u32, nz as u32);
        }
        ctx.queue.submit([enc.finish()]);
        ctx.wait()?;
        z0 += nz;
    }
    Ok(out)
}

/// Builds the min/max grid of `grid` on the GPU and reads it back: the GPU twin of
/// `cpu::skip::min_max_grid`.
pub fn min_max_grid(
    ctx: &GpuContext,
    grid: &Grid<f32>,
    block: usize,
    radius: usize,
) -> Result<MinMaxGrid<f32>> {
    let tex = ctx.upload_volume_r32(grid.dims, &grid.data)?;
    let buf = min_max_buffer(ctx, &tex, grid, block, radius)?;
    let cells = cell_count(grid.dims, block);
    let n = cells[0] * cells[1] * cells[2];
    let bytes = ctx.read_buffer(&buf, (n * 8) as u64)?;
    Ok(MinMaxGrid {
        block,
        radius,
        cells,
        minmax: bytemuck::cast_slice::<u8, [f32; 2]>(&bytes).to_vec(),
    })
}
