#!/usr/bin/env python3
"""Regenerates the pictures of docs/iterative.md (docs/images/iterative-*.png) with the
release binary, and prints the numbers their captions quote.

    cargo build --release
    python3 scripts/docs_iterative.py [--voxlab target/release/voxlab] [--keep DIR]

On first use it creates target/docs-venv (matplotlib and numpy, pinned below) and
re-runs itself inside it. Everything is computed by `voxlab`: exact parallel-beam
line integrals of the built-in modified Shepp–Logan head (`voxlab project`), the
reconstructions and their RMS errors against the analytic phantom (`voxlab reconstruct
--truth`), the convergence logs (`--convergence`), and the phantom panel (`voxlab
phantom`). Python only lays the float32 images side by side in a fixed grey window and
plots the CSV files.
"""

import argparse
import csv
import os
import re
import shutil
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
VENV = os.path.join(ROOT, "target", "docs-venv")
REQUIREMENTS = ["matplotlib==3.11.2", "numpy==2.4.6"]
IMAGES = os.path.join(ROOT, "docs", "images")
PHANTOM = "shepp-logan-modified"
N = 256  # detector bins of 1 mm and image size

# The two problems, as `voxlab project` angle options.
FEW_VIEWS = ["--angles", "30"]  # 30 views over 180°
LIMITED = ["--angles", "90", "--range", "90"]  # 90 views over 90°

# The grey window of the pictures (one row of panels per window): the brain (0.2), the
# ventricles (0) and the small features (0.3) in full contrast; the skull (1) saturates.
WINDOWS = [(0.0, 0.5)]
# The head's bounding box in the 256² image (rows, cols), to keep the files small.
CROP = (slice(9, 247), slice(38, 218))
# TV run past its default 200 iterations.
TV_LONG = 1000


def ensure_venv():
    """Re-runs this script inside target/docs-venv, creating it when needed."""
    if os.path.realpath(sys.prefix) == os.path.realpath(VENV):
        return
    py = os.path.join(VENV, "bin", "python")
    if not os.path.exists(py):
        subprocess.run([sys.executable, "-m", "venv", VENV], check=True)
        subprocess.run([py, "-m", "pip", "install", "--quiet", *REQUIREMENTS], check=True)
    os.execv(py, [py, os.path.abspath(__file__), *sys.argv[1:]])


def voxlab(exe, *args):
    """Runs voxlab; returns its stdout (stderr passes through)."""
    print("$ voxlab " + " ".join(args), flush=True)
    r = subprocess.run([exe, *args], check=True, stdout=subprocess.PIPE, text=True)
    sys.stdout.write(r.stdout)
    return r.stdout


def rms_of(out):
    m = re.search(r"RMS error against [\w-]+: ([0-9.eE+-]+)", out)
    return float(m.group(1))


def ms_of(out):
    m = re.search(r"([0-9.]+) ms per iteration", out)
    return float(m.group(1)) if m else None


def reconstruct(exe, tmp, sino, tag, method, extra=()):
    """One reconstruction: its image (.npy), convergence log, RMS and ms/iteration."""
    npy = os.path.join(tmp, f"{tag}-{method}.npy")
    args = ["reconstruct", sino, "--method", method, "--out", npy,
            "--truth", f"phantom:{PHANTOM}", *extra]
    log = None
    if method != "fbp":
        log = os.path.join(tmp, f"{tag}-{method}.csv")
        args += ["--convergence", log]
    out = voxlab(exe, *args)
    return {"npy": npy, "csv": log, "rms": rms_of(out), "ms": ms_of(out)}


