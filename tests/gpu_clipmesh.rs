//! Clipping meshes on the GPU backend: not yet ported (the segments are computed by
//! the CPU ray caster only), so a GPU render with a mesh must refuse clearly rather
//! than ignore the mesh.

mod common;

use std::sync::Arc;
use voxlab::camera::{AxisView, Camera};
use voxlab::io::mesh::TriMesh;
use voxlab::phantom::Phantom;
use voxlab::settings::{ClipMesh, ClipMeshUnits, RenderSettings};
use voxlab::AnyVolume;

#[test]
fn gpu_render_refuses_a_clip_mesh() {
    let Some(ctx) = common::gpu("gpu_render_refuses_a_clip_mesh") else {
        return;
    };
    let vol: AnyVolume = Phantom::shepp_logan_modified()
        .sample([16, 16, 16])
        .unwrap()
        .into();
    let d = vol.dims();
    let cam = Camera::axis_view(d, vol.affine(), AxisView::MinusY, 16, 16).unwrap();
    let tf = voxlab::transfer::TransferFunction::preset("phantom").unwrap();
    for clip in [
        ClipMesh::Bricks,
        ClipMesh::Mesh {
            mesh: Arc::new(TriMesh::cuboid([-1e3; 3], [1e3; 3])),
            units: ClipMeshUnits::World,
        },
    ] {
        let s = RenderSettings {
            clip_mesh: Some(clip),
            ..Default::default()
        };
        let r = voxlab::gpu::raycast::render(ctx, &vol, &tf, &cam, &s, &|_, _| {});
        let Err(e) = r else {
            panic!("a GPU render with a clip mesh must fail");
        };
        assert!(e.to_string().contains("clip mesh"), "{e}");
    }
}
