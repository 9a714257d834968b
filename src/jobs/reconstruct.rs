//! `voxlab reconstruct`: filtered backprojection of a projection file, or an
//! iterative method on Joseph's matched pair. A scikit-image sinogram
//! `(detector, angle)` or a parallel stack `(angle, row, col)` gives images in
//! scikit-image's orientation (as `iradon` with `circle=True` by default); a geometry
//! JSON of a cone beam gives FDK (or an iterative volume) on RTK's centred grid. See
//! docs/ct.md and docs/iterative.md; the algorithms are [`crate::cpu::fbp`],
//! [`crate::gpu::fbp`] and [`crate::cpu::iterative`].

use super::plan::{DevicePlan, MemoryPlan};
use super::{Backend, Engine, Progress};
use crate::cpu::fbp::{
    apply_circle_mask, fbp, parallel_stack_grid, rtk_grid, Grid, Reconstruction,
};
use crate::cpu::iterative::MatchedPair;
use crate::cpu::iterative::{IterativeOptions, Method, Problem, SubsetOrder};
use crate::cpu::project::JosephPair;
use crate::cpu::ramp::RampFilter;
use crate::ct::flat_field::{line_integrals, IntensityReport};
use crate::ct::{ct_to_phantom, Beam, Geometry, Lines, Projections, MAX_DETECTOR};
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::gpu::joseph_pair::GpuJosephPair;
use crate::io::projections::{
    geometry_path, read_angles_txt, read_field_image, read_geometry_with, read_projections_grid,
};
use crate::io::rtk_geometry::DetectorGrid;
use crate::io::ReadOptions;
use crate::io::{write_frame, PngOptions};
use crate::phantom::Phantom;
use crate::volume::AnyVolume;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

crate::choice_enum! {
    /// How `voxlab reconstruct` reconstructs.
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
    pub enum ReconstructMethod: "method", default Fbp {
        /// Filtered backprojection (parallel) or Feldkamp (cone): one pass.
        Fbp = "fbp",
        /// SIRT on Joseph's matched pair (ASTRA's and TIGRE's weights).
        Sirt = "sirt",
        /// CGLS: conjugate gradients on the least-squares normal equations.
        Cgls = "cgls",
        /// OS-SART: SIRT's update over ordered subsets of the views.
        OsSart = "os-sart",
        /// Least squares + total variation (Chambolle–Pock).
        Tv = "tv",
    }
}

impl ReconstructMethod {
    /// The iterative method, `None` for FBP/FDK.
    pub fn iterative(self) -> Option<Method> {
        match self {
            ReconstructMethod::Fbp => None,
            ReconstructMethod::Sirt => Some(Method::Sirt),
            ReconstructMethod::Cgls => Some(Method::Cgls),
            ReconstructMethod::OsSart => Some(Method::OsSart),
            ReconstructMethod::Tv => Some(Method::Tv),
        }
    }

    /// The iterations when none are asked for.
    pub fn default_iterations(self) -> usize {
        match self {
            ReconstructMethod::Fbp => 0,
            ReconstructMethod::Sirt => 100,
            ReconstructMethod::Cgls => 30,
            ReconstructMethod::OsSart => 20,
            ReconstructMethod::Tv => 200,
        }
    }
}

crate::choice_enum! {
    /// The image an iterative method starts from.
    #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
    pub enum Init: "initial image", default Zero {
        /// Zero everywhere.
        Zero = "zero",
        /// The FBP/FDK reconstruction (with --filter) on the same grid.
        Fbp = "fbp",
    }
}

/// The `voxlab reconstruct` job.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReconstructRequest {
    /// Projections: any volume format voxlab reads (`.npy` f64 exact; NRRD, MetaImage,
    /// TIFF, NIfTI, DICOM with x, y, z = col, row, angle); 2-D = a scikit-image sinogram
    /// (detector, angle), 3-D = a stack (angle, row, col).
    pub input: PathBuf,
    /// Which 3-D stack to read from an input that holds several (a 4-D NIfTI,
    /// MetaImage or NRRD, a DICOM time series; [`crate::io::ReadOptions::frame`]).
    pub frame: Option<usize>,
    /// The input holds detector intensities: the flat-field image (beam, no object) in
    /// any format the input may be in; a stack of frames is averaged. The projections
    /// become `−ln((I − D)/(F − D))` ([`crate::ct::flat_field`]). `None`: the input holds
    /// line integrals already.
    pub flat: Option<PathBuf>,
    /// With `flat`: the dark-field image (no beam; `None`: 0), as `flat`.
    pub dark: Option<PathBuf>,
    /// `parallel` (scikit-image's geometry; needs `angles`) or a geometry JSON file.
    /// `None`: `<input-stem>.geometry.json` beside the input.
    pub geometry: Option<String>,
    /// With `geometry = parallel`: a text file of angles in degrees (one per line), or
    /// a count N (N angles evenly over 180°).
    pub angles: Option<String>,
    /// With RTK's geometry XML: the detector's pixel spacing `[du, dv]` in mm, the
    /// detector centred on RTK's origin (`−(n − 1)/2 · spacing`), for projections whose
    /// file records no spacing (`.npy`, TIFF); it replaces the spacing and origin of a
    /// MetaImage or NRRD input. `None`: the input's own (RTK's XML has no pixel size).
    pub detector_spacing: Option<[f64; 2]>,
    /// Frequency window of the ramp (scikit-image's names).
    pub filter: RampFilter,
    /// The image is N × N (parallel; `None`: the detector count) or the volume N³
    /// (cone; `None`: the detector columns).
    pub size: Option<usize>,
    /// Voxel spacing in mm (parallel: `None` is the detector spacing; cone: du·SID/SDD).
    pub spacing: Option<f64>,
    /// Parallel beam: no mask to the inscribed circle (scikit-image's circle=False).
    pub no_circle: bool,
    /// Cone beam over less than a full turn: Parker's short-scan weights.
    pub short_scan: bool,
    pub backend: Backend,
    /// GPU FBP/FDK only: the backprojection samples the filtered projections through
    /// the texture unit (a 2-D texture array, hardware bilinear filtering) instead of
    /// the exact interpolation written out in the shader
    /// ([`crate::gpu::plan::Sampling`]). Real GPUs round the filter weights
    /// to about 8 fractional bits (docs/parity.md).
    pub hardware_filtering: bool,
    /// Write the reconstruction here: `.npy` (float32), `.nrrd`/`.nhdr` (the grid's
    /// affine) or `.png` (2-D images only). Checked before the work starts.
    pub out: Option<PathBuf>,
    /// A phantom (`phantom:NAME`) the projections came from: the RMS error against its
    /// exact values at the voxel centres.
    pub truth: Option<String>,
    /// With `truth`: write |reconstruction − truth| of the central slice to this PNG.
    pub error_map: Option<PathBuf>,
    /// FBP/FDK (default) or an iterative method (docs/iterative.md).
    pub method: ReconstructMethod,
    /// Iterative methods: iterations (`None`: sirt 100, cgls 30, os-sart 20, tv 200).
    pub iterations: Option<usize>,
    /// OS-SART: the number of subsets (`None`: 10, or the number of views if fewer).
    pub subsets: Option<usize>,
    /// OS-SART: the order of the subsets.
    pub subset_order: SubsetOrder,
    /// SIRT and OS-SART: the relaxation λ in (0, 2) (`None`: 1).
    pub relaxation: Option<f64>,
    /// TV: the weight of the total variation (`None`:
    /// [`crate::cpu::iterative::DEFAULT_TV_WEIGHT`]).
    pub tv_weight: Option<f64>,
    /// SIRT, OS-SART, TV: keep every voxel ≥ 0.
    pub nonnegative: bool,
    /// Iterative methods: the initial image.
    pub init: Init,
    /// Iterative methods: stop once the objective falls by less than this fraction in
    /// one iteration (0: run every iteration).
    pub tolerance: f64,
    /// Iterative methods: write `iteration,residual,objective` for every iteration to
    /// this CSV file.
    pub convergence: Option<PathBuf>,
}

