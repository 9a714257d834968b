//! Mirror pointers hold. The Rust helper and the WGSL helper that compute one sample,
//! one weight, one butterfly carry the same name and point at each other in a comment
//! of one form:
//!
//! ```text
//! // mirrors shaders/shared/rays.wgsl: intersect_box
//! /// Mirrors src/cpu/filter.rs: sample, apply_taps (commentary may follow)
//! ```
//!
//! that is `mirrors` (any case), a path from the crate root (`src/….rs` or
//! `shaders/….wgsl`), a colon, and one or more comma-separated names (`Type::method`
//! allowed in Rust files), on one line; in Rust docs the pointer may be one code span,
//! `` Mirrors `src/cpu/filter.rs: sinc`. `` (nothing else inside it). This test reads every Rust
//! file under `src/` and every WGSL file under `shaders/`, and fails, listing every bad
//! pointer, when a pointer is not of that form, names a file that does not exist, or
//! names something the file does not define (`fn`, `struct`, `enum`, `const`,
//! `static`, `type`, `trait` in Rust; `fn`, `struct`, `const`, `var`, `alias`,
//! `override` in WGSL). `mirrors` followed by anything that is not a path, a
//! backticked or a `::` name (`mirrors its Rust twin`) is prose, not a pointer.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// One pointer, or a problem with one.
#[derive(Debug, PartialEq)]
struct Pointer {
    path: String,
    names: Vec<String>,
}

/// The pointers in one comment text, and the malformed ones (`Err`).
fn pointers_in(comment: &str, next_comment: Option<&str>) -> Vec<Result<Pointer, String>> {
    let mut out = Vec::new();
    let lower = comment.to_ascii_lowercase();
    let mut from = 0;
    while let Some(at) = lower[from..].find("mirrors") {
        let start = from + at;
        from = start + "mirrors".len();
        let word_start = start == 0 || !is_ident(lower.as_bytes()[start - 1] as char);
        let after = &comment[from..];
        if !word_start || after.starts_with(is_ident) {
            continue;
        }
        let rest = after.trim_start();
        if rest.is_empty() {
            // The pointer, if any, would continue on the next line.
            if next_comment.is_some_and(|n| pointer_like(first_token(n.trim_start()))) {
                out.push(Err(
                    "pointer broken across lines (keep it on one line)".into()
                ));
            }
            continue;
        }
        let token = first_token(rest);
        if !pointer_like(token) {
            continue;
        }
        out.push(parse_pointer(rest));
    }
    out
}

fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

fn first_token(s: &str) -> &str {
    s.split_whitespace().next().unwrap_or("")
}

/// Whether the word after `mirrors` is meant as a pointer: a path, a file name or a
/// `::` path, possibly in backticks.
fn pointer_like(token: &str) -> bool {
    let t = token.trim_start_matches(['`', '(']);
    t.starts_with("src/")
        || t.starts_with("shaders/")
        || t.contains(".rs")
        || t.contains(".wgsl")
        || t.contains("::")
}

/// `path: name, name …` at the start of `s`, or the same in one code span.
fn parse_pointer(s: &str) -> Result<Pointer, String> {
    if let Some(span) = s.strip_prefix('`') {
        let Some((inner, _)) = span.split_once('`') else {
            return Err("pointer broken across lines (keep it on one line)".into());
        };
        let p = parse_plain(inner)?;
        let listed = format!("{}: {}", p.path, p.names.join(", "));
        if inner.trim_end() != listed {
            return Err(format!(
                "the code span holds more than `path: name, name`: `{inner}`"
            ));
        }
        return Ok(p);
    }
    parse_plain(s)
}

