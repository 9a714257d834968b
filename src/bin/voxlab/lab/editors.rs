//! The transfer-function editors: a 1-D editor over the volume's histogram (log
//! counts) and a 2-D editor over the value × gradient-magnitude histogram. Drawing and
//! pointer handling only; every edit is a call into [`voxlab::editor`].

use eframe::egui::{self, Color32, Pos2, Rect, Sense, Stroke, StrokeKind};
use voxlab::editor::{self, WidgetKind};
use voxlab::jobs::view::{joint_histogram, ViewState};
use voxlab::transfer::{Interpolation, TransferFunction, PRESETS};
use voxlab::transfer2d::{GradientAxis, Shape, TransferFunction2D, PRESETS_2D};
use voxlab::AnyVolume;

/// What the editors edit and draw over.
pub struct Context<'a> {
    pub state: &'a mut ViewState,
    /// Log heights of the raw-value histogram over `histogram_range`.
    pub histogram: &'a [f64],
    pub histogram_range: [f64; 2],
    pub volume: &'a AnyVolume,
}

pub struct EditorState {
    selected: Option<usize>,
    selected_widget: Option<usize>,
    /// The selected widget's handle being dragged.
    handle: Option<editor::Handle>,
    /// The opacity at the 1-D editor's top edge.
    alpha_top: f64,
    tf_path: String,
    tf2d_path: String,
    /// The 2-D histogram's texture and the axes it was counted on.
    joint: Option<(String, egui::TextureHandle)>,
    /// A sensible `g_max` for a new 2-D function.
    gradient_max: f64,
    /// Where the 1-D and 2-D editors were drawn last (for the pointer tests).
    rects: [Option<Rect>; 2],
}

const PICK_PX: f64 = 8.0;

impl EditorState {
    pub fn new(volume: &AnyVolume, state: &ViewState) -> Self {
        let r = volume.value_range();
        let s = volume.spacing();
        let h = s.iter().copied().fold(f64::INFINITY, f64::min).max(1e-9);
        let top = (1.25 * state.transfer.alpha_max()).clamp(0.01, 1.0);
        EditorState {
            selected: None,
            selected_widget: None,
            handle: None,
            alpha_top: top,
            tf_path: "transfer.json".into(),
            tf2d_path: "transfer-2d.json".into(),
            joint: None,
            gradient_max: ((r.max - r.min) / h * 0.5).max(1e-9),
            rects: [None; 2],
        }
    }

    /// Where the 1-D and the 2-D editors were drawn in the last frame.
    #[cfg(test)]
    pub fn rects(&self) -> [Option<Rect>; 2] {
        self.rects
    }

    /// The opacity at the 1-D editor's top edge.
    #[cfg(test)]
    pub fn alpha_top(&self) -> f64 {
        self.alpha_top
    }

    /// The selected point of the 1-D editor and widget of the 2-D editor.
    #[cfg(test)]
    pub fn selection(&self) -> (Option<usize>, Option<usize>) {
        (self.selected, self.selected_widget)
    }

    /// Shows both editors; returns whether the view changed.
    pub fn show(&mut self, ui: &mut egui::Ui, c: Context, message: &mut String) -> bool {
        let before = (
            c.state.transfer.clone(),
            c.state.settings.transfer_2d.clone(),
        );
        ui.heading("Transfer function");
        self.presets(ui, c.state);
        self.editor_1d(ui, c.histogram, c.histogram_range, c.state);
        self.files(ui, c.state, message);
        ui.separator();
        let mut two = c.state.settings.transfer_2d.is_some();
        if ui
            .checkbox(&mut two, "2-D transfer function (value × gradient)")
            .changed()
        {
            c.state.settings.transfer_2d =
                two.then(|| TransferFunction2D::from_1d(&c.state.transfer, 256, self.gradient_max));
            self.selected_widget = None;
        }
        if c.state.settings.transfer_2d.is_some() {
            self.editor_2d(ui, c.state, c.volume, message);
        }
        let after = (
            c.state.transfer.clone(),
            c.state.settings.transfer_2d.clone(),
        );
        before != after
    }

