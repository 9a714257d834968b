//! `voxlab.transform.radon` and `iradon` (scikit-image's, [`voxlab::jobs::radon`]) and
//! `voxlab.ct`'s projection and reconstruction ([`voxlab::jobs::project`],
//! [`voxlab::jobs::reconstruct`]), in memory.

use crate::{arrays, errors, job};
use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use voxlab::ct::Projections;
use voxlab::io::projections::{geometry_from_json, geometry_to_json, Layout};
use voxlab::jobs::project::ProjectRequest;
use voxlab::jobs::radon::IradonOptions;
use voxlab::jobs::reconstruct::{reconstruct, ReconstructRequest};
use voxlab::jobs::Backend;

/// scikit-image's `iradon` of a float64 `(detector, angle)` sinogram taken at `theta`
/// (degrees) with numpy's `cos`/`sin` of those angles ([`voxlab::jobs::radon::iradon`]):
/// an `output_size`² image summed in float32 when `float32` (scikit-image's rule for a
/// float32 sinogram), else float64.
#[pyfunction]
#[pyo3(signature = (sinogram, theta, cos, sin, output_size, filter, interpolation, circle, backend, float32, progress=None))]
#[allow(clippy::too_many_arguments)]
fn iradon(
    py: Python<'_>,
    sinogram: PyReadonlyArrayDyn<'_, f64>,
    theta: Vec<f64>,
    cos: Vec<f64>,
    sin: Vec<f64>,
    output_size: usize,
    filter: &str,
    interpolation: &str,
    circle: bool,
    backend: &str,
    float32: bool,
    progress: Option<Bound<'_, PyAny>>,
) -> PyResult<Py<PyAny>> {
    let shape = sinogram.shape().to_vec();
    if shape.len() != 2 {
        return Err(errors::raise(py, "ShapeError", "the sinogram must be 2-D"));
    }
    let options = IradonOptions {
        output_size,
        filter: filter.parse().map_err(|e| errors::to_py(py, &e))?,
        interpolation: interpolation.parse().map_err(|e| errors::to_py(py, &e))?,
        circle,
    };
    let backend: Backend = backend.parse().map_err(|e| errors::to_py(py, &e))?;
    let s = sinogram
        .as_slice()
        .map_err(|_| errors::raise(py, "LayoutError", "the sinogram must be C-contiguous"))?;
    let trig: Vec<(f64, f64)> = cos.into_iter().zip(sin).collect();
    let bins = shape[0];
    fn image<A: voxlab::real::Real + numpy::Element>(
        py: Python<'_>,
        r: voxlab::jobs::radon::IradonImage<A>,
    ) -> PyResult<Py<PyAny>> {
        Ok(r.data
            .into_pyarray(py)
            .reshape([r.size, r.size])?
            .into_any()
            .unbind())
    }
    if float32 {
        let r = job::run(py, job::callback(&progress), |p| {
            voxlab::jobs::radon::iradon::<f32>(s, bins, &theta, Some(&trig), &options, backend, p)
        })?;
        image(py, r)
    } else {
        let r = job::run(py, job::callback(&progress), |p| {
            voxlab::jobs::radon::iradon::<f64>(s, bins, &theta, Some(&trig), &options, backend, p)
        })?;
        image(py, r)
    }
}

/// A float64 `(detector, angle)` sinogram or `(angle, row, col)` stack as the library's
/// stack layout: `(angles, rows, cols, data)`, the column fastest.
pub fn projection_stack(
    py: Python<'_>,
    projections: &PyReadonlyArrayDyn<'_, f64>,
) -> PyResult<(usize, usize, usize, Vec<f64>)> {
    let shape = projections.shape().to_vec();
    let s = projections
        .as_slice()
        .map_err(|_| errors::raise(py, "LayoutError", "the projections must be C-contiguous"))?;
    Ok(match shape.len() {
        2 => {
            let (cols, angles) = (shape[0], shape[1]);
            let mut data = vec![0.0; cols * angles];
            for (c, row) in s.chunks(angles).enumerate() {
                for (k, &v) in row.iter().enumerate() {
                    data[k * cols + c] = v;
                }
            }
            (angles, 1, cols, data)
        }
        3 => (shape[0], shape[1], shape[2], s.to_vec()),
        _ => {
            return Err(errors::raise(
                py,
                "ShapeError",
                &format!(
                    "projections are a (detector, angle) sinogram or an (angle, row, col) \
                     stack; got shape {shape:?}"
                ),
            ))
        }
    })
}

