"""CT on voxlab's jobs: forward projection (``voxlab project``) and FBP/FDK
(``voxlab reconstruct``), in memory.

Geometry is the library's JSON form (docs/projection.md), as a dict: ``{"beam":
"parallel" | "cone", "sid": …, "sdd": …, "cols": …, "rows": …, "du": …, "dv": …,
"cu": …, "cv": …, "angles_deg": [...]}`` — scikit-image's parallel beam (rotation
centre at bin ``cols // 2``) or RTK's circular cone beam (rotation axis +y, source at
``(SID sin a, 0, SID cos a)``, flat detector, mm). :func:`project` returns it with the
projections, and :func:`reconstruct` takes it back.

Projections are float64 ``(angle, row, col)`` stacks; a one-row parallel beam is also
accepted (and, with ``layout="skimage"``/``"auto"``, returned) as scikit-image's
``(detector, angle)`` sinogram.
"""

from __future__ import annotations

import json as _json
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, Optional, Union

import numpy as np

from . import _voxlab, _plan, MemoryPlan
from . import _as_volume, Volume  # noqa: F401  (re-exported names of the package)

__all__ = ["Projected", "project", "reconstruct"]


@dataclass
class Projected:
    """Projections and their geometry: ``projections`` is ``(angle, row, col)``
    float64, or ``(detector, angle)`` for the ``skimage`` layout; ``geometry`` the
    JSON form as a dict."""

    projections: np.ndarray
    geometry: Dict[str, Any]
    layout: str
    info: Dict[str, Any] = field(default_factory=dict)


def project(
    volume: Any = None,
    *,
    backend: str = "cpu",
    progress: Optional[Callable[[str, int, int], Any]] = None,
    dry_run: bool = False,
    **options: Any,
) -> Union[Projected, MemoryPlan]:
    """Forward projection (``voxlab project``): a phantom spec (``"phantom:NAME[:N]"``;
    exact line integrals by default) or a volume (:class:`voxlab.Volume`, an array with
    ``spacing=``, or a path: Joseph's method), with the job's options ``beam``
    (``"parallel"`` | ``"cone"``), ``angles``, ``range``, ``angles_file``, ``cols``,
    ``rows``, ``du``, ``dv``, ``sid``, ``sdd``, ``method`` (``"analytic"`` |
    ``"joseph"``), ``layout`` (``"auto"`` | ``"stack"`` | ``"skimage"``),
    ``hardware_filtering`` (with ``backend="gpu"`` and Joseph's method: the grid sampled
    through the texture unit, whose weights real GPUs round to about 8 bits; see
    docs/parity.md). ``dry_run=True``: the job's :class:`voxlab.MemoryPlan` (on the
    GPU, the slabs and view batches it would use), nothing projected."""
    spacing = options.pop("spacing", None)
    affine = options.pop("affine", None)
    req: Dict[str, Any] = dict(options, backend=backend)
    arr = aff = None
    if volume is None or isinstance(volume, str) or hasattr(volume, "__fspath__"):
        if volume is not None:
            import os

            req["input"] = {"source": os.fspath(volume)}
    else:
        arr, m = _as_volume(volume, spacing, affine)
        aff = m.tolist()
        req["input"] = {"source": "array"}
    if dry_run:
        return _plan("project", _json.dumps(req), arr, aff, progress)
    stack, geometry, meta = _voxlab.project(_json.dumps(req), arr, aff, progress)
    info = _json.loads(meta)
    layout = info.pop("layout")
    p = stack[:, 0, :].T.copy() if layout == "skimage" else stack
    return Projected(p, _json.loads(geometry), layout, info)


