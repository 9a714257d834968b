"""numpy.fft's namespace and semantics on voxlab's Fourier transforms.

Every transform here is numpy.fft's function of the same name — the same arguments
(``n``/``s``, ``axis``/``axes``, ``norm`` = ``"backward"`` | ``"ortho"`` | ``"forward"``,
``out``), the same output shapes and dtypes (float32/complex64 in → complex64 out,
other inputs → complex128, ``irfft*`` → the matching real type, as numpy 2 does), the
same errors and warnings — built on one primitive: the complex-to-complex transform
along given axes of the library's CPU FFT (RustFFT, computed in float64 with the GIL
released), then rounded to the output dtype. Conventions are numpy's: forward is
``exp(−2πi·kn/N)``, DC at index 0, ``fftshift`` to centre it.

Beyond numpy:

- ``backend="gpu"`` on ``fft``, ``ifft``, ``fft2``, ``ifft2``, ``fftn`` and ``ifftn`` runs
  voxlab's GPU FFT (Stockham, float32; the result is complex64) when the transform
  covers every axis of the array (after ``s``/``n``); otherwise it raises
  :class:`voxlab.UnsupportedError` saying why. Every length is taken: powers of two
  directly, other lengths by Bluestein's algorithm on the GPU. Real transforms run on
  the CPU only.
- :func:`dft`: the exact O(N²) DFT of the library's oracle (``cpu::dft``), float64.

``fftshift``, ``ifftshift``, ``fftfreq`` and ``rfftfreq`` are numpy's own (they move and
count bins; no transform).
"""

from __future__ import annotations

import warnings
from typing import Any, Optional, Sequence

import numpy as np
from numpy.fft import fftfreq, fftshift, ifftshift, rfftfreq

from . import _voxlab
from ._errors import UnsupportedError

try:  # numpy >= 2
    from numpy.lib.array_utils import normalize_axis_index
except ImportError:  # numpy 1.x
    from numpy.core.multiarray import normalize_axis_index  # type: ignore

__all__ = [
    "fft", "ifft", "fft2", "ifft2", "fftn", "ifftn", "rfft", "irfft", "rfft2", "irfft2",
    "rfftn", "irfftn", "hfft", "ihfft", "fftshift", "ifftshift", "fftfreq", "rfftfreq",
    "dft",
]

_SWAP_DIRECTION_MAP = {"backward": "forward", None: "forward", "ortho": "ortho",
                       "forward": "backward"}


def _swap_direction(norm):
    try:
        return _SWAP_DIRECTION_MAP[norm]
    except KeyError:
        raise ValueError(f'Invalid norm value {norm}; should be "backward", '
                         '"ortho" or "forward".') from None


def _factor(norm, n, real_dtype=np.float64):
    """The scale of a forward-direction transform of length ``n`` under ``norm``,
    computed in ``real_dtype`` as numpy computes it (for float16 input numpy's factor
    ``1/n`` is the float16 nearest to it, and so is voxlab's)."""
    if norm is None or norm == "backward":
        return 1.0
    if norm == "ortho":
        return float(np.reciprocal(np.sqrt(n, dtype=real_dtype)))
    if norm == "forward":
        return float(np.reciprocal(n, dtype=real_dtype))
    raise ValueError(f'Invalid norm value {norm}; should be "backward",'
                     '"ortho" or "forward".')


def _fit(a, n, axis):
    """``a`` truncated or zero-padded to length ``n`` along ``axis`` (as pocketfft
    reads its input)."""
    m = a.shape[axis]
    if m == n:
        return a
    if m > n:
        idx = [slice(None)] * a.ndim
        idx[axis] = slice(0, n)
        return a[tuple(idx)]
    shape = list(a.shape)
    shape[axis] = n
    z = np.zeros(shape, dtype=a.dtype)
    idx = [slice(None)] * a.ndim
    idx[axis] = slice(0, m)
    z[tuple(idx)] = a
    return z


