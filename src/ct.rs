//! CT acquisition geometry and projection stacks, shared by every CT algorithm
//! (forward projection, ramp filtering, FBP, FDK and D²VR) on both backends.
//!
//! # The world frame (RTK's)
//! Millimetres. The object turns about the **+y axis**. At gantry angle `a` the unit
//! vectors of the view are
//! - `e_u = ( cos a, 0, −sin a)` — the detector's column direction,
//! - `e_v = ( 0,     1,  0    )` — the detector's row direction (the rotation axis),
//! - `e_w = ( sin a, 0,  cos a)` — from the isocentre towards the source.
//!
//! **Cone beam** (RTK's circular geometry): the source sits at `SID·e_w`, the flat
//! detector is perpendicular to `e_w` at distance `SDD` from the source. A point `P`
//! at depth `w = P·e_w` is magnified by `m = SDD / (SID − w)` and lands on the detector
//! at `(u, v) = m·(P·e_u, P·e_v)` mm.
//!
//! **Parallel beam**: rays travel along `−e_w`; `P` lands at `(u, v) = (P·e_u, P·e_v)`.
//! In scikit-image's terms (`radon`/`iradon`), a 2-D image with `x = col − n//2` to the
//! right and `y = n//2 − row` up lies in the world's xz-plane as `X = x`, `Z = −y`; then
//! `u = X cos a − Z sin a = x cos θ + y sin θ` with `θ = a`, exactly scikit-image's `s`.
//!
//! **Given view by view** ([`Geometry::from_views`]): RTK's geometry XML, ASTRA's
//! `cone_vec`/`parallel3d_vec` — per view a source (or ray direction), the centre of
//! detector pixel `(0, 0)` and the pixel steps `u`, `v` ([`ViewVectors`]). The
//! projective map then comes from the vectors (`per_view_matrix`: Cramer's rule on
//! the ray–plane intersection), and the FDK weights from each view's distances along
//! its detector normal ([`ViewFrame`]); the circle's fields become nominal values.
//!
//! # Detector pixels
//! Detector pixel `(col, row)` has its centre at
//! `u = (col − cu)·du`, `v = (row − cv)·dv`; `cu`, `cv` are the (possibly fractional)
//! index of the pixel the central ray hits. scikit-image puts it at `n//2`
//! ([`Geometry::parallel_skimage`]); RTK centres the detector, `(n − 1)/2`
//! ([`Geometry::cone_rtk`]).
//!
//! # Projection stacks
//! [`Projections`] stores `angles × rows × cols` values with the column fastest: the
//! layout of a NumPy array of shape `(angle, row, col)` — RTK's projection stack, and
//! the 3-D parallel stack of the command line. A scikit-image sinogram of shape
//! `(detector, angle)` is its transpose with one row (`crate::io` converts).
//!
//! # One backprojected point
//! Every reconstruction in voxlab (FBP, FDK, D²VR) sums, over the views, a weight times
//! the zero-padded bilinear interpolation of a (filtered) projection at the point's
//! detector position: [`ViewMatrix::project`] and [`bilinear_zero`] are that per-element
//! work, mirrored by `shaders/shared/ct_geometry.wgsl` and `ct_bilinear.wgsl`.
//!
//! # Intensities
//! A scanner's raw projections are intensities; [`flat_field`] turns them into line
//! integrals with flat- and dark-field images.

pub mod flat_field;

use crate::error::{Error, Result};
use crate::real::Real;
use glam::{DMat4, DVec3};

/// The shortest length (mm) a geometry may give: a nanometre.
pub const MIN_LENGTH_MM: f64 = 1e-6;
/// The longest length (mm) a geometry may give: a kilometre.
pub const MAX_LENGTH_MM: f64 = 1e6;

/// Parallel or circular cone-beam rays.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Beam {
    /// Parallel rays along `−e_w`.
    Parallel,
    /// A point source on a circle of radius `sid` (source–isocentre distance, mm) and a
    /// flat detector `sdd` mm from the source (source–detector distance).
    Cone { sid: f64, sdd: f64 },
}

/// Everything needed to map a world point to its detector position in every view.
#[derive(Clone, Debug, PartialEq)]
pub struct Geometry {
    pub beam: Beam,
    /// Gantry angles in degrees, one per projection.
    pub angles_deg: Vec<f64>,
    /// Detector columns (along `e_u`) and rows (along `e_v`).
    pub cols: usize,
    pub rows: usize,
    /// Detector pixel spacing in mm along columns (`du`) and rows (`dv`).
    pub du: f64,
    pub dv: f64,
    /// Index of the detector pixel the central ray hits (fractional allowed).
    pub cu: f64,
    pub cv: f64,
    /// A geometry given view by view ([`Geometry::from_views`]): one [`ViewVectors`]
    /// per projection, which then define every view; `None` for the circular orbit
    /// the fields above describe. With views, `beam`, `angles_deg`, `du`, `dv`, `cu`
    /// and `cv` are nominal values taken from them (see [`Geometry::from_views`]): the
    /// beam's kind, and view 0's spacing, centre and distances for defaults and
    /// messages.
    pub views: Option<Vec<ViewVectors>>,
}

/// One view of a geometry given view by view — RTK's geometry XML, ASTRA's `cone_vec`
/// and `parallel3d_vec` — as four vectors in the CT frame (mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewVectors {
    /// Cone beam: the source's position. Parallel beam: the rays' direction, from the
    /// source side towards the detector (any nonzero length).
    pub source: DVec3,
    /// The centre of detector pixel `(col, row) = (0, 0)`.
    pub pixel00: DVec3,
    /// From the centre of pixel `(col, row)` to that of `(col + 1, row)`.
    pub u: DVec3,
    /// From the centre of pixel `(col, row)` to that of `(col, row + 1)`.
    pub v: DVec3,
}

/// A geometry given view by view: the beam's kind, the detector's size and one
/// [`ViewVectors`] per projection. [`Geometry::from_views`] turns it into a [`Geometry`].
#[derive(Clone, Debug, PartialEq)]
pub struct ViewGeometry {
    /// Parallel rays (`ViewVectors::source` is a direction) or a point source.
    pub parallel: bool,
    pub cols: usize,
    pub rows: usize,
    pub views: Vec<ViewVectors>,
}

