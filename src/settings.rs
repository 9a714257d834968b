//! Render settings shared by every backend.
//!
//! One struct, serialisable to JSON, read by the CPU oracle (`cpu::raycast`) and the
//! GPU port alike, so a setting means the same thing everywhere.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

crate::choice_enum! {
    /// What a ray computes.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Mode: "mode" {
        /// Direct volume rendering: emission–absorption compositing through a transfer
        /// function (RGBA output).
        Dvr = "dvr",
        /// Maximum intensity projection of the raw values (scalar output).
        Mip = "mip",
        /// Minimum intensity projection of the raw values (scalar output).
        Minip = "minip",
        /// X-ray: the line integral of the raw values, in value × mm (scalar output).
        Xray = "xray",
        /// Maximum intensity difference accumulation (Bruckner & Gröller 2009): DVR whose
        /// accumulated colour fades where a sample raises the running maximum; `mida_gamma`
        /// moves it from DVR (−1) to MIP (+1) (RGBA output; see `cpu::modes`).
        Mida = "mida",
        /// Iso-surfaces only: the `iso_surfaces` composited front to back (RGBA output).
        /// DVR with iso-surfaces set draws both in one image.
        Iso = "iso",
    }
}

impl Mode {
    /// Whether the mode produces RGBA (through a transfer function or iso colours).
    pub fn rgba(self) -> bool {
        matches!(self, Mode::Dvr | Mode::Mida | Mode::Iso)
    }
}

/// One iso-surface: where the field crosses `value`, a surface of this colour and
/// opacity (per crossing, not per step).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IsoSurface {
    pub value: f64,
    pub color: [f64; 3],
    pub opacity: f64,
}

impl IsoSurface {
    /// Reads `VALUE:#RRGGBB:OPACITY`, e.g. `0.3:#ff0000:0.4` (the `#` is optional;
    /// opacity in [0, 1]).
    ///
    /// # Errors
    /// [`Error::Invalid`] naming `--iso` and what is wrong.
    pub fn parse(text: &str) -> Result<IsoSurface> {
        let bad = |why: String| Error::invalid("--iso", format!("'{text}': {why}"));
        let parts: Vec<&str> = text.split(':').collect();
        let [value, color, opacity] = parts[..] else {
            return Err(bad(
                "expected VALUE:COLOUR:OPACITY, e.g. 0.3:#ff0000:0.4".into()
            ));
        };
        let num = |t: &str, what: &str| {
            t.trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| bad(format!("{what} '{t}' is not a finite number")))
        };
        let hex = color.trim().strip_prefix('#').unwrap_or(color.trim());
        if hex.len() != 6 || !hex.chars().all(|c| c.is_ascii_hexdigit()) {
            return Err(bad(format!("colour '{color}' is not #rrggbb")));
        }
        let channel = |i: usize| {
            u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).expect("checked hex digits") as f64
                / 255.0
        };
        let opacity = num(opacity, "opacity")?;
        if !(0.0..=1.0).contains(&opacity) {
            return Err(bad(format!("opacity {opacity} must lie in [0, 1]")));
        }
        Ok(IsoSurface {
            value: num(value, "value")?,
            color: [channel(0), channel(1), channel(2)],
            opacity,
        })
    }
}

/// The most iso-surfaces one render may draw (the GPU's parameter block holds four).
pub const MAX_ISO_SURFACES: usize = 4;

crate::choice_enum! {
    /// The reconstruction filter used to sample the volume between voxel centres.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Filter: "filter" {
        /// The nearest voxel (box kernel, radius ½).
        Nearest = "nearest",
        /// Tent kernel (radius 1): trilinear interpolation.
        Trilinear = "trilinear",
        /// Cubic B-spline (radius 2) on the voxel values: smooth and approximating (it
        /// does not pass through the voxel values, and blurs).
        Bspline = "bspline",
        /// Cubic B-spline (radius 2) on prefiltered coefficients: interpolating, and the
        /// most accurate cubic (Unser's B-spline interpolation).
        BsplineInterp = "bspline-interp",
        /// Catmull–Rom cubic (Keys, a = −½; radius 2): interpolating.
        CatmullRom = "catmull-rom",
        /// Lanczos-2 windowed sinc (radius 2), weights normalised to sum to 1.
        Lanczos2 = "lanczos2",
        /// Lanczos-3 windowed sinc (radius 3), weights normalised to sum to 1.
        Lanczos3 = "lanczos3",
        /// Lanczos-4 windowed sinc (radius 4), weights normalised to sum to 1.
        Lanczos4 = "lanczos4",
        /// The full sinc over the whole grid and the clamp-to-edge extension beyond it (no
        /// window, no normalisation); O(n³) per sample, slow.
        Sinc = "sinc",
        /// The cubic B-spline of `bspline`, evaluated with 8 trilinear fetches instead of
        /// 64 taps (Sigg & Hadwiger 2005, `cpu::tricubic`); the same values to rounding. On
        /// the GPU with `hardware_filtering` the fetches go through the texture unit.
        BsplineFast = "cubic-bspline-fast" | "bspline-fast",
        /// The interpolating B-spline of `bspline-interp` (prefiltered coefficients),
        /// evaluated with 8 trilinear fetches like `cubic-bspline-fast`.
        BsplineFastInterp = "cubic-bspline-fast-interp" | "bspline-fast-interp",
    }
}

