//! CT geometry files against the peers that write them: RTK's geometry XML and ASTRA's
//! `proj_geom`, read into voxlab's per-view vectors, checked against the numbers RTK
//! and ASTRA computed themselves (`tests/data/ct/rtk_*.json`, `astra_*_vec.json`,
//! made by `scripts/make_geometry_fixtures.py`); and the detection of the three
//! formats behind `--geometry FILE`.

mod common;

use glam::{DMat3, DVec2, DVec3};
use serde_json::Value;
use std::path::Path;
use voxlab::ct::{Geometry, ViewGeometry, ViewVectors};
use voxlab::io::astra_geometry::parse_astra_geometry;
use voxlab::io::projections::{
    detect_geometry_format, parse_geometry, read_geometry_file, read_projections_grid,
    view_geometry_to_json, DetectorGrid, GeometryFile, GeometryFormat,
};
use voxlab::io::rtk_geometry::parse_rtk_geometry;
use voxlab::io::ReadOptions;
use voxlab::phantom::{Phantom, PhantomKind, Primitive};
use voxlab::Error;

use common::ct_data as data;

fn json(name: &str) -> Value {
    serde_json::from_str(&std::fs::read_to_string(data(name)).unwrap()).unwrap()
}

fn vec3(v: &Value) -> DVec3 {
    DVec3::new(
        v[0].as_f64().unwrap(),
        v[1].as_f64().unwrap(),
        v[2].as_f64().unwrap(),
    )
}

fn mat34(v: &Value) -> [[f64; 4]; 3] {
    let mut m = [[0.0; 4]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = v[i][j].as_f64().unwrap();
        }
    }
    m
}

/// The projection grid RTK used for a fixture (size, spacing, origin; identity
/// direction).
fn rtk_grid(record: &Value) -> DetectorGrid {
    let img = &record["projection_image"];
    assert_eq!(img["direction"], "identity");
    let n = |i: usize| img["size"][i].as_u64().unwrap() as usize;
    let f = |k: &str, i: usize| img[k][i].as_f64().unwrap();
    DetectorGrid::with_origin(
        n(0),
        n(1),
        DVec2::new(f("origin", 0), f("origin", 1)),
        f("spacing", 0),
        f("spacing", 1),
    )
}

/// The 3×4 projective map of a view: world point → homogeneous continuous pixel
/// indices `(col·w, row·w, w)`. Cone: `P = [u | v | pixel00 − s]⁻¹ · [I | −s]`, so a
/// point on the ray from the source through pixel `(c, r)` maps to `(c, r, 1)·t`.
/// Parallel: `(col, row)` of the point's foot along the rays, last row `(0, 0, 0, 1)`.
fn projective(v: &ViewVectors, parallel: bool) -> [[f64; 4]; 3] {
    let (m, o) = if parallel {
        (DMat3::from_cols(v.u, v.v, v.source), v.pixel00)
    } else {
        (DMat3::from_cols(v.u, v.v, v.pixel00 - v.source), v.source)
    };
    let inv = m.inverse();
    let t = -(inv * o);
    let mut p = [[0.0; 4]; 3];
    for i in 0..3 {
        let r = inv.row(i);
        p[i] = [r.x, r.y, r.z, t[i]];
    }
    if parallel {
        p[2] = [0.0, 0.0, 0.0, 1.0];
    }
    p
}

/// RTK's matrix (world → physical mm on the projection image) in pixel indices:
/// `index = S⁻¹·(physical − origin)` for the grid's steps `S`.
fn rtk_matrix_in_pixels(m: &[[f64; 4]; 3], grid: &DetectorGrid) -> [[f64; 4]; 3] {
    let s = glam::DMat2::from_cols(grid.col_step, grid.row_step).inverse();
    let mut out = [[0.0; 4]; 3];
    for j in 0..4 {
        let phys = DVec2::new(m[0][j], m[1][j]) - grid.origin * m[2][j];
        let idx = s * phys;
        out[0][j] = idx.x;
        out[1][j] = idx.y;
        out[2][j] = m[2][j];
    }
    out
}

