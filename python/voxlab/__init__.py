"""voxlab: volume rendering and tomography, with an exact CPU oracle and a GPU port.

The Python package is a thin shell over the Rust library's jobs (``voxlab::jobs``):
the same requests, the same validation, the same error messages as the ``voxlab``
command line, with NumPy arrays in and out.

Conventions (docs/python.md has them all):

- A volume is a C-ordered NumPy array of shape ``(nz, ny, nx)``, x fastest: element
  ``a[k, j, i]`` is voxel ``(i, j, k)``. Its ``affine`` maps voxel ``(i, j, k, 1)`` to
  world millimetres. dtypes: uint8, uint16, int16, float32, float64 (float64 volumes
  are stored as float32, the library's widest voxel type).
- Images come back as float32 ``(h, w, 4)`` RGBA or ``(h, w)`` scalars, row 0 at the
  top: exactly the arrays the command line writes to ``.npy``.
- The GIL is released while Rust computes; long jobs take ``progress=callback``
  (called as ``callback(stage, done, total)``) and stop on Ctrl-C.
- Errors are :class:`VoxlabError` subclasses (see :mod:`voxlab._errors`).

Submodules: :mod:`voxlab.fft` (numpy.fft's namespace on voxlab's FFTs),
:mod:`voxlab.transform` (scikit-image's ``iradon`` on voxlab's FBP), :mod:`voxlab.ct`
(forward projection, FBP and FDK with the library's geometry) and
:mod:`voxlab.ndimage` (scipy.ndimage's Gaussian, median and gradient magnitude).
Also :func:`fvr`, :func:`d2vr`, :func:`adaptive`, :func:`process`, :func:`resample`
and :func:`bench`: the remaining jobs.
"""

from __future__ import annotations

import json as _json
import os as _os
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _voxlab
from ._errors import (
    CancelledError,
    DtypeError,
    FileError,
    FormatError,
    GpuError,
    InternalError,
    InvalidError,
    LayoutError,
    NoGpuError,
    NonFiniteError,
    ShapeError,
    TooLargeError,
    UnsupportedError,
    VoxlabError,
    VoxlabWarning,
)

__version__ = _voxlab.__version__

ProgressCallback = Callable[[str, int, int], Any]

#: The voxel dtypes a volume may have.
VOLUME_DTYPES = (np.uint8, np.uint16, np.int16, np.float32, np.float64)

#: The backends every job knows: the f64 oracle, the same CPU code in f32, the GPU
#: port, and ``auto`` (a hardware GPU when there is one, else the oracle).
BACKENDS = ("cpu", "cpu-f32", "gpu", "auto")


# ------------------------------------------------------------------------------------
# Memory plans
# ------------------------------------------------------------------------------------


@dataclass
class MemoryPlan:
    """What a job would allocate and how it would cut itself to fit, worked out without
    doing the work: what ``dry_run=True`` returns (the command line's ``--dry-run``).
    The job reads its input and makes every check its run makes before the work, so a
    dry run raises what the run would raise — :class:`TooLargeError` for a job that
    cannot fit even split — and nothing is rendered, reconstructed or written.

    ``host_bytes``: the job's large host arrays at their peak. ``device`` (GPU backends
    only): ``adapter``, ``peak_bytes`` (the most held at once), ``largest_buffer_bytes``,
    the planner's ``max_binding_bytes`` and ``max_texture_3d`` (lowered by
    ``VOXLAB_GPU_MAX_BINDING`` and ``VOXLAB_GPU_MAX_TEXTURE_3D``, each lowering one line
    of ``lowered``), the adapter's own ``adapter_max_binding_bytes`` and, where known,
    ``memory_bytes``. ``split``: how the work is cut, one line per split (``"ray casting
    in 8 bricks (…)"``), empty when it runs in one piece. ``writes``: the files the job
    would write (none for the Python functions, which return arrays). ``str(plan)`` is
    the text ``--dry-run`` prints."""

    job: str
    backend: str
    host_bytes: int
    device: Optional[Dict[str, Any]]
    split: List[str]
    writes: List[str]
    text: str = field(repr=False)

    def __str__(self) -> str:
        return self.text


def _plans(job: str, request: str, *args: Any, **kwargs: Any) -> Tuple[MemoryPlan, ...]:
    """The memory plans of ``job`` for its JSON request (``_voxlab.plan``)."""
    return tuple(MemoryPlan(**_json.loads(p))
                 for p in _voxlab.plan(job, request, *args, **kwargs))


