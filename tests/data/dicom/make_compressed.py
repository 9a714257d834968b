"""Writes the compressed DICOM fixtures of tests/io_dicom_compressed.rs.

Run from the repository root (needs pydicom 3 with numpy, pylibjpeg,
pylibjpeg-libjpeg, pylibjpeg-openjpeg and pyjpegls, and DCMTK's dcmcjpeg):

    python tests/data/dicom/make_compressed.py

Every image holds the same integer pattern, which tests/io_dicom_compressed.rs
computes again (`pattern`), so lossless files need no stored answer:

    v(x, y, f) = (5·((x − 20)² + (y − 13)²) + 9·((x·y) mod 7) + 300·f) mod 4096

on 45 columns × 36 rows (sizes that are not multiples of JPEG's 8×8 blocks, and large
enough for OpenJPEG's six resolution levels), for
frame f. 8-bit files hold v >> 4; signed files hold 8·v − 16384; 32-bit files hold
70000·v. Each file is decoded again here with pydicom and checked: lossless files
must give the pattern back exactly; for lossy files pydicom's decoding is stored beside
them (NAME.expected.raw, little-endian samples) and its largest deviation from the
pattern is printed, for the Rust test's tolerance.
"""
import os
import subprocess
import tempfile

import numpy as np
import pydicom
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.encaps import encapsulate, generate_frames
from pydicom.uid import (
    ExplicitVRLittleEndian,
    JPEG2000,
    JPEG2000Lossless,
    JPEGLSLossless,
    JPEGLSNearLossless,
    RLELossless,
    generate_uid,
)

OUT = os.path.dirname(os.path.abspath(__file__))
COLS, ROWS = 45, 36


def pattern(frames, kind="u12"):
    f, y, x = np.meshgrid(np.arange(frames), np.arange(ROWS), np.arange(COLS), indexing="ij")
    v = (5 * ((x - 20) ** 2 + (y - 13) ** 2) + 9 * ((x * y) % 7) + 300 * f) % 4096
    if kind == "u8":
        return (v >> 4).astype(np.uint8)
    if kind == "i16":
        return (8 * v - 16384).astype(np.int16)
    if kind == "u32":
        return (70000 * v).astype(np.uint32)
    return v.astype(np.uint16)


def dataset(arr, bits_stored=None):
    frames = arr.shape[0]
    ds = Dataset()
    ds.file_meta = FileMetaDataset()
    ds.file_meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds.file_meta.MediaStorageSOPClassUID = "1.2.840.10008.5.1.4.1.1.7"
    ds.file_meta.MediaStorageSOPInstanceUID = generate_uid()
    ds.SOPClassUID = ds.file_meta.MediaStorageSOPClassUID
    ds.SOPInstanceUID = ds.file_meta.MediaStorageSOPInstanceUID
    ds.StudyInstanceUID = generate_uid()
    ds.SeriesInstanceUID = generate_uid()
    ds.Modality = "OT"
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.Rows, ds.Columns = ROWS, COLS
    bits = arr.dtype.itemsize * 8
    ds.BitsAllocated = bits
    ds.BitsStored = bits_stored or bits
    ds.HighBit = ds.BitsStored - 1
    ds.PixelRepresentation = 1 if arr.dtype.kind == "i" else 0
    if frames > 1:
        ds.NumberOfFrames = frames
    ds.PixelData = arr.tobytes()
    return ds


def save(ds, name):
    path = os.path.join(OUT, name)
    ds.save_as(path, enforce_file_format=True)
    return path


def check(path, want, lossy=False):
    ds = pydicom.dcmread(path)
    got = ds.pixel_array.reshape(want.shape)
    dev = np.abs(got.astype(np.int64) - want.astype(np.int64)).max()
    name = os.path.basename(path)
    print(f"{name}: {ds.file_meta.TransferSyntaxUID.name}, {os.path.getsize(path)} bytes, "
          f"max |pydicom - pattern| = {dev}")
    if lossy:
        got.astype(got.dtype.newbyteorder("<")).tofile(path.replace(".dcm", ".expected.raw"))
    else:
        assert dev == 0, name


def compressed(arr, uid, name, bits_stored=None, **kw):
    ds = dataset(arr, bits_stored)
    ds.compress(uid, arr if arr.shape[0] > 1 else arr[0], **kw)
    return save(ds, name)


