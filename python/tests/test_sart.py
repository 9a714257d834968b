"""voxlab.transform.iradon_sart against scikit-image's iradon_sart: the golden-ratio
view order, random and phantom sinograms, float64 and float32, odd and even sizes,
several iterations, projection shifts, clip, relaxation, dtype rules, warnings and
errors; the float32 backends and the GPU."""

import warnings

import numpy as np
import pytest

import voxlab
import voxlab.transform as vt

skt = pytest.importorskip("skimage.transform")

# The library repeats scikit-image's arithmetic step for step (the compiled code's mix
# of double and dtype products), so float64 and float32 images are equal bit for bit:
# the rays' updates are written band by band in parallel, each pixel's in the rays'
# order, as scikit-image's one loop writes them.


def disc_sinogram(n, angles, seed, dtype=np.float64):
    img = np.random.default_rng(seed).random((n, n))
    r, c = np.mgrid[:n, :n] - n // 2
    img[r * r + c * c > (n // 2) ** 2] = 0
    theta = np.linspace(0, 180, angles, endpoint=False)
    return skt.radon(img, theta).astype(dtype), theta


@pytest.mark.parametrize("theta", [np.arange(180.0), np.linspace(0, 180, 37, endpoint=False),
                                   np.sort(np.random.default_rng(3).uniform(-90, 270, 50)),
                                   np.arange(30.0, dtype=np.float32) * 6])
def test_the_view_order_is_skimages(theta):
    assert list(vt.order_angles_golden_ratio(theta)) == list(
        skt.order_angles_golden_ratio(theta))


@pytest.mark.parametrize("n", [32, 33, 48])
def test_one_iteration_equals_skimage_bit_for_bit(n):
    sino, theta = disc_sinogram(n, 29, n)
    want = skt.iradon_sart(sino, theta)
    got = vt.iradon_sart(sino, theta)
    assert got.dtype == want.dtype == np.float64 and got.shape == want.shape
    np.testing.assert_array_equal(got, want)


def test_iterations_shifts_clip_and_relaxation_equal_skimage():
    sino, theta = disc_sinogram(40, 24, 7)
    shifts = np.random.default_rng(1).uniform(-1.5, 1.5, len(theta))
    want = got = None
    for _ in range(3):
        want = skt.iradon_sart(sino, theta, image=want, projection_shifts=shifts,
                               clip=(0.0, 0.9), relaxation=0.3)
        got = vt.iradon_sart(sino, theta, image=got, projection_shifts=shifts,
                             clip=(0.0, 0.9), relaxation=0.3)
        np.testing.assert_array_equal(got, want)


def test_float32_equals_skimage_bit_for_bit():
    sino, theta = disc_sinogram(36, 30, 11, np.float32)
    want = skt.iradon_sart(sino, theta)
    got = vt.iradon_sart(sino, theta)
    assert got.dtype == want.dtype == np.float32
    np.testing.assert_array_equal(got, want)
    want2 = skt.iradon_sart(sino, theta, image=want, clip=(0, 1))
    got2 = vt.iradon_sart(sino, theta, image=got, clip=(0, 1))
    np.testing.assert_array_equal(got2, want2)


def test_the_shepp_logan_phantom_at_default_angles():
    img = skt.rescale(voxlab.phantom("shepp-logan-modified", (64, 64, 1)).array[0]
                      .astype(np.float64), 1.0)
    sino = skt.radon(img)
    np.testing.assert_array_equal(vt.iradon_sart(sino), skt.iradon_sart(sino))


def test_dtypes_warnings_and_errors_are_skimages():
    sino, theta = disc_sinogram(20, 8, 2)
    ints = (sino * 10).astype(np.int16)
    for f in (skt.iradon_sart, vt.iradon_sart):
        with pytest.warns(UserWarning, match="Only floating point data type"):
            out = f(ints, theta)
        assert out.dtype == np.float64
        with pytest.raises(ValueError, match="two dimensional"):
            f(np.ones((4, 4, 4)))
        with pytest.raises(ValueError, match="does not match the number of projections"):
            f(sino, theta[:5])
        with pytest.raises(ValueError, match="Only floating point"):
            f(sino, theta, dtype=np.int32)
        with pytest.raises(ValueError, match="does not match first dimension"):
            f(sino, theta, image=np.zeros((5, 5)))
        with pytest.raises(ValueError, match="length-2"):
            f(sino, theta, clip=(0, 1, 2))
        with pytest.warns(UserWarning, match="image is cast"):
            f(sino, theta, image=np.zeros((20, 20), np.float32))
    np.testing.assert_array_equal(vt.iradon_sart(sino, theta, dtype=np.float32),
                                  skt.iradon_sart(sino, theta, dtype=np.float32))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        vt.iradon_sart(sino, theta)


# float32 throughout (cpu-f32, the GPU) against scikit-image's float64: each view's
# deviation divides by Σw², so float32 rounding grows over an iteration (measured
# ≤ 8.8e-5 of the peak over 32²…64², 20…90 views, shifts, clip). The GPU against the
# CPU's float32: the same steps, a pixel's sums in three phases instead of the rays'
# order, and its weights in float32 (measured ≤ 4.0e-7).
TOL_F32 = 2e-4
TOL_GPU_F32 = 2e-6


def rel_max(a, b):
    return np.abs(a.astype(np.float64) - b.astype(np.float64)).max() / np.abs(b).max()


def test_cpu_f32_backend():
    sino, theta = disc_sinogram(48, 40, 5)
    want = skt.iradon_sart(sino, theta)
    got = vt.iradon_sart(sino, theta, backend="cpu-f32")
    assert got.dtype == np.float64
    assert rel_max(got, want) <= TOL_F32
    np.testing.assert_array_equal(
        got, vt.iradon_sart(sino.astype(np.float32), theta).astype(np.float64))


def test_gpu_backend(gpu):
    sino, theta = disc_sinogram(48, 40, 6)
    shifts = np.random.default_rng(2).uniform(-1, 1, len(theta))
    want = skt.iradon_sart(sino, theta, projection_shifts=shifts, clip=(0, 5))
    got = vt.iradon_sart(sino, theta, projection_shifts=shifts, clip=(0, 5), backend="gpu")
    assert rel_max(got, want) <= TOL_F32
    f32 = vt.iradon_sart(sino, theta, projection_shifts=shifts, clip=(0, 5),
                         backend="cpu-f32")
    assert rel_max(got, f32) <= TOL_GPU_F32


def test_progress_counts_the_views():
    sino, theta = disc_sinogram(24, 12, 3)
    seen = []
    vt.iradon_sart(sino, theta, progress=lambda stage, done, total: seen.append((done, total)))
    assert seen and seen[-1] == (12, 12)