/// `max |a − s·b| / max |a|` for the best scale `s` (least squares): two projective
/// maps agree up to scale when this is at rounding level.
fn projective_distance(a: &[[f64; 4]; 3], b: &[[f64; 4]; 3]) -> f64 {
    let (fa, fb): (Vec<f64>, Vec<f64>) = (a.concat(), b.concat());
    let s =
        fa.iter().zip(&fb).map(|(x, y)| x * y).sum::<f64>() / fb.iter().map(|y| y * y).sum::<f64>();
    let big = fa.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    fa.iter()
        .zip(&fb)
        .fold(0.0f64, |m, (x, y)| m.max((x - s * y).abs()))
        / big
}

const RTK_CASES: [&str; 3] = ["circular", "tilted", "parallel"];

/// Per view: voxlab's vectors from RTK's XML against RTK's own source position and
/// detector pixel positions (`GetSourcePosition`, `GetProjectionCoordinatesToFixed
/// SystemMatrix`), and the projective map they define against the `<Matrix>` RTK wrote
/// in the file.
#[test]
fn rtk_xml_views_are_rtks_own() {
    for case in RTK_CASES {
        let record = json(&format!("rtk_{case}.json"));
        let path = data(&format!("rtk_{case}.xml"));
        let text = std::fs::read_to_string(&path).unwrap();
        let rtk = parse_rtk_geometry(&text, &path).unwrap();
        let grid = rtk_grid(&record);
        let vg = rtk.view_geometry(&grid).unwrap();
        let n = record["matrices"].as_array().unwrap().len();
        assert_eq!(vg.views.len(), n, "{case}");
        assert_eq!(vg.parallel, case == "parallel");
        assert_eq!((vg.cols, vg.rows), (grid.cols, grid.rows));
        let (mut worst_pos, mut worst_map, mut worst_file) = (0.0f64, 0.0f64, 0.0f64);
        for (k, v) in vg.views.iter().enumerate() {
            let pix = &record["pixel_positions"][k];
            let (p00, p10, p01) = (vec3(&pix[0]), vec3(&pix[1]), vec3(&pix[2]));
            worst_pos = worst_pos
                .max((v.pixel00 - p00).length())
                .max((v.pixel00 + v.u - p10).length())
                .max((v.pixel00 + v.v - p01).length());
            if !vg.parallel {
                let s = vec3(&record["source_positions"][k]);
                worst_pos = worst_pos.max((v.source - s).length());
            } else {
                // The rays cross the detector at right angles here (no tilt of the
                // detector relative to the rays in RTK's parallel geometry).
                assert!(v.source.dot(v.u).abs() < 1e-12 && v.source.dot(v.v).abs() < 1e-12);
            }
            let mine = projective(v, vg.parallel);
            let rtk_getmatrix = rtk_matrix_in_pixels(&mat34(&record["matrices"][k]), &grid);
            let in_file =
                rtk_matrix_in_pixels(&rtk.matrices[k].expect("RTK writes matrices"), &grid);
            worst_map = worst_map.max(projective_distance(&rtk_getmatrix, &mine));
            worst_file = worst_file.max(projective_distance(&in_file, &mine));
        }
        eprintln!(
            "{case}: positions {worst_pos:e} mm, GetMatrix {worst_map:e}, <Matrix> {worst_file:e}"
        );
        // RTK's positions are its own f64 products; the vectors agree to rounding
        // (measured: 5.2e-13 mm at most, over ~600 mm).
        assert!(
            worst_pos < 1e-11,
            "{case}: positions differ by {worst_pos:e} mm"
        );
        // Measured 1.3e-15 at most; the file's 15 significant digits give the same.
        assert!(
            worst_map < 1e-14,
            "{case}: GetMatrix vs voxlab {worst_map:e}"
        );
        assert!(
            worst_file < 1e-14,
            "{case}: <Matrix> vs voxlab {worst_file:e}"
        );
    }
}

