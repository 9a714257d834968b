//! Cameras: orthographic and perspective, orbit parameters, axis-aligned views and ray
//! generation. Rays are clipped to boxes with the slab test of `crate::real`
//! ([`intersect_box`](crate::real::intersect_box), [`slab_interval`](crate::real::slab_interval)).
//!
//! Image conventions: row 0 is at the top; pixel `(col, row)` has its centre at image
//! coordinates `(col + 0.5, row + 0.5)`. A camera is an eye (or, for orthographic views,
//! the centre of the image plane), a unit `forward` direction and unit `right` and `up`
//! vectors spanning the image plane. Pixel x grows along `right`, pixel y along `−up`.
//! Cameras are set up in f64 world coordinates (mm).

use crate::error::{Error, Result};
use glam::{DMat3, DMat4, DVec3};
use serde::{Deserialize, Serialize};

/// How rays leave the camera.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Projection {
    /// Parallel rays along `forward`; the image plane is `width_mm × height_mm`.
    Orthographic { width_mm: f64, height_mm: f64 },
    /// Rays from the eye; `fov_y_deg` is the full vertical field of view.
    Perspective { fov_y_deg: f64 },
}

/// A ray in world space: `origin + t · dir`, `dir` of unit length, valid for
/// `t ∈ [t_min, ∞)` (`t_min` is −∞ for orthographic rays, 0 for perspective ones).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: DVec3,
    pub dir: DVec3,
    pub t_min: f64,
}

/// One of the six axis-aligned orthographic views of a volume's index axes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum AxisView {
    PlusX,
    MinusX,
    PlusY,
    MinusY,
    PlusZ,
    MinusZ,
}

impl std::str::FromStr for AxisView {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Ok(match s {
            "+x" | "x" => AxisView::PlusX,
            "-x" => AxisView::MinusX,
            "+y" | "y" => AxisView::PlusY,
            "-y" => AxisView::MinusY,
            "+z" | "z" => AxisView::PlusZ,
            "-z" => AxisView::MinusZ,
            _ => {
                return Err(Error::invalid(
                    "view",
                    format!("'{s}' is not one of +x, -x, +y, -y, +z, -z"),
                ))
            }
        })
    }
}

impl AxisView {
    /// The index axis rays travel along, and the sign of their direction.
    pub fn axis(self) -> (usize, f64) {
        match self {
            AxisView::PlusX => (0, 1.0),
            AxisView::MinusX => (0, -1.0),
            AxisView::PlusY => (1, 1.0),
            AxisView::MinusY => (1, -1.0),
            AxisView::PlusZ => (2, 1.0),
            AxisView::MinusZ => (2, -1.0),
        }
    }
    /// The index axes along image columns and image rows: the remaining two axes,
    /// the faster one across columns, the slower one down the rows. That is NumPy's
    /// layout of `vol.max(axis=…)` for a `(nz, ny, nx)` array, so the image equals the
    /// reduction pixel for pixel, for either sign of the view.
    pub fn image_axes(self) -> (usize, usize) {
        match self.axis().0 {
            0 => (1, 2),
            1 => (0, 2),
            _ => (0, 1),
        }
    }
}

/// Orbit parameters around a target point.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Orbit {
    /// Rotation about the world +z axis, degrees; 0 looks along +y (from −y).
    pub azimuth_deg: f64,
    /// Angle above the xy-plane, degrees (−89 … 89).
    pub elevation_deg: f64,
    /// Distance from the target in mm; `None` fits the volume in view.
    pub distance_mm: Option<f64>,
}

impl Default for Orbit {
    fn default() -> Self {
        Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            distance_mm: None,
        }
    }
}

/// A camera: where rays start, which way they go, and the image size.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// The eye (perspective) or the centre of the image plane (orthographic).
    pub eye: DVec3,
    pub forward: DVec3,
    pub right: DVec3,
    pub up: DVec3,
    pub projection: Projection,
    pub width: usize,
    pub height: usize,
}

/// The largest image side accepted (a 16384² RGBA f64 frame is 8 GiB).
pub const MAX_IMAGE_SIDE: usize = 16384;

fn check_image(width: usize, height: usize) -> Result<()> {
    if width == 0 || height == 0 || width > MAX_IMAGE_SIDE || height > MAX_IMAGE_SIDE {
        return Err(Error::invalid(
            "image size",
            format!("{width}×{height}: each side must be 1 … {MAX_IMAGE_SIDE}"),
        ));
    }
    Ok(())
}

