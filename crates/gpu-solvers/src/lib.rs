//! # lucent-gpu-solvers: lucent's solvers on the GPU
//!
//! Registry twins of CPU solvers on [`lucent_gpu`] (wgpu compute, WGSL kernels from the
//! repository's `shaders/`): same parameters, same capabilities, same stability checks
//! and the same driver, cross-checked against their twins on the suite scenes
//! (`tolerances.toml`, `docs/validation.md`).
//!
//! | entry | equation | on the device | stable for |
//! |---|---|---|---|
//! | `gpu-direct` | φ_u(x) = Σ_l E_l(x) e^{−∫σ_t ds} (+ sky) | exact ray march of the trilinear σ_t per cell and light | always |
//! | `gpu-ftcs-diffusion` | V dφ/dτ = b − Aφ (diffusion-mg's system) | FTCS on CSR in correction form, f64 residual on the host | cΔt ≤ 2V / max_i Σ_j \|a_ij\| |
//! | `gpu-ftcs-p1` | (1/c)∂φ/∂t = −∇·E − σ_aφ + q, (1/c)∂E/∂t = −∇φ/3 − σ_t′E | FTCS, φ and E ping-pong | (1−K_φ)(1−K_E) + r² ≤ 1 (staggered 4r²) |
//! | `gpu-convection-diffusion` | u·∇ρ = −σ_t ρ per light, then (1 − σ̂_s t ∇²)L = ρ | short-characteristic layer sweeps, red–black Gauss–Seidel | always (no time step) |
//! | `gpu-diffusion-mg` | −∇·(D∇φ) + σ_a φ = q (`diffusion-mg`'s embedded-boundary system) | full multigrid and V-cycles: red–black colours, fused residual and restriction, prolongation, the coarsest level by its dense inverse; the f64 outer iteration on the device where it has f64 (else on the host) | always (a fixed-point iteration on an M-matrix) |
//! | `gpu-dom` | ω·∇ψ + σ_t ψ = σ_s Σ p ψ′ + Q (`dom`'s discrete ordinates) | source fill, eight octant sweeps by cell hyperplanes, scattering product; DSA, Anderson, GMRES on the host | always (implicit sweeps) |
//! | `gpu-lbm` | f_k(x + e_k, t + 1) = C(f(x, t))_k, ρ = Σ f_k (`lbm`'s lattice) | pull steps between two copies, one dispatch per step, one buffer per link | ω± ∈ (0, 2) by construction; σ_a h < 1 |
//!
//! Units as the twins': lengths in the grid's unit, σ in 1/length, cΔt a length.
//!
//! ## Precision
//!
//! Fields are f32 on the device (WGSL has no portable f64); reductions are pairwise per
//! workgroup and added in f64 on the host. Each backend's documentation states how close
//! it comes to its twin; `gpu-ftcs-diffusion` reaches the twin's f64 tolerance by defect
//! correction. Bad input is refused before upload (NaN, negative coefficients) and a
//! grid beyond the adapter's binding limit before allocation ([`lucent_gpu::GpuError`],
//! surfaced as `SolveError::Device`).
//!
//! ```no_run
//! use glam::DVec3;
//! use lucent_core::{Boundary, Field, Light, Medium, Problem, SolveOptions, Solver, Spectrum};
//! use lucent_gpu_solvers::GpuSolver;
//! use lucent_grid::{Grid, GridGeometry};
//!
//! let geometry = GridGeometry::new([32, 32, 32], DVec3::splat(1.0 / 32.0), DVec3::ZERO)?;
//! let medium = Medium {
//!     sigma_t: vec![Grid::filled(geometry, 2.0)],
//!     albedo: vec![Field::Constant(0.8)],
//!     phase: lucent_optics::Phase::Isotropic,
//! };
//! let sun = Light::Directional {
//!     direction: DVec3::new(0.3, 0.2, 1.0).normalize(),
//!     irradiance: Spectrum::Grey(1.0),
//! };
//! let problem = Problem::new(geometry, medium, vec![sun], Boundary::Vacuum, None)?;
//! let solver = (GpuSolver::GPU_DIRECT.build)(&Default::default())?;
//! let solution = solver.solve(&problem, &SolveOptions::default())?;
//! println!("{}", solution.report.stop_reason);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod convection;
mod direct;
mod dom;
mod ftcs;
mod lbm;
mod multigrid;
mod p1;
mod params;
mod solver;

pub use dom::{Wavefront, dom_transport, dom_transport_with};
pub use lbm::march as lbm_march;
pub use multigrid::{DENSE_COARSEST_MAX, DeviceMultigrid, KernelTiming, OuterIteration};
pub use params::GpuConvectionParams;
pub use solver::GpuSolver;
