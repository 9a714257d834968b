//! The GPU FFT against the oracle. From the bottom of the ladder up:
//! - the CPU twins of the shader functions, run through the same pass plans in f64,
//!   equal the exact DFT (no device needed);
//! - the shared parameter struct has one layout in Rust and WGSL, and both shaders
//!   validate (naga, no device needed);
//! - on the device, every variant matches `cpu::dft::dft_nd` (or, where the `O(N²)`
//!   oracle is too slow, `cpu::fft::fft_nd` in f64, itself tested against the DFT in
//!   tests/fft.rs) on random data, both directions, unitary and unnormalised; the
//!   parity cases are generated from one list for every variant;
//! - a delta transforms to a constant exactly; bad sizes are typed errors.
//!
//! `cargo test --release --test gpu_fft -- --nocapture` prints every measured error.

mod common;

use common::wgsl_struct_layout;

use rustfft::num_complex::Complex;
use std::mem::{offset_of, size_of};
use voxlab::cpu::dft::{dft_1d, dft_nd, Direction, Normalization};
use voxlab::gpu::fft::{self, FftParams, FftPass, GpuFftVariant};

type C = Complex<f64>;

/// The parity bound: relative L2 error ≤ `REL_L2_PER_STAGE · log2(N)`, `N` the total
/// size transformed (the project's target for f32 FFTs, as for `cpu::fft` in f32).
/// Measured on lavapipe (Mesa 22.3.6, LLVM 15): at most 1.6e-7 for every variant over
/// every case below (see docs/fft.md), well inside the bound.
const REL_L2_PER_STAGE: f64 = 1e-6;

/// The CPU twins through the pass plans against the exact DFT: f64 all the way, so
/// only rounding separates them.
const TWIN_REL_L2: f64 = 1e-14;

fn random_complex(rng: &mut common::Rng, n: usize) -> Vec<C> {
    (0..n)
        .map(|_| C::new(2.0 * rng.unit() - 1.0, 2.0 * rng.unit() - 1.0))
        .collect()
}

/// The relative L2 error of `port` against `oracle` (`metrics::error_stats_complex`;
/// ∞ on a NaN/Inf mismatch, so that every bound fails).
fn rel_l2<T: Copy + Into<f64>>(port: &[Complex<T>], oracle: &[C]) -> f64 {
    voxlab::metrics::error_stats_complex(oracle, port, f64::INFINITY)
        .infinite_if_mismatched()
        .rel_l2
}

/// Asserts the relative L2 error of `port` against `oracle` is at most `bound`
/// (`metrics::check_parity_complex`: a failure names the worst element and leaves
/// `target/parity/<case>/`); returns the error. `dims` x fastest.
fn assert_rel_l2(
    case: &str,
    dims: &[usize],
    port: &[Complex<f32>],
    oracle: &[C],
    bound: f64,
) -> f64 {
    let tol = voxlab::metrics::Tolerance::rel_l2(bound);
    common::assert_parity_complex(case, dims, oracle, port, tol).rel_l2
}

fn to_f32(x: &[C]) -> Vec<Complex<f32>> {
    x.iter()
        .map(|v| Complex::new(v.re as f32, v.im as f32))
        .collect()
}

/// The oracle sees exactly the f32 values the device sees.
fn to_f64(x: &[Complex<f32>]) -> Vec<C> {
    x.iter().map(|v| C::new(v.re as f64, v.im as f64)).collect()
}

// ---------------------------------------------------------------------------------
// Without a device
// ---------------------------------------------------------------------------------

/// Powers of two run the variant's passes; every other length runs Bluestein's
/// algorithm through the twins of `shaders/fft_bluestein.wgsl` and the same passes of
/// length `M` (1000 and 1025 take `M` past `LOCAL_MAX_N`).
const TWIN_LENGTHS: [usize; 21] = [
    1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 3, 5, 6, 7, 12, 17, 100, 127, 1000, 1025,
];

#[test]
fn cpu_twins_match_the_exact_dft() {
    let mut rng = common::Rng(0x5eed_f0f7);
    for n in TWIN_LENGTHS {
        let x = random_complex(&mut rng, n);
        for dir in [Direction::Forward, Direction::Inverse] {
            let want = dft_1d(&x, dir, Normalization::None);
            for variant in GpuFftVariant::ALL {
                let got = fft::reference_line(&x, dir, variant);
                let e = rel_l2(&got, &want);
                assert!(e < TWIN_REL_L2, "{variant:?} N={n} {dir:?}: rel L2 {e:e}");
            }
        }
    }
}

