// σ_t of a brick atlas (lucent-gpu `BrickAtlas`), clamped to the grid: `sigma_at` for
// `direct.wgsl`. WebGPU has no sparse resources, so the page table is software: per brick
// of B³ cells (B = params.kind.z; bricks numbered x fastest, as lucent-grid's
// `BrickLayout`), `table[brick]` is (slot, constant bits); slot 0xffffffff marks a constant
// brick, whose value is the second word. A stored brick holds (B + 2)³ values, its cells
// and a one-cell apron, x fastest, at `atlas[slot · (B + 2)³]`.

@group(0) @binding(0) var<storage, read> atlas: array<f32>;
@group(0) @binding(4) var<storage, read> table: array<vec2<u32>>;

const CONSTANT_BRICK: u32 = 0xffffffffu;

fn sigma_at(i: i32, j: i32, k: i32) -> f32 {
    let n = vec3<i32>(params.dims.xyz);
    let c = vec3<u32>(clamp(vec3<i32>(i, j, k), vec3<i32>(0), n - vec3<i32>(1)));
    let b = params.kind.z;
    let bricks = (params.dims.xyz + vec3<u32>(b - 1u)) / b;
    let brick = c / b;
    let entry = table[index_of(brick, bricks)];
    if (entry.x == CONSTANT_BRICK) {
        return bitcast<f32>(entry.y);
    }
    let edge = b + 2u;
    let local = c - brick * b + vec3<u32>(1u);
    return atlas[entry.x * edge * edge * edge + local.x + edge * (local.y + edge * local.z)];
}
