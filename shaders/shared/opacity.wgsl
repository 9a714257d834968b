// Opacity correction and its two functions, accurate on any conformant GPU.
//
// Vulkan only promises log to an absolute 2^-21 for arguments in [0.5, 2], and pow is
// exp2(y·log2(x)); so `1 − pow(1 − a, r)` loses most digits of a small a on real
// hardware (NVIDIA: 1e-6 relative differences between two casters on one image), while
// lavapipe computes it in full f32. Near zero both functions use series here, and
// log/exp only where those are accurate to a few ulp.
// Imported by the ray caster, D²VR, the multi-volume and the adaptive casters and the
// pre-integration table.

// ln(1 + x) (as f64::ln_1p): for x in [−1/2, 1], 2·atanh(z) with z = x / (2 + x),
// |z| ≤ 1/3, summed to z^17 (truncation < 2^-28 relative); elsewhere log(1 + x), whose
// argument then lies outside [1/2, 2], where log is good to 3 ulp.
fn ln_1p(x: f32) -> f32 {
    if (x >= -0.5 && x <= 1.0) {
        let z = x / (2.0 + x);
        let z2 = z * z;
        var s = 1.0 / 17.0;
        s = 1.0 / 15.0 + z2 * s;
        s = 1.0 / 13.0 + z2 * s;
        s = 1.0 / 11.0 + z2 * s;
        s = 1.0 / 9.0 + z2 * s;
        s = 1.0 / 7.0 + z2 * s;
        s = 1.0 / 5.0 + z2 * s;
        s = 1.0 / 3.0 + z2 * s;
        s = 1.0 + z2 * s;
        return 2.0 * z * s;
    }
    return log(1.0 + x);
}

// e^x − 1 (as f64::exp_m1): for |x| ≤ 1/2 the Taylor series to x^11/11!
// (truncation < 2^-30 relative); elsewhere exp(x) − 1, which loses nothing there.
fn exp_m1(x: f32) -> f32 {
    if (abs(x) <= 0.5) {
        var s = 1.0 + x / 11.0;
        s = 1.0 + x / 10.0 * s;
        s = 1.0 + x / 9.0 * s;
        s = 1.0 + x / 8.0 * s;
        s = 1.0 + x / 7.0 * s;
        s = 1.0 + x / 6.0 * s;
        s = 1.0 + x / 5.0 * s;
        s = 1.0 + x / 4.0 * s;
        s = 1.0 + x / 3.0 * s;
        s = 1.0 + x / 2.0 * s;
        return x * s;
    }
    return exp(x) - 1.0;
}

// 1 − (1 − a)^r, the opacity of a sample of opacity a per reference step over r
// reference steps (mirrors the CPU's `1 − (1 − α)^r`), as −expm1(r·ln(1 − a)).
fn step_opacity(a: f32, r: f32) -> f32 {
    if (a >= 1.0) {
        return 1.0;
    }
    return -exp_m1(r * ln_1p(-a));
}
