//! Clipping meshes: a closed triangle mesh restricts every ray to the parts inside it
//! (Gavrilov & Turlapov, InVols: mesh-based clipping, and empty-space skipping with a
//! mesh made of the non-empty cells of the acceleration grid).
//!
//! **Coordinates.** A mesh is given in world millimetres (the volume's world frame),
//! or in voxel indices (`ClipMeshUnits::Voxel`), which are carried to world by the
//! volume's affine before anything else. Ray parameters are world millimetres along
//! the unit camera direction, the same `t` the ray caster steps in.
//!
//! **Ray–triangle test** (watertight, Woop, Benthin & Wald, JCGT 2013): with `k_z` the
//! axis of the largest `|d|` and `k_x, k_y` the other two (swapped when `d_kz < 0` to
//! keep the winding), each corner `P` is taken relative to the ray origin and sheared
//! so that the ray becomes the `z` axis: `P'_x = P_kx − S_x P_kz`, `P'_y = P_ky − S_y P_kz`
//! with `S_x = d_kx/d_kz`, `S_y = d_ky/d_kz`. The 2D edge functions
//! `U = C'_x B'_y − C'_y B'_x`, `V = A'_x C'_y − A'_y C'_x`, `W = B'_x A'_y − B'_y A'_x`
//! decide the hit (all ≥ 0 or all ≤ 0, `det = U + V + W ≠ 0`), and
//! `t = (U A_kz + V B_kz + W C_kz) / (det · d_kz)`. An edge function depends only on
//! the edge's two corners and swaps sign exactly when they are swapped, so a triangle
//! and its neighbour see the same value, negated, on their shared edge. **Edge rule**:
//! a hit with an edge function exactly zero counts only if `sign(det) · o(P, Q) > 0`
//! for that edge `P → Q` (in the triangle's winding), where `o(P, Q) = +1` when `P`
//! precedes `Q` lexicographically by world coordinates, −1 otherwise. Of two
//! triangles sharing an edge that the ray crosses, exactly one satisfies it (either
//! both windings agree and the edge runs opposite ways, or they disagree and `det`
//! has opposite signs), so a ray through an edge counts once. A ray grazing a
//! silhouette edge counts twice or not at all, which leaves a segment of length zero.
//! A ray exactly through a vertex is not guaranteed to count once.
//! The test runs in f64 on the CPU (both precisions; the segments are then rounded to
//! the working precision) and in f32 on the GPU (`shaders/clipmesh.wgsl`).
//! A bounding-volume hierarchy with padded boxes hands each ray only the triangles
//! near its line ([`ClipTriangles::segments`]); it finds the same hits as testing
//! every triangle. The GPU walks the same hierarchy
//! ([`ClipTriangles::flat_hierarchy`], `gpu::clipmesh`), and keeps testing every
//! triangle as its reference.
//!
//! **Segments.** Hits at `t ≤ t₀` (the ray's start) are only counted: an odd count
//! means the ray starts inside, and `t₀` becomes the first boundary. Sorted with the
//! hits beyond `t₀`, boundaries `b₀ ≤ b₁ ≤ …` pair up into inside segments
//! `[b₀, b₁], [b₂, b₃], …` (parity); an unpaired last boundary (an open mesh) opens a
//! segment to infinity. At most [`MAX_SEGMENTS`] = 8 are kept: with more than 16
//! boundaries the eighth segment runs from `b₁₄` to the last boundary (or to infinity
//! when their count is odd), covering the gaps between the later segments: more
//! samples, never fewer, so nothing visible is lost.
//!
//! **Sampling.** The segments never move the sample grid: the ray caster keeps its
//! steps `k` (from the volume / clipping-box entry), and takes sample `k` only when its
//! midpoint parameter lies in a segment (`[a, b]`, closed). A mesh enclosing the whole
//! volume therefore gives exactly the image without a mesh. The sample indices of each
//! segment become an inclusive range ([`MeshRanges`]) that is intersected with the
//! empty-space-skipping ranges ([`ClippedRanges`]).
//!
//! **The bricks mesh** (InVols): the boundary of the union of the non-empty cells of
//! the min/max grid (`cpu::skip`) for the current transfer function: for each
//! non-empty cell, each of its six faces whose neighbour is empty or outside the
//! grid becomes two triangles. Cell `c` covers index space `[cB − ½, (c+1)B − ½]`
//! (not cut at the volume's box); every sample of an empty cell is transparent, so a
//! bricks mesh renders exactly the image without it. Faces are not merged (merging
//! coplanar faces creates T-junctions, where the edge rule above no longer holds).
//! Since the grid depends on the filter and classification, bricks apply where
//! skipping does: DVR with a 1D transfer function (`skip::skip_radius`, with
//! skipping itself on or off).
//!
//! Clipping meshes work with DVR, MIP, MinIP and X-ray; MIDA and iso-surfaces refuse
//! them. A clipping box and a mesh combine (both apply).

