"""MetaImage both ways against ITK (SimpleITK, whose MetaImageIO is ITK's): files ITK
writes are read with ITK's values and affine, and files voxlab writes are read by ITK
with voxlab's."""

import numpy as np
import pytest

import voxlab

sitk = pytest.importorskip("SimpleITK")

# An oblique, anisotropic geometry: a rotation about an oblique axis, spacing and origin.
_angle = 0.37
_c, _s = np.cos(_angle), np.sin(_angle)
_ROT = np.array([[_c, -_s, 0.0], [_s, _c, 0.0], [0.0, 0.0, 1.0]]) @ np.array(
    [[1.0, 0.0, 0.0], [0.0, np.cos(0.2), -np.sin(0.2)], [0.0, np.sin(0.2), np.cos(0.2)]]
)
_SPACING = (0.7, 1.3, 2.25)
_ORIGIN = (-12.5, 3.25, 100.125)


def _itk_affine(img):
    """ITK's voxel-to-physical map: origin + direction · diag(spacing) · index."""
    d = np.array(img.GetDirection()).reshape(3, 3)
    a = np.eye(4)
    a[:3, :3] = d @ np.diag(img.GetSpacing())
    a[:3, 3] = img.GetOrigin()
    return a


def _itk_image(array):
    img = sitk.GetImageFromArray(array)  # array (nz, ny, nx) -> image (nx, ny, nz)
    img.SetSpacing(_SPACING)
    img.SetOrigin(_ORIGIN)
    img.SetDirection(tuple(_ROT.flatten()))
    return img


_DTYPES = [np.uint8, np.int16, np.uint16, np.float32, np.int8, np.int32, np.float64]


@pytest.mark.parametrize("dtype", _DTYPES, ids=lambda t: np.dtype(t).name)
@pytest.mark.parametrize("ext,compress", [(".mha", False), (".mha", True), (".mhd", False), (".mhd", True)])
def test_voxlab_reads_what_itk_writes(tmp_path, dtype, ext, compress):
    rng = np.random.default_rng(7)
    info = np.iinfo(dtype) if np.issubdtype(dtype, np.integer) else None
    if info is not None:
        lo, hi = max(info.min, -30000), min(info.max, 60000)
        arr = rng.integers(lo, hi, size=(5, 6, 7)).astype(dtype)
    else:
        arr = (rng.standard_normal((5, 6, 7)) * 100).astype(dtype)
    img = _itk_image(arr)
    path = tmp_path / f"itk{ext}"
    sitk.WriteImage(img, str(path), useCompression=compress)
    vol = voxlab.read(path)
    assert vol.format == "MetaImage"
    # voxlab's voxel types (docs/io.md): int8 and int32 and float64 widen or narrow as
    # every reader maps them; the values here are exact in the voxel type it gives.
    np.testing.assert_array_equal(vol.array.astype(np.float64), arr.astype(np.float32).astype(np.float64))
    np.testing.assert_allclose(vol.affine, _itk_affine(img), rtol=0, atol=1e-12)


@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.uint16, np.float32], ids=lambda t: np.dtype(t).name)
@pytest.mark.parametrize("ext", [".mha", ".mhd"])
def test_itk_reads_what_voxlab_writes(tmp_path, dtype, ext):
    rng = np.random.default_rng(11)
    arr = (rng.random((4, 5, 6)) * 200).astype(dtype)
    affine = np.eye(4)
    affine[:3, :3] = _ROT @ np.diag(_SPACING)
    affine[:3, 3] = _ORIGIN
    path = tmp_path / f"vox{ext}"
    voxlab.write(path, arr, affine=affine)
    img = sitk.ReadImage(str(path))
    np.testing.assert_array_equal(sitk.GetArrayFromImage(img), arr)
    np.testing.assert_allclose(img.GetSpacing(), _SPACING, rtol=0, atol=1e-12)
    np.testing.assert_allclose(img.GetOrigin(), _ORIGIN, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.array(img.GetDirection()).reshape(3, 3), _ROT, rtol=0, atol=1e-12)
    # And voxlab reads its own file back exactly.
    back = voxlab.read(path)
    np.testing.assert_array_equal(back.array, arr)
    np.testing.assert_array_equal(back.affine, voxlab.read(path).affine)
    np.testing.assert_allclose(back.affine, affine, rtol=0, atol=1e-13)


