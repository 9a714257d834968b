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
//! # Sampling ([`Sampling`])
//! [`Sampling::Exact`] (the default) reads the projections from storage buffers with
//! the bilinear interpolation written out in the shader (`shaders/shared/ct_bilinear.wgsl`,
//! the oracle's twin). [`Sampling::Hardware`] is the paper's own reconstruction: each
//! view is a layer of a 2-D texture array (`R32Float`, or `R16Float` for f16 storage)
//! with a border of one zero texel, and the texture unit filters every value
//! (`textureSampleLevel`, linear, clamp to edge: the border is the exact path's zeros).
//! A texture unit cannot filter GFR's gradient, so that path gathers the cell's four
//! texels (`textureGather`, exact) and weighs them in the shader, as the exact path
//! does. Real GPUs round each filter weight to about 8 fractional bits; a reconstructed
//! value then differs from the exact path's by at most [`hardware_error_bound`] (MIP and
//! MinIP images by as much, X-ray images by that times the ray's length; DVR passes it
//! through the transfer function and is measured, not bounded).
//!
//! The final background blend is done on the host in f64 from the accumulated
//! `(C, A)`, exactly as `cpu::raycast::cast_ray` ends.
//!
//! # Past one binding ([`D2vrSplit`])
//! Every sample reads every view, so the projections cannot be cut into passes the
//! way a backprojection's are (the classification needs the whole sum). They are
//! bound instead as up to [`MAX_PROJECTION_PARTS`] storage bindings (or texture
//! arrays) of whole views each (binding 3, then 8, 9, …), and the shader picks the
//! binding by the element's index or the view's ([`projections_wgsl`]): every tap reads
//! the same value, so the image is the unsplit one bit for bit. A texture array holds
//! at most `max_texture_array_layers` views and, so that `VOXLAB_GPU_MAX_BINDING`
//! splits both paths alike, at most a binding's bytes. The per-pixel accumulators (32 bytes a pixel) are cut
//! into bands of rows, each a dispatch series of its own (every pixel is cast alone).
//! `VOXLAB_GPU_MAX_BINDING` lowers the limit the split plans against (docs/gpu.md).

use super::context::{GpuContext, LLVMPIPE_LOOP_LIMIT};
use super::params::RaycastParams;
use super::plan::{Held, Pieces, Sampling};
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
    /// gradient (0 GFS, 1 GFR), cylinder, occupancy, and per projection binding the
    /// values it holds (exact) or the views (texture layers, hardware).
    pub flags: [u32; 4],
    /// samples [x, y) of this dispatch, the band's first row and its rows.
    pub chunk: [u32; 4],
}

/// The most storage bindings the filtered projections may be split into. An adapter
/// offering fewer storage buffers per shader stage lowers it ([`D2vrSplit::new`]).
pub const MAX_PROJECTION_PARTS: usize = 8;

/// The shader's storage buffers besides the projections (views, LUT, occupancy, and
/// the two accumulators).
const OTHER_STORAGE_BUFFERS: u32 = 5;

impl ProjStorage {
    /// The hardware path's texture format: `R32Float` (filtered where the device has
    /// `FLOAT32_FILTERABLE`) or `R16Float` (filtered everywhere).
    pub fn texture_format(self) -> wgpu::TextureFormat {
        match self {
            ProjStorage::F32 => wgpu::TextureFormat::R32Float,
            ProjStorage::F16 => wgpu::TextureFormat::R16Float,
        }
    }

    /// Bytes of one texel of the hardware path's texture.
    fn texel_bytes(self) -> u64 {
        match self {
            ProjStorage::F32 => 4,
            ProjStorage::F16 => 2,
        }
    }
}

/// Accumulator bytes per pixel in each of the two buffers (`vec4<f32>`, `vec4<u32>`).
const ACC_BYTES_PER_PIXEL: u64 = 16;