use super::grid::Grid;
use super::march::step_bounds;
use super::skip::{SampleRanges, Skipper};
use crate::error::{Error, Result};
use crate::io::mesh::TriMesh;
use crate::real::Real;
use crate::settings::{ClipMesh, ClipMeshUnits, Mode, RenderSettings};
use crate::transfer::LutR;
use glam::{DMat4, DVec3};
use std::sync::Arc;

/// The most inside segments one ray keeps (see the module docs for the merge).
pub const MAX_SEGMENTS: usize = 8;

/// "Infinity" for an open segment (also the f32 value the GPU uses).
pub const OPEN_END: f64 = 3.0e38;

/// A triangle in world coordinates, ready for the watertight test.
pub type Triangle = [[f64; 3]; 3];

/// Watertight ray–triangle intersection: the hit parameter along `o + d·t`, or `None`.
/// See the module docs for the edge rule. Mirrors `shaders/clipmesh.wgsl: intersect_triangle`.
pub fn intersect_triangle(o: [f64; 3], d: [f64; 3], tri: &Triangle) -> Option<f64> {
    let kz = if d[0].abs() > d[1].abs() {
        if d[0].abs() > d[2].abs() {
            0
        } else {
            2
        }
    } else if d[1].abs() > d[2].abs() {
        1
    } else {
        2
    };
    let mut kx = (kz + 1) % 3;
    let mut ky = (kx + 1) % 3;
    if d[kz] < 0.0 {
        std::mem::swap(&mut kx, &mut ky);
    }
    let sx = d[kx] / d[kz];
    let sy = d[ky] / d[kz];
    let rel = |p: [f64; 3]| [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
    let (a, b, c) = (rel(tri[0]), rel(tri[1]), rel(tri[2]));
    let (ax, ay) = (a[kx] - sx * a[kz], a[ky] - sy * a[kz]);
    let (bx, by) = (b[kx] - sx * b[kz], b[ky] - sy * b[kz]);
    let (cx, cy) = (c[kx] - sx * c[kz], c[ky] - sy * c[kz]);
    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    // Edge rule for edge functions exactly zero: U is edge B→C, V is C→A, W is A→B.
    let s = det > 0.0;
    let owns = |p: [f64; 3], q: [f64; 3]| lex_less(p, q) == s;
    if (u == 0.0 && !owns(tri[1], tri[2]))
        || (v == 0.0 && !owns(tri[2], tri[0]))
        || (w == 0.0 && !owns(tri[0], tri[1]))
    {
        return None;
    }
    let t = (u * a[kz] + v * b[kz] + w * c[kz]) / (det * d[kz]);
    t.is_finite().then_some(t)
}

/// Lexicographic `p < q` on world coordinates. Mirrors `shaders/clipmesh.wgsl: lex_less`.
#[inline]
pub fn lex_less(p: [f64; 3], q: [f64; 3]) -> bool {
    if p[0] != q[0] {
        p[0] < q[0]
    } else if p[1] != q[1] {
        p[1] < q[1]
    } else {
        p[2] < q[2]
    }
}

/// The inside segments of one ray, in increasing order.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Segments {
    pub count: usize,
    pub seg: [[f64; 2]; MAX_SEGMENTS],
}

