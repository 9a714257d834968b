//! The `voxlab` command line: a thin layer over the library.

mod cli_adaptive;
mod cli_bench;
mod cli_d2vr;
mod cli_multi;
mod cli_process;
mod cli_project;
mod cli_reconstruct;

use clap::{Args, Parser, Subcommand};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use voxlab::camera::{AxisView, Camera, Orbit, Projection};
use voxlab::frame::PngOptions;
use voxlab::render::{Backend, Renderer, Scene};
use voxlab::settings::{
    Classification, Compositing, Filter, GradientMethod, Light, Mode, RenderSettings,
};
use voxlab::transfer::{TransferFunction, WindowMap};
use voxlab::{AnyVolume, Error, Result};

#[derive(Parser)]
#[command(
    name = "voxlab",
    version,
    about = "Volume rendering and tomography: an exact CPU oracle and a GPU port that must agree with it",
    long_about = "voxlab renders volumes (CT, MRI, analytic phantoms) by ray casting: direct volume \
rendering with transfer functions and shading, maximum/minimum intensity projection, and X-ray \
line integrals. Every algorithm has an exact f64 CPU implementation (the oracle) and an f32 twin.\n\n\
It reads NRRD, NIfTI-1, DICOM (files and series), PVM, VolPack .den, TIFF stacks, .npy and \
raw volumes, and refuses broken files with an error naming the file and the field.\n\n\
Start with `voxlab demo`, which renders a gallery from two embedded real scans and the \
built-in phantoms."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Refuse volumes with more voxels than this before allocating anything (default
    /// 2147483648, or the VOXLAB_MAX_VOXELS environment variable).
    #[arg(long, global = true)]
    max_voxels: Option<usize>,
}

#[derive(Subcommand)]
enum Command {
    /// Render a gallery into a folder (no input needed): two real scans embedded in the
    /// binary (micro-CT of bone, MR head) and the built-in phantoms.
    Demo {
        /// Folder to write the pictures, index.html and README.md into.
        #[arg(long, default_value = "voxlab-demo")]
        out: PathBuf,
    },
    /// Render a volume or a phantom to an image (.png or .npy).
    Render(Box<RenderArgs>),
    /// Render on the CPU f64 oracle and on the GPU and compare: images, a diff heat map,
    /// error statistics and timings. Takes the options of `render`.
    Compare(Box<CompareArgs>),
    /// Write an analytic phantom sampled on a grid to a volume file (.nrrd, .nhdr, .npy,
    /// .nii or .nii.gz).
    Phantom {
        /// Phantom and size: NAME, NAME:N or NAME:NX,NY,NZ. Names: shepp-logan,
        /// shepp-logan-modified, marschner-lobb, sphere, spheres, ellipsoid, slab.
        spec: String,
        /// Output volume file (.nrrd, .nhdr, .npy, .nii or .nii.gz).
        #[arg(long)]
        out: PathBuf,
    },
    /// Describe a volume (format, dimensions, spacing, orientation, type, value range,
    /// NaN/inf counts, histogram; --plot draws it), or the GPU.
    Info {
        /// Volume file, DICOM directory or phantom:NAME[:SIZE]. Not needed with --gpu.
        input: Option<String>,
        #[command(flatten)]
        load: LoadArgs,
        /// Also draw the histogram (256 bins, log counts, minimum to maximum from left to
        /// right) into this PNG file.
        #[arg(long)]
        plot: Option<PathBuf>,
        /// Number of histogram bins to print.
        #[arg(long, default_value_t = 16)]
        bins: usize,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
        /// List the GPU adapters, open the best one, print its limits and features, and
        /// run a small self-test on it.
        #[arg(long)]
        gpu: bool,
    },
    /// Convert a volume between formats, optionally cropping, resampling and changing
    /// its voxel type on the way (e.g. a DICOM series to NRRD).
    Convert(Box<ConvertArgs>),
    /// Write one axis-aligned slice of a volume as an image: 8- or 16-bit gray PNG, or
    /// float32 .npy; laid out like the NumPy slice of the (nz, ny, nx) array.
    Slice(Box<SliceArgs>),
    /// Fourier volume rendering: an X-ray projection (value × mm) from one slice of the
    /// volume's 3-D spectrum (projection-slice theorem), written as .png or .npy.
    Fvr(Box<FvrArgs>),
    /// D²VR: render straight from X-ray projections (a stack + geometry JSON, or an
    /// exactly projected phantom) without reconstructing a volume: each sample is
    /// backprojected from the ramp-filtered projections on the fly.
    D2vr(Box<cli_d2vr::D2vrArgs>),
    /// Check and time the FFTs on random complex data: CPU f64, CPU f32 and the GPU
    /// (Stockham and split-stream), each validated against the exact DFT (when
    /// N·ΣN_axis ≤ 1e9, else the CPU f64 FFT). Prints the relative L2 error, the median
    /// time after a warm-up, GFLOP/s (5·N·log2 N / t) and GB/s (one read and one write
    /// of the array). Exit status 3 when an error exceeds 1e-12 (f64) or 1e-6·log2 N
    /// (f32).
    Fft(FftArgs),
    /// CT forward projection: exact line integrals of a phantom, or Joseph's method on
    /// a volume (CPU f64/f32 or GPU), in a parallel or cone-beam geometry; writes a
    /// projection stack (.npy, .nrrd) and its geometry JSON.
    Project(Box<cli_project::ProjectArgs>),
    /// CT reconstruction by filtered backprojection: FBP of a scikit-image sinogram or a
    /// parallel stack (as iradon), FDK of a cone-beam stack (on RTK's grid); CPU f64/f32
    /// or GPU; writes .npy (float32), .nrrd or .png.
    Reconstruct(Box<cli_reconstruct::ReconstructArgs>),
    /// Benchmark every algorithm on the CPU f64 oracle, CPU f32 and the GPU: warm-up,
    /// timed runs (median, min, max), each result checked against the oracle first;
    /// writes a JSON, Markdown and SVG report (see docs/benchmarking.md). Exit status 3
    /// when a result fails its parity check or a case errors.
    Bench(Box<cli_bench::BenchArgs>),
    /// Volume processing: resample a box to other dimensions or spacing (any
    /// reconstruction filter), Gaussian smoothing, 3-D median filter, or the
    /// gradient-magnitude field (value per mm); CPU f64/f32 or GPU; writes a float32
    /// volume (.nrrd, .nhdr, .npy, .nii, .nii.gz).
    Process(Box<cli_process::ProcessArgs>),
    /// Regular, direct and spectral adaptive sampling of one scene side by side: samples
    /// per pixel, time per frame and image error against regular sampling (Markdown and
    /// JSON), the images and the samples-per-ray images.
    Adaptive(Box<cli_adaptive::AdaptiveArgs>),
    /// List the built-in transfer-function presets, or print one as JSON.
    Tf {
        /// Preset to print as JSON (omit to list them).
        name: Option<String>,
    },
}

/// Arguments of `voxlab fft`.
#[derive(Args)]
struct FftArgs {
    /// Shapes, row-major with the last axis fastest: 1024, 256x256, 64x64x64, …
    #[arg(required = true)]
    shapes: Vec<String>,
    /// cpu, gpu or all. Without a GPU adapter, `all` says so and runs the CPU.
    #[arg(long, default_value = "all")]
    backend: String,
    /// Timed runs per case (after one warm-up run, which is the one checked).
    #[arg(long, default_value_t = 5)]
    runs: usize,
    /// Also write every number to this JSON file.
    #[arg(long)]
    json: Option<PathBuf>,
}

