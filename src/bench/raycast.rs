//! Benchmark cases of the ray caster (family `raycast`) and of the precomputed gradient
//! volume (family `gradient`).
//!
//! **raycast.** The modified Shepp–Logan head sampled on an `n³` grid
//! ([`raycast_scene`]), seen by a perspective orbit camera (azimuth 30°, elevation 20°,
//! 540 mm from the centre, 30° field of view) at `size × size` pixels, the `phantom`
//! transfer function, step ½ voxel. The variants ([`raycast_variants`]): shaded DVR with
//! trilinear and Catmull–Rom reconstruction, unshaded DVR with trilinear, shaded DVR through the GPU's texture
//! filtering unit (`hardware_filtering`), shaded DVR with the cubic B-spline as 64 taps
//! (`bspline`), as 8 trilinear fetches (`cubic-bspline-fast`) and as 8 texture-unit
//! fetches (`cubic-bspline-fast-hardware`), MIP, MinIP and X-ray; at 128³ → 256² shaded
//! DVR with the nearest, interpolating cubic B-spline and Lanczos-3 filters, MIDA
//! (γ = 0) and two semi-transparent iso-surfaces (0.25 and 0.6); empty-space skipping
//! (on in every other variant) switched off (`dvr-shaded-trilinear-skip-off`), and the
//! bundled micro-CT scan with skipping on and off (`microct-dvr-skip-on|off`, see
//! [`microct_scene`]); clipping meshes on and off ([`mesh_variants`]). One run is
//! `cpu::raycast::render::<R>` or `gpu::raycast::render` end to end (the volume's
//! conversion to the working precision included, as a caller would see it). Work: rays
//! (= pixels) and samples (the oracle's `total_samples`, counted by one untimed f64
//! render while the case is prepared).
//!
//! **gradient.** `cpu::gradient::precompute_gradients` with central differences
//! `(f(x+1) − f(x−1))/2` on every voxel of the same phantom, the set-up pass of a
//! ray caster that interpolates gradients instead of differencing on the fly, and its
//! GPU port `gpu::gradient::precompute_gradients` (kernel = the slab dispatches; end to
//! end = upload, dispatches and the readback of the three components). Work: voxel
//! updates (one gradient per voxel) and bytes (one f32 read and three f32 writes per
//! voxel, 16 B, whatever the backend's precision).

use super::{Case, GpuRun, Prepared, Run, Suite, Unit, Work};
use crate::camera::{Camera, Orbit, Projection};
use crate::cpu::grid::Grid;
use crate::error::Result;
use crate::metrics::Tolerance;
use crate::phantom::Phantom;
use crate::settings::{Filter, GradientMethod, IsoSurface, Mode, RenderSettings};
use crate::transfer::TransferFunction;
use crate::AnyVolume;
use std::rc::Rc;
use std::time::Instant;

/// The benchmark scene: the modified Shepp–Logan head on an `n³` grid, the `phantom`
/// transfer function, and the perspective orbit camera at `size × size` pixels.
pub fn raycast_scene(n: usize, size: usize) -> Result<(AnyVolume, TransferFunction, Camera)> {
    let vol: AnyVolume = Phantom::shepp_logan_modified().sample([n; 3])?.into();
    let tf = TransferFunction::preset("phantom")?;
    let cam = Camera::orbit(
        glam::DVec3::ZERO,
        [256.0; 3],
        Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            distance_mm: Some(540.0),
        },
        Projection::Perspective { fov_y_deg: 30.0 },
        size,
        size,
    )?;
    Ok((vol, tf, cam))
}

/// The suffix of the variants whose phantom is quantised to u16 ([`u16_scene`]).
pub const U16_SUFFIX: &str = "-u16";

