//! The GPU volume processing (`gpu::process`) against the f64 CPU oracle
//! (`cpu::process`), over one case list, and the GPU-only refusals.

mod common;

use glam::DVec3;
use voxlab::cpu::process::{self as cp, Field, Region, ResampleSpec};
use voxlab::gpu::process as gp;
use voxlab::gpu::GpuContext;
use voxlab::phantom::Phantom;
use voxlab::settings::Filter;
use voxlab::{Error, Volume};

/// Largest `max |gpu − cpu| / max |cpu|` allowed for resampling, the Gaussian and the
/// gradient magnitude (f32 sample coordinates, weights and sums against f64). Measured
/// on lavapipe over the cases below: resampling of the whole volume and index boxes
/// 6.8e-7 … 1.7e-6, world boxes 2.4e-6 … 3.1e-6 (worst: Catmull–Rom; the f32 sample
/// position is off by ~1e-6 voxel, which the phantom's unit steps turn into value
/// error), Gaussian 1.9e-7 … 3.1e-7, gradient magnitude 1.7e-7. The bound leaves a
/// factor of about 6 over the worst.
const TOL_MAX_REL: f64 = 2e-5;

/// The input: Shepp–Logan 20×18×16 (edges) plus a smooth ramp and deterministic
/// noise, with an oblique affine so that world boxes and world gradients are exercised.
fn input() -> Volume<f32> {
    let ph = Phantom::shepp_logan().sample([20, 18, 16]).unwrap();
    let mut rng = common::Rng(99);
    let data: Vec<f32> = ph
        .data()
        .iter()
        .enumerate()
        .map(|(n, &x)| x + 0.01 * (n % 20) as f32 + 0.05 * rng.unit() as f32)
        .collect();
    Volume::with_affine([20, 18, 16], common::oblique_affine(), data).unwrap()
}

enum Case {
    Resample(ResampleSpec),
    Gaussian([f64; 3]),
    Median(usize),
    Gradient,
}

fn cases(v: &Volume<f32>) -> Vec<(String, Case)> {
    let mut out = Vec::new();
    for filter in Filter::ALL.into_iter().filter(|f| *f != Filter::Sinc) {
        out.push((
            format!("resample whole {filter:?}"),
            Case::Resample(ResampleSpec {
                region: Region::Whole,
                // No output voxel centre falls on a tie of the nearest rule (a
                // midpoint between input voxels), where f32 and f64 may round apart:
                // 2·dims is not a divisor of (2i + 1)·n for dims (28, 14, 32), n (20, 18, 16).
                dims: [28, 14, 32],
                filter,
            }),
        ));
    }
    for filter in [Filter::Trilinear, Filter::CatmullRom, Filter::Lanczos4] {
        out.push((
            format!("resample index box {filter:?}"),
            Case::Resample(ResampleSpec {
                region: Region::Index {
                    lo: [2.3, 1.0, 4.5],
                    hi: [15.0, 16.2, 9.0],
                },
                dims: [31, 9, 17],
                filter,
            }),
        ));
        let c = v.center_world();
        out.push((
            format!("resample world box {filter:?}"),
            Case::Resample(ResampleSpec {
                region: Region::World {
                    lo: (c - DVec3::new(6.0, 5.0, 4.0)).to_array(),
                    hi: (c + DVec3::new(5.0, 6.0, 7.0)).to_array(),
                },
                dims: [16, 14, 12],
                filter,
            }),
        ));
    }
    for sigma in [[1.0, 1.0, 1.0], [0.6, 2.5, 1.4], [6.0, 0.3, 0.5]] {
        out.push((format!("gaussian {sigma:?}"), Case::Gaussian(sigma)));
    }
    for k in [1, 3, 5] {
        out.push((format!("median {k}"), Case::Median(k)));
    }
    out.push(("gradient magnitude".into(), Case::Gradient));
    out
}

