// The importance volume of adaptive sampling: per voxel and axis the largest one-sided
// difference, then a max filter along one axis per pass (x, y, z).
// Mirrors src/cpu/adaptive.rs: axis_difference, max_filter_axis.

#import adaptive_params

@group(0) @binding(0) var<uniform> params: AdaptiveParams;
// The volume (R32Float) and the importance volumes (Rgba32Float) are 3-D textures,
// read texel by texel.
@group(0) @binding(1) var volume: texture_3d<f32>;
@group(0) @binding(2) var src: texture_3d<f32>;
@group(0) @binding(3) var dst: texture_storage_3d<rgba32float, write>;

fn at_clamped(q: vec3<i32>) -> f32 {
    let n = vec3<i32>(params.dims.xyz);
    let c = clamp(q, vec3<i32>(0), n - vec3<i32>(1));
    return textureLoad(volume, c, 0).x;
}

// mirrors src/cpu/adaptive.rs: axis_difference
fn axis_difference(v: vec3<i32>, axis: u32) -> f32 {
    var e = vec3<i32>(0);
    e[axis] = 1;
    let c = at_clamped(v);
    let fwd = at_clamped(v + e) - c;
    let bwd = c - at_clamped(v - e);
    return max(abs(fwd), abs(bwd));
}

fn voxel_of(gid: vec3<u32>) -> bool {
    return gid.x < params.dims.x && gid.y < params.dims.y && gid.z < params.dims.z;
}

@compute @workgroup_size(4, 4, 4)
fn differences(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (!voxel_of(gid)) {
        return;
    }
    let v = vec3<i32>(gid);
    textureStore(dst, v, vec4<f32>(axis_difference(v, 0u), axis_difference(v, 1u), axis_difference(v, 2u), 0.0));
}

// mirrors src/cpu/adaptive.rs: max_filter_axis (all three channels at once)
@compute @workgroup_size(4, 4, 4)
fn max_filter(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (!voxel_of(gid)) {
        return;
    }
    let axis = params.extra.z;
    let r = params.extra.w;
    let n = params.dims[axis];
    let p = gid;
    var lo = 0u;
    if (p[axis] > r) {
        lo = p[axis] - r;
    }
    let hi = min(p[axis] + r, n - 1u);
    var q = p;
    var m = vec4<f32>(0.0);
    for (var x = lo; x <= hi; x++) {
        q[axis] = x;
        m = max(m, textureLoad(src, vec3<i32>(q), 0));
    }
    textureStore(dst, vec3<i32>(p), m);
}
