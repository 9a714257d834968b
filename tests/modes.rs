//! MIDA, windowed MIP/MinIP and iso-surfaces on the CPU oracle, against their
//! definitions: MIDA at γ = −1 is DVR, at γ = 1 the MIP sample's colour; the window
//! commutes with the projection; iso-surface hits of a sphere lie on its radius.

use glam::DVec3;
use voxlab::camera::{AxisView, Camera, Orbit, Projection};
use voxlab::cpu::grid::Grid;
use voxlab::cpu::modes::{first_iso_hit, window_map, window_preset, Span};
use voxlab::cpu::raycast::{render, Field, GridField};
use voxlab::frame::Frame;
use voxlab::metrics::max_abs_error;
use voxlab::phantom::Phantom;
use voxlab::real::intersect_box;
use voxlab::real::{Real, V3};
use voxlab::settings::{
    Classification, Filter, GradientMethod, IsoSurface, Light, Mode, RenderSettings,
};
use voxlab::transfer::TransferFunction;
use voxlab::{AnyVolume, Volume};

fn phantom_scene(n: usize, size: usize) -> (AnyVolume, TransferFunction, Camera) {
    let vol: AnyVolume = Phantom::shepp_logan_modified()
        .sample([n, n + 3, n - 2])
        .unwrap()
        .into();
    let tf = TransferFunction::preset("phantom").unwrap();
    let cam = Camera::orbit(
        DVec3::ZERO,
        [256.0; 3],
        Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            distance_mm: Some(540.0),
        },
        Projection::Perspective { fov_y_deg: 30.0 },
        size,
        size * 3 / 4,
    )
    .unwrap();
    (vol, tf, cam)
}

fn draw<R: Real>(
    vol: &AnyVolume,
    tf: &TransferFunction,
    cam: &Camera,
    s: &RenderSettings,
) -> Frame {
    render::<R>(vol, tf, cam, s, &|_, _| {}).unwrap().image
}

/// γ = −1 makes β ≡ 1, so MIDA is DVR to the bit (DVR without early termination: MIDA
/// never terminates early). Measured max |Δ| 0 in f64 and f32, shaded and unshaded,
/// post- and pre-classified.
#[test]
fn mida_at_gamma_minus_one_is_dvr() {
    let (vol, tf, cam) = phantom_scene(24, 40);
    for (shade, class) in [
        (true, Classification::Post),
        (false, Classification::Post),
        (true, Classification::Pre),
    ] {
        let mut dvr = RenderSettings {
            ert_threshold: 1.0,
            classification: class,
            ..RenderSettings::default()
        };
        dvr.shading.enabled = shade;
        let mida = RenderSettings {
            mode: Mode::Mida,
            mida_gamma: -1.0,
            ..dvr.clone()
        };
        let d64 = max_abs_error(
            &draw::<f64>(&vol, &tf, &cam, &dvr),
            &draw::<f64>(&vol, &tf, &cam, &mida),
        );
        let d32 = max_abs_error(
            &draw::<f32>(&vol, &tf, &cam, &dvr),
            &draw::<f32>(&vol, &tf, &cam, &mida),
        );
        eprintln!("MIDA(γ=−1) vs DVR, shade {shade}, {class:?}: f64 {d64:.1e}, f32 {d32:.1e}");
        assert_eq!(d64, 0.0);
        assert_eq!(d32, 0.0);
    }
}

