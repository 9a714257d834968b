//! Volume processing on the GPU: the port of [`crate::cpu::process`] — resampling,
//! Gaussian smoothing, median filtering and the gradient-magnitude field.
//!
//! The input is uploaded once as an f32 storage buffer; each operation runs one compute
//! shader (`shaders/process_*.wgsl`, importing `shaders/shared/process_params.wgsl`;
//! resampling's kernels are `shaders/shared/filters.wgsl`, the ray caster's), one
//! invocation per output voxel, and reads the result back. The work is
//! split into several dispatches of at most [`WORK_PER_DISPATCH`] kernel taps each,
//! each submitted and waited for, so that no single dispatch runs long on a software
//! rasteriser (lavapipe can lose the device past ~10 s). Each operation compiles its
//! pipeline once per call (not per slab); where the adapter has timestamp queries each
//! dispatch is timed on the device, and the `*_planned` functions return the sum
//! ([`ProcessTimings`]).
//!
//! What runs where:
//! - resampling: `shaders/process_resample.wgsl` ports `cpu::filter::axis_taps` and
//!   `apply_taps` as loops over a storage buffer (the ray caster's generated
//!   `accumulate_taps` reads a texture and the ray caster's parameters, so it is not
//!   shared); nearest, trilinear, cubic B-spline, interpolating B-spline (its
//!   coefficients are solved on the host in f64, `cpu::filter::prepare`, then rounded),
//!   Catmull–Rom, Lanczos-2/3/4; the full sinc is CPU-only (a clear error here);
//! - Gaussian: three separable passes (x, y, z) ping-ponging two buffers, weights from
//!   the host in f64 rounded to f32;
//! - median: windows up to `k = 5` (125 values per voxel, held in registers);
//! - gradient magnitude: the clamped central differences and `L⁻ᵀ`.
//!
//! Gaussian smoothing, the median and the gradient magnitude split a volume past one
//! storage binding of the planner's limits ([`crate::gpu::plan`]; 128 MiB = 32 Mi
//! voxels on lavapipe) into z-slabs ([`ProcessPlan`]), each read with the filter's
//! radius of ghost slices on either side, so that every output voxel sees the very
//! values it sees unsplit: a split result equals the unsplit one bit for bit.
//! Resampling splits its output into z-slabs ([`ResamplePlan`]), each read from the run
//! of input slices its taps reach (found from the output slab's corners through the
//! output → input map, widened by the filter's reach and one slice for the shader's
//! f32 rounding); the shader keeps the unsplit map and only offsets the slices it
//! indexes, so a split result equals the unsplit one bit for bit too.

use super::context::{GpuContext, TimestampPair};
use super::plan::{binding_limit, count_of, Pieces};
use crate::cpu::filter::prepare;
use crate::cpu::grid::Grid;
use crate::cpu::process::{
    check_median_size, check_sigma, gaussian_weights, resample_plan, world_gradient_matrix, Field,
    ResampleSpec,
};
use crate::error::{Error, Result};
use crate::settings::Filter;
use crate::volume::Volume;
use glam::{DMat4, DVec4};
use std::ops::Range;
use wgpu::util::DeviceExt;

/// `shaders/shared/process_params.wgsl`: the WGSL twin of [`ProcessParams`] and the
/// bindings and helpers every processing shader shares.
pub const PARAMS_WGSL: &str = super::shaders::PROCESS_PARAMS;

/// The processing shaders (`shaders/<name>.wgsl`), one per operation.
pub const SHADERS: [&str; 4] = [
    "process_resample",
    "process_gaussian",
    "process_median",
    "process_gradient",
];

/// The largest median window side on the GPU (`5³ = 125` values per voxel).
pub const MAX_MEDIAN_SIZE_GPU: usize = 5;

/// The most kernel taps (voxel reads) one dispatch may perform.
pub const WORK_PER_DISPATCH: u64 = 1 << 26;

/// Invocations per workgroup (`WORKGROUP` in `shaders/shared/process_params.wgsl`).
const WORKGROUP: u64 = 64;

/// Parameters of one processing dispatch, shared with
/// `shaders/shared/process_params.wgsl: ProcessParams` (96 bytes, six 16-byte vectors;
/// `tests/gpu_layout.rs` checks the layout).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ProcessParams {
    /// Input grid nx, ny, nz, and the first of its slices the input buffer holds.
    pub in_dims: [u32; 4],
    /// Output grid nx, ny, nz, and the first output voxel of this dispatch.
    pub out_dims: [u32; 4],
    /// Filter code or window side; radius; axis (Gaussian) or the first output voxel
    /// the output buffer holds (resampling); voxels in this dispatch.
    pub op: [u32; 4],
    /// Rows of the output → input index map, or of `L⁻ᵀ`.
    pub m0: [f32; 4],
    pub m1: [f32; 4],
    pub m2: [f32; 4],
}

