#!/usr/bin/env python3
"""voxlab's CPU f32 path beside the CPU codes a user would pick instead, on one machine.

One command (from the repository root):

    python3 scripts/peers/bench_peers.py [--quick] [--out docs/bench/peers-cpu.md]

It creates target/peers-venv (once) and installs scripts/peers/requirements-bench.txt
into it one line at a time, so a peer that does not install is reported and skipped;
builds target/release/voxlab and the ct_export example when they are missing; then
re-runs itself inside the venv and times the same task with each peer and with voxlab:

- FFT, complex64 forward, 2-D 1024² and 3-D 256³ (--quick: 128³): numpy.fft, scipy.fft
  (workers = cores), pyFFTW (FFTW_MEASURE, threads = cores, and one thread through
  fft_peers.py) against `voxlab fft --backend cpu` (its in-process `cpu-f32` median);
- parallel-beam FBP 512² from 402 views: scikit-image `iradon` and ASTRA's CPU `FBP`
  against `voxlab reconstruct --backend cpu-f32`;
- cone-beam FDK 128³ (and 256³ without --quick): RTK's
  `FDKConeBeamReconstructionFilter` against `voxlab reconstruct --backend cpu-f32`;
- DVR of the 256³ modified Shepp-Logan volume (--quick: 128³) to 512² (--quick: 256²):
  VTK's `vtkFixedPointVolumeRayCastMapper` in an offscreen window against
  `voxlab render --backend cpu-f32`, same transfer function, step and view.

Every time is the median of --runs runs (default 3) after one warm-up. voxlab is timed
by its own clock where the CLI prints one (`fft --json`, `render`); `reconstruct` prints
none, so its time is the command's wall clock minus the median wall clock of
`voxlab --version` (process start), input reading and output writing included.
Accuracy is measured against one reference per task (numpy's f64 FFT, the phantom's
exact values, voxlab's f64 render). Writes the Markdown table to --out and every number
to the same path with .json.
"""

import argparse
import hashlib
import json
import os
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import time

sys.dont_write_bytecode = True  # no __pycache__ beside the imported peer scripts

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
VENV = os.path.join(ROOT, "target", "peers-venv")
REQUIREMENTS = os.path.join(HERE, "requirements-bench.txt")
STAMP = os.path.join(VENV, "bench-install.json")
VOXLAB = os.path.join(ROOT, "target", "release", "voxlab")
CT_EXPORT = os.path.join(ROOT, "target", "release", "examples", "ct_export")


# ------------------------------------------------------------------------------------
# Set-up: the venv (with a per-package install report) and the voxlab binaries
# ------------------------------------------------------------------------------------


def requirement_lines():
    with open(REQUIREMENTS) as fh:
        return [ln.split("#")[0].strip() for ln in fh if ln.split("#")[0].strip()]


def ensure_venv():
    """Creates the venv and installs each requirement line on its own; returns the
    install report {line: "ok" | error text}. Skips pip when the report matches the
    current requirements."""
    text = open(REQUIREMENTS).read()
    digest = hashlib.sha256(text.encode()).hexdigest()
    if os.path.exists(STAMP):
        stamp = json.load(open(STAMP))
        if stamp.get("requirements_sha256") == digest:
            return stamp["install"]
    if not os.path.exists(os.path.join(VENV, "bin", "python")):
        print(f"creating {VENV}", file=sys.stderr)
        subprocess.run([sys.executable, "-m", "venv", VENV], check=True)
    pip = os.path.join(VENV, "bin", "pip")
    report = {}
    for line in requirement_lines():
        print(f"pip install {line}", file=sys.stderr, flush=True)
        r = subprocess.run([pip, "install", "--disable-pip-version-check", "-q", line],
                           capture_output=True, text=True)
        if r.returncode == 0:
            report[line] = "ok"
        else:
            tail = (r.stderr or r.stdout).strip().splitlines()[-3:]
            report[line] = "pip failed: " + " | ".join(tail)
            print(f"  {report[line]}", file=sys.stderr)
    with open(STAMP, "w") as fh:
        json.dump({"requirements_sha256": digest, "install": report}, fh, indent=1)
    return report


def ensure_binaries():
    if not os.path.exists(VOXLAB):
        subprocess.run(["cargo", "build", "--release"], cwd=ROOT, check=True)
    if not os.path.exists(CT_EXPORT):
        subprocess.run(["cargo", "build", "--release", "--example", "ct_export"], cwd=ROOT,
                       check=True)


# ------------------------------------------------------------------------------------
# Timing and machine description
# ------------------------------------------------------------------------------------


def timed_runs(fn, runs):
    """One warm-up call, then `runs` timed calls: (median s, [s...], warm-up result)."""
    out = fn()
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), times, out


def cores():
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def voxlab_env():
    return dict(os.environ, RAYON_NUM_THREADS=str(cores()))


def run_voxlab(args, **kw):
    return subprocess.run([VOXLAB, *args], check=True, env=voxlab_env(),
                          capture_output=True, text=True, **kw)


def voxlab_wall(args, runs, startup, warmup_extra=()):
    """voxlab's time for a CLI command without its own clock: wall clock minus the
    process start-up (median of `voxlab --version`). The untimed warm-up run gets
    `warmup_extra` appended; returns (median, times, the warm-up's output)."""
    def once():
        t = time.perf_counter()
        run_voxlab(args)
        return time.perf_counter() - t

    warm = run_voxlab(list(args) + list(warmup_extra))  # page cache, CPU frequency
    walls = [once() for _ in range(runs)]
    return (statistics.median(walls) - startup, [w - startup for w in walls],
            warm.stdout + warm.stderr)


