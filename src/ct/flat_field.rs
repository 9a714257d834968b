//! Detector intensities to line integrals: flat- and dark-field correction.
//!
//! A scanner records intensities `I`; reconstruction needs line integrals `p` of the
//! attenuation. Beer–Lambert with a flat field `F` (the beam with no object) and a dark
//! field `D` (no beam) gives, per detector pixel,
//!
//! ```text
//! p = −ln( (I − D) / (F − D) )
//! ```
//!
//! `F` and `D` are one image each (`rows × cols`); a stack of several frames is averaged
//! first, in f64 ([`mean_frames`]). [`line_integrals`] applies the formula to every view
//! and never produces NaN or ±∞; the rule for the pixels where the logarithm is not
//! defined follows RTK's conversion from raw counts
//! (`rtk::LUTbasedVariableI0RawToAttenuationImageFilter`, `−ln(max(I, 1) / I0)`), which
//! floors the measured signal instead of letting the logarithm diverge:
//!
//! | pixel                                  | p                              | counted as       |
//! |----------------------------------------|--------------------------------|------------------|
//! | `F − D ≤ 0` (dead: no beam measured)   | 0 in every view                | `dead_pixels`    |
//! | `I − D ≤ 0` (starved: no photons left) | `−ln ε`, ε = [`RATIO_FLOOR`]   | `starved`        |
//! | ratio below ε or past `f64::MAX`       | the ratio clamped to `[ε, MAX]`| `clamped`        |
//! | `I > F` (brighter than the flat)       | `p < 0`, kept as it is         | `above_flat`     |
//!
//! RTK floors the count at one, which presumes integer counts; voxlab's intensities may
//! be in any unit (normalised floats included), so the floor is put on the unit-free
//! ratio instead: ε = `f64::MIN_POSITIVE`, the smallest positive normal double, so that
//! `p ≤ −ln ε ≈ 708.4` is always finite. Every starved sample is also counted as
//! clamped. RTK also sets negative line integrals to 0; voxlab keeps them, because a
//! pixel brighter than the flat is noise whose mean is what FBP needs.
//!
//! ```
//! use voxlab::ct::{flat_field::line_integrals, Projections};
//! // One view of 2 pixels: flat 100, dark 10, intensities 55 and 10 (starved).
//! let i = Projections::new(1, 1, 2, vec![55.0, 10.0]).unwrap();
//! let (p, report) = line_integrals(&i, &[100.0, 100.0], Some(&[10.0, 10.0][..])).unwrap();
//! assert!((p.data[0] - 2f64.ln()).abs() < 1e-15);
//! assert!(p.data[1].is_finite());
//! assert_eq!((report.starved, report.dead_pixels), (1, 0));
//! ```

use super::{Lines, Projections};
use crate::error::{Error, Result};

/// The smallest ratio `(I − D)/(F − D)` the logarithm is taken of: the smallest
/// positive normal f64, so the largest line integral is `−ln ε ≈ 708.4`.
pub const RATIO_FLOOR: f64 = f64::MIN_POSITIVE;

/// What happened to the pixels of a flat/dark correction (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct IntensityReport {
    /// Values converted (`angles × rows × cols`).
    pub samples: usize,
    /// Detector pixels per view (`rows × cols`).
    pub pixels: usize,
    /// Detector pixels with `F − D ≤ 0`: set to 0 in every view.
    pub dead_pixels: usize,
    /// Samples with `I − D ≤ 0` on a live pixel.
    pub starved: usize,
    /// Samples whose ratio was clamped to `[ε, f64::MAX]` (the starved ones included).
    pub clamped: usize,
    /// Samples brighter than the flat (`p < 0`, kept).
    pub above_flat: usize,
}

impl IntensityReport {
    /// One line for a user: the counts and the rule.
    pub fn summary(&self) -> String {
        format!(
            "flat/dark: {} samples → line integrals; {} dead pixel(s) of {} (F − D ≤ 0, set \
             to 0), {} starved sample(s) (I − D ≤ 0), {} clamped to the ratio floor, {} \
             above the flat (p < 0, kept)",
            self.samples,
            self.dead_pixels,
            self.pixels,
            self.starved,
            self.clamped,
            self.above_flat
        )
    }
}

/// How one sample was converted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sample {
    /// A line integral computed as it is (`p ≥ 0`).
    Plain,
    /// `I > F`: `p < 0`, kept.
    AboveFlat,
    /// `I − D ≤ 0`: the ratio floored at ε.
    Starved,
    /// The ratio was positive but outside `[ε, f64::MAX]`: clamped.
    Clamped,
}

