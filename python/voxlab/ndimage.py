"""scipy.ndimage's signatures on voxlab's process job, for the operations
docs/processing.md claims compatible: :func:`gaussian_filter` (``mode='reflect'``,
``truncate=4.0``, ``order=0``), :func:`median_filter` (a cubic ``size``,
``mode='reflect'``) and :func:`gradient_magnitude` (central differences divided by the
spacing: scipy's ``correlate1d(a, [-0.5, 0, 0.5], mode='reflect')`` per axis).

Inputs are 3-D ``(nz, ny, nx)`` arrays (uint8, uint16, int16, float32, float64;
float64 is stored as float32, the library's widest voxel type); the result is always
float32 (computed in f64 on the ``cpu`` backend, then rounded once). What scipy does
and voxlab does not (other modes, ``cval``, ``origin``, derivative orders,
footprints, ``output=``) raises :class:`voxlab.UnsupportedError`.
"""

from __future__ import annotations

from typing import Any, Optional

import numpy as np

from ._errors import UnsupportedError
from ._jobs import process

__all__ = ["gaussian_filter", "median_filter", "gradient_magnitude"]


def _array(input: Any) -> np.ndarray:
    a = np.asarray(input)
    if a.ndim != 3:
        from ._errors import ShapeError

        raise ShapeError(f"voxlab.ndimage works on 3-D (nz, ny, nx) arrays; got shape {a.shape}")
    return a


def _unsupported(what: str) -> None:
    raise UnsupportedError(f"voxlab.ndimage: {what} is not supported (scipy.ndimage has it)")


def gaussian_filter(input: Any, sigma: Any, order: Any = 0, output: Any = None,
                    mode: str = "reflect", cval: float = 0.0, truncate: float = 4.0,
                    *, radius: Any = None, axes: Any = None,
                    backend: str = "cpu") -> np.ndarray:
    """``scipy.ndimage.gaussian_filter`` with ``mode='reflect'`` and ``truncate=4.0``:
    σ in voxels, one value or one per NumPy axis ``(σz, σy, σx)``."""
    a = _array(input)
    if np.any(np.asarray(order) != 0):
        _unsupported("a derivative order")
    if output is not None:
        _unsupported("output=")
    if mode != "reflect":
        _unsupported(f"mode={mode!r} (only 'reflect')")
    if float(truncate) != 4.0:
        _unsupported(f"truncate={truncate} (only 4.0)")
    if radius is not None or axes is not None:
        _unsupported("radius= or axes=")
    s = np.atleast_1d(np.asarray(sigma, dtype=np.float64))
    if s.size == 1:
        sig = [float(s[0])]
    elif s.size == 3:
        sig = [float(s[2]), float(s[1]), float(s[0])]  # (σz, σy, σx) → x, y, z
    else:
        raise ValueError("sequence argument must have length equal to input rank")
    return process(a, "gaussian", sigma=sig, backend=backend, spacing=1.0).array


def median_filter(input: Any, size: Any = None, footprint: Any = None, output: Any = None,
                  mode: str = "reflect", cval: float = 0.0, origin: Any = 0,
                  *, axes: Any = None, backend: str = "cpu") -> np.ndarray:
    """``scipy.ndimage.median_filter(a, size=k, mode='reflect')`` for an odd cubic
    window ``k`` (one value, or three equal ones)."""
    a = _array(input)
    if footprint is not None:
        _unsupported("footprint=")
    if output is not None:
        _unsupported("output=")
    if mode != "reflect":
        _unsupported(f"mode={mode!r} (only 'reflect')")
    if np.any(np.asarray(origin) != 0) or axes is not None:
        _unsupported("origin= or axes=")
    if size is None:
        raise RuntimeError("no footprint or filter size provided")
    k = np.atleast_1d(np.asarray(size))
    if k.size not in (1, 3) or np.any(k != k.flat[0]):
        _unsupported(f"size={size!r} (a cubic window only)")
    return process(a, "median", size=int(k.flat[0]), backend=backend, spacing=1.0).array


def gradient_magnitude(input: Any, spacing: Any = 1.0, *, backend: str = "cpu") -> np.ndarray:
    """|∇f| in value per mm from central differences with reflected borders:
    ``sqrt(Σ_ax (correlate1d(a, [-0.5, 0, 0.5], axis=ax, mode='reflect') / s[ax])²)``
    with ``spacing`` one value or ``(sz, sy, sx)`` (NumPy axis order)."""
    a = _array(input)
    s = np.atleast_1d(np.asarray(spacing, dtype=np.float64))
    sp = (float(s[0]),) * 3 if s.size == 1 else (float(s[2]), float(s[1]), float(s[0]))
    return process(a, "gradient-magnitude", backend=backend, spacing=sp).array
