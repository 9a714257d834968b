#!/usr/bin/env python3
"""cuFFT (through CuPy) on the sizes of voxlab's FFT suite: complex64, forward.

The GPU peer for `cargo bench --bench fft` / `voxlab fft --backend gpu`: the same
shapes (2-D 256², 512², 1024², 1000²; 3-D 64³, 128³, 256³, 100³), the same input (random complex
values, uniform in [-1, 1) in both parts, unnormalised forward transform over every
axis), and the same two times:

- kernel: `cupy.fft.fftn` on a device-resident array, timed with `cupy.cuda.Event`
  pairs around the call (the cuFFT plan is made and cached by the warm-up call, so
  planning is not timed; the output allocation comes from CuPy's memory pool);
- e2e: host-to-device copy + `fftn` + device-to-host copy, timed the same way
  (the host arrays are ordinary pageable numpy arrays, as voxlab's are).

Each is the median of `--runs` runs after one warm-up. The warm-up's result is
checked against numpy's f64 `fftn` of the same (complex64) input: relative L2
error `‖X − X_ref‖₂ / ‖X_ref‖₂`, with the same pass bound as voxlab's f32 GPU FFT,
`1e-6 · log2 N`.

Standalone: Python 3 standard library, numpy and cupy only. Run on a machine with an
NVIDIA GPU:

    python3 scripts/peers/gpu_fft_peers.py --runs 20 --out gpu-fft-peers.json

It prints a Markdown table on stdout and writes every number to the JSON file.
"""

import argparse
import json
import math
import platform
import statistics
import sys
import time

import numpy as np

try:
    import cupy as cp
except ImportError as e:  # pragma: no cover - depends on the machine
    sys.exit(f"gpu_fft_peers.py needs CuPy and an NVIDIA GPU: {e}")

# voxlab's FFT suite (`voxlab bench`, full): 2-D and 3-D power-of-two shapes, and
# 1000² and 100³, lengths voxlab's GPU FFT takes by Bluestein's algorithm.
SHAPES = ["256x256", "512x512", "1024x1024", "1000x1000",
          "64x64x64", "128x128x128", "256x256x256", "100x100x100"]


def parse_shape(s):
    shape = tuple(int(x) for x in s.lower().split("x"))
    if not shape or any(n <= 0 for n in shape):
        raise argparse.ArgumentTypeError(f"bad shape {s!r}")
    return shape


def random_complex64(shape, seed):
    rng = np.random.default_rng(seed)
    re = rng.uniform(-1.0, 1.0, shape)
    im = rng.uniform(-1.0, 1.0, shape)
    return (re + 1j * im).astype(np.complex64)


def event_time_ms(fn, runs):
    """Median over `runs` of the GPU time between two events around `fn()`, in ms."""
    start, stop = cp.cuda.Event(), cp.cuda.Event()
    times = []
    for _ in range(runs):
        start.record()
        fn()
        stop.record()
        stop.synchronize()
        times.append(cp.cuda.get_elapsed_time(start, stop))
    return statistics.median(times), times


def bench_shape(shape, runs, seed):
    n = int(np.prod(shape))
    axes = tuple(range(len(shape)))
    host = random_complex64(shape, seed)
    dev = cp.asarray(host)

    # Warm-up (makes and caches the cuFFT plan) and the checked result.
    out = cp.fft.fftn(dev, axes=axes)
    cp.cuda.get_current_stream().synchronize()
    got = cp.asnumpy(out)
    assert got.dtype == np.complex64, got.dtype
    ref = np.fft.fftn(host.astype(np.complex128), axes=axes)
    rel_l2 = float(np.linalg.norm(got - ref) / np.linalg.norm(ref))
    bound = 1e-6 * math.log2(n)
    del out, got, ref

    kernel_ms, kernel_all = event_time_ms(lambda: cp.fft.fftn(dev, axes=axes), runs)

    def e2e():
        d = cp.asarray(host)
        return cp.asnumpy(cp.fft.fftn(d, axes=axes))

    e2e()  # warm-up of the copy path
    e2e_ms, e2e_all = event_time_ms(e2e, runs)

    flops = 5.0 * n * math.log2(n)
    return {
        "shape": "x".join(map(str, shape)),
        "dims": len(shape),
        "n": n,
        "kernel_median_ms": kernel_ms,
        "kernel_runs_ms": kernel_all,
        "e2e_median_ms": e2e_ms,
        "e2e_runs_ms": e2e_all,
        "gflops_kernel": flops / (kernel_ms * 1e-3) / 1e9,
        "gbps_kernel": 2 * 8 * n / (kernel_ms * 1e-3) / 1e9,
        "rel_l2_vs_numpy_f64": rel_l2,
        "bound": bound,
        "passed": rel_l2 <= bound,
    }