def _plan(job: str, request: str, *args: Any, **kwargs: Any) -> MemoryPlan:
    """The memory plan of a job that makes one."""
    (plan,) = _plans(job, request, *args, **kwargs)
    return plan


# ------------------------------------------------------------------------------------
# Arrays
# ------------------------------------------------------------------------------------


def _volume_array(a: Any, what: str = "volume") -> np.ndarray:
    """``a`` as an array the library reads in place: 3-D, a voxel dtype, native byte
    order, C-contiguous and aligned. Such an array is passed on as it is, and the
    library reads its buffer without a copy (uint8, uint16, int16, float32; float64 is
    converted to float32); any other layout or byte order is copied here first."""
    arr = np.asarray(a)
    if arr.dtype.kind == "c" or arr.dtype.type not in VOLUME_DTYPES:
        raise DtypeError(
            f"a {what} is uint8, uint16, int16, float32 or float64; got {arr.dtype}"
        )
    if arr.ndim != 3:
        raise ShapeError(
            f"a {what} is a 3-D array of shape (nz, ny, nx); got shape {arr.shape}"
        )
    if 0 in arr.shape:
        raise ShapeError(f"a {what} has at least one voxel per axis; got shape {arr.shape}")
    if not arr.dtype.isnative:
        arr = arr.astype(arr.dtype.newbyteorder("="))
    return np.require(arr, requirements=["C_CONTIGUOUS", "ALIGNED"])


def _affine(affine: Any = None, spacing: Any = None) -> np.ndarray:
    """A 4x4 voxel-to-world matrix from ``affine`` or ``spacing`` (identity when
    neither)."""
    if affine is not None and spacing is not None:
        raise InvalidError("invalid geometry: give spacing or affine, not both")
    if affine is not None:
        m = np.asarray(affine, dtype=np.float64)
        if m.shape != (4, 4):
            raise ShapeError(f"an affine is a 4x4 matrix; got shape {m.shape}")
        return m
    m = np.eye(4)
    if spacing is not None:
        s = np.asarray(spacing, dtype=np.float64).reshape(-1)
        if s.shape == (1,):
            s = np.repeat(s, 3)
        if s.shape != (3,):
            raise ShapeError(f"spacing is (sx, sy, sz) in mm; got {spacing!r}")
        m[0, 0], m[1, 1], m[2, 2] = s
    return m


# ------------------------------------------------------------------------------------
# Volumes
# ------------------------------------------------------------------------------------


@dataclass
class Volume:
    """A volume: voxels, geometry and where it came from.

    ``array`` has shape ``(nz, ny, nx)`` (x fastest); ``affine`` maps voxel
    ``(i, j, k, 1)`` (``i`` along x, the last array axis) to world millimetres.
    """

    array: np.ndarray
    affine: np.ndarray = field(default_factory=lambda: np.eye(4))
    #: The file format's name (``"NRRD"``, ``"analytic phantom"``, ``"array"`` …).
    format: str = "array"
    #: The path or phantom spec it was read from, if any.
    source: Optional[str] = None

    def __post_init__(self) -> None:
        self.affine = _affine(self.affine)

    @property
    def spacing(self) -> Tuple[float, float, float]:
        """Voxel spacing ``(sx, sy, sz)`` in mm: the lengths of the affine's columns."""
        n = np.linalg.norm(self.affine[:3, :3], axis=0)
        return (float(n[0]), float(n[1]), float(n[2]))

    @property
    def shape(self) -> Tuple[int, ...]:
        return tuple(self.array.shape)

    @property
    def dims(self) -> Tuple[int, int, int]:
        """``(nx, ny, nz)``: the library's order."""
        nz, ny, nx = self.array.shape
        return (nx, ny, nz)

    @property
    def dtype(self) -> np.dtype:
        return self.array.dtype

    def world(self, ijk: Any) -> np.ndarray:
        """World coordinates (mm) of voxel indices ``(..., 3)`` given as ``(i, j, k)``."""
        p = np.asarray(ijk, dtype=np.float64)
        return p @ self.affine[:3, :3].T + self.affine[:3, 3]

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        a = self.array
        return a if dtype is None else a.astype(dtype)

    def __repr__(self) -> str:
        sx, sy, sz = self.spacing
        return (
            f"Volume(shape={self.shape}, dtype={self.dtype}, "
            f"spacing=({sx:g}, {sy:g}, {sz:g}) mm, format={self.format!r})"
        )


