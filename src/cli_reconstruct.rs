//! `voxlab reconstruct`: filtered backprojection of a projection file. A scikit-image
//! sinogram `(detector, angle)` or a parallel stack `(angle, row, col)` gives FBP
//! images in scikit-image's orientation (as `iradon` with `circle=True` by default);
//! a geometry JSON of a cone beam gives FDK on RTK's centred grid. See docs/ct.md.

use clap::{Args, ValueEnum};
use std::path::{Path, PathBuf};
use voxlab::cpu::fbp::{
    apply_circle_mask, fbp, parallel_stack_grid, rtk_grid, Grid, Reconstruction,
};
use voxlab::cpu::ramp::RampFilter;
use voxlab::ct::{ct_to_phantom, Beam, Geometry, Projections, MAX_DETECTOR};
use voxlab::frame::{Frame, PngOptions};
use voxlab::io::npy::write_npy_f32;
use voxlab::io::projections::{geometry_path, read_angles_txt, read_geometry, read_projections};
use voxlab::volume::AnyVolume;
use voxlab::{Error, Result};

/// Arguments of `voxlab reconstruct`.
#[derive(Args)]
pub struct ReconstructArgs {
    /// Projections: .npy, .nrrd or .nhdr; 2-D = a scikit-image sinogram (detector,
    /// angle), 3-D = a stack (angle, row, col).
    input: PathBuf,
    /// `parallel` (scikit-image's geometry; needs --angles) or a geometry JSON file (as
    /// `voxlab project` writes). Default: <input-stem>.geometry.json beside the input.
    #[arg(long)]
    geometry: Option<String>,
    /// With --geometry parallel: a text file of angles in degrees (one per line), or a
    /// count N (N angles evenly over 180°).
    #[arg(long)]
    angles: Option<String>,
    /// Frequency window of the ramp (scikit-image's filter names).
    #[arg(long, value_enum, default_value = "ramp")]
    filter: RampFilter,
    /// Output size: the image is N × N (parallel; default the detector count) or the
    /// volume N³ (cone; default the detector columns).
    #[arg(long)]
    size: Option<usize>,
    /// Voxel spacing in mm (parallel: default the detector spacing; cone: default
    /// du·SID/SDD, the detector spacing at the isocentre).
    #[arg(long)]
    spacing: Option<f64>,
    /// Parallel beam: do not mask the image to the inscribed circle (scikit-image's
    /// circle=False: no padding of the sinogram, values in the corners). The default is
    /// iradon's circle=True.
    #[arg(long)]
    no_circle: bool,
    /// Cone beam over less than a full turn (at least 180° + the fan angle): weigh the
    /// projections with Parker's short-scan weights before filtering (docs/ct.md).
    #[arg(long)]
    short_scan: bool,
    /// Who computes: cpu (f64), cpu-f32, or gpu (f32 backprojection).
    #[arg(long, value_enum, default_value = "cpu")]
    backend: BackendArg,
    /// Output: .npy (float32; (n, n), (rows, n, n) or (N, N, N)), .nrrd/.nhdr (volume
    /// with the grid's affine, mm in the CT frame) or .png (2-D images only, windowed
    /// to the value range).
    #[arg(long)]
    out: PathBuf,
    /// A phantom (phantom:NAME) the projections came from: prints the RMS error of the
    /// reconstruction against its exact values at the voxel centres.
    #[arg(long)]
    truth: Option<String>,
    /// With --truth: write |reconstruction − truth| of the central slice to this PNG
    /// (black = 0, white = the largest error).
    #[arg(long, requires = "truth")]
    error_map: Option<PathBuf>,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum BackendArg {
    Cpu,
    CpuF32,
    Gpu,
}

fn extension(p: &Path) -> Option<String> {
    p.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
}

/// `--angles`: a count (evenly over 180°) or a file.
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

/// The geometry of the input: --geometry, else the JSON beside the input.
fn geometry_for(a: &ReconstructArgs, p: &Projections<f64>) -> Result<Geometry> {
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
            eprintln!("voxlab: using the geometry {}", beside.display());
            read_geometry(&beside)?
        }
    };
    p.check_against(&g).map_err(|e| match e {
        Error::Invalid { message, .. } => Error::invalid(
            format!("projections {} vs geometry", a.input.display()),
            message,
        ),
        other => other,
    })?;
    Ok(g)
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

