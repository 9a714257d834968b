//! GPU ramp filtering, backprojection and the whole FBP/FDK against the CPU f64 oracle.

mod common;

use voxlab::cpu::fbp::{backproject, parallel_stack_grid, rtk_grid};
use voxlab::ct::{Geometry, Projections};
use voxlab::metrics::max_abs_error;

fn none(_: usize, _: usize) {}

#[test]
fn gpu_backprojection_matches_the_f64_oracle() {
    let Some(ctx) = common::gpu("gpu_backprojection_matches_the_f64_oracle") else {
        return;
    };
    for (name, g, grid) in common::ct_cases(45, 37) {
        let mut rng = common::Rng(7);
        let mut q = Projections::<f64>::zeros(&g).unwrap();
        for v in &mut q.data {
            *v = rng.unit() * 10.0 - 3.0;
        }
        let want = backproject(&q, &g, &grid, &none).unwrap();
        let q32 = Projections::new(
            q.angles,
            q.rows,
            q.cols,
            q.data.iter().map(|&v| v as f32).collect(),
        )
        .unwrap();
        let got = voxlab::gpu::fbp::backproject(ctx, &q32, &g, &grid).unwrap();
        // Measured worst, relative to the data scale: 6.2e-7 parallel, 8.0e-7 stack,
        // 2.2e-6 cone (f32 projective map and interpolation); views given by vectors:
        // 2.1e-6 tilted cone, 1.4e-6 wobbling cone, 6.4e-7 parallel3d-vec.
        let e = common::assert_parity_array(
            &format!("gpu_backproject_{name}"),
            &grid.dims,
            &want.data,
            &got.data,
            voxlab::metrics::Tolerance::max_abs_rel(1e-5),
        );
        eprintln!("gpu backprojection {name}: max rel {:.2e}", e.max_abs_rel);
    }
}

/// The largest spread of the bilinear cell of (col, row) and of the cells next to it
/// (zeros outside the detector; `common::cells_spread`): the steepest a bilinear value
/// may change where a texture unit's rounded coordinate may land.
fn local_spread(q: &Projections<f64>, view: usize, col: f64, row: f64) -> f64 {
    let v = q.view(view);
    let (c0, r0) = (col.floor() as i64, row.floor() as i64);
    common::cells_spread((q.cols, q.rows), c0 - 1..=c0 + 1, r0 - 1..=r0 + 1, |i| v[i])
}

