//! `voxlab render`: ray casting, from a [`Scene`] or from a request.
//!
//! Two levels:
//! - [`render`] / [`Renderer`] (from [`super::renderer`], re-exported here): a
//!   [`Scene`] and [`RenderSettings`] on a [`Backend`].
//! - [`run`]: the whole `voxlab render` job from a [`RenderRequest`] — load the
//!   input, build the transfer function, camera and settings ([`build_scene`]), then
//!   one frame, the median of repeated frames, jittered frames averaged, a stereo pair,
//!   several volumes or the adaptive caster, with timings and sample counts.

use super::input::{volume_center, VolumeInput};
pub use super::renderer::{render, render_with_progress, PreparedScene, Rendered, Renderer, Scene};
use super::stereo::StereoLayout;
pub use super::Backend;
use super::{cancellable, check_cancel, since, Engine, Progress};
use crate::camera::{AxisView, Camera, Orbit, Projection};
use crate::cpu::adaptive::Sampling;
use crate::cpu::raycast::RenderOutput;
use crate::error::{Error, Result};
use crate::gpu::raycast::{GpuTimings, SessionStats};
use crate::settings::{
    Classification, ClipMeshUnits, ClipSpace, Compositing, Filter, GradientMethod, IsoSurface,
    Light, Mode, RenderSettings,
};
use crate::transfer::{TransferFunction, WindowMap};
use crate::transfer2d::{GradientAxis, TransferFunction2D};
use crate::volume::AnyVolume;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use std::time::Instant;

/// Where the camera looks from: an axis view, or an orbit around the volume.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ViewRequest {
    /// Axis-aligned orthographic view `+x`, `-x`, `+y`, `-y`, `+z`, `-z` (rays along
    /// that index axis; the image is laid out like NumPy's reduction over that axis).
    /// `None`: the orbit view.
    pub axis: Option<String>,
    /// Orbit view: rotation about world +z in degrees (0 looks along +y).
    pub azimuth: f64,
    /// Orbit view: degrees above the xy-plane.
    pub elevation: f64,
}

impl Default for ViewRequest {
    fn default() -> Self {
        ViewRequest {
            axis: None,
            azimuth: 30.0,
            elevation: 20.0,
        }
    }
}

/// Empty-space skipping, clipping and jittered sampling (docs/acceleration.md); each
/// field left `None`/`false` keeps the settings' value.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AccelRequest {
    /// Skip cells the transfer function leaves transparent (the image does not change).
    pub skip_empty: Option<bool>,
    /// Edge of one skipping cell in voxels.
    pub block_size: Option<usize>,
    /// Restrict rays to the box `x0, y0, z0, x1, y1, z1` (∩ the volume) in `clip_space`.
    pub clip_box: Option<[f64; 6]>,
    pub clip_space: ClipSpace,
    /// Offset every ray's start by a random fraction of a step from this seed.
    pub jitter: Option<u32>,
    /// Average this many jittered frames (seeds `jitter` …, default 0).
    pub accumulate: Option<usize>,
    /// Offset ray starts by the 4×4 ordered pattern (interleaved sampling).
    pub interleaved: bool,
    /// Clip to a closed triangle mesh (a `.obj`/`.ply` file), or `bricks`: the
    /// non-empty skipping cells.
    pub clip_mesh: Option<String>,
    /// Units of the mesh file's vertices.
    pub clip_mesh_units: ClipMeshUnits,
}

impl AccelRequest {
    /// Writes the fields given into `s` (reading a mesh file), then validates `s`.
    ///
    /// # Errors
    /// The mesh reader's errors; `accumulate` with `interleaved`; invalid settings.
    pub fn apply(&self, s: &mut RenderSettings) -> Result<()> {
        if let Some(v) = self.skip_empty {
            s.skip_empty = v;
        }
        if let Some(b) = self.block_size {
            s.block_size = b;
        }
        if let Some(c) = self.clip_box {
            s.clip_box = Some(crate::settings::ClipBox {
                lo: [c[0], c[1], c[2]],
                hi: [c[3], c[4], c[5]],
                space: self.clip_space,
            });
        }
        if self.jitter.is_some() {
            s.jitter = self.jitter;
        }
        if self.interleaved {
            s.interleaved = true;
        }
        if let Some(m) = &self.clip_mesh {
            s.clip_mesh = Some(if m == "bricks" {
                crate::settings::ClipMesh::Bricks
            } else {
                crate::settings::ClipMesh::Mesh {
                    mesh: std::sync::Arc::new(crate::io::mesh::read_mesh(std::path::Path::new(m))?),
                    units: self.clip_mesh_units,
                }
            });
        }
        if self.accumulate.is_some() && s.interleaved {
            return Err(Error::invalid(
                "--accumulate",
                "averages jittered frames; it excludes --interleaved",
            ));
        }
        s.validate()
    }

