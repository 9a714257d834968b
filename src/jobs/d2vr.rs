//! `voxlab d2vr`: direct volume rendering from X-ray projections, without
//! reconstructing a grid: every sample is backprojected from the ramp-filtered
//! projections on the fly (Xu & Mueller 2006; docs/d2vr.md). The renderers are
//! [`crate::cpu::d2vr`] and [`crate::gpu::d2vr`].

use super::project::BeamKind;
use super::{Backend, Engine, Progress};
use crate::camera::{Camera, Orbit, Projection};
use crate::cpu::d2vr::{
    render_d2vr, D2vrGradient, D2vrGrid, D2vrOptions, D2vrStats, OccupancyMask,
};
use crate::cpu::ramp::{filter_projections, FilterMethod, RampFilter};
use crate::cpu::raycast::RenderOutput;
use crate::ct::{Geometry, Projections};
use crate::error::{Error, Result};
use crate::real::Real;
use crate::settings::{Mode, RenderSettings};
use crate::transfer::TransferFunction;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use std::sync::Arc;

crate::choice_enum! {
    /// Gradient estimator for shading.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Gradient: "D²VR gradient" {
        /// Central differences of six extra reconstructed samples.
        Gfs = "gfs",
        /// The analytic gradient of the backprojection, from the projections.
        Gfr = "gfr",
    }
}

/// The `voxlab d2vr` job.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct D2vrRequest {
    /// Raw projections: a stack (`.npy` of shape (angle, row, col), NRRD) with its
    /// geometry JSON, or `phantom:NAME`, projected exactly with `beam`, `angles` and
    /// `detector`.
    pub input: String,
    /// Geometry JSON of a projection stack (`None`: `<name>.geometry.json` beside it).
    pub geometry: Option<PathBuf>,
    /// For phantom input: parallel, or cone (SID 600 mm, SDD 900 mm).
    pub beam: BeamKind,
    /// For phantom input: number of projections (over 180° parallel, 360° cone).
    pub angles: usize,
    /// For phantom input: detector side in pixels (it covers the phantom's 256 mm).
    pub detector: usize,
    pub filter: RampFilter,
    /// Virtual grid side N (N³, centred on the isocentre).
    pub grid: usize,
    /// Virtual grid spacing in mm (`None`: 256 mm / N).
    pub spacing: Option<f64>,
    /// dvr, mip, minip or xray.
    pub mode: Mode,
    /// Transfer function: a preset name or a JSON file.
    pub tf: String,
    pub gradient: Gradient,
    /// Reconstruct everywhere (no bounding cylinder).
    pub no_cylinder: bool,
    /// Skip voxels in no object's shadow (occupancy mask from the raw projections).
    pub occupancy: bool,
    /// Early-ray-termination threshold (1 = off).
    pub ert: f64,
    /// Step in voxels of the virtual grid.
    pub step: f64,
    /// Image side in pixels.
    pub size: usize,
    /// Orbit view: rotation about world +z and elevation, degrees.
    pub azimuth: f64,
    pub elevation: f64,
    /// Value range of the reconstruction (scales the shading threshold).
    pub range: [f64; 2],
    /// cpu (the f64 oracle), cpu-f32 or gpu.
    pub backend: Backend,
    /// GPU: keep the filtered projections as 16-bit floats (half the memory).
    pub f16_projections: bool,
    /// GPU: hold the filtered projections in 2-D texture arrays and let the texture
    /// unit interpolate every value (the paper's reconstruction; real GPUs round its
    /// weights to about 8 bits, docs/d2vr.md) instead of the exact interpolation
    /// written out in the shader.
    pub hardware_filtering: bool,
    /// A projection stack already in memory with its geometry (a NumPy array, the
    /// output of the project job), used instead of reading `input`, which then only
    /// names it in messages.
    #[serde(skip)]
    pub memory: Option<Arc<(Projections<f64>, Geometry)>>,
}

impl Default for D2vrRequest {
    fn default() -> Self {
        D2vrRequest {
            input: "phantom:shepp-logan-modified".into(),
            geometry: None,
            beam: BeamKind::Cone,
            angles: 128,
            detector: 128,
            filter: RampFilter::RamLak,
            grid: 128,
            spacing: None,
            mode: Mode::Dvr,
            tf: "phantom".into(),
            gradient: Gradient::Gfr,
            no_cylinder: false,
            occupancy: false,
            ert: 0.99,
            step: 1.0,
            size: 256,
            azimuth: 30.0,
            elevation: 20.0,
            range: [0.0, 1.0],
            backend: Backend::CpuF32,
            f16_projections: false,
            hardware_filtering: false,
            memory: None,
        }
    }
}

/// A D²VR image and what it cost.
#[derive(Clone, Debug)]
pub struct D2vrRendering {
    pub render: RenderOutput,
    pub stats: D2vrStats,
    /// Seconds of rendering (the projections filtered and the mask built before).
    pub seconds: f64,
    pub engine: Engine,
}

