"""scikit-image's ``radon`` and ``iradon`` on voxlab's library.

:func:`iradon` has ``skimage.transform.iradon``'s signature, conventions, dtype
handling and errors, and computes with the library's iradon job
(``jobs::radon::iradon``: the ramp filters of ``cpu::ramp``, which are
scikit-image's ``_get_fourier_filter``, then scikit-image's pixel-driven
backprojection with its interpolants, ``cpu::radon``/``gpu::radon``) in float64
(``backend="cpu"``, the oracle), float32 (``"cpu-f32"``) or on the GPU (``"gpu"``).

Conventions (scikit-image's): a sinogram has shape ``(detector, angle)``; angles
``theta`` in degrees; the rotation centre is detector bin ``n // 2`` and image pixel
``(n // 2, n // 2)``; ``x = col − n//2``, ``y = n//2 − row``, ``s = x·cos θ + y·sin θ``.

:func:`radon` is scikit-image's rotate-and-sum transform on the library's
``cpu::radon`` (``jobs::radon::radon``), equal to scikit-image's result.

Both compute as scikit-image does, step for step (``cpu::radon``): every filter
(``None`` included), every interpolation, ``circle``, rectangular and odd sizes,
scikit-image's dtype rules; on the GPU (``backend="gpu"``, ``gpu::radon``) in
float32.
"""

from __future__ import annotations

from typing import Any, Optional

import numpy as np

from . import _voxlab

__all__ = ["iradon", "radon"]

_FILTERS = ("ramp", "shepp-logan", "cosine", "hamming", "hann", None)
_INTERPOLATIONS = ("linear", "nearest", "cubic")


def _convert_to_float(image: np.ndarray, preserve_range: bool) -> np.ndarray:
    """scikit-image's ``convert_to_float``: float16 → float32; with ``preserve_range``
    float32/float64 kept and everything else float64; without it ``img_as_float``'s
    scaling of integers (unsigned to [0, 1], signed to [−1, 1])."""
    if image.dtype == np.float16:
        return image.astype(np.float32)
    if preserve_range:
        if image.dtype.char not in "df":
            image = image.astype(float)
        return image
    if image.dtype.kind == "f":
        return image
    if image.dtype == bool:
        return image.astype(float)
    if image.dtype.kind == "u":
        return np.multiply(image, 1.0 / np.iinfo(image.dtype).max, dtype=np.float64)
    if image.dtype.kind == "i":
        out = np.multiply(image, 1.0 / np.iinfo(image.dtype).max, dtype=np.float64)
        return np.maximum(out, -1.0)
    raise ValueError(f"Cannot convert from {image.dtype} to float64.")