fn run_case(ctx: &GpuContext, v: &Volume<f32>, case: &Case) -> (Field<f64>, Field<f32>) {
    match case {
        Case::Resample(s) => (
            cp::resample::<f64, f32>(v, s).unwrap(),
            gp::resample(ctx, v, s).unwrap(),
        ),
        Case::Gaussian(s) => (
            cp::gaussian::<f64, f32>(v, *s).unwrap(),
            gp::gaussian(ctx, v, *s).unwrap(),
        ),
        Case::Median(k) => (
            cp::median::<f64, f32>(v, *k).unwrap(),
            gp::median(ctx, v, *k).unwrap(),
        ),
        Case::Gradient => (
            cp::gradient_magnitude::<f64, f32>(v).unwrap(),
            gp::gradient_magnitude(ctx, v).unwrap(),
        ),
    }
}

#[test]
fn gpu_processing_matches_the_f64_oracle() {
    let Some(ctx) = common::gpu("gpu_processing_matches_the_f64_oracle") else {
        return;
    };
    let v = input();
    for (name, case) in cases(&v) {
        let t = std::time::Instant::now();
        let (cpu, gpu) = run_case(ctx, &v, &case);
        assert_eq!(cpu.grid.dims, gpu.grid.dims, "{name}");
        assert!(
            (cpu.affine - gpu.affine).abs_diff_eq(glam::DMat4::ZERO, 0.0),
            "{name}: affine"
        );
        // The median selects one of the f32 input values: exact.
        let tol = if matches!(case, Case::Median(_)) {
            voxlab::metrics::Tolerance::max_abs(0.0)
        } else {
            voxlab::metrics::Tolerance::max_abs_rel(TOL_MAX_REL)
        };
        let e = common::assert_parity_array(
            &format!("gpu_process {name}"),
            &cpu.grid.dims,
            &cpu.grid.data,
            &gpu.grid.data,
            tol,
        );
        eprintln!(
            "{name}: max rel {:.2e} ({:.2} s)",
            e.max_abs_rel,
            t.elapsed().as_secs_f64()
        );
    }
}

#[test]
fn gpu_refusals_are_clear_errors() {
    let Some(ctx) = common::gpu("gpu_refusals_are_clear_errors") else {
        return;
    };
    let v = input();
    let sinc = ResampleSpec {
        region: Region::Whole,
        dims: [4, 4, 4],
        filter: Filter::Sinc,
    };
    let invalid = |r: voxlab::Result<Field<f32>>| match r {
        Err(Error::Invalid { what, .. }) => what,
        other => panic!("expected an Invalid error, got {other:?}"),
    };
    assert_eq!(invalid(gp::resample(ctx, &v, &sinc)), "resampling filter");
    assert_eq!(invalid(gp::median(ctx, &v, 7)), "median window size");
    assert_eq!(invalid(gp::median(ctx, &v, 4)), "median window size");
    assert_eq!(
        invalid(gp::gaussian(ctx, &v, [1.0, f64::NAN, 1.0])),
        "Gaussian sigma"
    );
    let empty = ResampleSpec {
        region: Region::World {
            lo: [0.0; 3],
            hi: [1.0, 1.0, -1.0],
        },
        dims: [2, 2, 2],
        filter: Filter::Trilinear,
    };
    assert_eq!(invalid(gp::resample(ctx, &v, &empty)), "resampling box");
}

