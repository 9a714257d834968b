//! The GPU multi-volume ray caster: a WGSL port of `cpu::multi` that must match the f64
//! oracle.
//!
//! Shader: `shaders/multi.wgsl` (one invocation per pixel; every helper names its Rust
//! twin), importing the ray caster's shared modules: camera rays
//! (`shaders/shared/camera.wgsl`), the box test (`rays.wgsl`), Phong (`shading.wgsl`),
//! opacity (`opacity.wgsl`) and the clamped index (`filters.wgsl`). Parameters:
//! [`MultiParams`], whose WGSL twin is `shaders/shared/multi_params.wgsl`; its camera,
//! shading and image members carry `RaycastParams`' names, so the shared helpers read
//! them unchanged.
//!
//! Data on the device:
//! - every volume as its own `R32Float` 3D texture of raw values (bindings 1 … 3; a
//!   1×1×1 dummy fills an unused slot), sampled in its own index coordinates;
//! - the three lookup tables one after another in one storage buffer, each read with
//!   `LutR::classify`'s manual linear interpolation from its own first entry.
//!
//! The algorithm is `cpu::multi`'s step by step: the same union of the boxes, the same
//! steps of `step / |d_0|` world mm with the last one ending on the union's far side,
//! the same midpoint samples, optical depths `τ_i = −ln(1 − α_i) · len · |d_i| / Δ_ref`
//! added and colours mixed by them (`ln_1p`/`exp_m1` evaluated accurately in f32), the
//! same opacity threshold for early ray termination, the same per-volume shading
//! (`shade_gradient`: the gradient of the volume's own field, mapped to the world by its
//! `M_i⁻ᵀ`). Samples are reconstructed on the exact path (`textureLoad` of the 8 voxels,
//! weighted in voxel coordinates in `apply_taps`' order).
//!
//! Supported: nearest and trilinear reconstruction, central and forward gradients
//! computed on the fly. Other filters, Sobel gradients, precomputed gradients and
//! hardware filtering are refused with an error naming what is supported (the CPU
//! backends render them).

use super::context::{
    buffer_entry, compute_pipeline, render_bands, texture_entry, GpuContext, LLVMPIPE_LOOP_LIMIT,
};
use super::raycast::{GpuRenderOutput, GpuTimings};
use crate::camera::{Camera, Projection};
use crate::cpu::raycast::RenderOutput;
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::multi::{MultiVolume, MAX_VOLUMES};
use crate::settings::{Compositing, Filter, GradientMethod, Light, Mode, RenderSettings};
use glam::{DMat3, DMat4, DVec3};
use std::time::Instant;
use wgpu::util::DeviceExt;

/// Parameters of one multi-volume dispatch; twin of `shaders/shared/multi_params.wgsl`
/// (`tests/gpu_layout.rs` checks that the two layouts agree).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct MultiParams {
    pub eye: [f32; 4],
    pub forward: [f32; 4],
    pub right: [f32; 4],
    pub up: [f32; 4],
    pub background: [f32; 4],
    pub light: [f32; 4],
    /// Ambient, diffuse, specular, shininess.
    pub shading: [f32; 4],
    /// Step (voxels of volume 0), reference step, ERT threshold, miss value.
    pub misc: [f32; 4],
    /// Width, height, mode, filter.
    pub image: [u32; 4],
    /// Volumes, back-to-front, first row of the tile, rows in the tile.
    pub flags: [u32; 4],
    /// Rows of each volume's world → index affine (`3 i + r`).
    pub to_index: [[f32; 4]; 9],
    /// Rows of each volume's `M_i⁻ᵀ` (`3 i + r`).
    pub normal: [[f32; 4]; 9],
    /// `n − ½` per axis; w = the shading gradient threshold.
    pub box_hi: [[f32; 4]; 3],
    /// LUT scale, offset, entries − 1, first entry in the shared table buffer.
    pub lut: [[f32; 4]; 3],
    /// Dimensions; w = shade this volume.
    pub dims: [[u32; 4]; 3],
    /// Gradient method (0 central, 1 forward), unused ×3.
    pub gradient: [u32; 4],
}

/// `shaders/shared/multi_params.wgsl`: the WGSL twin of [`MultiParams`].
pub const PARAMS_WGSL: &str = super::shaders::MULTI_PARAMS;

