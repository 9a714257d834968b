"""voxlab.ct.reconstruct with flat= and dark=: intensities made from exact line
integrals give the reconstruction of the line integrals; arrays and paths agree with
the command line; dead and starved pixels are counted and nothing is NaN."""

import numpy as np
import pytest

import voxlab
import voxlab.ct as vct


def _case():
    pr = vct.project("phantom:sphere", beam="cone", angles=16, cols=24, rows=16)
    # (angle, row, col), float64; scaled to line integrals up to 2 so that the
    # intensities stay well above the dark field.
    p = pr.projections * (2.0 / pr.projections.max())
    rows, cols = p.shape[1:]
    k = np.arange(rows * cols, dtype=np.float64).reshape(rows, cols)
    flat = 1000.0 + 37.0 * (k % 7) + k // cols
    dark = 90.0 + (k % 5)
    i = np.where(p == 0.0, flat, dark + (flat - dark) * np.exp(-p))
    return pr, p, i, flat, dark


def test_arrays_give_the_line_integrals_reconstruction():
    pr, p, i, flat, dark = _case()
    want = vct.reconstruct(p, pr.geometry, size=16)
    assert want.info["intensity"] is None
    frames = np.stack([flat - 1.0, flat, flat + 1.0])  # averages to flat exactly
    got = vct.reconstruct(i, pr.geometry, size=16, flat=frames, dark=dark)
    np.testing.assert_allclose(got.array, want.array, rtol=0, atol=1e-12)
    rep = got.info["intensity"]
    assert rep["samples"] == p.size and rep["pixels"] == flat.size
    assert (rep["dead_pixels"], rep["starved"], rep["clamped"]) == (0, 0, 0)


def test_paths_equal_the_command_line(tmp_path, cli):
    pr, p, i, flat, dark = _case()
    fi, ff, fd = tmp_path / "i.npy", tmp_path / "flat.npy", tmp_path / "dark.npy"
    np.save(fi, i)
    np.save(ff, flat)
    np.save(fd, dark)
    import json

    (tmp_path / "i.geometry.json").write_text(json.dumps(pr.geometry))
    out = tmp_path / "r.npy"
    cli("reconstruct", fi, "--flat", ff, "--dark", fd, "--size", "16", "--out", out)
    got = vct.reconstruct(i, pr.geometry, size=16, flat=ff, dark=str(fd))
    np.testing.assert_array_equal(got.array.astype(np.float32), np.load(out))


def test_dead_and_starved_pixels_are_counted_and_finite():
    pr, p, i, flat, dark = _case()
    flat = flat.copy()
    flat[0, 3] = dark[0, 3]  # dead
    i = i.copy()
    i[2, 5, 5] = dark[5, 5] - 10.0  # starved
    got = vct.reconstruct(i, pr.geometry, size=16, flat=flat, dark=dark)
    assert np.isfinite(got.array).all()
    rep = got.info["intensity"]
    assert (rep["dead_pixels"], rep["starved"]) == (1, 1)


def test_bad_fields_are_clear():
    pr, p, i, flat, dark = _case()
    with pytest.raises(voxlab.FormatError, match="flat.*shape"):
        vct.reconstruct(i, pr.geometry, flat=flat[:, :-1])
    bad = dark.copy()
    bad[1, 1] = np.nan
    with pytest.raises(voxlab.VoxlabError, match="NaN"):
        vct.reconstruct(i, pr.geometry, flat=flat, dark=bad)
    with pytest.raises(voxlab.InvalidError, match="dark"):
        vct.reconstruct(i, pr.geometry, dark=dark)
