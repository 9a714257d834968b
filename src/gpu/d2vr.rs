//! D²VR on the GPU: the port of [`crate::cpu::d2vr::render_d2vr`].
//!
//! The paper (Xu & Mueller 2006, §4) marches image-aligned slices: for each depth the
//! whole image's samples are reconstructed from all projections, classified, shaded and
//! composited front to back into an accumulation buffer. Here a dispatch handles a
//! *chunk* of sample indices `[k0, k1)` of every ray (one invocation per pixel, the
//! loop over views inside), with exactly the CPU ray caster's sample positions and step
//! rule, so parity is exact up to f32. Chunks are sized so that one invocation stays
//! far below llvmpipe's 65 535-loop-iteration limit and one dispatch does a bounded
//! amount of work. A ray that reached the early-ray-termination threshold skips all
//! later chunks (occlusion culling); the bounding cylinder and the occupancy mask
//! skip reconstructions as on the CPU.
//!
//! # Storage precision (paper §3.3)
//! [`ProjStorage::F32`] uploads the filtered projections as f32; [`ProjStorage::F16`]
//! packs them as IEEE half floats, two per word (`pack2x16float` layout), halving the
//! memory and bandwidth. The reconstruction and everything after it stays f32.
//!
//! The final background blend is done on the host in f64 from the accumulated
//! `(C, A)`, exactly as `cpu::raycast::cast_ray` ends.

use super::context::{GpuContext, LLVMPIPE_LOOP_LIMIT};
use super::params::RaycastParams;
use super::raycast::raycast_params;
use crate::camera::Camera;
use crate::cpu::d2vr::{
    check_inputs, effective_cylinder, D2vrGradient, D2vrGrid, D2vrOptions, D2vrStats, OccupancyMask,
};
use crate::cpu::raycast::RenderOutput;
use crate::ct::{Geometry, Projections};
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::settings::{Compositing, Filter, Mode, RenderSettings};
use crate::transfer::TransferFunction;
use glam::DMat3;
use std::time::Instant;
use wgpu::util::DeviceExt;

/// `shaders/shared/d2vr_params.wgsl`: the WGSL twin of [`D2vrParams`].
pub const PARAMS_WGSL: &str = super::shaders::D2VR_PARAMS;

/// Bilinear taps one dispatch may read in total (keeps a dispatch well under a
/// second on lavapipe).
const TAPS_PER_DISPATCH: f64 = 4e8;

/// How the filtered projections are stored on the GPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProjStorage {
    F32,
    /// IEEE binary16, two values per 32-bit word.
    F16,
}

/// Per-chunk parameters, shared with `shaders/shared/d2vr_params.wgsl: D2vrParams`
/// (160 bytes, ten 16-byte vectors; `tests/gpu_d2vr.rs` checks the layout).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct D2vrParams {
    pub to_world_0: [f32; 4],
    pub to_world_1: [f32; 4],
    pub to_world_2: [f32; 4],
    pub jt_0: [f32; 4],
    pub jt_1: [f32; 4],
    pub jt_2: [f32; 4],
    /// radius², y_lo, y_hi, π/(2A).
    pub cylinder: [f32; 4],
    /// cols, rows, views, storage (0 f32, 1 f16).
    pub det: [u32; 4],
    /// gradient (0 GFS, 1 GFR), cylinder, occupancy, unused.
    pub flags: [u32; 4],
    /// samples [x, y) of this dispatch.
    pub chunk: [u32; 4],
}

/// The complete WGSL module for a storage precision: `shaders/d2vr.wgsl` and its
/// imports, with the generated module `d2vr_tap` (`fn tap(i: u32) -> f32`, projection
/// element i read in `storage`'s precision).
pub fn shader_source(storage: ProjStorage) -> String {
    let tap = match storage {
        ProjStorage::F32 => "fn tap(i: u32) -> f32 {\n    return bitcast<f32>(proj[i]);\n}\n",
        ProjStorage::F16 => {
            "fn tap(i: u32) -> f32 {\n    let v = unpack2x16float(proj[i >> 1u]);\n    \
             return select(v.x, v.y, (i & 1u) == 1u);\n}\n"
        }
    };
    super::shaders::resolve_with("d2vr", &[("d2vr_tap", tap)])
}

