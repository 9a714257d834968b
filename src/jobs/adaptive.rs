//! `voxlab adaptive`: regular, direct and spectral adaptive sampling of one scene side
//! by side, in the manner of Table 1 of Suwelack et al. (MIAR 2010): samples per pixel,
//! time per frame and image error against regular sampling, as Markdown and JSON, with
//! the images and the samples-per-ray images (see docs/adaptive-sampling.md). The
//! caster itself is [`crate::cpu::adaptive`] and [`crate::gpu::adaptive`].

use super::input::{volume_center, volume_extent, VolumeInput};
use super::{check_cancel, Backend, Engine, Progress};
use crate::camera::{Camera, Orbit, Projection};
use crate::cpu::adaptive::{self as ca, AdaptiveSettings, Sampling};
use crate::cpu::raycast::RenderOutput;
use crate::error::{Error, Result};
use crate::io::{write_frame, PngOptions};
use crate::metrics::error_stats;
use crate::transfer::TransferFunction;
use crate::volume::AnyVolume;
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Instant;

/// The `voxlab adaptive` job.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AdaptiveRequest {
    /// The volume (default: the modified Shepp–Logan phantom).
    pub input: VolumeInput,
    /// Transfer function: a preset name or a JSON file. `None`: a medical-style
    /// function with a sharp opacity ramp (at 0.25 for phantoms, at 60 % of the value
    /// range for files).
    pub tf: Option<String>,
    /// Move the transfer function along the raw value axis by this much (through the
    /// window map, as a user browsing structures would; the spectrum is not recomputed).
    pub shift: f64,
    pub backend: Backend,
    /// Image width and height in pixels.
    pub size: usize,
    /// Orbit camera azimuth and elevation in degrees.
    pub azimuth: f64,
    pub elevation: f64,
    /// Regular step and smallest adaptive step T_min (voxels).
    pub step: f64,
    /// Largest step T_max (voxels).
    pub t_max: f64,
    /// Oversampling factor over the estimated Nyquist rate.
    pub oversampling: f64,
    /// Fraction of the spectrum's energy below the cut-off frequency.
    pub energy: f64,
    /// Block edge of direct sampling (voxels).
    pub block: usize,
    /// Timed renders per sampling (1 … 100; the median is reported).
    pub runs: usize,
}

impl Default for AdaptiveRequest {
    fn default() -> Self {
        AdaptiveRequest {
            input: VolumeInput::default(),
            tf: None,
            shift: 0.0,
            backend: Backend::CpuF32,
            size: 256,
            azimuth: 30.0,
            elevation: 20.0,
            step: 0.5,
            t_max: 8.0,
            oversampling: 2.0,
            energy: 0.99,
            block: 8,
            runs: 3,
        }
    }
}

/// One row of the table.
#[derive(Clone, Debug, Serialize)]
pub struct Row {
    pub sampling: Sampling,
    /// Mean samples per pixel over the pixels whose ray meets the volume.
    pub samples_per_pixel: f64,
    /// Total samples over all rays.
    pub total_samples: u64,
    /// Median render time (s), preparation excluded.
    pub seconds_per_frame: f64,
    /// Preparation: pre-integration plus the spectral table and importance volume
    /// (adaptive) or the block spectra (direct), seconds.
    pub prepare_seconds: f64,
    /// Against regular sampling (RGBA, values in [0, 1]).
    pub max_abs: f64,
    pub rmse: f64,
    pub psnr_db: f64,
}

/// The whole report.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub input: String,
    pub dims: [usize; 3],
    pub transfer_function: String,
    pub shift: f64,
    pub backend: Backend,
    pub image: [usize; 2],
    pub settings: AdaptiveSettings,
    pub rows: Vec<Row>,
    /// 1 − adaptive samples / regular samples.
    pub adaptive_reduction: f64,
    /// Adaptive samples / direct samples.
    pub adaptive_over_direct: f64,
    pub goals: Vec<(String, bool)>,
}

