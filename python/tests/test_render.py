"""Rendering and validation: axis views against NumPy reductions (exact), images and
samples equal to the command line's .npy for the same arguments, options and their
errors, the Renderer, compare (oracle vs GPU, and vs an image the user brings)."""

import numpy as np
import pytest

import voxlab

AXES = {"+z": 0, "-z": 0, "+y": 1, "-y": 1, "+x": 2, "-x": 2}


def random_volume(shape=(9, 11, 13), seed=4):
    return np.random.default_rng(seed).random(shape).astype(np.float32)


@pytest.mark.parametrize("view", list(AXES))
@pytest.mark.parametrize("backend", ["cpu", "cpu-f32"])
def test_axis_views_are_numpy_reductions(view, backend):
    a = random_volume()
    spacing = (0.5, 1.25, 2.0)  # x, y, z in mm
    axis = AXES[view]
    sp = spacing[2 - axis]
    f32 = backend == "cpu-f32"
    # The oracle in f64 rounds its image to float32 once: 2 ulps of float32. The f32
    # path sums in f32: n_axis · 2⁻²⁴ relative.
    rtol = 3e-7 * (a.shape[axis] if f32 else 1)
    for mode, want in [("mip", a.max(axis=axis)), ("minip", a.min(axis=axis)),
                       ("xray", a.astype(np.float64).sum(axis=axis) * sp)]:
        r = voxlab.render(a, spacing=spacing, mode=mode, view=view, step=1, backend=backend)
        assert r.image.dtype == np.float32 and r.image.shape == want.shape
        np.testing.assert_allclose(r.image, want, rtol=rtol, atol=0)


CLI_CASES = [
    ("phantom:shepp-logan-modified:32", {}, []),
    ("phantom:marschner-lobb:25", {"filter": "catmull-rom", "azimuth": 75.0, "elevation": -10.0,
                                   "width": 40, "height": 28, "tf": "marschner-lobb"},
     ["--filter", "catmull-rom", "--azimuth", "75", "--elevation", "-10", "--width", "40",
      "--height", "28", "--tf", "marschner-lobb"]),
    ("phantom:spheres:24", {"mode": "mip", "ortho": True, "width": 30, "height": 30},
     ["--mode", "mip", "--ortho", "--width", "30", "--height", "30"]),
    ("phantom:shepp-logan:20", {"mode": "xray", "view": "-y", "step": 0.7},
     ["--mode", "xray", "--view", "-y", "--step", "0.7"]),
    ("phantom:spheres:20", {"iso": [{"value": 0.5, "color": [1.0, 0.2, 0.0], "opacity": 1.0}],
                            "mode": "iso", "width": 24, "height": 24, "shadows": True,
                            "iso_opaque": True},
     ["--iso", "0.5:#ff3300:1", "--mode", "iso", "--width", "24", "--height", "24",
      "--shadows", "--iso-opaque"]),
    ("phantom:shepp-logan-modified:24", {"skip_empty": True, "jitter": 3, "width": 32,
                                         "height": 32, "background": [0.1, 0.2, 0.3, 1.0]},
     ["--skip-empty", "on", "--jitter", "3", "--width", "32", "--height", "32",
      "--background", "0.1,0.2,0.3,1"]),
]


@pytest.mark.parametrize("backend", ["cpu", "cpu-f32"])
@pytest.mark.parametrize("case", range(len(CLI_CASES)))
def test_images_equal_the_command_lines_npy(tmp_path, cli, backend, case):
    source, kwargs, args = CLI_CASES[case]
    out, samples = tmp_path / "img.npy", tmp_path / "samples.npy"
    r = cli("render", source, *args, "--backend", backend, "--out", out, "--samples", samples,
            check=False)
    if r.returncode != 0:
        pytest.fail(f"voxlab render {source} {' '.join(args)}: {r.stderr}")
    got = voxlab.render(source, backend=backend, samples=True, **kwargs)
    want = np.load(out)
    assert got.image.dtype == want.dtype and got.image.shape == want.shape
    np.testing.assert_array_equal(got.image, want)
    np.testing.assert_array_equal(got.samples, np.load(samples))
    assert got.total_samples == int(np.load(samples).astype(np.float64).sum())


def test_a_volume_in_memory_renders_as_its_file(tmp_path, cli):
    v = voxlab.phantom("shepp-logan-modified", (20, 24, 16))
    path = tmp_path / "v.nrrd"
    voxlab.write(path, v)
    out = tmp_path / "img.npy"
    cli("render", path, "--width", "32", "--height", "24", "--tf", "phantom", "--out", out)
    want = np.load(out)
    for vol in (v, voxlab.read(path), str(path)):
        got = voxlab.render(vol, width=32, height=24, tf="phantom").image
        np.testing.assert_array_equal(got, want)


