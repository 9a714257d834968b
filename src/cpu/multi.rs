//! The CPU multi-volume ray caster: the oracle for `gpu::multi`.
//!
//! Up to [`MAX_VOLUMES`](crate::multi::MAX_VOLUMES) fields, each placed in the shared
//! world by its own index → world matrix `M_i = T_i A_i` (see [`crate::multi`] for the
//! frames and the combination rule). Per pixel:
//! 1. the world ray `o + t d` is carried into every volume's index space,
//!    `o_i = M_i⁻¹ o`, `d_i = M_i⁻¹ d` (the parameter `t` stays world mm), and clipped to
//!    its box `[−½, n_i − ½]³`, giving `[t_in,i, t_out,i]`;
//! 2. the ray runs over the union `[min t_in,i, max t_out,i]` in steps of
//!    `Δ = step / |d_0|` (volume 0's voxels, as the single-volume caster steps), the last
//!    one shortened to end on the union's far side; each step is represented by its
//!    midpoint `t_m` (the midpoint rule);
//! 3. volume `i` contributes at `t_m` when `t_in,i ≤ t_m ≤ t_out,i`, sampled at
//!    `o_i + t_m d_i` with the render's filter, classified by its own transfer function
//!    (DVR) and optionally shaded with its own gradient (`n = −M_i⁻ᵀ ∇f_i`, normalised);
//! 4. DVR: optical depths over the step `τ_i = −ln(1 − α_i) · len · |d_i| / Δ_ref` add,
//!    colours mix weighted by them, and `α = 1 − e^{−τ}` composites as in
//!    `cpu::raycast` (`cpu::shade`: front to back with early ray termination, or back
//!    to front);
//!    X-ray sums `Σ_i f_i · len`; MIP/MinIP take the extreme over volumes and steps.
//!
//! With one volume and the identity transform every step, sample point and opacity is
//! the single-volume caster's (`tests/multi.rs` checks it to 1e-12 in f64). Pixels run
//! in parallel (rayon) and every sum in a fixed order, so the image does not depend on
//! the number of threads. Empty-space skipping does not apply (it never changes an
//! image).

use super::field::{box_hi, Field, GridField};
use super::grid::Grid;
use super::march::segment_t;
use super::raycast::RenderOutput;
use super::shade::{light_half, over, over_background, shade_gradient, under_until, ShadingR};
use crate::camera::{Camera, Ray};
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::multi::MultiVolume;
use crate::real::{intersect_box, Real, M3, V3};
use crate::settings::{Compositing, Light, Mode, RenderSettings};
use crate::transfer::{LutR, TransferFunction};
use glam::{DMat3, DMat4};
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// One volume as the caster sees it: a field, where it sits, how it is classified.
pub struct Layer<'a, R> {
    pub field: &'a dyn Field<R>,
    /// Index → shared world (`T_i · A_i`).
    pub index_to_world: DMat4,
    pub transfer: &'a TransferFunction,
    /// Phong-shade this volume (when the settings' shading is on).
    pub shade: bool,
}

/// A layer prepared for casting.
struct Prepared<'a, R> {
    field: &'a dyn Field<R>,
    to_index: DMat4,
    normal: M3<R>,
    hi: V3<R>,
    lut: LutR<R>,
    shade: bool,
    grad_thr: R,
}

