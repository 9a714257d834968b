//! The adaptive ray caster on the GPU, mirroring `cpu::adaptive` (see its docs for the
//! method): regular, spectral adaptive and direct sampling, pre-integrated DVR, front
//! to back, trilinear, no shading.
//!
//! On the device: the pre-integrated table (`gpu::preintegrate`), the importance volume
//! (`shaders/adaptive_importance.wgsl`: differences, then one max-filter pass per axis)
//! and the ray march (`shaders/adaptive.wgsl`, one invocation per pixel). The volume and
//! every table live in storage buffers and are read with manual interpolation, in the
//! CPU's order of operations.
//!
//! On the host, and why: the spectral table `ν_g(I)` and direct sampling's block
//! spectra are FFTs of a transfer function or of blocks, computed once per transfer
//! function (`cpu::adaptive::spectral_table`, `direct_steps` in f32) and uploaded; the
//! rays' index-space origins and directions are computed in f64 and rounded to f32,
//! exactly as the CPU f32 path rounds them, so both march from the same numbers.

use super::context::{
    buffer_entry, render_bands, rgba_storage_entry, texture_entry, GpuContext, Kernel,
    LLVMPIPE_LOOP_LIMIT,
};
use super::shaders;
use crate::camera::{Camera, PixelRect};
use crate::cpu::adaptive::{
    direct_steps, importance_radius, spectral_table, AdaptiveSettings, AdaptiveState, Sampling,
};
use crate::cpu::grid::Grid;
use crate::cpu::raycast::RenderOutput;
use crate::cpu::shade::over_background;
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::transfer::TransferFunction;
use crate::volume::AnyVolume;
use std::time::Instant;
use wgpu::util::DeviceExt;

pub use super::params::AdaptiveParams;

/// `shaders/shared/adaptive_params.wgsl`: the WGSL twin of [`AdaptiveParams`].
pub const PARAMS_WGSL: &str = shaders::ADAPTIVE_PARAMS;

/// Where the time of a GPU adaptive render went, in seconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct AdaptiveTimings {
    /// Shader compilation and pipelines.
    pub setup: f64,
    /// The volume's upload and the rays' computation (each band uploads its own rays
    /// with its dispatch).
    pub upload: f64,
    /// Pre-integration and importance volume on the device, spectra on the host.
    pub prepare: f64,
    /// The ray-casting passes (timestamps when available, else wall clock).
    pub kernel: f64,
    pub kernel_from_timestamps: bool,
    pub readback: f64,
    pub total: f64,
}

/// What a GPU adaptive render returns.
#[derive(Clone, Debug)]
pub struct GpuAdaptiveOutput {
    pub output: RenderOutput,
    pub timings: AdaptiveTimings,
    /// How the volume was cut into bricks ([`AdaptiveSplit::line`]), when it was.
    pub split: Option<String>,
}

fn init_buffer(
    ctx: &GpuContext,
    label: &str,
    bytes: &[u8],
    usage: wgpu::BufferUsages,
) -> Result<wgpu::Buffer> {
    ctx.check_storage(label, bytes.len() as u64)?;
    let pad;
    let contents = if bytes.is_empty() {
        pad = [0u8; 16];
        &pad[..]
    } else {
        bytes
    };
    Ok(ctx
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents,
            usage,
        }))
}

/// The importance volume's two compute pipelines (`shaders/adaptive_importance.wgsl`:
/// the differences, the max filter along one axis) over their bind group layout, taken
/// once for every brick of a split render from the device's kept programs
/// ([`GpuContext::program`]).
pub struct ImportancePipelines {
    layout: wgpu::BindGroupLayout,
    diff: wgpu::ComputePipeline,
    maxf: wgpu::ComputePipeline,
}

impl ImportancePipelines {
    /// Compiles the pipelines on `ctx`.
    pub fn new(ctx: &GpuContext) -> Result<Self> {
        let program = ctx.program(
            "adaptive_importance.wgsl",
            &shaders::resolve("adaptive_importance"),
            Some(&[
                buffer_entry(0, wgpu::BufferBindingType::Uniform),
                texture_entry(1, false),
                texture_entry(2, false),
                rgba_storage_entry(3),
            ]),
        )?;
        let (
            Kernel {
                layout,
                pipeline: diff,
            },
            _,
        ) = program.kernel(ctx, "differences")?;
        let maxf = program.kernel(ctx, "max_filter")?.0.pipeline;
        Ok(ImportancePipelines { layout, diff, maxf })
    }
}

