// gpu-ftcs-p1, the flux half of the step (see p1.wgsl): E′_a = (1 − K_E) E_a − (r/3) ∂_a φ
// from the old φ and E, max |E′| per workgroup into partials[4 (offset + group) + 3].

struct P1Params {
    dims: vec4<u32>,
    scheme: vec4<u32>,
    rates: vec4<f32>,
}

@group(0) @binding(0) var<storage, read> phi_in: array<f32>;
@group(0) @binding(1) var<storage, read> ex_in: array<f32>;
@group(0) @binding(2) var<storage, read> ey_in: array<f32>;
@group(0) @binding(3) var<storage, read> ez_in: array<f32>;
@group(0) @binding(4) var<storage, read_write> ex_out: array<f32>;
@group(0) @binding(5) var<storage, read_write> ey_out: array<f32>;
@group(0) @binding(6) var<storage, read_write> ez_out: array<f32>;
@group(0) @binding(7) var<storage, read_write> partials: array<f32>;
@group(0) @binding(8) var<uniform> params: P1Params;

fn phi_at(at: vec3<u32>, axis: u32, step: i32) -> f32 {
    let dims = params.dims.xyz;
    var to = vec3<i32>(at);
    to[axis] = to[axis] + step;
    if (to[axis] < 0 || to[axis] >= i32(dims[axis])) {
        return 0.0;
    }
    return phi_in[index_of(vec3<u32>(to), dims)];
}

@compute @workgroup_size(256)
fn flux_step(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let g = flat_group(wg, params.dims.w);
    let c = g * WG + local;
    let dims = params.dims.xyz;
    var largest = 0.0;
    if (c < dims.x * dims.y * dims.z) {
        let at = cell_of(c, dims);
        let keep = 1.0 - params.rates.y;
        let r3 = params.rates.z / 3.0;
        var gradient = vec3<f32>(0.0);
        for (var a = 0u; a < 3u; a = a + 1u) {
            if (params.scheme.x == 1u) {
                gradient[a] = phi_at(at, a, 1) - phi_in[c];
            } else {
                gradient[a] = 0.5 * (phi_at(at, a, 1) - phi_at(at, a, -1));
            }
        }
        let ex = keep * ex_in[c] - r3 * gradient.x;
        let ey = keep * ey_in[c] - r3 * gradient.y;
        let ez = keep * ez_in[c] - r3 * gradient.z;
        ex_out[c] = ex;
        ey_out[c] = ey;
        ez_out[c] = ez;
        largest = max(magnitude(ex), max(magnitude(ey), magnitude(ez)));
    }
    let most = workgroup_combine(local, largest, 1u);
    if (local == 0u) {
        partials[4u * (params.scheme.y + g) + 3u] = most;
    }
}
