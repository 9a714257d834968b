"""The fvr, d2vr, adaptive, process and bench jobs from Python: equal to the command
line's files for the same arguments, and to analytic truths and scipy.ndimage on
scipy's own conventions."""

import json

import numpy as np
import pytest

import voxlab
import voxlab.ndimage as vnd

ndi = pytest.importorskip("scipy.ndimage")


# --- FVR -----------------------------------------------------------------------------

def test_fvr_equals_the_command_line(tmp_path, cli):
    out = tmp_path / "f.npy"
    cli("fvr", "phantom:sphere:24", "--kernel", "trilinear", "--padding", "2",
        "--azimuth", "30", "--elevation", "10", "--out", out)
    got = voxlab.fvr("phantom:sphere:24", kernel="trilinear", padding=2, azimuth=30,
                     elevation=10)
    want = np.load(out)
    assert got.dtype == np.float32 and got.shape == want.shape
    np.testing.assert_array_equal(got, want)


def test_fvr_of_an_array_equals_the_command_line_on_its_file(tmp_path, cli):
    v = voxlab.phantom("spheres", 20)
    path = tmp_path / "v.nrrd"
    voxlab.write(path, v)
    out = tmp_path / "f.npy"
    cli("fvr", path, "--kernel", "lanczos3", "--padding", "1", "--view", "+x", "--out", out)
    got = voxlab.fvr(v, kernel="lanczos3", padding=1, view="+x")
    np.testing.assert_array_equal(got, np.load(out))


@pytest.mark.parametrize("kernel", ["nearest", "dirichlet"])
@pytest.mark.parametrize("padding", [1, 2])
def test_fvr_along_an_axis_is_the_sum_along_it(kernel, padding):
    # Projection-slice theorem: the spectrum's central slice perpendicular to z holds
    # grid frequencies exactly (no kernel interpolation with nearest or the exact
    # Dirichlet kernel), so its inverse 2-D FFT is the sum along z times the spacing
    # (value × mm): f64 throughout, rounded once to the float32 image.
    a = np.random.default_rng(1).random((16, 16, 16)).astype(np.float32)
    img = voxlab.fvr(a, kernel=kernel, padding=padding, view="+z", spacing=2.0)
    want = a.astype(np.float64).sum(axis=0) * 2.0
    np.testing.assert_allclose(img, want, rtol=2.0 ** -24, atol=1e-12)


def test_fvr_bad_options_are_the_jobs_errors():
    with pytest.raises(voxlab.InvalidError, match="kernl"):
        voxlab.fvr("phantom:sphere:8", kernl="nearest")
    with pytest.raises(voxlab.InvalidError):
        voxlab.fvr("phantom:sphere:8", kernel="bicubic")


# --- D²VR ----------------------------------------------------------------------------

def test_d2vr_equals_the_command_line(tmp_path, cli):
    out = tmp_path / "d.npy"
    args = ["--angles", "16", "--detector", "16", "--grid", "16", "--size", "24"]
    cli("d2vr", "phantom:shepp-logan-modified", *args, "--out", out)
    r = voxlab.d2vr("phantom:shepp-logan-modified", angles=16, detector=16, grid=16, size=24)
    want = np.load(out)
    assert r.image.shape == want.shape == (24, 24, 4)
    np.testing.assert_array_equal(r.image, want)
    s = r.stats
    assert 0 < s["value_reconstructions"] <= s["box_samples"]
    assert s["fraction"] == s["value_reconstructions"] / s["box_samples"]


