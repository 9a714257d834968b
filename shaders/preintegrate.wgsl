// The pre-integrated transfer function: one invocation per table entry (front i, back
// j), the twin of src/cpu/preintegrate.rs (see its module docs for the definition).

#import adaptive_params
#import opacity

@group(0) @binding(0) var<uniform> params: AdaptiveParams;
@group(0) @binding(1) var<storage, read> lut: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> table: array<vec4<f32>>;

const SUBSTEPS_PER_CELL: u32 = 8u;

// mirrors src/cpu/preintegrate.rs: lut_at
fn lut_at(x_in: f32) -> vec4<f32> {
    let n = arrayLength(&lut);
    let x = min(max(x_in, 0.0), f32(n - 1u));
    let i0f = floor(x);
    let f = x - i0f;
    let i0 = min(u32(i0f), n - 1u);
    let i1 = min(i0 + 1u, n - 1u);
    let a = lut[i0];
    let b = lut[i1];
    return a + f * (b - a);
}

// mirrors src/cpu/preintegrate.rs: preint_entry
fn preint_entry(xf: f32, xb: f32) -> vec4<f32> {
    let cells = u32(ceil(abs(xb - xf)));
    let k = SUBSTEPS_PER_CELL * (cells + 1u);
    let inv_k = 1.0 / f32(k);
    var c = vec3<f32>(0.0);
    var a = 0.0;
    for (var m = 0u; m < k; m++) {
        let x = xf + (xb - xf) * ((f32(m) + 0.5) * inv_k);
        let s = lut_at(x);
        if (s.w <= 0.0) {
            continue;
        }
        let alpha = step_opacity(s.w, inv_k);
        let w = (1.0 - a) * alpha;
        c = c + w * s.xyz;
        a = a + w;
    }
    return vec4<f32>(c, a);
}

@compute @workgroup_size(8, 8, 1)
fn preintegrate(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = params.table.x;
    if (gid.x >= n || gid.y >= n) {
        return;
    }
    table[gid.y * n + gid.x] = preint_entry(f32(gid.x), f32(gid.y));
}
