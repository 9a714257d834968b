//! Clipping meshes on the CPU (`cpu::clipmesh`, `io::mesh`): OBJ/PLY parsing and its
//! errors, the watertight edge rule, segment pairing, and renders: a cube mesh equals
//! the clipping box, a four-segment comb clips exactly where analytic, and an
//! enclosing mesh or the bricks mesh renders the image without a mesh bit for bit.

mod common;

use glam::DVec3;
use std::path::Path;
use std::sync::Arc;
use voxlab::camera::{AxisView, Camera, Projection};
use voxlab::cpu::clipmesh::{intersect_triangle, make_segments, ClipTriangles, OPEN_END};
use voxlab::cpu::raycast::render;
use voxlab::io::mesh::{parse_obj, parse_ply, read_mesh, TriMesh};
use voxlab::settings::{ClipBox, ClipMesh, ClipMeshUnits, ClipSpace, Mode, RenderSettings};
use voxlab::{AnyVolume, Volume};

fn none() -> &'static (dyn Fn(usize, usize) + Sync) {
    &|_, _| {}
}

fn p() -> &'static Path {
    Path::new("test.mesh")
}

use common::sparse_tf;

use common::odd_phantom as phantom;

fn perspective(size: usize) -> Camera {
    common::orbit_camera(
        Projection::Perspective { fov_y_deg: 30.0 },
        size,
        size * 3 / 4,
    )
}

fn mesh(m: TriMesh, units: ClipMeshUnits) -> Option<ClipMesh> {
    Some(ClipMesh::Mesh {
        mesh: Arc::new(m),
        units,
    })
}

#[test]
fn obj_round_trip_fans_and_negative_indices() {
    let cube = TriMesh::cuboid([-1.0, -2.0, -3.0], [1.0, 2.5, 3.25]);
    assert_eq!(parse_obj(cube.to_obj().as_bytes(), p()).unwrap(), cube);
    // A quad with relative indices and v/t/n corners fans into two triangles.
    let src = "# quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nf -4/1/1 -3 -2//1 -1\n";
    let m = parse_obj(src.as_bytes(), p()).unwrap();
    assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
}

#[test]
fn ply_round_trip_ascii_and_binary() {
    let cube = TriMesh::cuboid([-1.0, -2.0, -3.0], [1.0, 2.5, 3.25]);
    for binary in [false, true] {
        assert_eq!(parse_ply(&cube.to_ply(binary), p()).unwrap(), cube);
    }
    // Float vertices with an extra property, a quad face, an extra element.
    let src = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
               property float z\nproperty uchar red\nelement face 1\n\
               property list uchar uint vertex_indices\nelement edge 1\nproperty int a\n\
               end_header\n0 0 0 1\n1 0 0 2\n1 1 0 3\n0 1 0 4\n4 0 1 2 3\n7\n";
    let m = parse_ply(src.as_bytes(), p()).unwrap();
    assert_eq!(m.vertices.len(), 4);
    assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    // Files on disk, by extension.
    let dir = common::scratch("clipmesh_files");
    std::fs::write(dir.join("c.obj"), cube.to_obj()).unwrap();
    std::fs::write(dir.join("c.ply"), cube.to_ply(true)).unwrap();
    assert_eq!(read_mesh(&dir.join("c.obj")).unwrap(), cube);
    assert_eq!(read_mesh(&dir.join("c.ply")).unwrap(), cube);
    assert!(read_mesh(&dir.join("c.stl")).is_err());
}

