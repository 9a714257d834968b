//! FBP and FDK on the GPU: the backprojection of `crate::cpu::fbp` as a WGSL compute
//! shader (`shaders/fbp_backproject.wgsl`). One invocation takes
//! [`VOXELS_PER_INVOCATION`] neighbouring voxels along k, each summed exactly as alone,
//! and loops over a chunk of views: several dispatches keep each one short on software
//! drivers, all of a slab's in one submission. [`backproject_timed`] says how long the
//! dispatches took on the device (timestamp queries, where the adapter has them).
//!
//! The view matrices are uploaded as `ViewMatrix<f32>` (WGSL `CtView`). The filtered
//! projections are read one of two ways ([`Sampling`]): exactly, from an f32
//! storage buffer with the bilinear interpolation written out in the shader (the
//! oracle's twin, the default), or through the texture unit, from an `R32Float` 2-D
//! texture array with a linear sampler (the fast path of real GPUs, whose filter
//! weights carry about 8 fractional bits). [`fbp`] runs the whole reconstruction on
//! the GPU: ramp filtering with [`crate::gpu::ramp::filter_projections`] (cosine
//! pre-weighting, batched FFTs, the response, cropping), then [`backproject`].

use crate::cpu::fbp::{backprojection_scale, Grid, Reconstruction};
use crate::cpu::ramp::RampFilter;
use crate::ct::ViewMatrix;
use crate::ct::{Geometry, Projections};
use crate::error::{Error, Result};
use crate::gpu::plan::{binding_limit, count_of, Held, Pieces, Sampling};
use crate::gpu::{context::Kernel, GpuContext};
use crate::volume::check_dims;
use wgpu::util::DeviceExt;

/// The shader's uniform block.
///
/// WGSL twin: shaders/shared/fbp_params.wgsl: FbpParams
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct FbpParams {
    pub origin: [f32; 4],
    pub step_i: [f32; 4],
    pub step_j: [f32; 4],
    pub step_k: [f32; 4],
    pub dims: [u32; 4],
    pub det: [u32; 4],
    pub scale: [f32; 4],
    pub slab: [u32; 4],
}

const WORKGROUP: u32 = 64;
/// Voxels (neighbours along k) one invocation backprojects (`VOXELS` in
/// `shaders/fbp_backproject.wgsl`).
pub const VOXELS_PER_INVOCATION: usize = 4;
/// Views per dispatch: bounded work per invocation.
const VIEWS_PER_DISPATCH: usize = 32;

/// Texels of one view on the device: the detector, with the hardware path's border
/// of one zero texel all round ([`Sampling::Hardware`]: the filtered projections in an
/// `R32Float` 2-D texture array, one layer per view).
pub fn view_texels(sampling: Sampling, g: &Geometry) -> usize {
    match sampling {
        Sampling::Exact => g.rows * g.cols,
        Sampling::Hardware => (g.rows + 2) * (g.cols + 2),
    }
}

/// The most a voxel of the hardware path ([`Sampling::Hardware`]) may differ
/// from the exact path's on a texture unit whose interpolation weights carry `bits`
/// fractional bits (8 on NVIDIA), in units of the reconstruction.
///
/// A bilinear value is linear in each weight, and its slope along either axis is at
/// most `D_k`, the largest difference of two texels in one 2 × 2 cell of view `k`
/// (its zero border included). Each weight is off by at most `2^−bits`, so a sample is
/// off by at most `D_k · 2^(1−bits)`, and a voxel by at most
/// `π/(2A) · Σ_k w_k · D_k · 2^(1−bits)`, with `w_k` the view's distance weight, which
/// is largest at a corner of the grid's box (its denominator is affine in the point).
/// Infinite when a corner lies at or behind a cone-beam source.
pub fn hardware_error_bound<R: crate::real::Real>(
    filtered: &Projections<R>,
    g: &Geometry,
    grid: &Grid,
    bits: u32,
) -> f64 {
    filtered_backprojection_bound(
        filtered,
        g,
        &grid.corners(0..grid.dims[1], 0..grid.dims[2]),
        bits,
        0.0,
    )
}

