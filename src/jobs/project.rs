//! `voxlab project`: forward projections of a phantom (exact line integrals, or
//! Joseph on a sampled grid) or of a volume file (Joseph), in a parallel
//! (scikit-image's `radon`) or cone-beam (RTK's circular) geometry. See
//! docs/projection.md; the projectors are [`crate::cpu::project`] and
//! [`crate::gpu::project`].

use super::input::VolumeInput;
use super::{Backend, Engine, Progress};
use crate::cpu::project::{project_phantom, project_volume, Grid, ProjectOptions};
use crate::ct::{Beam, Geometry, Projections};
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::io::projections::{
    geometry_path, read_angles_txt, write_geometry, write_projections, Layout,
};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

crate::choice_enum! {
    /// The beam.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum BeamKind: "beam" {
        /// scikit-image's radon, stacked along the rotation axis.
        Parallel = "parallel",
        /// RTK's circular geometry, flat detector.
        Cone = "cone",
    }
}

crate::choice_enum! {
    /// How line integrals are computed.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Method: "projection method" {
        /// Exact line integrals of the phantom (phantoms only).
        Analytic = "analytic",
        /// Joseph's method on the voxel grid.
        Joseph = "joseph",
    }
}

crate::choice_enum! {
    /// How the projections are laid out in the file.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum LayoutChoice: "layout" {
        /// skimage for a one-row parallel beam, else stack.
        Auto = "auto",
        /// (angle, row, col).
        Stack = "stack",
        /// (detector, angle), one row only.
        Skimage = "skimage",
    }
}

/// The `voxlab project` job.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ProjectRequest {
    /// A volume (placed as a patient: centred, its z axis on the rotation axis, its
    /// axial slices seen like scikit-image images) or `phantom:NAME[:N | :NX,NY,NZ]`.
    pub input: VolumeInput,
    pub beam: BeamKind,
    /// Number of projections, evenly spread over `range`.
    pub angles: usize,
    /// Angular range in degrees (`None`: 180 parallel, 360 cone).
    pub range: Option<f64>,
    /// A text file of angles in degrees, one per line; replaces `angles` and `range`.
    pub angles_file: Option<PathBuf>,
    /// A geometry file (voxlab's JSON, ASTRA's `proj_geom` JSON, RTK's XML;
    /// [`crate::io::projections::read_geometry_with`]); replaces `beam`, the angles and
    /// the distances. RTK's XML takes its detector from `cols`, `rows`, `du`, `dv`,
    /// centred as RTK centres it.
    pub geometry_file: Option<PathBuf>,
    /// Detector columns.
    pub cols: usize,
    /// Detector rows (`None`: 1 parallel, 256 cone).
    pub rows: Option<usize>,
    /// Detector column spacing in mm (`None`: 1 parallel, 1.5 cone).
    pub du: Option<f64>,
    /// Detector row spacing in mm (`None`: `du`).
    pub dv: Option<f64>,
    /// Cone beam: source–isocentre distance in mm (`None`: 1000).
    pub sid: Option<f64>,
    /// Cone beam: source–detector distance in mm (`None`: 1500).
    pub sdd: Option<f64>,
    /// `None`: analytic for phantoms, Joseph for files.
    pub method: Option<Method>,
    /// Who computes Joseph's method; the analytic method runs on the CPU in f64 only.
    pub backend: Backend,
    /// GPU Joseph only: the projector samples the grid through the texture unit (a 3-D
    /// texture, hardware trilinear filtering) instead of the exact interpolation
    /// written out in the shader ([`crate::gpu::plan::Sampling`]). Real GPUs round the
    /// filter weights to about 8 fractional bits (docs/parity.md).
    pub hardware_filtering: bool,
    pub layout: LayoutChoice,
}

impl Default for ProjectRequest {
    fn default() -> Self {
        ProjectRequest {
            input: VolumeInput::default(),
            beam: BeamKind::Parallel,
            angles: 180,
            range: None,
            angles_file: None,
            geometry_file: None,
            cols: 256,
            rows: None,
            du: None,
            dv: None,
            sid: None,
            sdd: None,
            method: None,
            backend: Backend::Cpu,
            hardware_filtering: false,
            layout: LayoutChoice::Auto,
        }
    }
}

