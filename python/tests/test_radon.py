"""voxlab.transform.radon against scikit-image's radon, on scikit-image's conventions:
phantoms and random images, odd, even and rectangular sizes, circle True and False,
every input dtype, the warning and the errors. The library repeats skimage's
arithmetic step for step (bilinear warp, then the column sums), so the float64 and
float32 sinograms are equal, not close; the GPU (float32, no f64 blend) agrees to its
summation bound."""

import warnings

import numpy as np
import pytest

import voxlab
import voxlab.transform as vt

skt = pytest.importorskip("skimage.transform")
skd = pytest.importorskip("skimage.data")


def assert_float32_sums_agree(got, want):
    """The GPU blends the two interpolated rows in float32 where scikit-image (and the
    CPU) blend in float64, so each bin is only as exact as a float32 sum of its n
    terms: |Δ| ≤ n·2⁻²⁴·Σ|terms| ≤ n·2⁻²⁴·max|bin| for these non-negative images."""
    n = want.shape[0]
    np.testing.assert_allclose(got, want, rtol=0, atol=n * 2.0 ** -24 * np.abs(want).max())


def disc_image(shape, seed):
    """Random values inside the inscribed circle, zero outside (radon's circle rule)."""
    rng = np.random.default_rng(seed)
    img = rng.random(shape)
    r = min(shape) // 2
    i, j = np.ogrid[: shape[0], : shape[1]]
    img[(i - shape[0] // 2) ** 2 + (j - shape[1] // 2) ** 2 > r * r] = 0
    return img


@pytest.mark.parametrize("shape", [(32, 32), (33, 33), (24, 31), (31, 20)])
@pytest.mark.parametrize("circle", [True, False])
def test_random_images_equal_skimage(shape, circle):
    img = disc_image(shape, sum(shape)) if circle else np.random.default_rng(5).random(shape)
    theta = np.linspace(0, 180, 37, endpoint=False)
    want = skt.radon(img, theta, circle=circle)
    got = vt.radon(img, theta, circle=circle)
    assert got.dtype == want.dtype == np.float64 and got.shape == want.shape
    np.testing.assert_array_equal(got, want)


def test_the_shepp_logan_phantom_equals_skimage():
    img = skt.rescale(skd.shepp_logan_phantom(), 0.25, mode="reflect", channel_axis=None)
    for circle in (True, False):
        want = skt.radon(img, circle=circle)  # theta=None: np.arange(180)
        np.testing.assert_array_equal(vt.radon(img, circle=circle), want)


def test_any_angles_equal_skimage():
    img = disc_image((21, 21), 9)
    theta = np.random.default_rng(1).uniform(-400, 400, 23)
    np.testing.assert_array_equal(vt.radon(img, theta), skt.radon(img, theta))
    theta32 = theta.astype(np.float32)
    np.testing.assert_array_equal(vt.radon(img, theta32), skt.radon(img, theta32))


@pytest.mark.parametrize("dtype", [np.float32, np.float16, np.uint8, np.uint16, np.int16,
                                   np.int32, bool])
@pytest.mark.parametrize("preserve_range", [False, True])
def test_dtypes_are_handled_as_skimage(dtype, preserve_range):
    img = disc_image((26, 26), 4)
    if dtype is bool:
        a = img > 0.5
    elif np.issubdtype(dtype, np.integer):
        a = (img * (np.iinfo(dtype).max // 2)).astype(dtype)
    else:
        a = img.astype(dtype)
    theta = np.arange(0, 180, 7.5)
    want = skt.radon(a, theta, preserve_range=preserve_range)
    got = vt.radon(a, theta, preserve_range=preserve_range)
    assert got.dtype == want.dtype
    np.testing.assert_array_equal(got, want)


def test_negative_integers_are_scaled_as_skimage():
    a = (np.random.default_rng(2).standard_normal((15, 15)) * 8000).astype(np.int16)
    a[disc_image((15, 15), 0) == 0] = 0
    np.testing.assert_array_equal(vt.radon(a, np.arange(12)), skt.radon(a, np.arange(12)))


def test_the_outside_circle_warning_is_skimages():
    img = np.ones((12, 12))
    with pytest.warns(UserWarning, match="image must be zero outside the reconstruction circle"):
        want = skt.radon(img, np.arange(5))
    with pytest.warns(UserWarning, match="image must be zero outside the reconstruction circle"):
        got = vt.radon(img, np.arange(5))
    np.testing.assert_array_equal(got, want)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        vt.radon(img, np.arange(5), circle=False)
        vt.radon(disc_image((12, 12), 1), np.arange(5))


def test_errors_are_skimages_and_the_librarys():
    for f in (skt.radon, vt.radon):
        with pytest.raises(ValueError, match="must be 2-D"):
            f(np.ones((4, 4, 4)))
    with pytest.raises(voxlab.InvalidError, match="backend"):
        vt.radon(np.zeros((8, 8)), backend="tpu")


def test_analytic_truths():
    # A unit pixel at the rotation centre: 1 in bin n // 2 at every angle.
    for n in (9, 10):
        img = np.zeros((n, n))
        img[n // 2, n // 2] = 1.0
        s = vt.radon(img, np.arange(0, 360, 90))  # quarter turns: onto the grid
        np.testing.assert_allclose(s[n // 2], 1.0, rtol=0, atol=1e-12)
        np.testing.assert_allclose(s.sum(axis=0), 1.0, rtol=0, atol=1e-12)
    # Angle 0 sums the columns exactly.
    img = disc_image((17, 17), 3)
    np.testing.assert_array_equal(vt.radon(img, [0.0])[:, 0], img.sum(axis=0))


def test_cpu_f32_backend_is_skimage_on_float32():
    img = disc_image((30, 30), 8)
    theta = np.arange(0, 180, 4.0)
    got = vt.radon(img, theta, backend="cpu-f32")
    want = skt.radon(img.astype(np.float32), theta)
    assert got.dtype == want.dtype == np.float32
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("circle", [True, False])
def test_gpu_backend_is_skimage_to_the_float32_sum_bound(gpu, circle):
    img = disc_image((30, 30), 9) if circle else np.random.default_rng(9).random((27, 30))
    theta = np.sort(np.random.default_rng(10).uniform(-90, 270, 45))
    got = vt.radon(img.astype(np.float32), theta, circle=circle, backend="gpu")
    want = skt.radon(img.astype(np.float32), theta, circle=circle)
    assert got.dtype == want.dtype == np.float32
    assert_float32_sums_agree(got, want)
    # A float64 image keeps its dtype; the values are the GPU's float32 ones.
    got64 = vt.radon(img, theta, circle=circle, backend="gpu")
    assert got64.dtype == np.float64
    np.testing.assert_array_equal(got64, got.astype(np.float64))