#[test]
fn pass_plans_have_the_promised_lengths() {
    use FftPass::*;
    let ss = |l| fft::plan(GpuFftVariant::SplitStream, l);
    let st = |l| fft::plan(GpuFftVariant::StockhamGlobal, l);
    let local = |l| fft::plan(GpuFftVariant::Stockham, l);
    assert!(ss(0).is_empty() && st(0).is_empty());
    assert_eq!(ss(1), [SplitStream { stage: 0 }]);
    assert_eq!(ss(2), [SplitStreamLastTwo { stage: 0 }]);
    assert_eq!(
        ss(4),
        [
            SplitStream { stage: 0 },
            SplitStream { stage: 1 },
            SplitStreamLastTwo { stage: 2 }
        ]
    );
    assert_eq!(st(1), [Radix2 { span: 1 }]);
    assert_eq!(st(4), [Radix4 { span: 1 }, Radix4 { span: 4 }]);
    assert_eq!(
        st(5),
        [Radix2 { span: 1 }, Radix4 { span: 2 }, Radix4 { span: 8 }]
    );
    assert!(local(0).is_empty());
    for l in 1..=10 {
        assert_eq!(local(l), [StockhamLocal], "log2 N = {l}");
    }
    assert_eq!(fft::LOCAL_MAX_N, 1 << 10);
    // Lines a workgroup of the workgroup-memory path takes: up to 16 (128 bytes), as
    // many as fill 1024 values.
    for (n, lines) in [(2, 16), (64, 16), (128, 8), (256, 4), (512, 2), (1024, 1)] {
        assert_eq!(fft::local_lines(n), lines, "N = {n}");
    }
    assert_eq!(local(11), st(11));
    for l in 2..=20 {
        assert_eq!(ss(l).len() as u32, l - 1, "split stream, log2 N = {l}");
        assert_eq!(st(l).len() as u32, l.div_ceil(2), "Stockham, log2 N = {l}");
    }
    // Bluestein: M is the least power of two ≥ 2n − 1; a load, the forward passes of
    // length M, a multiplication, the inverse passes and a store.
    use fft::FftStep::*;
    assert_eq!(fft::bluestein_length(16), None);
    assert_eq!(fft::bluestein_length(1), None);
    assert_eq!(fft::bluestein_length(3), Some(8));
    assert_eq!(fft::bluestein_length(12), Some(32));
    assert_eq!(fft::bluestein_length(17), Some(64));
    assert_eq!(fft::bluestein_length(1000), Some(2048));
    assert_eq!(
        fft::axis_plan(GpuFftVariant::Stockham, 100),
        [
            BluesteinLoad,
            Inner {
                pass: StockhamLocal,
                inverse: false
            },
            BluesteinMultiply,
            Inner {
                pass: StockhamLocal,
                inverse: true
            },
            BluesteinStore
        ]
    );
    assert_eq!(
        fft::axis_plan(GpuFftVariant::StockhamGlobal, 12),
        [
            BluesteinLoad,
            Inner {
                pass: Radix2 { span: 1 },
                inverse: false
            },
            Inner {
                pass: Radix4 { span: 2 },
                inverse: false
            },
            Inner {
                pass: Radix4 { span: 8 },
                inverse: false
            },
            BluesteinMultiply,
            Inner {
                pass: Radix2 { span: 1 },
                inverse: true
            },
            Inner {
                pass: Radix4 { span: 2 },
                inverse: true
            },
            Inner {
                pass: Radix4 { span: 8 },
                inverse: true
            },
            BluesteinStore
        ]
    );
    for variant in GpuFftVariant::ALL {
        for n in [3usize, 5, 12, 100, 1000, 1025] {
            let m = fft::bluestein_length(n).unwrap();
            assert!(
                m >= 2 * n - 1 && m < 4 * n && m.is_power_of_two(),
                "n = {n}"
            );
            let inner = fft::plan(variant, m.trailing_zeros()).len();
            assert_eq!(
                fft::axis_plan(variant, n).len(),
                3 + 2 * inner,
                "{variant:?} n = {n}"
            );
        }
        assert_eq!(
            fft::axis_plan(variant, 64),
            fft::plan(variant, 6)
                .into_iter()
                .map(Pass)
                .collect::<Vec<_>>()
        );
    }
}

/// The chirp is exact where it must be (c_0 = 1, and c_j = c_{j+2n}'s period folded
/// into j² mod 2n), and Bluestein's kernel spectrum is the DFT of the wrapped
/// conjugate chirp divided by M.
#[test]
fn bluestein_tables_are_the_chirp_and_its_kernel() {
    for n in [3usize, 7, 12, 100] {
        for dir in [Direction::Forward, Direction::Inverse] {
            let c = fft::bluestein_chirp(n, dir);
            assert_eq!(c[0], C::new(1.0, 0.0));
            let sign = if dir == Direction::Forward { -1.0 } else { 1.0 };
            for (j, v) in c.iter().enumerate() {
                let angle = sign * std::f64::consts::PI * (j * j) as f64 / n as f64;
                assert!(
                    (v - C::from_polar(1.0, angle)).norm() < 1e-12,
                    "n {n} j {j}"
                );
            }
            let m = fft::bluestein_length(n).unwrap();
            let mut b = vec![C::new(0.0, 0.0); m];
            for j in 0..n {
                b[j] = c[j].conj();
                b[(m - j) % m] = c[j].conj();
            }
            let want: Vec<C> = dft_1d(&b, Direction::Forward, Normalization::None)
                .iter()
                .map(|v| v / m as f64)
                .collect();
            let got = fft::bluestein_kernel(n, m, dir);
            assert!(rel_l2(&got, &want) < 1e-14, "n {n} {dir:?}");
        }
    }
}

