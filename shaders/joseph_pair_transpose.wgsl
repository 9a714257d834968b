// The exact transpose of Joseph's projector as a gather, one invocation per voxel:
// for every view of the list (in order), the detector pixels whose rays can touch the
// voxel (the view's footprint map, widened by MARGIN pixels against f32 rounding:
// a pixel whose ray misses the voxel adds weight 0), each weighted by joseph_weight,
// the number the forward pass multiplies the voxel by.
// Mirrors src/cpu/project.rs: JosephPair::transpose_voxel; the host side is
// src/gpu/joseph_pair.rs.

#import project_params
#import joseph

@group(0) @binding(0) var<uniform> tp: TransposeParams;
@group(0) @binding(1) var<storage, read> views: array<JosephView>;
@group(0) @binding(2) var<storage, read> footprints: array<JosephFootprint>;
// Per view: the driving axis every ray of the view shares, or 3 when they differ.
@group(0) @binding(3) var<storage, read> axes: array<u32>;
// The views, in the order of the projections' slots.
@group(0) @binding(4) var<storage, read> list: array<u32>;
// [slot][row][col]
@group(0) @binding(5) var<storage, read> proj: array<f32>;
// [z][y][x], from voxel out_base on
@group(0) @binding(6) var<storage, read_write> out: array<f32>;

const WORKGROUP: u32 = 64u;
// The half-size of the voxel's box (src/cpu/project.rs: FOOTPRINT_HALF).
const HALF: f32 = 0.999999999;
// Extra pixels on every side of the box.
const MARGIN: f32 = 1.0;

// The pixels (c0, c1, r0, r1) whose rays can pass through the box of half-sizes h
// about x; c0 > c1 when none can.
// mirrors src/cpu/project.rs: pixels_box
fn footprint_box(f: JosephFootprint, x: vec3<f32>, h: vec3<f32>) -> vec4<i32> {
    let empty = vec4<i32>(1, 0, 1, 0);
    let cc = dot(f.c.xyz, x) + f.c.w;
    let hc = dot(h, abs(f.c.xyz));
    let rc = dot(f.r.xyz, x) + f.r.w;
    let hr = dot(h, abs(f.r.xyz));
    let tc = dot(f.t.xyz, x) + f.t.w;
    let ht = dot(h, abs(f.t.xyz));
    var clo = 0.0;
    var chi = f32(tp.cols - 1u);
    var rlo = 0.0;
    var rhi = f32(tp.rows - 1u);
    let parallel = all(f.t == vec4<f32>(0.0, 0.0, 0.0, 1.0));
    if parallel {
        clo = cc - hc;
        chi = cc + hc;
        rlo = rc - hr;
        rhi = rc + hr;
    } else {
        let dlo = tc - ht;
        let dhi = tc + ht;
        if dlo > 1e-6 * max(abs(dhi), 1.0) {
            let qc = vec4<f32>((cc - hc) / dlo, (cc - hc) / dhi, (cc + hc) / dlo, (cc + hc) / dhi);
            let qr = vec4<f32>((rc - hr) / dlo, (rc - hr) / dhi, (rc + hr) / dlo, (rc + hr) / dhi);
            clo = min(min(qc.x, qc.y), min(qc.z, qc.w));
            chi = max(max(qc.x, qc.y), max(qc.z, qc.w));
            rlo = min(min(qr.x, qr.y), min(qr.z, qr.w));
            rhi = max(max(qr.x, qr.y), max(qr.z, qr.w));
        }
    }
    let c0 = max(ceil(clo) - MARGIN, 0.0);
    let c1 = min(floor(chi) + MARGIN, f32(tp.cols - 1u));
    let r0 = max(ceil(rlo) - MARGIN, 0.0);
    let r1 = min(floor(rhi) + MARGIN, f32(tp.rows - 1u));
    // Also false for NaN.
    if !(c0 <= c1 && r0 <= r1) {
        return empty;
    }
    return vec4<i32>(i32(c0), i32(c1), i32(r0), i32(r1));
}

@compute @workgroup_size(WORKGROUP)
fn transpose(@builtin(global_invocation_id) gid: vec3<u32>) {
    let id = gid.x + gid.y * tp.row_stride;
    if id >= tp.n_voxels {
        return;
    }
    let vi = tp.voxel_offset + id;
    let v = vec3<u32>(vi % tp.nx, (vi / tp.nx) % tp.ny, vi / (tp.nx * tp.ny));
    let dims = vec3<u32>(tp.nx, tp.ny, tp.nz);
    let x = vec3<f32>(v);
    let per_view = tp.cols * tp.rows;
    var acc = 0.0;
    if tp.accumulate != 0u {
        acc = out[vi - tp.out_base];
    }
    for (var slot = tp.slot_lo; slot < tp.slot_hi; slot++) {
        let k = list[slot];
        var h = vec3<f32>(HALF);
        let ax = axes[k];
        if ax < 3u {
            h[ax] = 0.0;
        }
        let b = footprint_box(footprints[k], x, h);
        let view = views[k];
        let base = slot * per_view;
        var part = 0.0;
        for (var row = b.z; row <= b.w; row++) {
            for (var col = b.x; col <= b.y; col++) {
                let yv = proj[base + u32(row) * tp.cols + u32(col)];
                if yv == 0.0 {
                    continue;
                }
                let r = pixel_ray(view, f32(col), f32(row));
                part += joseph_weight(joseph_planes(dims, r.o, r.d, r.t_min), v) * yv;
            }
        }
        acc += part;
    }
    out[vi - tp.out_base] = acc;
}
