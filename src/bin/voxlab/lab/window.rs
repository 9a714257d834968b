//! The window: egui on wgpu, presenting on the ray caster's own device. A thin
//! shell: the view it shows is a [`ViewState`], every frame is the render job's,
//! rendered off the UI thread ([`worker::Frames`]: a prepared scene of the volume, on
//! the GPU a render session that uploads the volume once), the two sides of the
//! difference view are rendered off the UI thread too ([`worker::Worker`]), the editors
//! call [`voxlab::editor`], the difference view [`voxlab::metrics`]. Nothing here
//! computes an image.

use super::editors;
use super::worker::{self, Worker};
use super::Options;
use eframe::egui;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use voxlab::camera::AxisView;
use voxlab::choice::Choice;
use voxlab::frame::Frame;
use voxlab::gpu::context::GpuContext;
use voxlab::io::frame::rgba8;
use voxlab::jobs::render::{Renderer, Scene};
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
    /// One side of the difference view (0: A, 1: B).
    Side(usize),
    Difference,
}

/// One side of the difference view: a backend, and its frames of the current view.
struct Side {
    backend: Backend,
    worker: Worker,
    /// The side's last render (coarse or full).
    done: Option<worker::Done>,
    texture: Option<egui::TextureHandle>,
}

impl Side {
    fn new(backend: Backend) -> Self {
        Side {
            backend,
            worker: Worker::start(),
            done: None,
            texture: None,
        }
    }
}

struct Lab {
    state: ViewState,
    /// The volume, its voxels shared (clones are cheap: every render request takes one).
    volume: AnyVolume,
    renderer: Renderer,
    /// The interactive frames, rendered off the UI thread.
    frames_worker: worker::Frames,
    /// The interactive backend's last frame, with its generation.
    frame: Option<(u64, Frame)>,
    texture: Option<egui::TextureHandle>,
    generation: u64,
    /// The generation last asked of `frames_worker`.
    requested: u64,
    frame_ms: f64,
    samples_per_ray: f64,
    frames_drawn: u64,
    /// The difference view's sides A and B. A side on the interactive backend takes the
    /// interactive frame; another is rendered by its own worker.
    sides: [Side; 2],
    /// The difference A − B of the current view: its generation, statistics and heat map.
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
    /// Where the 3-D view was drawn in the last frame.
    view_rect: Option<egui::Rect>,
}

