//! The CPU ray caster's fast kernels (DVR steps classified in batches, rays marched in
//! packets; MIP, MinIP and X-ray values taken in batches) against the general
//! per-sample loop: the same image and the same sample counts, to the last bit, in f32
//! and f64, over views, filters, skipping, clipping, jitter, shading, early
//! termination, windows and value ranges, whole and in bricks.

mod common;

use voxlab::camera::{AxisView, Camera, Projection};
use voxlab::cpu::raycast::{render_with, Kernel, RenderOutput};
use voxlab::phantom::Phantom;
use voxlab::real::Real;
use voxlab::settings::{ClipBox, ClipSpace, Filter, RenderSettings};
use voxlab::transfer::TransferFunction;
use voxlab::AnyVolume;

fn none() -> &'static (dyn Fn(usize, usize) + Sync) {
    &|_, _| {}
}

#[derive(Clone, Copy, Debug)]
enum Cam {
    Perspective,
    Ortho,
    AxisZ,
    AxisMinusX,
}

/// One case: a camera, a filter and what is switched on.
#[derive(Clone, Copy, Debug)]
struct Case {
    name: &'static str,
    cam: Cam,
    filter: Filter,
    skip: bool,
    block: usize,
    clip: bool,
    jitter: Option<u32>,
    shade: bool,
    ert: f64,
    step: f64,
    tf: &'static str,
}

const BASE: Case = Case {
    name: "perspective, trilinear, skipping",
    cam: Cam::Perspective,
    filter: Filter::Trilinear,
    skip: true,
    block: 8,
    clip: false,
    jitter: None,
    shade: false,
    ert: 0.99,
    step: 0.5,
    tf: "phantom",
};

const CASES: &[Case] = &[
    BASE,
    Case {
        name: "axis view +z, no skipping",
        cam: Cam::AxisZ,
        skip: false,
        ..BASE
    },
    Case {
        name: "axis view −x, block 32",
        cam: Cam::AxisMinusX,
        block: 32,
        ..BASE
    },
    Case {
        name: "orthographic, clip box, jitter",
        cam: Cam::Ortho,
        clip: true,
        jitter: Some(7),
        ..BASE
    },
    Case {
        name: "perspective, shaded",
        shade: true,
        ..BASE
    },
    Case {
        name: "orthographic, early termination at 0.5",
        cam: Cam::Ortho,
        ert: 0.5,
        tf: "grayscale",
        ..BASE
    },
    Case {
        name: "perspective, step 0.37 (general opacity exponent)",
        step: 0.37,
        ..BASE
    },
    Case {
        name: "perspective, step 1 (exponent 1)",
        step: 1.0,
        ..BASE
    },
    Case {
        name: "perspective, nearest",
        filter: Filter::Nearest,
        ..BASE
    },
    Case {
        name: "orthographic, B-spline interpolation",
        cam: Cam::Ortho,
        filter: Filter::BsplineInterp,
        ..BASE
    },
];

fn volume(n: usize) -> AnyVolume {
    Phantom::shepp_logan_modified()
        .sample([n, n + 5, n - 3])
        .unwrap()
        .into()
}

fn camera(vol: &AnyVolume, cam: Cam) -> Camera {
    let orbit = |projection| common::orbit_camera(projection, 61, 47);
    let d = vol.dims();
    match cam {
        Cam::Perspective => orbit(Projection::Perspective { fov_y_deg: 30.0 }),
        Cam::Ortho => orbit(Projection::Orthographic {
            width_mm: 270.0,
            height_mm: 270.0 * 47.0 / 61.0,
        }),
        Cam::AxisZ => Camera::axis_view(d, vol.affine(), AxisView::PlusZ, 67, 53).unwrap(),
        Cam::AxisMinusX => Camera::axis_view(d, vol.affine(), AxisView::MinusX, 45, 45).unwrap(),
    }
}

fn settings(c: &Case, dims: [usize; 3]) -> RenderSettings {
    let mut s = RenderSettings {
        filter: c.filter,
        skip_empty: c.skip,
        block_size: c.block,
        jitter: c.jitter,
        ert_threshold: c.ert,
        step: c.step,
        sample_count: true,
        clip_box: c.clip.then(|| ClipBox {
            lo: [3.0, -1.0, 2.0],
            hi: [
                dims[0] as f64 * 0.6,
                dims[1] as f64 - 4.0,
                dims[2] as f64 * 0.8,
            ],
            space: ClipSpace::Voxel,
        }),
        ..RenderSettings::default()
    };
    s.shading.enabled = c.shade;
    s
}

