//! The backend-neutral front door: `render(&scene, &settings, backend)`.
//!
//! A [`Scene`] is what is rendered (volume, transfer function, camera); the
//! [`RenderSettings`](crate::settings::RenderSettings) say how. The backend says who
//! computes it: the f64 oracle or the same code in f32. (The GPU backend joins with the
//! GPU port of the ray caster.)

use crate::camera::Camera;
use crate::cpu::raycast::{self, RenderOutput};
use crate::error::Result;
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
}

impl Backend {
    pub fn name(self) -> &'static str {
        match self {
            Backend::Cpu => "cpu (f64 oracle)",
            Backend::CpuF32 => "cpu-f32",
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

/// Renders `scene` with `settings` on `backend`.
pub fn render(scene: &Scene, settings: &RenderSettings, backend: Backend) -> Result<RenderOutput> {
    render_with_progress(scene, settings, backend, &|_, _| {})
}

/// [`render`] with a progress callback `(rows done, rows total)`.
pub fn render_with_progress(
    scene: &Scene,
    settings: &RenderSettings,
    backend: Backend,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<RenderOutput> {
    let (v, tf, cam) = (&scene.volume, &scene.transfer, &scene.camera);
    match backend {
        Backend::Cpu => raycast::render::<f64>(v, tf, cam, settings, progress),
        Backend::CpuF32 => raycast::render::<f32>(v, tf, cam, settings, progress),
    }
}
