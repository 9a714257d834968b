// Parameters of one ray-casting dispatch.
// Rust twin: src/gpu/raycast.rs: RaycastParams (#[repr(C)], bytemuck). Every member is a
// 16-byte vector so both sides agree without padding rules; tests/gpu_layout.rs checks
// the offsets with naga.

struct RaycastParams {
    // Camera in world space (mm). eye.w = 1 for perspective, 0 for orthographic.
    eye: vec4<f32>,
    // forward.w = tan(fov_y / 2) (perspective).
    forward: vec4<f32>,
    // right.w = image width in mm (orthographic) or the aspect ratio (perspective).
    right: vec4<f32>,
    // up.w = image height in mm (orthographic).
    up: vec4<f32>,
    // Rows of the world-to-index affine (3×4).
    to_index_0: vec4<f32>,
    to_index_1: vec4<f32>,
    to_index_2: vec4<f32>,
    // Rows of J⁻ᵀ: index-space gradient to world-space gradient.
    normal_0: vec4<f32>,
    normal_1: vec4<f32>,
    normal_2: vec4<f32>,
    // Box upper corner n − 0.5 per axis; box_hi.w = step in voxels.
    box_hi: vec4<f32>,
    background: vec4<f32>,
    // light.xyz = direction toward the light (unit); light.w = 1 directional, 0 headlight.
    light: vec4<f32>,
    // ambient, diffuse, specular, shininess.
    shading: vec4<f32>,
    // reference step, early-ray-termination threshold, shading gradient threshold, miss value.
    misc: vec4<f32>,
    // LUT: raw value → table coordinate x = scale·t + offset; z = entries − 1.
    lut: vec4<f32>,
    // Volume dimensions (w unused).
    dims: vec4<u32>,
    // width, height, mode, filter.
    image: vec4<u32>,
    // pre-classification, shading, precomputed gradients, back-to-front.
    flags: vec4<u32>,
    // gradient method, hardware trilinear; zw unused.
    flags2: vec4<u32>,
    // 2D transfer function: value scale, value offset, nv − 1, ng − 1 (classify2d.wgsl).
    tf2d_a: vec4<f32>,
    // gradient scale, 1/g0, log axis (1/0), 2D transfer function on (1/0).
    tf2d_b: vec4<f32>,
    // Empty-space skipping on, jitter mode (0 none, 1 random, 2 interleaved), jitter
    // seed, clipping box (0 none, 1 index space, 2 world); see shaders/shared/skip.wgsl.
    accel: vec4<u32>,
    // Skipping cells per axis, block size in voxels.
    skip_cells: vec4<u32>,
    // Skipping: overshoot factor e, relative margin (src/cpu/skip.rs: OpacityPrefix).
    skip_tf: vec4<f32>,
    // Clipping box corners (index space or world mm, per accel.w).
    clip_lo: vec4<f32>,
    clip_hi: vec4<f32>,
    // MIDA gamma, lowest value, 1/(value range), unused (shaders/shared/modes.wgsl).
    mode_params: vec4<f32>,
    // MIP/MinIP grey window: width, centre, 1 when on, unused.
    window: vec4<f32>,
    // Iso-surfaces drawn, opaque, shadows, refine.
    iso_flags: vec4<u32>,
    // The iso-values.
    iso_values: vec4<f32>,
    // Colour (rgb) and opacity of each iso-surface.
    iso_color_0: vec4<f32>,
    iso_color_1: vec4<f32>,
    iso_color_2: vec4<f32>,
    iso_color_3: vec4<f32>,
    // Clipping mesh: x = 1 when on (segments per pixel, shaders/clipmesh.wgsl); yzw unused.
    clip_mesh: vec4<u32>,
    // A brick of a larger volume (src/gpu/raycast.rs: BrickPlacement): xyz its first
    // voxel's index in the whole volume, w = 1 when on; box_hi is then the whole
    // volume's, dims the brick's.
    brick: vec4<f32>,
    // The faces of the samples the brick owns, lo − 1/2 and hi − 1/2 in the whole
    // volume's index space (±3.4e38 at the volume's border); own_lo.w = 1 in a pass of
    // the shadow rays (shaders/shared/modes_cast.wgsl: shadow_pass).
    own_lo: vec4<f32>,
    own_hi: vec4<f32>,
    // The pixels of this dispatch (a tile of the image): first column, first row,
    // columns, rows.
    tile: vec4<u32>,
}
