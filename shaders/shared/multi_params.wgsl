// Parameters of one multi-volume ray-casting dispatch (shaders/multi.wgsl).
// Rust twin: src/gpu/multi.rs: MultiParams (#[repr(C)], bytemuck). Every member is a
// 16-byte vector or an array of them, so both sides agree without padding rules;
// tests/gpu_layout.rs checks the offsets with naga. The camera, shading and image
// members carry the names and meanings of RaycastParams, so camera_ray
// (shaders/shared/camera.wgsl) and phong (shaders/shared/shading.wgsl) read them
// unchanged.

struct MultiParams {
    // Camera in world space (mm), as RaycastParams: eye.w = 1 perspective, 0 orthographic.
    eye: vec4<f32>,
    forward: vec4<f32>,
    right: vec4<f32>,
    up: vec4<f32>,
    background: vec4<f32>,
    // light.xyz = direction toward the light (unit); light.w = 1 directional, 0 headlight.
    light: vec4<f32>,
    // ambient, diffuse, specular, shininess.
    shading: vec4<f32>,
    // step (voxels of volume 0), reference step, early-ray-termination threshold, miss value.
    misc: vec4<f32>,
    // width, height, mode, filter (0 nearest, 1 trilinear).
    image: vec4<u32>,
    // volumes, back-to-front, unused ×2.
    flags: vec4<u32>,
    // Rows of volume i's world-to-index affine: to_index[3 i + r].
    to_index: array<vec4<f32>, 9>,
    // Rows of volume i's J⁻ᵀ (index-space gradient → world): normal[3 i + r].
    normal: array<vec4<f32>, 9>,
    // Box upper corner n − 0.5 per axis; w = the shading gradient threshold.
    box_hi: array<vec4<f32>, 3>,
    // LUT: raw value → table coordinate x = scale·t + offset; z = entries − 1;
    // w = the table's first entry in the shared LUT buffer.
    lut: array<vec4<f32>, 3>,
    // Volume dimensions; w = shade this volume (1/0).
    dims: array<vec4<u32>, 3>,
    // Gradient method (0 central, 1 forward), unused ×3.
    gradient: vec4<u32>,
    // Volume i's voxel held at texel 0 of its texture (a cell's part of the volume when
    // the render is split; 0 whole); w unused.
    origin: array<vec4<i32>, 3>,
    // The box of volume 0's index space whose step midpoints this pass takes,
    // own_lo <= p < own_hi (±f32 max on open faces; everything when not split).
    own_lo: vec4<f32>,
    own_hi: vec4<f32>,
    // x = 1: read and write each ray's carried state (a split render's cells);
    // y = 1: finish the pixels (the last cell, or not split); unused ×2.
    carry: vec4<u32>,
    // The pixels this dispatch casts: first column, first row, columns, rows (of the
    // frame image.xy; one invocation each, row-major in the output buffers).
    tile: vec4<u32>,
}