def machine():
    model = platform.processor()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        load = os.getloadavg()
    except OSError:
        load = None
    return {"cpu": model, "cores": cores(), "os": platform.platform(),
            "host": platform.node(), "load_average_at_start": load,
            "python": platform.python_version()}


def versions():
    from importlib.metadata import PackageNotFoundError, version

    v = {}
    for dist in ("numpy", "scipy", "pyFFTW", "scikit-image", "itk", "itk-rtk", "vtk",
                 "astra-toolbox"):
        try:
            v[dist] = version(dist)
        except PackageNotFoundError:
            v[dist] = None
    try:
        import pyfftw

        v["fftw"] = "FFTW 3 bundled with pyFFTW"
        v["pyfftw_simd"] = bool(pyfftw.simd_alignment)
    except Exception:
        pass
    try:
        v["voxlab"] = run_voxlab(["--version"]).stdout.strip()
    except Exception as e:
        v["voxlab"] = f"unavailable: {e}"
    try:
        v["rustc"] = subprocess.run(["rustc", "--version"], capture_output=True,
                                    text=True).stdout.strip()
    except OSError:
        v["rustc"] = None
    return v


def err_text(e):
    s = f"{type(e).__name__}: {e}".strip()
    return s.splitlines()[0][:300] if s else type(e).__name__


# ------------------------------------------------------------------------------------
# (a) FFT
# ------------------------------------------------------------------------------------


def fft_task(shapes, runs, rows):
    import numpy as np

    sys.path.insert(0, HERE)
    n_threads = cores()
    for shape in shapes:
        size = "x".join(map(str, shape))
        rng = np.random.default_rng(0x5EED)
        a = (rng.uniform(-1, 1, shape) + 1j * rng.uniform(-1, 1, shape)).astype("complex64")
        ref = np.fft.fftn(a.astype("complex128"))
        nref = np.linalg.norm(ref)

        def rel(x):
            return float(np.linalg.norm(x - ref) / nref)

        # voxlab, all cores and one thread (its own median, after a warm-up).
        vox = {}
        for threads in (n_threads, 1):
            try:
                with tempfile.TemporaryDirectory() as d:
                    out = os.path.join(d, "fft.json")
                    env = dict(os.environ, RAYON_NUM_THREADS=str(threads))
                    subprocess.run([VOXLAB, "fft", "--backend", "cpu", "--runs", str(runs),
                                    "--json", out, size], check=True, env=env,
                                   stdout=subprocess.DEVNULL)
                    rep = json.load(open(out))
                case = next(c for c in rep["cases"] if c["backend"] == "cpu-f32")
                vox[threads] = (case["median_s"], case["rel_l2"], rep["threads"])
            except Exception as e:
                vox[threads] = (None, None, err_text(e))

        peers = []
        peers.append(("numpy.fft.fftn", 1, lambda: np.fft.fftn(a)))
        try:
            import scipy.fft

            peers.append(("scipy.fft.fftn", n_threads,
                          lambda: scipy.fft.fftn(a, workers=n_threads)))
        except Exception as e:
            rows.append(unavailable("FFT", size, "scipy.fft", e))
        try:
            import pyfftw

            def fftw_plan(threads):
                x = pyfftw.empty_aligned(shape, dtype="complex64", n=64)
                y = pyfftw.empty_aligned(shape, dtype="complex64", n=64)
                plan = pyfftw.FFTW(x, y, axes=tuple(range(len(shape))),
                                   direction="FFTW_FORWARD", flags=("FFTW_MEASURE",),
                                   threads=threads)
                x[...] = a  # FFTW_MEASURE overwrites the arrays while planning

                def go():
                    plan.execute()
                    return y
                return go

            t = time.perf_counter()
            go = fftw_plan(n_threads)
            print(f"  FFTW plan {size} ({n_threads} threads): "
                  f"{time.perf_counter() - t:.1f} s", file=sys.stderr)
            peers.append(("pyFFTW", n_threads, go))
        except Exception as e:
            rows.append(unavailable("FFT", size, "pyFFTW", e))

        for name, threads, fn in peers:
            med, times, out = timed_runs(fn, runs)
            v = vox[n_threads]
            rows.append(row("FFT c64", size, name, threads, med, times, v[0], None,
                            rel(out), v[1], "rel L2 vs numpy f64 fftn (voxlab: vs its f64 FFT)",
                            voxlab_threads=v[2]))
            print_row(rows[-1])
        # FFTW on one thread against voxlab on one thread: fft_peers.py's measurement.
        try:
            from fft_peers import fftw_median

            med, e = fftw_median(shape, runs)
            v = vox[1]
            rows.append(row("FFT c64", size, "pyFFTW (fft_peers.py)", 1, med, None, v[0],
                            None, e, v[1], "rel L2 vs numpy f64 fftn (voxlab: vs its f64 FFT)",
                            voxlab_threads=v[2]))
            print_row(rows[-1])
        except Exception as e:
            rows.append(unavailable("FFT", size, "pyFFTW (fft_peers.py)", e))
        del ref


# ------------------------------------------------------------------------------------
# (b) parallel-beam FBP 512² from 402 views
# ------------------------------------------------------------------------------------


