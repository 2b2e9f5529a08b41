// gpu-lbm: one step of lucent-lbm's lattice (Geist et al. 2004; Bernabei ch. 4) on the
// device, the pull pattern between two copies of the populations:
//
//   f_k(x, t + 1) = C(f(x − e_k, t))_k,   ρ = Σ_k f_k,
//
// one invocation per cell. Each cell gathers f*_k(x − e_k) from the copy `read` (where
// x − e_k is outside the box, the wall's rule on the cell's own outgoing populations),
// collides (TRT, BGK or Geist's probabilities; true or the thesis's absorption; the
// isotropic source and its first moment), and writes its f*_k into copy `1 − read`: a
// cell writes only its own slots, so one dispatch is one synchronous step with no
// conflicts. The arithmetic is lucent-lbm's (`Collider::relax_lanes`, `Collider::collide`,
// `Collider::wall`), line for line, in f32 as there.
//
// Per workgroup the step leaves, at partials[5 (slot + group) + ·]: Σ(ρ′ − ρ)², Σρ′²,
// the absorbed light, the net outflow through the walls, and max |ρ′| (NOT_FINITE for NaN
// or infinity), for lucent-lbm's `Ledger` on the host.
//
// Joined after a lattice file (`lbm_d3q7.wgsl` or `lbm_d3q19.wgsl`: Q, CS2, E, OPPOSITE,
// W, W_GEIST, the population bindings and `load`/`store`).

struct LbmParams {
    // nx, ny, nz, groups_x
    dims: vec4<u32>,
    // x: the copy read (0 or 1); y: the step's slot in the partials (in workgroups);
    // z: 1 if the problem has a first moment
    step: vec4<u32>,
    // x: collision (0 TRT, 1 BGK, 2 Geist); y: absorption (0 true, 1 thesis);
    // z: wall (0 Robin, 1 Dirichlet, 2 Neumann, 3 reflect)
    scheme: vec4<u32>,
    // x: the wall's parameter (A, ρ_w, J_n or the reflectance)
    wall: vec4<f32>,
}

@group(0) @binding(0) var<uniform> params: LbmParams;
// TRT, BGK: D/h; Geist: κ_t.
@group(0) @binding(1) var<storage, read> first: array<f32>;
// TRT, BGK: κ_a = σ_a h; Geist: κ_s.
@group(0) @binding(2) var<storage, read> second: array<f32>;
// q₀ h per cell.
@group(0) @binding(3) var<storage, read> source: array<f32>;
// q₁ h per cell, three per cell (a placeholder when step.z is 0).
@group(0) @binding(4) var<storage, read> moment: array<f32>;
@group(0) @binding(5) var<storage, read_write> rho: array<f32>;
@group(0) @binding(6) var<storage, read_write> partials: array<f32>;

// Whether x + e leaves the box.
fn leaves(at: vec3<u32>, e: vec3<i32>) -> bool {
    let to = vec3<i32>(at) + e;
    let dims = vec3<i32>(params.dims.xyz);
    return any(to < vec3<i32>(0)) || any(to >= dims);
}

fn source_weight(k: u32) -> f32 {
    if (params.scheme.x == 2u) {
        return W_GEIST[k];
    }
    return W[k];
}

// Whether the cell is on the face (axis, side): side 0 the low face, 1 the high one.
fn on_face(at: vec3<u32>, axis: u32, side: u32) -> bool {
    if (side == 0u) {
        return at[axis] == 0u;
    }
    return at[axis] + 1u == params.dims[axis];
}

fn face_sign(side: u32) -> i32 {
    return select(1, -1, side == 0u);
}

