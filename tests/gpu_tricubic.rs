//! The fast tricubic B-spline on the GPU against the f64 oracle: point by point
//! (`gpu::tricubic::sample_fast` against `cpu::tricubic::sample_fast` in f64, which
//! equals the 64-tap B-spline to 1e-12, `tests/tricubic.rs`) and in whole renders
//! (the GPU ray caster with `cubic-bspline-fast(-interp)` against the CPU f64 render
//! with the 64-tap `bspline(-interp)`), for the manual path (8 × 8 `textureLoad`s) and
//! the hardware path (8 texture-unit fetches). Both lists are case tables.
//!
//! Two expectations for the hardware path: lavapipe (Mesa's CPU Vulkan driver, the GPU
//! of CI) lerps in f32 and stays near the manual path; a real GPU computes the
//! sampler's lerp fractions with `subTexelPrecisionBits` = 8 fractional bits, so each
//! of the three fractions of a fetch may be off by up to 2⁻⁸ and a fetch by up to
//! 3 × 2⁻⁸ × the largest difference between neighbouring voxels (Δ). The fast
//! B-spline's 8 fetch weights are positive and sum to 1, so the sample inherits the
//! same bound, 3 × 2⁻⁸ × Δ: no worse than hardware trilinear filtering.

mod common;

use common::Rng;
use glam::DVec3;
use voxlab::camera::{Camera, Orbit, Projection};
use voxlab::cpu::filter::prepare;
use voxlab::cpu::grid::Grid;
use voxlab::metrics::Tolerance;
use voxlab::phantom::Phantom;
use voxlab::real::V3;
use voxlab::settings::{Classification, Filter, Mode, RenderSettings};
use voxlab::transfer::TransferFunction;
use voxlab::AnyVolume;

// ------------------------------------------------------------------ point by point

#[derive(Clone, Copy, Debug)]
enum Data {
    /// Uniform random values in [−1, 1] (Δ ≤ 2): the worst case for the weights.
    Random,
    /// The modified Shepp–Logan phantom, prefiltered (`bspline-interp` coefficients).
    PhantomCoefficients,
}

fn grid(data: Data, dims: [usize; 3]) -> Grid<f64> {
    match data {
        Data::Random => {
            let mut rng = Rng(17);
            let n = dims.iter().product::<usize>();
            Grid {
                dims,
                data: (0..n).map(|_| 2.0 * rng.unit() - 1.0).collect(),
            }
        }
        Data::PhantomCoefficients => {
            let v = Phantom::shepp_logan_modified().sample(dims).unwrap();
            prepare(&Grid::<f64>::from_volume(&v), Filter::BsplineInterp)
        }
    }
}

/// The largest difference between neighbouring voxels along any axis (Δ).
fn neighbour_range(g: &Grid<f64>) -> f64 {
    let [nx, ny, nz] = g.dims;
    let mut d = 0.0f64;
    for k in 0..nz as isize {
        for j in 0..ny as isize {
            for i in 0..nx as isize {
                let v = g.at_clamped(i, j, k);
                for (a, b, c) in [(1, 0, 0), (0, 1, 0), (0, 0, 1)] {
                    d = d.max((g.at_clamped(i + a, j + b, k + c) - v).abs());
                }
            }
        }
    }
    d
}

/// Samples `count` points over the box and 1.5 voxels beyond it (plus the corners) on
/// the f64 oracle and the GPU, at the same f32 points: returns (oracle, GPU, Δ).
fn points_samples(
    name: &str,
    data: Data,
    dims: [usize; 3],
    hardware: bool,
) -> Option<(Vec<f64>, Vec<f32>, f64)> {
    let ctx = common::gpu(name)?;
    let g = grid(data, dims);
    let g32 = Grid::<f32> {
        dims,
        data: g.data.iter().map(|&x| x as f32).collect(),
    };
    let mut rng = Rng(23);
    let mut pts: Vec<[f32; 3]> = (0..20_000)
        .map(|_| dims.map(|n| (-2.0 + (n as f64 + 3.0) * rng.unit()) as f32))
        .collect();
    for c in 0..8 {
        pts.push([0, 1, 2].map(|a| {
            if c >> a & 1 == 1 {
                dims[a] as f32 - 0.5
            } else {
                -0.5
            }
        }));
    }
    let got = voxlab::gpu::tricubic::sample_fast(ctx, &g32, &pts, hardware).unwrap();
    let want = pts
        .iter()
        .map(|p| {
            voxlab::cpu::tricubic::sample_fast(&g, V3::new(p[0] as f64, p[1] as f64, p[2] as f64))
        })
        .collect();
    Some((want, got, neighbour_range(&g)))
}

