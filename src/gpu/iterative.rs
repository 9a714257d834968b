//! The iterative methods with the whole iteration on the device: the port of
//! [`crate::cpu::iterative::solve`] (SIRT, OS-SART, CGLS, TV), in f32.
//!
//! The image, the projections, the weights, the residuals and the method's other
//! vectors live in device buffers from the first iteration to the last. Every step
//! of an iteration is a dispatch: the projections through [`GpuJosephPair`]'s
//! queued kernels, the vector steps through `shaders/iterative.wgsl` (one entry
//! point per step of the CPU code, named after it). The scalars the methods need —
//! inner products, CGLS's `α` and `β`, the log, the stop flag — stay in a small
//! device buffer: every inner product is a deterministic two-pass reduction (fixed
//! chunks of `CHUNK` values, each summed in a fixed tree, then the chunk sums in
//! one workgroup), so a run gives the same numbers on every submission order, and
//! the tolerance rule (`stalled`) is evaluated on the device, which then freezes
//! the image: every update checks the flag.
//!
//! The host only queues. It reads the scalar buffer back once per **batch** of
//! iterations (to report progress and to stop early), never per step; the batch
//! grows until a batch takes about [`BATCH_SECONDS`] (or is fixed by
//! [`Batch::Fixed`]). TV's power iteration for `‖A‖` reads one scalar back before
//! the first iteration.
//!
//! It needs a whole pair: past one binding the pair is cut into pieces
//! ([`super::joseph_pair::PairPlan`]) and the iterations run on the host
//! ([`fits_on_device`] says which).
//!
//! The mirror pointers: `residual` ↔ `residual_of`, `weight_rows` ↔ the weighted
//! residual of `sart`, `reciprocal`, `mask` ↔ `masked`, `sart_update` ↔ `update`,
//! `axpy`, `direction`, `cgls_alpha` / `cgls_beta` ↔ `cgls`, `normalise` ↔
//! `operator_norm`, `partials` / `finish` ↔ `sum_by`, `log_entry` ↔ `stalled`,
//! `midpoint`, `dual_data`, `primal` ↔ `tv`, `dual_gradient` ↔ `tv_dual_step`.
//! Their CPU f32 and f64 twins are held to the same tolerances in
//! `tests/gpu_iterative.rs`.

use super::context::{buffer_entry, GpuContext, Kernel};
use super::joseph_pair::GpuJosephPair;
use crate::cpu::iterative::{
    check_problem, keeps_column_weights, live_axes, subset_order, subset_views, IterativeOptions,
    MatchedPair, Method, Problem, Solution, TvSteps,
};
use crate::error::{Error, Result};
use std::cell::RefCell;
use std::collections::HashMap;
use std::time::Instant;
use wgpu::util::DeviceExt;

/// Parameters of one vector step, shared with
/// `shaders/shared/iterative_params.wgsl: SolveParams` (twenty 4-byte values, 80
/// bytes; `tests/gpu_layout.rs` checks the layout).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SolveParams {
    pub n: u32,
    pub per_view: u32,
    pub row_stride: u32,
    pub term: u32,
    pub nx: u32,
    pub ny: u32,
    pub nz: u32,
    pub n_axes: u32,
    pub axis0: u32,
    pub axis1: u32,
    pub axis2: u32,
    pub nonnegative: u32,
    pub slot0: u32,
    pub slot1: u32,
    pub slot2: u32,
    pub _pad0: u32,
    pub f0: f32,
    pub f1: f32,
    pub f2: f32,
    pub _pad1: u32,
}

/// The WGSL twin of [`SolveParams`].
pub const PARAMS_WGSL: &str = super::shaders::ITERATIVE_PARAMS;

/// The complete WGSL module: `shaders/iterative.wgsl` and its imports.
pub fn shader_source() -> String {
    super::shaders::resolve("iterative")
}

/// Invocations per workgroup of the element-wise steps (`WORKGROUP` in the shader).
const WORKGROUP: u32 = 64;
/// Values per chunk of a reduction (`CHUNK`; the CPU's sums use the same chunks).
const CHUNK: usize = 4096;
/// Invocations per reduction workgroup (`REDUCE`).
const REDUCE: u32 = 256;

