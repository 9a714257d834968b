// Clipping meshes on the GPU: the inside segments of every pixel's ray.
// Mirrors src/cpu/clipmesh.rs (intersect_triangle, lex_less, make_segments); the
// module docs of src/gpu/clipmesh.rs explain the passes and what f32 changes.
// Prepended at load time: shaders/shared/raycast_params.wgsl and rays.wgsl
// (camera_ray, the same rays as shaders/raycast.wgsl).
//
// Two entry points, one bind group:
// - clip_hits: tests the triangles [chunk.x, chunk.y) against the pixel's ray and
//   merges the hits into the pixel's state (hits at or before t_min only counted;
//   the KEEP smallest beyond it kept sorted, with their count and maximum). One
//   dispatch per chunk of triangles keeps every invocation under llvmpipe's 65535
//   loop iterations (a chunk costs at most CHUNK · (1 + KEEP) iterations).
// - clip_segments: pairs the boundaries into at most MAX_SEGMENTS segments.

const MAX_SEGMENTS: u32 = 8u;
// 2 · MAX_SEGMENTS: enough boundaries for every segment and the merged eighth one.
const KEEP: u32 = 16u;
// Words of state per pixel: behind count, forward count, largest forward hit, unused,
// then KEEP sorted hits (f32 bits).
const STATE_WORDS: u32 = 20u;
// vec4s of output per pixel: (count, 0, 0, 0), then four of (a₀, b₀, a₁, b₁).
const SEGMENT_VEC4S: u32 = 5u;
const OPEN_END: f32 = 3.0e38;

struct ClipChunk {
    // First triangle, one past the last, 1 on the first chunk (reset the state), unused.
    range: vec4<u32>,
}

@group(0) @binding(0) var<uniform> params: RaycastParams;
@group(0) @binding(1) var<uniform> chunk: ClipChunk;
// Three corners per triangle, world mm (w unused).
@group(0) @binding(2) var<storage, read> triangles: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> state: array<u32>;
@group(0) @binding(4) var<storage, read_write> segments: array<vec4<f32>>;

// mirrors src/cpu/clipmesh.rs: lex_less
fn lex_less(p: vec3<f32>, q: vec3<f32>) -> bool {
    if (p.x != q.x) {
        return p.x < q.x;
    } else if (p.y != q.y) {
        return p.y < q.y;
    }
    return p.z < q.z;
}

fn comp(v: vec3<f32>, k: u32) -> f32 {
    if (k == 0u) {
        return v.x;
    } else if (k == 1u) {
        return v.y;
    }
    return v.z;
}

// mirrors src/cpu/clipmesh.rs: intersect_triangle (watertight test, edge rule); in f32.
// Returns (hit, t) with hit = 1 or 0.
fn intersect_triangle(o: vec3<f32>, d: vec3<f32>, p0: vec3<f32>, p1: vec3<f32>, p2: vec3<f32>) -> vec2<f32> {
    let ad = abs(d);
    var kz = 2u;
    if (ad.x > ad.y) {
        if (ad.x > ad.z) {
            kz = 0u;
        }
    } else if (ad.y > ad.z) {
        kz = 1u;
    }
    var kx = (kz + 1u) % 3u;
    var ky = (kx + 1u) % 3u;
    let dkz = comp(d, kz);
    if (dkz < 0.0) {
        let tmp = kx;
        kx = ky;
        ky = tmp;
    }
    let sx = comp(d, kx) / dkz;
    let sy = comp(d, ky) / dkz;
    let a = p0 - o;
    let b = p1 - o;
    let c = p2 - o;
    let ax = comp(a, kx) - sx * comp(a, kz);
    let ay = comp(a, ky) - sy * comp(a, kz);
    let bx = comp(b, kx) - sx * comp(b, kz);
    let by = comp(b, ky) - sy * comp(b, kz);
    let cx = comp(c, kx) - sx * comp(c, kz);
    let cy = comp(c, ky) - sy * comp(c, kz);
    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    if ((u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0)) {
        return vec2<f32>(0.0);
    }
    let det = u + v + w;
    if (det == 0.0) {
        return vec2<f32>(0.0);
    }
    // Edge rule for edge functions exactly zero: U is edge B→C, V is C→A, W is A→B.
    let s = det > 0.0;
    if ((u == 0.0 && lex_less(p1, p2) != s) || (v == 0.0 && lex_less(p2, p0) != s) || (w == 0.0 && lex_less(p0, p1) != s)) {
        return vec2<f32>(0.0);
    }
    let t = (u * comp(a, kz) + v * comp(b, kz) + w * comp(c, kz)) / (det * dkz);
    // is_finite
    if (!(abs(t) <= 3.4e38)) {
        return vec2<f32>(0.0);
    }
    return vec2<f32>(1.0, t);
}

