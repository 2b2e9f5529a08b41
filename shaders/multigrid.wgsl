// gpu-diffusion-mg: the kernels of one cycle of lucent-diffusion's cell-centred multigrid
// (Mertens's embedded-boundary diffusion, lucent-diffusion's `level` module) on one level
// of the hierarchy, in f32:
//
//   (A x)_i = (e_i + Σ_f c_f) x_i − Σ_f c_f x_{j(f)},
//
// each cell storing the coupling c through its low face on each axis (0 on the box), e
// the diagonal's part that is not a face coupling, and 1/d (0 outside the medium).
//
// `smooth_colour` is one colour of red–black Gauss–Seidel in the host's residual form
// x_i += (b_i + Σ c x_j − (e_i + Σ c) x_i)/d_i, its sums in the host's order;
// `restrict_residual` is the coarse right-hand side Σ_children (b − A x), one invocation
// per coarse cell summing its up to eight children in the host's order (no atomics), and
// zeroes the coarse solution the coarse cycle starts from;
// `prolong` adds each coarse cell's correction to its children in the medium
// (piecewise-constant prolongation). One invocation per cell; cells x fastest.

struct LevelParams {
    // nx, ny, nz, groups_x of the dispatch
    dims: vec4<u32>,
    // the coarse level's nx, ny, nz; w: the colour a `smooth_colour` dispatch updates
    // (0 red: i + j + k even)
    coarse: vec4<u32>,
}

@group(0) @binding(0) var<uniform> lv: LevelParams;
@group(0) @binding(1) var<storage, read> cx: array<f32>;
@group(0) @binding(2) var<storage, read> cy: array<f32>;
@group(0) @binding(3) var<storage, read> cz: array<f32>;
@group(0) @binding(4) var<storage, read> extra: array<f32>;
@group(0) @binding(5) var<storage, read> inv_diag: array<f32>;
@group(0) @binding(6) var<storage, read> b: array<f32>;
@group(0) @binding(7) var<storage, read_write> x: array<f32>;
// The coarse level's right-hand side (`restrict_residual` writes it) or its solution
// (`prolong` reads it).
@group(0) @binding(8) var<storage, read_write> coarse: array<f32>;
// The coarse level's solution, which `restrict_residual` sets to zero: the coarse cycle
// that follows starts from it, so a cycle needs no clearing pass below its top level.
@group(0) @binding(9) var<storage, read_write> coarse_x: array<f32>;

// b − A x at cell (i, j, k), index g.
fn residual_at(i: u32, j: u32, k: u32, g: u32) -> f32 {
    let nx = lv.dims.x;
    let ny = lv.dims.y;
    let nz = lv.dims.z;
    let slab = nx * ny;
    var s = 0.0;
    if (i > 0u) {
        s += cx[g] * x[g - 1u];
    }
    if (i + 1u < nx) {
        s += cx[g + 1u] * x[g + 1u];
    }
    if (j > 0u) {
        s += cy[g] * x[g - nx];
    }
    if (j + 1u < ny) {
        s += cy[g + nx] * x[g + nx];
    }
    if (k > 0u) {
        s += cz[g] * x[g - slab];
    }
    if (k + 1u < nz) {
        s += cz[g + slab] * x[g + slab];
    }
    var c = cx[g] + cy[g] + cz[g];
    if (i + 1u < nx) {
        c += cx[g + 1u];
    }
    if (j + 1u < ny) {
        c += cy[g + nx];
    }
    if (k + 1u < nz) {
        c += cz[g + slab];
    }
    return (b[g] + s) - (extra[g] + c) * x[g];
}

@compute @workgroup_size(256)
fn smooth_colour(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    // One invocation per cell of the colour: invocation t takes the (t mod h)-th cell of
    // that colour in row t / h (h = ⌈nx/2⌉ per row), so no invocation idles on the other
    // colour and neighbouring invocations read neighbouring memory.
    let nx = lv.dims.x;
    let ny = lv.dims.y;
    let half = (nx + 1u) / 2u;
    let t = flat_group(wg, lv.dims.w) * WG + local;
    if (t >= half * ny * lv.dims.z) {
        return;
    }
    let row = t / half;
    let j = row % ny;
    let k = row / ny;
    let i = 2u * (t % half) + ((lv.coarse.w + j + k) & 1u);
    if (i >= nx) {
        return;
    }
    let g = i + nx * row;
    // Cells outside the medium (d = 0) are not unknowns: nothing to read or write.
    let d = inv_diag[g];
    if (d == 0.0) {
        return;
    }
    x[g] += residual_at(i, j, k, g) * d;
}

@compute @workgroup_size(256)
fn restrict_residual(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    let nx = lv.dims.x;
    let ny = lv.dims.y;
    let nz = lv.dims.z;
    let cnx = lv.coarse.x;
    let cny = lv.coarse.y;
    let gc = flat_group(wg, lv.dims.w) * WG + local;
    if (gc >= cnx * cny * lv.coarse.z) {
        return;
    }
    let ic = gc % cnx;
    let jc = (gc / cnx) % cny;
    let kc = gc / (cnx * cny);
    var sum = 0.0;
    for (var k = 2u * kc; k < min(2u * kc + 2u, nz); k++) {
        for (var j = 2u * jc; j < min(2u * jc + 2u, ny); j++) {
            for (var i = 2u * ic; i < min(2u * ic + 2u, nx); i++) {
                // Only cells in the medium pass their residual down (as on the host).
                let g = i + nx * (j + ny * k);
                if (inv_diag[g] != 0.0) {
                    sum += residual_at(i, j, k, g);
                }
            }
        }
    }
    coarse[gc] = sum;
    coarse_x[gc] = 0.0;
}

@compute @workgroup_size(256)
fn prolong(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    let nx = lv.dims.x;
    let ny = lv.dims.y;
    let g = flat_group(wg, lv.dims.w) * WG + local;
    if (g >= nx * ny * lv.dims.z) {
        return;
    }
    if (inv_diag[g] == 0.0) {
        return;
    }
    let i = g % nx;
    let j = (g / nx) % ny;
    let k = g / (nx * ny);
    x[g] += coarse[i / 2u + lv.coarse.x * (j / 2u + lv.coarse.y * (k / 2u))];
}
