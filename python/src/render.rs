//! `voxlab.render`, `voxlab.Renderer` (and its prepared scenes), `voxlab.compare`,
//! `voxlab.compare_images`: the render and compare jobs from JSON requests (built from
//! keyword arguments).

use crate::{arrays, errors, job};
use numpy::PyReadonlyArrayDyn;
use pyo3::prelude::*;
use std::sync::Mutex;
use voxlab::cpu::raycast::RenderOutput;
use voxlab::jobs::compare::CompareRequest;
use voxlab::jobs::input::VolumeInput;
use voxlab::jobs::render::{
    build_scene, build_view, PreparedScene as JobPreparedScene, RenderRequest, Rendered,
    Renderer as JobRenderer, SceneRequest,
};
use voxlab::jobs::Backend;
use voxlab::metrics::{check_parity, diff_heatmap, Tolerance};
use voxlab::transfer::TransferFunction;
use voxlab::transfer2d::TransferFunction2D;
use voxlab::volume::AnyVolume;

/// A volume from Python: an array with its affine, or nothing (the request's `input`
/// names a file or phantom).
pub(crate) fn memory_input(
    py: Python<'_>,
    scene: &mut SceneRequest,
    volume: Option<(&Bound<'_, PyAny>, [[f64; 4]; 4])>,
) -> PyResult<()> {
    let (array, affine) = volume.unzip();
    arrays::memory_input(py, &mut scene.input, array, affine)
}

/// Transfer functions given in memory (their JSON, parsed here): the scene's
/// `transfer` and `transfer_2d`, used instead of the request's `tf` and `tf2d`.
pub(crate) fn memory_transfers(
    py: Python<'_>,
    scene: &mut SceneRequest,
    tf: Option<&str>,
    tf2d: Option<&str>,
) -> PyResult<()> {
    if let Some(t) = tf {
        scene.transfer = Some(TransferFunction::from_json(t).map_err(|e| errors::to_py(py, &e))?);
    }
    if let Some(t) = tf2d {
        scene.transfer_2d =
            Some(TransferFunction2D::from_json(t).map_err(|e| errors::to_py(py, &e))?);
    }
    Ok(())
}

/// What a render returns to the Python half: image, samples image, and the rest as JSON.
type RenderParts = (Py<PyAny>, Option<Py<PyAny>>, String);

fn output_parts(
    py: Python<'_>,
    out: &RenderOutput,
    meta: serde_json::Value,
) -> PyResult<RenderParts> {
    let image = arrays::from_frame(py, &out.image)?;
    let samples = match &out.samples {
        Some(s) => Some(arrays::from_frame(py, s)?),
        None => None,
    };
    Ok((image, samples, meta.to_string()))
}

/// The render job (`voxlab render`) from a JSON [`RenderRequest`].
#[pyfunction]
#[pyo3(signature = (request, volume=None, affine=None, progress=None, tf=None, tf2d=None))]
fn render(
    py: Python<'_>,
    request: &str,
    volume: Option<Bound<'_, PyAny>>,
    affine: Option<[[f64; 4]; 4]>,
    progress: Option<Bound<'_, PyAny>>,
    tf: Option<&str>,
    tf2d: Option<&str>,
) -> PyResult<RenderParts> {
    let mut req: RenderRequest = errors::parse_request(py, "render option", request)?;
    let vol = volume
        .as_ref()
        .map(|v| (v, affine.unwrap_or(arrays::rows(glam::DMat4::IDENTITY))));
    memory_input(py, &mut req.scene, vol)?;
    memory_transfers(py, &mut req.scene, tf, tf2d)?;
    let r = job::run(py, job::callback(&progress), |p| {
        voxlab::jobs::render::run(&req, p)
    })?;
    let meta = serde_json::json!({
        "engine": r.engine.describe(),
        "backend": r.engine.backend().name(),
        "fallback": r.engine.fallback_reason(),
        "seconds": r.seconds,
        "total_samples": r.output.total_samples,
        "gpu_timings": r.gpu_timings,
        "frames": r.frames,
        "stereo": r.stereo,
        "volumes": r.volumes,
        "settings": r.settings,
    });
    output_parts(py, &r.output, meta)
}

/// A renderer that keeps its engine (for the GPU, the process's device) between
/// renders; [`Renderer::prepare`] keeps a volume too.
#[pyclass(frozen, module = "voxlab._voxlab")]
struct Renderer {
    inner: JobRenderer,
}

#[pymethods]
impl Renderer {
    #[new]
    fn new(py: Python<'_>, backend: &str) -> PyResult<Self> {
        let b: Backend = backend.parse().map_err(|e| errors::to_py(py, &e))?;
        let inner = job::run(py, None, |_| JobRenderer::new(b))?;
        Ok(Renderer { inner })
    }

    /// The engine, described: `cpu (f64 oracle)`, `gpu (NAME, Vulkan)`.
    fn describe(&self) -> String {
        self.inner.describe()
    }

    /// The backend renders run on (`auto` resolved).
    #[getter]
    fn backend(&self) -> &'static str {
        self.inner.backend().name()
    }

    /// Why `auto` fell back to the CPU, if it did.
    #[getter]
    fn fallback_reason(&self) -> Option<String> {
        self.inner.fallback_reason().map(str::to_string)
    }

    /// One frame of a JSON [`RenderRequest`] (its `backend` is ignored: the renderer's
    /// is used). Stereo pairs, repeats, extra volumes and adaptive sampling go through
    /// `voxlab.render`.
    #[pyo3(signature = (request, volume=None, affine=None, progress=None, tf=None, tf2d=None))]
    #[allow(clippy::too_many_arguments)]
    fn render(
        &self,
        py: Python<'_>,
        request: &str,
        volume: Option<Bound<'_, PyAny>>,
        affine: Option<[[f64; 4]; 4]>,
        progress: Option<Bound<'_, PyAny>>,
        tf: Option<&str>,
        tf2d: Option<&str>,
    ) -> PyResult<RenderParts> {
        let mut req: RenderRequest = errors::parse_request(py, "render option", request)?;
        single_frames(py, &req, "Renderer.render")?;
        let vol = volume
            .as_ref()
            .map(|v| (v, affine.unwrap_or(arrays::rows(glam::DMat4::IDENTITY))));
        memory_input(py, &mut req.scene, vol)?;
        memory_transfers(py, &mut req.scene, tf, tf2d)?;
        let renderer = &self.inner;
        let (r, seconds) = job::run(py, job::callback(&progress), |p| {
            let (scene, mut settings) = build_scene(&req.scene, req.samples, p)?;
            req.scene.accel.apply(&mut settings)?;
            let t = std::time::Instant::now();
            let r = req.scene.accel.render(renderer, &scene, &settings, p)?;
            Ok((r, t.elapsed().as_secs_f64()))
        })?;
        output_parts(py, &r.output, frame_meta(renderer, &r, seconds))
    }

    /// Prepares the scene of a JSON [`RenderRequest`] for many frames
    /// ([`JobRenderer::prepare`]): loads the volume, and on the GPU uploads it once.
    #[pyo3(signature = (request, volume=None, affine=None, progress=None, tf=None, tf2d=None))]
    #[allow(clippy::too_many_arguments)]
    fn prepare(
        &self,
        py: Python<'_>,
        request: &str,
        volume: Option<Bound<'_, PyAny>>,
        affine: Option<[[f64; 4]; 4]>,
        progress: Option<Bound<'_, PyAny>>,
        tf: Option<&str>,
        tf2d: Option<&str>,
    ) -> PyResult<PreparedScene> {
        let mut req: RenderRequest = errors::parse_request(py, "render option", request)?;
        single_frames(py, &req, "Renderer.prepare")?;
        let vol = volume
            .as_ref()
            .map(|v| (v, affine.unwrap_or(arrays::rows(glam::DMat4::IDENTITY))));
        memory_input(py, &mut req.scene, vol)?;
        memory_transfers(py, &mut req.scene, tf, tf2d)?;
        let renderer = JobRenderer::on(self.inner.engine());
        let (prepared, volume) = job::run(py, job::callback(&progress), |p| {
            let (scene, mut settings) = build_scene(&req.scene, req.samples, p)?;
            req.scene.accel.apply(&mut settings)?;
            let prepared = renderer.prepare(&scene, &settings)?;
            // A copy of its own: the caller may change the array between frames.
            Ok((prepared, scene.volume.into_owned()))
        })?;
        // The loaded volume stays (frames build their cameras and `auto` transfer
        // functions from it); the request's own reference to the caller's data goes.
        let mut input = req.scene.input;
        input.memory = None;
        Ok(PreparedScene {
            renderer,
            input,
            state_file: req.scene.state_file,
            volume,
            prepared: Mutex::new(prepared),
        })
    }
}

