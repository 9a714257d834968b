//! The memory planner: the limits a GPU job plans against, and the one way a job cuts
//! an axis into pieces that each fit them.
//!
//! # Limits
//! The planner's limits are the adapter's own (`adapter.limits()`), lowered by two
//! environment variables so that a small machine (lavapipe, 128 MiB per binding)
//! exercises every split a large volume would need on a real GPU:
//!
//! | variable | lowers | value |
//! |---|---|---|
//! | `VOXLAB_GPU_MAX_BINDING` | `max_storage_buffer_binding_size` | bytes, or with a `KiB`/`MiB`/`GiB` suffix |
//! | `VOXLAB_GPU_MAX_TEXTURE_3D` | `max_texture_dimension_3d` | texels per axis |
//!
//! A third, `VOXLAB_GPU_MEMORY`, sets the device memory a job may fill, which wgpu does
//! not report ([`DeviceMemory`]).
//!
//! They only ever lower a limit (a value above the adapter's is the adapter's), and they
//! are read once, when the process opens its device ([`GpuContext::new`]); the device
//! itself is opened with the adapter's full limits. A value that is not a positive
//! number is refused with an error that names the variable.
//!
//! # Pieces
//! [`Pieces::plan`] cuts `total` units (slices of a slab, views of a batch) into
//! consecutive runs of at most `per_piece` units, where `per_piece` is the most whose
//! bytes fit the limit, rounded down to a multiple of `align` where at least `align`
//! fit (so that a split keeps the unsplit path's dispatch boundaries, and with them its
//! rounding). Every piece but the last has `per_piece` units.
//!
//! [`GpuContext::new`]: super::GpuContext::new

use crate::error::{Error, Result};
use std::ops::Range;

/// The environment variable that lowers the planner's storage-binding limit (bytes).
pub const MAX_BINDING_ENV: &str = "VOXLAB_GPU_MAX_BINDING";
/// The environment variable that lowers the planner's 3-D texture limit (texels/axis).
pub const MAX_TEXTURE_3D_ENV: &str = "VOXLAB_GPU_MAX_TEXTURE_3D";

/// The environment variable that sets the device memory the planner lets a job fill
/// ([`DeviceMemory`]; bytes, or with a `KiB`/`MiB`/`GiB` suffix).
pub const MEMORY_ENV: &str = "VOXLAB_GPU_MEMORY";

/// The share of a known part's data-sheet memory the planner fills; the rest is left to
/// the driver, the display and other processes.
pub const DATA_SHEET_SHARE: f64 = 0.9;

/// The device memory the planner lets one job hold at once. wgpu does not report a
/// device's memory, so it comes from the data sheet of a part the roofline's table
/// knows ([`super::peak`]; [`DATA_SHEET_SHARE`] of it), or from [`MEMORY_ENV`], which
/// sets it for an adapter the table does not know and lowers it for one it does.
/// Unknown otherwise: then only the bindings and the 3-D texture limit cut a job, and
/// an allocation past the memory fails when it is made.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct DeviceMemory {
    /// Bytes a job may hold on the device at once.
    pub bytes: u64,
    /// Where the figure comes from ("90 % of the NVIDIA H200 (SXM, HBM3e)'s 141 GB").
    pub source: String,
}