/// How an iterative reconstruction went.
#[derive(Clone, Debug)]
pub struct IterationLog {
    pub method: Method,
    /// `‖b − A x_k‖` for `k = 0` (the initial image) … the last iteration.
    pub residual: Vec<f64>,
    /// The objective the method decreases, for the same iterates
    /// ([`crate::cpu::iterative::Solution::objective`]).
    pub objective: Vec<f64>,
    pub iterations: usize,
    /// Stopped by the tolerance.
    pub converged: bool,
    /// Wall-clock seconds per iteration (the matched pair's set-up excluded).
    pub seconds_per_iteration: f64,
}

impl IterationLog {
    /// The log as CSV: a header, then `iteration,residual,objective` lines.
    pub fn csv(&self) -> String {
        let mut s = String::from("iteration,residual,objective\n");
        for (k, (r, o)) in self.residual.iter().zip(&self.objective).enumerate() {
            s.push_str(&format!("{k},{r:.9e},{o:.9e}\n"));
        }
        s
    }
}

/// The error against a phantom.
#[derive(Clone, Debug)]
pub struct TruthError {
    pub phantom: String,
    pub rms: f64,
    /// |reconstruction − truth| of the central slice (0 outside the circle), and its
    /// slice index.
    pub slice: Frame,
    pub slice_index: usize,
}

/// A reconstruction and how it was made.
#[derive(Clone, Debug)]
pub struct Reconstructed {
    pub reconstruction: Reconstruction<f64>,
    /// FBP (parallel) or FDK (cone).
    pub parallel: bool,
    /// Who computed it: `cpu f64`, `cpu f32`, `gpu (NAME)`.
    pub what: String,
    pub truth: Option<TruthError>,
    /// Where the geometry came from when it was found beside the input.
    pub geometry_file: Option<PathBuf>,
    /// Iterative methods: residuals and objectives per iteration.
    pub iterative: Option<IterationLog>,
    /// With a flat field: what the conversion of intensities to line integrals did.
    pub intensity: Option<IntensityReport>,
}

/// `angles`: a count (evenly over 180°) or a file.
fn parse_angles(s: &str) -> Result<Vec<f64>> {
    if let Ok(n) = s.trim().parse::<usize>() {
        if n == 0 {
            return Err(Error::invalid("--angles", "must be at least 1"));
        }
        if n > MAX_DETECTOR {
            return Err(Error::too_large(
                "--angles",
                format!("{n} (at most {MAX_DETECTOR})"),
            ));
        }
        return Ok(Geometry::even_angles(n, 180.0));
    }
    read_angles_txt(Path::new(s))
}

/// The detector's pixel grid an RTK geometry XML needs: `detector_spacing` centred
/// when given, else the input's header's (`header`).
fn detector_grid(
    a: &ReconstructRequest,
    [_, rows, cols]: [usize; 3],
    header: Option<&DetectorGrid>,
) -> Result<Option<DetectorGrid>> {
    let Some([du, dv]) = a.detector_spacing else {
        return Ok(header.cloned());
    };
    for (name, s) in [("du", du), ("dv", dv)] {
        if !(s.is_finite() && (crate::ct::MIN_LENGTH_MM..=crate::ct::MAX_LENGTH_MM).contains(&s)) {
            return Err(Error::invalid(
                "--detector-spacing",
                format!(
                    "{name} = {s} mm must be finite and in [{:e}, {:e}] mm",
                    crate::ct::MIN_LENGTH_MM,
                    crate::ct::MAX_LENGTH_MM
                ),
            ));
        }
    }
    Ok(Some(DetectorGrid::centred(cols, rows, du, dv)))
}

