//! `voxlab fvr`: Fourier volume rendering — an X-ray projection (value × mm) from one
//! slice of the volume's 3-D spectrum (the projection-slice theorem; Jansen et al.
//! 2004, after Malzbender 1993). The algorithm is [`crate::cpu::fvr`] and
//! [`crate::gpu::fvr`].

use super::input::VolumeInput;
use super::render::ViewRequest;
use super::{stage, Backend, Engine, Progress};
use crate::cpu::fvr::{fvr_project, FvrLayout, FvrSpectrum, FvrView, Kernel};
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
    let view = view_of(a)?;
    let engine = open(a)?;
    let vol = a.input.load(progress)?.to_f32();
    let m = check_volume(a, &engine, vol.dims(), vol.affine())?;
    let fft_stage = format!("3-D FFT of the {m}³ padded volume");
    let view_stage = format!("{} slice and 2-D inverse FFT ({m}²)", a.kernel.name());
    let frame = match (engine.backend(), engine.gpu()) {
        (Backend::Gpu, Some(ctx)) => {
            use crate::gpu::fvr::{fvr_project_timed, GpuFvrSpectrum, SpectrumSlabs};
            let limit = crate::gpu::plan::binding_limit(&ctx.limits);
            if let Some(line) = SpectrumSlabs::new(&ctx.limits, m, limit)?.describe() {
                progress.note(&line);
            }
            // The spectrum is transformed and kept on the GPU (f32).
            let t_up = std::time::Instant::now();
            let spectrum = stage(
                progress,
                &format!("{fft_stage} on the GPU"),
                "volume",
                0,
                || GpuFvrSpectrum::compute(ctx, &vol, a.padding),
            )?;
            let up = t_up.elapsed().as_secs_f64();
            stage(progress, &view_stage, "view", 0, || {
                let (frame, tm) = fvr_project_timed(ctx, &spectrum, view, a.kernel, a.deapodize)?;
                let device = tm
                    .kernel
                    .map(|k| format!("; slice and inverse FFT on the device {:.3} ms", k * 1e3))
                    .unwrap_or_default();
                progress.note(&format!(
                    "GPU ({}): spectrum (upload and 3-D FFT) {up:.3} s; view {:.3} s (setup \
                     {:.3}, slice {:.3}, inverse FFT and readback {:.3}, crop {:.3}{device})",
                    ctx.summary.name, tm.total, tm.setup, tm.slice, tm.fft, tm.crop
                ));
                Ok(frame)
            })?
        }
        (backend, _) => {
            let spectrum = stage(progress, &fft_stage, "volume", 0, || {
                FvrSpectrum::new(&vol, a.padding)
            })?;
            stage(progress, &view_stage, "view", 0, || match backend {
                Backend::CpuF32 => fvr_project(&spectrum.to_f32(), view, a.kernel, a.deapodize),
                _ => fvr_project(&spectrum, view, a.kernel, a.deapodize),
            })?
        }
    };
    Ok(FvrImage { frame, engine })
}

/// What [`run`] and [`plan`] refuse of the volume before any transform: voxels that are
/// not isotropic, a bad padding, a Dirichlet slice past its limits (the GPU's included).
/// Returns the padded side.
fn check_volume(
    a: &FvrRequest,
    engine: &Engine,
    dims: [usize; 3],
    affine: glam::DMat4,
) -> Result<usize> {
    let layout = FvrLayout::of(dims, affine, a.padding)?;
    if a.kernel == Kernel::Dirichlet {
        match engine.gpu().filter(|_| engine.backend() == Backend::Gpu) {
            Some(ctx) => crate::gpu::fvr::check_dirichlet(&ctx.limits, &layout)?,
            None => layout.check_dirichlet_work()?,
        }
    }
    Ok(layout.side())
}

/// The view `a` asks for.
fn view_of(a: &FvrRequest) -> Result<FvrView> {
    Ok(match &a.view.axis {
        Some(v) => FvrView::Axis(v.parse()?),
        None => FvrView::Orbit {
            azimuth_deg: a.view.azimuth,
            elevation_deg: a.view.elevation,
        },
    })
}

fn open(a: &FvrRequest) -> Result<Engine> {
    Engine::open_for(
        "Fourier volume rendering",
        a.backend,
        &[Backend::Cpu, Backend::CpuF32, Backend::Gpu],
    )
}

/// `voxlab fvr --dry-run`: the memory plan of [`run`] after reading the volume (for its
/// size) and checking the options: on the CPU the host's padded complex f64 spectrum
/// and image; on the GPU the padded f32 cube, its 3-D FFT on the device (or in slabs
/// through the host), the spectrum's f32 slabs and the slice against the planner's
/// limits, and how many slabs it is bound in. Nothing is transformed or written.
///
/// # Errors
/// As [`run`] up to the work; [`crate::Error::TooLarge`] for a spectrum that cannot
/// be bound even split.
pub fn plan(a: &FvrRequest, progress: &dyn Progress) -> Result<super::plan::MemoryPlan> {
    view_of(a)?;
    let engine = open(a)?;
    let vol = a.input.load(progress)?;
    let m = check_volume(a, &engine, vol.dims(), vol.affine())? as u64;
    let voxels = vol.dims().iter().product::<usize>() as u64;
    // The CPU: the volume (f32), the padded complex f64 spectrum and the f64 image.
    let mut host = 4 * voxels + 16 * m.pow(3) + 8 * m * m;
    let (device, split) = match engine.gpu().filter(|_| engine.backend() == Backend::Gpu) {
        Some(ctx) => {
            use crate::gpu::fft::{device_bytes, split_plan};
            use crate::gpu::fvr::SpectrumSlabs;
            let limit = crate::gpu::plan::binding_limit(&ctx.limits);
            let side = m as usize;
            let slabs = SpectrumSlabs::new(&ctx.limits, side, limit)?;
            let slab = slabs.depth as u64 * m * m * 8;
            let cube = [side; 3];
            let fft3_split = split_plan(ctx, &cube)?;
            let mut split: Vec<String> = slabs.describe().into_iter().collect();
            // The 3-D FFT: in place on the device when the cube fits one binding (its
            // two buffers, Bluestein's work buffers, the tables), else in slabs
            // through the host (whose pieces fit a binding each).
            let (fft3, fft3_largest) = match &fft3_split {
                None if slabs.slabs == 1 => device_bytes(&cube, &[0, 1, 2]),
                _ => {
                    split.extend(fft3_split.map(|p| p.describe()));
                    (0, 0)
                }
            };
            // Then per view: the spectrum's slabs, and the inverse 2-D FFT of the
            // slice (its two buffers, the slice being the first, Bluestein's work
            // buffers where M is not a power of two, and the tables).
            let (fft2, fft2_largest) = device_bytes(&[side, side], &[0, 1]);
            let peak = fft3.max(8 * m.pow(3) + fft2);
            let largest = slab.max(fft2_largest).max(fft3_largest);
            // The host: the volume, the padded f32 cube (and the result of a split
            // FFT), the f64 image.
            host = 4 * voxels + 8 * m.pow(3) * if fft3 == 0 { 3 } else { 1 } + 8 * m * m;
            (Some(super::plan::DevicePlan::on(ctx, peak, largest)), split)
        }
        None => (None, Vec::new()),
    };
    Ok(super::plan::MemoryPlan {
        job: format!("fvr {} (padded {m}³)", a.kernel.name()),
        backend: engine.describe(),
        host_bytes: host,
        device,
        split,
        writes: Vec::new(),
    })
}
