// gpu-convection-diffusion, the light march: Zhang & Ma's convection–absorption to steady
// state by short characteristics (lucent-explicit `convection`, `Model::Characteristic`,
// ported): a cell's value is the upstream value where the ray through its centre crosses
// the previous plane of cell centres across the light's dominant axis (or the box, if it
// leaves first), interpolated from the nodes there — quadratic, limited to the range of
// the bracketing bilinear nodes — times the exact attenuation e^{−τ} of that step (τ by
// the trapezoid rule). For a point light the interpolated quantity is φ r² (its I·T).
//
// Layer sweeps: one dispatch per layer, in the light's order. A distant light's layers
// are the planes across its dominant axis, upwind first: every cell reads only the layer
// before, so one pass is the exact steady state. A point light's layers are the cubic
// shells around the cell nearest to it (Chebyshev distance s); a cell reads nodes of
// earlier shells from this pass (`current`) and nodes of its own shell from the previous
// pass (`previous`), so a pass is Gauss–Seidel across shells and Jacobi within one, and
// passes repeat until the largest change is below the tolerance.

struct March {
    // nx, ny, nz, groups_x
    dims: vec4<u32>,
    // the box's lower corner (world); w: the cell size h
    origin: vec4<f32>,
    // direction of travel (distant, unit) or position (point); w: density
    light: vec4<f32>,
    // x: 0 distant, 1 point; y: the distant light's dominant axis; z: cells per face
    // (point: the largest n_b · n_d)
    kind: vec4<u32>,
    // the point light's nearest cell (may lie outside the grid)
    centre: vec4<i32>,
}

struct Layer {
    s: i32,
    pad0: i32,
    pad1: i32,
    pad2: i32,
}

@group(0) @binding(0) var<storage, read> sigma: array<f32>;
@group(0) @binding(1) var<storage, read> previous: array<f32>;
@group(0) @binding(2) var<storage, read_write> current: array<f32>;
@group(0) @binding(3) var<uniform> march: March;
@group(0) @binding(4) var<uniform> sweep_layer: Layer;

fn box_hi() -> vec3<f32> {
    return march.origin.xyz + vec3<f32>(march.dims.xyz) * march.origin.w;
}

fn centre_of(at: vec3<i32>) -> vec3<f32> {
    return march.origin.xyz + (vec3<f32>(at) + vec3<f32>(0.5)) * march.origin.w;
}

fn is_point() -> bool {
    return march.kind.x == 1u;
}

// The layer a cell belongs to.
fn layer_of(at: vec3<i32>) -> i32 {
    if (is_point()) {
        let d = abs(at - march.centre.xyz);
        return max(d.x, max(d.y, d.z));
    }
    let a = march.kind.y;
    if (march.light[a] > 0.0) {
        return at[a];
    }
    return i32(march.dims[a]) - 1 - at[a];
}

// φ r² for a point light (smooth where φ ∝ 1/r² is not), 1 for a distant one.
fn spread(y: vec3<f32>) -> f32 {
    if (is_point()) {
        let d = y - march.light.xyz;
        return dot(d, d);
    }
    return 1.0;
}

// The light's value at a point of an inflow face or near a point light: its density, over
// r² (at least a quarter cell²) for a point light.
fn source_value(y: vec3<f32>) -> f32 {
    if (is_point()) {
        let h = march.origin.w;
        return march.light.w / max(spread(y), 0.25 * h * h);
    }
    return march.light.w;
}

fn light_at(y: vec3<f32>) -> f32 {
    return source_value(y) * spread(y);
}

// Node position in index coordinates: centres at integers, faces at −½ and n − ½.
fn position(a: u32, i: i32) -> f32 {
    let n = i32(march.dims[a]);
    if (i < 0) {
        return -0.5;
    }
    if (i >= n) {
        return f32(n) - 0.5;
    }
    return f32(i);
}

struct Node {
    psi: f32,
    sigma: f32,
}