/// The golden-ratio order of views `iradon_sart` visits
/// ([`voxlab::cpu::radon::golden_order`]), in the angles' precision (float32 or
/// float64).
#[pyfunction]
fn golden_order(py: Python<'_>, theta: &Bound<'_, PyAny>) -> PyResult<Vec<usize>> {
    if let Ok(t) = theta.extract::<PyReadonlyArrayDyn<'_, f64>>() {
        let v = t
            .as_slice()
            .map_err(|_| errors::raise(py, "LayoutError", "theta must be C-contiguous"))?;
        Ok(voxlab::cpu::radon::golden_order(v))
    } else if let Ok(t) = theta.extract::<PyReadonlyArrayDyn<'_, f32>>() {
        let v = t
            .as_slice()
            .map_err(|_| errors::raise(py, "LayoutError", "theta must be C-contiguous"))?;
        Ok(voxlab::cpu::radon::golden_order(v))
    } else {
        Err(errors::raise(
            py,
            "DtypeError",
            "theta must be float32 or float64",
        ))
    }
}

/// One call of scikit-image's `iradon_sart` ([`voxlab::jobs::radon::iradon_sart`]) on
/// a C-contiguous float32 or float64 `(n, angles)` sinogram, in its precision: `theta`,
/// `image` (`n × n`) and `shifts` of the same dtype; returns the image.
#[pyfunction]
#[pyo3(signature = (sinogram, theta, image, shifts, clip, relaxation, backend, progress=None))]
#[allow(clippy::too_many_arguments)]
fn iradon_sart(
    py: Python<'_>,
    sinogram: &Bound<'_, PyAny>,
    theta: &Bound<'_, PyAny>,
    image: Option<Bound<'_, PyAny>>,
    shifts: Option<Bound<'_, PyAny>>,
    clip: Option<(f64, f64)>,
    relaxation: f64,
    backend: &str,
    progress: Option<Bound<'_, PyAny>>,
) -> PyResult<Py<PyAny>> {
    let backend: Backend = backend.parse().map_err(|e| errors::to_py(py, &e))?;
    #[allow(clippy::too_many_arguments)]
    fn go<R: voxlab::real::Real + numpy::Element>(
        py: Python<'_>,
        sinogram: &Bound<'_, PyAny>,
        theta: &Bound<'_, PyAny>,
        image: Option<Bound<'_, PyAny>>,
        shifts: Option<Bound<'_, PyAny>>,
        clip: Option<(f64, f64)>,
        relaxation: f64,
        backend: Backend,
        progress: Option<Bound<'_, PyAny>>,
    ) -> PyResult<Py<PyAny>> {
        let vec = |a: &Bound<'_, PyAny>, what: &str| -> PyResult<Vec<R>> {
            let x = a.extract::<PyReadonlyArrayDyn<'_, R>>().map_err(|_| {
                errors::raise(
                    py,
                    "DtypeError",
                    &format!("{what} must have the sinogram's dtype"),
                )
            })?;
            Ok(x.as_slice()
                .map_err(|_| {
                    errors::raise(py, "LayoutError", &format!("{what} must be C-contiguous"))
                })?
                .to_vec())
        };
        let sino = sinogram
            .extract::<PyReadonlyArrayDyn<'_, R>>()
            .map_err(|e| errors::raise(py, "DtypeError", &e.to_string()))?;
        let shape = sino.shape().to_vec();
        if shape.len() != 2 {
            return Err(errors::raise(py, "ShapeError", "the sinogram must be 2-D"));
        }
        let s = vec(sinogram, "the sinogram")?;
        let options = voxlab::jobs::radon::SartOptions {
            image: image.as_ref().map(|a| vec(a, "image")).transpose()?,
            shifts: shifts
                .as_ref()
                .map(|a| vec(a, "projection_shifts"))
                .transpose()?,
            clip: clip.map(|(lo, hi)| [R::of(lo), R::of(hi)]),
            relaxation,
        };
        let theta = vec(theta, "theta")?;
        let n = shape[0];
        let out = job::run(py, job::callback(&progress), |p| {
            voxlab::jobs::radon::iradon_sart(&s, n, &theta, &options, backend, p)
        })?;
        Ok(out.into_pyarray(py).reshape([n, n])?.into_any().unbind())
    }
    if sinogram.extract::<PyReadonlyArrayDyn<'_, f64>>().is_ok() {
        go::<f64>(
            py, sinogram, theta, image, shifts, clip, relaxation, backend, progress,
        )
    } else if sinogram.extract::<PyReadonlyArrayDyn<'_, f32>>().is_ok() {
        go::<f32>(
            py, sinogram, theta, image, shifts, clip, relaxation, backend, progress,
        )
    } else {
        Err(errors::raise(
            py,
            "DtypeError",
            "SART takes a float32 or float64 sinogram",
        ))
    }
}

