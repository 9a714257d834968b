//! The GPU ray caster: a WGSL port of `cpu::raycast` that must match the f64 oracle.
//!
//! Shaders: `shaders/raycast.wgsl` (one invocation per pixel; every helper names its
//! Rust twin) and `shaders/raycast_prepare.wgsl` (pre-classification and gradient
//! volumes, one invocation per voxel), assembled by `gpu::shaders` from their
//! `#import`s: the shared modules under `shaders/shared/` (parameters, classification,
//! rays and the camera, shading, opacity, skipping, modes, the filter kernels, the
//! fast B-spline) and four modules generated here per render ([`sample_tex_wgsl`],
//! [`accumulate_taps_wgsl`], [`gradient_wgsl`], [`modes_wgsl`]). Parameters:
//! [`RaycastParams`] (in `gpu::params`), whose WGSL twin is
//! `shaders/shared/raycast_params.wgsl`.
//!
//! Data on the device:
//! - the volume as an `R32Float` 3D texture holding the raw values (u8/u16/i16 are exact
//!   in f32, so every voxel type is normalised exactly as on the CPU: not at all);
//! - on the hardware path, an 8- or 16-bit volume instead as an `R16Unorm` texture of
//!   half the bytes ([`CompactVolume`]), mapped back to raw values after the sampler
//!   filters it; each texture is uploaded at the first frame that reads it, so a
//!   session that only draws hardware-filtered frames of a u16 volume holds 2 bytes per
//!   voxel;
//! - the transfer function's lookup table as a storage buffer, read with the same
//!   manual linear interpolation as `LutR::classify`;
//! - pre-classified colours and precomputed gradients as `Rgba32Float` 3D textures,
//!   computed on the GPU by `raycast_prepare.wgsl`.
//!
//! Two trilinear paths: the *exact* one loads the 8 voxels with `textureLoad` and
//! weights them in voxel coordinates (the CPU's arithmetic), and the *hardware* one
//! (`RenderSettings::hardware_filtering`) uses one `textureSampleLevel` through a linear
//! sampler. Real GPUs quantise the hardware filter's weights to about 8 bits; lavapipe
//! does not, so only a real GPU shows the hardware path's true error.
//!
//! **Sessions.** [`RaycastSession`] keeps a volume on the device for many frames: it is
//! checked, converted and uploaded once ([`RaycastSession::new`]), and each frame
//! ([`RaycastSession::render`]) makes again only what its transfer function, camera and
//! settings changed — the pipeline of a new shader source, a lookup table whose entries
//! changed, the pre-classified colours of a new table, … — each cached under the key
//! that determines it ([`SessionStats`] counts what was made). The one-shot [`render`]
//! is a session of one frame, so the two paths are one code path and give the same
//! image bit for bit. `jobs::renderer::Renderer::prepare` keeps a session for GPU
//! frames; the Python package's prepared scenes and the lab render through it.
//!
//! What stays on the CPU, and why:
//! - the full sinc: every sample sums the whole grid (n³ texture reads per sample, about
//!   2·10⁶ for 128³), which is no GPU algorithm; it is refused with a clear error;
//! - the B-spline prefilter of `bspline-interp`: a sequential recurrence along every
//!   line, run once per session in f32 by the same code as the CPU path
//!   (`cpu::filter::prepare`), together with the pre-classified and gradient volumes it
//!   would have to prefilter.

use super::context::{
    buffer_entry, render_bands, texture_entry, GpuContext, Kernel, LLVMPIPE_LOOP_LIMIT,
};
use super::gradient::gradient_method_id;
use super::shaders;
use crate::camera::{Camera, PixelRect, Projection};
use crate::cpu::filter::prepare;
use crate::cpu::grid::Grid;
use crate::cpu::raycast::RenderOutput;
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::settings::{
    Classification, Compositing, Filter, GradientMethod, Light, Mode, RenderSettings,
};
use crate::transfer::TransferFunction;
use crate::volume::AnyVolume;
use glam::{DMat3, DVec3};
use std::sync::Arc;
use std::time::Instant;
use wgpu::util::DeviceExt;

pub use super::params::RaycastParams;

/// `shaders/shared/raycast_params.wgsl`: the WGSL twin of [`RaycastParams`].
pub const PARAMS_WGSL: &str = super::shaders::RAYCAST_PARAMS;

/// Where the time of a GPU render went, in seconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct GpuTimings {
    /// Shader compilation, pipelines, buffers (excluding uploads).
    pub setup: f64,
    /// Volume and lookup-table uploads (host to device, waited for).
    pub upload: f64,
    /// Pre-classification and gradient passes (and CPU prefiltering for bspline-interp).
    pub prepare: f64,
    /// The ray-casting passes: from timestamp queries when the adapter has them,
    /// otherwise wall-clock time of the waited-for submissions.
    pub kernel: f64,
    /// Whether `kernel` comes from timestamp queries.
    pub kernel_from_timestamps: bool,
    /// Copying the image back to the host.
    pub readback: f64,
    /// Everything, end to end.
    pub total: f64,
}

impl GpuTimings {
    /// Adds another render's times to these (bricks of one frame, frames of an
    /// accumulation); the kernel time counts as from timestamps only when both were.
    pub fn add(&mut self, t: &GpuTimings) {
        self.setup += t.setup;
        self.upload += t.upload;
        self.prepare += t.prepare;
        self.kernel += t.kernel;
        self.readback += t.readback;
        self.total += t.total;
        self.kernel_from_timestamps &= t.kernel_from_timestamps;
    }
}

/// What a GPU render returns: the same output as the CPU, and timings.
#[derive(Clone, Debug)]
pub struct GpuRenderOutput {
    pub output: RenderOutput,
    pub timings: GpuTimings,
    /// A brick's render ([`RaycastSession::place`]): whether each ray meets the whole
    /// volume's box.
    pub hits: Option<Vec<bool>>,
}

/// Where a session's volume sits as a brick of a larger one (a rank's brick in
/// `jobs::distributed_render`): the rays, step grids and sample positions are the whole
/// volume's, and only the samples the brick owns are taken, as
/// `cpu::raycast::render_owned` takes them with `cpu::field::BrickField`.
#[derive(Clone, Debug, PartialEq)]
pub struct BrickPlacement {
    /// The whole volume's index of the session volume's voxel 0 (the brick with its
    /// ghost voxels).
    pub origin: [usize; 3],
    /// The brick proper, `lo .. hi` in the whole volume (its owned samples).
    pub lo: [usize; 3],
    pub hi: [usize; 3],
    /// The whole volume's dimensions, affine and value range.
    pub whole: [usize; 3],
    pub affine: glam::DMat4,
    pub range: (f64, f64),
}

/// The first tap's offset from `floor(x)` and the number of taps of a truncated filter.
fn tap_layout(f: Filter) -> (i32, usize) {
    match f {
        Filter::Trilinear => (0, 2),
        Filter::Bspline
        | Filter::BsplineInterp
        | Filter::BsplineFast
        | Filter::BsplineFastInterp
        | Filter::CatmullRom => (-1, 4),
        Filter::Lanczos2 => (-1, 4),
        Filter::Lanczos3 => (-2, 6),
        Filter::Lanczos4 => (-3, 8),
        Filter::Nearest | Filter::Sinc => (0, 1),
    }
}

/// WGSL of `accumulate_taps(t, p)` for `filter`: the weights of every tap, then
/// `Σ_k w_z[k] Σ_j w_y[j] Σ_i w_x[i] f[i, j, k]` written out in full, in the order of
/// `cpu::filter::apply_taps`. Straight-line code keeps the ray march the only loop.
pub fn accumulate_taps_wgsl(filter: Filter) -> String {
    let (off, count) = tap_layout(filter);
    let lanczos = matches!(
        filter,
        Filter::Lanczos2 | Filter::Lanczos3 | Filter::Lanczos4
    );
    let mut w = String::new();
    w += &format!(
        "// Generated by src/gpu/raycast.rs: accumulate_taps_wgsl({:?}).\n\
         fn accumulate_taps(t: texture_3d<f32>, p: vec3<f32>) -> vec4<f32> {{\n\
         \x20   let filter_kind = {}u;\n\
         \x20   let n = params.dims.xyz;\n\
         \x20   let fl = floor(p);\n\
         \x20   let f = p - fl;\n\
         \x20   let i0 = vec3<i32>(fl);\n",
        filter,
        // A constant, so tap_weight's branches fold away where this is inlined.
        filter_id(filter).unwrap_or(u32::MAX)
    );
    for (axis, c) in ["x", "y", "z"].iter().enumerate() {
        for m in 0..count {
            w += &format!("    let w{c}{m}r = tap_weight(filter_kind, f.{c}, {m}u);\n");
        }
        if lanczos {
            let sum: Vec<String> = (0..count).map(|m| format!("w{c}{m}r")).collect();
            w += &format!("    let s{c} = {};\n", sum.join(" + "));
            for m in 0..count {
                w += &format!("    let w{c}{m} = w{c}{m}r / s{c};\n");
            }
        } else {
            for m in 0..count {
                w += &format!("    let w{c}{m} = w{c}{m}r;\n");
            }
        }
        for m in 0..count {
            w += &format!(
                "    let {c}{m} = clamp_index(i0.{c} + {}, n.{c});\n",
                off + m as i32
            );
        }
        let _ = axis;
    }
    let mut z_terms = Vec::new();
    for b in 0..count {
        let mut y_terms = Vec::new();
        for a in 0..count {
            let x_terms: Vec<String> = (0..count)
                .map(|i| format!("wx{i} * textureLoad(t, vec3<i32>(x{i}, y{a}, z{b}), 0)"))
                .collect();
            w += &format!("    let ax_{b}_{a} = {};\n", x_terms.join(" + "));
            y_terms.push(format!("wy{a} * ax_{b}_{a}"));
        }
        w += &format!("    let ay_{b} = {};\n", y_terms.join(" + "));
        z_terms.push(format!("wz{b} * ay_{b}"));
    }
    w += &format!("    return {};\n}}\n", z_terms.join(" + "));
    w
}

/// WGSL of `gradient_at(p)` for one stencil of `cpu::gradient::gradient_stencil`,
/// written out (the Sobel stencil is 54 field samples); `None` gives a stub for renders
/// that never difference the field on the fly.
pub fn gradient_wgsl(method: Option<GradientMethod>) -> String {
    let e = |axis: usize, s: i32| {
        let mut v = ["0.0"; 3].map(String::from);
        v[axis] = format!("{s}.0");
        format!("vec3<f32>({}, {}, {})", v[0], v[1], v[2])
    };
    let mut w = format!("// Generated by src/gpu/raycast.rs: gradient_wgsl({method:?}).\nfn gradient_at(p: vec3<f32>) -> vec3<f32> {{\n");
    match method {
        None => w += "    return vec3<f32>(0.0);\n",
        Some(GradientMethod::Central) => {
            for a in 0..3 {
                w += &format!(
                    "    let g{a} = (sample_value(p + {}) - sample_value(p + {})) * 0.5;\n",
                    e(a, 1),
                    e(a, -1)
                );
            }
            w += "    return vec3<f32>(g0, g1, g2);\n";
        }
        Some(GradientMethod::Forward) => {
            w += "    let f0 = sample_value(p);\n";
            for a in 0..3 {
                w += &format!("    let g{a} = sample_value(p + {}) - f0;\n", e(a, 1));
            }
            w += "    return vec3<f32>(g0, g1, g2);\n";
        }
        Some(GradientMethod::Sobel) => {
            let wts = [0.25f64, 0.5, 0.25];
            for a in 0..3 {
                let (b, c) = ((a + 1) % 3, (a + 2) % 3);
                let mut terms = Vec::new();
                for ob in 0..3 {
                    for oc in 0..3 {
                        let q = format!("p + {} + {}", e(b, ob as i32 - 1), e(c, oc as i32 - 1));
                        w += &format!(
                            "    let d{a}_{ob}{oc} = sample_value({q} + {}) - sample_value({q} + {});\n",
                            e(a, 1),
                            e(a, -1)
                        );
                        terms.push(format!("{:?} * d{a}_{ob}{oc}", wts[ob] * wts[oc]));
                    }
                }
                // The CPU sums the nine terms in this order, from zero.
                w += &format!("    let g{a} = ({}) * 0.5;\n", terms.join(" + "));
            }
            w += "    return vec3<f32>(g0, g1, g2);\n";
        }
    }
    w + "}\n"
}

