//! `voxlab compare`: the same scene on the CPU f64 oracle and on the GPU, and how far
//! apart they are ([`crate::metrics`]): the parity harness as a user feature.

use super::plan::MemoryPlan;
use super::render::{build_scene, plan_frame, Renderer, Scene, SceneRequest};
use super::{Backend, Engine, Progress};
use crate::cpu::raycast::RenderOutput;
use crate::error::{Error, Result};
use crate::gpu::raycast::GpuTimings;
use crate::metrics::{check_parity, write_artifacts, ParityReport, Tolerance};
use crate::settings::RenderSettings;
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Instant;

/// The `voxlab compare` job: a scene, and the bounds the port must stay within.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CompareRequest {
    pub scene: SceneRequest,
    /// No element may differ by more than this (`None`: no bound).
    pub max_abs: Option<f64>,
    /// The RMS difference may not exceed this (`None`: no bound).
    pub rmse: Option<f64>,
}

/// Both renders and the verdict.
#[derive(Clone, Debug)]
pub struct Comparison {
    pub cpu: RenderOutput,
    pub gpu: RenderOutput,
    pub report: ParityReport,
    /// The GPU, described (adapter and backend).
    pub adapter: String,
    pub cpu_seconds: f64,
    pub gpu_timings: GpuTimings,
    pub settings: RenderSettings,
    pub image: [usize; 2],
}

/// The memory plans of the two renders (the oracle's, the GPU's), after the checks
/// each makes before its work: a frame the GPU would refuse is refused before the
/// oracle spends minutes on it.
fn plans(scene: &Scene, settings: &RenderSettings) -> Result<[MemoryPlan; 2]> {
    let oracle = plan_frame(scene, settings, &Engine::open(Backend::Cpu)?)?;
    let gpu = plan_frame(scene, settings, &Engine::open(Backend::Gpu)?)?;
    Ok([oracle, gpu])
}

/// `voxlab compare --dry-run`: the memory plans of the oracle's render and the GPU's
/// ([`crate::jobs::render`]'s, one each), after loading the input; renders nothing.
///
/// # Errors
/// Invalid input or settings; no GPU adapter; what either render would refuse before
/// it starts.
pub fn plan(c: &CompareRequest, progress: &dyn Progress) -> Result<[MemoryPlan; 2]> {
    let (scene, mut settings) = build_scene(&c.scene, true, progress)?;
    c.scene.accel.apply(&mut settings)?;
    plans(&scene, &settings)
}

/// Renders the scene on the oracle and the GPU and compares them.
///
/// # Errors
/// Invalid input or settings; no GPU adapter; what either render refuses (checked for
/// both before the oracle renders); [`Error::Cancelled`].
pub fn run(c: &CompareRequest, progress: &dyn Progress) -> Result<Comparison> {
    let (scene, mut settings) = build_scene(&c.scene, true, progress)?;
    c.scene.accel.apply(&mut settings)?;
    plans(&scene, &settings)?;
    let gpu = Renderer::new(Backend::Gpu)?;
    progress.begin("cpu (f64 oracle)", "rows", scene.camera.height as u64);
    let t = Instant::now();
    let cpu_out = c
        .scene
        .accel
        .render(&Renderer::new(Backend::Cpu)?, &scene, &settings, progress)?
        .output;
    let cpu_seconds = t.elapsed().as_secs_f64();
    progress.end(cpu_seconds);
    super::check_cancel(progress)?;
    let g = c.scene.accel.render(&gpu, &scene, &settings, &())?;
    let tol = Tolerance {
        max_abs: c.max_abs.unwrap_or(f64::INFINITY),
        rmse: c.rmse.unwrap_or(f64::INFINITY),
        ..Tolerance::NONE
    };
    let report = check_parity("compare", &cpu_out.image, &g.output.image, tol, None)?;
    Ok(Comparison {
        cpu: cpu_out,
        gpu: g.output,
        report,
        adapter: gpu.describe(),
        cpu_seconds,
        gpu_timings: g.gpu_timings.unwrap_or_default(),
        settings,
        image: [scene.camera.width, scene.camera.height],
    })
}

impl Comparison {
    /// Writes `cpu.png`, `gpu.png`, `diff.png` (the |Δ| heat map with its scale) and
    /// `stats.json` (the input's name, the settings, the statistics, the bounds
    /// `max_abs`/`rmse` as given, the timings and the sample counts) into `dir`.
    ///
    /// # Errors
    /// I/O errors, naming the file.
    pub fn write_evidence(
        &self,
        dir: &Path,
        input: &str,
        max_abs: Option<f64>,
        rmse: Option<f64>,
    ) -> Result<()> {
        let r = &self.report;
        write_artifacts(dir, &self.cpu.image, &self.gpu.image, &r.stats, r.tolerance)?;
        let json = serde_json::to_string_pretty(&serde_json::json!({
            "input": input,
            "adapter": self.adapter,
            "settings": self.settings,
            "image": self.image,
            "stats": r.stats,
            "tolerance": { "max_abs": max_abs, "rmse": rmse },
            "passed": r.passed,
            "cpu_f64_seconds": self.cpu_seconds,
            "gpu_seconds": self.gpu_timings,
            "samples": { "cpu": self.cpu.total_samples, "gpu": self.gpu.total_samples },
        }))
        .map_err(|e| Error::invalid("compare statistics", e.to_string()))?;
        crate::io::write_text(&dir.join("stats.json"), &json)
    }
}
