// The renderer's ray march (lucent-render `render`, ported): one invocation per pixel of
// a band of rows, one channel per dispatch. Each step of length Δ takes the medium and the
// source as constant and integrates them exactly,
//   L += T·S·(1 − e^{−σ_t Δ})/σ_t,   T ← T·e^{−σ_t Δ},
// with S = σ_s·L_s(x, −ω) + Q_e, the step ends at t0 + step·(jitter + k) and the march
// stopping where the box ends or T ≤ 10⁻⁴ (OPAQUE). Every grid is sampled trilinearly
// exactly as `Grid::sample_trilinear` does (clamped to the cell centres, the same order of
// lerps), in f32.
//
// The in-scattered radiance per unit σ_s, L_s, is the sum of what this pass carries:
//   flags bit 0: an isotropic part, iso(x)/(4π) (the fluence of a solution kept without
//                directions, or the isotropic rest of a per-light solution);
//   lights:      Σ_l p(ω_l·ω) E_l(x) s_l T_l(x) over this pass's lights (`Light::arrival`
//                ported: directional, point and spot lights), T_l packed in `transmittance`;
//   flags bit 2: discrete ordinates, Σ_m κ-kernel weights × the stored in-scattered
//                radiance, interpolated in space with the 8 corner weights;
// and flags bit 1 adds the emission Q_e. Passes beyond the first (lights that did not fit
// one binding) add their radiance to the image; only the first writes T·background.

struct RenderParams {
    // nx, ny, nz, groups_x
    dims: vec4<u32>,
    // width, height, first row of the band, pixels in the band
    image: vec4<u32>,
    // lights in this pass, ordinate directions, flags, first light record of this pass
    counts: vec4<u32>,
    // first and last output colour written, accumulate (1) or write (0), camera kind
    // (0 pinhole, 1 orthographic)
    outputs: vec4<u32>,
    // x: channel of the light spectra, y: max steps
    channel: vec4<u32>,
    // grid origin (world); w: step length
    origin: vec4<f32>,
    // 1 / cell size per axis; w: aspect (width / height)
    inv_spacing: vec4<f32>,
    // the box (world); lo.w: ordinate kernel concentration κ, hi.w: unused
    box_lo: vec4<f32>,
    box_hi: vec4<f32>,
    // camera position (or centre of the orthographic image plane); w: half the view's
    // height at unit distance (pinhole: tan(fov/2)) or in world units (orthographic)
    eye: vec4<f32>,
    right: vec4<f32>,
    up: vec4<f32>,
    forward: vec4<f32>,
    // radiance behind the medium per output colour
    background: vec4<f32>,
    // phase function: g1, g2, weight of the first lobe, 1 for Rayleigh
    phase: vec4<f32>,
    // x: how far away directional lights are (unused: they arrive along their
    // direction), y: the floor on r² of point and spot lights
    lighting: vec4<f32>,
}

@group(0) @binding(0) var<storage, read> sigma_t: array<f32>;
@group(0) @binding(1) var<storage, read> albedo: array<f32>;
@group(0) @binding(2) var<storage, read> iso: array<f32>;
@group(0) @binding(3) var<storage, read> emission: array<f32>;
@group(0) @binding(4) var<storage, read> transmittance: array<f32>;
// ordinate directions (xyz, w unused), then 4 records per light:
// (position or direction, kind 0 directional / 1 point / 2 spot), (spot axis, 0),
// (cos inner, cos outer, 0, 0), (spectrum r, g, b, 0)
@group(0) @binding(5) var<storage, read> records: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read> ordinates: array<f32>;
@group(0) @binding(7) var<storage, read_write> image: array<f32>;
@group(0) @binding(8) var<uniform> params: RenderParams;

const OPAQUE: f32 = 1.0e-4;
const INV_4PI: f32 = 0.07957747154594767;
const FLAG_ISO: u32 = 1u;
const FLAG_EMISSION: u32 = 2u;
const FLAG_ORDINATES: u32 = 4u;

// `lowbias32` (C. Wellons), as lucent-render's `jitter`.
fn lowbias32(x: u32) -> u32 {
    var h = x;
    h = h ^ (h >> 16u);
    h = h * 0x7feb352du;
    h = h ^ (h >> 15u);
    h = h * 0x846ca68bu;
    return h ^ (h >> 16u);
}

fn jitter(x: u32, y: u32) -> f32 {
    return f32(lowbias32(x ^ lowbias32(y)) >> 8u) / 16777216.0;
}

// Where a trilinear sample reads: the base cell, the strides to the next cell along each
// axis (0 on an axis of one cell) and the fractions.
struct Lerp {
    base: u32,
    stride: vec3<u32>,
    t: vec3<f32>,
}

