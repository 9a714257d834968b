//! Benchmark cases of D²VR (family `d2vr`): direct rendering from filtered projections,
//! Xu & Mueller's sizes.
//!
//! The scene ([`d2vr_scene`]): the modified Shepp–Logan head, exact cone-beam
//! projections (`project_phantom`; SID 600 mm, SDD 900 mm, a full 360° orbit, a detector
//! covering 256 mm at the isocentre), Ram-Lak filtered with the FDK cosine weight
//! (`cpu::ramp`, FFT path, in f64), a centred virtual grid spanning ±128 mm, an
//! orthographic orbit view (azimuth 30°, elevation 20°) and a skull-and-tissue transfer
//! function, shaded DVR at a step of one voxel. The sizes ([`D2vrConfig`]): `table1` is
//! the paper's Table 1 (128 projections of 128², a 128³ virtual grid, a 256² image) and
//! `half` halves every side.
//!
//! The variants ([`d2vr_variants`]) follow the paper's columns: **GFS** (density only,
//! gradients by central differences of six more reconstructions), **GFR** (density and
//! gradient reconstructed from the projections), **+B** (samples outside the bounding
//! cylinder skipped), **+OC** (occlusion culling: early ray termination at 0.95; the
//! others run with it off), **+M** (the occupancy mask built from the raw projections:
//! samples in the shadow of no object skipped).
//!
//! The f64 oracle renders the f64 filtered projections; the f32 CPU path and the GPU
//! (f32 storage) render the same projections rounded to f32, so the comparison measures
//! the renderers alone. Work: rays (= pixels) and samples: the grid box's samples along
//! every ray (`box_samples`, the plain march without cylinder, mask or early
//! termination), so what the accelerations skip shows as throughput.

use super::{Case, GpuRun, Prepared, Run, Suite, Unit, Work};
use crate::camera::{Camera, Orbit, Projection};
use crate::cpu::d2vr::OccupancyMask;
use crate::cpu::d2vr::{box_samples, render_d2vr, D2vrGradient, D2vrGrid, D2vrOptions};
use crate::cpu::project::project_phantom;
use crate::cpu::ramp::{filter_projections, FilterMethod, RampFilter};
use crate::ct::{Geometry, Projections};
use crate::error::Result;
use crate::gpu::plan::Sampling;
use crate::metrics::Tolerance;
use crate::phantom::Phantom;
use crate::settings::{Mode, RenderSettings};
use crate::transfer::{ControlPoint, TransferFunction, WindowMap};
use glam::DVec3;
use std::rc::Rc;
use std::time::Instant;

/// The sizes of one D²VR configuration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct D2vrConfig {
    pub name: &'static str,
    /// Projections over 360°.
    pub views: usize,
    /// Detector side (pixels).
    pub detector: usize,
    /// Virtual grid side (voxels).
    pub grid: usize,
    /// Image side (pixels).
    pub image: usize,
}

/// The paper's Table 1: 128 × 128², 128³, 256².
pub const TABLE1: D2vrConfig = D2vrConfig {
    name: "table1",
    views: 128,
    detector: 128,
    grid: 128,
    image: 256,
};
/// Half of Table 1 on every side: 64 × 64², 64³, 128².
pub const HALF: D2vrConfig = D2vrConfig {
    name: "half",
    views: 64,
    detector: 64,
    grid: 64,
    image: 128,
};
/// The quick suite's: 16 × 16², 16³, 32².
pub const TINY: D2vrConfig = D2vrConfig {
    name: "tiny",
    views: 16,
    detector: 16,
    grid: 16,
    image: 32,
};

/// One variant: name, mode, gradient, bounding cylinder, ERT threshold, occupancy
/// mask, and how the GPU reads the projections.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct D2vrVariant {
    pub name: &'static str,
    pub mode: Mode,
    pub gradient: D2vrGradient,
    pub cylinder: bool,
    pub ert: f64,
    pub mask: bool,
    pub sampling: Sampling,
}

/// The paper's columns (shaded DVR) and the occupancy mask, every one exact.
pub fn d2vr_variants() -> Vec<D2vrVariant> {
    let v = |name, gradient, cylinder, ert, mask| D2vrVariant {
        name,
        mode: Mode::Dvr,
        gradient,
        cylinder,
        ert,
        mask,
        sampling: Sampling::Exact,
    };
    use D2vrGradient::{Gfr, Gfs};
    vec![
        v("GFS", Gfs, false, 1.0, false),
        v("GFR", Gfr, false, 1.0, false),
        v("GFS+B", Gfs, true, 1.0, false),
        v("GFS+B+OC", Gfs, true, 0.95, false),
        v("GFR+B+OC", Gfr, true, 0.95, false),
        v("GFR+B+OC+M", Gfr, true, 0.95, true),
    ]
}

