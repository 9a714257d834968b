//! 2D transfer functions, Bézier 1D curves, faux shading, Hounsfield presets and stereo
//! pairs on the CPU: widget definitions, the overlap rule, the table's bilinear read,
//! JSON, renders against the 1D oracle, and the stereo layouts.

use glam::DVec3;
use voxlab::camera::{Camera, Orbit, Projection};
use voxlab::cpu::raycast::render;
use voxlab::jobs::render::{Backend, Renderer, Scene};
use voxlab::jobs::stereo::{combine, stereo_cameras, StereoLayout};
use voxlab::metrics::max_abs_error;
use voxlab::phantom::Phantom;
use voxlab::settings::RenderSettings;
use voxlab::transfer::{
    bernstein3, faux_shade, ControlPoint, Interpolation, TransferFunction, WindowMap, HU_PRESETS,
};
use voxlab::transfer2d::{GradientAxis, Shape, TransferFunction2D, Widget, PRESETS_2D};
use voxlab::{AnyVolume, Volume};

fn none() -> &'static (dyn Fn(usize, usize) + Sync) {
    &|_, _| {}
}

fn widget(shape: Shape, rgba: [f64; 4], border: f64) -> Widget {
    Widget {
        shape,
        rgba,
        border,
    }
}

fn tf2d(widgets: Vec<Widget>, axis: GradientAxis, size: [usize; 2]) -> TransferFunction2D {
    TransferFunction2D {
        name: "test".into(),
        domain: [0.0, 1.0],
        gradient_max: 0.1,
        gradient_axis: axis,
        gradient_g0: Some(0.005),
        widgets,
        window: WindowMap::default(),
        lut_size: size,
        faux_shading: None,
    }
}

/// The widget set the render tests use (Shepp–Logan values in [0, 1], gradient
/// magnitudes up to about 0.1 per mm on a 24³ grid).
pub fn phantom_widgets() -> Vec<Widget> {
    vec![
        widget(
            Shape::Triangle {
                apex: 0.3,
                half_width: 0.15,
                gradient: [0.002, 0.05],
            },
            [1.0, 0.8, 0.6, 0.6],
            0.5,
        ),
        widget(
            Shape::Ellipse {
                center: [0.2, 0.0],
                radii: [0.05, 0.01],
            },
            [0.3, 0.6, 1.0, 0.3],
            0.5,
        ),
        widget(
            Shape::Rectangle {
                value: [0.95, 1.0],
                gradient: [0.0, 0.1],
            },
            [1.0, 1.0, 1.0, 0.4],
            0.2,
        ),
    ]
}

#[test]
fn widget_shapes_follow_their_definitions() {
    let rect = widget(
        Shape::Rectangle {
            value: [0.2, 0.6],
            gradient: [0.0, 0.04],
        },
        [1.0, 0.5, 0.25, 0.8],
        0.5,
    );
    // Centre (0.4, 0.02), half sizes (0.2, 0.02); d = max(|Δu|/0.2, |Δg|/0.02).
    let w = |u, g| rect.eval(u, g).map_or(0.0, |(w, _)| w);
    assert_eq!(w(0.4, 0.02), 1.0);
    assert_eq!(w(0.45, 0.025), 1.0); // d = 0.25 < 0.5
    assert!((w(0.55, 0.02) - (1.0 - 0.75) / 0.5).abs() < 1e-12); // d = 0.75
    assert!((w(0.4, 0.036) - (1.0 - 0.8) / 0.5).abs() < 1e-12); // d = 0.8
    assert_eq!(w(0.61, 0.02), 0.0);
    let ell = widget(
        Shape::Ellipse {
            center: [0.5, 0.0],
            radii: [0.1, 0.02],
        },
        [1.0; 4],
        0.0,
    );
    let we = |u, g| ell.eval(u, g).map_or(0.0, |(w, _)| w);
    assert_eq!(we(0.5 + 0.06, 0.016 - 1e-9), 1.0); // d² = 0.36 + 0.64 − ε
    assert_eq!(we(0.5 + 0.06, 0.0161), 0.0);
    let tri = widget(
        Shape::Triangle {
            apex: 0.5,
            half_width: 0.2,
            gradient: [0.01, 0.05],
        },
        [1.0; 4],
        1.0,
    );
    let wt = |u, g| tri.eval(u, g).map_or(0.0, |(w, _)| w);
    // At g = 0.03 the half width is 0.1: d = |u − 0.5|/0.1, w = 1 − d.
    assert!((wt(0.53, 0.03) - 0.7).abs() < 1e-12);
    assert!((wt(0.45, 0.03) - 0.5).abs() < 1e-12);
    assert_eq!(wt(0.61, 0.03), 0.0);
    assert_eq!(wt(0.5, 0.009), 0.0); // below the apex
    assert_eq!(wt(0.5, 0.01), 1.0); // the apex itself
    assert!((wt(0.6, 0.05) - 0.5).abs() < 1e-12); // widest at the top
}