/// What to render and how: shared by `render` and `compare`.
#[derive(Args)]
struct SceneArgs {
    /// A volume: a file (NRRD, NIfTI, DICOM, PVM, VolPack .den, TIFF stack, .npy of
    /// shape (nz, ny, nx), or raw with --raw-*), a DICOM directory, or a phantom:
    /// phantom:NAME[:N | :NX,NY,NZ], e.g. phantom:shepp-logan-modified:128.
    input: String,
    #[command(flatten)]
    load: LoadArgs,
    /// What rays compute: dvr (colour and opacity through the transfer function), mip,
    /// minip, xray (line integral, value × mm), mida (maximum intensity difference
    /// accumulation, see --mida-gamma), iso (iso-surfaces only, see --iso).
    #[arg(long, value_enum, default_value = "dvr")]
    mode: Mode,
    /// Transfer function: a preset name (see `voxlab tf`), a JSON file, or auto (the
    /// `phantom` preset for phantoms; for files, a soft grayscale ramp over the volume's
    /// value range).
    #[arg(long, default_value = "auto")]
    tf: String,
    /// Window in raw data units, as WIDTH (with --level) or WIDTH,CENTRE. MIP and MinIP:
    /// the grey window, clamp((v − centre)/width + ½, 0, 1). Other modes: maps
    /// [centre − width/2, centre + width/2] onto the transfer function's domain
    /// (Ψ(t) = a·t + b).
    #[arg(long, allow_hyphen_values = true)]
    window: Option<String>,
    /// A named CT window in Hounsfield units (brain, subdural, abdomen, liver, lung,
    /// bone), used like --window WIDTH,CENTRE.
    #[arg(long, conflicts_with_all = ["window", "level"])]
    window_preset: Option<String>,
    /// MIDA's γ in [-1, 1]: -1 is DVR, 0 plain MIDA, 1 MIP (with --mode mida).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    mida_gamma: f64,
    /// An iso-surface VALUE:COLOUR:OPACITY, e.g. 0.3:#ff0000:0.4 (COLOUR #rrggbb;
    /// OPACITY in [0, 1]); repeatable, up to 4. Drawn by --mode iso, and with DVR.
    #[arg(long = "iso", allow_hyphen_values = true)]
    iso: Vec<String>,
    /// Opaque iso-surfaces: the first crossing ends the ray.
    #[arg(long)]
    iso_opaque: bool,
    /// Binary shadows on opaque iso-surfaces (with --iso-opaque; use --light).
    #[arg(long)]
    shadows: bool,
    /// Take each iso-surface hit at the first sample past the crossing, instead of
    /// refining it by linear interpolation between the two samples.
    #[arg(long)]
    no_iso_refine: bool,
    /// Window centre (level) in raw data units. Needs --window.
    #[arg(long, requires = "window", allow_negative_numbers = true)]
    level: Option<f64>,
    #[command(flatten)]
    view: ViewArgs,
    /// Orbit camera: distance from the volume centre in mm (default: fit the volume).
    #[arg(long)]
    distance: Option<f64>,
    /// Orthographic instead of perspective projection for the orbit camera.
    #[arg(long)]
    ortho: bool,
    /// Perspective vertical field of view in degrees.
    #[arg(long, default_value_t = 30.0)]
    fov: f64,
    /// Image width in pixels (default 256, or the cross-section with --view).
    #[arg(long)]
    width: Option<usize>,
    /// Image height in pixels (default 256, or the cross-section with --view).
    #[arg(long)]
    height: Option<usize>,
    /// Reconstruction filter.
    #[arg(long, value_enum, default_value = "trilinear")]
    filter: Filter,
    /// Step along rays in voxels.
    #[arg(long, default_value_t = 0.5)]
    step: f64,
    /// Apply the transfer function after (post) or before (pre) interpolation.
    #[arg(long, value_enum, default_value = "post")]
    classification: Classification,
    /// Compositing order.
    #[arg(long, value_enum, default_value = "front-to-back")]
    compositing: Compositing,
    /// Early ray termination: stop a front-to-back ray at this opacity (1 = off).
    #[arg(long, default_value_t = 0.99)]
    ert: f64,
    /// Gradient stencil for shading.
    #[arg(long, value_enum, default_value = "central")]
    gradient: GradientMethod,
    /// Precompute a gradient volume instead of differencing the reconstructed field.
    #[arg(long)]
    precompute_gradients: bool,
    /// Turn Phong shading off.
    #[arg(long)]
    no_shading: bool,
    /// Directional light x,y,z (world, toward the light); default: a headlight.
    #[arg(long, value_parser = list::<f64, 3>, allow_hyphen_values = true)]
    light: Option<[f64; 3]>,
    /// Background r,g,b,a in [0, 1] for DVR.
    #[arg(long, value_parser = list::<f64, 4>, default_value = "0,0,0,1")]
    background: [f64; 4],
    /// Render settings from a JSON file (the fields of RenderSettings); other options
    /// on the command line are ignored where the file sets them.
    #[arg(long)]
    settings: Option<PathBuf>,
    /// GPU only: trilinear filtering by the texture unit instead of the exact manual
    /// interpolation, for --filter trilinear and the 8 trilinear fetches of
    /// cubic-bspline-fast(-interp) (real GPUs quantise its weights to about 8 bits).
    #[arg(long)]
    hardware_filtering: bool,
    /// 2D transfer function over (value, gradient magnitude): a JSON file of widgets
    /// or a 2D preset name (ct-bone-2d, …); DVR with post-classification.
    #[arg(long)]
    tf2d: Option<String>,
    /// Gradient-magnitude axis of the 2D transfer function: linear (g/g_max) or log
    /// (ln(1 + g/g0)/ln(1 + g_max/g0)); overrides the JSON's.
    #[arg(long, value_enum)]
    gradient_axis: Option<voxlab::transfer2d::GradientAxis>,
    /// A named preset: a 1D one (ct-air, ct-fat, ct-water, ct-soft-tissue, ct-blood,
    /// ct-bone, … as for --tf) or a 2D one (ct-bone-2d, …, microct-bone-2d).
    #[arg(long)]
    tf_preset: Option<String>,
    /// Faux shading (limb darkening) exponent k: colours become c·(α/α_max)^k.
    #[arg(long, allow_negative_numbers = true)]
    faux_shading: Option<f64>,
}

/// Where the camera looks from: an axis view, or an orbit around the volume.
#[derive(Args, Clone)]
struct ViewArgs {
    /// Axis-aligned orthographic view: +x, -x, +y, -y, +z, -z (rays along that index
    /// axis). The image is laid out like NumPy's reduction over that axis of the
    /// (nz, ny, nx) array (`vol.sum(axis=…)` for X-ray); its default size is the
    /// volume's cross-section, so every pixel centre lies on a ray through voxel
    /// centres. Without it, the orbit view below.
    #[arg(long = "view", allow_hyphen_values = true)]
    axis: Option<String>,
    /// Orbit view: rotation about world +z in degrees (0 looks along +y).
    #[arg(long, default_value_t = 30.0, allow_negative_numbers = true)]
    azimuth: f64,
    /// Orbit view: degrees above the xy-plane.
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
    elevation: f64,
}

