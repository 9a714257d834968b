"""voxlab.transform.iradon against scikit-image's iradon: random images and phantoms,
every filter, circle True/False, output sizes, odd sizes, dtypes, errors; the GPU."""

import numpy as np
import pytest

import voxlab
import voxlab.transform as vt

skt = pytest.importorskip("skimage.transform")

FILTERS = ["ramp", "shepp-logan", "cosine", "hamming", "hann"]
# Both compute in float64 with the same filter and linear interpolation; they differ by
# rounding only: measured ≤ 8e-15 of the peak (docs/ct.md: 4.9e-15 on its fixtures).
TOL_F64 = 5e-14
# A float32 sinogram: scikit-image filters it with a float32 FFT, voxlab in float64;
# both then sum in float32 the same way.
TOL_F32 = 2e-6
# float32 throughout (cpu-f32 and the GPU): t, the filter and the sum in float32,
# against scikit-image's float64 result (measured ≤ 1.3e-6 over every interpolation and
# filter, 31² … 64², random angles and angles every 15°; docs/python.md).
TOL_F32_PATH = 5e-6


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
    got = vt.iradon(sino, theta, filter_name=filter_name, circle=False)
    assert got.shape == want.shape
    assert rel_max(got, want) <= TOL_F64


def test_circle_false_corners_past_the_detector_equal_skimage():
    # 91 bins: the 64² output's corners reach |t| = 45.25, past the last bin centre
    # (45): there scikit-image's np.interp(left=0, right=0) gives 0, and so does voxlab.
    n = 64
    img = random_image(n, False, 3)
    theta = np.linspace(0, 180, 50, endpoint=False)
    sino = skt.radon(img, theta, circle=False)
    want = skt.iradon(sino, theta, circle=False)
    got = vt.iradon(sino, theta, circle=False)
    assert rel_max(got, want) <= TOL_F64
    r, c = np.mgrid[:n, :n] - n // 2
    assert np.abs(want[r * r + c * c > 45 * 45]).max() > 0  # the corners are not all 0


@pytest.mark.parametrize("output_size", [20, 40, 41, 57])
def test_output_size(output_size):
    img = random_image(40, True, 5)
    theta = np.arange(0, 180, 4.0)
    sino = skt.radon(img, theta)
    want = skt.iradon(sino, theta, output_size=output_size)
    got = vt.iradon(sino, theta, output_size=output_size)
    assert got.shape == (output_size, output_size)
    assert rel_max(got, want) <= TOL_F64


def test_an_output_larger_than_the_padded_detector_equals_skimage():
    img = random_image(40, True, 5)
    theta = np.arange(0, 180, 4.0)
    sino = skt.radon(img, theta)  # padded to ceil(√2·40) = 57 bins: |t| ≤ 28 on the detector
    want = skt.iradon(sino, theta, output_size=63)
    got = vt.iradon(sino, theta, output_size=63)
    assert rel_max(got, want) <= TOL_F64


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
    # float32 output: both sum in float32 as scikit-image does; scikit-image's FFT of a
    # float32 sinogram runs in float32 (voxlab's in float64), which bounds the gap.
    tol = TOL_F64 if want.dtype == np.float64 else TOL_F32
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


# Where the arithmetic is numpy's (linear, nearest) the results differ only by the FFT's
# rounding (rustfft against pocketfft), as for the linear default; the cubic spline is
# solved differently from scipy's banded solver and differs by its rounding too.
TOL_CUBIC = 5e-14


@pytest.mark.parametrize("interpolation", ["nearest", "cubic"])
@pytest.mark.parametrize("circle", [True, False])
@pytest.mark.parametrize("n", [32, 33])
def test_every_interpolation_equals_skimage(interpolation, circle, n):
    img = random_image(n, circle, 20 + n)
    theta = np.sort(np.random.default_rng(n).uniform(0, 180, 41))
    sino = skt.radon(img, theta, circle=circle)
    want = skt.iradon(sino, theta, interpolation=interpolation, circle=circle)
    got = vt.iradon(sino, theta, interpolation=interpolation, circle=circle)
    assert got.shape == want.shape and got.dtype == want.dtype
    assert rel_max(got, want) <= (TOL_CUBIC if interpolation == "cubic" else TOL_F64)


