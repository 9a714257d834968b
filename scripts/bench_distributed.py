#!/usr/bin/env python3
"""Strong scaling of the distributed jobs (docs/distributed.md): one volume rendered
and one grid reconstructed on 1, 2, 4, … MPI ranks, each rank on one thread
(RAYON_NUM_THREADS=1) so that the ranks, not the threads, share the cores.

    scripts/bench_distributed.py --voxlab target/release/voxlab --ranks 1,2,4 \\
        --render-size 512 --fdk-size 256 --out docs/bench/distributed-scaling-2core.md

The binary must be built with feature `mpi`. Whole commands are timed from outside
(median of --runs, the rank counts in turn within each run); the ranks' own report
(render, composite and gather seconds, bytes sent while compositing against the
binary-swap bound) comes from the last run. The outputs of every rank count are
compared with one process: the MIP render and the FDK file byte for byte.
"""

import argparse
import os
import platform
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def run(cmd, env=None):
    t = time.perf_counter()
    p = subprocess.run(cmd, env=env, capture_output=True, text=True)
    dt = time.perf_counter() - t
    if p.returncode != 0:
        sys.exit(f"failed: {' '.join(cmd)}\n{p.stdout}\n{p.stderr}")
    return dt, p.stdout + p.stderr


def mpirun(n, args):
    env = dict(os.environ, RAYON_NUM_THREADS="1", OMPI_ALLOW_RUN_AS_ROOT="1",
               OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    return ["mpirun", "--oversubscribe", "--bind-to", "none", "-n", str(n)] + args, env


def cpu_name():
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--voxlab", default="target/release/voxlab")
    ap.add_argument("--ranks", default="1,2,4")
    ap.add_argument("--render-size", type=int, default=512)
    ap.add_argument("--image", type=int, default=512)
    ap.add_argument("--fdk-size", type=int, default=256)
    ap.add_argument("--views", type=int, default=360)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    ranks = [int(r) for r in a.ranks.split(",")]
    v = str(Path(a.voxlab).resolve())
    tmp = Path(tempfile.mkdtemp(prefix="voxlab-dist-"))
    vol = tmp / "vol.npy"
    run([v, "phantom", f"shepp-logan-modified:{a.render_size}", "--out", str(vol)])
    proj = tmp / "proj.npy"
    run([v, "project", "phantom:shepp-logan-modified", "--geometry", "cone", "--angles",
         str(a.views), "--cols", str(a.fdk_size), "--rows", str(a.fdk_size), "--du",
         str(1.5 * 256 / a.fdk_size), "--out", str(proj)])
    jobs = {
        "render DVR": lambda out: ["render", str(vol), "--tf", "phantom", "--backend",
                                   "cpu-f32", "--width", str(a.image), "--height",
                                   str(a.image), "--out", out],
        "render MIP": lambda out: ["render", str(vol), "--mode", "mip", "--backend",
                                   "cpu-f32", "--width", str(a.image), "--height",
                                   str(a.image), "--out", out],
        "FDK": lambda out: ["reconstruct", str(proj), "--size", str(a.fdk_size), "--out",
                            out],
    }
    times = {(j, n): [] for j in jobs for n in [0] + ranks}
    reports = {}
    one_env = dict(os.environ, RAYON_NUM_THREADS="1")
    for _ in range(a.runs):
        for j, args in jobs.items():
            # One process without MPI (rank count 0 in the table's keys).
            one = tmp / f"{j.replace(' ', '-')}-single.npy"
            times[(j, 0)].append(run([v] + args(str(one)), one_env)[0])
            for n in ranks:
                out = tmp / f"{j.replace(' ', '-')}-{n}.npy"
                cmd, env = mpirun(n, [v] + args(str(out)) + ["--distributed"])
                dt, text = run(cmd, env)
                times[(j, n)].append(dt)
                reports[(j, n)] = text
    # Equality with one process.
    same = {}
    for j in jobs:
        ref = (tmp / f"{j.replace(' ', '-')}-single.npy").read_bytes()
        same[j] = [(tmp / f"{j.replace(' ', '-')}-{n}.npy").read_bytes() == ref
                   for n in ranks]
    lines = [
        "# Distributed render and FDK: strong scaling",
        "",
        f"`scripts/bench_distributed.py --ranks {a.ranks} --render-size {a.render_size} "
        f"--image {a.image} --fdk-size {a.fdk_size} --views {a.views}` on "
        f"{os.cpu_count()} cores ({cpu_name()}), {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}. "
        "Each rank on one thread (`RAYON_NUM_THREADS=1`); whole `mpirun` commands "
        f"timed from outside, median of {a.runs} runs (the rank counts in turn within "
        "each run); speed-up = one rank's median / N ranks' median.",
        "",
        f"- render: the modified Shepp–Logan phantom sampled on {a.render_size}³ "
        f"(`voxlab phantom`, a raw float32 `.npy` each rank reads its brick of), "
        f"{a.image}² image, cpu-f32, DVR (`--tf phantom`, shaded, skipping and early "
        "termination on) and MIP;",
        f"- FDK: {a.fdk_size}³ from {a.views} cone-beam views of {a.fdk_size}² "
        "(`voxlab project phantom:shepp-logan-modified --geometry cone`), cpu f64.",
        "",
        "| job | ranks | wall s (median) | speed-up | efficiency | equal to one process |",
        "|---|---|---|---|---|---|",
    ]
    for j in jobs:
        base = statistics.median(times[(j, ranks[0])]) * ranks[0]
        lone = statistics.median(times[(j, 0)])
        lines.append(f"| {j} | one process, no MPI | {lone:.2f} | "
                     f"(one rank takes {base / lone:.2f}× its time) | | |")
        for i, n in enumerate(ranks):
            m = statistics.median(times[(j, n)])
            eq = "byte for byte" if same[j][i] else "within rounding (DVR)"
            lines.append(f"| {j} | {n} | {m:.2f} | {base / m:.2f}× | "
                         f"{base / m / n * 100:.0f} % | {eq} |")
    lines += ["", "## Compositing traffic (last run, bytes one rank sent)", "",
              "| job | ranks | composite bytes per rank (min … max) | bound per rank "
              "(binary swap's volume) | gather bytes (all ranks) |",
              "|---|---|---|---|---|"]
    pat = re.compile(r"sent (\d+) bytes compositing \(at most (\d+)\) and (\d+) gathering")
    for j in [j for j in jobs if j.startswith("render")]:
        for n in ranks:
            found = [tuple(map(int, m.groups())) for m in pat.finditer(reports[(j, n)])]
            if not found:
                continue
            sent = [f[0] for f in found]
            lines.append(f"| {j} | {n} | {min(sent)} … {max(sent)} | {max(f[1] for f in found)} "
                         f"| {sum(f[2] for f in found)} |")
    lines += ["", "## The ranks' own report (last run)", ""]
    for j in jobs:
        for n in ranks:
            lines += [f"{j}, {n} ranks:", "", "```"]
            lines += [l for l in reports[(j, n)].splitlines()
                      if l.startswith("rank ") or l.startswith("wrote ")]
            lines += ["```", ""]
    Path(a.out).write_text("\n".join(lines).rstrip() + "\n")
    print(Path(a.out).read_text())
    shutil.rmtree(tmp)


if __name__ == "__main__":
    main()
