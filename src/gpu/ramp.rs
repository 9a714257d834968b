//! Ramp filtering of CT projections on the GPU: the same filter as
//! [`crate::cpu::ramp::filter_projections`] (scikit-image's construction, FDK cosine
//! pre-weighting, division by the isocentre spacing; the module docs there give the
//! formulas), in f32, with the batched power-of-two FFT of [`crate::gpu::fft`].
//!
//! # Pipeline
//! For each chunk of whole views (`shaders/ramp_filter.wgsl`):
//! 1. `ramp_pad`: two detector lines share one complex line of the padded length
//!    `P = `[`padded_length`]`(cols)` (a power of two), `z = a + i·b`, each sample
//!    multiplied by the cosine weight for a cone beam ([`preweighted_sample`]), zeros
//!    past `cols`; for a geometry given view by view by each view's
//!    [`RampView::weight`] (cosine weight and `1/spacing`, from a table of
//!    [`RampViewGpu`]);
//! 2. a batch of forward FFTs of length `P` ([`GpuFftPlan::lines`], Stockham);
//! 3. `ramp_multiply`: times the even real response [`effective_response`] scaled by
//!    `1/(P·spacing)` (a real even filter acts on the real and imaginary parts
//!    separately, so the two packed lines do not mix);
//! 4. a batch of inverse FFTs (no scaling: `1/P` is in the response);
//! 5. `ramp_crop`: the first `cols` values, real part for the even line, imaginary
//!    part for the odd one.
//!
//! Everything between the upload of a chunk and the readback of its filtered lines
//! stays on the device, in one submission. Chunks keep the packed array within one
//! storage binding (`max_storage_buffer_binding_size`, 128 MiB on lavapipe).
//!
//! Accuracy against the f64 oracle ([`FilterMethod::Direct`](crate::cpu::ramp::FilterMethod)):
//! `tests/gpu_ct_fbp.rs`.

use crate::cpu::dft::{Direction, Normalization};
use crate::cpu::ramp::{
    cosine_weight, effective_response, isocentre_spacing, padded_length, ramp_views, RampFilter,
    RampView,
};
use crate::ct::{Beam, Geometry, Projections};
use crate::error::{Error, Result};
use crate::gpu::fft::{GpuFftPlan, GpuFftVariant};
use crate::gpu::GpuContext;
use wgpu::util::DeviceExt;

/// How [`filter_projections`] cuts the views into chunks whose packed lines fit one
/// storage binding of the planner's limits ([`crate::gpu::plan`]). Each line is
/// filtered alone, so chunking never changes a value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RampPlan {
    /// Views per chunk (the last may hold fewer).
    pub views_per_chunk: usize,
    /// The device bytes of one chunk: its lines, their packed complex lines and the
    /// response.
    pub device_bytes: u64,
}

impl RampPlan {
    /// The chunks for `g` under `limits`: all views, halved until the packed lines of
    /// a chunk fit one binding.
    ///
    /// # Errors
    /// [`Error::TooLarge`] when one view's padded lines alone exceed a binding.
    pub fn new(limits: &wgpu::Limits, g: &Geometry) -> Result<Self> {
        let (cols, rows, views) = (g.cols, g.rows, g.n_angles().max(1));
        let pl = padded_length(cols);
        let limit = crate::gpu::plan::binding_limit(limits);
        // Packed bytes of `v` views: ⌈v·rows/2⌉ complex lines of P values of 8 bytes.
        let packed_bytes = |v: usize| ((v * rows).div_ceil(2) * pl * 8) as u64;
        if packed_bytes(1) > limit {
            return Err(Error::too_large(
                "GPU ramp filter",
                format!(
                    "one view's padded lines ({} bytes) exceed one storage binding ({limit} bytes)",
                    packed_bytes(1)
                ),
            ));
        }
        let mut per_chunk = views;
        while packed_bytes(per_chunk) > limit {
            per_chunk = per_chunk.div_ceil(2);
        }
        Ok(RampPlan {
            views_per_chunk: per_chunk,
            device_bytes: packed_bytes(per_chunk)
                + (per_chunk * rows * cols * 4) as u64
                + (pl * 4) as u64,
        })
    }

    /// The number of chunks for `views` views.
    pub fn chunks(&self, views: usize) -> usize {
        views.div_ceil(self.views_per_chunk).max(1)
    }
}