/// The planner's [`DeviceMemory`] for an adapter whose data sheet (`gpu::peak`) gives
/// `sheet` (the part and its memory in GB), with [`MEMORY_ENV`] as `var` returns it,
/// and a line when the variable set or lowered it.
///
/// # Errors
/// [`Error::Invalid`] naming the variable when its value is not a positive byte count.
pub fn device_memory(
    sheet: Option<(&str, f64)>,
    var: impl Fn(&str) -> Option<String>,
) -> Result<(Option<DeviceMemory>, Option<String>)> {
    let sheet = sheet.map(|(part, gb)| DeviceMemory {
        bytes: (gb * 1e9 * DATA_SHEET_SHARE) as u64,
        source: format!("{:.0} % of the {part}'s {gb} GB", 100.0 * DATA_SHEET_SHARE),
    });
    let Some(text) = var(MEMORY_ENV).filter(|s| !s.trim().is_empty()) else {
        return Ok((sheet, None));
    };
    let bytes = parse_bytes(&text).ok_or_else(|| {
        Error::invalid(
            MEMORY_ENV,
            format!("'{text}' is not a positive byte count (for example 8GiB or 8589934592)"),
        )
    })?;
    Ok(match sheet {
        Some(m) if m.bytes <= bytes => (Some(m), None),
        Some(m) => (
            Some(DeviceMemory {
                bytes,
                source: MEMORY_ENV.to_string(),
            }),
            Some(format!(
                "device memory lowered to {bytes} bytes by {MEMORY_ENV} (the data sheet's: \
                 {}, {})",
                m.bytes, m.source
            )),
        ),
        None => (
            Some(DeviceMemory {
                bytes,
                source: MEMORY_ENV.to_string(),
            }),
            Some(format!(
                "device memory set to {bytes} bytes by {MEMORY_ENV} (wgpu does not report \
                 this adapter's)"
            )),
        ),
    })
}

/// The most storage bindings of the planner's size a job holds at once (D²VR's
/// projections and the FVR spectrum: 8): where the device memory is known, the
/// planner's binding is at most this fraction of it, so that every job's pieces fit.
pub const BINDINGS_AT_ONCE: u64 = 8;

/// `limits` with the storage binding capped at a [`BINDINGS_AT_ONCE`]th of `memory`,
/// and a line when that lowers it.
pub fn binding_within_memory(
    mut limits: wgpu::Limits,
    memory: Option<&DeviceMemory>,
) -> (wgpu::Limits, Option<String>) {
    let Some(m) = memory else {
        return (limits, None);
    };
    let cap = (m.bytes / BINDINGS_AT_ONCE) & !3;
    if cap.max(4) >= limits.max_storage_buffer_binding_size {
        return (limits, None);
    }
    let was = limits.max_storage_buffer_binding_size;
    limits.max_storage_buffer_binding_size = cap.max(4);
    let note = format!(
        "storage binding lowered to {} bytes, an {BINDINGS_AT_ONCE}th of the device memory \
         (a job holds up to {BINDINGS_AT_ONCE} bindings at once; it was {was})",
        cap.max(4)
    );
    (limits, Some(note))
}

/// Parses a byte count: digits, optionally followed by `K`/`KiB`, `M`/`MiB`, `G`/`GiB`
/// (powers of 1024), case-insensitive. `None` for anything else or for zero.
pub fn parse_bytes(text: &str) -> Option<u64> {
    let t = text.trim();
    let split = t.find(|c: char| !c.is_ascii_digit()).unwrap_or(t.len());
    let (digits, suffix) = t.split_at(split);
    let n: u64 = digits.parse().ok()?;
    let shift = match suffix.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 0,
        "k" | "kib" => 10,
        "m" | "mib" => 20,
        "g" | "gib" => 30,
        _ => return None,
    };
    n.checked_mul(1u64 << shift).filter(|&v| v > 0)
}

