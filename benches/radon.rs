//! `cargo bench --bench radon`: scikit-image's Radon transform and its inverse as the
//! library computes them (`jobs::radon`, the code behind `voxlab.transform.radon` and
//! `iradon`), on the CPU in f64 and f32 and on the GPU when an adapter is found.
//!
//! Cases: the radon of a random `n²` disc image at 180 angles, the iradon of its
//! `(n, 180)` sinogram onto `n²` (`circle=True`, ramp filter) for each interpolation,
//! and one iteration of `iradon_sart` on it (relaxation 0.15);
//! `n` = 256 (the size of docs/bench/python-overhead.md and of scikit-image's timings
//! there). Times are whole job calls (filtering included), medians of
//! `VOXLAB_BENCH_RUNS` (default 5) runs after one warm-up, in milliseconds. Under
//! `cargo test` (no `--bench`) each case runs once at a tiny size.

mod common;
use common::{median_min_max, BenchArgs};

use std::time::Instant;
use voxlab::cpu::radon::{rotation, Interpolation};
use voxlab::cpu::ramp::RampFilter;
use voxlab::jobs::radon::{iradon, iradon_sart, radon, IradonOptions, SartOptions};
use voxlab::jobs::Backend;

fn timed<T>(args: &BenchArgs, mut f: impl FnMut() -> T) -> (f64, f64, f64) {
    let mut t = Vec::new();
    for run in 0..=args.runs {
        let t0 = Instant::now();
        std::hint::black_box(f());
        if run > 0 {
            t.push(t0.elapsed().as_secs_f64() * 1e3);
        }
    }
    median_min_max(t)
}

fn main() {
    let args = BenchArgs::from_env();
    let gpu = voxlab::gpu::GpuContext::shared().is_ok();
    let n = if args.smoke { 24 } else { 256 };
    let angles = if args.smoke { 12 } else { 180 };
    let theta: Vec<f64> = (0..angles)
        .map(|k| 180.0 * k as f64 / angles as f64)
        .collect();
    let trig: Vec<(f64, f64)> = theta
        .iter()
        .map(|d| (d.to_radians().cos(), d.to_radians().sin()))
        .collect();
    // A random disc image (radon's circle rule), xorshift for a fixed seed.
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let r = (n / 2) as i64;
    let image: Vec<f64> = (0..n * n)
        .map(|i| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let (y, x) = ((i / n) as i64 - r, (i % n) as i64 - r);
            if x * x + y * y > r * r {
                0.0
            } else {
                (state >> 11) as f64 / (1u64 << 53) as f64
            }
        })
        .collect();
    let maps: Vec<[f64; 6]> = trig.iter().map(|&(c, s)| rotation(n, c, s)).collect();
    let mut backends = vec![("f64", Backend::Cpu), ("f32", Backend::CpuF32)];
    if gpu {
        backends.push(("GPU f32", Backend::Gpu));
    }
    println!("| case | backend | median ms | min | max |\n|---|---|---|---|---|");
    let name = format!("radon {n}² at {angles} angles");
    if args.wants(&name) {
        let image32: Vec<f32> = image.iter().map(|&v| v as f32).collect();
        for &(label, b) in &backends {
            let t = if b == Backend::Cpu {
                timed(&args, || radon(&image, n, n, &maps, true, b, &()).unwrap())
            } else {
                timed(&args, || {
                    radon(&image32, n, n, &maps, true, b, &()).unwrap()
                })
            };
            println!(
                "| {name} | {label} | {:.1} | {:.1} | {:.1} |",
                t.0, t.1, t.2
            );
        }
    }
    let sino = radon(&image, n, n, &maps, true, Backend::Cpu, &()).unwrap();
    let name = format!("iradon_sart {n}² from {angles} views, one iteration");
    if args.wants(&name) {
        let sino32: Vec<f32> = sino.data.iter().map(|&v| v as f32).collect();
        let theta32: Vec<f32> = theta.iter().map(|&v| v as f32).collect();
        for &(label, b) in &backends {
            let t = if b == Backend::Cpu {
                let o = SartOptions {
                    image: None,
                    shifts: None,
                    clip: None,
                    relaxation: 0.15,
                };
                timed(&args, || {
                    iradon_sart(&sino.data, n, &theta, &o, b, &()).unwrap()
                })
            } else {
                let o = SartOptions {
                    image: None,
                    shifts: None,
                    clip: None,
                    relaxation: 0.15,
                };
                timed(&args, || {
                    iradon_sart(&sino32, n, &theta32, &o, b, &()).unwrap()
                })
            };
            println!(
                "| {name} | {label} | {:.1} | {:.1} | {:.1} |",
                t.0, t.1, t.2
            );
        }
    }
    for kind in [
        Interpolation::Linear,
        Interpolation::Nearest,
        Interpolation::Cubic,
    ] {
        let name = format!("iradon {n}² from {angles} views, {kind}");
        if !args.wants(&name) {
            continue;
        }
        let options = IradonOptions {
            output_size: n,
            filter: RampFilter::RamLak,
            interpolation: kind,
            circle: true,
        };
        for &(label, b) in &backends {
            let t = timed(&args, || {
                iradon::<f64>(&sino.data, n, &theta, Some(&trig), &options, b, &()).unwrap()
            });
            println!(
                "| {name} | {label} | {:.1} | {:.1} | {:.1} |",
                t.0, t.1, t.2
            );
        }
    }
}