/// What the job returns: the report and each sampling's last render.
#[derive(Clone, Debug)]
pub struct Comparison {
    pub report: Report,
    /// In the order of [`Sampling::ALL`], as the report's rows.
    pub outputs: Vec<(Sampling, RenderOutput)>,
    /// The largest sample count of any ray (white in the samples images).
    pub max_count: f64,
}

fn default_tf(input: &VolumeInput, volume: &AnyVolume) -> TransferFunction {
    if input.is_phantom() {
        ca::medical_tf(0.0, 1.0, 0.25, 0.05)
    } else {
        let r = volume.value_range();
        let (lo, hi) = (r.min, r.max.max(r.min + 1e-6));
        ca::medical_tf(lo, hi, lo + 0.6 * (hi - lo), 0.05 * (hi - lo))
    }
}

/// One render by the adaptive caster and its times.
#[derive(Clone, Debug)]
pub struct AdaptiveRun {
    pub output: RenderOutput,
    /// Preparation seconds (pre-integration, spectra, importance volume).
    pub prepare: f64,
    /// Render seconds (GPU: the kernel).
    pub render: f64,
    /// How the GPU cut the volume into bricks, when it did
    /// ([`crate::gpu::adaptive::AdaptiveSplit::line`]).
    pub split: Option<String>,
}

/// Renders once on `engine` with the adaptive caster.
///
/// # Errors
/// Invalid settings; GPU errors.
pub fn render_once(
    volume: &AnyVolume,
    tf: &TransferFunction,
    camera: &Camera,
    settings: &AdaptiveSettings,
    engine: Engine,
) -> Result<AdaptiveRun> {
    match (engine.backend(), engine.gpu()) {
        (Backend::Gpu, Some(ctx)) => {
            let o = crate::gpu::adaptive::render(ctx, volume, tf, camera, settings)?;
            Ok(AdaptiveRun {
                output: o.output,
                prepare: o.timings.prepare,
                render: o.timings.kernel,
                split: o.split,
            })
        }
        (Backend::CpuF32, _) => cpu_once::<f32>(volume, tf, camera, settings),
        _ => cpu_once::<f64>(volume, tf, camera, settings),
    }
}

fn cpu_once<R: crate::real::Real>(
    volume: &AnyVolume,
    tf: &TransferFunction,
    camera: &Camera,
    settings: &AdaptiveSettings,
) -> Result<AdaptiveRun> {
    ca::check_cost(volume.dims(), camera, settings)?;
    let t = Instant::now();
    let scene = ca::prepare::<R>(volume, tf, settings)?;
    let prepare = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let output = ca::render_prepared(&scene, camera, settings)?;
    Ok(AdaptiveRun {
        output,
        prepare,
        render: t.elapsed().as_secs_f64(),
        split: None,
    })
}

/// What one frame of the adaptive caster holds, after every check its render makes
/// before the work, in the run's order: on the CPU [`ca::check_cost`], the volume (and
/// the importance volume of adaptive sampling: three reals a voxel) in the working
/// precision; on the GPU [`crate::gpu::adaptive::check`], the f32 volume and the rays
/// packed on the host, [`crate::gpu::adaptive::device_textures`] (of the largest brick
/// where the volume is split), [`crate::gpu::adaptive::device_tables`] and one band's
/// [`crate::gpu::adaptive::band_buffers`] on the device. `image` is the output's host
/// bytes. `render --dry-run --sampling` and `adaptive --dry-run` call it.
///
/// # Errors
/// What the frame's render would refuse before it starts.
pub(crate) fn frame_plan(
    engine: &Engine,
    volume: &AnyVolume,
    tf: &TransferFunction,
    camera: &Camera,
    s: &AdaptiveSettings,
    image: u64,
) -> Result<(u64, Option<super::plan::DevicePlan>, Option<String>)> {
    let dims = volume.dims();
    let voxels = dims.iter().product::<usize>() as u64;
    let planned = match engine.gpu() {
        Some(ctx) => {
            let split = crate::gpu::adaptive::check(ctx, dims, camera, s)?;
            let (tex, carried) = match &split {
                Some(cut) => (cut.largest, true),
                None => (dims, false),
            };
            let textures = crate::gpu::adaptive::device_textures(tex, s);
            let bands = crate::gpu::adaptive::band_buffers(ctx, camera, carried);
            let tables = crate::gpu::adaptive::device_tables(dims, s);
            let sizes = || textures.iter().chain(&bands).chain(&tables).map(|b| b.1);
            let pixels = camera.width as u64 * camera.height as u64;
            // The rays; split, each ray's carried state and a brick's f32 texels.
            let extra = match &split {
                Some(_) => {
                    pixels * 16 * crate::gpu::adaptive::CARRIED_VEC4S as u64
                        + 4 * tex.iter().product::<usize>() as u64
                }
                None => 0,
            };
            let device =
                super::plan::DevicePlan::on(ctx, sizes().sum(), sizes().max().unwrap_or(0));
            (
                4 * voxels + 32 * pixels + extra + image,
                Some(device),
                split.map(|c| c.line),
            )
        }
        None => {
            ca::check_cost(dims, camera, s)?;
            let real = if engine.backend() == Backend::CpuF32 {
                4
            } else {
                8
            };
            let importance = if s.sampling == Sampling::Adaptive {
                3 * real * voxels
            } else {
                0
            };
            (real * voxels + importance + image, None, None)
        }
    };
    tf.validate()?;
    volume.check_finite("volume")?;
    Ok(planned)
}

