//! `voxlab render --volume …`: multi-volume rendering (docs/multi-volume.md).

use clap::Args;
use std::path::Path;
use voxlab::frame::PngOptions;
use voxlab::multi::{parse_transform, MultiVolume, MAX_VOLUMES};
use voxlab::render::{Backend, Scene};
use voxlab::settings::RenderSettings;
use voxlab::transfer::TransferFunction;
use voxlab::{Error, Result};

/// Extra volumes rendered together with INPUT (volume 0, placed by the identity).
#[derive(Args, Default)]
pub struct MultiArgs {
    /// An extra volume (a file or phantom:NAME[:N]) rendered with INPUT in one image;
    /// repeatable, up to 2. Extinctions add for DVR, line integrals for X-ray, MIP takes
    /// the maximum (docs/multi-volume.md).
    #[arg(long = "volume")]
    pub volumes: Vec<String>,
    /// The placement of each --volume, in order: a row-major 3×4 matrix
    /// a,b,c,d,e,f,g,h,i,j,k,l from the volume's own world frame (mm) into INPUT's world
    /// (last column: translation in mm). Default: the identity.
    #[arg(long = "transform", allow_hyphen_values = true)]
    pub transforms: Vec<String>,
    /// The transfer function of each --volume, in order (a preset name or a JSON file).
    /// Default: INPUT's.
    #[arg(long = "volume-tf")]
    pub tfs: Vec<String>,
}

impl MultiArgs {
    pub fn active(&self) -> bool {
        !self.volumes.is_empty() || !self.transforms.is_empty() || !self.tfs.is_empty()
    }

    /// Volume 0 (INPUT) and the extra volumes, checked.
    pub(crate) fn volumes(
        &self,
        scene: &Scene,
        load: &crate::LoadArgs,
    ) -> Result<Vec<MultiVolume>> {
        if self.volumes.is_empty() {
            return Err(Error::invalid(
                "--transform/--volume-tf",
                "they place and classify extra volumes: give at least one --volume",
            ));
        }
        if self.volumes.len() > MAX_VOLUMES - 1 {
            return Err(Error::invalid(
                "--volume",
                format!(
                    "{} given: at most {} extra volumes besides INPUT ({MAX_VOLUMES} in all)",
                    self.volumes.len(),
                    MAX_VOLUMES - 1
                ),
            ));
        }
        for (flag, n) in [
            ("--transform", self.transforms.len()),
            ("--volume-tf", self.tfs.len()),
        ] {
            if n > self.volumes.len() {
                return Err(Error::invalid(
                    flag,
                    format!(
                        "{n} given for {} --volume: at most one per --volume, in order",
                        self.volumes.len()
                    ),
                ));
            }
        }
        let mut out = vec![MultiVolume::new(
            scene.volume.clone(),
            scene.transfer.clone(),
        )];
        for (i, spec) in self.volumes.iter().enumerate() {
            let volume = crate::load_input(spec, load)?;
            let transfer = match self.tfs.get(i) {
                Some(t) => TransferFunction::preset_or_file(t)?,
                None => scene.transfer.clone(),
            };
            let transform = match self.transforms.get(i) {
                Some(t) => parse_transform(t).map_err(|e| {
                    Error::invalid(format!("--transform of --volume {spec}"), e.to_string())
                })?,
                None => voxlab::multi::IDENTITY,
            };
            out.push(MultiVolume::new(volume, transfer).with_transform(transform));
        }
        Ok(out)
    }
}

/// Renders INPUT with the extra volumes and writes the image.
pub(crate) fn render(
    args: &MultiArgs,
    scene: &Scene,
    load: &crate::LoadArgs,
    settings: &RenderSettings,
    backend: Backend,
    out: &Path,
    sixteen_bit: bool,
) -> Result<()> {
    let vols = args.volumes(scene, load)?;
    let t = std::time::Instant::now();
    let progress = |_: usize, _: usize| {};
    let (output, who) = match backend {
        Backend::CpuF32 => (
            voxlab::cpu::multi::render::<f32>(&vols, &scene.camera, settings, &progress)?,
            "cpu-f32",
        ),
        Backend::Cpu => (
            voxlab::cpu::multi::render::<f64>(&vols, &scene.camera, settings, &progress)?,
            "cpu (f64 oracle)",
        ),
        Backend::Gpu => {
            let ctx = voxlab::gpu::GpuContext::new()?;
            (
                voxlab::gpu::multi::render(&ctx, &vols, &scene.camera, settings, &progress)?.output,
                "gpu",
            )
        }
        // As the single-volume path (render::Renderer::new): a real GPU when there is
        // one; a CPU emulating a GPU only when VOXLAB_ADAPTER chose it; else the oracle.
        Backend::Auto => match voxlab::gpu::GpuContext::new() {
            Ok(ctx) if !ctx.summary.is_cpu() || std::env::var_os("VOXLAB_ADAPTER").is_some() => (
                voxlab::gpu::multi::render(&ctx, &vols, &scene.camera, settings, &progress)?.output,
                "gpu",
            ),
            _ => (
                voxlab::cpu::multi::render::<f64>(&vols, &scene.camera, settings, &progress)?,
                "cpu (f64 oracle)",
            ),
        },
    };
    output.image.save(
        out,
        PngOptions {
            sixteen_bit,
            range: None,
        },
    )?;
    eprintln!(
        "wrote {} ({}×{}, {:?}, {} volumes, {} samples, {:.2} s on {who})",
        out.display(),
        scene.camera.width,
        scene.camera.height,
        settings.mode,
        vols.len(),
        output.total_samples,
        t.elapsed().as_secs_f64(),
    );
    Ok(())
}
