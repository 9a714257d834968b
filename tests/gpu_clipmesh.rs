//! Clipping meshes on the GPU (`gpu::clipmesh`, `shaders/clipmesh.wgsl`) against the
//! CPU f64 oracle (`cpu::clipmesh`): the per-pixel segments themselves, then renders
//! from one case list: a cube mesh equal to a clipping box, a comb of four boxes giving
//! four segments per ray, an enclosing mesh and the bricks mesh (both must also equal
//! the GPU image without a mesh, bit for bit), in DVR (both compositing orders), MIP,
//! MinIP and X-ray.

mod common;

use glam::DVec3;
use std::sync::Arc;
use voxlab::camera::{AxisView, Camera, Projection};
use voxlab::cpu::clipmesh::ClipTriangles;
use voxlab::io::mesh::TriMesh;
use voxlab::metrics::Tolerance;
use voxlab::phantom::Phantom;
use voxlab::settings::{ClipMesh, ClipMeshUnits, Compositing, Mode, RenderSettings};
use voxlab::AnyVolume;

fn none() -> &'static (dyn Fn(usize, usize) + Sync) {
    &|_, _| {}
}

use common::sparse_tf;

fn phantom() -> AnyVolume {
    Phantom::shepp_logan_modified()
        .sample([32, 35, 30])
        .unwrap()
        .into()
}

#[derive(Clone, Copy, Debug)]
enum Cam {
    Axis,
    Perspective,
}

