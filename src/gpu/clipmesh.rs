//! Clipping meshes on the GPU: the inside segments of every pixel's ray, computed by a
//! compute pass before the ray caster (`shaders/clipmesh.wgsl`), which then takes only
//! the samples inside them, exactly as `cpu::clipmesh` describes.
//!
//! **Method.** Each invocation owns one pixel, builds the ray caster's ray for it
//! (`camera_ray`, the same function `shaders/raycast.wgsl` calls) and runs the
//! watertight ray–triangle test (Woop, Benthin & Wald, JCGT 2013) against the mesh's
//! triangles, read from a storage buffer. The segments then go to the ray caster as a
//! storage buffer of `1 + 2·MAX_SEGMENTS` floats per pixel. The crate is a wgpu
//! compute-only pipeline with no render targets, so the classic depth-peeling of the
//! mesh's faces in a rasterisation pass is not available; intersecting in a compute
//! shader instead runs the same formulas as the CPU test, so both backends pair the same
//! hits by parity and agree wherever the hits agree.
//!
//! **Passes.** `clip_hits` merges the hits of the triangles it tests into a per-pixel
//! state: hits at or before the ray's start only counted (parity: does the ray start
//! inside?), the 16 smallest hits beyond it kept sorted by insertion, plus their count
//! and maximum, which is all `make_segments` needs (with more than 16 boundaries the
//! eighth segment runs from boundary 14 to the last one, or to infinity when their count
//! is odd). The triangles it tests are those of a stackless walk of the mesh's
//! bounding-volume hierarchy (`ClipTriangles::flat_hierarchy`, boxes widened by
//! [`BOX_PAD`] × the mesh's scale), at most [`NODES_PER_DISPATCH`] nodes per dispatch,
//! the pixel's place in the walk kept in its state; or, as the reference
//! ([`GpuClipMesh::with_search`]), every triangle in chunks of [`CHUNK`] per dispatch.
//! Either way an invocation stays under the 65535 loop iterations llvmpipe runs, so a
//! mesh of any size runs as several dispatches; `clip_segments` then pairs the
//! boundaries. A mesh whose triangles do not fit one storage binding (48 bytes a
//! triangle) is refused.
//!
//! **f32.** The CPU test runs in f64, the GPU one in f32 with the same names and order of
//! operations. The edge rule still makes a shared edge count once (the edge functions
//! of two neighbours are still exact negatives of each other, since both compute the
//! same products of the same rounded corners); what changes is which triangle a ray
//! within about 1e-6 (relative) of an edge is assigned to, and the hit parameter,
//! rounded to about 1e-7 relative. The sample grid is the same on both sides (the
//! segments never move it), so a segment end moving by ε changes only samples whose
//! midpoint lies within ε of it.
//!
//! The bricks mesh is built on the host (`cpu::clipmesh::bricks_mesh` from the f32
//! min/max grid) and then intersected here like any other mesh.

use super::context::{buffer_entry, GpuContext, Kernel};
use super::params::RaycastParams;
use crate::cpu::clipmesh::{ClipTriangles, MAX_SEGMENTS};
use crate::error::{Error, Result};
use wgpu::util::DeviceExt;

/// Triangles per `clip_hits` dispatch: `CHUNK · (1 + 16)` loop iterations stay under
/// llvmpipe's 65535 per invocation.
pub const CHUNK: usize = 2048;

/// u32 words of hit state per pixel (`shaders/clipmesh.wgsl: STATE_WORDS`).
const STATE_WORDS: usize = 20;

/// vec4s of segments per pixel (`shaders/clipmesh.wgsl: SEGMENT_VEC4S`).
pub const SEGMENT_VEC4S: usize = 1 + MAX_SEGMENTS / 2;

/// The complete shader source: `shaders/clipmesh.wgsl` and its imports (the ray
/// caster's parameters and camera rays).
pub fn shader() -> String {
    super::shaders::resolve("clipmesh")
}

/// Hierarchy nodes a pixel visits per `clip_hits` dispatch
/// (`shaders/clipmesh.wgsl: NODES_PER_DISPATCH`).
pub const NODES_PER_DISPATCH: usize = 512;

