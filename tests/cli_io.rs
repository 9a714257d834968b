//! The command line's input side: raw files described by options, the voxel limit,
//! the rule for NaN/inf voxels, `info` (format, orientation, NaN counts, plot) and
//! `convert` (crop, resample, type), all checked against values computed here.

mod common;

use common::{s, scratch, stderr, voxlab, voxlab_command};
use std::path::{Path, PathBuf};
use std::process::Output;

fn ok(o: &Output) -> String {
    assert!(o.status.success(), "{}", stderr(o));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn json(o: &Output) -> serde_json::Value {
    serde_json::from_str(&ok(o)).unwrap()
}

/// A big-endian u16 raw file with a 10-byte header: value = i + 10 j + 100 k.
fn raw_file(d: &Path) -> PathBuf {
    let mut bytes = b"0123456789".to_vec();
    for k in 0..3u16 {
        for j in 0..4u16 {
            for i in 0..5u16 {
                bytes.extend_from_slice(&(i + 10 * j + 100 * k).to_be_bytes());
            }
        }
    }
    let p = d.join("vol.raw");
    std::fs::write(&p, bytes).unwrap();
    p
}

/// The options that describe [`raw_file`].
const RAW: [&str; 8] = [
    "--raw-dims",
    "5,4,3",
    "--raw-type",
    "u16",
    "--raw-endian",
    "big",
    "--raw-offset",
    "10",
];

/// `args` followed by [`RAW`].
fn with_raw<'a>(args: &[&'a str]) -> Vec<&'a str> {
    [args, &RAW[..]].concat()
}

