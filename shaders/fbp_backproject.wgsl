// Backprojection for FBP and FDK: one invocation per VOXELS neighbouring voxels along k,
// a loop over a chunk of views.
// Rust twin: src/gpu/fbp.rs (dispatch), src/cpu/fbp.rs (the oracle). The geometry
// (CtView, project_point) is shared/ct_geometry.wgsl. The generated module
// fbp_projection (src/gpu/fbp.rs: projection_wgsl) binds the filtered projections at
// binding 2 and defines `fn projection(v: u32, x: f32, y: f32) -> f32`, view v of them
// at detector (col x, row y), zero outside the detector: exactly (a storage buffer and
// shared/ct_bilinear.wgsl's bilinear_zero) or through the texture unit (a 2-D texture
// array and a linear sampler at binding 4).

#import ct_geometry
#import fbp_params
#import fbp_projection

@group(0) @binding(0) var<uniform> params: FbpParams;
@group(0) @binding(1) var<storage, read> views: array<CtView>;
@group(0) @binding(3) var<storage, read_write> out_vol: array<f32>;

// Voxels one invocation backprojects: neighbours along k, which share the view's
// matrix and give the loop over views independent sums to overlap.
// Rust twin: src/gpu/fbp.rs: VOXELS_PER_INVOCATION.
const VOXELS: u32 = 4u;

// Adds this chunk's share of π/(2A)·Σ_k w_k·projection(k, col_k, row_k) to up to
// VOXELS voxels (i, j, k … k + VOXELS − 1), each summed exactly as alone.
// mirrors src/cpu/fbp.rs: backproject_point
@compute @workgroup_size(64)
fn backproject_point(@builtin(global_invocation_id) gid: vec3<u32>) {
    let idx = gid.x + gid.y * params.dims.w;
    let nx = params.dims.x;
    let ny = params.dims.y;
    let nz = params.dims.z;
    let runs = (nz + VOXELS - 1u) / VOXELS;
    if idx >= nx * ny * runs {
        return;
    }
    let i = f32(idx % nx);
    let j = f32((idx / nx) % ny);
    let k0 = (idx / (nx * ny)) * VOXELS;
    let held = min(VOXELS, nz - k0);
    // The slab's slices are the grid's slices slab.x …: the same voxel positions, bit
    // for bit, as the unsplit volume's.
    var p: array<vec3<f32>, 4>;
    for (var q = 0u; q < VOXELS; q++) {
        let k = f32(k0 + q + params.slab.x);
        p[q] = params.origin.xyz + i * params.step_i.xyz + j * params.step_j.xyz + k * params.step_k.xyz;
    }
    var acc = array<f32, 4>(0.0, 0.0, 0.0, 0.0);
    for (var v = params.det.z; v < params.det.z + params.det.w; v++) {
        let view = views[v];
        // The view's place among the projections bound (slab.y: the first bound).
        let held_view = v - params.slab.y;
        for (var q = 0u; q < VOXELS; q++) {
            let r = project_point(view, p[q]);
            if r.w > 0.0 {
                acc[q] += r.z * projection(held_view, r.x, r.y);
            }
        }
    }
    let first = idx % (nx * ny) + k0 * nx * ny;
    for (var q = 0u; q < held; q++) {
        out_vol[first + q * nx * ny] += acc[q] * params.scale.x;
    }
}
