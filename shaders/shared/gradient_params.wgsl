// Parameters of one gradient-volume dispatch (a slab of z-slices).
// Rust twin: src/gpu/gradient.rs: GradientParams (#[repr(C)], bytemuck); the layout is
// checked in tests/gpu_layout.rs.

struct GradientParams {
    // nx, ny, nz of the volume; w = gradient method (0 central, 1 forward, 2 Sobel).
    dims: vec4<u32>,
    // x = first z-slice of the slab, y = slices in the slab (zw unused).
    slab: vec4<u32>,
}
