//! The window: egui on wgpu, presenting on the ray caster's own device. A thin
//! shell: the view it shows is a [`ViewState`], every frame is the render job's
//! (a [`PreparedScene`] of the volume through [`Renderer::render_prepared_with`]: on the
//! GPU the volume is uploaded once, and interaction re-makes only what it changed),
//! the editors call [`voxlab::editor`], the difference view
//! [`voxlab::metrics`]. Nothing here computes an image.

use super::editors;
use super::worker::{self, Worker};
use super::Options;
use eframe::egui;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;
use voxlab::camera::AxisView;
use voxlab::choice::Choice;
use voxlab::frame::Frame;
use voxlab::gpu::context::GpuContext;
use voxlab::io::frame::rgba8;
use voxlab::jobs::render::{PreparedScene, Renderer, Scene};
use voxlab::jobs::view::{ViewProjection, ViewState};
use voxlab::jobs::Backend;
use voxlab::metrics::{diff_heatmap, error_stats, ErrorStats};
use voxlab::settings::{Classification, ClipBox, ClipSpace, Filter, Mode};
use voxlab::{AnyVolume, Error, Result};

/// Opens the window and runs until it closes (or `--frames` frames were drawn).
pub fn run(options: Options) -> Result<()> {
    let mut native = eframe::NativeOptions::default();
    let (w, h) = (options.state.width as f32, options.state.height as f32);
    native.viewport = egui::ViewportBuilder::default()
        .with_title("voxlab view")
        .with_inner_size([(w + 720.0).max(1100.0), (h + 90.0).max(760.0)]);
    native.renderer = eframe::Renderer::Wgpu;
    let renderer = Renderer::new(options.backend)?;
    if let Some(ctx) = renderer.gpu() {
        // The window presents on the device the ray caster renders on.
        native.wgpu_options.wgpu_setup = eframe::egui_wgpu::WgpuSetupExisting {
            instance: GpuContext::instance().clone(),
            adapter: ctx.adapter.clone(),
            device: ctx.device.clone(),
            queue: ctx.queue.clone(),
        }
        .into();
    }
    let failure = Arc::new(Mutex::new(None));
    let failure_slot = failure.clone();
    let result = eframe::run_native(
        "voxlab view",
        native,
        Box::new(move |_cc| {
            let lab = Lab::new(options, renderer, failure_slot)?;
            Ok(Box::new(lab))
        }),
    );
    if let Some(e) = failure.lock().expect("not poisoned").take() {
        return Err(e);
    }
    result.map_err(|e| {
        Error::invalid(
            "window",
            format!(
                "cannot open a window: {e}; on a machine without a display, run the lab \
                 under a virtual X server: xvfb-run -a voxlab view …"
            ),
        )
    })
}

/// What the central panel shows.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Show {
    Interactive,
    Reference,
    Difference,
}

struct Lab {
    state: ViewState,
    volume: AnyVolume,
    renderer: Renderer,
    /// `volume` prepared for the interactive frames (on the GPU: uploaded once, with
    /// the pipelines and set-up volumes cached), made on the first frame.
    prepared: Option<PreparedScene>,
    /// The interactive backend's last frame, with its generation.
    frame: Option<(u64, Frame)>,
    texture: Option<egui::TextureHandle>,
    generation: u64,
    rendered: u64,
    frame_ms: f64,
    samples_per_ray: f64,
    frames_drawn: u64,
    worker: Worker,
    reference_backend: Backend,
    reference: Option<worker::Done>,
    reference_texture: Option<egui::TextureHandle>,
    diff: Option<(u64, ErrorStats, egui::TextureHandle)>,
    within: Option<bool>,
    show: Show,
    histogram: Vec<f64>,
    histogram_range: [f64; 2],
    editors: editors::EditorState,
    message: String,
    help: bool,
    save_state: Option<PathBuf>,
    screenshot: Option<PathBuf>,
    frames: Option<u64>,
    window_screenshot: Option<PathBuf>,
    /// The window's pixels, once asked for (`--window-screenshot`).
    window_pixels: Option<Arc<Mutex<Option<Arc<egui::ColorImage>>>>>,
    /// Where `--frames`' final writes report a failure to [`run`].
    failure_slot: Arc<Mutex<Option<Error>>>,
}