/// The geometry of the input, a stack of `shape` (`[angles, rows, cols]`), and the file
/// it was read from when found beside it. `header`: the detector grid the input's file
/// records (MetaImage, NRRD), which an RTK geometry XML takes its pixels from.
pub(super) fn geometry_for(
    a: &ReconstructRequest,
    shape: [usize; 3],
    header: Option<&DetectorGrid>,
) -> Result<(Geometry, Option<PathBuf>)> {
    let [n, rows, cols] = shape;
    let grid = detector_grid(a, shape, header)?;
    let mut beside_file = None;
    let g = match a.geometry.as_deref() {
        Some("parallel") => {
            let Some(angles) = &a.angles else {
                return Err(Error::invalid(
                    "--angles",
                    "--geometry parallel needs the projection angles: --angles FILE.txt \
                     (degrees, one per line) or --angles N (evenly over 180°)",
                ));
            };
            let angles = parse_angles(angles)?;
            if angles.len() != n {
                return Err(Error::invalid(
                    "--angles",
                    format!(
                        "{} angles given, but {} holds {n} projections ({})",
                        angles.len(),
                        a.input.display(),
                        if rows == 1 {
                            format!("a (detector, angle) = ({cols}, {n}) sinogram")
                        } else {
                            format!("(angle, row, col) = ({n}, {rows}, {cols})")
                        }
                    ),
                ));
            }
            let du = a.spacing.unwrap_or(1.0);
            Geometry::parallel_stack(cols, rows, du, du, angles)?
        }
        Some(file) => {
            if a.angles.is_some() {
                return Err(Error::invalid(
                    "--angles",
                    "the geometry file lists the angles (use --angles with --geometry parallel)",
                ));
            }
            read_geometry_with(Path::new(file), grid.as_ref())?
        }
        None => {
            let beside = geometry_path(&a.input);
            if !beside.is_file() {
                return Err(Error::invalid(
                    "--geometry",
                    format!(
                        "no geometry for {}: give --geometry parallel --angles FILE|N, or \
                         --geometry FILE.json (or put {} beside the input)",
                        a.input.display(),
                        beside.display()
                    ),
                ));
            }
            if a.angles.is_some() {
                return Err(Error::invalid(
                    "--angles",
                    "--angles goes with --geometry parallel",
                ));
            }
            let g = read_geometry_with(&beside, grid.as_ref())?;
            beside_file = Some(beside);
            g
        }
    };
    g.check_stack(shape).map_err(|e| match e {
        Error::Invalid { message, .. } => Error::invalid(
            format!("projections {} vs geometry", a.input.display()),
            message,
        ),
        other => other,
    })?;
    Ok((g, beside_file))
}

/// The geometry of iradon's `circle=True` padding (`_sinogram_circle_to_square`) and
/// its width: `ceil(√2·cols)` bins, old bin `cols//2` moved to the new centre (the
/// lines are padded by `padded_centred`).
fn circle_geometry(g: &Geometry) -> (Geometry, usize) {
    let diag = crate::ct::circle_diagonal(g.cols);
    let mut g2 = g.clone();
    let shift = (diag / 2 - g.cols / 2) as f64;
    g2.cols = diag;
    g2.cu = g.cu + shift;
    // Views given by vectors: old column c is new column c + shift.
    if let Some(views) = &mut g2.views {
        for v in views {
            v.pixel00 -= v.u * shift;
        }
    }
    (g2, diag)
}

/// The `.npy` shape a reconstruction is written in: `(ny, nx)` for one slice, else
/// `(nz, ny, nx)`.
pub(super) fn npy_shape(d: [usize; 3]) -> Vec<usize> {
    if d[2] == 1 {
        vec![d[1], d[0]]
    } else {
        vec![d[2], d[1], d[0]]
    }
}

pub(super) fn extension(p: &Path) -> Option<String> {
    p.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
}

/// The options checked before any input is read: the outputs, the truth phantom and
/// the spacing.
pub(super) fn check_request(a: &ReconstructRequest) -> Result<Option<Phantom>> {
    check_flat_dark(a)?;
    if let Some(out) = &a.out {
        crate::io::check_output("--out", out, &["npy", "nrrd", "nhdr", "png"])?;
    }
    if let Some(e) = &a.error_map {
        if a.truth.is_none() {
            return Err(Error::invalid("--error-map", "needs --truth phantom:NAME"));
        }
        crate::io::check_output("--error-map", e, &["png"])?;
    }
    let truth = match &a.truth {
        Some(t) => {
            let spec = t
                .strip_prefix("phantom:")
                .ok_or_else(|| Error::invalid("--truth", format!("'{t}': give phantom:NAME")))?;
            Some(crate::phantom::parse_spec(spec, 64)?.0)
        }
        None => None,
    };
    if let Some(s) = a.spacing {
        if !(s.is_finite() && s > 0.0) {
            return Err(Error::invalid(
                "--spacing",
                "must be a positive number of mm",
            ));
        }
    }
    if a.hardware_filtering {
        if a.method != ReconstructMethod::Fbp {
            return Err(Error::invalid(
                "--hardware-filtering",
                "samples the FBP/FDK backprojection's projections: not for an iterative \
                 --method",
            ));
        }
        if a.backend != Backend::Gpu {
            return Err(Error::invalid(
                "--hardware-filtering",
                "is the GPU's texture unit: give --backend gpu",
            ));
        }
    }
    if a.method == ReconstructMethod::Fbp {
        let given = [
            ("--iterations", a.iterations.is_some()),
            ("--subsets", a.subsets.is_some()),
            ("--subset-order", a.subset_order != SubsetOrder::Sequential),
            ("--relaxation", a.relaxation.is_some()),
            ("--tv-weight", a.tv_weight.is_some()),
            ("--nonnegative", a.nonnegative),
            ("--init", a.init != Init::Zero),
            ("--tolerance", a.tolerance != 0.0),
            ("--convergence", a.convergence.is_some()),
        ];
        if let Some((flag, _)) = given.iter().find(|(_, g)| *g) {
            return Err(Error::invalid(
                *flag,
                "goes with an iterative --method (sirt, cgls, os-sart, tv)",
            ));
        }
    } else {
        if a.short_scan {
            return Err(Error::invalid(
                "--short-scan",
                "Parker's weights are for FDK: an iterative method handles a short scan \
                 as it is",
            ));
        }
        if let Some(c) = &a.convergence {
            crate::io::check_output("--convergence", c, &["csv"])?;
        }
        let method = a.method.iterative().unwrap_or_default();
        let only = |flag: &str, ok: bool, which: &str| -> Result<()> {
            if ok {
                Ok(())
            } else {
                Err(Error::invalid(flag, format!("goes with --method {which}")))
            }
        };
        only(
            "--subsets",
            a.subsets.is_none() || method == Method::OsSart,
            "os-sart",
        )?;
        only(
            "--subset-order",
            a.subset_order == SubsetOrder::Sequential || method == Method::OsSart,
            "os-sart",
        )?;
        only(
            "--relaxation",
            a.relaxation.is_none() || matches!(method, Method::Sirt | Method::OsSart),
            "sirt or os-sart",
        )?;
        only(
            "--tv-weight",
            a.tv_weight.is_none() || method == Method::Tv,
            "tv",
        )?;
    }
    Ok(truth)
}