/// The shader's uniform block.
///
/// mirrors shaders/shared/ramp_params.wgsl: RampParams
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct RampParams {
    /// Detector columns, rows, padded length `P`, detector lines in the chunk.
    pub dims: [u32; 4],
    /// Complex lines in the chunk, invocations per row of workgroups, the weighting
    /// (0 none, 1 circular cone beam, 2 per view from the table), the chunk's first
    /// view.
    pub work: [u32; 4],
    /// `cu`, `cv` (pixels), `du`, `dv` (mm).
    pub detector: [f32; 4],
    /// SDD (mm) for a cone beam.
    pub cone: [f32; 4],
}

/// One view's [`RampView`] in f32 for upload: `[r, sdd]`, `[u, 1/spacing]`, `[v, 0]`.
///
/// mirrors shaders/shared/ramp_params.wgsl: RampViewGpu
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct RampViewGpu {
    pub r: [f32; 4],
    pub u: [f32; 4],
    pub v: [f32; 4],
}

impl RampViewGpu {
    /// The view rounded to f32.
    pub fn new(v: &RampView) -> Self {
        let f = |x: glam::DVec3, w: f64| [x.x as f32, x.y as f32, x.z as f32, w as f32];
        RampViewGpu {
            r: f(v.r, v.sdd),
            u: f(v.u, v.scale),
            v: f(v.v, 0.0),
        }
    }

