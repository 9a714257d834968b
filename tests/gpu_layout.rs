//! The parameter structs shared by Rust and WGSL have one layout: naga's offsets for
//! the WGSL struct equal Rust's `offset_of!` for every member, and the sizes agree.
//! Needs no GPU. Also checks that every generated shader variant validates, and that
//! every registered stage that needs no generated module validates as resolved by
//! `gpu::shaders`.

mod common;

use common::wgsl_struct_layout;

use std::mem::{offset_of, size_of};
use voxlab::gpu::raycast::{RaycastParams, PARAMS_WGSL};

#[test]
fn raycast_params_layout_agrees() {
    // The struct alone is not a complete module for naga's validator, but parsing
    // computes the layout.
    let (span, members) = wgsl_struct_layout(PARAMS_WGSL, "RaycastParams");
    assert_eq!(span as usize, size_of::<RaycastParams>(), "struct size");
    let rust: Vec<(&str, usize)> = vec![
        ("eye", offset_of!(RaycastParams, eye)),
        ("forward", offset_of!(RaycastParams, forward)),
        ("right", offset_of!(RaycastParams, right)),
        ("up", offset_of!(RaycastParams, up)),
        ("to_index_0", offset_of!(RaycastParams, to_index_0)),
        ("to_index_1", offset_of!(RaycastParams, to_index_1)),
        ("to_index_2", offset_of!(RaycastParams, to_index_2)),
        ("normal_0", offset_of!(RaycastParams, normal_0)),
        ("normal_1", offset_of!(RaycastParams, normal_1)),
        ("normal_2", offset_of!(RaycastParams, normal_2)),
        ("box_hi", offset_of!(RaycastParams, box_hi)),
        ("background", offset_of!(RaycastParams, background)),
        ("light", offset_of!(RaycastParams, light)),
        ("shading", offset_of!(RaycastParams, shading)),
        ("misc", offset_of!(RaycastParams, misc)),
        ("lut", offset_of!(RaycastParams, lut)),
        ("dims", offset_of!(RaycastParams, dims)),
        ("image", offset_of!(RaycastParams, image)),
        ("flags", offset_of!(RaycastParams, flags)),
        ("flags2", offset_of!(RaycastParams, flags2)),
        ("tf2d_a", offset_of!(RaycastParams, tf2d_a)),
        ("tf2d_b", offset_of!(RaycastParams, tf2d_b)),
        ("accel", offset_of!(RaycastParams, accel)),
        ("skip_cells", offset_of!(RaycastParams, skip_cells)),
        ("skip_tf", offset_of!(RaycastParams, skip_tf)),
        ("clip_lo", offset_of!(RaycastParams, clip_lo)),
        ("clip_hi", offset_of!(RaycastParams, clip_hi)),
        ("mode_params", offset_of!(RaycastParams, mode_params)),
        ("window", offset_of!(RaycastParams, window)),
        ("iso_flags", offset_of!(RaycastParams, iso_flags)),
        ("iso_values", offset_of!(RaycastParams, iso_values)),
        ("iso_color_0", offset_of!(RaycastParams, iso_color_0)),
        ("iso_color_1", offset_of!(RaycastParams, iso_color_1)),
        ("iso_color_2", offset_of!(RaycastParams, iso_color_2)),
        ("iso_color_3", offset_of!(RaycastParams, iso_color_3)),
        ("clip_mesh", offset_of!(RaycastParams, clip_mesh)),
        ("brick", offset_of!(RaycastParams, brick)),
        ("own_lo", offset_of!(RaycastParams, own_lo)),
        ("own_hi", offset_of!(RaycastParams, own_hi)),
        ("tile", offset_of!(RaycastParams, tile)),
    ];
    assert_eq!(members.len(), rust.len(), "member count");
    for ((wname, woff), (rname, roff)) in members.iter().zip(&rust) {
        assert_eq!(wname, rname, "member order");
        assert_eq!(*woff as usize, *roff, "offset of {rname}");
    }
}