def test_nearest_ties_fall_as_skimages():
    # At 30°, 60°, 120° … t = y·cos θ − x·sin θ lands on (or a rounding away from) a
    # midpoint between two bins for many pixels; which neighbour is taken depends on
    # numpy's t to the last bit. A wrong choice costs a whole bin step.
    img = random_image(40, True, 7)
    theta = np.arange(0.0, 180.0, 15.0)
    sino = skt.radon(img, theta)
    want = skt.iradon(sino, theta, interpolation="nearest")
    got = vt.iradon(sino, theta, interpolation="nearest")
    assert rel_max(got, want) <= TOL_F64
    # float32 rounds cos 60° to 0.5 and t onto the midpoint; the rounding's remainder
    # (cpu::radon::Angle) still takes numpy's side.
    f32 = vt.iradon(sino, theta, interpolation="nearest", backend="cpu-f32")
    assert rel_max(f32, want) <= TOL_F32_PATH


@pytest.mark.parametrize("interpolation", ["linear", "nearest", "cubic"])
def test_unfiltered_backprojection_equals_skimage(interpolation):
    img = random_image(33, True, 8)
    theta = np.linspace(0, 180, 30, endpoint=False)
    sino = skt.radon(img, theta)
    want = skt.iradon(sino, theta, filter_name=None, interpolation=interpolation)
    got = vt.iradon(sino, theta, filter_name=None, interpolation=interpolation)
    assert rel_max(got, want) <= TOL_CUBIC


def test_unfiltered_backprojection_of_one_view_is_the_smeared_view():
    # One angle (0°): every column of the image is the view's bin at that column,
    # times π/2 (scikit-image's π/(2A)); exact, since no filter touches the values.
    n = 17
    sino = np.random.default_rng(4).random((n, 1))
    got = vt.iradon(sino, [0.0], filter_name=None, circle=False, output_size=n)
    np.testing.assert_array_equal(got, np.tile(sino[:, 0], (n, 1)) * np.pi / 2)


def test_cubic_needs_four_bins():
    with pytest.raises(ValueError):
        skt.iradon(np.ones((3, 2)), [0.0, 90.0], interpolation="cubic", circle=False)
    with pytest.raises(ValueError, match="at least 4 detector bins"):
        vt.iradon(np.ones((3, 2)), [0.0, 90.0], interpolation="cubic", circle=False)


@pytest.mark.parametrize("interpolation", ["linear", "nearest", "cubic"])
def test_cpu_f32_backend(interpolation):
    img = random_image(48, True, 11)
    theta = np.sort(np.random.default_rng(11).uniform(0, 180, 60))
    sino = skt.radon(img, theta)
    want = skt.iradon(sino, theta, interpolation=interpolation)
    got = vt.iradon(sino, theta, interpolation=interpolation, backend="cpu-f32")
    assert rel_max(got, want) <= TOL_F32_PATH


@pytest.mark.parametrize("interpolation", ["linear", "nearest", "cubic"])
@pytest.mark.parametrize("filter_name", ["ramp", "hann", None])
@pytest.mark.parametrize("angles", ["random", "every 15"])
def test_gpu_backend_is_the_cpu_f32_path(gpu, interpolation, filter_name, angles):
    img = random_image(48, True, 12)
    if angles == "random":
        theta = np.sort(np.random.default_rng(12).uniform(0, 180, 60))
    else:
        theta = np.arange(0.0, 180.0, 15.0)
    sino = skt.radon(img, theta)
    want = skt.iradon(sino, theta, interpolation=interpolation, filter_name=filter_name)
    f32 = vt.iradon(sino, theta, interpolation=interpolation, filter_name=filter_name,
                    backend="cpu-f32")
    got = vt.iradon(sino, theta, interpolation=interpolation, filter_name=filter_name,
                    backend="gpu")
    assert rel_max(got, want) <= TOL_F32_PATH
    # The same float32 arithmetic; only the ramp filters' FFTs round differently.
    assert rel_max(got, f32) <= TOL_F32_PATH


def test_progress_is_reported():
    img = random_image(64, True, 13)
    theta = np.linspace(0, 180, 90, endpoint=False)
    sino = skt.radon(img, theta)
    seen = []
    vt.iradon(sino, theta, progress=lambda stage, done, total: seen.append((stage, done, total)))
    assert seen and seen[-1][1] == seen[-1][2]
    assert all("iradon" in s for s, _, _ in seen)