// The scalar buffer (`SLOT_*` in the shader): the stop flag, the log's length, the
// last objective, the methods' scalars, then the log from LOG_BASE.
const SLOT_STOP: u32 = 0;
const SLOT_LOGGED: u32 = 1;
const SLOT_RR: u32 = 3;
const SLOT_WRR: u32 = 4;
const SLOT_GAMMA: u32 = 5;
const SLOT_QQ: u32 = 6;
const SLOT_ALPHA: u32 = 7;
const SLOT_GAMMA_NEW: u32 = 8;
const SLOT_BETA: u32 = 9;
const SLOT_TV: u32 = 10;
const SLOT_NORM: u32 = 11;
const LOG_BASE: usize = 16;

/// The target wall time of one batch of iterations under [`Batch::Auto`].
pub const BATCH_SECONDS: f64 = 0.25;

/// How many iterations the host queues between two readbacks of the scalars.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Batch {
    /// One, then as many as take about [`BATCH_SECONDS`].
    #[default]
    Auto,
    /// This many (at least one).
    Fixed(usize),
}

/// What a device run did besides its [`Solution`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DeviceStats {
    /// Readbacks of the scalar buffer during the iterations (one per batch).
    pub batches: usize,
    /// Readbacks before the first iteration (TV's `‖A‖`).
    pub setup_readbacks: usize,
}

/// The reductions' terms (`TERM_*` in the shader).
#[derive(Clone, Copy)]
enum Term {
    /// `Σ a·b`.
    Dot = 0,
    /// `Σ (a − b)²`.
    Diff = 1,
    /// `Σ b·a²`.
    Weighted = 2,
    /// `Σ |∇a|` (isotropic TV).
    Tv = 3,
}

/// The buffers of one step; `None` binds a dummy.
#[derive(Default, Clone, Copy)]
struct Binds<'a> {
    a: Option<&'a wgpu::Buffer>,
    b: Option<&'a wgpu::Buffer>,
    c: Option<&'a wgpu::Buffer>,
    out: Option<&'a wgpu::Buffer>,
    out2: Option<&'a wgpu::Buffer>,
    list: Option<&'a wgpu::Buffer>,
}

/// The compiled steps, the scalar buffer and an encoder that collects steps until
/// the next projection.
struct Steps<'c> {
    ctx: &'c GpuContext,
    kernels: HashMap<&'static str, Kernel>,
    dummy_read: wgpu::Buffer,
    dummy_write: [wgpu::Buffer; 2],
    scalars: wgpu::Buffer,
    scalar_count: usize,
    partials: wgpu::Buffer,
    base: SolveParams,
    encoder: RefCell<Option<wgpu::CommandEncoder>>,
}

const ENTRIES: [&str; 17] = [
    "residual",
    "weight_rows",
    "reciprocal",
    "mask",
    "sart_update",
    "axpy",
    "direction",
    "normalise",
    "cgls_alpha",
    "cgls_beta",
    "partials",
    "finish",
    "log_entry",
    "midpoint",
    "dual_data",
    "dual_gradient",
    "primal",
];

