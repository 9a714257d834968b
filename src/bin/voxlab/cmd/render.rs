//! `voxlab render`: one volume (or several) to an image, through
//! [`voxlab::jobs::render::run`].

use crate::cli::{choice, list, LoadArgs, Terminal, ViewArgs};
use clap::Args;
use std::path::PathBuf;
use std::process::ExitCode;
use voxlab::cpu::adaptive::Sampling;
use voxlab::io::{check_output, write_frame, PngOptions};
use voxlab::jobs::render::{
    AccelRequest, Backend, ExtraVolume, RenderRequest, SceneRequest, StereoRequest,
};
use voxlab::jobs::stereo::StereoLayout;
use voxlab::settings::{
    Classification, ClipMeshUnits, ClipSpace, Compositing, Filter, GradientMethod, IsoSurface, Mode,
};
use voxlab::transfer2d::GradientAxis;
use voxlab::{Error, Result};

/// What to render and how: shared by `render` and `compare`.
#[derive(Args)]
pub struct SceneArgs {
    /// A volume: a file (NRRD, NIfTI, DICOM, PVM, VolPack .den, TIFF stack, .npy of
    /// shape (nz, ny, nx), or raw with --raw-*), a DICOM directory, or a phantom:
    /// phantom:NAME[:N | :NX,NY,NZ], e.g. phantom:shepp-logan-modified:128, or an
    /// embedded scan (embedded:microct-bone, embedded:mr-brain). Not with --state.
    #[arg(required_unless_present = "state")]
    pub input: Option<String>,
    #[command(flatten)]
    pub load: LoadArgs,
    /// A view state written by `voxlab view --save-state` (or its menu): its input,
    /// camera, image size, settings and transfer functions, rendered exactly as the
    /// lab shows them. Replaces INPUT and every scene option; --backend and the output
    /// options still apply.
    #[arg(long, conflicts_with = "input")]
    pub state: Option<PathBuf>,
    /// What rays compute: dvr (colour and opacity through the transfer function), mip,
    /// minip, xray (line integral, value × mm), mida (maximum intensity difference
    /// accumulation, see --mida-gamma), iso (iso-surfaces only, see --iso).
    #[arg(long, value_parser = choice::<Mode>(), default_value = "dvr")]
    pub mode: Mode,
    /// Transfer function: a preset name (see `voxlab tf`), a JSON file, or auto (the
    /// `phantom` preset for phantoms, `microct-bone` for embedded:microct-bone; for
    /// files, a soft grayscale ramp over the volume's value range).
    #[arg(long, default_value = "auto")]
    pub tf: String,
    /// Window in raw data units, as WIDTH (with --level) or WIDTH,CENTRE. MIP and MinIP:
    /// the grey window, clamp((v − centre)/width + ½, 0, 1). Other modes: maps
    /// [centre − width/2, centre + width/2] onto the transfer function's domain
    /// (Ψ(t) = a·t + b).
    #[arg(long, allow_hyphen_values = true)]
    pub window: Option<String>,
    /// A named CT window in Hounsfield units (brain, subdural, abdomen, liver, lung,
    /// bone), used like --window WIDTH,CENTRE.
    #[arg(long, conflicts_with_all = ["window", "level"])]
    pub window_preset: Option<String>,
    /// MIDA's γ in [-1, 1]: -1 is DVR, 0 plain MIDA, 1 MIP (with --mode mida).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub mida_gamma: f64,
    /// An iso-surface VALUE:COLOUR:OPACITY, e.g. 0.3:#ff0000:0.4 (COLOUR #rrggbb;
    /// OPACITY in [0, 1]); repeatable, up to 4. Drawn by --mode iso, and with DVR.
    #[arg(long = "iso", allow_hyphen_values = true)]
    pub iso: Vec<String>,
    /// Opaque iso-surfaces: the first crossing ends the ray.
    #[arg(long)]
    pub iso_opaque: bool,
    /// Binary shadows on opaque iso-surfaces (with --iso-opaque; use --light).
    #[arg(long)]
    pub shadows: bool,
    /// Take each iso-surface hit at the first sample past the crossing, instead of
    /// refining it by linear interpolation between the two samples.
    #[arg(long)]
    pub no_iso_refine: bool,
    /// Window centre (level) in raw data units. Needs --window.
    #[arg(long, requires = "window", allow_negative_numbers = true)]
    pub level: Option<f64>,
    #[command(flatten)]
    pub view: ViewArgs,
    /// Orbit camera: distance from the volume centre in mm (default: fit the volume).
    #[arg(long)]
    pub distance: Option<f64>,
    /// Orthographic instead of perspective projection for the orbit camera.
    #[arg(long)]
    pub ortho: bool,
    /// Perspective vertical field of view in degrees.
    #[arg(long, default_value_t = 30.0)]
    pub fov: f64,
    /// Image width in pixels (default 256, or the cross-section with --view).
    #[arg(long)]
    pub width: Option<usize>,
    /// Image height in pixels (default 256, or the cross-section with --view).
    #[arg(long)]
    pub height: Option<usize>,
    /// Reconstruction filter.
    #[arg(long, value_parser = choice::<Filter>(), default_value = "trilinear")]
    pub filter: Filter,
    /// Step along rays in voxels.
    #[arg(long, default_value_t = 0.5)]
    pub step: f64,
    /// Apply the transfer function after (post) or before (pre) interpolation.
    #[arg(long, value_parser = choice::<Classification>(), default_value = "post")]
    pub classification: Classification,
    /// Compositing order.
    #[arg(long, value_parser = choice::<Compositing>(), default_value = "front-to-back")]
    pub compositing: Compositing,
    /// Early ray termination: stop a front-to-back ray at this opacity (1 = off).
    #[arg(long, default_value_t = 0.99)]
    pub ert: f64,
    /// Gradient stencil for shading.
    #[arg(long, value_parser = choice::<GradientMethod>(), default_value = "central")]
    pub gradient: GradientMethod,
    /// Precompute a gradient volume instead of differencing the reconstructed field.
    #[arg(long)]
    pub precompute_gradients: bool,
    /// Turn Phong shading off.
    #[arg(long)]
    pub no_shading: bool,
    /// Directional light x,y,z (world, toward the light); default: a headlight.
    #[arg(long, value_parser = list::<f64, 3>, allow_hyphen_values = true)]
    pub light: Option<[f64; 3]>,
    /// Background r,g,b,a in [0, 1] for DVR.
    #[arg(long, value_parser = list::<f64, 4>, default_value = "0,0,0,1")]
    pub background: [f64; 4],
    /// Render settings from a JSON file (the fields of RenderSettings); other options
    /// on the command line are ignored where the file sets them.
    #[arg(long)]
    pub settings: Option<PathBuf>,
    /// GPU only: trilinear filtering by the texture unit instead of the exact manual
    /// interpolation, for --filter trilinear and the 8 trilinear fetches of
    /// cubic-bspline-fast(-interp) (real GPUs quantise its weights to about 8 bits).
    #[arg(long)]
    pub hardware_filtering: bool,
    /// 2D transfer function over (value, gradient magnitude): a JSON file of widgets
    /// or a 2D preset name (ct-bone-2d, …); DVR with post-classification.
    #[arg(long)]
    tf2d: Option<String>,
    /// Gradient-magnitude axis of the 2D transfer function: linear (g/g_max) or log
    /// (ln(1 + g/g0)/ln(1 + g_max/g0)); overrides the JSON's.
    #[arg(long, value_parser = choice::<GradientAxis>())]
    pub gradient_axis: Option<GradientAxis>,
    /// A named preset: a 1D one (ct-air, ct-fat, ct-water, ct-soft-tissue, ct-blood,
    /// ct-bone, … as for --tf) or a 2D one (ct-bone-2d, …, microct-bone-2d).
    #[arg(long)]
    pub tf_preset: Option<String>,
    /// Faux shading (limb darkening) exponent k: colours become c·(α/α_max)^k.
    #[arg(long, allow_negative_numbers = true)]
    pub faux_shading: Option<f64>,
}