/// At γ = 1 MIDA is the transfer function's colour of the ray's maximum, `α c` over the
/// background, where the maximum is the one the MIP mode finds. Metric: max |Δ| against
/// that image built from a plain MIP render; measured 0 (unshaded, so the colour is the
/// lookup of the MIP value). Below 1 the difference to it shrinks as (1 − γ): the blend
/// is linear, so d(γ) / d(0) = 1 − γ (measured to 1e-15).
#[test]
fn mida_tends_to_mip_as_gamma_tends_to_one() {
    let (vol, tf, cam) = phantom_scene(24, 40);
    let mut base = RenderSettings {
        mode: Mode::Mida,
        ..RenderSettings::default()
    };
    base.shading.enabled = false;
    let mip = draw::<f64>(
        &vol,
        &tf,
        &cam,
        &RenderSettings {
            mode: Mode::Mip,
            ..base.clone()
        },
    );
    let lut = tf.lut(base.lut_size).to_real::<f64>();
    let bg = base.background;
    let mut expected = Frame::new(mip.width, mip.height, 4);
    for (i, &v) in mip.data.iter().enumerate() {
        let [r, g, b, a] = lut.classify(v);
        let px = &mut expected.data[4 * i..4 * i + 4];
        let t = 1.0 - a;
        px.copy_from_slice(&[
            a * r + t * bg[0] * bg[3],
            a * g + t * bg[1] * bg[3],
            a * b + t * bg[2] * bg[3],
            a + t * bg[3],
        ]);
    }
    let at = |g: f64| {
        draw::<f64>(
            &vol,
            &tf,
            &cam,
            &RenderSettings {
                mida_gamma: g,
                ..base.clone()
            },
        )
    };
    let one = at(1.0);
    let d1 = max_abs_error(&one, &expected);
    eprintln!("MIDA(γ=1) vs coloured MIP: max |Δ| {d1:.1e}");
    assert!(d1 <= 1e-12, "{d1}");
    let d0 = max_abs_error(&at(0.0), &one);
    assert!(d0 > 0.05, "plain MIDA should differ from MIP: {d0}");
    for g in [0.5, 0.9, 0.99] {
        let dg = max_abs_error(&at(g), &one);
        eprintln!(
            "γ = {g}: max |MIDA(γ) − MIDA(1)| = {dg:.3e}, / d(0) = {:.6}",
            dg / d0
        );
        assert!((dg / d0 - (1.0 - g)).abs() < 1e-9, "γ {g}: {dg} vs {d0}");
    }
}

/// Plain MIDA (γ = 0) lies between DVR and MIP: it differs from both.
#[test]
fn mida_at_gamma_zero_differs_from_dvr() {
    let (vol, tf, cam) = phantom_scene(24, 40);
    let dvr = RenderSettings {
        ert_threshold: 1.0,
        ..RenderSettings::default()
    };
    let mida = RenderSettings {
        mode: Mode::Mida,
        ..dvr.clone()
    };
    let d = max_abs_error(
        &draw::<f64>(&vol, &tf, &cam, &dvr),
        &draw::<f64>(&vol, &tf, &cam, &mida),
    );
    eprintln!("MIDA(0) vs DVR: max |Δ| {d:.3}");
    assert!(d > 0.05);
}

/// The window map is non-decreasing, so windowing commutes with max and min: the
/// windowed MIP/MinIP equals the window applied to the plain one. Measured max |Δ| 0.
#[test]
fn windowed_mip_is_the_window_of_the_mip() {
    let (vol, tf, cam) = phantom_scene(24, 40);
    for mode in [Mode::Mip, Mode::Minip] {
        for window in [[0.4, 0.3], [0.05, 0.21], [2.0, 0.0]] {
            let plain = RenderSettings {
                mode,
                ..RenderSettings::default()
            };
            let windowed = RenderSettings {
                window: Some(window),
                sample_count: true,
                ..plain.clone()
            };
            let p = draw::<f64>(&vol, &tf, &cam, &plain);
            let out = render::<f64>(&vol, &tf, &cam, &windowed, &|_, _| {}).unwrap();
            let (w, counts) = (out.image, out.samples.unwrap());
            let mut mapped = p.clone();
            for (v, &n) in mapped.data.iter_mut().zip(&counts.data) {
                // Rays that miss keep the miss value.
                if n > 0.0 {
                    *v = window_map(*v, window);
                }
            }
            assert!(counts.data.contains(&0.0));
            let d = max_abs_error(&w, &mapped);
            eprintln!("{mode:?} window {window:?}: max |Δ| {d:.1e}");
            assert_eq!(d, 0.0);
            assert!(w.data.iter().all(|v| (0.0..=1.0).contains(v)));
        }
    }
    // The map itself: centre → ½, centre ± width/2 → 0 and 1, clamped beyond.
    assert_eq!(window_map(40.0, [80.0, 40.0]), 0.5);
    assert_eq!(window_map(0.0, [80.0, 40.0]), 0.0);
    assert_eq!(window_map(80.0, [80.0, 40.0]), 1.0);
    assert_eq!(window_map(-1000.0, [80.0, 40.0]), 0.0);
    assert_eq!(window_map(3000.0, [80.0, 40.0]), 1.0);
}