/// The generated module `d2vr_projections`: the filtered projections of `parts` runs
/// of whole views at binding 3, then 8, 9, … (the hardware path's sampler after
/// them), with `fn projection(k: u32, x: f32, y: f32) -> f32`, view `k` at detector
/// column `x`, row `y` (zero outside the detector), and `fn projection_grad(k: u32, x:
/// f32, y: f32) -> vec3<f32>`, that value and its derivatives along `x` and `y`.
///
/// Exact: storage buffers of `storage`'s words (each holding `dp.flags.w` values) read
/// by `shaders/shared/ct_bilinear.wgsl`. Hardware: 2-D texture arrays (each holding
/// `dp.flags.w` views) with a zero border; the value filtered by the texture unit, the
/// gradient from the cell's four gathered texels and
/// `shaders/shared/bilinear_cell.wgsl`.
pub fn projections_wgsl(storage: ProjStorage, sampling: Sampling, parts: usize) -> String {
    assert!(
        (1..=MAX_PROJECTION_PARTS).contains(&parts),
        "1 … {MAX_PROJECTION_PARTS} projection bindings"
    );
    let binding = |k: usize| if k == 0 { 3 } else { 7 + k };
    // `switch` over the parts: `call(name)` is the statement reading part `name`.
    let by_part = |call: &dyn Fn(&str) -> String| -> String {
        if parts == 1 {
            return format!("    {}\n", call("proj"));
        }
        let mut s = String::from("    switch part {\n");
        for k in 0..parts {
            let case = if k + 1 == parts {
                "default".to_string()
            } else {
                format!("case {k}u")
            };
            s += &format!("        {case}: {{ {} }}\n", call(&format!("proj{k}")));
        }
        s + "    }\n"
    };
    let name = |k: usize| {
        if parts == 1 {
            "proj".to_string()
        } else {
            format!("proj{k}")
        }
    };
    match sampling {
        Sampling::Exact => {
            let mut s = String::from(
                "// Generated by src/gpu/d2vr.rs: projections_wgsl (exact). The filtered\n\
                 // projections (angle, row, col), col fastest: f32 bits, or f16 pairs.\n\
                 #import ct_bilinear\n",
            );
            for k in 0..parts {
                s += &format!(
                    "@group(0) @binding({}) var<storage, read> {}: array<u32>;\n",
                    binding(k),
                    name(k)
                );
            }
            // The word holding element j of a binding, and how the value is read.
            let (word, value) = match storage {
                ProjStorage::F32 => ("j", "return bitcast<f32>(w);"),
                ProjStorage::F16 => (
                    "j >> 1u",
                    "let v = unpack2x16float(w);\n    return select(v.x, v.y, (j & 1u) == 1u);",
                ),
            };
            s += "// Element i of the projections, for shared/ct_bilinear.wgsl.\n";
            if parts == 1 {
                s += &format!(
                    "fn tap(i: u32) -> f32 {{\n    let j = i;\n    let w = proj[{word}];\n    \
                     {value}\n}}\n"
                );
            } else {
                s += "// Word w of binding part.\nfn proj_word(part: u32, w: u32) -> u32 {\n";
                s += &by_part(&|p| format!("return {p}[w];"));
                s += "}\n";
                s += &format!(
                    "fn tap(i: u32) -> f32 {{\n    let part = i / dp.flags.w;\n    \
                     let j = i - part * dp.flags.w;\n    let w = proj_word(part, {word});\n    \
                     {value}\n}}\n"
                );
            }
            s += "fn projection(k: u32, x: f32, y: f32) -> f32 {\n    \
                  return bilinear_zero(k * dp.det.x * dp.det.y, dp.det.x, dp.det.y, x, y);\n}\n\
                  fn projection_grad(k: u32, x: f32, y: f32) -> vec3<f32> {\n    \
                  return bilinear_zero_grad(k * dp.det.x * dp.det.y, dp.det.x, dp.det.y, x, y);\n}\n";
            s
        }
        Sampling::Hardware => {
            let mut s = String::from(
                "// Generated by src/gpu/d2vr.rs: projections_wgsl (hardware). One layer per\n\
                 // view of (cols + 2) × (rows + 2) texels: detector pixel (c, r) at texel\n\
                 // (c + 1, r + 1), a border of zeros all round, so clamping to the edge reads\n\
                 // zero outside the detector.\n\
                 #import bilinear_cell\n",
            );
            for k in 0..parts {
                s += &format!(
                    "@group(0) @binding({}) var {}: texture_2d_array<f32>;\n",
                    binding(k),
                    name(k)
                );
            }
            s += &format!(
                "@group(0) @binding({}) var proj_sampler: sampler;\n",
                binding(parts)
            );
            s += "// Layer `layer` of texture array `part`, filtered at uv.\n\
                  fn proj_filtered(part: u32, uv: vec2<f32>, layer: u32) -> f32 {\n";
            s += &by_part(&|p| {
                format!("return textureSampleLevel({p}, proj_sampler, uv, layer, 0.0).x;")
            });
            s += "}\n// The 2 × 2 texels around uv, in textureGather's order: (i, j+1), \
                  (i+1, j+1), (i+1, j), (i, j).\n\
                  fn proj_gathered(part: u32, uv: vec2<f32>, layer: u32) -> vec4<f32> {\n";
            s += &by_part(&|p| format!("return textureGather(0, {p}, proj_sampler, uv, layer);"));
            s += "}\n";
            s += "fn projection(k: u32, x: f32, y: f32) -> f32 {\n    \
                  let part = k / dp.flags.w;\n    \
                  let size = vec2<f32>(f32(dp.det.x + 2u), f32(dp.det.y + 2u));\n    \
                  // Texel (c + 1, r + 1)'s centre is at normalised (c + 1.5, r + 1.5) / size.\n    \
                  let uv = (vec2<f32>(x, y) + 1.5) / size;\n    \
                  return proj_filtered(part, uv, k - part * dp.flags.w);\n}\n";
            s += "fn projection_grad(k: u32, x: f32, y: f32) -> vec3<f32> {\n    \
                  let c = bilinear_cell(dp.det.x, dp.det.y, x, y);\n    \
                  if (!c.inside) {\n        return vec3<f32>(0.0);\n    }\n    \
                  let part = k / dp.flags.w;\n    \
                  let size = vec2<f32>(f32(dp.det.x + 2u), f32(dp.det.y + 2u));\n    \
                  // The texels of detector pixels corner and corner + 1 are corner + 1 and\n    \
                  // corner + 2; the point between their centres is corner + 2, half a texel\n    \
                  // from any other choice.\n    \
                  let uv = (vec2<f32>(c.corner) + 2.0) / size;\n    \
                  let g = proj_gathered(part, uv, k - part * dp.flags.w);\n    \
                  return bilinear_mix_grad(vec4<f32>(g.w, g.z, g.x, g.y), c.t);\n}\n";
            s
        }
    }
}