impl<'c> Steps<'c> {
    fn new(
        ctx: &'c GpuContext,
        dims: [usize; 3],
        per_view: usize,
        longest: usize,
        logs: usize,
    ) -> Result<Self> {
        use wgpu::BufferBindingType as T;
        let ro = T::Storage { read_only: true };
        let rw = T::Storage { read_only: false };
        let program = ctx.program(
            "iterative.wgsl",
            &shader_source(),
            Some(&[
                buffer_entry(0, T::Uniform),
                buffer_entry(1, ro),
                buffer_entry(2, ro),
                buffer_entry(3, ro),
                buffer_entry(4, rw),
                buffer_entry(5, rw),
                buffer_entry(6, rw),
                buffer_entry(7, ro),
            ]),
        )?;
        let mut kernels = HashMap::new();
        for e in ENTRIES {
            kernels.insert(e, program.kernel(ctx, e)?.0);
        }
        let small = |label: &str| {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 16,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            })
        };
        let scalar_count = LOG_BASE + 2 * logs;
        let scalars = vector(ctx, "iterative scalars", scalar_count)?;
        let partials = vector(ctx, "iterative partial sums", longest.div_ceil(CHUNK))?;
        let axes = live_axes(dims);
        let axis = |f: usize| axes.get(f).copied().unwrap_or(0) as u32;
        let base = SolveParams {
            per_view: per_view as u32,
            nx: dims[0] as u32,
            ny: dims[1] as u32,
            nz: dims[2] as u32,
            n_axes: axes.len() as u32,
            axis0: axis(0),
            axis1: axis(1),
            axis2: axis(2),
            ..Default::default()
        };
        Ok(Steps {
            ctx,
            kernels,
            dummy_read: small("dummy read"),
            dummy_write: [small("dummy write 1"), small("dummy write 2")],
            scalars,
            scalar_count,
            partials,
            base,
            encoder: RefCell::new(None),
        })
    }

    /// Records one dispatch of `entry` over `groups` workgroups.
    fn record<'a>(
        &'a self,
        entry: &'static str,
        groups: (u32, u32),
        params: SolveParams,
        binds: Binds<'a>,
    ) {
        let dev = &self.ctx.device;
        let ubuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("iterative params"),
            contents: bytemuck::bytes_of(&params),
            usage: super::context::PARAMS_USAGE,
        });
        let dummy = &self.dummy_read;
        let read = |b: Option<&'a wgpu::Buffer>| b.unwrap_or(dummy).as_entire_binding();
        let kernel = &self.kernels[entry];
        let bind = self.ctx.bind_group(
            entry,
            &kernel.layout,
            &[
                ubuf.as_entire_binding(),
                read(binds.a),
                read(binds.b),
                read(binds.c),
                binds
                    .out
                    .unwrap_or(&self.dummy_write[0])
                    .as_entire_binding(),
                binds
                    .out2
                    .unwrap_or(&self.dummy_write[1])
                    .as_entire_binding(),
                self.scalars.as_entire_binding(),
                read(binds.list),
            ],
        );
        let mut slot = self.encoder.borrow_mut();
        let enc = slot.get_or_insert_with(|| dev.create_command_encoder(&Default::default()));
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(entry),
            timestamp_writes: None,
        });
        pass.set_pipeline(&kernel.pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups(groups.0, groups.1, 1);
    }

    /// A 2-D grid of `groups` workgroups of `size` invocations, and its row stride.
    fn grid(&self, groups: usize, size: u32) -> ((u32, u32), u32) {
        let max_x = self.ctx.limits.max_compute_workgroups_per_dimension.max(1);
        let groups = (groups as u32).max(1);
        let x = groups.min(max_x);
        ((x, groups.div_ceil(x)), x * size)
    }

    /// An element-wise step over `n` values.
    fn each(&self, entry: &'static str, n: usize, params: SolveParams, binds: Binds) {
        let (groups, row_stride) = self.grid((n as u32).div_ceil(WORKGROUP) as usize, WORKGROUP);
        let params = SolveParams {
            n: n as u32,
            row_stride,
            ..params
        };
        self.record(entry, groups, params, binds);
    }

    /// A one-invocation step on the scalars.
    fn scalar(&self, entry: &'static str, params: SolveParams) {
        self.record(entry, (1, 1), params, Binds::default());
    }

    /// `s[slot] ← Σ term` over `n` values of `a` (and `b`).
    fn sum(&self, term: Term, n: usize, a: &wgpu::Buffer, b: Option<&wgpu::Buffer>, slot: u32) {
        let chunks = n.div_ceil(CHUNK).max(1);
        let (groups, row_stride) = self.grid(chunks, REDUCE);
        let params = SolveParams {
            n: n as u32,
            row_stride,
            term: term as u32,
            ..self.base
        };
        let binds = Binds {
            a: Some(a),
            b,
            out: Some(&self.partials),
            ..Default::default()
        };
        self.record("partials", groups, params, binds);
        let params = SolveParams {
            n: chunks as u32,
            slot0: slot,
            ..self.base
        };
        let binds = Binds {
            a: Some(&self.partials),
            ..Default::default()
        };
        self.record("finish", (1, 1), params, binds);
    }

    /// Logs `(√s[rr], f0·s[o1] + f1·s[o2])` and applies the tolerance.
    fn log(&self, rr: u32, (f0, o1): (f64, u32), (f1, o2): (f64, u32), tolerance: f64) {
        self.scalar(
            "log_entry",
            SolveParams {
                slot0: rr,
                slot1: o1,
                slot2: o2,
                f0: f0 as f32,
                f1: f1 as f32,
                f2: tolerance as f32,
                ..self.base
            },
        );
    }

    /// Submits what was recorded.
    fn flush(&self) {
        if let Some(enc) = self.encoder.borrow_mut().take() {
            self.ctx.queue.submit([enc.finish()]);
        }
    }

    /// Copies `src` into `dst` (`n` values), in order with the steps.
    fn copy(&self, src: &wgpu::Buffer, dst: &wgpu::Buffer, n: usize) {
        let mut slot = self.encoder.borrow_mut();
        let enc =
            slot.get_or_insert_with(|| self.ctx.device.create_command_encoder(&Default::default()));
        enc.copy_buffer_to_buffer(src, 0, dst, 0, (n * 4) as u64);
    }

    /// Reads the scalar buffer back (flushing first).
    fn read_scalars(&self) -> Result<Vec<f32>> {
        self.flush();
        let bytes = self
            .ctx
            .read_buffer(&self.scalars, (self.scalar_count * 4) as u64)?;
        Ok(bytemuck::pod_collect_to_vec::<u8, f32>(&bytes))
    }
}

