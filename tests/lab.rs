//! The lab's model without a window: the view state and its JSON round trip, the orbit
//! camera's operations, the transfer-function editors' operations, the 2-D histogram,
//! and `voxlab render --state`.

mod common;

use common::{s, scratch, stderr, voxlab};
use glam::DVec3;
use voxlab::camera::{AxisView, Camera, Orbit, Projection};
use voxlab::editor::{self, WidgetKind};
use voxlab::jobs::input::{volume_center, volume_extent, VolumeInput};
use voxlab::jobs::render::{render, Backend};
use voxlab::jobs::view::{joint_histogram, ViewProjection, ViewState};
use voxlab::transfer::{ControlPoint, TransferFunction};
use voxlab::transfer2d::{GradientAxis, TransferFunction2D};
use voxlab::volume::Volume;
use voxlab::{AnyVolume, Error};

fn phantom_state(n: usize, w: usize, h: usize) -> (ViewState, AnyVolume) {
    let input = VolumeInput::new(format!("phantom:shepp-logan-modified:{n}"));
    let volume = input.load(&()).unwrap();
    (ViewState::new(input, &volume, w, h).unwrap(), volume)
}

fn close(a: DVec3, b: DVec3, eps: f64) -> bool {
    (a - b).abs().max_element() <= eps
}

#[test]
fn the_default_view_is_the_render_jobs_default_camera() {
    let (state, volume) = phantom_state(24, 40, 30);
    let lab = state.camera().unwrap();
    let job = Camera::orbit(
        volume_center(&volume),
        volume_extent(&volume),
        Orbit::default(),
        Projection::Perspective { fov_y_deg: 30.0 },
        40,
        30,
    )
    .unwrap();
    for (a, b) in [
        (lab.eye, job.eye),
        (lab.forward, job.forward),
        (lab.right, job.right),
        (lab.up, job.up),
    ] {
        assert!(close(a, b, 1e-12 * job.eye.length().max(1.0)), "{a} vs {b}");
    }
    assert_eq!(lab.projection, job.projection);
    // The phantom gets the phantom preset, as `--tf auto` gives it.
    assert_eq!(state.transfer, TransferFunction::preset("phantom").unwrap());
}

#[test]
fn a_state_round_trips_through_json_exactly() {
    let (mut state, _) = phantom_state(16, 33, 17);
    state.view.orbit_by(13.0, -7.0);
    state.view.pan_by(3.0, 5.0, 17);
    state.view.zoom_by(1.7);
    state.settings.step = 0.37;
    state.settings.transfer_2d = Some(TransferFunction2D::preset("ct-bone-2d").unwrap());
    editor::add_point(&mut state.transfer, 0.3, 0.2);
    let path = scratch("lab-state").join("state.json");
    state.save(&path).unwrap();
    let back = ViewState::load(&path).unwrap();
    assert_eq!(back.to_json(), state.to_json());
    assert_eq!(back.camera().unwrap(), state.camera().unwrap());
    assert_eq!(back.settings, state.settings);
    assert_eq!(back.transfer, state.transfer);
}

#[test]
fn a_bad_state_names_its_field() {
    let (state, _) = phantom_state(8, 8, 8);
    let json = state.to_json();
    let p = std::path::Path::new("s.json");
    let err = |text: &str| ViewState::from_json(text, p).unwrap_err().to_string();
    let e = err(&json.replace("voxlab-view-state", "something"));
    assert!(e.contains("format") && e.contains("s.json"), "{e}");
    let e = err(&json.replace("\"version\": 1", "\"version\": 7"));
    assert!(e.contains("version") && e.contains('7'), "{e}");
    let e = err(&json.replace("\"elevation_deg\": 20.0", "\"elevation_deg\": 120.0"));
    assert!(e.contains("view.elevation_deg"), "{e}");
    let e = err(&json.replace("\"width\": 8", "\"widht\": 8"));
    assert!(e.contains("width"), "{e}");
    let e = err(&json.replace("\"fov_y_deg\": 30.0", "\"fov_y_deg\": 0.0"));
    assert!(e.contains("fov_y_deg"), "{e}");
}

