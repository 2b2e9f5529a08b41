//! # lucent: light transport in participating media
//!
//! The facade of the lucent workspace. Each solver and support crate stands alone (pick
//! the one your renderer needs); this crate re-exports them under one roof, reads scene
//! files, holds the registry of every solver, and is the `lucent` command.
//!
//! | module | crate | what it solves |
//! |---|---|---|
//! | [`optics`] | `lucent-optics` | coefficients, phase functions, spherical quadratures, Fresnel, analytic diffusion references |
//! | [`grid`] | `lucent-grid` | dense and bricked voxel grids, resampling, transfer functions, procedural volumes, volume files |
//! | [`core`] | `lucent-core` | the `Problem`, the `Solver` trait, solutions and stop reasons, the `direct` solver |
//! | [`render`] | `lucent-render` | cameras, ray marching, tone mapping, PNG and EXR |
//! | [`mc`] | `lucent-mc` | Monte Carlo ground truth: delta tracking, track-length fluence with standard errors |
//! | [`diffusion`] | `lucent-diffusion` | steady diffusion, embedded boundary, matrix-free multigrid |
//! | [`fem`] | `lucent-fem` | Murray's finite elements for the RTE, Krylov solvers on a linear-operator trait |
//! | [`dom`] | `lucent-dom` | discrete ordinates: octant wavefront sweeps, first-collision sources, DSA |
//! | [`lbm`] | `lucent-lbm` | Lattice-Boltzmann lighting: D3Q7/D3Q19, TRT matched to diffusion, AA streaming |
//! | [`explicit`] | `lucent-explicit` | FTCS, P1, ordinates, Zhang & Ma convection–diffusion, Jacobi, with their stability bounds |
//! | [`scene`] | (here) | TOML scene files and the built-in default scene |
//! | [`auto`] | (here) | `auto`: the cheapest solver measured to meet a tolerance, chosen by regime |
//! | [`resolution`] | (here) | the coarsest grid meeting a tolerance, by Richardson estimates |
//!
//! See `ARCHITECTURE.md` at the repository root for the crate map and the data flow
//! volume → medium → problem → solver → solution → image.
//!
//! ```
//! use lucent::optics::{OpticalCoefficients, SphericalQuadrature};
//! let medium = OpticalCoefficients::from_extinction_albedo(2.0, 0.9, 0.5)?;
//! assert!((medium.sigma_t_reduced() - 1.1).abs() < 1e-12);
//! assert_eq!(SphericalQuadrature::octahedral(1)?.len(), 32);
//! # Ok::<(), lucent::optics::OpticsError>(())
//! ```

pub mod auto;
pub mod crosscheck;
pub mod fuzzing;
pub mod pareto;
pub mod progress;
pub mod resolution;
pub mod scene;

use std::path::PathBuf;

pub use lucent_core as core;
pub use lucent_diffusion as diffusion;
pub use lucent_dom as dom;
pub use lucent_explicit as explicit;
pub use lucent_fem as fem;
pub use lucent_gpu as gpu;
pub use lucent_gpu_solvers as gpu_solvers;
pub use lucent_grid as grid;
pub use lucent_lbm as lbm;
pub use lucent_mc as mc;
pub use lucent_optics as optics;
pub use lucent_paging as paging;
pub use lucent_render as render;

/// Every solver lucent has, by name.
pub fn registry() -> lucent_core::Registry {
    let mut registry = lucent_core::Registry::with_core_solvers();
    registry.register(lucent_mc::McSolver::ENTRY);
    for entry in lucent_diffusion::DiffusionSolver::ENTRIES {
        registry.register(entry);
    }
    for entry in lucent_explicit::ExplicitSolver::ENTRIES {
        registry.register(entry);
    }
    registry.register(lucent_fem::FemP1Solver::ENTRY);
    registry.register(lucent_fem::FemDiffusionSolver::ENTRY);
    registry.register(lucent_dom::DomSolver::ENTRY);
    registry.register(lucent_lbm::LbmSolver::ENTRY);
    registry.register(lucent_hybrid::HybridSolver::ENTRY);
    for entry in lucent_gpu_solvers::GpuSolver::ENTRIES {
        registry.register(entry);
    }
    registry.register(auto::AutoSolver::ENTRY);
    registry
}

/// Builds rayon's global pool within [`lucent_core::SolveOptions::MAX_THREADS`] when
/// `RAYON_NUM_THREADS` asks for more (rayon would try to start them all: 100 000 threads
/// never finished starting), and says so; `None` when nothing was capped. Call it before
/// any parallel work (the `lucent` command and the Python module do).
pub fn cap_global_threads() -> Option<String> {
    let asked = std::env::var("RAYON_NUM_THREADS").ok()?;
    let n: usize = asked.trim().parse().ok()?;
    let most = lucent_core::SolveOptions::MAX_THREADS;
    if n <= most {
        return None;
    }
    rayon::ThreadPoolBuilder::new()
        .num_threads(most)
        .build_global()
        .ok()
        .map(|()| format!("RAYON_NUM_THREADS={n} capped at {most} threads"))
}