    /// Renders one frame, or the average of `accumulate` jittered frames (reporting
    /// frames done).
    pub fn render(
        &self,
        renderer: &Renderer,
        scene: &Scene,
        settings: &RenderSettings,
        progress: &dyn Progress,
    ) -> Result<Rendered> {
        cancellable(progress, |cp| match self.accumulate {
            Some(n) => super::accumulate::render_accumulated(
                renderer,
                scene,
                settings,
                settings.jitter.unwrap_or(0),
                n,
                &|done, total| cp.advance(done, total),
            ),
            None => renderer.render(scene, settings, &|done, total| cp.advance(done, total)),
        })
    }
}

impl AccelRequest {
    /// [`AccelRequest::render`] of a prepared scene with `tf` and `camera`: one frame,
    /// or the average of `accumulate` jittered frames, from the volume prepared once.
    #[allow(clippy::too_many_arguments)]
    pub fn render_prepared(
        &self,
        renderer: &Renderer,
        prepared: &PreparedScene,
        tf: &TransferFunction,
        camera: &Camera,
        settings: &RenderSettings,
        progress: &dyn Progress,
    ) -> Result<Rendered> {
        cancellable(progress, |cp| match self.accumulate {
            Some(n) => super::accumulate::render_accumulated_prepared(
                renderer,
                prepared,
                tf,
                camera,
                settings,
                settings.jitter.unwrap_or(0),
                n,
                &|done, total| cp.advance(done, total),
            ),
            None => {
                renderer.render_prepared_with(prepared, tf, camera, settings, &|done, total| {
                    cp.advance(done, total)
                })
            }
        })
    }
}

/// What to render and how: the scene part of `voxlab render` and `voxlab compare`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SceneRequest {
    pub input: VolumeInput,
    /// What rays compute.
    pub mode: Mode,
    /// Transfer function: a preset name, a JSON file, or `auto` (the `phantom` preset
    /// for phantoms; for files, a soft grayscale ramp over the volume's value range).
    pub tf: String,
    /// A 2D transfer function over (value, gradient magnitude): a JSON file of widgets
    /// or a 2D preset name.
    pub tf2d: Option<String>,
    /// A named preset, 1D or 2D (replaces `tf`, or sets `tf2d`).
    pub tf_preset: Option<String>,
    /// The 2D transfer function's gradient axis (overrides its JSON's).
    pub gradient_axis: Option<GradientAxis>,
    /// Faux shading exponent k: colours become c·(α/α_max)^k.
    pub faux_shading: Option<f64>,
    /// `[width, centre]` in raw data units: the grey window of MIP and MinIP, else the
    /// interval mapped onto the transfer function's domain.
    pub window: Option<[f64; 2]>,
    /// A named CT window (brain, subdural, abdomen, liver, lung, bone), used like
    /// `window`.
    pub window_preset: Option<String>,
    /// MIDA's γ in [-1, 1].
    pub mida_gamma: f64,
    /// Iso-surfaces (up to 4), drawn by `iso` and with DVR.
    pub iso: Vec<IsoSurface>,
    /// The first iso-surface crossing ends the ray.
    pub iso_opaque: bool,
    /// Binary shadows on opaque iso-surfaces.
    pub shadows: bool,
    /// Refine iso-surface hits by linear interpolation between two samples.
    pub iso_refine: bool,
    pub view: ViewRequest,
    /// Orbit camera: distance from the volume centre in mm (`None`: fit the volume).
    pub distance: Option<f64>,
    /// Orthographic instead of perspective projection for the orbit camera.
    pub ortho: bool,
    /// Perspective vertical field of view in degrees.
    pub fov: f64,
    /// Image size in pixels (default 256, or the cross-section for an axis view).
    pub width: Option<usize>,
    pub height: Option<usize>,
    pub filter: Filter,
    /// Step along rays in voxels.
    pub step: f64,
    pub classification: Classification,
    pub compositing: Compositing,
    /// Early ray termination threshold (1 = off).
    pub ert: f64,
    pub gradient: GradientMethod,
    pub precompute_gradients: bool,
    /// Phong shading on.
    pub shading: bool,
    /// Directional light (world, toward the light); `None`: a headlight.
    pub light: Option<[f64; 3]>,
    /// Background RGBA in [0, 1] for DVR.
    pub background: [f64; 4],
    /// Render settings from a JSON file instead of the fields above (the fields of
    /// [`RenderSettings`]).
    pub settings_file: Option<PathBuf>,
    /// A view state of the lab (`voxlab view --save-state`, [`super::view::ViewState`]):
    /// its input, camera, image size, settings and transfer functions replace every
    /// field above (`accel` still applies to it).
    pub state_file: Option<PathBuf>,
    /// GPU only: trilinear filtering by the texture unit.
    pub hardware_filtering: bool,
    pub accel: AccelRequest,
    /// A transfer function given in memory (the Python package, the lab), used instead
    /// of `tf` (but not of `tf_preset`, `faux_shading` and `window`, which apply to it).
    #[serde(skip)]
    pub transfer: Option<TransferFunction>,
    /// A 2D transfer function given in memory, used instead of `tf2d`.
    #[serde(skip)]
    pub transfer_2d: Option<TransferFunction2D>,
}