/// [`raycast_scene`] with the phantom quantised to u16, `round(v · 60000)`, and the
/// transfer function's window map scaled to match (`a = 1/60000`): the same picture,
/// an integer volume, which the GPU's hardware path samples from a 16-bit texture
/// (`gpu::raycast::CompactVolume`).
///
/// # Errors
/// As [`raycast_scene`].
pub fn u16_scene(n: usize, size: usize) -> Result<(AnyVolume, TransferFunction, Camera)> {
    const SCALE: f64 = 60000.0;
    let (vol, mut tf, cam) = raycast_scene(n, size)?;
    let v = vol.to_f32();
    let data = v
        .data()
        .iter()
        .map(|&x| (f64::from(x) * SCALE).round() as u16)
        .collect();
    let vol = crate::volume::Volume::with_affine(v.dims(), v.affine(), data)?.into();
    tf.window = crate::transfer::WindowMap {
        a: 1.0 / SCALE,
        b: 0.0,
    };
    Ok((vol, tf, cam))
}

/// The ray caster's benchmark variants, by name: the settings of each.
pub fn raycast_variants() -> Vec<(&'static str, RenderSettings)> {
    let with = |f: &dyn Fn(&mut RenderSettings)| {
        let mut s = RenderSettings::default();
        f(&mut s);
        s
    };
    vec![
        ("dvr-shaded-trilinear", RenderSettings::default()),
        // Post-classified DVR without shading: the CPU's ray-packet kernel
        // (`cpu::march::Packet`), the configuration held against VTK's CPU ray caster.
        (
            "dvr-unshaded-trilinear",
            with(&|s| s.shading.enabled = false),
        ),
        (
            "dvr-shaded-catmull-rom",
            with(&|s| s.filter = Filter::CatmullRom),
        ),
        (
            "dvr-shaded-hardware-trilinear",
            with(&|s| s.hardware_filtering = true),
        ),
        // The same on a u16 volume: the hardware path samples a 16-bit texture.
        (
            "dvr-shaded-hardware-trilinear-u16",
            with(&|s| s.hardware_filtering = true),
        ),
        // The cubic B-spline: 64 taps, 8 manual trilinear fetches, 8 texture-unit
        // fetches (the same image up to the sampler's precision; `cpu::tricubic`).
        ("dvr-shaded-bspline", with(&|s| s.filter = Filter::Bspline)),
        (
            "dvr-shaded-cubic-bspline-fast",
            with(&|s| s.filter = Filter::BsplineFast),
        ),
        (
            "dvr-shaded-cubic-bspline-fast-hardware",
            with(&|s| {
                s.filter = Filter::BsplineFast;
                s.hardware_filtering = true
            }),
        ),
        ("mip-trilinear", with(&|s| s.mode = Mode::Mip)),
        ("minip-trilinear", with(&|s| s.mode = Mode::Minip)),
        ("xray-trilinear", with(&|s| s.mode = Mode::Xray)),
        // Empty-space skipping (on by default) against none: the same image.
        (
            "dvr-shaded-trilinear-skip-off",
            with(&|s| s.skip_empty = false),
        ),
        // The other reconstruction filters (the full sinc, O(n³) per sample, is left
        // out) and the other modes.
        ("dvr-shaded-nearest", with(&|s| s.filter = Filter::Nearest)),
        (
            "dvr-shaded-bspline-interp",
            with(&|s| s.filter = Filter::BsplineInterp),
        ),
        (
            "dvr-shaded-lanczos3",
            with(&|s| s.filter = Filter::Lanczos3),
        ),
        ("mida-trilinear", with(&|s| s.mode = Mode::Mida)),
        (
            "iso-trilinear",
            with(&|s| {
                s.mode = Mode::Iso;
                s.iso_surfaces = vec![
                    IsoSurface {
                        value: 0.25,
                        color: [0.9, 0.6, 0.4],
                        opacity: 0.3,
                    },
                    IsoSurface {
                        value: 0.6,
                        color: [1.0, 1.0, 0.95],
                        opacity: 0.8,
                    },
                ];
            }),
        ),
    ]
}

