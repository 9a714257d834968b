"""FVR, D²VR, spectral adaptive sampling, processing and the benchmark suite: the
fvr, d2vr, adaptive, process and bench jobs, in memory (re-exported by
:mod:`voxlab`; :mod:`voxlab.ndimage` has the scipy.ndimage-compatible shells)."""

from __future__ import annotations

import json as _json
import os as _os
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Union

import numpy as np

from . import _voxlab, _as_volume, _json_default, _plan, MemoryPlan, Volume
from ._errors import InvalidError

ProgressCallback = Callable[[str, int, int], Any]

__all__ = [
    "fvr", "d2vr", "D2vrResult", "adaptive", "AdaptiveResult", "process", "resample",
    "bench",
]


def _input(req: Dict[str, Any], volume: Any, spacing: Any = None, affine: Any = None):
    """The request's input: a path or phantom spec by name, or an array in memory
    (returned with its affine)."""
    if volume is None or isinstance(volume, str) or hasattr(volume, "__fspath__"):
        if volume is not None:
            req["input"] = {"source": _os.fspath(volume)}
        return None, None
    arr, aff = _as_volume(volume, spacing, affine)
    req["input"] = {"source": "array"}
    return arr, aff.tolist()


def _dumps(req: Dict[str, Any]) -> str:
    return _json.dumps(req, default=_json_default)


def _view(req: Dict[str, Any], options: Dict[str, Any]) -> None:
    view = {}
    v = options.pop("view", None)
    if isinstance(v, dict):
        view.update(v)
    elif v is not None:
        view["axis"] = v
    for k in ("azimuth", "elevation"):
        if k in options:
            view[k] = options.pop(k)
    if view:
        req["view"] = view


def fvr(
    volume: Any = None,
    *,
    kernel: str = "lanczos3",
    padding: int = 2,
    deapodize: bool = False,
    backend: str = "cpu",
    spacing: Any = None,
    affine: Any = None,
    progress: Optional[ProgressCallback] = None,
    dry_run: bool = False,
    **options: Any,
) -> Union[np.ndarray, MemoryPlan]:
    """Fourier volume rendering (``voxlab fvr``): the X-ray projection (value × mm) of
    an isotropic volume from one slice of its 3-D spectrum, as the float32 ``(h, w)``
    image the command line writes to ``.npy``. ``kernel``: ``nearest``,
    ``trilinear``, ``lanczos3``, ``lanczos4``, ``dirichlet`` (exact, small volumes);
    ``padding``: the zero-padded cube's side over the largest dimension (1: none, the
    image wraps around: ghosting); ``deapodize``: divide by the kernel's spatial
    transfer; ``view`` (``"+z"`` …) or ``azimuth``/``elevation`` (degrees).
    ``backend``: cpu, cpu-f32, gpu. ``dry_run=True``: the job's :class:`MemoryPlan`
    (the padded spectrum's bytes, and on the GPU its slabs), nothing computed."""
    req: Dict[str, Any] = {"kernel": kernel, "padding": int(padding),
                           "deapodize": bool(deapodize), "backend": backend}
    _view(req, options)
    load = {k: options.pop(k) for k in ("phantom_size", "non_finite") if k in options}
    req.update(options)
    arr, aff = _input(req, volume, spacing, affine)
    if load:
        req.setdefault("input", {"source": "array"})["load"] = load
    if dry_run:
        return _plan("fvr", _dumps(req), arr, aff, progress)
    image, _engine = _voxlab.fvr(_dumps(req), arr, aff, progress)
    return image


@dataclass
class D2vrResult:
    """A D²VR image (float32 ``(h, w, 4)``, or ``(h, w)`` for grey modes), its
    samples-per-ray image when made, and the work counters (``stats``:
    ``box_samples``, ``visited_samples``, ``value_reconstructions``,
    ``gradient_reconstructions``, ``fraction``)."""

    image: np.ndarray
    samples: Optional[np.ndarray]
    stats: Dict[str, Any]
    seconds: float
    engine: str
    backend: str
    total_samples: int


