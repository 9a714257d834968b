//! Projection stacks, geometry JSON and angle lists on disk: round trips, the
//! scikit-image transposition, and clear errors on bad input.

mod common;

use common::{assert_format, scratch};
use std::path::Path;
use voxlab::ct::{Geometry, Projections};
use voxlab::io::npy::{read_npy_f64, write_npy_f32, write_npy_f64};
use voxlab::io::projections::{
    geometry_from_json, geometry_path, read_angles_txt, read_geometry, read_projections,
    read_projections_for, write_geometry, write_projections, Layout,
};
use voxlab::Error;

/// A stack whose every value encodes its position: 1000·a + 10·r + c (+ a fraction
/// that f32 cannot hold, to see f64 kept exact).
fn coded(angles: usize, rows: usize, cols: usize) -> Projections<f64> {
    let mut data = Vec::new();
    for a in 0..angles {
        for r in 0..rows {
            for c in 0..cols {
                data.push(1000.0 * a as f64 + 10.0 * r as f64 + c as f64 + 1e-9);
            }
        }
    }
    Projections::new(angles, rows, cols, data).unwrap()
}

#[test]
fn npy_stacks_round_trip_in_both_precisions() {
    let dir = scratch("npy_round_trip");
    let p = coded(5, 3, 4);
    let f = dir.join("p64.npy");
    write_projections(&f, &p, Layout::Stack, None).unwrap();
    let (shape, _, was_f8) = read_npy_f64(&f).unwrap();
    assert_eq!((shape, was_f8), (vec![5, 3, 4], true));
    assert_eq!(read_projections::<f64>(&f).unwrap(), p, "f64 is exact");

    let p32 = Projections::new(5, 3, 4, p.data.iter().map(|&v| v as f32).collect()).unwrap();
    let f = dir.join("p32.npy");
    write_projections(&f, &p32, Layout::Stack, None).unwrap();
    assert!(!read_npy_f64(&f).unwrap().2, "f32 written as <f4");
    assert_eq!(read_projections::<f32>(&f).unwrap(), p32);
}

#[test]
fn a_2d_array_is_always_skimage_detector_by_angle() {
    let dir = scratch("skimage");
    // sinogram[d, a] = 100·d + a, shape (detector = 6, angle = 4), as radon returns.
    let (det, ang) = (6usize, 4usize);
    let sino: Vec<f64> = (0..det * ang)
        .map(|i| 100.0 * (i / ang) as f64 + (i % ang) as f64)
        .collect();
    let f = dir.join("sino.npy");
    write_npy_f64(&f, &[det, ang], &sino).unwrap();
    let p = read_projections::<f64>(&f).unwrap();
    assert_eq!((p.angles, p.rows, p.cols), (ang, 1, det));
    for a in 0..ang {
        for d in 0..det {
            assert_eq!(p.view(a)[d], 100.0 * d as f64 + a as f64);
        }
    }
    // Written back with the scikit-image layout: the same bytes' values.
    let g = dir.join("back.npy");
    write_projections(&g, &p, Layout::Skimage, None).unwrap();
    let (shape, values, _) = read_npy_f64(&g).unwrap();
    assert_eq!(shape, vec![det, ang]);
    assert_eq!(values, sino);
    // A multi-row stack has no scikit-image form.
    let e = write_projections(&g, &coded(2, 2, 3), Layout::Skimage, None).unwrap_err();
    assert!(e.to_string().contains("one detector row"), "{e}");
}