def astra_fbp(sino, theta_deg, n):
    """ASTRA's CPU FBP (Ram-Lak) of a scikit-image sinogram (detector, angle) onto
    scikit-image's grid. ASTRA centres its detector between bins (n-1)/2 and its pixels
    on (i - (n-1)/2): one zero bin is appended so bin n/2 is the centre, the volume
    window is shifted half a pixel, the angles are negated and the rows flipped -- the
    one of the eight orientations whose RMS error matches iradon's (the others give
    RMS >= 0.10 against 0.052 on the 256² fixture)."""
    import astra
    import numpy as np

    s = np.vstack([sino, np.zeros((1, sino.shape[1]))]).T.astype(np.float32)
    pg = astra.create_proj_geom("parallel", 1.0, n + 1, np.deg2rad(-np.asarray(theta_deg)))
    h = n / 2
    vg = astra.create_vol_geom(n, n, -h - 0.5, h - 0.5, -h - 0.5, h - 0.5)
    sid = astra.data2d.create("-sino", pg, s)
    rid = astra.data2d.create("-vol", vg)
    pid = astra.create_projector("linear", pg, vg)
    cfg = astra.astra_dict("FBP")
    cfg.update(ReconstructionDataId=rid, ProjectionDataId=sid, ProjectorId=pid)
    cfg["option"] = {"FilterType": "ram-lak"}
    alg = astra.algorithm.create(cfg)
    try:
        astra.algorithm.run(alg)
        return astra.data2d.get(rid)[::-1].astype(np.float64)
    finally:
        astra.algorithm.delete(alg)
        astra.data2d.delete([sid, rid])
        astra.projector.delete(pid)


def fbp_task(work, ct, runs, startup, rows):
    import numpy as np

    n = 512
    size = f"{n}² from 402 views"
    sino_path = os.path.join(work, "sino512.npy")
    run_voxlab(["project", "phantom:shepp-logan", "--geometry", "parallel", "--angles",
                "402", "--cols", str(n), "--out", sino_path])
    geom = json.load(open(os.path.join(work, "sino512.geometry.json")))
    theta = np.asarray(geom["angles_deg"])
    sino = np.load(sino_path)
    # Truth: ct_export's 256² of 1 mm pixels at X = col - 128 is the centre of this 512²
    # grid at X = col - 256 (the phantom is zero outside its 256 mm cube).
    truth = np.zeros((n, n))
    t256 = np.load(os.path.join(ct, "truth2d.npy"))
    truth[128:384, 128:384] = t256
    r, c = np.mgrid[:n, :n] - n // 2
    circle = r * r + c * c <= 128**2  # ct-peers.md's circle, the phantom's disc

    def rms(img):
        return float(np.sqrt(np.mean((img - truth)[circle] ** 2)))

    out = os.path.join(work, "fbp512.npy")
    args = ["reconstruct", sino_path, "--backend", "cpu-f32", "--out", out]
    vmed, vtimes, _ = voxlab_wall(args, runs, startup)
    vrms = rms(np.load(out).astype(np.float64))
    metric = "RMS vs exact phantom, r ≤ 128 px disc"

    try:
        from skimage.transform import iradon

        med, times, img = timed_runs(lambda: iradon(sino, theta=theta, filter_name="ramp",
                                                    interpolation="linear", circle=True),
                                     runs)
        rows.append(row("parallel FBP", size, "scikit-image iradon (ramp, linear)", 1, med,
                        times, vmed, vtimes, rms(img), vrms, metric))
    except Exception as e:
        rows.append(unavailable("parallel FBP", size, "scikit-image iradon", e))
    print_row(rows[-1])
    try:
        med, times, img = timed_runs(lambda: astra_fbp(sino, theta, n), runs)
        rows.append(row("parallel FBP", size, "ASTRA FBP (CPU, ram-lak, linear)", 1, med,
                        times, vmed, vtimes, rms(img), vrms, metric))
    except Exception as e:
        rows.append(unavailable("parallel FBP", size, "ASTRA FBP (CPU)", e))
    print_row(rows[-1])


# ------------------------------------------------------------------------------------
# (c) cone-beam FDK
# ------------------------------------------------------------------------------------


def fdk_task(work, ct, sizes, runs, startup, rows):
    import numpy as np

    sys.path.insert(0, HERE)
    for n in sizes:
        # 128³: ct-peers.md's geometry (160² detector of 3 mm, 2 mm voxels);
        # 256³: 256² detector of 1.5 mm, 1 mm voxels. SID 1000, SDD 1500, 180 views/360°.
        det, du, sp = (160, 3.0, 2.0) if n == 128 else (n, 1.5, 1.0)
        size = f"{n}³ from 180 × {det}²"
        proj_path = os.path.join(work, f"cone{n}.npy")
        run_voxlab(["project", "phantom:shepp-logan", "--geometry", "cone", "--angles", "180",
                    "--cols", str(det), "--rows", str(det), "--du", str(du), "--sid", "1000",
                    "--sdd", "1500", "--out", proj_path])
        geom = json.load(open(os.path.join(work, f"cone{n}.geometry.json")))
        angles = list(geom["angles_deg"])
        proj = np.load(proj_path)
        if n == 128:
            truth = np.load(os.path.join(ct, "truth3d.npy"))
            mask = np.load(os.path.join(ct, "brain3d.npy")).astype(bool)
            metric = "RMS vs exact phantom, brain voxels"
        else:
            # `voxlab phantom` samples voxel centres (i - 127.5) mm of the phantom frame;
            # CT (X, Y, Z) = phantom (x, z, -y): T[Z, Y, X] = P[z = Y, y = -Z, x = X].
            pp = os.path.join(work, f"sl{n}.npy")
            run_voxlab(["phantom", f"shepp-logan:{n}", "--out", pp])
            truth = np.load(pp).astype(np.float64).transpose(1, 0, 2)[::-1]
            mask = np.ones(truth.shape, dtype=bool)
            metric = "RMS vs exact phantom, all voxels"

        def rms(vol):
            return float(np.sqrt(np.mean((vol - truth)[mask] ** 2)))

        out = os.path.join(work, f"fdk{n}.npy")
        args = ["reconstruct", proj_path, "--backend", "cpu-f32", "--size", str(n),
                "--spacing", str(sp), "--out", out]
        # The warm-up also prints voxlab's own RMS over all voxels: a check of the
        # truth's orientation at 256³.
        vmed, vtimes, txt = voxlab_wall(args, runs, startup,
                                        ["--truth", "phantom:shepp-logan"])
        vol = np.load(out).astype(np.float64)
        vrms = rms(vol)
        m = re.search(r"RMS error against shepp-logan: ([0-9.eE+-]+)", txt)
        own = float(m.group(1)) if m else None
        if n != 128 and own is not None and abs(own - vrms) > 1e-3 * max(vrms, 1e-12):
            print(f"  warning: voxlab says RMS {own}, this script {vrms}", file=sys.stderr)
        try:
            from make_ct_fixtures import rtk_fdk

            def go():
                return rtk_fdk(proj, angles, n, sp, du=du, dv=du, sid=1000.0, sdd=1500.0)

            med, times, rec = timed_runs(go, runs)
            import itk

            threads = int(itk.MultiThreaderBase.GetGlobalDefaultNumberOfThreads())
            rows.append(row("cone FDK", size, "RTK FDKConeBeamReconstructionFilter (ramp)",
                            threads, med, times, vmed, vtimes, rms(rec), vrms, metric,
                            voxlab_own_rms_all_voxels=own,
                            rms_all_voxels={"peer": float(np.sqrt(np.mean((rec - truth) ** 2))),
                                            "voxlab": float(np.sqrt(np.mean((vol - truth) ** 2)))}))
        except Exception as e:
            rows.append(unavailable("cone FDK", size, "RTK FDK", e))
        print_row(rows[-1])


