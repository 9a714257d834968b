//! Images: RGBA and scalar frames, stored in f64 so that the oracle's output is kept
//! exactly; written as PNG (8- or 16-bit) or `.npy` (float32).
//!
//! Layout: row 0 at the top, pixels row by row, channels interleaved
//! (`data[(row * width + col) * channels + c]`).

use crate::error::{Error, Result};
use std::path::Path;

/// An image of 1 (scalar) or 4 (RGBA) channels.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub data: Vec<f64>,
}

/// How to turn a frame into PNG pixels.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PngOptions {
    /// Write 16 bits per channel instead of 8.
    pub sixteen_bit: bool,
    /// For scalar frames: the values mapped to black and white. `None` uses the
    /// frame's finite minimum and maximum.
    pub range: Option<(f64, f64)>,
}

impl Frame {
    /// A frame of zeros.
    pub fn new(width: usize, height: usize, channels: usize) -> Self {
        assert!(
            channels == 1 || channels == 4,
            "frames have 1 or 4 channels"
        );
        Frame {
            width,
            height,
            channels,
            data: vec![0.0; width * height * channels],
        }
    }

    /// The channels of pixel `(col, row)`.
    pub fn pixel(&self, col: usize, row: usize) -> &[f64] {
        let i = (row * self.width + col) * self.channels;
        &self.data[i..i + self.channels]
    }

    /// Finite minimum and maximum over all channels (`None` when nothing is finite).
    pub fn finite_range(&self) -> Option<(f64, f64)> {
        let mut r: Option<(f64, f64)> = None;
        for &v in self.data.iter().filter(|v| v.is_finite()) {
            r = Some(match r {
                None => (v, v),
                Some((lo, hi)) => (lo.min(v), hi.max(v)),
            });
        }
        r
    }

    /// Pixel values quantised for PNG: RGBA frames clamp [0, 1]; scalar frames map the
    /// range to [0, 1] first. NaN becomes 0.
    fn quantised(&self, opts: PngOptions) -> Vec<u16> {
        let max = if opts.sixteen_bit { 65535.0 } else { 255.0 };
        let (lo, hi) = if self.channels == 1 {
            opts.range
                .or_else(|| self.finite_range())
                .unwrap_or((0.0, 1.0))
        } else {
            (0.0, 1.0)
        };
        let scale = if hi > lo { 1.0 / (hi - lo) } else { 0.0 };
        self.data
            .iter()
            .map(|&v| {
                let u = ((v - lo) * scale).clamp(0.0, 1.0);
                if u.is_nan() {
                    0
                } else {
                    (u * max).round() as u16
                }
            })
            .collect()
    }

    /// Encodes as PNG bytes: gray for scalar frames, RGBA for RGBA frames.
    pub fn to_png_bytes(&self, opts: PngOptions) -> Result<Vec<u8>> {
        use image::{ImageBuffer, ImageFormat, Luma, Rgba};
        let (w, h) = (self.width as u32, self.height as u32);
        let q = self.quantised(opts);
        let mut bytes = std::io::Cursor::new(Vec::new());
        let err = |e: image::ImageError| Error::invalid("PNG encoding", e.to_string());
        match (self.channels, opts.sixteen_bit) {
            (1, false) => {
                let px: Vec<u8> = q.iter().map(|&v| v as u8).collect();
                ImageBuffer::<Luma<u8>, _>::from_raw(w, h, px)
                    .expect("buffer size matches")
                    .write_to(&mut bytes, ImageFormat::Png)
                    .map_err(err)?
            }
            (1, true) => ImageBuffer::<Luma<u16>, _>::from_raw(w, h, q)
                .expect("buffer size matches")
                .write_to(&mut bytes, ImageFormat::Png)
                .map_err(err)?,
            (_, false) => {
                let px: Vec<u8> = q.iter().map(|&v| v as u8).collect();
                ImageBuffer::<Rgba<u8>, _>::from_raw(w, h, px)
                    .expect("buffer size matches")
                    .write_to(&mut bytes, ImageFormat::Png)
                    .map_err(err)?
            }
            (_, true) => ImageBuffer::<Rgba<u16>, _>::from_raw(w, h, q)
                .expect("buffer size matches")
                .write_to(&mut bytes, ImageFormat::Png)
                .map_err(err)?,
        }
        Ok(bytes.into_inner())
    }

    /// Writes `.png` or `.npy` (float32; shape `(h, w)` or `(h, w, 4)`) by extension,
    /// atomically.
    pub fn save(&self, path: &Path, opts: PngOptions) -> Result<()> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase());
        match ext.as_deref() {
            Some("png") => {
                let bytes = self.to_png_bytes(opts)?;
                crate::io::write_atomic(path, |w| {
                    w.write_all(&bytes).map_err(|e| Error::io(path, e))
                })
            }
            Some("npy") => {
                let data: Vec<f32> = self.data.iter().map(|&v| v as f32).collect();
                let shape: Vec<usize> = if self.channels == 1 {
                    vec![self.height, self.width]
                } else {
                    vec![self.height, self.width, self.channels]
                };
                crate::io::npy::write_npy_f32(path, &shape, &data)
            }
            _ => Err(Error::invalid(
                "output file",
                format!("{}: the extension must be .png or .npy", path.display()),
            )),
        }
    }
}
/// Draws a histogram as an RGBA frame of `width` × `height` pixels: one bar per bin,
/// heights on a logarithmic count axis (log(1 + count), so that the long tails of CT
/// and MR histograms stay visible beside the background's peak), light bars on a dark
/// background, with a baseline. The value axis runs from the histogram's minimum at
/// the left to its maximum at the right; `voxlab info` prints the numbers beside it.
pub fn histogram_plot(h: &crate::volume::Histogram, width: usize, height: usize) -> Result<Frame> {
    if width < 16 || height < 16 || width > 8192 || height > 8192 {
        return Err(Error::invalid(
            "histogram plot size",
            format!("{width}×{height} must be between 16 and 8192 pixels per side"),
        ));
    }
    let mut f = Frame::new(width, height, 4);
    let set = |f: &mut Frame, col: usize, row: usize, rgb: [f64; 3]| {
        let i = (row * width + col) * 4;
        f.data[i..i + 4].copy_from_slice(&[rgb[0], rgb[1], rgb[2], 1.0]);
    };
    for row in 0..height {
        for col in 0..width {
            set(&mut f, col, row, [0.08, 0.08, 0.1]);
        }
    }
    let (margin, base) = (8, height - 8);
    let plot_w = width - 2 * margin;
    let plot_h = base - margin;
    let top = h
        .counts
        .iter()
        .map(|&c| (1.0 + c as f64).ln())
        .fold(0.0, f64::max);
    let bins = h.counts.len().max(1);
    for col in 0..plot_w {
        let b = (col * bins / plot_w).min(bins - 1);
        let c = h.counts.get(b).copied().unwrap_or(0);
        let frac = if top > 0.0 {
            (1.0 + c as f64).ln() / top
        } else {
            0.0
        };
        let bar = (frac * plot_h as f64).round() as usize;
        for r in 0..bar.min(plot_h) {
            set(&mut f, margin + col, base - 1 - r, [0.55, 0.75, 0.95]);
        }
    }
    for col in margin..width - margin {
        set(&mut f, col, base, [0.9, 0.9, 0.9]);
    }
    Ok(f)
}
