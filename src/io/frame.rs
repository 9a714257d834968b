//! Images out: a [`Frame`] as PNG (8- or 16-bit; gray for scalar frames, RGBA for
//! RGBA frames) or `.npy` (float32), written atomically.

use crate::error::{Error, Result};
use crate::frame::Frame;
use std::path::Path;

/// How to turn a frame into PNG pixels.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PngOptions {
    /// Write 16 bits per channel instead of 8.
    pub sixteen_bit: bool,
    /// For scalar frames: the values mapped to black and white. `None` uses the
    /// frame's finite minimum and maximum.
    pub range: Option<(f64, f64)>,
}

/// Pixel values quantised for PNG: RGBA frames clamp [0, 1]; scalar frames map the
/// range to [0, 1] first. NaN becomes 0.
fn quantised(frame: &Frame, opts: PngOptions) -> Vec<u16> {
    let max = if opts.sixteen_bit { 65535.0 } else { 255.0 };
    let (lo, hi) = if frame.channels == 1 {
        opts.range
            .or_else(|| frame.finite_range())
            .unwrap_or((0.0, 1.0))
    } else {
        (0.0, 1.0)
    };
    let scale = if hi > lo { 1.0 / (hi - lo) } else { 0.0 };
    frame
        .data
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

/// The frame as 8-bit RGBA, quantised as an 8-bit PNG of it is (a scalar frame's grey
/// repeated in red, green and blue, opaque): what a window shows.
pub fn rgba8(frame: &Frame, range: Option<(f64, f64)>) -> Vec<u8> {
    let q = quantised(
        frame,
        PngOptions {
            sixteen_bit: false,
            range,
        },
    );
    match frame.channels {
        1 => q
            .iter()
            .flat_map(|&v| [v as u8, v as u8, v as u8, 255])
            .collect(),
        _ => q.iter().map(|&v| v as u8).collect(),
    }
}

/// Encodes as PNG bytes: gray for scalar frames, RGBA for RGBA frames.
pub fn png_bytes(frame: &Frame, opts: PngOptions) -> Result<Vec<u8>> {
    use image::{ImageBuffer, ImageFormat, Luma, Rgba};
    let (w, h) = (frame.width as u32, frame.height as u32);
    let q = quantised(frame, opts);
    let mut bytes = std::io::Cursor::new(Vec::new());
    let err = |e: image::ImageError| Error::invalid("PNG encoding", e.to_string());
    match (frame.channels, opts.sixteen_bit) {
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

/// Writes `frame` as `.png` or `.npy` (float32; shape `(h, w)` or `(h, w, 4)`) by
/// the extension of `path`, atomically.
///
/// # Errors
/// [`Error::Invalid`] for another extension; the writer's I/O errors.
pub fn write_frame(path: &Path, frame: &Frame, opts: PngOptions) -> Result<()> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase());
    match ext.as_deref() {
        Some("png") => {
            let bytes = png_bytes(frame, opts)?;
            super::write_atomic(path, |w| {
                w.write_all(&bytes).map_err(|e| Error::io(path, e))
            })
        }
        Some("npy") => {
            let data: Vec<f32> = frame.data.iter().map(|&v| v as f32).collect();
            let shape: Vec<usize> = if frame.channels == 1 {
                vec![frame.height, frame.width]
            } else {
                vec![frame.height, frame.width, frame.channels]
            };
            super::npy::write_npy_f32(path, &shape, &data)
        }
        _ => Err(Error::invalid(
            "output file",
            format!("{}: the extension must be .png or .npy", path.display()),
        )),
    }
}
