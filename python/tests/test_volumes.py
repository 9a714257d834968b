"""Volumes in and out, phantoms, transfer functions: against the command line's
output for the same arguments and against analytic truths."""

import json

import numpy as np
import pytest

import voxlab

DATA = ["data/mr-colin27/ch2.nii.gz", "data/mr-brain-dicom",
        "data/mr-brain-volpack/brainsmall.den", "data/microct-bone/bone_128x128x128.tif"]


@pytest.mark.parametrize("path", DATA)
def test_read_matches_voxlab_info(repo, cli, path):
    info = json.loads(cli("info", path, "--json").stdout)
    v = voxlab.read(repo / path)
    assert v.dims == tuple(info["dims"])
    assert v.array.shape == tuple(reversed(info["dims"]))
    assert v.array.flags["C_CONTIGUOUS"]
    assert v.format == info["format"]
    assert np.dtype(v.dtype).name == {"u8": "uint8", "u16": "uint16", "i16": "int16",
                                      "f32": "float32"}[info["type"]]
    np.testing.assert_array_equal(v.affine, np.array(info["affine_rows"]))
    np.testing.assert_allclose(v.spacing, info["spacing_mm"], rtol=1e-12)
    assert float(v.array.min()) == info["range"]["min"]
    assert float(v.array.max()) == info["range"]["max"]


@pytest.mark.parametrize("path", DATA + ["phantom:spheres:20"])
def test_info_is_the_command_lines_json(repo, cli, path):
    want = json.loads(cli("info", path, "--json", "--bins", "24").stdout)
    src = path if path.startswith("phantom:") else repo / path
    got = voxlab.info(src, bins=24)
    got["input"] = want["input"]  # the path as given
    assert got == want


def test_info_of_an_array():
    a = np.zeros((3, 4, 5), np.int16)
    a[1, 2, 3] = 7
    d = voxlab.info(a, bins=2)
    assert d["format"] == "array in memory" and d["dims"] == [5, 4, 3] and d["type"] == "i16"
    assert d["range"]["min"] == 0 and d["range"]["max"] == 7
    assert d["histogram"]["counts"] == [59, 1]


def test_read_npy_is_the_array_and_a_phantom_spec_reads(tmp_path):
    a = (np.arange(4 * 5 * 6, dtype=np.int16).reshape(4, 5, 6) - 50)
    np.save(tmp_path / "a.npy", a)
    v = voxlab.read(tmp_path / "a.npy")
    np.testing.assert_array_equal(v.array, a)
    assert v.array.dtype == np.int16
    p = voxlab.read("phantom:sphere:16")
    np.testing.assert_array_equal(p.array, voxlab.phantom("sphere", 16).array)


def test_read_raw(tmp_path):
    a = np.arange(3 * 4 * 5, dtype=">u2").reshape(3, 4, 5)
    (tmp_path / "a.raw").write_bytes(a.tobytes())
    v = voxlab.read(tmp_path / "a.raw", raw={"dims": [5, 4, 3], "sample": "u16",
                                             "endian": "big", "spacing": [1, 2, 3]})
    np.testing.assert_array_equal(v.array, a.astype(np.uint16))
    assert v.spacing == (1.0, 2.0, 3.0)


@pytest.mark.parametrize("ext", [".nrrd", ".nhdr", ".nii", ".nii.gz", ".npy"])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int16, np.float32])
def test_write_read_round_trip(tmp_path, ext, dtype):
    rng = np.random.default_rng(7)
    a = (rng.random((5, 6, 7)) * 200).astype(dtype)
    affine = np.array([[0.5, 0, 0, -10], [0, 0.75, 0, 3], [0, 0, 2.0, 4.5], [0, 0, 0, 1]])
    path = tmp_path / f"v{ext}"
    voxlab.write(path, a, affine=affine)
    v = voxlab.read(path)
    np.testing.assert_array_equal(v.array, a)
    assert v.array.dtype == dtype
    if ext != ".npy":  # .npy keeps no geometry
        np.testing.assert_allclose(v.affine, affine, atol=1e-6)


def test_write_volume_object_keeps_its_affine_and_float64_becomes_float32(tmp_path):
    a = np.linspace(0, 1, 2 * 3 * 4).reshape(2, 3, 4)
    voxlab.write(tmp_path / "f.nrrd", a, spacing=(1, 2, 3))
    v = voxlab.read(tmp_path / "f.nrrd")
    assert v.array.dtype == np.float32
    np.testing.assert_array_equal(v.array, a.astype(np.float32))
    assert v.spacing == (1.0, 2.0, 3.0)
    voxlab.write(tmp_path / "g.nii", v)
    np.testing.assert_array_equal(voxlab.read(tmp_path / "g.nii").affine, v.affine)


@pytest.mark.parametrize("name,size", [("shepp-logan-modified", "24"), ("spheres", "16,12,8"),
                                       ("marschner-lobb", "17")])