/// The clipping-mesh variants (`cpu::clipmesh`, `gpu::clipmesh`), all shaded DVR or
/// X-ray with trilinear reconstruction: without a mesh and skipping off
/// (`mesh-off-dvr`), the bricks mesh of the skipping grid with skipping off
/// (`mesh-bricks-dvr`: the same image), a user mesh of two boxes that cut a 40 mm slab
/// out of the head along x (`mesh-slab-dvr`, skipping on, against `dvr-shaded-trilinear`;
/// `mesh-slab-xray` against `mesh-off-xray`), and on the micro-CT scan
/// (`microct-mesh-off`, `microct-mesh-bricks`, skipping off).
pub fn mesh_variants() -> Vec<(&'static str, RenderSettings)> {
    use crate::settings::{ClipMesh, ClipMeshUnits};
    let mut slab = crate::io::mesh::TriMesh::cuboid([-200.0; 3], [-20.0, 200.0, 200.0]);
    slab.append_cuboid([20.0, -200.0, -200.0], [200.0; 3]);
    let slab = Some(ClipMesh::Mesh {
        mesh: std::sync::Arc::new(slab),
        units: ClipMeshUnits::World,
    });
    let off = RenderSettings {
        skip_empty: false,
        ..RenderSettings::default()
    };
    let bricks = RenderSettings {
        clip_mesh: Some(ClipMesh::Bricks),
        ..off.clone()
    };
    let xray = RenderSettings {
        mode: Mode::Xray,
        ..RenderSettings::default()
    };
    vec![
        ("mesh-off-dvr", off.clone()),
        ("mesh-bricks-dvr", bricks.clone()),
        (
            "mesh-slab-dvr",
            RenderSettings {
                clip_mesh: slab.clone(),
                ..RenderSettings::default()
            },
        ),
        ("mesh-off-xray", xray.clone()),
        (
            "mesh-slab-xray",
            RenderSettings {
                clip_mesh: slab,
                ..xray
            },
        ),
        ("microct-mesh-off", off),
        ("microct-mesh-bricks", bricks),
    ]
}

/// The micro-CT variants ([`microct_scene`]): skipping on and off.
pub fn microct_variants() -> Vec<(&'static str, RenderSettings)> {
    vec![
        (MICROCT_SKIP_ON, RenderSettings::default()),
        (
            MICROCT_SKIP_OFF,
            RenderSettings {
                skip_empty: false,
                ..RenderSettings::default()
            },
        ),
    ]
}

/// The real micro-CT scan (`data/microct-bone`, 128³ u8) with the `microct-bone`
/// preset, which leaves the marrow and the air transparent: skipping on and off.
const MICROCT_SKIP_ON: &str = "microct-dvr-skip-on";
const MICROCT_SKIP_OFF: &str = "microct-dvr-skip-off";

/// The micro-CT scene: the bundled scan, the `microct-bone` preset, and the orbit
/// camera of [`raycast_scene`] aimed at the scan's centre.
pub fn microct_scene(size: usize) -> Result<(AnyVolume, TransferFunction, Camera)> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("data/microct-bone/bone_128x128x128.tif");
    let vol = crate::io::read_volume(&path)?;
    let tf = TransferFunction::preset("microct-bone")?;
    let d = vol.dims();
    let centre = vol.affine().transform_point3(
        glam::DVec3::new(d[0] as f64 - 1.0, d[1] as f64 - 1.0, d[2] as f64 - 1.0) * 0.5,
    );
    let extent =
        vol.affine()
            .transform_vector3(glam::DVec3::new(d[0] as f64, d[1] as f64, d[2] as f64));
    let cam = Camera::orbit(
        centre,
        extent.abs().to_array(),
        Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            distance_mm: None,
        },
        Projection::Perspective { fov_y_deg: 30.0 },
        size,
        size,
    )?;
    Ok((vol, tf, cam))
}

