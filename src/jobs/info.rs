//! `voxlab info`: what a volume is (format, dimensions, spacing, orientation, type,
//! affine, value range, NaN/∞ counts, histogram), or what the GPU is.

use super::input::VolumeInput;
use crate::error::{Error, Result};
use crate::gpu::context::AdapterSummary;
use crate::volume::{Histogram, NonFiniteCount, ValueRange, VoxelKind};
use serde::Serialize;

/// A volume described. Serialises as `voxlab info --json` prints it.
#[derive(Clone, Debug, Serialize)]
pub struct VolumeInfo {
    pub input: String,
    pub format: &'static str,
    pub dims: [usize; 3],
    pub spacing_mm: [f64; 3],
    #[serde(rename = "type")]
    pub kind: VoxelKind,
    /// The nearest world axis of each index axis ([`orientation`]).
    pub orientation: String,
    /// The voxel-to-world affine, row by row.
    pub affine_rows: Vec<[f64; 4]>,
    pub range: ValueRange,
    pub non_finite: NonFiniteCount,
    pub histogram: Histogram,
    /// The finer histogram of the plot, when asked for: 256 bins, or one per integer
    /// value for integer volumes with at most 1024 distinct values.
    #[serde(skip)]
    pub plot_histogram: Option<Histogram>,
    /// For a file of several 3-D volumes (a time series, a vector image): how many, and
    /// which one the rest describes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frames: Option<Frames>,
}

/// How many 3-D volumes a file holds and which one `info` describes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Frames {
    pub count: usize,
    pub described: usize,
}

/// Describes `input` as stored (NaN and infinite voxels are counted, not replaced),
/// its histogram with `bins` bins (clamped to 1 … 4096), and the plot's histogram when
/// `plot`.
///
/// # Errors
/// The input's errors.
pub fn run(input: &VolumeInput, bins: usize, plot: bool) -> Result<VolumeInfo> {
    let format = input.format_name()?;
    // A file of several volumes is described by the one asked for, else by its first.
    let count = input.frame_count()?;
    let described = input.load.frame.unwrap_or(0);
    let v = if count > 1 && input.load.frame.is_none() {
        let mut first = input.clone();
        first.load.frame = Some(0);
        first.read()?
    } else {
        input.read()?
    };
    let r = v.value_range();
    let plot_histogram = plot.then(|| {
        let integer = v.kind() != VoxelKind::F32;
        let span = r.max - r.min;
        let plot_bins = if integer && span.is_finite() && span < 1024.0 {
            span as usize + 1
        } else {
            256
        };
        v.histogram(plot_bins)
    });
    Ok(VolumeInfo {
        input: input.source.clone(),
        format,
        dims: v.dims(),
        spacing_mm: v.spacing(),
        kind: v.kind(),
        orientation: orientation(v.affine(), format),
        affine_rows: (0..4).map(|i| v.affine().row(i).to_array()).collect(),
        range: r,
        non_finite: v.non_finite(),
        histogram: v.histogram(bins.clamp(1, 4096)),
        plot_histogram,
        frames: (count > 1).then_some(Frames { count, described }),
    })
}

/// The nearest world axis of each index axis, as anatomical letters when the format
/// fixes the world frame (NIfTI: RAS+, DICOM: LPS+), else as ±X/±Y/±Z.
pub fn orientation(affine: glam::DMat4, format: &str) -> String {
    let letters: Option<[[&str; 2]; 3]> = match format {
        "NIfTI-1" | "NIfTI" => Some([["R", "L"], ["A", "P"], ["S", "I"]]),
        "DICOM" => Some([["L", "R"], ["P", "A"], ["S", "I"]]),
        _ => None,
    };
    let m = glam::DMat3::from_mat4(affine);
    let mut out = Vec::new();
    for c in 0..3 {
        let v = m.col(c).to_array();
        let (axis, val) = v
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .expect("three components");
        let neg = usize::from(*val < 0.0);
        out.push(match letters {
            Some(l) => l[axis][neg].to_string(),
            None => format!("{}{}", ["+", "-"][neg], ["X", "Y", "Z"][axis]),
        });
    }
    match letters {
        Some(_) => format!(
            "{} (index axes x, y, z point to {}; world frame {})",
            out.concat(),
            out.join(", "),
            if format == "DICOM" { "LPS+" } else { "RAS+" }
        ),
        None => format!(
            "x → {}, y → {}, z → {} (world frame as the file gives it)",
            out[0], out[1], out[2]
        ),
    }
}

/// The GPU described: every adapter, the one opened, and a self-test on it.
#[derive(Clone, Debug)]
pub struct GpuInfo {
    /// Best first.
    pub adapters: Vec<AdapterSummary>,
    /// The opened adapter's report: limits and features.
    pub opened: String,
    /// Values the self-test computed on the device and checked against the CPU.
    pub self_test_values: usize,
}

/// Lists the adapters, opens the best one and runs the self-test.
///
/// # Errors
/// [`Error::NoAdapter`] without one; the self-test's failures.
pub fn gpu() -> Result<GpuInfo> {
    let adapters = crate::gpu::context::list_adapters();
    if adapters.is_empty() {
        return Err(Error::NoAdapter(
            crate::gpu::context::NO_ADAPTER_HELP.into(),
        ));
    }
    let ctx = crate::gpu::GpuContext::new()?;
    let n = crate::gpu::probe::self_test(&ctx)?;
    Ok(GpuInfo {
        adapters,
        opened: ctx.describe(),
        self_test_values: n,
    })
}