/// The complete shader: `shaders/multi.wgsl` and its imports.
pub fn multi_shader() -> String {
    super::shaders::resolve("multi")
}

/// Pixels per dispatch: keeps one submission well under the ~10 s after which a
/// software driver may lose the device.
const PIXELS_PER_DISPATCH: usize = 8 * 1024;

fn v4(v: DVec3, w: f64) -> [f32; 4] {
    [v.x as f32, v.y as f32, v.z as f32, w as f32]
}

/// The settings the GPU port covers beyond `multi::validate_settings`.
fn check_gpu_settings(settings: &RenderSettings) -> Result<()> {
    if !matches!(settings.filter, Filter::Nearest | Filter::Trilinear) {
        return Err(Error::invalid(
            "filter",
            format!(
                "the GPU multi-volume caster reconstructs with nearest or trilinear; \
                 render {} with --backend cpu or cpu-f32",
                settings.filter.name()
            ),
        ));
    }
    if settings.hardware_filtering {
        return Err(Error::invalid(
            "hardware filtering",
            "the GPU multi-volume caster runs the exact trilinear path only",
        ));
    }
    let shaded = settings.mode == Mode::Dvr && settings.shading.enabled;
    if shaded && settings.precompute_gradients {
        return Err(Error::invalid(
            "precomputed gradients",
            "the GPU multi-volume caster differences the field on the fly; \
             render without precomputed gradients or on the CPU",
        ));
    }
    if shaded && settings.gradient == GradientMethod::Sobel {
        return Err(Error::invalid(
            "gradient",
            "the GPU multi-volume caster shades with central or forward gradients; \
             render Sobel gradients on the CPU",
        ));
    }
    Ok(())
}

/// Fills the parameter block (everything but the tile rows).
pub fn multi_params(
    volumes: &[MultiVolume],
    camera: &Camera,
    settings: &RenderSettings,
    luts: &[crate::transfer::LutR<f32>],
    ranges: &[(f64, f64)],
) -> Result<MultiParams> {
    let (eye_w, fwd_w, right_w, up_w) = match camera.projection {
        Projection::Perspective { fov_y_deg } => (
            1.0,
            (0.5 * fov_y_deg.to_radians()).tan(),
            camera.width as f64 / camera.height as f64,
            0.0,
        ),
        Projection::Orthographic {
            width_mm,
            height_mm,
        } => (0.0, 0.0, width_mm, height_mm),
    };
    let s = &settings.shading;
    let (light, light_w) = match s.light {
        Light::Headlight => (DVec3::ZERO, 0.0),
        Light::Direction(d) => (DVec3::from_array(d).normalize(), 1.0),
    };
    let mode = match settings.mode {
        Mode::Dvr => 0,
        Mode::Mip => 1,
        Mode::Minip => 2,
        Mode::Xray => 3,
        m => {
            return Err(Error::invalid(
                "multi-volume render",
                format!("mode {m:?} is not supported with several volumes"),
            ))
        }
    };
    let mut p = MultiParams {
        eye: v4(camera.eye, eye_w),
        forward: v4(camera.forward, fwd_w),
        right: v4(camera.right, right_w),
        up: v4(camera.up, up_w),
        background: settings.background.map(|c| c as f32),
        light: v4(light, light_w),
        shading: [
            s.ambient as f32,
            s.diffuse as f32,
            s.specular as f32,
            s.shininess as f32,
        ],
        misc: [
            settings.step as f32,
            settings.reference_step as f32,
            settings.ert_threshold as f32,
            settings.miss_value as f32,
        ],
        image: [
            camera.width as u32,
            camera.height as u32,
            mode,
            (settings.filter == Filter::Trilinear) as u32,
        ],
        flags: [
            volumes.len() as u32,
            (settings.compositing == Compositing::BackToFront) as u32,
            0,
            camera.height as u32,
        ],
        gradient: [
            (settings.gradient == GradientMethod::Forward) as u32,
            0,
            0,
            0,
        ],
        ..Default::default()
    };
    let mut base = 0usize;
    for (i, v) in volumes.iter().enumerate() {
        let m: DMat4 = v.index_to_world()?;
        let to_index = m.inverse();
        let normal = DMat3::from_mat4(m).inverse().transpose();
        for r in 0..3 {
            let row = to_index.row(r);
            p.to_index[3 * i + r] = [row.x as f32, row.y as f32, row.z as f32, row.w as f32];
            p.normal[3 * i + r] = v4(normal.row(r), 0.0);
        }
        let dims = v.volume.dims();
        let (lo, hi) = ranges[i];
        let grad_thr = s.gradient_threshold * (hi - lo).max(f64::MIN_POSITIVE);
        p.box_hi[i] = [
            dims[0] as f32 - 0.5,
            dims[1] as f32 - 0.5,
            dims[2] as f32 - 0.5,
            grad_thr as f32,
        ];
        let lut = &luts[i];
        p.lut[i] = [
            lut.scale,
            lut.offset,
            (lut.entries.len() - 1) as f32,
            base as f32,
        ];
        base += lut.entries.len();
        let shade = v.shade && s.enabled && settings.mode == Mode::Dvr;
        p.dims[i] = [dims[0] as u32, dims[1] as u32, dims[2] as u32, shade as u32];
    }
    Ok(p)
}