/// Rounds to IEEE binary16 bits (round to nearest even), as `pack2x16float` does.
pub fn f16_bits(x: f32) -> u16 {
    half_from_f32(x)
}

fn half_from_f32(x: f32) -> u16 {
    let b = x.to_bits();
    let sign = ((b >> 16) & 0x8000) as u16;
    let exp = ((b >> 23) & 0xff) as i32;
    let man = b & 0x7f_ffff;
    if exp == 0xff {
        return sign | 0x7c00 | if man != 0 { 0x200 } else { 0 };
    }
    let e = exp - 127 + 15;
    if e >= 0x1f {
        return sign | 0x7c00;
    }
    if e <= 0 {
        if e < -10 {
            return sign;
        }
        let m = man | 0x80_0000;
        let shift = (14 - e) as u32;
        let half = m >> shift;
        let rem = m & ((1 << shift) - 1);
        let mid = 1 << (shift - 1);
        let round = (rem > mid || (rem == mid && half & 1 == 1)) as u32;
        return sign | (half + round) as u16;
    }
    let half = ((e as u32) << 10) | (man >> 13);
    let rem = man & 0x1fff;
    let round = (rem > 0x1000 || (rem == 0x1000 && half & 1 == 1)) as u32;
    sign | (half + round) as u16
}

/// Where the time went, seconds.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct D2vrTimings {
    /// Shader, pipeline, buffers and uploads.
    pub setup: f64,
    /// The chunk dispatches (wall clock, waited for).
    pub kernel: f64,
    /// Readback and the host's final blend.
    pub readback: f64,
    pub total: f64,
    /// Number of chunk dispatches.
    pub dispatches: usize,
}

/// What the GPU returns: the image, the work counters and timings.
#[derive(Clone, Debug)]
pub struct GpuD2vrOutput {
    pub render: RenderOutput,
    pub stats: D2vrStats,
    pub timings: D2vrTimings,
}

