//! Projection stacks and CT geometry on disk: projection arrays in every volume format
//! voxlab reads, flat- and dark-field images, a small geometry JSON file, and angle
//! lists.
//!
//! # Arrays
//!
//! A [`Projections`] stack is `angles × rows × cols` values with the column fastest,
//! exactly a C-order NumPy array of shape `(angle, row, col)`:
//!
//! | array on disk                  | read as                                          |
//! |--------------------------------|--------------------------------------------------|
//! | 3-D `(angle, row, col)`        | the stack as it is (RTK's layout, 3-D parallel)   |
//! | 2-D `(detector, angle)`        | **always** scikit-image's sinogram: transposed    |
//! |                                | into a one-row stack `(angle, 1, detector)`       |
//!
//! A 2-D array is never read as `(angle, detector)`: `skimage.transform.radon` returns
//! `(detector, angle)` and that is the only 2-D layout there is here. Writing uses
//! [`Layout::Stack`] (3-D) or [`Layout::Skimage`] (2-D `(detector, angle)`, one-row
//! stacks only).
//!
//! `.npy`: `f4` and `f8` in either byte order, C or Fortran order, are read; an `f8`
//! file read as `Projections<f64>` is exact. Writing uses the stack's own precision
//! (`<f4` for f32, `<f8` for f64).
//!
//! Every other format [`crate::io::read_volume_with`] reads — NRRD (`.nrrd`, `.nhdr`),
//! MetaImage (`.mha`, `.mhd`, RTK's own projection format), TIFF (a multi-page file or a
//! directory of pages), NIfTI, DICOM, PVM, `.den` — is read as a volume whose
//! `(x, y, z)` axes are `(col, row, angle)`, so its samples arrive as that reader gives
//! them (integers exact, doubles rounded to f32; see [`crate::io`]); a volume of one
//! slice (`z = 1`) is a 2-D array and so a scikit-image sinogram `(y, x) = (detector,
//! angle)`. [`ReadOptions::frame`] picks one stack of a 4-D file. NRRD is also written,
//! as gzip-compressed `float` with spacing `du dv 1` (stack) or `1 du` (sinogram) when a
//! geometry is given, else 1.
//!
//! # Flat and dark fields
//!
//! [`read_field_image`] reads a flat- or dark-field file in any of the formats above for
//! projections of `rows × cols` pixels: one `(rows, cols)` image or a stack
//! `(frame, rows, cols)` whose frames are averaged in f64 (for one-row sinograms also a
//! `(detector, frame)` array). [`crate::ct::flat_field`] turns intensities into line
//! integrals with them.
//!
//! # By detector lines
//!
//! A 3-D stack stored uncompressed in one block — a C-order float `.npy`, a raw NRRD, a
//! binary MetaImage ([`line_stack`]) — can also be read a few detector lines at a time
//! ([`read_projection_lines`]): only those lines are read from the file or held, each
//! the whole read's bit for bit. The distributed reconstruction reads its ranks'
//! lines so.
//!
//! Every read refuses non-finite samples, arrays that are not 2-D or 3-D, and sizes
//! past [`crate::volume::max_voxels`] (before allocating); truncated files and wrong
//! dtypes are format errors from the readers. Writes are atomic
//! ([`crate::io::write_atomic`]).
//!
//! # Geometry JSON
//!
//! A [`Geometry`] is stored beside an output `<name>.npy` as `<name>.geometry.json`
//! ([`geometry_path`]):
//!
//! ```json
//! { "beam": "cone", "sid": 1000.0, "sdd": 1500.0,
//!   "cols": 256, "rows": 192, "du": 1.5, "dv": 1.5, "cu": 127.5, "cv": 95.5,
//!   "angles_deg": [0.0, 1.0, 2.0] }
//! ```
//!
//! `beam` is `"parallel"` or `"cone"` (`sid`, `sdd` in mm, required for cone and
//! refused for parallel). The angles are either a list `angles_deg` or an even spread
//! `"angles": {"count": 360, "range_deg": 360}` ([`Geometry::even_angles`]). `cu`, `cv`
//! default to the convention of the beam (`cols/2` and `(rows−1)/2` for parallel,
//! `(n−1)/2` for cone), `du`, `dv` to 1. Extra sections whose values are objects or
//! arrays (a description of the volume, versions, …) are ignored; an unknown field with
//! a plain value is refused, so a typo is an error and not a silent default.
//!
//! A geometry may also be given **view by view** ([`ViewGeometry`]): `beam`, `cols`,
//! `rows` and one entry per projection, four vectors in the CT frame (mm, see
//! [`ViewVectors`]) — the circular fields are then refused:
//!
//! ```json
//! { "beam": "cone", "cols": 4, "rows": 3,
//!   "views": [{"source": [0, 0, 1000], "pixel00": [-4.5, -3, -500],
//!              "u": [3, 0, 0], "v": [0, 3, 0]}] }
//! ```
//!
//! # Other geometry files
//!
//! [`read_geometry_with`] (and [`parse_geometry`]) read voxlab's JSON, RTK's geometry
//! XML ([`super::rtk_geometry`]) and ASTRA's `proj_geom` as JSON
//! ([`super::astra_geometry`]), telling them apart by their contents
//! ([`detect_geometry_format`]). RTK's file needs the projections' [`DetectorGrid`],
//! which [`read_projections_grid`] takes from a MetaImage or NRRD header.
//!
//! # Angle lists
//!
//! [`read_angles_txt`]: one angle in degrees per line; blank lines and `#` comments
//! (whole-line or trailing) are ignored.