#[test]
fn fft_params_layout_agrees() {
    let (span, members) = wgsl_struct_layout(fft::PARAMS_WGSL, "FftParams");
    assert_eq!(span as usize, size_of::<FftParams>(), "struct size");
    let rust = [
        ("n", offset_of!(FftParams, n)),
        ("log2n", offset_of!(FftParams, log2n)),
        ("stride", offset_of!(FftParams, stride)),
        ("batch", offset_of!(FftParams, batch)),
        ("stage", offset_of!(FftParams, stage)),
        ("direction", offset_of!(FftParams, direction)),
        ("span", offset_of!(FftParams, span)),
        ("scale", offset_of!(FftParams, scale)),
    ];
    assert_eq!(members.len(), rust.len(), "member count");
    for ((wname, woff), (rname, roff)) in members.iter().zip(&rust) {
        assert_eq!(wname, rname, "member order");
        assert_eq!(*woff as usize, *roff, "offset of {rname}");
    }
}

#[test]
fn every_fft_shader_validates() {
    let bluestein = voxlab::gpu::shaders::resolve("fft_bluestein");
    let sources = GpuFftVariant::ALL
        .map(|v| (format!("{v:?}"), v.shader_source()))
        .into_iter()
        .chain([("Bluestein".to_string(), bluestein)]);
    for (variant, src) in sources {
        common::validate_wgsl(&src, &variant);
    }
}

// ---------------------------------------------------------------------------------
// Parity on the device
// ---------------------------------------------------------------------------------

