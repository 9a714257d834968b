//! What a job reads: a volume file, a DICOM directory, raw samples or an analytic
//! phantom, named by one string, and the rule for NaN and infinite voxels.
//!
//! `phantom:NAME[:N | :NX,NY,NZ]` samples a phantom ([`crate::phantom::parse_spec`]);
//! `embedded:microct-bone` and `embedded:mr-brain` are the two scans built into the
//! binary (the demo's and the lab's defaults, [`super::demo`]); anything else is a path, told apart by its magic number or extension
//! ([`crate::io::read_volume`]), or raw samples when [`LoadOptions::raw`] describes
//! them. A volume already in memory (a NumPy array, the lab's current volume) is given
//! with [`VolumeInput::memory`].

use super::Progress;
use crate::error::{Error, Result};
use crate::transfer::TransferFunction;
use crate::volume::AnyVolume;
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::sync::Arc;

crate::choice_enum! {
    /// What to do with NaN and infinite voxels.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum NonFinite: "non-finite rule", default Replace {
        /// Replace NaN and −∞ by the smallest finite value and +∞ by the largest, with a
        /// warning (see docs/io.md).
        Replace = "replace",
        /// Refuse the volume.
        Error = "error",
    }
}

crate::choice_enum! {
    /// Byte order of raw multi-byte samples.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Endian: "byte order", default Little {
        /// Least significant byte first.
        Little = "little",
        /// Most significant byte first.
        Big = "big",
    }
}

/// How headerless samples are laid out ([`crate::io::raw`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RawInput {
    /// Samples along x, y and z (x fastest).
    pub dims: [usize; 3],
    /// Sample type: u8, i8, u16, i16, u32, i32, u64, i64, f32, f64.
    pub sample: String,
    pub endian: Endian,
    /// Voxel spacing in mm.
    pub spacing: [f64; 3],
    /// Bytes to skip before the first sample.
    pub offset: u64,
}

impl Default for RawInput {
    fn default() -> Self {
        RawInput {
            dims: [1; 3],
            sample: "u8".into(),
            endian: Endian::Little,
            spacing: [1.0; 3],
            offset: 0,
        }
    }
}

/// How a volume is read.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LoadOptions {
    /// Grid size of `phantom:NAME` given without one.
    pub phantom_size: usize,
    /// Read the file as headerless samples laid out like this.
    pub raw: Option<RawInput>,
    /// NaN or infinite voxels: replaced (with a warning) or refused.
    pub non_finite: NonFinite,
    /// Refuse data files that a header names outside its own folder
    /// ([`crate::io::ReadOptions::confine_data_files`]).
    pub confine_data_files: bool,
    /// Which 3-D volume of a file that holds several (a time series, a vector image) to
    /// read ([`crate::io::ReadOptions::frame`]).
    pub frame: Option<usize>,
}

impl Default for LoadOptions {
    fn default() -> Self {
        LoadOptions {
            phantom_size: 128,
            raw: None,
            non_finite: NonFinite::Replace,
            confine_data_files: false,
            frame: None,
        }
    }
}

/// One input volume.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VolumeInput {
    /// A file, a DICOM directory or `phantom:NAME[:SIZE]`; for a volume in memory, the
    /// name messages use.
    pub source: String,
    #[serde(default)]
    pub load: LoadOptions,
    /// A volume already in memory, used instead of reading `source`.
    #[serde(skip)]
    pub memory: Option<Arc<AnyVolume>>,
}

impl Default for VolumeInput {
    /// The modified Shepp–Logan phantom at the default size.
    fn default() -> Self {
        VolumeInput::new("phantom:shepp-logan-modified")
    }
}

impl VolumeInput {
    /// `source` read with the default options.
    pub fn new(source: impl Into<String>) -> Self {
        VolumeInput {
            source: source.into(),
            load: LoadOptions::default(),
            memory: None,
        }
    }

    /// A volume in memory, called `name` in messages.
    pub fn memory(name: impl Into<String>, volume: AnyVolume) -> Self {
        VolumeInput {
            source: name.into(),
            load: LoadOptions::default(),
            memory: Some(Arc::new(volume)),
        }
    }

    /// The same input read with `load`.
    pub fn with_load(mut self, load: LoadOptions) -> Self {
        self.load = load;
        self
    }

    /// Whether the input is an analytic phantom.
    pub fn is_phantom(&self) -> bool {
        self.memory.is_none() && self.source.starts_with("phantom:")
    }