use super::brick::{raw_layout, read_lines};
use super::npy::{npy_float_shape, read_npy_f64, read_npy_f64_lines, write_npy_f32, write_npy_f64};
use super::nrrd::{write_nrrd, NrrdWriteOptions};
pub use super::rtk_geometry::DetectorGrid;
use super::{choose_frame, read_volume_with, ReadOptions};
use crate::ct::{Beam, Geometry, Lines, Projections, ViewGeometry, ViewVectors, MAX_DETECTOR};
use crate::error::{Error, Result};
use crate::real::Real;
use crate::volume::{max_voxels, AnyVolume, Volume};
use glam::{DMat4, DVec3};
use std::path::{Path, PathBuf};

/// How a stack is laid out in the file written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// 3-D `(angle, row, col)`, column fastest.
    Stack,
    /// 2-D `(detector, angle)`, scikit-image's sinogram (one-row stacks only).
    Skimage,
}

/// Reads a projection stack from any file [`crate::io::read_volume`] reads (see the module
/// docs for the layouts). Fails on non-finite samples, arrays that are not 2-D or 3-D,
/// and unsupported dtypes or formats.
pub fn read_projections<R: Real>(path: &Path) -> Result<Projections<R>> {
    read_projections_with(path, &ReadOptions::default())
}

/// [`read_projections`] with [`ReadOptions`]: `frame` picks one 3-D stack of a file
/// that holds several (a 4-D NIfTI, MetaImage or NRRD).
pub fn read_projections_with<R: Real>(
    path: &Path,
    options: &ReadOptions,
) -> Result<Projections<R>> {
    let (shape, values) = read_array(path, options)?;
    from_array(path, &shape, values)
}

/// The array in a projection, flat- or dark-field file: its shape in NumPy's order
/// (slowest axis first) and its values. `.npy` is read in f64 as stored; every other
/// format through [`read_volume_with`], its `(x, y, z)` taken as `(col, row, angle)`
/// and a volume of one slice as a 2-D `(y, x)` array.
fn read_array(path: &Path, options: &ReadOptions) -> Result<(Vec<usize>, Vec<f64>)> {
    let (shape, values, _) = read_array_affine(path, options)?;
    Ok((shape, values))
}

/// [`read_array`] and the volume's index-to-world affine (`None` for `.npy`, which
/// has none).
fn read_array_affine(
    path: &Path,
    options: &ReadOptions,
) -> Result<(Vec<usize>, Vec<f64>, Option<DMat4>)> {
    if path.is_file() && extension(path).as_deref() == Some("npy") {
        choose_frame(path, "frame", 1, "", options.frame)?;
        let (shape, values, _) = read_npy_f64(path)?;
        return Ok((shape, values, None));
    }
    let vol = read_volume_with(path, options)?;
    let [nx, ny, nz] = vol.dims();
    let shape = if nz == 1 {
        vec![ny, nx]
    } else {
        vec![nz, ny, nx]
    };
    let affine = vol.affine();
    Ok((shape, vol.values_f64(), Some(affine)))
}

/// [`read_projections_with`], and the detector grid the file's header describes: the
/// spacing, origin and direction of a 3-D MetaImage or NRRD stack, its `(x, y)` axes
/// the columns and rows ([`DetectorGrid::from_affine`]) — what an RTK geometry file
/// needs ([`read_geometry_with`]). MetaImage's numbers are ITK's; a NRRD's are taken as
/// written, which is ITK's reading for the LPS space ITK and RTK write (a NRRD in a RAS
/// space differs from ITK's reading by the signs of `x` and `y`). `None` for every
/// other format (`.npy` has no geometry; NIfTI's RAS and DICOM's patient frame are not
/// the projection image's plane) and for 2-D sinograms.
///
/// # Errors
/// As [`read_projections_with`]; a header whose projection axis moves the pixels
/// within the detector plane.
pub fn read_projections_grid<R: Real>(
    path: &Path,
    options: &ReadOptions,
) -> Result<(Projections<R>, Option<DetectorGrid>)> {
    let (shape, values, affine) = read_array_affine(path, options)?;
    let p = from_array(path, &shape, values)?;
    let with_grid = matches!(
        super::detect_format(path),
        Ok(super::Format::MetaImage | super::Format::Nrrd)
    );
    let grid = match affine {
        Some(a) if shape.len() == 3 && with_grid => Some(header_grid(path, p.cols, p.rows, &a)?),
        _ => None,
    };
    Ok((p, grid))
}

/// The detector grid a stack's header affine describes ([`DetectorGrid::from_affine`]),
/// its errors naming `path`.
fn header_grid(path: &Path, cols: usize, rows: usize, affine: &DMat4) -> Result<DetectorGrid> {
    DetectorGrid::from_affine(cols, rows, affine).map_err(|e| e.in_file(path))
}

