//! `voxlab render --distributed`: one image rendered by several processes (the ranks
//! of a [`Comm`], MPI's under `mpirun`), each holding one brick of the volume, the
//! pieces composited sort-last (docs/distributed.md).
//!
//! # The decomposition
//! The volume is cut into one brick per rank by the k-d tree of
//! [`crate::io::brick::kd_tree`]. A rank reads only its brick and the ghost voxels its
//! filter and gradients reach ([`crate::cpu::field::brick_ghost`]) — straight from the
//! file when its samples lie uncompressed in one block (a C-order `.npy`, a raw NRRD,
//! an uncompressed MetaImage; [`crate::io::brick::read_brick`]), else from the whole
//! volume, which every rank then reads (phantoms, the embedded scan, DICOM, compressed
//! files). The value range, which scales the shading's threshold and `--tf auto`, is
//! the ranks' ranges joined.
//!
//! # Rendering and compositing
//! Every rank casts every ray of the image with the single-process caster, restricted
//! to the samples its brick owns ([`crate::cpu::raycast::render_owned`] on the CPU
//! backends, [`crate::gpu::raycast::render_owned`] with `--backend gpu`): the rays,
//! their step grids and their sample positions are those of the single-process render,
//! and each sample belongs to exactly one brick. The image is cut into one band of rows
//! per rank; each rank sends every other rank the rectangle of that rank's band its
//! brick covers (direct send: radix-k compositing in one round of `k = N`), and each
//! rank joins the pieces of its band, pixel by pixel, in the order the pixel's ray
//! meets the bricks (the k-d tree walked front to back along the ray,
//! [`crate::io::brick::KdTree::front_to_back`]) with [`crate::cpu::composite`]. Rank 0
//! gathers the bands. A rank sends at most `(N − 1)/N` of its image, the volume binary
//! swap sends; pixels its brick does not cover are not sent at all.
//!
//! # Exactness
//! MIP and MinIP equal the single-process image (of the same backend) exactly; X-ray
//! and DVR equal it up to the regrouping of their sums by brick (and DVR up to
//! `1 − ert` where early ray termination ends a ray inside a brick);
//! `tests/distributed_render.rs` and `tests/gpu_distributed_render.rs` measure both.

use super::distributed::{agree, Comm, Counted};
use super::render::{build_view_for, RenderRequest};
use super::{Backend, Progress};
use crate::camera::Camera;
use crate::cpu::composite::composite_pixel;
use crate::cpu::field::{brick_ghost, BrickField, GridField};
use crate::cpu::grid::Grid;
use crate::cpu::raycast::{render_owned, Owned};
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::gpu::raycast::{render_owned as gpu_render_owned, BrickPlacement};
use crate::io::brick::{kd_tree, raw_layout, read_brick, Brick, KdTree, RawLayout};
use crate::real::Real;
use crate::settings::RenderSettings;
use crate::volume::AnyVolume;
use glam::DMat4;
use std::path::Path;
use std::time::Instant;

/// What one rank did.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderRankReport {
    /// Its brick (without ghost voxels).
    pub brick: Brick,
    /// Voxels it read (its brick and ghost voxels; the whole volume when read whole).
    pub voxels_read: u64,
    /// Seconds reading, ray casting, compositing its band and gathering.
    pub read_seconds: f64,
    pub render_seconds: f64,
    pub composite_seconds: f64,
    pub gather_seconds: f64,
    /// Samples its rays took.
    pub samples: u64,
    /// Bytes it sent to other ranks for the compositing, and for the gather.
    pub composite_bytes: u64,
    /// The most it can send for the compositing: every other rank's band, whole
    /// (binary swap's volume for this cut of the image), with the messages' headers.
    pub composite_bound: u64,
    pub gather_bytes: u64,
    /// Bytes it sent in all (with the agreements and the value range).
    pub bytes_sent: u64,
}