/// An 8- or 16-bit integer volume held in an `R16Unorm` texture for the hardware path:
/// the texel stores `(raw − offset) · 65535 / range` (an exact 16-bit integer: `range` is
/// 255 for u8, so the factor is 257, and 65535 for u16 and i16), the sampler returns it
/// divided by 65535 — `(raw − offset) / range` — and filters it, and the shader maps it
/// back with `· range + offset` ([`Self::wgsl`]). Half the `R32Float` texture's bytes and
/// texture traffic.
///
/// u8 volumes take 16-bit texels too: llvmpipe filters `R8Unorm` in 8-bit fixed point,
/// which rounds every filtered value to a whole raw unit (measured there: MIP of a u8
/// phantom 1.7 raw units off the `R32Float` texture's image, against 1.3e-7 of the
/// range with 16-bit texels). The exact path never reads a compact texture: a
/// normalised texel's `textureLoad` is `u / 65535` rounded to f32, which need not map
/// back to the raw value exactly, so the exact path, the set-up passes and the skipping
/// grid keep the `R32Float` texture.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CompactVolume {
    /// The type's span of raw values above `offset`: 255 (u8) or 65535 (u16, i16).
    pub range: u32,
    /// The type's smallest raw value: 0 for unsigned types, −32768 for i16.
    pub offset: i32,
}

impl CompactVolume {
    /// The compact form of `volume`'s voxel type where the adapter has
    /// `TEXTURE_FORMAT_16BIT_NORM`: u8, u16 and i16; none for f32.
    pub fn of(ctx: &GpuContext, volume: &AnyVolume) -> Option<Self> {
        let (range, offset) = match volume {
            AnyVolume::U8(_) => (255, 0),
            AnyVolume::U16(_) => (65535, 0),
            AnyVolume::I16(_) => (65535, -32768),
            AnyVolume::F32(_) => return None,
        };
        ctx.features
            .contains(wgpu::Features::TEXTURE_FORMAT_16BIT_NORM)
            .then_some(CompactVolume { range, offset })
    }

    /// The texture format.
    pub const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R16Unorm;

    /// Bytes per voxel on the device.
    pub const BYTES_PER_VOXEL: u64 = 2;

    /// The texels of `values` (the volume's integers, exact in f32; x fastest).
    pub fn texels(self, values: &[f32]) -> Vec<u16> {
        use rayon::prelude::*;
        let (off, factor) = (self.offset as f32, (65535 / self.range) as f32);
        values
            .par_iter()
            .map(|&v| ((v - off) * factor) as u16)
            .collect()
    }

    /// Whether sessions use compact textures: unless `VOXLAB_GPU_F32_TEXTURES=1`.
    pub fn enabled() -> bool {
        std::env::var_os("VOXLAB_GPU_F32_TEXTURES").is_none_or(|v| v != "1")
    }

    /// WGSL of `volume_value(s)`: the raw value of a sample `s` of the texture.
    pub fn wgsl(self) -> String {
        let range = self.range;
        match self.offset {
            0 => format!("    return s * {range}.0;\n"),
            o => format!("    return s * {range}.0 - {}.0;\n", -o),
        }
    }
}

/// Whether a frame of `settings` samples pre-classified colours.
pub fn preclassifies(settings: &RenderSettings) -> bool {
    matches!(settings.mode, Mode::Dvr | Mode::Mida)
        && settings.classification == Classification::Pre
}

/// Whether a frame of `settings` reads the precomputed gradient volume.
pub fn reads_gradient_volume(settings: &RenderSettings) -> bool {
    settings.mode.rgba()
        && (settings.shading.enabled || settings.transfer_2d.is_some())
        && settings.precompute_gradients
}

/// The textures of the volume's raw values that a frame of `settings` reads, for a
/// volume whose compact form (where sessions use one) is `compact`: whether the
/// `R32Float` one (the exact path, and the set-up passes that make pre-classified
/// colours or gradients on the GPU), and the compact one on the hardware path. A
/// prefiltered filter reads neither: it samples the B-spline coefficients.
pub fn volume_textures(
    settings: &RenderSettings,
    compact: Option<CompactVolume>,
) -> (bool, Option<CompactVolume>) {
    let prefiltered = settings.filter.prefiltered();
    let compact = compact.filter(|_| settings.hardware_filtering && !prefiltered);
    let exact = !prefiltered
        && (compact.is_none() || preclassifies(settings) || reads_gradient_volume(settings));
    (exact, compact)
}

/// WGSL of `sample_tex(t, p)` with only the render's reconstruction path (the filter
/// and, for trilinear and the fast B-splines, hardware or manual): the Sobel stencil
/// inlines it 54 times, and a runtime switch over every filter there took the NVIDIA
/// compiler minutes. With it, `volume_value(s)`: the raw value of a sample of the
/// volume's texture (the identity, or [`CompactVolume::wgsl`] where the render samples
/// a compact texture).
pub fn sample_tex_wgsl(settings: &RenderSettings, compact: Option<CompactVolume>) -> String {
    let body = match (settings.filter, settings.hardware_filtering) {
        (Filter::Nearest, _) => {
            "    let n = params.dims.xyz;\n    \
             let q = vec3<i32>(floor(p + vec3<f32>(0.5)));\n    \
             let c = vec3<i32>(clamp_index(q.x, n.x), clamp_index(q.y, n.y), clamp_index(q.z, n.z));\n    \
             return textureLoad(t, c, 0);\n"
        }
        (Filter::Trilinear, true) => {
            "    let uvw = (p + vec3<f32>(0.5)) / vec3<f32>(params.dims.xyz);\n    \
             return textureSampleLevel(t, linear_clamp, uvw, 0.0);\n"
        }
        (Filter::BsplineFast | Filter::BsplineFastInterp, true) => {
            "    return sample_fast_bspline_hw(t, linear_clamp, p, params.dims.xyz);\n"
        }
        (Filter::BsplineFast | Filter::BsplineFastInterp, false) => {
            "    return sample_fast_bspline(t, p, params.dims.xyz);\n"
        }
        _ => "    return accumulate_taps(t, p);\n",
    };
    let value = compact.map_or_else(|| "    return s;\n".to_string(), CompactVolume::wgsl);
    format!(
        "// Generated by src/gpu/raycast.rs: sample_tex_wgsl ({:?}, hardware {}, \
         compact {compact:?}).\n\
         fn sample_tex(t: texture_3d<f32>, p: vec3<f32>) -> vec4<f32> {{\n{body}}}\n\
         fn volume_value(s: f32) -> f32 {{\n{value}}}\n",
        settings.filter, settings.hardware_filtering
    )
}

/// The complete ray-casting shader for these settings: `shaders/raycast.wgsl` and its
/// imports, with the generated sampling path, tap sums, gradient stencil and modes;
/// `compact` when the volume's texture is a [`CompactVolume`].
pub fn raycast_shader(settings: &RenderSettings, compact: Option<CompactVolume>) -> String {
    let taps = match settings.filter {
        // Nearest, hardware trilinear and the fast B-splines never reach accumulate_taps.
        Filter::Nearest | Filter::Sinc | Filter::BsplineFast | Filter::BsplineFastInterp => {
            STUB_TAPS.to_string()
        }
        Filter::Trilinear if settings.hardware_filtering => STUB_TAPS.to_string(),
        f => accumulate_taps_wgsl(f),
    };
    let on_the_fly = settings.mode.rgba()
        && (settings.shading.enabled || settings.transfer_2d.is_some())
        && !settings.precompute_gradients;
    let gradient = gradient_wgsl(on_the_fly.then_some(settings.gradient));
    shaders::resolve_with(
        "raycast",
        &[
            ("sample_tex", &sample_tex_wgsl(settings, compact)),
            ("accumulate_taps", &taps),
            ("gradient_at", &gradient),
            ("cast_mida_iso", &modes_wgsl(settings)),
        ],
    )
}

/// The generated module `cast_mida_iso`: `shaders/shared/modes_cast.wgsl` (the MIDA and
/// iso-surface marches) when the settings draw MIDA or iso-surfaces, else stubs of
/// `cast_mida`/`cast_iso`: each of those marches inlines the filter's tap sum many
/// times over (samples, gradients, shadow rays), and with the 512-tap Lanczos-4 a
/// software driver's compiler (llvmpipe) ran out of memory on shaders that never take
/// those branches.
pub fn modes_wgsl(settings: &RenderSettings) -> String {
    let needed = matches!(settings.mode, Mode::Mida | Mode::Iso)
        || (settings.mode == Mode::Dvr && !settings.iso_surfaces.is_empty());
    if needed {
        return "#import modes_cast\n".to_string();
    }
    STUB_MODES.to_string()
}

/// The complete set-up shader: `shaders/raycast_prepare.wgsl` and its imports.
pub fn prepare_shader() -> String {
    shaders::resolve("raycast_prepare")
}

const STUB_TAPS: &str = "// Unreachable for this filter.\nfn accumulate_taps(t: texture_3d<f32>, p: vec3<f32>) -> vec4<f32> {\n    return vec4<f32>(0.0);\n}\n";

const STUB_MODES: &str = "// Compiled out for these settings (src/gpu/raycast.rs: modes_wgsl).\n\
fn cast_mida(ray: Ray, o: vec3<f32>, d: vec3<f32>, t_in: f32, t_out: f32, dt: f32, n: u32, speed: f32) -> Pixel {\n    var p: Pixel;\n    return p;\n}\n\
fn cast_iso(ray: Ray, o: vec3<f32>, d: vec3<f32>, t_in: f32, t_out: f32, dt: f32, n: u32, speed: f32, dvr: bool) -> Pixel {\n    var p: Pixel;\n    return p;\n}\n";

fn filter_id(f: Filter) -> Result<u32> {
    Ok(match f {
        Filter::Nearest => 0,
        Filter::Trilinear => 1,
        Filter::Bspline => 2,
        Filter::BsplineInterp => 3,
        Filter::CatmullRom => 4,
        Filter::Lanczos2 => 5,
        Filter::Lanczos3 => 6,
        Filter::Lanczos4 => 7,
        Filter::BsplineFast => 8,
        Filter::BsplineFastInterp => 9,
        Filter::Sinc => {
            return Err(Error::invalid(
                "filter",
                "the full sinc runs on the CPU only: every sample sums the whole grid \
                 (n³ texture reads per sample); use lanczos4 on the GPU",
            ))
        }
    })
}

/// The GPU ray caster's filters: not the full sinc, and the texture unit for trilinear
/// and the fast B-splines' trilinear fetches only.
fn check_filter(settings: &RenderSettings) -> Result<()> {
    filter_id(settings.filter)?;
    if settings.hardware_filtering && !settings.filter.hardware_filterable() {
        return Err(Error::invalid(
            "hardware filtering",
            format!(
                "the sampler filters trilinearly only (and serves the 8 trilinear fetches \
                 of cubic-bspline-fast); the {} filter always runs on the exact path",
                settings.filter.name()
            ),
        ));
    }
    Ok(())
}

fn v4(v: DVec3, w: f64) -> [f32; 4] {
    [v.x as f32, v.y as f32, v.z as f32, w as f32]
}

/// Fills the parameter block for a render (everything but the tile rows).
pub fn raycast_params(
    dims: [usize; 3],
    affine: glam::DMat4,
    lut: &crate::transfer::LutR<f32>,
    value_range: (f64, f64),
    camera: &Camera,
    settings: &RenderSettings,
) -> Result<RaycastParams> {
    let to_index = affine.inverse();
    let normal = DMat3::from_mat4(affine).inverse().transpose();
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
    let row = |m: glam::DMat4, i: usize| {
        let r = m.row(i);
        [r.x as f32, r.y as f32, r.z as f32, r.w as f32]
    };
    let nrow = |i: usize| v4(normal.row(i), 0.0);
    let mode = match settings.mode {
        Mode::Dvr => 0,
        Mode::Mip => 1,
        Mode::Minip => 2,
        Mode::Xray => 3,
        Mode::Mida => 4,
        Mode::Iso => 5,
    };
    check_filter(settings)?;
    let tf2d = match (&settings.transfer_2d, settings.mode) {
        (Some(t), Mode::Dvr) => t.coordinates().uniforms(),
        _ => [[0.0; 4]; 2],
    };
    let gradient = gradient_method_id(settings.gradient);
    Ok(RaycastParams {
        eye: v4(camera.eye, eye_w),
        forward: v4(camera.forward, fwd_w),
        right: v4(camera.right, right_w),
        up: v4(camera.up, up_w),
        to_index_0: row(to_index, 0),
        to_index_1: row(to_index, 1),
        to_index_2: row(to_index, 2),
        normal_0: nrow(0),
        normal_1: nrow(1),
        normal_2: nrow(2),
        box_hi: [
            dims[0] as f32 - 0.5,
            dims[1] as f32 - 0.5,
            dims[2] as f32 - 0.5,
            settings.step as f32,
        ],
        background: settings.background.map(|c| c as f32),
        light: v4(light, light_w),
        shading: [
            s.ambient as f32,
            s.diffuse as f32,
            s.specular as f32,
            s.shininess as f32,
        ],
        misc: [
            settings.reference_step as f32,
            settings.ert_threshold as f32,
            (s.gradient_threshold * (value_range.1 - value_range.0).max(f64::MIN_POSITIVE)) as f32,
            settings.miss_value as f32,
        ],
        lut: [lut.scale, lut.offset, (lut.entries.len() - 1) as f32, 0.0],
        dims: [dims[0] as u32, dims[1] as u32, dims[2] as u32, 0],
        image: [
            camera.width as u32,
            camera.height as u32,
            mode,
            filter_id(settings.filter)?,
        ],
        flags: [
            preclassifies(settings) as u32,
            (settings.mode.rgba() && s.enabled) as u32,
            reads_gradient_volume(settings) as u32,
            (settings.compositing == Compositing::BackToFront) as u32,
        ],
        flags2: [gradient, settings.hardware_filtering as u32, 0, 0],
        tile: [0, 0, camera.width as u32, camera.height as u32],
        tf2d_a: tf2d[0],
        tf2d_b: tf2d[1],
        ..accel_params(dims, settings, modes_params(settings, value_range))
    })
}