impl Default for SceneRequest {
    fn default() -> Self {
        SceneRequest {
            input: VolumeInput::default(),
            mode: Mode::Dvr,
            tf: "auto".into(),
            tf2d: None,
            tf_preset: None,
            gradient_axis: None,
            faux_shading: None,
            window: None,
            window_preset: None,
            mida_gamma: 0.0,
            iso: Vec::new(),
            iso_opaque: false,
            shadows: false,
            iso_refine: true,
            view: ViewRequest::default(),
            distance: None,
            ortho: false,
            fov: 30.0,
            width: None,
            height: None,
            filter: Filter::Trilinear,
            step: 0.5,
            classification: Classification::Post,
            compositing: Compositing::FrontToBack,
            ert: 0.99,
            gradient: GradientMethod::Central,
            precompute_gradients: false,
            shading: true,
            light: None,
            background: [0.0, 0.0, 0.0, 1.0],
            settings_file: None,
            state_file: None,
            hardware_filtering: false,
            accel: AccelRequest::default(),
            transfer: None,
            transfer_2d: None,
        }
    }
}

/// The window `[width, centre]` of a request: `window_preset` or `window`, checked.
fn window_of(a: &SceneRequest) -> Result<Option<[f64; 2]>> {
    if let Some(name) = &a.window_preset {
        if a.window.is_some() {
            return Err(Error::invalid(
                "--window-preset",
                "give a window preset or a window, not both",
            ));
        }
        return crate::cpu::modes::window_preset(name).map(Some);
    }
    let Some([w, c]) = a.window else {
        return Ok(None);
    };
    if !(w.is_finite() && w > 0.0 && c.is_finite()) {
        return Err(Error::invalid(
            "--window",
            format!("width {w} must be finite and positive, centre {c} finite"),
        ));
    }
    Ok(Some([w, c]))
}

/// Loads the input and builds the scene (volume, transfer function, camera) and the
/// settings (with sample counts when `sample_count`), checked; not yet the
/// acceleration fields ([`AccelRequest::apply`]).
///
/// # Errors
/// Whatever the input, the transfer functions, the camera or the settings refuse.
pub fn build_scene(
    a: &SceneRequest,
    sample_count: bool,
    progress: &dyn Progress,
) -> Result<(Scene, RenderSettings)> {
    let (volume, (transfer, camera, settings)) = match &a.state_file {
        Some(path) => {
            let state = super::view::ViewState::load(path)?;
            let volume = state.input.load(progress)?;
            (volume, state_view(&state, sample_count)?)
        }
        None => {
            let volume = a.input.load(progress)?;
            let view = build_view(a, &volume, sample_count)?;
            (volume, view)
        }
    };
    let scene = Scene {
        volume,
        transfer,
        camera,
    };
    Ok((scene, settings))
}

/// The transfer function, camera and settings of a view state file.
fn state_view(
    state: &super::view::ViewState,
    sample_count: bool,
) -> Result<(TransferFunction, Camera, RenderSettings)> {
    state.validate()?;
    let mut settings = state.settings.clone();
    settings.sample_count = sample_count;
    Ok((state.transfer.clone(), state.camera()?, settings))
}

/// [`build_scene`] for a volume already loaded from `a.input` (a prepared scene's
/// frames): the transfer function, camera and settings, checked. With `state_file`
/// they are the state's (whose input is then the volume's source).
///
/// # Errors
/// Whatever the transfer functions, the camera or the settings refuse.
pub fn build_view(
    a: &SceneRequest,
    volume: &AnyVolume,
    sample_count: bool,
) -> Result<(TransferFunction, Camera, RenderSettings)> {
    if let Some(path) = &a.state_file {
        return state_view(&super::view::ViewState::load(path)?, sample_count);
    }
    let range = || {
        let r = volume.value_range();
        (r.min, r.max)
    };
    build_view_for(a, volume.dims(), volume.affine(), range, sample_count)
}

