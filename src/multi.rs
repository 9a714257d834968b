//! Multi-volume scenes: up to three volumes, each with its own transfer function and
//! its own placement in one shared world, rendered into one image (`cpu::multi`,
//! `gpu::multi`; docs/multi-volume.md).
//!
//! # Frames
//! Volume `i` keeps its own affine `A_i` (index → the volume's own world frame, from its
//! file or `Phantom::sample`), and its 3×4 transform `T_i` places that frame in the
//! shared world:
//!
//! `x_world = T_i · A_i · p_index`,   `T_i = [[a b c d] [e f g h] [i j k l]]` (row-major,
//! the last column the translation in mm).
//!
//! With `T_i` the identity a volume sits where the single-volume caster puts it.
//!
//! # Combining the volumes (Gavrilov & Turlapov, "InVols" §3; Fluør 2006 §2.1)
//! One ray crosses the union of the volumes' boxes with one step `Δ` (world mm); at each
//! sample every volume whose box contains it is sampled in its own index coordinates
//! (outside its box a volume contributes nothing), and
//! - **DVR**: each volume's opacity `α_i` (per reference step of `reference_step` of its
//!   own voxels, as the single-volume caster's opacity correction defines it) becomes an
//!   extinction `σ_i = −ln(1 − α_i) · s_i / Δ_ref`, `s_i` the volume's voxels per mm
//!   along the ray. The extinctions add, the colours mix weighted by extinction:
//!   `σ = Σ σ_i`, `c = Σ σ_i c_i / σ`, and the step composites front to back with
//!   `α = 1 − exp(−σ Δ)`. One volume gives `α = 1 − (1 − α_1)^(Δ s_1/Δ_ref)`, exactly the
//!   single-volume caster. A fully opaque sample (`α_i = 1`, `σ_i = ∞`) makes the step
//!   opaque with the mean colour of the opaque volumes there (the limit of the rule).
//! - **X-ray**: the line integrals add (`Σ_k Σ_i f_i(p_k) Δ_k`).
//! - **MIP / MinIP**: the maximum / minimum over samples and volumes.
//!
//! The step is `step` voxels of volume 0 measured along the ray, `Δ = step / s_0`,
//! exactly the single-volume caster's step for volume 0; for a unit-spaced volume 0 it
//! is `step` mm. Shading (optional per volume) uses each volume's gradient mapped to the
//! world by the inverse transpose of `T_i A_i`'s linear part.

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::settings::{Classification, Filter, Mode, RenderSettings};
use crate::transfer::TransferFunction;
use crate::volume::AnyVolume;
use glam::{DMat3, DMat4, DVec3, DVec4};

/// The most volumes one multi-volume render draws (the GPU binds three textures).
pub const MAX_VOLUMES: usize = 3;

/// The identity as a row-major 3×4 transform.
pub const IDENTITY: [f64; 12] = [
    1.0, 0.0, 0.0, 0.0, //
    0.0, 1.0, 0.0, 0.0, //
    0.0, 0.0, 1.0, 0.0,
];

/// One volume of a multi-volume scene.
#[derive(Clone, Debug)]
pub struct MultiVolume {
    pub volume: AnyVolume,
    pub transfer: TransferFunction,
    /// Row-major 3×4 transform from the volume's own world frame (its affine) into the
    /// shared world; see the module docs.
    pub transform: [f64; 12],
    /// Phong-shade this volume's samples (when the settings' shading is on).
    pub shade: bool,
}

impl MultiVolume {
    /// A volume placed by the identity, shaded.
    pub fn new(volume: AnyVolume, transfer: TransferFunction) -> Self {
        MultiVolume {
            volume,
            transfer,
            transform: IDENTITY,
            shade: true,
        }
    }

    /// The same volume placed by `transform` (row-major 3×4).
    pub fn with_transform(self, transform: [f64; 12]) -> Self {
        MultiVolume { transform, ..self }
    }

    /// `T_i · A_i`: the volume's index coordinates → the shared world.
    pub fn index_to_world(&self) -> Result<DMat4> {
        Ok(transform_matrix(&self.transform)? * self.volume.affine())
    }
}

/// The 4×4 matrix of a row-major 3×4 transform, after checking that it is finite and
/// invertible.
pub fn transform_matrix(t: &[f64; 12]) -> Result<DMat4> {
    if let Some(x) = t.iter().find(|x| !x.is_finite()) {
        return Err(Error::invalid(
            "volume transform",
            format!("{x} is not finite: all 12 entries must be finite numbers"),
        ));
    }
    let m = DMat4::from_cols(
        DVec4::new(t[0], t[4], t[8], 0.0),
        DVec4::new(t[1], t[5], t[9], 0.0),
        DVec4::new(t[2], t[6], t[10], 0.0),
        DVec4::new(t[3], t[7], t[11], 1.0),
    );
    let lin = DMat3::from_mat4(m);
    let scale = lin
        .to_cols_array()
        .iter()
        .fold(0.0f64, |a, x| a.max(x.abs()));
    let det = lin.determinant();
    if det.abs().partial_cmp(&(1e-12 * scale.powi(3))) != Some(std::cmp::Ordering::Greater)
        || scale == 0.0
    {
        return Err(Error::invalid(
            "volume transform",
            format!(
                "its 3×3 part is singular (determinant {det:.3e}): a transform must map \
                 the volume onto a solid, not a plane, line or point"
            ),
        ));
    }
    Ok(m)
}

