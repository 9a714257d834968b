#!/usr/bin/env python3
"""Makes the small CT peer fixtures in tests/data/ct/ (scikit-image and RTK).

Usage (from the repository root):

    python3 -m venv /tmp/venv-ct
    /tmp/venv-ct/bin/pip install -r scripts/peers/requirements-ct.txt
    /tmp/venv-ct/bin/python scripts/peers/make_ct_fixtures.py [--out tests/data/ct] [--no-rtk]

Everything is deterministic (no random numbers). See tests/data/ct/README.md for
what each file holds and the conventions.
"""

import argparse
import json
import os
import sys

import numpy as np
import skimage
from numpy.fft import fft, ifft
from skimage.data import shepp_logan_phantom
from skimage.transform import iradon, radon, resize
from skimage.transform.radon_transform import (
    _get_fourier_filter,
    _sinogram_circle_to_square,
)

FILTERS = ["ramp", "shepp-logan", "cosine", "hamming", "hann"]


# --------------------------------------------------------------------------------------
# scikit-image (parallel beam, 2-D)
# --------------------------------------------------------------------------------------


def circle_mask(n):
    """radon(circle=True)'s reconstruction circle: (r - n//2)^2 + (c - n//2)^2 <= (n//2)^2."""
    r = np.arange(n)[:, None] - n // 2
    c = np.arange(n)[None, :] - n // 2
    return r * r + c * c <= (n // 2) ** 2


def test_image(n):
    """scikit-image's Shepp-Logan (400x400) resized to n x n with anti-aliasing, zero
    outside radon's inscribed circle."""
    img = resize(shepp_logan_phantom(), (n, n), order=1, anti_aliasing=True, mode="reflect")
    img = img.astype(np.float64)
    img[~circle_mask(n)] = 0.0
    return img


def filtered_ramp(sino):
    """The ramp-filtered sinogram iradon backprojects, on the sinogram's own n bins.

    iradon (circle=True) first zero-pads the sinogram to ceil(sqrt(2) n) bins keeping
    bin n//2 at the new centre, zero-pads again to P = max(64, 2^ceil(log2(2 ceil(sqrt(2)n)))),
    multiplies the FFT by _get_fourier_filter(P, 'ramp') and crops. The ramp kernel
    (Kak & Slaney ch. 3 eq. 61) is exact for every lag below P/2, so this equals the
    linear convolution of the n-bin sinogram with 2 f, f[0] = 1/4, f[k odd] = -1/(pi k)^2
    -- the same for any padding >= 2n. Returned cropped back to the original n bins.
    """
    n = sino.shape[0]
    sq = _sinogram_circle_to_square(sino)
    m = sq.shape[0]
    p = max(64, int(2 ** np.ceil(np.log2(2 * m))))
    img = np.pad(sq, ((0, p - m), (0, 0)))
    filt = np.real(ifft(fft(img, axis=0) * _get_fourier_filter(p, "ramp"), axis=0))[:m]
    before = m // 2 - n // 2
    out = filt[before : before + n]

    # Cross-check: the direct recipe on the unpadded n bins gives the same numbers.
    p2 = max(64, int(2 ** np.ceil(np.log2(2 * n))))
    img2 = np.pad(sino, ((0, p2 - n), (0, 0)))
    out2 = np.real(ifft(fft(img2, axis=0) * _get_fourier_filter(p2, "ramp"), axis=0))[:n]
    assert np.max(np.abs(out - out2)) < 1e-12 * np.max(np.abs(out)), "ramp padding mismatch"
    return out, filt


def backproject_like_iradon(filt_sq, theta, n):
    """iradon's linear backprojection of an already filtered, square-padded sinogram."""
    m = filt_sq.shape[0]
    rec = np.zeros((n, n))
    radius = n // 2
    xpr, ypr = np.mgrid[:n, :n] - radius
    x = np.arange(m) - m // 2
    for col, a in zip(filt_sq.T, np.deg2rad(theta)):
        t = ypr * np.cos(a) - xpr * np.sin(a)
        rec += np.interp(t, x, col, left=0, right=0)
    rec[(xpr**2 + ypr**2) > radius**2] = 0.0
    return rec * np.pi / (2 * len(theta))


def make_skimage(out, theta):
    made = []
    for n in (64, 63):
        img = test_image(n)
        sino = radon(img, theta=theta, circle=True)
        assert sino.shape == (n, len(theta))
        np.save(os.path.join(out, f"skimage_image{n}.npy"), img)
        np.save(os.path.join(out, f"skimage_radon{n}.npy"), sino)
        made += [f"skimage_image{n}.npy", f"skimage_radon{n}.npy"]
        for f in FILTERS:
            rec = iradon(sino, theta=theta, filter_name=f, interpolation="linear", circle=True)
            assert rec.shape == (n, n)
            name = f"skimage_iradon{n}_{f}.npy"
            np.save(os.path.join(out, name), rec)
            made.append(name)
            if f == "ramp":
                filt, filt_sq = filtered_ramp(sino)
                # Backprojecting the filtered sinogram reproduces iradon exactly.
                again = backproject_like_iradon(filt_sq, theta, n)
                err = np.max(np.abs(again - rec))
                assert err < 1e-12 * np.max(np.abs(rec)), f"backprojection mismatch {err}"
                name = f"skimage_filtered{n}_ramp.npy"
                np.save(os.path.join(out, name), filt)
                made.append(name)
    with open(os.path.join(out, "skimage_theta.txt"), "w") as fh:
        for t in theta:
            fh.write(f"{float(t)!r}\n")
    made.append("skimage_theta.txt")
    return made


# --------------------------------------------------------------------------------------
# RTK (circular cone beam, 3-D)
# --------------------------------------------------------------------------------------

N3 = 32
SPACING3 = 2.0
SID, SDD = 1000.0, 1500.0
COLS, ROWS, DU, DV = 48, 40, 3.0, 3.0
N_PROJ = 60

# Ellipsoids (density, centre mm, semi-axes mm) in RTK world coordinates (x, y, z);
# y is the rotation axis. Axis-aligned, sampled exactly at voxel centres (value = sum of
# the densities of the ellipsoids containing the centre).
ELLIPSOIDS = [
    (1.0, (0.0, 0.0, 0.0), (24.0, 26.0, 20.0)),
    (-0.5, (-6.0, 4.0, 3.0), (8.0, 12.0, 6.0)),
    (0.8, (10.0, -8.0, -5.0), (5.0, 5.0, 5.0)),
    (0.3, (-4.0, -12.0, 8.0), (6.0, 4.0, 4.0)),
]


def rtk_grid_axis(n, spacing):
    return (np.arange(n) - (n - 1) / 2.0) * spacing


def rtk_volume():
    ax = rtk_grid_axis(N3, SPACING3)
    z, y, x = np.meshgrid(ax, ax, ax, indexing="ij")  # NumPy order (z, y, x)
    vol = np.zeros((N3, N3, N3))
    for rho, c, r in ELLIPSOIDS:
        q = ((x - c[0]) / r[0]) ** 2 + ((y - c[1]) / r[1]) ** 2 + ((z - c[2]) / r[2]) ** 2
        vol[q <= 1.0] += rho
    return vol


def to_itk(arr, spacing, origin):
    import itk

    img = itk.image_from_array(np.ascontiguousarray(arr, dtype=np.float32))
    img.SetSpacing([float(s) for s in spacing])
    img.SetOrigin([float(o) for o in origin])
    return img


def rtk_geometry(angles, sid=SID, sdd=SDD):
    from itk import RTK as rtk

    g = rtk.ThreeDCircularProjectionGeometry.New()
    for a in angles:
        g.AddProjection(float(sid), float(sdd), float(a))  # gantry angle in degrees, no offsets
    return g


def proj_origin():
    return (-(COLS - 1) / 2.0 * DU, -(ROWS - 1) / 2.0 * DV, 0.0)


def rtk_joseph(vol, angles):
    import itk
    from itk import RTK as rtk

    ImageType = itk.Image[itk.F, 3]
    o3 = -(N3 - 1) / 2.0 * SPACING3
    vimg = to_itk(vol, (SPACING3,) * 3, (o3,) * 3)
    zeros = to_itk(np.zeros((len(angles), ROWS, COLS)), (DU, DV, 1.0), proj_origin())
    fp = rtk.JosephForwardProjectionImageFilter[ImageType, ImageType].New()
    fp.SetInput(0, zeros)
    fp.SetInput(1, vimg)
    fp.SetGeometry(rtk_geometry(angles))
    fp.Update()
    return itk.array_from_image(fp.GetOutput()).astype(np.float64)


def rtk_fdk(proj, angles, n, spacing, hann=0.0, du=DU, dv=DV, sid=SID, sdd=SDD):
    """RTK FDK of proj (angle, row, col), detector centred with pixel pitch du x dv mm,
    onto an n^3 grid, RTK-centred; ramp filter with the Hann window cut at `hann`
    (0 = plain ramp, RTK's default)."""
    import itk
    from itk import RTK as rtk

    ImageType = itk.Image[itk.F, 3]
    o3 = -(n - 1) / 2.0 * spacing
    grid = to_itk(np.zeros((n, n, n)), (spacing,) * 3, (o3,) * 3)
    _, rows, cols = proj.shape
    pimg = to_itk(proj, (du, dv, 1.0), (-(cols - 1) / 2.0 * du, -(rows - 1) / 2.0 * dv, 0.0))
    fdk = rtk.FDKConeBeamReconstructionFilter[ImageType].New()
    fdk.SetInput(0, grid)
    fdk.SetInput(1, pimg)
    fdk.SetGeometry(rtk_geometry(angles, sid, sdd))
    fdk.GetRampFilter().SetTruncationCorrection(0.0)
    fdk.GetRampFilter().SetHannCutFrequency(hann)
    fdk.Update()
    return itk.array_from_image(fdk.GetOutput()).astype(np.float64)


def formula_uv(p, a_deg):
    """src/ct.rs: u = m P.e_u, v = m P.e_v, m = SDD/(SID - P.e_w)."""
    a = np.deg2rad(a_deg)
    eu = np.array([np.cos(a), 0.0, -np.sin(a)])
    ew = np.array([np.sin(a), 0.0, np.cos(a)])
    m = SDD / (SID - p @ ew)
    return m * (p @ eu), m * p[1]


def verify_angle_convention():
    """Project a small off-centre ball with RTK's Joseph projector and compare each
    projection's centroid with src/ct.rs's formula. Returns the worst error in mm."""
    p = np.array([20.0, 12.0, -14.0])  # mm, RTK world (x, y, z)
    ax = rtk_grid_axis(N3, SPACING3)
    z, y, x = np.meshgrid(ax, ax, ax, indexing="ij")
    ball = (((x - p[0]) ** 2 + (y - p[1]) ** 2 + (z - p[2]) ** 2) <= 3.5**2).astype(float)
    # The ball's voxel centroid (the voxelised ball is symmetric about p only approximately).
    w = ball.sum()
    pc = np.array([(x * ball).sum() / w, (y * ball).sum() / w, (z * ball).sum() / w])
    angles = [0.0, 30.0, 90.0, 150.0, 200.0, 270.0, 333.0]
    proj = rtk_joseph(ball, angles)
    u_ax = (np.arange(COLS) - (COLS - 1) / 2.0) * DU
    v_ax = (np.arange(ROWS) - (ROWS - 1) / 2.0) * DV
    worst = 0.0
    rows = []
    for k, a in enumerate(angles):
        img = proj[k]
        s = img.sum()
        u = (img.sum(axis=0) * u_ax).sum() / s
        v = (img.sum(axis=1) * v_ax).sum() / s
        fu, fv = formula_uv(pc, a)
        worst = max(worst, abs(u - fu), abs(v - fv))
        rows.append((a, u, v, fu, fv))
    return pc, rows, worst


def verify_projection_matrix():
    """RTK's own 3x4 projection matrices (world mm -> detector mm, homogeneous) against
    src/ct.rs's formula on a few points and angles. Returns the worst error in mm."""
    import itk

    angles = [0.0, 30.0, 90.0, 150.0, 200.0, 270.0, 333.0]
    g = rtk_geometry(angles)
    worst = 0.0
    for k, a in enumerate(angles):
        m = itk.array_from_vnl_matrix(g.GetMatrix(k).GetVnlMatrix().as_matrix())
        for p in ([20.0, 12.0, -14.0], [-31.0, -5.0, 40.0], [0.0, 0.0, 0.0]):
            q = m @ np.array(p + [1.0])
            fu, fv = formula_uv(np.array(p), a)
            worst = max(worst, abs(q[0] / q[2] - fu), abs(q[1] / q[2] - fv))
    return worst


def make_rtk(out):
    import itk

    angles = [k * 360.0 / N_PROJ for k in range(N_PROJ)]
    vol = rtk_volume()
    proj = rtk_joseph(vol, angles)
    assert proj.shape == (N_PROJ, ROWS, COLS)
    fdk = rtk_fdk(proj, angles, N3, SPACING3, hann=0.0)
    fdk_hann = rtk_fdk(proj, angles, N3, SPACING3, hann=1.0)
    np.save(os.path.join(out, "rtk_volume32.npy"), vol)
    # RTK's Python filters run in float32: storing their outputs as float32 is exact
    # and halves the fixtures' size.
    np.save(os.path.join(out, "rtk_joseph32.npy"), proj.astype(np.float32))
    np.save(os.path.join(out, "rtk_fdk32.npy"), fdk.astype(np.float32))
    np.save(os.path.join(out, "rtk_fdk32_hann.npy"), fdk_hann.astype(np.float32))
    pc, conv_rows, worst = verify_angle_convention()
    worst_matrix = verify_projection_matrix()
    assert worst < 0.2 and worst_matrix < 1e-9, (worst, worst_matrix)
    geom = {
        "beam": "cone",
        "sid": SID,
        "sdd": SDD,
        "cols": COLS,
        "rows": ROWS,
        "du": DU,
        "dv": DV,
        "cu": (COLS - 1) / 2.0,
        "cv": (ROWS - 1) / 2.0,
        "angles_deg": angles,
        "volume": {
            "shape_zyx": [N3, N3, N3],
            "spacing_mm": SPACING3,
            "origin_mm": -(N3 - 1) / 2.0 * SPACING3,
            "ellipsoids_density_centre_semiaxes_xyz_mm": [
                [rho, list(c), list(r)] for rho, c, r in ELLIPSOIDS
            ],
        },
        "fdk": {"rtk_fdk32.npy": {"hann_cut": 0.0}, "rtk_fdk32_hann.npy": {"hann_cut": 1.0},
                "truncation_correction": 0.0},
        "angle_check": {
            "ball_centroid_mm": pc.tolist(),
            "angles_deg_u_v_formula_u_v_mm": [list(map(float, r)) for r in conv_rows],
            "worst_error_mm": worst,
            "projection_matrix_worst_error_mm": worst_matrix,
        },
        "versions": versions(),
    }
    with open(os.path.join(out, "rtk_geometry.json"), "w") as fh:
        json.dump(geom, fh, indent=1)
        fh.write("\n")
    print(f"RTK angle check: worst |centroid - formula| = {worst:.4f} mm, "
          f"|projection matrix - formula| = {worst_matrix:.2e} mm")
    for r in conv_rows:
        print("  a=%6.1f  RTK (u,v)=(%8.3f,%8.3f)  formula=(%8.3f,%8.3f)" % r)
    return ["rtk_volume32.npy", "rtk_joseph32.npy", "rtk_fdk32.npy", "rtk_fdk32_hann.npy",
            "rtk_geometry.json"] + make_rtk_perview(out, vol)


# Per-view geometry: the same volume through an orbit whose every view differs (SID, SDD,
# detector shifts and an in-plane tilt changing with the angle), written by RTK's own XML
# writer; RTK's Joseph projections of it and RTK's FDK of those.
N_PERVIEW = 60


def perview_parameters(a_deg):
    """(SID, SDD, gantry, out-of-plane, in-plane, source offset x, y, projection
    offset x, y) of the view at gantry angle a_deg (RTK's AddProjection order)."""
    a = np.deg2rad(a_deg)
    return (SID + 40.0 * np.sin(a), SDD + 25.0 * np.cos(2.0 * a), a_deg, 0.0,
            2.0 + 1.0 * np.cos(a), 0.0, 0.0, 6.0 + 2.0 * np.sin(a), -4.5 + 1.5 * np.cos(a))


def rtk_perview_geometry(angles):
    from itk import RTK as rtk

    g = rtk.ThreeDCircularProjectionGeometry.New()
    for a in angles:
        sid, sdd, ga, oop, ip, sx, sy, px, py = (float(v) for v in perview_parameters(a))
        g.AddProjection(sid, sdd, ga, px, py, oop, ip, sx, sy)
    return g


def make_rtk_perview(out, vol):
    import itk
    from itk import RTK as rtk

    ImageType = itk.Image[itk.F, 3]
    angles = [360.0 * k / N_PERVIEW for k in range(N_PERVIEW)]
    geometry = rtk_perview_geometry(angles)
    o3 = -(N3 - 1) / 2.0 * SPACING3
    vimg = to_itk(vol, (SPACING3,) * 3, (o3,) * 3)
    zeros = to_itk(np.zeros((N_PERVIEW, ROWS, COLS)), (DU, DV, 1.0), proj_origin())
    fp = rtk.JosephForwardProjectionImageFilter[ImageType, ImageType].New()
    fp.SetInput(0, zeros)
    fp.SetInput(1, vimg)
    fp.SetGeometry(geometry)
    fp.Update()
    proj = itk.array_from_image(fp.GetOutput()).astype(np.float32)
    grid = to_itk(np.zeros((N3, N3, N3)), (SPACING3,) * 3, (o3,) * 3)
    fdk = rtk.FDKConeBeamReconstructionFilter[ImageType].New()
    fdk.SetInput(0, grid)
    fdk.SetInput(1, to_itk(proj, (DU, DV, 1.0), proj_origin()))
    fdk.SetGeometry(geometry)
    fdk.GetRampFilter().SetTruncationCorrection(0.0)
    fdk.Update()
    rec = itk.array_from_image(fdk.GetOutput()).astype(np.float32)
    writer = rtk.ThreeDCircularProjectionGeometryXMLFileWriter.New()
    writer.SetFilename(os.path.join(out, "rtk_perview_geometry.xml"))
    writer.SetObject(geometry)
    writer.WriteFile()
    np.save(os.path.join(out, "rtk_perview_joseph32.npy"), proj)
    np.save(os.path.join(out, "rtk_perview_fdk32.npy"), rec)
    rms = float(np.sqrt(np.mean((rec.astype(np.float64) - vol) ** 2)))
    print(f"RTK per-view FDK: RMS against the volume {rms:.5f}")
    return ["rtk_perview_geometry.xml", "rtk_perview_joseph32.npy", "rtk_perview_fdk32.npy"]


def versions():
    v = {"python": sys.version.split()[0], "numpy": np.__version__,
         "scikit-image": skimage.__version__}
    try:
        import itk
        from importlib.metadata import version

        v["itk"] = itk.Version.GetITKVersion()
        v["itk-rtk"] = version("itk-rtk")
    except Exception:  # RTK not installed
        pass
    return v


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="tests/data/ct")
    ap.add_argument("--no-rtk", action="store_true")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    theta = np.linspace(0.0, 180.0, 45, endpoint=False)  # 4 degrees apart
    made = make_skimage(args.out, theta)
    if not args.no_rtk:
        made += make_rtk(args.out)
    print("versions:", json.dumps(versions()))
    total = sum(os.path.getsize(os.path.join(args.out, f)) for f in made)
    print(f"wrote {len(made)} files, {total / 1024:.0f} KiB, to {args.out}")


if __name__ == "__main__":
    main()
