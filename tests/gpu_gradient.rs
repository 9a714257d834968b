//! The GPU gradient volume (`gpu::gradient`) against the f64 CPU oracle
//! (`cpu::gradient::precompute_gradients`) for every stencil, on one case list, and
//! against the CPU's own f32 result, which it must reproduce bit for bit where the
//! arithmetic is the same sequence of f32 operations (central and forward differences).

mod common;

use voxlab::cpu::gradient::precompute_gradients;
use voxlab::cpu::grid::Grid;
use voxlab::gpu::gradient as gg;
use voxlab::phantom::Phantom;
use voxlab::settings::GradientMethod;
use voxlab::Error;

/// Largest `max |gpu − oracle| / max |oracle|`: f32 voxels and f32 differences against
/// f64 arithmetic on the same f32 voxels. Central and forward differences are exact in
/// f32 up to one rounding of the subtraction; Sobel adds nine rounded products. Measured
/// on lavapipe: central 5.4e-8, forward 5.4e-8, Sobel 1.0e-7; bound ≈ 2.4× the worst.
const TOL_MAX_REL: f64 = 2.5e-7;

/// Shepp–Logan 21 × 18 × 13 (edges, odd sizes so workgroups overhang every axis) plus
/// deterministic noise.
fn input() -> Grid<f32> {
    let ph = Phantom::shepp_logan().sample([21, 18, 13]).unwrap();
    let mut rng = common::Rng(7);
    Grid {
        dims: [21, 18, 13],
        data: ph
            .data()
            .iter()
            .map(|&x| x + 0.1 * rng.unit() as f32)
            .collect(),
    }
}

fn check(method: GradientMethod, max_slab_bytes: u64, label: &str) {
    let Some(ctx) = common::gpu(label) else {
        return;
    };
    let g32 = input();
    let g64 = Grid::<f64> {
        dims: g32.dims,
        data: g32.data.iter().map(|&v| v as f64).collect(),
    };
    let oracle = precompute_gradients(&g64, method);
    let cpu32 = precompute_gradients(&g32, method);
    let gpu = gg::precompute_gradients_in_slabs(ctx, &g32, method, max_slab_bytes).unwrap();
    // The three components one after the other: dims [nx, ny, nz, 3].
    for g in &gpu.components {
        assert_eq!(g.dims, g32.dims);
    }
    let all_oracle: Vec<f64> = oracle.iter().flat_map(|c| c.data.iter().copied()).collect();
    let all_gpu: Vec<f32> = gpu
        .components
        .iter()
        .flat_map(|c| c.data.iter().copied())
        .collect();
    let [nx, ny, nz] = g32.dims;
    let worst = common::assert_parity_array(
        &format!("gpu_gradient {label}"),
        &[nx, ny, nz, 3],
        &all_oracle,
        &all_gpu,
        voxlab::metrics::Tolerance::max_abs_rel(TOL_MAX_REL),
    )
    .max_abs_rel;
    eprintln!("{label}: max |gpu − oracle| / max |oracle| = {worst:.2e}");
    if method != GradientMethod::Sobel {
        for (c, (g, f)) in gpu.components.iter().zip(&cpu32).enumerate() {
            assert_eq!(
                g.data, f.data,
                "{label}: component {c} differs from the CPU's f32 result"
            );
        }
    }
}

/// (test name, stencil, slab limit in bytes): the whole volume in one slab, and slabs
/// of one to five slices (one slice is 21 · 18 · 3 · 4 = 4536 bytes).
macro_rules! cases {
    ($($name:ident: $method:expr, $slab:expr;)*) => {$(
        #[test]
        fn $name() {
            check($method, $slab, stringify!($name));
        }
    )*};
}

cases! {
    central_one_slab: GradientMethod::Central, u64::MAX;
    forward_one_slab: GradientMethod::Forward, u64::MAX;
    sobel_one_slab: GradientMethod::Sobel, u64::MAX;
    central_one_slice_slabs: GradientMethod::Central, 4536;
    sobel_five_slice_slabs: GradientMethod::Sobel, 5 * 4536;
}

#[test]
fn refusals_are_clear() {
    let Some(ctx) = common::gpu("gradient refusals") else {
        return;
    };
    let g = input();
    let e = gg::precompute_gradients_in_slabs(ctx, &g, GradientMethod::Central, 4535)
        .err()
        .expect("a slice larger than the slab limit is refused");
    assert!(matches!(e, Error::TooLarge { .. }), "{e}");
    let bad = Grid::<f32> {
        dims: [4, 4, 4],
        data: vec![0.0; 63],
    };
    let e = gg::precompute_gradients(ctx, &bad, GradientMethod::Central)
        .expect_err("a grid whose data do not fill it is refused");
    assert!(matches!(e, Error::Invalid { .. }), "{e}");
}