#[test]
fn window_presets_resolve_by_name() {
    assert_eq!(window_preset("bone").unwrap(), [1800.0, 400.0]);
    assert_eq!(window_preset("lung").unwrap(), [1500.0, -600.0]);
    assert_eq!(window_preset("brain").unwrap(), [80.0, 40.0]);
    assert_eq!(window_preset("abdomen").unwrap(), [400.0, 40.0]);
    let e = window_preset("elbow").unwrap_err().to_string();
    assert!(e.contains("bone") && e.contains("elbow"), "{e}");
}

#[test]
fn bad_mode_settings_are_refused() {
    let bad = [
        RenderSettings {
            mode: Mode::Mida,
            mida_gamma: 1.5,
            ..RenderSettings::default()
        },
        RenderSettings {
            window: Some([0.0, 1.0]),
            ..RenderSettings::default()
        },
        RenderSettings {
            mode: Mode::Iso,
            ..RenderSettings::default()
        },
        RenderSettings {
            mode: Mode::Iso,
            iso_surfaces: vec![IsoSurface {
                value: 0.3,
                color: [1.2, 0.0, 0.0],
                opacity: 0.5,
            }],
            ..RenderSettings::default()
        },
        RenderSettings {
            mode: Mode::Iso,
            iso_surfaces: vec![
                IsoSurface {
                    value: 0.3,
                    color: [1.0, 0.0, 0.0],
                    opacity: 0.5,
                };
                5
            ],
            ..RenderSettings::default()
        },
        RenderSettings {
            mode: Mode::Iso,
            iso_shadows: true,
            iso_surfaces: vec![IsoSurface {
                value: 0.3,
                color: [1.0, 0.0, 0.0],
                opacity: 0.5,
            }],
            ..RenderSettings::default()
        },
    ];
    let words = [
        "[-1, 1]",
        "width",
        "at least one",
        "[0, 1]",
        "at most 4",
        "opaque",
    ];
    for (s, w) in bad.iter().zip(words) {
        let e = s.validate().unwrap_err().to_string();
        eprintln!("{e}");
        assert!(e.contains(w), "{e}");
    }
}

/// A sphere of radius `r` around `c` as the distance field `|p − c|`, exactly (with its
/// analytic gradient), in index space.
struct Sphere {
    c: DVec3,
    n: usize,
}

impl<R: Real> Field<R> for Sphere {
    fn dims(&self) -> [usize; 3] {
        [self.n; 3]
    }
    fn value(&self, p: V3<R>) -> R {
        R::of((p.to_dvec() - self.c).length())
    }
    fn gradient(&self, p: V3<R>) -> V3<R> {
        V3::from_dvec((p.to_dvec() - self.c).normalize_or_zero())
    }
    fn value_range(&self) -> (f64, f64) {
        (0.0, self.n as f64)
    }
}

const N: usize = 40;
const C: [f64; 3] = [19.3, 19.6, 19.45];
const RADIUS: f64 = 12.0;