/// [`build_view`] (without a state file) for a grid of `dims` placed by `affine`,
/// whose value range `range` gives when `--tf auto` asks for it: a volume no process
/// holds whole (`jobs::distributed_render`).
///
/// # Errors
/// Whatever the transfer functions, the camera or the settings refuse.
pub fn build_view_for(
    a: &SceneRequest,
    dims: [usize; 3],
    affine: glam::DMat4,
    range: impl FnOnce() -> (f64, f64),
    sample_count: bool,
) -> Result<(TransferFunction, Camera, RenderSettings)> {
    let mut tf = if let Some(t) = &a.transfer {
        t.validate()?;
        t.clone()
    } else if a.tf == "auto" {
        super::input::auto_transfer_for(&a.input, range)?
    } else {
        TransferFunction::preset_or_file(&a.tf)?
    };
    let mut tf2d = match (&a.transfer_2d, &a.tf2d) {
        (Some(t), _) => {
            t.validate()?;
            Some(t.clone())
        }
        (None, Some(spec)) => Some(TransferFunction2D::preset_or_file(spec)?),
        (None, None) => None,
    };
    if let Some(name) = &a.tf_preset {
        if crate::transfer2d::PRESETS_2D.iter().any(|(n, _)| n == name) {
            tf2d = Some(TransferFunction2D::preset(name)?);
        } else {
            tf = TransferFunction::preset(name).map_err(|_| {
                let mut names: Vec<&str> =
                    crate::transfer::PRESETS.iter().map(|(n, _)| *n).collect();
                names.extend(crate::transfer2d::PRESETS_2D.iter().map(|(n, _)| *n));
                Error::invalid(
                    "--tf-preset",
                    format!("'{name}' is not one of {}", names.join(", ")),
                )
            })?;
        }
    }
    if let Some(axis) = a.gradient_axis {
        match tf2d.as_mut() {
            Some(t) => t.gradient_axis = axis,
            None => {
                return Err(Error::invalid(
                    "--gradient-axis",
                    "needs a 2D transfer function (--tf2d or a 2D --tf-preset)",
                ))
            }
        }
    }
    if let Some(k) = a.faux_shading {
        tf.faux_shading = Some(k);
        if let Some(t) = tf2d.as_mut() {
            t.faux_shading = Some(k);
        }
        tf.validate()?;
    }
    let window = window_of(a)?;
    let grey_window = matches!(a.mode, Mode::Mip | Mode::Minip);
    if let (Some([w, l]), false) = (window, grey_window) {
        tf.window = WindowMap::from_window_level(w, l, tf.domain)?;
        if let Some(t) = tf2d.as_mut() {
            t.window = WindowMap::from_window_level(w, l, t.domain)?;
        }
    }
    let camera = scene_camera(a, dims, affine)?;
    let mut settings = match &a.settings_file {
        Some(p) => crate::json::read_file::<RenderSettings>(p, "render settings JSON")?,
        None => {
            let mut s = RenderSettings {
                mode: a.mode,
                filter: a.filter,
                step: a.step,
                classification: a.classification,
                compositing: a.compositing,
                ert_threshold: a.ert,
                gradient: a.gradient,
                precompute_gradients: a.precompute_gradients,
                background: a.background,
                sample_count,
                hardware_filtering: a.hardware_filtering,
                ..RenderSettings::default()
            };
            s.shading.enabled = a.shading;
            s.mida_gamma = a.mida_gamma;
            s.window = window.filter(|_| grey_window);
            s.iso_surfaces = a.iso.clone();
            s.iso_opaque = a.iso_opaque;
            s.iso_shadows = a.shadows;
            s.iso_refine = a.iso_refine;
            if let Some(l) = a.light {
                s.shading.light = Light::Direction(l);
            }
            s
        }
    };
    if tf2d.is_some() {
        settings.transfer_2d = tf2d;
    }
    settings.validate()?;
    Ok((tf, camera, settings))
}

/// The camera of a request for `volume`: the axis view, or the orbit around the
/// volume's centre.
fn scene_camera(a: &SceneRequest, dims: [usize; 3], affine: glam::DMat4) -> Result<Camera> {
    match &a.view.axis {
        Some(v) => {
            let view: AxisView = v.parse()?;
            let (ca, ra) = view.image_axes();
            Camera::axis_view(
                dims,
                affine,
                view,
                a.width.unwrap_or(dims[ca]),
                a.height.unwrap_or(dims[ra]),
            )
        }
        None => {
            let projection = if a.ortho {
                Projection::Orthographic {
                    width_mm: 0.0,
                    height_mm: 0.0,
                }
            } else {
                Projection::Perspective { fov_y_deg: a.fov }
            };
            let orbit = Orbit {
                azimuth_deg: a.view.azimuth,
                elevation_deg: a.view.elevation,
                distance_mm: a.distance,
            };
            Camera::orbit(
                super::input::grid_center(dims, affine),
                super::input::grid_extent(dims, affine),
                orbit,
                projection,
                a.width.unwrap_or(256),
                a.height.unwrap_or(256),
            )
        }
    }
}

/// A stereo pair (parallel eyes, off-axis frusta; docs/stereo.md).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StereoRequest {
    pub layout: StereoLayout,
    /// Distance between the eyes in mm.
    pub eye_separation: f64,
    /// Distance of the zero-parallax plane in mm (`None`: the eye's distance to the
    /// volume centre).
    pub convergence: Option<f64>,
}

impl Default for StereoRequest {
    fn default() -> Self {
        StereoRequest {
            layout: StereoLayout::Anaglyph,
            eye_separation: 65.0,
            convergence: None,
        }
    }
}

/// An extra volume rendered with the input in one image (docs/multi-volume.md).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExtraVolume {
    /// A file or `phantom:NAME[:N]` (read with the input's load options).
    pub input: String,
    /// Row-major 3×4 matrix from the volume's own world frame (mm) into the input's
    /// world (last column: translation in mm); `None`: the identity.
    #[serde(default)]
    pub transform: Option<[f64; 12]>,
    /// Its transfer function (a preset name or a JSON file); `None`: the input's.
    #[serde(default)]
    pub tf: Option<String>,
}