/// The texture pair: the MIP of the field inside the bounding cylinder, read exactly
/// and through the texture unit ([`Sampling::Hardware`], the paper's own
/// reconstruction). MIP, because a MIP pixel moves by no more than one sample, which
/// [`crate::gpu::d2vr::hardware_error_bound`] bounds; a shaded DVR pixel passes the
/// error through the transfer function (`cargo bench --bench d2vr` measures it).
pub fn d2vr_texture_variants() -> Vec<D2vrVariant> {
    let v = |name, sampling| D2vrVariant {
        name,
        mode: Mode::Mip,
        gradient: D2vrGradient::Gfr,
        cylinder: true,
        ert: 1.0,
        mask: false,
        sampling,
    };
    vec![
        v("MIP+B", Sampling::Exact),
        v("MIP+B-hardware", Sampling::Hardware),
    ]
}

/// The head's transfer function: soft tissue faint, bone opaque.
pub fn d2vr_tf() -> TransferFunction {
    let p = |value: f64, rgba: [f64; 4]| ControlPoint { value, rgba };
    TransferFunction {
        name: "head".into(),
        domain: [0.0, 1.2],
        points: vec![
            p(0.15, [0.0, 0.0, 0.0, 0.0]),
            p(0.3, [0.8, 0.5, 0.4, 0.05]),
            p(0.5, [0.8, 0.5, 0.4, 0.05]),
            p(0.8, [1.0, 1.0, 0.9, 0.6]),
        ],
        window: WindowMap::default(),
        interpolation: Default::default(),
        faux_shading: None,
    }
}

/// Everything a D²VR render of one configuration needs.
pub struct D2vrScene {
    pub geometry: Geometry,
    /// Exact, unfiltered projections (for the occupancy mask).
    pub raw: Projections<f64>,
    /// Ram-Lak + FDK-weighted projections, f64.
    pub filtered: Projections<f64>,
    /// The same, rounded to f32.
    pub filtered_f32: Projections<f32>,
    pub grid: D2vrGrid,
    pub camera: Camera,
    pub tf: TransferFunction,
}

/// Builds the scene of a configuration (exact projections, filtered in f64).
pub fn d2vr_scene(c: &D2vrConfig) -> Result<D2vrScene> {
    let det = c.detector;
    // 256 mm field: the detector covers it at the isocentre (magnification 1.5).
    let geometry = Geometry::cone_rtk(
        600.0,
        900.0,
        det,
        det,
        384.0 / det as f64,
        384.0 / det as f64,
        Geometry::even_angles(c.views, 360.0),
    )?;
    let raw = project_phantom(&Phantom::shepp_logan_modified(), &geometry)?;
    let filtered = filter_projections(&raw, &geometry, RampFilter::RamLak, FilterMethod::Fft)?;
    let filtered_f32 = Projections::new(
        filtered.angles,
        filtered.rows,
        filtered.cols,
        filtered.data.iter().map(|&v| v as f32).collect(),
    )?;
    let grid = D2vrGrid::centred([c.grid; 3], 256.0 / c.grid as f64)?;
    let camera = Camera::orbit(
        DVec3::ZERO,
        [256.0; 3],
        Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            distance_mm: None,
        },
        Projection::Orthographic {
            width_mm: 0.0,
            height_mm: 0.0,
        },
        c.image,
        c.image,
    )?;
    Ok(D2vrScene {
        geometry,
        raw,
        filtered,
        filtered_f32,
        grid,
        camera,
        tf: d2vr_tf(),
    })
}

/// The render settings and D²VR options of a variant.
pub fn d2vr_settings(v: &D2vrVariant) -> (RenderSettings, D2vrOptions) {
    (
        RenderSettings {
            mode: v.mode,
            step: 1.0,
            ert_threshold: v.ert,
            ..RenderSettings::default()
        },
        D2vrOptions {
            gradient: v.gradient,
            cylinder: v.cylinder,
            value_range: (0.0, 1.0),
        },
    )
}

