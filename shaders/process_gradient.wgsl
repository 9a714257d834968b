// Gradient magnitude in world units, one invocation per voxel: central differences with
// clamped neighbours (src/cpu/gradient.rs: gradient_at_voxel, Central), then |L⁻ᵀ g|.
// Mirrors src/cpu/process.rs: gradient_magnitude; the host side is src/gpu/process.rs.

#import process_params

// |M g| with M's rows in params.m0..m2. Mirrors src/cpu/process.rs: world_gradient_length.
fn world_gradient_length(g: vec3<f32>) -> f32 {
    return length(vec3<f32>(dot(params.m0.xyz, g), dot(params.m1.xyz, g), dot(params.m2.xyz, g)));
}

@compute @workgroup_size(WORKGROUP)
fn gradient_magnitude(@builtin(global_invocation_id) gid: vec3<u32>,
                      @builtin(num_workgroups) nwg: vec3<u32>) {
    var v: vec3<u32>;
    if !output_voxel(gid, nwg, &v) {
        return;
    }
    let n = params.in_dims;
    let p = vec3<i32>(v);
    let gx = (in_at(clamped(p.x + 1, n.x), v.y, v.z) - in_at(clamped(p.x - 1, n.x), v.y, v.z)) * 0.5;
    let gy = (in_at(v.x, clamped(p.y + 1, n.y), v.z) - in_at(v.x, clamped(p.y - 1, n.y), v.z)) * 0.5;
    let gz = (in_at(v.x, v.y, clamped(p.z + 1, n.z)) - in_at(v.x, v.y, clamped(p.z - 1, n.z))) * 0.5;
    dst[out_index(v)] = world_gradient_length(vec3<f32>(gx, gy, gz));
}
