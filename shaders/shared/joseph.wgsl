// Joseph's rays on the GPU: a detector pixel's ray in the grid's index frame, the
// planes of Joseph's sum along it and one voxel's weight in that sum. The forward
// projector (shaders/project.wgsl) and its transpose (shaders/joseph_pair_transpose.wgsl)
// both start from joseph_planes, so they use the very same numbers.
// Reads nothing of the stage; needs JosephView (#import project_params).

struct Ray {
    o: vec3<f32>,
    d: vec3<f32>,
    t_min: f32,
}

// mirrors src/cpu/project.rs: pixel_ray
fn pixel_ray(v: JosephView, col: f32, row: f32) -> Ray {
    let o = v.a0.xyz + col * v.a_u.xyz + row * v.a_v.xyz;
    let e = v.d0.xyz + col * v.d_u.xyz + row * v.d_v.xyz;
    let w = v.w0.xyz + col * v.w_u.xyz + row * v.w_v.xyz;
    let inv_len = 1.0 / sqrt(w.x * w.x + w.y * w.y + w.z * w.z);
    return Ray(o, e * inv_len, v.a0.w);
}

// Narrows [lo, hi] (x, y of `range`) to where x0 + s·k lies in (−1, n).
// mirrors src/cpu/project.rs: clip_planes
fn clip_planes(x0: f32, k: f32, n: u32, range: ptr<function, vec2<f32>>) -> bool {
    let nf = f32(n);
    if abs(k) > 1e-20 {
        let s1 = (-1.0 - x0) / k;
        let s2 = (nf - x0) / k;
        (*range).x = max((*range).x, min(s1, s2));
        (*range).y = min((*range).y, max(s1, s2));
    } else if !(x0 > -1.0 && x0 < nf) {
        return false;
    }
    return (*range).x <= (*range).y;
}

// Where a ray meets the grid: driving axis m, in-plane axes a, b, in-plane
// coordinates x_a(s) = xa0 + s·ka, x_b(s) = xb0 + s·kb on plane s, the planes
// s0..=s1, the world length w between two planes; hit = false when it takes no sample.
struct Planes {
    hit: bool,
    m: u32,
    a: u32,
    b: u32,
    xa0: f32,
    ka: f32,
    xb0: f32,
    kb: f32,
    s0: u32,
    s1: u32,
    w: f32,
}

// The planes of Joseph's sum for o + t·d, t ≥ t_min (index frame, |d| = 1 world mm).
// mirrors src/cpu/project.rs: joseph_planes
fn joseph_planes(dims: vec3<u32>, o3: vec3<f32>, d3: vec3<f32>, t_min: f32) -> Planes {
    var none: Planes;
    none.hit = false;
    let o = array<f32, 3>(o3.x, o3.y, o3.z);
    let d = array<f32, 3>(d3.x, d3.y, d3.z);
    let n = array<u32, 3>(dims.x, dims.y, dims.z);
    let ad = abs(d3);
    var m = 2u;
    var a = 0u;
    var b = 1u;
    if ad.x >= ad.y && ad.x >= ad.z {
        m = 0u;
        a = 1u;
        b = 2u;
    } else if ad.y >= ad.z {
        m = 1u;
        a = 0u;
        b = 2u;
    }
    if ad[m] == 0.0 {
        return none;
    }
    let inv = 1.0 / d[m];
    let ka = d[a] * inv;
    let kb = d[b] * inv;
    let xa0 = o[a] - o[m] * ka;
    let xb0 = o[b] - o[m] * kb;
    var range = vec2<f32>(0.0, f32(n[m] - 1u));
    if !clip_planes(xa0, ka, n[a], &range) || !clip_planes(xb0, kb, n[b], &range) {
        return none;
    }
    let s_min = o[m] + t_min * d[m];
    if d[m] > 0.0 {
        range.x = max(range.x, s_min);
    } else {
        range.y = min(range.y, s_min);
    }
    if range.x > range.y {
        return none;
    }
    let s0 = u32(ceil(range.x));
    let s1 = u32(floor(range.y));
    if s0 > s1 {
        return none;
    }
    return Planes(true, m, a, b, xa0, ka, xb0, kb, s0, s1, abs(inv));
}

// The bilinear tap weight of index i at coordinate x: 1 − t at floor(x), t after it.
fn tap_weight(x: f32, i: u32) -> f32 {
    let f = floor(x);
    let t = x - f;
    let fi = f32(i);
    if f == fi {
        return 1.0 - t;
    }
    if f == fi - 1.0 {
        return t;
    }
    return 0.0;
}

// The weight of voxel `v` in Joseph's sum along the ray of `pl`.
// mirrors src/cpu/project.rs: joseph_weight
fn joseph_weight(pl: Planes, v: vec3<u32>) -> f32 {
    let c = array<u32, 3>(v.x, v.y, v.z);
    let s = c[pl.m];
    if !pl.hit || s < pl.s0 || s > pl.s1 {
        return 0.0;
    }
    let sr = f32(s);
    let ha = tap_weight(pl.xa0 + sr * pl.ka, c[pl.a]);
    if ha == 0.0 {
        return 0.0;
    }
    return pl.w * ha * tap_weight(pl.xb0 + sr * pl.kb, c[pl.b]);
}
