//! GPU ramp filtering, backprojection and the whole FBP/FDK against the CPU f64 oracle.

mod common;

use voxlab::cpu::fbp::{backproject, parallel_stack_grid, rtk_grid};
use voxlab::ct::{Geometry, Projections};

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
        // 2.2e-6 cone (f32 projective map and interpolation).
        common::assert_parity_array(
            &format!("gpu_backproject_{name}"),
            &grid.dims,
            &want.data,
            &got.data,
            voxlab::metrics::Tolerance::max_abs_rel(1e-5),
        );
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
        // parallel, 2.3e-6 FDK.
        common::assert_parity_array(
            &format!("gpu_fbp_{name}"),
            &grid.dims,
            &want.data,
            &got.data,
            voxlab::metrics::Tolerance::max_abs_rel(1e-5),
        );
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
            // (f32 pre-weighting, FFTs and response).
            common::assert_parity_array(
                &format!("gpu_ramp_{}_{name}", filter.name()),
                &[want.cols, want.rows, want.angles],
                &want.data,
                &got.data,
                voxlab::metrics::Tolerance::max_abs_rel(1e-6),
            );
        }
    }
}
