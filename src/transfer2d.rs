//! 2D transfer functions over (data value, gradient magnitude): widgets, the 2D lookup
//! table, JSON and presets (Fluør 2006 ch. 3 and §5.1.2; Kniss et al. 2002).
//!
//! A sample's colour and opacity depend on its value `t` (mapped by the window map
//! `Ψ(t) = a·t + b` into the value domain `[d0, d1]`, as for 1D transfer functions) and
//! on the magnitude `g = |∇f|` of the world-space gradient of the raw data (value per
//! mm: the same gradient the Phong shading uses). Boundaries between materials have high
//! `g`; interiors low `g`, so a 2D transfer function can show a boundary and hide the
//! material on both sides of it.
//!
//! # Widgets
//! Each widget has a shape in the (mapped value `u`, gradient magnitude `g`) plane, an
//! RGBA (opacity per reference step, as in 1D) and a soft edge `border ∈ [0, 1]`: with
//! the shape's normalised distance `d` (0 at the centre line, 1 on the boundary), the
//! widget's weight is `w = clamp((1 − d)/border, 0, 1)` (a hard edge, `w = [d ≤ 1]`,
//! when `border = 0`), so opacity ramps linearly to zero over the outer `border`
//! fraction of the shape.
//! - **rectangle** `value [u0, u1] × gradient [g0, g1]`: `d = max(|u − uc|/hu,
//!   |g − gc|/hg)` (centre `(uc, gc)`, half sizes `hu, hg`);
//! - **ellipse** centre `(uc, gc)`, radii `(ru, rg)`: `d = √(((u − uc)/ru)² +
//!   ((g − gc)/rg)²)`; Fluør's circle is an ellipse with equal radii in screen units;
//! - **triangle** (Kniss's): the apex at value `apex` and gradient `g0`, widening
//!   linearly with the gradient magnitude to `apex ± half_width` at `g1`:
//!   `d = |u − apex| / (half_width (g − g0)/(g1 − g0))` for `g ∈ [g0, g1]` (zero weight
//!   outside; the soft edge runs across the value axis only);
//! - **profile**: a 1D transfer function's control points, the same at every gradient
//!   magnitude in `[g0, g1]` (all of them when absent), times the widget's RGBA;
//!   [`TransferFunction2D::from_1d`] uses it.
//!
//! # Overlaps
//! Where widgets overlap, with `a_i = w_i α_i`: the opacity is the largest,
//! `α = max_i a_i`, and the colour is the opacity-weighted mean
//! `c = Σ a_i c_i / Σ a_i` (where every `a_i` is 0, the plain mean of the covering
//! widgets' colours, weighted by `w_i`; a single covering widget gives its own colour
//! exactly). Max opacity keeps a widget's opacity from growing where another one
//! touches it; the weighted colour blends smoothly across soft edges.
//!
//! # Lookup table and gradient axis
//! The table has `nv × ng` RGBA entries (value fastest): entry `(i, j)` holds the
//! transfer function at `u_i = d0 + i (d1 − d0)/(nv − 1)` and at the gradient magnitude
//! `g_j` whose axis coordinate is `y = j/(ng − 1)`. The gradient axis runs over
//! `[0, g_max]` either linearly, `y = g/g_max`, or logarithmically,
//! `y = ln(1 + g/g₀) / ln(1 + g_max/g₀)` (`g₀ > 0`; fine steps at small magnitudes where
//! interiors and noise live). A sample is read with bilinear interpolation between the
//! four surrounding entries, clamped at the edges, by [`Lut2R::classify2d`] on the CPU
//! and by its WGSL twin `classify2d` in `shaders/shared/classify2d.wgsl` on the GPU,
//! with the same arithmetic.
//!
//! Faux shading ([`crate::transfer::faux_shade`]) may be switched on, with `α_max` the
//! largest opacity a widget can reach.

use crate::error::{Error, Result};
use crate::real::Real;
use crate::transfer::{
    eval_points, faux_shade, ControlPoint, Interpolation, TransferFunction, WindowMap,
};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Default table size `[value entries, gradient entries]`.
pub const DEFAULT_LUT_SIZE_2D: [usize; 2] = [1024, 256];
/// The most entries a 2D table may have (2²² RGBA: 64 MiB in f32 on the GPU).
pub const MAX_LUT_ENTRIES_2D: usize = 1 << 22;

