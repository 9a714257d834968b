#!/usr/bin/env python3
"""voxlab's iterative reconstruction beside ASTRA's CPU SIRT, CGLS and SART and
scikit-image's iradon_sart, on the same sinograms; writes docs/bench/iterative-peers.{md,json}.

One command (from the repository root):

    python3 scripts/peers/iterative_peers.py [--runs 3] [--views 180,30]

Like bench_peers.py (whose set-up it reuses) it creates target/peers-venv from
scripts/peers/requirements-bench.txt when needed, builds target/release/voxlab and the
ct_export example when they are missing, and re-runs itself inside the venv.

Problem: exact line integrals of Phantom::shepp_logan() (Kak & Slaney intensities,
256 mm cube) from `voxlab project phantom:shepp-logan --geometry parallel --angles V
--cols 256`: scikit-image's parallel geometry, 256 bins of 1 mm, centre bin 128, V
views over [0°, 180°), no noise. Every tool gets that one sinogram and reconstructs
256² pixels of 1 mm, pixel (row, col) at X = col − 128, Z = row − 128 mm, on the disc
(col − 128)² + (row − 128)² ≤ 128² (voxlab's support; ASTRA gets it as its
reconstruction mask; iradon_sart works inside that circle). The truth is ct_export's
truth2d.npy (the phantom's exact values at the pixel centres); every error is the RMS
of (reconstruction − truth) over that disc, the circle metric of docs/bench/ct-peers.md.

Times are per iteration (SART, OS-SART: per pass over all views), medians of --runs
runs after one warm-up: voxlab's own figure (`… ms per iteration` on stdout: the
solve's wall clock over its iterations, the matched pair's set-up excluded), on all
cores and on one thread; ASTRA: the wall clock of `astra.algorithm.run(alg, N)` over N
(data and algorithm creation excluded); scikit-image: the wall clock of the N calls
over N.
"""

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import textwrap
import time

sys.dont_write_bytecode = True  # no __pycache__ beside the imported peer scripts
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_peers  # noqa: E402
from bench_peers import CT_EXPORT, ROOT, STAMP, VOXLAB, cores, err_text  # noqa: E402

N = 256  # image and detector size
SIRT_IT, CGLS_IT, SART_PASSES = 100, 30, 10
SKIMAGE_RELAXATION = 0.15  # iradon_sart's default


# ------------------------------------------------------------------------------------
# voxlab
# ------------------------------------------------------------------------------------


