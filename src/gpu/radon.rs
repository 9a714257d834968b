//! scikit-image's Radon transform and the backprojection of its `iradon` on the GPU:
//! the port of [`crate::cpu::radon`] (`shaders/radon.wgsl`), in f32.
//!
//! - [`radon_square`]: one invocation per sinogram bin and angle; it warps the square
//!   image by the angle's inverse map (bilinear, zero outside) and sums the rows in
//!   order, as `cpu::radon::radon_column` does. The CPU blends the two interpolated
//!   rows in f64 (scikit-image's `top`/`bottom` are doubles); WGSL has no f64, so the
//!   port blends in f32 and differs from the CPU f32 path by that rounding.
//! - [`iradon_backproject`]: one invocation per output pixel; it sums, over the angles
//!   in order, the filtered view read at `t = y·cos θ − x·sin θ` by the interpolation
//!   (`iradon_sample`, the same arithmetic as the CPU's in f32), masks the inscribed
//!   circle and scales by `π/(2A)`. The cubic spline's curvatures are solved on the
//!   host by `cpu::radon::spline_curvatures` (a sequential recurrence along each line,
//!   as the ray caster's B-spline prefilter) and uploaded beside the views.
//!
//! Each invocation loops over the image's rows (radon) or the angles (iradon); on a
//! CPU adapter (llvmpipe) that loop is capped at [`LLVMPIPE_LOOP_LIMIT`] iterations,
//! and longer loops are refused. Every buffer must fit one storage binding.

use super::context::{buffer_entry, GpuContext, Kernel, LLVMPIPE_LOOP_LIMIT};
use crate::cpu::radon::{Angle, Interpolation};
use crate::error::{Error, Result};
use wgpu::util::DeviceExt;

/// `shaders/shared/radon_params.wgsl`: the WGSL twin of [`RadonParams`].
pub const PARAMS_WGSL: &str = super::shaders::RADON_PARAMS;

const WORKGROUP: u32 = 64;

/// Parameters of one dispatch; twin of `shaders/shared/radon_params.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct RadonParams {
    /// radon: square side, angles, unused ×2; iradon: bins, angles, output side,
    /// interpolation ([`Interpolation::id`]).
    pub dims: [u32; 4],
    /// x extent of the dispatch in invocations, circle mask (iradon), unused ×2.
    pub work: [u32; 4],
    /// iradon: π and 2A in f32, unused ×2.
    pub scale: [f32; 4],
}

/// The complete shader source: `shaders/radon.wgsl` and its imports.
pub fn shader_source() -> String {
    super::shaders::resolve("radon")
}

/// Refuses a loop longer than a CPU adapter runs per invocation.
fn check_loop(ctx: &GpuContext, what: &str, iterations: usize) -> Result<()> {
    if ctx.summary.is_cpu() && iterations > LLVMPIPE_LOOP_LIMIT - 16 {
        return Err(Error::invalid(
            what,
            format!(
                "{iterations} iterations per invocation exceed the {LLVMPIPE_LOOP_LIMIT} \
                 loop iterations a CPU Vulkan driver (llvmpipe) runs; use the CPU backend"
            ),
        ));
    }
    Ok(())
}

/// A read-only storage buffer of `data`, refused past one binding.
fn upload(ctx: &GpuContext, label: &str, data: &[u8]) -> Result<wgpu::Buffer> {
    ctx.check_storage(label, data.len() as u64)?;
    let zero = [0u8; 16];
    Ok(ctx
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: if data.is_empty() { &zero } else { data },
            usage: wgpu::BufferUsages::STORAGE,
        }))
}

