//! `voxlab adaptive`: regular, direct and spectral adaptive sampling of one scene side
//! by side, in the manner of Table 1 of Suwelack et al. (MIAR 2010): samples per pixel,
//! time per frame and image error against regular sampling, written as Markdown and
//! JSON, with the images and the samples-per-ray images (see docs/adaptive-sampling.md).

use clap::{Args, ValueEnum};
use glam::DVec3;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;
use voxlab::camera::{Camera, Orbit, Projection};
use voxlab::cpu::adaptive::{self as ca, AdaptiveSettings, Sampling};
use voxlab::cpu::raycast::RenderOutput;
use voxlab::frame::PngOptions;
use voxlab::metrics::error_stats;
use voxlab::transfer::TransferFunction;
use voxlab::{AnyVolume, Error, Result};

/// Where to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum AdaptiveBackend {
    /// The f64 CPU oracle.
    Cpu,
    /// The same CPU code in f32 (the fair baseline for timings).
    CpuF32,
    /// The GPU port (f32).
    Gpu,
}

/// Arguments of `voxlab adaptive`.
#[derive(Args)]
pub struct AdaptiveArgs {
    /// Volume file (any format `info` reads) or phantom:NAME[:SIZE]; default: the
    /// modified Shepp–Logan phantom.
    input: Option<String>,
    #[command(flatten)]
    load: crate::LoadArgs,
    /// Transfer function: a preset name or a JSON file. Default: a medical-style
    /// function with a sharp opacity ramp (at 0.25 for phantoms, at 60 % of the value
    /// range for files).
    #[arg(long)]
    tf: Option<String>,
    /// Move the transfer function along the raw value axis by this much (through the
    /// window map, as a user browsing structures would; the spectrum is not recomputed).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    shift: f64,
    /// Folder for the images, table.md and table.json.
    #[arg(long)]
    out: PathBuf,
    /// cpu (f64 oracle), cpu-f32 or gpu.
    #[arg(long, value_enum, default_value = "cpu-f32")]
    backend: AdaptiveBackend,
    /// Image width and height in pixels.
    #[arg(long, default_value_t = 256)]
    size: usize,
    /// Orbit camera azimuth and elevation in degrees.
    #[arg(long, default_value_t = 30.0, allow_negative_numbers = true)]
    azimuth: f64,
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
    elevation: f64,
    /// Regular step and smallest adaptive step T_min (voxels).
    #[arg(long, default_value_t = 0.5)]
    step: f64,
    /// Largest step T_max (voxels).
    #[arg(long, default_value_t = 8.0)]
    t_max: f64,
    /// Oversampling factor over the estimated Nyquist rate.
    #[arg(long, default_value_t = 2.0)]
    oversampling: f64,
    /// Fraction of the spectrum's energy below the cut-off frequency.
    #[arg(long, default_value_t = 0.99)]
    energy: f64,
    /// Block edge of direct sampling (voxels).
    #[arg(long, default_value_t = 8)]
    block: usize,
    /// Timed renders per sampling (the median is reported).
    #[arg(long, default_value_t = 3)]
    runs: usize,
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
    pub backend: AdaptiveBackend,
    pub image: [usize; 2],
    pub settings: AdaptiveSettings,
    pub rows: Vec<Row>,
    /// 1 − adaptive samples / regular samples.
    pub adaptive_reduction: f64,
    /// Adaptive samples / direct samples.
    pub adaptive_over_direct: f64,
    pub goals: Vec<(String, bool)>,
}

fn default_tf(input: &str, volume: &AnyVolume) -> TransferFunction {
    if input.starts_with("phantom:") {
        ca::medical_tf(0.0, 1.0, 0.25, 0.05)
    } else {
        let r = volume.value_range();
        let (lo, hi) = (r.min, r.max.max(r.min + 1e-6));
        ca::medical_tf(lo, hi, lo + 0.6 * (hi - lo), 0.05 * (hi - lo))
    }
}