crate::choice_enum! {
    /// How gradient magnitudes are laid out along the table's second axis.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum GradientAxis: "gradient axis", default Linear {
        /// `y = g / g_max`.
        Linear = "linear",
        /// `y = ln(1 + g/g₀) / ln(1 + g_max/g₀)`.
        Log = "log",
    }
}

/// A widget's shape in the (mapped value, gradient magnitude) plane.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Shape {
    /// The box `value × gradient`.
    Rectangle { value: [f64; 2], gradient: [f64; 2] },
    /// Centre `(value, gradient)` and radii.
    Ellipse { center: [f64; 2], radii: [f64; 2] },
    /// Apex at `(apex, gradient[0])`, half width `half_width` at `gradient[1]`.
    Triangle {
        apex: f64,
        half_width: f64,
        gradient: [f64; 2],
    },
    /// A 1D transfer function's control points, constant along the gradient axis over
    /// `gradient` (everywhere when absent).
    Profile {
        points: Vec<ControlPoint>,
        #[serde(default, skip_serializing_if = "Interpolation::is_linear")]
        interpolation: Interpolation,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        gradient: Option<[f64; 2]>,
    },
}

fn one4() -> [f64; 4] {
    [1.0; 4]
}

/// A shape with a colour, an opacity and a soft edge.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Widget {
    pub shape: Shape,
    /// RGB in [0, 1] and opacity per reference step; for a profile, a tint multiplying
    /// the profile's RGBA (default white, opaque: the profile unchanged).
    #[serde(default = "one4")]
    pub rgba: [f64; 4],
    /// The outer fraction of the shape over which opacity ramps to zero (0 = hard).
    #[serde(default)]
    pub border: f64,
}

/// The soft-edge weight at normalised distance `d` (1 on the boundary).
#[inline]
pub fn soft_edge(d: f64, border: f64) -> f64 {
    if d.is_nan() || d > 1.0 {
        0.0
    } else if border <= 0.0 {
        1.0
    } else {
        ((1.0 - d) / border).clamp(0.0, 1.0)
    }
}

impl Widget {
    /// The widget's weight and RGBA at mapped value `u`, gradient magnitude `g`
    /// (`None` where it does not reach).
    pub fn eval(&self, u: f64, g: f64) -> Option<(f64, [f64; 4])> {
        let (w, rgba) = match &self.shape {
            Shape::Rectangle { value, gradient } => {
                let (uc, hu) = (0.5 * (value[0] + value[1]), 0.5 * (value[1] - value[0]));
                let (gc, hg) = (
                    0.5 * (gradient[0] + gradient[1]),
                    0.5 * (gradient[1] - gradient[0]),
                );
                let d = ((u - uc).abs() / hu).max((g - gc).abs() / hg);
                (soft_edge(d, self.border), self.rgba)
            }
            Shape::Ellipse { center, radii } => {
                let x = (u - center[0]) / radii[0];
                let y = (g - center[1]) / radii[1];
                (soft_edge((x * x + y * y).sqrt(), self.border), self.rgba)
            }
            Shape::Triangle {
                apex,
                half_width,
                gradient,
            } => {
                if g < gradient[0] || g > gradient[1] {
                    return None;
                }
                let h = half_width * (g - gradient[0]) / (gradient[1] - gradient[0]);
                let du = (u - apex).abs();
                let d = if h > 0.0 {
                    du / h
                } else if du == 0.0 {
                    0.0
                } else {
                    f64::INFINITY
                };
                (soft_edge(d, self.border), self.rgba)
            }
            Shape::Profile {
                points,
                interpolation,
                gradient,
            } => {
                if let Some([g0, g1]) = gradient {
                    if g < *g0 || g > *g1 {
                        return None;
                    }
                }
                let c = eval_points(points, *interpolation, u);
                (1.0, std::array::from_fn(|k| c[k] * self.rgba[k]))
            }
        };
        (w > 0.0).then_some((w, rgba))
    }

    /// The largest opacity the widget reaches.
    pub fn alpha_max(&self) -> f64 {
        match &self.shape {
            Shape::Profile { points, .. } => {
                points.iter().map(|p| p.rgba[3]).fold(0.0, f64::max) * self.rgba[3]
            }
            _ => self.rgba[3],
        }
    }