/// `π/(2A) · Σ_k w_k · (D_k · 2^(1−bits) + M_k · rounding)` for points in the box with
/// these eight world `corners`: the most a backprojection `π/(2A) Σ_k w_k q_k(x_k, y_k)`
/// of `filtered` at such a point moves when a texture unit rounds each bilinear weight
/// to `bits` fractional bits ([`hardware_error_bound`]) and its filtered value by
/// `rounding` of itself (0 for `R32Float`; `2⁻¹¹` where a unit may return a 16-bit
/// texture's filtered value in half precision), `M_k` being view `k`'s largest
/// magnitude. Shared by FDK's voxels and D²VR's samples
/// (`gpu::d2vr::hardware_error_bound`).
pub fn filtered_backprojection_bound<R: crate::real::Real>(
    filtered: &Projections<R>,
    g: &Geometry,
    corners: &[[f64; 3]],
    bits: u32,
    rounding: f64,
) -> f64 {
    let (cols, rows) = (filtered.cols, filtered.rows);
    let at = |v: &[R], c: isize, r: isize| -> f64 {
        if c < 0 || r < 0 || c >= cols as isize || r >= rows as isize {
            0.0
        } else {
            v[r as usize * cols + c as usize].f64()
        }
    };
    let mut sum = 0.0;
    for (k, m) in g.view_matrices::<f64>().iter().enumerate() {
        let mut w_max = 0f64;
        for &p in corners {
            match m.project(p) {
                Some((_, _, w)) => w_max = w_max.max(w),
                None => return f64::INFINITY,
            }
        }
        let v = filtered.view(k);
        let top = v.iter().fold(0f64, |m, x| m.max(x.f64().abs()));
        let mut spread = 0f64;
        for r in -1..rows as isize {
            for c in -1..cols as isize {
                let t = [
                    at(v, c, r),
                    at(v, c + 1, r),
                    at(v, c, r + 1),
                    at(v, c + 1, r + 1),
                ];
                let hi = t.iter().fold(f64::NEG_INFINITY, |a, &b| a.max(b));
                let lo = t.iter().fold(f64::INFINITY, |a, &b| a.min(b));
                spread = spread.max(hi - lo);
            }
        }
        sum += w_max * (spread * 2f64.powi(1 - bits as i32) + top * rounding);
    }
    backprojection_scale(g.n_angles()) * sum
}

/// The generated module `fbp_projection`: the binding of the filtered projections
/// (binding 2; the hardware path's sampler at 4) and `fn projection(v: u32, x: f32,
/// y: f32) -> f32`, view `v` of those bound at detector column `x`, row `y`, zero
/// outside the detector.
pub fn projection_wgsl(sampling: Sampling) -> String {
    match sampling {
        Sampling::Exact => "\
// Generated by src/gpu/fbp.rs: projection_wgsl (exact). The filtered projections
// (view, row, col), col fastest, in one f32 storage buffer.
#import ct_bilinear
@group(0) @binding(2) var<storage, read> proj: array<f32>;
// Element i of the filtered projections, for shared/ct_bilinear.wgsl: bilinear_zero.
fn tap(i: u32) -> f32 {
    return proj[i];
}
fn projection(v: u32, x: f32, y: f32) -> f32 {
    let cols = params.det.x;
    let rows = params.det.y;
    return bilinear_zero(v * cols * rows, cols, rows, x, y);
}
"
        .into(),
        Sampling::Hardware => "\
// Generated by src/gpu/fbp.rs: projection_wgsl (hardware). One layer per view of
// (cols + 2) × (rows + 2) texels: detector pixel (c, r) at texel (c + 1, r + 1), a
// border of zeros all round, so clamping to the edge reads zero outside the detector.
@group(0) @binding(2) var proj: texture_2d_array<f32>;
@group(0) @binding(4) var proj_sampler: sampler;
fn projection(v: u32, x: f32, y: f32) -> f32 {
    let size = vec2<f32>(f32(params.det.x + 2u), f32(params.det.y + 2u));
    // Texel (c + 1, r + 1)'s centre is at normalised ((c + 1.5), (r + 1.5)) / size.
    let uv = (vec2<f32>(x, y) + 1.5) / size;
    return textureSampleLevel(proj, proj_sampler, uv, v, 0.0).x;
}
"
        .into(),
    }
}

/// The shader source: `shaders/fbp_backproject.wgsl` and its imports (the shared CT
/// geometry and `FbpParams`), reading the projections exactly.
pub fn shader_source() -> String {
    sampled_shader_source(Sampling::Exact)
}

/// The shader source reading the projections as `sampling` says.
pub fn sampled_shader_source(sampling: Sampling) -> String {
    super::shaders::resolve_with(
        "fbp_backproject",
        &[("fbp_projection", &projection_wgsl(sampling))],
    )
}

