//! Images: RGBA and scalar frames, stored in f64 so that the oracle's output is kept
//! exactly; `io::write_frame` writes them as PNG (8- or 16-bit) or `.npy` (float32).
//!
//! Layout: row 0 at the top, pixels row by row, channels interleaved
//! (`data[(row * width + col) * channels + c]`).

/// An image of 1 (scalar) or 4 (RGBA) channels.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub data: Vec<f64>,
}

/// A frame's samples, row-major, channels interleaved.
impl AsRef<[f64]> for Frame {
    fn as_ref(&self) -> &[f64] {
        &self.data
    }
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
}