/// The complete WGSL module of one operation (`name` is one of [`SHADERS`]).
pub fn shader_source(name: &str) -> String {
    super::shaders::resolve(name)
}

fn u32_dims(d: [usize; 3]) -> [u32; 4] {
    [d[0] as u32, d[1] as u32, d[2] as u32, 0]
}

fn rows(m: DMat4) -> [[f32; 4]; 3] {
    [0, 1, 2].map(|r| m.row(r).to_array().map(|x| x as f32))
}

/// Checks that `voxels` f32 values fit one storage binding.
fn check_binding(ctx: &GpuContext, what: &str, voxels: usize) -> Result<u64> {
    let bytes = (voxels as u64).saturating_mul(4);
    let limit = crate::gpu::plan::binding_limit(&ctx.limits);
    if bytes > limit {
        return Err(Error::too_large(
            what,
            format!(
                "{voxels} f32 voxels ({bytes} bytes) exceed the adapter's storage-binding \
                 limit of {limit} bytes: use --backend cpu or a smaller volume"
            ),
        ));
    }
    Ok(bytes)
}

fn upload(ctx: &GpuContext, label: &str, data: &[f32]) -> Result<wgpu::Buffer> {
    check_binding(ctx, label, data.len())?;
    Ok(ctx
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytemuck::cast_slice(data),
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
        }))
}

/// What one processing call did on the device.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProcessTimings {
    /// The output slabs (1 when the volume is not split).
    pub slabs: usize,
    /// Dispatches, each submitted and waited for: per slab and per pass,
    /// [`dispatches`] of the pass's output voxels.
    pub dispatches: usize,
    /// Shader compilation and pipeline creation (wall clock, once per call).
    pub setup: f64,
    /// The dispatches alone on the device, summed, from timestamp queries; `None`
    /// where the adapter has none.
    pub kernel: Option<f64>,
}

impl ProcessTimings {
    fn new(ctx: &GpuContext) -> Self {
        ProcessTimings {
            kernel: ctx
                .features
                .contains(wgpu::Features::TIMESTAMP_QUERY)
                .then_some(0.0),
            ..Default::default()
        }
    }

    fn add_dispatch(&mut self, kernel: Option<f64>) {
        self.dispatches += 1;
        if let (Some(total), Some(k)) = (self.kernel.as_mut(), kernel) {
            *total += k;
        }
    }
}

/// The dispatches a processing pass splits `voxels` output voxels of `taps` kernel taps
/// each into: at most [`WORK_PER_DISPATCH`] taps per dispatch, and between one
/// workgroup and 2²⁴ voxels.
pub fn dispatches(voxels: u64, taps: u64) -> usize {
    voxels.div_ceil(voxels_per_dispatch(taps)) as usize
}

fn voxels_per_dispatch(taps: u64) -> u64 {
    (WORK_PER_DISPATCH / taps.max(1)).clamp(WORKGROUP, 1 << 24)
}

/// One compiled operation.
struct Op {
    kernel: super::context::Kernel,
    params: wgpu::Buffer,
    query: Option<TimestampPair>,
}

impl Op {
    /// `entry` of `shaders/<name>.wgsl`, from the device's kept programs (compiled
    /// when no call before compiled it), adding the time to `t.setup`.
    fn new(ctx: &GpuContext, name: &str, entry: &str, t: &mut ProcessTimings) -> Result<Self> {
        let start = std::time::Instant::now();
        let kernel = ctx.kernel(&format!("{name}.wgsl"), &shader_source(name), None, entry)?;
        let params = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("process params"),
            size: std::mem::size_of::<ProcessParams>() as u64,
            usage: super::context::PARAMS_USAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        t.setup += start.elapsed().as_secs_f64();
        Ok(Op {
            kernel,
            params,
            query: ctx.timestamps(),
        })
    }

