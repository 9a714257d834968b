//! RTK's geometry XML: the file `rtk::ThreeDCircularProjectionGeometryXMLFileWriter`
//! writes (`rtksimulatedgeometry`, `rtkprojections`, every RTK application's
//! `--geometry`), read into one [`ViewVectors`] per projection.
//!
//! # The file
//!
//! ```xml
//! <?xml version="1.0"?>
//! <!DOCTYPE RTKGEOMETRY>
//! <RTKThreeDCircularGeometry version="3">
//!     <SourceToIsocenterDistance>1000</SourceToIsocenterDistance>
//!     <SourceToDetectorDistance>1500</SourceToDetectorDistance>
//!   <Projection>
//!     <GantryAngle>30</GantryAngle>
//!     <Matrix>
//!        -1299.03810567666   0   750.000000000001   0
//!        0   -1500   0   0
//!        0.5   0   0.866025403784439   -1000
//!     </Matrix>
//!   </Projection>
//!   …
//! </RTKThreeDCircularGeometry>
//! ```
//!
//! A parameter written before the first `<Projection>` holds for every projection (RTK
//! writes a parameter there when it is the same in every view, and leaves out a
//! parameter that is 0 everywhere); one written inside a `<Projection>` holds for that
//! projection and, as in RTK's reader, for the following ones until it is given again.
//! The parameters, per projection (RTK's `AddProjection`):
//!
//! | element | meaning | default |
//! |---|---|---|
//! | `GantryAngle` (or `Angle`) | `g`, degrees | 0 |
//! | `OutOfPlaneAngle`, `InPlaneAngle` | `o`, `i`, degrees | 0 |
//! | `SourceToIsocenterDistance` | SID, mm | 0 |
//! | `SourceToDetectorDistance` | SDD, mm; **0 means a parallel beam** | 0 |
//! | `SourceOffsetX`, `SourceOffsetY` | `(sx, sy)`, mm | 0 |
//! | `ProjectionOffsetX`, `ProjectionOffsetY` | `(px, py)`, mm | 0 |
//! | `Matrix` | RTK's 3×4 projection matrix (checked, below) | |
//! | `RadiusCylindricalDetector` | a curved detector: refused unless 0 | 0 |
//! | `CollimationUInf`, … `VSup` | collimation of RTK's forward projectors: ignored | |
//!
//! # The geometry (RTK's `rtkThreeDCircularProjectionGeometry.cxx`)
//!
//! The world frame is voxlab's CT frame ([`crate::ct`]). View `k` has the rotation
//! `R = Rz(−i)·Rx(−o)·Ry(−g)` (ITK's `Euler3DTransform` in ZXY order, angles negated),
//! which takes world coordinates to the view's own frame. In that frame the source sits
//! at `(sx, sy, SID)`, the flat detector is the plane `z = SID − SDD`, and a point of
//! the projection image with physical coordinates `(U, V)` lies at `(U + px, V + py,
//! SID − SDD)`. So a world point `P` with `Q = R·P` lands at
//!
//! `U = sx − px + SDD·(Q.x − sx)/(SID − Q.z)`, `V = sy − py + SDD·(Q.y − sy)/(SID − Q.z)`
//!
//! — RTK's matrix `T(sx − px, sy − py) · M(SDD, SID) · T(−sx, −sy, 0) · R`. A parallel
//! beam (SDD = 0) sends rays along the view's −z; `U = Q.x − px`, `V = Q.y − py`, and
//! the source offsets cancel.
//!
//! # The detector grid is not in the file
//!
//! RTK takes the pixels from the projection image: pixel `(col, row)` has the physical
//! coordinates `origin + D·diag(spacing)·(col, row)` (ITK's index-to-physical rule,
//! `D` the image's direction), and the projection offsets shift that plane. So reading
//! the file needs a [`DetectorGrid`]: from the projections' MetaImage or NRRD header
//! ([`DetectorGrid::from_affine`]), or from sizes and spacings
//! ([`DetectorGrid::centred`]: RTK's default, the origin that centres the detector,
//! `−(n − 1)/2·spacing`).
//!
//! Each `<Matrix>` is compared with the one the parameters give, as RTK's reader does
//! (any entry more than 0.001 apart is an error): a file edited by hand that no longer
//! agrees with itself is refused instead of read one way or the other.

