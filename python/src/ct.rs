//! `voxlab.transform.iradon`: filtered backprojection of a scikit-image sinogram by
//! the reconstruct job ([`voxlab::jobs::reconstruct::reconstruct`]), in memory.

use crate::{errors, job};
use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use voxlab::cpu::ramp::RampFilter;
use voxlab::ct::{Geometry, Projections};
use voxlab::jobs::reconstruct::{reconstruct, ReconstructRequest};
use voxlab::jobs::Backend;

/// FBP of a float64 `(detector, angle)` sinogram taken at `theta` (degrees) onto an
/// `output_size`² image in scikit-image's orientation, masked to the inscribed circle
/// when `circle` (the sinogram is then padded as `iradon` pads it).
#[pyfunction]
#[pyo3(signature = (sinogram, theta, output_size, filter, circle, backend, progress=None))]
#[allow(clippy::too_many_arguments)]
fn fbp_parallel(
    py: Python<'_>,
    sinogram: PyReadonlyArrayDyn<'_, f64>,
    theta: Vec<f64>,
    output_size: usize,
    filter: &str,
    circle: bool,
    backend: &str,
    progress: Option<Bound<'_, PyAny>>,
) -> PyResult<Py<PyAny>> {
    let shape = sinogram.shape().to_vec();
    if shape.len() != 2 {
        return Err(errors::raise(py, "ShapeError", "the sinogram must be 2-D"));
    }
    let (cols, angles) = (shape[0], shape[1]);
    let filter: RampFilter = filter.parse().map_err(|e| errors::to_py(py, &e))?;
    let backend: Backend = backend.parse().map_err(|e| errors::to_py(py, &e))?;
    let s = sinogram
        .as_slice()
        .map_err(|_| errors::raise(py, "LayoutError", "the sinogram must be C-contiguous"))?;
    // (detector, angle) → the one-row stack (angle, 1, detector).
    let mut data = vec![0.0; cols * angles];
    for (c, row) in s.chunks(angles).enumerate() {
        for (k, &v) in row.iter().enumerate() {
            data[k * cols + c] = v;
        }
    }
    let req = ReconstructRequest {
        filter,
        size: Some(output_size),
        no_circle: !circle,
        backend,
        ..Default::default()
    };
    let rec = job::run(py, job::callback(&progress), |p| {
        let proj = Projections::new(angles, 1, cols, data)?;
        let g = Geometry::parallel_skimage(cols, theta)?;
        reconstruct(&req, proj, g, None, p)
    })?;
    let d = rec.reconstruction.grid.dims;
    Ok(rec
        .reconstruction
        .data
        .into_pyarray(py)
        .reshape([d[1], d[0]])?
        .into_any()
        .unbind())
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(fbp_parallel, m)?)?;
    Ok(())
}
