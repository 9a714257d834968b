//! Volumes, phantoms and transfer functions: `voxlab.read`, `voxlab.write`,
//! `voxlab.phantom`, `voxlab.TransferFunction`.

use crate::{arrays, errors, job};
use glam::DVec3;
use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use voxlab::jobs::input::VolumeInput;
use voxlab::phantom::Phantom;
use voxlab::transfer::TransferFunction;

/// What `read` and `phantom` hand to the Python half: the array, the affine (rows),
/// the format's name and the voxel type's name.
type VolumeParts = (Py<PyAny>, [[f64; 4]; 4], String, String);

fn parts(py: Python<'_>, v: voxlab::volume::AnyVolume, format: &str) -> PyResult<VolumeParts> {
    let affine = arrays::rows(v.affine());
    let kind = v.kind().name().to_string();
    Ok((
        arrays::from_volume(py, v)?,
        affine,
        format.to_string(),
        kind,
    ))
}

/// Reads any volume `voxlab info` reads (a file, a DICOM directory, `phantom:…`),
/// NaN and infinities kept.
#[pyfunction]
#[pyo3(signature = (source, raw_json=None, frame=None))]
fn read_volume(
    py: Python<'_>,
    source: String,
    raw_json: Option<String>,
    frame: Option<usize>,
) -> PyResult<VolumeParts> {
    let mut input = VolumeInput::new(source);
    input.load.frame = frame;
    if let Some(j) = raw_json {
        input.load.raw = Some(errors::parse_request(py, "raw layout", &j)?);
    }
    let (v, format) = job::run(py, None, |_| {
        let format = input.format_name()?;
        Ok((input.read()?, format))
    })?;
    parts(py, v, format)
}

/// `voxlab info --json` of a source (or of an array with its affine), as JSON text.
#[pyfunction]
#[pyo3(signature = (source, bins, volume=None, affine=None))]
fn volume_info(
    py: Python<'_>,
    source: String,
    bins: usize,
    volume: Option<Bound<'_, PyAny>>,
    affine: Option<[[f64; 4]; 4]>,
) -> PyResult<String> {
    let input = match &volume {
        Some(v) => {
            let a = affine.unwrap_or(arrays::rows(glam::DMat4::IDENTITY));
            VolumeInput::memory(source, arrays::volume(py, v, a)?)
        }
        None => VolumeInput::new(source),
    };
    let info = job::run(py, None, |_| voxlab::jobs::info::run(&input, bins, false))?;
    serde_json::to_string(&info).map_err(|e| errors::raise(py, "InternalError", &e.to_string()))
}

/// Writes a volume by extension (`.nrrd`, `.nhdr`, `.nii`, `.nii.gz`, `.mha`, `.mhd`,
/// `.npy`); `nifti_version` 1 or 2 chooses the NIfTI header.
#[pyfunction]
#[pyo3(signature = (path, array, affine, nifti_version=None))]
fn write_volume(
    py: Python<'_>,
    path: std::path::PathBuf,
    array: &Bound<'_, PyAny>,
    affine: [[f64; 4]; 4],
    nifti_version: Option<u8>,
) -> PyResult<()> {
    use voxlab::io::nifti::{write_nifti_version, NiftiVersion};
    let v = arrays::volume(py, array, affine)?;
    let version = match nifti_version {
        None => None,
        Some(1) => Some(NiftiVersion::One),
        Some(2) => Some(NiftiVersion::Two),
        Some(other) => {
            return Err(errors::raise(
                py,
                "InvalidError",
                &format!("invalid nifti_version: {other} (1 or 2)"),
            ))
        }
    };
    let name = path.to_string_lossy().to_ascii_lowercase();
    let nifti = name.ends_with(".nii") || name.ends_with(".nii.gz");
    job::run(py, None, |_| match version {
        Some(version) if nifti => write_nifti_version(&path, &v, version),
        Some(_) => Err(voxlab::Error::invalid(
            "nifti_version",
            format!("{} is not a .nii or .nii.gz file", path.display()),
        )),
        None => voxlab::io::write_volume(&path, &v),
    })
}

/// How the library holds an array given as a volume: whether it reads the array's own
/// buffer (the copy rule of docs/python.md) and the address of the voxels it reads.
#[pyfunction]
fn _volume_buffer(py: Python<'_>, array: &Bound<'_, PyAny>) -> PyResult<(bool, usize)> {
    let v = arrays::volume(py, array, arrays::rows(glam::DMat4::IDENTITY))?;
    let address = voxlab::with_volume!(&v, x => x.data().as_ptr() as usize);
    Ok((arrays::is_borrowed(&v), address))
}

/// A phantom sampled at the voxel centres (`voxlab phantom`).
#[pyfunction]
fn sample_phantom(py: Python<'_>, spec: String) -> PyResult<VolumeParts> {
    let s = job::run(py, None, |_| voxlab::jobs::phantom::run(&spec))?;
    parts(py, s.volume, "analytic phantom")
}

fn phantom_by_name(py: Python<'_>, name: &str) -> PyResult<Phantom> {
    let name = name.strip_prefix("phantom:").unwrap_or(name);
    Phantom::by_name(name).map_err(|e| errors::to_py(py, &e))
}

