"""Independent reference numbers for tests/io_tiff.rs, computed with tifffile + numpy.

Run from the repository root:  python tests/data/tiff_reference.py

Prints, for data/microct-bone/bone_128x128x128.tif: the page count and page shape,
dtype, min, max, sum, and a weighted sum sum(v[i] * (i % 251 + 1)) over the voxels
in x-fastest order (i = flat index of the (z, y, x) array), plus the tags that give
the spacing (ImageDescription, resolution).
"""
import numpy as np
import tifffile

path = "data/microct-bone/bone_128x128x128.tif"
with tifffile.TiffFile(path) as tif:
    print(f"pages: {len(tif.pages)}, page shape {tif.pages[0].shape}, dtype {tif.pages[0].dtype}")
    p = tif.pages[0]
    for name in ["ImageDescription", "XResolution", "YResolution", "ResolutionUnit", "Compression"]:
        t = p.tags.get(name)
        print(f"  {name}: {t.value if t is not None else None!r}")
    vol = tif.asarray()
flat = vol.reshape(-1).astype(np.float64)
w = (np.arange(flat.size) % 251 + 1).astype(np.float64)
print(f"shape (z,y,x) = {vol.shape}, dtype {vol.dtype}")
print(f"min = {flat.min():.6g}  max = {flat.max():.6g}  sum = {flat.sum():.17g}")
print(f"weighted sum = {(flat * w).sum():.17g}")
print(f"voxel (x=10, y=20, z=30) = {vol[30, 20, 10]}")