#[test]
fn probe_params_layout_agrees() {
    let src = voxlab::gpu::probe::SHADER;
    let (span, members) = wgsl_struct_layout(src, "Params");
    assert_eq!(span as usize, size_of::<voxlab::gpu::probe::ProbeParams>());
    let offs: Vec<u32> = members.iter().map(|m| m.1).collect();
    assert_eq!(offs, vec![0, 4, 8, 12]);
}

use common::validate_wgsl;

/// Every shader variant the ray caster can generate parses and validates.
#[test]
fn every_generated_shader_validates() {
    use voxlab::settings::{Filter, GradientMethod, RenderSettings};
    let mut n = 0;
    for filter in Filter::ALL.into_iter().filter(|f| *f != Filter::Sinc) {
        for gradient in [
            GradientMethod::Central,
            GradientMethod::Forward,
            GradientMethod::Sobel,
        ] {
            for precompute in [false, true] {
                let s = RenderSettings {
                    filter,
                    gradient,
                    precompute_gradients: precompute,
                    ..RenderSettings::default()
                };
                let src = voxlab::gpu::raycast::raycast_shader(&s, None);
                validate_wgsl(&src, &format!("{filter:?} {gradient:?}"));
                n += 1;
            }
        }
    }
    // The hardware paths over compact (8/16-bit normalised) volume textures.
    for compact in [(255, 0), (65535, 0), (65535, -32768)] {
        let (range, offset) = compact;
        let c = voxlab::gpu::raycast::CompactVolume { range, offset };
        for filter in [Filter::Trilinear, Filter::BsplineFast] {
            let s = RenderSettings {
                filter,
                hardware_filtering: true,
                ..RenderSettings::default()
            };
            let src = voxlab::gpu::raycast::raycast_shader(&s, Some(c));
            let map = match compact {
                (255, 0) => "return s * 255.0;",
                (65535, 0) => "return s * 65535.0;",
                _ => "return s * 65535.0 - 32768.0;",
            };
            assert!(src.contains(map), "{c:?}");
            validate_wgsl(&src, &format!("{c:?} {filter:?}"));
        }
    }
    validate_wgsl(&voxlab::gpu::raycast::prepare_shader(), "raycast_prepare");
    assert_eq!(n, 48);
}

/// The MIDA and iso-surface variants (which import `shared/modes_cast.wgsl` instead of
/// the stubs) validate too.
#[test]
fn mode_shader_variants_validate() {
    use voxlab::settings::{Filter, Mode, RenderSettings};
    for mode in [Mode::Mida, Mode::Iso] {
        for filter in [Filter::Trilinear, Filter::Lanczos2] {
            let s = RenderSettings {
                mode,
                filter,
                ..RenderSettings::default()
            };
            let src = voxlab::gpu::raycast::raycast_shader(&s, None);
            assert!(src.contains("fn cast_mida(") && src.contains("fn in_shadow("));
            validate_wgsl(&src, &format!("{mode:?} {filter:?}"));
        }
    }
}

#[test]
fn ct_view_layout_agrees() {
    // ct_bilinear.wgsl reads the importer's `tap`: lay it out inside a complete module.
    let (span, members) = wgsl_struct_layout(&voxlab::gpu::fbp::shader_source(), "CtView");
    assert_eq!(span as usize, size_of::<voxlab::ct::ViewMatrix<f32>>());
    let offs: Vec<u32> = members.iter().map(|m| m.1).collect();
    assert_eq!(offs, vec![0, 16, 32, 48]);
}