/// A distributed render, as every rank knows it at the end.
#[derive(Clone, Debug)]
pub struct DistributedRendering {
    /// The image (rank 0 only).
    pub image: Option<Frame>,
    /// Samples per ray (rank 0 only, when the request asks for them).
    pub samples: Option<Frame>,
    pub total_samples: u64,
    pub camera: Camera,
    pub settings: RenderSettings,
    pub dims: [usize; 3],
    /// `cpu f64`, `cpu f32` or `gpu`.
    pub what: String,
    /// Whether every rank read the whole volume (not a raw file).
    pub reads_whole: bool,
    /// The bytes per pixel a rank's piece takes (values and the sample count), and the
    /// binary-swap bound on what one rank sends while compositing:
    /// `(N − 1)/N × pixels × pixel bytes`.
    pub pixel_bytes: u64,
    pub binary_swap_bound: u64,
    pub seconds: f64,
    /// Every rank's report, in rank order.
    pub ranks: Vec<RenderRankReport>,
}

impl DistributedRendering {
    /// One line per rank: its brick, what it read, its times and bytes.
    pub fn describe(&self) -> String {
        let mut s = String::new();
        for (r, rep) in self.ranks.iter().enumerate() {
            let b = rep.brick;
            s += &format!(
                "rank {r}: brick x {}..{} y {}..{} z {}..{}, read {} voxels in {:.3} s, \
                 render {:.3} s ({} samples), composite {:.3} s, gather {:.3} s, \
                 sent {} bytes compositing (at most {}) and {} gathering\n",
                b.lo[0],
                b.hi[0],
                b.lo[1],
                b.hi[1],
                b.lo[2],
                b.hi[2],
                rep.voxels_read,
                rep.read_seconds,
                rep.render_seconds,
                rep.samples,
                rep.composite_seconds,
                rep.gather_seconds,
                rep.composite_bytes,
                rep.composite_bound,
                rep.gather_bytes
            );
        }
        s
    }
}

/// The options `--distributed` refuses, checked before anything is read.
fn check(req: &RenderRequest) -> Result<()> {
    let refuse = |what: &str, why: &str| Err(Error::invalid(what.to_string(), why.to_string()));
    let a = &req.scene;
    if req.sampling.is_some() {
        return refuse("--sampling", "does not go with --distributed");
    }
    if req.stereo.is_some() {
        return refuse("--stereo", "does not go with --distributed");
    }
    if req.repeat.is_some() {
        return refuse("--repeat", "does not go with --distributed");
    }
    if !req.volumes.is_empty() {
        return refuse("--volume", "extra volumes do not go with --distributed");
    }
    if a.accel.accumulate.is_some() {
        return refuse("--accumulate", "does not go with --distributed");
    }
    if a.state_file.is_some() {
        return refuse("--state", "does not go with --distributed");
    }
    if a.accel.clip_mesh.as_deref() == Some("bricks") {
        return refuse(
            "--clip-mesh bricks",
            "is built from the whole volume's skipping grid; it does not go with --distributed",
        );
    }
    if a.input.load.raw.is_some() || a.input.load.frame.is_some() {
        return refuse(
            if a.input.load.raw.is_some() {
                "--raw"
            } else {
                "--frame"
            },
            "does not go with --distributed yet: convert the volume to .npy, NRRD or \
             MetaImage first",
        );
    }
    Ok(())
}

/// Where the volume comes from: a raw block each rank reads its brick of, or the whole
/// volume, read by every rank.
enum Source {
    Raw(RawLayout),
    Whole(AnyVolume),
}

impl Source {
    fn open(req: &RenderRequest, progress: &dyn Progress) -> Result<Source> {
        let input = &req.scene.input;
        let file =
            input.memory.is_none() && !input.is_phantom() && !input.source.starts_with("embedded:");
        if file {
            if let Some(layout) = raw_layout(Path::new(&input.source))? {
                return Ok(Source::Raw(layout));
            }
        }
        Ok(Source::Whole(input.load(progress)?))
    }

    fn dims(&self) -> [usize; 3] {
        match self {
            Source::Raw(l) => l.dims,
            Source::Whole(v) => v.dims(),
        }
    }

    fn affine(&self) -> DMat4 {
        match self {
            Source::Raw(l) => l.affine,
            Source::Whole(v) => v.affine(),
        }
    }

