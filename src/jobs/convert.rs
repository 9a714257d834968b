//! `voxlab convert`: a volume in another format, optionally cropped, resampled (any
//! reconstruction filter, in f64 through the oracle's filters) and converted to
//! another voxel type.
//!
//! Converting keeps every value: NaN and ±∞ voxels of a float volume stay in a float
//! output (the rendering rule that replaces them is not applied). An integer output
//! type or resampling cannot keep them and is refused, unless `replace_non_finite`
//! asks for the rendering rule (NaN and −∞ → the smallest finite value, +∞ → the
//! largest, with a warning); `input.load.non_finite = error` refuses them in any case.

use super::input::VolumeInput;
use super::Progress;
use crate::error::{Error, Result};
use crate::settings::Filter;
use crate::volume::{AnyVolume, VoxelKind};
use serde::{Deserialize, Serialize};

/// The `voxlab convert` job (the output file is the caller's).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ConvertRequest {
    pub input: VolumeInput,
    /// Keep only the voxels `x0..x1, y0..y1, z0..z1` (end exclusive), given as
    /// `[x0, y0, z0, x1, y1, z1]`; the world position of every kept voxel is unchanged.
    pub crop: Option<[usize; 6]>,
    /// Resample (after cropping) to these dimensions over the same box.
    pub resize: Option<[usize; 3]>,
    /// Resample (after cropping) to this spacing in mm (one value or three) over the
    /// same box.
    pub spacing: Option<Vec<f64>>,
    /// Reconstruction filter for resampling.
    pub filter: Filter,
    /// Voxel type of the output: u8, u16, i16 or f32 (values rounded and clamped into
    /// integer types). `None`: the input's type, or f32 after resampling.
    pub voxel_type: Option<String>,
    /// Replace NaN and infinite voxels as rendering does, so that an integer type or
    /// resampling can take them (`--replace-non-finite`).
    pub replace_non_finite: bool,
    /// Multiply every value by this (finite, positive) before the type conversion, as
    /// a scanner stores intensities: `--type u16 --scale 65535` keeps a [0, 1] volume's
    /// detail ([`quantise`]). `None`: the values as they are.
    pub scale: Option<f64>,
}

impl Default for ConvertRequest {
    fn default() -> Self {
        ConvertRequest {
            input: VolumeInput::default(),
            crop: None,
            resize: None,
            spacing: None,
            filter: Filter::Trilinear,
            voxel_type: None,
            replace_non_finite: false,
            scale: None,
        }
    }
}

/// `vol` as a volume of `kind`: each value times `scale`, rounded and saturated into an
/// integer type (`round(v · scale)`), as a scanner stores intensities; for f32 the
/// product itself (computed in f64, stored in f32).
///
/// # Errors
/// A `scale` that is not finite and positive.
pub fn quantise(vol: &AnyVolume, kind: VoxelKind, scale: f64) -> Result<AnyVolume> {
    check_scale(scale)?;
    let v = vol.to_f32();
    let data = v
        .data()
        .iter()
        .map(|&x| (f64::from(x) * scale) as f32)
        .collect();
    let scaled: AnyVolume = crate::volume::Volume::with_affine(v.dims(), v.affine(), data)?.into();
    Ok(scaled.convert_to(kind))
}

fn check_scale(scale: f64) -> Result<()> {
    if scale.is_finite() && scale > 0.0 {
        Ok(())
    } else {
        Err(Error::invalid(
            "--scale",
            format!("{scale}: the scale must be finite and positive"),
        ))
    }
}

/// The voxel type named `t` (u8, u16, i16, f32 and their long names).
///
/// # Errors
/// Another name.
pub fn voxel_kind(t: &str) -> Result<VoxelKind> {
    Ok(match t.to_ascii_lowercase().as_str() {
        "u8" | "uint8" => VoxelKind::U8,
        "u16" | "uint16" => VoxelKind::U16,
        "i16" | "int16" => VoxelKind::I16,
        "f32" | "float32" | "float" => VoxelKind::F32,
        other => {
            return Err(Error::invalid(
                "--type",
                format!("'{other}' is not u8, u16, i16 or f32"),
            ))
        }
    })
}

/// Reads, crops, resamples and converts; returns the volume to write.
///
/// # Errors
/// Bad options; the input's errors.
pub fn run(c: &ConvertRequest, progress: &dyn Progress) -> Result<AnyVolume> {
    if c.resize.is_some() && c.spacing.is_some() {
        return Err(Error::invalid(
            "--resize",
            "give new dimensions or a new spacing, not both",
        ));
    }
    let kind = c.voxel_type.as_deref().map(voxel_kind).transpose()?;
    if let Some(scale) = c.scale {
        check_scale(scale)?;
    }
    let mut vol = if c.input.load.non_finite == super::input::NonFinite::Error {
        c.input.load(progress)?
    } else {
        c.input.read()?
    };
    let count = vol.non_finite();
    if count.total() > 0 {
        let needs_finite =
            kind.is_some_and(|k| k != VoxelKind::F32) || c.resize.is_some() || c.spacing.is_some();
        if c.replace_non_finite {
            vol.replace_non_finite();
            progress.warn(&format!(
                "{}: {} NaN, {} +inf and {} -inf voxel(s) replaced (NaN and -inf by the \
                 smallest finite value, +inf by the largest)",
                c.input.source, count.nan, count.pos_inf, count.neg_inf
            ));
        } else if needs_finite {
            return Err(Error::invalid(
                if kind.is_some_and(|k| k != VoxelKind::F32) {
                    "--type"
                } else {
                    "--resize/--spacing"
                },
                format!(
                    "{} holds {} NaN, {} +inf and {} -inf voxel(s) (first at index {}), which \
                     {} cannot keep; --replace-non-finite replaces them as rendering does",
                    c.input.source,
                    count.nan,
                    count.pos_inf,
                    count.neg_inf,
                    count.first.unwrap_or(0),
                    if kind.is_some_and(|k| k != VoxelKind::F32) {
                        "an integer type"
                    } else {
                        "resampling"
                    }
                ),
            ));
        }
    }
    if let Some(b) = &c.crop {
        vol = vol.crop([b[0], b[1], b[2]], [b[3], b[4], b[5]])?;
    }
    let resample_dims = match (&c.resize, &c.spacing) {
        (Some(d), _) => Some(*d),
        (None, Some(sp)) => {
            let sp: Vec<f64> = if sp.len() == 1 {
                vec![sp[0]; 3]
            } else {
                sp.clone()
            };
            if sp.len() != 3 || !sp.iter().all(|x| x.is_finite() && *x > 0.0) {
                return Err(Error::invalid(
                    "--spacing",
                    "give one or three positive numbers (mm)",
                ));
            }
            let (d, s) = (vol.dims(), vol.spacing());
            Some([0, 1, 2].map(|a| ((d[a] as f64 * s[a] / sp[a]).round() as usize).max(1)))
        }
        (None, None) => None,
    };
    if let Some(dims) = resample_dims {
        let what = format!(
            "resampling to {}×{}×{} ({:?})",
            dims[0], dims[1], dims[2], c.filter
        );
        vol = super::stage(progress, &what, "volume", 0, || {
            crate::cpu::filter::resample_volume(&vol.to_f32(), c.filter, dims)
        })?
        .into();
    }
    match (c.scale, kind) {
        (Some(scale), k) => vol = quantise(&vol, k.unwrap_or(vol.kind()), scale)?,
        (None, Some(k)) => vol = vol.convert_to(k),
        (None, None) => {}
    }
    Ok(vol)
}
