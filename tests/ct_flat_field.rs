//! Raw CT projections: intensities made from the exact line integrals of an analytic
//! phantom, `I = D + (F − D)·exp(−p)` with non-uniform flat and dark fields given as
//! stacks of frames, read back from `.npy`, MetaImage and TIFF and turned into line
//! integrals again; dead and starved pixels counted exactly; the reconstruct job and
//! the command line with `--flat` / `--dark`.

mod common;

use common::{s, scratch, stderr, voxlab};
use glam::DVec3;
use std::fs::File;
use std::path::{Path, PathBuf};
use tiff::encoder::{colortype, TiffEncoder};
use voxlab::cpu::project::project_phantom;
use voxlab::ct::flat_field::{line_integrals, IntensityReport, RATIO_FLOOR};
use voxlab::ct::{Geometry, Projections};
use voxlab::io::metaimage::{write_metaimage, MetaImageWriteOptions};
use voxlab::io::npy::write_npy_f64;
use voxlab::io::projections::{read_field_image, read_projections, write_geometry};
use voxlab::io::ReadOptions;
use voxlab::jobs::reconstruct::{run, ReconstructRequest};
use voxlab::jobs::Backend;
use voxlab::phantom::{Phantom, Primitive};
use voxlab::{AnyVolume, Volume};

/// Recovered line integrals from f64 intensities: a few ulps of `I/(I − D)` (measured
/// 3.3e-16 here; the intensities are at most ~12× their dark-subtracted part).
const F64_TOL: f64 = 1e-12;
/// From intensities rounded to f32 (MetaImage and TIFF hold f32 here): the rounding
/// of `I` (2^-24 relative) over `I − D` (at least 1/12 of `I` on these fields), so
/// below 12·6e-8 = 7.2e-7 (measured 6.9e-8).
const F32_TOL: f64 = 1e-6;

/// A cone beam of 32 × 24 pixels, 24 views over a full turn.
fn geometry() -> Geometry {
    Geometry::cone_rtk(
        1000.0,
        1500.0,
        32,
        24,
        4.0,
        4.0,
        Geometry::even_angles(24, 360.0),
    )
    .unwrap()
}

/// A ball of radius 25.6 mm and density 0.02 per mm: line integrals up to ~1.
fn line_integrals_truth(g: &Geometry) -> Projections<f64> {
    let ph = Phantom::from_primitives("ball", vec![Primitive::sphere(0.02, DVec3::ZERO, 0.2)]);
    project_phantom(&ph, g).unwrap()
}

/// Integer-valued, non-uniform flat and dark images, and three frames of each whose
/// mean is exactly the image (F − 1, F, F + 1).
fn fields(pixels: usize) -> (Vec<f64>, Vec<f64>) {
    let flat = (0..pixels)
        .map(|k| 1000.0 + 37.0 * (k % 7) as f64 + (k / 32) as f64)
        .collect();
    let dark = (0..pixels).map(|k| 90.0 + (k % 5) as f64).collect();
    (flat, dark)
}

fn frames(image: &[f64]) -> Vec<f64> {
    [-1.0, 0.0, 1.0]
        .iter()
        .flat_map(|d| image.iter().map(move |v| v + d))
        .collect()
}

/// `I = D + (F − D)·exp(−p)`, exactly `F` where `p = 0`.
fn intensities(p: &Projections<f64>, flat: &[f64], dark: &[f64]) -> Projections<f64> {
    let n = p.rows * p.cols;
    let data = p
        .data
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            let k = i % n;
            if v == 0.0 {
                flat[k]
            } else {
                dark[k] + (flat[k] - dark[k]) * (-v).exp()
            }
        })
        .collect();
    Projections::new(p.angles, p.rows, p.cols, data).unwrap()
}

fn npy(path: &Path, shape: &[usize], values: &[f64]) {
    write_npy_f64(path, shape, values).unwrap();
}