/// Renders once with the chosen backend; returns the output and the render time.
fn render_once(
    volume: &AnyVolume,
    tf: &TransferFunction,
    camera: &Camera,
    settings: &AdaptiveSettings,
    backend: AdaptiveBackend,
) -> Result<(RenderOutput, f64, f64)> {
    match backend {
        AdaptiveBackend::Cpu => cpu_once::<f64>(volume, tf, camera, settings),
        AdaptiveBackend::CpuF32 => cpu_once::<f32>(volume, tf, camera, settings),
        AdaptiveBackend::Gpu => {
            let ctx = voxlab::gpu::GpuContext::shared()?;
            let o = voxlab::gpu::adaptive::render(ctx, volume, tf, camera, settings)?;
            Ok((o.output, o.timings.prepare, o.timings.kernel))
        }
    }
}

fn cpu_once<R: voxlab::real::Real>(
    volume: &AnyVolume,
    tf: &TransferFunction,
    camera: &Camera,
    settings: &AdaptiveSettings,
) -> Result<(RenderOutput, f64, f64)> {
    let t = Instant::now();
    let scene = ca::prepare::<R>(volume, tf, settings)?;
    let prep = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let out = ca::render_prepared(&scene, camera, settings)?;
    Ok((out, prep, t.elapsed().as_secs_f64()))
}

/// Runs the comparison and writes the report into `a.out`.
pub fn run(a: AdaptiveArgs) -> Result<()> {
    let input = a
        .input
        .clone()
        .unwrap_or_else(|| "phantom:shepp-logan-modified".to_string());
    if a.out.is_file() {
        return Err(Error::invalid(
            "--out",
            format!("{} is a file, not a folder", a.out.display()),
        ));
    }
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
    let volume = crate::load_input(&input, &a.load)?;
    let mut tf = match &a.tf {
        Some(spec) => TransferFunction::preset_or_file(spec)?,
        None => default_tf(&input, &volume),
    };
    // Ψ'(t) = Ψ(t − shift): the function moves up the value axis by `shift`.
    tf.window.b -= tf.window.a * a.shift;
    let camera = Camera::orbit(
        volume_center(&volume),
        extent(&volume),
        Orbit {
            azimuth_deg: a.azimuth,
            elevation_deg: a.elevation,
            distance_mm: None,
        },
        Projection::Perspective { fov_y_deg: 30.0 },
        a.size,
        a.size,
    )?;
    std::fs::create_dir_all(&a.out).map_err(|e| Error::io(&a.out, e))?;

    let mut outputs: Vec<(Sampling, RenderOutput, f64, f64)> = Vec::new();
    for sampling in Sampling::ALL {
        let s = AdaptiveSettings {
            sampling,
            ..base.clone()
        };
        let mut times = Vec::new();
        let mut prep = 0.0;
        let mut out = None;
        for _ in 0..a.runs {
            let (o, p, t) = render_once(&volume, &tf, &camera, &s, a.backend)?;
            times.push(t);
            prep = p;
            out = Some(o);
        }
        times.sort_by(f64::total_cmp);
        let median = times[times.len() / 2];
        eprintln!(
            "{:>8}: {:.3} s per frame, {} samples",
            sampling.name(),
            median,
            out.as_ref().map_or(0, |o| o.total_samples)
        );
        outputs.push((sampling, out.expect("runs ≥ 1"), median, prep));
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
        let name = sampling.name();
        out.image
            .save(&a.out.join(format!("{name}.png")), PngOptions::default())?;
        counts.save(
            &a.out.join(format!("samples-{name}.png")),
            PngOptions {
                sixteen_bit: false,
                range: Some((0.0, max_count)),
            },
        )?;
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
        input: input.clone(),
        dims: volume.dims(),
        transfer_function: a.tf.clone().unwrap_or_else(|| "medical (default)".into()),
        shift: a.shift,
        backend: a.backend,
        image: [a.size, a.size],
        settings: base,
        rows,
        adaptive_reduction: reduction,
        adaptive_over_direct: over_direct,
        goals,
    };
    let md = markdown(&report);
    print!("{md}");
    write_text(&a.out.join("table.md"), &md)?;
    let json = serde_json::to_string_pretty(&report).expect("the report serialises");
    write_text(&a.out.join("table.json"), &json)?;
    Ok(())
}

