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
use voxlab::gpu::plan::Sampling;
use voxlab::settings::{Compositing, Mode, RenderSettings};

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
    for sampling in [Sampling::Exact, Sampling::Hardware] {
        for storage in [ProjStorage::F32, ProjStorage::F16] {
            for parts in [1, 2, 3, gd2vr::MAX_PROJECTION_PARTS] {
                let src = gd2vr::shader_source(storage, sampling, parts);
                common::validate_wgsl(&src, &format!("{sampling:?} {storage:?} {parts}"));
                // Only the exact path carries the storage read; only the hardware one
                // the textures, one per part.
                let exact = sampling == Sampling::Exact;
                assert_eq!(src.contains("fn bilinear_zero("), exact);
                assert_eq!(
                    src.matches("texture_2d_array<f32>;").count(),
                    if exact { 0 } else { parts }
                );
            }
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
    // Decoding is exact: every half float but NaN comes back to its own bits, and the
    // known values to themselves.
    for h in 0..=u16::MAX {
        let v = gd2vr::f32_from_f16_bits(h);
        if v.is_nan() {
            assert_eq!(h & 0x7c00, 0x7c00, "{h:#06x}");
            continue;
        }
        assert_eq!(gd2vr::f16_bits(v), h, "{h:#06x} → {v}");
    }
    for (bits, x) in [
        (0x3c00u16, 1.0f32),
        (0xc000, -2.0),
        (0x7bff, 65504.0),
        (0x0001, 2f32.powi(-24)),
    ] {
        assert_eq!(gd2vr::f32_from_f16_bits(bits), x);
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

/// One row of [`CASES`] set up on the shared scene (`sc::phantom`, `sc::grid`,
/// `sc::tf`, a `SIDE`² camera): its geometry, the f32 filtered projections the GPU
/// reads, the occupancy mask, the options and settings, and the f64 oracle's render.
struct Row {
    g: voxlab::ct::Geometry,
    q32: voxlab::ct::Projections<f32>,
    mask: Option<OccupancyMask>,
    o: D2vrOptions,
    s: RenderSettings,
    cpu: cd2vr::D2vrOutput,
}

fn row(&(mode, gradient, cylinder, beam, occ): &Case) -> Row {
    let (ph, grid) = (sc::phantom(), sc::grid());
    let g = if beam == "cone" {
        sc::cone()
    } else {
        sc::parallel()
    };
    let q = sc::filtered(&ph, &g);
    let mask =
        occ.then(|| OccupancyMask::from_projections(&sc::raw(&ph, &g), &g, &grid, 1e-9).unwrap());
    let o = D2vrOptions {
        gradient,
        cylinder,
        value_range: (0.0, 1.5),
    };
    let s = settings(mode);
    let cpu = cd2vr::render_d2vr(
        &q,
        &g,
        &grid,
        &sc::tf(),
        &sc::camera(SIDE),
        &s,
        &o,
        mask.as_ref(),
        &|_, _| {},
    )
    .unwrap();
    Row {
        q32: sc::to_f32(&q),
        g,
        mask,
        o,
        s,
        cpu,
    }
}

#[test]
fn gpu_matches_the_cpu_oracle() {
    let Some(ctx) = common::gpu("gpu_matches_the_cpu_oracle") else {
        return;
    };
    let (cam, grid, tf) = (sc::camera(SIDE), sc::grid(), sc::tf());
    for case in CASES {
        let &(mode, gradient, cylinder, beam, occ) = case;
        let Row {
            g,
            q32,
            mask,
            o,
            s,
            cpu,
        } = row(case);
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
                Sampling::Exact,
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

/// The paper's reconstruction, projections in textures filtered by the texture unit
/// (`Sampling::Hardware`), over the parity table in both storage precisions: MIP and
/// X-ray images pixel by pixel within [`pixel_bounds`] (8-bit weights; on lavapipe at
/// most 2.6e-3 of it is used, the widest 1.5e-2 … 2.9e-2 of the peak) plus the exact
/// path's tolerance, on any adapter, and those bounds within the library's
/// `gd2vr::hardware_error_bound` (times the longest chord for X-ray); on a CPU
/// adapter (whose texture unit filters in f32) every image, DVR included, within a hair
/// of the exact GPU path's, GFR's gathered gradient with it. The same samples are
/// reconstructed as on the exact path. An adapter without `FLOAT32_FILTERABLE` refuses
/// f32 textures and still filters f16 ones.
#[test]
fn hardware_sampling_is_within_the_texture_units_bound() {
    let Some(ctx) = common::gpu("hardware_sampling_is_within_the_texture_units_bound") else {
        return;
    };
    let f32_filterable = ctx.features.contains(wgpu::Features::FLOAT32_FILTERABLE);
    let (cam, grid, tf) = (sc::camera(SIDE), sc::grid(), sc::tf());
    // The longest chord through the grid's box, mm (X-ray integrates over it).
    let d = grid.dims.map(|n| n as f64);
    let chord = grid
        .affine
        .transform_vector3(glam::DVec3::new(d[0], d[1], d[2]))
        .length();
    for case in CASES {
        let &(mode, gradient, cylinder, beam, occ) = case;
        let row = row(case);
        let Row {
            g,
            q32,
            mask,
            o,
            s,
            cpu,
        } = &row;
        let peak = cpu
            .render
            .image
            .data
            .iter()
            .fold(0f64, |m, v| m.max(v.abs()));
        for storage in [ProjStorage::F32, ProjStorage::F16] {
            let case = format!("{mode:?} {gradient:?} cyl={cylinder} {beam} occ={occ} {storage:?}");
            let run = |sampling| {
                gd2vr::render_d2vr(
                    ctx,
                    q32,
                    g,
                    &grid,
                    &tf,
                    &cam,
                    s,
                    o,
                    mask.as_ref(),
                    storage,
                    sampling,
                )
            };
            if storage == ProjStorage::F32 && !f32_filterable {
                let e = run(Sampling::Hardware).unwrap_err();
                assert!(e.to_string().contains("FLOAT32_FILTERABLE"), "{case}: {e}");
                continue;
            }
            let hw = run(Sampling::Hardware).unwrap();
            let exact = run(Sampling::Exact).unwrap();
            let max_diff =
                |a: &[f64], b: &[f64]| a.iter().zip(b).fold(0f64, |m, (x, y)| m.max((x - y).abs()));
            let (got, want) = (&hw.render.image.data, &cpu.render.image.data);
            let off = max_diff(got, want);
            let from_exact = max_diff(got, &exact.render.image.data);
            let tol = if storage == ProjStorage::F32 {
                TOL_F32
            } else {
                TOL_F16
            };
            let field = gd2vr::hardware_error_bound(q32, g, &grid, storage, 8);
            let library = match mode {
                Mode::Mip | Mode::Minip => Some(field),
                Mode::Xray => Some(field * chord),
                _ => None,
            };
            let (mut used, mut widest) = (0f64, 0f64);
            if let Some(library) = library {
                let pixels = pixel_bounds(&row, storage);
                for (i, ((a, b), e)) in got.iter().zip(want).zip(&pixels).enumerate() {
                    let bound = e + tol * peak;
                    assert!(
                        (a - b).abs() <= bound,
                        "{case}: pixel {i} off by {:e}, over the texture unit's bound {bound:e}",
                        (a - b).abs()
                    );
                    used = used.max((a - b).abs() / bound);
                }
                widest = pixels.iter().fold(0f64, |m, &v| m.max(v));
                assert!(
                    widest <= library,
                    "{case}: a pixel's bound {widest:e} over the library's {library:e}"
                );
                // Nothing but the values differs: the same samples, the same culling.
                assert_eq!(hw.stats, exact.stats, "{case}");
            }
            eprintln!(
                "hardware {case} on {}: {:.1e} of the peak from the oracle{}, {:.1e} from the \
                 exact GPU path",
                ctx.summary.name,
                off / peak,
                library.map_or(String::new(), |b| format!(
                    " ({used:.1e} of the pixel bounds, the widest {:.1e}; library bound {:.1e})",
                    widest / peak,
                    b / peak
                )),
                from_exact / peak
            );
            assert_eq!(hw.stats.box_samples, exact.stats.box_samples, "{case}");
            if ctx.summary.is_cpu() {
                // Measured on lavapipe: 1.0e-7 (X-ray) … 4.8e-6 (DVR GFS, f16) of the
                // peak; the bound is 4× the worst. (A texture coordinate a quarter
                // texel off gives 4.1e-2 … 2.3e-1, which the pixel bounds catch on
                // every MIP and X-ray row too; gathered taps in the wrong order give
                // 2.8e-1 on DVR GFR.)
                assert!(
                    from_exact <= 2e-5 * peak,
                    "{case}: {from_exact:e} from the exact GPU path (peak {peak:e})"
                );
            }
        }
    }
}

/// Per pixel of a MIP or X-ray row, how far the texture unit's image may lie from the
/// exact path's with filter weights of 8 fractional bits: a sample in detector cell `c`
/// of view `k` moves by at most `2 · D · 2⁻⁸` with `D` the spread of the cell's four
/// taps (zero outside the detector), so a sample by `π/(2A) Σ_k w_k · 2 · D_k · 2⁻⁸`, a
/// MIP pixel by the largest of its samples' bounds and an X-ray pixel by their sum over
/// the chord. Those sums are a MIP or X-ray of a field: the CPU oracle renders it from
/// "projections" `S` that hold, at each detector pixel, the largest spread of the cells
/// it is a tap of and of their neighbours (`common::cells_spread`; so the bilinear
/// value of `S` anywhere in a cell is at least the spread of that cell and of its
/// neighbours, where an f32 position may fall), on a detector two pixels wider on every
/// side (so that the cells reaching one pixel past the edge are inside it; its
/// bounding cylinder is wider, which only adds samples to a sum of non-negative
/// terms). `storage` rounds the taps as the texture
/// holds them; for f16 every pixel of `S` also carries `2⁻¹¹` of its view's largest
/// value over `2 · 2⁻⁸`, a unit's half-precision result (the library's allowance).
fn pixel_bounds(row: &Row, storage: ProjStorage) -> Vec<f64> {
    let g = &row.g;
    let (cols, rows, views) = (g.cols, g.rows, g.n_angles());
    let held = |v: f32| match storage {
        ProjStorage::F32 => v as f64,
        ProjStorage::F16 => gd2vr::f32_from_f16_bits(gd2vr::f16_bits(v)) as f64,
    };
    let (wide, high) = (cols + 4, rows + 4);
    let mut s = vec![0f64; views * wide * high];
    for k in 0..views {
        let view = &row.q32.data[k * cols * rows..(k + 1) * cols * rows];
        let top = view.iter().fold(0f64, |m, &v| m.max(held(v).abs()));
        let rounded = match storage {
            ProjStorage::F32 => 0.0,
            ProjStorage::F16 => top * 2f64.powi(-11) / (2.0 / 256.0),
        };
        for y in 0..high {
            for x in 0..wide {
                // Pixel (p, q) = (x − 2, y − 2) of the detector is a tap of cells
                // p − 1 ..= p, whose neighbours reach cells p − 2 ..= p + 1.
                let (p, q) = (x as i64 - 2, y as i64 - 2);
                let m = common::cells_spread((cols, rows), p - 2..=p + 1, q - 2..=q + 1, |i| {
                    held(view[i])
                });
                s[(k * high + y) * wide + x] = m + rounded;
            }
        }
    }
    let big = voxlab::ct::Geometry {
        cols: wide,
        rows: high,
        cu: g.cu + 2.0,
        cv: g.cv + 2.0,
        ..g.clone()
    };
    let sp = voxlab::ct::Projections::new(views, high, wide, s).unwrap();
    let out = cd2vr::render_d2vr(
        &sp,
        &big,
        &sc::grid(),
        &sc::tf(),
        &sc::camera(SIDE),
        &row.s,
        &row.o,
        row.mask.as_ref(),
        &|_, _| {},
    )
    .unwrap();
    out.render
        .image
        .data
        .iter()
        .map(|v| v * 2.0 / 256.0)
        .collect()
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
        Sampling::Exact,
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
    let one = D2vrSplit::new(
        &limits(1 << 27),
        &g,
        ProjStorage::F32,
        Sampling::Exact,
        (128, 128),
    )
    .unwrap();
    assert_eq!((one.views.count(), one.rows.count()), (1, 1));
    assert!(one.describe().is_empty());
    // 150 000 bytes: 16 whole views a binding (147 456 bytes), 73 rows of 128 pixels
    // (2048 bytes each) a band.
    let s = D2vrSplit::new(
        &limits(150_000),
        &g,
        ProjStorage::F32,
        Sampling::Exact,
        (128, 128),
    )
    .unwrap();
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
    let h = D2vrSplit::new(
        &limits(150_000),
        &g,
        ProjStorage::F16,
        Sampling::Exact,
        (128, 128),
    )
    .unwrap();
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
    let o = D2vrSplit::new(&limits(64), &odd, ProjStorage::F16, Sampling::Exact, (4, 4)).unwrap();
    assert_eq!((o.views.per_piece, o.views.count()), (2, 4));
    assert_eq!(o.part_bytes(2), 60);
    assert_eq!(o.part_bytes(1), 32);
    // 40 000 bytes: 4 views a binding in f32 is 16 bindings, more than the renderer
    // binds; in f16, 8 views a binding is 8.
    let e = D2vrSplit::new(
        &limits(40_000),
        &g,
        ProjStorage::F32,
        Sampling::Exact,
        (32, 32),
    )
    .unwrap_err();
    assert!(e.to_string().contains("16 storage bindings"), "{e}");
    let f = D2vrSplit::new(
        &limits(40_000),
        &g,
        ProjStorage::F16,
        Sampling::Exact,
        (32, 32),
    )
    .unwrap();
    assert_eq!(f.views.count(), gd2vr::MAX_PROJECTION_PARTS);
    // An adapter with fewer storage buffers per stage binds fewer.
    let few = wgpu::Limits {
        max_storage_buffers_per_shader_stage: 7,
        ..limits(150_000)
    };
    let e = D2vrSplit::new(&few, &g, ProjStorage::F32, Sampling::Exact, (32, 32)).unwrap_err();
    assert!(e.to_string().contains("more than the 2"), "{e}");
    // One view, or one image row, larger than a binding.
    let e = D2vrSplit::new(
        &limits(9000),
        &g,
        ProjStorage::F32,
        Sampling::Exact,
        (32, 32),
    )
    .unwrap_err();
    assert!(e.to_string().contains("one view (9216 bytes)"), "{e}");
    let e = D2vrSplit::new(
        &limits(150_000),
        &g,
        ProjStorage::F16,
        Sampling::Exact,
        (10_000, 2),
    )
    .unwrap_err();
    assert!(
        e.to_string().contains("one image row (160000 bytes)"),
        "{e}"
    );
}

/// The hardware path's plan: bordered views in texture arrays, cut by the binding
/// limit (so that `VOXLAB_GPU_MAX_BINDING` splits both paths alike) and by the array's
/// layers, a detector wider than a 2-D texture refused, and the adapter's sampled
/// textures per stage obeyed.
#[test]
fn the_hardware_split_plan_binds_bordered_texture_arrays() {
    // 64 views of 48 × 48 values: 50 × 50 texels with the border, 10 000 bytes a view
    // in R32Float, 5000 in R16Float.
    let g = sc::cone();
    let hw = Sampling::Hardware;
    let one = D2vrSplit::new(&limits(1 << 27), &g, ProjStorage::F32, hw, (32, 32)).unwrap();
    assert_eq!((one.views.count(), one.view_bytes), (1, 10_000));
    assert_eq!(one.part_bytes(64), 640_000);
    assert_eq!(one.device_bytes(), 640_000 + 2 * 32 * 32 * 16);
    assert_eq!(
        one.describe(),
        ["D²VR projections in 1 binding of 64 views (one texture array each)"]
    );
    // 150 000 bytes: 15 views an array (the exact path fits 16 unbordered ones).
    let s = D2vrSplit::new(&limits(150_000), &g, ProjStorage::F32, hw, (32, 32)).unwrap();
    assert_eq!((s.views.per_piece, s.views.count()), (15, 5));
    assert_eq!(
        s.describe(),
        ["D²VR projections in 5 bindings of 15 views (one texture array each)"]
    );
    let h = D2vrSplit::new(&limits(150_000), &g, ProjStorage::F16, hw, (32, 32)).unwrap();
    assert_eq!(
        (h.views.per_piece, h.views.count(), h.view_bytes),
        (30, 3, 5000)
    );
    assert_eq!(h.part_bytes(30), 150_000);
    // An array holds at most max_texture_array_layers views.
    let layered = wgpu::Limits {
        max_texture_array_layers: 10,
        ..limits(1 << 27)
    };
    let l = D2vrSplit::new(&layered, &g, ProjStorage::F32, hw, (32, 32)).unwrap();
    assert_eq!((l.views.per_piece, l.views.count()), (10, 7));
    // A bordered view wider than a 2-D texture.
    let narrow = wgpu::Limits {
        max_texture_dimension_2d: 49,
        ..limits(1 << 27)
    };
    let e = D2vrSplit::new(&narrow, &g, ProjStorage::F32, hw, (32, 32)).unwrap_err();
    assert!(e.to_string().contains("2-D texture size of 49"), "{e}");
    assert!(D2vrSplit::new(&narrow, &g, ProjStorage::F32, Sampling::Exact, (32, 32)).is_ok());
    // Fewer sampled textures per stage than the arrays needed.
    let few = wgpu::Limits {
        max_sampled_textures_per_shader_stage: 2,
        ..limits(150_000)
    };
    let e = D2vrSplit::new(&few, &g, ProjStorage::F32, hw, (32, 32)).unwrap_err();
    assert!(
        e.to_string().contains("5 texture arrays") && e.to_string().contains("more than the 2"),
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
        let f32_filterable = ctx.features.contains(wgpu::Features::FLOAT32_FILTERABLE);
        for (storage, sampling) in [
            (ProjStorage::F32, Sampling::Exact),
            (ProjStorage::F16, Sampling::Exact),
            (ProjStorage::F32, Sampling::Hardware),
            (ProjStorage::F16, Sampling::Hardware),
        ] {
            if storage == ProjStorage::F32 && sampling == Sampling::Hardware && !f32_filterable {
                continue;
            }
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
                    sampling,
                )
                .unwrap()
            };
            let (whole, split) = (run(ctx), run(&small));
            let case = format!("{mode:?} {gradient:?} {beam} occ={occ} {storage:?} {sampling:?}");
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