/// The hardware path (projections in a texture array, bilinear by the texture unit)
/// against the f64 oracle, voxel by voxel, within what a texture unit with 8-bit
/// interpolation weights may add: each weight off by ≤ 2⁻⁸ moves a bilinear value by
/// ≤ 2⁻⁸ × the local spread per axis, so voxel p may be off by
/// π/(2A) · Σ_k w_k(p) · spread_k(p) · 2⁻⁷, plus the exact path's f32 bound. On a CPU
/// adapter (lavapipe filters in f32) it is also held to the exact GPU path: there the
/// only difference is the normalised coordinate `(x + 1.5)/(cols + 2)` rounded to f32.
#[test]
fn hardware_backprojection_is_within_the_texture_units_bound() {
    use voxlab::gpu::fbp::{backproject_planned, BackprojectionPlan};
    use voxlab::gpu::plan::Sampling;
    let Some(ctx) = common::gpu("hardware_backprojection_is_within_the_texture_units_bound") else {
        return;
    };
    if !ctx.features.contains(wgpu::Features::FLOAT32_FILTERABLE) {
        let (_, g, grid) = common::ct_cases(10, 10).remove(0);
        let hardware = Sampling::Hardware;
        let plan = BackprojectionPlan::sampled(&ctx.limits, &g, &grid, hardware).unwrap();
        let q = common::random_projections_f32(&g, 3);
        let e = backproject_planned(ctx, &q, &g, &grid, &plan).unwrap_err();
        assert!(e.to_string().contains("FLOAT32_FILTERABLE"), "{e}");
        return;
    }
    for (name, g, grid) in common::ct_cases(45, 37) {
        let q32 = common::random_projections_f32(&g, 5);
        let q = Projections::new(
            q32.angles,
            q32.rows,
            q32.cols,
            q32.data.iter().map(|&v| v as f64).collect(),
        )
        .unwrap();
        let want = backproject(&q, &g, &grid, &none).unwrap();
        let plan = BackprojectionPlan::sampled(&ctx.limits, &g, &grid, Sampling::Hardware).unwrap();
        let got = backproject_planned(ctx, &q32, &g, &grid, &plan).unwrap();
        let exact = voxlab::gpu::fbp::backproject(ctx, &q32, &g, &grid).unwrap();
        let scale = want.data.iter().fold(0f64, |m, v| m.max(v.abs()));
        let views = g.view_matrices::<f64>();
        let per_scale = std::f64::consts::PI / (2.0 * g.n_angles() as f64);
        let [nx, ny, nz] = grid.dims;
        let (mut worst, mut worst_share) = (0f64, 0f64);
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    let p = grid.point(i, j, k).to_array();
                    let mut sum = 0.0;
                    for (v, m) in views.iter().enumerate() {
                        if let Some((c, r, w)) = m.project(p) {
                            sum += w * local_spread(&q, v, c, r);
                        }
                    }
                    let bound = per_scale * sum / 128.0 + 1e-5 * scale;
                    let at = i + nx * (j + ny * k);
                    let d = (got.data[at] as f64 - want.data[at]).abs();
                    assert!(
                        d <= bound,
                        "{name}: voxel ({i}, {j}, {k}) off by {d:e}, over the texture \
                         unit's bound {bound:e}"
                    );
                    worst = worst.max(d);
                    worst_share = worst_share.max(d / bound);
                }
            }
        }
        let from_exact = max_abs_error(&got.data, &exact.data);
        eprintln!(
            "hardware backprojection {name} on {}: max |Δ| {worst:.2e} ({:.1e} of the \
             scale, {worst_share:.1e} of the bound), {:.1e} of the scale from the exact \
             GPU path",
            ctx.summary.name,
            worst / scale,
            from_exact / scale
        );
        if ctx.summary.is_cpu() {
            // Measured on lavapipe: 4.8e-7 (cone) … 7.4e-7 (stack) of the scale; the
            // bound is about 5× the worst.
            assert!(
                from_exact <= 4e-6 * scale,
                "{name}: {from_exact:e} from the exact GPU path (scale {scale:e})"
            );
        }
    }
}

#[test]
fn gpu_fbp_of_shepp_logan_matches_the_cpu() {
    use voxlab::cpu::fbp::fbp;
    use voxlab::cpu::project::project_phantom;
    use voxlab::cpu::ramp::RampFilter;
    let Some(ctx) = common::gpu("gpu_fbp_of_shepp_logan_matches_the_cpu") else {
        return;
    };
    let ph = voxlab::phantom::Phantom::shepp_logan();
    for (name, g, grid) in [
        (
            "parallel",
            Geometry::parallel_stack(64, 1, 4.0, 4.0, Geometry::even_angles(60, 180.0)).unwrap(),
            None,
        ),
        (
            "fdk",
            Geometry::cone_rtk(
                1000.0,
                1500.0,
                48,
                48,
                8.0,
                8.0,
                Geometry::even_angles(40, 360.0),
            )
            .unwrap(),
            Some(rtk_grid([24; 3], [10.0; 3])),
        ),
        (
            "fdk-vec-tilted",
            common::cone_tilted(
                40,
                1000.0,
                1500.0,
                (48, 48, 8.0, 8.0),
                4.0,
                6.0,
                (9.0, -5.0),
            ),
            Some(rtk_grid([24; 3], [10.0; 3])),
        ),
        (
            "fdk-vec-wobble",
            common::cone_wobble(40, 1000.0, 1500.0, (48, 48, 8.0, 8.0)),
            Some(rtk_grid([24; 3], [10.0; 3])),
        ),
        (
            "parallel3d-vec",
            common::parallel_vec(60, (64, 9, 4.0, 4.0), 12.0, 300.0),
            Some(rtk_grid([48, 9, 48], [4.0; 3])),
        ),
    ] {
        let grid = grid.unwrap_or_else(|| parallel_stack_grid(64, &g));
        let p = project_phantom(&ph, &g).unwrap();
        let want = fbp(&p, &g, RampFilter::Hann, &grid, &none).unwrap();
        let p32 = Projections::new(
            p.angles,
            p.rows,
            p.cols,
            p.data.iter().map(|&v| v as f32).collect(),
        )
        .unwrap();
        let got = voxlab::gpu::fbp::fbp(ctx, &p32, &g, RampFilter::Hann, &grid).unwrap();
        // Measured worst, relative (GPU ramp filter + GPU backprojection, f32): 8.2e-7
        // parallel, 2.3e-6 FDK; views given by vectors: 2.5e-6 tilted cone, 2.7e-6
        // wobbling cone, 1.5e-6 parallel3d-vec.
        let e = common::assert_parity_array(
            &format!("gpu_fbp_{name}"),
            &grid.dims,
            &want.data,
            &got.data,
            voxlab::metrics::Tolerance::max_abs_rel(1e-5),
        );
        eprintln!("gpu fbp {name}: max rel {:.2e}", e.max_abs_rel);
    }
}

