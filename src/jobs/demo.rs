//! `voxlab demo`: the main job on an embedded default. Renders a small gallery into a
//! folder, with no download and no flags: two real scans embedded in the binary (an
//! X-ray micro-CT of bone and the classic UNC MR brain, see `data/README.md`) and the
//! analytic phantoms in several modes and filters; then writes an `index.html` and a
//! `README.md` that show them.

use super::embedded::{microct_bone, mr_brain};
use super::input::{volume_center, volume_extent};
use super::render::{Renderer, Scene};
use crate::camera::{AxisView, Camera, Orbit, Projection};
use crate::error::{Error, Result};
use crate::io::{write_frame, PngOptions};
use crate::phantom::Phantom;
use crate::settings::{Classification, Filter, Mode, RenderSettings};
use crate::transfer::TransferFunction;
use std::path::{Path, PathBuf};

/// One picture of the gallery.
#[derive(Clone, Debug)]
pub struct DemoItem {
    pub file: PathBuf,
    pub title: String,
    pub seconds: f64,
}

/// The `marschner-lobb` preset: a soft iso-surface near 0.5, the classic way to
/// compare reconstruction filters.
pub fn marschner_lobb_tf() -> Result<TransferFunction> {
    TransferFunction::preset("marschner-lobb")
}

