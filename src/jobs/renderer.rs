//! A [`Scene`] (volume, transfer function, camera) rendered with [`RenderSettings`]
//! (how) on a [`Backend`] (who: the f64 oracle, the same code in f32, or the GPU
//! port). A [`Renderer`] keeps its engine (and the GPU device) for many renders, and
//! [`Renderer::prepare`] checks and converts a volume once for many frames. The
//! render job ([`super::render`]), jittered accumulation and stereo pairs are built on
//! it.

pub use super::Backend;
use super::Engine;
use crate::camera::Camera;
use crate::cpu::raycast::{self, RenderOutput};
use crate::error::Result;
use crate::gpu::raycast::GpuTimings;
use crate::gpu::GpuContext;
use crate::settings::RenderSettings;
use crate::transfer::TransferFunction;
use crate::volume::AnyVolume;

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
        let (output, gpu_timings) = match (self.backend(), self.gpu()) {
            (Backend::Gpu, Some(ctx)) => {
                let g = crate::gpu::raycast::render(ctx, v, tf, cam, settings, progress)?;
                (g.output, Some(g.timings))
            }
            (Backend::CpuF32, _) => (
                raycast::render::<f32>(v, tf, cam, settings, progress)?,
                None,
            ),
            _ => (
                raycast::render::<f64>(v, tf, cam, settings, progress)?,
                None,
            ),
        };
        Ok(Rendered {
            output,
            backend: self.backend(),
            gpu_timings,
        })
    }
}

/// A scene whose volume is prepared once for many frames: on the CPU backends the
/// finiteness check, the conversion and the skipping's min/max grids
/// ([`raycast::Prepared`]); the GPU backend renders from the scene as usual.
pub struct PreparedScene<'a> {
    scene: &'a Scene,
    cpu: PreparedCpu,
}

enum PreparedCpu {
    Gpu,
    F32(raycast::Prepared<f32>),
    F64(raycast::Prepared<f64>),
}

impl Renderer {
    /// Prepares `scene` for frames with `settings`' filter and gradients.
    pub fn prepare<'a>(
        &self,
        scene: &'a Scene,
        settings: &RenderSettings,
    ) -> Result<PreparedScene<'a>> {
        settings.validate()?;
        let v = &scene.volume;
        let cpu = match (self.backend(), self.gpu()) {
            (Backend::Gpu, Some(_)) => PreparedCpu::Gpu,
            (Backend::CpuF32, _) => PreparedCpu::F32(raycast::Prepared::new(v, settings)?),
            _ => PreparedCpu::F64(raycast::Prepared::new(v, settings)?),
        };
        Ok(PreparedScene { scene, cpu })
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
        let tf = &p.scene.transfer;
        settings.validate()?;
        tf.validate()?;
        let (output, gpu_timings) = match (&p.cpu, self.gpu()) {
            (PreparedCpu::Gpu, Some(ctx)) => {
                let g = crate::gpu::raycast::render(
                    ctx,
                    &p.scene.volume,
                    tf,
                    camera,
                    settings,
                    progress,
                )?;
                (g.output, Some(g.timings))
            }
            (PreparedCpu::F32(c), _) => (c.render(tf, camera, settings, progress)?, None),
            (PreparedCpu::F64(c), _) => (c.render(tf, camera, settings, progress)?, None),
            (PreparedCpu::Gpu, None) => unreachable!("prepared for the GPU without one"),
        };
        Ok(Rendered {
            output,
            backend: self.backend(),
            gpu_timings,
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