fn parse_plain(s: &str) -> Result<Pointer, String> {
    let Some((path, rest)) = s.split_once(": ") else {
        return Err("no `path: name` (a path from the crate root, a colon, names)".into());
    };
    let well_formed_path = (path.starts_with("src/") && path.ends_with(".rs"))
        || (path.starts_with("shaders/") && path.ends_with(".wgsl"));
    if !well_formed_path || path.contains(char::is_whitespace) {
        return Err(format!(
            "{path:?} is not a path from the crate root (src/….rs or shaders/….wgsl)"
        ));
    }
    let mut names = Vec::new();
    let mut rest = rest;
    loop {
        let end = rest
            .find(|c: char| !(is_ident(c) || c == ':'))
            .unwrap_or(rest.len());
        let name = rest[..end].trim_end_matches(':');
        let valid = !name.is_empty()
            && name.split("::").all(|p| {
                !p.is_empty()
                    && p.chars().all(is_ident)
                    && !p.starts_with(|c: char| c.is_ascii_digit())
            });
        if !valid {
            break;
        }
        names.push(name.to_string());
        rest = &rest[name.len()..];
        match rest.strip_prefix(", ") {
            Some(r) if r.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_') => rest = r,
            _ => break,
        }
    }
    if names.is_empty() {
        return Err(format!("{path}: no name after the colon"));
    }
    Ok(Pointer {
        path: path.to_string(),
        names,
    })
}

/// A line split into its code and the text of its comment (after `//`, `///` or
/// `//!`), when it has one outside a string literal.
fn split_comment(line: &str) -> (&str, Option<&str>) {
    let mut in_string = false;
    let bytes = line.as_bytes();
    let mut i = 0;
    while i + 1 < bytes.len() {
        match bytes[i] {
            b'\\' if in_string => i += 1,
            // A quote character as a char literal.
            b'\'' if !in_string && line[i..].starts_with("'\"'") => i += 2,
            b'"' => in_string = !in_string,
            b'/' if !in_string && bytes[i + 1] == b'/' => {
                return (
                    &line[..i],
                    Some(line[i + 2..].trim_start_matches(['/', '!'])),
                );
            }
            _ => {}
        }
        i += 1;
    }
    (line, None)
}

/// Identifier-and-punctuation tokens of a source text, comments dropped.
fn tokens(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in text.lines() {
        let mut cur = String::new();
        for c in split_comment(line).0.chars() {
            if is_ident(c) {
                cur.push(c);
            } else {
                if !cur.is_empty() {
                    out.push(std::mem::take(&mut cur));
                }
                if !c.is_whitespace() {
                    out.push(c.to_string());
                }
            }
        }
        if !cur.is_empty() {
            out.push(cur);
        }
    }
    out
}

/// The names a file defines at any level (items, methods, associated consts).
fn definitions(path: &Path, text: &str) -> HashSet<String> {
    let rust = path.extension().is_some_and(|e| e == "rs");
    let keywords: &[&str] = if rust {
        &[
            "fn", "struct", "enum", "const", "static", "type", "trait", "union", "mod",
        ]
    } else {
        &["fn", "struct", "const", "alias", "override", "var"]
    };
    let t = tokens(text);
    let mut defs = HashSet::new();
    let mut i = 0;
    while i < t.len() {
        if keywords.contains(&t[i].as_str()) {
            let mut j = i + 1;
            // WGSL `var<storage, read> name`.
            if t[i] == "var" && t.get(j).is_some_and(|x| x == "<") {
                while j < t.len() && t[j] != ">" {
                    j += 1;
                }
                j += 1;
            }
            if let Some(name) = t.get(j) {
                if name.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_') {
                    defs.insert(name.clone());
                }
            }
        }
        // `macro_rules! name`
        if rust && t[i] == "macro_rules" && t.get(i + 1).is_some_and(|x| x == "!") {
            if let Some(name) = t.get(i + 2) {
                defs.insert(name.clone());
            }
        }
        i += 1;
    }
    defs
}

fn files(root: &Path, dir: &str, ext: &str, out: &mut Vec<PathBuf>) {
    let mut stack = vec![root.join(dir)];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == ext) {
                out.push(p);
            }
        }
    }
    out.sort();
}

/// Every pointer in the crate: (file, line number, pointer or problem, the comment).
fn scan(root: &Path) -> Vec<(String, usize, Result<Pointer, String>, String)> {
    let mut paths = Vec::new();
    files(root, "src", "rs", &mut paths);
    files(root, "shaders", "wgsl", &mut paths);
    let mut out = Vec::new();
    for p in &paths {
        let text = std::fs::read_to_string(p).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        let rel = p.strip_prefix(root).unwrap().to_string_lossy().into_owned();
        for (n, line) in lines.iter().enumerate() {
            let Some(c) = split_comment(line).1 else {
                continue;
            };
            let next = lines.get(n + 1).and_then(|l| split_comment(l).1);
            for r in pointers_in(c, next) {
                out.push((rel.clone(), n + 1, r, c.trim().to_string()));
            }
        }
    }
    out
}

