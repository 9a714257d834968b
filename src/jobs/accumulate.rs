//! Frame accumulation: jittered frames averaged.
//!
//! Jittered ray starts (`cpu::jitter`) turn the coherent "wood-grain" error of a fixed
//! step into noise; averaging `N` frames with independent offsets (seeds `seed, seed +
//! 1, …`) shrinks that noise like `1/√N` towards the exact integral. Both backends
//! jitter each pixel by the same offsets.

use super::renderer::{PreparedScene, Rendered, Renderer, Scene};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::frame::Frame;
use crate::settings::RenderSettings;
use crate::transfer::TransferFunction;

/// Renders `frames` frames jittered with seeds `seed, seed + 1, …` and averages them
/// (images and sample counts; `total_samples` is the sum over frames, GPU timings are
/// summed). `progress(frames done, frames)` is called after each frame.
pub fn render_accumulated(
    renderer: &Renderer,
    scene: &Scene,
    settings: &RenderSettings,
    seed: u32,
    frames: usize,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Rendered> {
    check_frames(frames)?;
    // The volume is checked, converted (uploaded) and bounded once, not once per frame.
    let prepared = renderer.prepare(scene, settings)?;
    render_accumulated_prepared(
        renderer,
        &prepared,
        &scene.transfer,
        &scene.camera,
        settings,
        seed,
        frames,
        progress,
    )
}

/// [`render_accumulated`] of a scene already prepared (with `tf` and `camera`).
#[allow(clippy::too_many_arguments)]
pub fn render_accumulated_prepared(
    renderer: &Renderer,
    prepared: &PreparedScene,
    tf: &TransferFunction,
    camera: &Camera,
    settings: &RenderSettings,
    seed: u32,
    frames: usize,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Rendered> {
    check_frames(frames)?;
    let mut acc: Option<Rendered> = None;
    for f in 0..frames {
        let s = RenderSettings {
            jitter: Some(seed.wrapping_add(f as u32)),
            interleaved: false,
            ..settings.clone()
        };
        let r = renderer.render_prepared_with(prepared, tf, camera, &s, &|_, _| {})?;
        acc = Some(match acc {
            None => r,
            Some(mut a) => {
                add_into(&mut a.output.image, &r.output.image);
                if let (Some(x), Some(y)) = (&mut a.output.samples, &r.output.samples) {
                    add_into(x, y);
                }
                a.output.total_samples += r.output.total_samples;
                if let (Some(x), Some(y)) = (&mut a.gpu_timings, &r.gpu_timings) {
                    x.add(y);
                }
                a.gpu_session = r.gpu_session;
                a
            }
        });
        progress(f + 1, frames);
    }
    let mut a = acc.expect("at least one frame");
    let k = 1.0 / frames as f64;
    a.output.image.data.iter_mut().for_each(|v| *v *= k);
    if let Some(s) = &mut a.output.samples {
        s.data.iter_mut().for_each(|v| *v *= k);
    }
    Ok(a)
}

fn check_frames(frames: usize) -> Result<()> {
    if frames == 0 || frames > 65_536 {
        return Err(Error::invalid("accumulate", "frames must lie in 1 … 65536"));
    }
    Ok(())
}

fn add_into(a: &mut Frame, b: &Frame) {
    for (x, y) in a.data.iter_mut().zip(&b.data) {
        *x += *y;
    }
}