def iradon(
    radon_image: Any,
    theta: Any = None,
    output_size: Optional[int] = None,
    filter_name: Optional[str] = "ramp",
    interpolation: str = "linear",
    circle: bool = True,
    preserve_range: bool = True,
    *,
    backend: str = "cpu",
    progress: Any = None,
) -> np.ndarray:
    """Inverse radon transform by filtered backprojection (scikit-image's ``iradon``).

    Parameters are scikit-image's: ``radon_image`` is the ``(detector, angle)``
    sinogram; ``theta`` the angles in degrees (default: evenly over [0, 180));
    ``output_size`` the image's side (default: the detector count when ``circle``,
    else ``floor(sqrt(n²/2))``); ``filter_name`` one of ``ramp``, ``shepp-logan``,
    ``cosine``, ``hamming``, ``hann`` or ``None`` (no filter); ``interpolation`` how
    a filtered projection is read between its bins: ``linear`` (``np.interp``),
    ``nearest`` (the nearest bin, the left one at a tie) or ``cubic`` (the not-a-knot
    cubic spline, scipy's ``interp1d(kind="cubic")``), 0 past the first and last bin
    centres; ``circle`` that the object lies inside the inscribed circle (the sinogram
    is padded to ``ceil(√2·n)`` bins and the output zeroed outside the circle). The
    result has the input's float type (float32 for float16/float32 input, summed in
    float32 as scikit-image sums it; float64 otherwise).

    ``backend``: ``cpu`` (the f64 oracle: scikit-image's arithmetic), ``cpu-f32``
    (float32 throughout), ``gpu`` (float32, ``gpu::radon``) or ``auto``.
    """
    radon_image = np.asarray(radon_image)
    if radon_image.ndim != 2:
        raise ValueError("The input image must be 2-D")
    if theta is None:
        theta = np.linspace(0, 180, radon_image.shape[1], endpoint=False)
    angles_count = len(theta)
    if angles_count != radon_image.shape[1]:
        raise ValueError(
            "The given ``theta`` does not match the number of "
            "projections in ``radon_image``."
        )
    if interpolation not in _INTERPOLATIONS:
        raise ValueError(f"Unknown interpolation: {interpolation}")
    if filter_name not in _FILTERS:
        raise ValueError(f"Unknown filter: {filter_name}")
    radon_image = _convert_to_float(radon_image, preserve_range)
    dtype = radon_image.dtype
    img_shape = radon_image.shape[0]
    if output_size is None:
        if circle:
            output_size = img_shape
        else:
            output_size = int(np.floor(np.sqrt((img_shape) ** 2 / 2.0)))
    sino = np.ascontiguousarray(radon_image, dtype=np.float64)
    # t = ypr·cos θ − xpr·sin θ with numpy's cosines and sines, taken angle by angle as
    # scikit-image takes them (so that nearest-bin ties fall the same way).
    angles = np.deg2rad(theta)
    cos = [float(np.cos(a)) for a in angles]
    sin = [float(np.sin(a)) for a in angles]
    degrees = [float(t) for t in np.asarray(theta, dtype=np.float64).reshape(-1)]
    rec = _voxlab.iradon(
        sino, degrees, cos, sin, int(output_size),
        "none" if filter_name is None else filter_name, interpolation, bool(circle),
        backend, dtype == np.float32, progress,
    )
    return rec.astype(dtype, copy=False)


def radon(image: Any, theta: Any = None, circle: bool = True, *,
          preserve_range: bool = False, backend: str = "cpu",
          progress: Any = None) -> np.ndarray:
    """Radon transform (scikit-image's ``radon``): the ``(detector, angle)`` sinogram
    of a 2-D image at the angles ``theta`` (degrees; default ``np.arange(180)``).

    The library's rotate-and-sum transform (``cpu::radon``): the image — cropped to
    its centred inscribed square when ``circle`` (warning when it is not zero outside
    the inscribed circle), else zero-padded to ``ceil(√2·max(shape))`` — is rotated
    about pixel ``(n // 2, n // 2)`` with bilinear interpolation (zero outside) and
    its columns summed, step for step as scikit-image does, so the results are equal.
    The rotation centre is detector bin ``n // 2``. dtypes as scikit-image's:
    ``img_as_float`` scaling unless ``preserve_range``; float32 (and float16) images
    compute and return float32, everything else float64.

    ``backend``: ``cpu`` (the image's precision), ``cpu-f32`` (float32 throughout) or
    ``gpu`` (float32 on the device, ``gpu::radon``; the sinogram keeps the image's
    dtype, holding float32-rounded values).
    """
    image = np.asarray(image)
    if image.ndim != 2:
        raise ValueError("The input image must be 2-D")
    if theta is None:
        theta = np.arange(180)
    image = _convert_to_float(image, preserve_range)
    if backend == "cpu-f32":
        image = image.astype(np.float32)
    # scikit-image's rotation matrices, built as it builds them (in the angles' own
    # precision), then rounded to the image's precision by the library.
    n = min(image.shape) if circle else int(np.ceil(np.sqrt(2) * max(image.shape)))
    center = n // 2
    maps = []
    for angle in np.deg2rad(theta):
        cos_a, sin_a = np.cos(angle), np.sin(angle)
        r = np.array([cos_a, sin_a, -center * (cos_a + sin_a - 1),
                      -sin_a, cos_a, -center * (cos_a - sin_a - 1)])
        maps.append([float(v) for v in r.astype(image.dtype)])
    img = np.ascontiguousarray(image)
    return _voxlab.radon(img, maps, bool(circle), backend, progress)