#[test]
fn orbit_pan_zoom_and_axis_views() {
    let (state, _) = phantom_state(16, 64, 64);
    let v0 = state.view;
    let c0 = v0.camera(64, 64).unwrap();
    let target = DVec3::from_array(v0.target);

    // Orbiting keeps the target and the distance.
    let mut v = v0;
    v.orbit_by(50.0, 20.0);
    let c = v.camera(64, 64).unwrap();
    assert!((c.eye.distance(target) - v0.distance_mm).abs() < 1e-9);
    assert!((v.azimuth_deg - (v0.azimuth_deg - 20.0)).abs() < 1e-12);
    assert!((v.elevation_deg - (v0.elevation_deg + 8.0)).abs() < 1e-12);
    v.orbit_by(0.0, 1e6);
    assert_eq!(v.elevation_deg, 90.0);
    let top = v.camera(64, 64).unwrap();
    assert!(close(top.forward, -DVec3::Z, 1e-12), "{}", top.forward);

    // Panning moves target and eye together, in the image plane, by mm per pixel.
    let mut v = v0;
    v.pan_by(10.0, -4.0, 64);
    let c = v.camera(64, 64).unwrap();
    let mm = v0.mm_per_pixel(64);
    let moved = DVec3::from_array(v.target) - target;
    assert!(close(
        moved,
        c0.right * (-10.0 * mm) + c0.up * (-4.0 * mm),
        1e-9
    ));
    assert!(close(c.forward, c0.forward, 1e-12));

    // Zooming by 2 halves the distance; in orthographic, the visible height.
    let mut v = v0;
    v.zoom_by(2.0);
    assert!((v.distance_mm - v0.distance_mm / 2.0).abs() < 1e-9);
    let mut o = v0;
    o.set_orthographic(true, 30.0);
    let ViewProjection::Orthographic { height_mm } = o.projection else {
        panic!("orthographic")
    };
    assert!((height_mm - 64.0 * v0.mm_per_pixel(64)).abs() < 1e-9);
    o.zoom_by(2.0);
    assert!((o.mm_per_pixel(64) - v0.mm_per_pixel(64) / 2.0).abs() < 1e-12);
    o.set_orthographic(false, 30.0);
    assert!((o.mm_per_pixel(64) - v0.mm_per_pixel(64) / 2.0).abs() < 1e-9);

    // Axis views: rays along the named world axis.
    for (view, dir) in [
        (AxisView::PlusX, DVec3::X),
        (AxisView::MinusX, -DVec3::X),
        (AxisView::PlusY, DVec3::Y),
        (AxisView::MinusY, -DVec3::Y),
        (AxisView::PlusZ, DVec3::Z),
        (AxisView::MinusZ, -DVec3::Z),
    ] {
        let mut v = v0;
        v.look_along(view);
        let c = v.camera(64, 64).unwrap();
        assert!(close(c.forward, dir, 1e-12), "{view:?}: {}", c.forward);
        assert!(c.up.dot(c.forward).abs() < 1e-12 && (c.up.length() - 1.0).abs() < 1e-12);
    }
}

fn ramp_tf() -> TransferFunction {
    TransferFunction {
        name: "test".into(),
        domain: [0.0, 1.0],
        points: vec![
            ControlPoint {
                value: 0.0,
                rgba: [0.0, 0.2, 1.0, 0.0],
            },
            ControlPoint {
                value: 1.0,
                rgba: [1.0, 0.6, 0.0, 0.5],
            },
        ],
        window: Default::default(),
        interpolation: Default::default(),
        faux_shading: None,
    }
}

