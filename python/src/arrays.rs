//! NumPy arrays to and from the library's volumes and frames.
//!
//! Volumes are `(nz, ny, nx)` arrays, x fastest: exactly the library's memory order,
//! so a C-contiguous array of a voxel type is lent to the library without a copy
//! (`Volume::shared`: the volume reads the array's buffer and keeps the array alive)
//! and results come back as NumPy arrays that take over the Rust buffer without a
//! copy. The Python half makes other layouts contiguous first (documented in
//! docs/python.md) and checks dtypes and shapes.

use crate::errors;
use glam::DMat4;
use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use std::sync::Arc;
use voxlab::frame::Frame;
use voxlab::volume::{AnyVolume, SharedVoxels, Volume};

/// A row-major 4×4 matrix (`m[row][col]`) as glam's column-major matrix.
pub fn mat4(m: [[f64; 4]; 4]) -> DMat4 {
    DMat4::from_cols_array_2d(&m).transpose()
}

/// A matrix as rows.
pub fn rows(m: DMat4) -> [[f64; 4]; 4] {
    m.transpose().to_cols_array_2d()
}

/// The slice of a C-contiguous array of `T`, or a TypeError naming what it needs.
fn slice_of<'a, T: numpy::Element>(
    py: Python<'_>,
    a: &'a PyReadonlyArrayDyn<'_, T>,
    what: &str,
) -> PyResult<&'a [T]> {
    a.as_slice().map_err(|_| {
        errors::raise(
            py,
            "LayoutError",
            &format!("{what} must be C-contiguous (np.ascontiguousarray makes it so)"),
        )
    })
}

/// A NumPy array's buffer lent to a volume without a copy ([`Volume::shared`]): the
/// array object travels with it and keeps the buffer alive.
struct NumpyVoxels<T> {
    _array: Py<PyAny>,
    ptr: *const T,
    len: usize,
}

// SAFETY: the buffer is plain voxels at a fixed address for as long as `_array` keeps
// the array alive (an array never moves its data); it is only read. The package's
// rule (docs/python.md: the copy rule) is that an array is not written while a call
// that reads it runs, the same rule NumPy's own GIL-releasing functions follow.
unsafe impl<T: Sync> Send for NumpyVoxels<T> {}
unsafe impl<T: Sync> Sync for NumpyVoxels<T> {}

impl<T: Send + Sync> SharedVoxels<T> for NumpyVoxels<T> {
    fn voxels(&self) -> &[T] {
        if self.len == 0 {
            return &[];
        }
        // SAFETY: `ptr` and `len` come from the C-contiguous, aligned array's slice,
        // which `_array` keeps alive (see the Send/Sync note above).
        unsafe { std::slice::from_raw_parts(self.ptr, self.len) }
    }
}

/// The voxels of a C-contiguous, aligned, native-order array of `T`, borrowed.
fn borrowed<T: numpy::Element + Send + Sync + 'static>(
    py: Python<'_>,
    a: &Bound<'_, PyAny>,
    x: &PyReadonlyArrayDyn<'_, T>,
) -> PyResult<Arc<dyn SharedVoxels<T>>> {
    let s = slice_of(py, x, "the volume")?;
    if !(s.as_ptr() as usize).is_multiple_of(std::mem::align_of::<T>()) {
        return Err(errors::raise(
            py,
            "LayoutError",
            "the volume's buffer is not aligned (np.require(a, requirements='CA') makes it so)",
        ));
    }
    Ok(Arc::new(NumpyVoxels {
        _array: a.clone().unbind(),
        ptr: s.as_ptr(),
        len: s.len(),
    }))
}

