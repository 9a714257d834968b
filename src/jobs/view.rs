//! `voxlab view`, the interactive lab: its whole view as one JSON document, and the
//! orbit camera it is seen with. The window (egui on wgpu, in the `voxlab` binary
//! behind the `lab` feature) is a thin shell over this, the render job and
//! [`crate::editor`]; everything it edits lives here, tested without a window.
//!
//! ```json
//! { "format": "voxlab-view-state", "version": 1,
//!   "input": { "source": "phantom:shepp-logan-modified:64" },
//!   "width": 512, "height": 512,
//!   "view": { "target": [0, 0, 0], "azimuth_deg": 30, "elevation_deg": 20,
//!             "distance_mm": 990.1,
//!             "projection": { "type": "perspective", "fov_y_deg": 30 } },
//!   "settings": { …RenderSettings… },
//!   "transfer": { …a 1-D transfer function, as `--tf` reads it… } }
//! ```
//!
//! The 2-D transfer function, when one is on, is `settings.transfer_2d` (as in a
//! `--settings` file). [`ViewState::scene`] turns a state into the scene and settings
//! the render job draws; the lab and `voxlab render --state` both call it, so they see
//! the same camera to the last bit.

use crate::camera::{AxisView, Camera, Orbit, Projection};
use crate::error::{Error, Result};
use crate::jobs::input::{volume_center, volume_extent, VolumeInput};
use crate::jobs::renderer::Scene;
use crate::settings::RenderSettings;
use crate::transfer::TransferFunction;
use crate::volume::AnyVolume;
use glam::DVec3;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The `format` field of every state file.
pub const FORMAT: &str = "voxlab-view-state";
/// The state format's version; a file of a later version is refused.
pub const VERSION: u32 = 1;

/// How the orbit camera projects.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum ViewProjection {
    /// Rays from the eye, `fov_y_deg` the full vertical field of view.
    Perspective { fov_y_deg: f64 },
    /// Parallel rays; the image spans `height_mm` vertically at the target.
    Orthographic { height_mm: f64 },
}

/// An orbit camera: a target, the direction the eye sees it from, a distance and a
/// projection. World +z is up, except looking straight down or up, where the image's
/// up is the direction the azimuth faces.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OrbitView {
    /// The point the camera looks at and orbits about (world, mm).
    pub target: [f64; 3],
    /// Rotation about world +z in degrees; 0 looks along +y (from −y), as in
    /// `voxlab render --azimuth`.
    pub azimuth_deg: f64,
    /// Degrees above the xy-plane, in [−90, 90].
    pub elevation_deg: f64,
    /// From the target to the eye (perspective) or to the image plane's centre
    /// (orthographic), in mm.
    pub distance_mm: f64,
    pub projection: ViewProjection,
}

/// Degrees the view turns per pixel dragged.
pub const DEGREES_PER_PIXEL: f64 = 0.4;

impl OrbitView {
    /// The view that fits `volume` as `voxlab render` frames it by default: its centre,
    /// azimuth 30°, elevation 20°, the distance (or, orthographic, the height) that
    /// shows the whole box with a 5 % margin at `width × height` pixels.
    ///
    /// # Errors
    /// An image size or field of view [`Camera::orbit`] refuses.
    pub fn fit(
        volume: &AnyVolume,
        projection: ViewProjection,
        width: usize,
        height: usize,
    ) -> Result<Self> {
        let center = volume_center(volume);
        let proj = match projection {
            ViewProjection::Perspective { fov_y_deg } => Projection::Perspective { fov_y_deg },
            ViewProjection::Orthographic { .. } => Projection::Orthographic {
                width_mm: 0.0,
                height_mm: 0.0,
            },
        };
        let orbit = Orbit::default();
        let cam = Camera::orbit(center, volume_extent(volume), orbit, proj, width, height)?;
        let projection = match cam.projection {
            Projection::Orthographic { height_mm, .. } => {
                ViewProjection::Orthographic { height_mm }
            }
            Projection::Perspective { fov_y_deg } => ViewProjection::Perspective { fov_y_deg },
        };
        Ok(OrbitView {
            target: center.to_array(),
            azimuth_deg: orbit.azimuth_deg,
            elevation_deg: orbit.elevation_deg,
            distance_mm: (cam.eye - center).length(),
            projection,
        })
    }

