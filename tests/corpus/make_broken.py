#!/usr/bin/env python3
"""Writes the regression corpus of broken volume files, tests/corpus/broken/.

Each file is small and broken in one way a real file can be: truncated data, a header
that promises more than the file holds, sizes whose product overflows or exceeds the
voxel limit, unknown types and encodings, lying lengths. tests/io_corpus.rs reads every
file and checks that it gets its expected error (listed in EXPECTED.tsv beside them:
file, error kind, field, words the message must contain).

Run from anywhere: python3 tests/corpus/make_broken.py  (standard library only)
"""
import gzip
import os
import struct

HERE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "broken")
os.makedirs(HERE, exist_ok=True)
expected = []


def put(name, data, kind, field, words):
    with open(os.path.join(HERE, name), "wb") as f:
        f.write(data)
    expected.append((name, kind, field, words))


def nrrd(fields, data=b"", magic=b"NRRD0004"):
    return magic + b"\n" + "".join(f"{k}: {v}\n" for k, v in fields).encode() + b"\n" + data


base = [("type", "uchar"), ("dimension", "3"), ("sizes", "4 4 4"), ("encoding", "raw")]

# --- NRRD ------------------------------------------------------------------------
put("nrrd-truncated-data.nrrd", nrrd(base, bytes(63)), "format", "data", "expected 64 bytes, found 63")
put("nrrd-sizes-overflow.nrrd",
    nrrd([("type", "float"), ("dimension", "3"), ("sizes", "4294967296 4294967296 4294967296"),
          ("encoding", "raw"), ("endian", "little")], bytes(16)),
    "format", "sizes", "")
put("nrrd-over-voxel-limit.nrrd",
    nrrd([("type", "uchar"), ("dimension", "3"), ("sizes", "2048 2048 1024"), ("encoding", "raw")], bytes(16)),
    "format", "sizes", "limit")
put("nrrd-unknown-type.nrrd", nrrd([("type", "quaternion"), ("dimension", "3"), ("sizes", "1 1 1"),
                                    ("encoding", "raw")], bytes(8)), "format", "type", "quaternion")
put("nrrd-unknown-encoding.nrrd", nrrd([("type", "uchar"), ("dimension", "3"), ("sizes", "1 1 1"),
                                        ("encoding", "bzip2")], bytes(8)), "format", "encoding", "bzip2")
put("nrrd-corrupt-gzip.nrrd", nrrd([("type", "uchar"), ("dimension", "3"), ("sizes", "4 4 4"),
                                    ("encoding", "gzip")], b"\x1f\x8b\x08\x00garbage-not-deflate"),
    "format", "data", "")