/// Rays over a grid of directions and offsets, clipped to the box, as spans with
/// `step` voxels; the same cut into steps as the ray caster.
fn sphere_spans(step: f64) -> Vec<Span<f64>> {
    let lo = V3::splat(-0.5);
    let hi = V3::splat(N as f64 - 0.5);
    let c = DVec3::from_array(C);
    let mut spans = Vec::new();
    for dir in [
        DVec3::Z,
        DVec3::new(0.3, -0.2, 1.0).normalize(),
        DVec3::new(1.0, 0.7, 0.4).normalize(),
    ] {
        let u = dir.any_orthonormal_vector();
        let v = dir.cross(u);
        for a in -14..=14 {
            for b in -14..=14 {
                let off = u * (a as f64 * 0.83) + v * (b as f64 * 0.83);
                if off.length() > RADIUS * 0.97 {
                    continue; // grazing rays may miss between samples
                }
                let o = c + off - dir * 40.0;
                let (o, d) = (V3::from_dvec(o), V3::from_dvec(dir));
                let (t_in, t_out) = intersect_box(o, d, lo, hi).unwrap();
                let dt = step;
                let n = ((t_out - t_in) / dt - 1e-3).ceil().max(1.0) as usize;
                spans.push(Span {
                    o,
                    d,
                    t_in,
                    t_out,
                    dt,
                    n,
                    speed: 1.0,
                });
            }
        }
    }
    spans
}

/// The worst |distance from the centre − r| of the first hits of `tau = r`.
fn worst_hit_error<F: Field<f64>>(field: &F, spans: &[Span<f64>], refine: bool) -> f64 {
    let c = DVec3::from_array(C);
    spans
        .iter()
        .map(|s| {
            let t = first_iso_hit(field, s, RADIUS, refine).expect("the ray crosses the sphere");
            ((s.o + s.d * t).to_dvec() - c).length() - RADIUS
        })
        .fold(0.0, |m: f64, e| m.max(e.abs()))
}

/// Hit-point refinement on a sphere (distance field, iso-value = radius 12 voxels,
/// step 0.5 voxels, 1,839 rays in three directions). The exact field isolates the
/// refinement: linear interpolation of `|p − c|` along the ray errs by about
/// `step²/(8r)`; measured refined 2.44e-3 voxels vs unrefined 0.487 (the next sample
/// past the surface). On the voxel grid (trilinear, which itself bends the distance
/// field between voxels) measured refined 2.15e-2 vs unrefined 0.506. Bounds ≈ 1.6–2.5×
/// the refined measurements; unrefined errors lie within one step.
#[test]
fn iso_hits_of_a_sphere_lie_on_its_radius() {
    let spans = sphere_spans(0.5);
    let exact = Sphere {
        c: DVec3::from_array(C),
        n: N,
    };
    let c = DVec3::from_array(C);
    let grid = Grid::<f64> {
        dims: [N; 3],
        data: (0..N * N * N)
            .map(|i| {
                let p = DVec3::new((i % N) as f64, ((i / N) % N) as f64, (i / (N * N)) as f64);
                (p - c).length()
            })
            .collect(),
    };
    let field = GridField::new(grid, Filter::Trilinear, GradientMethod::Central, false);
    let (er, eu) = (
        worst_hit_error(&exact, &spans, true),
        worst_hit_error(&exact, &spans, false),
    );
    let (gr, gu) = (
        worst_hit_error(&field, &spans, true),
        worst_hit_error(&field, &spans, false),
    );
    eprintln!(
        "{} rays: exact field refined {er:.2e} unrefined {eu:.2e}; trilinear grid refined {gr:.2e} unrefined {gu:.2e} (voxels)",
        spans.len()
    );
    assert!(er < 6e-3, "{er}");
    assert!(gr < 3.5e-2, "{gr}");
    assert!(eu > 0.3 && eu <= 0.5 + 1e-9, "{eu}");
    assert!(gu > 0.3 && gu <= 0.55, "{gu}");
    assert!(er * 50.0 < eu && gr * 10.0 < gu);
}

fn sphere_volume() -> AnyVolume {
    let c = DVec3::from_array(C);
    Volume::<f32>::from_fn([N; 3], [1.0; 3], |i, j, k| {
        (DVec3::new(i as f64, j as f64, k as f64) - c).length() as f32
    })
    .unwrap()
    .into()
}

