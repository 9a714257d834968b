//! `voxlab project`: runs, output shapes and layouts, the analytic value of known
//! pixels, the volume-file placement, and clear errors on bad arguments.

mod common;

use common::{s, scratch, stderr, voxlab};
use voxlab::ct::Beam;
use voxlab::io::npy::read_npy_f64;
use voxlab::io::projections::{read_geometry, read_projections};

/// phantom:sphere is a ball of density 1 and radius 0.6 × 128 mm: the central chord.
const SPHERE_CHORD: f64 = 2.0 * 0.6 * 128.0;

#[test]
fn a_parallel_phantom_sinogram_is_written_in_skimage_layout() {
    let d = scratch("parallel");
    let out = d.join("sino.npy");
    let png = d.join("sino.png");
    let o = voxlab(&[
        "project",
        "phantom:sphere",
        "--angles",
        "8",
        "--out",
        s(&out),
        "--png",
        s(&png),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (shape, v, f8) = read_npy_f64(&out).unwrap();
    // Defaults: 256 columns of 1 mm, one row → (detector, angle), float64.
    assert_eq!((shape.as_slice(), f8), (&[256usize, 8][..], true));
    for a in 0..8 {
        // Column 128 (= cols/2, scikit-image's centre) passes through the centre.
        let got = v[128 * 8 + a];
        assert!((got - SPHERE_CHORD).abs() < 1e-9, "angle {a}: {got}");
        // Column 128 + 40: the chord at distance 40 mm.
        let want = 2.0 * (76.8f64 * 76.8 - 40.0 * 40.0).sqrt();
        assert!((v[168 * 8 + a] - want).abs() < 1e-9);
    }
    let g = read_geometry(&d.join("sino.geometry.json")).unwrap();
    assert_eq!(
        (g.beam, g.cols, g.rows, g.cu),
        (Beam::Parallel, 256, 1, 128.0)
    );
    assert_eq!(g.angles_deg, voxlab::ct::Geometry::even_angles(8, 180.0));
    assert!(std::fs::metadata(&png).unwrap().len() > 100);
    // The same sinogram as a stack on request.
    let out3 = d.join("stack.npy");
    let o = voxlab(&[
        "project",
        "phantom:sphere",
        "--angles",
        "8",
        "--layout",
        "stack",
        "--out",
        s(&out3),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(read_npy_f64(&out3).unwrap().0, vec![8, 1, 256]);
}

#[test]
fn cone_joseph_on_cpu_and_gpu_agree_with_the_analytic_centre() {
    let d = scratch("cone");
    let geo = [
        "--geometry",
        "cone",
        "--cols",
        "33",
        "--rows",
        "17",
        "--du",
        "12",
        "--angles",
        "6",
    ];
    let run = |out: &std::path::Path, extra: &[&str]| {
        let mut args = vec!["project", "phantom:sphere:48", "--out", s(out)];
        args.extend_from_slice(&geo);
        args.extend_from_slice(extra);
        let o = voxlab(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        read_projections::<f64>(out).unwrap()
    };
    let exact = run(&d.join("exact.npy"), &[]);
    let cpu = run(&d.join("cpu.nrrd"), &["--method", "joseph"]);
    let f32 = run(
        &d.join("f32.npy"),
        &["--method", "joseph", "--backend", "cpu-f32"],
    );
    assert!(
        !read_npy_f64(&d.join("f32.npy")).unwrap().2,
        "cpu-f32 writes float32"
    );
    assert_eq!((exact.angles, exact.rows, exact.cols), (6, 17, 33));
    let centre = 8 * 33 + 16;
    for k in 0..6 {
        // The central ray of the centred detector goes through the isocentre.
        assert!((exact.view(k)[centre] - SPHERE_CHORD).abs() < 1e-9);
        // Joseph on the 48³ grid (256/48 mm voxels). At 0° and 180° the central ray
        // runs along a grid axis through 28 sampled voxels (centres within 76.8 mm):
        // exactly 28 × 256/48 mm. Elsewhere the sampled edge moves the chord by less
        // than a voxel; measured −2.31 mm.
        let j = cpu.view(k)[centre];
        if k % 3 == 0 {
            // (read from the float32 NRRD: rounded to f32)
            assert!((j - 28.0 * 256.0 / 48.0).abs() < 2e-5, "{k}: {j}");
        }
        assert!((j - SPHERE_CHORD).abs() < 256.0 / 48.0, "{k}: {j}");
        // Measured: 1.5e-5 (the f32 file's rounding of ~150).
        assert!((f32.view(k)[centre] - j).abs() < 1e-4);
    }
    let g = read_geometry(&d.join("cpu.geometry.json")).unwrap();
    assert_eq!(
        g.beam,
        Beam::Cone {
            sid: 1000.0,
            sdd: 1500.0
        }
    );
    if voxlab::gpu::GpuContext::shared().is_ok() {
        let gpu = run(
            &d.join("gpu.npy"),
            &["--method", "joseph", "--backend", "gpu"],
        );
        let worst = gpu
            .data
            .iter()
            .zip(&cpu.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        // NRRD holds float32, so both are f32-rounded; see tests/gpu_ct_project.rs.
        // Measured on lavapipe: 4.0e-4 (of values up to ~150).
        assert!(worst < 2e-3, "{worst}");
    }
}

#[test]
fn a_volume_file_is_placed_like_the_phantom() {
    let d = scratch("file");
    let vol = d.join("ball.nrrd");
    let o = voxlab(&["phantom", "spheres:24", "--out", s(&vol)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let angles = d.join("angles.txt");
    std::fs::write(&angles, "# degrees\n0\n30\n90 # side\n").unwrap();
    let common = [
        "--angles-file",
        s(&angles),
        "--cols",
        "40",
        "--rows",
        "5",
        "--du",
        "8",
    ];
    let mut a = vec!["project", s(&vol), "--out"];
    let from_file = d.join("file.npy");
    a.push(s(&from_file));
    a.extend_from_slice(&common);
    let o = voxlab(&a);
    assert!(o.status.success(), "{}", stderr(&o));
    let from_phantom = d.join("phantom.npy");
    let mut b = vec![
        "project",
        "phantom:spheres:24",
        "--method",
        "joseph",
        "--out",
    ];
    b.push(s(&from_phantom));
    b.extend_from_slice(&common);
    let o = voxlab(&b);
    assert!(o.status.success(), "{}", stderr(&o));
    let (p, q) = (
        read_projections::<f64>(&from_file).unwrap(),
        read_projections::<f64>(&from_phantom).unwrap(),
    );
    assert_eq!((p.angles, p.rows, p.cols), (3, 5, 40));
    let worst = p
        .data
        .iter()
        .zip(&q.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    // The same samples and placement; only the f32 sample values and the affine's
    // rounding differ, and for these values neither does. Measured: 0.
    assert!(worst < 1e-9, "{worst}");
    assert!(q.data.iter().any(|&v| v > 10.0));
    // The analytic method needs a phantom.
    let o = voxlab(&[
        "project",
        s(&vol),
        "--method",
        "analytic",
        "--out",
        s(&from_file),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("phantoms only"), "{}", stderr(&o));
}

#[test]
fn bad_arguments_are_clear_errors() {
    let d = scratch("bad");
    let out = d.join("p.npy");
    let angles = d.join("bad.txt");
    std::fs::write(&angles, "0\nfive\n").unwrap();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["--sid", "500"], "only a cone beam"),
        (vec!["--angles", "0"], "at least 1"),
        (vec!["--cols", "0"], "detector columns"),
        (vec!["--du=-1"], "du"),
        (vec!["--layout", "skimage", "--rows", "4"], "one row"),
        (vec!["--backend", "gpu"], "CPU in f64 only"),
        (vec!["--geometry", "cone", "--sdd", "nan"], "SDD"),
        (vec!["--angles-file", s(&angles)], "line 2"),
        (
            vec!["--angles-file", s(&angles), "--angles", "3"],
            "cannot be used with",
        ),
    ];
    for (extra, words) in cases {
        let mut args = vec!["project", "phantom:sphere:8", "--out", s(&out)];
        args.extend_from_slice(&extra);
        let o = voxlab(&args);
        assert!(!o.status.success(), "{extra:?}");
        assert!(stderr(&o).contains(words), "{extra:?}: {}", stderr(&o));
    }
    let o = voxlab(&["project", "phantom:sphere:8", "--out", s(&d.join("p.png"))]);
    assert!(
        stderr(&o).contains(".npy, .nrrd or .nhdr"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists());
}

/// Joseph on the GPU: the 32³ Shepp–Logan grid through 12 cone-beam views of 40 × 30
/// pixels of 8 mm (the scene of the split and texture tests).
const GPU_CONE_32: [&str; 16] = [
    "project",
    "phantom:shepp-logan:32",
    "--geometry",
    "cone",
    "--angles",
    "12",
    "--cols",
    "40",
    "--rows",
    "30",
    "--du",
    "8",
    "--method",
    "joseph",
    "--backend",
    "gpu",
];

#[test]
fn a_split_gpu_projection_says_so_and_matches_the_unsplit_one() {
    if common::gpu("a_split_gpu_projection_says_so_and_matches_the_unsplit_one").is_none() {
        return;
    }
    let d = scratch("project-split");
    let run = |out: &std::path::Path, binding: Option<&str>, dry: bool| {
        let mut args = GPU_CONE_32.to_vec();
        args.extend_from_slice(&["--out", s(out)]);
        if dry {
            args.push("--dry-run");
        }
        // 32 × 32 slices of 4 KiB: 5 per slab in 20 KiB.
        let o = common::voxlab_with_binding(&args, binding);
        assert!(o.status.success(), "{}", stderr(&o));
        o
    };
    let (whole, split) = (d.join("whole.npy"), d.join("split.npy"));
    run(&whole, None, false);
    let o = run(&split, Some("20KiB"), false);
    assert!(
        stderr(&o).contains("projection in 7 slabs of 5 slices"),
        "{}",
        stderr(&o)
    );
    let (_, a, _) = read_npy_f64(&whole).unwrap();
    let (_, b, _) = read_npy_f64(&split).unwrap();
    let peak = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let worst = a
        .iter()
        .zip(&b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    // The slabs' sums in another order (tests/gpu_ct_project.rs: within 1.7e-6).
    assert!(peak > 1.0 && worst <= 1e-5 * peak, "{worst:e} of {peak:e}");
    let never = d.join("never.npy");
    let o = run(&never, Some("20KiB"), true);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("split:  projection in 7 slabs of 5 slices"),
        "{text}"
    );
    assert!(!never.exists());
}

/// `--hardware-filtering`: the grid sampled from 3-D textures, the report says so, a
/// split run says so too, the projections are within the texture unit's bound of the
/// exact run (on a CPU adapter, which filters in f32, within f32 rounding), and the
/// option is refused off the GPU and for the analytic method, writing nothing.
#[test]
fn hardware_filtering_samples_the_grid_from_a_texture() {
    let Some(ctx) = common::gpu("hardware_filtering_samples_the_grid_from_a_texture") else {
        return;
    };
    if !ctx.features.contains(wgpu::Features::FLOAT32_FILTERABLE) {
        eprintln!("hardware_filtering: this adapter cannot filter f32 textures");
        return;
    }
    let d = scratch("project-hardware");
    let run = |out: &std::path::Path, extra: &[&str], binding: Option<&str>| {
        let mut args = GPU_CONE_32.to_vec();
        args.extend_from_slice(&["--out", s(out)]);
        args.extend_from_slice(extra);
        let o = common::voxlab_with_binding(&args, binding);
        assert!(o.status.success(), "{}", stderr(&o));
        format!("{}{}", String::from_utf8_lossy(&o.stdout), stderr(&o))
    };
    let hw = ["--hardware-filtering"];
    let (exact, whole, split) = (d.join("exact.npy"), d.join("hw.npy"), d.join("split.npy"));
    run(&exact, &[], None);
    let said = run(&whole, &hw, None);
    assert!(said.contains("grid filtered by the texture unit"), "{said}");
    // 34 × 34 texels a bordered slice (4,624 bytes): 20 KiB holds 2 slices and the
    // border.
    let said = run(&split, &hw, Some("20KiB"));
    let line = "projection in 16 slabs of 2 slices, grid in 3-D textures";
    assert!(said.contains(line), "{said}");
    let never = d.join("never.npy");
    let mut dry = hw.to_vec();
    dry.push("--dry-run");
    let said = run(&never, &dry, Some("20KiB"));
    assert!(said.contains(&format!("split:  {line}")), "{said}");
    assert!(!never.exists());

    let (_, a, _) = read_npy_f64(&exact).unwrap();
    let (_, b, _) = read_npy_f64(&whole).unwrap();
    let (_, c, _) = read_npy_f64(&split).unwrap();
    let diff = |x: &[f64], y: &[f64]| {
        x.iter()
            .zip(y)
            .fold(0.0f64, |m, (p, q)| m.max((p - q).abs()))
    };
    let peak = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let grid = voxlab::cpu::project::Grid::<f64>::phantom(
        &voxlab::phantom::Phantom::shepp_logan(),
        [32; 3],
    )
    .unwrap();
    let g = voxlab::ct::Geometry::cone_rtk(
        1000.0,
        1500.0,
        40,
        30,
        8.0,
        8.0,
        voxlab::ct::Geometry::even_angles(12, 360.0),
    )
    .unwrap();
    let bound = voxlab::gpu::project::hardware_error_bound(&grid, &g, 8);
    let (from_exact, from_whole) = (diff(&a, &b), diff(&b, &c));
    assert!(
        peak > 1.0 && from_exact <= bound,
        "{from_exact:e} over {bound:e}"
    );
    assert!(diff(&a, &c) <= bound, "{:e} over {bound:e}", diff(&a, &c));
    if ctx.summary.is_cpu() {
        // Measured on lavapipe: 6.4e-7 and 1.1e-6 of the peak.
        assert!(from_exact <= 4e-6 * peak, "{from_exact:e} of {peak:e}");
        assert!(from_whole <= 1e-5 * peak, "{from_whole:e} of {peak:e}");
    }

    for (extra, words) in [
        (
            &["--method", "joseph", "--backend", "cpu"][..],
            "give --backend gpu",
        ),
        (
            &["--method", "analytic", "--backend", "cpu"][..],
            "analytic",
        ),
    ] {
        let mut args = vec![
            "project",
            "phantom:shepp-logan:8",
            "--hardware-filtering",
            "--out",
            s(&never),
        ];
        args.extend_from_slice(extra);
        let o = voxlab(&args);
        assert!(!o.status.success(), "{extra:?}");
        assert!(
            stderr(&o).contains("--hardware-filtering"),
            "{}",
            stderr(&o)
        );
        assert!(stderr(&o).contains(words), "{extra:?}: {}", stderr(&o));
        assert!(!never.exists());
    }
}

/// `--geometry-file`: ASTRA's `cone` description projects exactly as the same circle
/// given by flags (ASTRA's own numbers: angles in radians, distances from the origin);
/// RTK's XML of an orbit that changes view by view projects with the request's
/// detector, and the geometry written beside the output holds its views, which
/// `reconstruct` then reads; flags that the file replaces are refused.
#[test]
fn a_geometry_file_gives_the_projection_geometry() {
    let d = scratch("geometry-file");
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(common::ct_data("astra_cone.json")).unwrap())
            .unwrap();
    let num = |k: &str| j[k].as_f64().unwrap();
    let angles: Vec<String> = j["ProjectionAngles"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| format!("{:.17e}", a.as_f64().unwrap().to_degrees()))
        .collect();
    let angles_txt = d.join("angles.txt");
    std::fs::write(&angles_txt, angles.join("\n")).unwrap();
    let (flags, file) = (d.join("flags.npy"), d.join("astra.npy"));
    let (dso, dod) = (num("DistanceOriginSource"), num("DistanceOriginDetector"));
    let sdd = format!("{}", dso + dod);
    let dso = format!("{dso}");
    let (du, dv) = (
        format!("{}", num("DetectorSpacingX")),
        format!("{}", num("DetectorSpacingY")),
    );
    let (cols, rows) = (
        j["DetectorColCount"].to_string(),
        j["DetectorRowCount"].to_string(),
    );
    #[rustfmt::skip]
    let o = voxlab(&[
        "project", "phantom:shepp-logan-modified", "--geometry", "cone", "--sid", &dso,
        "--sdd", &sdd, "--cols", &cols, "--rows", &rows, "--du", &du, "--dv", &dv,
        "--angles-file", s(&angles_txt), "--out", s(&flags),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = voxlab(&[
        "project",
        "phantom:shepp-logan-modified",
        "--geometry-file",
        s(&common::ct_data("astra_cone.json")),
        "--out",
        s(&file),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (shape_a, a, _) = read_npy_f64(&flags).unwrap();
    let (shape_b, b, _) = read_npy_f64(&file).unwrap();
    assert_eq!(shape_a, shape_b);
    let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let worst = a
        .iter()
        .zip(&b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    eprintln!("ASTRA cone file vs flags: worst {worst:e} of {scale}");
    // Measured: 2.1e-11 of 63 (3.4e-13 relative): the views' rays and the circle's are
    // built by different arithmetic and round differently.
    assert!(scale > 1.0 && worst < 1e-11 * scale, "{worst:e} of {scale}");

    let rtk = d.join("rtk.npy");
    #[rustfmt::skip]
    let o = voxlab(&[
        "project", "phantom:sphere:32", "--geometry-file",
        s(&common::ct_data("rtk_perview_geometry.xml")), "--cols", "48", "--rows", "40", "--du", "3",
        "--out", s(&rtk),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let g = read_geometry(&d.join("rtk.geometry.json")).unwrap();
    assert_eq!((g.n_angles(), g.cols, g.rows), (60, 48, 40));
    assert!(!g.is_circular() && g.beam != Beam::Parallel);
    let p = read_projections::<f64>(&rtk).unwrap();
    assert!(p.data.iter().any(|&v| v > 1.0));
    let o = voxlab(&[
        "reconstruct",
        s(&rtk),
        "--size",
        "16",
        "--spacing",
        "4",
        "--out",
        s(&d.join("vol.npy")),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));

    let o = voxlab(&[
        "project",
        "phantom:sphere:8",
        "--geometry-file",
        s(&common::ct_data("astra_cone.json")),
        "--sid",
        "500",
        "--out",
        s(&d.join("no.npy")),
    ]);
    assert!(!o.status.success() && !d.join("no.npy").exists());
    assert!(stderr(&o).contains("cannot be used with"), "{}", stderr(&o));
}
