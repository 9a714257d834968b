//! Stereo pairs: two renders from eyes `e` apart, combined into one image.
//!
//! # Cameras
//! Parallel axes with an off-axis (asymmetric-frustum) shift, which keeps vertical
//! parallax zero everywhere, unlike toe-in. The left and right eyes sit at
//! `eye ∓ (e/2)·right` with the mono camera's forward, up and field of view. Each eye's
//! frustum is shifted sideways so that the plane at the convergence distance `D` (in
//! front of the mono eye) has zero parallax: points on it appear at the same pixel in
//! both images, nearer points stand out of the screen, farther ones behind it.
//!
//! The shift is `s = e·H / (4 D tan(fov_y/2))` pixels (half the disparity of a point at
//! infinity), rounded to a whole number of pixels, so the zero-parallax plane actually
//! lies at `D' = e·H / (4 s tan(fov_y/2))` (reported in [`StereoPair`]). A shifted
//! frustum is rendered exactly as a window of a symmetric one: each eye renders
//! `W + 2s` columns with the mono camera's pixel pitch (`2 tan(fov_y/2)/H` per pixel)
//! and keeps `W` of them, columns `2s …` for the left eye and `0 …` for the right. With
//! `e = 0` both eyes are the mono camera. Orthographic cameras have no parallax to shift
//! and are refused.
//!
//! Both views are rendered through [`Renderer`], so any
//! backend works, or on a given GPU context with [`render_pair_gpu`].
//!
//! # Layouts
//! - **side by side**: left | right, `2W × H` (parallel viewing: left image on the
//!   left);
//! - **anaglyph** (red/cyan glasses): red from the left image, green and blue from the
//!   right one; for RGBA images alpha is the larger of the two; scalar images (MIP,
//!   X-ray) are first scaled by their joint range `[lo, hi]` to `[0, 1]`, giving the
//!   RGBA `((L − lo)/(hi − lo), (R − lo)/(hi − lo), (R − lo)/(hi − lo), 1)`;
//! - **interlaced**: rows alternate, even rows (0, 2, …) from the left image, odd rows
//!   from the right (row-interleaved polarised displays).

use super::renderer::{Renderer, Scene};
use crate::camera::{Camera, Projection};
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::settings::RenderSettings;

crate::choice_enum! {
    /// How the two views are combined.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum StereoLayout: "stereo layout" {
        /// Left | right.
        SideBySide = "side-by-side",
        /// Red from the left image, green and blue from the right.
        Anaglyph = "anaglyph",
        /// Even rows from the left image, odd rows from the right.
        Interlaced = "interlaced",
    }
}

/// The left and right cameras, as windows of wider renders.
#[derive(Clone, Debug, PartialEq)]
pub struct StereoCameras {
    /// The left eye's wide camera; its image's columns `left_offset .. + W` are the view.
    pub left: Camera,
    pub left_offset: usize,
    /// The right eye's wide camera and offset.
    pub right: Camera,
    pub right_offset: usize,
    /// The frustum shift in pixels.
    pub shift_px: usize,
    /// The distance of the zero-parallax plane after rounding the shift (mm; infinite
    /// for zero shift).
    pub convergence_mm: f64,
}

/// Left and right cameras for eye separation `separation_mm ≥ 0` and zero parallax at
/// `convergence_mm > 0` in front of the mono camera (see the module docs).
pub fn stereo_cameras(
    mono: &Camera,
    separation_mm: f64,
    convergence_mm: f64,
) -> Result<StereoCameras> {
    if !(separation_mm.is_finite() && separation_mm >= 0.0) {
        return Err(Error::invalid(
            "eye separation",
            format!("{separation_mm} mm must be finite and ≥ 0"),
        ));
    }
    if !(convergence_mm.is_finite() && convergence_mm > 0.0) {
        return Err(Error::invalid(
            "convergence distance",
            format!("{convergence_mm} mm must be finite and positive"),
        ));
    }
    let Projection::Perspective { fov_y_deg } = mono.projection else {
        return Err(Error::invalid(
            "stereo",
            "an orthographic camera has no parallax; use a perspective camera",
        ));
    };
    let h = (0.5 * fov_y_deg.to_radians()).tan();
    let exact = separation_mm * mono.height as f64 / (4.0 * convergence_mm * h);
    let s = exact.round();
    if s > crate::camera::MAX_IMAGE_SIDE as f64 {
        return Err(Error::too_large(
            "stereo",
            format!("a frustum shift of {s} pixels (the eyes are too far apart for the image)"),
        ));
    }
    let s = s as usize;
    let wide = mono.width + 2 * s;
    let eye = |sign: f64| Camera {
        eye: mono.eye + mono.right * (sign * 0.5 * separation_mm),
        width: wide,
        ..mono.clone()
    };
    Ok(StereoCameras {
        left: eye(-1.0),
        left_offset: 2 * s,
        right: eye(1.0),
        right_offset: 0,
        shift_px: s,
        convergence_mm: if s == 0 {
            f64::INFINITY
        } else {
            separation_mm * mono.height as f64 / (4.0 * s as f64 * h)
        },
    })
}