/// What a parity case transforms.
enum Case {
    /// `lines` contiguous 1-D lines of length `n` (`gpu::fft::fft_lines`).
    Lines { n: usize, lines: usize },
    /// Every axis of an array of this shape (`gpu::fft::fft_nd`).
    Nd(&'static [usize]),
}

/// Above this length a line's oracle is `cpu::fft::fft_nd` in f64 instead of the
/// `O(N²)` DFT.
const EXACT_DFT_MAX_LINE: usize = 1024;

fn oracle(case: &Case, x: &[C], dir: Direction, norm: Normalization) -> Vec<C> {
    match *case {
        Case::Lines { n, .. } if n > EXACT_DFT_MAX_LINE => {
            let mut y = x.to_vec();
            for line in y.chunks_mut(n) {
                voxlab::cpu::fft::fft_nd(line, &[n], dir, norm);
            }
            y
        }
        Case::Lines { n, .. } => x.chunks(n).flat_map(|l| dft_1d(l, dir, norm)).collect(),
        Case::Nd(shape) => dft_nd(x, shape, dir, norm),
    }
}

fn parity(name: &str, case: Case, variant: GpuFftVariant) {
    let test = format!("{name}::{variant:?}");
    let Some(ctx) = common::gpu(&test) else {
        return;
    };
    let (total, transformed) = match case {
        Case::Lines { n, lines } => (n * lines, n),
        Case::Nd(shape) => (shape.iter().product(), shape.iter().product()),
    };
    // The array's dimensions x fastest (the FFT's shapes are row-major).
    let dims: Vec<usize> = match case {
        Case::Lines { n, lines } => vec![n, lines],
        Case::Nd(shape) => shape.iter().rev().copied().collect(),
    };
    let tol = REL_L2_PER_STAGE * (transformed as f64).log2();
    let mut rng = common::Rng(0x0ff7_0000 ^ total as u64);
    let x32 = to_f32(&random_complex(&mut rng, total));
    let x = to_f64(&x32);
    for norm in [Normalization::Unitary, Normalization::Unnormalized] {
        for dir in [Direction::Forward, Direction::Inverse] {
            let got = match case {
                Case::Lines { n, .. } => fft::fft_lines(ctx, &x32, n, dir, norm, variant),
                Case::Nd(shape) => fft::fft_nd(ctx, &x32, shape, dir, norm, variant),
            }
            .unwrap_or_else(|e| panic!("{test}: {e}"));
            let want = oracle(&case, &x, dir, norm);
            let case_name = format!("gpu_fft_{name}_{variant:?}_{dir:?}_{norm:?}");
            let e = assert_rel_l2(&case_name, &dims, &got, &want, tol);
            eprintln!(
                "gpu fft {name:<10} {variant:<11?} {dir:<7?} {norm:<12?} rel L2 {e:.2e} (bound {tol:.1e})"
            );
        }
    }
}

/// One parity test per case and variant, from one list (`Stockham` uses workgroup
/// memory for lines up to `LOCAL_MAX_N`, so `lines_4096` exercises its fallback).
macro_rules! parity_cases {
    ($($name:ident: $case:expr;)*) => {$(
        mod $name {
            use super::*;
            #[test]
            fn split_stream() {
                parity(stringify!($name), $case, GpuFftVariant::SplitStream);
            }
            #[test]
            fn stockham() {
                parity(stringify!($name), $case, GpuFftVariant::Stockham);
            }
            #[test]
            fn stockham_global() {
                parity(stringify!($name), $case, GpuFftVariant::StockhamGlobal);
            }
        }
    )*};
}

parity_cases! {
    lines_2: Case::Lines { n: 2, lines: 5 };
    lines_4: Case::Lines { n: 4, lines: 5 };
    lines_8: Case::Lines { n: 8, lines: 5 };
    lines_64: Case::Lines { n: 64, lines: 4 };
    lines_1024: Case::Lines { n: 1024, lines: 3 };
    lines_4096: Case::Lines { n: 4096, lines: 6 };
    nd_64x64: Case::Nd(&[64, 64]);
    nd_256x128: Case::Nd(&[256, 128]);
    nd_32x32x32: Case::Nd(&[32, 32, 32]);
    nd_4x1x8: Case::Nd(&[4, 1, 8]);
    bluestein_lines_3: Case::Lines { n: 3, lines: 7 };
    bluestein_lines_100: Case::Lines { n: 100, lines: 5 };
    bluestein_lines_1000: Case::Lines { n: 1000, lines: 3 };
    bluestein_lines_3000: Case::Lines { n: 3000, lines: 2 };
    bluestein_nd_12x20: Case::Nd(&[12, 20]);
    bluestein_nd_6x8x10: Case::Nd(&[6, 8, 10]);
    bluestein_nd_3x5x7: Case::Nd(&[3, 5, 7]);
    bluestein_nd_17x1x9: Case::Nd(&[17, 1, 9]);
}

/// A delta at the origin transforms to a constant, exactly: every twiddle that meets a
/// non-zero value is `exp(0) = 1`.
#[test]
fn delta_transforms_to_a_constant() {
    let Some(ctx) = common::gpu("delta_transforms_to_a_constant") else {
        return;
    };
    for shape in [&[8usize][..], &[16, 8], &[4, 8, 2]] {
        let total: usize = shape.iter().product();
        let mut x = vec![Complex::new(0.0f32, 0.0); total];
        x[0] = Complex::new(1.0, 0.0);
        for variant in GpuFftVariant::ALL {
            for (norm, dir) in [
                (Normalization::Unnormalized, Direction::Forward),
                (Normalization::Unitary, Direction::Inverse),
            ] {
                let y = fft::fft_nd(ctx, &x, shape, dir, norm, variant).unwrap();
                let c = norm.factor(shape, dir) as f32;
                assert!(
                    y.iter().all(|&v| v == Complex::new(c, 0.0)),
                    "{variant:?} {shape:?} {dir:?} {norm:?}: {y:?}"
                );
            }
        }
    }
}

/// The device keeps the FFT's layouts and pipelines (`GpuContext::kept`): a second
/// transform of the same kind makes nothing, Bluestein's steps or another variant make
/// theirs once, and the results are the same bit for bit. (A context of its own, so no other
/// test's transforms come between.)
#[test]
fn a_second_transform_takes_the_first_ones_pipelines() {
    if common::gpu("a_second_transform_takes_the_first_ones_pipelines").is_none() {
        return;
    }
    let ctx = voxlab::gpu::GpuContext::new().expect("a second context on the test adapter");
    let mut rng = common::Rng(0x5eed_0029);
    let x = to_f32(&random_complex(&mut rng, 16 * 8));
    let run = |shape: &[usize], n: usize, variant| {
        let (f, i) = (Direction::Forward, Normalization::Unnormalized);
        fft::fft_nd(&ctx, &x[..n], shape, f, i, variant).unwrap()
    };
    assert_eq!(ctx.kept_made(), 0);
    let first = run(&[16, 8], 128, GpuFftVariant::Stockham);
    let made = ctx.kept_made();
    assert!(made >= 2, "a program and its pipeline: {made}");
    let again = run(&[16, 8], 128, GpuFftVariant::Stockham);
    assert_eq!(ctx.kept_made(), made, "a second transform made something");
    assert_eq!(first, again);
    // Bluestein's steps (a prime length) and another variant make theirs, once.
    run(&[13], 13, GpuFftVariant::Stockham);
    let bluestein = ctx.kept_made();
    assert!(bluestein > made);
    run(&[13], 13, GpuFftVariant::Stockham);
    assert_eq!(ctx.kept_made(), bluestein);
    run(&[16, 8], 128, GpuFftVariant::SplitStream);
    let split = ctx.kept_made();
    assert!(split > bluestein);
    run(&[16, 8], 128, GpuFftVariant::SplitStream);
    assert_eq!(ctx.kept_made(), split);
}

/// A shape that does not describe the data is a typed error; so is a line length that
/// does not divide it.
#[test]
fn mismatched_shapes_are_refused() {
    let Some(ctx) = common::gpu("mismatched_shapes_are_refused") else {
        return;
    };
    let x = vec![Complex::new(1.0f32, 0.0); 24];
    for variant in GpuFftVariant::ALL {
        let (dir, norm) = (Direction::Forward, Normalization::Unitary);
        let e = fft::fft_nd(ctx, &x, &[4, 8], dir, norm, variant)
            .expect_err("the shape does not fit the data");
        assert!(matches!(e, voxlab::Error::Invalid { .. }), "{e:?}");
        assert!(e.to_string().contains("does not describe 24 values"), "{e}");
        let e = fft::fft_lines(ctx, &x, 5, dir, norm, variant).expect_err("5 does not divide 24");
        assert!(e.to_string().contains("does not divide"), "{e}");
    }
}

/// A transform records one dispatch per step of every axis's plan: a power-of-two
/// axis its passes, any other axis Bluestein's load, passes, multiplication, passes
/// and store; `fft_nd_timed` reports that count.
#[test]
fn dispatches_follow_the_axis_plans() {
    let Some(ctx) = common::gpu("dispatches_follow_the_axis_plans") else {
        return;
    };
    let (dir, norm) = (Direction::Forward, Normalization::Unitary);
    for variant in GpuFftVariant::ALL {
        for shape in [&[12usize, 16][..], &[64], &[5, 6, 7], &[1, 3]] {
            let want: usize = shape
                .iter()
                .map(|&n| fft::axis_plan(variant, n).len())
                .sum();
            let plan = fft::GpuFftPlan::new(ctx, shape, dir, norm, variant).unwrap();
            assert_eq!(plan.dispatches(), want, "{variant:?} {shape:?}");
            let x = vec![Complex::new(1.0f32, 0.0); shape.iter().product()];
            let t = fft::fft_nd_timed(ctx, &x, shape, dir, norm, variant).unwrap();
            assert_eq!(t.timings.dispatches, want, "{variant:?} {shape:?}");
        }
    }
    // Stockham with M ≤ LOCAL_MAX_N: five dispatches for a length-12 axis, one for 16.
    let plan = fft::GpuFftPlan::new(ctx, &[12, 16], dir, norm, GpuFftVariant::Stockham).unwrap();
    assert_eq!(plan.dispatches(), 6);
}

/// A 1-D array over one storage binding whose length is prime (no four-step view) is
/// refused before anything is allocated on the device.
#[test]
fn oversized_data_is_refused() {
    let Some(ctx) = common::gpu("oversized_data_is_refused") else {
        return;
    };
    let limit = ctx
        .limits
        .max_storage_buffer_binding_size
        .min(ctx.limits.max_buffer_size);
    if limit > 256 << 20 {
        eprintln!("oversized_data_is_refused: the binding limit is {limit} bytes; not allocating that much on the host");
        return;
    }
    // The least prime past the binding (2^24 + 1 = 97 · 257 · 673 would be split).
    let is_prime = |n: usize| n > 1 && (2..=n.isqrt()).all(|d| !n.is_multiple_of(d));
    let len = ((limit / 8 + 1) as usize..).find(|&n| is_prime(n)).unwrap();
    let x = vec![Complex::new(0.0f32, 0.0); len];
    let e = fft::fft_nd(
        ctx,
        &x,
        &[len],
        Direction::Forward,
        Normalization::Unitary,
        GpuFftVariant::Stockham,
    )
    .expect_err("over the binding limit");
    assert!(matches!(e, voxlab::Error::TooLarge { .. }), "{e:?}");
    assert!(
        e.to_string().contains("max_storage_buffer_binding_size"),
        "{e}"
    );
    assert!(e.to_string().contains("no factor"), "{e}");
}

/// The workgroup-memory Stockham path runs the same butterflies on the same twiddles
/// as the storage-buffer passes: the results agree to the last bit. The shapes put
/// several lines in a workgroup along the last axis and along strided ones, lines of a
/// workgroup across the end of a stride's run (`3×64×5`: stride 5, 16 lines a
/// workgroup), a last workgroup with fewer lines (`17×64`, `3×64×5`), and Bluestein's
/// work lines (`12×20`, `64×48`).
#[test]
fn workgroup_memory_path_equals_the_global_passes() {
    let Some(ctx) = common::gpu("workgroup_memory_path_equals_the_global_passes") else {
        return;
    };
    let mut rng = common::Rng(0xb17_b17);
    let shapes: [&[usize]; 10] = [
        &[2],
        &[8, 512],
        &[16, 32, 8],
        &[4, 1024],
        &[17, 64],
        &[3, 64, 5],
        &[64, 3, 64],
        &[5, 2, 3],
        &[12, 20],
        &[64, 48],
    ];
    for shape in shapes {
        let total: usize = shape.iter().product();
        let x = to_f32(&random_complex(&mut rng, total));
        for dir in [Direction::Forward, Direction::Inverse] {
            let run = |variant| {
                fft::fft_nd(ctx, &x, shape, dir, Normalization::Unitary, variant).unwrap()
            };
            let local = run(GpuFftVariant::Stockham);
            let global = run(GpuFftVariant::StockhamGlobal);
            let same = local
                .iter()
                .zip(&global)
                .all(|(a, b)| a.re.to_bits() == b.re.to_bits() && a.im.to_bits() == b.im.to_bits());
            assert!(same, "{shape:?} {dir:?}: the two Stockham paths differ");
        }
    }
}

/// `fft_nd_timed` reports where the time went (printed; lavapipe's times say nothing
/// about a GPU's) and returns the same data as `fft_nd`.
#[test]
fn timings_are_reported() {
    let Some(ctx) = common::gpu("timings_are_reported") else {
        return;
    };
    let shape = [256usize, 128];
    let x = to_f32(&random_complex(&mut common::Rng(0x7133), 256 * 128));
    for variant in GpuFftVariant::ALL {
        let (dir, norm) = (Direction::Forward, Normalization::Unitary);
        let out = fft::fft_nd_timed(ctx, &x, &shape, dir, norm, variant).unwrap();
        let t = out.timings;
        eprintln!(
            "gpu fft timings 256x128 {variant:<14?} setup {:.2} ms, upload {:.2} ms, \
             kernel {:.2} ms ({}), readback {:.2} ms, total {:.2} ms",
            t.setup * 1e3,
            t.upload * 1e3,
            t.kernel * 1e3,
            if t.kernel_from_timestamps {
                "timestamps"
            } else {
                "wall clock"
            },
            t.readback * 1e3,
            t.total * 1e3,
        );
        let parts = [t.setup, t.upload, t.kernel, t.readback, t.total];
        assert!(parts.iter().all(|v| v.is_finite() && *v >= 0.0), "{t:?}");
        assert!(
            t.kernel > 0.0 && t.total >= t.setup + t.upload + t.readback,
            "{t:?}"
        );
        let plain = fft::fft_nd(ctx, &x, &shape, dir, norm, variant).unwrap();
        assert_eq!(out.data, plain);
    }
}

/// Forward then inverse restores the input (unitary and unnormalised), on a 3-D array.
#[test]
fn round_trip_restores_the_input() {
    let Some(ctx) = common::gpu("round_trip_restores_the_input") else {
        return;
    };
    let shape = [8usize, 16, 32];
    let x = to_f32(&random_complex(&mut common::Rng(0x4242), 8 * 16 * 32));
    for variant in GpuFftVariant::ALL {
        for norm in [Normalization::Unitary, Normalization::Unnormalized] {
            let y = fft::fft_nd(ctx, &x, &shape, Direction::Forward, norm, variant).unwrap();
            let z = fft::fft_nd(ctx, &y, &shape, Direction::Inverse, norm, variant).unwrap();
            // Two transforms, each within the parity bound.
            let e = assert_rel_l2(
                &format!("gpu_fft_round_trip_{variant:?}_{norm:?}"),
                &[32, 16, 8],
                &z,
                &to_f64(&x),
                2.0 * REL_L2_PER_STAGE * 12.0,
            );
            eprintln!("gpu fft round trip 8x16x32 {variant:<14?} {norm:<12?} rel L2 {e:.2e}");
        }
    }
}

#[test]
fn a_device_buffer_transforms_like_host_data() {
    let Some(ctx) = common::gpu("a_device_buffer_transforms_like_host_data") else {
        return;
    };
    use wgpu::util::DeviceExt;
    let mut rng = common::Rng(0xb0ff);
    let shape = [8, 16];
    let x: Vec<Complex<f32>> = random_complex(&mut rng, 128)
        .iter()
        .map(|v| Complex::new(v.re as f32, v.im as f32))
        .collect();
    let (dir, norm) = (Direction::Inverse, Normalization::Unnormalized);
    let variant = GpuFftVariant::Stockham;
    let want = fft::fft_nd(ctx, &x, &shape, dir, norm, variant).unwrap();
    let host: Vec<[f32; 2]> = x.iter().map(|v| [v.re, v.im]).collect();
    let buffer = ctx
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("input"),
            contents: bytemuck::cast_slice(&host),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        });
    let got = fft::fft_nd_buffer_timed(ctx, &buffer, &shape, dir, norm, variant).unwrap();
    assert_eq!(got.data, want, "the same passes give the same bits");
    assert_eq!(got.timings.upload, 0.0);
    let e = fft::fft_nd_buffer_timed(ctx, &buffer, &[8, 8], dir, norm, variant).unwrap_err();
    assert!(e.to_string().contains("do not hold"), "{e}");
}

