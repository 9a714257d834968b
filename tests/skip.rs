//! Empty-space skipping, the clipping box and jittered sampling on the CPU: skipping
//! never changes an image, the min/max grid is conservative, clipping matches zeroed
//! voxels and an analytic slab, and accumulated jittered frames converge to a
//! fine-step reference.

mod common;

use glam::DVec3;
use voxlab::camera::{AxisView, Camera, Orbit, Projection};
use voxlab::cpu::filter::sample;
use voxlab::cpu::grid::Grid;
use voxlab::cpu::raycast::render;
use voxlab::cpu::skip::{cell_count, Skipper};
use voxlab::real::{Real, V3};
use voxlab::settings::{
    Classification, ClipBox, ClipSpace, Compositing, Filter, Mode, RenderSettings,
};
use voxlab::transfer::TransferFunction;
use voxlab::{AnyVolume, Volume};

fn none() -> &'static (dyn Fn(usize, usize) + Sync) {
    &|_, _| {}
}

use common::sparse_tf;

use common::odd_phantom as phantom;
use voxlab::metrics::max_abs_error;

#[derive(Clone, Copy, Debug)]
enum Cam {
    Perspective,
    Ortho,
    Axis,
}

fn camera(vol: &AnyVolume, cam: Cam, size: usize) -> Camera {
    let orbit = |projection| common::orbit_camera(projection, size, size * 3 / 4);
    match cam {
        Cam::Perspective => orbit(Projection::Perspective { fov_y_deg: 30.0 }),
        Cam::Ortho => orbit(Projection::Orthographic {
            width_mm: 270.0,
            height_mm: 270.0 * 0.75,
        }),
        Cam::Axis => {
            let d = vol.dims();
            Camera::axis_view(d, vol.affine(), AxisView::MinusY, d[0], d[2]).unwrap()
        }
    }
}

#[derive(Clone, Copy, Debug)]
struct Case {
    filter: Filter,
    cam: Cam,
    classification: Classification,
    compositing: Compositing,
    block: usize,
}

const BASE: Case = Case {
    filter: Filter::Trilinear,
    cam: Cam::Perspective,
    classification: Classification::Post,
    compositing: Compositing::FrontToBack,
    block: 8,
};

fn settings(case: &Case, skip: bool) -> RenderSettings {
    RenderSettings {
        filter: case.filter,
        classification: case.classification,
        compositing: case.compositing,
        block_size: case.block,
        skip_empty: skip,
        sample_count: true,
        ..RenderSettings::default()
    }
}