/// The f32 CPU path against the f64 oracle, DVR (RGBA in [0, 1]; the peak is an opaque
/// pixel's 1). f32 rounding of sample positions (|t| ≈ 540 mm), amplified by the
/// `phantom` preset's narrow opacity bands (slope ≈ 12 per unit value), moves pixels by
/// ~1e-4; a ray whose opacity lands within rounding of the ERT threshold (0.99) stops one
/// sample earlier or later, which moves its pixel by up to the remaining transmittance,
/// 1e-2. Bound: that plus the rounding. Measured (f32 CPU and lavapipe alike): max
/// 1.8e-3 (64³ → 256², one pixel), 3.2e-4 … 5.5e-4 (128³ → 256²), 5.6e-5 … 9.9e-5
/// (quick), 1.8e-3 (256³ → 512², trilinear and Catmull–Rom, 3–5 pixels beyond 1e-3);
/// rel L2 1.7e-5 (64³) … 4.2e-5 (256³, Catmull–Rom), growing with the size: bound
/// about 4× the worst.
const DVR_F32: Tolerance = Tolerance::max_abs_rel(1.2e-2).with_rel_l2(1.5e-4);
/// The GPU's exact (shader-interpolated) path against the oracle, DVR: the same
/// reasoning and measurements as [`DVR_F32`] (`tests/gpu_raycast.rs` EXACT_DVR holds
/// 32³ → 48² to 1e-3, where no ray sits at the threshold).
const DVR_GPU: Tolerance = DVR_F32;
/// The hardware-filtered path: `tests/gpu_raycast.rs` HARDWARE_DVR, the derived bound
/// for 8-bit sampler weights: each of the three 1-D weights may be off by 2⁻⁸, so a
/// filtered value by 3 × 2⁻⁸ of the data range, and the `phantom` preset's opacity
/// bands (slope up to 12 per unit) make that 36 × 2⁻⁸ on a pixel. The RMS bound is a
/// quarter of the largest error per sample, relative to the oracle image's RMS
/// (0.51–0.52, measured at 24³ → 32² and 64³ → 256²): 2.3e-2 rel L2. Measured on an
/// NVIDIA H200 at 256³ → 512²: max 5.2e-2 (above the single-axis 12 × 2⁻⁸ first
/// written here); lavapipe filters in full f32 and meets the exact bound (6.9e-5 max,
/// 1.1e-5 rel L2 at 24³ → 32²).
const HARDWARE_DVR_GPU: Tolerance = Tolerance::max_abs_rel(36.0 / 256.0).with_rel_l2(2.5e-2);
/// DVR with the nearest-voxel filter, f32 CPU and GPU alike. A sample position within
/// rounding of a cell boundary (x.5) picks the neighbouring voxel in one precision and
/// not in the other: the sample's value jumps by the data step, so its classified
/// colour can change entirely. One sample adds at most its opacity to a pixel: the
/// `phantom` preset's largest, 0.5 per reference voxel, is 0.29 at the ½-voxel step.
/// Bound: 0.3 per pixel; such flips are rare, so rel L2 stays small: measured (CPU
/// f32, 128³ → 256²) max 2.3e-2, rel L2 2.2e-4; bound about 4× that.
const NEAREST_DVR: Tolerance = Tolerance::max_abs_rel(0.3).with_rel_l2(1e-3);
/// X-ray, both the f32 CPU and the GPU: `tests/gpu_raycast.rs` EXACT_SCALAR (5e-5 of
/// the data scale, 4× its worst). Measured (f32 CPU / lavapipe): 2.0e-6 / 4.2e-6 at
/// 24³ → 32², 9.6e-6 / 2.0e-5 at 256³ → 512²; rel L2 ≤ 2.8e-6. Bound: 4× the worst.
const XRAY: Tolerance = Tolerance::max_abs_rel(8e-5).with_rel_l2(1e-5);
/// The GPU's X-ray through a user clipping mesh (`gpu::clipmesh`): its segments are
/// computed in f32, so a sample whose midpoint lies within rounding (≈ 1e-7 of |t|) of a
/// mesh face is taken on one backend and not on the other, which moves that pixel by one
/// sample's `value × step` (1 mm here) against a peak of ≈ 330 value·mm, 3e-3. Measured
/// on lavapipe (`mesh-slab-xray`, 128³ → 256²): max 3.1e-3 (one sample), rel L2 8.4e-5.
/// Bound: about three flipped samples on a pixel.
const XRAY_MESH_GPU: Tolerance = Tolerance::max_abs_rel(1e-2).with_rel_l2(3e-4);
/// MIP and MinIP. The maximum along a ray sits on the sharpest edges, where f32 rounding
/// of the sample position (≈ 3e-5 mm at |t| ≈ 540 mm, several roundings) meets a slope of
/// up to the data range per voxel: the error grows with the resolution. Measured (f32
/// CPU / lavapipe): MIP 6.1e-6 / 9.6e-6 at 24³ → 32², 7.1e-5 / 1.5e-4 at 256³ → 512²;
/// rel L2 ≤ 3.8e-6. MinIP 0 (every ray's minimum is the air's exact 0, in any precision:
/// a timing case). Bound: about 3× the worst (the full suite has MIP at 256³ only).
const MIP: Tolerance = Tolerance::max_abs_rel(5e-4).with_rel_l2(1.5e-5);
/// Central differences in f32 against f64 from the same f32 voxels: one rounding of the
/// difference (2⁻²⁴ relative to the larger neighbour), so ≤ 6e-8 of the peak.
const GRADIENT_F32: Tolerance = Tolerance::max_abs_rel(1e-6).with_rel_l2(1e-6);