/// The raw projections and their geometry: given in memory, read, or projected exactly
/// from a phantom.
fn projections<R: Real>(a: &D2vrRequest) -> Result<(Projections<R>, Geometry)> {
    if let Some(m) = &a.memory {
        let g = geometry(a)?;
        let p = &m.0;
        let data = p.data.iter().map(|&v| R::of(v)).collect();
        return Ok((Projections::new(p.angles, p.rows, p.cols, data)?, g));
    }
    let g = geometry(a)?;
    if let Some(name) = a.input.strip_prefix("phantom:") {
        let ph = crate::phantom::Phantom::by_name(name)?;
        let p = crate::cpu::project::project_phantom(&ph, &g)?;
        let data = p.data.iter().map(|&v| R::of(v)).collect();
        Ok((Projections::new(p.angles, p.rows, p.cols, data)?, g))
    } else {
        let path = PathBuf::from(&a.input);
        Ok((crate::io::projections::read_projections_for(&path, &g)?, g))
    }
}

/// The geometry of the projections `a` names: given in memory, the phantom's
/// (`beam`, `angles`, `detector`), or read from the stack's geometry JSON.
fn geometry(a: &D2vrRequest) -> Result<Geometry> {
    if let Some(m) = &a.memory {
        // Projections in hand are checked against their geometry here, so that the
        // dry run ([`plan`]) refuses them as the run does.
        let (p, g) = m.as_ref();
        g.validate()?;
        p.check_against(g)?;
        return Ok(g.clone());
    }
    if let Some(name) = a.input.strip_prefix("phantom:") {
        crate::phantom::Phantom::by_name(name)?;
        let d = 384.0 / a.detector.max(1) as f64;
        match a.beam {
            BeamKind::Parallel => Geometry::parallel_stack(
                a.detector,
                a.detector,
                256.0 / a.detector.max(1) as f64,
                256.0 / a.detector.max(1) as f64,
                Geometry::even_angles(a.angles, 180.0),
            ),
            BeamKind::Cone => Geometry::cone_rtk(
                600.0,
                900.0,
                a.detector,
                a.detector,
                d,
                d,
                Geometry::even_angles(a.angles, 360.0),
            ),
        }
    } else {
        let path = PathBuf::from(&a.input);
        let gpath = a
            .geometry
            .clone()
            .unwrap_or_else(|| crate::io::projections::geometry_path(&path));
        crate::io::projections::read_geometry(&gpath)
    }
}

/// `voxlab d2vr --dry-run`: the memory plan of [`run`] (host bytes of the projections,
/// their filtered copies and the image; on the GPU the device bytes against the
/// planner's limits and the split, [`crate::gpu::d2vr::D2vrSplit`]), from the
/// geometry alone: nothing is projected, read past the geometry, or rendered.
///
/// # Errors
/// Bad options or geometry; a GPU render that cannot fit even split.
pub fn plan(a: &D2vrRequest) -> Result<super::plan::MemoryPlan> {
    check_request(a)?;
    scene(a)?;
    let g = geometry(a)?;
    g.validate()?;
    let engine = Engine::open(a.backend)?;
    let values = (g.n_angles() * g.rows * g.cols) as u64;
    let pixels = (a.size * a.size) as u64;
    let real = if engine.backend() == Backend::Cpu {
        8
    } else {
        4
    };
    // The raw and filtered projections, the image (f64 RGBA) and its sample counts, the
    // occupancy mask.
    let mut host = 2 * real * values + pixels * (4 * 8 + 4);
    // The occupancy mask: one u32 per voxel of the virtual grid.
    let mask = if a.occupancy {
        4 * (a.grid as u64).pow(3)
    } else {
        4
    };
    host += mask;
    let (device, split) = match engine.gpu() {
        Some(ctx) => {
            let (storage, sampling) = gpu_format(a);
            ctx.require_filtering(sampling, storage.texture_format())?;
            let s = crate::gpu::d2vr::D2vrSplit::new(
                &ctx.limits,
                &g,
                storage,
                sampling,
                (a.size, a.size),
            )?;
            // The f32 copy the upload packs, and the accumulators read back.
            host += 4 * values + 32 * pixels;
            let matrices = 48 * g.n_angles() as u64;
            let device = super::plan::DevicePlan::on(
                ctx,
                s.device_bytes() + matrices + mask,
                s.largest_buffer(),
            );
            (Some(device), s.describe())
        }
        None => (None, Vec::new()),
    };
    Ok(super::plan::MemoryPlan {
        job: format!("d2vr {:?}", a.mode).to_lowercase(),
        backend: engine.describe(),
        host_bytes: host,
        device,
        split,
        writes: Vec::new(),
    })
}

/// The options [`run`] refuses before any work.
fn check_request(a: &D2vrRequest) -> Result<()> {
    if a.f16_projections && a.backend != Backend::Gpu {
        return Err(Error::unsupported(
            "D²VR with 16-bit projections",
            a.backend,
            "16-bit projections are a GPU storage format (use the gpu backend)",
        ));
    }
    if a.hardware_filtering && a.backend != Backend::Gpu {
        return Err(Error::invalid(
            "--hardware-filtering",
            "is the GPU's texture unit: give --backend gpu or gpu-f16",
        ));
    }
    Ok(())
}