impl Segments {
    /// The segments as a slice.
    pub fn as_slice(&self) -> &[[f64; 2]] {
        &self.seg[..self.count]
    }
}

/// Pairs the sorted hits beyond `t0` into segments, given how many hits lie at or
/// before `t0` (see the module docs). Mirrors `shaders/clipmesh.wgsl: clip_segments`.
pub fn make_segments(t0: f64, behind: usize, forward: &[f64]) -> Segments {
    let mut b: Vec<f64> = Vec::with_capacity(forward.len() + 1);
    if behind % 2 == 1 {
        b.push(t0);
    }
    b.extend_from_slice(forward);
    let mut s = Segments::default();
    let pairs = b.len().div_ceil(2);
    let end = |i: usize| b.get(i).copied().unwrap_or(OPEN_END);
    for (i, seg) in s.seg.iter_mut().enumerate().take(pairs) {
        *seg = [b[2 * i], end(2 * i + 1)];
    }
    s.count = pairs.min(MAX_SEGMENTS);
    if pairs > MAX_SEGMENTS {
        let last = if b.len() % 2 == 1 {
            OPEN_END
        } else {
            b[b.len() - 1]
        };
        s.seg[MAX_SEGMENTS - 1] = [b[2 * (MAX_SEGMENTS - 1)], last];
    }
    s
}

/// A clipping mesh resolved for one render: its triangles in world millimetres, their
/// bounding box, and a bounding-volume hierarchy over them (see `Bvh`).
#[derive(Clone, Debug)]
pub struct ClipTriangles {
    pub triangles: Vec<Triangle>,
    pub lo: [f64; 3],
    pub hi: [f64; 3],
    bvh: Bvh,
}

impl ClipTriangles {
    /// Flattens a (validated) mesh and builds its hierarchy.
    #[allow(clippy::needless_range_loop)]
    pub fn new(mesh: &TriMesh) -> Self {
        let triangles: Vec<Triangle> = (0..mesh.triangles.len())
            .map(|i| mesh.triangle(i))
            .collect();
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for t in &triangles {
            for p in t {
                for a in 0..3 {
                    lo[a] = lo[a].min(p[a]);
                    hi[a] = hi[a].max(p[a]);
                }
            }
        }
        let bvh = Bvh::new(&triangles, lo, hi);
        ClipTriangles {
            triangles,
            lo,
            hi,
            bvh,
        }
    }

    /// How many nodes the hierarchy has (a leaf holds at most `Bvh::LEAF` = 4 triangles).
    pub fn bvh_nodes(&self) -> usize {
        self.bvh.nodes.len()
    }

    /// The hierarchy laid out for a stackless walk (`shaders/clipmesh.wgsl:
    /// clip_hits`): the nodes in depth-first order, each with the index just past its
    /// subtree (where a walk goes when the line misses the node's box), and the
    /// triangle indices grouped by leaf. Each box is widened by a further `pad`
    /// (absolute, world mm) on every side.
    pub fn flat_hierarchy(&self, pad: f64) -> (Vec<FlatNode>, Vec<u32>) {
        let nodes = &self.bvh.nodes;
        let mut flat = Vec::with_capacity(nodes.len());
        // (node, index past its subtree), depth first: the left child follows its
        // parent, so a node's subtree ends where its parent's right child starts.
        let mut stack = vec![(0usize, nodes.len())];
        if nodes.is_empty() {
            stack.clear();
        }
        while let Some((i, skip)) = stack.pop() {
            let n = &nodes[i];
            debug_assert_eq!(flat.len(), i);
            flat.push(FlatNode {
                lo: n.lo.map(|x| x - pad),
                hi: n.hi.map(|x| x + pad),
                skip: skip as u32,
                first: if n.count > 0 { n.first } else { 0 },
                count: n.count,
            });
            if n.count == 0 {
                let right = n.first as usize;
                stack.push((right, skip));
                stack.push((i + 1, right));
            }
        }
        (flat, self.bvh.order.clone())
    }

