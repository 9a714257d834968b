//! The benchmark cases of the fft, fvr, project, fbp and fdk families
//! (`voxlab::bench::fourier`, `voxlab::bench::ct`): every quick case prepares, its
//! CPU f32 and GPU results pass the case's tolerances against the f64 oracle, and
//! the work amounts are right for small cases counted by hand.
//!
//! `cargo test --release --test bench_fourier_ct -- --nocapture` prints every measured
//! error; the numbers quoted at each tolerance (`src/bench/*.rs`) come from here.

mod common;

use voxlab::bench::{ct, fourier, Case, Suite, Unit, Work};
use voxlab::metrics::Tolerance;

/// Holds `got` to `want` (the oracle) within `tol`, as the runner does
/// (`metrics::check_parity_array`: max |Δ| / max |oracle| and ‖Δ‖ / ‖oracle‖; any
/// NaN/∞ fails); prints the errors, and on failure leaves `target/parity/<case>/`.
fn check(case: &str, backend: &str, got: &[f64], want: &[f64], tol: Tolerance) {
    let name = format!("{case} {backend}");
    let dir = common::parity_dir(&name);
    let r = voxlab::metrics::check_parity_array(&name, &[want.len()], want, got, tol, Some(&dir))
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    eprintln!(
        "{case:<40} {backend:<8} max rel {:.2e} (bound {:.1e}), rel L2 {:.2e} (bound {:.1e})",
        r.stats.max_abs_rel, tol.max_abs_rel, r.stats.rel_l2, tol.rel_l2
    );
    assert!(r.passed, "{}", r.message);
}

/// Prepares and runs every quick case of `family` on every backend.
fn run_family(test: &str, family: &str) {
    let cases: Vec<Case> = fourier::cases(Suite::Quick)
        .into_iter()
        .chain(ct::cases(Suite::Quick))
        .filter(|c| c.family == family)
        .collect();
    assert!(!cases.is_empty(), "no quick {family} case");
    let ctx = common::gpu(test);
    for case in cases {
        let id = case.id();
        let mut p = (case.prepare)().unwrap_or_else(|e| panic!("{id}: prepare: {e}"));
        assert!(!p.work.is_empty(), "{id}: no work");
        assert!(p.work.iter().all(|w| w.amount > 0.0), "{id}: {:?}", p.work);
        let oracle = (p.cpu_f64)().unwrap();
        assert!(oracle.seconds >= 0.0 && !oracle.output.is_empty(), "{id}");
        assert!(oracle.output.iter().any(|v| *v != 0.0), "{id}: all zero");
        if let Some(f32_run) = p.cpu_f32.as_mut() {
            let r = f32_run().unwrap();
            check(&id, "CPU f32", &r.output, &oracle.output, p.tol_f32);
        }
        if let (Some(gpu), Some(ctx)) = (p.gpu.as_mut(), ctx) {
            // Twice: the second run reuses what the first made (plans, buffers).
            for run in 0..2 {
                let r = gpu(ctx).unwrap_or_else(|e| panic!("{id}: GPU: {e}"));
                assert!(r.end_to_end > 0.0 && r.kernel > 0.0, "{id}: {r:?}");
                assert!(r.kernel <= r.end_to_end * 1.5 || r.kernel_from_timestamps);
                check(
                    &id,
                    &format!("GPU #{run}"),
                    &r.output,
                    &oracle.output,
                    p.tol_gpu,
                );
            }
        }
    }
}

macro_rules! family_tests {
    ($($name:ident => $family:literal,)*) => {$(
        #[test]
        fn $name() {
            run_family(stringify!($name), $family);
        }
    )*};
}

family_tests! {
    quick_fft_cases_match_the_oracle => "fft",
    quick_fvr_cases_match_the_oracle => "fvr",
    quick_project_cases_match_the_oracle => "project",
    quick_fbp_cases_match_the_oracle => "fbp",
    quick_fdk_cases_match_the_oracle => "fdk",
}

fn amount(work: &[Work], unit: Unit) -> f64 {
    work.iter()
        .find(|w| w.unit == unit)
        .unwrap_or_else(|| panic!("no {unit:?} in {work:?}"))
        .amount
}

fn quick(family: &str, name: &str) -> Case {
    fourier::cases(Suite::Quick)
        .into_iter()
        .chain(ct::cases(Suite::Quick))
        .find(|c| c.family == family && c.name == name)
        .unwrap_or_else(|| panic!("no quick case {family}/{name}"))
}

#[test]
fn work_amounts_are_counted_by_hand() {
    // FFT 32²: N = 1024, 5·N·log₂N = 5·1024·10 flops, 16·N bytes.
    let p = (quick("fft", "2d").prepare)().unwrap();
    assert_eq!(amount(&p.work, Unit::Flops), 51_200.0);
    assert_eq!(amount(&p.work, Unit::Bytes), 16_384.0);
    // FVR 16³ (M = 32): one 16² image.
    let p = (quick("fvr", "trilinear").prepare)().unwrap();
    assert_eq!(amount(&p.work, Unit::Rays), 256.0);
    // Projection 16³ → 12 × 16²: 3072 rays, at most 16 planes each.
    let p = (quick("project", "parallel").prepare)().unwrap();
    assert_eq!(amount(&p.work, Unit::Rays), 3072.0);
    let s = amount(&p.work, Unit::Samples);
    assert!(s > 0.5 * 3072.0 * 16.0 && s <= 3072.0 * 16.0, "{s}");
    // FBP 32² from 45 views: 32² × 45 voxel updates; FDK 16³ from 30 views.
    let p = (quick("fbp", "parallel-ramlak").prepare)().unwrap();
    assert_eq!(amount(&p.work, Unit::VoxelUpdates), 46_080.0);
    let p = (quick("fdk", "cone-ramlak").prepare)().unwrap();
    assert_eq!(amount(&p.work, Unit::VoxelUpdates), 122_880.0);
}

/// Joseph's sample count on a view along a grid axis: the 16 mm detector pixels sit
/// on the 16 mm voxel centres, so every ray crosses all 16 planes (16² rays · 16).
#[test]
fn joseph_samples_of_an_axis_view_are_rays_times_planes() {
    let (grid, _) = ct::project_scene(16, 1, false).unwrap();
    let g = voxlab::ct::Geometry::parallel_stack(16, 16, 16.0, 16.0, vec![0.0]).unwrap();
    assert_eq!(ct::joseph_samples(grid.dims, grid.affine, &g), 4096.0);
    // A detector twice as wide: the outer half of the rays misses the grid (in-plane
    // coordinate beyond the last voxel centre + 1).
    let g = voxlab::ct::Geometry::parallel_stack(32, 16, 16.0, 16.0, vec![0.0]).unwrap();
    let s = ct::joseph_samples(grid.dims, grid.affine, &g);
    assert!((4096.0..=18.0 * 16.0 * 16.0).contains(&s), "{s}");
}
