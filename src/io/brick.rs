//! Bricks: a box of a volume's voxels read straight from its file, without reading the
//! rest (the input of a distributed job, where no rank holds the whole volume), and the
//! k-d tree of bricks a volume is cut into for a number of ranks.
//!
//! A file can be read brick by brick when its samples are stored uncompressed in one
//! block: a C-order `.npy` array, a raw-encoded NRRD (attached or detached, any byte
//! skip, no line skip), or an uncompressed binary MetaImage (`.mha`, or `.mhd` with one
//! data file). [`raw_layout`] says where that block is; [`read_brick`]
//! reads one box of it, one positioned read per run of rows of `x` that follow each
//! other in the file, and decodes the
//! samples exactly as the whole-file reader does, so a brick equals the same box cut
//! from the whole volume, bit for bit, with the affine moved to the brick's first voxel.
//! [`read_lines`] reads whole lines of `x` the same way (a projection stack's detector
//! lines, [`crate::io::projections::read_projection_lines`]).
//!
//! The reads are positioned (`pread`), not a memory map: a file that shrinks while it
//! is mapped kills the process with a bus error when the lost pages are touched, where
//! a read gives an error naming the file; and the samples are decoded into a new
//! buffer anyway, so a map would save no copy.

use super::read_samples;
pub use super::RawLayout;
use crate::error::{Error, Result};
use crate::volume::{check_dims, max_voxels, AnyVolume};
use glam::{DMat4, DVec3};
use std::path::Path;

/// A box of voxels: `lo[a] .. hi[a]` along each axis (x, y, z).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Brick {
    pub lo: [usize; 3],
    pub hi: [usize; 3],
}

impl Brick {
    /// The whole of a volume of `dims`.
    pub fn all(dims: [usize; 3]) -> Brick {
        Brick {
            lo: [0; 3],
            hi: dims,
        }
    }

    /// Voxels along each axis.
    pub fn dims(&self) -> [usize; 3] {
        std::array::from_fn(|a| self.hi[a].saturating_sub(self.lo[a]))
    }

    /// How many voxels it holds.
    pub fn voxels(&self) -> usize {
        self.dims().iter().product()
    }

    /// This brick grown by `ghost` voxels on every side, within a volume of `dims`.
    pub fn with_ghost(&self, ghost: usize, dims: [usize; 3]) -> Brick {
        Brick {
            lo: std::array::from_fn(|a| self.lo[a].saturating_sub(ghost)),
            hi: std::array::from_fn(|a| (self.hi[a] + ghost).min(dims[a])),
        }
    }

    /// The two boxes either side of the plane between slices `at − 1` and `at` of
    /// `axis` (the low side first).
    fn cut(&self, axis: usize, at: usize) -> (Brick, Brick) {
        let (mut low, mut high) = (*self, *self);
        low.hi[axis] = at;
        high.lo[axis] = at;
        (low, high)
    }
}

/// Where `path` keeps its samples when it can be read brick by brick (module docs);
/// `None` for every other file (compressed or text data, Fortran order, other formats).
///
/// # Errors
/// A bad header; a file too short for the data its header announces.
pub fn raw_layout(path: &Path) -> Result<Option<RawLayout>> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("npy") => super::npy::raw_layout(path),
        Some("nrrd") | Some("nhdr") => super::nrrd::raw_layout(path),
        Some("mha") | Some("mhd") => super::metaimage::raw_layout(path),
        _ => Ok(None),
    }
}