/// Renders with skipping off and on; returns the largest difference and the fraction
/// of samples skipping kept.
fn skip_vs_plain<R: Real>(case: &Case, n: usize, size: usize) -> (f64, f64) {
    let vol = phantom(n);
    let cam = camera(&vol, case.cam, size);
    let tf = sparse_tf();
    let plain = render::<R>(&vol, &tf, &cam, &settings(case, false), none()).unwrap();
    let skip = render::<R>(&vol, &tf, &cam, &settings(case, true), none()).unwrap();
    let diff = plain
        .image
        .data
        .iter()
        .zip(&skip.image.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    let visible = plain.image.data.chunks(4).filter(|p| p[0] > 0.01).count();
    assert!(
        visible > 20,
        "{case:?}: the image must show something ({visible} pixels)"
    );
    let kept = skip.total_samples as f64 / plain.total_samples as f64;
    (diff, kept)
}

/// Skipping keeps every sample position and drops only transparent samples, so the
/// image is bit-identical (measured: 0 in every case, f64 and f32) while a fraction of
/// the samples is taken (measured 0.54–0.75 with 5³ and 8³ blocks on this 64×67×62
/// phantom, 1.0 with 32³ blocks: 2×3×2 cells, all touching the skull).
macro_rules! identical_cases {
    ($($name:ident: $case:expr;)*) => {
        $(
            #[test]
            fn $name() {
                let case = $case;
                let (d64, k64) = skip_vs_plain::<f64>(&case, 64, 40);
                let (d32, k32) = skip_vs_plain::<f32>(&case, 64, 40);
                eprintln!("{}: max |Δ| f64 {d64:e}, f32 {d32:e}; samples kept {k64:.3} / {k32:.3}", stringify!($name));
                assert_eq!(d64, 0.0, "f64 images differ");
                assert_eq!(d32, 0.0, "f32 images differ");
                let most = if case.block >= 32 { 1.0 } else { 0.8 };
                assert!(k64 <= most && k32 <= most, "skipping must save samples");
            }
        )*
    };
}

identical_cases! {
    skip_identical_trilinear_perspective: BASE;
    skip_identical_trilinear_ortho: Case { cam: Cam::Ortho, ..BASE };
    skip_identical_nearest_axis: Case { filter: Filter::Nearest, cam: Cam::Axis, ..BASE };
    skip_identical_catmull_rom_ortho: Case { filter: Filter::CatmullRom, cam: Cam::Ortho, ..BASE };
    skip_identical_lanczos3_perspective: Case { filter: Filter::Lanczos3, ..BASE };
    skip_identical_bspline_interp_perspective: Case { filter: Filter::BsplineInterp, ..BASE };
    skip_identical_preclassified: Case { classification: Classification::Pre, ..BASE };
    skip_identical_preclassified_catmull_rom: Case { classification: Classification::Pre, filter: Filter::CatmullRom, cam: Cam::Ortho, ..BASE };
    skip_identical_back_to_front: Case { compositing: Compositing::BackToFront, ..BASE };
    skip_identical_back_to_front_ortho: Case { compositing: Compositing::BackToFront, cam: Cam::Ortho, ..BASE };
    skip_identical_block_32: Case { block: 32, ..BASE };
    skip_identical_block_5_bspline: Case { block: 5, filter: Filter::Bspline, ..BASE };
}

/// Skipping is off where it does not apply: MIP images and sample counts are unchanged.
#[test]
fn skipping_leaves_mip_alone() {
    let vol = phantom(24);
    let cam = camera(&vol, Cam::Perspective, 24);
    let tf = sparse_tf();
    let s = |skip| RenderSettings {
        mode: Mode::Mip,
        skip_empty: skip,
        ..RenderSettings::default()
    };
    let a = render::<f64>(&vol, &tf, &cam, &s(false), none()).unwrap();
    let b = render::<f64>(&vol, &tf, &cam, &s(true), none()).unwrap();
    assert_eq!(a.image.data, b.image.data);
    assert_eq!(a.total_samples, b.total_samples);
}

/// The grid is conservative: every point whose reconstructed sample has non-zero
/// opacity lies in a non-empty cell. Checked at every voxel centre and at 20 000
/// random points per filter, with a TF whose opacity is zero below 0.33.
#[test]
fn the_grid_is_conservative() {
    let vol = phantom(36);
    let tf = sparse_tf();
    let values = match &vol {
        AnyVolume::F32(v) => Grid::<f64>::from_volume(v),
        _ => unreachable!(),
    };
    let dims = values.dims;
    let mut rng = common::Rng(0x1234_5678);
    let mut unit = || rng.unit();
    for filter in [
        Filter::Nearest,
        Filter::Trilinear,
        Filter::Bspline,
        Filter::BsplineInterp,
        Filter::CatmullRom,
        Filter::Lanczos2,
        Filter::Lanczos4,
    ] {
        for block in [4, 7, 16] {
            let s = RenderSettings {
                filter,
                block_size: block,
                ..RenderSettings::default()
            };
            let lut = tf.lut(s.lut_size).to_real::<f64>();
            let grid = voxlab::cpu::filter::prepare(&values, filter);
            let skip = Skipper::new(&grid, &lut, &s).unwrap();
            assert_eq!(skip.grid.cells, cell_count(dims, block));
            let cell_of = |p: V3<f64>| {
                let c = |x: f64, n: usize| {
                    (((x + 0.5) / block as f64).floor().max(0.0) as i32).min(n as i32 - 1)
                };
                [
                    c(p.x(), skip.grid.cells[0]),
                    c(p.y(), skip.grid.cells[1]),
                    c(p.z(), skip.grid.cells[2]),
                ]
            };
            let (mut visible, mut empty_cells) = (0, 0);
            let mut check = |p: V3<f64>| {
                let a = lut.classify(sample(&grid, filter, p))[3];
                if a > 0.0 {
                    visible += 1;
                    assert!(
                        !skip.cell_empty(cell_of(p)),
                        "{filter:?} block {block}: opacity {a} at {p:?} in an empty cell"
                    );
                }
            };
            for k in 0..dims[2] {
                for j in 0..dims[1] {
                    for i in 0..dims[0] {
                        check(V3::new(i as f64, j as f64, k as f64));
                    }
                }
            }
            for _ in 0..20_000 {
                let r = |n: usize, u: f64| u * n as f64 - 0.5;
                check(V3::new(
                    r(dims[0], unit()),
                    r(dims[1], unit()),
                    r(dims[2], unit()),
                ));
            }
            let n = skip.grid.cells.iter().product::<usize>();
            for i in 0..n {
                let [lo, hi] = skip.grid.minmax[i];
                empty_cells += skip.tf.range_empty(lo, hi) as usize;
            }
            eprintln!("{filter:?} block {block}: {visible} visible points, {empty_cells} of {n} cells empty");
            assert!(visible > 100);
            assert!(empty_cells > 0, "some cells must be empty");
        }
    }
}

/// A cube volume of ones inside a box of zeros-and-ones: the clip box as zeroed voxels.
fn ramp_volume(n: usize) -> Volume<f32> {
    let mut v = Volume::from_fn([n, n, n], [1.0; 3], |i, j, k| {
        (0.3 + 0.7 * ((i * 7 + j * 3 + k * 5) % 11) as f64 / 10.0) as f32
    })
    .unwrap();
    let c = (n as f64 - 1.0) / 2.0;
    v.set_affine(glam::DMat4::from_translation(DVec3::splat(-c)))
        .unwrap();
    v
}

/// Clipping to a voxel box equals zeroing the voxels outside it, with a TF transparent
/// at zero, except at the box's faces: there the zeroed volume's filter blends in the
/// zeros over one voxel, and the clipped ray starts exactly on the face. X-ray with the
/// nearest filter has neither effect when the box faces lie on voxel faces and on the
/// step grid: the two agree (measured 0, X-ray and unshaded DVR). Trilinear DVR differs
/// only in pixels whose rays cross the box (see below).
#[test]
fn clip_box_matches_zeroed_voxels() {
    let n = 20;
    let vol = ramp_volume(n);
    let (lo, hi) = ([4usize, 6, 3], [13usize, 15, 16]);
    let mut zeroed = vol.clone();
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let inside = (0..3).all(|a| [i, j, k][a] >= lo[a] && [i, j, k][a] <= hi[a]);
                if !inside {
                    zeroed.data_mut()[i + n * (j + n * k)] = 0.0;
                }
            }
        }
    }
    let (vol, zeroed): (AnyVolume, AnyVolume) = (vol.into(), zeroed.into());
    let cam = Camera::axis_view(vol.dims(), vol.affine(), AxisView::MinusY, n, n).unwrap();
    let clip = ClipBox {
        lo: lo.map(|x| x as f64),
        hi: hi.map(|x| x as f64),
        space: ClipSpace::Voxel,
    };
    let tf = TransferFunction::preset("grayscale").unwrap();
    // X-ray, nearest: equal to rounding.
    let s = |clip_box| RenderSettings {
        mode: Mode::Xray,
        filter: Filter::Nearest,
        step: 0.25,
        clip_box,
        ..RenderSettings::default()
    };
    let a = render::<f64>(&vol, &tf, &cam, &s(Some(clip)), none()).unwrap();
    let b = render::<f64>(&zeroed, &tf, &cam, &s(None), none()).unwrap();
    let d = max_abs_error(&a.image.data, &b.image.data);
    eprintln!("x-ray clip vs zeroed: max |Δ| {d:e}");
    assert!(d < 1e-12, "{d}");
    // DVR, nearest, step ½ on the axis view: the clipped rays start on the box face,
    // which lies on the unclipped rays' step grid, so both sample the same points.
    // Unshaded: the gradient stencil reaches one voxel further than the filter and
    // sees the zeros too.
    let s = |clip_box, filter| {
        let mut s = RenderSettings {
            clip_box,
            filter,
            ..RenderSettings::default()
        };
        s.shading.enabled = false;
        s
    };
    let a = render::<f64>(&vol, &tf, &cam, &s(Some(clip), Filter::Nearest), none()).unwrap();
    let b = render::<f64>(&zeroed, &tf, &cam, &s(None, Filter::Nearest), none()).unwrap();
    let d = max_abs_error(&a.image.data, &b.image.data);
    eprintln!("dvr nearest clip vs zeroed: max |Δ| {d:e}");
    assert!(d < 1e-12, "{d}");
    // DVR, trilinear: the zeroed volume blends the zeros in over one voxel at every
    // face the ray crosses (here the faces y = lo − ½ and y = hi + ½ on every ray), the
    // clipped one does not. Measured max |Δ| 0.27 (RGBA in [0, 1]); the pixels outside
    // the box's silhouette (rays that never enter the box) agree exactly.
    let a = render::<f64>(&vol, &tf, &cam, &s(Some(clip), Filter::Trilinear), none()).unwrap();
    let b = render::<f64>(&zeroed, &tf, &cam, &s(None, Filter::Trilinear), none()).unwrap();
    let (mut outside, mut inside) = (0.0f64, 0.0f64);
    for row in 0..n {
        for col in 0..n {
            // Axis view −y: columns along x, rows along z (top = high z).
            let (x, z) = (col, n - 1 - row);
            let dd = max_abs_error(
                &a.image.data[(row * n + col) * 4..][..4],
                &b.image.data[(row * n + col) * 4..][..4],
            );
            let far = x + 1 < lo[0] || x > hi[0] + 1 || z + 1 < lo[2] || z > hi[2] + 1;
            if far {
                outside = outside.max(dd);
            } else {
                inside = inside.max(dd);
            }
        }
    }
    eprintln!("dvr trilinear clip vs zeroed: outside {outside:e}, through the box {inside:e}");
    assert!(outside < 1e-12, "{outside}");
    assert!(inside < 0.5, "{inside}");
}

