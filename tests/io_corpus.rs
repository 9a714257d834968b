//! The regression corpus of broken files (`tests/corpus/broken/`, written by
//! `tests/corpus/make_broken.py`, expectations in `EXPECTED.tsv`): every file gets its
//! expected typed error naming the file and the field, and the command line turns each
//! into a non-zero exit with no output file left behind.

use std::path::{Path, PathBuf};
use std::process::Command;
use voxlab::Error;

struct Case {
    file: PathBuf,
    kind: String,
    field: String,
    words: String,
}

fn corpus() -> Vec<Case> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus/broken");
    let text = std::fs::read_to_string(dir.join("EXPECTED.tsv")).unwrap();
    let cases: Vec<Case> = text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let f: Vec<&str> = l.split('\t').collect();
            assert_eq!(f.len(), 4, "bad EXPECTED.tsv line: {l}");
            Case {
                file: dir.join(f[0]),
                kind: f[1].into(),
                field: f[2].into(),
                words: f[3].into(),
            }
        })
        .collect();
    // Every file in the folder is listed, and every listed file exists.
    let mut on_disk: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n != "EXPECTED.tsv")
        .collect();
    on_disk.sort();
    let mut listed: Vec<String> = cases
        .iter()
        .map(|c| c.file.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    listed.sort();
    assert_eq!(
        on_disk, listed,
        "tests/corpus/broken and EXPECTED.tsv disagree"
    );
    cases
}

#[test]
fn every_broken_file_gets_its_expected_error() {
    let cases = corpus();
    assert!(cases.len() >= 15, "the corpus shrank to {}", cases.len());
    for c in &cases {
        let e = match voxlab::io::read_volume(&c.file) {
            Ok(v) => panic!(
                "{}: read as {:?} instead of failing",
                c.file.display(),
                v.dims()
            ),
            Err(e) => e,
        };
        let msg = e.to_string();
        let name = c.file.file_name().unwrap().to_string_lossy().into_owned();
        let (kind, field) = match &e {
            Error::Format { field, .. } => ("format", field.as_str()),
            Error::Invalid { .. } => ("invalid", ""),
            Error::TooLarge { .. } => ("too-large", ""),
            Error::Io { .. } => ("io", ""),
            _ => ("other", ""),
        };
        assert_eq!(kind, c.kind, "{name}: wrong kind of error: {msg}");
        if !c.field.is_empty() {
            assert_eq!(field, c.field, "{name}: wrong field: {msg}");
        }
        assert!(
            msg.contains(&c.words),
            "{name}: '{msg}' lacks '{}'",
            c.words
        );
        // The message names the file it is about.
        if kind == "format" || kind == "io" {
            assert!(
                msg.contains(&name) || msg.contains(".raw") || msg.contains(".dcm"),
                "{name}: {msg}"
            );
        }
    }
}

#[test]
fn the_command_line_exits_non_zero_and_writes_nothing() {
    let out_dir = std::env::temp_dir().join(format!("voxlab-corpus-{}", std::process::id()));
    std::fs::create_dir_all(&out_dir).unwrap();
    for c in corpus() {
        let out = out_dir.join("out.nrrd");
        let r = Command::new(env!("CARGO_BIN_EXE_voxlab"))
            .arg("convert")
            .arg(&c.file)
            .arg(&out)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&r.stderr);
        assert!(
            !r.status.success(),
            "{}: convert succeeded",
            c.file.display()
        );
        assert!(
            stderr.starts_with("voxlab: error: "),
            "{}: {stderr}",
            c.file.display()
        );
        assert!(
            !stderr.contains("panicked"),
            "{}: {stderr}",
            c.file.display()
        );
        assert_eq!(
            std::fs::read_dir(&out_dir).unwrap().count(),
            0,
            "{}: something was written",
            c.file.display()
        );
    }
    std::fs::remove_dir_all(&out_dir).unwrap();
}