    /// [`RampView::weight`] in f32.
    ///
    /// mirrors shaders/ramp_filter.wgsl: view_weight
    pub fn weight(&self, col: f32, row: f32) -> f32 {
        if self.r[3] == 0.0 {
            return self.u[3];
        }
        let x: [f32; 3] = std::array::from_fn(|i| self.r[i] + self.u[i] * col + self.v[i] * row);
        self.u[3] * self.r[3] / (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt()
    }
}

/// `shaders/shared/ramp_params.wgsl`: the WGSL twin of [`RampParams`].
pub const PARAMS_WGSL: &str = super::shaders::RAMP_PARAMS;

const WORKGROUP: u32 = 64;

/// The shader source: `shaders/ramp_filter.wgsl` (three entry points) and its imports.
pub fn shader_source() -> String {
    super::shaders::resolve("ramp_filter")
}

/// Detector line `line` (view-major, then row; `data` holds the chunk) at column `c`,
/// cosine-weighted for a cone beam, zero past the chunk's last line.
///
/// mirrors shaders/ramp_filter.wgsl: preweighted_sample
/// `views` holds every view's [`RampViewGpu`] for a geometry given view by view
/// (then `line` counts from view 0).
pub fn preweighted_sample(
    data: &[f32],
    g: &Geometry,
    views: Option<&[RampViewGpu]>,
    line: usize,
    c: usize,
) -> f32 {
    let Some(&x) = data.get(line * g.cols + c) else {
        return 0.0;
    };
    if let Some(v) = views {
        return x * v[line / g.rows].weight(c as f32, (line % g.rows) as f32);
    }
    match g.beam {
        Beam::Parallel => x,
        Beam::Cone { sdd, .. } => {
            let u = (c as f32 - g.cu as f32) * g.du as f32;
            let v = ((line % g.rows) as f32 - g.cv as f32) * g.dv as f32;
            x * cosine_weight(sdd, u as f64, v as f64) as f32
        }
    }
}

/// Filters every detector row of `projections` (shaped for `g`) with `filter` on the
/// GPU, in f32: the semantics of [`crate::cpu::ramp::filter_projections`].
///
/// # Errors
/// [`Error::Invalid`] for an invalid geometry, a stack that does not match it, or
/// non-finite values; [`Error::TooLarge`] when one view's padded lines exceed one
/// storage binding; [`Error::Gpu`] when the device fails.
pub fn filter_projections(
    ctx: &GpuContext,
    projections: &Projections<f32>,
    g: &Geometry,
    filter: RampFilter,
) -> Result<Projections<f32>> {
    g.validate()?;
    projections.check_against(g)?;
    if projections.data.iter().any(|v| !v.is_finite()) {
        return Err(Error::invalid(
            "projections",
            "contain NaN or infinite values",
        ));
    }
    let (cols, rows) = (g.cols, g.rows);
    let pl = padded_length(cols);
    let mut out = projections.data.clone();
    if out.is_empty() {
        return Projections::new(projections.angles, rows, cols, out);
    }
    let per_chunk = RampPlan::new(&ctx.limits, g)?.views_per_chunk;

    let per_view = ramp_views(g)?;
    // Views given by vectors carry their own 1/spacing in their weights.
    let inv_spacing = if per_view.is_some() {
        1.0
    } else {
        1.0 / isocentre_spacing(g)
    };
    let table: Vec<RampViewGpu> = match &per_view {
        Some(v) => v.iter().map(RampViewGpu::new).collect(),
        None => vec![RampViewGpu::default()],
    };
    let resp: Vec<f32> = effective_response(pl, filter)
        .iter()
        .map(|&v| (v * inv_spacing / pl as f64) as f32)
        .collect();
    let dev = &ctx.device;
    let rbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("ramp response"),
        contents: bytemuck::cast_slice(&resp),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let vbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("ramp views"),
        contents: bytemuck::cast_slice(&table),
        usage: wgpu::BufferUsages::STORAGE,
    });
    // One explicit layout for the three entry points (each uses only some bindings).
    let entry = super::context::buffer_entry;
    let storage = |read_only| wgpu::BufferBindingType::Storage { read_only };
    let program = ctx.program(
        "ramp_filter.wgsl",
        &shader_source(),
        Some(&[
            entry(0, wgpu::BufferBindingType::Uniform),
            entry(1, storage(false)),
            entry(2, storage(false)),
            entry(3, storage(true)),
            entry(4, storage(true)),
        ]),
    )?;
    let stages = [
        program.kernel(ctx, "ramp_pad")?.0,
        program.kernel(ctx, "ramp_multiply")?.0,
        program.kernel(ctx, "ramp_crop")?.0,
    ];
    let (cone, sdd) = match g.beam {
        _ if per_view.is_some() => (2, 0.0),
        Beam::Parallel => (0, 0.0),
        Beam::Cone { sdd, .. } => (1, sdd as f32),
    };
    let line_len = rows * cols;
    let mut plans: Option<(usize, GpuFftPlan, GpuFftPlan)> = None;
    for (index, chunk) in out.chunks_mut(per_chunk * line_len).enumerate() {
        let n_lines = chunk.len() / cols;
        let pairs = n_lines.div_ceil(2);
        if plans.as_ref().map(|p| p.0) != Some(pairs) {
            let (none, variant) = (Normalization::None, GpuFftVariant::Stockham);
            plans = Some((
                pairs,
                GpuFftPlan::lines(ctx, pairs, pl, Direction::Forward, none, variant)?,
                GpuFftPlan::lines(ctx, pairs, pl, Direction::Inverse, none, variant)?,
            ));
        }
        let (_, fwd, inv) = plans.as_ref().expect("plans were just made");
        let lbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("ramp lines"),
            contents: bytemuck::cast_slice(chunk),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        });
        let packed = ctx.storage_buffer("ramp packed lines", (pairs * pl * 8) as u64)?;
        let invocations = (pairs * pl).max(n_lines * cols) as u32;
        let groups = invocations.div_ceil(WORKGROUP).max(1);
        let gx = groups.min(ctx.limits.max_compute_workgroups_per_dimension.max(1));
        let gy = groups.div_ceil(gx);
        let params = RampParams {
            dims: [cols as u32, rows as u32, pl as u32, n_lines as u32],
            work: [
                pairs as u32,
                gx * WORKGROUP,
                cone,
                (index * per_chunk) as u32,
            ],
            detector: [g.cu as f32, g.cv as f32, g.du as f32, g.dv as f32],
            cone: [sdd, 0.0, 0.0, 0.0],
        };
        let ubuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("ramp params"),
            contents: bytemuck::bytes_of(&params),
            usage: super::context::PARAMS_USAGE,
        });
        let mut enc = dev.create_command_encoder(&Default::default());
        let run = |enc: &mut wgpu::CommandEncoder, stage: usize, z: &wgpu::Buffer| {
            let p = &stages[stage];
            let bind = ctx.bind_group(
                "ramp",
                &p.layout,
                &[
                    ubuf.as_entire_binding(),
                    lbuf.as_entire_binding(),
                    z.as_entire_binding(),
                    rbuf.as_entire_binding(),
                    vbuf.as_entire_binding(),
                ],
            );
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("ramp"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&p.pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(gx, gy, 1);
        };
        run(&mut enc, 0, &packed);
        let spectrum = fwd.encode_in_place(ctx, &mut enc, &packed);
        run(&mut enc, 1, spectrum);
        let filtered = inv.encode_in_place(ctx, &mut enc, spectrum);
        run(&mut enc, 2, filtered);
        ctx.queue.submit([enc.finish()]);
        ctx.wait()?;
        let bytes = ctx.read_buffer(&lbuf, (chunk.len() * 4) as u64)?;
        chunk.copy_from_slice(bytemuck::cast_slice(&bytes));
    }
    Projections::new(projections.angles, rows, cols, out)
}
