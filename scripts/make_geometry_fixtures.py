#!/usr/bin/env python3
"""Geometry-file fixtures from the peers themselves: RTK's geometry XML and ASTRA's
proj_geom, with the numbers each peer computes from them, into tests/data/ct/.

    python3 -m venv target/rtk-venv
    target/rtk-venv/bin/pip install itk-rtk numpy astra-toolbox
    target/rtk-venv/bin/python scripts/make_geometry_fixtures.py

RTK (itk-rtk): three geometries built with ThreeDCircularProjectionGeometry.AddProjection
and written by ThreeDCircularProjectionGeometryXMLFileWriter (`rtk_<name>.xml`); for
each, `rtk_<name>.json` records the projection grid used (size, spacing, origin of the
projection image), RTK's 3x4 matrices (GetMatrix), RTK's source positions
(GetSourcePosition) and the world positions of detector pixels (0,0), (1,0) and (0,1)
(GetProjectionCoordinatesToFixedSystemMatrix applied to the pixels' physical
coordinates), and `rtk_<name>_ellipsoids.mha` holds RTK's exact projections
(RayEllipsoidIntersectionImageFilter, in double, stored as float32) of two ellipsoids,
on that grid.

ASTRA (astra-toolbox): a `cone` and a `parallel3d` proj_geom as JSON
(`astra_cone.json`, `astra_parallel3d.json`), and ASTRA's own geom_2vec of each
(`astra_cone_vec.json`, `astra_parallel3d_vec.json`).

No random numbers; the versions used are recorded in `geometry_fixtures.json`.
"""

import json
import os
import sys

import numpy as np

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "data", "ct")

# Two axis-aligned ellipsoids (density, centre mm, semi-axes mm), RTK's world frame.
ELLIPSOIDS = [
    (1.0, (5.0, -3.0, 4.0), (30.0, 25.0, 20.0)),
    (0.5, (-12.0, 8.0, -6.0), (10.0, 12.0, 8.0)),
]


def rtk_cases():
    """name -> (projections [(sid, sdd, gantry, px, py, oop, inplane, sx, sy)], grid)."""
    circular = [(600.0, 900.0, 30.0 * k, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0) for k in range(12)]
    gantry = [0.0, 37.0, 81.0, 130.0, 175.0, 222.0, 260.0, 313.0]
    tilted = []
    for k, a in enumerate(gantry):
        tilted.append(
            (
                590.0 + 3.0 * k,  # SID per view
                880.0 + 5.5 * k,  # SDD per view
                a,
                4.0 - 1.25 * k,  # ProjectionOffsetX
                -2.5 + 0.75 * k,  # ProjectionOffsetY
                -6.0 + 1.5 * k,  # OutOfPlaneAngle (degrees)
                3.0 - 0.8 * k,  # InPlaneAngle (degrees)
                1.5 - 0.5 * k,  # SourceOffsetX
                -1.0 + 0.3 * k,  # SourceOffsetY
            )
        )
    parallel = []
    for k in range(8):
        parallel.append((500.0, 0.0, 22.5 * k, 3.0 - k, -1.5 + 0.5 * k, 0.0, 2.0, 0.7, -0.4))
    centred = lambda cols, rows, du, dv: (-(cols - 1) / 2.0 * du, -(rows - 1) / 2.0 * dv, 0.0)
    return {
        "circular": (circular, {"size": [24, 20], "spacing": [4.0, 4.0], "origin": centred(24, 20, 4.0, 4.0)}),
        "tilted": (tilted, {"size": [24, 20], "spacing": [4.0, 3.5], "origin": (-40.0, -30.0, 0.0)}),
        "parallel": (parallel, {"size": [24, 20], "spacing": [4.0, 4.0], "origin": centred(24, 20, 4.0, 4.0)}),
    }


def matrix(m):
    import itk

    return itk.array_from_vnl_matrix(m.GetVnlMatrix().as_matrix()).tolist()