/// The importance volume on the device from the volume's R32Float 3-D texture: an
/// `Rgba32Float` 3-D texture, one texel per voxel, `(G_x, G_y, G_z, 0)`.
pub fn importance_texture(
    ctx: &GpuContext,
    pipelines: &ImportancePipelines,
    volume: &wgpu::TextureView,
    dims: [usize; 3],
    t_max: f64,
) -> Result<wgpu::Texture> {
    let dev = &ctx.device;
    let ImportancePipelines { layout, diff, maxf } = pipelines;
    let a = ctx.rgba_texture(dims, true)?;
    let b = ctx.rgba_texture(dims, true)?;
    let none = ctx.rgba_texture([1, 1, 1], false)?;
    let view = |t: &wgpu::Texture| t.create_view(&Default::default());
    let (av, bv, nv) = (view(&a), view(&b), view(&none));
    let r = importance_radius(t_max) as u32;
    let groups = dims.map(|n| (n as u32).div_ceil(4));
    let mut enc = dev.create_command_encoder(&Default::default());
    // Pass 0: differences into a; passes 1–3: x, y, z max filters, a → b → a → b.
    let passes: [(
        &wgpu::ComputePipeline,
        &wgpu::TextureView,
        &wgpu::TextureView,
        u32,
    ); 4] = [
        (diff, &nv, &av, 0),
        (maxf, &av, &bv, 0),
        (maxf, &bv, &av, 1),
        (maxf, &av, &bv, 2),
    ];
    let mut keep = Vec::new();
    for (pipeline, src, dst, axis) in passes {
        let params = AdaptiveParams {
            dims: [dims[0] as u32, dims[1] as u32, dims[2] as u32, 0],
            extra: [0, 0, axis, r],
            ..Default::default()
        };
        let pbuf = init_buffer(
            ctx,
            "importance params",
            bytemuck::bytes_of(&params),
            super::context::PARAMS_USAGE,
        )?;
        let bind = ctx.bind_group(
            "importance",
            layout,
            &[
                pbuf.as_entire_binding(),
                wgpu::BindingResource::TextureView(volume),
                wgpu::BindingResource::TextureView(src),
                wgpu::BindingResource::TextureView(dst),
            ],
        );
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
        }
        keep.push(pbuf);
    }
    ctx.queue.submit([enc.finish()]);
    Ok(b)
}

/// The importance volume of `grid` computed on the device and read back (the same
/// three grids as `cpu::adaptive::importance_volume`).
pub fn importance_volume(ctx: &GpuContext, grid: &Grid<f32>, t_max: f64) -> Result<[Grid<f32>; 3]> {
    let vol = ctx.upload_volume_r32(grid.dims, &grid.data)?;
    let pipelines = ImportancePipelines::new(ctx)?;
    let view = vol.create_view(&Default::default());
    let tex = importance_texture(ctx, &pipelines, &view, grid.dims, t_max)?;
    let bytes = ctx.read_texture_3d(&tex, grid.dims, 16)?;
    let texels: &[[f32; 4]] = bytemuck::cast_slice(&bytes);
    Ok(std::array::from_fn(|a| Grid {
        dims: grid.dims,
        data: texels.iter().map(|t| t[a]).collect(),
    }))
}

/// The 3-D textures a GPU adaptive render holds, as `(label, bytes)` in the order it
/// creates them, for a volume (or, split, a brick with its ghost voxels) of `dims`: the
/// volume (`R32Float`) and, for adaptive sampling, the two importance volumes
/// (`Rgba32Float`).
pub fn device_textures(dims: [usize; 3], settings: &AdaptiveSettings) -> Vec<(&'static str, u64)> {
    let voxels = dims.iter().product::<usize>() as u64;
    let mut t = vec![("volume", 4 * voxels)];
    if settings.sampling == Sampling::Adaptive {
        t.extend([("importance a", 16 * voxels), ("importance b", 16 * voxels)]);
    }
    t
}