def _as_volume(v: Any, spacing: Any = None, affine: Any = None) -> Tuple[np.ndarray, np.ndarray]:
    if isinstance(v, Volume):
        if spacing is not None or affine is not None:
            return _volume_array(v.array), _affine(affine, spacing)
        return _volume_array(v.array), v.affine
    return _volume_array(v), _affine(affine, spacing)


def read(path: Union[str, "os.PathLike[str]"], *, raw: Optional[Dict[str, Any]] = None,
         frame: Optional[int] = None) -> Volume:
    """Reads a volume: every format ``voxlab info`` reads (NRRD attached/detached,
    NIfTI-1 ``.nii``/``.nii.gz``, DICOM file or series directory, PVM, VolPack
    ``.den``, multi-page TIFF, ``.npy``, MetaImage ``.mha``/``.mhd``), a
    ``phantom:NAME[:SIZE]`` or ``embedded:NAME`` spec, or raw
    samples described by ``raw={"dims": [nx, ny, nz], "sample": "u16", "endian":
    "little", "spacing": [sx, sy, sz], "offset": 0}``.

    A file that holds several 3-D volumes (a NIfTI time series or vector image,
    ``dim[4..7]``; a 4-D or vector MetaImage; a NRRD with a non-spatial axis; a DICOM
    time series) is read one volume at a time: ``frame=k`` (0, 1, …; :func:`info` says
    how many there are); without it such a file is refused naming how many it holds.

    NaN and infinite voxels are kept as stored. Raises :class:`FileError`,
    :class:`FormatError` (the file and the field) or :class:`TooLargeError`.
    """
    source = _os.fspath(path)
    raw_json = None if raw is None else _json.dumps(raw)
    arr, affine, fmt, _kind = _voxlab.read_volume(source, raw_json, frame)
    return Volume(arr, np.array(affine, dtype=np.float64), fmt, source)


def info(source: Any, *, bins: int = 16) -> Dict[str, Any]:
    """``voxlab info --json`` as a dict: format, dims, spacing, type, orientation,
    affine rows, value range, NaN/inf counts and a histogram of ``bins`` bins (the
    command line's default 16), for a path, a ``phantom:`` spec, a :class:`Volume` or
    an array (``format`` is then ``"array in memory"``)."""
    if isinstance(source, (str, _os.PathLike)):
        return _json.loads(_voxlab.volume_info(_os.fspath(source), int(bins)))
    arr, aff = _as_volume(source)
    name = source.source if isinstance(source, Volume) and source.source else "array"
    return _json.loads(_voxlab.volume_info(name, int(bins), arr, aff.tolist()))


def write(
    path: Union[str, "os.PathLike[str]"],
    volume: Any,
    *,
    spacing: Any = None,
    affine: Any = None,
    nifti_version: Optional[int] = None,
) -> None:
    """Writes a volume by extension, atomically: ``.nrrd`` (gzip), ``.nhdr`` (detached,
    data in ``<stem>.raw.gz``), ``.nii``/``.nii.gz`` (affine as sform and qform),
    ``.mha``/``.mhd`` (MetaImage, ITK's affine convention; ``.mhd`` keeps the data in
    ``<stem>.raw``) or ``.npy`` (shape ``(nz, ny, nx)``, no geometry).

    ``volume`` is a :class:`Volume` (its affine is written) or an array with
    ``spacing=(sx, sy, sz)`` mm or a 4x4 ``affine`` (default: 1 mm voxels at the
    origin). float64 arrays are written as float32. ``nifti_version``: 1 or 2 for
    ``.nii``/``.nii.gz`` (default: NIfTI-1, or NIfTI-2 when an axis is longer than
    32767 voxels; NIfTI-2 keeps the affine in float64, NIfTI-1 in float32).
    """
    arr, aff = _as_volume(volume, spacing, affine)
    _voxlab.write_volume(_os.fspath(path), arr, aff.tolist(), nifti_version)


def phantom(name: str, size: Union[int, Sequence[int]] = 128) -> Volume:
    """An analytic phantom point-sampled at the voxel centres of a grid covering its
    cube (``voxlab phantom``): ``size`` is N (N³) or ``(nx, ny, nz)``. The volume is
    float32, centred on the world origin (see :func:`phantom_names`)."""
    name = name[len("phantom:"):] if name.startswith("phantom:") else name
    if isinstance(size, (int, np.integer)):
        spec = f"{name}:{int(size)}"
    else:
        spec = f"{name}:" + ",".join(str(int(s)) for s in size)
    arr, affine, fmt, _kind = _voxlab.sample_phantom(spec)
    return Volume(arr, np.array(affine, dtype=np.float64), fmt, f"phantom:{spec}")