/// Same image bits and same per-ray sample counts.
fn assert_same(fast: &RenderOutput, slow: &RenderOutput, what: &str) {
    assert_eq!(fast.image.data.len(), slow.image.data.len());
    let differing = (fast.image.data.iter())
        .zip(&slow.image.data)
        .filter(|(a, b)| a.to_bits() != b.to_bits())
        .count();
    assert_eq!(differing, 0, "{what}: {differing} values differ");
    assert_eq!(
        fast.total_samples, slow.total_samples,
        "{what}: sample totals"
    );
    if let (Some(f), Some(s)) = (&fast.samples, &slow.samples) {
        assert!(f.data == s.data, "{what}: per-ray sample counts differ");
    }
}

fn check<R: Real>(vol: &AnyVolume, c: &Case) {
    let tf = TransferFunction::preset(c.tf).unwrap();
    let cam = camera(vol, c.cam);
    let s = settings(c, vol.dims());
    let fast = render_with::<R>(vol, &tf, &cam, &s, none(), Kernel::Batched).unwrap();
    let slow = render_with::<R>(vol, &tf, &cam, &s, none(), Kernel::PerSample).unwrap();
    assert!(slow.total_samples > 1000, "{}: too few samples", c.name);
    assert_same(&fast, &slow, &format!("{} ({})", c.name, R::NAME));
    // Something was drawn: the image is not the background everywhere.
    assert!(
        slow.image.data.chunks(4).any(|p| p[3] > 0.05),
        "{}: empty image",
        c.name
    );
}

#[test]
fn fast_kernels_equal_the_per_sample_loop_in_f32() {
    let vol = volume(40);
    for c in CASES {
        check::<f32>(&vol, c);
    }
}

#[test]
fn fast_kernels_equal_the_per_sample_loop_in_f64() {
    let vol = volume(40);
    for c in CASES {
        check::<f64>(&vol, c);
    }
}

/// A u16 volume with a window mapping raw values onto the table, and a grid two
/// voxels wide (the vector path's narrowest).
#[test]
fn fast_kernels_equal_the_per_sample_loop_on_integer_and_thin_volumes() {
    let ph = Phantom::shepp_logan_modified();
    let f = ph.sample([48, 40, 36]).unwrap();
    let u16vol = voxlab::Volume::<u16>::new(
        f.dims(),
        [1.0; 3],
        f.data()
            .iter()
            .map(|v| (v * 4000.0).round() as u16)
            .collect(),
    )
    .unwrap();
    let vol: AnyVolume = u16vol.into();
    let mut tf = TransferFunction::preset("phantom").unwrap();
    tf.window = voxlab::transfer::WindowMap::from_window_level(4000.0, 2000.0, tf.domain).unwrap();
    let cam = camera(&vol, Cam::Perspective);
    let s = settings(&BASE, vol.dims());
    let fast = render_with::<f32>(&vol, &tf, &cam, &s, none(), Kernel::Batched).unwrap();
    let slow = render_with::<f32>(&vol, &tf, &cam, &s, none(), Kernel::PerSample).unwrap();
    assert_same(&fast, &slow, "u16 with a window");
    assert!(slow.image.data.chunks(4).any(|p| p[3] > 0.05));

    let thin: AnyVolume = ph.sample([2, 30, 30]).unwrap().into();
    for cam in [Cam::AxisMinusX, Cam::AxisZ] {
        let cam = camera(&thin, cam);
        let tf = TransferFunction::preset("phantom").unwrap();
        let fast = render_with::<f32>(&thin, &tf, &cam, &s, none(), Kernel::Batched).unwrap();
        let slow = render_with::<f32>(&thin, &tf, &cam, &s, none(), Kernel::PerSample).unwrap();
        assert_same(&fast, &slow, "two voxels wide");
    }
}

