//! `voxlab d2vr`: direct volume rendering from X-ray projections, through
//! [`voxlab::jobs::d2vr::run`].

use crate::cli::{choice, Terminal};
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use voxlab::cpu::ramp::RampFilter;
use voxlab::io::{check_output, write_frame, PngOptions};
use voxlab::jobs::d2vr::{D2vrRequest, Gradient};
use voxlab::jobs::project::BeamKind;
use voxlab::jobs::Backend;
use voxlab::settings::Mode;
use voxlab::{Error, Result};

/// Arguments of `voxlab d2vr`.
#[derive(Args)]
pub struct D2vrArgs {
    /// Raw projections: a stack (.npy of shape (angle, row, col), NRRD) with its
    /// geometry JSON (--geometry, default `<name>.geometry.json` beside it), or
    /// phantom:NAME, projected exactly with --beam / --angles / --detector.
    pub input: String,
    /// Geometry JSON of a projection stack.
    #[arg(long)]
    pub geometry: Option<PathBuf>,
    /// For phantom input: parallel or cone (SID 600 mm, SDD 900 mm).
    #[arg(long, value_parser = choice::<BeamKind>(), default_value = "cone")]
    pub beam: BeamKind,
    /// For phantom input: number of projections (over 180° parallel, 360° cone).
    #[arg(long, default_value_t = 128)]
    pub angles: usize,
    /// For phantom input: detector side in pixels (it covers the phantom's 256 mm).
    #[arg(long, default_value_t = 128)]
    pub detector: usize,
    /// Output image (.png or .npy).
    #[arg(long)]
    pub out: PathBuf,
    /// Ramp filter window.
    #[arg(long, value_parser = choice::<RampFilter>(), default_value = "ramp")]
    pub filter: RampFilter,
    /// Virtual grid side N (N³, centred on the isocentre).
    #[arg(long, default_value_t = 128)]
    pub grid: usize,
    /// Virtual grid spacing in mm (default: 256 mm / N).
    #[arg(long)]
    pub spacing: Option<f64>,
    /// dvr, mip, minip or xray.
    #[arg(long, value_parser = choice::<Mode>(), default_value = "dvr")]
    pub mode: Mode,
    /// Transfer function: preset name or JSON file.
    #[arg(long, default_value = "phantom")]
    pub tf: String,
    /// Gradients for shading.
    #[arg(long, value_parser = choice::<Gradient>(), default_value = "gfr")]
    pub gradient: Gradient,
    /// Reconstruct everywhere (no bounding cylinder).
    #[arg(long)]
    pub no_cylinder: bool,
    /// Skip voxels in no object's shadow (occupancy mask from the raw projections).
    #[arg(long)]
    pub occupancy: bool,
    /// Early-ray-termination threshold (1 = off).
    #[arg(long, default_value_t = 0.99)]
    pub ert: f64,
    /// Step in voxels of the virtual grid.
    #[arg(long, default_value_t = 1.0)]
    pub step: f64,
    /// Image side in pixels.
    #[arg(long, default_value_t = 256)]
    pub size: usize,
    /// Orbit view: rotation about world +z in degrees.
    #[arg(long, default_value_t = 30.0, allow_negative_numbers = true)]
    pub azimuth: f64,
    /// Orbit view: degrees above the xy-plane.
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
    pub elevation: f64,
    /// Value range of the reconstruction (scales the shading threshold).
    #[arg(long, num_args = 2, default_values_t = [0.0, 1.0], allow_negative_numbers = true)]
    pub range: Vec<f64>,
    /// cpu-f32 (the CPU in f32, the default), cpu (the f64 oracle), gpu (f32
    /// projections), gpu-f16 (16-bit projections on the GPU), or auto.
    #[arg(long, default_value = "cpu-f32")]
    pub backend: String,
    /// GPU only: hold the filtered projections in 2-D texture arrays and let the
    /// texture unit interpolate every value, as the paper does (GFR's gradient gathers
    /// the four texels; real GPUs quantise the filter's weights to about 8 bits,
    /// docs/d2vr.md), instead of the exact interpolation written out in the shader.
    #[arg(long)]
    pub hardware_filtering: bool,
    /// Print the memory plan (host bytes, device bytes against the adapter's limits,
    /// and how the GPU would bind the projections and band the image) from the
    /// geometry, and render and write nothing.
    #[arg(long)]
    pub dry_run: bool,
}

pub fn run(a: D2vrArgs) -> Result<ExitCode> {
    check_output("output file", &a.out, &["png", "npy"])?;
    let (backend, f16_projections) = match a.backend.as_str() {
        "gpu-f16" => (Backend::Gpu, true),
        other => (
            other.parse::<Backend>().map_err(|_| {
                Error::invalid(
                    "--backend",
                    format!("'{other}' is not cpu, cpu-f32, gpu, gpu-f16 or auto"),
                )
            })?,
            false,
        ),
    };
    let req = D2vrRequest {
        input: a.input.clone(),
        geometry: a.geometry.clone(),
        beam: a.beam,
        angles: a.angles,
        detector: a.detector,
        filter: a.filter,
        grid: a.grid,
        spacing: a.spacing,
        mode: a.mode,
        tf: a.tf.clone(),
        gradient: a.gradient,
        no_cylinder: a.no_cylinder,
        occupancy: a.occupancy,
        ert: a.ert,
        step: a.step,
        size: a.size,
        azimuth: a.azimuth,
        elevation: a.elevation,
        range: [a.range[0], a.range[1]],
        backend,
        f16_projections,
        hardware_filtering: a.hardware_filtering,
        memory: None,
    };
    if a.dry_run {
        let mut plan = voxlab::jobs::d2vr::plan(&req)?;
        plan.writes.push(a.out.display().to_string());
        print!("{}", plan.describe());
        return Ok(ExitCode::SUCCESS);
    }
    let term = Terminal::bars();
    let o = voxlab::jobs::d2vr::run(&req, &term)?;
    drop(term);
    let stats = &o.stats;
    eprintln!(
        "D²VR: {:.2} s; {:.1} % of the box's samples reconstructed ({} of {}), {} gradient reconstructions",
        o.seconds,
        100.0 * stats.fraction(),
        stats.value_reconstructions,
        stats.box_samples,
        stats.gradient_reconstructions
    );
    write_frame(
        &a.out,
        &o.render.image,
        PngOptions {
            sixteen_bit: false,
            range: None,
        },
    )?;
    Ok(ExitCode::SUCCESS)
}