def phantom_names() -> list:
    """The analytic phantoms' names."""
    return list(_voxlab.phantom_names())


def phantom_values(name: str, points: Any) -> np.ndarray:
    """The phantom's exact values at world points ``(n, 3)`` in mm (the frame of
    :func:`phantom`'s volumes): no sampling, no interpolation."""
    p = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    return _voxlab.phantom_values(name, p)


def phantom_line_integrals(
    name: str,
    origins: Any,
    directions: Any,
    t0: float = -np.inf,
    t1: float = np.inf,
) -> np.ndarray:
    """Exact line integrals ``∫ f(o + t·d) |d| dt`` over ``t ∈ [t0, t1]`` (density × mm)
    along rays with world origins and directions ``(n, 3)`` in mm (``d`` need not be
    unit length; infinite bounds integrate the whole line)."""
    o = np.ascontiguousarray(np.asarray(origins, dtype=np.float64).reshape(-1, 3))
    d = np.ascontiguousarray(np.asarray(directions, dtype=np.float64).reshape(-1, 3))
    return _voxlab.phantom_line_integrals(name, o, d, float(t0), float(t1))


# ------------------------------------------------------------------------------------
# Transfer functions
# ------------------------------------------------------------------------------------


class TransferFunction:
    """A 1D transfer function: control points ``(value, (r, g, b, a))`` over a domain,
    the window map ``Ψ(t) = a·t + b`` from raw values into the domain, linear or
    Bézier interpolation, optional faux shading. JSON is the library's format (the
    files ``--tf`` reads, what ``voxlab tf NAME`` prints)."""

    def __init__(self, json_text: str):
        self._json = _voxlab.tf_normalise(json_text)

    @staticmethod
    def presets() -> list:
        """The names of the built-in presets."""
        return list(_voxlab.tf_presets())

    @classmethod
    def preset(cls, name: str) -> "TransferFunction":
        """A built-in preset (``voxlab tf NAME``)."""
        return cls(_voxlab.tf_preset(name))

    @classmethod
    def from_json(cls, text: str) -> "TransferFunction":
        """Parses and validates the library's JSON (unknown fields are errors)."""
        return cls(text)

    @classmethod
    def from_points(
        cls,
        points: Any,
        *,
        domain: Optional[Sequence[float]] = None,
        window: Optional[Tuple[float, float]] = None,
        interpolation: str = "linear",
        faux_shading: Optional[float] = None,
        name: str = "",
    ) -> "TransferFunction":
        """From control points: ``[(value, (r, g, b, a)), …]`` or an ``(n, 5)`` array of
        rows ``value, r, g, b, a`` (opacity per voxel-length step). ``domain`` defaults
        to the values' range; ``window=(a, b)`` is the map ``Ψ(t) = a·t + b``."""
        rows = []
        for p in points:
            if len(p) == 2:
                v, rgba = p
                rows.append((float(v), [float(c) for c in rgba]))
            else:
                rows.append((float(p[0]), [float(c) for c in p[1:5]]))
        if not rows:
            raise InvalidError("invalid transfer function: no control points")
        values = [v for v, _ in rows]
        d = [min(values), max(values)] if domain is None else [float(x) for x in domain]
        obj: Dict[str, Any] = {
            "name": name,
            "domain": d,
            "points": [{"value": v, "rgba": c} for v, c in rows],
        }
        if window is not None:
            obj["window"] = {"a": float(window[0]), "b": float(window[1])}
        if interpolation != "linear":
            obj["interpolation"] = interpolation
        if faux_shading is not None:
            obj["faux_shading"] = float(faux_shading)
        return cls(_json.dumps(obj))

    def to_json(self) -> str:
        """The library's JSON."""
        return self._json

    def to_dict(self) -> Dict[str, Any]:
        return _json.loads(self._json)

    @property
    def name(self) -> str:
        return self.to_dict().get("name", "")

    @property
    def domain(self) -> Tuple[float, float]:
        d = self.to_dict()["domain"]
        return (d[0], d[1])

    @property
    def points(self) -> list:
        return [(p["value"], tuple(p["rgba"])) for p in self.to_dict()["points"]]

    def __call__(self, values: Any) -> np.ndarray:
        """RGBA at raw data values (the window map, then the control points, faux
        shading when on): shape ``values.shape + (4,)``, float64."""
        v = np.asarray(values, dtype=np.float64)
        out = _voxlab.tf_eval(self._json, np.ascontiguousarray(v.reshape(-1)))
        return out.reshape(v.shape + (4,))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, TransferFunction) and self.to_dict() == other.to_dict()

    def __repr__(self) -> str:
        return f"TransferFunction(name={self.name!r}, points={len(self.points)}, domain={self.domain})"