/// Every filter × parallel (a 2-row stack) and cone: GPU ramp filtering against the
/// CPU f64 oracle (`FilterMethod::Direct`), relative to the largest filtered value.
#[test]
fn gpu_ramp_filter_matches_the_f64_oracle() {
    use voxlab::cpu::ramp::{filter_projections, FilterMethod, RampFilter};
    let Some(ctx) = common::gpu("gpu_ramp_filter_matches_the_f64_oracle") else {
        return;
    };
    let geometries = [
        (
            "parallel",
            Geometry::parallel_stack(37, 2, 1.5, 1.25, Geometry::even_angles(9, 180.0)).unwrap(),
        ),
        (
            "cone",
            Geometry::cone_rtk(
                300.0,
                450.0,
                40,
                7,
                1.0,
                1.2,
                Geometry::even_angles(5, 360.0),
            )
            .unwrap(),
        ),
        (
            "cone-vec-tilted",
            common::cone_tilted(5, 300.0, 450.0, (40, 7, 1.0, 1.2), 4.0, 6.0, (3.2, -2.1)),
        ),
        (
            "cone-vec-wobble",
            common::cone_wobble(5, 300.0, 450.0, (40, 7, 1.0, 1.2)),
        ),
        (
            "parallel3d-vec",
            common::parallel_vec(9, (37, 2, 1.5, 1.25), 12.0, 40.0),
        ),
    ];
    for filter in RampFilter::ALL {
        for (name, g) in &geometries {
            let mut rng = common::Rng(11);
            let mut p = Projections::<f64>::zeros(g).unwrap();
            for v in &mut p.data {
                *v = rng.unit() * 10.0 - 3.0;
            }
            let want = filter_projections(&p, g, filter, FilterMethod::Direct).unwrap();
            let p32 = Projections::new(
                p.angles,
                p.rows,
                p.cols,
                p.data.iter().map(|&v| v as f32).collect(),
            )
            .unwrap();
            let got = voxlab::gpu::ramp::filter_projections(ctx, &p32, g, filter).unwrap();
            // Measured worst, relative: 2.3e-7 (ramp, cone); every case 1.3e-7 … 2.3e-7
            // (f32 pre-weighting, FFTs and response); views given by vectors 1.3e-7 …
            // 2.6e-7 (their weights are computed in f32 on the device).
            let e = common::assert_parity_array(
                &format!("gpu_ramp_{}_{name}", filter.name()),
                &[want.cols, want.rows, want.angles],
                &want.data,
                &got.data,
                voxlab::metrics::Tolerance::max_abs_rel(1e-6),
            );
            eprintln!(
                "gpu ramp {} {name}: max rel {:.2e}",
                filter.name(),
                e.max_abs_rel
            );
        }
    }
}

/// The split plans the tests run: (slices per slab, views per batch). Batches of a
/// multiple of 32 views keep the unsplit path's per-dispatch sums; 7 regroups them.
const SPLITS: [(usize, usize); 5] = [(1, 1000), (4, 32), (5, 64), (1000, 32), (3, 7)];