/// What `project` returns: the stack `(angle, row, col)` (float64), the geometry JSON,
/// and the rest as JSON.
type ProjectParts = (Py<PyAny>, String, String);

/// The project job (`voxlab project`) from a JSON request: a phantom (exact line
/// integrals) or a volume (Joseph), parallel or cone beam.
#[pyfunction]
#[pyo3(signature = (request, volume=None, affine=None, progress=None))]
fn project(
    py: Python<'_>,
    request: &str,
    volume: Option<Bound<'_, PyAny>>,
    affine: Option<[[f64; 4]; 4]>,
    progress: Option<Bound<'_, PyAny>>,
) -> PyResult<ProjectParts> {
    let mut req: ProjectRequest = errors::parse_request(py, "project option", request)?;
    arrays::memory_input(py, &mut req.input, volume.as_ref(), affine)?;
    let r = job::run(py, job::callback(&progress), |p| {
        voxlab::jobs::project::run(&req, p)
    })?;
    let meta = serde_json::json!({
        "layout": match r.layout { Layout::Stack => "stack", Layout::Skimage => "skimage" },
        "backend": r.backend.name(),
        "what": r.what,
    });
    let geometry = geometry_to_json(&r.geometry);
    let p = r.projections;
    let shape = [p.angles, p.rows, p.cols];
    let arr = p.data.into_pyarray(py).reshape(shape)?.into_any().unbind();
    Ok((arr, geometry, meta.to_string()))
}

/// A flat- or dark-field argument: a path (any projection format, read by
/// [`voxlab::io::projections::read_field_image`]) or a float64 array (one `(rows, cols)`
/// image or a `(frame, rows, cols)` stack, averaged).
pub enum Field {
    Path(std::path::PathBuf),
    Array(Vec<usize>, Vec<f64>),
}

impl Field {
    fn from_py(
        py: Python<'_>,
        what: &str,
        obj: Option<Bound<'_, PyAny>>,
    ) -> PyResult<Option<Self>> {
        let Some(obj) = obj else { return Ok(None) };
        if obj.is_none() {
            return Ok(None);
        }
        if let Ok(path) = obj.extract::<std::path::PathBuf>() {
            return Ok(Some(Field::Path(path)));
        }
        let arr = obj.extract::<PyReadonlyArrayDyn<'_, f64>>().map_err(|_| {
            errors::raise(
                py,
                "DtypeError",
                &format!("{what} must be a path or a float64 array"),
            )
        })?;
        let shape = arr.shape().to_vec();
        let values = arr
            .as_slice()
            .map_err(|_| errors::raise(py, "LayoutError", &format!("{what} must be C-contiguous")))?
            .to_vec();
        Ok(Some(Field::Array(shape, values)))
    }

    /// The averaged `rows × cols` image.
    fn image(self, what: &str, rows: usize, cols: usize) -> voxlab::Result<Vec<f64>> {
        use voxlab::io::projections::{field_image, read_field_image};
        match self {
            Field::Path(p) => read_field_image(&p, what, rows, cols, &Default::default()),
            Field::Array(shape, values) => field_image(
                std::path::Path::new(&format!("{what} array")),
                what,
                &shape,
                values,
                rows,
                cols,
            ),
        }
    }
}