#[test]
fn gpu_processing_in_slabs_equals_the_unsplit_volume_bit_for_bit() {
    use voxlab::gpu::plan::Pieces;
    let Some(ctx) = common::gpu("gpu_processing_in_slabs_equals_the_unsplit_volume_bit_for_bit")
    else {
        return;
    };
    let v = input();
    let dims = v.dims();
    for (name, case) in cases(&v) {
        if let Case::Resample(spec) = &case {
            // Resampling: output slabs of 1, 3 and 5 slices, each from its own run of
            // input slices.
            let (to_in, _) = cp::resample_plan(dims, v.affine(), spec).unwrap();
            let whole = gp::resample(ctx, &v, spec).unwrap();
            for per_piece in [1, 3, 5] {
                let plan =
                    gp::ResamplePlan::in_slabs(dims, to_in, spec.dims, spec.filter, per_piece)
                        .unwrap();
                assert!(plan.is_split(), "{name}");
                let start = std::time::Instant::now();
                let (split, times) = gp::resample_planned(ctx, &v, spec, &plan).unwrap();
                // Each output slab of at most 5·28·14 voxels is one dispatch.
                check_timings(ctx, &times, plan.slabs.count(), start.elapsed());
                let first = split
                    .grid
                    .data
                    .iter()
                    .zip(&whole.grid.data)
                    .position(|(a, b)| a.to_bits() != b.to_bits());
                assert_eq!(first, None, "{name}, {}", plan.describe());
                assert_eq!(split.affine, whole.affine);
            }
            continue;
        }
        let plan = match &case {
            Case::Resample(_) => unreachable!(),
            Case::Gaussian(s) => gp::ProcessPlan::gaussian(&ctx.limits, dims, *s),
            Case::Median(k) => gp::ProcessPlan::median(&ctx.limits, dims, *k),
            Case::Gradient => gp::ProcessPlan::gradient_magnitude(&ctx.limits, dims),
        }
        .unwrap();
        assert!(!plan.is_split(), "{name}");
        let (_, whole) = run_case(ctx, &v, &case);
        // Slabs of 1, 3 and 5 slices (16 = 3·5 + 1: a short last slab).
        for per_piece in [1, 3, 5] {
            let plan = gp::ProcessPlan {
                slabs: Pieces {
                    total: dims[2],
                    per_piece,
                },
                ..plan
            };
            let start = std::time::Instant::now();
            let (split, times) = match &case {
                Case::Gaussian(s) => gp::gaussian_planned(ctx, &v, *s, &plan),
                Case::Median(k) => gp::median_planned(ctx, &v, *k, &plan),
                Case::Gradient => gp::gradient_magnitude_planned(ctx, &v, &plan),
                Case::Resample(_) => unreachable!(),
            }
            .unwrap();
            // A slab of at most 5 + 2·ghost slices of 20·18 voxels is one dispatch per
            // pass (the median's 5³ window: 2²⁶ / (125·63) = 8,521 voxels per
            // dispatch); the Gaussian makes three passes.
            let passes = if matches!(case, Case::Gaussian(_)) {
                3
            } else {
                1
            };
            assert_eq!(times.slabs, plan.slabs.count(), "{name}");
            check_timings(ctx, &times, passes * plan.slabs.count(), start.elapsed());
            let first = split
                .grid
                .data
                .iter()
                .zip(&whole.grid.data)
                .position(|(a, b)| a != b);
            assert_eq!(first, None, "{name}, {}", plan.describe());
            assert_eq!(split.affine, whole.affine);
        }
    }
}

/// `times` counts `dispatches`; its kernel time is there exactly when the adapter has
/// timestamp queries, and lies within the call's wall clock `wall`.
fn check_timings(
    ctx: &GpuContext,
    times: &gp::ProcessTimings,
    dispatches: usize,
    wall: std::time::Duration,
) {
    assert_eq!(times.dispatches, dispatches, "{times:?}");
    let timed = ctx.features.contains(wgpu::Features::TIMESTAMP_QUERY);
    assert_eq!(times.kernel.is_some(), timed, "{times:?}");
    if let Some(k) = times.kernel {
        assert!(k > 0.0 && k <= wall.as_secs_f64(), "{times:?} in {wall:?}");
    }
    assert!(
        times.setup > 0.0 && times.setup <= wall.as_secs_f64(),
        "{times:?}"
    );
}

#[test]
fn processing_dispatches_hold_at_most_the_taps_of_one_dispatch() {
    // 2²⁶ taps of 7 per voxel: 9,586,980 voxels per dispatch.
    assert_eq!(gp::dispatches(9_586_980, 7), 1);
    assert_eq!(gp::dispatches(9_586_981, 7), 2);
    // At most 2²⁴ voxels, even of one tap each.
    assert_eq!(gp::dispatches(1 << 25, 1), 2);
    // At least one workgroup of 64, even past 2²⁶ taps per voxel.
    assert_eq!(gp::dispatches(100, 1 << 30), 2);
    assert_eq!(gp::dispatches(0, 7), 0);
}