impl Camera {
    /// A camera at `eye` looking at `target`, with `up_hint` roughly up.
    pub fn look_at(
        eye: DVec3,
        target: DVec3,
        up_hint: DVec3,
        projection: Projection,
        width: usize,
        height: usize,
    ) -> Result<Self> {
        check_image(width, height)?;
        let forward = (target - eye).normalize_or_zero();
        let right = forward.cross(up_hint).normalize_or_zero();
        if forward == DVec3::ZERO || right == DVec3::ZERO || !right.is_finite() {
            return Err(Error::invalid(
                "camera",
                "eye and target coincide, or the up vector is parallel to the view direction",
            ));
        }
        let up = right.cross(forward);
        let cam = Camera {
            eye,
            forward,
            right,
            up,
            projection,
            width,
            height,
        };
        cam.validate()?;
        Ok(cam)
    }

    /// An orbit camera around a volume of world-space centre `center` and extent
    /// `extent` (mm), with the world +z axis up. With `distance_mm: None` the whole
    /// volume fits the view (its bounding sphere with a 5 % margin).
    pub fn orbit(
        center: DVec3,
        extent: [f64; 3],
        orbit: Orbit,
        projection: Projection,
        width: usize,
        height: usize,
    ) -> Result<Self> {
        check_image(width, height)?;
        if !(-89.999..=89.999).contains(&orbit.elevation_deg) || !orbit.azimuth_deg.is_finite() {
            return Err(Error::invalid(
                "orbit",
                "elevation must lie in (−90°, 90°) and azimuth be finite",
            ));
        }
        let radius = 0.5 * DVec3::from_array(extent).length() * 1.05;
        let (sa, ca) = orbit.azimuth_deg.to_radians().sin_cos();
        let (se, ce) = orbit.elevation_deg.to_radians().sin_cos();
        let toward_eye = DVec3::new(ce * sa, -ce * ca, se);
        let aspect = width as f64 / height.max(1) as f64;
        if let Projection::Perspective { fov_y_deg } = projection {
            if !(fov_y_deg > 0.0 && fov_y_deg < 180.0) {
                return Err(Error::invalid(
                    "--fov",
                    format!("{fov_y_deg}° must lie strictly between 0° and 180°"),
                ));
            }
        }
        let (projection, fit_distance) = match projection {
            Projection::Perspective { fov_y_deg } => {
                let half = 0.5 * fov_y_deg.to_radians();
                let half_min = if aspect < 1.0 {
                    (half.tan() * aspect).atan()
                } else {
                    half
                };
                (projection, radius / half_min.sin())
            }
            Projection::Orthographic {
                width_mm,
                height_mm,
            } => {
                // Non-positive sizes mean "fit".
                let (w, h) = if width_mm > 0.0 && height_mm > 0.0 {
                    (width_mm, height_mm)
                } else {
                    let h = 2.0 * radius / aspect.min(1.0);
                    (h * aspect, h)
                };
                (
                    Projection::Orthographic {
                        width_mm: w,
                        height_mm: h,
                    },
                    2.0 * radius,
                )
            }
        };
        let distance = orbit.distance_mm.unwrap_or(fit_distance);
        if !(distance.is_finite() && distance > 0.0) {
            return Err(Error::invalid("orbit distance", "must be positive"));
        }
        Self::look_at(
            center + toward_eye * distance,
            center,
            DVec3::Z,
            projection,
            width,
            height,
        )
    }