/// Projections in memory for the reconstruct job: the stack, its geometry JSON and the
/// flat and dark fields that make them line integrals.
pub struct StackInput {
    stack: (usize, usize, usize, Vec<f64>),
    geometry: String,
    flat: Option<Field>,
    dark: Option<Field>,
}

impl StackInput {
    /// The arguments of `reconstruct_stack` (and its dry run), checked: the layout of
    /// the projections, `dark` only with `flat`.
    pub fn new(
        py: Python<'_>,
        projections: &PyReadonlyArrayDyn<'_, f64>,
        geometry: &str,
        flat: Option<Bound<'_, PyAny>>,
        dark: Option<Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let stack = projection_stack(py, projections)?;
        let flat = Field::from_py(py, "flat", flat)?;
        let dark = Field::from_py(py, "dark", dark)?;
        if dark.is_some() && flat.is_none() {
            return Err(errors::raise(
                py,
                "InvalidError",
                "invalid dark: goes with flat: intensities need the flat field",
            ));
        }
        Ok(StackInput {
            stack,
            geometry: geometry.to_string(),
            flat,
            dark,
        })
    }

    /// The projections as line integrals (converted from intensities when there is a
    /// flat field, with the conversion's counts) and their geometry.
    pub fn line_integrals(
        self,
    ) -> voxlab::Result<(
        Projections<f64>,
        voxlab::ct::Geometry,
        Option<voxlab::ct::flat_field::IntensityReport>,
    )> {
        let (angles, rows, cols, data) = self.stack;
        let g = geometry_from_json(&self.geometry, std::path::Path::new("geometry"))?;
        let proj = Projections::new(angles, rows, cols, data)?;
        let Some(flat) = self.flat else {
            return Ok((proj, g, None));
        };
        let f = flat.image("flat", rows, cols)?;
        let d = match self.dark {
            Some(d) => Some(d.image("dark", rows, cols)?),
            None => None,
        };
        let (q, r) = voxlab::ct::flat_field::line_integrals(&proj, &f, d.as_deref())?;
        Ok((q, g, Some(r)))
    }
}