/// What [`run`] and [`plan`] share: the request checked, the volume loaded, the
/// transfer function shifted, the camera and the engine.
struct Setup {
    base: AdaptiveSettings,
    volume: AnyVolume,
    tf: TransferFunction,
    camera: Camera,
    engine: Engine,
}

fn setup(a: &AdaptiveRequest, progress: &dyn Progress) -> Result<Setup> {
    if a.runs == 0 || a.runs > 100 {
        return Err(Error::invalid("--runs", "must lie in 1..=100"));
    }
    if !a.shift.is_finite() {
        return Err(Error::invalid("--shift", "must be finite"));
    }
    let base = AdaptiveSettings {
        step: a.step,
        t_max: a.t_max,
        oversampling: a.oversampling,
        energy: a.energy,
        block: a.block,
        sample_count: true,
        ..Default::default()
    };
    base.validate()?;
    let volume = a.input.load(progress)?;
    let mut tf = match &a.tf {
        Some(spec) => TransferFunction::preset_or_file(spec)?,
        None => default_tf(&a.input, &volume),
    };
    // Ψ'(t) = Ψ(t − shift): the function moves up the value axis by `shift`.
    tf.window.b -= tf.window.a * a.shift;
    let camera = Camera::orbit(
        volume_center(&volume),
        volume_extent(&volume),
        Orbit {
            azimuth_deg: a.azimuth,
            elevation_deg: a.elevation,
            distance_mm: None,
        },
        Projection::Perspective { fov_y_deg: 30.0 },
        a.size,
        a.size,
    )?;
    let engine = Engine::open_for(
        "adaptive sampling",
        a.backend,
        &[Backend::Cpu, Backend::CpuF32, Backend::Gpu],
    )?;
    Ok(Setup {
        base,
        volume,
        tf,
        camera,
        engine,
    })
}

/// `voxlab adaptive --dry-run`: what [`run`] would hold, after loading the input and
/// checking the request as the run does, rendering nothing: each sampling's frame
/// (`frame_plan`; they render one after another, so the plan is the largest) and the
/// three images and sample-count images the comparison keeps.
///
/// # Errors
/// As [`run`] up to its first render, and what any of the three renders would refuse
/// before it starts.
pub fn plan(a: &AdaptiveRequest, progress: &dyn Progress) -> Result<super::plan::MemoryPlan> {
    let Setup {
        base,
        volume,
        tf,
        camera,
        engine,
    } = setup(a, progress)?;
    // Each frame's RGBA image and counts (f64), and the u32 counts while it renders.
    let pixels = (camera.width * camera.height) as u64;
    let image = pixels * (8 * 4 + 8 + 4);
    let kept = (Sampling::ALL.len() as u64 - 1) * pixels * (8 * 4 + 8);
    let mut host = 0;
    let mut split = Vec::new();
    let mut device: Option<super::plan::DevicePlan> = None;
    for sampling in Sampling::ALL {
        let s = AdaptiveSettings {
            sampling,
            ..base.clone()
        };
        let (h, d, cut) = frame_plan(&engine, &volume, &tf, &camera, &s, image)?;
        split.extend(cut.map(|c| format!("{} sampling: {c}", sampling.name())));
        host = host.max(h + kept);
        if let Some(d) = d {
            if device.as_ref().is_none_or(|x| d.peak_bytes > x.peak_bytes) {
                device = Some(d);
            }
        }
    }
    Ok(super::plan::MemoryPlan {
        job: "adaptive (regular, direct and adaptive sampling)".to_string(),
        backend: engine.describe(),
        host_bytes: host,
        device,
        split,
        writes: Vec::new(),
    })
}

