//! ASTRA's 3-D projection geometries: a `proj_geom` dict (`astra.create_proj_geom`)
//! saved as JSON, read into one [`ViewVectors`] per projection.
//!
//! ```json
//! { "type": "cone", "DetectorSpacingX": 1.5, "DetectorSpacingY": 2.0,
//!   "DetectorRowCount": 20, "DetectorColCount": 24,
//!   "ProjectionAngles": [0.0, 0.628, 1.257],
//!   "DistanceOriginSource": 800.0, "DistanceOriginDetector": 400.0 }
//! ```
//!
//! Saved from Python with
//! `json.dump({k: (v.tolist() if hasattr(v, "tolist") else v) for k, v in proj_geom.items()}, f)`.
//!
//! | `type` | keys |
//! |---|---|
//! | `cone` | `DetectorSpacingX`, `DetectorSpacingY`, `DetectorRowCount`, `DetectorColCount`, `ProjectionAngles` (radians), `DistanceOriginSource`, `DistanceOriginDetector` |
//! | `parallel3d` | `DetectorSpacingX`, `DetectorSpacingY`, `DetectorRowCount`, `DetectorColCount`, `ProjectionAngles` (radians) |
//! | `cone_vec` | `DetectorRowCount`, `DetectorColCount`, `Vectors`: one row of 12 per projection, `(src, d, u, v)` |
//! | `parallel3d_vec` | `DetectorRowCount`, `DetectorColCount`, `Vectors`: `(ray, d, u, v)` |
//!
//! `cone` and `parallel3d` become vectors exactly as ASTRA's `geom_2vec`
//! (`python/astra/functions.py`) makes them: at angle `θ` the source is at
//! `DSO·(sin θ, −cos θ, 0)`, the detector centre at `DOD·(−sin θ, cos θ, 0)`,
//! `u = DetectorSpacingX·(cos θ, sin θ, 0)`, `v = (0, 0, DetectorSpacingY)`; a parallel
//! ray is `(sin θ, −cos θ, 0)`. [`AstraGeometry::vectors`] holds that form.
//!
//! # ASTRA's detector and frame
//!
//! `d` is the centre of the whole detector, `u` the step from one detector column to
//! the next and `v` from one row to the next (ASTRA's projection data are
//! `(rows, angles, cols)`, the column fastest). ASTRA's corner of the detector is
//! `d − (cols/2)·u − (rows/2)·v` and pixel centres sit half a pixel in
//! (`ConeVecProjectionGeometry3D.cpp`, `projectPoint`'s `− 0.5`), so pixel `(col, row)`
//! has its centre at `d + (col + ½ − cols/2)·u + (row + ½ − rows/2)·v`.
//!
//! ASTRA's objects turn about its `z` axis; voxlab's about `+y`. The rotation
//! [`astra_to_ct`], `(x, y, z) → (x, z, −y)` (the same as
//! [`crate::ct::phantom_to_ct`]), maps one onto the other: it takes ASTRA's `cone`
//! geometry at angle `θ` onto RTK's circular geometry at gantry angle `θ` (SID = DSO,
//! SDD = DSO + DOD, the same pixel `(col, row)`; `Geometry::cone_rtk`), and ASTRA's
//! `parallel3d` onto voxlab's parallel stack at `θ`. The projection arrays are ordered
//! differently: ASTRA's `(rows, angles, cols)` is voxlab's `(angles, rows, cols)`
//! transposed (`np.transpose(p, (1, 0, 2))`). A volume on ASTRA's grid, `a[z, y, x]`,
//! holds the same point as voxlab's CT-frame array `b[Z, Y, X]` at
//! `b = a.transpose(1, 0, 2)[::-1]` (ASTRA's `z` is voxlab's `Y`, its `y` voxlab's
//! `−Z`; both grids centre their voxels alike).
//!
//! A parallel ray's sign carries no meaning (line integrals do not depend on it;
//! ASTRA's own `geom_2vec` and its internal `parallel3d` disagree on it), so
//! `parallel3d_vec` rays are taken as written.