fn lerp_at(p: vec3<f32>) -> Lerp {
    let v = (p - params.origin.xyz) * params.inv_spacing.xyz - vec3<f32>(0.5);
    let n = params.dims.xyz;
    var cell = vec3<u32>(0u);
    var t = vec3<f32>(0.0);
    for (var a = 0; a < 3; a = a + 1) {
        // `axis_lerp`: NaN and single-cell axes read cell 0.
        if (n[a] > 1u && v[a] == v[a]) {
            let c = clamp(v[a], 0.0, f32(n[a] - 1u));
            cell[a] = min(u32(c), n[a] - 2u);
            t[a] = c - f32(cell[a]);
        }
    }
    var l: Lerp;
    l.base = index_of(cell, n);
    l.stride = vec3<u32>(select(0u, 1u, n.x > 1u), select(0u, n.x, n.y > 1u), select(0u, n.x * n.y, n.z > 1u));
    l.t = t;
    return l;
}

// The trilinear blend of the 8 corner values c[dx + 2 dy + 4 dz], in the host's order.
fn blend(l: Lerp, c: array<f32, 8>) -> f32 {
    let c00 = mix(c[0], c[1], l.t.x);
    let c10 = mix(c[2], c[3], l.t.x);
    let c01 = mix(c[4], c[5], l.t.x);
    let c11 = mix(c[6], c[7], l.t.x);
    return mix(mix(c00, c10, l.t.y), mix(c01, c11, l.t.y), l.t.z);
}

fn corner(l: Lerp, i: u32) -> u32 {
    return l.base + select(0u, l.stride.x, (i & 1u) != 0u) + select(0u, l.stride.y, (i & 2u) != 0u)
        + select(0u, l.stride.z, (i & 4u) != 0u);
}

fn sample_sigma_t(l: Lerp) -> f32 {
    var c: array<f32, 8>;
    for (var i = 0u; i < 8u; i = i + 1u) {
        c[i] = sigma_t[corner(l, i)];
    }
    return blend(l, c);
}

fn sample_albedo(l: Lerp) -> f32 {
    var c: array<f32, 8>;
    for (var i = 0u; i < 8u; i = i + 1u) {
        c[i] = albedo[corner(l, i)];
    }
    return blend(l, c);
}

fn sample_iso(l: Lerp) -> f32 {
    var c: array<f32, 8>;
    for (var i = 0u; i < 8u; i = i + 1u) {
        c[i] = iso[corner(l, i)];
    }
    return blend(l, c);
}

fn sample_emission(l: Lerp) -> f32 {
    var c: array<f32, 8>;
    for (var i = 0u; i < 8u; i = i + 1u) {
        c[i] = emission[corner(l, i)];
    }
    return blend(l, c);
}

fn sample_transmittance(l: Lerp, offset: u32) -> f32 {
    var c: array<f32, 8>;
    for (var i = 0u; i < 8u; i = i + 1u) {
        c[i] = transmittance[offset + corner(l, i)];
    }
    return blend(l, c);
}

// Henyey–Greenstein written as lucent-optics does: 1 + g² − 2gμ = (1 − g)² + 2g(1 − μ).
fn henyey_greenstein(g: f32, mu: f32) -> f32 {
    let d = (1.0 - g) * (1.0 - g) + 2.0 * g * (1.0 - mu);
    return INV_4PI * (1.0 - g * g) / (d * sqrt(d));
}

fn phase(mu_in: f32) -> f32 {
    let mu = clamp(mu_in, -1.0, 1.0);
    let p = params.phase;
    if (p.w > 0.5) {
        return 3.0 / 16.0 * 0.3183098861837907 * (1.0 + mu * mu);
    }
    return p.z * henyey_greenstein(p.x, mu) + (1.0 - p.z) * henyey_greenstein(p.y, mu);
}

// Σ over this pass's lights of p(ω_l·ω) E_l(x) s_l T_l(x).
fn lights_inscattered(l: Lerp, x: vec3<f32>, omega: vec3<f32>) -> f32 {
    let cells = params.dims.x * params.dims.y * params.dims.z;
    let floor_r2 = params.lighting.y;
    var total = 0.0;
    for (var i = 0u; i < params.counts.x; i = i + 1u) {
        let r = params.counts.w + 4u * i;
        let at = records[r];
        let kind = u32(at.w);
        var w = at.xyz;
        var irradiance = 1.0;
        if (kind != 0u) {
            let d = x - at.xyz;
            let r2 = dot(d, d);
            if (kind == 1u) {
                w = select(vec3<f32>(0.0, 0.0, 1.0), d / sqrt(r2), r2 > 0.0);
                irradiance = 1.0 / max(r2, floor_r2);
            } else {
                let axis = records[r + 1u].xyz;
                w = select(axis, d / sqrt(r2), r2 > 0.0);
                let cos = dot(w, axis);
                let ci = records[r + 2u].x;
                let co = records[r + 2u].y;
                var falloff = 0.0;
                if (cos >= ci) {
                    falloff = 1.0;
                } else if (cos > co) {
                    let s = (cos - co) / (ci - co);
                    falloff = s * s * (3.0 - 2.0 * s);
                }
                irradiance = falloff / max(r2, floor_r2);
            }
        }
        let spectrum = records[r + 3u][params.channel.x];
        total = total + phase(dot(w, omega)) * spectrum * irradiance * sample_transmittance(l, i * cells);
    }
    return total;
}

