//! `voxlab render` with 2D transfer functions, presets, faux shading and stereo, and
//! clear errors for bad 2D transfer-function JSON.

mod common;

use common::{s, scratch, stderr, voxlab};

const PHANTOM: &str = "phantom:shepp-logan-modified:24";

fn npy_f32(path: &std::path::Path) -> (Vec<usize>, Vec<f32>) {
    let bytes = std::fs::read(path).unwrap();
    let hlen = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let header = String::from_utf8_lossy(&bytes[10..10 + hlen]).to_string();
    let shape: Vec<usize> = header
        .split("'shape': (")
        .nth(1)
        .unwrap()
        .split(')')
        .next()
        .unwrap()
        .split(',')
        .filter_map(|t| t.trim().parse().ok())
        .collect();
    let data = bytes[10 + hlen..]
        .chunks(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    (shape, data)
}

#[test]
fn render_with_a_2d_widget_file_presets_and_faux_shading() {
    let d = scratch("cli_tf2d_render");
    let tf = d.join("widgets.json");
    std::fs::write(
        &tf,
        r#"{"domain":[0,1],"gradient_max":0.1,"lut_size":[128,32],"widgets":[
            {"shape":{"type":"triangle","apex":0.3,"half_width":0.15,"gradient":[0.002,0.05]},
             "rgba":[1,0.8,0.6,0.6],"border":0.5}]}"#,
    )
    .unwrap();
    let out = d.join("a.npy");
    let o = voxlab(&[
        "render",
        PHANTOM,
        "--tf2d",
        s(&tf),
        "--gradient-axis",
        "log",
        "--width",
        "20",
        "--height",
        "16",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (shape, px) = npy_f32(&out);
    assert_eq!(shape, vec![16, 20, 4]);
    assert!(px.iter().any(|&v| v > 0.05));
    for preset in ["ct-bone", "ct-bone-2d"] {
        let out = d.join(format!("{preset}.png"));
        let o = voxlab(&[
            "render",
            PHANTOM,
            "--tf-preset",
            preset,
            "--faux-shading",
            "2",
            "--width",
            "12",
            "--height",
            "12",
            "--out",
            s(&out),
        ]);
        assert!(o.status.success(), "{preset}: {}", stderr(&o));
        assert!(out.exists());
    }
}

#[test]
fn stereo_layouts_have_their_sizes() {
    let d = scratch("cli_tf2d_stereo");
    for (layout, w) in [("anaglyph", 20), ("side-by-side", 40), ("interlaced", 20)] {
        let out = d.join(format!("{layout}.npy"));
        let o = voxlab(&[
            "render",
            PHANTOM,
            "--stereo",
            layout,
            "--eye-separation",
            "60",
            "--width",
            "20",
            "--height",
            "14",
            "--out",
            s(&out),
        ]);
        assert!(o.status.success(), "{layout}: {}", stderr(&o));
        assert!(stderr(&o).contains("frustum shift"), "{}", stderr(&o));
        let (shape, _) = npy_f32(&out);
        assert_eq!(shape, vec![14, w, 4], "{layout}");
    }
}

#[test]
fn bad_2d_json_and_options_are_clear_errors() {
    let d = scratch("cli_tf2d_errors");
    let out = d.join("x.png");
    let bad = d.join("bad.json");
    for (text, words) in [
        ("{ not json", "JSON"),
        (
            r#"{"domain":[0,1],"gradient_max":0,"widgets":[]}"#,
            "gradient_max",
        ),
        (
            r#"{"domain":[0,1],"gradient_max":1,"widgets":[{"shape":{"type":"star"}}]}"#,
            "star",
        ),
    ] {
        std::fs::write(&bad, text).unwrap();
        let o = voxlab(&["render", PHANTOM, "--tf2d", s(&bad), "--out", s(&out)]);
        assert!(!o.status.success());
        let e = stderr(&o);
        assert!(e.contains(words) && !e.contains("panicked"), "{text}: {e}");
    }
    for (args, words) in [
        (vec!["--gradient-axis", "log"], "2D transfer function"),
        (vec!["--tf-preset", "ct-nothing"], "ct-nothing"),
        (vec!["--faux-shading", "-1"], "faux shading"),
        (
            vec!["--tf2d", "ct-bone-2d", "--classification", "pre"],
            "post-classification",
        ),
        (vec!["--stereo", "anaglyph", "--ortho"], "orthographic"),
    ] {
        let mut a = vec![
            "render",
            PHANTOM,
            "--width",
            "8",
            "--height",
            "8",
            "--out",
            s(&out),
        ];
        a.extend(args.iter().copied());
        let o = voxlab(&a);
        assert!(!o.status.success(), "{args:?}");
        let e = stderr(&o);
        assert!(
            e.contains(words) && !e.contains("panicked"),
            "{args:?}: {e}"
        );
    }
    assert!(!out.exists());
}