def test_d2vr_of_projections_in_memory_equals_the_command_line_on_their_file(tmp_path, cli):
    p = voxlab.ct.project("phantom:shepp-logan-modified", beam="cone", angles=16, cols=16,
                          rows=16)
    np.save(tmp_path / "p.npy", p.projections)
    (tmp_path / "p.json").write_text(json.dumps(p.geometry))
    out = tmp_path / "d.npy"
    args = ["--grid", "16", "--size", "24"]
    cli("d2vr", tmp_path / "p.npy", "--geometry", tmp_path / "p.json", *args, "--out", out)
    want = np.load(out)
    r = voxlab.d2vr(p, grid=16, size=24)  # a Projected carries its geometry
    np.testing.assert_array_equal(r.image, want)
    r = voxlab.d2vr(p.projections, geometry=p.geometry, grid=16, size=24, backend="cpu")
    cli("d2vr", tmp_path / "p.npy", "--geometry", tmp_path / "p.json", *args,
        "--backend", "cpu", "--out", out)
    np.testing.assert_array_equal(r.image, np.load(out))
    with pytest.raises(voxlab.InvalidError, match="geometry"):
        voxlab.d2vr(p.projections, grid=16)
    with pytest.raises(voxlab.InvalidError, match="projection stack|projections"):
        voxlab.d2vr(p.projections[:, :, :15], geometry=p.geometry, grid=16)


def test_hardware_filtered_d2vr_equals_the_command_line(tmp_path, cli, gpu):
    # A parallel beam (distance weight 1) and no ramp filter, so that the values the
    # texture unit interpolates are the projections over the detector spacing, and the
    # bound can be computed here from the array alone.
    du = 256 / 24
    p = voxlab.ct.project("phantom:shepp-logan-modified", beam="parallel", angles=16,
                          cols=24, rows=24, du=du)
    np.save(tmp_path / "p.npy", p.projections)
    (tmp_path / "p.json").write_text(json.dumps(p.geometry))
    # f16 textures filter on every adapter (f32 ones need FLOAT32_FILTERABLE).
    scene = dict(filter="none", mode="mip", grid=24, size=32, backend="gpu",
                 f16_projections=True)
    out = tmp_path / "d.npy"
    cli("d2vr", tmp_path / "p.npy", "--geometry", tmp_path / "p.json", "--filter", "none",
        "--mode", "mip", "--grid", "24", "--size", "32", "--backend", "gpu-f16",
        "--hardware-filtering", "--out", out)
    got = voxlab.d2vr(p, hardware_filtering=True, **scene)
    np.testing.assert_array_equal(got.image, np.load(out))
    exact = voxlab.d2vr(p, **scene)
    # Each of a bilinear filter's two weights off by at most 2^-8 on real GPUs moves a
    # view's value by at most 2 * D_k / 256 (D_k: the largest spread of a 2x2 cell of
    # view k, zero border included), and a half-precision result by 2^-11 of the
    # view's largest value M_k; a sample, and so a MIP pixel, by at most pi / (2 A)
    # times their sum.
    q = np.pad(np.asarray(p.projections, dtype=np.float64) / du, ((0, 0), (1, 1), (1, 1)))
    cells = [q[:, i:q.shape[1] - 1 + i, j:q.shape[2] - 1 + j] for i in (0, 1) for j in (0, 1)]
    spread = (np.max(cells, axis=0) - np.min(cells, axis=0)).max(axis=(1, 2))
    top = np.abs(q).max(axis=(1, 2))
    peak = np.abs(exact.image).max()
    bound = np.pi / (2 * len(spread)) * (2 * spread / 256 + top * 2.0**-11).sum() + 1e-5 * peak
    assert peak > 0.5
    assert np.abs(got.image - exact.image).max() <= bound
    with pytest.raises(voxlab.InvalidError, match="hardware-filtering.*backend gpu"):
        voxlab.d2vr(p, hardware_filtering=True, grid=24, size=32)


# --- Spectral adaptive sampling -------------------------------------------------------

def test_adaptive_report_equals_the_command_lines_table(tmp_path, cli):
    args = ["--size", "24", "--runs", "1"]
    cli("adaptive", "phantom:marschner-lobb:24", *args, "--out", tmp_path)
    want = json.load(open(tmp_path / "table.json"))
    r = voxlab.adaptive("phantom:marschner-lobb:24", size=24, runs=1)
    rep = r.report
    assert [row["sampling"] for row in rep["rows"]] == [row["sampling"] for row in want["rows"]]
    for a, b in zip(rep["rows"], want["rows"]):
        for k in ("samples_per_pixel", "total_samples", "max_abs", "rmse", "psnr_db"):
            assert a[k] == b[k], (a["sampling"], k)
    for k in ("dims", "image", "adaptive_reduction", "adaptive_over_direct", "goals"):
        assert rep[k] == want[k], k
    # The samples images count every sample of the report.
    for row in rep["rows"]:
        s = r.samples[row["sampling"]]
        assert s is not None and s.shape == (24, 24)
        assert int(s.astype(np.float64).sum()) == row["total_samples"]
        assert r.images[row["sampling"]].shape == (24, 24, 4)
    assert rep["rows"][0]["max_abs"] == 0.0  # regular sampling is the reference
    assert "| " in r.markdown


