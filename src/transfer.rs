//! 1D transfer functions: RGBA control points over a domain, the window/level map Ψ,
//! lookup tables, JSON and presets.
//!
//! A raw data value `t` is first mapped by the window map `Ψ(t) = a·t + b` into the
//! transfer function's domain `[d0, d1]`; the RGBA there is the piecewise-linear
//! interpolation of the control points (constant beyond the first and last). Opacity is
//! per reference step `Δs₀ = 1` voxel; colours are not premultiplied.
//!
//! Renderers do not evaluate the control points per sample: they use a [`Lut`] of
//! `n` entries at `d0 + k (d1 − d0)/(n − 1)`, read with linear interpolation between
//! entries and clamped at the ends, exactly as a GPU reads a 1D texture.

use crate::error::{Error, Result};
use crate::real::Real;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Default lookup-table resolution.
pub const DEFAULT_LUT_SIZE: usize = 4096;

/// One control point: a mapped value and its colour and opacity.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControlPoint {
    pub value: f64,
    /// Red, green, blue in [0, 1]; alpha is the opacity per voxel-length step.
    pub rgba: [f64; 4],
}

/// The affine window map `Ψ(t) = a·t + b` applied to raw values before lookup.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WindowMap {
    pub a: f64,
    pub b: f64,
}

impl Default for WindowMap {
    fn default() -> Self {
        WindowMap { a: 1.0, b: 0.0 }
    }
}

impl WindowMap {
    /// The map that sends the window `[level − width/2, level + width/2]` of raw values
    /// onto the domain `[d0, d1]`.
    pub fn from_window_level(width: f64, level: f64, domain: [f64; 2]) -> Result<Self> {
        if !(width.is_finite() && width > 0.0 && level.is_finite()) {
            return Err(Error::invalid(
                "window",
                format!("width {width} must be positive and level {level} finite"),
            ));
        }
        let a = (domain[1] - domain[0]) / width;
        let b = domain[0] - a * (level - width / 2.0);
        Ok(WindowMap { a, b })
    }
    #[inline(always)]
    pub fn apply(&self, t: f64) -> f64 {
        self.a * t + self.b
    }
}

/// A 1D RGBA transfer function.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransferFunction {
    #[serde(default)]
    pub name: String,
    /// The domain `[d0, d1]` of mapped values the lookup table covers.
    pub domain: [f64; 2],
    /// Control points, sorted by value.
    pub points: Vec<ControlPoint>,
    /// The window map from raw data values into the domain.
    #[serde(default)]
    pub window: WindowMap,
    /// How colour and opacity run between control points (piecewise linear unless
    /// the JSON says `"interpolation": "bezier"`).
    #[serde(default, skip_serializing_if = "Interpolation::is_linear")]
    pub interpolation: Interpolation,
    /// Faux shading (limb darkening) exponent `k`: colours become
    /// `c·(α/α_max)^k` in the lookup table (see [`faux_shade`]); absent = off.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub faux_shading: Option<f64>,
}

/// How a transfer function runs between its control points, per channel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Interpolation {
    /// Straight lines between control points.
    #[default]
    Linear,
    /// One cubic Bézier segment per pair of neighbouring control points and channel,
    /// passing through the control points (Fluør 2006 §5.1.2). On `[v_i, v_{i+1}]`,
    /// `h = v_{i+1} − v_i`, `u = (v − v_i)/h`:
    /// `y(u) = Σ_k C(3,k) u^k (1−u)^(3−k) b_k` with `b_0 = y_i`, `b_3 = y_{i+1}`,
    /// `b_1 = y_i + h m_i/3`, `b_2 = y_{i+1} − h m_{i+1}/3`. The inner control points sit
    /// at abscissae `v_i + h/3` and `v_i + 2h/3`, so the curve is a function of the value
    /// (a C¹ cubic Hermite spline in Bézier form). Slopes `m_i` are Catmull–Rom:
    /// `(y_{i+1} − y_{i−1})/(v_{i+1} − v_{i−1})`, one-sided at the ends, 0 across
    /// coincident values. Results are clamped to [0, 1] (the curve may overshoot).
    Bezier,
}

