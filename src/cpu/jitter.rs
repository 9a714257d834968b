//! Jittered ray starts and interleaved sampling: the offset of each pixel's first step.
//!
//! A ray marched with a fixed step `Δs` samples every pixel's ray at the same depths
//! `t_in + (k + ½)Δs`; on thin or steep structures the error of that quadrature is
//! coherent across neighbouring pixels and shows as concentric "wood-grain" bands.
//! Offsetting each ray's sample grid by `u·Δs`, `u ∈ [0, 1)` per pixel, turns the
//! coherent error into noise (Scharsach's jittered ray starts), which frame
//! accumulation (`crate::accumulate`) then averages away. Interleaved sampling (Fluør
//! 2006, after Keller & Heidrich) uses a fixed 4×4 ordered pattern instead,
//! `u = (B[row mod 4][col mod 4] + ½)/16`, so sixteen neighbouring pixels share the
//! work of one finer step in a single frame.
//!
//! With offset `u`, step `k` of a ray covers `[t_s + kΔs, t_s + (k+1)Δs] ∩ [t_in,
//! t_out]` for the virtual start `t_s = t_in − uΔs`: the first step is shortened at the
//! entry and the last at the exit, so every frame is still a complete midpoint-rule
//! quadrature of the ray, and `u = 0` is exactly the unjittered ray.
//!
//! Random offsets come from a PCG hash (O'Neill 2014; the `pcg_hash` of Jarzynski &
//! Olano 2020) of `(col, row, seed)`, identical in Rust and WGSL
//! (`shaders/shared/skip.wgsl: pcg_hash, ray_offset`), so the CPU and the GPU jitter
//! the same pixel by the same amount. `u` has 24 bits, exact in f32 and f64.

use crate::settings::RenderSettings;

/// The 4×4 ordered (Bayer) pattern of interleaved sampling.
pub const BAYER4: [[u32; 4]; 4] = [[0, 8, 2, 10], [12, 4, 14, 6], [3, 11, 1, 9], [15, 7, 13, 5]];

/// PCG hash of one 32-bit word.
/// mirrors shaders/shared/skip.wgsl: pcg_hash
#[inline]
pub fn pcg_hash(v: u32) -> u32 {
    let state = v.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

/// The random offset `u ∈ [0, 1)` of pixel `(col, row)` for `seed`, 24 bits.
/// mirrors shaders/shared/skip.wgsl: jitter_offset
#[inline]
pub fn jitter_offset(seed: u32, col: u32, row: u32) -> f64 {
    let h = pcg_hash(col.wrapping_add(pcg_hash(row.wrapping_add(pcg_hash(seed)))));
    (h >> 8) as f64 / (1u32 << 24) as f64
}

/// The interleaved-sampling offset of pixel `(col, row)`.
/// mirrors shaders/shared/skip.wgsl: interleaved_offset
#[inline]
pub fn interleaved_offset(col: u32, row: u32) -> f64 {
    (BAYER4[(row % 4) as usize][(col % 4) as usize] as f64 + 0.5) / 16.0
}

/// The ray-start offset (in steps) the settings give pixel `(col, row)`.
/// mirrors shaders/shared/skip.wgsl: ray_offset
#[inline]
pub fn ray_offset(settings: &RenderSettings, col: usize, row: usize) -> f64 {
    match (settings.jitter, settings.interleaved) {
        (Some(seed), _) => jitter_offset(seed, col as u32, row as u32),
        (None, true) => interleaved_offset(col as u32, row as u32),
        (None, false) => 0.0,
    }
}