/// The projections and how they were made.
#[derive(Clone, Debug)]
pub struct Projected {
    pub projections: Projections<f64>,
    pub geometry: Geometry,
    pub layout: Layout,
    /// The backend that computed them (never `Auto`): `Cpu` results are written in
    /// f64, the others in f32.
    pub backend: Backend,
    /// What was projected and how, for messages: `shepp-logan analytic, cpu f64`.
    pub what: String,
}

/// The geometry the request describes.
///
/// # Errors
/// Inconsistent or absurd geometry parameters.
pub fn geometry(a: &ProjectRequest) -> Result<Geometry> {
    let cone = a.beam == BeamKind::Cone;
    if let Some(file) = &a.geometry_file {
        if a.angles_file.is_some() || a.range.is_some() || a.sid.is_some() || a.sdd.is_some() {
            return Err(Error::invalid(
                "--geometry-file",
                "the geometry file gives the angles and distances (drop --angles-file, \
                 --range, --sid and --sdd)",
            ));
        }
        // RTK's XML holds no detector pixels: those of the request, centred as in RTK.
        let rows = a.rows.unwrap_or(256);
        let du = a.du.unwrap_or(1.5);
        let grid =
            crate::io::rtk_geometry::DetectorGrid::centred(a.cols, rows, du, a.dv.unwrap_or(du));
        return crate::io::projections::read_geometry_with(file, Some(&grid));
    }
    if !cone && (a.sid.is_some() || a.sdd.is_some()) {
        return Err(Error::invalid(
            "--sid/--sdd",
            "only a cone beam has a source (add --geometry cone)",
        ));
    }
    let angles_deg = match &a.angles_file {
        Some(f) => read_angles_txt(f)?,
        None => {
            if a.angles == 0 {
                return Err(Error::invalid("--angles", "must be at least 1"));
            }
            if a.angles > crate::ct::MAX_DETECTOR {
                return Err(Error::too_large(
                    "--angles",
                    format!("{} (at most {})", a.angles, crate::ct::MAX_DETECTOR),
                ));
            }
            let range = a.range.unwrap_or(if cone { 360.0 } else { 180.0 });
            if !range.is_finite() {
                return Err(Error::invalid("--range", "must be finite"));
            }
            Geometry::even_angles(a.angles, range)
        }
    };
    let rows = a.rows.unwrap_or(if cone { 256 } else { 1 });
    let du = a.du.unwrap_or(if cone { 1.5 } else { 1.0 });
    let dv = a.dv.unwrap_or(du);
    if cone {
        Geometry::cone_rtk(
            a.sid.unwrap_or(1000.0),
            a.sdd.unwrap_or(1500.0),
            a.cols,
            rows,
            du,
            dv,
            angles_deg,
        )
    } else {
        Geometry::parallel_stack(a.cols, rows, du, dv, angles_deg)
    }
}

/// How the GPU projector reads the grid: refuses hardware filtering off the GPU or
/// for the analytic method.
fn sampling(a: &ProjectRequest, method: Method) -> Result<crate::gpu::plan::Sampling> {
    use crate::gpu::plan::Sampling;
    if !a.hardware_filtering {
        return Ok(Sampling::Exact);
    }
    if method != Method::Joseph {
        return Err(Error::invalid(
            "--hardware-filtering",
            "samples the grid of Joseph's method: not for the analytic projection (add \
             --method joseph)",
        ));
    }
    if a.backend != Backend::Gpu {
        return Err(Error::invalid(
            "--hardware-filtering",
            "is the GPU's texture unit: give --backend gpu",
        ));
    }
    Ok(Sampling::Hardware)
}

/// A phantom and the grid it is sampled on.
type NamedPhantom = (crate::phantom::Phantom, [usize; 3]);

/// The phantom the input names (`phantom:SPEC`, with its grid size) and the method:
/// `analytic` for a phantom, `joseph` for a volume, unless the request says.
fn phantom_and_method(a: &ProjectRequest) -> Result<(Option<NamedPhantom>, Method)> {
    let phantom = match a.input.source.strip_prefix("phantom:") {
        Some(spec) if a.input.memory.is_none() => {
            Some(crate::phantom::parse_spec(spec, a.input.load.phantom_size)?)
        }
        _ => None,
    };
    let method = a.method.unwrap_or(if phantom.is_some() {
        Method::Analytic
    } else {
        Method::Joseph
    });
    Ok((phantom, method))
}