/// The complete WGSL module for a storage precision, a sampling and a number of
/// projection bindings: `shaders/d2vr.wgsl` and its imports, with
/// [`projections_wgsl`].
pub fn shader_source(storage: ProjStorage, sampling: Sampling, parts: usize) -> String {
    super::shaders::resolve_with(
        "d2vr",
        &[(
            "d2vr_projections",
            &projections_wgsl(storage, sampling, parts),
        )],
    )
}

/// How a D²VR render fits the planner's limits (module docs): the filtered projections
/// in runs of whole views, one storage binding or texture array each, and the image in
/// bands of rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct D2vrSplit {
    /// The views, cut into the projection bindings.
    pub views: Pieces,
    /// The image rows, cut into bands.
    pub rows: Pieces,
    /// Values (detector pixels) per view.
    pub per_view: usize,
    pub storage: ProjStorage,
    pub sampling: Sampling,
    /// Device bytes of one view: its values in `storage`'s precision, with the
    /// hardware path's zero border.
    pub view_bytes: u64,
    /// Image width in pixels.
    pub width: usize,
}

impl D2vrSplit {
    /// The split for `geometry`'s projections stored as `storage`, read as `sampling`
    /// says, and a `width × height` image under `limits`.
    ///
    /// # Errors
    /// [`Error::TooLarge`] when one view or one image row exceeds a binding, the views
    /// need more bindings than the adapter offers (at most [`MAX_PROJECTION_PARTS`]),
    /// or (hardware) a bordered view is wider than a 2-D texture.
    pub fn new(
        limits: &wgpu::Limits,
        geometry: &Geometry,
        storage: ProjStorage,
        sampling: Sampling,
        (width, height): (usize, usize),
    ) -> Result<Self> {
        let limit = crate::gpu::plan::binding_limit(limits);
        let per_view = geometry.rows * geometry.cols;
        let (view_bytes, room) = match (sampling, storage) {
            (Sampling::Exact, ProjStorage::F32) => (4 * per_view as u64, limit),
            // An f16 binding of v views holds ⌈v·n/2⌉ words: at most 2 bytes past v·n·2.
            (Sampling::Exact, ProjStorage::F16) => (2 * per_view as u64, limit.saturating_sub(2)),
            (Sampling::Hardware, _) => {
                let side = limits.max_texture_dimension_2d as usize;
                let (c, r) = (geometry.cols + 2, geometry.rows + 2);
                if c > side || r > side {
                    return Err(Error::too_large(
                        "D²VR projections texture",
                        format!(
                            "a detector of {} × {} pixels with its zero border exceeds the \
                             adapter's 2-D texture size of {side} texels: use the exact path \
                             (without hardware filtering)",
                            geometry.cols, geometry.rows
                        ),
                    ));
                }
                let unit = storage.texel_bytes() * (c * r) as u64;
                let layers = limits.max_texture_array_layers.max(1) as u64;
                (unit, limit.min(layers * unit))
            }
        };
        let views = Pieces::plan(
            "D²VR projections",
            "view",
            geometry.n_angles(),
            view_bytes,
            room,
            1,
        )?;
        // Element indices are u32 in the shader.
        if geometry.n_angles() as u64 * per_view as u64 > u32::MAX as u64 {
            return Err(Error::too_large(
                "D²VR projections",
                format!(
                    "{} values exceed the shader's 32-bit element index",
                    geometry.n_angles() * per_view
                ),
            ));
        }
        let (offered, kind) = match sampling {
            Sampling::Exact => (
                limits
                    .max_storage_buffers_per_shader_stage
                    .saturating_sub(OTHER_STORAGE_BUFFERS),
                "storage bindings",
            ),
            Sampling::Hardware => (
                limits.max_sampled_textures_per_shader_stage,
                "texture arrays",
            ),
        };
        let most = MAX_PROJECTION_PARTS.min(offered as usize);
        if views.count() > most {
            return Err(Error::too_large(
                "D²VR projections",
                format!(
                    "{} views of {per_view} values need {} {kind} of at most {} views, more \
                     than the {most} the renderer binds: use fewer or smaller projections, \
                     16-bit storage (gpu-f16), or the CPU",
                    geometry.n_angles(),
                    views.count(),
                    views.per_piece
                ),
            ));
        }
        let rows = Pieces::plan(
            "D²VR image",
            "image row",
            height,
            ACC_BYTES_PER_PIXEL * width as u64,
            limit,
            1,
        )?;
        Ok(D2vrSplit {
            views,
            rows,
            per_view,
            storage,
            sampling,
            view_bytes,
            width,
        })
    }

