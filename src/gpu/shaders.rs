//! The one place that assembles WGSL.
//!
//! Every `.wgsl` file under `shaders/` is registered once in [`MODULES`], by name (its
//! file stem: `rays` is `shaders/shared/rays.wgsl`, `raycast` is
//! `shaders/raycast.wgsl`), with its text from `include_str!`. A source pulls another
//! module in with a line of its own (the form of vello's shaders):
//!
//! ```wgsl
//! #import rays
//! ```
//!
//! [`resolve`] expands the imports recursively and in place: the line is replaced by
//! the imported module's expanded text the first time that module is met and dropped
//! after that, so every module appears once, wherever it is first imported (WGSL
//! declarations may come in any order). An import of a module that is being expanded
//! (a cycle) and an import of an unknown name are programmer errors: the sources are
//! fixed at compile time, [`resolve`] panics naming the chain or the importer, and a
//! unit test resolves every registered module.
//!
//! Code the host writes per call (the ray caster's per-settings `sample_tex`,
//! `accumulate_taps` and `gradient_at`, FVR's slab bindings, D²VR's projection reads)
//! is imported by name like any module: the names are declared in [`GENERATED`] with
//! the function that writes them, and the text is passed to [`resolve_with`] as a
//! *virtual module*. A generated text may itself import registered modules
//! (`#import modes_cast` chooses a registered variant). Nothing else glues WGSL
//! together: no family formats one module's source into another's.
//!
//! What a module may use without importing it: the bindings and the `params` uniform
//! of the stage that imports it (each shared module's header says which members it
//! reads), and functions the stage defines for it (`gradient_voxel.wgsl` calls the
//! stage's `volume`, `ct_bilinear.wgsl` its `tap`, `joseph_bilinear.wgsl` its `vol`).

use std::collections::HashSet;
use std::fmt;

/// One registered WGSL file.
#[derive(Clone, Copy, Debug)]
pub struct Module {
    /// The name `#import` uses: the file stem.
    pub name: &'static str,
    /// The file, relative to the crate root.
    pub path: &'static str,
    /// Its text.
    pub source: &'static str,
}

/// A module whose text the host generates per call.
#[derive(Clone, Copy, Debug)]
pub struct Generated {
    /// The name `#import` uses.
    pub name: &'static str,
    /// The Rust function that writes it.
    pub by: &'static str,
}

macro_rules! registry {
    ($($konst:ident = $name:literal => $path:literal,)*) => {
        $(
            #[doc = concat!("`shaders/", $path, "` (`#import ", $name, "`).")]
            pub const $konst: &str = include_str!(concat!("../../shaders/", $path));
        )*
        /// Every WGSL file under `shaders/`, once.
        pub static MODULES: &[Module] = &[
            $(Module { name: $name, path: concat!("shaders/", $path), source: $konst },)*
        ];
    };
}

