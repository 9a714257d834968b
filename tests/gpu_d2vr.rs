//! D²VR on the GPU (`gpu::d2vr`) against the CPU f64 oracle (`cpu::d2vr`): the shared
//! parameter layout and shader validity (naga, no device), parity over one case table
//! (mode × gradient × cylinder × beam, occupancy), the 16-bit projection storage with
//! its own bound, the split past one binding (projections over several bindings, the
//! image in bands: the unsplit image bit for bit), and the refusals.

mod common;
mod d2vr_scene;

use common::wgsl_struct_layout;
use d2vr_scene as sc;
use std::mem::{offset_of, size_of};
use voxlab::cpu::d2vr::{self as cd2vr, D2vrGradient, D2vrOptions, OccupancyMask};
use voxlab::gpu::d2vr::{self as gd2vr, D2vrParams, D2vrSplit, ProjStorage};
use voxlab::settings::{Compositing, Mode, RenderSettings};
use wgpu::naga;

/// Largest `max |gpu − cpu| / max |cpu|` for f32 storage. The GPU reconstructs every
/// sample in f32 (64 views); a DVR pixel amplifies a value error by the TF's slope, and
/// a ray that crosses the ERT threshold one sample earlier or later differs by up to
/// one sample's contribution. Measured on lavapipe over `CASES`: 1.8e-6 … 1.6e-5
/// (worst: DVR GFR cone, with and without occupancy).
const TOL_F32: f64 = 1e-4;
/// The same for f16 storage (11-bit significand: relative rounding 2⁻¹¹ ≈ 4.9e-4 per
/// tap, then the TF's slope). Measured: 3.0e-5 (X-ray) … 1.2e-4 (MIP) … 8.8e-3 (DVR
/// GFR cone).
const TOL_F16: f64 = 3e-2;

#[test]
fn d2vr_params_layout_agrees() {
    let (span, members) = wgsl_struct_layout(gd2vr::PARAMS_WGSL, "D2vrParams");
    assert_eq!(span as usize, size_of::<D2vrParams>());
    let rust = [
        ("to_world_0", offset_of!(D2vrParams, to_world_0)),
        ("to_world_1", offset_of!(D2vrParams, to_world_1)),
        ("to_world_2", offset_of!(D2vrParams, to_world_2)),
        ("jt_0", offset_of!(D2vrParams, jt_0)),
        ("jt_1", offset_of!(D2vrParams, jt_1)),
        ("jt_2", offset_of!(D2vrParams, jt_2)),
        ("cylinder", offset_of!(D2vrParams, cylinder)),
        ("det", offset_of!(D2vrParams, det)),
        ("flags", offset_of!(D2vrParams, flags)),
        ("chunk", offset_of!(D2vrParams, chunk)),
    ];
    assert_eq!(members.len(), rust.len());
    for ((name, off), (rname, roff)) in members.iter().zip(rust) {
        assert_eq!((name.as_str(), *off as usize), (rname, roff));
    }
}

#[test]
fn d2vr_shader_validates() {
    for storage in [ProjStorage::F32, ProjStorage::F16] {
        for parts in [1, 2, 3, gd2vr::MAX_PROJECTION_PARTS] {
            let src = gd2vr::shader_source(storage, parts);
            let module = naga::front::wgsl::parse_str(&src)
                .unwrap_or_else(|e| panic!("{}", e.emit_to_string(&src)));
            naga::valid::Validator::new(
                naga::valid::ValidationFlags::all(),
                naga::valid::Capabilities::all(),
            )
            .validate(&module)
            .unwrap_or_else(|e| panic!("{storage:?} {parts}: {e:?}"));
        }
    }
}

#[test]
fn f16_rounding_matches_ieee() {
    for (x, bits) in [
        (0.0f32, 0x0000u16),
        (1.0, 0x3c00),
        (-2.0, 0xc000),
        (65504.0, 0x7bff),
        (1e6, 0x7c00),
        (5.960_464_5e-8, 0x0001),
        (0.333_333_34, 0x3555),
    ] {
        assert_eq!(gd2vr::f16_bits(x), bits, "{x}");
    }
}

