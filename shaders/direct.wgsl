// gpu-direct: transmittance e^{-τ} from a light to every cell centre, τ = ∫ σ_t ds the
// exact line integral of the trilinear σ_t (lucent-grid `Grid::line_integral`, ported):
// the segment is clipped to the box −½ ≤ v ≤ n − ½ in voxel coordinates (centres at
// integers), cut where it crosses the planes through cell centres (a DDA over dual
// cells), and each piece, on which the interpolant is a cubic in the arc length, is
// integrated exactly by the 2-point Gauss rule. Marching stops at τ = cutoff.
//
// One invocation per cell and light. kind 0: a directional light travelling along
// `light.xyz` (the segment starts where the ray backwards leaves the box); kind 1: a
// point or spot light at `light.xyz` (world); kind 2: the sky, Σ_d w_d e^{-τ_d} over the
// directions of `sky` (xyz: direction of travel, w: weight).
//
// σ_t is read through `sigma_at(i, j, k)` (clamped to the grid), defined by the snippet
// prepended to this file: `sigma_dense.wgsl` (one array, binding 0) or `sigma_atlas.wgsl`
// (a brick atlas with a software page table, bindings 0 and 4). Cells are written in
// chunks: invocation c handles cell `first + c` and writes `transmittance[c]`, so a grid
// larger than one binding is computed chunk by chunk.

struct DirectParams {
    // nx, ny, nz, groups_x
    dims: vec4<u32>,
    // the box's lower corner (world); w: the optical depth where marching stops
    origin: vec4<f32>,
    // cell size per axis (world); w: unused
    spacing: vec4<f32>,
    // direction (kind 0) or position (kind 1)
    light: vec4<f32>,
    // x: kind, y: sky directions, z: brick edge (atlas), w: unused
    kind: vec4<u32>,
    // x: first cell of this chunk, y: cells in the chunk
    chunk: vec4<u32>,
}

@group(0) @binding(1) var<storage, read> sky: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> transmittance: array<f32>;
@group(0) @binding(3) var<uniform> params: DirectParams;

const GAUSS: f32 = 0.5773502691896258;
const FAR: f32 = 1.0e30;