/// The line integral of one sample on a live pixel (`gain = F − D > 0`):
/// `−ln(clamp((i − dark) / gain, ε, MAX))`, and how it was obtained.
pub fn line_integral(i: f64, dark: f64, gain: f64) -> (f64, Sample) {
    // The inputs are finite, so `signal` is never NaN.
    let signal = i - dark;
    if signal <= 0.0 {
        return (-RATIO_FLOOR.ln(), Sample::Starved);
    }
    let ratio = signal / gain;
    if ratio < RATIO_FLOOR {
        (-RATIO_FLOOR.ln(), Sample::Clamped)
    } else if ratio > f64::MAX {
        (-f64::MAX.ln(), Sample::Clamped)
    } else if ratio > 1.0 {
        (-ratio.ln(), Sample::AboveFlat)
    } else {
        (-ratio.ln(), Sample::Plain)
    }
}

/// The pixel-wise mean of a stack of frames of `pixels` values each, accumulated in f64
/// in frame order. `what` names the input in errors (`"flat field a.mha"`).
///
/// # Errors
/// No frames, a length that is not a whole number of frames, a non-finite value.
pub fn mean_frames(what: &str, frames: &[f64], pixels: usize) -> Result<Vec<f64>> {
    if pixels == 0 || frames.is_empty() {
        return Err(Error::invalid(what, "holds no frames (an empty stack)"));
    }
    if !frames.len().is_multiple_of(pixels) {
        return Err(Error::invalid(
            what,
            format!(
                "{} values are not a whole number of frames of {pixels} pixels",
                frames.len()
            ),
        ));
    }
    check_finite(what, frames)?;
    let n = frames.len() / pixels;
    let mut sum = vec![0.0f64; pixels];
    for frame in frames.chunks_exact(pixels) {
        for (s, v) in sum.iter_mut().zip(frame) {
            *s += v;
        }
    }
    if n > 1 {
        for s in &mut sum {
            *s /= n as f64;
        }
    }
    Ok(sum)
}

/// Line integrals `−ln((I − D)/(F − D))` of every view of `intensities`, with one flat
/// image and an optional dark image (`None`: 0) of `rows × cols` pixels each (average
/// stacks with [`mean_frames`] first). Dead, starved and clamped samples follow the rule
/// of the module docs; the result is always finite.
///
/// # Errors
/// A flat or dark image of the wrong size, or a non-finite value in any input.
pub fn line_integrals(
    intensities: &Projections<f64>,
    flat: &[f64],
    dark: Option<&[f64]>,
) -> Result<(Projections<f64>, IntensityReport)> {
    let (rows, cols) = (intensities.rows, intensities.cols);
    let row_of = |m: usize| m % rows.max(1);
    let (out, report) = convert(&intensities.data, rows, cols, row_of, flat, dark)?;
    let p = Projections::new(intensities.angles, rows, cols, out)?;
    Ok((p, report))
}

/// [`line_integrals`] of some detector lines of a stack (a rank's, in a distributed
/// reconstruction): each line converted with its own row of the flat and dark images,
/// so every value is the whole stack's bit for bit. The report counts these lines'
/// samples (the dead pixels are the images', as for the whole stack).
///
/// # Errors
/// As [`line_integrals`].
pub fn line_integrals_lines(
    intensities: &Lines<f64>,
    flat: &[f64],
    dark: Option<&[f64]>,
) -> Result<(Lines<f64>, IntensityReport)> {
    let (rows, cols) = (intensities.rows, intensities.cols);
    let ids = &intensities.ids;
    let (out, report) = convert(&intensities.data, rows, cols, |m| ids[m] % rows, flat, dark)?;
    let shape = [intensities.angles, rows, cols];
    Ok((Lines::new(shape, ids.clone(), out)?, report))
}

/// The one body of [`line_integrals`] and [`line_integrals_lines`]: `data` is lines of
/// `cols` values, line `m` on detector row `row_of(m)`.
fn convert(
    data: &[f64],
    rows: usize,
    cols: usize,
    row_of: impl Fn(usize) -> usize,
    flat: &[f64],
    dark: Option<&[f64]>,
) -> Result<(Vec<f64>, IntensityReport)> {
    let pixels = rows * cols;
    let size = |what: &str, n: usize| -> Result<()> {
        if n == pixels {
            Ok(())
        } else {
            Err(Error::invalid(
                what,
                format!(
                    "{n} pixels, but the projections have rows × cols = {rows} × {cols} = {pixels}"
                ),
            ))
        }
    };
    size("flat field", flat.len())?;
    check_finite("flat field", flat)?;
    if let Some(d) = dark {
        size("dark field", d.len())?;
        check_finite("dark field", d)?;
    }
    check_finite("projections", data)?;
    let dark_at = |k: usize| dark.map_or(0.0, |d| d[k]);
    let mut report = IntensityReport {
        samples: data.len(),
        pixels,
        ..Default::default()
    };
    let live: Vec<bool> = (0..pixels).map(|k| flat[k] - dark_at(k) > 0.0).collect();
    report.dead_pixels = live.iter().filter(|l| !**l).count();
    let mut out = vec![0.0f64; data.len()];
    if cols > 0 {
        for (m, (line_in, line_out)) in data
            .chunks_exact(cols)
            .zip(out.chunks_exact_mut(cols))
            .enumerate()
        {
            let first = row_of(m) * cols;
            for (c, (&i, o)) in line_in.iter().zip(line_out.iter_mut()).enumerate() {
                let k = first + c;
                if !live[k] {
                    continue;
                }
                let d = dark_at(k);
                let (p, how) = line_integral(i, d, flat[k] - d);
                *o = p;
                match how {
                    Sample::Plain => {}
                    Sample::AboveFlat => report.above_flat += 1,
                    Sample::Starved => {
                        report.starved += 1;
                        report.clamped += 1;
                    }
                    Sample::Clamped => report.clamped += 1,
                }
            }
        }
    }
    Ok((out, report))
}