/// X-ray of a constant volume through a world-space clip box: every ray that crosses
/// the box integrates `value × chord length`, with the chord computed analytically
/// (box ∩ volume, orthographic oblique view). Measured max relative error 2e-15 (f64):
/// the constant field makes the midpoint rule exact.
#[test]
fn clip_box_in_world_space_is_an_exact_chord() {
    let n = 16;
    let mut v = Volume::from_fn([n, n, n], [2.0; 3], |_, _, _| 0.5f32).unwrap();
    let c = DVec3::splat(-(n as f64 - 1.0) / 2.0);
    v.set_affine(glam::DMat4::from_scale(DVec3::splat(2.0)) * glam::DMat4::from_translation(c))
        .unwrap();
    let vol: AnyVolume = v.into();
    let cam = Camera::orbit(
        DVec3::ZERO,
        [32.0; 3],
        Orbit {
            azimuth_deg: 27.0,
            elevation_deg: 18.0,
            distance_mm: Some(100.0),
        },
        Projection::Orthographic {
            width_mm: 40.0,
            height_mm: 40.0,
        },
        24,
        24,
    )
    .unwrap();
    let (lo, hi) = (DVec3::new(-7.0, -3.0, -9.0), DVec3::new(5.0, 20.0, 4.5));
    let s = RenderSettings {
        mode: Mode::Xray,
        filter: Filter::Nearest,
        clip_box: Some(ClipBox {
            lo: lo.to_array(),
            hi: hi.to_array(),
            space: ClipSpace::World,
        }),
        ..RenderSettings::default()
    };
    let tf = TransferFunction::preset("grayscale").unwrap();
    let out = render::<f64>(&vol, &tf, &cam, &s, none()).unwrap();
    let half = n as f64; // volume box [−16, 16] mm
    let (vlo, vhi) = (DVec3::splat(-half), DVec3::splat(half));
    let mut worst = 0.0f64;
    let mut hits = 0;
    for row in 0..24 {
        for col in 0..24 {
            let r = cam.ray(col, row);
            let chord = voxlab::real::slab_interval(r.origin, r.dir, lo.max(vlo), hi.min(vhi))
                .map_or(0.0, |(t0, t1)| (t1 - t0).max(0.0));
            let got = out.image.data[row * 24 + col];
            let want = 0.5 * chord;
            if chord > 0.0 {
                hits += 1;
            }
            worst = worst.max((got - want).abs() / 8.0);
        }
    }
    eprintln!("world clip: {hits} rays through the box, max relative error {worst:e}");
    assert!(hits > 50);
    assert!(worst < 1e-12, "{worst}");
}

