//! `voxlab adaptive` end to end on a small phantom: the table, the JSON and the images.

mod common;

use common::{s, scratch, voxlab};

#[test]
fn adaptive_writes_table_json_and_images() {
    let dir = scratch("cli_adaptive");
    let out = voxlab(&[
        "adaptive",
        "phantom:shepp-logan-modified:32",
        "--out",
        s(&dir),
        "--size",
        "32",
        "--runs",
        "1",
        "--backend",
        "cpu",
        "--shift",
        "0.05",
    ]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    for f in [
        "table.md",
        "table.json",
        "regular.png",
        "direct.png",
        "adaptive.png",
        "samples-regular.png",
        "samples-direct.png",
        "samples-adaptive.png",
    ] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("table.json")).unwrap()).unwrap();
    let rows = json["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 3);
    let spp = |i: usize| rows[i]["samples_per_pixel"].as_f64().unwrap();
    // Regular, direct, adaptive: neither takes more samples than regular (at 32³ the
    // importance volume's 10-voxel max filter reaches nearly everywhere).
    assert!(spp(1) <= spp(0) && spp(2) <= spp(0), "{rows:?}");
    // PSNR is null in JSON when the images are identical (infinite).
    let psnr = rows[2]["psnr_db"].as_f64().unwrap_or(f64::INFINITY);
    assert!(psnr > 40.0, "{rows:?}");
    let md = std::fs::read_to_string(dir.join("table.md")).unwrap();
    assert!(md.contains("| adaptive |"), "{md}");
}

/// `adaptive --dry-run` loads the volume, checks the three renders and prints the plan:
/// on the f64 oracle the volume and the importance volume (8 + 3 × 8 bytes a voxel:
/// 1 MiB at 32³), one frame's RGBA image and counts (44 bytes a pixel) and the two
/// frames kept (40 bytes a pixel): 1,556,480 bytes at 64². Nothing is written.
#[test]
fn adaptive_dry_run_plans_and_writes_nothing() {
    let dir = scratch("cli_adaptive_dry").join("never");
    let out = voxlab(&[
        "adaptive",
        "phantom:sphere:32",
        "--size",
        "64",
        "--backend",
        "cpu",
        "--out",
        s(&dir),
        "--dry-run",
    ]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("dry run: adaptive (regular, direct and adaptive sampling) on cpu")
            && text.contains("host:   1.5 MiB at the peak")
            && text.contains("table.md and table.json"),
        "{text}"
    );
    assert!(!dir.exists(), "the dry run made {}", dir.display());
}

#[test]
fn adaptive_refuses_bad_options() {
    let dir = scratch("cli_adaptive_bad");
    let out = voxlab(&["adaptive", "--out", s(&dir), "--t-max", "0.1"]);
    assert!(!out.status.success());
    assert!(
        common::stderr(&out).contains("t-max"),
        "{}",
        common::stderr(&out)
    );
}

