"""voxlab.fft against numpy.fft: random inputs of many shapes, axes, norms and lengths
(odd, even, prime, padded, truncated), dtypes and errors; the exact DFT; the GPU."""

import warnings

import numpy as np
import pytest

import voxlab
import voxlab.fft as vf

NORMS = [None, "backward", "ortho", "forward"]
RNG = np.random.default_rng(20261202)


def rand(shape, dtype=np.complex128):
    x = RNG.standard_normal(shape) + (1j * RNG.standard_normal(shape) if np.dtype(dtype).kind == "c" else 0)
    return x.astype(dtype)


def close(got, want, dtype=np.float64):
    """f64: both are FFTs of f64 data, within a few ulps of the norm (1e-12 relative
    to the largest value). f32/complex64: numpy computes in single precision, voxlab in
    double then rounds: 1e-5 relative to the largest value."""
    assert got.shape == want.shape, (got.shape, want.shape)
    assert got.dtype == want.dtype, (got.dtype, want.dtype)
    tol = 1e-12 if np.finfo(np.result_type(dtype, np.float32)).bits == 64 else 1e-5
    scale = max(np.abs(want).max(), 1e-300)
    err = np.abs(got.astype(np.complex128) - want.astype(np.complex128)).max() / scale
    assert err <= tol, f"max error {err:.3g} relative to the peak (tolerance {tol})"


SHAPES_1D = [(1,), (2,), (7,), (8,), (15,), (16,), (17,), (97,), (128,), (210,)]


@pytest.mark.parametrize("shape", SHAPES_1D + [(3, 10), (4, 5, 6)])
@pytest.mark.parametrize("norm", NORMS)
@pytest.mark.parametrize("name", ["fft", "ifft"])
def test_c2c_1d(shape, norm, name):
    x = rand(shape)
    for axis in range(-len(shape), len(shape)):
        for n in [None, 1, shape[axis] + 3, max(1, shape[axis] - 1), 2 * shape[axis]]:
            close(getattr(vf, name)(x, n=n, axis=axis, norm=norm),
                  getattr(np.fft, name)(x, n=n, axis=axis, norm=norm))


@pytest.mark.parametrize("shape", SHAPES_1D + [(6, 9), (3, 4, 5)])
@pytest.mark.parametrize("norm", NORMS)
def test_real_1d(shape, norm):
    x = rand(shape, np.float64)
    for axis in range(-len(shape), len(shape)):
        for n in [None, 1, 2, shape[axis] + 1, shape[axis] + 2, 2 * shape[axis] + 1]:
            close(vf.rfft(x, n=n, axis=axis, norm=norm), np.fft.rfft(x, n=n, axis=axis, norm=norm))
            close(vf.ihfft(x, n=n, axis=axis, norm=norm), np.fft.ihfft(x, n=n, axis=axis, norm=norm))
        z = rand(shape)
        for n in [None, 1, 2, 3, 2 * shape[axis] - 1, 2 * shape[axis], 2 * shape[axis] + 5]:
            if n is None and shape[axis] == 1:
                continue  # n = 0: the error case, tested below
            close(vf.irfft(z, n=n, axis=axis, norm=norm), np.fft.irfft(z, n=n, axis=axis, norm=norm))
            close(vf.hfft(z, n=n, axis=axis, norm=norm), np.fft.hfft(z, n=n, axis=axis, norm=norm))


ND_CASES = [
    ((8, 8), None, None), ((7, 9), None, None), ((5, 6, 7), None, None),
    ((5, 6, 7), None, (0, 2)), ((5, 6, 7), None, (2, 0)), ((4, 5, 6), (3, 8), (1, 2)),
    ((4, 5, 6), (6, 4, 9), (0, 1, 2)), ((3, 4, 5), None, (-1,)), ((3, 4, 5), (7,), (0,)),
    ((4, 6), None, (1, 1)), ((2, 3, 4, 5), None, (0, 3)), ((6, 10), (-1, 7), (0, 1)),
]


@pytest.mark.parametrize("shape,s,axes", ND_CASES)
@pytest.mark.parametrize("norm", NORMS)
def test_nd(shape, s, axes, norm):
    x = rand(shape)
    r = rand(shape, np.float64)
    close(vf.fftn(x, s=s, axes=axes, norm=norm), np.fft.fftn(x, s=s, axes=axes, norm=norm))
    close(vf.ifftn(x, s=s, axes=axes, norm=norm), np.fft.ifftn(x, s=s, axes=axes, norm=norm))
    close(vf.rfftn(r, s=s, axes=axes, norm=norm), np.fft.rfftn(r, s=s, axes=axes, norm=norm))
    spec = np.fft.rfftn(r, s=s, axes=axes)
    close(vf.irfftn(spec, s=s, axes=axes, norm=norm), np.fft.irfftn(spec, s=s, axes=axes, norm=norm))
    if len(shape) >= 2 and (axes is None or len(axes) == 2):
        kw = {} if axes is None else {"axes": axes}
        close(vf.fft2(x, s=s, norm=norm, **kw), np.fft.fft2(x, s=s, norm=norm, **kw))
        close(vf.ifft2(x, s=s, norm=norm, **kw), np.fft.ifft2(x, s=s, norm=norm, **kw))
        close(vf.rfft2(r, s=s, norm=norm, **kw), np.fft.rfft2(r, s=s, norm=norm, **kw))
        close(vf.irfft2(spec, s=s, norm=norm, **kw), np.fft.irfft2(spec, s=s, norm=norm, **kw))


