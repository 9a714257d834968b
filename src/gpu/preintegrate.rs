//! The pre-integrated transfer function on the GPU: one invocation per table entry,
//! the same sub-step definition as `cpu::preintegrate` (see its docs), in f32.
//! Shader: `shaders/preintegrate.wgsl`; parameters: [`AdaptiveParams`] (the adaptive
//! caster's block, in `gpu::params`).

use super::context::{buffer_entry, GpuContext, Kernel};
use super::params::AdaptiveParams;
use crate::error::{Error, Result};
use crate::transfer::TransferFunction;
use wgpu::util::DeviceExt;

/// Builds the table on the device: `n × n` entries `(C_r, C_g, C_b, α)`, front value
/// along the fast axis, in a storage buffer (`STORAGE | COPY_SRC`).
pub fn preintegrate_buffer(
    ctx: &GpuContext,
    tf: &TransferFunction,
    n: usize,
) -> Result<wgpu::Buffer> {
    tf.validate()?;
    if !(2..=1024).contains(&n) {
        return Err(Error::invalid(
            "pre-integration size",
            "must lie in 2..=1024",
        ));
    }
    let lut = tf.lut(n).to_real::<f32>();
    let dev = &ctx.device;
    let ro = wgpu::BufferBindingType::Storage { read_only: true };
    let rw = wgpu::BufferBindingType::Storage { read_only: false };
    let Kernel { layout, pipeline } = ctx.kernel(
        "preintegrate.wgsl",
        &super::shaders::resolve("preintegrate"),
        Some(&[
            buffer_entry(0, wgpu::BufferBindingType::Uniform),
            buffer_entry(1, ro),
            buffer_entry(2, rw),
        ]),
        "preintegrate",
    )?;
    let mut params = AdaptiveParams::default();
    params.table[0] = n as u32;
    let pbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("preintegrate params"),
        contents: bytemuck::bytes_of(&params),
        usage: super::context::PARAMS_USAGE,
    });
    let lut_buf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("lut"),
        contents: bytemuck::cast_slice(&lut.entries),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let table = ctx.storage_buffer("preintegrated table", (n * n * 16) as u64)?;
    let bind = ctx.bind_group(
        "preintegrate",
        &layout,
        &[
            pbuf.as_entire_binding(),
            lut_buf.as_entire_binding(),
            table.as_entire_binding(),
        ],
    );
    let mut enc = dev.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups((n as u32).div_ceil(8), (n as u32).div_ceil(8), 1);
    }
    ctx.queue.submit([enc.finish()]);
    Ok(table)
}

/// Builds the table on the device and reads it back (`entries[j·n + i]`, as
/// `cpu::preintegrate::PreintTable::entries`).
pub fn preintegrate(ctx: &GpuContext, tf: &TransferFunction, n: usize) -> Result<Vec<[f32; 4]>> {
    let buf = preintegrate_buffer(ctx, tf, n)?;
    let bytes = ctx.read_buffer(&buf, (n * n * 16) as u64)?;
    Ok(bytemuck::cast_slice(&bytes).to_vec())
}