    /// The voxels of `b`, and how many voxels were read for them.
    fn brick(&self, b: &Brick, name: &str) -> Result<(AnyVolume, u64)> {
        match self {
            Source::Raw(layout) => {
                let v = read_brick(layout, b, Path::new(name))?;
                let count = v.non_finite();
                if count.total() > 0 {
                    return Err(Error::NonFinite {
                        what: format!("{name} (brick {:?} .. {:?})", b.lo, b.hi),
                        count: count.total(),
                        first: count.first.unwrap_or(0),
                    });
                }
                Ok((v, b.voxels() as u64))
            }
            Source::Whole(v) => Ok((
                v.crop(b.lo, b.hi)?,
                v.dims().iter().product::<usize>() as u64,
            )),
        }
    }
}

/// Renders `req` on every rank of `comm`; rank 0 gets the image. Every rank calls it
/// with the same request; `progress` reports this rank's work (give rank 0 a terminal
/// and the others `&()`).
///
/// # Errors
/// As [`super::render::run`]; options a distributed render does not take (stereo,
/// extra volumes, MIDA, iso-surfaces, pre-classification, filters of unbounded
/// reach); a volume too small to cut into one brick per rank; on more than one rank,
/// [`Error::Rank`] with the lowest failing rank's message.
pub fn run(
    req: &RenderRequest,
    comm: &dyn Comm,
    progress: &dyn Progress,
) -> Result<DistributedRendering> {
    let counted = Counted::new(comm);
    let comm: &dyn Comm = &counted;
    match req.backend {
        Backend::CpuF32 => run_in::<f32>(req, comm, &counted, progress, "cpu f32"),
        Backend::Gpu => run_in::<f32>(req, comm, &counted, progress, "gpu"),
        Backend::Cpu | Backend::Auto => run_in::<f64>(req, comm, &counted, progress, "cpu f64"),
    }
}

/// A brick's voxels (with their ghost voxels) and what reading it took.
struct Read {
    volume: AnyVolume,
    settings: RenderSettings,
    origin: [usize; 3],
    brick: Brick,
    voxels_read: u64,
    seconds: f64,
    range: (f64, f64),
    tree: KdTree,
    source: Source,
}

fn read_mine(
    req: &RenderRequest,
    ranks: usize,
    rank: usize,
    progress: &dyn Progress,
) -> Result<Read> {
    let t = Instant::now();
    check(req)?;
    let source = Source::open(req, progress)?;
    let dims = source.dims();
    let (tree, bricks) = kd_tree(dims, ranks)?;
    let brick = bricks[rank];
    // The filter and gradients come from the request (or its settings file): a view
    // built now, before any voxel is read, says which.
    let (_, _, settings) = build_view_for(&req.scene, dims, source.affine(), || (0.0, 1.0), true)?;
    let mut settings = settings;
    req.scene.accel.apply(&mut settings)?;
    crate::cpu::raycast::check_owned_settings(&settings)?;
    let ghosted = brick.with_ghost(brick_ghost(settings.filter), dims);
    let (volume, voxels_read) = source.brick(&ghosted, &req.scene.input.source)?;
    let r = volume.value_range();
    let range = (r.min, r.max);
    Ok(Read {
        volume,
        settings,
        origin: ghosted.lo,
        brick,
        voxels_read,
        seconds: t.elapsed().as_secs_f64(),
        range,
        tree,
        source,
    })
}

/// Rows `r·h/N .. (r+1)·h/N` of an image `h` rows high: rank `r`'s band.
fn band(r: usize, n: usize, h: usize) -> std::ops::Range<usize> {
    r * h / n..(r + 1) * h / n
}

fn put<R: Real>(out: &mut Vec<u8>, v: R) {
    if std::mem::size_of::<R>() == 4 {
        out.extend_from_slice(&(v.f64() as f32).to_le_bytes());
    } else {
        out.extend_from_slice(&v.f64().to_le_bytes());
    }
}

fn take<R: Real>(b: &mut &[u8]) -> R {
    let n = std::mem::size_of::<R>();
    let (head, rest) = b.split_at(n);
    *b = rest;
    if n == 4 {
        R::of(f32::from_le_bytes(head.try_into().expect("four bytes")) as f64)
    } else {
        R::of(f64::from_le_bytes(head.try_into().expect("eight bytes")))
    }
}

fn take_u32(b: &mut &[u8]) -> u32 {
    let (head, rest) = b.split_at(4);
    *b = rest;
    u32::from_le_bytes(head.try_into().expect("four bytes"))
}