/// Reads a flat- or dark-field file (`what`: `"flat"` or `"dark"`) for projections of
/// `rows × cols` pixels and returns its frames averaged in f64
/// ([`crate::ct::flat_field::mean_frames`]): one `rows × cols` image. Any format
/// [`read_projections`] reads; the array is
///
/// - 3-D `(frame, row, col)`: frames averaged;
/// - 2-D with one detector row (`rows == 1`) and shape `(cols, frames)`: scikit-image's
///   `(detector, angle)` layout, frames averaged;
/// - 2-D `(rows, cols)`: one image.
///
/// # Errors
/// A shape that is none of these (naming the file, `shape` and the projections' size),
/// an empty stack, non-finite values, the readers' errors.
pub fn read_field_image(
    path: &Path,
    what: &str,
    rows: usize,
    cols: usize,
    options: &ReadOptions,
) -> Result<Vec<f64>> {
    let (shape, values) = read_array(path, options)?;
    field_image(path, what, &shape, values, rows, cols)
}

/// [`read_field_image`] of an array already in memory: `shape` in NumPy's order, `path`
/// names it in errors (a file, or `flat array`).
///
/// # Errors
/// As [`read_field_image`].
pub fn field_image(
    path: &Path,
    what: &str,
    shape: &[usize],
    values: Vec<f64>,
    rows: usize,
    cols: usize,
) -> Result<Vec<f64>> {
    if shape.iter().product::<usize>() != values.len() {
        return Err(Error::format(
            path,
            "shape",
            format!("shape {shape:?} does not hold {} values", values.len()),
        ));
    }
    let (frames, values) = match *shape {
        [k, r, c] if r == rows && c == cols => (k, values),
        [d, k] if rows == 1 && d == cols => {
            // (detector, frame) → frame-major.
            let mut out = vec![0.0; values.len()];
            for (i, v) in values.iter().enumerate() {
                out[(i % k.max(1)) * cols + i / k.max(1)] = *v;
            }
            (k, out)
        }
        [r, c] if r == rows && c == cols => (1, values),
        _ => {
            return Err(Error::format(
                path,
                "shape",
                format!(
                    "the {what} field is an array of shape {shape:?}, but the projections \
                     have rows × cols = {rows} × {cols}: give one ({rows}, {cols}) image or \
                     a stack (frames, {rows}, {cols}){}",
                    if rows == 1 {
                        format!(" or a ({cols}, frames) array")
                    } else {
                        String::new()
                    }
                ),
            ))
        }
    };
    if frames == 0 {
        return Err(Error::format(
            path,
            "shape",
            format!("the {what} field holds no frames (shape {shape:?})"),
        ));
    }
    if let Some(k) = values.iter().position(|v| !v.is_finite()) {
        return Err(Error::format(
            path,
            "data",
            format!(
                "sample {k} is {} (the {what} field must be finite)",
                values[k]
            ),
        ));
    }
    crate::ct::flat_field::mean_frames(
        &format!("{what} field {}", path.display()),
        &values,
        rows * cols,
    )
}

/// A projection file that can be read detector line by detector line
/// ([`read_projection_lines`]), from its header alone: its `(angles, rows, cols)` and
/// the detector grid of a MetaImage or NRRD header (as [`read_projections_grid`]
/// gives it).
#[derive(Clone, Debug, PartialEq)]
pub struct LineStack {
    pub shape: [usize; 3],
    pub grid: Option<DetectorGrid>,
}

/// The [`LineStack`] of `path` when its detector lines can be read alone: a 3-D C-order
/// float `.npy` stack, or a 3-D stack stored uncompressed in one block — a raw-encoded
/// NRRD (`.nrrd`, or `.nhdr` and its data file) or a binary MetaImage (`.mha`, or
/// `.mhd` and one data file), as [`super::brick::raw_layout`] finds them. `None` for
/// every other file [`read_projections`] reads (read whole): compressed or text data,
/// Fortran order, a 2-D sinogram, a file of several stacks, other formats.
///
/// # Errors
/// A bad header; a file too short for the data its header announces; a header whose
/// projection axis moves the pixels within the detector plane.
pub fn line_stack(path: &Path) -> Result<Option<LineStack>> {
    if extension(path).as_deref() == Some("npy") {
        return Ok(match npy_float_shape(path)? {
            (shape, false) if shape.len() == 3 => Some(LineStack {
                shape: [shape[0], shape[1], shape[2]],
                grid: None,
            }),
            _ => None,
        });
    }
    Ok(match raw_layout(path)? {
        Some(l) if l.dims[2] > 1 => {
            let [cols, rows, angles] = l.dims;
            Some(LineStack {
                shape: [angles, rows, cols],
                grid: Some(header_grid(path, cols, rows, &l.affine)?),
            })
        }
        _ => None,
    })
}