// The value (ψ = φ · spread) and σ at node (plane, ib, id) of the upstream plane; beyond
// the grid laterally, the point of the (inflow) face beside it.
fn node_value(axis: u32, b: u32, d: u32, plane: i32, ib: i32, id: i32) -> Node {
    var to = vec3<i32>(0);
    to[axis] = plane;
    to[b] = ib;
    to[d] = id;
    let n = vec3<i32>(march.dims.xyz);
    let clamped = clamp(to, vec3<i32>(0), n - vec3<i32>(1));
    let i = index_of(vec3<u32>(clamped), march.dims.xyz);
    var point = centre_of(to);
    let inside = ib >= 0 && ib < n[b] && id >= 0 && id < n[d];
    if (inside) {
        var value = previous[i];
        if (layer_of(to) < sweep_layer.s) {
            value = current[i];
        }
        return Node(value * spread(point), sigma[i]);
    }
    let lo = march.origin.xyz;
    let hi = box_hi();
    point[b] = clamp(point[b], lo[b], hi[b]);
    point[d] = clamp(point[d], lo[d], hi[d]);
    return Node(light_at(point), sigma[i]);
}

// The steady value of cell `at` (index c).
fn characteristic(at: vec3<i32>, c: u32) -> f32 {
    let h = march.origin.w;
    let x = centre_of(at);
    var u = march.light.xyz;
    if (is_point()) {
        let r = x - march.light.xyz;
        let distance = length(r);
        // Cells within 2h of a point light hold its value, attenuated over the distance.
        if (distance < 2.0 * h) {
            return source_value(x) * exp(-sigma[c] * distance);
        }
        u = r / distance;
    }
    var axis = 0u;
    if (abs(u.y) > abs(u[axis])) {
        axis = 1u;
    }
    if (abs(u.z) > abs(u[axis])) {
        axis = 2u;
    }
    if (u[axis] == 0.0) {
        return previous[c];
    }
    let lo = march.origin.xyz;
    let hi = box_hi();
    var to_box = 1.0e30;
    for (var a = 0u; a < 3u; a = a + 1u) {
        if (u[a] > 0.0) {
            to_box = min(to_box, (x[a] - lo[a]) / u[a]);
        } else if (u[a] < 0.0) {
            to_box = min(to_box, (x[a] - hi[a]) / u[a]);
        }
    }
    let to_plane = h / abs(u[axis]);
    let spread_x = spread(x);
    if (to_box <= to_plane) {
        let y = x - u * to_box;
        return light_at(y) * exp(-sigma[c] * to_box) / spread_x;
    }
    let y = x - u * to_plane;
    var plane = at[axis] + 1;
    if (u[axis] > 0.0) {
        plane = at[axis] - 1;
    }
    let b = (axis + 1u) % 3u;
    let d = (axis + 2u) % 3u;
    let n = vec3<i32>(march.dims.xyz);
    // Bilinear brackets and quadratic stencils per lateral axis.
    var lin_i = vec2<i32>(0);
    var lin_t = vec2<f32>(0.0);
    var quad_start = vec2<i32>(0);
    var quad_q = vec2<f32>(0.0);
    for (var k = 0u; k < 2u; k = k + 1u) {
        var a = b;
        if (k == 1u) {
            a = d;
        }
        let q = (y[a] - lo[a]) / h - 0.5;
        let i = clamp(i32(floor(q)), -1, n[a] - 1);
        let p0 = position(a, i);
        let p1 = position(a, i + 1);
        var t = 0.0;
        if (p1 > p0) {
            t = clamp((q - p0) / (p1 - p0), 0.0, 1.0);
        }
        lin_i[k] = i;
        lin_t[k] = t;
        let centre = clamp(i32(floor(q + 0.5)), 0, n[a] - 1);
        var start = centre - 1;
        if (u[a] < 0.0 && centre == 0 && n[a] >= 3) {
            start = 0;
        } else if (u[a] > 0.0 && centre == n[a] - 1 && n[a] >= 3) {
            start = n[a] - 3;
        }
        quad_start[k] = start;
        quad_q[k] = q;
    }
    var lowest = 1.0e38;
    var highest = -1.0e38;
    var bilinear = 0.0;
    var sigma_up = 0.0;
    for (var p = 0; p < 2; p = p + 1) {
        let wb = select(1.0 - lin_t.x, lin_t.x, p == 1);
        for (var r = 0; r < 2; r = r + 1) {
            let wd = select(1.0 - lin_t.y, lin_t.y, r == 1);
            let node = node_value(axis, b, d, plane, lin_i.x + p, lin_i.y + r);
            lowest = min(lowest, node.psi);
            highest = max(highest, node.psi);
            bilinear = bilinear + wb * wd * node.psi;
            sigma_up = sigma_up + wb * wd * node.sigma;
        }
    }
    // Lagrange weights on three nodes per lateral axis.
    var weights = array<vec3<f32>, 2>(vec3<f32>(0.0), vec3<f32>(0.0));
    for (var k = 0u; k < 2u; k = k + 1u) {
        var a = b;
        if (k == 1u) {
            a = d;
        }
        let s = quad_start[k];
        let x0 = position(a, s);
        let x1 = position(a, s + 1);
        let x2 = position(a, s + 2);
        let q = quad_q[k];
        weights[k] = vec3<f32>(
            (q - x1) * (q - x2) / ((x0 - x1) * (x0 - x2)),
            (q - x0) * (q - x2) / ((x1 - x0) * (x1 - x2)),
            (q - x0) * (q - x1) / ((x2 - x0) * (x2 - x1)),
        );
    }
    var psi = 0.0;
    for (var p = 0; p < 3; p = p + 1) {
        for (var r = 0; r < 3; r = r + 1) {
            let w = weights[0][p] * weights[1][r];
            if (w != 0.0) {
                psi = psi + w * node_value(axis, b, d, plane, quad_start.x + p, quad_start.y + r).psi;
            }
        }
    }
    if (finite(psi)) {
        psi = clamp(psi, lowest, highest);
    } else {
        psi = bilinear;
    }
    return psi * exp(-0.5 * (sigma[c] + sigma_up) * to_plane) / spread_x;
}

