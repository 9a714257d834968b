//! Files of several 3-D volumes in MetaImage and NRRD, built byte by byte: every frame
//! reads back as the values written for it (each sample encodes its frame and its
//! voxel), in every layout the readers take — data after the header, a data file,
//! zlib/gzip, text, MetaImage `LIST`s, NRRD frame axes first, between or last — and a
//! file of several frames without a choice, or a choice past the last, is refused
//! naming the count. (NIfTI's frames are tested in io_nifti.rs.)

mod common;

use common::{assert_format, scratch};
use std::io::Write;
use std::path::{Path, PathBuf};
use voxlab::io::{frame_count, read_volume, read_volume_with, ReadOptions};

/// The volume's sizes (x, y, z) and frame count of every file here.
const DIMS: [usize; 3] = [3, 2, 2];
const FRAMES: usize = 4;

/// Sample `(x, y, z)` of frame `t`: 100·t + the voxel's index, as i16.
fn value(t: usize, i: usize) -> i16 {
    (100 * t + i) as i16
}

fn frame_values(t: usize) -> Vec<f64> {
    (0..12).map(|i| f64::from(value(t, i))).collect()
}

/// All frames, frame axis slowest (the fourth axis of a 4-D image).
fn slowest() -> Vec<i16> {
    (0..FRAMES)
        .flat_map(|t| (0..12).map(move |i| value(t, i)))
        .collect()
}

/// All frames, frame axis fastest (a vector axis first).
fn fastest() -> Vec<i16> {
    (0..12)
        .flat_map(|i| (0..FRAMES).map(move |t| value(t, i)))
        .collect()
}

fn le(v: &[i16]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

fn be(v: &[i16]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_be_bytes()).collect()
}

