//! Joseph's matched pair on the GPU: the port of [`crate::cpu::project::JosephPair`]
//! for the iterative methods ([`crate::cpu::iterative`]), in f32.
//!
//! `forward` is `shaders/project.wgsl: project` over the requested views (the same
//! kernel as [`super::project::project_volume`]); `transpose` is
//! `shaders/joseph_pair_transpose.wgsl: transpose`, the voxel-driven gather of
//! [`JosephPair::transpose_voxel`]: every voxel sums, view by view in order, the
//! pixels of its footprint box ([`JosephFootprint`], built in f64 on the host and
//! widened by one pixel against f32 rounding), each weighted by `joseph_weight` from
//! the ray's own `joseph_planes` — the numbers the forward pass uses, so the pair
//! stays matched in f32 (`tests/gpu_iterative.rs` checks `⟨Ax, y⟩ = ⟨x, Aᵀy⟩`).
//!
//! The grid, the view rays, the footprints and the buffers are made once. Two ways
//! in: [`MatchedPair`] (upload the input, project, read the result back: what
//! [`crate::cpu::iterative::solve`] calls, and the parity tests), and
//! [`GpuJosephPair::enqueue_forward`] / [`GpuJosephPair::enqueue_transpose`], which
//! only queue the dispatches between device buffers (what the device-resident
//! solver [`super::iterative`] calls, so that no iteration waits for the host).
//! Either way every dispatch does bounded work (a slow software device must never
//! run one dispatch for many seconds).
//!
//! Past one storage binding the pair is cut ([`PairPlan`]): the grid in z-slabs and
//! the projections in chunks of views, each piece in its own buffers, and only the
//! [`MatchedPair`] way in is open (the iterations then run on the host).
//!
//! [`JosephPair`]: crate::cpu::project::JosephPair
//! [`JosephPair::transpose_voxel`]: crate::cpu::project::JosephPair::transpose_voxel

use super::context::GpuContext;
use super::plan::{binding_limit, count_of, Pieces};
use super::project::{views_per_dispatch, ForwardKernel, GridBinding, SAMPLES_PER_DISPATCH};
use crate::cpu::iterative::MatchedPair;
use crate::cpu::project::{joseph_views, view_axes, JosephFootprint, JosephView};
use crate::ct::Geometry;
use crate::error::{Error, Result};
use glam::{DMat3, DMat4, DVec3};
use wgpu::util::DeviceExt;

/// Invocations per workgroup (`WORKGROUP` in `shaders/joseph_pair_transpose.wgsl`).
const WORKGROUP: u32 = 64;

/// Footprint pixels one voxel visits per view, for sizing dispatches (a voxel about a
/// detector pixel wide, widened by one pixel on every side).
const PIXELS_PER_VOXEL_VIEW: usize = 16;

/// Parameters of one transpose dispatch, shared with
/// `shaders/shared/project_params.wgsl: TransposeParams` (twelve u32, 48 bytes;
/// `tests/gpu_layout.rs` checks the layout).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TransposeParams {
    pub nx: u32,
    pub ny: u32,
    pub nz: u32,
    pub cols: u32,
    pub rows: u32,
    pub voxel_offset: u32,
    pub n_voxels: u32,
    pub slot_lo: u32,
    pub slot_hi: u32,
    pub accumulate: u32,
    pub row_stride: u32,
    /// The voxel the output buffer starts at (a slab's first, past one binding).
    pub out_base: u32,
}

/// How a [`GpuJosephPair`] cuts a problem that exceeds one storage binding: the grid
/// in z-slabs and the projections in chunks of views, each piece in its own
/// buffers. `Aᵀ` gathers every voxel's sum view by view in order, so a slab's voxels
/// and a later chunk's views (added to what the earlier left) give the unsplit sums
/// bit for bit; `A` projects each slab as a grid of its own and adds the slabs'
/// projections, as the split GPU projection does
/// ([`super::project::ProjectionPlan`]): the unsplit values up to the order of their
/// f32 additions. A split pair serves [`MatchedPair`] only; the device-resident
/// solver ([`super::iterative`]) needs a whole one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PairPlan {
    /// z-slices of the grid per slab.
    pub slabs: Pieces,
    /// Views per chunk of projections.
    pub views: Pieces,
}

