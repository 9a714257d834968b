// Set-up passes of the GPU ray caster, one invocation per voxel, written to
// rgba32float storage textures that the ray caster then samples like the data.
// Twins of src/cpu/raycast.rs: preclassify and src/cpu/gradient.rs:
// precompute_gradients.

#import raycast_params
#import classify
#import gradient_voxel

@group(0) @binding(0) var<uniform> params: RaycastParams;
@group(0) @binding(1) var volume: texture_3d<f32>;
@group(0) @binding(2) var<storage, read> lut: array<vec4<f32>>;
@group(0) @binding(3) var target_tex: texture_storage_3d<rgba32float, write>;

// classify(t): shaders/shared/classify.wgsl; voxel(i): shaders/shared/gradient_voxel.wgsl.

fn inside(id: vec3<u32>) -> bool {
    return all(id < params.dims.xyz);
}

// mirrors src/cpu/raycast.rs: preclassify — opacity-weighted colour of every voxel
@compute @workgroup_size(4, 4, 4)
fn preclassify(@builtin(global_invocation_id) id: vec3<u32>) {
    if (!inside(id)) {
        return;
    }
    let c = classify(voxel(vec3<i32>(id)));
    textureStore(target_tex, vec3<i32>(id), vec4<f32>(c.xyz * c.w, c.w));
}

// mirrors src/cpu/gradient.rs: precompute_gradients (clamped neighbours);
// gradient_at_voxel: shaders/shared/gradient_voxel.wgsl
@compute @workgroup_size(4, 4, 4)
fn precompute_gradients(@builtin(global_invocation_id) id: vec3<u32>) {
    if (!inside(id)) {
        return;
    }
    let p = vec3<i32>(id);
    textureStore(target_tex, p, vec4<f32>(gradient_at_voxel(p, params.flags2.x), 0.0));
}