/// Relative to Δ (the largest neighbour difference). Manual path: f32 arithmetic,
/// measured on lavapipe (llvmpipe, LLVM 15) over 20,008 points: max 1.25e-7 Δ, RMSE
/// 1.7e-8 Δ (random 32³, Δ = 2.0) and 4.2e-8 Δ, 2.4e-9 Δ (the phantom's B-spline
/// coefficients, Δ = 11.7); bound about 4× the worst.
const MANUAL_POINTS: Tolerance = Tolerance {
    max_abs: 5e-7,
    rmse: 8e-8,
    ..Tolerance::NONE
};

/// Hardware path on lavapipe (f32 lerps, but the fetch point goes through the
/// normalised coordinate `(c + ½)/n` and back, rounding it once more): measured max
/// 8.2e-7 Δ, RMSE 1.1e-7 Δ (random 32³) and 3.9e-7 Δ, 1.9e-8 Δ (phantom coefficients);
/// bound about 4× the worst.
const LAVAPIPE_HARDWARE_POINTS: Tolerance = Tolerance {
    max_abs: 4e-6,
    rmse: 5e-7,
    ..Tolerance::NONE
};

/// Hardware path on a real GPU: 3 × 2⁻⁸ × Δ (module docs), the RMSE a quarter of it
/// (the three fractions' rounding errors are independent and largely cancel across the
/// 8 fetches).
const GPU_HARDWARE_POINTS: Tolerance = Tolerance {
    max_abs: 3.0 / 256.0,
    rmse: 3.0 / 1024.0,
    ..Tolerance::NONE
};

fn check_points(name: &str, data: Data, dims: [usize; 3], hardware: bool) {
    let Some((want, got, delta)) = points_samples(name, data, dims, hardware) else {
        return;
    };
    let ctx = common::gpu(name).unwrap();
    let tol = match (hardware, ctx.summary.is_cpu()) {
        (false, _) => MANUAL_POINTS,
        (true, true) => LAVAPIPE_HARDWARE_POINTS,
        (true, false) => GPU_HARDWARE_POINTS,
    };
    let e = common::assert_parity_array(name, &[want.len()], &want, &got, tol.scaled(delta));
    let (worst, rmse) = (e.max_abs, e.rmse);
    eprintln!(
        "{name}: max |Δ| {worst:.2e} ({:.2e} of Δ = {delta:.3}), rmse {rmse:.2e} ({:.2e} of Δ) on {}",
        worst / delta,
        rmse / delta,
        ctx.describe()
    );
}

macro_rules! point_cases {
    ($($name:ident: $data:expr, $dims:expr, $hardware:expr;)*) => {
        $(
            #[test]
            fn $name() {
                check_points(stringify!($name), $data, $dims, $hardware);
            }
        )*
    };
}

point_cases! {
    points_manual_random: Data::Random, [32, 32, 32], false;
    points_manual_phantom_coefficients: Data::PhantomCoefficients, [32, 35, 30], false;
    points_hardware_random: Data::Random, [32, 32, 32], true;
    points_hardware_phantom_coefficients: Data::PhantomCoefficients, [32, 35, 30], true;
}

// ------------------------------------------------------------------ whole renders

#[derive(Clone, Copy, Debug)]
struct Case {
    mode: Mode,
    filter: Filter,
    ortho: bool,
    classification: Classification,
    precompute: bool,
    hardware: bool,
}

const BASE: Case = Case {
    mode: Mode::Dvr,
    filter: Filter::BsplineFast,
    ortho: false,
    classification: Classification::Post,
    precompute: false,
    hardware: false,
};

fn scene(
    case: &Case,
    n: usize,
    size: usize,
) -> (AnyVolume, TransferFunction, Camera, RenderSettings) {
    let vol: AnyVolume = Phantom::shepp_logan_modified()
        .sample([n, n + 3, n - 2])
        .unwrap()
        .into();
    let tf = TransferFunction::preset("phantom").unwrap();
    let projection = if case.ortho {
        Projection::Orthographic {
            width_mm: 270.0,
            height_mm: 270.0 * 0.75,
        }
    } else {
        Projection::Perspective { fov_y_deg: 30.0 }
    };
    let cam = Camera::orbit(
        DVec3::ZERO,
        [256.0; 3],
        Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            distance_mm: Some(540.0),
        },
        projection,
        size,
        size * 3 / 4,
    )
    .unwrap();
    let s = RenderSettings {
        mode: case.mode,
        filter: case.filter,
        classification: case.classification,
        precompute_gradients: case.precompute,
        hardware_filtering: case.hardware,
        ..RenderSettings::default()
    };
    (vol, tf, cam, s)
}