# ------------------------------------------------------------------------------------
# (d) DVR
# ------------------------------------------------------------------------------------


def vtk_renderer(vol, tf, width, step):
    """An offscreen VTK scene: the volume (spacing 1, x fastest), the transfer function's
    control points as VTK colour and opacity functions (opacity per unit distance 1 =
    one voxel, voxlab's convention), trilinear, unshaded, a parallel camera looking
    along +z whose view fills the image with the volume's cross-section, as
    `voxlab render --view +z`. Returns (render window, its renderer, mapper)."""
    import vtk
    from vtk.util import numpy_support

    nz, ny, nx = vol.shape
    img = vtk.vtkImageData()
    img.SetDimensions(nx, ny, nz)
    img.SetSpacing(1.0, 1.0, 1.0)
    img.GetPointData().SetScalars(numpy_support.numpy_to_vtk(vol.ravel(), deep=True))
    ctf, otf = vtk.vtkColorTransferFunction(), vtk.vtkPiecewiseFunction()
    for p in tf["points"]:
        r, g, b, a = p["rgba"]
        ctf.AddRGBPoint(p["value"], r, g, b)
        otf.AddPoint(p["value"], a)
    prop = vtk.vtkVolumeProperty()
    prop.SetColor(ctf)
    prop.SetScalarOpacity(otf)
    prop.SetInterpolationTypeToLinear()
    prop.ShadeOff()
    prop.SetScalarOpacityUnitDistance(1.0)
    mapper = vtk.vtkFixedPointVolumeRayCastMapper()
    mapper.SetInputData(img)
    mapper.AutoAdjustSampleDistancesOff()  # else it lowers quality to hit a frame rate
    mapper.SetSampleDistance(step)
    mapper.SetImageSampleDistance(1.0)  # one ray per pixel
    mapper.SetNumberOfThreads(cores())
    volume = vtk.vtkVolume()
    volume.SetMapper(mapper)
    volume.SetProperty(prop)
    ren = vtk.vtkRenderer()
    ren.AddVolume(volume)
    ren.SetBackground(0.0, 0.0, 0.0)
    win = vtk.vtkRenderWindow()
    win.SetOffScreenRendering(1)
    win.SetSize(width, width)
    win.AddRenderer(ren)
    cam = ren.GetActiveCamera()
    cam.ParallelProjectionOn()
    c = ((nx - 1) / 2, (ny - 1) / 2, (nz - 1) / 2)
    cam.SetFocalPoint(*c)
    # The distance sets where VTK's samples fall along each ray; at 1000 (also 500 or
    # 2000) they fall where voxlab's do (mean abs difference 0.019 at 256³ → 512²
    # against 0.038 at 1024): this phantom's sharp edges make the images sensitive to
    # the sample phase. The time per frame does not depend on it.
    cam.SetPosition(c[0], c[1], c[2] - 1000.0)
    cam.SetViewUp(0.0, -1.0, 0.0)
    cam.SetParallelScale(ny / 2)
    ren.ResetCameraClippingRange()
    return win, ren, mapper


def vtk_image(win, width):
    import numpy as np
    import vtk
    from vtk.util import numpy_support

    w2i = vtk.vtkWindowToImageFilter()
    w2i.SetInput(win)
    w2i.ReadFrontBufferOff()
    w2i.Update()
    arr = numpy_support.vtk_to_numpy(w2i.GetOutput().GetPointData().GetScalars())
    # VTK's rows run bottom to top: flip to voxlab's (and NumPy's) top-to-bottom.
    return arr.reshape(width, width, -1)[::-1, :, :3].astype(np.float64) / 255.0


