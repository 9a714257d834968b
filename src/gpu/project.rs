//! Joseph forward projection on the GPU: the port of
//! [`crate::cpu::project::project_volume`].
//!
//! The grid is uploaded once as f32 into a storage buffer (read with manual bilinear
//! interpolation: the exact path, the same taps and zero rule as the CPU's
//! [`crate::cpu::project::slice_bilinear`]); every view's rays go up as
//! [`JosephView<f32>`] (built by the same code as the CPU's, in f64, then rounded).
//! `shaders/project.wgsl: project` runs one invocation per detector pixel —
//! `pixel_ray`, then `joseph_ray` — over as many views per dispatch as keep one
//! dispatch near [`SAMPLES_PER_DISPATCH`] bilinear samples (a slow software device
//! must never run one dispatch for many seconds); each chunk is read back as it
//! finishes.

use super::context::{GpuContext, TimestampPair};
use super::plan::{binding_limit, count_of, Pieces};
use crate::cpu::project::{joseph_views, Grid, JosephView, ProjectOptions};
use crate::ct::{Geometry, Projections};
use crate::error::{Error, Result};
use crate::real::Real;
use std::time::Instant;
use wgpu::util::DeviceExt;

/// `shaders/shared/project_params.wgsl`: the WGSL twins of [`ProjectParams`] and
/// [`JosephView`].
pub const PARAMS_WGSL: &str = super::shaders::PROJECT_PARAMS;

/// Invocations per workgroup (`WORKGROUP` in `shaders/project.wgsl`).
const WORKGROUP: u32 = 64;

/// The bilinear samples one dispatch may take at most (about a second on lavapipe).
pub const SAMPLES_PER_DISPATCH: usize = 1 << 25;

/// The complete WGSL module: `shaders/project.wgsl` and its imports.
pub fn shader_source() -> String {
    super::shaders::resolve("project")
}

/// Parameters of one dispatch, shared with
/// `shaders/shared/project_params.wgsl: ProjectParams` (twelve u32, 48 bytes;
/// `tests/gpu_layout.rs` checks the layout).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ProjectParams {
    pub nx: u32,
    pub ny: u32,
    pub nz: u32,
    pub cols: u32,
    pub rows: u32,
    pub view_offset: u32,
    pub n_views: u32,
    pub row_stride: u32,
    /// Where the dispatch's first view goes in the output (values).
    pub out_offset: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}

/// Where the time of a GPU projection went, in seconds (wall clock).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ProjectTimings {
    /// Shader compilation, uploads, buffers.
    pub setup: f64,
    /// Dispatches and readbacks.
    pub project: f64,
    /// The dispatches alone on the device, from timestamp queries; `None` where the
    /// adapter has none.
    pub kernel: Option<f64>,
    /// Everything.
    pub total: f64,
}

/// The views one dispatch of `shaders/project.wgsl: project` may cover: about
/// [`SAMPLES_PER_DISPATCH`] samples (a grid of `dims`, `per_view` pixels per view), and
/// no more than a storage binding of `limit` bytes holds; at least one.
pub fn views_per_dispatch(dims: [usize; 3], per_view: usize, limit: u64) -> usize {
    let longest = dims.iter().copied().max().unwrap_or(1);
    let by_work = SAMPLES_PER_DISPATCH / (per_view * longest).max(1);
    let by_bytes = (limit / (per_view as u64 * 4).max(1)) as usize;
    by_work.min(by_bytes).max(1)
}