// One layer: a distant light's plane `s`, or a point light's shell `s` (six faces, each
// cell on several faces taken by the face of its lowest axis).
@compute @workgroup_size(64)
fn layer_sweep(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let t = flat_group(wg, march.dims.w) * 64u + local;
    let n = vec3<i32>(march.dims.xyz);
    let s = sweep_layer.s;
    var at = vec3<i32>(0);
    if (is_point()) {
        let per_face = march.kind.z;
        let face = t / per_face;
        if (face >= 6u || (s == 0 && face > 0u)) {
            return;
        }
        let a = face / 2u;
        let b = (a + 1u) % 3u;
        let d = (a + 2u) % 3u;
        let l = t % per_face;
        let ib = i32(l % u32(n[b]));
        let id = i32(l / u32(n[b]));
        if (id >= n[d]) {
            return;
        }
        var side = -1;
        if (face % 2u == 1u) {
            side = 1;
        }
        at[a] = march.centre[a] + side * s;
        at[b] = ib;
        at[d] = id;
        if (at[a] < 0 || at[a] >= n[a]) {
            return;
        }
        let off = abs(at - march.centre.xyz);
        if (off[b] > s || off[d] > s) {
            return;
        }
        // A cell on an edge or corner of the shell belongs to the face of its lowest axis.
        if ((b < a && off[b] == s) || (d < a && off[d] == s)) {
            return;
        }
    } else {
        let a = march.kind.y;
        let b = (a + 1u) % 3u;
        let d = (a + 2u) % 3u;
        if (t >= u32(n[b] * n[d])) {
            return;
        }
        at[a] = s;
        if (march.light[a] < 0.0) {
            at[a] = n[a] - 1 - s;
        }
        at[b] = i32(t % u32(n[b]));
        at[d] = i32(t / u32(n[b]));
    }
    let c = index_of(vec3<u32>(at), march.dims.xyz);
    current[c] = characteristic(at, c);
}