fn mha(path: &Path, dims: [usize; 3], values: &[f64]) {
    let v: Vec<f32> = values.iter().map(|&x| x as f32).collect();
    let vol = AnyVolume::from(Volume::new(dims, [1.0; 3], v).unwrap());
    write_metaimage(path, &vol, MetaImageWriteOptions { compress: false }).unwrap();
}

/// One f32 page per view (`cols × rows`).
fn tiff_pages(path: &Path, cols: usize, rows: usize, values: &[f64]) {
    let mut enc = TiffEncoder::new(File::create(path).unwrap()).unwrap();
    for page in values.chunks_exact(cols * rows) {
        let v: Vec<f32> = page.iter().map(|&x| x as f32).collect();
        enc.write_image::<colortype::Gray32Float>(cols as u32, rows as u32, &v)
            .unwrap();
    }
}

fn f32_rounded(v: &[f64]) -> Vec<f64> {
    v.iter().map(|&x| f64::from(x as f32)).collect()
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
}

/// The files of one case: intensities, flat and dark frames, geometry.
struct Case {
    dir: PathBuf,
    p: Projections<f64>,
    i: Projections<f64>,
    flat: Vec<f64>,
    dark: Vec<f64>,
}

fn case(name: &str) -> Case {
    let dir = scratch(name);
    let g = geometry();
    let p = line_integrals_truth(&g);
    let (flat, dark) = fields(g.rows * g.cols);
    let i = intensities(&p, &flat, &dark);
    write_geometry(&dir.join("g.json"), &g).unwrap();
    Case {
        dir,
        p,
        i,
        flat,
        dark,
    }
}

fn request(
    c: &Case,
    input: &Path,
    flat: Option<&PathBuf>,
    dark: Option<&PathBuf>,
) -> ReconstructRequest {
    ReconstructRequest {
        input: input.to_path_buf(),
        geometry: Some(s(&c.dir.join("g.json")).to_string()),
        size: Some(24),
        backend: Backend::Cpu,
        flat: flat.cloned(),
        dark: dark.cloned(),
        ..Default::default()
    }
}

#[test]
fn npy_intensities_give_the_line_integrals_back_in_f64() {
    let c = case("flat-npy");
    let (a, r, k) = (c.p.angles, c.p.rows, c.p.cols);
    let (fi, di, pi) = (
        c.dir.join("i.npy"),
        c.dir.join("flat.npy"),
        c.dir.join("p.npy"),
    );
    npy(&fi, &[a, r, k], &c.i.data);
    npy(&di, &[3, r, k], &frames(&c.flat));
    let dark = c.dir.join("dark.npy");
    npy(&dark, &[r, k], &c.dark);
    npy(&pi, &[a, r, k], &c.p.data);
    // The library function on what the readers give.
    let i = read_projections::<f64>(&fi).unwrap();
    let f = read_field_image(&di, "flat", r, k, &ReadOptions::default()).unwrap();
    assert_eq!(
        f, c.flat,
        "three frames F − 1, F, F + 1 average to F exactly"
    );
    let d = read_field_image(&dark, "dark", r, k, &ReadOptions::default()).unwrap();
    let (p, report) = line_integrals(&i, &f, Some(&d[..])).unwrap();
    let err = max_abs_diff(&p.data, &c.p.data);
    eprintln!("npy: max |Δp| = {err:e}");
    assert!(err < F64_TOL, "max |Δp| = {err:e}");
    assert_eq!(
        (
            report.dead_pixels,
            report.starved,
            report.clamped,
            report.above_flat
        ),
        (0, 0, 0, 0),
        "{report:?}"
    );
    // FDK from the intensities equals FDK from the line integrals.
    let from_i = run(&request(&c, &fi, Some(&di), Some(&dark)), &()).unwrap();
    let from_p = run(&request(&c, &pi, None, None), &()).unwrap();
    assert!(from_p.intensity.is_none());
    assert_eq!(from_i.intensity.unwrap().samples, a * r * k);
    let (x, y) = (&from_i.reconstruction.data, &from_p.reconstruction.data);
    let scale = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(scale > 0.01, "the ball is there: {scale}");
    let err = max_abs_diff(x, y);
    eprintln!("npy: max |Δ FDK| = {err:e}");
    assert!(err < 1e-12, "max |Δ FDK| = {err:e} (values up to {scale})");
}

