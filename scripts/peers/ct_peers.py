#!/usr/bin/env python3
"""Accuracy and speed of the CT peers (scikit-image iradon, RTK FDK) on voxlab's exact
Shepp-Logan inputs; writes docs/bench/ct-peers.{md,json}.

Usage (from the repository root):

    python3 -m venv /tmp/venv-ct
    /tmp/venv-ct/bin/pip install -r scripts/peers/requirements-ct.txt
    cargo build --release --example ct_export
    target/release/examples/ct_export /tmp/ct-peers
    /tmp/venv-ct/bin/python scripts/peers/ct_peers.py /tmp/ct-peers [--no-big]

The inputs (see examples/ct_export.rs) are exact line integrals of
Phantom::shepp_logan() (Kak & Slaney intensities, 256 mm cube) placed by
ct::phantom_to_ct, and the phantom's exact values on the reconstruction grids.
Errors are RMS of (reconstruction - truth): 2-D inside the reconstruction circle
(col-128)^2 + (row-128)^2 <= 128^2, 3-D inside the brain mask (voxel centres inside the
phantom's primitive 1). Timings are the median of 3 wall-clock runs.
"""

import argparse
import json
import os
import platform
import statistics
import sys
import time

import numpy as np
import skimage
from scipy.ndimage import binary_erosion
from skimage.transform import iradon

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from make_ct_fixtures import rtk_fdk, versions  # noqa: E402

FILTERS = ["ramp", "shepp-logan", "cosine", "hamming", "hann"]


def median_time(fn, runs=3):
    times, out = [], None
    for _ in range(runs):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), times, out