# ------------------------------------------------------------------------------------
# Rendering
# ------------------------------------------------------------------------------------

# Keyword arguments that go elsewhere than the scene request's top level.
_REQUEST_KEYS = ("sampling", "stereo", "repeat", "volumes")
_VIEW_KEYS = ("azimuth", "elevation")
_ACCEL_KEYS = (
    "skip_empty", "block_size", "clip_box", "clip_space", "jitter", "accumulate",
    "interleaved", "clip_mesh", "clip_mesh_units",
)
_LOAD_KEYS = ("phantom_size", "raw", "non_finite", "frame", "confine_data_files")


@dataclass
class RenderResult:
    """A rendered frame: ``image`` (float32 ``(h, w, 4)`` RGBA, or ``(h, w)`` for MIP,
    MinIP, X-ray), ``samples`` (float32 ``(h, w)`` samples per ray, when asked), and
    how it was made."""

    image: np.ndarray
    samples: Optional[np.ndarray]
    total_samples: int
    #: Seconds of rendering (the median frame with ``repeat``).
    seconds: float
    #: Who rendered: ``cpu (f64 oracle)``, ``cpu-f32``, ``gpu (ADAPTER, Vulkan)``.
    engine: str
    backend: str
    #: GPU only: setup, upload, kernel, readback, total seconds.
    gpu_timings: Optional[Dict[str, Any]] = None
    #: The rest of the job's report (settings, frames, stereo, fallback reason).
    info: Dict[str, Any] = field(default_factory=dict)


class _Request:
    """Keyword arguments as the render job's JSON request; a TransferFunction or a
    dict of 2D widgets given in memory travels beside it as JSON (the scene's
    ``transfer`` / ``transfer_2d``, parsed by the library; no file)."""

    def __init__(self, options: Dict[str, Any], top_keys: Sequence[str]):
        #: The in-memory transfer functions' JSON: {"tf": …, "tf2d": …}.
        self.transfers: Dict[str, str] = {}
        scene: Dict[str, Any] = {}
        top: Dict[str, Any] = {}
        view: Dict[str, Any] = {}
        accel: Dict[str, Any] = {}
        load: Dict[str, Any] = {}
        for key, value in options.items():
            if key in top_keys:
                top[key] = value
            elif key == "view":
                if isinstance(value, dict):
                    view.update(value)
                else:
                    view["axis"] = value
            elif key in _VIEW_KEYS:
                view[key] = value
            elif key in _ACCEL_KEYS:
                accel[key] = value
            elif key in _LOAD_KEYS:
                load[key] = value
            elif key in ("tf", "tf2d") and not isinstance(value, (str, _os.PathLike)):
                self.transfers[key] = (
                    value.to_json() if isinstance(value, TransferFunction)
                    else _json.dumps(value, default=_json_default)
                )
            elif isinstance(value, _os.PathLike):
                scene[key] = _os.fspath(value)
            else:
                scene[key] = value
        if view:
            scene["view"] = view
        if accel:
            scene["accel"] = accel
        self.scene = scene
        self.top = top
        self.load = load

    def input(self, volume: Any) -> Tuple[Optional[np.ndarray], Optional[list]]:
        """Sets the scene's input; returns the array and affine for a volume in memory."""
        if volume is None or isinstance(volume, (str, _os.PathLike)):
            if volume is not None:
                self.scene["input"] = {"source": _os.fspath(volume)}
            if self.load:
                self.scene.setdefault("input", {"source": "phantom:shepp-logan-modified"})
                self.scene["input"]["load"] = self.load
            return None, None
        spacing = self.scene.pop("spacing", None)
        affine = self.scene.pop("affine", None)
        arr, aff = _as_volume(volume, spacing, affine)
        self.scene["input"] = {"source": "array", "load": self.load} if self.load else {"source": "array"}
        return arr, aff.tolist()

    def json(self, **extra: Any) -> str:
        return _json.dumps({"scene": self.scene, **self.top, **extra}, default=_json_default)

    def close(self) -> None:
        pass


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"{type(o).__name__} is not a render option value")


