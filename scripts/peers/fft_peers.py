#!/usr/bin/env python3
"""voxlab's CPU FFT against FFTW, one thread each, complex64 (f32), forward.

FFTW runs through pyFFTW with FFTW_MEASURE planning (planning not timed), one
thread, out of place on 64-byte-aligned arrays. voxlab runs as its own binary:

    RAYON_NUM_THREADS=1 target/release/voxlab fft --backend cpu --runs R --json F SHAPE

and its `cpu-f32` case is read from the JSON (the median of R runs after one warm-up,
the transform only; voxlab checks the result against the exact DFT or its f64 FFT).
FFTW is timed the same way: one warm-up, then the median of R runs of `execute()`.

Set up (once) and run:

    python3 -m venv /tmp/venv-fft
    /tmp/venv-fft/bin/pip install -r scripts/peers/requirements-fft.txt
    cargo build --release
    /tmp/venv-fft/bin/python scripts/peers/fft_peers.py --runs 5 \
        256x256x256 512x512 1024x1024 2048x2048

It prints a Markdown table (the one in docs/bench/fft-peers.md).
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np
import pyfftw


def fftw_median(shape, runs):
    a = pyfftw.empty_aligned(shape, dtype="complex64", n=64)
    b = pyfftw.empty_aligned(shape, dtype="complex64", n=64)
    plan = pyfftw.FFTW(
        a,
        b,
        axes=tuple(range(len(shape))),
        direction="FFTW_FORWARD",
        flags=("FFTW_MEASURE",),
        threads=1,
    )
    rng = np.random.default_rng(0x5EED)
    # FFTW_MEASURE overwrites the arrays while planning: fill afterwards.
    a[...] = (rng.uniform(-1, 1, shape) + 1j * rng.uniform(-1, 1, shape)).astype("complex64")
    plan.execute()  # warm-up
    reference = np.fft.fftn(a.astype("complex128"))
    err = float(np.linalg.norm(b - reference) / np.linalg.norm(reference))
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        plan.execute()
        times.append(time.perf_counter() - t)
    return statistics.median(times), err


def voxlab_median(binary, shape, runs):
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "fft.json")
        env = dict(os.environ, RAYON_NUM_THREADS="1")
        subprocess.run(
            [binary, "fft", "--backend", "cpu", "--runs", str(runs), "--json", out,
             "x".join(map(str, shape))],
            check=True, env=env, stdout=subprocess.DEVNULL,
        )
        with open(out) as f:
            report = json.load(f)
    case = next(c for c in report["cases"] if c["backend"] == "cpu-f32")
    assert report["threads"] == 1, report["threads"]
    return case["median_s"], case["rel_l2"], case["passed"]


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("shapes", nargs="+", help="e.g. 256x256x256 1024x1024")
    p.add_argument("--runs", type=int, default=5)
    p.add_argument("--voxlab", default="target/release/voxlab")
    args = p.parse_args()
    pyfftw.config.NUM_THREADS = 1
    print(f"FFTW {'.'.join(map(str, pyfftw.__version__.split('.')[:3]))} via pyFFTW "
          f"(FFTW_MEASURE, 1 thread) vs voxlab cpu::fft::fft_nd (rustfft, "
          f"RAYON_NUM_THREADS=1); complex64 forward; median of {args.runs} runs after "
          "1 warm-up, ms", file=sys.stderr)
    print("| shape | N | FFTW ms | voxlab f32 ms | voxlab / FFTW | FFTW rel L2 | voxlab rel L2 |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for s in args.shapes:
        shape = tuple(int(x) for x in s.split("x"))
        n = int(np.prod(shape))
        tf, ef = fftw_median(shape, args.runs)
        tv, ev, ok = voxlab_median(args.voxlab, shape, args.runs)
        print(f"| {s} | {n} | {tf * 1e3:.1f} | {tv * 1e3:.1f} | {tv / tf:.2f}× | "
              f"{ef:.1e} | {ev:.1e}{'' if ok else ' FAIL'} |", flush=True)


if __name__ == "__main__":
    main()
