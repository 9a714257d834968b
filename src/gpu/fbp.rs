//! FBP and FDK on the GPU: the backprojection of `crate::cpu::fbp` as a WGSL compute
//! shader (`shaders/fbp_backproject.wgsl`). One invocation takes
//! [`VOXELS_PER_INVOCATION`] neighbouring voxels along k, each summed exactly as alone,
//! and loops over a chunk of views: several dispatches keep each one short on software
//! drivers, all of a slab's in one submission. [`backproject_timed`] says how long the
//! dispatches took on the device (timestamp queries, where the adapter has them).
//!
//! The view matrices are uploaded as `ViewMatrix<f32>` (WGSL `CtView`), the filtered
//! projections as one f32 storage buffer. [`fbp`] runs the whole reconstruction on
//! the GPU: ramp filtering with [`crate::gpu::ramp::filter_projections`] (cosine
//! pre-weighting, batched FFTs, the response, cropping), then [`backproject`].

use crate::cpu::fbp::{backprojection_scale, Grid, Reconstruction};
use crate::cpu::ramp::RampFilter;
use crate::ct::ViewMatrix;
use crate::ct::{Geometry, Projections};
use crate::error::{Error, Result};
use crate::gpu::plan::{binding_limit, count_of, Pieces};
use crate::gpu::GpuContext;
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

/// The shader source: `shaders/fbp_backproject.wgsl` and its imports (the shared CT
/// geometry and `FbpParams`).
pub fn shader_source() -> String {
    super::shaders::resolve("fbp_backproject")
}

/// How [`backproject`] cuts a job to fit the planner's limits
/// ([`crate::gpu::plan`]): the output volume in z-slabs, the filtered projections in
/// batches of whole views.
///
/// A batch holds a multiple of the views one dispatch sums (32) wherever at least 32
/// views fit one binding, and each slab's voxels sit where the unsplit volume's do
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
}

impl BackprojectionPlan {
    /// The plan for `g` onto `grid` under `limits` (the context's, or lower ones).
    ///
    /// # Errors
    /// [`Error::TooLarge`] when one slice of the volume or one view's projection alone
    /// exceeds a binding.
    pub fn new(limits: &wgpu::Limits, g: &Geometry, grid: &Grid) -> Result<Self> {
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
        let view_bytes = (g.rows * g.cols) as u64 * 4;
        let batches = Pieces::plan(
            "GPU filtered projections",
            "view",
            g.n_angles(),
            view_bytes,
            slab_limit,
            VIEWS_PER_DISPATCH,
        )?;
        let matrices = (g.n_angles() * size_of::<ViewMatrix<f32>>()) as u64;
        Ok(BackprojectionPlan {
            slabs,
            batches,
            device_bytes: matrices
                + batches.per_piece as u64 * view_bytes
                + slabs.per_piece as u64 * slice_bytes,
        })
    }

    /// Whether the job is cut at all.
    pub fn is_split(&self) -> bool {
        self.slabs.is_split() || self.batches.is_split()
    }

    /// One line for the user: "backprojection in 4 slabs of 16 slices × 2 batches of
    /// 64 views".
    pub fn describe(&self) -> String {
        format!(
            "backprojection in {} of {} × {} of {}",
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
    let limit = binding_limit(&ctx.limits);
    let batch_bytes = (plan.batches.per_piece * g.rows * g.cols * 4) as u64;
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
    let upload = |views: std::ops::Range<usize>| {
        dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("fbp projections"),
            contents: bytemuck::cast_slice(
                &filtered.data[views.start * per_view..views.end * per_view],
            ),
            usage: wgpu::BufferUsages::STORAGE,
        })
    };
    // One batch stays on the device for every slab; several are sent again per slab.
    let resident = (!plan.batches.is_split()).then(|| upload(0..g.n_angles()));
    let [nx, ny, _] = grid.dims;
    let slice = nx * ny;
    let module = ctx.shader("fbp_backproject.wgsl", &shader_source())?;
    let pipeline = dev.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("backproject_point"),
        layout: None,
        module: &module,
        entry_point: Some("backproject_point"),
        compilation_options: Default::default(),
        cache: None,
    });
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
                    sent = upload(batch.clone());
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
                        usage: wgpu::BufferUsages::UNIFORM,
                    });
                    ctx.bind_group(
                        "fbp",
                        &pipeline.get_bind_group_layout(0),
                        &[
                            ubuf.as_entire_binding(),
                            vbuf.as_entire_binding(),
                            pbuf.as_entire_binding(),
                            out.as_entire_binding(),
                        ],
                    )
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