/// [`crate::cpu::d2vr::render_d2vr`] on the GPU (front-to-back compositing only).
///
/// # Errors
/// As the CPU version; [`Error::Invalid`] for back-to-front compositing,
/// [`Error::TooLarge`] when the projections exceed a storage binding,
/// [`Error::Gpu`] on device failure.
#[allow(clippy::too_many_arguments)]
pub fn render_d2vr(
    ctx: &GpuContext,
    filtered: &Projections<f32>,
    geometry: &Geometry,
    grid: &D2vrGrid,
    tf: &TransferFunction,
    camera: &Camera,
    settings: &RenderSettings,
    options: &D2vrOptions,
    occupancy: Option<&OccupancyMask>,
    storage: ProjStorage,
) -> Result<GpuD2vrOutput> {
    let t0 = Instant::now();
    check_inputs(settings, options, grid)?;
    tf.validate()?;
    geometry.validate()?;
    // As on the CPU: the bounding cylinder is that of a circular orbit.
    geometry.require_circular("D²VR")?;
    filtered.check_against(geometry)?;
    if settings.mode == Mode::Dvr && settings.compositing == Compositing::BackToFront {
        return Err(Error::invalid(
            "compositing",
            "GPU D²VR marches image-aligned slices front to back; use front-to-back",
        ));
    }
    if matches!(settings.mode, Mode::Mida | Mode::Iso)
        || (settings.mode == Mode::Dvr && !settings.iso_surfaces.is_empty())
        || settings.window.is_some()
    {
        return Err(Error::invalid(
            "mode",
            "GPU D²VR renders DVR, MIP, MinIP and X-ray; MIDA, iso-surfaces and the grey \
             window (docs/modes.md) run on the CPU D²VR",
        ));
    }
    if let Some(m) = occupancy {
        if m.dims != grid.dims {
            return Err(Error::invalid(
                "occupancy mask",
                format!("mask is {:?} but the grid is {:?}", m.dims, grid.dims),
            ));
        }
    }
    // The ray caster's parameter block; the filter is irrelevant to D²VR.
    let rs = RenderSettings {
        filter: Filter::Trilinear,
        hardware_filtering: false,
        ..settings.clone()
    };
    let lut = tf.lut(settings.lut_size).to_real::<f32>();
    let rp: RaycastParams = raycast_params(
        grid.dims,
        grid.affine,
        &lut,
        options.value_range,
        camera,
        &rs,
    )?;

    let lin = DMat3::from_mat4(grid.affine);
    let jt = lin.transpose();
    let row4 = |i: usize| {
        let r = grid.affine.row(i);
        [r.x as f32, r.y as f32, r.z as f32, r.w as f32]
    };
    let jrow = |i: usize| {
        let r = jt.row(i);
        [r.x as f32, r.y as f32, r.z as f32, 0.0]
    };
    let cyl = effective_cylinder(geometry);
    let base = D2vrParams {
        to_world_0: row4(0),
        to_world_1: row4(1),
        to_world_2: row4(2),
        jt_0: jrow(0),
        jt_1: jrow(1),
        jt_2: jrow(2),
        cylinder: [
            (cyl.radius * cyl.radius) as f32,
            cyl.y_lo as f32,
            cyl.y_hi as f32,
            crate::cpu::d2vr::backprojection_scale(geometry.n_angles()) as f32,
        ],
        det: [
            geometry.cols as u32,
            geometry.rows as u32,
            geometry.n_angles() as u32,
            (storage == ProjStorage::F16) as u32,
        ],
        flags: [
            (options.gradient == D2vrGradient::Gfr) as u32,
            options.cylinder as u32,
            occupancy.is_some() as u32,
            0,
        ],
        chunk: [0; 4],
    };

    // Uploads.
    let words: Vec<u32> = match storage {
        ProjStorage::F32 => filtered.data.iter().map(|v| v.to_bits()).collect(),
        ProjStorage::F16 => filtered
            .data
            .chunks(2)
            .map(|c| {
                let lo = half_from_f32(c[0]) as u32;
                let hi = c.get(1).map_or(0, |&v| half_from_f32(v) as u32);
                lo | (hi << 16)
            })
            .collect(),
    };
    let limit = crate::gpu::plan::binding_limit(&ctx.limits);
    if words.len() as u64 * 4 > limit {
        return Err(Error::too_large(
            "D²VR projections",
            format!(
                "{} bytes exceed the adapter's storage-binding limit of {limit} bytes: \
                 use fewer or smaller projections, 16-bit storage, or the CPU",
                words.len() * 4
            ),
        ));
    }
    let dev = &ctx.device;
    let init = |label: &str, bytes: &[u8], usage: wgpu::BufferUsages| {
        dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytes,
            usage,
        })
    };
    let storage_ro = wgpu::BufferUsages::STORAGE;
    let proj_buf = init("d2vr projections", bytemuck::cast_slice(&words), storage_ro);
    let views = geometry.view_matrices::<f32>();
    let views_buf = init("d2vr views", bytemuck::cast_slice(&views), storage_ro);
    let lut_host: Vec<[f32; 4]> = lut.entries.clone();
    let lut_buf = init("d2vr lut", bytemuck::cast_slice(&lut_host), storage_ro);
    let occ_host: Vec<u32> = occupancy.map_or(vec![0], |m| m.occupied.clone());
    let occ_buf = init(
        "d2vr occupancy",
        bytemuck::cast_slice(&occ_host),
        storage_ro,
    );
    let rp_buf = init(
        "d2vr raycast params",
        bytemuck::bytes_of(&rp),
        wgpu::BufferUsages::UNIFORM,
    );
    let (w, h) = (camera.width, camera.height);
    let pixels = (w * h) as u64;
    let acc_buf = ctx.storage_buffer("d2vr accumulation", pixels * 16)?;
    let cnt_buf = ctx.storage_buffer("d2vr counts", pixels * 16)?;
    // Storage buffers start zeroed in wgpu.

    let module = ctx.shader("d2vr.wgsl", &shader_source(storage))?;
    let pipeline = dev.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("d2vr_chunk"),
        layout: None,
        module: &module,
        entry_point: Some("d2vr_chunk"),
        compilation_options: Default::default(),
        cache: None,
    });
    let layout = pipeline.get_bind_group_layout(0);

    // Chunk size: per invocation, samples × views × (1 value + 6 GFS neighbours or
    // 1 GFR pass) loop iterations stay under half llvmpipe's limit; per dispatch, the
    // taps stay under TAPS_PER_DISPATCH.
    let per_sample = geometry.n_angles()
        * match (settings.mode, settings.shading.enabled, options.gradient) {
            (Mode::Dvr, true, D2vrGradient::Gfs) => 7,
            (Mode::Dvr, true, D2vrGradient::Gfr) => 2,
            _ => 1,
        };
    let by_loop = (LLVMPIPE_LOOP_LIMIT / 2) / per_sample.max(1);
    let by_work = (TAPS_PER_DISPATCH / (pixels as f64 * per_sample as f64 * 4.0)) as usize;
    let chunk = by_loop.min(by_work).max(1);
    if by_loop == 0 {
        return Err(Error::too_large(
            "D²VR views",
            format!(
                "{} views × {} reconstructions per sample exceed one GPU invocation's loop \
                 budget ({LLVMPIPE_LOOP_LIMIT} iterations on llvmpipe): use GFR or fewer views",
                geometry.n_angles(),
                per_sample / geometry.n_angles()
            ),
        ));
    }
    // The longest ray: the box diagonal in voxels over the step.
    let d = grid.dims;
    let diag = ((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) as f64).sqrt();
    let max_n = (diag / settings.step).ceil() as usize + 2;
    let setup = t0.elapsed().as_secs_f64();

    let t = Instant::now();
    let mut dispatches = 0;
    let mut k0 = 0usize;
    while k0 < max_n {
        let k1 = (k0 + chunk).min(max_n);
        let p = D2vrParams {
            chunk: [k0 as u32, k1 as u32, 0, 0],
            ..base
        };
        let dp_buf = init(
            "d2vr chunk",
            bytemuck::bytes_of(&p),
            wgpu::BufferUsages::UNIFORM,
        );
        let bind = ctx.bind_group(
            "d2vr",
            &layout,
            &[
                rp_buf.as_entire_binding(),
                dp_buf.as_entire_binding(),
                views_buf.as_entire_binding(),
                proj_buf.as_entire_binding(),
                lut_buf.as_entire_binding(),
                occ_buf.as_entire_binding(),
                acc_buf.as_entire_binding(),
                cnt_buf.as_entire_binding(),
            ],
        );
        let mut enc = dev.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("d2vr_chunk"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups((w as u32).div_ceil(8), (h as u32).div_ceil(8), 1);
        }
        ctx.queue.submit([enc.finish()]);
        // One chunk at a time: keeps each submission short on a software device.
        ctx.wait()?;
        dispatches += 1;
        k0 = k1;
    }
    let kernel = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let acc: Vec<[f32; 4]> =
        bytemuck::cast_slice(&ctx.read_buffer(&acc_buf, pixels * 16)?).to_vec();
    let cnt: Vec<[u32; 4]> =
        bytemuck::cast_slice(&ctx.read_buffer(&cnt_buf, pixels * 16)?).to_vec();
    let channels = if settings.mode == Mode::Dvr { 4 } else { 1 };
    let mut image = Frame::new(w, h, channels);
    let bg = settings.background;
    for i in 0..w * h {
        let a = acc[i].map(|v| v as f64);
        let px: [f64; 4] = if cnt[i][0] == 0 {
            if settings.mode == Mode::Dvr {
                bg
            } else {
                [settings.miss_value, 0.0, 0.0, 0.0]
            }
        } else if settings.mode == Mode::Dvr {
            let t = 1.0 - a[3];
            [
                a[0] + t * bg[0] * bg[3],
                a[1] + t * bg[1] * bg[3],
                a[2] + t * bg[2] * bg[3],
                a[3] + t * bg[3],
            ]
        } else {
            a
        };
        image.data[i * channels..(i + 1) * channels].copy_from_slice(&px[..channels]);
    }
    let visited: Vec<u32> = cnt.iter().map(|c| c[1]).collect();
    let render = RenderOutput::from_counts(image, &visited, settings.sample_count);
    let stats = D2vrStats {
        box_samples: cnt.iter().map(|c| c[0] as u64).sum(),
        visited_samples: render.total_samples,
        value_reconstructions: cnt.iter().map(|c| c[2] as u64).sum(),
        gradient_reconstructions: cnt.iter().map(|c| c[3] as u64).sum(),
    };
    let readback = t.elapsed().as_secs_f64();
    Ok(GpuD2vrOutput {
        render,
        stats,
        timings: D2vrTimings {
            setup,
            kernel,
            readback,
            total: t0.elapsed().as_secs_f64(),
            dispatches,
        },
    })
}