use crate::ct::{ViewGeometry, ViewVectors, MAX_DETECTOR, MAX_LENGTH_MM};
use crate::error::{Error, Result};
use glam::{DMat3, DMat4, DVec2, DVec3};
use std::path::Path;

/// Where the detector pixels lie in the plane of a projection image: pixel
/// `(col, row)` at `origin + col·col_step + row·row_step` (mm, the image's physical
/// coordinates in RTK's sense).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DetectorGrid {
    pub cols: usize,
    pub rows: usize,
    /// The physical coordinates of pixel `(0, 0)`'s centre: the image's origin.
    pub origin: DVec2,
    /// From pixel `(col, row)` to `(col + 1, row)`: `(spacing_x, 0)` for an image with
    /// the identity direction.
    pub col_step: DVec2,
    /// From pixel `(col, row)` to `(col, row + 1)`: `(0, spacing_y)`.
    pub row_step: DVec2,
}

impl DetectorGrid {
    /// A grid of `cols × rows` pixels of `du × dv` mm centred on the projection plane's
    /// origin: RTK's default origin, `−(n − 1)/2·spacing` per axis.
    pub fn centred(cols: usize, rows: usize, du: f64, dv: f64) -> Self {
        Self::with_origin(
            cols,
            rows,
            DVec2::new(
                -(cols as f64 - 1.0) / 2.0 * du,
                -(rows as f64 - 1.0) / 2.0 * dv,
            ),
            du,
            dv,
        )
    }

    /// A grid with the identity direction: an image's origin and spacing.
    pub fn with_origin(cols: usize, rows: usize, origin: DVec2, du: f64, dv: f64) -> Self {
        DetectorGrid {
            cols,
            rows,
            origin,
            col_step: DVec2::new(du, 0.0),
            row_step: DVec2::new(0.0, dv),
        }
    }

    /// The grid of a projection stack read as a volume whose `(x, y, z)` axes are
    /// `(col, row, projection)` and whose index-to-world `affine` is ITK's
    /// (`origin + direction·spacing·index`, as the MetaImage and NRRD readers give it).
    ///
    /// # Errors
    /// [`Error::Invalid`] when the projection axis moves the pixels within the plane
    /// (a direction that mixes the projection index into `x` or `y`), or the two
    /// pixel steps are degenerate.
    pub fn from_affine(cols: usize, rows: usize, affine: &DMat4) -> Result<Self> {
        let z = affine.z_axis;
        if z.x != 0.0 || z.y != 0.0 {
            return Err(Error::invalid(
                "projection image geometry",
                format!(
                    "the projection axis moves the pixels within the detector plane \
                     (its direction column is ({}, {}, {})): each projection would have \
                     its own origin, which an RTK geometry does not describe",
                    z.x, z.y, z.z
                ),
            ));
        }
        let g = DetectorGrid {
            cols,
            rows,
            origin: affine.w_axis.truncate().truncate(),
            col_step: affine.x_axis.truncate().truncate(),
            row_step: affine.y_axis.truncate().truncate(),
        };
        g.validate()?;
        Ok(g)
    }

    /// Checks the sizes and that the steps span the plane.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::invalid("detector grid", m));
        for (name, n) in [("columns", self.cols), ("rows", self.rows)] {
            if n == 0 || n > MAX_DETECTOR {
                return bad(format!("{n} {name} (1 to {MAX_DETECTOR})"));
            }
        }
        let all = [self.origin, self.col_step, self.row_step];
        if all
            .iter()
            .any(|v| !v.is_finite() || v.abs().max_element() > MAX_LENGTH_MM)
        {
            return bad(format!(
                "origin {:?}, steps {:?} and {:?} must be finite mm within ±{MAX_LENGTH_MM:e}",
                self.origin.to_array(),
                self.col_step.to_array(),
                self.row_step.to_array()
            ));
        }
        let area = self.col_step.perp_dot(self.row_step).abs();
        let scale = self.col_step.length() * self.row_step.length();
        if area.is_nan() || area <= 1e-12 * scale || area == 0.0 {
            return bad(format!(
                "the pixel steps {:?} and {:?} do not span the detector plane",
                self.col_step.to_array(),
                self.row_step.to_array()
            ));
        }
        Ok(())
    }
}