/// Rows of a `w`×`h` image per dispatch: at most 8,192 pixels, and a
/// band's RGBA f32 pixels within one storage binding.
pub fn rows_per_band(ctx: &GpuContext, w: usize, h: usize) -> usize {
    let max_binding = ctx.limits.max_storage_buffer_binding_size as usize;
    (max_binding / (w.max(1) * 16))
        .min(PIXELS_PER_DISPATCH / w.max(1))
        .clamp(1, h.max(1))
}

/// Refuses, before anything is converted or uploaded, a GPU multi-volume render the
/// device cannot run: what every backend refuses ([`crate::multi::check`]), filters and
/// options this caster lacks, a volume past the 3-D texture limit, rays past a CPU
/// driver's loop limit. [`render`] and `voxlab render --volume … --dry-run` call it.
///
/// # Errors
/// [`Error::Invalid`] or [`Error::TooLarge`] saying which.
pub fn check(
    ctx: &GpuContext,
    volumes: &[MultiVolume],
    camera: &Camera,
    settings: &RenderSettings,
) -> Result<()> {
    let per_ray = crate::multi::check(volumes, camera, settings)?;
    check_gpu_settings(settings)?;
    let max3d = ctx.limits.max_texture_dimension_3d as usize;
    for (i, v) in volumes.iter().enumerate() {
        let dims = v.volume.dims();
        if dims.iter().any(|&n| n > max3d) {
            return Err(Error::too_large(
                format!("volume {i}"),
                format!("{dims:?} exceeds the adapter's 3D texture limit of {max3d} per axis"),
            ));
        }
    }
    ctx.check_memory("multi-volume render", device_bytes(ctx, volumes, camera).0)
        .map_err(|e| match e {
            Error::TooLarge { what, message } => Error::TooLarge {
                what,
                message: format!(
                    "{message}; the multi-volume caster holds every volume whole: render on \
                     the CPU (--backend cpu-f32)"
                ),
            },
            e => e,
        })?;
    if ctx.summary.is_cpu() && per_ray > (LLVMPIPE_LOOP_LIMIT - 64) as f64 {
        return Err(Error::invalid(
            "step",
            format!(
                "up to {per_ray:.0} steps per ray exceed the {LLVMPIPE_LOOP_LIMIT} loop \
                 iterations a CPU Vulkan driver (llvmpipe) runs per invocation; use a \
                 larger step"
            ),
        ));
    }
    Ok(())
}

/// What a GPU multi-volume render holds on the device: every volume's `R32Float`
/// texture and one band's RGBA f32 pixels and u32 counts, as `(at once, the largest
/// single object)` in bytes.
pub fn device_bytes(ctx: &GpuContext, volumes: &[MultiVolume], camera: &Camera) -> (u64, u64) {
    let (w, h) = (camera.width, camera.height);
    let band = (rows_per_band(ctx, w, h) * w * 20) as u64;
    let textures = volumes
        .iter()
        .map(|v| 4 * v.volume.dims().iter().product::<usize>() as u64);
    (
        textures.clone().sum::<u64>() + band,
        textures.max().unwrap_or(0).max(band),
    )
}