def test_itk_2d_images_are_one_slice(tmp_path):
    arr = np.arange(12, dtype=np.uint16).reshape(3, 4)
    img = sitk.GetImageFromArray(arr)
    img.SetSpacing((0.5, 2.0))
    img.SetOrigin((1.0, -2.0))
    path = tmp_path / "slice.mha"
    sitk.WriteImage(img, str(path))
    vol = voxlab.read(path)
    assert vol.array.shape == (1, 3, 4)
    np.testing.assert_array_equal(vol.array[0], arr)
    np.testing.assert_allclose(vol.affine[:3, 3], [1.0, -2.0, 0.0])
    np.testing.assert_allclose(np.diag(vol.affine)[:2], [0.5, 2.0])


@pytest.mark.parametrize("ext,compress", [(".mha", False), (".mha", True), (".mhd", False)])
def test_itk_4d_images_read_one_frame_at_a_time(tmp_path, ext, compress):
    """A 4-D image ITK writes (a time series): frame k is ITK's array[k], with the
    spatial part of ITK's 4-D geometry; without a frame the file is refused."""
    rng = np.random.default_rng(5)
    arr = rng.integers(-3000, 3000, size=(3, 4, 5, 6)).astype(np.int16)  # (t, z, y, x)
    img = sitk.GetImageFromArray(arr, isVector=False)
    assert img.GetDimension() == 4
    img.SetSpacing(_SPACING + (2.5,))
    img.SetOrigin(_ORIGIN + (40.0,))
    d4 = np.eye(4)
    d4[:3, :3] = _ROT
    img.SetDirection(tuple(d4.flatten()))
    path = tmp_path / f"run{ext}"
    sitk.WriteImage(img, str(path), useCompression=compress)
    affine = np.eye(4)
    affine[:3, :3] = _ROT @ np.diag(_SPACING)
    affine[:3, 3] = _ORIGIN
    for k in range(3):
        vol = voxlab.read(path, frame=k)
        np.testing.assert_array_equal(vol.array, arr[k])
        np.testing.assert_allclose(vol.affine, affine, rtol=0, atol=1e-12)
    with pytest.raises(voxlab.VoxlabError, match="3 3-D volumes"):
        voxlab.read(path)
    with pytest.raises(voxlab.VoxlabError, match="past the file's 3"):
        voxlab.read(path, frame=3)


@pytest.mark.parametrize("ext", [".nrrd", ".mha"])
@pytest.mark.parametrize("compress", [False, True])
def test_itk_vector_images_read_one_component_at_a_time(tmp_path, ext, compress):
    """A vector image ITK writes (NRRD: kinds vector, a `none` direction; MetaImage:
    ElementNumberOfChannels; the components fastest): frame k is component k."""
    rng = np.random.default_rng(9)
    arr = rng.random((4, 5, 6, 3)).astype(np.float32)  # (z, y, x, component)
    img = sitk.GetImageFromArray(arr, isVector=True)
    img.SetSpacing(_SPACING)
    img.SetOrigin(_ORIGIN)
    img.SetDirection(tuple(_ROT.flatten()))
    path = tmp_path / f"vec{ext}"
    sitk.WriteImage(img, str(path), useCompression=compress)
    for k in range(3):
        vol = voxlab.read(path, frame=k)
        np.testing.assert_array_equal(vol.array, arr[..., k])
        np.testing.assert_allclose(vol.affine, _itk_affine(img), rtol=0, atol=1e-12)
    with pytest.raises(voxlab.VoxlabError, match="--frame"):
        voxlab.read(path)
