// Fast tricubic B-spline filtering: the 64-tap cubic B-spline as 8 trilinear fetches
// (Sigg & Hadwiger 2005, GPU Gems 2 ch. 20). The twin of src/cpu/tricubic.rs, whose module
// docs derive the formula: per axis, with i = floor(x), f = x − i and the B-spline
// weights w0..w3 of the taps i − 1 … i + 2, the fetches lie at i − 1 + w1/g0 and
// i + 1 + w3/g1 with weights g0 = w0 + w1 and g1 = w2 + w3.
// Two variants: sample_fast_bspline does each trilinear fetch by hand (8 textureLoads,
// exact in f32), sample_fast_bspline_hw asks the texture unit (8 textureSampleLevel
// through a linear ClampToEdge sampler; real GPUs quantise its weights to ~8 bits).
// Straight-line code, no loops (llvmpipe's per-invocation loop budget, see raycast.wgsl).

// The fetches of all three axes at once: for axis d, the first voxels
// (base0[d], base1[d]), fractions (frac0[d], frac1[d]) and weights (g0[d], g1[d]).
struct FastAxes {
    base0: vec3<i32>,
    base1: vec3<i32>,
    frac0: vec3<f32>,
    frac1: vec3<f32>,
    g0: vec3<f32>,
    g1: vec3<f32>,
}

// mirrors src/cpu/tricubic.rs: fast_bspline_axis (the three axes of p together)
fn fast_bspline_axis(p: vec3<f32>) -> FastAxes {
    let fl = floor(p);
    let f = p - fl;
    let i = vec3<i32>(fl);
    let sixth = 1.0 / 6.0;
    let e = vec3<f32>(1.0) - f;
    let w0 = e * e * e * sixth;
    let w1 = (vec3<f32>(4.0) - 6.0 * f * f + 3.0 * f * f * f) * sixth;
    let w2 = (vec3<f32>(4.0) - 6.0 * e * e + 3.0 * e * e * e) * sixth;
    let w3 = f * f * f * sixth;
    let g0 = w0 + w1;
    let g1 = w2 + w3;
    return FastAxes(i - vec3<i32>(1), i + vec3<i32>(1), w1 / g0, w3 / g1, g0, g1);
}

fn tricubic_clamp(i: vec3<i32>, n: vec3<u32>) -> vec3<i32> {
    return clamp(i, vec3<i32>(0), vec3<i32>(n) - vec3<i32>(1));
}

// mirrors src/cpu/tricubic.rs: trilinear_fetch (voxels base … base + 1, clamped)
fn trilinear_fetch(t: texture_3d<f32>, base: vec3<i32>, frac: vec3<f32>, n: vec3<u32>) -> vec4<f32> {
    let a = tricubic_clamp(base, n);
    let b = tricubic_clamp(base + vec3<i32>(1), n);
    let x00 = (1.0 - frac.x) * textureLoad(t, vec3<i32>(a.x, a.y, a.z), 0) + frac.x * textureLoad(t, vec3<i32>(b.x, a.y, a.z), 0);
    let x10 = (1.0 - frac.x) * textureLoad(t, vec3<i32>(a.x, b.y, a.z), 0) + frac.x * textureLoad(t, vec3<i32>(b.x, b.y, a.z), 0);
    let x01 = (1.0 - frac.x) * textureLoad(t, vec3<i32>(a.x, a.y, b.z), 0) + frac.x * textureLoad(t, vec3<i32>(b.x, a.y, b.z), 0);
    let x11 = (1.0 - frac.x) * textureLoad(t, vec3<i32>(a.x, b.y, b.z), 0) + frac.x * textureLoad(t, vec3<i32>(b.x, b.y, b.z), 0);
    let y0 = (1.0 - frac.y) * x00 + frac.y * x10;
    let y1 = (1.0 - frac.y) * x01 + frac.y * x11;
    return (1.0 - frac.z) * y0 + frac.z * y1;
}

// The texture unit's trilinear fetch at index coordinate c (voxel centres at integers).
fn trilinear_fetch_hw(t: texture_3d<f32>, s: sampler, c: vec3<f32>, n: vec3<u32>) -> vec4<f32> {
    return textureSampleLevel(t, s, (c + vec3<f32>(0.5)) / vec3<f32>(n), 0.0);
}