/// The wood-grain scene: unshaded DVR of the modified Shepp–Logan (32³) with the
/// `phantom` preset's thin opacity bands, a coarse step of 1.5 voxels, oblique
/// orthographic view.
fn grain_scene() -> (voxlab::jobs::render::Scene, RenderSettings) {
    let volume = phantom(32);
    let camera = camera(&volume, Cam::Ortho, 48);
    let mut s = RenderSettings {
        step: 1.5,
        ..RenderSettings::default()
    };
    s.shading.enabled = false;
    let scene = voxlab::jobs::render::Scene {
        volume,
        transfer: TransferFunction::preset("phantom").unwrap(),
        camera,
    };
    (scene, s)
}

fn rmse(a: &[f64], b: &[f64]) -> f64 {
    (a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>() / a.len() as f64).sqrt()
}

/// Accumulating jittered frames removes the wood grain: the RMSE against a step-0.05
/// reference falls as N grows. Measured (f64, RGBA in [0, 1]): unjittered 9.71e-2,
/// interleaved 9.42e-2, N = 1, 2, 4, 8, 16: 9.26e-2, 6.68e-2, 4.96e-2, 3.70e-2, 3.02e-2
/// (N = 16 is 0.33× N = 1 and 0.31× the unjittered error).
#[test]
fn accumulated_jitter_converges_to_the_fine_step_reference() {
    use voxlab::jobs::accumulate::render_accumulated;
    use voxlab::jobs::render::{Backend, Renderer};
    let (scene, s) = grain_scene();
    let cpu = Renderer::new(Backend::Cpu).unwrap();
    let fine = RenderSettings {
        step: 0.05,
        ..s.clone()
    };
    let reference = cpu.render(&scene, &fine, none()).unwrap().output.image.data;
    let plain = cpu.render(&scene, &s, none()).unwrap().output.image.data;
    let e_plain = rmse(&plain, &reference);
    let inter = RenderSettings {
        interleaved: true,
        ..s.clone()
    };
    let e_inter = rmse(
        &cpu.render(&scene, &inter, none())
            .unwrap()
            .output
            .image
            .data,
        &reference,
    );
    let mut errs = Vec::new();
    for n in [1, 2, 4, 8, 16] {
        let img = render_accumulated(&cpu, &scene, &s, 7, n, none())
            .unwrap()
            .output
            .image
            .data;
        errs.push(rmse(&img, &reference));
    }
    eprintln!(
        "rmse: unjittered {e_plain:.3e}, interleaved {e_inter:.3e}, N = 1, 2, 4, 8, 16: {errs:?}"
    );
    assert!(errs[4] < 0.5 * errs[0], "N = 16 must halve the N = 1 error");
    assert!(errs[4] < e_plain, "N = 16 must beat the unjittered image");
    assert!(
        e_inter < e_plain,
        "interleaved sampling must beat the unjittered image"
    );
    for w in errs.windows(2) {
        assert!(
            w[1] < w[0] * 1.05,
            "the error must not grow with N: {errs:?}"
        );
    }
}