    /// The inside segments of the ray `origin + dir·t`, `t ≥ t0` (f64, exact test):
    /// the hierarchy hands over the triangles whose (padded) boxes the ray's line
    /// crosses, each gets the watertight test. The same hits as
    /// [`segments_brute_force`](Self::segments_brute_force), so the same segments.
    pub fn segments(&self, origin: DVec3, dir: DVec3, t0: f64) -> Segments {
        let (o, d) = (origin.to_array(), dir.to_array());
        self.pair_hits(o, d, t0, |f| self.bvh.for_each_candidate(o, d, f))
    }

    /// [`segments`](Self::segments) by testing every triangle: the reference the
    /// hierarchy is checked against.
    pub fn segments_brute_force(&self, origin: DVec3, dir: DVec3, t0: f64) -> Segments {
        let (o, d) = (origin.to_array(), dir.to_array());
        self.pair_hits(o, d, t0, |f| (0..self.triangles.len()).for_each(f))
    }

    /// Tests the triangles `candidates` names, counts the hits at or before `t0`, sorts
    /// the others and pairs them.
    fn pair_hits(
        &self,
        o: [f64; 3],
        d: [f64; 3],
        t0: f64,
        candidates: impl FnOnce(&mut dyn FnMut(usize)),
    ) -> Segments {
        let mut behind = 0usize;
        let mut forward = Vec::new();
        candidates(&mut |i| {
            if let Some(t) = intersect_triangle(o, d, &self.triangles[i]) {
                if t <= t0 {
                    behind += 1;
                } else {
                    forward.push(t);
                }
            }
        });
        forward.sort_by(f64::total_cmp);
        make_segments(t0, behind, &forward)
    }
}

/// A bounding-volume hierarchy over a mesh's triangles, for the CPU's segment search.
///
/// **Build**: top down; a node's triangles are split at the median of their centroids
/// along the longest axis of the centroids' box, until at most [`Bvh::LEAF`] remain.
/// Nodes are stored depth first (the left child follows its parent).
///
/// **Conservative boxes**: every box is widened by `pad` = 1e-9 × (the mesh box's
/// largest extent or coordinate): far more than the rounding of the slab test (about
/// 1e-16 relative) and of the watertight test's hit, so no triangle the exact test hits
/// is ever left out. A false candidate only costs one exact test. Hits at any `t`
/// count (those before the ray's start decide whether it starts inside), so the test
/// is for the whole line, not a half ray.
#[derive(Clone, Debug)]
struct Bvh {
    nodes: Vec<BvhNode>,
    /// Triangle indices, grouped by leaf.
    order: Vec<u32>,
}

/// A node of [`ClipTriangles::flat_hierarchy`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FlatNode {
    pub lo: [f64; 3],
    pub hi: [f64; 3],
    /// The index just past this node's subtree.
    pub skip: u32,
    /// Leaf: its first triangle in the order; interior: 0.
    pub first: u32,
    /// Leaf: how many triangles; interior: 0 (its first child is the next node).
    pub count: u32,
}

#[derive(Clone, Copy, Debug)]
struct BvhNode {
    lo: [f64; 3],
    hi: [f64; 3],
    /// Leaf: the first index in `order`; interior: the right child.
    first: u32,
    /// Leaf: how many triangles; interior: 0.
    count: u32,
}

impl Bvh {
    /// The most triangles in a leaf.
    const LEAF: usize = 4;