def dvr_task(work, n, width, runs, rows, block=8):
    import numpy as np

    size = f"{n}³ → {width}², step 0.5 voxel"
    vol_path = os.path.join(work, f"slm{n}.npy")
    run_voxlab(["phantom", f"shepp-logan-modified:{n}", "--out", vol_path])
    tf = json.loads(run_voxlab(["tf", "phantom"]).stdout)
    common = ["render", vol_path, "--view", "+z", "--width", str(width), "--height",
              str(width), "--tf", "phantom", "--no-shading", "--filter", "trilinear"]

    def voxlab_render(backend, out, step=0.5, extra=()):
        txt = run_voxlab(common + ["--step", str(step), "--backend", backend, "--out", out,
                                   *extra]).stderr
        m = re.search(r"per frame: median ([0-9.]+) s", txt) or \
            re.search(r"samples, ([0-9.]+) s on", txt)
        return float(m.group(1))

    # Per frame, as VTK is timed: `--repeat 5` renders five frames from one prepared
    # volume (converted and bounded once, as VTK's mapper keeps its own copy and
    # min-max volume) and prints their median; each timed run is one such median.
    repeat = ["--repeat", "5"]
    ref_path = os.path.join(work, "dvr_f64.npy")
    voxlab_render("cpu", ref_path, extra=["--interleaved"])
    ref = np.load(ref_path)[..., :3].astype(np.float64)  # over the opaque black background
    # The fine-step reference: the f64 oracle at an eighth of the step.
    fine_path = os.path.join(work, "dvr_f64_fine.npy")
    voxlab_render("cpu", fine_path, step=0.0625)
    fine = np.load(fine_path)[..., :3].astype(np.float64)
    # Without interleaved sampling first: its image, for the error of the plain grid.
    plain_path = os.path.join(work, "dvr_f32_plain.npy")
    voxlab_render("cpu-f32", plain_path)
    plain = np.load(plain_path)[..., :3].astype(np.float64)
    f32_path = os.path.join(work, "dvr_f32.npy")
    # Interleaved sampling (a fixed per-pixel offset of the first sample, no extra
    # work) spreads the step's wood-grain rings into fine noise; cells of `block`.
    tuned = repeat + ["--block-size", str(block), "--interleaved"]
    voxlab_render("cpu-f32", f32_path, extra=tuned)  # warm-up
    vtimes = [voxlab_render("cpu-f32", f32_path, extra=tuned) for _ in range(runs)]
    vmed = statistics.median(vtimes)
    default_block = [voxlab_render("cpu-f32", f32_path, extra=repeat + ["--interleaved"])
                     for _ in range(runs)]
    one_shot = [voxlab_render("cpu-f32", f32_path, extra=["--interleaved"])
                for _ in range(runs)]
    f32 = np.load(f32_path)[..., :3].astype(np.float64)

    def mean_abs(img, against=None):
        return float(np.mean(np.abs(img - (ref if against is None else against))))

    metric = "mean abs RGB diff from voxlab f64 render (0–1)"
    try:
        vol = np.load(vol_path).astype(np.float32)
        t = time.perf_counter()
        win, ren, mapper = vtk_renderer(vol, tf, width, 0.5)
        win.Render()  # set-up: context, textures, min-max volume, first frame
        first = time.perf_counter() - t
        cam = ren.GetActiveCamera()
        times = []
        for k in range(runs + 1):
            # The mapper re-casts every frame; a 0.001° nudge makes sure nothing is
            # reused from the previous frame.
            cam.Azimuth(1e-3 if k % 2 == 0 else -1e-3)
            t = time.perf_counter()
            win.Render()
            times.append(time.perf_counter() - t)
        times = times[1:]  # the first after set-up is the warm-up
        img = vtk_image(win, width)
        rows.append(row("DVR (unshaded)", size, "VTK vtkFixedPointVolumeRayCastMapper",
                        cores(), statistics.median(times), times, vmed, vtimes,
                        mean_abs(img), mean_abs(f32), metric,
                        vtk_window=type(win).__name__, vtk_first_render_s=first,
                        voxlab_block_size=block,
                        voxlab_default_block_median_s=statistics.median(default_block),
                        voxlab_default_block_times_s=default_block,
                        voxlab_one_shot_median_s=statistics.median(one_shot),
                        voxlab_one_shot_times_s=one_shot,
                        fine_reference="voxlab f64 at step 0.0625 voxel",
                        peer_error_vs_fine=mean_abs(img, fine),
                        voxlab_error_vs_fine=mean_abs(f32, fine),
                        voxlab_plain_grid_error_vs_fine=mean_abs(plain, fine),
                        voxlab_plain_grid_diff_from_f64=mean_abs(plain),
                        peer_diff_from_plain_grid=mean_abs(img, plain)))
        try:
            from PIL import Image

            Image.fromarray((np.clip(img, 0, 1) * 255).astype(np.uint8)).save(
                os.path.join(work, "dvr_vtk.png"))
            Image.fromarray((np.clip(f32, 0, 1) * 255 + 0.5).astype(np.uint8)).save(
                os.path.join(work, "dvr_voxlab.png"))
        except Exception:
            pass
    except Exception as e:
        rows.append(unavailable("DVR (unshaded)", size, "VTK FixedPointVolumeRayCast", e))
    print_row(rows[-1])


# ------------------------------------------------------------------------------------
# The table
# ------------------------------------------------------------------------------------


def row(task, size, peer, threads, peer_s, peer_times, vox_s, vox_times, peer_acc, vox_acc,
        metric, **extra):
    return {"task": task, "size": size, "peer": peer, "peer_threads": threads,
            "peer_median_s": peer_s, "peer_times_s": peer_times,
            "voxlab_median_s": vox_s, "voxlab_times_s": vox_times,
            "ratio_voxlab_over_peer": (vox_s / peer_s) if (vox_s and peer_s) else None,
            "peer_accuracy": peer_acc, "voxlab_accuracy": vox_acc, "accuracy_metric": metric,
            **extra}


