// Clipping meshes on the GPU: the inside segments of every pixel's ray.
// The twin of src/cpu/clipmesh.rs (intersect_triangle, lex_less, make_segments); the
// module docs of src/gpu/clipmesh.rs explain the passes and what f32 changes. The rays
// are shared/camera.wgsl's camera_ray, the same rays as shaders/raycast.wgsl.
//
// Two entry points, one bind group:
// - clip_hits: tests triangles against the pixel's ray and merges the hits into the
//   pixel's state (hits at or before t_min only counted; the KEEP smallest beyond it
//   kept sorted, with their count and maximum): the candidates of a walk of the
//   mesh's bounding-volume hierarchy, NODES_PER_DISPATCH nodes per dispatch (the
//   pixel's place in the walk kept in its state), or, without the hierarchy, the
//   triangles [chunk.x, chunk.y) (a chunk costs at most CHUNK · (1 + KEEP) loop
//   iterations). Either way every invocation stays under llvmpipe's 65535.
// - clip_segments: pairs the boundaries into at most MAX_SEGMENTS segments.

#import raycast_params
#import camera

const MAX_SEGMENTS: u32 = 8u;
// 2 · MAX_SEGMENTS: enough boundaries for every segment and the merged eighth one.
const KEEP: u32 = 16u;
// Words of state per pixel: behind count, forward count, largest forward hit, the
// next node of the hierarchy's walk, then KEEP sorted hits (f32 bits).
const STATE_WORDS: u32 = 20u;
// vec4s of output per pixel: (count, 0, 0, 0), then four of (a₀, b₀, a₁, b₁).
const SEGMENT_VEC4S: u32 = 5u;
const OPEN_END: f32 = 3.0e38;

struct ClipChunk {
    // First triangle, one past the last, 1 on the first chunk (reset the state), and
    // the number of hierarchy nodes: 0 tests the triangles [x, y); otherwise the pixel
    // walks the hierarchy for at most NODES_PER_DISPATCH nodes from where it stopped.
    range: vec4<u32>,
}

// Nodes a pixel visits per dispatch: each costs at most 1 + LEAF · (1 + KEEP) loop
// iterations (LEAF = 4), so a dispatch stays under llvmpipe's 65535.
const NODES_PER_DISPATCH: u32 = 512u;

@group(0) @binding(0) var<uniform> params: RaycastParams;
@group(0) @binding(1) var<uniform> chunk: ClipChunk;
// Three corners per triangle, world mm (w unused).
@group(0) @binding(2) var<storage, read> triangles: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> state: array<u32>;
@group(0) @binding(4) var<storage, read_write> segments: array<vec4<f32>>;
// The hierarchy (src/cpu/clipmesh.rs: ClipTriangles::flat_hierarchy), two vec4s a node:
// (lo.xyz, bits of the index past its subtree), (hi.xyz, bits of first · 8 + count);
// count 0 for an interior node, whose first child is the next node. The triangles are
// stored in the hierarchy's leaf order.
@group(0) @binding(5) var<storage, read> nodes: array<vec4<f32>>;

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

// Whether the line o + d·t (any t) crosses the box [lo, hi]: the slab test, an axis
// the line runs parallel to checked directly (the closure `crosses` of
// src/cpu/clipmesh.rs: Bvh::for_each_candidate).
fn line_crosses_box(o: vec3<f32>, d: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>) -> bool {
    var near = -OPEN_END;
    var far = OPEN_END;
    for (var a = 0u; a < 3u; a++) {
        let da = comp(d, a);
        let oa = comp(o, a);
        if (da == 0.0) {
            if (oa < comp(lo, a) || oa > comp(hi, a)) {
                return false;
            }
        } else {
            let t1 = (comp(lo, a) - oa) / da;
            let t2 = (comp(hi, a) - oa) / da;
            near = max(near, min(t1, t2));
            far = min(far, max(t1, t2));
        }
    }
    return near <= far;
}

// Tests triangle tri against the ray and merges a hit into the pixel's state.
fn add_hit(ray: Ray, tri: u32, behind: ptr<function, u32>, count: ptr<function, u32>, tmax: ptr<function, f32>, h: ptr<function, array<f32, 16>>) {
    let hit = intersect_triangle(ray.origin, ray.dir, triangles[3u * tri].xyz, triangles[3u * tri + 1u].xyz, triangles[3u * tri + 2u].xyz);
    if (hit.x == 0.0) {
        return;
    }
    let t = hit.y;
    if (t <= ray.t_min) {
        *behind += 1u;
        return;
    }
    // Insertion into the KEEP smallest, sorted.
    *tmax = max(*tmax, t);
    var j = min(*count, KEEP - 1u);
    *count += 1u;
    if (*count > KEEP && t >= (*h)[KEEP - 1u]) {
        return;
    }
    while (j > 0u && (*h)[j - 1u] > t) {
        (*h)[j] = (*h)[j - 1u];
        j -= 1u;
    }
    (*h)[j] = t;
}

// The pixel of the ray caster's tile (params.tile) an invocation serves, -1 past it.
fn pixel_of(id: vec3<u32>) -> i32 {
    if (id.x >= params.tile.z || id.y >= params.tile.w) {
        return -1;
    }
    return i32(id.y * params.tile.z + id.x);
}

@compute @workgroup_size(8, 8)
fn clip_hits(@builtin(global_invocation_id) id: vec3<u32>) {
    let pix = pixel_of(id);
    if (pix < 0) {
        return;
    }
    let base = u32(pix) * STATE_WORDS;
    let first = chunk.range.z == 1u;
    let n_nodes = chunk.range.w;
    // Where this pixel's walk of the hierarchy stopped; past the end, it is done.
    var node = 0u;
    if (!first) {
        node = state[base + 3u];
        if (n_nodes > 0u && node >= n_nodes) {
            return;
        }
    }
    let ray = camera_ray(params.tile.x + id.x, params.tile.y + id.y);
    var behind = 0u;
    var count = 0u;
    var tmax = -OPEN_END;
    var h: array<f32, 16>;
    if (!first) {
        behind = state[base];
        count = state[base + 1u];
        tmax = bitcast<f32>(state[base + 2u]);
        for (var i = 0u; i < KEEP; i++) {
            h[i] = bitcast<f32>(state[base + 4u + i]);
        }
    }
    if (n_nodes == 0u) {
        for (var tri = chunk.range.x; tri < chunk.range.y; tri++) {
            add_hit(ray, tri, &behind, &count, &tmax, &h);
        }
    } else {
        // Stackless: into a node whose box the line crosses (its first child, or its
        // triangles for a leaf, then the next node), past its subtree otherwise.
        for (var visited = 0u; visited < NODES_PER_DISPATCH && node < n_nodes; visited++) {
            let a = nodes[2u * node];
            let b = nodes[2u * node + 1u];
            if (!line_crosses_box(ray.origin, ray.dir, a.xyz, b.xyz)) {
                node = bitcast<u32>(a.w);
                continue;
            }
            let leaf = bitcast<u32>(b.w);
            let n_tri = leaf & 7u;
            for (var tri = leaf >> 3u; tri < (leaf >> 3u) + n_tri; tri++) {
                add_hit(ray, tri, &behind, &count, &tmax, &h);
            }
            node += 1u;
        }
    }
    state[base + 3u] = node;
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
    let ray = camera_ray(params.tile.x + id.x, params.tile.y + id.y);
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