use crate::ct::{ViewGeometry, ViewVectors, MAX_DETECTOR, MAX_LENGTH_MM};
use crate::error::{Error, Result};
use glam::DVec3;
use serde::Deserialize;
use std::path::Path;

/// ASTRA's frame → voxlab's CT frame: `(x, y, z) → (x, z, −y)`, a proper rotation that
/// takes ASTRA's rotation axis `z` to voxlab's `y`.
pub fn astra_to_ct(p: DVec3) -> DVec3 {
    DVec3::new(p.x, p.z, -p.y)
}

/// The geometries read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AstraKind {
    Cone,
    ConeVec,
    Parallel3d,
    Parallel3dVec,
}

impl AstraKind {
    /// ASTRA's name (`type`).
    pub fn name(self) -> &'static str {
        match self {
            AstraKind::Cone => "cone",
            AstraKind::ConeVec => "cone_vec",
            AstraKind::Parallel3d => "parallel3d",
            AstraKind::Parallel3dVec => "parallel3d_vec",
        }
    }

    /// Parallel rays.
    pub fn parallel(self) -> bool {
        matches!(self, AstraKind::Parallel3d | AstraKind::Parallel3dVec)
    }
}

/// An ASTRA projection geometry in vector form (ASTRA's frame and layout).
#[derive(Clone, Debug, PartialEq)]
pub struct AstraGeometry {
    /// The `type` read (`cone` and `parallel3d` are turned into vectors).
    pub kind: AstraKind,
    pub rows: usize,
    pub cols: usize,
    /// One row per projection: `(src or ray, d, u, v)`, as ASTRA's `Vectors` (for
    /// `cone` and `parallel3d`, what `geom_2vec` gives).
    pub vectors: Vec<[f64; 12]>,
}

impl AstraGeometry {
    /// The views in voxlab's CT frame (module docs).
    pub fn view_geometry(&self) -> ViewGeometry {
        let (rows, cols) = (self.rows as f64, self.cols as f64);
        let views = self
            .vectors
            .iter()
            .map(|r| {
                let at = |i: usize| DVec3::new(r[i], r[i + 1], r[i + 2]);
                let (s, d, u, v) = (at(0), at(3), at(6), at(9));
                let pixel00 = d - (cols - 1.0) / 2.0 * u - (rows - 1.0) / 2.0 * v;
                ViewVectors {
                    source: astra_to_ct(s),
                    pixel00: astra_to_ct(pixel00),
                    u: astra_to_ct(u),
                    v: astra_to_ct(v),
                }
            })
            .collect();
        ViewGeometry {
            parallel: self.kind.parallel(),
            cols: self.cols,
            rows: self.rows,
            views,
        }
    }
}