#[test]
fn editor_points_add_move_delete_and_pick() {
    let mut tf = ramp_tf();
    // A new point takes the curve's colour there (the mean of the ends at 0.5).
    let i = editor::add_point(&mut tf, 0.5, 0.9);
    assert_eq!(i, 1);
    assert_eq!(tf.points[1].rgba, [0.5, 0.4, 0.5, 0.9]);
    tf.validate().unwrap();
    // Outside the domain: clamped.
    assert_eq!(editor::add_point(&mut tf, 7.0, 2.0), 3);
    assert_eq!((tf.points[3].value, tf.points[3].rgba[3]), (1.0, 1.0));
    editor::delete_point(&mut tf, 3).unwrap();

    // A drag never passes a neighbour.
    assert_eq!(
        editor::move_point(&mut tf, 1, 1.5, -1.0).unwrap(),
        [1.0, 0.0]
    );
    assert_eq!(
        editor::move_point(&mut tf, 1, 0.25, 0.3).unwrap(),
        [0.25, 0.3]
    );
    tf.validate().unwrap();
    editor::set_colour(&mut tf, 1, [2.0, 0.5, -1.0]).unwrap();
    assert_eq!(tf.points[1].rgba, [1.0, 0.5, 0.0, 0.3]);

    // Picking measures in the editor's aspect: opacity over the range it shows.
    assert_eq!(editor::nearest_point(&tf, 0.26, 0.31, 1.0, 0.02), Some(1));
    assert_eq!(editor::nearest_point(&tf, 0.26, 0.31, 0.1, 0.02), None);
    assert_eq!(editor::nearest_point(&tf, 0.6, 0.2, 1.0, 0.05), None);

    // The last point stays.
    editor::delete_point(&mut tf, 0).unwrap();
    editor::delete_point(&mut tf, 0).unwrap();
    assert!(editor::delete_point(&mut tf, 0).is_err());
    assert!(editor::move_point(&mut tf, 5, 0.0, 0.0).is_err());
    tf.validate().unwrap();

    // What the editor saves, `--tf` reads.
    let back = TransferFunction::from_json(&tf.to_json()).unwrap();
    assert_eq!(back, tf);
}

#[test]
fn window_level_round_trips_and_maps_the_window_onto_the_domain() {
    let mut tf = ramp_tf();
    assert_eq!(editor::window_level(&tf), (1.0, 0.5));
    editor::set_window_level(&mut tf, 400.0, 40.0).unwrap();
    let (w, l) = editor::window_level(&tf);
    assert!((w - 400.0).abs() < 1e-9 && (l - 40.0).abs() < 1e-9);
    assert!((tf.window.apply(-160.0) - 0.0).abs() < 1e-12);
    assert!((tf.window.apply(240.0) - 1.0).abs() < 1e-12);
    assert!(editor::set_window_level(&mut tf, 0.0, 1.0).is_err());
    assert!(editor::set_window_level(&mut tf, 1.0, f64::NAN).is_err());
}

fn near(a: [f64; 2], b: [f64; 2]) -> bool {
    (a[0] - b[0]).abs() < 1e-12 && (a[1] - b[1]).abs() < 1e-12
}