/// The skipping, jitter and clipping members of the parameter block (`cpu::skip`,
/// `accumulate`).
fn accel_params(dims: [usize; 3], settings: &RenderSettings, rest: RaycastParams) -> RaycastParams {
    use crate::cpu::skip::{cell_count, overshoot, skip_radius, ClipR};
    let cells = cell_count(dims, settings.block_size);
    let clip = settings.clip_box.as_ref().map(ClipR::<f32>::new);
    let corner =
        |v: Option<crate::real::V3<f32>>| v.map_or([0.0; 4], |v| [v.0[0], v.0[1], v.0[2], 0.0]);
    RaycastParams {
        accel: [
            skip_radius(settings).is_some() as u32,
            match (settings.jitter, settings.interleaved) {
                (Some(_), _) => 1,
                (None, true) => 2,
                _ => 0,
            },
            settings.jitter.unwrap_or(0),
            clip.map_or(0, |c| if c.world { 2 } else { 1 }),
        ],
        skip_cells: [
            cells[0] as u32,
            cells[1] as u32,
            cells[2] as u32,
            settings.block_size as u32,
        ],
        skip_tf: [
            overshoot(settings.filter, settings.classification) as f32,
            f32::EPSILON * 1024.0,
            0.0,
            0.0,
        ],
        clip_lo: corner(clip.map(|c| c.lo)),
        clip_hi: corner(clip.map(|c| c.hi)),
        ..rest
    }
}

/// The members of the parameter block for MIDA, the grey window and iso-surfaces
/// (mirrors src/cpu/modes.rs: ModeSetup::new); the rest zero.
fn modes_params(settings: &RenderSettings, value_range: (f64, f64)) -> RaycastParams {
    let m = crate::cpu::modes::ModeSetup::<f32>::new(settings, value_range);
    let mut p = RaycastParams {
        mode_params: [m.gamma, m.lo, m.inv_range, 0.0],
        window: match m.window {
            Some([w, c]) => [w, c, 1.0, 0.0],
            None => [0.0; 4],
        },
        iso_flags: [
            m.iso.len() as u32,
            m.opaque as u32,
            m.shadows as u32,
            m.refine as u32,
        ],
        ..Default::default()
    };
    let colors = [
        &mut p.iso_color_0,
        &mut p.iso_color_1,
        &mut p.iso_color_2,
        &mut p.iso_color_3,
    ];
    for ((iso, value), color) in m.iso.iter().zip(&mut p.iso_values).zip(colors) {
        *value = iso.value;
        *color = [iso.color[0], iso.color[1], iso.color[2], iso.opacity];
    }
    p
}

