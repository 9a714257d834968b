// Phong shading, two-sided, shared by the ray caster, D²VR and the multi-volume caster.
// Reads the importer's `params.shading` (ambient, diffuse, specular, shininess) and
// `params.light` (direction; w = 1 directional, 0 headlight), members of RaycastParams
// and MultiParams alike.

#import rays

// A ray's light and half vectors.
struct LightHalf {
    l: vec3<f32>,
    h: vec3<f32>,
}

// mirrors src/cpu/shade.rs: light_half
// The light (params.light, or a headlight back along the ray) and the unit bisector of
// it and the view direction −dir.
fn light_half(dir: vec3<f32>) -> LightHalf {
    let view = -dir;
    var light = view;
    if (params.light.w == 1.0) {
        light = params.light.xyz;
    }
    return LightHalf(light, normalize_or_zero(light + view));
}

// mirrors src/cpu/shade.rs: phong (two-sided)
fn phong(c: vec3<f32>, n: vec3<f32>, l: vec3<f32>, h: vec3<f32>) -> vec3<f32> {
    let ndl = abs(dot(n, l));
    let ndh = abs(dot(n, h));
    let diffuse = params.shading.x + params.shading.y * ndl;
    var spec = 0.0;
    if (ndh > 0.0) {
        spec = params.shading.z * pow(ndh, params.shading.w);
    }
    return c * diffuse + vec3<f32>(spec);
}