def rms(a):
    return float(np.sqrt(np.mean(np.square(a))))


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
    return {"cpu": model, "cores": os.cpu_count(), "os": platform.platform()}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("inputs", nargs="?", default="/tmp/ct-peers")
    ap.add_argument("--out", default="docs/bench")
    ap.add_argument("--no-big", action="store_true", help="skip the 512² / 256³ timings")
    ap.add_argument("--md-only", action="store_true",
                    help="rewrite ct-peers.md from an existing ct-peers.json")
    args = ap.parse_args()
    if args.md_only:
        res = json.load(open(os.path.join(args.out, "ct-peers.json")))
        write_md(res, os.path.join(args.out, "ct-peers.md"))
        return
    d = args.inputs
    meta = json.load(open(os.path.join(d, "export.json")))
    res = {"inputs": meta, "versions": versions(), "machine": machine()}

    # ---------------- 2-D: scikit-image iradon ----------------
    sino = np.load(os.path.join(d, "sino2d.npy"))
    theta = np.loadtxt(os.path.join(d, "theta2d.txt"))
    truth2 = np.load(os.path.join(d, "truth2d.npy"))
    n = truth2.shape[0]
    r, c = np.mgrid[:n, :n] - n // 2
    circle = r * r + c * c <= (n // 2) ** 2
    brain2 = np.load(os.path.join(d, "brain2d.npy")).astype(bool)
    masks2 = {"circle": circle, "brain": brain2}
    for k in (1, 2):
        masks2[f"brain_eroded{k}"] = binary_erosion(brain2, iterations=k)
    res["skimage"] = {"pixels": {k: int(v.sum()) for k, v in masks2.items()}, "filters": {}}
    for f in FILTERS:
        med, times, rec = median_time(
            lambda f=f: iradon(sino, theta=theta, filter_name=f, interpolation="linear",
                               circle=True)
        )
        err = rec - truth2
        res["skimage"]["filters"][f] = {
            **{f"rms_{k}": rms(err[m]) for k, m in masks2.items()},
            "max_abs_circle": float(np.max(np.abs(err[circle]))),
            "seconds_median": med,
            "seconds": times,
        }
        print(f"skimage iradon {f:12s} rms {rms(err[circle]):.5f}  {med:.2f} s", flush=True)
    if not args.no_big:
        # Timing only: any 512 x 402 sinogram costs the same; use the 256-bin one
        # resampled to 512 bins.
        x = np.arange(512) / 2.0 - 0.25
        big = np.stack([np.interp(x, np.arange(n), sino[:, k]) for k in range(len(theta))], 1)
        med, times, _ = median_time(
            lambda: iradon(big, theta=theta, filter_name="ramp", interpolation="linear",
                           circle=True)
        )
        res["skimage"]["timing_512"] = {"seconds_median": med, "seconds": times,
                                        "sinogram": [512, len(theta)], "output": [512, 512]}
        print(f"skimage iradon 512^2 from 402 angles: {med:.2f} s", flush=True)

    # ---------------- 3-D: RTK FDK ----------------
    cone = meta["cone"]
    vol = meta["volume"]
    proj = np.load(os.path.join(d, "cone_proj.npy"))
    truth3 = np.load(os.path.join(d, "truth3d.npy"))
    brain = np.load(os.path.join(d, "brain3d.npy")).astype(bool)
    angles = [k * cone["range_deg"] / cone["angles"] for k in range(cone["angles"])]
    n3, sp = vol["shape_zyx"][0], vol["spacing_mm"]
    masks3 = {"brain": brain}
    for k in (1, 2):
        masks3[f"brain_eroded{k}"] = binary_erosion(brain, iterations=k)
    res["rtk"] = {"voxels": {k: int(v.sum()) for k, v in masks3.items()}, "fdk": {}}
    for name, hann in (("ramp", 0.0), ("hann", 1.0)):
        med, times, rec = median_time(
            lambda hann=hann: rtk_fdk(proj, angles, n3, sp, hann=hann, du=cone["du"],
                                      dv=cone["dv"], sid=cone["sid"], sdd=cone["sdd"])
        )
        err = rec - truth3
        mid = err[:, n3 // 2, :]  # the central axial slice Y = -1 mm
        res["rtk"]["fdk"][name] = {
            "hann_cut": hann,
            **{f"rms_{k}": rms(err[m]) for k, m in masks3.items()},
            "max_abs_brain": float(np.max(np.abs(err[brain]))),
            "rms_all": rms(err),
            "rms_brain_central_slice": rms(mid[brain[:, n3 // 2, :]]),
            "seconds_median": med,
            "seconds": times,
        }
        print(f"RTK FDK {name}: rms brain {rms(err[brain]):.5f}  {med:.2f} s", flush=True)
    if not args.no_big:
        big = np.ones((180, 256, 256), dtype=np.float32)  # timing only
        big_angles = [k * 2.0 for k in range(180)]
        t = time.perf_counter()
        rtk_fdk(big, big_angles, 256, 1.0, du=1.5, dv=1.5)
        first = time.perf_counter() - t
        print(f"RTK FDK 256^3 from 180 x 256^2: first run {first:.1f} s", flush=True)
        if first < 90:
            med, times, _ = median_time(
                lambda: rtk_fdk(big, big_angles, 256, 1.0, du=1.5, dv=1.5), runs=2
            )
            times = [first] + times
            med = statistics.median(times)
        else:
            times, med = [first], first
        res["rtk"]["timing_256"] = {"seconds_median": med, "seconds": times,
                                    "projections": [180, 256, 256], "volume": [256] * 3,
                                    "sid": 1000.0, "sdd": 1500.0, "du": 1.5,
                                    "spacing_mm": 1.0}
        print(f"RTK FDK 256^3: median {med:.1f} s", flush=True)

    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "ct-peers.json"), "w") as fh:
        json.dump(res, fh, indent=1)
        fh.write("\n")
    write_md(res, os.path.join(args.out, "ct-peers.md"))
    print("wrote", os.path.join(args.out, "ct-peers.{md,json}"))


def write_md(res, path):
    v, m = res["versions"], res["machine"]
    sk, rt = res["skimage"], res["rtk"]
    lines = [
        "# CT peers: scikit-image and RTK on voxlab's exact inputs",
        "",
        "How accurate and how fast the two reference CT codes are on the same inputs voxlab's",
        "CT reconstructions get: exact line integrals of `Phantom::shepp_logan()` (Kak & Slaney",
        "intensities: skull 1, brain 0.02, ventricles 0, small features 0.03; 256 mm cube),",
        "placed in the CT frame by `ct::phantom_to_ct`, and the phantom's exact values at the",
        "reconstruction grid's pixel/voxel centres as the truth. voxlab's accuracy target is",
        "\"within 5% of the peer's RMS error\" on exactly these inputs.",
        "",
        "## Commands",
        "",
        "```sh",
        "python3 -m venv /tmp/venv-ct",
        "/tmp/venv-ct/bin/pip install -r scripts/peers/requirements-ct.txt",
        "cargo build --release --example ct_export",
        "target/release/examples/ct_export /tmp/ct-peers",
        "/tmp/venv-ct/bin/python scripts/peers/ct_peers.py /tmp/ct-peers",
        "```",
        "",
        f"Versions: Python {v['python']}, numpy {v['numpy']}, scikit-image {v['scikit-image']}, "
        f"ITK {v.get('itk', '-')}, itk-rtk {v.get('itk-rtk', '-')} (RTK's CPU filters, float32).",
        f"Machine: {m['cpu']}, {m['cores']} cores shared with other jobs (timings are",
        "indicative: median of 3 wall-clock runs), Linux.",
        "",
        "## 2-D parallel beam: scikit-image `iradon`",
        "",
        "Geometry `Geometry::parallel_skimage(256, Geometry::even_angles(402, 180))`: 256 bins",
        "of 1 mm, centre bin 128, 402 angles over [0°, 180°). Sinogram `(256, 402)`;",
        "`iradon(sino, theta, filter_name=f, interpolation='linear', circle=True)` → 256²",
        "with pixel `(row, col)` at `X = col − 128`, `Z = row − 128` mm. Errors: RMS over the",
        f"reconstruction circle `(col−128)² + (row−128)² ≤ 128²` ({sk['pixels']['circle']} "
        "pixels; the target metric), over the brain (pixel centres inside primitive 1,",
        f"{sk['pixels']['brain']} pixels) and over the brain eroded by 1 and 2 pixels",
        "(`scipy.ndimage.binary_erosion`, 4-connected; "
        f"{sk['pixels']['brain_eroded1']} and {sk['pixels']['brain_eroded2']} pixels).",
        "",
        "| filter | RMS circle | 1.05 × RMS circle | max abs circle | RMS brain | RMS brain −1 px | RMS brain −2 px | time 256² (s) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for f, r in sk["filters"].items():
        lines.append(f"| {f} | {r['rms_circle']:.5f} | {1.05 * r['rms_circle']:.5f} | "
                     f"{r['max_abs_circle']:.4f} | {r['rms_brain']:.5f} | "
                     f"{r['rms_brain_eroded1']:.5f} | {r['rms_brain_eroded2']:.5f} | "
                     f"{r['seconds_median']:.2f} |")
    if "timing_512" in sk:
        lines += ["", f"`iradon` (ramp) 512² from 402 angles × 512 bins: "
                      f"{sk['timing_512']['seconds_median']:.2f} s (median of 3)."]
    lines += [
        "",
        "## 3-D circular cone beam: RTK FDK",
        "",
        "Geometry `Geometry::cone_rtk(1000, 1500, 160, 160, 3, 3, even_angles(180, 360))`:",
        "SID 1000 mm, SDD 1500 mm, 160 × 160 detector of 3 mm pixels, centred, 180 views over",
        "360°. RTK: `ThreeDCircularProjectionGeometry.AddProjection(1000, 1500, angle)`,",
        "projections as an ITK image of spacing (3, 3, 1), origin (−238.5, −238.5, 0);",
        "`FDKConeBeamReconstructionFilter` onto 128³ voxels of 2 mm, origin −127 mm",
        "(RTK-centred), `SetTruncationCorrection(0)`, `SetHannCutFrequency(c)`. Errors: RMS",
        f"over the {rt['voxels']['brain']} voxels inside the brain ellipsoid (primitive 1; the",
        "target metric), over that mask eroded by 1 and 2 voxels (6-connected; "
        f"{rt['voxels']['brain_eroded1']} and {rt['voxels']['brain_eroded2']} voxels),",
        "over the brain in the central axial slice (Y = −1 mm) and over the whole volume.",
        "",
        "| filter | RMS brain | 1.05 × RMS brain | max abs brain | RMS brain −1 vx | RMS brain −2 vx | RMS brain, central slice | RMS whole volume | time 128³ (s) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, r in rt["fdk"].items():
        label = "ramp (no window, c = 0)" if name == "ramp" else "Hann (c = 1)"
        lines.append(f"| {label} | {r['rms_brain']:.5f} | {1.05 * r['rms_brain']:.5f} | "
                     f"{r['max_abs_brain']:.4f} | {r['rms_brain_eroded1']:.5f} | "
                     f"{r['rms_brain_eroded2']:.5f} | {r['rms_brain_central_slice']:.5f} | "
                     f"{r['rms_all']:.5f} | {r['seconds_median']:.2f} |")
    if "timing_256" in rt:
        t = rt["timing_256"]
        lines += ["", f"RTK FDK (CPU) 256³ from 180 × 256² projections: "
                      f"{t['seconds_median']:.1f} s (median of {len(t['seconds'])})."]
    lines += [
        "",
        "## Reading the numbers",
        "",
        "- The target metrics (circle, brain) are dominated by the one pixel/voxel layer next",
        "  to the skull (density 1 against the brain's 0.02): the reconstruction blurs that edge",
        "  over about a pixel, so the RMS drops twenty-fold once the mask is eroded by one",
        "  pixel/voxel. The target metrics therefore mostly measure how the edge is blurred",
        "  (filter window, interpolation); the eroded columns measure the interior accuracy and",
        "  the low-contrast detail. Smoother windows (Hann, Hamming) lose at the edge and gain",
        "  little inside.",
        "- Geometry check (one-off, not part of this script): reconstructing the cone",
        "  projections with RTK's angles negated",
        "  gives a brain RMS of 0.142 instead of 0.054 (ramp), and scikit-image's `radon` of",
        "  the 2-D truth matches the exported sinogram to 4% relative RMS (pixelisation at the",
        "  skull), against 51% with the image flipped upside down: both peers see voxlab's",
        "  inputs in the intended orientation.",
        "- RTK's FDK scale needs no correction: on the small fixture (tests/data/ct) its",
        "  mean over the eroded unit-density region is 0.9997.",
        "",
        "Raw numbers: `docs/bench/ct-peers.json`.",
        "",
    ]
    with open(path, "w") as fh:
        fh.write("\n".join(lines))


if __name__ == "__main__":
    main()