/// Reads the voxels of `brick` from the block `layout` describes (`path`, the file
/// the user named, in errors): a volume of the brick's size whose affine puts its
/// voxel 0 where the whole volume's voxel `brick.lo` is.
///
/// # Errors
/// An empty brick or one outside the volume; I/O errors.
pub fn read_brick(layout: &RawLayout, brick: &Brick, path: &Path) -> Result<AnyVolume> {
    let d = layout.dims;
    if (0..3).any(|a| brick.lo[a] >= brick.hi[a] || brick.hi[a] > d[a]) {
        return Err(Error::invalid(
            format!("brick of {}", path.display()),
            format!(
                "{:?} .. {:?} is empty or leaves the {}×{}×{} volume",
                brick.lo, brick.hi, d[0], d[1], d[2]
            ),
        ));
    }
    let bd = brick.dims();
    check_dims(bd)?;
    if brick.voxels() > max_voxels() {
        return Err(Error::too_large(
            format!("brick of {}", path.display()),
            format!("{} voxels (limit {})", brick.voxels(), max_voxels()),
        ));
    }
    let size = layout.stored.size();
    let row = bd[0] * size;
    let mut bytes = super::reserve::<u8>(brick.voxels() * size, path)?;
    bytes.resize(brick.voxels() * size, 0);
    let (file, _) = super::open(&layout.data)?;
    // The box's rows of x, in file order; rows that follow each other in the file (a
    // box as wide as the volume) are read as one run: one positioned read per run.
    let mut at = 0;
    let mut run: Option<(u64, usize)> = None;
    let mut read = |(start, len): (u64, usize), at: &mut usize| {
        super::read_at(&file, start, &mut bytes[*at..*at + len])
            .map_err(|e| super::read_error(&layout.data, e))?;
        *at += len;
        Ok::<(), Error>(())
    };
    for k in brick.lo[2]..brick.hi[2] {
        for j in brick.lo[1]..brick.hi[1] {
            let start = layout.offset + ((brick.lo[0] + d[0] * (j + d[1] * k)) * size) as u64;
            run = match run {
                Some((s, len)) if s + len as u64 == start => Some((s, len + row)),
                Some(done) => {
                    read(done, &mut at)?;
                    Some((start, row))
                }
                None => Some((start, row)),
            };
        }
    }
    if let Some(done) = run {
        read(done, &mut at)?;
    }
    let samples = read_samples(
        &mut &bytes[..],
        layout.stored,
        layout.endian,
        brick.voxels(),
        path,
    )?;
    let lo = DVec3::new(brick.lo[0] as f64, brick.lo[1] as f64, brick.lo[2] as f64);
    samples.into_volume(bd, layout.affine * DMat4::from_translation(lo))
}

/// Reads whole lines of `x` from the block `layout` describes (`path`, the file the
/// user named, in errors): line `y + ny·z` holds the voxels `(0..nx, y, z)`. Returns
/// the lines read (`lines` sorted, each once) and their values in f64, line after
/// line, decoded as the whole-file reader decodes them (so each value is the whole
/// volume's, bit for bit); one positioned read per run of consecutive lines, nothing else read
/// or held.
///
/// # Errors
/// A line past the volume's `ny·nz`; more values than a volume may hold; I/O errors.
pub fn read_lines(
    layout: &RawLayout,
    lines: &[usize],
    path: &Path,
) -> Result<(Vec<usize>, Vec<f64>)> {
    let [nx, ny, nz] = layout.dims;
    let total = ny * nz;
    if let Some(&bad) = lines.iter().find(|&&l| l >= total) {
        return Err(Error::invalid(
            format!("lines of {}", path.display()),
            format!("line {bad} is past the volume's {total} lines of x"),
        ));
    }
    let mut wanted = lines.to_vec();
    wanted.sort_unstable();
    wanted.dedup();
    let count = wanted.len() * nx;
    if count > max_voxels() {
        return Err(Error::too_large(
            format!("lines of {}", path.display()),
            format!("{count} values (limit {})", max_voxels()),
        ));
    }
    let mut values = super::reserve::<f64>(count, path)?;
    values.resize(count, 0.0);
    let size = layout.stored.size();
    let (file, _) = super::open(&layout.data)?;
    super::read_line_runs(
        &file,
        &layout.data,
        layout.offset,
        nx * size,
        &wanted,
        |at, bytes| {
            let n = bytes.len() / size;
            let samples = read_samples(&mut &bytes[..], layout.stored, layout.endian, n, path)?;
            for (v, x) in values[at * nx..at * nx + n]
                .iter_mut()
                .zip(samples.into_f32())
            {
                *v = f64::from(x);
            }
            Ok(())
        },
    )?;
    Ok((wanted, values))
}

/// Cuts a volume of `dims` into `n` bricks by a k-d tree: the box's longest axis is
/// cut where the two sides get voxels in proportion to their ranks (`⌊n/2⌋` and
/// `⌈n/2⌉`), recursively. The bricks tile the volume, in the tree's order (the first
/// half before the second along each cut).
///
/// # Errors
/// `n` = 0; more bricks than a box can be cut into (a box 1 voxel wide on every axis
/// that should hold two).
pub fn kd_bricks(dims: [usize; 3], n: usize) -> Result<Vec<Brick>> {
    Ok(kd_tree(dims, n)?.1)
}

/// The k-d tree of [`kd_bricks`]: its cuts, and its bricks (the leaves, in order).
///
/// # Errors
/// As [`kd_bricks`].
pub fn kd_tree(dims: [usize; 3], n: usize) -> Result<(KdTree, Vec<Brick>)> {
    if n == 0 {
        return Err(Error::invalid("bricks", "a volume needs at least one"));
    }
    let mut out = Vec::with_capacity(n);
    let tree = split(Brick::all(dims), n, &mut out)?;
    Ok((tree, out))
}

