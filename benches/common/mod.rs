//! What every benchmark shares: the command line cargo passes, and medians.
#![allow(dead_code)]

/// How a benchmark was invoked.
pub struct BenchArgs {
    /// Only cases whose name contains this run (the first non-flag argument).
    pub filter: Option<String>,
    /// Without `--bench` (as under `cargo test`), each case runs once on a tiny input.
    pub smoke: bool,
    /// Timed runs after one warm-up: `VOXLAB_BENCH_RUNS`, default 5 (1 in smoke mode).
    pub runs: usize,
}

impl BenchArgs {
    pub fn from_env() -> Self {
        let filter = std::env::args().skip(1).find(|a| !a.starts_with('-'));
        let smoke = !std::env::args().any(|a| a == "--bench");
        let runs = if smoke {
            1
        } else {
            std::env::var("VOXLAB_BENCH_RUNS")
                .ok()
                .and_then(|s| s.parse().ok())
                .unwrap_or(5)
        };
        BenchArgs {
            filter,
            smoke,
            runs,
        }
    }

    /// Whether the case called `name` is selected by the filter.
    pub fn wants(&self, name: &str) -> bool {
        self.filter.as_deref().is_none_or(|f| name.contains(f))
    }
}

/// Median, minimum and maximum of some timings (at least one).
pub fn median_min_max(mut t: Vec<f64>) -> (f64, f64, f64) {
    t.sort_by(|a, b| a.total_cmp(b));
    (t[t.len() / 2], t[0], t[t.len() - 1])
}