/// The jitter offsets: 24-bit values in [0, 1), reproducible, different per pixel and
/// seed; the Bayer pattern covers 16 distinct offsets.
#[test]
fn jitter_offsets_are_uniform_and_reproducible() {
    use voxlab::cpu::jitter::{interleaved_offset, jitter_offset, pcg_hash};
    // Reference values of the PCG hash (Jarzynski & Olano 2020), computed with Python integers.
    assert_eq!(pcg_hash(0), 129_708_002);
    let mut sum = 0.0;
    let mut hist = [0usize; 10];
    for row in 0..100u32 {
        for col in 0..100u32 {
            let u = jitter_offset(3, col, row);
            assert!((0.0..1.0).contains(&u));
            assert_eq!(u, jitter_offset(3, col, row));
            sum += u;
            hist[(u * 10.0) as usize] += 1;
        }
    }
    let mean = sum / 10_000.0;
    assert!((mean - 0.5).abs() < 0.01, "{mean}");
    assert!(hist.iter().all(|&h| (900..1100).contains(&h)), "{hist:?}");
    assert_ne!(jitter_offset(3, 5, 5), jitter_offset(4, 5, 5));
    let mut seen: Vec<u64> = (0..16)
        .map(|i| (interleaved_offset(i % 4, i / 4) * 32.0) as u64)
        .collect();
    seen.sort();
    seen.dedup();
    assert_eq!(seen.len(), 16);
}