def _result(parts: Tuple[np.ndarray, Optional[np.ndarray], str]) -> RenderResult:
    image, samples, meta = parts
    info = _json.loads(meta)
    return RenderResult(
        image=image,
        samples=samples,
        total_samples=int(info.pop("total_samples")),
        seconds=float(info.pop("seconds")),
        engine=info.pop("engine"),
        backend=info.pop("backend"),
        gpu_timings=info.pop("gpu_timings", None),
        info=info,
    )


def render(
    volume: Any = None,
    *,
    backend: str = "cpu",
    samples: bool = False,
    progress: Optional[ProgressCallback] = None,
    dry_run: bool = False,
    **options: Any,
) -> Union[RenderResult, MemoryPlan]:
    """Renders a volume (``voxlab render``): every mode, filter, camera and option of
    the render job, as keyword arguments named like its request fields (the command
    line's options with ``_`` for ``-``): ``mode``, ``tf`` (preset name, JSON file or
    :class:`TransferFunction`), ``tf2d``, ``tf_preset``, ``window=(width, centre)``,
    ``window_preset``, ``view`` (``"+z"`` … or the orbit's ``azimuth``/``elevation``),
    ``width``, ``height``, ``filter``, ``step``, ``ortho``, ``fov``, ``distance``,
    ``shading``, ``iso=[{"value":…, "color":…, "opacity":…}]``, ``skip_empty``,
    ``clip_box``, ``jitter``, ``accumulate``, ``stereo={"layout":…}``, ``repeat``,
    ``sampling``, ``volumes`` … An unknown keyword is an :class:`InvalidError` naming
    it.

    ``volume``: a :class:`Volume`, a ``(nz, ny, nx)`` array (with ``spacing=`` or
    ``affine=``), a file path, ``"phantom:NAME[:N]"``, or None (the modified
    Shepp–Logan phantom, 128³). ``backend``: ``cpu`` (the f64 oracle), ``cpu-f32``,
    ``gpu`` or ``auto``. ``samples=True`` also returns the samples-per-ray image.
    ``dry_run=True`` renders nothing and returns the job's :class:`MemoryPlan` (host
    and device bytes, and on the GPU the bricks it would cut the volume into).
    """
    req = _Request(options, _REQUEST_KEYS)
    try:
        arr, aff = req.input(volume)
        text = req.json(backend=backend, samples=bool(samples))
        if dry_run:
            return _plan("render", text, arr, aff, progress, **req.transfers)
        return _result(_voxlab.render(text, arr, aff, progress, **req.transfers))
    finally:
        req.close()


class Renderer:
    """A renderer that keeps its engine between renders: for ``backend="gpu"`` the
    device and its queue are opened once.

    :meth:`render` is one-shot: each call converts the volume (and on the GPU uploads
    it and compiles the pipelines) again. For many frames of one volume — an orbit, a
    transfer-function sweep — :meth:`prepare` it once and render the frames from the
    :class:`PreparedScene`: on the GPU the volume stays uploaded, and a frame makes
    again only what it changed.
    """

    def __init__(self, backend: str = "cpu"):
        self._inner = _voxlab.Renderer(backend)

    @property
    def backend(self) -> str:
        """The backend frames render on (``auto`` resolved)."""
        return self._inner.backend

    @property
    def fallback_reason(self) -> Optional[str]:
        """Why ``auto`` chose the CPU, if it did."""
        return self._inner.fallback_reason

    def describe(self) -> str:
        return self._inner.describe()

    def render(
        self,
        volume: Any = None,
        *,
        samples: bool = False,
        progress: Optional[ProgressCallback] = None,
        **options: Any,
    ) -> RenderResult:
        """One frame, with :func:`render`'s keyword arguments (but not ``stereo``,
        ``repeat``, ``volumes`` or ``sampling``, which :func:`render` does). The volume
        is converted (on the GPU: uploaded) for this frame alone."""
        req = _Request(options, _REQUEST_KEYS)
        try:
            arr, aff = req.input(volume)
            text = req.json(samples=bool(samples))
            return _result(self._inner.render(text, arr, aff, progress, **req.transfers))
        finally:
            req.close()

    def prepare(
        self,
        volume: Any = None,
        *,
        samples: bool = False,
        progress: Optional[ProgressCallback] = None,
        **options: Any,
    ) -> "PreparedScene":
        """Loads ``volume`` (as :func:`render` takes it) and prepares it for many frames:
        on the GPU the volume is uploaded here, once. ``samples`` and ``options``
        (:meth:`render`'s keyword arguments) are the frames' defaults; each
        :meth:`PreparedScene.render` may override any of them but those that choose
        the volume (``spacing``, ``affine``, ``state_file``, ``phantom_size``, ``raw``,
        ``non_finite``).

        The prepared scene holds the library's own copy of the volume, taken now:
        later changes to the array do not reach its frames (prepare again).
        """
        req = _Request(options, _REQUEST_KEYS)
        try:
            arr, aff = req.input(volume)
            inner = self._inner.prepare(req.json(), arr, aff, progress, **req.transfers)
        finally:
            req.close()
        return PreparedScene(inner, self, options, bool(samples))

    def __repr__(self) -> str:
        return f"Renderer({self.describe()!r})"


