//! Empty-space skipping, the clipping box and jittered sampling on the GPU: the grid
//! equals the CPU's, skipping leaves the GPU image unchanged, and every option matches
//! the CPU f64 oracle (same seed, same jitter) within the ray caster's f32 bound.

mod common;

use voxlab::camera::{AxisView, Camera, Projection};
use voxlab::cpu::grid::Grid;
use voxlab::gpu::skip::{SkipGridParams, MINMAX_WGSL};
use voxlab::metrics::Tolerance;
use voxlab::phantom::Phantom;
use voxlab::settings::{
    Classification, ClipBox, ClipSpace, Compositing, Filter, Mode, RenderSettings,
};
use voxlab::transfer::TransferFunction;
use voxlab::AnyVolume;

/// The ray caster's DVR bound (tests/gpu_raycast.rs: EXACT_DVR, f32 rounding of sample
/// positions through narrow opacity bands). Measured here on lavapipe: worst max |Δ|
/// 3.2e-4 (jittered back to front), RMSE 8.8e-6; the other cases 6e-7 … 6e-5.
const DVR: Tolerance = Tolerance {
    max_abs: 1e-3,
    rmse: 5e-5,
    ..Tolerance::NONE
};

fn none() -> &'static (dyn Fn(usize, usize) + Sync) {
    &|_, _| {}
}

use common::sparse_tf;

use common::odd_phantom as phantom;

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

#[test]
fn skip_grid_params_layout_agrees() {
    let (span, members) = common::wgsl_struct_layout(MINMAX_WGSL, "SkipGridParams");
    assert_eq!(span as usize, std::mem::size_of::<SkipGridParams>());
    let rust = [
        ("dims", std::mem::offset_of!(SkipGridParams, dims)),
        ("cells", std::mem::offset_of!(SkipGridParams, cells)),
        ("misc", std::mem::offset_of!(SkipGridParams, misc)),
    ];
    assert_eq!(members.len(), rust.len());
    for ((w, wo), (r, ro)) in members.iter().zip(&rust) {
        assert_eq!(w, r);
        assert_eq!(*wo as usize, *ro);
    }
}

/// The GPU grid equals the CPU's f32 grid exactly (min and max are exact).
#[test]
fn gpu_min_max_grid_equals_the_cpu_grid() {
    let Some(ctx) = common::gpu("gpu_min_max_grid_equals_the_cpu_grid") else {
        return;
    };
    let vol = Phantom::shepp_logan_modified()
        .sample([37, 29, 41])
        .unwrap();
    let grid = Grid::<f32>::from_volume(&vol);
    for (block, radius) in [(8, 1), (5, 2), (32, 4), (64, 1), (1, 1)] {
        let cpu = voxlab::cpu::skip::min_max_grid(&grid, block, radius);
        let gpu = voxlab::gpu::skip::min_max_grid(ctx, &grid, block, radius).unwrap();
        assert_eq!(cpu, gpu, "block {block}, radius {radius}");
    }
}

#[derive(Clone, Copy, Debug)]
struct Case {
    filter: Filter,
    cam: Cam,
    classification: Classification,
    compositing: Compositing,
    block: usize,
    jitter: Option<u32>,
    interleaved: bool,
    clip: Option<ClipBox>,
    mode: Mode,
}

const BASE: Case = Case {
    filter: Filter::Trilinear,
    cam: Cam::Perspective,
    classification: Classification::Post,
    compositing: Compositing::FrontToBack,
    block: 8,
    jitter: None,
    interleaved: false,
    clip: None,
    mode: Mode::Dvr,
};

const VOXEL_BOX: ClipBox = ClipBox {
    lo: [5.0, 3.0, 8.0],
    hi: [24.0, 30.0, 25.5],
    space: ClipSpace::Voxel,
};

const WORLD_BOX: ClipBox = ClipBox {
    lo: [-90.0, -200.0, -40.0],
    hi: [60.0, 50.0, 200.0],
    space: ClipSpace::World,
};

fn settings(case: &Case, skip: bool) -> RenderSettings {
    RenderSettings {
        mode: case.mode,
        filter: case.filter,
        classification: case.classification,
        compositing: case.compositing,
        block_size: case.block,
        skip_empty: skip,
        jitter: case.jitter,
        interleaved: case.interleaved,
        clip_box: case.clip,
        sample_count: true,
        ..RenderSettings::default()
    }
}

