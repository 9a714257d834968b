// The fast tricubic B-spline at a list of points (src/gpu/tricubic.rs: sample_fast),
// for measuring the manual and the texture-unit paths against src/cpu/tricubic.rs:
// sample_fast. The sampling itself is shared/tricubic.wgsl, as in the ray caster.

#import tricubic

// x: the number of points.
@group(0) @binding(0) var<uniform> count: vec4<u32>;
@group(0) @binding(1) var volume: texture_3d<f32>;
// Index-space points (xyz; w unused).
@group(0) @binding(2) var<storage, read> points: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> values: array<f32>;
@group(0) @binding(4) var linear_clamp: sampler;

// 8 manual trilinear fetches (exact in f32).
@compute @workgroup_size(64)
fn sample_points_exact(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if (i >= count.x) {
        return;
    }
    values[i] = sample_fast_bspline(volume, points[i].xyz, textureDimensions(volume)).x;
}

// 8 fetches through the texture unit.
@compute @workgroup_size(64)
fn sample_points_hw(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if (i >= count.x) {
        return;
    }
    values[i] = sample_fast_bspline_hw(volume, linear_clamp, points[i].xyz, textureDimensions(volume)).x;
}