    fn validate(&self, i: usize) -> Result<()> {
        let bad = |why: String| {
            Err(Error::invalid(
                "2D transfer function",
                format!("widget {i}: {why}"),
            ))
        };
        if self.rgba.iter().any(|c| !(0.0..=1.0).contains(c)) {
            return bad(format!("rgba {:?} must lie in [0, 1]", self.rgba));
        }
        if !(0.0..=1.0).contains(&self.border) {
            return bad(format!("border {} must lie in [0, 1]", self.border));
        }
        let range = |what: &str, r: [f64; 2]| {
            if r.iter().all(|x| x.is_finite()) && r[1] > r[0] {
                Ok(())
            } else {
                bad(format!("{what} {r:?} must be finite and increasing"))
            }
        };
        match &self.shape {
            Shape::Rectangle { value, gradient } => {
                range("value", *value)?;
                range("gradient", *gradient)
            }
            Shape::Ellipse { center, radii } => {
                if !center.iter().all(|x| x.is_finite())
                    || !radii.iter().all(|r| r.is_finite() && *r > 0.0)
                {
                    return bad("ellipse centre must be finite and radii positive".into());
                }
                Ok(())
            }
            Shape::Triangle {
                apex,
                half_width,
                gradient,
            } => {
                if !(apex.is_finite() && half_width.is_finite() && *half_width > 0.0) {
                    return bad("triangle apex must be finite and half width positive".into());
                }
                range("gradient", *gradient)
            }
            Shape::Profile {
                points,
                interpolation,
                gradient,
            } => {
                if let Some(g) = gradient {
                    range("gradient", *g)?;
                }
                // The 1D checks on the points.
                TransferFunction {
                    name: String::new(),
                    domain: [0.0, 1.0],
                    points: points.clone(),
                    window: WindowMap::default(),
                    interpolation: *interpolation,
                    faux_shading: None,
                }
                .validate()
                .map_err(|e| Error::invalid("2D transfer function", format!("widget {i}: {e}")))
            }
        }
    }
}

fn default_lut_size() -> [usize; 2] {
    DEFAULT_LUT_SIZE_2D
}

/// A 2D transfer function: widgets over (mapped value, gradient magnitude).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransferFunction2D {
    #[serde(default)]
    pub name: String,
    /// The mapped-value domain `[d0, d1]` the table covers.
    pub domain: [f64; 2],
    /// The largest gradient magnitude the table covers (raw value per mm); larger ones
    /// are clamped to it.
    pub gradient_max: f64,
    #[serde(default)]
    pub gradient_axis: GradientAxis,
    /// `g₀` of the logarithmic axis (default `g_max/100`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gradient_g0: Option<f64>,
    pub widgets: Vec<Widget>,
    /// The window map from raw values into the domain.
    #[serde(default)]
    pub window: WindowMap,
    /// Table size `[value entries, gradient entries]`.
    #[serde(default = "default_lut_size")]
    pub lut_size: [usize; 2],
    /// Faux shading exponent `k` (see [`faux_shade`]); absent = off.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub faux_shading: Option<f64>,
}

/// Built-in 2D presets: (name, JSON).
pub const PRESETS_2D: &[(&str, &str)] = &[
    ("ct-air-2d", include_str!("../data/tf/ct-air-2d.json")),
    ("ct-fat-2d", include_str!("../data/tf/ct-fat-2d.json")),
    ("ct-water-2d", include_str!("../data/tf/ct-water-2d.json")),
    (
        "ct-soft-tissue-2d",
        include_str!("../data/tf/ct-soft-tissue-2d.json"),
    ),
    ("ct-blood-2d", include_str!("../data/tf/ct-blood-2d.json")),
    ("ct-bone-2d", include_str!("../data/tf/ct-bone-2d.json")),
    (
        "microct-bone-2d",
        include_str!("../data/tf/microct-bone-2d.json"),
    ),
];