/// Renders on the GPU. Same inputs and outputs as `cpu::raycast::render`.
///
/// A one-frame [`RaycastSession`]: the volume is converted and uploaded, the pipelines
/// compiled and the set-up passes run for this frame alone. Frames of one volume
/// render faster from one session.
pub fn render(
    ctx: &GpuContext,
    volume: &AnyVolume,
    tf: &TransferFunction,
    camera: &Camera,
    settings: &RenderSettings,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<GpuRenderOutput> {
    // Refuse bad settings before uploading anything.
    settings.validate()?;
    tf.validate()?;
    RaycastSession::new(ctx, volume)?.render(tf, camera, settings, progress)
}

/// Renders the samples of one brick of a larger volume, for sort-last compositing:
/// `brick` holds the brick's voxels with their ghost voxels, `placement` says where
/// they sit. The GPU twin of `cpu::raycast::render_owned` (the same refusals and the
/// same [`crate::cpu::raycast::Partial`]).
///
/// # Errors
/// Invalid settings or transfer function; modes a brick does not render; as
/// [`RaycastSession::new`] and [`RaycastSession::render`].
pub fn render_owned(
    ctx: &GpuContext,
    brick: &AnyVolume,
    placement: BrickPlacement,
    tf: &TransferFunction,
    camera: &Camera,
    settings: &RenderSettings,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<crate::cpu::raycast::Partial> {
    crate::cpu::raycast::check_owned_settings(settings)?;
    let s = crate::cpu::raycast::owned_settings(settings);
    tf.validate()?;
    let mut session = RaycastSession::new(ctx, brick)?;
    session.place(placement)?;
    let out = session.render(tf, camera, &s, progress)?;
    let (w, h) = (camera.width, camera.height);
    let counts = out
        .output
        .samples
        .map(|f| f.data.iter().map(|&c| c as u32).collect())
        .unwrap_or_else(|| vec![0; w * h]);
    Ok(crate::cpu::raycast::Partial {
        image: out.output.image,
        counts,
        hits: out.hits.unwrap_or_else(|| vec![false; w * h]),
    })
}

/// Whether a frame's rays carry their state from brick to brick when the volume is cut
/// ([`render_bricked`]): MIDA and iso-surfaces, which look along the whole ray.
pub fn carries_state(settings: &RenderSettings) -> bool {
    draws_iso(settings) || settings.mode == Mode::Mida
}

/// Whether a frame draws iso-surfaces (mode iso, or DVR with some).
fn draws_iso(settings: &RenderSettings) -> bool {
    settings.mode == Mode::Iso || (settings.mode == Mode::Dvr && !settings.iso_surfaces.is_empty())
}

/// A volume's products prefiltered along whole lines, which a brick of it cannot make
/// from its own voxels: the interpolating B-splines' coefficients, and where a frame
/// uses them its pre-classified colours (RGBA) and precomputed gradients (x, y, z), each
/// prefiltered as an unsplit session prefilters it. [`render_bricked`] makes them once
/// and gives each brick its part ([`RaycastSession::give_prefiltered`]).
#[derive(Clone, Debug, Default)]
pub struct Prefiltered {
    pub coefficients: Option<Grid<f32>>,
    pub preclassified: Option<[Grid<f32>; 4]>,
    pub gradients: Option<[Grid<f32>; 3]>,
}

impl Prefiltered {
    /// The whole volume's products for frames of `settings` (an interpolating B-spline
    /// filter) with `tf`: the coefficients, the pre-classified colours when the frame
    /// pre-classifies, the gradients when it precomputes them.
    pub fn of_volume(volume: &AnyVolume, tf: &TransferFunction, settings: &RenderSettings) -> Self {
        let grid = Grid::<f32> {
            dims: volume.dims(),
            data: volume.to_f32().into_data(),
        };
        let filter = settings.filter;
        let lut = tf.lut(settings.lut_size).to_real::<f32>();
        Prefiltered {
            coefficients: Some(prepare(&grid, filter)),
            preclassified: (settings.classification == Classification::Pre).then(|| {
                crate::cpu::raycast::preclassify(&grid, &lut).map(|g| prepare(&g, filter))
            }),
            gradients: settings.precompute_gradients.then(|| {
                crate::cpu::gradient::precompute_gradients(&grid, settings.gradient)
                    .map(|g| prepare(&g, filter))
            }),
        }
    }

    /// The voxels `lo .. hi` of each product.
    pub fn crop(&self, lo: [usize; 3], hi: [usize; 3]) -> Self {
        Prefiltered {
            coefficients: self.coefficients.as_ref().map(|g| g.crop(lo, hi)),
            preclassified: self
                .preclassified
                .as_ref()
                .map(|c| c.each_ref().map(|g| g.crop(lo, hi))),
            gradients: self
                .gradients
                .as_ref()
                .map(|c| c.each_ref().map(|g| g.crop(lo, hi))),
        }
    }
}

/// The ghost voxels each brick of a frame's split volume carries:
/// `cpu::field::brick_ghost` (the filter's and the gradient's reach), and for
/// iso-surfaces one step more (a crossing between a brick's first sample and the last
/// of the brick in front is shaded by the later brick, up to a step outside its box).
pub fn brick_ghost_for(settings: &RenderSettings) -> usize {
    let step = if draws_iso(settings) {
        settings.step.ceil().max(1.0) as usize
    } else {
        0
    };
    crate::cpu::field::brick_ghost(settings.filter) + step
}

/// The bricks a volume of `dims` is cut into so that each, with the ghost voxels a
/// frame of `settings` needs ([`brick_ghost_for`]), fits `max_texels` per axis and,
/// where given, `max_voxels` in all: the k-d tree of `io::brick` for the fewest bricks
/// that fit (one when the volume fits whole).
///
/// # Errors
/// No cut fits (a limit below the ghost voxels).
pub fn brick_plan(
    dims: [usize; 3],
    settings: &RenderSettings,
    max_texels: usize,
    max_voxels: Option<u64>,
) -> Result<(crate::io::brick::KdTree, Vec<crate::io::brick::Brick>)> {
    let ghost = brick_ghost_for(settings);
    let reach = format!(
        "the {} filter's {ghost} ghost voxels",
        settings.filter.name()
    );
    crate::io::brick::fitting_kd_tree(dims, ghost, max_texels, max_voxels, &reach)
}

/// The device bytes a frame's volume textures take per voxel: the raw values
/// (`R32Float` and/or, on the hardware path, a 16-bit [`CompactVolume`]; a prefiltered
/// filter's coefficients, `R32Float`) and the `Rgba32Float` pre-classified colours and
/// precomputed gradients where the frame reads them ([`volume_textures`]).
pub fn texture_bytes_per_voxel(settings: &RenderSettings, compact: Option<CompactVolume>) -> u64 {
    let rgba = 16 * (preclassifies(settings) as u64 + reads_gradient_volume(settings) as u64);
    let values = match volume_textures(settings, compact) {
        _ if settings.filter.prefiltered() => 4,
        (exact, compact) => {
            4 * exact as u64 + compact.map_or(0, |_| CompactVolume::BYTES_PER_VOXEL)
        }
    };
    values + rgba
}

/// The device bytes of a `camera` image's output buffers, at most: RGBA f32 and a count
/// a pixel, or in a brick whose rays carry their state (`carried`, [`carries_state`])
/// the state's [`CARRIED_VEC4S`] vec4 in place of the RGBA.
pub fn output_bytes(camera: &Camera, carried: bool) -> u64 {
    let vec4s = if carried { CARRIED_VEC4S as u64 } else { 1 };
    camera.width as u64 * camera.height as u64 * (4 + 16 * vec4s)
}

/// The host bytes a frame split into bricks ([`render_bricked`]) holds beyond the
/// volume and its bricks: each ray's carried state ([`carries_state`]) and the whole
/// volume's B-spline coefficients (the interpolating B-splines), f32.
pub fn split_host_bytes(dims: [usize; 3], camera: &Camera, settings: &RenderSettings) -> u64 {
    let pixels = camera.width as u64 * camera.height as u64;
    let carry = if carries_state(settings) {
        pixels * 16 * CARRIED_VEC4S as u64
    } else {
        0
    };
    let coefficients = if settings.filter.prefiltered() {
        dims.iter().product::<usize>() as u64 * 4
    } else {
        0
    };
    carry + coefficients
}

/// How a frame's volume is cut into bricks to fit the device ([`volume_split`]).
pub struct VolumeSplit {
    /// The k-d tree and its bricks ([`brick_plan`]).
    pub tree: crate::io::brick::KdTree,
    pub bricks: Vec<crate::io::brick::Brick>,
    /// The texels of the largest brick with its ghost voxels.
    pub largest: u64,
    /// What the job prints: "ray casting in 4 bricks (…, why)".
    pub line: String,
}

/// Whether and how a frame of a `dims` volume is cut into bricks on `ctx`: when an axis
/// exceeds the planner's 3-D texture limit, or when the volume's textures
/// ([`texture_bytes_per_voxel`]) and the image's buffers exceed the device memory a job
/// may fill ([`GpuContext::memory`]). `None` when the volume fits whole. Renders
/// (`jobs::renderer::Renderer`) and their `--dry-run` plans both ask it.
///
/// # Errors
/// A frame bricks cannot render ([`crate::cpu::raycast::check_split_settings`]: the
/// full sinc, whose reach is the whole volume), naming why the volume must be cut; no
/// cut that fits ([`brick_plan`]).
pub fn volume_split(
    ctx: &GpuContext,
    dims: [usize; 3],
    settings: &RenderSettings,
    compact: Option<CompactVolume>,
    camera: &Camera,
) -> Result<Option<VolumeSplit>> {
    let max = ctx.limits.max_texture_dimension_3d as usize;
    let per_voxel = texture_bytes_per_voxel(settings, compact).max(1);
    let whole = dims.iter().product::<usize>() as u64 * per_voxel + output_bytes(camera, false);
    let memory = ctx.memory.as_ref().filter(|m| whole > m.bytes);
    let why = if dims.iter().any(|&n| n > max) {
        format!("the {dims:?} volume exceeds the 3-D texture limit of {max} texels per axis")
    } else if let Some(m) = memory {
        format!(
            "the {dims:?} volume's textures and the image's buffers, {}, exceed the {} of \
             device memory a job may fill",
            crate::gpu::plan::human_bytes(whole),
            crate::gpu::plan::human_bytes(m.bytes)
        )
    } else {
        return Ok(None);
    };
    crate::cpu::raycast::check_split_settings(settings, true).map_err(|e| match e {
        Error::Invalid { what, message } => Error::Invalid {
            what,
            message: format!("{message}; {why}, so it renders in bricks"),
        },
        e => e,
    })?;
    let out = output_bytes(camera, carries_state(settings));
    let max_voxels = ctx
        .memory
        .as_ref()
        .map(|m| m.bytes.saturating_sub(out) / per_voxel);
    let (tree, bricks) = brick_plan(dims, settings, max, max_voxels)?;
    let ghost = brick_ghost_for(settings);
    let largest = bricks
        .iter()
        .map(|b| b.with_ghost(ghost, dims).voxels() as u64)
        .max()
        .unwrap_or(0);
    let shadows = if defers_shadows(settings) {
        "; the shadow rays in sweeps through the bricks in the light's order"
    } else {
        ""
    };
    let line = format!(
        "ray casting in {} bricks ({why}; the largest brick with its {ghost} ghost voxels \
         holds {largest} texels{shadows})",
        bricks.len()
    );
    Ok(Some(VolumeSplit {
        tree,
        bricks,
        largest,
        line,
    }))
}

/// The vec4 a brick's ray hands the next brick: MIDA's (`shaders/shared/modes_cast.wgsl:
/// mida_store`) `(c, a)`, `(running, best, started, 0)`, the best sample's colour;
/// iso-surfaces' (`iso_store`) `(c, a)`, then until an opaque surface ends the ray
/// `(t0, v0, started, 0)`, after it `(c in shadow, shadow)` and `(hit, first)`:
/// [`carried_iso`].
pub const CARRIED_VEC4S: usize = 3;

/// An iso-surface ray's state from its [`CARRIED_VEC4S`] vec4. Once an opaque surface
/// has ended the ray, the second vec4's `w` says how its shadow ray stands: 1 lit (or
/// no shadows), −1 in shadow (the colour is then the second vec4's `xyz`), `k + 1`
/// waiting at the shadow ray's sample `k` ([`shadow_waits`]; its hit point and first
/// sample's value in the third vec4).
/// Mirrors `shaders/shared/modes_cast.wgsl: iso_load`.
pub fn carried_iso(v: &[[f32; 4]]) -> crate::cpu::modes::IsoState<f32> {
    let (ended, shadow) = (v[1][3] != 0.0, v[1][3]);
    let c = if ended && shadow == -1.0 {
        &v[1]
    } else {
        &v[0]
    };
    crate::cpu::modes::IsoState {
        c: [c[0], c[1], c[2]],
        a: v[0][3],
        t0: if ended { 0.0 } else { v[1][0] },
        v0: if ended { 0.0 } else { v[1][1] },
        started: ended || v[1][2] == 1.0,
        done: ended,
    }
}

/// Whether a brick's iso-surface ray ([`carried_iso`]) ended on an opaque surface
/// whose shadow ray has yet to leave the box or meet a surface.
pub fn shadow_waits(v: &[[f32; 4]]) -> bool {
    v[1][3] >= 2.0
}

/// Whether a frame's shadow rays, in bricks, are marched after its rays
/// ([`render_bricked`]): opaque iso-surfaces with shadows.
fn defers_shadows(settings: &RenderSettings) -> bool {
    draws_iso(settings) && settings.iso_opaque && settings.iso_shadows
}

/// The orders of the bricks (leaves of `tree`) that a frame's shadow rays are marched
/// in, sweep after sweep until each has ended ([`render_bricked`]). Every shadow ray
/// goes toward the light: for a directional light all of them along one index-space
/// direction, so the bricks front to back along it take each in one sweep; for a
/// headlight back along its own ray (`rays`: the bricks in the rays' order), so the
/// rays' order reversed, then, for rays that pass the eye of a perspective camera
/// inside the volume, the rays' order itself. A ray left waiting after a sweep (the
/// GPU's rounding of a direction across an axis) takes the next.
fn shadow_orders(
    tree: &crate::io::brick::KdTree,
    settings: &RenderSettings,
    affine: glam::DMat4,
    rays: &[usize],
) -> [Vec<usize>; 2] {
    match settings.shading.light {
        crate::settings::Light::Direction(l) => {
            let d = affine.inverse().transform_vector3(DVec3::from_array(l));
            let mut order = Vec::new();
            tree.front_to_back(d.to_array(), &mut order);
            let back = order.iter().rev().copied().collect();
            [order, back]
        }
        crate::settings::Light::Headlight => [rays.iter().rev().copied().collect(), rays.to_vec()],
    }
}

/// A MIDA ray's state from its [`CARRIED_VEC4S`] vec4.
/// Mirrors `shaders/shared/modes_cast.wgsl: mida_load`.
pub fn carried_mida(v: &[[f32; 4]]) -> crate::cpu::modes::MidaState<f32> {
    crate::cpu::modes::MidaState {
        c: [v[0][0], v[0][1], v[0][2]],
        a: v[0][3],
        running: v[1][0],
        best: v[1][1],
        best_rgba: v[2],
        started: v[1][2] == 1.0,
    }
}

/// Renders a volume cut into `bricks` (the leaves of `tree`, from [`brick_plan`]; past
/// the 3-D texture limit or the device memory, [`volume_split`]) on one GPU: each brick
/// rendered as a placed session ([`render_owned`]) in turn, so the device holds one
/// brick at a time. DVR, MIP, MinIP and X-ray: the pieces composited on the host in each
/// pixel's visibility order (`cpu::composite`); MIP and MinIP equal the unsplit render
/// exactly, X-ray and DVR up to the regrouping of their sums by brick. MIDA and
/// iso-surfaces ([`carries_state`]): the bricks rendered in the rays' order
/// (`cpu::composite::ray_order`), each ray's state (`cpu::modes::MidaState`,
/// `cpu::modes::IsoState`) handed from brick to brick on the device and finished on
/// the host (`cpu::modes::mida_finish`, the background): the unsplit render's samples
/// and arithmetic in its order. An opaque iso-surface hit with shadows keeps both its
/// endings, lit and in shadow, and its shadow ray is marched afterwards through the
/// bricks in the light's order, handed on the same way, sweep after sweep until it
/// has left the box or met a surface (`cpu::modes::shadow_steps`; one sweep for a
/// directional light, two for a headlight whose rays pass the eye inside the volume).
/// The interpolating B-splines sample the whole volume's coefficients (and
/// pre-classified colours, precomputed gradients), made once on the host
/// ([`RaycastSession::give_prefiltered`]).
///
/// # Errors
/// As [`render_owned`], but MIDA, iso-surfaces (with shadows too) and the
/// interpolating B-splines are rendered
/// ([`crate::cpu::raycast::check_split_settings`]).
pub fn render_bricked<'c>(
    ctx: &'c GpuContext,
    volume: &AnyVolume,
    tf: &TransferFunction,
    camera: &Camera,
    settings: &RenderSettings,
    (tree, bricks): (&crate::io::brick::KdTree, &[crate::io::brick::Brick]),
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<GpuRenderOutput> {
    let t_start = Instant::now();
    settings.validate()?;
    tf.validate()?;
    crate::cpu::raycast::check_split_settings(settings, true)?;
    volume.check_finite("volume")?;
    let dims = volume.dims();
    let ghost = brick_ghost_for(settings);
    let r = volume.value_range();
    let range = (r.min, r.max);
    let (w, h) = (camera.width, camera.height);
    let carried = carries_state(settings);
    let mut carry = vec![[0.0f32; 4]; if carried { w * h * CARRIED_VEC4S } else { 0 }];
    let order: Vec<usize> = if carried {
        crate::cpu::composite::ray_order(tree, camera, volume.affine())
    } else {
        (0..bricks.len()).collect()
    };
    // A brick casts only the rays of the pixels that may meet it (its rectangle); a
    // brick no ray meets adds nothing: its pass is skipped (its piece is empty). A
    // pixel no brick casts misses the volume.
    let seen = bricks_seen(camera, volume.affine(), bricks);
    let mut pieces: Vec<Option<Piece>> = (0..bricks.len()).map(|_| None).collect();
    // The bricks' times summed; `total` is the whole render's, set at the end.
    let mut timings = GpuTimings {
        kernel_from_timestamps: true,
        ..GpuTimings::default()
    };
    // The interpolating B-splines sample coefficients prefiltered along whole lines:
    // the whole volume's, made once on the host as an unsplit session makes them.
    let t_coef = Instant::now();
    let s = crate::cpu::raycast::owned_settings(settings);
    let whole = match settings.filter.prefiltered() {
        true => Some(Prefiltered::of_volume(volume, tf, &s)),
        false => None,
    };
    timings.prepare += t_coef.elapsed().as_secs_f64();
    let mut session: Option<RaycastSession> = None;
    // Loads brick `bi` (with its ghost voxels) into the one session of every brick:
    // the pipelines compile once.
    let load = |session: &mut Option<RaycastSession<'c>>, bi: usize| -> Result<()> {
        let b = &bricks[bi];
        let g = b.with_ghost(ghost, dims);
        let placement = BrickPlacement {
            origin: g.lo,
            lo: b.lo,
            hi: b.hi,
            whole: dims,
            affine: volume.affine(),
            range,
        };
        let brick = volume.crop(g.lo, g.hi)?;
        match session.as_mut() {
            None => *session = Some(RaycastSession::new(ctx, &brick)?),
            Some(x) => x.replace_volume(&brick)?,
        }
        let session = session.as_mut().expect("made above");
        session.place(placement)?;
        if let Some(p) = &whole {
            session.give_prefiltered(p.crop(g.lo, g.hi))?;
        }
        Ok(())
    };
    // Progress over the bricks' passes: the rays', then as many again for the shadow
    // rays' first sweep.
    let deferred = defers_shadows(settings);
    let passes = bricks.len() * (1 + deferred as usize);
    for (i, &bi) in order.iter().enumerate() {
        let Some(rect) = &seen[bi] else {
            continue;
        };
        load(&mut session, bi)?;
        let session = session.as_mut().expect("loaded");
        // Progress in the image's rows: the rectangle's scaled to them.
        let rows =
            |done: usize, total: usize| progress(i * h + done * h / total.max(1), passes * h);
        let state = carried.then_some(&mut carry[..]);
        let out = session.render_frame(tf, camera, &s, state, false, Some(rect), &rows)?;
        timings.add(&out.timings);
        let counts: Vec<u32> = match &out.output.samples {
            Some(f) => f.data.iter().map(|&c| c as u32).collect(),
            None => vec![0; rect.len()],
        };
        let hits = out.hits.unwrap_or_default();
        pieces[bi] = Some(Piece {
            rect: rect.clone(),
            image: out.output.image,
            counts,
            hits,
        });
    }
    // The opaque hits' shadow rays, which cross bricks the rays did not: marched
    // through the bricks in the light's order, each brick taking the samples it owns
    // from where the last left them (shaders/shared/modes_cast.wgsl: shadow_pass),
    // sweep after sweep until every one has left the box or met a surface. Each
    // sweep takes each waiting ray at least one brick further, so there are at most
    // as many sweeps as bricks; one or two in practice.
    if deferred {
        let sweeps = shadow_orders(tree, settings, volume.affine(), &order);
        let waiting = |carry: &[[f32; 4]]| carry.chunks(CARRIED_VEC4S).any(shadow_waits);
        let mut pass = bricks.len();
        'sweeps: for sweep in 0..=bricks.len() {
            if !waiting(&carry) {
                break;
            }
            if sweep == bricks.len() {
                return Err(Error::Gpu(format!(
                    "shadow rays still crossed the bricks after {sweep} sweeps"
                )));
            }
            for &bi in &sweeps[sweep % 2] {
                if !waiting(&carry) {
                    break 'sweeps;
                }
                load(&mut session, bi)?;
                let session = session.as_mut().expect("loaded");
                let at = pass.min(passes - 1);
                let rows = |done: usize, total: usize| progress(at * total + done, passes * total);
                let out =
                    session.render_frame(tf, camera, &s, Some(&mut carry), true, None, &rows)?;
                timings.add(&out.timings);
                pass += 1;
            }
        }
    }
    let ch = if settings.mode.rgba() { 4 } else { 1 };
    let mut image = Frame::new(w, h, ch);
    let mut counts = vec![0u32; w * h];
    // Whether each ray meets the whole volume's box: every brick that casts it says the
    // same, and a ray that meets the box meets a brick, whose rectangle holds its pixel.
    let mut hits = vec![false; w * h];
    for piece in pieces.iter().flatten() {
        for (i, row) in piece.rect.rows.clone().enumerate() {
            let (from, to) = (i * piece.rect.width(), row * w + piece.rect.cols.start);
            for (hit, &met) in hits[to..]
                .iter_mut()
                .zip(&piece.hits[from..][..piece.rect.width()])
            {
                *hit |= met;
            }
        }
    }
    use rayon::prelude::*;
    if carried {
        // Each ray's state after the last brick, finished as the unsplit render
        // finishes it.
        let gamma = settings.mida_gamma as f32;
        let bg = settings.background.map(|x| x as f32);
        image
            .data
            .par_chunks_mut(ch)
            .zip(counts.par_iter_mut())
            .zip(carry.par_chunks(CARRIED_VEC4S))
            .enumerate()
            .for_each(|(p, ((px, n), state))| {
                let (col, row) = (p % w, p / w);
                *n = pieces
                    .iter()
                    .flatten()
                    .filter_map(|piece| piece.at(col, row).map(|i| piece.counts[i]))
                    .sum();
                let hit = hits[p];
                let v = match (hit, settings.mode) {
                    (false, _) => bg,
                    (true, Mode::Mida) => {
                        crate::cpu::modes::mida_finish(&carried_mida(state), gamma, bg)
                    }
                    (true, _) => {
                        let st = carried_iso(state);
                        crate::cpu::shade::over_background(st.c, st.a, bg)
                    }
                };
                for (x, v) in px.iter_mut().zip(v) {
                    *x = v as f64;
                }
            });
    } else {
        // The pieces joined pixel by pixel in visibility order.
        let to_index = volume.affine().inverse();
        image
            .data
            .par_chunks_mut(w * ch)
            .zip(counts.par_chunks_mut(w))
            .enumerate()
            .for_each(|(row, (px_row, n_row))| {
                let mut order = Vec::with_capacity(bricks.len());
                for col in 0..w {
                    let p = row * w + col;
                    let d = to_index.transform_vector3(camera.ray(col, row).dir);
                    // A brick that did not cast this pixel's ray adds nothing.
                    let piece = |b: usize| {
                        let Some((piece, i)) = pieces[b]
                            .as_ref()
                            .and_then(|piece| Some((piece, piece.at(col, row)?)))
                        else {
                            return ([0.0f32; 4], 0);
                        };
                        let mut v = [0.0f32; 4];
                        for (c, x) in v.iter_mut().take(ch).enumerate() {
                            *x = piece.image.data[i * ch + c] as f32;
                        }
                        (v, piece.counts[i])
                    };
                    let hit = hits[p];
                    let (px, n) = crate::cpu::composite::composite_pixel(
                        tree,
                        d.to_array(),
                        settings,
                        hit,
                        piece,
                        &mut order,
                    );
                    for (c, v) in px.iter().take(ch).enumerate() {
                        px_row[col * ch + c] = *v as f64;
                    }
                    n_row[col] = n;
                }
            });
    }
    timings.total = t_start.elapsed().as_secs_f64();
    Ok(GpuRenderOutput {
        output: RenderOutput::from_counts(image, &counts, settings.sample_count),
        timings,
        hits: None,
    })
}

