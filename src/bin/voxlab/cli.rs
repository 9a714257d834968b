//! What every subcommand shares: how values are parsed, how an input volume is named
//! (`LoadArgs`), the view flags, and the terminal's progress display.

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use std::ffi::OsStr;
use std::marker::PhantomData;
use std::sync::Mutex;
use voxlab::choice::Choice;
use voxlab::jobs::input::{Endian, LoadOptions, NonFinite, RawInput, VolumeInput};
use voxlab::jobs::render::ViewRequest;
use voxlab::jobs::Progress;

/// Parses exactly `N` comma-separated values, e.g. `1,2,3` for `--light`.
pub fn list<T: std::str::FromStr, const N: usize>(s: &str) -> Result<[T; N], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != N {
        return Err(format!(
            "expected {N} comma-separated values, got {}",
            parts.len()
        ));
    }
    let values = parts
        .iter()
        .map(|p| {
            p.parse::<T>()
                .map_err(|_| format!("'{p}' is not a valid number"))
        })
        .collect::<Result<Vec<T>, String>>()?;
    values
        .try_into()
        .map_err(|_| "wrong number of values".to_string())
}

/// The value parser of a library [`Choice`] type: its names (aliases hidden) with
/// their help in `--help`, and clap's message for anything else.
#[derive(Clone)]
pub struct ChoiceParser<T>(PhantomData<T>);

/// `value_parser = choice::<Filter>()`.
pub fn choice<T>() -> ChoiceParser<T> {
    ChoiceParser(PhantomData)
}

impl<T: Choice + Clone + Send + Sync + 'static> TypedValueParser for ChoiceParser<T> {
    type Value = T;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &OsStr,
    ) -> Result<T, clap::Error> {
        let names = PossibleValuesParser::new(possible::<T>());
        let name = names.parse_ref(cmd, arg, value)?;
        Ok(T::parse_choice(&name).expect("a possible value is a name or an alias"))
    }

    fn possible_values(&self) -> Option<Box<dyn Iterator<Item = PossibleValue> + '_>> {
        Some(Box::new(possible::<T>().into_iter()))
    }
}

fn possible<T: Choice>() -> Vec<PossibleValue> {
    T::CHOICES
        .iter()
        .map(|c| {
            let help = c.help();
            let mut p = PossibleValue::new(c.name);
            if !help.is_empty() {
                p = p.help(help);
            }
            for a in c.aliases {
                p = p.alias(a);
            }
            p
        })
        .collect()
}

/// How to load INPUT: phantom size, raw layout, and what to do with NaN/Inf voxels.
#[derive(Args, Clone)]
pub struct LoadArgs {
    /// Phantom grid size when INPUT is phantom:NAME without a size.
    #[arg(long, default_value_t = 128)]
    pub phantom_size: usize,
    /// Raw input: dimensions NX,NY,NZ (x fastest). Reads INPUT as headerless samples.
    #[arg(long, value_parser = list::<usize, 3>)]
    pub raw_dims: Option<[usize; 3]>,
    /// Raw input: sample type (u8, i8, u16, i16, u32, i32, u64, i64, f32, f64).
    #[arg(long, default_value = "u8")]
    pub raw_type: String,
    /// Raw input: byte order of multi-byte samples.
    #[arg(long, value_parser = choice::<Endian>(), default_value = "little")]
    pub raw_endian: Endian,
    /// Raw input: voxel spacing SX,SY,SZ in mm.
    #[arg(long, value_parser = list::<f64, 3>, default_value = "1,1,1")]
    pub raw_spacing: [f64; 3],
    /// Raw input: bytes to skip before the first sample.
    #[arg(long, default_value_t = 0)]
    pub raw_offset: u64,
    /// NaN or infinite voxels: replace them (NaN and -inf by the smallest finite value,
    /// +inf by the largest, with a warning; see docs/io.md) or refuse the volume.
    #[arg(long, value_parser = choice::<NonFinite>(), default_value = "replace")]
    pub non_finite: NonFinite,
    /// Refuse a data file that a header (NRRD `data file:`) names outside the header's
    /// own folder. The format allows absolute paths and `../`, so without this flag a
    /// header can make voxlab read any file you can read.
    #[arg(long)]
    pub confine_data_files: bool,
    /// Which 3-D volume to read from a file that holds several (a NIfTI time series or
    /// vector image, a 4-D or vector MetaImage, a NRRD with a non-spatial axis, a DICOM
    /// time series): 0, 1, …; `voxlab info` says how many a file holds.
    #[arg(long)]
    pub frame: Option<usize>,
}

impl LoadArgs {
    /// The library's load options.
    pub fn options(&self) -> LoadOptions {
        LoadOptions {
            phantom_size: self.phantom_size,
            raw: self.raw_dims.map(|dims| RawInput {
                dims,
                sample: self.raw_type.clone(),
                endian: self.raw_endian,
                spacing: self.raw_spacing,
                offset: self.raw_offset,
            }),
            non_finite: self.non_finite,
            confine_data_files: self.confine_data_files,
            frame: self.frame,
        }
    }

    /// `source` loaded with these options.
    pub fn input(&self, source: &str) -> VolumeInput {
        VolumeInput::new(source).with_load(self.options())
    }
}