#[test]
fn overlaps_take_max_opacity_and_opacity_weighted_colour() {
    let a = widget(
        Shape::Rectangle {
            value: [0.0, 0.6],
            gradient: [0.0, 0.1],
        },
        [1.0, 0.0, 0.0, 0.2],
        0.0,
    );
    let b = widget(
        Shape::Rectangle {
            value: [0.4, 1.0],
            gradient: [0.0, 0.1],
        },
        [0.0, 0.0, 1.0, 0.6],
        0.0,
    );
    let t = tf2d(vec![a, b], GradientAxis::Linear, [8, 4]);
    let c = t.eval(0.5, 0.05);
    let want = [0.2 / 0.8, 0.0, 0.6 / 0.8, 0.6];
    for k in 0..4 {
        assert!((c[k] - want[k]).abs() < 1e-15, "{c:?} vs {want:?}");
    }
    // One widget alone gives its own colour exactly; none gives transparent black.
    assert_eq!(t.eval(0.1, 0.05), [1.0, 0.0, 0.0, 0.2]);
    assert_eq!(t.eval(0.5, 0.2), [0.0; 4]);
}

#[test]
fn the_table_holds_the_function_at_nodes_and_is_bilinear_between() {
    for axis in [GradientAxis::Linear, GradientAxis::Log] {
        let t = tf2d(phantom_widgets(), axis, [33, 17]);
        t.validate().unwrap();
        let lut = t.lut();
        let r = lut.to_real::<f64>();
        let node = |i: usize, j: usize| {
            (
                i as f64 / 32.0,
                t.gradient_at_axis(j as f64 / 16.0),
                t.eval_shaded(i as f64 / 32.0, t.gradient_at_axis(j as f64 / 16.0)),
            )
        };
        let mut worst: f64 = 0.0;
        for j in 0..17 {
            // The axis map inverts its inverse.
            let g = t.gradient_at_axis(j as f64 / 16.0);
            assert!(
                (r.gradient_coordinate(g) - j as f64).abs() < 1e-9,
                "{axis:?} row {j}"
            );
            for i in 0..33 {
                let (u, g, want) = node(i, j);
                let got = r.classify2d(u, g);
                for k in 0..4 {
                    worst = worst.max((got[k] - want[k]).abs());
                }
            }
        }
        // Node coordinates round-trip through the scale within ~1e-14, times the
        // table's slopes (≤ 33 per cell).
        assert!(worst < 1e-11, "{axis:?}: {worst:e}");
        // Between nodes: the bilinear blend of the four corners.
        let (fx, fy) = (0.3, 0.8);
        for (i, j) in [(3usize, 2usize), (10, 5), (20, 12), (31, 15)] {
            let u = (i as f64 + fx) / 32.0;
            let y = j as f64 + fy;
            let g = t.gradient_at_axis(y / 16.0);
            let (a, b, c, d) = (
                node(i, j).2,
                node(i + 1, j).2,
                node(i, j + 1).2,
                node(i + 1, j + 1).2,
            );
            let got = r.classify2d(u, g);
            for k in 0..4 {
                let r0 = a[k] + fx * (b[k] - a[k]);
                let r1 = c[k] + fx * (d[k] - c[k]);
                let want = r0 + fy * (r1 - r0);
                assert!((got[k] - want).abs() < 1e-11, "{axis:?} ({i},{j}) ch {k}");
            }
        }
    }
}

