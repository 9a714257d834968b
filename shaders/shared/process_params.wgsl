// Parameters of one dispatch of the volume-processing shaders (shaders/process_*.wgsl),
// their bindings and the index helpers they share. Rust twin: src/gpu/process.rs:
// ProcessParams (#[repr(C)], bytemuck). Six 16-byte vectors, no padding (96 bytes);
// tests/gpu_layout.rs checks the offsets with naga.

struct ProcessParams {
    // The input grid: nx, ny, nz, and the first of its slices the src buffer holds (a
    // slab of the input; 0 when it holds them all).
    in_dims: vec4<u32>,
    // The output grid: nx, ny, nz, and the first output voxel (linear index) of this
    // dispatch.
    out_dims: vec4<u32>,
    // x: filter code (resample) or window side k (median); y: kernel radius (Lanczos
    // order, Gaussian radius); z: axis (Gaussian pass), or the first output voxel the
    // dst buffer holds (resample: a slab of the output); w: voxels in this dispatch.
    op: vec4<u32>,
    // Rows of a 3 × 4 matrix: the output-index → input-index map (resample), or the
    // index → world gradient map L⁻ᵀ (gradient magnitude; w unused).
    m0: vec4<f32>,
    m1: vec4<f32>,
    m2: vec4<f32>,
}

const WORKGROUP: u32 = 64u;

@group(0) @binding(0) var<uniform> params: ProcessParams;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read_write> dst: array<f32>;

// The output voxel of invocation `gid` (2-D dispatch, WORKGROUP × groups_x wide), or
// false when it lies past this dispatch's voxels.
fn output_voxel(gid: vec3<u32>, nwg: vec3<u32>, out: ptr<function, vec3<u32>>) -> bool {
    let local = gid.x + gid.y * nwg.x * WORKGROUP;
    if local >= params.op.w {
        return false;
    }
    let n = params.out_dims.w + local;
    let nx = params.out_dims.x;
    let ny = params.out_dims.y;
    *out = vec3<u32>(n % nx, (n / nx) % ny, n / (nx * ny));
    return true;
}

fn out_index(v: vec3<u32>) -> u32 {
    return v.x + params.out_dims.x * (v.y + params.out_dims.y * v.z);
}

// The clamp-to-edge index of i on an axis of n voxels (the CPU's Grid::at_clamped).
fn clamped(i: i32, n: u32) -> u32 {
    return u32(clamp(i, 0, i32(n) - 1));
}

// Voxel (i, j, k) of the input grid, k within the slices the src buffer holds.
fn in_at(i: u32, j: u32, k: u32) -> f32 {
    return src[i + params.in_dims.x * (j + params.in_dims.y * (k - params.in_dims.w))];
}

// scipy's 'reflect' rule: d c b a | a b c d | d c b a (period 2n).
// Mirrors src/cpu/process.rs: reflect_index.
fn reflect_index(i: i32, n: u32) -> u32 {
    let p = 2 * i32(n);
    var m = i % p;
    if m < 0 {
        m = m + p;
    }
    if m >= i32(n) {
        return u32(p - 1 - m);
    }
    return u32(m);
}