    /// Checks every number.
    ///
    /// # Errors
    /// The field that is out of range, named.
    pub fn validate(&self) -> Result<()> {
        let bad = |field: &str, why: String| Err(Error::invalid(field, why));
        if self.target.iter().any(|t| !t.is_finite()) {
            return bad("view.target", format!("{:?} must be finite", self.target));
        }
        if !self.azimuth_deg.is_finite() {
            return bad("view.azimuth_deg", "must be finite".into());
        }
        if !(-90.0..=90.0).contains(&self.elevation_deg) {
            return bad(
                "view.elevation_deg",
                format!("{} must lie in [-90, 90]", self.elevation_deg),
            );
        }
        if !(self.distance_mm.is_finite() && self.distance_mm > 0.0) {
            return bad(
                "view.distance_mm",
                format!("{} must be finite and positive", self.distance_mm),
            );
        }
        match self.projection {
            ViewProjection::Perspective { fov_y_deg }
                if !(fov_y_deg > 0.0 && fov_y_deg < 180.0) =>
            {
                bad(
                    "view.projection.fov_y_deg",
                    format!("{fov_y_deg}° must lie strictly between 0° and 180°"),
                )
            }
            ViewProjection::Orthographic { height_mm }
                if !(height_mm.is_finite() && height_mm > 0.0) =>
            {
                bad(
                    "view.projection.height_mm",
                    format!("{height_mm} must be finite and positive"),
                )
            }
            _ => Ok(()),
        }
    }

    /// The unit vectors from the target toward the eye and the image's up.
    fn frame(&self) -> (DVec3, DVec3) {
        let (sa, ca) = self.azimuth_deg.to_radians().sin_cos();
        let (se, ce) = self.elevation_deg.to_radians().sin_cos();
        let toward_eye = DVec3::new(ce * sa, -ce * ca, se);
        // The derivative of `toward_eye` along the elevation: perpendicular to it, +z's
        // projection where that exists, the azimuth's direction at the poles.
        let up = DVec3::new(-se * sa, se * ca, ce);
        (toward_eye, up)
    }

    /// The camera for a `width × height` image.
    ///
    /// # Errors
    /// An invalid view ([`OrbitView::validate`]) or image size.
    pub fn camera(&self, width: usize, height: usize) -> Result<Camera> {
        self.validate()?;
        let (toward_eye, up) = self.frame();
        let target = DVec3::from_array(self.target);
        let projection = match self.projection {
            ViewProjection::Perspective { fov_y_deg } => Projection::Perspective { fov_y_deg },
            ViewProjection::Orthographic { height_mm } => Projection::Orthographic {
                width_mm: height_mm * width as f64 / height.max(1) as f64,
                height_mm,
            },
        };
        Camera::look_at(
            target + toward_eye * self.distance_mm,
            target,
            up,
            projection,
            width,
            height,
        )
    }

    /// Turns the view by a drag of `(dx, dy)` pixels: right turns the volume right
    /// (the eye moves left), down tilts it toward the viewer; the elevation stops at
    /// ±90°.
    pub fn orbit_by(&mut self, dx: f64, dy: f64) {
        self.azimuth_deg = (self.azimuth_deg - DEGREES_PER_PIXEL * dx).rem_euclid(360.0);
        self.elevation_deg = (self.elevation_deg + DEGREES_PER_PIXEL * dy).clamp(-90.0, 90.0);
    }

    /// Millimetres at the target per image pixel, for an image `height` pixels high.
    pub fn mm_per_pixel(&self, height: usize) -> f64 {
        let h = match self.projection {
            ViewProjection::Perspective { fov_y_deg } => {
                2.0 * self.distance_mm * (0.5 * fov_y_deg.to_radians()).tan()
            }
            ViewProjection::Orthographic { height_mm } => height_mm,
        };
        h / height.max(1) as f64
    }

    /// Moves the target (and the eye with it) so that the volume follows a drag of
    /// `(dx, dy)` pixels on an image `height` pixels high.
    pub fn pan_by(&mut self, dx: f64, dy: f64, height: usize) {
        let (toward_eye, up) = self.frame();
        let right = (-toward_eye).cross(up);
        let s = self.mm_per_pixel(height);
        let t = DVec3::from_array(self.target) - right * (dx * s) + up * (dy * s);
        self.target = t.to_array();
    }