/// The `voxlab render` job.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RenderRequest {
    pub scene: SceneRequest,
    pub backend: Backend,
    /// Also return the samples-per-ray image.
    pub samples: bool,
    /// The pre-integrated caster of docs/adaptive-sampling.md, its samples placed
    /// regularly, adaptively or directly (DVR only, no shading).
    pub sampling: Option<Sampling>,
    pub stereo: Option<StereoRequest>,
    /// Render the frame this many times (1 … 1000) with the volume prepared once, and
    /// report the median time per frame.
    pub repeat: Option<u32>,
    /// Volumes rendered together with the input (at most 2).
    pub volumes: Vec<ExtraVolume>,
}

/// Per-frame timing of a repeated render.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FrameTimes {
    /// The median seconds per frame.
    pub median: f64,
    pub frames: usize,
    /// Seconds spent preparing the volume once.
    pub prepare: f64,
    /// GPU only: the session's counters after the last frame (one volume upload for
    /// all frames).
    pub gpu_session: Option<SessionStats>,
    /// GPU only: the host-to-device upload seconds of each frame (the first carries the
    /// volume's upload; frames that upload nothing report 0).
    pub gpu_uploads: Vec<f64>,
    /// GPU only: the median seconds of the frames' ray casting on the device (timestamp
    /// queries; without them, the waited dispatches' wall clock), and whether it came
    /// from timestamps.
    pub gpu_kernel_median: Option<f64>,
    pub gpu_kernel_from_timestamps: bool,
}

/// How a stereo pair was made.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct StereoInfo {
    pub layout: StereoLayout,
    pub eye_separation: f64,
    /// Columns each eye's frustum is shifted by.
    pub shift_px: usize,
    /// Distance of the zero-parallax plane (mm).
    pub convergence_mm: f64,
}

/// What a render job returns.
#[derive(Clone, Debug)]
pub struct Rendering {
    /// The image (a stereo pair: the combined image), the samples-per-ray image when
    /// asked for, and the sample count.
    pub output: RenderOutput,
    /// Who computed it.
    pub engine: Engine,
    /// Seconds of rendering (end to end after loading; the median frame for
    /// `repeat`).
    pub seconds: f64,
    pub gpu_timings: Option<GpuTimings>,
    pub frames: Option<FrameTimes>,
    pub stereo: Option<StereoInfo>,
    /// Volumes rendered (1 unless extra volumes were given).
    pub volumes: usize,
    pub sampling: Option<Sampling>,
    /// The settings and the camera used.
    pub settings: RenderSettings,
    pub camera: Camera,
}

/// `--repeat`: 1 … 1000 frames of the single-volume caster.
fn check_repeat(req: &RenderRequest) -> Result<()> {
    if req.repeat.is_some()
        && (!req.volumes.is_empty() || req.sampling.is_some() || req.stereo.is_some())
    {
        return Err(Error::invalid(
            "--repeat",
            "times the single-volume caster; it excludes --stereo, --sampling and extra volumes",
        ));
    }
    match req.repeat {
        Some(n) if !(1..=1000).contains(&n) => Err(Error::invalid(
            "--repeat",
            format!("{n} is not in 1 … 1000"),
        )),
        _ => Ok(()),
    }
}

/// `voxlab render --dry-run`: what [`run`] would hold and how it would split, after
/// loading the input (for its size) and checking the request, rendering nothing. The
/// host side is the volume in the working precision and the image; the device side
/// (GPU) the volume's textures that a frame reads (or the largest brick's, past the 3-D
/// texture limit or the device memory: [`crate::gpu::raycast::volume_split`]; see
/// [`crate::gpu::raycast::texture_bytes_per_voxel`]), the pre-classified colours and
/// precomputed gradients where the frame reads them, and the image's output buffers.
///
/// # Errors
/// As [`run`] up to the rendering; a volume that cannot be cut into bricks that fit.
pub fn plan(req: &RenderRequest, progress: &dyn Progress) -> Result<super::plan::MemoryPlan> {
    let (scene, mut settings) = build_scene(&req.scene, req.samples, progress)?;
    req.scene.accel.apply(&mut settings)?;
    check_repeat(req)?;
    if !req.volumes.is_empty() {
        return plan_multi(req, &scene, &settings, progress);
    }
    if let Some(sampling) = req.sampling {
        return plan_sampling(req, &scene, &settings, sampling);
    }
    let engine = super::Engine::open(req.backend)?;
    let plan = plan_frame(&scene, &settings, &engine)?;
    if req.repeat.is_some() {
        check_session_fits(&scene, &settings, &engine)?;
    }
    Ok(plan)
}

/// Refuses `--repeat` (frames of one renderer session, which holds its volume whole) on
/// a GPU where the frame's volume is cut into bricks
/// ([`crate::gpu::raycast::volume_split`]).
fn check_session_fits(scene: &Scene, settings: &RenderSettings, engine: &Engine) -> Result<()> {
    let Some(ctx) = engine.gpu() else {
        return Ok(());
    };
    use crate::gpu::raycast::CompactVolume;
    let compact = CompactVolume::of(ctx, &scene.volume).filter(|_| CompactVolume::enabled());
    let dims = scene.volume.dims();
    match crate::gpu::raycast::volume_split(ctx, dims, settings, compact, &scene.camera)? {
        Some(cut) => Err(Error::invalid(
            "--repeat",
            format!(
                "times the frames of one renderer session, which holds the volume whole, but \
                 this frame needs {}: render it without --repeat",
                cut.line
            ),
        )),
        None => Ok(()),
    }
}