/// Reconstructs (and writes `out` and `error_map` when given).
///
/// # Errors
/// Bad options, projections or geometry; an output the result cannot be written as;
/// GPU errors; [`Error::Cancelled`].
pub fn run(a: &ReconstructRequest, progress: &dyn Progress) -> Result<Reconstructed> {
    check_request(a)?;
    let (p, intensity, header) = read_input(a)?;
    let (g, geometry_file) = geometry_for(a, [p.angles, p.rows, p.cols], header.as_ref())?;
    if let Some(f) = &geometry_file {
        progress.note(&format!("using the geometry {}", f.display()));
    }
    let mut done = reconstruct(a, p, g, geometry_file, progress)?;
    done.intensity = intensity;
    Ok(done)
}

/// The request's projections as line integrals: the input read (its `frame`), and with
/// `flat` (and `dark`) converted from intensities by [`line_integrals`], with the
/// report of that conversion, and the detector grid the input's header records
/// (MetaImage, NRRD; for RTK's geometry XML).
///
/// # Errors
/// The readers' errors; flat or dark images that do not match the projections' rows ×
/// cols (naming the file); `dark` without `flat`.
#[allow(clippy::type_complexity)]
pub fn read_input(
    a: &ReconstructRequest,
) -> Result<(
    Projections<f64>,
    Option<IntensityReport>,
    Option<DetectorGrid>,
)> {
    check_flat_dark(a)?;
    let options = ReadOptions {
        frame: a.frame,
        ..Default::default()
    };
    let (p, header) = read_projections_grid::<f64>(&a.input, &options)?;
    let Some((f, d)) = read_fields(a, p.rows, p.cols)? else {
        return Ok((p, None, header));
    };
    let (p, report) = line_integrals(&p, &f, d.as_deref())?;
    Ok((p, Some(report), header))
}

/// The request's flat image and dark image (`None`: no `flat`), each averaged over its
/// frames ([`read_field_image`]) for projections of `rows × cols` pixels.
///
/// # Errors
/// As [`read_field_image`]; `dark` without `flat`.
#[allow(clippy::type_complexity)]
pub fn read_fields(
    a: &ReconstructRequest,
    rows: usize,
    cols: usize,
) -> Result<Option<(Vec<f64>, Option<Vec<f64>>)>> {
    check_flat_dark(a)?;
    let Some(flat) = &a.flat else {
        return Ok(None);
    };
    let fields = ReadOptions::default();
    let f = read_field_image(flat, "flat", rows, cols, &fields)?;
    let d = match &a.dark {
        Some(dark) => Some(read_field_image(dark, "dark", rows, cols, &fields)?),
        None => None,
    };
    Ok(Some((f, d)))
}

/// `dark` goes with `flat`.
fn check_flat_dark(a: &ReconstructRequest) -> Result<()> {
    if a.dark.is_some() && a.flat.is_none() {
        return Err(Error::invalid(
            "--dark",
            "goes with --flat: intensities need the flat field (the dark field alone \
             gives no line integrals)",
        ));
    }
    Ok(())
}

/// Reconstructs projections already in memory with their geometry: what [`run`] does
/// once it has read the input (the request's `input`, `geometry` and `angles` are not
/// used; `geometry_file` is only reported back). A scikit-image sinogram
/// `(detector, angle)` is the one-row stack of [`Geometry::parallel_skimage`].
///
/// # Errors
/// As [`run`]; projections that do not fit the geometry.
pub fn reconstruct(
    a: &ReconstructRequest,
    p: Projections<f64>,
    g: Geometry,
    geometry_file: Option<PathBuf>,
    progress: &dyn Progress,
) -> Result<Reconstructed> {
    let truth = check_request(a)?;
    p.check_against(&g)?;
    if let Some(method) = a.method.iterative() {
        return iterative(a, method, p, g, geometry_file, truth, progress);
    }
    let parallel = g.beam == Beam::Parallel;
    let (grid, p, g) = fbp_problem(a, p, g, progress)?;
    super::check_cancel(progress)?;
    progress.begin("reconstructing", "voxel lines", 0);
    let t = std::time::Instant::now();
    let engine = Engine::open(a.backend)?;
    let (mut rec, what): (Reconstruction<f64>, String) = super::cancellable(progress, |cp| {
        let rows = |done, total| cp.advance(done, total);
        Ok(match (engine.backend(), engine.gpu()) {
            (Backend::Gpu, Some(ctx)) => {
                let mut p32 = p.narrow()?;
                if a.short_scan {
                    p32 = crate::gpu::parker::weigh(ctx, &p32, &g)?;
                }
                let ramp = crate::gpu::ramp::RampPlan::new(&ctx.limits, &g)?;
                let plan = backprojection_plan(a, ctx, &g, &grid)?;
                for line in gpu_split_lines(&ramp, &plan, g.n_angles()) {
                    progress.note(&line);
                }
                let q = crate::gpu::ramp::filter_projections(ctx, &p32, &g, a.filter)?;
                let r = crate::gpu::fbp::backproject_planned(ctx, &q, &g, &grid, &plan)?;
                let how = if a.hardware_filtering {
                    ", projections filtered by the texture unit"
                } else {
                    ""
                };
                (widen(r), format!("gpu ({}){how}", ctx.summary.name))
            }
            (Backend::CpuF32, _) => {
                let mut p32 = p.narrow()?;
                if a.short_scan {
                    p32 = crate::cpu::parker::weigh(&p32, &g)?;
                }
                (
                    widen(fbp(&p32, &g, a.filter, &grid, &rows)?),
                    "cpu f32".into(),
                )
            }
            _ => {
                let p = if a.short_scan {
                    crate::cpu::parker::weigh(&p, &g)?
                } else {
                    p
                };
                (fbp(&p, &g, a.filter, &grid, &rows)?, "cpu f64".into())
            }
        })
    })?;
    progress.end(t.elapsed().as_secs_f64());
    if parallel && !a.no_circle {
        apply_circle_mask(&mut rec)?;
    }
    let truth = truth.map(|ph| truth_error(&rec, &ph, parallel && !a.no_circle));
    let done = Reconstructed {
        reconstruction: rec,
        parallel,
        what,
        truth,
        geometry_file,
        iterative: None,
        intensity: None,
    };
    finish(a, done)
}