/// Only the detector lines `lines` (line `a·rows + r` is row `r` of view `a`) of a
/// stack [`line_stack`] accepts, in increasing order, each once; nothing else of the
/// file is read or held. The values are the whole stack's ([`read_projections`]) bit
/// for bit, and checked as it checks them.
///
/// # Errors
/// As [`read_projections`]; a line past the stack; a file [`line_stack`] refuses.
pub fn read_projection_lines<R: Real>(path: &Path, lines: &[usize]) -> Result<Lines<R>> {
    let (shape, ids, values) = if extension(path).as_deref() == Some("npy") {
        read_npy_f64_lines(path, lines)?
    } else {
        match raw_layout(path)? {
            Some(l) if l.dims[2] > 1 => {
                let [cols, rows, angles] = l.dims;
                let (ids, values) = read_lines(&l, lines, path)?;
                (vec![angles, rows, cols], ids, values)
            }
            _ => {
                return Err(Error::format(
                    path,
                    "encoding",
                    "this file cannot be read by detector lines (only a 3-D .npy stack, \
                     a raw NRRD or an uncompressed MetaImage can)",
                ))
            }
        }
    };
    let [angles, rows, cols] = match *shape {
        [a, r, c] => [a, r, c],
        _ => {
            return Err(Error::format(
                path,
                "shape",
                format!("reading by detector lines needs a 3-D (angle, row, col) stack, not shape {shape:?}"),
            ))
        }
    };
    // A value that is not finite is named by its view, row and column.
    let at = |k: usize| {
        let line = ids[k / cols];
        format!(
            "view {}, row {}, column {}",
            line / rows,
            line % rows,
            k % cols
        )
    };
    check_stack(path, &shape, [angles, rows, cols], &values, &at)?;
    Lines::new(
        [angles, rows, cols],
        ids,
        values.into_iter().map(R::of).collect(),
    )
}

/// [`read_projections`], then checks the stack's shape against `geometry`.
pub fn read_projections_for<R: Real>(path: &Path, geometry: &Geometry) -> Result<Projections<R>> {
    let p = read_projections(path)?;
    p.check_against(geometry).map_err(|e| match e {
        Error::Invalid { message, .. } => {
            Error::invalid(format!("projections {}", path.display()), message)
        }
        other => other,
    })?;
    Ok(p)
}

/// Turns an array read from `path` into a stack (module docs: 3-D direct, 2-D
/// transposed from `(detector, angle)`).
fn from_array<R: Real>(path: &Path, shape: &[usize], values: Vec<f64>) -> Result<Projections<R>> {
    let bad_shape = |m: String| Error::format(path, "shape", m);
    let (angles, rows, cols) = match *shape {
        [a, r, c] => (a, r, c),
        [det, a] => (a, 1, det),
        _ => {
            return Err(bad_shape(format!(
                "projections need a 3-D (angle, row, col) or a 2-D scikit-image \
                 (detector, angle) array, not shape {shape:?}"
            )))
        }
    };
    check_stack(path, shape, [angles, rows, cols], &values, &|k| {
        format!("sample {k}")
    })?;
    let data: Vec<R> = if shape.len() == 2 {
        // values[d * angles + a] → data[a * cols + d]
        let mut out = vec![R::zero(); values.len()];
        for (i, v) in values.iter().enumerate() {
            let (d, a) = (i / angles, i % angles);
            out[a * cols + d] = R::of(*v);
        }
        out
    } else {
        values.into_iter().map(R::of).collect()
    };
    Projections::new(angles, rows, cols, data)
}

/// The checks [`read_projections`] makes of a stack's shape and values (`values` may
/// be some of its lines only; `at(k)` names value `k` in a message).
fn check_stack(
    path: &Path,
    shape: &[usize],
    [angles, rows, cols]: [usize; 3],
    values: &[f64],
    at: &dyn Fn(usize) -> String,
) -> Result<()> {
    let bad_shape = |m: String| Error::format(path, "shape", m);
    for (name, n) in [("angles", angles), ("rows", rows), ("columns", cols)] {
        if n == 0 {
            return Err(bad_shape(format!("shape {shape:?} has no {name}")));
        }
        if n > MAX_DETECTOR {
            return Err(Error::too_large(
                format!("projections {}", path.display()),
                format!("{n} {name} (at most {MAX_DETECTOR})"),
            ));
        }
    }
    if values.len() > max_voxels() {
        return Err(Error::too_large(
            format!("projections {}", path.display()),
            format!("{} values (limit {})", values.len(), max_voxels()),
        ));
    }
    if let Some(k) = values.iter().position(|v| !v.is_finite()) {
        return Err(Error::format(
            path,
            "data",
            format!("{} is {} (projections must be finite)", at(k), values[k]),
        ));
    }
    Ok(())
}