#[test]
fn raw_input_is_read_as_described() {
    let d = scratch("raw");
    let p = raw_file(&d);
    let spacing = ["--raw-spacing", "0.5,0.5,2"];
    let j = json(&voxlab(
        &[with_raw(&["info", s(&p), "--json"]), spacing.to_vec()].concat(),
    ));
    assert_eq!(j["format"], "raw");
    assert_eq!(j["dims"], serde_json::json!([5, 4, 3]));
    assert_eq!(j["spacing_mm"], serde_json::json!([0.5, 0.5, 2.0]));
    assert_eq!(j["range"]["min"], 0.0);
    assert_eq!(j["range"]["max"], 234.0);
    // Converted to NRRD and read back: every value where it belongs.
    let out = d.join("vol.nrrd");
    ok(&voxlab(
        &[with_raw(&["convert", s(&p), s(&out)]), spacing.to_vec()].concat(),
    ));
    let v = voxlab::io::read_volume(&out).unwrap();
    let vals = v.values_f64();
    assert_eq!(vals[2 + 5 * (3 + 4 * 2)], 232.0);
    // A wrong guess of the dims is caught by the file's length.
    let o = voxlab(&["info", s(&p), "--raw-dims", "5,4,4", "--raw-type", "u16"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("has 130 bytes"));
    // No description at all: the error says what to add.
    let o = voxlab(&["info", s(&p)]);
    assert!(stderr(&o).contains("--raw-dims"));
}

#[test]
fn a_phantom_is_written_as_a_scanner_would_store_it() {
    use voxlab::phantom::Phantom;
    use voxlab::AnyVolume;
    let d = scratch("phantom-types");
    let p = d.join("u16.npy");
    let out = ok(&voxlab(&[
        "phantom",
        "shepp-logan-modified:9,8,7",
        "--type",
        "u16",
        "--scale",
        "60000",
        "--out",
        s(&p),
    ]));
    assert!(out.contains("9×8×7 u16"), "{out}");
    let want: Vec<u16> = Phantom::shepp_logan_modified()
        .sample([9, 8, 7])
        .unwrap()
        .data()
        .iter()
        .map(|&v| (f64::from(v) * 60000.0).round() as u16)
        .collect();
    match voxlab::io::read_volume(&p).unwrap() {
        AnyVolume::U16(v) => assert_eq!(v.data(), &want[..]),
        other => panic!("{:?}", other.kind()),
    }
    assert!(want.iter().any(|&v| v > 50000) && want.contains(&0));
    // i16 saturates: the sphere's 1 × 80000 is stored as 32767, the air as 0.
    let q = d.join("i16.npy");
    ok(&voxlab(&[
        "phantom",
        "sphere:6",
        "--type",
        "i16",
        "--scale",
        "80000",
        "--out",
        s(&q),
    ]));
    match voxlab::io::read_volume(&q).unwrap() {
        AnyVolume::I16(v) => {
            assert!(v.data().iter().all(|&x| x == 0 || x == i16::MAX));
            assert!(v.data().contains(&i16::MAX) && v.data().contains(&0));
        }
        other => panic!("{:?}", other.kind()),
    }
    for (flag, value, named) in [("--scale", "-1", "--scale"), ("--type", "u32", "--type")] {
        let r = d.join("refused.npy");
        let arg = format!("{flag}={value}");
        let o = voxlab(&["phantom", "sphere:6", &arg, "--out", s(&r)]);
        assert!(
            !o.status.success() && stderr(&o).contains(named),
            "{}",
            stderr(&o)
        );
        assert!(!r.exists());
    }
}

/// `convert --scale`: a [0, 1] f32 volume to u16 keeps its detail (round(v · S),
/// saturated), the input's type when no --type is given; a bad scale is refused before
/// anything is read or written.
#[test]
fn convert_scales_values_before_the_type() {
    use voxlab::phantom::Phantom;
    use voxlab::AnyVolume;
    let d = scratch("convert-scale");
    let f = d.join("f32.nrrd");
    ok(&voxlab(&[
        "phantom",
        "shepp-logan-modified:9,8,7",
        "--out",
        s(&f),
    ]));
    let truth: Vec<f64> = Phantom::shepp_logan_modified()
        .sample([9, 8, 7])
        .unwrap()
        .data()
        .iter()
        .map(|&v| f64::from(v))
        .collect();
    let u = d.join("u16.nrrd");
    ok(&voxlab(&[
        "convert",
        s(&f),
        s(&u),
        "--type",
        "u16",
        "--scale",
        "65535",
    ]));
    match voxlab::io::read_volume(&u).unwrap() {
        AnyVolume::U16(v) => {
            let want: Vec<u16> = truth
                .iter()
                .map(|&x| (x * 65535.0).round() as u16)
                .collect();
            assert_eq!(v.data(), &want[..]);
        }
        other => panic!("{:?}", other.kind()),
    }
    // No --type: an f32 input stays f32, each value times 2.
    let g = d.join("twice.nrrd");
    ok(&voxlab(&["convert", s(&f), s(&g), "--scale", "2"]));
    match voxlab::io::read_volume(&g).unwrap() {
        AnyVolume::F32(v) => {
            for (a, b) in v.data().iter().zip(&truth) {
                assert_eq!(*a, (b * 2.0) as f32);
            }
        }
        other => panic!("{:?}", other.kind()),
    }
    // u8 saturates at 255.
    let b = d.join("u8.nrrd");
    ok(&voxlab(&[
        "convert",
        s(&f),
        s(&b),
        "--type",
        "u8",
        "--scale",
        "1000",
    ]));
    match voxlab::io::read_volume(&b).unwrap() {
        AnyVolume::U8(v) => {
            for (a, t) in v.data().iter().zip(&truth) {
                assert_eq!(*a, (t * 1000.0).round().clamp(0.0, 255.0) as u8);
            }
        }
        other => panic!("{:?}", other.kind()),
    }
    for bad in ["0", "-3", "nan", "inf"] {
        let r = d.join("refused.nrrd");
        let arg = format!("--scale={bad}");
        let o = voxlab(&["convert", s(&f), s(&r), &arg]);
        assert!(
            !o.status.success() && stderr(&o).contains("--scale"),
            "{bad}: {}",
            stderr(&o)
        );
        assert!(!r.exists());
    }
}

#[test]
fn voxel_limit_from_option_and_environment() {
    let d = scratch("limit");
    let p = d.join("v.nrrd");
    ok(&voxlab(&["phantom", "sphere:8", "--out", s(&p)]));
    let o = voxlab(&["--max-voxels", "511", "info", s(&p)]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("limit of 511 voxels"));
    ok(&voxlab(&["--max-voxels", "512", "info", s(&p)]));
    let o = voxlab_command(&["info", s(&p)])
        .env("VOXLAB_MAX_VOXELS", "100")
        .output()
        .unwrap();
    assert!(stderr(&o).contains("limit of 100 voxels"));
}

#[test]
fn non_finite_voxels_are_reported_and_replaced_or_refused() {
    let d = scratch("nan");
    // 4×1×1 floats: NaN, 2, +inf, -1.
    let mut bytes = Vec::new();
    for v in [f32::NAN, 2.0, f32::INFINITY, -1.0] {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    let p = d.join("nan.raw");
    std::fs::write(&p, bytes).unwrap();
    let raw = ["--raw-dims", "4,1,1", "--raw-type", "f32"];
    let mut args = vec!["info", s(&p), "--json"];
    args.extend(raw);
    let j = json(&voxlab(&args));
    assert_eq!(j["non_finite"]["nan"], 1);
    assert_eq!(j["non_finite"]["pos_inf"], 1);
    assert_eq!(j["range"]["min"], -1.0);
    // Rendering replaces them by the rule and says so.
    let out = d.join("x.npy");
    let mut args = vec![
        "render",
        s(&p),
        "--mode",
        "xray",
        "--view",
        "+z",
        "--step",
        "1",
        "--out",
        s(&out),
    ];
    args.extend(raw);
    let o = voxlab(&args);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("1 NaN, 1 +inf and 0 -inf"), "{err}");
    let img = voxlab::io::npy::read_npy_f32(&out).unwrap().1;
    // NaN → min (-1), +inf → max (2): one voxel along z, spacing 1.
    assert_eq!(img, vec![-1.0, 2.0, 2.0, -1.0]);
    // --non-finite error refuses and writes nothing.
    std::fs::remove_file(&out).unwrap();
    args.extend(["--non-finite", "error"]);
    let o = voxlab(&args);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("non-finite"));
    assert!(!out.exists());
}