fn run_in<R: Real>(
    req: &RenderRequest,
    comm: &dyn Comm,
    counted: &Counted,
    progress: &dyn Progress,
    what: &str,
) -> Result<DistributedRendering> {
    let t0 = Instant::now();
    let (rank, ranks) = (comm.rank(), comm.size());
    progress.begin("reading the bricks", "ranks", 0);
    let read = agree(comm, read_mine(req, ranks, rank, progress))?;
    progress.end(read.seconds);
    let dims = read.source.dims();
    let affine = read.source.affine();
    // The whole volume's value range: the ranks' ranges joined.
    let all = comm.all_gather(&[read.range.0, read.range.1]);
    let range = all
        .chunks_exact(2)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), r| {
            (l.min(r[0]), h.max(r[1]))
        });
    let (tf, camera, mut settings) = build_view_for(&req.scene, dims, affine, || range, true)?;
    req.scene.accel.apply(&mut settings)?;
    settings.sample_count = req.samples;

    // Every ray, this brick's samples.
    let t = Instant::now();
    let (w, h) = (camera.width, camera.height);
    progress.begin(
        &format!("rendering brick {rank} ({what})"),
        "rows",
        h as u64,
    );
    let rows = |done: usize, total: usize| progress.advance(done as u64, total as u64);
    let partial = super::check_cancel(progress).and_then(|_| {
        if what == "gpu" {
            let placement = BrickPlacement {
                origin: read.origin,
                lo: read.brick.lo,
                hi: read.brick.hi,
                whole: dims,
                affine,
                range,
            };
            let ctx = crate::gpu::GpuContext::shared()?;
            gpu_render_owned(ctx, &read.volume, placement, &tf, &camera, &settings, &rows)
        } else {
            let field = BrickField {
                inner: GridField::<R>::new(
                    Grid::from_any(&read.volume),
                    read.settings.filter,
                    read.settings.gradient,
                    read.settings.precompute_gradients,
                ),
                origin: read.origin,
                whole: dims,
                range,
            };
            let own = Owned::new(read.brick.lo, read.brick.hi, dims);
            render_owned(&field, affine, &tf, &camera, &settings, own, &rows)
        }
    });
    // This rank's own time, before it waits for the others.
    let render_seconds = t.elapsed().as_secs_f64();
    let partial = agree(comm, partial)?;
    progress.end(render_seconds);
    let samples: u64 = partial.counts.iter().map(|&c| c as u64).sum();

    // Direct send: each rank gets the pieces of its band.
    let t = Instant::now();
    let sent0 = counted.sent();
    let ch = partial.image.channels;
    let real = std::mem::size_of::<R>();
    let pixel_bytes = (ch * real + 4) as u64;
    let messages: Vec<Vec<u8>> = (0..ranks)
        .map(|dest| {
            let rows = band(dest, ranks, h);
            // The rectangle of the band this brick covers.
            let (mut r0, mut r1, mut c0, mut c1) = (usize::MAX, 0, usize::MAX, 0);
            for row in rows.clone() {
                for col in 0..w {
                    if partial.counts[row * w + col] > 0 {
                        r0 = r0.min(row);
                        r1 = r1.max(row + 1);
                        c0 = c0.min(col);
                        c1 = c1.max(col + 1);
                    }
                }
            }
            let mut m = Vec::new();
            if r0 == usize::MAX {
                return m;
            }
            for x in [r0, r1, c0, c1] {
                m.extend_from_slice(&(x as u32).to_le_bytes());
            }
            m.reserve((r1 - r0) * (c1 - c0) * pixel_bytes as usize);
            for row in r0..r1 {
                for col in c0..c1 {
                    let p = row * w + col;
                    for c in 0..ch {
                        put(&mut m, R::of(partial.image.data[p * ch + c]));
                    }
                    m.extend_from_slice(&partial.counts[p].to_le_bytes());
                }
            }
            m
        })
        .collect();
    drop(partial.image);
    let got = comm.all_to_all(messages);
    let composite_bytes = counted.sent() - sent0;
    let mine = band(rank, ranks, h);
    let n_px = mine.len() * w;
    // The pieces of this band, per source rank (= brick).
    let mut pieces: Vec<Vec<([R; 4], u32)>> = vec![vec![([R::zero(); 4], 0); n_px]; ranks];
    for (src, m) in got.iter().enumerate() {
        if m.is_empty() {
            continue;
        }
        let mut b = &m[..];
        let (r0, r1, c0, c1) = (
            take_u32(&mut b) as usize,
            take_u32(&mut b) as usize,
            take_u32(&mut b) as usize,
            take_u32(&mut b) as usize,
        );
        for row in r0..r1 {
            for col in c0..c1 {
                let mut v = [R::zero(); 4];
                for x in v.iter_mut().take(ch) {
                    *x = take::<R>(&mut b);
                }
                let n = take_u32(&mut b);
                pieces[src][(row - mine.start) * w + col] = (v, n);
            }
        }
    }
    let to_index = affine.inverse();
    let mut order = Vec::with_capacity(ranks);
    let mut band_out = Vec::with_capacity(n_px * (ch * real + 4));
    for row in mine.clone() {
        for col in 0..w {
            let p = (row - mine.start) * w + col;
            let d = to_index.transform_vector3(camera.ray(col, row).dir);
            let hit = partial.hits[row * w + col];
            let (px, n) = composite_pixel(
                &read.tree,
                d.to_array(),
                &settings,
                hit,
                |b| pieces[b][p],
                &mut order,
            );
            for &v in px.iter().take(ch) {
                put(&mut band_out, v);
            }
            band_out.extend_from_slice(&n.to_le_bytes());
        }
    }
    drop(pieces);
    let composite_seconds = t.elapsed().as_secs_f64();

    // Rank 0 gathers the bands.
    let t = Instant::now();
    let sent0 = counted.sent();
    let bands = comm.gather(0, band_out);
    let gather_bytes = counted.sent() - sent0;
    let (image, sample_frame) = if rank == 0 {
        let mut image = Frame::new(w, h, ch);
        let mut counts = vec![0f64; w * h];
        for (r, m) in bands.iter().enumerate() {
            let mut b = &m[..];
            for row in band(r, ranks, h) {
                for col in 0..w {
                    let p = row * w + col;
                    for c in 0..ch {
                        image.data[p * ch + c] = take::<R>(&mut b).f64();
                    }
                    counts[p] = take_u32(&mut b) as f64;
                }
            }
        }
        let samples = req.samples.then_some(Frame {
            width: w,
            height: h,
            channels: 1,
            data: counts,
        });
        (Some(image), samples)
    } else {
        (None, None)
    };
    let gather_seconds = t.elapsed().as_secs_f64();

    // Every rank's report.
    let b = read.brick;
    let mine = [
        b.lo[0] as f64,
        b.lo[1] as f64,
        b.lo[2] as f64,
        b.hi[0] as f64,
        b.hi[1] as f64,
        b.hi[2] as f64,
        read.voxels_read as f64,
        read.seconds,
        render_seconds,
        composite_seconds,
        gather_seconds,
        samples as f64,
        composite_bytes as f64,
        ((h - band(rank, ranks, h).len()) * w) as f64 * pixel_bytes as f64
            + 16.0 * (ranks - 1) as f64,
        gather_bytes as f64,
        counted.sent() as f64,
    ];
    let all = comm.all_gather(&mine);
    let reports: Vec<RenderRankReport> = all
        .chunks_exact(mine.len())
        .map(|r| RenderRankReport {
            brick: Brick {
                lo: [r[0] as usize, r[1] as usize, r[2] as usize],
                hi: [r[3] as usize, r[4] as usize, r[5] as usize],
            },
            voxels_read: r[6] as u64,
            read_seconds: r[7],
            render_seconds: r[8],
            composite_seconds: r[9],
            gather_seconds: r[10],
            samples: r[11] as u64,
            composite_bytes: r[12] as u64,
            composite_bound: r[13] as u64,
            gather_bytes: r[14] as u64,
            bytes_sent: r[15] as u64,
        })
        .collect();
    let pixels = (w * h) as u64;
    Ok(DistributedRendering {
        image,
        samples: sample_frame,
        total_samples: reports.iter().map(|r| r.samples).sum(),
        camera,
        settings,
        dims,
        what: what.into(),
        reads_whole: matches!(read.source, Source::Whole(_)),
        pixel_bytes,
        binary_swap_bound: pixels * pixel_bytes * (ranks as u64 - 1) / ranks as u64,
        seconds: t0.elapsed().as_secs_f64(),
        ranks: reports,
    })
}