fn zlib(bytes: &[u8]) -> Vec<u8> {
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    z.write_all(bytes).unwrap();
    z.finish().unwrap()
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn frame(k: usize) -> ReadOptions {
    ReadOptions {
        frame: Some(k),
        ..Default::default()
    }
}

/// Every frame of `p` equals what was written for it, and the file's frame choices
/// are checked: none refused naming the count, one past the last refused.
fn check_frames(p: &Path, field: &str) {
    let name = p.display();
    assert_eq!(frame_count(p).unwrap(), FRAMES, "{name}");
    for t in 0..FRAMES {
        let v = read_volume_with(p, &frame(t)).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(v.dims(), DIMS, "{name}");
        assert_eq!(v.values_f64(), frame_values(t), "{name} frame {t}");
    }
    assert_format(read_volume(p), field, "4 3-D volumes");
    assert_format(read_volume(p), field, "--frame");
    assert_format(
        read_volume_with(p, &frame(FRAMES)),
        field,
        "frame 4 is past the file's 4",
    );
}

/// A MetaImage header of `ndims` axes: spacing 0.5, 1, 2 mm and offset (10, −20, 30)
/// on the spatial axes, 7 and 1000 on the others.
fn mha_header(ndims: usize, dims: &str, extra: &str, data: &str) -> String {
    let more = |x: &str| format!(" {x}").repeat(ndims.saturating_sub(3));
    format!(
        "ObjectType = Image\nNDims = {ndims}\nDimSize = {dims}\nElementType = MET_SHORT\n\
         ElementSpacing = 0.5 1 2{}\nOffset = 10 -20 30{}\n{extra}ElementDataFile = {data}\n",
        more("7"),
        more("1000")
    )
}

#[test]
fn four_d_metaimages_read_one_frame_at_a_time() {
    let dir = scratch("frames-mha");
    let h4 = |extra: &str, data: &str| mha_header(4, "3 2 2 4", extra, data);
    // Data after the header, both byte orders; zlib; text.
    let mut local = h4("", "LOCAL").into_bytes();
    local.extend(le(&slowest()));
    check_frames(&write(&dir, "local.mha", &local), "DimSize");
    let mut msb = h4("ElementByteOrderMSB = True\n", "LOCAL").into_bytes();
    msb.extend(be(&slowest()));
    check_frames(&write(&dir, "msb.mha", &msb), "DimSize");
    let mut z = h4("CompressedData = True\n", "LOCAL").into_bytes();
    z.extend(zlib(&le(&slowest())));
    check_frames(&write(&dir, "z.mha", &z), "DimSize");
    let text: Vec<String> = slowest().iter().map(|v| v.to_string()).collect();
    let t = h4("BinaryData = False\n", "LOCAL") + &text.join(" ");
    check_frames(&write(&dir, "text.mha", t.as_bytes()), "DimSize");
    // A data file, with a header to skip.
    let mut raw = b"PREFIX".to_vec();
    raw.extend(le(&slowest()));
    write(&dir, "d.raw", &raw);
    check_frames(
        &write(&dir, "d.mhd", h4("HeaderSize = 6\n", "d.raw").as_bytes()),
        "DimSize",
    );
    // LIST: one file per 3-D volume (NDims − 1 axes each), and `LIST 2D`, one per slice.
    let all = le(&slowest());
    let mut list = h4("", "LIST");
    for t in 0..FRAMES {
        write(&dir, &format!("v{t}.raw"), &all[24 * t..24 * (t + 1)]);
        list += &format!("v{t}.raw\n");
    }
    check_frames(&write(&dir, "l3.mhd", list.as_bytes()), "DimSize");
    let mut list = h4("", "LIST 2D");
    for s in 0..2 * FRAMES {
        write(&dir, &format!("s{s}.raw"), &all[12 * s..12 * (s + 1)]);
        list += &format!("s{s}.raw\n");
    }
    check_frames(&write(&dir, "l2.mhd", list.as_bytes()), "DimSize");
    // Only the files that hold the frame are opened: frame 1 reads with the others gone.
    std::fs::remove_file(dir.join("s0.raw")).unwrap();
    std::fs::remove_file(dir.join("s7.raw")).unwrap();
    let v = read_volume_with(&dir.join("l2.mhd"), &frame(1)).unwrap();
    assert_eq!(v.values_f64(), frame_values(1));
    assert_format(
        read_volume_with(&dir.join("l2.mhd"), &frame(0)),
        "data file",
        "s0.raw",
    );
    // The geometry is the first three axes': spacing, offset and directions.
    let p = dir.join("local.mha");
    let v = read_volume_with(&p, &frame(2)).unwrap();
    assert_eq!(v.spacing(), [0.5, 1.0, 2.0]);
    assert_eq!(v.affine().w_axis.truncate().to_array(), [10.0, -20.0, 30.0]);
    // Two frame axes (5-D): counted as one, the fourth fastest.
    let mut five = mha_header(5, "3 2 2 2 2", "", "LOCAL").into_bytes();
    five.extend(le(&slowest()));
    check_frames(&write(&dir, "five.mha", &five), "DimSize");
    // Channels interleaved, then a fourth axis: frame k is channel k mod 2 of
    // volume k div 2; in one file and in a LIST of slices.
    let mut mixed = Vec::new();
    for v in 0..2 {
        for i in 0..12 {
            for c in 0..2 {
                mixed.push(value(2 * v + c, i));
            }
        }
    }
    let hc = |data: &str| mha_header(4, "3 2 2 2", "ElementNumberOfChannels = 2\n", data);
    let mut ch = hc("LOCAL").into_bytes();
    ch.extend(le(&mixed));
    check_frames(&write(&dir, "ch.mha", &ch), "DimSize");
    let all = le(&mixed);
    let mut list = hc("LIST 2D");
    for s in 0..4 {
        write(&dir, &format!("c{s}.raw"), &all[24 * s..24 * (s + 1)]);
        list += &format!("c{s}.raw\n");
    }
    check_frames(&write(&dir, "lc.mhd", list.as_bytes()), "DimSize");
    // Channels alone (a 3-D vector image): the field is ElementNumberOfChannels.
    let mut vec3 = mha_header(3, "3 2 2", "ElementNumberOfChannels = 4\n", "LOCAL").into_bytes();
    vec3.extend(le(&fastest()));
    check_frames(&write(&dir, "vec.mha", &vec3), "ElementNumberOfChannels");
    // Every frame must be in the file, though one is read.
    let mut short = h4("", "LOCAL").into_bytes();
    short.extend(le(&slowest()[..40]));
    let p = write(&dir, "short.mha", &short);
    assert_format(read_volume_with(&p, &frame(0)), "data", "too short");
    // A single 4-D frame is a plain volume; NDims past MetaIO's 10 is refused.
    let mut one = mha_header(4, "3 2 2 1", "", "LOCAL").into_bytes();
    one.extend(le(&slowest()[..12]));
    let v = read_volume(&write(&dir, "one.mha", &one)).unwrap();
    assert_eq!(v.values_f64(), frame_values(0));
    let p = write(
        &dir,
        "eleven.mha",
        mha_header(11, "1 1 1 1 1 1 1 1 1 1 1", "", "LOCAL").as_bytes(),
    );
    assert_format(read_volume(&p), "NDims", "2 to 10");
}

fn nrrd(fields: &str, encoding: &str, data: &[u8]) -> Vec<u8> {
    let mut b = format!("NRRD0004\ntype: short\nendian: little\nencoding: {encoding}\n{fields}\n")
        .into_bytes();
    b.extend(data);
    b
}

#[test]
fn nrrds_with_non_spatial_axes_read_one_frame_at_a_time() {
    let dir = scratch("frames-nrrd");
    // A time axis last, named by kinds: raw, gzip, text; and a detached data file.
    let last = "dimension: 4\nsizes: 3 2 2 4\nkinds: domain domain domain time\n";
    check_frames(
        &write(&dir, "t.nrrd", &nrrd(last, "raw", &le(&slowest()))),
        "sizes",
    );
    let gz = common::gzip(&le(&slowest()));
    check_frames(&write(&dir, "tg.nrrd", &nrrd(last, "gzip", &gz)), "sizes");
    let text: Vec<String> = slowest().iter().map(|v| v.to_string()).collect();
    check_frames(
        &write(
            &dir,
            "tt.nrrd",
            &nrrd(last, "ascii", text.join("\n").as_bytes()),
        ),
        "sizes",
    );
    write(&dir, "t.raw", &le(&slowest()));
    let detached = nrrd(&format!("{last}data file: t.raw\n"), "raw", b"");
    check_frames(&write(&dir, "t.nhdr", &detached), "sizes");
    // A vector axis first, by a `none` direction: the frames are interleaved.
    let first = "dimension: 4\nsizes: 4 3 2 2\nspace dimension: 3\n\
                 space directions: none (0.5,0,0) (0,1,0) (0,0,2)\n";
    let p = write(&dir, "v.nrrd", &nrrd(first, "raw", &le(&fastest())));
    check_frames(&p, "sizes");
    let v = read_volume_with(&p, &frame(3)).unwrap();
    assert_eq!(v.spacing(), [0.5, 1.0, 2.0]);
    // ... and gzip-compressed.
    let gz = common::gzip(&le(&fastest()));
    check_frames(&write(&dir, "vg.nrrd", &nrrd(first, "gzip", &gz)), "sizes");
    // No kinds and no directions: a fourth axis numbers frames, as in NIfTI.
    let plain = "dimension: 4\nsizes: 3 2 2 4\nspacings: 0.5 1 2 nan\n";
    check_frames(
        &write(&dir, "p.nrrd", &nrrd(plain, "raw", &le(&slowest()))),
        "sizes",
    );
    // A frame axis between space axes: frame t of a [x, t, y, z] layout.
    let mut mid = Vec::new();
    for z in 0..2 {
        for y in 0..2 {
            for t in 0..FRAMES {
                for x in 0..3 {
                    mid.push(value(t, x + 3 * y + 6 * z));
                }
            }
        }
    }
    let between = "dimension: 4\nsizes: 3 4 2 2\nkinds: space list space space\n";
    check_frames(
        &write(&dir, "m.nrrd", &nrrd(between, "raw", &le(&mid))),
        "sizes",
    );
    // Every frame must be in the file, though one is read.
    let p = write(
        &dir,
        "short.nrrd",
        &nrrd(last, "raw", &le(&slowest()[..40])),
    );
    assert_format(read_volume_with(&p, &frame(0)), "data", "too short");
}

/// The command line: `info` counts the frames, `--frame` picks one for every command,
/// and a format of one volume takes `--frame 0` and refuses a later one.
#[test]
fn the_command_line_counts_and_picks_frames() {
    let dir = scratch("frames-cli");
    let mut local = mha_header(4, "3 2 2 4", "", "LOCAL").into_bytes();
    local.extend(le(&slowest()));
    let p = write(&dir, "run.mha", &local);
    let p = p.to_str().unwrap();
    let out = common::voxlab(&["info", p]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", common::stderr(&out));
    assert!(text.contains("4 3-D volumes"), "{text}");
    let npy = dir.join("t2.npy");
    let out = common::voxlab(&["convert", p, npy.to_str().unwrap(), "--frame", "2"]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    assert_eq!(read_volume(&npy).unwrap().values_f64(), frame_values(2));
    let out = common::voxlab(&["convert", p, npy.to_str().unwrap()]);
    assert!(
        !out.status.success() && common::stderr(&out).contains("--frame"),
        "{}",
        common::stderr(&out)
    );
    // A file of one volume: frame 0 is it, frame 1 is past it.
    let one = npy.to_str().unwrap();
    assert_eq!(frame_count(&npy).unwrap(), 1);
    assert!(read_volume_with(&npy, &frame(0)).is_ok());
    assert_format(
        read_volume_with(&npy, &frame(1)),
        "frame",
        "past the file's 1",
    );
    let out = common::voxlab(&["info", one, "--frame", "1"]);
    assert!(
        !out.status.success() && common::stderr(&out).contains("past the file's 1"),
        "{}",
        common::stderr(&out)
    );
}