/// How far the GPU's hierarchy boxes are widened, relative to the mesh's scale (its
/// box's largest extent or coordinate): some 800 times f32's rounding, so no triangle
/// the f32 test hits is left out when the ray's origin lies within a hundred mesh
/// sizes of it.
pub const BOX_PAD: f64 = 1e-4;

/// A clipping mesh uploaded for one render, with its pipelines.
pub struct GpuClipMesh {
    triangles: wgpu::Buffer,
    count: usize,
    /// The hierarchy (two vec4s a node) and its node count; 0 tests every triangle.
    nodes: wgpu::Buffer,
    node_count: usize,
    layout: wgpu::BindGroupLayout,
    hits: wgpu::ComputePipeline,
    finish: wgpu::ComputePipeline,
}

impl GpuClipMesh {
    /// Uploads `mesh`'s triangles (f32, world mm) in the order of its hierarchy, the
    /// hierarchy itself, and builds the pipelines.
    pub fn new(ctx: &GpuContext, mesh: &ClipTriangles) -> Result<Self> {
        Self::with_search(ctx, mesh, true)
    }

    /// [`GpuClipMesh::new`], walking the hierarchy (`hierarchy`) or testing every
    /// triangle: the same hits, the latter the reference for tests.
    pub fn with_search(ctx: &GpuContext, mesh: &ClipTriangles, hierarchy: bool) -> Result<Self> {
        let max_binding = ctx.limits.max_storage_buffer_binding_size as usize;
        let count = mesh.triangles.len();
        // A node is two vec4s (32 bytes); a mesh has fewer nodes than triangles.
        if count.saturating_mul(48) > max_binding {
            return Err(Error::too_large(
                "clip mesh",
                format!(
                    "{count} triangles need {} bytes, more than the {max_binding}-byte \
                     storage binding of this adapter",
                    count.saturating_mul(48)
                ),
            ));
        }
        let scale = (0..3)
            .map(|a| {
                (mesh.hi[a] - mesh.lo[a])
                    .max(mesh.lo[a].abs())
                    .max(mesh.hi[a].abs())
            })
            .fold(0.0f64, f64::max);
        let (flat, order) = if hierarchy && count > 0 {
            mesh.flat_hierarchy(BOX_PAD * scale)
        } else {
            (Vec::new(), (0..count as u32).collect())
        };
        let mut corners: Vec<[f32; 4]> = Vec::with_capacity(3 * count.max(1));
        for &i in &order {
            for p in &mesh.triangles[i as usize] {
                corners.push([p[0] as f32, p[1] as f32, p[2] as f32, 0.0]);
            }
        }
        let mut node_data: Vec<[f32; 4]> = Vec::with_capacity(2 * flat.len().max(1));
        for n in &flat {
            let lo = n.lo.map(|x| x as f32);
            let hi = n.hi.map(|x| x as f32);
            node_data.push([lo[0], lo[1], lo[2], f32::from_bits(n.skip)]);
            node_data.push([hi[0], hi[1], hi[2], f32::from_bits(n.first * 8 + n.count)]);
        }
        if node_data.is_empty() {
            node_data.push([0.0; 4]);
        }
        if corners.is_empty() {
            corners.push([0.0; 4]);
        }
        let dev = &ctx.device;
        let triangles = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("clip mesh triangles"),
            contents: bytemuck::cast_slice(&corners),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let nodes = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("clip mesh hierarchy"),
            contents: bytemuck::cast_slice(&node_data),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let storage = |read_only| wgpu::BufferBindingType::Storage { read_only };
        let program = ctx.program(
            "clipmesh.wgsl",
            &shader(),
            Some(&[
                buffer_entry(0, wgpu::BufferBindingType::Uniform),
                buffer_entry(1, wgpu::BufferBindingType::Uniform),
                buffer_entry(2, storage(true)),
                buffer_entry(3, storage(false)),
                buffer_entry(4, storage(false)),
                buffer_entry(5, storage(true)),
            ]),
        )?;
        let (
            Kernel {
                layout,
                pipeline: hits,
            },
            _,
        ) = program.kernel(ctx, "clip_hits")?;
        Ok(GpuClipMesh {
            hits,
            finish: program.kernel(ctx, "clip_segments")?.0.pipeline,
            triangles,
            count,
            node_count: flat.len(),
            nodes,
            layout,
        })
    }