/// How [`backproject`] cuts a job to fit the planner's limits
/// ([`crate::gpu::plan`]): the output volume in z-slabs, the filtered projections in
/// batches of whole views.
///
/// A batch holds a multiple of the views one dispatch sums (32) wherever at least 32
/// views fit one binding (and, sampled by the texture unit, one texture array: at most
/// the adapter's `max_texture_array_layers`), and each slab's voxels sit where the
/// unsplit volume's do
/// (the shader takes the slab's first slice), so a split reconstruction equals the
/// unsplit one bit for bit. Only where fewer than 32 views fit a binding do the
/// per-dispatch sums regroup (a float reassociation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BackprojectionPlan {
    /// Slices of the output volume per slab.
    pub slabs: Pieces,
    /// Views of filtered projections per batch.
    pub batches: Pieces,
    /// The largest device allocation of the job at once: the view matrices, one batch
    /// and one slab (bytes).
    pub device_bytes: u64,
    /// How the projections are read (and so stored on the device).
    pub sampling: Sampling,
}

impl BackprojectionPlan {
    /// The plan for `g` onto `grid` under `limits` (the context's, or lower ones),
    /// reading the projections exactly.
    ///
    /// # Errors
    /// [`Error::TooLarge`] when one slice of the volume or one view's projection alone
    /// exceeds a binding.
    pub fn new(limits: &wgpu::Limits, g: &Geometry, grid: &Grid) -> Result<Self> {
        Self::sampled(limits, g, grid, Sampling::Exact)
    }

    /// [`Self::new`] for projections read as `sampling` says. The hardware path's
    /// batches are texture arrays: at most `max_texture_array_layers` views, and no
    /// more bytes than a binding, so that the planner's lowered limits split both
    /// paths alike.
    ///
    /// # Errors
    /// As [`Self::new`]; for [`Sampling::Hardware`] also a detector (with
    /// its border) past the adapter's 2-D texture size.
    pub fn sampled(
        limits: &wgpu::Limits,
        g: &Geometry,
        grid: &Grid,
        sampling: Sampling,
    ) -> Result<Self> {
        let limit = binding_limit(limits);
        let [nx, ny, nz] = grid.dims;
        // Voxel indices are u32 in the shader: a slab holds fewer than 2³² voxels.
        let slice_bytes = (nx * ny) as u64 * 4;
        let slab_limit = limit.min(u32::MAX as u64 / 4 * 4);
        let slabs = Pieces::plan(
            "GPU backprojection volume",
            "slice of the volume",
            nz,
            slice_bytes,
            slab_limit,
            1,
        )?;
        let view_bytes = view_texels(sampling, g) as u64 * 4;
        let batch_limit = match sampling {
            Sampling::Exact => slab_limit,
            Sampling::Hardware => {
                let side = limits.max_texture_dimension_2d as usize;
                if g.cols + 2 > side || g.rows + 2 > side {
                    return Err(Error::too_large(
                        "GPU filtered projections texture",
                        format!(
                            "a detector of {} × {} pixels and its border exceed the \
                             adapter's 2-D texture size of {side} texels: read the \
                             projections exactly (no --hardware-filtering)",
                            g.cols, g.rows
                        ),
                    ));
                }
                slab_limit.min(limits.max_texture_array_layers.max(1) as u64 * view_bytes)
            }
        };
        let batches = Pieces::plan(
            "GPU filtered projections",
            "view",
            g.n_angles(),
            view_bytes,
            batch_limit,
            VIEWS_PER_DISPATCH,
        )?;
        let matrices = (g.n_angles() * size_of::<ViewMatrix<f32>>()) as u64;
        Ok(BackprojectionPlan {
            slabs,
            batches,
            device_bytes: matrices
                + batches.per_piece as u64 * view_bytes
                + slabs.per_piece as u64 * slice_bytes,
            sampling,
        })
    }

    /// Whether the job is cut at all.
    pub fn is_split(&self) -> bool {
        self.slabs.is_split() || self.batches.is_split()
    }

    /// One line for the user: "backprojection in 4 slabs of 16 slices × 2 batches of
    /// 64 views" (", projections in textures" on the hardware path).
    pub fn describe(&self) -> String {
        let textures = match self.sampling {
            Sampling::Exact => "",
            Sampling::Hardware => ", projections in textures",
        };
        format!(
            "backprojection in {} of {} × {} of {}{textures}",
            count_of(self.slabs.count(), "slab"),
            count_of(self.slabs.per_piece, "slice"),
            count_of(self.batches.count(), "batch"),
            count_of(self.batches.per_piece, "view"),
        )
        .replace("batchs", "batches")
    }
}