/// Whether `e` says a GPU backend found no adapter and the environment lets harnesses
/// skip it (with the reason) instead of failing: anywhere but CI (`CI=true`), where a
/// missing adapter must fail the run.
pub fn device_missing(e: &lucent_core::SolveError) -> bool {
    let ci = std::env::var("CI").is_ok_and(|v| v == "true" || v == "1");
    matches!(
        e,
        lucent_core::SolveError::Device {
            unavailable: true,
            ..
        }
    ) && !ci
}

/// Everything that can go wrong between a scene file and an image, with a message meant
/// for the person at the command line.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be read or written.
    #[error("{path}: {reason}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// A scene file that is not valid TOML or not a valid scene.
    #[error("{path}: bad scene: {reason}")]
    Scene {
        /// The scene file.
        path: PathBuf,
        /// The parser's message (with line and column).
        reason: String,
    },
    /// A scene value that makes no sense.
    #[error("invalid scene: {0}")]
    Invalid(String),
    /// An output the job could not write (checked before any solving).
    #[error("output {path}: {reason}")]
    Output {
        /// The output file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// A scene too large for the memory budget in memory (it is valid: a larger budget,
    /// or solving out of core where the scene and solver allow, would do).
    #[error("over the memory budget: {0}")]
    OverBudget(String),
    /// A command-line argument that makes no sense.
    #[error("{0}")]
    Usage(String),
    /// From reading or building grids.
    #[error(transparent)]
    Grid(#[from] lucent_grid::GridError),
    /// From assembling the problem.
    #[error(transparent)]
    Problem(#[from] lucent_core::ProblemError),
    /// From the solver.
    #[error(transparent)]
    Solve(#[from] lucent_core::SolveError),
    /// From the renderer.
    #[error(transparent)]
    Render(#[from] lucent_render::RenderError),
    /// From the optics.
    #[error(transparent)]
    Optics(#[from] lucent_optics::OpticsError),
    /// A budget under which a solver cannot solve the scene out of core, found before
    /// anything was built.
    #[error(
        "`{solver}` cannot solve this scene out of core within the memory budget of {budget} bytes{}",
        match smallest {
            Some(b) => format!(": the smallest budget that would do is {} MiB (--memory-budget {}MiB)", b.div_ceil(1 << 20), b.div_ceil(1 << 20)),
            None => ": the medium's bookkeeping alone needs more (coarser bricks or a smaller grid)".into(),
        }
    )]
    PagedBudget {
        /// The solver.
        solver: String,
        /// The budget asked for.
        budget: u64,
        /// The smallest budget that would do, where the search found one (it stops where
        /// the medium's bookkeeping alone would pass the caller's budget or 1 GiB).
        smallest: Option<u64>,
    },
    /// A solve a job needed stopped without converging, so its result cannot be used.
    #[error("{what}: the solve {reason}")]
    Unconverged {
        /// Which solve.
        what: String,
        /// Why it stopped, in words.
        reason: String,
        /// Whether it diverged (rather than stopping at a limit).
        diverged: bool,
    },
}

/// A byte count from the command line: a number of bytes (`4096`, `1e9`) or a number with
/// a unit, binary (`KiB`, `MiB`, `GiB`, `TiB`) or decimal (`kB`/`KB`, `MB`, `GB`, `TB`),
/// case-insensitive, spaces allowed before the unit (`512MiB`, `1.5 GB`).
pub fn parse_bytes(text: &str) -> Result<u64, String> {
    let t = text.trim();
    let split = t
        .find(|c: char| c.is_ascii_alphabetic() && c != 'e' && c != 'E')
        .unwrap_or(t.len());
    let (number, unit) = t.split_at(split);
    let value: f64 = number
        .trim()
        .parse()
        .map_err(|_| format!("`{text}` is not a size (examples: 512MiB, 2GiB, 1e9)"))?;
    let scale = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "kib" => 1024.0,
        "mib" => 1024f64.powi(2),
        "gib" => 1024f64.powi(3),
        "tib" => 1024f64.powi(4),
        "kb" => 1e3,
        "mb" => 1e6,
        "gb" => 1e9,
        "tb" => 1e12,
        other => {
            return Err(format!(
                "`{text}`: unknown unit `{other}` (B, KiB, MiB, GiB, TiB, kB, MB, GB, TB)"
            ));
        }
    };
    let bytes = value * scale;
    if !(1.0..1.8e19).contains(&bytes) {
        return Err(format!("`{text}` must be at least one byte"));
    }
    Ok(bytes.round() as u64)
}

#[cfg(test)]
mod tests {
    use super::parse_bytes;

    #[test]
    fn sizes_parse_with_binary_and_decimal_units() {
        assert_eq!(parse_bytes("512MiB"), Ok(512 << 20));
        assert_eq!(parse_bytes("2 GiB"), Ok(2 << 30));
        assert_eq!(parse_bytes("1.5GB"), Ok(1_500_000_000));
        assert_eq!(parse_bytes("1e9"), Ok(1_000_000_000));
        assert_eq!(parse_bytes("4096"), Ok(4096));
        assert_eq!(parse_bytes("64kib"), Ok(65_536));
        for bad in ["", "MiB", "-1GiB", "0", "12 parsecs", "NaN", "1e30"] {
            assert!(parse_bytes(bad).is_err(), "{bad}");
        }
    }
}