    /// The segments of the rays of the ray caster's tile (`params.tile`: first column,
    /// first row, columns, rows): [`SEGMENT_VEC4S`] vec4s per pixel, row-major.
    pub fn segments(&self, ctx: &GpuContext, params: &RaycastParams) -> Result<wgpu::Buffer> {
        let dev = &ctx.device;
        let (w, rows) = (params.tile[2] as usize, params.tile[3] as usize);
        let pixels = w * rows;
        let state = ctx.storage_buffer("clip mesh hits", (pixels * STATE_WORDS * 4) as u64)?;
        let out = ctx.storage_buffer("clip mesh segments", (pixels * SEGMENT_VEC4S * 16) as u64)?;
        let pbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("clip mesh params"),
            contents: bytemuck::bytes_of(params),
            usage: super::context::PARAMS_USAGE,
        });
        let groups = ((w as u32).div_ceil(8), (rows as u32).div_ceil(8));
        // Without the hierarchy, chunks of triangles; with it, dispatches of a walk
        // (a pixel visits each node at most once; a finished pixel returns at once).
        let chunks = if self.node_count > 0 {
            self.node_count.div_ceil(NODES_PER_DISPATCH)
        } else {
            self.count.div_ceil(CHUNK).max(1)
        };
        for c in 0..=chunks {
            let finish = c == chunks;
            let lo = (c * CHUNK).min(self.count) as u32;
            let hi = ((c + 1) * CHUNK).min(self.count) as u32;
            let range: [u32; 4] = [lo, hi, (c == 0) as u32, self.node_count as u32];
            let cbuf = dev.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("clip mesh chunk"),
                contents: bytemuck::bytes_of(&range),
                usage: super::context::PARAMS_USAGE,
            });
            let bind = ctx.bind_group(
                "clipmesh",
                &self.layout,
                &[
                    pbuf.as_entire_binding(),
                    cbuf.as_entire_binding(),
                    self.triangles.as_entire_binding(),
                    state.as_entire_binding(),
                    out.as_entire_binding(),
                    self.nodes.as_entire_binding(),
                ],
            );
            let mut enc = dev.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                pass.set_pipeline(if finish { &self.finish } else { &self.hits });
                pass.set_bind_group(0, &bind, &[]);
                pass.dispatch_workgroups(groups.0, groups.1, 1);
            }
            ctx.queue.submit([enc.finish()]);
            ctx.wait()?;
        }
        Ok(out)
    }
}

/// The inside segments of every pixel's ray for `params` (one tile: `params.tile`), read
/// back: per pixel the count and up to [`MAX_SEGMENTS`] `[t0, t1]` pairs in world mm.
/// The GPU twin of `cpu::clipmesh::ClipTriangles::segments`, for tests and tools.
pub fn segments(
    ctx: &GpuContext,
    mesh: &ClipTriangles,
    params: &RaycastParams,
) -> Result<Vec<Vec<[f32; 2]>>> {
    segments_with_search(ctx, mesh, params, true)
}

/// [`segments`] with the hierarchy (`hierarchy`) or testing every triangle.
pub fn segments_with_search(
    ctx: &GpuContext,
    mesh: &ClipTriangles,
    params: &RaycastParams,
    hierarchy: bool,
) -> Result<Vec<Vec<[f32; 2]>>> {
    let gm = GpuClipMesh::with_search(ctx, mesh, hierarchy)?;
    let buf = gm.segments(ctx, params)?;
    let pixels = params.tile[2] as usize * params.tile[3] as usize;
    let raw: Vec<[f32; 4]> =
        bytemuck::cast_slice(&ctx.read_buffer(&buf, (pixels * SEGMENT_VEC4S * 16) as u64)?)
            .to_vec();
    Ok(raw
        .chunks(SEGMENT_VEC4S)
        .map(|p| {
            let n = p[0][0] as usize;
            (0..n)
                .map(|i| {
                    let v = p[1 + i / 2];
                    if i % 2 == 0 {
                        [v[0], v[1]]
                    } else {
                        [v[2], v[3]]
                    }
                })
                .collect()
        })
        .collect())
}