/// The largest number of projections or detector pixels per axis accepted (a lying
/// header or a typo must not allocate terabytes).
pub const MAX_DETECTOR: usize = 1 << 16;

impl Geometry {
    /// Checks that a stack of `[angles, rows, cols]` has the shape the geometry
    /// describes.
    pub fn check_stack(&self, [angles, rows, cols]: [usize; 3]) -> Result<()> {
        if (angles, rows, cols) != (self.n_angles(), self.rows, self.cols) {
            return Err(Error::invalid(
                "projections",
                format!(
                    "stack is {angles}×{rows}×{cols} (angles×rows×cols) but the geometry \
                     describes {}×{}×{}",
                    self.n_angles(),
                    self.rows,
                    self.cols
                ),
            ));
        }
        Ok(())
    }

    /// scikit-image's parallel-beam 2-D geometry: `cols` detector bins of 1 (pixel)
    /// unit, the rotation centre at bin `cols / 2` (integer division), one row.
    pub fn parallel_skimage(cols: usize, angles_deg: Vec<f64>) -> Result<Self> {
        let g = Geometry {
            beam: Beam::Parallel,
            angles_deg,
            cols,
            rows: 1,
            du: 1.0,
            dv: 1.0,
            cu: (cols / 2) as f64,
            cv: 0.0,
            views: None,
        };
        g.validate()?;
        Ok(g)
    }

    /// A 3-D parallel stack: each detector row is a scikit-image sinogram; rows are
    /// `dv` apart along the rotation axis and centred like RTK's, `cv = (rows − 1)/2`.
    pub fn parallel_stack(
        cols: usize,
        rows: usize,
        du: f64,
        dv: f64,
        angles_deg: Vec<f64>,
    ) -> Result<Self> {
        let g = Geometry {
            beam: Beam::Parallel,
            angles_deg,
            cols,
            rows,
            du,
            dv,
            cu: (cols / 2) as f64,
            cv: (rows as f64 - 1.0) / 2.0,
            views: None,
        };
        g.validate()?;
        Ok(g)
    }

    /// RTK's circular cone-beam geometry with a centred flat detector.
    pub fn cone_rtk(
        sid: f64,
        sdd: f64,
        cols: usize,
        rows: usize,
        du: f64,
        dv: f64,
        angles_deg: Vec<f64>,
    ) -> Result<Self> {
        let g = Geometry {
            beam: Beam::Cone { sid, sdd },
            angles_deg,
            cols,
            rows,
            du,
            dv,
            cu: (cols as f64 - 1.0) / 2.0,
            cv: (rows as f64 - 1.0) / 2.0,
            views: None,
        };
        g.validate()?;
        Ok(g)
    }

    /// A geometry given view by view (RTK's XML, ASTRA's vectors, voxlab's `views`).
    ///
    /// The views define everything; the circular fields are filled with nominal
    /// values for defaults and messages: `beam` is [`Beam::Parallel`] or
    /// [`Beam::Cone`] with view 0's source–isocentre distance `|S₀|` and its
    /// source–detector distance `SDD₀` (the source's distance from the detector
    /// plane); `angles_deg[k]` is view `k`'s gantry angle in RTK's sense (the source's
    /// azimuth about the `y` axis, `atan2(S_x, S_z)`; for a parallel beam that of
    /// `−direction`); `du`, `dv` are view 0's `|u|`, `|v|`; `cu`, `cv` the detector
    /// indices where view 0's ray through the isocentre lands (the detector's centre
    /// when it misses). A parallel beam's direction is stored normalised.
    ///
    /// # Errors
    /// [`Error::Invalid`] for views that do not define a detector and a beam
    /// ([`Geometry::validate`]: non-finite vectors, `u` and `v` parallel or of
    /// absurd length, a source on the detector plane, rays parallel to it);
    /// [`Error::TooLarge`] for too many views or pixels.
    pub fn from_views(views: ViewGeometry) -> Result<Self> {
        let ViewGeometry {
            parallel,
            cols,
            rows,
            mut views,
        } = views;
        if views.is_empty() {
            return Err(Error::invalid("CT geometry", "no views"));
        }
        if views.len() > MAX_DETECTOR {
            return Err(Error::too_large(
                "CT geometry",
                format!("{} views (at most {MAX_DETECTOR})", views.len()),
            ));
        }
        for (k, v) in views.iter().enumerate() {
            check_view(k, v, parallel)?;
        }
        if parallel {
            for v in &mut views {
                v.source = v.source.normalize();
            }
        }
        let angles_deg = views
            .iter()
            .map(|v| {
                let s = if parallel { -v.source } else { v.source };
                s.x.atan2(s.z).to_degrees()
            })
            .collect();
        let v0 = views[0];
        let beam = if parallel {
            Beam::Parallel
        } else {
            let f = view_frame(&v0, false);
            Beam::Cone {
                sid: v0.source.length(),
                sdd: f.sdd,
            }
        };
        let m = per_view_matrix(&v0, parallel);
        let centre = ((cols as f64 - 1.0) / 2.0, (rows as f64 - 1.0) / 2.0);
        let (cu, cv) = if m[2][3] > 0.0 {
            let (c, r) = (m[0][3] / m[2][3], m[1][3] / m[2][3]);
            if c.is_finite() && r.is_finite() && c.abs() <= 1e12 && r.abs() <= 1e12 {
                (c, r)
            } else {
                centre
            }
        } else {
            centre
        };
        let g = Geometry {
            beam,
            angles_deg,
            cols,
            rows,
            du: v0.u.length(),
            dv: v0.v.length(),
            cu,
            cv,
            views: Some(views),
        };
        g.validate()?;
        Ok(g)
    }

    /// Whether the geometry is the circular orbit of its fields (no per-view vectors).
    pub fn is_circular(&self) -> bool {
        self.views.is_none()
    }

    /// A clear error for an option that needs a circular orbit, given a geometry
    /// defined view by view; `what` names the option.
    ///
    /// # Errors
    /// [`Error::Invalid`] naming `what` when `self` has per-view vectors.
    pub fn require_circular(&self, what: &str) -> Result<()> {
        if self.is_circular() {
            Ok(())
        } else {
            Err(Error::invalid(
                what,
                "needs a circular orbit (a geometry of beam, angles and detector), but this \
                 geometry is given view by view",
            ))
        }
    }