#[test]
fn json_round_trips_and_bad_json_is_a_clear_error() {
    for (name, _) in PRESETS_2D {
        let t = TransferFunction2D::preset(name).unwrap();
        assert_eq!(
            TransferFunction2D::from_json(&t.to_json()).unwrap(),
            t,
            "{name}"
        );
    }
    let t = tf2d(phantom_widgets(), GradientAxis::Log, [16, 8]);
    assert_eq!(TransferFunction2D::from_json(&t.to_json()).unwrap(), t);
    let ok = r#"{"domain":[0,1],"gradient_max":1,"widgets":[{"shape":{"type":"ellipse","center":[0.5,0],"radii":[0.1,0.2]},"rgba":[1,1,1,0.5]}]}"#;
    let t = TransferFunction2D::from_json(ok).unwrap();
    assert_eq!(t.lut_size, voxlab::transfer2d::DEFAULT_LUT_SIZE_2D);
    for (bad, words) in [
        ("{", "EOF"),
        (
            &ok.replace("\"gradient_max\":1", "\"gradient_max\":-1"),
            "gradient_max",
        ),
        (&ok.replace("ellipse", "hexagon"), "hexagon"),
        (&ok.replace("[0.1,0.2]", "[0.1,0]"), "radii"),
        (&ok.replace("[1,1,1,0.5]", "[1,1,2,0.5]"), "rgba"),
        (&ok.replace("\"rgba\"", "\"border\":3,\"rgba\""), "border"),
        (
            r#"{"domain":[0,1],"gradient_max":1,"widgets":[]}"#,
            "widget",
        ),
        (
            &ok.replace(
                "\"gradient_max\":1",
                "\"gradient_max\":1,\"lut_size\":[1,4]",
            ),
            "lut_size",
        ),
    ] {
        let e = TransferFunction2D::from_json(bad).unwrap_err().to_string();
        assert!(e.contains(words), "{bad}: {e}");
    }
}

fn scene(n: usize, w: usize, h: usize) -> Scene {
    let vol: AnyVolume = Phantom::shepp_logan_modified()
        .sample([n, n + 3, n - 2])
        .unwrap()
        .into();
    let camera = Camera::orbit(
        DVec3::ZERO,
        [256.0; 3],
        Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            distance_mm: Some(540.0),
        },
        Projection::Perspective { fov_y_deg: 30.0 },
        w,
        h,
    )
    .unwrap();
    Scene {
        volume: vol,
        transfer: TransferFunction::preset("phantom").unwrap(),
        camera,
    }
}