/// The memory plan of a single-volume frame of `scene` on `engine`, after every check
/// its render makes before the work ([`crate::cpu::raycast`]'s cost, and on the GPU
/// [`crate::gpu::raycast::check_device`] and the bricks past the 3-D texture limit or
/// the device memory).
/// `render --dry-run` and `compare` (before its CPU render, for the GPU's) call it.
///
/// # Errors
/// What the frame's render would refuse before it starts.
pub(crate) fn plan_frame(
    scene: &Scene,
    settings: &RenderSettings,
    engine: &Engine,
) -> Result<super::plan::MemoryPlan> {
    let dims = scene.volume.dims();
    crate::cpu::raycast::check_cost(dims, &scene.camera, settings)?;
    let voxels = dims.iter().product::<usize>() as u64;
    let image = image_bytes(&scene.camera, settings);
    let backend = engine.describe();
    let (host, device, split) = match (engine.backend(), engine.gpu()) {
        (Backend::Gpu, Some(ctx)) => {
            use crate::gpu::raycast::{
                carries_state, output_bytes, split_host_bytes, texture_bytes_per_voxel,
                CompactVolume,
            };
            let compact =
                CompactVolume::of(ctx, &scene.volume).filter(|_| CompactVolume::enabled());
            let cut =
                crate::gpu::raycast::volume_split(ctx, dims, settings, compact, &scene.camera)?;
            // A split frame's host also holds the rays' carried states and the whole
            // volume's coefficients, where it uses them.
            let (texels, split, extra) = match cut {
                Some(c) => (
                    c.largest,
                    vec![c.line],
                    split_host_bytes(dims, &scene.camera, settings),
                ),
                None => (voxels, Vec::new(), 0),
            };
            crate::gpu::raycast::check_device(ctx, dims, settings, compact)?;
            let out = output_bytes(&scene.camera, !split.is_empty() && carries_state(settings));
            let per_voxel = texture_bytes_per_voxel(settings, compact);
            // The largest single object: the output or the volume's values (at most 4
            // bytes a texel; a 16-bit compact texture alone 2).
            let device = super::plan::DevicePlan::on(
                ctx,
                texels * per_voxel + out,
                out.max(texels * per_voxel.min(4)),
            );
            // The host keeps the volume as f32 (and each brick's copy).
            (voxels * 4 + texels * 4 + image + extra, Some(device), split)
        }
        (Backend::CpuF32, _) => (voxels * 4 + image, None, Vec::new()),
        _ => (voxels * 8 + image, None, Vec::new()),
    };
    Ok(super::plan::MemoryPlan {
        job: format!("render {:?}", settings.mode).to_lowercase(),
        backend,
        host_bytes: host,
        device,
        split,
        writes: Vec::new(),
    })
}