impl Lab {
    fn new(
        o: Options,
        renderer: Renderer,
        failure_slot: Arc<Mutex<Option<Error>>>,
    ) -> Result<Self> {
        let h = o.volume.histogram(256);
        let histogram_range = [h.min, h.max];
        Ok(Lab {
            histogram: voxlab::volume::log_heights(&h.counts),
            histogram_range,
            editors: editors::EditorState::new(&o.volume, &o.state),
            state: o.state,
            volume: o.volume,
            renderer,
            prepared: None,
            frame: None,
            texture: None,
            generation: 1,
            rendered: 0,
            frame_ms: 0.0,
            samples_per_ray: 0.0,
            frames_drawn: 0,
            worker: Worker::start(),
            reference_backend: Backend::Cpu,
            reference: None,
            reference_texture: None,
            diff: None,
            within: None,
            show: if o.compare {
                Show::Difference
            } else {
                Show::Interactive
            },
            message: String::new(),
            help: false,
            save_state: o.save_state,
            screenshot: o.screenshot,
            frames: o.frames,
            window_screenshot: o.window_screenshot,
            window_pixels: None,
            failure_slot,
        })
    }

    /// Marks the view changed: the next frame renders again, the reference restarts.
    fn changed(&mut self) {
        self.generation += 1;
    }

    fn scene(&self) -> Result<(Scene, voxlab::settings::RenderSettings)> {
        let (mut scene, mut settings) = self.state.scene(self.volume.clone())?;
        settings.sample_count = true;
        scene.transfer = self.state.transfer.clone();
        Ok((scene, settings))
    }

    /// The interactive frame of the current view, from the prepared volume (prepared
    /// again only when the settings need it: on the CPU backends, another filter or
    /// gradient method; on the GPU the session serves every setting).
    fn render_frame(&mut self) -> Result<voxlab::jobs::render::Rendered> {
        self.state.validate()?;
        let camera = self.state.camera()?;
        let mut settings = self.state.settings.clone();
        settings.sample_count = true;
        let tf = &self.state.transfer;
        let prepared = match self.prepared.take() {
            Some(p) if p.serves(&settings) => p,
            _ => self.renderer.prepare_volume(&self.volume, tf, &settings)?,
        };
        let out = self
            .renderer
            .render_prepared_with(&prepared, tf, &camera, &settings, &|_, _| {});
        self.prepared = Some(prepared);
        out
    }

    /// Renders the interactive frame when the view changed.
    fn render(&mut self, ctx: &egui::Context) {
        if self.rendered == self.generation {
            return;
        }
        self.rendered = self.generation;
        let t = Instant::now();
        let result = self
            .render_frame()
            .map(|out| (out, t.elapsed().as_secs_f64()));
        match result {
            Ok((out, seconds)) => {
                self.frame_ms = seconds * 1e3;
                let px = (out.output.image.width * out.output.image.height).max(1);
                self.samples_per_ray = out.output.total_samples as f64 / px as f64;
                let image = to_color_image(&out.output.image);
                match &mut self.texture {
                    Some(t) => t.set(image, egui::TextureOptions::NEAREST),
                    None => {
                        self.texture =
                            Some(ctx.load_texture("view", image, egui::TextureOptions::NEAREST))
                    }
                }
                self.frame = Some((self.generation, out.output.image));
                self.message.clear();
            }
            Err(e) => self.message = format!("render: {e}"),
        }
        if self.show != Show::Interactive {
            self.request_reference(ctx);
        }
    }

    /// Starts the reference render of the current view (coarse, then full), cancelling
    /// the one in flight.
    fn request_reference(&mut self, ctx: &egui::Context) {
        if self
            .reference
            .as_ref()
            .is_some_and(|r| r.generation == self.generation && r.full)
            || self
                .worker
                .busy_with(self.generation, self.reference_backend)
        {
            return;
        }
        match self.scene() {
            Ok((scene, settings)) => self.worker.request(worker::Job {
                generation: self.generation,
                backend: self.reference_backend,
                scene,
                settings,
                view: self.state.view,
                size: [self.state.width, self.state.height],
                repaint: ctx.clone(),
            }),
            Err(e) => self.message = format!("reference: {e}"),
        }
    }

