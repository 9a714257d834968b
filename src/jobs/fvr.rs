//! `voxlab fvr`: Fourier volume rendering — an X-ray projection (value × mm) from one
//! slice of the volume's 3-D spectrum (the projection-slice theorem; Jansen et al.
//! 2004, after Malzbender 1993). The algorithm is [`crate::cpu::fvr`] and
//! [`crate::gpu::fvr`].

use super::input::VolumeInput;
use super::render::ViewRequest;
use super::{stage, Backend, Engine, Progress};
use crate::cpu::fvr::{fvr_project, padded_side, FvrSpectrum, FvrView, Kernel};
use crate::error::Result;
use crate::frame::Frame;
use serde::{Deserialize, Serialize};

/// The `voxlab fvr` job.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FvrRequest {
    /// A volume (isotropic voxels only).
    pub input: VolumeInput,
    pub view: ViewRequest,
    /// How the spectrum is sampled on the slice (dirichlet: exact, small volumes only).
    pub kernel: Kernel,
    /// Oversampling: the volume is zero-padded to a cube of side padding × max(dims),
    /// rounded up to even.
    pub padding: usize,
    /// Divide the image by the kernel's spatial transfer (undo its apodisation).
    pub deapodize: bool,
    /// cpu: f64 throughout; cpu-f32: the f64 spectrum rounded to complex f32, then
    /// slice and inverse 2-D FFT in f32; gpu: the CPU builds the spectrum in f64, the
    /// slice and the inverse 2-D FFT run on the GPU (the padded side must be a power
    /// of two).
    pub backend: Backend,
}

impl Default for FvrRequest {
    fn default() -> Self {
        FvrRequest {
            input: VolumeInput::default(),
            view: ViewRequest::default(),
            kernel: Kernel::Lanczos3,
            padding: 2,
            deapodize: false,
            backend: Backend::Cpu,
        }
    }
}

/// The image (value × mm) and who made it.
#[derive(Clone, Debug)]
pub struct FvrImage {
    pub frame: Frame,
    pub engine: Engine,
}

/// Renders one view.
///
/// # Errors
/// Bad input or options (anisotropic voxels, a padded side the GPU cannot transform);
/// GPU errors; [`Error::Cancelled`](crate::Error::Cancelled).
pub fn run(a: &FvrRequest, progress: &dyn Progress) -> Result<FvrImage> {
    let view = match &a.view.axis {
        Some(v) => FvrView::Axis(v.parse()?),
        None => FvrView::Orbit {
            azimuth_deg: a.view.azimuth,
            elevation_deg: a.view.elevation,
        },
    };
    let engine = Engine::open_for(
        "Fourier volume rendering",
        a.backend,
        &[Backend::Cpu, Backend::CpuF32, Backend::Gpu],
    )?;
    let vol = a.input.load(progress)?.to_f32();
    let m = padded_side(vol.dims(), a.padding)?;
    let spectrum = stage(
        progress,
        &format!("3-D FFT of the {m}³ padded volume"),
        "volume",
        0,
        || FvrSpectrum::new(&vol, a.padding),
    )?;
    let frame = stage(
        progress,
        &format!("{} slice and 2-D inverse FFT ({m}²)", a.kernel.name()),
        "view",
        0,
        || match (engine.backend(), engine.gpu()) {
            (Backend::Gpu, Some(ctx)) => {
                use crate::gpu::fvr::{fvr_project_timed, GpuFvrSpectrum};
                let t_up = std::time::Instant::now();
                let uploaded = GpuFvrSpectrum::upload(ctx, &spectrum)?;
                let up = t_up.elapsed().as_secs_f64();
                let (frame, tm) = fvr_project_timed(ctx, &uploaded, view, a.kernel, a.deapodize)?;
                progress.note(&format!(
                    "GPU ({}): spectrum upload {up:.3} s; view {:.3} s (setup {:.3}, slice {:.3}, \
                     inverse FFT and readback {:.3}, crop {:.3})",
                    ctx.summary.name, tm.total, tm.setup, tm.slice, tm.fft, tm.crop
                ));
                Ok(frame)
            }
            (Backend::CpuF32, _) => fvr_project(&spectrum.to_f32(), view, a.kernel, a.deapodize),
            _ => fvr_project(&spectrum, view, a.kernel, a.deapodize),
        },
    )?;
    Ok(FvrImage { frame, engine })
}