/// How the GPU holds and reads the filtered projections.
fn gpu_format(a: &D2vrRequest) -> (crate::gpu::d2vr::ProjStorage, crate::gpu::plan::Sampling) {
    use crate::gpu::d2vr::ProjStorage;
    use crate::gpu::plan::Sampling;
    (
        if a.f16_projections {
            ProjStorage::F16
        } else {
            ProjStorage::F32
        },
        if a.hardware_filtering {
            Sampling::Hardware
        } else {
            Sampling::Exact
        },
    )
}

/// Renders.
///
/// # Errors
/// Bad options, projections or geometry; GPU errors; [`Error::Cancelled`].
pub fn run(a: &D2vrRequest, progress: &dyn Progress) -> Result<D2vrRendering> {
    check_request(a)?;
    let engine = Engine::open(a.backend)?;
    match engine.backend() {
        Backend::Cpu => run_on::<f64>(a, engine, progress),
        _ => run_on::<f32>(a, engine, progress),
    }
}

/// What a render of `a` sees, besides the projections.
struct Scene {
    grid: D2vrGrid,
    camera: Camera,
    tf: TransferFunction,
    settings: RenderSettings,
    options: D2vrOptions,
}

/// The grid, camera, transfer function and settings of `a`, each checked: [`run`] and
/// [`plan`] make them before any projection.
fn scene(a: &D2vrRequest) -> Result<Scene> {
    let n = a.grid;
    let grid = D2vrGrid::centred([n; 3], a.spacing.unwrap_or(256.0 / n.max(1) as f64))?;
    let extent = grid
        .affine
        .transform_vector3(glam::DVec3::splat(n as f64))
        .abs();
    let camera = Camera::orbit(
        glam::DVec3::ZERO,
        extent.to_array(),
        Orbit {
            azimuth_deg: a.azimuth,
            elevation_deg: a.elevation,
            distance_mm: None,
        },
        Projection::Orthographic {
            width_mm: 0.0,
            height_mm: 0.0,
        },
        a.size,
        a.size,
    )?;
    let tf = TransferFunction::preset_or_file(&a.tf)?;
    tf.validate()?;
    let settings = RenderSettings {
        mode: a.mode,
        step: a.step,
        ert_threshold: a.ert,
        ..RenderSettings::default()
    };
    settings.validate()?;
    let options = D2vrOptions {
        gradient: match a.gradient {
            Gradient::Gfs => D2vrGradient::Gfs,
            Gradient::Gfr => D2vrGradient::Gfr,
        },
        cylinder: !a.no_cylinder,
        value_range: (a.range[0], a.range[1]),
    };
    crate::cpu::d2vr::check_inputs(&settings, &options, &grid, &camera)?;
    Ok(Scene {
        grid,
        camera,
        tf,
        settings,
        options,
    })
}

fn run_on<R: Real + rustfft::FftNum>(
    a: &D2vrRequest,
    engine: Engine,
    progress: &dyn Progress,
) -> Result<D2vrRendering> {
    let Scene {
        grid,
        camera,
        tf,
        settings,
        options,
    } = scene(a)?;
    let (raw, g) = projections::<R>(a)?;
    let q = filter_projections(&raw, &g, a.filter, FilterMethod::Fft)?;
    let mask = if a.occupancy {
        Some(OccupancyMask::from_projections(&raw, &g, &grid, 0.0)?)
    } else {
        None
    };
    super::check_cancel(progress)?;
    progress.begin("D²VR", "rows", a.size as u64);
    let t = std::time::Instant::now();
    let (render, stats) = match engine.gpu() {
        Some(ctx) => {
            use crate::gpu::d2vr::render_d2vr as gpu_d2vr;
            let (storage, sampling) = gpu_format(a);
            let q32 = Projections::new(
                q.angles,
                q.rows,
                q.cols,
                q.data.iter().map(|v| v.f64() as f32).collect(),
            )?;
            let o = gpu_d2vr(
                ctx,
                &q32,
                &g,
                &grid,
                &tf,
                &camera,
                &settings,
                &options,
                mask.as_ref(),
                storage,
                sampling,
            )?;
            if a.hardware_filtering {
                progress.note("D²VR projections in textures, filtered by the texture unit");
            }
            for line in o.split.describe() {
                progress.note(&line);
            }
            (o.render, o.stats)
        }
        None => {
            let o = super::cancellable(progress, |cp| {
                render_d2vr(
                    &q,
                    &g,
                    &grid,
                    &tf,
                    &camera,
                    &settings,
                    &options,
                    mask.as_ref(),
                    &|done, total| cp.advance(done, total),
                )
            })?;
            (o.render, o.stats)
        }
    };
    let seconds = t.elapsed().as_secs_f64();
    progress.end(seconds);
    Ok(D2vrRendering {
        render,
        stats,
        seconds,
        engine,
    })
}