/// Semi-transparent iso-surfaces composite front to back: an unshaded red sphere of
/// opacity 0.4 seen along z is crossed twice (in and out) by every ray through its
/// disc, so a pixel is 0.4 + 0.6·0.4 = 0.64 red over the black background; rays beside
/// it see the background. Exact to 1e-12.
#[test]
fn semi_transparent_sphere_is_crossed_twice() {
    let vol = sphere_volume();
    let cam = Camera::axis_view(vol.dims(), vol.affine(), AxisView::PlusZ, N, N).unwrap();
    let mut s = RenderSettings {
        mode: Mode::Iso,
        iso_surfaces: vec![IsoSurface {
            value: RADIUS,
            color: [1.0, 0.0, 0.0],
            opacity: 0.4,
        }],
        ..RenderSettings::default()
    };
    s.shading.enabled = false;
    let tf = TransferFunction::preset("phantom").unwrap();
    let img = draw::<f64>(&vol, &tf, &cam, &s);
    let c = DVec3::from_array(C);
    let (mut inside, mut outside) = (0, 0);
    for row in 0..N {
        for col in 0..N {
            let ray = cam.ray(col, row);
            let idx = vol.affine().inverse().transform_point3(ray.origin);
            let r = ((idx.x - c.x).powi(2) + (idx.y - c.y).powi(2)).sqrt();
            let px = &img.data[4 * (row * N + col)..4 * (row * N + col) + 4];
            if r < RADIUS - 0.5 {
                inside += 1;
                for (x, e) in px.iter().zip([0.64, 0.0, 0.0, 1.0]) {
                    assert!((x - e).abs() < 1e-12, "({col}, {row}): {px:?}");
                }
            } else if r > RADIUS + 0.5 {
                outside += 1;
                assert_eq!(px, [0.0, 0.0, 0.0, 1.0]);
            }
        }
    }
    assert!(inside > 300 && outside > 300, "{inside} {outside}");
}

/// Binary shadows on an opaque sphere under a directional light: a hit whose normal
/// faces away from the light is in shadow (its shadow ray leaves through the sphere),
/// one facing it is lit. Unshaded, so a pixel is the colour or the colour × ambient.
/// Checked on every pixel with |n·L| > 0.15; measured 0 wrong.
#[test]
fn opaque_sphere_shadows_its_far_side() {
    let vol = sphere_volume();
    let cam = Camera::axis_view(vol.dims(), vol.affine(), AxisView::PlusZ, N, N).unwrap();
    let light = DVec3::new(1.0, 0.3, -0.4).normalize();
    let mut s = RenderSettings {
        mode: Mode::Iso,
        iso_surfaces: vec![IsoSurface {
            value: RADIUS,
            color: [0.2, 0.8, 1.0],
            opacity: 0.4,
        }],
        iso_opaque: true,
        iso_shadows: true,
        ..RenderSettings::default()
    };
    s.shading.enabled = false;
    s.shading.light = Light::Direction(light.to_array());
    let ka = s.shading.ambient;
    let tf = TransferFunction::preset("phantom").unwrap();
    let img = draw::<f64>(&vol, &tf, &cam, &s);
    let c = DVec3::from_array(C);
    let to_index = vol.affine().inverse();
    let (mut lit, mut dark) = (0, 0);
    for row in 0..N {
        for col in 0..N {
            let ray = cam.ray(col, row);
            let o = to_index.transform_point3(ray.origin);
            let d = to_index.transform_vector3(ray.dir).normalize();
            // Ray–sphere: |o + t d − c|² = r².
            let oc = o - c;
            let b = oc.dot(d);
            let disc = b * b - (oc.length_squared() - RADIUS * RADIUS);
            if disc < 4.0 {
                continue;
            }
            let p = o + d * (-b - disc.sqrt());
            let n = (p - c) / RADIUS;
            let ndl = n.dot(light);
            if ndl.abs() < 0.15 {
                continue;
            }
            let px = &img.data[4 * (row * N + col)..4 * (row * N + col) + 3];
            let k = if ndl > 0.0 { 1.0 } else { ka };
            if ndl > 0.0 {
                lit += 1;
            } else {
                dark += 1;
            }
            for (x, e) in px.iter().zip([0.2, 0.8, 1.0]) {
                assert!(
                    (x - e * k).abs() < 1e-12,
                    "({col}, {row}) n·L {ndl}: {px:?}"
                );
            }
        }
    }
    eprintln!("{lit} lit and {dark} shadowed pixels checked");
    assert!(lit > 100 && dark > 100);
}