/// The adapter's limits lowered by [`MAX_BINDING_ENV`] and [`MAX_TEXTURE_3D_ENV`] as
/// `var` returns them (`std::env::var(..).ok()` in a process), and a line for each
/// limit it lowered (for `voxlab devices` and the jobs' plans).
///
/// # Errors
/// [`Error::Invalid`] naming the variable when its value is not a positive number.
pub fn lowered_limits(
    adapter: &wgpu::Limits,
    var: impl Fn(&str) -> Option<String>,
) -> Result<(wgpu::Limits, Vec<String>)> {
    let mut limits = adapter.clone();
    let mut lowered = Vec::new();
    if let Some(text) = var(MAX_BINDING_ENV).filter(|s| !s.trim().is_empty()) {
        let bytes = parse_bytes(&text).ok_or_else(|| {
            Error::invalid(
                MAX_BINDING_ENV,
                format!("'{text}' is not a positive byte count (for example 8MiB or 8388608)"),
            )
        })?;
        // Bindings are sized in whole f32/u32 words.
        let bytes = (bytes & !3).max(4);
        if bytes < limits.max_storage_buffer_binding_size {
            limits.max_storage_buffer_binding_size = bytes;
            lowered.push(format!(
                "storage binding lowered to {bytes} bytes by {MAX_BINDING_ENV} \
                 (the adapter's: {})",
                adapter.max_storage_buffer_binding_size
            ));
        }
    }
    if let Some(text) = var(MAX_TEXTURE_3D_ENV).filter(|s| !s.trim().is_empty()) {
        let texels = text
            .trim()
            .parse::<u32>()
            .ok()
            .filter(|&n| n > 0)
            .ok_or_else(|| {
                Error::invalid(
                    MAX_TEXTURE_3D_ENV,
                    format!("'{text}' is not a positive number of texels per axis"),
                )
            })?;
        if texels < limits.max_texture_dimension_3d {
            limits.max_texture_dimension_3d = texels;
            lowered.push(format!(
                "3-D texture lowered to {texels} texels per axis by {MAX_TEXTURE_3D_ENV} \
                 (the adapter's: {})",
                adapter.max_texture_dimension_3d
            ));
        }
    }
    Ok((limits, lowered))
}

/// The planner's per-buffer limit: one storage binding, and one buffer.
pub fn binding_limit(limits: &wgpu::Limits) -> u64 {
    limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size)
}

/// How a GPU job reads the data it interpolates: the filtered projections of the
/// FBP/FDK backprojection (`gpu::fbp`) and of D²VR (`gpu::d2vr`), the grid of Joseph's
/// projection (`gpu::project`). The plan carries it, because the two ways hold the data in
/// different device objects (a storage buffer, a texture with a zero border).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Sampling {
    /// An f32 storage buffer and the CPU's interpolation written out in the shader:
    /// the twin held to the f64 oracle within f32 rounding.
    #[default]
    Exact,
    /// An `R32Float` texture with a border of one zero texel all round, read by the
    /// texture unit (`textureSampleLevel`, linear, clamp to edge): the border gives the
    /// exact path's zeros outside the data. Real GPUs round each interpolation weight
    /// to about 8 fractional bits (lavapipe filters in full f32), so each family states
    /// a bound for it (docs/parity.md). Needs `FLOAT32_FILTERABLE`.
    Hardware,
}

/// Data a job interpolates, on the device as its [`Sampling`] reads it: a storage
/// buffer (exact) or a view of a texture with its zero border (hardware).
pub enum Held {
    Buffer(wgpu::Buffer),
    Texture(wgpu::TextureView),
}

impl Held {
    /// The resource a bind group binds.
    pub fn binding(&self) -> wgpu::BindingResource<'_> {
        match self {
            Held::Buffer(b) => b.as_entire_binding(),
            Held::Texture(v) => wgpu::BindingResource::TextureView(v),
        }
    }
}

/// An axis of `total` units cut into consecutive pieces of at most `per_piece` units.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Pieces {
    pub total: usize,
    pub per_piece: usize,
}

impl Pieces {
    /// The most units of `unit_bytes` bytes each that fit `limit` bytes (and at most
    /// `max_units`, for 32-bit indices), rounded down to a multiple of `align` where at
    /// least `align` fit; at most `total`.
    ///
    /// # Errors
    /// [`Error::TooLarge`] naming `what` when one unit alone exceeds the limit.
    pub fn plan(
        what: &str,
        unit: &str,
        total: usize,
        unit_bytes: u64,
        limit: u64,
        align: usize,
    ) -> Result<Pieces> {
        let fit = limit.checked_div(unit_bytes).unwrap_or(u64::MAX);
        let fit = usize::try_from(fit).unwrap_or(usize::MAX);
        if fit == 0 {
            return Err(Error::too_large(
                what,
                format!(
                    "one {unit} ({unit_bytes} bytes) exceeds the storage-binding limit of \
                     {limit} bytes, so no split can fit it"
                ),
            ));
        }
        let align = align.max(1);
        let per = if fit >= align { fit - fit % align } else { fit };
        Ok(Pieces {
            total,
            per_piece: per.min(total).max(1),
        })
    }

