//! The CPU ray caster: the oracle every GPU ray-casting path is checked against.
//!
//! For each pixel a ray is generated in world space (`camera`), carried into the
//! volume's index space by the inverse affine, clipped to the volume's box
//! `[-0.5, n − 0.5]³`, and cut into steps of `step` voxels; the last step is shortened
//! to end exactly on the box. Each step is represented by the sample at its midpoint,
//! weighted by its length (the midpoint rule), so with `step = 1` on an axis-aligned
//! view the samples fall exactly on voxel centres.
//!
//! Modes (Fluør 2006 §2.1–2.4, Gavrilov & Turlapov §2):
//! - **DVR**, emission–absorption: `α' = 1 − (1 − α)^(Δs/Δs₀)` per step; front to back
//!   `C += (1 − A) α' c`, `A += (1 − A) α'` with early ray termination once
//!   `A ≥ ert_threshold`; back to front `C = α' c + (1 − α') C`. Post-classification
//!   interpolates the data and classifies each sample; pre-classification classifies
//!   every voxel and interpolates opacity-weighted colours `(αr, αg, αb, α)`.
//!   Phong shading with the normal `n = −∇f/|∇f|` (two-sided):
//!   `c' = c (k_a + k_d |n·L|) + k_s |n·H|^s`.
//!   With a 2D transfer function (`RenderSettings::transfer_2d`, see `transfer2d`)
//!   post-classification reads the table at (value, |world-space gradient|).
//! - **MIP / MinIP**: the maximum / minimum sample.
//! - **X-ray**: `Σ f(p_k) Δℓ_k`, the line integral in value × mm.
//! - **MIDA**, the MIP/MinIP grey window and **iso-surfaces** (alone or with DVR): see
//!   [`super::modes`].
//!
//! Pixels are independent and every sum runs in a fixed order, so the result is
//! bit-identical for any number of threads. The same code runs in f64 (the oracle) and
//! f32 (the fair CPU baseline).
//!
//! This file holds the set-up and the per-ray loops. What they are built from sits
//! below it, each piece importing nothing above itself: the fields sampled
//! ([`super::field`]), one sample's classification, shading, opacity correction and
//! compositing ([`super::shade`]), the step grid and the batched kernels
//! ([`super::march`]), the jittered starts ([`super::jitter`]) and the slab test
//! ([`crate::real::intersect_box`]).

use super::field::box_hi;
pub use super::field::{Field, GridField, PhantomField};
use super::filter::prepare;
use super::grid::Grid;
use super::shade::{
    classify_sample, light_half, over, over_background, shade_sample, transmit_pow, under_until,
    SampleSetup, ShadingR,
};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::real::{intersect_box, Real, M3, V3};
use crate::settings::{
    Classification, Compositing, Filter, GradientMethod, Light, Mode, RenderSettings,
};
use crate::transfer::{LutR, TransferFunction};
use crate::volume::AnyVolume;
use glam::{DMat3, DMat4};
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// What a render returns.
#[derive(Clone, Debug)]
pub struct RenderOutput {
    /// RGBA (DVR) or scalar (MIP, MinIP, X-ray) image.
    pub image: Frame,
    /// Samples taken per ray, when asked for.
    pub samples: Option<Frame>,
    /// Total samples over all rays.
    pub total_samples: u64,
}

impl RenderOutput {
    /// Assembles an output from the image and the per-ray sample counts (row by row);
    /// the counts become a scalar frame when `keep_counts`. Shared by every backend.
    pub fn from_counts(image: Frame, counts: &[u32], keep_counts: bool) -> Self {
        let (width, height) = (image.width, image.height);
        RenderOutput {
            total_samples: counts.iter().map(|&c| c as u64).sum(),
            samples: keep_counts.then(|| Frame {
                width,
                height,
                channels: 1,
                data: counts.iter().map(|&c| c as f64).collect(),
            }),
            image,
        }
    }
}

/// Everything a ray needs, prepared once per render: what every sample needs
/// (`cpu::shade`), and what the ray caster adds around it.
pub(crate) struct Setup<R> {
    pub(crate) base: SampleSetup<R>,
    miss: R,
    /// Empty-space skipping (`cpu::skip`), when it applies.
    skip: Option<super::skip::Skipper<R>>,
    clip: Option<super::skip::ClipR<R>>,
    /// MIDA, window and iso-surface set-up (`cpu::modes`).
    pub(crate) modes: super::modes::ModeSetup<R>,
    /// The clipping mesh (`cpu::clipmesh`), if any.
    clip_mesh: Option<std::sync::Arc<super::clipmesh::ClipTriangles>>,
    /// DVR steps are classified in batches (`cpu::march`): post-classification with
    /// the 1D table, front to back.
    batched: bool,
    /// The table as the batches read it (`march::lut_pairs`), when batched.
    lut_pairs: Vec<[R; 8]>,
    /// MIP, MinIP and X-ray take their steps' values in batches (`march::values`).
    batched_values: bool,
    /// A brick's share of the samples, in a distributed render ([`render_owned`]).
    own: Option<Owned<R>>,
    /// Where the skipping grid's voxel 0 lies in the field's index space: a brick's
    /// origin (its cells are walked from `o − skip_origin`; the walk's ranges keep a
    /// step of margin each side, so its rounding cannot drop a visible sample), else 0.
    skip_origin: V3<R>,
}