#[test]
fn project_params_and_joseph_view_layouts_agree() {
    use voxlab::cpu::project::JosephView;
    use voxlab::gpu::project::{ProjectParams, PARAMS_WGSL as PROJECT_WGSL};
    let (span, members) = wgsl_struct_layout(PROJECT_WGSL, "ProjectParams");
    assert_eq!(span as usize, size_of::<ProjectParams>());
    let rust = [
        ("nx", offset_of!(ProjectParams, nx)),
        ("ny", offset_of!(ProjectParams, ny)),
        ("nz", offset_of!(ProjectParams, nz)),
        ("cols", offset_of!(ProjectParams, cols)),
        ("rows", offset_of!(ProjectParams, rows)),
        ("view_offset", offset_of!(ProjectParams, view_offset)),
        ("n_views", offset_of!(ProjectParams, n_views)),
        ("row_stride", offset_of!(ProjectParams, row_stride)),
        ("out_offset", offset_of!(ProjectParams, out_offset)),
        ("_pad0", offset_of!(ProjectParams, _pad0)),
        ("_pad1", offset_of!(ProjectParams, _pad1)),
        ("_pad2", offset_of!(ProjectParams, _pad2)),
    ];
    assert_eq!(members.len(), rust.len(), "member count");
    for ((wname, woff), (rname, roff)) in members.iter().zip(&rust) {
        assert_eq!(wname, rname, "member order");
        assert_eq!(*woff as usize, *roff, "offset of {rname}");
    }
    // JosephView: nine vec4<f32> rows, in the order of `JosephView::rows`.
    let (span, members) = wgsl_struct_layout(PROJECT_WGSL, "JosephView");
    assert_eq!(span as usize, size_of::<JosephView<f32>>());
    let names = ["a0", "a_u", "a_v", "d0", "d_u", "d_v", "w0", "w_u", "w_v"];
    assert_eq!(members.len(), names.len());
    for (i, ((wname, woff), rname)) in members.iter().zip(names).enumerate() {
        assert_eq!(wname, rname);
        assert_eq!(*woff as usize, i * 16);
    }
}

#[test]
fn transpose_params_and_joseph_footprint_layouts_agree() {
    use voxlab::cpu::project::JosephFootprint;
    use voxlab::gpu::joseph_pair::TransposeParams;
    use voxlab::gpu::project::PARAMS_WGSL as PROJECT_WGSL;
    let (span, members) = wgsl_struct_layout(PROJECT_WGSL, "TransposeParams");
    assert_eq!(span as usize, size_of::<TransposeParams>());
    let rust = [
        ("nx", offset_of!(TransposeParams, nx)),
        ("ny", offset_of!(TransposeParams, ny)),
        ("nz", offset_of!(TransposeParams, nz)),
        ("cols", offset_of!(TransposeParams, cols)),
        ("rows", offset_of!(TransposeParams, rows)),
        ("voxel_offset", offset_of!(TransposeParams, voxel_offset)),
        ("n_voxels", offset_of!(TransposeParams, n_voxels)),
        ("slot_lo", offset_of!(TransposeParams, slot_lo)),
        ("slot_hi", offset_of!(TransposeParams, slot_hi)),
        ("accumulate", offset_of!(TransposeParams, accumulate)),
        ("row_stride", offset_of!(TransposeParams, row_stride)),
        ("out_base", offset_of!(TransposeParams, out_base)),
    ];
    assert_eq!(members.len(), rust.len(), "member count");
    for ((wname, woff), (rname, roff)) in members.iter().zip(&rust) {
        assert_eq!(wname, rname, "member order");
        assert_eq!(*woff as usize, *roff, "offset of {rname}");
    }
    // JosephFootprint: three vec4<f32> rows, in the order of `JosephFootprint::rows`.
    let (span, members) = wgsl_struct_layout(PROJECT_WGSL, "JosephFootprint");
    assert_eq!(span as usize, size_of::<JosephFootprint<f32>>());
    let names = ["c", "r", "t"];
    assert_eq!(members.len(), names.len());
    for (i, ((wname, woff), rname)) in members.iter().zip(names).enumerate() {
        assert_eq!(wname, rname);
        assert_eq!(*woff as usize, i * 16);
    }
}