    /// Zooms in by `factor` (> 1 brings the volume closer): the distance shrinks in
    /// perspective, the visible height in orthographic.
    pub fn zoom_by(&mut self, factor: f64) {
        if !(factor.is_finite() && factor > 0.0) {
            return;
        }
        match &mut self.projection {
            ViewProjection::Perspective { .. } => {
                self.distance_mm = (self.distance_mm / factor).max(1e-6)
            }
            ViewProjection::Orthographic { height_mm } => {
                *height_mm = (*height_mm / factor).max(1e-6)
            }
        }
    }

    /// Looks along a world axis (`+x`: rays travel toward +x), keeping target and
    /// distance.
    pub fn look_along(&mut self, view: AxisView) {
        let (azimuth, elevation) = match view {
            AxisView::PlusX => (270.0, 0.0),
            AxisView::MinusX => (90.0, 0.0),
            AxisView::PlusY => (0.0, 0.0),
            AxisView::MinusY => (180.0, 0.0),
            AxisView::PlusZ => (0.0, -90.0),
            AxisView::MinusZ => (0.0, 90.0),
        };
        self.azimuth_deg = azimuth;
        self.elevation_deg = elevation;
    }

    /// Switches between perspective (`fov_y_deg`) and orthographic projection, keeping
    /// the size of the target's neighbourhood on screen.
    pub fn set_orthographic(&mut self, on: bool, fov_y_deg: f64) {
        let half = (0.5 * fov_y_deg.to_radians()).tan();
        self.projection = match (self.projection, on) {
            (ViewProjection::Perspective { fov_y_deg: f }, true) => ViewProjection::Orthographic {
                height_mm: 2.0 * self.distance_mm * (0.5 * f.to_radians()).tan(),
            },
            (ViewProjection::Orthographic { height_mm }, false) => {
                self.distance_mm = 0.5 * height_mm / half;
                ViewProjection::Perspective { fov_y_deg }
            }
            (p, _) => p,
        };
    }
}

/// Everything the lab shows: what to read, how to look at it, how to render it.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewState {
    /// Always [`FORMAT`].
    pub format: String,
    /// [`VERSION`] when written.
    pub version: u32,
    pub input: VolumeInput,
    /// Image size in pixels.
    pub width: usize,
    pub height: usize,
    pub view: OrbitView,
    pub settings: RenderSettings,
    /// The 1-D transfer function (the 2-D one is `settings.transfer_2d`).
    pub transfer: TransferFunction,
}

impl ViewState {
    /// The default view of `volume` read from `input`: its `voxlab render` defaults
    /// (the `auto` transfer function, DVR, azimuth 30°, elevation 20°, 30° perspective)
    /// at `width × height`.
    ///
    /// # Errors
    /// An image size the camera refuses.
    pub fn new(
        input: VolumeInput,
        volume: &AnyVolume,
        width: usize,
        height: usize,
    ) -> Result<Self> {
        let view = OrbitView::fit(
            volume,
            ViewProjection::Perspective { fov_y_deg: 30.0 },
            width,
            height,
        )?;
        let transfer = crate::jobs::input::auto_transfer(&input, volume)?;
        Ok(ViewState {
            format: FORMAT.into(),
            version: VERSION,
            input,
            width,
            height,
            view,
            settings: RenderSettings::default(),
            transfer,
        })
    }

    /// Checks the format, the version, the view, the settings and the transfer
    /// functions.
    ///
    /// # Errors
    /// The first field that is wrong, named.
    pub fn validate(&self) -> Result<()> {
        if self.format != FORMAT {
            return Err(Error::invalid(
                "format",
                format!(
                    "'{}' is not a view state (expected '{FORMAT}')",
                    self.format
                ),
            ));
        }
        if self.version == 0 || self.version > VERSION {
            return Err(Error::invalid(
                "version",
                format!(
                    "{} is not a state version this voxlab reads (1 … {VERSION})",
                    self.version
                ),
            ));
        }
        self.view.validate()?;
        self.settings.validate()?;
        self.transfer.validate()?;
        Ok(())
    }

