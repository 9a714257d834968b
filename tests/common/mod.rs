//! Helpers shared by the integration tests.
#![allow(dead_code)]

use glam::{DMat4, DQuat, DVec3};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use voxlab::gpu::GpuContext;
use voxlab::{AnyVolume, Error, Volume};

// ---------------------------------------------------------------------------------
// Files and folders
// ---------------------------------------------------------------------------------

/// The repository root.
pub fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A fixture of `tests/data/ct/` (the peers' CT data: RTK, ASTRA, scikit-image).
pub fn ct_data(name: &str) -> PathBuf {
    root().join("tests/data/ct").join(name)
}

/// A fresh, empty directory for one test: `<test file>/<name>` under Cargo's
/// temporary folder for integration tests, so that tests running in parallel (within
/// one file or across files) never share one.
pub fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(env!("CARGO_CRATE_NAME"))
        .join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

pub fn gzip(data: &[u8]) -> Vec<u8> {
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    gz.write_all(data).unwrap();
    gz.finish().unwrap()
}

// ---------------------------------------------------------------------------------
// Volumes and reader errors
// ---------------------------------------------------------------------------------

/// A rotated, anisotropic, translated voxel-to-world affine.
pub fn oblique_affine() -> DMat4 {
    let rotation = DQuat::from_axis_angle(DVec3::new(1.0, 2.0, 3.0).normalize(), 0.7);
    DMat4::from_scale_rotation_translation(
        DVec3::new(0.5, 1.25, 2.0),
        rotation,
        DVec3::new(-12.5, 3.25, 100.1),
    )
}

/// One 5×4×3 volume of each voxel type (u8, u16, i16, f32, in that order) with
/// `affine`, holding extreme and special values.
pub fn sample_volumes(affine: DMat4) -> Vec<AnyVolume> {
    let dims = [5, 4, 3];
    let n = 60;
    let mut u8s: Vec<u8> = (0..n).map(|i| (i * 37 % 256) as u8).collect();
    u8s[n - 1] = u8::MAX;
    let mut u16s: Vec<u16> = (0..n).map(|i| (i * 1097 % 65536) as u16).collect();
    u16s[n - 1] = u16::MAX;
    let mut i16s: Vec<i16> = (0..n).map(|i| (i as i16 - 30) * 1000).collect();
    i16s[0] = i16::MIN;
    i16s[1] = i16::MAX;
    let mut f32s: Vec<f32> = (0..n).map(|i| (i as f32 - 20.5) * 0.1).collect();
    f32s[..6].copy_from_slice(&[
        f32::NAN,
        f32::INFINITY,
        -0.0,
        1e-40,
        f32::MAX,
        -f32::MIN_POSITIVE,
    ]);
    vec![
        Volume::with_affine(dims, affine, u8s).unwrap().into(),
        Volume::with_affine(dims, affine, u16s).unwrap().into(),
        Volume::with_affine(dims, affine, i16s).unwrap().into(),
        Volume::with_affine(dims, affine, f32s).unwrap().into(),
    ]
}

/// The voxel values as exact bit patterns (so NaN equals NaN and -0 differs from 0).
pub fn bits(v: &AnyVolume) -> Vec<u64> {
    match v {
        AnyVolume::F32(v) => v.data().iter().map(|x| x.to_bits() as u64).collect(),
        other => other.values_f64().iter().map(|x| x.to_bits()).collect(),
    }
}

/// The field of a format error (fails the test on any other error).
pub fn format_field(e: &Error) -> &str {
    match e {
        Error::Format { field, .. } => field,
        other => panic!("expected a format error, got {other:?}"),
    }
}

/// Asserts a format error about `field` whose message mentions `words`.
#[track_caller]
pub fn assert_format(r: voxlab::Result<impl std::fmt::Debug>, field: &str, words: &str) {
    let e = r.expect_err("expected an error");
    assert_eq!(format_field(&e), field, "{e}");
    assert!(e.to_string().contains(words), "'{words}' not in: {e}");
}

/// The message of a format error (fails the test on a volume or any other error).
pub fn format_err(r: voxlab::Result<AnyVolume>) -> String {
    match r {
        Err(e @ Error::Format { .. }) => e.to_string(),
        Err(e) => panic!("expected a format error, got {e}"),
        Ok(v) => panic!("expected an error, got a volume {:?}", v.dims()),
    }
}

// ---------------------------------------------------------------------------------
// The command line
// ---------------------------------------------------------------------------------

/// The `voxlab` binary with `args`, in a clean environment: no voxel limit from the
/// caller's environment, and a runtime directory that exists.
pub fn voxlab_command(args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_voxlab"));
    c.args(args)
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .env_remove("VOXLAB_MAX_VOXELS");
    c
}

/// Runs `voxlab` with `args` (see [`voxlab_command`]) under the planner's binding limit
/// `binding` (`VOXLAB_GPU_MAX_BINDING`; `None`: the adapter's own).
pub fn voxlab_with_binding(args: &[&str], binding: Option<&str>) -> Output {
    let mut c = voxlab_command(args);
    match binding {
        Some(b) => c.env("VOXLAB_GPU_MAX_BINDING", b),
        None => c.env_remove("VOXLAB_GPU_MAX_BINDING"),
    };
    c.output().expect("the voxlab binary runs")
}

/// The checks of every "a split GPU job writes the unsplit file" command-line test:
/// `voxlab ARGS --out DIR/whole.npy` under the adapter's own binding limit and
/// `voxlab ARGS --out DIR/split.npy` under `binding` (`VOXLAB_GPU_MAX_BINDING`) both
/// succeed and write the same bytes, and the split run says every line of `says` on
/// stderr. Returns the unsplit run's stderr (for what it must not say).
pub fn split_writes_the_unsplit_file(
    dir: &Path,
    args: &[&str],
    binding: &str,
    says: &[&str],
) -> String {
    let run = |name: &str, binding: Option<&str>| {
        let out = dir.join(name);
        let with_out = [args, &["--out", s(&out)]].concat();
        let o = voxlab_with_binding(&with_out, binding);
        assert!(o.status.success(), "{args:?}: {}", stderr(&o));
        (std::fs::read(&out).unwrap(), stderr(&o))
    };
    let (whole, quiet) = run("whole.npy", None);
    let (split, said) = run("split.npy", Some(binding));
    for line in says {
        assert!(said.contains(line), "{args:?}: no '{line}' in:\n{said}");
    }
    assert!(
        whole == split,
        "{args:?}: the split file differs from the unsplit one"
    );
    quiet
}

/// Waits for `child` at most `limit`, killing it (and failing) when it hangs.
pub fn wait_bounded(
    mut child: std::process::Child,
    limit: std::time::Duration,
    what: &str,
) -> std::process::Output {
    let t = std::time::Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if t.elapsed() > limit {
            let _ = child.kill();
            panic!("{what} hung for {limit:?}");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// Runs `voxlab` with `args` (see [`voxlab_command`]).
pub fn voxlab(args: &[&str]) -> Output {
    voxlab_command(args)
        .output()
        .expect("the voxlab binary runs")
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

// ---------------------------------------------------------------------------------
// Deterministic pseudo-random numbers (no RNG crate; a failure reproduces)
// ---------------------------------------------------------------------------------

/// xorshift64*.
pub struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    /// Uniform in `0..n` (0 when `n` is 0).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }

    /// Uniform in `[0, 1)`, from the top 53 bits.
    pub fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Plain xorshift64 (shifts 13, 7, 17).
pub struct XorShift(pub u64);

impl XorShift {
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

// ---------------------------------------------------------------------------------
// GPU
// ---------------------------------------------------------------------------------

/// Opens the GPU, or decides what a missing adapter means: a failure, unless
/// `VOXLAB_ALLOW_NO_GPU=1`, in which case the skip is announced loudly (straight to the
/// terminal, past the test harness's output capture) and recorded in
/// `target/gpu-tests-skipped.txt`, which the test script reports at the end.
pub fn gpu(test: &str) -> Option<&'static GpuContext> {
    match GpuContext::shared() {
        Ok(ctx) => Some(ctx),
        Err(e) => {
            if std::env::var("VOXLAB_ALLOW_NO_GPU").as_deref() == Ok("1") {
                let msg = format!(
                    "\n*** GPU TEST SKIPPED: {test}: {e}\n*** (VOXLAB_ALLOW_NO_GPU=1 allows this; the GPU code was NOT tested)\n"
                );
                let _ = std::io::stderr().write_all(msg.as_bytes());
                let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("target");
                let _ = std::fs::create_dir_all(&dir);
                if let Ok(mut f) = std::fs::OpenOptions::new()
                    .create(true)
                    .append(true)
                    .open(dir.join("gpu-tests-skipped.txt"))
                {
                    let _ = writeln!(f, "{test}");
                }
                None
            } else {
                panic!(
                    "no GPU adapter for {test}: {e}\n\
                     Install a Vulkan driver (the README's test command does this when run as root), \
                     or set VOXLAB_ALLOW_NO_GPU=1 to skip the GPU tests."
                )
            }
        }
    }
}

/// Where a failing parity check leaves its evidence: `target/parity/<case>/`, with
/// every character of `case` but letters, digits, `-`, `_` and `.` made `_`.
pub fn parity_dir(case: &str) -> PathBuf {
    let name: String = case
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("target/parity")
        .join(name)
}

/// Asserts parity of `port` against `oracle`, writing `target/parity/<case>/` on failure.
pub fn assert_parity(
    case: &str,
    oracle: &voxlab::frame::Frame,
    port: &voxlab::frame::Frame,
    tol: voxlab::metrics::Tolerance,
) -> voxlab::metrics::ErrorStats {
    let dir = parity_dir(case);
    let report = voxlab::metrics::check_parity(case, oracle, port, tol, Some(&dir)).unwrap();
    assert!(report.passed, "{}", report.message);
    report.stats
}

/// Asserts parity of a real array `port` against `oracle`, both of dimensions `dims`
/// (x fastest; `&[len]` for a plain slice), writing `target/parity/<case>/` on failure.
pub fn assert_parity_array<A, B>(
    case: &str,
    dims: &[usize],
    oracle: &[A],
    port: &[B],
    tol: voxlab::metrics::Tolerance,
) -> voxlab::metrics::ErrorStats
where
    A: Copy + Into<f64>,
    B: Copy + Into<f64>,
{
    let dir = parity_dir(case);
    let report =
        voxlab::metrics::check_parity_array(case, dims, oracle, port, tol, Some(&dir)).unwrap();
    assert!(report.passed, "{}", report.message);
    report.stats
}

/// Asserts parity of a complex array `port` against `oracle`, both of dimensions `dims` (x
/// fastest), each
/// element compared by the modulus of its difference; writes `target/parity/<case>/`
/// on failure.
pub fn assert_parity_complex<A, B>(
    case: &str,
    dims: &[usize],
    oracle: &[rustfft::num_complex::Complex<A>],
    port: &[rustfft::num_complex::Complex<B>],
    tol: voxlab::metrics::Tolerance,
) -> voxlab::metrics::ErrorStats
where
    A: Copy + Into<f64>,
    B: Copy + Into<f64>,
{
    let dir = parity_dir(case);
    let report =
        voxlab::metrics::check_parity_complex(case, dims, oracle, port, tol, Some(&dir)).unwrap();
    assert!(report.passed, "{}", report.message);
    report.stats
}

/// Parses and validates a complete WGSL module with naga (no device), panicking with
/// `what` and naga's message when it does not.
pub fn validate_wgsl(src: &str, what: &str) {
    use wgpu::naga;
    let module = naga::front::wgsl::parse_str(src)
        .unwrap_or_else(|e| panic!("{what}: {}", e.emit_to_string(src)));
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    )
    .validate(&module)
    .unwrap_or_else(|e| panic!("{what}: {}", e.emit_to_string(src)));
}

/// The size and member offsets of WGSL struct `name` as naga lays it out, for the
/// layout tests that hold a `#[repr(C)]` parameter struct against its WGSL copy.
pub fn wgsl_struct_layout(src: &str, name: &str) -> (u32, Vec<(String, u32)>) {
    use wgpu::naga;
    let module = naga::front::wgsl::parse_str(src).expect("the shared WGSL parses");
    for (_, ty) in module.types.iter() {
        if ty.name.as_deref() == Some(name) {
            if let naga::TypeInner::Struct { members, span } = &ty.inner {
                return (
                    *span,
                    members
                        .iter()
                        .map(|m| (m.name.clone().unwrap_or_default(), m.offset))
                        .collect(),
                );
            }
        }
    }
    panic!("struct {name} not found in the WGSL");
}

// ---------------------------------------------------------------------------------
// CT
// ---------------------------------------------------------------------------------

/// The largest spread (max − min of its four taps) of the bilinear cells `cs × rs` of
/// a `cols × rows` detector view (`value(i)`, column fastest; zero outside the
/// detector; cell `(c, r)` has the taps `c ..= c + 1`, `r ..= r + 1`): the steepest a
/// bilinear value may change anywhere in those cells, which bounds what a texture
/// unit's rounded weights (and a coordinate rounded into a neighbouring cell) can move
/// it by, per unit of weight.
pub fn cells_spread(
    (cols, rows): (usize, usize),
    cs: std::ops::RangeInclusive<i64>,
    rs: std::ops::RangeInclusive<i64>,
    value: impl Fn(usize) -> f64,
) -> f64 {
    let at = |c: i64, r: i64| {
        if c >= 0 && r >= 0 && c < cols as i64 && r < rows as i64 {
            value(r as usize * cols + c as usize)
        } else {
            0.0
        }
    };
    let mut widest = 0f64;
    for r in rs {
        for c in cs.clone() {
            let t = [at(c, r), at(c + 1, r), at(c, r + 1), at(c + 1, r + 1)];
            let hi = t.iter().fold(f64::NEG_INFINITY, |m, &v| m.max(v));
            let lo = t.iter().fold(f64::INFINITY, |m, &v| m.min(v));
            widest = widest.max(hi - lo);
        }
    }
    widest
}

/// RTK's view axes at gantry angle `a_deg`: `(e_u, e_v, e_w)` (written out here, not
/// taken from voxlab, so that per-view test geometries are built independently).
pub fn rtk_axes(a_deg: f64) -> (DVec3, DVec3, DVec3) {
    let (s, c) = a_deg.to_radians().sin_cos();
    (DVec3::new(c, 0.0, -s), DVec3::Y, DVec3::new(s, 0.0, c))
}

/// A flat detector of `cols × rows` pixels of `du × dv` mm centred on `centre`, its
/// columns along `eu` and rows along `ev`, turned by `turn`: the
/// [`voxlab::ct::ViewVectors`] with `source`.
pub fn detector_view(
    source: DVec3,
    centre: DVec3,
    (eu, ev): (DVec3, DVec3),
    turn: DQuat,
    (cols, rows, du, dv): (usize, usize, f64, f64),
) -> voxlab::ct::ViewVectors {
    let (u, v) = (turn * eu * du, turn * ev * dv);
    voxlab::ct::ViewVectors {
        source,
        pixel00: centre - u * ((cols as f64 - 1.0) / 2.0) - v * ((rows as f64 - 1.0) / 2.0),
        u,
        v,
    }
}

/// A circular cone-beam orbit (RTK's frame, `n` views over 360°) whose flat detector
/// is turned by `in_plane_deg` about the central ray and then tilted by
/// `out_of_plane_deg` about its own column axis, and moved by `offset` (mm along
/// `e_u`, `e_v`) — the ASTRA `cone_vec` of a misaligned scanner.
#[allow(clippy::too_many_arguments)]
pub fn cone_tilted(
    n: usize,
    sid: f64,
    sdd: f64,
    size: (usize, usize, f64, f64),
    in_plane_deg: f64,
    out_of_plane_deg: f64,
    offset: (f64, f64),
) -> voxlab::ct::Geometry {
    let views = (0..n)
        .map(|k| {
            let (eu, ev, ew) = rtk_axes(k as f64 * 360.0 / n as f64);
            let turn = DQuat::from_axis_angle(eu, out_of_plane_deg.to_radians())
                * DQuat::from_axis_angle(ew, in_plane_deg.to_radians());
            let centre = ew * (sid - sdd) + eu * offset.0 + ev * offset.1;
            detector_view(ew * sid, centre, (eu, ev), turn, size)
        })
        .collect();
    voxlab::ct::Geometry::from_views(voxlab::ct::ViewGeometry {
        parallel: false,
        cols: size.0,
        rows: size.1,
        views,
    })
    .unwrap()
}

/// A wobbling cone-beam orbit: per view its own SID (`sid ± 5 %`), SDD (`sdd ± 4 %`),
/// a source that rises and falls along the rotation axis (±6 mm, a helix that turns
/// back) with the detector following it, and a detector offset of `(2.5, −1.5)` mm.
pub fn cone_wobble(
    n: usize,
    sid: f64,
    sdd: f64,
    size: (usize, usize, f64, f64),
) -> voxlab::ct::Geometry {
    let views = (0..n)
        .map(|k| {
            let a = k as f64 * 360.0 / n as f64;
            let (eu, ev, ew) = rtk_axes(a);
            let t = a.to_radians();
            let (sid_k, sdd_k) = (
                sid * (1.0 + 0.05 * (3.0 * t).sin()),
                sdd * (1.0 + 0.04 * (2.0 * t).cos()),
            );
            let h = 6.0 * t.sin();
            let source = ew * sid_k + ev * h;
            let centre = source - ew * sdd_k + eu * 2.5 - ev * 1.5;
            detector_view(source, centre, (eu, ev), DQuat::IDENTITY, size)
        })
        .collect();
    voxlab::ct::Geometry::from_views(voxlab::ct::ViewGeometry {
        parallel: false,
        cols: size.0,
        rows: size.1,
        views,
    })
    .unwrap()
}

/// ASTRA's `parallel3d_vec` with an oblique detector: `n` views over 180°, rays along
/// `−e_w`, the detector turned by `turn_deg` about its row axis (the rays meet it
/// obliquely, its columns foreshortened by `cos turn`), `dist` mm behind the
/// isocentre and offset by `(1.7, 0.6)` mm.
pub fn parallel_vec(
    n: usize,
    size: (usize, usize, f64, f64),
    turn_deg: f64,
    dist: f64,
) -> voxlab::ct::Geometry {
    let views = (0..n)
        .map(|k| {
            let (eu, ev, ew) = rtk_axes(k as f64 * 180.0 / n as f64);
            let turn = DQuat::from_axis_angle(ev, turn_deg.to_radians());
            let centre = -ew * dist + eu * 1.7 + ev * 0.6;
            detector_view(-ew * 3.0, centre, (eu, ev), turn, size)
        })
        .collect();
    voxlab::ct::Geometry::from_views(voxlab::ct::ViewGeometry {
        parallel: true,
        cols: size.0,
        rows: size.1,
        views,
    })
    .unwrap()
}

/// The per-view CT cases appended to [`ct_cases`]: a cone orbit with a turned and
/// tilted, offset detector; a wobbling, helix-like cone orbit with per-view SID and
/// SDD; a `parallel3d_vec` stack with an oblique detector.
pub fn per_view_cases(
    parallel_angles: usize,
    cone_angles: usize,
) -> Vec<(&'static str, voxlab::ct::Geometry, voxlab::cpu::fbp::Grid)> {
    use voxlab::cpu::fbp::rtk_grid;
    vec![
        (
            "cone-vec-tilted",
            cone_tilted(
                cone_angles,
                300.0,
                450.0,
                (40, 30, 1.0, 1.0),
                4.0,
                6.0,
                (3.2, -2.1),
            ),
            rtk_grid([21, 15, 18], [1.1, 1.3, 0.9]),
        ),
        (
            "cone-vec-wobble",
            cone_wobble(cone_angles, 300.0, 450.0, (40, 30, 1.0, 1.0)),
            rtk_grid([20, 14, 17], [1.1, 1.3, 0.9]),
        ),
        (
            "parallel3d-vec",
            parallel_vec(parallel_angles, (36, 7, 1.5, 1.25), 12.0, 40.0),
            rtk_grid([24, 5, 22], [1.4, 1.25, 1.4]),
        ),
    ]
}

/// Small CT cases shared by the CPU and GPU reconstruction tests: (name, geometry,
/// reconstruction grid) for a scikit-image parallel beam, a 3-D parallel stack and an
/// RTK cone beam with `parallel_angles` / `cone_angles` views, then the geometries
/// given view by view of [`per_view_cases`].
pub fn ct_cases(
    parallel_angles: usize,
    cone_angles: usize,
) -> Vec<(&'static str, voxlab::ct::Geometry, voxlab::cpu::fbp::Grid)> {
    use voxlab::cpu::fbp::{parallel_stack_grid, rtk_grid, skimage_grid};
    use voxlab::ct::Geometry;
    let par =
        Geometry::parallel_skimage(41, Geometry::even_angles(parallel_angles, 180.0)).unwrap();
    let stack =
        Geometry::parallel_stack(36, 5, 1.5, 1.25, Geometry::even_angles(17, 180.0)).unwrap();
    let cone = Geometry::cone_rtk(
        300.0,
        450.0,
        40,
        30,
        1.0,
        1.0,
        Geometry::even_angles(cone_angles, 360.0),
    )
    .unwrap();
    vec![
        ("parallel", par, skimage_grid(41)),
        ("stack", stack.clone(), parallel_stack_grid(30, &stack)),
        ("cone", cone, rtk_grid([21, 15, 18], [1.1, 1.3, 0.9])),
    ]
    .into_iter()
    .chain(per_view_cases(parallel_angles, cone_angles))
    .collect()
}

/// The cases of Joseph's matched pair (tests/iterative.rs, tests/gpu_iterative.rs):
/// the shared CT cases ([`ct_cases`]), plus an oblique grid in a cone beam with an
/// offset detector and irregular angles (no view lines up with a grid axis).
pub fn joseph_pair_cases() -> Vec<(String, voxlab::ct::Geometry, [usize; 3], DMat4)> {
    use glam::{DQuat, DVec3};
    let mut v: Vec<_> = ct_cases(13, 9)
        .into_iter()
        .map(|(n, g, grid)| (n.to_string(), g, grid.dims, grid.affine))
        .collect();
    let mut cone = voxlab::ct::Geometry::cone_rtk(
        250.0,
        400.0,
        23,
        17,
        1.3,
        1.1,
        vec![3.0, 47.5, 101.0, 188.8, 270.1, 333.3],
    )
    .unwrap();
    cone.cu += 2.7;
    cone.cv -= 1.9;
    let q = DQuat::from_axis_angle(DVec3::new(1.0, 2.0, 3.0).normalize(), 0.6);
    let affine = DMat4::from_quat(q)
        * DMat4::from_scale(DVec3::new(1.2, 0.9, 1.1))
        * DMat4::from_translation(DVec3::new(-7.5, -6.0, -6.5));
    v.push(("oblique-cone".into(), cone, [16, 13, 14], affine));
    v
}

/// `max |port − oracle| / max |oracle|` ([`voxlab::metrics::ErrorStats::max_abs_rel`]).
pub fn max_rel(port: &[f64], oracle: &[f64]) -> f64 {
    voxlab::metrics::error_stats(oracle, port, f64::INFINITY).max_abs_rel
}

// ---------------------------------------------------------------------------------
// Scenes
// ---------------------------------------------------------------------------------

/// The ray-casting tests' orbit camera: 33° azimuth, 21° elevation, 540 mm from the
/// centre of a 256 mm scene (the phantoms' world box).
pub fn orbit_camera(
    projection: voxlab::camera::Projection,
    width: usize,
    height: usize,
) -> voxlab::camera::Camera {
    voxlab::camera::Camera::orbit(
        DVec3::ZERO,
        [256.0; 3],
        voxlab::camera::Orbit {
            azimuth_deg: 33.0,
            elevation_deg: 21.0,
            distance_mm: Some(540.0),
        },
        projection,
        width,
        height,
    )
    .unwrap()
}

/// The modified Shepp–Logan phantom on an `n × (n+3) × (n−2)` grid (odd shapes catch
/// axis mix-ups).
pub fn odd_phantom(n: usize) -> AnyVolume {
    voxlab::phantom::Phantom::shepp_logan_modified()
        .sample([n, n + 3, n - 2])
        .unwrap()
        .into()
}

/// Opaque only above 0.6: the modified Shepp–Logan's skull (1.0), translucent
/// (α = 0.25 per voxel) so rays cross it twice; air, brain (0.2), ventricles (0) and
/// the small ellipsoids (0.3) are transparent, so empty-space skipping has much to skip.
pub fn sparse_tf() -> voxlab::transfer::TransferFunction {
    let p = |value: f64, rgba: [f64; 4]| voxlab::transfer::ControlPoint { value, rgba };
    voxlab::transfer::TransferFunction {
        name: "sparse".into(),
        domain: [0.0, 1.0],
        points: vec![
            p(0.0, [0.0; 4]),
            p(0.6, [1.0, 0.8, 0.3, 0.0]),
            p(1.0, [0.9, 0.9, 0.9, 0.25]),
        ],
        window: Default::default(),
        interpolation: Default::default(),
        faux_shading: None,
    }
}

/// Joseph's projection of a constant grid (every voxel `value`) through `g`, against
/// `value × chord`: Joseph is exact when a ray enters and leaves through the two faces
/// across its driving axis while its other coordinates stay between the first and
/// last voxel centres. Returns the rays that qualify and the worst relative error.
pub fn constant_grid_chords(
    grid: &voxlab::cpu::project::Grid<f64>,
    value: f64,
    g: &voxlab::ct::Geometry,
) -> (usize, f64) {
    use voxlab::cpu::project::{pixel_ray, project_volume, JosephView, ProjectOptions};
    let (dims, affine) = (grid.dims, grid.affine);
    let p = project_volume(grid, g, &ProjectOptions::default()).unwrap();
    let (mut checked, mut worst) = (0, 0.0f64);
    for k in 0..g.n_angles() {
        let v = JosephView::<f64>::new(g, k, affine);
        for row in 0..g.rows {
            for col in 0..g.cols {
                // The ray in index space.
                let (o, d, t0) = pixel_ray(&v, col as f64, row as f64);
                let (o, d) = (DVec3::from_array(o), DVec3::from_array(d));
                let m = d.abs().max_position();
                let t = |s: f64| (s - o[m]) / d[m];
                let inside = [-0.5, dims[m] as f64 - 0.5].iter().all(|&s| {
                    let x = o + d * t(s);
                    (0..3).all(|a| a == m || (x[a] >= 0.0 && x[a] <= dims[a] as f64 - 1.0))
                        && t(s) > t0
                });
                if !inside {
                    continue;
                }
                let hi = DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64) - 0.5;
                let (a, b) = voxlab::real::slab_interval(o, d, DVec3::splat(-0.5), hi).unwrap();
                let want = value * (b - a);
                worst = worst.max((p.view(k)[row * g.cols + col] - want).abs() / want);
                checked += 1;
            }
        }
    }
    (checked, worst)
}

/// (min, max, sum, weighted sum Σ v[i]·(i mod 251 + 1)) of a volume's values in
/// x-fastest order, as `tests/data/dicom_reference.py` and the DICOM fixture scripts
/// compute them for the peers' decodings.
pub fn volume_stats(v: &AnyVolume) -> (f64, f64, f64, f64) {
    let vals = v.values_f64();
    let (mut lo, mut hi, mut sum, mut wsum) = (f64::MAX, f64::MIN, 0.0, 0.0);
    for (i, &x) in vals.iter().enumerate() {
        lo = lo.min(x);
        hi = hi.max(x);
        sum += x;
        wsum += x * ((i % 251) + 1) as f64;
    }
    (lo, hi, sum, wsum)
}

/// Projections shaped for `g` with values uniform in [−3, 7), from `Rng(seed)` in
/// storage order, in f32.
pub fn random_projections_f32(g: &voxlab::ct::Geometry, seed: u64) -> voxlab::ct::Projections<f32> {
    let mut rng = Rng(seed);
    let n = g.n_angles() * g.rows * g.cols;
    let data = (0..n).map(|_| (rng.unit() * 10.0 - 3.0) as f32).collect();
    voxlab::ct::Projections::new(g.n_angles(), g.rows, g.cols, data).unwrap()
}

// ---------------------------------------------------------------------------------
// Ranks as threads (the distributed jobs without MPI)
// ---------------------------------------------------------------------------------

/// Ranks as threads of this process: every collective meets at a barrier.
pub struct Threads<'a> {
    rank: usize,
    shared: &'a ThreadsShared,
}

pub struct ThreadsShared {
    size: usize,
    barrier: std::sync::Barrier,
    slots: std::sync::Mutex<Vec<Vec<f64>>>,
    bytes: std::sync::Mutex<Vec<u8>>,
}

impl voxlab::jobs::distributed::Comm for Threads<'_> {
    fn rank(&self) -> usize {
        self.rank
    }
    fn size(&self) -> usize {
        self.shared.size
    }
    fn all_gather(&self, values: &[f64]) -> Vec<f64> {
        self.shared.slots.lock().unwrap()[self.rank] = values.to_vec();
        self.shared.barrier.wait();
        let all = self.shared.slots.lock().unwrap().concat();
        self.shared.barrier.wait();
        all
    }
    fn broadcast(&self, root: usize, bytes: &mut Vec<u8>) {
        if self.rank == root {
            *self.shared.bytes.lock().unwrap() = bytes.clone();
        }
        self.shared.barrier.wait();
        *bytes = self.shared.bytes.lock().unwrap().clone();
        self.shared.barrier.wait();
    }
}

