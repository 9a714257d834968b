//! The reference renders off the UI thread: the CPU f64 oracle (or the f32 path) of the
//! current view, a quarter-size frame first and then the full one. A newer view cancels
//! the render in flight (through [`voxlab::jobs::cancellable`]), so the window stays
//! responsive however slow the oracle is.

use eframe::egui;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::Arc;
use std::time::Instant;
use voxlab::frame::Frame;
use voxlab::jobs::render::{Renderer, Scene};
use voxlab::jobs::view::OrbitView;
use voxlab::jobs::{cancellable, Backend, Progress};
use voxlab::settings::RenderSettings;
use voxlab::Result;

/// One reference render to make.
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

/// A finished (or failed, or cancelled) reference render.
pub struct Done {
    pub generation: u64,
    pub backend: Backend,
    /// The full-size frame (else the coarse one).
    pub full: bool,
    pub seconds: f64,
    pub result: Result<Frame>,
}

pub struct Worker {
    jobs: Sender<Job>,
    done: Receiver<Done>,
    /// The generation of the latest request: older renders stop.
    latest: Arc<AtomicU64>,
    requested: Option<(u64, Backend)>,
}

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

impl Worker {
    pub fn start() -> Self {
        let (jobs, rx) = channel::<Job>();
        let (tx, done) = channel::<Done>();
        let latest = Arc::new(AtomicU64::new(0));
        let seen = latest.clone();
        std::thread::Builder::new()
            .name("voxlab-reference".into())
            .spawn(move || {
                while let Ok(mut job) = rx.recv() {
                    // Only the newest request is worth doing.
                    while let Ok(newer) = rx.try_recv() {
                        job = newer;
                    }
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
