//! `voxlab render --clip-mesh`: the bricks mesh keeps the image and takes fewer samples
//! than no skipping, a file mesh (OBJ or PLY) around a corner of air leaves the image
//! empty, and bad mesh files are refused with the file named.

mod common;

use common::{s, scratch, stderr, voxlab};
use voxlab::io::mesh::TriMesh;

fn render(dir: &std::path::Path, name: &str, extra: &[&str]) -> (Vec<f32>, Vec<f32>) {
    let img = dir.join(format!("{name}.npy"));
    let samples = dir.join(format!("{name}-samples.npy"));
    let mut args = vec![
        "render",
        "phantom:shepp-logan-modified:40",
        "--tf",
        "phantom",
        "--width",
        "48",
        "--height",
        "36",
        "--out",
        s(&img),
        "--samples",
        s(&samples),
    ];
    args.extend_from_slice(extra);
    let o = voxlab(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let (_, px) = voxlab::io::npy::read_npy_f32(&img).unwrap();
    let (_, n) = voxlab::io::npy::read_npy_f32(&samples).unwrap();
    (px, n)
}

#[test]
fn bricks_mesh_keeps_the_image() {
    let d = scratch("cli-clipmesh-bricks");
    let (plain, n_plain) = render(&d, "plain", &["--skip-empty", "off"]);
    let (bricks, n_bricks) = render(
        &d,
        "bricks",
        &[
            "--skip-empty",
            "off",
            "--block-size",
            "8",
            "--clip-mesh",
            "bricks",
        ],
    );
    assert_eq!(plain, bricks, "the bricks mesh changed the image");
    let (a, b): (f32, f32) = (n_bricks.iter().sum(), n_plain.iter().sum());
    eprintln!("samples: {a} with the bricks mesh, {b} without");
    assert!(a < b);
}

#[test]
fn file_meshes_clip_and_bad_files_fail() {
    let d = scratch("cli-clipmesh-file");
    // Voxels 0..=2 of the corner: air only, so nothing is visible.
    let corner = TriMesh::cuboid([-0.5; 3], [2.5; 3]);
    std::fs::write(d.join("corner.obj"), corner.to_obj()).unwrap();
    std::fs::write(d.join("corner.ply"), corner.to_ply(true)).unwrap();
    for f in ["corner.obj", "corner.ply"] {
        let path = d.join(f);
        let (img, n) = render(
            &d,
            f,
            &["--clip-mesh", s(&path), "--clip-mesh-units", "voxel"],
        );
        assert!(n.iter().sum::<f32>() < 100.0 * 48.0);
        assert!(img.chunks(4).all(|p| p[0] < 1e-6), "{f}: nothing visible");
    }
    std::fs::write(d.join("bad.obj"), "v 0 0 0\nf 1 2 3\n").unwrap();
    let img = d.join("x.npy");
    let bad = d.join("bad.obj");
    let o = voxlab(&[
        "render",
        "phantom:shepp-logan-modified:16",
        "--out",
        s(&img),
        "--clip-mesh",
        s(&bad),
    ]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("bad.obj") && e.contains("line 2"), "{e}");
}
