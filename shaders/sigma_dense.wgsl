// σ_t of a dense grid (one array, x fastest), clamped to the grid: `sigma_at` for
// `direct.wgsl`.

@group(0) @binding(0) var<storage, read> sigma_t: array<f32>;

fn sigma_at(i: i32, j: i32, k: i32) -> f32 {
    let n = vec3<i32>(params.dims.xyz);
    let c = vec3<u32>(clamp(vec3<i32>(i, j, k), vec3<i32>(0), n - vec3<i32>(1)));
    return sigma_t[index_of(c, params.dims.xyz)];
}
