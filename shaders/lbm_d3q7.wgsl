// gpu-lbm's D3Q7 lattice (rest and the six axis links), in lucent-lbm's order (odd links in
// pairs 2k − 1, 2k, each the other's opposite): the link tables and one storage buffer
// per link (bindings 7 …), each holding the link's populations twice (the two copies the
// pull step reads and writes, n cells apart). Joined before `lbm.wgsl`.

const Q: u32 = 7u;
const CS2: f32 = 1.0 / 4.0;

var<private> E: array<vec3<i32>, 7> = array<vec3<i32>, 7>(
    vec3<i32>(0, 0, 0),
    vec3<i32>(1, 0, 0),
    vec3<i32>(-1, 0, 0),
    vec3<i32>(0, 1, 0),
    vec3<i32>(0, -1, 0),
    vec3<i32>(0, 0, 1),
    vec3<i32>(0, 0, -1),
);
var<private> OPPOSITE: array<u32, 7> = array<u32, 7>(0u, 2u, 1u, 4u, 3u, 6u, 5u);
// The equilibrium's weights (TRT, BGK).
var<private> W: array<f32, 7> = array<f32, 7>(
    1.0 / 4.0, 1.0 / 8.0, 1.0 / 8.0, 1.0 / 8.0, 1.0 / 8.0, 1.0 / 8.0, 1.0 / 8.0,
);
// Geist's redistribution weights (rest 0).
var<private> W_GEIST: array<f32, 7> = array<f32, 7>(
    0.0, 1.0 / 6.0, 1.0 / 6.0, 1.0 / 6.0, 1.0 / 6.0, 1.0 / 6.0, 1.0 / 6.0,
);

@group(0) @binding(7) var<storage, read_write> f0: array<f32>;
@group(0) @binding(8) var<storage, read_write> f1: array<f32>;
@group(0) @binding(9) var<storage, read_write> f2: array<f32>;
@group(0) @binding(10) var<storage, read_write> f3: array<f32>;
@group(0) @binding(11) var<storage, read_write> f4: array<f32>;
@group(0) @binding(12) var<storage, read_write> f5: array<f32>;
@group(0) @binding(13) var<storage, read_write> f6: array<f32>;

fn load(k: u32, i: u32) -> f32 {
    switch k {
        case 0u: { return f0[i]; }
        case 1u: { return f1[i]; }
        case 2u: { return f2[i]; }
        case 3u: { return f3[i]; }
        case 4u: { return f4[i]; }
        case 5u: { return f5[i]; }
        default: { return f6[i]; }
    }
}

fn store(k: u32, i: u32, value: f32) {
    switch k {
        case 0u: { f0[i] = value; }
        case 1u: { f1[i] = value; }
        case 2u: { f2[i] = value; }
        case 3u: { f3[i] = value; }
        case 4u: { f4[i] = value; }
        case 5u: { f5[i] = value; }
        default: { f6[i] = value; }
    }
}