#[test]
fn gpu_backprojection_in_slabs_and_batches_equals_the_unsplit_one() {
    use voxlab::gpu::fbp::{backproject_timed, BackprojectionPlan};
    use voxlab::gpu::plan::Pieces;
    use voxlab::gpu::plan::Sampling;
    let Some(ctx) = common::gpu("gpu_backprojection_in_slabs_and_batches_equals_the_unsplit_one")
    else {
        return;
    };
    let mut samplings = vec![Sampling::Exact];
    if ctx.features.contains(wgpu::Features::FLOAT32_FILTERABLE) {
        samplings.push(Sampling::Hardware);
    }
    for (name, g, grid) in common::ct_cases(75, 70) {
        let q = common::random_projections_f32(&g, 11);
        for &sampling in &samplings {
            let unsplit = BackprojectionPlan::sampled(&ctx.limits, &g, &grid, sampling).unwrap();
            assert!(!unsplit.is_split());
            let whole = backproject_timed(ctx, &q, &g, &grid, &unsplit).unwrap().0;
            let scale = whole.data.iter().fold(0f32, |m, v| m.max(v.abs()));
            for (slices, views) in SPLITS {
                let plan = BackprojectionPlan {
                    slabs: Pieces {
                        total: grid.dims[2],
                        per_piece: slices.min(grid.dims[2]),
                    },
                    batches: Pieces {
                        total: g.n_angles(),
                        per_piece: views.min(g.n_angles()),
                    },
                    device_bytes: 0,
                    sampling,
                };
                let (got, timings) = backproject_timed(ctx, &q, &g, &grid, &plan).unwrap();
                let what = format!("{name}: {}", plan.describe());
                // One submission per slab and batch, one dispatch per 32 views of a batch.
                let per_slab: usize = plan.batches.ranges().map(|b| b.len().div_ceil(32)).sum();
                assert_eq!(
                    (timings.submissions, timings.dispatches),
                    (
                        plan.slabs.count() * plan.batches.count(),
                        plan.slabs.count() * per_slab
                    ),
                    "{what}"
                );
                let timestamps = ctx.features.contains(wgpu::Features::TIMESTAMP_QUERY);
                assert_eq!(timings.kernel.is_some(), timestamps, "{what}");
                assert!(
                    timings.kernel.is_none_or(|k| k > 0.0),
                    "{what}: {timings:?}"
                );
                if views % 32 == 0 {
                    let first = got.data.iter().zip(&whole.data).position(|(a, b)| a != b);
                    assert_eq!(first, None, "{what}: differs from the unsplit volume");
                } else {
                    // Sums of 7 views instead of 32: a reassociation of f32 additions.
                    let worst = max_abs_error(&got.data, &whole.data);
                    assert!(worst <= 1e-5 * scale as f64, "{what}: {worst} of {scale}");
                }
            }
        }
    }
}