// mirrors src/cpu/tricubic.rs: sample_fast (8 exact trilinear fetches, summed x
// innermost, then y, then z)
fn sample_fast_bspline(t: texture_3d<f32>, p: vec3<f32>, n: vec3<u32>) -> vec4<f32> {
    let a = fast_bspline_axis(p);
    let v000 = trilinear_fetch(t, vec3<i32>(a.base0.x, a.base0.y, a.base0.z), vec3<f32>(a.frac0.x, a.frac0.y, a.frac0.z), n);
    let v100 = trilinear_fetch(t, vec3<i32>(a.base1.x, a.base0.y, a.base0.z), vec3<f32>(a.frac1.x, a.frac0.y, a.frac0.z), n);
    let v010 = trilinear_fetch(t, vec3<i32>(a.base0.x, a.base1.y, a.base0.z), vec3<f32>(a.frac0.x, a.frac1.y, a.frac0.z), n);
    let v110 = trilinear_fetch(t, vec3<i32>(a.base1.x, a.base1.y, a.base0.z), vec3<f32>(a.frac1.x, a.frac1.y, a.frac0.z), n);
    let v001 = trilinear_fetch(t, vec3<i32>(a.base0.x, a.base0.y, a.base1.z), vec3<f32>(a.frac0.x, a.frac0.y, a.frac1.z), n);
    let v101 = trilinear_fetch(t, vec3<i32>(a.base1.x, a.base0.y, a.base1.z), vec3<f32>(a.frac1.x, a.frac0.y, a.frac1.z), n);
    let v011 = trilinear_fetch(t, vec3<i32>(a.base0.x, a.base1.y, a.base1.z), vec3<f32>(a.frac0.x, a.frac1.y, a.frac1.z), n);
    let v111 = trilinear_fetch(t, vec3<i32>(a.base1.x, a.base1.y, a.base1.z), vec3<f32>(a.frac1.x, a.frac1.y, a.frac1.z), n);
    let y0 = a.g0.y * (a.g0.x * v000 + a.g1.x * v100) + a.g1.y * (a.g0.x * v010 + a.g1.x * v110);
    let y1 = a.g0.y * (a.g0.x * v001 + a.g1.x * v101) + a.g1.y * (a.g0.x * v011 + a.g1.x * v111);
    return a.g0.z * y0 + a.g1.z * y1;
}

// The same 8 fetches through the texture unit (hardware_filtering): fetch points
// base + frac in index coordinates (src/cpu/tricubic.rs: fetch_points).
fn sample_fast_bspline_hw(t: texture_3d<f32>, s: sampler, p: vec3<f32>, n: vec3<u32>) -> vec4<f32> {
    let a = fast_bspline_axis(p);
    let c0 = vec3<f32>(a.base0) + a.frac0;
    let c1 = vec3<f32>(a.base1) + a.frac1;
    let v000 = trilinear_fetch_hw(t, s, vec3<f32>(c0.x, c0.y, c0.z), n);
    let v100 = trilinear_fetch_hw(t, s, vec3<f32>(c1.x, c0.y, c0.z), n);
    let v010 = trilinear_fetch_hw(t, s, vec3<f32>(c0.x, c1.y, c0.z), n);
    let v110 = trilinear_fetch_hw(t, s, vec3<f32>(c1.x, c1.y, c0.z), n);
    let v001 = trilinear_fetch_hw(t, s, vec3<f32>(c0.x, c0.y, c1.z), n);
    let v101 = trilinear_fetch_hw(t, s, vec3<f32>(c1.x, c0.y, c1.z), n);
    let v011 = trilinear_fetch_hw(t, s, vec3<f32>(c0.x, c1.y, c1.z), n);
    let v111 = trilinear_fetch_hw(t, s, vec3<f32>(c1.x, c1.y, c1.z), n);
    let y0 = a.g0.y * (a.g0.x * v000 + a.g1.x * v100) + a.g1.y * (a.g0.x * v010 + a.g1.x * v110);
    let y1 = a.g0.y * (a.g0.x * v001 + a.g1.x * v101) + a.g1.y * (a.g0.x * v011 + a.g1.x * v111);
    return a.g0.z * y0 + a.g1.z * y1;
}