/// A brick's render in [`render_bricked`] over the pixels of its rectangle: their
/// image, their rays' sample counts and whether each ray meets the whole volume's box,
/// row-major over `rect`.
struct Piece {
    rect: PixelRect,
    image: Frame,
    counts: Vec<u32>,
    hits: Vec<bool>,
}

impl Piece {
    /// Where pixel `(col, row)` of the frame lies in the piece, if it does.
    fn at(&self, col: usize, row: usize) -> Option<usize> {
        let r = &self.rect;
        r.contains(col, row)
            .then(|| (row - r.rows.start) * r.width() + col - r.cols.start)
    }
}

/// Which of `bricks` (of a volume placed by `affine`) a ray of `camera` may meet:
/// [`bricks_seen`] is not `None`. The multi-volume and adaptive casters skip the
/// others' passes, whose rays would all miss.
pub fn bricks_in_view(
    camera: &Camera,
    affine: glam::DMat4,
    bricks: &[crate::io::brick::Brick],
) -> Vec<bool> {
    bricks_seen(camera, affine, bricks)
        .iter()
        .map(Option::is_some)
        .collect()
}

/// The pixels of `camera` whose rays may meet each of `bricks` (of a volume placed by
/// `affine`): [`Camera::pixels_seen`] of each brick's box one and a half voxels wider
/// each way than the samples it owns (faces at half voxels), `None` for a brick no ray
/// meets. [`render_bricked`] casts each brick's rays over its rectangle alone and skips
/// the bricks no ray meets.
pub fn bricks_seen(
    camera: &Camera,
    affine: glam::DMat4,
    bricks: &[crate::io::brick::Brick],
) -> Vec<Option<PixelRect>> {
    bricks
        .iter()
        .map(|b| {
            let corners: Vec<glam::DVec3> = (0..8)
                .map(|c| {
                    let at = |a: usize| {
                        if c >> a & 1 == 0 {
                            b.lo[a] as f64 - 2.0
                        } else {
                            b.hi[a] as f64 + 1.0
                        }
                    };
                    affine.transform_point3(glam::DVec3::new(at(0), at(1), at(2)))
                })
                .collect();
            camera.pixels_seen(&corners)
        })
        .collect()
}

/// A volume's dimensions, value range and f32 grid.
type Checked = ([usize; 3], (f64, f64), Grid<f32>);

/// A session's volume checked (finite, each axis within the adapter's 3-D texture
/// limit) and converted.
fn checked_f32(ctx: &GpuContext, volume: &AnyVolume) -> Result<Checked> {
    volume.check_finite("volume")?;
    let dims = volume.dims();
    let max3d = ctx.limits.max_texture_dimension_3d as usize;
    if dims.iter().any(|&n| n > max3d) {
        return Err(Error::too_large(
            "volume",
            format!("{dims:?} exceeds the adapter's 3D texture limit of {max3d} per axis"),
        ));
    }
    let values = volume.to_f32();
    let r = values.value_range();
    let grid = Grid::<f32> {
        dims,
        data: values.into_data(),
    };
    Ok((dims, (r.min, r.max), grid))
}

/// What a [`RaycastSession`] has done since it was made, counted so that callers and
/// tests can see which frames re-used the device's data.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct SessionStats {
    /// Frames rendered.
    pub frames: usize,
    /// Uploads of the volume: one per texture of it, each at the first frame that
    /// reads it (the `R32Float` one; the [`CompactVolume`] one for hardware-filtered
    /// frames of an 8- or 16-bit volume; none for a prefiltered filter, which samples
    /// the B-spline coefficients, a set-up product).
    pub volume_uploads: usize,
    /// Bytes of the volume's textures on the device now.
    pub volume_bytes: u64,
    /// Lookup tables uploaded (the 1-D and 2-D transfer functions' tables, the
    /// skipping's opacity prefix), each when its entries changed.
    pub table_uploads: usize,
    /// Compute pipelines the session compiled: one per distinct ray-casting shader
    /// source, the pre-classification and gradient passes and the min/max grid's,
    /// each when no earlier session on the device had compiled it.
    pub pipelines_compiled: usize,
    /// Pipelines taken from the device instead, compiled by an earlier session on it
    /// ([`GpuContext::kept`], [`GpuContext::program`]).
    pub pipelines_shared: usize,
    /// Set-up products made: the B-spline coefficients, the pre-classified colours,
    /// the gradient volume and the skipping's min/max grid, each when its key changed.
    pub prepare_passes: usize,
}

impl SessionStats {
    /// Counts a pipeline the session asked the device for: compiled now, or taken.
    fn count_pipeline(&mut self, made: bool) {
        match made {
            true => self.pipelines_compiled += 1,
            false => self.pipelines_shared += 1,
        }
    }
}

/// How many ray-casting pipelines (one per generated shader source) a session keeps;
/// the least recently used goes first.
pub const PIPELINES_KEPT: usize = 8;

/// A device resource and the key it was made for: the bit patterns of everything
/// that determines it.
struct Cached<T> {
    key: Vec<u32>,
    value: T,
}

/// Whether `slot` holds a resource made for `key`.
fn fresh<T>(slot: &Option<Cached<T>>, key: &[u32]) -> bool {
    slot.as_ref().is_some_and(|c| c.key == key)
}

/// A cache key: the bit patterns of a table's entries, then `extra`.
fn table_key(entries: &[[f32; 4]], extra: &[u32]) -> Vec<u32> {
    let mut k: Vec<u32> = bytemuck::cast_slice(entries).to_vec();
    k.extend_from_slice(extra);
    k
}

