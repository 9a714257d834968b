"""NIfTI-1 and NIfTI-2 against nibabel (an independent implementation), both ways:
3-D and 4-D files (one 3-D volume read at a time with ``frame``), plain and gzip, every
voxel type, the affine (NIfTI-2 keeps it in float64), and ``info``'s frame count."""

import numpy as np
import pytest

import voxlab

nib = pytest.importorskip("nibabel")


def as_zyx(a):
    """nibabel's (x, y, z) array as voxlab's (nz, ny, nx)."""
    return np.ascontiguousarray(np.transpose(a, (2, 1, 0)))


AFFINE = np.array([[0.5, 0.1, 0.0, -10.125], [0.0, 1.25, 0.2, 3.0],
                   [0.05, 0.0, 2.0, 7.5], [0, 0, 0, 1]])


@pytest.mark.parametrize("image", ["Nifti1Image", "Nifti2Image"])
@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.uint16, np.float32, np.float64])
@pytest.mark.parametrize("name", ["v.nii", "v.nii.gz"])
def test_four_d_files_written_by_nibabel_read_frame_by_frame(tmp_path, image, dtype, name):
    a = (np.random.default_rng(3).random((5, 4, 3, 6)) * 200).astype(dtype)
    path = tmp_path / name
    nib.save(getattr(nib, image)(a, AFFINE), path)
    loaded = nib.load(path)
    assert voxlab.info(path)["frames"] == {"count": 6, "described": 0}
    with pytest.raises(voxlab.FormatError, match="6 3-D volumes"):
        voxlab.read(path)
    for k in (0, 2, 5):
        v = voxlab.read(path, frame=k)
        want = as_zyx(a[..., k])
        np.testing.assert_array_equal(v.array, want.astype(v.array.dtype))
        np.testing.assert_allclose(v.affine, loaded.affine, rtol=0, atol=1e-12)
    with pytest.raises(voxlab.FormatError, match="past the file's 6"):
        voxlab.read(path, frame=6)


@pytest.mark.parametrize("version", [1, 2])
def test_files_voxlab_writes_read_in_nibabel(tmp_path, version):
    a = (np.random.default_rng(4).random((3, 4, 5)) * 100).astype(np.float32)
    path = tmp_path / "w.nii.gz"
    voxlab.write(path, a, affine=AFFINE, nifti_version=version)
    img = nib.load(path)
    assert isinstance(img, nib.Nifti2Image if version == 2 else nib.Nifti1Image)
    np.testing.assert_array_equal(as_zyx(np.asarray(img.dataobj)), a)
    if version == 2:
        # float64 geometry: the affine exactly.
        np.testing.assert_array_equal(img.affine, AFFINE)
    else:
        np.testing.assert_array_equal(img.affine, AFFINE.astype(np.float32).astype(np.float64))
    back = voxlab.read(path)
    np.testing.assert_array_equal(back.array, a)
    np.testing.assert_array_equal(back.affine, img.affine)
    with pytest.raises(voxlab.InvalidError, match="nifti_version"):
        voxlab.write(tmp_path / "w.nrrd", a, nifti_version=2)


def test_a_frame_renders_and_the_command_line_agrees(tmp_path, cli):
    a = np.zeros((6, 6, 6, 3), np.float32)
    for k in range(3):
        a[..., k] = k + 1
    path = tmp_path / "t.nii"
    nib.save(nib.Nifti2Image(a, np.eye(4)), path)
    img = voxlab.render(path, frame=2, mode="mip", view="+z", step=1.0).image
    np.testing.assert_array_equal(img, np.full((6, 6), 3.0, np.float32))
    out = tmp_path / "m.npy"
    cli("render", path, "--frame", "1", "--mode", "mip", "--view", "+z", "--step", "1",
        "--out", out)
    np.testing.assert_array_equal(np.load(out), np.full((6, 6), 2.0, np.float32))