// The wall's incoming populations from the outgoing ones (`out` holds f*_k for the links
// leaving the box, 0 for the others): incoming[k̄] = −f*_k + 2 w_k ρ_w per face, a link
// leaving through c faces counting 1/c in each face's sums and taking the mean of their
// rules; for a reflecting wall incoming[k̄] = r f*_k. Returns the net outflow.
fn wall_rule(at: vec3<u32>, out: ptr<function, array<f32, Q>>,
             incoming: ptr<function, array<f32, Q>>) -> f32 {
    var escaped = 0.0;
    if (params.scheme.z == 3u) {
        let r = params.wall.x;
        for (var k = 1u; k < Q; k = k + 1u) {
            if (leaves(at, E[k])) {
                let value = r * (*out)[k];
                (*incoming)[OPPOSITE[k]] = value;
                escaped = escaped + (*out)[k] - value;
            }
        }
        return escaped;
    }
    var crossings: array<f32, Q>;
    for (var axis = 0u; axis < 3u; axis = axis + 1u) {
        for (var side = 0u; side < 2u; side = side + 1u) {
            if (on_face(at, axis, side)) {
                for (var k = 1u; k < Q; k = k + 1u) {
                    if (E[k][axis] == face_sign(side)) {
                        crossings[k] = crossings[k] + 1.0;
                    }
                }
            }
        }
    }
    var count: array<f32, Q>;
    var sum: array<f32, Q>;
    for (var axis = 0u; axis < 3u; axis = axis + 1u) {
        for (var side = 0u; side < 2u; side = side + 1u) {
            if (!on_face(at, axis, side)) {
                continue;
            }
            // F = Σ f*_k and W = Σ w_k over the links leaving through this face.
            var big_f = 0.0;
            var big_w = 0.0;
            for (var k = 1u; k < Q; k = k + 1u) {
                if (E[k][axis] == face_sign(side)) {
                    let share = 1.0 / crossings[k];
                    big_f = big_f + share * (*out)[k];
                    big_w = big_w + share * source_weight(k);
                }
            }
            var rho_w: f32;
            switch params.scheme.z {
                case 0u: {
                    let a = params.wall.x;
                    rho_w = 4.0 * a * big_f / (1.0 + 4.0 * a * big_w);
                }
                case 1u: {
                    rho_w = params.wall.x;
                }
                default: {
                    rho_w = (2.0 * big_f - params.wall.x) / (2.0 * big_w);
                }
            }
            for (var k = 1u; k < Q; k = k + 1u) {
                if (E[k][axis] == face_sign(side)) {
                    sum[k] = sum[k] - (*out)[k] + 2.0 * source_weight(k) * rho_w;
                    count[k] = count[k] + 1.0;
                }
            }
        }
    }
    for (var k = 1u; k < Q; k = k + 1u) {
        if (count[k] > 0.0) {
            let value = sum[k] / count[k];
            (*incoming)[OPPOSITE[k]] = value;
            escaped = escaped + (*out)[k] - value;
        }
    }
    return escaped;
}

// 3 e_k · q₁ of the cell.
fn moment_along(k: u32, c: u32) -> f32 {
    if (params.step.z == 0u) {
        return 0.0;
    }
    let e = 3.0 * vec3<f32>(E[k]);
    return e.x * moment[3u * c] + e.y * moment[3u * c + 1u] + e.z * moment[3u * c + 2u];
}