impl PairPlan {
    /// The plan for a grid of `dims` seen in `g` under `limits`.
    ///
    /// # Errors
    /// [`Error::TooLarge`] when one slice of the grid or one projection alone exceeds a
    /// binding, or the grid has 2³² voxels or more.
    pub fn new(limits: &wgpu::Limits, dims: [usize; 3], g: &Geometry) -> Result<PairPlan> {
        let limit = binding_limit(limits).min(u32::MAX as u64 / 4 * 4);
        let [nx, ny, nz] = dims;
        if dims.iter().product::<usize>() >= u32::MAX as usize {
            return Err(Error::too_large(
                "GPU iterative reconstruction",
                format!("a {nx}×{ny}×{nz} grid: the GPU pair indexes voxels with 32 bits"),
            ));
        }
        let slice = (nx * ny) as u64 * 4;
        let per_view = (g.cols * g.rows) as u64 * 4;
        Ok(PairPlan {
            slabs: Pieces::plan(
                "GPU iterative grid",
                "slice of the grid",
                nz,
                slice,
                limit,
                1,
            )?,
            views: Pieces::plan(
                "GPU iterative projections",
                "projection",
                g.n_angles(),
                per_view,
                limit,
                1,
            )?,
        })
    }

    /// Whether anything is cut.
    pub fn is_split(&self) -> bool {
        self.slabs.is_split() || self.views.is_split()
    }

    /// One line for the user: "the pair in 4 slabs of 8 slices and 3 chunks of 20
    /// views, the iterations on the host".
    pub fn describe(&self) -> String {
        format!(
            "the pair in {} of {} and {} of {}, the iterations on the host",
            count_of(self.slabs.count(), "slab"),
            count_of(self.slabs.per_piece, "slice"),
            count_of(self.views.count(), "chunk"),
            count_of(self.views.per_piece, "view")
        )
    }

    /// Device bytes of a pair on this plan for `g`: the pieces' buffers (a slab in
    /// and out, a chunk of projections in and out), the rays and the view list.
    pub fn device_bytes(&self, dims: [usize; 3], g: &Geometry) -> u64 {
        let slab = (self.slabs.per_piece * dims[0] * dims[1]) as u64 * 4;
        let chunk = (self.views.per_piece * g.cols * g.rows) as u64 * 4;
        let per_view = (size_of::<JosephView<f32>>() + size_of::<JosephFootprint<f32>>() + 8)
            as u64
            * self.slabs.count() as u64;
        2 * slab + 2 * chunk + per_view * g.n_angles() as u64
    }
}

/// The complete WGSL module of the transpose: `shaders/joseph_pair_transpose.wgsl` and its
/// imports.
pub fn transpose_source() -> String {
    super::shaders::resolve("joseph_pair_transpose")
}

/// One transpose dispatch: voxels `v0 .. v0 + nv` (the output buffer starting at
/// `out_base`), slots `s0 .. s1`, added to the output when `add`.
#[derive(Clone, Copy)]
struct Transpose {
    voxels: (usize, usize),
    slots: (usize, usize),
    out_base: usize,
    add: bool,
}

/// Joseph's projector and its exact transpose on one GPU (module docs).
pub struct GpuJosephPair<'c> {
    ctx: &'c GpuContext,
    dims: [usize; 3],
    cols: usize,
    rows: usize,
    n_views: usize,
    forward_kernel: ForwardKernel,
    transpose_pipeline: wgpu::ComputePipeline,
    transpose_layout: wgpu::BindGroupLayout,
    views: wgpu::Buffer,
    footprints: wgpu::Buffer,
    axes: wgpu::Buffer,
    list: wgpu::Buffer,
    grid: wgpu::Buffer,
    projections: wgpu::Buffer,
    grid_out: wgpu::Buffer,
    projections_out: wgpu::Buffer,
    plan: PairPlan,
    /// The rays of every slab past the first, each slab seen as a grid of its own
    /// (the first slab's are `views`).
    slab_views: Vec<wgpu::Buffer>,
}