// ---------------------------------------------------------------------------------
// Two real transforms through one complex transform
// ---------------------------------------------------------------------------------

#[test]
fn two_real_shader_validates() {
    let src = voxlab::gpu::shaders::resolve("fft_two_real");
    common::validate_wgsl(&src, "fft_two_real.wgsl");
}

/// `gpu::fft::two_real_ffts` against the exact DFT of each real line (up to
/// [`EXACT_DFT_MAX_LINE`]) and against `cpu::fft::two_real_ffts` in f64 (every size; it
/// is itself checked against two separate transforms in tests/fft.rs), within the
/// parity bound `1e-6·log2 N` for each spectrum. Measured on lavapipe: at most
/// 1.3e-7 (see the printed errors).
#[test]
fn two_real_ffts_match_the_cpu_and_the_dft() {
    let Some(ctx) = common::gpu("two_real_ffts_match_the_cpu_and_the_dft") else {
        return;
    };
    let mut rng = common::Rng(0x2ea1);
    for n in [1usize, 2, 4, 8, 64, 1024, 4096, 1 << 16, 3, 6, 100, 1000] {
        let a: Vec<f32> = (0..n).map(|_| 2.0 * rng.unit() as f32 - 1.0).collect();
        let b: Vec<f32> = (0..n).map(|_| 2.0 * rng.unit() as f32 - 1.0).collect();
        let (a64, b64): (Vec<f64>, Vec<f64>) = (
            a.iter().map(|&v| v as f64).collect(),
            b.iter().map(|&v| v as f64).collect(),
        );
        let (ga, gb) = fft::two_real_ffts(ctx, &a, &b).unwrap();
        let (ca, cb) = voxlab::cpu::fft::two_real_ffts(&a64, &b64);
        let tol = REL_L2_PER_STAGE * (n as f64).log2().max(1.0);
        let case = |which: &str| format!("gpu_two_real_ffts_{n}_{which}");
        let ea = assert_rel_l2(&case("a_vs_cpu"), &[n], &ga, &ca, tol);
        let eb = assert_rel_l2(&case("b_vs_cpu"), &[n], &gb, &cb, tol);
        eprintln!(
            "gpu two_real_ffts N={n:<6} vs cpu f64: rel L2 {ea:.2e}, {eb:.2e} (bound {tol:.1e})"
        );
        if n <= EXACT_DFT_MAX_LINE {
            let dft = |x: &[f64]| {
                let c: Vec<C> = x.iter().map(|&v| C::new(v, 0.0)).collect();
                dft_1d(&c, Direction::Forward, Normalization::Unnormalized)
            };
            let da = assert_rel_l2(&case("a_vs_dft"), &[n], &ga, &dft(&a64), tol);
            let db = assert_rel_l2(&case("b_vs_dft"), &[n], &gb, &dft(&b64), tol);
            eprintln!("gpu two_real_ffts N={n:<6} vs exact DFT: rel L2 {da:.2e}, {db:.2e}");
        }
    }
    let e = fft::two_real_ffts(ctx, &[1.0; 4], &[1.0; 8]).unwrap_err();
    assert!(e.to_string().contains("4 and 8"), "{e}");
}

