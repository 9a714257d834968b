//! Every render of the lab runs off the UI thread, so the window stays responsive
//! however slow a backend is:
//! - [`Frames`]: the interactive frames, on the lab's backend, from a prepared scene of
//!   the volume kept on the worker (on the GPU a render session: the volume uploaded
//!   once, the pipelines cached);
//! - [`Worker`]: the two sides of the difference view (the CPU f64 oracle, the f32
//!   path, or the GPU), a quarter-size frame first and then the full one.
//!
//! Both render only the newest view: a request made while a render runs cancels it
//! (through [`voxlab::jobs::cancellable`]; on the CPU between rows, on the GPU between
//! row bands), and requests that queued up behind it are skipped.

use eframe::egui;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::Arc;
use std::time::Instant;
use voxlab::frame::Frame;
use voxlab::jobs::render::{PreparedScene, Rendered, Renderer, Scene};
use voxlab::jobs::view::{OrbitView, ViewState};
use voxlab::jobs::{cancellable, Backend, Progress};
use voxlab::settings::RenderSettings;
use voxlab::{AnyVolume, Result};

/// Cancels a render once a newer view was requested.
struct Newer {
    latest: Arc<AtomicU64>,
    mine: u64,
}

impl Progress for Newer {
    fn cancelled(&self) -> bool {
        self.latest.load(Ordering::Relaxed) != self.mine
    }
}

/// The newest of the requests waiting on `rx` (blocking for the first).
fn newest<T>(rx: &Receiver<T>) -> Option<T> {
    let mut job = rx.recv().ok()?;
    while let Ok(newer) = rx.try_recv() {
        job = newer;
    }
    Some(job)
}

/// One interactive frame to make: the whole view (camera, settings, transfer
/// functions, image size).
pub struct FrameJob {
    pub generation: u64,
    pub state: ViewState,
    /// Woken when the frame is done.
    pub repaint: egui::Context,
}

/// A finished (or failed, or cancelled) interactive frame.
pub struct FrameDone {
    pub generation: u64,
    pub seconds: f64,
    pub result: Result<Rendered>,
}

/// The interactive frames' thread.
pub struct Frames {
    jobs: Sender<FrameJob>,
    done: Receiver<FrameDone>,
    latest: Arc<AtomicU64>,
}

impl Frames {
    /// Starts the thread; it renders `volume` on `renderer`'s backend.
    pub fn start(renderer: Renderer, volume: AnyVolume) -> Self {
        let (jobs, rx) = channel::<FrameJob>();
        let (tx, done) = channel::<FrameDone>();
        let latest = Arc::new(AtomicU64::new(0));
        let seen = latest.clone();
        std::thread::Builder::new()
            .name("voxlab-frames".into())
            .spawn(move || {
                let mut prepared: Option<PreparedScene> = None;
                while let Some(job) = newest(&rx) {
                    let stop = Newer {
                        latest: seen.clone(),
                        mine: job.generation,
                    };
                    let t = Instant::now();
                    let result = frame(&renderer, &volume, &mut prepared, &job.state, &stop);
                    let _ = tx.send(FrameDone {
                        generation: job.generation,
                        seconds: t.elapsed().as_secs_f64(),
                        result,
                    });
                    job.repaint.request_repaint();
                }
            })
            .expect("a thread can be started");
        Frames { jobs, done, latest }
    }

    /// Asks for a frame of `job`'s view, cancelling the one in flight.
    pub fn request(&self, job: FrameJob) {
        self.latest.store(job.generation, Ordering::Relaxed);
        let _ = self.jobs.send(job);
    }

    /// A finished frame, if one is waiting.
    pub fn poll(&self) -> Option<FrameDone> {
        self.done.try_recv().ok()
    }
}