#: Options that choose the volume: given to :meth:`Renderer.prepare` only.
_VOLUME_KEYS = ("spacing", "affine", "state_file") + _LOAD_KEYS


class PreparedScene:
    """A volume prepared for many frames by :meth:`Renderer.prepare`.

    It holds the library's own copy of the volume, taken when it was prepared (later
    changes to the caller's array do not reach it). On the GPU it keeps a render
    session: the volume is uploaded once (by the first frame; a hardware-filtered frame
    of a uint8, uint16 or int16 volume uploads it as a 16-bit texture, an exact frame as
    float32), and each :meth:`render` makes again only what its options changed since
    the last frame (a new camera uploads nothing; a new transfer function uploads its
    lookup table; a new filter, mode or shading compiles its shader once). Each frame
    equals :func:`render` of the same volume and options, bit for bit.
    ``result.info["gpu_session"]`` counts what the session has done
    (``volume_uploads``, ``volume_bytes`` on the device, ``table_uploads``,
    ``pipelines_compiled``, ``prepare_passes``, ``frames``), ``result.gpu_timings`` what the frame did (``upload`` is 0 for a frame
    that uploaded nothing). On the CPU backends the conversion is kept for frames of
    the same filter and gradients (another filter converts again).

    Frames render one at a time (a second thread waits for the first).
    """

    def __init__(self, inner: Any, renderer: Renderer, options: Dict[str, Any],
                 samples: bool = False):
        self._inner = inner
        self._renderer = renderer
        self._options = {k: v for k, v in options.items() if k not in _VOLUME_KEYS}
        self._samples = samples

    @property
    def renderer(self) -> Renderer:
        return self._renderer

    @property
    def shape(self) -> Tuple[int, int, int]:
        """The prepared volume's shape ``(nz, ny, nx)``."""
        return tuple(self._inner.shape)

    def session_stats(self) -> Optional[Dict[str, int]]:
        """The GPU session's counters so far (None on the CPU backends)."""
        return _json.loads(self._inner.session_stats())

    def render(
        self,
        *,
        samples: Optional[bool] = None,
        progress: Optional[ProgressCallback] = None,
        **options: Any,
    ) -> RenderResult:
        """One frame: :meth:`Renderer.render`'s keyword arguments over the ones given
        to :meth:`Renderer.prepare` (all but those that choose the volume; ``samples``
        None: as prepared)."""
        bad = sorted(k for k in options if k in _VOLUME_KEYS)
        if bad:
            raise InvalidError(
                f"invalid PreparedScene.render option '{bad[0]}': it chooses the volume, "
                "which was fixed by Renderer.prepare; prepare another scene for another "
                "volume"
            )
        req = _Request({**self._options, **options}, _REQUEST_KEYS)
        try:
            text = req.json(samples=self._samples if samples is None else bool(samples))
            return _result(self._inner.render(text, progress, **req.transfers))
        finally:
            req.close()

    def __repr__(self) -> str:
        return f"PreparedScene({self.shape}, {self._renderer.describe()!r})"


# ------------------------------------------------------------------------------------
# Validation
# ------------------------------------------------------------------------------------


@dataclass
class CompareResult:
    """How far an image is from the oracle's: ``stats`` holds ``metrics::ErrorStats``
    (``n``, ``max_abs``, ``worst_index``, ``rmse``, ``rel_l2``, ``psnr_db``, ``n_over``,
    ``non_finite_mismatches``, ``peak``, ``max_abs_rel``); ``heatmap`` is the float32
    ``(h, w, 4)`` per-pixel max |Δ| heat map with its scale bar (``diff.png``)."""

    oracle: np.ndarray
    port: np.ndarray
    heatmap: np.ndarray
    stats: Dict[str, Any]
    passed: bool
    message: str
    info: Dict[str, Any] = field(default_factory=dict)


