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
//! # Angle lists
//!
//! [`read_angles_txt`]: one angle in degrees per line; blank lines and `#` comments
//! (whole-line or trailing) are ignored.

use super::npy::{npy_float_shape, read_npy_f64, read_npy_f64_lines, write_npy_f32, write_npy_f64};
use super::nrrd::{write_nrrd, NrrdWriteOptions};
use super::{choose_frame, read_volume_with, ReadOptions};
use crate::ct::{Beam, Geometry, Projections, MAX_DETECTOR};
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
    if path.is_file() && extension(path).as_deref() == Some("npy") {
        choose_frame(path, "frame", 1, "", options.frame)?;
        let (shape, values, _) = read_npy_f64(path)?;
        return Ok((shape, values));
    }
    let vol = read_volume_with(path, options)?;
    let [nx, ny, nz] = vol.dims();
    let shape = if nz == 1 {
        vec![ny, nx]
    } else {
        vec![nz, ny, nx]
    };
    Ok((shape, vol.values_f64()))
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

/// The `(angles, rows, cols)` of a projection file that can be read detector line by
/// detector line ([`read_projection_lines`]): a 3-D C-order float `.npy` stack. `None`
/// for every other file [`read_projections`] reads (read whole).
///
/// # Errors
/// A `.npy` file whose header is bad or whose data is short.
pub fn projection_shape(path: &Path) -> Result<Option<[usize; 3]>> {
    if extension(path).as_deref() != Some("npy") {
        return Ok(None);
    }
    Ok(match npy_float_shape(path)? {
        (shape, false) if shape.len() == 3 => Some([shape[0], shape[1], shape[2]]),
        _ => None,
    })
}

/// [`read_projections`] of a stack [`projection_shape`] accepts, reading only the
/// detector lines `lines` (line `a·rows + r` is row `r` of view `a`); every other line
/// is zero. The values read are checked as [`read_projections`] checks them.
///
/// # Errors
/// As [`read_projections`]; a line past the stack.
pub fn read_projection_lines<R: Real>(path: &Path, lines: &[usize]) -> Result<Projections<R>> {
    let (shape, values) = read_npy_f64_lines(path, lines)?;
    from_array(path, &shape, values)
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
            format!("sample {k} is {} (projections must be finite)", values[k]),
        ));
    }
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
    #[serde(default = "one")]
    du: f64,
    #[serde(default = "one")]
    dv: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cu: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cv: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    angles_deg: Option<Vec<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    angles: Option<EvenAngles>,
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
];

fn one() -> f64 {
    1.0
}

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

/// The geometry as JSON text (always with the explicit `angles_deg` list).
pub fn geometry_to_json(g: &Geometry) -> String {
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
        du: g.du,
        dv: g.dv,
        cu: Some(g.cu),
        cv: Some(g.cv),
        angles_deg: Some(g.angles_deg.clone()),
        angles: None,
    };
    serde_json::to_string_pretty(&j).expect("plain numbers serialise") + "\n"
}

/// Parses geometry JSON text (`path` only names it in errors) and validates it.
pub fn geometry_from_json(text: &str, path: &Path) -> Result<Geometry> {
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
                "give exactly one of angles_deg (a list) or angles ({count, range_deg})".into(),
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
        du: j.du,
        dv: j.dv,
        cu: j.cu.unwrap_or(dcu),
        cv: j.cv.unwrap_or(dcv),
        views: None,
    };
    g.validate().map_err(|e| match e {
        Error::Invalid { message, .. } | Error::TooLarge { message, .. } => bad(message),
        other => other,
    })?;
    Ok(g)
}

/// Reads a geometry JSON file.
pub fn read_geometry(path: &Path) -> Result<Geometry> {
    let text = read_small_text(path)?;
    geometry_from_json(&text, path)
}

/// Writes a geometry JSON file, atomically.
pub fn write_geometry(path: &Path, g: &Geometry) -> Result<()> {
    g.validate()?;
    let text = geometry_to_json(g);
    super::write_atomic(path, |w| {
        w.write_all(text.as_bytes()).map_err(|e| Error::io(path, e))
    })
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