// ∫ σ_t ds from voxel point `va` to `vb`, the segment being `len` long in world units.
fn optical_depth(va: vec3<f32>, vb: vec3<f32>, len: f32) -> f32 {
    let cutoff = params.origin.w;
    let n = vec3<i32>(params.dims.xyz);
    let dv = vb - va;
    if (len <= 0.0) {
        return 0.0;
    }
    var t0 = 0.0;
    var t1 = 1.0;
    for (var a = 0; a < 3; a = a + 1) {
        let lo = -0.5;
        let hi = f32(n[a]) - 0.5;
        if (dv[a] == 0.0) {
            if (va[a] < lo || va[a] > hi) {
                return 0.0;
            }
        } else {
            let ta = (lo - va[a]) / dv[a];
            let tb = (hi - va[a]) / dv[a];
            t0 = max(t0, min(ta, tb));
            t1 = min(t1, max(ta, tb));
        }
    }
    if (t0 >= t1) {
        return 0.0;
    }
    let start = va + dv * t0;
    var cell = vec3<i32>(0);
    var t_next = vec3<f32>(FAR);
    var t_step = vec3<f32>(FAR);
    var step = vec3<i32>(0);
    for (var a = 0; a < 3; a = a + 1) {
        cell[a] = clamp(i32(floor(start[a])), -1, n[a] - 1);
        if (dv[a] > 0.0) {
            step[a] = 1;
            t_step[a] = 1.0 / dv[a];
            t_next[a] = t0 + (f32(cell[a] + 1) - start[a]) / dv[a];
        } else if (dv[a] < 0.0) {
            step[a] = -1;
            t_step[a] = -1.0 / dv[a];
            t_next[a] = t0 + (f32(cell[a]) - start[a]) / dv[a];
        }
    }
    var t = t0;
    var total = 0.0;
    // A segment crosses at most n_x + n_y + n_z + 3 dual cells.
    let most = n.x + n.y + n.z + 3;
    for (var visited = 0; visited < most; visited = visited + 1) {
        var a = 2;
        if (t_next.x <= t_next.y && t_next.x <= t_next.z) {
            a = 0;
        } else if (t_next.y <= t_next.z) {
            a = 1;
        }
        let t_end = min(t_next[a], t1);
        if (t_end > t) {
            let c000 = sigma_at(cell.x, cell.y, cell.z);
            let c100 = sigma_at(cell.x + 1, cell.y, cell.z);
            let c010 = sigma_at(cell.x, cell.y + 1, cell.z);
            let c110 = sigma_at(cell.x + 1, cell.y + 1, cell.z);
            let c001 = sigma_at(cell.x, cell.y, cell.z + 1);
            let c101 = sigma_at(cell.x + 1, cell.y, cell.z + 1);
            let c011 = sigma_at(cell.x, cell.y + 1, cell.z + 1);
            let c111 = sigma_at(cell.x + 1, cell.y + 1, cell.z + 1);
            let corner = vec3<f32>(cell);
            let mid = 0.5 * (t + t_end);
            let half = 0.5 * (t_end - t);
            var sum = 0.0;
            for (var g = 0; g < 2; g = g + 1) {
                let tt = mid + (f32(g) * 2.0 - 1.0) * GAUSS * half;
                let u = clamp(va + dv * tt - corner, vec3<f32>(0.0), vec3<f32>(1.0));
                let x0 = mix(c000, c100, u.x);
                let x1 = mix(c010, c110, u.x);
                let x2 = mix(c001, c101, u.x);
                let x3 = mix(c011, c111, u.x);
                sum = sum + mix(mix(x0, x1, u.y), mix(x2, x3, u.y), u.z);
            }
            total = total + half * len * sum;
            if (total > cutoff) {
                return total;
            }
        }
        if (t_end >= t1) {
            return total;
        }
        t = t_end;
        cell[a] = cell[a] + step[a];
        t_next[a] = t_next[a] + t_step[a];
        if (cell[a] < -1 || cell[a] > n[a] - 1) {
            return total;
        }
    }
    return total;
}

// τ along direction of travel `d` (world, unit) from where the ray backwards through
// voxel point `v` leaves the box, to `v`.
fn depth_along(v: vec3<f32>, d: vec3<f32>) -> f32 {
    let n = vec3<f32>(params.dims.xyz);
    let h = params.spacing.xyz;
    let dv = d / h;
    var s = FAR;
    for (var a = 0; a < 3; a = a + 1) {
        if (dv[a] > 0.0) {
            s = min(s, (v[a] + 0.5) / dv[a]);
        } else if (dv[a] < 0.0) {
            s = min(s, (n[a] - 0.5 - v[a]) / -dv[a]);
        }
    }
    if (s >= FAR) {
        return 0.0;
    }
    return optical_depth(v - dv * s, v, s);
}

@compute @workgroup_size(64)
fn transmit(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let offset = flat_group(wg, params.dims.w) * 64u + local;
    if (offset >= params.chunk.y) {
        return;
    }
    let c = params.chunk.x + offset;
    let dims = params.dims.xyz;
    let v = vec3<f32>(cell_of(c, dims));
    let h = params.spacing.xyz;
    var result = 0.0;
    switch params.kind.x {
        case 0u: {
            result = exp(-depth_along(v, params.light.xyz));
        }
        case 1u: {
            let x = params.origin.xyz + (v + vec3<f32>(0.5)) * h;
            let source_point = (params.light.xyz - params.origin.xyz) / h - vec3<f32>(0.5);
            result = exp(-optical_depth(source_point, v, length(x - params.light.xyz)));
        }
        default: {
            var sum = 0.0;
            for (var d = 0u; d < params.kind.y; d = d + 1u) {
                let dir = sky[d];
                sum = sum + dir.w * exp(-depth_along(v, dir.xyz));
            }
            result = sum;
        }
    }
    transmittance[offset] = result;
}
