// The iterative methods' vector steps on the device, so that a whole iteration of
// SIRT, OS-SART, CGLS or TV runs without the host: residuals and weights, updates,
// the deterministic reductions behind every inner product and log entry, CGLS's
// step scalars, the TV primal-dual steps, and the stop rule. One entry point per
// step; all share one bind-group layout (unused bindings are dummies).
// The twin of the CPU methods in src/cpu/iterative.rs (each entry point says which
// function it mirrors); the host side is src/gpu/iterative.rs.

#import iterative_params

@group(0) @binding(0) var<uniform> p: SolveParams;
@group(0) @binding(1) var<storage, read> a: array<f32>;
@group(0) @binding(2) var<storage, read> b: array<f32>;
@group(0) @binding(3) var<storage, read> c: array<f32>;
@group(0) @binding(4) var<storage, read_write> out: array<f32>;
@group(0) @binding(5) var<storage, read_write> out2: array<f32>;
// SLOT_* scalars, then the log (residual, objective) per entry from LOG_BASE.
@group(0) @binding(6) var<storage, read_write> s: array<f32>;
// The views of the rays being stepped (slot → view).
@group(0) @binding(7) var<storage, read> list: array<u32>;

const WORKGROUP: u32 = 64u;
// Reductions: values per chunk (src/cpu/iterative.rs: CHUNK) and invocations per
// chunk; each invocation sums CHUNK / REDUCE values in order, then a fixed tree.
const CHUNK: u32 = 4096u;
const REDUCE: u32 = 256u;

// Twins of src/gpu/iterative.rs: SLOT_*.
const SLOT_STOP: u32 = 0u;
const SLOT_LOGGED: u32 = 1u;
const SLOT_PREVIOUS: u32 = 2u;
const LOG_BASE: u32 = 16u;

// Reduction terms (src/gpu/iterative.rs: Term).
const TERM_DOT: u32 = 0u;
const TERM_DIFF: u32 = 1u;
const TERM_WEIGHTED: u32 = 2u;
const TERM_TV: u32 = 3u;

fn index(gid: vec3<u32>) -> u32 {
    return gid.x + gid.y * p.row_stride;
}

fn stopped() -> bool {
    return s[SLOT_STOP] != 0.0;
}

// The ray `id` of the stepped views as an index into an all-views array.
fn ray_of(id: u32) -> u32 {
    return list[id / p.per_view] * p.per_view + id % p.per_view;
}

// out ← b − out over the stepped views (b holds every view).
// mirrors src/cpu/iterative.rs: residual_of
@compute @workgroup_size(WORKGROUP)
fn residual(@builtin(global_invocation_id) gid: vec3<u32>) {
    let id = index(gid);
    if id >= p.n {
        return;
    }
    out[id] = b[ray_of(id)] - out[id];
}

// out ← out · a over the stepped views (a: the row weights of every view).
// mirrors src/cpu/iterative.rs: sart (the weighted residual)
@compute @workgroup_size(WORKGROUP)
fn weight_rows(@builtin(global_invocation_id) gid: vec3<u32>) {
    let id = index(gid);
    if id >= p.n {
        return;
    }
    out[id] = out[id] * a[ray_of(id)];
}

// out ← 1/out where out > 1e-6, else 0.
// mirrors src/cpu/iterative.rs: reciprocal
@compute @workgroup_size(WORKGROUP)
fn reciprocal(@builtin(global_invocation_id) gid: vec3<u32>) {
    let id = index(gid);
    if id >= p.n {
        return;
    }
    let v = out[id];
    out[id] = select(0.0, 1.0 / v, v > 1e-6);
}

// out ← 0 where a (the support: 1 inside, 0 outside) is 0.
// mirrors src/cpu/project.rs: masked
@compute @workgroup_size(WORKGROUP)
fn mask(@builtin(global_invocation_id) gid: vec3<u32>) {
    let id = index(gid);
    if id >= p.n {
        return;
    }
    if a[id] == 0.0 {
        out[id] = 0.0;
    }
}

// out ← out + λ·b·a (a: Aᵀ of the weighted residual, b: the column weights), then
// max(out, 0) when asked.
// mirrors src/cpu/iterative.rs: update
@compute @workgroup_size(WORKGROUP)
fn sart_update(@builtin(global_invocation_id) gid: vec3<u32>) {
    let id = index(gid);
    if id >= p.n || stopped() {
        return;
    }
    let v = out[id] + p.f0 * b[id] * a[id];
    out[id] = select(v, max(v, 0.0), p.nonnegative != 0u);
}

// out ← out + f0·s[slot0]·a (CGLS: x += αp with f0 = 1, r −= αq with f0 = −1).
// mirrors src/cpu/iterative.rs: axpy
@compute @workgroup_size(WORKGROUP)
fn axpy(@builtin(global_invocation_id) gid: vec3<u32>) {
    let id = index(gid);
    if id >= p.n || stopped() {
        return;
    }
    out[id] = out[id] + (p.f0 * s[p.slot0]) * a[id];
}