/// `(n, 3)` float64 rows as points.
fn points(py: Python<'_>, a: &PyReadonlyArrayDyn<'_, f64>, what: &str) -> PyResult<Vec<DVec3>> {
    let s = a
        .as_slice()
        .map_err(|_| errors::raise(py, "LayoutError", &format!("{what} must be C-contiguous")))?;
    if a.ndim() != 2 || a.shape()[1] != 3 {
        return Err(errors::raise(
            py,
            "ShapeError",
            &format!(
                "{what} is an (n, 3) array of x, y, z; got shape {:?}",
                a.shape()
            ),
        ));
    }
    Ok(s.chunks(3).map(|p| DVec3::new(p[0], p[1], p[2])).collect())
}

use numpy::PyUntypedArrayMethods;

/// The exact phantom values at world points (mm).
#[pyfunction]
fn phantom_values(
    py: Python<'_>,
    name: String,
    world: PyReadonlyArrayDyn<'_, f64>,
) -> PyResult<Py<PyAny>> {
    let ph = phantom_by_name(py, &name)?;
    let pts = points(py, &world, "points")?;
    let v: Vec<f64> = job::run(py, None, |_| {
        Ok(pts.iter().map(|&p| ph.value_world(p)).collect())
    })?;
    Ok(v.into_pyarray(py).into_any().unbind())
}

/// The exact line integrals `∫ f(o + t d) |d| dt` over `[t0, t1]` (world mm).
#[pyfunction]
fn phantom_line_integrals(
    py: Python<'_>,
    name: String,
    origins: PyReadonlyArrayDyn<'_, f64>,
    directions: PyReadonlyArrayDyn<'_, f64>,
    t0: f64,
    t1: f64,
) -> PyResult<Py<PyAny>> {
    let ph = phantom_by_name(py, &name)?;
    let o = points(py, &origins, "origins")?;
    let d = points(py, &directions, "directions")?;
    if o.len() != d.len() {
        return Err(errors::raise(
            py,
            "ShapeError",
            &format!("{} origins but {} directions", o.len(), d.len()),
        ));
    }
    let v: Vec<f64> = job::run(py, None, |_| {
        Ok(o.iter()
            .zip(&d)
            .map(|(&o, &d)| ph.line_integral_world(o, d, t0, t1))
            .collect())
    })?;
    Ok(v.into_pyarray(py).into_any().unbind())
}

/// The names of the phantoms.
#[pyfunction]
fn phantom_names() -> Vec<&'static str> {
    voxlab::phantom::PHANTOM_NAMES.to_vec()
}

/// The 1D transfer-function presets' names.
#[pyfunction]
fn tf_presets() -> Vec<&'static str> {
    voxlab::transfer::PRESETS.iter().map(|(n, _)| *n).collect()
}

/// A preset as JSON.
#[pyfunction]
fn tf_preset(py: Python<'_>, name: &str) -> PyResult<String> {
    voxlab::jobs::tf::get(name)
        .map(|t| t.to_json())
        .map_err(|e| errors::to_py(py, &e))
}

fn tf_parse(py: Python<'_>, json: &str) -> PyResult<TransferFunction> {
    TransferFunction::from_json(json).map_err(|e| errors::to_py(py, &e))
}

/// A transfer function's JSON, parsed, validated and written back.
#[pyfunction]
fn tf_normalise(py: Python<'_>, json: &str) -> PyResult<String> {
    Ok(tf_parse(py, json)?.to_json())
}

/// RGBA (with faux shading when on) at raw data values: the window map, then the
/// control points.
#[pyfunction]
fn tf_eval(py: Python<'_>, json: &str, values: PyReadonlyArrayDyn<'_, f64>) -> PyResult<Py<PyAny>> {
    let tf = tf_parse(py, json)?;
    let n = values.len();
    let vals = values.as_array().iter().copied().collect::<Vec<f64>>();
    let mut out = Vec::with_capacity(n * 4);
    for v in vals {
        out.extend(tf.eval_shaded(tf.window.apply(v)));
    }
    Ok(out.into_pyarray(py).reshape([n, 4])?.into_any().unbind())
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(_volume_buffer, m)?)?;
    m.add_function(wrap_pyfunction!(read_volume, m)?)?;
    m.add_function(wrap_pyfunction!(write_volume, m)?)?;
    m.add_function(wrap_pyfunction!(volume_info, m)?)?;
    m.add_function(wrap_pyfunction!(sample_phantom, m)?)?;
    m.add_function(wrap_pyfunction!(phantom_values, m)?)?;
    m.add_function(wrap_pyfunction!(phantom_line_integrals, m)?)?;
    m.add_function(wrap_pyfunction!(phantom_names, m)?)?;
    m.add_function(wrap_pyfunction!(tf_presets, m)?)?;
    m.add_function(wrap_pyfunction!(tf_preset, m)?)?;
    m.add_function(wrap_pyfunction!(tf_normalise, m)?)?;
    m.add_function(wrap_pyfunction!(tf_eval, m)?)?;
    Ok(())
}