def _c2c(x, axes, forward, scale, exact=False):
    x = np.ascontiguousarray(x, dtype=np.complex128)
    return _voxlab.c2c(x, list(axes), bool(forward), float(scale), bool(exact))


def _store(result, out):
    if out is None:
        return result
    np.copyto(out, result, casting="same_kind")
    return out


def _raw_fft(a, n, axis, is_real, is_forward, norm, out=None):
    """numpy's ``_raw_fft`` on voxlab's transform."""
    if n < 1:
        raise ValueError(f"Invalid number of FFT data points ({n}) specified.")
    if not is_forward:
        norm = _swap_direction(norm)
    real_dtype = np.result_type(a.real.dtype, 1.0)
    fct = _factor(norm, n, real_dtype)
    n_out = n
    if is_real and is_forward:
        n_out = n // 2 + 1
    axis = normalize_axis_index(axis, a.ndim)
    if out is None:
        if is_real and not is_forward:
            out_dtype = real_dtype
        else:
            out_dtype = np.result_type(a.dtype, 1j)
    else:
        shape = getattr(out, "shape", None)
        if shape is not None and (len(shape) != a.ndim or shape[axis] != n_out):
            raise ValueError("output array has wrong shape.")
        out_dtype = out.dtype
    if is_real and is_forward:
        if np.iscomplexobj(a):
            raise TypeError("rfft takes real input; got a complex array "
                            f"({a.dtype}); use fft")
        y = _c2c(_fit(a, n, axis), [axis], True, fct)
        idx = [slice(None)] * a.ndim
        idx[axis] = slice(0, n_out)
        y = y[tuple(idx)]
    elif is_real:
        # irfft: the first n//2 + 1 bins, completed by Hermitian symmetry
        # X[n − k] = conj(X[k]); the real part of the inverse ignores the imaginary
        # parts of DC (and of Nyquist for even n), as numpy does.
        m = n // 2 + 1
        x = _fit(np.asarray(a, dtype=np.complex128), m, axis)
        idx = [slice(None)] * a.ndim
        idx[axis] = slice(1, n - m + 1)
        tail = np.conj(np.flip(x[tuple(idx)], axis=axis))
        full = np.concatenate([x, tail], axis=axis)
        y = _c2c(full, [axis], False, fct).real
    else:
        y = _c2c(_fit(a, n, axis), [axis], is_forward, fct)
    if out is not None:
        return _store(y, out)
    return y.astype(out_dtype, copy=False)


def _check_backend(backend):
    if backend not in ("cpu", "gpu"):
        raise ValueError(f"backend must be 'cpu' or 'gpu'; got {backend!r}")


def _gpu_fftn(a, s, axes, is_forward, norm):
    """The whole-array transform on the GPU (complex64), or UnsupportedError."""
    nd = a.ndim
    norm_axes = [normalize_axis_index(ax, nd) for ax in axes]
    if sorted(norm_axes) != list(range(nd)):
        raise UnsupportedError(
            "the GPU FFT transforms every axis of the array once; "
            f"axes {list(axes)} of a {nd}-D array are not that (use backend='cpu')")
    for ns in s:
        if ns < 1:
            raise ValueError(f"Invalid number of FFT data points ({ns}) specified.")
    x = a
    for ns, ax in zip(s, norm_axes):
        x = _fit(x, ns, ax)
    dir_norm = norm if is_forward else _swap_direction(norm)
    fct = _factor(dir_norm, int(np.prod(x.shape)))
    x = np.ascontiguousarray(x, dtype=np.complex128)
    return _voxlab.c2c_gpu(x, bool(is_forward), float(fct))


# ---- one-dimensional ---------------------------------------------------------------


def fft(a, n=None, axis=-1, norm=None, out=None, *, backend="cpu"):
    """numpy.fft.fft: the 1-D discrete Fourier transform along ``axis``."""
    a = np.asarray(a)
    _check_backend(backend)
    if n is None:
        n = a.shape[axis]
    if backend == "gpu":
        if a.ndim != 1:
            raise UnsupportedError(
                "the GPU FFT transforms every axis; a 1-D fft on the GPU needs a 1-D "
                "array (use fftn, or backend='cpu')")
        return _store(_gpu_fftn(a, [n], [0], True, norm), out)
    return _raw_fft(a, n, axis, False, True, norm, out)