// ---------------------------------------------------------------------------------
// The largest sizes
// ---------------------------------------------------------------------------------

/// The largest arrays, forward and unnormalised, against `cpu::fft::fft_nd` in f64 as
/// the oracle (the exact DFT would take hours at these sizes; the f64 FFT is itself
/// held to 1e-12 of the exact DFT at small sizes in tests/fft.rs, so its own error is
/// negligible next to the f32 bound). Bound: `1e-6·log2 N`, `N` the total size.
/// 256³ complex f32 is 128 MiB, exactly lavapipe's limit on one storage binding:
/// it must be accepted and transformed, not refused.
fn large_parity(shape: &[usize], variant: GpuFftVariant) {
    let test = format!("large {shape:?} {variant:?}");
    let Some(ctx) = common::gpu(&test) else {
        return;
    };
    let total: usize = shape.iter().product();
    let tol = REL_L2_PER_STAGE * (total as f64).log2();
    let mut rng = common::Rng(0x1a26e ^ total as u64);
    let x32 = to_f32(&random_complex(&mut rng, total));
    let mut want = to_f64(&x32);
    let (dir, norm) = (Direction::Forward, Normalization::Unnormalized);
    voxlab::cpu::fft::fft_nd(&mut want, shape, dir, norm);
    let start = std::time::Instant::now();
    let got = fft::fft_nd_timed(ctx, &x32, shape, dir, norm, variant)
        .unwrap_or_else(|e| panic!("{test}: {e}"));
    let seconds = start.elapsed().as_secs_f64();
    let dims: Vec<usize> = shape.iter().rev().copied().collect();
    let case = format!("gpu_fft_large_{shape:?}_{variant:?}");
    let e = assert_rel_l2(&case, &dims, &got.data, &want, tol);
    eprintln!(
        "gpu fft {test}: rel L2 {e:.2e} (bound {tol:.1e}); {seconds:.2} s on the device, passes {:.3} s",
        got.timings.kernel
    );
}