    /// The bytes of the projection binding holding `views` views.
    pub fn part_bytes(&self, views: usize) -> u64 {
        match (self.sampling, self.storage) {
            (Sampling::Exact, ProjStorage::F16) => 4 * ((views * self.per_view) as u64).div_ceil(2),
            _ => views as u64 * self.view_bytes,
        }
    }

    /// The device bytes held at once: every projection binding, the views' matrices
    /// aside, and the two accumulators of the largest band.
    pub fn device_bytes(&self) -> u64 {
        let parts: u64 = self.views.ranges().map(|r| self.part_bytes(r.len())).sum();
        parts + 2 * self.band_bytes()
    }

    /// The bytes of one accumulator of the largest band.
    pub fn band_bytes(&self) -> u64 {
        ACC_BYTES_PER_PIXEL * (self.rows.per_piece * self.width) as u64
    }

    /// The largest single buffer or texture.
    pub fn largest_buffer(&self) -> u64 {
        self.part_bytes(self.views.per_piece).max(self.band_bytes())
    }

    /// One line per axis that is cut ("D²VR projections in 3 bindings of 40 views (one
    /// storage binding each)"), and on the hardware path always the projections' line
    /// (it says they are in textures); empty when an exact render runs in one piece.
    pub fn describe(&self) -> Vec<String> {
        use crate::gpu::plan::count_of;
        let mut lines = Vec::new();
        if self.views.is_split() || self.sampling == Sampling::Hardware {
            let each = match self.sampling {
                Sampling::Exact => "storage binding",
                Sampling::Hardware => "texture array",
            };
            lines.push(format!(
                "D²VR projections in {} of {} views (one {each} each)",
                count_of(self.views.count(), "binding"),
                self.views.per_piece
            ));
        }
        if self.rows.is_split() {
            lines.push(format!(
                "D²VR image in {} of {} rows",
                count_of(self.rows.count(), "band"),
                self.rows.per_piece
            ));
        }
        lines
    }
}