def test_nd_defaults_and_deprecations_like_numpy():
    x = rand((4, 6, 5))
    close(vf.fftn(x), np.fft.fftn(x))
    close(vf.fft2(x), np.fft.fft2(x))
    with pytest.warns(DeprecationWarning):
        got = vf.fftn(x, s=(3, 4))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        close(got, np.fft.fftn(x, s=(3, 4)))


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.complex64, np.complex128,
                                   np.int16, np.int64, np.uint8, bool, np.float16])
def test_dtype_promotion_is_numpy_2s(dtype):
    x = (RNG.standard_normal(24) * 10).astype(dtype) if dtype is not bool else RNG.random(24) > 0.5
    for f in ["fft", "ifft"]:
        close(getattr(vf, f)(x), getattr(np.fft, f)(x), dtype)
    if np.dtype(dtype).kind != "c":
        close(vf.rfft(x), np.fft.rfft(x), dtype)
        close(vf.ihfft(x), np.fft.ihfft(x), dtype)
    spec = np.fft.rfft(np.real(x).astype(np.float64)).astype(np.result_type(np.real(x).dtype, 1j))
    close(vf.irfft(spec), np.fft.irfft(spec), dtype)
    close(vf.hfft(spec), np.fft.hfft(spec), dtype)


def test_out_like_numpy():
    x = rand((4, 8))
    out = np.empty((4, 8), np.complex128)
    r = vf.fft(x, out=out)
    assert r is out
    close(out, np.fft.fft(x))
    out2 = np.empty((4, 8), np.complex128)
    r = vf.fftn(x, out=out2)
    assert r is out2
    close(out2, np.fft.fftn(x))
    with pytest.raises(ValueError, match="output array has wrong shape"):
        vf.fft(x, out=np.empty((4, 7), np.complex128))
    with pytest.raises(TypeError):
        vf.fft(x, out=np.empty((4, 8), np.float64))


def test_errors_like_numpy():
    x = rand((4, 5))
    for f in (vf.fft, np.fft.fft):
        with pytest.raises(ValueError, match=r"Invalid number of FFT data points \(0\)"):
            f(x, n=0)
        with pytest.raises(ValueError, match="Invalid norm value"):
            f(x, norm="unitary")
        with pytest.raises(IndexError):  # numpy reads a.shape[axis] first
            f(x, axis=2)
        with pytest.raises(np.exceptions.AxisError):
            f(x, n=4, axis=2)
    for f in (vf.irfft, np.fft.irfft):
        with pytest.raises(ValueError, match="Invalid number of FFT data points"):
            f(np.ones(1, complex))
    for f in (vf.fftn, np.fft.fftn):
        with pytest.raises(ValueError, match="Shape and axes have different lengths"):
            f(x, s=(2, 3), axes=(0,))
    with pytest.raises(TypeError):
        vf.rfft(x)


def test_shifts_and_frequencies_are_numpys():
    assert vf.fftshift is np.fft.fftshift and vf.ifftshift is np.fft.ifftshift
    assert vf.fftfreq is np.fft.fftfreq and vf.rfftfreq is np.fft.rfftfreq


@pytest.mark.parametrize("shape,axes", [((12,), None), ((5, 7), None), ((4, 5, 6), (0, 2)), ((9, 4), (1,))])
@pytest.mark.parametrize("norm", NORMS)
def test_exact_dft(shape, axes, norm):
    x = rand(shape)
    close(vf.dft(x, axes=axes, norm=norm), np.fft.fftn(x, axes=axes, norm=norm))
    close(vf.dft(x, axes=axes, norm=norm, inverse=True), np.fft.ifftn(x, axes=axes, norm=norm))
    # The DFT of a single frequency is exactly one bin (analytic).
    n = 16
    k = 3
    t = np.arange(n)
    d = vf.dft(np.exp(2j * np.pi * k * t / n))
    want = np.zeros(n, complex)
    want[k] = n
    assert np.abs(d - want).max() < 1e-12


def test_gpu_backend_refuses_what_it_cannot_do():
    with pytest.raises(voxlab.UnsupportedError, match="every axis"):
        vf.fftn(rand((8, 8)), axes=(1,), backend="gpu")
    with pytest.raises(ValueError, match="backend"):
        vf.fft(rand(8), backend="cuda")


@pytest.mark.parametrize("shape", [(256,), (32, 64), (8, 16, 32), (100,), (6, 8), (12, 20, 7)])
@pytest.mark.parametrize("norm", NORMS)
def test_gpu_against_numpy(gpu, shape, norm):
    # Lengths that are not powers of two run Bluestein's algorithm on the GPU.
    x = rand(shape)
    # docs/fft.md: the GPU's f32 FFT is within 1e-6·log2 N relative L2 of the exact DFT.
    tol = 1e-6 * np.log2(np.prod(shape))
    for f in ("fftn", "ifftn"):
        got = getattr(vf, f)(x, norm=norm, backend="gpu")
        want = getattr(np.fft, f)(x, norm=norm)
        assert got.dtype == np.complex64 and got.shape == want.shape
        rel = np.linalg.norm(got - want) / np.linalg.norm(want)
        assert rel <= tol, (f, rel, tol)
    if len(shape) == 1:
        got = vf.fft(x, norm=norm, backend="gpu")
        assert np.linalg.norm(got - np.fft.fft(x, norm=norm)) / np.linalg.norm(np.fft.fft(x)) <= tol * (1 if norm in (None, "backward") else 10)
