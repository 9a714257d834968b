// The min/max grid of empty-space skipping: one workgroup per cell, 64 invocations
// stride through the cell's footprint and reduce in workgroup memory.
// Mirrors src/cpu/skip.rs: min_max_grid (footprint, the [min, max] per cell, x fastest).
// Rust twin of SkipGridParams: src/gpu/skip.rs (checked in tests/gpu_skip.rs).

struct SkipGridParams {
    // Volume dimensions (w unused).
    dims: vec4<u32>,
    // Cells per axis, block size in voxels.
    cells: vec4<u32>,
    // Filter radius, first cell row z of this dispatch.
    misc: vec4<u32>,
}

@group(0) @binding(0) var<uniform> gp: SkipGridParams;
@group(0) @binding(1) var volume: texture_3d<f32>;
@group(0) @binding(2) var<storage, read_write> minmax: array<vec2<f32>>;

var<workgroup> wmin: array<f32, 64>;
var<workgroup> wmax: array<f32, 64>;

// The voxels lo..=hi a sample in cell c can read.
// mirrors src/cpu/skip.rs: footprint
fn footprint(c: u32, n: u32, block: u32, radius: u32) -> vec2<u32> {
    var lo = 0u;
    if (c * block > radius + 1u) {
        lo = c * block - radius - 1u;
    }
    let hi = min((c + 1u) * block + radius, n - 1u);
    return vec2<u32>(lo, hi);
}

@compute @workgroup_size(64)
fn skip_minmax(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    let cell = vec3<u32>(wg.x, wg.y, wg.z + gp.misc.y);
    let b = gp.cells.w;
    let r = gp.misc.x;
    let fx = footprint(cell.x, gp.dims.x, b, r);
    let fy = footprint(cell.y, gp.dims.y, b, r);
    let fz = footprint(cell.z, gp.dims.z, b, r);
    let sx = fx.y - fx.x + 1u;
    let sy = fy.y - fy.x + 1u;
    let sz = fz.y - fz.x + 1u;
    let total = sx * sy * sz;
    var lo = 3.0e38;
    var hi = -3.0e38;
    for (var i = li; i < total; i += 64u) {
        let x = fx.x + i % sx;
        let y = fy.x + (i / sx) % sy;
        let z = fz.x + i / (sx * sy);
        let v = textureLoad(volume, vec3<i32>(i32(x), i32(y), i32(z)), 0).x;
        lo = min(lo, v);
        hi = max(hi, v);
    }
    wmin[li] = lo;
    wmax[li] = hi;
    workgroupBarrier();
    for (var s = 32u; s > 0u; s = s >> 1u) {
        if (li < s) {
            wmin[li] = min(wmin[li], wmin[li + s]);
            wmax[li] = max(wmax[li], wmax[li + s]);
        }
        workgroupBarrier();
    }
    if (li == 0u) {
        let idx = cell.x + gp.cells.x * (cell.y + gp.cells.y * cell.z);
        minmax[idx] = vec2<f32>(wmin[0], wmax[0]);
    }
}