    /// Runs over every output voxel of `base.out_dims`, in dispatches of at most
    /// [`WORK_PER_DISPATCH`] taps (`taps` per voxel), each waited for and counted in
    /// `t`.
    fn run(
        &self,
        ctx: &GpuContext,
        base: ProcessParams,
        (src, dst, extra): (&wgpu::Buffer, &wgpu::Buffer, Option<&wgpu::Buffer>),
        taps: u64,
        t: &mut ProcessTimings,
    ) -> Result<()> {
        let [nx, ny, nz, _] = base.out_dims.map(|x| x as u64);
        self.run_range(ctx, base, (src, dst, extra), (taps, 0..nx * ny * nz), t)
    }

    /// [`Self::run`] over the output voxels `voxels` (linear indices) alone.
    fn run_range(
        &self,
        ctx: &GpuContext,
        base: ProcessParams,
        (src, dst, extra): (&wgpu::Buffer, &wgpu::Buffer, Option<&wgpu::Buffer>),
        (taps, voxels): (u64, Range<u64>),
        t: &mut ProcessTimings,
    ) -> Result<()> {
        let total = voxels.end;
        let per = voxels_per_dispatch(taps);
        let mut resources = vec![
            self.params.as_entire_binding(),
            src.as_entire_binding(),
            dst.as_entire_binding(),
        ];
        if let Some(e) = extra {
            resources.push(e.as_entire_binding());
        }
        let bind = ctx.bind_group("process", &self.kernel.layout, &resources);
        let max_x = ctx.limits.max_compute_workgroups_per_dimension.max(1) as u64;
        let mut first = voxels.start;
        while first < total {
            let count = per.min(total - first);
            let mut p = base;
            p.out_dims[3] = first as u32;
            p.op[3] = count as u32;
            ctx.queue
                .write_buffer(&self.params, 0, bytemuck::bytes_of(&p));
            let groups = count.div_ceil(WORKGROUP);
            let x = groups.min(max_x);
            let y = groups.div_ceil(x);
            let kernel = ctx.run_pass(
                (&self.kernel.pipeline, "process"),
                std::slice::from_ref(&bind),
                [x as u32, y as u32, 1],
                self.query.as_ref(),
            )?;
            t.add_dispatch(kernel);
            first += count;
        }
        Ok(())
    }
}

fn read_f32(ctx: &GpuContext, buf: &wgpu::Buffer, n: usize) -> Result<Vec<f32>> {
    let bytes = ctx.read_buffer(buf, (n * 4) as u64)?;
    Ok(bytemuck::cast_slice(&bytes).to_vec())
}

fn field(dims: [usize; 3], data: Vec<f32>, affine: DMat4) -> Field<f32> {
    Field {
        grid: Grid { dims, data },
        affine,
    }
}

/// The filter code of `shaders/process_resample.wgsl` and the taps per voxel.
fn filter_code(filter: Filter) -> Result<(u32, u32, u64)> {
    // The fast B-splines resample with their kernels' exact 64-tap sums.
    Ok(match filter.exact() {
        Filter::Nearest => (0, 0, 1),
        Filter::Trilinear => (1, 1, 8),
        Filter::Bspline | Filter::BsplineInterp => (2, 2, 64),
        Filter::CatmullRom => (3, 2, 64),
        Filter::Lanczos2 | Filter::Lanczos3 | Filter::Lanczos4 => {
            let n = filter.radius() as u32;
            (4, n, 8 * (n as u64).pow(3))
        }
        Filter::BsplineFast | Filter::BsplineFastInterp => unreachable!("exact() maps them"),
        Filter::Sinc => {
            return Err(Error::invalid(
                "resampling filter",
                "the full sinc runs on the CPU only (use --backend cpu, or lanczos4 on the GPU)",
            ))
        }
    })
}

/// How [`resample`] fits the planner's limits (module docs): the output in z-slabs,
/// each read from its run of input slices.
#[derive(Clone, Debug, PartialEq)]
pub struct ResamplePlan {
    /// Output slices per slab.
    pub slabs: Pieces,
    /// The input slices each slab reads (all of them when the job is not split).
    pub inputs: Vec<Range<usize>>,
}

impl ResamplePlan {
    /// The plan for resampling `vol` as `spec` asks, under `limits` ([`Self::new`]
    /// with the output → input map of [`resample_plan`]).
    ///
    /// # Errors
    /// As [`resample_plan`] and [`Self::new`].
    pub fn for_volume(
        limits: &wgpu::Limits,
        vol: &Volume<f32>,
        spec: &ResampleSpec,
    ) -> Result<Self> {
        let (to_in, _) = resample_plan(vol.dims(), vol.affine(), spec)?;
        Self::new(limits, vol.dims(), to_in, spec.dims, spec.filter)
    }

