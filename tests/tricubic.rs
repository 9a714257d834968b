//! The fast tricubic B-spline (8 trilinear fetches, `cpu::tricubic`) against the 64-tap
//! oracle (`cpu::filter::sample` with `Bspline` / `BsplineInterp`): per point, in
//! renders, at the borders, in f32 and f64; and its names.

mod common;

use common::Rng;
use glam::DVec3;
use voxlab::camera::{Camera, Orbit, Projection};
use voxlab::cpu::filter::{axis_taps, prepare, sample};
use voxlab::cpu::grid::Grid;
use voxlab::cpu::tricubic::{fast_bspline_axis, fetch_points, sample_fast};
use voxlab::phantom::Phantom;
use voxlab::real::V3;
use voxlab::settings::{Filter, Mode, RenderSettings};
use voxlab::transfer::TransferFunction;
use voxlab::AnyVolume;

fn random_grid(dims: [usize; 3], seed: u64) -> Grid<f64> {
    let mut rng = Rng(seed);
    let n = dims.iter().product::<usize>();
    Grid {
        dims,
        data: (0..n).map(|_| 2.0 * rng.unit() - 1.0).collect(),
    }
}

/// Random points over the sampled box `[−½, n − ½]` and a margin of 1.5 voxels beyond
/// it, plus voxel centres, cell edges and the exact corners of the box.
fn points(dims: [usize; 3], count: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = Rng(seed);
    let mut out = Vec::new();
    for _ in 0..count {
        out.push(dims.map(|n| -2.0 + (n as f64 + 3.0) * rng.unit()));
    }
    for _ in 0..count / 4 {
        // Integers and half-integers, including −½ and n − ½.
        out.push(dims.map(|n| (rng.below(2 * n + 1) as f64 - 1.0) * 0.5));
    }
    for c in 0..8 {
        out.push([0, 1, 2].map(|a| {
            if c >> a & 1 == 1 {
                dims[a] as f64 - 0.5
            } else {
                -0.5
            }
        }));
    }
    out
}

const SHAPES: [[usize; 3]; 5] = [[1, 1, 1], [2, 3, 1], [5, 7, 3], [9, 4, 6], [16, 16, 16]];

/// Each axis's two fetches reproduce the four B-spline taps of `cpu::filter::axis_taps`
/// (the weights pair up, the fractions stay between their voxels).
#[test]
fn pairs_reproduce_the_four_taps() {
    for k in 0..=200 {
        let x = -1.5 + k as f64 * 0.0371;
        let t = axis_taps::<f64>(Filter::Bspline, x);
        let a = fast_bspline_axis(x);
        assert_eq!(a.base[0], t.first);
        assert!((a.g[0] - (t.w[0] + t.w[1])).abs() < 1e-15);
        assert!((a.g[1] - (t.w[2] + t.w[3])).abs() < 1e-15);
        assert!((a.g[0] * a.frac[0] - t.w[1]).abs() < 1e-15);
        assert!((a.g[1] * a.frac[1] - t.w[3]).abs() < 1e-15);
        assert!((0.5..=1.0).contains(&a.frac[0]), "{x}: {:?}", a.frac);
        assert!(
            (0.0..=0.2 + 1e-15).contains(&a.frac[1]),
            "{x}: {:?}",
            a.frac
        );
    }
}

/// f64: the 8 fetches equal the 64 taps to rounding, everywhere including the borders
/// and beyond them (clamp-to-edge). Measured worst |Δ| 1.3e-15 over 5 shapes × 2
/// filters × 2,508 points; bound 1e-12.
#[test]
fn fast_bspline_equals_the_64_tap_oracle_in_f64() {
    let mut worst = 0.0f64;
    for (s, dims) in SHAPES.into_iter().enumerate() {
        let values = random_grid(dims, 11 + s as u64);
        for (fast, exact) in [
            (Filter::BsplineFast, Filter::Bspline),
            (Filter::BsplineFastInterp, Filter::BsplineInterp),
        ] {
            let g_fast = prepare(&values, fast);
            let g_exact = prepare(&values, exact);
            assert_eq!(g_fast, g_exact, "{fast:?} samples the same grid");
            for p in points(dims, 2000, 7 + s as u64) {
                let p = V3::new(p[0], p[1], p[2]);
                let a = sample(&g_fast, fast, p);
                let b = sample(&g_exact, exact, p);
                let d = (a - b).abs();
                worst = worst.max(d);
                assert!(d <= 1e-12, "{fast:?} {dims:?} at {p:?}: {a} vs {b}");
            }
        }
    }
    eprintln!("fast vs 64-tap, f64: worst |Δ| {worst:.2e}");
}