#[test]
fn metaimage_and_tiff_stacks_read_like_npy() {
    let c = case("flat-formats");
    let (a, r, k) = (c.p.angles, c.p.rows, c.p.cols);
    // The same f32-rounded intensities in three formats; flat and dark are integers.
    let i32 = f32_rounded(&c.i.data);
    let fi_npy = c.dir.join("i.npy");
    npy(&fi_npy, &[a, r, k], &i32);
    let fi_mha = c.dir.join("i.mha");
    mha(&fi_mha, [k, r, a], &i32);
    let fi_tif = c.dir.join("i.tif");
    tiff_pages(&fi_tif, k, r, &i32);
    let flat_mha = c.dir.join("flat.mha");
    mha(&flat_mha, [k, r, 3], &frames(&c.flat));
    // The dark field as a directory of single-page TIFFs (three frames).
    let dark_dir = c.dir.join("dark");
    std::fs::create_dir_all(&dark_dir).unwrap();
    for (n, frame) in frames(&c.dark).chunks_exact(r * k).enumerate() {
        tiff_pages(&dark_dir.join(format!("dark{n}.tif")), k, r, frame);
    }
    let flat_npy = c.dir.join("flat.npy");
    npy(&flat_npy, &[r, k], &c.flat);
    let dark_npy = c.dir.join("dark.npy");
    npy(&dark_npy, &[r, k], &c.dark);
    let base = run(&request(&c, &fi_npy, Some(&flat_npy), Some(&dark_npy)), &()).unwrap();
    for input in [&fi_mha, &fi_tif] {
        let i = read_projections::<f64>(input).unwrap();
        assert_eq!(i.data, i32, "{} reads the values written", input.display());
        let f = read_field_image(&flat_mha, "flat", r, k, &ReadOptions::default()).unwrap();
        let d = read_field_image(&dark_dir, "dark", r, k, &ReadOptions::default()).unwrap();
        assert_eq!((&f, &d), (&c.flat, &c.dark));
        let (p, _) = line_integrals(&i, &f, Some(&d[..])).unwrap();
        let err = max_abs_diff(&p.data, &c.p.data);
        eprintln!("{}: max |Δp| = {err:e}", input.display());
        assert!(err < F32_TOL, "{}: max |Δp| = {err:e}", input.display());
        let got = run(&request(&c, input, Some(&flat_mha), Some(&dark_dir)), &()).unwrap();
        assert_eq!(
            got.reconstruction.data,
            base.reconstruction.data,
            "{}: FDK equals the .npy one bit for bit",
            input.display()
        );
    }
}

#[test]
fn dead_starved_and_bright_pixels_are_counted_and_finite() {
    let c = case("flat-defects");
    let (r, k) = (c.p.rows, c.p.cols);
    let n = r * k;
    let (mut flat, dark) = (c.flat.clone(), c.dark.clone());
    let mut i = c.i.clone();
    // Dead pixels: F = D (3) and F < D (40).
    flat[3] = dark[3];
    flat[40] = dark[40] - 7.0;
    // Starved: I = D and I < D on live pixels; one view's pixel brighter than the flat.
    i.data[5 * n + 100] = dark[100];
    i.data[7 * n + 101] = dark[101] - 50.0;
    i.data[9 * n + 102] = flat[102] + 5.0;
    let (p, report) = line_integrals(&i, &flat, Some(&dark[..])).unwrap();
    assert!(p.data.iter().all(|v| v.is_finite()));
    assert_eq!(
        report,
        IntensityReport {
            samples: i.data.len(),
            pixels: n,
            dead_pixels: 2,
            starved: 2,
            clamped: 2,
            above_flat: 1,
        }
    );
    for view in 0..p.angles {
        assert_eq!(p.data[view * n + 3], 0.0);
        assert_eq!(p.data[view * n + 40], 0.0);
    }
    assert_eq!(p.data[5 * n + 100], -RATIO_FLOOR.ln());
    assert_eq!(p.data[7 * n + 101], -RATIO_FLOOR.ln());
    assert!(p.data[9 * n + 102] < 0.0);
    // Every other sample is the truth.
    let defects = [5 * n + 100, 7 * n + 101, 9 * n + 102];
    for (j, (&got, &want)) in p.data.iter().zip(&c.p.data).enumerate() {
        if j % n == 3 || j % n == 40 || defects.contains(&j) {
            continue;
        }
        assert!((got - want).abs() < F64_TOL, "sample {j}: {got} vs {want}");
    }
}

