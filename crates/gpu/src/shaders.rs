//! The WGSL sources of lucent's kernels, from the repository's top-level `shaders/` folder,
//! compiled into the crate. Every kernel is prefixed with `shaders/common.wgsl` (2-D workgroup numbering, pairwise workgroup sums, finiteness
//! tests). `tests/it/shaders.rs` validates every one with naga, so a shader error fails
//! `cargo test` rather than a user's run.

/// Helpers prepended to the kernels below.
pub const COMMON: &str = include_str!("../../../shaders/common.wgsl");

macro_rules! kernel {
    ($file:literal) => {
        concat!(
            include_str!("../../../shaders/common.wgsl"),
            include_str!(concat!("../../../shaders/", $file))
        )
    };
}

/// Pairwise workgroup reductions (sum, sum of squares, maximum of |x|) into per-workgroup
/// partials that the host adds in f64.
pub const REDUCE: &str = kernel!("reduce.wgsl");

/// `gpu-direct`: transmittance by exact ray marching of the trilinear σ_t, read from a
/// dense grid (`sigma_dense.wgsl`).
pub const DIRECT: &str = concat!(
    include_str!("../../../shaders/common.wgsl"),
    include_str!("../../../shaders/sigma_dense.wgsl"),
    include_str!("../../../shaders/direct.wgsl")
);
/// `gpu-direct` reading σ_t from a [`crate::BrickAtlas`] (`sigma_atlas.wgsl`).
pub const DIRECT_ATLAS: &str = concat!(
    include_str!("../../../shaders/common.wgsl"),
    include_str!("../../../shaders/sigma_atlas.wgsl"),
    include_str!("../../../shaders/direct.wgsl")
);
/// `gpu-ftcs-diffusion`: one FTCS step on a CSR system, with residual partials.
pub const FTCS: &str = kernel!("ftcs.wgsl");
/// `gpu-ftcs-p1`: the fluence half of a P1 FTCS step.
pub const P1: &str = kernel!("p1.wgsl");
/// `gpu-ftcs-p1`: the flux half of a P1 FTCS step.
pub const P1_FLUX: &str = kernel!("p1_flux.wgsl");
/// `gpu-convection-diffusion`: one layer of the short-characteristic light march.
pub const CONVECTION: &str = kernel!("convection.wgsl");
/// `gpu-convection-diffusion`: red–black Gauss–Seidel of the implicit scattering step.
pub const SCATTER: &str = kernel!("scatter.wgsl");
/// `gpu-lbm` on the D3Q7 lattice: one pull step (`lbm_d3q7.wgsl` + `lbm.wgsl`).
pub const LBM_D3Q7: &str = concat!(
    include_str!("../../../shaders/common.wgsl"),
    include_str!("../../../shaders/lbm_d3q7.wgsl"),
    include_str!("../../../shaders/lbm.wgsl")
);
/// `gpu-lbm` on the D3Q19 lattice: one pull step (`lbm_d3q19.wgsl` + `lbm.wgsl`).
pub const LBM_D3Q19: &str = concat!(
    include_str!("../../../shaders/common.wgsl"),
    include_str!("../../../shaders/lbm_d3q19.wgsl"),
    include_str!("../../../shaders/lbm.wgsl")
);
/// `gpu-dom`: one hyperplane of the eight octant sweeps, and the scattering product.
pub const DOM: &str = kernel!("dom.wgsl");
/// `gpu-diffusion-mg`: a multigrid level's red–black smoothing colour, fused residual and
/// restriction, and prolongation.
pub const MULTIGRID: &str = kernel!("multigrid.wgsl");
/// `gpu-diffusion-mg`'s outer iteration in f64 (residual, correction, norm) and the
/// coarsest level's dense solve: only for a device with `SHADER_F64`
/// ([`crate::GpuContext::has_f64`]).
pub const MULTIGRID_F64: &str = kernel!("multigrid_f64.wgsl");
/// The largest change between two fields (stopping rules of passes).
pub const MAX_CHANGE: &str = kernel!("max_change.wgsl");
/// lucent-render's ray march on the device: one invocation per pixel.
pub const RENDER: &str = kernel!("render.wgsl");

/// Every shader with its file names (`a + b` where a kernel joins several files), for
/// validation (`common.wgsl` inside every kernel). Those whose name ends in `_f64.wgsl`
/// need naga's `FLOAT64` capability (wgpu's `SHADER_F64`).
pub const ALL: &[(&str, &str)] = &[
    ("common.wgsl", COMMON),
    ("reduce.wgsl", REDUCE),
    ("sigma_dense.wgsl + direct.wgsl", DIRECT),
    ("sigma_atlas.wgsl + direct.wgsl", DIRECT_ATLAS),
    ("ftcs.wgsl", FTCS),
    ("p1.wgsl", P1),
    ("p1_flux.wgsl", P1_FLUX),
    ("convection.wgsl", CONVECTION),
    ("scatter.wgsl", SCATTER),
    ("lbm_d3q7.wgsl + lbm.wgsl", LBM_D3Q7),
    ("lbm_d3q19.wgsl + lbm.wgsl", LBM_D3Q19),
    ("dom.wgsl", DOM),
    ("multigrid.wgsl", MULTIGRID),
    ("multigrid_f64.wgsl", MULTIGRID_F64),
    ("max_change.wgsl", MAX_CHANGE),
    ("render.wgsl", RENDER),
];

/// The module of `source` on `context`'s device.
pub(crate) fn module(
    context: &crate::GpuContext,
    name: &str,
    source: &str,
) -> Result<wgpu::ShaderModule, crate::GpuError> {
    context.checked(|| {
        context
            .device()
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(name),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            })
    })
}
