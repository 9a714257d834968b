//! The backend-neutral front door: `render(&scene, &settings, backend)`.
//!
//! A [`Scene`] is what is rendered (volume, transfer function, camera); the
//! [`RenderSettings`] say how. The backend says who
//! computes it: the f64 oracle, the same code in f32, or the GPU port. A [`Renderer`]
//! keeps one GPU device open across many renders.

use crate::camera::Camera;
use crate::cpu::raycast::{self, RenderOutput};
use crate::error::Result;
use crate::gpu::raycast::GpuTimings;
use crate::gpu::GpuContext;
use crate::settings::RenderSettings;
use crate::transfer::TransferFunction;
use crate::volume::AnyVolume;

/// Who computes a render.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
pub enum Backend {
    /// The CPU oracle in f64.
    Cpu,
    /// The same CPU code in f32: the fair baseline for speed comparisons.
    CpuF32,
    /// The WGSL port on the GPU (f32).
    Gpu,
    /// The GPU when a hardware adapter exists, else the CPU oracle (a CPU-emulated
    /// adapter such as lavapipe is used only when `VOXLAB_ADAPTER` names it).
    Auto,
}

impl Backend {
    pub fn name(self) -> &'static str {
        match self {
            Backend::Cpu => "cpu (f64 oracle)",
            Backend::CpuF32 => "cpu-f32",
            Backend::Gpu => "gpu",
            Backend::Auto => "auto",
        }
    }
}

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

/// A backend made ready: for the GPU, an open device reused by every render.
pub struct Renderer {
    backend: Backend,
    gpu: Option<GpuContext>,
    /// Why `Auto` fell back to the CPU, if it did.
    pub fallback_reason: Option<String>,
}

impl Renderer {
    /// Opens the backend. `Gpu` fails without an adapter; `Auto` falls back to the CPU
    /// oracle and records why.
    pub fn new(backend: Backend) -> Result<Self> {
        match backend {
            Backend::Gpu => Ok(Renderer {
                backend,
                gpu: Some(GpuContext::new()?),
                fallback_reason: None,
            }),
            Backend::Auto => match GpuContext::new() {
                // A CPU emulating a GPU (lavapipe) is slower than the CPU oracle itself;
                // auto takes it only when VOXLAB_ADAPTER chose it.
                Ok(ctx) if ctx.summary.is_cpu() && std::env::var_os("VOXLAB_ADAPTER").is_none() => {
                    Ok(Renderer {
                        backend: Backend::Cpu,
                        gpu: None,
                        fallback_reason: Some(format!(
                        "the only adapter, {}, is a CPU emulating a GPU; the CPU oracle is faster \
                         (set VOXLAB_ADAPTER to use it anyway)",
                        ctx.summary.name
                    )),
                    })
                }
                Ok(ctx) => Ok(Renderer {
                    backend: Backend::Gpu,
                    gpu: Some(ctx),
                    fallback_reason: None,
                }),
                Err(e) => Ok(Renderer {
                    backend: Backend::Cpu,
                    gpu: None,
                    fallback_reason: Some(e.to_string()),
                }),
            },
            b => Ok(Renderer {
                backend: b,
                gpu: None,
                fallback_reason: None,
            }),
        }
    }

    /// The backend renders run on (never `Auto`).
    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// The GPU context, for GPU renderers.
    pub fn gpu(&self) -> Option<&GpuContext> {
        self.gpu.as_ref()
    }

    /// A description: the backend, and the adapter for the GPU.
    pub fn describe(&self) -> String {
        match &self.gpu {
            Some(ctx) => format!("gpu ({}, {})", ctx.summary.name, ctx.summary.backend),
            None => self.backend.name().to_string(),
        }
    }

    /// Renders with a progress callback `(rows done, rows total)`.
    pub fn render(
        &self,
        scene: &Scene,
        settings: &RenderSettings,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<Rendered> {
        let (v, tf, cam) = (&scene.volume, &scene.transfer, &scene.camera);
        let (output, gpu_timings) = match (self.backend, &self.gpu) {
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
            backend: self.backend,
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
        let cpu = match (self.backend, &self.gpu) {
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
        let (output, gpu_timings) = match (&p.cpu, &self.gpu) {
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
            backend: self.backend,
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