fn pixel_of(id: vec3<u32>) -> i32 {
    if (id.x >= params.image.x || id.y >= params.flags2.w) {
        return -1;
    }
    return i32(id.y * params.image.x + id.x);
}

@compute @workgroup_size(8, 8)
fn clip_hits(@builtin(global_invocation_id) id: vec3<u32>) {
    let pix = pixel_of(id);
    if (pix < 0) {
        return;
    }
    let ray = camera_ray(id.x, params.flags2.z + id.y);
    let base = u32(pix) * STATE_WORDS;
    var behind = 0u;
    var count = 0u;
    var tmax = -OPEN_END;
    var h: array<f32, 16>;
    if (chunk.range.z == 0u) {
        behind = state[base];
        count = state[base + 1u];
        tmax = bitcast<f32>(state[base + 2u]);
        for (var i = 0u; i < KEEP; i++) {
            h[i] = bitcast<f32>(state[base + 4u + i]);
        }
    }
    for (var tri = chunk.range.x; tri < chunk.range.y; tri++) {
        let hit = intersect_triangle(ray.origin, ray.dir, triangles[3u * tri].xyz, triangles[3u * tri + 1u].xyz, triangles[3u * tri + 2u].xyz);
        if (hit.x == 0.0) {
            continue;
        }
        let t = hit.y;
        if (t <= ray.t_min) {
            behind += 1u;
            continue;
        }
        // Insertion into the KEEP smallest, sorted.
        tmax = max(tmax, t);
        var j = min(count, KEEP - 1u);
        count += 1u;
        if (count > KEEP && t >= h[KEEP - 1u]) {
            continue;
        }
        while (j > 0u && h[j - 1u] > t) {
            h[j] = h[j - 1u];
            j -= 1u;
        }
        h[j] = t;
    }
    state[base] = behind;
    state[base + 1u] = count;
    state[base + 2u] = bitcast<u32>(tmax);
    for (var i = 0u; i < KEEP; i++) {
        state[base + 4u + i] = bitcast<u32>(h[i]);
    }
}

// Boundary i of b = [t0 if behind is odd] ++ forward hits (see make_segments).
fn boundary(i: u32, odd: u32, t0: f32, h: ptr<function, array<f32, 16>>) -> f32 {
    if (odd == 1u) {
        if (i == 0u) {
            return t0;
        }
        return (*h)[i - 1u];
    }
    return (*h)[i];
}

// mirrors src/cpu/clipmesh.rs: make_segments (pairing by parity, the merge beyond
// MAX_SEGMENTS); the forward hits are the KEEP smallest, their count and maximum.
@compute @workgroup_size(8, 8)
fn clip_segments(@builtin(global_invocation_id) id: vec3<u32>) {
    let pix = pixel_of(id);
    if (pix < 0) {
        return;
    }
    let ray = camera_ray(id.x, params.flags2.z + id.y);
    let base = u32(pix) * STATE_WORDS;
    let behind = state[base];
    let count = state[base + 1u];
    let tmax = bitcast<f32>(state[base + 2u]);
    var h: array<f32, 16>;
    for (var i = 0u; i < KEEP; i++) {
        h[i] = bitcast<f32>(state[base + 4u + i]);
    }
    let odd = behind % 2u;
    let nb = count + odd;
    let pairs = (nb + 1u) / 2u;
    var seg: array<vec2<f32>, 8>;
    let kept = min(pairs, MAX_SEGMENTS);
    for (var i = 0u; i < kept; i++) {
        var b = OPEN_END;
        if (2u * i + 1u < nb) {
            b = boundary(2u * i + 1u, odd, ray.t_min, &h);
        }
        seg[i] = vec2<f32>(boundary(2u * i, odd, ray.t_min, &h), b);
    }
    if (pairs > MAX_SEGMENTS) {
        var last = tmax;
        if (nb % 2u == 1u) {
            last = OPEN_END;
        }
        seg[MAX_SEGMENTS - 1u] = vec2<f32>(boundary(2u * (MAX_SEGMENTS - 1u), odd, ray.t_min, &h), last);
    }
    let out = u32(pix) * SEGMENT_VEC4S;
    segments[out] = vec4<f32>(f32(kept), 0.0, 0.0, 0.0);
    for (var i = 0u; i < 4u; i++) {
        segments[out + 1u + i] = vec4<f32>(seg[2u * i], seg[2u * i + 1u]);
    }
}
