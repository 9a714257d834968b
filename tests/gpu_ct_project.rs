//! The GPU port of Joseph's projector (`gpu::project`) against the CPU oracle
//! (`cpu::project::project_volume::<f64>`), over one case list: parallel and cone
//! beams, phantom grids placed by the phantom rotation, an off-centre anisotropic
//! grid, a grid turned by an oblique affine, geometries given view by view, and
//! chunked dispatches.

mod common;

use glam::{DMat4, DQuat, DVec3};
use voxlab::cpu::project::{project_volume, Grid, JosephPlanes, ProjectOptions};
use voxlab::ct::Geometry;
use voxlab::gpu::project as gproject;
use voxlab::metrics::max_abs_error;
use voxlab::phantom::Phantom;

/// Largest `max |gpu − cpu| / max |cpu|`. The GPU rounds the grid and the view
/// vectors to f32 and accumulates in f32. Measured on lavapipe (Mesa's Vulkan on the
/// CPU): 7.4e-7 (skimage row) … 9.0e-6 (Shepp–Logan 32³, cone: the source sits ~125
/// voxels away, so f32 ray positions are off by ~1e-5 voxel, across phantom edges);
/// 6.5e-6 for the 300-view chunked run; 1.3e-5 for the same grid through the turned
/// and tilted detector given view by view (same cause, rays more oblique). The bound
/// leaves a factor of about 4.
const TOL_MAX_REL: f64 = 5e-5;
/// Largest `‖gpu − cpu‖₂ / ‖cpu‖₂`. Measured on lavapipe: 2.7e-7 … 1.4e-6 (the same
/// cone case; 1.5e-6 through the tilted detector).
const TOL_REL_L2: f64 = 7e-6;

struct Case {
    name: &'static str,
    grid: fn() -> Grid<f64>,
    geometry: fn() -> Geometry,
}

fn shepp32() -> Grid<f64> {
    Grid::phantom(&Phantom::shepp_logan_modified(), [32; 3]).unwrap()
}

fn anisotropic() -> Grid<f64> {
    // 20 × 12 × 16 voxels of 5 × 8 × 6 mm, off-centre, smooth values.
    let dims = [20usize, 12, 16];
    let affine = DMat4::from_translation(DVec3::new(7.0, -4.0, 3.0))
        * DMat4::from_scale(DVec3::new(5.0, 8.0, 6.0))
        * DMat4::from_translation(DVec3::new(-9.5, -5.5, -7.5));
    let data = (0..20 * 12 * 16)
        .map(|i| {
            let (x, y, z) = (i % 20, i / 20 % 12, i / 240);
            1.0 + ((x * 7 + y * 3 + z * 5) % 11) as f64 * 0.1
        })
        .collect();
    Grid::new(dims, affine, data).unwrap()
}

fn oblique() -> Grid<f64> {
    let ph = Phantom::shepp_logan_modified();
    let mut g = Grid::phantom(&ph, [24; 3]).unwrap();
    let q = DQuat::from_axis_angle(DVec3::new(1.0, 2.0, 3.0).normalize(), 0.6);
    g.affine = DMat4::from_quat(q) * g.affine;
    g
}

const CASES: &[Case] = &[
    Case {
        name: "shepp32-parallel",
        grid: shepp32,
        geometry: || {
            Geometry::parallel_stack(40, 36, 7.0, 7.0, Geometry::even_angles(9, 180.0)).unwrap()
        },
    },
    Case {
        name: "shepp32-parallel-skimage-row",
        grid: shepp32,
        geometry: || Geometry::parallel_skimage(61, Geometry::even_angles(13, 180.0)).unwrap(),
    },
    Case {
        name: "shepp32-cone",
        grid: shepp32,
        geometry: || {
            Geometry::cone_rtk(
                1000.0,
                1500.0,
                48,
                40,
                8.0,
                8.0,
                Geometry::even_angles(9, 360.0),
            )
            .unwrap()
        },
    },
    Case {
        name: "anisotropic-cone-short-sid",
        grid: anisotropic,
        geometry: || {
            Geometry::cone_rtk(
                300.0,
                500.0,
                50,
                30,
                4.0,
                5.0,
                vec![0.0, 33.0, 100.0, 222.0],
            )
            .unwrap()
        },
    },
    Case {
        name: "oblique-parallel",
        grid: oblique,
        geometry: || {
            Geometry::parallel_stack(30, 30, 9.0, 9.0, vec![0.0, 10.0, 71.0, 160.0]).unwrap()
        },
    },
    // Geometries given view by view (`ct::Geometry::from_views`).
    Case {
        name: "shepp32-cone-vec-tilted",
        grid: shepp32,
        geometry: || {
            common::cone_tilted(9, 1000.0, 1500.0, (48, 40, 8.0, 8.0), 4.0, 6.0, (9.0, -5.0))
        },
    },
    Case {
        name: "anisotropic-cone-vec-wobble",
        grid: anisotropic,
        geometry: || common::cone_wobble(7, 300.0, 500.0, (50, 30, 4.0, 5.0)),
    },
    Case {
        name: "oblique-parallel3d-vec",
        grid: oblique,
        geometry: || common::parallel_vec(5, (30, 30, 9.0, 9.0), 12.0, 150.0),
    },
];