    /// Takes finished reference renders and updates the difference.
    fn collect_reference(&mut self, ctx: &egui::Context) {
        while let Some(done) = self.worker.poll() {
            match done.result {
                Ok(ref frame) => {
                    let image = to_color_image(frame);
                    match &mut self.reference_texture {
                        Some(t) => t.set(image, egui::TextureOptions::NEAREST),
                        None => {
                            self.reference_texture = Some(ctx.load_texture(
                                "reference",
                                image,
                                egui::TextureOptions::NEAREST,
                            ))
                        }
                    }
                }
                Err(Error::Cancelled) => continue,
                Err(ref e) => self.message = format!("reference: {e}"),
            }
            self.reference = Some(done);
        }
        let (Some((g, port)), Some(r)) = (&self.frame, &self.reference) else {
            return;
        };
        let Ok(oracle) = &r.result else { return };
        if !(r.full && r.generation == *g && self.diff.as_ref().is_none_or(|d| d.0 != *g)) {
            return;
        }
        if oracle.data.len() != port.data.len() {
            return;
        }
        let stats = error_stats(&oracle.data, &port.data, f64::INFINITY);
        let heat = diff_heatmap(oracle, port, None);
        let texture =
            ctx.load_texture("diff", to_color_image(&heat), egui::TextureOptions::NEAREST);
        let (_, gpu_tol) = voxlab::bench::raycast::raycast_tolerances(&self.state.settings);
        let (f32_tol, _) = voxlab::bench::raycast::raycast_tolerances(&self.state.settings);
        let tol = match (self.renderer.backend(), r.backend) {
            (Backend::Gpu, _) => Some(gpu_tol),
            (Backend::CpuF32, Backend::Cpu) | (Backend::Cpu, Backend::CpuF32) => Some(f32_tol),
            _ => None,
        };
        self.within = tol.map(|t| t.admits(&stats));
        self.diff = Some((*g, stats, texture));
    }

    fn save_state(&mut self) {
        let path = self
            .save_state
            .clone()
            .unwrap_or_else(|| PathBuf::from("voxlab-state.json"));
        self.message = match self.state.save(&path) {
            Ok(()) => format!("wrote {}", path.display()),
            Err(e) => format!("save state: {e}"),
        };
    }

    fn write_screenshot(&mut self) -> Result<()> {
        let path = self
            .screenshot
            .clone()
            .unwrap_or_else(|| PathBuf::from("voxlab-view.png"));
        let Some((_, frame)) = &self.frame else {
            return Err(Error::invalid("--screenshot", "no frame has been rendered"));
        };
        voxlab::io::write_frame(&path, frame, voxlab::io::PngOptions::default())?;
        self.message = format!("wrote {}", path.display());
        Ok(())
    }

    /// `--frames`: after the last frame (and, in the reference and difference views,
    /// once the reference is done), write what was asked for and close.
    fn finish(&mut self, ctx: &egui::Context) {
        let reference_done = self.show == Show::Interactive
            || self.diff.as_ref().is_some_and(|d| d.0 == self.generation)
            || self
                .reference
                .as_ref()
                .is_some_and(|r| r.generation == self.generation && r.full && r.result.is_err());
        if !reference_done {
            ctx.request_repaint_after(std::time::Duration::from_millis(50));
            return;
        }
        if let Some(path) = self.window_screenshot.clone() {
            match &self.window_pixels {
                None => {
                    let slot = Arc::new(Mutex::new(None));
                    let put = slot.clone();
                    let wake = ctx.clone();
                    ctx.request_screenshot(move |image| {
                        *put.lock().expect("not poisoned") = Some(image);
                        wake.request_repaint();
                    });
                    self.window_pixels = Some(slot);
                    ctx.request_repaint();
                    return;
                }
                Some(slot) => {
                    let Some(image) = slot.lock().expect("not poisoned").take() else {
                        ctx.request_repaint_after(std::time::Duration::from_millis(20));
                        return;
                    };
                    if let Err(e) = write_window(&path, &image) {
                        self.failure_slot
                            .lock()
                            .expect("not poisoned")
                            .get_or_insert(e);
                    }
                    self.window_screenshot = None;
                }
            }
        }
        let slot = self.failure_slot.clone();
        let fail = |e: Error| {
            slot.lock().expect("not poisoned").get_or_insert(e);
        };
        if self.frame.is_none() {
            fail(Error::invalid("view", self.message.clone()));
        }
        if self.screenshot.is_some() && self.frame.is_some() {
            if let Err(e) = self.write_screenshot() {
                fail(e);
            }
        }
        if let Some(p) = self.save_state.clone() {
            if let Err(e) = self.state.save(&p) {
                fail(e);
            }
        }
        self.frames = None;
        ctx.send_viewport_cmd(egui::ViewportCommand::Close);
    }

