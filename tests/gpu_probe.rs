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