/// The occupancy mask of a scene (voxels whose every projection's footprint is zero
/// in the raw projections are empty).
pub fn d2vr_mask(scene: &D2vrScene) -> Result<OccupancyMask> {
    OccupancyMask::from_projections(&scene.raw, &scene.geometry, &scene.grid, 1e-9)
}

/// f32 (CPU or GPU) against the f64 oracle, GFS. `tests/gpu_d2vr.rs` holds the GPU to
/// 1e-4 at 32²; at the benchmark sizes a ray whose opacity crosses the ERT threshold
/// within rounding stops one sample earlier or later. Measured on lavapipe (f32 CPU /
/// GPU): max 9.8e-5 / 2.2e-4 (half, every GFS variant), 8.6e-4 / 2.2e-3 (table1
/// GFS+B+OC), 1.2e-6 / 1.9e-6 (quick); rel L2 ≤ 2.2e-5. Bound: about 4× the worst.
const GFS_F32: Tolerance = Tolerance::max_abs_rel(1e-2).with_rel_l2(1e-4);
/// GFR: its gradient jumps at every detector-cell edge (the bilinear interpolant's
/// derivative is piecewise constant), so where f32 puts a sample across an edge the
/// shading of that pixel changes by up to a few per cent (isolated pixels: 3 of 16384 at
/// half, 17–23 of 65536 at table1 beyond 1e-3). Measured on lavapipe (f32 CPU / GPU): max
/// 5.8e-3 / 1.2e-2 (half), 1.4e-2 / 9.2e-3 (table1 GFR+B+OC), 1.0e-6 / 1.1e-6 (quick);
/// rel L2 ≤ 1.3e-4. Bound: about 4× the worst.
const GFR_F32: Tolerance = Tolerance::max_abs_rel(5e-2).with_rel_l2(5e-4);
/// MIP (the texture pair's exact half): a pixel is one sample, so f32 moves it by the
/// rounding of one reconstruction. Measured on lavapipe (f32 CPU / GPU): max 2.2e-6 /
/// 3.4e-6 (quick), 1.4e-5 / 1.8e-5 (half), 1.8e-5 / 2.4e-5 (table1); rel L2 ≤ 4.1e-6.
/// Bound: about 4× the worst.
const MIP_F32: Tolerance = Tolerance::max_abs_rel(1e-4).with_rel_l2(2e-5);

/// Every D²VR case of a suite.
pub fn cases(suite: Suite) -> Vec<Case> {
    let all = [d2vr_variants(), d2vr_texture_variants()].concat();
    let pick = |names: &[&str]| -> Vec<D2vrVariant> {
        all.iter()
            .filter(|v| names.contains(&v.name))
            .copied()
            .collect()
    };
    // On 16 cores the f32 CPU takes about a tenth of the 2-core timings in
    // docs/bench/d2vr-lavapipe.md: half ≈ 0.1–0.35 s per variant, table1 +B+OC ≈ 0.6–0.8 s;
    // table1 without the cylinder and ERT (4–10 s per run) is left out.
    let plan: Vec<(D2vrConfig, Vec<D2vrVariant>)> = match suite {
        Suite::Quick => vec![(
            TINY,
            pick(&["GFS", "GFR+B+OC+M", "MIP+B", "MIP+B-hardware"]),
        )],
        Suite::Full => vec![
            (HALF, all.clone()),
            (
                TABLE1,
                pick(&[
                    "GFS+B+OC",
                    "GFR+B+OC",
                    "GFR+B+OC+M",
                    "MIP+B",
                    "MIP+B-hardware",
                ]),
            ),
        ],
    };
    let mut out = Vec::new();
    for (config, variants) in plan {
        for v in variants {
            out.push(Case::new(
                "d2vr",
                format!("{}-{}", config.name, v.name.to_lowercase()),
                format!(
                    "{} × {}² → {}³ → {}²",
                    config.views, config.detector, config.grid, config.image
                ),
                move || prepare(&config, &v),
            ));
        }
    }
    out
}

/// The tolerance of a variant's f32 paths (CPU and the exact GPU alike).
pub fn d2vr_tolerance(v: &D2vrVariant) -> Tolerance {
    match (v.mode, v.gradient) {
        (Mode::Mip, _) => MIP_F32,
        (_, D2vrGradient::Gfs) => GFS_F32,
        (_, D2vrGradient::Gfr) => GFR_F32,
    }
}