/// Writes a stack as `.npy` (in the stack's precision) or NRRD (`float`), atomically.
/// `geometry`, when given, must match the stack; NRRD then records `du`, `dv` as
/// spacings. [`Layout::Skimage`] needs a one-row stack.
pub fn write_projections<R: Real>(
    path: &Path,
    p: &Projections<R>,
    layout: Layout,
    geometry: Option<&Geometry>,
) -> Result<()> {
    if let Some(g) = geometry {
        p.check_against(g)?;
    }
    let (shape, values): (Vec<usize>, Vec<R>) = match layout {
        Layout::Stack => (vec![p.angles, p.rows, p.cols], p.data.clone()),
        Layout::Skimage => {
            if p.rows != 1 {
                return Err(Error::invalid(
                    "projection layout",
                    format!(
                        "a scikit-image (detector, angle) sinogram has one detector row; \
                         this stack has {} (write it as a 3-D stack)",
                        p.rows
                    ),
                ));
            }
            let mut out = vec![R::zero(); p.data.len()];
            for a in 0..p.angles {
                for d in 0..p.cols {
                    out[d * p.angles + a] = p.data[a * p.cols + d];
                }
            }
            (vec![p.cols, p.angles], out)
        }
    };
    match extension(path).as_deref() {
        Some("npy") => {
            if R::NAME == "f64" {
                let v: Vec<f64> = values.iter().map(|x| x.f64()).collect();
                write_npy_f64(path, &shape, &v)
            } else {
                let v: Vec<f32> = values.iter().map(|x| x.f64() as f32).collect();
                write_npy_f32(path, &shape, &v)
            }
        }
        Some("nrrd") | Some("nhdr") => {
            let (du, dv) = geometry.map_or((1.0, 1.0), |g| (g.du, g.dv));
            let (dims, spacing) = match layout {
                Layout::Stack => ([p.cols, p.rows, p.angles], [du, dv, 1.0]),
                Layout::Skimage => ([p.angles, p.cols, 1], [1.0, du, 1.0]),
            };
            let affine = DMat4::from_scale(DVec3::from_array(spacing));
            let v: Vec<f32> = values.iter().map(|x| x.f64() as f32).collect();
            let vol = AnyVolume::from(Volume::with_affine(dims, affine, v)?);
            write_nrrd(
                path,
                &vol,
                NrrdWriteOptions {
                    gzip: true,
                    detached: extension(path).as_deref() == Some("nhdr"),
                },
            )
        }
        _ => Err(unsupported(path)),
    }
}

/// `<dir>/<name>.geometry.json` for an output `<dir>/<name>.<ext>`.
pub fn geometry_path(output: &Path) -> PathBuf {
    let stem = output
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "projections".into());
    output.with_file_name(format!("{stem}.geometry.json"))
}

/// The JSON form of a [`Geometry`] (module docs).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct GeometryJson {
    beam: BeamName,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    sid: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    sdd: Option<f64>,
    cols: usize,
    rows: usize,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    du: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    dv: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cu: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cv: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    angles_deg: Option<Vec<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    angles: Option<EvenAngles>,
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "bounded_views"
    )]
    views: Option<Vec<ViewJson>>,
}

/// One view of the per-view form: [`ViewVectors`] in mm.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct ViewJson {
    source: [f64; 3],
    pixel00: [f64; 3],
    u: [f64; 3],
    v: [f64; 3],
}

/// `views`, refused past [`MAX_DETECTOR`] entries as they are read
/// ([`crate::json::bounded`]).
fn bounded_views<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<Option<Vec<ViewJson>>, D::Error> {
    crate::json::bounded(d).map(Some)
}

/// The fields of [`GeometryJson`].
const KNOWN_FIELDS: &[&str] = &[
    "beam",
    "sid",
    "sdd",
    "cols",
    "rows",
    "du",
    "dv",
    "cu",
    "cv",
    "angles_deg",
    "angles",
    "views",
];

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
enum BeamName {
    Parallel,
    Cone,
}

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct EvenAngles {
    count: usize,
    range_deg: f64,
}

/// The geometry as JSON text: a circular orbit with the explicit `angles_deg` list, a
/// geometry given view by view in the per-view form ([`view_geometry_to_json`]).
pub fn geometry_to_json(g: &Geometry) -> String {
    if let Some(views) = &g.views {
        return view_geometry_to_json(&ViewGeometry {
            parallel: g.beam == Beam::Parallel,
            cols: g.cols,
            rows: g.rows,
            views: views.clone(),
        });
    }
    let (beam, sid, sdd) = match g.beam {
        Beam::Parallel => (BeamName::Parallel, None, None),
        Beam::Cone { sid, sdd } => (BeamName::Cone, Some(sid), Some(sdd)),
    };
    let j = GeometryJson {
        beam,
        sid,
        sdd,
        cols: g.cols,
        rows: g.rows,
        du: Some(g.du),
        dv: Some(g.dv),
        cu: Some(g.cu),
        cv: Some(g.cv),
        angles_deg: Some(g.angles_deg.clone()),
        angles: None,
        views: None,
    };
    serde_json::to_string_pretty(&j).expect("plain numbers serialise") + "\n"
}

/// A geometry given view by view as voxlab's JSON (the per-view form of the module
/// docs).
pub fn view_geometry_to_json(g: &ViewGeometry) -> String {
    let j = GeometryJson {
        beam: if g.parallel {
            BeamName::Parallel
        } else {
            BeamName::Cone
        },
        sid: None,
        sdd: None,
        cols: g.cols,
        rows: g.rows,
        du: None,
        dv: None,
        cu: None,
        cv: None,
        angles_deg: None,
        angles: None,
        views: Some(
            g.views
                .iter()
                .map(|v| ViewJson {
                    source: v.source.to_array(),
                    pixel00: v.pixel00.to_array(),
                    u: v.u.to_array(),
                    v: v.v.to_array(),
                })
                .collect(),
        ),
    };
    serde_json::to_string_pretty(&j).expect("plain numbers serialise") + "\n"
}

/// Parses voxlab's geometry JSON text (`path` only names it in errors) and validates
/// it: the circular form as a [`Geometry`], the per-view form through
/// [`Geometry::from_views`]. [`parse_geometry`] reads every format.
pub fn geometry_from_json(text: &str, path: &Path) -> Result<Geometry> {
    parse_voxlab_geometry(text, path)?.into_geometry(path)
}