def voxlab_iterative(sino, out, extra, threads, runs):
    """`voxlab reconstruct SINO --backend cpu-f32 … --truth phantom:shepp-logan` once
    as a warm-up and `runs` more times on `threads` threads: voxlab's own ms per
    iteration of each timed run, the command's wall clock, and the RMS it prints."""
    args = [VOXLAB, "reconstruct", sino, "--backend", "cpu-f32", "--out", out,
            "--truth", "phantom:shepp-logan", *extra]
    env = dict(bench_peers.voxlab_env(), RAYON_NUM_THREADS=str(threads))

    def once():
        t = time.perf_counter()
        r = subprocess.run(args, check=True, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t
        ms = re.search(r"([0-9.]+) ms per iteration", r.stdout)
        own = re.search(r"RMS error against shepp-logan: ([0-9.eE+-]+)", r.stdout)
        return float(ms.group(1)), wall, float(own.group(1)), r.stdout

    first = once()
    timed = [once() for _ in range(runs)]
    ms = [t[0] for t in timed]
    return {"ms_per_iteration_median": statistics.median(ms), "ms_per_iteration": ms,
            "command_wall_s": [t[1] for t in timed], "voxlab_rms_printed": first[2],
            "stdout": first[3].strip(), "threads": threads}


PY_VENV = os.path.join(ROOT, "target", "py-venv", "bin", "python")

IRADON_SART_CHILD = textwrap.dedent("""
    import json, sys, time
    import numpy as np
    from voxlab.transform import iradon_sart
    sino = np.load(sys.argv[1])
    theta = np.array(json.loads(sys.argv[2]), dtype=np.float64)
    passes, runs, relaxation = int(sys.argv[3]), int(sys.argv[4]), float(sys.argv[5])
    def run():
        img = None
        for _ in range(passes):
            img = iradon_sart(sino, theta=theta, image=img, relaxation=relaxation)
        return img
    img = run()  # warm-up
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        img = run()
        times.append(time.perf_counter() - t)
    np.save(sys.argv[6], img)
    print(json.dumps(times))
""")


def voxlab_iradon_sart(sino, theta, out, passes, relaxation, threads, runs):
    """voxlab's `voxlab.transform.iradon_sart` (scikit-image's SART step for step, float64
    on the CPU), `passes` calls each feeding the last image back, timed in a child
    process of the test command's venv (target/py-venv, where `scripts/test.sh` installs
    the package) on `threads` threads, after one warm-up."""
    if not os.path.exists(PY_VENV):
        raise RuntimeError(f"{PY_VENV} is missing: run `bash scripts/test.sh` first")
    env = dict(bench_peers.voxlab_env(), RAYON_NUM_THREADS=str(threads))
    r = subprocess.run([PY_VENV, "-c", IRADON_SART_CHILD, sino, json.dumps(list(theta)),
                        str(passes), str(runs), str(relaxation), out],
                       check=True, env=env, capture_output=True, text=True)
    ms = [t * 1e3 / passes for t in json.loads(r.stdout.strip().splitlines()[-1])]
    return {"ms_per_iteration_median": statistics.median(ms), "ms_per_iteration": ms,
            "threads": threads}


# ------------------------------------------------------------------------------------
# ASTRA (CPU)
# ------------------------------------------------------------------------------------


def astra_geometry(n, theta_deg):
    """ASTRA's geometry for a scikit-image sinogram of n bins onto scikit-image's n²
    grid, with the conventions of bench_peers.astra_fbp (angles negated, volume window
    shifted half a pixel, image rows flipped back afterwards), but as `parallel_vec`
    with exactly n bins whose centre moves half a bin so that bin n/2 lies on the axis
    (astra_fbp appends a zero bin instead): the same rays as voxlab's."""
    import astra
    import numpy as np

    h = n / 2
    vg = astra.create_vol_geom(n, n, -h - 0.5, h - 0.5, -h - 0.5, h - 0.5)
    pg = astra.create_proj_geom("parallel", 1.0, n, np.deg2rad(-np.asarray(theta_deg)))
    vec = astra.functions.geom_2vec(pg)["Vectors"].copy()
    vec[:, 2:4] -= 0.5 * vec[:, 4:6]  # detector centre d − u/2: bin n/2 at offset 0
    return vg, astra.create_proj_geom("parallel_vec", n, vec)


def astra_conventions(sino, theta_deg, truth):
    """Checks of astra_geometry: ASTRA's linear forward projection of the truth against
    the exact sinogram (relative L2; scikit-image's radon gives about the same; the
    image upside down gives far more), and against astra_fbp's geometry of n + 1 bins
    (its first n bins)."""
    import astra
    import numpy as np
    from skimage.transform import radon

    n = truth.shape[0]
    vg, pg = astra_geometry(n, theta_deg)
    pg_fbp = astra.create_proj_geom("parallel", 1.0, n + 1, np.deg2rad(-np.asarray(theta_deg)))

    def fp(geom, img):
        pid = astra.create_projector("linear", geom, vg)
        try:
            sid, s = astra.create_sino(img.astype(np.float32), pid)
            astra.data2d.delete(sid)
            return s.T[:n].astype(np.float64)
        finally:
            astra.projector.delete(pid)

    ours = fp(pg, truth[::-1])
    nrm = np.linalg.norm(sino)
    return {
        "fp_rel_l2_vs_exact_sinogram": float(np.linalg.norm(ours - sino) / nrm),
        "fp_rel_l2_image_upside_down": float(np.linalg.norm(fp(pg, truth) - sino) / nrm),
        "skimage_radon_rel_l2_vs_exact_sinogram": float(
            np.linalg.norm(radon(truth, theta=theta_deg, circle=True) - sino) / nrm),
        "max_abs_diff_vs_astra_fbp_geometry": float(
            np.max(np.abs(ours - fp(pg_fbp, truth[::-1])))),
        "sinogram_max": float(sino.max()),
    }


def astra_residual(sino, theta_deg, img):
    """‖sino − A img‖ (L2 over every bin), A ASTRA's linear forward projector in
    astra_geometry; img in scikit-image orientation."""
    import astra
    import numpy as np

    vg, pg = astra_geometry(img.shape[0], theta_deg)
    pid = astra.create_projector("linear", pg, vg)
    try:
        sid, fp = astra.create_sino(img[::-1].astype(np.float32), pid)
        astra.data2d.delete(sid)
        return float(np.linalg.norm(fp.T.astype(np.float64) - sino))
    finally:
        astra.projector.delete(pid)


def astra_run(alg, sino, theta_deg, mask, iterations, options):
    """One ASTRA CPU reconstruction with the `linear` projector from zero: returns
    (wall s of run(), CPU s of run(), image in scikit-image orientation)."""
    import astra
    import numpy as np

    n = mask.shape[0]
    vg, pg = astra_geometry(n, theta_deg)
    pid = astra.create_projector("linear", pg, vg)
    sid = astra.data2d.create("-sino", pg, sino.T.astype(np.float32))
    rid = astra.data2d.create("-vol", vg, 0.0)
    mid = astra.data2d.create("-vol", vg, mask[::-1].astype(np.float32))
    cfg = astra.astra_dict(alg)
    cfg.update(ReconstructionDataId=rid, ProjectionDataId=sid, ProjectorId=pid)
    cfg["option"] = {"ReconstructionMaskId": mid, **options}
    a = astra.algorithm.create(cfg)
    try:
        t, c = time.perf_counter(), time.process_time()
        astra.algorithm.run(a, iterations)
        wall, cpu = time.perf_counter() - t, time.process_time() - c
        return wall, cpu, astra.data2d.get(rid)[::-1].astype(np.float64)
    finally:
        astra.algorithm.delete(a)
        astra.data2d.delete([sid, rid, mid])
        astra.projector.delete(pid)


def astra_timed(alg, sino, theta_deg, mask, iterations, per, options, runs):
    """A warm-up and `runs` timed runs; `per` = ASTRA iterations per reported
    iteration (SART: one ASTRA iteration is one view, so `per` = the view count)."""
    astra_run(alg, sino, theta_deg, mask, iterations * per, options)
    walls, cpus, img = [], [], None
    for _ in range(runs):
        w, c, img = astra_run(alg, sino, theta_deg, mask, iterations * per, options)
        walls.append(w * 1e3 / iterations)
        cpus.append(c * 1e3 / iterations)
    return img, {"ms_per_iteration_median": statistics.median(walls),
                 "ms_per_iteration": walls, "cpu_ms_per_iteration": cpus, "threads": 1}


# ------------------------------------------------------------------------------------
# One case: V views
# ------------------------------------------------------------------------------------


def run_case(work, views, truth, runs):
    import numpy as np
    from ct_peers import rms
    from skimage.transform import iradon_sart

    sino_path = os.path.join(work, f"sino{views}.npy")
    bench_peers.run_voxlab(["project", "phantom:shepp-logan", "--geometry", "parallel",
                            "--angles", str(views), "--cols", str(N), "--out", sino_path])
    geom = json.load(open(os.path.join(work, f"sino{views}.geometry.json")))
    theta = np.asarray(geom["angles_deg"], dtype=np.float64)
    sino = np.load(sino_path)
    r, c = np.mgrid[:N, :N] - N // 2
    circle = r * r + c * c <= (N // 2) ** 2

    def err(img):
        return rms((img - truth)[circle])

    def fit(img):
        """‖b − A x‖ with A = ASTRA's linear projector in astra_geometry: the data
        misfit of any tool's image on voxlab's discretisation."""
        try:
            return astra_residual(sino, theta, img)
        except Exception:
            return None

    case = {"views": views, "sinogram": list(sino.shape), "geometry": {
        k: geom[k] for k in ("beam", "cols", "du", "cu")}, "pixels_in_disc": int(circle.sum()),
        "conventions": astra_conventions(sino, theta, truth), "groups": []}
    n_threads = cores()

    def voxlab(label, extra):
        out = os.path.join(work, f"voxlab_{views}_{label}.npy")
        res = {"tool": "voxlab", "settings": " ".join(extra)}
        try:
            res["all_cores"] = voxlab_iterative(sino_path, out, extra, n_threads, runs)
            img = np.load(out).astype(np.float64)
            res["rms_circle"], res["residual_norm"] = err(img), fit(img)
            res["one_thread"] = voxlab_iterative(sino_path, out, extra, 1, runs)
            res["truth_check_abs_diff"] = abs(res["rms_circle"]
                                              - res["all_cores"]["voxlab_rms_printed"])
        except Exception as e:
            res["unavailable"] = err_text(e)
        show(views, label, res)
        return res

    def astra(label, alg, iterations, per, options, settings):
        res = {"tool": f"ASTRA {alg} (CPU, linear)", "settings": settings}
        try:
            img, t = astra_timed(alg, sino, theta, circle, iterations, per, options, runs)
            res.update(t, rms_circle=err(img), residual_norm=fit(img))
        except Exception as e:
            res["unavailable"] = err_text(e)
        show(views, label, res)
        return res

    def group(name, iterations, unit, vox, peers):
        case["groups"].append({"name": name, "iterations": iterations, "unit": unit,
                               "voxlab": vox, "peers": peers})

    it = ["--iterations"]
    group("SIRT", SIRT_IT, "iteration",
          voxlab("sirt", ["--method", "sirt", *it, str(SIRT_IT)]),
          [astra("sirt", "SIRT", SIRT_IT, 1, {}, "Relaxation 1")])
    group("SIRT, x ≥ 0", SIRT_IT, "iteration",
          voxlab("sirt_nonneg", ["--method", "sirt", *it, str(SIRT_IT), "--nonnegative"]),
          [astra("sirt_nonneg", "SIRT", SIRT_IT, 1, {"MinConstraint": 0.0},
                 "MinConstraint 0")])
    group("CGLS", CGLS_IT, "iteration",
          voxlab("cgls", ["--method", "cgls", *it, str(CGLS_IT)]),
          [astra("cgls", "CGLS", CGLS_IT, 1, {}, "")])

    # SART: one view per update (voxlab: as many subsets as views, visited in order).
    sart_lo = voxlab("sart_015", ["--method", "os-sart", *it, str(SART_PASSES), "--subsets",
                                  str(views), "--relaxation", str(SKIMAGE_RELAXATION)])
    peers = [astra("sart_015", "SART", SART_PASSES, views,
                   {"Relaxation": SKIMAGE_RELAXATION, "ProjectionOrder": "sequential"},
                   f"Relaxation {SKIMAGE_RELAXATION}, ProjectionOrder sequential")]
    sk = {"tool": "scikit-image iradon_sart",
          "settings": f"relaxation {SKIMAGE_RELAXATION}, its default; float64"}
    try:
        def passes(k=SART_PASSES, relaxation=SKIMAGE_RELAXATION):
            img = None
            for _ in range(k):
                img = iradon_sart(sino, theta=theta, image=img, relaxation=relaxation)
            return img

        med, times, img = bench_peers.timed_runs(passes, runs)
        sk_img = img
        sk.update(ms_per_iteration_median=med * 1e3 / SART_PASSES,
                  ms_per_iteration=[t * 1e3 / SART_PASSES for t in times], threads=1,
                  rms_circle=err(img), residual_norm=fit(img))
        with np.errstate(all="ignore"):  # (iradon_sart updates `image` in place)
            img = iradon_sart(sino, theta=theta, relaxation=1.0)
            diverged = [err(img)]
            diverged.append(err(iradon_sart(sino, theta=theta, image=img, relaxation=1.0)))
        sk["relaxation_1_rms_after_1_and_2_passes"] = diverged
    except Exception as e:
        sk["unavailable"] = err_text(e)
    show(views, "sart_015", sk)
    peers.append(sk)
    # A reference, not a goal: ASTRA's SART in iradon_sart's view order.
    try:
        from skimage.transform import order_angles_golden_ratio

        order = np.array(list(order_angles_golden_ratio(theta)), dtype=np.float32)
        gold = astra("sart_gold", "SART", SART_PASSES, views,
                     {"Relaxation": SKIMAGE_RELAXATION, "ProjectionOrder": "custom",
                      "ProjectionOrderList": order},
                     f"Relaxation {SKIMAGE_RELAXATION}, ProjectionOrder custom: "
                     "iradon_sart's golden-ratio order; reference, not a goal")
        gold["reference"] = True
        peers.append(gold)
    except Exception as e:
        print(f"golden-ratio reference: {err_text(e)}", file=sys.stderr)
    group(f"SART, one view per update, λ = {SKIMAGE_RELAXATION}", SART_PASSES, "pass",
          sart_lo, peers)
    # scikit-image's own SART (its projector, weights and step) in voxlab beside it.
    vsk = {"tool": "voxlab",
           "settings": f"voxlab.transform.iradon_sart(…, relaxation={SKIMAGE_RELAXATION}) "
                       f"× {SART_PASSES}, float64"}
    try:
        out = os.path.join(work, f"voxlab_{views}_iradon_sart.npy")
        vsk["all_cores"] = voxlab_iradon_sart(sino_path, theta, out, SART_PASSES,
                                              SKIMAGE_RELAXATION, n_threads, runs)
        img = np.load(out)
        vsk["rms_circle"], vsk["residual_norm"] = err(img), fit(img)
        vsk["one_thread"] = voxlab_iradon_sart(sino_path, theta, out, SART_PASSES,
                                               SKIMAGE_RELAXATION, 1, runs)
        if "unavailable" not in sk:
            vsk["max_abs_diff_vs_scikit_image"] = float(np.max(np.abs(img - sk_img)))
    except Exception as e:
        vsk["unavailable"] = err_text(e)
    show(views, "iradon_sart", vsk)
    group(f"scikit-image's SART (`iradon_sart`), λ = {SKIMAGE_RELAXATION}", SART_PASSES,
          "pass", vsk, [sk])
    group("SART, one view per update, λ = 1", SART_PASSES, "pass",
          voxlab("sart_1", ["--method", "os-sart", *it, str(SART_PASSES), "--subsets",
                            str(views)]),
          [astra("sart_1", "SART", SART_PASSES, views,
                 {"Relaxation": 1.0, "ProjectionOrder": "sequential"},
                 "Relaxation 1, ProjectionOrder sequential")])
    group(f"OS-SART, voxlab's defaults ({min(10, views)} subsets, λ = 1)", SART_PASSES,
          "pass", voxlab("ossart", ["--method", "os-sart", *it, str(SART_PASSES)]), [])
    return case


def show(views, label, res):
    if "unavailable" in res:
        print(f"{views:4d} views {label:12s} {res['tool']}: unavailable ({res['unavailable']})",
              file=sys.stderr, flush=True)
        return
    t = res.get("all_cores", res)["ms_per_iteration_median"]
    one = f", 1 thread {res['one_thread']['ms_per_iteration_median']:.1f}" \
        if "one_thread" in res else ""
    print(f"{views:4d} views {label:12s} {res['tool']:34s} RMS {res['rms_circle']:.6f}  "
          f"{t:.1f} ms/it{one}", file=sys.stderr, flush=True)


# ------------------------------------------------------------------------------------
# Goals and the page
# ------------------------------------------------------------------------------------


def ms(res, key="all_cores"):
    if "unavailable" in res:
        return None
    return res[key]["ms_per_iteration_median"] if key in res else res["ms_per_iteration_median"]


def goals(res):
    """Accuracy: voxlab's RMS ≤ 1.05 × the peer's, every pair at equal iterations.
    Speed: voxlab's time per iteration ≤ 1/10 of ASTRA's (CPU), 180 views."""
    acc, speed, refs = [], [], []
    for case in res["cases"]:
        for g in case["groups"]:
            v = g["voxlab"]
            for p in g["peers"]:
                if "unavailable" in p or "unavailable" in v:
                    continue
                if p.get("reference"):
                    refs.append({"views": case["views"], "group": g["name"],
                                 "peer": p["tool"], "settings": p["settings"],
                                 "rms": p["rms_circle"]})
                    continue
                ratio = v["rms_circle"] / p["rms_circle"]
                acc.append({"views": case["views"], "group": g["name"], "peer": p["tool"],
                            "voxlab_rms": v["rms_circle"], "peer_rms": p["rms_circle"],
                            "ratio": ratio, "met": ratio <= 1.05,
                            "voxlab_residual": v.get("residual_norm"),
                            "peer_residual": p.get("residual_norm")})
                if p["tool"].startswith("ASTRA") and case["views"] == 180:
                    r_all = ms(v) / ms(p)
                    r_one = ms(v, "one_thread") / ms(p)
                    speed.append({"views": case["views"], "group": g["name"],
                                  "peer": p["tool"], "voxlab_ms": ms(v),
                                  "voxlab_ms_one_thread": ms(v, "one_thread"),
                                  "peer_ms": ms(p), "ratio": r_all,
                                  "ratio_one_thread": r_one, "met": r_all <= 0.1,
                                  "met_one_thread": r_one <= 0.1})
    return {"accuracy": acc, "speed": speed, "references": refs}


def reading(res):
    """A few sentences computed from the numbers."""
    gl = res["goals"]
    astra = [a for a in gl["accuracy"] if a["peer"].startswith("ASTRA")]
    sk = [a for a in gl["accuracy"] if a["peer"].startswith("scikit-image")]
    out = ["## Reading the numbers", ""]
    if astra:
        close = [a for a in astra if abs(a["ratio"] - 1) < 1e-3]
        out.append(f"- voxlab and ASTRA pose the same problem (the same rays, Joseph's "
                   "discretisation, the same support and weights). In "
                   f"{len(close)} of {len(astra)} pairs their RMS errors agree to 0.1% "
                   f"(at most {100 * max(abs(a['ratio'] - 1) for a in close):.3f}% apart): "
                   "there the accuracy goal is met by matching ASTRA, not by beating it."
                   if close else "- voxlab and ASTRA pose the same problem.")
        for a in astra:
            if a in close:
                continue
            line = (f"- {a['views']} views, {a['group']}: voxlab's RMS is "
                    f"{a['voxlab_rms']:.5f} against ASTRA's {a['peer_rms']:.5f} (ratio "
                    f"{a['ratio']:.3f})")
            if a.get("voxlab_residual") and a.get("peer_residual"):
                line += (f"; its data misfit ‖b − Ax‖ is {a['voxlab_residual']:.2f} against "
                         f"{a['peer_residual']:.2f}")
                if (a["voxlab_residual"] < a["peer_residual"]) == (a["ratio"] > 1):
                    line += (": the closer fit is the less accurate image (the sinogram "
                             "holds exact line integrals, which no 256² pixel image "
                             "reproduces, so a closer fit need not mean a smaller error)")
            out.append(line + ".")
    closer = False
    for a in sk:
        if a["group"].startswith("scikit-image's SART"):
            out.append(f"- {a['views']} views, scikit-image's own SART: voxlab's "
                       "`voxlab.transform.iradon_sart`, which repeats `iradon_sart`'s "
                       f"arithmetic, reaches RMS {a['voxlab_rms']:.5f} against "
                       f"{a['peer_rms']:.5f} (ratio {a['ratio']:.3f}).")
            continue
        line = (f"- {a['views']} views, SART λ = {SKIMAGE_RELAXATION}: scikit-image's "
                f"`iradon_sart` reaches RMS {a['peer_rms']:.5f}, voxlab "
                f"{a['voxlab_rms']:.5f} (ratio {a['ratio']:.3f})")
        if a.get("voxlab_residual") and a.get("peer_residual"):
            line += (f"; data misfit on voxlab's discretisation {a['peer_residual']:.2f} "
                     f"against voxlab's {a['voxlab_residual']:.2f}")
            closer |= a["peer_residual"] < a["voxlab_residual"]
        gold = next((r for r in gl.get("references", []) if r["views"] == a["views"]), None)
        if gold:
            line += (f". ASTRA's SART in `iradon_sart`'s golden-ratio view order reaches "
                     f"{gold['rms']:.5f}")
            gap = a["voxlab_rms"] - a["peer_rms"]
            moved = a["voxlab_rms"] - gold["rms"]
            if gap and abs(moved) < 0.1 * abs(gap):
                line += ", so the view order does not explain the difference"
            elif gap:
                line += (f", so the view order accounts for {100 * moved / gap:.0f}% of the "
                         "difference")
        out.append(line + ".")
    if closer:
        out.append("- `iradon_sart`'s relaxation does not scale the step as ASTRA's and "
                   "voxlab's do: at 0.15 its images fit the sinogram more closely than "
                   "theirs (even measured with their projector) and at 1 it diverges. Equal "
                   "λ is therefore not an equal step; these rows compare the three at the "
                   "same nominal setting, and the measurements here do not separate the "
                   "step from the projector (scikit-image's own ray sampling and "
                   "interpolation).")
    if gl["speed"]:
        lo = min(s["ratio"] for s in gl["speed"])
        hi = max(s["ratio"] for s in gl["speed"])
        lo1 = min(s["ratio_one_thread"] for s in gl["speed"])
        hi1 = max(s["ratio_one_thread"] for s in gl["speed"])
        if hi <= 0.1:
            goal = (f"The 1/10 goal holds on all cores with a margin of {0.1 / hi:.2f}× "
                    "(the slowest comparison) on this machine.")
        else:
            goal = ("The 1/10 goal needs voxlab "
                    f"{max(lo / 0.1, 1):.1f}–{max(hi / 0.1, 1):.1f}× faster than it is on "
                    "this machine.")
        out.append(f"- Speed, 180 views: voxlab on all cores takes {lo:.2f}–{hi:.2f}× "
                   f"ASTRA's time per iteration, on one thread {lo1:.2f}–{hi1:.2f}× (ASTRA "
                   f"runs on one thread). {goal}")
    return [textwrap.fill(x, 88, subsequent_indent="  ") if x.startswith("- ") else x
            for x in out] + [""]


def f_ms(x):
    return "—" if x is None else f"{x:.1f}"


def write_md(res, path):
    m, v = res["machine"], res["versions"]
    cmds = res.get("commands") or ["python3 scripts/peers/iterative_peers.py"]
    load = lambda k: ", ".join(f"{x:.1f}" for x in (m.get(k) or []))  # noqa: E731
    lines = [
        "# Iterative reconstruction: voxlab beside ASTRA and scikit-image",
        "",
        "voxlab's `reconstruct --method sirt|cgls|os-sart` beside ASTRA's CPU `SIRT`, `CGLS`",
        "and `SART` and scikit-image's `iradon_sart`, at equal iterations on the same",
        "noise-free sinograms: accuracy against the exact phantom and time per iteration.",
        "",
        "## Command",
        "",
        "```sh",
        *cmds,
        "```",
        "",
        *(["(the first command wrote every case; the later ones re-ran the cases they name",
           "on a quieter machine and kept the others)", ""] if len(cmds) > 1 else []),
        "(reuses `bench_peers.py`'s set-up: creates `target/peers-venv` from",
        "`scripts/peers/requirements-bench.txt` and builds `target/release/voxlab` and the",
        "`ct_export` example when missing; scratch files go to `target/peers-bench/iterative`).",
        "",
        "## Machine and versions",
        "",
        f"- Date: {res['date_utc']}; medians of {res['runs']} runs after one warm-up.",
        f"- Machine: {m['cpu']}, {m['cores']} cores, {m['os']}; "
        + ("the load average of each case is under its heading."
           if all("load_average_at_start" in c for c in res["cases"]) else
           f"load average {load('load_average_at_start')} at the start, "
           f"{load('load_average_at_end')} at the end."),
        "  The machine is shared with other jobs: times can move by tens of percent",
        "  between runs of the script.",
        f"- Versions: {v.get('voxlab')} ({v.get('rustc')}; binary built "
        f"{res['voxlab_binary_mtime_utc']});",
        f"  Python {m['python']}, numpy {v.get('numpy')}, scikit-image "
        f"{v.get('scikit-image')}, ASTRA {v.get('astra-toolbox')} (CPU algorithms, float32).",
        f"- Threads: voxlab on {m['cores']} threads (all cores, rayon) and on one thread",
        "  (`RAYON_NUM_THREADS=1`); ASTRA's CPU algorithms and `iradon_sart` run on one",
        "  thread (ASTRA's CPU time / wall time over its runs: "
        f"{res['astra_cpu_over_wall']:.2f}).",
        "",
        "## Problem",
        "",
        "- Sinogram: `voxlab project phantom:shepp-logan --geometry parallel --angles V",
        "  --cols 256`: exact line integrals of `Phantom::shepp_logan()` (Kak & Slaney",
        "  intensities, 256 mm cube), scikit-image's parallel geometry (256 bins of 1 mm,",
        "  centre bin 128, V views evenly over [0°, 180°)), float64, no noise. The one",
        "  file goes to every tool.",
        "- Image: 256² pixels of 1 mm, pixel `(row, col)` at `X = col − 128`, `Z = row − 128`",
        "  mm (scikit-image's grid), unknowns on the disc `(col − 128)² + (row − 128)² ≤ 128²`",
        f"  ({res['cases'][0]['pixels_in_disc']} pixels): voxlab's support, ASTRA's "
        "`ReconstructionMaskId`;",
        "  `iradon_sart` works inside the same circle. All start from zero.",
        "- Error: RMS of (reconstruction − exact phantom at the pixel centres) over that",
        "  disc (the circle metric of docs/bench/ct-peers.md; the truth is `ct_export`'s",
        "  `truth2d.npy`). voxlab's own `--truth` figure agrees with the script's to",
        f"  {res['truth_check_max_abs_diff']:.1e} (it prints six decimals).",
        "- Time: per iteration (SART and OS-SART: per pass over all views). voxlab: the",
        "  `… ms per iteration` it prints (the solve's wall clock over its iterations; the",
        "  set-up of the projector pair excluded, the row and column sums included); ASTRA:",
        "  wall clock of `astra.algorithm.run(alg, N)` / N (data and algorithm creation",
        "  excluded; its row and column sums happen inside `run`); `iradon_sart`: wall",
        "  clock of the N calls / N.",
        "",
        "## Results",
        "",
        "RMS ratio and time ratio = voxlab / peer (below 1: voxlab is more accurate or faster).",
        "‖b − Ax‖ ratio: the data misfit of voxlab's image over the peer's, both measured with",
        "ASTRA's `linear` projector in the geometry below (voxlab's discretisation). Times in",
        "ms per iteration (per pass for SART).",
    ]
    for case in res["cases"]:
        lines += [
            "",
            f"### 256² from {case['views']} views",
            "",
            *([f"Run {case['date_utc']}; load average "
               + ", ".join(f"{x:.1f}" for x in case["load_average_at_start"])
               + " at the start"
               + ("" if "load_average_at_end" not in case else ", " + ", ".join(
                   f"{x:.1f}" for x in case["load_average_at_end"]) + " at the end")
               + ".", ""] if "load_average_at_start" in case else []),
            "| method (iterations) | voxlab settings | peer (settings) | RMS voxlab | RMS peer "
            "| RMS ratio | ‖b − Ax‖ ratio | voxlab ms, all cores | voxlab ms, 1 thread "
            "| peer ms (1 thread) | time ratio, all cores | time ratio, 1 thread |",
            "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for g in case["groups"]:
            vx = g["voxlab"]
            label = f"{g['name']} ({g['iterations']} {g['unit']}{'es' if g['unit'] == 'pass' else 's'})"
            vset = f"`{vx['settings']}`"
            if "unavailable" in vx:
                lines.append(f"| {label} | {vset} | — | not run: {vx['unavailable']} "
                             "| | | | | | | | |")
                continue
            va, v1 = ms(vx), ms(vx, "one_thread")
            if not g["peers"]:
                lines.append(f"| {label} | {vset} | — | {vx['rms_circle']:.5f} | — | — | — | "
                             f"{f_ms(va)} | {f_ms(v1)} | — | — | — |")
            for p in g["peers"]:
                peer = f"{p['tool']}" + (f" ({p['settings']})" if p["settings"] else "")
                if "unavailable" in p:
                    lines.append(f"| {label} | {vset} | {peer}: not run: {p['unavailable']} "
                                 f"| {vx['rms_circle']:.5f} | | | | {f_ms(va)} | {f_ms(v1)} "
                                 "| | | |")
                    continue
                pm = ms(p)
                fr = (f"{vx['residual_norm'] / p['residual_norm']:.3f}"
                      if vx.get("residual_norm") and p.get("residual_norm") else "—")
                lines.append(
                    f"| {label} | {vset} | {peer} | {vx['rms_circle']:.5f} | "
                    f"{p['rms_circle']:.5f} | {vx['rms_circle'] / p['rms_circle']:.3f} | {fr} | "
                    f"{f_ms(va)} | {f_ms(v1)} | {f_ms(pm)} | {va / pm:.2f}× | {v1 / pm:.2f}× |")
    gl = res["goals"]
    n_acc = sum(a["met"] for a in gl["accuracy"])
    n_sp = sum(s["met"] for s in gl["speed"])
    lines += [
        "",
        "## Goals",
        "",
        f"**Accuracy** — voxlab's RMS within 5% of the peer's or lower at equal iterations "
        f"(ratio ≤ 1.05): met in {n_acc} of {len(gl['accuracy'])} comparisons.",
        "",
        "| views | method | peer | RMS voxlab | RMS peer | ratio | met |",
        "|---:|---|---|---:|---:|---:|---|",
        *[f"| {a['views']} | {a['group']} | {a['peer']} | {a['voxlab_rms']:.5f} | "
          f"{a['peer_rms']:.5f} | {a['ratio']:.3f} | {'yes' if a['met'] else '**no**'} |"
          for a in gl["accuracy"]],
        "",
        f"**Speed** — voxlab's CPU time per iteration ≤ 1/10 of ASTRA's CPU on 256² from 180 "
        f"views (ratio ≤ 0.10): met in {n_sp} of {len(gl['speed'])} comparisons "
        f"(on one thread: {sum(s['met_one_thread'] for s in gl['speed'])}).",
        "",
        "| method | ASTRA | voxlab ms, all cores | voxlab ms, 1 thread | ASTRA ms | ratio, all "
        "cores | ratio, 1 thread | met (all cores) | speed-up still needed for 0.10 |",
        "|---|---|---:|---:|---:|---:|---:|---|---:|",
        *[f"| {s['group']} | {s['peer']} | {s['voxlab_ms']:.1f} | "
          f"{s['voxlab_ms_one_thread']:.1f} | {s['peer_ms']:.1f} | {s['ratio']:.2f} | "
          f"{s['ratio_one_thread']:.2f} | {'yes' if s['met'] else '**no**'} | "
          f"{max(s['ratio'] / 0.1, 1.0):.1f}× |" for s in gl["speed"]],
        "",
    ]
    lines += reading(res) + [
        "## Conventions and notes",
        "",
    ]
    c180 = next((c for c in res["cases"] if c["views"] == 180), res["cases"][0])
    cv = c180["conventions"]
    sk_div = next((p.get("relaxation_1_rms_after_1_and_2_passes") for g in c180["groups"]
                   for p in g["peers"] if p["tool"].startswith("scikit-image")), None)
    lines += [
        "- ASTRA geometry (`astra_geometry` in the script): the conventions of",
        "  `bench_peers.astra_fbp` (angles negated, the volume window shifted half a pixel,",
        "  the image rows flipped back), as a `parallel_vec` geometry of exactly 256 bins",
        "  whose centre moves half a bin so that bin 128 lies on the rotation axis:",
        "  the same 256 rays per view as voxlab's, with ASTRA's `linear` (Joseph) projector,",
        "  the discretisation of voxlab's projector pair.",
        f"  Check ({c180['views']} views): ASTRA's forward projection of the truth differs "
        "from the exact",
        f"  sinogram by {100 * cv['fp_rel_l2_vs_exact_sinogram']:.2f}% (relative L2; "
        "scikit-image's `radon`: "
        f"{100 * cv['skimage_radon_rel_l2_vs_exact_sinogram']:.2f}%: the pixelisation",
        f"  of the skull; {100 * cv['fp_rel_l2_image_upside_down']:.0f}% with the image "
        "upside down), and from `astra_fbp`'s",
        "  257-bin `parallel` geometry (its first 256 bins) by at most "
        f"{cv['max_abs_diff_vs_astra_fbp_geometry']:.3f}",
        f"  (values up to {cv['sinogram_max']:.1f}).",
        "- SIRT weights: both use `x ← x + λ C Aᵀ R (b − A x)` with `R` = 1 / row sums (ray",
        "  lengths through the support) and `C` = 1 / column sums, λ = 1. ASTRA computes the",
        "  sums in float32 during the first forward projection of `run` (weights of sums",
        "  within ±1e-6 of zero set to 0); voxlab computes them with two extra projections",
        "  before the first iteration (a zero sum gives a zero weight) and counts them in",
        "  its time per iteration. Non-negativity: ASTRA's `MinConstraint 0` and voxlab's",
        "  `--nonnegative` both clamp after every update.",
        "- SART: ASTRA's `SART` counts one view as one iteration; N passes are",
        "  `run(alg, N × V)`, with `ProjectionOrder sequential` (views 0, 1, 2, …), the",
        "  order of voxlab's `--subsets V` (subset s holds view s). Both weigh every view's",
        "  update by its own column sums. voxlab's time per pass also includes one forward",
        "  projection of all views per pass for the residual it logs.",
        "- scikit-image's `iradon_sart` is single-view SART with its own projector",
        "  (it samples each ray at equidistant points with linear interpolation),",
        "  relaxation 0.15 by default, views in golden-ratio order",
        "  (`order_angles_golden_ratio`), float64 for a float64 sinogram; one call is one",
        "  pass (the previous image passed as `image`, which it updates in place).",
        *([f"  At relaxation 1 it diverges on this input (RMS {sk_div[0]:.1e} after one pass,",
           f"  {sk_div[1]:.1e} after two), so the λ = 1 rows have no scikit-image peer."]
          if sk_div else []),
        "- CGLS: both are plain CGLS on the normal equations from zero, restricted to the",
        "  disc; ASTRA's `CGLS` takes no non-negativity option, nor does voxlab's.",
        "- OS-SART with voxlab's defaults (10 subsets, λ = 1) has no",
        "  equal-settings peer here; it is listed for its accuracy per pass.",
        "",
        "Raw numbers (every run, thread counts, voxlab's output): "
        f"`{os.path.basename(os.path.splitext(path)[0])}.json`.",
        "",
    ]
    with open(path, "w") as fh:
        fh.write("\n".join(lines))


def command_line(args):
    """The command that reproduces this run's cases, as the page shows it."""
    cmd = "python3 scripts/peers/iterative_peers.py"
    if args.runs != 3:
        cmd += f" --runs {args.runs}"
    if args.views != "180,30":
        cmd += f" --views {args.views}"
    if args.merge:
        cmd += " --merge"
    return cmd


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--views", default="180,30", help="comma-separated view counts")
    bench_peers.add_common_arguments(
        ap, os.path.join("docs", "bench", "iterative-peers.md"),
        "keep the other view counts' cases of an existing --out JSON",
        "scratch folder (bench_peers.py's; ct_export's files in ct/)")
    args = bench_peers.parse_and_enter(ap, __file__, write_md)
    json_path = os.path.splitext(args.out)[0] + ".json"
    import numpy as np

    install = json.load(open(STAMP))["install"] if os.path.exists(STAMP) else {}
    ct = os.path.join(args.work, "ct")
    truth_path = os.path.join(ct, "truth2d.npy")
    if not os.path.exists(truth_path):
        bench_peers.ensure_binaries()
        subprocess.run([CT_EXPORT, ct], check=True)
    truth = np.load(truth_path)
    work = os.path.join(args.work, "iterative")
    os.makedirs(work, exist_ok=True)

    res = {"date_utc": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
           "runs": args.runs, "machine": bench_peers.machine(),
           "versions": bench_peers.versions(), "install": install,
           "voxlab_binary_mtime_utc": time.strftime(
               "%Y-%m-%d %H:%M UTC", time.gmtime(os.path.getmtime(VOXLAB))),
           "iterations": {"sirt": SIRT_IT, "cgls": CGLS_IT, "sart_passes": SART_PASSES},
           "cases": []}
    t0 = time.perf_counter()
    for views in (int(x) for x in args.views.split(",")):
        start = (time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), os.getloadavg())
        case = run_case(work, views, truth, args.runs)
        case.update(date_utc=start[0], load_average_at_start=start[1],
                    load_average_at_end=os.getloadavg())
        res["cases"].append(case)
    res["total_s"] = time.perf_counter() - t0
    res["commands"] = [command_line(args)]
    if args.merge and os.path.exists(json_path):
        old = json.load(open(json_path))
        done = {c["views"] for c in res["cases"]}
        kept = [c for c in old["cases"] if c["views"] not in done]
        if kept:
            for c in kept:  # cases from before per-case dates and loads were recorded
                c.setdefault("date_utc", old["date_utc"])
                if c is old["cases"][0]:
                    c.setdefault("load_average_at_start",
                                 old["machine"]["load_average_at_start"])
            res["cases"] = sorted(kept + res["cases"], key=lambda c: -c["views"])
            res["commands"] = old.get("commands", ["python3 scripts/peers/iterative_peers.py"]) \
                + res["commands"]
    if time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime(os.path.getmtime(VOXLAB))) != \
            res["voxlab_binary_mtime_utc"]:
        res["warning"] = "target/release/voxlab changed during the run"
        print(f"warning: {res['warning']}", file=sys.stderr)
    res["machine"]["load_average_at_end"] = os.getloadavg()
    res["goals"] = goals(res)
    checks = [g["voxlab"]["truth_check_abs_diff"] for c in res["cases"] for g in c["groups"]
              if "truth_check_abs_diff" in g["voxlab"]]
    res["truth_check_max_abs_diff"] = max(checks) if checks else float("nan")
    if checks and max(checks) > 2e-6:
        print(f"warning: voxlab's printed RMS and this script's differ by {max(checks):.2e}",
              file=sys.stderr)
    ratios = [c / w for case in res["cases"] for g in case["groups"] for p in g["peers"]
              if p["tool"].startswith("ASTRA") and "unavailable" not in p
              for c, w in zip(p["cpu_ms_per_iteration"], p["ms_per_iteration"])]
    res["astra_cpu_over_wall"] = statistics.median(ratios) if ratios else float("nan")
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(json_path, "w") as fh:
        json.dump(res, fh, indent=1)
        fh.write("\n")
    write_md(res, args.out)
    print(f"wrote {args.out} and {json_path} in {res['total_s']:.0f} s", file=sys.stderr)


if __name__ == "__main__":
    main()