    /// The orthographic view along an index axis of a volume with `dims` and `affine`.
    /// The image spans the volume's cross-section; with `width × height` equal to the
    /// cross-section's dimensions every pixel centre lies on a ray through voxel centres.
    /// See [`AxisView::image_axes`] for the orientation.
    pub fn axis_view(
        dims: [usize; 3],
        affine: DMat4,
        view: AxisView,
        width: usize,
        height: usize,
    ) -> Result<Self> {
        check_image(width, height)?;
        let (a, sign) = view.axis();
        let (ca, ra) = view.image_axes();
        let lin = DMat3::from_mat4(affine);
        let col = |i: usize| lin.col(i);
        let center = affine.transform_point3(DVec3::new(
            (dims[0] as f64 - 1.0) * 0.5,
            (dims[1] as f64 - 1.0) * 0.5,
            (dims[2] as f64 - 1.0) * 0.5,
        ));
        let forward = (col(a) * sign).normalize();
        let right = col(ca).normalize();
        let up = -col(ra).normalize();
        let width_mm = col(ca).length() * dims[ca] as f64;
        let height_mm = col(ra).length() * dims[ra] as f64;
        // The eye plane sits just outside the volume on the side rays come from.
        let eye = center - forward * (col(a).length() * dims[a] as f64);
        let cam = Camera {
            eye,
            forward,
            right,
            up,
            projection: Projection::Orthographic {
                width_mm,
                height_mm,
            },
            width,
            height,
        };
        cam.validate()?;
        Ok(cam)
    }

    fn validate(&self) -> Result<()> {
        check_image(self.width, self.height)?;
        match self.projection {
            Projection::Perspective { fov_y_deg } if !(fov_y_deg > 0.0 && fov_y_deg < 179.0) => {
                Err(Error::invalid(
                    "field of view",
                    format!("{fov_y_deg}° must lie in (0°, 179°)"),
                ))
            }
            Projection::Orthographic {
                width_mm,
                height_mm,
            } if !(width_mm > 0.0
                && height_mm > 0.0
                && width_mm.is_finite()
                && height_mm.is_finite()) =>
            {
                Err(Error::invalid("orthographic view size", "must be positive"))
            }
            _ if !(self.eye.is_finite() && self.forward.is_finite()) => Err(Error::invalid(
                "camera",
                "position and direction must be finite",
            )),
            _ => Ok(()),
        }
    }

    /// The ray through continuous image point `(x, y)` (pixel centres at `+ 0.5`).
    pub fn ray_at(&self, x: f64, y: f64) -> Ray {
        let u = x / self.width as f64 - 0.5;
        let v = 0.5 - y / self.height as f64;
        match self.projection {
            Projection::Orthographic {
                width_mm,
                height_mm,
            } => Ray {
                origin: self.eye + self.right * (u * width_mm) + self.up * (v * height_mm),
                dir: self.forward,
                t_min: f64::NEG_INFINITY,
            },
            Projection::Perspective { fov_y_deg } => {
                let h = (0.5 * fov_y_deg.to_radians()).tan();
                let aspect = self.width as f64 / self.height as f64;
                let dir =
                    (self.forward + self.right * (2.0 * u * h * aspect) + self.up * (2.0 * v * h))
                        .normalize();
                Ray {
                    origin: self.eye,
                    dir,
                    t_min: 0.0,
                }
            }
        }
    }

    /// The ray through the centre of pixel `(col, row)`.
    pub fn ray(&self, col: usize, row: usize) -> Ray {
        self.ray_at(col as f64 + 0.5, row as f64 + 0.5)
    }

    /// Whether a ray of some pixel may meet the convex hull of `points` (world, mm):
    /// [`Camera::pixels_seen`] is not `None`. A conservative test, for skipping work no
    /// ray reaches (the GPU casters' bricks and cells).
    pub fn may_see(&self, points: &[DVec3]) -> bool {
        self.pixels_seen(points).is_some()
    }