/// The storage buffers a GPU adaptive render of a `dims` volume holds for the whole
/// frame, as `(label, bytes)`: the pre-integrated table (`n²` RGBA f32) and its lookup
/// table, the spectral table (adaptive sampling) and the block steps (direct sampling).
pub fn device_tables(dims: [usize; 3], settings: &AdaptiveSettings) -> Vec<(&'static str, u64)> {
    let n = settings.preint_size as u64;
    let bins = settings.spectrum_bins as u64 + 1;
    let blocks = dims
        .iter()
        .map(|&d| d.div_ceil(settings.block.max(1)) as u64)
        .product::<u64>();
    vec![
        ("preintegrated table", 16 * n * n),
        ("pre-integration lookup table", 16 * n),
        (
            "spectrum",
            4 * if settings.sampling == Sampling::Adaptive {
                bins * bins
            } else {
                1
            },
        ),
        (
            "direct steps",
            4 * if settings.sampling == Sampling::Direct {
                blocks
            } else {
                1
            },
        ),
    ]
}

/// The storage buffers of one band of rows of a GPU adaptive render, as `(label,
/// bytes)`: its rays, pixels (or, split, the rays' carried states: [`CARRIED_VEC4S`]
/// vec4 a pixel) and sample counts (bands sized to fit one binding).
pub fn band_buffers(ctx: &GpuContext, camera: &Camera, split: bool) -> Vec<(&'static str, u64)> {
    let w = camera.width as u64;
    let rows = rows_per_band(ctx, camera.width, camera.height, split) as u64;
    let pixel = if split { 16 * CARRIED_VEC4S as u64 } else { 16 };
    vec![
        ("rays", 32 * w * rows),
        ("pixels", pixel * w * rows),
        ("samples", 4 * w * rows),
    ]
}

/// Rows of a `w`×`h` image per dispatch: at most 65,536 pixels (bounded work per
/// dispatch), and a band's largest buffer (its rays, 32 bytes a pixel; split, its
/// carried states, 48) within one storage binding.
fn rows_per_band(ctx: &GpuContext, w: usize, h: usize, split: bool) -> usize {
    let binding = crate::gpu::plan::binding_limit(&ctx.limits) as usize;
    let per_pixel = if split { 16 * CARRIED_VEC4S } else { 32 };
    (65536 / w.max(1))
        .min(binding / (per_pixel * w.max(1)))
        .clamp(1, h.max(1))
}

/// The vec4 a pixel's ray hands the next brick (`shaders/adaptive.wgsl: state_store`):
/// `(c, a)`, `(s, f0, k, taken)`, `(started, done, 0, 0)`.
pub const CARRIED_VEC4S: usize = 3;

/// A ray's state from its [`CARRIED_VEC4S`] vec4.
/// Mirrors `shaders/adaptive.wgsl: state_load`.
pub fn carried_state(v: &[[f32; 4]]) -> AdaptiveState<f32> {
    AdaptiveState {
        c: [v[0][0], v[0][1], v[0][2]],
        a: v[0][3],
        s: v[1][0],
        f0: v[1][1],
        k: v[1][2] as u32,
        taken: v[1][3] as u32,
        started: v[2][0] == 1.0,
        done: v[2][1] == 1.0,
    }
}

/// The ghost voxels each brick of a split adaptive render carries: a step starting in
/// the brick ends up to `T_max` outside it (its trilinear sample one voxel further),
/// and the importance volume at a voxel the brick owns reads differences up to the max
/// filter's radius ([`importance_radius`]) and one voxel further.
pub fn brick_ghost(settings: &AdaptiveSettings) -> usize {
    importance_radius(settings.t_max) + 1
}

/// How a split adaptive render cuts its volume ([`volume_split`]).
pub struct AdaptiveSplit {
    /// The k-d tree and its bricks (`io::brick::fitting_kd_tree`).
    pub tree: crate::io::brick::KdTree,
    pub bricks: Vec<crate::io::brick::Brick>,
    /// The dimensions of the largest brick with its ghost voxels.
    pub largest: [usize; 3],
    /// What the job prints: "adaptive ray casting in 4 bricks (…, why)".
    pub line: String,
}