/// A frame of `state` from the prepared volume (prepared again only when the settings
/// need it: on the CPU backends another filter or gradient method; on the GPU the
/// session serves every setting).
fn frame(
    renderer: &Renderer,
    volume: &AnyVolume,
    prepared: &mut Option<PreparedScene>,
    state: &ViewState,
    stop: &Newer,
) -> Result<Rendered> {
    state.validate()?;
    let camera = state.camera()?;
    let mut settings = state.settings.clone();
    settings.sample_count = true;
    let tf = &state.transfer;
    let p = match prepared.take() {
        Some(p) if p.serves(&settings) => p,
        _ => renderer.prepare_volume(volume, tf, &settings)?,
    };
    let out = cancellable(stop, |cp| {
        renderer.render_prepared_with(&p, tf, &camera, &settings, &|d, t| cp.advance(d, t))
    });
    *prepared = Some(p);
    out
}

/// One render of a side of the difference view.
pub struct Job {
    pub generation: u64,
    pub backend: Backend,
    pub scene: Scene,
    pub settings: RenderSettings,
    pub view: OrbitView,
    pub size: [usize; 2],
    /// Woken when a frame is done.
    pub repaint: egui::Context,
}

/// A finished (or failed, or cancelled) render of a side.
pub struct Done {
    pub generation: u64,
    pub backend: Backend,
    /// The full-size frame (else the coarse one).
    pub full: bool,
    pub seconds: f64,
    pub result: Result<Frame>,
}

/// A side's thread.
pub struct Worker {
    jobs: Sender<Job>,
    done: Receiver<Done>,
    /// The generation of the latest request: older renders stop.
    latest: Arc<AtomicU64>,
    requested: Option<(u64, Backend)>,
}

impl Worker {
    pub fn start() -> Self {
        let (jobs, rx) = channel::<Job>();
        let (tx, done) = channel::<Done>();
        let latest = Arc::new(AtomicU64::new(0));
        let seen = latest.clone();
        std::thread::Builder::new()
            .name("voxlab-reference".into())
            .spawn(move || {
                while let Some(job) = newest(&rx) {
                    let stop = Newer {
                        latest: seen.clone(),
                        mine: job.generation,
                    };
                    let [w, h] = job.size;
                    for full in [false, true] {
                        let (cw, ch) = if full {
                            (w, h)
                        } else {
                            (w.div_ceil(4), h.div_ceil(4))
                        };
                        let t = Instant::now();
                        let result = render(&job, cw, ch, &stop);
                        let cancelled = matches!(result, Err(voxlab::Error::Cancelled));
                        let _ = tx.send(Done {
                            generation: job.generation,
                            backend: job.backend,
                            full,
                            seconds: t.elapsed().as_secs_f64(),
                            result,
                        });
                        job.repaint.request_repaint();
                        if cancelled {
                            break;
                        }
                    }
                }
            })
            .expect("a thread can be started");
        Worker {
            jobs,
            done,
            latest,
            requested: None,
        }
    }

    /// Asks for `job`, cancelling the render in flight.
    pub fn request(&mut self, job: Job) {
        self.latest.store(job.generation, Ordering::Relaxed);
        self.requested = Some((job.generation, job.backend));
        let _ = self.jobs.send(job);
    }

    /// Whether the last request was for this view and backend.
    pub fn busy_with(&self, generation: u64, backend: Backend) -> bool {
        self.requested == Some((generation, backend))
    }

    /// A finished render, if one is waiting.
    pub fn poll(&self) -> Option<Done> {
        self.done.try_recv().ok()
    }
}

fn render(job: &Job, width: usize, height: usize, stop: &Newer) -> Result<Frame> {
    let camera = job.view.camera(width, height)?;
    let scene = Scene {
        camera,
        ..job.scene.clone()
    };
    let renderer = Renderer::new(job.backend)?;
    cancellable(stop, |cp| {
        renderer.render(&scene, &job.settings, &|d, t| cp.advance(d, t))
    })
    .map(|r| r.output.image)
}