#[test]
fn a_processing_plan_keeps_the_ghost_slices_within_one_binding() {
    let limits = |bytes: u64| wgpu::Limits {
        max_storage_buffer_binding_size: bytes,
        ..wgpu::Limits::default()
    };
    // 20 × 18 slices of 1,440 bytes; 14,400 bytes hold 10 slices.
    let p = gp::ProcessPlan::gaussian(&limits(14_400), [20, 18, 16], [1.0, 1.0, 1.0]).unwrap();
    // σ = 1: 4 ghost slices on either side leave 2 output slices per slab.
    assert_eq!((p.ghost, p.slabs.per_piece, p.slabs.count()), (4, 2, 8));
    assert_eq!(
        p.describe(),
        "processing in 8 slabs of 2 slices (4 ghost slices on either side)"
    );
    let p = gp::ProcessPlan::gradient_magnitude(&limits(14_400), [20, 18, 16]).unwrap();
    assert_eq!((p.slabs.per_piece, p.slabs.count()), (8, 2));
    // σ = 1.4 along z reaches 6 slices: 13 slices exceed 10.
    let e = gp::ProcessPlan::gaussian(&limits(14_400), [20, 18, 16], [1.0, 1.0, 1.4]).unwrap_err();
    assert!(e.to_string().contains("12 ghost slices"), "{e}");
    // Everything fits: one slab, whatever the reach.
    let p = gp::ProcessPlan::median(&limits(1 << 20), [20, 18, 16], 5).unwrap();
    assert!(!p.is_split());
}

#[test]
fn a_resampling_plan_fits_each_output_slab_and_its_input_slices_in_one_binding() {
    let limits = |bytes: u64| wgpu::Limits {
        max_storage_buffer_binding_size: bytes,
        ..wgpu::Limits::default()
    };
    let identity = glam::DMat4::IDENTITY;
    let (input, output) = ([20, 18, 16], [20, 18, 16]);
    // The same grid, trilinear: output slice k reads input slices k − 1 … k + 2 (its
    // taps k and k + 1, and one more on either side for the shader's rounding).
    let one = gp::ResamplePlan::new(&limits(1 << 20), input, identity, output, Filter::Trilinear)
        .unwrap();
    assert!(!one.is_split());
    assert_eq!(one.inputs, vec![(0..16)]);
    // Slices of 1,440 bytes; 14,400 bytes hold 10. Inside the volume d output slices
    // read d + 3 input ones, at its ends fewer: slabs of 8 read 10 and 9.
    let p =
        gp::ResamplePlan::new(&limits(14_400), input, identity, output, Filter::Trilinear).unwrap();
    assert_eq!((p.slabs.per_piece, p.slabs.count()), (8, 2));
    assert_eq!(p.inputs, [0..10, 7..16]);
    assert_eq!(
        p.describe(),
        "resampling in 2 slabs of 8 slices (each reading at most 10 input slices)"
    );
    // Lanczos-4 reaches 4 slices: one output slice reads 10 input slices, which 10 fit
    // and 9 do not.
    let p =
        gp::ResamplePlan::new(&limits(14_400), input, identity, output, Filter::Lanczos4).unwrap();
    assert_eq!((p.slabs.per_piece, p.largest_input()), (1, 10));
    let e = gp::ResamplePlan::new(&limits(12_960), input, identity, output, Filter::Lanczos4)
        .unwrap_err();
    assert!(e.to_string().contains("reads 10 input slices"), "{e}");
    // Halving every axis: an output slab of 10 × 9 × k reads about 2k input slices.
    let half = glam::DMat4::from_translation(glam::DVec3::splat(0.5))
        * glam::DMat4::from_scale(glam::DVec3::splat(2.0));
    let p =
        gp::ResamplePlan::new(&limits(14_400), input, half, [10, 9, 8], Filter::Trilinear).unwrap();
    assert_eq!((p.slabs.per_piece, p.slabs.count()), (4, 2));
    assert_eq!(p.inputs, [0..9, 7..16]);
    // The sinc has no GPU port.
    assert!(gp::ResamplePlan::new(&limits(14_400), input, identity, output, Filter::Sinc).is_err());
}
