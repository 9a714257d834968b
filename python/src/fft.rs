//! The one transform under `voxlab.fft`: complex to complex along given axes, in
//! f64 on the CPU ([`voxlab::jobs::fft::transform_axes`]: RustFFT, or the exact DFT),
//! or in f32 on the GPU over every axis ([`voxlab::gpu::fft`]). The Python half builds
//! numpy.fft's whole namespace on it (padding, real transforms, norms, dtypes).

use crate::{errors, job};
use numpy::{Complex64, IntoPyArray, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use rustfft::num_complex::Complex;
use voxlab::cpu::dft::{Direction, Normalization};

fn direction(forward: bool) -> Direction {
    if forward {
        Direction::Forward
    } else {
        Direction::Inverse
    }
}

/// `a` (complex128, C-contiguous) transformed along `axes`, times `scale`.
#[pyfunction]
#[pyo3(signature = (a, axes, forward, scale, exact=false))]
fn c2c(
    py: Python<'_>,
    a: PyReadonlyArrayDyn<'_, Complex64>,
    axes: Vec<usize>,
    forward: bool,
    scale: f64,
    exact: bool,
) -> PyResult<Py<PyAny>> {
    let shape = a.shape().to_vec();
    let mut data: Vec<Complex<f64>> = a
        .as_slice()
        .map_err(|_| errors::raise(py, "LayoutError", "the FFT input must be C-contiguous"))?
        .to_vec();
    job::run(py, None, |_| {
        voxlab::jobs::fft::transform_axes(
            &mut data,
            &shape,
            &axes,
            direction(forward),
            scale,
            exact,
        )
    })?;
    Ok(data.into_pyarray(py).reshape(shape)?.into_any().unbind())
}

/// `a` transformed along every axis on the GPU in f32 (any lengths: Bluestein's algorithm
/// for those that are not powers of two), times `scale`; returns complex64.
#[pyfunction]
fn c2c_gpu(
    py: Python<'_>,
    a: PyReadonlyArrayDyn<'_, Complex64>,
    forward: bool,
    scale: f64,
) -> PyResult<Py<PyAny>> {
    let shape = a.shape().to_vec();
    let data: Vec<Complex<f32>> = a
        .as_slice()
        .map_err(|_| errors::raise(py, "LayoutError", "the FFT input must be C-contiguous"))?
        .iter()
        .map(|v| Complex::new(v.re as f32, v.im as f32))
        .collect();
    let out = job::run(py, None, |_| {
        let ctx = voxlab::gpu::GpuContext::shared()?;
        let mut out = voxlab::gpu::fft::fft_nd(
            ctx,
            &data,
            &shape,
            direction(forward),
            Normalization::None,
            voxlab::gpu::fft::GpuFftVariant::Stockham,
        )?;
        if scale != 1.0 {
            let s = scale as f32;
            out.iter_mut().for_each(|v| *v *= s);
        }
        Ok(out)
    })?;
    Ok(out.into_pyarray(py).reshape(shape)?.into_any().unbind())
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(c2c, m)?)?;
    m.add_function(wrap_pyfunction!(c2c_gpu, m)?)?;
    Ok(())
}