def ifft(a, n=None, axis=-1, norm=None, out=None, *, backend="cpu"):
    """numpy.fft.ifft: the 1-D inverse discrete Fourier transform along ``axis``."""
    a = np.asarray(a)
    _check_backend(backend)
    if n is None:
        n = a.shape[axis]
    if backend == "gpu":
        if a.ndim != 1:
            raise UnsupportedError(
                "the GPU FFT transforms every axis; a 1-D ifft on the GPU needs a 1-D "
                "array (use ifftn, or backend='cpu')")
        return _store(_gpu_fftn(a, [n], [0], False, norm), out)
    return _raw_fft(a, n, axis, False, False, norm, out=out)


def rfft(a, n=None, axis=-1, norm=None, out=None):
    """numpy.fft.rfft: the 1-D transform of real input (the ``n//2 + 1`` non-negative
    frequencies)."""
    a = np.asarray(a)
    if n is None:
        n = a.shape[axis]
    return _raw_fft(a, n, axis, True, True, norm, out=out)


def irfft(a, n=None, axis=-1, norm=None, out=None):
    """numpy.fft.irfft: the inverse of :func:`rfft` (real output of length ``n``,
    default ``2·(m − 1)``)."""
    a = np.asarray(a)
    if n is None:
        n = (a.shape[axis] - 1) * 2
    return _raw_fft(a, n, axis, True, False, norm, out=out)


def hfft(a, n=None, axis=-1, norm=None, out=None):
    """numpy.fft.hfft: the transform of a Hermitian-symmetric signal (real output)."""
    a = np.asarray(a)
    if n is None:
        n = (a.shape[axis] - 1) * 2
    new_norm = _swap_direction(norm)
    output = irfft(np.conjugate(a), n, axis, norm=new_norm, out=None)
    return _store(output, out)


def ihfft(a, n=None, axis=-1, norm=None, out=None):
    """numpy.fft.ihfft: the inverse of :func:`hfft`."""
    a = np.asarray(a)
    if n is None:
        n = a.shape[axis]
    new_norm = _swap_direction(norm)
    res = rfft(a, n, axis, norm=new_norm, out=out)
    return np.conjugate(res, out=res)


# ---- n-dimensional -----------------------------------------------------------------


def _cook_nd_args(a, s=None, axes=None, invreal=0):
    if s is None:
        shapeless = True
        if axes is None:
            s = list(a.shape)
        else:
            s = np.take(a.shape, axes)
    else:
        shapeless = False
    s = list(s)
    if axes is None:
        if not shapeless:
            msg = ("`axes` should not be `None` if `s` is not `None` "
                   "(Deprecated in NumPy 2.0). In a future version of NumPy, "
                   "this will raise an error and `s[i]` will correspond to "
                   "the size along the transformed axis specified by "
                   "`axes[i]`. To retain current behaviour, pass a sequence "
                   "[0, ..., k-1] to `axes` for an array of dimension k.")
            warnings.warn(msg, DeprecationWarning, stacklevel=4)
        axes = list(range(-len(s), 0))
    if len(s) != len(axes):
        raise ValueError("Shape and axes have different lengths.")
    if invreal and shapeless:
        s[-1] = (a.shape[axes[-1]] - 1) * 2
    if None in s:
        msg = ("Passing an array containing `None` values to `s` is "
               "deprecated in NumPy 2.0 and will raise an error in "
               "a future version of NumPy. To use the default behaviour "
               "of the corresponding 1-D transform, pass the value matching "
               "the default for its `n` parameter. To use the default "
               "behaviour for every axis, the `s` argument can be omitted.")
        warnings.warn(msg, DeprecationWarning, stacklevel=4)
    s = [a.shape[_a] if _s == -1 else _s for _s, _a in zip(s, axes)]
    return s, axes