/// Every brick of a k-d tree of `n` over `vol` (as `f32`), with the ghost voxels the
/// filter needs: a distributed render's fields (`BrickField`: its voxels sampled at
/// the whole grid's coordinates) and the voxel boxes they own.
fn bricks(
    vol: &AnyVolume,
    filter: Filter,
    gradient: voxlab::settings::GradientMethod,
    n: usize,
) -> Vec<(
    voxlab::cpu::field::BrickField<f32>,
    voxlab::io::brick::Brick,
)> {
    use voxlab::cpu::field::{brick_ghost, BrickField, GridField};
    use voxlab::cpu::grid::Grid;
    let whole = Grid::<f32>::from_any(vol);
    let d = vol.dims();
    let range = (whole.data.iter()).fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
        (lo.min(v as f64), hi.max(v as f64))
    });
    let (_, bricks) = voxlab::io::brick::kd_tree(d, n).unwrap();
    bricks
        .into_iter()
        .map(|b| {
            let g = brick_ghost(filter);
            let lo: [usize; 3] = std::array::from_fn(|a| b.lo[a].saturating_sub(g));
            let hi: [usize; 3] = std::array::from_fn(|a| (b.hi[a] + g).min(d[a]));
            let dims: [usize; 3] = std::array::from_fn(|a| hi[a] - lo[a]);
            let mut data = Vec::with_capacity(dims.iter().product());
            for z in lo[2]..hi[2] {
                for y in lo[1]..hi[1] {
                    let at = (z * d[1] + y) * d[0];
                    data.extend_from_slice(&whole.data[at + lo[0]..at + hi[0]]);
                }
            }
            let field = BrickField {
                inner: GridField::new(Grid { dims, data }, filter, gradient, false),
                origin: lo,
                whole: d,
                range,
            };
            (field, b)
        })
        .collect()
}

/// A brick's share rendered by both kernels: the same partial image and counts, bit
/// for bit. Returns the rays with samples compared.
fn check_brick(
    field: &voxlab::cpu::field::BrickField<f32>,
    b: &voxlab::io::brick::Brick,
    vol: &AnyVolume,
    tf: &TransferFunction,
    cam: &Camera,
    s: &RenderSettings,
    what: &str,
) -> usize {
    use voxlab::cpu::raycast::{render_owned_with, Owned};
    let d = vol.dims();
    let own = || Owned::new(b.lo, b.hi, d);
    let render =
        |k: Kernel| render_owned_with(field, vol.affine(), tf, cam, s, own(), none(), k).unwrap();
    let (fast, slow) = (render(Kernel::Batched), render(Kernel::PerSample));
    let what = format!("{what}, brick {:?}..{:?}", b.lo, b.hi);
    let differing = (fast.image.data.iter())
        .zip(&slow.image.data)
        .filter(|(a, b)| a.to_bits() != b.to_bits())
        .count();
    assert_eq!(differing, 0, "{what}: {differing} values differ");
    assert!(fast.counts == slow.counts, "{what}: sample counts differ");
    slow.counts.iter().filter(|&&k| k > 0).count()
}

/// A brick of a distributed render (`render_owned`: a `BrickField` that samples its
/// voxels and ghost voxels at the whole grid's coordinates, and only its own samples):
/// the packet kernel (unshaded) and the batches (shaded), sampling at the brick's
/// origin, against the per-sample loop, for every brick of three and of four, over the
/// case list's trilinear cases, in f32.
#[test]
fn fast_kernels_equal_the_per_sample_loop_on_bricks() {
    let vol = volume(40);
    let mut compared = 0;
    for c in CASES.iter().filter(|c| c.filter == Filter::Trilinear) {
        let tf = TransferFunction::preset(c.tf).unwrap();
        let cam = camera(&vol, c.cam);
        let s = settings(c, vol.dims());
        for n in [3, 4] {
            for (field, b) in bricks(&vol, s.filter, s.gradient, n) {
                let what = format!("{} of {n}", c.name);
                compared += check_brick(&field, &b, &vol, &tf, &cam, &s, &what);
            }
        }
    }
    assert!(compared > 10_000, "{compared} rays with samples compared");
}