#[test]
fn nrrd_stacks_and_sinograms_round_trip() {
    let dir = scratch("nrrd");
    let p = coded(4, 3, 5);
    let p32 = Projections::new(4, 3, 5, p.data.iter().map(|&v| v as f32).collect()).unwrap();
    let geo = Geometry::parallel_stack(5, 3, 0.5, 2.0, Geometry::even_angles(4, 180.0)).unwrap();
    for name in ["p.nrrd", "p.nhdr"] {
        let f = dir.join(name);
        write_projections(&f, &p32, Layout::Stack, Some(&geo)).unwrap();
        assert_eq!(
            read_projections_for::<f32>(&f, &geo).unwrap(),
            p32,
            "{name}"
        );
        let vol = voxlab::io::read_volume(&f).unwrap();
        assert_eq!(vol.dims(), [5, 3, 4]);
        assert_eq!(vol.spacing(), [0.5, 2.0, 1.0]);
    }
    let s = coded(7, 1, 6);
    let f = dir.join("s.nrrd");
    write_projections(&f, &s, Layout::Skimage, None).unwrap();
    assert_eq!(voxlab::io::read_volume(&f).unwrap().dims(), [7, 6, 1]);
    let back = read_projections::<f64>(&f).unwrap();
    // NRRD stores float: f32 rounding of values up to ~6000.
    let worst = back
        .data
        .iter()
        .zip(&s.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert_eq!((back.angles, back.rows, back.cols), (7, 1, 6));
    assert!(worst < 1e-3, "{worst}");
}

#[test]
fn geometry_json_round_trips_and_fills_conventional_defaults() {
    let dir = scratch("geometry");
    let cone =
        Geometry::cone_rtk(1000.0, 1500.0, 64, 48, 1.5, 2.0, vec![0.0, 90.5, 181.25]).unwrap();
    let par = Geometry::parallel_skimage(65, Geometry::even_angles(7, 180.0)).unwrap();
    for g in [&cone, &par] {
        let f = geometry_path(&dir.join("out.npy"));
        assert_eq!(f, dir.join("out.geometry.json"));
        write_geometry(&f, g).unwrap();
        assert_eq!(&read_geometry(&f).unwrap(), g);
    }
    let p = Path::new("g.json");
    let g = geometry_from_json(
        r#"{"beam": "cone", "sid": 1000, "sdd": 1500, "cols": 64, "rows": 48,
            "du": 1.5, "dv": 2, "angles": {"count": 3, "range_deg": 360}}"#,
        p,
    )
    .unwrap();
    assert_eq!(
        g,
        Geometry::cone_rtk(1000.0, 1500.0, 64, 48, 1.5, 2.0, vec![0.0, 120.0, 240.0]).unwrap()
    );
    let g = geometry_from_json(
        r#"{"beam": "parallel", "cols": 9, "rows": 1, "angles_deg": [0, 45]}"#,
        p,
    )
    .unwrap();
    assert_eq!(g, Geometry::parallel_skimage(9, vec![0.0, 45.0]).unwrap());
    // Extra sections (objects, arrays) are metadata.
    let g = geometry_from_json(
        r#"{"beam": "parallel", "cols": 9, "rows": 1, "angles_deg": [0, 45],
            "volume": {"dims": [32, 32, 32]}, "notes": ["made by a script"]}"#,
        p,
    )
    .unwrap();
    assert_eq!(g, Geometry::parallel_skimage(9, vec![0.0, 45.0]).unwrap());
}

#[test]
fn bad_geometry_json_is_a_clear_error() {
    let p = Path::new("g.json");
    let cases = [
        (
            r#"{"beam": "fan", "cols": 8, "rows": 1, "angles_deg": [0]}"#,
            "fan",
        ),
        (
            r#"{"beam": "cone", "cols": 8, "rows": 1, "angles_deg": [0]}"#,
            "sid and sdd",
        ),
        (
            r#"{"beam": "parallel", "sid": 5, "sdd": 6, "cols": 8, "rows": 1, "angles_deg": [0]}"#,
            "no sid",
        ),
        (
            r#"{"beam": "parallel", "cols": 8, "rows": 1}"#,
            "exactly one",
        ),
        (
            r#"{"beam": "parallel", "cols": 8, "rows": 1, "angles_deg": [0], "angels": 3}"#,
            "unknown field",
        ),
        (
            r#"{"beam": "parallel", "cols": 8, "rows": 1, "angles_deg": [0], "sdd": {"a": 1}}"#,
            "expected f64",
        ),
        (
            r#"{"beam": "parallel", "cols": 0, "rows": 1, "angles_deg": [0]}"#,
            "at least 1",
        ),
        (
            r#"{"beam": "parallel", "cols": 8, "rows": 1, "du": -1, "angles_deg": [0]}"#,
            "du",
        ),
        (
            r#"{"beam": "parallel", "cols": 8, "rows": 1, "angles": {"count": 0, "range_deg": 180}}"#,
            "count",
        ),
        (
            r#"{"beam": "parallel", "cols": 999999999, "rows": 1, "angles_deg": [0]}"#,
            "at most",
        ),
        ("{not json", "key"),
    ];
    for (text, words) in cases {
        assert_format(geometry_from_json(text, p), "geometry", words);
    }
}

