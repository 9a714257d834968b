//! `voxlab reconstruct`: filtered backprojection of a projection file. A scikit-image
//! sinogram `(detector, angle)` or a parallel stack `(angle, row, col)` gives FBP
//! images in scikit-image's orientation (as `iradon` with `circle=True` by default);
//! a geometry JSON of a cone beam gives FDK on RTK's centred grid. See docs/ct.md; the
//! algorithms are [`crate::cpu::fbp`] and [`crate::gpu::fbp`].

use super::{Backend, Engine, Progress};
use crate::cpu::fbp::{
    apply_circle_mask, fbp, parallel_stack_grid, rtk_grid, Grid, Reconstruction,
};
use crate::cpu::ramp::RampFilter;
use crate::ct::{ct_to_phantom, Beam, Geometry, Projections, MAX_DETECTOR};
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::io::projections::{geometry_path, read_angles_txt, read_geometry, read_projections};
use crate::io::{write_frame, PngOptions};
use crate::phantom::Phantom;
use crate::volume::AnyVolume;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The `voxlab reconstruct` job.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReconstructRequest {
    /// Projections: `.npy`, `.nrrd` or `.nhdr`; 2-D = a scikit-image sinogram
    /// (detector, angle), 3-D = a stack (angle, row, col).
    pub input: PathBuf,
    /// `parallel` (scikit-image's geometry; needs `angles`) or a geometry JSON file.
    /// `None`: `<input-stem>.geometry.json` beside the input.
    pub geometry: Option<String>,
    /// With `geometry = parallel`: a text file of angles in degrees (one per line), or
    /// a count N (N angles evenly over 180°).
    pub angles: Option<String>,
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
    /// Write the reconstruction here: `.npy` (float32), `.nrrd`/`.nhdr` (the grid's
    /// affine) or `.png` (2-D images only). Checked before the work starts.
    pub out: Option<PathBuf>,
    /// A phantom (`phantom:NAME`) the projections came from: the RMS error against its
    /// exact values at the voxel centres.
    pub truth: Option<String>,
    /// With `truth`: write |reconstruction − truth| of the central slice to this PNG.
    pub error_map: Option<PathBuf>,
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

/// The geometry of the input, and the file it was read from when found beside it.
fn geometry_for(
    a: &ReconstructRequest,
    p: &Projections<f64>,
) -> Result<(Geometry, Option<PathBuf>)> {
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
            if angles.len() != p.angles {
                return Err(Error::invalid(
                    "--angles",
                    format!(
                        "{} angles given, but {} holds {} projections ({})",
                        angles.len(),
                        a.input.display(),
                        p.angles,
                        if p.rows == 1 {
                            format!("a (detector, angle) = ({}, {}) sinogram", p.cols, p.angles)
                        } else {
                            format!("(angle, row, col) = ({}, {}, {})", p.angles, p.rows, p.cols)
                        }
                    ),
                ));
            }
            let du = a.spacing.unwrap_or(1.0);
            Geometry::parallel_stack(p.cols, p.rows, du, du, angles)?
        }
        Some(file) => {
            if a.angles.is_some() {
                return Err(Error::invalid(
                    "--angles",
                    "the geometry file lists the angles (use --angles with --geometry parallel)",
                ));
            }
            read_geometry(Path::new(file))?
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
            let g = read_geometry(&beside)?;
            beside_file = Some(beside);
            g
        }
    };
    p.check_against(&g).map_err(|e| match e {
        Error::Invalid { message, .. } => Error::invalid(
            format!("projections {} vs geometry", a.input.display()),
            message,
        ),
        other => other,
    })?;
    Ok((g, beside_file))
}

/// The padded stack and geometry of iradon's `circle=True` (`_sinogram_circle_to_square`):
/// `ceil(√2·cols)` bins, old bin `cols//2` moved to the new centre.
fn pad_for_circle(p: &Projections<f64>, g: &Geometry) -> Result<(Projections<f64>, Geometry)> {
    let n = p.cols;
    let diag = ((2.0f64).sqrt() * n as f64).ceil() as usize;
    let before = diag / 2 - n / 2;
    let mut data = vec![0.0; p.angles * p.rows * diag];
    for (dst, src) in data.chunks_mut(diag).zip(p.data.chunks(n)) {
        dst[before..before + n].copy_from_slice(src);
    }
    let mut g2 = g.clone();
    g2.cols = diag;
    g2.cu = g.cu + before as f64;
    Ok((Projections::new(p.angles, p.rows, diag, data)?, g2))
}

fn extension(p: &Path) -> Option<String> {
    p.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
}

/// The options checked before any input is read: the outputs, the truth phantom and
/// the spacing.
fn check_request(a: &ReconstructRequest) -> Result<Option<Phantom>> {
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
    Ok(truth)
}

/// Reconstructs (and writes `out` and `error_map` when given).
///
/// # Errors
/// Bad options, projections or geometry; an output the result cannot be written as;
/// GPU errors; [`Error::Cancelled`].
pub fn run(a: &ReconstructRequest, progress: &dyn Progress) -> Result<Reconstructed> {
    check_request(a)?;
    let p = read_projections::<f64>(&a.input)?;
    let (g, geometry_file) = geometry_for(a, &p)?;
    if let Some(f) = &geometry_file {
        progress.note(&format!("using the geometry {}", f.display()));
    }
    reconstruct(a, p, g, geometry_file, progress)
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
    let parallel = g.beam == Beam::Parallel;
    let (p, g, grid) = if parallel {
        let n = a.size.unwrap_or(p.cols);
        check_size(n, 1 << 14)?;
        let (p, g) = if a.no_circle {
            (p, g)
        } else {
            pad_for_circle(&p, &g)?
        };
        let grid = scaled_parallel_grid(n, &g, a.spacing.unwrap_or(g.du));
        (p, g, grid)
    } else {
        if a.no_circle {
            return Err(Error::invalid(
                "--no-circle",
                "the circle mask is for parallel-beam images only",
            ));
        }
        let Beam::Cone { sid, sdd } = g.beam else {
            unreachable!("cone")
        };
        let n = a.size.unwrap_or(g.cols);
        check_size(n, 2048)?;
        let s = a.spacing.unwrap_or(g.du * sid / sdd);
        let grid = rtk_grid([n; 3], [s; 3]);
        // A source inside the reconstructed grid: refused; in its corners: a warning.
        if let Some(w) = g.check_source_outside(
            grid.affine,
            grid.dims,
            "geometry sid",
            "the reconstruction grid",
        )? {
            progress.warn(&w);
        }
        (p, g, grid)
    };
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
        if parallel && g.rows > 1 && png {
            return Err(Error::invalid(
                "--out",
                format!(
                    "{} detector rows give a stack of {} images: write .npy or .nrrd",
                    g.rows, g.rows
                ),
            ));
        }
    }

    if a.short_scan {
        // Checked before any work: a clear error for a parallel beam or a wrong span.
        crate::cpu::parker::short_scan(&g)?;
    }
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
                let r = crate::gpu::fbp::fbp(ctx, &p32, &g, a.filter, &grid)?;
                (widen(r), format!("gpu ({})", ctx.summary.name))
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
    };
    if let Some(out) = &a.out {
        done.write(out)?;
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
                let shape: Vec<usize> = if d[2] == 1 {
                    vec![d[1], d[0]]
                } else {
                    vec![d[2], d[1], d[0]]
                };
                crate::io::npy::write_npy_f32(out, &shape, &values)
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