#[test]
fn gpu_matches_the_f64_oracle() {
    let Some(ctx) = common::gpu("gpu_matches_the_f64_oracle") else {
        return;
    };
    let (mut worst_max, mut worst_l2) = (0.0f64, 0.0f64);
    for case in CASES {
        let grid = (case.grid)();
        let g = (case.geometry)();
        let cpu = project_volume(&grid, &g, &ProjectOptions::default()).unwrap();
        let gpu = gproject::project_volume(ctx, &grid, &g, &ProjectOptions::default()).unwrap();
        assert_eq!(
            (gpu.angles, gpu.rows, gpu.cols),
            (cpu.angles, cpu.rows, cpu.cols)
        );
        let dims = [cpu.cols, cpu.rows, cpu.angles];
        let tol = voxlab::metrics::Tolerance::max_abs_rel(TOL_MAX_REL).with_rel_l2(TOL_REL_L2);
        let name = format!("gpu_project_{}", case.name);
        let e = common::assert_parity_array(&name, &dims, &cpu.data, &gpu.data, tol);
        let (rel_max, rel_l2, at) = (e.max_abs_rel, e.rel_l2, e.worst_index);
        eprintln!(
            "{}: max rel {rel_max:.2e} (at {at}: cpu {:.4} gpu {:.4}), rel L2 {rel_l2:.2e}",
            case.name, cpu.data[at], gpu.data[at]
        );
        assert!(e.peak > 1.0, "{}: the case projects something", case.name);
        worst_max = worst_max.max(rel_max);
        worst_l2 = worst_l2.max(rel_l2);
    }
    eprintln!("worst: max rel {worst_max:.2e}, rel L2 {worst_l2:.2e}");
}

#[test]
fn many_views_are_split_into_dispatches_and_agree() {
    let Some(ctx) = common::gpu("many_views_are_split_into_dispatches_and_agree") else {
        return;
    };
    // 64 × 64 pixels × 64 planes = 2^18 samples per view: 128 views per dispatch, so
    // 300 views take three dispatches.
    let grid = Grid::<f64>::phantom(&Phantom::shepp_logan_modified(), [64; 3]).unwrap();
    let g = Geometry::parallel_stack(64, 64, 4.5, 4.5, Geometry::even_angles(300, 180.0)).unwrap();
    let cpu = project_volume(&grid, &g, &ProjectOptions::default()).unwrap();
    let (gpu, timings) =
        gproject::project_volume_timed(ctx, &grid, &g, &ProjectOptions::default()).unwrap();
    // The dispatches' device time, where the adapter has timestamps: some of the time
    // of the dispatches and readbacks, never more.
    let timestamps = ctx.features.contains(wgpu::Features::TIMESTAMP_QUERY);
    assert_eq!(timings.kernel.is_some(), timestamps, "{timings:?}");
    assert!(
        timings
            .kernel
            .is_none_or(|k| k > 0.0 && k <= timings.project),
        "{timings:?}"
    );
    let e = common::assert_parity_array(
        "gpu_project_300_views",
        &[cpu.cols, cpu.rows, cpu.angles],
        &cpu.data,
        &gpu.data,
        voxlab::metrics::Tolerance::max_abs_rel(TOL_MAX_REL),
    );
    eprintln!("300 views: max rel {:.2e}", e.max_abs_rel);
}

/// Slices per slab in the split runs: single slices, an odd size, and a remainder.
const SLABS: [usize; 3] = [1, 3, 7];