registry! {
    ADAPTIVE = "adaptive" => "adaptive.wgsl",
    ADAPTIVE_IMPORTANCE = "adaptive_importance" => "adaptive_importance.wgsl",
    CLIPMESH = "clipmesh" => "clipmesh.wgsl",
    D2VR = "d2vr" => "d2vr.wgsl",
    FBP_BACKPROJECT = "fbp_backproject" => "fbp_backproject.wgsl",
    FFT_BLUESTEIN = "fft_bluestein" => "fft_bluestein.wgsl",
    FFT_SPLIT_STREAM = "fft_split_stream" => "fft_split_stream.wgsl",
    FFT_STOCKHAM = "fft_stockham" => "fft_stockham.wgsl",
    FFT_TWO_REAL = "fft_two_real" => "fft_two_real.wgsl",
    FVR_SLICE = "fvr_slice" => "fvr_slice.wgsl",
    GRADIENT = "gradient" => "gradient.wgsl",
    ITERATIVE = "iterative" => "iterative.wgsl",
    JOSEPH_PAIR_TRANSPOSE = "joseph_pair_transpose" => "joseph_pair_transpose.wgsl",
    MULTI = "multi" => "multi.wgsl",
    OPACITY_PROBE = "opacity_probe" => "opacity_probe.wgsl",
    PARKER = "parker" => "parker.wgsl",
    PREINTEGRATE = "preintegrate" => "preintegrate.wgsl",
    PROBE = "probe" => "probe.wgsl",
    PROCESS_GAUSSIAN = "process_gaussian" => "process_gaussian.wgsl",
    PROCESS_GRADIENT = "process_gradient" => "process_gradient.wgsl",
    PROCESS_MEDIAN = "process_median" => "process_median.wgsl",
    PROCESS_RESAMPLE = "process_resample" => "process_resample.wgsl",
    PROJECT = "project" => "project.wgsl",
    RADON = "radon" => "radon.wgsl",
    RADON_SART = "radon_sart" => "radon_sart.wgsl",
    RAMP_FILTER = "ramp_filter" => "ramp_filter.wgsl",
    RAYCAST = "raycast" => "raycast.wgsl",
    RAYCAST_PREPARE = "raycast_prepare" => "raycast_prepare.wgsl",
    SKIP_MINMAX = "skip_minmax" => "skip_minmax.wgsl",
    TRICUBIC_POINTS = "tricubic_points" => "tricubic_points.wgsl",
    ADAPTIVE_PARAMS = "adaptive_params" => "shared/adaptive_params.wgsl",
    BILINEAR_CELL = "bilinear_cell" => "shared/bilinear_cell.wgsl",
    CAMERA = "camera" => "shared/camera.wgsl",
    CLASSIFY = "classify" => "shared/classify.wgsl",
    CLASSIFY2D = "classify2d" => "shared/classify2d.wgsl",
    CT_BILINEAR = "ct_bilinear" => "shared/ct_bilinear.wgsl",
    CT_GEOMETRY = "ct_geometry" => "shared/ct_geometry.wgsl",
    D2VR_PARAMS = "d2vr_params" => "shared/d2vr_params.wgsl",
    FBP_PARAMS = "fbp_params" => "shared/fbp_params.wgsl",
    FFT_COMMON = "fft_common" => "shared/fft_common.wgsl",
    FFT_PARAMS = "fft_params" => "shared/fft_params.wgsl",
    FILTERS = "filters" => "shared/filters.wgsl",
    FVR_PARAMS = "fvr_params" => "shared/fvr_params.wgsl",
    GRADIENT_PARAMS = "gradient_params" => "shared/gradient_params.wgsl",
    GRADIENT_VOXEL = "gradient_voxel" => "shared/gradient_voxel.wgsl",
    ITERATIVE_PARAMS = "iterative_params" => "shared/iterative_params.wgsl",
    JOSEPH = "joseph" => "shared/joseph.wgsl",
    JOSEPH_BILINEAR = "joseph_bilinear" => "shared/joseph_bilinear.wgsl",
    MODES = "modes" => "shared/modes.wgsl",
    MODES_CAST = "modes_cast" => "shared/modes_cast.wgsl",
    MULTI_PARAMS = "multi_params" => "shared/multi_params.wgsl",
    OPACITY = "opacity" => "shared/opacity.wgsl",
    PARKER_PARAMS = "parker_params" => "shared/parker_params.wgsl",
    PROCESS_PARAMS = "process_params" => "shared/process_params.wgsl",
    PROJECT_PARAMS = "project_params" => "shared/project_params.wgsl",
    RADON_PARAMS = "radon_params" => "shared/radon_params.wgsl",
    RAMP_PARAMS = "ramp_params" => "shared/ramp_params.wgsl",
    RAYCAST_PARAMS = "raycast_params" => "shared/raycast_params.wgsl",
    RAYS = "rays" => "shared/rays.wgsl",
    SHADING = "shading" => "shared/shading.wgsl",
    SKIP = "skip" => "shared/skip.wgsl",
    TRICUBIC = "tricubic" => "shared/tricubic.wgsl",
}