/// Columns `offset .. offset + width` of a frame.
pub fn crop_columns(f: &Frame, offset: usize, width: usize) -> Frame {
    let ch = f.channels;
    let mut out = Frame::new(width, f.height, ch);
    for row in 0..f.height {
        let src = (row * f.width + offset) * ch;
        out.data[row * width * ch..(row + 1) * width * ch]
            .copy_from_slice(&f.data[src..src + width * ch]);
    }
    out
}

/// A rendered stereo pair.
#[derive(Clone, Debug)]
pub struct StereoPair {
    pub left: Frame,
    pub right: Frame,
    pub cameras: StereoCameras,
}

/// Renders the left and right views of `scene` (whose camera is the mono one).
pub fn render_pair(
    renderer: &Renderer,
    scene: &Scene,
    settings: &RenderSettings,
    separation_mm: f64,
    convergence_mm: f64,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<StereoPair> {
    render_pair_with(
        &|sc, p| Ok(renderer.render(sc, settings, p)?.output.image),
        scene,
        separation_mm,
        convergence_mm,
        progress,
    )
}

/// [`render_pair`] on a given GPU context (e.g. the process-wide
/// `GpuContext::shared()`) instead of a [`Renderer`]'s own device.
pub fn render_pair_gpu(
    ctx: &crate::gpu::GpuContext,
    scene: &Scene,
    settings: &RenderSettings,
    separation_mm: f64,
    convergence_mm: f64,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<StereoPair> {
    render_pair_with(
        &|sc, p| {
            Ok(
                crate::gpu::raycast::render(
                    ctx,
                    &sc.volume,
                    &sc.transfer,
                    &sc.camera,
                    settings,
                    p,
                )?
                .output
                .image,
            )
        },
        scene,
        separation_mm,
        convergence_mm,
        progress,
    )
}

/// A view renderer: the image of a scene, with a progress callback.
type ViewRenderer<'a> = dyn Fn(&Scene, &(dyn Fn(usize, usize) + Sync)) -> Result<Frame> + 'a;

fn render_pair_with(
    render_view: &ViewRenderer<'_>,
    scene: &Scene,
    separation_mm: f64,
    convergence_mm: f64,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<StereoPair> {
    let cams = stereo_cameras(&scene.camera, separation_mm, convergence_mm)?;
    let w = scene.camera.width;
    let h = scene.camera.height;
    let view = |cam: &Camera, offset: usize, first: bool| -> Result<Frame> {
        let sc = Scene {
            volume: scene.volume.clone(),
            transfer: scene.transfer.clone(),
            camera: cam.clone(),
        };
        let image = render_view(&sc, &|done, _| {
            progress(if first { done } else { h + done }, 2 * h)
        })?;
        Ok(crop_columns(&image, offset, w))
    };
    let left = view(&cams.left, cams.left_offset, true)?;
    let right = view(&cams.right, cams.right_offset, false)?;
    Ok(StereoPair {
        left,
        right,
        cameras: cams,
    })
}

/// Combines a pair into one image (see the module docs for the layouts).
pub fn combine(left: &Frame, right: &Frame, layout: StereoLayout) -> Result<Frame> {
    if (left.width, left.height, left.channels) != (right.width, right.height, right.channels) {
        return Err(Error::invalid(
            "stereo pair",
            "the left and right images differ in size or channels",
        ));
    }
    let (w, h, ch) = (left.width, left.height, left.channels);
    Ok(match layout {
        StereoLayout::SideBySide => {
            let mut out = Frame::new(2 * w, h, ch);
            for row in 0..h {
                let dst = row * 2 * w * ch;
                out.data[dst..dst + w * ch]
                    .copy_from_slice(&left.data[row * w * ch..(row + 1) * w * ch]);
                out.data[dst + w * ch..dst + 2 * w * ch]
                    .copy_from_slice(&right.data[row * w * ch..(row + 1) * w * ch]);
            }
            out
        }
        StereoLayout::Interlaced => {
            let mut out = Frame::new(w, h, ch);
            for row in 0..h {
                let src = if row % 2 == 0 { left } else { right };
                out.data[row * w * ch..(row + 1) * w * ch]
                    .copy_from_slice(&src.data[row * w * ch..(row + 1) * w * ch]);
            }
            out
        }
        StereoLayout::Anaglyph => {
            let mut out = Frame::new(w, h, 4);
            let (lo, scale) = match (left.finite_range(), right.finite_range()) {
                (Some(a), Some(b)) if ch == 1 => {
                    let (lo, hi) = (a.0.min(b.0), a.1.max(b.1));
                    (lo, if hi > lo { 1.0 / (hi - lo) } else { 1.0 })
                }
                _ => (0.0, 1.0),
            };
            for i in 0..w * h {
                let (l, r) = (
                    &left.data[i * ch..(i + 1) * ch],
                    &right.data[i * ch..(i + 1) * ch],
                );
                let o = &mut out.data[i * 4..(i + 1) * 4];
                if ch == 1 {
                    let (l, r) = ((l[0] - lo) * scale, (r[0] - lo) * scale);
                    o.copy_from_slice(&[l, r, r, 1.0]);
                } else {
                    o.copy_from_slice(&[l[0], r[1], r[2], l[3].max(r[3])]);
                }
            }
            out
        }
    })
}