/// Whether and how an adaptive render of a `dims` volume is cut into bricks on `ctx`:
/// when an axis exceeds the planner's 3-D texture limit, or when the textures
/// ([`device_textures`]) and one band's buffers exceed the device memory a job may
/// fill. `None` when the volume fits whole. [`render`] and the dry runs ask it.
///
/// # Errors
/// No cut fits (a limit below the ghost voxels, [`brick_ghost`]).
pub fn volume_split(
    ctx: &GpuContext,
    dims: [usize; 3],
    camera: &Camera,
    settings: &AdaptiveSettings,
) -> Result<Option<AdaptiveSplit>> {
    let max = ctx.limits.max_texture_dimension_3d as usize;
    let tables = device_tables(dims, settings);
    let held = |tex, split| -> u64 {
        device_textures(tex, settings)
            .iter()
            .chain(&band_buffers(ctx, camera, split))
            .chain(&tables)
            .map(|b| b.1)
            .sum()
    };
    let whole = held(dims, false);
    let memory = ctx.memory.as_ref().filter(|m| whole > m.bytes);
    let why = if dims.iter().any(|&n| n > max) {
        format!("the {dims:?} volume exceeds the 3-D texture limit of {max} texels per axis")
    } else if let Some(m) = memory {
        format!(
            "the {dims:?} volume's textures, its tables and a band's buffers, {}, exceed \
             the {} of device memory a job may fill",
            crate::gpu::plan::human_bytes(whole),
            crate::gpu::plan::human_bytes(m.bytes)
        )
    } else {
        return Ok(None);
    };
    let per_voxel = device_textures([1, 1, 1], settings)
        .iter()
        .map(|t| t.1)
        .sum::<u64>();
    // What a brick leaves: the memory less the tables and a band's buffers.
    let fixed = held([0, 0, 0], true);
    let max_voxels = ctx
        .memory
        .as_ref()
        .map(|m| m.bytes.saturating_sub(fixed) / per_voxel);
    let ghost = brick_ghost(settings);
    let reach = format!(
        "the {ghost} ghost voxels of steps up to T_max = {}",
        settings.t_max
    );
    let (tree, bricks) = crate::io::brick::fitting_kd_tree(dims, ghost, max, max_voxels, &reach)?;
    let largest = bricks
        .iter()
        .map(|b| b.with_ghost(ghost, dims).dims())
        .max_by_key(|d| d.iter().product::<usize>())
        .unwrap_or(dims);
    let line = format!(
        "adaptive ray casting in {} bricks ({why}; the largest brick with its {ghost} ghost \
         voxels holds {} texels)",
        bricks.len(),
        largest.iter().product::<usize>()
    );
    Ok(Some(AdaptiveSplit {
        tree,
        bricks,
        largest,
        line,
    }))
}

/// Refuses, before anything is uploaded, a GPU adaptive render that the device cannot
/// run: invalid settings, too many samples per ray or per frame
/// ([`crate::cpu::adaptive`]'s check), rays past a CPU driver's loop limit, a table or a
/// band's buffer past one storage binding ([`device_tables`], [`band_buffers`]), what the
/// device holds at once past the memory a job may fill, and a volume no cut into bricks
/// fits ([`volume_split`]; past the 3-D texture limit or the device memory the render
/// is split). Returns the split. [`render`] and `voxlab render --sampling … --dry-run`
/// call it.
///
/// # Errors
/// [`Error::Invalid`] or [`Error::TooLarge`] saying which.
pub fn check(
    ctx: &GpuContext,
    dims: [usize; 3],
    camera: &Camera,
    settings: &AdaptiveSettings,
) -> Result<Option<AdaptiveSplit>> {
    crate::cpu::adaptive::check_cost(dims, camera, settings)?;
    let diag = crate::volume::diagonal(dims);
    if ctx.summary.is_cpu() && diag / settings.step + 2.0 > (LLVMPIPE_LOOP_LIMIT - 16) as f64 {
        return Err(Error::invalid(
            "step",
            "too many steps per ray for a CPU Vulkan driver (llvmpipe); use a larger step",
        ));
    }
    let tables = device_tables(dims, settings);
    for (label, bytes) in &tables {
        ctx.check_storage(label, *bytes)?;
    }
    let split = volume_split(ctx, dims, camera, settings)?;
    let (tex, split_bands) = match &split {
        Some(cut) => (cut.largest, true),
        None => (dims, false),
    };
    let bands = band_buffers(ctx, camera, split_bands);
    for (label, bytes) in &bands {
        ctx.check_storage(label, *bytes)?;
    }
    let held = device_textures(tex, settings)
        .iter()
        .chain(&bands)
        .chain(&tables)
        .map(|b| b.1)
        .sum();
    ctx.check_memory("adaptive render", held)?;
    Ok(split)
}

