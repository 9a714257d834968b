//! A [`Scene`] (volume, transfer function, camera) rendered with [`RenderSettings`]
//! (how) on a [`Backend`] (who: the f64 oracle, the same code in f32, or the GPU
//! port). A [`Renderer`] keeps its engine (and the GPU device) for many renders.
//!
//! [`Renderer::prepare`] makes a [`PreparedScene`] of a volume for many frames, and
//! [`Renderer::render_prepared`] renders its frames, each equal to [`Renderer::render`]
//! of the same scene. On the CPU backends the volume is checked and converted once (and
//! the skipping's min/max grids kept); on the GPU the prepared scene holds a
//! [`RaycastSession`]: the volume is uploaded once, and frames that orbit the camera,
//! edit the transfer function or change settings make again only what changed (a
//! frame that changes nothing but the camera uploads nothing and runs no set-up pass;
//! [`Rendered::gpu_session`] counts). The render job ([`super::render`], including
//! `--repeat`), jittered accumulation, the Python package's prepared scenes and the lab
//! are built on it.

pub use super::Backend;
use super::Engine;
use crate::camera::Camera;
use crate::cpu::raycast::{self, RenderOutput};
use crate::error::Result;
use crate::gpu::raycast::{GpuTimings, RaycastSession, SessionStats};
use crate::gpu::GpuContext;
use crate::settings::RenderSettings;
use crate::transfer::TransferFunction;
use crate::volume::AnyVolume;
use std::sync::{Mutex, MutexGuard};

/// What to render.
#[derive(Clone, Debug)]
pub struct Scene {
    pub volume: AnyVolume,
    pub transfer: TransferFunction,
    pub camera: Camera,
}

/// A render and how it was made.
#[derive(Clone, Debug)]
pub struct Rendered {
    pub output: RenderOutput,
    /// The backend that computed it (never `Auto`).
    pub backend: Backend,
    /// GPU timings, for GPU renders.
    pub gpu_timings: Option<GpuTimings>,
    /// What the GPU session had done after this frame (a one-shot render's session
    /// made one frame), for GPU renders.
    pub gpu_session: Option<SessionStats>,
    /// How a GPU render past the 3-D texture limit was split (`ray casting in 4
    /// bricks …`), when it was.
    pub split: Option<String>,
}

/// A backend made ready for renders: [`Engine`] with the ray caster's entry points.
pub struct Renderer {
    engine: Engine,
}

impl Renderer {
    /// Opens the backend. `Gpu` fails without an adapter; `Auto` falls back to the CPU
    /// oracle and records why ([`Renderer::fallback_reason`]).
    pub fn new(backend: Backend) -> Result<Self> {
        Ok(Renderer {
            engine: Engine::open(backend)?,
        })
    }

    /// A renderer on an engine already open.
    pub fn on(engine: Engine) -> Self {
        Renderer { engine }
    }

    /// The engine renders run on.
    pub fn engine(&self) -> Engine {
        self.engine
    }

    /// The backend renders run on (never `Auto`).
    pub fn backend(&self) -> Backend {
        self.engine.backend()
    }

    /// The GPU context, for GPU renderers.
    pub fn gpu(&self) -> Option<&GpuContext> {
        self.engine.gpu()
    }

    /// Why `Auto` fell back to the CPU, if it did.
    pub fn fallback_reason(&self) -> Option<&str> {
        self.engine.fallback_reason()
    }

    /// A description: the backend, and the adapter for the GPU.
    pub fn describe(&self) -> String {
        self.engine.describe()
    }

    /// Renders with a progress callback `(rows done, rows total)`.
    pub fn render(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<Rendered> {
        let (v, tf, cam) = (&scene.volume, &scene.transfer, &scene.camera);
        let mut split = None;
        let (output, gpu_timings, gpu_session) = match (self.backend(), self.gpu()) {
            (Backend::Gpu, Some(ctx)) => {
                settings.validate()?;
                tf.validate()?;
                use crate::gpu::raycast::{volume_split, CompactVolume};
                let compact = CompactVolume::of(ctx, v).filter(|_| CompactVolume::enabled());
                if let Some(cut) = volume_split(ctx, v.dims(), settings, compact, cam)? {
                    // Past the 3-D texture limit or the device memory: bricks, one on
                    // the device at a time, composited on the host.
                    let g = crate::gpu::raycast::render_bricked(
                        ctx,
                        v,
                        tf,
                        cam,
                        settings,
                        (&cut.tree, &cut.bricks),
                        progress,
                    )?;
                    split = Some(cut.line);
                    (g.output, Some(g.timings), None)
                } else {
                    let mut session = RaycastSession::new(ctx, v)?;
                    let g = session.render(tf, cam, settings, progress)?;
                    (g.output, Some(g.timings), Some(session.stats()))
                }
            }
            (Backend::CpuF32, _) => (
                raycast::render::<f32>(v, tf, cam, settings, progress)?,
                None,
                None,
            ),
            _ => (
                raycast::render::<f64>(v, tf, cam, settings, progress)?,
                None,
                None,
            ),
        };
        Ok(Rendered {
            output,
            backend: self.backend(),
            gpu_timings,
            gpu_session,
            split,
        })
    }
}

/// A scene's volume prepared once for many frames, with the transfer function frames
/// render with unless told another ([`Renderer::render_prepared_with`]).
///
/// On the GPU: a [`RaycastSession`] (the volume uploaded once; pipelines, lookup tables
/// and set-up volumes cached and made again only when a frame changes what determines
/// them), so frames may change every setting. On the CPU backends: the finiteness
/// check, the conversion and the skipping's min/max grids ([`raycast::Prepared`]), for
/// frames that keep the filter and gradients prepared for ([`PreparedScene::serves`]).
///
/// It holds its own copy of the volume, taken when it was prepared: later changes to
/// the scene do not reach it.
pub struct PreparedScene {
    transfer: TransferFunction,
    engine: PreparedEngine,
}

enum PreparedEngine {
    /// Behind a lock, so that frames render through `&self` (one at a time).
    Gpu(Box<Mutex<RaycastSession<'static>>>),
    F32(raycast::Prepared<f32>),
    F64(raycast::Prepared<f64>),
}

impl PreparedScene {
    /// The transfer function [`Renderer::render_prepared`] renders with.
    pub fn transfer(&self) -> &TransferFunction {
        &self.transfer
    }