impl Interpolation {
    pub fn is_linear(&self) -> bool {
        *self == Interpolation::Linear
    }
}

/// The cubic Bernstein polynomials `B_k(u) = C(3,k) u^k (1−u)^(3−k)`.
#[inline]
pub fn bernstein3(u: f64) -> [f64; 4] {
    let v = 1.0 - u;
    [v * v * v, 3.0 * u * v * v, 3.0 * u * u * v, u * u * u]
}

/// Faux shading (limb darkening, Fluør 2006 §2.5.3 after Helgeland & Andreassen 2004):
/// the colour is ramped to black as the opacity ramps to zero,
/// `c' = c·(α/α_max)^k`, where `α_max` is the transfer function's largest opacity and
/// `k > 0` sets how fast (k = 1: proportionally). Opacity is unchanged. Applied to the
/// lookup table once, so rendering costs nothing extra.
#[inline]
pub fn faux_shade(rgba: [f64; 4], alpha_max: f64, k: f64) -> [f64; 4] {
    if alpha_max <= 0.0 {
        return [0.0, 0.0, 0.0, rgba[3]];
    }
    let f = (rgba[3] / alpha_max).clamp(0.0, 1.0).powf(k);
    [rgba[0] * f, rgba[1] * f, rgba[2] * f, rgba[3]]
}

/// Evaluates control points at `u` with the given interpolation (exact, no table);
/// constant beyond the first and last point.
pub fn eval_points(pts: &[ControlPoint], interpolation: Interpolation, u: f64) -> [f64; 4] {
    if u <= pts[0].value {
        return pts[0].rgba;
    }
    let last = pts[pts.len() - 1];
    if u >= last.value {
        return last.rgba;
    }
    // First point strictly greater than u.
    let i = pts.partition_point(|p| p.value <= u);
    let (p0, p1) = (pts[i - 1], pts[i]);
    let h = p1.value - p0.value;
    let w = (u - p0.value) / h;
    match interpolation {
        Interpolation::Linear => {
            std::array::from_fn(|c| p0.rgba[c] + w * (p1.rgba[c] - p0.rgba[c]))
        }
        Interpolation::Bezier => {
            let b = bernstein3(w);
            let (m0, m1) = (bezier_slope(pts, i - 1), bezier_slope(pts, i));
            std::array::from_fn(|c| {
                let y0 = p0.rgba[c];
                let y1 = p1.rgba[c];
                let c1 = y0 + h * m0[c] / 3.0;
                let c2 = y1 - h * m1[c] / 3.0;
                (b[0] * y0 + b[1] * c1 + b[2] * c2 + b[3] * y1).clamp(0.0, 1.0)
            })
        }
    }
}

/// The Catmull–Rom slope of every channel at control point `i` (see
/// [`Interpolation::Bezier`]).
pub fn bezier_slope(pts: &[ControlPoint], i: usize) -> [f64; 4] {
    let (a, b) = (i.saturating_sub(1), (i + 1).min(pts.len() - 1));
    let dv = pts[b].value - pts[a].value;
    if dv <= 0.0 {
        return [0.0; 4];
    }
    std::array::from_fn(|c| (pts[b].rgba[c] - pts[a].rgba[c]) / dv)
}

/// Built-in presets: (name, JSON).
pub const PRESETS: &[(&str, &str)] = &[
    ("ct-bone", include_str!("../data/tf/ct-bone.json")),
    (
        "ct-soft-tissue",
        include_str!("../data/tf/ct-soft-tissue.json"),
    ),
    ("ct-vessels", include_str!("../data/tf/ct-vessels.json")),
    ("mri-brain", include_str!("../data/tf/mri-brain.json")),
    ("microct-bone", include_str!("../data/tf/microct-bone.json")),
    ("phantom", include_str!("../data/tf/phantom.json")),
    (
        "marschner-lobb",
        include_str!("../data/tf/marschner-lobb.json"),
    ),
    ("grayscale", include_str!("../data/tf/grayscale.json")),
    // Hounsfield-range presets (Fluør 2006 Table 3.1); see docs/transfer-functions-2d.md.
    ("ct-air", include_str!("../data/tf/ct-air.json")),
    ("ct-fat", include_str!("../data/tf/ct-fat.json")),
    ("ct-water", include_str!("../data/tf/ct-water.json")),
    ("ct-blood", include_str!("../data/tf/ct-blood.json")),
];