fn check_finite(what: &str, values: &[f64]) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(k) => Err(Error::invalid(
            what,
            format!("value {k} is {} (inputs must be finite)", values[k]),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rule_of_every_kind_of_pixel() {
        // Pixels: plain, above flat, starved (I = D), starved (I < D), dead (F = D).
        let flat = [100.0, 100.0, 100.0, 100.0, 5.0];
        let dark = [10.0, 10.0, 10.0, 10.0, 5.0];
        let i = Projections::new(1, 1, 5, vec![55.0, 190.0, 10.0, 3.0, 7.0]).unwrap();
        let (p, r) = line_integrals(&i, &flat, Some(&dark[..])).unwrap();
        assert!((p.data[0] - 2f64.ln()).abs() < 1e-15);
        assert!((p.data[1] + 2f64.ln()).abs() < 1e-15);
        assert_eq!(p.data[2], -RATIO_FLOOR.ln());
        assert_eq!(p.data[3], -RATIO_FLOOR.ln());
        assert_eq!(p.data[4], 0.0);
        assert!(p.data.iter().all(|v| v.is_finite()));
        assert_eq!(
            r,
            IntensityReport {
                samples: 5,
                pixels: 5,
                dead_pixels: 1,
                starved: 2,
                clamped: 2,
                above_flat: 1,
            }
        );
    }

    #[test]
    fn extreme_ratios_stay_finite() {
        let tiny = f64::MIN_POSITIVE * f64::EPSILON; // subnormal
        let i = Projections::new(1, 1, 2, vec![tiny, f64::MAX]).unwrap();
        let (p, r) = line_integrals(&i, &[1.0, tiny], None).unwrap();
        assert!(p.data.iter().all(|v| v.is_finite()), "{:?}", p.data);
        assert_eq!(r.clamped, 2);
        assert_eq!(r.starved, 0);
    }

    #[test]
    fn frames_average_and_bad_inputs_are_named() {
        let m = mean_frames("flat", &[1.0, 2.0, 3.0, 6.0], 2).unwrap();
        assert_eq!(m, vec![2.0, 4.0]);
        let e = mean_frames("flat x.mha", &[], 2).unwrap_err().to_string();
        assert!(e.contains("flat x.mha") && e.contains("no frames"), "{e}");
        let e = mean_frames("dark", &[1.0, f64::NAN], 2)
            .unwrap_err()
            .to_string();
        assert!(e.contains("dark") && e.contains("NaN"), "{e}");
        let i = Projections::new(1, 1, 2, vec![1.0, 1.0]).unwrap();
        let e = line_integrals(&i, &[1.0], None).unwrap_err().to_string();
        assert!(e.contains("flat field") && e.contains("rows × cols"), "{e}");
    }

    /// Some lines converted alone are the whole stack's lines, bit for bit, and count
    /// their own samples.
    #[test]
    fn lines_convert_as_the_whole_stack_does() {
        let (angles, rows, cols) = (3, 4, 5);
        let n = angles * rows * cols;
        let i: Vec<f64> = (0..n).map(|k| ((k * 37) % 101) as f64 + 0.5).collect();
        let flat: Vec<f64> = (0..rows * cols).map(|k| 80.0 + k as f64).collect();
        let mut dark: Vec<f64> = (0..rows * cols).map(|k| (k % 7) as f64).collect();
        dark[6] = flat[6]; // one dead pixel: row 1, column 1
        let p = Projections::new(angles, rows, cols, i).unwrap();
        let (whole, all) = line_integrals(&p, &flat, Some(&dark)).unwrap();
        assert!(all.above_flat > 0 && all.starved > 0, "{all:?}");
        let ids = vec![1, 2, 5, 11];
        let some = p.lines(&ids).unwrap();
        let (got, r) = line_integrals_lines(&some, &flat, Some(&dark)).unwrap();
        let want = whole.lines(&ids).unwrap();
        assert_eq!(got.ids, ids);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&got.data), bits(&want.data));
        // Line 5 is row 1 of view 1: its column 1 is the dead pixel, 0.
        assert_eq!(got.data[2 * cols + 1], 0.0);
        assert_eq!((r.samples, r.pixels, r.dead_pixels), (4 * cols, 20, 1));
        // Every line once: the whole stack's counts.
        let every: Vec<usize> = (0..angles * rows).collect();
        let (_, counts) =
            line_integrals_lines(&p.lines(&every).unwrap(), &flat, Some(&dark)).unwrap();
        assert_eq!(counts, all);
    }
}