impl Filter {
    /// The distinct kernels (the two `*-fast` filters evaluate `Bspline`'s and
    /// `BsplineInterp`'s kernels another way; see [`Filter::FAST`]).
    pub const ALL: [Filter; 9] = [
        Filter::Nearest,
        Filter::Trilinear,
        Filter::Bspline,
        Filter::BsplineInterp,
        Filter::CatmullRom,
        Filter::Lanczos2,
        Filter::Lanczos3,
        Filter::Lanczos4,
        Filter::Sinc,
    ];
    /// The B-splines evaluated with 8 trilinear fetches (`cpu::tricubic`).
    pub const FAST: [Filter; 2] = [Filter::BsplineFast, Filter::BsplineFastInterp];
    /// The filter evaluating the same kernel tap by tap: `Bspline` for `BsplineFast`,
    /// `BsplineInterp` for `BsplineFastInterp`, the filter itself otherwise.
    pub fn exact(self) -> Filter {
        match self {
            Filter::BsplineFast => Filter::Bspline,
            Filter::BsplineFastInterp => Filter::BsplineInterp,
            f => f,
        }
    }
    /// Whether the GPU's texture unit can do the filter's interpolation
    /// (`hardware_filtering`): trilinear, and the fast B-splines' 8 trilinear fetches.
    pub fn hardware_filterable(self) -> bool {
        self == Filter::Trilinear || Filter::FAST.contains(&self)
    }
    /// Whether the filter samples prefiltered B-spline coefficients instead of the
    /// voxel values (`cpu::filter::prepare`).
    pub fn prefiltered(self) -> bool {
        matches!(self, Filter::BsplineInterp | Filter::BsplineFastInterp)
    }
    /// The kernel's radius in voxels (the grid's half-size for the full sinc).
    pub fn radius(self) -> usize {
        match self {
            Filter::Nearest | Filter::Trilinear => 1,
            Filter::Bspline
            | Filter::BsplineInterp
            | Filter::BsplineFast
            | Filter::BsplineFastInterp
            | Filter::CatmullRom
            | Filter::Lanczos2 => 2,
            Filter::Lanczos3 => 3,
            Filter::Lanczos4 => 4,
            Filter::Sinc => usize::MAX,
        }
    }
}

crate::choice_enum! {
    /// The finite-difference stencil for gradients.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum GradientMethod: "gradient method" {
        /// `(f(x+h) − f(x−h)) / 2h`: exact on quadratics.
        Central = "central",
        /// `(f(x+h) − f(x)) / h`: exact on linear functions only.
        Forward = "forward",
        /// 3D Sobel: central difference smoothed by `[1 2 1]/4` across the other two axes.
        Sobel = "sobel",
    }
}

crate::choice_enum! {
    /// Where the transfer function is applied.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Classification: "classification" {
        /// Interpolate the data, then classify each sample (the default, sharper).
        Post = "post",
        /// Classify every voxel, then interpolate opacity-weighted colours.
        Pre = "pre",
    }
}

crate::choice_enum! {
    /// The order samples are composited in.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Compositing: "compositing" {
        /// `C += (1 − A) α c; A += (1 − A) α`, nearest sample first; allows early ray
        /// termination.
        FrontToBack = "front-to-back",
        /// `C = α c + (1 − α) C`, farthest sample first (the "over" operator).
        BackToFront = "back-to-front",
    }
}

/// Direction of the light.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Light {
    /// A light at the eye: `L = −ray direction`.
    Headlight,
    /// A directional light: world-space direction *toward* the light.
    Direction([f64; 3]),
}

