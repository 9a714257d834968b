"""Independent reference numbers for tests/io_dicom.rs, computed with pydicom + numpy.

Run from the repository root:  python tests/data/dicom_reference.py

For the MR series (data/mr-brain-dicom) the slices are sorted by the projection of
ImagePositionPatient onto the slice normal (cross product of the two
ImageOrientationPatient vectors); RescaleSlope/Intercept are applied. For each volume
it prints dims (x, y, z), min, max, sum, and a weighted sum
sum(v[i] * (i % 251 + 1)) over the voxels in x-fastest order (i = flat index), which
catches wrong orientation or slice order; and for the series the affine columns.
"""
import glob
import numpy as np
import pydicom


def rescaled(ds):
    a = ds.pixel_array.astype(np.float64)
    return a * float(ds.get("RescaleSlope", 1)) + float(ds.get("RescaleIntercept", 0))


def stats(vol):  # vol indexed [z, y, x]; flattening is x-fastest
    flat = vol.reshape(-1)
    w = (np.arange(flat.size) % 251 + 1).astype(np.float64)
    print(f"  dims (x,y,z) = {vol.shape[::-1]}")
    print(f"  min = {flat.min():.6g}  max = {flat.max():.6g}  sum = {flat.sum():.17g}")
    print(f"  weighted sum = {(flat * w).sum():.17g}")


files = sorted(glob.glob("data/mr-brain-dicom/*.dcm"))
dss = [pydicom.dcmread(f) for f in files]
iop = np.array(dss[0].ImageOrientationPatient, dtype=np.float64)
row, col = iop[:3], iop[3:]
normal = np.cross(row, col)
dss.sort(key=lambda d: np.dot(np.array(d.ImagePositionPatient, dtype=np.float64), normal))
proj = [np.dot(np.array(d.ImagePositionPatient, dtype=np.float64), normal) for d in dss]
steps = np.diff(proj)
ps = [float(x) for x in dss[0].PixelSpacing]
print("mr-brain-dicom series:")
print(f"  first file after sorting = {dss[0].filename}")
print(f"  steps: median {np.median(steps):.9f}, min {steps.min():.9f}, max {steps.max():.9f}")
print(f"  x step = {row * ps[1]}")
print(f"  y step = {col * ps[0]}")
mean_step = (proj[-1] - proj[0]) / (len(proj) - 1)
print(f"  mean step = {mean_step:.9f}")
print(f"  z step = {normal * mean_step}")
print(f"  origin = {np.array(dss[0].ImagePositionPatient, dtype=np.float64)}")
stats(np.stack([rescaled(d) for d in dss]))

for name in ["implicit_little", "explicit_big", "deflated", "rle", "jpeg_lossless_sel1", "jpeg_2000"]:
    ds = pydicom.dcmread(f"tests/corpus/dicom/{name}.dcm")
    print(f"{name}.dcm ({ds.file_meta.TransferSyntaxUID}):")
    stats(rescaled(ds)[None, :, :])