/// MIP, MinIP and X-ray take their steps' values in batches (`march::values`): the
/// same image and sample counts as the per-sample loop, to the bit, in f32 and f64, on
/// every camera, with the filters, a clip box and jitter, a window, a clipping mesh,
/// on a volume of signed values with zeros of both signs, and on the bricks of a
/// distributed render.
#[test]
fn scalar_modes_take_batched_values_as_the_per_sample_loop_does() {
    use std::sync::Arc;
    use voxlab::settings::{ClipMesh, ClipMeshUnits, Mode};
    let vol = volume(40);
    // Signed values, zeros of both signs in a block (where trilinear sums of zeros
    // and products of zero weights meet).
    let signed: AnyVolume = {
        let v = match &vol {
            AnyVolume::F32(v) => v,
            _ => unreachable!("the phantom is f32"),
        };
        let d = v.dims();
        let data = (v.data().iter().enumerate())
            .map(|(i, &x)| {
                let (x_, y, z) = (i % d[0], i / d[0] % d[1], i / (d[0] * d[1]));
                if (10..20).contains(&x_) && (10..20).contains(&y) && (5..15).contains(&z) {
                    if (x_ + y + z) % 2 == 0 {
                        -0.0
                    } else {
                        0.0
                    }
                } else {
                    x - 0.3
                }
            })
            .collect();
        voxlab::Volume::with_affine(d, v.affine(), data)
            .unwrap()
            .into()
    };
    let tf = TransferFunction::preset("phantom").unwrap();
    let d = vol.dims();
    let base = |mode: Mode, filter: Filter| RenderSettings {
        mode,
        filter,
        sample_count: true,
        ..RenderSettings::default()
    };
    let mut rays = 0;
    for mode in [Mode::Mip, Mode::Minip, Mode::Xray] {
        let mut variants: Vec<(String, RenderSettings)> = Vec::new();
        for filter in [Filter::Trilinear, Filter::Nearest, Filter::BsplineInterp] {
            variants.push((format!("{filter:?}"), base(mode, filter)));
        }
        let tri = base(mode, Filter::Trilinear);
        variants.push((
            "clip box, jitter, step 0.37".into(),
            RenderSettings {
                clip_box: Some(ClipBox {
                    lo: [3.0, -1.0, 2.0],
                    hi: [d[0] as f64 * 0.6, d[1] as f64 - 4.0, d[2] as f64 * 0.8],
                    space: ClipSpace::Voxel,
                }),
                jitter: Some(7),
                step: 0.37,
                ..tri.clone()
            },
        ));
        variants.push((
            "window".into(),
            RenderSettings {
                window: Some([0.1, 0.6]),
                ..tri.clone()
            },
        ));
        let mut comb = voxlab::io::mesh::TriMesh::default();
        for (y0, y1) in [(2.0, 9.0), (14.0, 17.0), (25.0, 40.0)] {
            comb.append_cuboid([4.5, y0, 3.5], [30.5, y1, 33.5]);
        }
        variants.push((
            "clipping mesh".into(),
            RenderSettings {
                clip_mesh: Some(ClipMesh::Mesh {
                    mesh: Arc::new(comb),
                    units: ClipMeshUnits::Voxel,
                }),
                ..tri.clone()
            },
        ));
        for (name, s) in &variants {
            for (vname, v) in [("phantom", &vol), ("signed", &signed)] {
                for cam in [Cam::Perspective, Cam::Ortho, Cam::AxisZ, Cam::AxisMinusX] {
                    let cam = camera(v, cam);
                    let what = format!("{mode:?}, {name}, {vname}");
                    let fast = render_with::<f32>(v, &tf, &cam, s, none(), Kernel::Batched);
                    let slow = render_with::<f32>(v, &tf, &cam, s, none(), Kernel::PerSample);
                    assert_same(&fast.unwrap(), &slow.unwrap(), &format!("{what} (f32)"));
                    let fast = render_with::<f64>(v, &tf, &cam, s, none(), Kernel::Batched);
                    let slow =
                        render_with::<f64>(v, &tf, &cam, s, none(), Kernel::PerSample).unwrap();
                    assert_same(&fast.unwrap(), &slow, &format!("{what} (f64)"));
                    rays += slow
                        .samples
                        .as_ref()
                        .map_or(0, |f| f.data.iter().filter(|&&k| k > 0.0).count());
                }
            }
        }
        // The bricks of a distributed render (trilinear: the filters a brick takes).
        let cam = camera(&vol, Cam::Perspective);
        for n in [3, 4] {
            for (field, b) in bricks(&signed, Filter::Trilinear, tri.gradient, n) {
                let what = format!("{mode:?} of {n}");
                rays += check_brick(&field, &b, &signed, &tf, &cam, &tri, &what);
            }
        }
    }
    assert!(rays > 100_000, "{rays} rays with samples compared");
}