    fn presets(&mut self, ui: &mut egui::Ui, state: &mut ViewState) {
        egui::ComboBox::from_label("preset")
            .selected_text(state.transfer.name.clone())
            .show_ui(ui, |ui| {
                for (name, _) in PRESETS {
                    if ui.selectable_label(false, *name).clicked() {
                        if let Ok(t) = TransferFunction::preset(name) {
                            state.transfer = t;
                            state.settings.transfer_2d = None;
                            self.selected = None;
                            self.alpha_top = (1.25 * state.transfer.alpha_max()).clamp(0.01, 1.0);
                        }
                    }
                }
                for (name, _) in PRESETS_2D {
                    if ui.selectable_label(false, *name).clicked() {
                        if let Ok(t) = TransferFunction2D::preset(name) {
                            state.settings.transfer_2d = Some(t);
                            self.selected_widget = None;
                        }
                    }
                }
            });
    }

    fn editor_1d(
        &mut self,
        ui: &mut egui::Ui,
        histogram: &[f64],
        range: [f64; 2],
        state: &mut ViewState,
    ) {
        let tf = &mut state.transfer;
        let (response, painter) =
            ui.allocate_painter(egui::vec2(380.0, 170.0), Sense::click_and_drag());
        let rect = response.rect;
        self.rects[0] = Some(rect);
        let [d0, d1] = tf.domain;
        let top = self.alpha_top;
        let to_screen = |u: f64, a: f64| {
            Pos2::new(
                rect.left() + ((u - d0) / (d1 - d0)) as f32 * rect.width(),
                rect.bottom() - (a / top) as f32 * (rect.height() - 14.0) - 14.0,
            )
        };
        let from_screen = |p: Pos2| {
            let u = d0 + (p.x - rect.left()) as f64 / rect.width() as f64 * (d1 - d0);
            let a = (rect.bottom() - 14.0 - p.y) as f64 / (rect.height() - 14.0) as f64 * top;
            (u, a)
        };
        painter.rect_filled(rect, 2.0, Color32::from_gray(24));
        // The histogram, in mapped values: bin centre t goes to Ψ(t).
        let n = histogram.len().max(1);
        for (b, h) in histogram.iter().enumerate() {
            let t = range[0] + (b as f64 + 0.5) / n as f64 * (range[1] - range[0]);
            let x = to_screen(tf.window.apply(t), 0.0).x;
            if x >= rect.left() && x <= rect.right() {
                let y0 = rect.bottom() - 14.0;
                let y1 = y0 - *h as f32 * (rect.height() - 14.0);
                painter.line_segment(
                    [Pos2::new(x, y0), Pos2::new(x, y1)],
                    Stroke::new(1.5, Color32::from_gray(70)),
                );
            }
        }
        // The colour strip and the opacity curve.
        let steps = 190;
        let mut curve = Vec::with_capacity(steps + 1);
        for i in 0..=steps {
            let u = d0 + i as f64 / steps as f64 * (d1 - d0);
            let c = tf.eval(u);
            curve.push(to_screen(u, c[3].min(top)));
            let x0 = rect.left() + i as f32 / (steps + 1) as f32 * rect.width();
            let x1 = rect.left() + (i + 1) as f32 / (steps + 1) as f32 * rect.width();
            painter.rect_filled(
                Rect::from_min_max(
                    Pos2::new(x0, rect.bottom() - 12.0),
                    Pos2::new(x1 + 0.5, rect.bottom()),
                ),
                0.0,
                rgb(c),
            );
        }
        painter.add(egui::Shape::line(curve, Stroke::new(1.5, Color32::WHITE)));
        for (i, p) in tf.points.iter().enumerate() {
            let at = to_screen(p.value, p.rgba[3].min(top));
            painter.circle_filled(at, 5.0, rgb(p.rgba));
            let outline = if self.selected == Some(i) {
                Color32::YELLOW
            } else {
                Color32::GRAY
            };
            painter.circle_stroke(at, 5.0, Stroke::new(1.5, outline));
        }
        let radius = PICK_PX / rect.width().min(rect.height()) as f64;
        let pick = |tf: &TransferFunction, p: Pos2| {
            let (u, a) = from_screen(p);
            editor::nearest_point(tf, u, a, top, radius)
        };
        if let Some(p) = response.interact_pointer_pos() {
            if response.drag_started_by(egui::PointerButton::Primary) || response.clicked() {
                self.selected = pick(tf, p).or_else(|| {
                    let (u, a) = from_screen(p);
                    Some(editor::add_point(tf, u, a))
                });
            } else if response.dragged_by(egui::PointerButton::Primary) {
                if let Some(i) = self.selected {
                    let (u, a) = from_screen(p);
                    let _ = editor::move_point(tf, i, u, a);
                }
            }
            if response.secondary_clicked() {
                if let Some(i) = pick(tf, p) {
                    if editor::delete_point(tf, i).is_ok() {
                        self.selected = None;
                    }
                }
            }
        }
        ui.horizontal(|ui| {
            ui.add(
                egui::Slider::new(&mut self.alpha_top, 0.005..=1.0)
                    .logarithmic(true)
                    .text("opacity axis"),
            );
        });
        if let Some(i) = self.selected.filter(|&i| i < tf.points.len()) {
            ui.horizontal(|ui| {
                let p = tf.points[i];
                let mut c = [p.rgba[0] as f32, p.rgba[1] as f32, p.rgba[2] as f32];
                ui.label(format!("point {i}"));
                if ui.color_edit_button_rgb(&mut c).changed() {
                    let _ = editor::set_colour(tf, i, c.map(f64::from));
                }
                let (mut v, mut a) = (p.value, p.rgba[3]);
                let dv = ui.add(
                    egui::DragValue::new(&mut v)
                        .speed((d1 - d0) / 500.0)
                        .prefix("value "),
                );
                let da = ui.add(
                    egui::DragValue::new(&mut a)
                        .speed(0.001)
                        .range(0.0..=1.0)
                        .prefix("α "),
                );
                if dv.changed() || da.changed() {
                    let _ = editor::move_point(tf, i, v, a);
                }
                if ui.button("delete").clicked() && editor::delete_point(tf, i).is_ok() {
                    self.selected = None;
                }
            });
        }
        ui.horizontal(|ui| {
            let (mut w, mut l) = editor::window_level(tf);
            let speed = (w.abs() / 200.0).max(1e-6);
            let a = ui.add(egui::DragValue::new(&mut w).speed(speed).prefix("window "));
            let b = ui.add(egui::DragValue::new(&mut l).speed(speed).prefix("level "));
            if (a.changed() || b.changed()) && w > 0.0 {
                let _ = editor::set_window_level(tf, w, l);
            }
            if ui.button("reset").clicked() {
                tf.window = Default::default();
            }
        });
        let mut bezier = tf.interpolation == Interpolation::Bezier;
        if ui.checkbox(&mut bezier, "Bézier between points").changed() {
            tf.interpolation = if bezier {
                Interpolation::Bezier
            } else {
                Interpolation::Linear
            };
        }
    }