/// The most a reconstructed sample of the hardware path ([`Sampling::Hardware`]) may
/// differ from the exact path's on a texture unit whose filter weights carry `bits`
/// fractional bits (8 on NVIDIA), in the field's units: FDK's bound
/// ([`crate::gpu::fbp::filtered_backprojection_bound`]) over the grid's box grown by
/// one and a half voxels (samples lie within half a voxel of it, GFS's neighbours one
/// voxel further), from the values the texture holds (rounded to f16 for
/// [`ProjStorage::F16`], where the bound also allows the unit to return the filtered
/// value in half precision: `2⁻¹¹` of the view's largest value). A MIP or MinIP pixel
/// moves by at most as much, an X-ray pixel by at most that times its ray's length in
/// the box. Infinite when the box reaches a cone-beam source.
pub fn hardware_error_bound(
    filtered: &Projections<f32>,
    geometry: &Geometry,
    grid: &D2vrGrid,
    storage: ProjStorage,
    bits: u32,
) -> f64 {
    let held;
    let (q, rounding) = match storage {
        ProjStorage::F32 => (filtered, 0.0),
        ProjStorage::F16 => {
            held = Projections {
                angles: filtered.angles,
                rows: filtered.rows,
                cols: filtered.cols,
                data: filtered
                    .data
                    .iter()
                    .map(|&v| f32_from_f16_bits(f16_bits(v)))
                    .collect(),
            };
            (&held, 2f64.powi(-11))
        }
    };
    let corners: Vec<[f64; 3]> = (0..8)
        .map(|n| {
            let at = |axis: usize| {
                if n >> axis & 1 == 0 {
                    -1.5
                } else {
                    grid.dims[axis] as f64 + 0.5
                }
            };
            grid.affine
                .transform_point3(glam::DVec3::new(at(0), at(1), at(2)))
                .to_array()
        })
        .collect();
    crate::gpu::fbp::filtered_backprojection_bound(q, geometry, &corners, bits, rounding)
}

/// Rounds to IEEE binary16 bits (round to nearest even), as `pack2x16float` does.
pub fn f16_bits(x: f32) -> u16 {
    half_from_f32(x)
}