    /// The camera of the state's view at its image size.
    ///
    /// # Errors
    /// An invalid view or image size.
    pub fn camera(&self) -> Result<Camera> {
        self.view.camera(self.width, self.height)
    }

    /// The scene and settings to render `volume` (the state's input, loaded) with.
    ///
    /// # Errors
    /// Whatever [`ViewState::validate`] or the camera refuses.
    pub fn scene(&self, volume: AnyVolume) -> Result<(Scene, RenderSettings)> {
        self.validate()?;
        let camera = self.camera()?;
        Ok((
            Scene {
                volume,
                transfer: self.transfer.clone(),
                camera,
            },
            self.settings.clone(),
        ))
    }

    /// The state as pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a view state always serialises")
    }

    /// Parses and checks a state; `path` names it in messages.
    ///
    /// # Errors
    /// JSON errors with the field's path; [`ViewState::validate`]'s.
    pub fn from_json(text: &str, path: &Path) -> Result<Self> {
        let s: ViewState = crate::json::parse(text, path, "view state")?;
        s.validate().map_err(|e| e.in_file(path))?;
        Ok(s)
    }

    /// Reads a state file.
    ///
    /// # Errors
    /// As [`ViewState::from_json`], and the file's read errors.
    pub fn load(path: &Path) -> Result<Self> {
        let s: ViewState = crate::json::read_file(path, "view state")?;
        s.validate().map_err(|e| e.in_file(path))?;
        Ok(s)
    }

    /// Writes the state (atomically: a complete file or none).
    ///
    /// # Errors
    /// The file's write errors.
    pub fn save(&self, path: &Path) -> Result<()> {
        crate::io::write_text(path, &self.to_json())
    }
}

/// The 2-D editor's backdrop: voxel counts over the 2-D transfer function's own axes,
/// the mapped value (through its window map, over its domain) across and the gradient
/// magnitude (value per mm, central differences, on its linear or logarithmic axis)
/// up. Voxels outside the table's range fall into its edge bins, as the renderer
/// clamps them.
#[derive(Clone, Debug, PartialEq)]
pub struct JointHistogram {
    /// `[value bins, gradient bins]`.
    pub bins: [usize; 2],
    /// Counts, value fastest; row 0 is the smallest gradient magnitude.
    pub counts: Vec<u64>,
}

/// Counts `volume`'s voxels over `tf`'s (value, gradient magnitude) plane in
/// `bins = [value bins, gradient bins]` (each clamped to 1 … 1024).
///
/// # Errors
/// A transfer function [`crate::transfer2d::TransferFunction2D::validate`] refuses.
pub fn joint_histogram(
    volume: &AnyVolume,
    tf: &crate::transfer2d::TransferFunction2D,
    bins: [usize; 2],
) -> Result<JointHistogram> {
    use rayon::prelude::*;
    tf.validate()?;
    let [nv, ng] = bins.map(|b| b.clamp(1, 1024));
    let c = tf.coordinates();
    let [tv, tg] = c.size.map(|n| (n - 1).max(1) as f64);
    let values = crate::cpu::grid::Grid::<f32>::from_any(volume);
    let gradient =
        crate::with_volume!(volume, v => crate::cpu::process::gradient_magnitude::<f32, _>(v))?;
    let bin = |x: f64, n: usize| ((x * n as f64).floor().max(0.0) as usize).min(n - 1);
    let counts = values
        .data
        .par_iter()
        .zip(gradient.grid.data.par_iter())
        .fold(
            || vec![0u64; nv * ng],
            |mut h, (&v, &g)| {
                let (v, g) = (f64::from(v), f64::from(g));
                let x = (v * c.v_scale + c.v_offset) / tv;
                let y = if c.log {
                    (g * c.g0_inv).ln_1p() * c.g_scale
                } else {
                    g * c.g_scale
                } / tg;
                h[bin(y, ng) * nv + bin(x, nv)] += 1;
                h
            },
        )
        .reduce(
            || vec![0u64; nv * ng],
            |mut a, b| {
                a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
                a
            },
        );
    Ok(JointHistogram {
        bins: [nv, ng],
        counts,
    })
}
