//! The GPU is present and computes: adapter selection, device limits, and a compute
//! dispatch whose every output matches the CPU twin's f32 arithmetic.

mod common;

#[test]
fn adapter_opens_and_computes() {
    let Some(ctx) = common::gpu("adapter_opens_and_computes") else {
        return;
    };
    eprintln!("{}", ctx.describe());
    // We asked for the adapter's own limits, not wgpu's defaults.
    assert_eq!(
        ctx.device.limits().max_storage_buffer_binding_size,
        ctx.adapter.limits().max_storage_buffer_binding_size
    );
    let n = voxlab::gpu::probe::self_test(ctx).expect("the device computes a·x + b like the CPU");
    assert!(n > 4096);
}

#[test]
fn probe_matches_cpu_on_awkward_sizes() {
    let Some(ctx) = common::gpu("probe_matches_cpu_on_awkward_sizes") else {
        return;
    };
    for len in [1usize, 63, 64, 65, 1000] {
        let x: Vec<f32> = (0..len).map(|i| (i as f32).sin() * 1e3).collect();
        let y = voxlab::gpu::probe::saxpy_gpu(ctx, -2.5, 0.125, &x).unwrap();
        assert_eq!(y.len(), len);
        for (xi, yi) in x.iter().zip(&y) {
            let want = voxlab::gpu::probe::saxpy_cpu(-2.5, *xi, 0.125);
            assert!((yi - want).abs() <= want.abs() * 2.0 * f32::EPSILON);
        }
    }
    assert!(voxlab::gpu::probe::saxpy_gpu(ctx, 1.0, 0.0, &[])
        .unwrap()
        .is_empty());
}

#[test]
fn broken_shader_is_a_typed_error() {
    let Some(ctx) = common::gpu("broken_shader_is_a_typed_error") else {
        return;
    };
    let e = ctx
        .shader("broken.wgsl", "fn main( {")
        .expect_err("must not compile");
    assert!(matches!(e, voxlab::Error::Gpu(_)));
    assert!(e.to_string().contains("broken.wgsl"));
}

/// The compositing shaders' `ln_1p`, `exp_m1` and `step_opacity`
/// (`shaders/shared/opacity.wgsl`) against f64 over the ranges the casters use, down to
/// opacities of 1e-7 per step. Bound: 16 f32 ulps (relative 16·2^-23): Vulkan allows
/// exp 3 + 2|x| ulps and log 3 ulps (outside [0.5, 2]), which the series and the
/// exp/log branches keep under 8; `1 − pow(1 − a, r)` misses it by orders of magnitude
/// for small a (0.06 relative at a = 1e-6, where 1 − a rounds).
#[test]
fn opacity_functions_match_f64() {
    let Some(ctx) = common::gpu("opacity_functions_match_f64") else {
        return;
    };
    let logs = |lo: f64, hi: f64, n: usize| -> Vec<f64> {
        (0..n)
            .map(|i| 10f64.powf(lo + (hi - lo) * i as f64 / (n - 1) as f64))
            .collect()
    };
    // ln_1p on (−1, 4]: tiny values of both signs, then the whole range.
    let mut x1: Vec<f64> = logs(-8.0, 0.0, 200)
        .iter()
        .flat_map(|&m| [m, -m * 0.999])
        .collect();
    x1.extend((1..=500).map(|i| -1.0 + 5.0 * i as f64 / 500.0));
    // exp_m1 on [−30, 2].
    let mut x2: Vec<f64> = logs(-8.0, 0.3, 200).iter().flat_map(|&m| [m, -m]).collect();
    x2.extend((0..=500).map(|i| -30.0 + 32.0 * i as f64 / 500.0));
    // step_opacity: a in [1e-7, 1 − 2^-20], r from 1/20 to 8 reference steps.
    let mut ar = Vec::new();
    for &a in logs(-7.0, 0.0, 120)
        .iter()
        .chain(&[0.5, 0.9, 0.999, 1.0 - 2f64.powi(-20)])
    {
        let a = a.min(1.0 - 2f64.powi(-20));
        for r in [0.05, 0.25, 0.5, 1.0, 1.7, 8.0] {
            ar.push((a, r));
        }
    }
    let n = x1.len().max(x2.len()).max(ar.len());
    let at = |v: &[f64], i: usize| v[i % v.len()] as f32;
    let inputs: Vec<[f32; 4]> = (0..n)
        .map(|i| {
            let (a, r) = ar[i % ar.len()];
            [at(&x1, i), at(&x2, i), a as f32, r as f32]
        })
        .collect();
    let out = voxlab::gpu::probe::opacity_gpu(ctx, &inputs).unwrap();
    let ulps = |got: f32, want: f64| (got as f64 - want).abs() / want.abs() / f32::EPSILON as f64;
    let (mut worst_ln, mut worst_exp, mut worst_alpha) = (0.0f64, 0.0f64, 0.0f64);
    for (v, o) in inputs.iter().zip(&out) {
        let [x1, x2, a, r] = v.map(|x| x as f64);
        worst_ln = worst_ln.max(ulps(o[0], x1.ln_1p()));
        worst_exp = worst_exp.max(ulps(o[1], x2.exp_m1()));
        worst_alpha = worst_alpha.max(ulps(o[2], -(r * (-a).ln_1p()).exp_m1()));
    }
    eprintln!(
        "worst error in f32 ulps: ln_1p {worst_ln:.2}, exp_m1 {worst_exp:.2}, step_opacity {worst_alpha:.2}"
    );
    for (name, e) in [
        ("ln_1p", worst_ln),
        ("exp_m1", worst_exp),
        ("step_opacity", worst_alpha),
    ] {
        assert!(e <= 16.0, "{name}: {e:.1} ulps");
    }
}

/// An entry point a kept program lacks is a typed error naming it (the device's
/// validation, caught), not a panic; the program's other entry points still compile.
#[test]
fn a_missing_entry_point_is_a_typed_error() {
    let Some(ctx) = common::gpu("a_missing_entry_point_is_a_typed_error") else {
        return;
    };
    let source = voxlab::gpu::shaders::resolve("probe");
    let program = ctx.program("probe.wgsl", &source, None).unwrap();
    let e = program
        .kernel(ctx, "no_such_entry")
        .expect_err("the shader has no such entry point");
    assert!(matches!(e, voxlab::Error::Gpu(_)), "{e:?}");
    assert!(e.to_string().contains("no_such_entry"), "{e}");
    program
        .kernel(ctx, "saxpy")
        .expect("the probe's entry point");
}