def d2vr(
    projections: Any = "phantom:shepp-logan-modified",
    *,
    backend: str = "cpu-f32",
    progress: Optional[ProgressCallback] = None,
    dry_run: bool = False,
    **options: Any,
) -> Union[D2vrResult, MemoryPlan]:
    """D²VR (``voxlab d2vr``): volume rendering straight from projections, with no
    reconstructed grid. ``projections``: ``"phantom:NAME"`` (projected exactly with
    ``beam``, ``angles``, ``detector``), a projection stack file (``.npy``/NRRD with
    its geometry JSON beside it, or ``geometry=`` a path), or projections in memory:
    a :class:`voxlab.ct.Projected` (``voxlab.ct.project``'s result, which carries its
    geometry), or an array — an ``(angle, row, col)`` stack or a ``(detector, angle)``
    sinogram, float64 (other dtypes are converted) — with ``geometry=`` its geometry
    (a dict as docs/projection.md describes, or its JSON text). The job's options as
    keywords: ``beam``, ``angles``, ``detector``, ``filter``, ``grid``, ``spacing``,
    ``mode``, ``tf``, ``gradient`` (``gfs`` | ``gfr``), ``no_cylinder``,
    ``occupancy``, ``ert``, ``step``, ``size``, ``azimuth``, ``elevation``,
    ``range``; with ``backend="gpu"``, ``f16_projections`` (hold the filtered
    projections as 16-bit floats) and ``hardware_filtering`` (hold them in textures and
    let the texture unit interpolate every value, as the paper does; real GPUs round
    its weights to about 8 bits, so the image differs from the exact path's within the
    bound docs/d2vr.md states for MIP, MinIP and X-ray). ``dry_run=True``: the job's
    :class:`MemoryPlan` from the geometry alone (on the GPU, how the projections are
    cut into pieces), nothing projected or rendered."""
    req: Dict[str, Any] = dict(options, backend=backend)
    geometry = req.pop("geometry", None)
    stack = None
    if hasattr(projections, "projections") and hasattr(projections, "geometry"):
        stack, geometry = projections.projections, projections.geometry
    elif isinstance(projections, np.ndarray):
        stack = projections
    if stack is not None:
        if geometry is None:
            raise InvalidError(
                "invalid d2vr option `geometry`: projections in memory need their geometry"
            )
        g = geometry if isinstance(geometry, str) else _json.dumps(geometry)
        a = np.ascontiguousarray(np.asarray(stack, dtype=np.float64))
        if dry_run:
            return _plan("d2vr", _dumps(req), progress=progress, projections=a, geometry=g)
        image, samples, meta = _voxlab.d2vr(_dumps(req), progress, a, g)
    else:
        req["input"] = _os.fspath(projections)
        if geometry is not None:
            req["geometry"] = _os.fspath(geometry)
        if dry_run:
            return _plan("d2vr", _dumps(req), progress=progress)
        image, samples, meta = _voxlab.d2vr(_dumps(req), progress)
    info = _json.loads(meta)
    return D2vrResult(image, samples, info["stats"], info["seconds"], info["engine"],
                      info["backend"], int(info["total_samples"]))


@dataclass
class AdaptiveResult:
    """Regular, direct and spectral adaptive sampling of one scene: ``report`` is the
    job's report as a dict (``table.json``: per sampling ``samples_per_pixel``,
    ``total_samples``, ``seconds_per_frame``, ``max_abs``, ``rmse``, ``psnr_db``; the
    reductions and goals), ``markdown`` its ``table.md``, ``images`` and ``samples``
    each sampling's last image and samples-per-ray image by name."""

    report: Dict[str, Any]
    markdown: str
    images: Dict[str, np.ndarray]
    samples: Dict[str, Optional[np.ndarray]]
    max_count: float = 0.0
    info: Dict[str, Any] = field(default_factory=dict)


def adaptive(
    volume: Any = None,
    *,
    backend: str = "cpu-f32",
    spacing: Any = None,
    affine: Any = None,
    progress: Optional[ProgressCallback] = None,
    dry_run: bool = False,
    **options: Any,
) -> Union[AdaptiveResult, MemoryPlan]:
    """Spectral adaptive sampling against regular and direct sampling (``voxlab
    adaptive``), with its report. Options as the job's: ``tf``, ``shift``, ``size``,
    ``azimuth``, ``elevation``, ``step``, ``t_max``, ``oversampling``, ``energy``,
    ``block``, ``runs``. ``dry_run=True``: the job's :class:`MemoryPlan`, nothing
    rendered."""
    req: Dict[str, Any] = dict(options, backend=backend)
    arr, aff = _input(req, volume, spacing, affine)
    if dry_run:
        return _plan("adaptive", _dumps(req), arr, aff, progress)
    report, md, outs, max_count = _voxlab.adaptive(_dumps(req), arr, aff, progress)
    images = {name: img for name, img, _ in outs}
    samples = {name: s for name, _, s in outs}
    return AdaptiveResult(_json.loads(report), md, images, samples, max_count)