/// Runs the comparison.
///
/// # Errors
/// Invalid options or input; GPU errors; [`Error::Cancelled`].
pub fn run(a: &AdaptiveRequest, progress: &dyn Progress) -> Result<Comparison> {
    let Setup {
        base,
        volume,
        tf,
        camera,
        engine,
    } = setup(a, progress)?;
    let mut outputs: Vec<(Sampling, RenderOutput, f64, f64)> = Vec::new();
    for (k, sampling) in Sampling::ALL.into_iter().enumerate() {
        let s = AdaptiveSettings {
            sampling,
            ..base.clone()
        };
        progress.begin(
            &format!("{} sampling", sampling.name()),
            "runs",
            a.runs as u64,
        );
        let mut times = Vec::new();
        let mut prep = 0.0;
        let mut out = None;
        for r in 0..a.runs {
            check_cancel(progress)?;
            let run = render_once(&volume, &tf, &camera, &s, engine)?;
            if let (0, Some(split)) = (r, &run.split) {
                progress.note(&format!("{} sampling: {split}", sampling.name()));
            }
            times.push(run.render);
            prep = run.prepare;
            out = Some(run.output);
            progress.advance(r as u64 + 1, a.runs as u64);
        }
        times.sort_by(f64::total_cmp);
        let median = times[times.len() / 2];
        progress.end(median);
        outputs.push((sampling, out.expect("runs ≥ 1"), median, prep));
        debug_assert_eq!(outputs.len(), k + 1);
    }

    let reference = outputs[0].1.image.clone();
    let hit: Vec<bool> = outputs[0]
        .1
        .samples
        .as_ref()
        .expect("sample counts were asked for")
        .data
        .iter()
        .map(|&c| c > 0.0)
        .collect();
    let n_hit = hit.iter().filter(|&&h| h).count().max(1);
    let max_count = outputs
        .iter()
        .flat_map(|o| o.1.samples.as_ref().unwrap().data.iter().copied())
        .fold(1.0, f64::max);
    let mut rows = Vec::new();
    for (sampling, out, secs, prep) in &outputs {
        let counts = out.samples.as_ref().unwrap();
        let e = error_stats(&reference.data, &out.image.data, 1.0);
        rows.push(Row {
            sampling: *sampling,
            samples_per_pixel: counts.data.iter().sum::<f64>() / n_hit as f64,
            total_samples: out.total_samples,
            seconds_per_frame: *secs,
            prepare_seconds: *prep,
            max_abs: e.max_abs,
            rmse: e.rmse,
            psnr_db: e.psnr_db,
        });
    }
    let spp = |s: Sampling| rows.iter().find(|r| r.sampling == s).unwrap();
    let (reg, dir, ada) = (
        spp(Sampling::Regular),
        spp(Sampling::Direct),
        spp(Sampling::Adaptive),
    );
    let reduction = 1.0 - ada.samples_per_pixel / reg.samples_per_pixel;
    let over_direct = ada.samples_per_pixel / dir.samples_per_pixel.max(1e-300);
    let goals = vec![
        (
            format!(
                "adaptive takes ≥ 50 % fewer samples than regular: {:.1} %",
                100.0 * reduction
            ),
            reduction >= 0.5,
        ),
        (
            format!("adaptive PSNR vs regular ≥ 40 dB: {:.1} dB", ada.psnr_db),
            ada.psnr_db >= 40.0,
        ),
        (
            format!("adaptive ≤ 1.5 × the samples of direct: {over_direct:.2} ×"),
            over_direct <= 1.5,
        ),
    ];
    let report = Report {
        input: a.input.source.clone(),
        dims: volume.dims(),
        transfer_function: a.tf.clone().unwrap_or_else(|| "medical (default)".into()),
        shift: a.shift,
        backend: engine.backend(),
        image: [a.size, a.size],
        settings: base,
        rows,
        adaptive_reduction: reduction,
        adaptive_over_direct: over_direct,
        goals,
    };
    Ok(Comparison {
        report,
        outputs: outputs.into_iter().map(|(s, o, _, _)| (s, o)).collect(),
        max_count,
    })
}