/// The k-d tree with the fewest bricks each of which, with `ghost` voxels around it
/// (clipped to the volume), holds at most `max_texels` per axis and, where given,
/// `max_voxels` in all: one brick when the volume fits whole. Two families are tried:
/// [`kd_tree`]'s proportional cuts of `n` bricks (the smallest `n` that fits), and a
/// regular grid of `kx × ky × kz` bricks ([`grid_tree`], the fewest that fit), whose
/// cuts fall on the same planes across the volume, so its bricks never come out
/// narrower than needed (a 64³ volume under 32 texels with 3 ghost voxels: 27 bricks
/// against the proportional cuts' 60). The fewer bricks win; the proportional cuts
/// on a tie. When no grid fits, neither does any k-d tree (the brick holding the
/// volume's middle voxel is as wide as the grid's one-voxel bricks, ghost voxels
/// included) or it would need more than 65,536 bricks, so the refusal comes at once.
/// The GPU casters' split planners ask it.
///
/// # Errors
/// [`Error::TooLarge`] when no cut fits (a limit below the ghost voxels), naming the
/// limits and `reach`, what the ghost voxels are for ("the catmull-rom filter's 2 ghost
/// voxels").
pub fn fitting_kd_tree(
    dims: [usize; 3],
    ghost: usize,
    max_texels: usize,
    max_voxels: Option<u64>,
    reach: &str,
) -> Result<(KdTree, Vec<Brick>)> {
    let fits = |b: &Brick| {
        let g = b.with_ghost(ghost, dims);
        g.dims().iter().all(|&n| n <= max_texels)
            && max_voxels.is_none_or(|m| g.voxels() as u64 <= m)
    };
    let grid = grid_counts(dims, ghost, max_texels, max_voxels)
        .map(|k| grid_tree(dims, k))
        .filter(|(_, bricks)| bricks.iter().all(fits));
    let most = grid.as_ref().map_or(0, |(_, b)| b.len());
    for n in 1..=most {
        match kd_tree(dims, n) {
            Ok((tree, bricks)) if bricks.iter().all(fits) => return Ok((tree, bricks)),
            Ok(_) => {}
            Err(_) => break,
        }
    }
    grid.ok_or_else(|| {
        let voxels = max_voxels
            .map(|m| format!(" and {m} texels in all"))
            .unwrap_or_default();
        Error::too_large(
            "volume",
            format!(
                "{dims:?} cannot be cut into bricks of at most {max_texels} texels per \
                 axis{voxels} with {reach}"
            ),
        )
    })
}

/// The most bricks a split planner cuts a volume into.
const MAX_BRICKS: usize = 1 << 16;

/// The widest a brick of a regular grid of `k` pieces along an axis of `n` voxels gets
/// with its ghost voxels, clipped to the axis: exactly `⌈n/2⌉ + ghost` for two pieces
/// (each has one inner face), at most `⌈n/k⌉ + 2·ghost` for more (an upper bound; the
/// planner checks the real bricks).
fn grid_width(n: usize, k: usize, ghost: usize) -> usize {
    match k {
        0 | 1 => n,
        2 => (n.div_ceil(2) + ghost).min(n),
        _ => (n.div_ceil(k) + 2 * ghost).min(n),
    }
}

/// The fewest pieces per axis `[kx, ky, kz]` (at most [`MAX_BRICKS`] in all) whose
/// regular grid's bricks, with their ghost voxels, fit `max_texels` per axis and
/// `max_voxels` in all; `None` when none does.
fn grid_counts(
    dims: [usize; 3],
    ghost: usize,
    max_texels: usize,
    max_voxels: Option<u64>,
) -> Option<[usize; 3]> {
    let w = |a: usize, k: usize| grid_width(dims[a], k, ghost);
    // The fewest pieces along each axis for the texel limit alone (the width does not
    // grow with k).
    let least: Vec<usize> = (0..3)
        .map(|a| (1..=dims[a].max(1)).find(|&k| w(a, k) <= max_texels))
        .collect::<Option<_>>()?;
    let mut best: Option<[usize; 3]> = None;
    let mut bound = MAX_BRICKS + 1;
    for kx in least[0]..=dims[0].max(1) {
        if kx * least[1] * least[2] >= bound {
            break;
        }
        for ky in least[1]..=dims[1].max(1) {
            if kx * ky * least[2] >= bound {
                break;
            }
            for kz in least[2]..=dims[2].max(1) {
                if kx * ky * kz >= bound {
                    break;
                }
                let voxels = (w(0, kx) * w(1, ky) * w(2, kz)) as u64;
                if max_voxels.is_none_or(|m| voxels <= m) {
                    bound = kx * ky * kz;
                    best = Some([kx, ky, kz]);
                    break;
                }
            }
        }
    }
    best
}

