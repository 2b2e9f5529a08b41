// Reductions of an f32 field to per-workgroup partials, summed by the host in f64.
//
// Each workgroup of 256 invocations loads 256 consecutive values (zero past the end) and
// combines them as a balanced binary tree in workgroup memory (common.wgsl's
// `workgroup_combine`): a pairwise sum, whose rounding error grows as log2(256) = 8 ulps
// rather than the 256 of a running sum. The host adds the partials in f64 (lucent-gpu
// `reduce`), so a sum over n values carries at most about 8·2⁻²⁴ relative error per
// partial, independent of n. Workgroups are numbered over a 2-D dispatch.

struct Params {
    len: u32,
    // The dispatch's width in workgroups (the y index counts rows of this many).
    groups_x: u32,
}

@group(0) @binding(0) var<storage, read> values: array<f32>;
@group(0) @binding(1) var<storage, read_write> partials: array<f32>;
@group(0) @binding(2) var<uniform> params: Params;

fn load(index: u32, square: bool, absolute: bool) -> f32 {
    if (index >= params.len) {
        return 0.0;
    }
    let v = values[index];
    if (square) {
        return v * v;
    }
    if (absolute) {
        return abs(v);
    }
    return v;
}

@compute @workgroup_size(256)
fn sum(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let g = flat_group(wg, params.groups_x);
    let total = workgroup_combine(local, load(g * WG + local, false, false), 0u);
    if (local == 0u) {
        partials[g] = total;
    }
}

@compute @workgroup_size(256)
fn sum_of_squares(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let g = flat_group(wg, params.groups_x);
    let total = workgroup_combine(local, load(g * WG + local, true, false), 0u);
    if (local == 0u) {
        partials[g] = total;
    }
}

@compute @workgroup_size(256)
fn max_abs(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let g = flat_group(wg, params.groups_x);
    let most = workgroup_combine(local, load(g * WG + local, false, true), 1u);
    if (local == 0u) {
        partials[g] = most;
    }
}
