//! The Radon transform of a 2-D image as scikit-image's `radon` computes it: the image
//! (cropped to its inscribed square, or zero-padded to its circumscribed one) is
//! rotated about its centre pixel by bilinear interpolation and its columns summed.
//!
//! For angle θ (cos c, sin s) and the square's centre `m = n / 2` (integer division),
//! output pixel (row `r`, column `k`) reads the image at
//!
//! ```text
//! x = c·k + s·r − m(c + s − 1)      (column)
//! y = −s·k + c·r − m(c − s − 1)     (row)
//! ```
//!
//! with bilinear weights from `⌊x⌋, ⌈x⌉, ⌊y⌋, ⌈y⌉` and zero outside the square
//! (skimage's `warp(..., order=1, mode='constant', cval=0)`), and the sinogram's bin
//! `k` of that angle is `Σ_r` of those values, summed over `r` in order
//! (`rotated.sum(0)`). The arithmetic is skimage's, step for step, in the image's
//! precision: coordinates in `R` (the matrix rounded to `R`), each row blend
//! `(1 − dx)·a + dx·b` in `R` and the column blend in f64 (skimage's `top`/`bottom`
//! are doubles), rounded back to `R`. With the same cosines and sines the result is
//! bit-identical to skimage's in f64 (the f32 path differs
//! from skimage's float32 build by rounding: measured in python/tests/test_radon.py).
//!
//! The transform is linear: a unit pixel at the centre gives 1 in bin `m` of every
//! angle, and every angle's bins sum to the image's sum when no mass leaves the square.

use crate::real::Real;
use rayon::prelude::*;

/// Where the image lies on its square: the square's side and the image's offset in
/// it (`row0`, `col0`: negative when the square crops the image).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Square {
    pub side: usize,
    pub row0: isize,
    pub col0: isize,
}

impl Square {
    /// `circle`: the centred square of side `min(rows, cols)` (scikit-image crops the
    /// longer axis, `ceil(excess / 2)` before). Otherwise the square of side
    /// `⌈√2 · max(rows, cols)⌉`, the image padded so that its centre pixel
    /// `(rows / 2, cols / 2)` lands on the square's `side / 2`.
    pub fn of(rows: usize, cols: usize, circle: bool) -> Square {
        if circle {
            let side = rows.min(cols);
            let crop = |n: usize| -> isize { -((n - side).div_ceil(2) as isize) };
            Square {
                side,
                row0: crop(rows),
                col0: crop(cols),
            }
        } else {
            let diagonal = std::f64::consts::SQRT_2 * rows.max(cols) as f64;
            let pad = |n: usize| -> (usize, isize) {
                let p = (diagonal - n as f64).ceil() as usize;
                let before = (n + p) / 2 - n / 2;
                (n + p, before as isize)
            };
            let (side, row0) = pad(rows);
            let (_, col0) = pad(cols);
            Square { side, row0, col0 }
        }
    }
}

/// True when some pixel outside the inscribed circle is non-zero: the pixel
/// `(i, j)` with `(i − rows/2)² + (j − cols/2)² > (min(rows, cols)/2)²` (integer
/// division, skimage's test before it warns).
pub fn outside_circle<R: Real>(image: &[R], rows: usize, cols: usize) -> bool {
    let radius = (rows.min(cols) / 2) as i64;
    let (ci, cj) = ((rows / 2) as i64, (cols / 2) as i64);
    image.chunks(cols.max(1)).enumerate().any(|(i, row)| {
        row.iter().enumerate().any(|(j, &v)| {
            let (di, dj) = (i as i64 - ci, j as i64 - cj);
            di * di + dj * dj > radius * radius && v != R::zero()
        })
    })
}

/// The image placed on its square (row-major, `side²`).
pub fn square<R: Real>(image: &[R], rows: usize, cols: usize, sq: Square) -> Vec<R> {
    let n = sq.side;
    let mut out = vec![R::zero(); n * n];
    for (i, row) in image.chunks(cols.max(1)).enumerate().take(rows) {
        let si = i as isize + sq.row0;
        if si < 0 || si >= n as isize {
            continue;
        }
        for (j, &v) in row.iter().enumerate() {
            let sj = j as isize + sq.col0;
            if sj >= 0 && sj < n as isize {
                out[si as usize * n + sj as usize] = v;
            }
        }
    }
    out
}

/// The square image's pixel `(r, c)`, zero outside (skimage's `get_pixel2d`, mode
/// `'C'`, cval 0).
#[inline(always)]
fn pixel<R: Real>(img: &[R], n: usize, r: i64, c: i64) -> R {
    if r < 0 || c < 0 || r >= n as i64 || c >= n as i64 {
        R::zero()
    } else {
        img[r as usize * n + c as usize]
    }
}