    /// The four vectors of view `k` ([`ViewVectors`]): the stored ones for a
    /// geometry given view by view, else those of the circular orbit — cone source
    /// `SID·e_w` (parallel direction `−e_w`), pixel `(0, 0)` at
    /// [`Geometry::detector_point`], `u = du·e_u`, `v = dv·e_v`. Feeding every view's
    /// vectors to [`Geometry::from_views`] gives the same geometry view by view.
    pub fn view_vectors(&self, k: usize) -> ViewVectors {
        if let Some(views) = &self.views {
            return views[k];
        }
        let (eu, ev, ew) = self.axes(k);
        ViewVectors {
            source: match self.beam {
                Beam::Parallel => -ew,
                Beam::Cone { sid, .. } => ew * sid,
            },
            pixel00: self.detector_point(k, 0.0, 0.0),
            u: eu * self.du,
            v: ev * self.dv,
        }
    }

    /// Distances of view `k` along its detector normal ([`ViewFrame`]).
    pub fn view_frame(&self, k: usize) -> ViewFrame {
        match &self.views {
            Some(views) => view_frame(&views[k], self.beam == Beam::Parallel),
            None => {
                let (_, _, ew) = self.axes(k);
                let (sid, sdd) = match self.beam {
                    Beam::Parallel => (0.0, 0.0),
                    Beam::Cone { sid, sdd } => (sid, sdd),
                };
                ViewFrame {
                    normal: -ew,
                    sid,
                    sdd,
                    source_distance: sid,
                }
            }
        }
    }

    /// `n` angles evenly spread over `[0, range_deg)` (`range_deg = 180` for a parallel
    /// scan, `360` for a full cone-beam circle).
    pub fn even_angles(n: usize, range_deg: f64) -> Vec<f64> {
        (0..n).map(|k| k as f64 * range_deg / n as f64).collect()
    }