def test_a_transfer_function_object_is_its_preset():
    tf = voxlab.TransferFunction.preset("phantom")
    a = voxlab.render("phantom:shepp-logan:16", tf=tf, width=16, height=16).image
    b = voxlab.render("phantom:shepp-logan:16", tf="phantom", width=16, height=16).image
    np.testing.assert_array_equal(a, b)
    ramp = voxlab.TransferFunction.from_points([(0, (1, 1, 1, 0)), (1, (1, 1, 1, 1))])
    c = voxlab.render("phantom:shepp-logan:16", tf=ramp, width=16, height=16).image
    assert not np.array_equal(a, c)


def test_the_default_renders():
    r = voxlab.render(width=16, height=12)
    assert r.image.shape == (12, 16, 4) and r.engine == "cpu (f64 oracle)"
    assert r.image[..., 3].max() > 0


def test_unknown_and_bad_options_name_the_field():
    with pytest.raises(voxlab.InvalidError, match="colour") as e:
        voxlab.render("phantom:sphere:8", colour="red")
    assert isinstance(e.value, ValueError)
    with pytest.raises(voxlab.InvalidError, match="filter.*bicubic-ish.*catmull-rom"):
        voxlab.render("phantom:sphere:8", filter="bicubic-ish")
    with pytest.raises(voxlab.InvalidError, match="azimuth"):
        voxlab.render("phantom:sphere:8", azimuth="north")
    with pytest.raises(voxlab.InvalidError, match="jitter"):
        voxlab.render("phantom:sphere:8", jitter=-1)
    with pytest.raises(voxlab.InvalidError, match="backend"):
        voxlab.render("phantom:sphere:8", backend="tpu")
    with pytest.raises(voxlab.FileError) as e:
        voxlab.render("/no/such/volume.nrrd")
    assert isinstance(e.value, OSError) and "/no/such/volume.nrrd" in str(e.value)


def test_bad_arrays_are_clear_errors():
    with pytest.raises(voxlab.DtypeError, match="int32") as e:
        voxlab.render(np.zeros((4, 4, 4), np.int32))
    assert isinstance(e.value, TypeError)
    with pytest.raises(voxlab.DtypeError):
        voxlab.render(np.zeros((4, 4, 4), np.complex64))
    with pytest.raises(voxlab.ShapeError, match="3-D") as e:
        voxlab.render(np.zeros((4, 4), np.float32))
    assert isinstance(e.value, ValueError)
    with pytest.raises(voxlab.ShapeError):
        voxlab.render(np.zeros((0, 4, 4), np.float32))


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int16, np.float32, np.float64])
def test_layouts_and_dtypes_render_the_same(dtype):
    a = (random_volume((6, 7, 8)) * 100).astype(dtype)
    want = voxlab.render(a, mode="mip", view="+z", step=1).image
    np.testing.assert_array_equal(want, a.max(axis=0).astype(np.float32))
    f = np.asfortranarray(a)  # copied to C order first (docs/python.md)
    np.testing.assert_array_equal(voxlab.render(f, mode="mip", view="+z", step=1).image, want)
    big = a.astype(a.dtype.newbyteorder(">"))
    np.testing.assert_array_equal(voxlab.render(big, mode="mip", view="+z", step=1).image, want)
    strided = np.repeat(a, 2, axis=2)[:, :, ::2]
    np.testing.assert_array_equal(voxlab.render(strided, mode="mip", view="+z", step=1).image, want)


def test_renderer_keeps_its_engine_and_renders_like_render():
    r = voxlab.Renderer("cpu-f32")
    assert r.backend == "cpu-f32"
    v = voxlab.phantom("spheres", 16)
    for az in (0.0, 90.0, 200.0):
        got = r.render(v, azimuth=az, width=20, height=20, samples=True)
        want = voxlab.render(v, backend="cpu-f32", azimuth=az, width=20, height=20, samples=True)
        np.testing.assert_array_equal(got.image, want.image)
        np.testing.assert_array_equal(got.samples, want.samples)
    with pytest.raises(voxlab.InvalidError, match="voxlab.render"):
        r.render(v, repeat=3)


def test_auto_falls_back_and_says_why():
    r = voxlab.Renderer("auto")
    if r.backend == "cpu":
        assert r.fallback_reason


