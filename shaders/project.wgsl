// Joseph forward projection of a voxel grid, one invocation per detector pixel.
// Mirrors src/cpu/project.rs: project_volume and JosephPair::forward (per pixel:
// pixel_ray, then joseph_ray); the host sides are src/gpu/project.rs and
// src/gpu/joseph_pair.rs.

#import project_params
#import joseph

@group(0) @binding(0) var<uniform> p: ProjectParams;
@group(0) @binding(1) var<storage, read> views: array<JosephView>;
// [z][y][x]
@group(0) @binding(2) var<storage, read> vol: array<f32>;
// [out_offset + (slot − view_offset)·rows·cols + row·cols + col]
@group(0) @binding(3) var<storage, read_write> out: array<f32>;
// The views to project, in output order (all of them for project_volume; a subset
// for the iterative methods' JosephPair::forward).
@group(0) @binding(4) var<storage, read> list: array<u32>;

const WORKGROUP: u32 = 64u;

// Bilinear interpolation, continued by zeros, of the index plane starting at `base`.
// mirrors src/cpu/project.rs: slice_bilinear
fn slice_bilinear(base: u32, sa: u32, na: u32, sb: u32, nb: u32, x: f32, y: f32) -> f32 {
    let fx = floor(x);
    let fy = floor(y);
    if !(fx >= -1.0 && fx < f32(na) && fy >= -1.0 && fy < f32(nb)) {
        return 0.0;
    }
    let tx = x - fx;
    let ty = y - fy;
    let ix = i32(fx);
    let iy = i32(fy);
    var tap: array<f32, 4>;
    for (var q = 0; q < 4; q++) {
        let i = ix + (q & 1);
        let j = iy + (q >> 1u);
        if i < 0 || j < 0 || i >= i32(na) || j >= i32(nb) {
            tap[q] = 0.0;
        } else {
            tap[q] = vol[base + u32(i) * sa + u32(j) * sb];
        }
    }
    let top = tap[0] * (1.0 - tx) + tap[1] * tx;
    let bottom = tap[2] * (1.0 - tx) + tap[3] * tx;
    return top * (1.0 - ty) + bottom * ty;
}

// Joseph's line integral along o + t·d, t ≥ t_min (index frame, |d| = 1 world mm).
// mirrors src/cpu/project.rs: joseph_ray
fn joseph_ray(o: vec3<f32>, d: vec3<f32>, t_min: f32) -> f32 {
    let pl = joseph_planes(vec3<u32>(p.nx, p.ny, p.nz), o, d, t_min);
    if !pl.hit {
        return 0.0;
    }
    let stride = array<u32, 3>(1u, p.nx, p.nx * p.ny);
    let dims = array<u32, 3>(p.nx, p.ny, p.nz);
    var sum = 0.0;
    for (var s = pl.s0; s <= pl.s1; s++) {
        let sr = f32(s);
        sum += slice_bilinear(s * stride[pl.m], stride[pl.a], dims[pl.a], stride[pl.b],
                              dims[pl.b], pl.xa0 + sr * pl.ka, pl.xb0 + sr * pl.kb);
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