    /// Checks every field: a clear error instead of NaNs or absurd allocations later.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::invalid("CT geometry", m));
        if self.angles_deg.is_empty() {
            return bad("no projection angles".into());
        }
        if self.angles_deg.len() > MAX_DETECTOR {
            return Err(Error::too_large(
                "CT geometry",
                format!("{} angles (at most {MAX_DETECTOR})", self.angles_deg.len()),
            ));
        }
        if let Some(k) = self.angles_deg.iter().position(|a| !a.is_finite()) {
            return bad(format!("angle {k} is not finite"));
        }
        for (name, n) in [
            ("detector columns", self.cols),
            ("detector rows", self.rows),
        ] {
            if n == 0 {
                return bad(format!("{name} must be at least 1"));
            }
            if n > MAX_DETECTOR {
                return Err(Error::too_large(
                    "CT geometry",
                    format!("{n} {name} (at most {MAX_DETECTOR})"),
                ));
            }
        }
        for (name, s) in [("du", self.du), ("dv", self.dv)] {
            if !(s.is_finite() && s > 0.0) {
                return bad(format!(
                    "detector spacing {name} = {s} must be finite and > 0"
                ));
            }
        }
        for (name, c) in [("cu", self.cu), ("cv", self.cv)] {
            if !c.is_finite() {
                return bad(format!("detector centre {name} is not finite"));
            }
        }
        if let Beam::Cone { sid, sdd } = self.beam {
            if !(sid.is_finite() && sid > 0.0 && sdd.is_finite() && sdd > 0.0) {
                return bad(format!(
                    "SID = {sid} and SDD = {sdd} must be finite and > 0"
                ));
            }
        }
        // Lengths in mm between a nanometre and a kilometre: a denormal or absurd
        // distance gives zeros or overflow, not an error, further down.
        let mut lengths = vec![
            ("detector spacing du", self.du),
            ("detector spacing dv", self.dv),
        ];
        if let Beam::Cone { sid, sdd } = self.beam {
            lengths.push(("SID", sid));
            lengths.push(("SDD", sdd));
        }
        for (name, v) in lengths {
            if !(MIN_LENGTH_MM..=MAX_LENGTH_MM).contains(&v) {
                return bad(format!(
                    "{name} = {v:e} mm is outside [{MIN_LENGTH_MM:e}, {MAX_LENGTH_MM:e}] mm"
                ));
            }
        }
        if let Some(views) = &self.views {
            if views.len() != self.angles_deg.len() {
                return bad(format!(
                    "{} views for {} angles",
                    views.len(),
                    self.angles_deg.len()
                ));
            }
            for (k, v) in views.iter().enumerate() {
                check_view(k, v, self.beam == Beam::Parallel)?;
            }
        }
        Ok(())
    }

    /// Checks the source against a voxel box (`dims` voxels placed by `affine` in the
    /// CT frame, the volume projected or the grid reconstructed). A source inside the
    /// largest circle about the rotation axis that fits in the box's cross-section lies
    /// inside the box at every view — its rays start inside the object and their
    /// integrals mean nothing — and is refused; a source that only enters the box's
    /// corners at some views gives a warning (returned). Parallel beams pass.
    ///
    /// `what` names the SID's origin in the error (`--sid`, `geometry sid`) and `box_name`
    /// the box (`the object`, `the reconstruction grid`).
    ///
    /// # Errors
    /// [`Error::Invalid`] naming `what`, the SID and the box's radius.
    pub fn check_source_outside(
        &self,
        affine: DMat4,
        dims: [usize; 3],
        what: &str,
        box_name: &str,
    ) -> Result<Option<String>> {
        let Beam::Cone { sid, .. } = self.beam else {
            return Ok(None);
        };
        if let Some(views) = &self.views {
            // Each view's source against the box, in the grid's index frame.
            let inv = affine.inverse();
            for (k, v) in views.iter().enumerate() {
                let x = inv.transform_point3(v.source);
                if (0..3).all(|a| x[a] > -0.5 && x[a] < dims[a] as f64 - 0.5) {
                    return Err(Error::invalid(
                        what,
                        format!(
                            "the source of view {k} at ({:.4}, {:.4}, {:.4}) mm lies inside \
                             {box_name}",
                            v.source.x, v.source.y, v.source.z
                        ),
                    ));
                }
            }
            return Ok(None);
        }
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        let mut r_out: f64 = 0.0;
        for p in crate::volume::box_corners(dims, affine) {
            lo = lo.min(p);
            hi = hi.max(p);
            r_out = r_out.max(p.x.hypot(p.z));
        }
        // The rotation axis is the CT frame's y axis.
        let r_in = (-lo.x).min(hi.x).min(-lo.z).min(hi.z).max(0.0);
        if sid <= r_in {
            return Err(Error::invalid(
                what,
                format!(
                    "the source at SID = {sid} mm lies inside {box_name} at every view (its box \
                     holds a circle of radius {r_in:.4} mm about the rotation axis): SID must \
                     exceed {r_in:.4} mm"
                ),
            ));
        }
        Ok((sid < r_out).then(|| {
            format!(
                "the source at SID = {sid} mm enters the corners of {box_name}'s box (radius \
                 up to {r_out:.4} mm about the rotation axis) at some views; rays from inside \
                 the box give wrong values there"
            )
        }))
    }

    /// Number of projections.
    pub fn n_angles(&self) -> usize {
        self.angles_deg.len()
    }

    /// The view unit vectors `(e_u, e_v, e_w)` at projection `k`. For a geometry
    /// given view by view: `e_u = u/|u|`, `e_w` the detector's unit normal towards
    /// the source (against a parallel beam's rays), `e_v = e_w × e_u` (along `v` when
    /// `u ⟂ v`).
    pub fn axes(&self, k: usize) -> (DVec3, DVec3, DVec3) {
        if let Some(views) = &self.views {
            let f = view_frame(&views[k], self.beam == Beam::Parallel);
            let eu = views[k].u.normalize();
            let ew = -f.normal;
            return (eu, ew.cross(eu), ew);
        }
        let a = self.angles_deg[k].to_radians();
        let (s, c) = a.sin_cos();
        (DVec3::new(c, 0.0, -s), DVec3::Y, DVec3::new(s, 0.0, c))
    }

    /// The world position of the centre of detector pixel `(col, row)` of view `k`
    /// (continuous indices allowed).
    pub fn detector_point(&self, k: usize, col: f64, row: f64) -> DVec3 {
        if let Some(views) = &self.views {
            let v = &views[k];
            return v.pixel00 + v.u * col + v.v * row;
        }
        let (eu, ev, ew) = self.axes(k);
        let (u, v) = ((col - self.cu) * self.du, (row - self.cv) * self.dv);
        match self.beam {
            // The detector plane of a parallel beam is taken through the isocentre.
            Beam::Parallel => eu * u + ev * v,
            Beam::Cone { sid, sdd } => ew * (sid - sdd) + eu * u + ev * v,
        }
    }

    /// The ray through detector pixel `(col, row)` of view `k`: origin, unit direction
    /// (towards the detector) and the smallest ray parameter that is part of the beam.
    /// A parallel ray is the whole line through the pixel's point on the isocentre
    /// plane (`t ≥ −∞`; keeping the origin there keeps chord computations exact); a
    /// cone ray starts at the source (`t ≥ 0`).
    ///
    /// For a geometry given view by view a parallel ray's origin is the pixel's
    /// point moved along the ray to the plane through the isocentre perpendicular
    /// to it, for the same reason.
    pub fn ray(&self, k: usize, col: f64, row: f64) -> (DVec3, DVec3, f64) {
        if let Some(views) = &self.views {
            let det = self.detector_point(k, col, row);
            let s = views[k].source;
            return match self.beam {
                Beam::Parallel => {
                    let d = s.normalize();
                    (det - d * det.dot(d), d, f64::NEG_INFINITY)
                }
                Beam::Cone { .. } => (s, (det - s).normalize(), 0.0),
            };
        }
        let (_, _, ew) = self.axes(k);
        let det = self.detector_point(k, col, row);
        match self.beam {
            Beam::Parallel => (det, -ew, f64::NEG_INFINITY),
            Beam::Cone { sid, .. } => {
                let src = ew * sid;
                (src, (det - src).normalize(), 0.0)
            }
        }
    }

    /// The projective map of view `k` in precision `R`.
    pub fn view_matrix<R: Real>(&self, k: usize) -> ViewMatrix<R> {
        ViewMatrix::from_f64(&self.view_matrix_f64(k))
    }

    fn view_matrix_f64(&self, k: usize) -> [[f64; 4]; 4] {
        if let Some(views) = &self.views {
            return per_view_matrix(&views[k], self.beam == Beam::Parallel);
        }
        let (eu, ev, ew) = self.axes(k);
        // Rows: numerator of the column index, of the row index, the denominator, and
        // the weight's numerator (see `ViewMatrix`).
        match self.beam {
            Beam::Parallel => [
                [eu.x / self.du, eu.y / self.du, eu.z / self.du, self.cu],
                [ev.x / self.dv, ev.y / self.dv, ev.z / self.dv, self.cv],
                [0.0, 0.0, 0.0, 1.0],
                [1.0, 0.0, 0.0, 0.0],
            ],
            Beam::Cone { sid, sdd } => {
                // col = cu + (SDD/du)·(P·e_u)/(SID − P·e_w); multiply through by the
                // denominator so one division serves both indices.
                let den = [-ew.x, -ew.y, -ew.z, sid];
                let row = |e: DVec3, d: f64, c: f64| {
                    [
                        sdd / d * e.x + c * den[0],
                        sdd / d * e.y + c * den[1],
                        sdd / d * e.z + c * den[2],
                        c * den[3],
                    ]
                };
                [
                    row(eu, self.du, self.cu),
                    row(ev, self.dv, self.cv),
                    den,
                    [sid, 0.0, 0.0, 0.0],
                ]
            }
        }
    }

    /// The views `views` alone, as a geometry of their own: its view `k` is view
    /// `views.start + k` here, with the same rays (every per-view quantity — axes,
    /// detector points, view matrices — depends on the view's own angle or vectors
    /// only). How `voxlab reconstruct --distributed` gives each rank its views.
    ///
    /// # Errors
    /// [`Error::Invalid`] for an empty range or one past the last view.
    pub fn select_views(&self, views: std::ops::Range<usize>) -> Result<Geometry> {
        if views.is_empty() || views.end > self.n_angles() {
            return Err(Error::invalid(
                "CT geometry",
                format!(
                    "views {}..{} of {}: give a non-empty range of them",
                    views.start,
                    views.end,
                    self.n_angles()
                ),
            ));
        }
        let mut g = self.clone();
        g.angles_deg = self.angles_deg[views.clone()].to_vec();
        g.views = self.views.as_ref().map(|v| v[views].to_vec());
        Ok(g)
    }

    /// Every view's projective map, for upload to the GPU (`ViewMatrix<f32>` is `Pod`).
    pub fn view_matrices<R: Real>(&self) -> Vec<ViewMatrix<R>> {
        (0..self.n_angles()).map(|k| self.view_matrix(k)).collect()
    }
}

