"""Writes the small NIfTI-1 fixtures of tests/io_nifti.rs with nibabel, and
expected.json: for each file nibabel's `img.affine`, its shape and every voxel value
as `img.get_fdata()` returns it (x fastest, i.e. Fortran order), so that the Rust
reader can be checked against an independent implementation.

Run from this directory:  python make_fixtures.py   (needs nibabel and numpy)
"""

import json
import struct

import nibabel as nib
import numpy as np


def rotation(axis, angle):
    axis = np.asarray(axis, float)
    axis /= np.linalg.norm(axis)
    x, y, z = axis
    c, s = np.cos(angle), np.sin(angle)
    C = 1 - c
    return np.array(
        [
            [c + x * x * C, x * y * C - z * s, x * z * C + y * s],
            [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
            [z * x * C - y * s, z * y * C + x * s, c + z * z * C],
        ]
    )


def affine(rot, zooms, offset):
    a = np.eye(4)
    a[:3, :3] = rot @ np.diag(zooms)
    a[:3, 3] = offset
    return a


shape = (6, 5, 4)
ramp = np.arange(np.prod(shape)).reshape(shape, order="F")
fixtures = {}

# 1. int16, gzip, oblique sform (code 2) and a different qform (code 1): the sform wins.
data = ((ramp * 37) % 2000 - 1000).astype(np.int16)
img = nib.Nifti1Image(data, None)
img.set_sform(affine(rotation([1, 2, 3], 0.4), [0.9, 1.1, 2.5], [-40.5, 12.25, 7.0]), code=2)
img.set_qform(affine(np.eye(3), [1, 1, 1], [0, 0, 0]), code=1)
nib.save(img, "sform_i16.nii.gz")
fixtures["sform_i16.nii.gz"] = img

# 2. uint8, big-endian, qform only (code 1) with a reflection (qfac -1), sform code 0.
data = (ramp * 11 % 256).astype(np.uint8)
hdr = nib.Nifti1Header(endianness=">")
img = nib.Nifti1Image(data, None, header=hdr)
img.set_data_dtype(np.uint8)
flip = rotation([0.2, -1, 0.5], 2.1) @ np.diag([1, 1, -1])
img.set_qform(affine(flip, [1.5, 0.75, 3.0], [10.0, -20.0, 30.5]), code=1)
img.set_sform(None, code=0)
nib.save(img, "qform_u8_be.nii")
fixtures["qform_u8_be.nii"] = img

# 3. int16 scaled by scl_slope 0.25, scl_inter -10 (stored raw), sform and qform.
raw = ((ramp * 53) % 4000 - 2000).astype(np.int16)
aff = affine(rotation([0, 0, 1], -0.3), [2, 2, 2], [1, 2, 3])
img = nib.Nifti1Image(raw, aff)
img.set_qform(aff, code=1)
nib.save(img, "scaled_i16.nii")
# nibabel would rescale the data to fit the slope; patch the two header fields instead
# (little-endian f32 at bytes 112 and 116), so the stored integers stay `raw`.
with open("scaled_i16.nii", "r+b") as f:
    f.seek(112)
    f.write(struct.pack("<ff", 0.25, -10.0))
fixtures["scaled_i16.nii"] = None

# 4. float64, little-endian, sform only (qform code 0).
data = (ramp * 0.125 - 3.0).astype(np.float64)
img = nib.Nifti1Image(data, None)
img.set_sform(affine(rotation([3, -1, 2], 1.2), [0.5, 0.6, 0.7], [5, 6, 7]), code=1)
img.set_qform(None, code=0)
nib.save(img, "sform_only_f64.nii")
fixtures["sform_only_f64.nii"] = img

expected = {}
for name in fixtures:
    loaded = nib.load(name)
    values = np.asarray(loaded.get_fdata(), dtype=np.float64).ravel(order="F")
    h = loaded.header
    expected[name] = {
        "shape": [int(s) for s in loaded.shape],
        "datatype": int(h["datatype"]),
        "affine": loaded.affine.tolist(),
        "qform_code": int(h["qform_code"]),
        "sform_code": int(h["sform_code"]),
        "slope_inter": [float(loaded.dataobj.slope), float(loaded.dataobj.inter)],
        "values": values.tolist(),
    }
with open("expected.json", "w") as f:
    json.dump(expected, f, indent=1)
    f.write("\n")