#[test]
fn render_takes_a_sampling() {
    let dir = scratch("cli_render_sampling");
    let (img, counts) = (dir.join("a.png"), dir.join("n.png"));
    let out = voxlab(&[
        "render",
        "phantom:shepp-logan-modified:32",
        "--width",
        "24",
        "--height",
        "24",
        "--sampling",
        "adaptive",
        "--out",
        s(&img),
        "--samples",
        s(&counts),
    ]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    assert!(img.is_file() && counts.is_file());
    assert!(common::stderr(&out).contains("adaptive sampling"));
    // DVR only.
    let out = voxlab(&[
        "render",
        "phantom:shepp-logan-modified:32",
        "--mode",
        "mip",
        "--sampling",
        "direct",
        "--out",
        s(&img),
    ]);
    assert!(!out.status.success());
    assert!(
        common::stderr(&out).contains("DVR only"),
        "{}",
        common::stderr(&out)
    );
}

/// The GPU adaptive caster holds the volume and the importance volume in 3-D textures
/// and uploads each band of rows with its own rays, so neither the volume nor the image
/// is bounded by one storage binding: under a 1 MiB binding a 72³ volume (1.4 MiB of
/// f32, 5.7 MiB of importance) renders, a 2048-pixel row's rays (64 KiB) allow bands of
/// 16 rows instead of 32, and the image is the same bit for bit, for every sampling.
/// Past the 3-D texture limit it renders in bricks, saying so, and writes the unsplit
/// file byte for byte (`render --sampling`, every sampling, and `adaptive`, whose dry
/// run prints the split); under a limit no brick with its ghost voxels fits, the run
/// and its dry run refuse alike, naming the volume and the limit.
#[test]
fn gpu_adaptive_textures_and_bands_write_the_unsplit_image() {
    if common::gpu("gpu_adaptive_textures_and_bands_write_the_unsplit_image").is_none() {
        return;
    }
    let dir = scratch("cli_adaptive_bands");
    for sampling in ["regular", "direct", "adaptive"] {
        let args = [
            "render",
            "phantom:shepp-logan-modified:72",
            "--width",
            "2048",
            "--height",
            "48",
            "--sampling",
            sampling,
            "--backend",
            "gpu",
        ];
        common::split_writes_the_unsplit_file(&dir, &args, "1MiB", &[]);
    }
    // Past the texture limit: 64³ with 11 ghost voxels in bricks of at most 40 texels.
    let texture_limit = |args: &[&str], out: &std::path::Path, limit: &str| {
        let args = [args, &["--backend", "gpu", "--out", s(out)][..]].concat();
        let mut c = common::voxlab_command(&args);
        if !limit.is_empty() {
            c.env("VOXLAB_GPU_MAX_TEXTURE_3D", limit);
        }
        c.output().unwrap()
    };
    for sampling in ["regular", "direct", "adaptive"] {
        let args = [
            "render",
            "phantom:shepp-logan-modified:64",
            "--width",
            "40",
            "--height",
            "32",
            "--sampling",
            sampling,
        ];
        let (whole, split) = (dir.join("whole.npy"), dir.join("split.npy"));
        let a = texture_limit(&args, &whole, "");
        let b = texture_limit(&args, &split, "40");
        assert!(
            a.status.success() && b.status.success(),
            "{}",
            common::stderr(&b)
        );
        let said = common::stderr(&b);
        assert!(
            said.contains(
                " bricks (the [64, 64, 64] volume exceeds the 3-D texture limit of 40 \
                 texels per axis; the largest brick with its 11 ghost voxels holds"
            ),
            "{sampling}: {said}"
        );
        assert!(
            !common::stderr(&a).contains("bricks"),
            "{}",
            common::stderr(&a)
        );
        assert_eq!(
            std::fs::read(&whole).unwrap(),
            std::fs::read(&split).unwrap(),
            "{sampling}: the split file differs from the unsplit one"
        );
    }
    let adaptive = [
        "adaptive",
        "phantom:shepp-logan-modified:64",
        "--size",
        "24",
        "--runs",
        "1",
    ];
    let plan = texture_limit(
        &[&adaptive[..], &["--dry-run"]].concat(),
        &dir.join("p"),
        "40",
    );
    assert!(plan.status.success(), "{}", common::stderr(&plan));
    assert!(!dir.join("p").exists());
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&plan.stdout),
        common::stderr(&plan)
    );
    for sampling in ["regular", "direct", "adaptive"] {
        assert!(
            text.contains(&format!("{sampling} sampling: adaptive ray casting in ")),
            "{text}"
        );
    }
    let (whole, split) = (dir.join("whole"), dir.join("split"));
    let a = texture_limit(&adaptive, &whole, "");
    let b = texture_limit(&adaptive, &split, "40");
    assert!(
        a.status.success() && b.status.success(),
        "{}",
        common::stderr(&b)
    );
    assert!(common::stderr(&b).contains("adaptive sampling: adaptive ray casting in "));
    // Every image the comparison writes (the tables hold timings).
    let mut images = 0;
    for e in std::fs::read_dir(&whole).unwrap() {
        let name = e.unwrap().file_name();
        if !name.to_string_lossy().starts_with("table") {
            let same = std::fs::read(whole.join(&name)).unwrap()
                == std::fs::read(split.join(&name)).unwrap();
            assert!(same, "adaptive: {name:?} differs split");
            images += 1;
        }
    }
    assert!(images >= 3, "{images} images");

    let never = dir.join("never.npy");
    let render = [
        "render",
        "phantom:shepp-logan-modified:32",
        "--sampling",
        "adaptive",
    ];
    let adaptive = ["adaptive", "phantom:shepp-logan-modified:32"];
    for command in [&render[..], &adaptive[..]] {
        let mut said = Vec::new();
        for dry in [&[][..], &["--dry-run"]] {
            let args = [command, &["--backend", "gpu", "--out", s(&never)][..], dry].concat();
            let o = common::voxlab_command(&args)
                .env("VOXLAB_GPU_MAX_TEXTURE_3D", "16")
                .output()
                .unwrap();
            assert!(!o.status.success(), "{args:?} ran");
            let err = common::stderr(&o);
            assert!(
                err.contains(
                    "volume is too large: [32, 32, 32] cannot be cut into bricks of at most 16 \
                     texels per axis with the 11 ghost voxels of steps up to T_max = 8"
                ),
                "{err}"
            );
            assert!(!never.exists());
            said.push(err);
        }
        assert_eq!(said[0], said[1], "{command:?}");
    }
}