/// (mode, gradient, cylinder, beam, occupancy)
type Case = (Mode, D2vrGradient, bool, &'static str, bool);
/// Measured max relative errors on lavapipe (f32 storage): DVR 4.9e-6 … 1.6e-5,
/// MIP ≤ 7.5e-6, X-ray ≤ 1.9e-6. The whole table runs in about 5 s.
const CASES: &[Case] = &[
    (Mode::Dvr, D2vrGradient::Gfr, true, "parallel", false),
    (Mode::Dvr, D2vrGradient::Gfs, true, "parallel", false),
    (Mode::Dvr, D2vrGradient::Gfr, false, "cone", false),
    (Mode::Dvr, D2vrGradient::Gfs, true, "cone", false),
    (Mode::Dvr, D2vrGradient::Gfr, true, "cone", true),
    (Mode::Mip, D2vrGradient::Gfr, true, "parallel", false),
    (Mode::Mip, D2vrGradient::Gfr, false, "cone", false),
    (Mode::Xray, D2vrGradient::Gfr, false, "parallel", false),
    (Mode::Xray, D2vrGradient::Gfr, true, "cone", true),
];

const SIDE: usize = 32;

fn settings(mode: Mode) -> RenderSettings {
    RenderSettings {
        mode,
        step: 1.0,
        ..RenderSettings::default()
    }
}

#[test]
fn gpu_matches_the_cpu_oracle() {
    let Some(ctx) = common::gpu("gpu_matches_the_cpu_oracle") else {
        return;
    };
    let ph = sc::phantom();
    let cam = sc::camera(SIDE);
    let grid = sc::grid();
    let tf = sc::tf();
    for &(mode, gradient, cylinder, beam, occ) in CASES {
        let g = if beam == "cone" {
            sc::cone()
        } else {
            sc::parallel()
        };
        let q = sc::filtered(&ph, &g);
        let q32 = sc::to_f32(&q);
        let mask = occ
            .then(|| OccupancyMask::from_projections(&sc::raw(&ph, &g), &g, &grid, 1e-9).unwrap());
        let o = D2vrOptions {
            gradient,
            cylinder,
            value_range: (0.0, 1.5),
        };
        let s = settings(mode);
        let cpu = cd2vr::render_d2vr(&q, &g, &grid, &tf, &cam, &s, &o, mask.as_ref(), &|_, _| {})
            .unwrap();
        for storage in [ProjStorage::F32, ProjStorage::F16] {
            let gpu = gd2vr::render_d2vr(
                ctx,
                &q32,
                &g,
                &grid,
                &tf,
                &cam,
                &s,
                &o,
                mask.as_ref(),
                storage,
            )
            .unwrap();
            let tol = if storage == ProjStorage::F32 {
                TOL_F32
            } else {
                TOL_F16
            };
            let e = common::assert_parity(
                &format!("gpu_d2vr_{mode:?}_{gradient:?}_{cylinder}_{beam}_{occ}_{storage:?}"),
                &cpu.render.image,
                &gpu.render.image,
                voxlab::metrics::Tolerance::max_abs_rel(tol),
            )
            .max_abs_rel;
            let timestamps = ctx.features.contains(wgpu::Features::TIMESTAMP_QUERY);
            assert_eq!(gpu.timings.kernel_from_timestamps, timestamps);
            assert!(gpu.timings.kernel > 0.0 && gpu.timings.kernel <= gpu.timings.total);
            eprintln!(
                "{mode:?} {gradient:?} cyl={cylinder} {beam} occ={occ} {storage:?}: max rel {e:.2e}; \
                 fraction cpu {:.3} gpu {:.3}; {} dispatches, kernel {:.3} s",
                cpu.stats.fraction(),
                gpu.stats.fraction(),
                gpu.timings.dispatches,
                gpu.timings.kernel
            );
            if storage == ProjStorage::F32 {
                assert_eq!(gpu.stats.box_samples, cpu.stats.box_samples);
                // Reconstruction counts agree up to samples at the f32 cylinder edge.
                let (a, b) = (
                    cpu.stats.value_reconstructions as f64,
                    gpu.stats.value_reconstructions as f64,
                );
                assert!((a - b).abs() <= 1e-3 * a + 8.0, "{a} vs {b}");
            }
        }
    }
}

#[test]
fn gpu_refuses_back_to_front() {
    let Some(ctx) = common::gpu("gpu_refuses_back_to_front") else {
        return;
    };
    let g = sc::parallel();
    let q = sc::to_f32(&sc::filtered(&sc::sphere(), &g));
    let mut s = settings(Mode::Dvr);
    s.compositing = Compositing::BackToFront;
    let o = D2vrOptions::default();
    let r = gd2vr::render_d2vr(
        ctx,
        &q,
        &g,
        &sc::grid(),
        &sc::tf(),
        &sc::camera(8),
        &s,
        &o,
        None,
        ProjStorage::F32,
    );
    assert!(r.is_err());
}

/// Limits with a storage binding of `bytes` (and room for every projection binding).
fn limits(bytes: u64) -> wgpu::Limits {
    wgpu::Limits {
        max_storage_buffer_binding_size: bytes,
        max_storage_buffers_per_shader_stage: 16,
        ..wgpu::Limits::default()
    }
}

#[test]
fn the_split_plan_cuts_whole_views_and_rows_and_refuses_what_cannot_fit() {
    // 64 views of 48 × 48 values: 9216 bytes a view in f32, 4608 in f16 pairs.
    let g = sc::cone();
    let one = D2vrSplit::new(&limits(1 << 27), &g, ProjStorage::F32, (128, 128)).unwrap();
    assert_eq!((one.views.count(), one.rows.count()), (1, 1));
    assert!(one.describe().is_empty());
    // 150 000 bytes: 16 whole views a binding (147 456 bytes), 73 rows of 128 pixels
    // (2048 bytes each) a band.
    let s = D2vrSplit::new(&limits(150_000), &g, ProjStorage::F32, (128, 128)).unwrap();
    assert_eq!((s.views.per_piece, s.views.count()), (16, 4));
    assert_eq!((s.rows.per_piece, s.rows.count()), (73, 2));
    assert_eq!(s.part_bytes(16), 147_456);
    assert_eq!(s.largest_buffer(), 73 * 2048);
    assert_eq!(s.device_bytes(), 4 * 147_456 + 2 * 73 * 2048);
    assert_eq!(
        s.describe(),
        [
            "D²VR projections in 4 bindings of 16 views (one storage binding each)",
            "D²VR image in 2 bands of 73 rows"
        ]
    );
    let h = D2vrSplit::new(&limits(150_000), &g, ProjStorage::F16, (128, 128)).unwrap();
    assert_eq!((h.views.per_piece, h.views.count()), (32, 2));
    assert_eq!(h.part_bytes(32), 147_456);
    // f16 pairs of an odd number of values round up to whole words.
    let odd = voxlab::ct::Geometry::parallel_stack(
        3,
        5,
        1.0,
        1.0,
        voxlab::ct::Geometry::even_angles(7, 180.0),
    )
    .unwrap();
    // 15 values a view: two views are 30 values (60 bytes), one is 8 words.
    let o = D2vrSplit::new(&limits(64), &odd, ProjStorage::F16, (4, 4)).unwrap();
    assert_eq!((o.views.per_piece, o.views.count()), (2, 4));
    assert_eq!(o.part_bytes(2), 60);
    assert_eq!(o.part_bytes(1), 32);
    // 40 000 bytes: 4 views a binding in f32 is 16 bindings, more than the renderer
    // binds; in f16, 8 views a binding is 8.
    let e = D2vrSplit::new(&limits(40_000), &g, ProjStorage::F32, (32, 32)).unwrap_err();
    assert!(e.to_string().contains("16 storage bindings"), "{e}");
    let f = D2vrSplit::new(&limits(40_000), &g, ProjStorage::F16, (32, 32)).unwrap();
    assert_eq!(f.views.count(), gd2vr::MAX_PROJECTION_PARTS);
    // An adapter with fewer storage buffers per stage binds fewer.
    let few = wgpu::Limits {
        max_storage_buffers_per_shader_stage: 7,
        ..limits(150_000)
    };
    let e = D2vrSplit::new(&few, &g, ProjStorage::F32, (32, 32)).unwrap_err();
    assert!(e.to_string().contains("more than the 2"), "{e}");
    // One view, or one image row, larger than a binding.
    let e = D2vrSplit::new(&limits(9000), &g, ProjStorage::F32, (32, 32)).unwrap_err();
    assert!(e.to_string().contains("one view (9216 bytes)"), "{e}");
    let e = D2vrSplit::new(&limits(150_000), &g, ProjStorage::F16, (10_000, 2)).unwrap_err();
    assert!(
        e.to_string().contains("one image row (160000 bytes)"),
        "{e}"
    );
}

#[test]
fn split_renders_equal_the_unsplit_bit_for_bit() {
    let Some(ctx) = common::gpu("split_renders_equal_the_unsplit_bit_for_bit") else {
        return;
    };
    let mut small = voxlab::gpu::GpuContext::new().unwrap();
    small.limits.max_storage_buffer_binding_size = 150_000;
    let ph = sc::phantom();
    let cam = sc::camera(128);
    let grid = sc::grid();
    let tf = sc::tf();
    let cases = [
        (Mode::Dvr, D2vrGradient::Gfr, "cone", true),
        (Mode::Dvr, D2vrGradient::Gfs, "parallel", false),
        (Mode::Mip, D2vrGradient::Gfr, "cone", false),
        (Mode::Xray, D2vrGradient::Gfr, "parallel", false),
        (Mode::Dvr, D2vrGradient::Gfr, "odd", false),
    ];
    for (mode, gradient, beam, occ) in cases {
        let g = match beam {
            "cone" => sc::cone(),
            "parallel" => sc::parallel(),
            // 47 × 47 values a view and 63 views: a binding of f16 pairs starts and
            // ends mid-word of the unsplit packing.
            _ => {
                let d = sc::EXTENT / 47.0;
                let angles = voxlab::ct::Geometry::even_angles(63, 180.0);
                voxlab::ct::Geometry::parallel_stack(47, 47, d, d, angles).unwrap()
            }
        };
        let q32 = sc::to_f32(&sc::filtered(&ph, &g));
        let mask = occ
            .then(|| OccupancyMask::from_projections(&sc::raw(&ph, &g), &g, &grid, 1e-9).unwrap());
        let o = D2vrOptions {
            gradient,
            cylinder: true,
            value_range: (0.0, 1.5),
        };
        let s = settings(mode);
        for storage in [ProjStorage::F32, ProjStorage::F16] {
            let run = |c: &voxlab::gpu::GpuContext| {
                gd2vr::render_d2vr(
                    c,
                    &q32,
                    &g,
                    &grid,
                    &tf,
                    &cam,
                    &s,
                    &o,
                    mask.as_ref(),
                    storage,
                )
                .unwrap()
            };
            let (whole, split) = (run(ctx), run(&small));
            let case = format!("{mode:?} {gradient:?} {beam} occ={occ} {storage:?}");
            assert_eq!(whole.split.views.count(), 1, "{case}");
            assert!(split.split.views.count() > 1, "{case}: {:?}", split.split);
            assert_eq!(split.split.rows.count(), 2, "{case}");
            assert!(
                split.render.image.data.iter().any(|&v| v != 0.0),
                "{case}: blank"
            );
            let (a, b) = (&split.render.image.data, &whole.render.image.data);
            assert_eq!(a.len(), b.len(), "{case}");
            let differ = a
                .iter()
                .zip(b)
                .filter(|(x, y)| x.to_bits() != y.to_bits())
                .count();
            assert_eq!(differ, 0, "{case}: {differ} of {} values differ", a.len());
            assert_eq!(split.stats, whole.stats, "{case}");
        }
    }
}