    fn new(triangles: &[Triangle], lo: [f64; 3], hi: [f64; 3]) -> Self {
        let scale = (0..3)
            .map(|a| (hi[a] - lo[a]).max(lo[a].abs()).max(hi[a].abs()))
            .fold(0.0f64, f64::max);
        let pad = 1e-9 * scale;
        let centroid = |t: &Triangle| [0, 1, 2].map(|a| (t[0][a] + t[1][a] + t[2][a]) / 3.0);
        let centroids: Vec<[f64; 3]> = triangles.iter().map(centroid).collect();
        let mut order: Vec<u32> = (0..triangles.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * triangles.len().div_ceil(Self::LEAF));
        if !triangles.is_empty() {
            Self::build(triangles, &centroids, pad, &mut order, 0, &mut nodes);
        }
        Bvh { nodes, order }
    }

    /// Builds the node for `order[start..start + ids.len()]` (`ids`), returns its index.
    fn build(
        triangles: &[Triangle],
        centroids: &[[f64; 3]],
        pad: f64,
        ids: &mut [u32],
        start: usize,
        nodes: &mut Vec<BvhNode>,
    ) -> usize {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        let mut clo = [f64::INFINITY; 3];
        let mut chi = [f64::NEG_INFINITY; 3];
        for &i in ids.iter() {
            for p in &triangles[i as usize] {
                for a in 0..3 {
                    lo[a] = lo[a].min(p[a]);
                    hi[a] = hi[a].max(p[a]);
                }
            }
            let c = centroids[i as usize];
            for a in 0..3 {
                clo[a] = clo[a].min(c[a]);
                chi[a] = chi[a].max(c[a]);
            }
        }
        let node = nodes.len();
        nodes.push(BvhNode {
            lo: lo.map(|x| x - pad),
            hi: hi.map(|x| x + pad),
            first: start as u32,
            count: ids.len() as u32,
        });
        if ids.len() <= Self::LEAF {
            return node;
        }
        let axis = (0..3)
            .max_by(|&a, &b| (chi[a] - clo[a]).total_cmp(&(chi[b] - clo[b])))
            .unwrap_or(0);
        let mid = ids.len() / 2;
        ids.select_nth_unstable_by(mid, |&p, &q| {
            centroids[p as usize][axis].total_cmp(&centroids[q as usize][axis])
        });
        let (left, right) = ids.split_at_mut(mid);
        Self::build(triangles, centroids, pad, left, start, nodes);
        let r = Self::build(triangles, centroids, pad, right, start + mid, nodes);
        nodes[node].first = r as u32;
        nodes[node].count = 0;
        node
    }

    /// Calls `f` with every triangle whose box the line `o + d·t` (any `t`) crosses.
    fn for_each_candidate(&self, o: [f64; 3], d: [f64; 3], mut f: impl FnMut(usize)) {
        if self.nodes.is_empty() {
            return;
        }
        let inv = d.map(|x| 1.0 / x);
        let crosses = |n: &BvhNode| {
            let mut near = f64::NEG_INFINITY;
            let mut far = f64::INFINITY;
            for a in 0..3 {
                if d[a] == 0.0 {
                    if o[a] < n.lo[a] || o[a] > n.hi[a] {
                        return false;
                    }
                } else {
                    let (t1, t2) = ((n.lo[a] - o[a]) * inv[a], (n.hi[a] - o[a]) * inv[a]);
                    near = near.max(t1.min(t2));
                    far = far.min(t1.max(t2));
                }
            }
            near <= far
        };
        let mut stack = [0u32; 64];
        let mut top = 1usize;
        while top > 0 {
            top -= 1;
            let i = stack[top] as usize;
            let n = &self.nodes[i];
            if !crosses(n) {
                continue;
            }
            if n.count > 0 {
                let first = n.first as usize;
                for &t in &self.order[first..first + n.count as usize] {
                    f(t as usize);
                }
            } else {
                // Depth ≤ log2(triangles) + 1 < 64: the stack never holds more.
                stack[top] = n.first;
                stack[top + 1] = i as u32 + 1;
                top += 2;
            }
        }
    }
}

