//! `voxlab._voxlab.plan`: a job's memory plan (`dry_run=True` in the Python half, the
//! command line's `--dry-run`), from the same request and in-memory inputs its run
//! takes. The library's `plan` functions check everything the run checks before the
//! work, so a dry run refuses what the run refuses, with the same error.

use crate::{ct, errors, job, jobs, render};
use numpy::PyReadonlyArrayDyn;
use pyo3::prelude::*;
use voxlab::jobs::plan::MemoryPlan;

/// The plan as JSON: [`MemoryPlan`]'s fields and `text`, what `--dry-run` prints.
fn plan_json(plan: &MemoryPlan) -> String {
    let mut v = serde_json::to_value(plan).expect("a plan serialises");
    v["text"] = plan.describe().into();
    v.to_string()
}

/// The memory plan of `job` (`render`, `compare`, `project`, `reconstruct`, `fvr`,
/// `d2vr`, `adaptive` or `process`) for its JSON `request`, as JSON (one plan; two,
/// the CPU render's then the GPU's, for `compare`). The volume in memory goes with
/// `volume`/`affine` (and the transfer functions with `tf`/`tf2d`) as in the jobs'
/// own functions; `projections` with `geometry` are `reconstruct`'s input (with its
/// `flat` and `dark` fields) and `d2vr`'s projections in memory.
#[pyfunction]
#[pyo3(signature = (
    job, request, volume=None, affine=None, progress=None, tf=None, tf2d=None,
    projections=None, geometry=None, flat=None, dark=None
))]
#[allow(clippy::too_many_arguments)]
fn plan(
    py: Python<'_>,
    job: &str,
    request: &str,
    volume: Option<Bound<'_, PyAny>>,
    affine: Option<[[f64; 4]; 4]>,
    progress: Option<Bound<'_, PyAny>>,
    tf: Option<&str>,
    tf2d: Option<&str>,
    projections: Option<PyReadonlyArrayDyn<'_, f64>>,
    geometry: Option<&str>,
    flat: Option<Bound<'_, PyAny>>,
    dark: Option<Bound<'_, PyAny>>,
) -> PyResult<Vec<String>> {
    let what = format!("{job} option");
    let identity = || crate::arrays::rows(glam::DMat4::IDENTITY);
    let scene_volume = volume
        .as_ref()
        .map(|v| (v, affine.unwrap_or_else(identity)));
    let progress = job::callback(&progress);
    let plans: Vec<MemoryPlan> = match job {
        "render" => {
            let mut req: voxlab::jobs::render::RenderRequest =
                errors::parse_request(py, &what, request)?;
            render::memory_input(py, &mut req.scene, scene_volume)?;
            render::memory_transfers(py, &mut req.scene, tf, tf2d)?;
            vec![job::run(py, progress, |p| {
                voxlab::jobs::render::plan(&req, p)
            })?]
        }
        "compare" => {
            let mut req: voxlab::jobs::compare::CompareRequest =
                errors::parse_request(py, &what, request)?;
            render::memory_input(py, &mut req.scene, scene_volume)?;
            render::memory_transfers(py, &mut req.scene, tf, tf2d)?;
            job::run(py, progress, |p| voxlab::jobs::compare::plan(&req, p))?.to_vec()
        }
        "project" => {
            let mut req: voxlab::jobs::project::ProjectRequest =
                errors::parse_request(py, &what, request)?;
            crate::arrays::memory_input(py, &mut req.input, volume.as_ref(), affine)?;
            vec![job::run(py, progress, |p| {
                voxlab::jobs::project::plan(&req, p)
            })?]
        }
        "reconstruct" => {
            let req: voxlab::jobs::reconstruct::ReconstructRequest =
                errors::parse_request(py, &what, request)?;
            let (Some(stack), Some(g)) = (&projections, geometry) else {
                return Err(errors::raise(
                    py,
                    "InvalidError",
                    "invalid reconstruct option: the plan of projections in memory needs \
                     them and their geometry",
                ));
            };
            let input = ct::StackInput::new(py, stack, g, flat, dark)?;
            vec![job::run(py, progress, |p| {
                let (proj, g, _) = input.line_integrals()?;
                voxlab::jobs::reconstruct::plan_of(&req, proj, g, p)
            })?]
        }
        "fvr" => {
            let mut req: voxlab::jobs::fvr::FvrRequest = errors::parse_request(py, &what, request)?;
            crate::arrays::memory_input(py, &mut req.input, volume.as_ref(), affine)?;
            vec![job::run(py, progress, |p| {
                voxlab::jobs::fvr::plan(&req, p)
            })?]
        }
        "d2vr" => {
            let mut req: voxlab::jobs::d2vr::D2vrRequest =
                errors::parse_request(py, &what, request)?;
            let stack = jobs::d2vr_stack(py, projections.as_ref(), geometry)?;
            vec![job::run(py, progress, |_| {
                jobs::d2vr_memory(&mut req, stack)?;
                voxlab::jobs::d2vr::plan(&req)
            })?]
        }
        "adaptive" => {
            let mut req: voxlab::jobs::adaptive::AdaptiveRequest =
                errors::parse_request(py, &what, request)?;
            crate::arrays::memory_input(py, &mut req.input, volume.as_ref(), affine)?;
            vec![job::run(py, progress, |p| {
                voxlab::jobs::adaptive::plan(&req, p)
            })?]
        }
        "process" => {
            let mut req: voxlab::jobs::process::ProcessRequest =
                errors::parse_request(py, &what, request)?;
            crate::arrays::memory_input(py, &mut req.input, volume.as_ref(), affine)?;
            vec![job::run(py, progress, |p| {
                voxlab::jobs::process::plan(&req, p)
            })?]
        }
        other => {
            return Err(errors::raise(
                py,
                "InvalidError",
                &format!(
                    "no memory plan for the job '{other}': render, compare, project, \
                     reconstruct, fvr, d2vr, adaptive or process"
                ),
            ))
        }
    };
    Ok(plans.iter().map(plan_json).collect())
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(plan, m)?)?;
    Ok(())
}