/// The grid of an FBP/FDK job and the projections it backprojects: the grid from the
/// unpadded sinogram (padding keeps rows, spacing and centre), then a parallel
/// sinogram padded to the inscribed circle's diagonal unless `no_circle`; a short scan
/// checked before any work.
fn fbp_problem(
    a: &ReconstructRequest,
    p: Projections<f64>,
    g: Geometry,
    progress: &dyn Progress,
) -> Result<(Grid, Projections<f64>, Geometry)> {
    let grid = fbp_grid(a, &g, progress)?;
    let (p, g) = fbp_projections(a, p, g)?;
    Ok((grid, p, g))
}

/// The grid of an FBP/FDK job, checked against the voxel limit and the output.
pub(super) fn fbp_grid(
    a: &ReconstructRequest,
    g: &Geometry,
    progress: &dyn Progress,
) -> Result<Grid> {
    let grid = reconstruction_grid(a, g, progress)?;
    check_grid(a, &grid, g.beam == Beam::Parallel, g.rows)?;
    Ok(grid)
}

/// The FBP/FDK job `--init fbp` runs first: `a`'s input, geometry, grid, filter and
/// backend, no outputs and none of the iterative options.
pub(super) fn init_request(a: &ReconstructRequest) -> ReconstructRequest {
    ReconstructRequest {
        method: ReconstructMethod::Fbp,
        out: None,
        truth: None,
        error_map: None,
        convergence: None,
        iterations: None,
        subsets: None,
        subset_order: SubsetOrder::Sequential,
        relaxation: None,
        tv_weight: None,
        nonnegative: false,
        init: Init::Zero,
        tolerance: 0.0,
        ..a.clone()
    }
}

/// The projections an FBP/FDK job backprojects and their geometry: a parallel sinogram
/// padded to the inscribed circle's diagonal unless `no_circle`; a short scan checked.
pub(super) fn fbp_projections(
    a: &ReconstructRequest,
    p: Projections<f64>,
    g: Geometry,
) -> Result<(Projections<f64>, Geometry)> {
    Ok(match fbp_geometry(a, g)? {
        (g, Some(diag)) => (p.padded_centred(diag), g),
        (g, None) => (p, g),
    })
}

/// [`fbp_projections`] of some lines of the stack (a distributed rank's).
pub(super) fn fbp_lines(
    a: &ReconstructRequest,
    p: Lines<f64>,
    g: Geometry,
) -> Result<(Lines<f64>, Geometry)> {
    Ok(match fbp_geometry(a, g)? {
        (g, Some(diag)) => (p.padded_centred(diag), g),
        (g, None) => (p, g),
    })
}

/// The geometry [`fbp_projections`] gives and the width its lines are padded to, if
/// they are.
fn fbp_geometry(a: &ReconstructRequest, g: Geometry) -> Result<(Geometry, Option<usize>)> {
    let (g, pad) = if g.beam == Beam::Parallel && !a.no_circle {
        let (g, diag) = circle_geometry(&g);
        (g, Some(diag))
    } else {
        (g, None)
    };
    if a.short_scan {
        // A clear error for a parallel beam or a wrong span.
        crate::cpu::parker::short_scan(&g)?;
    }
    Ok((g, pad))
}

/// `voxlab reconstruct --dry-run`: the memory plan of [`run`] — host bytes, device
/// bytes against the planner's limits and the split the GPU backprojection would use —
/// after reading the input and checking the request, without reconstructing or
/// writing anything.
///
/// # Errors
/// As [`run`] up to the work; [`Error::TooLarge`] for a job that cannot fit even
/// split.
pub fn plan(a: &ReconstructRequest, progress: &dyn Progress) -> Result<MemoryPlan> {
    check_request(a)?;
    let (p, _, header) = read_input(a)?;
    let (g, _) = geometry_for(a, [p.angles, p.rows, p.cols], header.as_ref())?;
    plan_of(a, p, g, progress)
}

