// gpu-lbm's D3Q19 lattice (rest, the six axis links and the twelve face diagonals), in lucent-lbm's order (odd links in
// pairs 2k − 1, 2k, each the other's opposite): the link tables and one storage buffer
// per link (bindings 7 …), each holding the link's populations twice (the two copies the
// pull step reads and writes, n cells apart). Joined before `lbm.wgsl`.

const Q: u32 = 19u;
const CS2: f32 = 1.0 / 3.0;

var<private> E: array<vec3<i32>, 19> = array<vec3<i32>, 19>(
    vec3<i32>(0, 0, 0),
    vec3<i32>(1, 0, 0),
    vec3<i32>(-1, 0, 0),
    vec3<i32>(0, 1, 0),
    vec3<i32>(0, -1, 0),
    vec3<i32>(0, 0, 1),
    vec3<i32>(0, 0, -1),
    vec3<i32>(1, 1, 0),
    vec3<i32>(-1, -1, 0),
    vec3<i32>(1, -1, 0),
    vec3<i32>(-1, 1, 0),
    vec3<i32>(1, 0, 1),
    vec3<i32>(-1, 0, -1),
    vec3<i32>(1, 0, -1),
    vec3<i32>(-1, 0, 1),
    vec3<i32>(0, 1, 1),
    vec3<i32>(0, -1, -1),
    vec3<i32>(0, 1, -1),
    vec3<i32>(0, -1, 1),
);
var<private> OPPOSITE: array<u32, 19> = array<u32, 19>(0u, 2u, 1u, 4u, 3u, 6u, 5u, 8u, 7u, 10u, 9u, 12u, 11u, 14u, 13u, 16u, 15u, 18u, 17u);
// The equilibrium's weights (TRT, BGK).
var<private> W: array<f32, 19> = array<f32, 19>(
    1.0 / 3.0, 1.0 / 18.0, 1.0 / 18.0, 1.0 / 18.0, 1.0 / 18.0, 1.0 / 18.0, 1.0 / 18.0, 1.0 / 36.0, 1.0 / 36.0, 1.0 / 36.0, 1.0 / 36.0, 1.0 / 36.0, 1.0 / 36.0, 1.0 / 36.0, 1.0 / 36.0, 1.0 / 36.0, 1.0 / 36.0, 1.0 / 36.0, 1.0 / 36.0,
);
// Geist's redistribution weights (rest 0).
var<private> W_GEIST: array<f32, 19> = array<f32, 19>(
    0.0, 1.0 / 12.0, 1.0 / 12.0, 1.0 / 12.0, 1.0 / 12.0, 1.0 / 12.0, 1.0 / 12.0, 1.0 / 24.0, 1.0 / 24.0, 1.0 / 24.0, 1.0 / 24.0, 1.0 / 24.0, 1.0 / 24.0, 1.0 / 24.0, 1.0 / 24.0, 1.0 / 24.0, 1.0 / 24.0, 1.0 / 24.0, 1.0 / 24.0,
);

@group(0) @binding(7) var<storage, read_write> f0: array<f32>;
@group(0) @binding(8) var<storage, read_write> f1: array<f32>;
@group(0) @binding(9) var<storage, read_write> f2: array<f32>;
@group(0) @binding(10) var<storage, read_write> f3: array<f32>;
@group(0) @binding(11) var<storage, read_write> f4: array<f32>;
@group(0) @binding(12) var<storage, read_write> f5: array<f32>;
@group(0) @binding(13) var<storage, read_write> f6: array<f32>;
@group(0) @binding(14) var<storage, read_write> f7: array<f32>;
@group(0) @binding(15) var<storage, read_write> f8: array<f32>;
@group(0) @binding(16) var<storage, read_write> f9: array<f32>;
@group(0) @binding(17) var<storage, read_write> f10: array<f32>;
@group(0) @binding(18) var<storage, read_write> f11: array<f32>;
@group(0) @binding(19) var<storage, read_write> f12: array<f32>;
@group(0) @binding(20) var<storage, read_write> f13: array<f32>;
@group(0) @binding(21) var<storage, read_write> f14: array<f32>;
@group(0) @binding(22) var<storage, read_write> f15: array<f32>;
@group(0) @binding(23) var<storage, read_write> f16: array<f32>;
@group(0) @binding(24) var<storage, read_write> f17: array<f32>;
@group(0) @binding(25) var<storage, read_write> f18: array<f32>;

fn load(k: u32, i: u32) -> f32 {
    switch k {
        case 0u: { return f0[i]; }
        case 1u: { return f1[i]; }
        case 2u: { return f2[i]; }
        case 3u: { return f3[i]; }
        case 4u: { return f4[i]; }
        case 5u: { return f5[i]; }
        case 6u: { return f6[i]; }
        case 7u: { return f7[i]; }
        case 8u: { return f8[i]; }
        case 9u: { return f9[i]; }
        case 10u: { return f10[i]; }
        case 11u: { return f11[i]; }
        case 12u: { return f12[i]; }
        case 13u: { return f13[i]; }
        case 14u: { return f14[i]; }
        case 15u: { return f15[i]; }
        case 16u: { return f16[i]; }
        case 17u: { return f17[i]; }
        default: { return f18[i]; }
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
        case 6u: { f6[i] = value; }
        case 7u: { f7[i] = value; }
        case 8u: { f8[i] = value; }
        case 9u: { f9[i] = value; }
        case 10u: { f10[i] = value; }
        case 11u: { f11[i] = value; }
        case 12u: { f12[i] = value; }
        case 13u: { f13[i] = value; }
        case 14u: { f14[i] = value; }
        case 15u: { f15[i] = value; }
        case 16u: { f16[i] = value; }
        case 17u: { f17[i] = value; }
        default: { f18[i] = value; }
    }
}
