// Empty-space skipping, the clipping box and jittered ray starts for the ray caster:
// the twins of src/cpu/skip.rs (range_empty, cell_empty, CellWalk, SampleRanges,
// ClipR::interval) and src/accumulate.rs (pcg_hash, jitter_offset, interleaved_offset);
// each helper names its Rust twin. Reads the ray caster's `params: RaycastParams`,
// `skip_minmax: array<vec2<f32>>` (one [min, max] per cell, x fastest) and
// `skip_prefix: array<u32>` (the LUT's prefix count of non-zero opacities).

#import rays

// ---------------------------------------------------------------- jitter
// mirrors src/cpu/jitter.rs: pcg_hash
fn pcg_hash(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// mirrors src/cpu/jitter.rs: jitter_offset (24 bits, exact in f32)
fn jitter_offset(seed: u32, col: u32, row: u32) -> f32 {
    let h = pcg_hash(col + pcg_hash(row + pcg_hash(seed)));
    return f32(h >> 8u) / 16777216.0;
}

// mirrors src/cpu/jitter.rs: interleaved_offset (the 4×4 Bayer pattern BAYER4)
fn interleaved_offset(col: u32, row: u32) -> f32 {
    var bayer = array<u32, 16>(0u, 8u, 2u, 10u, 12u, 4u, 14u, 6u, 3u, 11u, 1u, 9u, 15u, 7u, 13u, 5u);
    return (f32(bayer[(row % 4u) * 4u + col % 4u]) + 0.5) / 16.0;
}

// mirrors src/cpu/jitter.rs: ray_offset (accel.y: 0 none, 1 random, 2 interleaved)
fn ray_offset(col: u32, row: u32) -> f32 {
    if (params.accel.y == 1u) {
        return jitter_offset(params.accel.z, col, row);
    } else if (params.accel.y == 2u) {
        return interleaved_offset(col, row);
    }
    return 0.0;
}

// Step k covers [t_s + k dt, t_s + (k+1) dt]; the first starts at t_in, the last ends
// at t_out. Mirrors src/cpu/raycast.rs: cast_ray (segment).
fn step_bounds(k: u32, n: u32, t_in: f32, t_s: f32, t_out: f32, dt: f32) -> vec2<f32> {
    var ta = t_in;
    if (k != 0u) {
        ta = t_s + f32(k) * dt;
    }
    var tb = t_out;
    if (k + 1u != n) {
        tb = t_s + f32(k + 1u) * dt;
    }
    return vec2<f32>(ta, tb);
}

// ---------------------------------------------------------------- clipping box
// mirrors src/cpu/skip.rs: ClipR::interval (accel.w: 0 none, 1 index space, 2 world)
fn clip_interval(o: vec3<f32>, d: vec3<f32>, wo: vec3<f32>, wd: vec3<f32>) -> Hit {
    if (params.accel.w == 2u) {
        return intersect_box(wo, wd, params.clip_lo.xyz, params.clip_hi.xyz);
    }
    return intersect_box(o, d, params.clip_lo.xyz, params.clip_hi.xyz);
}

// ---------------------------------------------------------------- emptiness
// mirrors src/cpu/skip.rs: OpacityPrefix::range_empty
fn range_empty(lo: f32, hi: f32) -> bool {
    let last = params.lut.z;
    let expand = params.skip_tf.x;
    let margin = params.skip_tf.y;
    let w = hi - lo;
    let m = margin * max(abs(lo), abs(hi)) + margin;
    let a = lo - expand * w - m;
    let b = hi + expand * w + m;
    let xa = params.lut.x * a + params.lut.y;
    let xb = params.lut.x * b + params.lut.y;
    let x0 = min(max(min(xa, xb), 0.0), last);
    let x1 = min(max(max(xa, xb), 0.0), last);
    let i0 = max(i32(floor(x0)) - 1, 0);
    let i1 = min(i32(floor(x1)) + 2, i32(last));
    return skip_prefix[i1 + 1] == skip_prefix[i0];
}

// mirrors src/cpu/skip.rs: Skipper::cell_empty
fn cell_empty(c: vec3<i32>) -> bool {
    let n = vec3<i32>(params.skip_cells.xyz);
    let mm = skip_minmax[c.x + n.x * (c.y + n.y * c.z)];
    return range_empty(mm.x, mm.y);
}

// ---------------------------------------------------------------- the walk
// mirrors src/cpu/skip.rs: CellWalk
struct CellWalk {
    o: vec3<f32>,
    d: vec3<f32>,
    cell: vec3<i32>,
    step: vec3<i32>,
    t: f32,
    t_end: f32,
}

// mirrors src/cpu/skip.rs: CellWalk::new
fn walk_new(o: vec3<f32>, d: vec3<f32>, t0: f32, t1: f32) -> CellWalk {
    let b = f32(params.skip_cells.w);
    let last = vec3<f32>(params.skip_cells.xyz) - vec3<f32>(1.0);
    let p = o + d * t0;
    var w: CellWalk;
    w.o = o;
    w.d = d;
    w.cell = vec3<i32>(min(max(floor((p + vec3<f32>(0.5)) / b), vec3<f32>(0.0)), last));
    w.step = vec3<i32>(sign(d));
    w.t = t0;
    w.t_end = t1;
    return w;
}

// The parameters at which the walk leaves the current cell along each axis.
// mirrors src/cpu/skip.rs: CellWalk::boundary
fn walk_boundaries(w: ptr<function, CellWalk>) -> vec3<f32> {
    let step = (*w).step;
    let edge = (*w).cell + select(vec3<i32>(0), vec3<i32>(1), step > vec3<i32>(0));
    let t = (vec3<f32>(edge) * f32(params.skip_cells.w) - vec3<f32>(0.5) - (*w).o) / (*w).d;
    return select(t, vec3<f32>(BIG), step == vec3<i32>(0));
}

// mirrors src/cpu/skip.rs: CellWalk::advance
fn walk_advance(w: ptr<function, CellWalk>) {
    let b = walk_boundaries(w);
    var cell = (*w).cell;
    let step = (*w).step;
    var tb = b.z;
    if (b.x <= b.y && b.x <= b.z) {
        tb = b.x;
        cell.x = cell.x + step.x;
    } else if (b.y <= b.z) {
        tb = b.y;
        cell.y = cell.y + step.y;
    } else {
        cell.z = cell.z + step.z;
    }
    (*w).t = max((*w).t, tb);
    (*w).cell = cell;
}

// mirrors src/cpu/skip.rs: CellWalk::active
fn walk_active(w: ptr<function, CellWalk>) -> bool {
    let c = (*w).cell;
    let n = vec3<i32>(params.skip_cells.xyz);
    return (*w).t < (*w).t_end && all(c >= vec3<i32>(0)) && all(c < n);
}

// The next span of non-empty cells: (ok, t_a, t_b).
// mirrors src/cpu/skip.rs: CellWalk::next_span
fn walk_next_span(w: ptr<function, CellWalk>) -> vec3<f32> {
    loop {
        if (!walk_active(w) || !cell_empty((*w).cell)) {
            break;
        }
        walk_advance(w);
    }
    if (!walk_active(w)) {
        return vec3<f32>(0.0);
    }
    let start = (*w).t;
    loop {
        walk_advance(w);
        if (!walk_active(w) || cell_empty((*w).cell)) {
            break;
        }
    }
    return vec3<f32>(1.0, start, min((*w).t, (*w).t_end));
}

// mirrors src/cpu/skip.rs: SampleRanges
// (The walk itself lives in its own variable, passed alongside.)
struct SampleRanges {
    skip: bool,
    backward: bool,
    t_s: f32,
    dt: f32,
    n: i32,
    next: i32,
}

// mirrors src/cpu/skip.rs: SampleRanges::new
fn ranges_new(skip: bool, t_s: f32, dt: f32, n: u32, backward: bool) -> SampleRanges {
    var r: SampleRanges;
    r.skip = skip;
    r.backward = backward;
    r.t_s = t_s;
    r.dt = dt;
    r.n = i32(n);
    r.next = 0;
    if (backward) {
        r.next = i32(n);
    }
    return r;
}

// The walk of a ray, reversed for back-to-front.
// mirrors src/cpu/skip.rs: SampleRanges::new
fn ranges_walk(o: vec3<f32>, d: vec3<f32>, t_in: f32, t_out: f32, backward: bool) -> CellWalk {
    if (backward) {
        return walk_new(o, -d, -t_out, -t_in);
    }
    return walk_new(o, d, t_in, t_out);
}

fn ranges_k(r: ptr<function, SampleRanges>, t: f32) -> f32 {
    let lim = f32((*r).n) + 2.0;
    return min(max((t - (*r).t_s) / (*r).dt - 0.5, -lim), lim);
}

// The next inclusive range of sample indices: (ok, k_lo, k_hi).
// mirrors src/cpu/skip.rs: SampleRanges::next
fn ranges_next(r: ptr<function, SampleRanges>, w: ptr<function, CellWalk>) -> vec3<i32> {
    if (!(*r).skip) {
        if (((*r).backward && (*r).next == 0) || (!(*r).backward && (*r).next == (*r).n)) {
            return vec3<i32>(0);
        }
        if ((*r).backward) {
            (*r).next = 0;
        } else {
            (*r).next = (*r).n;
        }
        return vec3<i32>(1, 0, (*r).n - 1);
    }
    loop {
        let span = walk_next_span(w);
        if (span.x == 0.0) {
            return vec3<i32>(0);
        }
        var ta = span.y;
        var tb = span.z;
        if ((*r).backward) {
            ta = -span.z;
            tb = -span.y;
        }
        var lo = max(i32(floor(ranges_k(r, ta))) - 1, 0);
        var hi = min(i32(ceil(ranges_k(r, tb))) + 1, (*r).n - 1);
        if ((*r).backward) {
            hi = min(hi, (*r).next - 1);
            if (lo > hi) {
                continue;
            }
            (*r).next = lo;
        } else {
            lo = max(lo, (*r).next);
            if (lo > hi) {
                continue;
            }
            (*r).next = hi + 1;
        }
        return vec3<i32>(1, lo, hi);
    }
    return vec3<i32>(0);
}
