//! A job's memory plan: what `--dry-run` prints, and what a job checks before it
//! allocates. The host bytes are the job's large arrays at their peak; the device
//! bytes are its largest allocation at once, against the planner's limits
//! ([`crate::gpu::plan`]); the split is how the job cuts itself to fit them.

use crate::gpu::plan::human_bytes;
use crate::gpu::GpuContext;
use serde::Serialize;

/// The device side of a [`MemoryPlan`].
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct DevicePlan {
    /// The adapter's name.
    pub adapter: String,
    /// The most the job holds on the device at once (bytes).
    pub peak_bytes: u64,
    /// The largest single buffer it creates (bytes).
    pub largest_buffer_bytes: u64,
    /// The planner's storage-binding limit (bytes).
    pub max_binding_bytes: u64,
    /// The adapter's own storage-binding limit (bytes).
    pub adapter_max_binding_bytes: u64,
    /// The planner's 3-D texture limit (texels per axis).
    pub max_texture_3d: u32,
    /// The limits the environment lowered, one line each.
    pub lowered: Vec<String>,
    /// The device memory a job may fill, where known (bytes).
    pub memory_bytes: Option<u64>,
}

impl DevicePlan {
    /// The device part of a plan on `ctx`.
    pub fn on(ctx: &GpuContext, peak_bytes: u64, largest_buffer_bytes: u64) -> Self {
        DevicePlan {
            adapter: ctx.summary.name.clone(),
            peak_bytes,
            largest_buffer_bytes,
            max_binding_bytes: crate::gpu::plan::binding_limit(&ctx.limits),
            adapter_max_binding_bytes: ctx.adapter_limits.max_storage_buffer_binding_size,
            max_texture_3d: ctx.limits.max_texture_dimension_3d,
            lowered: ctx.lowered.clone(),
            memory_bytes: ctx.memory.as_ref().map(|m| m.bytes),
        }
    }
}

/// What a job would allocate and how it would split, computed without doing the work.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct MemoryPlan {
    /// The job and its method ("reconstruct fdk").
    pub job: String,
    /// The backend it would run on.
    pub backend: String,
    /// The job's large host arrays at their peak (bytes).
    pub host_bytes: u64,
    /// The device side (GPU backends only).
    pub device: Option<DevicePlan>,
    /// How the work is cut, one line per split ("backprojection in 4 slabs …"); empty
    /// when it runs in one piece.
    pub split: Vec<String>,
    /// What the job would write.
    pub writes: Vec<String>,
}

impl MemoryPlan {
    /// The plan as text, one fact per line.
    pub fn describe(&self) -> String {
        let mut s = format!(
            "dry run: {} on {} (nothing is computed or written)\n\
             host:   {} at the peak\n",
            self.job,
            self.backend,
            human_bytes(self.host_bytes)
        );
        if let Some(d) = &self.device {
            s += &format!(
                "device: {} at once, the largest buffer {}, on {}\n\
                 limits: storage binding {} (adapter: {}), 3-D texture {} per axis{}\n",
                human_bytes(d.peak_bytes),
                human_bytes(d.largest_buffer_bytes),
                d.adapter,
                human_bytes(d.max_binding_bytes),
                human_bytes(d.adapter_max_binding_bytes),
                d.max_texture_3d,
                d.memory_bytes
                    .map(|m| format!(", device memory {}", human_bytes(m)))
                    .unwrap_or_default()
            );
            for l in &d.lowered {
                s += &format!("        {l}\n");
            }
        }
        if self.split.is_empty() {
            s += "split:  none (one piece)\n";
        }
        for l in &self.split {
            s += &format!("split:  {l}\n");
        }
        for w in &self.writes {
            s += &format!("would write: {w}\n");
        }
        s
    }
}