/// The modules the host writes per call, and who writes them.
pub static GENERATED: &[Generated] = &[
    Generated {
        name: "sample_tex",
        by: "src/gpu/raycast.rs: sample_tex_wgsl",
    },
    Generated {
        name: "accumulate_taps",
        by: "src/gpu/raycast.rs: accumulate_taps_wgsl",
    },
    Generated {
        name: "gradient_at",
        by: "src/gpu/raycast.rs: gradient_wgsl",
    },
    Generated {
        name: "cast_mida_iso",
        by: "src/gpu/raycast.rs: modes_wgsl",
    },
    Generated {
        name: "fvr_slabs",
        by: "src/gpu/fvr.rs: slab_bindings_wgsl",
    },
    Generated {
        name: "fbp_projection",
        by: "src/gpu/fbp.rs: projection_wgsl",
    },
    Generated {
        name: "joseph_volume",
        by: "src/gpu/project.rs: volume_wgsl",
    },
    Generated {
        name: "d2vr_projections",
        by: "src/gpu/d2vr.rs: projections_wgsl",
    },
];

/// Why a set of modules does not resolve.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ImportError {
    /// `importer` imports a name that is neither registered nor generated.
    Unknown { module: String, importer: String },
    /// `importer` imports a generated module whose text was not passed.
    NotGenerated {
        module: String,
        importer: String,
        by: &'static str,
    },
    /// Text passed for a name that [`GENERATED`] does not declare.
    Undeclared { module: String },
    /// The chain of imports that leads back to its start.
    Cycle(Vec<String>),
    /// An `#import` line that does not name one module.
    Malformed { importer: String, line: String },
}

impl fmt::Display for ImportError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ImportError::Unknown { module, importer } => write!(
                f,
                "{importer} imports {module}, which is no registered WGSL module \
                 (src/gpu/shaders.rs: MODULES) and no generated one (GENERATED)"
            ),
            ImportError::NotGenerated {
                module,
                importer,
                by,
            } => write!(
                f,
                "{importer} imports the generated module {module} ({by}), but its text \
                 was not passed to resolve_with"
            ),
            ImportError::Undeclared { module } => write!(
                f,
                "generated text passed for {module}, which src/gpu/shaders.rs: GENERATED \
                 does not declare"
            ),
            ImportError::Cycle(chain) => write!(f, "import cycle: {}", chain.join(" → ")),
            ImportError::Malformed { importer, line } => write!(
                f,
                "{importer}: malformed import {line:?} (expected `#import NAME` on a line \
                 of its own)"
            ),
        }
    }
}

impl std::error::Error for ImportError {}

/// The registered module `name`, if there is one.
pub fn module(name: &str) -> Option<&'static Module> {
    MODULES.iter().find(|m| m.name == name)
}

/// The text of registered module `name` as written (imports not expanded).
///
/// # Panics
/// When no module has that name (a programmer error).
pub fn source(name: &str) -> &'static str {
    match module(name) {
        Some(m) => m.source,
        None => panic!("no registered WGSL module {name} (src/gpu/shaders.rs: MODULES)"),
    }
}

/// The complete WGSL of registered module `name`: its imports expanded.
///
/// # Panics
/// As [`resolve_with`].
pub fn resolve(name: &str) -> String {
    resolve_with(name, &[])
}

/// The complete WGSL of registered module `name`, with `generated` (name, text) as the
/// texts of the generated modules it imports.
///
/// # Panics
/// On any [`ImportError`]: the modules are fixed at compile time and the generated
/// texts are written by this crate, so an error is a programmer error.
pub fn resolve_with(name: &str, generated: &[(&str, &str)]) -> String {
    try_resolve(name, generated).unwrap_or_else(|e| panic!("WGSL module {name}: {e}"))
}