// Σ_m e^{κ(ω_m·ω − 1)} J_m(x) / Σ_m e^{κ(ω_m·ω − 1)}, J_m interpolated with the corner
// weights (`OrdinateRadiance::inscattered`).
fn ordinates_inscattered(l: Lerp, omega: vec3<f32>) -> f32 {
    let m_count = params.counts.y;
    let kappa = params.box_lo.w;
    var weights: array<f32, 8>;
    var cells: array<u32, 8>;
    for (var i = 0u; i < 8u; i = i + 1u) {
        let tx = select(1.0 - l.t.x, l.t.x, (i & 1u) != 0u);
        let ty = select(1.0 - l.t.y, l.t.y, (i & 2u) != 0u);
        let tz = select(1.0 - l.t.z, l.t.z, (i & 4u) != 0u);
        weights[i] = tx * ty * tz;
        cells[i] = corner(l, i) * m_count;
    }
    var total = 0.0;
    var norm = 0.0;
    for (var m = 0u; m < m_count; m = m + 1u) {
        let w = exp(kappa * (dot(records[m].xyz, omega) - 1.0));
        var j = 0.0;
        for (var i = 0u; i < 8u; i = i + 1u) {
            j = j + weights[i] * ordinates[cells[i] + m];
        }
        total = total + w * j;
        norm = norm + w;
    }
    return total / norm;
}

fn ray_box(o: vec3<f32>, d: vec3<f32>) -> vec2<f32> {
    var t0 = 0.0;
    var t1 = 3.0e38;
    for (var a = 0; a < 3; a = a + 1) {
        let lo = params.box_lo[a];
        let hi = params.box_hi[a];
        if (d[a] == 0.0) {
            if (o[a] < lo || o[a] > hi) {
                return vec2<f32>(1.0, 0.0);
            }
        } else {
            let ta = (lo - o[a]) / d[a];
            let tb = (hi - o[a]) / d[a];
            t0 = max(t0, min(ta, tb));
            t1 = min(t1, max(ta, tb));
        }
    }
    return vec2<f32>(t0, t1);
}

@compute @workgroup_size(64)
fn march(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) local: u32) {
    let id = flat_group(wg, params.dims.w) * 64u + local;
    if (id >= params.image.w) {
        return;
    }
    let width = params.image.x;
    let x = id % width;
    let y = params.image.z + id / width;
    let u = (f32(x) + 0.5) / f32(width);
    let v = (f32(y) + 0.5) / f32(params.image.y);
    let sx = 2.0 * u - 1.0;
    let sy = 1.0 - 2.0 * v;
    let half = params.eye.w;
    let aspect = params.inv_spacing.w;
    var o = params.eye.xyz;
    var d = params.forward.xyz;
    if (params.outputs.w == 0u) {
        d = normalize(d + params.right.xyz * (sx * half * aspect) + params.up.xyz * (sy * half));
    } else {
        o = o + params.right.xyz * (sx * half * aspect) + params.up.xyz * (sy * half);
    }
    let omega = -d;
    let flags = params.counts.z;
    let step = params.origin.w;

    var radiance = 0.0;
    var t = 1.0;
    let hit = ray_box(o, d);
    if (hit.x < hit.y) {
        let t1 = hit.y;
        let start = hit.x + step * jitter(x, y);
        var previous = hit.x;
        // The step count is bounded (the box's length over the step, plus the partial
        // steps at both ends), so a ray cannot loop forever whatever f32 rounding does.
        for (var k = 0u; k < params.channel.y; k = k + 1u) {
            if (!(previous < t1 && t > OPAQUE)) {
                break;
            }
            let end = min(start + f32(k) * step, t1);
            let ds = end - previous;
            let p = o + d * (0.5 * (previous + end));
            let l = lerp_at(p);
            let s_t = sample_sigma_t(l);
            let s_s = sample_albedo(l) * s_t;
            var source = 0.0;
            if (s_s > 0.0) {
                var inscattered = lights_inscattered(l, p, omega);
                if ((flags & FLAG_ISO) != 0u) {
                    inscattered = inscattered + sample_iso(l) * INV_4PI;
                }
                if ((flags & FLAG_ORDINATES) != 0u) {
                    inscattered = inscattered + ordinates_inscattered(l, omega);
                }
                source = s_s * inscattered;
            }
            if ((flags & FLAG_EMISSION) != 0u) {
                source = source + sample_emission(l);
            }
            let attenuation = exp(-s_t * ds);
            var weight = ds;
            if (s_t * ds > 1.0e-6) {
                weight = (1.0 - attenuation) / s_t;
            }
            radiance = radiance + t * source * weight;
            t = t * attenuation;
            previous = end;
        }
    }
    let pixel = (y * width + x) * 3u;
    for (var c = params.outputs.x; c <= params.outputs.y; c = c + 1u) {
        if (params.outputs.z == 1u) {
            image[pixel + c] = image[pixel + c] + radiance;
        } else {
            image[pixel + c] = radiance + t * params.background[c];
        }
    }
}