def _raw_fftnd(a, s, axes, function, norm, out, backend, is_forward):
    a = np.asarray(a)
    _check_backend(backend)
    s, axes = _cook_nd_args(a, s, axes)
    if backend == "gpu":
        return _store(_gpu_fftn(a, s, axes, is_forward, norm), out)
    itl = list(range(len(axes)))
    itl.reverse()
    for ii in itl:
        a = function(a, n=s[ii], axis=axes[ii], norm=norm, out=out)
    return a


def fftn(a, s=None, axes=None, norm=None, out=None, *, backend="cpu"):
    """numpy.fft.fftn: the N-D discrete Fourier transform over ``axes``."""
    return _raw_fftnd(a, s, axes, fft, norm, out, backend, True)


def ifftn(a, s=None, axes=None, norm=None, out=None, *, backend="cpu"):
    """numpy.fft.ifftn: the N-D inverse discrete Fourier transform over ``axes``."""
    return _raw_fftnd(a, s, axes, ifft, norm, out, backend, False)


def fft2(a, s=None, axes=(-2, -1), norm=None, out=None, *, backend="cpu"):
    """numpy.fft.fft2: :func:`fftn` over the last two axes."""
    return _raw_fftnd(a, s, axes, fft, norm, out, backend, True)


def ifft2(a, s=None, axes=(-2, -1), norm=None, out=None, *, backend="cpu"):
    """numpy.fft.ifft2: :func:`ifftn` over the last two axes."""
    return _raw_fftnd(a, s, axes, ifft, norm, out, backend, False)


def rfftn(a, s=None, axes=None, norm=None, out=None):
    """numpy.fft.rfftn: real input; the last axis keeps ``s[-1]//2 + 1`` bins."""
    a = np.asarray(a)
    s, axes = _cook_nd_args(a, s, axes)
    a = rfft(a, s[-1], axes[-1], norm, out=out)
    for ii in range(len(axes) - 2, -1, -1):
        a = fft(a, s[ii], axes[ii], norm, out=out)
    return a


def rfft2(a, s=None, axes=(-2, -1), norm=None, out=None):
    """numpy.fft.rfft2: :func:`rfftn` over the last two axes."""
    return rfftn(a, s, axes, norm, out=out)


def irfftn(a, s=None, axes=None, norm=None, out=None):
    """numpy.fft.irfftn: the inverse of :func:`rfftn` (real output of shape ``s``)."""
    a = np.asarray(a)
    s, axes = _cook_nd_args(a, s, axes, invreal=1)
    for ii in range(len(axes) - 1):
        a = ifft(a, s[ii], axes[ii], norm)
    a = irfft(a, s[-1], axes[-1], norm, out=out)
    return a


def irfft2(a, s=None, axes=(-2, -1), norm=None, out=None):
    """numpy.fft.irfft2: :func:`irfftn` over the last two axes."""
    return irfftn(a, s, axes, norm, out=out)


# ---- the exact DFT -----------------------------------------------------------------


def dft(a, axes: Optional[Sequence[int]] = None, norm: Optional[str] = None,
        inverse: bool = False) -> np.ndarray:
    """The exact discrete Fourier transform over ``axes`` (default: all), the
    library's O(N²) oracle (``cpu::dft``: exact twiddles, float64 sums), with numpy's
    sign and ``norm`` conventions: ``dft(a)`` is ``fftn(a)`` computed exactly,
    ``dft(a, inverse=True)`` is ``ifftn(a)``. Returns complex128."""
    a = np.asarray(a)
    if axes is None:
        axes = list(range(a.ndim))
    axes = [normalize_axis_index(ax, a.ndim) for ax in axes]
    n = int(np.prod([a.shape[ax] for ax in axes])) if axes else 1
    dir_norm = _swap_direction(norm) if inverse else norm
    fct = _factor(dir_norm, max(n, 1))
    return _c2c(a, axes, not inverse, fct, exact=True)