#[test]
fn bad_mesh_files_give_errors() {
    let obj_bad = [
        ("v 0 0\n", "line 1"),
        ("v 0 0 nan\n", "line 1"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "line 4"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -4\n", "line 4"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "line 4"),
        ("v 0 0 0\nv 1 0 0\nf 1 2\n", "line 3"),
        ("v 0 0 0\nf 1 x 1\n", "line 2"),
    ];
    for (src, field) in obj_bad {
        common::assert_format(parse_obj(src.as_bytes(), p()), field, "");
    }
    let cube = TriMesh::cuboid([0.0; 3], [1.0; 3]);
    let bin = cube.to_ply(true);
    let ascii = String::from_utf8(cube.to_ply(false)).unwrap();
    // Truncated binary and ASCII bodies.
    assert!(parse_ply(&bin[..bin.len() - 3], p()).is_err());
    assert!(parse_ply(&ascii.as_bytes()[..ascii.len() - 8], p()).is_err());
    // A header that lies about the counts, absurd counts, NaN, out-of-range index.
    let lie = ascii.replace("element vertex 8", "element vertex 9");
    assert!(parse_ply(lie.as_bytes(), p()).is_err());
    let huge = ascii.replace("element face 12", "element face 99999999999");
    assert!(parse_ply(huge.as_bytes(), p()).is_err());
    let nan = ascii.replacen("0.0 0.0 0.0", "0.0 NaN 0.0", 1);
    assert!(parse_ply(nan.as_bytes(), p()).is_err());
    let oob = ascii.replacen("3 0 4 6", "3 0 4 8", 1);
    assert!(parse_ply(oob.as_bytes(), p()).is_err());
    assert!(parse_ply(b"ply\nformat binary_big_endian 1.0\nend_header\n", p()).is_err());
    assert!(parse_ply(b"not a ply", p()).is_err());
    assert!(parse_ply(b"", p()).is_err());
}

#[test]
fn a_ray_through_a_shared_edge_counts_once() {
    // The unit square z = 0 as two triangles sharing the diagonal (0,0)–(1,1), with
    // both windings of the second triangle; rays hit the diagonal exactly.
    let a = [0.0, 0.0, 0.0];
    let b = [1.0, 0.0, 0.0];
    let c = [1.0, 1.0, 0.0];
    let d = [0.0, 1.0, 0.0];
    for second in [[a, c, d], [c, a, d]] {
        for (o, dir) in [
            ([0.5, 0.5, 2.0], [0.0, 0.0, -1.0]),
            ([0.25, 0.25, -3.0], [0.0, 0.0, 1.0]),
            ([0.0, 0.0, 1.0], [0.5, 0.5, -1.0]),
        ] {
            let hits = [[a, b, c], second]
                .iter()
                .filter(|t| intersect_triangle(o, dir, t).is_some())
                .count();
            assert_eq!(hits, 1, "{o:?} {dir:?} {second:?}");
        }
    }
    // The edge between two faces of a cube, crossed diagonally: one entry, one exit.
    let cube = ClipTriangles::new(&TriMesh::cuboid([0.0; 3], [2.0; 3]));
    let s = cube.segments(
        DVec3::new(-1.0, 1.0, -1.0),
        DVec3::new(1.0, 0.0, 1.0),
        -10.0,
    );
    assert_eq!(s.as_slice(), &[[1.0, 3.0]]);
}

#[test]
fn segments_pair_by_parity_and_merge_beyond_eight() {
    // Start inside (one hit behind): [t0, 2], [5, 7].
    let s = make_segments(0.0, 1, &[2.0, 5.0, 7.0]);
    assert_eq!(s.as_slice(), &[[0.0, 2.0], [5.0, 7.0]]);
    // Open mesh: the unpaired boundary opens a segment to infinity.
    let s = make_segments(0.0, 0, &[1.0, 2.0, 3.0]);
    assert_eq!(s.as_slice(), &[[1.0, 2.0], [3.0, OPEN_END]]);
    // 10 pairs: the first 7 exact, the 8th covers pairs 8–10 and their gaps.
    let hits: Vec<f64> = (0..20).map(|i| i as f64).collect();
    let s = make_segments(-1.0, 0, &hits);
    assert_eq!(s.count, 8);
    assert_eq!(s.seg[6], [12.0, 13.0]);
    assert_eq!(s.seg[7], [14.0, 19.0]);
    // A ray starting inside a box: the segment starts at t0.
    let cube = ClipTriangles::new(&TriMesh::cuboid([-1.0; 3], [1.0; 3]));
    let s = cube.segments(DVec3::ZERO, DVec3::X, 0.0);
    assert_eq!(s.as_slice(), &[[0.0, 1.0]]);
}

/// Renders with the settings' clip mesh (f64 oracle).
fn draw(vol: &AnyVolume, cam: &Camera, s: &RenderSettings) -> voxlab::cpu::raycast::RenderOutput {
    render::<f64>(vol, &sparse_tf(), cam, s, none()).unwrap()
}

#[test]
fn cube_mesh_gives_the_clip_box_image() {
    // Axis view, step 1: samples at voxel centres for both the box and the mesh.
    let vol = phantom(32);
    let d = vol.dims();
    let cam = Camera::axis_view(d, vol.affine(), AxisView::MinusY, d[0], d[2]).unwrap();
    let (lo, hi) = ([4.0, 6.0, 3.0], [25.0, 20.0, 22.0]);
    for mode in [Mode::Dvr, Mode::Xray, Mode::Mip] {
        let base = RenderSettings {
            mode,
            step: 1.0,
            ..Default::default()
        };
        let boxed = RenderSettings {
            clip_box: Some(ClipBox {
                lo,
                hi,
                space: ClipSpace::Voxel,
            }),
            ..base.clone()
        };
        let meshed = RenderSettings {
            clip_mesh: mesh(
                TriMesh::cuboid(lo.map(|x| x - 0.5), hi.map(|x| x + 0.5)),
                ClipMeshUnits::Voxel,
            ),
            ..base
        };
        let a = draw(&vol, &cam, &boxed);
        let b = draw(&vol, &cam, &meshed);
        let err = a
            .image
            .data
            .iter()
            .zip(&b.image.data)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        eprintln!("{mode:?}: cube mesh vs clip box, max |difference| {err:e}");
        // Measured 3.7e-15 (DVR), 3.6e-14 (X-ray), 5.7e-15 (MIP): the clip box and the
        // mesh reach the same samples through different rounding of t.
        assert!(err <= 2e-13, "{mode:?}: {err:e}");
    }
}

#[test]
fn comb_mesh_with_four_segments_clips_exactly() {
    // A constant volume of ones with unit voxels; four boxes along y (voxels 1–3,
    // 6–8, 11–12, 15–20) over x 4–11, z 3–12: every ray down y through the comb
    // integrates 3 + 3 + 2 + 6 = 14 voxels; every other ray sees nothing.
    let dims = [16, 24, 16];
    let vol: AnyVolume = Volume::new(dims, [1.0; 3], vec![1.0f32; 16 * 24 * 16])
        .unwrap()
        .into();
    let mut comb = TriMesh::default();
    for (y0, y1) in [(1.0, 3.0), (6.0, 8.0), (11.0, 12.0), (15.0, 20.0)] {
        comb.append_cuboid([3.5, y0 - 0.5, 2.5], [11.5, y1 + 0.5, 12.5]);
    }
    let cam = Camera::axis_view(dims, vol.affine(), AxisView::MinusY, 16, 16).unwrap();
    let s = RenderSettings {
        mode: Mode::Xray,
        step: 1.0,
        sample_count: true,
        clip_mesh: mesh(comb, ClipMeshUnits::Voxel),
        ..Default::default()
    };
    let out = draw(&vol, &cam, &s);
    let inside = out.image.data.iter().filter(|&&v| v != 0.0).count();
    assert_eq!(inside, 8 * 10);
    for &v in &out.image.data {
        // Measured: exactly 14 (sums of unit steps).
        assert!(v == 0.0 || (v - 14.0).abs() < 1e-12, "{v}");
    }
    assert_eq!(out.total_samples, 80 * 14);
}

#[test]
fn enclosing_and_bricks_meshes_render_the_unclipped_image() {
    let vol = phantom(40);
    let cam = perspective(48);
    let big = TriMesh::cuboid([-300.0; 3], [300.0; 3]);
    for mode in [Mode::Dvr, Mode::Mip, Mode::Xray] {
        let s = RenderSettings {
            mode,
            block_size: 8,
            sample_count: true,
            ..Default::default()
        };
        let plain = draw(&vol, &cam, &s);
        let enclosed = draw(
            &vol,
            &cam,
            &RenderSettings {
                clip_mesh: mesh(big.clone(), ClipMeshUnits::World),
                ..s.clone()
            },
        );
        assert_eq!(plain.image.data, enclosed.image.data, "{mode:?}");
        assert_eq!(plain.total_samples, enclosed.total_samples);
        if mode != Mode::Dvr {
            continue;
        }
        for skip in [false, true] {
            let bricks = RenderSettings {
                skip_empty: skip,
                clip_mesh: Some(ClipMesh::Bricks),
                ..s.clone()
            };
            let b = draw(&vol, &cam, &bricks);
            assert_eq!(plain.image.data, b.image.data, "bricks, skip {skip}");
            let unskipped = draw(
                &vol,
                &cam,
                &RenderSettings {
                    skip_empty: false,
                    ..s.clone()
                },
            );
            // The mesh takes fewer samples than no skipping at all.
            assert!(
                b.total_samples < unskipped.total_samples,
                "{} vs {}",
                b.total_samples,
                unskipped.total_samples
            );
        }
    }
    // Bricks refuse modes without a transfer-function grid; MIDA refuses any mesh.
    let mip = RenderSettings {
        mode: Mode::Mip,
        clip_mesh: Some(ClipMesh::Bricks),
        ..Default::default()
    };
    assert!(render::<f64>(&vol, &sparse_tf(), &cam, &mip, none()).is_err());
    let mida = RenderSettings {
        mode: Mode::Mida,
        clip_mesh: mesh(big, ClipMeshUnits::World),
        ..Default::default()
    };
    assert!(render::<f64>(&vol, &sparse_tf(), &cam, &mida, none()).is_err());
}

/// The hierarchy (`ClipTriangles::segments`) finds exactly the hits of testing every
/// triangle (`segments_brute_force`), so the same segments, on a brick wall of cubes
/// with shared faces, the cut-away mesh and a random triangle soup; for random lines
/// and for lines along the axes and diagonals through the bricks' edges and corners,
/// where the boxes are flat and a slab test without padding drops hits.
#[test]
fn hierarchy_finds_every_hit_of_the_brute_force_search() {
    let mut rng = common::Rng(0x9e37_79b9_7f4a_7c15);
    let mut bricks = TriMesh::default();
    for z in 0..4 {
        for y in 0..5 {
            for x in 0..6 {
                if (x * 7 + y * 3 + z * 5) % 4 != 0 {
                    let lo = [x as f64, y as f64, z as f64].map(|c| c * 2.0 - 5.0);
                    bricks.append_cuboid(lo, lo.map(|c| c + 2.0));
                }
            }
        }
    }
    let cutaway = read_mesh(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("data/meshes/cutaway.obj")
            .as_path(),
    )
    .unwrap();
    let mut soup = TriMesh::default();
    for _ in 0..300 {
        let base = soup.vertices.len() as u32;
        let c = [0; 3].map(|_| rng.unit() * 10.0 - 5.0);
        for _ in 0..3 {
            soup.vertices
                .push([0; 3].map(|a: usize| c[a % 3] + rng.unit() * 2.0 - 1.0));
        }
        soup.triangles.push([base, base + 1, base + 2]);
    }
    // A flat sheet of 0.7-mm squares at z = 0.3: its leaves' boxes have no thickness.
    let mut sheet = TriMesh::default();
    for j in 0..=16 {
        for i in 0..=16 {
            sheet
                .vertices
                .push([i as f64 * 0.7 - 5.6, j as f64 * 0.7 - 5.6, 0.3]);
        }
    }
    for j in 0..16u32 {
        for i in 0..16u32 {
            let v = j * 17 + i;
            sheet.triangles.push([v, v + 1, v + 18]);
            sheet.triangles.push([v, v + 18, v + 17]);
        }
    }
    let mut sheet_rays = Vec::new();
    for j in 0..=32 {
        for i in 0..=32 {
            // Through the sheet's corners and edge midpoints, obliquely.
            let p = DVec3::new(i as f64 * 0.35 - 5.6, j as f64 * 0.35 - 5.6, 0.3);
            let d = DVec3::new(0.3 + 0.01 * i as f64, -0.2 + 0.013 * j as f64, 1.0).normalize();
            sheet_rays.push((p - 7.0 * d, d));
        }
    }
    for (name, m) in [
        ("bricks", &bricks),
        ("cutaway", &cutaway),
        ("soup", &soup),
        ("sheet", &sheet),
    ] {
        let tris = ClipTriangles::new(m);
        assert!(tris.bvh_nodes() > 1, "{name}: a hierarchy was built");
        let mut rays: Vec<(DVec3, DVec3)> = (0..3000)
            .map(|_| {
                let o = DVec3::new(rng.unit(), rng.unit(), rng.unit()) * 40.0 - 20.0;
                let d = DVec3::new(rng.unit(), rng.unit(), rng.unit()) * 2.0 - 1.0;
                (o, d.normalize())
            })
            .collect();
        // Through the bricks' edges and corners (even integers from −5 … offsets).
        for i in -3..=3 {
            for j in -3..=3 {
                let (u, v) = (i as f64 * 2.0 - 1.0, j as f64 * 2.0 - 1.0);
                for d in [
                    DVec3::X,
                    DVec3::Y,
                    DVec3::Z,
                    -DVec3::Z,
                    DVec3::ONE.normalize(),
                    DVec3::new(1.0, 1.0, 0.0).normalize(),
                ] {
                    let o = if d.z == 0.0 {
                        DVec3::new(u - 20.0 * d.x, v - 20.0 * d.y, u)
                    } else {
                        DVec3::new(u, v, 0.0) - 20.0 * d
                    };
                    rays.push((o, d));
                }
            }
        }
        if name == "sheet" {
            rays.extend(sheet_rays.iter().copied());
        }
        let mut hits = 0;
        for (o, d) in rays {
            for t0 in [0.0, 20.0] {
                let fast = tris.segments(o, d, t0);
                assert_eq!(
                    fast,
                    tris.segments_brute_force(o, d, t0),
                    "{name}: ray {o} {d} from {t0}"
                );
                hits += fast.count;
            }
        }
        assert!(
            hits > 100,
            "{name}: the rays hit the mesh ({hits} segments)"
        );
    }
}