impl TransferFunction2D {
    /// Checks the domain, the gradient axis, the table size and every widget.
    pub fn validate(&self) -> Result<()> {
        let inv = |why: String| Err(Error::invalid("2D transfer function", why));
        let [d0, d1] = self.domain;
        if !(d0.is_finite() && d1.is_finite() && d1 > d0) {
            return inv(format!("domain [{d0}, {d1}] must be finite with d0 < d1"));
        }
        if !(self.gradient_max.is_finite() && self.gradient_max > 0.0) {
            return inv(format!(
                "gradient_max {} must be finite and positive",
                self.gradient_max
            ));
        }
        if let Some(g0) = self.gradient_g0 {
            if !(g0.is_finite() && g0 > 0.0) {
                return inv(format!("gradient_g0 {g0} must be finite and positive"));
            }
        }
        let [nv, ng] = self.lut_size;
        if nv < 2 || ng < 2 || nv.saturating_mul(ng) > MAX_LUT_ENTRIES_2D {
            return inv(format!(
                "lut_size {:?}: each side ≥ 2 and at most {MAX_LUT_ENTRIES_2D} entries",
                self.lut_size
            ));
        }
        if self.widgets.is_empty() {
            return inv("needs at least one widget".into());
        }
        for (i, w) in self.widgets.iter().enumerate() {
            w.validate(i)?;
        }
        if let Some(k) = self.faux_shading {
            if !(k.is_finite() && k > 0.0) {
                return inv(format!(
                    "faux shading exponent {k} must be finite and positive"
                ));
            }
        }
        if !(self.window.a.is_finite() && self.window.b.is_finite() && self.window.a != 0.0) {
            return Err(Error::invalid(
                "window map",
                "a must be finite and non-zero, b finite",
            ));
        }
        Ok(())
    }