    /// Replaces the transfer function frames render with.
    pub fn set_transfer(&mut self, tf: TransferFunction) {
        self.transfer = tf;
    }

    /// Whether frames with `settings` can render from this preparation: always on the
    /// GPU; on the CPU when they keep the filter and gradients it was prepared for.
    pub fn serves(&self, settings: &RenderSettings) -> bool {
        match &self.engine {
            PreparedEngine::Gpu(_) => true,
            PreparedEngine::F32(c) => c.serves(settings),
            PreparedEngine::F64(c) => c.serves(settings),
        }
    }

    /// The GPU session's counters (uploads, compiled pipelines, set-up passes); `None`
    /// on the CPU backends.
    pub fn gpu_stats(&self) -> Option<SessionStats> {
        match &self.engine {
            PreparedEngine::Gpu(s) => Some(lock(s).stats()),
            _ => None,
        }
    }
}

/// The session, also after a frame panicked while holding it (its caches are replaced
/// whole, never left half-made).
fn lock<'a>(s: &'a Mutex<RaycastSession<'static>>) -> MutexGuard<'a, RaycastSession<'static>> {
    s.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

impl Renderer {
    /// Prepares `scene` for frames; on the CPU backends for `settings`' filter and
    /// gradients. On the GPU this uploads the volume.
    pub fn prepare(&self, scene: &Scene, settings: &RenderSettings) -> Result<PreparedScene> {
        self.prepare_volume(&scene.volume, &scene.transfer, settings)
    }

    /// [`Renderer::prepare`] of a volume and a transfer function (no camera yet).
    pub fn prepare_volume(
        &self,
        volume: &AnyVolume,
        transfer: &TransferFunction,
        settings: &RenderSettings,
    ) -> Result<PreparedScene> {
        settings.validate()?;
        let engine = match (self.backend(), self.engine.gpu()) {
            (Backend::Gpu, Some(ctx)) => {
                PreparedEngine::Gpu(Box::new(Mutex::new(RaycastSession::new(ctx, volume)?)))
            }
            (Backend::CpuF32, _) => PreparedEngine::F32(raycast::Prepared::new(volume, settings)?),
            _ => PreparedEngine::F64(raycast::Prepared::new(volume, settings)?),
        };
        Ok(PreparedScene {
            transfer: transfer.clone(),
            engine,
        })
    }

    /// Renders a frame of a prepared scene seen by `camera`: the same image as
    /// [`Renderer::render`] of the scene with that camera.
    pub fn render_prepared(
        &self,
        p: &PreparedScene,
        camera: &Camera,
        settings: &RenderSettings,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<Rendered> {
        self.render_prepared_with(p, &p.transfer, camera, settings, progress)
    }

    /// [`Renderer::render_prepared`] with another transfer function (on the GPU its
    /// lookup table is uploaded when its entries changed since the last frame).
    pub fn render_prepared_with(
        &self,
        p: &PreparedScene,
        tf: &TransferFunction,
        camera: &Camera,
        settings: &RenderSettings,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<Rendered> {
        settings.validate()?;
        tf.validate()?;
        let (output, gpu_timings, gpu_session) = match &p.engine {
            PreparedEngine::Gpu(s) => {
                let mut session = lock(s);
                let g = session.render(tf, camera, settings, progress)?;
                (g.output, Some(g.timings), Some(session.stats()))
            }
            PreparedEngine::F32(c) => (c.render(tf, camera, settings, progress)?, None, None),
            PreparedEngine::F64(c) => (c.render(tf, camera, settings, progress)?, None, None),
        };
        Ok(Rendered {
            output,
            backend: self.backend(),
            gpu_timings,
            gpu_session,
            split: None,
        })
    }
}

/// Renders `scene` with `settings` on `backend`.
pub fn render(scene: &Scene, settings: &RenderSettings, backend: Backend) -> Result<RenderOutput> {
    Ok(render_with_progress(scene, settings, backend, &|_, _| {})?.output)
}

/// [`render`] with a progress callback `(rows done, rows total)`, saying which backend
/// computed it.
pub fn render_with_progress(
    scene: &Scene,
    settings: &RenderSettings,
    backend: Backend,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Rendered> {
    Renderer::new(backend)?.render(scene, settings, progress)
}