def process(
    volume: Any,
    op: str,
    *,
    backend: str = "cpu",
    spacing: Any = None,
    affine: Any = None,
    progress: Optional[ProgressCallback] = None,
    dry_run: bool = False,
    **options: Any,
) -> Union[Volume, MemoryPlan]:
    """The process job (``voxlab process``): ``op`` is ``resample``, ``gaussian``,
    ``median`` or ``gradient-magnitude``, with the job's options (``dims``,
    ``spacing_out``, ``index_box``, ``world_box``, ``filter``, ``sigma``, ``size``).
    Returns a float32 :class:`Volume` with its affine (mm); with ``dry_run=True``, the
    job's :class:`MemoryPlan` (on the GPU, the slabs it would cut the volume into),
    nothing computed."""
    req: Dict[str, Any] = dict(options, op=op, backend=backend)
    if "spacing_out" in req:
        s = req.pop("spacing_out")
        req["spacing"] = [float(s)] if np.isscalar(s) else [float(x) for x in s]
    if "sigma" in req and req["sigma"] is not None and np.isscalar(req["sigma"]):
        req["sigma"] = [float(req["sigma"])]
    arr, aff = _input(req, volume, spacing, affine)
    if dry_run:
        return _plan("process", _dumps(req), arr, aff, progress)
    out, affine_out, meta = _voxlab.process(_dumps(req), arr, aff, progress)
    v = Volume(out, np.array(affine_out, dtype=np.float64), "process")
    v.info = _json.loads(meta)  # type: ignore[attr-defined]
    return v


def resample(
    volume: Any,
    *,
    dims: Optional[Sequence[int]] = None,
    spacing_out: Any = None,
    index_box: Optional[Sequence[float]] = None,
    world_box: Optional[Sequence[float]] = None,
    filter: str = "trilinear",
    backend: str = "cpu",
    spacing: Any = None,
    affine: Any = None,
    progress: Optional[ProgressCallback] = None,
    dry_run: bool = False,
) -> Union[Volume, MemoryPlan]:
    """Resamples a box of the volume (``voxlab process --op resample``) to ``dims``
    ``(nx, ny, nz)`` or to ``spacing_out`` mm, with any reconstruction filter; the
    output's affine places every voxel where it sampled (docs/processing.md).
    ``dry_run=True``: the job's :class:`MemoryPlan`, nothing computed."""
    opts: Dict[str, Any] = {"filter": filter}
    if dims is not None:
        opts["dims"] = [int(d) for d in dims]
    if spacing_out is not None:
        opts["spacing_out"] = spacing_out
    if index_box is not None:
        opts["index_box"] = [float(x) for x in index_box]
    if world_box is not None:
        opts["world_box"] = [float(x) for x in world_box]
    return process(volume, "resample", backend=backend, spacing=spacing, affine=affine,
                   progress=progress, dry_run=dry_run, **opts)


def bench(
    suite: str = "quick",
    *,
    out: Any = None,
    progress: Optional[ProgressCallback] = None,
    **options: Any,
) -> Dict[str, Any]:
    """Runs the benchmark suite (``voxlab bench``) and returns its report as a dict
    (``<name>.json``), with ``"paths"`` (the report files written into ``out``,
    default ``bench-results``) and ``"problems"`` (parity failures and errors, one
    line each) added. Options as the job's: ``only``, ``runs``, ``warmup``,
    ``backends`` (``cpu`` | ``gpu`` | ``all``), ``require_gpu``, ``budget``, ``name``,
    ``merge``, ``rerender``."""
    req: Dict[str, Any] = dict(options, suite=suite)
    if out is not None:
        req["out"] = _os.fspath(out)
    report, paths, problems = _voxlab.bench(_dumps(req), progress)
    r = _json.loads(report)
    r["paths"] = list(paths)
    r["problems"] = list(problems)
    return r
