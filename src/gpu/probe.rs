//! The smallest end-to-end GPU check: `y[i] = a·x[i] + b` on the device, compared with
//! the same f32 arithmetic on the CPU. `voxlab info --gpu` runs it, and so does the GPU
//! test suite before anything else, so a broken driver is reported as such rather than
//! as a wrong image.
//!
//! Shader: `shaders/probe.wgsl`. The CPU twin is [`saxpy_cpu`].

use super::context::GpuContext;
use crate::error::{Error, Result};
use wgpu::util::DeviceExt;

/// Parameters shared with `shaders/probe.wgsl: Params` (16 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ProbeParams {
    pub a: f32,
    pub b: f32,
    pub n: u32,
    pub _pad: u32,
}

/// The WGSL source, `shaders/probe.wgsl` (it imports nothing).
pub const SHADER: &str = super::shaders::PROBE;

/// The CPU twin of `shaders/probe.wgsl: saxpy` (one fused-free multiply-add in f32).
pub fn saxpy_cpu(a: f32, x: f32, b: f32) -> f32 {
    a * x + b
}

/// Runs the probe on `x`; returns the device's `a·x + b`.
pub fn saxpy_gpu(ctx: &GpuContext, a: f32, b: f32, x: &[f32]) -> Result<Vec<f32>> {
    if x.is_empty() {
        return Ok(Vec::new());
    }
    let n =
        u32::try_from(x.len()).map_err(|_| Error::too_large("probe input", "over 2^32 values"))?;
    let dev = &ctx.device;
    let params = ProbeParams { a, b, n, _pad: 0 };
    let pbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("probe params"),
        contents: bytemuck::bytes_of(&params),
        usage: super::context::PARAMS_USAGE,
    });
    let xbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("probe x"),
        contents: bytemuck::cast_slice(x),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let bytes = std::mem::size_of_val(x) as u64;
    let ybuf = dev.create_buffer(&wgpu::BufferDescriptor {
        label: Some("probe y"),
        size: bytes,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    dispatch_1d(
        ctx,
        "probe",
        "saxpy",
        &[
            pbuf.as_entire_binding(),
            xbuf.as_entire_binding(),
            ybuf.as_entire_binding(),
        ],
        n,
    )?;
    let out = ctx.read_buffer(&ybuf, bytes)?;
    Ok(bytemuck::cast_slice(&out).to_vec())
}

/// Runs the probe on a fixed input and checks every value against the CPU twin.
/// Returns how many values were checked.
pub fn self_test(ctx: &GpuContext) -> Result<usize> {
    let x: Vec<f32> = (0..4099).map(|i| (i as f32) * 0.37 - 500.0).collect();
    let (a, b) = (1.5f32, -0.25f32);
    let y = saxpy_gpu(ctx, a, b, &x)?;
    for (i, (&xi, &yi)) in x.iter().zip(&y).enumerate() {
        let want = saxpy_cpu(a, xi, b);
        // A fused multiply-add may differ from the CPU's two roundings by one ulp.
        if (yi - want).abs() > want.abs() * 2.0 * f32::EPSILON {
            return Err(Error::Gpu(format!(
                "probe mismatch at {i}: device {yi}, CPU {want}: the driver computes wrongly"
            )));
        }
    }
    Ok(x.len())
}

/// Evaluates the compositing shaders' `ln_1p`, `exp_m1` and `step_opacity`
/// (`shaders/shared/opacity.wgsl`, through `shaders/opacity_probe.wgsl`) on the device:
/// each input `[x₁, x₂, a, r]` gives `[ln_1p(x₁), exp_m1(x₂), step_opacity(a, r)]`.
pub fn opacity_gpu(ctx: &GpuContext, inputs: &[[f32; 4]]) -> Result<Vec<[f32; 3]>> {
    if inputs.is_empty() {
        return Ok(Vec::new());
    }
    let n = u32::try_from(inputs.len())
        .map_err(|_| Error::too_large("opacity probe input", "over 2^32 values"))?;
    let dev = &ctx.device;
    let xbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("opacity probe in"),
        contents: bytemuck::cast_slice(inputs),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let bytes = std::mem::size_of_val(inputs) as u64;
    let ybuf = ctx.storage_buffer("opacity probe out", bytes)?;
    dispatch_1d(
        ctx,
        "opacity_probe",
        "main",
        &[xbuf.as_entire_binding(), ybuf.as_entire_binding()],
        n,
    )?;
    let out = ctx.read_buffer(&ybuf, bytes)?;
    let out: &[[f32; 4]] = bytemuck::cast_slice(&out);
    Ok(out.iter().map(|v| [v[0], v[1], v[2]]).collect())
}

/// Runs `entry` of `shaders/<name>.wgsl` over `n` invocations (workgroups of 64), the
/// bindings in group 0 in order, and submits.
fn dispatch_1d(
    ctx: &GpuContext,
    name: &str,
    entry: &str,
    bindings: &[wgpu::BindingResource],
    n: u32,
) -> Result<()> {
    let super::context::Kernel { layout, pipeline } = ctx.kernel(
        &format!("{name}.wgsl"),
        &super::shaders::resolve(name),
        None,
        entry,
    )?;
    let bind = ctx.bind_group(name, &layout, bindings);
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups(n.div_ceil(64), 1, 1);
    }
    ctx.queue.submit([enc.finish()]);
    Ok(())
}