    /// The number of pieces (1 for an empty axis; a `per_piece` of 0 counts as 1).
    pub fn count(&self) -> usize {
        self.total.div_ceil(self.per_piece.max(1)).max(1)
    }

    /// Whether the axis is cut at all.
    pub fn is_split(&self) -> bool {
        self.count() > 1
    }

    /// The pieces, in order.
    pub fn ranges(&self) -> impl Iterator<Item = Range<usize>> + '_ {
        let per = self.per_piece.max(1);
        (0..self.total)
            .step_by(per)
            .map(move |s| s..(s + per).min(self.total))
    }
}

/// `n` with its unit, plural when `n != 1`: "1 slab", "4 slabs".
pub fn count_of(n: usize, unit: &str) -> String {
    if n == 1 {
        format!("1 {unit}")
    } else {
        format!("{n} {unit}s")
    }
}

/// Bytes for people: "512 B", "3.0 KiB", "128.0 MiB", "2.50 GiB".
pub fn human_bytes(bytes: u64) -> String {
    let b = bytes as f64;
    if bytes < 1 << 10 {
        format!("{bytes} B")
    } else if bytes < 1 << 20 {
        format!("{:.1} KiB", b / 1024.0)
    } else if bytes < 1 << 30 {
        format!("{:.1} MiB", b / (1 << 20) as f64)
    } else {
        format!("{:.2} GiB", b / (1u64 << 30) as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn byte_counts_parse_with_binary_suffixes_and_refuse_the_rest() {
        assert_eq!(parse_bytes("4096"), Some(4096));
        assert_eq!(parse_bytes("8MiB"), Some(8 << 20));
        assert_eq!(parse_bytes(" 2 k "), Some(2048));
        assert_eq!(parse_bytes("1GiB"), Some(1 << 30));
        for bad in ["", "0", "-1", "1.5M", "12 parsecs", "99999999999999999999"] {
            assert_eq!(parse_bytes(bad), None, "{bad}");
        }
    }

    #[test]
    fn device_memory_comes_from_the_data_sheet_or_the_variable() {
        let none = |_: &str| None;
        let set = |v: &'static str| move |k: &str| (k == MEMORY_ENV).then(|| v.to_string());
        // A part the table knows: 90 % of its data sheet's 141 GB.
        let h200 = Some(("NVIDIA H200 (SXM, HBM3e)", 141.0));
        let (m, note) = device_memory(h200, none).unwrap();
        let m = m.unwrap();
        assert_eq!(m.bytes, 126_900_000_000);
        assert_eq!(m.source, "90 % of the NVIDIA H200 (SXM, HBM3e)'s 141 GB");
        assert_eq!(note, None);
        // The variable lowers it, and never raises it.
        let (m, note) = device_memory(h200, set("64GiB")).unwrap();
        assert_eq!(m.unwrap().bytes, 64 << 30);
        assert!(note.unwrap().contains("lowered to 68719476736 bytes"));
        let (m, note) = device_memory(h200, set("1024GiB")).unwrap();
        assert_eq!(m.unwrap().bytes, 126_900_000_000);
        assert_eq!(note, None);
        // An adapter the table does not know: unknown, or what the variable says.
        let lavapipe = None;
        assert_eq!(device_memory(lavapipe, none).unwrap(), (None, None));
        let (m, note) = device_memory(lavapipe, set("1MiB")).unwrap();
        assert_eq!(m.unwrap().bytes, 1 << 20);
        assert!(note
            .unwrap()
            .contains("set to 1048576 bytes by VOXLAB_GPU_MEMORY"));
        let e = device_memory(lavapipe, set("lots"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("VOXLAB_GPU_MEMORY") && e.contains("'lots'"),
            "{e}"
        );
    }

    #[test]
    fn the_binding_is_at_most_an_eighth_of_a_known_memory() {
        let limits = wgpu::Limits {
            max_storage_buffer_binding_size: 1 << 27,
            ..wgpu::Limits::default()
        };
        let memory = |bytes| DeviceMemory {
            bytes,
            source: "test".into(),
        };
        // 1 MiB of memory: bindings of 128 KiB.
        let (l, note) = binding_within_memory(limits.clone(), Some(&memory(1 << 20)));
        assert_eq!(l.max_storage_buffer_binding_size, 1 << 17);
        assert!(note.unwrap().contains("lowered to 131072 bytes, an 8th"));
        // An H200's 126.9 GB: an eighth is past the binding, which stays.
        let (l, note) = binding_within_memory(limits.clone(), Some(&memory(126_900_000_000)));
        assert_eq!(l.max_storage_buffer_binding_size, 1 << 27);
        assert_eq!(note, None);
        let (l, note) = binding_within_memory(limits, None);
        assert_eq!((l.max_storage_buffer_binding_size, note), (1 << 27, None));
    }

    #[test]
    fn the_variables_only_lower_the_limits_and_name_themselves_when_wrong() {
        let adapter = wgpu::Limits {
            max_storage_buffer_binding_size: 1 << 27,
            max_texture_dimension_3d: 2048,
            ..wgpu::Limits::default()
        };
        let env = |b: &'static str, t: &'static str| {
            move |k: &str| match k {
                MAX_BINDING_ENV => Some(b.to_string()),
                MAX_TEXTURE_3D_ENV => Some(t.to_string()),
                _ => None,
            }
        };
        let (l, notes) = lowered_limits(&adapter, env("1MiB", "64")).unwrap();
        assert_eq!(l.max_storage_buffer_binding_size, 1 << 20);
        assert_eq!(l.max_texture_dimension_3d, 64);
        assert_eq!(notes.len(), 2);
        let (l, notes) = lowered_limits(&adapter, env("1GiB", "4096")).unwrap();
        assert_eq!(l.max_storage_buffer_binding_size, 1 << 27);
        assert_eq!(l.max_texture_dimension_3d, 2048);
        assert!(notes.is_empty());
        // Rounded down to whole words.
        let (l, _) = lowered_limits(&adapter, env("1023", "")).unwrap();
        assert_eq!(l.max_storage_buffer_binding_size, 1020);
        let e = lowered_limits(&adapter, env("lots", "")).unwrap_err();
        assert!(e.to_string().contains(MAX_BINDING_ENV), "{e}");
        let e = lowered_limits(&adapter, env("", "0")).unwrap_err();
        assert!(e.to_string().contains(MAX_TEXTURE_3D_ENV), "{e}");
    }

    #[test]
    fn pieces_cover_the_axis_in_order_and_keep_the_alignment() {
        let p = Pieces::plan("x", "view", 100, 10, 350, 32).unwrap();
        // 35 fit, rounded down to 32.
        assert_eq!(p.per_piece, 32);
        let r: Vec<_> = p.ranges().collect();
        assert_eq!(r, vec![0..32, 32..64, 64..96, 96..100]);
        assert_eq!(p.count(), 4);
        // Fewer than the alignment fit: as many as fit.
        let p = Pieces::plan("x", "view", 100, 10, 250, 32).unwrap();
        assert_eq!(p.per_piece, 25);
        // Everything fits: one piece.
        let p = Pieces::plan("x", "view", 7, 10, 1 << 20, 32).unwrap();
        assert_eq!((p.count(), p.is_split()), (1, false));
        let e = Pieces::plan("GPU volume", "slice", 7, 100, 99, 1).unwrap_err();
        assert!(e.to_string().contains("GPU volume"), "{e}");
    }
}