/// The boundary of the non-empty cells of `skip`'s grid (see the module docs), in
/// world coordinates through `affine` (index → world), outward-facing.
pub fn bricks_mesh<R: Real>(skip: &Skipper<R>, dims: [usize; 3], affine: DMat4) -> TriMesh {
    let n = skip.grid.cells;
    let b = skip.grid.block as f64;
    let full = |c: [i64; 3]| {
        (0..3).all(|a| c[a] >= 0 && (c[a] as usize) < n[a])
            && !skip.cell_empty([c[0] as i32, c[1] as i32, c[2] as i32])
    };
    let _ = dims;
    let mut mesh = TriMesh::default();
    let world = |p: [f64; 3]| affine.transform_point3(DVec3::from_array(p)).to_array();
    for z in 0..n[2] as i64 {
        for y in 0..n[1] as i64 {
            for x in 0..n[0] as i64 {
                let c = [x, y, z];
                if !full(c) {
                    continue;
                }
                for axis in 0..3 {
                    for side in [0i64, 1] {
                        let mut nb = c;
                        nb[axis] += 2 * side - 1;
                        if full(nb) {
                            continue;
                        }
                        // The face at index coordinate (c + side)·B − ½ along `axis`.
                        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
                        let corner = |du: i64, dv: i64| {
                            let mut p = [0.0; 3];
                            p[axis] = (c[axis] + side) as f64 * b - 0.5;
                            p[u] = (c[u] + du) as f64 * b - 0.5;
                            p[v] = (c[v] + dv) as f64 * b - 0.5;
                            world(p)
                        };
                        let base = mesh.vertices.len() as u32;
                        for (du, dv) in [(0, 0), (1, 0), (1, 1), (0, 1)] {
                            mesh.vertices.push(corner(du, dv));
                        }
                        // (u, v, axis) is right-handed: counter-clockwise faces +axis.
                        if side == 1 {
                            mesh.triangles.push([base, base + 1, base + 2]);
                            mesh.triangles.push([base, base + 2, base + 3]);
                        } else {
                            mesh.triangles.push([base, base + 2, base + 1]);
                            mesh.triangles.push([base, base + 3, base + 2]);
                        }
                    }
                }
            }
        }
    }
    mesh
}

/// Resolves `settings.clip_mesh` for one render: the mesh in world coordinates, or
/// the bricks mesh of `voxels` (what the skipping grid bounds; see `cpu::skip`) for
/// `lut`. `None` when no mesh is set.
pub fn resolve<R: Real>(
    settings: &RenderSettings,
    affine: DMat4,
    dims: [usize; 3],
    voxels: Option<&Grid<R>>,
    lut: &LutR<R>,
) -> Result<Option<Arc<ClipTriangles>>> {
    let Some(cm) = &settings.clip_mesh else {
        return Ok(None);
    };
    check_mode(settings)?;
    let mesh = match cm {
        ClipMesh::Mesh { mesh, units } => match units {
            ClipMeshUnits::World => return Ok(Some(Arc::new(ClipTriangles::new(mesh)))),
            ClipMeshUnits::Voxel => TriMesh {
                vertices: mesh
                    .vertices
                    .iter()
                    .map(|&p| affine.transform_point3(DVec3::from_array(p)).to_array())
                    .collect(),
                triangles: mesh.triangles.clone(),
            },
        },
        ClipMesh::Bricks => {
            let skip = bricks_skipper(settings, voxels, lut)?;
            bricks_mesh(&skip, dims, affine)
        }
    };
    Ok(Some(Arc::new(ClipTriangles::new(&mesh))))
}

/// The skipping grid the bricks mesh is made from (built even with skipping off).
pub fn bricks_skipper<R: Real>(
    settings: &RenderSettings,
    voxels: Option<&Grid<R>>,
    lut: &LutR<R>,
) -> Result<Skipper<R>> {
    let on = RenderSettings {
        skip_empty: true,
        ..settings.clone()
    };
    voxels
        .and_then(|g| Skipper::new(g, lut, &on))
        .ok_or_else(|| {
            Error::invalid(
                "clip mesh",
                "the bricks mesh needs DVR with a 1D transfer function, a voxel grid and a \
                 filter that empty-space skipping supports (not sinc, not pre-classified \
                 bspline-interp)",
            )
        })
}

