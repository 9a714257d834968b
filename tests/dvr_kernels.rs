//! The CPU ray caster's fast DVR kernels (steps classified in batches, rays marched in
//! packets) against the general per-sample loop: the same image and the same sample
//! counts, to the last bit, in f32 and f64, over views, filters, skipping, clipping,
//! jitter, shading, early termination, windows and value ranges.

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