/// Refuses what a single frame cannot be: stereo pairs, repeats, extra volumes,
/// adaptive sampling.
fn single_frames(py: Python<'_>, req: &RenderRequest, what: &str) -> PyResult<()> {
    if req.stereo.is_some()
        || req.repeat.is_some()
        || !req.volumes.is_empty()
        || req.sampling.is_some()
    {
        return Err(errors::raise(
            py,
            "InvalidError",
            &format!(
                "invalid {what} option: a Renderer renders single frames; stereo, repeat, \
                 volumes and sampling go through voxlab.render"
            ),
        ));
    }
    Ok(())
}

/// The JSON half of a frame's result.
fn frame_meta(renderer: &JobRenderer, r: &Rendered, seconds: f64) -> serde_json::Value {
    serde_json::json!({
        "engine": renderer.describe(),
        "backend": renderer.backend().name(),
        "fallback": renderer.fallback_reason(),
        "seconds": seconds,
        "total_samples": r.output.total_samples,
        "gpu_timings": r.gpu_timings,
        "gpu_session": r.gpu_session,
    })
}

/// A volume prepared for many frames (`Renderer.prepare`): the library's own copy of
/// the volume, taken when it was prepared, and on the GPU a render session (the volume
/// uploaded once; pipelines, lookup tables and set-up volumes made again only when a
/// frame changes them).
#[pyclass(frozen, module = "voxlab._voxlab")]
struct PreparedScene {
    renderer: JobRenderer,
    /// Where the volume came from (for the `auto` transfer function), without its data.
    input: VolumeInput,
    state_file: Option<std::path::PathBuf>,
    volume: AnyVolume,
    /// Frames render one at a time; a CPU preparation is replaced when a frame changes
    /// the filter or gradients.
    prepared: Mutex<JobPreparedScene>,
}