# --- Processing: scipy.ndimage on its own conventions ---------------------------------

@pytest.fixture
def rand():
    return np.random.default_rng(30).random((7, 9, 11)).astype(np.float32)


# The job computes in f64 from the float32 voxels and rounds once to float32:
# within half an ulp of scipy's float64 result (2⁻²⁴ relative), plus scipy's own
# summation-order rounding (1e-15 of the O(1) values).
F32_ROUNDING = dict(rtol=2.0 ** -24, atol=1e-14)


@pytest.mark.parametrize("sigma", [1.0, (1.5, 0.7, 2.2), 3.0])
def test_gaussian_filter_is_scipys(rand, sigma):
    got = vnd.gaussian_filter(rand, sigma)
    want = ndi.gaussian_filter(rand.astype(np.float64), sigma, mode="reflect", truncate=4.0)
    assert got.dtype == np.float32 and got.shape == rand.shape
    np.testing.assert_allclose(got, want, **F32_ROUNDING)


@pytest.mark.parametrize("size", [3, 5])
def test_median_filter_is_scipys_exactly(rand, size):
    got = vnd.median_filter(rand, size=size)
    np.testing.assert_array_equal(got, ndi.median_filter(rand, size=size, mode="reflect"))


def test_median_filter_of_integers_is_scipys_exactly():
    a = np.random.default_rng(3).integers(0, 4000, (6, 8, 5)).astype(np.uint16)
    got = vnd.median_filter(a, size=3)
    np.testing.assert_array_equal(got, ndi.median_filter(a, size=3).astype(np.float32))


def test_gradient_magnitude_is_scipys_central_differences(rand):
    s = (2.0, 1.0, 0.5)  # (sz, sy, sx)
    got = vnd.gradient_magnitude(rand, spacing=s)
    a = rand.astype(np.float64)
    want = np.sqrt(sum((ndi.correlate1d(a, [-0.5, 0, 0.5], axis=ax, mode="reflect") / s[ax]) ** 2
                       for ax in range(3)))
    np.testing.assert_allclose(got, want, **F32_ROUNDING)


def test_ndimage_refuses_what_it_does_not_do(rand):
    with pytest.raises(voxlab.UnsupportedError, match="mode='nearest'"):
        vnd.gaussian_filter(rand, 1.0, mode="nearest")
    with pytest.raises(voxlab.UnsupportedError, match="order"):
        vnd.gaussian_filter(rand, 1.0, order=1)
    with pytest.raises(voxlab.UnsupportedError, match="footprint"):
        vnd.median_filter(rand, footprint=np.ones((3, 3, 3)))
    with pytest.raises(voxlab.ShapeError):
        vnd.gaussian_filter(rand[0], 1.0)
    with pytest.raises(voxlab.InvalidError):
        vnd.median_filter(rand, size=4)  # the job's own error: an even window


def test_resample_equals_the_command_line(tmp_path, cli):
    out = tmp_path / "r.nrrd"
    cli("process", "phantom:shepp-logan-modified:12", "--op", "resample", "--dims", "20,16,9",
        "--filter", "catmull-rom", "--out", out)
    want = voxlab.read(out)
    got = voxlab.resample("phantom:shepp-logan-modified:12", dims=(20, 16, 9), filter="catmull-rom")
    assert got.array.shape == (9, 16, 20)
    np.testing.assert_array_equal(got.array, want.array)
    np.testing.assert_array_equal(got.affine, want.affine)


