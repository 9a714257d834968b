// The camera's primary rays, the same for every caster that builds them on the device
// (shaders/raycast.wgsl, d2vr.wgsl, clipmesh.wgsl, multi.wgsl). Reads the importer's
// `params` uniform: eye, forward, right, up and image, the members of RaycastParams
// (shaders/shared/raycast_params.wgsl) that MultiParams (multi_params.wgsl) repeats
// under the same names.

#import rays

// mirrors src/camera.rs: Camera::ray (pixel centres at +0.5)
fn camera_ray(col: u32, row: u32) -> Ray {
    let u = (f32(col) + 0.5) / f32(params.image.x) - 0.5;
    let v = 0.5 - (f32(row) + 0.5) / f32(params.image.y);
    var r: Ray;
    if (params.eye.w == 1.0) {
        let h = params.forward.w;
        let aspect = params.right.w;
        r.origin = params.eye.xyz;
        r.dir = normalize(params.forward.xyz + params.right.xyz * (2.0 * u * h * aspect) + params.up.xyz * (2.0 * v * h));
        r.t_min = 0.0;
    } else {
        r.origin = params.eye.xyz + params.right.xyz * (u * params.right.w) + params.up.xyz * (v * params.up.w);
        r.dir = params.forward.xyz;
        r.t_min = -BIG;
    }
    return r;
}

