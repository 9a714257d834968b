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

import warnings
from typing import Any, Iterator, Optional

import numpy as np

from . import _voxlab

__all__ = ["iradon", "iradon_sart", "order_angles_golden_ratio", "radon"]

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


def order_angles_golden_ratio(theta: Any) -> Iterator[int]:
    """The order ``iradon_sart`` visits the views in (scikit-image's
    ``order_angles_golden_ratio``: Kohler's golden-ratio scheme), computed by the
    library (``cpu::radon::golden_order``) in ``theta``'s precision: a generator of
    indices into ``theta``, each once."""
    theta = np.asarray(theta)
    dtype = np.float32 if theta.dtype == np.float32 else np.float64
    yield from _voxlab.golden_order(np.ascontiguousarray(theta, dtype=dtype))


def iradon_sart(radon_image: Any, theta: Any = None, image: Any = None,
                projection_shifts: Any = None, clip: Any = None,
                relaxation: float = 0.15, dtype: Any = None, *, backend: str = "cpu",
                progress: Any = None) -> np.ndarray:
    """Inverse radon transform by one iteration of SART (scikit-image's
    ``iradon_sart``): every view once, in the golden-ratio order, each view's rays
    sampled every half pixel with bilinear weights inside the circle of radius
    ``n//2 − 1``, the deviation ``(p − Σw·x)/Σw²`` spread back along the ray with a
    Hamming window, ``image += relaxation·update`` after each view, then ``clip``.

    Parameters, defaults, dtype rules, warnings and errors are scikit-image's:
    ``radon_image`` the ``(n, angles)`` sinogram; ``theta`` the angles in degrees
    (default: evenly over [0, 180)); ``image`` the ``n × n`` start (default zeros; pass
    the previous result for further iterations); ``projection_shifts`` each view's
    shift in bins; ``clip`` ``(low, high)``; ``relaxation`` the step; ``dtype``
    float32 or float64 (default: the sinogram's float type, else float64 with a
    warning). The arithmetic is scikit-image's in that precision (``cpu::radon``).

    ``backend``: ``cpu`` (the sinogram's precision), ``cpu-f32`` (float32) or ``gpu``
    (float32, the whole iteration on the device: ``gpu::radon::iradon_sart``); the
    result has ``dtype`` in every case.
    """
    radon_image = np.asarray(radon_image)
    if radon_image.ndim != 2:
        raise ValueError("radon_image must be two dimensional")
    if dtype is None:
        if radon_image.dtype.char in "fd":
            dtype = radon_image.dtype
        else:
            warnings.warn(
                "Only floating point data type are valid for SART inverse "
                "radon transform. Input data is cast to float. To disable "
                "this warning, please cast image_radon to float.",
                stacklevel=2,
            )
            dtype = np.dtype(float)
    elif np.dtype(dtype).char not in "fd":
        raise ValueError(
            "Only floating point data type are valid for inverse radon transform."
        )
    dtype = np.dtype(dtype)
    radon_image = radon_image.astype(dtype, copy=False)
    n = radon_image.shape[0]
    reconstructed_shape = (n, n)
    if theta is None:
        theta = np.linspace(0, 180, radon_image.shape[1], endpoint=False, dtype=dtype)
    elif len(theta) != radon_image.shape[1]:
        raise ValueError(
            f"Shape of theta ({len(theta)}) does not match the "
            f"number of projections ({radon_image.shape[1]})"
        )
    else:
        theta = np.asarray(theta, dtype=dtype)
    if image is not None:
        image = np.asarray(image)
        if image.shape != reconstructed_shape:
            raise ValueError(
                f"Shape of image ({image.shape}) does not match first dimension "
                f"of radon_image ({reconstructed_shape})"
            )
        if image.dtype != dtype:
            warnings.warn(
                f"image dtype does not match output dtype: image is cast to {dtype}",
                stacklevel=2,
            )
        image = np.asarray(image, dtype=dtype)
    if projection_shifts is not None:
        if len(projection_shifts) != radon_image.shape[1]:
            raise ValueError(
                f"Shape of projection_shifts ({len(projection_shifts)}) does not match "
                f"the number of projections ({radon_image.shape[1]})"
            )
        projection_shifts = np.asarray(projection_shifts, dtype=dtype)
    if clip is not None:
        if len(clip) != 2:
            raise ValueError("clip must be a length-2 sequence")
        clip = tuple(float(c) for c in np.asarray(clip, dtype=dtype))
    work = np.float32 if backend == "cpu-f32" else dtype
    as_work = lambda a: None if a is None else np.ascontiguousarray(a, dtype=work)  # noqa: E731
    rec = _voxlab.iradon_sart(
        as_work(radon_image), as_work(theta), as_work(image), as_work(projection_shifts),
        clip, float(relaxation), backend, progress,
    )
    return rec.astype(dtype, copy=False)