/// The reconstruct job on projections in memory: a float64 `(detector, angle)`
/// sinogram or `(angle, row, col)` stack with its geometry JSON, the options of a JSON
/// [`ReconstructRequest`]. With `flat` (and `dark`), the projections are intensities
/// turned into line integrals first ([`voxlab::ct::flat_field::line_integrals`]).
/// Returns the reconstruction laid out as the CLI's `.npy` (`(n, n)`, `(rows, n, n)` or
/// `(N, N, N)`), its grid's voxel-to-world affine (rows, mm in the CT frame) and the
/// rest as JSON (`intensity`: the conversion's counts).
#[pyfunction]
#[pyo3(signature = (projections, geometry, request, progress=None, flat=None, dark=None))]
fn reconstruct_stack(
    py: Python<'_>,
    projections: PyReadonlyArrayDyn<'_, f64>,
    geometry: &str,
    request: &str,
    progress: Option<Bound<'_, PyAny>>,
    flat: Option<Bound<'_, PyAny>>,
    dark: Option<Bound<'_, PyAny>>,
) -> PyResult<(Py<PyAny>, [[f64; 4]; 4], String)> {
    let req: ReconstructRequest = errors::parse_request(py, "reconstruct option", request)?;
    let input = StackInput::new(py, &projections, geometry, flat, dark)?;
    let rec = job::run(py, job::callback(&progress), |p| {
        let (proj, g, report) = input.line_integrals()?;
        let mut done = reconstruct(&req, proj, g, None, p)?;
        done.intensity = report;
        Ok(done)
    })?;
    let meta = serde_json::json!({
        "intensity": rec.intensity,
        "parallel": rec.parallel,
        "what": rec.what,
        "truth_rms": rec.truth.as_ref().map(|t| t.rms),
        "iterative": rec.iterative.as_ref().map(|l| serde_json::json!({
            "method": l.method.name(),
            "residual": l.residual,
            "objective": l.objective,
            "iterations": l.iterations,
            "converged": l.converged,
            "seconds_per_iteration": l.seconds_per_iteration,
        })),
    });
    let r = rec.reconstruction;
    let d = r.grid.dims;
    let affine = arrays::rows(r.grid.affine);
    let arr = r.data.into_pyarray(py);
    let arr = if d[2] == 1 {
        arr.reshape([d[1], d[0]])?.into_any().unbind()
    } else {
        arr.reshape([d[2], d[1], d[0]])?.into_any().unbind()
    };
    Ok((arr, affine, meta.to_string()))
}

/// The Radon transform of a C-contiguous float32 or float64 `(rows, cols)` image
/// ([`voxlab::jobs::radon::radon`], in the image's precision), one angle per inverse
/// map `[h0 … h5]` (scikit-image's rotation matrix's first two rows, as the Python half
/// computes it): the `(bins, angles)` sinogram of the same dtype.
#[pyfunction]
#[pyo3(signature = (image, maps, circle, backend, progress=None))]
fn radon(
    py: Python<'_>,
    image: &Bound<'_, PyAny>,
    maps: Vec<[f64; 6]>,
    circle: bool,
    backend: &str,
    progress: Option<Bound<'_, PyAny>>,
) -> PyResult<Py<PyAny>> {
    let backend: Backend = backend.parse().map_err(|e| errors::to_py(py, &e))?;
    let cs = maps;
    fn go<R: voxlab::real::Real + numpy::Element>(
        py: Python<'_>,
        a: PyReadonlyArrayDyn<'_, R>,
        cs: &[[f64; 6]],
        circle: bool,
        backend: Backend,
        progress: Option<Bound<'_, PyAny>>,
    ) -> PyResult<Py<PyAny>> {
        let shape = a.shape().to_vec();
        if shape.len() != 2 {
            return Err(errors::raise(py, "ShapeError", "the image must be 2-D"));
        }
        let s = a
            .as_slice()
            .map_err(|_| errors::raise(py, "LayoutError", "the image must be C-contiguous"))?;
        let sino = job::run(py, job::callback(&progress), |p| {
            voxlab::jobs::radon::radon(s, shape[0], shape[1], cs, circle, backend, p)
        })?;
        Ok(sino
            .data
            .into_pyarray(py)
            .reshape([sino.bins, sino.angles])?
            .into_any()
            .unbind())
    }
    if let Ok(a) = image.extract::<PyReadonlyArrayDyn<'_, f64>>() {
        go(py, a, &cs, circle, backend, progress)
    } else if let Ok(a) = image.extract::<PyReadonlyArrayDyn<'_, f32>>() {
        go(py, a, &cs, circle, backend, progress)
    } else {
        Err(errors::raise(
            py,
            "DtypeError",
            "the Radon transform takes a float32 or float64 image",
        ))
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(radon, m)?)?;
    m.add_function(wrap_pyfunction!(iradon, m)?)?;
    m.add_function(wrap_pyfunction!(iradon_sart, m)?)?;
    m.add_function(wrap_pyfunction!(golden_order, m)?)?;
    m.add_function(wrap_pyfunction!(project, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct_stack, m)?)?;
    Ok(())
}
