// Phong shading, two-sided, shared by the ray caster, D²VR and the multi-volume caster.
// Reads the importer's `params.shading` (ambient, diffuse, specular, shininess), a
// member of RaycastParams and MultiParams alike.

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