/// RTK's exact projections of two ellipsoids (RayEllipsoidIntersectionImageFilter, in
/// its MetaImage with spacing and origin) against voxlab's exact line integrals along
/// the rays the XML and the MetaImage's grid define: every sign, angle, offset and
/// pixel-centre convention shows up here.
#[test]
fn rtk_ellipsoid_projections_follow_the_views() {
    for case in RTK_CASES {
        let record = json(&format!("rtk_{case}.json"));
        let mha = data(&format!("rtk_{case}_ellipsoids.mha"));
        let (p, grid) = read_projections_grid::<f64>(&mha, &ReadOptions::default()).unwrap();
        let grid = grid.expect("a MetaImage stack has a grid");
        assert_eq!(grid, rtk_grid(&record), "{case}: the grid from the header");
        let xml = data(&format!("rtk_{case}.xml"));
        let GeometryFile::Views(vg) = read_geometry_file(&xml, Some(&grid)).unwrap() else {
            panic!("{case}: views expected");
        };
        assert_eq!(vg.views.len(), p.angles);
        let prims = record["ellipsoids"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| {
                Primitive::ellipsoid(
                    e["density"].as_f64().unwrap(),
                    vec3(&e["center"]),
                    vec3(&e["semi_axes"]),
                )
            })
            .collect();
        let phantom = Phantom {
            name: "rtk ellipsoids".into(),
            kind: PhantomKind::Primitives(prims),
            half_extent_mm: 1.0,
        };
        let (mut worst, mut max) = (0.0f64, 0.0f64);
        for (k, v) in vg.views.iter().enumerate() {
            for r in 0..p.rows {
                for c in 0..p.cols {
                    let pix = v.pixel00 + c as f64 * v.u + r as f64 * v.v;
                    let li = if vg.parallel {
                        phantom.line_integral_world(pix, v.source, f64::NEG_INFINITY, f64::INFINITY)
                    } else {
                        phantom.line_integral_world(v.source, pix - v.source, 0.0, f64::INFINITY)
                    };
                    let rtk = p.view(k)[r * p.cols + c];
                    worst = worst.max((li - rtk).abs());
                    max = max.max(rtk);
                }
            }
        }
        eprintln!("{case}: |voxlab − RTK| ≤ {worst:e} (max {max})");
        assert!(max > 50.0, "{case}: the ellipsoids are in view ({max})");
        // RTK's double results stored as float32: half an ulp in [32, 64) is 1.9e-6,
        // and that is what is measured (1.906e-6); the geometry adds nothing visible.
        assert!(
            worst < 2e-6,
            "{case}: |voxlab − RTK| up to {worst:e} (max {max})"
        );
    }
}

fn astra_views(name: &str) -> ViewGeometry {
    let path = data(name);
    parse_astra_geometry(&std::fs::read_to_string(&path).unwrap(), &path)
        .unwrap()
        .view_geometry()
}

/// ASTRA's `cone` and `parallel3d` turned into vectors as ASTRA's own `geom_2vec` does.
#[test]
fn astra_angles_become_astras_own_vectors() {
    for name in ["cone", "parallel3d"] {
        let path = data(&format!("astra_{name}.json"));
        let g = parse_astra_geometry(&std::fs::read_to_string(&path).unwrap(), &path).unwrap();
        let reference = json(&format!("astra_{name}_vec.json"));
        assert_eq!(reference["type"], format!("{name}_vec"));
        let rows = reference["Vectors"].as_array().unwrap();
        assert_eq!(g.vectors.len(), rows.len());
        assert_eq!(
            g.rows as u64,
            reference["DetectorRowCount"].as_u64().unwrap()
        );
        assert_eq!(
            g.cols as u64,
            reference["DetectorColCount"].as_u64().unwrap()
        );
        let mut worst = 0.0f64;
        for (mine, theirs) in g.vectors.iter().zip(rows) {
            for (i, x) in mine.iter().enumerate() {
                let t = theirs[i].as_f64().unwrap();
                worst = worst.max((x - t).abs() / t.abs().max(1.0));
            }
        }
        eprintln!("{name}: geom_2vec {worst:e}");
        // Equal bit for bit here; numpy's and Rust's sin/cos may differ in the last bit
        // elsewhere.
        assert!(worst < 1e-15, "{name}: geom_2vec differs by {worst:e}");
        // And ASTRA's vector file reads to the same views.
        let a = astra_views(&format!("astra_{name}.json"));
        let b = astra_views(&format!("astra_{name}_vec.json"));
        assert_eq!(a.parallel, b.parallel);
        for (va, vb) in a.views.iter().zip(&b.views) {
            for (x, y) in [
                (va.source, vb.source),
                (va.pixel00, vb.pixel00),
                (va.u, vb.u),
                (va.v, vb.v),
            ] {
                assert!((x - y).length() <= 1e-12 * y.length().max(1.0));
            }
        }
    }
}