#[derive(Args)]
pub struct RenderArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Output image: .png (8-bit; 16-bit with --sixteen-bit) or .npy (float32: RGBA
    /// (h, w, 4) for DVR, scalar (h, w) for MIP, MinIP and X-ray).
    #[arg(long)]
    pub out: PathBuf,
    /// Who computes: cpu (the f64 oracle), cpu-f32, gpu (the WGSL port), or auto
    /// (the GPU when a hardware adapter exists, else the CPU oracle; it says which it
    /// used and why).
    #[arg(long, value_parser = choice::<Backend>(), default_value = "cpu")]
    pub backend: Backend,
    /// Write 16-bit PNG.
    #[arg(long)]
    pub sixteen_bit: bool,
    /// Also write the samples-per-ray image to this file (.png or .npy).
    #[arg(long)]
    pub samples: Option<PathBuf>,
    /// Render with the pre-integrated DVR caster of docs/adaptive-sampling.md, its
    /// samples placed regularly, adaptively (spectral analysis of the transfer function)
    /// or directly (spectra of the classified volume). DVR only, no shading.
    #[arg(long, value_parser = choice::<Sampling>())]
    pub sampling: Option<Sampling>,
    /// Render a stereo pair (parallel eyes, off-axis frusta) laid out as anaglyph
    /// (red = left, green/blue = right), side-by-side (left | right) or interlaced
    /// (even rows left, odd rows right).
    #[arg(long, value_parser = choice::<StereoLayout>())]
    pub stereo: Option<StereoLayout>,
    /// Stereo: distance between the eyes in mm.
    #[arg(long, default_value_t = 65.0)]
    pub eye_separation: f64,
    /// Stereo: distance of the zero-parallax plane in mm (default: the eye's distance
    /// to the volume centre).
    #[arg(long)]
    pub convergence: Option<f64>,
    /// Render the frame N times and report the median time per frame, the volume
    /// prepared once (checked, converted, bounded for skipping) as an interactive
    /// renderer does; the timing quoted against other renderers' frame times. On the
    /// GPU it also prints the session's counters and the median ray casting per frame
    /// on the device (frames per second).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub repeat: Option<u32>,
    #[command(flatten)]
    pub accel: AccelArgs,
    #[command(flatten)]
    pub multi: MultiArgs,
    /// Render on the ranks of `mpirun -n N voxlab render … --distributed`: each rank
    /// reads one brick of the volume (straight from a raw .npy, NRRD or MetaImage
    /// file), casts every ray through it, and the pieces are composited sort-last on
    /// the ranks; rank 0 writes the image. DVR, MIP, MinIP and X-ray, on the CPU or
    /// (--backend gpu) each rank's GPU. Needs a build with the `mpi` feature
    /// (docs/distributed.md).
    #[arg(long)]
    pub distributed: bool,
    /// Print the memory plan (host and device bytes against the adapter's limits, and
    /// the bricks a volume past the 3-D texture limit is cut into) after loading the
    /// input, and render and write nothing.
    #[arg(long)]
    pub dry_run: bool,
}

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
    /// The extra volumes, each with its transform and transfer function.
    fn volumes(&self) -> Result<Vec<ExtraVolume>> {
        if self.volumes.is_empty() && (!self.transforms.is_empty() || !self.tfs.is_empty()) {
            return Err(Error::invalid(
                "--transform/--volume-tf",
                "they place and classify extra volumes: give at least one --volume",
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
        self.volumes
            .iter()
            .enumerate()
            .map(|(i, spec)| {
                let transform = match self.transforms.get(i) {
                    Some(t) => Some(voxlab::multi::parse_transform(t).map_err(|e| {
                        Error::invalid(format!("--transform of --volume {spec}"), e.to_string())
                    })?),
                    None => None,
                };
                Ok(ExtraVolume {
                    input: spec.clone(),
                    transform,
                    tf: self.tfs.get(i).cloned(),
                })
            })
            .collect()
    }
}

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OnOff {
    On,
    Off,
}

/// Empty-space skipping, clipping and jittered sampling (docs/acceleration.md).
#[derive(Args)]
pub struct AccelArgs {
    /// Skip cells the transfer function leaves transparent (DVR; the image does not
    /// change). Default: on.
    #[arg(long, value_enum)]
    pub skip_empty: Option<OnOff>,
    /// Edge of one skipping cell in voxels (default 32).
    #[arg(long)]
    pub block_size: Option<usize>,
    /// Restrict rays to the box X0,Y0,Z0,X1,Y1,Z1 (∩ the volume), in --clip-space.
    #[arg(long, value_parser = list::<f64, 6>, allow_hyphen_values = true)]
    pub clip_box: Option<[f64; 6]>,
    /// voxel: voxel indices X0..=X1 (index space [X0 − ½, X1 + ½]); world: millimetres.
    #[arg(long, value_parser = choice::<ClipSpace>(), default_value = "voxel")]
    pub clip_space: ClipSpace,
    /// Offset every ray's start by a random fraction of a step from this seed.
    #[arg(long, conflicts_with = "interleaved")]
    pub jitter: Option<u32>,
    /// Average N jittered frames with seeds SEED … SEED + N − 1 (SEED from --jitter,
    /// default 0).
    #[arg(long)]
    pub accumulate: Option<usize>,
    /// Offset ray starts by a fixed 4×4 ordered pattern (interleaved sampling).
    #[arg(long)]
    pub interleaved: bool,
    /// Restrict rays to the inside of a closed triangle mesh (FILE.obj or FILE.ply), or
    /// `bricks`: the boundary of the non-empty skipping cells (DVR; same image).
    #[arg(long)]
    pub clip_mesh: Option<String>,
    /// Units of the --clip-mesh file's vertices: world millimetres or voxel indices.
    #[arg(long, value_parser = choice::<ClipMeshUnits>(), default_value = "world")]
    pub clip_mesh_units: ClipMeshUnits,
}

impl AccelArgs {
    pub fn request(&self) -> AccelRequest {
        AccelRequest {
            skip_empty: self.skip_empty.map(|v| v == OnOff::On),
            block_size: self.block_size,
            clip_box: self.clip_box,
            clip_space: self.clip_space,
            jitter: self.jitter,
            accumulate: self.accumulate,
            interleaved: self.interleaved,
            clip_mesh: self.clip_mesh.clone(),
            clip_mesh_units: self.clip_mesh_units,
        }
    }
}

/// `--window` (WIDTH with --level, or WIDTH,CENTRE) as `[width, centre]`; the job
/// checks the numbers.
fn window_arg(a: &SceneArgs) -> Result<Option<[f64; 2]>> {
    let Some(text) = &a.window else {
        if a.level.is_some() {
            return Err(Error::invalid("--level", "needs --window WIDTH"));
        }
        return Ok(None);
    };
    let number = |t: &str| {
        t.trim()
            .parse::<f64>()
            .map_err(|_| Error::invalid("--window", format!("'{t}' is not a number")))
    };
    Ok(Some(match (text.split_once(','), a.level) {
        (Some((w, c)), None) => [number(w)?, number(c)?],
        (Some(_), Some(_)) => {
            return Err(Error::invalid(
                "--window",
                "give WIDTH,CENTRE or WIDTH with --level, not both",
            ))
        }
        (None, Some(l)) => [number(text)?, l],
        (None, None) => {
            return Err(Error::invalid(
                "--window",
                "needs a centre: --window WIDTH,CENTRE or --window WIDTH --level CENTRE",
            ))
        }
    }))
}

impl SceneArgs {
    /// The library's scene request, with the acceleration flags.
    pub fn request(&self, accel: &AccelArgs) -> Result<SceneRequest> {
        Ok(SceneRequest {
            input: self.load.input(self.input.as_deref().unwrap_or_default()),
            mode: self.mode,
            tf: self.tf.clone(),
            tf2d: self.tf2d.clone(),
            tf_preset: self.tf_preset.clone(),
            gradient_axis: self.gradient_axis,
            faux_shading: self.faux_shading,
            window: window_arg(self)?,
            window_preset: self.window_preset.clone(),
            mida_gamma: self.mida_gamma,
            iso: self
                .iso
                .iter()
                .map(|t| IsoSurface::parse(t))
                .collect::<Result<_>>()?,
            iso_opaque: self.iso_opaque,
            shadows: self.shadows,
            iso_refine: !self.no_iso_refine,
            view: self.view.request(),
            distance: self.distance,
            ortho: self.ortho,
            fov: self.fov,
            width: self.width,
            height: self.height,
            filter: self.filter,
            step: self.step,
            classification: self.classification,
            compositing: self.compositing,
            ert: self.ert,
            gradient: self.gradient,
            precompute_gradients: self.precompute_gradients,
            shading: !self.no_shading,
            light: self.light,
            background: self.background,
            settings_file: self.settings.clone(),
            state_file: self.state.clone(),
            hardware_filtering: self.hardware_filtering,
            accel: accel.request(),
            transfer: None,
            transfer_2d: None,
        })
    }
}

pub fn run(r: RenderArgs) -> Result<ExitCode> {
    check_output("output file", &r.out, &["png", "npy"])?;
    if let Some(s) = &r.samples {
        check_output("output file", s, &["png", "npy"])?;
    }
    let req = RenderRequest {
        scene: r.scene.request(&r.accel)?,
        backend: r.backend,
        samples: r.samples.is_some(),
        sampling: r.sampling,
        stereo: r.stereo.map(|layout| StereoRequest {
            layout,
            eye_separation: r.eye_separation,
            convergence: r.convergence,
        }),
        repeat: r.repeat,
        volumes: r.multi.volumes()?,
    };
    if r.dry_run {
        let mut plan = voxlab::jobs::render::plan(&req, &Terminal::bars())?;
        plan.writes.push(r.out.display().to_string());
        print!("{}", plan.describe());
        return Ok(ExitCode::SUCCESS);
    }
    if r.distributed {
        return distributed(&r, &req);
    }
    let term = Terminal::bars();
    let out = voxlab::jobs::render::run(&req, &term)?;
    drop(term);
    let png = PngOptions {
        sixteen_bit: r.sixteen_bit,
        range: None,
    };
    write_frame(&r.out, &out.output.image, png)?;
    let (cam, mode) = (&out.camera, out.settings.mode);
    if let Some(st) = &out.stereo {
        let img = &out.output.image;
        eprintln!(
            "wrote {} ({}×{}, stereo {:?}, eyes {} mm apart, frustum shift {} px, zero parallax at {:.1} mm, {:.2} s on {})",
            r.out.display(),
            img.width,
            img.height,
            st.layout,
            st.eye_separation,
            st.shift_px,
            st.convergence_mm,
            out.seconds,
            out.engine.describe()
        );
        return Ok(ExitCode::SUCCESS);
    }
    if let (Some(path), Some(samples)) = (&r.samples, &out.output.samples) {
        write_frame(path, samples, png)?;
    }
    if let Some(sampling) = out.sampling {
        eprintln!(
            "wrote {} ({}×{}, {} sampling, {} samples, {:.2} s on {:?})",
            r.out.display(),
            cam.width,
            cam.height,
            sampling.name(),
            out.output.total_samples,
            out.seconds,
            out.engine.backend()
        );
    } else if out.volumes > 1 {
        eprintln!(
            "wrote {} ({}×{}, {:?}, {} volumes, {} samples, {:.2} s on {})",
            r.out.display(),
            cam.width,
            cam.height,
            mode,
            out.volumes,
            out.output.total_samples,
            out.seconds,
            out.engine.backend().label(),
        );
    } else {
        eprintln!(
            "wrote {} ({}×{}, {:?}, {} samples, {:.2} s on {})",
            r.out.display(),
            cam.width,
            cam.height,
            mode,
            out.output.total_samples,
            out.seconds,
            out.engine.describe()
        );
        if let Some(f) = out.frames {
            eprintln!(
                "per frame: median {:.3} s of {} frames (samples and image: the last frame); \
                 the volume prepared once in {:.3} s",
                f.median, f.frames, f.prepare
            );
            if let Some(g) = f.gpu_session {
                let uploads: Vec<String> =
                    f.gpu_uploads.iter().map(|u| format!("{u:.4}")).collect();
                eprintln!(
                    "GPU session: the volume uploaded {} time(s) ({} on the device) for {} \
                     frames, {} table upload(s), {} pipeline(s) compiled{}, {} set-up \
                     pass(es); upload seconds per frame: {}",
                    g.volume_uploads,
                    voxlab::gpu::plan::human_bytes(g.volume_bytes),
                    g.frames,
                    g.table_uploads,
                    g.pipelines_compiled,
                    match g.pipelines_shared {
                        0 => String::new(),
                        n => format!(" and {n} taken from the device"),
                    },
                    g.prepare_passes,
                    uploads.join(" ")
                );
            }
            if let Some(k) = f.gpu_kernel_median {
                eprintln!(
                    "GPU ray casting per frame: median {:.3} ms ({:.1} frames/s){}",
                    k * 1e3,
                    1.0 / k,
                    if f.gpu_kernel_from_timestamps {
                        " on the device (timestamps)"
                    } else {
                        " (wall clock of the waited dispatches)"
                    }
                );
            }
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// `--distributed`: every rank renders its brick; rank 0 writes the image and reports
/// every rank.
fn distributed(r: &RenderArgs, req: &RenderRequest) -> Result<ExitCode> {
    super::on_mpi_ranks(
        |comm, progress| voxlab::jobs::distributed_render::run(req, comm, progress),
        |d| {
            let png = PngOptions {
                sixteen_bit: r.sixteen_bit,
                range: None,
            };
            let image = d.image.as_ref().expect("rank 0 holds the image");
            write_frame(&r.out, image, png)?;
            if let (Some(path), Some(samples)) = (&r.samples, &d.samples) {
                write_frame(path, samples, png)?;
            }
            let v = d.dims;
            println!(
                "wrote {} ({}×{}, {:?}, {}×{}×{} volume in {} bricks{}, {} samples, {:.2} s, \
                 {} on {})",
                r.out.display(),
                d.camera.width,
                d.camera.height,
                d.settings.mode,
                v[0],
                v[1],
                v[2],
                d.ranks.len(),
                if d.reads_whole {
                    " (read whole by every rank: not a raw file)"
                } else {
                    ""
                },
                d.total_samples,
                d.seconds,
                d.what,
                match d.ranks.len() {
                    1 => "1 rank".to_string(),
                    n => format!("{n} ranks"),
                },
            );
            print!("{}", d.describe());
            Ok(())
        },
    )
}