/// A volume of `dims` cut into a regular grid of `k = [kx, ky, kz]` bricks (piece `i`
/// of an axis of `n` voxels spans `⌊i·n/k⌋ … ⌊(i+1)·n/k⌋`), as a k-d tree: each cut
/// halves the pieces of the axis that has the most left. Each `k` must lie in
/// `1 ..= n`.
pub fn grid_tree(dims: [usize; 3], k: [usize; 3]) -> (KdTree, Vec<Brick>) {
    fn node(
        dims: [usize; 3],
        k: [usize; 3],
        pieces: [(usize, usize); 3],
        out: &mut Vec<Brick>,
    ) -> KdTree {
        let at = |a: usize, i: usize| i * dims[a] / k[a];
        let axis = (0..3)
            .max_by_key(|&a| (pieces[a].1 - pieces[a].0, a))
            .unwrap_or(0);
        let (i0, i1) = pieces[axis];
        if i1 - i0 <= 1 {
            out.push(Brick {
                lo: std::array::from_fn(|a| at(a, pieces[a].0)),
                hi: std::array::from_fn(|a| at(a, pieces[a].1)),
            });
            return KdTree::Leaf(out.len() - 1);
        }
        let mid = i0 + (i1 - i0) / 2;
        let (mut low, mut high) = (pieces, pieces);
        low[axis].1 = mid;
        high[axis].0 = mid;
        KdTree::Cut {
            axis,
            cut: at(axis, mid),
            low: Box::new(node(dims, k, low, out)),
            high: Box::new(node(dims, k, high, out)),
        }
    }
    let mut out = Vec::with_capacity(k.iter().product());
    let tree = node(dims, k, std::array::from_fn(|a| (0, k[a])), &mut out);
    (tree, out)
}

/// The k-d tree with the fewest bricks that each satisfy `fits`, of two families:
/// [`halved_kd_tree`]'s halvings, and a regular grid ([`grid_tree`]) with fewer bricks
/// (the halvings win a tie). `fits` must hold for a box's sub-boxes where it holds for
/// the box (true of every size limit). `None` where the halvings find none, for then
/// no grid fits either (a one-voxel cell fails, or it would take more than 65,536): the
/// multi-volume caster's cells, each holding its own part of every volume.
pub fn fewest_kd_tree(
    dims: [usize; 3],
    fits: &dyn Fn(&Brick) -> bool,
) -> Option<(KdTree, Vec<Brick>)> {
    let halved = halved_kd_tree(dims, fits)?;
    match fewest_grid(dims, fits, halved.1.len()) {
        Some(k) => Some(grid_tree(dims, k)),
        None => Some(halved),
    }
}

/// The pieces per axis of the regular grid with the fewest bricks, fewer than
/// `fewer_than`, each of which satisfies `fits`; `None` when no such grid does.
fn fewest_grid(
    dims: [usize; 3],
    fits: &dyn Fn(&Brick) -> bool,
    fewer_than: usize,
) -> Option<[usize; 3]> {
    let every = |k: [usize; 3]| {
        let at = |a: usize, i: usize| i * dims[a] / k[a];
        (0..k[2]).all(|z| {
            (0..k[1]).all(|y| {
                (0..k[0]).all(|x| {
                    fits(&Brick {
                        lo: [at(0, x), at(1, y), at(2, z)],
                        hi: [at(0, x + 1), at(1, y + 1), at(2, z + 1)],
                    })
                })
            })
        })
    };
    let mut best = None;
    let mut bound = fewer_than;
    for kx in 1..=dims[0] {
        if kx >= bound {
            break;
        }
        for ky in 1..=dims[1] {
            if kx * ky >= bound {
                break;
            }
            // More pieces along z only make the bricks smaller: the first that fits is
            // the fewest for this kx, ky.
            for kz in 1..=dims[2] {
                if kx * ky * kz >= bound {
                    break;
                }
                if every([kx, ky, kz]) {
                    bound = kx * ky * kz;
                    best = Some([kx, ky, kz]);
                    break;
                }
            }
        }
    }
    best
}