/// The distances of one view along its detector normal — the quantities FDK's
/// weights are made of (RTK's `FDKWeightProjectionFilter` and
/// `FDKBackProjectionImageFilter`; [`Geometry::view_frame`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewFrame {
    /// The detector plane's unit normal, pointing from the source's side to the
    /// detector (along a parallel beam's rays: `normal · direction > 0`).
    pub normal: DVec3,
    /// Cone beam: the isocentre's depth along the normal from the source,
    /// `SID_k = (O − S)·n̂` (RTK's source-to-isocentre distance). 0 for a parallel beam.
    pub sid: f64,
    /// Cone beam: the detector plane's distance from the source,
    /// `SDD_k = (pixel00 − S)·n̂`. 0 for a parallel beam.
    pub sdd: f64,
    /// Cone beam: the source's distance from the isocentre `|S|` (equal to `sid` when
    /// the normal through the source meets the isocentre). 0 for a parallel beam.
    pub source_distance: f64,
}

/// [`ViewFrame`] of one view given by vectors (`source` a unit direction when
/// `parallel`).
fn view_frame(v: &ViewVectors, parallel: bool) -> ViewFrame {
    let n = v.u.cross(v.v).normalize();
    if parallel {
        let n = if n.dot(v.source) < 0.0 { -n } else { n };
        return ViewFrame {
            normal: n,
            sid: 0.0,
            sdd: 0.0,
            source_distance: 0.0,
        };
    }
    let r = v.pixel00 - v.source;
    let n = if n.dot(r) < 0.0 { -n } else { n };
    ViewFrame {
        normal: n,
        sid: -n.dot(v.source),
        sdd: n.dot(r),
        source_distance: v.source.length(),
    }
}

/// The rows of [`ViewMatrix`] for one view given by vectors (`source` a unit
/// direction when `parallel`).
///
/// Cone beam, source `S`, pixel `(0, 0)` at `D₀`, steps `u`, `v`, normal
/// `n̂ ∝ u × v` towards the detector, `r = D₀ − S`: the ray from `S` through `P`
/// meets the detector at `S + t·(P − S) = D₀ + col·u + row·v`, and Cramer's rule gives
///
/// `col = (P − S)·(v × r) / (P − S)·(u × v)`, `row = (P − S)·(r × u) / (P − S)·(u × v)`.
///
/// Numerators and denominator are scaled alike so that the denominator is the depth
/// `(P − S)·n̂` in mm, and the weight's numerator is `SID_k = (O − S)·n̂`: the FDK
/// weight `(SID_k/depth)²` is then RTK's (its backprojection divides the projective
/// map by its value at the isocentre). Parallel beam, unit direction `d`: `P` moves
/// along `d` onto the plane, `col = d·(v × (D₀ − P)) / d·(u × v)`,
/// `row = d·((D₀ − P) × u) / d·(u × v)`, denominator 1, weight 1.
fn per_view_matrix(v: &ViewVectors, parallel: bool) -> [[f64; 4]; 4] {
    let n = v.u.cross(v.v);
    if parallel {
        let d = v.source;
        let q = d.dot(n);
        let c = -d.cross(v.v) / q;
        let r = -v.u.cross(d) / q;
        return [
            [c.x, c.y, c.z, d.dot(v.v.cross(v.pixel00)) / q],
            [r.x, r.y, r.z, d.dot(v.pixel00.cross(v.u)) / q],
            [0.0, 0.0, 0.0, 1.0],
            [1.0, 0.0, 0.0, 0.0],
        ];
    }
    let s = v.source;
    let r = v.pixel00 - s;
    let f = view_frame(v, false);
    // σ/|n|: the factor that turns (P − S)·n into the depth (P − S)·n̂.
    let scale = f.normal.dot(n).recip();
    let a = v.v.cross(r) * scale;
    let b = r.cross(v.u) * scale;
    let row = |e: DVec3| [e.x, e.y, e.z, -e.dot(s)];
    [row(a), row(b), row(f.normal), [f.sid, 0.0, 0.0, 0.0]]
}

/// Checks one view given by vectors: finite, lengths in range, `u` and `v` not
/// parallel, the source off the detector plane (cone) or the rays not parallel to it.
fn check_view(k: usize, v: &ViewVectors, parallel: bool) -> Result<()> {
    let bad = |m: String| Err(Error::invalid("CT geometry", format!("view {k}: {m}")));
    for (name, x) in [
        ("source", v.source),
        ("pixel00", v.pixel00),
        ("u", v.u),
        ("v", v.v),
    ] {
        if !x.is_finite() {
            return bad(format!("{name} is not finite"));
        }
        if x.length() > MAX_LENGTH_MM {
            return bad(format!(
                "|{name}| = {:e} mm exceeds {MAX_LENGTH_MM:e} mm",
                x.length()
            ));
        }
    }
    for (name, x) in [("u", v.u), ("v", v.v)] {
        let l = x.length();
        if l < MIN_LENGTH_MM {
            return bad(format!(
                "the pixel step |{name}| = {l:e} mm is below {MIN_LENGTH_MM:e} mm"
            ));
        }
    }
    let (lu, lv) = (v.u.length(), v.v.length());
    let sin = v.u.cross(v.v).length() / (lu * lv);
    if !(sin.is_finite() && sin >= MIN_SINE) {
        return bad(format!(
            "u and v are parallel (the sine of their angle is {sin:e}): they span no detector"
        ));
    }
    let n = v.u.cross(v.v).normalize();
    if parallel {
        let l = v.source.length();
        if !(l.is_finite() && l >= 1e-150) {
            return bad("the ray direction (source) is zero".into());
        }
        let c = (v.source.dot(n) / l).abs();
        if !(c.is_finite() && c >= MIN_SINE) {
            return bad(format!(
                "the rays run parallel to the detector plane (cosine with its normal {c:e})"
            ));
        }
    } else {
        let sdd = n.dot(v.pixel00 - v.source).abs();
        if !(sdd.is_finite() && sdd >= MIN_LENGTH_MM) {
            return bad(format!(
                "the source lies on the detector plane (distance {sdd:e} mm)"
            ));
        }
        if v.source.length() < MIN_LENGTH_MM {
            return bad("the source sits at the isocentre".into());
        }
    }
    Ok(())
}