    /// Where the volume comes from, for `info`: `analytic phantom`, `raw`, or the
    /// detected file format's name.
    ///
    /// # Errors
    /// The file's detection errors.
    pub fn format_name(&self) -> Result<&'static str> {
        if self.memory.is_some() {
            Ok("array in memory")
        } else if self.is_phantom() {
            Ok("analytic phantom")
        } else if self.source.starts_with("embedded:") {
            Ok("embedded scan")
        } else if self.load.raw.is_some() {
            Ok(crate::io::Format::Raw.name())
        } else {
            Ok(crate::io::detect_format(Path::new(&self.source))?.name())
        }
    }

    /// How many 3-D volumes the input holds (see [`crate::io::frame_count`]); 1 for
    /// phantoms, embedded scans, raw samples and volumes in memory.
    ///
    /// # Errors
    /// The file's header errors.
    pub fn frame_count(&self) -> Result<usize> {
        if self.memory.is_some()
            || self.is_phantom()
            || self.source.starts_with("embedded:")
            || self.load.raw.is_some()
        {
            return Ok(1);
        }
        crate::io::frame_count(Path::new(&self.source))
    }

    /// The volume as stored, NaN and infinite voxels included (`info` reports them).
    ///
    /// # Errors
    /// Whatever the reader refuses: the file and the field it names.
    pub fn read(&self) -> Result<AnyVolume> {
        if let Some(v) = &self.memory {
            return Ok(v.as_ref().clone());
        }
        if let Some(name) = self.source.strip_prefix("embedded:") {
            return match name {
                "microct-bone" => super::embedded::microct_bone(),
                "mr-brain" => super::embedded::mr_brain(),
                _ => Err(Error::invalid(
                    "input",
                    format!("'{name}' is not an embedded scan (microct-bone, mr-brain)"),
                )),
            };
        }
        if let Some(spec) = self.source.strip_prefix("phantom:") {
            let (phantom, dims) = crate::phantom::parse_spec(spec, self.load.phantom_size)?;
            return Ok(phantom.sample(dims)?.into());
        }
        let path = Path::new(&self.source);
        match &self.load.raw {
            Some(r) => {
                let spec = crate::io::raw::RawSpec {
                    dims: r.dims,
                    sample: crate::io::raw::RawType::parse(&r.sample)?,
                    big_endian: r.endian == Endian::Big,
                    spacing: r.spacing,
                    offset: r.offset,
                };
                crate::io::raw::read_raw(path, &spec)
            }
            None => crate::io::read_volume_with(
                path,
                &crate::io::ReadOptions {
                    confine_data_files: self.load.confine_data_files,
                    frame: self.load.frame,
                },
            ),
        }
    }

    /// The volume with the non-finite rule applied: NaN/±∞ voxels are reported
    /// through `progress` and replaced, or refused ([`LoadOptions::non_finite`]).
    ///
    /// # Errors
    /// [`Error::NonFinite`] under [`NonFinite::Error`]; the reader's errors.
    pub fn load(&self, progress: &dyn Progress) -> Result<AnyVolume> {
        let mut volume = self.read()?;
        let count = volume.non_finite();
        if count.total() > 0 {
            match self.load.non_finite {
                NonFinite::Error => {
                    return Err(Error::NonFinite {
                        what: self.source.clone(),
                        count: count.total(),
                        first: count.first.unwrap_or(0),
                    })
                }
                NonFinite::Replace => {
                    volume.replace_non_finite();
                    progress.warn(&format!(
                        "{}: {} NaN, {} +inf and {} -inf voxel(s) (first at index {}); NaN and \
                         -inf replaced by the smallest finite value, +inf by the largest \
                         (--non-finite error refuses instead)",
                        self.source,
                        count.nan,
                        count.pos_inf,
                        count.neg_inf,
                        count.first.unwrap_or(0)
                    ));
                }
            }
        }
        Ok(volume)
    }
}

/// The centre of a volume's box in world coordinates (mm).
pub fn volume_center(v: &AnyVolume) -> glam::DVec3 {
    grid_center(v.dims(), v.affine())
}

/// A volume's extent along its index axes in mm: dims × spacing.
pub fn volume_extent(v: &AnyVolume) -> [f64; 3] {
    grid_extent(v.dims(), v.affine())
}

/// [`volume_center`] from a grid's dimensions and affine alone.
pub fn grid_center(dims: [usize; 3], affine: glam::DMat4) -> glam::DVec3 {
    let d = dims.map(|n| (n as f64 - 1.0) * 0.5);
    affine.transform_point3(glam::DVec3::from_array(d))
}

/// [`volume_extent`] from a grid's dimensions and affine alone.
pub fn grid_extent(dims: [usize; 3], affine: glam::DMat4) -> [f64; 3] {
    let m = glam::DMat3::from_mat4(affine);
    let s = [m.x_axis.length(), m.y_axis.length(), m.z_axis.length()];
    [
        dims[0] as f64 * s[0],
        dims[1] as f64 * s[1],
        dims[2] as f64 * s[2],
    ]
}

/// The transfer function `--tf auto` gives `volume` read from `input`: the `phantom`
/// preset for phantoms, `microct-bone` for the embedded micro-CT; for other volumes, a
/// soft grayscale ramp over the value range.
///
/// # Errors
/// None in practice (the preset is built in).
pub fn auto_transfer(input: &VolumeInput, volume: &AnyVolume) -> Result<TransferFunction> {
    auto_transfer_for(input, || {
        let r = volume.value_range();
        (r.min, r.max)
    })
}

/// [`auto_transfer`] given the volume's value range (asked for only when needed), for
/// a volume no process holds whole.
///
/// # Errors
/// None in practice (the preset is built in).
pub fn auto_transfer_for(
    input: &VolumeInput,
    range: impl FnOnce() -> (f64, f64),
) -> Result<TransferFunction> {
    if input.is_phantom() {
        TransferFunction::preset("phantom")
    } else if input.memory.is_none() && input.source == "embedded:microct-bone" {
        TransferFunction::preset("microct-bone")
    } else {
        let (lo, hi) = range();
        Ok(TransferFunction::auto_for_range(lo, hi))
    }
}