/// `shaders/project.wgsl: project`, compiled once; [`Self::dispatch`] projects a run
/// of a view list. Shared by [`project_volume`] and the iterative methods' GPU pair
/// (`gpu::joseph_pair`).
pub struct ForwardKernel {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

impl ForwardKernel {
    /// Compiles the kernel.
    ///
    /// # Errors
    /// [`Error::Gpu`] when the shader does not compile.
    pub fn new(ctx: &GpuContext) -> Result<Self> {
        let module = ctx.shader("project.wgsl", &shader_source())?;
        let pipeline = ctx
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some("project"),
                layout: None,
                module: &module,
                entry_point: Some("project"),
                compilation_options: Default::default(),
                cache: None,
            });
        let layout = pipeline.get_bind_group_layout(0);
        Ok(ForwardKernel { pipeline, layout })
    }

    /// Submits the projection of slots `first .. first + n` of the view list: `shape`
    /// is the grid's `nx, ny, nz` and the detector's `cols, rows`; `buffers` are the
    /// views ([`JosephView<f32>`]), the grid, the list (u32 view indices) and the
    /// output, which receives `[slot − first][row][col]` from value `out_offset` on.
    /// With `query`, the dispatch is timed on the device (read it once the submission
    /// has completed).
    pub fn dispatch(
        &self,
        ctx: &GpuContext,
        shape: [usize; 5],
        (first, n): (usize, usize),
        out_offset: usize,
        buffers: [&wgpu::Buffer; 4],
        query: Option<&TimestampPair>,
    ) {
        let dev = &ctx.device;
        let max_x = ctx.limits.max_compute_workgroups_per_dimension.max(1);
        let invocations = (n * shape[3] * shape[4]) as u32;
        let groups = invocations.div_ceil(WORKGROUP).max(1);
        let x = groups.min(max_x);
        let y = groups.div_ceil(x);
        let params = ProjectParams {
            nx: shape[0] as u32,
            ny: shape[1] as u32,
            nz: shape[2] as u32,
            cols: shape[3] as u32,
            rows: shape[4] as u32,
            view_offset: first as u32,
            n_views: n as u32,
            row_stride: x * WORKGROUP,
            out_offset: out_offset as u32,
            ..Default::default()
        };
        let ubuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("project params"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let [views, vol, list, out] = buffers;
        let bind = ctx.bind_group(
            "project",
            &self.layout,
            &[
                ubuf.as_entire_binding(),
                views.as_entire_binding(),
                vol.as_entire_binding(),
                out.as_entire_binding(),
                list.as_entire_binding(),
            ],
        );
        let mut enc = dev.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("project"),
                timestamp_writes: query.map(TimestampPair::pass_writes),
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(x, y, 1);
        }
        if let Some(q) = query {
            q.resolve(&mut enc);
        }
        ctx.queue.submit([enc.finish()]);
    }
}

/// How [`project_volume`] cuts a job to fit the planner's limits
/// ([`crate::gpu::plan`]): the grid in z-slabs, the output in chunks of views.
///
/// Each slab is projected as a grid of its own (its affine moved to its first slice)
/// whose taps outside it count zero, and the slabs' projections are summed: every
/// bilinear tap of Joseph's sum belongs to exactly one slab, so a split projection is
/// the unsplit one up to the order of its f32 additions (and the rounding of the
/// moved ray origins).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProjectionPlan {
    /// Slices of the grid per slab.
    pub slabs: Pieces,
    /// Views per dispatch (and per output buffer).
    pub views_per_dispatch: usize,
    /// The largest device allocation at once: one slab, the output chunk and the
    /// views (bytes).
    pub device_bytes: u64,
}

impl ProjectionPlan {
    /// The plan for `g` through a grid of `dims` under `limits`.
    ///
    /// # Errors
    /// [`Error::TooLarge`] when one projection or one slice of the grid alone exceeds a
    /// binding.
    pub fn new(limits: &wgpu::Limits, g: &Geometry, dims: [usize; 3]) -> Result<Self> {
        let limit = binding_limit(limits).min(u32::MAX as u64 / 4 * 4);
        let per_view = g.rows * g.cols;
        if per_view as u64 * 4 > limit {
            return Err(Error::too_large(
                "GPU projection",
                format!(
                    "one {}×{} projection ({} bytes) exceeds the storage-binding limit of \
                     {limit} bytes",
                    g.cols,
                    g.rows,
                    per_view * 4
                ),
            ));
        }
        let [nx, ny, nz] = dims;
        let slice_bytes = (nx * ny) as u64 * 4;
        let slabs = Pieces::plan(
            "GPU projection grid",
            "slice of the grid",
            nz,
            slice_bytes,
            limit,
            1,
        )?;
        let chunk = views_per_dispatch([nx, ny, slabs.per_piece], per_view, limit)
            .min(g.n_angles())
            .max(1);
        let views = (g.n_angles() * (size_of::<JosephView<f32>>() + 4)) as u64;
        Ok(ProjectionPlan {
            slabs,
            views_per_dispatch: chunk,
            device_bytes: slabs.per_piece as u64 * slice_bytes
                + (chunk * per_view * 4) as u64
                + views,
        })
    }

    /// Whether the grid is cut at all.
    pub fn is_split(&self) -> bool {
        self.slabs.is_split()
    }

    /// One line for the user: "projection in 4 slabs of 16 slices".
    pub fn describe(&self) -> String {
        format!(
            "projection in {} of {}",
            count_of(self.slabs.count(), "slab"),
            count_of(self.slabs.per_piece, "slice")
        )
    }
}

/// [`crate::cpu::project::project_volume`] on the GPU, in f32: the same projections
/// within the tolerance `tests/gpu_ct_project.rs` states, in the pieces of
/// [`ProjectionPlan::new`] under the context's limits.
///
/// # Errors
/// [`Error::Invalid`] for an invalid geometry; [`Error::TooLarge`] as
/// [`ProjectionPlan::new`]; [`Error::Gpu`] on device failure.
pub fn project_volume<R: Real>(
    ctx: &GpuContext,
    grid: &Grid<R>,
    g: &Geometry,
    options: &ProjectOptions,
) -> Result<Projections<f32>> {
    Ok(project_volume_timed(ctx, grid, g, options)?.0)
}