#[pymethods]
impl PreparedScene {
    /// One frame of a JSON [`RenderRequest`] of the prepared volume: every option but
    /// the input's (its `input`, `state_file` and `backend` are the preparation's).
    #[pyo3(signature = (request, progress=None, tf=None, tf2d=None))]
    fn render(
        &self,
        py: Python<'_>,
        request: &str,
        progress: Option<Bound<'_, PyAny>>,
        tf: Option<&str>,
        tf2d: Option<&str>,
    ) -> PyResult<RenderParts> {
        let mut req: RenderRequest = errors::parse_request(py, "render option", request)?;
        single_frames(py, &req, "PreparedScene.render")?;
        req.scene.input = self.input.clone();
        req.scene.state_file = self.state_file.clone();
        memory_transfers(py, &mut req.scene, tf, tf2d)?;
        let renderer = &self.renderer;
        let (r, seconds) = job::run(py, job::callback(&progress), |p| {
            let (transfer, camera, mut settings) =
                build_view(&req.scene, &self.volume, req.samples)?;
            req.scene.accel.apply(&mut settings)?;
            let mut prepared = self.prepared.lock().unwrap_or_else(|e| e.into_inner());
            if !prepared.serves(&settings) {
                *prepared = renderer.prepare_volume(&self.volume, &transfer, &settings)?;
            }
            let t = std::time::Instant::now();
            let r = req
                .scene
                .accel
                .render_prepared(renderer, &prepared, &transfer, &camera, &settings, p)?;
            Ok((r, t.elapsed().as_secs_f64()))
        })?;
        output_parts(py, &r.output, frame_meta(renderer, &r, seconds))
    }

