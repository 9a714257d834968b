//! `voxlab reconstruct`: FBP/FDK or an iterative method (SIRT, CGLS, OS-SART, TV) on a
//! projection file, through [`voxlab::jobs::reconstruct::run`].

use crate::cli::{choice, Terminal};
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use voxlab::cpu::iterative::SubsetOrder;
use voxlab::cpu::ramp::RampFilter;
use voxlab::jobs::reconstruct::{Init, ReconstructMethod, ReconstructRequest};
use voxlab::jobs::Backend;
use voxlab::Result;

/// Arguments of `voxlab reconstruct`.
#[derive(Args)]
pub struct ReconstructArgs {
    /// Projections in any volume format voxlab reads (.npy, .nrrd/.nhdr, .mha/.mhd, TIFF
    /// file or directory, NIfTI, DICOM; x, y, z = col, row, angle); 2-D = a scikit-image
    /// sinogram (detector, angle), 3-D = a stack (angle, row, col). Line integrals, or
    /// intensities with --flat (and --dark).
    pub input: PathBuf,
    /// Which 3-D stack to read from an input that holds several (a 4-D NIfTI, MetaImage
    /// or NRRD, a DICOM time series): 0, 1, …
    #[arg(long)]
    pub frame: Option<usize>,
    /// The input holds detector intensities I: the flat-field image F (beam, no object),
    /// one (rows, cols) image or a stack of frames (averaged), any format the input may
    /// be in. The projections become p = −ln((I − D)/(F − D)); dead pixels (F − D ≤ 0)
    /// give 0, starved ones (I − D ≤ 0) the floored ratio; the counts are printed
    /// (docs/ct.md).
    #[arg(long)]
    pub flat: Option<PathBuf>,
    /// With --flat: the dark-field image D (no beam; default 0), as --flat.
    #[arg(long, requires = "flat")]
    pub dark: Option<PathBuf>,
    /// `parallel` (scikit-image's geometry; needs --angles) or a geometry file, its
    /// format told by its contents: voxlab's JSON (as `voxlab project` writes; circular
    /// or view by view), ASTRA's proj_geom as JSON (cone, cone_vec, parallel3d,
    /// parallel3d_vec), or RTK's geometry XML (its detector pixels come from the
    /// projections' spacing and origin, as in RTK, or from --detector-spacing). Default:
    /// <input-stem>.geometry.json beside the input (docs/ct.md).
    #[arg(long)]
    pub geometry: Option<String>,
    /// With --geometry parallel: a text file of angles in degrees (one per line), or a
    /// count N (N angles evenly over 180°).
    #[arg(long)]
    pub angles: Option<String>,
    /// With RTK's geometry XML: the detector pixel spacing DU[,DV] in mm (DV = DU when
    /// omitted), the detector centred as RTK centres it, for projections whose file
    /// records no spacing (.npy, TIFF); replaces a MetaImage's or NRRD's own.
    #[arg(long, value_name = "DU[,DV]", value_delimiter = ',', num_args = 1)]
    pub detector_spacing: Option<Vec<f64>>,
    /// Frequency window of the ramp (scikit-image's filter names).
    #[arg(long, value_parser = choice::<RampFilter>(), default_value = "ramp")]
    pub filter: RampFilter,
    /// Output size: the image is N × N (parallel; default the detector count) or the
    /// volume N³ (cone; default the detector columns).
    #[arg(long)]
    pub size: Option<usize>,
    /// Voxel spacing in mm (parallel: default the detector spacing; cone: default
    /// du·SID/SDD, the detector spacing at the isocentre).
    #[arg(long)]
    pub spacing: Option<f64>,
    /// Parallel beam: do not mask the image to the inscribed circle (scikit-image's
    /// circle=False: no padding of the sinogram, values in the corners). The default is
    /// iradon's circle=True.
    #[arg(long)]
    pub no_circle: bool,
    /// Cone beam over less than a full turn (at least 180° + the fan angle): weigh the
    /// projections with Parker's short-scan weights before filtering (docs/ct.md).
    #[arg(long)]
    pub short_scan: bool,
    /// Who computes: cpu (f64), cpu-f32, gpu (f32: FBP/FDK backprojection, or the
    /// iterative methods on Joseph's pair), or auto (iterative methods: cpu).
    #[arg(long, value_parser = choice::<Backend>(), default_value = "cpu")]
    pub backend: Backend,
    /// GPU FBP/FDK only: the backprojection samples the filtered projections through
    /// the texture unit (a 2-D texture array, hardware bilinear filtering) instead of
    /// the exact interpolation written out in the shader (real GPUs quantise its
    /// weights to about 8 bits; docs/parity.md).
    #[arg(long)]
    pub hardware_filtering: bool,
    /// Output: .npy (float32; (n, n), (rows, n, n) or (N, N, N)), .nrrd/.nhdr (volume
    /// with the grid's affine, mm in the CT frame) or .png (2-D images only, windowed
    /// to the value range).
    #[arg(long)]
    pub out: PathBuf,
    /// A phantom (phantom:NAME) the projections came from: prints the RMS error of the
    /// reconstruction against its exact values at the voxel centres.
    #[arg(long)]
    pub truth: Option<String>,
    /// With --truth: write |reconstruction − truth| of the central slice to this PNG
    /// (black = 0, white = the largest error).
    #[arg(long, requires = "truth")]
    pub error_map: Option<PathBuf>,
    /// fbp (FBP/FDK, one pass) or an iterative method on Joseph's matched projector
    /// pair: sirt, cgls, os-sart, tv (docs/iterative.md).
    #[arg(long, value_parser = choice::<ReconstructMethod>(), default_value = "fbp")]
    pub method: ReconstructMethod,
    /// Iterative methods: the number of iterations (default: sirt 100, cgls 30,
    /// os-sart 20, tv 200).
    #[arg(long)]
    pub iterations: Option<usize>,
    /// os-sart: the number of ordered subsets (default 10, or the number of views if
    /// fewer); subset s holds the views s, s + K, s + 2K, …
    #[arg(long)]
    pub subsets: Option<usize>,
    /// os-sart: the order the subsets are visited in.
    #[arg(long, value_parser = choice::<SubsetOrder>(), default_value = "sequential")]
    pub subset_order: SubsetOrder,
    /// sirt, os-sart: the relaxation λ, in (0, 2) (default 1).
    #[arg(long)]
    pub relaxation: Option<f64>,
    /// tv: the weight w of the total variation in ½‖Ax − b‖² + w·TV(x) (default 0.2,
    /// for densities near 1 per mm).
    #[arg(long)]
    pub tv_weight: Option<f64>,
    /// sirt, os-sart, tv: keep every voxel ≥ 0.
    #[arg(long)]
    pub nonnegative: bool,
    /// Iterative methods: start from zero or from the FBP/FDK image (--filter applies).
    #[arg(long, value_parser = choice::<Init>(), default_value = "zero")]
    pub init: Init,
    /// Iterative methods: stop once the objective falls by less than this fraction in
    /// one iteration (default 0: run every iteration).
    #[arg(long, default_value_t = 0.0)]
    pub tolerance: f64,
    /// Iterative methods: write iteration,residual,objective per iteration to this CSV.
    #[arg(long)]
    pub convergence: Option<PathBuf>,
    /// Print the memory plan (host bytes, device bytes against the adapter's limits,
    /// and the split the GPU would use) after reading the input, and write nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// Run on the ranks of `mpirun -n N voxlab reconstruct … --distributed`, writing
    /// one .npy output together. FBP/FDK: the volume cut into one slab per rank, each
    /// rank reading only the detector rows its slab needs from a 3-D .npy, raw NRRD or
    /// uncompressed MetaImage stack (other files are read whole) and converting only
    /// those with --flat/--dark (equal byte for byte to a single-process run). --method sirt, os-sart, cgls or tv: the
    /// views cut among the ranks, each reading only its views and holding the whole
    /// image, the backprojections summed by an all-reduce every iteration (os-sart:
    /// every subset) (equal to a single-process run up to rounding; bit for bit on one
    /// rank; --convergence is written by rank 0; --init fbp starts from the FBP made in
    /// slabs). Needs a build with the `mpi` feature; CPU backends only; not with --truth
    /// or --frame (docs/distributed.md).
    #[arg(long)]
    pub distributed: bool,
    /// With --distributed --dry-run: the number of ranks to plan for (no MPI needed):
    /// prints each rank's slab, the detector lines it would read and its host memory.
    #[arg(long, requires = "distributed", requires = "dry_run")]
    pub ranks: Option<usize>,
}

