// Joseph forward projection of a voxel grid, one invocation per detector pixel.
// Mirrors src/cpu/project.rs: project_volume and JosephPair::forward (per pixel:
// pixel_ray, then joseph_ray); the host sides are src/gpu/project.rs and
// src/gpu/joseph_pair.rs.

#import project_params
#import joseph
// The grid (binding 2) and `fn plane_sample(pl: Planes, s: u32) -> f32`, Joseph's
// sample on plane s: exact (a storage buffer, shared/joseph_bilinear.wgsl) or through
// the texture unit, as src/gpu/project.rs: volume_wgsl writes it.
#import joseph_volume

@group(0) @binding(0) var<uniform> p: ProjectParams;
@group(0) @binding(1) var<storage, read> views: array<JosephView>;
// [out_offset + (slot − view_offset)·rows·cols + row·cols + col]
@group(0) @binding(3) var<storage, read_write> out: array<f32>;
// The views to project, in output order (all of them for project_volume; a subset
// for the iterative methods' JosephPair::forward).
@group(0) @binding(4) var<storage, read> list: array<u32>;

const WORKGROUP: u32 = 64u;

// Joseph's line integral along o + t·d, t ≥ t_min (index frame, |d| = 1 world mm).
// mirrors src/cpu/project.rs: joseph_ray
fn joseph_ray(o: vec3<f32>, d: vec3<f32>, t_min: f32) -> f32 {
    let pl = joseph_planes(vec3<u32>(p.nx, p.ny, p.nz), o, d, t_min);
    if !pl.hit {
        return 0.0;
    }
    var sum = 0.0;
    for (var s = pl.s0; s <= pl.s1; s++) {
        sum += plane_sample(pl, s);
    }
    return sum * pl.w;
}

@compute @workgroup_size(WORKGROUP)
fn project(@builtin(global_invocation_id) gid: vec3<u32>) {
    let id = gid.x + gid.y * p.row_stride;
    let per_view = p.cols * p.rows;
    if id >= p.n_views * per_view {
        return;
    }
    let k = id / per_view;
    let rem = id % per_view;
    let r = pixel_ray(views[list[p.view_offset + k]], f32(rem % p.cols), f32(rem / p.cols));
    out[p.out_offset + id] = joseph_ray(r.o, r.d, r.t_min);
}
