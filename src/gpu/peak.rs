//! The hardware's own limits, for the roofline: the published peak memory bandwidth
//! and FP32 rate of common GPUs, found by the adapter's name, so that `voxlab bench`
//! and `voxlab fft` can say how far each kernel is from what the part can do; and their
//! memory, which wgpu does not report, for the planner ([`super::plan::DeviceMemory`]).
//!
//! The figures are the vendors' data-sheet numbers (boost clock, dense FP32 without
//! tensor cores). An adapter not in the table (a software rasteriser such as lavapipe,
//! an integrated GPU, a part not listed) has no peak, and the reports say so instead
//! of guessing.

/// One GPU's data-sheet peaks.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Peak {
    /// The part, as the vendor names it.
    pub part: &'static str,
    /// Peak memory bandwidth, 1e9 bytes per second.
    pub memory_gbps: f64,
    /// Peak dense FP32 rate (FMA counted as two), 1e12 operations per second.
    pub fp32_tflops: f64,
    /// Device memory, 1e9 bytes (the smallest model of the part's name where it comes
    /// in several sizes): what the planner fills at most ([`super::plan::DeviceMemory`]).
    pub memory_gb: f64,
}

/// The table: the words an adapter's name must contain (case-insensitive, each a whole
/// word), and the part's peaks. More specific entries come first (the first match
/// wins).
const TABLE: &[(&[&str], Peak)] = &[
    (
        &["H200"],
        peak("NVIDIA H200 (SXM, HBM3e)", 4800.0, 67.0, 141.0),
    ),
    (
        &["H100", "NVL"],
        peak("NVIDIA H100 NVL", 3900.0, 60.0, 94.0),
    ),
    (
        &["H100", "PCIe"],
        peak("NVIDIA H100 PCIe", 2000.0, 51.0, 80.0),
    ),
    (
        &["H100"],
        peak("NVIDIA H100 SXM5 (HBM3)", 3350.0, 67.0, 80.0),
    ),
    (
        &["A100", "SXM4", "80GB"],
        peak("NVIDIA A100 SXM4 80 GB", 2039.0, 19.5, 80.0),
    ),
    (
        &["A100", "80GB"],
        peak("NVIDIA A100 PCIe 80 GB", 1935.0, 19.5, 80.0),
    ),
    (&["A100"], peak("NVIDIA A100 40 GB", 1555.0, 19.5, 40.0)),
    (&["L40S"], peak("NVIDIA L40S", 864.0, 91.6, 48.0)),
    (&["L40"], peak("NVIDIA L40", 864.0, 90.5, 48.0)),
    (&["L4"], peak("NVIDIA L4", 300.0, 30.3, 24.0)),
    (&["A10"], peak("NVIDIA A10", 600.0, 31.2, 24.0)),
    (&["V100"], peak("NVIDIA V100 (SXM2)", 900.0, 15.7, 16.0)),
    (&["T4"], peak("NVIDIA T4", 320.0, 8.1, 16.0)),
    (
        &["RTX", "4090"],
        peak("NVIDIA GeForce RTX 4090", 1008.0, 82.6, 24.0),
    ),
    (
        &["RTX", "4080"],
        peak("NVIDIA GeForce RTX 4080", 716.8, 48.7, 16.0),
    ),
    (
        &["RTX", "3090"],
        peak("NVIDIA GeForce RTX 3090", 936.0, 35.6, 24.0),
    ),
    (
        &["RTX", "A6000"],
        peak("NVIDIA RTX A6000", 768.0, 38.7, 48.0),
    ),
    (
        &["MI300X"],
        peak("AMD Instinct MI300X", 5300.0, 163.4, 192.0),
    ),
    (
        &["MI250X"],
        peak("AMD Instinct MI250X", 3276.8, 47.9, 128.0),
    ),
];

const fn peak(part: &'static str, memory_gbps: f64, fp32_tflops: f64, memory_gb: f64) -> Peak {
    Peak {
        part,
        memory_gbps,
        fp32_tflops,
        memory_gb,
    }
}

/// The peaks of the adapter named `name` (`wgpu::AdapterInfo::name`), when the table
/// knows the part.
pub fn peak_of(name: &str) -> Option<Peak> {
    let words: Vec<String> = name
        .split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|w| !w.is_empty())
        .map(str::to_ascii_lowercase)
        .collect();
    TABLE
        .iter()
        .find(|(need, _)| {
            need.iter()
                .all(|n| words.iter().any(|w| w == &n.to_ascii_lowercase()))
        })
        .map(|(_, p)| *p)
}

/// `achieved` as a fraction of `peak` (`None` without a peak or a finite figure).
pub fn fraction(achieved: f64, peak: Option<f64>) -> Option<f64> {
    peak.filter(|p| *p > 0.0)
        .map(|p| achieved / p)
        .filter(|f| f.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adapters_find_their_part_and_others_none() {
        let part = |n: &str| peak_of(n).map(|p| p.part);
        assert_eq!(part("NVIDIA H200"), Some("NVIDIA H200 (SXM, HBM3e)"));
        assert_eq!(
            part("NVIDIA H100 80GB HBM3"),
            Some("NVIDIA H100 SXM5 (HBM3)")
        );
        assert_eq!(part("NVIDIA H100 PCIe"), Some("NVIDIA H100 PCIe"));
        assert_eq!(part("NVIDIA H100 NVL"), Some("NVIDIA H100 NVL"));
        assert_eq!(
            part("NVIDIA A100-SXM4-80GB"),
            Some("NVIDIA A100 SXM4 80 GB")
        );
        assert_eq!(part("NVIDIA A100-PCIE-40GB"), Some("NVIDIA A100 40 GB"));
        assert_eq!(part("NVIDIA A10"), Some("NVIDIA A10"));
        assert_eq!(part("NVIDIA L4"), Some("NVIDIA L4"));
        assert_eq!(part("NVIDIA L40S"), Some("NVIDIA L40S"));
        assert_eq!(
            part("NVIDIA GeForce RTX 4090"),
            Some("NVIDIA GeForce RTX 4090")
        );
        // Whole words only: no A10 inside an A100, no L4 inside an L40.
        assert_eq!(part("NVIDIA A1000"), None);
        assert_eq!(part("llvmpipe (LLVM 15.0.6, 256 bits)"), None);
        assert_eq!(part("AMD Radeon Graphics (RADV RENOIR)"), None);
        let h200 = peak_of("NVIDIA H200").unwrap();
        assert_eq!(fraction(480.0, Some(h200.memory_gbps)), Some(0.1));
        assert_eq!(h200.memory_gb, 141.0);
        assert_eq!(peak_of("NVIDIA H100 80GB HBM3").unwrap().memory_gb, 80.0);
        assert_eq!(fraction(480.0, None), None);
        assert_eq!(fraction(f64::NAN, Some(1.0)), None);
    }
}