/// A device vector of `n` f32 (storage; copies both ways), refused with a clear error
/// past one storage binding.
fn vector(ctx: &GpuContext, label: &str, n: usize) -> Result<wgpu::Buffer> {
    let bytes = (n.max(1) * 4) as u64;
    ctx.check_storage(label, bytes)?;
    Ok(ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes,
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    }))
}

/// The device vectors and the projections of one run.
struct Run<'p, 'c> {
    pair: &'p GpuJosephPair<'c>,
    steps: Steps<'c>,
    n: usize,
    rays: usize,
    /// The support as 1/0 per voxel (`None`: every voxel).
    keep: Option<wgpu::Buffer>,
    b: wgpu::Buffer,
    all: wgpu::Buffer,
}

impl<'p, 'c> Run<'p, 'c> {
    fn vector(&self, label: &str, n: usize) -> Result<wgpu::Buffer> {
        vector(self.steps.ctx, label, n)
    }

    fn upload(&self, label: &str, values: &[f32]) -> Result<wgpu::Buffer> {
        let buf = self.vector(label, values.len())?;
        if !values.is_empty() {
            self.steps
                .ctx
                .queue
                .write_buffer(&buf, 0, bytemuck::cast_slice(values));
        }
        Ok(buf)
    }

    /// `out ← A x` over the `m` views of `list`.
    fn forward(&self, x: &wgpu::Buffer, list: &wgpu::Buffer, m: usize, out: &wgpu::Buffer) {
        self.steps.flush();
        self.pair.enqueue_forward(x, list, m, out);
    }

    /// `out ← M Aᵀ y` over the `m` views of `list` (`M` the support).
    fn transpose_masked(
        &self,
        y: &wgpu::Buffer,
        list: &wgpu::Buffer,
        m: usize,
        out: &wgpu::Buffer,
    ) -> Result<()> {
        self.steps.flush();
        self.pair.enqueue_transpose(y, list, m, out, false)?;
        self.mask(out);
        Ok(())
    }

    /// `out ← 0` outside the support.
    fn mask(&self, out: &wgpu::Buffer) {
        if let Some(keep) = &self.keep {
            self.steps.each(
                "mask",
                self.n,
                self.steps.base,
                Binds {
                    a: Some(keep),
                    out: Some(out),
                    ..Default::default()
                },
            );
        }
    }

    fn each(&self, entry: &'static str, n: usize, params: SolveParams, binds: Binds) {
        self.steps.each(entry, n, params, binds);
    }
}

/// Paces the batches: counts the iterations queued since the last readback and reads
/// the scalars back when a batch is full.
struct Pacer<'f> {
    batch: Batch,
    size: usize,
    queued: usize,
    started: Instant,
    batches: usize,
    on_batch: &'f mut dyn FnMut(usize, f64) -> Result<()>,
}

impl Pacer<'_> {
    /// After one queued iteration (`last`: the run's last): reads back when the batch
    /// is full; true when the device has stopped.
    fn tick(&mut self, steps: &Steps, last: bool) -> Result<bool> {
        self.queued += 1;
        if self.queued < self.size && !last {
            return Ok(false);
        }
        let s = steps.read_scalars()?;
        self.batches += 1;
        let logged = s[SLOT_LOGGED as usize] as usize;
        let residual = if logged > 0 {
            s[LOG_BASE + 2 * (logged - 1)] as f64
        } else {
            0.0
        };
        (self.on_batch)(logged.saturating_sub(1), residual)?;
        let secs = self.started.elapsed().as_secs_f64();
        if let Batch::Auto = self.batch {
            let per = secs / self.queued as f64;
            self.size = ((BATCH_SECONDS / per.max(1e-9)) as usize).clamp(1, 1 << 16);
        }
        self.queued = 0;
        self.started = Instant::now();
        Ok(s[SLOT_STOP as usize] != 0.0)
    }
}