    /// Parses and validates JSON.
    pub fn from_json(text: &str) -> Result<Self> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let tf: TransferFunction2D = serde_json::from_str(text).map_err(|e| {
            Error::invalid(
                "2D transfer function JSON",
                crate::json::explain(&e.to_string()),
            )
        })?;
        tf.validate()?;
        Ok(tf)
    }

    /// Pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a 2D transfer function always serialises")
    }

    /// Loads a JSON file.
    pub fn load(path: &Path) -> Result<Self> {
        let tf: TransferFunction2D = crate::json::read_file(path, "2D transfer function JSON")?;
        tf.validate()
            .map_err(|e| Error::format(path, "2D transfer function", e.to_string()))?;
        Ok(tf)
    }

    /// Saves as JSON (atomically).
    pub fn save(&self, path: &Path) -> Result<()> {
        let json = self.to_json();
        crate::io::write_atomic(path, |w| {
            w.write_all(json.as_bytes()).map_err(|e| Error::io(path, e))
        })
    }

    /// A built-in preset by name (see [`PRESETS_2D`]).
    pub fn preset(name: &str) -> Result<Self> {
        let (_, json) = PRESETS_2D.iter().find(|(n, _)| *n == name).ok_or_else(|| {
            let names: Vec<&str> = PRESETS_2D.iter().map(|(n, _)| *n).collect();
            Error::invalid(
                "2D transfer function preset",
                format!("'{name}' is not one of {}", names.join(", ")),
            )
        })?;
        Self::from_json(json)
    }

    /// A preset name or a JSON file path.
    pub fn preset_or_file(spec: &str) -> Result<Self> {
        if PRESETS_2D.iter().any(|(n, _)| *n == spec) {
            Self::preset(spec)
        } else if Path::new(spec).exists() {
            Self::load(Path::new(spec))
        } else {
            // Neither a preset nor a file: say both, with the presets.
            let names: Vec<&str> = PRESETS_2D.iter().map(|(n, _)| *n).collect();
            let close = crate::json::nearest(spec, &names)
                .map(|n| format!(" (did you mean {n}?)"))
                .unwrap_or_default();
            Err(Error::invalid(
                "2D transfer function",
                format!(
                    "'{}' is neither a preset nor a file{close}; the presets are {}",
                    crate::error::escape_controls(spec),
                    names.join(", ")
                ),
            ))
        }
    }

    /// The equivalent 2D transfer function of a 1D one: one profile widget, constant
    /// along the gradient axis, with the same domain, window and faux shading, and
    /// `value_entries` table entries along the value axis (2 along the gradient axis,
    /// which is all a constant needs). With `value_entries` equal to the 1D table's
    /// size the value nodes coincide and the two tables classify identically.
    pub fn from_1d(tf: &TransferFunction, value_entries: usize, gradient_max: f64) -> Self {
        TransferFunction2D {
            name: format!("{} (2D)", tf.name),
            domain: tf.domain,
            gradient_max,
            gradient_axis: GradientAxis::Linear,
            gradient_g0: None,
            widgets: vec![Widget {
                shape: Shape::Profile {
                    points: tf.points.clone(),
                    interpolation: tf.interpolation,
                    gradient: None,
                },
                rgba: [1.0; 4],
                border: 0.0,
            }],
            window: tf.window,
            lut_size: [value_entries.max(2), 2],
            faux_shading: tf.faux_shading,
        }
    }

    /// `g₀` of the logarithmic axis.
    pub fn g0(&self) -> f64 {
        self.gradient_g0.unwrap_or(self.gradient_max / 100.0)
    }

    /// The gradient magnitude at axis coordinate `y ∈ [0, 1]` (the inverse of the axis
    /// map).
    pub fn gradient_at_axis(&self, y: f64) -> f64 {
        match self.gradient_axis {
            GradientAxis::Linear => y * self.gradient_max,
            GradientAxis::Log => {
                let g0 = self.g0();
                g0 * ((y * (self.gradient_max / g0).ln_1p()).exp() - 1.0)
            }
        }
    }

    /// The largest opacity any widget reaches (faux shading's `α_max`).
    pub fn alpha_max(&self) -> f64 {
        self.widgets
            .iter()
            .map(Widget::alpha_max)
            .fold(0.0, f64::max)
    }

    /// The composited RGBA at mapped value `u` and gradient magnitude `g`, without
    /// faux shading (see the module docs for the overlap rule).
    pub fn eval(&self, u: f64, g: f64) -> [f64; 4] {
        let mut hits = self.widgets.iter().filter_map(|w| w.eval(u, g));
        let Some(first) = hits.next() else {
            return [0.0; 4];
        };
        let Some(second) = hits.next() else {
            let (w, c) = first;
            return [c[0], c[1], c[2], w * c[3]];
        };
        let (mut amax, mut asum, mut wsum) = (0.0f64, 0.0, 0.0);
        let (mut ca, mut cw) = ([0.0; 3], [0.0; 3]);
        for (w, c) in [first, second].into_iter().chain(hits) {
            let a = w * c[3];
            amax = amax.max(a);
            asum += a;
            wsum += w;
            for k in 0..3 {
                ca[k] += a * c[k];
                cw[k] += w * c[k];
            }
        }
        let rgb = if asum > 0.0 {
            ca.map(|x| x / asum)
        } else {
            cw.map(|x| x / wsum)
        };
        [rgb[0], rgb[1], rgb[2], amax]
    }

    /// [`eval`](Self::eval) with faux shading when it is on.
    pub fn eval_shaded(&self, u: f64, g: f64) -> [f64; 4] {
        let c = self.eval(u, g);
        match self.faux_shading {
            Some(k) => faux_shade(c, self.alpha_max(), k),
            None => c,
        }
    }

    /// The lookup table (see the module docs), built in parallel.
    pub fn lut(&self) -> Lut2 {
        let [nv, ng] = self.lut_size;
        let [d0, d1] = self.domain;
        let mut entries = vec![[0.0; 4]; nv * ng];
        entries.par_chunks_mut(nv).enumerate().for_each(|(j, row)| {
            let g = self.gradient_at_axis(j as f64 / (ng - 1) as f64);
            for (i, e) in row.iter_mut().enumerate() {
                *e = self.eval_shaded(d0 + (d1 - d0) * i as f64 / (nv - 1) as f64, g);
            }
        });
        Lut2 {
            domain: self.domain,
            window: self.window,
            gradient_max: self.gradient_max,
            gradient_axis: self.gradient_axis,
            g0: self.g0(),
            size: self.lut_size,
            entries,
        }
    }

    /// The table's coordinate maps without its entries (the GPU's uniforms).
    pub fn coordinates(&self) -> Lut2Coordinates {
        Lut2Coordinates::new(
            self.domain,
            self.window,
            self.gradient_max,
            self.gradient_axis,
            self.g0(),
            self.lut_size,
        )
    }
}

/// A 2D transfer function sampled into `nv × ng` RGBA entries (value fastest).
#[derive(Clone, Debug, PartialEq)]
pub struct Lut2 {
    pub domain: [f64; 2],
    pub window: WindowMap,
    pub gradient_max: f64,
    pub gradient_axis: GradientAxis,
    pub g0: f64,
    pub size: [usize; 2],
    pub entries: Vec<[f64; 4]>,
}

/// The affine and logarithmic maps from (raw value, gradient magnitude) to table
/// coordinates: `x = v_scale·t + v_offset`; `y = g_scale·g` (linear) or
/// `y = g_scale·ln(1 + g·g0_inv)` (log).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lut2Coordinates {
    pub v_scale: f64,
    pub v_offset: f64,
    pub g_scale: f64,
    pub g0_inv: f64,
    pub log: bool,
    pub size: [usize; 2],
}