/// The memory plan of [`reconstruct`] on projections in hand (the Python module's
/// `reconstruct(…, dry_run=True)`): as [`plan`] after its reading.
///
/// # Errors
/// As [`reconstruct`] up to the work; [`Error::TooLarge`] for a job that cannot fit
/// even split.
pub fn plan_of(
    a: &ReconstructRequest,
    p: Projections<f64>,
    g: Geometry,
    progress: &dyn Progress,
) -> Result<MemoryPlan> {
    check_request(a)?;
    p.check_against(&g)?;
    let mut writes: Vec<String> = a.out.iter().map(|o| o.display().to_string()).collect();
    writes.extend(a.error_map.iter().map(|o| o.display().to_string()));
    writes.extend(a.convergence.iter().map(|o| o.display().to_string()));
    let read = (p.data.len() * 8) as u64;
    if let Some(method) = a.method.iterative() {
        let grid = reconstruction_grid(a, &g, progress)?;
        check_grid(a, &grid, g.beam == Beam::Parallel, g.rows)?;
        iterative_options(a, method, g.n_angles())?;
        let voxels = grid.dims.iter().product::<usize>() as u64;
        // The projections and their residual, the image and the solver's vectors
        // (SIRT/CGLS/OS-SART keep three image-sized ones, TV its dual field too).
        let vectors = if method == Method::Tv { 7 } else { 4 };
        let host = 2 * read + vectors * voxels * 8;
        let mut split = Vec::new();
        let (backend, device) = match a.backend {
            Backend::Gpu => {
                let engine = Engine::open(Backend::Gpu)?;
                let ctx = engine
                    .gpu()
                    .ok_or_else(|| Error::NoAdapter(NO_GPU.into()))?;
                let rays = (p.data.len() * 4) as u64;
                let largest = rays.max(voxels * 4 * if method == Method::Tv { 3 } else { 1 });
                let pair = crate::gpu::joseph_pair::PairPlan::new(&ctx.limits, grid.dims, &g)?;
                let dev = if !crate::gpu::iterative::fits(&pair, grid.dims, method, &ctx.limits) {
                    // The pair in pieces, the iterations on the host (in f32).
                    split.push(format!("GPU iterative: {}", pair.describe()));
                    let bytes = pair.device_bytes(grid.dims, &g);
                    let piece = (pair.slabs.per_piece * grid.dims[0] * grid.dims[1])
                        .max(pair.views.per_piece * g.rows * g.cols)
                        as u64
                        * 4;
                    DevicePlan::on(ctx, bytes, piece)
                } else {
                    DevicePlan::on(ctx, 2 * rays + vectors * voxels * 4, largest)
                };
                (format!("gpu ({})", ctx.summary.name), Some(dev))
            }
            Backend::CpuF32 => ("cpu f32".into(), None),
            _ => ("cpu f64".into(), None),
        };
        return Ok(MemoryPlan {
            job: format!("reconstruct {method:?}").to_lowercase(),
            backend,
            host_bytes: host,
            device,
            split,
            writes,
        });
    }
    let (grid, p, g) = fbp_problem(a, p, g, progress)?;
    let values = p.data.len() as u64;
    let voxels = grid.dims.iter().product::<usize>() as u64;
    let padded = if values * 8 != read { values * 8 } else { 0 };
    let method = match g.beam {
        Beam::Parallel => "fbp",
        Beam::Cone { .. } => "fdk",
    };
    let engine = Engine::open(a.backend)?;
    let (backend, host, device, split) = match (engine.backend(), engine.gpu()) {
        (Backend::Gpu, Some(ctx)) => {
            let ramp = crate::gpu::ramp::RampPlan::new(&ctx.limits, &g)?;
            let bp = backprojection_plan(a, ctx, &g, &grid)?;
            let split = gpu_split_lines(&ramp, &bp, g.n_angles());
            let largest = (bp.slabs.per_piece * grid.dims[0] * grid.dims[1] * 4) as u64;
            let view_bytes = crate::gpu::fbp::view_texels(bp.sampling, &g) as u64 * 4;
            let largest = largest.max(bp.batches.per_piece as u64 * view_bytes);
            let device = DevicePlan::on(ctx, ramp.device_bytes.max(bp.device_bytes), largest);
            // f64 input (and its padded copy), f32 copy and filtered f32, the f32
            // result and its f64 widening.
            let host = read + padded + values * 8 + voxels * 12;
            (
                format!("gpu ({})", ctx.summary.name),
                host,
                Some(device),
                split,
            )
        }
        (Backend::CpuF32, _) => (
            "cpu f32".to_string(),
            read + padded + values * 8 + voxels * 12,
            None,
            Vec::new(),
        ),
        _ => (
            "cpu f64".to_string(),
            read + padded + values * 8 + voxels * 8,
            None,
            Vec::new(),
        ),
    };
    Ok(MemoryPlan {
        job: format!("reconstruct {method}"),
        backend,
        host_bytes: host,
        device,
        split,
        writes,
    })
}

/// The GPU backprojection's plan for `a` (its sampling from `--hardware-filtering`)
/// under the context's limits.
fn backprojection_plan(
    a: &ReconstructRequest,
    ctx: &crate::gpu::GpuContext,
    g: &Geometry,
    grid: &Grid,
) -> Result<crate::gpu::fbp::BackprojectionPlan> {
    use crate::gpu::fbp::BackprojectionPlan;
    use crate::gpu::plan::Sampling;
    let sampling = if a.hardware_filtering {
        Sampling::Hardware
    } else {
        Sampling::Exact
    };
    // Here too, so that `--dry-run` refuses what the run would.
    ctx.require_filtering(sampling, wgpu::TextureFormat::R32Float)?;
    BackprojectionPlan::sampled(&ctx.limits, g, grid, sampling)
}

/// The lines a split GPU FBP/FDK prints (none when it runs in one piece).
fn gpu_split_lines(
    ramp: &crate::gpu::ramp::RampPlan,
    bp: &crate::gpu::fbp::BackprojectionPlan,
    views: usize,
) -> Vec<String> {
    let mut split = Vec::new();
    let chunks = ramp.chunks(views);
    if chunks > 1 {
        split.push(format!(
            "ramp filter in {} of {}",
            crate::gpu::plan::count_of(chunks, "chunk"),
            crate::gpu::plan::count_of(ramp.views_per_chunk, "view")
        ));
    }
    if bp.is_split() {
        split.push(bp.describe());
    }
    split
}

/// Why a GPU plan has no device.
const NO_GPU: &str = "the GPU backend opened no device";

/// Writes what the request asks for (`out`, `error_map`, `convergence`).
fn finish(a: &ReconstructRequest, done: Reconstructed) -> Result<Reconstructed> {
    if let Some(out) = &a.out {
        done.write(out)?;
    }
    if let (Some(path), Some(log)) = (&a.convergence, &done.iterative) {
        let text = log.csv();
        crate::io::write_atomic(path, |w| {
            w.write_all(text.as_bytes())
                .map_err(|e| Error::io(path.clone(), e))
        })?;
    }
    if let (Some(path), Some(t)) = (&a.error_map, &done.truth) {
        let hi = t.slice.data.iter().fold(0.0f64, |m, &v| m.max(v));
        write_frame(
            path,
            &t.slice,
            PngOptions {
                range: Some((0.0, hi.max(1e-12))),
                ..Default::default()
            },
        )?;
    }
    Ok(done)
}

/// The grid a reconstruction fills (from the unpadded geometry): parallel,
/// `n × n × rows` voxels centred like scikit-image's (`n` = `size` or the detector
/// count); cone, RTK's centred `N³`
/// grid (a source inside it refused, in its corners a warning).
fn reconstruction_grid(
    a: &ReconstructRequest,
    g: &Geometry,
    progress: &dyn Progress,
) -> Result<Grid> {
    match g.beam {
        Beam::Parallel => {
            let n = a.size.unwrap_or(g.cols);
            check_size(n, 1 << 14)?;
            Ok(scaled_parallel_grid(n, g, a.spacing.unwrap_or(g.du)))
        }
        Beam::Cone { sid, sdd } => {
            if a.no_circle {
                return Err(Error::invalid(
                    "--no-circle",
                    "the circle mask is for parallel-beam images only",
                ));
            }
            let n = a.size.unwrap_or(g.cols);
            check_size(n, 2048)?;
            let s = a.spacing.unwrap_or(g.du * sid / sdd);
            let grid = rtk_grid([n; 3], [s; 3]);
            if let Some(w) = g.check_source_outside(
                grid.affine,
                grid.dims,
                "geometry sid",
                "the reconstruction grid",
            )? {
                progress.warn(&w);
            }
            Ok(grid)
        }
    }
}

