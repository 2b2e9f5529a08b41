// gpu-dom: one transport step of lucent-dom's source iteration on the device (Bernabei
// ch. 5): the eight octant sweeps of
//
//   ω_n·∇ψ_n + σ_t ψ_n = S_n,   S_n = Q_n + σ_s J_n (filled by the host),
//
// with lucent-dom's closures (step, diamond difference with its set-to-zero fix-up,
// Bernabei's exponential short characteristic; their linear forms for the Krylov phase),
// then the in-scattered radiance J′_m = Σ_n ψ̄_n B_nm and the scalar flux Σ_n w_n ψ̄_n.
//
// `sweep_plane` is one hyperplane i′ + j′ + k′ = p of the cell wavefront of all eight
// octants at once (i′ counted from each octant's upwind corner): one invocation per
// (octant, (j′, k′) in the plane's bounding box, direction), those whose i′ falls outside
// the grid returning at once. Directions run fastest, so a cell's invocations read its
// source and face slots, stored direction-fastest, as contiguous runs. A cell's three upwind faces were written by the
// previous dispatch, and each face slot — indexed by the cell's two other coordinates, of
// which the plane fixes the third — is read and then overwritten by one invocation only:
// no races, and only 3 × (face area) values per direction live on the device. Dispatches in
// one compute pass see each other's writes (WebGPU's usage scopes), so a sweep is one
// command buffer of nx + ny + nz − 2 dispatches and `scatter`. `sweep_blocks` is the same
// wavefront over blocks of cells (below); both run `sweep_cell` on each cell and direction.
//
// Per cell and direction the data are split by octant (src0..7, psi0..7: cells × the
// octant's directions, lucent-dom's block order), so that at 256³ × 48 directions each
// binding holds 400 MB, under the 2 GiB a binding may hold on current drivers. f32
// throughout (the CPU sweeps in f64 and stores f32).

struct DomParams {
    // nx, ny, nz, groups_x
    dims: vec4<u32>,
    // x: the hyperplane p; y: directions N (= storage directions M); z: the most
    // directions of an octant
    plane: vec4<u32>,
    // The plane's (j′, k′) bounding box: lowest j′, lowest k′, extent in j′, extent in k′
    bounds: vec4<u32>,
    // cell widths, and the smallest (the exponential closure's thin-cell limit)
    h: vec4<f32>,
}

struct StepFlags {
    // x: closure (0 step, 1 diamond, 2 exponential); y: 1 for the linear form
    flags: vec4<u32>,
}

@group(0) @binding(0) var<uniform> params: DomParams;
@group(0) @binding(1) var<uniform> step_flags: StepFlags;
// Per octant (bit a: ω_a < 0): first direction, count.
@group(0) @binding(2) var<storage, read> octants: array<vec2<u32>, 8>;
// Per direction, GEOMETRY floats: c (3), w, fraction (9, row a = downwind face), chords
// (9), |ω| (3), pad.
@group(0) @binding(3) var<storage, read> geometry: array<f32>;
// Grid index → block index.
@group(0) @binding(4) var<storage, read> order: array<u32>;
@group(0) @binding(5) var<storage, read> sigma_t: array<f32>;
// The x, y and z face planes (ny nz, nx nz, nx ny slots), per slot all directions.
@group(0) @binding(6) var<storage, read_write> faces: array<f32>;
// Incoming radiance per boundary face cell, faces −x, +x, −y, +y, −z, +z in turn.
@group(0) @binding(7) var<storage, read> inflow: array<f32>;
// w |ω_a| ψ leaving through the downwind face planes, laid out as `faces`.
@group(0) @binding(8) var<storage, read_write> outflow: array<f32>;
// Scalar flux per cell (block order).
@group(0) @binding(9) var<storage, read_write> fluence: array<f32>;
// The scattering matrix B, N × M row-major.
@group(0) @binding(10) var<storage, read> scattering: array<f32>;
// Per octant, cells × its directions: the source S in, the in-scattered radiance J′ out.
@group(0) @binding(11) var<storage, read_write> src0: array<f32>;
@group(0) @binding(12) var<storage, read_write> src1: array<f32>;
@group(0) @binding(13) var<storage, read_write> src2: array<f32>;
@group(0) @binding(14) var<storage, read_write> src3: array<f32>;
@group(0) @binding(15) var<storage, read_write> src4: array<f32>;
@group(0) @binding(16) var<storage, read_write> src5: array<f32>;
@group(0) @binding(17) var<storage, read_write> src6: array<f32>;
@group(0) @binding(18) var<storage, read_write> src7: array<f32>;
// Per octant, cells × its directions: the cell-average radiance ψ̄.
@group(0) @binding(19) var<storage, read_write> psi0: array<f32>;
@group(0) @binding(20) var<storage, read_write> psi1: array<f32>;
@group(0) @binding(21) var<storage, read_write> psi2: array<f32>;
@group(0) @binding(22) var<storage, read_write> psi3: array<f32>;
@group(0) @binding(23) var<storage, read_write> psi4: array<f32>;
@group(0) @binding(24) var<storage, read_write> psi5: array<f32>;
@group(0) @binding(25) var<storage, read_write> psi6: array<f32>;
@group(0) @binding(26) var<storage, read_write> psi7: array<f32>;

