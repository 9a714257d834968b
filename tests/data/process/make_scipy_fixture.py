"""Makes scipy_fixture.json: scipy.ndimage.gaussian_filter, median_filter and a
gradient magnitude from correlate1d of a fixed 6×5×4 (x×y×z) array, the reference
numbers of tests/process.rs.

voxlab stores volumes x fastest, i.e. as the NumPy array of shape (nz, ny, nx); so
sigma_xyz = (sx, sy, sz) is scipy's sigma=(sz, sy, sx). Run: python3 make_scipy_fixture.py
"""
import json

import numpy as np
import scipy
from scipy import ndimage

nx, ny, nz = 6, 5, 4
# A fixed, exactly representable (in f32) pattern: no random generator involved.
i = np.arange(nx * ny * nz)
a = (((i * 37) % 23) - 7.0) / 4.0
a = a.astype(np.float32).reshape(nz, ny, nx)

out = {
    "scipy_version": scipy.__version__,
    "dims_xyz": [nx, ny, nz],
    "input": a.ravel().astype(float).tolist(),
    "gaussian": [],
    "median": [],
}
for sx, sy, sz in [(1.0, 1.0, 1.0), (0.7, 1.3, 2.2), (0.4, 0.4, 0.4)]:
    g = ndimage.gaussian_filter(a.astype(np.float64), sigma=(sz, sy, sx), mode="reflect", truncate=4.0)
    out["gaussian"].append({"sigma_xyz": [sx, sy, sz], "output": g.ravel().tolist()})
for size in [3, 5]:
    m = ndimage.median_filter(a.astype(np.float64), size=size, mode="reflect")
    out["median"].append({"size": size, "output": m.ravel().tolist()})

# Gradient magnitude in value per mm: central differences, reflect borders, spacing
# (sx, sy, sz) = (2, 0.5, 4) mm, i.e. (4, 0.5, 2) in NumPy axis order.
sx, sy, sz = 2.0, 0.5, 4.0
g = sum(
    (ndimage.correlate1d(a.astype(np.float64), [-0.5, 0.0, 0.5], axis=ax, mode="reflect") / s) ** 2
    for ax, s in zip(range(3), (sz, sy, sx))
)
out["gradient_magnitude"] = {"spacing_xyz": [sx, sy, sz], "output": np.sqrt(g).ravel().tolist()}

with open("scipy_fixture.json", "w") as f:
    json.dump(out, f)