/// Runs `voxlab render`: see the [module docs](self).
///
/// # Errors
/// Invalid input or settings, a missing GPU for `gpu`, an unsupported combination
/// (e.g. `repeat` with a stereo pair), [`Error::Cancelled`].
pub fn run(req: &RenderRequest, progress: &dyn Progress) -> Result<Rendering> {
    let (scene, mut settings) = build_scene(&req.scene, req.samples, progress)?;
    req.scene.accel.apply(&mut settings)?;
    check_repeat(req)?;
    check_cancel(progress)?;
    if !req.volumes.is_empty() {
        return render_multi(req, &scene, settings, progress);
    }
    if let Some(sampling) = req.sampling {
        return render_sampling(req, &scene, settings, sampling, progress);
    }
    let renderer = Renderer::new(req.backend)?;
    if let Some(why) = renderer.fallback_reason() {
        progress.note(&format!(
            "not using a GPU: {why}; rendering with the CPU oracle"
        ));
    }
    let who = renderer.describe();
    let h = scene.camera.height as u64;
    progress.begin(&format!("rendering ({who})"), "rows", h);
    let t = Instant::now();
    let mut result = Rendering {
        output: RenderOutput {
            image: crate::frame::Frame::new(1, 1, 1),
            samples: None,
            total_samples: 0,
        },
        engine: renderer.engine(),
        seconds: 0.0,
        gpu_timings: None,
        frames: None,
        stereo: None,
        volumes: 1,
        sampling: None,
        settings: settings.clone(),
        camera: scene.camera.clone(),
    };
    if let Some(st) = &req.stereo {
        let conv = st.convergence.unwrap_or_else(|| {
            (volume_center(&scene.volume) - scene.camera.eye).dot(scene.camera.forward)
        });
        let pair = cancellable(progress, |cp| {
            super::stereo::render_pair(
                &renderer,
                &scene,
                &settings,
                st.eye_separation,
                conv,
                &|done, total| cp.advance(done, total),
            )
        })?;
        let img = super::stereo::combine(&pair.left, &pair.right, st.layout)?;
        result.output.image = img;
        result.stereo = Some(StereoInfo {
            layout: st.layout,
            eye_separation: st.eye_separation,
            shift_px: pair.cameras.shift_px,
            convergence_mm: pair.cameras.convergence_mm,
        });
        result.seconds = since(t);
        progress.end(result.seconds);
        return Ok(result);
    }
    match req.repeat {
        Some(n) => {
            if req.scene.accel.accumulate.is_some() {
                return Err(Error::invalid(
                    "--repeat",
                    "times one frame; it excludes --accumulate",
                ));
            }
            check_session_fits(&scene, &settings, &renderer.engine())?;
            let t_prep = Instant::now();
            let prepared = renderer.prepare(&scene, &settings)?;
            let prepare = since(t_prep);
            let mut times = Vec::with_capacity(n as usize);
            let (mut uploads, mut kernels) = (Vec::new(), Vec::new());
            let mut last: Option<Rendered> = None;
            let rows = n as usize * h as usize;
            for f in 0..n as usize {
                let t_f = Instant::now();
                let r = cancellable(progress, |cp| {
                    renderer.render_prepared(&prepared, &scene.camera, &settings, &|done, _| {
                        cp.advance(f * h as usize + done, rows)
                    })
                })?;
                times.push(since(t_f));
                uploads.extend(r.gpu_timings.map(|t| t.upload));
                kernels.extend(r.gpu_timings.map(|t| t.kernel));
                last = Some(r);
            }
            times.sort_by(f64::total_cmp);
            kernels.sort_by(f64::total_cmp);
            let frames = FrameTimes {
                median: times[times.len() / 2],
                frames: times.len(),
                prepare,
                gpu_session: last.as_ref().and_then(|r| r.gpu_session),
                gpu_uploads: uploads,
                gpu_kernel_median: kernels.get(kernels.len() / 2).copied(),
                gpu_kernel_from_timestamps: last
                    .as_ref()
                    .and_then(|r| r.gpu_timings)
                    .is_some_and(|t| t.kernel_from_timestamps),
            };
            let last = last.expect("at least one frame");
            result.output = last.output;
            result.gpu_timings = last.gpu_timings;
            result.seconds = frames.median;
            result.frames = Some(frames);
        }
        None => {
            let r = req
                .scene
                .accel
                .render(&renderer, &scene, &settings, progress)?;
            if let Some(split) = &r.split {
                progress.note(split);
            }
            result.output = r.output;
            result.gpu_timings = r.gpu_timings;
            result.seconds = since(t);
        }
    }
    progress.end(since(t));
    Ok(result)
}

/// The input with the extra volumes, on the chosen backend.
fn render_multi(
    req: &RenderRequest,
    scene: &Scene,
    settings: RenderSettings,
    progress: &dyn Progress,
) -> Result<Rendering> {
    let vols = multi_volumes(req, scene, progress)?;
    let engine = Engine::open(req.backend)?;
    let t = Instant::now();
    let progress_rows = |_: usize, _: usize| {};
    let output = match engine.gpu() {
        Some(ctx) => {
            let r =
                crate::gpu::multi::render(ctx, &vols, &scene.camera, &settings, &progress_rows)?;
            if let Some(split) = &r.split {
                progress.note(split);
            }
            r.output
        }
        None if engine.backend() == Backend::CpuF32 => {
            crate::cpu::multi::render::<f32>(&vols, &scene.camera, &settings, &progress_rows)?
        }
        None => crate::cpu::multi::render::<f64>(&vols, &scene.camera, &settings, &progress_rows)?,
    };
    Ok(Rendering {
        output,
        engine,
        seconds: since(t),
        gpu_timings: None,
        frames: None,
        stereo: None,
        volumes: vols.len(),
        sampling: None,
        settings,
        camera: scene.camera.clone(),
    })
}

