// Reductions of an f32 field to per-workgroup partials, summed by the host in f64.
//
// Each workgroup of 256 invocations loads 256 consecutive values (zero past the end) and
// combines them as a balanced binary tree in workgroup memory: a pairwise sum, whose
// rounding error grows as log2(256) = 8 ulps rather than the 256 of a running sum. The
// host adds the partials in f64 (lucent-gpu `reduce`), so a sum over n values carries at
// most about 8·2⁻²⁴ relative error per partial, independent of n.
//
// Workgroups are numbered over a 2-D dispatch (x fastest) so that fields of more than
// 65 535 × 256 values can be reduced in one dispatch.

struct Params {
    len: u32,
    // The dispatch's width in workgroups (the y index counts rows of this many).
    groups_x: u32,
}

@group(0) @binding(0) var<storage, read> values: array<f32>;
@group(0) @binding(1) var<storage, read_write> partials: array<f32>;
@group(0) @binding(2) var<uniform> params: Params;

const WORKGROUP: u32 = 256u;
var<workgroup> scratch: array<f32, 256>;

fn group_index(wg: vec3<u32>) -> u32 {
    return wg.x + wg.y * params.groups_x;
}

// Combines `scratch` as a pairwise tree; `op` 0: sum, 1: maximum.
fn tree(local: u32, op: u32) {
    var stride = WORKGROUP / 2u;
    loop {
        if (stride == 0u) {
            break;
        }
        workgroupBarrier();
        if (local < stride) {
            let a = scratch[local];
            let b = scratch[local + stride];
            if (op == 0u) {
                scratch[local] = a + b;
            } else {
                scratch[local] = max(a, b);
            }
        }
        stride = stride / 2u;
    }
}

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
    let g = group_index(wg);
    scratch[local] = load(g * WORKGROUP + local, false, false);
    tree(local, 0u);
    if (local == 0u) {
        partials[g] = scratch[0];
    }
}

@compute @workgroup_size(256)
fn sum_of_squares(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let g = group_index(wg);
    scratch[local] = load(g * WORKGROUP + local, true, false);
    tree(local, 0u);
    if (local == 0u) {
        partials[g] = scratch[0];
    }
}

@compute @workgroup_size(256)
fn max_abs(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let g = group_index(wg);
    scratch[local] = load(g * WORKGROUP + local, false, true);
    tree(local, 1u);
    if (local == 0u) {
        partials[g] = scratch[0];
    }
}