/// Whether [`solve`] can hold `method`'s problem on `pair`'s device: a whole pair
/// (not [`super::joseph_pair::PairPlan::is_split`]) and, for TV, a dual field within
/// one storage binding. Where it cannot, the iterations run on the host with the
/// pair in pieces ([`crate::cpu::iterative::solve`] over the pair's [`MatchedPair`]).
pub fn fits_on_device(pair: &GpuJosephPair, method: Method) -> bool {
    fits(&pair.plan(), pair.dims(), method, &pair.context().limits)
}

/// [`fits_on_device`] for a pair of `plan` on a grid of `dims` under `limits`,
/// before any pair is made (the dry run).
pub fn fits(
    plan: &super::joseph_pair::PairPlan,
    dims: [usize; 3],
    method: Method,
    limits: &wgpu::Limits,
) -> bool {
    let n: usize = dims.iter().product();
    let tv = (live_axes(dims).len().max(1) * n * 4) as u64;
    !plan.is_split() && (method != Method::Tv || tv <= limits.max_storage_buffer_binding_size)
}

/// [`crate::cpu::iterative::solve`] with the whole iteration on the device of `pair`
/// (module docs): the same options, checks and [`Solution`] (in f32; the log's
/// sums are the device's f32 reductions). `on_batch(iterations, residual)` is
/// called after every batch with the iterations done so far and the last logged
/// residual; an error it returns stops the run.
///
/// # Errors
/// Bad options or sizes ([`Error::Invalid`], as the CPU's); [`Error::TooLarge`]
/// when a vector exceeds one storage binding; [`Error::Gpu`] on device failure;
/// what `on_batch` returns.
pub fn solve(
    pair: &GpuJosephPair,
    prob_b: &[f32],
    support: Option<&[bool]>,
    x0: &[f32],
    opts: &IterativeOptions,
    batch: Batch,
    on_batch: &mut dyn FnMut(usize, f64) -> Result<()>,
) -> Result<(Solution<f32>, DeviceStats)> {
    let prob = Problem {
        pair,
        b: prob_b,
        support,
    };
    check_problem(&prob, x0.len(), opts)?;
    let ctx = pair.context();
    if pair.plan().is_split() {
        return Err(Error::too_large(
            "GPU iterative reconstruction",
            format!(
                "the device-resident solver needs a whole pair, this one is cut ({}): \
                 run crate::cpu::iterative::solve over it",
                pair.plan().describe()
            ),
        ));
    }
    let n = pair.n_voxels();
    let nv = pair.n_views();
    let rays = nv * pair.per_view();
    let axes = live_axes(pair.dims());
    if opts.method == Method::Tv {
        let bytes = (axes.len().max(1) * n * 4) as u64;
        if bytes > ctx.limits.max_storage_buffer_binding_size {
            return Err(Error::too_large(
                "GPU TV reconstruction",
                format!(
                    "its dual field ({} × {n} f32, {bytes} bytes) exceeds the adapter's \
                     storage-binding limit of {} bytes: use a smaller grid or --backend cpu-f32",
                    axes.len(),
                    ctx.limits.max_storage_buffer_binding_size
                ),
            ));
        }
    }
    let logs = opts.iterations + 2;
    let steps = Steps::new(ctx, pair.dims(), pair.per_view(), n.max(rays), logs)?;
    let all: Vec<usize> = (0..nv).collect();
    let mut run = Run {
        pair,
        n,
        rays,
        keep: None,
        b: vector(ctx, "projections", rays)?,
        all: pair.view_list(&all)?,
        steps,
    };
    ctx.queue
        .write_buffer(&run.b, 0, bytemuck::cast_slice(prob_b));
    if let Some(m) = support {
        let ones: Vec<f32> = m.iter().map(|&k| f32::from(u8::from(k))).collect();
        run.keep = Some(run.upload("support", &ones)?);
    }
    let x0: Vec<f32> = match support {
        Some(m) => x0
            .iter()
            .zip(m)
            .map(|(&v, &k)| if k { v } else { 0.0 })
            .collect(),
        None => x0.to_vec(),
    };
    let x = run.upload("image", &x0)?;
    run.steps.ctx.queue.write_buffer(
        &run.steps.scalars,
        0,
        &vec![0u8; run.steps.scalar_count * 4],
    );
    let mut pacer = Pacer {
        batch,
        size: match batch {
            Batch::Auto => 1,
            Batch::Fixed(k) => k.max(1),
        },
        queued: 0,
        started: Instant::now(),
        batches: 0,
        on_batch,
    };
    let mut stats = DeviceStats::default();
    let norm_estimate = match opts.method {
        Method::Sirt => {
            sart(&run, &x, opts, false, &mut pacer)?;
            None
        }
        Method::OsSart => {
            sart(&run, &x, opts, true, &mut pacer)?;
            None
        }
        Method::Cgls => {
            cgls(&run, &x, opts, &mut pacer)?;
            None
        }
        Method::Tv => {
            let norm_a = operator_norm(&run)?;
            stats.setup_readbacks = 1;
            tv(&run, &x, opts, norm_a, &mut pacer)?;
            Some(norm_a)
        }
    };
    stats.batches = pacer.batches;
    let s = run.steps.read_scalars()?;
    let logged = (s[SLOT_LOGGED as usize] as usize).max(1);
    let residual = (0..logged).map(|k| s[LOG_BASE + 2 * k] as f64).collect();
    let objective = (0..logged)
        .map(|k| s[LOG_BASE + 2 * k + 1] as f64)
        .collect();
    let bytes = ctx.read_buffer(&x, (n * 4) as u64)?;
    Ok((
        Solution {
            x: bytemuck::pod_collect_to_vec::<u8, f32>(&bytes),
            residual,
            objective,
            iterations: logged - 1,
            converged: s[SLOT_STOP as usize] != 0.0,
            norm_estimate,
        },
        stats,
    ))
}