/// Where the camera looks from: an axis view, or an orbit around the volume.
#[derive(Args, Clone)]
pub struct ViewArgs {
    /// Axis-aligned orthographic view: +x, -x, +y, -y, +z, -z (rays along that index
    /// axis). The image is laid out like NumPy's reduction over that axis of the
    /// (nz, ny, nx) array (`vol.sum(axis=…)` for X-ray); its default size is the
    /// volume's cross-section, so every pixel centre lies on a ray through voxel
    /// centres. Without it, the orbit view below.
    #[arg(long = "view", allow_hyphen_values = true)]
    pub axis: Option<String>,
    /// Orbit view: rotation about world +z in degrees (0 looks along +y).
    #[arg(long, default_value_t = 30.0, allow_negative_numbers = true)]
    pub azimuth: f64,
    /// Orbit view: degrees above the xy-plane.
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
    pub elevation: f64,
}

impl ViewArgs {
    pub fn request(&self) -> ViewRequest {
        ViewRequest {
            axis: self.axis.clone(),
            azimuth: self.azimuth,
            elevation: self.elevation,
        }
    }
}

/// How a job's stages show on the terminal.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Style {
    /// Progress bars (drawn only on a terminal), notes as `voxlab: …`.
    Bars,
    /// A line per stage as it begins (`STAGE …`) and ends (`  1.23 s`), notes
    /// indented.
    Lines,
}

/// The terminal's [`Progress`]: indicatif bars (or lines) on stderr, warnings as
/// `voxlab: warning: …`.
pub struct Terminal {
    style: Style,
    bar: Mutex<Option<ProgressBar>>,
    /// Prefix of notes in the bar style (`voxlab: `, or nothing).
    note_prefix: &'static str,
}

impl Terminal {
    pub fn bars() -> Self {
        Terminal {
            style: Style::Bars,
            bar: Mutex::new(None),
            note_prefix: "voxlab: ",
        }
    }

    pub fn lines() -> Self {
        Terminal {
            style: Style::Lines,
            bar: Mutex::new(None),
            note_prefix: "  ",
        }
    }

    /// Bars whose notes are printed as they are.
    pub fn plain_notes(mut self) -> Self {
        self.note_prefix = "";
        self
    }

    /// Runs `f` with the bar (if one is shown) hidden, so that a line can be printed.
    pub fn suspend(&self, f: impl FnOnce()) {
        match self.bar.lock().expect("unpoisoned").as_ref() {
            Some(pb) => pb.suspend(f),
            None => f(),
        }
    }

    /// Sets the current bar's message.
    pub fn message(&self, text: String) {
        if let Some(pb) = self.bar.lock().expect("unpoisoned").as_ref() {
            pb.set_message(text);
        }
    }
}

impl Drop for Terminal {
    fn drop(&mut self) {
        if let Some(pb) = self.bar.lock().expect("unpoisoned").take() {
            pb.finish_and_clear();
        }
    }
}

/// A bar of `len` steps, `what [=====>   ] 12/40 unit, 3s (eta 7s)`.
fn progress_bar(len: u64, what: &str, unit: &str) -> ProgressBar {
    let pb = ProgressBar::new(len);
    pb.set_style(
        ProgressStyle::with_template(&format!(
            "{{msg}} [{{bar:40}}] {{pos}}/{{len}} {unit}, {{elapsed}} (eta {{eta}})"
        ))
        .expect("valid template")
        .progress_chars("=> "),
    );
    pb.set_message(what.to_string());
    pb
}

impl Progress for Terminal {
    fn begin(&self, stage: &str, unit: &str, steps: u64) {
        match self.style {
            Style::Lines => eprintln!("{stage} …"),
            Style::Bars => {
                let pb = if steps > 0 {
                    progress_bar(steps, stage, unit)
                } else {
                    let pb = ProgressBar::new_spinner();
                    pb.set_message(stage.to_string());
                    pb.enable_steady_tick(std::time::Duration::from_millis(200));
                    pb
                };
                if let Some(old) = self.bar.lock().expect("unpoisoned").replace(pb) {
                    old.finish_and_clear();
                }
            }
        }
    }

    fn advance(&self, done: u64, steps: u64) {
        if let Some(pb) = self.bar.lock().expect("unpoisoned").as_ref() {
            if pb.length() != Some(steps) && steps > 0 {
                pb.set_length(steps);
            }
            pb.set_position(done);
        }
    }

    fn end(&self, seconds: f64) {
        match self.style {
            Style::Lines => eprintln!("  {seconds:.2} s"),
            Style::Bars => {
                if let Some(pb) = self.bar.lock().expect("unpoisoned").take() {
                    pb.finish_and_clear();
                }
            }
        }
    }

    fn note(&self, text: &str) {
        let prefix = self.note_prefix;
        let text = voxlab::error::escape_controls(text);
        self.suspend(|| eprintln!("{prefix}{text}"));
    }

    fn warn(&self, text: &str) {
        let text = voxlab::error::escape_controls(text);
        self.suspend(|| eprintln!("voxlab: warning: {text}"));
    }
}