def test_progress_reports_rows_and_a_failing_callback_stops_the_job():
    seen = []
    r = voxlab.render("phantom:sphere:16", width=24, height=40,
                      progress=lambda s, d, t: seen.append((s, d, t)))
    assert seen[-1] == (seen[-1][0], 40, 40) and "rendering" in seen[-1][0]
    assert [d for _, d, _ in seen] == sorted(d for _, d, _ in seen)

    class Stop(Exception):
        pass

    calls = []

    def stop(stage, done, total):
        calls.append(done)
        if done > 0:
            raise Stop()

    with pytest.raises(Stop):
        voxlab.render("phantom:shepp-logan-modified:96", width=256, height=256,
                      filter="lanczos3", progress=stop)
    assert r.image.shape == (40, 24, 4)


def test_ctrl_c_interrupts_a_render_and_the_gil_is_released():
    import _thread
    import threading
    import time

    kw = dict(filter="lanczos3", step=0.25)
    t = time.perf_counter()
    voxlab.render("phantom:shepp-logan-modified:64", width=64, height=64, **kw)
    small = time.perf_counter() - t
    # A frame that takes about 4 s here (time grows with the pixel count).
    side = int(min(2048, 64 * np.sqrt(4.0 / max(small, 1e-3))))
    full = small * (side / 64) ** 2
    ticks = []
    stop = threading.Event()

    def tick():
        while not stop.is_set():
            ticks.append(1)
            time.sleep(0.005)

    def interrupt():
        time.sleep(0.1 * full)
        _thread.interrupt_main()

    threading.Thread(target=tick, daemon=True).start()
    threading.Thread(target=interrupt, daemon=True).start()
    t = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        voxlab.render("phantom:shepp-logan-modified:64", width=side, height=side, **kw)
    took = time.perf_counter() - t
    stop.set()
    assert took < 0.5 * full, (took, full)  # stopped soon after Ctrl-C, not run to its end
    assert len(ticks) > 10  # the other thread ran while Rust rendered


def test_compare_with_your_own_image():
    kw = dict(mode="mip", view="+z", step=1)
    v = random_volume((5, 6, 7))
    oracle = voxlab.render(v, **kw).image
    same = voxlab.compare(v, oracle, **kw)
    assert same.passed and same.stats["max_abs"] == 0 and same.stats["n"] == oracle.size
    mine = oracle.astype(np.float64).copy()
    mine[2, 3] += 0.125
    r = voxlab.compare(v, mine, max_abs=0.1, **kw)
    assert not r.passed
    assert r.stats["max_abs"] == 0.125
    assert r.stats["worst_index"] == 2 * oracle.shape[1] + 3
    np.testing.assert_allclose(r.stats["rmse"], np.sqrt(0.125 ** 2 / oracle.size), rtol=1e-12)
    assert r.heatmap.dtype == np.float32 and r.heatmap.shape[1] == oracle.shape[1]
    assert r.heatmap.shape[2] == 4
    with pytest.raises(voxlab.InvalidError, match="shape"):
        voxlab.compare_images(oracle, oracle[:, :3])


def test_gpu_renders_match_the_oracle(gpu):
    v = voxlab.phantom("shepp-logan-modified", 32)
    # tests/gpu_raycast.rs: EXACT_SCALAR bounds max |Δ| by 5e-5 of the data scale (1 here),
    # EXACT_DVR by 1e-3 (lavapipe measured 2.4e-4).
    mip = voxlab.compare(v, mode="mip", ortho=True, width=40, height=40, max_abs=5e-5, rmse=1e-5)
    assert mip.passed, mip.message
    dvr = voxlab.compare(v, width=40, height=40, max_abs=1e-3, rmse=5e-5)
    assert dvr.passed, dvr.message
    assert dvr.oracle.shape == dvr.port.shape == (40, 40, 4)
    # The Renderer on the GPU gives the compare job's GPU image.
    got = gpu.render(v, width=40, height=40)
    np.testing.assert_array_equal(got.image, dvr.port)
    assert got.gpu_timings is not None and got.engine.startswith("gpu")
    # And an axis view is the NumPy reduction within the same bound.
    a = random_volume()
    x = gpu.render(a, mode="xray", view="+z", step=1).image
    np.testing.assert_allclose(x, a.astype(np.float64).sum(axis=0), rtol=0, atol=5e-5 * a.shape[0])


def test_hardware_frames_of_a_uint16_volume_hold_two_bytes_per_voxel(gpu):
    # A uint16 volume: hardware-filtered frames read a 16-bit texture alone; an exact
    # frame adds the float32 one.
    v = np.round(voxlab.phantom("shepp-logan-modified", 24).array * 60000).astype(np.uint16)
    scene = gpu.prepare(v, width=32, height=24)
    n = v.size
    fast = scene.render(azimuth=30.0, hardware_filtering=True).info["gpu_session"]
    assert (fast["volume_uploads"], fast["volume_bytes"]) == (1, 2 * n), fast
    scene.render(azimuth=30.0, hardware_filtering=True, mode="mip")
    assert scene.session_stats()["volume_bytes"] == 2 * n
    exact = scene.render(azimuth=30.0).info["gpu_session"]
    assert (exact["volume_uploads"], exact["volume_bytes"]) == (2, 6 * n), exact