/// Renders the gallery into `out` with `renderer`, creating the folder; reports each
/// finished picture.
pub fn run(
    out: &Path,
    renderer: &Renderer,
    report: &dyn Fn(&DemoItem, usize, usize),
) -> Result<Vec<DemoItem>> {
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    let size = 256;
    let head = Phantom::shepp_logan_modified();
    let head_vol: crate::AnyVolume = head.sample([128; 3])?.into();
    let spheres_vol: crate::AnyVolume = Phantom::by_name("spheres")?.sample([96; 3])?.into();
    let ml = Phantom::marschner_lobb();
    let ml_vol: crate::AnyVolume = ml.sample([41; 3])?.into();
    let phantom_tf = TransferFunction::preset("phantom")?;
    // Frame the phantoms' content (radius ≈ 0.95 of the half extent), not the corners
    // of their cubes.
    let orbit = |vol: &crate::AnyVolume, projection, elevation_deg: f64| {
        let half = 0.5 * volume_extent(vol)[0];
        let projection = match projection {
            Projection::Orthographic { .. } => Projection::Orthographic {
                width_mm: 2.1 * half,
                height_mm: 2.1 * half,
            },
            p => p,
        };
        Camera::orbit(
            volume_center(vol),
            volume_extent(vol),
            Orbit {
                azimuth_deg: 30.0,
                elevation_deg,
                distance_mm: Some(4.2 * half),
            },
            projection,
            size,
            size,
        )
    };
    let persp = Projection::Perspective { fov_y_deg: 30.0 };
    let ortho = Projection::Orthographic {
        width_mm: 0.0,
        height_mm: 0.0,
    };

    struct Job {
        file: &'static str,
        title: String,
        scene: Scene,
        settings: RenderSettings,
        png: PngOptions,
    }
    let base = RenderSettings::default();
    let bone_vol = microct_bone()?;
    let brain_vol = mr_brain()?;
    let mut brain_tf = TransferFunction::preset("mri-brain")?;
    // The mri-brain preset's domain is [0, 1]; this 8-bit scan's tissue lies in 0…140.
    brain_tf.window = crate::transfer::WindowMap::from_window_level(140.0, 70.0, brain_tf.domain)?;
    // `distance` is in half-extents of the volume's longest side.
    let real_orbit =
        |vol: &crate::AnyVolume, azimuth_deg: f64, elevation_deg: f64, distance: f64| {
            let half = 0.5 * volume_extent(vol).iter().cloned().fold(0.0, f64::max);
            Camera::orbit(
                volume_center(vol),
                volume_extent(vol),
                Orbit {
                    azimuth_deg,
                    elevation_deg,
                    distance_mm: Some(distance * half),
                },
                Projection::Perspective { fov_y_deg: 30.0 },
                size,
                size,
            )
        };
    let mut jobs = vec![
        Job {
            file: "microct-bone-dvr.png",
            title: "X-ray micro-CT of bone (real scan, 128³ u8 TIFF stack), shaded DVR, microct-bone preset".into(),
            scene: Scene {
                volume: bone_vol.clone(),
                transfer: TransferFunction::preset("microct-bone")?,
                camera: real_orbit(&bone_vol, -60.0, 30.0, 5.2)?,
            },
            settings: RenderSettings { step: 0.5, ..base.clone() },
            png: PngOptions::default(),
        },
        Job {
            file: "mr-brain-dvr.png",
            title: "MR head (real scan, UNC brain from VolPack, 128×128×84 u8), shaded DVR, mri-brain preset".into(),
            scene: Scene {
                volume: brain_vol.clone(),
                transfer: brain_tf,
                camera: real_orbit(&brain_vol, 150.0, 15.0, 3.6)?,
            },
            settings: RenderSettings { step: 0.5, ..base.clone() },
            png: PngOptions::default(),
        },
        Job {
            file: "shepp-logan-dvr.png",
            title: "Shepp–Logan (modified), shaded DVR, trilinear, post-classification".into(),
            scene: Scene {
                volume: head_vol.clone(),
                transfer: phantom_tf.clone(),
                camera: orbit(&head_vol, persp, 20.0)?,
            },
            settings: RenderSettings { step: 0.25, ..base.clone() },
            png: PngOptions::default(),
        },
        Job {
            file: "shepp-logan-dvr-preclassified.png",
            title: "Shepp–Logan, shaded DVR, pre-classification".into(),
            scene: Scene {
                volume: head_vol.clone(),
                transfer: phantom_tf.clone(),
                camera: orbit(&head_vol, persp, 20.0)?,
            },
            settings: RenderSettings {
                classification: Classification::Pre,
                step: 0.25,
                ..base.clone()
            },
            png: PngOptions::default(),
        },
        Job {
            file: "spheres-mip.png",
            title: "Nested spheres, maximum intensity projection (orthographic): 1.5 where the inner sphere adds to the outer".into(),
            scene: Scene {
                volume: spheres_vol.clone(),
                transfer: phantom_tf.clone(),
                camera: orbit(&spheres_vol, ortho, 20.0)?,
            },
            settings: RenderSettings { mode: Mode::Mip, ..base.clone() },
            png: PngOptions::default(),
        },
        Job {
            file: "shepp-logan-xray.png",
            title: "Shepp–Logan, X-ray line integrals along +y (axis view)".into(),
            scene: Scene {
                volume: head_vol.clone(),
                transfer: phantom_tf.clone(),
                camera: Camera::axis_view(head_vol.dims(), head_vol.affine(), AxisView::PlusY, 128, 128)?,
            },
            settings: RenderSettings { mode: Mode::Xray, step: 1.0, ..base.clone() },
            png: PngOptions::default(),
        },
    ];
    for filter in [
        Filter::Nearest,
        Filter::Trilinear,
        Filter::CatmullRom,
        Filter::Lanczos3,
    ] {
        let file: &'static str = match filter {
            Filter::Nearest => "marschner-lobb-nearest.png",
            Filter::Trilinear => "marschner-lobb-trilinear.png",
            Filter::CatmullRom => "marschner-lobb-catmull-rom.png",
            _ => "marschner-lobb-lanczos3.png",
        };
        jobs.push(Job {
            file,
            title: format!(
                "Marschner–Lobb 41³, iso 0.5, {} reconstruction",
                filter.name()
            ),
            scene: Scene {
                volume: ml_vol.clone(),
                transfer: marschner_lobb_tf()?,
                camera: orbit(&ml_vol, persp, 35.0)?,
            },
            settings: RenderSettings {
                filter,
                step: 0.25,
                ..base.clone()
            },
            png: PngOptions::default(),
        });
    }
    let total = jobs.len() + 1;
    let mut items = Vec::new();
    for job in jobs {
        let t = std::time::Instant::now();
        let mut settings = job.settings;
        let counts = job.file == "shepp-logan-dvr.png";
        settings.sample_count = counts;
        let out_img = renderer.render(&job.scene, &settings, &|_, _| {})?.output;
        let path = out.join(job.file);
        write_frame(&path, &out_img.image, job.png)?;
        let item = DemoItem {
            file: path,
            title: job.title,
            seconds: t.elapsed().as_secs_f64(),
        };
        report(&item, items.len() + 1, total);
        items.push(item);
        if let Some(samples) = out_img.samples {
            let path = out.join("shepp-logan-samples.png");
            write_frame(&path, &samples, PngOptions::default())?;
            let item = DemoItem {
                file: path,
                title: "Samples per ray of the first picture (early ray termination at 0.99; white = most)".into(),
                seconds: 0.0,
            };
            report(&item, items.len() + 1, total);
            items.push(item);
        }
    }
    write_index(out, &items, &renderer.describe())?;
    Ok(items)
}

fn write_index(out: &Path, items: &[DemoItem], who: &str) -> Result<()> {
    let name = |p: &Path| {
        p.file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    let mut html = String::from(
        "<!doctype html><meta charset=utf-8><title>voxlab demo</title>\n\
         <style>body{font-family:sans-serif;background:#222;color:#eee}figure{display:inline-block;margin:8px}\
         img{image-rendering:pixelated;width:256px}</style>\n<h1>voxlab demo</h1>\n",
    );
    html += &format!("<p>Rendered by {who}.</p>\n");
    let mut md = format!("# voxlab demo gallery\n\nRendered by {who}.\n\n");
    for it in items {
        let f = name(&it.file);
        html += &format!(
            "<figure><img src=\"{f}\"><figcaption>{}</figcaption></figure>\n",
            it.title
        );
        md += &format!("## {}\n\n![{}]({f})\n\n", it.title, it.title);
    }
    for (file, text) in [("index.html", html), ("README.md", md)] {
        let path = out.join(file);
        crate::io::write_text(&path, &text)?;
    }
    Ok(())
}
