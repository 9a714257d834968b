"""Errors, warnings and the worker thread: library errors keep the command line's
messages, panics become exceptions, NaN voxels warn or fail as the job says."""

import warnings

import numpy as np
import pytest

import voxlab
from voxlab import _voxlab


def test_the_hierarchy():
    assert issubclass(voxlab.FileError, OSError)
    assert issubclass(voxlab.FormatError, ValueError) and issubclass(voxlab.FormatError, OSError)
    for c in (voxlab.InvalidError, voxlab.TooLargeError, voxlab.NonFiniteError,
              voxlab.ShapeError, voxlab.LayoutError):
        assert issubclass(c, ValueError) and issubclass(c, voxlab.VoxlabError)
    assert issubclass(voxlab.DtypeError, TypeError)
    assert issubclass(voxlab.UnsupportedError, NotImplementedError)
    assert issubclass(voxlab.NoGpuError, voxlab.GpuError) and issubclass(voxlab.GpuError, RuntimeError)


def test_a_panic_is_an_exception_not_a_crash():
    with pytest.raises(voxlab.InternalError, match="boom 42") as e:
        _voxlab._panic_in_job("boom 42")
    assert isinstance(e.value, RuntimeError)
    _voxlab._panic_in_job.__doc__  # the interpreter is still alive


def test_messages_are_the_command_lines(tmp_path, cli):
    bad = tmp_path / "bad.nrrd"
    bad.write_bytes(b"NRRD0004\ntype: float\ndimension: 3\nsizes: 2 2\nencoding: raw\n\n")
    r = cli("info", bad, check=False)
    assert r.returncode != 0
    with pytest.raises(voxlab.FormatError) as e:
        voxlab.read(bad)
    assert str(e.value) in r.stderr
    with pytest.raises(voxlab.FileError) as e:
        voxlab.read(tmp_path / "missing.nii")
    assert "missing.nii" in str(e.value)
    assert str(e.value) in cli("info", tmp_path / "missing.nii", check=False).stderr


def test_non_finite_voxels_warn_or_fail():
    a = np.ones((4, 5, 6), np.float32)
    a[1, 2, 3] = np.nan
    with pytest.warns(voxlab.VoxlabWarning, match="NaN"):
        r = voxlab.render(a, mode="mip", view="+z", step=1)
    assert np.isfinite(r.image).all()
    with pytest.raises(voxlab.NonFiniteError, match="non-finite"):
        voxlab.render(a, mode="mip", view="+z", step=1, non_finite="error")
    v = voxlab.Volume(a)
    voxlab.write("/tmp/voxlab-nan-test.npy", v)
    assert np.isnan(voxlab.read("/tmp/voxlab-nan-test.npy").array[1, 2, 3])  # kept as stored


def test_unsupported_backends_say_what_runs():
    with pytest.raises(voxlab.InvalidError, match="backend"):
        voxlab.Renderer("quantum")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        voxlab.Renderer("cpu")  # no warning for a plain CPU renderer