/// (variant, volume side, image side) of every raycast case of a suite.
fn raycast_grid(suite: Suite) -> Vec<(&'static str, usize, usize)> {
    match suite {
        Suite::Quick => vec![
            ("dvr-shaded-trilinear", 32, 48),
            ("dvr-unshaded-trilinear", 24, 32),
            ("dvr-shaded-catmull-rom", 24, 32),
            ("dvr-shaded-hardware-trilinear", 24, 32),
            ("dvr-shaded-hardware-trilinear-u16", 24, 32),
            ("mip-trilinear", 24, 32),
            ("minip-trilinear", 24, 32),
            ("xray-trilinear", 24, 32),
            ("mida-trilinear", 24, 32),
            ("iso-trilinear", 24, 32),
            ("mesh-slab-dvr", 24, 32),
        ],
        // The f64 oracle dominates: on 16 cores about 0.1 s at 128³ → 256² (shaded DVR,
        // trilinear), ×8 per doubling of both sides (×4 rays, ×2 samples per ray).
        Suite::Full => vec![
            ("dvr-shaded-trilinear", 64, 256),
            ("dvr-shaded-trilinear", 128, 256),
            ("dvr-shaded-trilinear", 256, 512),
            ("dvr-shaded-trilinear", 512, 1024),
            ("dvr-unshaded-trilinear", 256, 512),
            ("dvr-shaded-catmull-rom", 256, 512),
            ("dvr-shaded-hardware-trilinear", 256, 512),
            ("dvr-shaded-hardware-trilinear-u16", 256, 512),
            ("dvr-shaded-hardware-trilinear-u16", 512, 1024),
            ("dvr-shaded-bspline", 256, 512),
            ("dvr-shaded-cubic-bspline-fast", 256, 512),
            ("dvr-shaded-cubic-bspline-fast-hardware", 256, 512),
            ("mip-trilinear", 256, 512),
            ("minip-trilinear", 256, 512),
            ("xray-trilinear", 256, 512),
            ("dvr-shaded-trilinear-skip-off", 256, 512),
            (MICROCT_SKIP_ON, 128, 512),
            (MICROCT_SKIP_OFF, 128, 512),
            ("dvr-shaded-nearest", 128, 256),
            ("dvr-shaded-bspline-interp", 128, 256),
            ("dvr-shaded-lanczos3", 128, 256),
            ("mida-trilinear", 128, 256),
            ("iso-trilinear", 128, 256),
            ("mesh-off-dvr", 128, 256),
            ("mesh-bricks-dvr", 128, 256),
            ("mesh-slab-dvr", 128, 256),
            ("mesh-off-xray", 128, 256),
            ("mesh-slab-xray", 128, 256),
            ("microct-mesh-off", 128, 256),
            ("microct-mesh-bricks", 128, 256),
        ],
    }
}