/// f32 against the f64 oracle: the 8-fetch sum's rounding is that of the 64-tap sum.
/// Values in [−1, 1]; measured worst |Δ| 2.0e-7 (fast) and 2.1e-7 (64 taps) over
/// 2,508 points of a 16³ grid; bound 1e-6 (about 8 f32 ulps of 1).
#[test]
fn fast_bspline_in_f32_meets_the_f64_oracle() {
    let dims = [16, 16, 16];
    let g64 = random_grid(dims, 5);
    let g32 = Grid::<f32> {
        dims,
        data: g64.data.iter().map(|&x| x as f32).collect(),
    };
    let (mut worst_fast, mut worst_taps) = (0.0f64, 0.0f64);
    for p in points(dims, 2000, 3) {
        let q = V3::new(p[0] as f32, p[1] as f32, p[2] as f32);
        // The f32 point itself is rounded; evaluate the oracle there.
        let want_q = sample(
            &g64,
            Filter::Bspline,
            V3::new(q.x() as f64, q.y() as f64, q.z() as f64),
        );
        let fast = sample_fast(&g32, q) as f64;
        let taps = sample(&g32, Filter::Bspline, q) as f64;
        worst_fast = worst_fast.max((fast - want_q).abs());
        worst_taps = worst_taps.max((taps - want_q).abs());
    }
    eprintln!("f32 vs f64 oracle: fast {worst_fast:.2e}, 64 taps {worst_taps:.2e}");
    assert!(worst_fast < 1e-6, "{worst_fast}");
    assert!(worst_taps < 1e-6, "{worst_taps}");
}

/// The interpolating variant passes through every voxel value (measured worst |Δ|
/// 5.6e-16; bound 1e-12).
#[test]
fn fast_interp_passes_through_the_voxels() {
    let dims = [6, 5, 4];
    let values = random_grid(dims, 99);
    let c = prepare(&values, Filter::BsplineFastInterp);
    let mut worst = 0.0f64;
    for k in 0..4 {
        for j in 0..5 {
            for i in 0..6 {
                let v = sample(
                    &c,
                    Filter::BsplineFastInterp,
                    V3::new(i as f64, j as f64, k as f64),
                );
                worst = worst.max((v - values.at_clamped(i, j, k)).abs());
            }
        }
    }
    eprintln!("fast interp at voxel centres: worst |Δ| {worst:.2e}");
    assert!(worst < 1e-12, "{worst}");
}

/// The 8 fetch points and weights: weights sum to 1, each point lies within its pair
/// of voxels, and the weighted points' mean is the sample point itself (the B-spline
/// reproduces linear functions, so does a trilinear fetch).
#[test]
fn fetch_points_reproduce_linear_functions() {
    let mut rng = Rng(4);
    for _ in 0..500 {
        let p = [0; 3].map(|_| -0.5 + 20.0 * rng.unit());
        let pts = fetch_points(p);
        let s: f64 = pts.iter().map(|(_, w)| w).sum();
        assert!((s - 1.0).abs() < 1e-14);
        for a in 0..3 {
            let mean: f64 = pts.iter().map(|(q, w)| w * q[a]).sum();
            assert!((mean - p[a]).abs() < 1e-13, "{p:?}: {mean}");
            for (q, _) in &pts {
                assert!((q[a] - p[a]).abs() <= 1.2 + 1e-12, "{p:?}: {q:?}");
            }
        }
    }
}

