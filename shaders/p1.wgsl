// gpu-ftcs-p1: one FTCS step of Murray's P1 system (thesis §3.4.2) on a homogeneous
// medium, zero beyond the grid, as lucent-explicit's `p1::march`:
//
//   φ′ = (1 − K_φ) φ − r ∇·E + cΔt q,    E′_a = (1 − K_E) E_a − (r/3) ∂_a φ,
//
// r = cΔt/h; collocated: central differences ½(f_{i+1} − f_{i−1}); staggered (E_a on the
// face between i and i + 1): one-cell differences. Both kernels read the old state and
// write the new one (ping-pong), so the pair is exactly forward Euler. Per workgroup
// they leave, at partials[4 (offset + group) + ·]: Σ (φ′ − φ)², Σ φ′², max |φ′| and
// max |E′| (NOT_FINITE for NaN or infinity), for the stopping rule and the growth monitor.

struct P1Params {
    // nx, ny, nz, groups_x
    dims: vec4<u32>,
    // x: 1 staggered, 0 collocated; y: step slot of the partials
    scheme: vec4<u32>,
    // K_φ, K_E, r, cΔt
    rates: vec4<f32>,
}

@group(0) @binding(0) var<storage, read> phi_in: array<f32>;
@group(0) @binding(1) var<storage, read> ex_in: array<f32>;
@group(0) @binding(2) var<storage, read> ey_in: array<f32>;
@group(0) @binding(3) var<storage, read> ez_in: array<f32>;
@group(0) @binding(4) var<storage, read> source: array<f32>;
@group(0) @binding(5) var<storage, read_write> phi_out: array<f32>;
@group(0) @binding(6) var<storage, read_write> partials: array<f32>;
@group(0) @binding(7) var<uniform> params: P1Params;

fn neighbour(at: vec3<u32>, axis: u32, step: i32) -> i32 {
    let dims = params.dims.xyz;
    var to = vec3<i32>(at);
    to[axis] = to[axis] + step;
    if (to[axis] < 0 || to[axis] >= i32(dims[axis])) {
        return -1;
    }
    return i32(index_of(vec3<u32>(to), dims));
}

fn flux_at(axis: u32, c: i32) -> f32 {
    if (c < 0) {
        return 0.0;
    }
    switch axis {
        case 0u: { return ex_in[c]; }
        case 1u: { return ey_in[c]; }
        default: { return ez_in[c]; }
    }
}

@compute @workgroup_size(256)
fn fluence_step(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let g = flat_group(wg, params.dims.w);
    let c = g * WG + local;
    let dims = params.dims.xyz;
    var change = 0.0;
    var size = 0.0;
    var largest = 0.0;
    if (c < dims.x * dims.y * dims.z) {
        let at = cell_of(c, dims);
        var divergence = 0.0;
        for (var a = 0u; a < 3u; a = a + 1u) {
            if (params.scheme.x == 1u) {
                divergence = divergence + flux_at(a, i32(c)) - flux_at(a, neighbour(at, a, -1));
            } else {
                divergence = divergence
                    + 0.5 * (flux_at(a, neighbour(at, a, 1)) - flux_at(a, neighbour(at, a, -1)));
            }
        }
        let old = phi_in[c];
        let next = (1.0 - params.rates.x) * old - params.rates.z * divergence
            + params.rates.w * source[c];
        phi_out[c] = next;
        change = (next - old) * (next - old);
        size = next * next;
        largest = magnitude(next);
    }
    let slot = 4u * (params.scheme.y + g);
    let change_sum = workgroup_combine(local, change, 0u);
    let size_sum = workgroup_combine(local, size, 0u);
    let most = workgroup_combine(local, largest, 1u);
    if (local == 0u) {
        partials[slot] = change_sum;
        partials[slot + 1u] = size_sum;
        partials[slot + 2u] = most;
    }
}