def test_phantom_equals_the_command_line(tmp_path, cli, name, size):
    out = tmp_path / "p.npy"
    cli("phantom", f"{name}:{size}", "--out", out)
    dims = [int(s) for s in size.split(",")]
    v = voxlab.phantom(name, dims[0] if len(dims) == 1 else dims)
    np.testing.assert_array_equal(v.array, np.load(out))


@pytest.mark.parametrize("name", ["shepp-logan", "spheres", "marschner-lobb", "ellipsoid"])
def test_phantom_samples_are_its_exact_values_at_voxel_centres(name):
    v = voxlab.phantom(name, (9, 8, 7))
    k, j, i = np.meshgrid(*[np.arange(n) for n in v.array.shape], indexing="ij")
    ijk = np.stack([i, j, k], axis=-1).reshape(-1, 3)
    exact = voxlab.phantom_values(name, v.world(ijk)).reshape(v.array.shape)
    np.testing.assert_array_equal(v.array, exact.astype(np.float32))


def test_sphere_line_integrals_are_chords():
    # The sphere phantom: density 1, radius 0.6 of the half extent h (h from the grid).
    v = voxlab.phantom("sphere", 8)
    h = v.spacing[0] * 8 / 2
    r = 0.6 * h
    d = np.array([0.0, 0.3, 0.5, 0.59]) * h
    origins = np.stack([np.full_like(d, -1000.0), d, np.zeros_like(d)], axis=1)
    dirs = np.tile([2.0, 0.0, 0.0], (len(d), 1))  # not unit length: |d| scales dt
    got = voxlab.phantom_line_integrals("sphere", origins, dirs)
    np.testing.assert_allclose(got, 2 * np.sqrt(r * r - d * d), rtol=1e-12)
    # A bounded piece: from the centre plane onwards is half the chord.
    half = voxlab.phantom_line_integrals("sphere", origins, dirs, t0=500.0)
    np.testing.assert_allclose(half, np.sqrt(r * r - d * d), rtol=1e-12)


def test_phantom_errors():
    with pytest.raises(voxlab.InvalidError, match="not one of") as e:
        voxlab.phantom("nope", 8)
    assert isinstance(e.value, ValueError)
    assert "sphere" in voxlab.phantom_names()


def test_presets_are_the_command_lines(cli):
    names = [line.split()[0] for line in cli("tf").stdout.splitlines() if line.strip()]
    assert voxlab.TransferFunction.presets()[: len(names)] == names
    for n in names:
        assert voxlab.TransferFunction.preset(n).to_dict() == json.loads(cli("tf", n).stdout)


def test_transfer_function_points_json_and_values():
    tf = voxlab.TransferFunction.from_points(
        [(0.0, (0, 0, 0, 0)), (1.0, (1, 0.5, 0.25, 0.8))], window=(2.0, -1.0))
    assert tf.domain == (0.0, 1.0)
    back = voxlab.TransferFunction.from_json(tf.to_json())
    assert back == tf
    # Ψ(t) = 2t − 1, then linear between the points (clamped outside the domain).
    t = np.array([0.5, 0.75, 1.0, 0.0, 2.0])
    u = np.clip(2 * t - 1, 0, 1)
    np.testing.assert_allclose(tf(t), u[:, None] * np.array([1, 0.5, 0.25, 0.8]), atol=1e-15)
    assert tf(np.zeros((2, 3))).shape == (2, 3, 4)
    with pytest.raises(voxlab.VoxlabError):
        voxlab.TransferFunction.from_json('{"domain": [0, 1], "points": [], "bogus": 1}')
    with pytest.raises(voxlab.InvalidError):
        voxlab.TransferFunction.preset("no-such-preset")


# --- The copy rule ---------------------------------------------------------------------

@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int16, np.float32])
def test_a_contiguous_array_is_read_in_place(dtype):
    a = np.arange(4 * 5 * 6).reshape(4, 5, 6).astype(dtype)
    borrowed, address = voxlab._voxlab._volume_buffer(a)
    assert borrowed and address == a.ctypes.data


def test_other_layouts_are_copied_first():
    a = np.arange(4 * 5 * 6, dtype=np.float32).reshape(4, 5, 6)
    # float64 becomes float32 (the library's widest voxel type): a copy.
    borrowed, address = voxlab._voxlab._volume_buffer(a.astype(np.float64))
    assert not borrowed
    # A strided view is made contiguous by the Python half, and that copy is lent.
    view = voxlab._volume_array(a[:, :, ::2])
    assert view.flags.c_contiguous and not np.shares_memory(view, a)
    borrowed, address = voxlab._voxlab._volume_buffer(view)
    assert borrowed and address == view.ctypes.data
    # A contiguous native array passes the Python half untouched.
    assert voxlab._volume_array(a) is a


def test_a_borrowed_volume_renders_as_a_copy_does():
    a = voxlab.phantom("spheres", 24).array
    lent = voxlab.render(a, mode="mip", view="+z", step=1.0).image
    copied = voxlab.render(a.copy(), mode="mip", view="+z", step=1.0).image
    np.testing.assert_array_equal(lent, copied)
    np.testing.assert_array_equal(lent, a.max(axis=0))
