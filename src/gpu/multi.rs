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
//!   1×1×1 dummy fills an unused slot), sampled in its own index coordinates (split: a
//!   cell's part of it, from voxel `origin` on);
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
//! A scene with a volume past the 3-D texture limit, or whose textures exceed the device
//! memory a job may fill, is cut into k-d cells of the scene ([`scene_split`]), each
//! holding its part of every volume; the cells render in the rays' order, each ray's
//! state ([`CARRIED_VEC4S`] vec4 a pixel) handed from cell to cell, and the image is the
//! unsplit one bit for bit ([`render`]; docs/gpu.md, "The multi-volume caster in cells").
//!
//! Supported: nearest and trilinear reconstruction, central and forward gradients
//! computed on the fly. Other filters, Sobel gradients, precomputed gradients and
//! hardware filtering are refused with an error naming what is supported (the CPU
//! backends render them).

use super::context::{
    buffer_entry, render_bands, texture_entry, GpuContext, Kernel, LLVMPIPE_LOOP_LIMIT,
};
use super::raycast::GpuTimings;
use crate::camera::{Camera, PixelRect, Projection};
use crate::cpu::raycast::RenderOutput;
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::gpu::plan::human_bytes;
use crate::io::brick::{Brick, KdTree};
use crate::multi::{MultiVolume, MAX_VOLUMES};
use crate::settings::{Compositing, Filter, GradientMethod, Light, Mode, RenderSettings};
use crate::volume::Volume;
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
    /// Volumes, back-to-front, unused ×2.
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
    /// Volume `i`'s voxel held at texel 0 of its texture (a cell's part of the volume
    /// when split; 0 whole); w unused.
    pub origin: [[i32; 4]; 3],
    /// The box of volume 0's index space whose step midpoints the pass takes,
    /// `own_lo ≤ p < own_hi` (±`f32::MAX` on open faces; everything when not split).
    pub own_lo: [f32; 4],
    pub own_hi: [f32; 4],
    /// x = 1: read and write each ray's carried state ([`CARRIED_VEC4S`] vec4 a pixel);
    /// y = 1: finish the pixels (the last cell, or not split); unused ×2.
    pub carry: [u32; 4],
    /// The pixels a dispatch casts: first column, first row, columns, rows (of the
    /// frame `image.xy`; one invocation each, row-major in the output buffers).
    pub tile: [u32; 4],
}

/// The vec4s a pixel's ray hands the next cell of a split render
/// (`shaders/multi.wgsl: Carried`): what it gathered (DVR colour and opacity, MIP and
/// MinIP the extreme and whether one was found, X-ray the sum) and where it is (the
/// next step, the samples taken, ended early, the ray's steps).
pub const CARRIED_VEC4S: usize = 2;

/// A GPU multi-volume render: the image, timings, and how the scene was cut when it was.
#[derive(Debug)]
pub struct GpuMultiOutput {
    pub output: RenderOutput,
    pub timings: GpuTimings,
    /// The line the job prints for a split render ([`MultiSplit::line`]).
    pub split: Option<String>,
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
            0,
        ],
        gradient: [
            (settings.gradient == GradientMethod::Forward) as u32,
            0,
            0,
            0,
        ],
        own_lo: [-f32::MAX; 4],
        own_hi: [f32::MAX; 4],
        carry: [0, 1, 0, 0],
        tile: [0, 0, camera.width as u32, camera.height as u32],
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

/// Rows of a `w`×`h` image per dispatch: at most 8,192 pixels, and a band's RGBA f32
/// pixels (split: the rays' carried states, [`CARRIED_VEC4S`] vec4 a pixel) within one
/// storage binding.
pub fn rows_per_band(ctx: &GpuContext, w: usize, h: usize, split: bool) -> usize {
    let max_binding = ctx.limits.max_storage_buffer_binding_size as usize;
    (max_binding / (w.max(1) * pixel_bytes(split) as usize))
        .min(PIXELS_PER_DISPATCH / w.max(1))
        .clamp(1, h.max(1))
}

/// A pixel's bytes in a band's pixel buffer.
fn pixel_bytes(split: bool) -> u64 {
    if split {
        16 * CARRIED_VEC4S as u64
    } else {
        16
    }
}

