//! What a device lacks. `VOXLAB_GPU_WITHOUT` opens the device without some of the
//! optional features `FLOAT32_FILTERABLE`, `TEXTURE_FORMAT_16BIT_NORM` and
//! `TIMESTAMP_QUERY`, so that an adapter that has them all (lavapipe does) runs the
//! paths of one that lacks them: every hardware-filtering job refuses f32 textures, in
//! its run and in its `--dry-run`, writing nothing; the exact paths and the 16-bit
//! paths (D²VR's f16 projections, a u16 volume's compact texture) still run and write
//! the same bytes; 16-bit volumes fall back to f32 textures;
//! kernel times come from the clock. And a CPU driver's loop limit, refused by the run
//! and its `--dry-run` alike.

mod common;

use common::{s, scratch, stderr, voxlab_command};
use std::path::Path;
use std::process::Output;

/// `voxlab ARGS` with `VOXLAB_GPU_WITHOUT=without` (`None`: the variable unset).
fn without(without: Option<&str>, args: &[&str]) -> Output {
    let mut c = voxlab_command(args);
    match without {
        Some(w) => c.env("VOXLAB_GPU_WITHOUT", w),
        None => c.env_remove("VOXLAB_GPU_WITHOUT"),
    };
    c.env_remove("VOXLAB_GPU_F32_TEXTURES");
    c.output().expect("the voxlab binary runs")
}

/// `voxlab ARGS --out OUT` succeeds; returns the bytes it wrote.
fn writes(w: Option<&str>, args: &[&str], out: &Path) -> Vec<u8> {
    let o = without(w, &[args, &["--out", s(out)]].concat());
    assert!(o.status.success(), "{args:?} without {w:?}: {}", stderr(&o));
    std::fs::read(out).unwrap()
}

const NO_F32_FILTERING: Option<&str> = Some("FLOAT32_FILTERABLE");

