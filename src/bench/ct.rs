//! Benchmark cases of the CT family: Joseph forward projection (`project`), parallel
//! filtered backprojection (`fbp`) and cone-beam FDK (`fdk`).
//!
//! **project.** The modified Shepp–Logan phantom sampled on an `n³` grid
//! ([`crate::cpu::project::Grid::phantom`]) projected with Joseph's method
//! ([`crate::cpu::project::project_volume`], f64 oracle and f32 baseline;
//! [`crate::gpu::project::project_volume_timed`]) in two geometries ([`project_scene`]):
//! a cone beam in RTK's convention (SID 1000 mm, SDD 1500 mm, 360°, `n × n` detector
//! of `384/n` mm pixels: a 256 mm field at the isocentre) and a parallel stack (180°,
//! `n × n` detector of `256/n` mm pixels). Work: rays (detector pixels × views) and
//! samples (the bilinear samples Joseph's sum takes: one per index plane the clipped
//! ray crosses, counted by [`joseph_samples`] with the projector's own clipping).
//!
//! **fbp.** Parallel FBP ([`crate::cpu::fbp::fbp`], Ram-Lak ramp via the FFT, then
//! backprojection) of an `n²` slice from 402 views over 180° of exact Shepp–Logan line
//! integrals ([`crate::cpu::project::project_phantom`], the phantom scaled to fill the
//! image, 1 mm bins, scikit-image's geometry and output grid): [`fbp_scene`]. The GPU
//! runs [`crate::gpu::fbp::fbp`] (GPU ramp filter, then the backprojection
//! dispatches). Work: voxel updates = pixels × views.
//!
//! **fdk.** FDK of an `n³` volume (RTK's centred grid, `256/n` mm voxels) from `views`
//! cone-beam views over 360° of an `n × n` detector (`512/n` mm pixels, SID 1000 mm,
//! SDD 1500 mm) of the exact Shepp–Logan projections: [`fdk_scene`]. Work: voxel
//! updates = voxels × views.
//!
//! CPU times are the whole reconstruction or projection (filtering included; the
//! input conversion to f32 is done once, untimed). The GPU kernel time is that of the
//! backprojection's or projection's dispatches on the device, from timestamp queries
//! ([`crate::gpu::fbp::backproject_timed`], [`crate::gpu::project::ProjectTimings`]);
//! on an adapter without them, the wall clock of the step. Set-up (shader compilation,
//! uploads) is inside the end-to-end figure; see each case's note.
//!
//! `cargo bench --bench project` and `--bench ct` build their scenes with the same
//! constructors.

use super::case::flat;
use super::{Case, GpuRun, Prepared, Run, Suite, Unit, Work};
use crate::cpu::fbp::{fbp, rtk_grid, skimage_grid, Grid as FbpGrid};
use crate::cpu::project::{
    joseph_views, pixel_ray, project_phantom, project_volume, Grid, JosephView, ProjectOptions,
};
use crate::cpu::ramp::{FilterMethod, RampFilter};
use crate::ct::{Beam, Geometry, Projections};
use crate::error::Result;
use crate::gpu::plan::Sampling;
use crate::gpu::project::ProjectionPlan;
use crate::gpu::GpuContext;
use crate::metrics::Tolerance;
use crate::phantom::Phantom;
use glam::DMat4;
use rayon::prelude::*;
use std::sync::Arc;
use std::time::Instant;

/// The views of the parallel FBP cases (scikit-image's classic 402 over 180°).
pub const FBP_VIEWS: usize = 402;

/// The geometry of a projection case: `n × n` detector pixels, `views` views; a cone
/// beam (SID 1000 mm, SDD 1500 mm, 360°, `384/n` mm pixels: 256 mm at the isocentre)
/// or a parallel stack (180°, `256/n` mm pixels).
///
/// # Errors
/// For `n` or `views` of 0.
pub fn project_geometry(n: usize, views: usize, cone: bool) -> Result<Geometry> {
    if cone {
        let d = 384.0 / n as f64;
        Geometry::cone_rtk(
            1000.0,
            1500.0,
            n,
            n,
            d,
            d,
            Geometry::even_angles(views, 360.0),
        )
    } else {
        let d = 256.0 / n as f64;
        Geometry::parallel_stack(n, n, d, d, Geometry::even_angles(views, 180.0))
    }
}