/// A 1D transfer function converted to 2D renders exactly like the 1D one: the 2D
/// table's value nodes coincide with the 1D table's (same size, domain and window), its
/// two gradient rows are equal, so the bilinear read is the 1D linear read plus
/// `fy·(r₁ − r₀) = 0`. Measured max |Δ| = 0 in f64 and f32, with and without shading,
/// for a piecewise-linear and a Bézier + faux-shaded 1D function; the bound 1e-12 only
/// allows for a compiler contracting the two reads differently.
#[test]
fn a_converted_1d_transfer_function_renders_like_the_1d_one() {
    let sc = scene(20, 32, 24);
    let mut bez = sc.transfer.clone();
    bez.interpolation = Interpolation::Bezier;
    bez.faux_shading = Some(1.5);
    for (tf, shading) in [(&sc.transfer, true), (&sc.transfer, false), (&bez, true)] {
        let mut s = RenderSettings::default();
        s.shading.enabled = shading;
        let one = render::<f64>(&sc.volume, tf, &sc.camera, &s, none()).unwrap();
        let one32 = render::<f32>(&sc.volume, tf, &sc.camera, &s, none()).unwrap();
        s.transfer_2d = Some(TransferFunction2D::from_1d(tf, s.lut_size, 0.1));
        let two = render::<f64>(&sc.volume, tf, &sc.camera, &s, none()).unwrap();
        let two32 = render::<f32>(&sc.volume, tf, &sc.camera, &s, none()).unwrap();
        let (d, d32) = (
            max_abs_error(&one.image, &two.image),
            max_abs_error(&one32.image, &two32.image),
        );
        eprintln!("1D vs converted 2D, shading {shading}: f64 {d:e}, f32 {d32:e}");
        assert!(d <= 1e-12 && d32 <= 1e-6, "{d:e} {d32:e}");
        assert!(one.image.data.iter().any(|&v| v > 0.05));
    }
}

/// A linear ramp `f = x` (index) on a grid of spacing 0.5 mm has world gradient
/// magnitude 2 per mm everywhere inside (1 at the clamped faces). A widget covering
/// gradients [0, 2.5] over every value renders exactly like the constant 1D transfer
/// function of the same RGBA (the table rows 0 … 2 are that RGBA, row 3 is 0, and the
/// samples read rows ≤ 2 or row 2 with fy ≈ 0: measured max |Δ| 0); one covering
/// [2.5, 8] only renders the background.
#[test]
fn gradient_magnitude_in_world_units_selects_what_is_seen() {
    let n = 12;
    let data: Vec<f32> = (0..n * n * n).map(|i| (i % n) as f32).collect();
    let vol: AnyVolume = Volume::new([n; 3], [0.5; 3], data).unwrap().into();
    let rgba = [0.9, 0.6, 0.3, 0.2];
    let constant = TransferFunction {
        name: String::new(),
        domain: [-1.0, 20.0],
        points: vec![ControlPoint { value: 0.0, rgba }],
        window: WindowMap::default(),
        interpolation: Interpolation::Linear,
        faux_shading: None,
    };
    let cam = Camera::orbit(
        DVec3::splat(2.75),
        [6.0; 3],
        Orbit::default(),
        Projection::Perspective { fov_y_deg: 30.0 },
        16,
        16,
    )
    .unwrap();
    let mut s = RenderSettings::default();
    s.shading.enabled = false;
    let want = render::<f64>(&vol, &constant, &cam, &s, none())
        .unwrap()
        .image;
    let band = |g: [f64; 2]| TransferFunction2D {
        name: String::new(),
        domain: [-1.0, 20.0],
        gradient_max: 8.0,
        gradient_axis: GradientAxis::Linear,
        gradient_g0: None,
        widgets: vec![widget(
            Shape::Rectangle {
                value: [-1.0, 20.0],
                gradient: g,
            },
            rgba,
            0.0,
        )],
        window: WindowMap::default(),
        lut_size: [8, 9],
        faux_shading: None,
    };
    s.transfer_2d = Some(band([0.0, 2.5]));
    let got = render::<f64>(&vol, &constant, &cam, &s, none())
        .unwrap()
        .image;
    let d = max_abs_error(&want, &got);
    assert!(d < 1e-12, "{d:e}");
    s.transfer_2d = Some(band([2.5, 8.0]));
    let got = render::<f64>(&vol, &constant, &cam, &s, none())
        .unwrap()
        .image;
    for px in got.data.chunks(4) {
        assert_eq!(px, &[0.0, 0.0, 0.0, 1.0]);
    }
}