#[test]
fn the_backprojection_plan_cuts_what_exceeds_a_binding_and_refuses_what_cannot_fit() {
    use voxlab::gpu::fbp::BackprojectionPlan;
    use voxlab::gpu::plan::Sampling;
    // 40 × 30 detector, 100 views; a 21 × 15 × 18 grid: slices of 1,260 bytes, views
    // of 4,800 bytes.
    let (_, g, grid) = common::ct_cases(10, 100).remove(2);
    let limits = |bytes: u64| wgpu::Limits {
        max_storage_buffer_binding_size: bytes,
        ..wgpu::Limits::default()
    };
    let whole = BackprojectionPlan::new(&limits(1 << 27), &g, &grid).unwrap();
    assert!(!whole.is_split());
    // 40 views fit 192,000 bytes: batches of 32 (aligned), slabs of all 18 slices.
    let p = BackprojectionPlan::new(&limits(192_000), &g, &grid).unwrap();
    assert_eq!((p.batches.per_piece, p.batches.count()), (32, 4));
    assert_eq!((p.slabs.per_piece, p.slabs.count()), (18, 1));
    // 12,600 bytes: 10 slices per slab, 2 slabs; 2 views per batch (fewer than 32).
    let p = BackprojectionPlan::new(&limits(12_600), &g, &grid).unwrap();
    assert_eq!((p.slabs.per_piece, p.slabs.count()), (10, 2));
    assert_eq!((p.batches.per_piece, p.batches.count()), (2, 50));
    assert_eq!(
        p.describe(),
        "backprojection in 2 slabs of 10 slices × 50 batches of 2 views"
    );
    // One view (4,800 bytes) no longer fits.
    let e = BackprojectionPlan::new(&limits(4_000), &g, &grid).unwrap_err();
    assert!(e.to_string().contains("one view (4800 bytes)"), "{e}");
    let e = BackprojectionPlan::new(&limits(1_000), &g, &grid).unwrap_err();
    assert!(e.to_string().contains("slice of the volume"), "{e}");

    // Projections in textures: a view is (40 + 2) × (30 + 2) texels, 5,376 bytes, and a
    // batch at most the adapter's texture-array layers.
    let hardware =
        |limits: &wgpu::Limits| BackprojectionPlan::sampled(limits, &g, &grid, Sampling::Hardware);
    let p = hardware(&limits(1 << 27)).unwrap();
    assert!(!p.is_split());
    assert_eq!(
        p.device_bytes,
        100 * 64 + 100 * 5_376 + 21 * 15 * 18 * 4,
        "matrices, the views with their borders, the volume"
    );
    // 192,000 bytes hold 35 bordered views: batches of 32.
    let p = hardware(&limits(192_000)).unwrap();
    assert_eq!((p.batches.per_piece, p.batches.count()), (32, 4));
    assert_eq!(
        p.describe(),
        "backprojection in 1 slab of 18 slices × 4 batches of 32 views, projections in \
         textures"
    );
    let layers = |n: u32| wgpu::Limits {
        max_texture_array_layers: n,
        ..limits(1 << 27)
    };
    let p = hardware(&layers(64)).unwrap();
    assert_eq!((p.batches.per_piece, p.batches.count()), (64, 2));
    let p = hardware(&layers(20)).unwrap();
    assert_eq!((p.batches.per_piece, p.batches.count()), (20, 5));
    // A detector whose bordered image exceeds the 2-D texture size: refused, naming
    // the way out; the exact path still plans it.
    let small = wgpu::Limits {
        max_texture_dimension_2d: 41,
        ..limits(1 << 27)
    };
    let e = hardware(&small).unwrap_err();
    assert!(
        e.to_string().contains("40 × 30") && e.to_string().contains("2-D texture size of 41"),
        "{e}"
    );
    assert!(BackprojectionPlan::new(&small, &g, &grid).is_ok());
}

/// Views given by vectors filtered in chunks (each chunk reads its views' weights
/// from the table at its first view) equal the unchunked filtering value for value.
#[test]
fn gpu_ramp_filter_of_views_in_chunks_equals_the_unchunked_one() {
    use voxlab::cpu::ramp::RampFilter;
    use voxlab::gpu::ramp::{filter_projections, RampPlan};
    let Some(ctx) = common::gpu("gpu_ramp_filter_of_views_in_chunks_equals_the_unchunked_one")
    else {
        return;
    };
    // An even number of rows keeps the pairs of lines that share a complex FFT the
    // same in every chunking.
    let g = common::cone_wobble(11, 300.0, 450.0, (40, 8, 1.0, 1.2));
    let p = common::random_projections_f32(&g, 3);
    let whole = filter_projections(ctx, &p, &g, RampFilter::RamLak).unwrap();
    let mut small = voxlab::gpu::GpuContext::new().unwrap();
    // Two views' packed lines (8 rows paired into 4 lines of 128 complex values, 4 KiB
    // a view).
    small.limits.max_storage_buffer_binding_size = 8 * 1024;
    let plan = RampPlan::new(&small.limits, &g).unwrap();
    assert!(plan.chunks(g.n_angles()) > 3, "{plan:?}");
    let chunked = filter_projections(&small, &p, &g, RampFilter::RamLak).unwrap();
    assert_eq!(chunked.data, whole.data);
}