/// A projection case: the modified Shepp–Logan phantom on an `n³` grid (f64) and
/// [`project_geometry`].
///
/// # Errors
/// As [`project_geometry`].
pub fn project_scene(n: usize, views: usize, cone: bool) -> Result<(Grid<f64>, Geometry)> {
    let grid = Grid::<f64>::phantom(&Phantom::shepp_logan_modified(), [n; 3])?;
    Ok((grid, project_geometry(n, views, cone)?))
}

/// A parallel FBP case: exact projections of Shepp–Logan scaled to fill an `n²` image
/// (1 mm bins), `views` views over 180° (scikit-image's geometry), and its output
/// grid.
///
/// # Errors
/// For `n` or `views` of 0.
pub fn fbp_scene(n: usize, views: usize) -> Result<(Projections<f64>, Geometry, FbpGrid)> {
    let g = Geometry::parallel_skimage(n, Geometry::even_angles(views, 180.0))?;
    let mut ph = Phantom::shepp_logan();
    ph.half_extent_mm = n as f64 / 2.0;
    let p = project_phantom(&ph, &g)?;
    Ok((p, g, skimage_grid(n)))
}

/// An FDK case: exact cone-beam projections of Shepp–Logan on an `n × n` detector
/// (`512/n` mm pixels, SID 1000 mm, SDD 1500 mm), `views` views over 360°, and RTK's
/// centred `n³` grid of `256/n` mm voxels.
///
/// # Errors
/// For `n` or `views` of 0.
pub fn fdk_scene(n: usize, views: usize) -> Result<(Projections<f64>, Geometry, FbpGrid)> {
    let d = 512.0 / n as f64;
    let g = Geometry::cone_rtk(
        1000.0,
        1500.0,
        n,
        n,
        d,
        d,
        Geometry::even_angles(views, 360.0),
    )?;
    let p = project_phantom(&Phantom::shepp_logan(), &g)?;
    Ok((p, g, rtk_grid([n; 3], [256.0 / n as f64; 3])))
}

/// The bilinear samples Joseph's projector takes for every ray of `g` through a grid
/// of `dims` placed by `affine`: per ray, the index planes of its dominant axis between
/// the clipped entry and exit — the loop bounds of `cpu::project::joseph_ray`
/// (mirrored here in f64, the oracle's precision).
pub fn joseph_samples(dims: [usize; 3], affine: DMat4, g: &Geometry) -> f64 {
    let views: Vec<JosephView<f64>> = joseph_views(g, affine);
    let (rows, cols) = (g.rows, g.cols);
    views
        .par_iter()
        .map(|v| {
            let mut n = 0u64;
            for r in 0..rows {
                for c in 0..cols {
                    let (o, d, t_min) = pixel_ray(v, c as f64, r as f64);
                    n += ray_planes(dims, o, d, t_min);
                }
            }
            n as f64
        })
        .sum()
}

/// Narrows `[lo, hi]` to the planes where `x0 + s·k` lies in `(−1, n)` (as
/// `cpu::project::clip_planes`).
fn clip(x0: f64, k: f64, n: usize, lo: &mut f64, hi: &mut f64) -> bool {
    let n = n as f64;
    if k.abs() > 1e-20 {
        let (s1, s2) = ((-1.0 - x0) / k, (n - x0) / k);
        *lo = lo.max(s1.min(s2));
        *hi = hi.min(s1.max(s2));
    } else if !(x0 > -1.0 && x0 < n) {
        return false;
    }
    *lo <= *hi
}

