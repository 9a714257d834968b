//! `voxlab.fvr`, `voxlab.d2vr`, `voxlab.adaptive`, `voxlab.process` and
//! `voxlab.bench`: the fvr, d2vr, adaptive, process and bench jobs from JSON requests
//! (built from keyword arguments by the Python half), volumes in memory.

use crate::{arrays, errors, job};
use numpy::PyReadonlyArrayDyn;
use pyo3::prelude::*;
use voxlab::jobs::adaptive::AdaptiveRequest;
use voxlab::jobs::d2vr::D2vrRequest;
use voxlab::jobs::fvr::FvrRequest;
use voxlab::jobs::process::ProcessRequest;
use voxlab::volume::AnyVolume;

/// The fvr job (`voxlab fvr`): the X-ray image (value × mm, float32 `(h, w)`) and the
/// engine, described.
#[pyfunction]
#[pyo3(signature = (request, volume=None, affine=None, progress=None))]
fn fvr(
    py: Python<'_>,
    request: &str,
    volume: Option<Bound<'_, PyAny>>,
    affine: Option<[[f64; 4]; 4]>,
    progress: Option<Bound<'_, PyAny>>,
) -> PyResult<(Py<PyAny>, String)> {
    let mut req: FvrRequest = errors::parse_request(py, "fvr option", request)?;
    arrays::memory_input(py, &mut req.input, volume.as_ref(), affine)?;
    let r = job::run(py, job::callback(&progress), |p| {
        voxlab::jobs::fvr::run(&req, p)
    })?;
    Ok((arrays::from_frame(py, &r.frame)?, r.engine.describe()))
}

/// The projections `d2vr` renders from memory: the stack and its geometry JSON, given
/// both or neither.
pub(crate) type D2vrStack = Option<((usize, usize, usize, Vec<f64>), String)>;

/// [`D2vrStack`] from the arguments, checked in pairs.
pub(crate) fn d2vr_stack(
    py: Python<'_>,
    projections: Option<&PyReadonlyArrayDyn<'_, f64>>,
    geometry: Option<&str>,
) -> PyResult<D2vrStack> {
    match (projections, geometry) {
        (Some(p), Some(g)) => Ok(Some((crate::ct::projection_stack(py, p)?, g.to_string()))),
        (None, None) => Ok(None),
        _ => Err(errors::raise(
            py,
            "InvalidError",
            "invalid d2vr option `geometry`: projections in memory need their geometry, \
             and a geometry needs projections",
        )),
    }
}

/// The projections in memory put into the request (as `input = "projections"` unless it
/// names something else).
pub(crate) fn d2vr_memory(req: &mut D2vrRequest, stack: D2vrStack) -> voxlab::Result<()> {
    if let Some(((angles, rows, cols, data), g)) = stack {
        let g = voxlab::io::projections::geometry_from_json(&g, std::path::Path::new("geometry"))?;
        let proj = voxlab::ct::Projections::new(angles, rows, cols, data)?;
        req.memory = Some(std::sync::Arc::new((proj, g)));
        if req.input == D2vrRequest::default().input {
            req.input = "projections".into();
        }
    }
    Ok(())
}

/// The d2vr job (`voxlab d2vr`): the image (as the CLI's `.npy`), the samples-per-ray
/// image when the job made one, and the rest as JSON. `projections` (a float64
/// `(detector, angle)` sinogram or `(angle, row, col)` stack) with its `geometry`
/// JSON are rendered instead of the request's `input`.
#[pyfunction]
#[pyo3(signature = (request, progress=None, projections=None, geometry=None))]
fn d2vr(
    py: Python<'_>,
    request: &str,
    progress: Option<Bound<'_, PyAny>>,
    projections: Option<PyReadonlyArrayDyn<'_, f64>>,
    geometry: Option<&str>,
) -> PyResult<(Py<PyAny>, Option<Py<PyAny>>, String)> {
    let mut req: D2vrRequest = errors::parse_request(py, "d2vr option", request)?;
    let stack = d2vr_stack(py, projections.as_ref(), geometry)?;
    let r = job::run(py, job::callback(&progress), |p| {
        d2vr_memory(&mut req, stack)?;
        voxlab::jobs::d2vr::run(&req, p)
    })?;
    let image = arrays::from_frame(py, &r.render.image)?;
    let samples = match &r.render.samples {
        Some(s) => Some(arrays::from_frame(py, s)?),
        None => None,
    };
    let s = r.stats;
    let meta = serde_json::json!({
        "engine": r.engine.describe(),
        "backend": r.engine.backend().name(),
        "seconds": r.seconds,
        "total_samples": r.render.total_samples,
        "stats": {
            "box_samples": s.box_samples,
            "visited_samples": s.visited_samples,
            "value_reconstructions": s.value_reconstructions,
            "gradient_reconstructions": s.gradient_reconstructions,
            "fraction": s.fraction(),
        },
    });
    Ok((image, samples, meta.to_string()))
}

