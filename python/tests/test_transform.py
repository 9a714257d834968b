"""voxlab.transform.iradon against scikit-image's iradon: random images and phantoms,
every filter, circle True/False, output sizes, odd sizes, dtypes, errors; the GPU."""

import warnings

import numpy as np
import pytest

import voxlab
import voxlab.transform as vt

skt = pytest.importorskip("skimage.transform")

FILTERS = ["ramp", "shepp-logan", "cosine", "hamming", "hann"]
# Both compute in float64 with the same filter and linear interpolation; they differ by
# rounding only: measured ≤ 8e-15 of the peak (docs/ct.md: 4.9e-15 on its fixtures).
TOL_F64 = 5e-14


def rel_max(a, b):
    return np.abs(a.astype(np.float64) - b.astype(np.float64)).max() / np.abs(b).max()


def random_image(n, circle, seed):
    img = np.random.default_rng(seed).random((n, n))
    if circle:  # radon(circle=True) wants zero outside the inscribed circle
        r, c = np.mgrid[:n, :n] - n // 2
        img[r * r + c * c > (n // 2) ** 2] = 0
    return img


@pytest.mark.parametrize("n", [31, 32, 47, 64])
@pytest.mark.parametrize("filter_name", FILTERS)
def test_circle_true_equals_skimage(n, filter_name):
    img = random_image(n, True, n)
    theta = np.linspace(0, 180, 37, endpoint=False)
    sino = skt.radon(img, theta, circle=True)
    want = skt.iradon(sino, theta, filter_name=filter_name, circle=True)
    got = vt.iradon(sino, theta, filter_name=filter_name, circle=True)
    assert got.shape == want.shape and got.dtype == want.dtype == np.float64
    assert rel_max(got, want) <= TOL_F64


@pytest.mark.parametrize("shape", [(33, 33), (47, 47), (33, 20), (12, 33)])
@pytest.mark.parametrize("filter_name", ["ramp", "hann"])
def test_circle_false_equals_skimage(shape, filter_name):
    # Sizes whose default output stays on the detector (see the next test otherwise);
    # rectangular images are padded to a square by radon.
    img = np.random.default_rng(shape[0]).random(shape)
    theta = np.sort(np.random.default_rng(1).uniform(0, 180, 29))
    sino = skt.radon(img, theta, circle=False)
    want = skt.iradon(sino, theta, filter_name=filter_name, circle=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error", voxlab.VoxlabWarning)  # no corner pixel differs here
        got = vt.iradon(sino, theta, filter_name=filter_name, circle=False)
    assert got.shape == want.shape
    assert rel_max(got, want) <= TOL_F64


def test_circle_false_corners_past_the_detector_warn_and_differ_only_there():
    n = 64
    img = random_image(n, False, 3)
    theta = np.linspace(0, 180, 50, endpoint=False)
    sino = skt.radon(img, theta, circle=False)  # 91 bins: the 64² output's corners reach 45.25
    want = skt.iradon(sino, theta, circle=False)
    with pytest.warns(voxlab.VoxlabWarning, match="past the detector"):
        got = vt.iradon(sino, theta, circle=False)
    r, c = np.mgrid[:n, :n] - n // 2
    inside = r * r + c * c <= (sino.shape[0] // 2) ** 2  # every ray on the detector
    assert rel_max(got[inside], want[inside]) <= TOL_F64


@pytest.mark.parametrize("output_size", [20, 40, 41, 57])
def test_output_size(output_size):
    img = random_image(40, True, 5)
    theta = np.arange(0, 180, 4.0)
    sino = skt.radon(img, theta)
    want = skt.iradon(sino, theta, output_size=output_size)
    with warnings.catch_warnings():
        warnings.simplefilter("error", voxlab.VoxlabWarning)
        got = vt.iradon(sino, theta, output_size=output_size)
    assert got.shape == (output_size, output_size)
    assert rel_max(got, want) <= TOL_F64


def test_an_output_larger_than_the_padded_detector_warns_and_differs_only_there():
    img = random_image(40, True, 5)
    theta = np.arange(0, 180, 4.0)
    sino = skt.radon(img, theta)  # padded to ceil(√2·40) = 57 bins: |s| ≤ 28 on the detector
    want = skt.iradon(sino, theta, output_size=63)
    with pytest.warns(voxlab.VoxlabWarning, match="past the detector"):
        got = vt.iradon(sino, theta, output_size=63)
    r, c = np.mgrid[:63, :63] - 31
    on = r * r + c * c <= 28 * 28
    assert rel_max(got[on], want[on]) <= TOL_F64


def test_default_theta_and_a_phantom_slice():
    v = voxlab.phantom("shepp-logan-modified", (64, 64, 1))
    img = v.array[0].astype(np.float64)
    sino = skt.radon(img, circle=True)  # theta = arange(180)
    want = skt.iradon(sino)
    got = vt.iradon(sino)
    assert rel_max(got, want) <= TOL_F64


@pytest.mark.parametrize("dtype", [np.float16, np.float32, np.uint8, np.int16, bool])
@pytest.mark.parametrize("preserve_range", [True, False])
def test_dtypes(dtype, preserve_range):
    rng = np.random.default_rng(9)
    theta = np.linspace(0, 180, 24, endpoint=False)
    sino = rng.random((33, 24)) * (50 if dtype in (np.uint8, np.int16) else 1)
    sino = sino.astype(dtype) if dtype is not bool else sino > 0.5
    want = skt.iradon(sino, theta, preserve_range=preserve_range)
    got = vt.iradon(sino, theta, preserve_range=preserve_range)
    assert got.dtype == want.dtype
    # float32 output: scikit-image accumulates in float32, voxlab in float64 then rounds.
    tol = TOL_F64 if want.dtype == np.float64 else 2e-6
    assert rel_max(got, want) <= tol


def test_errors_like_skimage():
    sino = np.ones((16, 8))
    for f in (skt.iradon, vt.iradon):
        with pytest.raises(ValueError, match="must be 2-D"):
            f(np.ones((4, 4, 4)))
        with pytest.raises(ValueError, match="does not match the number of projections"):
            f(sino, theta=np.arange(7))
        with pytest.raises(ValueError, match="Unknown interpolation"):
            f(sino, interpolation="spline")
        with pytest.raises(ValueError, match="Unknown filter"):
            f(sino, filter_name="parzen")


def test_what_is_not_covered_says_so():
    sino = np.ones((16, 8))
    for interp in ("nearest", "cubic"):
        with pytest.raises(voxlab.UnsupportedError, match="interpolation"):
            vt.iradon(sino, interpolation=interp)
    with pytest.raises(voxlab.UnsupportedError, match="filter_name=None"):
        vt.iradon(sino, filter_name=None)


def test_cpu_f32_backend():
    img = random_image(48, True, 11)
    theta = np.linspace(0, 180, 60, endpoint=False)
    sino = skt.radon(img, theta)
    want = skt.iradon(sino, theta)
    # docs/ct.md: --backend cpu-f32 equals iradon to 2.6e-6 relative.
    assert rel_max(vt.iradon(sino, theta, backend="cpu-f32"), want) <= 5e-6


def test_gpu_backend(gpu):
    img = random_image(48, True, 12)
    theta = np.linspace(0, 180, 60, endpoint=False)
    sino = skt.radon(img, theta)
    want = skt.iradon(sino, theta)
    # docs/ct.md: --backend gpu (lavapipe) equals iradon to 1.8e-6 relative.
    assert rel_max(vt.iradon(sino, theta, backend="gpu"), want) <= 5e-6


def test_progress_is_reported():
    img = random_image(64, True, 13)
    theta = np.linspace(0, 180, 90, endpoint=False)
    sino = skt.radon(img, theta)
    seen = []
    vt.iradon(sino, theta, progress=lambda stage, done, total: seen.append((stage, done, total)))
    assert seen and seen[-1][1] == seen[-1][2]
    assert all("reconstructing" in s for s, _, _ in seen)