/// Runs `voxlab reconstruct`.
pub fn run(a: ReconstructArgs) -> Result<()> {
    crate::check_output_as("--out", &a.out, &["npy", "nrrd", "nhdr", "png"])?;
    if let Some(e) = &a.error_map {
        crate::check_output_as("--error-map", e, &["png"])?;
    }
    let truth = match &a.truth {
        Some(t) => {
            let spec = t
                .strip_prefix("phantom:")
                .ok_or_else(|| Error::invalid("--truth", format!("'{t}': give phantom:NAME")))?;
            Some(voxlab::phantom::parse_spec(spec, 64)?.0)
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
    let p = read_projections::<f64>(&a.input)?;
    let g = geometry_for(&a, &p)?;
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
        (p, g, rtk_grid([n; 3], [s; 3]))
    };
    let total = grid.dims.iter().product::<usize>();
    if total > voxlab::volume::max_voxels() {
        return Err(Error::too_large(
            "--size",
            format!(
                "{}×{}×{} voxels (limit {})",
                grid.dims[0],
                grid.dims[1],
                grid.dims[2],
                voxlab::volume::max_voxels()
            ),
        ));
    }
    if !parallel && extension(&a.out).as_deref() == Some("png") {
        return Err(Error::invalid(
            "--out",
            "a cone-beam reconstruction is a volume: write .npy or .nrrd (a .png is for a \
             2-D image)",
        ));
    }
    if parallel && g.rows > 1 && extension(&a.out).as_deref() == Some("png") {
        return Err(Error::invalid(
            "--out",
            format!(
                "{} detector rows give a stack of {} images: write .npy or .nrrd",
                g.rows, g.rows
            ),
        ));
    }

    let pb = crate::progress_bar(0, "reconstructing", "voxel lines");
    let progress = |done: usize, total: usize| {
        pb.set_length(total as u64);
        pb.set_position(done as u64);
    };
    if a.short_scan {
        // Checked before any work: a clear error for a parallel beam or a wrong span.
        voxlab::cpu::parker::short_scan(&g)?;
    }
    let (mut rec, what): (Reconstruction<f64>, String) = match a.backend {
        BackendArg::Cpu => {
            let p = if a.short_scan {
                voxlab::cpu::parker::weigh(&p, &g)?
            } else {
                p
            };
            (fbp(&p, &g, a.filter, &grid, &progress)?, "cpu f64".into())
        }
        BackendArg::CpuF32 => {
            let mut p32 = narrow(&p)?;
            if a.short_scan {
                p32 = voxlab::cpu::parker::weigh(&p32, &g)?;
            }
            (
                widen(fbp(&p32, &g, a.filter, &grid, &progress)?),
                "cpu f32".into(),
            )
        }
        BackendArg::Gpu => {
            let ctx = voxlab::gpu::GpuContext::new()?;
            let mut p32 = narrow(&p)?;
            if a.short_scan {
                p32 = voxlab::gpu::parker::weigh(&ctx, &p32, &g)?;
            }
            let r = voxlab::gpu::fbp::fbp(&ctx, &p32, &g, a.filter, &grid)?;
            (widen(r), format!("gpu ({})", ctx.summary.name))
        }
    };
    pb.finish_and_clear();
    if parallel && !a.no_circle {
        apply_circle_mask(&mut rec)?;
    }

    let d = rec.grid.dims;
    let values: Vec<f32> = rec.data.iter().map(|&v| v as f32).collect();
    match extension(&a.out).as_deref() {
        Some("npy") => {
            let shape: Vec<usize> = if d[2] == 1 {
                vec![d[1], d[0]]
            } else {
                vec![d[2], d[1], d[0]]
            };
            write_npy_f32(&a.out, &shape, &values)?;
        }
        Some("png") => {
            let mut f = Frame::new(d[0], d[1], 1);
            f.data = rec.data.clone();
            f.save(&a.out, PngOptions::default())?;
        }
        _ => voxlab::io::write_volume(&a.out, &AnyVolume::from(rec.to_volume()?))?,
    }
    let shape = if d[2] == 1 {
        format!("{}×{} image", d[0], d[1])
    } else {
        format!("{}×{}×{} volume", d[0], d[1], d[2])
    };
    let (lo, hi) = rec
        .data
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        });
    println!(
        "wrote {} ({} {}, {} filter, {what}; values {lo:.4} … {hi:.4})",
        a.out.display(),
        if parallel { "FBP" } else { "FDK" },
        shape,
        a.filter.name()
    );
    if let Some(ph) = &truth {
        let (rms, errs) = error_against(&rec, ph, parallel && !a.no_circle);
        println!("RMS error against {}: {rms:.6}", ph.name);
        if let Some(path) = &a.error_map {
            let k = d[2] / 2;
            let mut f = Frame::new(d[0], d[1], 1);
            f.data = errs[k * d[0] * d[1]..(k + 1) * d[0] * d[1]].to_vec();
            let hi = f.data.iter().fold(0.0f64, |m, &v| m.max(v));
            f.save(
                path,
                PngOptions {
                    range: Some((0.0, hi.max(1e-12))),
                    ..Default::default()
                },
            )?;
            println!(
                "wrote {} (|error| of slice {k}, white = {hi:.4})",
                path.display()
            );
        }
    }
    Ok(())
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
/// `|rec − truth|` at every voxel (0 outside the circle).
fn error_against(
    rec: &Reconstruction<f64>,
    ph: &voxlab::phantom::Phantom,
    circle: bool,
) -> (f64, Vec<f64>) {
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
    ((sum / count.max(1) as f64).sqrt(), errs)
}

fn narrow(p: &Projections<f64>) -> Result<Projections<f32>> {
    Projections::new(
        p.angles,
        p.rows,
        p.cols,
        p.data.iter().map(|&v| v as f32).collect(),
    )
}

fn widen(r: Reconstruction<f32>) -> Reconstruction<f64> {
    Reconstruction {
        grid: r.grid,
        data: r.data.into_iter().map(f64::from).collect(),
    }
}