    /// The GPU session's counters as JSON (`null` on the CPU backends).
    fn session_stats(&self) -> String {
        let prepared = self.prepared.lock().unwrap_or_else(|e| e.into_inner());
        serde_json::to_string(&prepared.gpu_stats()).expect("counters serialise")
    }

    /// The prepared volume's shape `(nz, ny, nx)`.
    #[getter]
    fn shape(&self) -> (usize, usize, usize) {
        let d = self.volume.dims();
        (d[2], d[1], d[0])
    }
}

/// What a comparison returns: oracle image, GPU image, heat map, and the rest as JSON.
type CompareParts = (Py<PyAny>, Py<PyAny>, Py<PyAny>, String);

/// The compare job (`voxlab compare`) from a JSON [`CompareRequest`].
#[pyfunction]
#[pyo3(signature = (request, volume=None, affine=None, progress=None, tf=None, tf2d=None))]
fn compare(
    py: Python<'_>,
    request: &str,
    volume: Option<Bound<'_, PyAny>>,
    affine: Option<[[f64; 4]; 4]>,
    progress: Option<Bound<'_, PyAny>>,
    tf: Option<&str>,
    tf2d: Option<&str>,
) -> PyResult<CompareParts> {
    let mut req: CompareRequest = errors::parse_request(py, "compare option", request)?;
    let vol = volume
        .as_ref()
        .map(|v| (v, affine.unwrap_or(arrays::rows(glam::DMat4::IDENTITY))));
    memory_input(py, &mut req.scene, vol)?;
    memory_transfers(py, &mut req.scene, tf, tf2d)?;
    let c = job::run(py, job::callback(&progress), |p| {
        voxlab::jobs::compare::run(&req, p)
    })?;
    let heat = diff_heatmap(&c.cpu.image, &c.gpu.image, None);
    let meta = serde_json::json!({
        "stats": c.report.stats,
        "max_abs_rel": c.report.stats.max_abs_rel,
        "peak": c.report.stats.peak,
        "passed": c.report.passed,
        "message": c.report.message,
        "adapter": c.adapter,
        "cpu_seconds": c.cpu_seconds,
        "gpu_timings": c.gpu_timings,
        "samples": {"cpu": c.cpu.total_samples, "gpu": c.gpu.total_samples},
    });
    Ok((
        arrays::from_frame(py, &c.cpu.image)?,
        arrays::from_frame(py, &c.gpu.image)?,
        arrays::from_frame(py, &heat)?,
        meta.to_string(),
    ))
}

/// Two images of one shape compared with `metrics::check_parity`: the statistics and
/// the heat map.
#[pyfunction]
#[pyo3(signature = (oracle, port, max_abs=None, rmse=None))]
fn compare_images(
    py: Python<'_>,
    oracle: PyReadonlyArrayDyn<'_, f64>,
    port: PyReadonlyArrayDyn<'_, f64>,
    max_abs: Option<f64>,
    rmse: Option<f64>,
) -> PyResult<(Py<PyAny>, String)> {
    let a = arrays::frame(py, &oracle, "the oracle image")?;
    let b = arrays::frame(py, &port, "the image to check")?;
    let tol = Tolerance {
        max_abs: max_abs.unwrap_or(f64::INFINITY),
        rmse: rmse.unwrap_or(f64::INFINITY),
        ..Tolerance::NONE
    };
    let (report, heat) = job::run(py, None, |_| {
        let r = check_parity("compare", &a, &b, tol, None)?;
        Ok((r, diff_heatmap(&a, &b, None)))
    })?;
    let meta = serde_json::json!({
        "stats": report.stats,
        "max_abs_rel": report.stats.max_abs_rel,
        "peak": report.stats.peak,
        "passed": report.passed,
        "message": report.message,
    });
    Ok((arrays::from_frame(py, &heat)?, meta.to_string()))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    m.add_function(wrap_pyfunction!(compare_images, m)?)?;
    m.add_class::<Renderer>()?;
    m.add_class::<PreparedScene>()?;
    Ok(())
}