gz = gzip.compress(bytes(64))
put("nrrd-gzip-truncated.nrrd", nrrd([("type", "uchar"), ("dimension", "3"), ("sizes", "4 4 4"),
                                      ("encoding", "gzip")], gz[: len(gz) // 2]), "format", "data", "")
put("nrrd-missing-endian.nrrd", nrrd([("type", "short"), ("dimension", "3"), ("sizes", "2 2 2"),
                                      ("encoding", "raw")], bytes(16)), "format", "endian", "")
put("nrrd-nan-spacing.nrrd", nrrd(base + [("spacings", "1 nan 1")], bytes(64)), "format", "spacings", "")
put("nrrd-missing-data-file.nhdr", nrrd(base + [("data file", "no-such-file.raw")]), "format", "data file",
    "no-such-file.raw")
put("nrrd-bad-magic.nrrd", b"NRRD9999\n" + nrrd(base, bytes(64))[9:], "format", "magic", "")

# --- .npy ------------------------------------------------------------------------
def npy(dict_text, data, major=1):
    d = dict_text.encode()
    pad = (64 - (10 + len(d) + 1) % 64) % 64
    d = d + b" " * pad + b"\n"
    return b"\x93NUMPY" + bytes([major, 0]) + struct.pack("<H", len(d)) + d + data


put("npy-truncated.npy", npy("{'descr': '<f4', 'fortran_order': False, 'shape': (4, 4, 4), }", bytes(255)),
    "format", "data", "expected 256 bytes, found 255")
put("npy-shape-overflow.npy",
    npy("{'descr': '<f4', 'fortran_order': False, 'shape': (4294967296, 4294967296, 4294967296), }", bytes(8)),
    "format", "shape", "")
put("npy-complex.npy", npy("{'descr': '<c8', 'fortran_order': False, 'shape': (2, 2, 2), }", bytes(64)),
    "format", "descr", "")
put("npy-header-past-end.npy", b"\x93NUMPY\x01\x00\xff\xff{'descr'", "format", "", "")
put("npy-4d.npy", npy("{'descr': '|u1', 'fortran_order': False, 'shape': (1, 2, 2, 2), }", bytes(8)),
    "format", "shape", "")


# --- NIfTI-1 ----------------------------------------------------------------------
def nifti(dims=(4, 4, 4), datatype=2, bitpix=8, sizeof_hdr=348, magic=b"n+1\0", vox_offset=352.0,
          data=None, endian="<"):
    h = bytearray(348)
    struct.pack_into(endian + "i", h, 0, sizeof_hdr)
    dim = [len(dims)] + list(dims) + [1] * (7 - len(dims))
    struct.pack_into(endian + "8h", h, 40, *dim)
    struct.pack_into(endian + "hh", h, 70, datatype, bitpix)
    struct.pack_into(endian + "8f", h, 76, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    struct.pack_into(endian + "f", h, 108, vox_offset)
    struct.pack_into(endian + "f", h, 112, 1.0)  # scl_slope
    h[344:348] = magic
    if data is None:
        n = 1
        for d in dims:
            n *= d
        data = bytes(n * bitpix // 8)
    return bytes(h) + bytes(4) + data


put("nifti-truncated.nii", nifti(data=bytes(63)), "format", "data", "")
put("nifti-bad-sizeof-hdr.nii", nifti(sizeof_hdr=349), "format", "sizeof_hdr", "")
put("nifti-4d.nii", nifti(dims=(2, 2, 2, 3)), "format", "dim[4]", "choose one with --frame")
put("nifti-complex.nii", nifti(datatype=32, bitpix=64), "format", "datatype", "")
put("nifti-bitpix-mismatch.nii", nifti(datatype=4, bitpix=8), "format", "bitpix", "")
put("nifti-over-voxel-limit.nii", nifti(dims=(32767, 32767, 32767), data=bytes(16)), "format", "dim", "")
put("nifti-vox-offset-past-end.nii", nifti(vox_offset=1e9), "format", "vox_offset", "")
put("nifti-corrupt-gzip.nii.gz", b"\x1f\x8b\x08\x00" + b"not deflate at all" * 4, "format", "", "")

# --- PVM --------------------------------------------------------------------------
put("pvm-truncated.pvm", b"PVM\n4 4 4\n1\n" + bytes(40), "format", "data", "")
put("pvm-rgb.pvm", b"PVM2\n2 2 2\n1 1 1\n3\n" + bytes(24), "format", "components", "")
put("pvm-zero-dims.pvm", b"PVM\n0 4 4\n1\n", "format", "", "")
put("pvm-negative-spacing.pvm", b"PVM2\n2 2 2\n1 -1 1\n1\n" + bytes(8), "format", "", "")
put("pvm-dds-garbage.pvm", b"DDS v3d\n" + bytes(5), "format", "", "DDS")

# --- VolPack .den -----------------------------------------------------------------
def den(dims=(3, 2, 2), length=None, version=1, data=None):
    h = struct.pack("<h", version)
    for arr in ([0, 0, 0], [d - 1 for d in dims], list(dims)) * 3:
        h += struct.pack("<3h", *arr)
    n = dims[0] * dims[1] * dims[2]
    h += struct.pack("<h", 0) + struct.pack("<i", n if length is None else length)
    return h + (bytes(n) if data is None else data)


put("den-truncated.den", den(data=bytes(5)), "format", "data", "")
put("den-bad-length.den", den(length=13), "format", "map_length", "")
put("den-bad-version.den", den(version=7), "format", "", "")

# --- DICOM and TIFF (cut from the bundled files) ----------------------------------
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
def src(rel):
    with open(os.path.join(ROOT, rel), "rb") as f:
        return f.read()


put("dicom-truncated-pixels.dcm", src("tests/corpus/dicom/explicit_big.dcm")[:60000], "format", "PixelData", "truncated")
put("dicom-truncated-header.dcm", src("tests/corpus/dicom/implicit_little.dcm")[:200], "format", "MediaStorageSOPInstanceUID", "truncated")
def j2k_wider(b):
    """The JPEG 2000 codestream's SIZ says 513 columns; the DICOM attributes say 512."""
    at = b.index(b"\xff\x4f\xff\x51") + 8
    return b[:at] + struct.pack(">I", 513) + b[at + 4:]


put("dicom-jpeg2000-size.dcm", j2k_wider(src("tests/corpus/dicom/jpeg_2000.dcm")), "format", "Rows/Columns",
    "the compressed frame is 513 x 512")
put("tiff-truncated.tif", src("data/microct-bone/bone_128x128x128.tif")[:40000], "format", "file", "truncated")
put("tiff-ifd-past-end.tif", b"II*\x00" + struct.pack("<I", 1 << 30) + bytes(16), "format", "file", "")

# --- Hostile headers: lying lengths, endless data files, terminal escapes ----------
def dicom_element(group, elem, vr, value):
    v = value + (b"\0" if len(value) % 2 else b"")
    if vr in (b"OB", b"OW", b"SQ", b"UN", b"UT"):
        return struct.pack("<HH", group, elem) + vr + b"\0\0" + struct.pack("<I", len(v)) + v
    return struct.pack("<HH", group, elem) + vr + struct.pack("<H", len(v)) + v


def dicom_file(dataset, syntax=b"1.2.840.10008.1.2.1"):
    meta = dicom_element(0x0002, 0x0001, b"OB", b"\0\1") + dicom_element(0x0002, 0x0010, b"UI", syntax)
    meta = dicom_element(0x0002, 0x0000, b"UL", struct.pack("<I", len(meta))) + meta
    return bytes(128) + b"DICM" + meta + dataset


image = (dicom_element(0x0028, 0x0002, b"US", struct.pack("<H", 1))
         + dicom_element(0x0028, 0x0004, b"CS", b"MONOCHROME2")
         + dicom_element(0x0028, 0x0010, b"US", struct.pack("<H", 16))
         + dicom_element(0x0028, 0x0011, b"US", struct.pack("<H", 16))
         + dicom_element(0x0028, 0x0100, b"US", struct.pack("<H", 16))
         + dicom_element(0x0028, 0x0101, b"US", struct.pack("<H", 16))
         + dicom_element(0x0028, 0x0102, b"US", struct.pack("<H", 15))
         + dicom_element(0x0028, 0x0103, b"US", struct.pack("<H", 0)))
# PixelData (7FE0,0010) OW claiming 0xFFFFFFF0 bytes (4 GiB) in a file of a few hundred.
huge = struct.pack("<HH", 0x7FE0, 0x0010) + b"OW\0\0" + struct.pack("<I", 0xFFFFFFF0) + bytes(512)
put("dicom-huge-pixel-length.dcm", dicom_file(image + huge), "format", "PixelData", "claims 4294967280 bytes")
put("nrrd-ascii-data-dev-zero.nhdr",
    b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 4 4 4\nencoding: ascii\ndata file: /dev/zero\n",
    "format", "data file", "character device")
put("nrrd-data-file-list.nhdr",
    b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 4 4 2\nencoding: raw\ndata file: LIST\nslice0.raw\nslice1.raw\n",
    "format", "data file", "LIST")
put("nrrd-terminal-escapes.nrrd",
    nrrd([("type", "\x1b[2J\x1b]0;pwned\x07\x00"), ("dimension", "3"), ("sizes", "1 1 1"), ("encoding", "raw")], bytes(1)),
    "format", "type", "\\u{1b}[2J\\u{1b}]0;pwned\\u{7}\\u{0}")
put("nrrd-gzip-extra-data.nrrd", nrrd(base[:3] + [("encoding", "gzip")], gzip.compress(bytes(65), mtime=0)),
    "format", "data", "1 bytes more than")
put("nifti-vox-offset-huge.nii", nifti(vox_offset=3e38), "format", "vox_offset", "past the end of any file")

# --- MetaImage -------------------------------------------------------------------
def mha(extra, data=b"", dims="4 4 4", etype="MET_UCHAR", datafile="LOCAL"):
    h = ("ObjectType = Image\nNDims = 3\nDimSize = %s\nElementType = %s\n%sElementDataFile = %s\n"
         % (dims, etype, extra, datafile))
    return h.encode() + data


put("mha-truncated-data.mha", mha("", bytes(63)), "format", "data", "expected 64 bytes, found 63")
put("mha-over-voxel-limit.mha", mha("", bytes(16), dims="2048 2048 1024"), "format", "DimSize", "limit")
put("mha-unknown-type.mha", mha("", bytes(64), etype="MET_UCHAR_ARRAY"), "format", "ElementType", "MET_UCHAR_ARRAY")
put("mha-corrupt-zlib.mha", mha("CompressedData = True\n", b"\x78\x9cgarbage"), "format", "data", "decoded")
put("mha-nan-spacing.mha", mha("ElementSpacing = 1 nan 1\n", bytes(64)), "format", "ElementSpacing", "finite")
put("mha-missing-data-file.mhd", mha("", datafile="no-such-file.raw"), "format", "data file", "no-such-file.raw")
put("mha-data-dev-zero.mhd", mha("", datafile="/dev/zero"), "format", "data file", "character device")
put("mha-header-size-past-end.mhd", mha("HeaderSize = 100000\n", datafile="mha-truncated-data.mha"),
    "format", "HeaderSize", "100000")

with open(os.path.join(HERE, "EXPECTED.tsv"), "w") as f:
    f.write("# file\terror kind\tfield (empty: any)\twords the message must contain (empty: none)\n")
    for row in expected:
        f.write("\t".join(row) + "\n")
print(f"wrote {len(expected)} broken files to {HERE}")