/// One `<Projection>` of an RTK geometry: RTK's nine parameters (angles in degrees as
/// in the file, lengths in mm).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RtkProjection {
    pub gantry_deg: f64,
    pub out_of_plane_deg: f64,
    pub in_plane_deg: f64,
    /// Source to isocentre distance.
    pub sid: f64,
    /// Source to detector distance; 0 for a parallel beam.
    pub sdd: f64,
    /// `(SourceOffsetX, SourceOffsetY)`.
    pub source_offset: DVec2,
    /// `(ProjectionOffsetX, ProjectionOffsetY)`.
    pub projection_offset: DVec2,
}

/// ITK's rotation matrices (`itk::Euler3DTransform::ComputeMatrix`).
fn rot_x(t: f64) -> DMat3 {
    let (s, c) = t.sin_cos();
    DMat3::from_cols_array_2d(&[[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])
}
fn rot_y(t: f64) -> DMat3 {
    let (s, c) = t.sin_cos();
    DMat3::from_cols_array_2d(&[[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])
}
fn rot_z(t: f64) -> DMat3 {
    let (s, c) = t.sin_cos();
    DMat3::from_cols_array_2d(&[[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
}

impl RtkProjection {
    /// A parallel beam (`SDD = 0`).
    pub fn is_parallel(&self) -> bool {
        self.sdd == 0.0
    }

    /// RTK's rotation `R = Rz(−i)·Rx(−o)·Ry(−g)`: world coordinates → the view's frame.
    pub fn rotation(&self) -> DMat3 {
        rot_z(-self.in_plane_deg.to_radians())
            * rot_x(-self.out_of_plane_deg.to_radians())
            * rot_y(-self.gantry_deg.to_radians())
    }

    /// RTK's 3×4 projection matrix (rows): world point `(P, 1)` → homogeneous physical
    /// coordinates `(U·w, V·w, w)` on the projection image (`GetMatrix`).
    pub fn matrix(&self) -> [[f64; 4]; 3] {
        let r = self.rotation();
        let (r0, r1, r2) = (r.row(0), r.row(1), r.row(2));
        let (sx, sy) = (self.source_offset.x, self.source_offset.y);
        let (tx, ty) = (sx - self.projection_offset.x, sy - self.projection_offset.y);
        let row = |a: DVec3, t: f64| [a.x, a.y, a.z, t];
        let (m0, m1, m2) = if self.is_parallel() {
            // T(tx, ty) · [[1,0,0,0],[0,1,0,0],[0,0,0,1]] · T(−sx, −sy, 0) · R
            (row(r0, -sx), row(r1, -sy), [0.0, 0.0, 0.0, 1.0])
        } else {
            // T(tx, ty) · [[−SDD,0,0,0],[0,−SDD,0,0],[0,0,1,−SID]] · T(−sx, −sy, 0) · R
            (
                row(-self.sdd * r0, self.sdd * sx),
                row(-self.sdd * r1, self.sdd * sy),
                row(r2, -self.sid),
            )
        };
        let add = |a: [f64; 4], t: f64| [0, 1, 2, 3].map(|j| a[j] + t * m2[j]);
        [add(m0, tx), add(m1, ty), m2]
    }

    /// The view's four vectors on `grid` (module docs).
    pub fn view_vectors(&self, grid: &DetectorGrid) -> ViewVectors {
        let back = self.rotation().transpose();
        let p = self.projection_offset;
        let plane = |uv: DVec2, z: f64| back * DVec3::new(uv.x, uv.y, z);
        let (source, z) = if self.is_parallel() {
            // RTK puts a parallel detector at −SID (its ProjectionCoordinatesToDetector
            // matrix); any plane along the rays gives the same lines.
            (back * DVec3::NEG_Z, -self.sid)
        } else {
            (
                back * DVec3::new(self.source_offset.x, self.source_offset.y, self.sid),
                self.sid - self.sdd,
            )
        };
        ViewVectors {
            source,
            pixel00: plane(grid.origin + p, z),
            u: plane(grid.col_step, 0.0),
            v: plane(grid.row_step, 0.0),
        }
    }
}

/// The contents of an RTK geometry file: its projections and the matrices written
/// with them (`None` where a projection has no `<Matrix>`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RtkGeometry {
    /// The file's `version` attribute (2 or 3).
    pub version: u32,
    pub projections: Vec<RtkProjection>,
    pub matrices: Vec<Option<[[f64; 4]; 3]>>,
}

impl RtkGeometry {
    /// One [`ViewVectors`] per projection on `grid`.
    ///
    /// # Errors
    /// [`Error::Invalid`] for a bad grid.
    pub fn view_geometry(&self, grid: &DetectorGrid) -> Result<ViewGeometry> {
        grid.validate()?;
        Ok(ViewGeometry {
            parallel: self.projections.first().is_some_and(|p| p.is_parallel()),
            cols: grid.cols,
            rows: grid.rows,
            views: self
                .projections
                .iter()
                .map(|p| p.view_vectors(grid))
                .collect(),
        })
    }
}

/// The element names of the format (compared without regard to case, as RTK does).
const PARAMETERS: &[&str] = &[
    "GantryAngle",
    "Angle",
    "OutOfPlaneAngle",
    "InPlaneAngle",
    "SourceToIsocenterDistance",
    "SourceToDetectorDistance",
    "SourceOffsetX",
    "SourceOffsetY",
    "ProjectionOffsetX",
    "ProjectionOffsetY",
    "RadiusCylindricalDetector",
    "CollimationUInf",
    "CollimationUSup",
    "CollimationVInf",
    "CollimationVSup",
    "Matrix",
];

/// The root element's name.
pub const RTK_ROOT: &str = "RTKThreeDCircularGeometry";

/// RTK's reader refuses a matrix entry further than this from the parameters' matrix.
const MATRIX_TOLERANCE: f64 = 0.001;

/// Parses an RTK geometry XML document (`path` only names it in errors).
///
/// # Errors
/// [`Error::Format`] naming the file and the element: not XML, another root element, a
/// version other than 2 or 3, an unknown element, a number that is not finite, a
/// cylindrical detector, parallel and cone-beam projections mixed, a `<Matrix>` that
/// disagrees with the parameters; [`Error::TooLarge`] past [`MAX_DETECTOR`]
/// projections.
pub fn parse_rtk_geometry(text: &str, path: &Path) -> Result<RtkGeometry> {
    use xml::reader::{ParserConfig2, XmlEvent};
    let bad = |field: &str, m: String| Error::format(path, field, m);
    let reader = ParserConfig2::new()
        .trim_whitespace(true)
        .cdata_to_characters(true)
        .ignore_comments(true)
        .coalesce_characters(true)
        .allow_multiple_root_elements(false)
        // No element name, attribute or number of this format is long; a value is one
        // number and a matrix twelve.
        .max_name_length(256)
        .max_attributes(16)
        .max_attribute_length(4096)
        .max_data_length(1 << 16)
        .max_entity_expansion_length(4096)
        .max_entity_expansion_depth(2)
        .create_reader(text.as_bytes());

    let mut out = RtkGeometry::default();
    let mut cur = RtkProjection::default();
    let mut matrix: Option<[[f64; 4]; 3]> = None;
    // The open elements (canonical names), and the text of the innermost one.
    let mut stack: Vec<&'static str> = Vec::new();
    let mut chars = String::new();
    let mut seen_root = false;
    for event in reader {
        // xml-rs writes the position (line:column) and the reason.
        let event =
            event.map_err(|e| bad("XML", crate::error::escape_controls(&e.to_string()).into()))?;
        match event {
            XmlEvent::StartElement {
                name, attributes, ..
            } => {
                let local = name.local_name.as_str();
                if stack.is_empty() {
                    if seen_root || !local.eq_ignore_ascii_case(RTK_ROOT) {
                        return Err(bad(
                            "root element",
                            format!("<{}> is not RTK's <{RTK_ROOT}>", super::snippet(local)),
                        ));
                    }
                    seen_root = true;
                    let version = attributes
                        .iter()
                        .find(|a| a.name.local_name == "version")
                        .map(|a| a.value.trim().to_string());
                    out.version = match version.as_deref().map(str::parse::<u32>) {
                        Some(Ok(v @ (2 | 3))) => v,
                        Some(_) => {
                            return Err(bad(
                                "version",
                                format!(
                                    "version \"{}\": RTK's geometry files are version 2 or 3",
                                    super::snippet(version.as_deref().unwrap_or(""))
                                ),
                            ))
                        }
                        None => {
                            return Err(bad(
                                "version",
                                format!(
                                "<{RTK_ROOT}> has no version attribute (RTK writes version=\"3\")"
                            ),
                            ))
                        }
                    };
                    stack.push(RTK_ROOT);
                    continue;
                }
                let parent = *stack.last().unwrap_or(&RTK_ROOT);
                if local.eq_ignore_ascii_case("Projection") {
                    if parent != RTK_ROOT {
                        return Err(bad("Projection", format!("<Projection> inside <{parent}>")));
                    }
                    if out.projections.len() >= MAX_DETECTOR {
                        return Err(Error::too_large(
                            format!("RTK geometry {}", path.display()),
                            format!("more than {MAX_DETECTOR} projections"),
                        ));
                    }
                    matrix = None;
                    stack.push("Projection");
                } else if let Some(&p) = PARAMETERS.iter().find(|p| local.eq_ignore_ascii_case(p)) {
                    if parent != RTK_ROOT && parent != "Projection" {
                        return Err(bad(p, format!("<{p}> inside <{parent}>")));
                    }
                    stack.push(p);
                } else {
                    return Err(bad(
                        "element",
                        format!(
                            "unknown element <{}> in <{parent}> (RTK's are Projection, {})",
                            super::snippet(local),
                            PARAMETERS.join(", ")
                        ),
                    ));
                }
                chars.clear();
            }
            XmlEvent::Characters(s) => match stack.last() {
                Some(&p) if p != RTK_ROOT && p != "Projection" => chars.push_str(&s),
                _ => {
                    return Err(bad(
                        "text",
                        format!(
                            "text '{}' outside a parameter element",
                            super::snippet(s.trim())
                        ),
                    ))
                }
            },
            XmlEvent::EndElement { .. } => {
                let Some(name) = stack.pop() else { continue };
                match name {
                    RTK_ROOT => {}
                    "Projection" => {
                        check_projection(&cur, out.projections.len(), &out.projections, path)?;
                        if let Some(m) = matrix {
                            check_matrix(&cur, &m, out.projections.len(), path)?;
                        }
                        out.projections.push(cur);
                        out.matrices.push(matrix);
                    }
                    "Matrix" => {
                        let nums: Vec<&str> = chars.split_whitespace().collect();
                        if nums.len() != 12 {
                            return Err(bad(
                                "Matrix",
                                format!(
                                    "projection {}: {} numbers, a 3×4 matrix has 12",
                                    out.projections.len(),
                                    nums.len()
                                ),
                            ));
                        }
                        let mut m = [[0.0; 4]; 3];
                        for (k, s) in nums.iter().enumerate() {
                            m[k / 4][k % 4] = number(s, "Matrix", path)?;
                        }
                        matrix = Some(m);
                    }
                    p => {
                        let v = number(chars.trim(), p, path)?;
                        match p {
                            "GantryAngle" | "Angle" => cur.gantry_deg = v,
                            "OutOfPlaneAngle" => cur.out_of_plane_deg = v,
                            "InPlaneAngle" => cur.in_plane_deg = v,
                            "SourceToIsocenterDistance" => cur.sid = v,
                            "SourceToDetectorDistance" => cur.sdd = v,
                            "SourceOffsetX" => cur.source_offset.x = v,
                            "SourceOffsetY" => cur.source_offset.y = v,
                            "ProjectionOffsetX" => cur.projection_offset.x = v,
                            "ProjectionOffsetY" => cur.projection_offset.y = v,
                            "RadiusCylindricalDetector" if v != 0.0 => {
                                return Err(bad(
                                    p,
                                    format!(
                                        "a cylindrical detector (radius {v} mm) is not \
                                         supported: voxlab's detectors are flat"
                                    ),
                                ))
                            }
                            // Collimation only masks rays in RTK's forward projectors.
                            _ => {}
                        }
                    }
                }
                chars.clear();
            }
            XmlEvent::EndDocument => break,
            _ => {}
        }
    }
    if !seen_root {
        return Err(bad(
            "root element",
            format!("no <{RTK_ROOT}> element: not an RTK geometry file"),
        ));
    }
    if out.projections.is_empty() {
        return Err(bad("Projection", "the file holds no <Projection>".into()));
    }
    Ok(out)
}

/// A finite number, as the text of element `field`.
fn number(s: &str, field: &str, path: &Path) -> Result<f64> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(Error::format(
            path,
            field,
            format!("'{}' is not a finite number", super::snippet(s)),
        )),
    }
}

/// The parameters of projection `k` make a geometry, of the same kind as the earlier
/// ones.
fn check_projection(
    p: &RtkProjection,
    k: usize,
    earlier: &[RtkProjection],
    path: &Path,
) -> Result<()> {
    let bad =
        |field: &str, m: String| Err(Error::format(path, field, format!("projection {k}: {m}")));
    for (name, v) in [
        ("SourceToIsocenterDistance", p.sid),
        ("SourceToDetectorDistance", p.sdd),
        ("SourceOffsetX", p.source_offset.x),
        ("SourceOffsetY", p.source_offset.y),
        ("ProjectionOffsetX", p.projection_offset.x),
        ("ProjectionOffsetY", p.projection_offset.y),
    ] {
        if v.abs() > MAX_LENGTH_MM {
            return bad(name, format!("{v:e} mm is beyond ±{MAX_LENGTH_MM:e} mm"));
        }
    }
    for (name, v) in [
        ("GantryAngle", p.gantry_deg),
        ("OutOfPlaneAngle", p.out_of_plane_deg),
        ("InPlaneAngle", p.in_plane_deg),
    ] {
        if v.abs() > 1e9 {
            return bad(name, format!("{v:e} degrees"));
        }
    }
    if let Some(first) = earlier.first() {
        if first.is_parallel() != p.is_parallel() {
            return bad(
                "SourceToDetectorDistance",
                format!(
                    "SDD = {} after {} projection(s) with SDD = {}: parallel (SDD 0) and \
                     cone-beam projections cannot be mixed",
                    p.sdd,
                    earlier.len(),
                    first.sdd
                ),
            );
        }
    }
    if !p.is_parallel() {
        if p.sdd < 0.0 || p.sid <= 0.0 {
            return bad(
                "SourceToDetectorDistance",
                format!(
                    "SID = {} mm and SDD = {} mm: a cone beam needs both positive",
                    p.sid, p.sdd
                ),
            );
        }
        if p.sdd < crate::ct::MIN_LENGTH_MM {
            return bad("SourceToDetectorDistance", format!("SDD = {:e} mm", p.sdd));
        }
    }
    Ok(())
}

/// RTK's own check: the matrix written must be the parameters' to 0.001.
fn check_matrix(p: &RtkProjection, m: &[[f64; 4]; 3], k: usize, path: &Path) -> Result<()> {
    let want = p.matrix();
    for i in 0..3 {
        for j in 0..4 {
            if (m[i][j] - want[i][j]).abs() > MATRIX_TOLERANCE {
                return Err(Error::format(
                    path,
                    "Matrix",
                    format!(
                        "projection {k}: entry ({i}, {j}) is {} but the parameters give {} \
                         (RTK's reader refuses this too: the matrix and the parameters \
                         disagree)",
                        m[i][j], want[i][j]
                    ),
                ));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const ONE: &str = r#"<?xml version="1.0"?>
<!DOCTYPE RTKGEOMETRY>
<RTKThreeDCircularGeometry version="3">
    <SourceToIsocenterDistance>1000</SourceToIsocenterDistance>
    <SourceToDetectorDistance>1500</SourceToDetectorDistance>
  <Projection>
    <GantryAngle>90</GantryAngle>
  </Projection>
</RTKThreeDCircularGeometry>
"#;

    #[test]
    fn a_plain_circular_view_is_rtks_circle() {
        let g = parse_rtk_geometry(ONE, Path::new("one.xml")).unwrap();
        assert_eq!(g.projections.len(), 1);
        let v = g.projections[0].view_vectors(&DetectorGrid::centred(3, 1, 2.0, 2.0));
        // Gantry 90°: source at SID·(1, 0, 0), e_u = (0, 0, −1).
        assert!((v.source - DVec3::new(1000.0, 0.0, 0.0)).length() < 1e-9);
        assert!((v.u - DVec3::new(0.0, 0.0, -2.0)).length() < 1e-12);
        assert!((v.pixel00 - DVec3::new(-500.0, 0.0, 2.0)).length() < 1e-9);
    }

    #[test]
    fn bad_files_are_refused_with_the_element() {
        let cases = [
            ("<a/>", "root element"),
            ("<RTKThreeDCircularGeometry version=\"4\"/>", "version"),
            ("<RTKThreeDCircularGeometry version=\"3\"/>", "Projection"),
            (
                "<RTKThreeDCircularGeometry version=\"3\"><Projection><GantryAngle>x</GantryAngle></Projection></RTKThreeDCircularGeometry>",
                "GantryAngle",
            ),
            (
                "<RTKThreeDCircularGeometry version=\"3\"><RadiusCylindricalDetector>800</RadiusCylindricalDetector><Projection/></RTKThreeDCircularGeometry>",
                "RadiusCylindricalDetector",
            ),
            (
                "<RTKThreeDCircularGeometry version=\"3\"><Projection><Gantry>1</Gantry></Projection></RTKThreeDCircularGeometry>",
                "element",
            ),
            (
                "<RTKThreeDCircularGeometry version=\"3\"><SourceToIsocenterDistance>1000</SourceToIsocenterDistance><Projection><SourceToDetectorDistance>1500</SourceToDetectorDistance></Projection><Projection><SourceToDetectorDistance>0</SourceToDetectorDistance></Projection></RTKThreeDCircularGeometry>",
                "SourceToDetectorDistance",
            ),
            (
                "<RTKThreeDCircularGeometry version=\"3\"><Projection><Matrix>1 0 0 0 0 1 0 0 0 0 0 1</Matrix><ProjectionOffsetX>5</ProjectionOffsetX></Projection></RTKThreeDCircularGeometry>",
                "Matrix",
            ),
            ("<RTKThreeDCircularGeometry version=\"3\"><Projection>", "XML"),
        ];
        for (text, field) in cases {
            match parse_rtk_geometry(text, Path::new("g.xml")) {
                Err(Error::Format { field: f, .. }) => assert_eq!(f, field, "{text}"),
                other => panic!("{text}: {other:?}"),
            }
        }
    }

    #[test]
    fn parallel_source_offsets_cancel() {
        let p = RtkProjection {
            gantry_deg: 30.0,
            source_offset: DVec2::new(3.0, -2.0),
            ..Default::default()
        };
        let q = RtkProjection {
            source_offset: DVec2::ZERO,
            ..p
        };
        assert_eq!(p.matrix(), q.matrix());
    }
}