def reconstruct(
    projections: Any,
    geometry: Any,
    *,
    filter: str = "ramp",
    size: Optional[int] = None,
    spacing: Optional[float] = None,
    circle: bool = True,
    short_scan: bool = False,
    backend: str = "cpu",
    hardware_filtering: bool = False,
    method: str = "fbp",
    iterations: Optional[int] = None,
    subsets: Optional[int] = None,
    subset_order: str = "sequential",
    relaxation: Optional[float] = None,
    tv_weight: Optional[float] = None,
    nonnegative: bool = False,
    init: str = "zero",
    tolerance: float = 0.0,
    flat: Any = None,
    dark: Any = None,
    progress: Optional[Callable[[str, int, int], Any]] = None,
    dry_run: bool = False,
) -> Union[Volume, MemoryPlan]:
    """FBP (parallel beam: scikit-image's images, ``circle`` as iradon's) or FDK (cone
    beam, RTK's centred grid) of ``projections`` with ``geometry`` (a dict, a JSON
    string, or a :class:`Projected`'s ``geometry``), or an iterative reconstruction
    on the same grid: ``voxlab reconstruct`` in memory. ``size``: the image side N
    (parallel; default the detector count) or the volume N³ (cone; default the
    detector columns); ``spacing`` in mm; ``short_scan``: Parker's weights for a cone
    beam over less than a full turn (FBP/FDK only). ``hardware_filtering`` (with
    ``backend="gpu"``, FBP/FDK only): the backprojection samples the filtered
    projections through the GPU's texture unit instead of the exact interpolation
    (real GPUs quantise the filter weights to about 8 bits; docs/parity.md).

    ``method``: ``"fbp"`` (the default), or ``"sirt"``, ``"cgls"``, ``"os-sart"``,
    ``"tv"`` on Joseph's matched projector pair (docs/iterative.md), with
    ``iterations`` (default sirt 100, cgls 30, os-sart 20, tv 200), ``subsets`` and
    ``subset_order`` (``"sequential"`` or ``"random"``; os-sart), ``relaxation``
    (sirt, os-sart; in (0, 2), default 1), ``tv_weight`` (tv; default 0.2),
    ``nonnegative`` (sirt, os-sart, tv), ``init`` (``"zero"`` or ``"fbp"``) and
    ``tolerance`` (stop once the objective falls by less than this fraction in one
    iteration). A parallel-beam image is supported on the inscribed disc when
    ``circle``.

    ``flat`` and ``dark``: the projections are detector intensities ``I``, and
    become the line integrals ``p = -ln((I - D) / (F - D))`` before anything else
    (docs/ct.md). Each is a path (any format ``voxlab reconstruct --flat`` reads) or
    an array: one ``(rows, cols)`` image or a ``(frame, rows, cols)`` stack, averaged
    in float64 (for a one-row sinogram also ``(detector, frame)``); ``dark`` defaults
    to 0 and needs ``flat``. Dead pixels (``F - D <= 0``) give 0, starved samples
    (``I - D <= 0``) the ratio floored at the smallest positive normal float64;
    nothing is NaN or infinite. The counts are in ``info["intensity"]``
    (``samples``, ``pixels``, ``dead_pixels``, ``starved``, ``clamped``,
    ``above_flat``); it is ``None`` without ``flat``.

    Returns a :class:`voxlab.Volume` whose array is laid out as the command line's
    ``.npy`` (``(n, n)`` for one row, ``(rows, n, n)``, or ``(N, N, N)``) and whose
    affine maps the grid into the CT frame (mm). Its ``info`` dict holds ``what``
    computed it and, for an iterative method, ``iterative``: the ``residual``
    ``‖b − Ax_k‖`` and the ``objective`` for k = 0 (the initial image) … the last
    iteration, ``iterations``, ``converged`` and ``seconds_per_iteration``.

    ``dry_run=True`` reconstructs nothing and returns the job's
    :class:`voxlab.MemoryPlan`: host bytes, and on the GPU the device bytes and the
    slabs and view batches the backprojection would use.
    """
    g = geometry if isinstance(geometry, str) else _json.dumps(geometry)
    req = {"filter": filter, "size": size, "spacing": spacing, "no_circle": not circle,
           "short_scan": bool(short_scan), "backend": backend,
           "hardware_filtering": bool(hardware_filtering), "method": method,
           "iterations": iterations, "subsets": subsets, "subset_order": subset_order,
           "relaxation": relaxation, "tv_weight": tv_weight,
           "nonnegative": bool(nonnegative), "init": init, "tolerance": float(tolerance)}
    p = np.ascontiguousarray(np.asarray(projections, dtype=np.float64))
    fields = [f if f is None or isinstance(f, str) or hasattr(f, "__fspath__")
              else np.ascontiguousarray(np.asarray(f, dtype=np.float64))
              for f in (flat, dark)]
    if dry_run:
        return _plan("reconstruct", _json.dumps(req), progress=progress, projections=p,
                     geometry=g, flat=fields[0], dark=fields[1])
    arr, affine, meta = _voxlab.reconstruct_stack(
        p, g, _json.dumps(req), progress, fields[0], fields[1])
    v = Volume(arr, np.array(affine, dtype=np.float64), "reconstruction")
    v.info = _json.loads(meta)  # type: ignore[attr-defined]
    return v