// The collision of cell c: `fout` from `fin`; returns (ρ̂, absorbed).
fn collide(c: u32, fin: ptr<function, array<f32, Q>>,
           fout: ptr<function, array<f32, Q>>) -> vec2<f32> {
    var total = 0.0;
    for (var k = 0u; k < Q; k = k + 1u) {
        total = total + (*fin)[k];
    }
    let q0 = source[c];
    if (params.scheme.x == 2u) {
        // Geist: κ_t interacting, κ_s scattering isotropically per step.
        let kt = first[c];
        let ks = second[c];
        let ka = kt - ks;
        let moving = total - (*fin)[0];
        let scattered = ks * moving;
        var rest = 0.0;
        var absorbed = ka * moving;
        if (params.scheme.y == 1u) {
            rest = ka * moving;
            absorbed = 0.0;
        }
        (*fout)[0] = rest + W_GEIST[0] * (q0 + moment_along(0u, c));
        for (var k = 1u; k < Q; k = k + 1u) {
            (*fout)[k] = W_GEIST[k] * ((*fin)[0] + scattered) + (1.0 - kt) * (*fin)[k]
                + W_GEIST[k] * (q0 + moment_along(k, c));
        }
        return vec2<f32>(total, absorbed);
    }
    let d = first[c];
    let ka = second[c];
    let odd = 1.0 / (d * (1.0 / CS2) + 0.5);
    var even = odd;
    if (params.scheme.x == 0u) {
        even = 1.0 / (0.25 * CS2 / d + 0.5);
    }
    // ρ̂ = Σf + S/2, second order in the source S = q₀ − κ_a ρ̂ (true absorption); with
    // the thesis's absorption nothing leaves and κ_a ρ̂ moves to the rest population.
    var r: f32;
    var absorbed = 0.0;
    var kept = 0.0;
    if (params.scheme.y == 0u) {
        r = (total + 0.5 * q0) / (1.0 + 0.5 * ka);
        absorbed = ka * r;
    } else {
        r = total + 0.5 * q0;
        kept = ka * r;
    }
    let net = q0 - ka * r;
    let half = 1.0 - 0.5 * even;
    let odd_half = 1.0 - 0.5 * odd;
    (*fout)[0] = (*fin)[0] - even * ((*fin)[0] - W[0] * r) + half * (W[0] * net + kept);
    for (var i = 1u; i < Q; i = i + 2u) {
        let j = i + 1u;
        let w = W[i];
        let plus = 0.5 * ((*fin)[i] + (*fin)[j]);
        let minus = 0.5 * ((*fin)[i] - (*fin)[j]);
        let both = even * (plus - w * r) - half * w * net;
        (*fout)[i] = (*fin)[i] - both - odd * minus;
        (*fout)[j] = (*fin)[j] - both + odd * minus;
        if (params.step.z == 1u) {
            (*fout)[i] = (*fout)[i] + odd_half * W[i] * moment_along(i, c);
            (*fout)[j] = (*fout)[j] + odd_half * W[j] * moment_along(j, c);
        }
    }
    return vec2<f32>(r, absorbed);
}

@compute @workgroup_size(256)
fn lbm_step(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let g = flat_group(wg, params.dims.w);
    let c = g * WG + local;
    let dims = params.dims.xyz;
    let n = dims.x * dims.y * dims.z;
    var change = 0.0;
    var size = 0.0;
    var absorbed = 0.0;
    var escaped = 0.0;
    var largest = 0.0;
    if (c < n) {
        let at = cell_of(c, dims);
        let read = params.step.x * n;
        let write = (1u - params.step.x) * n;
        var fin: array<f32, Q>;
        var fout: array<f32, Q>;
        var incoming: array<f32, Q>;
        let wall = any(at == vec3<u32>(0u)) || any(at + vec3<u32>(1u) == dims);
        if (wall) {
            var outgoing: array<f32, Q>;
            for (var k = 1u; k < Q; k = k + 1u) {
                if (leaves(at, E[k])) {
                    outgoing[k] = load(k, read + c);
                }
            }
            escaped = wall_rule(at, &outgoing, &incoming);
        }
        for (var k = 0u; k < Q; k = k + 1u) {
            if (wall && leaves(at, -E[k])) {
                fin[k] = incoming[k];
            } else {
                let u = vec3<u32>(vec3<i32>(at) - E[k]);
                fin[k] = load(k, read + index_of(u, dims));
            }
        }
        let result = collide(c, &fin, &fout);
        for (var k = 0u; k < Q; k = k + 1u) {
            store(k, write + c, fout[k]);
        }
        let old = rho[c];
        rho[c] = result.x;
        change = (result.x - old) * (result.x - old);
        size = result.x * result.x;
        absorbed = result.y;
        largest = magnitude(result.x);
    }
    let slot = 5u * (params.step.y + g);
    let change_sum = workgroup_combine(local, change, 0u);
    let size_sum = workgroup_combine(local, size, 0u);
    let absorbed_sum = workgroup_combine(local, absorbed, 0u);
    let escaped_sum = workgroup_combine(local, escaped, 0u);
    let most = workgroup_combine(local, largest, 1u);
    if (local == 0u) {
        partials[slot] = change_sum;
        partials[slot + 1u] = size_sum;
        partials[slot + 2u] = absorbed_sum;
        partials[slot + 3u] = escaped_sum;
        partials[slot + 4u] = most;
    }
}