#[test]
fn project_shader_validates() {
    validate_wgsl(&voxlab::gpu::project::shader_source(), "project.wgsl");
}

#[test]
fn fbp_params_layout_agrees() {
    use voxlab::gpu::fbp::{shader_source, FbpParams};
    let (span, members) = wgsl_struct_layout(&shader_source(), "FbpParams");
    assert_eq!(span as usize, size_of::<FbpParams>(), "struct size");
    let rust: Vec<(&str, usize)> = vec![
        ("origin", offset_of!(FbpParams, origin)),
        ("step_i", offset_of!(FbpParams, step_i)),
        ("step_j", offset_of!(FbpParams, step_j)),
        ("step_k", offset_of!(FbpParams, step_k)),
        ("dims", offset_of!(FbpParams, dims)),
        ("det", offset_of!(FbpParams, det)),
        ("scale", offset_of!(FbpParams, scale)),
        ("slab", offset_of!(FbpParams, slab)),
    ];
    for ((name, off), (wname, woff)) in rust.iter().zip(&members) {
        assert_eq!((*name, *off as u32), (wname.as_str(), *woff));
    }
    assert_eq!(members.len(), rust.len());
}

/// Both ways of reading the filtered projections make a valid backprojector, and only
/// the exact one carries the storage buffer and shared/ct_bilinear.wgsl.
#[test]
fn both_backprojector_variants_validate() {
    use voxlab::gpu::fbp::sampled_shader_source;
    use voxlab::gpu::plan::Sampling;
    for (sampling, buffer) in [(Sampling::Exact, true), (Sampling::Hardware, false)] {
        let src = sampled_shader_source(sampling);
        validate_wgsl(&src, &format!("backprojection {sampling:?}"));
        assert_eq!(src.contains("fn bilinear_zero("), buffer, "{sampling:?}");
        assert_eq!(
            src.contains("texture_2d_array<f32>"),
            !buffer,
            "{sampling:?}"
        );
    }
}

/// Both ways of reading Joseph's grid make a valid projector, and only the exact one
/// carries the storage buffer and shared/joseph_bilinear.wgsl.
#[test]
fn both_projector_variants_validate() {
    use voxlab::gpu::plan::Sampling;
    use voxlab::gpu::project::sampled_shader_source;
    for (sampling, buffer) in [(Sampling::Exact, true), (Sampling::Hardware, false)] {
        let src = sampled_shader_source(sampling);
        validate_wgsl(&src, &format!("projection {sampling:?}"));
        assert_eq!(src.contains("fn slice_bilinear("), buffer, "{sampling:?}");
        assert_eq!(src.contains("texture_3d<f32>"), !buffer, "{sampling:?}");
    }
}

#[test]
fn ramp_params_layout_agrees() {
    use voxlab::gpu::ramp::{shader_source, RampParams};
    let (span, members) = wgsl_struct_layout(&shader_source(), "RampParams");
    assert_eq!(span as usize, size_of::<RampParams>(), "struct size");
    let rust: Vec<(&str, usize)> = vec![
        ("dims", offset_of!(RampParams, dims)),
        ("work", offset_of!(RampParams, work)),
        ("detector", offset_of!(RampParams, detector)),
        ("cone", offset_of!(RampParams, cone)),
    ];
    for ((name, off), (wname, woff)) in rust.iter().zip(&members) {
        assert_eq!((*name, *off as u32), (wname.as_str(), *woff));
    }
    assert_eq!(members.len(), rust.len());
}

#[test]
fn ramp_view_layout_agrees() {
    use voxlab::gpu::ramp::{shader_source, RampViewGpu};
    let (span, members) = wgsl_struct_layout(&shader_source(), "RampViewGpu");
    assert_eq!(span as usize, size_of::<RampViewGpu>(), "struct size");
    let rust: Vec<(&str, usize)> = vec![
        ("r", offset_of!(RampViewGpu, r)),
        ("u", offset_of!(RampViewGpu, u)),
        ("v", offset_of!(RampViewGpu, v)),
    ];
    for ((name, off), (wname, woff)) in rust.iter().zip(&members) {
        assert_eq!((*name, *off as u32), (wname.as_str(), *woff));
    }
    assert_eq!(members.len(), rust.len());
}