    fn files(&mut self, ui: &mut egui::Ui, state: &mut ViewState, message: &mut String) {
        let tf = &state.transfer;
        let loaded = file_row(
            ui,
            &mut self.tf_path,
            "--tf",
            |p| tf.save(p),
            TransferFunction::load,
            message,
        );
        if let Some(t) = loaded {
            state.transfer = t;
            self.selected = None;
        }
    }

    fn editor_2d(
        &mut self,
        ui: &mut egui::Ui,
        state: &mut ViewState,
        volume: &AnyVolume,
        message: &mut String,
    ) {
        let Some(tf) = state.settings.transfer_2d.as_mut() else {
            return;
        };
        ui.horizontal(|ui| {
            let speed = tf.gradient_max / 200.0;
            ui.add(
                egui::DragValue::new(&mut tf.gradient_max)
                    .speed(speed)
                    .range(1e-9..=f64::MAX)
                    .prefix("g max "),
            );
            let mut log = tf.gradient_axis == GradientAxis::Log;
            if ui.checkbox(&mut log, "log axis").changed() {
                tf.gradient_axis = if log {
                    GradientAxis::Log
                } else {
                    GradientAxis::Linear
                };
            }
        });
        let key = format!(
            "{:?}{:?}{}{:?}{:?}",
            tf.domain, tf.window, tf.gradient_max, tf.gradient_axis, tf.gradient_g0
        );
        if self.joint.as_ref().is_none_or(|(k, _)| *k != key) {
            match joint_histogram(volume, tf, [256, 128]) {
                Ok(h) => {
                    let mut counts = vec![0u64; h.counts.len()];
                    // Row 0 of the image is the largest gradient (the top).
                    let [nv, ng] = h.bins;
                    for r in 0..ng {
                        counts[(ng - 1 - r) * nv..(ng - r) * nv]
                            .copy_from_slice(&h.counts[r * nv..(r + 1) * nv]);
                    }
                    let heights = voxlab::volume::log_heights(&counts);
                    let px: Vec<u8> = heights
                        .iter()
                        .flat_map(|&x| {
                            let g = (x * 200.0) as u8;
                            [g, g, g, 255]
                        })
                        .collect();
                    let image = egui::ColorImage::from_rgba_unmultiplied([nv, ng], &px);
                    let t = ui
                        .ctx()
                        .load_texture("joint", image, egui::TextureOptions::LINEAR);
                    self.joint = Some((key, t));
                }
                Err(e) => *message = e.to_string(),
            }
        }
        let (response, painter) =
            ui.allocate_painter(egui::vec2(380.0, 200.0), Sense::click_and_drag());
        let rect = response.rect;
        self.rects[1] = Some(rect);
        if let Some((_, t)) = &self.joint {
            painter.image(
                t.id(),
                rect,
                Rect::from_min_max(Pos2::ZERO, Pos2::new(1.0, 1.0)),
                Color32::WHITE,
            );
        }
        let c = tf.coordinates();
        let [d0, d1] = tf.domain;
        let axis = |g: f64| {
            let y = if c.log {
                (g * c.g0_inv).ln_1p() * c.g_scale
            } else {
                g * c.g_scale
            };
            y / (c.size[1] - 1).max(1) as f64
        };
        let to_screen = |u: f64, g: f64| {
            Pos2::new(
                rect.left() + ((u - d0) / (d1 - d0)) as f32 * rect.width(),
                rect.bottom() - axis(g.max(0.0)) as f32 * rect.height(),
            )
        };
        let from_screen = |p: Pos2, tf: &TransferFunction2D| {
            let u = d0 + (p.x - rect.left()) as f64 / rect.width() as f64 * (d1 - d0);
            let y = ((rect.bottom() - p.y) / rect.height()) as f64;
            (u, tf.gradient_at_axis(y.clamp(0.0, 1.0)))
        };
        for (i, w) in tf.widgets.iter().enumerate() {
            let colour = if self.selected_widget == Some(i) {
                Color32::YELLOW
            } else {
                rgb(w.rgba)
            };
            let stroke = Stroke::new(1.5, colour);
            match &w.shape {
                Shape::Rectangle { value, gradient } => {
                    let r = Rect::from_two_pos(
                        to_screen(value[0], gradient[0]),
                        to_screen(value[1], gradient[1]),
                    );
                    painter.rect_stroke(r, 0.0, stroke, StrokeKind::Middle);
                }
                Shape::Ellipse { center, radii } => {
                    let pts = (0..48)
                        .map(|k| {
                            let t = k as f64 / 48.0 * std::f64::consts::TAU;
                            to_screen(
                                center[0] + radii[0] * t.cos(),
                                center[1] + radii[1] * t.sin(),
                            )
                        })
                        .collect();
                    painter.add(egui::Shape::closed_line(pts, stroke));
                }
                Shape::Triangle {
                    apex,
                    half_width,
                    gradient,
                } => {
                    let pts = vec![
                        to_screen(*apex, gradient[0]),
                        to_screen(apex + half_width, gradient[1]),
                        to_screen(apex - half_width, gradient[1]),
                    ];
                    painter.add(egui::Shape::closed_line(pts, stroke));
                }
                Shape::Profile {
                    points, gradient, ..
                } => {
                    let g = gradient.unwrap_or([0.0, tf.gradient_max]);
                    let r = Rect::from_two_pos(
                        to_screen(points[0].value, g[0]),
                        to_screen(points[points.len() - 1].value, g[1]),
                    );
                    painter.rect_stroke(r, 0.0, stroke, StrokeKind::Middle);
                }
            }
        }
        // The selected widget's handles: drag one to resize the widget, the opposite
        // side staying where it is.
        let selected = self.selected_widget.filter(|&i| i < tf.widgets.len());
        let handles: Vec<(editor::Handle, Pos2)> = selected
            .map(|i| editor::widget_handles(&tf.widgets[i]))
            .unwrap_or_default()
            .into_iter()
            .map(|(h, [u, g])| (h, to_screen(u, g)))
            .collect();
        for (h, at) in &handles {
            let colour = if self.handle == Some(*h) {
                Color32::WHITE
            } else {
                Color32::YELLOW
            };
            painter.rect_filled(
                Rect::from_center_size(*at, egui::vec2(7.0, 7.0)),
                1.0,
                colour,
            );
        }
        if let Some(p) = response.interact_pointer_pos() {
            if response.drag_started_by(egui::PointerButton::Primary) || response.clicked() {
                self.handle = handles
                    .iter()
                    .find(|(_, at)| at.distance(p) <= PICK_PX as f32)
                    .map(|(h, _)| *h);
                if self.handle.is_none() {
                    let (u, g) = from_screen(p, tf);
                    self.selected_widget = editor::widget_at(tf, u, g);
                }
            } else if response.dragged_by(egui::PointerButton::Primary) {
                if let Some(i) = self.selected_widget {
                    let (u1, g1) = from_screen(p, tf);
                    match self.handle {
                        Some(h) => {
                            let _ = editor::drag_handle(tf, i, h, [u1, g1]);
                        }
                        None => {
                            let (u0, g0) = from_screen(p - response.drag_delta(), tf);
                            let _ = editor::move_widget(tf, i, [u1 - u0, g1 - g0]);
                        }
                    }
                }
            }
        }
        if response.drag_stopped() {
            self.handle = None;
        }
        ui.horizontal(|ui| {
            let mid = [0.5 * (d0 + d1), 0.3 * tf.gradient_max];
            let half = [0.1 * (d1 - d0), 0.2 * tf.gradient_max];
            for (label, kind) in [
                ("+ rectangle", WidgetKind::Rectangle),
                ("+ ellipse", WidgetKind::Ellipse),
                ("+ triangle", WidgetKind::Triangle),
            ] {
                if ui.button(label).clicked() {
                    match editor::add_widget(tf, kind, mid, half, [1.0, 0.9, 0.7, 0.2]) {
                        Ok(i) => self.selected_widget = Some(i),
                        Err(e) => *message = e.to_string(),
                    }
                }
            }
        });
        if let Some(i) = self.selected_widget.filter(|&i| i < tf.widgets.len()) {
            let (_, [mut hv, mut hg]) = editor::widget_box(&tf.widgets[i]);
            ui.horizontal(|ui| {
                let w = &mut tf.widgets[i];
                let mut c = w.rgba.map(|x| x as f32);
                if ui.color_edit_button_rgba_unmultiplied(&mut c).changed() {
                    w.rgba = c.map(f64::from);
                }
                ui.add(egui::Slider::new(&mut w.border, 0.0..=1.0).text("border"));
            });
            ui.horizontal(|ui| {
                let a = ui.add(
                    egui::DragValue::new(&mut hv)
                        .speed((d1 - d0) / 500.0)
                        .prefix("half value "),
                );
                let b = ui.add(
                    egui::DragValue::new(&mut hg)
                        .speed(tf.gradient_max / 500.0)
                        .prefix("half gradient "),
                );
                if a.changed() || b.changed() {
                    let _ = editor::resize_widget(tf, i, [hv, hg]);
                }
                if ui.button("delete").clicked() && editor::delete_widget(tf, i).is_ok() {
                    self.selected_widget = None;
                    self.handle = None;
                }
            });
        }
        let current = tf.clone();
        let loaded = file_row(
            ui,
            &mut self.tf2d_path,
            "--tf2d",
            |p| current.save(p),
            TransferFunction2D::load,
            message,
        );
        if let Some(t) = loaded {
            *tf = t;
            self.selected_widget = None;
        }
    }
}

/// A path field with save and load buttons: what was loaded, if anything; what
/// happened goes to `message` (`flag` is the `voxlab render` option that reads the file).
fn file_row<T>(
    ui: &mut egui::Ui,
    path: &mut String,
    flag: &str,
    save: impl FnOnce(&std::path::Path) -> voxlab::Result<()>,
    load: impl FnOnce(&std::path::Path) -> voxlab::Result<T>,
    message: &mut String,
) -> Option<T> {
    ui.horizontal(|ui| {
        let label = ui.label("file");
        ui.add(egui::TextEdit::singleline(path).desired_width(160.0))
            .labelled_by(label.id);
        let p = std::path::Path::new(path.as_str());
        if ui.button("save").clicked() {
            *message = match save(p) {
                Ok(()) => format!("wrote {} (voxlab render {flag} reads it)", p.display()),
                Err(e) => e.to_string(),
            };
        }
        if ui.button("load").clicked() {
            match load(p) {
                Ok(t) => return Some(t),
                Err(e) => *message = e.to_string(),
            }
        }
        None
    })
    .inner
}

fn rgb(c: [f64; 4]) -> Color32 {
    let q = |x: f64| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
    Color32::from_rgb(q(c[0]), q(c[1]), q(c[2]))
}