/// The number of planes `joseph_ray` sums over for one ray.
fn ray_planes(dims: [usize; 3], o: [f64; 3], d: [f64; 3], t_min: f64) -> u64 {
    let ad = d.map(f64::abs);
    let (m, a, b) = if ad[0] >= ad[1] && ad[0] >= ad[2] {
        (0, 1, 2)
    } else if ad[1] >= ad[2] {
        (1, 0, 2)
    } else {
        (2, 0, 1)
    };
    if ad[m] == 0.0 {
        return 0;
    }
    let (ka, kb) = (d[a] / d[m], d[b] / d[m]);
    let (xa0, xb0) = (o[a] - o[m] * ka, o[b] - o[m] * kb);
    let (mut lo, mut hi) = (0.0, (dims[m] - 1) as f64);
    if !clip(xa0, ka, dims[a], &mut lo, &mut hi) || !clip(xb0, kb, dims[b], &mut lo, &mut hi) {
        return 0;
    }
    let s_min = o[m] + t_min * d[m];
    if d[m] > 0.0 {
        lo = lo.max(s_min);
    } else {
        hi = hi.min(s_min);
    }
    if lo > hi {
        return 0;
    }
    let (s0, s1) = (lo.ceil(), hi.floor());
    if s1 < s0 {
        0
    } else {
        (s1 - s0) as u64 + 1
    }
}

/// The CT cases of `suite`.
///
/// Full sizes and the CPU time they cost: the f64 oracle and the f32 baseline dominate
/// (each runs a warm-up and several timed runs). On two quiet cores FDK 128³ from 180
/// views takes 3.8 s (`docs/bench/ct-lavapipe.md`) and Joseph's 128³ → 180 × 128²
/// about as long, so on 16 cores about 0.5 s each; 256³ from 360 views would be 16×
/// that, about 9 s a run and over a minute and a half per case for the two CPU
/// backends. The 256³ projection and FDK cases therefore take 180 views (half the
/// work; 256² detectors kept), which keeps the five families under about four minutes
/// on a 16-core machine.
pub fn cases(suite: Suite) -> Vec<Case> {
    // (side, views) of each family's cases.
    type Sizes = &'static [(usize, usize)];
    let (project, fbps, fdks): (Sizes, Sizes, Sizes) = match suite {
        Suite::Quick => (&[(16, 12)], &[(32, 45)], &[(16, 30)]),
        Suite::Full => (
            &[(128, 180), (256, 180)],
            &[(256, FBP_VIEWS), (512, FBP_VIEWS)],
            &[(128, 180), (256, 180)],
        ),
    };
    let mut out = Vec::new();
    for &(n, views) in project {
        for (cone, sampling) in [
            (false, Sampling::Exact),
            (true, Sampling::Exact),
            (true, Sampling::Hardware),
        ] {
            let name = match (cone, sampling) {
                (false, _) => "parallel",
                (true, Sampling::Exact) => "cone",
                (true, Sampling::Hardware) => "cone-hardware",
            };
            out.push(Case::new(
                "project",
                name,
                format!("{n}³ → {views} × {n}²"),
                move || prepare_project(n, views, cone, sampling),
            ));
        }
    }
    for &(n, views) in fbps {
        out.push(Case::new(
            "fbp",
            "parallel-ramlak",
            format!("{n}² from {views} views"),
            move || prepare_fbp(n, views),
        ));
    }
    for &(n, views) in fdks {
        for sampling in [Sampling::Exact, Sampling::Hardware] {
            let name = match sampling {
                Sampling::Exact => "cone-ramlak",
                Sampling::Hardware => "cone-ramlak-hardware",
            };
            out.push(Case::new(
                "fdk",
                name,
                format!("{n}³ from {views} × {n}²"),
                move || prepare_fdk(n, views, sampling),
            ));
        }
    }
    out
}

