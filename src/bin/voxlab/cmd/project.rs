//! `voxlab project`: CT forward projection to a projection stack and its geometry,
//! through [`voxlab::jobs::project::run`].

use crate::cli::{choice, LoadArgs, Terminal};
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use voxlab::io::projections::Layout;
use voxlab::io::{check_output, write_frame, PngOptions};
use voxlab::jobs::project::{BeamKind, LayoutChoice, Method, ProjectRequest};
use voxlab::jobs::Backend;
use voxlab::{Error, Result};

/// Arguments of `voxlab project`.
#[derive(Args)]
pub struct ProjectArgs {
    /// A volume file (placed as a patient: centred, its z axis on the rotation axis,
    /// its axial slices seen like scikit-image images) or phantom:NAME[:N | :NX,NY,NZ].
    pub input: String,
    #[command(flatten)]
    pub load: LoadArgs,
    /// Output projections: .npy (float64 from the cpu backend, else float32), .nrrd or
    /// .nhdr (float32). The geometry goes to <out-stem>.geometry.json beside it.
    #[arg(long)]
    pub out: PathBuf,
    /// Beam: parallel (scikit-image's radon, stacked along the rotation axis) or cone
    /// (RTK's circular geometry, flat detector).
    #[arg(long, value_parser = choice::<BeamKind>(), default_value = "parallel")]
    pub geometry: BeamKind,
    /// Number of projections, evenly spread over --range.
    #[arg(long, default_value_t = 180)]
    pub angles: usize,
    /// Angular range in degrees (default 180 for parallel, 360 for cone).
    #[arg(long)]
    pub range: Option<f64>,
    /// A text file of angles in degrees, one per line (# comments allowed); replaces
    /// --angles and --range.
    #[arg(long, conflicts_with_all = ["angles", "range"])]
    pub angles_file: Option<PathBuf>,
    /// A geometry file instead of --geometry and the angles: voxlab's geometry JSON
    /// (circular or view by view), ASTRA's proj_geom as JSON or RTK's geometry XML,
    /// told apart by their contents (docs/ct.md). With RTK's XML, --cols, --rows, --du
    /// and --dv give its detector, centred as RTK centres it.
    #[arg(long, conflicts_with_all = ["angles", "range", "angles_file", "sid", "sdd"])]
    pub geometry_file: Option<PathBuf>,
    /// Detector columns.
    #[arg(long, default_value_t = 256)]
    pub cols: usize,
    /// Detector rows (default 1 for parallel: one scikit-image sinogram of the central
    /// slice; 256 for cone).
    #[arg(long)]
    pub rows: Option<usize>,
    /// Detector column spacing in mm (default 1 for parallel, 1.5 for cone: a 256 mm
    /// field at the isocentre with the default magnification of 1.5).
    #[arg(long)]
    pub du: Option<f64>,
    /// Detector row spacing in mm (default: --du).
    #[arg(long)]
    pub dv: Option<f64>,
    /// Cone beam: source–isocentre distance in mm.
    #[arg(long)]
    pub sid: Option<f64>,
    /// Cone beam: source–detector distance in mm.
    #[arg(long)]
    pub sdd: Option<f64>,
    /// analytic: exact line integrals of the phantom (phantoms only; the default for
    /// them); joseph: Joseph's method on the voxel grid (the default for files).
    #[arg(long, value_parser = choice::<Method>())]
    pub method: Option<Method>,
    /// Who computes Joseph's method: cpu (f64), cpu-f32, gpu (f32), or auto. The
    /// analytic method runs on the CPU in f64 only.
    #[arg(long, value_parser = choice::<Backend>(), default_value = "cpu")]
    pub backend: Backend,
    /// GPU Joseph only: the projector samples the grid through the texture unit (a 3-D
    /// texture, hardware trilinear filtering) instead of the exact interpolation
    /// written out in the shader (real GPUs quantise its weights to about 8 bits;
    /// docs/parity.md).
    #[arg(long)]
    pub hardware_filtering: bool,
    /// File layout: stack (angle, row, col); skimage (detector, angle), one row only;
    /// auto: skimage for a one-row parallel beam, else stack.
    #[arg(long, value_parser = choice::<LayoutChoice>(), default_value = "auto")]
    pub layout: LayoutChoice,
    /// Also write a picture of the sinogram (of the central detector row): detector
    /// down, angle across, as scikit-image examples show it.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Print the memory plan (host bytes, device bytes against the adapter's limits,
    /// and the slabs the GPU would use) after checking the geometry, and write nothing.
    #[arg(long)]
    pub dry_run: bool,
}

pub fn run(a: ProjectArgs) -> Result<ExitCode> {
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
    check_output("--out", &a.out, &["npy", "nrrd", "nhdr"])?;
    if let Some(png) = &a.png {
        check_output("--png", png, &["png"])?;
    }
    let req = ProjectRequest {
        input: a.load.input(&a.input),
        beam: a.geometry,
        angles: a.angles,
        range: a.range,
        angles_file: a.angles_file.clone(),
        geometry_file: a.geometry_file.clone(),
        cols: a.cols,
        rows: a.rows,
        du: a.du,
        dv: a.dv,
        sid: a.sid,
        sdd: a.sdd,
        method: a.method,
        backend: a.backend,
        hardware_filtering: a.hardware_filtering,
        layout: a.layout,
    };
    let term = Terminal::bars();
    if a.dry_run {
        let mut plan = voxlab::jobs::project::plan(&req, &term)?;
        drop(term);
        plan.writes.push(a.out.display().to_string());
        plan.writes
            .extend(a.png.iter().map(|p| p.display().to_string()));
        print!("{}", plan.describe());
        return Ok(ExitCode::SUCCESS);
    }
    let p = voxlab::jobs::project::run(&req, &term)?;
    drop(term);
    let gpath = p.write(&a.out)?;
    if let Some(png) = &a.png {
        write_frame(png, &p.sinogram(), PngOptions::default())?;
    }
    let s = &p.projections;
    let peak = s.data.iter().fold(0.0f64, |m, v| m.max(*v));
    let shape = match p.layout {
        Layout::Stack => format!("(angle, row, col) = ({}, {}, {})", s.angles, s.rows, s.cols),
        Layout::Skimage => format!("(detector, angle) = ({}, {})", s.cols, s.angles),
    };
    println!(
        "wrote {} ({}; {shape}; max {peak:.4} value × mm) and {}",
        a.out.display(),
        p.what,
        gpath.display()
    );
    Ok(ExitCode::SUCCESS)
}
