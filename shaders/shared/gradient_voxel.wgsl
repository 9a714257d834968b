// The gradient of the voxel grid at voxel p, index space, with clamped neighbours:
// central (method 0), forward (1) or 3D Sobel (2). Imported by raycast_prepare.wgsl
// (precompute_gradients) and gradient.wgsl; reads the importer's
// `volume: texture_3d<f32>` and `params.dims` (RaycastParams, GradientParams).

// The voxel at i with clamped indices (the CPU's Grid::at_clamped).
fn voxel(i: vec3<i32>) -> f32 {
    let n = vec3<i32>(params.dims.xyz) - vec3<i32>(1);
    return textureLoad(volume, clamp(i, vec3<i32>(0), n), 0).x;
}

fn unit(a: u32, s: i32) -> vec3<i32> {
    var v = vec3<i32>(0);
    v[a] = s;
    return v;
}

// mirrors src/cpu/gradient.rs: gradient_at_voxel
fn gradient_at_voxel(p: vec3<i32>, method: u32) -> vec3<f32> {
    var g = vec3<f32>(0.0);
    if (method == 0u) {
        for (var a = 0u; a < 3u; a++) {
            g[a] = (voxel(p + unit(a, 1)) - voxel(p + unit(a, -1))) * 0.5;
        }
    } else if (method == 1u) {
        let f0 = voxel(p);
        for (var a = 0u; a < 3u; a++) {
            g[a] = voxel(p + unit(a, 1)) - f0;
        }
    } else {
        let sobel_w = array<f32, 3>(0.25, 0.5, 0.25);
        for (var a = 0u; a < 3u; a++) {
            let b = (a + 1u) % 3u;
            let c = (a + 2u) % 3u;
            var acc = 0.0;
            for (var ob = 0u; ob < 3u; ob++) {
                for (var oc = 0u; oc < 3u; oc++) {
                    let q = p + unit(b, i32(ob) - 1) + unit(c, i32(oc) - 1);
                    let d = voxel(q + unit(a, 1)) - voxel(q + unit(a, -1));
                    acc = acc + (sobel_w[ob] * sobel_w[oc]) * d;
                }
            }
            g[a] = acc * 0.5;
        }
    }
    return g;
}
