//! The transfer-function editors' operations, with no window: what `voxlab view`'s 1-D
//! and 2-D editors do to a [`TransferFunction`] and a [`TransferFunction2D`] when the
//! user clicks, drags or deletes. Every operation leaves a function that
//! [`TransferFunction::validate`] (or [`TransferFunction2D::validate`]) accepts, so the
//! lab can hand it to the renderer at once, and `voxlab render --tf/--tf2d` reads what
//! the lab saves.
//!
//! Coordinates are the ones the functions are defined on: the 1-D editor's x axis is
//! the mapped value `u` over the function's domain, its y axis the opacity `α ∈ [0, 1]`
//! per reference step; the 2-D editor's axes are the mapped value and the gradient
//! magnitude `g ∈ [0, g_max]` (raw value per mm).

use crate::error::{Error, Result};
use crate::transfer::{ControlPoint, TransferFunction, WindowMap};
use crate::transfer2d::{Shape, TransferFunction2D, Widget};

/// Adds a control point at mapped value `value` with opacity `alpha` (both clamped to
/// the domain and to [0, 1]), coloured as the function is there now; it goes after any
/// points of the same value. Returns its index.
pub fn add_point(tf: &mut TransferFunction, value: f64, alpha: f64) -> usize {
    let value = value.clamp(tf.domain[0], tf.domain[1]);
    let c = tf.eval(value);
    let i = tf.points.partition_point(|p| p.value <= value);
    tf.points.insert(
        i,
        ControlPoint {
            value,
            rgba: [c[0], c[1], c[2], alpha.clamp(0.0, 1.0)],
        },
    );
    i
}

/// Moves point `i` to `(value, alpha)`. The value is held between its neighbours' (a
/// drag never reorders the points) and inside the domain, the opacity in [0, 1].
/// Returns where the point went.
///
/// # Errors
/// `i` is not a point.
pub fn move_point(tf: &mut TransferFunction, i: usize, value: f64, alpha: f64) -> Result<[f64; 2]> {
    check_point(tf, i)?;
    let lo = if i > 0 {
        tf.points[i - 1].value
    } else {
        tf.domain[0]
    };
    let hi = tf.points.get(i + 1).map_or(tf.domain[1], |p| p.value);
    let p = &mut tf.points[i];
    p.value = value.clamp(lo.min(hi), hi.max(lo));
    p.rgba[3] = alpha.clamp(0.0, 1.0);
    Ok([p.value, p.rgba[3]])
}

/// Deletes point `i`.
///
/// # Errors
/// `i` is not a point, or it is the only one (a function needs one).
pub fn delete_point(tf: &mut TransferFunction, i: usize) -> Result<()> {
    check_point(tf, i)?;
    if tf.points.len() == 1 {
        return Err(Error::invalid(
            "transfer function",
            "the last control point cannot be deleted",
        ));
    }
    tf.points.remove(i);
    Ok(())
}

/// Sets point `i`'s colour (each channel clamped to [0, 1]), keeping its opacity.
///
/// # Errors
/// `i` is not a point.
pub fn set_colour(tf: &mut TransferFunction, i: usize, rgb: [f64; 3]) -> Result<()> {
    check_point(tf, i)?;
    let p = &mut tf.points[i];
    for (c, v) in p.rgba.iter_mut().zip(rgb) {
        *c = v.clamp(0.0, 1.0);
    }
    Ok(())
}

fn check_point(tf: &TransferFunction, i: usize) -> Result<()> {
    if i < tf.points.len() {
        Ok(())
    } else {
        Err(Error::invalid(
            "transfer function",
            format!("no control point {i} (it has {})", tf.points.len()),
        ))
    }
}

/// The point nearest to `(value, alpha)` within `radius`, distances measured with the
/// domain's width and `alpha_range` (the opacity an editor's height shows) both scaled
/// to 1, so that a pick radius in pixels over the editor's size becomes `radius`; the
/// later point wins a tie.
pub fn nearest_point(
    tf: &TransferFunction,
    value: f64,
    alpha: f64,
    alpha_range: f64,
    radius: f64,
) -> Option<usize> {
    let width = tf.domain[1] - tf.domain[0];
    let mut best: Option<(usize, f64)> = None;
    for (i, p) in tf.points.iter().enumerate() {
        let d = ((p.value - value) / width).hypot((p.rgba[3] - alpha) / alpha_range);
        if d <= radius && best.is_none_or(|(_, b)| d <= b) {
            best = Some((i, d));
        }
    }
    best.map(|(i, _)| i)
}