/// Bilinear interpolation at row `r`, column `c` (skimage's `bilinear_interpolation`:
/// the row blends in `R`, the column blend in f64, rounded to `R`).
#[inline(always)]
fn bilinear<R: Real>(img: &[R], n: usize, r: R, c: R) -> R {
    let (minr, minc) = (r.floor(), c.floor());
    let (maxr, maxc) = (r.ceil(), c.ceil());
    let (dr, dc) = (r - minr, c - minc);
    let (r0, r1) = (minr.f64() as i64, maxr.f64() as i64);
    let (c0, c1) = (minc.f64() as i64, maxc.f64() as i64);
    let one = R::one();
    let top = ((one - dc) * pixel(img, n, r0, c0) + dc * pixel(img, n, r0, c1)).f64();
    let bottom = ((one - dc) * pixel(img, n, r1, c0) + dc * pixel(img, n, r1, c1)).f64();
    let dr = dr.f64();
    R::of((1.0 - dr) * top + dr * bottom)
}

/// The rotation of angle θ about pixel `(m, m)`, `m = n / 2`, as the inverse map
/// from output (column `k`, row `r`) to input: `[c, s, −m(c + s − 1), −s, c,
/// −m(c − s − 1)]` (`x = h₀k + h₁r + h₂`, `y = h₃k + h₄r + h₅`), computed in f64.
/// (scikit-image builds the same matrix in the angles' own precision; its Python
/// shell passes that matrix to [`radon_square`] as it is.)
pub fn rotation(n: usize, cos: f64, sin: f64) -> [f64; 6] {
    let m = (n / 2) as f64;
    [
        cos,
        sin,
        -m * (cos + sin - 1.0),
        -sin,
        cos,
        -m * (cos - sin - 1.0),
    ]
}

/// One sinogram column: the square image warped by the inverse map `h` (see
/// [`rotation`]; rounded to `R`, as skimage's `matrix.astype(image.dtype)`), summed
/// over rows.
pub fn radon_column<R: Real>(img: &[R], n: usize, h: &[f64; 6]) -> Vec<R> {
    let h: [R; 6] = h.map(R::of);
    let mut acc = vec![R::zero(); n];
    for r in 0..n {
        let y = R::of(r as f64);
        for (k, a) in acc.iter_mut().enumerate() {
            let x = R::of(k as f64);
            let col = h[0] * x + h[1] * y + h[2];
            let row = h[3] * x + h[4] * y + h[5];
            *a = *a + bilinear(img, n, row, col);
        }
    }
    acc
}

/// The sinogram `(side, angles)` (row-major: bin, then angle) of a square image
/// (`side²`, row-major), one inverse map per angle ([`rotation`]). Columns are
/// independent and run in parallel; the result does not depend on the thread count.
pub fn radon_square<R: Real>(img: &[R], n: usize, maps: &[[f64; 6]]) -> Vec<R> {
    let cols: Vec<Vec<R>> = maps.par_iter().map(|h| radon_column(img, n, h)).collect();
    let a = maps.len();
    let mut out = vec![R::zero(); n * a];
    for (j, col) in cols.iter().enumerate() {
        for (i, &v) in col.iter().enumerate() {
            out[i * a + j] = v;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_centre_pixel_projects_to_the_centre_bin_at_every_angle() {
        for n in [7usize, 8] {
            let mut img = vec![0.0f64; n * n];
            img[(n / 2) * n + n / 2] = 1.0;
            let angles: Vec<(f64, f64)> = [0.0f64, 90.0, 180.0, 270.0]
                .iter()
                .map(|d| (d.to_radians().cos(), d.to_radians().sin()))
                .collect();
            let maps: Vec<[f64; 6]> = angles.iter().map(|&(c, s)| rotation(n, c, s)).collect();
            let s = radon_square(&img, n, &maps);
            for (j, &(c, si)) in angles.iter().enumerate() {
                let col: Vec<f64> = (0..n).map(|i| s[i * angles.len() + j]).collect();
                // Quarter turns land within rounding of the grid: all mass in bin n/2.
                let total: f64 = col.iter().sum();
                assert!((total - 1.0).abs() < 1e-12, "{n} {c} {si}: {col:?}");
                assert!((col[n / 2] - 1.0).abs() < 1e-12, "{col:?}");
            }
        }
    }

    #[test]
    fn angle_zero_sums_the_columns() {
        let (rows, cols) = (5usize, 5usize);
        let img: Vec<f64> = (0..rows * cols).map(|i| (i * 7 % 11) as f64).collect();
        let s = radon_square(&img, 5, &[rotation(5, 1.0, 0.0)]);
        for k in 0..cols {
            let want: f64 = (0..rows).map(|r| img[r * cols + k]).sum();
            assert_eq!(s[k], want);
        }
    }

    #[test]
    fn squares_are_skimages() {
        assert_eq!(
            Square::of(6, 9, true),
            Square {
                side: 6,
                row0: 0,
                col0: -2
            }
        );
        // ⌈√2·9⌉ = 13: rows 6 → pad 7, before (13/2 − 6/2) = 3; cols 9 → pad 4, before 2.
        assert_eq!(
            Square::of(6, 9, false),
            Square {
                side: 13,
                row0: 3,
                col0: 2
            }
        );
        let mut img = vec![0.0f32; 9];
        assert!(!outside_circle(&img, 3, 3));
        img[0] = 1.0; // corner: (1² + 1²) > 1²
        assert!(outside_circle(&img, 3, 3));
    }
}
