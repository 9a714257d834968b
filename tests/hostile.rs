//! Hostile input and interrupted writes: endless streams, FIFOs, lying lengths,
//! detached pairs from different writes, signals during a write, outputs that cannot be
//! written, impossible CT geometry, JSON that means something else, terminal escapes,
//! and data files outside a header's folder (docs/io.md, "What is guaranteed"). The
//! broken files themselves are in the regression corpus (tests/corpus/broken/).

mod common;

use common::{s, scratch, stderr, voxlab, voxlab_command, wait_bounded};
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};
use voxlab::io::nrrd::{write_nrrd, NrrdWriteOptions};
use voxlab::{AnyVolume, Error, Volume};

fn volume(seed: u8) -> AnyVolume {
    let data: Vec<u8> = (0..4 * 5 * 6)
        .map(|i| (i as u8).wrapping_mul(7).wrapping_add(seed))
        .collect();
    Volume::new([4, 5, 6], [1.0, 1.0, 1.0], data)
        .unwrap()
        .into()
}

fn spawn(args: &[&str]) -> Child {
    voxlab_command(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

// 1. Unbounded reads -------------------------------------------------------------

#[test]
fn devices_and_endless_streams_are_refused_at_once() {
    let dir = scratch("devices");
    let link = dir.join("mesh.obj");
    std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
    let out = dir.join("x.png");
    let sphere = "phantom:sphere:8";
    for args in [
        vec!["render", sphere, "--tf", "/dev/zero"],
        vec!["render", sphere, "--settings", "/dev/zero"],
        vec!["render", sphere, "--tf2d", "/dev/zero"],
        vec!["render", sphere, "--clip-mesh", s(&link)],
        vec!["info", "/dev/zero"],
    ] {
        let mut a = args.clone();
        a.extend(["--out", s(&out)]);
        if args[0] == "info" {
            a.truncate(2);
        }
        let o = wait_bounded(spawn(&a), Duration::from_secs(60), &args.join(" "));
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {e}");
        assert!(e.contains("is a character device"), "{args:?}: {e}");
        assert!(e.contains("regular files only"), "{args:?}: {e}");
    }
    assert!(!out.exists());
}

#[test]
fn small_files_are_read_only_up_to_their_limit() {
    let dir = scratch("limits");
    let big = dir.join("big.json");
    // A sparse file: its size is known without writing (or reading) 100 MB.
    std::fs::File::create(&big)
        .unwrap()
        .set_len(100 << 20)
        .unwrap();
    match voxlab::source::read_limited(&big, "--settings", 1 << 20) {
        Err(Error::TooLarge { what, message }) => {
            assert_eq!(what, "--settings");
            assert!(message.contains("104857600 bytes"), "{message}");
            assert!(message.contains("at most 1048576"), "{message}");
        }
        other => panic!("{other:?}"),
    }
    let e =
        voxlab::json::read_file::<voxlab::settings::RenderSettings>(&big, "settings").unwrap_err();
    assert!(matches!(e, Error::TooLarge { .. }), "{e}");
}

#[test]
fn ascii_data_is_read_only_as_far_as_its_values_need() {
    let dir = scratch("ascii");
    // Four values, then 20 MB of digits that no value can need: the reader takes at
    // most 64 bytes per value (plus 64 KiB), so the tail is never read.
    let mut text =
        b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 1\nencoding: ascii\n\n1 2 3 4\n".to_vec();
    text.extend(std::iter::repeat_n(b'7', 20 << 20));
    let p = dir.join("a.nrrd");
    std::fs::write(&p, &text).unwrap();
    let v = voxlab::io::read_volume(&p).unwrap();
    assert_eq!(v.values_f64(), vec![1.0, 2.0, 3.0, 4.0]);
    // Values beyond the limit are not found: "too short", not a read of the whole file.
    let mut spaced =
        b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 1 1\nencoding: ascii\n\n1".to_vec();
    spaced.extend(std::iter::repeat_n(b' ', 1 << 20));
    spaced.extend(b"2\n");
    std::fs::write(&p, &spaced).unwrap();
    common::assert_format(
        voxlab::io::read_volume(&p),
        "data",
        "expected 2 values, found 1",
    );
}

// 3. Detached pairs from different writes -----------------------------------------

#[test]
fn a_header_refuses_the_data_file_of_another_write() {
    let dir = scratch("pairs");
    let hdr = dir.join("pair.nhdr");
    let opts = NrrdWriteOptions {
        gzip: true,
        detached: true,
    };
    write_nrrd(&hdr, &volume(1), opts).unwrap();
    assert_eq!(voxlab::io::read_volume(&hdr).unwrap(), volume(1));
    let old_header = std::fs::read(&hdr).unwrap();
    // A second write of the same shape, interrupted after its data file: the old
    // header is left beside the new data (what a kill between the two renames leaves).
    write_nrrd(&hdr, &volume(2), opts).unwrap();
    std::fs::write(&hdr, &old_header).unwrap();
    let e = voxlab::io::read_volume(&hdr).unwrap_err().to_string();
    assert!(e.contains("pair.nhdr: data file:"), "{e}");
    assert!(e.contains("does not belong to this header"), "{e}");
    // A data file of the right length but other bytes: the hash tells.
    let raw = NrrdWriteOptions {
        gzip: false,
        detached: true,
    };
    let hdr2 = dir.join("raw.nhdr");
    write_nrrd(&hdr2, &volume(3), raw).unwrap();
    let old = std::fs::read(&hdr2).unwrap();
    write_nrrd(&hdr2, &volume(4), raw).unwrap();
    std::fs::write(&hdr2, &old).unwrap();
    let e = voxlab::io::read_volume(&hdr2).unwrap_err().to_string();
    assert!(e.contains("FNV-1a hash"), "{e}");
    // The current pair reads.
    write_nrrd(&hdr2, &volume(5), raw).unwrap();
    assert_eq!(voxlab::io::read_volume(&hdr2).unwrap(), volume(5));
}

#[test]
fn a_data_file_longer_than_its_header_says_is_refused() {
    let dir = scratch("longer");
    let hdr = dir.join("h.nhdr");
    std::fs::write(
        &hdr,
        "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: h.raw\n",
    )
    .unwrap();
    std::fs::write(dir.join("h.raw"), [0u8; 9]).unwrap();
    common::assert_format(voxlab::io::read_volume(&hdr), "data", "1 more than");
    std::fs::write(dir.join("h.raw"), [0u8; 7]).unwrap();
    common::assert_format(
        voxlab::io::read_volume(&hdr),
        "data",
        "expected 8 bytes, found 7",
    );
    std::fs::write(dir.join("h.raw"), [0u8; 8]).unwrap();
    assert_eq!(voxlab::io::read_volume(&hdr).unwrap().dims(), [2, 2, 2]);
}

// 4. Signals during a write ---------------------------------------------------------

/// Starts a long write, waits for its temporary file, sends `sig`, and checks that the
/// process died of it and left nothing behind.
fn interrupted_write_leaves_nothing(sig: libc::c_int, name: &str) {
    // The signal must land while the temporary file exists; on a loaded machine the
    // write can finish between seeing that file and the kill. Such a try (the child
    // exits 0 with its output complete) proves nothing either way: try again.
    for attempt in 0..5 {
        let dir = scratch(&format!("{name}-{attempt}"));
        let out = dir.join("big.nii.gz");
        let child = spawn(&["phantom", "shepp-logan:256", "--out", s(&out)]);
        let pid = child.id() as libc::pid_t;
        let t = Instant::now();
        loop {
            if names(&dir).iter().any(|n| n.contains(".tmp-")) {
                break;
            }
            assert!(
                t.elapsed() < Duration::from_secs(120),
                "no temporary file appeared: {:?}",
                names(&dir)
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        // SAFETY: signalling the child this test started.
        assert_eq!(unsafe { libc::kill(pid, sig) }, 0);
        let o = wait_bounded(child, Duration::from_secs(60), "the interrupted write");
        use std::os::unix::process::ExitStatusExt;
        if o.status.success() && names(&dir) == vec!["big.nii.gz".to_string()] {
            eprintln!("{name}: the write finished before the signal (try {attempt}); again");
            continue;
        }
        assert_eq!(o.status.signal(), Some(sig), "{}", stderr(&o));
        assert_eq!(names(&dir), Vec::<String>::new(), "left behind");
        return;
    }
    panic!("{name}: the write finished before the signal in every try");
}

#[test]
fn sigterm_during_a_write_removes_its_temporary_file() {
    interrupted_write_leaves_nothing(libc::SIGTERM, "sigterm");
}

#[test]
fn sigint_during_a_write_removes_its_temporary_file() {
    interrupted_write_leaves_nothing(libc::SIGINT, "sigint");
}

#[test]
fn sighup_during_a_write_removes_its_temporary_file() {
    interrupted_write_leaves_nothing(libc::SIGHUP, "sighup");
}

// 5. Outputs checked before the work ------------------------------------------------

#[test]
fn every_output_is_checked_before_the_work() {
    let dir = scratch("outputs");
    let npy = dir.join("p.npy");
    let o = voxlab(&[
        "project",
        "phantom:shepp-logan",
        "--angles",
        "4",
        "--cols",
        "16",
        "--out",
        s(&npy),
        "--png",
        "/nonexistent/x.png",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("--png"), "{}", stderr(&o));
    // A folder no file can be created in (even by root): /proc.
    let png = dir.join("x.png");
    let o = voxlab(&[
        "render",
        "phantom:sphere:8",
        "--out",
        s(&png),
        "--samples",
        "/proc/voxlab-samples.png",
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("cannot write into the folder /proc"),
        "{}",
        stderr(&o)
    );
    let o = voxlab(&["compare", "phantom:sphere:8", "--out-dir", "/proc/version"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("--out-dir: /proc/version is a file, not a folder"),
        "{}",
        stderr(&o)
    );
    let o = voxlab(&["phantom", "sphere:8", "--out", "/proc/v.nrrd"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert_eq!(names(&dir), Vec::<String>::new(), "something was written");
}

// 6. Pipes and FIFOs ----------------------------------------------------------------

#[test]
fn a_fifo_or_a_pipe_is_refused_without_hanging() {
    let dir = scratch("fifo");
    let fifo = dir.join("f.nrrd");
    let c = std::ffi::CString::new(s(&fifo)).unwrap();
    // SAFETY: a plain libc call on a NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    // Nobody writes to the FIFO: opening it for reading would block forever.
    let o = wait_bounded(
        spawn(&["info", s(&fifo)]),
        Duration::from_secs(30),
        "info FIFO",
    );
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("is a pipe or FIFO"), "{}", stderr(&o));
    // A pipe as from `voxlab info <(cat x.nrrd)`.
    let mut child = voxlab_command(&["info", "/dev/stdin"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdin.take());
    let o = wait_bounded(child, Duration::from_secs(30), "info pipe");
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("is a pipe or FIFO"), "{}", stderr(&o));
    match voxlab::io::read_volume(&fifo) {
        Err(Error::Invalid { message, .. }) => assert!(message.contains("f.nrrd"), "{message}"),
        other => panic!("{other:?}"),
    }
}

// 7. Terminal escapes ---------------------------------------------------------------

#[test]
fn no_control_character_of_a_file_reaches_the_terminal() {
    let p = common::root().join("tests/corpus/broken/nrrd-terminal-escapes.nrrd");
    let o = voxlab(&["info", s(&p)]);
    assert_eq!(o.status.code(), Some(1));
    let bytes = &o.stderr;
    assert!(
        !bytes.iter().any(|&b| b < 0x20 && b != b'\n'),
        "{:?}",
        String::from_utf8_lossy(bytes)
    );
    assert!(
        stderr(&o).contains(r"'\u{1b}[2J\u{1b}]0;pwned\u{7}\u{0}'"),
        "{}",
        stderr(&o)
    );
}

// 8. Impossible CT geometry ---------------------------------------------------------

#[test]
fn a_source_inside_the_object_or_a_denormal_distance_is_refused() {
    let dir = scratch("geometry");
    let out = dir.join("p.npy");
    let run = |sid: &str| {
        voxlab(&[
            "project",
            "phantom:shepp-logan",
            "--geometry",
            "cone",
            "--sid",
            sid,
            "--cols",
            "8",
            "--rows",
            "8",
            "--angles",
            "2",
            "--out",
            s(&out),
        ])
    };
    // The phantom's 256 mm box holds a circle of radius 128 mm about the axis.
    let o = run("10");
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("lies inside the object at every view"),
        "{}",
        stderr(&o)
    );
    assert!(stderr(&o).contains("radius 128.0000 mm"), "{}", stderr(&o));
    let o = run("1e-300");
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("SID = 1e-300 mm is outside"),
        "{}",
        stderr(&o)
    );
    // Between the inscribed circle and the corners: projected, with a warning.
    let o = run("150");
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("enters the corners"), "{}", stderr(&o));
    // Reconstructing those projections onto a grid of 800 mm puts the source (150 mm
    // from the axis) inside the grid.
    let rec = dir.join("r.npy");
    let o = voxlab(&[
        "reconstruct",
        s(&out),
        "--size",
        "8",
        "--spacing",
        "100",
        "--out",
        s(&rec),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains(
            "invalid geometry sid: the source at SID = 150 mm lies inside the reconstruction grid"
        ),
        "{}",
        stderr(&o)
    );
    assert!(!rec.exists());
    let g = voxlab::io::projections::geometry_from_json(
        r#"{"beam": "cone", "sid": 1e-320, "sdd": 1500, "cols": 4, "rows": 4, "du": 1, "dv": 1, "angles_deg": [0]}"#,
        Path::new("g.json"),
    );
    common::assert_format(g, "geometry", "SID = 1e-320 mm is outside");
}

// 9. JSON that silently means something else ------------------------------------------

#[test]
fn json_with_unknown_fields_or_the_wrong_shape_is_refused() {
    let dir = scratch("json");
    let out = dir.join("x.npy");
    let render = |settings: &Path| {
        voxlab(&[
            "render",
            "phantom:sphere:8",
            "--mode",
            "xray",
            "--settings",
            s(settings),
            "--out",
            s(&out),
        ])
    };
    let typo = dir.join("typo.json");
    std::fs::write(&typo, r#"{"stpe": 0.01}"#).unwrap();
    let o = render(&typo);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(
        e.contains("typo.json: render settings JSON: unknown field `stpe`"),
        "{e}"
    );
    assert!(e.contains("did you mean `step`?"), "{e}");
    let array = dir.join("array.json");
    std::fs::write(&array, "[]").unwrap();
    let e = stderr(&render(&array));
    assert!(e.contains("the top level must be a JSON object"), "{e}");
    // A byte-order mark is accepted, and the file means what it says.
    let plain = dir.join("plain.json");
    std::fs::write(&plain, r#"{"mode": "xray", "step": 0.25}"#).unwrap();
    let bom = dir.join("bom.json");
    std::fs::write(&bom, "\u{feff}{\"mode\": \"xray\", \"step\": 0.25}").unwrap();
    assert!(render(&plain).status.success());
    let a = std::fs::read(&out).unwrap();
    assert!(render(&bom).status.success());
    assert_eq!(std::fs::read(&out).unwrap(), a);
    // Transfer functions: an unknown field in a control point.
    let tf = dir.join("tf.json");
    std::fs::write(
        &tf,
        r#"{"domain": [0, 1], "points": [{"value": 0, "rgbaa": [0, 0, 0, 0]}]}"#,
    )
    .unwrap();
    let e = voxlab::transfer::TransferFunction::load(&tf)
        .unwrap_err()
        .to_string();
    assert!(e.contains("unknown field `rgbaa`"), "{e}");
    assert!(e.contains("did you mean `rgba`?"), "{e}");
    // A 2D transfer function where a 1D one is read: said so.
    let tf2d = common::root().join("data/tf/ct-bone-2d.json");
    let e = voxlab::transfer::TransferFunction::load(&tf2d)
        .unwrap_err()
        .to_string();
    assert!(e.contains("this is a 2D transfer function"), "{e}");
    assert!(e.contains("--tf2d"), "{e}");
    assert!(voxlab::transfer2d::TransferFunction2D::load(&tf2d).is_ok());
}

// 10. Misleading messages -----------------------------------------------------------

#[test]
fn messages_name_the_option_or_field_that_is_wrong() {
    let dir = scratch("messages");
    let out = dir.join("x.png");
    for fov in ["-1", "0", "nan", "inf", "180"] {
        let o = voxlab(&[
            "render",
            "phantom:sphere:8",
            &format!("--fov={fov}"),
            "--out",
            s(&out),
        ]);
        assert_eq!(o.status.code(), Some(1));
        assert!(
            stderr(&o).contains("invalid --fov:"),
            "{fov}: {}",
            stderr(&o)
        );
    }
    let o = voxlab(&[
        "render",
        "phantom:sphere:8",
        "--tf",
        "bonee",
        "--out",
        s(&out),
    ]);
    let e = stderr(&o);
    assert!(e.contains("'bonee' is neither a preset nor a file"), "{e}");
    assert!(e.contains("grayscale"), "{e}");
    let raw = dir.join("v.raw");
    std::fs::write(&raw, [0u8; 8]).unwrap();
    let o = voxlab(&[
        "info",
        s(&raw),
        "--raw-dims",
        "2,2,2",
        "--raw-spacing",
        "1e-320,1,1",
    ]);
    let e = stderr(&o);
    assert!(e.contains("v.raw: spacing:"), "{e}");
    assert!(!out.exists());
}

// 11. Data files outside the header's folder ------------------------------------------

#[test]
fn data_files_can_be_confined_to_the_headers_folder() {
    let dir = scratch("confine");
    let inner = dir.join("inner");
    std::fs::create_dir_all(&inner).unwrap();
    std::fs::write(dir.join("secret.raw"), [9u8; 8]).unwrap();
    let hdr = inner.join("h.nhdr");
    std::fs::write(
        &hdr,
        "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: ../secret.raw\n",
    )
    .unwrap();
    // The format allows it, and by default it is read.
    assert_eq!(
        voxlab::io::read_volume(&hdr).unwrap().values_f64(),
        vec![9.0; 8]
    );
    let confined = voxlab::io::ReadOptions {
        confine_data_files: true,
        ..Default::default()
    };
    common::assert_format(
        voxlab::io::read_volume_with(&hdr, &confined),
        "data file",
        "lies outside the header's folder",
    );
    let o = voxlab(&["info", s(&hdr), "--confine-data-files"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("'../secret.raw' lies outside"),
        "{}",
        stderr(&o)
    );
    // An absolute path, and a link that leads out, too.
    let abs: PathBuf = dir.join("secret.raw");
    std::fs::write(
        &hdr,
        format!(
            "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: {}\n",
            abs.display()
        ),
    )
    .unwrap();
    assert!(voxlab::io::read_volume_with(&hdr, &confined).is_err());
    std::os::unix::fs::symlink(&abs, inner.join("link.raw")).unwrap();
    std::fs::write(
        &hdr,
        "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: link.raw\n",
    )
    .unwrap();
    assert!(voxlab::io::read_volume_with(&hdr, &confined).is_err());
    // Inside the folder it reads.
    std::fs::write(inner.join("own.raw"), [3u8; 8]).unwrap();
    std::fs::write(
        &hdr,
        "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: own.raw\n",
    )
    .unwrap();
    assert_eq!(
        voxlab::io::read_volume_with(&hdr, &confined)
            .unwrap()
            .values_f64(),
        vec![3.0; 8]
    );
}

/// The work limits of every ray march: at most `MAX_SAMPLES_PER_RAY` samples on a ray
/// and `MAX_SAMPLES_PER_FRAME` in a frame, at the boundary exactly.
#[test]
fn the_ray_work_limits_hold_at_their_boundaries() {
    use voxlab::camera::{Camera, Orbit, Projection};
    use voxlab::settings::{check_ray_work, MAX_SAMPLES_PER_FRAME, MAX_SAMPLES_PER_RAY};
    assert_eq!((MAX_SAMPLES_PER_RAY, MAX_SAMPLES_PER_FRAME), (1e7, 1e12));
    let camera = |w, h| {
        let ortho = Projection::Orthographic {
            width_mm: 1.0,
            height_mm: 1.0,
        };
        Camera::orbit(glam::DVec3::ZERO, [1.0; 3], Orbit::default(), ortho, w, h).unwrap()
    };
    // 1000² = 10⁶ rays; 101 × 9901 = 10⁶ + 1.
    assert!(check_ray_work("render", 0.5, 1e7, &camera(1, 1)).is_ok());
    assert!(check_ray_work("render", 0.5, 1e6, &camera(1000, 1000)).is_ok());
    for (per_ray, (w, h), says) in [
        (
            1e7 + 1.0,
            (1, 1),
            "step 0.5 gives up to 10000001 samples per ray",
        ),
        (
            1e6,
            (101, 9901),
            "step 0.5 gives up to 1.0e12 samples per frame (1000000 per ray, 1000001 rays",
        ),
        (f64::NAN, (1, 1), "samples per ray"),
    ] {
        match check_ray_work("render", 0.5, per_ray, &camera(w, h)) {
            Err(e @ Error::TooLarge { .. }) => {
                assert!(e.to_string().contains(says), "{per_ray} × {w}×{h}: {e}")
            }
            other => panic!("{per_ray} × {w}×{h}: {other:?}"),
        }
    }
    assert_eq!(voxlab::volume::diagonal([3, 4, 12]), 13.0);
}

/// A frame of too many samples (a tiny step on a large image) is refused by every ray
/// caster of the library, CPU and GPU, before it converts or uploads anything: without
/// the limit each of these frames runs for hours (16³ voxels, a diagonal of 27.7, at
/// 1e-4 voxel through 2048² rays is 1.2e12 samples; the adaptive caster's smallest step
/// is 1e-3, through 8192² rays 1.9e12). On a GPU nothing else bounded it: a CPU driver's
/// loop limit refuses such rays, a GPU's does not exist.
#[test]
fn every_ray_caster_refuses_a_frame_of_too_many_samples() {
    use glam::DVec3;
    use voxlab::camera::{Camera, Orbit, Projection};
    use voxlab::cpu::adaptive::AdaptiveSettings;
    use voxlab::multi::MultiVolume;
    use voxlab::phantom::Phantom;
    use voxlab::settings::RenderSettings;
    use voxlab::transfer::TransferFunction;
    let volume: AnyVolume = Phantom::shepp_logan_modified()
        .sample([16; 3])
        .unwrap()
        .into();
    let tf = TransferFunction::preset("phantom").unwrap();
    let camera = |side| {
        Camera::orbit(
            DVec3::ZERO,
            [16.0; 3],
            Orbit::default(),
            Projection::Perspective { fov_y_deg: 30.0 },
            side,
            side,
        )
        .unwrap()
    };
    let (big, bigger) = (camera(2048), camera(8192));
    let settings = RenderSettings {
        step: 1e-4,
        ..RenderSettings::default()
    };
    let adaptive = AdaptiveSettings {
        step: 1e-3,
        t_max: 8.0,
        ..AdaptiveSettings::default()
    };
    let vols = [MultiVolume::new(volume.clone(), tf.clone())];
    let none = |_: usize, _: usize| {};
    let refused = |what: &str, r: voxlab::Result<()>| match r {
        Err(e @ Error::TooLarge { .. }) => {
            assert!(e.to_string().contains("samples per frame"), "{what}: {e}")
        }
        other => panic!("{what}: {other:?}"),
    };
    refused(
        "cpu render",
        voxlab::cpu::raycast::render::<f32>(&volume, &tf, &big, &settings, &none).map(|_| ()),
    );
    refused(
        "cpu adaptive",
        voxlab::cpu::adaptive::render::<f32>(&volume, &tf, &bigger, &adaptive).map(|_| ()),
    );
    refused(
        "cpu multi",
        voxlab::cpu::multi::render::<f32>(&vols, &big, &settings, &none).map(|_| ()),
    );
    let Some(ctx) = common::gpu("every_ray_caster_refuses_a_frame_of_too_many_samples") else {
        return;
    };
    refused(
        "gpu render",
        voxlab::gpu::raycast::render(ctx, &volume, &tf, &big, &settings, &none).map(|_| ()),
    );
    refused(
        "gpu adaptive",
        voxlab::gpu::adaptive::render(ctx, &volume, &tf, &bigger, &adaptive).map(|_| ()),
    );
    refused(
        "gpu multi",
        voxlab::gpu::multi::render(ctx, &vols, &big, &settings, &none).map(|_| ()),
    );
}