/// Real data: the bundled micro-CT scan (the benchmark's scene) renders identically with
/// skipping on (8³ cells) and off, f32 and f64. Measured: max |Δ| 0, 0.577 of the
/// samples taken at 48² pixels.
#[test]
fn skipping_leaves_the_micro_ct_unchanged() {
    let (vol, tf, cam) = voxlab::bench::raycast::microct_scene(48).unwrap();
    let s = |skip_empty| RenderSettings {
        skip_empty,
        block_size: 8,
        sample_count: true,
        ..RenderSettings::default()
    };
    let off = render::<f32>(&vol, &tf, &cam, &s(false), none()).unwrap();
    let on = render::<f32>(&vol, &tf, &cam, &s(true), none()).unwrap();
    assert_eq!(off.image.data, on.image.data);
    let off64 = render::<f64>(&vol, &tf, &cam, &s(false), none()).unwrap();
    let on64 = render::<f64>(&vol, &tf, &cam, &s(true), none()).unwrap();
    assert_eq!(off64.image.data, on64.image.data);
    assert!(
        off.image.data.chunks(4).any(|p| p[0] > 0.1),
        "the bone must show"
    );
    let kept = on.total_samples as f64 / off.total_samples as f64;
    eprintln!("micro-CT: samples kept {kept:.3}");
    assert!(kept < 0.9);
}

/// A volume prepared once (`raycast::Prepared`, what frame accumulation and
/// `render --repeat` use) renders every frame exactly as a one-off render does, while
/// the camera, transfer function, block size, mode, classification and jitter change
/// from frame to frame and the min/max grids are reused; a frame with another filter is
/// refused, not rendered wrongly.
#[test]
fn prepared_volume_frames_equal_one_off_renders() {
    use voxlab::cpu::raycast::Prepared;
    let vol = phantom(29);
    let dense = TransferFunction::preset("phantom").unwrap();
    let sparse = sparse_tf();
    let mut base = RenderSettings {
        step: 0.7,
        ..Default::default()
    };
    base.shading.enabled = false; // the ray-packet kernel's case
    let prepared32 = Prepared::<f32>::new(&vol, &base).unwrap();
    let prepared64 = Prepared::<f64>::new(&vol, &base).unwrap();
    type Frame<'a> = (Cam, &'a TransferFunction, RenderSettings);
    let frames: Vec<Frame> = vec![
        (Cam::Perspective, &sparse, base.clone()),
        (Cam::Axis, &dense, base.clone()),
        (
            Cam::Ortho,
            &sparse,
            RenderSettings {
                block_size: 4,
                ..base.clone()
            },
        ),
        (
            Cam::Perspective,
            &dense,
            RenderSettings {
                jitter: Some(7),
                ..base.clone()
            },
        ),
        (
            Cam::Ortho,
            &dense,
            RenderSettings {
                mode: Mode::Mip,
                ..base.clone()
            },
        ),
        (
            Cam::Axis,
            &sparse,
            RenderSettings {
                classification: Classification::Pre,
                block_size: 4,
                ..base.clone()
            },
        ),
        (
            Cam::Perspective,
            &sparse,
            RenderSettings {
                block_size: 4,
                ..base.clone()
            },
        ),
        (Cam::Axis, &dense, RenderSettings::default()),
    ];
    fn same<R: voxlab::real::Real>(p: &Prepared<R>, v: &AnyVolume, f: &Frame, i: usize) {
        let (cam, tf, s) = f;
        let camera = camera(v, *cam, 40);
        let a = p.render(tf, &camera, s, none()).unwrap();
        let b = render::<R>(v, tf, &camera, s, none()).unwrap();
        assert!(
            a.image
                .data
                .iter()
                .zip(&b.image.data)
                .all(|(x, y)| x.to_bits() == y.to_bits()),
            "frame {i} ({}) differs from the one-off render",
            R::NAME
        );
        assert_eq!(a.total_samples, b.total_samples, "frame {i} ({})", R::NAME);
    }
    for (i, f) in frames.iter().enumerate() {
        same(&prepared32, &vol, f, i);
        same(&prepared64, &vol, f, i);
    }
    let other = RenderSettings {
        filter: Filter::CatmullRom,
        ..base.clone()
    };
    let e = prepared32
        .render(&dense, &camera(&vol, Cam::Axis, 16), &other, none())
        .unwrap_err();
    assert!(e.to_string().contains("prepared for"), "{e}");
}