fn prepare_project(n: usize, views: usize, cone: bool, sampling: Sampling) -> Result<Prepared> {
    let (g64, g) = project_scene(n, views, cone)?;
    let g32 = Grid::<f32>::new(g64.dims, g64.affine, g64.to_f32())?;
    let rays = (g.n_angles() * g.rows * g.cols) as f64;
    let samples = joseph_samples(g64.dims, g64.affine, &g);
    let tol = project_tol(&g, n);
    let tol_gpu = match sampling {
        Sampling::Exact => tol,
        Sampling::Hardware => hardware_project_tol(&g64, &g, tol),
    };
    let g = Arc::new(g);
    let (ga, gb, gc) = (Arc::clone(&g), Arc::clone(&g), g);
    let g32 = Arc::new(g32);
    let g32b = Arc::clone(&g32);
    let gpu = move |ctx: &GpuContext| -> Result<GpuRun> {
        let plan = ProjectionPlan::sampled(&ctx.limits, &gc, g32b.dims, sampling)?;
        let (p, t) = crate::gpu::project::project_volume_planned(
            ctx,
            &g32b,
            &gc,
            &ProjectOptions::default(),
            &plan,
        )?;
        Ok(GpuRun {
            output: flat(&p.data),
            kernel: t.kernel.unwrap_or(t.project),
            kernel_from_timestamps: t.kernel.is_some(),
            end_to_end: t.total,
            setup: t.setup,
        })
    };
    Ok(Prepared {
        cpu_f64: Box::new(move || {
            let t = Instant::now();
            let p = project_volume(&g64, &ga, &ProjectOptions::default())?;
            let seconds = t.elapsed().as_secs_f64();
            Ok(Run {
                seconds,
                output: p.data,
            })
        }),
        cpu_f32: Some(Box::new(move || {
            let t = Instant::now();
            let p = project_volume(&g32, &gb, &ProjectOptions::default())?;
            let seconds = t.elapsed().as_secs_f64();
            Ok(Run {
                seconds,
                output: flat(&p.data),
            })
        })),
        gpu: Some(Box::new(gpu)),
        tol_f32: tol,
        tol_gpu,
        work: vec![
            Work {
                amount: rays,
                unit: Unit::Rays,
            },
            Work {
                amount: samples,
                unit: Unit::Samples,
            },
        ],
        note: format!(
            "Joseph projection of the modified Shepp–Logan phantom on {n}³ voxels, {} beam. \
             Samples = bilinear samples summed ({:.1} per ray). GPU: kernel = the dispatches \
             on the device (timestamp queries; without them, dispatches + per-chunk \
             readbacks, wall clock); end to end = everything, set-up (shader \
             compilation, grid and view uploads) included.",
            if cone { "cone" } else { "parallel" },
            samples / rays
        ) + match sampling {
            Sampling::Exact => "",
            Sampling::Hardware => {
                " GPU: the projector samples the grid from a 3-D texture through the \
                 texture unit (hardware trilinear; gpu::plan::Sampling::Hardware); the \
                 GPU bound is max |Δ| ≤ gpu::project::hardware_error_bound for 8-bit \
                 weights."
            }
        },
    })
}

/// Tolerance of the Joseph projections (f32 CPU and GPU against the f64 oracle) of an
/// `n³` grid in `g`. Both round the ray to f32: a sample position is off by about
/// `ε·D` voxels, `D` the distance of the ray's origin from the grid in voxels (the
/// source for a cone beam, `SID·n/256`; about `n` for a parallel beam), and the error
/// of a sample across a phantom edge grows with it. The bounds of
/// `tests/gpu_ct_project.rs` (max 5e-5, rel L2 7e-6, for `D` ≤ 190) grow with `D`
/// beyond: max `max(5e-5, 3e-7·D)`, rel L2 `max(7e-6, 3e-8·D)`. Measured on lavapipe
/// (CPU f32 and GPU alike): cone 16³ (D = 62) 3.8e-6 / 9.3e-7; parallel 16³ 2.3e-6 /
/// 4.2e-7; cone 128³ (D = 500) 4.0e-5 / 2.3e-6; parallel 128³ 8.8e-6 / 7.3e-7.
pub fn project_tol(g: &Geometry, n: usize) -> Tolerance {
    let d = match g.beam {
        Beam::Cone { sid, .. } => sid * n as f64 / 256.0,
        Beam::Parallel => n as f64,
    };
    Tolerance::max_abs_rel((3e-7 * d).max(5e-5)).with_rel_l2((3e-8 * d).max(7e-6))
}