#[test]
fn editor_widgets_add_pick_move_resize_delete() {
    let mut tf = TransferFunction2D::from_1d(&ramp_tf(), 64, 10.0);
    tf.widgets.clear();
    for (k, kind) in [
        WidgetKind::Rectangle,
        WidgetKind::Ellipse,
        WidgetKind::Triangle,
    ]
    .into_iter()
    .enumerate()
    {
        let c = [0.2 + 0.3 * k as f64, 5.0];
        let i = editor::add_widget(&mut tf, kind, c, [0.05, 2.0], [1.0, 0.0, 0.0, 0.5]).unwrap();
        assert_eq!(i, k);
        let (at, half) = editor::widget_box(&tf.widgets[i]);
        assert!(
            near(at, c) && near(half, [0.05, 2.0]),
            "{kind:?}: {at:?} {half:?}"
        );
        assert_eq!(editor::widget_at(&tf, c[0], c[1]), Some(i), "{kind:?}");
        assert_eq!(editor::widget_at(&tf, c[0] + 0.08, c[1]), None, "{kind:?}");
        editor::move_widget(&mut tf, i, [0.01, 1.0]).unwrap();
        let moved = [c[0] + 0.01, 6.0];
        let (at, half) = editor::widget_box(&tf.widgets[i]);
        assert!(
            near(at, moved) && near(half, [0.05, 2.0]),
            "{kind:?}: {at:?} {half:?}"
        );
        editor::resize_widget(&mut tf, i, [0.02, 3.0]).unwrap();
        let (at2, half) = editor::widget_box(&tf.widgets[i]);
        assert!((at2[0] - moved[0]).abs() < 1e-12 && (at2[1] - moved[1]).abs() < 1e-12);
        assert!((half[0] - 0.02).abs() < 1e-12 && (half[1] - 3.0).abs() < 1e-12);
        tf.validate().unwrap();
    }
    // The topmost widget wins where two overlap.
    editor::add_widget(
        &mut tf,
        WidgetKind::Ellipse,
        [0.21, 6.0],
        [0.1, 4.0],
        [0.0; 4],
    )
    .unwrap();
    assert_eq!(editor::widget_at(&tf, 0.21, 6.0), Some(3));
    // A refused widget leaves the function as it was.
    let before = tf.clone();
    assert!(editor::add_widget(
        &mut tf,
        WidgetKind::Rectangle,
        [0.5, 1.0],
        [0.0, 1.0],
        [1.0; 4]
    )
    .is_err());
    assert!(editor::add_widget(
        &mut tf,
        WidgetKind::Rectangle,
        [0.5, 1.0],
        [0.1, 1.0],
        [2.0; 4]
    )
    .is_err());
    assert_eq!(tf, before);
    editor::delete_widget(&mut tf, 0).unwrap();
    assert_eq!(tf.widgets.len(), 3);
    assert!(editor::delete_widget(&mut tf, 3).is_err());
    assert!(editor::resize_widget(&mut tf, 0, [-1.0, 1.0]).is_err());
    let back = TransferFunction2D::from_json(&tf.to_json()).unwrap();
    assert_eq!(back, tf);
}

#[test]
fn a_widgets_handles_resize_it_about_the_opposite_side() {
    let mut tf = TransferFunction2D::from_1d(&ramp_tf(), 64, 10.0);
    tf.widgets.clear();
    for kind in [
        WidgetKind::Rectangle,
        WidgetKind::Ellipse,
        WidgetKind::Triangle,
    ] {
        tf.widgets.clear();
        let i = editor::add_widget(&mut tf, kind, [0.5, 5.0], [0.1, 2.0], [1.0; 4]).unwrap();
        let handles = editor::widget_handles(&tf.widgets[i]);
        assert_eq!(handles.len(), 8, "{kind:?}");
        // The corners and edge midpoints of the box [0.4, 0.6] × [3, 7].
        let at = |v: i8, g: i8| {
            handles
                .iter()
                .find(|(h, _)| h.value == v && h.gradient == g)
                .map(|(_, p)| *p)
                .unwrap()
        };
        assert!(near(at(-1, -1), [0.4, 3.0]) && near(at(1, 1), [0.6, 7.0]));
        assert!(near(at(0, 1), [0.5, 7.0]) && near(at(1, 0), [0.6, 5.0]));
        // The high-value, high-gradient corner dragged to (0.7, 9): the low corner stays.
        let corner = editor::Handle {
            value: 1,
            gradient: 1,
        };
        editor::drag_handle(&mut tf, i, corner, [0.7, 9.0]).unwrap();
        let (c, h) = editor::widget_box(&tf.widgets[i]);
        assert!(
            near(c, [0.55, 6.0]) && near(h, [0.15, 3.0]),
            "{kind:?}: {c:?} {h:?}"
        );
        // The low-value edge's midpoint: only the value extent changes.
        let edge = editor::Handle {
            value: -1,
            gradient: 0,
        };
        editor::drag_handle(&mut tf, i, edge, [0.5, 123.0]).unwrap();
        let (c, h) = editor::widget_box(&tf.widgets[i]);
        assert!(
            near(c, [0.6, 6.0]) && near(h, [0.1, 3.0]),
            "{kind:?}: {c:?} {h:?}"
        );
        // Past the opposite edge the box turns over instead of inverting.
        editor::drag_handle(&mut tf, i, edge, [0.9, 0.0]).unwrap();
        let (c, h) = editor::widget_box(&tf.widgets[i]);
        assert!(
            near(c, [0.8, 6.0]) && near(h, [0.1, 3.0]),
            "{kind:?}: {c:?} {h:?}"
        );
        tf.validate().unwrap();
        assert!(editor::drag_handle(&mut tf, i, edge, [f64::NAN, 0.0]).is_err());
        assert!(editor::drag_handle(&mut tf, 7, edge, [0.5, 0.0]).is_err());
    }
}