def task_key(r):
    """fft, fbp, fdk or dvr: the --only name of a row's task."""
    return {"FFT": "fft", "parallel FBP": "fbp", "cone FDK": "fdk"}.get(
        r["task"].split(" c64")[0], "dvr")


def unavailable(task, size, peer, e):
    print(f"  {peer}: unavailable ({err_text(e)})", file=sys.stderr)
    return {"task": task, "size": size, "peer": peer, "unavailable": err_text(e)}


def fmt_s(s):
    if s is None:
        return "—"
    return f"{s * 1e3:.1f} ms" if s < 1 else f"{s:.2f} s"


def fmt_acc(x):
    return "—" if x is None else f"{x:.2e}" if x < 1e-3 else f"{x:.4f}"


def md_row(r):
    if "unavailable" in r:
        return f"| {r['task']} | {r['size']} | {r['peer']} | not run: {r['unavailable']} " \
               "| | | | | |"
    ratio = r["ratio_voxlab_over_peer"]
    vt = r.get("voxlab_threads", cores())
    return (f"| {r['task']} | {r['size']} | {r['peer']} ({r['peer_threads']} thr) | "
            f"{fmt_s(r['peer_median_s'])} | {fmt_s(r['voxlab_median_s'])} ({vt} thr) | "
            f"{'—' if ratio is None else f'{ratio:.2f}×'} | {fmt_acc(r['peer_accuracy'])} | "
            f"{fmt_acc(r['voxlab_accuracy'])} | {r['accuracy_metric']} |")


def print_row(r):
    print(md_row(r), file=sys.stderr, flush=True)


HEADER = ("| task | size | peer (threads) | peer median | voxlab CPU f32 median (threads) "
          "| voxlab / peer | peer accuracy | voxlab accuracy | accuracy metric |\n"
          "|---|---|---|---:|---:|---:|---:|---:|---|")