/// The k-d tree whose bricks each satisfy `fits`, a brick that does not halved at the
/// middle of its longest axis: the planner of a split whose pieces differ in what they
/// hold (the multi-volume caster's cells, each holding its own part of every volume).
/// `None` when a brick one voxel wide on every axis does not fit, or past 65,536 bricks.
pub fn halved_kd_tree(
    dims: [usize; 3],
    fits: &dyn Fn(&Brick) -> bool,
) -> Option<(KdTree, Vec<Brick>)> {
    fn halve(b: Brick, fits: &dyn Fn(&Brick) -> bool, out: &mut Vec<Brick>) -> Option<KdTree> {
        if out.len() >= 1 << 16 {
            return None;
        }
        if fits(&b) {
            out.push(b);
            return Some(KdTree::Leaf(out.len() - 1));
        }
        let bd = b.dims();
        let axis = (0..3).max_by_key(|&a| (bd[a], a)).unwrap_or(0);
        if bd[axis] < 2 {
            return None;
        }
        let cut = b.lo[axis] + bd[axis] / 2;
        let (first, second) = b.cut(axis, cut);
        let low = Box::new(halve(first, fits, out)?);
        let high = Box::new(halve(second, fits, out)?);
        Some(KdTree::Cut {
            axis,
            cut,
            low,
            high,
        })
    }
    let mut out = Vec::new();
    let tree = halve(Brick::all(dims), fits, &mut out)?;
    Some((tree, out))
}

/// A k-d tree of bricks: a leaf names its brick (its index in [`kd_tree`]'s list); a
/// cut divides a box by the plane between voxel slices `cut − 1` and `cut` of `axis`
/// (index coordinate `cut − ½`), `low` holding the voxels below it.
#[derive(Clone, Debug, PartialEq)]
pub enum KdTree {
    Leaf(usize),
    Cut {
        axis: usize,
        cut: usize,
        low: Box<KdTree>,
        high: Box<KdTree>,
    },
}

impl KdTree {
    /// The bricks in the order a ray of index-space direction `d` meets them: at each
    /// cut the low side first when `d` runs up the cut's axis, the high side first
    /// otherwise (a ray parallel to the plane never crosses it, so either order is
    /// right). Appends to `order`.
    pub fn front_to_back(&self, d: [f64; 3], order: &mut Vec<usize>) {
        self.visit(&|axis, _| d[axis] >= 0.0, order);
    }

    /// The bricks in the order every ray leaving the index-space point `eye` meets
    /// them (a perspective camera's rays): at each cut the side holding `eye` first.
    /// A ray from `eye` crosses a cut's plane only away from `eye`'s side, so this one
    /// order is each ray's own. Appends to `order`.
    pub fn front_to_back_from(&self, eye: [f64; 3], order: &mut Vec<usize>) {
        self.visit(&|axis, cut| eye[axis] < cut as f64 - 0.5, order);
    }

    /// The leaves, at each cut the low side first where `low_first(axis, cut)`.
    fn visit(&self, low_first: &dyn Fn(usize, usize) -> bool, order: &mut Vec<usize>) {
        match self {
            KdTree::Leaf(b) => order.push(*b),
            KdTree::Cut {
                axis,
                cut,
                low,
                high,
            } => {
                let (first, second) = if low_first(*axis, *cut) {
                    (low, high)
                } else {
                    (high, low)
                };
                first.visit(low_first, order);
                second.visit(low_first, order);
            }
        }
    }
}

fn split(b: Brick, n: usize, out: &mut Vec<Brick>) -> Result<KdTree> {
    if n == 1 {
        out.push(b);
        return Ok(KdTree::Leaf(out.len() - 1));
    }
    let bd = b.dims();
    let axis = (0..3).max_by_key(|&a| (bd[a], a)).unwrap_or(0);
    let (n1, n2) = (n / 2, n - n / 2);
    // The cut leaves each side at least one slice per brick it must hold.
    let cut = b.lo[axis] + bd[axis] * n1 / n;
    if cut <= b.lo[axis] || cut >= b.hi[axis] {
        return Err(Error::invalid(
            "bricks",
            format!(
                "a {}×{}×{} box cannot be cut into {n} bricks along its longest axis",
                bd[0], bd[1], bd[2]
            ),
        ));
    }
    let (first, second) = b.cut(axis, cut);
    let low = Box::new(split(first, n1, out)?);
    let high = Box::new(split(second, n2, out)?);
    Ok(KdTree::Cut {
        axis,
        cut,
        low,
        high,
    })
}