/// Phong shading parameters; the normal is the normalised negative gradient.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Shading {
    pub enabled: bool,
    pub ambient: f64,
    pub diffuse: f64,
    pub specular: f64,
    pub shininess: f64,
    pub light: Light,
    /// Gradient magnitudes below this fraction of the data range per voxel leave a
    /// sample unshaded (ramping in linearly from half of it), so that rounding noise in
    /// flat regions does not pick random normals.
    pub gradient_threshold: f64,
}

impl Default for Shading {
    fn default() -> Self {
        Shading {
            enabled: true,
            ambient: 0.3,
            diffuse: 0.7,
            specular: 0.3,
            shininess: 32.0,
            light: Light::Headlight,
            gradient_threshold: 1e-3,
        }
    }
}

/// Everything that decides how a scene becomes an image, for every backend.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RenderSettings {
    pub mode: Mode,
    pub filter: Filter,
    /// Step along the ray in voxels (index-space length). The last step of a ray is
    /// shortened to end exactly at the volume's boundary.
    pub step: f64,
    /// The step the transfer function's opacities are defined for (voxels).
    pub reference_step: f64,
    pub classification: Classification,
    pub compositing: Compositing,
    /// Front-to-back rays stop once their opacity reaches this (1 disables it).
    pub ert_threshold: f64,
    pub gradient: GradientMethod,
    /// Precompute a gradient volume and interpolate it, instead of differencing the
    /// reconstructed field at each sample.
    pub precompute_gradients: bool,
    pub shading: Shading,
    /// RGBA behind the volume (DVR).
    pub background: [f64; 4],
    /// Value of scalar pixels whose ray misses the volume (MIP, MinIP, X-ray).
    pub miss_value: f64,
    /// Lookup-table resolution of the transfer function.
    pub lut_size: usize,
    /// Also return the number of samples each ray took.
    pub sample_count: bool,
    /// GPU only: sample the volume through the texture unit's trilinear filtering
    /// instead of the exact manual interpolation (the trilinear filter, and the 8
    /// trilinear fetches of the `cubic-bspline-fast` filters; the CPU has one exact path
    /// and ignores this).
    pub hardware_filtering: bool,
    /// DVR with post-classification only: classify samples by (value, gradient
    /// magnitude) through this 2D transfer function instead of the scene's 1D one
    /// (`transfer2d`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub transfer_2d: Option<crate::transfer2d::TransferFunction2D>,
    /// DVR: skip cells of a min/max grid the transfer function leaves fully
    /// transparent (`cpu::skip`); the image does not change, only the work.
    pub skip_empty: bool,
    /// Edge of one empty-space-skipping cell, in voxels.
    pub block_size: usize,
    /// Restricts rays to this box (intersected with the volume's).
    pub clip_box: Option<ClipBox>,
    /// Per-pixel random ray-start offset in `[0, step)` from this seed (`accumulate`).
    pub jitter: Option<u32>,
    /// Per-pixel ray-start offset from a fixed 4×4 ordered pattern (interleaved
    /// sampling, one frame).
    pub interleaved: bool,
    /// MIDA's γ in [−1, 1]: −1 is DVR, 0 plain MIDA, 1 MIP (see `cpu::modes`).
    pub mida_gamma: f64,
    /// MIP/MinIP grey window `[width, centre]` in raw units: the output becomes
    /// `clamp((v − centre) / width + ½, 0, 1)` (rays that miss keep `miss_value`); `None`
    /// keeps the raw values.
    pub window: Option<[f64; 2]>,
    /// Iso-surfaces (mode `iso`, or together with DVR), at most [`MAX_ISO_SURFACES`].
    pub iso_surfaces: Vec<IsoSurface>,
    /// Opaque iso-surfaces: the first crossing ends the ray.
    pub iso_opaque: bool,
    /// Binary shadows on opaque iso-surfaces: a ray from the hit toward the light that
    /// crosses an iso-value again leaves the hit in shadow (ambient light only).
    pub iso_shadows: bool,
    /// Refine each crossing by linear interpolation between the two samples around it
    /// (off: the hit is the first sample past the crossing).
    pub iso_refine: bool,
    /// Restricts rays to the inside of a closed triangle mesh, or of the bricks mesh
    /// of the skipping grid (`cpu::clipmesh`). Not part of a settings file.
    #[serde(skip)]
    pub clip_mesh: Option<ClipMesh>,
}

crate::choice_enum! {
    /// The units a clipping mesh's vertices are given in.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum ClipMeshUnits: "clip-mesh units", default World {
        /// World millimetres (the volume's world frame).
        World = "world",
        /// Voxel indices (carried to world by the volume's affine).
        Voxel = "voxel",
    }
}