    /// The pixels whose rays may meet the convex hull of `points` (world, mm), as a
    /// rectangle of the image; `None` when no ray does. Conservative: `None` when the
    /// hull lies wholly behind a perspective eye; otherwise the pixels whose centres lie
    /// within a pixel of the bounding box of the points' images ([`Camera::ray_at`]
    /// inverted), `None` when there are none; the whole image when a point lies on or
    /// behind a perspective eye's plane (its image is unbounded). The GPU ray caster
    /// casts a brick's rays only over its rectangle.
    pub fn pixels_seen(&self, points: &[DVec3]) -> Option<PixelRect> {
        let whole = PixelRect::whole(self.width, self.height);
        if matches!(self.projection, Projection::Perspective { .. })
            && points
                .iter()
                .all(|&p| (p - self.eye).dot(self.forward) < 0.0)
        {
            return None;
        }
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for &p in points {
            let d = p - self.eye;
            let (x, y) = (d.dot(self.right), d.dot(self.up));
            let (u, v) = match self.projection {
                Projection::Orthographic {
                    width_mm,
                    height_mm,
                } => (x / width_mm, y / height_mm),
                Projection::Perspective { fov_y_deg } => {
                    let z = d.dot(self.forward);
                    if z.is_nan() || z <= 1e-9 * d.length().max(1.0) {
                        return Some(whole);
                    }
                    let h = (0.5 * fov_y_deg.to_radians()).tan();
                    let aspect = self.width as f64 / self.height as f64;
                    (x / (2.0 * z * h * aspect), y / (2.0 * z * h))
                }
            };
            // Image coordinates as `ray_at` takes them.
            let (px, py) = (
                (u + 0.5) * self.width as f64,
                (0.5 - v) * self.height as f64,
            );
            if !(px.is_finite() && py.is_finite()) {
                return Some(whole);
            }
            lo = [lo[0].min(px), lo[1].min(py)];
            hi = [hi[0].max(px), hi[1].max(py)];
        }
        // Pixel i's centre i + ½ within a pixel of [lo, hi]: i from ⌈lo − 1.5⌉ to
        // ⌊hi + ½⌋, within the image.
        let span = |lo: f64, hi: f64, n: usize| {
            let first = (lo - 1.5).ceil().clamp(0.0, n as f64) as usize;
            let end = ((hi + 0.5).floor() + 1.0).clamp(0.0, n as f64) as usize;
            first..end.max(first)
        };
        let rect = PixelRect {
            cols: span(lo[0], hi[0], self.width),
            rows: span(lo[1], hi[1], self.height),
        };
        (!rect.is_empty()).then_some(rect)
    }
}

/// A rectangle of an image's pixels: columns `cols` and rows `rows` (half-open ranges,
/// row 0 at the top).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PixelRect {
    pub cols: std::ops::Range<usize>,
    pub rows: std::ops::Range<usize>,
}

impl PixelRect {
    /// Every pixel of a `width × height` image.
    pub fn whole(width: usize, height: usize) -> Self {
        PixelRect {
            cols: 0..width,
            rows: 0..height,
        }
    }

    /// Its width in pixels.
    pub fn width(&self) -> usize {
        self.cols.len()
    }

    /// Its height in pixels.
    pub fn height(&self) -> usize {
        self.rows.len()
    }

    /// Its pixels.
    pub fn len(&self) -> usize {
        self.width() * self.height()
    }