/// Exact path, DVR on [0, 1] RGBA, Shepp–Logan 32×35×30 at 48×36 on lavapipe: worst
/// of the six DVR cases max |Δ| 1.19e-4, RMSE 7.2e-6 (`cubic-bspline-fast-interp`);
/// the f32 rounding of sample positions seen by the 64-tap filters in
/// `tests/gpu_raycast.rs`, amplified by the `phantom` preset's opacity bands. Bound
/// about 4× the worst.
const EXACT_DVR: Tolerance = Tolerance {
    max_abs: 5e-4,
    rmse: 3e-5,
    ..Tolerance::NONE
};
/// Exact path, MIP and X-ray relative to the image's scale (1 for MIP, 70.9 for the
/// X-ray): measured max 4.4e-6 (X-ray), RMSE 6.4e-7; bound about 4× the worst.
const EXACT_SCALAR: Tolerance = Tolerance {
    max_abs: 2e-5,
    rmse: 3e-6,
    ..Tolerance::NONE
};
/// Hardware path on lavapipe (f32 lerps): measured DVR max 1.19e-4, RMSE 7.2e-6, MIP
/// 2.9e-6, 6.2e-7: within the exact path's bounds, which it is held to.
const LAVAPIPE_HARDWARE_DVR: Tolerance = EXACT_DVR;
const LAVAPIPE_HARDWARE_SCALAR: Tolerance = EXACT_SCALAR;
/// Hardware path on a real GPU: per sample 3 × 2⁻⁸ × Δ with Δ ≤ 1 (the phantom's range),
/// and ×12 for DVR (the `phantom` preset's opacity slope): the bounds of hardware
/// trilinear filtering in `tests/gpu_raycast.rs` (measured there on an NVIDIA H200:
/// 6.4e-3 MIP), which the module docs show carry over.
const GPU_HARDWARE_SCALAR: Tolerance = Tolerance {
    max_abs: 3.0 / 256.0,
    rmse: 3.0 / 1024.0,
    ..Tolerance::NONE
};
const GPU_HARDWARE_DVR: Tolerance = Tolerance {
    max_abs: 36.0 / 256.0,
    rmse: 9.0 / 256.0,
    ..Tolerance::NONE
};

fn check_render(name: &str, case: Case, n: usize, size: usize) {
    let Some(ctx) = common::gpu(name) else {
        return;
    };
    let (vol, tf, cam, s) = scene(&case, n, size);
    let oracle_settings = RenderSettings {
        filter: case.filter.exact(),
        ..s.clone()
    };
    let cpu = voxlab::cpu::raycast::render::<f64>(&vol, &tf, &cam, &oracle_settings, &|_, _| {})
        .unwrap()
        .image;
    let gpu = voxlab::gpu::raycast::render(ctx, &vol, &tf, &cam, &s, &|_, _| {})
        .unwrap()
        .output
        .image;
    let dvr = case.mode == Mode::Dvr;
    let tol = match (case.hardware, ctx.summary.is_cpu(), dvr) {
        (false, _, true) => EXACT_DVR,
        (false, _, false) => EXACT_SCALAR,
        (true, true, true) => LAVAPIPE_HARDWARE_DVR,
        (true, true, false) => LAVAPIPE_HARDWARE_SCALAR,
        (true, false, true) => GPU_HARDWARE_DVR,
        (true, false, false) => GPU_HARDWARE_SCALAR,
    };
    let scale = if dvr {
        1.0
    } else {
        cpu.data.iter().fold(1.0f64, |m, x| m.max(x.abs()))
    };
    let stats = common::assert_parity(name, &cpu, &gpu, tol.scaled(scale));
    eprintln!(
        "{name}: max |Δ| {:.2e}, rmse {:.2e} (relative to the scale {scale:.3})",
        stats.max_abs / scale,
        stats.rmse / scale
    );
}

macro_rules! render_cases {
    ($($name:ident: $case:expr;)*) => {
        $(
            #[test]
            fn $name() {
                check_render(stringify!($name), $case, 32, 48);
            }
        )*
    };
}

render_cases! {
    dvr_fast_perspective: BASE;
    mip_fast_ortho: Case { mode: Mode::Mip, ortho: true, ..BASE };
    xray_fast_interp_ortho: Case { mode: Mode::Xray, filter: Filter::BsplineFastInterp, ortho: true, ..BASE };
    dvr_fast_interp_perspective: Case { filter: Filter::BsplineFastInterp, ..BASE };
    dvr_fast_preclassified: Case { classification: Classification::Pre, ..BASE };
    dvr_fast_precomputed_gradients: Case { precompute: true, ..BASE };
    mip_fast_hardware: Case { mode: Mode::Mip, ortho: true, hardware: true, ..BASE };
    dvr_fast_hardware: Case { hardware: true, ..BASE };
    dvr_fast_interp_hardware: Case { filter: Filter::BsplineFastInterp, hardware: true, ..BASE };
}