/// A volume on the device for many frames: the GPU ray caster's persistent state.
///
/// [`RaycastSession::new`] checks the volume (finite, within the adapter's 3-D texture
/// size) and converts it to f32. [`RaycastSession::render`] then renders frames of any
/// transfer function, camera and settings, making again only what changed since an
/// earlier frame, each product cached under the key that determines it:
///
/// | on the device | made from | key |
/// |---|---|---|
/// | the volume as `R32Float` | the f32 values | uploaded once, at the first frame that reads it |
/// | the volume as a [`CompactVolume`] (8/16-bit volumes, hardware-filtered frames) | the integer values | uploaded once, at the first such frame |
/// | the ray-casting pipeline | [`raycast_shader`] | the generated source (the last [`PIPELINES_KEPT`]) |
/// | the set-up and min/max pipelines | fixed shaders | compiled once |
/// | the B-spline coefficients (`settings.filter.prefiltered()`) | CPU prefilter | made once (both interpolating B-splines share them) |
/// | the lookup table, the 2-D one | the transfer functions | their entries |
/// | pre-classified colours | `raycast_prepare.wgsl` (CPU for prefiltered filters) | LUT entries, window map, prefiltering |
/// | the gradient volume | `raycast_prepare.wgsl` (CPU for prefiltered filters) | gradient method, prefiltering |
/// | skipping's min/max grid | `gpu::skip` | block size, filter radius, prefiltering |
/// | skipping's opacity prefix | the LUT | LUT entries |
///
/// Per frame only the parameter block (camera and settings), the clipping mesh's
/// segments and the image bands are new. A frame equals, bit for bit, the one-shot
/// [`render`] of the same inputs (which is a session of one frame). The session keeps
/// one product of each kind (the last key), and its own f32 copy of the volume on the
/// host for the CPU-side set-up (the prefilter, the CPU fallback of the min/max grid,
/// clipping meshes).
///
/// Timings ([`GpuTimings`]) count what a frame did: the first frame also carries the
/// session's set-up and volume upload; a frame that uploads nothing reports `upload =
/// 0`, one that prepares nothing `prepare = 0`. [`RaycastSession::stats`] counts
/// uploads, compiled pipelines and set-up passes.
///
/// ```no_run
/// # use voxlab::{camera::*, gpu::{GpuContext, raycast::RaycastSession}, phantom::Phantom};
/// # use voxlab::{settings::RenderSettings, transfer::TransferFunction};
/// let ctx = GpuContext::shared()?;
/// let volume = Phantom::shepp_logan_modified().sample([64; 3])?.into();
/// let tf = TransferFunction::preset("phantom")?;
/// let mut session = RaycastSession::new(ctx, &volume)?;       // uploads the volume
/// for azimuth in (0..360).step_by(10) {
///     let orbit = Orbit { azimuth_deg: azimuth as f64, ..Orbit::default() };
///     let camera = Camera::orbit(glam::DVec3::splat(31.5), [64.0; 3], orbit,
///         Projection::Perspective { fov_y_deg: 30.0 }, 128, 128)?;
///     let frame = session.render(&tf, &camera, &RenderSettings::default(), &|_, _| {})?;
///     // frames after the first: frame.timings.upload == 0.0
/// }
/// assert_eq!(session.stats().volume_uploads, 1);
/// # Ok::<(), voxlab::Error>(())
/// ```
pub struct RaycastSession<'c> {
    ctx: &'c GpuContext,
    dims: [usize; 3],
    affine: glam::DMat4,
    /// The f32 volume's value range (the shading's gradient threshold is relative to it).
    range: (f64, f64),
    /// The volume as f32 on the host, x fastest.
    grid: Grid<f32>,
    /// The volume as an `R32Float` 3-D texture, once a frame has read it.
    volume: Option<wgpu::Texture>,
    /// How the volume's type fits a compact texture (none for f32 volumes), whether
    /// hardware-filtered frames use it, and the texture once one has.
    compact_kind: Option<CompactVolume>,
    compact_on: bool,
    compact: Option<wgpu::Texture>,
    /// What a frame binds: its textures filterable where the device filters f32 ones.
    frame: Arc<FrameResources>,
    /// On a device without `FLOAT32_FILTERABLE`: what hardware-filtered frames bind,
    /// every texture filterable (they read only the compact texture: [`check_device`]).
    compact_filtering: Option<Arc<FrameResources>>,
    /// Buffers bound where skipping is off, and where there is no clipping mesh.
    skip_off: (wgpu::Buffer, wgpu::Buffer),
    no_segments: wgpu::Buffer,
    /// Ray-casting pipelines by shader source (and whether over the compact-filtering
    /// layout), least recently used first; the device keeps them for other sessions
    /// too ([`GpuContext::kept`]).
    pipelines: Vec<((String, bool), Kernel)>,
    /// The set-up passes' and the min/max grid's pipelines used so far
    /// ([`session_kernel`]).
    kernels: Vec<(&'static str, Kernel)>,
    /// The interpolating B-splines' coefficients, on the host and as a texture.
    coefficients: Option<(Grid<f32>, wgpu::Texture)>,
    /// What a brick was given, prefiltered over the whole volume
    /// ([`RaycastSession::give_prefiltered`]), uploaded by the next frame that needs it.
    given: Prefiltered,
    lut: Option<Cached<wgpu::Buffer>>,
    lut2: Option<Cached<wgpu::Buffer>>,
    prefix: Option<Cached<wgpu::Buffer>>,
    preclassified: Option<Cached<wgpu::Texture>>,
    gradients: Option<Cached<wgpu::Texture>>,
    minmax: Option<Cached<wgpu::Buffer>>,
    stats: SessionStats,
    /// The session's own set-up and upload, reported with its first frame.
    pending: Option<GpuTimings>,
    /// Set when the volume is a brick of a larger one ([`RaycastSession::place`]).
    brick: Option<BrickPlacement>,
}

/// A frame's bindings: every texture `filterable` (and a filtering sampler) or none
/// (for a device without f32 filtering).
fn frame_bindings(filterable: bool) -> [wgpu::BindGroupLayoutEntry; 12] {
    let storage = |read_only| wgpu::BufferBindingType::Storage { read_only };
    [
        buffer_entry(0, wgpu::BufferBindingType::Uniform),
        texture_entry(1, filterable),
        texture_entry(2, filterable),
        texture_entry(3, filterable),
        wgpu::BindGroupLayoutEntry {
            binding: 4,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Sampler(if filterable {
                wgpu::SamplerBindingType::Filtering
            } else {
                wgpu::SamplerBindingType::NonFiltering
            }),
            count: None,
        },
        buffer_entry(5, storage(true)),
        buffer_entry(6, storage(false)),
        buffer_entry(7, storage(false)),
        buffer_entry(8, storage(true)),
        buffer_entry(9, storage(true)),
        buffer_entry(10, storage(true)),
        buffer_entry(11, storage(true)),
    ]
}

/// What a frame binds besides its data, kept by the device for every session: whether
/// its textures bind filterable ([`frame_bindings`]), the sampler (linear where
/// filterable, else nearest) and a placeholder texture.
struct FrameResources {
    filterable: bool,
    sampler: wgpu::Sampler,
    /// A 1×1×1 texture bound where a frame has no pre-classified or gradient volume.
    dummy: wgpu::Texture,
}

impl FrameResources {
    fn new(ctx: &GpuContext, filterable: bool, dummy: wgpu::Texture) -> Self {
        let filter_mode = if filterable {
            wgpu::FilterMode::Linear
        } else {
            wgpu::FilterMode::Nearest
        };
        FrameResources {
            filterable,
            sampler: ctx.clamp_sampler("linear clamp", filter_mode),
            dummy,
        }
    }
}

impl<'c> RaycastSession<'c> {
    /// Checks `volume` (finite voxels, each axis within the adapter's 3-D texture
    /// limit) and converts it to f32; its textures are uploaded by the first frame that
    /// reads each. The session holds its own copy: later changes to `volume` do not
    /// reach it. Hardware-filtered frames of an 8- or 16-bit volume read a
    /// [`CompactVolume`] texture unless the environment variable
    /// `VOXLAB_GPU_F32_TEXTURES=1` (or [`Self::set_compact_textures`]) says otherwise.
    ///
    /// # Errors
    /// [`Error::NonFinite`], [`Error::TooLarge`], out of GPU memory.
    pub fn new(ctx: &'c GpuContext, volume: &AnyVolume) -> Result<Self> {
        let t_start = Instant::now();
        let (dims, range, grid) = checked_f32(ctx, volume)?;
        let filterable = ctx.features.contains(wgpu::Features::FLOAT32_FILTERABLE);
        let dev = &ctx.device;
        // The sampler and placeholder every session on the device binds.
        let (frame, _) = ctx.kept(&format!("raycast frame, filterable {filterable}"), || {
            let dummy = ctx.rgba_texture([1, 1, 1], false)?;
            Ok(FrameResources::new(ctx, filterable, dummy))
        })?;
        // Without f32 filtering, hardware-filtered frames that read only the compact
        // texture bind every texture filterable: an 8-bit placeholder for the others.
        let compact_filtering = match filterable {
            true => None,
            false => {
                let (f, _) = ctx.kept("raycast frame, compact filtering", || {
                    let dummy =
                        ctx.upload_volume_texels([1, 1, 1], wgpu::TextureFormat::R8Unorm, &[0])?;
                    Ok(FrameResources::new(ctx, true, dummy))
                })?;
                Some(f)
            }
        };
        let zeros = |label, bytes: &[u8]| {
            dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytes,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let skip_off = (
            zeros("skip minmax (off)", &[0u8; 16]),
            zeros("skip prefix (off)", &[0u8; 16]),
        );
        let no_segments = zeros(
            "clip mesh segments (off)",
            &[0u8; 16 * super::clipmesh::SEGMENT_VEC4S],
        );
        let setup = t_start.elapsed().as_secs_f64();
        Ok(RaycastSession {
            ctx,
            dims,
            affine: volume.affine(),
            range,
            grid,
            volume: None,
            compact_kind: CompactVolume::of(ctx, volume),
            compact_on: CompactVolume::enabled(),
            compact: None,
            frame,
            compact_filtering,
            skip_off,
            no_segments,
            pipelines: Vec::new(),
            kernels: Vec::new(),
            coefficients: None,
            given: Prefiltered::default(),
            lut: None,
            lut2: None,
            prefix: None,
            preclassified: None,
            gradients: None,
            minmax: None,
            stats: SessionStats::default(),
            pending: Some(GpuTimings {
                setup,
                total: t_start.elapsed().as_secs_f64(),
                ..GpuTimings::default()
            }),
            brick: None,
        })
    }

    /// Replaces the session's volume by `volume` (checked as [`Self::new`] does, its
    /// textures uploaded by the next frame), dropping the old one's textures and what
    /// was computed from it (B-spline coefficients, pre-classified colours, gradients,
    /// the skipping grid) and its brick placement;
    /// the compiled pipelines and the transfer function's tables stay. The next brick
    /// of [`render_bricked`] renders without compiling anything again.
    ///
    /// # Errors
    /// As [`Self::new`].
    pub fn replace_volume(&mut self, volume: &AnyVolume) -> Result<()> {
        let (dims, range, grid) = checked_f32(self.ctx, volume)?;
        self.dims = dims;
        self.affine = volume.affine();
        self.range = range;
        self.grid = grid;
        self.volume = None;
        self.compact_kind = CompactVolume::of(self.ctx, volume);
        self.compact = None;
        self.stats.volume_bytes = 0;
        self.coefficients = None;
        self.given = Prefiltered::default();
        self.preclassified = None;
        self.gradients = None;
        self.minmax = None;
        self.brick = None;
        Ok(())
    }

    /// Whether hardware-filtered frames of an 8- or 16-bit volume read the
    /// [`CompactVolume`] texture (`true`, the default unless
    /// `VOXLAB_GPU_F32_TEXTURES=1`) or the `R32Float` one.
    pub fn set_compact_textures(&mut self, on: bool) {
        self.compact_on = on;
    }

    /// Uploads the volume's textures that a frame needs and the session lacks: the
    /// `R32Float` one when `exact`, the compact one for `compact`.
    fn upload_volume(&mut self, exact: bool, compact: Option<CompactVolume>) -> Result<()> {
        let (ctx, dims) = (self.ctx, self.dims);
        let voxels = self.grid.data.len() as u64;
        let before = self.stats.volume_uploads;
        if exact && self.volume.is_none() {
            self.volume = Some(ctx.upload_volume_r32(dims, &self.grid.data)?);
            self.stats.volume_uploads += 1;
            self.stats.volume_bytes += 4 * voxels;
        }
        if let (Some(c), None) = (compact, &self.compact) {
            let texels = c.texels(&self.grid.data);
            let format = CompactVolume::FORMAT;
            let bytes = bytemuck::cast_slice(&texels);
            self.compact = Some(ctx.upload_volume_texels(dims, format, bytes)?);
            self.stats.volume_uploads += 1;
            self.stats.volume_bytes += CompactVolume::BYTES_PER_VOXEL * voxels;
        }
        if self.stats.volume_uploads > before {
            // Submit the staged copies now, so that the frame's upload time holds them.
            ctx.queue.submit(std::iter::empty::<wgpu::CommandBuffer>());
        }
        Ok(())
    }

    /// Gives a placed brick the whole volume's prefiltered products over its voxels
    /// with their ghosts ([`Prefiltered`]), for its next frame to sample in place of its
    /// own prefilter (which would differ near the brick's faces).
    ///
    /// # Errors
    /// A grid of other dimensions than the session's volume.
    pub fn give_prefiltered(&mut self, p: Prefiltered) -> Result<()> {
        let grids = p
            .coefficients
            .iter()
            .chain(p.preclassified.iter().flatten());
        for g in grids.chain(p.gradients.iter().flatten()) {
            if g.dims != self.dims {
                return Err(Error::invalid(
                    "prefiltered grid",
                    format!("{:?} for a {:?} volume", g.dims, self.dims),
                ));
            }
        }
        if p.coefficients.is_some() {
            self.coefficients = None;
        }
        if p.preclassified.is_some() {
            self.preclassified = None;
        }
        if p.gradients.is_some() {
            self.gradients = None;
        }
        self.given = p;
        Ok(())
    }

    /// Makes the session's volume a brick of a larger volume: its frames take only
    /// the samples the brick owns, of the whole volume's rays ([`BrickPlacement`];
    /// see [`render_owned`]).
    ///
    /// # Errors
    /// A placement the volume does not fit: the brick outside its own voxels, or the
    /// voxels outside the whole volume.
    pub fn place(&mut self, b: BrickPlacement) -> Result<()> {
        let d = self.dims;
        let fits = (0..3).all(|a| {
            b.origin[a] <= b.lo[a]
                && b.lo[a] < b.hi[a]
                && b.hi[a] <= b.origin[a] + d[a]
                && b.origin[a] + d[a] <= b.whole[a]
        });
        if !fits {
            return Err(Error::invalid(
                "brick placement",
                format!(
                    "the brick {:?} .. {:?} of a {:?} volume does not lie in the {:?} \
                     voxels from {:?}",
                    b.lo, b.hi, b.whole, d, b.origin
                ),
            ));
        }
        self.brick = Some(b);
        Ok(())
    }

    /// The device the session lives on.
    pub fn context(&self) -> &'c GpuContext {
        self.ctx
    }

    /// The volume's dimensions (x, y, z).
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// What the session has done so far.
    pub fn stats(&self) -> SessionStats {
        self.stats
    }