impl Lab {
    fn new(
        o: Options,
        renderer: Renderer,
        failure_slot: Arc<Mutex<Option<Error>>>,
    ) -> Result<Self> {
        let h = o.volume.histogram(256);
        let histogram_range = [h.min, h.max];
        let volume = o.volume.into_shared();
        let [a, b] = o.sides.unwrap_or([renderer.backend(), Backend::Cpu]);
        Ok(Lab {
            histogram: voxlab::volume::log_heights(&h.counts),
            histogram_range,
            editors: editors::EditorState::new(&volume, &o.state),
            state: o.state,
            frames_worker: worker::Frames::start(Renderer::on(renderer.engine()), volume.clone()),
            volume,
            renderer,
            frame: None,
            texture: None,
            generation: 1,
            requested: 0,
            frame_ms: 0.0,
            samples_per_ray: 0.0,
            frames_drawn: 0,
            sides: [Side::new(a), Side::new(b)],
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
            view_rect: None,
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

    /// Asks for the interactive frame of the current view when it changed (the frames'
    /// worker renders it off the UI thread; a newer view cancels it).
    fn render(&mut self, ctx: &egui::Context) {
        if self.requested == self.generation {
            return;
        }
        self.requested = self.generation;
        self.frames_worker.request(worker::FrameJob {
            generation: self.generation,
            state: self.state.clone(),
            repaint: ctx.clone(),
        });
    }

    /// Takes finished interactive frames.
    fn collect_frames(&mut self, ctx: &egui::Context) {
        while let Some(done) = self.frames_worker.poll() {
            match done.result {
                Ok(out) => {
                    self.frame_ms = done.seconds * 1e3;
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
                    self.frame = Some((done.generation, out.output.image));
                    if self.message.starts_with("render:") {
                        self.message.clear();
                    }
                }
                Err(Error::Cancelled) => {}
                Err(e) => self.message = format!("render: {e}"),
            }
        }
    }

    /// Whether side `i` of the difference view takes the interactive frame.
    fn side_is_interactive(&self, i: usize) -> bool {
        self.sides[i].backend == self.renderer.backend()
    }

    /// Starts the renders of the current view on the sides that are not the interactive
    /// frame (coarse, then full), cancelling those in flight.
    fn request_sides(&mut self, ctx: &egui::Context) {
        for i in 0..2 {
            if self.side_is_interactive(i) {
                continue;
            }
            let side = &self.sides[i];
            if side
                .done
                .as_ref()
                .is_some_and(|r| r.generation == self.generation && r.full)
                || side.worker.busy_with(self.generation, side.backend)
            {
                continue;
            }
            match self.scene() {
                Ok((scene, settings)) => {
                    let job = worker::Job {
                        generation: self.generation,
                        backend: self.sides[i].backend,
                        scene,
                        settings,
                        view: self.state.view,
                        size: [self.state.width, self.state.height],
                        repaint: ctx.clone(),
                    };
                    self.sides[i].worker.request(job);
                }
                Err(e) => self.message = format!("side {}: {e}", ["A", "B"][i]),
            }
        }
    }

    /// Side `i`'s full frame of the current view, once there is one.
    fn side_frame(&self, i: usize) -> Option<&Frame> {
        if self.side_is_interactive(i) {
            return self
                .frame
                .as_ref()
                .filter(|(g, _)| *g == self.generation)
                .map(|(_, f)| f);
        }
        match &self.sides[i].done {
            Some(d) if d.full && d.generation == self.generation => d.result.as_ref().ok(),
            _ => None,
        }
    }

    /// Takes the sides' finished renders and makes the difference A − B of the
    /// current view once both sides have their full frame.
    fn collect_sides(&mut self, ctx: &egui::Context) {
        for i in 0..2 {
            while let Some(done) = self.sides[i].worker.poll() {
                match done.result {
                    Ok(ref frame) => {
                        let image = to_color_image(frame);
                        let side = &mut self.sides[i];
                        match &mut side.texture {
                            Some(t) => t.set(image, egui::TextureOptions::NEAREST),
                            None => {
                                side.texture = Some(ctx.load_texture(
                                    ["side-a", "side-b"][i],
                                    image,
                                    egui::TextureOptions::NEAREST,
                                ))
                            }
                        }
                    }
                    Err(Error::Cancelled) => continue,
                    Err(ref e) => self.message = format!("side {}: {e}", ["A", "B"][i]),
                }
                self.sides[i].done = Some(done);
            }
        }
        if self.diff.as_ref().is_some_and(|d| d.0 == self.generation) {
            return;
        }
        let (Some(a), Some(b)) = (self.side_frame(0), self.side_frame(1)) else {
            return;
        };
        if a.data.len() != b.data.len() {
            return;
        }
        // B is the reference: the statistics are A's error against it.
        let stats = error_stats(&b.data, &a.data, f64::INFINITY);
        let heat = diff_heatmap(b, a, None);
        let texture =
            ctx.load_texture("diff", to_color_image(&heat), egui::TextureOptions::NEAREST);
        let (f32_tol, gpu_tol) = voxlab::bench::raycast::raycast_tolerances(&self.state.settings);
        let pair = (self.sides[0].backend, self.sides[1].backend);
        let tol = match pair {
            (Backend::Gpu, Backend::Cpu | Backend::CpuF32)
            | (Backend::Cpu | Backend::CpuF32, Backend::Gpu) => Some(gpu_tol),
            (Backend::CpuF32, Backend::Cpu) | (Backend::Cpu, Backend::CpuF32) => Some(f32_tol),
            _ => None,
        };
        self.within = tol.map(|t| t.admits(&stats));
        self.diff = Some((self.generation, stats, texture));
    }

    /// Whether the current view's difference is done (or cannot be made).
    fn difference_done(&self) -> bool {
        self.diff.as_ref().is_some_and(|d| d.0 == self.generation)
            || (0..2).any(|i| {
                self.sides[i]
                    .done
                    .as_ref()
                    .is_some_and(|r| r.generation == self.generation && r.full && r.result.is_err())
            })
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
        let frame_done = self
            .frame
            .as_ref()
            .is_some_and(|(g, _)| *g == self.generation)
            || self.message.starts_with("render:");
        let reference_done = self.show == Show::Interactive || self.difference_done();
        if !frame_done || !reference_done {
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
        // The GPU side only: the CPU oracle interpolates exactly, so the difference view
        // shows what the texture unit's weights cost.
        let served = s.filter.hardware_filterable();
        s.hardware_filtering &= served;
        ui.add_enabled(
            served,
            egui::Checkbox::new(&mut s.hardware_filtering, "texture-unit filtering (GPU)"),
        )
        .on_hover_text(
            "The GPU interpolates with the texture unit (trilinear, or the fast B-splines' \
             trilinear fetches): faster, and on real GPUs each weight is rounded to about \
             8 bits. The CPU side stays exact.",
        );
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
            ui.add(
                egui::DragValue::new(&mut self.state.width)
                    .range(16..=4096)
                    .prefix("w "),
            );
            ui.add(
                egui::DragValue::new(&mut self.state.height)
                    .range(16..=4096)
                    .prefix("h "),
            );
        });
        ui.separator();
        ui.label("difference view: A − B (B is the reference)");
        for (i, name) in ["A", "B"].into_iter().enumerate() {
            let interactive = self.renderer.backend();
            let before = self.sides[i].backend;
            egui::ComboBox::from_label(format!("side {name}"))
                .selected_text(side_label(before, interactive))
                .show_ui(ui, |ui| {
                    for b in [Backend::Gpu, Backend::CpuF32, Backend::Cpu] {
                        ui.selectable_value(
                            &mut self.sides[i].backend,
                            b,
                            side_label(b, interactive),
                        );
                    }
                });
            if self.sides[i].backend != before {
                self.sides[i].done = None;
                self.diff = None;
            }
        }
        ui.horizontal(|ui| {
            ui.selectable_value(&mut self.show, Show::Interactive, "interactive");
            ui.selectable_value(&mut self.show, Show::Side(0), "A");
            ui.selectable_value(&mut self.show, Show::Side(1), "B");
            ui.selectable_value(&mut self.show, Show::Difference, "A − B (D)");
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
            Show::Side(i) if self.side_is_interactive(i) => self.texture.as_ref(),
            Show::Side(i) => self.sides[i].texture.as_ref(),
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
        self.view_rect = Some(response.rect);
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
            for i in 0..2 {
                let name = ["A", "B"][i];
                let side = &self.sides[i];
                if self.side_is_interactive(i) {
                    ui.label(format!(
                        "{name}: {} (the interactive frame)",
                        side.backend.name()
                    ));
                    continue;
                }
                match &side.done {
                    Some(r) if r.generation == self.generation => ui.label(format!(
                        "{name}: {}, {} in {:.2} s",
                        r.backend.name(),
                        if r.full {
                            "full"
                        } else {
                            "coarse (refining…)"
                        },
                        r.seconds
                    )),
                    _ => ui.label(format!("{name}: {}, rendering…", side.backend.name())),
                };
            }
            if let Some((g, s, _)) = &self.diff {
                if *g == self.generation {
                    ui.label(format!(
                        "A ({}) − B ({}): max |Δ| {:.3e}, RMSE {:.3e}, PSNR {:.1} dB{}",
                        self.sides[0].backend.name(),
                        self.sides[1].backend.name(),
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

/// How the side pickers name a backend: the interactive one says so.
fn side_label(b: Backend, interactive: Backend) -> String {
    if b == interactive {
        format!("{} (interactive)", b.name())
    } else {
        b.name().to_string()
    }
}

fn to_color_image(frame: &Frame) -> egui::ColorImage {
    egui::ColorImage::from_rgba_unmultiplied([frame.width, frame.height], &rgba8(frame, None))
}

impl eframe::App for Lab {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        self.draw(ui);
    }
}

impl Lab {
    /// One frame of the window: keys, panels, renders.
    fn draw(&mut self, ui: &mut egui::Ui) {
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
        self.collect_frames(&ctx);
        if self.show != Show::Interactive {
            self.request_sides(&ctx);
        }
        self.collect_sides(&ctx);
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

/// The window driven by simulated pointer and key events (egui_kittest: the lab's own
/// drawing code, without a display), on the CPU backends.
#[cfg(test)]
mod tests {
    use super::*;
    use egui::{Event, Modifiers, PointerButton, Pos2, Vec2};
    use egui_kittest::kittest::Queryable;
    use egui_kittest::Harness;
    use std::time::{Duration, Instant};
    use voxlab::editor::{self, WidgetKind};
    use voxlab::jobs::input::VolumeInput;
    use voxlab::jobs::view::DEGREES_PER_PIXEL;
    use voxlab::transfer2d::TransferFunction2D;

    /// The lab on `input` at `size`² pixels, rendering on `backend`.
    fn lab(input: &str, size: usize, backend: Backend) -> Harness<'static, Lab> {
        let input = VolumeInput::new(input);
        let volume = input.load(&()).unwrap();
        let state = ViewState::new(input, &volume, size, size).unwrap();
        let options = Options {
            state,
            volume,
            backend,
            save_state: None,
            screenshot: None,
            frames: None,
            window_screenshot: None,
            compare: false,
            sides: None,
        };
        let lab = Lab::new(
            options,
            Renderer::new(backend).unwrap(),
            Arc::new(Mutex::new(None)),
        )
        .unwrap();
        Harness::builder()
            .with_size(Vec2::new(1400.0, 1000.0))
            .build_ui_state(|ui, lab: &mut Lab| lab.draw(ui), lab)
    }

    /// Steps the window until `done` (the renders run on their own threads).
    fn wait(h: &mut Harness<'static, Lab>, what: &str, done: impl Fn(&Lab) -> bool) {
        let start = Instant::now();
        while !done(h.state()) {
            assert!(
                start.elapsed() < Duration::from_secs(300),
                "timed out waiting for {what}"
            );
            std::thread::sleep(Duration::from_millis(5));
            h.step();
        }
    }

    /// The interactive frame of the current view is there.
    fn frame_ready(lab: &Lab) -> bool {
        lab.frame
            .as_ref()
            .is_some_and(|(g, _)| *g == lab.generation)
    }

    fn button(h: &Harness<'static, Lab>, pos: Pos2, button: PointerButton, pressed: bool) {
        h.event(Event::PointerButton {
            pos,
            button,
            pressed,
            modifiers: Modifiers::NONE,
        });
    }

    /// Presses `b` at `from`, moves to `to` in eight steps and releases it there.
    fn drag(h: &mut Harness<'static, Lab>, from: Pos2, to: Pos2, b: PointerButton) {
        h.hover_at(from);
        h.step();
        button(h, from, b, true);
        h.step();
        for k in 1..=8 {
            h.hover_at(from + (to - from) * (k as f32 / 8.0));
            h.step();
        }
        button(h, to, b, false);
        h.step();
    }

    fn click(h: &mut Harness<'static, Lab>, at: Pos2, b: PointerButton) {
        h.hover_at(at);
        h.step();
        button(h, at, b, true);
        h.step();
        button(h, at, b, false);
        h.step();
    }

    #[test]
    fn dragging_the_view_orbits_it_and_the_wheel_zooms() {
        let mut h = lab("phantom:sphere:16", 64, Backend::CpuF32);
        h.step();
        wait(&mut h, "the first frame", frame_ready);
        let rect = h.state().view_rect.unwrap();
        let before = h.state().state.view;
        // 80 px to the right, as the drag reports it (egui decides it is a drag after a
        // few pixels, which the orbit does not see).
        drag(
            &mut h,
            rect.center(),
            rect.center() + Vec2::new(80.0, 0.0),
            PointerButton::Primary,
        );
        let after = h.state().state.view;
        let turned = (before.azimuth_deg - after.azimuth_deg).rem_euclid(360.0);
        assert!(
            turned > DEGREES_PER_PIXEL * 70.0 && turned <= DEGREES_PER_PIXEL * 80.0 + 1e-9,
            "azimuth {} → {}",
            before.azimuth_deg,
            after.azimuth_deg
        );
        assert_eq!(after.elevation_deg, before.elevation_deg);
        // The frame follows the view.
        wait(&mut h, "the orbited frame", frame_ready);
        // The wheel over the view zooms in by exp(Δ/200).
        let d0 = h.state().state.view.distance_mm;
        h.hover_at(rect.center());
        h.step();
        h.event(Event::MouseWheel {
            unit: egui::MouseWheelUnit::Point,
            delta: Vec2::new(0.0, 100.0),
            modifiers: Modifiers::NONE,
            phase: egui::TouchPhase::Move,
            source: egui::MouseWheelSource::Unknown,
        });
        for _ in 0..60 {
            h.step();
        }
        let d1 = h.state().state.view.distance_mm;
        let want = d0 / 0.5f64.exp();
        assert!(
            (d1 - want).abs() < 0.01 * want,
            "distance {d0} → {d1}, want {want}"
        );
        // A right-drag pans: the target moves, the direction of view does not.
        let before = h.state().state.view;
        drag(
            &mut h,
            rect.center(),
            rect.center() + Vec2::new(0.0, 40.0),
            PointerButton::Secondary,
        );
        let after = h.state().state.view;
        assert_ne!(after.target, before.target);
        assert_eq!(
            (after.azimuth_deg, after.elevation_deg),
            (before.azimuth_deg, before.elevation_deg)
        );
    }

    #[test]
    fn the_1d_editor_adds_moves_and_deletes_points_where_the_pointer_is() {
        let mut h = lab("phantom:sphere:16", 48, Backend::CpuF32);
        h.step();
        let rect = h.state().editors.rects()[0].unwrap();
        let n = h.state().state.transfer.points.len();
        let [d0, d1] = h.state().state.transfer.domain;
        // High in the editor, where no point is: a click adds one there.
        let at = Pos2::new(rect.left() + 0.37 * rect.width(), rect.top() + 12.0);
        click(&mut h, at, PointerButton::Primary);
        let tf = &h.state().state.transfer;
        assert_eq!(tf.points.len(), n + 1);
        let (Some(i), _) = h.state().editors.selection() else {
            panic!("the new point is selected");
        };
        let px = (d1 - d0) / rect.width() as f64;
        assert!(
            (tf.points[i].value - (d0 + 0.37 * (d1 - d0))).abs() <= px,
            "value {}",
            tf.points[i].value
        );
        let frames_before = h.state().generation;
        // Dragged 30 px right: the point follows (held between its neighbours).
        let value = tf.points[i].value;
        drag(
            &mut h,
            at,
            at + Vec2::new(30.0, 0.0),
            PointerButton::Primary,
        );
        let moved = h.state().state.transfer.points[i].value;
        assert!(
            moved > value && moved <= value + 30.0 * px + 1e-9,
            "{value} → {moved}"
        );
        assert!(
            h.state().generation > frames_before,
            "the edit renders again"
        );
        // A right-click on it deletes it.
        let top = h.state().editors.alpha_top();
        let p = h.state().state.transfer.points[i];
        let on = Pos2::new(
            rect.left() + ((p.value - d0) / (d1 - d0)) as f32 * rect.width(),
            rect.bottom() - (p.rgba[3] / top) as f32 * (rect.height() - 14.0) - 14.0,
        );
        click(&mut h, on, PointerButton::Secondary);
        assert_eq!(h.state().state.transfer.points.len(), n);
    }

    #[test]
    fn a_2d_widget_follows_its_handle() {
        let mut h = lab("phantom:marschner-lobb:24", 48, Backend::CpuF32);
        // One rectangle on a linear gradient axis.
        {
            let lab = h.state_mut();
            let mut tf = TransferFunction2D::from_1d(&lab.state.transfer, 64, 2.0);
            tf.gradient_axis = voxlab::transfer2d::GradientAxis::Linear;
            tf.widgets.clear();
            let [d0, d1] = tf.domain;
            let mid = 0.5 * (d0 + d1);
            editor::add_widget(
                &mut tf,
                WidgetKind::Rectangle,
                [mid, 1.0],
                [0.2 * (d1 - d0), 0.5],
                [1.0, 0.5, 0.2, 0.4],
            )
            .unwrap();
            lab.state.settings.transfer_2d = Some(tf);
            lab.changed();
        }
        h.step();
        let rect = h.state().editors.rects()[1].unwrap();
        let tf = h.state().state.settings.transfer_2d.clone().unwrap();
        let [d0, d1] = tf.domain;
        let to_screen = |u: f64, g: f64| {
            Pos2::new(
                rect.left() + ((u - d0) / (d1 - d0)) as f32 * rect.width(),
                rect.bottom() - (g / tf.gradient_max) as f32 * rect.height(),
            )
        };
        let (c, half) = editor::widget_box(&tf.widgets[0]);
        // A click inside selects it; its handles appear.
        click(&mut h, to_screen(c[0], c[1]), PointerButton::Primary);
        assert_eq!(h.state().editors.selection().1, Some(0));
        // The high corner dragged 40 px right and 30 px up; the low corner stays.
        let corner = to_screen(c[0] + half[0], c[1] + half[1]);
        let to = corner + Vec2::new(40.0, -30.0);
        drag(&mut h, corner, to, PointerButton::Primary);
        let tf2 = h.state().state.settings.transfer_2d.clone().unwrap();
        let (c2, half2) = editor::widget_box(&tf2.widgets[0]);
        let (px_v, px_g) = (
            (d1 - d0) / rect.width() as f64,
            tf.gradient_max / rect.height() as f64,
        );
        let low = [c[0] - half[0], c[1] - half[1]];
        let low2 = [c2[0] - half2[0], c2[1] - half2[1]];
        assert!((low2[0] - low[0]).abs() < 1e-9 && (low2[1] - low[1]).abs() < 1e-9);
        let high2 = [c2[0] + half2[0], c2[1] + half2[1]];
        let want = [c[0] + half[0] + 40.0 * px_v, c[1] + half[1] + 30.0 * px_g];
        assert!(
            (high2[0] - want[0]).abs() <= 1.5 * px_v && (high2[1] - want[1]).abs() <= 1.5 * px_g,
            "high corner {high2:?}, want {want:?}"
        );
        // Dragging inside moves the widget whole.
        let inside = to_screen(c2[0], c2[1]);
        drag(
            &mut h,
            inside,
            inside + Vec2::new(-20.0, 0.0),
            PointerButton::Primary,
        );
        let tf3 = h.state().state.settings.transfer_2d.clone().unwrap();
        let (c3, half3) = editor::widget_box(&tf3.widgets[0]);
        assert!((half3[0] - half2[0]).abs() < 1e-9 && c3[0] < c2[0]);
    }

    #[test]
    fn keys_choose_views_and_the_difference_of_two_chosen_sides() {
        let mut h = lab("phantom:sphere:16", 40, Backend::CpuF32);
        h.step();
        wait(&mut h, "the first frame", frame_ready);
        let mut v = h.state().state.view;
        h.key_press(egui::Key::Num5);
        h.step();
        v.look_along(AxisView::PlusZ);
        assert_eq!(h.state().state.view, v);
        h.key_press(egui::Key::O);
        h.step();
        assert!(matches!(
            h.state().state.view.projection,
            ViewProjection::Orthographic { .. }
        ));
        // Side A from the picker: the f64 oracle instead of the interactive frame.
        h.get_by_label("side A").click();
        h.run_steps(3);
        let options = h.query_all_by_label("cpu").collect::<Vec<_>>();
        options.last().expect("the picker lists cpu").click();
        h.step();
        assert_eq!(h.state().sides[0].backend, Backend::Cpu);
        // D: the difference view; both sides are the oracle, so A − B is exactly 0.
        h.key_press(egui::Key::D);
        h.step();
        assert!(h.state().show == Show::Difference);
        wait(&mut h, "the difference", |lab| {
            lab.diff.as_ref().is_some_and(|d| d.0 == lab.generation)
        });
        let (_, stats, _) = h.state().diff.as_ref().unwrap();
        assert_eq!(stats.max_abs, 0.0);
        // Side B from the picker: the interactive frame (cpu-f32) against A (the
        // oracle), within the f32 path's stated tolerance.
        h.get_by_label("side B").click();
        h.run_steps(3);
        let options = h
            .query_all_by_label("cpu-f32 (interactive)")
            .collect::<Vec<_>>();
        options.last().expect("the picker lists cpu-f32").click();
        h.step();
        assert_eq!(h.state().sides[1].backend, Backend::CpuF32);
        h.state_mut().changed();
        wait(&mut h, "the difference", |lab| {
            lab.diff.as_ref().is_some_and(|d| d.0 == lab.generation)
        });
        let (_, stats, _) = h.state().diff.as_ref().unwrap();
        assert!(stats.max_abs > 0.0);
        assert_eq!(h.state().within, Some(true));
    }

    #[test]
    fn frames_render_off_the_ui_thread() {
        // The f64 oracle at 256² on a 64³ phantom takes a good part of a second.
        let mut h = lab("phantom:shepp-logan-modified:64", 256, Backend::Cpu);
        h.step();
        wait(&mut h, "the first frame", frame_ready);
        // A new view: the step that asks for its frame returns without it (a render on
        // the UI thread would have drawn it within the step), and the frame comes
        // later.
        h.state_mut().state.view.orbit_by(30.0, 0.0);
        h.state_mut().changed();
        h.step();
        assert_eq!(h.state().requested, h.state().generation);
        assert!(!frame_ready(h.state()), "the step waited for the render");
        wait(&mut h, "the new frame", frame_ready);
        // A newer view cancels the one in flight: only the last is shown.
        for _ in 0..3 {
            h.state_mut().state.view.orbit_by(30.0, 0.0);
            h.state_mut().changed();
            h.step();
        }
        wait(&mut h, "the last frame", frame_ready);
        let lab = h.state();
        let (scene, settings) = lab.scene().unwrap();
        let want = voxlab::jobs::render::render(&scene, &settings, Backend::Cpu).unwrap();
        assert_eq!(lab.frame.as_ref().unwrap().1, want.image);
    }
}