def test_resampling_to_the_same_grid_is_the_identity(rand):
    for f in ("trilinear", "catmull-rom", "lanczos3"):
        r = voxlab.resample(rand, dims=(11, 9, 7), filter=f, spacing=(0.5, 1, 2))
        np.testing.assert_array_equal(r.array, rand)
        np.testing.assert_array_equal(r.affine, np.diag([0.5, 1, 2, 1]))


# --- bench -----------------------------------------------------------------------------

def test_bench_returns_the_report_it_writes(tmp_path, cli):
    r = voxlab.bench("quick", only="process/median-3,fft/2d", backends="cpu", runs=1,
                     warmup=0, out=tmp_path, name="py")
    ids = cli("bench", "--suite", "quick", "--only", "process/median-3,fft/2d",
              "--list").stdout.split()
    assert r["problems"] == []
    assert sorted(p.rsplit("/", 1)[-1] for p in r["paths"]) == ["py.json", "py.md", "py.svg"]
    written = json.load(open(tmp_path / "py.json"))
    r2 = {k: v for k, v in r.items() if k not in ("paths", "problems")}
    assert r2 == written
    # The command line's list of the same selection, in the same order.
    listed = [w for w in ids if "/" in w]
    assert [f"{c['family']}/{c['name']}" for c in written["cases"]] == listed
    assert written["suite"] == "quick" and written["runs"] == 1
    for c in written["cases"]:
        assert c["error"] is None and c["cpu_f64"]["status"] == "passed"
        assert c["cpu_f64"]["runs"] == 1 and c["cpu_f32"]["runs"] == 1


# --- Transfer functions in memory -------------------------------------------------------

TF2D = {
    "name": "two-widgets", "domain": [0.0, 1.0], "gradient_max": 2.0,
    "gradient_axis": "linear", "lut_size": [64, 16],
    "widgets": [
        {"shape": {"type": "triangle", "apex": 0.3, "half_width": 0.2, "gradient": [0.0, 2.0]},
         "rgba": [1.0, 0.8, 0.6, 0.7], "border": 0.5},
        {"shape": {"type": "ellipse", "center": [0.9, 0.0], "radii": [0.2, 0.5]},
         "rgba": [0.4, 0.6, 1.0, 0.3], "border": 0.6},
    ],
}


def test_transfer_functions_in_memory_equal_the_command_line_with_their_files(
        tmp_path, cli, monkeypatch):
    import tempfile

    def no_temp_files(*a, **k):
        raise AssertionError("a transfer function in memory must not go through a file")

    monkeypatch.setattr(tempfile, "mkstemp", no_temp_files)
    ramp = voxlab.TransferFunction.from_points([(0, (1, 0.5, 0.2, 0)), (1, (1, 1, 1, 0.8))])
    f1 = tmp_path / "ramp.json"
    f1.write_text(ramp.to_json())
    f2 = tmp_path / "w.json"
    f2.write_text(json.dumps(TF2D))
    size = ["--width", "20", "--height", "16"]
    cli("render", "phantom:shepp-logan-modified:16", *size, "--tf", f1, "--out", tmp_path / "a.npy")
    cli("render", "phantom:shepp-logan-modified:16", *size, "--tf2d", f2, "--out", tmp_path / "b.npy")
    a = voxlab.render("phantom:shepp-logan-modified:16", width=20, height=16, tf=ramp).image
    np.testing.assert_array_equal(a, np.load(tmp_path / "a.npy"))
    b = voxlab.render("phantom:shepp-logan-modified:16", width=20, height=16, tf2d=TF2D).image
    np.testing.assert_array_equal(b, np.load(tmp_path / "b.npy"))
    r = voxlab.Renderer("cpu").render("phantom:shepp-logan-modified:16", width=20, height=16,
                                      tf2d=TF2D).image
    np.testing.assert_array_equal(r, b)


def test_a_bad_transfer_function_in_memory_is_the_librarys_error():
    bad = dict(TF2D, widgets=[])
    with pytest.raises(voxlab.InvalidError, match="widget"):
        voxlab.render("phantom:sphere:8", width=8, height=8, tf2d=bad)
