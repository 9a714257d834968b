//! What a benchmark ran on: the operating system, the CPU, the memory, the GPU adapter
//! and its driver, the versions of voxlab, wgpu and rustc, the date, and the exact
//! command line. A figure without its machine means little, so every report carries
//! this header.

use crate::gpu::GpuContext;

/// The machine and software a report was measured on.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Machine {
    /// `std::env::consts::OS`, with the distribution's name where
    /// `/etc/os-release` gives one.
    pub os: String,
    pub arch: String,
    /// `/proc/cpuinfo`'s "model name" (or the nearest equivalent field), else "unknown".
    pub cpu_model: String,
    /// Logical cores (hardware threads) the process may use.
    pub logical_cores: usize,
    /// Threads in rayon's global pool: what the CPU backends run on.
    pub rayon_threads: usize,
    /// Total memory in bytes from `/proc/meminfo` (None where unreadable).
    pub memory_bytes: Option<u64>,
    /// The adapter the GPU backend ran on; None when no GPU was used.
    pub adapter: Option<Adapter>,
    /// Why no adapter was used (no adapter found, or `--backends cpu`).
    pub no_adapter_reason: Option<String>,
    pub voxlab_version: String,
    /// The wgpu version voxlab is built against (from Cargo.lock).
    pub wgpu_version: String,
    pub rustc_version: String,
    /// When the run started, UTC, ISO 8601 (`2026-11-24T11:30:00Z`).
    pub date_utc: String,
    /// The command line, arguments joined by spaces (quoted where they hold spaces).
    pub command_line: String,
}

/// A GPU adapter as the report records it.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Adapter {
    pub name: String,
    /// Vulkan, Metal or Dx12.
    pub backend: String,
    /// DiscreteGpu, IntegratedGpu, VirtualGpu, Cpu (a software rasteriser) or Other.
    pub device_type: String,
    pub driver: String,
    pub driver_info: String,
    /// Whether the device has timestamp queries, i.e. whether kernel times are measured
    /// on the GPU itself rather than by the host's clock around a waited submission.
    pub timestamp_queries: bool,
    /// The part's data-sheet peaks, when [`crate::gpu::peak`] knows it (the roofline).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peak: Option<AdapterPeak>,
}

/// An adapter's data-sheet peaks as the report records them.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AdapterPeak {
    pub part: String,
    /// Peak memory bandwidth, 1e9 bytes per second.
    pub memory_gbps: f64,
    /// Peak dense FP32 rate, 1e12 operations per second.
    pub fp32_tflops: f64,
}

impl AdapterPeak {
    /// The peak of the throughput unit `unit` in that unit's scale
    /// ([`super::report::unit_scale`]): GB/s against the memory bandwidth, GFLOP/s
    /// against the FP32 rate; `None` for the other units.
    pub fn of_unit(&self, unit: super::case::Unit) -> Option<f64> {
        match unit {
            super::case::Unit::Bytes => Some(self.memory_gbps),
            super::case::Unit::Flops => Some(self.fp32_tflops * 1e3),
            _ => None,
        }
    }
}

impl Adapter {
    pub fn of(ctx: &GpuContext) -> Self {
        let s = &ctx.summary;
        Adapter {
            name: s.name.clone(),
            backend: s.backend.clone(),
            device_type: s.device_type.clone(),
            driver: s.driver.clone(),
            driver_info: s.driver_info.clone(),
            timestamp_queries: ctx.features.contains(wgpu::Features::TIMESTAMP_QUERY),
            peak: crate::gpu::peak::peak_of(&s.name).map(|p| AdapterPeak {
                part: p.part.to_string(),
                memory_gbps: p.memory_gbps,
                fp32_tflops: p.fp32_tflops,
            }),
        }
    }
}

impl Machine {
    /// Describes this machine now; `gpu` is the adapter in use, or why there is none.
    pub fn current(gpu: std::result::Result<&GpuContext, &str>) -> Self {
        let (adapter, no_adapter_reason) = match gpu {
            Ok(ctx) => (Some(Adapter::of(ctx)), None),
            Err(why) => (None, Some(why.to_string())),
        };
        Machine {
            os: os_name(),
            arch: std::env::consts::ARCH.to_string(),
            cpu_model: cpu_model(),
            logical_cores: std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(1),
            rayon_threads: rayon::current_num_threads(),
            memory_bytes: memory_bytes(),
            adapter,
            no_adapter_reason,
            voxlab_version: env!("CARGO_PKG_VERSION").to_string(),
            wgpu_version: env!("VOXLAB_WGPU_VERSION").to_string(),
            rustc_version: env!("VOXLAB_RUSTC_VERSION").to_string(),
            date_utc: utc_now(),
            command_line: command_line(),
        }
    }

    /// The adapter's name, or "no GPU".
    pub fn adapter_name(&self) -> &str {
        self.adapter.as_ref().map_or("no GPU", |a| a.name.as_str())
    }
}

fn os_name() -> String {
    let os = std::env::consts::OS.to_string();
    let pretty = std::fs::read_to_string("/etc/os-release")
        .ok()
        .and_then(|t| {
            t.lines()
                .find_map(|l| l.strip_prefix("PRETTY_NAME="))
                .map(|v| v.trim_matches('"').to_string())
        });
    match pretty {
        Some(p) if !p.is_empty() => format!("{os} ({p})"),
        _ => os,
    }
}

/// The CPU's model name: x86's "model name", else the fields ARM and others use.
fn cpu_model() -> String {
    let Ok(text) = std::fs::read_to_string("/proc/cpuinfo") else {
        return "unknown".to_string();
    };
    for key in ["model name", "Model", "Hardware", "cpu model", "uarch"] {
        let found = text.lines().find_map(|l| {
            let (k, v) = l.split_once(':')?;
            (k.trim() == key && !v.trim().is_empty()).then(|| v.trim().to_string())
        });
        if let Some(v) = found {
            return v;
        }
    }
    "unknown".to_string()
}

fn memory_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

fn command_line() -> String {
    std::env::args()
        .map(|a| {
            if a.is_empty() || a.contains(char::is_whitespace) {
                format!("'{a}'")
            } else {
                a
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// Now, UTC, as `YYYY-MM-DDTHH:MM:SSZ`.
pub fn utc_now() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    utc_from_unix(secs)
}

/// Seconds since 1970-01-01T00:00:00Z as ISO 8601, by Howard Hinnant's
/// days-to-civil algorithm (proleptic Gregorian calendar).
pub fn utc_from_unix(secs: u64) -> String {
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn civil_dates() {
        assert_eq!(utc_from_unix(0), "1970-01-01T00:00:00Z");
        // 2000-02-29 (a leap day of a year divisible by 400) at 12:34:56.
        assert_eq!(utc_from_unix(951_827_696), "2000-02-29T12:34:56Z");
        assert_eq!(utc_from_unix(1_798_761_599), "2026-12-31T23:59:59Z");
    }
}
