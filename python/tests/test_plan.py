"""``dry_run=True``: every heavy job's memory plan from Python. The plan is the command
line's ``--dry-run`` for the same arguments (the text it prints, less the files it would
write), a dry run raises what the run raises, and it computes and writes nothing."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

import voxlab
import voxlab.ct as vct


def cli_plan(cli, *args):
    """`--dry-run`'s text for ARGS, without its `would write:` lines (the Python
    functions return arrays and write nothing)."""
    out = cli(*args, "--dry-run").stdout
    return "".join(l for l in out.splitlines(True) if not l.startswith("would write:"))


def cone(tmp_path, cli):
    """A small cone-beam stack: the file the command line reads, and the same
    projections in memory."""
    p = tmp_path / "p.npy"
    cli("project", "phantom:shepp-logan", "--geometry", "cone", "--angles", "12", "--cols",
        "20", "--rows", "16", "--out", p)
    return p, vct.project("phantom:shepp-logan", beam="cone", angles=12, cols=20, rows=16)


def test_each_jobs_plan_is_the_command_lines_dry_run(tmp_path, cli):
    o = tmp_path
    v = voxlab.phantom("spheres", 20)
    path = o / "v.nrrd"
    voxlab.write(path, v)
    p, pr = cone(tmp_path, cli)
    cases = [
        (voxlab.render("phantom:spheres:24", width=40, height=30, mode="mip", dry_run=True),
         ["render", "phantom:spheres:24", "--width", "40", "--height", "30", "--mode", "mip",
          "--out", o / "r.png"]),
        (voxlab.render(v, width=32, height=24, backend="cpu-f32", dry_run=True),
         ["render", path, "--width", "32", "--height", "24", "--backend", "cpu-f32",
          "--out", o / "r.png"]),
        (vct.project(v, angles=10, cols=24, rows=8, dry_run=True),
         ["project", path, "--angles", "10", "--cols", "24", "--rows", "8", "--out",
          o / "q.npy"]),
        (vct.reconstruct(pr.projections, pr.geometry, size=24, dry_run=True),
         ["reconstruct", p, "--size", "24", "--out", o / "x.npy"]),
        (vct.reconstruct(pr.projections, pr.geometry, size=16, method="sirt", iterations=3,
                         dry_run=True),
         ["reconstruct", p, "--size", "16", "--method", "sirt", "--iterations", "3", "--out",
          o / "x.npy"]),
        (voxlab.fvr(v, kernel="lanczos3", padding=2, view="+x", dry_run=True),
         ["fvr", path, "--kernel", "lanczos3", "--padding", "2", "--view", "+x", "--out",
          o / "f.npy"]),
        (voxlab.d2vr("phantom:shepp-logan-modified", angles=16, detector=16, grid=16, size=24,
                     dry_run=True),
         ["d2vr", "phantom:shepp-logan-modified", "--angles", "16", "--detector", "16",
          "--grid", "16", "--size", "24", "--out", o / "d.npy"]),
        (voxlab.d2vr(pr, grid=16, size=24, dry_run=True),
         ["d2vr", p, "--grid", "16", "--size", "24", "--out", o / "d.npy"]),
        (voxlab.adaptive("phantom:marschner-lobb:24", size=24, runs=1, dry_run=True),
         ["adaptive", "phantom:marschner-lobb:24", "--size", "24", "--runs", "1",
          "--out", o / "a"]),
        (voxlab.process(v, "gaussian", sigma=1.5, dry_run=True),
         ["process", path, "--op", "gaussian", "--sigma", "1.5", "--out", o / "g.nrrd"]),
        (voxlab.resample(v, dims=(30, 20, 10), dry_run=True),
         ["process", path, "--op", "resample", "--dims", "30,20,10", "--out", o / "s.nrrd"]),
    ]
    for plan, args in cases:
        assert isinstance(plan, voxlab.MemoryPlan), args[0]
        assert str(plan) == cli_plan(cli, *args), args
        assert plan.device is None and plan.writes == [] and plan.split == [], args
        assert plan.text.startswith(f"dry run: {plan.job} on {plan.backend} "), args
    assert not any(f.name != "v.nrrd" and f.name != "p.npy" and f.suffix != ".json"
                   for f in tmp_path.iterdir()), sorted(f.name for f in tmp_path.iterdir())


def test_a_renders_plan_counts_the_volume_and_the_image_it_would_hold():
    # render's plan on the CPU: the volume as one float per voxel (f64 for the oracle,
    # f32 for cpu-f32) and the image (f64 per channel) with its u32 sample counts.
    a = np.zeros((10, 12, 14), np.uint16)
    for backend, real in (("cpu", 8), ("cpu-f32", 4)):
        for mode, ch in (("mip", 1), ("dvr", 4)):
            plan = voxlab.render(a, mode=mode, width=40, height=30, backend=backend,
                                 dry_run=True)
            assert plan.host_bytes == 10 * 12 * 14 * real + 40 * 30 * (8 * ch + 4)
            assert plan.job == f"render {mode}"


@pytest.mark.parametrize("job", ["render", "fvr", "process", "project", "reconstruct", "d2vr"])
def test_a_dry_run_raises_what_the_run_raises(job):
    g = {"beam": "parallel", "cols": 8, "rows": 1, "du": 1.0, "dv": 1.0,
         "angles_deg": [0.0, 45.0, 90.0]}
    calls = {
        "render": lambda **k: voxlab.render("phantom:sphere:8", width=0, **k),
        "fvr": lambda **k: voxlab.fvr("phantom:sphere:8", kernel="bicubic", **k),
        "process": lambda **k: voxlab.process("phantom:sphere:8", "median", size=4, **k),
        "project": lambda **k: vct.project("phantom:sphere:8", beam="fan", **k),
        # Four views where the geometry has three.
        "reconstruct": lambda **k: vct.reconstruct(np.zeros((8, 4)), g, **k),
        "d2vr": lambda **k: voxlab.d2vr(np.zeros((3, 1, 7)), geometry=g, grid=8, **k),
    }
    with pytest.raises(voxlab.VoxlabError) as run:
        calls[job]()
    with pytest.raises(type(run.value)) as dry:
        calls[job](dry_run=True)
    assert str(dry.value) == str(run.value)


def test_a_dry_run_computes_nothing():
    # A 96³ oracle DVR at 1920 × 1080 would take minutes on a small machine; its plan
    # is the loaded phantom and arithmetic: no rendering stage is reported, where a run
    # reports one.
    def stages(**options):
        seen = set()
        r = voxlab.render("phantom:marschner-lobb:96", progress=lambda s, d, t: seen.add(s),
                          **options)
        return r, {s.split(" (")[0] for s in seen}

    plan, seen = stages(width=1920, height=1080, dry_run=True)
    assert plan.host_bytes == 96 ** 3 * 8 + 1920 * 1080 * 36
    assert "rendering" not in seen, seen
    _, seen = stages(width=8, height=6)
    assert "rendering" in seen, seen


SPLIT_SCRIPT = """
import json, sys, numpy as np, voxlab, voxlab.ct as vct
pr = vct.project("phantom:shepp-logan", beam="cone", angles=12, cols=20, rows=16)
plans = [
    voxlab.render("phantom:marschner-lobb:64", mode="mip", width=48, height=40,
                  backend="gpu", dry_run=True),
    vct.reconstruct(pr.projections, pr.geometry, size=64, backend="gpu", dry_run=True),
]
print(json.dumps([dict(p.__dict__) for p in plans]))
"""


def test_a_gpu_dry_run_says_how_it_would_split(tmp_path, cli, gpu, monkeypatch):
    # Lowered limits (read when a process opens its device): a fresh interpreter, and
    # the command line under the same environment.
    monkeypatch.setenv("VOXLAB_GPU_MAX_TEXTURE_3D", "32")
    monkeypatch.setenv("VOXLAB_GPU_MAX_BINDING", "64KiB")
    r = subprocess.run([sys.executable, "-c", SPLIT_SCRIPT], capture_output=True, text=True,
                       env=dict(os.environ))
    assert r.returncode == 0, r.stderr
    render, recon = json.loads(r.stdout)
    for plan in (render, recon):
        d = plan["device"]
        assert d["max_texture_3d"] == 32 and d["max_binding_bytes"] == 64 * 1024, d
        assert len(d["lowered"]) == 2 and d["peak_bytes"] > 0, d
        assert plan["split"], plan
    assert "bricks (the [64, 64, 64] volume exceeds the 3-D texture limit of 32" in \
        render["split"][0], render["split"]
    assert any("slabs" in line for line in recon["split"]), recon["split"]
    # The same plans as the command line's.
    p, _ = cone(tmp_path, cli)
    assert render["text"] == cli_plan(
        cli, "render", "phantom:marschner-lobb:64", "--mode", "mip", "--width", "48",
        "--height", "40", "--backend", "gpu", "--out", tmp_path / "r.png")
    assert recon["text"] == cli_plan(
        cli, "reconstruct", p, "--size", "64", "--backend", "gpu", "--out", tmp_path / "x.npy")


def test_compares_plans_are_the_oracles_and_the_gpus(tmp_path, cli, gpu):
    cpu, dev = voxlab.compare("phantom:spheres:24", width=40, height=30, dry_run=True)
    assert cpu.backend.startswith("cpu") and cpu.device is None
    assert dev.device is not None and dev.device["adapter"] in dev.backend
    assert str(cpu) + str(dev) == cli_plan(
        cli, "compare", "phantom:spheres:24", "--width", "40", "--height", "30",
        "--out-dir", tmp_path / "c")
    # With an image of one's own, only the oracle renders.
    (only,) = voxlab.compare("phantom:spheres:24", np.zeros((30, 40, 4)), width=40,
                             height=30, dry_run=True)
    assert str(only) == str(cpu)