    fn keys(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        use egui::Key;
        let pressed = |k: Key| ctx.input(|i| i.key_pressed(k));
        let axes = [
            (Key::Num1, AxisView::PlusX),
            (Key::Num2, AxisView::MinusX),
            (Key::Num3, AxisView::PlusY),
            (Key::Num4, AxisView::MinusY),
            (Key::Num5, AxisView::PlusZ),
            (Key::Num6, AxisView::MinusZ),
        ];
        for (k, v) in axes {
            if pressed(k) {
                self.state.view.look_along(v);
                self.changed();
            }
        }
        if pressed(Key::O) {
            let ortho = matches!(
                self.state.view.projection,
                ViewProjection::Perspective { .. }
            );
            self.state.view.set_orthographic(ortho, 30.0);
            self.changed();
        }
        if pressed(Key::R) {
            self.reset_view();
        }
        if pressed(Key::D) {
            self.show = if self.show == Show::Difference {
                Show::Interactive
            } else {
                Show::Difference
            };
            self.changed();
        }
        if pressed(Key::Plus) || pressed(Key::Equals) {
            self.state.view.zoom_by(1.25);
            self.changed();
        }
        if pressed(Key::Minus) {
            self.state.view.zoom_by(0.8);
            self.changed();
        }
        if pressed(Key::S) {
            self.save_state();
        }
        if pressed(Key::P) {
            if let Err(e) = self.write_screenshot() {
                self.message = format!("screenshot: {e}");
            }
        }
        if pressed(Key::H) || pressed(Key::F1) || pressed(Key::Questionmark) {
            self.help = !self.help;
        }
        if pressed(Key::Escape) {
            self.help = false;
        }
        if pressed(Key::Q) {
            ctx.send_viewport_cmd(egui::ViewportCommand::Close);
        }
    }

    fn reset_view(&mut self) {
        let p = match self.state.view.projection {
            ViewProjection::Perspective { fov_y_deg } => ViewProjection::Perspective { fov_y_deg },
            o => o,
        };
        match voxlab::jobs::view::OrbitView::fit(
            &self.volume,
            p,
            self.state.width,
            self.state.height,
        ) {
            Ok(v) => {
                self.state.view = v;
                self.changed();
            }
            Err(e) => self.message = format!("reset: {e}"),
        }
    }