/// Every raycast and gradient case of a suite.
pub fn cases(suite: Suite) -> Vec<Case> {
    let mut variants = raycast_variants();
    variants.extend(microct_variants());
    variants.extend(mesh_variants());
    let mut out = Vec::new();
    for (name, n, size) in raycast_grid(suite) {
        let settings = variants
            .iter()
            .find(|(v, _)| *v == name)
            .map(|(_, s)| s.clone())
            .unwrap_or_default();
        out.push(Case::new(
            "raycast",
            name,
            format!("{n}³ → {size}²"),
            move || prepare_raycast(name, n, size, settings.clone()),
        ));
    }
    let sides: &[usize] = match suite {
        Suite::Quick => &[32],
        // 512³ would hold 3 × 512³ f64 gradient components per backend for the parity
        // check (3.2 GB each): left out.
        Suite::Full => &[128, 256],
    };
    for &n in sides {
        out.push(Case::new(
            "gradient",
            "central-differences",
            format!("{n}³"),
            move || prepare_gradient(n),
        ));
    }
    out
}

/// The tolerances of a ray-caster variant: (f32 CPU, GPU).
pub fn raycast_tolerances(settings: &RenderSettings) -> (Tolerance, Tolerance) {
    let user_mesh = matches!(
        settings.clip_mesh,
        Some(crate::settings::ClipMesh::Mesh { .. })
    );
    match settings.mode {
        Mode::Dvr if settings.hardware_filtering => (DVR_F32, HARDWARE_DVR_GPU),
        Mode::Dvr if settings.filter == Filter::Nearest => (NEAREST_DVR, NEAREST_DVR),
        Mode::Dvr | Mode::Mida | Mode::Iso => (DVR_F32, DVR_GPU),
        Mode::Xray if user_mesh => (XRAY, XRAY_MESH_GPU),
        Mode::Xray => (XRAY, XRAY),
        Mode::Mip | Mode::Minip => (MIP, MIP),
    }
}

fn prepare_raycast(
    name: &str,
    n: usize,
    size: usize,
    settings: RenderSettings,
) -> Result<Prepared> {
    let (vol, tf, cam) = if name.starts_with("microct") {
        microct_scene(size)?
    } else if name.ends_with(U16_SUFFIX) {
        u16_scene(n, size)?
    } else {
        raycast_scene(n, size)?
    };
    let scene = Rc::new((vol, tf, cam, settings));
    let oracle =
        crate::cpu::raycast::render::<f64>(&scene.0, &scene.1, &scene.2, &scene.3, &|_, _| {})?;
    let (tol_f32, tol_gpu) = raycast_tolerances(&scene.3);
    let cpu = |s: Rc<(AnyVolume, TransferFunction, Camera, RenderSettings)>, f64_path: bool| {
        Box::new(move || {
            let t = Instant::now();
            let out = if f64_path {
                crate::cpu::raycast::render::<f64>(&s.0, &s.1, &s.2, &s.3, &|_, _| {})?
            } else {
                crate::cpu::raycast::render::<f32>(&s.0, &s.1, &s.2, &s.3, &|_, _| {})?
            };
            let seconds = t.elapsed().as_secs_f64();
            Ok(Run {
                seconds,
                output: out.image.data,
            })
        }) as super::CpuFn
    };
    let g = scene.clone();
    let gpu = Box::new(move |ctx: &crate::gpu::GpuContext| {
        let r = crate::gpu::raycast::render(ctx, &g.0, &g.1, &g.2, &g.3, &|_, _| {})?;
        let t = r.timings;
        Ok(GpuRun {
            output: r.output.image.data,
            kernel: t.kernel,
            kernel_from_timestamps: t.kernel_from_timestamps,
            end_to_end: t.total - t.setup,
            setup: t.setup,
        })
    }) as super::GpuFn;
    let subject = if name.starts_with("microct") {
        "the bundled micro-CT bone scan (128³ u8), `microct-bone` TF"
    } else if name.ends_with(U16_SUFFIX) {
        "Shepp–Logan (modified) quantised to u16 (round(v · 60000); the GPU's hardware \
         path samples a 16-bit texture), `phantom` TF windowed to match"
    } else {
        "Shepp–Logan (modified), `phantom` TF"
    };
    let mut note = format!(
        "{subject}, perspective orbit camera, step 0.5 voxel; end to end per backend \
         (volume conversion included; GPU end to end = upload, set-up passes, ray \
         casting, readback). Samples: the f64 oracle's count."
    );
    if scene.3.hardware_filtering {
        note.push_str(
            " GPU samples through the texture unit (8-bit weights on NVIDIA): held to the \
             derived hardware bound, not the exact one.",
        );
    }
    Ok(Prepared {
        cpu_f64: cpu(scene.clone(), true),
        cpu_f32: Some(cpu(scene.clone(), false)),
        gpu: Some(gpu),
        tol_f32,
        tol_gpu,
        work: vec![
            Work {
                amount: (size * size) as f64,
                unit: Unit::Rays,
            },
            Work {
                amount: oracle.total_samples as f64,
                unit: Unit::Samples,
            },
        ],
        note,
    })
}