/// Backprojects filtered projections onto `grid` on the GPU (f32); the same sum as
/// `cpu::fbp::backproject`, in the pieces of [`BackprojectionPlan::new`] under the
/// context's limits.
///
/// # Errors
/// An invalid geometry or projections that do not fit it; [`Error::TooLarge`] as
/// [`BackprojectionPlan::new`]; [`Error::Gpu`] on device failure.
pub fn backproject(
    ctx: &GpuContext,
    filtered: &Projections<f32>,
    g: &Geometry,
    grid: &Grid,
) -> Result<Reconstruction<f32>> {
    backproject_planned(
        ctx,
        filtered,
        g,
        grid,
        &BackprojectionPlan::new(&ctx.limits, g, grid)?,
    )
}

/// [`backproject`] in the pieces of `plan` (a plan under lower limits than the
/// context's splits the job further).
///
/// # Errors
/// As [`backproject`]; [`Error::Invalid`] for a plan made for another job.
pub fn backproject_planned(
    ctx: &GpuContext,
    filtered: &Projections<f32>,
    g: &Geometry,
    grid: &Grid,
    plan: &BackprojectionPlan,
) -> Result<Reconstruction<f32>> {
    backproject_timed(ctx, filtered, g, grid, plan).map(|(r, _)| r)
}

/// Where the time of a GPU backprojection went.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BackprojectionTimings {
    /// Compute dispatches recorded: per slab, one per 32 views of each batch.
    pub dispatches: usize,
    /// Submissions waited for: one per slab and batch.
    pub submissions: usize,
    /// The dispatches' time on the device, summed over the submissions, from timestamp
    /// queries; `None` where the adapter has none.
    pub kernel: Option<f64>,
}

