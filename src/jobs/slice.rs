//! `voxlab slice`: one axis-aligned slice of a volume, laid out like the NumPy slice of
//! the `(nz, ny, nx)` array ([`crate::volume::AnyVolume::slice`]).

use super::input::VolumeInput;
use super::Progress;
use crate::error::{Error, Result};
use crate::frame::Frame;
use serde::{Deserialize, Serialize};

/// The `voxlab slice` job.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SliceRequest {
    pub input: VolumeInput,
    /// The axis across which to cut: `z` gives `a[k, :, :]`, `y` `a[:, j, :]`, `x`
    /// `a[:, :, i]`.
    pub axis: String,
    /// Slice index along the axis (`None`: the middle slice).
    pub index: Option<usize>,
    /// Gray-scale `[width, centre]` in data units (`None`: the volume's whole value
    /// range, the same for every slice).
    pub window: Option<[f64; 2]>,
}

impl Default for SliceRequest {
    fn default() -> Self {
        SliceRequest {
            input: VolumeInput::default(),
            axis: "z".into(),
            index: None,
            window: None,
        }
    }
}

/// The slice and the values its gray scale maps to black and white.
#[derive(Clone, Debug)]
pub struct Slice {
    pub frame: Frame,
    pub axis: usize,
    pub index: usize,
    pub range: (f64, f64),
}

/// Cuts the slice.
///
/// # Errors
/// An unknown axis, an index outside the volume, a bad window; the input's errors.
pub fn run(a: &SliceRequest, progress: &dyn Progress) -> Result<Slice> {
    let vol = a.input.load(progress)?;
    let axis = match a.axis.to_ascii_lowercase().as_str() {
        "x" => 0,
        "y" => 1,
        "z" => 2,
        other => {
            return Err(Error::invalid(
                "--axis",
                format!("'{other}' is not x, y or z"),
            ))
        }
    };
    let index = a.index.unwrap_or(vol.dims()[axis] / 2);
    let frame = vol.slice(axis, index)?;
    let range = match a.window {
        Some([w, l]) if w > 0.0 && w.is_finite() && l.is_finite() => (l - 0.5 * w, l + 0.5 * w),
        Some(_) => {
            return Err(Error::invalid("--window", "must be positive and finite"));
        }
        None => {
            let r = vol.value_range();
            (r.min, r.max)
        }
    };
    Ok(Slice {
        frame,
        axis,
        index,
        range,
    })
}