    /// The plan for resampling a volume of `in_dims` onto `out_dims` through the
    /// output-index → input-index map `to_in` with `filter`, under `limits`: one piece
    /// when the input and the output each fit a binding; else the most output slices
    /// per slab whose output and input slices both fit one.
    ///
    /// # Errors
    /// [`Error::Invalid`] for the full sinc; [`Error::TooLarge`] when one output slice
    /// or the input slices it reads exceed a binding.
    pub fn new(
        limits: &wgpu::Limits,
        in_dims: [usize; 3],
        to_in: DMat4,
        out_dims: [usize; 3],
        filter: Filter,
    ) -> Result<Self> {
        let (_, radius, _) = filter_code(filter)?;
        let limit = binding_limit(limits);
        let in_slice = (in_dims[0] * in_dims[1]) as u64 * 4;
        let out_slice = (out_dims[0] * out_dims[1]) as u64 * 4;
        let nz = out_dims[2];
        if in_slice * in_dims[2] as u64 <= limit && out_slice * nz as u64 <= limit {
            return Ok(ResamplePlan {
                slabs: Pieces {
                    total: nz,
                    per_piece: nz.max(1),
                },
                inputs: std::iter::once(0..in_dims[2]).collect(),
            });
        }
        let what = "GPU resampling";
        let fit_out = Pieces::plan(what, "output slice", nz, out_slice, limit, 1)?.per_piece;
        let fit_in = Pieces::plan(what, "input slice", in_dims[2], in_slice, limit, 1)?.per_piece;
        let inputs_for = |per: usize| input_runs(in_dims, to_in, out_dims, radius, per);
        let fits = |per: usize| inputs_for(per).iter().all(|r| r.len() <= fit_in);
        if !fits(1) {
            let need = inputs_for(1).iter().map(Range::len).max().unwrap_or(0);
            return Err(Error::too_large(
                what,
                format!(
                    "one output slice reads {need} input slices of {in_slice} bytes, more \
                     than the storage-binding limit of {limit} bytes: use --backend cpu"
                ),
            ));
        }
        // The most output slices per slab that fit (bisection: fewer slices never
        // read more input).
        let (mut lo, mut hi) = (1, fit_out.min(nz).max(1));
        while lo < hi {
            let mid = (lo + hi).div_ceil(2);
            if fits(mid) {
                lo = mid;
            } else {
                hi = mid - 1;
            }
        }
        Ok(ResamplePlan {
            slabs: Pieces {
                total: nz,
                per_piece: lo,
            },
            inputs: inputs_for(lo),
        })
    }

    /// The output in slabs of `per_piece` slices, each with the input slices its taps
    /// reach, whatever the limits (tests run every split with it).
    ///
    /// # Errors
    /// [`Error::Invalid`] for the full sinc.
    pub fn in_slabs(
        in_dims: [usize; 3],
        to_in: DMat4,
        out_dims: [usize; 3],
        filter: Filter,
        per_piece: usize,
    ) -> Result<Self> {
        let (_, radius, _) = filter_code(filter)?;
        let per_piece = per_piece.clamp(1, out_dims[2].max(1));
        Ok(ResamplePlan {
            slabs: Pieces {
                total: out_dims[2],
                per_piece,
            },
            inputs: input_runs(in_dims, to_in, out_dims, radius, per_piece),
        })
    }

    /// Whether the output is cut at all.
    pub fn is_split(&self) -> bool {
        self.slabs.is_split()
    }

    /// The most input slices one slab reads.
    pub fn largest_input(&self) -> usize {
        self.inputs.iter().map(Range::len).max().unwrap_or(0)
    }

    /// One line for the user: "resampling in 4 slabs of 16 slices (each reading at
    /// most 40 input slices)".
    pub fn describe(&self) -> String {
        format!(
            "resampling in {} of {} (each reading at most {})",
            count_of(self.slabs.count(), "slab"),
            count_of(self.slabs.per_piece, "slice"),
            count_of(self.largest_input(), "input slice")
        )
    }
}

/// The input slices of each slab of `per` output slices ([`input_slices`], the
/// filter's reach `radius` taps).
fn input_runs(
    in_dims: [usize; 3],
    to_in: DMat4,
    out_dims: [usize; 3],
    radius: u32,
    per: usize,
) -> Vec<Range<usize>> {
    let reach = (radius as usize).max(1);
    Pieces {
        total: out_dims[2],
        per_piece: per,
    }
    .ranges()
    .map(|r| input_slices(in_dims, to_in, out_dims, r, reach))
    .collect()
}