impl<'c> GpuJosephPair<'c> {
    /// The pair for a grid of `dims` voxels with index-to-world `affine`, seen in
    /// geometry `g`, on `ctx`.
    ///
    /// The grid and the projections are cut as [`PairPlan::new`] plans them under the
    /// context's limits.
    ///
    /// # Errors
    /// [`Error::Invalid`] for an invalid geometry or affine; [`Error::TooLarge`] as
    /// [`PairPlan::new`]; [`Error::Gpu`] on device failure.
    pub fn new(ctx: &'c GpuContext, dims: [usize; 3], affine: DMat4, g: &Geometry) -> Result<Self> {
        g.validate()?;
        let plan = PairPlan::new(&ctx.limits, dims, g)?;
        Self::planned(ctx, dims, affine, g, plan)
    }

    /// [`Self::new`] cut as `plan` says (a plan under lower limits than the context's
    /// cuts it further).
    ///
    /// # Errors
    /// As [`Self::new`]; [`Error::Invalid`] for a plan made for another problem.
    pub fn planned(
        ctx: &'c GpuContext,
        dims: [usize; 3],
        affine: DMat4,
        g: &Geometry,
        plan: PairPlan,
    ) -> Result<Self> {
        g.validate()?;
        let det = DMat3::from_mat4(affine).determinant();
        if !affine.is_finite() || !det.is_finite() || det.abs() < 1e-300 {
            return Err(Error::invalid(
                "reconstruction grid",
                "the index-to-world affine must be finite and invertible",
            ));
        }
        if plan.slabs.total != dims[2] || plan.views.total != g.n_angles() {
            return Err(Error::invalid(
                "GPU pair plan",
                format!(
                    "made for {} slices and {} views, not {dims:?} and {}",
                    plan.slabs.total,
                    plan.views.total,
                    g.n_angles()
                ),
            ));
        }
        let per_view = g.cols * g.rows;
        let slab = plan.slabs.per_piece * dims[0] * dims[1];
        let chunk = plan.views.per_piece * per_view;
        let limit = binding_limit(&ctx.limits);
        if (slab.max(chunk) as u64) * 4 > limit {
            return Err(Error::too_large(
                "GPU pair plan",
                format!(
                    "a piece of {} bytes exceeds the storage-binding limit of {limit} bytes: \
                     use PairPlan::new",
                    slab.max(chunk) * 4
                ),
            ));
        }
        let dev = &ctx.device;
        let init = |label: &str, contents: &[u8]| {
            dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let views32: Vec<JosephView<f32>> = joseph_views(g, affine);
        let views64: Vec<JosephView<f64>> = joseph_views(g, affine);
        let foot: Vec<JosephFootprint<f32>> = views64
            .iter()
            .map(|v| {
                let f = JosephFootprint::new(v);
                JosephFootprint {
                    rows: f.rows.map(|r| r.map(|x| x as f32)),
                }
            })
            .collect();
        let axes: Vec<u32> = view_axes(dims, &views32, g.cols, g.rows)
            .into_iter()
            .map(|a| a.map_or(3, |m| m as u32))
            .collect();
        let views = init("joseph views", bytemuck::cast_slice(&views32));
        let slab_views = plan
            .slabs
            .ranges()
            .skip(1)
            .map(|s| {
                let moved = affine * DMat4::from_translation(DVec3::new(0.0, 0.0, s.start as f64));
                let v: Vec<JosephView<f32>> = joseph_views(g, moved);
                init("joseph slab views", bytemuck::cast_slice(&v))
            })
            .collect();
        let footprints = init("joseph footprints", bytemuck::cast_slice(&foot));
        let axes = init("joseph view axes", bytemuck::cast_slice(&axes));
        let buffer = |label: &str, bytes: usize, usage: wgpu::BufferUsages| {
            dev.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: (bytes as u64).max(4),
                usage,
                mapped_at_creation: false,
            })
        };
        let input = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let list = buffer("view list", g.n_angles() * 4, input);
        let grid = buffer("grid in", slab * 4, input);
        let projections = buffer("projections in", chunk * 4, input);
        let grid_out = ctx.storage_buffer("grid out", (slab * 4) as u64)?;
        let projections_out = ctx.storage_buffer("projections out", (chunk * 4) as u64)?;
        let super::context::Kernel {
            layout: transpose_layout,
            pipeline: transpose_pipeline,
        } = ctx.kernel(
            "joseph_pair_transpose.wgsl",
            &transpose_source(),
            None,
            "transpose",
        )?;
        Ok(GpuJosephPair {
            ctx,
            dims,
            cols: g.cols,
            rows: g.rows,
            n_views: g.n_angles(),
            forward_kernel: ForwardKernel::new(ctx)?,
            transpose_pipeline,
            transpose_layout,
            views,
            footprints,
            axes,
            list,
            grid,
            projections,
            grid_out,
            projections_out,
            plan,
            slab_views,
        })
    }

    /// How the pair cuts its problem ([`PairPlan`]).
    pub fn plan(&self) -> PairPlan {
        self.plan
    }

    /// The device this pair runs on.
    pub fn context(&self) -> &'c GpuContext {
        self.ctx
    }

    /// Checks a view list: at most every view, each index below the count.
    fn check_views(&self, views: &[usize]) -> Result<()> {
        if views.len() > self.n_views || views.iter().any(|&k| k >= self.n_views) {
            return Err(Error::invalid(
                "views",
                format!("a list of up to {} view indices below that", self.n_views),
            ));
        }
        Ok(())
    }

    /// A device view list for [`Self::enqueue_forward`] and
    /// [`Self::enqueue_transpose`], checking every index.
    ///
    /// # Errors
    /// [`Error::Invalid`] for a view out of range.
    pub fn view_list(&self, views: &[usize]) -> Result<wgpu::Buffer> {
        self.check_views(views)?;
        let list: Vec<u32> = views.iter().map(|&k| k as u32).collect();
        let bytes: &[u8] = if list.is_empty() {
            &[0; 4]
        } else {
            bytemuck::cast_slice(&list)
        };
        Ok(self
            .ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("view list"),
                contents: bytes,
                usage: wgpu::BufferUsages::STORAGE,
            }))
    }

    /// Uploads the view list, checking every index.
    fn upload_list(&self, views: &[usize]) -> Result<()> {
        self.check_views(views)?;
        let list: Vec<u32> = views.iter().map(|&k| k as u32).collect();
        if !list.is_empty() {
            self.ctx
                .queue
                .write_buffer(&self.list, 0, bytemuck::cast_slice(&list));
        }
        Ok(())
    }

    fn read(&self, buf: &wgpu::Buffer, n: usize) -> Result<Vec<f32>> {
        if n == 0 {
            return Ok(Vec::new());
        }
        let bytes = self.ctx.read_buffer(buf, (n * 4) as u64)?;
        Ok(bytemuck::pod_collect_to_vec::<u8, f32>(&bytes))
    }

    /// The views per forward dispatch and the kernel's shape (grid, detector).
    fn forward_plan(&self) -> (usize, [usize; 5]) {
        let limit = self.ctx.limits.max_storage_buffer_binding_size;
        let chunk = views_per_dispatch(self.dims, self.per_view(), limit);
        let [nx, ny, nz] = self.dims;
        (chunk, [nx, ny, nz, self.cols, self.rows])
    }

    /// Queues `out ← A x` over the first `n` views of `list`: `x` one f32 per voxel,
    /// `out` at least `n × per_view` values (`[slot][row][col]`). Nothing waits. For a
    /// whole pair (not [`PairPlan::is_split`]).
    pub fn enqueue_forward(
        &self,
        x: &wgpu::Buffer,
        list: &wgpu::Buffer,
        n: usize,
        out: &wgpu::Buffer,
    ) {
        let pv = self.per_view();
        let (chunk, shape) = self.forward_plan();
        let mut k0 = 0;
        while k0 < n {
            let m = chunk.min(n - k0);
            let bufs = [&self.views, list, out];
            let grid = GridBinding::Buffer(x);
            self.forward_kernel
                .dispatch(self.ctx, shape, (k0, m), k0 * pv, bufs, grid, None);
            k0 += m;
        }
    }

    /// Queues `out ← Aᵀ y` over the first `n` views of `list` (`n ≥ 1`): `y` holds
    /// `n × per_view` values in the list's order, `out` one per voxel. With `pace`,
    /// waits for the device after every range of views (keeps a software device's
    /// queue short when nothing else bounds it). For a whole pair.
    ///
    /// # Errors
    /// [`Error::Gpu`] when a wait fails.
    pub fn enqueue_transpose(
        &self,
        y: &wgpu::Buffer,
        list: &wgpu::Buffer,
        n: usize,
        out: &wgpu::Buffer,
        pace: bool,
    ) -> Result<()> {
        self.queue_transpose([list, y, out], n, 0..self.n_voxels(), false, pace)
    }

    /// Queues `Aᵀ` over the first `n` views of `list` for the voxels `voxels` into
    /// `out`, which holds them from `voxels.start` on; `add`: onto what `out` holds
    /// (an earlier chunk of views), else over it.
    fn queue_transpose(
        &self,
        [list, y, out]: [&wgpu::Buffer; 3],
        n: usize,
        voxels: std::ops::Range<usize>,
        add: bool,
        pace: bool,
    ) -> Result<()> {
        // Bounded work per dispatch: voxels × slots × footprint pixels. Slots outside
        // (each later range adds to the sums), so every voxel sums its views in order.
        let nvox = voxels.len();
        let budget = SAMPLES_PER_DISPATCH / PIXELS_PER_VOXEL_VIEW;
        let per = nvox.min(budget).max(1);
        let slots = (budget / per).clamp(1, crate::gpu::context::LLVMPIPE_LOOP_LIMIT);
        let mut s0 = 0;
        while s0 < n {
            let s1 = (s0 + slots).min(n);
            let mut v0 = voxels.start;
            while v0 < voxels.end {
                let nv = per.min(voxels.end - v0);
                let step = Transpose {
                    voxels: (v0, nv),
                    slots: (s0, s1),
                    out_base: voxels.start,
                    add: add || s0 > 0,
                };
                self.dispatch_transpose(step, [list, y, out]);
                v0 += nv;
            }
            if pace {
                self.ctx.wait()?;
            }
            s0 = s1;
        }
        Ok(())
    }

    /// One transpose dispatch (`step`); `buffers` are the view list, the projections
    /// and the output grid.
    fn dispatch_transpose(&self, step: Transpose, [list, proj, out]: [&wgpu::Buffer; 3]) {
        let Transpose {
            voxels: (v0, nv),
            slots: (s0, s1),
            out_base,
            add,
        } = step;
        let dev = &self.ctx.device;
        let max_x = self.ctx.limits.max_compute_workgroups_per_dimension.max(1);
        let groups = (nv as u32).div_ceil(WORKGROUP).max(1);
        let x = groups.min(max_x);
        let y = groups.div_ceil(x);
        let params = TransposeParams {
            nx: self.dims[0] as u32,
            ny: self.dims[1] as u32,
            nz: self.dims[2] as u32,
            cols: self.cols as u32,
            rows: self.rows as u32,
            voxel_offset: v0 as u32,
            n_voxels: nv as u32,
            slot_lo: s0 as u32,
            slot_hi: s1 as u32,
            accumulate: u32::from(add),
            row_stride: x * WORKGROUP,
            out_base: out_base as u32,
        };
        let ubuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("transpose params"),
            contents: bytemuck::bytes_of(&params),
            usage: super::context::PARAMS_USAGE,
        });
        let bind = self.ctx.bind_group(
            "project transpose",
            &self.transpose_layout,
            &[
                ubuf.as_entire_binding(),
                self.views.as_entire_binding(),
                self.footprints.as_entire_binding(),
                self.axes.as_entire_binding(),
                list.as_entire_binding(),
                proj.as_entire_binding(),
                out.as_entire_binding(),
            ],
        );
        let mut enc = dev.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("project transpose"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.transpose_pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(x, y, 1);
        }
        self.ctx.queue.submit([enc.finish()]);
    }
}