#[test]
fn the_joint_histogram_counts_a_ramp_at_its_slope() {
    // f = 3·x mm with 2 mm voxels along x: |∇f| = 3 per mm inside, half that on the two
    // x faces (clamped neighbours); values 0, 6, …, 42.
    let n = [8, 5, 4];
    let vol = Volume::<f32>::from_fn(n, [2.0, 1.0, 1.0], |i, _, _| 6.0 * i as f32).unwrap();
    let volume = AnyVolume::F32(vol);
    let mut tf = TransferFunction2D::from_1d(&ramp_tf(), 64, 4.0);
    tf.domain = [0.0, 48.0];
    tf.gradient_axis = GradientAxis::Linear;
    let h = joint_histogram(&volume, &tf, [8, 4]).unwrap();
    assert_eq!(h.bins, [8, 4]);
    assert_eq!(h.counts.iter().sum::<u64>(), 8 * 5 * 4);
    let plane = 5 * 4;
    for i in 0..8 {
        // Value 6i falls in value bin i; slope 3 in gradient bin 3 (3/4 of g_max 4),
        // the faces' 1.5 in bin 1.
        let g = if i == 0 || i == 7 { 1 } else { 3 };
        assert_eq!(h.counts[g * 8 + i], plane, "value bin {i}");
    }
}

#[test]
fn embedded_scans_are_inputs() {
    let v = VolumeInput::new("embedded:microct-bone").load(&()).unwrap();
    assert_eq!(v.dims(), [128, 128, 128]);
    let v = VolumeInput::new("embedded:mr-brain").load(&()).unwrap();
    assert_eq!(v.dims(), [128, 128, 84]);
    let e = VolumeInput::new("embedded:knee").load(&()).unwrap_err();
    assert!(e.to_string().contains("microct-bone"), "{e}");
}

#[test]
fn render_state_draws_the_states_scene() {
    let dir = scratch("lab-render-state");
    let (mut state, volume) = phantom_state(24, 48, 36);
    state.view.orbit_by(-30.0, 15.0);
    state.view.zoom_by(1.3);
    state.settings.step = 0.8;
    editor::add_point(&mut state.transfer, 0.5, 0.05);
    let path = dir.join("state.json");
    state.save(&path).unwrap();
    let out = dir.join("cpu.npy");
    let o = voxlab(&["render", "--state", s(&path), "--out", s(&out)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (scene, settings) = state.scene(volume).unwrap();
    let want = render(&scene, &settings, Backend::Cpu).unwrap();
    let (shape, got) = voxlab::io::npy::read_npy_f32(&out).unwrap();
    assert_eq!(shape, vec![36, 48, 4]);
    assert_eq!(got.len(), want.image.data.len());
    for (g, w) in got.iter().zip(&want.image.data) {
        assert_eq!(*g, *w as f32);
    }
    // INPUT and --state exclude each other; one of them is needed.
    let o = voxlab(&[
        "render",
        "phantom:sphere:8",
        "--state",
        s(&path),
        "--out",
        s(&out),
    ]);
    assert!(
        !o.status.success() && stderr(&o).contains("--state"),
        "{}",
        stderr(&o)
    );
    let o = voxlab(&["render", "--out", s(&out)]);
    assert!(
        !o.status.success() && stderr(&o).contains("INPUT"),
        "{}",
        stderr(&o)
    );
    // A broken state names the file and the field.
    std::fs::write(
        &path,
        state.to_json().replace("\"step\": 0.8", "\"step\": -1.0"),
    )
    .unwrap();
    let o = voxlab(&["render", "--state", s(&path), "--out", s(&out)]);
    assert!(!o.status.success(), "a negative step was accepted");
    let e = stderr(&o);
    assert!(e.contains("state.json") && e.contains("step"), "{e}");
    assert!(matches!(
        ViewState::load(&path).unwrap_err(),
        Error::Format { .. }
    ));
}