/// The hardware MIP's tolerance: [`crate::gpu::d2vr::hardware_error_bound`] for
/// weights of 8 fractional bits (NVIDIA's) on the f32 projections the GPU holds, plus
/// the exact path's [`MIP_F32`] taken against a peak of 2 (the modified Shepp–Logan's
/// densities are at most 1, and its FDK overshoots them by a few per cent), as one
/// bound on max |Δ|.
fn hardware_mip_tol(scene: &D2vrScene) -> Tolerance {
    let bound = crate::gpu::d2vr::hardware_error_bound(
        &scene.filtered_f32,
        &scene.geometry,
        &scene.grid,
        crate::gpu::d2vr::ProjStorage::F32,
        8,
    );
    Tolerance::max_abs(bound + 2.0 * MIP_F32.max_abs_rel)
}

fn prepare(config: &D2vrConfig, v: &D2vrVariant) -> Result<Prepared> {
    let scene = d2vr_scene(config)?;
    let mask = if v.mask {
        Some(d2vr_mask(&scene)?)
    } else {
        None
    };
    let (settings, options) = d2vr_settings(v);
    let tol_gpu = match v.sampling {
        Sampling::Exact => d2vr_tolerance(v),
        Sampling::Hardware => hardware_mip_tol(&scene),
    };
    let samples = box_samples(
        scene.grid.dims,
        scene.grid.affine,
        &scene.camera,
        settings.step,
    );
    let all = Rc::new((scene, mask, settings, options));
    let a = all.clone();
    let cpu_f64 = Box::new(move || {
        let (s, m, st, o) = &*a;
        let t = Instant::now();
        let r = render_d2vr(
            &s.filtered,
            &s.geometry,
            &s.grid,
            &s.tf,
            &s.camera,
            st,
            o,
            m.as_ref(),
            &|_, _| {},
        )?;
        let seconds = t.elapsed().as_secs_f64();
        Ok(Run {
            seconds,
            output: r.render.image.data,
        })
    }) as super::CpuFn;
    let a = all.clone();
    let cpu_f32 = Box::new(move || {
        let (s, m, st, o) = &*a;
        let t = Instant::now();
        let r = render_d2vr(
            &s.filtered_f32,
            &s.geometry,
            &s.grid,
            &s.tf,
            &s.camera,
            st,
            o,
            m.as_ref(),
            &|_, _| {},
        )?;
        let seconds = t.elapsed().as_secs_f64();
        Ok(Run {
            seconds,
            output: r.render.image.data,
        })
    }) as super::CpuFn;
    let a = all;
    let sampling = v.sampling;
    let gpu = Box::new(move |ctx: &crate::gpu::GpuContext| {
        let (s, m, st, o) = &*a;
        let r = crate::gpu::d2vr::render_d2vr(
            ctx,
            &s.filtered_f32,
            &s.geometry,
            &s.grid,
            &s.tf,
            &s.camera,
            st,
            o,
            m.as_ref(),
            crate::gpu::d2vr::ProjStorage::F32,
            sampling,
        )?;
        let t = r.timings;
        Ok(GpuRun {
            output: r.render.image.data,
            kernel: t.kernel,
            kernel_from_timestamps: t.kernel_from_timestamps,
            end_to_end: t.total - t.setup,
            setup: t.setup,
        })
    }) as super::GpuFn;
    Ok(Prepared {
        cpu_f64,
        cpu_f32: Some(cpu_f32),
        gpu: Some(gpu),
        tol_f32: d2vr_tolerance(v),
        tol_gpu,
        work: vec![
            Work {
                amount: (config.image * config.image) as f64,
                unit: Unit::Rays,
            },
            Work {
                amount: samples as f64,
                unit: Unit::Samples,
            },
        ],
        note: format!(
            "Shepp–Logan (modified) from exact cone-beam projections, {}, step 1 voxel. \
             Samples: the grid box's plain march (what +B, +OC and +M skip counts as done). \
             GPU: f32 projection storage{}; kernel = the chunk dispatches on the device \
             (timestamp queries; without them, wall clock); its set-up includes the \
             uploads, so end to end = chunk dispatches + readback + the host's final blend \
             (wall clock).",
            match v.mode {
                Mode::Mip => "MIP",
                _ => "shaded DVR",
            },
            match v.sampling {
                Sampling::Exact => "",
                Sampling::Hardware =>
                    " in 2-D texture arrays, every value filtered by the texture unit \
                     (gpu::plan::Sampling::Hardware); the GPU bound is max |Δ| ≤ \
                     gpu::d2vr::hardware_error_bound for 8-bit weights",
            }
        ),
    })
}