def test_a_second_prepared_gpu_scene_takes_the_first_ones_pipeline(gpu):
    # The device keeps the compiled pipelines: a second scene takes the ray caster's and
    # the min/max grid's, compiles nothing, and renders the same image.
    v = voxlab.phantom("shepp-logan-modified", 16)
    options = dict(width=24, height=20, mode="dvr", filter="catmull-rom", azimuth=17.0)
    first = gpu.prepare(v, **options).render()
    second = gpu.prepare(v, **options).render()
    a, b = first.info["gpu_session"], second.info["gpu_session"]
    assert a["pipelines_compiled"] + a["pipelines_shared"] == 2, a
    assert (b["pipelines_compiled"], b["pipelines_shared"]) == (0, 2), b
    np.testing.assert_array_equal(first.image, second.image)


def test_a_prepared_gpu_scene_renders_like_render_and_uploads_once(gpu):
    v = voxlab.phantom("shepp-logan-modified", 32)
    scene = gpu.prepare(v, width=40, height=30, samples=True)
    assert scene.shape == (32, 32, 32)
    bone = voxlab.TransferFunction.preset("ct-bone")
    frames = [
        dict(azimuth=30.0),
        dict(azimuth=80.0),
        dict(azimuth=130.0, elevation=-10.0),
        dict(azimuth=130.0, mode="mip", ortho=True),
        dict(azimuth=180.0, filter="catmull-rom"),
        dict(azimuth=180.0, tf=bone, window=(1.0, 0.5)),
        dict(azimuth=230.0),
    ]
    for k, options in enumerate(frames):
        got = scene.render(samples=True, **options)
        want = voxlab.render(v, backend="gpu", width=40, height=30, samples=True, **options)
        np.testing.assert_array_equal(got.image, want.image, err_msg=str(options))
        np.testing.assert_array_equal(got.samples, want.samples, err_msg=str(options))
        session = got.info["gpu_session"]
        assert session["volume_uploads"] == 1 and session["frames"] == k + 1, session
        if k in (1, 2):
            # Only the camera changed: nothing uploaded, nothing prepared.
            assert got.gpu_timings["upload"] == 0.0, got.gpu_timings
            assert got.gpu_timings["prepare"] == 0.0, got.gpu_timings
        if k == 1:
            first = session
        if k == 2:
            assert session["table_uploads"] == first["table_uploads"]
            assert session["pipelines_compiled"] == first["pipelines_compiled"]
            assert session["prepare_passes"] == first["prepare_passes"]
    assert scene.session_stats() == session
    # The volume was copied at prepare: changing the array does not reach the frames.
    a = random_volume((12, 10, 8))
    kept = gpu.prepare(a, mode="mip", view="+z", step=1)
    before = kept.render().image
    a[:] = 0
    np.testing.assert_array_equal(kept.render().image, before)
    # Options that choose the volume belong to prepare.
    with pytest.raises(voxlab.InvalidError, match="spacing"):
        kept.render(spacing=(1, 2, 3))
    with pytest.raises(voxlab.InvalidError, match="voxlab.render"):
        kept.render(stereo={"layout": "anaglyph"})


def test_a_prepared_cpu_scene_renders_like_render():
    r = voxlab.Renderer("cpu-f32")
    v = voxlab.phantom("spheres", 16)
    scene = r.prepare(v, width=20, height=20)
    for options in (dict(azimuth=0.0), dict(azimuth=90.0), dict(filter="catmull-rom")):
        got = scene.render(**options)
        want = voxlab.render(v, backend="cpu-f32", width=20, height=20, **options)
        np.testing.assert_array_equal(got.image, want.image)
        assert got.info["gpu_session"] is None
    assert scene.session_stats() is None
    # The array is lent to prepare without a copy, but the scene keeps a copy of its
    # own: a frame that prepares again (a new filter) after the array changed still
    # shows the volume as it was.
    orig = v.array.copy()
    a = v.array.copy()
    kept = r.prepare(a, width=20, height=20, mode="mip", view="+z", step=1)
    a[:] = 0
    got = kept.render(filter="catmull-rom").image
    want = voxlab.render(orig, backend="cpu-f32", width=20, height=20, mode="mip", view="+z",
                         step=1, filter="catmull-rom").image
    np.testing.assert_array_equal(got, want)