/// GPU with skipping against GPU without (identical) and against the CPU f64 oracle
/// with the same settings (the DVR bound); the sample counts of the CPU and the GPU
/// agree.
fn check(name: &str, case: Case) {
    let Some(ctx) = common::gpu(name) else {
        return;
    };
    let vol = phantom(36);
    let cam = camera(&vol, case.cam, 32);
    let tf = sparse_tf();
    let gpu = |skip| {
        voxlab::gpu::raycast::render(ctx, &vol, &tf, &cam, &settings(&case, skip), none())
            .unwrap()
            .output
    };
    let (on, off) = (gpu(true), gpu(false));
    let cpu = voxlab::cpu::raycast::render::<f64>(&vol, &tf, &cam, &settings(&case, true), none())
        .unwrap();
    let same = voxlab::metrics::error_stats(&off.image.data, &on.image.data, f64::INFINITY)
        .infinite_if_mismatched()
        .max_abs;
    let stats = common::assert_parity(name, &cpu.image, &on.image, DVR);
    let counts_differ = cpu
        .samples
        .unwrap()
        .data
        .iter()
        .zip(&on.samples.unwrap().data)
        .filter(|(a, b)| a != b)
        .count();
    eprintln!(
        "{name}: gpu skip on vs off max |Δ| {same:e}; vs oracle max |Δ| {:.2e}, rmse {:.2e}; \
         samples kept {:.3}; {counts_differ} sample counts differ from the CPU's",
        stats.max_abs,
        stats.rmse,
        on.total_samples as f64 / off.total_samples as f64
    );
    assert_eq!(same, 0.0, "skipping changed the GPU image");
    assert!(
        counts_differ * 100 <= cam.width * cam.height,
        "{counts_differ}"
    );
}

macro_rules! gpu_cases {
    ($($name:ident: $case:expr;)*) => {
        $(
            #[test]
            fn $name() {
                check(stringify!($name), $case);
            }
        )*
    };
}

gpu_cases! {
    gpu_skip_trilinear_perspective: BASE;
    gpu_skip_trilinear_ortho: Case { cam: Cam::Ortho, ..BASE };
    gpu_skip_nearest_axis: Case { filter: Filter::Nearest, cam: Cam::Axis, ..BASE };
    gpu_skip_catmull_rom_ortho: Case { filter: Filter::CatmullRom, cam: Cam::Ortho, ..BASE };
    gpu_skip_lanczos3_perspective: Case { filter: Filter::Lanczos3, ..BASE };
    gpu_skip_bspline_interp_perspective: Case { filter: Filter::BsplineInterp, ..BASE };
    gpu_skip_preclassified: Case { classification: Classification::Pre, ..BASE };
    gpu_skip_back_to_front: Case { compositing: Compositing::BackToFront, ..BASE };
    gpu_skip_block_5: Case { block: 5, cam: Cam::Ortho, ..BASE };
    gpu_jitter_seed_7: Case { jitter: Some(7), ..BASE };
    gpu_jitter_back_to_front: Case { jitter: Some(123), compositing: Compositing::BackToFront, cam: Cam::Ortho, ..BASE };
    gpu_interleaved: Case { interleaved: true, ..BASE };
    gpu_clip_voxel: Case { clip: Some(VOXEL_BOX), ..BASE };
    gpu_clip_world_jitter: Case { clip: Some(WORLD_BOX), jitter: Some(3), cam: Cam::Ortho, ..BASE };
    gpu_clip_mip: Case { clip: Some(VOXEL_BOX), mode: Mode::Mip, ..BASE };
}

/// Accumulated jittered frames on the GPU match the CPU's (same seeds).
#[test]
fn gpu_accumulation_matches_the_cpu() {
    use voxlab::jobs::accumulate::render_accumulated;
    use voxlab::jobs::render::{Backend, Renderer, Scene};
    let Some(_) = common::gpu("gpu_accumulation_matches_the_cpu") else {
        return;
    };
    let volume = phantom(32);
    let camera = camera(&volume, Cam::Ortho, 32);
    let scene = Scene {
        volume,
        transfer: TransferFunction::preset("phantom").unwrap(),
        camera,
    };
    let s = RenderSettings {
        step: 1.5,
        ..RenderSettings::default()
    };
    let gpu = Renderer::new(Backend::Gpu).unwrap();
    let cpu = Renderer::new(Backend::Cpu).unwrap();
    let g = render_accumulated(&gpu, &scene, &s, 11, 4, none()).unwrap();
    let c = render_accumulated(&cpu, &scene, &s, 11, 4, none()).unwrap();
    let stats = common::assert_parity("gpu_accumulation", &c.output.image, &g.output.image, DVR);
    eprintln!(
        "accumulated 4 frames: max |Δ| {:.2e}, rmse {:.2e}",
        stats.max_abs, stats.rmse
    );
}