/// Renders on the GPU. Same inputs and outputs as `cpu::adaptive::render`.
///
/// A volume past the 3-D texture limit or the device memory ([`volume_split`]) renders
/// in bricks, one on the device at a time, in the order every ray meets them
/// (`cpu::composite::ray_order`): each brick's texture (with [`brick_ghost`] voxels)
/// and importance volume, and each ray's [`AdaptiveState`] handed from brick to brick
/// (a step belongs to the brick its start lies in), finished on the host: the unsplit
/// render's steps, samples and arithmetic in its order.
pub fn render(
    ctx: &GpuContext,
    volume: &AnyVolume,
    tf: &TransferFunction,
    camera: &Camera,
    settings: &AdaptiveSettings,
) -> Result<GpuAdaptiveOutput> {
    let t_start = Instant::now();
    let dims = volume.dims();
    let split = check(ctx, dims, camera, settings)?;
    tf.validate()?;
    volume.check_finite("volume")?;
    let values = volume.to_f32();
    let grid = Grid::<f32> {
        dims,
        data: values.data().to_vec(),
    };
    let ro = wgpu::BufferBindingType::Storage { read_only: true };
    let rw = wgpu::BufferBindingType::Storage { read_only: false };
    let Kernel { layout, pipeline } = ctx.kernel(
        "adaptive.wgsl",
        &shaders::resolve("adaptive"),
        Some(&[
            buffer_entry(0, wgpu::BufferBindingType::Uniform),
            texture_entry(1, false),
            buffer_entry(2, ro),
            buffer_entry(3, ro),
            texture_entry(4, false),
            buffer_entry(5, ro),
            buffer_entry(6, ro),
            buffer_entry(7, rw),
            buffer_entry(8, rw),
        ]),
        "adaptive",
    )?;
    let t_setup = t_start.elapsed().as_secs_f64();

    // The rays, computed here, go up band by band.
    let t_up = Instant::now();
    let storage = wgpu::BufferUsages::STORAGE;
    let (w, h) = (camera.width, camera.height);
    let to_index = volume.affine().inverse();
    let mut rays = Vec::with_capacity(2 * w * h);
    for row in 0..h {
        for col in 0..w {
            let r = camera.ray(col, row);
            let o = to_index.transform_point3(r.origin);
            let d = to_index.transform_vector3(r.dir);
            rays.push([
                o.x as f32,
                o.y as f32,
                o.z as f32,
                r.t_min.max(-1e30) as f32,
            ]);
            rays.push([d.x as f32, d.y as f32, d.z as f32, 0.0]);
        }
    }
    let mut upload = t_up.elapsed().as_secs_f64();

    // Set-up: tables on the device, spectra (and direct sampling's steps, over the whole
    // volume) on the host.
    let t_prep = Instant::now();
    let n = settings.preint_size;
    let preint = super::preintegrate::preintegrate_buffer(ctx, tf, n)?;
    // The table is built before the first band: its time is the set-up's.
    ctx.wait()?;
    let lut = tf.lut(n).to_real::<f32>();
    let adaptive = settings.sampling == Sampling::Adaptive;
    let direct = settings.sampling == Sampling::Direct;
    let spec = adaptive.then(|| spectral_table(tf, settings.spectrum_bins, settings.energy));
    let spec_data: Vec<f32> = spec
        .as_ref()
        .map_or(vec![0.0], |s| s.nu.iter().map(|&v| v as f32).collect());
    let spec_buf = init_buffer(ctx, "spectrum", bytemuck::cast_slice(&spec_data), storage)?;
    let ds = direct.then(|| direct_steps(&grid, tf, settings));
    let direct_data: Vec<f32> = ds
        .as_ref()
        .map_or(vec![0.0], |d| d.step.iter().map(|&v| v as f32).collect());
    let direct_buf = init_buffer(
        ctx,
        "direct steps",
        bytemuck::cast_slice(&direct_data),
        storage,
    )?;
    let mut prepare = t_prep.elapsed().as_secs_f64();

    let blocks = ds.as_ref().map_or([1, 1, 1], |d| d.blocks);
    let (d0, d1) = (tf.domain[0], tf.domain[1]);
    let bins = settings.spectrum_bins;
    let params = AdaptiveParams {
        steps: [
            settings.step as f32,
            settings.t_max as f32,
            (2.0 * settings.oversampling) as f32,
            settings.ert_threshold as f32,
        ],
        window: [
            tf.window.a as f32,
            tf.window.b as f32,
            lut.scale,
            lut.offset,
        ],
        spectrum: [
            d0 as f32,
            (bins as f64 / (d1 - d0)) as f32,
            bins as f32,
            0.0,
        ],
        background: settings.background.map(|c| c as f32),
        dims: [
            dims[0] as u32,
            dims[1] as u32,
            dims[2] as u32,
            match settings.sampling {
                Sampling::Regular => 0,
                Sampling::Adaptive => 1,
                Sampling::Direct => 2,
            },
        ],
        image: [w as u32, h as u32, 0, 0],
        table: [
            n as u32,
            bins as u32,
            settings.block as u32,
            blocks[0] as u32,
        ],
        extra: [blocks[1] as u32, blocks[2] as u32, 0, 0],
        brick: [0; 4],
        own_lo: [-f32::MAX; 4],
        own_hi: [f32::MAX; 4],
    };

    // One volume (or brick) on the device: its texture and importance volume, then the
    // bands of rows (bounded work per dispatch).
    let mut kernel = 0.0;
    let mut from_timestamps = false;
    let mut readback = 0.0;
    let mut image = Frame::new(w, h, 4);
    let mut counts = vec![0u32; w * h];
    // The importance volume's pipelines, compiled by the first brick that needs them.
    let mut importance_pipelines: Option<ImportancePipelines> = None;
    // One pass casts the rays of the pixels `rect` (the whole image, or a brick's
    // rectangle); `image` and `counts` are the rectangle's.
    let mut pass = |texels: &Grid<f32>,
                    mut params: AdaptiveParams,
                    rect: &PixelRect,
                    carry: Option<&mut [[f32; 4]]>,
                    image: &mut Frame,
                    counts: &mut [u32]|
     -> Result<()> {
        let t_up = Instant::now();
        let vol_tex = ctx.upload_volume_r32(texels.dims, &texels.data)?;
        let vol_view = vol_tex.create_view(&Default::default());
        ctx.wait()?;
        upload += t_up.elapsed().as_secs_f64();
        let t_prep = Instant::now();
        let importance = if adaptive {
            let pipelines = match &importance_pipelines {
                Some(p) => p,
                None => importance_pipelines.insert(ImportancePipelines::new(ctx)?),
            };
            importance_texture(ctx, pipelines, &vol_view, texels.dims, settings.t_max)?
        } else {
            ctx.rgba_texture([1, 1, 1], false)?
        };
        let importance_view = importance.create_view(&Default::default());
        ctx.wait()?;
        prepare += t_prep.elapsed().as_secs_f64();
        let carried = carry.is_some();
        let bands = render_bands(
            ctx,
            (&pipeline, "adaptive"),
            rows_per_band(ctx, rect.width(), rect.height(), carried),
            (rect, [w, h]),
            (image, counts),
            carry,
            &|_, _| {},
            |band, out_buf, cnt_buf| {
                let (row0, rows) = (band.rows.start, band.rows.len());
                params.image[0] = band.width() as u32;
                params.image[2] = row0 as u32;
                params.image[3] = rows as u32;
                let pbuf = init_buffer(
                    ctx,
                    "adaptive params",
                    bytemuck::bytes_of(&params),
                    super::context::PARAMS_USAGE,
                )?;
                // Each band its own rays, its pixels': an image of any size within one
                // binding.
                let mut band_rays = Vec::with_capacity(2 * band.len());
                for row in band.rows.clone() {
                    let first = row * w + band.cols.start;
                    band_rays.extend_from_slice(&rays[2 * first..2 * (first + band.width())]);
                }
                let ray_buf = init_buffer(ctx, "rays", bytemuck::cast_slice(&band_rays), storage)?;
                Ok(ctx.bind_group(
                    "adaptive",
                    &layout,
                    &[
                        pbuf.as_entire_binding(),
                        wgpu::BindingResource::TextureView(&vol_view),
                        preint.as_entire_binding(),
                        spec_buf.as_entire_binding(),
                        wgpu::BindingResource::TextureView(&importance_view),
                        direct_buf.as_entire_binding(),
                        ray_buf.as_entire_binding(),
                        out_buf.as_entire_binding(),
                        cnt_buf.as_entire_binding(),
                    ],
                ))
            },
        )?;
        kernel += bands.kernel;
        from_timestamps = bands.from_timestamps;
        readback += bands.readback;
        Ok(())
    };
    let line = match &split {
        None => {
            pass(
                &grid,
                params,
                &PixelRect::whole(w, h),
                None,
                &mut image,
                &mut counts,
            )?;
            None
        }
        Some(cut) => {
            let ghost = brick_ghost(settings);
            let mut carry = vec![[0.0f32; 4]; w * h * CARRIED_VEC4S];
            let order = crate::cpu::composite::ray_order(&cut.tree, camera, volume.affine());
            // A brick holds steps of the rays of its rectangle's pixels alone, and none
            // when no ray meets it: skipped. A ray no brick casts misses the volume.
            let seen = super::raycast::bricks_seen(camera, volume.affine(), &cut.bricks);
            for bi in order {
                let Some(rect) = &seen[bi] else {
                    continue;
                };
                let b = &cut.bricks[bi];
                let g = b.with_ghost(ghost, dims);
                let c = values.crop(g.lo, g.hi)?;
                let texels = Grid::<f32> {
                    dims: c.dims(),
                    data: c.into_data(),
                };
                let mut p = params;
                p.brick = [g.lo[0] as i32, g.lo[1] as i32, g.lo[2] as i32, 1];
                for (a, &n) in dims.iter().enumerate() {
                    if b.lo[a] > 0 {
                        p.own_lo[a] = b.lo[a] as f32 - 0.5;
                    }
                    if b.hi[a] < n {
                        p.own_hi[a] = b.hi[a] as f32 - 0.5;
                    }
                }
                // The pixels stay in `carry`: the rectangle's image and counts are
                // scratch.
                let mut scratch = Frame::new(rect.width(), rect.height(), 4);
                let mut scratch_counts = vec![0u32; rect.len()];
                pass(
                    &texels,
                    p,
                    rect,
                    Some(&mut carry),
                    &mut scratch,
                    &mut scratch_counts,
                )?;
            }
            // Each ray's state after the last brick, finished as the unsplit render
            // finishes it.
            let bg = settings.background.map(|c| c as f32);
            let miss = [bg[0] * bg[3], bg[1] * bg[3], bg[2] * bg[3], bg[3]];
            for (p, state) in carry.chunks(CARRIED_VEC4S).enumerate() {
                let st = carried_state(state);
                let (px, n) = match st.started {
                    true => (over_background(st.c, st.a, bg), st.taken),
                    false => (miss, 0),
                };
                for (x, v) in image.data[4 * p..4 * p + 4].iter_mut().zip(px) {
                    *x = v as f64;
                }
                counts[p] = n;
            }
            Some(cut.line.clone())
        }
    };
    Ok(GpuAdaptiveOutput {
        output: RenderOutput::from_counts(image, &counts, settings.sample_count),
        timings: AdaptiveTimings {
            setup: t_setup,
            upload,
            prepare,
            kernel,
            kernel_from_timestamps: from_timestamps,
            readback,
            total: t_start.elapsed().as_secs_f64(),
        },
        split: line,
    })
}