/// Runs `job(comm)` on `ranks` threads, one [`Threads`] rank each; the results in rank
/// order.
pub fn on_thread_ranks<T: Send>(ranks: usize, job: impl Fn(&Threads) -> T + Sync) -> Vec<T> {
    let shared = ThreadsShared {
        size: ranks,
        barrier: std::sync::Barrier::new(ranks),
        slots: std::sync::Mutex::new(vec![Vec::new(); ranks]),
        bytes: std::sync::Mutex::new(Vec::new()),
    };
    std::thread::scope(|sc| {
        let handles: Vec<_> = (0..ranks)
            .map(|rank| {
                let comm = Threads {
                    rank,
                    shared: &shared,
                };
                let job = &job;
                sc.spawn(move || job(&comm))
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    })
}

/// `mpirun --oversubscribe -n ranks voxlab ARGS…` (OpenMPI), killed after two minutes
/// (a hang is a failure).
pub fn mpirun(ranks: usize, args: &[&str]) -> Output {
    mpirun_env(ranks, args, &[])
}

/// [`mpirun`] with environment variables for the ranks.
pub fn mpirun_env(ranks: usize, args: &[&str], env: &[(&str, &str)]) -> Output {
    use std::time::{Duration, Instant};
    let mut c = Command::new("mpirun");
    c.args(["--oversubscribe", "-n", &ranks.to_string()])
        .envs(env.iter().copied())
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .arg(env!("CARGO_BIN_EXE_voxlab"))
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped());
    let mut child = c.spawn().expect("mpirun (OpenMPI) on the PATH");
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > Duration::from_secs(120) {
            let _ = child.kill();
            panic!("mpirun -n {ranks} {args:?} still runs after 120 s");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    child.wait_with_output().unwrap()
}

/// The distributed renders' test volume: smooth and not cubic (37×29×23, odd on every
/// axis, so bricks differ in size), placed by an oblique, anisotropic affine, written
/// to `dir/volume.nrrd` as raw float32 (read brick by brick).
pub fn brick_test_volume(dir: &Path) -> PathBuf {
    use voxlab::io::nrrd::{write_nrrd, NrrdWriteOptions};
    let dims = [37, 29, 23];
    let rot = DMat4::from_quat(DQuat::from_euler(glam::EulerRot::ZXY, 0.3, -0.2, 0.15));
    let affine = DMat4::from_translation(DVec3::new(-12.0, 4.0, 7.5))
        * rot
        * DMat4::from_scale(DVec3::new(0.8, 1.0, 1.3));
    let mut data = Vec::with_capacity(dims.iter().product());
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let (x, y, z) = (
                    i as f64 / 36.0 - 0.5,
                    j as f64 / 28.0 - 0.5,
                    k as f64 / 22.0 - 0.5,
                );
                let r2 = x * x + 1.3 * y * y + 0.8 * z * z;
                let v = 1000.0 * (-6.0 * r2).exp() + 250.0 * (9.0 * x + 4.0 * y * z).sin();
                data.push(v as f32);
            }
        }
    }
    let vol = AnyVolume::F32(Volume::with_affine(dims, affine, data).unwrap());
    let path = dir.join("volume.nrrd");
    let raw = NrrdWriteOptions {
        gzip: false,
        detached: false,
    };
    write_nrrd(&path, &vol, raw).unwrap();
    path
}