/// The hardware projector's tolerance: [`crate::gpu::project::hardware_error_bound`]
/// for weights of 8 fractional bits (NVIDIA's), plus the exact path's `exact` taken
/// against the largest value a ray can reach ([`crate::gpu::project::longest_ray`]
/// times the largest voxel), as one bound on max |Δ|.
fn hardware_project_tol(grid: &Grid<f64>, g: &Geometry, exact: Tolerance) -> Tolerance {
    let bound = crate::gpu::project::hardware_error_bound(grid, g, 8);
    let top = grid.data.iter().fold(0f64, |m, v| m.max(v.abs()));
    let reach = crate::gpu::project::longest_ray(grid, g) * top;
    Tolerance::max_abs(bound + exact.max_abs_rel * reach)
}

/// Tolerance of FBP/FDK in f32 (CPU and GPU) against the f64 oracle for an `n²` image
/// or `n³` volume. The tests' bound (1e-5 of the data scale, `tests/ct_fbp.rs`,
/// `tests/gpu_ct_fbp.rs`, at n ≤ 64) does not hold at benchmark sizes: the f32
/// rounding of the line integrals (which grow with `n` here: the phantom fills the
/// field) passes through the ramp filter, and the error grows about linearly with
/// `n`. Bounds: max `max(1e-5, 1.5e-7·n)`, rel L2 `max(5e-6, 1e-7·n)`. Measured on
/// lavapipe (CPU f32; GPU): FBP 32² 1.4e-6 / 1.4e-6; 7.9e-7 / 9.9e-7; FBP 256²
/// 6.8e-6 / 3.2e-6; 3.4e-6 / 2.0e-6; FBP 512² 1.4e-5 / 6.0e-6; 7.3e-6 / 3.9e-6;
/// FDK 16³ 9.6e-7 / 8.1e-7; 7.8e-7 / 6.4e-7; FDK 128³ 6.3e-6 / 3.6e-6; 4.2e-6 /
/// 2.8e-6.
pub fn recon_tol(n: usize) -> Tolerance {
    Tolerance::max_abs_rel((1.5e-7 * n as f64).max(1e-5)).with_rel_l2((1e-7 * n as f64).max(5e-6))
}

/// The hardware path's tolerance: [`crate::gpu::fbp::hardware_error_bound`] for
/// weights of 8 fractional bits (NVIDIA's) on the f64-filtered projections, plus the
/// exact path's [`recon_tol`] taken against a peak of 2 (the modified Shepp–Logan's
/// densities are at most 1, and its FDK overshoots them by a few per cent), as one
/// bound on max |Δ|.
fn hardware_recon_tol(
    n: usize,
    p: &Projections<f64>,
    g: &Geometry,
    grid: &FbpGrid,
) -> Result<Tolerance> {
    let q = crate::cpu::ramp::filter_projections(p, g, RampFilter::RamLak, FilterMethod::Fft)?;
    let bound = crate::gpu::fbp::hardware_error_bound(&q, g, grid, 8);
    Ok(Tolerance::max_abs(bound + 2.0 * recon_tol(n).max_abs_rel))
}

fn to_f32(p: &Projections<f64>) -> Result<Projections<f32>> {
    Projections::new(
        p.angles,
        p.rows,
        p.cols,
        p.data.iter().map(|&v| v as f32).collect(),
    )
}

fn none(_: usize, _: usize) {}