/// The `type` of a JSON object, if it has one (the other keys are skipped unread).
pub(crate) fn json_type(text: &str) -> Option<String> {
    #[derive(Deserialize)]
    struct Peek {
        #[serde(rename = "type")]
        kind: Option<String>,
    }
    serde_json::from_str::<Peek>(text).ok().and_then(|p| p.kind)
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct AnglesJson {
    #[serde(rename = "type")]
    _kind: String,
    #[serde(rename = "DetectorSpacingX")]
    spacing_x: f64,
    #[serde(rename = "DetectorSpacingY")]
    spacing_y: f64,
    #[serde(rename = "DetectorRowCount")]
    rows: usize,
    #[serde(rename = "DetectorColCount")]
    cols: usize,
    #[serde(rename = "ProjectionAngles", deserialize_with = "crate::json::bounded")]
    angles: Vec<f64>,
    #[serde(rename = "DistanceOriginSource", default)]
    dso: Option<f64>,
    #[serde(rename = "DistanceOriginDetector", default)]
    dod: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct VectorsJson {
    #[serde(rename = "type")]
    _kind: String,
    #[serde(rename = "DetectorRowCount")]
    rows: usize,
    #[serde(rename = "DetectorColCount")]
    cols: usize,
    #[serde(rename = "Vectors", deserialize_with = "crate::json::bounded")]
    vectors: Vec<[f64; 12]>,
}

/// Parses ASTRA's `proj_geom` as JSON (`path` only names it in errors).
///
/// # Errors
/// [`Error::Format`] naming the file and the key: not JSON, a `type` voxlab does not
/// read (2-D geometries and `cyl_cone_vec` are named as such), a missing or unknown key,
/// counts outside `1..=`[`MAX_DETECTOR`], spacings or distances that are not positive
/// and finite, vectors that are not finite.
pub fn parse_astra_geometry(text: &str, path: &Path) -> Result<AstraGeometry> {
    let bad = |field: &str, m: String| Error::format(path, field, m);
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let Some(kind_name) = json_type(text) else {
        return Err(bad(
            "type",
            "not a JSON object with a string \"type\" (ASTRA's proj_geom)".into(),
        ));
    };
    let kind = match kind_name.as_str() {
        "cone" => AstraKind::Cone,
        "cone_vec" => AstraKind::ConeVec,
        "parallel3d" => AstraKind::Parallel3d,
        "parallel3d_vec" => AstraKind::Parallel3dVec,
        "parallel" | "parallel_vec" | "fanflat" | "fanflat_vec" | "sparse_matrix" => {
            return Err(bad(
                "type",
                format!(
                    "\"{kind_name}\" is a 2-D ASTRA geometry: give its 3-D form \
                     (parallel3d, cone, … with DetectorRowCount 1)"
                ),
            ))
        }
        "cyl_cone_vec" => {
            return Err(bad(
                "type",
                "\"cyl_cone_vec\": a cylindrical detector is not supported (voxlab's \
                 detectors are flat)"
                    .into(),
            ))
        }
        other => {
            return Err(bad(
                "type",
                format!(
                    "\"{}\" is not one of cone, cone_vec, parallel3d, parallel3d_vec",
                    super::snippet(other)
                ),
            ))
        }
    };
    let serde_err = |e: serde_json::Error| bad(kind.name(), crate::json::explain(&e.to_string()));
    let g = match kind {
        AstraKind::Cone | AstraKind::Parallel3d => {
            let j: AnglesJson = serde_json::from_str(text).map_err(serde_err)?;
            check_counts(j.rows, j.cols, j.angles.len(), path)?;
            positive("DetectorSpacingX", j.spacing_x, path)?;
            positive("DetectorSpacingY", j.spacing_y, path)?;
            if let Some(k) = j
                .angles
                .iter()
                .position(|a| !a.is_finite() || a.abs() > 1e9)
            {
                return Err(bad(
                    "ProjectionAngles",
                    format!(
                        "angle {k} ({}) is not a finite angle in radians",
                        j.angles[k]
                    ),
                ));
            }
            let (dso, dod) = match (kind, j.dso, j.dod) {
                (AstraKind::Cone, Some(s), Some(d)) => {
                    positive("DistanceOriginSource", s, path)?;
                    positive("DistanceOriginDetector", d, path)?;
                    (s, d)
                }
                (AstraKind::Cone, _, _) => {
                    return Err(bad(
                        "DistanceOriginSource",
                        "a cone geometry needs DistanceOriginSource and \
                         DistanceOriginDetector (mm)"
                            .into(),
                    ))
                }
                (_, None, None) => (0.0, 0.0),
                _ => {
                    return Err(bad(
                        "DistanceOriginSource",
                        "a parallel3d geometry has no source or detector distance".into(),
                    ))
                }
            };
            let vectors = j
                .angles
                .iter()
                .map(|&t| geom_2vec(kind, t, dso, dod, j.spacing_x, j.spacing_y))
                .collect();
            AstraGeometry {
                kind,
                rows: j.rows,
                cols: j.cols,
                vectors,
            }
        }
        AstraKind::ConeVec | AstraKind::Parallel3dVec => {
            let j: VectorsJson = serde_json::from_str(text).map_err(serde_err)?;
            check_counts(j.rows, j.cols, j.vectors.len(), path)?;
            for (k, r) in j.vectors.iter().enumerate() {
                if let Some(i) = r
                    .iter()
                    .position(|x| !x.is_finite() || x.abs() > MAX_LENGTH_MM)
                {
                    return Err(bad(
                        "Vectors",
                        format!(
                            "projection {k}, number {i} ({}) is not a finite length within \
                             ±{MAX_LENGTH_MM:e} mm",
                            r[i]
                        ),
                    ));
                }
            }
            AstraGeometry {
                kind,
                rows: j.rows,
                cols: j.cols,
                vectors: j.vectors,
            }
        }
    };
    Ok(g)
}

/// One row of ASTRA's `geom_2vec` for a `cone` (`dso`, `dod`) or `parallel3d`
/// geometry at angle `t` (radians).
fn geom_2vec(kind: AstraKind, t: f64, dso: f64, dod: f64, sx: f64, sy: f64) -> [f64; 12] {
    let (s, c) = t.sin_cos();
    match kind {
        AstraKind::Cone => [
            s * dso,
            -c * dso,
            0.0,
            -s * dod,
            c * dod,
            0.0,
            c * sx,
            s * sx,
            0.0,
            0.0,
            0.0,
            sy,
        ],
        _ => [s, -c, 0.0, 0.0, 0.0, 0.0, c * sx, s * sx, 0.0, 0.0, 0.0, sy],
    }
}

fn check_counts(rows: usize, cols: usize, views: usize, path: &Path) -> Result<()> {
    for (name, n) in [
        ("DetectorRowCount", rows),
        ("DetectorColCount", cols),
        ("ProjectionAngles", views),
    ] {
        if n == 0 || n > MAX_DETECTOR {
            return Err(Error::format(
                path,
                name,
                format!("{n}: must be 1 to {MAX_DETECTOR}"),
            ));
        }
    }
    Ok(())
}

fn positive(name: &str, v: f64, path: &Path) -> Result<()> {
    if (crate::ct::MIN_LENGTH_MM..=MAX_LENGTH_MM).contains(&v) {
        Ok(())
    } else {
        Err(Error::format(
            path,
            name,
            format!(
                "{v}: must be a length in [{:e}, {MAX_LENGTH_MM:e}] mm",
                crate::ct::MIN_LENGTH_MM
            ),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn astra_frame_is_a_proper_rotation_onto_the_ct_frame() {
        let (x, y, z) = (
            astra_to_ct(DVec3::X),
            astra_to_ct(DVec3::Y),
            astra_to_ct(DVec3::Z),
        );
        assert_eq!(z, DVec3::Y, "ASTRA's rotation axis is voxlab's");
        assert_eq!(x.cross(y), z, "right-handed");
    }

    #[test]
    fn bad_proj_geoms_name_the_key() {
        let cases = [
            (r#"{"type": "fanflat"}"#, "type"),
            (r#"{"type": "cyl_cone_vec"}"#, "type"),
            (r#"{"DetectorRowCount": 1}"#, "type"),
            (
                r#"{"type": "cone_vec", "DetectorRowCount": 0, "DetectorColCount": 2, "Vectors": [[0,0,0,0,0,0,0,0,0,0,0,0]]}"#,
                "DetectorRowCount",
            ),
            (
                r#"{"type": "cone_vec", "DetectorRowCount": 1, "DetectorColCount": 2, "Vectors": [[0,0,0]]}"#,
                "cone_vec",
            ),
            (
                r#"{"type": "cone", "DetectorSpacingX": 1, "DetectorSpacingY": 1, "DetectorRowCount": 1, "DetectorColCount": 2, "ProjectionAngles": [0], "DistanceOriginSource": 10}"#,
                "DistanceOriginSource",
            ),
            (
                r#"{"type": "parallel3d", "DetectorSpacingX": -1, "DetectorSpacingY": 1, "DetectorRowCount": 1, "DetectorColCount": 2, "ProjectionAngles": [0]}"#,
                "DetectorSpacingX",
            ),
            (
                r#"{"type": "parallel3d", "DetectorSpacingX": 1, "DetectorSpacingY": 1, "DetectorRowCount": 1, "DetectorColCount": 2, "ProjectionAngles": [0], "Extra": 1}"#,
                "parallel3d",
            ),
        ];
        for (text, field) in cases {
            match parse_astra_geometry(text, Path::new("g.json")) {
                Err(Error::Format { field: f, .. }) => assert_eq!(f, field, "{text}"),
                other => panic!("{text}: {other:?}"),
            }
        }
    }
}
