//! The parameter blocks that several GPU families share, one `#[repr(C)]`,
//! `bytemuck::Pod` struct each, with its WGSL twin under `shaders/shared/`
//! (`tests/gpu_layout.rs` holds every member's offset against naga's layout of the
//! twin). They live here, below the families, so that a family reads another's
//! parameters without importing that family: the ray caster's block is filled by
//! `gpu::raycast` and read by `gpu::clipmesh` and `gpu::d2vr`; the adaptive block is
//! shared by `gpu::adaptive` and `gpu::preintegrate`. Each family re-exports its own
//! block (`gpu::raycast::RaycastParams`, `gpu::adaptive::AdaptiveParams`). A block
//! only one family uses stays in that family's file.

/// Parameters of one ray-casting dispatch; twin of `shaders/shared/raycast_params.wgsl`
/// (`tests/gpu_layout.rs` checks that the two layouts agree). Filled by
/// `gpu::raycast::raycast_params`; read by the ray caster, its set-up passes, the
/// clipping-mesh passes (`gpu::clipmesh`) and D²VR (`gpu::d2vr`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct RaycastParams {
    pub eye: [f32; 4],
    pub forward: [f32; 4],
    pub right: [f32; 4],
    pub up: [f32; 4],
    pub to_index_0: [f32; 4],
    pub to_index_1: [f32; 4],
    pub to_index_2: [f32; 4],
    pub normal_0: [f32; 4],
    pub normal_1: [f32; 4],
    pub normal_2: [f32; 4],
    pub box_hi: [f32; 4],
    pub background: [f32; 4],
    pub light: [f32; 4],
    pub shading: [f32; 4],
    pub misc: [f32; 4],
    pub lut: [f32; 4],
    pub dims: [u32; 4],
    pub image: [u32; 4],
    pub flags: [u32; 4],
    pub flags2: [u32; 4],
    /// 2D transfer function: value scale, value offset, nv − 1, ng − 1.
    pub tf2d_a: [f32; 4],
    /// 2D transfer function: gradient scale, 1/g0, log axis, on.
    pub tf2d_b: [f32; 4],
    pub accel: [u32; 4],
    pub skip_cells: [u32; 4],
    pub skip_tf: [f32; 4],
    pub clip_lo: [f32; 4],
    pub clip_hi: [f32; 4],
    /// MIDA γ, lowest value, 1/(value range), unused (`cpu::modes`).
    pub mode_params: [f32; 4],
    /// MIP/MinIP grey window: width, centre, 1 when on, unused.
    pub window: [f32; 4],
    /// Iso-surfaces drawn, opaque, shadows, refine.
    pub iso_flags: [u32; 4],
    /// The iso-values.
    pub iso_values: [f32; 4],
    /// Colour (rgb) and opacity of each iso-surface.
    pub iso_color_0: [f32; 4],
    pub iso_color_1: [f32; 4],
    pub iso_color_2: [f32; 4],
    pub iso_color_3: [f32; 4],
    /// Clipping mesh: 1 when on (segments per pixel in binding 11, `gpu::clipmesh`),
    /// the rest unused.
    pub clip_mesh: [u32; 4],
    /// A brick of a larger volume (`gpu::raycast::BrickPlacement`): xyz its first
    /// voxel's index in the whole volume, w = 1 when on.
    pub brick: [f32; 4],
    /// The faces of the samples the brick owns, `lo − ½` and `hi − ½` in the whole
    /// volume's index space (±f32::MAX where the face is the volume's border);
    /// `own_lo[3]` = 1 in a pass of the shadow rays (`gpu::raycast::render_bricked`).
    pub own_lo: [f32; 4],
    pub own_hi: [f32; 4],
    /// The pixels of this dispatch (a tile of the image): first column, first row,
    /// columns, rows.
    pub tile: [u32; 4],
}

/// Parameters of the adaptive passes; twin of `shaders/shared/adaptive_params.wgsl`
/// (`tests/gpu_layout.rs` checks that the two layouts agree). Read by the adaptive
/// caster and its importance passes (`gpu::adaptive`) and by the pre-integration
/// table (`gpu::preintegrate`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct AdaptiveParams {
    /// step (T_min), T_max, 2·oversampling, early-termination opacity.
    pub steps: [f32; 4],
    /// Window map a, b; pre-integration coordinate scale, offset.
    pub window: [f32; 4],
    /// Spectral table: d0, bins/(d1 − d0), bins, 0.
    pub spectrum: [f32; 4],
    pub background: [f32; 4],
    /// nx, ny, nz, sampling (0 regular, 1 adaptive, 2 direct).
    pub dims: [u32; 4],
    /// Width, height, first row, rows of the dispatch's pixels (a band of the image's
    /// rows; its width is a brick's rectangle's, `gpu::raycast::bricks_seen`, when the
    /// volume is cut).
    pub image: [u32; 4],
    /// Pre-integration n, spectral bins, block edge, blocks along x.
    pub table: [u32; 4],
    /// Blocks along y, z; importance passes: axis, radius.
    pub extra: [u32; 4],
    /// A brick: the whole volume's voxel at its texture's texel 0; 1 when the rays carry
    /// their state from brick to brick (zeros when not split).
    pub brick: [i32; 4],
    /// The box a brick owns the steps starting in (index coordinates; the whole
    /// volume's faces open, `±f32::MAX`).
    pub own_lo: [f32; 4],
    pub own_hi: [f32; 4],
}