/// The input slices the taps of output slices `out_z` reach: the extremes of the input
/// z coordinate over the slab's corners (the map is affine), widened by `reach` taps
/// and one slice for the shader's f32 rounding, clamped into the volume as the taps are.
fn input_slices(
    in_dims: [usize; 3],
    to_in: DMat4,
    out_dims: [usize; 3],
    out_z: Range<usize>,
    reach: usize,
) -> Range<usize> {
    let mut zs = Vec::with_capacity(8);
    for x in [0, out_dims[0].max(1) - 1] {
        for y in [0, out_dims[1].max(1) - 1] {
            for z in [out_z.start, out_z.end.max(out_z.start + 1) - 1] {
                let p = to_in * DVec4::new(x as f64, y as f64, z as f64, 1.0);
                zs.push(p.z);
            }
        }
    }
    let lo = zs.iter().fold(f64::INFINITY, |m, &v| m.min(v));
    let hi = zs.iter().fold(f64::NEG_INFINITY, |m, &v| m.max(v));
    let last = in_dims[2] as f64 - 1.0;
    let first = (lo.floor() - reach as f64).clamp(0.0, last) as usize;
    let end = (hi.floor() + reach as f64 + 2.0).clamp(first as f64 + 1.0, last + 1.0) as usize;
    first..end
}

/// [`crate::cpu::process::resample`] on the GPU (f32), in the slabs of
/// [`ResamplePlan::new`] under the context's limits.
///
/// # Errors
/// As the CPU version; also [`Error::Invalid`] for the full sinc,
/// [`Error::TooLarge`] as [`ResamplePlan::new`], [`Error::Gpu`] on device failure.
pub fn resample(ctx: &GpuContext, vol: &Volume<f32>, spec: &ResampleSpec) -> Result<Field<f32>> {
    let plan = ResamplePlan::for_volume(&ctx.limits, vol, spec)?;
    Ok(resample_planned(ctx, vol, spec, &plan)?.0)
}

/// [`resample`] in the slabs of `plan`, with what it did on the device.
///
/// # Errors
/// As [`resample`]; [`Error::Invalid`] for a plan made for other output dimensions.
pub fn resample_planned(
    ctx: &GpuContext,
    vol: &Volume<f32>,
    spec: &ResampleSpec,
    plan: &ResamplePlan,
) -> Result<(Field<f32>, ProcessTimings)> {
    let (code, radius, taps) = filter_code(spec.filter)?;
    let (to_in, affine) = resample_plan(vol.dims(), vol.affine(), spec)?;
    if plan.slabs.total != spec.dims[2] || plan.inputs.len() != plan.slabs.count() {
        return Err(Error::invalid(
            "resampling plan",
            format!(
                "made for {} output slices, not {}",
                plan.slabs.total, spec.dims[2]
            ),
        ));
    }
    let n_out = spec.dims.iter().product::<usize>();
    if n_out > u32::MAX as usize {
        return Err(Error::too_large(
            "resampled volume",
            format!("{n_out} voxels exceed the shaders' 32-bit voxel index: use --backend cpu"),
        ));
    }
    let host: Vec<f32> = if spec.filter.prefiltered() {
        prepare(&Grid::<f64>::from_volume(vol), spec.filter)
            .data
            .iter()
            .map(|&x| x as f32)
            .collect()
    } else {
        vol.data().to_vec()
    };
    let [m0, m1, m2] = rows(to_in);
    let mut t = ProcessTimings::new(ctx);
    let op = Op::new(ctx, "process_resample", "resample", &mut t)?;
    let in_slice = vol.dims()[0] * vol.dims()[1];
    let out_slice = spec.dims[0] * spec.dims[1];
    let mut data = Vec::with_capacity(n_out);
    for (slab, input) in plan.slabs.ranges().zip(&plan.inputs) {
        let src = upload(
            ctx,
            "volume",
            &host[input.start * in_slice..input.end * in_slice],
        )?;
        let out = out_slice * slab.len();
        let dst = ctx.storage_buffer(
            "resampled volume",
            check_binding(ctx, "resampled volume", out)?,
        )?;
        let first = (slab.start * out_slice) as u64;
        let p = ProcessParams {
            in_dims: [
                vol.dims()[0] as u32,
                vol.dims()[1] as u32,
                vol.dims()[2] as u32,
                input.start as u32,
            ],
            out_dims: u32_dims(spec.dims),
            op: [code, radius, first as u32, 0],
            m0,
            m1,
            m2,
        };
        let voxels = first..first + out as u64;
        op.run_range(ctx, p, (&src, &dst, None), (taps, voxels), &mut t)?;
        data.extend(read_f32(ctx, &dst, out)?);
    }
    t.slabs = plan.slabs.count();
    Ok((field(spec.dims, data, affine), t))
}

