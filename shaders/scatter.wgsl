// gpu-convection-diffusion, the scattering step: Zhang & Ma's Eq. 23, ∂L/∂t = σ_s ∇²L
// with reflecting (Neumann) box faces, by one backward-Euler step (lucent-explicit
// `scatter`): (1 + a·faces_i) x_i − a Σ_nb x_nb = L0_i, a = σ_s t / h², faces_i the
// neighbours cell i has. Solved by red–black Gauss–Seidel (`sweep`, colour (i+j+k) mod 2
// per dispatch: each colour reads only the other, so a dispatch is race-free), with the
// residual Σ (L0 − M x)² and Σ L0² per workgroup from `residual`.

struct ScatterParams {
    // nx, ny, nz, groups_x
    dims: vec4<u32>,
    // x: colour (sweep)
    colour: vec4<u32>,
    // x: a = σ_s t / h²
    a: vec4<f32>,
}

@group(0) @binding(0) var<storage, read> initial: array<f32>;
@group(0) @binding(1) var<storage, read_write> field: array<f32>;
@group(0) @binding(2) var<uniform> params: ScatterParams;

// (Σ_nb x_nb, number of neighbours) of cell `at`.
fn neighbours(at: vec3<u32>) -> vec2<f32> {
    let dims = params.dims.xyz;
    var sum = 0.0;
    var faces = 0.0;
    for (var axis = 0u; axis < 3u; axis = axis + 1u) {
        if (at[axis] > 0u) {
            var to = at;
            to[axis] = to[axis] - 1u;
            sum = sum + field[index_of(to, dims)];
            faces = faces + 1.0;
        }
        if (at[axis] + 1u < dims[axis]) {
            var to = at;
            to[axis] = to[axis] + 1u;
            sum = sum + field[index_of(to, dims)];
            faces = faces + 1.0;
        }
    }
    return vec2<f32>(sum, faces);
}

// One colour: threads cover half the cells, thread t the t-th cell of that colour in
// x-fastest order (x pairs up within a row; odd n_x handled by the parity test).
@compute @workgroup_size(256)
fn sweep(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let t = flat_group(wg, params.dims.w) * WG + local;
    let dims = params.dims.xyz;
    let half_x = (dims.x + 1u) / 2u;
    let row = t / half_x;
    if (row >= dims.y * dims.z) {
        return;
    }
    let j = row % dims.y;
    let k = row / dims.y;
    let i = 2u * (t % half_x) + ((j + k + params.colour.x) % 2u);
    if (i >= dims.x) {
        return;
    }
    let at = vec3<u32>(i, j, k);
    let c = index_of(at, dims);
    let nb = neighbours(at);
    let a = params.a.x;
    field[c] = (initial[c] + a * nb.x) / (1.0 + a * nb.y);
}

@group(0) @binding(3) var<storage, read_write> partials: array<f32>;

@compute @workgroup_size(256)
fn residual(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let g = flat_group(wg, params.dims.w);
    let c = g * WG + local;
    let dims = params.dims.xyz;
    var r2 = 0.0;
    var b2 = 0.0;
    if (c < dims.x * dims.y * dims.z) {
        let at = cell_of(c, dims);
        let nb = neighbours(at);
        let a = params.a.x;
        let r = initial[c] - ((1.0 + a * nb.y) * field[c] - a * nb.x);
        r2 = r * r;
        b2 = initial[c] * initial[c];
    }
    let r_sum = workgroup_combine(local, r2, 0u);
    let b_sum = workgroup_combine(local, b2, 0u);
    if (local == 0u) {
        partials[2u * g] = r_sum;
        partials[2u * g + 1u] = b_sum;
    }
}
