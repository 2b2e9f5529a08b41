// gpu-diffusion-mg's outer iteration on the device, in f64 (adapters with SHADER_F64):
// the iterative refinement that lets f32 V-cycles reach 1e-8 relative,
//
//   r = b − A φ (f64),   solve A e ≈ r by one f32 cycle,   φ += e,   r −= A e,
//
// with φ, b and r kept in f64 on the device, so no vector crosses the bus between cycles:
// only ‖r‖² (8 bytes) comes back for the stopping rule. Products and sums are exact f64
// arithmetic on the operator's f32 coefficients, as on the host (lucent-diffusion's
// `Level::residual` and `Level::correct`); a compensated f32 ("float-float") residual was
// not used because WGSL lets an implementation contract and reassociate floating-point
// operations, which breaks the error-free transformations it relies on.
//
// Also the coarsest level's solve as a dense inverse (computed on the host in f64 by
// Cholesky, for a coarsest level of at most a few hundred unknowns), so a cycle needs no
// round trip to the host either.
//
// The operator is multigrid.wgsl's: (A x)_i = (e_i + Σ_f c_f) x_i − Σ_f c_f x_{j(f)}.

struct OuterParams {
    // nx, ny, nz, groups_x of the dispatch
    dims: vec4<u32>,
    // x: partials to add (`outer_sum`), or unknowns of the coarsest level (`coarsest_dense`);
    // y: which value of `norm` the sum goes to
    count: vec4<u32>,
}

@group(0) @binding(0) var<uniform> op: OuterParams;
@group(0) @binding(1) var<storage, read> cx: array<f32>;
@group(0) @binding(2) var<storage, read> cy: array<f32>;
@group(0) @binding(3) var<storage, read> cz: array<f32>;
@group(0) @binding(4) var<storage, read> extra: array<f32>;
// The problem's right-hand side, the solution and its residual.
@group(0) @binding(5) var<storage, read> rhs: array<f64>;
@group(0) @binding(6) var<storage, read_write> phi: array<f64>;
@group(0) @binding(7) var<storage, read_write> r: array<f64>;
// The finest level's x: the cycle's correction e (or full multigrid's start).
@group(0) @binding(8) var<storage, read> e: array<f32>;
// The finest level's b: the next cycle's right-hand side, r in f32.
@group(0) @binding(9) var<storage, read_write> b: array<f32>;
// Σ r² per workgroup, and their total.
@group(0) @binding(10) var<storage, read_write> partials: array<f64>;
@group(0) @binding(11) var<storage, read_write> norm: array<f64>;
// `coarsest_dense`: the inverse (row-major, unknowns × unknowns), the unknowns' cells, and
// the coarsest level's b and x.
@group(0) @binding(12) var<storage, read> inverse: array<f64>;
@group(0) @binding(13) var<storage, read> unknowns: array<u32>;
@group(0) @binding(14) var<storage, read> coarsest_b: array<f32>;
@group(0) @binding(15) var<storage, read_write> coarsest_x: array<f32>;

var<workgroup> scratch64: array<f64, 256>;

// The pairwise sum of `value` over the workgroup (every invocation calls it).
fn workgroup_sum64(local: u32, value: f64) -> f64 {
    scratch64[local] = value;
    var stride = WG / 2u;
    loop {
        if (stride == 0u) {
            break;
        }
        workgroupBarrier();
        if (local < stride) {
            scratch64[local] = scratch64[local] + scratch64[local + stride];
        }
        stride = stride / 2u;
    }
    workgroupBarrier();
    return scratch64[0];
}

// The vector A is applied to: φ (f64) or e (f32).
fn value(g: u32, of_phi: bool) -> f64 {
    if (of_phi) {
        return phi[g];
    }
    return f64(e[g]);
}