/// [`crate::cpu::process::gaussian`] on the GPU (f32): three separable passes.
///
/// # Errors
/// As the CPU version; also [`Error::TooLarge`] past the storage-binding limit,
/// [`Error::Gpu`] on device failure.
fn gaussian_whole(
    ctx: &GpuContext,
    op: &Op,
    vol: &Volume<f32>,
    sigma: [f64; 3],
    t: &mut ProcessTimings,
) -> Result<Field<f32>> {
    let dims = vol.dims();
    let n = vol.len();
    let mut a = upload(ctx, "volume", vol.data())?;
    let mut b = ctx.storage_buffer("gaussian pass", check_binding(ctx, "volume", n)?)?;
    for (axis, &s) in sigma.iter().enumerate() {
        let w: Vec<f32> = gaussian_weights(s).iter().map(|&x| x as f32).collect();
        let wbuf = upload(ctx, "gaussian weights", &w)?;
        let p = ProcessParams {
            in_dims: u32_dims(dims),
            out_dims: u32_dims(dims),
            op: [0, (w.len() / 2) as u32, axis as u32, 0],
            ..Default::default()
        };
        op.run(ctx, p, (&a, &b, Some(&wbuf)), w.len() as u64, t)?;
        std::mem::swap(&mut a, &mut b);
    }
    Ok(field(dims, read_f32(ctx, &a, n)?, vol.affine()))
}

/// The GPU's median window: odd, from 1 to [`MAX_MEDIAN_SIZE_GPU`].
fn check_median_size_gpu(k: usize) -> Result<()> {
    check_median_size(k, MAX_MEDIAN_SIZE_GPU).map_err(|_| {
        Error::invalid(
            "median window size",
            format!(
                "{k}: on the GPU the window side must be odd, from 1 to {MAX_MEDIAN_SIZE_GPU} \
                 (125 values per voxel); use --backend cpu for larger windows"
            ),
        )
    })
}

/// [`crate::cpu::process::median`] on the GPU (f32), windows up to
/// [`MAX_MEDIAN_SIZE_GPU`] (checked by the caller).
///
/// # Errors
/// [`Error::TooLarge`] past the storage-binding limit; [`Error::Gpu`] on device failure.
fn median_whole(
    ctx: &GpuContext,
    op: &Op,
    vol: &Volume<f32>,
    k: usize,
    t: &mut ProcessTimings,
) -> Result<Field<f32>> {
    let dims = vol.dims();
    let n = vol.len();
    let src = upload(ctx, "volume", vol.data())?;
    let dst = ctx.storage_buffer("median", check_binding(ctx, "volume", n)?)?;
    let k3 = (k * k * k) as u64;
    let p = ProcessParams {
        in_dims: u32_dims(dims),
        out_dims: u32_dims(dims),
        op: [k as u32, 0, 0, 0],
        ..Default::default()
    };
    op.run(ctx, p, (&src, &dst, None), k3 * (k3 / 2 + 1), t)?;
    Ok(field(dims, read_f32(ctx, &dst, n)?, vol.affine()))
}

/// [`crate::cpu::process::gradient_magnitude`] on the GPU (f32).
///
/// # Errors
/// [`Error::TooLarge`] past the storage-binding limit; [`Error::Gpu`] on device failure.
fn gradient_magnitude_whole(
    ctx: &GpuContext,
    op: &Op,
    vol: &Volume<f32>,
    t: &mut ProcessTimings,
) -> Result<Field<f32>> {
    let dims = vol.dims();
    let n = vol.len();
    let src = upload(ctx, "volume", vol.data())?;
    let dst = ctx.storage_buffer("gradient magnitude", check_binding(ctx, "volume", n)?)?;
    let [m0, m1, m2] = rows(DMat4::from_mat3(world_gradient_matrix(vol.affine())));
    let p = ProcessParams {
        in_dims: u32_dims(dims),
        out_dims: u32_dims(dims),
        op: [0; 4],
        m0,
        m1,
        m2,
    };
    op.run(ctx, p, (&src, &dst, None), 7, t)?;
    Ok(field(dims, read_f32(ctx, &dst, n)?, vol.affine()))
}