/// One test per large case and variant, from one list.
macro_rules! large_cases {
    ($($name:ident: $shape:expr;)*) => {$(
        mod $name {
            use super::*;
            #[test]
            fn stockham() {
                large_parity($shape, GpuFftVariant::Stockham);
            }
            #[test]
            fn split_stream() {
                large_parity($shape, GpuFftVariant::SplitStream);
            }
        }
    )*};
}

large_cases! {
    large_1d_65536: &[1 << 16];
    large_2d_1024x1024: &[1024, 1024];
    large_3d_256x256x256: &[256, 256, 256];
}

/// Shapes and split plans (slabs along axis 1 for axis 0's lines, slabs along axis 0
/// for the other axes), remainders included.
const SPLITS: [(&[usize], usize, usize); 6] = [
    (&[64, 32], 5, 7),
    (&[16, 8, 32], 3, 5),
    (&[8, 64, 4], 64, 1),
    (&[32, 16, 16], 1, 32),
    (&[12, 20, 6], 7, 5),
    (&[20, 16, 3], 3, 4),
];

#[test]
fn an_fft_in_slabs_equals_the_unsplit_one_bit_for_bit() {
    use voxlab::gpu::plan::Pieces;
    let Some(ctx) = common::gpu("an_fft_in_slabs_equals_the_unsplit_one_bit_for_bit") else {
        return;
    };
    let mut rng = common::Rng(5);
    for (shape, band, slab) in SPLITS {
        let x = to_f32(&random_complex(&mut rng, shape.iter().product()));
        let plan = fft::FftSplitPlan {
            axis0_lines: Pieces {
                total: shape[1],
                per_piece: band,
            },
            other_axes: Pieces {
                total: shape[0],
                per_piece: slab,
            },
            four_step: None,
        };
        for variant in [GpuFftVariant::Stockham, GpuFftVariant::SplitStream] {
            for (dir, norm) in [
                (Direction::Forward, Normalization::Unnormalized),
                (Direction::Inverse, Normalization::Unnormalized),
                (Direction::Forward, Normalization::Unitary),
            ] {
                let whole = fft::fft_nd(ctx, &x, shape, dir, norm, variant).unwrap();
                let split = fft::fft_nd_planned(ctx, &x, shape, dir, norm, variant, &plan)
                    .unwrap()
                    .data;
                let first = split.iter().zip(&whole).position(|(a, b)| a != b);
                assert_eq!(
                    first,
                    None,
                    "{shape:?} {variant:?} {dir:?} {norm:?}: {}",
                    plan.describe()
                );
            }
        }
    }
    // The plan under a small binding: [64, 32] complex values, 8 bytes each.
    let limits = wgpu::Limits {
        max_storage_buffer_binding_size: 4096,
        ..wgpu::Limits::default()
    };
    let p = fft::FftSplitPlan::new(&limits, &[64, 32]).unwrap();
    // 8 columns of 64 values (512 bytes each) and 16 rows of 32 values (256 bytes).
    assert_eq!((p.axis0_lines.per_piece, p.axis0_lines.count()), (8, 4));
    assert_eq!((p.other_axes.per_piece, p.other_axes.count()), (16, 4));
    // Bluestein's work lines count: a column of 12 values takes M = 32 on the device
    // (256 bytes, 16 columns a piece); a row of 20 takes M = 64 (512 bytes, 8 rows).
    let p = fft::FftSplitPlan::new(&limits, &[12, 20]).unwrap();
    assert_eq!((p.axis0_lines.per_piece, p.axis0_lines.count()), (16, 2));
    assert_eq!((p.other_axes.per_piece, p.other_axes.count()), (8, 2));
    assert_eq!(fft::work_len(&[12, 20], &[0, 1]), 12 * 64);
    assert_eq!(fft::work_len(&[12, 20], &[0]), 20 * 32);
    assert_eq!(fft::work_len(&[16, 32], &[0, 1]), 0);
    // A 1-D array is cut as its four-step view [N2, N1], N2 the largest divisor ≤ √N.
    assert_eq!(fft::four_step_factors(4096), Some([64, 64]));
    assert_eq!(fft::four_step_factors(12288), Some([96, 128]));
    assert_eq!(fft::four_step_factors(1000), Some([25, 40]));
    assert_eq!(fft::four_step_factors(6), Some([2, 3]));
    assert_eq!(fft::four_step_factors(4099), None);
    assert_eq!(fft::four_step_factors(2), None);
    let p = fft::FftSplitPlan::new(&limits, &[4096]).unwrap();
    assert_eq!(p.four_step, Some([64, 64]));
    assert_eq!(p.view(&[4096]), [64, 64]);
    assert_eq!((p.axis0_lines.per_piece, p.axis0_lines.count()), (8, 8));
    assert_eq!((p.other_axes.per_piece, p.other_axes.count()), (8, 8));
    assert!(p
        .describe()
        .starts_with("FFT in four steps as 64 × 64: 8 slabs"));
    let e = fft::FftSplitPlan::new(&limits, &[4099]).unwrap_err();
    assert!(matches!(e, voxlab::Error::TooLarge { .. }), "{e:?}");
    assert!(e.to_string().contains("no factor"), "{e}");
}