#[test]
fn process_params_layout_agrees() {
    use voxlab::gpu::process::{ProcessParams, PARAMS_WGSL};
    let (span, members) = wgsl_struct_layout(PARAMS_WGSL, "ProcessParams");
    assert_eq!(span as usize, size_of::<ProcessParams>(), "struct size");
    let rust: Vec<(&str, usize)> = vec![
        ("in_dims", offset_of!(ProcessParams, in_dims)),
        ("out_dims", offset_of!(ProcessParams, out_dims)),
        ("op", offset_of!(ProcessParams, op)),
        ("m0", offset_of!(ProcessParams, m0)),
        ("m1", offset_of!(ProcessParams, m1)),
        ("m2", offset_of!(ProcessParams, m2)),
    ];
    assert_eq!(members.len(), rust.len(), "member count");
    for ((wname, woff), (rname, roff)) in members.iter().zip(&rust) {
        assert_eq!(wname, rname, "member order");
        assert_eq!(*woff as usize, *roff, "offset of {rname}");
    }
}

#[test]
fn gradient_params_layout_agrees() {
    use voxlab::gpu::gradient::{GradientParams, PARAMS_WGSL};
    let (span, members) = wgsl_struct_layout(PARAMS_WGSL, "GradientParams");
    assert_eq!(span as usize, size_of::<GradientParams>(), "struct size");
    let rust: Vec<(&str, usize)> = vec![
        ("dims", offset_of!(GradientParams, dims)),
        ("slab", offset_of!(GradientParams, slab)),
    ];
    assert_eq!(members.len(), rust.len(), "member count");
    for ((wname, woff), (rname, roff)) in members.iter().zip(&rust) {
        assert_eq!(wname, rname, "member order");
        assert_eq!(*woff as usize, *roff, "offset of {rname}");
    }
}

#[test]
fn parker_params_layout_agrees() {
    use voxlab::gpu::parker::{ParkerParams, PARAMS_WGSL};
    let (span, members) = wgsl_struct_layout(PARAMS_WGSL, "ParkerParams");
    assert_eq!(span as usize, size_of::<ParkerParams>(), "struct size");
    let rust: Vec<(&str, usize)> = vec![
        ("dims", offset_of!(ParkerParams, dims)),
        ("detector", offset_of!(ParkerParams, detector)),
        ("scan", offset_of!(ParkerParams, scan)),
        ("work", offset_of!(ParkerParams, work)),
    ];
    assert_eq!(members.len(), rust.len(), "member count");
    for ((wname, woff), (rname, roff)) in members.iter().zip(&rust) {
        assert_eq!(wname, rname, "member order");
        assert_eq!(*woff as usize, *roff, "offset of {rname}");
    }
}

#[test]
fn radon_params_layout_agrees() {
    use voxlab::gpu::radon::{RadonParams, PARAMS_WGSL};
    let (span, members) = wgsl_struct_layout(PARAMS_WGSL, "RadonParams");
    assert_eq!(span as usize, size_of::<RadonParams>(), "struct size");
    let rust: Vec<(&str, usize)> = vec![
        ("dims", offset_of!(RadonParams, dims)),
        ("work", offset_of!(RadonParams, work)),
        ("scale", offset_of!(RadonParams, scale)),
    ];
    assert_eq!(members.len(), rust.len(), "member count");
    for ((wname, woff), (rname, roff)) in members.iter().zip(&rust) {
        assert_eq!(wname, rname, "member order");
        assert_eq!(*woff as usize, *roff, "offset of {rname}");
    }
}