def write_md(res, path):
    m, v = res["machine"], res["versions"]
    lines = [
        "# voxlab's CPU f32 path beside the CPU peers",
        "",
        "The same tasks, on the same machine, with the CPU libraries a user would reach for",
        "instead of voxlab, and with voxlab's CPU f32 path; one table.",
        "",
        "## Machine and versions",
        "",
        f"- Date: {res['date_utc']}. Mode: {'--quick' if res['quick'] else 'full'}; "
        f"medians of {res['runs']} runs after one warm-up.",
        f"- Machine: {m['cpu']}, {m['cores']} cores, {m['os']}; load average at the start "
        f"{', '.join(f'{x:.1f}' for x in m['load_average_at_start'] or [])}.",
        *([f"- Runs per task (`--merge`): " + ", ".join(
            f"{k} {d}" for k, d in res["task_dates"].items())]
          if len(set(res.get("task_dates", {}).values())) > 1 else []),
        "- **The machine is shared with compilers and other jobs running at the same time:",
        "  these are single runs of the whole script, and the ratios can move by tens of",
        "  percent (and more for the long renders) from one run to the next.**",
        f"- Threads: voxlab (rayon) and the multi-threaded peers use all {m['cores']} cores;",
        "  numpy.fft, scikit-image `iradon` and ASTRA's CPU FBP run on one thread (they have",
        "  no threads option); the FFT rows marked 1 thr compare FFTW and voxlab on one",
        "  thread each (as docs/bench/fft-peers.md).",
        f"- Versions: {v.get('voxlab')} ({v.get('rustc')}); Python {m['python']}, "
        f"numpy {v.get('numpy')}, scipy {v.get('scipy')}, pyFFTW {v.get('pyFFTW')} "
        f"(its bundled FFTW 3), scikit-image {v.get('scikit-image')}, "
        f"ASTRA {v.get('astra-toolbox')}, ITK {v.get('itk')}, itk-rtk {v.get('itk-rtk')}, "
        f"VTK {v.get('vtk')}.",
    ]
    failed = {k: s for k, s in res["install"].items() if s != "ok"}
    if failed:
        lines.append("- Not installed: " + "; ".join(f"`{k}`: {s}" for k, s in failed.items()))
    lines += [
        "",
        "## Command",
        "",
        "```sh",
        f"python3 scripts/peers/bench_peers.py{' --quick' if res['quick'] else ''}",
        "```",
        "",
        "(creates `target/peers-venv` from `scripts/peers/requirements-bench.txt` and builds",
        "`target/release/voxlab` and the `ct_export` example when missing).",
        "",
        "## Results",
        "",
        "Ratio = voxlab time / peer time (below 1: voxlab is faster). Times in ms or s.",
        "",
        HEADER,
        *[md_row(r) for r in res["rows"]],
        "",
        "## What is timed",
        "",
        "- **FFT**: forward, unnormalised, complex64 random values uniform in [−1, 1) in",
        "  both parts. numpy and scipy: `fftn` (out of place, output allocated in the call);",
        "  pyFFTW: `FFTW.execute()` of an `FFTW_MEASURE` plan on 64-byte-aligned arrays",
        "  (planning not timed); voxlab: `voxlab fft --backend cpu --json`, the `cpu-f32`",
        "  case, `cpu::fft::fft_nd` in place, the median the binary measures itself (input",
        "  copy outside the timed region). Accuracy: the peers' relative L2 error against",
        "  numpy's f64 `fftn` of the same input; voxlab's against its own f64 FFT of its own",
        "  random input (both references agree with the exact DFT to ~1e−15).",
        "- **Parallel FBP**: exact line integrals of `Phantom::shepp_logan()` (Kak & Slaney",
        "  intensities, 256 mm cube) from `voxlab project --geometry parallel --angles 402",
        "  --cols 512`: 512 bins of 1 mm, centre bin 256, 402 angles over [0°, 180°); output",
        "  512² pixels of 1 mm. scikit-image: `iradon(sino, theta, filter_name='ramp',",
        "  interpolation='linear', circle=True)`. ASTRA: `FBP` (CPU) with a `linear`",
        "  projector and `ram-lak` filter, geometry aligned to scikit-image's (see",
        "  `astra_fbp` in the script). voxlab: `voxlab reconstruct sino.npy --backend",
        "  cpu-f32`; wall clock minus the median wall clock of `voxlab --version` "
        f"({res['voxlab_startup_s'] * 1e3:.1f} ms),",
        "  so it includes reading the sinogram and writing the image. Accuracy: RMS against",
        "  the phantom's exact values at the pixel centres over the disc of radius 128 px",
        "  around the centre (the phantom's section; the same pixels as the circle metric",
        "  of docs/bench/ct-peers.md).",
        "- **Cone FDK**: exact projections from `voxlab project --geometry cone --sid 1000",
        "  --sdd 1500 --angles 180` (360°), 128³: 160² detector of 3 mm, 2 mm voxels (the",
        "  geometry of ct-peers.md); 256³: 256² detector of 1.5 mm, 1 mm voxels. RTK:",
        "  `FDKConeBeamReconstructionFilter` (float32, plain ramp, no truncation",
        "  correction) through `make_ct_fixtures.rtk_fdk`, the whole call timed (image",
        "  conversion included). voxlab: `voxlab reconstruct … --backend cpu-f32 --size N",
        "  --spacing S`, wall clock minus start-up as above. Accuracy: RMS against the exact",
        "  phantom at the voxel centres, over the brain voxels at 128³ (ct-peers.md's",
        "  target metric) and over all voxels at 256³.",
        "- **DVR**: `voxlab phantom shepp-logan-modified:N` (float32, values in [0, 1]),",
        "  the `phantom` transfer-function preset (12 control points, opacity per voxel",
        "  length), trilinear interpolation, post-classification, front-to-back, step 0.5",
        "  voxel, no shading, an orthographic view along +z whose image covers the volume's",
        "  cross-section. voxlab: `voxlab render --view +z --width W --height W --tf phantom",
        "  --step 0.5 --no-shading --backend cpu-f32 --interleaved --repeat 5 --block-size",
        "  B`: interleaved sampling (a fixed per-pixel offset of the ray's first sample, no",
        "  extra work; docs/acceleration.md) and the median",
        "  time per frame it prints, five frames rendered from one prepared volume",
        "  (converted and bounded for skipping once, as VTK's mapper keeps its own copy and",
        "  min-max volume between frames); each of the runs is one such median. B = "
        f"{next((r.get('voxlab_block_size') for r in res['rows'] if r.get('voxlab_block_size')), '—')}",
        "  (cells of the empty-space grid, the CPU's best on this scene); the JSON also has",
        "  the default cells of 32 and the one-off render (set-up included). VTK:",
        "  `vtkFixedPointVolumeRayCastMapper`",
        "  with `AutoAdjustSampleDistancesOff`, `SampleDistance 0.5`, `ImageSampleDistance",
        "  1`, threads = cores, the same control points in a `vtkColorTransferFunction` /",
        "  `vtkPiecewiseFunction`, `ScalarOpacityUnitDistance 1`, linear interpolation,",
        "  shading off, in an offscreen render window "
        f"({next((r.get('vtk_window') for r in res['rows'] if r.get('vtk_window')), '—')});",
        "  timed per `Render()` call after the set-up render (the camera nudged by 0.001°",
        "  between frames). Shading is off in both because VTK's gradient shading and",
        "  voxlab's Phong model use different gradient and light conventions. Accuracy:",
        "  mean absolute RGB difference (0–1 scale) from voxlab's f64 render of the same",
        "  scene (interleaved too); VTK's image is read back in 8 bits and VTK samples in 16-bit fixed point,",
        "  so its number mixes precision with small convention differences (where the",
        "  samples fall along the ray, opacity correction) and is a sanity check of the",
        "  match, not an error. This phantom's sharp edges make both images sensitive to",
        "  the sample phase: VTK's camera sits 1000 mm from the centre, where its samples",
        "  fall where voxlab's plain (not interleaved) grid's do: VTK's mean difference",
        "  from that image is "
        + "; ".join(f"{r['peer_diff_from_plain_grid']:.3f}" for r in res["rows"]
                    if r.get("peer_diff_from_plain_grid") is not None)
        + " (0.038 with the camera at 1024 mm).",
        "  Against a fine-step reference (voxlab's f64 render at step 0.0625 voxel, the",
        "  yardstick for equal quality) the mean absolute RGB errors are "
        + "; ".join(f"VTK {r['peer_error_vs_fine']:.4f}, voxlab f32 "
                    f"{r['voxlab_error_vs_fine']:.4f} (without interleaving "
                    f"{r['voxlab_plain_grid_error_vs_fine']:.4f})"
                    for r in res["rows"] if r.get("peer_error_vs_fine") is not None) + ".",
        "",
        "## Reading it",
        "",
        "- Peers that run on one thread (numpy.fft, `iradon`, ASTRA's CPU FBP) are set",
        "  against voxlab on all cores: that is the choice a user has, not a per-core",
        "  comparison. The 1-thread FFT rows are the per-core one.",
        "- With the machine oversubscribed, multi-threaded code suffers most (a thread",
        "  that waits for its partner's time slice stalls the whole transform): on some",
        "  runs FFTW on all cores is slower than FFTW on one. docs/bench/fft-peers.md has",
        "  the one-thread FFT comparison on a quieter machine.",
        "- The FBP and FDK accuracies are the same inputs and the same reference for both",
        "  sides, so the accuracy columns compare directly (voxlab's target: within 5% of",
        "  the peer's RMS error).",
        "- DVR: VTK's fixed-point ray caster samples a 16-bit fixed-point copy of the",
        "  volume and leaps over empty space with a coarse min-max volume; voxlab's CPU",
        "  renderer is the f32 twin of its f64 oracle (within 1e-7 of it), skips empty",
        "  cells of its own min/max grid, ends rays early and marches them sixteen to a",
        "  vector register (docs/raycasting.md). Both are timed per frame with their",
        "  set-up left out; voxlab's one-off render with set-up is in the JSON.",
        "",
        "Raw numbers (every run, thread counts, versions): "
        f"`{os.path.basename(os.path.splitext(path)[0])}.json`.",
        "",
    ]
    with open(path, "w") as fh:
        fh.write("\n".join(lines))