fn load_src(o: u32, i: u32) -> f32 {
    switch o {
        case 0u: { return src0[i]; }
        case 1u: { return src1[i]; }
        case 2u: { return src2[i]; }
        case 3u: { return src3[i]; }
        case 4u: { return src4[i]; }
        case 5u: { return src5[i]; }
        case 6u: { return src6[i]; }
        default: { return src7[i]; }
    }
}

fn store_src(o: u32, i: u32, v: f32) {
    switch o {
        case 0u: { src0[i] = v; }
        case 1u: { src1[i] = v; }
        case 2u: { src2[i] = v; }
        case 3u: { src3[i] = v; }
        case 4u: { src4[i] = v; }
        case 5u: { src5[i] = v; }
        case 6u: { src6[i] = v; }
        default: { src7[i] = v; }
    }
}

fn load_psi(o: u32, i: u32) -> f32 {
    switch o {
        case 0u: { return psi0[i]; }
        case 1u: { return psi1[i]; }
        case 2u: { return psi2[i]; }
        case 3u: { return psi3[i]; }
        case 4u: { return psi4[i]; }
        case 5u: { return psi5[i]; }
        case 6u: { return psi6[i]; }
        default: { return psi7[i]; }
    }
}

fn store_psi(o: u32, i: u32, v: f32) {
    switch o {
        case 0u: { psi0[i] = v; }
        case 1u: { psi1[i] = v; }
        case 2u: { psi2[i] = v; }
        case 3u: { psi3[i] = v; }
        case 4u: { psi4[i] = v; }
        case 5u: { psi5[i] = v; }
        case 6u: { psi6[i] = v; }
        default: { psi7[i] = v; }
    }
}

const GEOMETRY: u32 = 28u;

fn g(n: u32, k: u32) -> f32 {
    return geometry[n * GEOMETRY + k];
}

// φ₁(x) = (1 − e^{−x})/x with its series near 0.
fn phi1(x: f32) -> f32 {
    if (x < 1e-3) {
        return 1.0 - 0.5 * x + x * x / 6.0;
    }
    return (1.0 - exp(-x)) / x;
}

struct Cell {
    average: f32,
    out: vec3<f32>,
}

fn step_closure(c: vec3<f32>, sigma: f32, source: f32, inflow: vec3<f32>) -> Cell {
    let psi = (source + dot(c, inflow)) / (sigma + c.x + c.y + c.z);
    return Cell(psi, vec3<f32>(psi));
}

// Diamond difference; with `fix`, the set-to-zero fix-up of negative outflows (faces
// that went negative send 0 and the cell is solved again, at most four passes).
fn diamond_closure(c: vec3<f32>, sigma: f32, source: f32, inflow: vec3<f32>, fix: bool) -> Cell {
    let psi = (source + 2.0 * dot(c, inflow)) / (sigma + 2.0 * (c.x + c.y + c.z));
    let out = 2.0 * psi - inflow;
    if (!fix || all(out >= vec3<f32>(0.0))) {
        return Cell(psi, out);
    }
    var zeroed = vec3<bool>(false);
    var average = 0.0;
    var o = vec3<f32>(0.0);
    for (var attempt = 0u; attempt < 4u; attempt++) {
        var num = source;
        var den = sigma;
        for (var a = 0u; a < 3u; a++) {
            if (zeroed[a]) {
                num += c[a] * inflow[a];
            } else {
                num += 2.0 * c[a] * inflow[a];
                den += 2.0 * c[a];
            }
        }
        average = num / den;
        var changed = false;
        for (var a = 0u; a < 3u; a++) {
            if (zeroed[a]) {
                o[a] = 0.0;
            } else {
                o[a] = 2.0 * average - inflow[a];
            }
            if (o[a] < 0.0) {
                zeroed[a] = true;
                changed = true;
            }
        }
        if (!changed) {
            break;
        }
    }
    return Cell(average, max(o, vec3<f32>(0.0)));
}

