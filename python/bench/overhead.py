"""Python overhead over the same Rust call (a benchmark, not a test): the wall-clock
time of a voxlab call from Python against the seconds its job spent in Rust on the
worker thread (``voxlab._voxlab._last_job_seconds()``: the closure that calls the
library, none of the array conversions around it). Prints a markdown table.

    python python/bench/overhead.py [--runs 5]
"""

import argparse
import os
import platform
import statistics
import time

import numpy as np

import voxlab
import voxlab.transform as vt
from voxlab import _voxlab


def measure(f, runs):
    walls, rusts = [], []
    f()  # warm-up
    for _ in range(runs):
        t = time.perf_counter()
        f()
        walls.append(time.perf_counter() - t)
        rusts.append(_voxlab._last_job_seconds())
    return statistics.median(walls), statistics.median(rusts)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--runs", type=int, default=5)
    a = p.parse_args()
    rng = np.random.default_rng(0)
    n = 256
    theta = np.linspace(0, 180, 180, endpoint=False)
    sino = rng.random((n, 180))
    vol = voxlab.phantom("shepp-logan-modified", 256)
    cases = []
    for backend in ("cpu", "cpu-f32"):
        cases.append((f"iradon 256² (180 angles), {backend}",
                      lambda b=backend: vt.iradon(sino, theta, backend=b)))
    for backend in ("cpu-f32", "cpu"):
        cases.append((f"render 256³ → 512² (DVR), {backend}",
                      lambda b=backend: voxlab.render(vol, width=512, height=512, backend=b)))
    # A prepared scene (Renderer.prepare): one frame of an orbit, the volume converted
    # once before the loop.
    scene = voxlab.Renderer("cpu-f32").prepare(vol, width=512, height=512)
    angle = iter(range(0, 10**6, 7))
    cases.append(("prepared frame 256³ → 512² (DVR, orbit), cpu-f32",
                  lambda: scene.render(azimuth=float(next(angle)))))
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, {platform.platform()}")
    print("| call | Python wall (median) | Rust job (median) | overhead |")
    print("|---|---|---|---|")
    for name, f in cases:
        w, r = measure(f, a.runs)
        print(f"| {name} | {w * 1e3:.1f} ms | {r * 1e3:.1f} ms | {100 * (w - r) / r:+.2f} % |",
              flush=True)


if __name__ == "__main__":
    main()