    /// Renders a frame. Same inputs and outputs as `cpu::raycast::render` (the volume
    /// being the session's); the image equals the one-shot [`render`]'s bit for bit.
    ///
    /// # Errors
    /// Invalid settings or transfer function, options the GPU path refuses (the full
    /// sinc, hardware filtering of other filters or without `FLOAT32_FILTERABLE`, rays
    /// longer than a CPU driver's loop limit), too many samples per ray or per frame
    /// ([`crate::settings::check_ray_work`]), shader or device errors; MIDA and
    /// iso-surfaces in a placed session (a brick's rays carry their state from the
    /// bricks in front: [`render_bricked`]).
    pub fn render(
        &mut self,
        tf: &TransferFunction,
        camera: &Camera,
        settings: &RenderSettings,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<GpuRenderOutput> {
        self.render_frame(tf, camera, settings, None, false, None, progress)
    }

    /// A frame; a brick's MIDA or iso-surface frame ([`carries_state`]) takes and
    /// leaves each ray's state in `carry` ([`CARRIED_VEC4S`] per pixel, [`carried_mida`],
    /// [`carried_iso`]) and makes no image. With `shadows`, a brick's iso-surface frame
    /// marches only the waiting shadow rays' samples it owns
    /// (`shaders/shared/modes_cast.wgsl: shadow_pass`). With `rect`, only the rays of
    /// those pixels are cast (and carried): the image, counts and hits are the
    /// rectangle's.
    #[allow(clippy::too_many_arguments)]
    fn render_frame(
        &mut self,
        tf: &TransferFunction,
        camera: &Camera,
        settings: &RenderSettings,
        carry: Option<&mut [[f32; 4]]>,
        shadows: bool,
        rect: Option<&PixelRect>,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<GpuRenderOutput> {
        let t_start = Instant::now();
        settings.validate()?;
        tf.validate()?;
        let whole = PixelRect::whole(camera.width, camera.height);
        let rect = rect.unwrap_or(&whole);
        if rect.is_empty() || rect.cols.end > camera.width || rect.rows.end > camera.height {
            return Err(Error::Gpu(format!(
                "the pixels {rect:?} of a {}×{} frame",
                camera.width, camera.height
            )));
        }
        let carries = self.brick.is_some() && carries_state(settings);
        let pixels = camera.width * camera.height;
        match carry.as_ref() {
            None if carries => {
                return Err(Error::invalid(
                    "--mode",
                    "a brick's MIDA and iso-surface rays carry their state from the bricks \
                     in front of it: render the bricks in turn (gpu::raycast::render_bricked)",
                ))
            }
            Some(c) if !carries || c.len() != pixels * CARRIED_VEC4S => {
                return Err(Error::Gpu(format!(
                    "a carried ray state of {} vec4 for {pixels} pixels of a {} frame",
                    c.len(),
                    if carries { "carrying brick" } else { "whole" }
                )))
            }
            _ => {}
        }
        let ctx = self.ctx;
        let dev = &ctx.device;
        let dims = self.dims;
        // A brick casts the whole volume's rays.
        let (ray_dims, ray_affine, ray_range) = match &self.brick {
            Some(b) => (b.whole, b.affine, b.range),
            None => (dims, self.affine, self.range),
        };
        let compact_kind = self.compact_kind.filter(|_| self.compact_on);
        crate::cpu::raycast::check_cost(ray_dims, camera, settings)?;
        check_device(ctx, ray_dims, settings, compact_kind)?;
        // What this session's textures (its brick's, when placed) and the image's
        // buffers take, against the device memory: a session holds its volume whole.
        let held = dims.iter().product::<usize>() as u64
            * texture_bytes_per_voxel(settings, compact_kind)
            + output_bytes(camera, carries);
        ctx.check_memory("the ray caster's volume textures", held)
            .map_err(|e| match e {
                Error::TooLarge { what, message } => Error::TooLarge {
                    what,
                    message: format!(
                        "{message}; a renderer session holds its volume whole: render the \
                         frame on its own, which cuts the volume into bricks"
                    ),
                },
                e => e,
            })?;
        let lut = tf.lut(settings.lut_size).to_real::<f32>();
        let mut params = raycast_params(ray_dims, ray_affine, &lut, ray_range, camera, settings)?;
        if let Some(b) = &self.brick {
            // The texture (and its skipping cells) is the brick's; the box the rays
            // cross, the whole volume's.
            params = accel_params(dims, settings, params);
            params.dims = [dims[0] as u32, dims[1] as u32, dims[2] as u32, 0];
            params.brick = [
                b.origin[0] as f32,
                b.origin[1] as f32,
                b.origin[2] as f32,
                1.0,
            ];
            let face = |i: usize, open: bool, far: f32| {
                if open {
                    far
                } else {
                    i as f32 - 0.5
                }
            };
            for a in 0..3 {
                params.own_lo[a] = face(b.lo[a], b.lo[a] == 0, -f32::MAX);
                params.own_hi[a] = face(b.hi[a], b.hi[a] >= b.whole[a], f32::MAX);
            }
            params.own_lo[3] = if shadows && carries { 1.0 } else { 0.0 };
        }
        let pre = params.flags[0] == 1;
        let precomputed = params.flags[2] == 1;
        let skipping = params.accel[0] == 1;
        let prefiltered = settings.filter.prefiltered();
        let (exact, compact) =
            volume_textures(settings, self.compact_kind.filter(|_| self.compact_on));
        // Without f32 filtering a hardware-filtered frame reads only the compact
        // texture (check_device refused the others), over the all-filterable layout.
        let compact_filtered = settings.hardware_filtering && self.compact_filtering.is_some();
        let pipeline =
            self.raycast_pipeline(raycast_shader(settings, compact), compact_filtered)?;
        let setup = t_start.elapsed().as_secs_f64();

        // Uploads: the volume's textures this frame reads for the first time (the
        // R32Float one for the exact path and the set-up passes on the GPU), and the
        // lookup tables whose entries changed.
        let t_up = Instant::now();
        let uploads_before = self.stats.table_uploads + self.stats.volume_uploads;
        self.upload_volume(exact, compact)?;
        let table = |label, entries: &[u8]| {
            dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: entries,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let lut_key = table_key(&lut.entries, &[]);
        if !fresh(&self.lut, &lut_key) {
            self.lut = None;
            let value = table("lut", bytemuck::cast_slice(&lut.entries));
            self.lut = Some(Cached {
                key: lut_key.clone(),
                value,
            });
            self.stats.table_uploads += 1;
        }
        let lut2_entries: Vec<[f32; 4]> = match (&settings.transfer_2d, settings.mode) {
            (Some(t), Mode::Dvr) => t.lut().to_real::<f32>().entries,
            _ => vec![[0.0; 4]],
        };
        let lut2_key = table_key(&lut2_entries, &[]);
        if !fresh(&self.lut2, &lut2_key) {
            self.lut2 = None;
            let value = table("lut2d", bytemuck::cast_slice(&lut2_entries));
            self.lut2 = Some(Cached {
                key: lut2_key,
                value,
            });
            self.stats.table_uploads += 1;
        }
        // Empty-space skipping's prefix count of non-zero opacities (O(LUT), on the host).
        if skipping && !fresh(&self.prefix, &lut_key) {
            self.prefix = None;
            let prefix = crate::cpu::skip::opacity_prefix(&lut, 0.0).prefix;
            let value = table("skip prefix", bytemuck::cast_slice(&prefix));
            self.prefix = Some(Cached {
                key: lut_key,
                value,
            });
            self.stats.table_uploads += 1;
        }
        let upload = if self.stats.table_uploads + self.stats.volume_uploads > uploads_before {
            ctx.wait()?;
            t_up.elapsed().as_secs_f64()
        } else {
            0.0
        };

        // Set-up passes: B-spline coefficients, pre-classified colours, gradients and
        // the skipping's min/max grid, each made when its key changed.
        let t_prep = Instant::now();
        let passes_before = self.stats.prepare_passes;
        if prefiltered && self.coefficients.is_none() {
            // A sequential recurrence along every line, on the CPU (module docs), or
            // the whole volume's, given.
            let c = match self.given.coefficients.take() {
                Some(c) => c,
                None => prepare(&self.grid, settings.filter),
            };
            let tex = ctx.upload_volume_r32(dims, &c.data)?;
            self.coefficients = Some((c, tex));
            self.stats.prepare_passes += 1;
        }
        let lut_buf = &self.lut.as_ref().expect("uploaded above").value;
        if pre {
            let key = table_key(
                &lut.entries,
                &[
                    lut.scale.to_bits(),
                    lut.offset.to_bits(),
                    prefiltered as u32,
                ],
            );
            if !fresh(&self.preclassified, &key) {
                self.preclassified = None;
                let value = if prefiltered {
                    let rgba = match self.given.preclassified.take() {
                        Some(rgba) => rgba,
                        None => crate::cpu::raycast::preclassify(&self.grid, &lut)
                            .map(|g| prepare(&g, settings.filter)),
                    };
                    ctx.upload_rgba(
                        dims,
                        &interleave(&rgba[0], &rgba[1], &rgba[2], Some(&rgba[3])),
                    )?
                } else {
                    let k = prepare_kernel(ctx, &mut self.kernels, &mut self.stats, "preclassify")?;
                    let volume = self.volume.as_ref().expect("uploaded above");
                    run_prepare(ctx, &k, &params, volume, lut_buf, dims)?
                };
                self.preclassified = Some(Cached { key, value });
                self.stats.prepare_passes += 1;
            }
        }
        if precomputed {
            let key = vec![gradient_method_id(settings.gradient), prefiltered as u32];
            if !fresh(&self.gradients, &key) {
                self.gradients = None;
                let value = if prefiltered {
                    let g = match self.given.gradients.take() {
                        Some(g) => g,
                        None => crate::cpu::gradient::precompute_gradients(
                            &self.grid,
                            settings.gradient,
                        )
                        .map(|g| prepare(&g, settings.filter)),
                    };
                    ctx.upload_rgba(dims, &interleave(&g[0], &g[1], &g[2], None))?
                } else {
                    let k = prepare_kernel(
                        ctx,
                        &mut self.kernels,
                        &mut self.stats,
                        "precompute_gradients",
                    )?;
                    let volume = self.volume.as_ref().expect("uploaded above");
                    run_prepare(ctx, &k, &params, volume, lut_buf, dims)?
                };
                self.gradients = Some(Cached { key, value });
                self.stats.prepare_passes += 1;
            }
        }
        // What the filter samples: the raw values (in the R32Float or the compact
        // texture), or the B-spline coefficients. The skipping grid is built from an
        // R32Float texture where there is one, else on the CPU (the same values).
        let (sampled_grid, sampled_tex, exact_tex) = match (&self.coefficients, prefiltered) {
            (Some((g, t)), true) => (g, t, Some(t)),
            _ => {
                let t = match compact {
                    Some(_) => self.compact.as_ref(),
                    None => self.volume.as_ref(),
                };
                (&self.grid, t.expect("uploaded above"), self.volume.as_ref())
            }
        };
        if skipping {
            let radius = crate::cpu::skip::skip_radius(settings).unwrap_or(1);
            let key = vec![
                settings.block_size as u32,
                radius as u32,
                prefiltered as u32,
            ];
            if !fresh(&self.minmax, &key) {
                self.minmax = None;
                let (kernels, stats) = (&mut self.kernels, &mut self.stats);
                let value = super::skip::min_max_buffer_with(
                    ctx,
                    exact_tex,
                    sampled_grid,
                    (settings.block_size, radius),
                    &mut || {
                        session_kernel(kernels, stats, "skip_minmax", || {
                            super::skip::minmax_kernel(ctx)
                        })
                    },
                )?;
                self.minmax = Some(Cached { key, value });
                self.stats.prepare_passes += 1;
            }
        }
        // Clipping mesh (gpu::clipmesh): resolved on the host every frame (the bricks
        // mesh from the same grid the skipping bounds), its segments computed per band.
        let clip_mesh = {
            let voxels = match settings.classification {
                Classification::Post => sampled_grid,
                Classification::Pre => &self.grid,
            };
            let r = crate::cpu::clipmesh::resolve(settings, self.affine, dims, Some(voxels), &lut)?;
            match r {
                Some(m) => Some(super::clipmesh::GpuClipMesh::new(ctx, &m)?),
                None => None,
            }
        };
        params.clip_mesh[0] = clip_mesh.is_some() as u32;
        let prepare_time = if self.stats.prepare_passes > passes_before || clip_mesh.is_some() {
            ctx.wait()?;
            t_prep.elapsed().as_secs_f64()
        } else {
            0.0
        };

        // Ray casting over the rectangle, in bands of rows that fit the storage-binding
        // limit.
        let (w, h) = (rect.width(), rect.height());
        let max_binding = ctx.limits.max_storage_buffer_binding_size as usize;
        let pixel_bytes = if clip_mesh.is_some() {
            16 * super::clipmesh::SEGMENT_VEC4S
        } else if carries {
            16 * CARRIED_VEC4S
        } else {
            16
        };
        let rows_per_tile = (max_binding / (w * pixel_bytes))
            .clamp(1, h)
            .min((1 << 20) / w + 1)
            .max(1);
        let view = |t: &wgpu::Texture| t.create_view(&Default::default());
        let FrameResources { sampler, dummy, .. } = self.frame_resources(compact_filtered);
        let Kernel { layout, pipeline } = &self.pipelines[pipeline].1;
        let textures_of = |c: &Option<Cached<wgpu::Texture>>, used: bool| match c {
            Some(c) if used => view(&c.value),
            _ => view(dummy),
        };
        let (vol_view, pre_view, grad_view) = (
            view(sampled_tex),
            textures_of(&self.preclassified, pre),
            textures_of(&self.gradients, precomputed),
        );
        let (skip_minmax, skip_prefix) = match (&self.minmax, &self.prefix, skipping) {
            (Some(m), Some(p), true) => (&m.value, &p.value),
            _ => (&self.skip_off.0, &self.skip_off.1),
        };
        let lut2_buf = &self.lut2.as_ref().expect("uploaded above").value;
        let no_segments = &self.no_segments;
        let mut image = Frame::new(w, h, if settings.mode.rgba() { 4 } else { 1 });
        let mut counts = vec![0u32; w * h];
        let bands = render_bands(
            ctx,
            (pipeline, "raycast"),
            rows_per_tile,
            (rect, [camera.width, camera.height]),
            (&mut image, &mut counts),
            carry,
            progress,
            |band, out_buf, cnt_buf| {
                let (c0, r0) = (band.cols.start as u32, band.rows.start as u32);
                params.tile = [c0, r0, band.width() as u32, band.height() as u32];
                let pbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("raycast params"),
                    contents: bytemuck::bytes_of(&params),
                    usage: super::context::PARAMS_USAGE,
                });
                let seg_buf = match &clip_mesh {
                    Some(m) => Some(m.segments(ctx, &params)?),
                    None => None,
                };
                Ok(ctx.bind_group(
                    "raycast",
                    layout,
                    &[
                        pbuf.as_entire_binding(),
                        wgpu::BindingResource::TextureView(&vol_view),
                        wgpu::BindingResource::TextureView(&pre_view),
                        wgpu::BindingResource::TextureView(&grad_view),
                        wgpu::BindingResource::Sampler(sampler),
                        lut_buf.as_entire_binding(),
                        out_buf.as_entire_binding(),
                        cnt_buf.as_entire_binding(),
                        lut2_buf.as_entire_binding(),
                        skip_minmax.as_entire_binding(),
                        skip_prefix.as_entire_binding(),
                        seg_buf.as_ref().unwrap_or(no_segments).as_entire_binding(),
                    ],
                ))
            },
        )?;
        let mut timings = GpuTimings {
            setup,
            upload,
            prepare: prepare_time,
            kernel: bands.kernel,
            kernel_from_timestamps: bands.from_timestamps,
            readback: bands.readback,
            total: t_start.elapsed().as_secs_f64(),
        };
        if let Some(p) = self.pending.take() {
            timings.setup += p.setup;
            timings.upload += p.upload;
            timings.total += p.total;
        }
        self.stats.frames += 1;
        // A brick's counts carry the rays' hits in their top bit.
        let hits = self.brick.as_ref().map(|_| {
            counts
                .iter_mut()
                .map(|c| {
                    let hit = *c & 0x8000_0000 != 0;
                    *c &= 0x7fff_ffff;
                    hit
                })
                .collect()
        });
        Ok(GpuRenderOutput {
            output: RenderOutput::from_counts(image, &counts, settings.sample_count),
            timings,
            hits,
        })
    }

    /// What a frame binds: the compact-filtering resources where it is one.
    fn frame_resources(&self, compact_filtered: bool) -> &FrameResources {
        match &self.compact_filtering {
            Some(f) if compact_filtered => f.as_ref(),
            _ => self.frame.as_ref(),
        }
    }

    /// The index in `self.pipelines` of the ray-casting pipeline of `source`, taken
    /// from the device's kept programs or compiled when it is not there
    /// ([`GpuContext::program`]; the session drops its least recently used past
    /// [`PIPELINES_KEPT`]).
    fn raycast_pipeline(&mut self, source: String, compact_filtered: bool) -> Result<usize> {
        let key = (source, compact_filtered);
        if let Some(i) = self.pipelines.iter().position(|(k, _)| *k == key) {
            let hit = self.pipelines.remove(i);
            self.pipelines.push(hit);
        } else {
            if self.pipelines.len() >= PIPELINES_KEPT {
                self.pipelines.remove(0);
            }
            let ctx = self.ctx;
            let bindings = frame_bindings(self.frame_resources(compact_filtered).filterable);
            let (kernel, made) = ctx
                .program("raycast.wgsl", &key.0, Some(&bindings))?
                .kernel(ctx, "raycast")?;
            self.stats.count_pipeline(made);
            self.pipelines.push((key, kernel));
        }
        Ok(self.pipelines.len() - 1)
    }
}

/// On a CPU adapter, refuses rays that could run past llvmpipe's loop limit.
/// What the GPU ray caster refuses of `settings` over a volume of `dims` (the whole
/// volume's, for a brick) whose hardware-filtered frames read `compact` (the session's
/// [`CompactVolume`] in use, if any) on this device: the full sinc, hardware filtering
/// of a filter the texture unit cannot serve, hardware filtering of f32 textures
/// without `FLOAT32_FILTERABLE` (a frame that reads only the compact 16-bit texture
/// needs no such feature), and rays past a CPU driver's loop limit
/// ([`LLVMPIPE_LOOP_LIMIT`]). Every frame checks it, and so does `voxlab render
/// --dry-run`.
///
/// # Errors
/// [`Error::Invalid`] naming `filter` or `hardware filtering`; [`Error::Gpu`] without
/// `FLOAT32_FILTERABLE`; [`Error::Invalid`] naming `step` for rays longer than the loop
/// limit.
pub fn check_device(
    ctx: &GpuContext,
    dims: [usize; 3],
    settings: &RenderSettings,
    compact: Option<CompactVolume>,
) -> Result<()> {
    check_filter(settings)?;
    let compact_only = matches!(volume_textures(settings, compact), (false, Some(_)));
    if settings.hardware_filtering && !compact_only {
        ctx.require_float32_filtering().map_err(|e| match e {
            Error::Gpu(m) => Error::Gpu(format!(
                "{m}; without it the texture unit filters only an 8- or 16-bit volume's \
                 compact texture, for frames that read no pre-classified colours, \
                 precomputed gradients or B-spline coefficients"
            )),
            e => e,
        })?;
    }
    check_loop_limit(ctx, dims, settings)
}

fn check_loop_limit(ctx: &GpuContext, dims: [usize; 3], settings: &RenderSettings) -> Result<()> {
    if !ctx.summary.is_cpu() {
        return Ok(());
    }
    // The ray march is the only loop per invocation (plus 3 box-slab iterations).
    let diag = crate::volume::diagonal(dims);
    // Skipping adds one iteration per cell crossed, twice; iso-surfaces loop over the
    // iso-values per step (crossings, their sort) and an opaque surface's shadow ray
    // marches once more.
    let cells = crate::cpu::skip::cell_count(dims, settings.block_size);
    let isos = settings.iso_surfaces.len() as f64;
    let per_step = 1.0
        + 2.0 * isos
        + if settings.iso_shadows {
            1.0 + isos
        } else {
            0.0
        };
    let mut steps =
        (diag / settings.step + 2.0) * per_step + 2.0 * (cells[0] + cells[1] + cells[2]) as f64;
    if settings.clip_mesh.is_some() {
        // Up to MAX_SEGMENTS mesh ranges per skipping range, and their search.
        steps += 8.0 * 2.0 * (cells[0] + cells[1] + cells[2]) as f64 + 64.0;
    }
    if steps > (LLVMPIPE_LOOP_LIMIT - 16) as f64 {
        return Err(Error::invalid(
            "step",
            format!(
                "up to {steps:.0} steps per ray exceed the {LLVMPIPE_LOOP_LIMIT} loop \
                 iterations a CPU Vulkan driver (llvmpipe) runs per invocation; use a \
                 larger step"
            ),
        ));
    }
    Ok(())
}

/// Interleaves three or four grids into RGBA texels (the fourth channel 0 if absent).
fn interleave(r: &Grid<f32>, g: &Grid<f32>, b: &Grid<f32>, a: Option<&Grid<f32>>) -> Vec<[f32; 4]> {
    (0..r.data.len())
        .map(|i| {
            [
                r.data[i],
                g.data[i],
                b.data[i],
                a.map_or(0.0, |a| a.data[i]),
            ]
        })
        .collect()
}

/// The bindings of `raycast_prepare.wgsl`.
const PREPARE_BINDINGS: [wgpu::BindGroupLayoutEntry; 4] = [
    buffer_entry(0, wgpu::BufferBindingType::Uniform),
    texture_entry(1, false),
    buffer_entry(2, wgpu::BufferBindingType::Storage { read_only: true }),
    super::context::rgba_storage_entry(3),
];

/// The session's pipeline `name` from `kernels`, or, on its first use in the session,
/// from `get` (the device's kept programs, [`GpuContext::program`]), counted in `stats`
/// as compiled or taken.
fn session_kernel(
    kernels: &mut Vec<(&'static str, Kernel)>,
    stats: &mut SessionStats,
    name: &'static str,
    get: impl FnOnce() -> Result<(Kernel, bool)>,
) -> Result<Kernel> {
    if let Some((_, k)) = kernels.iter().find(|(n, _)| *n == name) {
        return Ok(k.clone());
    }
    let (kernel, made) = get()?;
    stats.count_pipeline(made);
    kernels.push((name, kernel.clone()));
    Ok(kernel)
}

/// The session's pipeline of one of `raycast_prepare.wgsl`'s entry points
/// ([`session_kernel`]).
fn prepare_kernel(
    ctx: &GpuContext,
    kernels: &mut Vec<(&'static str, Kernel)>,
    stats: &mut SessionStats,
    entry: &'static str,
) -> Result<Kernel> {
    session_kernel(kernels, stats, entry, || {
        let bindings = Some(&PREPARE_BINDINGS[..]);
        ctx.program("raycast_prepare.wgsl", &prepare_shader(), bindings)?
            .kernel(ctx, entry)
    })
}

/// Runs one of `raycast_prepare.wgsl`'s passes into a new RGBA texture.
fn run_prepare(
    ctx: &GpuContext,
    Kernel { layout, pipeline }: &Kernel,
    params: &RaycastParams,
    volume: &wgpu::Texture,
    lut: &wgpu::Buffer,
    dims: [usize; 3],
) -> Result<wgpu::Texture> {
    let dev = &ctx.device;
    let target = ctx.rgba_texture(dims, true)?;
    let pbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("prepare params"),
        contents: bytemuck::bytes_of(params),
        usage: super::context::PARAMS_USAGE,
    });
    let vol_view = volume.create_view(&Default::default());
    let target_view = target.create_view(&Default::default());
    let bind = ctx.bind_group(
        "prepare",
        layout,
        &[
            pbuf.as_entire_binding(),
            wgpu::BindingResource::TextureView(&vol_view),
            lut.as_entire_binding(),
            wgpu::BindingResource::TextureView(&target_view),
        ],
    );
    let mut enc = dev.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups(
            (dims[0] as u32).div_ceil(4),
            (dims[1] as u32).div_ceil(4),
            (dims[2] as u32).div_ceil(4),
        );
    }
    ctx.queue.submit([enc.finish()]);
    Ok(target)
}

#[cfg(test)]
mod tests {
    use super::GpuTimings;

    #[test]
    fn timings_add_field_by_field_and_keep_timestamps_only_when_both_had_them() {
        let t = |x: f64, ts: bool| GpuTimings {
            setup: x,
            upload: 2.0 * x,
            prepare: 3.0 * x,
            kernel: 4.0 * x,
            kernel_from_timestamps: ts,
            readback: 5.0 * x,
            total: 6.0 * x,
        };
        let mut a = t(1.0, true);
        a.add(&t(0.5, true));
        assert_eq!(a, t(1.5, true));
        a.add(&t(0.5, false));
        assert_eq!(a, t(2.0, false));
        a.add(&t(1.0, true));
        assert_eq!(a, t(3.0, false));
    }
}