/// [`resolve_with`], returning the error instead of panicking.
pub fn try_resolve(name: &str, generated: &[(&str, &str)]) -> Result<String, ImportError> {
    if let Some((g, _)) = generated
        .iter()
        .find(|(g, _)| !GENERATED.iter().any(|d| d.name == *g))
    {
        return Err(ImportError::Undeclared {
            module: g.to_string(),
        });
    }
    let lookup = |wanted: &str, importer: &str| -> Result<String, ImportError> {
        if let Some(m) = module(wanted) {
            return Ok(m.source.to_string());
        }
        if let Some((_, text)) = generated.iter().find(|(g, _)| *g == wanted) {
            return Ok(text.to_string());
        }
        match GENERATED.iter().find(|d| d.name == wanted) {
            Some(d) => Err(ImportError::NotGenerated {
                module: wanted.to_string(),
                importer: importer.to_string(),
                by: d.by,
            }),
            None => Err(ImportError::Unknown {
                module: wanted.to_string(),
                importer: importer.to_string(),
            }),
        }
    };
    let root = lookup(name, "resolve")?;
    assemble(name, &root, &lookup)
}

/// Expands the imports of `text` (module `name`) through `lookup(name, importer)`.
fn assemble(
    name: &str,
    text: &str,
    lookup: &dyn Fn(&str, &str) -> Result<String, ImportError>,
) -> Result<String, ImportError> {
    let mut out = String::with_capacity(text.len() * 4);
    let mut included = HashSet::from([name.to_string()]);
    let mut stack = vec![name.to_string()];
    expand(text, lookup, &mut out, &mut included, &mut stack)?;
    Ok(out)
}