// out ← a + s[slot0]·out (CGLS: p ← s + βp).
// mirrors src/cpu/iterative.rs: cgls (the new direction)
@compute @workgroup_size(WORKGROUP)
fn direction(@builtin(global_invocation_id) gid: vec3<u32>) {
    let id = index(gid);
    if id >= p.n || stopped() {
        return;
    }
    out[id] = a[id] + s[p.slot0] * out[id];
}

// out ← out / sqrt(s[slot0]) when that is positive (the power iteration).
// mirrors src/cpu/iterative.rs: operator_norm (the normalisation)
@compute @workgroup_size(WORKGROUP)
fn normalise(@builtin(global_invocation_id) gid: vec3<u32>) {
    let id = index(gid);
    let nv = sqrt(max(s[p.slot0], 0.0));
    if id >= p.n || !(nv > 0.0) {
        return;
    }
    out[id] = out[id] * (1.0 / nv);
}

// CGLS's step: stop when γ = ‖s‖² or ‖q‖² is 0, else s[slot2] ← α = γ / ‖q‖²
// (slot0 γ, slot1 ‖q‖²).
// mirrors src/cpu/iterative.rs: cgls (alpha)
@compute @workgroup_size(1)
fn cgls_alpha() {
    if stopped() {
        return;
    }
    let gamma = s[p.slot0];
    let qq = s[p.slot1];
    if gamma == 0.0 || qq == 0.0 {
        s[SLOT_STOP] = 1.0;
        return;
    }
    s[p.slot2] = gamma / qq;
}

// CGLS's next direction weight: s[slot2] ← β = γ_new / γ, then γ ← γ_new (slot0 γ,
// slot1 γ_new).
// mirrors src/cpu/iterative.rs: cgls (beta)
@compute @workgroup_size(1)
fn cgls_beta() {
    if stopped() {
        return;
    }
    s[p.slot2] = s[p.slot1] / s[p.slot0];
    s[p.slot0] = s[p.slot1];
}

// The forward difference of a along `axis` at voxel i (0 at the last voxel).
// mirrors src/cpu/iterative.rs: forward_difference
fn forward_difference(axis: u32, i: u32) -> f32 {
    let dims = array<u32, 3>(p.nx, p.ny, p.nz);
    let strides = array<u32, 3>(1u, p.nx, p.nx * p.ny);
    let cc = (i / strides[axis]) % dims[axis];
    if cc + 1u < dims[axis] {
        return a[i + strides[axis]] - a[i];
    }
    return 0.0;
}

fn live_axis(f: u32) -> u32 {
    return array<u32, 3>(p.axis0, p.axis1, p.axis2)[f];
}

// One value of the sum a reduction takes.
fn term(i: u32) -> f32 {
    switch p.term {
        case TERM_DOT: {
            return a[i] * b[i];
        }
        case TERM_DIFF: {
            let d = a[i] - b[i];
            return d * d;
        }
        case TERM_WEIGHTED: {
            return b[i] * a[i] * a[i];
        }
        default: {
            // TERM_TV: |∇a| at voxel i.
            var len2 = 0.0;
            for (var f = 0u; f < p.n_axes; f++) {
                let d = forward_difference(live_axis(f), i);
                len2 += d * d;
            }
            return sqrt(len2);
        }
    }
}

var<workgroup> tree: array<f32, REDUCE>;

// Sums tree[0 .. REDUCE] into tree[0] in a fixed order.
fn tree_sum(t: u32) {
    for (var w = REDUCE / 2u; w > 0u; w = w / 2u) {
        workgroupBarrier();
        if t < w {
            tree[t] = tree[t] + tree[t + w];
        }
    }
    workgroupBarrier();
}

// out[chunk] ← Σ term(i) over chunk `workgroup` of CHUNK values (of p.n): the same
// sum whatever the device's scheduling.
// mirrors src/cpu/iterative.rs: sum_by (the chunk sums)
@compute @workgroup_size(REDUCE)
fn partials(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let chunk = wg.x + wg.y * (p.row_stride / REDUCE);
    let base = chunk * CHUNK;
    var acc = 0.0;
    for (var k = 0u; k < CHUNK / REDUCE; k++) {
        let i = base + k * REDUCE + t;
        if i < p.n {
            acc += term(i);
        }
    }
    tree[t] = acc;
    tree_sum(t);
    if t == 0u && base < p.n {
        out[chunk] = tree[0];
    }
}