/// voxlab's geometry JSON, either form.
fn parse_voxlab_geometry(text: &str, path: &Path) -> Result<GeometryFile> {
    let bad = |m: String| Error::format(path, "geometry", m);
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut value: serde_json::Value =
        serde_json::from_str(text).map_err(|e| bad(e.to_string()))?;
    if !value.is_object() {
        return Err(bad("the top level must be a JSON object { … }".into()));
    }
    // Extra sections (objects, arrays) are metadata and ignored; an unknown scalar is
    // refused below as a likely typo.
    if let Some(map) = value.as_object_mut() {
        map.retain(|k, v| KNOWN_FIELDS.contains(&k.as_str()) || !(v.is_object() || v.is_array()));
    }
    let j: GeometryJson =
        serde_json::from_value(value).map_err(|e| bad(crate::json::explain(&e.to_string())))?;
    if let Some(views) = j.views {
        let given = [
            ("sid", j.sid.is_some()),
            ("sdd", j.sdd.is_some()),
            ("du", j.du.is_some()),
            ("dv", j.dv.is_some()),
            ("cu", j.cu.is_some()),
            ("cv", j.cv.is_some()),
            ("angles_deg", j.angles_deg.is_some()),
            ("angles", j.angles.is_some()),
        ];
        if let Some((name, _)) = given.iter().find(|(_, g)| *g) {
            return Err(bad(format!(
                "{name} goes with the circular form; a geometry given by \"views\" holds \
                 beam, cols, rows and the views only"
            )));
        }
        let vg = ViewGeometry {
            parallel: j.beam == BeamName::Parallel,
            cols: j.cols,
            rows: j.rows,
            views: views
                .iter()
                .map(|v| ViewVectors {
                    source: DVec3::from_array(v.source),
                    pixel00: DVec3::from_array(v.pixel00),
                    u: DVec3::from_array(v.u),
                    v: DVec3::from_array(v.v),
                })
                .collect(),
        };
        return Ok(GeometryFile::Views(vg));
    }
    let beam = match (j.beam, j.sid, j.sdd) {
        (BeamName::Parallel, None, None) => Beam::Parallel,
        (BeamName::Parallel, _, _) => {
            return Err(bad("a parallel beam has no sid/sdd".into()));
        }
        (BeamName::Cone, Some(sid), Some(sdd)) => Beam::Cone { sid, sdd },
        (BeamName::Cone, _, _) => {
            return Err(bad("a cone beam needs both sid and sdd (mm)".into()));
        }
    };
    let angles_deg = match (j.angles_deg, j.angles) {
        (Some(list), None) => list,
        (None, Some(e)) => {
            if e.count == 0 || e.count > MAX_DETECTOR {
                return Err(bad(format!(
                    "angles.count = {} must be in 1..={MAX_DETECTOR}",
                    e.count
                )));
            }
            if !e.range_deg.is_finite() {
                return Err(bad("angles.range_deg is not finite".into()));
            }
            Geometry::even_angles(e.count, e.range_deg)
        }
        _ => {
            return Err(bad(
                "give exactly one of angles_deg (a list), angles ({count, range_deg}) or \
                 views (one per projection)"
                    .into(),
            ))
        }
    };
    let (dcu, dcv) = match beam {
        Beam::Parallel => ((j.cols / 2) as f64, (j.rows as f64 - 1.0) / 2.0),
        Beam::Cone { .. } => ((j.cols as f64 - 1.0) / 2.0, (j.rows as f64 - 1.0) / 2.0),
    };
    let g = Geometry {
        beam,
        angles_deg,
        cols: j.cols,
        rows: j.rows,
        du: j.du.unwrap_or(1.0),
        dv: j.dv.unwrap_or(1.0),
        cu: j.cu.unwrap_or(dcu),
        cv: j.cv.unwrap_or(dcv),
        views: None,
    };
    g.validate().map_err(|e| match e {
        Error::Invalid { message, .. } | Error::TooLarge { message, .. } => bad(message),
        other => other,
    })?;
    Ok(GeometryFile::Circular(g))
}

/// The formats of a CT geometry file, told apart by their contents
/// ([`detect_geometry_format`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GeometryFormat {
    /// voxlab's JSON (module docs): an object with `beam`.
    Voxlab,
    /// ASTRA's `proj_geom` as JSON ([`super::astra_geometry`]): an object with `type`.
    Astra,
    /// RTK's geometry XML ([`super::rtk_geometry`]): an XML document.
    Rtk,
}

impl GeometryFormat {
    /// The format's name in messages.
    pub fn name(self) -> &'static str {
        match self {
            GeometryFormat::Voxlab => "voxlab geometry JSON",
            GeometryFormat::Astra => "ASTRA proj_geom JSON",
            GeometryFormat::Rtk => "RTK geometry XML",
        }
    }
}

/// What a geometry file describes: voxlab's circular [`Geometry`], or views given one
/// by one (RTK's XML, ASTRA's geometries, voxlab's per-view JSON).
#[derive(Clone, Debug, PartialEq)]
pub enum GeometryFile {
    Circular(Geometry),
    Views(ViewGeometry),
}