/// `--dry-run` of a render with extra volumes: [`crate::multi::check`] (and on the GPU
/// [`crate::gpu::multi::check`]) on the loaded volumes, and what the caster holds: each
/// volume's field in the working precision on the host (f32 copies for the GPU), its
/// R32Float texture (split: the largest cell's parts) and one band of the image on the
/// device, and the split.
fn plan_multi(
    req: &RenderRequest,
    scene: &Scene,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Result<super::plan::MemoryPlan> {
    let vols = multi_volumes(req, scene, progress)?;
    let engine = Engine::open(req.backend)?;
    let all: u64 = vols
        .iter()
        .map(|v| v.volume.dims().iter().product::<usize>() as u64)
        .sum();
    let image = image_bytes(&scene.camera, settings);
    let mut split = Vec::new();
    let (host, device) = match engine.gpu() {
        Some(ctx) => {
            let cut = crate::gpu::multi::check(ctx, &vols, &scene.camera, settings)?;
            let (peak, largest) =
                crate::gpu::multi::device_bytes(ctx, &vols, &scene.camera, settings, cut.as_ref());
            let device = super::plan::DevicePlan::on(ctx, peak, largest);
            // Split: the carried ray states on the host.
            let carried = cut.as_ref().map_or(0, |c| {
                split.push(c.line.clone());
                (scene.camera.width * scene.camera.height * 16 * crate::gpu::multi::CARRIED_VEC4S)
                    as u64
            });
            (4 * all + image + carried, Some(device))
        }
        None => {
            crate::multi::check(&vols, &scene.camera, settings)?;
            let real = if engine.backend() == Backend::CpuF32 {
                4
            } else {
                8
            };
            (real * all + image, None)
        }
    };
    Ok(super::plan::MemoryPlan {
        job: format!("render {:?} of {} volumes", settings.mode, vols.len()).to_lowercase(),
        backend: engine.describe(),
        host_bytes: host,
        device,
        split,
        writes: Vec::new(),
    })
}

/// The host image of a render: f64 channels and a u32 sample count per pixel.
fn image_bytes(camera: &Camera, settings: &RenderSettings) -> u64 {
    let ch = if settings.mode.rgba() { 4 } else { 1 };
    camera.width as u64 * camera.height as u64 * (8 * ch + 4)
}

/// INPUT and the `--volume`s, loaded and placed, for the multi-volume caster.
fn multi_volumes(
    req: &RenderRequest,
    scene: &Scene,
    progress: &dyn Progress,
) -> Result<Vec<crate::multi::MultiVolume>> {
    use crate::multi::{MultiVolume, MAX_VOLUMES};
    if req.volumes.len() > MAX_VOLUMES - 1 {
        return Err(Error::invalid(
            "--volume",
            format!(
                "{} given: at most {} extra volumes besides INPUT ({MAX_VOLUMES} in all)",
                req.volumes.len(),
                MAX_VOLUMES - 1
            ),
        ));
    }
    let mut vols = vec![MultiVolume::new(
        scene.volume.clone(),
        scene.transfer.clone(),
    )];
    for extra in &req.volumes {
        let input = VolumeInput::new(extra.input.clone()).with_load(req.scene.input.load.clone());
        let volume = input.load(progress)?;
        let transfer = match &extra.tf {
            Some(t) => TransferFunction::preset_or_file(t)?,
            None => scene.transfer.clone(),
        };
        let transform = extra.transform.unwrap_or(crate::multi::IDENTITY);
        vols.push(MultiVolume::new(volume, transfer).with_transform(transform));
    }
    Ok(vols)
}

/// The adaptive caster's settings for `--sampling`: DVR only, the render's step as the
/// regular and smallest step.
fn adaptive_settings(
    settings: &RenderSettings,
    sampling: Sampling,
) -> Result<crate::cpu::adaptive::AdaptiveSettings> {
    if settings.mode != Mode::Dvr {
        return Err(Error::invalid(
            "--sampling",
            "the adaptive caster renders DVR only (--mode dvr)",
        ));
    }
    Ok(crate::cpu::adaptive::AdaptiveSettings {
        sampling,
        step: settings.step,
        t_max: settings.step.max(8.0),
        ert_threshold: settings.ert_threshold,
        background: settings.background,
        sample_count: true,
        ..Default::default()
    })
}

/// `--dry-run` of a render with `--sampling`: the adaptive caster's frame plan
/// ([`super::adaptive::frame_plan`], the checks in the run's order).
fn plan_sampling(
    req: &RenderRequest,
    scene: &Scene,
    settings: &RenderSettings,
    sampling: Sampling,
) -> Result<super::plan::MemoryPlan> {
    let s = adaptive_settings(settings, sampling)?;
    let engine = Engine::open(req.backend)?;
    let image = image_bytes(&scene.camera, settings);
    let (host_bytes, device, split) = super::adaptive::frame_plan(
        &engine,
        &scene.volume,
        &scene.transfer,
        &scene.camera,
        &s,
        image,
    )?;
    Ok(super::plan::MemoryPlan {
        job: format!("render dvr with {sampling:?} sampling").to_lowercase(),
        backend: engine.describe(),
        host_bytes,
        device,
        split: split.into_iter().collect(),
        writes: Vec::new(),
    })
}

/// The scene through the adaptive caster (docs/adaptive-sampling.md).
fn render_sampling(
    req: &RenderRequest,
    scene: &Scene,
    settings: RenderSettings,
    sampling: Sampling,
    progress: &dyn Progress,
) -> Result<Rendering> {
    let s = adaptive_settings(&settings, sampling)?;
    let engine = Engine::open(req.backend)?;
    let t = Instant::now();
    let run =
        super::adaptive::render_once(&scene.volume, &scene.transfer, &scene.camera, &s, engine)?;
    if let Some(split) = &run.split {
        progress.note(split);
    }
    Ok(Rendering {
        output: run.output,
        engine,
        seconds: since(t),
        gpu_timings: None,
        frames: None,
        stereo: None,
        volumes: 1,
        sampling: Some(sampling),
        settings,
        camera: scene.camera.clone(),
    })
}