/// [`project_volume`] with timings.
///
/// # Errors
/// As [`project_volume`].
pub fn project_volume_timed<R: Real>(
    ctx: &GpuContext,
    grid: &Grid<R>,
    g: &Geometry,
    options: &ProjectOptions,
) -> Result<(Projections<f32>, ProjectTimings)> {
    g.validate()?;
    let plan = ProjectionPlan::new(&ctx.limits, g, grid.dims)?;
    project_volume_planned(ctx, grid, g, options, &plan)
}

/// [`project_volume_timed`] in the pieces of `plan` (a plan under lower limits than
/// the context's splits the grid further).
///
/// # Errors
/// As [`project_volume`]; [`Error::Invalid`] for a plan made for another grid.
pub fn project_volume_planned<R: Real>(
    ctx: &GpuContext,
    grid: &Grid<R>,
    g: &Geometry,
    options: &ProjectOptions,
    plan: &ProjectionPlan,
) -> Result<(Projections<f32>, ProjectTimings)> {
    let t0 = Instant::now();
    g.validate()?;
    let [nx, ny, nz] = grid.dims;
    if plan.slabs.total != nz || grid.data.len() != nx * ny * nz {
        return Err(Error::invalid(
            "projection plan",
            format!(
                "made for {} slices, not a grid of {:?} with {} values",
                plan.slabs.total,
                grid.dims,
                grid.data.len()
            ),
        ));
    }
    let limit = binding_limit(&ctx.limits);
    let slab_bytes = (plan.slabs.per_piece * nx * ny * 4) as u64;
    if slab_bytes > limit {
        return Err(Error::too_large(
            "projection plan",
            format!(
                "a slab of {slab_bytes} bytes exceeds the storage-binding limit of {limit} \
                 bytes: use ProjectionPlan::new"
            ),
        ));
    }
    let dev = &ctx.device;
    let all: Vec<u32> = (0..g.n_angles() as u32).collect();
    let list = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("view list"),
        contents: bytemuck::cast_slice(&all),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let kernel = ForwardKernel::new(ctx)?;
    let per_view = g.rows * g.cols;
    let chunk = plan.views_per_dispatch.max(1);
    let out = ctx.storage_buffer("projections", (chunk * per_view * 4) as u64)?;
    let mut result = Projections::<f32>::zeros(g)?;
    let query = ctx.timestamps();
    let mut kernel_seconds = query.as_ref().map(|_| 0.0);
    let setup = t0.elapsed().as_secs_f64();

    let t = Instant::now();
    let slice = nx * ny;
    let last = plan.slabs.count() - 1;
    for (s, slab) in plan.slabs.ranges().enumerate() {
        // The slab as a grid of its own: its index frame starts at its first slice.
        let affine = if slab.start == 0 {
            grid.affine
        } else {
            grid.affine
                * glam::DMat4::from_translation(glam::DVec3::new(0.0, 0.0, slab.start as f64))
        };
        let data: Vec<f32> = grid.data[slab.start * slice..slab.end * slice]
            .iter()
            .map(|v| v.f64() as f32)
            .collect();
        let vol = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("projection grid slab"),
            contents: bytemuck::cast_slice(&data),
            usage: wgpu::BufferUsages::STORAGE,
        });
        drop(data);
        let views: Vec<JosephView<f32>> = joseph_views(g, affine);
        let vbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("joseph views"),
            contents: bytemuck::cast_slice(&views),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let mut k0 = 0;
        while k0 < g.n_angles() {
            let n = chunk.min(g.n_angles() - k0);
            let shape = [nx, ny, slab.len(), g.cols, g.rows];
            let buffers = [&vbuf, &vol, &list, &out];
            kernel.dispatch(ctx, shape, (k0, n), 0, buffers, query.as_ref());
            let bytes = ctx.read_buffer(&out, (n * per_view * 4) as u64)?;
            if let (Some(q), Some(k)) = (&query, kernel_seconds.as_mut()) {
                *k += q.seconds(ctx)?;
            }
            let got: Vec<f32> = bytemuck::pod_collect_to_vec::<u8, f32>(&bytes);
            let dst = &mut result.data[k0 * per_view..(k0 + n) * per_view];
            if s == 0 {
                dst.copy_from_slice(&got);
            } else {
                dst.iter_mut().zip(&got).for_each(|(d, v)| *d += v);
            }
            if s == last {
                if let Some(f) = options.on_view {
                    (0..n).for_each(|_| f());
                }
            }
            k0 += n;
        }
    }
    let project = t.elapsed().as_secs_f64();
    Ok((
        result,
        ProjectTimings {
            setup,
            project,
            kernel: kernel_seconds,
            total: t0.elapsed().as_secs_f64(),
        },
    ))
}