impl Lut2Coordinates {
    fn new(
        domain: [f64; 2],
        window: WindowMap,
        gradient_max: f64,
        axis: GradientAxis,
        g0: f64,
        size: [usize; 2],
    ) -> Self {
        let [nv, ng] = size;
        let k = (nv - 1) as f64 / (domain[1] - domain[0]);
        let log = axis == GradientAxis::Log;
        let g_scale = if log {
            (ng - 1) as f64 / (gradient_max / g0).ln_1p()
        } else {
            (ng - 1) as f64 / gradient_max
        };
        Lut2Coordinates {
            v_scale: window.a * k,
            v_offset: (window.b - domain[0]) * k,
            g_scale,
            g0_inv: 1.0 / g0,
            log,
            size,
        }
    }

    /// The two vec4s of `RaycastParams` (`tf2d_a`, `tf2d_b`) for an enabled table.
    pub fn uniforms(&self) -> [[f32; 4]; 2] {
        [
            [
                self.v_scale as f32,
                self.v_offset as f32,
                (self.size[0] - 1) as f32,
                (self.size[1] - 1) as f32,
            ],
            [
                self.g_scale as f32,
                self.g0_inv as f32,
                self.log as u32 as f32,
                1.0,
            ],
        ]
    }
}

/// A [`Lut2`] in the working precision `R`, with its coordinate maps.
#[derive(Clone, Debug)]
pub struct Lut2R<R> {
    pub v_scale: R,
    pub v_offset: R,
    pub g_scale: R,
    pub g0_inv: R,
    pub log: bool,
    pub size: [usize; 2],
    pub entries: Vec<[R; 4]>,
}

impl Lut2 {
    /// The coordinate maps.
    pub fn coordinates(&self) -> Lut2Coordinates {
        Lut2Coordinates::new(
            self.domain,
            self.window,
            self.gradient_max,
            self.gradient_axis,
            self.g0,
            self.size,
        )
    }

    /// Converts to precision `R`.
    pub fn to_real<R: Real>(&self) -> Lut2R<R> {
        let c = self.coordinates();
        Lut2R {
            v_scale: R::of(c.v_scale),
            v_offset: R::of(c.v_offset),
            g_scale: R::of(c.g_scale),
            g0_inv: R::of(c.g0_inv),
            log: c.log,
            size: self.size,
            entries: self
                .entries
                .iter()
                .map(|e| [R::of(e[0]), R::of(e[1]), R::of(e[2]), R::of(e[3])])
                .collect(),
        }
    }
}

impl<R: Real> Lut2R<R> {
    /// The table's gradient coordinate of magnitude `g`, clamped to `[0, ng − 1]`.
    /// Mirrors `shaders/shared/classify2d.wgsl: gradient_coordinate`.
    #[inline]
    pub fn gradient_coordinate(&self, g: R) -> R {
        let y = if self.log {
            self.g_scale * (R::one() + g * self.g0_inv).ln()
        } else {
            self.g_scale * g
        };
        y.max(R::zero()).min(R::of((self.size[1] - 1) as f64))
    }

    /// Classifies raw value `t` at gradient magnitude `g`: bilinear interpolation
    /// between the four surrounding entries, clamped at the edges.
    /// Mirrors `shaders/shared/classify2d.wgsl: classify2d`.
    #[inline]
    pub fn classify2d(&self, t: R, g: R) -> [R; 4] {
        let [nv, ng] = self.size;
        let x = (self.v_scale * t + self.v_offset)
            .max(R::zero())
            .min(R::of((nv - 1) as f64));
        let y = self.gradient_coordinate(g);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let i0 = x0.to_usize().unwrap_or(0).min(nv - 1);
        let j0 = y0.to_usize().unwrap_or(0).min(ng - 1);
        let i1 = (i0 + 1).min(nv - 1);
        let j1 = (j0 + 1).min(ng - 1);
        let e = &self.entries;
        let (a, b) = (&e[j0 * nv + i0], &e[j0 * nv + i1]);
        let (c, d) = (&e[j1 * nv + i0], &e[j1 * nv + i1]);
        std::array::from_fn(|k| {
            let r0 = a[k] + fx * (b[k] - a[k]);
            let r1 = c[k] + fx * (d[k] - c[k]);
            r0 + fy * (r1 - r0)
        })
    }
}