fn camera(vol: &AnyVolume, cam: Cam) -> Camera {
    let d = vol.dims();
    match cam {
        Cam::Axis => Camera::axis_view(d, vol.affine(), AxisView::MinusY, d[0], d[2]).unwrap(),
        Cam::Perspective => {
            common::orbit_camera(Projection::Perspective { fov_y_deg: 30.0 }, 32, 24)
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Mesh {
    /// A cuboid in voxel units (the faces half a voxel outside voxels 4–25, 6–20, 3–22).
    Cube,
    /// Four boxes along y: rays down y cross four segments.
    Comb,
    /// A cube enclosing the volume: the image without a mesh.
    Enclosing,
    /// The bricks mesh of the skipping grid: the image without a mesh.
    Bricks,
}

fn comb() -> TriMesh {
    let mut comb = TriMesh::default();
    for (y0, y1) in [(2.0, 6.0), (9.0, 13.0), (17.0, 20.0), (24.0, 31.0)] {
        comb.append_cuboid([3.5, y0 - 0.5, 2.5], [27.5, y1 + 0.5, 26.5]);
    }
    comb
}

fn clip_mesh(m: Mesh) -> ClipMesh {
    let mesh = |m: TriMesh, units| ClipMesh::Mesh {
        mesh: Arc::new(m),
        units,
    };
    match m {
        Mesh::Cube => mesh(
            TriMesh::cuboid([3.5, 5.5, 2.5], [25.5, 20.5, 22.5]),
            ClipMeshUnits::Voxel,
        ),
        Mesh::Comb => mesh(comb(), ClipMeshUnits::Voxel),
        Mesh::Enclosing => mesh(
            TriMesh::cuboid([-300.0; 3], [300.0; 3]),
            ClipMeshUnits::World,
        ),
        Mesh::Bricks => ClipMesh::Bricks,
    }
}

#[derive(Clone, Copy, Debug)]
struct Case {
    mesh: Mesh,
    mode: Mode,
    compositing: Compositing,
    cam: Cam,
    skip: bool,
}

const BASE: Case = Case {
    mesh: Mesh::Cube,
    mode: Mode::Dvr,
    compositing: Compositing::FrontToBack,
    cam: Cam::Perspective,
    skip: false,
};

fn settings(case: &Case, mesh: bool) -> RenderSettings {
    RenderSettings {
        mode: case.mode,
        compositing: case.compositing,
        block_size: 8,
        skip_empty: case.skip,
        sample_count: true,
        clip_mesh: mesh.then(|| clip_mesh(case.mesh)),
        ..RenderSettings::default()
    }
}

/// DVR against the f64 oracle (the ray caster's bound, tests/gpu_raycast.rs:
/// EXACT_DVR). Measured on lavapipe over the cases below: worst max |Δ| 1.4e-5 (cube,
/// perspective), RMSE 5.6e-7.
const DVR: Tolerance = Tolerance {
    max_abs: 1e-3,
    rmse: 5e-5,
    ..Tolerance::NONE
};

/// MIP, MinIP and X-ray, relative to the largest oracle value. Measured on lavapipe:
/// worst max |Δ| 7.9e-6 (MIP, comb and enclosing), RMSE 1.4e-6 (MIP); X-ray 3.6e-6
/// (comb); MinIP 1.6e-6 (comb).
const SCALAR: Tolerance = Tolerance {
    max_abs: 2e-5,
    rmse: 5e-6,
    ..Tolerance::NONE
};

/// GPU with the mesh against the CPU f64 oracle with the mesh; enclosing and bricks
/// meshes also against the GPU without a mesh (identical); sample counts agree with the
/// CPU's on all but a few pixels (f32 segment ends).
fn check(name: &str, case: Case) {
    let Some(ctx) = common::gpu(name) else {
        return;
    };
    let vol = phantom();
    let cam = camera(&vol, case.cam);
    let tf = sparse_tf();
    let gpu = |mesh| {
        voxlab::gpu::raycast::render(ctx, &vol, &tf, &cam, &settings(&case, mesh), none())
            .unwrap()
            .output
    };
    let on = gpu(true);
    let cpu = voxlab::cpu::raycast::render::<f64>(&vol, &tf, &cam, &settings(&case, true), none())
        .unwrap();
    let tol = if case.mode == Mode::Dvr {
        DVR
    } else {
        let scale = cpu.image.data.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        Tolerance {
            max_abs: SCALAR.max_abs * scale,
            rmse: SCALAR.rmse * scale,
            ..Tolerance::NONE
        }
    };
    let stats = common::assert_parity(name, &cpu.image, &on.image, tol);
    let counts_differ = cpu
        .samples
        .unwrap()
        .data
        .iter()
        .zip(&on.samples.as_ref().unwrap().data)
        .filter(|(a, b)| a != b)
        .count();
    eprintln!(
        "{name}: vs oracle max |Δ| {:.2e}, rmse {:.2e} (bound {:.1e}); {counts_differ} \
         sample counts differ from the CPU's; samples {} (CPU {})",
        stats.max_abs, stats.rmse, tol.max_abs, on.total_samples, cpu.total_samples
    );
    assert!(
        counts_differ * 50 <= cam.width * cam.height,
        "{counts_differ}"
    );
    if matches!(case.mesh, Mesh::Enclosing | Mesh::Bricks) {
        let off = gpu(false);
        assert_eq!(
            on.image.data, off.image.data,
            "{name}: the mesh changed the image"
        );
        if case.mesh == Mesh::Enclosing {
            assert_eq!(on.total_samples, off.total_samples);
        } else {
            assert!(on.total_samples <= off.total_samples);
        }
    }
}

macro_rules! gpu_cases {
    ($($name:ident: $case:expr;)*) => {
        $(
            #[test]
            fn $name() {
                check(stringify!($name), $case);
            }
        )*
    };
}

gpu_cases! {
    gpu_clipmesh_cube_dvr: BASE;
    gpu_clipmesh_cube_dvr_axis: Case { cam: Cam::Axis, ..BASE };
    gpu_clipmesh_cube_mip: Case { mode: Mode::Mip, ..BASE };
    gpu_clipmesh_cube_xray_axis: Case { mode: Mode::Xray, cam: Cam::Axis, ..BASE };
    gpu_clipmesh_comb_dvr: Case { mesh: Mesh::Comb, ..BASE };
    gpu_clipmesh_comb_dvr_back_to_front: Case { mesh: Mesh::Comb, compositing: Compositing::BackToFront, ..BASE };
    gpu_clipmesh_comb_dvr_skip_axis: Case { mesh: Mesh::Comb, skip: true, cam: Cam::Axis, ..BASE };
    gpu_clipmesh_comb_mip: Case { mesh: Mesh::Comb, mode: Mode::Mip, ..BASE };
    gpu_clipmesh_comb_xray: Case { mesh: Mesh::Comb, mode: Mode::Xray, ..BASE };
    gpu_clipmesh_comb_minip: Case { mesh: Mesh::Comb, mode: Mode::Minip, ..BASE };
    gpu_clipmesh_cube_minip_axis: Case { mesh: Mesh::Cube, mode: Mode::Minip, cam: Cam::Axis, ..BASE };
    gpu_clipmesh_enclosing_dvr: Case { mesh: Mesh::Enclosing, ..BASE };
    gpu_clipmesh_enclosing_mip: Case { mesh: Mesh::Enclosing, mode: Mode::Mip, ..BASE };
    gpu_clipmesh_enclosing_xray: Case { mesh: Mesh::Enclosing, mode: Mode::Xray, ..BASE };
    gpu_clipmesh_bricks_dvr: Case { mesh: Mesh::Bricks, ..BASE };
    gpu_clipmesh_bricks_dvr_skip_back_to_front: Case { mesh: Mesh::Bricks, skip: true, compositing: Compositing::BackToFront, ..BASE };
}

/// `m` (voxel units) carried to world mm by `vol`'s affine, ready for the segment search.
fn world_triangles(vol: &AnyVolume, m: &TriMesh) -> ClipTriangles {
    let affine = vol.affine();
    ClipTriangles::new(&TriMesh {
        vertices: m
            .vertices
            .iter()
            .map(|&p| affine.transform_point3(DVec3::from_array(p)).to_array())
            .collect(),
        triangles: m.triangles.clone(),
    })
}

/// The ray caster's parameters for `cam` over `vol`, as one tile of all its rows.
fn tile_params(vol: &AnyVolume, cam: &Camera) -> voxlab::gpu::raycast::RaycastParams {
    let s = RenderSettings::default();
    let lut = sparse_tf().lut(s.lut_size).to_real::<f32>();
    let mut params =
        voxlab::gpu::raycast::raycast_params(vol.dims(), vol.affine(), &lut, (0.0, 1.0), cam, &s)
            .unwrap();
    params.tile = [0, 0, cam.width as u32, cam.height as u32];
    params
}

/// The segments of every pixel's ray, GPU (f32) against `ClipTriangles::segments`
/// (f64): the comb gives four segments on a good share of the rays (97 of 768 in this
/// oblique view), and the counts agree on every pixel; the ends agree to f32 rounding of
/// |t| ≈ 540 mm. Measured on lavapipe: worst |Δt| 1.8e-4 mm.
#[test]
fn gpu_segments_match_the_cpu() {
    let Some(ctx) = common::gpu("gpu_segments_match_the_cpu") else {
        return;
    };
    let vol = phantom();
    let cam = camera(&vol, Cam::Perspective);
    let params = tile_params(&vol, &cam);
    let tris = world_triangles(&vol, &comb());
    let gpu = voxlab::gpu::clipmesh::segments(ctx, &tris, &params).unwrap();
    let mut four = 0;
    // Every segment's two ends, pixel by pixel, on both sides.
    let (mut cpu_t, mut gpu_t) = (Vec::new(), Vec::<f32>::new());
    for row in 0..cam.height {
        for col in 0..cam.width {
            let ray = cam.ray(col, row);
            let c = tris.segments(ray.origin, ray.dir, ray.t_min);
            let g = &gpu[row * cam.width + col];
            assert_eq!(c.count, g.len(), "pixel ({col}, {row})");
            four += (c.count >= 4) as usize;
            for (a, b) in c.as_slice().iter().zip(g) {
                cpu_t.extend_from_slice(&a[..2]);
                gpu_t.extend_from_slice(&b[..2]);
            }
        }
    }
    let worst = common::assert_parity_array(
        "gpu_segments_match_the_cpu",
        &[2, cpu_t.len() / 2],
        &cpu_t,
        &gpu_t,
        Tolerance::max_abs(5e-4),
    )
    .max_abs;
    eprintln!("segments: worst |Δt| {worst:e} mm; {four} rays with ≥ 4 segments");
    assert!(four * 10 >= cam.width * cam.height, "{four}");
}

/// The hierarchy walk finds exactly the hits of testing every triangle: the same
/// segments, bit for bit, on every pixel. Meshes: the comb, and a wall of 6 × 6 × 6
/// touching cubes (2 592 triangles, 2 047 nodes: the walk spans four dispatches),
/// whose coplanar faces and shared edges and corners are where a box test too tight
/// for f32 would drop hits; views: perspective and down an axis (rays through edges).
#[test]
fn gpu_hierarchy_finds_the_hits_of_every_triangle() {
    let Some(ctx) = common::gpu("gpu_hierarchy_finds_the_hits_of_every_triangle") else {
        return;
    };
    let vol = phantom();
    let mut wall = TriMesh::default();
    for z in 0..6 {
        for y in 0..6 {
            for x in 0..6 {
                let lo = [
                    3.5 + 4.0 * x as f64,
                    4.5 + 4.0 * y as f64,
                    2.5 + 4.0 * z as f64,
                ];
                wall.append_cuboid(lo, lo.map(|v| v + 4.0));
            }
        }
    }
    let mut pixels = 0;
    for (name, m) in [("comb", comb()), ("wall", wall)] {
        let tris = world_triangles(&vol, &m);
        for cam in [Cam::Perspective, Cam::Axis] {
            let params = tile_params(&vol, &camera(&vol, cam));
            let every =
                voxlab::gpu::clipmesh::segments_with_search(ctx, &tris, &params, false).unwrap();
            let walked =
                voxlab::gpu::clipmesh::segments_with_search(ctx, &tris, &params, true).unwrap();
            assert_eq!(every.len(), walked.len());
            let mut segments = 0;
            for (i, (a, b)) in every.iter().zip(&walked).enumerate() {
                let bits = |v: &Vec<[f32; 2]>| -> Vec<[u32; 2]> {
                    v.iter().map(|s| s.map(f32::to_bits)).collect()
                };
                assert_eq!(bits(a), bits(b), "{name} {cam:?}: pixel {i}");
                segments += a.len();
            }
            assert!(
                segments > every.len(),
                "{name} {cam:?}: {segments} segments"
            );
            pixels += every.len();
            eprintln!(
                "{name} ({} triangles, {} nodes) {cam:?}: {segments} segments, the same",
                tris.triangles.len(),
                tris.bvh_nodes()
            );
        }
    }
    assert!(pixels > 1000);
}