/// The views of a circular [`Geometry`] through its own `detector_point` and `ray`.
fn views_of(g: &Geometry) -> Vec<ViewVectors> {
    (0..g.n_angles())
        .map(|k| {
            let p00 = g.detector_point(k, 0.0, 0.0);
            let (o, d, _) = g.ray(k, 0.0, 0.0);
            ViewVectors {
                source: if matches!(g.beam, voxlab::ct::Beam::Parallel) {
                    d
                } else {
                    o
                },
                pixel00: p00,
                u: g.detector_point(k, 1.0, 0.0) - p00,
                v: g.detector_point(k, 0.0, 1.0) - p00,
            }
        })
        .collect()
}

fn num(v: &Value, k: &str) -> f64 {
    v[k].as_f64().unwrap()
}

/// ASTRA's `cone` at angle θ is RTK's circle at gantry angle θ (SID = DSO,
/// SDD = DSO + DOD, the same pixel (col, row)) after ASTRA's frame is turned onto the CT
/// frame; `parallel3d` is voxlab's parallel geometry with ASTRA's centred detector.
#[test]
fn astra_cone_and_parallel3d_are_voxlabs_circles() {
    let j = json("astra_cone.json");
    let angles: Vec<f64> = j["ProjectionAngles"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_f64().unwrap().to_degrees())
        .collect();
    let (dso, dod) = (
        num(&j, "DistanceOriginSource"),
        num(&j, "DistanceOriginDetector"),
    );
    let rtk = Geometry::cone_rtk(
        dso,
        dso + dod,
        j["DetectorColCount"].as_u64().unwrap() as usize,
        j["DetectorRowCount"].as_u64().unwrap() as usize,
        num(&j, "DetectorSpacingX"),
        num(&j, "DetectorSpacingY"),
        angles,
    )
    .unwrap();
    let astra = astra_views("astra_cone.json");
    assert!(!astra.parallel);
    assert_eq!((astra.cols, astra.rows), (rtk.cols, rtk.rows));
    let mut worst = 0.0f64;
    for (a, b) in astra.views.iter().zip(views_of(&rtk)) {
        for (x, y) in [
            (a.source, b.source),
            (a.pixel00, b.pixel00),
            (a.u, b.u),
            (a.v, b.v),
        ] {
            worst = worst.max((x - y).length() / dso);
        }
        let d = projective_distance(&projective(&b, false), &projective(a, false));
        assert!(d < 1e-12, "projective maps differ by {d:e}");
    }
    eprintln!("cone vs cone_rtk: {worst:e} of the SID");
    assert!(
        worst < 1e-12,
        "cone: vectors differ by {worst:e} of the SID"
    );

    let j = json("astra_parallel3d.json");
    let (cols, rows) = (
        j["DetectorColCount"].as_u64().unwrap() as usize,
        j["DetectorRowCount"].as_u64().unwrap() as usize,
    );
    let par = Geometry {
        beam: voxlab::ct::Beam::Parallel,
        angles_deg: j["ProjectionAngles"]
            .as_array()
            .unwrap()
            .iter()
            .map(|a| a.as_f64().unwrap().to_degrees())
            .collect(),
        cols,
        rows,
        du: num(&j, "DetectorSpacingX"),
        dv: num(&j, "DetectorSpacingY"),
        // ASTRA centres its detector: (n − 1)/2, not scikit-image's n//2.
        cu: (cols as f64 - 1.0) / 2.0,
        cv: (rows as f64 - 1.0) / 2.0,
        views: None,
    };
    par.validate().unwrap();
    let astra = astra_views("astra_parallel3d.json");
    assert!(astra.parallel);
    for (a, b) in astra.views.iter().zip(views_of(&par)) {
        for (x, y) in [(a.pixel00, b.pixel00), (a.u, b.u), (a.v, b.v)] {
            assert!((x - y).length() < 1e-12 * 100.0, "{x} vs {y}");
        }
        // ASTRA's geom_2vec ray points the other way from voxlab's (−e_w): the same
        // lines.
        assert!(
            (a.source + b.source).length() < 1e-15,
            "{} vs {}",
            a.source,
            b.source
        );
        let d = projective_distance(&projective(&b, true), &projective(a, true));
        assert!(d < 1e-12, "parallel projective maps differ by {d:e}");
    }
}