def read_log(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    it = [int(r["iteration"]) for r in rows]
    res = [float(r["residual"]) for r in rows]
    return it, res


def save_png(fig, path, palette):
    """Saves a figure as a small PNG: 8-bit grey, or a 64-colour palette for plots."""
    from PIL import Image

    tmp = path + ".tmp.png"
    fig.savefig(tmp)
    im = Image.open(tmp).convert("RGB")
    im = im.quantize(64) if palette else im.convert("L")
    im.save(path, optimize=True)
    os.remove(tmp)
    print(f"wrote {os.path.relpath(path, ROOT)} ({os.path.getsize(path) // 1024} KiB)")


def panels(path, columns):
    """`columns`: (title, image) pairs; one row per grey window, pixels 1:1."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    h = CROP[0].stop - CROP[0].start
    w = CROP[1].stop - CROP[1].start
    title_px, gap = 30, 4
    dpi = 100
    cols, rows = len(columns), len(WINDOWS)
    fw = cols * w + (cols - 1) * gap
    fh = title_px + rows * h + (rows - 1) * gap
    fig = plt.figure(figsize=(fw / dpi, fh / dpi), dpi=dpi, facecolor="white")
    for r, (lo, hi) in enumerate(WINDOWS):
        for c, (title, img) in enumerate(columns):
            x0 = c * (w + gap) / fw
            y0 = 1 - (title_px + (r + 1) * h + r * gap) / fh
            ax = fig.add_axes([x0, y0, w / fw, h / fh])
            ax.imshow(img[CROP], cmap="gray", vmin=lo, vmax=hi, interpolation="nearest")
            ax.set_axis_off()
            if r == 0:
                ax.set_title(title, fontsize=8.5, pad=3)
    save_png(fig, path, palette=False)
    plt.close(fig)


def convergence_plot(path, logs):
    """`logs`: (subplot title, [(label, colour key, csv)]): the relative residual
    ‖b − A x_k‖ / ‖b‖ (x_0 = 0) against the iteration k ≥ 1, both axes logarithmic."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(logs), figsize=(8.4, 3.2), dpi=100)
    styles = {"sirt": "C0", "cgls": "C1", "os-sart": "C2", "tv": "C3"}
    for ax, (title, entries) in zip(axes, logs):
        for label, style, path_csv in entries:
            it, res = read_log(path_csv)
            ax.loglog(it[1:], [v / res[0] for v in res[1:]], color=styles[style], lw=1.4,
                      label=label)
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("iteration (OS-SART: pass over the 10 subsets)", fontsize=8)
        ax.set_ylabel("‖b − A x‖ / ‖b‖", fontsize=8)
        ax.tick_params(labelsize=7.5)
        ax.grid(True, which="both", lw=0.3, alpha=0.6)
        ax.legend(fontsize=7.5)
    fig.tight_layout()
    save_png(fig, path, palette=True)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--voxlab", default=os.path.join(ROOT, "target", "release", "voxlab"))
    ap.add_argument("--keep", help="keep the sinograms, images and logs in this folder")
    a = ap.parse_args()
    ensure_venv()
    import numpy as np

    exe = os.path.abspath(a.voxlab)
    if not os.path.exists(exe):
        sys.exit(f"{exe} is missing: run `cargo build --release` first")
    tmp = a.keep or tempfile.mkdtemp(prefix="voxlab-iterative-")
    os.makedirs(tmp, exist_ok=True)
    try:
        # The phantom panel: `voxlab phantom` samples the cell centres of the 256 mm
        # cube (half a pixel off the reconstruction's pixel centres; for display only,
        # the RMS figures are --truth's exact values at the pixel centres). Its (z, y, x)
        # slice has y up; the reconstruction's rows go down, as scikit-image's.
        ph = os.path.join(tmp, "phantom.npy")
        voxlab(exe, "phantom", f"{PHANTOM}:{N},{N},1", "--out", ph)
        truth = np.load(ph).reshape(N, N)[::-1]

        sino = {}
        for tag, opts in [("views30", FEW_VIEWS), ("limited90", LIMITED)]:
            sino[tag] = os.path.join(tmp, f"{tag}.npy")
            voxlab(exe, "project", f"phantom:{PHANTOM}", "--cols", str(N), *opts,
                   "--out", sino[tag])

        res = {}
        for tag in sino:
            for m in ["fbp", "sirt", "cgls", "os-sart", "tv"]:
                res[(tag, m)] = reconstruct(exe, tmp, sino[tag], tag, m)
            # TV past its default 200 iterations (the first 200 are the same iterates).
            res[(tag, "tv-1000")] = reconstruct(exe, tmp, sino[tag], tag + "-1000", "tv",
                                                ["--iterations", str(TV_LONG)])
        res[("views30", "sirt-nonneg")] = reconstruct(exe, tmp, sino["views30"],
                                                      "views30-nonneg", "sirt",
                                                      ["--nonnegative"])

        def col(tag, m, name):
            return (f"{name}  RMS {res[(tag, m)]['rms']:.4f}", np.load(res[(tag, m)]["npy"]))

        panels(os.path.join(IMAGES, "iterative-few-views.png"), [
            ("phantom", truth),
            col("views30", "fbp", "FBP"),
            col("views30", "sirt", "SIRT 100"),
            col("views30", "cgls", "CGLS 30"),
            col("views30", "tv", "TV 200"),
            col("views30", "tv-1000", f"TV {TV_LONG}"),
        ])
        panels(os.path.join(IMAGES, "iterative-limited-angle.png"), [
            ("phantom", truth),
            col("limited90", "fbp", "FBP"),
            col("limited90", "cgls", "CGLS 30"),
            col("limited90", "tv", "TV 200"),
            col("limited90", "tv-1000", f"TV {TV_LONG}"),
        ])
        curves = [("SIRT", "sirt", "sirt"), ("CGLS", "cgls", "cgls"),
                  ("OS-SART", "os-sart", "os-sart"), ("TV", "tv", "tv-1000")]
        convergence_plot(os.path.join(IMAGES, "iterative-convergence.png"), [
            (title, [(label, style, res[(tag, m)]["csv"]) for label, style, m in curves])
            for tag, title in [("views30", "30 views over 180°"),
                               ("limited90", "90 views over 90°")]
        ])

        print("\n| problem | method | RMS vs phantom | ms per iteration |")
        print("|---|---|---|---|")
        for (tag, m), r in res.items():
            ms = f"{r['ms']:.1f}" if r["ms"] is not None else "—"
            print(f"| {tag} | {m} | {r['rms']:.4f} | {ms} |")
    finally:
        if not a.keep:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
