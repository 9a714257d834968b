//! Benchmark cases (being written).
use super::{Case, Suite};

pub fn cases(_suite: Suite) -> Vec<Case> {
    Vec::new()
}
