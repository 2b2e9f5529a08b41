// The largest change between two fields and the largest value of the new one, per
// workgroup of 256 cells, into partials[2 group + 0, 1] (NOT_FINITE for NaN or
// infinity): the stopping rule of passes and sweeps (max |new − old| / max |new|).

struct ChangeParams {
    len: u32,
    groups_x: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<storage, read> before: array<f32>;
@group(0) @binding(1) var<storage, read> after: array<f32>;
@group(0) @binding(2) var<storage, read_write> partials: array<f32>;
@group(0) @binding(3) var<uniform> params: ChangeParams;

@compute @workgroup_size(256)
fn max_change(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let g = flat_group(wg, params.groups_x);
    let c = g * WG + local;
    var change = 0.0;
    var largest = 0.0;
    if (c < params.len) {
        change = magnitude(after[c] - before[c]);
        largest = magnitude(after[c]);
    }
    let most_change = workgroup_combine(local, change, 1u);
    let most = workgroup_combine(local, largest, 1u);
    if (local == 0u) {
        partials[2u * g] = most_change;
        partials[2u * g + 1u] = most;
    }
}