def make_rtk(versions):
    import itk
    from itk import RTK as rtk

    for name, (projs, grid) in rtk_cases().items():
        g = rtk.ThreeDCircularProjectionGeometry.New()
        for p in projs:
            g.AddProjection(*[float(x) for x in p])
        xml = os.path.join(OUT, f"rtk_{name}.xml")
        w = rtk.ThreeDCircularProjectionGeometryXMLFileWriter.New()
        w.SetFilename(xml)
        w.SetObject(g)
        w.WriteFile()
        # RTK reads its own file back (and checks the matrices against the parameters).
        back = rtk.ThreeDCircularProjectionGeometryXMLFileReader.New()
        back.SetFilename(xml)
        back.GenerateOutputInformation()

        cols, rows = grid["size"]
        du, dv = grid["spacing"]
        ox, oy, _ = grid["origin"]
        record = {
            "xml": os.path.basename(xml),
            "projection_image": {
                "size": [cols, rows, len(projs)],
                "spacing": [du, dv, 1.0],
                "origin": list(grid["origin"]),
                "direction": "identity",
            },
            "parameters": [
                dict(
                    zip(
                        [
                            "sid",
                            "sdd",
                            "gantry_deg",
                            "projection_offset_x",
                            "projection_offset_y",
                            "out_of_plane_deg",
                            "in_plane_deg",
                            "source_offset_x",
                            "source_offset_y",
                        ],
                        p,
                    )
                )
                for p in projs
            ],
            "matrices": [],
            "source_positions": [],
            "pixel_positions": [],
        }
        for k in range(len(projs)):
            record["matrices"].append(matrix(g.GetMatrix(k)))
            s = g.GetSourcePosition(k)
            record["source_positions"].append([float(s[i]) for i in range(3)])
            m = np.array(matrix(g.GetProjectionCoordinatesToFixedSystemMatrix(k)))
            pix = []
            for c, r in [(0, 0), (1, 0), (0, 1)]:
                q = m @ np.array([ox + c * du, oy + r * dv, 0.0, 1.0])
                pix.append(q[:3].tolist())
            record["pixel_positions"].append(pix)

        # RTK's exact line integrals of the ellipsoids, on the projection grid.
        ImageType = itk.Image[itk.D, 3]
        zeros = itk.image_from_array(np.zeros((len(projs), rows, cols)))
        zeros.SetSpacing([du, dv, 1.0])
        zeros.SetOrigin([float(o) for o in grid["origin"]])
        img = zeros
        for rho, c, a in ELLIPSOIDS:
            f = rtk.RayEllipsoidIntersectionImageFilter[ImageType, ImageType].New()
            f.SetInput(img)
            f.SetGeometry(g)
            f.SetDensity(rho)
            f.SetCenter(c)
            f.SetAxis(a)
            f.Update()
            img = f.GetOutput()
        arr = itk.array_from_image(img)
        out = itk.image_from_array(arr.astype(np.float32))
        out.SetSpacing([du, dv, 1.0])
        out.SetOrigin([float(o) for o in grid["origin"]])
        mha = os.path.join(OUT, f"rtk_{name}_ellipsoids.mha")
        itk.imwrite(out, mha, compression=True)
        record["ellipsoids"] = [{"density": r, "center": list(c), "semi_axes": list(a)} for r, c, a in ELLIPSOIDS]
        record["ellipsoid_projections"] = {
            "file": os.path.basename(mha),
            "shape_angle_row_col": list(arr.shape),
            "max": float(arr.max()),
        }
        record["versions"] = versions
        with open(os.path.join(OUT, f"rtk_{name}.json"), "w") as fh:
            json.dump(record, fh, indent=1)
            fh.write("\n")
        print(f"rtk_{name}: {len(projs)} views, max line integral {arr.max():.4f}")


def jsonable(geom):
    return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in geom.items()}


def make_astra():
    import astra

    angles = np.linspace(0.0, 2.0 * np.pi, 10, endpoint=False) + 0.1
    cone = astra.create_proj_geom("cone", 1.5, 2.0, 20, 24, angles, 800.0, 400.0)
    par = astra.create_proj_geom("parallel3d", 1.25, 0.75, 18, 22, np.linspace(0.0, np.pi, 9, endpoint=False))
    for name, geom in [("cone", cone), ("parallel3d", par)]:
        with open(os.path.join(OUT, f"astra_{name}.json"), "w") as fh:
            json.dump(jsonable(geom), fh, indent=1)
            fh.write("\n")
        vec = astra.functions.geom_2vec(geom)
        with open(os.path.join(OUT, f"astra_{name}_vec.json"), "w") as fh:
            json.dump(jsonable(vec), fh, indent=1)
            fh.write("\n")
        print(f"astra_{name}: {vec['type']}, {len(vec['Vectors'])} views")


def main():
    import itk

    import astra

    versions = {
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "itk": itk.Version.GetITKVersion(),
        "itk-rtk": __import__("importlib.metadata").metadata.version("itk-rtk"),
        "astra-toolbox": astra.__version__,
    }
    os.makedirs(OUT, exist_ok=True)
    make_rtk(versions)
    make_astra()
    with open(os.path.join(OUT, "geometry_fixtures.json"), "w") as fh:
        json.dump({"script": "scripts/make_geometry_fixtures.py", "versions": versions}, fh, indent=1)
        fh.write("\n")


if __name__ == "__main__":
    main()