    /// The left panel: rendering settings.
    fn settings_panel(&mut self, ui: &mut egui::Ui) {
        let before = (
            self.state.settings.clone(),
            self.state.view,
            self.state.width,
            self.state.height,
        );
        ui.heading("View");
        ui.label(format!("input: {}", self.state.input.source));
        ui.label(format!("interactive: {}", self.renderer.describe()));
        let s = &mut self.state.settings;
        egui::ComboBox::from_label("mode")
            .selected_text(s.mode.name())
            .show_ui(ui, |ui| {
                for m in [
                    Mode::Dvr,
                    Mode::Mip,
                    Mode::Minip,
                    Mode::Xray,
                    Mode::Mida,
                    Mode::Iso,
                ] {
                    ui.selectable_value(&mut s.mode, m, m.name());
                }
            });
        egui::ComboBox::from_label("filter")
            .selected_text(s.filter.name())
            .show_ui(ui, |ui| {
                for f in Filter::CHOICES.iter().map(|c| c.value) {
                    ui.selectable_value(&mut s.filter, f, f.name());
                }
            });
        egui::ComboBox::from_label("classification")
            .selected_text(s.classification.name())
            .show_ui(ui, |ui| {
                for c in [Classification::Post, Classification::Pre] {
                    ui.selectable_value(&mut s.classification, c, c.name());
                }
            });
        ui.add(
            egui::Slider::new(&mut s.step, 0.05..=4.0)
                .logarithmic(true)
                .text("step (voxels)"),
        );
        ui.add(egui::Slider::new(&mut s.ert_threshold, 0.5..=1.0).text("early termination"));
        ui.checkbox(&mut s.shading.enabled, "Phong shading");
        ui.checkbox(&mut s.skip_empty, "empty-space skipping");
        if s.mode == Mode::Mida {
            ui.add(egui::Slider::new(&mut s.mida_gamma, -1.0..=1.0).text("MIDA γ"));
        }
        let range = self.volume.value_range();
        if matches!(s.mode, Mode::Mip | Mode::Minip) {
            let mut on = s.window.is_some();
            ui.checkbox(&mut on, "grey window (else the value range)");
            match (on, &mut s.window) {
                (true, None) => {
                    s.window = Some([range.max - range.min, 0.5 * (range.max + range.min)])
                }
                (false, Some(_)) => s.window = None,
                _ => {}
            }
            if let Some([w, c]) = &mut s.window {
                let speed = ((range.max - range.min) / 300.0).max(1e-9);
                ui.horizontal(|ui| {
                    ui.add(
                        egui::DragValue::new(w)
                            .speed(speed)
                            .range(1e-9..=f64::MAX)
                            .prefix("width "),
                    );
                    ui.add(egui::DragValue::new(c).speed(speed).prefix("centre "));
                });
            }
        }
        if matches!(s.mode, Mode::Iso | Mode::Dvr) {
            ui.label("iso-surfaces (drawn by iso, and with DVR)");
            let mut remove = None;
            let speed = ((range.max - range.min) / 300.0).max(1e-9);
            for (k, iso) in s.iso_surfaces.iter_mut().enumerate() {
                ui.horizontal(|ui| {
                    ui.add(
                        egui::DragValue::new(&mut iso.value)
                            .speed(speed)
                            .prefix("value "),
                    );
                    let mut c = iso.color.map(|x| x as f32);
                    if ui.color_edit_button_rgb(&mut c).changed() {
                        iso.color = c.map(f64::from);
                    }
                    ui.add(
                        egui::DragValue::new(&mut iso.opacity)
                            .speed(0.01)
                            .range(0.0..=1.0)
                            .prefix("α "),
                    );
                    if ui.small_button("×").clicked() {
                        remove = Some(k);
                    }
                });
            }
            if let Some(k) = remove {
                s.iso_surfaces.remove(k);
            }
            ui.horizontal(|ui| {
                if s.iso_surfaces.len() < voxlab::settings::MAX_ISO_SURFACES
                    && ui.button("+ iso-surface").clicked()
                {
                    s.iso_surfaces.push(voxlab::settings::IsoSurface {
                        value: 0.5 * (range.min + range.max),
                        color: [0.9, 0.8, 0.6],
                        opacity: 1.0,
                    });
                }
                ui.checkbox(&mut s.iso_opaque, "opaque");
                ui.checkbox(&mut s.iso_shadows, "shadows");
                ui.checkbox(&mut s.iso_refine, "refine");
            });
        }
        let mut clip = s.clip_box.is_some();
        ui.checkbox(&mut clip, "clip box (voxels)");
        let dims = self.volume.dims();
        if clip && s.clip_box.is_none() {
            s.clip_box = Some(ClipBox {
                lo: [0.0; 3],
                hi: dims.map(|n| n as f64 - 1.0),
                space: ClipSpace::Voxel,
            });
        } else if !clip {
            s.clip_box = None;
        }
        if let Some(b) = &mut s.clip_box {
            for (a, name) in ["x", "y", "z"].iter().enumerate() {
                let top = dims[a] as f64 - 1.0;
                ui.horizontal(|ui| {
                    ui.label(*name);
                    ui.add(
                        egui::DragValue::new(&mut b.lo[a])
                            .range(0.0..=top)
                            .speed(0.5),
                    );
                    ui.add(
                        egui::DragValue::new(&mut b.hi[a])
                            .range(0.0..=top)
                            .speed(0.5),
                    );
                });
                if b.hi[a] < b.lo[a] {
                    b.hi[a] = b.lo[a];
                }
            }
        }
        ui.separator();
        ui.label("camera (drag: orbit, right-drag or shift-drag: pan, wheel: zoom)");
        let mut ortho = matches!(
            self.state.view.projection,
            ViewProjection::Orthographic { .. }
        );
        if ui.checkbox(&mut ortho, "orthographic").changed() {
            self.state.view.set_orthographic(ortho, 30.0);
        }
        if let ViewProjection::Perspective { fov_y_deg } = &mut self.state.view.projection {
            ui.add(egui::Slider::new(fov_y_deg, 5.0..=120.0).text("field of view °"));
        }
        ui.horizontal_wrapped(|ui| {
            for (label, v) in [
                ("+x", AxisView::PlusX),
                ("−x", AxisView::MinusX),
                ("+y", AxisView::PlusY),
                ("−y", AxisView::MinusY),
                ("+z", AxisView::PlusZ),
                ("−z", AxisView::MinusZ),
            ] {
                if ui.button(label).clicked() {
                    self.state.view.look_along(v);
                }
            }
        });
        if ui.button("reset view (R)").clicked() {
            self.reset_view();
        }
        ui.horizontal(|ui| {
            ui.label("image");
            ui.add(egui::DragValue::new(&mut self.state.width).range(16..=4096));
            ui.label("×");
            ui.add(egui::DragValue::new(&mut self.state.height).range(16..=4096));
        });
        ui.separator();
        ui.label("compare with");
        egui::ComboBox::from_id_salt("reference")
            .selected_text(self.reference_backend.name())
            .show_ui(ui, |ui| {
                for b in [Backend::Cpu, Backend::CpuF32] {
                    ui.selectable_value(&mut self.reference_backend, b, b.name());
                }
            });
        ui.horizontal(|ui| {
            ui.selectable_value(&mut self.show, Show::Interactive, "interactive");
            ui.selectable_value(&mut self.show, Show::Reference, "reference");
            ui.selectable_value(&mut self.show, Show::Difference, "difference (D)");
        });
        ui.separator();
        ui.horizontal(|ui| {
            if ui.button("save state (S)").clicked() {
                self.save_state();
            }
            if ui.button("screenshot (P)").clicked() {
                if let Err(e) = self.write_screenshot() {
                    self.message = format!("screenshot: {e}");
                }
            }
            if ui.button("help (H)").clicked() {
                self.help = !self.help;
            }
        });
        let after = (
            self.state.settings.clone(),
            self.state.view,
            self.state.width,
            self.state.height,
        );
        if after != before {
            self.changed();
        }
    }