/// Both samplings, each against its own unsplit run and the oracle (the hardware path
/// within the texture unit's bound, `gpu::project::hardware_error_bound`).
#[test]
fn a_grid_in_slabs_projects_as_the_whole_grid() {
    use voxlab::gpu::plan::{Pieces, Sampling};
    let Some(ctx) = common::gpu("a_grid_in_slabs_projects_as_the_whole_grid") else {
        return;
    };
    let mut samplings = vec![Sampling::Exact];
    if ctx.features.contains(wgpu::Features::FLOAT32_FILTERABLE) {
        samplings.push(Sampling::Hardware);
    }
    let mut worst = 0.0f64;
    for sampling in samplings {
        for case in CASES {
            let grid = (case.grid)();
            let g = (case.geometry)();
            let cpu = project_volume(&grid, &g, &ProjectOptions::default()).unwrap();
            let unsplit =
                gproject::ProjectionPlan::sampled(&ctx.limits, &g, grid.dims, sampling).unwrap();
            assert!(!unsplit.is_split());
            let options = ProjectOptions::default();
            let (whole, _) =
                gproject::project_volume_planned(ctx, &grid, &g, &options, &unsplit).unwrap();
            let peak = whole.data.iter().fold(0f32, |m, v| m.max(v.abs())) as f64;
            for slices in SLABS {
                let plan = gproject::ProjectionPlan {
                    slabs: Pieces {
                        total: grid.dims[2],
                        per_piece: slices,
                    },
                    ..unsplit
                };
                let (split, _) =
                    gproject::project_volume_planned(ctx, &grid, &g, &options, &plan).unwrap();
                let name = format!("gpu_project_{}_{sampling:?}_slabs_of_{slices}", case.name);
                let tol = match sampling {
                    Sampling::Exact => {
                        voxlab::metrics::Tolerance::max_abs_rel(TOL_MAX_REL).with_rel_l2(TOL_REL_L2)
                    }
                    Sampling::Hardware => voxlab::metrics::Tolerance::max_abs(
                        gproject::hardware_error_bound(&grid, &g, 8) + TOL_MAX_REL * peak,
                    ),
                };
                common::assert_parity_array(
                    &name,
                    &[cpu.cols, cpu.rows, cpu.angles],
                    &cpu.data,
                    &split.data,
                    tol,
                );
                let diff = split
                    .data
                    .iter()
                    .zip(&whole.data)
                    .fold(0f64, |m, (a, b)| m.max((a - b).abs() as f64));
                worst = worst.max(diff / peak);
                // Measured on lavapipe: at most 1.7e-6 of the peak (f32 sums in another
                // order, ray origins moved to each slab's frame). A real texture unit
                // may round a moved coordinate's weights the other way, which only the
                // oracle's bound above covers.
                if sampling == Sampling::Exact || ctx.summary.is_cpu() {
                    assert!(
                        diff <= 1e-5 * peak,
                        "{name}: {diff:e} of {peak:e} from the unsplit run"
                    );
                }
            }
        }
    }
    eprintln!("slabs against the unsplit projection: worst {worst:.2e} of the peak");
}

#[test]
fn a_grid_past_the_storage_limit_is_projected_in_slabs() {
    let Some(ctx) = common::gpu("a_grid_past_the_storage_limit_is_projected_in_slabs") else {
        return;
    };
    let limit = voxlab::gpu::plan::binding_limit(&ctx.limits) as usize / 4;
    let side = ((limit as f64).cbrt() as usize + 2).max(2);
    if side.pow(3) > 400_000_000 {
        eprintln!("SKIPPED: a grid past this adapter's binding would need {side}³ voxels");
        return;
    }
    let data: Vec<f32> = (0..side.pow(3)).map(|i| (i % 7) as f32 * 0.25).collect();
    let centred = DMat4::from_translation(DVec3::splat(-(side as f64) / 2.0));
    let grid = Grid::<f32>::new([side; 3], centred, data).unwrap();
    let g = Geometry::parallel_stack(8, 6, 1.0, 1.0, vec![0.0, 35.0, 90.0]).unwrap();
    let plan = gproject::ProjectionPlan::new(&ctx.limits, &g, grid.dims).unwrap();
    assert_eq!(plan.slabs.count(), 2, "{}", plan.describe());
    let gpu = gproject::project_volume(ctx, &grid, &g, &ProjectOptions::default()).unwrap();
    let cpu = project_volume(&grid, &g, &ProjectOptions::default()).unwrap();
    let tol = voxlab::metrics::Tolerance::max_abs_rel(TOL_MAX_REL);
    let e = common::assert_parity_array(
        "gpu_project_past_the_binding",
        &[8, 6, 3],
        &cpu.data,
        &gpu.data,
        tol,
    );
    assert!(e.peak > 1.0);
}

