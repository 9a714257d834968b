"""voxlab.ct: projections and reconstructions equal to the command line's files for
the same arguments; FBP through the job equals iradon."""

import json

import numpy as np
import pytest

import voxlab
import voxlab.ct as vct

skt = pytest.importorskip("skimage.transform")


def test_cone_projection_and_fdk_equal_the_command_line(tmp_path, cli):
    p = tmp_path / "cone.npy"
    cli("project", "phantom:shepp-logan", "--geometry", "cone", "--angles", "24", "--cols", "32",
        "--rows", "24", "--out", p)
    got = vct.project("phantom:shepp-logan", beam="cone", angles=24, cols=32, rows=24)
    want = np.load(p)
    assert got.layout == "stack" and got.projections.shape == (24, 24, 32)
    np.testing.assert_array_equal(got.projections, want)
    assert got.geometry == json.load(open(tmp_path / "cone.geometry.json"))
    r = tmp_path / "rec.npy"
    cli("reconstruct", p, "--size", "24", "--out", r)
    rec = vct.reconstruct(got.projections, got.geometry, size=24)
    assert rec.array.shape == (24, 24, 24)
    np.testing.assert_array_equal(rec.array.astype(np.float32), np.load(r))


def test_hardware_filtered_fdk_equals_the_command_line(tmp_path, cli, gpu):
    p = tmp_path / "cone.npy"
    cli("project", "phantom:shepp-logan", "--geometry", "cone", "--angles", "24", "--cols", "32",
        "--rows", "24", "--out", p)
    pr = vct.project("phantom:shepp-logan", beam="cone", angles=24, cols=32, rows=24)
    r = tmp_path / "rec.npy"
    cli("reconstruct", p, "--size", "24", "--backend", "gpu", "--hardware-filtering",
        "--out", r)
    rec = vct.reconstruct(pr.projections, pr.geometry, size=24, backend="gpu",
                          hardware_filtering=True)
    assert "texture unit" in rec.info["what"]
    np.testing.assert_array_equal(rec.array.astype(np.float32), np.load(r))
    exact = vct.reconstruct(pr.projections, pr.geometry, size=24)
    # The texture unit's 8-bit weights (real GPUs) move each voxel by at most
    # pi/(2A) * sum_k w_k * spread_k / 128: gpu::fbp::hardware_error_bound gives 0.042
    # for this scene, 3.1 % of the peak (1.337); tests/gpu_ct_fbp.rs holds the bound
    # voxel by voxel and the CPU adapter's f32 agreement.
    peak = np.abs(exact.array).max()
    assert np.abs(rec.array - exact.array).max() <= 3.5e-2 * peak
    with pytest.raises(voxlab.InvalidError, match="hardware-filtering.*backend gpu"):
        vct.reconstruct(pr.projections, pr.geometry, size=24, hardware_filtering=True)
    with pytest.raises(voxlab.InvalidError, match="hardware-filtering.*iterative"):
        vct.reconstruct(pr.projections, pr.geometry, size=24, backend="gpu",
                        hardware_filtering=True, method="sirt")