/// Bézier segments against the Bernstein formula written out here, per channel.
#[test]
fn bezier_curves_match_the_bernstein_formula() {
    let pts = vec![
        ControlPoint {
            value: 0.0,
            rgba: [0.0, 0.2, 1.0, 0.0],
        },
        ControlPoint {
            value: 0.3,
            rgba: [0.5, 0.9, 0.4, 0.3],
        },
        ControlPoint {
            value: 0.5,
            rgba: [1.0, 0.1, 0.2, 0.8],
        },
        ControlPoint {
            value: 1.0,
            rgba: [0.6, 0.5, 0.0, 0.5],
        },
    ];
    let tf = TransferFunction {
        name: "bez".into(),
        domain: [0.0, 1.0],
        points: pts.clone(),
        window: WindowMap::default(),
        interpolation: Interpolation::Bezier,
        faux_shading: None,
    };
    tf.validate().unwrap();
    let v: Vec<f64> = pts.iter().map(|p| p.value).collect();
    let slope = |i: usize, c: usize| {
        let (a, b) = (i.saturating_sub(1), (i + 1).min(3));
        (pts[b].rgba[c] - pts[a].rgba[c]) / (v[b] - v[a])
    };
    let mut max_err: f64 = 0.0;
    for i in 0..3 {
        let h = v[i + 1] - v[i];
        for s in 0..=20 {
            let u = s as f64 / 20.0;
            let x = v[i] + u * h;
            let got = tf.eval(x);
            for (c, got_c) in got.iter().enumerate() {
                let b = [
                    pts[i].rgba[c],
                    pts[i].rgba[c] + h * slope(i, c) / 3.0,
                    pts[i + 1].rgba[c] - h * slope(i + 1, c) / 3.0,
                    pts[i + 1].rgba[c],
                ];
                let mut want = 0.0;
                for k in 0..4 {
                    let binom = [1.0, 3.0, 3.0, 1.0][k];
                    want += binom * u.powi(k as i32) * (1.0 - u).powi(3 - k as i32) * b[k];
                }
                let want = want.clamp(0.0, 1.0);
                max_err = max_err.max((got_c - want).abs());
            }
        }
    }
    // Measured 2.2e-16: the same polynomial summed in another order.
    assert!(max_err < 1e-14, "{max_err:e}");
    // Through the control points; the Bernstein basis sums to 1.
    for p in &pts {
        assert_eq!(tf.eval(p.value), p.rgba);
    }
    assert!((bernstein3(0.37).iter().sum::<f64>() - 1.0).abs() < 1e-15);
    let back = TransferFunction::from_json(&tf.to_json()).unwrap();
    assert_eq!(back, tf);
    assert!(tf.to_json().contains("\"bezier\""));
}

#[test]
fn faux_shading_darkens_colour_by_relative_opacity() {
    let mut tf = TransferFunction::preset("ct-bone").unwrap();
    let k = 2.0;
    tf.faux_shading = Some(k);
    let amax = 1.0; // ct-bone's largest opacity
    assert_eq!(tf.alpha_max(), amax);
    let lut = tf.lut(64);
    let mut plain = tf.clone();
    plain.faux_shading = None;
    let raw = plain.lut(64);
    for (e, r) in lut.entries.iter().zip(&raw.entries) {
        let f = (r[3] / amax).powf(k);
        for c in 0..3 {
            assert!((e[c] - r[c] * f).abs() < 1e-15);
        }
        assert_eq!(e[3], r[3]);
    }
    assert_eq!(
        faux_shade([0.8, 0.4, 0.2, 0.25], 0.5, 1.0),
        [0.4, 0.2, 0.1, 0.25]
    );
    let back = TransferFunction::from_json(&tf.to_json()).unwrap();
    assert_eq!(back.faux_shading, Some(2.0));
    tf.faux_shading = Some(-1.0);
    assert!(tf.validate().is_err());
}