fn scene(mode: Mode, filter: Filter) -> (AnyVolume, TransferFunction, Camera, RenderSettings) {
    let vol: AnyVolume = Phantom::shepp_logan_modified()
        .sample([24, 26, 22])
        .unwrap()
        .into();
    let tf = TransferFunction::preset("phantom").unwrap();
    let cam = Camera::orbit(
        DVec3::ZERO,
        [256.0; 3],
        Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            distance_mm: Some(540.0),
        },
        Projection::Perspective { fov_y_deg: 30.0 },
        40,
        30,
    )
    .unwrap();
    let s = RenderSettings {
        mode,
        filter,
        ..RenderSettings::default()
    };
    (vol, tf, cam, s)
}

/// Whole f64 renders (shaded DVR with on-the-fly and precomputed gradients, MIP,
/// X-ray, pre-classified DVR) with the fast filters equal those with the 64-tap ones.
/// Measured worst |Δ| 2.6e-15 (DVR) and 2.1e-14 (X-ray, absolute); bound 1e-12
/// relative to the image's scale.
#[test]
fn fast_renders_equal_64_tap_renders_in_f64() {
    use voxlab::settings::Classification;
    for (fast, exact) in [
        (Filter::BsplineFast, Filter::Bspline),
        (Filter::BsplineFastInterp, Filter::BsplineInterp),
    ] {
        for (mode, tweak) in [
            (Mode::Dvr, 0),
            (Mode::Dvr, 1),
            (Mode::Dvr, 2),
            (Mode::Mip, 0),
            (Mode::Xray, 0),
        ] {
            let render = |filter| {
                let (vol, tf, cam, mut s) = scene(mode, filter);
                match tweak {
                    1 => s.precompute_gradients = true,
                    2 => s.classification = Classification::Pre,
                    _ => {}
                }
                voxlab::cpu::raycast::render::<f64>(&vol, &tf, &cam, &s, &|_, _| {})
                    .unwrap()
                    .image
            };
            let (a, b) = (render(fast), render(exact));
            let scale = b.data.iter().fold(1.0f64, |m, x| m.max(x.abs()));
            let worst = a
                .data
                .iter()
                .zip(&b.data)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max);
            eprintln!("{fast:?} {mode:?} variant {tweak}: max |Δ| {worst:.2e}");
            assert!(worst <= 1e-12 * scale, "{fast:?} {mode:?} {tweak}: {worst}");
        }
    }
}

/// The names: the CLI's `--filter cubic-bspline-fast(-interp)`, the JSON settings, and
/// the short aliases.
#[test]
fn fast_filters_have_their_names() {
    for (f, name) in [
        (Filter::BsplineFast, "cubic-bspline-fast"),
        (Filter::BsplineFastInterp, "cubic-bspline-fast-interp"),
    ] {
        assert_eq!(f.name(), name);
        assert_eq!(name.parse::<Filter>().unwrap(), f);
        assert_eq!(serde_json::to_string(&f).unwrap(), format!("\"{name}\""));
        assert_eq!(
            serde_json::from_str::<Filter>(&format!("\"{name}\"")).unwrap(),
            f
        );
        assert_eq!(f.radius(), 2);
    }
    assert_eq!(
        "bspline-fast".parse::<Filter>().unwrap(),
        Filter::BsplineFast
    );
    assert_eq!(Filter::BsplineFast.exact(), Filter::Bspline);
    assert_eq!(Filter::BsplineFastInterp.exact(), Filter::BsplineInterp);
    assert!(Filter::BsplineFastInterp.prefiltered() && !Filter::BsplineFast.prefiltered());
}

/// The CLI renders with the fast filter (and the help lists it).
#[test]
fn cli_renders_with_the_fast_filter() {
    let dir = common::scratch("tricubic_cli");
    let out = dir.join("fast.png");
    let o = common::voxlab(&[
        "render",
        "phantom:shepp-logan-modified:24",
        "--filter",
        "cubic-bspline-fast",
        "--width",
        "24",
        "--height",
        "24",
        "--backend",
        "cpu-f32",
        "--out",
        common::s(&out),
    ]);
    assert!(o.status.success(), "{}", common::stderr(&o));
    assert!(out.is_file());
    let help = common::voxlab(&["render", "--help"]);
    let text = String::from_utf8_lossy(&help.stdout);
    assert!(text.contains("cubic-bspline-fast"), "{text}");
}
