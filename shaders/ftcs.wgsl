// gpu-ftcs-diffusion: one FTCS step on lucent-diffusion's assembled system A φ = b
// (compressed sparse rows), V dφ/dτ = b − Aφ marched as φ′ = φ + (cΔt/V)(b − Aφ).
//
// One invocation per row: r = b − Aφ from φ_in, φ_out = φ_in + scale · r, and the
// workgroup's pairwise Σ r² into `partials[offset + group]`, so the residual of every
// step of a recorded batch reaches the host without a round-trip per step. With
// `write` = 0 only the residual is computed (the state after a batch's last step).
//
// The host runs this in correction form (defect correction): b is the f64 residual of
// the host's f64 solution, φ the f32 correction, so f32 rounding limits each correction,
// not the solution (lucent-gpu-solvers `ftcs`).

struct StepParams {
    rows: u32,
    groups_x: u32,
    offset: u32,
    write: u32,
    scale: f32,
    pad0: f32,
    pad1: f32,
    pad2: f32,
}

@group(0) @binding(0) var<storage, read> row_start: array<u32>;
@group(0) @binding(1) var<storage, read> columns: array<u32>;
@group(0) @binding(2) var<storage, read> entries: array<f32>;
@group(0) @binding(3) var<storage, read> rhs: array<f32>;
@group(0) @binding(4) var<storage, read> phi_in: array<f32>;
@group(0) @binding(5) var<storage, read_write> phi_out: array<f32>;
@group(0) @binding(6) var<storage, read_write> partials: array<f32>;
@group(0) @binding(7) var<uniform> params: StepParams;

@compute @workgroup_size(256)
fn step(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let g = flat_group(wg, params.groups_x);
    let row = g * WG + local;
    var r = 0.0;
    if (row < params.rows) {
        var ax = 0.0;
        let end = row_start[row + 1u];
        for (var e = row_start[row]; e < end; e = e + 1u) {
            ax = ax + entries[e] * phi_in[columns[e]];
        }
        r = rhs[row] - ax;
        if (params.write == 1u) {
            phi_out[row] = phi_in[row] + params.scale * r;
        }
    }
    let sum = workgroup_combine(local, r * r, 0u);
    if (local == 0u) {
        partials[params.offset + g] = sum;
    }
}