/// `voxlab project --dry-run`: the memory plan of [`run`] (host bytes, device bytes
/// against the planner's limits, the slabs the GPU projection would use) after
/// checking the geometry and reading the input's size, without projecting or writing.
///
/// # Errors
/// As [`run`] up to the work; [`Error::TooLarge`] for a job that cannot fit even
/// split.
pub fn plan(a: &ProjectRequest, progress: &dyn Progress) -> Result<super::plan::MemoryPlan> {
    let g = geometry(a)?;
    let (phantom, method) = phantom_and_method(a)?;
    let sampling = sampling(a, method)?;
    let values = (g.n_angles() * g.rows * g.cols) as u64;
    let plan = |backend: String, host: u64, device, split| super::plan::MemoryPlan {
        job: format!(
            "project {}",
            if method == Method::Analytic {
                "analytic"
            } else {
                "joseph"
            }
        ),
        backend,
        host_bytes: host,
        device,
        split,
        writes: Vec::new(),
    };
    if method == Method::Analytic {
        return Ok(plan("cpu f64".into(), values * 8, None, Vec::new()));
    }
    let dims = match &phantom {
        Some((_, dims)) => *dims,
        None => a.input.load(progress)?.dims(),
    };
    let voxels = dims.iter().product::<usize>() as u64;
    let engine = Engine::open(a.backend)?;
    Ok(match (engine.backend(), engine.gpu()) {
        (Backend::Gpu, Some(ctx)) => {
            ctx.require_filtering(sampling, wgpu::TextureFormat::R32Float)?;
            let p = crate::gpu::project::ProjectionPlan::sampled(&ctx.limits, &g, dims, sampling)?;
            let slab = p.slab_bytes(dims);
            let chunk = (p.views_per_dispatch * g.rows * g.cols * 4) as u64;
            let split = if p.is_split() {
                vec![p.describe()]
            } else {
                Vec::new()
            };
            // The f64 grid and one f32 slab (and, for a texture, the slab again inside
            // its zero border); the f32 projections and their f64 copy.
            let slab_host = match sampling {
                crate::gpu::plan::Sampling::Exact => slab,
                crate::gpu::plan::Sampling::Hardware => {
                    (p.slabs.per_piece * dims[0] * dims[1] * 4) as u64 + slab
                }
            };
            plan(
                format!("gpu ({})", ctx.summary.name),
                voxels * 8 + slab_host + values * 12,
                Some(super::plan::DevicePlan::on(
                    ctx,
                    p.device_bytes,
                    slab.max(chunk),
                )),
                split,
            )
        }
        (Backend::CpuF32, _) => plan(
            "cpu f32".into(),
            voxels * 12 + values * 12,
            None,
            Vec::new(),
        ),
        _ => plan("cpu f64".into(), voxels * 8 + values * 8, None, Vec::new()),
    })
}

