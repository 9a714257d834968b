"""scikit-image's ``radon`` and ``iradon`` on voxlab's library.

:func:`iradon` has ``skimage.transform.iradon``'s signature, conventions, dtype
handling and errors, and computes with the library's reconstruct job (the ramp
filters of ``cpu::ramp``, which are scikit-image's ``_get_fourier_filter``, and the
parallel-beam backprojector of ``cpu::fbp``/``gpu::fbp``) in float64 (``backend="cpu"``,
the oracle), float32 (``"cpu-f32"``) or on the GPU (``"gpu"``).

Conventions (scikit-image's): a sinogram has shape ``(detector, angle)``; angles
``theta`` in degrees; the rotation centre is detector bin ``n // 2`` and image pixel
``(n // 2, n // 2)``; ``x = col − n//2``, ``y = n//2 − row``, ``s = x·cos θ + y·sin θ``.

:func:`radon` is scikit-image's rotate-and-sum transform on the library's
``cpu::radon`` (``jobs::radon::radon``), equal to scikit-image's result.

Not covered yet, each refused with :class:`voxlab.UnsupportedError` rather than
computed differently: ``interpolation="nearest"`` and ``"cubic"`` (only ``"linear"``,
scikit-image's default) and ``filter_name=None`` (no filter).
"""

from __future__ import annotations

from typing import Any, Optional

import numpy as np

from . import _voxlab
from ._errors import UnsupportedError

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
    ``cosine``, ``hamming``, ``hann``; ``circle`` that the object lies inside the
    inscribed circle (the sinogram is padded to ``ceil(√2·n)`` bins and the output
    zeroed outside the circle). The result has the input's float type (float32 for
    float16/float32 input, float64 otherwise).

    ``backend``: ``cpu`` (the f64 oracle), ``cpu-f32``, ``gpu`` or ``auto``.
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
    if interpolation != "linear":
        raise UnsupportedError(
            f"iradon: interpolation={interpolation!r} is not implemented by voxlab's "
            "backprojector (it interpolates linearly: interpolation='linear')"
        )
    if filter_name is None:
        raise UnsupportedError(
            "iradon: filter_name=None (unfiltered backprojection) is not implemented "
            "(filters: 'ramp', 'shepp-logan', 'cosine', 'hamming', 'hann')"
        )
    radon_image = _convert_to_float(radon_image, preserve_range)
    dtype = radon_image.dtype
    img_shape = radon_image.shape[0]
    if output_size is None:
        if circle:
            output_size = img_shape
        else:
            output_size = int(np.floor(np.sqrt((img_shape) ** 2 / 2.0)))
    sino = np.ascontiguousarray(radon_image, dtype=np.float64)
    theta = [float(t) for t in np.asarray(theta, dtype=np.float64).reshape(-1)]
    padded = int(np.ceil(np.sqrt(2) * img_shape)) if circle else img_shape
    _warn_outside_detector(padded, int(output_size), theta, circle)
    rec = _voxlab.fbp_parallel(
        sino, theta, int(output_size), filter_name, bool(circle), backend, progress
    )
    return rec.astype(dtype, copy=False)


def _warn_outside_detector(n: int, size: int, theta: Any, circle: bool) -> None:
    """Warns when some output pixel's ray may miss the (padded) detector's bin centres
    (an ``output_size`` larger than the detector allows, or the corners of a
    ``circle=False`` output): there iradon's ``np.interp(left=0, right=0)`` gives 0
    past the last bin centre, while voxlab's backprojector ramps linearly to 0 over
    one more bin, so the two differ within one bin of the edge."""
    r = size // 2
    lo, hi = -(n // 2), n - 1 - n // 2
    if circle:
        # Pixels outside the circle of radius r are zeroed; inside, |s| ≤ r.
        t = np.array([-r, r], dtype=np.float64)
    else:
        a = np.deg2rad(np.asarray(theta, dtype=np.float64))
        c = np.array([-r, size - 1 - r], dtype=np.float64)
        # s = col·cos θ − row·sin θ (offsets from the centre) is extreme at a corner.
        t = (c[None, :, None] * np.cos(a)[:, None, None]
             - c[None, None, :] * np.sin(a)[:, None, None])
    if t.min() < lo or t.max() > hi:
        import warnings

        from ._errors import VoxlabWarning

        warnings.warn(
            f"iradon: rays of the {size}x{size} output may reach past the "
            f"detector's last bin centre (|s| up to {np.abs(t).max():.2f}, bins span "
            f"{lo}..{hi}); within one bin of the edge voxlab interpolates linearly to "
            "zero where scikit-image gives 0, so pixels that far out differ",
            VoxlabWarning,
            stacklevel=3,
        )


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

    ``backend``: ``cpu`` (the image's precision) or ``cpu-f32`` (float32 throughout);
    the GPU has no Radon transform and is refused with :class:`voxlab.UnsupportedError`.
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