/// The window `(width, level)` of raw values the function's window map sends onto its
/// domain (the inverse of [`WindowMap::from_window_level`]).
pub fn window_level(tf: &TransferFunction) -> (f64, f64) {
    let WindowMap { a, b } = tf.window;
    let width = (tf.domain[1] - tf.domain[0]) / a;
    (width, (tf.domain[0] - b) / a + 0.5 * width)
}

/// Sets the window map so that raw values `[level − width/2, level + width/2]` fill
/// the domain.
///
/// # Errors
/// A width that is not positive and finite, or a level that is not finite.
pub fn set_window_level(tf: &mut TransferFunction, width: f64, level: f64) -> Result<()> {
    tf.window = WindowMap::from_window_level(width, level, tf.domain)?;
    Ok(())
}

/// The shapes the 2-D editor adds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WidgetKind {
    Rectangle,
    Ellipse,
    Triangle,
}

/// Adds a widget of `kind` centred at `(value, gradient)` with half sizes
/// `(half_value, half_gradient)` (a triangle's apex sits at the bottom centre, its
/// half width at the top), colour `rgba` and a soft border of 0.2; it is drawn on top
/// of the others. Returns its index.
///
/// # Errors
/// Sizes that are not positive and finite, or a colour outside [0, 1].
pub fn add_widget(
    tf: &mut TransferFunction2D,
    kind: WidgetKind,
    center: [f64; 2],
    half: [f64; 2],
    rgba: [f64; 4],
) -> Result<usize> {
    if !half.iter().all(|h| h.is_finite() && *h > 0.0) || !center.iter().all(|c| c.is_finite()) {
        return Err(Error::invalid(
            "2D widget",
            format!("centre {center:?} must be finite and half sizes {half:?} positive"),
        ));
    }
    let [v, g] = center;
    let [hv, hg] = half;
    let shape = match kind {
        WidgetKind::Rectangle => Shape::Rectangle {
            value: [v - hv, v + hv],
            gradient: [g - hg, g + hg],
        },
        WidgetKind::Ellipse => Shape::Ellipse {
            center,
            radii: half,
        },
        WidgetKind::Triangle => Shape::Triangle {
            apex: v,
            half_width: hv,
            gradient: [g - hg, g + hg],
        },
    };
    tf.widgets.push(Widget {
        shape,
        rgba,
        border: 0.2,
    });
    if let Err(e) = tf.validate() {
        tf.widgets.pop();
        return Err(e);
    }
    Ok(tf.widgets.len() - 1)
}

/// The topmost widget (the last drawn) that reaches `(value, gradient)`.
pub fn widget_at(tf: &TransferFunction2D, value: f64, gradient: f64) -> Option<usize> {
    (0..tf.widgets.len())
        .rev()
        .find(|&i| tf.widgets[i].eval(value, gradient).is_some())
}

/// A widget's centre `(value, gradient)` and half sizes, as [`add_widget`] takes them
/// (a profile's centre is its points' midpoint and gradient band).
pub fn widget_box(w: &Widget) -> ([f64; 2], [f64; 2]) {
    let mid = |a: [f64; 2]| ([0.5 * (a[0] + a[1])], 0.5 * (a[1] - a[0]));
    match &w.shape {
        Shape::Rectangle { value, gradient } => {
            let (([v], hv), ([g], hg)) = (mid(*value), mid(*gradient));
            ([v, g], [hv, hg])
        }
        Shape::Ellipse { center, radii } => (*center, *radii),
        Shape::Triangle {
            apex,
            half_width,
            gradient,
        } => {
            let ([g], hg) = mid(*gradient);
            ([*apex, g], [*half_width, hg])
        }
        Shape::Profile {
            points, gradient, ..
        } => {
            let v = [points[0].value, points[points.len() - 1].value];
            let ([vc], hv) = mid(v);
            let ([g], hg) = gradient.map_or(([0.0], f64::INFINITY), mid);
            ([vc, g], [hv, hg])
        }
    }
}

/// Moves widget `i` by `(d_value, d_gradient)`.
///
/// # Errors
/// `i` is not a widget.
pub fn move_widget(tf: &mut TransferFunction2D, i: usize, delta: [f64; 2]) -> Result<()> {
    let [dv, dg] = delta;
    let w = widget_mut(tf, i)?;
    match &mut w.shape {
        Shape::Rectangle { value, gradient } => {
            value.iter_mut().for_each(|v| *v += dv);
            gradient.iter_mut().for_each(|g| *g += dg);
        }
        Shape::Ellipse { center, .. } => {
            center[0] += dv;
            center[1] += dg;
        }
        Shape::Triangle { apex, gradient, .. } => {
            *apex += dv;
            gradient.iter_mut().for_each(|g| *g += dg);
        }
        Shape::Profile {
            points, gradient, ..
        } => {
            points.iter_mut().for_each(|p| p.value += dv);
            if let Some(g) = gradient {
                g.iter_mut().for_each(|g| *g += dg);
            }
        }
    }
    Ok(())
}