/// The largest difference of two voxels among those a sample at in-plane coordinates
/// (`xa`, `xb`) on plane `s` may reach through the texture unit: the 4 × 4 taps around
/// it (a coordinate rounded across a texel boundary lands in the next cell) on the
/// planes `s − 1 ..= s + 1`, zero outside the grid. Independent of the library's
/// global bound (`gpu::project::hardware_error_bound`).
fn local_spread(grid: &Grid<f64>, p: &JosephPlanes<f64>, s: usize, xa: f64, xb: f64) -> f64 {
    let [nx, ny, _] = grid.dims;
    let at = |c: [i64; 3]| -> f64 {
        if (0..3).any(|i| c[i] < 0 || c[i] >= grid.dims[i] as i64) {
            0.0
        } else {
            grid.data[(c[2] as usize * ny + c[1] as usize) * nx + c[0] as usize]
        }
    };
    let (fa, fb) = (xa.floor() as i64, xb.floor() as i64);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for ds in -1..=1 {
        for da in -1..=2 {
            for db in -1..=2 {
                let mut c = [0i64; 3];
                c[p.m] = s as i64 + ds;
                c[p.a] = fa + da;
                c[p.b] = fb + db;
                let v = at(c);
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
    }
    hi - lo
}

/// The texture-unit path (`Sampling::Hardware`) against the f64 oracle, pixel by
/// pixel, within the bound the filter's rounding allows: each of a sample's three
/// trilinear weights may be off by 2⁻⁸ (NVIDIA's 8 fractional bits), which moves the
/// sample by at most 2⁻⁸ × the local spread per axis, so a ray may be off by
/// `w · Σ_s 3 · spread_s · 2⁻⁸`, plus the exact path's f32 bound. On a CPU adapter
/// (lavapipe filters in f32) it is also held to the exact GPU path: there the only
/// difference is the normalised coordinate `(x + 1.5)/(n + 2)` rounded to f32.
#[test]
fn hardware_projection_is_within_the_texture_units_bound() {
    use voxlab::cpu::project::{joseph_planes, joseph_views, pixel_ray, JosephView};
    use voxlab::gpu::plan::Sampling;
    let Some(ctx) = common::gpu("hardware_projection_is_within_the_texture_units_bound") else {
        return;
    };
    let hardware = Sampling::Hardware;
    if !ctx.features.contains(wgpu::Features::FLOAT32_FILTERABLE) {
        let (grid, g) = ((CASES[0].grid)(), (CASES[0].geometry)());
        let plan = gproject::ProjectionPlan::sampled(&ctx.limits, &g, grid.dims, hardware).unwrap();
        let e = gproject::project_volume_planned(ctx, &grid, &g, &ProjectOptions::default(), &plan)
            .unwrap_err();
        assert!(e.to_string().contains("FLOAT32_FILTERABLE"), "{e}");
        return;
    }
    for case in CASES {
        let grid = (case.grid)();
        let g = (case.geometry)();
        let cpu = project_volume(&grid, &g, &ProjectOptions::default()).unwrap();
        let plan = gproject::ProjectionPlan::sampled(&ctx.limits, &g, grid.dims, hardware).unwrap();
        let (got, _) =
            gproject::project_volume_planned(ctx, &grid, &g, &ProjectOptions::default(), &plan)
                .unwrap();
        let exact = gproject::project_volume(ctx, &grid, &g, &ProjectOptions::default()).unwrap();
        let peak = cpu.data.iter().fold(0f64, |m, v| m.max(v.abs()));
        let views: Vec<JosephView<f64>> = joseph_views(&g, grid.affine);
        let (mut worst, mut worst_share) = (0f64, 0f64);
        for (k, v) in views.iter().enumerate() {
            for row in 0..g.rows {
                for col in 0..g.cols {
                    let (o, d, t_min) = pixel_ray(v, col as f64, row as f64);
                    let mut sum = 0.0;
                    let mut w = 0.0;
                    if let Some(p) = joseph_planes(grid.dims, o, d, t_min) {
                        w = p.w;
                        for s in p.s0..=p.s1 {
                            let sr = s as f64;
                            let (xa, xb) = (p.xa0 + sr * p.ka, p.xb0 + sr * p.kb);
                            sum += local_spread(&grid, &p, s, xa, xb);
                        }
                    }
                    let bound = w * 3.0 * sum / 256.0 + TOL_MAX_REL * peak;
                    let at = (k * g.rows + row) * g.cols + col;
                    let dv = (got.data[at] as f64 - cpu.data[at]).abs();
                    assert!(
                        dv <= bound,
                        "{}: view {k} pixel ({col}, {row}) off by {dv:e}, over the texture \
                         unit's bound {bound:e}",
                        case.name
                    );
                    worst = worst.max(dv);
                    worst_share = worst_share.max(dv / bound);
                }
            }
        }
        let library = gproject::hardware_error_bound(&grid, &g, 8);
        assert!(
            worst <= library + TOL_MAX_REL * peak,
            "{}: {worst:e} over the library's bound {library:e}",
            case.name
        );
        let from_exact = max_abs_error(&got.data, &exact.data);
        eprintln!(
            "hardware projection {} on {}: max |Δ| {worst:.2e} ({:.1e} of the peak, \
             {worst_share:.1e} of the bound; library bound {:.1e} of the peak), {:.1e} of \
             the peak from the exact GPU path",
            case.name,
            ctx.summary.name,
            worst / peak,
            library / peak,
            from_exact / peak
        );
        if ctx.summary.is_cpu() {
            // Measured on lavapipe: 2.2e-7 (anisotropic cone) … 1.0e-6 (tilted cone) of
            // the peak; the bound is 4× the worst.
            assert!(
                from_exact <= 4e-6 * peak,
                "{}: {from_exact:e} from the exact GPU path (peak {peak:e})",
                case.name
            );
        }
    }
}

/// The hardware plan: bordered slabs under the binding and the 3-D texture limits, the
/// refusal of a slice wider than a texture, and the line it prints.
#[test]
fn the_hardware_projection_plan_borders_its_slabs() {
    use voxlab::gpu::plan::Sampling;
    let g = Geometry::parallel_stack(8, 6, 1.0, 1.0, vec![0.0, 35.0, 90.0]).unwrap();
    let limits = |binding: u64, side: u32| wgpu::Limits {
        max_storage_buffer_binding_size: binding,
        max_texture_dimension_3d: side,
        ..wgpu::Limits::default()
    };
    let plan =
        |l: &wgpu::Limits, dims| gproject::ProjectionPlan::sampled(l, &g, dims, Sampling::Hardware);
    // 30 × 20 voxels a slice: 32 × 22 × 4 = 2,816 bytes with the border. A binding of
    // 12 slices holds 10 and the two border slices.
    let p = plan(&limits(12 * 2816, 2048), [30, 20, 25]).unwrap();
    assert_eq!((p.slabs.per_piece, p.slabs.count()), (10, 3));
    assert_eq!(p.slab_bytes([30, 20, 25]), 12 * 2816);
    assert_eq!(
        p.describe(),
        "projection in 3 slabs of 10 slices, grid in 3-D textures"
    );
    // The exact plan under the same binding: 30 × 20 × 4 = 2,400 bytes a slice.
    let e = gproject::ProjectionPlan::new(&limits(12 * 2816, 2048), &g, [30, 20, 25]).unwrap();
    assert_eq!(
        (e.slabs.per_piece, e.slab_bytes([30, 20, 25])),
        (14, 14 * 2400)
    );
    // A texture of 9 texels per axis holds 7 slices and the border, but not the slice.
    let e = plan(&limits(1 << 27, 9), [30, 20, 25]).unwrap_err();
    assert!(e.to_string().contains("32×22 texels"), "{e}");
    let p = plan(&limits(1 << 27, 9), [7, 5, 25]).unwrap();
    assert_eq!((p.slabs.per_piece, p.slabs.count()), (7, 4));
    // One slice and its border past the binding: no split fits.
    assert!(plan(&limits(2 * 2816, 2048), [30, 20, 25]).is_err());
}