/// The grid's size against the voxel limit, and the output's kind against the grid.
fn check_grid(a: &ReconstructRequest, grid: &Grid, parallel: bool, rows: usize) -> Result<()> {
    let total = grid.dims.iter().product::<usize>();
    if total > crate::volume::max_voxels() {
        return Err(Error::too_large(
            "--size",
            format!(
                "{}×{}×{} voxels (limit {})",
                grid.dims[0],
                grid.dims[1],
                grid.dims[2],
                crate::volume::max_voxels()
            ),
        ));
    }
    if let Some(out) = &a.out {
        let png = extension(out).as_deref() == Some("png");
        if !parallel && png {
            return Err(Error::invalid(
                "--out",
                "a cone-beam reconstruction is a volume: write .npy or .nrrd (a .png is for a \
                 2-D image)",
            ));
        }
        if parallel && rows > 1 && png {
            return Err(Error::invalid(
                "--out",
                format!("{rows} detector rows give a stack of {rows} images: write .npy or .nrrd"),
            ));
        }
    }
    Ok(())
}

/// The inscribed disc of every z-slice ([`apply_circle_mask`]'s rule) as a support.
pub(super) fn circle_support(dims: [usize; 3]) -> Vec<bool> {
    let r = (dims[0] / 2) as i64;
    (0..dims.iter().product::<usize>())
        .map(|idx| {
            let (i, j) = (
                (idx % dims[0]) as i64 - r,
                ((idx / dims[0]) % dims[1]) as i64 - r,
            );
            i * i + j * j <= r * r
        })
        .collect()
}

/// What one precision's solve gives back: the image in f64, and its log.
type Solved = (Vec<f64>, IterationLog);

/// [`crate::cpu::iterative::solve`] in precision `R`, reporting every iteration.
fn solve_in<R: crate::real::Real>(
    pair: &dyn MatchedPair<R>,
    b: &[f64],
    support: Option<&[bool]>,
    x0: &[f64],
    opts: &IterativeOptions,
    progress: &dyn Progress,
) -> Result<Solved> {
    let b: Vec<R> = b.iter().map(|&v| R::of(v)).collect();
    let x0: Vec<R> = x0.iter().map(|&v| R::of(v)).collect();
    let prob = Problem {
        pair,
        b: &b,
        support,
    };
    let total = opts.iterations as u64;
    let mut hook = |it: usize, _: &[R], _: f64| {
        progress.advance(it as u64, total);
        super::check_cancel(progress)
    };
    let t = std::time::Instant::now();
    let sol = crate::cpu::iterative::solve(&prob, x0, opts, &mut hook)?;
    Ok(solved(opts, sol, t.elapsed().as_secs_f64()))
}

/// The image in f64 and the log of a solution that took `secs`.
pub(super) fn solved<R: crate::real::Real>(
    opts: &IterativeOptions,
    sol: crate::cpu::iterative::Solution<R>,
    secs: f64,
) -> Solved {
    (
        sol.x.iter().map(|v| v.f64()).collect(),
        IterationLog {
            method: opts.method,
            residual: sol.residual,
            objective: sol.objective,
            iterations: sol.iterations,
            converged: sol.converged,
            seconds_per_iteration: secs / sol.iterations.max(1) as f64,
        },
    )
}

/// [`crate::gpu::iterative::solve`]: the whole iteration on the device, reporting
/// every batch of iterations.
fn solve_on_device(
    pair: &GpuJosephPair,
    b: &[f64],
    support: Option<&[bool]>,
    x0: &[f64],
    opts: &IterativeOptions,
    progress: &dyn Progress,
) -> Result<Solved> {
    let b: Vec<f32> = b.iter().map(|&v| v as f32).collect();
    let x0: Vec<f32> = x0.iter().map(|&v| v as f32).collect();
    let total = opts.iterations as u64;
    let mut hook = |it: usize, _: f64| {
        progress.advance(it as u64, total);
        super::check_cancel(progress)
    };
    let t = std::time::Instant::now();
    let batch = crate::gpu::iterative::Batch::Auto;
    let (sol, _) = crate::gpu::iterative::solve(pair, &b, support, &x0, opts, batch, &mut hook)?;
    Ok(solved(opts, sol, t.elapsed().as_secs_f64()))
}

/// The options of an iterative `method` on `n_views` views, the request's defaults
/// filled in, checked.
///
/// # Errors
/// [`Error::Invalid`] naming the option.
pub(super) fn iterative_options(
    a: &ReconstructRequest,
    method: Method,
    n_views: usize,
) -> Result<IterativeOptions> {
    let opts = IterativeOptions {
        method,
        iterations: a.iterations.unwrap_or(a.method.default_iterations()),
        subsets: a.subsets.unwrap_or(10.min(n_views)),
        order: a.subset_order,
        relaxation: a.relaxation.unwrap_or(1.0),
        tv_weight: a
            .tv_weight
            .unwrap_or(crate::cpu::iterative::DEFAULT_TV_WEIGHT),
        nonnegative: a.nonnegative,
        tolerance: a.tolerance,
    };
    opts.check(n_views)?;
    Ok(opts)
}