def _stats(meta: Dict[str, Any]) -> Dict[str, Any]:
    s = dict(meta.pop("stats"))
    s["peak"] = meta.pop("peak")
    s["max_abs_rel"] = meta.pop("max_abs_rel")
    return s


def compare_images(
    oracle: Any,
    port: Any,
    *,
    max_abs: Optional[float] = None,
    rmse: Optional[float] = None,
) -> CompareResult:
    """Compares two images of one shape (``(h, w)`` or ``(h, w, 4)``) with the library's
    parity check: error statistics, a verdict against ``max_abs``/``rmse`` (no bound
    when None) and the heat map."""
    a = np.ascontiguousarray(np.asarray(oracle, dtype=np.float64))
    b = np.ascontiguousarray(np.asarray(port, dtype=np.float64))
    heat, meta = _voxlab.compare_images(a, b, max_abs, rmse)
    info = _json.loads(meta)
    stats = _stats(info)
    return CompareResult(
        np.asarray(oracle), np.asarray(port), heat, stats, info.pop("passed"),
        info.pop("message"), info,
    )


def compare(
    volume: Any = None,
    image: Any = None,
    *,
    max_abs: Optional[float] = None,
    rmse: Optional[float] = None,
    progress: Optional[ProgressCallback] = None,
    dry_run: bool = False,
    **options: Any,
) -> Union[CompareResult, Tuple[MemoryPlan, ...]]:
    """The oracle against a port (``voxlab compare``).

    Without ``image``: renders the scene (``volume`` and :func:`render`'s keyword
    arguments) on the CPU f64 oracle and on the GPU and compares them; a scene the GPU
    would refuse (a filter it lacks, a missing device feature, a frame past the work
    limits) raises before the oracle renders. With ``image``
    (your own renderer's output for the same scene, laid out like voxlab's images):
    renders the oracle and compares ``image`` with it.

    ``dry_run=True`` renders nothing and returns the renders' :class:`MemoryPlan`\ s:
    the oracle's and the GPU's, or with ``image`` the oracle's alone.
    """
    if image is not None:
        if dry_run:
            return (render(volume, backend="cpu", progress=progress, dry_run=True,
                           **options),)
        ref = render(volume, backend="cpu", progress=progress, **options)
        r = compare_images(ref.image, image, max_abs=max_abs, rmse=rmse)
        r.info["cpu_seconds"] = ref.seconds
        return r
    req = _Request(options, ())
    try:
        arr, aff = req.input(volume)
        extra = {}
        if max_abs is not None:
            extra["max_abs"] = max_abs
        if rmse is not None:
            extra["rmse"] = rmse
        if dry_run:
            return _plans("compare", req.json(**extra), arr, aff, progress,
                          **req.transfers)
        cpu, gpu, heat, meta = _voxlab.compare(req.json(**extra), arr, aff, progress,
                                                **req.transfers)
    finally:
        req.close()
    info = _json.loads(meta)
    stats = _stats(info)
    return CompareResult(cpu, gpu, heat, stats, info.pop("passed"), info.pop("message"), info)


from . import ct, fft, transform  # noqa: E402  (submodules use the names above)
from ._jobs import (  # noqa: E402
    AdaptiveResult, D2vrResult, adaptive, bench, d2vr, fvr, process, resample,
)
from . import ndimage  # noqa: E402

__all__ = [
    "Volume", "read", "write", "info", "phantom", "phantom_names", "phantom_values",
    "phantom_line_integrals", "TransferFunction", "render", "Renderer", "PreparedScene",
    "RenderResult", "MemoryPlan",
    "compare", "compare_images", "CompareResult", "ct", "fft", "transform", "ndimage",
    "fvr", "d2vr", "D2vrResult", "adaptive", "AdaptiveResult", "process", "resample",
    "bench", "BACKENDS",
    "VOLUME_DTYPES", "VoxlabError", "FileError", "FormatError", "InvalidError",
    "TooLargeError", "NonFiniteError", "UnsupportedError", "GpuError", "NoGpuError",
    "CancelledError", "InternalError", "DtypeError", "ShapeError", "LayoutError",
    "VoxlabWarning",
]