/// `r ← b − A x` over the `m` views of `list`.
fn residual(run: &Run, x: &wgpu::Buffer, list: &wgpu::Buffer, m: usize, r: &wgpu::Buffer) {
    run.forward(x, list, m, r);
    let len = m * run.pair.per_view();
    run.each(
        "residual",
        len,
        run.steps.base,
        Binds {
            b: Some(&run.b),
            out: Some(r),
            list: Some(list),
            ..Default::default()
        },
    );
}

/// SIRT (`subsets = false`) and OS-SART, as `cpu::iterative::sart`.
fn sart(
    run: &Run,
    x: &wgpu::Buffer,
    opts: &IterativeOptions,
    subsets: bool,
    pacer: &mut Pacer,
) -> Result<()> {
    let pair = run.pair;
    let (n, rays, pv) = (run.n, run.rays, pair.per_view());
    let steps = &run.steps;
    // Row weights from the support's ones.
    let ones_owned;
    let ones_x = match &run.keep {
        Some(k) => k,
        None => {
            ones_owned = run.upload("ones", &vec![1.0; n])?;
            &ones_owned
        }
    };
    let row_w = run.vector("row weights", rays)?;
    run.forward(ones_x, &run.all, pair.n_views(), &row_w);
    run.each(
        "reciprocal",
        rays,
        steps.base,
        Binds {
            out: Some(&row_w),
            ..Default::default()
        },
    );
    let k = if subsets { opts.subsets } else { 1 };
    let groups: Vec<Vec<usize>> = (0..k).map(|s| subset_views(pair.n_views(), k, s)).collect();
    let lists: Vec<wgpu::Buffer> = if subsets {
        groups
            .iter()
            .map(|v| pair.view_list(v))
            .collect::<Result<_>>()?
    } else {
        Vec::new()
    };
    let list_of = |s: usize| if subsets { &lists[s] } else { &run.all };
    let ones_y = run.upload("ones", &vec![1.0; rays])?;
    let col_w_into = |s: usize, out: &wgpu::Buffer| -> Result<()> {
        run.transpose_masked(&ones_y, list_of(s), groups[s].len(), out)?;
        run.each(
            "reciprocal",
            n,
            steps.base,
            Binds {
                out: Some(out),
                ..Default::default()
            },
        );
        Ok(())
    };
    let keep = keeps_column_weights(k, n, 4);
    let kept: Vec<wgpu::Buffer> = if keep {
        (0..k)
            .map(|s| {
                let buf = run.vector("column weights", n)?;
                col_w_into(s, &buf)?;
                Ok(buf)
            })
            .collect::<Result<_>>()?
    } else {
        Vec::new()
    };
    let scratch = if keep {
        None
    } else {
        Some(run.vector("column weights", n)?)
    };
    let r = run.vector("residual", rays)?;
    let u = run.vector("update", n)?;
    let update = SolveParams {
        f0: opts.relaxation as f32,
        nonnegative: u32::from(opts.nonnegative),
        ..steps.base
    };
    for it in 0..=opts.iterations {
        // The residual of the current iterate (the last pass only logs it).
        residual(run, x, &run.all, pair.n_views(), &r);
        steps.sum(Term::Dot, rays, &r, Some(&r), SLOT_RR);
        steps.sum(Term::Weighted, rays, &r, Some(&row_w), SLOT_WRR);
        steps.log(SLOT_RR, (0.5, SLOT_WRR), (0.0, SLOT_WRR), opts.tolerance);
        if it == opts.iterations {
            pacer.tick(steps, true)?;
            break;
        }
        let order = if subsets {
            subset_order(opts.order, k, it)
        } else {
            vec![0]
        };
        for s in order {
            let (list, m) = (list_of(s), groups[s].len());
            if subsets {
                residual(run, x, list, m, &r);
            }
            let weighted = Binds {
                a: Some(&row_w),
                out: Some(&r),
                list: Some(list),
                ..Default::default()
            };
            run.each("weight_rows", m * pv, steps.base, weighted);
            run.transpose_masked(&r, list, m, &u)?;
            let c = match &scratch {
                Some(buf) => {
                    col_w_into(s, buf)?;
                    buf
                }
                None => &kept[s],
            };
            let binds = Binds {
                a: Some(&u),
                b: Some(c),
                out: Some(x),
                ..Default::default()
            };
            run.each("sart_update", n, update, binds);
        }
        if pacer.tick(steps, false)? {
            break;
        }
    }
    Ok(())
}

