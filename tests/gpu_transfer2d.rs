//! The GPU's 2D transfer-function classification against the CPU f64 oracle, from one
//! case list; and a 1D transfer function converted to 2D against the 1D render.

mod common;

use glam::DVec3;
use voxlab::camera::{Camera, Orbit, Projection};
use voxlab::metrics::Tolerance;
use voxlab::phantom::Phantom;
use voxlab::settings::RenderSettings;
use voxlab::transfer::{Interpolation, TransferFunction, WindowMap};
use voxlab::transfer2d::{GradientAxis, Shape, TransferFunction2D, Widget};
use voxlab::AnyVolume;

#[derive(Clone, Copy, Debug)]
struct Case {
    axis: GradientAxis,
    shading: bool,
    precompute: bool,
    faux: Option<f64>,
}

const CASES: &[(&str, Case)] = &[
    (
        "linear",
        Case {
            axis: GradientAxis::Linear,
            shading: false,
            precompute: false,
            faux: None,
        },
    ),
    (
        "log_shaded",
        Case {
            axis: GradientAxis::Log,
            shading: true,
            precompute: false,
            faux: None,
        },
    ),
    (
        "log_precomputed_faux",
        Case {
            axis: GradientAxis::Log,
            shading: true,
            precompute: true,
            faux: Some(2.0),
        },
    ),
];

fn widgets() -> Vec<Widget> {
    let w = |shape, rgba, border| Widget {
        shape,
        rgba,
        border,
    };
    vec![
        w(
            Shape::Triangle {
                apex: 0.3,
                half_width: 0.15,
                gradient: [0.002, 0.05],
            },
            [1.0, 0.8, 0.6, 0.6],
            0.5,
        ),
        w(
            Shape::Ellipse {
                center: [0.2, 0.0],
                radii: [0.05, 0.01],
            },
            [0.3, 0.6, 1.0, 0.3],
            0.5,
        ),
        w(
            Shape::Rectangle {
                value: [0.95, 1.0],
                gradient: [0.0, 0.1],
            },
            [1.0, 1.0, 1.0, 0.4],
            0.2,
        ),
    ]
}

fn scene() -> (AnyVolume, TransferFunction, Camera) {
    let vol: AnyVolume = Phantom::shepp_logan_modified()
        .sample([24, 27, 22])
        .unwrap()
        .into();
    let cam = Camera::orbit(
        DVec3::ZERO,
        [256.0; 3],
        Orbit {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            distance_mm: Some(540.0),
        },
        Projection::Perspective { fov_y_deg: 30.0 },
        40,
        30,
    )
    .unwrap();
    (vol, TransferFunction::preset("phantom").unwrap(), cam)
}

/// 2D classification, lavapipe (Mesa 22.3.6), Shepp–Logan 24×27×22 at 40×30: measured
/// max |Δ| 4.4e-5 (linear axis, unshaded), 2.9e-4 (log axis, shaded), 7.3e-5 (log,
/// precomputed gradients, faux shading); RMSE ≤ 5.5e-6. The differences are f32 rounding of the sample positions and of the gradient
/// (a difference of two interpolated values, then |J⁻ᵀ ∇f|), amplified by the widgets'
/// soft edges (slope up to 1/(0.5·0.15) per unit value and 1/(0.5·0.01) per unit
/// gradient). Bound: about 3.5× the worst.
const DVR_2D: Tolerance = Tolerance {
    max_abs: 1e-3,
    rmse: 2e-5,
    ..Tolerance::NONE
};

#[test]
fn gpu_2d_classification_matches_the_oracle() {
    let Some(ctx) = common::gpu("gpu_2d_classification_matches_the_oracle") else {
        return;
    };
    let (vol, tf, cam) = scene();
    for (name, c) in CASES {
        let mut s = RenderSettings {
            precompute_gradients: c.precompute,
            transfer_2d: Some(TransferFunction2D {
                name: (*name).into(),
                domain: [0.0, 1.0],
                gradient_max: 0.1,
                gradient_axis: c.axis,
                gradient_g0: Some(0.005),
                widgets: widgets(),
                window: WindowMap::default(),
                lut_size: [256, 64],
                faux_shading: c.faux,
            }),
            ..RenderSettings::default()
        };
        s.shading.enabled = c.shading;
        let cpu = voxlab::cpu::raycast::render::<f64>(&vol, &tf, &cam, &s, &|_, _| {}).unwrap();
        let gpu = voxlab::gpu::raycast::render(ctx, &vol, &tf, &cam, &s, &|_, _| {})
            .unwrap()
            .output;
        assert!(cpu.image.data.iter().any(|&v| v > 0.05), "{name}: blank");
        let st = common::assert_parity(&format!("tf2d_{name}"), &cpu.image, &gpu.image, DVR_2D);
        eprintln!("{name}: max |Δ| {:.2e}, rmse {:.2e}", st.max_abs, st.rmse);
    }
}

/// A 1D transfer function converted to 2D renders on the GPU exactly as the 1D one
/// does on the GPU (same f32 value coordinate, two equal gradient rows: measured max
/// |Δ| 0), for a piecewise-linear and a Bézier + faux-shaded curve.
#[test]
fn gpu_converted_1d_transfer_function_renders_like_the_1d_one() {
    let Some(ctx) = common::gpu("gpu_converted_1d_transfer_function_renders_like_the_1d_one")
    else {
        return;
    };
    let (vol, tf, cam) = scene();
    let mut bez = tf.clone();
    bez.interpolation = Interpolation::Bezier;
    bez.faux_shading = Some(1.5);
    for tf in [tf, bez] {
        let mut s = RenderSettings::default();
        let one = voxlab::gpu::raycast::render(ctx, &vol, &tf, &cam, &s, &|_, _| {})
            .unwrap()
            .output;
        s.transfer_2d = Some(TransferFunction2D::from_1d(&tf, s.lut_size, 0.1));
        let two = voxlab::gpu::raycast::render(ctx, &vol, &tf, &cam, &s, &|_, _| {})
            .unwrap()
            .output;
        let d = voxlab::metrics::error_stats(&one.image.data, &two.image.data, f64::INFINITY)
            .infinite_if_mismatched()
            .max_abs;
        eprintln!(
            "GPU 1D vs converted 2D ({:?}): max |Δ| {d:e}",
            tf.interpolation
        );
        assert!(d <= 1e-6, "{d:e}");
    }
}