#[test]
fn sart_ray_layout_agrees() {
    use voxlab::gpu::radon::{sart_shader_source, SartRayGpu};
    let src = sart_shader_source();
    let (span, members) = wgsl_struct_layout(&src, "SartRayGpu");
    assert_eq!(span as usize, size_of::<SartRayGpu>(), "struct size");
    let rust: Vec<(&str, usize)> = vec![
        ("ds", offset_of!(SartRayGpu, ds)),
        ("dx", offset_of!(SartRayGpu, dx)),
        ("dy", offset_of!(SartRayGpu, dy)),
        ("x0", offset_of!(SartRayGpu, x0)),
        ("y0", offset_of!(SartRayGpu, y0)),
        ("ns", offset_of!(SartRayGpu, ns)),
        ("window", offset_of!(SartRayGpu, window)),
        ("live", offset_of!(SartRayGpu, live)),
    ];
    assert_eq!(members.len(), rust.len(), "member count");
    for ((wname, woff), (rname, roff)) in members.iter().zip(&rust) {
        assert_eq!(wname, rname, "member order");
        assert_eq!(*woff as usize, *roff, "offset of {rname}");
    }
}

/// The Parker shader parses and validates.
#[test]
fn parker_shader_validates() {
    validate_wgsl(&voxlab::gpu::parker::shader_source(), "parker.wgsl");
}

/// The gradient-volume shader parses and validates.
#[test]
fn gradient_shader_validates() {
    validate_wgsl(&voxlab::gpu::gradient::shader_source(), "gradient.wgsl");
}

/// Every processing shader parses and validates.
#[test]
fn process_shaders_validate() {
    use voxlab::gpu::process::*;
    for name in SHADERS {
        validate_wgsl(&shader_source(name), name);
    }
}

#[test]
fn adaptive_params_layout_agrees() {
    use voxlab::gpu::adaptive::{AdaptiveParams, PARAMS_WGSL};
    let (span, members) = wgsl_struct_layout(PARAMS_WGSL, "AdaptiveParams");
    assert_eq!(span as usize, size_of::<AdaptiveParams>(), "struct size");
    let rust: Vec<(&str, usize)> = vec![
        ("steps", offset_of!(AdaptiveParams, steps)),
        ("window", offset_of!(AdaptiveParams, window)),
        ("spectrum", offset_of!(AdaptiveParams, spectrum)),
        ("background", offset_of!(AdaptiveParams, background)),
        ("dims", offset_of!(AdaptiveParams, dims)),
        ("image", offset_of!(AdaptiveParams, image)),
        ("table", offset_of!(AdaptiveParams, table)),
        ("extra", offset_of!(AdaptiveParams, extra)),
        ("brick", offset_of!(AdaptiveParams, brick)),
        ("own_lo", offset_of!(AdaptiveParams, own_lo)),
        ("own_hi", offset_of!(AdaptiveParams, own_hi)),
    ];
    assert_eq!(members.len(), rust.len(), "member count");
    for ((wname, woff), (rname, roff)) in members.iter().zip(&rust) {
        assert_eq!(wname, rname, "member order");
        assert_eq!(*woff as usize, *roff, "offset of {rname}");
    }
}

