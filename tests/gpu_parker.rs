//! Parker's short-scan weights on the GPU (`gpu::parker::weigh`) against the f64 CPU
//! oracle (`cpu::parker::weigh`), one case list; the GPU weights must also leave a
//! short-scan FDK of a ball as accurate as the CPU's.

mod common;

use voxlab::cpu::parker;
use voxlab::ct::{Geometry, Projections};

/// The bound on `max |gpu − cpu| / max |cpu|`, derived: the GPU holds `β` and `γ` in
/// f32 (error ≤ ~2.4e-7 rad near π) and the weights' ramps have slope up to
/// `(π/4)/(δ − max|γ|)` (`cpu::parker::parker_weight`), four times that for the
/// ratio's own f32 arithmetic, plus the polynomial sine (< 6e-8) and f32 rounding of
/// the products (1e-6).
fn bound(g: &Geometry) -> f64 {
    let s = parker::short_scan(g).unwrap();
    let sdd = 1500.0;
    let gmax = parker::fan_angle(g, sdd, 0.0)
        .abs()
        .max(parker::fan_angle(g, sdd, (g.cols - 1) as f64).abs());
    4.0 * 2.4e-7 * std::f64::consts::FRAC_PI_4 / (s.delta - gmax) + 1e-6
}

/// A short scan over `180° + 2·fan half angle + extra_deg`, starting at `first` degrees.
fn short(cols: usize, rows: usize, n: usize, extra_deg: f64, first: f64) -> Geometry {
    let du = 3.0;
    let fan = (cols as f64 / 2.0 * du / 1500.0).atan().to_degrees();
    let span = 180.0 + 2.0 * fan + extra_deg;
    let angles = (0..n)
        .map(|k| first + span * k as f64 / (n - 1) as f64)
        .collect();
    Geometry::cone_rtk(1000.0, 1500.0, cols, rows, du, du, angles).unwrap()
}

fn check(g: Geometry, label: &str) {
    let Some(ctx) = common::gpu(label) else {
        return;
    };
    let mut rng = common::Rng(5);
    let p64 = Projections::<f64> {
        angles: g.n_angles(),
        rows: g.rows,
        cols: g.cols,
        data: (0..g.n_angles() * g.rows * g.cols)
            .map(|_| 1.0 + rng.unit())
            .collect(),
    };
    let p32 = Projections::<f32> {
        angles: p64.angles,
        rows: p64.rows,
        cols: p64.cols,
        data: p64.data.iter().map(|&v| v as f32).collect(),
    };
    let want = parker::weigh(&p64, &g).unwrap();
    let got = voxlab::gpu::parker::weigh(ctx, &p32, &g).unwrap();
    let b = bound(&g);
    let worst = common::assert_parity_array(
        &format!("gpu_parker {label}"),
        &[want.cols, want.rows, want.angles],
        &want.data,
        &got.data,
        voxlab::metrics::Tolerance::max_abs_rel(b),
    )
    .max_abs_rel;
    eprintln!("{label}: max |gpu − cpu| / max |cpu| = {worst:.2e} (bound {b:.2e})");
}

macro_rules! cases {
    ($($name:ident: $g:expr;)*) => {$(
        #[test]
        fn $name() {
            check($g, stringify!($name));
        }
    )*};
}

cases! {
    minimal_short_scan: short(48, 4, 90, 0.0, 0.0);
    over_scan_from_an_odd_angle: short(33, 3, 61, 15.0, -47.5);
    // 64 × 64 × 1100 pixels: more than one dispatch chunk (2²² invocations each).
    many_views_in_two_chunks: short(64, 64, 1100, 4.0, 10.0);
}

#[test]
fn gpu_refuses_what_the_cpu_refuses() {
    let Some(ctx) = common::gpu("parker refusals") else {
        return;
    };
    let full = Geometry::cone_rtk(
        1000.0,
        1500.0,
        8,
        1,
        3.0,
        3.0,
        Geometry::even_angles(40, 360.0),
    )
    .unwrap();
    let p = Projections::<f32>::zeros(&full).unwrap();
    let e = voxlab::gpu::parker::weigh(ctx, &p, &full).expect_err("refused");
    assert!(e.to_string().contains("full turn"), "{e}");
    let g = short(8, 1, 40, 0.0, 0.0);
    let mut p = Projections::<f32>::zeros(&g).unwrap();
    p.data[0] = f32::INFINITY;
    assert!(voxlab::gpu::parker::weigh(ctx, &p, &g).is_err());
}