/// Sets widget `i`'s half sizes `(half_value, half_gradient)` about its centre
/// ([`widget_box`]); a profile keeps its points.
///
/// # Errors
/// `i` is not a widget, or a size is not positive and finite.
pub fn resize_widget(tf: &mut TransferFunction2D, i: usize, half: [f64; 2]) -> Result<()> {
    if !half.iter().all(|h| h.is_finite() && *h > 0.0) {
        return Err(Error::invalid(
            "2D widget",
            format!("half sizes {half:?} must be positive and finite"),
        ));
    }
    let ([v, g], _) = widget_box(widget_mut(tf, i)?);
    let [hv, hg] = half;
    let w = widget_mut(tf, i)?;
    match &mut w.shape {
        Shape::Rectangle { value, gradient } => {
            *value = [v - hv, v + hv];
            *gradient = [g - hg, g + hg];
        }
        Shape::Ellipse { radii, .. } => *radii = half,
        Shape::Triangle {
            half_width,
            gradient,
            ..
        } => {
            *half_width = hv;
            *gradient = [g - hg, g + hg];
        }
        Shape::Profile { .. } => {}
    }
    Ok(())
}

/// A handle on a widget's box (its centre ± its half sizes, [`widget_box`]): the side it
/// holds on each axis, −1 the low edge, +1 the high edge, 0 neither (an edge's
/// midpoint). The four corners and the four edge midpoints are the eight handles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Handle {
    pub value: i8,
    pub gradient: i8,
}

/// The handles of widget `w` and where they are, `(value, gradient)`: the eight of its
/// box for rectangles, ellipses and triangles; none for a profile (whose points the
/// 1-D editor shapes).
pub fn widget_handles(w: &Widget) -> Vec<(Handle, [f64; 2])> {
    if matches!(w.shape, Shape::Profile { .. }) {
        return Vec::new();
    }
    let ([v, g], [hv, hg]) = widget_box(w);
    let mut out = Vec::with_capacity(8);
    for gradient in [-1i8, 0, 1] {
        for value in [-1i8, 0, 1] {
            if value == 0 && gradient == 0 {
                continue;
            }
            out.push((
                Handle { value, gradient },
                [v + f64::from(value) * hv, g + f64::from(gradient) * hg],
            ));
        }
    }
    out
}

/// Drags handle `h` of widget `i` to `(value, gradient)`: on each axis the handle
/// holds, the opposite edge stays where it is and the held edge goes to the point (past
/// the opposite edge, the box turns over); an axis it does not hold keeps its extent.
///
/// # Errors
/// `i` is not a widget, a profile (no handles), or the point is not finite.
pub fn drag_handle(tf: &mut TransferFunction2D, i: usize, h: Handle, to: [f64; 2]) -> Result<()> {
    if !to.iter().all(|x| x.is_finite()) {
        return Err(Error::invalid(
            "2D widget",
            format!("handle position {to:?} must be finite"),
        ));
    }
    let w = widget_mut(tf, i)?;
    if matches!(w.shape, Shape::Profile { .. }) {
        return Err(Error::invalid(
            "2D widget",
            "a profile widget has no handles (shape its points instead)",
        ));
    }
    let (centre, half) = widget_box(w);
    let mut new_centre = centre;
    let mut new_half = half;
    for (axis, side) in [h.value, h.gradient].into_iter().enumerate() {
        if side == 0 {
            continue;
        }
        let fixed = centre[axis] - f64::from(side) * half[axis];
        new_centre[axis] = 0.5 * (fixed + to[axis]);
        // A box of no extent is no box: keep it a hair wide.
        let least = 1e-9 * (fixed.abs() + to[axis].abs()).max(1e-9);
        new_half[axis] = (0.5 * (to[axis] - fixed).abs()).max(least);
    }
    move_widget(
        tf,
        i,
        [new_centre[0] - centre[0], new_centre[1] - centre[1]],
    )?;
    resize_widget(tf, i, new_half)
}

/// Deletes widget `i` (a 2-D function may have none: it is then transparent).
///
/// # Errors
/// `i` is not a widget.
pub fn delete_widget(tf: &mut TransferFunction2D, i: usize) -> Result<()> {
    widget_mut(tf, i)?;
    tf.widgets.remove(i);
    Ok(())
}

fn widget_mut(tf: &mut TransferFunction2D, i: usize) -> Result<&mut Widget> {
    let n = tf.widgets.len();
    tf.widgets.get_mut(i).ok_or_else(|| {
        Error::invalid(
            "2D transfer function",
            format!("no widget {i} (it has {n})"),
        )
    })
}