/// Refuses modes a clipping mesh does not apply to.
pub fn check_mode(settings: &RenderSettings) -> Result<()> {
    let iso = !settings.iso_surfaces.is_empty();
    match settings.mode {
        Mode::Dvr | Mode::Mip | Mode::Minip | Mode::Xray if !iso => Ok(()),
        _ => Err(Error::invalid(
            "clip mesh",
            "works with DVR, MIP, MinIP and X-ray (not MIDA or iso-surfaces)",
        )),
    }
}

/// The midpoint parameter of step `k` of `n` from `t_s` by `dt`, cut to `[t_in, t_out]`:
/// the middle of its bounds ([`step_bounds`]), for every step alike.
#[inline]
pub fn step_mid<R: Real>(k: usize, n: usize, t_in: R, t_out: R, t_s: R, dt: R) -> R {
    let (ta, tb) = step_bounds(k, n, t_in, t_s, t_out, dt);
    (ta + tb) * R::of(0.5)
}

/// The sample indices of a ray inside its segments: up to [`MAX_SEGMENTS`] inclusive,
/// increasing ranges. Mirrors `shaders/raycast.wgsl: mesh_ranges`.
#[derive(Clone, Copy, Debug)]
pub struct MeshRanges {
    pub count: usize,
    pub range: [(usize, usize); MAX_SEGMENTS],
}

impl MeshRanges {
    /// Every sample `0 .. n` (no mesh).
    pub fn all(n: usize) -> Self {
        let mut range = [(0, 0); MAX_SEGMENTS];
        range[0] = (0, n.saturating_sub(1));
        MeshRanges {
            count: (n > 0) as usize,
            range,
        }
    }

    /// No sample.
    pub fn none() -> Self {
        MeshRanges {
            count: 0,
            range: [(0, 0); MAX_SEGMENTS],
        }
    }

    /// These samples cut to `lo ..= hi`.
    pub fn within(&self, lo: usize, hi: usize) -> Self {
        let mut out = MeshRanges::none();
        for &(a, b) in &self.range[..self.count] {
            let (a, b) = (a.max(lo), b.min(hi));
            if a <= b {
                out.range[out.count] = (a, b);
                out.count += 1;
            }
        }
        out
    }

    /// The samples whose midpoint (see [`step_mid`]) lies in a segment.
    pub fn new<R: Real>(segs: &Segments, n: usize, t_in: R, t_out: R, t_s: R, dt: R) -> Self {
        let mut out = MeshRanges {
            count: 0,
            range: [(0, 0); MAX_SEGMENTS],
        };
        if n == 0 {
            return out;
        }
        let mid = |k: usize| step_mid(k, n, t_in, t_out, t_s, dt);
        let last = n as i64 - 1;
        for s in segs.as_slice() {
            let (a, b) = (R::of(s[0]), R::of(s[1]));
            // Estimate, then correct against the exact midpoints.
            let guess = |t: R| {
                ((t - t_s) / dt - R::of(0.5))
                    .max(R::of(-2.0))
                    .min(R::of(n as f64 + 2.0))
                    .floor()
                    .to_i64()
                    .unwrap_or(0)
            };
            let mut lo = (guess(a) - 1).clamp(0, last);
            while lo <= last && mid(lo as usize) < a {
                lo += 1;
            }
            while lo > 0 && mid(lo as usize - 1) >= a {
                lo -= 1;
            }
            let mut hi = (guess(b) + 2).clamp(0, last);
            while hi >= 0 && mid(hi as usize) > b {
                hi -= 1;
            }
            while hi < last && mid(hi as usize + 1) <= b {
                hi += 1;
            }
            if lo > hi {
                continue;
            }
            // Keep the ranges disjoint and increasing.
            if out.count > 0 {
                let prev = &mut out.range[out.count - 1];
                if lo as usize <= prev.1 {
                    prev.1 = prev.1.max(hi as usize);
                    continue;
                }
            }
            out.range[out.count] = (lo as usize, hi as usize);
            out.count += 1;
        }
        out
    }
}