/// Which loop a DVR ray's steps go through. Both give the same image to the last bit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// The fast kernels of `cpu::march` wherever they apply (DVR with
    /// post-classification, the 1D transfer function and front-to-back compositing):
    /// rays marched in packets of sixteen (unshaded, f32, trilinear, AVX-512), else
    /// each ray's steps classified in batches.
    Batched,
    /// One step at a time through the general per-sample code (the reference the
    /// batched kernel is tested against).
    PerSample,
}

/// Renders a volume with precision `R`. `progress(done_rows, total_rows)` is called as
/// rows finish (from worker threads).
pub fn render<R: Real>(
    volume: &AnyVolume,
    tf: &TransferFunction,
    camera: &Camera,
    settings: &RenderSettings,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<RenderOutput> {
    render_with::<R>(volume, tf, camera, settings, progress, Kernel::Batched)
}

/// [`render`] with a chosen DVR [`Kernel`].
pub fn render_with<R: Real>(
    volume: &AnyVolume,
    tf: &TransferFunction,
    camera: &Camera,
    settings: &RenderSettings,
    progress: &(dyn Fn(usize, usize) + Sync),
    kernel: Kernel,
) -> Result<RenderOutput> {
    settings.validate()?;
    tf.validate()?;
    check_cost(volume.dims(), camera, settings)?;
    Prepared::<R>::new(volume, settings)?.render_with(tf, camera, settings, progress, kernel)
}

/// The per-volume part of a CPU render, done once for many frames (frame
/// accumulation, stereo pairs, repeated renders): the finiteness check, the conversion
/// to `R` (with the gradients when they are precomputed), and the min/max grids of
/// empty-space skipping, built on first use for each block size and filter reach. Each
/// frame then pays only for its rays (and the transfer function's table).
pub struct Prepared<R: Real> {
    field: GridField<R>,
    affine: DMat4,
    gradient: (GradientMethod, bool),
    minmax: super::skip::MinMaxCache<R>,
}

impl<R: Real> Prepared<R> {
    /// Checks and converts `volume` for frames with `settings`' filter and gradients.
    pub fn new(volume: &AnyVolume, settings: &RenderSettings) -> Result<Self> {
        volume.check_finite("volume")?;
        let grid = Grid::<R>::from_any(volume);
        let gradient = (settings.gradient, settings.precompute_gradients);
        Ok(Prepared {
            field: GridField::new(grid, settings.filter, gradient.0, gradient.1),
            affine: volume.affine(),
            gradient,
            minmax: Default::default(),
        })
    }

    /// Whether frames with `settings` can render from this preparation: they keep
    /// the filter and gradients it was prepared for.
    pub fn serves(&self, settings: &RenderSettings) -> bool {
        settings.filter == self.field.filter
            && (settings.gradient, settings.precompute_gradients) == self.gradient
    }

    /// Renders a frame; `settings` must keep the filter and gradients prepared for
    /// (everything else, the camera and the transfer function may change).
    pub fn render(
        &self,
        tf: &TransferFunction,
        camera: &Camera,
        settings: &RenderSettings,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<RenderOutput> {
        self.render_with(tf, camera, settings, progress, Kernel::Batched)
    }

    /// [`Prepared::render`] with a chosen DVR [`Kernel`].
    pub fn render_with(
        &self,
        tf: &TransferFunction,
        camera: &Camera,
        settings: &RenderSettings,
        progress: &(dyn Fn(usize, usize) + Sync),
        kernel: Kernel,
    ) -> Result<RenderOutput> {
        if !self.serves(settings) {
            return Err(Error::invalid(
                "prepared volume",
                format!(
                    "prepared for the {:?} filter and {:?} gradients (precomputed: {}); \
                     this frame asks for {:?} and {:?} ({})",
                    self.field.filter,
                    self.gradient.0,
                    self.gradient.1,
                    settings.filter,
                    settings.gradient,
                    settings.precompute_gradients
                ),
            ));
        }
        check_cost(self.field.dims(), camera, settings)?;
        render_field_with(
            &self.field,
            self.affine,
            tf,
            camera,
            settings,
            progress,
            kernel,
            Some(&self.minmax),
        )
    }
}

/// Refuses renders of the `dims` volume whose cost is absurd: too many samples per ray
/// or per frame ([`crate::settings::check_ray_work`]), or the full sinc (O(n³) per
/// sample) on too much. The CPU and GPU casters and `voxlab render --dry-run` call it.
pub(crate) fn check_cost(
    dims: [usize; 3],
    camera: &Camera,
    settings: &RenderSettings,
) -> Result<()> {
    let per_ray = crate::volume::diagonal(dims) / settings.step;
    crate::settings::check_ray_work("render", settings.step, per_ray, camera)?;
    if settings.filter == Filter::Sinc {
        let voxels = (dims[0] * dims[1] * dims[2]) as f64;
        let work = camera.width as f64 * camera.height as f64 * per_ray * voxels;
        if work > 1e12 {
            return Err(Error::too_large(
                "full-sinc render",
                format!(
                    "about {work:.1e} multiply-adds (every sample sums the whole grid); \
                     use lanczos4, a smaller volume, a smaller image or a larger step"
                ),
            ));
        }
    }
    Ok(())
}

/// Renders any [`Field`] placed in the world by `affine` (index → world).
pub fn render_field<R: Real, F: Field<R>>(
    field: &F,
    affine: DMat4,
    tf: &TransferFunction,
    camera: &Camera,
    settings: &RenderSettings,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<RenderOutput> {
    render_field_with(
        field,
        affine,
        tf,
        camera,
        settings,
        progress,
        Kernel::Batched,
        None,
    )
}

/// [`render_field`] with a chosen DVR [`Kernel`], taking the skipping's min/max grid
/// from `cache` (and adding it there) when one is given (see [`Prepared`]).
#[allow(clippy::too_many_arguments)]
pub fn render_field_with<R: Real, F: Field<R>>(
    field: &F,
    affine: DMat4,
    tf: &TransferFunction,
    camera: &Camera,
    settings: &RenderSettings,
    progress: &(dyn Fn(usize, usize) + Sync),
    kernel: Kernel,
    cache: Option<&super::skip::MinMaxCache<R>>,
) -> Result<RenderOutput> {
    let setup = setup_for(field, affine, tf, settings, kernel, cache, None)?;
    Ok(cast_image(field, &setup, camera, settings, progress))
}

/// The samples of one brick of a tiling (`jobs::distributed_render`): those whose
/// midpoint lies in `[lo − ½, hi − ½)` on each axis of the whole grid's index space, a
/// face on the whole grid's border reaching to infinity, so that the bricks of a
/// tiling own every sample of every ray exactly once.
#[derive(Clone, Copy, Debug)]
pub struct Owned<R> {
    lo: [Option<R>; 3],
    hi: [Option<R>; 3],
}

impl<R: Real> Owned<R> {
    /// The samples of the brick of voxels `lo .. hi` of a grid of `whole` voxels.
    pub fn new(lo: [usize; 3], hi: [usize; 3], whole: [usize; 3]) -> Self {
        Owned {
            lo: std::array::from_fn(|a| (lo[a] > 0).then(|| R::of(lo[a] as f64 - 0.5))),
            hi: std::array::from_fn(|a| (hi[a] < whole[a]).then(|| R::of(hi[a] as f64 - 0.5))),
        }
    }

    /// Whether the brick owns the index-space point `p` (a shadow ray's sample).
    /// Mirrors `shaders/shared/modes_cast.wgsl: owns_point`.
    pub fn contains(&self, p: V3<R>) -> bool {
        (0..3).all(|a| {
            self.lo[a].is_none_or(|b| p.0[a] >= b) && self.hi[a].is_none_or(|b| p.0[a] < b)
        })
    }

    /// The steps of `steps` whose midpoints the brick owns: one run (each axis's
    /// coordinate of the midpoints is monotone along the ray, so each face keeps a
    /// prefix or a suffix of them), found by bisection against the exact midpoints.
    pub(crate) fn range(&self, steps: &super::march::Steps<R>) -> Option<(usize, usize)> {
        let (mut first, mut last) = (0usize, steps.n.checked_sub(1)?);
        for a in 0..3 {
            let faces = [
                self.lo[a].map(|b| (b, true)),
                self.hi[a].map(|b| (b, false)),
            ];
            for (bound, lower) in faces.into_iter().flatten() {
                let keep = |k: usize| {
                    let x = steps.segment(k).0 .0[a];
                    if lower {
                        x >= bound
                    } else {
                        x < bound
                    }
                };
                match (keep(first), keep(last)) {
                    (true, true) => {}
                    (false, false) => return None,
                    // A prefix is kept: it ends at the change.
                    (true, false) => last = last_like_first(first, last, keep),
                    // A suffix: it starts after the change.
                    (false, true) => first = last_like_first(first, last, keep) + 1,
                }
            }
        }
        Some((first, last))
    }
}

/// The last of `lo ..= hi` where the monotone `keep` still gives what it gives at
/// `lo` (it gives the other at `hi`), by bisection.
/// Mirrors `shaders/raycast.wgsl: last_like_first`.
fn last_like_first(lo: usize, hi: usize, keep: impl Fn(usize) -> bool) -> usize {
    let want = keep(lo);
    let (mut a, mut b) = (lo, hi);
    while b - a > 1 {
        let m = a + (b - a) / 2;
        if keep(m) == want {
            a = m;
        } else {
            b = m;
        }
    }
    a
}

/// One brick's share of a render ([`render_owned`]).
#[derive(Clone, Debug)]
pub struct Partial {
    /// Premultiplied `(C, A)` composited front to back (or back to front) from the
    /// brick's samples alone, without background (DVR); the maximum, minimum or sum of
    /// its samples without the window (MIP, MinIP, X-ray; undefined where `counts` is 0).
    pub image: Frame,
    /// Samples the brick took per ray.
    pub counts: Vec<u32>,
    /// Whether each ray meets the whole grid's box (within the clipping box): a ray
    /// that does not gets the background (or the miss value) in the whole render.
    pub hits: Vec<bool>,
}

/// Renders the samples of `own`'s brick only, for sort-last compositing: the rays,
/// their step grids and their samples are those of the whole grid's render (`field`
/// samples at the whole grid's coordinates, [`super::field::BrickField`]); the
/// window, the background and the miss value are left to the composite. DVR, MIP,
/// MinIP and X-ray.
///
/// # Errors
/// Invalid settings or transfer function; other modes.
pub fn render_owned<R: Real, F: Field<R>>(
    field: &F,
    affine: DMat4,
    tf: &TransferFunction,
    camera: &Camera,
    settings: &RenderSettings,
    own: Owned<R>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Partial> {
    render_owned_with(
        field,
        affine,
        tf,
        camera,
        settings,
        own,
        progress,
        Kernel::Batched,
    )
}

/// [`render_owned`] with the kernel chosen: `Batched` takes the packet kernel where it
/// applies (unshaded DVR in f32, trilinear, AVX-512), as a whole render does.
#[allow(clippy::too_many_arguments)]
pub fn render_owned_with<R: Real, F: Field<R>>(
    field: &F,
    affine: DMat4,
    tf: &TransferFunction,
    camera: &Camera,
    settings: &RenderSettings,
    own: Owned<R>,
    progress: &(dyn Fn(usize, usize) + Sync),
    kernel: Kernel,
) -> Result<Partial> {
    check_owned_settings(settings)?;
    check_cost(field.dims(), camera, settings)?;
    let s = owned_settings(settings);
    let setup = setup_for(field, affine, tf, &s, kernel, None, Some(own))?;
    let out = cast_image(field, &setup, camera, &s, progress);
    let (w, h) = (camera.width, camera.height);
    let mut hits = vec![false; w * h];
    hits.par_chunks_mut(w).enumerate().for_each(|(row, hit)| {
        for (col, x) in hit.iter_mut().enumerate() {
            let u = R::of(super::jitter::ray_offset(&s, col, row));
            *x = plan_ray(&setup, &camera.ray(col, row), u).is_some();
        }
    });
    let counts = out
        .samples
        .map(|f| f.data.iter().map(|&c| c as u32).collect())
        .unwrap_or_else(|| vec![0; w * h]);
    Ok(Partial {
        image: out.image,
        counts,
        hits,
    })
}

/// What a brick renders (`render_owned`): DVR (post- or pre-classified: a brick
/// classifies its own voxels and ghosts, the values the whole grid classifies there),
/// MIP, MinIP and X-ray (MIDA and iso-surfaces look along the whole ray), with a filter
/// of finite reach (the B-spline-interpolating and full-sinc filters reach across the
/// whole volume).
///
/// # Errors
/// Any other mode, iso-surfaces, those filters.
pub fn check_owned_settings(s: &RenderSettings) -> Result<()> {
    check_split_settings(s, false)
}

/// [`check_owned_settings`], or where `one_device` (the bricks rendered in turn by one
/// device, with the whole volume at hand: `gpu::raycast::render_bricked`) every mode,
/// each ray's state handed from one brick to the next (and each opaque iso-surface
/// hit's shadow ray, afterwards, in the light's order), and the interpolating
/// B-splines too, their coefficients (and pre-classified colours, precomputed
/// gradients) prefiltered over the whole volume.
///
/// # Errors
/// As [`check_owned_settings`]; on one device only the full sinc.
pub fn check_split_settings(s: &RenderSettings, one_device: bool) -> Result<()> {
    if !one_device
        && (!matches!(s.mode, Mode::Dvr | Mode::Mip | Mode::Minip | Mode::Xray)
            || !s.iso_surfaces.is_empty())
    {
        return Err(Error::invalid(
            "--mode",
            "bricks composite DVR, MIP, MinIP or X-ray (MIDA and iso-surfaces look along the \
             whole ray)",
        ));
    }
    if (s.filter.prefiltered() && !one_device) || s.filter == Filter::Sinc {
        return Err(Error::invalid(
            "--filter",
            format!(
                "{} reaches across the whole volume; bricks take the filters of finite \
                 reach (nearest, trilinear, bspline, catmull-rom, lanczos2-4, \
                 cubic-bspline-fast{})",
                s.filter.name(),
                if one_device {
                    ", bspline-interp, cubic-bspline-fast-interp"
                } else {
                    ""
                }
            ),
        ));
    }
    Ok(())
}

/// A brick's settings: the window, the background and the miss value are left to the
/// composite (`cpu::composite::finish`), and the samples are counted.
pub fn owned_settings(settings: &RenderSettings) -> RenderSettings {
    let mut s = settings.clone();
    s.window = None;
    s.background = [0.0; 4];
    s.sample_count = true;
    s
}

/// Everything the rays of a render share, checked and built once.
fn setup_for<R: Real, F: Field<R>>(
    field: &F,
    affine: DMat4,
    tf: &TransferFunction,
    settings: &RenderSettings,
    kernel: Kernel,
    cache: Option<&super::skip::MinMaxCache<R>>,
    own: Option<Owned<R>>,
) -> Result<Setup<R>> {
    settings.validate()?;
    tf.validate()?;
    let dims = field.dims();
    let lin = DMat3::from_mat4(affine);
    // World-space gradient = J⁻ᵀ × index-space gradient.
    let normal = M3::from_dmat3(lin.inverse().transpose());
    let lut = tf.lut(settings.lut_size).to_real::<R>();
    // A brick classifies its own voxels (with their ghosts), placed at its origin.
    let brick_origin = field.brick().map_or(V3::zero(), |(_, o)| {
        V3::new(R::of(o[0] as f64), R::of(o[1] as f64), R::of(o[2] as f64))
    });
    let voxels = field.voxel_values().or(field.brick().map(|(g, _)| g));
    let pre = match (settings.mode, settings.classification, voxels) {
        (Mode::Dvr | Mode::Mida, Classification::Pre, Some(values)) => Some((
            preclassify(values, &lut).map(|g| prepare(&g, settings.filter)),
            brick_origin,
        )),
        (Mode::Dvr | Mode::Mida, Classification::Pre, None) => {
            return Err(Error::invalid(
                "classification",
                "pre-classification needs a voxel grid",
            ))
        }
        _ => None,
    };
    let (lo_v, hi_v) = field.value_range();
    let s = &settings.shading;
    let setup = Setup {
        base: SampleSetup {
            to_index: affine.inverse(),
            normal,
            lo: V3::splat(R::of(-0.5)),
            hi: box_hi(dims),
            step: R::of(settings.step),
            ref_step: R::of(settings.reference_step),
            lut,
            lut2: match (&settings.transfer_2d, settings.mode) {
                (Some(t2), Mode::Dvr) => Some(t2.lut().to_real::<R>()),
                _ => None,
            },
            pre,
            filter: settings.filter,
            k: ShadingR {
                ambient: R::of(s.ambient),
                diffuse: R::of(s.diffuse),
                specular: R::of(s.specular),
                shininess: R::of(s.shininess),
            },
            shade: s.enabled && settings.mode.rgba(),
            light: match s.light {
                Light::Headlight => None,
                Light::Direction(d) => Some(V3::from_dvec(glam::DVec3::from_array(d).normalize())),
            },
            grad_thr: R::of(s.gradient_threshold * (hi_v - lo_v).max(f64::MIN_POSITIVE)),
            ert: R::of(settings.ert_threshold),
            bg: settings.background.map(R::of),
        },
        miss: R::of(settings.miss_value),
        skip: None,
        clip: settings.clip_box.as_ref().map(super::skip::ClipR::new),
        modes: super::modes::ModeSetup::new(settings, (lo_v, hi_v)),
        clip_mesh: None,
        batched: settings.mode == Mode::Dvr
            && settings.classification == Classification::Post
            && settings.compositing == Compositing::FrontToBack
            && settings.transfer_2d.is_none()
            && kernel == Kernel::Batched,
        lut_pairs: Vec::new(),
        batched_values: matches!(settings.mode, Mode::Mip | Mode::Minip | Mode::Xray)
            && kernel == Kernel::Batched,
        own,
        skip_origin: V3::zero(),
    };
    // Post-classification bounds what the filter samples; pre-classification the voxels.
    let skip_voxels = match settings.classification {
        Classification::Post => field.sampled_grid(),
        Classification::Pre => field.voxel_values(),
    };
    // A brick skips through the cells of its own voxels (what its filter samples, or
    // what it pre-classifies), placed at its origin.
    let (skip_grid, skip_origin) = match (skip_voxels, field.brick()) {
        (None, Some((g, _))) => (Some(g), brick_origin),
        _ => (skip_voxels, V3::zero()),
    };
    let setup = Setup {
        skip: skip_grid
            .and_then(|g| super::skip::Skipper::cached(g, &setup.base.lut, settings, cache)),
        skip_origin,
        lut_pairs: if setup.batched {
            super::march::lut_pairs(&setup.base.lut)
        } else {
            Vec::new()
        },
        clip_mesh: super::clipmesh::resolve(settings, affine, dims, skip_voxels, &setup.base.lut)?,
        ..setup
    };
    Ok(setup)
}

/// Casts every ray of `camera` through `setup`.
fn cast_image<R: Real, F: Field<R>>(
    field: &F,
    setup: &Setup<R>,
    camera: &Camera,
    settings: &RenderSettings,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> RenderOutput {
    let channels = if settings.mode.rgba() { 4 } else { 1 };
    let (w, h) = (camera.width, camera.height);
    let mut image = Frame::new(w, h, channels);
    let mut counts = vec![0u32; w * h];
    let done = AtomicUsize::new(0);
    // Unshaded DVR in f32 with the trilinear filter: rays in packets (`march`).
    let packets = packet_source(field, setup, settings);
    image
        .data
        .par_chunks_mut(w * channels)
        .zip(counts.par_chunks_mut(w))
        .enumerate()
        // A cancelled render unwinds from `progress`; the fuse stops the other rows.
        .panic_fuse()
        .for_each(|(row, (pixels, row_counts))| {
            if let Some((src, s32)) = &packets {
                if cast_row_packets(src, s32, camera, settings, row, pixels, row_counts) {
                    progress(done.fetch_add(1, Ordering::Relaxed) + 1, h);
                    return;
                }
            }
            for col in 0..w {
                let ray = camera.ray(col, row);
                let u = R::of(super::jitter::ray_offset(settings, col, row));
                let (px, n) = cast_ray(field, setup, settings.mode, settings.compositing, ray, u);
                for (c, v) in px.iter().take(channels).enumerate() {
                    pixels[col * channels + c] = v.f64();
                }
                row_counts[col] = n;
            }
            progress(done.fetch_add(1, Ordering::Relaxed) + 1, h);
        });
    RenderOutput::from_counts(image, &counts, settings.sample_count)
}

/// The packet kernel's inputs, when it applies: the render is batched, unshaded, in
/// f32 with the trilinear filter on a voxel grid, on a CPU with AVX-512, and no ray
/// can have 2²⁴ steps or more.
fn packet_source<'a, R: Real, F: Field<R>>(
    field: &'a F,
    setup: &'a Setup<R>,
    settings: &RenderSettings,
) -> Option<(super::march::Source<'a, f32>, &'a Setup<f32>)> {
    use std::any::TypeId;
    // A whole grid, or a brick sampled at its origin (a distributed render's).
    let (grid, origin) = match (field.sampled_grid(), field.brick()) {
        (Some(g), _) => (g, [0.0f32; 3]),
        (None, Some((g, o))) => (g, o.map(|x| x as f32)),
        (None, None) => return None,
    };
    if TypeId::of::<R>() != TypeId::of::<f32>() || !setup.batched || setup.base.shade {
        return None;
    }
    // SAFETY: R is f32 (checked above), so these have f32's layout.
    let (grid, s) = unsafe {
        (
            &*(grid as *const Grid<R> as *const Grid<f32>),
            &*(setup as *const Setup<R> as *const Setup<f32>),
        )
    };
    let src = super::march::Source {
        grid,
        origin,
        filter: s.base.filter,
        lut: &s.base.lut,
        pairs: &s.lut_pairs,
        speed: 1.0,
        ref_step: s.base.ref_step,
        e_full: s.base.step / s.base.ref_step,
    };
    // A brick's rays run through the whole grid's box.
    let max_steps = (crate::volume::diagonal(field.dims()) / settings.step).ceil() + 3.0;
    (max_steps < (1 << 24) as f64 && super::march::packets_usable(&src, max_steps as usize))
        .then_some((src, s))
}

/// Classifies every voxel: opacity-weighted colour grids `(αr, αg, αb, α)`.
/// Mirrors `shaders/raycast_prepare.wgsl: preclassify`.
pub fn preclassify<R: Real>(grid: &Grid<R>, lut: &LutR<R>) -> [Grid<R>; 4] {
    let rgba: Vec<[R; 4]> = grid
        .data
        .par_iter()
        .map(|&v| {
            let c = lut.classify(v);
            [c[0] * c[3], c[1] * c[3], c[2] * c[3], c[3]]
        })
        .collect();
    let ch = |c: usize| Grid {
        dims: grid.dims,
        data: rgba.iter().map(|p| p[c]).collect(),
    };
    [ch(0), ch(1), ch(2), ch(3)]
}

/// A ray carried into index space, clipped and cut into steps: what every mode marches.
pub(crate) struct Plan<R> {
    pub(crate) steps: super::march::Steps<R>,
    /// Voxels per unit `t` (`t` is world mm along a unit direction).
    pub(crate) speed: R,
    /// The steps inside the clipping mesh, when there is one.
    pub(crate) mesh: Option<super::clipmesh::MeshRanges>,
}

/// Plans `ray` (steps offset by `u·Δs`); `None` when nothing of it is left to sample.
/// Mirrors the start of `shaders/raycast.wgsl: cast_ray`.
pub(crate) fn plan_ray<R: Real>(s: &Setup<R>, ray: &crate::camera::Ray, u: R) -> Option<Plan<R>> {
    let o = V3::<R>::from_dvec(s.base.to_index.transform_point3(ray.origin));
    let d = V3::<R>::from_dvec(s.base.to_index.transform_vector3(ray.dir));
    let (t_in, t_out) = intersect_box(o, d, s.base.lo, s.base.hi)?;
    let mut t_in = t_in.max(R::of(ray.t_min));
    let mut t_out = t_out;
    if let Some(clip) = &s.clip {
        let (wo, wd) = (V3::from_dvec(ray.origin), V3::from_dvec(ray.dir));
        let (c0, c1) = clip.interval(o, d, wo, wd)?;
        t_in = t_in.max(c0);
        t_out = t_out.min(c1);
    }
    if t_out <= t_in {
        return None;
    }
    let speed = d.length();
    let dt = s.base.step / speed;
    // The virtual start of the (jittered) step grid; u = 0 gives t_s = t_in.
    let t_s = t_in - u * dt;
    let n = ((t_out - t_s) / dt - R::of(1e-3)).ceil().max(R::one());
    let n = n.to_usize().unwrap_or(1);
    // Step k covers [t_s + k dt, t_s + (k+1) dt]; the first starts at t_in, the last
    // ends at t_out. The clipping mesh keeps the step grid and takes only the samples
    // inside it.
    let mesh = s.clip_mesh.as_ref().map(|m| {
        let segs = m.segments(ray.origin, ray.dir, ray.t_min);
        super::clipmesh::MeshRanges::new(&segs, n, t_in, t_out, t_s, dt)
    });
    let steps = super::march::Steps {
        o,
        d,
        t_in,
        t_out,
        t_s,
        dt,
        n,
    };
    // A brick's steps: the same grid, its own samples only.
    let mesh = match &s.own {
        None => mesh,
        Some(own) => {
            let all = mesh.unwrap_or_else(|| super::clipmesh::MeshRanges::all(n));
            Some(match own.range(&steps) {
                Some((lo, hi)) => all.within(lo, hi),
                None => super::clipmesh::MeshRanges::none(),
            })
        }
    };
    Some(Plan { steps, speed, mesh })
}

/// Casts one ray; returns the pixel (RGBA, or the scalar in channel 0) and the number
/// of samples taken; `u` offsets the ray's steps by `u·Δs` (`cpu::jitter`).
/// Mirrors `shaders/raycast.wgsl: cast_ray`.
fn cast_ray<R: Real, F: Field<R>>(
    field: &F,
    s: &Setup<R>,
    mode: Mode,
    order: Compositing,
    ray: crate::camera::Ray,
    u: R,
) -> ([R; 4], u32) {
    let b = &s.base;
    let miss = if mode.rgba() {
        b.bg
    } else {
        [s.miss, R::zero(), R::zero(), R::zero()]
    };
    let Some(plan) = plan_ray(s, &ray, u) else {
        return (miss, 0);
    };
    let steps = plan.steps;
    let super::march::Steps {
        o,
        d,
        t_in,
        t_out,
        t_s,
        dt,
        n,
    } = steps;
    let speed = plan.speed;
    let e_full = b.step / b.ref_step;
    let segment = |k: usize| steps.segment(k);
    // MIDA and iso-surfaces march the unjittered grid from t_in.
    let span = super::modes::Span {
        o,
        d,
        t_in,
        t_out,
        dt,
        n: ((t_out - t_in) / dt - R::of(1e-3))
            .ceil()
            .max(R::one())
            .to_usize()
            .unwrap_or(1),
        speed,
    };
    let mesh_ranges = plan
        .mesh
        .unwrap_or_else(|| super::clipmesh::MeshRanges::all(n));
    match mode {
        // Over the steps inside the clipping mesh (all of them without one).
        Mode::Mip | Mode::Minip | Mode::Xray => super::clipmesh::cast_scalar_ranges(
            mode,
            &mesh_ranges,
            miss,
            s.modes.window,
            |lo, hi, sum| each_value(field, s, speed, &steps, lo, hi, |v, len| sum.take(v, len)),
        ),
        Mode::Mida => super::modes::cast_mida(field, b, &s.modes, &span, ray.dir),
        Mode::Iso => super::modes::cast_iso(field, b, &s.modes, &span, ray.dir, false),
        Mode::Dvr if !s.modes.iso.is_empty() => {
            super::modes::cast_iso(field, b, &s.modes, &span, ray.dir, true)
        }
        Mode::Dvr => {
            let (light, half) = light_half(b.light, ray.dir);
            let mut c = [R::zero(); 3];
            let mut a = R::zero();
            let mut taken = 0u32;
            let back = order == Compositing::BackToFront;
            let skip = s.skip.as_ref();
            let mut ranges = super::clipmesh::ClippedRanges::new(
                super::skip::SampleRanges::new(
                    skip,
                    o - s.skip_origin,
                    d,
                    (t_in, t_out),
                    t_s,
                    dt,
                    n,
                    back,
                ),
                mesh_ranges,
                back,
            );
            // A whole grid, or a brick sampled at its origin (as its field samples it).
            let sampled = match (field.sampled_grid(), field.brick()) {
                (Some(g), _) => Some((g, [R::zero(); 3])),
                (None, Some((g, o))) => Some((g, o.map(|x| R::of(x as f64)))),
                (None, None) => None,
            };
            let batched = match sampled {
                Some((grid, origin)) if s.batched && !back => Some(super::march::Source {
                    grid,
                    origin,
                    filter: b.filter,
                    lut: &b.lut,
                    pairs: &s.lut_pairs,
                    speed,
                    ref_step: b.ref_step,
                    e_full: b.step / b.ref_step,
                }),
                _ => None,
            };
            let mut batch = super::march::Batch::default();
            'ray: while let Some((k_lo, k_hi)) = ranges.next(skip) {
                if let Some(src) = &batched {
                    // The same samples and sums as the loop below, classified in batches.
                    let mut k = k_lo;
                    while k <= k_hi {
                        let m = (k_hi + 1 - k).min(super::march::BATCH);
                        batch.fill(src, &steps, k, m);
                        k += m;
                        // Only visible steps change the pixel; count up to the last one
                        // taken (all m unless the ray terminates early in this batch).
                        let mut left = batch.visible;
                        while left != 0 {
                            let l = left.trailing_zeros() as usize;
                            left &= left - 1;
                            let rgb = if b.shade {
                                let p = batch.position(l);
                                shade_sample(field, b, p, batch.colour(l), light, half)
                            } else {
                                batch.colour(l)
                            };
                            if under_until(&mut c, &mut a, rgb, batch.alpha_step[l], b.ert) {
                                taken += l as u32 + 1;
                                break 'ray;
                            }
                        }
                        taken += m as u32;
                    }
                    continue;
                }
                for i in k_lo..=k_hi {
                    let k = if back { k_lo + k_hi - i } else { i };
                    let (p, len) = segment(k);
                    taken += 1;
                    let (rgb, alpha) = classify_sample(field, b, p);
                    if alpha <= R::zero() {
                        continue;
                    }
                    // Opacity correction for a step of len·speed voxels.
                    let e = steps.exponent(k, len, speed, b.ref_step, e_full);
                    let alpha = R::one() - transmit_pow(R::one() - alpha, e);
                    let rgb = if b.shade {
                        shade_sample(field, b, p, rgb, light, half)
                    } else {
                        rgb
                    };
                    if back {
                        over(&mut c, &mut a, rgb, alpha);
                    } else if under_until(&mut c, &mut a, rgb, alpha, b.ert) {
                        break 'ray;
                    }
                }
            }
            (over_background(c, a, b.bg), taken)
        }
    }
}

/// Gives `take(value, length)` steps `lo ..= hi` of a ray in order (MIP, MinIP,
/// X-ray): in batches through `march::values` where they run in vector lanes (f32,
/// trilinear, AVX-512, on a whole grid or a brick sampled at its origin), else one at
/// a time through the field; the same values either way.
#[inline]
fn each_value<R: Real, F: Field<R>>(
    field: &F,
    s: &Setup<R>,
    speed: R,
    steps: &super::march::Steps<R>,
    lo: usize,
    hi: usize,
    mut take: impl FnMut(R, R),
) {
    use super::march::BATCH;
    let sampled = match (field.sampled_grid(), field.brick()) {
        (Some(g), _) => Some((g, [R::zero(); 3])),
        (None, Some((g, o))) => Some((g, o.map(|x| R::of(x as f64)))),
        (None, None) => None,
    };
    let lanes = sampled
        .filter(|_| s.batched_values)
        .map(|(grid, origin)| super::march::Source {
            grid,
            origin,
            filter: s.base.filter,
            lut: &s.base.lut,
            pairs: &s.lut_pairs,
            speed,
            ref_step: s.base.ref_step,
            e_full: s.base.step / s.base.ref_step,
        });
    let Some(src) = lanes.filter(|src| super::march::values_in_lanes(src, steps.n)) else {
        for k in lo..=hi {
            let (p, len) = steps.segment(k);
            take(field.value(p), len);
        }
        return;
    };
    let (mut value, mut len) = ([R::zero(); BATCH], [R::zero(); BATCH]);
    let mut k = lo;
    while k <= hi {
        let m = (hi + 1 - k).min(BATCH);
        super::march::values(&src, steps, k, m, &mut value, &mut len);
        for l in 0..m {
            take(value[l], len[l]);
        }
        k += m;
    }
}

/// One row of an unshaded DVR image (f32, trilinear, front to back), its rays marched
/// sixteen at a time in the lanes of a [`super::march::Packet`]: each lane steps its
/// own ray through its own ranges of steps (`SampleRanges`, `MeshRanges`), and takes
/// the row's next ray when its ray ends, so that no lane idles while rays are left.
/// Every ray gets the same samples and sums as in [`cast_ray`]. Returns false (having
/// written nothing) if the CPU cannot run packets.
fn cast_row_packets(
    src: &super::march::Source<f32>,
    s: &Setup<f32>,
    camera: &Camera,
    settings: &RenderSettings,
    row: usize,
    pixels: &mut [f64],
    counts: &mut [u32],
) -> bool {
    use super::clipmesh::{ClippedRanges, MeshRanges};
    use super::march::{Packet, PACKET};
    use super::skip::SampleRanges;
    let skip = s.skip.as_ref();
    let mut pk = Packet::default();
    if pk.step(src, s.base.ert).is_none() {
        return false;
    }
    // Two packets stepped at once, their stages interleaved: one's fetches overlap the
    // other's arithmetic (three or four at once were slower here: registers run out).
    const IN_TURN: usize = 2;
    let mut pks: [Packet; IN_TURN] = std::array::from_fn(|_| pk.clone());
    let mut ranges: [[Option<ClippedRanges<f32>>; PACKET]; IN_TURN] =
        std::array::from_fn(|_| std::array::from_fn(|_| None));
    let mut col_of = [[0usize; PACKET]; IN_TURN];
    let mut next_col = 0;
    let mut put = |col: usize, px: [f32; 4], n: u32| {
        for (c, v) in px.iter().enumerate() {
            pixels[col * 4 + c] = *v as f64;
        }
        counts[col] = n;
    };
    // Puts the row's next ray that has something to sample in lane l, writing the
    // pixels of the rays before it that have not.
    let mut refill = |l: usize,
                      pk: &mut Packet,
                      ranges: &mut [Option<ClippedRanges<f32>>; PACKET],
                      col_of: &mut [usize; PACKET],
                      put: &mut dyn FnMut(usize, [f32; 4], u32)| {
        while next_col < camera.width {
            let col = next_col;
            next_col += 1;
            let ray = camera.ray(col, row);
            let u = super::jitter::ray_offset(settings, col, row) as f32;
            let Some(plan) = plan_ray(s, &ray, u) else {
                put(col, s.base.bg, 0);
                continue;
            };
            let st = plan.steps;
            let mut r = ClippedRanges::new(
                SampleRanges::new(
                    skip,
                    st.o - s.skip_origin,
                    st.d,
                    (st.t_in, st.t_out),
                    st.t_s,
                    st.dt,
                    st.n,
                    false,
                ),
                plan.mesh.unwrap_or_else(|| MeshRanges::all(st.n)),
                false,
            );
            let Some(first) = r.next(skip) else {
                put(col, over_background([0.0; 3], 0.0, s.base.bg), 0);
                continue;
            };
            pk.start(l, &st, plan.speed, first);
            ranges[l] = Some(r);
            col_of[l] = col;
            return;
        }
    };
    for p in 0..IN_TURN {
        for l in 0..PACKET {
            refill(l, &mut pks[p], &mut ranges[p], &mut col_of[p], &mut put);
        }
    }
    while pks.iter().any(|pk| pk.live != 0) {
        // All packets stepped at once: the fetches of one overlap the others' arithmetic.
        let res =
            Packet::step_all(&mut pks, src, s.base.ert).expect("checked before the first ray");
        for (p, r) in res.into_iter().enumerate() {
            let (ended, hit) = r;
            let pk = &mut pks[p];
            let mut left = ended;
            while left != 0 {
                let l = left.trailing_zeros() as usize;
                left &= left - 1;
                if hit & (1 << l) == 0 {
                    if let Some((lo, hi)) = ranges[p][l].as_mut().and_then(|r| r.next(skip)) {
                        pk.k[l] = lo as i32;
                        pk.k_hi[l] = hi as i32;
                        continue;
                    }
                }
                let c = [pk.c[0][l], pk.c[1][l], pk.c[2][l]];
                put(
                    col_of[p][l],
                    over_background(c, pk.a[l], s.base.bg),
                    pk.taken[l],
                );
                pk.live &= !(1 << l);
                refill(l, pk, &mut ranges[p], &mut col_of[p], &mut put);
            }
        }
    }
    true
}