/// DVR and iso-surfaces in one image: with the iso-surfaces fully transparent the
/// image is DVR's exactly; with an opaque surface in front the pixels it covers are
/// the surface over whatever DVR accumulated before it.
#[test]
fn dvr_with_transparent_iso_surfaces_is_dvr() {
    let (vol, tf, cam) = phantom_scene(24, 40);
    let dvr = RenderSettings::default();
    let both = RenderSettings {
        iso_surfaces: vec![IsoSurface {
            value: 0.5,
            color: [1.0, 1.0, 0.0],
            opacity: 0.0,
        }],
        ..dvr.clone()
    };
    let d = max_abs_error(
        &draw::<f64>(&vol, &tf, &cam, &dvr),
        &draw::<f64>(&vol, &tf, &cam, &both),
    );
    eprintln!("DVR vs DVR + transparent iso: {d:.1e}");
    assert!(d < 1e-15, "{d}");
    let opaque = RenderSettings {
        iso_surfaces: vec![IsoSurface {
            value: 0.5,
            color: [1.0, 1.0, 0.0],
            opacity: 1.0,
        }],
        ..dvr.clone()
    };
    let img = draw::<f64>(&vol, &tf, &cam, &opaque);
    assert!(max_abs_error(&draw::<f64>(&vol, &tf, &cam, &dvr), &img) > 0.1);
}

/// The f32 CPU path against the f64 oracle for every mode of this module (Shepp–Logan
/// 24×27×22 at 40×30, perspective). Measured max |Δ|: MIDA γ = 0 5.9e-5, γ = 0.5
/// 2.9e-5; windowed MIP (width 0.1) 1.6e-5; iso semi-transparent 5.9e-6, opaque with
/// shadows 9.3e-6, DVR + iso 1.2e-5. Bound 3e-4, 5× the worst. (MIDA's MIP colour was
/// once shaded: on a plateau of the maximum f32 and f64 picked different samples and
/// gradients, 2.6e-3 at γ = 0.5; it is unshaded now.)
#[test]
fn f32_cpu_matches_the_f64_oracle() {
    let (vol, tf, cam) = phantom_scene(24, 40);
    let isos = vec![
        IsoSurface {
            value: 0.5,
            color: [1.0, 0.9, 0.7],
            opacity: 0.6,
        },
        IsoSurface {
            value: 0.25,
            color: [0.2, 0.6, 1.0],
            opacity: 0.3,
        },
    ];
    let mut shadows = RenderSettings {
        mode: Mode::Iso,
        iso_surfaces: isos.clone(),
        iso_opaque: true,
        iso_shadows: true,
        ..RenderSettings::default()
    };
    shadows.shading.light = Light::Direction([0.6, -1.0, 0.8]);
    let cases = [
        (
            "mida 0",
            RenderSettings {
                mode: Mode::Mida,
                ..RenderSettings::default()
            },
        ),
        (
            "mida 0.5",
            RenderSettings {
                mode: Mode::Mida,
                mida_gamma: 0.5,
                ..RenderSettings::default()
            },
        ),
        (
            "windowed mip",
            RenderSettings {
                mode: Mode::Mip,
                window: Some([0.1, 0.25]),
                ..RenderSettings::default()
            },
        ),
        (
            "iso",
            RenderSettings {
                mode: Mode::Iso,
                iso_surfaces: isos.clone(),
                ..RenderSettings::default()
            },
        ),
        ("iso opaque shadows", shadows),
        (
            "dvr + iso",
            RenderSettings {
                iso_surfaces: isos.clone(),
                ..RenderSettings::default()
            },
        ),
    ];
    for (name, s) in cases {
        let d = max_abs_error(
            &draw::<f64>(&vol, &tf, &cam, &s),
            &draw::<f32>(&vol, &tf, &cam, &s),
        );
        eprintln!("{name}: f32 vs f64 max |Δ| {d:.2e}");
        assert!(d < 3e-4, "{name}: {d}");
    }
}