/// Projects.
///
/// # Errors
/// Bad geometry or input; the analytic method on a file or off the CPU; GPU errors;
/// [`Error::Cancelled`] between views.
pub fn run(a: &ProjectRequest, progress: &dyn Progress) -> Result<Projected> {
    let g = geometry(a)?;
    let layout = match a.layout {
        LayoutChoice::Stack => Layout::Stack,
        LayoutChoice::Skimage => Layout::Skimage,
        LayoutChoice::Auto if g.beam == Beam::Parallel && g.rows == 1 => Layout::Skimage,
        LayoutChoice::Auto => Layout::Stack,
    };
    if layout == Layout::Skimage && g.rows != 1 {
        return Err(Error::invalid(
            "--layout skimage",
            format!("a (detector, angle) sinogram has one row, not {}", g.rows),
        ));
    }
    let (phantom, method) = phantom_and_method(a)?;
    let sampling = sampling(a, method)?;

    let views = g.n_angles();
    let done = std::sync::atomic::AtomicUsize::new(0);
    super::check_cancel(progress)?;
    progress.begin("projecting", "views", views as u64);
    let (what, p, backend): (String, Projections<f64>, Backend) =
        super::cancellable(progress, |cp| {
            let tick = || {
                cp.advance(
                    done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1,
                    views,
                )
            };
            let options = ProjectOptions {
                on_view: Some(&tick),
            };
            Ok(match method {
                Method::Analytic => {
                    let Some((ph, _)) = &phantom else {
                        return Err(Error::invalid(
                            "--method analytic",
                            "exact line integrals exist for phantoms only (phantom:NAME); use \
                     --method joseph for a volume file",
                        ));
                    };
                    if !matches!(a.backend, Backend::Cpu | Backend::Auto) {
                        return Err(Error::invalid(
                    "--backend",
                    "the analytic projection runs on the CPU in f64 only (drop --backend, or \
                     use --method joseph)",
                ));
                    }
                    let (_, dims) = phantom.as_ref().expect("a phantom");
                    let affine =
                        crate::cpu::project::phantom_to_ct_matrix() * ph.grid_affine(*dims);
                    if let Some(w) = g.check_source_outside(affine, *dims, "--sid", "the object")? {
                        progress.warn(&w);
                    }
                    let p = project_phantom(ph, &g)?;
                    (format!("{} analytic, cpu f64", ph.name), p, Backend::Cpu)
                }
                Method::Joseph => {
                    let (name, grid) = match &phantom {
                        Some((ph, dims)) => (
                            format!("{} {}×{}×{}", ph.name, dims[0], dims[1], dims[2]),
                            Grid::<f64>::phantom(ph, *dims)?,
                        ),
                        None => {
                            let vol = a.input.load(progress)?.to_f32();
                            (
                                a.input.source.clone(),
                                Grid::<f64>::from_volume_patient(&vol)?,
                            )
                        }
                    };
                    if let Some(w) =
                        g.check_source_outside(grid.affine, grid.dims, "--sid", "the object")?
                    {
                        progress.warn(&w);
                    }
                    let engine = Engine::open(a.backend)?;
                    match (engine.backend(), engine.gpu()) {
                        (Backend::Gpu, Some(ctx)) => {
                            let plan = crate::gpu::project::ProjectionPlan::sampled(
                                &ctx.limits,
                                &g,
                                grid.dims,
                                sampling,
                            )?;
                            if plan.is_split() {
                                progress.note(&plan.describe());
                            }
                            let p = crate::gpu::project::project_volume_planned(
                                ctx, &grid, &g, &options, &plan,
                            )?
                            .0;
                            let how = match sampling {
                                crate::gpu::plan::Sampling::Exact => "",
                                crate::gpu::plan::Sampling::Hardware => {
                                    ", grid filtered by the texture unit"
                                }
                            };
                            (
                                format!("{name} joseph, gpu ({}){how}", ctx.summary.name),
                                p.widen(),
                                Backend::Gpu,
                            )
                        }
                        (Backend::CpuF32, _) => {
                            let g32 = Grid::<f32>::new(
                                grid.dims,
                                grid.affine,
                                grid.data.iter().map(|&v| v as f32).collect(),
                            )?;
                            (
                                format!("{name} joseph, cpu f32"),
                                project_volume(&g32, &g, &options)?.widen(),
                                Backend::CpuF32,
                            )
                        }
                        _ => (
                            format!("{name} joseph, cpu f64"),
                            project_volume(&grid, &g, &options)?,
                            Backend::Cpu,
                        ),
                    }
                }
            })
        })?;
    progress.end(0.0);
    Ok(Projected {
        projections: p,
        geometry: g,
        layout,
        backend,
        what,
    })
}

impl Projected {
    /// Writes the projections to `out` (`.npy`: float64 from the f64 oracle, else
    /// float32; `.nrrd`/`.nhdr`: float32) and the geometry to
    /// `<out-stem>.geometry.json`; returns the geometry's path.
    ///
    /// # Errors
    /// An unsupported extension; I/O errors.
    pub fn write(&self, out: &Path) -> Result<PathBuf> {
        let p = &self.projections;
        if self.backend == Backend::Cpu {
            write_projections(out, p, self.layout, Some(&self.geometry))?;
        } else {
            write_projections(out, &p.narrow()?, self.layout, Some(&self.geometry))?;
        }
        let gpath = geometry_path(out);
        write_geometry(&gpath, &self.geometry)?;
        Ok(gpath)
    }

    /// The sinogram of the central detector row: detector down, angle across, as
    /// scikit-image examples show it.
    pub fn sinogram(&self) -> Frame {
        let p = &self.projections;
        let row = p.rows / 2;
        let mut f = Frame::new(p.angles, p.cols, 1);
        for a in 0..p.angles {
            for d in 0..p.cols {
                f.data[d * p.angles + a] = p.view(a)[row * p.cols + d];
            }
        }
        f
    }
}