/// The value of IEEE binary16 bits, exactly (every half float is an f32).
pub fn f32_from_f16_bits(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0f32 } else { 1.0 };
    let exp = ((h >> 10) & 0x1f) as i32;
    let man = (h & 0x3ff) as f32;
    match exp {
        0 => sign * man * 2f32.powi(-24),
        0x1f if man == 0.0 => sign * f32::INFINITY,
        0x1f => f32::NAN,
        _ => sign * (1.0 + man / 1024.0) * 2f32.powi(exp - 15),
    }
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
    /// The chunk dispatches: their time on the device from timestamp queries where the
    /// adapter has them, otherwise the wall clock of the waited-for submissions.
    pub kernel: f64,
    /// Whether `kernel` comes from timestamp queries.
    pub kernel_from_timestamps: bool,
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
    /// How the render was cut to fit the limits.
    pub split: D2vrSplit,
}

/// [`crate::cpu::d2vr::render_d2vr`] on the GPU (front-to-back compositing only), the
/// projections held as `storage` and read as `sampling` says (module docs).
///
/// # Errors
/// As the CPU version; [`Error::Invalid`] for back-to-front compositing,
/// [`Error::TooLarge`] when the projections or the image cannot fit even split
/// ([`D2vrSplit::new`]), [`Error::Gpu`] on device failure or, for f32 projections
/// filtered by the texture unit, an adapter without `FLOAT32_FILTERABLE`.
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
    sampling: Sampling,
) -> Result<GpuD2vrOutput> {
    let t0 = Instant::now();
    check_inputs(settings, options, grid, camera)?;
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

    let (w, h) = (camera.width, camera.height);
    let split = D2vrSplit::new(&ctx.limits, geometry, storage, sampling, (w, h))?;
    ctx.require_filtering(sampling, storage.texture_format())?;
    let base = D2vrParams {
        flags: [
            base.flags[0],
            base.flags[1],
            base.flags[2],
            match sampling {
                Sampling::Exact => (split.views.per_piece * split.per_view) as u32,
                Sampling::Hardware => split.views.per_piece as u32,
            },
        ],
        ..base
    };

    // Uploads: each binding's run of views, in the storage precision.
    let words_of = |values: &[f32]| -> Vec<u32> {
        match storage {
            ProjStorage::F32 => values.iter().map(|v| v.to_bits()).collect(),
            ProjStorage::F16 => values
                .chunks(2)
                .map(|c| {
                    let lo = half_from_f32(c[0]) as u32;
                    let hi = c.get(1).map_or(0, |&v| half_from_f32(v) as u32);
                    lo | (hi << 16)
                })
                .collect(),
        }
    };
    let dev = &ctx.device;
    let init = |label: &str, bytes: &[u8], usage: wgpu::BufferUsages| {
        dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytes,
            usage,
        })
    };
    let storage_ro = wgpu::BufferUsages::STORAGE;
    let (cols, rows) = (geometry.cols, geometry.rows);
    let upload = |r: std::ops::Range<usize>| -> Result<Held> {
        let values = &filtered.data[r.start * split.per_view..r.end * split.per_view];
        if sampling == Sampling::Exact {
            return Ok(Held::Buffer(init(
                "d2vr projections",
                bytemuck::cast_slice(&words_of(values)),
                storage_ro,
            )));
        }
        let tex = ctx.texture_layers(
            "d2vr projections texture",
            storage.texture_format(),
            [cols + 2, rows + 2, r.len()],
        )?;
        // Inside the zero border.
        let extent = [cols, rows, r.len()];
        match storage {
            ProjStorage::F32 => ctx.write_layers(&tex, [1, 1, 0], extent, values),
            ProjStorage::F16 => {
                let bits: Vec<u16> = values.iter().map(|&v| half_from_f32(v)).collect();
                ctx.write_layers(&tex, [1, 1, 0], extent, &bits)
            }
        }
        Ok(Held::Texture(tex.create_view(
            &wgpu::TextureViewDescriptor {
                dimension: Some(wgpu::TextureViewDimension::D2Array),
                ..Default::default()
            },
        )))
    };
    let held: Vec<Held> = split.views.ranges().map(upload).collect::<Result<_>>()?;
    let sampler = (sampling == Sampling::Hardware)
        .then(|| ctx.clamp_sampler("d2vr projections", wgpu::FilterMode::Linear));
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
        super::context::PARAMS_USAGE,
    );
    let pixels = (w * h) as u64;

    let super::context::Kernel { layout, pipeline } = ctx.kernel(
        "d2vr.wgsl",
        &shader_source(storage, sampling, split.views.count()),
        None,
        "d2vr_chunk",
    )?;

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
    let max_n = (crate::volume::diagonal(grid.dims) / settings.step).ceil() as usize + 2;
    let setup = t0.elapsed().as_secs_f64();

    let query = ctx.timestamps();
    let (mut kernel, mut readback) = (0.0, 0.0);
    let mut dispatches = 0;
    let mut acc: Vec<[f32; 4]> = Vec::with_capacity(pixels as usize);
    let mut cnt: Vec<[u32; 4]> = Vec::with_capacity(pixels as usize);
    for band in split.rows.ranges() {
        let t = Instant::now();
        let band_bytes = ACC_BYTES_PER_PIXEL * (band.len() * w) as u64;
        // Storage buffers start zeroed in wgpu.
        let acc_buf = ctx.storage_buffer("d2vr accumulation", band_bytes)?;
        let cnt_buf = ctx.storage_buffer("d2vr counts", band_bytes)?;
        // Every chunk of the band in one compute pass (the device orders the
        // dispatches and makes each one's sums visible to the next), one submission.
        let mut binds = Vec::new();
        let mut k0 = 0usize;
        while k0 < max_n {
            let k1 = (k0 + chunk).min(max_n);
            let p = D2vrParams {
                chunk: [k0 as u32, k1 as u32, band.start as u32, band.len() as u32],
                ..base
            };
            let dp_buf = init(
                "d2vr chunk",
                bytemuck::bytes_of(&p),
                super::context::PARAMS_USAGE,
            );
            // Bindings 0–7, then the projections' further bindings (8, 9, …) and the
            // hardware path's sampler.
            let mut resources = vec![
                rp_buf.as_entire_binding(),
                dp_buf.as_entire_binding(),
                views_buf.as_entire_binding(),
                held[0].binding(),
                lut_buf.as_entire_binding(),
                occ_buf.as_entire_binding(),
                acc_buf.as_entire_binding(),
                cnt_buf.as_entire_binding(),
            ];
            resources.extend(held[1..].iter().map(Held::binding));
            if let Some(s) = &sampler {
                resources.push(wgpu::BindingResource::Sampler(s));
            }
            binds.push(ctx.bind_group("d2vr", &layout, &resources));
            k0 = k1;
        }
        let extent = [(w as u32).div_ceil(8), (band.len() as u32).div_ceil(8), 1];
        let device = ctx.run_pass((&pipeline, "d2vr_chunk"), &binds, extent, query.as_ref())?;
        dispatches += binds.len();
        kernel += device.unwrap_or_else(|| t.elapsed().as_secs_f64());
        let t = Instant::now();
        acc.extend_from_slice(bytemuck::cast_slice(
            &ctx.read_buffer(&acc_buf, band_bytes)?,
        ));
        cnt.extend_from_slice(bytemuck::cast_slice(
            &ctx.read_buffer(&cnt_buf, band_bytes)?,
        ));
        readback += t.elapsed().as_secs_f64();
    }

    let t = Instant::now();
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
    let readback = readback + t.elapsed().as_secs_f64();
    Ok(GpuD2vrOutput {
        render,
        stats,
        split,
        timings: D2vrTimings {
            setup,
            kernel,
            kernel_from_timestamps: query.is_some(),
            readback,
            total: t0.elapsed().as_secs_f64(),
            dispatches,
        },
    })
}