impl Comparison {
    /// Writes `<sampling>.png` and `samples-<sampling>.png` for every sampling into
    /// `dir` (created if missing).
    ///
    /// # Errors
    /// I/O errors, naming the file.
    pub fn write_images(&self, dir: &Path) -> Result<()> {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        for (sampling, out) in &self.outputs {
            let name = sampling.name();
            write_frame(
                &dir.join(format!("{name}.png")),
                &out.image,
                PngOptions::default(),
            )?;
            if let Some(counts) = &out.samples {
                write_frame(
                    &dir.join(format!("samples-{name}.png")),
                    counts,
                    PngOptions {
                        sixteen_bit: false,
                        range: Some((0.0, self.max_count)),
                    },
                )?;
            }
        }
        Ok(())
    }

    /// Writes `table.md` (returned) and `table.json` into `dir`.
    ///
    /// # Errors
    /// I/O errors, naming the file.
    pub fn write_tables(&self, dir: &Path) -> Result<String> {
        let md = markdown(&self.report);
        crate::io::write_text(&dir.join("table.md"), &md)?;
        let json = serde_json::to_string_pretty(&self.report).expect("the report serialises");
        crate::io::write_text(&dir.join("table.json"), &json)?;
        Ok(md)
    }
}

/// The report as Markdown: the table and the goals.
pub fn markdown(r: &Report) -> String {
    let mut s = format!(
        "# Adaptive sampling: {} ({}×{}×{}), {} backend\n\n\
         Transfer function: {} shifted by {}; image {}×{}; step {} (T_min), T_max {}, \
         oversampling {}, energy {}, blocks {}³.\n\n\
         | sampling | samples/pixel | time/frame (s) | preparation (s) | max abs | RMSE | PSNR (dB) |\n\
         |---|---:|---:|---:|---:|---:|---:|\n",
        r.input,
        r.dims[0],
        r.dims[1],
        r.dims[2],
        match r.backend {
            Backend::Cpu => "CPU f64",
            Backend::CpuF32 => "CPU f32",
            Backend::Gpu => "GPU",
            Backend::Auto => "auto",
        },
        r.transfer_function,
        r.shift,
        r.image[0],
        r.image[1],
        r.settings.step,
        r.settings.t_max,
        r.settings.oversampling,
        r.settings.energy,
        r.settings.block,
    );
    for row in &r.rows {
        let reference = row.sampling == Sampling::Regular;
        let dash = |v: String| if reference { "—".to_string() } else { v };
        s += &format!(
            "| {} | {:.1} | {:.3} | {:.3} | {} | {} | {} |\n",
            row.sampling.name(),
            row.samples_per_pixel,
            row.seconds_per_frame,
            row.prepare_seconds,
            dash(format!("{:.2e}", row.max_abs)),
            dash(format!("{:.2e}", row.rmse)),
            dash(format!("{:.1}", row.psnr_db)),
        );
    }
    s += "\nSamples per pixel: mean over the pixels whose ray meets the volume. Errors: RGBA \
          against regular sampling.\n\n";
    for (g, ok) in &r.goals {
        s += &format!("- [{}] {g}\n", if *ok { "x" } else { " " });
    }
    s
}
