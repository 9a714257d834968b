//! `voxlab d2vr`: direct volume rendering from X-ray projections (see docs/d2vr.md).

use clap::{Args, ValueEnum};
use std::path::PathBuf;
use voxlab::camera::{Camera, Orbit, Projection};
use voxlab::cpu::d2vr::{render_d2vr, D2vrGradient, D2vrGrid, D2vrOptions, OccupancyMask};
use voxlab::cpu::ramp::{filter_projections, FilterMethod, RampFilter};
use voxlab::ct::{Geometry, Projections};
use voxlab::frame::PngOptions;
use voxlab::settings::{Mode, RenderSettings};
use voxlab::transfer::TransferFunction;
use voxlab::{Error, Result};

/// Gradient estimator for shading.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum GradientArg {
    /// Central differences of six extra reconstructed samples.
    Gfs,
    /// The analytic gradient of the backprojection, from the projections.
    Gfr,
}

/// Arguments of `voxlab d2vr`.
#[derive(Args)]
pub struct D2vrArgs {
    /// Raw projections: a stack (.npy of shape (angle, row, col), NRRD) with its
    /// geometry JSON (--geometry, default `<name>.geometry.json` beside it), or
    /// phantom:NAME, projected exactly with --beam / --angles / --detector.
    input: String,
    /// Geometry JSON of a projection stack.
    #[arg(long)]
    geometry: Option<PathBuf>,
    /// For phantom input: parallel or cone (SID 600 mm, SDD 900 mm).
    #[arg(long, default_value = "cone")]
    beam: String,
    /// For phantom input: number of projections (over 180° parallel, 360° cone).
    #[arg(long, default_value_t = 128)]
    angles: usize,
    /// For phantom input: detector side in pixels (it covers the phantom's 256 mm).
    #[arg(long, default_value_t = 128)]
    detector: usize,
    /// Output image (.png or .npy).
    #[arg(long)]
    out: PathBuf,
    /// Ramp filter window.
    #[arg(long, value_enum, default_value = "ramp")]
    filter: RampFilter,
    /// Virtual grid side N (N³, centred on the isocentre).
    #[arg(long, default_value_t = 128)]
    grid: usize,
    /// Virtual grid spacing in mm (default: 256 mm / N).
    #[arg(long)]
    spacing: Option<f64>,
    /// dvr, mip, minip or xray.
    #[arg(long, value_enum, default_value = "dvr")]
    mode: Mode,
    /// Transfer function: preset name or JSON file.
    #[arg(long, default_value = "phantom")]
    tf: String,
    /// Gradients for shading.
    #[arg(long, value_enum, default_value = "gfr")]
    gradient: GradientArg,
    /// Reconstruct everywhere (no bounding cylinder).
    #[arg(long)]
    no_cylinder: bool,
    /// Skip voxels in no object's shadow (occupancy mask from the raw projections).
    #[arg(long)]
    occupancy: bool,
    /// Early-ray-termination threshold (1 = off).
    #[arg(long, default_value_t = 0.99)]
    ert: f64,
    /// Step in voxels of the virtual grid.
    #[arg(long, default_value_t = 1.0)]
    step: f64,
    /// Image side in pixels.
    #[arg(long, default_value_t = 256)]
    size: usize,
    /// Orbit view: rotation about world +z in degrees.
    #[arg(long, default_value_t = 30.0, allow_negative_numbers = true)]
    azimuth: f64,
    /// Orbit view: degrees above the xy-plane.
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
    elevation: f64,
    /// Value range of the reconstruction (scales the shading threshold).
    #[arg(long, num_args = 2, default_values_t = [0.0, 1.0], allow_negative_numbers = true)]
    range: Vec<f64>,
    /// cpu (f32) or gpu (f32 projections), gpu-f16 (16-bit projections).
    #[arg(long, default_value = "cpu")]
    backend: String,
}

pub fn run(a: D2vrArgs) -> Result<()> {
    crate::check_output(&a.out)?;
    let (raw, g): (Projections<f32>, Geometry) =
        if let Some(name) = a.input.strip_prefix("phantom:") {
            let ph = voxlab::phantom::Phantom::by_name(name)?;
            let d = 384.0 / a.detector.max(1) as f64;
            let g = match a.beam.as_str() {
                "parallel" => Geometry::parallel_stack(
                    a.detector,
                    a.detector,
                    256.0 / a.detector.max(1) as f64,
                    256.0 / a.detector.max(1) as f64,
                    Geometry::even_angles(a.angles, 180.0),
                )?,
                "cone" => Geometry::cone_rtk(
                    600.0,
                    900.0,
                    a.detector,
                    a.detector,
                    d,
                    d,
                    Geometry::even_angles(a.angles, 360.0),
                )?,
                other => {
                    return Err(Error::invalid(
                        "--beam",
                        format!("'{other}' is not parallel or cone"),
                    ))
                }
            };
            let p = voxlab::cpu::project::project_phantom(&ph, &g)?;
            let data = p.data.iter().map(|&v| v as f32).collect();
            (Projections::new(p.angles, p.rows, p.cols, data)?, g)
        } else {
            let path = PathBuf::from(&a.input);
            let gpath = a
                .geometry
                .clone()
                .unwrap_or_else(|| voxlab::io::projections::geometry_path(&path));
            let g = voxlab::io::projections::read_geometry(&gpath)?;
            (voxlab::io::projections::read_projections_for(&path, &g)?, g)
        };
    let q = filter_projections(&raw, &g, a.filter, FilterMethod::Fft)?;
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
    let settings = RenderSettings {
        mode: a.mode,
        step: a.step,
        ert_threshold: a.ert,
        ..RenderSettings::default()
    };
    let options = D2vrOptions {
        gradient: match a.gradient {
            GradientArg::Gfs => D2vrGradient::Gfs,
            GradientArg::Gfr => D2vrGradient::Gfr,
        },
        cylinder: !a.no_cylinder,
        value_range: (a.range[0], a.range[1]),
    };
    let mask = if a.occupancy {
        Some(OccupancyMask::from_projections(&raw, &g, &grid, 0.0)?)
    } else {
        None
    };
    let t = std::time::Instant::now();
    let (render, stats) = match a.backend.as_str() {
        "cpu" => {
            let o = render_d2vr(
                &q,
                &g,
                &grid,
                &tf,
                &camera,
                &settings,
                &options,
                mask.as_ref(),
                &|_, _| {},
            )?;
            (o.render, o.stats)
        }
        "gpu" | "gpu-f16" => {
            use voxlab::gpu::d2vr::{render_d2vr as gpu_d2vr, ProjStorage};
            let ctx = voxlab::gpu::GpuContext::new()?;
            let storage = if a.backend == "gpu" {
                ProjStorage::F32
            } else {
                ProjStorage::F16
            };
            let o = gpu_d2vr(
                &ctx,
                &q,
                &g,
                &grid,
                &tf,
                &camera,
                &settings,
                &options,
                mask.as_ref(),
                storage,
            )?;
            (o.render, o.stats)
        }
        other => {
            return Err(Error::invalid(
                "--backend",
                format!("'{other}' is not cpu, gpu or gpu-f16"),
            ))
        }
    };
    eprintln!(
        "D²VR: {:.2} s; {:.1} % of the box's samples reconstructed ({} of {}), {} gradient reconstructions",
        t.elapsed().as_secs_f64(),
        100.0 * stats.fraction(),
        stats.value_reconstructions,
        stats.box_samples,
        stats.gradient_reconstructions
    );
    render.image.save(
        &a.out,
        PngOptions {
            sixteen_bit: false,
            range: None,
        },
    )
}