// (A v)_g in f64 at cell (i, j, k), v = φ or e.
fn apply_at(i: u32, j: u32, k: u32, g: u32, of_phi: bool) -> f64 {
    let nx = op.dims.x;
    let ny = op.dims.y;
    let nz = op.dims.z;
    let slab = nx * ny;
    var s = 0.0lf;
    var c = f64(cx[g]) + f64(cy[g]) + f64(cz[g]);
    if (i > 0u) {
        s += f64(cx[g]) * value(g - 1u, of_phi);
    }
    if (i + 1u < nx) {
        s += f64(cx[g + 1u]) * value(g + 1u, of_phi);
        c += f64(cx[g + 1u]);
    }
    if (j > 0u) {
        s += f64(cy[g]) * value(g - nx, of_phi);
    }
    if (j + 1u < ny) {
        s += f64(cy[g + nx]) * value(g + nx, of_phi);
        c += f64(cy[g + nx]);
    }
    if (k > 0u) {
        s += f64(cz[g]) * value(g - slab, of_phi);
    }
    if (k + 1u < nz) {
        s += f64(cz[g + slab]) * value(g + slab, of_phi);
        c += f64(cz[g + slab]);
    }
    return (f64(extra[g]) + c) * value(g, of_phi) - s;
}

// r = rhs − A φ, b = r in f32, partials of Σ r².
@compute @workgroup_size(256)
fn outer_residual(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    let group = flat_group(wg, op.dims.w);
    let g = group * WG + local;
    let nx = op.dims.x;
    let ny = op.dims.y;
    var square = 0.0lf;
    if (g < nx * ny * op.dims.z) {
        let res = rhs[g] - apply_at(g % nx, (g / nx) % ny, g / (nx * ny), g, true);
        r[g] = res;
        b[g] = f32(res);
        square = res * res;
    }
    let total = workgroup_sum64(local, square);
    if (local == 0u) {
        partials[group] = total;
    }
}

// φ += e, r −= A e, b = r in f32, partials of Σ r².
@compute @workgroup_size(256)
fn outer_correct(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    let group = flat_group(wg, op.dims.w);
    let g = group * WG + local;
    let nx = op.dims.x;
    let ny = op.dims.y;
    var square = 0.0lf;
    if (g < nx * ny * op.dims.z) {
        let ae = apply_at(g % nx, (g / nx) % ny, g / (nx * ny), g, false);
        phi[g] += f64(e[g]);
        let res = r[g] - ae;
        r[g] = res;
        b[g] = f32(res);
        square = res * res;
    }
    let total = workgroup_sum64(local, square);
    if (local == 0u) {
        partials[group] = total;
    }
}

// b = rhs in f32 (full multigrid's right-hand side), partials of Σ rhs² (its norm).
@compute @workgroup_size(256)
fn outer_load(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    let group = flat_group(wg, op.dims.w);
    let g = group * WG + local;
    var square = 0.0lf;
    if (g < op.dims.x * op.dims.y * op.dims.z) {
        let v = rhs[g];
        b[g] = f32(v);
        square = v * v;
    }
    let total = workgroup_sum64(local, square);
    if (local == 0u) {
        partials[group] = total;
    }
}

// φ = e: the solution starts from full multigrid's.
@compute @workgroup_size(256)
fn outer_start(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    let g = flat_group(wg, op.dims.w) * WG + local;
    if (g < op.dims.x * op.dims.y * op.dims.z) {
        phi[g] = f64(e[g]);
    }
}

// norm[count.y] = Σ partials, in a fixed order (one workgroup: strided sums, then the tree),
// so a solve's residual history does not depend on scheduling.
@compute @workgroup_size(256)
fn outer_sum(@builtin(local_invocation_index) local: u32) {
    var s = 0.0lf;
    for (var p = local; p < op.count.x; p += WG) {
        s += partials[p];
    }
    let total = workgroup_sum64(local, s);
    if (local == 0u) {
        norm[op.count.y] = total;
    }
}

// The coarsest level's x = A⁻¹ b on its unknowns (cells outside the medium keep x = 0),
// one invocation per unknown, in f64.
@compute @workgroup_size(256)
fn coarsest_dense(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    let m = op.count.x;
    let row = flat_group(wg, op.dims.w) * WG + local;
    if (row >= m) {
        return;
    }
    var s = 0.0lf;
    for (var c = 0u; c < m; c++) {
        s += inverse[row * m + c] * f64(coarsest_b[unknowns[c]]);
    }
    coarsest_x[unknowns[row]] = f32(s);
}