#[test]
fn a_withheld_feature_is_reported_and_unknown_names_are_refused() {
    assert_eq!(
        voxlab::gpu::context::withheld_features(" float32_filterable, TIMESTAMP_QUERY ").unwrap(),
        wgpu::Features::FLOAT32_FILTERABLE | wgpu::Features::TIMESTAMP_QUERY
    );
    assert_eq!(
        voxlab::gpu::context::withheld_features("").unwrap(),
        wgpu::Features::empty()
    );
    let e = voxlab::gpu::context::withheld_features("FLOAT32_FILTERABLE SHADER_F16").unwrap_err();
    let text = e.to_string();
    assert!(
        text.contains("VOXLAB_GPU_WITHOUT") && text.contains("'SHADER_F16'"),
        "{text}"
    );
    assert!(text.contains("TEXTURE_FORMAT_16BIT_NORM"), "{text}");

    let Some(ctx) = common::gpu("a_withheld_feature_is_reported_and_unknown_names_are_refused")
    else {
        return;
    };
    let o = without(Some("bogus"), &["info", "--gpu"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("VOXLAB_GPU_WITHOUT: 'bogus'"),
        "{}",
        stderr(&o)
    );
    let o = without(
        Some("FLOAT32_FILTERABLE,TEXTURE_FORMAT_16BIT_NORM,TIMESTAMP_QUERY"),
        &["info", "--gpu"],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout).into_owned() + &stderr(&o);
    assert!(
        text.contains("FLOAT32_FILTERABLE no, TEXTURE_FORMAT_16BIT_NORM no, TIMESTAMP_QUERY no"),
        "{text}"
    );
    // A line for each feature the adapter has and the variable withheld.
    for (name, f) in voxlab::gpu::context::OPTIONAL_FEATURES {
        let line = format!("{name} withheld by VOXLAB_GPU_WITHOUT");
        assert_eq!(
            text.contains(&line),
            ctx.features.contains(f),
            "{line}:\n{text}"
        );
    }
}

/// The job of each hardware-filtering path, with `--hardware-filtering` and `--dry-run`
/// to be appended: FDK, Joseph's projection, D²VR and the ray caster.
fn hardware_jobs(dir: &Path) -> Vec<Vec<String>> {
    let ct = |name: &str| common::ct_data(name).display().to_string();
    let volume = dir.join("head.nrrd");
    let o = without(None, &["phantom", "shepp-logan:24", "--out", s(&volume)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let job = |a: &[&str]| a.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    vec![
        job(&[
            "reconstruct",
            &ct("rtk_joseph32.npy"),
            "--geometry",
            &ct("rtk_geometry.json"),
            "--size",
            "32",
            "--backend",
            "gpu",
        ]),
        job(&[
            "project",
            s(&volume),
            "--geometry",
            "cone",
            "--angles",
            "6",
            "--cols",
            "24",
            "--rows",
            "16",
            "--du",
            "8",
            "--method",
            "joseph",
            "--backend",
            "gpu",
        ]),
        job(&[
            "d2vr",
            "phantom:sphere",
            "--angles",
            "8",
            "--detector",
            "16",
            "--grid",
            "16",
            "--size",
            "16",
            "--mode",
            "mip",
            "--backend",
            "gpu",
        ]),
        job(&[
            "render",
            s(&volume),
            "--width",
            "16",
            "--height",
            "16",
            "--backend",
            "gpu",
        ]),
    ]
}

/// Without `FLOAT32_FILTERABLE` every hardware-filtering job refuses its f32 textures,
/// naming the feature, in its run and in its `--dry-run` (which used to print a plan the
/// run would refuse), and writes nothing; each job's exact path still runs.
#[test]
fn without_f32_filtering_every_hardware_job_and_its_dry_run_refuse() {
    if common::gpu("without_f32_filtering_every_hardware_job_and_its_dry_run_refuse").is_none() {
        return;
    }
    let dir = scratch("cli_features_refuse");
    for job in hardware_jobs(&dir) {
        let job: Vec<&str> = job.iter().map(String::as_str).collect();
        let never = dir.join(format!("{}-never.npy", job[0]));
        for dry in [&[][..], &["--dry-run"]] {
            let args = [&job[..], &["--hardware-filtering", "--out", s(&never)], dry].concat();
            let o = without(NO_F32_FILTERING, &args);
            let err = stderr(&o);
            assert!(!o.status.success(), "{args:?} ran:\n{err}");
            assert!(
                err.contains("R32Float textures needs the FLOAT32_FILTERABLE feature")
                    && err.contains("(VOXLAB_GPU_WITHOUT withholds it)"),
                "{args:?}:\n{err}"
            );
            assert!(!never.exists(), "{args:?} wrote {}", never.display());
            // The adapter's own features: the same command plans or runs.
            let o = without(None, &args);
            assert!(o.status.success(), "{args:?}: {}", stderr(&o));
            let _ = std::fs::remove_file(&never);
        }
        // The exact path reads storage buffers (the ray caster: unfiltered textures)
        // and writes the same bytes as on the whole adapter.
        let (a, b) = (dir.join("exact-a.npy"), dir.join("exact-b.npy"));
        assert!(
            writes(None, &job, &a) == writes(NO_F32_FILTERING, &job, &b),
            "{job:?}: the exact path differs without FLOAT32_FILTERABLE"
        );
    }
}

/// D²VR's 16-bit projections filter on every adapter: without `FLOAT32_FILTERABLE`
/// `--backend gpu-f16 --hardware-filtering` runs and writes the same bytes.
#[test]
fn without_f32_filtering_d2vr_filters_its_16_bit_projections() {
    if common::gpu("without_f32_filtering_d2vr_filters_its_16_bit_projections").is_none() {
        return;
    }
    let dir = scratch("cli_features_f16");
    let job = [
        "d2vr",
        "phantom:shepp-logan-modified",
        "--angles",
        "12",
        "--detector",
        "24",
        "--grid",
        "24",
        "--size",
        "24",
        "--mode",
        "mip",
        "--backend",
        "gpu-f16",
        "--hardware-filtering",
    ];
    let (a, b) = (dir.join("a.npy"), dir.join("b.npy"));
    let whole = writes(None, &job, &a);
    assert!(whole == writes(NO_F32_FILTERING, &job, &b));
    let o = without(
        NO_F32_FILTERING,
        &[&job[..], &["--dry-run", "--out", s(&a)]].concat(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
}

/// A u16 Shepp–Logan head of `n`³ voxels written into `dir`, and the arguments of its
/// hardware-filtered GPU render at `n` × `n` pixels.
fn u16_head_render(dir: &Path, n: usize) -> Vec<String> {
    let volume = dir.join("head-u16.nrrd");
    let spec = format!("shepp-logan:{n}");
    let args = [
        "phantom",
        &spec,
        "--type",
        "u16",
        "--scale",
        "60000",
        "--out",
        s(&volume),
    ];
    let o = without(None, &args);
    assert!(o.status.success(), "{}", stderr(&o));
    let n = n.to_string();
    [
        "render",
        s(&volume),
        "--width",
        &n,
        "--height",
        &n,
        "--backend",
        "gpu",
        "--hardware-filtering",
    ]
    .iter()
    .map(|a| a.to_string())
    .collect()
}

/// Without `FLOAT32_FILTERABLE` the texture unit still filters a u16 volume's compact
/// `R16Unorm` texture: every hardware-filtered frame that reads only it (DVR, MIP, X-ray,
/// the fast B-spline's trilinear fetches) is the image the whole adapter renders, byte
/// for byte; frames that read f32 textures (precomputed gradients, pre-classified
/// colours, B-spline coefficients, or the volume itself with `VOXLAB_GPU_F32_TEXTURES=1`
/// or without 16-bit textures) are refused, by the run and its `--dry-run`.
#[test]
fn without_f32_filtering_a_u16_volume_renders_from_its_compact_texture() {
    let Some(ctx) =
        common::gpu("without_f32_filtering_a_u16_volume_renders_from_its_compact_texture")
    else {
        return;
    };
    if !ctx
        .features
        .contains(wgpu::Features::TEXTURE_FORMAT_16BIT_NORM)
    {
        eprintln!("this adapter has no 16-bit textures: every u16 volume reads f32 ones");
        return;
    }
    let dir = scratch("cli_features_compact");
    let job = u16_head_render(&dir, 24);
    let job: Vec<&str> = job.iter().map(String::as_str).collect();
    let (a, b) = (dir.join("a.npy"), dir.join("b.npy"));
    for extra in [
        &[][..],
        &["--mode", "mip"],
        &["--mode", "xray"],
        &["--filter", "cubic-bspline-fast"],
    ] {
        let args = [&job[..], extra].concat();
        let whole = writes(None, &args, &a);
        assert!(whole == writes(NO_F32_FILTERING, &args, &b), "{extra:?}");
    }
    let never = dir.join("never.npy");
    for (extra, env) in [
        (&["--precompute-gradients"][..], None),
        (&["--classification", "pre"], None),
        (&["--filter", "cubic-bspline-fast-interp"], None),
        (&[], Some(("VOXLAB_GPU_F32_TEXTURES", "1"))),
        (
            &[],
            Some((
                "VOXLAB_GPU_WITHOUT",
                "FLOAT32_FILTERABLE,TEXTURE_FORMAT_16BIT_NORM",
            )),
        ),
    ] {
        for dry in [&[][..], &["--dry-run"]] {
            let args = [&job[..], extra, dry, &["--out", s(&never)]].concat();
            let mut c = voxlab_command(&args);
            c.env("VOXLAB_GPU_WITHOUT", "FLOAT32_FILTERABLE")
                .env_remove("VOXLAB_GPU_F32_TEXTURES");
            if let Some((k, v)) = env {
                c.env(k, v);
            }
            let o = c.output().unwrap();
            let err = stderr(&o);
            assert!(!o.status.success(), "{args:?} {env:?} ran");
            assert!(
                err.contains("needs the FLOAT32_FILTERABLE feature")
                    && err.contains("filters only an 8- or 16-bit volume's compact texture"),
                "{args:?} {env:?}: {err}"
            );
            assert!(!never.exists());
        }
    }
}

/// The device bytes of a `--dry-run` plan ("device: 261.0 KiB at once, …").
fn device_bytes(plan: &str) -> f64 {
    let line = plan.lines().find(|l| l.starts_with("device:")).expect(plan);
    let words: Vec<&str> = line.split_whitespace().collect();
    let unit = match words[2] {
        "bytes" => 1.0,
        "KiB" => 1024.0,
        "MiB" => 1024.0 * 1024.0,
        u => panic!("unit {u} in {line}"),
    };
    words[1].parse::<f64>().unwrap() * unit
}

/// Without `TEXTURE_FORMAT_16BIT_NORM` a u16 volume's hardware-filtered render reads
/// f32 textures: the image is the one `VOXLAB_GPU_F32_TEXTURES=1` renders, byte for
/// byte, and the plan holds 2 bytes more a voxel on the device.
#[test]
fn without_16_bit_textures_a_u16_volume_renders_from_f32_textures() {
    let Some(ctx) = common::gpu("without_16_bit_textures_a_u16_volume_renders_from_f32_textures")
    else {
        return;
    };
    let dir = scratch("cli_features_u16");
    let job = u16_head_render(&dir, 32);
    let job: Vec<&str> = job.iter().map(String::as_str).collect();
    let no_norm = Some("TEXTURE_FORMAT_16BIT_NORM");
    let withheld = writes(no_norm, &job, &dir.join("a.npy"));
    let f32_textures = {
        let out = dir.join("b.npy");
        let mut c = voxlab_command(&[&job[..], &["--out", s(&out)]].concat());
        c.env("VOXLAB_GPU_F32_TEXTURES", "1")
            .env_remove("VOXLAB_GPU_WITHOUT");
        let o = c.output().unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        std::fs::read(out).unwrap()
    };
    assert!(withheld == f32_textures);

    if !ctx
        .features
        .contains(wgpu::Features::TEXTURE_FORMAT_16BIT_NORM)
    {
        return;
    }
    let plan = |w: Option<&str>| {
        let o = without(
            w,
            &[&job[..], &["--dry-run", "--out", s(&dir.join("c.npy"))]].concat(),
        );
        assert!(o.status.success(), "{}", stderr(&o));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let (compact, f32s) = (plan(None), plan(no_norm));
    assert!(
        f32s.contains("TEXTURE_FORMAT_16BIT_NORM withheld"),
        "{f32s}"
    );
    // 32³ voxels at 2 bytes (R16Unorm) or 4 (R32Float); the plan prints 4 digits.
    let more = device_bytes(&f32s) - device_bytes(&compact);
    assert!(
        (more - 2.0 * 32f64.powi(3)).abs() < 0.1 * 1024.0,
        "{more} more bytes:\n{compact}\n{f32s}"
    );
}

/// Without `TIMESTAMP_QUERY` the GPU FFT's kernel time comes from the clock, and the
/// JSON says so; with it (where the adapter has it), from timestamp queries.
#[test]
fn without_timestamps_kernel_times_come_from_the_clock() {
    let Some(ctx) = common::gpu("without_timestamps_kernel_times_come_from_the_clock") else {
        return;
    };
    let dir = scratch("cli_features_timestamps");
    let stamps = |w: Option<&str>| {
        let json = dir.join("fft.json");
        let o = without(
            w,
            &[
                "fft",
                "64x64",
                "--backend",
                "gpu",
                "--runs",
                "1",
                "--json",
                s(&json),
            ],
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        let cases = v["cases"].as_array().unwrap().clone();
        assert_eq!(cases.len(), 2);
        cases
            .iter()
            .map(|c| c["kernel_from_timestamps"].as_bool().unwrap())
            .collect::<Vec<_>>()
    };
    assert_eq!(stamps(Some("TIMESTAMP_QUERY")), [false, false]);
    let has = ctx.features.contains(wgpu::Features::TIMESTAMP_QUERY);
    assert_eq!(stamps(None), [has, has]);
}

/// A CPU driver (lavapipe) stops every loop of an invocation after 65,535 iterations:
/// a ray longer than that is refused naming `step`, by the run and by its `--dry-run`,
/// writing nothing; a real GPU has no such limit.
#[test]
fn rays_past_a_cpu_drivers_loop_limit_are_refused_by_the_run_and_the_dry_run() {
    let Some(ctx) =
        common::gpu("rays_past_a_cpu_drivers_loop_limit_are_refused_by_the_run_and_the_dry_run")
    else {
        return;
    };
    let dir = scratch("cli_features_loop");
    let out = dir.join("never.npy");
    // A 64³ volume's diagonal (110.9 voxels) at 0.001 voxels a step: 110,865 steps.
    let job = [
        "render",
        "phantom:sphere:64",
        "--step",
        "0.001",
        "--width",
        "8",
        "--height",
        "8",
        "--backend",
        "gpu",
        "--out",
        s(&out),
    ];
    for dry in [&[][..], &["--dry-run"]] {
        let o = without(None, &[&job[..], dry].concat());
        if ctx.summary.is_cpu() {
            assert!(!o.status.success(), "{dry:?} ran");
            let err = stderr(&o);
            assert!(
                err.contains("invalid step: up to 110865 steps per ray exceed the 65535 loop"),
                "{err}"
            );
            assert!(!out.exists());
        } else {
            assert!(o.status.success(), "{}", stderr(&o));
        }
    }
}

/// `voxlab compare` checks the GPU's render before the oracle's: a frame the GPU
/// refuses (here hardware filtering of an f32 volume without `FLOAT32_FILTERABLE`) is
/// refused at once, with the same message as `--dry-run`, writing nothing; it used to be
/// refused after the CPU oracle had rendered the frame (1.1e10 samples here: 64³ voxels
/// at 0.01 voxel through 1024² rays, minutes on two cores; the bound below is the hang
/// guard). Without the flag the plans print, one per render.
#[test]
fn compare_refuses_the_gpus_frame_before_the_oracle_renders() {
    let Some(ctx) = common::gpu("compare_refuses_the_gpus_frame_before_the_oracle_renders") else {
        return;
    };
    let dir = scratch("cli_features_compare");
    let never = dir.join("never");
    let args = [
        "compare",
        "phantom:sphere:64",
        "--width",
        "1024",
        "--height",
        "1024",
        "--step",
        "0.01",
        "--out-dir",
        s(&never),
    ];
    let hw = [&args[..], &["--hardware-filtering"]].concat();
    let run = |args: &[&str], w: Option<&str>| {
        let mut c = voxlab_command(args);
        if let Some(w) = w {
            c.env("VOXLAB_GPU_WITHOUT", w);
        }
        let child = c
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        common::wait_bounded(child, std::time::Duration::from_secs(60), &args.join(" "))
    };
    let refused = run(&hw, NO_F32_FILTERING);
    let dry = run(&[&hw[..], &["--dry-run"]].concat(), NO_F32_FILTERING);
    for o in [&refused, &dry] {
        assert_eq!(o.status.code(), Some(1), "{}", stderr(o));
        assert!(
            stderr(o).contains("R32Float textures needs the FLOAT32_FILTERABLE feature"),
            "{}",
            stderr(o)
        );
    }
    assert_eq!(stderr(&refused), stderr(&dry));
    assert!(!never.exists(), "compare wrote {}", never.display());
    // The plans: the oracle's (host only), then the GPU's on this adapter.
    let o = run(&[&args[..], &["--dry-run"]].concat(), None);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    let oracle = text.find("dry run: render dvr on cpu (f64 oracle)");
    let gpu = text.find("device: ");
    assert!(oracle.is_some() && gpu.is_some() && oracle < gpu, "{text}");
    assert!(text.contains(&ctx.summary.name), "{text}");
    assert!(!never.exists(), "the dry run wrote {}", never.display());
}