/// FBP or FDK of `p` onto `grid`: the prepared closures; the GPU backprojection reads
/// the projections as `sampling` says.
fn prepare_recon(
    n: usize,
    p: Projections<f64>,
    g: Geometry,
    grid: FbpGrid,
    work: f64,
    note: String,
    sampling: Sampling,
) -> Result<Prepared> {
    let tol_gpu = match sampling {
        Sampling::Exact => recon_tol(n),
        Sampling::Hardware => hardware_recon_tol(n, &p, &g, &grid)?,
    };
    let p32 = Arc::new(to_f32(&p)?);
    let p32b = Arc::clone(&p32);
    let g = Arc::new(g);
    let (ga, gb, gc) = (Arc::clone(&g), Arc::clone(&g), g);
    let gpu = move |ctx: &GpuContext| -> Result<GpuRun> {
        let t = Instant::now();
        let q = crate::gpu::ramp::filter_projections(ctx, &p32b, &gc, RampFilter::RamLak)?;
        let tb = Instant::now();
        let plan = crate::gpu::fbp::BackprojectionPlan::sampled(&ctx.limits, &gc, &grid, sampling)?;
        let (v, timings) = crate::gpu::fbp::backproject_timed(ctx, &q, &gc, &grid, &plan)?;
        let back = tb.elapsed().as_secs_f64();
        Ok(GpuRun {
            output: flat(&v.data),
            kernel: timings.kernel.unwrap_or(back),
            kernel_from_timestamps: timings.kernel.is_some(),
            end_to_end: t.elapsed().as_secs_f64(),
            setup: 0.0,
        })
    };
    Ok(Prepared {
        cpu_f64: Box::new(move || {
            let t = Instant::now();
            let v = fbp(&p, &ga, RampFilter::RamLak, &grid, &none)?;
            let seconds = t.elapsed().as_secs_f64();
            Ok(Run {
                seconds,
                output: v.data,
            })
        }),
        cpu_f32: Some(Box::new(move || {
            let t = Instant::now();
            let v = fbp(&p32, &gb, RampFilter::RamLak, &grid, &none)?;
            let seconds = t.elapsed().as_secs_f64();
            Ok(Run {
                seconds,
                output: flat(&v.data),
            })
        })),
        gpu: Some(Box::new(gpu)),
        tol_f32: recon_tol(n),
        tol_gpu,
        work: vec![Work {
            amount: work,
            unit: Unit::VoxelUpdates,
        }],
        note: format!(
            "{note} Ram-Lak ramp filter (FFT) and backprojection, timed together. GPU: \
             ramp filter and backprojection on the device; kernel = the backprojection's \
             dispatches on the device (timestamp queries; where the adapter has none, the \
             wall clock of the backprojection step with its shader compilation, upload and \
             readback), end to end = both steps; gpu::fbp keeps no separate set-up (0 \
             here)."
        ),
    })
}

fn prepare_fbp(n: usize, views: usize) -> Result<Prepared> {
    let (p, g, grid) = fbp_scene(n, views)?;
    let work = (n * n * views) as f64;
    let note = format!(
        "Parallel FBP of exact Shepp–Logan projections ({views} views over 180°, {n} bins \
         of 1 mm) onto scikit-image's {n}² grid. Voxel updates = {n}² × {views}."
    );
    prepare_recon(n, p, g, grid, work, note, Sampling::Exact)
}

fn prepare_fdk(n: usize, views: usize, sampling: Sampling) -> Result<Prepared> {
    let (p, g, grid) = fdk_scene(n, views)?;
    let work = (n * n * n * views) as f64;
    let note = format!(
        "FDK of exact Shepp–Logan cone-beam projections ({views} views over 360°, {n}² \
         detector, SID 1000 mm, SDD 1500 mm) onto RTK's centred {n}³ grid. Voxel updates \
         = {n}³ × {views}."
    );
    let note = match sampling {
        Sampling::Exact => note,
        Sampling::Hardware => format!(
            "{note} GPU: the backprojection samples the filtered projections from a 2-D \
             texture array through the texture unit (hardware bilinear; gpu::plan::\
             Sampling::Hardware); the GPU bound is max |Δ| ≤ \
             gpu::fbp::hardware_error_bound for 8-bit weights."
        ),
    };
    prepare_recon(n, p, g, grid, work, note, sampling)
}