/// How to load INPUT: phantom size, raw layout, and what to do with NaN/Inf voxels.
#[derive(Args, Clone)]
struct LoadArgs {
    /// Phantom grid size when INPUT is phantom:NAME without a size.
    #[arg(long, default_value_t = 128)]
    phantom_size: usize,
    /// Raw input: dimensions NX,NY,NZ (x fastest). Reads INPUT as headerless samples.
    #[arg(long, value_parser = list::<usize, 3>)]
    raw_dims: Option<[usize; 3]>,
    /// Raw input: sample type (u8, i8, u16, i16, u32, i32, u64, i64, f32, f64).
    #[arg(long, default_value = "u8")]
    raw_type: String,
    /// Raw input: byte order of multi-byte samples.
    #[arg(long, value_enum, default_value = "little")]
    raw_endian: RawEndian,
    /// Raw input: voxel spacing SX,SY,SZ in mm.
    #[arg(long, value_parser = list::<f64, 3>, default_value = "1,1,1")]
    raw_spacing: [f64; 3],
    /// Raw input: bytes to skip before the first sample.
    #[arg(long, default_value_t = 0)]
    raw_offset: u64,
    /// NaN or infinite voxels: replace them (NaN and -inf by the smallest finite value,
    /// +inf by the largest, with a warning; see docs/io.md) or refuse the volume.
    #[arg(long, value_enum, default_value = "replace")]
    non_finite: NonFiniteRule,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum RawEndian {
    Little,
    Big,
}

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum NonFiniteRule {
    Replace,
    Error,
}

#[derive(Args)]
struct ConvertArgs {
    /// Input volume (any format `info` reads, or a phantom).
    input: String,
    /// Output volume: .nrrd, .nhdr, .npy, .nii or .nii.gz.
    output: PathBuf,
    #[command(flatten)]
    load: LoadArgs,
    /// Keep only the voxels X0..X1, Y0..Y1, Z0..Z1 (index ranges, end exclusive),
    /// given as X0,Y0,Z0,X1,Y1,Z1. The world position of every kept voxel is unchanged.
    #[arg(long, value_parser = list::<usize, 6>)]
    crop: Option<[usize; 6]>,
    /// Resample (after cropping) to NX,NY,NZ voxels over the same box, with --filter.
    #[arg(long, value_parser = list::<usize, 3>, conflicts_with = "spacing")]
    resize: Option<[usize; 3]>,
    /// Resample (after cropping) to this voxel spacing in mm (one value, or SX,SY,SZ),
    /// over the same box, with --filter.
    #[arg(long, value_delimiter = ',')]
    spacing: Option<Vec<f64>>,
    /// Reconstruction filter for resampling (in f64, through the CPU oracle's filters).
    #[arg(long, value_enum, default_value = "trilinear")]
    filter: Filter,
    /// Voxel type of the output: u8, u16, i16 or f32 (values rounded and clamped into
    /// integer types). Default: the input's type, or f32 after resampling.
    #[arg(long = "type")]
    voxel_type: Option<String>,
}

#[derive(Args)]
struct SliceArgs {
    /// Input volume (any format `info` reads, or a phantom).
    input: String,
    #[command(flatten)]
    load: LoadArgs,
    /// The axis across which to cut: z gives a[k, :, :], y a[:, j, :], x a[:, :, i].
    #[arg(long, default_value = "z")]
    axis: String,
    /// Slice index along the axis (default: the middle slice).
    #[arg(long)]
    index: Option<usize>,
    /// Output image: .png (gray) or .npy (float32, raw values).
    #[arg(long)]
    out: PathBuf,
    /// Write 16-bit PNG.
    #[arg(long)]
    sixteen_bit: bool,
    /// Gray-scale window width in data units (with --level); default: the volume's
    /// whole value range, the same for every slice.
    #[arg(long, requires = "level", allow_negative_numbers = true)]
    window: Option<f64>,
    /// Gray-scale window centre in data units (with --window).
    #[arg(long, requires = "window", allow_negative_numbers = true)]
    level: Option<f64>,
}

#[derive(Args)]
struct FvrArgs {
    /// A volume file or phantom:NAME[:N | :NX,NY,NZ] (isotropic voxels only).
    input: String,
    #[command(flatten)]
    load: LoadArgs,
    /// Output image: .png (gray) or .npy (float32, value × mm).
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    view: ViewArgs,
    /// How the spectrum is sampled on the slice (dirichlet: exact, small volumes only).
    #[arg(long, value_enum, default_value = "lanczos3")]
    kernel: voxlab::cpu::fvr::Kernel,
    /// Oversampling factor: the volume is zero-padded to a cube of side
    /// padding × max(dims), rounded up to even.
    #[arg(long, default_value_t = 2)]
    padding: usize,
    /// Divide the image by the kernel's spatial transfer (undo its apodisation).
    #[arg(long)]
    deapodize: bool,
    /// Who computes: cpu (f64 throughout), cpu-f32 (the f64 spectrum rounded to
    /// complex f32, then slice and inverse 2-D FFT in f32), or gpu: the CPU still
    /// builds the 3-D spectrum in f64, which is then uploaded as f32; the slice (nearest, trilinear,
    /// lanczos2/3/4) and the inverse 2-D FFT run on the GPU. gpu needs the padded
    /// side padding × max(dims) (rounded up to even) to be a power of two.
    #[arg(long, default_value = "cpu")]
    backend: String,
    /// Write 16-bit PNG.
    #[arg(long)]
    sixteen_bit: bool,
}

#[derive(Args)]
struct RenderArgs {
    #[command(flatten)]
    scene: SceneArgs,
    /// Output image: .png (8-bit; 16-bit with --sixteen-bit) or .npy (float32: RGBA
    /// (h, w, 4) for DVR, scalar (h, w) for MIP, MinIP and X-ray).
    #[arg(long)]
    out: PathBuf,
    /// Who computes: cpu (the f64 oracle), cpu-f32, gpu (the WGSL port), or auto
    /// (the GPU when a hardware adapter exists, else the CPU oracle; it says which it
    /// used and why).
    #[arg(long, value_enum, default_value = "cpu")]
    backend: Backend,
    /// Write 16-bit PNG.
    #[arg(long)]
    sixteen_bit: bool,
    /// Also write the samples-per-ray image to this file (.png or .npy).
    #[arg(long)]
    samples: Option<PathBuf>,
    /// Render with the pre-integrated DVR caster of docs/adaptive-sampling.md, its
    /// samples placed regularly, adaptively (spectral analysis of the transfer function)
    /// or directly (spectra of the classified volume). DVR only, no shading.
    #[arg(long, value_enum)]
    sampling: Option<voxlab::cpu::adaptive::Sampling>,
    /// Render a stereo pair (parallel eyes, off-axis frusta) laid out as anaglyph
    /// (red = left, green/blue = right), side-by-side (left | right) or interlaced
    /// (even rows left, odd rows right).
    #[arg(long, value_enum)]
    stereo: Option<voxlab::stereo::StereoLayout>,
    /// Stereo: distance between the eyes in mm.
    #[arg(long, default_value_t = 65.0)]
    eye_separation: f64,
    /// Stereo: distance of the zero-parallax plane in mm (default: the eye's distance
    /// to the volume centre).
    #[arg(long)]
    convergence: Option<f64>,
    /// Render the frame N times and report the median time per frame, the volume
    /// prepared once (checked, converted, bounded for skipping) as an interactive
    /// renderer does; the timing quoted against other renderers' frame times.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=1000))]
    repeat: Option<u32>,
    #[command(flatten)]
    accel: AccelArgs,
    #[command(flatten)]
    multi: cli_multi::MultiArgs,
}

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum OnOff {
    On,
    Off,
}

/// Empty-space skipping, clipping and jittered sampling (docs/acceleration.md).
#[derive(Args)]
struct AccelArgs {
    /// Skip cells the transfer function leaves transparent (DVR; the image does not
    /// change). Default: on.
    #[arg(long, value_enum)]
    skip_empty: Option<OnOff>,
    /// Edge of one skipping cell in voxels (default 32).
    #[arg(long)]
    block_size: Option<usize>,
    /// Restrict rays to the box X0,Y0,Z0,X1,Y1,Z1 (∩ the volume), in --clip-space.
    #[arg(long, value_parser = list::<f64, 6>, allow_hyphen_values = true)]
    clip_box: Option<[f64; 6]>,
    /// voxel: voxel indices X0..=X1 (index space [X0 − ½, X1 + ½]); world: millimetres.
    #[arg(long, value_enum, default_value = "voxel")]
    clip_space: voxlab::settings::ClipSpace,
    /// Offset every ray's start by a random fraction of a step from this seed.
    #[arg(long, conflicts_with = "interleaved")]
    jitter: Option<u32>,
    /// Average N jittered frames with seeds SEED … SEED + N − 1 (SEED from --jitter,
    /// default 0).
    #[arg(long)]
    accumulate: Option<usize>,
    /// Offset ray starts by a fixed 4×4 ordered pattern (interleaved sampling).
    #[arg(long)]
    interleaved: bool,
    /// Restrict rays to the inside of a closed triangle mesh (FILE.obj or FILE.ply), or
    /// `bricks`: the boundary of the non-empty skipping cells (DVR; same image).
    #[arg(long)]
    clip_mesh: Option<String>,
    /// Units of the --clip-mesh file's vertices: world millimetres or voxel indices.
    #[arg(long, value_enum, default_value = "world")]
    clip_mesh_units: voxlab::settings::ClipMeshUnits,
}

impl AccelArgs {
    /// Writes the flags given into `s`.
    fn apply(&self, s: &mut RenderSettings) -> Result<()> {
        if let Some(v) = self.skip_empty {
            s.skip_empty = v == OnOff::On;
        }
        if let Some(b) = self.block_size {
            s.block_size = b;
        }
        if let Some(c) = self.clip_box {
            s.clip_box = Some(voxlab::settings::ClipBox {
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
                voxlab::settings::ClipMesh::Bricks
            } else {
                voxlab::settings::ClipMesh::Mesh {
                    mesh: std::sync::Arc::new(voxlab::io::mesh::read_mesh(Path::new(m))?),
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

    /// Renders one frame, or the average of --accumulate jittered frames.
    fn render(
        &self,
        renderer: &Renderer,
        scene: &Scene,
        settings: &RenderSettings,
        progress: &(dyn Fn(usize, usize) + Sync),
    ) -> Result<voxlab::render::Rendered> {
        match self.accumulate {
            Some(n) => voxlab::accumulate::render_accumulated(
                renderer,
                scene,
                settings,
                settings.jitter.unwrap_or(0),
                n,
                &|_, _| {},
            ),
            None => renderer.render(scene, settings, progress),
        }
    }
}

#[derive(Args)]
struct CompareArgs {
    #[command(flatten)]
    scene: SceneArgs,
    /// Folder for cpu.png, gpu.png, diff.png (|Δ| heat map with its scale) and stats.json.
    #[arg(long, default_value = "voxlab-compare")]
    out_dir: PathBuf,
    /// Fail (exit status 3) when any element differs by more than this.
    #[arg(long)]
    max_abs: Option<f64>,
    /// Fail (exit status 3) when the RMS difference exceeds this.
    #[arg(long)]
    rmse: Option<f64>,
    #[command(flatten)]
    accel: AccelArgs,
}

/// Parses exactly `N` comma-separated values, e.g. `1,2,3` for `--light`.
fn list<T: std::str::FromStr, const N: usize>(s: &str) -> std::result::Result<[T; N], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != N {
        return Err(format!(
            "expected {N} comma-separated values, got {}",
            parts.len()
        ));
    }
    let values = parts
        .iter()
        .map(|p| {
            p.parse::<T>()
                .map_err(|_| format!("'{p}' is not a valid number"))
        })
        .collect::<std::result::Result<Vec<T>, String>>()?;
    values
        .try_into()
        .map_err(|_| "wrong number of values".to_string())
}

fn main() -> ExitCode {
    // Die quietly when stdout is a closed pipe (`voxlab info … | head`), as command-line
    // tools do, instead of failing on the write.
    #[cfg(unix)]
    // SAFETY: restores the default disposition of SIGPIPE before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::parse();
    match run(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("voxlab: error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<ExitCode> {
    let limit = match cli.max_voxels {
        Some(n) => Some(n),
        None => match std::env::var("VOXLAB_MAX_VOXELS") {
            Ok(s) => Some(s.trim().parse::<usize>().map_err(|_| {
                Error::invalid("VOXLAB_MAX_VOXELS", format!("'{s}' is not a whole number"))
            })?),
            Err(_) => None,
        },
    };
    if let Some(n) = limit {
        if n == 0 {
            return Err(Error::invalid("--max-voxels", "must be at least 1"));
        }
        voxlab::volume::set_max_voxels(n);
    }
    if let Command::Compare(args) = cli.command {
        return compare(*args);
    }
    if let Command::Fft(args) = cli.command {
        return fft(args);
    }
    if let Command::Bench(args) = cli.command {
        return cli_bench::run(*args);
    }
    run_other(cli.command).map(|()| ExitCode::SUCCESS)
}

fn run_other(command: Command) -> Result<()> {
    match command {
        Command::Demo { out } => demo(&out),
        Command::Render(args) => render(*args),
        Command::Compare(_) | Command::Fft(_) | Command::Bench(_) => {
            unreachable!("handled in run")
        }
        Command::Phantom { spec, out } => {
            let spec = spec.strip_prefix("phantom:").unwrap_or(&spec);
            let (phantom, dims) = voxlab::phantom::parse_spec(spec, 128)?;
            let vol: AnyVolume = phantom.sample(dims)?.into();
            voxlab::io::write_volume(&out, &vol)?;
            println!(
                "wrote {} ({} {}×{}×{}, spacing {:.4} mm)",
                out.display(),
                phantom.name,
                dims[0],
                dims[1],
                dims[2],
                vol.spacing()[0]
            );
            Ok(())
        }
        Command::Convert(args) => convert(*args),
        Command::Slice(args) => slice(*args),
        Command::Fvr(args) => fvr(*args),
        Command::D2vr(args) => cli_d2vr::run(*args),
        Command::Project(args) => cli_project::project(*args),
        Command::Reconstruct(args) => cli_reconstruct::run(*args),
        Command::Process(args) => cli_process::run(*args),
        Command::Adaptive(args) => cli_adaptive::run(*args),
        Command::Info {
            input,
            load,
            plot,
            bins,
            json,
            gpu,
        } => {
            if gpu {
                return gpu_info();
            }
            let input = input.ok_or_else(|| {
                Error::invalid("arguments", "give a volume file or phantom:NAME, or --gpu")
            })?;
            info(&input, &load, bins, json, plot.as_deref())
        }
        Command::Tf { name } => {
            match name {
                None => {
                    for (n, _) in voxlab::transfer::PRESETS {
                        let tf = TransferFunction::preset(n)?;
                        println!(
                            "{n:16} domain [{}, {}], {} points",
                            tf.domain[0],
                            tf.domain[1],
                            tf.points.len()
                        );
                    }
                }
                Some(n) => println!("{}", TransferFunction::preset(&n)?.to_json()),
            }
            Ok(())
        }
    }
}

/// Where a volume came from, for `info`.
fn input_format(input: &str, load: &LoadArgs) -> Result<&'static str> {
    if input.starts_with("phantom:") {
        Ok("analytic phantom")
    } else if load.raw_dims.is_some() {
        Ok(voxlab::io::Format::Raw.name())
    } else {
        Ok(voxlab::io::detect_format(Path::new(input))?.name())
    }
}

/// Loads a volume file, a DICOM directory, a raw file (with `--raw-dims`) or samples
/// `phantom:NAME[:SIZE]`; then applies the non-finite rule: NaN/±inf voxels are
/// reported, and replaced or refused (`--non-finite`).
fn load_input(input: &str, load: &LoadArgs) -> Result<AnyVolume> {
    let mut volume = load_raw_input(input, load)?;
    let count = volume.non_finite();
    if count.total() > 0 {
        let what = format!(
            "{input}: {} NaN, {} +inf and {} -inf voxel(s) (first at index {})",
            count.nan,
            count.pos_inf,
            count.neg_inf,
            count.first.unwrap_or(0)
        );
        match load.non_finite {
            NonFiniteRule::Error => {
                return Err(Error::NonFinite {
                    what: input.to_string(),
                    count: count.total(),
                    first: count.first.unwrap_or(0),
                })
            }
            NonFiniteRule::Replace => {
                volume.replace_non_finite();
                eprintln!(
                    "voxlab: warning: {what}; NaN and -inf replaced by the smallest finite value, \
                     +inf by the largest (--non-finite error refuses instead)"
                );
            }
        }
    }
    Ok(volume)
}

/// Loads without the non-finite rule (`info` reports them as they are).
fn load_raw_input(input: &str, load: &LoadArgs) -> Result<AnyVolume> {
    if let Some(spec) = input.strip_prefix("phantom:") {
        let (phantom, dims) = voxlab::phantom::parse_spec(spec, load.phantom_size)?;
        return Ok(phantom.sample(dims)?.into());
    }
    let path = Path::new(input);
    match &load.raw_dims {
        Some(d) => {
            let spec = voxlab::io::raw::RawSpec {
                dims: *d,
                sample: voxlab::io::raw::RawType::parse(&load.raw_type)?,
                big_endian: matches!(load.raw_endian, RawEndian::Big),
                spacing: load.raw_spacing,
                offset: load.raw_offset,
            };
            voxlab::io::raw::read_raw(path, &spec)
        }
        None => voxlab::io::read_volume(path),
    }
}

fn progress_bar(len: u64, what: &str, unit: &str) -> indicatif::ProgressBar {
    let pb = indicatif::ProgressBar::new(len);
    pb.set_style(
        indicatif::ProgressStyle::with_template(&format!(
            "{{msg}} [{{bar:40}}] {{pos}}/{{len}} {unit}, {{elapsed}} (eta {{eta}})"
        ))
        .expect("valid template")
        .progress_chars("=> "),
    );
    pb.set_message(what.to_string());
    pb
}

/// `--window` (WIDTH with --level, or WIDTH,CENTRE) or `--window-preset`, as
/// `[width, centre]`.
fn window_arg(a: &SceneArgs) -> Result<Option<[f64; 2]>> {
    if let Some(name) = &a.window_preset {
        return voxlab::cpu::modes::window_preset(name).map(Some);
    }
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
    let [w, c] = match (text.split_once(','), a.level) {
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
    };
    if !(w.is_finite() && w > 0.0 && c.is_finite()) {
        return Err(Error::invalid(
            "--window",
            format!("width {w} must be finite and positive, centre {c} finite"),
        ));
    }
    Ok(Some([w, c]))
}

/// One `--iso VALUE:#RRGGBB:OPACITY`.
fn iso_arg(text: &str) -> Result<voxlab::settings::IsoSurface> {
    let bad = |why: String| Error::invalid("--iso", format!("'{text}': {why}"));
    let parts: Vec<&str> = text.split(':').collect();
    let [value, color, opacity] = parts[..] else {
        return Err(bad(
            "expected VALUE:COLOUR:OPACITY, e.g. 0.3:#ff0000:0.4".into()
        ));
    };
    let num = |t: &str, what: &str| {
        t.trim()
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| bad(format!("{what} '{t}' is not a finite number")))
    };
    let hex = color.trim().strip_prefix('#').unwrap_or(color.trim());
    if hex.len() != 6 || !hex.chars().all(|c| c.is_ascii_hexdigit()) {
        return Err(bad(format!("colour '{color}' is not #rrggbb")));
    }
    let channel = |i: usize| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).unwrap() as f64 / 255.0;
    let opacity = num(opacity, "opacity")?;
    if !(0.0..=1.0).contains(&opacity) {
        return Err(bad(format!("opacity {opacity} must lie in [0, 1]")));
    }
    Ok(voxlab::settings::IsoSurface {
        value: num(value, "value")?,
        color: [channel(0), channel(1), channel(2)],
        opacity,
    })
}

/// Loads the input and builds the camera, transfer function and settings.
fn build_scene(a: &SceneArgs, sample_count: bool) -> Result<(Scene, RenderSettings)> {
    let volume = load_input(&a.input, &a.load)?;
    let mut tf = if a.tf == "auto" {
        if a.input.starts_with("phantom:") {
            TransferFunction::preset("phantom")?
        } else {
            let r = volume.value_range();
            TransferFunction::auto_for_range(r.min, r.max)
        }
    } else {
        TransferFunction::preset_or_file(&a.tf)?
    };
    let mut tf2d = match &a.tf2d {
        Some(spec) => Some(voxlab::transfer2d::TransferFunction2D::preset_or_file(
            spec,
        )?),
        None => None,
    };
    if let Some(name) = &a.tf_preset {
        if voxlab::transfer2d::PRESETS_2D
            .iter()
            .any(|(n, _)| n == name)
        {
            tf2d = Some(voxlab::transfer2d::TransferFunction2D::preset(name)?);
        } else {
            tf = TransferFunction::preset(name).map_err(|_| {
                let mut names: Vec<&str> =
                    voxlab::transfer::PRESETS.iter().map(|(n, _)| *n).collect();
                names.extend(voxlab::transfer2d::PRESETS_2D.iter().map(|(n, _)| *n));
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
    let window = window_arg(a)?;
    let grey_window = matches!(a.mode, Mode::Mip | Mode::Minip);
    if let (Some([w, l]), false) = (window, grey_window) {
        tf.window = WindowMap::from_window_level(w, l, tf.domain)?;
        if let Some(t) = tf2d.as_mut() {
            t.window = WindowMap::from_window_level(w, l, t.domain)?;
        }
    }
    let dims = volume.dims();
    let camera = match &a.view.axis {
        Some(v) => {
            let view: AxisView = v.parse()?;
            let (ca, ra) = view.image_axes();
            Camera::axis_view(
                dims,
                volume.affine(),
                view,
                a.width.unwrap_or(dims[ca]),
                a.height.unwrap_or(dims[ra]),
            )?
        }
        None => {
            let d = dims.map(|n| (n as f64 - 1.0) * 0.5);
            let center = volume.affine().transform_point3(glam::DVec3::from_array(d));
            let s = volume.spacing();
            let extent = [
                dims[0] as f64 * s[0],
                dims[1] as f64 * s[1],
                dims[2] as f64 * s[2],
            ];
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
                center,
                extent,
                orbit,
                projection,
                a.width.unwrap_or(256),
                a.height.unwrap_or(256),
            )?
        }
    };
    let settings = match &a.settings {
        Some(p) => {
            let text = std::fs::read_to_string(p).map_err(|e| Error::io(p, e))?;
            serde_json::from_str::<RenderSettings>(&text)
                .map_err(|e| Error::format(p, "render settings JSON", e.to_string()))?
        }
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
            s.shading.enabled = !a.no_shading;
            s.mida_gamma = a.mida_gamma;
            s.window = window.filter(|_| grey_window);
            s.iso_surfaces = a.iso.iter().map(|t| iso_arg(t)).collect::<Result<_>>()?;
            s.iso_opaque = a.iso_opaque;
            s.iso_shadows = a.shadows;
            s.iso_refine = !a.no_iso_refine;
            if let Some(l) = a.light {
                s.shading.light = Light::Direction(l);
            }
            s
        }
    };
    let mut settings = settings;
    if tf2d.is_some() {
        settings.transfer_2d = tf2d;
    }
    settings.validate()?;
    let scene = Scene {
        volume,
        transfer: tf,
        camera,
    };
    Ok((scene, settings))
}

fn render(r: RenderArgs) -> Result<()> {
    check_output(&r.out)?;
    if let Some(s) = &r.samples {
        check_output(s)?;
    }
    let (scene, mut settings) = build_scene(&r.scene, r.samples.is_some())?;
    r.accel.apply(&mut settings)?;
    if r.repeat.is_some() && (r.multi.active() || r.sampling.is_some() || r.stereo.is_some()) {
        return Err(Error::invalid(
            "--repeat",
            "times the single-volume caster; it excludes --stereo, --sampling and extra volumes",
        ));
    }
    if r.multi.active() {
        return cli_multi::render(
            &r.multi,
            &scene,
            &r.scene.load,
            &settings,
            r.backend,
            &r.out,
            r.sixteen_bit,
        );
    }
    if let Some(sampling) = r.sampling {
        return cli_adaptive::render_sampling(
            &scene,
            &settings,
            sampling,
            r.backend,
            &r.out,
            r.samples.as_deref(),
            r.sixteen_bit,
        );
    }
    let a = &r;
    let renderer = Renderer::new(a.backend)?;
    if let Some(why) = &renderer.fallback_reason {
        eprintln!("voxlab: not using a GPU: {why}; rendering with the CPU oracle");
    }
    let who = renderer.describe();
    let pb = progress_bar(
        scene.camera.height as u64,
        &format!("rendering ({who})"),
        "rows",
    );
    let t = std::time::Instant::now();
    if let Some(layout) = a.stereo {
        let v = &scene.volume;
        let d = v.dims().map(|n| (n as f64 - 1.0) * 0.5);
        let center = v.affine().transform_point3(glam::DVec3::from_array(d));
        let conv = a
            .convergence
            .unwrap_or_else(|| (center - scene.camera.eye).dot(scene.camera.forward));
        pb.set_length(2 * scene.camera.height as u64);
        let pair = voxlab::stereo::render_pair(
            &renderer,
            &scene,
            &settings,
            a.eye_separation,
            conv,
            &|done, _| pb.set_position(done as u64),
        )?;
        pb.finish_and_clear();
        let img = voxlab::stereo::combine(&pair.left, &pair.right, layout)?;
        let png = PngOptions {
            sixteen_bit: a.sixteen_bit,
            range: None,
        };
        img.save(&a.out, png)?;
        eprintln!(
            "wrote {} ({}×{}, stereo {:?}, eyes {} mm apart, frustum shift {} px, zero parallax at {:.1} mm, {:.2} s on {})",
            a.out.display(),
            img.width,
            img.height,
            layout,
            a.eye_separation,
            pair.cameras.shift_px,
            pair.cameras.convergence_mm,
            t.elapsed().as_secs_f64(),
            who
        );
        return Ok(());
    }
    let mut per_frame = None;
    let out = match a.repeat {
        Some(n) => {
            if a.accel.accumulate.is_some() {
                return Err(Error::invalid(
                    "--repeat",
                    "times one frame; it excludes --accumulate",
                ));
            }
            let t_prep = std::time::Instant::now();
            let prepared = renderer.prepare(&scene, &settings)?;
            let prep_s = t_prep.elapsed().as_secs_f64();
            pb.set_length(n as u64 * scene.camera.height as u64);
            let mut times = Vec::with_capacity(n as usize);
            let mut last = None;
            for f in 0..n as u64 {
                let h = scene.camera.height as u64;
                let t_f = std::time::Instant::now();
                let r =
                    renderer.render_prepared(&prepared, &scene.camera, &settings, &|done, _| {
                        pb.set_position(f * h + done as u64)
                    })?;
                times.push(t_f.elapsed().as_secs_f64());
                last = Some(r.output);
            }
            times.sort_by(f64::total_cmp);
            per_frame = Some((times[times.len() / 2], times.len(), prep_s));
            last.expect("at least one frame")
        }
        None => {
            a.accel
                .render(&renderer, &scene, &settings, &|done, _| {
                    pb.set_position(done as u64)
                })?
                .output
        }
    };
    pb.finish_and_clear();
    let png = PngOptions {
        sixteen_bit: a.sixteen_bit,
        range: None,
    };
    out.image.save(&a.out, png)?;
    if let (Some(path), Some(samples)) = (&a.samples, &out.samples) {
        samples.save(path, png)?;
    }
    eprintln!(
        "wrote {} ({}×{}, {:?}, {} samples, {:.2} s on {})",
        a.out.display(),
        scene.camera.width,
        scene.camera.height,
        settings.mode,
        out.total_samples,
        per_frame.map_or(t.elapsed().as_secs_f64(), |p| p.0),
        who
    );
    if let Some((median, n, prep)) = per_frame {
        eprintln!(
            "per frame: median {median:.3} s of {n} frames (samples and image: the last frame); \
             the volume prepared once in {prep:.3} s"
        );
    }
    Ok(())
}

/// Renders on the oracle and the GPU, writes the evidence, prints the numbers; exit
/// status 3 when a given tolerance is exceeded.
fn compare(c: CompareArgs) -> Result<ExitCode> {
    let (scene, mut settings) = build_scene(&c.scene, true)?;
    c.accel.apply(&mut settings)?;
    let gpu = Renderer::new(Backend::Gpu)?;
    let pb = progress_bar(scene.camera.height as u64, "cpu (f64 oracle)", "rows");
    let t = std::time::Instant::now();
    let cpu_out = c
        .accel
        .render(&Renderer::new(Backend::Cpu)?, &scene, &settings, &|d, _| {
            pb.set_position(d as u64)
        })?
        .output;
    let cpu_time = t.elapsed().as_secs_f64();
    pb.finish_and_clear();
    let g = c.accel.render(&gpu, &scene, &settings, &|_, _| {})?;
    let timings = g.gpu_timings.unwrap_or_default();
    let tol = voxlab::metrics::Tolerance {
        max_abs: c.max_abs.unwrap_or(f64::INFINITY),
        rmse: c.rmse.unwrap_or(f64::INFINITY),
        ..voxlab::metrics::Tolerance::NONE
    };
    let report =
        voxlab::metrics::check_parity("compare", &cpu_out.image, &g.output.image, tol, None)?;
    voxlab::metrics::write_artifacts(
        &c.out_dir,
        &cpu_out.image,
        &g.output.image,
        &report.stats,
        tol,
    )?;
    let json = serde_json::to_string_pretty(&serde_json::json!({
        "input": c.scene.input,
        "adapter": gpu.describe(),
        "settings": settings,
        "image": [scene.camera.width, scene.camera.height],
        "stats": report.stats,
        "tolerance": { "max_abs": c.max_abs, "rmse": c.rmse },
        "passed": report.passed,
        "cpu_f64_seconds": cpu_time,
        "gpu_seconds": timings,
        "samples": { "cpu": cpu_out.total_samples, "gpu": g.output.total_samples },
    }))
    .expect("serialisable");
    let path = c.out_dir.join("stats.json");
    voxlab::io::write_atomic(&path, |w| {
        w.write_all(json.as_bytes())
            .map_err(|e| Error::io(&path, e))
    })?;
    let s = &report.stats;
    println!("oracle  cpu f64, {:.3} s", cpu_time);
    println!(
        "port    {}, {:.3} s end to end (set-up {:.3}, upload {:.3}, prepare {:.3}, kernel {:.3}{}, readback {:.3})",
        gpu.describe(),
        timings.total,
        timings.setup,
        timings.upload,
        timings.prepare,
        timings.kernel,
        if timings.kernel_from_timestamps { " by timestamps" } else { " wall" },
        timings.readback
    );
    println!(
        "error   max |Δ| {:.3e}, rmse {:.3e}, rel L2 {:.3e}, PSNR {:.1} dB, over tolerance {}/{}",
        s.max_abs, s.rmse, s.rel_l2, s.psnr_db, s.n_over, s.n
    );
    println!(
        "wrote   {}/{{cpu,gpu,diff}}.png and stats.json",
        c.out_dir.display()
    );
    if report.passed {
        Ok(ExitCode::SUCCESS)
    } else {
        eprintln!("voxlab: tolerance exceeded: {}", report.message);
        Ok(ExitCode::from(3))
    }
}

/// Fails early (before a long render) if the output cannot be written.
fn fft(a: FftArgs) -> Result<ExitCode> {
    use voxlab::fft_check::{self, Backends};
    let backends = match a.backend.as_str() {
        "cpu" => Backends {
            cpu: true,
            gpu: false,
        },
        "gpu" => Backends {
            cpu: false,
            gpu: true,
        },
        "all" => Backends {
            cpu: true,
            gpu: true,
        },
        other => {
            return Err(Error::invalid(
                "--backend",
                format!("'{other}' is not cpu, gpu or all"),
            ))
        }
    };
    if a.runs == 0 {
        return Err(Error::invalid("--runs", "must be at least 1"));
    }
    let shapes = a
        .shapes
        .iter()
        .map(|s| fft_check::parse_shape(s))
        .collect::<Result<Vec<_>>>()?;
    let ctx = if backends.gpu {
        match voxlab::gpu::GpuContext::new() {
            Ok(c) => {
                println!("GPU: {}", c.describe());
                Some(c)
            }
            Err(e) if backends.cpu => {
                println!("GPU: none available ({e}); running the CPU only");
                None
            }
            Err(e) => return Err(e),
        }
    } else {
        None
    };
    println!(
        "forward, unnormalised; {} timed run(s) after 1 warm-up; {} CPU threads",
        a.runs,
        rayon::current_num_threads()
    );
    println!("{}", fft_check::TABLE_HEADER);
    let report = fft_check::run(&shapes, backends, a.runs, ctx.as_ref(), &mut |c| {
        println!("{}", fft_check::format_case(c))
    })?;
    if let Some(path) = &a.json {
        let text = serde_json::to_string_pretty(&report)
            .map_err(|e| Error::invalid("FFT report", e.to_string()))?;
        std::fs::write(path, text).map_err(|e| Error::io(path, e))?;
    }
    if report.passed {
        println!("all within tolerance");
        Ok(ExitCode::SUCCESS)
    } else {
        eprintln!("voxlab: an FFT error exceeds its tolerance");
        Ok(ExitCode::from(3))
    }
}

fn check_output(path: &Path) -> Result<()> {
    check_output_as("output file", path, &["png", "npy"])
}

/// `.a`, `.a or .b`, `.a, .b or .c`.
fn extension_list(allowed: &[&str]) -> String {
    let dotted: Vec<String> = allowed.iter().map(|e| format!(".{e}")).collect();
    match dotted.split_last() {
        Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
        _ => dotted.concat(),
    }
}

/// Fails early on an output `what` that cannot be written: an extension not in
/// `allowed`, or a folder that does not exist.
fn check_output_as(what: &str, path: &Path, allowed: &[&str]) -> Result<()> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase());
    if !ext.as_deref().is_some_and(|e| allowed.contains(&e)) {
        return Err(Error::invalid(
            what,
            format!(
                "{}: the extension must be {}",
                path.display(),
                extension_list(allowed)
            ),
        ));
    }
    let parent = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if !parent.is_dir() {
        return Err(Error::invalid(
            what,
            format!(
                "{}: folder {} does not exist",
                path.display(),
                parent.display()
            ),
        ));
    }
    Ok(())
}

/// The nearest world axis of each index axis, as anatomical letters when the format
/// fixes the world frame (NIfTI: RAS+, DICOM: LPS+), else as ±X/±Y/±Z.
fn orientation(affine: glam::DMat4, format: &str) -> String {
    let letters: Option<[[&str; 2]; 3]> = match format {
        "NIfTI-1" => Some([["R", "L"], ["A", "P"], ["S", "I"]]),
        "DICOM" => Some([["L", "R"], ["P", "A"], ["S", "I"]]),
        _ => None,
    };
    let m = glam::DMat3::from_mat4(affine);
    let mut out = Vec::new();
    for c in 0..3 {
        let v = m.col(c).to_array();
        let (axis, val) = v
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .expect("three components");
        let neg = usize::from(*val < 0.0);
        out.push(match letters {
            Some(l) => l[axis][neg].to_string(),
            None => format!("{}{}", ["+", "-"][neg], ["X", "Y", "Z"][axis]),
        });
    }
    match letters {
        Some(_) => format!(
            "{} (index axes x, y, z point to {}; world frame {})",
            out.concat(),
            out.join(", "),
            if format == "DICOM" { "LPS+" } else { "RAS+" }
        ),
        None => format!(
            "x → {}, y → {}, z → {} (world frame as the file gives it)",
            out[0], out[1], out[2]
        ),
    }
}

fn info(input: &str, load: &LoadArgs, bins: usize, json: bool, plot: Option<&Path>) -> Result<()> {
    let format = input_format(input, load)?;
    let v = load_raw_input(input, load)?;
    let r = v.value_range();
    let nf = v.non_finite();
    let h = v.histogram(bins.clamp(1, 4096));
    if let Some(p) = plot {
        // The plot has room for finer bins than the text listing: 256, or one bin per
        // integer value for integer volumes with at most 1024 distinct values.
        let integer = v.kind() != voxlab::volume::VoxelKind::F32;
        let span = r.max - r.min;
        let plot_bins = if integer && span.is_finite() && span < 1024.0 {
            span as usize + 1
        } else {
            256
        };
        voxlab::frame::histogram_plot(&v.histogram(plot_bins), 768, 320)?
            .save(p, Default::default())?;
    }
    let orient = orientation(v.affine(), format);
    if json {
        let j = serde_json::json!({
            "input": input,
            "format": format,
            "dims": v.dims(),
            "spacing_mm": v.spacing(),
            "type": v.kind(),
            "orientation": orient,
            "affine_rows": (0..4).map(|i| v.affine().row(i).to_array()).collect::<Vec<_>>(),
            "range": r,
            "non_finite": nf,
            "histogram": h,
        });
        println!(
            "{}",
            serde_json::to_string_pretty(&j).expect("serialisable")
        );
        return Ok(());
    }
    let d = v.dims();
    let s = v.spacing();
    println!("{input}");
    println!("  format    {format}");
    println!(
        "  dims      {} × {} × {} ({} voxels, {})",
        d[0],
        d[1],
        d[2],
        d[0] * d[1] * d[2],
        v.kind().name()
    );
    println!("  spacing   {:.6} × {:.6} × {:.6} mm", s[0], s[1], s[2]);
    println!("  orient    {orient}");
    let a = v.affine();
    for i in 0..3 {
        let row = a.row(i);
        println!(
            "  affine    [{:10.4} {:10.4} {:10.4} | {:10.4}]",
            row.x, row.y, row.z, row.w
        );
    }
    println!("  range     [{}, {}]", r.min, r.max);
    println!(
        "  NaN/inf   {} NaN, {} +inf, {} -inf",
        nf.nan, nf.pos_inf, nf.neg_inf
    );
    println!("  histogram ({} bins)", h.counts.len());
    let max = h.counts.iter().copied().max().unwrap_or(1).max(1);
    for (b, &c) in h.counts.iter().enumerate() {
        let bar = "#".repeat(((c as f64 / max as f64) * 40.0).round() as usize);
        println!("  {:>12.5} {:>10} {bar}", h.bin_center(b), c);
    }
    if let Some(p) = plot {
        println!("  plot      {}", p.display());
    }
    Ok(())
}

fn fvr(a: FvrArgs) -> Result<()> {
    use voxlab::cpu::fvr::{fvr_project, padded_side, FvrSpectrum, FvrView};
    let (gpu, f32_path) = match a.backend.as_str() {
        "cpu" => (false, false),
        "cpu-f32" => (false, true),
        "gpu" => (true, false),
        other => {
            return Err(Error::invalid(
                "--backend",
                format!("'{other}' is not cpu, cpu-f32 or gpu"),
            ))
        }
    };
    check_output(&a.out)?;
    let view = match &a.view.axis {
        Some(v) => FvrView::Axis(v.parse()?),
        None => FvrView::Orbit {
            azimuth_deg: a.view.azimuth,
            elevation_deg: a.view.elevation,
        },
    };
    let vol = load_input(&a.input, &a.load)?.to_f32();
    let m = padded_side(vol.dims(), a.padding)?;
    eprintln!("3-D FFT of the {m}³ padded volume …");
    let t = std::time::Instant::now();
    let spectrum = FvrSpectrum::new(&vol, a.padding)?;
    eprintln!("  {:.2} s", t.elapsed().as_secs_f64());
    eprintln!("{} slice and 2-D inverse FFT ({m}²) …", a.kernel.name());
    let t = std::time::Instant::now();
    let frame = if gpu {
        use voxlab::gpu::fvr::{fvr_project_timed, GpuFvrSpectrum};
        let ctx = voxlab::gpu::GpuContext::new()?;
        let t_up = std::time::Instant::now();
        let uploaded = GpuFvrSpectrum::upload(&ctx, &spectrum)?;
        let up = t_up.elapsed().as_secs_f64();
        let (frame, tm) = fvr_project_timed(&ctx, &uploaded, view, a.kernel, a.deapodize)?;
        eprintln!(
            "  GPU ({}): spectrum upload {up:.3} s; view {:.3} s (setup {:.3}, slice {:.3}, \
             inverse FFT and readback {:.3}, crop {:.3})",
            ctx.summary.name, tm.total, tm.setup, tm.slice, tm.fft, tm.crop
        );
        frame
    } else if f32_path {
        fvr_project(&spectrum.to_f32(), view, a.kernel, a.deapodize)?
    } else {
        fvr_project(&spectrum, view, a.kernel, a.deapodize)?
    };
    eprintln!("  {:.2} s", t.elapsed().as_secs_f64());
    frame.save(
        &a.out,
        PngOptions {
            sixteen_bit: a.sixteen_bit,
            range: None,
        },
    )?;
    println!(
        "wrote {} ({}×{}, FVR X-ray, {} kernel, padding {}{})",
        a.out.display(),
        frame.width,
        frame.height,
        a.kernel.name(),
        a.padding,
        if a.deapodize { ", de-apodized" } else { "" }
    );
    Ok(())
}

fn slice(a: SliceArgs) -> Result<()> {
    let vol = load_input(&a.input, &a.load)?;
    let axis = match a.axis.to_ascii_lowercase().as_str() {
        "x" => 0,
        "y" => 1,
        "z" => 2,
        other => {
            return Err(Error::invalid(
                "--axis",
                format!("'{other}' is not x, y or z"),
            ))
        }
    };
    let index = a.index.unwrap_or(vol.dims()[axis] / 2);
    let frame = vol.slice(axis, index)?;
    let range = match (a.window, a.level) {
        (Some(w), Some(l)) if w > 0.0 && w.is_finite() && l.is_finite() => {
            (l - 0.5 * w, l + 0.5 * w)
        }
        (Some(_), Some(_)) => {
            return Err(Error::invalid("--window", "must be positive and finite"));
        }
        _ => {
            let r = vol.value_range();
            (r.min, r.max)
        }
    };
    frame.save(
        &a.out,
        PngOptions {
            sixteen_bit: a.sixteen_bit,
            range: Some(range),
        },
    )?;
    println!(
        "wrote {} ({}×{}, axis {} index {index}, gray {} → black, {} → white)",
        a.out.display(),
        frame.width,
        frame.height,
        a.axis,
        range.0,
        range.1
    );
    Ok(())
}

fn convert(c: ConvertArgs) -> Result<()> {
    use voxlab::volume::VoxelKind;
    let mut vol = load_input(&c.input, &c.load)?;
    if let Some(b) = &c.crop {
        vol = vol.crop([b[0], b[1], b[2]], [b[3], b[4], b[5]])?;
    }
    let resample_dims = match (&c.resize, &c.spacing) {
        (Some(d), _) => Some(*d),
        (None, Some(sp)) => {
            let sp: Vec<f64> = if sp.len() == 1 {
                vec![sp[0]; 3]
            } else {
                sp.clone()
            };
            if sp.len() != 3 || !sp.iter().all(|x| x.is_finite() && *x > 0.0) {
                return Err(Error::invalid(
                    "--spacing",
                    "give one or three positive numbers (mm)",
                ));
            }
            let (d, s) = (vol.dims(), vol.spacing());
            Some([0, 1, 2].map(|a| ((d[a] as f64 * s[a] / sp[a]).round() as usize).max(1)))
        }
        (None, None) => None,
    };
    if let Some(dims) = resample_dims {
        let pb = indicatif::ProgressBar::new_spinner();
        pb.set_message(format!(
            "resampling to {}×{}×{} ({:?})",
            dims[0], dims[1], dims[2], c.filter
        ));
        pb.enable_steady_tick(std::time::Duration::from_millis(200));
        let r = voxlab::cpu::filter::resample_volume(&vol.to_f32(), c.filter, dims);
        pb.finish_and_clear();
        vol = r?.into();
    }
    if let Some(t) = &c.voxel_type {
        let kind = match t.to_ascii_lowercase().as_str() {
            "u8" | "uint8" => VoxelKind::U8,
            "u16" | "uint16" => VoxelKind::U16,
            "i16" | "int16" => VoxelKind::I16,
            "f32" | "float32" | "float" => VoxelKind::F32,
            other => {
                return Err(Error::invalid(
                    "--type",
                    format!("'{other}' is not u8, u16, i16 or f32"),
                ))
            }
        };
        vol = vol.convert_to(kind);
    }
    voxlab::io::write_volume(&c.output, &vol)?;
    let d = vol.dims();
    let s = vol.spacing();
    println!(
        "wrote {} ({}×{}×{} {}, spacing {:.4} × {:.4} × {:.4} mm)",
        c.output.display(),
        d[0],
        d[1],
        d[2],
        vol.kind().name(),
        s[0],
        s[1],
        s[2]
    );
    Ok(())
}

fn gpu_info() -> Result<()> {
    let adapters = voxlab::gpu::context::list_adapters();
    if adapters.is_empty() {
        return Err(Error::NoAdapter(
            voxlab::gpu::context::NO_ADAPTER_HELP.into(),
        ));
    }
    println!("adapters (best first):");
    for a in &adapters {
        println!(
            "  {} [{} {}] driver {} {}",
            a.name, a.backend, a.device_type, a.driver, a.driver_info
        );
    }
    let ctx = voxlab::gpu::GpuContext::new()?;
    println!("\nopened:\n{}", ctx.describe());
    let n = voxlab::gpu::probe::self_test(&ctx)?;
    println!("self-test:    {n} values computed on the device match the CPU");
    Ok(())
}

fn demo(out: &Path) -> Result<()> {
    let renderer = Renderer::new(Backend::Auto)?;
    eprintln!(
        "voxlab demo: rendering a gallery of embedded real scans and built-in phantoms on {}…",
        renderer.describe()
    );
    if let Some(why) = &renderer.fallback_reason {
        eprintln!("  (not using a GPU: {why})");
    }
    let t = std::time::Instant::now();
    let items = voxlab::demo::run_demo(out, &renderer, &|item, n, total| {
        eprintln!(
            "  [{n}/{total}] {} ({:.1} s)",
            item.file.display(),
            item.seconds
        );
    })?;
    println!(
        "wrote {} pictures to {} in {:.1} s; open {} to see them",
        items.len(),
        out.display(),
        t.elapsed().as_secs_f64(),
        out.join("index.html").display()
    );
    Ok(())
}