/// What `adaptive` returns: the report (JSON, as `table.json`), the report as
/// markdown (`table.md`), and per sampling its name, image and samples image.
type AdaptiveParts = (
    String,
    String,
    Vec<(String, Py<PyAny>, Option<Py<PyAny>>)>,
    f64,
);

/// The adaptive job (`voxlab adaptive`): regular, direct and spectral adaptive
/// sampling of one scene, with the report and every sampling's last render.
#[pyfunction]
#[pyo3(signature = (request, volume=None, affine=None, progress=None))]
fn adaptive(
    py: Python<'_>,
    request: &str,
    volume: Option<Bound<'_, PyAny>>,
    affine: Option<[[f64; 4]; 4]>,
    progress: Option<Bound<'_, PyAny>>,
) -> PyResult<AdaptiveParts> {
    let mut req: AdaptiveRequest = errors::parse_request(py, "adaptive option", request)?;
    arrays::memory_input(py, &mut req.input, volume.as_ref(), affine)?;
    let c = job::run(py, job::callback(&progress), |p| {
        voxlab::jobs::adaptive::run(&req, p)
    })?;
    let report = serde_json::to_string(&c.report)
        .map_err(|e| errors::raise(py, "InternalError", &e.to_string()))?;
    let md = voxlab::jobs::adaptive::markdown(&c.report);
    let mut outs = Vec::new();
    for (s, o) in &c.outputs {
        let name = s.name().to_string();
        let img = arrays::from_frame(py, &o.image)?;
        let smp = match &o.samples {
            Some(f) => Some(arrays::from_frame(py, f)?),
            None => None,
        };
        outs.push((name, img, smp));
    }
    Ok((report, md, outs, c.max_count))
}

/// The process job (`voxlab process`): the float32 `(nz, ny, nx)` result, its
/// voxel-to-world affine (rows) and the rest as JSON.
#[pyfunction]
#[pyo3(signature = (request, volume=None, affine=None, progress=None))]
fn process(
    py: Python<'_>,
    request: &str,
    volume: Option<Bound<'_, PyAny>>,
    affine: Option<[[f64; 4]; 4]>,
    progress: Option<Bound<'_, PyAny>>,
) -> PyResult<(Py<PyAny>, [[f64; 4]; 4], String)> {
    let mut req: ProcessRequest = errors::parse_request(py, "process option", request)?;
    arrays::memory_input(py, &mut req.input, volume.as_ref(), affine)?;
    let r = job::run(py, job::callback(&progress), |p| {
        voxlab::jobs::process::run(&req, p)
    })?;
    let meta = serde_json::json!({
        "what": r.what,
        "seconds": r.seconds,
        "engine": r.engine.describe(),
        "backend": r.engine.backend().name(),
    });
    let aff = arrays::rows(r.volume.affine());
    let arr = arrays::from_volume(py, AnyVolume::F32(r.volume))?;
    Ok((arr, aff, meta.to_string()))
}

/// The bench job (`voxlab bench`): runs the suite, writes its reports into the
/// request's `out`, and returns the report (JSON, as `<name>.json`), the files written
/// and the problems (parity failures, errors).
#[pyfunction]
#[pyo3(name = "bench", signature = (request, progress=None))]
fn bench_suite(
    py: Python<'_>,
    request: &str,
    progress: Option<Bound<'_, PyAny>>,
) -> PyResult<(String, Vec<String>, Vec<String>)> {
    let req: voxlab::bench::job::BenchRequest = errors::parse_request(py, "bench option", request)?;
    let r = job::run(py, job::callback(&progress), |p| {
        voxlab::bench::job::run(&req, &|_| {}, p)
    })?;
    let report = serde_json::to_string(&r.report)
        .map_err(|e| errors::raise(py, "InternalError", &e.to_string()))?;
    let paths = r.paths.iter().map(|p| p.display().to_string()).collect();
    Ok((report, paths, r.problems))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(fvr, m)?)?;
    m.add_function(wrap_pyfunction!(d2vr, m)?)?;
    m.add_function(wrap_pyfunction!(adaptive, m)?)?;
    m.add_function(wrap_pyfunction!(process, m)?)?;
    m.add_function(wrap_pyfunction!(bench_suite, m)?)?;
    Ok(())
}