    /// The central panel: the 3-D view (or the reference, or the difference) and the
    /// numbers of the current frame.
    fn view_panel(&mut self, ui: &mut egui::Ui) {
        let size = egui::vec2(self.state.width as f32, self.state.height as f32);
        let texture = match self.show {
            Show::Interactive => self.texture.as_ref(),
            Show::Reference => self.reference_texture.as_ref(),
            Show::Difference => self.diff.as_ref().map(|d| &d.2),
        }
        .or(self.texture.as_ref());
        let response = match texture {
            // The heat map keeps its own size (the view and its colour scale below).
            Some(t) => ui.add(
                egui::Image::new((t.id(), egui::vec2(size.x, t.size_vec2().y)))
                    .sense(egui::Sense::click_and_drag()),
            ),
            None => ui.allocate_response(size, egui::Sense::click_and_drag()),
        };
        let shift = ui.input(|i| i.modifiers.shift);
        let d = response.drag_delta();
        if d != egui::Vec2::ZERO {
            if response.dragged_by(egui::PointerButton::Secondary)
                || response.dragged_by(egui::PointerButton::Middle)
                || shift
            {
                self.state
                    .view
                    .pan_by(d.x as f64, d.y as f64, self.state.height);
            } else {
                self.state.view.orbit_by(d.x as f64, d.y as f64);
            }
            self.changed();
        }
        if response.hovered() {
            let scroll = ui.input(|i| i.smooth_scroll_delta.y);
            if scroll != 0.0 {
                self.state.view.zoom_by((scroll as f64 / 200.0).exp());
                self.changed();
            }
        }
        ui.label(format!(
            "{}: {:.1} ms, {:.1} samples per ray, {}×{}",
            self.renderer.backend().name(),
            self.frame_ms,
            self.samples_per_ray,
            self.state.width,
            self.state.height
        ));
        if self.show != Show::Interactive {
            match &self.reference {
                Some(r) if r.generation == self.generation => ui.label(format!(
                    "{}: {} in {:.2} s",
                    r.backend.name(),
                    if r.full {
                        "full"
                    } else {
                        "coarse (refining…)"
                    },
                    r.seconds
                )),
                _ => ui.label(format!("{}: rendering…", self.reference_backend.name())),
            };
            if let Some((g, s, _)) = &self.diff {
                if *g == self.generation {
                    ui.label(format!(
                        "{} vs {}: max |Δ| {:.3e}, RMSE {:.3e}, PSNR {:.1} dB{}",
                        self.renderer.backend().name(),
                        self.reference_backend.name(),
                        s.max_abs,
                        s.rmse,
                        s.psnr_db,
                        match self.within {
                            Some(true) => ", within the port's tolerance",
                            Some(false) => ", OUTSIDE the port's tolerance",
                            None => "",
                        }
                    ));
                }
            }
        }
        if !self.message.is_empty() {
            ui.colored_label(egui::Color32::LIGHT_RED, &self.message);
        }
    }