// Bernabei's face-to-face exponential characteristic (lucent-dom `exponential`).
fn exponential_closure(n: u32, sigma: f32, source: f32, inflow: vec3<f32>, clamp_psi: bool) -> Cell {
    let c = vec3<f32>(g(n, 0u), g(n, 1u), g(n, 2u));
    var out = vec3<f32>(0.0);
    for (var a = 0u; a < 3u; a++) {
        if (c[a] == 0.0) {
            continue;
        }
        var v = 0.0;
        for (var b = 0u; b < 3u; b++) {
            let f = g(n, 4u + 3u * a + b);
            if (f > 0.0) {
                let s = g(n, 13u + 3u * a + b);
                let x = sigma * s;
                v += f * (inflow[b] * exp(-x) + source * s * phi1(x));
            }
        }
        out[a] = v;
    }
    var average: f32;
    if (sigma * params.h.w > 1e-6) {
        average = (source - dot(c, out - inflow)) / sigma;
        if (clamp_psi) {
            average = max(average, 0.0);
        }
    } else {
        average = dot(c, inflow + out) / (2.0 * (c.x + c.y + c.z));
    }
    return Cell(average, out);
}

// The slot of the face plane normal to `axis` that a cell at `at` reads and writes (and
// the boundary face cell's number): the cell's two other coordinates, as lucent-dom's
// `face_cell`.
fn face_slot(axis: u32, at: vec3<u32>) -> u32 {
    let dims = params.dims.xyz;
    if (axis == 0u) {
        return at.y + dims.y * at.z;
    }
    if (axis == 1u) {
        return at.x + dims.x * at.z;
    }
    return at.x + dims.x * at.y;
}

// Offsets of the three planes inside one direction's (or octant's) face block.
fn plane_offset(axis: u32) -> u32 {
    let dims = params.dims.xyz;
    if (axis == 0u) {
        return 0u;
    }
    if (axis == 1u) {
        return dims.y * dims.z;
    }
    return dims.y * dims.z + dims.x * dims.z;
}

// Offset of boundary face f (2·axis + side) inside `inflow`.
fn inflow_offset(f: u32) -> u32 {
    let dims = params.dims.xyz;
    let areas = vec3<u32>(dims.y * dims.z, dims.x * dims.z, dims.x * dims.y);
    var offset = 0u;
    for (var k = 0u; k < f; k++) {
        offset += areas[k / 2u];
    }
    return offset;
}

// One cell and direction of octant `octant`'s sweep: the cell at `r`, counted from the
// octant's upwind corner, and the octant's direction d. Its three upwind faces must be
// final (written by the cells before it in the wavefront, or the box's inflow).
fn sweep_cell(octant: u32, r: vec3<u32>, d: u32) {
    let dims = params.dims.xyz;
    let range = octants[octant];
    let negative = vec3<bool>((octant & 1u) != 0u, (octant & 2u) != 0u, (octant & 4u) != 0u);
    let at = select(r, dims - vec3<u32>(1u) - r, negative);
    let b = order[at.x + dims.x * (at.y + dims.y * at.z)];
    let sigma = sigma_t[b];
    let n = range.x + d;
    let n_dirs = params.plane.y;
    let upwind_edge = r == vec3<u32>(0u);
    let downwind_edge = r == dims - vec3<u32>(1u);
    var slots: vec3<u32>;
    var incoming: vec3<f32>;
    for (var a = 0u; a < 3u; a++) {
        slots[a] = face_slot(a, at);
        if (upwind_edge[a]) {
            // Entered through face 2a (ω_a > 0) or 2a + 1.
            let f = 2u * a + select(0u, 1u, negative[a]);
            incoming[a] = inflow[inflow_offset(f) + slots[a]];
        } else {
            incoming[a] = faces[(plane_offset(a) + slots[a]) * n_dirs + n];
        }
    }
    let at_cell = b * range.y + d;
    let source = load_src(octant, at_cell);
    let c = vec3<f32>(g(n, 0u), g(n, 1u), g(n, 2u));
    let linear = step_flags.flags.y == 1u;
    var solved: Cell;
    switch step_flags.flags.x {
        case 0u: { solved = step_closure(c, sigma, source, incoming); }
        case 1u: { solved = diamond_closure(c, sigma, source, incoming, !linear); }
        default: { solved = exponential_closure(n, sigma, source, incoming, !linear); }
    }
    store_psi(octant, at_cell, solved.average);
    let w = g(n, 3u);
    let speed = vec3<f32>(g(n, 22u), g(n, 23u), g(n, 24u));
    for (var a = 0u; a < 3u; a++) {
        let slot = (plane_offset(a) + slots[a]) * n_dirs + n;
        if (downwind_edge[a]) {
            outflow[slot] = w * speed[a] * solved.out[a];
        } else {
            faces[slot] = solved.out[a];
        }
    }
}