    /// Whether it holds no pixel.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whether it holds pixel `(col, row)`.
    pub fn contains(&self, col: usize, row: usize) -> bool {
        self.cols.contains(&col) && self.rows.contains(&row)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orbit_zero_looks_along_plus_y_with_x_right_and_z_up() {
        let c = Camera::orbit(
            DVec3::ZERO,
            [10.0; 3],
            Orbit {
                azimuth_deg: 0.0,
                elevation_deg: 0.0,
                distance_mm: Some(100.0),
            },
            Projection::Perspective { fov_y_deg: 30.0 },
            8,
            8,
        )
        .unwrap();
        assert!((c.forward - DVec3::Y).length() < 1e-12);
        assert!((c.right - DVec3::X).length() < 1e-12);
        assert!((c.up - DVec3::Z).length() < 1e-12);
        // The centre of the image looks straight ahead.
        let r = c.ray_at(4.0, 4.0);
        assert!((r.dir - DVec3::Y).length() < 1e-12);
    }

    /// `pixels_seen` is conservative: every pixel whose ray meets a box (every ray of the
    /// image tested against the box's slabs) lies in the box's rectangle, and none for a
    /// box it says no ray meets; and it does hide boxes off to the side of an
    /// orthographic view's frame, and outside a perspective frustum or behind its eye
    /// (cameras from 5 mm to 125 mm of a 40 mm box, so some inside it), and keeps most
    /// seen boxes' rectangles smaller than the image.
    #[test]
    fn pixels_seen_holds_every_pixel_whose_ray_meets_the_box() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut hidden, mut trials, mut behind, mut cut) = (0, 0, 0, 0);
        for i in 0..400 {
            let projection = if i % 2 == 0 {
                Projection::Perspective {
                    fov_y_deg: 10.0 + 80.0 * next(),
                }
            } else {
                Projection::Orthographic {
                    width_mm: 10.0 + 60.0 * next(),
                    height_mm: 10.0 + 40.0 * next(),
                }
            };
            let c = Camera::orbit(
                DVec3::splat(-20.0),
                [40.0; 3],
                Orbit {
                    azimuth_deg: 360.0 * next(),
                    elevation_deg: 170.0 * next() - 85.0,
                    distance_mm: Some(5.0 + 120.0 * next()),
                },
                projection,
                24,
                18,
            )
            .unwrap();
            for _ in 0..10 {
                let lo = DVec3::new(next(), next(), next()) * 160.0 - 80.0;
                let hi = lo + DVec3::new(next(), next(), next()) * 30.0 + 0.5;
                let corners: Vec<DVec3> = (0..8)
                    .map(|k| {
                        DVec3::new(
                            if k & 1 == 0 { lo.x } else { hi.x },
                            if k & 2 == 0 { lo.y } else { hi.y },
                            if k & 4 == 0 { lo.z } else { hi.z },
                        )
                    })
                    .collect();
                trials += 1;
                let seen = c.pixels_seen(&corners);
                assert_eq!(c.may_see(&corners), seen.is_some());
                match &seen {
                    Some(r) => {
                        assert!(!r.is_empty() && r.cols.end <= c.width && r.rows.end <= c.height);
                        cut += (r.len() < c.width * c.height) as usize;
                    }
                    None => {
                        hidden += 1;
                        let perspective = matches!(c.projection, Projection::Perspective { .. });
                        if perspective && corners.iter().all(|&p| (p - c.eye).dot(c.forward) < 0.0)
                        {
                            behind += 1;
                        }
                    }
                }
                for row in 0..c.height {
                    for col in 0..c.width {
                        let r = c.ray(col, row);
                        let met = crate::real::slab_interval(r.origin, r.dir, lo, hi)
                            .is_some_and(|(t0, t1)| t1 >= t0.max(r.t_min));
                        let inside = seen.as_ref().is_some_and(|s| s.contains(col, row));
                        assert!(
                            !met || inside,
                            "{c:?}: pixel ({col}, {row}) meets {lo} … {hi} outside {seen:?}"
                        );
                    }
                }
            }
        }
        assert!(hidden * 5 >= trials, "{hidden} of {trials} boxes hidden");
        assert!(
            cut * 2 >= trials - hidden,
            "{cut} of {} seen boxes' rectangles smaller than the image",
            trials - hidden
        );
        assert!(
            behind * 20 >= trials,
            "{behind} of {trials} boxes behind the eye"
        );
    }

    #[test]
    fn axis_view_pixels_hit_voxel_centres() {
        let dims = [5, 4, 3];
        let affine = DMat4::from_scale(DVec3::new(1.0, 2.0, 0.5));
        let inv = affine.inverse();
        for view in [AxisView::PlusZ, AxisView::MinusY, AxisView::PlusX] {
            let (ca, ra) = view.image_axes();
            let cam = Camera::axis_view(dims, affine, view, dims[ca], dims[ra]).unwrap();
            for row in 0..dims[ra] {
                for col in 0..dims[ca] {
                    let r = cam.ray(col, row);
                    let p = inv.transform_point3(r.origin);
                    assert!((p[ca] - col as f64).abs() < 1e-12, "{view:?}");
                    assert!((p[ra] - row as f64).abs() < 1e-12, "{view:?}");
                }
            }
        }
    }

    #[test]
    fn bad_cameras_are_refused() {
        assert!(Camera::look_at(
            DVec3::ZERO,
            DVec3::ZERO,
            DVec3::Z,
            Projection::Perspective { fov_y_deg: 30.0 },
            4,
            4
        )
        .is_err());
        assert!(Camera::look_at(
            DVec3::ZERO,
            DVec3::Z,
            DVec3::Z,
            Projection::Perspective { fov_y_deg: 30.0 },
            4,
            4
        )
        .is_err());
        assert!(Camera::look_at(
            DVec3::ZERO,
            DVec3::X,
            DVec3::Z,
            Projection::Perspective { fov_y_deg: 200.0 },
            4,
            4
        )
        .is_err());
        assert!(Camera::look_at(
            DVec3::ZERO,
            DVec3::X,
            DVec3::Z,
            Projection::Perspective { fov_y_deg: 30.0 },
            0,
            4
        )
        .is_err());
    }
}