    fn help_window(&mut self, ctx: &egui::Context) {
        let mut open = self.help;
        egui::Window::new("Keyboard")
            .open(&mut open)
            .collapsible(false)
            .show(ctx, |ui| {
                egui::Grid::new("keys").show(ui, |ui| {
                    for (k, what) in HELP {
                        ui.monospace(*k);
                        ui.label(*what);
                        ui.end_row();
                    }
                });
            });
        self.help = open;
    }
}

/// The shortcuts the help overlay lists.
pub const HELP: &[(&str, &str)] = &[
    ("drag", "orbit"),
    ("right-drag, shift-drag", "pan"),
    ("wheel, + / −", "zoom"),
    ("1 … 6", "look along +x, −x, +y, −y, +z, −z"),
    ("O", "orthographic ↔ perspective"),
    ("R", "reset the view"),
    ("D", "difference view on / off"),
    ("S", "save the state (--save-state, else voxlab-state.json)"),
    ("P", "screenshot (--screenshot, else voxlab-view.png)"),
    (
        "editor: click",
        "add a control point; drag: move; right-click: delete",
    ),
    ("H, F1, ?", "this help; Esc closes it"),
    ("Q", "quit"),
];

/// Writes the window's pixels as PNG.
fn write_window(path: &std::path::Path, image: &egui::ColorImage) -> Result<()> {
    let [w, h] = image.size;
    let mut frame = Frame::new(w, h, 4);
    for (i, p) in image.pixels.iter().enumerate() {
        let [r, g, b, a] = p.to_srgba_unmultiplied();
        frame.data[i * 4..i * 4 + 4].copy_from_slice(&[r, g, b, a].map(|c| f64::from(c) / 255.0));
    }
    voxlab::io::write_frame(path, &frame, voxlab::io::PngOptions::default())
}

fn to_color_image(frame: &Frame) -> egui::ColorImage {
    egui::ColorImage::from_rgba_unmultiplied([frame.width, frame.height], &rgba8(frame, None))
}

impl eframe::App for Lab {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        self.keys(&ctx);
        egui::Panel::left("settings")
            .resizable(false)
            .exact_size(300.0)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| self.settings_panel(ui));
            });
        egui::Panel::right("editors")
            .resizable(false)
            .exact_size(400.0)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| {
                    let edit = editors::Context {
                        state: &mut self.state,
                        histogram: &self.histogram,
                        histogram_range: self.histogram_range,
                        volume: &self.volume,
                    };
                    if self.editors.show(ui, edit, &mut self.message) {
                        self.generation += 1;
                    }
                });
            });
        self.render(&ctx);
        if self.show != Show::Interactive {
            self.request_reference(&ctx);
        }
        self.collect_reference(&ctx);
        egui::CentralPanel::default().show(ui, |ui| self.view_panel(ui));
        self.help_window(&ctx);
        self.frames_drawn += 1;
        if self.frames.is_some_and(|n| self.frames_drawn >= n) {
            self.finish(&ctx);
        }
        if self.frames.is_some() {
            // Scripted runs keep drawing until they are done.
            ctx.request_repaint();
        }
    }
}