def device_info():
    dev = cp.cuda.Device()
    props = cp.cuda.runtime.getDeviceProperties(dev.id)
    name = props["name"]
    if isinstance(name, bytes):
        name = name.decode(errors="replace")
    info = {
        "gpu": name,
        "gpu_memory_bytes": int(props.get("totalGlobalMem", 0)),
        "compute_capability": f"{props.get('major')}.{props.get('minor')}",
        "cuda_runtime": cp.cuda.runtime.runtimeGetVersion(),
        "cuda_driver": cp.cuda.runtime.driverGetVersion(),
        "cupy": cp.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
        "host": platform.node(),
        "platform": platform.platform(),
    }
    try:
        info["cufft"] = cp.cuda.cufft.getVersion()
    except Exception as e:  # older CuPy: not exposed
        info["cufft"] = f"unknown ({type(e).__name__})"
    return info


def label(shape):
    s = "x".join(map(str, shape))
    return f"{len(shape)}d {shape[0]}{'²' if len(shape) == 2 else '³'}" \
        if len(set(shape)) == 1 and len(shape) in (2, 3) else s


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("shapes", nargs="*", type=parse_shape,
                   help=f"shapes, last axis fastest (default: {' '.join(SHAPES)})")
    p.add_argument("--runs", type=int, default=20, help="timed runs per case (default 20)")
    p.add_argument("--seed", type=int, default=0x5EED)
    p.add_argument("--out", help="write every number to this JSON file")
    args = p.parse_args()
    if args.runs < 1:
        p.error("--runs must be at least 1")
    shapes = args.shapes or [parse_shape(s) for s in SHAPES]

    info = device_info()
    print(f"cuFFT {info['cufft']} via CuPy {info['cupy']} on {info['gpu']} "
          f"(CUDA runtime {info['cuda_runtime']}, driver {info['cuda_driver']}); "
          f"complex64 forward, median of {args.runs} runs after 1 warm-up, ms",
          file=sys.stderr)

    cases = []
    print("| case | N | cuFFT kernel ms | cuFFT e2e ms | GFLOP/s (kernel) | GB/s (kernel) "
          "| rel L2 vs numpy f64 |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for shape in shapes:
        started = time.perf_counter()
        c = bench_shape(shape, args.runs, args.seed)
        c["wall_s"] = time.perf_counter() - started
        cases.append(c)
        print(f"| {label(shape)} | {c['n']} | {c['kernel_median_ms']:.3f} | "
              f"{c['e2e_median_ms']:.3f} | {c['gflops_kernel']:.1f} | "
              f"{c['gbps_kernel']:.1f} | {c['rel_l2_vs_numpy_f64']:.1e}"
              f"{'' if c['passed'] else ' FAIL'} |", flush=True)
        cp.get_default_memory_pool().free_all_blocks()
        cp.fft.config.get_plan_cache().clear()

    report = {
        "what": "cuFFT (cupy.fft.fftn) complex64 forward, unnormalised; kernel = "
                "device-resident fftn between cuda Events; e2e = H2D + fftn + D2H; "
                "medians after 1 warm-up; rel L2 against numpy f64 fftn of the same input",
        "runs": args.runs,
        "seed": args.seed,
        "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "machine": info,
        "cases": cases,
    }
    if args.out:
        with open(args.out, "w") as f:
            json.dump(report, f, indent=2)
        print(f"wrote {args.out}", file=sys.stderr)
    if not all(c["passed"] for c in cases):
        sys.exit(3)


if __name__ == "__main__":
    main()