/// CGLS, as `cpu::iterative::cgls`.
fn cgls(run: &Run, x: &wgpu::Buffer, opts: &IterativeOptions, pacer: &mut Pacer) -> Result<()> {
    let (n, rays, nv) = (run.n, run.rays, run.pair.n_views());
    let steps = &run.steps;
    let r = run.vector("residual", rays)?;
    let s = run.vector("gradient", n)?;
    let p = run.vector("direction", n)?;
    let q = run.vector("A direction", rays)?;
    residual(run, x, &run.all, nv, &r);
    run.transpose_masked(&r, &run.all, nv, &s)?;
    steps.copy(&s, &p, n);
    steps.sum(Term::Dot, n, &s, Some(&s), SLOT_GAMMA);
    steps.sum(Term::Dot, rays, &r, Some(&r), SLOT_RR);
    steps.log(SLOT_RR, (0.5, SLOT_RR), (0.0, SLOT_RR), opts.tolerance);
    for it in 1..=opts.iterations {
        run.forward(&p, &run.all, nv, &q);
        steps.sum(Term::Dot, rays, &q, Some(&q), SLOT_QQ);
        let scalars = SolveParams {
            slot0: SLOT_GAMMA,
            slot1: SLOT_QQ,
            slot2: SLOT_ALPHA,
            ..steps.base
        };
        steps.scalar("cgls_alpha", scalars);
        let step = |sign: f32, from: &wgpu::Buffer, to: &wgpu::Buffer, len: usize| {
            let params = SolveParams {
                slot0: SLOT_ALPHA,
                f0: sign,
                ..steps.base
            };
            let binds = Binds {
                a: Some(from),
                out: Some(to),
                ..Default::default()
            };
            run.each("axpy", len, params, binds);
        };
        step(1.0, &p, x, n);
        step(-1.0, &q, &r, rays);
        run.transpose_masked(&r, &run.all, nv, &s)?;
        steps.sum(Term::Dot, n, &s, Some(&s), SLOT_GAMMA_NEW);
        let scalars = SolveParams {
            slot0: SLOT_GAMMA,
            slot1: SLOT_GAMMA_NEW,
            slot2: SLOT_BETA,
            ..steps.base
        };
        steps.scalar("cgls_beta", scalars);
        let params = SolveParams {
            slot0: SLOT_BETA,
            ..steps.base
        };
        let binds = Binds {
            a: Some(&s),
            out: Some(&p),
            ..Default::default()
        };
        run.each("direction", n, params, binds);
        steps.sum(Term::Dot, rays, &r, Some(&r), SLOT_RR);
        steps.log(SLOT_RR, (0.5, SLOT_RR), (0.0, SLOT_RR), opts.tolerance);
        if pacer.tick(steps, it == opts.iterations)? {
            break;
        }
    }
    Ok(())
}