/// The gradient family's input: the head's f32 voxels.
pub fn gradient_volume(n: usize) -> Result<Grid<f32>> {
    let v = Phantom::shepp_logan_modified().sample([n; 3])?;
    Ok(Grid::from_volume(&v))
}

fn prepare_gradient(n: usize) -> Result<Prepared> {
    let g32 = Rc::new(gradient_volume(n)?);
    let g64 = Rc::new(Grid::<f64> {
        dims: g32.dims,
        data: g32.data.iter().map(|&v| v as f64).collect(),
    });
    fn run<R: crate::real::Real>(g: &Grid<R>) -> Run {
        let t = Instant::now();
        let [gx, gy, gz] = crate::cpu::gradient::precompute_gradients(g, GradientMethod::Central);
        let seconds = t.elapsed().as_secs_f64();
        let output = [gx, gy, gz]
            .iter()
            .flat_map(|c| c.data.iter().map(|v| v.f64()))
            .collect();
        Run { seconds, output }
    }
    let voxels = (n * n * n) as f64;
    let gpu_grid = Rc::clone(&g32);
    let gpu = Box::new(move |ctx: &crate::gpu::GpuContext| {
        let r = crate::gpu::gradient::precompute_gradients_timed(
            ctx,
            &gpu_grid,
            GradientMethod::Central,
        )?;
        let t = r.timings;
        Ok(GpuRun {
            output: r
                .components
                .iter()
                .flat_map(|c| c.data.iter().map(|&v| v as f64))
                .collect(),
            kernel: t.kernel,
            kernel_from_timestamps: t.kernel_from_timestamps,
            end_to_end: t.total - t.setup,
            setup: t.setup,
        })
    }) as super::GpuFn;
    Ok(Prepared {
        cpu_f64: Box::new(move || Ok(run(&g64))),
        cpu_f32: Some(Box::new(move || Ok(run(&g32)))),
        gpu: Some(gpu),
        tol_f32: GRADIENT_F32,
        tol_gpu: GRADIENT_F32,
        work: vec![
            Work {
                amount: voxels,
                unit: Unit::VoxelUpdates,
            },
            Work {
                amount: 16.0 * voxels,
                unit: Unit::Bytes,
            },
        ],
        note: "Output: the x, y and z components, one after the other. GPU: the same \
               stencil in f32 (shaders/shared/gradient_voxel.wgsl), read back in slabs. \
               Work: one voxel update per gradient; bytes = 16 per voxel (one f32 read, \
               three f32 writes)."
            .into(),
    })
}