fn expand(
    text: &str,
    lookup: &dyn Fn(&str, &str) -> Result<String, ImportError>,
    out: &mut String,
    included: &mut HashSet<String>,
    stack: &mut Vec<String>,
) -> Result<(), ImportError> {
    let importer = stack.last().cloned().unwrap_or_default();
    for line in text.split_inclusive('\n') {
        let Some(rest) = line.trim_start().strip_prefix("#import") else {
            out.push_str(line);
            continue;
        };
        let target = rest.trim();
        let is_name = !target.is_empty()
            && rest.starts_with(char::is_whitespace)
            && target
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_');
        if !is_name {
            return Err(ImportError::Malformed {
                importer,
                line: line.trim_end().to_string(),
            });
        }
        if let Some(start) = stack.iter().position(|s| s == target) {
            let mut chain = stack[start..].to_vec();
            chain.push(target.to_string());
            return Err(ImportError::Cycle(chain));
        }
        if !included.insert(target.to_string()) {
            continue;
        }
        let body = lookup(target, &importer)?;
        out.push_str(&format!("// #import {target} ({importer})\n"));
        stack.push(target.to_string());
        expand(&body, lookup, out, included, stack)?;
        stack.pop();
        if !out.ends_with('\n') {
            out.push('\n');
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Resolves `root` among `modules` (name, text) alone.
    fn resolve_among(root: &str, modules: &[(&str, &str)]) -> Result<String, ImportError> {
        let lookup = |wanted: &str, importer: &str| {
            modules
                .iter()
                .find(|(n, _)| *n == wanted)
                .map(|(_, t)| t.to_string())
                .ok_or_else(|| ImportError::Unknown {
                    module: wanted.to_string(),
                    importer: importer.to_string(),
                })
        };
        let text = lookup(root, "test")?;
        assemble(root, &text, &lookup)
    }

    #[test]
    fn imports_expand_in_place_once() {
        let modules = [
            ("a", "#import b\nfn a() {}\n#import c\n"),
            ("b", "#import c\nfn b() {}\n"),
            ("c", "fn c() {}"),
        ];
        let out = resolve_among("a", &modules).unwrap();
        let fns: Vec<&str> = out.lines().filter(|l| l.starts_with("fn")).collect();
        assert_eq!(fns, ["fn c() {}", "fn b() {}", "fn a() {}"]);
        assert!(!out.lines().any(|l| l.starts_with("#import")));
    }

    #[test]
    fn cycles_are_named() {
        let modules = [
            ("a", "#import b\n"),
            ("b", "#import c\n"),
            ("c", "#import b\n"),
        ];
        assert_eq!(
            resolve_among("a", &modules),
            Err(ImportError::Cycle(vec!["b".into(), "c".into(), "b".into()]))
        );
        let own = [("a", "#import a\n")];
        assert_eq!(
            resolve_among("a", &own),
            Err(ImportError::Cycle(vec!["a".into(), "a".into()]))
        );
    }

    #[test]
    fn unknown_and_malformed_imports_are_named() {
        let modules = [("a", "#import b\n"), ("b", "#import nowhere\n")];
        assert_eq!(
            resolve_among("a", &modules),
            Err(ImportError::Unknown {
                module: "nowhere".into(),
                importer: "b".into()
            })
        );
        for bad in ["#import\n", "#import a b\n", "#importb\n", "#import <b>\n"] {
            let modules = [("a", bad), ("b", "")];
            assert!(
                matches!(
                    resolve_among("a", &modules),
                    Err(ImportError::Malformed { .. })
                ),
                "{bad:?}"
            );
        }
        // A commented-out import is a comment.
        assert!(resolve_among("a", &[("a", "// #import b\n")]).is_ok());
    }

    #[test]
    fn generated_modules_must_be_declared_and_passed() {
        let e = try_resolve("fvr_slice", &[]).unwrap_err();
        assert!(matches!(e, ImportError::NotGenerated { ref module, .. } if module == "fvr_slabs"));
        let e = try_resolve("probe", &[("no_such_slot", "")]).unwrap_err();
        assert_eq!(
            e,
            ImportError::Undeclared {
                module: "no_such_slot".into()
            }
        );
    }

    /// Every registered module resolves (each generated module stubbed by an empty
    /// text), names are unique, and no generated name shadows a registered one.
    #[test]
    fn every_registered_module_resolves() {
        let stubs: Vec<(&str, &str)> = GENERATED.iter().map(|g| (g.name, "")).collect();
        let mut names = HashSet::new();
        for m in MODULES {
            assert!(names.insert(m.name), "{} registered twice", m.name);
            let out = try_resolve(m.name, &stubs).unwrap_or_else(|e| panic!("{}: {e}", m.path));
            assert!(!out.contains("\n#import"), "{}", m.path);
        }
        for g in GENERATED {
            assert!(
                module(g.name).is_none(),
                "{} is registered and generated",
                g.name
            );
        }
    }

    /// The registry is the `shaders/` folder: every file there is registered under its
    /// stem, with its text.
    #[test]
    fn registry_matches_the_shaders_folder() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut on_disk = Vec::new();
        for dir in ["shaders", "shaders/shared"] {
            for e in std::fs::read_dir(root.join(dir)).unwrap() {
                let p = e.unwrap().path();
                if p.extension().is_some_and(|x| x == "wgsl") {
                    on_disk.push(format!(
                        "{dir}/{}",
                        p.file_name().unwrap().to_string_lossy()
                    ));
                }
            }
        }
        on_disk.sort();
        let mut registered: Vec<String> = MODULES.iter().map(|m| m.path.to_string()).collect();
        registered.sort();
        assert_eq!(registered, on_disk);
        for m in MODULES {
            let text = std::fs::read_to_string(root.join(m.path)).unwrap();
            assert_eq!(text, m.source, "{}", m.path);
            let stem = m.path.rsplit('/').next().unwrap().trim_end_matches(".wgsl");
            assert_eq!(stem, m.name, "{}", m.path);
        }
    }
}
