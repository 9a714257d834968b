//! The small D²VR scenes `tests/d2vr.rs` and `tests/gpu_d2vr.rs` share: two spheres,
//! exact projections, `cpu::ramp`'s Ram-Lak filter (with FDK pre-weighting for the
//! cone), a 48³ virtual grid and a 48² orbit camera.
#![allow(dead_code)]

use glam::DVec3;
use voxlab::camera::{Camera, Orbit, Projection};
use voxlab::cpu::d2vr::D2vrGrid;
use voxlab::cpu::project::project_phantom;
use voxlab::cpu::ramp::{filter_projections, FilterMethod, RampFilter};
use voxlab::ct::{Geometry, Projections};
use voxlab::phantom::{Phantom, Primitive};
use voxlab::transfer::{ControlPoint, TransferFunction, WindowMap};

/// Grid and detector side.
pub const N: usize = 48;
/// Projections per scan.
pub const ANGLES: usize = 64;
/// World extent of the grid (mm): the phantom cube, ±128 mm.
pub const EXTENT: f64 = 256.0;

/// A sphere of density 1 (radius 64 mm) holding a denser off-centre sphere.
pub fn phantom() -> Phantom {
    Phantom::from_primitives(
        "two spheres",
        vec![
            Primitive::sphere(1.0, DVec3::ZERO, 0.5),
            Primitive::sphere(0.5, DVec3::new(0.2, 0.1, -0.1), 0.2),
        ],
    )
}

/// One uniform sphere (radius 64 mm), for the analytic X-ray check.
pub fn sphere() -> Phantom {
    Phantom::from_primitives("sphere", vec![Primitive::sphere(1.0, DVec3::ZERO, 0.5)])
}

pub fn parallel() -> Geometry {
    let d = EXTENT / N as f64;
    Geometry::parallel_stack(N, N, d, d, Geometry::even_angles(ANGLES, 180.0)).unwrap()
}

pub fn cone() -> Geometry {
    Geometry::cone_rtk(
        600.0,
        900.0,
        N,
        N,
        8.0,
        8.0,
        Geometry::even_angles(ANGLES, 360.0),
    )
    .unwrap()
}

/// Ram-Lak filtered projections (`cpu::ramp`, the direct f64 oracle; FDK cosine
/// pre-weighting for a cone beam). With D²VR's `π/(2A)` this is FBP (parallel, 180°) or
/// FDK (cone, 360°).
pub fn ramp(p: &Projections<f64>, g: &Geometry) -> Projections<f64> {
    filter_projections(p, g, RampFilter::RamLak, FilterMethod::Direct).unwrap()
}

/// Exact projections of `ph`, filtered.
pub fn filtered(ph: &Phantom, g: &Geometry) -> Projections<f64> {
    ramp(&project_phantom(ph, g).unwrap(), g)
}

/// Exact, unfiltered projections.
pub fn raw(ph: &Phantom, g: &Geometry) -> Projections<f64> {
    project_phantom(ph, g).unwrap()
}

pub fn to_f32(p: &Projections<f64>) -> Projections<f32> {
    Projections::new(
        p.angles,
        p.rows,
        p.cols,
        p.data.iter().map(|&v| v as f32).collect(),
    )
    .unwrap()
}

pub fn grid() -> D2vrGrid {
    D2vrGrid::centred([N; 3], EXTENT / N as f64).unwrap()
}

/// An oblique orthographic orbit view that fits the grid, `side²` pixels.
pub fn camera(side: usize) -> Camera {
    Camera::orbit(
        DVec3::ZERO,
        [EXTENT; 3],
        Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            distance_mm: None,
        },
        Projection::Orthographic {
            width_mm: 0.0,
            height_mm: 0.0,
        },
        side,
        side,
    )
    .unwrap()
}

/// Transparent below 0.25, a translucent shell for density 1, an opaque core at 1.5.
pub fn tf() -> TransferFunction {
    let p = |value: f64, rgba: [f64; 4]| ControlPoint { value, rgba };
    TransferFunction {
        name: "d2vr test".into(),
        domain: [0.0, 2.0],
        points: vec![
            p(0.25, [0.0, 0.0, 0.0, 0.0]),
            p(0.8, [0.9, 0.6, 0.4, 0.15]),
            p(1.2, [0.9, 0.7, 0.5, 0.2]),
            p(1.5, [1.0, 1.0, 0.9, 0.9]),
        ],
        window: WindowMap::default(),
        interpolation: Default::default(),
        faux_shading: None,
    }
}