/// Parses `a,b,c,d,e,f,g,h,i,j,k,l` (row-major 3×4) and checks it.
pub fn parse_transform(text: &str) -> Result<[f64; 12]> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if parts.len() != 12 {
        return Err(Error::invalid(
            "--transform",
            format!(
                "'{text}' has {} values; a transform is 12 comma-separated numbers \
                 (a row-major 3×4 matrix)",
                parts.len()
            ),
        ));
    }
    let mut t = [0.0; 12];
    for (slot, p) in t.iter_mut().zip(&parts) {
        *slot = p.parse::<f64>().map_err(|_| {
            Error::invalid("--transform", format!("'{p}' in '{text}' is not a number"))
        })?;
    }
    transform_matrix(&t)?;
    Ok(t)
}

/// A row-major 3×4 transform: rotation by `angle_deg` about world axis `axis` (0, 1, 2)
/// about the origin, then translation by `shift` mm.
pub fn rotation_translation(axis: usize, angle_deg: f64, shift: DVec3) -> [f64; 12] {
    let r = match axis {
        0 => DMat3::from_rotation_x(angle_deg.to_radians()),
        1 => DMat3::from_rotation_y(angle_deg.to_radians()),
        _ => DMat3::from_rotation_z(angle_deg.to_radians()),
    };
    let (x, y, z) = (r.row(0), r.row(1), r.row(2));
    [
        x.x, x.y, x.z, shift.x, y.x, y.y, y.z, shift.y, z.x, z.y, z.z, shift.z,
    ]
}

/// Checks a multi-volume render's inputs that do not depend on the backend: 1 … 3
/// volumes, finite invertible transforms, valid transfer functions and volumes, and
/// settings the combination rule covers.
pub fn validate(volumes: &[MultiVolume], settings: &RenderSettings) -> Result<()> {
    if volumes.is_empty() || volumes.len() > MAX_VOLUMES {
        return Err(Error::invalid(
            "volumes",
            format!(
                "{} given: a multi-volume render draws 1 … {MAX_VOLUMES} volumes",
                volumes.len()
            ),
        ));
    }
    for (i, v) in volumes.iter().enumerate() {
        v.index_to_world()
            .map_err(|e| Error::invalid(format!("volume {i}"), e.to_string()))?;
        v.transfer.validate()?;
        v.volume.check_finite(&format!("volume {i}"))?;
    }
    validate_settings(settings)
}

/// The most samples a ray through the union of the boxes may take, from the union's
/// world bounding box and the shortest step (`step / ‖M_0⁻¹‖`).
pub fn max_samples_per_ray(boxes: &[([usize; 3], DMat4)], step: f64) -> f64 {
    let (mut lo, mut hi) = (glam::DVec3::splat(f64::INFINITY), glam::DVec3::NEG_INFINITY);
    for (dims, m) in boxes {
        for w in crate::volume::box_corners(*dims, *m) {
            lo = lo.min(w);
            hi = hi.max(w);
        }
    }
    let inv = DMat3::from_mat4(boxes[0].1).inverse();
    let norm = inv
        .to_cols_array()
        .iter()
        .map(|x| x * x)
        .sum::<f64>()
        .sqrt();
    (hi - lo).length() * norm / step + 2.0
}

/// Refuses a multi-volume render of the boxes `(dims, index → world)` with too many
/// samples per ray or per frame ([`crate::settings::check_ray_work`] on
/// [`max_samples_per_ray`]); returns the samples per ray.
///
/// # Errors
/// [`Error::TooLarge`].
pub fn check_ray_work(
    boxes: &[([usize; 3], DMat4)],
    camera: &Camera,
    settings: &RenderSettings,
) -> Result<f64> {
    let per_ray = max_samples_per_ray(boxes, settings.step);
    crate::settings::check_ray_work("multi-volume render", settings.step, per_ray, camera)?;
    Ok(per_ray)
}

/// [`validate`] and [`check_ray_work`]: what a multi-volume render of `volumes` through
/// `camera` checks on any backend before it converts a voxel (the GPU adds its own,
/// `gpu::multi::check`); `voxlab render --volume … --dry-run` calls it too. Returns the
/// samples per ray.
///
/// # Errors
/// As [`validate`] and [`check_ray_work`].
pub fn check(volumes: &[MultiVolume], camera: &Camera, settings: &RenderSettings) -> Result<f64> {
    validate(volumes, settings)?;
    let boxes: Vec<_> = volumes
        .iter()
        .map(|v| Ok((v.volume.dims(), v.index_to_world()?)))
        .collect::<Result<_>>()?;
    check_ray_work(&boxes, camera, settings)
}

/// The settings a multi-volume render supports.
pub fn validate_settings(settings: &RenderSettings) -> Result<()> {
    settings.validate()?;
    let refuse = |what: &str| {
        Err(Error::invalid(
            "multi-volume render",
            format!("{what} is not supported with several volumes"),
        ))
    };
    if !matches!(
        settings.mode,
        Mode::Dvr | Mode::Mip | Mode::Minip | Mode::Xray
    ) {
        return refuse(&format!(
            "mode {:?} (use dvr, mip, minip or xray)",
            settings.mode
        ));
    }
    if settings.classification == Classification::Pre && settings.mode == Mode::Dvr {
        return refuse("pre-classification");
    }
    if settings.transfer_2d.is_some() {
        return refuse("a 2D transfer function");
    }
    if settings.filter == Filter::Sinc {
        return refuse("the full sinc filter");
    }
    if settings.clip_box.is_some() {
        return refuse("a clipping box");
    }
    if settings.jitter.is_some() || settings.interleaved {
        return refuse("jittered or interleaved sampling");
    }
    if settings.window.is_some() {
        return refuse("the MIP/MinIP grey window");
    }
    if !settings.iso_surfaces.is_empty() {
        return refuse("iso-surfaces");
    }
    Ok(())
}