/// How a neighbourhood operation (Gaussian, median, gradient magnitude) is cut to fit
/// the planner's limits: output z-slabs of `slabs.per_piece` slices, each computed from
/// an input slab with `ghost` more slices on either side (fewer at the volume's ends).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProcessPlan {
    /// Output slices per slab.
    pub slabs: Pieces,
    /// The slices read past a slab on either side: the operation's reach along z.
    pub ghost: usize,
}

impl ProcessPlan {
    /// The plan for a volume of `dims` whose operation reaches `ghost` slices along z.
    ///
    /// # Errors
    /// [`Error::TooLarge`] when one binding cannot hold one output slice and its
    /// `2·ghost` ghost slices.
    pub fn new(limits: &wgpu::Limits, dims: [usize; 3], ghost: usize) -> Result<Self> {
        let [nx, ny, nz] = dims;
        let limit = binding_limit(limits);
        let slice_bytes = (nx * ny) as u64 * 4;
        let fit = Pieces::plan(
            "GPU processing volume",
            "slice of the volume",
            nz,
            slice_bytes,
            limit,
            1,
        )?
        .per_piece;
        let per = if fit >= nz {
            nz
        } else if fit > 2 * ghost {
            fit - 2 * ghost
        } else {
            return Err(Error::too_large(
                "GPU processing volume",
                format!(
                    "a slab needs one slice and {} ghost slices of {slice_bytes} bytes, more \
                     than the storage-binding limit of {limit} bytes: use --backend cpu",
                    2 * ghost
                ),
            ));
        };
        Ok(ProcessPlan {
            slabs: Pieces {
                total: nz,
                per_piece: per.max(1),
            },
            ghost,
        })
    }

    /// The plan of [`gaussian`]: the z radius of the kernel.
    ///
    /// # Errors
    /// [`Error::Invalid`] for a σ [`check_sigma`] refuses; as [`ProcessPlan::new`].
    pub fn gaussian(limits: &wgpu::Limits, dims: [usize; 3], sigma: [f64; 3]) -> Result<Self> {
        check_sigma(sigma)?;
        Self::new(limits, dims, crate::cpu::process::gaussian_radius(sigma[2]))
    }

    /// The plan of [`median`]: half the window.
    ///
    /// # Errors
    /// [`Error::Invalid`] for an even `k` or `k` > [`MAX_MEDIAN_SIZE_GPU`]; as
    /// [`ProcessPlan::new`].
    pub fn median(limits: &wgpu::Limits, dims: [usize; 3], k: usize) -> Result<Self> {
        check_median_size_gpu(k)?;
        Self::new(limits, dims, k / 2)
    }

    /// The plan of [`gradient_magnitude`]: one neighbour.
    ///
    /// # Errors
    /// As [`ProcessPlan::new`].
    pub fn gradient_magnitude(limits: &wgpu::Limits, dims: [usize; 3]) -> Result<Self> {
        Self::new(limits, dims, 1)
    }

    /// Whether the volume is cut at all.
    pub fn is_split(&self) -> bool {
        self.slabs.is_split()
    }

    /// One line for the user: "processing in 4 slabs of 16 slices (3 ghost slices on
    /// either side)".
    pub fn describe(&self) -> String {
        format!(
            "processing in {} of {} ({} on either side)",
            count_of(self.slabs.count(), "slab"),
            count_of(self.slabs.per_piece, "slice"),
            count_of(self.ghost, "ghost slice")
        )
    }

    /// Compiles `(shader, entry)` once, runs `whole` with it on each input slab of
    /// `vol`, gathers the output slabs, and returns them with what it did.
    fn run(
        &self,
        ctx: &GpuContext,
        vol: &Volume<f32>,
        (shader, entry): (&str, &str),
        mut whole: impl FnMut(&Op, &Volume<f32>, &mut ProcessTimings) -> Result<Field<f32>>,
    ) -> Result<(Field<f32>, ProcessTimings)> {
        let mut t = ProcessTimings::new(ctx);
        let op = Op::new(ctx, shader, entry, &mut t)?;
        let f = self.run_slabs(vol, |v| whole(&op, v, &mut t))?;
        t.slabs = self.slabs.count();
        Ok((f, t))
    }