/// The smallest sine of the angle between a view's `u` and `v` (and between a
/// parallel beam's rays and its detector plane) that a geometry may give: below it
/// the detector's coordinates are ill-conditioned.
pub const MIN_SINE: f64 = 1e-6;

/// The projective map of one view: world point `P` (mm) → continuous detector indices
/// `(col, row)` and the FDK distance weight.
///
/// With `P̃ = (P, 1)`: `den = r2·P̃`, `col = (r0·P̃)/den`, `row = (r1·P̃)/den`, and the
/// weight is `(r3[0]/den)²` — `(SID/(SID − w))²` for a cone beam, 1 for a parallel beam
/// (for a view given by vectors `(SID_k/depth)²`, the depth along its detector normal).
/// Layout: four rows of four numbers, the same bytes as WGSL's `CtView` in
/// `shaders/shared/ct_geometry.wgsl` (64 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ViewMatrix<R> {
    pub rows: [[R; 4]; 4],
}

// SAFETY-free Pod: only the f32 instance is uploaded.
unsafe impl bytemuck::Zeroable for ViewMatrix<f32> {}
unsafe impl bytemuck::Pod for ViewMatrix<f32> {}

impl<R: Real> ViewMatrix<R> {
    fn from_f64(m: &[[f64; 4]; 4]) -> Self {
        ViewMatrix {
            rows: m.map(|r| r.map(R::of)),
        }
    }

    /// Detector indices `(col, row)` of world point `p` and the distance weight.
    /// Returns `None` behind a cone-beam source (`den ≤ 0`), where nothing projects.
    ///
    /// mirrors shaders/shared/ct_geometry.wgsl: project_point
    #[inline(always)]
    pub fn project(&self, p: [R; 3]) -> Option<(R, R, R)> {
        let dot = |r: &[R; 4]| r[0] * p[0] + r[1] * p[1] + r[2] * p[2] + r[3];
        let den = dot(&self.rows[2]);
        if den <= R::zero() {
            return None;
        }
        let inv = R::one() / den;
        let w = self.rows[3][0] * inv;
        Some((dot(&self.rows[0]) * inv, dot(&self.rows[1]) * inv, w * w))
    }
}

/// Bilinear interpolation of a `cols × rows` image (column fastest) at continuous
/// indices `(x, y)`, with the image continued by **zeros**: each of the four taps
/// outside the image contributes nothing. Inside the node range this is plain bilinear
/// interpolation; within one pixel outside it ramps to zero; beyond, it is 0. (NumPy's
/// `np.interp(..., left=0, right=0)`, which scikit-image's `iradon` uses, jumps to zero
/// at the last node instead; the two differ only in that one-pixel margin.)
///
/// mirrors shaders/shared/ct_bilinear.wgsl: bilinear_zero
#[inline(always)]
pub fn bilinear_zero<R: Real>(img: &[R], cols: usize, rows: usize, x: R, y: R) -> R {
    let Some(([a, b, c, d], tx, ty)) = bilinear_taps(img, cols, rows, x, y) else {
        return R::zero();
    };
    let top = a * (R::one() - tx) + b * tx;
    let bottom = c * (R::one() - tx) + d * tx;
    top * (R::one() - ty) + bottom * ty
}

/// The four taps of [`bilinear_zero`] at `(x, y)` — `[(i, j), (i+1, j), (i, j+1),
/// (i+1, j+1)]` with `(i, j)` the floor, zero outside the image — and the fractions
/// `(tx, ty)`; `None` far outside (or for NaN), where every tap is zero. Shared by the
/// value and by D²VR's gradient (`cpu::d2vr::bilinear_zero_grad`).
#[inline(always)]
pub fn bilinear_taps<R: Real>(
    img: &[R],
    cols: usize,
    rows: usize,
    x: R,
    y: R,
) -> Option<([R; 4], R, R)> {
    let (fx, fy) = (x.floor(), y.floor());
    // Far outside (or NaN): nothing to interpolate. Also keeps the casts below in range.
    if !(fx >= -R::one() && fx < R::of(cols as f64) && fy >= -R::one() && fy < R::of(rows as f64)) {
        return None;
    }
    let (ix, iy) = (fx.to_i64().unwrap_or(-2), fy.to_i64().unwrap_or(-2));
    let at = |i: i64, j: i64| -> R {
        if i < 0 || j < 0 || i >= cols as i64 || j >= rows as i64 {
            R::zero()
        } else {
            img[j as usize * cols + i as usize]
        }
    };
    let taps = [
        at(ix, iy),
        at(ix + 1, iy),
        at(ix, iy + 1),
        at(ix + 1, iy + 1),
    ];
    Some((taps, x - fx, y - fy))
}

/// A stack of projections: `angles × rows × cols` values, column fastest (NumPy shape
/// `(angle, row, col)`).
#[derive(Clone, Debug, PartialEq)]
pub struct Projections<T> {
    pub angles: usize,
    pub rows: usize,
    pub cols: usize,
    pub data: Vec<T>,
}

impl<T: Copy + Default> Projections<T> {
    /// A zero-filled stack shaped for `g`.
    pub fn zeros(g: &Geometry) -> Result<Self> {
        Self::new(
            g.n_angles(),
            g.rows,
            g.cols,
            vec![T::default(); g.n_angles() * g.rows * g.cols],
        )
    }

    /// Wraps `data`, checking its length.
    pub fn new(angles: usize, rows: usize, cols: usize, data: Vec<T>) -> Result<Self> {
        let n = angles
            .checked_mul(rows)
            .and_then(|n| n.checked_mul(cols))
            .ok_or_else(|| {
                Error::too_large("projection stack", format!("{angles}×{rows}×{cols}"))
            })?;
        if data.len() != n {
            return Err(Error::invalid(
                "projection stack",
                format!("{} values for {angles}×{rows}×{cols}", data.len()),
            ));
        }
        Ok(Projections {
            angles,
            rows,
            cols,
            data,
        })
    }