/// Runs `entry` of `shaders/radon.wgsl` over `invocations` with these bindings and
/// reads `out_len` values back.
fn dispatch(
    ctx: &GpuContext,
    entry: &str,
    mut params: RadonParams,
    (src, aux, trig): (&wgpu::Buffer, &wgpu::Buffer, &wgpu::Buffer),
    invocations: usize,
    out_len: usize,
) -> Result<Vec<f32>> {
    let dev = &ctx.device;
    let storage = |read_only| wgpu::BufferBindingType::Storage { read_only };
    let Kernel { layout, pipeline } = ctx.kernel(
        "radon.wgsl",
        &shader_source(),
        Some(&[
            buffer_entry(0, wgpu::BufferBindingType::Uniform),
            buffer_entry(1, storage(true)),
            buffer_entry(2, storage(true)),
            buffer_entry(3, storage(true)),
            buffer_entry(4, storage(false)),
        ]),
        entry,
    )?;
    let groups = (invocations as u32).div_ceil(WORKGROUP).max(1);
    let gx = groups.min(ctx.limits.max_compute_workgroups_per_dimension.max(1));
    let gy = groups.div_ceil(gx);
    params.work[0] = gx * WORKGROUP;
    let pbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("radon params"),
        contents: bytemuck::bytes_of(&params),
        usage: super::context::PARAMS_USAGE,
    });
    let out_bytes = (out_len * 4) as u64;
    let out = ctx.storage_buffer("radon output", out_bytes)?;
    let bind = ctx.bind_group(
        "radon",
        &layout,
        &[
            pbuf.as_entire_binding(),
            src.as_entire_binding(),
            aux.as_entire_binding(),
            trig.as_entire_binding(),
            out.as_entire_binding(),
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
    ctx.wait()?;
    Ok(bytemuck::cast_slice(&ctx.read_buffer(&out, out_bytes)?).to_vec())
}

/// The sinogram `(side, angles)` (row-major: bin, then angle) of a square image
/// (`side²`, row-major), one inverse map per angle (`cpu::radon::rotation`, rounded to
/// f32): the port of `cpu::radon::radon_square`.
///
/// # Errors
/// An image that is not `side²` values; a buffer past one binding
/// ([`Error::TooLarge`]); on a CPU adapter more than its loop limit of rows;
/// [`Error::Gpu`] on device failure.
pub fn radon_square(
    ctx: &GpuContext,
    img: &[f32],
    side: usize,
    maps: &[[f64; 6]],
) -> Result<Vec<f32>> {
    if img.len() != side * side {
        return Err(Error::invalid(
            "image",
            format!("{} values for a {side} × {side} square", img.len()),
        ));
    }
    let out_len = side * maps.len();
    if out_len == 0 {
        return Ok(Vec::new());
    }
    check_loop(ctx, "image", side)?;
    let coefficients: Vec<f32> = maps.iter().flatten().map(|&v| v as f32).collect();
    let src = upload(ctx, "radon image", bytemuck::cast_slice(img))?;
    let aux = upload(ctx, "radon maps", bytemuck::cast_slice(&coefficients))?;
    let trig = upload(ctx, "radon (unused)", &[])?;
    let params = RadonParams {
        dims: [side as u32, maps.len() as u32, 0, 0],
        ..Default::default()
    };
    dispatch(
        ctx,
        "radon_column",
        params,
        (&src, &aux, &trig),
        out_len,
        out_len,
    )
}

/// scikit-image's `iradon` backprojection of filtered views (one line of `bins` values
/// per angle), in f32: the port of `cpu::radon::iradon_backproject` (`R = A = f32`).
/// `curvatures` are the lines' spline curvatures for [`Interpolation::Cubic`] (else
/// empty), `trig` each angle's `(cos θ, sin θ)` (split into f32 and its remainder,
/// `cpu::radon::Angle`).
///
/// # Errors
/// Lengths that do not match; a buffer past one binding ([`Error::TooLarge`]); on a
/// CPU adapter more angles than its loop limit; [`Error::Gpu`] on device failure.
#[allow(clippy::too_many_arguments)]
pub fn iradon_backproject(
    ctx: &GpuContext,
    views: &[f32],
    curvatures: &[f32],
    bins: usize,
    trig: &[(f64, f64)],
    size: usize,
    kind: Interpolation,
    circle: bool,
) -> Result<Vec<f32>> {
    let angles = trig.len();
    if views.len() != bins * angles
        || (kind == Interpolation::Cubic && curvatures.len() != views.len())
    {
        return Err(Error::invalid(
            "filtered views",
            format!(
                "{} values (and {} curvatures) for {bins} bins × {angles} angles",
                views.len(),
                curvatures.len()
            ),
        ));
    }
    if size == 0 {
        return Ok(Vec::new());
    }
    check_loop(ctx, "angles", angles)?;
    let cs: Vec<[f32; 4]> = trig
        .iter()
        .map(|&(c, s)| {
            let a = Angle::<f32>::new(c, s);
            [a.c, a.s, a.c_lo, a.s_lo]
        })
        .collect();
    let src = upload(ctx, "iradon views", bytemuck::cast_slice(views))?;
    let aux = upload(ctx, "iradon curvatures", bytemuck::cast_slice(curvatures))?;
    let trig = upload(ctx, "iradon angles", bytemuck::cast_slice(&cs))?;
    let params = RadonParams {
        dims: [bins as u32, angles as u32, size as u32, kind.id()],
        work: [0, circle as u32, 0, 0],
        scale: [
            std::f64::consts::PI as f32,
            (2.0 * angles as f64) as f32,
            0.0,
            0.0,
        ],
    };
    dispatch(
        ctx,
        "iradon_backproject",
        params,
        (&src, &aux, &trig),
        size * size,
        size * size,
    )
}

/// One ray of one view for `shaders/radon_sart.wgsl` (its WGSL twin is the struct of
/// that name there): `cpu::radon::SartRay` in f32, with where its Hamming window starts.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SartRayGpu {
    pub ds: f32,
    pub dx: f32,
    pub dy: f32,
    pub x0: f32,
    pub y0: f32,
    pub ns: u32,
    pub window: u32,
    pub live: u32,
}