/// The Hounsfield-range CT presets, by tissue (each also exists as a 2D transfer
/// function named `NAME-2d`, see `transfer2d::PRESETS_2D`).
pub const HU_PRESETS: &[&str] = &[
    "ct-air",
    "ct-fat",
    "ct-water",
    "ct-soft-tissue",
    "ct-blood",
    "ct-bone",
];

impl TransferFunction {
    /// Checks the domain, the points (finite, sorted, colours in [0, 1]) and the map.
    pub fn validate(&self) -> Result<()> {
        let [d0, d1] = self.domain;
        if !(d0.is_finite() && d1.is_finite() && d1 > d0) {
            return Err(Error::invalid(
                "transfer function domain",
                format!("[{d0}, {d1}] must be finite with d0 < d1"),
            ));
        }
        if self.points.is_empty() {
            return Err(Error::invalid(
                "transfer function",
                "needs at least one control point",
            ));
        }
        for (i, p) in self.points.iter().enumerate() {
            if !p.value.is_finite() {
                return Err(Error::invalid(
                    "transfer function",
                    format!("point {i} has a non-finite value"),
                ));
            }
            if p.rgba.iter().any(|c| !(0.0..=1.0).contains(c)) {
                return Err(Error::invalid(
                    "transfer function",
                    format!("point {i}: rgba {:?} must lie in [0, 1]", p.rgba),
                ));
            }
            if i > 0 && p.value < self.points[i - 1].value {
                return Err(Error::invalid(
                    "transfer function",
                    format!("point {i} is out of order (values must not decrease)"),
                ));
            }
        }
        if let Some(k) = self.faux_shading {
            if !(k.is_finite() && k > 0.0) {
                return Err(Error::invalid(
                    "faux shading",
                    format!("exponent {k} must be finite and positive"),
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
        let tf: TransferFunction = serde_json::from_str(text).map_err(|e| {
            Error::invalid(
                "transfer function JSON",
                crate::json::explain(&e.to_string()),
            )
        })?;
        tf.validate()?;
        Ok(tf)
    }

    /// Pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a transfer function always serialises")
    }

    /// Loads a JSON file.
    pub fn load(path: &Path) -> Result<Self> {
        let tf: TransferFunction =
            crate::json::read_file(path, "transfer function JSON").map_err(|e| match e {
                // A 2D transfer function's widgets given where a 1D one is read.
                Error::Format {
                    path,
                    field,
                    message,
                } if message.contains("unknown field `widgets`")
                    || message.contains("unknown field `gradient_max`") =>
                {
                    Error::Format {
                        path,
                        field,
                        message: format!(
                            "{message}; this is a 2D transfer function (widgets over value × \
                             gradient magnitude): give it with --tf2d"
                        ),
                    }
                }
                other => other,
            })?;
        tf.validate()
            .map_err(|e| Error::format(path, "transfer function", e.to_string()))?;
        Ok(tf)
    }

    /// Saves as JSON (atomically).
    pub fn save(&self, path: &Path) -> Result<()> {
        let json = self.to_json();
        crate::io::write_atomic(path, |w| {
            w.write_all(json.as_bytes()).map_err(|e| Error::io(path, e))
        })
    }

    /// A built-in preset by name (see [`PRESETS`]).
    pub fn preset(name: &str) -> Result<Self> {
        let (_, json) = PRESETS.iter().find(|(n, _)| *n == name).ok_or_else(|| {
            let names: Vec<&str> = PRESETS.iter().map(|(n, _)| *n).collect();
            Error::invalid(
                "transfer function preset",
                format!("'{name}' is not one of {}", names.join(", ")),
            )
        })?;
        Self::from_json(json)
    }

    /// A preset name or a JSON file path.
    pub fn preset_or_file(spec: &str) -> Result<Self> {
        if PRESETS.iter().any(|(n, _)| *n == spec) {
            Self::preset(spec)
        } else if Path::new(spec).exists() {
            Self::load(Path::new(spec))
        } else {
            // Neither a preset nor a file: say both, with the presets.
            let names: Vec<&str> = PRESETS.iter().map(|(n, _)| *n).collect();
            let close = crate::json::nearest(spec, &names)
                .map(|n| format!(" (did you mean {n}?)"))
                .unwrap_or_default();
            Err(Error::invalid(
                "transfer function",
                format!(
                    "'{}' is neither a preset nor a file{close}; the presets are {}",
                    crate::error::escape_controls(spec),
                    names.join(", ")
                ),
            ))
        }
    }

    /// A soft grayscale ramp over the data range `[lo, hi]`: transparent black at `lo`
    /// to white with opacity 0.1 per voxel at `hi`. What `--tf auto` uses for files.
    pub fn auto_for_range(lo: f64, hi: f64) -> Self {
        let (lo, hi) = if hi > lo {
            (lo, hi)
        } else {
            (lo - 0.5, lo + 0.5)
        };
        TransferFunction {
            name: "auto".into(),
            domain: [lo, hi],
            points: vec![
                ControlPoint {
                    value: lo,
                    rgba: [0.0, 0.0, 0.0, 0.0],
                },
                ControlPoint {
                    value: lo + 0.1 * (hi - lo),
                    rgba: [0.1, 0.1, 0.1, 0.0],
                },
                ControlPoint {
                    value: hi,
                    rgba: [1.0, 1.0, 1.0, 0.1],
                },
            ],
            window: WindowMap::default(),
            interpolation: Interpolation::Linear,
            faux_shading: None,
        }
    }

    /// Evaluation at mapped value `u` (exact, no table), piecewise linear or Bézier
    /// per [`Interpolation`]; without faux shading.
    pub fn eval(&self, u: f64) -> [f64; 4] {
        eval_points(&self.points, self.interpolation, u)
    }

    /// The largest opacity of the control points (faux shading's `α_max`; Bézier
    /// overshoot is clamped to [0, 1] and may exceed it slightly, which the clamp in
    /// [`faux_shade`] absorbs).
    pub fn alpha_max(&self) -> f64 {
        self.points.iter().map(|p| p.rgba[3]).fold(0.0, f64::max)
    }

    /// [`eval`](Self::eval) followed by faux shading when it is on: what the lookup
    /// table holds.
    pub fn eval_shaded(&self, u: f64) -> [f64; 4] {
        let c = self.eval(u);
        match self.faux_shading {
            Some(k) => faux_shade(c, self.alpha_max(), k),
            None => c,
        }
    }

    /// The lookup table of `n ≥ 2` entries over the domain.
    pub fn lut(&self, n: usize) -> Lut {
        let n = n.max(2);
        let [d0, d1] = self.domain;
        let entries = (0..n)
            .map(|k| self.eval_shaded(d0 + (d1 - d0) * k as f64 / (n - 1) as f64))
            .collect();
        Lut {
            domain: self.domain,
            window: self.window,
            entries,
        }
    }
}

/// A transfer function sampled into `n` RGBA entries, with its window map.
#[derive(Clone, Debug, PartialEq)]
pub struct Lut {
    pub domain: [f64; 2],
    pub window: WindowMap,
    pub entries: Vec<[f64; 4]>,
}

/// A [`Lut`] in the working precision `R`, with the window map and the domain folded
/// into one affine map from raw value to table coordinate: `x = scale·t + offset`.
#[derive(Clone, Debug)]
pub struct LutR<R> {
    pub scale: R,
    pub offset: R,
    pub entries: Vec<[R; 4]>,
}

impl Lut {
    /// Converts to precision `R`. The table coordinate of raw value `t` is
    /// `x = (Ψ(t) − d0) / (d1 − d0) · (n − 1)`.
    pub fn to_real<R: Real>(&self) -> LutR<R> {
        let n = self.entries.len();
        let k = (n - 1) as f64 / (self.domain[1] - self.domain[0]);
        LutR {
            scale: R::of(self.window.a * k),
            offset: R::of((self.window.b - self.domain[0]) * k),
            entries: self
                .entries
                .iter()
                .map(|e| [R::of(e[0]), R::of(e[1]), R::of(e[2]), R::of(e[3])])
                .collect(),
        }
    }
}

impl<R: Real> LutR<R> {
    /// Classifies raw value `t`: linear interpolation between table entries, clamped at
    /// both ends. Mirrors the GPU's manual 1D-texture lookup.
    #[inline]
    pub fn classify(&self, t: R) -> [R; 4] {
        let n = self.entries.len();
        let last = R::of((n - 1) as f64);
        let x = (self.scale * t + self.offset).max(R::zero()).min(last);
        // x ≥ 0: truncation is the floor (and cheaper than a call to floor).
        let i0 = x.to_usize().unwrap_or(0).min(n - 1);
        let f = x - R::of(i0 as f64);
        let i1 = (i0 + 1).min(n - 1);
        let (a, b) = (&self.entries[i0], &self.entries[i1]);
        [
            a[0] + f * (b[0] - a[0]),
            a[1] + f * (b[1] - a[1]),
            a[2] + f * (b[2] - a[2]),
            a[3] + f * (b[3] - a[3]),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_load() {
        for (name, _) in PRESETS {
            let tf = TransferFunction::preset(name).unwrap();
            assert!(tf.points.len() >= 2, "{name}");
        }
    }

    #[test]
    fn window_level_maps_window_onto_domain() {
        let w = WindowMap::from_window_level(400.0, 40.0, [0.0, 1.0]).unwrap();
        assert!((w.apply(-160.0) - 0.0).abs() < 1e-15);
        assert!((w.apply(240.0) - 1.0).abs() < 1e-15);
        assert!((w.apply(40.0) - 0.5).abs() < 1e-15);
        assert!(WindowMap::from_window_level(0.0, 1.0, [0.0, 1.0]).is_err());
    }

    #[test]
    fn lut_reproduces_piecewise_linear_at_entries_and_between() {
        let tf = TransferFunction {
            name: String::new(),
            domain: [0.0, 1.0],
            points: vec![
                ControlPoint {
                    value: 0.25,
                    rgba: [0.0, 0.0, 0.0, 0.0],
                },
                ControlPoint {
                    value: 0.75,
                    rgba: [1.0, 0.5, 0.25, 1.0],
                },
            ],
            window: WindowMap { a: 2.0, b: -0.5 },
            interpolation: Interpolation::Linear,
            faux_shading: None,
        };
        tf.validate().unwrap();
        // 5 entries at 0, .25, .5, .75, 1: the TF is linear between entries, so the
        // table reproduces it exactly.
        let lut = tf.lut(5).to_real::<f64>();
        for &t in &[0.0, 0.3, 0.4, 0.5, 0.61, 0.75, 1.0] {
            let got = lut.classify(t);
            let want = tf.eval(2.0 * t - 0.5);
            for c in 0..4 {
                assert!((got[c] - want[c]).abs() < 1e-14, "t={t} c={c}");
            }
        }
    }

    #[test]
    fn json_round_trip_and_bad_json() {
        let tf = TransferFunction::preset("ct-bone").unwrap();
        let back = TransferFunction::from_json(&tf.to_json()).unwrap();
        assert_eq!(tf, back);
        assert!(TransferFunction::from_json("{").is_err());
        let bad = r#"{"domain":[1,0],"points":[{"value":0,"rgba":[0,0,0,0]}]}"#;
        assert!(TransferFunction::from_json(bad).is_err());
        let bad = r#"{"domain":[0,1],"points":[{"value":0,"rgba":[2,0,0,0]}]}"#;
        assert!(TransferFunction::from_json(bad).is_err());
    }
}