    /// Checks that the stack has the shape `g` describes.
    pub fn check_against(&self, g: &Geometry) -> Result<()> {
        g.check_stack([self.angles, self.rows, self.cols])
    }

    /// The image of projection `k` (`rows × cols`, column fastest).
    pub fn view(&self, k: usize) -> &[T] {
        let n = self.rows * self.cols;
        &self.data[k * n..(k + 1) * n]
    }

    /// Mutable image of projection `k`.
    pub fn view_mut(&mut self, k: usize) -> &mut [T] {
        let n = self.rows * self.cols;
        &mut self.data[k * n..(k + 1) * n]
    }

    /// Its lines `ids` (`view·rows + row`, increasing) as [`Lines`].
    ///
    /// # Errors
    /// As [`Lines::new`].
    pub fn lines(&self, ids: &[usize]) -> Result<Lines<T>> {
        let total = self.angles * self.rows;
        if let Some(&bad) = ids.iter().find(|&&id| id >= total) {
            return Err(Error::invalid(
                "detector lines",
                format!("line {bad} is past the stack's {total} lines"),
            ));
        }
        let data = ids
            .iter()
            .flat_map(|&id| &self.data[id * self.cols..(id + 1) * self.cols])
            .copied()
            .collect();
        Lines::new([self.angles, self.rows, self.cols], ids.to_vec(), data)
    }

    /// Every detector line zero-padded to `cols ≥ self.cols` bins, bin `self.cols / 2`
    /// moved to `cols / 2` (scikit-image's `_sinogram_circle_to_square`, which `iradon`
    /// applies for `circle=True`).
    pub fn padded_centred(&self, cols: usize) -> Self {
        Projections {
            angles: self.angles,
            rows: self.rows,
            cols,
            data: pad_lines_centred(&self.data, self.cols, cols),
        }
    }
}

/// Lines of `n` values zero-padded to `cols ≥ n`, bin `n / 2` moved to `cols / 2`
/// ([`Projections::padded_centred`], [`Lines::padded_centred`]).
fn pad_lines_centred<T: Copy + Default>(data: &[T], n: usize, cols: usize) -> Vec<T> {
    let before = cols / 2 - n / 2;
    let mut out = vec![T::default(); data.len() / n.max(1) * cols];
    for (dst, src) in out.chunks_mut(cols).zip(data.chunks(n)) {
        dst[before..before + n].copy_from_slice(src);
    }
    out
}

/// Some detector lines of a stack shaped `angles × rows × cols`: line `ids[n]`
/// (`view·rows + row`, increasing) holds `data[n·cols..(n + 1)·cols]`. What a rank of
/// a distributed reconstruction reads, weighs and filters instead of the whole stack
/// (`cpu::ramp::filter_lines`, `cpu::fbp::backproject_region`).
#[derive(Clone, Debug, PartialEq)]
pub struct Lines<T> {
    pub angles: usize,
    pub rows: usize,
    pub cols: usize,
    pub ids: Vec<usize>,
    pub data: Vec<T>,
}

impl<T: Copy + Default> Lines<T> {
    /// Wraps `data`, checking that the ids increase, lie in the stack and match the
    /// data's length.
    pub fn new([angles, rows, cols]: [usize; 3], ids: Vec<usize>, data: Vec<T>) -> Result<Self> {
        let bad = |m: String| Err(Error::invalid("detector lines", m));
        let total = angles
            .checked_mul(rows)
            .ok_or_else(|| Error::too_large("detector lines", format!("{angles}×{rows} lines")))?;
        if ids.windows(2).any(|w| w[0] >= w[1]) {
            return bad("line ids must increase".into());
        }
        if let Some(&last) = ids.last() {
            if last >= total {
                return bad(format!("line {last} is past the stack's {total} lines"));
            }
        }
        if ids.len().checked_mul(cols) != Some(data.len()) {
            return bad(format!(
                "{} values for {} lines of {cols}",
                data.len(),
                ids.len()
            ));
        }
        Ok(Lines {
            angles,
            rows,
            cols,
            ids,
            data,
        })
    }

    /// Every line of `p`.
    pub fn all(p: Projections<T>) -> Self {
        Lines {
            angles: p.angles,
            rows: p.rows,
            cols: p.cols,
            ids: (0..p.angles * p.rows).collect(),
            data: p.data,
        }
    }

    /// Checks that the stack the lines come from has the shape `g` describes.
    pub fn check_against(&self, g: &Geometry) -> Result<()> {
        g.check_stack([self.angles, self.rows, self.cols])
    }

    /// The same lines with `f` applied to every value.
    pub fn map<U>(&self, f: impl Fn(T) -> U) -> Lines<U> {
        Lines {
            angles: self.angles,
            rows: self.rows,
            cols: self.cols,
            ids: self.ids.clone(),
            data: self.data.iter().map(|&v| f(v)).collect(),
        }
    }

    /// The same lines with new values (as many), for a filter's output.
    pub fn with_data<U>(&self, data: Vec<U>) -> Lines<U> {
        assert_eq!(data.len(), self.data.len(), "one value for each");
        Lines {
            angles: self.angles,
            rows: self.rows,
            cols: self.cols,
            ids: self.ids.clone(),
            data,
        }
    }

    /// [`Projections::padded_centred`] on these lines.
    pub fn padded_centred(&self, cols: usize) -> Self {
        Lines {
            angles: self.angles,
            rows: self.rows,
            cols,
            ids: self.ids.clone(),
            data: pad_lines_centred(&self.data, self.cols, cols),
        }
    }
}

/// The detector lines a backprojection reads, by view and row: a whole
/// [`Projections`] stack or some of its [`Lines`].
pub trait DetectorLines<T>: Sync {
    /// `[angles, rows, cols]` of the whole stack.
    fn shape(&self) -> [usize; 3];
    /// Row `row` of view `view`, `None` when it is not held.
    fn line(&self, view: usize, row: usize) -> Option<&[T]>;
    /// Whether every line is held.
    fn whole(&self) -> bool;
}