fn volume_center(v: &AnyVolume) -> DVec3 {
    let d = v.dims();
    v.affine().transform_point3(DVec3::new(
        (d[0] as f64 - 1.0) / 2.0,
        (d[1] as f64 - 1.0) / 2.0,
        (d[2] as f64 - 1.0) / 2.0,
    ))
}

fn extent(v: &AnyVolume) -> [f64; 3] {
    let d = v.dims();
    let s = v.spacing();
    [d[0] as f64 * s[0], d[1] as f64 * s[1], d[2] as f64 * s[2]]
}

fn write_text(path: &Path, text: &str) -> Result<()> {
    voxlab::io::write_atomic(path, |w| {
        w.write_all(text.as_bytes()).map_err(|e| Error::io(path, e))
    })
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
            AdaptiveBackend::Cpu => "CPU f64",
            AdaptiveBackend::CpuF32 => "CPU f32",
            AdaptiveBackend::Gpu => "GPU",
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
        s += &format!(
            "| {} | {:.1} | {:.3} | {:.3} | {} | {} | {} |\n",
            row.sampling.name(),
            row.samples_per_pixel,
            row.seconds_per_frame,
            row.prepare_seconds,
            if reference {
                "—".into()
            } else {
                format!("{:.2e}", row.max_abs)
            },
            if reference {
                "—".into()
            } else {
                format!("{:.2e}", row.rmse)
            },
            if reference {
                "—".into()
            } else {
                format!("{:.1}", row.psnr_db)
            },
        );
    }
    s += "\nSamples per pixel: mean over the pixels whose ray meets the volume. Errors: RGBA \
          against regular sampling.\n\n";
    for (g, ok) in &r.goals {
        s += &format!("- [{}] {g}\n", if *ok { "x" } else { " " });
    }
    s
}

/// `voxlab render --sampling …`: the scene through the adaptive caster.
pub fn render_sampling(
    scene: &voxlab::render::Scene,
    settings: &voxlab::settings::RenderSettings,
    sampling: Sampling,
    backend: voxlab::render::Backend,
    out: &Path,
    samples: Option<&Path>,
    sixteen_bit: bool,
) -> Result<()> {
    use voxlab::render::Backend;
    if settings.mode != voxlab::settings::Mode::Dvr {
        return Err(Error::invalid(
            "--sampling",
            "the adaptive caster renders DVR only (--mode dvr)",
        ));
    }
    let s = AdaptiveSettings {
        sampling,
        step: settings.step,
        t_max: settings.step.max(8.0),
        ert_threshold: settings.ert_threshold,
        background: settings.background,
        sample_count: true,
        ..Default::default()
    };
    let backend = match backend {
        Backend::Cpu => AdaptiveBackend::Cpu,
        Backend::CpuF32 => AdaptiveBackend::CpuF32,
        Backend::Gpu => AdaptiveBackend::Gpu,
        Backend::Auto => match voxlab::gpu::GpuContext::shared() {
            Ok(ctx) if !ctx.summary.is_cpu() => AdaptiveBackend::Gpu,
            _ => AdaptiveBackend::Cpu,
        },
    };
    let t = Instant::now();
    let (o, _, _) = render_once(&scene.volume, &scene.transfer, &scene.camera, &s, backend)?;
    let png = PngOptions {
        sixteen_bit,
        range: None,
    };
    o.image.save(out, png)?;
    if let (Some(path), Some(c)) = (samples, &o.samples) {
        c.save(path, png)?;
    }
    eprintln!(
        "wrote {} ({}×{}, {} sampling, {} samples, {:.2} s on {:?})",
        out.display(),
        scene.camera.width,
        scene.camera.height,
        sampling.name(),
        o.total_samples,
        t.elapsed().as_secs_f64(),
        backend
    );
    Ok(())
}
