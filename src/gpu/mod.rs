//! The GPU side: wgpu on Vulkan, Metal or DX12 (never the GL backend), with WGSL
//! compute shaders under `shaders/`.
//!
//! Four shared layers, then one file per family. Dependencies point one way: the
//! families import `context`, `shaders`, `params` and `plan`, and a family that builds on
//! another (the ray caster on `skip` and `clipmesh`, D²VR and the multi-volume caster
//! on `raycast`, `adaptive` on `preintegrate`, FVR and ramp filtering on `fft`) imports
//! it, never the other way round.
//!
//! - `context` finds an adapter, opens a device with the adapter's own limits, turns
//!   every failure into a typed [`crate::Error`], and holds the plumbing every family
//!   uses: compute pipelines, bind-group-layout entries, the row-band loop of the
//!   per-pixel casters, llvmpipe's loop limit.
//! - `shaders` is the one place that assembles WGSL: every `.wgsl` file registered once,
//!   `#import NAME` resolved there, generated code passed in as named modules.
//! - `params` holds the `#[repr(C)]` parameter blocks that several families share.
//! - `plan` holds the limits jobs plan against (the adapter's, lowered by
//!   `VOXLAB_GPU_MAX_BINDING` and `VOXLAB_GPU_MAX_TEXTURE_3D`) and the one way a job
//!   cuts an axis into pieces that fit them; `context` applies the limits when it opens
//!   the device.
//!
//! `probe` is the smallest end-to-end check that a device really computes: upload,
//! dispatch, read back, compare. `fft` is the power-of-two FFT (split-stream and
//! Stockham variants); `fvr` the Fourier volume rendering slice and its inverse FFT;
//! `project` Joseph's CT forward projector; `radon` scikit-image's Radon transform and
//! its inverse's backprojection.

pub mod adaptive;
pub mod clipmesh;
pub mod context;
pub mod d2vr;
pub mod fbp;
pub mod fft;
pub mod fvr;
pub mod gradient;
pub mod iterative;
pub mod joseph_pair;
pub mod multi;
pub mod params;
pub mod parker;
pub mod peak;
pub mod plan;
pub mod preintegrate;
pub mod probe;
pub mod process;
pub mod project;
pub mod radon;
pub mod ramp;
pub mod raycast;
pub mod shaders;
pub mod skip;
pub mod tricubic;

pub use context::{AdapterSummary, GpuContext};

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    /// The files of `gpu` that `src` (one file's code) refers to: `super::x` and
    /// `crate::gpu::x`, comments left out.
    fn uses(src: &str, files: &[String]) -> Vec<String> {
        let mut out = Vec::new();
        for line in src.lines() {
            let code = line.split("//").next().unwrap_or("");
            for prefix in ["super::", "crate::gpu::"] {
                for (at, _) in code.match_indices(prefix) {
                    let rest = &code[at + prefix.len()..];
                    let name: String = rest
                        .chars()
                        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                        .collect();
                    if files.contains(&name) && !out.contains(&name) {
                        out.push(name);
                    }
                }
            }
        }
        out
    }

    /// Dependencies among the files of `gpu` point one way: no file reaches itself
    /// through the files it uses (shared pieces live in `context`, `shaders`, `params`,
    /// `plan` and `peak`, below every family; `context` uses only `plan` and `peak`).
    #[test]
    fn gpu_files_import_one_way() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/gpu");
        let mut files = Vec::new();
        for e in std::fs::read_dir(&dir).unwrap() {
            let name = e.unwrap().file_name().to_string_lossy().into_owned();
            if let Some(stem) = name.strip_suffix(".rs").filter(|s| *s != "mod") {
                files.push(stem.to_string());
            }
        }
        let graph: BTreeMap<String, Vec<String>> = files
            .iter()
            .map(|f| {
                let src = std::fs::read_to_string(dir.join(format!("{f}.rs"))).unwrap();
                let mut deps = uses(&src, &files);
                deps.retain(|d| d != f);
                (f.clone(), deps)
            })
            .collect();
        // Depth-first search from every file; a file met again on the path is a circle.
        fn visit(
            f: &str,
            graph: &BTreeMap<String, Vec<String>>,
            path: &mut Vec<String>,
            done: &mut Vec<String>,
        ) {
            if let Some(start) = path.iter().position(|p| p == f) {
                panic!("import circle: {} → {f}", path[start..].join(" → "));
            }
            if done.iter().any(|d| d == f) {
                return;
            }
            path.push(f.to_string());
            for d in &graph[f] {
                visit(d, graph, path, done);
            }
            path.pop();
            done.push(f.to_string());
        }
        let mut done = Vec::new();
        for f in graph.keys() {
            visit(f, &graph, &mut Vec::new(), &mut done);
        }
        for shared in ["plan", "shaders", "params", "peak"] {
            assert!(
                graph[shared].is_empty(),
                "{shared} uses {:?}",
                graph[shared]
            );
        }
        // The device is opened under the planner's limits and the data sheet's memory,
        // and nothing else.
        let mut context = graph["context"].clone();
        context.sort();
        assert_eq!(
            context,
            ["peak", "plan"],
            "context uses {:?}",
            graph["context"]
        );
    }
}