/// The iterative path of [`reconstruct`]: the same grids as FBP/FDK (parallel: the
/// `n × n` image per detector row, supported on the inscribed disc unless
/// `no_circle`; cone: RTK's centred grid), Joseph's matched pair, and `method`.
fn iterative(
    a: &ReconstructRequest,
    method: Method,
    p: Projections<f64>,
    g: Geometry,
    geometry_file: Option<PathBuf>,
    truth: Option<Phantom>,
    progress: &dyn Progress,
) -> Result<Reconstructed> {
    // `auto` takes the f64 oracle; the GPU pair runs only when asked for.
    let backend = match a.backend {
        Backend::Auto => Backend::Cpu,
        b => b,
    };
    let parallel = g.beam == Beam::Parallel;
    let grid = reconstruction_grid(a, &g, progress)?;
    check_grid(a, &grid, parallel, g.rows)?;
    let support = (parallel && !a.no_circle).then(|| circle_support(grid.dims));
    let opts = iterative_options(a, method, g.n_angles())?;
    let iterations = opts.iterations;
    let x0 = match a.init {
        Init::Zero => vec![0.0; grid.dims.iter().product()],
        Init::Fbp => {
            reconstruct(&init_request(a), p.clone(), g.clone(), None, progress)?
                .reconstruction
                .data
        }
    };
    super::check_cancel(progress)?;
    let engine = Engine::open(backend)?;
    progress.begin(
        &format!("{} iterations", method.name()),
        "iterations",
        iterations as u64,
    );
    let t = std::time::Instant::now();
    let s = support.as_deref();
    let (dims, affine) = (grid.dims, grid.affine);
    let ((data, log), what) = match (engine.backend(), engine.gpu()) {
        (Backend::Gpu, Some(ctx)) => {
            let pair = GpuJosephPair::new(ctx, dims, affine, &g)?;
            let name = &ctx.summary.name;
            if crate::gpu::iterative::fits_on_device(&pair, method) {
                (
                    solve_on_device(&pair, &p.data, s, &x0, &opts, progress)?,
                    format!("gpu ({name}), f32"),
                )
            } else {
                // Past one binding: the pair in pieces, the iterations on the host.
                let plan = pair.plan().describe();
                progress.note(&format!("GPU iterative: {plan}"));
                (
                    solve_in::<f32>(&pair, &p.data, s, &x0, &opts, progress)?,
                    format!("gpu ({name}), f32, {plan}"),
                )
            }
        }
        (Backend::CpuF32, _) => {
            let pair = JosephPair::<f32>::new(dims, affine, &g)?;
            (
                solve_in::<f32>(&pair, &p.data, s, &x0, &opts, progress)?,
                "cpu f32".to_string(),
            )
        }
        _ => {
            let pair = JosephPair::<f64>::new(dims, affine, &g)?;
            (
                solve_in::<f64>(&pair, &p.data, s, &x0, &opts, progress)?,
                "cpu f64".to_string(),
            )
        }
    };
    progress.end(t.elapsed().as_secs_f64());
    if log.converged {
        progress.note(&format!(
            "stopped after {} iterations: the objective fell by less than {} in the last",
            log.iterations, a.tolerance
        ));
    }
    let rec = Reconstruction { grid, data };
    let truth = truth.map(|ph| truth_error(&rec, &ph, parallel && !a.no_circle));
    finish(
        a,
        Reconstructed {
            reconstruction: rec,
            parallel,
            what,
            truth,
            geometry_file,
            iterative: Some(log),
            intensity: None,
        },
    )
}

impl Reconstructed {
    /// Writes the reconstruction by extension: `.npy` (float32; `(n, n)`,
    /// `(rows, n, n)` or `(N, N, N)`), `.png` (a 2-D image, windowed to its value
    /// range), else a volume file with the grid's affine (mm in the CT frame).
    ///
    /// # Errors
    /// I/O errors; a `.png` of a volume.
    pub fn write(&self, out: &Path) -> Result<()> {
        let rec = &self.reconstruction;
        let d = rec.grid.dims;
        match extension(out).as_deref() {
            Some("npy") => {
                let values: Vec<f32> = rec.data.iter().map(|&v| v as f32).collect();
                crate::io::npy::write_npy_f32(out, &npy_shape(d), &values)
            }
            Some("png") => {
                if d[2] != 1 {
                    return Err(Error::invalid(
                        "--out",
                        "a volume is written as .npy or .nrrd (a .png is for a 2-D image)",
                    ));
                }
                let mut f = Frame::new(d[0], d[1], 1);
                f.data = rec.data.clone();
                write_frame(out, &f, PngOptions::default())
            }
            _ => crate::io::write_volume(out, &AnyVolume::from(rec.to_volume()?)),
        }
    }

    /// The smallest and largest value.
    pub fn value_range(&self) -> (f64, f64) {
        self.reconstruction
            .data
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                (l.min(v), h.max(v))
            })
    }
}

/// A parallel grid of `n × n × rows` voxels of `s` mm, centred like scikit-image's.
fn scaled_parallel_grid(n: usize, g: &Geometry, s: f64) -> Grid {
    let mut h = g.clone();
    h.du = s;
    parallel_stack_grid(n, &h)
}

fn check_size(n: usize, max: usize) -> Result<()> {
    if n == 0 {
        return Err(Error::invalid("--size", "must be at least 1"));
    }
    if n > max {
        return Err(Error::too_large("--size", format!("{n} (at most {max})")));
    }
    Ok(())
}

/// The RMS of `rec − truth` over the voxels (inside the circle when `circle`), and
/// `|rec − truth|` over the central slice (0 outside the circle).
fn truth_error(rec: &Reconstruction<f64>, ph: &Phantom, circle: bool) -> TruthError {
    let d = rec.grid.dims;
    let r = (d[0] / 2) as i64;
    let mut errs = vec![0.0; rec.data.len()];
    let (mut sum, mut count) = (0.0, 0usize);
    for k in 0..d[2] {
        for j in 0..d[1] {
            for i in 0..d[0] {
                let (x, y) = (i as i64 - r, j as i64 - r);
                if circle && x * x + y * y > r * r {
                    continue;
                }
                let t = ph.value_world(ct_to_phantom(rec.grid.point(i, j, k)));
                let e = rec.get(i, j, k) - t;
                errs[i + d[0] * (j + d[1] * k)] = e.abs();
                sum += e * e;
                count += 1;
            }
        }
    }
    let k = d[2] / 2;
    let mut slice = Frame::new(d[0], d[1], 1);
    slice.data = errs[k * d[0] * d[1]..(k + 1) * d[0] * d[1]].to_vec();
    TruthError {
        phantom: ph.name.to_string(),
        rms: (sum / count.max(1) as f64).sqrt(),
        slice,
        slice_index: k,
    }
}

fn widen(r: Reconstruction<f32>) -> Reconstruction<f64> {
    Reconstruction {
        grid: r.grid,
        data: r.data.into_iter().map(f64::from).collect(),
    }
}