def reencapsulate(path, name, fragments_per_frame, has_bot):
    """The same frames in more fragments, with or without a basic offset table."""
    ds = pydicom.dcmread(path)
    n = int(ds.get("NumberOfFrames", 1))
    frames = list(generate_frames(ds.PixelData, number_of_frames=n))
    ds.PixelData = encapsulate(frames, fragments_per_frame=fragments_per_frame, has_bot=has_bot)
    return save(ds, name)


def rle32(arr, name):
    """RLE of 32-bit samples, which pydicom's encoder refuses: four byte planes, most
    significant first, each PackBits-coded by pydicom's row encoder."""
    from pydicom.pixels.encoders.native import _encode_segment

    raw = arr[0].astype(">u4").tobytes()
    segments = [_encode_segment(raw[k::4], COLS) for k in range(4)]
    offsets, at = [], 64
    for s in segments:
        offsets.append(at)
        at += len(s)
    header = np.array([4] + offsets + [0] * 11, dtype="<u4").tobytes()
    ds = dataset(arr)
    ds.file_meta.TransferSyntaxUID = RLELossless
    ds.PixelData = encapsulate([header + b"".join(segments)])
    ds["PixelData"].VR = "OB"
    return save(ds, name)


def dcmcjpeg(arr, options, name, bits_stored=None):
    with tempfile.TemporaryDirectory() as tmp:
        src = os.path.join(tmp, "in.dcm")
        dataset(arr, bits_stored).save_as(src, enforce_file_format=True)
        path = os.path.join(OUT, name)
        subprocess.run(["dcmcjpeg", *options, src, path], check=True)
    return path


# RLE Lossless (pydicom's own encoder): 8, 16 (unsigned 12-bit, signed) and 32 bits.
check(compressed(pattern(2), RLELossless, "rle_u16_2f.dcm", 12), pattern(2))
check(compressed(pattern(1, "i16"), RLELossless, "rle_i16.dcm"), pattern(1, "i16"))
check(compressed(pattern(1, "u8"), RLELossless, "rle_u8.dcm"), pattern(1, "u8"))
check(rle32(pattern(1, "u32"), "rle_u32.dcm"), pattern(1, "u32"))

# JPEG (DCMTK): baseline and extended 8-bit (lossy), extended 12-bit (lossy),
# lossless process 14 (selection value 6) and SV1.
check(dcmcjpeg(pattern(1, "u8"), ["+eb", "+q", "75"], "jpeg_baseline.dcm"), pattern(1, "u8"), True)
check(dcmcjpeg(pattern(1, "u8"), ["+ee", "+q", "75"], "jpeg_extended_8.dcm"), pattern(1, "u8"), True)
check(dcmcjpeg(pattern(1), ["+ee", "+q", "90"], "jpeg_extended_12.dcm", 12), pattern(1), True)
p = dcmcjpeg(pattern(2), ["+e1"], "jpeg_lossless_sv1_2f.dcm", 12)
check(p, pattern(2))
check(reencapsulate(p, "jpeg_lossless_sv1_frag_bot.dcm", 3, True), pattern(2))
check(dcmcjpeg(pattern(1, "i16"), ["+el", "+sv", "6"], "jpeg_lossless_p14_i16.dcm"), pattern(1, "i16"))

# JPEG-LS (CharLS through pyjpegls): lossless, and near-lossless with NEAR = 3.
check(compressed(pattern(2), JPEGLSLossless, "jpegls_lossless_2f.dcm", 12), pattern(2))
check(compressed(pattern(1), JPEGLSNearLossless, "jpegls_near.dcm", 12, jls_error=3), pattern(1), True)

# JPEG 2000 (OpenJPEG through pylibjpeg-openjpeg): lossless signed, lossless in two
# frames split over fragments without an offset table, and lossy at 10:1.
check(compressed(pattern(1, "i16"), JPEG2000Lossless, "j2k_lossless_i16.dcm"), pattern(1, "i16"))
p = compressed(pattern(2), JPEG2000Lossless, "j2k_lossless_2f.dcm", 12)
check(reencapsulate(p, "j2k_lossless_frag_nobot.dcm", 2, False), pattern(2))
os.remove(p)
check(compressed(pattern(1), JPEG2000, "j2k_lossy.dcm", 12, j2k_cr=[10]), pattern(1), True)