#[test]
fn the_command_line_converts_and_refuses_bad_fields() {
    let c = case("flat-cli");
    let (a, r, k) = (c.p.angles, c.p.rows, c.p.cols);
    let fi = c.dir.join("i.mha");
    mha(&fi, [k, r, a], &f32_rounded(&c.i.data));
    let flat = frames(&c.flat);
    let flat_file = c.dir.join("flat.npy");
    npy(&flat_file, &[3, r, k], &flat);
    let mut dark = c.dark.clone();
    dark[7] = 5000.0; // dead: D > F
    let dark_file = c.dir.join("dark.mha");
    mha(&dark_file, [k, r, 1], &dark);
    let out = c.dir.join("r.npy");
    let g = c.dir.join("g.json");
    let o = voxlab(&[
        "reconstruct",
        s(&fi),
        "--geometry",
        s(&g),
        "--flat",
        s(&flat_file),
        "--dark",
        s(&dark_file),
        "--size",
        "24",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    let line = text
        .lines()
        .find(|l| l.starts_with("flat/dark:"))
        .unwrap_or_else(|| panic!("no flat/dark line in {text}"));
    assert!(
        line.contains(&format!("{} samples", a * r * k)) && line.contains("1 dead pixel(s)"),
        "{line}"
    );
    assert!(out.is_file());
    // A flat field of the wrong shape: the file and the field named, nothing written.
    let bad = c.dir.join("flat-bad.npy");
    npy(&bad, &[2, r, k + 1], &vec![1000.0; 2 * r * (k + 1)]);
    let out2 = c.dir.join("r2.npy");
    let with = |extra: &[&str]| {
        let mut all = vec!["reconstruct", s(&fi), "--geometry", s(&g), "--size", "24"];
        all.extend_from_slice(extra);
        all.extend_from_slice(&["--out", s(&out2)]);
        voxlab(&all)
    };
    let o = with(&["--flat", s(&bad)]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("flat-bad.npy") && e.contains("shape") && e.contains("flat"),
        "{e}"
    );
    assert!(!out2.exists(), "a failed run writes nothing");
    // NaN in the dark field; an empty flat stack; --dark without --flat.
    let nan = c.dir.join("dark-nan.npy");
    let mut d = c.dark.clone();
    d[11] = f64::NAN;
    npy(&nan, &[r, k], &d);
    let o = with(&["--flat", s(&flat_file), "--dark", s(&nan)]);
    let e = stderr(&o);
    assert!(
        !o.status.success() && e.contains("dark-nan.npy") && e.contains("NaN"),
        "{e}"
    );
    let empty = c.dir.join("flat-empty.npy");
    npy(&empty, &[0, r, k], &[]);
    let o = with(&["--flat", s(&empty)]);
    let e = stderr(&o);
    assert!(
        !o.status.success() && e.contains("flat-empty.npy") && e.contains("no frames"),
        "{e}"
    );
    let o = with(&["--dark", s(&dark_file)]);
    assert!(!o.status.success(), "{}", stderr(&o));
    assert!(!out2.exists(), "a failed run writes nothing");
}