/// `‖A‖` by 20 power iterations on `AᵀA` from the support's ones, raised by 1 %, as
/// `cpu::iterative::operator_norm` (one readback, at the end).
fn operator_norm(run: &Run) -> Result<f64> {
    let (n, rays, nv) = (run.n, run.rays, run.pair.n_views());
    let steps = &run.steps;
    let mut v = run.upload("power iterate", &vec![1.0; n])?;
    run.mask(&v);
    let mut w = run.vector("power iterate", n)?;
    let av = run.vector("A power iterate", rays)?;
    for _ in 0..20 {
        steps.sum(Term::Dot, n, &v, Some(&v), SLOT_NORM);
        let params = SolveParams {
            slot0: SLOT_NORM,
            ..steps.base
        };
        run.each(
            "normalise",
            n,
            params,
            Binds {
                out: Some(&v),
                ..Default::default()
            },
        );
        run.forward(&v, &run.all, nv, &av);
        run.transpose_masked(&av, &run.all, nv, &w)?;
        std::mem::swap(&mut v, &mut w);
    }
    steps.sum(Term::Dot, n, &v, Some(&v), SLOT_NORM);
    let s = steps.read_scalars()?;
    // est = √‖w‖ of the last iterate.
    let est = (s[SLOT_NORM as usize] as f64).sqrt().sqrt();
    // Reset the scalars the power iteration used.
    steps
        .ctx
        .queue
        .write_buffer(&steps.scalars, 0, &vec![0u8; steps.scalar_count * 4]);
    Ok(est * 1.01)
}

/// TV by Chambolle–Pock, as `cpu::iterative::tv`.
fn tv(
    run: &Run,
    x: &wgpu::Buffer,
    opts: &IterativeOptions,
    norm_a: f64,
    pacer: &mut Pacer,
) -> Result<()> {
    let (n, rays, nv) = (run.n, run.rays, run.pair.n_views());
    let steps = &run.steps;
    let n_axes = steps.base.n_axes as usize;
    let k = TvSteps::new(norm_a, n_axes, opts.tv_weight);
    let (sigma, tau, mu) = (k.step as f32, k.step as f32, k.mu as f32);
    let p = run.upload("data dual", &vec![0.0; rays])?;
    let q = run.upload("TV dual", &vec![0.0; n_axes.max(1) * n])?;
    let xbar = run.vector("extrapolated image", n)?;
    steps.copy(x, &xbar, n);
    let ax_prev = run.vector("A x", rays)?;
    let axbar = run.vector("A x̄", rays)?;
    let atp = run.vector("Aᵀ p", n)?;
    let log = |ax: &wgpu::Buffer| {
        steps.sum(Term::Diff, rays, ax, Some(&run.b), SLOT_RR);
        steps.sum(Term::Tv, n, x, None, SLOT_TV);
        steps.log(
            SLOT_RR,
            (0.5, SLOT_RR),
            (opts.tv_weight, SLOT_TV),
            opts.tolerance,
        );
    };
    run.forward(x, &run.all, nv, &ax_prev);
    log(&ax_prev);
    for it in 1..=opts.iterations {
        // A x̄ = 2 A x_k − A x_{k−1}: one forward per iteration gives both.
        run.forward(&xbar, &run.all, nv, &axbar);
        if it > 1 {
            let binds = Binds {
                a: Some(&axbar),
                out: Some(&ax_prev),
                ..Default::default()
            };
            run.each("midpoint", rays, steps.base, binds);
            log(&ax_prev);
        }
        let params = SolveParams {
            f0: sigma,
            ..steps.base
        };
        let binds = Binds {
            a: Some(&axbar),
            b: Some(&run.b),
            out: Some(&p),
            ..Default::default()
        };
        run.each("dual_data", rays, params, binds);
        let params = SolveParams {
            f0: sigma * mu,
            f1: k.radius as f32,
            ..steps.base
        };
        let binds = Binds {
            a: Some(&xbar),
            out: Some(&q),
            ..Default::default()
        };
        run.each("dual_gradient", n, params, binds);
        run.transpose_masked(&p, &run.all, nv, &atp)?;
        let params = SolveParams {
            f0: tau,
            f1: mu,
            term: u32::from(run.keep.is_some()),
            nonnegative: u32::from(opts.nonnegative),
            ..steps.base
        };
        let binds = Binds {
            a: Some(&atp),
            b: Some(&q),
            c: run.keep.as_ref(),
            out: Some(x),
            out2: Some(&xbar),
            ..Default::default()
        };
        run.each("primal", n, params, binds);
        if it == opts.iterations {
            // The objective of the last iterate (skipped on the device when stopped).
            run.forward(x, &run.all, nv, &axbar);
            log(&axbar);
        }
        if pacer.tick(steps, it == opts.iterations)? {
            break;
        }
    }
    Ok(())
}
