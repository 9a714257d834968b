// Set-up passes of the GPU ray caster, one invocation per voxel, written to
// rgba32float storage textures that the ray caster then samples like the data.
// Mirrors src/cpu/raycast.rs: preclassify and src/cpu/gradient.rs: gradient_at_voxel.
// Prepended at load time: shaders/shared/raycast_params.wgsl and classify.wgsl.

@group(0) @binding(0) var<uniform> params: RaycastParams;
@group(0) @binding(1) var volume: texture_3d<f32>;
@group(0) @binding(2) var<storage, read> lut: array<vec4<f32>>;
@group(0) @binding(3) var target_tex: texture_storage_3d<rgba32float, write>;

// classify(t): shaders/shared/classify.wgsl.


fn voxel(i: vec3<i32>) -> f32 {
    let n = vec3<i32>(params.dims.xyz) - vec3<i32>(1);
    return textureLoad(volume, clamp(i, vec3<i32>(0), n), 0).x;
}

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

fn unit(a: u32, s: i32) -> vec3<i32> {
    var v = vec3<i32>(0);
    v[a] = s;
    return v;
}

// mirrors src/cpu/gradient.rs: gradient_at_voxel (clamped neighbours)
@compute @workgroup_size(4, 4, 4)
fn precompute_gradients(@builtin(global_invocation_id) id: vec3<u32>) {
    if (!inside(id)) {
        return;
    }
    let p = vec3<i32>(id);
    let method = params.flags2.x;
    var g = vec3<f32>(0.0);
    if (method == 0u) {
        for (var a = 0u; a < 3u; a++) {
            g[a] = (voxel(p + unit(a, 1)) - voxel(p + unit(a, -1))) * 0.5;
        }
    } else if (method == 1u) {
        let f0 = voxel(p);
        for (var a = 0u; a < 3u; a++) {
            g[a] = voxel(p + unit(a, 1)) - f0;
        }
    } else {
        let sobel_w = array<f32, 3>(0.25, 0.5, 0.25);
        for (var a = 0u; a < 3u; a++) {
            let b = (a + 1u) % 3u;
            let c = (a + 2u) % 3u;
            var acc = 0.0;
            for (var ob = 0u; ob < 3u; ob++) {
                for (var oc = 0u; oc < 3u; oc++) {
                    let q = p + unit(b, i32(ob) - 1) + unit(c, i32(oc) - 1);
                    let d = voxel(q + unit(a, 1)) - voxel(q + unit(a, -1));
                    acc = acc + (sobel_w[ob] * sobel_w[oc]) * d;
                }
            }
            g[a] = acc * 0.5;
        }
    }
    textureStore(target_tex, p, vec4<f32>(g, 0.0));
}
