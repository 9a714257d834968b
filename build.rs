//! Records the compiler's version and the wgpu version for the benchmark report's
//! machine description (`voxlab bench`). Never fails the build: an unknown value is
//! reported as "unknown".

use std::process::Command;

fn main() {
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".to_string());
    let version = Command::new(rustc)
        .arg("--version")
        .output()
        .ok()
        .filter(|o| o.status.success())
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "unknown".to_string());
    println!("cargo:rustc-env=VOXLAB_RUSTC_VERSION={version}");

    // The resolved wgpu version from Cargo.lock, else the requirement in Cargo.toml.
    let lock = std::fs::read_to_string("Cargo.lock").unwrap_or_default();
    let mut lines = lock.lines();
    let mut wgpu = None;
    while let Some(l) = lines.next() {
        if l.trim() == "name = \"wgpu\"" {
            wgpu = lines
                .next()
                .and_then(|v| v.trim().strip_prefix("version = "))
                .map(|v| v.trim_matches('"').to_string());
            break;
        }
    }
    println!(
        "cargo:rustc-env=VOXLAB_WGPU_VERSION={}",
        wgpu.unwrap_or_else(|| "30".to_string())
    );
    println!("cargo:rerun-if-changed=Cargo.lock");
    println!("cargo:rerun-if-changed=build.rs");
}