/// A `(nz, ny, nx)` array as a volume with voxel-to-world `affine`: uint8, uint16,
/// int16 and float32 are borrowed without a copy (the volume reads the array's own
/// buffer, which it keeps alive); float64 is converted to float32 (the library's
/// volumes are f32 at most), a copy.
pub fn volume(py: Python<'_>, a: &Bound<'_, PyAny>, affine: [[f64; 4]; 4]) -> PyResult<AnyVolume> {
    let ndim: usize = a.getattr("ndim")?.extract()?;
    if ndim != 3 {
        return Err(errors::raise(
            py,
            "ShapeError",
            &format!("a volume is a 3-D array (nz, ny, nx); got {ndim} dimensions"),
        ));
    }
    let shape: Vec<usize> = a.getattr("shape")?.extract()?;
    let dims = [shape[2], shape[1], shape[0]];
    let affine = mat4(affine);
    let conv = |r: voxlab::Result<AnyVolume>| r.map_err(|e| errors::to_py(py, &e));
    if let Ok(x) = a.extract::<PyReadonlyArrayDyn<'_, u8>>() {
        let b = borrowed(py, a, &x)?;
        return conv(Volume::shared(dims, affine, b).map(AnyVolume::U8));
    }
    if let Ok(x) = a.extract::<PyReadonlyArrayDyn<'_, u16>>() {
        let b = borrowed(py, a, &x)?;
        return conv(Volume::shared(dims, affine, b).map(AnyVolume::U16));
    }
    if let Ok(x) = a.extract::<PyReadonlyArrayDyn<'_, i16>>() {
        let b = borrowed(py, a, &x)?;
        return conv(Volume::shared(dims, affine, b).map(AnyVolume::I16));
    }
    if let Ok(x) = a.extract::<PyReadonlyArrayDyn<'_, f32>>() {
        let b = borrowed(py, a, &x)?;
        return conv(Volume::shared(dims, affine, b).map(AnyVolume::F32));
    }
    if let Ok(x) = a.extract::<PyReadonlyArrayDyn<'_, f64>>() {
        let s = slice_of(py, &x, "the volume")?;
        let v: Vec<f32> = s.iter().map(|&v| v as f32).collect();
        return conv(Volume::with_affine(dims, affine, v).map(AnyVolume::F32));
    }
    let dtype = a.getattr("dtype")?.str()?.to_string();
    Err(errors::raise(
        py,
        "DtypeError",
        &format!("a volume is uint8, uint16, int16, float32 or float64; got {dtype}"),
    ))
}

/// Whether `v` reads its voxels straight from a NumPy array's buffer (for the tests of
/// the copy rule).
pub fn is_borrowed(v: &AnyVolume) -> bool {
    voxlab::with_volume!(v, x => x.is_shared())
}

/// A volume as a `(nz, ny, nx)` array of its own type (no copy of the voxels).
pub fn from_volume(py: Python<'_>, v: AnyVolume) -> PyResult<Py<PyAny>> {
    let [nx, ny, nz] = v.dims();
    let shape = [nz, ny, nx];
    Ok(match v {
        AnyVolume::U8(v) => v
            .into_data()
            .into_pyarray(py)
            .reshape(shape)?
            .into_any()
            .unbind(),
        AnyVolume::U16(v) => v
            .into_data()
            .into_pyarray(py)
            .reshape(shape)?
            .into_any()
            .unbind(),
        AnyVolume::I16(v) => v
            .into_data()
            .into_pyarray(py)
            .reshape(shape)?
            .into_any()
            .unbind(),
        AnyVolume::F32(v) => v
            .into_data()
            .into_pyarray(py)
            .reshape(shape)?
            .into_any()
            .unbind(),
    })
}

/// A frame as the CLI's `.npy` writes it: float32 `(h, w, 4)` RGBA or `(h, w)`, row 0
/// at the top.
pub fn from_frame(py: Python<'_>, f: &Frame) -> PyResult<Py<PyAny>> {
    let data: Vec<f32> = f.data.iter().map(|&v| v as f32).collect();
    let arr = data.into_pyarray(py);
    Ok(if f.channels == 1 {
        arr.reshape([f.height, f.width])?.into_any().unbind()
    } else {
        arr.reshape([f.height, f.width, f.channels])?
            .into_any()
            .unbind()
    })
}

/// A float64 `(h, w)` or `(h, w, 4)` array as a frame.
pub fn frame(py: Python<'_>, a: &PyReadonlyArrayDyn<'_, f64>, what: &str) -> PyResult<Frame> {
    let shape = a.shape().to_vec();
    let channels = match shape.len() {
        2 => 1,
        3 if shape[2] == 4 => 4,
        _ => {
            return Err(errors::raise(
                py,
                "ShapeError",
                &format!("{what} is an image of shape (h, w) or (h, w, 4); got {shape:?}"),
            ))
        }
    };
    let s = slice_of(py, a, what)?;
    Ok(Frame {
        width: shape[1],
        height: shape[0],
        channels,
        data: s.to_vec(),
    })
}

/// A request's input replaced by an array in memory with its affine (rows; the
/// identity when None), its load options kept; left as it is without an array. Every
/// job that reads a volume takes its array through here.
pub fn memory_input(
    py: Python<'_>,
    input: &mut voxlab::jobs::input::VolumeInput,
    array: Option<&Bound<'_, PyAny>>,
    affine: Option<[[f64; 4]; 4]>,
) -> PyResult<()> {
    if let Some(a) = array {
        let vol = volume(py, a, affine.unwrap_or(rows(DMat4::IDENTITY)))?;
        let load = input.load.clone();
        *input = voxlab::jobs::input::VolumeInput::memory("array", vol).with_load(load);
    }
    Ok(())
}
