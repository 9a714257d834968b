// Joseph forward projection of a voxel grid, one invocation per detector pixel.
// Mirrors src/cpu/project.rs: project_volume (per pixel: pixel_ray, then joseph_ray);
// the host side is src/gpu/project.rs.

#import project_params

@group(0) @binding(0) var<uniform> p: ProjectParams;
@group(0) @binding(1) var<storage, read> views: array<JosephView>;
// [z][y][x]
@group(0) @binding(2) var<storage, read> vol: array<f32>;
// [view − view_offset][row][col]
@group(0) @binding(3) var<storage, read_write> out: array<f32>;

const WORKGROUP: u32 = 64u;

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

// Bilinear interpolation, continued by zeros, of the index plane starting at `base`.
// mirrors src/cpu/project.rs: slice_bilinear
fn slice_bilinear(base: u32, sa: u32, na: u32, sb: u32, nb: u32, x: f32, y: f32) -> f32 {
    let fx = floor(x);
    let fy = floor(y);
    if !(fx >= -1.0 && fx < f32(na) && fy >= -1.0 && fy < f32(nb)) {
        return 0.0;
    }
    let tx = x - fx;
    let ty = y - fy;
    let ix = i32(fx);
    let iy = i32(fy);
    var tap: array<f32, 4>;
    for (var q = 0; q < 4; q++) {
        let i = ix + (q & 1);
        let j = iy + (q >> 1u);
        if i < 0 || j < 0 || i >= i32(na) || j >= i32(nb) {
            tap[q] = 0.0;
        } else {
            tap[q] = vol[base + u32(i) * sa + u32(j) * sb];
        }
    }
    let top = tap[0] * (1.0 - tx) + tap[1] * tx;
    let bottom = tap[2] * (1.0 - tx) + tap[3] * tx;
    return top * (1.0 - ty) + bottom * ty;
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

// Joseph's line integral along o + t·d, t ≥ t_min (index frame, |d| = 1 world mm).
// mirrors src/cpu/project.rs: joseph_ray
fn joseph_ray(o3: vec3<f32>, d3: vec3<f32>, t_min: f32) -> f32 {
    let o = array<f32, 3>(o3.x, o3.y, o3.z);
    let d = array<f32, 3>(d3.x, d3.y, d3.z);
    let dims = array<u32, 3>(p.nx, p.ny, p.nz);
    let stride = array<u32, 3>(1u, p.nx, p.nx * p.ny);
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
        return 0.0;
    }
    let inv = 1.0 / d[m];
    let ka = d[a] * inv;
    let kb = d[b] * inv;
    let xa0 = o[a] - o[m] * ka;
    let xb0 = o[b] - o[m] * kb;
    var range = vec2<f32>(0.0, f32(dims[m] - 1u));
    if !clip_planes(xa0, ka, dims[a], &range) || !clip_planes(xb0, kb, dims[b], &range) {
        return 0.0;
    }
    let s_min = o[m] + t_min * d[m];
    if d[m] > 0.0 {
        range.x = max(range.x, s_min);
    } else {
        range.y = min(range.y, s_min);
    }
    if range.x > range.y {
        return 0.0;
    }
    let s0 = u32(ceil(range.x));
    let s1 = u32(floor(range.y));
    var sum = 0.0;
    for (var s = s0; s <= s1; s++) {
        let sr = f32(s);
        sum += slice_bilinear(s * stride[m], stride[a], dims[a], stride[b], dims[b],
                              xa0 + sr * ka, xb0 + sr * kb);
    }
    return sum * abs(inv);
}

@compute @workgroup_size(WORKGROUP)
fn project(@builtin(global_invocation_id) gid: vec3<u32>) {
    let id = gid.x + gid.y * p.row_stride;
    let per_view = p.cols * p.rows;
    if id >= p.n_views * per_view {
        return;
    }
    let k = id / per_view;
    let rem = id % per_view;
    let r = pixel_ray(views[p.view_offset + k], f32(rem % p.cols), f32(rem / p.cols));
    out[id] = joseph_ray(r.o, r.d, r.t_min);
}