/// Renders a multi-volume scene on the GPU. Same inputs and meaning as
/// `cpu::multi::render`; returns the image, the sample counts and timings.
pub fn render(
    ctx: &GpuContext,
    volumes: &[MultiVolume],
    camera: &Camera,
    settings: &RenderSettings,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<GpuRenderOutput> {
    let t_start = Instant::now();
    check(ctx, volumes, camera, settings)?;

    // Inputs on the host: raw values in f32, value ranges, lookup tables.
    let values: Vec<_> = volumes.iter().map(|v| v.volume.to_f32()).collect();
    let ranges: Vec<(f64, f64)> = values
        .iter()
        .map(|v| {
            let r = v.value_range();
            (r.min, r.max)
        })
        .collect();
    let luts: Vec<_> = volumes
        .iter()
        .map(|v| v.transfer.lut(settings.lut_size).to_real::<f32>())
        .collect();
    let mut params = multi_params(volumes, camera, settings, &luts, &ranges)?;

    let dev = &ctx.device;
    let module = ctx.shader("multi.wgsl", &multi_shader())?;
    let storage = |read_only| wgpu::BufferBindingType::Storage { read_only };
    let layout = ctx.bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("multi"),
        entries: &[
            buffer_entry(0, wgpu::BufferBindingType::Uniform),
            texture_entry(1, false),
            texture_entry(2, false),
            texture_entry(3, false),
            buffer_entry(4, storage(true)),
            buffer_entry(5, storage(false)),
            buffer_entry(6, storage(false)),
        ],
    });
    let pipeline = compute_pipeline(ctx, "multi", &module, "multi", &layout)?;
    let t_setup = t_start.elapsed().as_secs_f64();

    let t_up = Instant::now();
    let mut textures = Vec::with_capacity(MAX_VOLUMES);
    for (v, vals) in volumes.iter().zip(&values) {
        textures.push(ctx.upload_volume_r32(v.volume.dims(), vals.data())?);
    }
    while textures.len() < MAX_VOLUMES {
        textures.push(ctx.upload_volume_r32([1, 1, 1], &[0.0])?);
    }
    let table: Vec<[f32; 4]> = luts.iter().flat_map(|l| l.entries.clone()).collect();
    let lut_buf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("multi luts"),
        contents: bytemuck::cast_slice(&table),
        usage: wgpu::BufferUsages::STORAGE,
    });
    ctx.wait()?;
    let upload = t_up.elapsed().as_secs_f64();

    let (w, h) = (camera.width, camera.height);
    let rows_per_tile = rows_per_band(ctx, w, h);
    let views: Vec<_> = textures
        .iter()
        .map(|t| t.create_view(&Default::default()))
        .collect();
    let mut image = Frame::new(w, h, if settings.mode.rgba() { 4 } else { 1 });
    let mut counts = vec![0u32; w * h];
    let bands = render_bands(
        ctx,
        (&pipeline, "multi"),
        rows_per_tile,
        (&mut image, &mut counts),
        None,
        progress,
        |row0, rows, out_buf, cnt_buf| {
            params.flags[2] = row0 as u32;
            params.flags[3] = rows as u32;
            let pbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("multi params"),
                contents: bytemuck::bytes_of(&params),
                usage: super::context::PARAMS_USAGE,
            });
            Ok(ctx.bind_group(
                "multi",
                &layout,
                &[
                    pbuf.as_entire_binding(),
                    wgpu::BindingResource::TextureView(&views[0]),
                    wgpu::BindingResource::TextureView(&views[1]),
                    wgpu::BindingResource::TextureView(&views[2]),
                    lut_buf.as_entire_binding(),
                    out_buf.as_entire_binding(),
                    cnt_buf.as_entire_binding(),
                ],
            ))
        },
    )?;
    Ok(GpuRenderOutput {
        output: RenderOutput::from_counts(image, &counts, settings.sample_count),
        timings: GpuTimings {
            setup: t_setup,
            upload,
            prepare: 0.0,
            kernel: bands.kernel,
            kernel_from_timestamps: bands.from_timestamps,
            readback: bands.readback,
            total: t_start.elapsed().as_secs_f64(),
        },
        hits: None,
    })
}