/// [`backproject_planned`], also saying how many dispatches and submissions it took and
/// how long the dispatches ran on the device. Each slab and batch is one submission:
/// one compute pass holding its dispatches (the device orders them and makes each one's
/// sums visible to the next), between two timestamps.
///
/// # Errors
/// As [`backproject_planned`].
pub fn backproject_timed(
    ctx: &GpuContext,
    filtered: &Projections<f32>,
    g: &Geometry,
    grid: &Grid,
    plan: &BackprojectionPlan,
) -> Result<(Reconstruction<f32>, BackprojectionTimings)> {
    g.validate()?;
    filtered.check_against(g)?;
    let n = check_dims(grid.dims)?;
    if plan.slabs.total != grid.dims[2] || plan.batches.total != g.n_angles() {
        return Err(Error::invalid(
            "backprojection plan",
            format!(
                "made for {} slices and {} views, not {} and {}",
                plan.slabs.total,
                plan.batches.total,
                grid.dims[2],
                g.n_angles()
            ),
        ));
    }
    let sampling = plan.sampling;
    ctx.require_filtering(sampling, wgpu::TextureFormat::R32Float)?;
    let limit = binding_limit(&ctx.limits);
    let batch_bytes = (plan.batches.per_piece * view_texels(sampling, g) * 4) as u64;
    let slab_bytes = (plan.slabs.per_piece * grid.dims[0] * grid.dims[1] * 4) as u64;
    if batch_bytes.max(slab_bytes) > limit {
        return Err(Error::too_large(
            "backprojection plan",
            format!(
                "a batch of {batch_bytes} bytes or a slab of {slab_bytes} bytes exceeds the \
                 storage-binding limit of {limit} bytes: use BackprojectionPlan::new"
            ),
        ));
    }
    let dev = &ctx.device;
    let views = g.view_matrices::<f32>();
    let vbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("fbp views"),
        contents: bytemuck::cast_slice(&views),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let per_view = g.rows * g.cols;
    let upload = |views: std::ops::Range<usize>| -> Result<Held> {
        let data = &filtered.data[views.start * per_view..views.end * per_view];
        Ok(match sampling {
            Sampling::Exact => {
                Held::Buffer(dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("fbp projections"),
                    contents: bytemuck::cast_slice(data),
                    usage: wgpu::BufferUsages::STORAGE,
                }))
            }
            Sampling::Hardware => {
                let tex = ctx.texture_layers(
                    "GPU filtered projections texture",
                    wgpu::TextureFormat::R32Float,
                    [g.cols + 2, g.rows + 2, views.len()],
                )?;
                // Inside the zero border, a dispatch's worth of views per write.
                for (i, run) in data.chunks(VIEWS_PER_DISPATCH * per_view).enumerate() {
                    let n = run.len() / per_view;
                    ctx.write_layers(
                        &tex,
                        [1, 1, i * VIEWS_PER_DISPATCH],
                        [g.cols, g.rows, n],
                        run,
                    );
                }
                Held::Texture(tex.create_view(&wgpu::TextureViewDescriptor {
                    dimension: Some(wgpu::TextureViewDimension::D2Array),
                    ..Default::default()
                }))
            }
        })
    };
    // One batch stays on the device for every slab; several are sent again per slab.
    let resident = if plan.batches.is_split() {
        None
    } else {
        Some(upload(0..g.n_angles())?)
    };
    let sampler = (sampling == Sampling::Hardware)
        .then(|| ctx.clamp_sampler("fbp projections", wgpu::FilterMode::Linear));
    let [nx, ny, _] = grid.dims;
    let slice = nx * ny;
    let Kernel { layout, pipeline } = ctx.kernel(
        "fbp_backproject.wgsl",
        &sampled_shader_source(sampling),
        None,
        "backproject_point",
    )?;
    let a = grid.affine;
    let v4 = |v: glam::DVec3| [v.x as f32, v.y as f32, v.z as f32, 0.0];
    let scale = backprojection_scale(g.n_angles()) as f32;
    let query = ctx.timestamps();
    let mut timings = BackprojectionTimings {
        dispatches: 0,
        submissions: 0,
        kernel: query.as_ref().map(|_| 0.0),
    };
    let mut data = vec![0f32; n];
    for slab in plan.slabs.ranges() {
        let voxels = slab.len() * slice;
        let invocations = slab.len().div_ceil(VOXELS_PER_INVOCATION) * slice;
        let groups = (invocations as u32).div_ceil(WORKGROUP).max(1);
        let gx = groups.min(ctx.limits.max_compute_workgroups_per_dimension.max(1));
        let gy = groups.div_ceil(gx);
        // A new buffer per slab: wgpu hands it out zeroed.
        let out = ctx.storage_buffer("fbp volume slab", (voxels * 4) as u64)?;
        for batch in plan.batches.ranges() {
            let sent;
            let pbuf = match &resident {
                Some(b) => b,
                None => {
                    sent = upload(batch.clone())?;
                    &sent
                }
            };
            // The first view the projection buffer holds.
            let base = if resident.is_some() { 0 } else { batch.start };
            let binds: Vec<wgpu::BindGroup> = batch
                .clone()
                .step_by(VIEWS_PER_DISPATCH)
                .map(|start| {
                    let count = VIEWS_PER_DISPATCH.min(batch.end - start);
                    let params = FbpParams {
                        origin: v4(a.w_axis.truncate()),
                        step_i: v4(a.x_axis.truncate()),
                        step_j: v4(a.y_axis.truncate()),
                        step_k: v4(a.z_axis.truncate()),
                        dims: [nx as u32, ny as u32, slab.len() as u32, gx * WORKGROUP],
                        det: [g.cols as u32, g.rows as u32, start as u32, count as u32],
                        scale: [scale, 0.0, 0.0, 0.0],
                        slab: [slab.start as u32, base as u32, 0, 0],
                    };
                    let ubuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                        label: Some("fbp params"),
                        contents: bytemuck::bytes_of(&params),
                        usage: super::context::PARAMS_USAGE,
                    });
                    let mut entries = vec![
                        ubuf.as_entire_binding(),
                        vbuf.as_entire_binding(),
                        pbuf.binding(),
                        out.as_entire_binding(),
                    ];
                    if let Some(s) = &sampler {
                        entries.push(wgpu::BindingResource::Sampler(s));
                    }
                    ctx.bind_group("fbp", &layout, &entries)
                })
                .collect();
            let pass = (&pipeline, "backproject_point");
            let device = ctx.run_pass(pass, &binds, [gx, gy, 1], query.as_ref())?;
            timings.dispatches += binds.len();
            timings.submissions += 1;
            if let (Some(d), Some(k)) = (device, timings.kernel.as_mut()) {
                *k += d;
            }
        }
        let bytes = ctx.read_buffer(&out, (voxels * 4) as u64)?;
        data[slab.start * slice..slab.end * slice]
            .copy_from_slice(&bytemuck::pod_collect_to_vec::<u8, f32>(&bytes));
    }
    Ok((Reconstruction { grid: *grid, data }, timings))
}

/// FBP/FDK on the GPU in f32: [`crate::gpu::ramp::filter_projections`], then
/// [`backproject`]; the same reconstruction as `cpu::fbp::fbp`.
pub fn fbp(
    ctx: &GpuContext,
    projections: &Projections<f32>,
    g: &Geometry,
    filter: RampFilter,
    grid: &Grid,
) -> Result<Reconstruction<f32>> {
    let q = crate::gpu::ramp::filter_projections(ctx, projections, g, filter)?;
    backproject(ctx, &q, g, grid)
}
