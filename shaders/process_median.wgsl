// 3-D median filter (cubic window k ≤ 5, reflect rule), one invocation per voxel.
// Mirrors src/cpu/process.rs: median; the host side is src/gpu/process.rs.

#import process_params

const MAX_WINDOW: u32 = 125u;

// The median of the k³ window around v (k = params.op.x): gather, then a partial
// selection sort up to the middle element. Mirrors src/cpu/process.rs: median_at.
fn median_at(v: vec3<u32>) -> f32 {
    var buf: array<f32, MAX_WINDOW>;
    let k = i32(params.op.x);
    let r = k / 2;
    var n = 0u;
    for (var dz = -r; dz <= r; dz = dz + 1) {
        let z = reflect_index(i32(v.z) + dz, params.in_dims.z);
        for (var dy = -r; dy <= r; dy = dy + 1) {
            let y = reflect_index(i32(v.y) + dy, params.in_dims.y);
            for (var dx = -r; dx <= r; dx = dx + 1) {
                let x = reflect_index(i32(v.x) + dx, params.in_dims.x);
                buf[n] = in_at(x, y, z);
                n = n + 1u;
            }
        }
    }
    let mid = n / 2u;
    for (var a = 0u; a <= mid; a = a + 1u) {
        var best = a;
        for (var b = a + 1u; b < n; b = b + 1u) {
            if buf[b] < buf[best] {
                best = b;
            }
        }
        let t = buf[a];
        buf[a] = buf[best];
        buf[best] = t;
    }
    return buf[mid];
}

@compute @workgroup_size(WORKGROUP)
fn median(@builtin(global_invocation_id) gid: vec3<u32>,
          @builtin(num_workgroups) nwg: vec3<u32>) {
    var v: vec3<u32>;
    if !output_voxel(gid, nwg, &v) {
        return;
    }
    dst[out_index(v)] = median_at(v);
}