/// How a multi-volume render too large for the device is cut ([`scene_split`]): a k-d
/// tree of cells over the reference grid (volume 0's voxel grid, widened to cover every
/// volume's box), each cell taking the steps whose midpoints lie in it and holding the
/// part of every volume those steps sample.
#[derive(Clone, Debug)]
pub struct MultiSplit {
    pub tree: KdTree,
    pub cells: Vec<MultiCell>,
    /// The cells' boxes in the reference grid (the tree's leaves, in the cells' order).
    pub boxes: Vec<Brick>,
    /// The reference grid's index → world (the cells' ray order).
    pub affine: DMat4,
    /// The largest cell's textures, in bytes.
    pub largest: u64,
    /// What the job prints: "multi-volume ray casting in 8 cells (…, why)".
    pub line: String,
}

/// One cell of a [`MultiSplit`].
#[derive(Clone, Debug, PartialEq)]
pub struct MultiCell {
    /// The box of volume 0's index space whose step midpoints the cell takes,
    /// `own_lo ≤ p < own_hi`, ±`f32::MAX` on the scene's outer faces.
    pub own_lo: [f32; 3],
    pub own_hi: [f32; 3],
    /// Each volume's voxels (with the ghost voxels its samples read) the cell's steps
    /// may sample; `None` where the cell meets no part of the volume.
    pub parts: Vec<Option<Brick>>,
}