impl MatchedPair<f32> for GpuJosephPair<'_> {
    fn dims(&self) -> [usize; 3] {
        self.dims
    }

    fn n_views(&self) -> usize {
        self.n_views
    }

    fn per_view(&self) -> usize {
        self.cols * self.rows
    }

    fn forward(&self, x: &[f32], views: &[usize]) -> Result<Vec<f32>> {
        if x.len() != self.n_voxels() {
            return Err(Error::invalid(
                "grid",
                format!("{} values for {} voxels", x.len(), self.n_voxels()),
            ));
        }
        self.upload_list(views)?;
        // Slab by slab, each a grid of its own; a dispatch's views at most one
        // binding's worth (and one chunk of the plan), each read back as it finishes
        // and added to the earlier slabs' sums.
        let pv = self.per_view();
        let [nx, ny, _] = self.dims;
        let limit = self.ctx.limits.max_storage_buffer_binding_size;
        let mut out = vec![0.0f32; views.len() * pv];
        for (s, slab) in self.plan.slabs.ranges().enumerate() {
            self.ctx.queue.write_buffer(
                &self.grid,
                0,
                bytemuck::cast_slice(&x[slab.start * nx * ny..slab.end * nx * ny]),
            );
            let rays = if s == 0 {
                &self.views
            } else {
                &self.slab_views[s - 1]
            };
            let dims = [nx, ny, slab.len()];
            let chunk = views_per_dispatch(dims, pv, limit).min(self.plan.views.per_piece);
            let shape = [nx, ny, slab.len(), self.cols, self.rows];
            let mut k0 = 0;
            while k0 < views.len() {
                let n = chunk.min(views.len() - k0);
                let bufs = [rays, &self.list, &self.projections_out];
                let grid = GridBinding::Buffer(&self.grid);
                self.forward_kernel
                    .dispatch(self.ctx, shape, (k0, n), 0, bufs, grid, None);
                let got = self.read(&self.projections_out, n * pv)?;
                let dst = &mut out[k0 * pv..(k0 + n) * pv];
                if s == 0 {
                    dst.copy_from_slice(&got);
                } else {
                    dst.iter_mut().zip(&got).for_each(|(d, v)| *d += v);
                }
                k0 += n;
            }
        }
        Ok(out)
    }

    fn transpose(&self, y: &[f32], views: &[usize]) -> Result<Vec<f32>> {
        let pv = self.per_view();
        if y.len() != views.len() * pv {
            return Err(Error::invalid(
                "projections",
                format!(
                    "{} values for {} views of {pv} pixels",
                    y.len(),
                    views.len()
                ),
            ));
        }
        let n = self.n_voxels();
        if views.is_empty() {
            return Ok(vec![0.0; n]);
        }
        self.check_views(views)?;
        // Slab by slab of voxels; for each, the views chunk by chunk, every later chunk
        // added to the sums the earlier left (the unsplit sums, bit for bit).
        let slice = self.dims[0] * self.dims[1];
        let per = self.plan.views.per_piece.max(1);
        let mut out = Vec::with_capacity(n);
        for slab in self.plan.slabs.ranges() {
            let voxels = slab.start * slice..slab.end * slice;
            for (c, chunk) in views.chunks(per).enumerate() {
                self.upload_list(chunk)?;
                let at = c * per * pv;
                self.ctx.queue.write_buffer(
                    &self.projections,
                    0,
                    bytemuck::cast_slice(&y[at..at + chunk.len() * pv]),
                );
                let bufs = [&self.list, &self.projections, &self.grid_out];
                self.queue_transpose(bufs, chunk.len(), voxels.clone(), c > 0, true)?;
            }
            out.extend(self.read(&self.grid_out, voxels.len())?);
        }
        Ok(out)
    }
}