    /// Runs `op` on each input slab of `vol` and gathers the output slabs.
    fn run_slabs(
        &self,
        vol: &Volume<f32>,
        mut op: impl FnMut(&Volume<f32>) -> Result<Field<f32>>,
    ) -> Result<Field<f32>> {
        let [nx, ny, nz] = vol.dims();
        if self.slabs.total != nz {
            return Err(Error::invalid(
                "processing plan",
                format!("made for {} slices, not {nz}", self.slabs.total),
            ));
        }
        if !self.is_split() {
            return op(vol);
        }
        let slice = nx * ny;
        let mut data = vec![0f32; vol.len()];
        for slab in self.slabs.ranges() {
            let lo = slab.start.saturating_sub(self.ghost);
            let hi = (slab.end + self.ghost).min(nz);
            let part = Volume::with_affine(
                [nx, ny, hi - lo],
                vol.affine(),
                vol.data()[lo * slice..hi * slice].to_vec(),
            )?;
            let out = op(&part)?;
            let from = (slab.start - lo) * slice;
            data[slab.start * slice..slab.end * slice]
                .copy_from_slice(&out.grid.data[from..from + slab.len() * slice]);
        }
        Ok(field(vol.dims(), data, vol.affine()))
    }
}

/// [`crate::cpu::process::gaussian`] on the GPU (f32): three separable passes, in the
/// slabs of [`ProcessPlan::gaussian`] under the context's limits.
///
/// # Errors
/// As the CPU version; also [`Error::TooLarge`] as [`ProcessPlan::new`],
/// [`Error::Gpu`] on device failure.
pub fn gaussian(ctx: &GpuContext, vol: &Volume<f32>, sigma: [f64; 3]) -> Result<Field<f32>> {
    let plan = ProcessPlan::gaussian(&ctx.limits, vol.dims(), sigma)?;
    Ok(gaussian_planned(ctx, vol, sigma, &plan)?.0)
}

/// [`gaussian`] in the slabs of `plan`, with what it did on the device.
///
/// # Errors
/// As [`gaussian`].
pub fn gaussian_planned(
    ctx: &GpuContext,
    vol: &Volume<f32>,
    sigma: [f64; 3],
    plan: &ProcessPlan,
) -> Result<(Field<f32>, ProcessTimings)> {
    check_sigma(sigma)?;
    plan.run(
        ctx,
        vol,
        ("process_gaussian", "gaussian_pass"),
        |op, v, t| gaussian_whole(ctx, op, v, sigma, t),
    )
}

/// [`crate::cpu::process::median`] on the GPU (f32), windows up to
/// [`MAX_MEDIAN_SIZE_GPU`], in the slabs of [`ProcessPlan::median`].
///
/// # Errors
/// [`Error::Invalid`] for an even `k` or `k` > 5; [`Error::TooLarge`] as
/// [`ProcessPlan::new`]; [`Error::Gpu`] on device failure.
pub fn median(ctx: &GpuContext, vol: &Volume<f32>, k: usize) -> Result<Field<f32>> {
    let plan = ProcessPlan::median(&ctx.limits, vol.dims(), k)?;
    Ok(median_planned(ctx, vol, k, &plan)?.0)
}

/// [`median`] in the slabs of `plan`, with what it did on the device.
///
/// # Errors
/// As [`median`].
pub fn median_planned(
    ctx: &GpuContext,
    vol: &Volume<f32>,
    k: usize,
    plan: &ProcessPlan,
) -> Result<(Field<f32>, ProcessTimings)> {
    check_median_size_gpu(k)?;
    plan.run(ctx, vol, ("process_median", "median"), |op, v, t| {
        median_whole(ctx, op, v, k, t)
    })
}

/// [`crate::cpu::process::gradient_magnitude`] on the GPU (f32), in the slabs of
/// [`ProcessPlan::gradient_magnitude`].
///
/// # Errors
/// [`Error::TooLarge`] as [`ProcessPlan::new`]; [`Error::Gpu`] on device failure.
pub fn gradient_magnitude(ctx: &GpuContext, vol: &Volume<f32>) -> Result<Field<f32>> {
    let plan = ProcessPlan::gradient_magnitude(&ctx.limits, vol.dims())?;
    Ok(gradient_magnitude_planned(ctx, vol, &plan)?.0)
}

/// [`gradient_magnitude`] in the slabs of `plan`, with what it did on the device.
///
/// # Errors
/// As [`gradient_magnitude`].
pub fn gradient_magnitude_planned(
    ctx: &GpuContext,
    vol: &Volume<f32>,
    plan: &ProcessPlan,
) -> Result<(Field<f32>, ProcessTimings)> {
    plan.run(
        ctx,
        vol,
        ("process_gradient", "gradient_magnitude"),
        |op, v, t| gradient_magnitude_whole(ctx, op, v, t),
    )
}