/// The problems of one pointer: a missing file, or names it does not define.
fn check(root: &Path, p: &Pointer) -> Vec<String> {
    let file = root.join(&p.path);
    let Ok(text) = std::fs::read_to_string(&file) else {
        return vec![format!("{} does not exist", p.path)];
    };
    let defs = definitions(&file, &text);
    let rust = p.path.ends_with(".rs");
    let mut problems = Vec::new();
    for name in &p.names {
        let parts: Vec<&str> = name.split("::").collect();
        if !rust && parts.len() > 1 {
            problems.push(format!("{}: {name} is a Rust path in a WGSL file", p.path));
            continue;
        }
        let missing: Vec<&str> = parts
            .iter()
            .copied()
            .filter(|x| !defs.contains(*x))
            .collect();
        if !missing.is_empty() {
            problems.push(format!("{} defines no {}", p.path, missing.join(", ")));
        }
    }
    problems
}

#[test]
fn every_mirror_pointer_holds() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let found = scan(root);
    let mut bad = Vec::new();
    let mut good = 0;
    for (file, line, r, comment) in &found {
        let problems = match r {
            Ok(p) => check(root, p),
            Err(e) => vec![e.clone()],
        };
        if problems.is_empty() {
            good += 1;
        }
        for problem in problems {
            bad.push(format!("{file}:{line}: {problem}\n    // {comment}"));
        }
    }
    assert!(
        bad.is_empty(),
        "{} bad mirror pointers (of {}):\n{}",
        bad.len(),
        found.len(),
        bad.join("\n")
    );
    // A parser that finds nothing would pass everything.
    assert!(good > 150, "only {good} mirror pointers found");
}

/// The checker itself: pointers of every form parse, and broken ones are caught.
#[test]
fn the_checker_catches_broken_pointers() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let one = |c: &str| {
        let mut v = pointers_in(c, None);
        assert_eq!(v.len(), 1, "{c}: {v:?}");
        v.remove(0)
    };
    let p = one(" mirrors shaders/shared/rays.wgsl: intersect_box (two-sided)").unwrap();
    assert_eq!(p.path, "shaders/shared/rays.wgsl");
    assert_eq!(p.names, ["intersect_box"]);
    assert!(check(root, &p).is_empty());
    let p = one("Lexicographic order. Mirrors src/cpu/skip.rs: CellWalk::new, CellWalk.").unwrap();
    assert_eq!(p.names, ["CellWalk::new", "CellWalk"]);
    // A name the file does not define, a file that does not exist, a Rust path in WGSL.
    let p = one(" mirrors shaders/shared/rays.wgsl: no_such_function").unwrap();
    assert_eq!(check(root, &p).len(), 1);
    let p = one(" mirrors shaders/filter.wgsl: sinc").unwrap();
    assert_eq!(check(root, &p), ["shaders/filter.wgsl does not exist"]);
    let p = one(" mirrors shaders/shared/rays.wgsl: Hit::ok").unwrap();
    assert_eq!(check(root, &p).len(), 1);
    let p = one(" Mirrors `shaders/shared/rays.wgsl: intersect_box, Hit`.").unwrap();
    assert_eq!(p.names, ["intersect_box", "Hit"]);
    assert!(check(root, &p).is_empty());
    // Malformed pointers.
    assert!(one(" Mirrors `shaders/raycast.wgsl: intersect_box` and `phong`.").is_ok());
    assert!(one(" Mirrors `shaders/shared/rays.wgsl: intersect_box (slabs)`.").is_err());
    assert!(one(" Mirrors `shaders/shared/rays.wgsl:").is_err());
    assert!(one(" mirrors skip.wgsl: walk_new").is_err());
    assert!(one(" mirrors cpu::modes::ModeSetup::new").is_err());
    assert!(one(" mirrors src/cpu/raycast.rs").is_err());
    assert_eq!(
        pointers_in(
            " the tap sums; this mirrors",
            Some(" src/cpu/filter.rs: axis_taps.")
        )
        .len(),
        1
    );
    // Prose.
    assert!(pointers_in(" every helper mirrors its Rust twin", None).is_empty());
    assert!(pointers_in(" the GPU port mirrors", Some(" the per-element function")).is_empty());
}
