// Shared by lucent's kernels: prepended to each kernel's source at build time
// (lucent-gpu `shaders`), so every kernel numbers workgroups and sums partials one way.
//
// Workgroups are numbered over a 2-D dispatch (x fastest) so that grids of more than
// 65 535 × 256 cells dispatch at once: group = wg.x + wg.y · groups_x.
// Partial sums are pairwise trees over the workgroup's 256 values (rounding error growing
// as log2 256 = 8 ulps, not 256); the host adds the partials in f64.

const WG: u32 = 256u;
// Stands for a value that is not finite in a partial maximum (f32's largest is 3.4e38).
const NOT_FINITE: f32 = 3.0e38;

var<workgroup> scratch: array<f32, 256>;

fn flat_group(wg: vec3<u32>, groups_x: u32) -> u32 {
    return wg.x + wg.y * groups_x;
}

fn finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

// |x|, or NOT_FINITE for NaN and infinities (max() of a NaN is implementation-defined).
fn magnitude(x: f32) -> f32 {
    if (finite(x)) {
        return min(abs(x), NOT_FINITE);
    }
    return NOT_FINITE;
}

// The pairwise sum (op 0) or maximum (op 1) of `value` over the workgroup; every
// invocation must call it (it holds barriers) and every one gets the result.
fn workgroup_combine(local: u32, value: f32, op: u32) -> f32 {
    scratch[local] = value;
    var stride = WG / 2u;
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
    workgroupBarrier();
    let total = scratch[0];
    workgroupBarrier();
    return total;
}

// Cell (i, j, k) of linear index c on a grid of `dims` (x fastest).
fn cell_of(c: u32, dims: vec3<u32>) -> vec3<u32> {
    return vec3<u32>(c % dims.x, (c / dims.x) % dims.y, c / (dims.x * dims.y));
}

fn index_of(at: vec3<u32>, dims: vec3<u32>) -> u32 {
    return at.x + dims.x * (at.y + dims.y * at.z);
}