#[test]
fn hounsfield_presets_exist_in_1d_and_2d_and_round_trip() {
    for name in HU_PRESETS {
        let one = TransferFunction::preset(name).unwrap();
        assert_eq!(TransferFunction::from_json(&one.to_json()).unwrap(), one);
        let two = TransferFunction2D::preset(&format!("{name}-2d")).unwrap();
        assert_eq!(two.domain, [-1000.0, 3000.0], "{name}");
    }
    // Each 1D preset is opaque somewhere in its Hounsfield range (Fluør Table 3.1).
    for (name, hu) in [
        ("ct-air", -1000.0),
        ("ct-fat", -100.0),
        ("ct-water", 0.0),
        ("ct-blood", 66.0),
        ("ct-bone", 1000.0),
    ] {
        assert!(
            TransferFunction::preset(name).unwrap().eval(hu)[3] > 0.0,
            "{name}"
        );
    }
}

fn pixel_renderer() -> Renderer {
    Renderer::new(Backend::Cpu).unwrap()
}

/// With zero separation both eyes are the mono camera: bit-identical views.
#[test]
fn stereo_with_zero_separation_equals_the_mono_render() {
    let sc = scene(16, 24, 18);
    let s = RenderSettings::default();
    let r = pixel_renderer();
    let mono = r.render(&sc, &s, none()).unwrap().output.image;
    let pair = voxlab::jobs::stereo::render_pair(&r, &sc, &s, 0.0, 540.0, none()).unwrap();
    assert_eq!(pair.cameras.shift_px, 0);
    assert_eq!(pair.left.data, mono.data);
    assert_eq!(pair.right.data, mono.data);
}

#[test]
fn stereo_layouts_take_their_channels_and_rows_from_the_right_eye() {
    let sc = scene(16, 24, 18);
    let s = RenderSettings::default();
    let r = pixel_renderer();
    let pair = voxlab::jobs::stereo::render_pair(&r, &sc, &s, 65.0, 540.0, none()).unwrap();
    // s = e·H/(4 D tan 15°) = 65·18/(4·540·0.268) = 2.02 → 2 px.
    assert_eq!(pair.cameras.shift_px, 2);
    assert!(
        max_abs_error(&pair.left, &pair.right) > 0.01,
        "the eyes see differently"
    );
    let (l, rt) = (&pair.left, &pair.right);
    let ana = combine(l, rt, StereoLayout::Anaglyph).unwrap();
    for i in 0..l.width * l.height {
        let (a, p, q) = (
            &ana.data[i * 4..i * 4 + 4],
            &l.data[i * 4..],
            &rt.data[i * 4..],
        );
        assert_eq!(a[0], p[0]);
        assert_eq!(a[1], q[1]);
        assert_eq!(a[2], q[2]);
        assert_eq!(a[3], p[3].max(q[3]));
    }
    let sbs = combine(l, rt, StereoLayout::SideBySide).unwrap();
    let il = combine(l, rt, StereoLayout::Interlaced).unwrap();
    assert_eq!((sbs.width, sbs.height), (2 * l.width, l.height));
    for row in 0..l.height {
        for col in 0..l.width {
            assert_eq!(sbs.pixel(col, row), l.pixel(col, row));
            assert_eq!(sbs.pixel(col + l.width, row), rt.pixel(col, row));
            let src = if row % 2 == 0 { l } else { rt };
            assert_eq!(il.pixel(col, row), src.pixel(col, row));
        }
    }
    // The left view is a window of a symmetric frustum shifted 2 px: equal to rendering
    // the wide left camera and cropping by hand.
    let cams = stereo_cameras(&sc.camera, 65.0, 540.0).unwrap();
    let wide = Scene {
        camera: cams.left.clone(),
        ..sc.clone()
    };
    let full = r.render(&wide, &s, none()).unwrap().output.image;
    assert_eq!(
        voxlab::jobs::stereo::crop_columns(&full, 4, 24).data,
        l.data
    );
    // Orthographic cameras are refused.
    let mut ortho = sc.camera.clone();
    ortho.projection = Projection::Orthographic {
        width_mm: 200.0,
        height_mm: 150.0,
    };
    assert!(stereo_cameras(&ortho, 65.0, 540.0).is_err());
    assert!(stereo_cameras(&sc.camera, -1.0, 540.0).is_err());
}
