//! The benchmark cases of the ray caster, the gradient volume and D²VR: every quick case
//! prepares, its f32 CPU and GPU results pass their tolerances against the f64 oracle,
//! and the work it claims is right for one case counted by hand.

mod common;

use voxlab::bench::{self, Case, Prepared, Suite, Unit, Work};
use voxlab::metrics::Tolerance;

/// Holds `port` to `oracle` within `tol` (max |port − oracle| / max |oracle| and
/// ‖port − oracle‖ / ‖oracle‖, as the runner checks them: `metrics::check_parity_array`);
/// prints the errors, and on failure leaves `target/parity/<id what>/`.
fn within(id: &str, what: &str, oracle: &[f64], port: &[f64], tol: Tolerance) {
    let name = format!("{id} {what}");
    let dir = common::parity_dir(&name);
    let r =
        voxlab::metrics::check_parity_array(&name, &[oracle.len()], oracle, port, tol, Some(&dir))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
    eprintln!(
        "{id} {what}: max rel {:.2e} (bound {:.1e}), rel L2 {:.2e} (bound {:.1e})",
        r.stats.max_abs_rel, tol.max_abs_rel, r.stats.rel_l2, tol.rel_l2
    );
    assert!(r.passed, "{}", r.message);
}

/// Prepares every quick case of `family`, runs each backend once and checks it against
/// the oracle. Returns how many cases ran.
fn check_family(family: &str) -> usize {
    let cases: Vec<Case> = bench::cases(Suite::Quick)
        .into_iter()
        .filter(|c| c.family == family)
        .collect();
    assert!(!cases.is_empty(), "no quick {family} cases");
    let ctx = common::gpu(&format!("bench_render {family}"));
    for case in &cases {
        let id = case.id();
        let mut p: Prepared = (case.prepare)().unwrap_or_else(|e| panic!("{id}: {e}"));
        assert!(!p.work.is_empty(), "{id}: no work");
        assert!(p.work.iter().all(|w| w.amount > 0.0), "{id}: {:?}", p.work);
        let oracle = (p.cpu_f64)().unwrap();
        assert!(oracle.seconds >= 0.0 && !oracle.output.is_empty());
        assert!(
            oracle.output.iter().any(|&v| v != 0.0),
            "{id}: blank oracle"
        );
        if let Some(f32_run) = p.cpu_f32.as_mut() {
            let r = f32_run().unwrap();
            within(&id, "cpu f32", &oracle.output, &r.output, p.tol_f32);
        }
        if let (Some(gpu_run), Some(ctx)) = (p.gpu.as_mut(), ctx) {
            let r = gpu_run(ctx).unwrap_or_else(|e| panic!("{id} gpu: {e}"));
            assert!(
                r.kernel > 0.0 && r.end_to_end >= r.kernel * 0.5,
                "{id}: {r:?}"
            );
            within(&id, "gpu", &oracle.output, &r.output, p.tol_gpu);
        }
    }
    cases.len()
}

/// One test per family, from one list.
macro_rules! family_tests {
    ($($name:ident: $family:expr;)*) => {
        $(
            #[test]
            fn $name() {
                assert!(check_family($family) > 0);
            }
        )*
    };
}

family_tests! {
    raycast_quick_cases_match_the_oracle: "raycast";
    gradient_quick_cases_match_the_oracle: "gradient";
    d2vr_quick_cases_match_the_oracle: "d2vr";
}

fn work(p: &Prepared, unit: Unit) -> f64 {
    p.work
        .iter()
        .find(|w: &&Work| w.unit == unit)
        .unwrap_or_else(|| panic!("no {unit:?} in {:?}", p.work))
        .amount
}

fn quick(family: &str, name: &str) -> Prepared {
    let case = bench::cases(Suite::Quick)
        .into_iter()
        .find(|c| c.family == family && c.name == name)
        .unwrap_or_else(|| panic!("no quick {family}/{name}"));
    (case.prepare)().unwrap()
}

#[test]
fn work_is_counted_right() {
    use voxlab::bench::d2vr::{d2vr_scene, TINY};
    use voxlab::bench::raycast::raycast_scene;
    use voxlab::settings::RenderSettings;
    // Ray caster, 32³ → 48²: one ray per pixel; samples as the oracle counts them.
    let p = quick("raycast", "dvr-shaded-trilinear");
    assert_eq!(work(&p, Unit::Rays), (48 * 48) as f64);
    let (vol, tf, cam) = raycast_scene(32, 48).unwrap();
    let s = RenderSettings {
        sample_count: true,
        ..RenderSettings::default()
    };
    let out = voxlab::cpu::raycast::render::<f64>(&vol, &tf, &cam, &s, &|_, _| {}).unwrap();
    let per_ray: f64 = out.samples.unwrap().data.iter().sum();
    assert_eq!(work(&p, Unit::Samples), per_ray);
    // At most one sample per half voxel along the 32·√3 diagonal, on every ray.
    assert!(per_ray <= (48 * 48) as f64 * (32.0 * 3f64.sqrt() / 0.5 + 2.0));
    // Gradient, 32³: one update per voxel, 4 B read + 3 × 4 B written.
    let p = quick("gradient", "central-differences");
    assert_eq!(work(&p, Unit::VoxelUpdates), 32768.0);
    assert_eq!(work(&p, Unit::Bytes), 16.0 * 32768.0);
    // D²VR, 32² image: rays; samples of the plain march through the 16³ box.
    let p = quick("d2vr", "tiny-gfs");
    assert_eq!(work(&p, Unit::Rays), 1024.0);
    let sc = d2vr_scene(&TINY).unwrap();
    let box_samples = voxlab::cpu::d2vr::box_samples(sc.grid.dims, sc.grid.affine, &sc.camera, 1.0);
    assert_eq!(work(&p, Unit::Samples), box_samples as f64);
    // The orthographic view sees the whole box: every ray hits it, at most 16·√3 + 1
    // samples each, and at least one.
    assert!(box_samples >= 1024 && box_samples as f64 <= 1024.0 * (16.0 * 3f64.sqrt() + 1.0));
}

#[test]
fn ids_are_unique_and_families_known() {
    for suite in [Suite::Quick, Suite::Full] {
        let cases: Vec<Case> = bench::cases(suite)
            .into_iter()
            .filter(|c| ["raycast", "gradient", "d2vr"].contains(&c.family))
            .collect();
        let mut ids: Vec<String> = cases.iter().map(|c| c.id()).collect();
        let n = ids.len();
        ids.sort();
        ids.dedup();
        assert_eq!(ids.len(), n, "{suite:?}: duplicate ids");
        for f in ["raycast", "gradient", "d2vr"] {
            assert!(cases.iter().any(|c| c.family == f), "{suite:?}: no {f}");
            assert!(bench::FAMILIES.contains(&f));
        }
    }
}