/// A clipping mesh (`cpu::clipmesh`).
#[derive(Clone, Debug, PartialEq)]
pub enum ClipMesh {
    /// A closed triangle mesh read from a file (`io::mesh`).
    Mesh {
        mesh: std::sync::Arc<crate::io::mesh::TriMesh>,
        units: ClipMeshUnits,
    },
    /// The boundary of the non-empty cells of the skipping grid for the current
    /// transfer function (renders exactly the image without a mesh).
    Bricks,
}

crate::choice_enum! {
    /// The space a clipping box is given in.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum ClipSpace: "clip space", default Voxel {
        /// Voxel indices: the box covers voxels `lo ..= hi`, i.e. index space
        /// `[lo − ½, hi + ½]` (fractional indices allowed).
        Voxel = "voxel",
        /// World millimetres: the box `[lo, hi]` in the volume's world frame.
        World = "world",
    }
}

/// An axis-aligned clipping box; rays see only box ∩ volume.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClipBox {
    pub lo: [f64; 3],
    pub hi: [f64; 3],
    pub space: ClipSpace,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            mode: Mode::Dvr,
            filter: Filter::Trilinear,
            step: 0.5,
            reference_step: 1.0,
            classification: Classification::Post,
            compositing: Compositing::FrontToBack,
            ert_threshold: 0.99,
            gradient: GradientMethod::Central,
            precompute_gradients: false,
            shading: Shading::default(),
            background: [0.0, 0.0, 0.0, 1.0],
            miss_value: 0.0,
            lut_size: crate::transfer::DEFAULT_LUT_SIZE,
            sample_count: false,
            hardware_filtering: false,
            transfer_2d: None,
            skip_empty: true,
            block_size: 32,
            clip_box: None,
            jitter: None,
            interleaved: false,
            mida_gamma: 0.0,
            window: None,
            iso_surfaces: Vec::new(),
            iso_opaque: false,
            iso_shadows: false,
            iso_refine: true,
            clip_mesh: None,
        }
    }
}

/// The most samples one ray may take (guards against a tiny step on a huge volume).
pub const MAX_SAMPLES_PER_RAY: f64 = 1e7;

/// The most samples one frame may take: about a minute of a large GPU's ray casting,
/// hours of the CPU oracle's (guards against a tiny step on a large image).
pub const MAX_SAMPLES_PER_FRAME: f64 = 1e12;

/// Refuses a ray march whose cost is absurd, before anything is computed: `per_ray`
/// (the longest ray's length over the step, `step` voxels; for one volume
/// [`crate::volume::diagonal`]` / step`) past [`MAX_SAMPLES_PER_RAY`], or `per_ray` over
/// the camera's rays past [`MAX_SAMPLES_PER_FRAME`]. Every ray caster (CPU and GPU:
/// single and multi-volume, adaptive, D²VR) calls it for every frame, and so do their
/// dry runs; `what` names the job in the error.
///
/// # Errors
/// [`Error::TooLarge`] naming `what`, the step, and the samples per ray or per frame.
pub fn check_ray_work(
    what: &str,
    step: f64,
    per_ray: f64,
    camera: &crate::camera::Camera,
) -> Result<()> {
    let rays = camera.width * camera.height;
    if per_ray.is_nan() || per_ray > MAX_SAMPLES_PER_RAY {
        return Err(Error::too_large(
            what,
            format!("step {step} gives up to {per_ray:.0} samples per ray"),
        ));
    }
    let total = per_ray * rays as f64;
    if total > MAX_SAMPLES_PER_FRAME {
        return Err(Error::too_large(
            what,
            format!(
                "step {step} gives up to {total:.1e} samples per frame ({per_ray:.0} per \
                 ray, {rays} rays; at most {MAX_SAMPLES_PER_FRAME:.0e}): use a larger step \
                 or a smaller image"
            ),
        ));
    }
    Ok(())
}