/// `--geometry FILE`'s detection: each fixture is told apart by its contents.
#[test]
fn geometry_files_are_told_apart_by_their_contents() {
    for (name, format) in [
        ("rtk_tilted.xml", GeometryFormat::Rtk),
        ("rtk_parallel.xml", GeometryFormat::Rtk),
        ("astra_cone.json", GeometryFormat::Astra),
        ("astra_parallel3d_vec.json", GeometryFormat::Astra),
        ("rtk_geometry.json", GeometryFormat::Voxlab),
    ] {
        let text = std::fs::read_to_string(data(name)).unwrap();
        assert_eq!(detect_geometry_format(&text), Some(format), "{name}");
    }
    assert_eq!(detect_geometry_format("  \n"), None);
    assert_eq!(detect_geometry_format("[1, 2]"), None);
    // An RTK file cannot be read without the projections' grid, and says so.
    let xml = data("rtk_tilted.xml");
    match read_geometry_file(&xml, None) {
        Err(Error::Format {
            path,
            field,
            message,
        }) => {
            assert_eq!(path, xml);
            assert_eq!(field, "detector");
            assert!(message.contains("projection image"), "{message}");
        }
        other => panic!("{other:?}"),
    }
    // voxlab's circular JSON still reads as before.
    match read_geometry_file(&data("rtk_geometry.json"), None).unwrap() {
        GeometryFile::Circular(g) => assert_eq!((g.cols, g.rows, g.n_angles()), (48, 40, 60)),
        other => panic!("{other:?}"),
    }
}