/// The reference grid of a split: voxel `j` is volume 0's voxel `j + offset`, and its
/// dimensions cover the union of every volume's box (`index → world`, dimensions).
/// Returns `(dims, offset)`.
fn reference_grid(boxes: &[(DMat4, [usize; 3])]) -> Result<([usize; 3], DVec3)> {
    let to0 = boxes[0].0.inverse();
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for (m, dims) in boxes {
        let n = DVec3::from_array(dims.map(|x| x as f64));
        for q in box_corners(DVec3::splat(-0.5), n - 0.5) {
            let p = to0.transform_point3(m.transform_point3(q));
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    let offset = (lo + 0.5).floor();
    let span = (hi + 0.5).ceil() - offset;
    if !span.is_finite() || span.max_element() > (1u64 << 31) as f64 {
        return Err(Error::too_large(
            "scene",
            format!(
                "the volumes' boxes span {:.3e} voxels of volume 0: too far apart to cut \
                 into cells",
                span.max_element()
            ),
        ));
    }
    Ok((span.max(DVec3::ONE).to_array().map(|x| x as usize), offset))
}

/// How far (voxels of the volume) a cell's part reaches past the image of the cell's
/// box: room for the f32 rounding of the sample positions.
const PART_MARGIN: f64 = 0.05;

/// The voxels of a volume of `dims` (reached from volume 0's index space by `to_i`) that
/// steps with midpoints in the box `[lo, hi]` of volume 0's index space may read: the
/// box's image (widened by [`PART_MARGIN`]) clipped to the volume's box, the voxels a
/// nearest or trilinear sample there reads, and `ghost` more each way (1 where the
/// volume is shaded: its gradient's differences). `None` when the box misses the volume.
fn cell_part(lo: DVec3, hi: DVec3, to_i: &DMat4, dims: [usize; 3], ghost: usize) -> Option<Brick> {
    let (mut a, mut b) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for q in box_corners(lo, hi) {
        let p = to_i.transform_point3(q);
        a = a.min(p);
        b = b.max(p);
    }
    let n = DVec3::from_array(dims.map(|x| x as f64));
    let a = (a - PART_MARGIN).max(DVec3::splat(-0.5));
    let b = (b + PART_MARGIN).min(n - 0.5);
    if !a.cmple(b).all() {
        return None;
    }
    let g = ghost as f64;
    Some(Brick {
        lo: std::array::from_fn(|k| (a[k].floor() - g).max(0.0) as usize),
        hi: std::array::from_fn(|k| (b[k].floor() + 2.0 + g).min(n[k]) as usize),
    })
}

/// The bytes a multi-volume render holds on the device besides its volumes: the lookup
/// tables and one band's pixels (split: carried states) and sample counts.
fn fixed_bytes(
    ctx: &GpuContext,
    camera: &Camera,
    settings: &RenderSettings,
    count: usize,
    split: bool,
) -> (u64, u64) {
    let (w, h) = (camera.width, camera.height);
    let rows = rows_per_band(ctx, w, h, split) as u64;
    let pixels = rows * w as u64 * pixel_bytes(split);
    let luts = (count * settings.lut_size.max(2) * 16) as u64;
    (luts + pixels + rows * w as u64 * 4, pixels)
}

/// Whether and how a multi-volume render is cut into cells on `ctx`: when a volume
/// exceeds the planner's 3-D texture limit, or the volumes' textures with the tables
/// and a band's buffers exceed the device memory a job may fill. `None` when every
/// volume fits whole. Cells halve the reference grid (volume 0's voxels over the union
/// of the boxes) until each cell's part of every volume fits the texture limit and the
/// cell's parts together fit the memory left. [`render`] and the dry run ask it.
///
/// # Errors
/// No cut fits (a limit below what one voxel of volume 0 needs of the volumes).
pub fn scene_split(
    ctx: &GpuContext,
    volumes: &[MultiVolume],
    camera: &Camera,
    settings: &RenderSettings,
) -> Result<Option<MultiSplit>> {
    let max = ctx.limits.max_texture_dimension_3d as usize;
    let textures: u64 = volumes
        .iter()
        .map(|v| 4 * v.volume.dims().iter().product::<usize>() as u64)
        .sum();
    let whole = textures + fixed_bytes(ctx, camera, settings, volumes.len(), false).0;
    let memory = ctx.memory.as_ref().filter(|m| whole > m.bytes);
    let too_wide = volumes
        .iter()
        .enumerate()
        .map(|(i, v)| (i, v.volume.dims()))
        .find(|(_, d)| d.iter().any(|&n| n > max));
    let why = if let Some((i, dims)) = too_wide {
        format!("volume {i}, {dims:?}, exceeds the 3-D texture limit of {max} texels per axis")
    } else if let Some(m) = memory {
        format!(
            "the volumes' textures, the tables and a band's buffers, {}, exceed the {} of \
             device memory a job may fill",
            human_bytes(whole),
            human_bytes(m.bytes)
        )
    } else {
        return Ok(None);
    };
    let fixed = fixed_bytes(ctx, camera, settings, volumes.len(), true).0;
    if let Some(m) = ctx.memory.as_ref().filter(|m| fixed >= m.bytes) {
        return Err(Error::too_large(
            "multi-volume render",
            format!(
                "the lookup tables and a band's buffers alone, {}, leave nothing of the {} \
                 of device memory a job may fill ({}) for the volumes",
                human_bytes(fixed),
                human_bytes(m.bytes),
                m.source
            ),
        ));
    }
    let budget = ctx.memory.as_ref().map(|m| m.bytes - fixed);
    let boxes = volumes
        .iter()
        .map(|v| Ok((v.index_to_world()?, v.volume.dims())))
        .collect::<Result<Vec<_>>>()?;
    let (dims, offset) = reference_grid(&boxes)?;
    let to0 = boxes[0].0;
    let shaded = settings.mode == Mode::Dvr && settings.shading.enabled;
    let parts = |b: &Brick| -> Vec<Option<Brick>> {
        let lo = DVec3::from_array(b.lo.map(|x| x as f64)) + offset - 0.5;
        let hi = DVec3::from_array(b.hi.map(|x| x as f64)) + offset - 0.5;
        volumes
            .iter()
            .zip(&boxes)
            .map(|(v, (m, d))| {
                cell_part(
                    lo,
                    hi,
                    &(m.inverse() * to0),
                    *d,
                    (shaded && v.shade) as usize,
                )
            })
            .collect()
    };
    let texels = |ps: &[Option<Brick>]| ps.iter().flatten().map(|p| p.voxels() as u64).sum::<u64>();
    let fits = |b: &Brick| {
        let ps = parts(b);
        ps.iter()
            .flatten()
            .all(|p| p.dims().iter().all(|&n| n <= max))
            && budget.is_none_or(|m| 4 * texels(&ps) <= m)
    };
    let Some((tree, bricks)) = crate::io::brick::fewest_kd_tree(dims, &fits) else {
        let bytes = budget
            .map(|m| {
                format!(
                    " and {} in all (the memory less the tables and a band's buffers)",
                    human_bytes(m)
                )
            })
            .unwrap_or_default();
        return Err(Error::too_large(
            "scene",
            format!(
                "the multi-volume scene cannot be cut into cells whose parts of the volumes \
                 fit {max} texels per axis{bytes}: a cell one voxel of volume 0 wide needs \
                 more (of a volume with finer voxels, or with the voxels a sample and its \
                 gradient read); render on the CPU (--backend cpu-f32) ({why})"
            ),
        ));
    };
    let cells: Vec<MultiCell> = bricks
        .iter()
        .map(|b| MultiCell {
            own_lo: std::array::from_fn(|k| {
                if b.lo[k] == 0 {
                    -f32::MAX
                } else {
                    (b.lo[k] as f64 + offset[k] - 0.5) as f32
                }
            }),
            own_hi: std::array::from_fn(|k| {
                if b.hi[k] == dims[k] {
                    f32::MAX
                } else {
                    (b.hi[k] as f64 + offset[k] - 0.5) as f32
                }
            }),
            parts: parts(b),
        })
        .collect();
    let largest = cells
        .iter()
        .map(|c| 4 * texels(&c.parts))
        .max()
        .unwrap_or(0);
    let line = format!(
        "multi-volume ray casting in {} cells ({why}; the largest cell holds {} texels of \
         the volumes)",
        cells.len(),
        largest / 4
    );
    Ok(Some(MultiSplit {
        tree,
        cells,
        boxes: bricks,
        affine: to0 * DMat4::from_translation(offset),
        largest,
        line,
    }))
}

/// The 8 corners of the box `[lo, hi]`.
fn box_corners(lo: DVec3, hi: DVec3) -> [DVec3; 8] {
    std::array::from_fn(|c| {
        DVec3::new(
            if c & 1 == 0 { lo.x } else { hi.x },
            if c & 2 == 0 { lo.y } else { hi.y },
            if c & 4 == 0 { lo.z } else { hi.z },
        )
    })
}

/// Refuses, before anything is converted or uploaded, a GPU multi-volume render the
/// device cannot run: what every backend refuses ([`crate::multi::check`]), filters and
/// options this caster lacks, rays past a CPU driver's loop limit, a scene no cut into
/// cells fits ([`scene_split`]; past the 3-D texture limit or the device memory the
/// render is split), a band's buffer past a binding, and what the device holds at once
/// past the memory a job may fill. Returns the split. [`render`] and
/// `voxlab render --volume … --dry-run` call it.
///
/// # Errors
/// [`Error::Invalid`] or [`Error::TooLarge`] saying which.
pub fn check(
    ctx: &GpuContext,
    volumes: &[MultiVolume],
    camera: &Camera,
    settings: &RenderSettings,
) -> Result<Option<MultiSplit>> {
    let per_ray = crate::multi::check(volumes, camera, settings)?;
    check_gpu_settings(settings)?;
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
    let split = scene_split(ctx, volumes, camera, settings)?;
    let (_, pixels) = fixed_bytes(ctx, camera, settings, volumes.len(), split.is_some());
    ctx.check_storage("pixels", pixels)?;
    let (held, _) = device_bytes(ctx, volumes, camera, settings, split.as_ref());
    ctx.check_memory("multi-volume render", held)?;
    Ok(split)
}

/// What a GPU multi-volume render holds on the device: every volume's `R32Float`
/// texture (split: the largest cell's parts of them), the lookup tables and one band's
/// pixels (split: carried states) and u32 counts, as `(at once, the largest single
/// object)` in bytes.
pub fn device_bytes(
    ctx: &GpuContext,
    volumes: &[MultiVolume],
    camera: &Camera,
    settings: &RenderSettings,
    split: Option<&MultiSplit>,
) -> (u64, u64) {
    let (fixed, pixels) = fixed_bytes(ctx, camera, settings, volumes.len(), split.is_some());
    let (textures, largest) = match split {
        None => {
            let each = volumes
                .iter()
                .map(|v| 4 * v.volume.dims().iter().product::<usize>() as u64);
            (each.clone().sum::<u64>(), each.max().unwrap_or(0))
        }
        Some(cut) => {
            let part = cut
                .cells
                .iter()
                .flat_map(|c| c.parts.iter().flatten())
                .map(|p| 4 * p.voxels() as u64)
                .max()
                .unwrap_or(0);
            (cut.largest, part)
        }
    };
    (textures + fixed, largest.max(pixels))
}

/// Renders a multi-volume scene on the GPU. Same inputs and meaning as
/// `cpu::multi::render`; returns the image, the sample counts, timings and the split.
///
/// A scene past the 3-D texture limit or the device memory ([`scene_split`]) renders
/// in cells, one on the device at a time, in the order every ray meets them
/// (`cpu::composite::ray_order`; back to front for back-to-front DVR): each cell's part
/// of every volume, and each ray's state handed from cell to cell (a step belongs to the
/// cell its midpoint lies in), the last cell finishing the pixels: the unsplit image, bit
/// for bit (`tests/gpu_multi.rs`).
pub fn render(
    ctx: &GpuContext,
    volumes: &[MultiVolume],
    camera: &Camera,
    settings: &RenderSettings,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<GpuMultiOutput> {
    let t_start = Instant::now();
    let split = check(ctx, volumes, camera, settings)?;

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
    let params = multi_params(volumes, camera, settings, &luts, &ranges)?;

    let dev = &ctx.device;
    let storage = |read_only| wgpu::BufferBindingType::Storage { read_only };
    let Kernel { layout, pipeline } = ctx.kernel(
        "multi.wgsl",
        &multi_shader(),
        Some(&[
            buffer_entry(0, wgpu::BufferBindingType::Uniform),
            texture_entry(1, false),
            texture_entry(2, false),
            texture_entry(3, false),
            buffer_entry(4, storage(true)),
            buffer_entry(5, storage(false)),
            buffer_entry(6, storage(false)),
        ]),
        "multi",
    )?;
    let table: Vec<[f32; 4]> = luts.iter().flat_map(|l| l.entries.clone()).collect();
    let lut_buf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("multi luts"),
        contents: bytemuck::cast_slice(&table),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let dummy = ctx.upload_volume_r32([1, 1, 1], &[0.0])?;
    let t_setup = t_start.elapsed().as_secs_f64();

    let (w, h) = (camera.width, camera.height);
    let mut image = Frame::new(w, h, if settings.mode.rgba() { 4 } else { 1 });
    let mut counts = vec![0u32; w * h];
    let mut upload = 0.0;
    let mut times = super::context::BandTimes::default();
    // One pass: the volumes (whole, or a cell's parts from voxel `origin` on) on the
    // device, then the bands of rows of the pixels `rect` (`image` and `counts` its
    // size).
    let mut pass = |parts: &[Option<(Volume<f32>, [usize; 3])>],
                    mut params: MultiParams,
                    (rect, carry): (&PixelRect, Option<&mut [[f32; 4]]>),
                    image: &mut Frame,
                    counts: &mut [u32],
                    progress: &(dyn Fn(usize, usize) + Sync)|
     -> Result<()> {
        let t_up = Instant::now();
        let mut textures = Vec::with_capacity(MAX_VOLUMES);
        for (i, part) in parts.iter().enumerate() {
            if let Some((v, origin)) = part {
                textures.push(Some(ctx.upload_volume_r32(v.dims(), v.data())?));
                params.origin[i] = [origin[0] as i32, origin[1] as i32, origin[2] as i32, 0];
            } else {
                textures.push(None);
            }
        }
        ctx.wait()?;
        upload += t_up.elapsed().as_secs_f64();
        let views: Vec<_> = (0..MAX_VOLUMES)
            .map(|i| {
                textures
                    .get(i)
                    .and_then(|t| t.as_ref())
                    .unwrap_or(&dummy)
                    .create_view(&Default::default())
            })
            .collect();
        let carried = carry.is_some();
        let bands = render_bands(
            ctx,
            (&pipeline, "multi"),
            rows_per_band(ctx, rect.width(), rect.height(), carried),
            (rect, [w, h]),
            (image, counts),
            carry,
            progress,
            |band, out_buf, cnt_buf| {
                params.tile = [
                    band.cols.start as u32,
                    band.rows.start as u32,
                    band.width() as u32,
                    band.height() as u32,
                ];
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
        times.kernel += bands.kernel;
        times.from_timestamps = bands.from_timestamps;
        times.readback += bands.readback;
        Ok(())
    };
    let line = match &split {
        None => {
            let whole: Vec<_> = values.into_iter().map(|v| Some((v, [0; 3]))).collect();
            let whole_frame = (&PixelRect::whole(w, h), None);
            pass(
                &whole,
                params,
                whole_frame,
                &mut image,
                &mut counts,
                progress,
            )?;
            None
        }
        Some(cut) => {
            let mut carry = vec![[0.0f32; 4]; w * h * CARRIED_VEC4S];
            let mut order = crate::cpu::composite::ray_order(&cut.tree, camera, cut.affine);
            if settings.mode == Mode::Dvr && settings.compositing == Compositing::BackToFront {
                order.reverse();
            }
            // A cell no ray meets holds none of their steps: skipped. The others cast
            // the pixels whose rays may meet them, but for the last, which casts them all
            // and finishes each (it runs alone, finishing misses, when none is in view).
            let seen = super::raycast::bricks_seen(camera, cut.affine, &cut.boxes);
            let shown: Vec<usize> = order
                .iter()
                .copied()
                .filter(|&ci| seen[ci].is_some())
                .collect();
            let order = if shown.is_empty() {
                vec![order[0]]
            } else {
                shown
            };
            let whole_frame = PixelRect::whole(w, h);
            for (j, &ci) in order.iter().enumerate() {
                let cell = &cut.cells[ci];
                let parts = cell
                    .parts
                    .iter()
                    .zip(&values)
                    .map(|(part, v)| part.map(|b| Ok((v.crop(b.lo, b.hi)?, b.lo))).transpose())
                    .collect::<Result<Vec<_>>>()?;
                let mut p = params;
                p.own_lo = [cell.own_lo[0], cell.own_lo[1], cell.own_lo[2], 0.0];
                p.own_hi = [cell.own_hi[0], cell.own_hi[1], cell.own_hi[2], 0.0];
                let last = j + 1 == order.len();
                p.carry = [1, last as u32, 0, 0];
                match seen[ci].as_ref().filter(|_| !last) {
                    // The pixels' states alone change: the image and counts are the
                    // last pass's.
                    Some(rect) => {
                        let mut tile = Frame::new(rect.width(), rect.height(), image.channels);
                        let mut tile_counts = vec![0u32; rect.len()];
                        let cast = (rect, Some(&mut carry[..]));
                        pass(&parts, p, cast, &mut tile, &mut tile_counts, &|_, _| {})?;
                    }
                    None => {
                        let cast = (&whole_frame, Some(&mut carry[..]));
                        pass(&parts, p, cast, &mut image, &mut counts, &|_, _| {})?;
                    }
                }
                progress((j + 1) * h / order.len(), h);
            }
            // The last cell finished each pixel into its first vec4.
            let ch = image.channels;
            for (p, state) in carry.chunks(CARRIED_VEC4S).enumerate() {
                for (x, v) in image.data[ch * p..ch * (p + 1)].iter_mut().zip(state[0]) {
                    *x = v as f64;
                }
            }
            Some(cut.line.clone())
        }
    };
    Ok(GpuMultiOutput {
        output: RenderOutput::from_counts(image, &counts, settings.sample_count),
        timings: GpuTimings {
            setup: t_setup,
            upload,
            prepare: 0.0,
            kernel: times.kernel,
            kernel_from_timestamps: times.from_timestamps,
            readback: times.readback,
            total: t_start.elapsed().as_secs_f64(),
        },
        split: line,
    })
}