impl RenderSettings {
    /// Checks every number a user can set.
    pub fn validate(&self) -> Result<()> {
        let positive = |what: &str, x: f64| {
            if x.is_finite() && x > 0.0 {
                Ok(())
            } else {
                Err(Error::invalid(
                    what,
                    format!("{x} must be finite and positive"),
                ))
            }
        };
        positive("step", self.step)?;
        if self.step < 1e-4 {
            return Err(Error::invalid(
                "step",
                format!("{} voxels is below the minimum of 1e-4", self.step),
            ));
        }
        positive("reference step", self.reference_step)?;
        if !(self.ert_threshold > 0.0 && self.ert_threshold <= 1.0) {
            return Err(Error::invalid(
                "early-ray-termination threshold",
                format!("{} must lie in (0, 1]", self.ert_threshold),
            ));
        }
        if !(2..=1 << 20).contains(&self.lut_size) {
            return Err(Error::invalid(
                "lookup-table size",
                "must lie in 2 … 1048576",
            ));
        }
        let s = &self.shading;
        for (what, x) in [
            ("ambient", s.ambient),
            ("diffuse", s.diffuse),
            ("specular", s.specular),
            ("shininess", s.shininess),
            ("gradient threshold", s.gradient_threshold),
        ] {
            if !(x.is_finite() && x >= 0.0) {
                return Err(Error::invalid(what, format!("{x} must be finite and ≥ 0")));
            }
        }
        if let Light::Direction(d) = s.light {
            if !d.iter().all(|c| c.is_finite()) || d == [0.0; 3] {
                return Err(Error::invalid(
                    "light direction",
                    "must be finite and non-zero",
                ));
            }
        }
        if self.background.iter().any(|c| !(0.0..=1.0).contains(c)) {
            return Err(Error::invalid(
                "background",
                "RGBA components must lie in [0, 1]",
            ));
        }
        if !self.miss_value.is_finite() {
            return Err(Error::invalid("miss value", "must be finite"));
        }
        if let Some(t) = &self.transfer_2d {
            t.validate()?;
            if self.mode.rgba() && self.classification == Classification::Pre {
                return Err(Error::invalid(
                    "classification",
                    "a 2D transfer function classifies interpolated samples by their \
                     gradient magnitude: it needs post-classification",
                ));
            }
        }
        if !(1..=4096).contains(&self.block_size) {
            return Err(Error::invalid("block size", "must lie in 1 … 4096 voxels"));
        }
        if let Some(c) = &self.clip_box {
            if !c.lo.iter().chain(&c.hi).all(|x| x.is_finite()) || (0..3).any(|a| c.lo[a] > c.hi[a])
            {
                return Err(Error::invalid(
                    "clip box",
                    "needs finite corners with lo ≤ hi on every axis",
                ));
            }
        }
        if self.jitter.is_some() && self.interleaved {
            return Err(Error::invalid(
                "jitter",
                "random jitter and interleaved sampling exclude each other",
            ));
        }
        validate_modes(self)
    }
}

/// Checks the settings of MIDA, the MIP/MinIP window and the iso-surfaces (the modes
/// of `cpu::modes`; called by [`RenderSettings::validate`]).
fn validate_modes(s: &RenderSettings) -> Result<()> {
    if !(s.mida_gamma.is_finite() && (-1.0..=1.0).contains(&s.mida_gamma)) {
        return Err(Error::invalid(
            "MIDA gamma",
            format!("{} must lie in [-1, 1]", s.mida_gamma),
        ));
    }
    if let Some([w, c]) = s.window {
        if !(w.is_finite() && w > 0.0 && c.is_finite()) {
            return Err(Error::invalid(
                "window",
                format!("width {w} must be finite and positive, centre {c} finite"),
            ));
        }
    }
    if s.iso_surfaces.len() > MAX_ISO_SURFACES {
        return Err(Error::invalid(
            "iso-surfaces",
            format!("{} given, at most {MAX_ISO_SURFACES}", s.iso_surfaces.len()),
        ));
    }
    for iso in &s.iso_surfaces {
        if !iso.value.is_finite() {
            return Err(Error::invalid("iso-value", "must be finite"));
        }
        if iso.color.iter().any(|c| !(0.0..=1.0).contains(c)) {
            return Err(Error::invalid(
                "iso-surface colour",
                "components must lie in [0, 1]",
            ));
        }
        if !(0.0..=1.0).contains(&iso.opacity) {
            return Err(Error::invalid(
                "iso-surface opacity",
                format!("{} must lie in [0, 1]", iso.opacity),
            ));
        }
    }
    if s.mode == Mode::Iso && s.iso_surfaces.is_empty() {
        return Err(Error::invalid(
            "iso-surfaces",
            "mode iso needs at least one iso-surface",
        ));
    }
    let isos = s.mode == Mode::Iso || (s.mode == Mode::Dvr && !s.iso_surfaces.is_empty());
    if (s.mode == Mode::Mida || isos) && s.compositing == Compositing::BackToFront {
        return Err(Error::invalid(
            "compositing",
            "MIDA and iso-surfaces composite front to back only",
        ));
    }
    if s.iso_shadows && !s.iso_opaque {
        return Err(Error::invalid(
            "shadows",
            "shadow rays are cast from opaque iso-surfaces only (add --iso-opaque)",
        ));
    }
    Ok(())
}