/// A 1-D transform past one binding runs in four steps (columns, twiddles, rows,
/// transpose): against the oracle within the parity bound, and against the unsplit
/// GPU transform within rounding (another factorisation of the same sum, so not to
/// the bit). Lengths: powers of two, a Bluestein row length (12288 = 96 × 128, the
/// columns of 96 by Bluestein), 1000 = 25 × 40 (both Bluestein), and the least, 6.
#[test]
fn a_1d_fft_past_one_binding_runs_in_four_steps() {
    let Some(ctx) = common::gpu("a_1d_fft_past_one_binding_runs_in_four_steps") else {
        return;
    };
    let limits = wgpu::Limits {
        max_storage_buffer_binding_size: 4096,
        ..wgpu::Limits::default()
    };
    let mut rng = common::Rng(0x4_57e9);
    for n in [4096usize, 1 << 16, 12288, 1000, 6] {
        let plan = fft::FftSplitPlan::new(&limits, &[n]).unwrap();
        let tol = REL_L2_PER_STAGE * (n as f64).log2();
        let x32 = to_f32(&random_complex(&mut rng, n));
        let x = to_f64(&x32);
        for variant in [GpuFftVariant::Stockham, GpuFftVariant::SplitStream] {
            for (dir, norm) in [
                (Direction::Forward, Normalization::Unnormalized),
                (Direction::Inverse, Normalization::Unitary),
            ] {
                let got = fft::fft_nd_planned(ctx, &x32, &[n], dir, norm, variant, &plan)
                    .unwrap()
                    .data;
                let want = oracle(&Case::Lines { n, lines: 1 }, &x, dir, norm);
                let name = format!("gpu_fft_four_step_{n}_{variant:?}_{dir:?}");
                let e = assert_rel_l2(&name, &[n], &got, &want, tol);
                let whole = fft::fft_nd(ctx, &x32, &[n], dir, norm, variant).unwrap();
                let d = rel_l2(&got, &to_f64(&whole));
                eprintln!(
                    "gpu fft four steps N={n:<6} {variant:<11?} {dir:<7?} rel L2 {e:.2e} \
                     (bound {tol:.1e}); against the unsplit GPU {d:.2e} ({})",
                    plan.describe()
                );
                assert!(d <= 2.0 * tol, "{name}: {d:e} from the unsplit transform");
            }
        }
    }
}
