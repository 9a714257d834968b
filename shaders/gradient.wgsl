// The gradient volume on the GPU, one invocation per voxel of a slab of z-slices,
// written component-planar (all x, then all y, then all z components of the slab).
// mirrors src/cpu/gradient.rs: precompute_gradients
// The stencil (voxel, gradient_at_voxel) is shared/gradient_voxel.wgsl.

#import gradient_params
#import gradient_voxel

@group(0) @binding(0) var<uniform> params: GradientParams;
@group(0) @binding(1) var volume: texture_3d<f32>;
@group(0) @binding(2) var<storage, read_write> out: array<f32>;

@compute @workgroup_size(4, 4, 4)
fn gradient_slab(@builtin(global_invocation_id) id: vec3<u32>) {
    let nx = params.dims.x;
    let ny = params.dims.y;
    if (id.x >= nx || id.y >= ny || id.z >= params.slab.y) {
        return;
    }
    let p = vec3<i32>(i32(id.x), i32(id.y), i32(id.z + params.slab.x));
    let g = gradient_at_voxel(p, params.dims.w);
    let n = nx * ny * params.slab.y;
    let i = id.x + nx * (id.y + ny * id.z);
    out[i] = g.x;
    out[n + i] = g.y;
    out[2u * n + i] = g.z;
}