def add_common_arguments(ap, out, merge_help, work_help):
    """The options every peer script shares: --out, --runs, --merge, --md-only,
    --no-venv, --work."""
    ap.add_argument("--out", default=out)
    ap.add_argument("--runs", type=int, default=3, help="timed runs after one warm-up")
    ap.add_argument("--merge", action="store_true", help=merge_help)
    ap.add_argument("--md-only", action="store_true",
                    help="only rewrite the Markdown from the existing --out JSON")
    ap.add_argument("--no-venv", action="store_true",
                    help="run in this interpreter (the peers must be importable)")
    ap.add_argument("--work", default=os.path.join(ROOT, "target", "peers-bench"),
                    help=work_help)


def parse_and_enter(ap, script, write_md):
    """Parses the options of `ap` (with add_common_arguments'); with --md-only rewrites
    the page from its JSON and exits; otherwise re-runs `script` inside the peers'
    venv (made, and the binaries built, when missing) unless --no-venv or already
    there. Returns the options."""
    args = ap.parse_args()
    if args.runs < 3:
        ap.error("--runs must be at least 3")
    if args.md_only:
        write_md(json.load(open(os.path.splitext(args.out)[0] + ".json")), args.out)
        sys.exit(0)
    in_venv = os.path.realpath(sys.prefix) == os.path.realpath(VENV)
    if not args.no_venv and not in_venv:
        ensure_venv()
        ensure_binaries()
        py = os.path.join(VENV, "bin", "python")
        os.execv(py, [py, os.path.abspath(script), *sys.argv[1:]])
    return args


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="smaller sizes: FFT 128³ instead of 256³, no FDK 256³, DVR 128³ → 256²")
    ap.add_argument("--only", default="fft,fbp,fdk,dvr",
                    help="comma-separated subset of fft,fbp,fdk,dvr")
    add_common_arguments(ap, os.path.join("docs", "bench", "peers-cpu.md"),
                         "keep the other tasks' rows of an existing --out JSON",
                         "scratch folder for inputs and outputs")
    args = parse_and_enter(ap, __file__, write_md)
    install = json.load(open(STAMP))["install"] if os.path.exists(STAMP) else {}
    ensure_binaries()

    os.makedirs(args.work, exist_ok=True)
    ct = os.path.join(args.work, "ct")
    if not os.path.exists(os.path.join(ct, "truth3d.npy")):
        subprocess.run([CT_EXPORT, ct], check=True)

    startup = statistics.median(
        [(lambda t: (run_voxlab(["--version"]), time.perf_counter() - t)[1])(
            time.perf_counter()) for _ in range(7)])
    res = {"date_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
           "quick": args.quick, "runs": args.runs, "machine": machine(),
           "versions": versions(), "install": install, "voxlab_startup_s": startup,
           "rows": []}
    rows = res["rows"]
    only = set(args.only.split(","))
    res["task_dates"] = {k: res["date_utc"] for k in only}
    old_json = os.path.splitext(args.out)[0] + ".json"
    kept = []
    if args.merge and os.path.exists(old_json):
        old = json.load(open(old_json))
        kept = [r for r in old["rows"] if task_key(r) not in only]
        res["task_dates"] = {**{task_key(r): old.get("task_dates", {}).get(
            task_key(r), old["date_utc"]) for r in kept}, **res["task_dates"]}
    print(HEADER, file=sys.stderr)
    t0 = time.perf_counter()
    if "fft" in only:
        fft_task([(1024, 1024), (128, 128, 128) if args.quick else (256, 256, 256)],
                 args.runs, rows)
    if "fbp" in only:
        fbp_task(args.work, ct, args.runs, startup, rows)
    if "fdk" in only:
        fdk_task(args.work, ct, [128] if args.quick else [128, 256], args.runs, startup, rows)
    if "dvr" in only:
        if args.quick:
            dvr_task(args.work, 128, 256, args.runs, rows)
        else:
            dvr_task(args.work, 256, 512, args.runs, rows)
    res["total_s"] = time.perf_counter() - t0
    order = ["fft", "fbp", "fdk", "dvr"]
    res["rows"] = sorted(kept + rows, key=lambda r: order.index(task_key(r)))
    res["machine"]["load_average_at_end"] = os.getloadavg()

    out = args.out
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    with open(os.path.splitext(out)[0] + ".json", "w") as fh:
        json.dump(res, fh, indent=1)
        fh.write("\n")
    write_md(res, out)
    print(f"wrote {out} and {os.path.splitext(out)[0]}.json in {res['total_s']:.0f} s",
          file=sys.stderr)


if __name__ == "__main__":
    main()
