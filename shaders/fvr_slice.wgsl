// Fourier volume rendering: the central slice of the centred 3-D spectrum, one
// invocation per output frequency sample. Mirrors src/cpu/fvr.rs: fvr_project (the
// per-sample closure) and FvrSpectrum::sample; the host side is src/gpu/fvr.rs. The
// kernels are shared/filters.wgsl's; the generated module fvr_slabs
// (src/gpu/fvr.rs: slab_bindings_wgsl) declares the spectrum's z-slab bindings 2, 3, …
// and spectrum_at(slab, i).

#import fvr_params
#import fvr_slabs
#import filters

@group(0) @binding(0) var<uniform> p: FvrParams;
// [k_u][k_r], each k at k mod M (DC at 0): (re, im).
@group(0) @binding(1) var<storage, read_write> slice: array<vec2<f32>>;

const WORKGROUP: u32 = 64u;

// mirrors src/cpu/fvr.rs: Kernel::weight (trilinear and Lanczos; nearest is handled
// apart)
fn kernel_weight(x: f32) -> f32 {
    if p.kernel == 1u {
        return weight_tent(x);
    }
    return weight_lanczos(x, p.radius);
}

// i.rem_euclid(M).
fn wrap(i: i32) -> u32 {
    let m = i32(p.m);
    return u32(((i % m) + m) % m);
}

// The centred spectrum at index (ix, iy, iz) ([z][y][x], frequency κ at M/2 + κ): plane
// iz lies in slab iz / slab_depth.
fn at(ix: u32, iy: u32, iz: u32) -> vec2<f32> {
    let slab = iz / p.slab_depth;
    let z = iz - slab * p.slab_depth;
    return spectrum_at(slab, (z * p.m + iy) * p.m + ix);
}

// The most voxels along x the Dirichlet sum takes (its phases are kept per invocation);
// the CPU's work limit (src/cpu/fvr.rs: MAX_DIRICHLET_WORK, N³·M² with M ≥ N) keeps N
// below 84. Rust twin: src/gpu/fvr.rs: DIRICHLET_MAX_NX.
const DIRICHLET_MAX_NX: u32 = 128u;

// e^{−2πi·k·r/M}: the angle reduced to a fraction of a turn first.
fn dirichlet_phase(k: f32, r: f32) -> vec2<f32> {
    let turns = k * r / f32(p.m);
    let a = -2.0 * PI * (turns - round(turns));
    return vec2<f32>(cos(a), sin(a));
}

fn cmul(a: vec2<f32>, b: vec2<f32>) -> vec2<f32> {
    return vec2<f32>(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

// The spectrum of the padded grid evaluated exactly at kappa: the sum over every voxel
// of its value times e^{−2πi κ·r/M}, r = n + offset − M/2, separable per axis (the x
// phases kept, summed along x, then y, then z), in f32.
// mirrors src/cpu/fvr.rs: FvrSpectrum::sample_exact
fn dirichlet(kappa: vec3<f32>) -> vec2<f32> {
    let half = f32(p.m / 2u);
    var px: array<vec2<f32>, DIRICHLET_MAX_NX>;
    for (var i = 0u; i < p.nx; i++) {
        px[i] = dirichlet_phase(kappa.x, f32(i + p.ox) - half);
    }
    var acc = vec2<f32>(0.0);
    for (var k = 0u; k < p.nz; k++) {
        var az = vec2<f32>(0.0);
        for (var j = 0u; j < p.ny; j++) {
            let row = (k * p.ny + j) * p.nx;
            var ax = vec2<f32>(0.0);
            for (var i = 0u; i < p.nx; i++) {
                ax += px[i] * values[row + i];
            }
            az += cmul(ax, dirichlet_phase(kappa.y, f32(j + p.oy) - half));
        }
        acc += cmul(az, dirichlet_phase(kappa.z, f32(k + p.oz) - half));
    }
    return acc;
}

// src/cpu/fvr.rs: FvrSpectrum::sample — the centred spectrum at frequency kappa (bins,
// [x, y, z]), weights normalised to sum to 1 per axis; the Dirichlet kernel is the
// exact sum.
fn sample(kappa: vec3<f32>) -> vec2<f32> {
    if p.kernel == 3u {
        return dirichlet(kappa);
    }
    let half = f32(p.m / 2u);
    var g = kappa + vec3<f32>(half);
    if p.kernel == 0u {
        // f64::round: half away from zero.
        let r = sign(g) * floor(abs(g) + 0.5);
        return at(wrap(i32(r.x)), wrap(i32(r.y)), wrap(i32(r.z)));
    }
    let r = i32(p.radius);
    let taps = 2u * p.radius;
    var idx: array<array<u32, 8>, 3>;
    var w: array<array<f32, 8>, 3>;
    for (var a = 0u; a < 3u; a++) {
        let first = i32(floor(g[a])) - r + 1;
        var sum = 0.0;
        for (var t = 0u; t < taps; t++) {
            let j = first + i32(t);
            idx[a][t] = wrap(j);
            let wt = kernel_weight(g[a] - f32(j));
            w[a][t] = wt;
            sum += wt;
        }
        for (var t = 0u; t < taps; t++) {
            w[a][t] = w[a][t] / sum;
        }
    }
    var acc = vec2<f32>(0.0);
    for (var tz = 0u; tz < taps; tz++) {
        var az = vec2<f32>(0.0);
        for (var ty = 0u; ty < taps; ty++) {
            var ax = vec2<f32>(0.0);
            for (var tx = 0u; tx < taps; tx++) {
                ax += at(idx[0][tx], idx[1][ty], idx[2][tz]) * w[0][tx];
            }
            az += ax * w[1][ty];
        }
        acc += az * w[2][tz];
    }
    return acc;
}

// src/cpu/fvr.rs: fvr_project, the per-sample closure `sample_at` and the Hermitian
// fill: S(k_r, k_u) = F(k_r·r + k_u·u)
// times the phase ramp e^{2πi(k_r δ_r + k_u δ_u)/M}.
@compute @workgroup_size(64)
fn extract_slice(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let id = gid.x + gid.y * groups.x * WORKGROUP;
    if id >= p.m * p.m {
        return;
    }
    let m = i32(p.m);
    let half = m / 2;
    let ju = i32(id / p.m);
    let ir = i32(id % p.m);
    // The slice is Hermitian (the volume is real): rows 0 < k_u < M/2 are the
    // conjugates of rows −k_u, written by those rows' invocations, except at
    // k_r = −M/2 (its partner +M/2 is not on the slice). The nearest kernel samples
    // everywhere (its ties round one way for κ and the other for −κ).
    let hermitian = p.kernel != 0u && ir != half;
    if hermitian && ju >= 1 && ju < half {
        return;
    }
    let ku = ((ju + half) % m) - half;
    let kr = ((ir + half) % m) - half;
    let right = vec3<f32>(p.right_x, p.right_y, p.right_z);
    let up = vec3<f32>(p.up_x, p.up_y, p.up_z);
    let kappa = right * f32(kr) + up * f32(ku);
    var s = sample(kappa);
    if p.dr != 0.0 || p.du != 0.0 {
        let phase = 2.0 * PI * (f32(kr) * p.dr + f32(ku) * p.du) / f32(p.m);
        let c = vec2<f32>(cos(phase), sin(phase));
        s = vec2<f32>(s.x * c.x - s.y * c.y, s.x * c.y + s.y * c.x);
    }
    slice[id] = s;
    if hermitian && ju > half {
        slice[u32((m - ju) * m + (m - ir) % m)] = vec2<f32>(s.x, -s.y);
    }
}