impl<T: Sync> DetectorLines<T> for Projections<T> {
    fn shape(&self) -> [usize; 3] {
        [self.angles, self.rows, self.cols]
    }
    fn line(&self, view: usize, row: usize) -> Option<&[T]> {
        let at = (view * self.rows + row) * self.cols;
        (view < self.angles && row < self.rows).then(|| &self.data[at..at + self.cols])
    }
    fn whole(&self) -> bool {
        true
    }
}

impl<T: Sync> DetectorLines<T> for Lines<T> {
    fn shape(&self) -> [usize; 3] {
        [self.angles, self.rows, self.cols]
    }
    fn line(&self, view: usize, row: usize) -> Option<&[T]> {
        if view >= self.angles || row >= self.rows {
            return None;
        }
        let n = self.ids.binary_search(&(view * self.rows + row)).ok()?;
        Some(&self.data[n * self.cols..(n + 1) * self.cols])
    }
    fn whole(&self) -> bool {
        self.ids.len() == self.angles * self.rows
    }
}

/// scikit-image's detector width for `circle=True`: the inscribed circle's diagonal,
/// `⌈√2·cols⌉` bins.
pub fn circle_diagonal(cols: usize) -> usize {
    (std::f64::consts::SQRT_2 * cols as f64).ceil() as usize
}

impl Projections<f64> {
    /// The same stack rounded to f32.
    pub fn narrow(&self) -> Result<Projections<f32>> {
        Projections::new(
            self.angles,
            self.rows,
            self.cols,
            self.data.iter().map(|&v| v as f32).collect(),
        )
    }
}

impl Projections<f32> {
    /// The same stack in f64 (exact).
    pub fn widen(self) -> Projections<f64> {
        Projections {
            angles: self.angles,
            rows: self.rows,
            cols: self.cols,
            data: self.data.into_iter().map(f64::from).collect(),
        }
    }
}

/// The rotation that places a [`crate::phantom::Phantom`] in the CT frame:
/// phantom `(x, y, z)` → CT `(X, Y, Z) = (x, z, −y)`. The phantom's z axis (head–foot)
/// becomes the rotation axis, and its axial slice `z = 0` lies in the plane `Y = 0`
/// with phantom `y` up in scikit-image's image (`y = −Z`), as a CT scanner sees it.
pub fn phantom_to_ct(p: DVec3) -> DVec3 {
    DVec3::new(p.x, p.z, -p.y)
}

/// The inverse of [`phantom_to_ct`].
pub fn ct_to_phantom(p: DVec3) -> DVec3 {
    DVec3::new(p.x, -p.z, p.y)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cone_projection_matches_the_ray_construction() {
        let g = Geometry::cone_rtk(
            1000.0,
            1500.0,
            64,
            48,
            1.5,
            2.0,
            Geometry::even_angles(7, 360.0),
        )
        .unwrap();
        for k in 0..7 {
            let m = g.view_matrix::<f64>(k);
            for &(c, r) in &[(0.0, 0.0), (10.3, 40.7), (63.0, 47.0), (31.5, 23.5)] {
                let (o, d, _) = g.ray(k, c, r);
                // Any point on the ray projects back onto (c, r).
                for t in [700.0, 1000.0, 1300.0] {
                    let p = o + d * t;
                    let (pc, pr, w) = m.project(p.to_array()).unwrap();
                    assert!(
                        (pc - c).abs() < 1e-9 && (pr - r).abs() < 1e-9,
                        "{k} {c} {r}: {pc} {pr}"
                    );
                    let (_, _, ew) = g.axes(k);
                    let expect = (1000.0 / (1000.0 - p.dot(ew))).powi(2);
                    assert!((w - expect).abs() < 1e-12 * expect);
                }
            }
        }
    }

    #[test]
    fn parallel_projection_is_skimage_s() {
        // s = x cos θ + y sin θ with the image in the xz-plane, y = −Z.
        let g = Geometry::parallel_skimage(65, vec![0.0, 30.0, 90.0, 137.0]).unwrap();
        for k in 0..4 {
            let th = g.angles_deg[k].to_radians();
            let (x, y) = (7.25, -3.5);
            let (c, r, w) = g.view_matrix::<f64>(k).project([x, 0.0, -y]).unwrap();
            let s = x * th.cos() + y * th.sin();
            assert!((c - (s + 32.0)).abs() < 1e-12 && r == 0.0 && w == 1.0);
        }
    }

    #[test]
    fn bilinear_zero_interpolates_and_pads_with_zeros() {
        let img = [1.0f64, 2.0, 3.0, 4.0, 5.0, 6.0]; // 3 cols × 2 rows
        assert_eq!(bilinear_zero(&img, 3, 2, 1.0, 1.0), 5.0);
        assert!((bilinear_zero(&img, 3, 2, 0.5, 0.5) - 3.0).abs() < 1e-15);
        assert_eq!(bilinear_zero(&img, 3, 2, -0.5, 0.0), 0.5);
        assert_eq!(bilinear_zero(&img, 3, 2, 2.5, 1.0), 3.0);
        assert_eq!(bilinear_zero(&img, 3, 2, 3.0, 0.0), 0.0);
        assert_eq!(bilinear_zero(&img, 3, 2, f64::NAN, 0.0), 0.0);
        assert_eq!(bilinear_zero(&img, 3, 2, 1e30, 0.0), 0.0);
    }

    #[test]
    fn bad_geometry_is_refused() {
        assert!(Geometry::parallel_skimage(0, vec![0.0]).is_err());
        assert!(Geometry::parallel_skimage(8, vec![]).is_err());
        assert!(Geometry::parallel_skimage(8, vec![f64::NAN]).is_err());
        assert!(Geometry::cone_rtk(-1.0, 1500.0, 8, 8, 1.0, 1.0, vec![0.0]).is_err());
        assert!(Geometry::cone_rtk(1000.0, 1500.0, 8, 8, 0.0, 1.0, vec![0.0]).is_err());
    }

    #[test]
    fn phantom_rotation_round_trips() {
        let p = DVec3::new(0.1, -0.7, 0.3);
        assert_eq!(ct_to_phantom(phantom_to_ct(p)), p);
        assert_eq!(phantom_to_ct(DVec3::Z), DVec3::Y);
    }
}
