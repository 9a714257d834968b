//! JSON in: the one parser for every JSON file and request voxlab reads (render
//! settings, transfer functions, geometries, bench reports).
//!
//! [`parse`] accepts a leading UTF-8 byte-order mark, refuses a document whose top level
//! is not an object (serde would otherwise read `[]` as a struct of defaults), and adds
//! the nearest known field to serde's "unknown field" message, so `{"stpe": 0.01}` says
//! ``did you mean `step`?`` instead of rendering with the default step. The types read
//! this way deny unknown fields.

use crate::error::{Error, Result};
use serde::de::DeserializeOwned;
use std::path::Path;

/// Parses `text` (the contents of `path`, a `what` such as "render settings JSON") as a
/// JSON object of type `T`.
///
/// # Errors
/// [`Error::Format`] naming the file and `what`: not JSON, not an object, an unknown
/// field (with the nearest known one), a wrong value.
pub fn parse<T: DeserializeOwned>(text: &str, path: &Path, what: &str) -> Result<T> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    match text.trim_start().chars().next() {
        Some('{') => {}
        Some(c) => {
            return Err(Error::format(
                path,
                what,
                format!(
                    "the top level must be a JSON object {{ … }}, not {}",
                    match c {
                        '[' => "an array".to_string(),
                        '"' => "a string".to_string(),
                        _ => format!("'{}'", crate::error::escape_controls(&c.to_string())),
                    }
                ),
            ))
        }
        None => return Err(Error::format(path, what, "the file is empty")),
    }
    serde_json::from_str(text).map_err(|e| Error::format(path, what, explain(&e.to_string())))
}

/// Reads a JSON file of at most [`crate::source::MAX_JSON_BYTES`] (a regular file) and
/// parses it ([`parse`]).
///
/// # Errors
/// As [`crate::source::read_text_limited`] and [`parse`].
pub fn read_file<T: DeserializeOwned>(path: &Path, what: &str) -> Result<T> {
    let text = crate::source::read_text_limited(path, what, crate::source::MAX_JSON_BYTES)?;
    parse(&text, path, what)
}

/// serde's message, with ``did you mean `NAME`?`` after an unknown field or variant
/// whose name is close to a known one.
pub fn explain(message: &str) -> String {
    let (Some(unknown), Some(expected)) = (
        between(message, "unknown field `", "`")
            .or_else(|| between(message, "unknown variant `", "`")),
        message.split_once("`, expected ").map(|(_, r)| r),
    ) else {
        return crate::error::escape_controls(message).into_owned();
    };
    // "one of `a`, `b`, `c`", "`a` or `b`", "`a`": the names between backticks.
    let known: Vec<&str> = expected.split('`').skip(1).step_by(2).collect();
    let mut out = crate::error::escape_controls(message).into_owned();
    if let Some(best) = nearest(unknown, &known) {
        out.push_str(&format!(" (did you mean `{best}`?)"));
    }
    out
}

/// The known name closest to `name` by edit distance, when it is close (at most a
/// third of the name's length, and at least 1).
pub fn nearest<'a>(name: &str, known: &[&'a str]) -> Option<&'a str> {
    let limit = (name.chars().count() / 3).max(1);
    known
        .iter()
        .map(|k| (edit_distance(&name.to_lowercase(), &k.to_lowercase()), *k))
        .filter(|(d, _)| *d <= limit)
        .min_by_key(|(d, _)| *d)
        .map(|(_, k)| k)
}

fn between<'a>(s: &'a str, open: &str, close: &str) -> Option<&'a str> {
    let (_, rest) = s.split_once(open)?;
    rest.split_once(close).map(|(inner, _)| inner)
}

/// Levenshtein distance with transpositions counted as one edit (optimal string
/// alignment), over characters.
fn edit_distance(a: &str, b: &str) -> usize {
    let (a, b): (Vec<char>, Vec<char>) = (a.chars().collect(), b.chars().collect());
    let mut d = vec![vec![0usize; b.len() + 1]; a.len() + 1];
    for (i, row) in d.iter_mut().enumerate() {
        row[0] = i;
    }
    for (j, cell) in d[0].iter_mut().enumerate() {
        *cell = j;
    }
    for i in 1..=a.len() {
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            let mut v = (d[i - 1][j] + 1)
                .min(d[i][j - 1] + 1)
                .min(d[i - 1][j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                v = v.min(d[i - 2][j - 2] + 1);
            }
            d[i][j] = v;
        }
    }
    d[a.len()][b.len()]
}

/// A JSON array of at most [`crate::ct::MAX_DETECTOR`] elements (projections, views),
/// refused past that as it is read, before more is allocated (serde's
/// `deserialize_with`).
///
/// # Errors
/// The deserializer's, and "more than … projections".
pub fn bounded<'de, D, T>(d: D) -> std::result::Result<Vec<T>, D::Error>
where
    D: serde::Deserializer<'de>,
    T: serde::Deserialize<'de>,
{
    use crate::ct::MAX_DETECTOR;
    struct V<T>(std::marker::PhantomData<T>);
    impl<'de, T: serde::Deserialize<'de>> serde::de::Visitor<'de> for V<T> {
        type Value = Vec<T>;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            write!(f, "a list of at most {MAX_DETECTOR} projections")
        }
        fn visit_seq<A: serde::de::SeqAccess<'de>>(
            self,
            mut seq: A,
        ) -> std::result::Result<Vec<T>, A::Error> {
            let mut out = Vec::new();
            while let Some(x) = seq.next_element()? {
                if out.len() == MAX_DETECTOR {
                    return Err(serde::de::Error::custom(format!(
                        "more than {MAX_DETECTOR} projections"
                    )));
                }
                out.push(x);
            }
            Ok(out)
        }
    }
    d.deserialize_seq(V(std::marker::PhantomData))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    #[serde(default, deny_unknown_fields)]
    struct S {
        step: f64,
        mode: String,
    }
    impl Default for S {
        fn default() -> Self {
            S {
                step: 0.5,
                mode: "dvr".into(),
            }
        }
    }

    fn err(text: &str) -> String {
        parse::<S>(text, Path::new("s.json"), "settings JSON")
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn an_unknown_field_names_the_nearest_known_one() {
        let e = err(r#"{"stpe": 0.01}"#);
        assert!(
            e.contains("s.json: settings JSON: unknown field `stpe`"),
            "{e}"
        );
        assert!(e.contains("did you mean `step`?"), "{e}");
        // Nothing close: no suggestion.
        assert!(!err(r#"{"zzzzzz": 1}"#).contains("did you mean"));
    }

    #[test]
    fn the_top_level_must_be_an_object() {
        assert!(err("[]").contains("not an array"), "{}", err("[]"));
        assert!(err("  \"x\"").contains("not a string"));
        assert!(err("").contains("empty"));
    }

    #[test]
    fn a_byte_order_mark_is_accepted() {
        let s: S = parse("\u{feff}{\"step\": 0.25}", Path::new("s.json"), "x").unwrap();
        assert_eq!(s.step, 0.25);
        assert_eq!(s.mode, "dvr");
    }

    #[test]
    fn edit_distances() {
        assert_eq!(edit_distance("stpe", "step"), 1);
        assert_eq!(edit_distance("", "abc"), 3);
        assert_eq!(edit_distance("kitten", "sitting"), 3);
        assert_eq!(nearest("filtr", &["filter", "mode"]), Some("filter"));
    }
}