/// Renders multi-volume scenes in precision `R` (voxel grids reconstructed with the
/// settings' filter). `progress(done_rows, total_rows)` is called as rows finish.
pub fn render<R: Real>(
    volumes: &[MultiVolume],
    camera: &Camera,
    settings: &RenderSettings,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<RenderOutput> {
    crate::multi::check(volumes, camera, settings)?;
    let fields: Vec<GridField<R>> = volumes
        .iter()
        .map(|v| {
            GridField::new(
                Grid::from_any(&v.volume),
                settings.filter,
                settings.gradient,
                settings.precompute_gradients,
            )
        })
        .collect();
    let layers = volumes
        .iter()
        .zip(&fields)
        .map(|(v, f)| {
            Ok(Layer {
                field: f as &dyn Field<R>,
                index_to_world: v.index_to_world()?,
                transfer: &v.transfer,
                shade: v.shade,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    render_layers(&layers, camera, settings, progress)
}

/// Renders prepared layers (any [`Field`]s, e.g. exact phantoms) in precision `R`.
pub fn render_layers<R: Real>(
    layers: &[Layer<'_, R>],
    camera: &Camera,
    settings: &RenderSettings,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<RenderOutput> {
    crate::multi::validate_settings(settings)?;
    if layers.is_empty() || layers.len() > crate::multi::MAX_VOLUMES {
        return Err(Error::invalid(
            "volumes",
            format!(
                "{} given: a multi-volume render draws 1 … {} volumes",
                layers.len(),
                crate::multi::MAX_VOLUMES
            ),
        ));
    }
    let boxes: Vec<_> = layers
        .iter()
        .map(|l| (l.field.dims(), l.index_to_world))
        .collect();
    crate::multi::check_ray_work(&boxes, camera, settings)?;
    let s = &settings.shading;
    let prepared = layers
        .iter()
        .enumerate()
        .map(|(i, l)| {
            l.transfer.validate()?;
            let m = l.index_to_world;
            if !(m.determinant().is_finite() && m.determinant() != 0.0) {
                return Err(Error::invalid(
                    format!("volume {i}"),
                    "its index → world matrix is singular or not finite",
                ));
            }
            let dims = l.field.dims();
            let (lo_v, hi_v) = l.field.value_range();
            Ok(Prepared {
                field: l.field,
                to_index: m.inverse(),
                normal: M3::from_dmat3(DMat3::from_mat4(m).inverse().transpose()),
                hi: box_hi(dims),
                lut: l.transfer.lut(settings.lut_size).to_real::<R>(),
                shade: l.shade && s.enabled && settings.mode == Mode::Dvr,
                grad_thr: R::of(s.gradient_threshold * (hi_v - lo_v).max(f64::MIN_POSITIVE)),
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let common = Common {
        step: R::of(settings.step),
        ref_step: R::of(settings.reference_step),
        k: ShadingR {
            ambient: R::of(s.ambient),
            diffuse: R::of(s.diffuse),
            specular: R::of(s.specular),
            shininess: R::of(s.shininess),
        },
        light: match s.light {
            Light::Headlight => None,
            Light::Direction(d) => Some(V3::from_dvec(glam::DVec3::from_array(d).normalize())),
        },
        ert: R::of(settings.ert_threshold),
        bg: settings.background.map(R::of),
        miss: R::of(settings.miss_value),
        mode: settings.mode,
        back: settings.compositing == Compositing::BackToFront,
    };

    let channels = if settings.mode.rgba() { 4 } else { 1 };
    let (w, h) = (camera.width, camera.height);
    let mut image = Frame::new(w, h, channels);
    let mut counts = vec![0u32; w * h];
    let done = AtomicUsize::new(0);
    image
        .data
        .par_chunks_mut(w * channels)
        .zip(counts.par_chunks_mut(w))
        .enumerate()
        .panic_fuse()
        .for_each(|(row, (pixels, row_counts))| {
            for col in 0..w {
                let (px, n) = cast_multi(&prepared, &common, camera.ray(col, row));
                for (c, v) in px.iter().take(channels).enumerate() {
                    pixels[col * channels + c] = v.f64();
                }
                row_counts[col] = n;
            }
            progress(done.fetch_add(1, Ordering::Relaxed) + 1, h);
        });
    Ok(RenderOutput::from_counts(
        image,
        &counts,
        settings.sample_count,
    ))
}

/// Per-render constants.
struct Common<R> {
    step: R,
    ref_step: R,
    k: ShadingR<R>,
    light: Option<V3<R>>,
    ert: R,
    bg: [R; 4],
    miss: R,
    mode: Mode,
    back: bool,
}

/// One volume's view of one ray.
#[derive(Clone, Copy)]
struct Span<R> {
    o: V3<R>,
    d: V3<R>,
    t_in: R,
    t_out: R,
    hit: bool,
}

/// Casts one ray through every layer; returns the pixel and the number of steps taken.
/// Mirrors `shaders/multi.wgsl: cast_multi`.
fn cast_multi<R: Real>(layers: &[Prepared<'_, R>], c: &Common<R>, ray: Ray) -> ([R; 4], u32) {
    let rgba = c.mode == Mode::Dvr;
    let miss = if rgba {
        c.bg
    } else {
        [c.miss, R::zero(), R::zero(), R::zero()]
    };
    let mut spans = [Span {
        o: V3::zero(),
        d: V3::zero(),
        t_in: R::zero(),
        t_out: R::zero(),
        hit: false,
    }; crate::multi::MAX_VOLUMES];
    let (mut t_in, mut t_out) = (R::infinity(), R::neg_infinity());
    for (l, sp) in layers.iter().zip(spans.iter_mut()) {
        sp.o = V3::<R>::from_dvec(l.to_index.transform_point3(ray.origin));
        sp.d = V3::<R>::from_dvec(l.to_index.transform_vector3(ray.dir));
        if let Some((a, b)) = intersect_box(sp.o, sp.d, V3::splat(R::of(-0.5)), l.hi) {
            let a = a.max(R::of(ray.t_min));
            if b > a {
                *sp = Span {
                    t_in: a,
                    t_out: b,
                    hit: true,
                    ..*sp
                };
                t_in = t_in.min(a);
                t_out = t_out.max(b);
            }
        }
    }
    if t_out.partial_cmp(&t_in) != Some(std::cmp::Ordering::Greater) {
        return (miss, 0);
    }
    let spans = &spans[..layers.len()];
    // The step: `step` voxels of volume 0 along the ray (world mm per step).
    let dt = c.step / spans[0].d.length();
    let n = ((t_out - t_in) / dt - R::of(1e-3))
        .ceil()
        .max(R::one())
        .to_usize()
        .unwrap_or(1);
    // The step rule of `march::Steps::segment`: a full step is dt long, its midpoint
    // t_in + (k + ½)·dt (so one volume gives the single-volume caster's samples).
    let segment = |k: usize| segment_t(k, n, t_in, t_in, t_out, dt);
    let inside = |sp: &Span<R>, tm: R| sp.hit && tm >= sp.t_in && tm <= sp.t_out;
    match c.mode {
        Mode::Mip | Mode::Minip => {
            let mut best: Option<R> = None;
            for k in 0..n {
                let (tm, _) = segment(k);
                for (l, sp) in layers.iter().zip(spans) {
                    if inside(sp, tm) {
                        let v = l.field.value(sp.o + sp.d * tm);
                        best = Some(match best {
                            None => v,
                            Some(b) if c.mode == Mode::Mip => b.max(v),
                            Some(b) => b.min(v),
                        });
                    }
                }
            }
            match best {
                Some(b) => ([b, R::zero(), R::zero(), R::zero()], n as u32),
                None => (miss, n as u32),
            }
        }
        Mode::Xray => {
            let mut sum = R::zero();
            for k in 0..n {
                let (tm, len) = segment(k);
                let mut f = R::zero();
                for (l, sp) in layers.iter().zip(spans) {
                    if inside(sp, tm) {
                        f = f + l.field.value(sp.o + sp.d * tm);
                    }
                }
                sum = sum + f * len;
            }
            ([sum, R::zero(), R::zero(), R::zero()], n as u32)
        }
        _ => {
            let (light, half) = light_half(c.light, ray.dir);
            let mut col = [R::zero(); 3];
            let mut a = R::zero();
            let mut taken = 0u32;
            for i in 0..n {
                let k = if c.back { n - 1 - i } else { i };
                let (tm, len) = segment(k);
                taken += 1;
                let Some((rgb, alpha)) = combine_sample(layers, spans, c, tm, len, light, half)
                else {
                    continue;
                };
                if c.back {
                    over(&mut col, &mut a, rgb, alpha);
                } else if under_until(&mut col, &mut a, rgb, alpha, c.ert) {
                    break;
                }
            }
            (over_background(col, a, c.bg), taken)
        }
    }
}

/// The combined colour and opacity of one step (`None` when it is transparent): every
/// volume's opacity becomes an optical depth over the step, the depths add and the
/// colours mix weighted by them. Mirrors `shaders/multi.wgsl: combine_sample`.
fn combine_sample<R: Real>(
    layers: &[Prepared<'_, R>],
    spans: &[Span<R>],
    c: &Common<R>,
    tm: R,
    len: R,
    light: V3<R>,
    half: V3<R>,
) -> Option<([R; 3], R)> {
    let mut tau = R::zero();
    let mut weighted = [R::zero(); 3];
    let mut opaque = 0u32;
    let mut opaque_rgb = [R::zero(); 3];
    for (l, sp) in layers.iter().zip(spans) {
        if !(sp.hit && tm >= sp.t_in && tm <= sp.t_out) {
            continue;
        }
        let p = sp.o + sp.d * tm;
        let q = l.lut.classify(l.field.value(p));
        let alpha = q[3];
        if alpha <= R::zero() {
            continue;
        }
        let mut rgb = [q[0], q[1], q[2]];
        if l.shade {
            rgb = shade(l, c, p, rgb, light, half);
        }
        if alpha >= R::one() {
            opaque += 1;
            for ch in 0..3 {
                opaque_rgb[ch] = opaque_rgb[ch] + rgb[ch];
            }
            continue;
        }
        // τ_i = σ_i · len, σ_i = −ln(1 − α_i) · |d_i| / Δ_ref.
        let t = -(-alpha).ln_1p() * (len * sp.d.length() / c.ref_step);
        tau = tau + t;
        for ch in 0..3 {
            weighted[ch] = weighted[ch] + t * rgb[ch];
        }
    }
    if opaque > 0 {
        let inv = R::one() / R::of(opaque as f64);
        return Some((opaque_rgb.map(|x| x * inv), R::one()));
    }
    if tau <= R::zero() {
        return None;
    }
    Some((weighted.map(|x| x / tau), -(-tau).exp_m1()))
}

/// Phong-shades a volume's sample with its own world-space normal, blending in from
/// unshaded where the gradient is tiny (as `cpu::shade::shade_sample`).
/// Mirrors `shaders/multi.wgsl: shade_layer`.
fn shade<R: Real>(
    l: &Prepared<'_, R>,
    c: &Common<R>,
    p: V3<R>,
    rgb: [R; 3],
    light: V3<R>,
    half: V3<R>,
) -> [R; 3] {
    shade_gradient(
        l.field.gradient(p),
        l.grad_thr,
        &l.normal,
        &c.k,
        rgb,
        light,
        half,
    )
}
