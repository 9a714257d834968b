//! `voxlab project`: forward projections of a phantom (exact line integrals, or
//! Joseph on a sampled grid) or of a volume file (Joseph), written as a projection
//! stack (`.npy`, `.nrrd`, `.nhdr`) with `<out>.geometry.json` beside it.
//! See docs/projection.md.

use crate::{load_input, LoadArgs};
use clap::{Args, ValueEnum};
use std::path::PathBuf;
use voxlab::cpu::project::{project_phantom, project_volume, Grid, ProjectOptions};
use voxlab::ct::{Geometry, Projections};
use voxlab::frame::{Frame, PngOptions};
use voxlab::io::projections::{
    geometry_path, read_angles_txt, write_geometry, write_projections, Layout,
};
use voxlab::{Error, Result};

/// Arguments of `voxlab project`.
#[derive(Args)]
pub struct ProjectArgs {
    /// A volume file (placed as a patient: centred, its z axis on the rotation axis,
    /// its axial slices seen like scikit-image images) or phantom:NAME[:N | :NX,NY,NZ].
    input: String,
    #[command(flatten)]
    load: LoadArgs,
    /// Output projections: .npy (float64 from the cpu backend, else float32), .nrrd or
    /// .nhdr (float32). The geometry goes to <out-stem>.geometry.json beside it.
    #[arg(long)]
    out: PathBuf,
    /// Beam: parallel (scikit-image's radon, stacked along the rotation axis) or cone
    /// (RTK's circular geometry, flat detector).
    #[arg(long, value_enum, default_value = "parallel")]
    geometry: BeamArg,
    /// Number of projections, evenly spread over --range.
    #[arg(long, default_value_t = 180)]
    angles: usize,
    /// Angular range in degrees (default 180 for parallel, 360 for cone).
    #[arg(long)]
    range: Option<f64>,
    /// A text file of angles in degrees, one per line (# comments allowed); replaces
    /// --angles and --range.
    #[arg(long, conflicts_with_all = ["angles", "range"])]
    angles_file: Option<PathBuf>,
    /// Detector columns.
    #[arg(long, default_value_t = 256)]
    cols: usize,
    /// Detector rows (default 1 for parallel: one scikit-image sinogram of the central
    /// slice; 256 for cone).
    #[arg(long)]
    rows: Option<usize>,
    /// Detector column spacing in mm (default 1 for parallel, 1.5 for cone: a 256 mm
    /// field at the isocentre with the default magnification of 1.5).
    #[arg(long)]
    du: Option<f64>,
    /// Detector row spacing in mm (default: --du).
    #[arg(long)]
    dv: Option<f64>,
    /// Cone beam: source–isocentre distance in mm.
    #[arg(long)]
    sid: Option<f64>,
    /// Cone beam: source–detector distance in mm.
    #[arg(long)]
    sdd: Option<f64>,
    /// analytic: exact line integrals of the phantom (phantoms only; the default for
    /// them); joseph: Joseph's method on the voxel grid (the default for files).
    #[arg(long, value_enum)]
    method: Option<MethodArg>,
    /// Who computes Joseph's method: cpu (f64), cpu-f32, or gpu (f32). The analytic
    /// method runs on the CPU in f64 only.
    #[arg(long, value_enum, default_value = "cpu")]
    backend: BackendArg,
    /// File layout: stack (angle, row, col); skimage (detector, angle), one row only;
    /// auto: skimage for a one-row parallel beam, else stack.
    #[arg(long, value_enum, default_value = "auto")]
    layout: LayoutArg,
    /// Also write a picture of the sinogram (of the central detector row): detector
    /// down, angle across, as scikit-image examples show it.
    #[arg(long)]
    png: Option<PathBuf>,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum BeamArg {
    Parallel,
    Cone,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum MethodArg {
    Analytic,
    Joseph,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum BackendArg {
    Cpu,
    CpuF32,
    Gpu,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum LayoutArg {
    Auto,
    Stack,
    Skimage,
}

/// The geometry the options describe.
fn geometry(a: &ProjectArgs) -> Result<Geometry> {
    let cone = a.geometry == BeamArg::Cone;
    if !cone && (a.sid.is_some() || a.sdd.is_some()) {
        return Err(Error::invalid(
            "--sid/--sdd",
            "only a cone beam has a source (add --geometry cone)",
        ));
    }
    let angles_deg = match &a.angles_file {
        Some(f) => read_angles_txt(f)?,
        None => {
            if a.angles == 0 {
                return Err(Error::invalid("--angles", "must be at least 1"));
            }
            if a.angles > voxlab::ct::MAX_DETECTOR {
                return Err(Error::too_large(
                    "--angles",
                    format!("{} (at most {})", a.angles, voxlab::ct::MAX_DETECTOR),
                ));
            }
            let range = a.range.unwrap_or(if cone { 360.0 } else { 180.0 });
            if !range.is_finite() {
                return Err(Error::invalid("--range", "must be finite"));
            }
            Geometry::even_angles(a.angles, range)
        }
    };
    let rows = a.rows.unwrap_or(if cone { 256 } else { 1 });
    let du = a.du.unwrap_or(if cone { 1.5 } else { 1.0 });
    let dv = a.dv.unwrap_or(du);
    if cone {
        Geometry::cone_rtk(
            a.sid.unwrap_or(1000.0),
            a.sdd.unwrap_or(1500.0),
            a.cols,
            rows,
            du,
            dv,
            angles_deg,
        )
    } else {
        Geometry::parallel_stack(a.cols, rows, du, dv, angles_deg)
    }
}

/// Runs `voxlab project`.
pub fn project(a: ProjectArgs) -> Result<()> {
    let ext = a
        .out
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if !matches!(ext.as_deref(), Some("npy" | "nrrd" | "nhdr")) {
        return Err(Error::invalid(
            "--out",
            format!(
                "{}: projections are written as .npy, .nrrd or .nhdr",
                a.out.display()
            ),
        ));
    }
    let g = geometry(&a)?;
    let layout = match a.layout {
        LayoutArg::Stack => Layout::Stack,
        LayoutArg::Skimage => Layout::Skimage,
        LayoutArg::Auto if a.geometry == BeamArg::Parallel && g.rows == 1 => Layout::Skimage,
        LayoutArg::Auto => Layout::Stack,
    };
    if layout == Layout::Skimage && g.rows != 1 {
        return Err(Error::invalid(
            "--layout skimage",
            format!("a (detector, angle) sinogram has one row, not {}", g.rows),
        ));
    }
    let phantom = match a.input.strip_prefix("phantom:") {
        Some(spec) => Some(voxlab::phantom::parse_spec(spec, a.load.phantom_size)?),
        None => None,
    };
    let method = a.method.unwrap_or(if phantom.is_some() {
        MethodArg::Analytic
    } else {
        MethodArg::Joseph
    });

    let pb = crate::progress_bar(g.n_angles() as u64, "projecting", "views");
    let tick = || pb.inc(1);
    let options = ProjectOptions {
        on_view: Some(&tick),
    };

    let (what, p): (String, Projections<f64>) = match method {
        MethodArg::Analytic => {
            let Some((ph, _)) = &phantom else {
                return Err(Error::invalid(
                    "--method analytic",
                    "exact line integrals exist for phantoms only (phantom:NAME); use \
                     --method joseph for a volume file",
                ));
            };
            if a.backend != BackendArg::Cpu {
                return Err(Error::invalid(
                    "--backend",
                    "the analytic projection runs on the CPU in f64 only (drop --backend, or \
                     use --method joseph)",
                ));
            }
            let p = project_phantom(ph, &g)?;
            (format!("{} analytic, cpu f64", ph.name), p)
        }
        MethodArg::Joseph => {
            let (name, grid) = match &phantom {
                Some((ph, dims)) => (
                    format!("{} {}×{}×{}", ph.name, dims[0], dims[1], dims[2]),
                    Grid::<f64>::phantom(ph, *dims)?,
                ),
                None => {
                    let vol = load_input(&a.input, &a.load)?.to_f32();
                    (a.input.clone(), Grid::<f64>::from_volume_patient(&vol)?)
                }
            };
            match a.backend {
                BackendArg::Cpu => (
                    format!("{name} joseph, cpu f64"),
                    project_volume(&grid, &g, &options)?,
                ),
                BackendArg::CpuF32 => {
                    let g32 = Grid::<f32>::new(
                        grid.dims,
                        grid.affine,
                        grid.data.iter().map(|&v| v as f32).collect(),
                    )?;
                    (
                        format!("{name} joseph, cpu f32"),
                        widen(project_volume(&g32, &g, &options)?),
                    )
                }
                BackendArg::Gpu => {
                    let ctx = voxlab::gpu::GpuContext::new()?;
                    let p = voxlab::gpu::project::project_volume(&ctx, &grid, &g, &options)?;
                    (
                        format!("{name} joseph, gpu ({})", ctx.summary.name),
                        widen(p),
                    )
                }
            }
        }
    };
    pb.finish_and_clear();

    if a.backend == BackendArg::Cpu {
        write_projections(&a.out, &p, layout, Some(&g))?;
    } else {
        let p32 = Projections::new(
            p.angles,
            p.rows,
            p.cols,
            p.data.iter().map(|&v| v as f32).collect(),
        )?;
        write_projections(&a.out, &p32, layout, Some(&g))?;
    }
    let gpath = geometry_path(&a.out);
    write_geometry(&gpath, &g)?;
    if let Some(png) = &a.png {
        sinogram_frame(&p).save(png, PngOptions::default())?;
    }
    let peak = p.data.iter().fold(0.0f64, |m, v| m.max(*v));
    let shape = match layout {
        Layout::Stack => format!("(angle, row, col) = ({}, {}, {})", p.angles, p.rows, p.cols),
        Layout::Skimage => format!("(detector, angle) = ({}, {})", p.cols, p.angles),
    };
    println!(
        "wrote {} ({what}; {shape}; max {peak:.4} value × mm) and {}",
        a.out.display(),
        gpath.display()
    );
    Ok(())
}

fn widen(p: Projections<f32>) -> Projections<f64> {
    Projections {
        angles: p.angles,
        rows: p.rows,
        cols: p.cols,
        data: p.data.into_iter().map(f64::from).collect(),
    }
}

/// The sinogram of the central detector row: detector down, angle across.
fn sinogram_frame(p: &Projections<f64>) -> Frame {
    let row = p.rows / 2;
    let mut f = Frame::new(p.angles, p.cols, 1);
    for a in 0..p.angles {
        for d in 0..p.cols {
            f.data[d * p.angles + a] = p.view(a)[row * p.cols + d];
        }
    }
    f
}