/// voxlab's per-view JSON: RTK's tilted views written and read back bit for bit, and
/// its mistakes named.
#[test]
fn per_view_json_round_trips_and_refuses_mixed_forms() {
    let record = json("rtk_tilted.json");
    let xml = data("rtk_tilted.xml");
    let GeometryFile::Views(vg) = read_geometry_file(&xml, Some(&rtk_grid(&record))).unwrap()
    else {
        panic!()
    };
    let text = view_geometry_to_json(&vg);
    let path = Path::new("views.json");
    assert_eq!(detect_geometry_format(&text), Some(GeometryFormat::Voxlab));
    match parse_geometry(&text, path, None).unwrap() {
        GeometryFile::Views(back) => assert_eq!(back, vg),
        other => panic!("{other:?}"),
    }
    let dir = common::scratch("per_view_json");
    let out = dir.join("tilted.geometry.json");
    voxlab::io::projections::write_view_geometry(&out, &vg).unwrap();
    assert_eq!(
        read_geometry_file(&out, None).unwrap(),
        GeometryFile::Views(vg.clone())
    );

    let v =
        r#"{"source": [0, 0, 1000], "pixel00": [-10, -10, -500], "u": [1, 0, 0], "v": [0, 1, 0]}"#;
    let bad = [
        (
            format!(r#"{{"beam": "cone", "cols": 20, "rows": 20, "sid": 1000, "views": [{v}]}}"#),
            "sid goes with the circular form",
        ),
        (
            format!(
                r#"{{"beam": "cone", "cols": 20, "rows": 20, "views": [{}]}}"#,
                v.replace("\"u\": [1, 0, 0]", "\"u\": [0, 2, 0]")
            ),
            "do not span a detector plane",
        ),
        (
            format!(
                r#"{{"beam": "cone", "cols": 20, "rows": 20, "views": [{}]}}"#,
                v.replace("[0, 0, 1000]", "[0, 0, -500]")
            ),
            "source lies in the detector plane",
        ),
        (
            format!(r#"{{"beam": "cone", "cols": 0, "rows": 20, "views": [{v}]}}"#),
            "no detector columns",
        ),
        (
            r#"{"beam": "cone", "cols": 2, "rows": 2, "views": [{"source": [0, 0, 1]}]}"#
                .to_string(),
            "missing field",
        ),
    ];
    for (text, want) in bad {
        match parse_geometry(&text, path, None) {
            Err(e @ Error::Format { .. }) => {
                let m = e.to_string();
                assert!(m.contains(want) && m.contains("views.json"), "{m}");
            }
            other => panic!("{text}: {other:?}"),
        }
    }
}

/// An ASTRA `cone` file read as a [`Geometry`]
/// has the projective maps of RTK's circle.
#[test]
fn astra_cone_file_reads_as_rtks_circle() {
    let g = voxlab::io::projections::read_geometry(&data("astra_cone.json")).unwrap();
    let astra = astra_views("astra_cone.json");
    for (k, a) in astra.views.iter().enumerate() {
        let m = g.view_matrix::<f64>(k).rows;
        let mine = [m[0], m[1], m[2]];
        let d = projective_distance(&projective(a, false), &mine);
        assert!(d < 1e-12, "view {k}: {d:e}");
    }
}

/// More views than `ct::MAX_DETECTOR` are refused as they are read, in every format,
/// and the error names the file.
#[test]
fn too_many_views_are_refused_while_reading() {
    let n = voxlab::ct::MAX_DETECTOR + 1;
    let path = Path::new("many.geometry");
    let row = "[0,0,1000, 0,0,-500, 1,0,0, 0,1,0]";
    let astra = format!(
        r#"{{"type": "cone_vec", "DetectorRowCount": 2, "DetectorColCount": 2, "Vectors": [{}]}}"#,
        vec![row; n].join(",")
    );
    let view =
        r#"{"source": [0, 0, 1000], "pixel00": [0, 0, -500], "u": [1, 0, 0], "v": [0, 1, 0]}"#;
    let voxlab = format!(
        r#"{{"beam": "cone", "cols": 2, "rows": 2, "views": [{}]}}"#,
        vec![view; n].join(",")
    );
    let rtk = format!(
        "<RTKThreeDCircularGeometry version=\"3\"><SourceToIsocenterDistance>1000</SourceToIsocenterDistance><SourceToDetectorDistance>1500</SourceToDetectorDistance>{}</RTKThreeDCircularGeometry>",
        "<Projection/>".repeat(n)
    );
    let grid = DetectorGrid::centred(2, 2, 1.0, 1.0);
    for text in [astra, voxlab, rtk] {
        let e = parse_geometry(&text, path, Some(&grid))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("many.geometry") && e.contains("more than 65536"),
            "{e}"
        );
    }
}

/// The detector grid a projection file's header gives: spacing, origin and direction of
/// a MetaImage or NRRD stack; none for `.npy` and NIfTI; a header whose projection axis moves
/// the pixels within the detector plane is refused, naming the file.
#[test]
fn projection_headers_give_the_detector_grid() {
    use glam::{DMat4, DVec4};
    use voxlab::{AnyVolume, Volume};
    let dir = common::scratch("projection_grid");
    let dims = [6, 4, 3]; // cols, rows, projections
    let data: Vec<f32> = (0..72).map(|i| i as f32).collect();
    // A flipped row axis and an origin off centre.
    let affine = DMat4::from_cols(
        DVec4::new(0.5, 0.0, 0.0, 0.0),
        DVec4::new(0.0, -0.25, 0.0, 0.0),
        DVec4::new(0.0, 0.0, 1.0, 0.0),
        DVec4::new(-1.25, 0.375, 0.0, 1.0),
    );
    let vol = AnyVolume::from(Volume::with_affine(dims, affine, data.clone()).unwrap());
    for name in ["stack.mha", "stack.nrrd"] {
        let path = dir.join(name);
        voxlab::io::write_volume(&path, &vol).unwrap();
        let (p, grid) = read_projections_grid::<f64>(&path, &ReadOptions::default()).unwrap();
        assert_eq!((p.angles, p.rows, p.cols), (3, 4, 6));
        let g = grid.unwrap();
        assert_eq!((g.cols, g.rows), (6, 4), "{name}");
        assert_eq!(g.origin, DVec2::new(-1.25, 0.375), "{name}");
        assert_eq!(g.col_step, DVec2::new(0.5, 0.0), "{name}");
        assert_eq!(g.row_step, DVec2::new(0.0, -0.25), "{name}");
    }
    // .npy has no geometry; NIfTI's is in RAS patient coordinates, not RTK's plane.
    for name in ["stack.npy", "stack.nii"] {
        let path = dir.join(name);
        voxlab::io::write_volume(&path, &vol).unwrap();
        let (_, grid) = read_projections_grid::<f64>(&path, &ReadOptions::default()).unwrap();
        assert_eq!(grid, None, "{name}");
    }

    let mut mixed = affine;
    mixed.z_axis.x = 0.1;
    let path = dir.join("mixed.mha");
    voxlab::io::write_volume(
        &path,
        &AnyVolume::from(Volume::with_affine(dims, mixed, data).unwrap()),
    )
    .unwrap();
    match read_projections_grid::<f64>(&path, &ReadOptions::default()) {
        Err(Error::Format {
            path: p, message, ..
        }) => {
            assert_eq!(p, path);
            assert!(message.contains("projection axis"), "{message}");
        }
        other => panic!("{other:?}"),
    }
}

/// XML entities cannot blow a small file up ("billion laughs"), and a file with a
/// parameter nested in another is refused.
#[test]
fn hostile_xml_is_refused() {
    let laughs = r#"<?xml version="1.0"?>
<!DOCTYPE lolz [
 <!ENTITY lol "lollollollollollollollollollol">
 <!ENTITY lol1 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
 <!ENTITY lol2 "&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;">
 <!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">
 <!ENTITY lol4 "&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;">
 <!ENTITY lol5 "&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;">
 <!ENTITY lol6 "&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;">
 <!ENTITY lol7 "&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;">
 <!ENTITY lol8 "&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;">
 <!ENTITY lol9 "&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;">
]>
<RTKThreeDCircularGeometry version="3"><Projection><GantryAngle>&lol9;</GantryAngle></Projection></RTKThreeDCircularGeometry>"#;
    let nested = "<RTKThreeDCircularGeometry version=\"3\"><Projection><GantryAngle><InPlaneAngle>1</InPlaneAngle></GantryAngle></Projection></RTKThreeDCircularGeometry>";
    let path = Path::new("hostile.xml");
    let grid = DetectorGrid::centred(2, 2, 1.0, 1.0);
    let t = std::time::Instant::now();
    for text in [laughs, nested] {
        match parse_geometry(text, path, Some(&grid)) {
            Err(Error::Format { path: p, .. }) => assert_eq!(p, path),
            other => panic!("{other:?}"),
        }
    }
    assert!(t.elapsed().as_secs_f64() < 5.0);
}

/// RTK's tilted geometry with offsets, read with
/// its MetaImage's grid as a [`Geometry`], projects every point as RTK's matrices do.
#[test]
fn rtk_xml_reads_as_a_geometry_with_rtks_matrices() {
    for case in RTK_CASES {
        let record = json(&format!("rtk_{case}.json"));
        let mha = data(&format!("rtk_{case}_ellipsoids.mha"));
        let (p, grid) = read_projections_grid::<f64>(&mha, &ReadOptions::default()).unwrap();
        let grid = grid.unwrap();
        let g = voxlab::io::projections::read_geometry_with(
            &data(&format!("rtk_{case}.xml")),
            Some(&grid),
        )
        .unwrap();
        p.check_against(&g).unwrap();
        for k in 0..g.n_angles() {
            let m = g.view_matrix::<f64>(k).rows;
            let rtk = rtk_matrix_in_pixels(&mat34(&record["matrices"][k]), &grid);
            let d = projective_distance(&rtk, &[m[0], m[1], m[2]]);
            assert!(d < 1e-12, "{case} view {k}: {d:e}");
        }
    }
}

/// A geometry given view by view (RTK's XML, read with its MetaImage's grid) written as
/// voxlab's JSON and read back is the same geometry, bit for bit; a circle stays one.
#[test]
fn a_geometry_given_view_by_view_round_trips_through_voxlabs_json() {
    for case in RTK_CASES {
        let mha = data(&format!("rtk_{case}_ellipsoids.mha"));
        let (_, grid) = read_projections_grid::<f64>(&mha, &ReadOptions::default()).unwrap();
        let g = voxlab::io::projections::read_geometry_with(
            &data(&format!("rtk_{case}.xml")),
            grid.as_ref(),
        )
        .unwrap();
        let text = voxlab::io::projections::geometry_to_json(&g);
        assert!(text.contains("\"views\""), "{case}");
        let back =
            voxlab::io::projections::geometry_from_json(&text, Path::new("back.json")).unwrap();
        assert_eq!(back.views, g.views, "{case}");
        assert_eq!(
            (back.cols, back.rows, back.beam),
            (g.cols, g.rows, g.beam),
            "{case}"
        );
    }
    let circle = Geometry::cone_rtk(1000.0, 1500.0, 8, 6, 1.0, 1.0, vec![0.0, 90.0]).unwrap();
    let text = voxlab::io::projections::geometry_to_json(&circle);
    assert!(!text.contains("\"views\""));
    let back = voxlab::io::projections::geometry_from_json(&text, Path::new("c.json")).unwrap();
    assert_eq!(back, circle);
}