/// Empty-space-skipping ranges intersected with the mesh's ranges, in compositing
/// order (the mesh's ranges reversed when the skipping ranges run back to front).
pub struct ClippedRanges<R> {
    pub inner: SampleRanges<R>,
    pub mesh: MeshRanges,
    backward: bool,
    current: Option<(usize, usize)>,
    next_mesh: usize,
}

impl<R: Real> ClippedRanges<R> {
    pub fn new(inner: SampleRanges<R>, mesh: MeshRanges, backward: bool) -> Self {
        ClippedRanges {
            inner,
            mesh,
            backward,
            current: None,
            next_mesh: 0,
        }
    }

    /// The next range of samples to take, or `None` when the ray is done.
    pub fn next(&mut self, skip: Option<&Skipper<R>>) -> Option<(usize, usize)> {
        loop {
            if let Some((lo, hi)) = self.current {
                while self.next_mesh < self.mesh.count {
                    let j = if self.backward {
                        self.mesh.count - 1 - self.next_mesh
                    } else {
                        self.next_mesh
                    };
                    self.next_mesh += 1;
                    let (a, b) = self.mesh.range[j];
                    let (a, b) = (a.max(lo), b.min(hi));
                    if a <= b {
                        return Some((a, b));
                    }
                }
            }
            self.current = Some(self.inner.next(skip)?);
            self.next_mesh = 0;
        }
    }
}

/// A MIP, MinIP or X-ray pixel as its samples come in, in ray order.
pub struct ScalarSum<R> {
    mode: Mode,
    taken: u32,
    best: Option<R>,
    sum: R,
}

impl<R: Real> ScalarSum<R> {
    /// Takes the next sample: its value and its step's length. The maximum (minimum)
    /// keeps the first of equal values, so which zero a ray of `+0` and `−0` keeps
    /// does not depend on how the compiler lays out a `max` (whose sign of zero is
    /// unspecified).
    #[inline(always)]
    pub fn take(&mut self, v: R, len: R) {
        self.taken += 1;
        match (self.mode, self.best) {
            (Mode::Xray, _) => self.sum = self.sum + v * len,
            (Mode::Mip, Some(b)) if v <= b => {}
            (Mode::Minip, Some(b)) if v >= b => {}
            _ => self.best = Some(v),
        }
    }
}

/// MIP, MinIP or X-ray over the samples of `ranges` only (every sample of a ray with
/// no mesh: [`MeshRanges::all`]); `values(lo, hi, sum)` gives samples `lo ..= hi`,
/// in order, to `sum` ([`ScalarSum::take`]). Rays with no sample inside return `miss`.
pub fn cast_scalar_ranges<R: Real>(
    mode: Mode,
    ranges: &MeshRanges,
    miss: [R; 4],
    window: Option<[R; 2]>,
    mut values: impl FnMut(usize, usize, &mut ScalarSum<R>),
) -> ([R; 4], u32) {
    let mut s = ScalarSum {
        mode,
        taken: 0,
        best: None,
        sum: R::zero(),
    };
    for &(lo, hi) in &ranges.range[..ranges.count] {
        values(lo, hi, &mut s);
    }
    if s.taken == 0 {
        return (miss, 0);
    }
    let out = match mode {
        Mode::Xray => s.sum,
        _ => {
            let b = s.best.unwrap_or(R::zero());
            match window {
                Some(w) => super::modes::window_map(b, w),
                None => b,
            }
        }
    };
    ([out, R::zero(), R::zero(), R::zero()], s.taken)
}

/// Re-exported for the settings: a mesh shared between settings clones.
pub type SharedMesh = Arc<TriMesh>;