def test_hardware_filtered_joseph_equals_the_command_line(tmp_path, cli, gpu):
    v = voxlab.phantom("shepp-logan", 24)
    path = tmp_path / "v.nrrd"
    voxlab.write(path, v)
    p = tmp_path / "p.npy"
    cli("project", path, "--geometry", "cone", "--angles", "12", "--cols", "40", "--rows",
        "30", "--du", "8", "--backend", "gpu", "--hardware-filtering", "--out", p)
    scene = dict(beam="cone", angles=12, cols=40, rows=30, du=8)
    got = vct.project(v, backend="gpu", hardware_filtering=True, **scene)
    assert "texture unit" in got.info["what"]
    np.testing.assert_array_equal(got.projections, np.load(p))
    exact = vct.project(v, **scene)
    # The texture unit's three weights, each off by at most 2^-8 on real GPUs, move a
    # sample by at most 3 * D / 256 (D: the largest spread of a 2x2x2 cell, zero
    # border included), and a ray by that times the length it sums over, at most
    # sqrt(3) * 24 voxels of this isotropic grid. tests/gpu_ct_project.rs holds a
    # tighter bound pixel by pixel, and the CPU adapter's f32 agreement.
    a = np.pad(np.asarray(v.array, dtype=np.float64), 1)
    cells = [a[i:a.shape[0] - 1 + i, j:a.shape[1] - 1 + j, k:a.shape[2] - 1 + k]
             for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    spread = (np.max(cells, axis=0) - np.min(cells, axis=0)).max()
    voxel = np.linalg.norm(np.asarray(v.affine)[:3, :3], axis=0).max()
    peak = np.abs(exact.projections).max()
    bound = 3 * spread / 256 * np.sqrt(3) * 24 * voxel + 1e-5 * peak
    assert peak > 1.0
    assert np.abs(got.projections - exact.projections).max() <= bound
    with pytest.raises(voxlab.InvalidError, match="hardware-filtering.*backend gpu"):
        vct.project(v, hardware_filtering=True, **scene)
    with pytest.raises(voxlab.InvalidError, match="hardware-filtering.*analytic"):
        vct.project("phantom:shepp-logan", backend="gpu", hardware_filtering=True, **scene)


def test_joseph_projection_of_an_array_equals_the_command_line_on_its_file(tmp_path, cli):
    v = voxlab.phantom("spheres", (20, 18, 6))
    path = tmp_path / "v.nrrd"
    voxlab.write(path, v)
    p = tmp_path / "p.npy"
    cli("project", path, "--angles", "30", "--cols", "40", "--rows", "6", "--out", p)
    got = vct.project(v, angles=30, cols=40, rows=6)
    np.testing.assert_array_equal(got.projections, np.load(p))
    for backend in ("cpu-f32",):
        f = vct.project(v, angles=30, cols=40, rows=6, backend=backend)
        np.testing.assert_allclose(f.projections, got.projections, rtol=0,
                                   atol=1e-5 * np.abs(got.projections).max())


def test_parallel_fbp_through_the_job_is_iradon():
    pr = vct.project("phantom:shepp-logan-modified", angles=60, cols=48)
    assert pr.layout == "skimage" and pr.projections.shape == (48, 60)
    theta = np.array(pr.geometry["angles_deg"])
    rec = vct.reconstruct(pr.projections, pr.geometry)
    want = skt.iradon(pr.projections, theta)
    assert rec.array.shape == want.shape
    # Same computation as voxlab.transform.iradon (test_transform: ≤ 5e-14 of the peak).
    assert np.abs(rec.array - want).max() <= 5e-14 * np.abs(want).max()


def test_bad_geometry_and_options_are_clear():
    pr = vct.project("phantom:sphere", angles=8, cols=16)
    with pytest.raises(voxlab.InvalidError, match="filtr"):
        voxlab._voxlab.reconstruct_stack(pr.projections, json.dumps(pr.geometry),
                                         json.dumps({"filtr": "ramp"}))
    bad = dict(pr.geometry, cols=17)
    with pytest.raises(voxlab.VoxlabError, match="17|cols|detector"):
        vct.reconstruct(pr.projections, bad)
    with pytest.raises(voxlab.InvalidError, match="beam"):
        vct.project("phantom:sphere", beam="fan")


def test_iterative_reconstruction_equals_the_command_line(tmp_path, cli):
    p = tmp_path / "s.npy"
    cli("project", "phantom:shepp-logan-modified", "--angles", "20", "--cols", "32", "--out", p)
    pr = vct.project("phantom:shepp-logan-modified", angles=20, cols=32)
    np.testing.assert_array_equal(pr.projections, np.load(p))
    for method, extra, kw in [
        ("sirt", ["--nonnegative"], {"nonnegative": True}),
        ("cgls", [], {}),
        ("os-sart", ["--subsets", "4", "--relaxation", "0.5"], {"subsets": 4, "relaxation": 0.5}),
        ("tv", ["--tv-weight", "0.1"], {"tv_weight": 0.1}),
    ]:
        r, c = tmp_path / f"{method}.npy", tmp_path / f"{method}.csv"
        cli("reconstruct", p, "--method", method, "--iterations", "6", *extra,
            "--convergence", c, "--out", r)
        rec = vct.reconstruct(pr.projections, pr.geometry, method=method, iterations=6, **kw)
        assert rec.array.shape == (32, 32)
        np.testing.assert_array_equal(rec.array.astype(np.float32), np.load(r))
        log = rec.info["iterative"]
        assert log["method"] == method and log["iterations"] == 6 and not log["converged"]
        csv = np.loadtxt(c, delimiter=",", skiprows=1)
        assert csv.shape == (7, 3)
        np.testing.assert_allclose(log["residual"], csv[:, 1], rtol=2e-9)
        np.testing.assert_allclose(log["objective"], csv[:, 2], rtol=2e-9)
        # Every method lowers the misfit of the zero image.
        assert log["residual"][-1] < 0.5 * log["residual"][0]


def test_iterative_options_are_checked():
    pr = vct.project("phantom:sphere", angles=8, cols=16)
    with pytest.raises(voxlab.InvalidError, match="method"):
        vct.reconstruct(pr.projections, pr.geometry, method="art")
    with pytest.raises(voxlab.InvalidError, match="relaxation"):
        vct.reconstruct(pr.projections, pr.geometry, method="sirt", relaxation=2.5)
    with pytest.raises(voxlab.InvalidError, match="subsets"):
        vct.reconstruct(pr.projections, pr.geometry, method="os-sart", subsets=9)