#[test]
fn angle_lists_allow_comments_and_refuse_garbage() {
    let dir = scratch("angles");
    let f = dir.join("a.txt");
    std::fs::write(&f, "# angles in degrees\n0\n  1.5  # half\n\n-30\n3e1\n").unwrap();
    assert_eq!(read_angles_txt(&f).unwrap(), vec![0.0, 1.5, -30.0, 30.0]);
    std::fs::write(&f, "0\n1\nten\n").unwrap();
    assert_format(read_angles_txt(&f), "line 3", "ten");
    std::fs::write(&f, "0\nnan\n").unwrap();
    assert_format(read_angles_txt(&f), "line 2", "finite");
    std::fs::write(&f, "# nothing\n\n").unwrap();
    assert_format(read_angles_txt(&f), "angles", "no angles");
}

#[test]
fn bad_arrays_are_refused_clearly() {
    let dir = scratch("bad_arrays");
    // NaN samples.
    let f = dir.join("nan.npy");
    write_npy_f32(
        &f,
        &[2, 2, 2],
        &[0.0, 1.0, f32::NAN, 0.0, 0.0, 0.0, 0.0, 0.0],
    )
    .unwrap();
    assert_format(read_projections::<f32>(&f), "data", "sample 2 is NaN");
    // 1-D and 4-D arrays.
    for shape in [vec![8usize], vec![1, 2, 2, 2]] {
        let f = dir.join("shape.npy");
        write_npy_f32(&f, &shape, &[0.0; 8]).unwrap();
        assert_format(read_projections::<f32>(&f), "shape", "(angle, row, col)");
    }
    // Empty axis.
    let f = dir.join("empty.npy");
    write_npy_f32(&f, &[0, 3, 3], &[]).unwrap();
    assert_format(read_projections::<f32>(&f), "shape", "no angles");
    // Integer dtype: not a projection.
    let f = dir.join("int.npy");
    let vol = voxlab::Volume::filled([4, 3, 2], [1.0; 3], 7u16).unwrap();
    voxlab::io::npy::write_npy_volume(&f, &vol.into()).unwrap();
    assert_format(read_projections::<f32>(&f), "descr", "<f8");
    // Truncated data.
    let f = dir.join("cut.npy");
    write_npy_f64(&f, &[3, 4, 5], &[1.0; 60]).unwrap();
    let bytes = std::fs::read(&f).unwrap();
    std::fs::write(&f, &bytes[..bytes.len() - 9]).unwrap();
    assert_format(read_projections::<f64>(&f), "data", "bytes");
    // A header promising an absurd size is refused before allocating.
    let f = dir.join("huge.npy");
    let text = "{'descr': '<f4', 'fortran_order': False, 'shape': (65536, 65536, 65536), }";
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend_from_slice(&(text.len() as u16).to_le_bytes());
    b.extend_from_slice(text.as_bytes());
    std::fs::write(&f, b).unwrap();
    assert_format(read_projections::<f32>(&f), "shape", "limit");
    // Unknown format.
    let f = dir.join("p.txt");
    std::fs::write(&f, "not projections").unwrap();
    let e = read_projections::<f32>(&f).unwrap_err();
    assert!(e.to_string().contains("unknown format"), "{e}");
}

#[test]
fn shapes_are_checked_against_the_geometry() {
    let dir = scratch("mismatch");
    let f = dir.join("p.npy");
    write_projections(&f, &coded(3, 2, 4), Layout::Stack, None).unwrap();
    let g = Geometry::cone_rtk(1000.0, 1500.0, 4, 2, 1.0, 1.0, vec![0.0, 1.0]).unwrap();
    let e = read_projections_for::<f64>(&f, &g).unwrap_err();
    assert!(matches!(e, Error::Invalid { .. }), "{e}");
    assert!(e.to_string().contains("3×2×4"), "{e}");
    let e = write_projections(&f, &coded(3, 2, 4), Layout::Stack, Some(&g)).unwrap_err();
    assert!(e.to_string().contains("geometry describes 2×2×4"), "{e}");
}

#[test]
fn fortran_order_files_read_like_numpy_load() {
    // A (detector = 3, angle = 2) sinogram saved with fortran_order = True.
    let dir = scratch("fortran");
    let f = dir.join("f.npy");
    let text = "{'descr': '<f8', 'fortran_order': True, 'shape': (3, 2), }";
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend_from_slice(&(text.len() as u16).to_le_bytes());
    b.extend_from_slice(text.as_bytes());
    // s[d, a] = 10 d + a stored first-axis-fastest.
    for a in 0..2 {
        for d in 0..3 {
            b.extend_from_slice(&((10 * d + a) as f64).to_le_bytes());
        }
    }
    std::fs::write(&f, b).unwrap();
    let p = read_projections::<f64>(&f).unwrap();
    assert_eq!(p.data, vec![0.0, 10.0, 20.0, 1.0, 11.0, 21.0]);
}
