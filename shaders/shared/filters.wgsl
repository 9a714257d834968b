// The reconstruction-filter kernels, once for every shader that weights taps: the ray
// caster (shaders/raycast.wgsl: tap_weight), resampling (shaders/process_resample.wgsl:
// axis_taps) and Fourier volume rendering (shaders/fvr_slice.wgsl: kernel_weight).
// Each mirrors its Rust twin in src/cpu/filter.rs (formulas and radii in its module
// docs), in the same order of operations. Reads no bindings.

const PI: f32 = 3.14159265358979323846;

// mirrors src/cpu/filter.rs: weight_tent
fn weight_tent(x: f32) -> f32 {
    return max(1.0 - abs(x), 0.0);
}

// mirrors src/cpu/filter.rs: weight_bspline
fn weight_bspline(x: f32) -> f32 {
    let a = abs(x);
    let sixth = 1.0 / 6.0;
    if (a < 1.0) {
        return (4.0 - 6.0 * a * a + 3.0 * a * a * a) * sixth;
    } else if (a < 2.0) {
        let t = 2.0 - a;
        return t * t * t * sixth;
    }
    return 0.0;
}

// mirrors src/cpu/filter.rs: weight_catmull_rom
fn weight_catmull_rom(x: f32) -> f32 {
    let a = abs(x);
    if (a < 1.0) {
        return 1.5 * a * a * a - 2.5 * a * a + 1.0;
    } else if (a < 2.0) {
        return -0.5 * a * a * a + 2.5 * a * a - 4.0 * a + 2.0;
    }
    return 0.0;
}

// Rust's f32::round: halves away from zero (WGSL's round() goes to even).
fn round_away(x: f32) -> f32 {
    return sign(x) * floor(abs(x) + 0.5);
}

// mirrors src/cpu/filter.rs: sin_pi (the argument reduced to [−1, 1] first, so it is
// exactly zero at integers)
fn sin_pi(x: f32) -> f32 {
    let r = x - 2.0 * round_away(x / 2.0);
    if (r > 0.5) {
        return sin(PI * (1.0 - r));
    } else if (r < -0.5) {
        return -sin(PI * (1.0 + r));
    }
    return sin(PI * r);
}

// mirrors src/cpu/filter.rs: sinc
fn sinc(x: f32) -> f32 {
    if (x == 0.0) {
        return 1.0;
    }
    return sin_pi(x) / (PI * x);
}

// mirrors src/cpu/filter.rs: weight_lanczos
fn weight_lanczos(x: f32, n: u32) -> f32 {
    let nr = f32(n);
    if (abs(x) >= nr) {
        return 0.0;
    }
    return sinc(x) * sinc(x / nr);
}

// The clamp-to-edge index of tap i on an axis of n voxels (the CPU's
// Grid::at_clamped).
fn clamp_index(i: i32, n: u32) -> i32 {
    return clamp(i, 0, i32(n) - 1);
}