impl GeometryFile {
    /// The [`Geometry`] ([`Geometry::from_views`] for views); `path` names the file in
    /// errors.
    ///
    /// # Errors
    /// [`Geometry::from_views`]'s, as [`Error::Format`] naming the file.
    pub fn into_geometry(self, path: &Path) -> Result<Geometry> {
        match self {
            GeometryFile::Circular(g) => Ok(g),
            GeometryFile::Views(v) => Geometry::from_views(v).map_err(|e| match e {
                Error::Invalid { message, .. } | Error::TooLarge { message, .. } => {
                    Error::format(path, "views", message)
                }
                other => other,
            }),
        }
    }
}

/// Which geometry format `text` is in: an XML document (it starts with `<`) is RTK's;
/// a JSON object with a `type` key is ASTRA's, one without is voxlab's. `None` for
/// anything else.
pub fn detect_geometry_format(text: &str) -> Option<GeometryFormat> {
    let t = text.strip_prefix('\u{feff}').unwrap_or(text).trim_start();
    if t.starts_with('<') {
        Some(GeometryFormat::Rtk)
    } else if t.starts_with('{') {
        Some(if super::astra_geometry::json_type(t).is_some() {
            GeometryFormat::Astra
        } else {
            GeometryFormat::Voxlab
        })
    } else {
        None
    }
}

/// Parses a geometry file's text in any of the formats ([`detect_geometry_format`];
/// `path` only names it in errors). An RTK file needs the projections' `detector`
/// grid (its pixels are not in the file); the other formats ignore it. Views are
/// checked to describe a beam and a detector ([`check_view_geometry`]).
///
/// # Errors
/// [`Error::Format`] naming the file and the field: an unknown format, an RTK file
/// without `detector`, and each reader's errors.
pub fn parse_geometry(
    text: &str,
    path: &Path,
    detector: Option<&DetectorGrid>,
) -> Result<GeometryFile> {
    let Some(format) = detect_geometry_format(text) else {
        return Err(Error::format(
            path,
            "geometry",
            "not a geometry file: voxlab's and ASTRA's are JSON objects { … }, RTK's is \
             XML <RTKThreeDCircularGeometry …>",
        ));
    };
    let file = match format {
        GeometryFormat::Voxlab => parse_voxlab_geometry(text, path)?,
        GeometryFormat::Astra => GeometryFile::Views(
            super::astra_geometry::parse_astra_geometry(text, path)?.view_geometry(),
        ),
        GeometryFormat::Rtk => {
            let rtk = super::rtk_geometry::parse_rtk_geometry(text, path)?;
            let Some(grid) = detector else {
                return Err(Error::format(
                    path,
                    "detector",
                    "an RTK geometry does not hold the detector's pixels: they come from \
                     the projection image (its size, spacing and origin), which must be \
                     given with it",
                ));
            };
            GeometryFile::Views(rtk.view_geometry(grid).map_err(|e| e.in_file(path))?)
        }
    };
    if let GeometryFile::Views(v) = &file {
        check_view_geometry(v).map_err(|e| match e {
            Error::Invalid { message, .. } | Error::TooLarge { message, .. } => {
                Error::format(path, "views", message)
            }
            other => other,
        })?;
    }
    Ok(file)
}

/// [`parse_geometry`] of a file's bytes (what the fuzz targets call): at most
/// [`MAX_GEOMETRY_BYTES`] of UTF-8 text.
///
/// # Errors
/// As [`parse_geometry`]; bytes that are not UTF-8 text or too many.
pub fn parse_geometry_bytes(
    bytes: &[u8],
    path: &Path,
    detector: Option<&DetectorGrid>,
) -> Result<GeometryFile> {
    if bytes.len() as u64 > MAX_GEOMETRY_BYTES {
        return Err(Error::too_large(
            format!("geometry {}", path.display()),
            format!("{} bytes (at most {MAX_GEOMETRY_BYTES})", bytes.len()),
        ));
    }
    let text = std::str::from_utf8(bytes)
        .map_err(|e| Error::format(path, "geometry", format!("not UTF-8 text: {e}")))?;
    parse_geometry(text, path, detector)
}

/// The most bytes a geometry file may have: RTK writes about 700 bytes per projection,
/// so [`MAX_DETECTOR`] projections fit.
pub const MAX_GEOMETRY_BYTES: u64 = 64 << 20;

/// Reads a geometry file in any format ([`parse_geometry`]).
///
/// # Errors
/// As [`parse_geometry`]; I/O errors; files over [`MAX_GEOMETRY_BYTES`].
pub fn read_geometry_file(path: &Path, detector: Option<&DetectorGrid>) -> Result<GeometryFile> {
    let text = read_small_text(path)?;
    parse_geometry(&text, path, detector)
}

/// Reads a geometry file in any format as a [`Geometry`]: voxlab's JSON, ASTRA's
/// `proj_geom` JSON, or RTK's XML with the projections' `detector` grid
/// ([`read_projections_grid`] gives it from a MetaImage or NRRD stack;
/// [`DetectorGrid::centred`] is RTK's default for given sizes and spacings).
///
/// # Errors
/// As [`read_geometry_file`] and [`GeometryFile::into_geometry`].
pub fn read_geometry_with(path: &Path, detector: Option<&DetectorGrid>) -> Result<Geometry> {
    read_geometry_file(path, detector)?.into_geometry(path)
}

