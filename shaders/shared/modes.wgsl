// MIDA, the MIP/MinIP grey window and iso-surfaces for the ray caster: the constants
// and per-sample helpers, twins of src/cpu/modes.rs (formulas and conventions in its
// module docs); each helper names its Rust twin. The two marches, cast_mida and
// cast_iso, are in shared/modes_cast.wgsl. Reads the ray caster's `params`
// (RaycastParams).

#import rays
#import opacity
#import shading

const MODE_MIDA: u32 = 4u;
const MODE_ISO: u32 = 5u;
const MAX_ISO: u32 = 4u;

// mirrors src/cpu/modes.rs: window_map
fn window_map(v: f32) -> f32 {
    return min(max((v - params.window.y) / params.window.x + 0.5, 0.0), 1.0);
}

// mirrors src/cpu/modes.rs: mida_beta
fn mida_beta(delta: f32, gamma: f32) -> f32 {
    return 1.0 - delta * (1.0 + min(gamma, 0.0));
}

// mirrors src/cpu/modes.rs: crosses
fn crosses(v0: f32, v1: f32, tau: f32) -> bool {
    return (v0 >= tau) != (v1 >= tau);
}

// mirrors src/cpu/modes.rs: iso_hit_t
fn iso_hit_t(t0: f32, v0: f32, t1: f32, v1: f32, tau: f32) -> f32 {
    if (params.iso_flags.w == 1u) {
        return t0 + (tau - v0) / (v1 - v0) * (t1 - t0);
    }
    return t1;
}

fn iso_color(j: u32) -> vec4<f32> {
    if (j == 0u) {
        return params.iso_color_0;
    } else if (j == 1u) {
        return params.iso_color_1;
    } else if (j == 2u) {
        return params.iso_color_2;
    }
    return params.iso_color_3;
}

// (C, A) over the background; mirrors src/cpu/shade.rs: over_background
fn over_background(c: vec3<f32>, a: f32) -> vec4<f32> {
    let t = 1.0 - a;
    let bg = params.background;
    return vec4<f32>(c + t * bg.xyz * bg.w, a + t * bg.w);
}

// Opacity correction for a step of len·speed voxels (as in cast_ray).
fn corrected_alpha(a: f32, len: f32, speed: f32) -> f32 {
    if (a < 1.0) {
        return step_opacity(a, len * speed / params.misc.x);
    }
    return 1.0;
}