pub fn run(a: ReconstructArgs) -> Result<ExitCode> {
    let req = ReconstructRequest {
        input: a.input.clone(),
        frame: a.frame,
        flat: a.flat.clone(),
        dark: a.dark.clone(),
        geometry: a.geometry.clone(),
        angles: a.angles.clone(),
        detector_spacing: detector_spacing(a.detector_spacing.as_deref())?,
        filter: a.filter,
        size: a.size,
        spacing: a.spacing,
        no_circle: a.no_circle,
        short_scan: a.short_scan,
        backend: a.backend,
        hardware_filtering: a.hardware_filtering,
        out: Some(a.out.clone()),
        truth: a.truth.clone(),
        error_map: a.error_map.clone(),
        method: a.method,
        iterations: a.iterations,
        subsets: a.subsets,
        subset_order: a.subset_order,
        relaxation: a.relaxation,
        tv_weight: a.tv_weight,
        nonnegative: a.nonnegative,
        init: a.init,
        tolerance: a.tolerance,
        convergence: a.convergence.clone(),
    };
    if a.distributed && a.dry_run {
        let Some(ranks) = a.ranks else {
            return Err(voxlab::Error::invalid(
                "--ranks",
                "--distributed --dry-run plans for a number of ranks: give --ranks N",
            ));
        };
        print!(
            "{}",
            voxlab::jobs::distributed::dry_run(&req, ranks, &Terminal::bars())?
        );
        return Ok(ExitCode::SUCCESS);
    }
    if a.distributed {
        return distributed(&req);
    }
    let term = Terminal::bars();
    if a.dry_run {
        let plan = voxlab::jobs::reconstruct::plan(&req, &term)?;
        drop(term);
        print!("{}", plan.describe());
        return Ok(ExitCode::SUCCESS);
    }
    let r = voxlab::jobs::reconstruct::run(&req, &term)?;
    drop(term);
    if let Some(report) = &r.intensity {
        println!("{}", report.summary());
    }
    let d = r.reconstruction.grid.dims;
    let shape = if d[2] == 1 {
        format!("{}×{} image", d[0], d[1])
    } else {
        format!("{}×{}×{} volume", d[0], d[1], d[2])
    };
    let (lo, hi) = r.value_range();
    match &r.iterative {
        None => println!(
            "wrote {} ({} {}, {} filter, {}; values {lo:.4} … {hi:.4})",
            a.out.display(),
            if r.parallel { "FBP" } else { "FDK" },
            shape,
            a.filter.name(),
            r.what
        ),
        Some(log) => {
            println!(
                "wrote {} ({} {}, {} iterations, {}; values {lo:.4} … {hi:.4})",
                a.out.display(),
                log.method.name().to_uppercase(),
                shape,
                log.iterations,
                r.what
            );
            let first = log.residual.first().copied().unwrap_or(0.0);
            let last = log.residual.last().copied().unwrap_or(0.0);
            println!(
                "residual ‖b − Ax‖: {first:.6e} → {last:.6e}; objective {:.6e}; {:.2} ms per iteration",
                log.objective.last().copied().unwrap_or(0.0),
                log.seconds_per_iteration * 1e3
            );
            if let Some(c) = &a.convergence {
                println!(
                    "wrote {} (residual and objective per iteration)",
                    c.display()
                );
            }
        }
    }
    if let Some(t) = &r.truth {
        println!("RMS error against {}: {:.6}", t.phantom, t.rms);
        if let Some(path) = &a.error_map {
            let hi = t.slice.data.iter().fold(0.0f64, |m, &v| m.max(v));
            println!(
                "wrote {} (|error| of slice {}, white = {hi:.4})",
                path.display(),
                t.slice_index
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// `--distributed`: every rank runs the job; rank 0 shows progress, the errors and the
/// report.
fn distributed(req: &ReconstructRequest) -> Result<ExitCode> {
    super::on_mpi_ranks(
        |comm, progress| voxlab::jobs::distributed::run(req, comm, progress),
        |d| {
            let g = d.grid.dims;
            if let Some(report) = d.intensity() {
                println!("{} (on the ranks' lines)", report.summary());
            }
            let on = match d.ranks.len() {
                1 => "1 rank".to_string(),
                n => format!("{n} ranks"),
            };
            if let Some(log) = &d.iterative {
                let shape = if g[2] == 1 {
                    format!("{}×{} image", g[0], g[1])
                } else {
                    format!("{}×{}×{} volume", g[0], g[1], g[2])
                };
                println!(
                    "wrote {} ({} {shape}, {} iterations, {} on {on}, the views cut among \
                     them; values {:.4} … {:.4})",
                    d.out.display(),
                    log.method.name().to_uppercase(),
                    log.iterations,
                    d.what,
                    d.range.0,
                    d.range.1
                );
                let first = log.residual.first().copied().unwrap_or(0.0);
                let last = log.residual.last().copied().unwrap_or(0.0);
                println!(
                    "residual ‖b − Ax‖: {first:.6e} → {last:.6e}; objective {:.6e}; {:.2} ms \
                     per iteration",
                    log.objective.last().copied().unwrap_or(0.0),
                    log.seconds_per_iteration * 1e3
                );
                print!("{}", d.describe());
                return Ok(());
            }
            println!(
                "wrote {} ({} {}×{}×{} volume, {} filter, {} on {} in slabs along {}; \
                 values {:.4} … {:.4})",
                d.out.display(),
                if d.parallel { "FBP" } else { "FDK" },
                g[0],
                g[1],
                g[2],
                req.filter.name(),
                d.what,
                on,
                if d.axis == 1 { 'j' } else { 'k' },
                d.range.0,
                d.range.1
            );
            print!("{}", d.describe());
            Ok(())
        },
    )
}

/// `--detector-spacing DU[,DV]` as `[du, dv]`.
fn detector_spacing(v: Option<&[f64]>) -> Result<Option<[f64; 2]>> {
    match v {
        None => Ok(None),
        Some(&[du]) => Ok(Some([du, du])),
        Some(&[du, dv]) => Ok(Some([du, dv])),
        Some(other) => Err(voxlab::Error::invalid(
            "--detector-spacing",
            format!("DU or DU,DV (mm), not {} values", other.len()),
        )),
    }
}