/// Reads a geometry file ([`read_geometry_with`] without a detector grid: RTK's XML is
/// refused, every other format read).
pub fn read_geometry(path: &Path) -> Result<Geometry> {
    read_geometry_with(path, None)
}

/// Writes a geometry JSON file, atomically.
pub fn write_geometry(path: &Path, g: &Geometry) -> Result<()> {
    g.validate()?;
    let text = geometry_to_json(g);
    super::write_atomic(path, |w| {
        w.write_all(text.as_bytes()).map_err(|e| Error::io(path, e))
    })
}

/// Writes a geometry given view by view as voxlab's per-view JSON, atomically.
///
/// # Errors
/// [`check_view_geometry`]'s; I/O errors.
pub fn write_view_geometry(path: &Path, g: &ViewGeometry) -> Result<()> {
    check_view_geometry(g)?;
    let text = view_geometry_to_json(g);
    super::write_atomic(path, |w| {
        w.write_all(text.as_bytes()).map_err(|e| Error::io(path, e))
    })
}

/// Checks that views describe a beam and a detector: sizes in `1..=`[`MAX_DETECTOR`],
/// finite vectors within [`crate::ct::MAX_LENGTH_MM`], pixel steps `u`, `v` that span a
/// plane, a cone-beam source off the detector plane, a parallel ray across it.
///
/// # Errors
/// [`Error::Invalid`] naming the view and the vector; [`Error::TooLarge`].
pub fn check_view_geometry(g: &ViewGeometry) -> Result<()> {
    let what = "CT views";
    for (name, n) in [
        ("detector columns", g.cols),
        ("detector rows", g.rows),
        ("views", g.views.len()),
    ] {
        if n == 0 {
            return Err(Error::invalid(what, format!("no {name}")));
        }
        if n > MAX_DETECTOR {
            return Err(Error::too_large(
                what,
                format!("{n} {name} (at most {MAX_DETECTOR})"),
            ));
        }
    }
    for (k, v) in g.views.iter().enumerate() {
        for (name, x) in [
            ("source", v.source),
            ("pixel00", v.pixel00),
            ("u", v.u),
            ("v", v.v),
        ] {
            if !x.is_finite() || x.abs().max_element() > crate::ct::MAX_LENGTH_MM {
                return Err(Error::invalid(
                    what,
                    format!(
                        "view {k}: {name} {:?} is not finite within ±{:e} mm",
                        x.to_array(),
                        crate::ct::MAX_LENGTH_MM
                    ),
                ));
            }
        }
        let n = v.u.cross(v.v);
        let (lu, lv) = (v.u.length(), v.v.length());
        if lu < crate::ct::MIN_LENGTH_MM
            || lv < crate::ct::MIN_LENGTH_MM
            || n.length() <= 1e-9 * lu * lv
        {
            return Err(Error::invalid(
                what,
                format!(
                    "view {k}: the pixel steps u {:?} and v {:?} do not span a detector plane",
                    v.u.to_array(),
                    v.v.to_array()
                ),
            ));
        }
        let n = n.normalize();
        let across = if g.parallel {
            v.source.dot(n).abs() / v.source.length()
        } else {
            (v.source - v.pixel00).dot(n).abs() / (v.source - v.pixel00).length()
        };
        if across.is_nan() || across <= 1e-9 {
            return Err(Error::invalid(
                what,
                format!(
                    "view {k}: {} (source {:?})",
                    if g.parallel {
                        "the rays run along the detector plane"
                    } else {
                        "the source lies in the detector plane"
                    },
                    v.source.to_array()
                ),
            ));
        }
    }
    Ok(())
}

/// Reads a list of angles in degrees: one per line, blank lines and `#` comments
/// ignored. Fails on anything that is not a finite number, and on an empty list.
pub fn read_angles_txt(path: &Path) -> Result<Vec<f64>> {
    let text = read_small_text(path)?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let body = line.split('#').next().unwrap_or("").trim();
        if body.is_empty() {
            continue;
        }
        match body.parse::<f64>() {
            Ok(a) if a.is_finite() => out.push(a),
            _ => {
                return Err(Error::format(
                    path,
                    format!("line {}", n + 1),
                    format!(
                        "'{}' is not a finite angle in degrees",
                        super::snippet(body)
                    ),
                ))
            }
        }
        if out.len() > MAX_DETECTOR {
            return Err(Error::too_large(
                format!("angles {}", path.display()),
                format!("more than {MAX_DETECTOR} angles"),
            ));
        }
    }
    if out.is_empty() {
        return Err(Error::format(path, "angles", "the file lists no angles"));
    }
    Ok(out)
}

/// Reads a text file of at most 64 MiB (geometry and angle files are tiny).
fn read_small_text(path: &Path) -> Result<String> {
    super::read_text_limited(path, "text file", 64 << 20)
}

fn extension(path: &Path) -> Option<String> {
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
}

fn unsupported(path: &Path) -> Error {
    Error::invalid(
        "projection file",
        format!(
            "{}: projections are written as .npy, .nrrd or .nhdr",
            path.display()
        ),
    )
}