// s[slot0] ← Σ a[0 .. p.n] (the chunk sums), in one workgroup.
// mirrors src/cpu/iterative.rs: sum_by (the chunks added)
@compute @workgroup_size(REDUCE)
fn finish(@builtin(local_invocation_index) t: u32) {
    var acc = 0.0;
    for (var i = t; i < p.n; i += REDUCE) {
        acc += a[i];
    }
    tree[t] = acc;
    tree_sum(t);
    if t == 0u {
        s[p.slot0] = tree[0];
    }
}

// Logs the entry (√s[slot0], f0·s[slot1] + f1·s[slot2]) unless stopped; then stops
// when the objective fell by no more than the tolerance f2 (relative).
// mirrors src/cpu/iterative.rs: stalled (and the pushes to the log)
@compute @workgroup_size(1)
fn log_entry() {
    if stopped() {
        return;
    }
    let k = u32(s[SLOT_LOGGED]);
    let objective = p.f0 * s[p.slot1] + p.f1 * s[p.slot2];
    s[LOG_BASE + 2u * k] = sqrt(max(s[p.slot0], 0.0));
    s[LOG_BASE + 2u * k + 1u] = objective;
    s[SLOT_LOGGED] = f32(k + 1u);
    let previous = s[SLOT_PREVIOUS];
    if p.f2 > 0.0 && k >= 1u && abs(previous - objective) <= p.f2 * abs(previous) {
        s[SLOT_STOP] = 1.0;
    }
    s[SLOT_PREVIOUS] = objective;
}

// out ← (a + out) / 2 (TV: A x_k from A x̄_k and A x_{k−1}).
// mirrors src/cpu/iterative.rs: tv (the midpoint)
@compute @workgroup_size(WORKGROUP)
fn midpoint(@builtin(global_invocation_id) gid: vec3<u32>) {
    let id = index(gid);
    if id >= p.n || stopped() {
        return;
    }
    out[id] = (a[id] + out[id]) / 2.0;
}

// The data term's dual: out ← (out + σ(a − b)) / (1 + σ), σ = f0 (a: A x̄, b: the
// projections).
// mirrors src/cpu/iterative.rs: tv (the dual of the data term)
@compute @workgroup_size(WORKGROUP)
fn dual_data(@builtin(global_invocation_id) gid: vec3<u32>) {
    let id = index(gid);
    if id >= p.n || stopped() {
        return;
    }
    out[id] = (out[id] + p.f0 * (a[id] - b[id])) / (1.0 + p.f0);
}

// TV's dual: q ← proj_{|q| ≤ f1}(q + f0·∇a), voxel by voxel (out: q, one field of
// p.n values per live axis; a: x̄).
// mirrors src/cpu/iterative.rs: tv_dual_step
@compute @workgroup_size(WORKGROUP)
fn dual_gradient(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = index(gid);
    if i >= p.n || stopped() {
        return;
    }
    var v = vec3<f32>(0.0);
    var len2 = 0.0;
    for (var f = 0u; f < p.n_axes; f++) {
        v[f] = out[f * p.n + i] + p.f0 * forward_difference(live_axis(f), i);
        len2 += v[f] * v[f];
    }
    let len = sqrt(len2);
    if len > p.f1 {
        let scale = select(0.0, p.f1 / len, len > 0.0);
        v = v * scale;
    }
    for (var f = 0u; f < p.n_axes; f++) {
        out[f * p.n + i] = v[f];
    }
}

// ∇ᵀq = −div q at voxel i (b: q, one field per live axis).
// mirrors src/cpu/iterative.rs: gradient_transpose
fn gradient_transpose(i: u32) -> f32 {
    let dims = array<u32, 3>(p.nx, p.ny, p.nz);
    let strides = array<u32, 3>(1u, p.nx, p.nx * p.ny);
    var acc = 0.0;
    for (var f = 0u; f < p.n_axes; f++) {
        let ax = live_axis(f);
        let cc = (i / strides[ax]) % dims[ax];
        if cc + 1u < dims[ax] {
            acc = acc - b[f * p.n + i];
        }
        if cc > 0u {
            acc = acc + b[f * p.n + i - strides[ax]];
        }
    }
    return acc;
}

// TV's primal step: x ← proj(x − τ(a + μ∇ᵀq)) (τ = f0, μ = f1; a: Aᵀp, b: q, c: the
// support when p.term is 1), x̄ ← 2x_new − x (out: x, out2: x̄).
// mirrors src/cpu/iterative.rs: tv (the primal step)
@compute @workgroup_size(WORKGROUP)
fn primal(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = index(gid);
    if i >= p.n || stopped() {
        return;
    }
    let g = a[i] + p.f1 * gradient_transpose(i);
    let old = out[i];
    var v = old - p.f0 * g;
    if p.nonnegative != 0u {
        v = max(v, 0.0);
    }
    if p.term == 1u && c[i] == 0.0 {
        v = 0.0;
    }
    out2[i] = 2.0 * v - old;
    out[i] = v;
}