@compute @workgroup_size(256)
fn sweep_plane(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    let dims = params.dims.xyz;
    let t = flat_group(wg, params.dims.w) * WG + local;
    // Directions fastest: the invocations of one cell read and write its octant's
    // contiguous values and face slots together.
    let widest = params.plane.z;
    let d = t % widest;
    let lane = t / widest;
    let per_octant = params.bounds.z * params.bounds.w;
    let octant = lane / per_octant;
    if (octant >= 8u) {
        return;
    }
    if (d >= octants[octant].y) {
        return;
    }
    let rest = lane - octant * per_octant;
    // Coordinates counted from the octant's upwind corner, inside the plane's bounding box.
    let ry = params.bounds.x + rest % params.bounds.z;
    let rz = params.bounds.y + rest / params.bounds.z;
    let p = params.plane.x;
    if (ry + rz > p || p - ry - rz >= dims.x) {
        return;
    }
    sweep_cell(octant, vec3<u32>(p - ry - rz, ry, rz), d);
}

// The block wavefront: blocks of BLOCK³ cells, counted from each octant's upwind corner,
// make the hyperplanes I′ + J′ + K′ = P (`params.plane.x`, the (J′, K′) bounding box in
// `params.bounds`); one workgroup per (octant, block) of the plane runs its block's own
// 3·BLOCK − 2 cell diagonals in turn, a storage barrier between them (a cell's upwind
// faces inside the block are written by other invocations of the same workgroup; those
// on the block's upwind sides by the previous dispatch). Invocations: BLOCK² (j, k)
// columns of the block, each marching its cells along i, times LANES that share the
// octant's directions. A sweep is then 3·(n/BLOCK) − 2 dispatches instead of 3n − 2.
const BLOCK: u32 = 4u;
const LANES: u32 = 4u;

@compute @workgroup_size(64)
fn sweep_blocks(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    let dims = params.dims.xyz;
    let blocks = (dims + vec3<u32>(BLOCK - 1u)) / BLOCK;
    let group = flat_group(wg, params.dims.w);
    let per_octant = params.bounds.z * params.bounds.w;
    let octant = group / per_octant;
    let rest = group - min(octant, 7u) * per_octant;
    let by = params.bounds.x + rest % params.bounds.z;
    let bz = params.bounds.y + rest / params.bounds.z;
    let p = params.plane.x;
    // No early return: every invocation must reach the barriers.
    let valid = octant < 8u && by + bz <= p && p - by - bz < blocks.x;
    var count = 0u;
    if (valid) {
        count = octants[octant].y;
    }
    let corner = vec3<u32>(p - by - bz, by, bz) * BLOCK;
    let lane = local % LANES;
    let column = local / LANES;
    let ly = column % BLOCK;
    let lz = column / BLOCK;
    for (var q = 0u; q < 3u * BLOCK - 2u; q++) {
        if (q >= ly + lz && q - ly - lz < BLOCK) {
            let r = corner + vec3<u32>(q - ly - lz, ly, lz);
            if (all(r < dims)) {
                for (var d = lane; d < count; d += LANES) {
                    sweep_cell(octant, r, d);
                }
            }
        }
        storageBarrier();
    }
}

// J′_m = Σ_n ψ̄_n B_nm, one invocation per cell and storage direction, summed in f32
// over the N propagation directions into the octant buffer of m (whose source the sweep
// has read); the invocation of m = 0 alone also sums the scalar flux Σ_n w_n ψ̄_n.
@compute @workgroup_size(256)
fn scatter(
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) wg: vec3<u32>,
) {
    let dims = params.dims.xyz;
    let n_dirs = params.plane.y;
    let t = flat_group(wg, params.dims.w) * WG + local;
    if (t >= dims.x * dims.y * dims.z * n_dirs) {
        return;
    }
    let b = t / n_dirs;
    let m = t - b * n_dirs;
    var sum = 0.0;
    var phi = 0.0;
    var out_octant = 0u;
    var out_index = 0u;
    for (var o = 0u; o < 8u; o++) {
        let range = octants[o];
        for (var d = 0u; d < range.y; d++) {
            let n = range.x + d;
            let psi = load_psi(o, b * range.y + d);
            sum += psi * scattering[n * n_dirs + m];
            if (m == 0u) {
                phi += g(n, 3u) * psi;
            }
            if (n == m) {
                out_octant = o;
                out_index = b * range.y + d;
            }
        }
    }
    store_src(out_octant, out_index, sum);
    if (m == 0u) {
        fluence[b] = phi;
    }
}