#[test]
fn convert_crops_resamples_and_retypes() {
    let d = scratch("convert");
    let src = d.join("sl.nrrd");
    ok(&voxlab(&["phantom", "shepp-logan:32", "--out", s(&src)]));
    let v = voxlab::io::read_volume(&src).unwrap();
    // Crop: the kept voxels equal the source's, at the same world positions.
    let crop = d.join("crop.nrrd");
    let o = voxlab(&["convert", s(&src), s(&crop), "--crop", "4,5,6,20,21,22"]);
    ok(&o);
    let c = voxlab::io::read_volume(&crop).unwrap();
    assert_eq!(c.dims(), [16, 16, 16]);
    let (sv, cv) = (v.values_f64(), c.values_f64());
    for (i, j, k) in [(0, 0, 0), (15, 3, 7), (9, 15, 15)] {
        assert_eq!(
            cv[i + 16 * (j + 16 * k)],
            sv[(i + 4) + 32 * ((j + 5) + 32 * (k + 6))]
        );
        let w_src = v.affine().transform_point3(glam::DVec3::new(
            (i + 4) as f64,
            (j + 5) as f64,
            (k + 6) as f64,
        ));
        let w_crop = c
            .affine()
            .transform_point3(glam::DVec3::new(i as f64, j as f64, k as f64));
        assert!((w_src - w_crop).length() < 1e-4, "{w_src} vs {w_crop}");
    }
    // Resample to half the spacing with nearest: every source voxel becomes 2×2×2.
    let fine = d.join("fine.npy");
    let sp = v.spacing()[0] / 2.0;
    ok(&voxlab(&[
        "convert",
        s(&src),
        s(&fine),
        "--spacing",
        &sp.to_string(),
        "--filter",
        "nearest",
    ]));
    let f = voxlab::io::read_volume(&fine).unwrap();
    assert_eq!(f.dims(), [64, 64, 64]);
    let fv = f.values_f64();
    for (i, j, k) in [(0, 0, 0), (33, 17, 40), (63, 63, 63)] {
        assert_eq!(
            fv[i + 64 * (j + 64 * k)],
            sv[i / 2 + 32 * (j / 2 + 32 * (k / 2))]
        );
    }
    // --type u8 rounds and clamps.
    let u8p = d.join("u8.nrrd");
    ok(&voxlab(&["convert", s(&src), s(&u8p), "--type", "u8"]));
    let u = voxlab::io::read_volume(&u8p).unwrap();
    assert_eq!(u.kind(), voxlab::volume::VoxelKind::U8);
    for (a, b) in u.values_f64().iter().zip(&sv) {
        assert_eq!(*a, b.round().clamp(0.0, 255.0));
    }
    // A crop box outside the volume is refused, and nothing is written.
    let bad = d.join("bad.nrrd");
    let o = voxlab(&["convert", s(&src), s(&bad), "--crop", "0,0,0,33,1,1"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("crop box"));
    assert!(!bad.exists());
}

#[test]
fn info_reports_format_orientation_and_draws_a_plot() {
    let d = scratch("info");
    let src = d.join("v.nrrd");
    ok(&voxlab(&["phantom", "spheres:16", "--out", s(&src)]));
    let plot = d.join("hist.png");
    let text = ok(&voxlab(&["info", s(&src), "--plot", s(&plot)]));
    assert!(text.contains("format    NRRD"), "{text}");
    assert!(text.contains("x → +X, y → +Y, z → +Z"), "{text}");
    assert!(text.contains("0 NaN"), "{text}");
    let img = image::open(&plot).unwrap().to_rgba8();
    assert_eq!(img.dimensions(), (768, 320));
    // Bars are drawn: some pixels are the bar colour.
    assert!(img.pixels().any(|p| p.0[2] > 200 && p.0[0] < 160));
}

#[test]
fn slices_are_laid_out_like_numpy_and_16_bit_png_keeps_values() {
    let d = scratch("slice");
    let p = raw_file(&d);
    let value = |i: usize, j: usize, k: usize| (i + 10 * j + 100 * k) as f32;
    // a[k=1, :, :] as float32 .npy: rows y, columns x.
    let npy = d.join("z1.npy");
    ok(&voxlab(&with_raw(&[
        "slice",
        s(&p),
        "--axis",
        "z",
        "--index",
        "1",
        "--out",
        s(&npy),
    ])));
    let (shape, vals) = voxlab::io::npy::read_npy_f32(&npy).unwrap();
    assert_eq!(shape, vec![4, 5]);
    for (n, v) in vals.iter().enumerate() {
        assert_eq!(*v, value(n % 5, n / 5, 1));
    }
    // a[:, :, i=3] as 16-bit PNG with the window [0, 65535]: pixel = value exactly.
    let png = d.join("x3.png");
    ok(&voxlab(&with_raw(&[
        "slice",
        s(&p),
        "--axis",
        "x",
        "--index",
        "3",
        "--sixteen-bit",
        "--window",
        "65535",
        "--level",
        "32767.5",
        "--out",
        s(&png),
    ])));
    let img = image::open(&png).unwrap().to_luma16();
    assert_eq!(img.dimensions(), (4, 3));
    for (col, row, px) in img.enumerate_pixels() {
        assert_eq!(px.0[0] as f32, value(3, col as usize, row as usize));
    }
    // Out of range.
    let o = voxlab(&with_raw(&[
        "slice",
        s(&p),
        "--axis",
        "y",
        "--index",
        "4",
        "--out",
        s(&png),
    ]));
    assert!(!o.status.success());
    assert!(stderr(&o).contains("outside the volume"));
}

#[test]
fn a_directory_of_tiff_files_is_a_stack_in_natural_order() {
    use tiff::encoder::{colortype::Gray16, TiffEncoder};
    let d = scratch("tiffdir");
    let stack = d.join("stack");
    std::fs::create_dir_all(&stack).unwrap();
    // Slices named so that plain string order (s1, s10, s2) would be wrong.
    for (name, value) in [("s1.tif", 1u16), ("s2.tif", 2), ("s10.tif", 10)] {
        let f = std::fs::File::create(stack.join(name)).unwrap();
        let mut enc = TiffEncoder::new(f).unwrap();
        enc.write_image::<Gray16>(3, 2, &[value; 6]).unwrap();
    }
    std::fs::write(stack.join("notes.txt"), b"not an image").unwrap();
    let j = json(&voxlab(&["info", s(&stack), "--json"]));
    assert_eq!(j["format"], "TIFF stack");
    assert_eq!(j["dims"], serde_json::json!([3, 2, 3]));
    let v = voxlab::io::read_volume(&stack).unwrap();
    let vals = v.values_f64();
    assert_eq!([vals[0], vals[6], vals[12]], [1.0, 2.0, 10.0]);
}

#[test]
fn convert_keeps_nan_and_infinities_and_refuses_what_cannot_hold_them() {
    let dir = common::scratch("convert_non_finite");
    let data = vec![
        1.0f32,
        f32::NAN,
        -2.5,
        f32::INFINITY,
        f32::NEG_INFINITY,
        7.0,
        0.0,
        3.0,
    ];
    let vol: voxlab::AnyVolume = voxlab::Volume::new([2, 2, 2], [1.0; 3], data.clone())
        .unwrap()
        .into();
    let input = dir.join("nan.nii.gz");
    voxlab::io::write_volume(&input, &vol).unwrap();
    let bits = |v: &voxlab::AnyVolume| -> Vec<u32> {
        v.values_f64()
            .iter()
            .map(|&x| (x as f32).to_bits())
            .collect()
    };
    // Every format keeps every value, bit for bit.
    for ext in ["nrrd", "nhdr", "npy", "nii"] {
        let out = dir.join(format!("out.{ext}"));
        let o = common::voxlab(&["convert", common::s(&input), common::s(&out)]);
        assert!(o.status.success(), "{ext}: {}", common::stderr(&o));
        let back = voxlab::io::read_volume(&out).unwrap();
        assert_eq!(bits(&back), bits(&vol), "{ext}");
    }
    // An integer type and resampling cannot keep them: refused, with the way out.
    let out = dir.join("u8.nrrd");
    let o = common::voxlab(&[
        "convert",
        common::s(&input),
        common::s(&out),
        "--type",
        "u8",
    ]);
    assert_eq!(o.status.code(), Some(1));
    let e = common::stderr(&o);
    assert!(e.contains("invalid --type:"), "{e}");
    assert!(
        e.contains("1 NaN, 1 +inf and 1 -inf voxel(s) (first at index 1)"),
        "{e}"
    );
    assert!(e.contains("--replace-non-finite"), "{e}");
    assert!(!out.exists());
    let o = common::voxlab(&[
        "convert",
        common::s(&input),
        common::s(&out),
        "--resize",
        "1,1,1",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(common::stderr(&o).contains("which resampling cannot keep"));
    // Asked for, the rendering rule: NaN and -inf → the smallest finite value (-2.5),
    // +inf → the largest (7); then rounded and clamped into u8 (-2.5 → 0).
    let out = dir.join("f32.nrrd");
    let o = common::voxlab(&[
        "convert",
        common::s(&input),
        common::s(&out),
        "--replace-non-finite",
    ]);
    assert!(o.status.success(), "{}", common::stderr(&o));
    assert!(common::stderr(&o).contains("replaced"));
    assert_eq!(
        voxlab::io::read_volume(&out).unwrap().values_f64(),
        vec![1.0, -2.5, -2.5, 7.0, -2.5, 7.0, 0.0, 3.0]
    );
    // --non-finite error refuses the input outright.
    let o = common::voxlab(&[
        "convert",
        common::s(&input),
        common::s(&out),
        "--non-finite",
        "error",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        common::stderr(&o).contains("non-finite"),
        "{}",
        common::stderr(&o)
    );
}