/// The complete SART shader source: `shaders/radon_sart.wgsl` and its imports.
pub fn sart_shader_source() -> String {
    super::shaders::resolve("radon_sart")
}

/// One call of scikit-image's `iradon_sart` on the GPU, in f32: the port of
/// `cpu::radon::iradon_sart` (`R = f32`). `sinogram` is `(n, angles)` row-major,
/// `order` the views' order (`cpu::radon::golden_order`), `image` the start. The whole
/// iteration runs on the device (one submission); the image is read back once. The
/// rays' set-up and the Hamming windows are made on the host, in f32 as the CPU makes
/// them; a pixel's update sums its rays three phases apart (rays `i ≡ 0, 1, 2 mod 3`),
/// not in the rays' order, so the result agrees with the CPU's f32 to rounding.
///
/// # Errors
/// Lengths that do not match; a buffer past one binding ([`Error::TooLarge`]);
/// [`Error::Gpu`] on device failure.
#[allow(clippy::too_many_arguments)]
pub fn iradon_sart(
    ctx: &GpuContext,
    sinogram: &[f32],
    n: usize,
    theta_deg: &[f32],
    order: &[usize],
    image: &[f32],
    shifts: &[f32],
    clip: Option<[f32; 2]>,
    relaxation: f64,
) -> Result<Vec<f32>> {
    use crate::cpu::radon::SartRay;
    let angles = theta_deg.len();
    if sinogram.len() != n * angles
        || image.len() != n * n
        || shifts.len() != angles
        || order.len() != angles
        || order.iter().any(|&k| k >= angles)
    {
        return Err(Error::invalid(
            "SART",
            format!(
                "{} sinogram values, {} image values, {} shifts and {} views for n = {n} \
                 and {angles} angles",
                sinogram.len(),
                image.len(),
                shifts.len(),
                order.len()
            ),
        ));
    }
    if n == 0 || angles == 0 {
        return Ok(image.to_vec());
    }
    // The views as lines, the rays of every view and the windows of every length.
    let mut lines = vec![0f32; n * angles];
    for (b, row) in sinogram.chunks(angles).enumerate() {
        for (k, &v) in row.iter().enumerate() {
            lines[k * n + b] = v;
        }
    }
    let mut made = crate::cpu::radon::SartWindows::<f32>::default();
    let mut windows: Vec<f32> = Vec::new();
    let mut window_at = std::collections::HashMap::new();
    let mut rays = Vec::with_capacity(n * angles);
    for k in 0..angles {
        for i in 0..n {
            let ray = SartRay::<f32>::new(n, theta_deg[k], i as f32 + shifts[k]);
            rays.push(match ray {
                None => SartRayGpu::default(),
                Some(r) => {
                    let window = *window_at.entry(r.ns).or_insert_with(|| {
                        let at = windows.len() as u32;
                        made.add(r.ns);
                        windows.extend_from_slice(made.of(r.ns));
                        at
                    });
                    SartRayGpu {
                        ds: r.ds,
                        dx: r.dx,
                        dy: r.dy,
                        x0: r.x0,
                        y0: r.y0,
                        ns: r.ns as u32,
                        window,
                        live: 1,
                    }
                }
            });
        }
    }
    check_loop(ctx, "rays", 2 * n + 2)?;
    let lines_buf = upload(ctx, "SART sinogram", bytemuck::cast_slice(&lines))?;
    let rays_buf = upload(ctx, "SART rays", bytemuck::cast_slice(&rays))?;
    let windows_buf = upload(ctx, "SART windows", bytemuck::cast_slice(&windows))?;
    let dev = &ctx.device;
    let rw = |label: &str, data: &[f32]| -> Result<wgpu::Buffer> {
        ctx.check_storage(label, (data.len() * 4) as u64)?;
        Ok(dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytemuck::cast_slice(data),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        }))
    };
    let image_buf = rw("SART image", image)?;
    let update_buf = rw("SART update", &vec![0f32; n * n])?;
    let deviation_buf = rw("SART deviations", &vec![0f32; n])?;
    // Every dispatch's parameters in one buffer, bound at its own (aligned) offset.
    let align = ctx.limits.min_uniform_buffer_offset_alignment.max(16) as usize;
    let stride = std::mem::size_of::<RadonParams>().div_ceil(align) * align;
    let max_x = ctx.limits.max_compute_workgroups_per_dimension.max(1);
    let groups = |invocations: usize| {
        let g = (invocations as u32).div_ceil(WORKGROUP).max(1);
        let gx = g.min(max_x);
        (gx, g.div_ceil(gx))
    };
    let (clip_on, [lo, hi]) = match clip {
        Some(c) => (1, c),
        None => (0, [0.0, 0.0]),
    };
    let steps: Vec<(&str, u32, usize)> = vec![
        ("sart_deviation", 0, n),
        ("sart_scatter", 0, n.div_ceil(3)),
        ("sart_scatter", 1, n.div_ceil(3)),
        ("sart_scatter", 2, n.div_ceil(3)),
        ("sart_apply", 0, n * n),
    ];
    let mut bytes = vec![0u8; stride * steps.len() * angles];
    let mut dispatches = Vec::with_capacity(steps.len() * angles);
    for (v, &view) in order.iter().enumerate() {
        for (s, &(entry, phase, invocations)) in steps.iter().enumerate() {
            let (gx, gy) = groups(invocations);
            let p = RadonParams {
                dims: [n as u32, angles as u32, view as u32, phase],
                work: [gx * WORKGROUP, clip_on, 0, 0],
                scale: [relaxation as f32, lo, hi, 0.0],
            };
            let at = (v * steps.len() + s) * stride;
            bytes[at..at + std::mem::size_of::<RadonParams>()]
                .copy_from_slice(bytemuck::bytes_of(&p));
            dispatches.push((entry, at as u32, gx, gy));
        }
    }
    let params_buf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("SART params"),
        contents: &bytes,
        usage: super::context::PARAMS_USAGE,
    });
    let storage = |read_only| wgpu::BufferBindingType::Storage { read_only };
    let program = ctx.program(
        "radon_sart.wgsl",
        &sart_shader_source(),
        Some(&[
            wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: true,
                    min_binding_size: wgpu::BufferSize::new(
                        std::mem::size_of::<RadonParams>() as u64
                    ),
                },
                count: None,
            },
            buffer_entry(1, storage(true)),
            buffer_entry(2, storage(true)),
            buffer_entry(3, storage(true)),
            buffer_entry(4, storage(false)),
            buffer_entry(5, storage(false)),
            buffer_entry(6, storage(false)),
        ]),
    )?;
    let pipelines: std::collections::HashMap<&str, Kernel> =
        ["sart_deviation", "sart_scatter", "sart_apply"]
            .into_iter()
            .map(|e| Ok((e, program.kernel(ctx, e)?.0)))
            .collect::<Result<_>>()?;
    let layout = &pipelines["sart_apply"].layout;
    let bind = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("radon sart"),
        layout,
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: &params_buf,
                    offset: 0,
                    size: wgpu::BufferSize::new(std::mem::size_of::<RadonParams>() as u64),
                }),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: lines_buf.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: rays_buf.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 3,
                resource: windows_buf.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 4,
                resource: image_buf.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 5,
                resource: update_buf.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 6,
                resource: deviation_buf.as_entire_binding(),
            },
        ],
    });
    let mut enc = dev.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        for &(entry, offset, gx, gy) in &dispatches {
            pass.set_pipeline(&pipelines[entry].pipeline);
            pass.set_bind_group(0, &bind, &[offset]);
            pass.dispatch_workgroups(gx, gy, 1);
        }
    }
    ctx.queue.submit([enc.finish()]);
    ctx.wait()?;
    Ok(bytemuck::cast_slice(&ctx.read_buffer(&image_buf, (n * n * 4) as u64)?).to_vec())
}