#[test]
fn multi_params_layout_agrees() {
    use voxlab::gpu::multi::{MultiParams, PARAMS_WGSL};
    let (span, members) = wgsl_struct_layout(PARAMS_WGSL, "MultiParams");
    assert_eq!(span as usize, size_of::<MultiParams>(), "struct size");
    let rust: Vec<(&str, usize)> = vec![
        ("eye", offset_of!(MultiParams, eye)),
        ("forward", offset_of!(MultiParams, forward)),
        ("right", offset_of!(MultiParams, right)),
        ("up", offset_of!(MultiParams, up)),
        ("background", offset_of!(MultiParams, background)),
        ("light", offset_of!(MultiParams, light)),
        ("shading", offset_of!(MultiParams, shading)),
        ("misc", offset_of!(MultiParams, misc)),
        ("image", offset_of!(MultiParams, image)),
        ("flags", offset_of!(MultiParams, flags)),
        ("to_index", offset_of!(MultiParams, to_index)),
        ("normal", offset_of!(MultiParams, normal)),
        ("box_hi", offset_of!(MultiParams, box_hi)),
        ("lut", offset_of!(MultiParams, lut)),
        ("dims", offset_of!(MultiParams, dims)),
        ("gradient", offset_of!(MultiParams, gradient)),
        ("origin", offset_of!(MultiParams, origin)),
        ("own_lo", offset_of!(MultiParams, own_lo)),
        ("own_hi", offset_of!(MultiParams, own_hi)),
        ("carry", offset_of!(MultiParams, carry)),
        ("tile", offset_of!(MultiParams, tile)),
    ];
    assert_eq!(members.len(), rust.len(), "member count");
    for ((wname, woff), (rname, roff)) in members.iter().zip(&rust) {
        assert_eq!(wname, rname, "member order");
        assert_eq!(*woff as usize, *roff, "offset of {rname}");
    }
}

/// The multi-volume shader parses and validates.
#[test]
fn multi_shader_validates() {
    validate_wgsl(&voxlab::gpu::multi::multi_shader(), "multi.wgsl");
}

/// Every registered module with an entry point (a stage) that imports no generated
/// module parses and validates as `gpu::shaders::resolve` assembles it; the stages
/// with generated modules are validated above and in their families' tests.
#[test]
fn every_resolved_stage_validates() {
    use voxlab::gpu::shaders::{resolve, try_resolve, MODULES};
    let mut n = 0;
    for m in MODULES.iter().filter(|m| m.source.contains("@compute")) {
        if try_resolve(m.name, &[]).is_err() {
            continue;
        }
        validate_wgsl(&resolve(m.name), m.path);
        n += 1;
    }
    // raycast, d2vr, fvr_slice, fbp_backproject and project need generated modules.
    assert_eq!(
        n,
        MODULES
            .iter()
            .filter(|m| m.source.contains("@compute"))
            .count()
            - 5
    );
}

#[test]
fn solve_params_layout_agrees() {
    use voxlab::gpu::iterative::{SolveParams, PARAMS_WGSL};
    let (span, members) = wgsl_struct_layout(PARAMS_WGSL, "SolveParams");
    assert_eq!(span as usize, size_of::<SolveParams>());
    let rust = [
        ("n", offset_of!(SolveParams, n)),
        ("per_view", offset_of!(SolveParams, per_view)),
        ("row_stride", offset_of!(SolveParams, row_stride)),
        ("term", offset_of!(SolveParams, term)),
        ("nx", offset_of!(SolveParams, nx)),
        ("ny", offset_of!(SolveParams, ny)),
        ("nz", offset_of!(SolveParams, nz)),
        ("n_axes", offset_of!(SolveParams, n_axes)),
        ("axis0", offset_of!(SolveParams, axis0)),
        ("axis1", offset_of!(SolveParams, axis1)),
        ("axis2", offset_of!(SolveParams, axis2)),
        ("nonnegative", offset_of!(SolveParams, nonnegative)),
        ("slot0", offset_of!(SolveParams, slot0)),
        ("slot1", offset_of!(SolveParams, slot1)),
        ("slot2", offset_of!(SolveParams, slot2)),
        ("_pad0", offset_of!(SolveParams, _pad0)),
        ("f0", offset_of!(SolveParams, f0)),
        ("f1", offset_of!(SolveParams, f1)),
        ("f2", offset_of!(SolveParams, f2)),
        ("_pad1", offset_of!(SolveParams, _pad1)),
    ];
    assert_eq!(members.len(), rust.len(), "member count");
    for ((wname, woff), (rname, roff)) in members.iter().zip(&rust) {
        assert_eq!(wname, rname, "member order");
        assert_eq!(*woff as usize, *roff, "offset of {rname}");
    }
}
