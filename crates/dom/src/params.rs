//! The registry parameters of `dom`, read from a scene's `[solver.params]` by serde
//! (unknown keys and ill-typed values are errors naming the key) and printed with their
//! defaults by `lucent solvers`.

use lucent_core::{SolveError, SolverParams};
use serde::{Deserialize, Serialize};

use crate::closure::Closure;
use crate::solve::{Acceleration, Outer};

/// The family of the propagation directions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Family {
    /// Level-symmetric S_N (`order` = N).
    #[default]
    LevelSymmetric,
    /// The nested octahedral sets (`order` = refinement level).
    Octahedral,
}

/// A truncation of a forward-peaked phase function ([`crate::DeltaM`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Truncation {
    /// The phase function as it is.
    #[default]
    None,
    /// Delta-M: f = χ_N of the level-symmetric S_N set (`order` = N).
    DeltaM,
    /// Delta-Eddington: f = χ₂ = g² for Henyey–Greenstein, with any direction set.
    DeltaEddington,
}

/// The parameters of `dom`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DomParams {
    /// S_N order, or the octahedral level; `None`: 8, or level 2.
    pub order: Option<usize>,
    /// The propagation set's family.
    pub family: Family,
    /// Store sources on the octahedral set of this level instead of the propagation set.
    pub storage_level: Option<usize>,
    /// Spatial closure of the sweeps.
    pub closure: Closure,
    /// The outer iteration: GMRES or source iteration.
    pub outer: Outer,
    /// GMRES restart length.
    pub restart: usize,
    /// Acceleration of the source iteration.
    pub acceleration: Acceleration,
    /// Sweeps of TSA's S2 problem per correction.
    pub tsa_sweeps: usize,
    /// Anderson mixing depth (0: off).
    pub anderson: usize,
    /// Wavefront block edge, in cells.
    pub block: usize,
    /// Keep the sweeps' per-direction work out of core in a pool of this many MiB (a
    /// temporary file holds the rest); `None`: in memory, or paged by itself when the
    /// memory budget is too small for it in memory.
    pub work_pool_mib: Option<u64>,
    /// Truncation of a forward-peaked phase function.
    pub truncation: Truncation,
}

impl Default for DomParams {
    fn default() -> Self {
        Self {
            order: None,
            family: Family::LevelSymmetric,
            storage_level: None,
            closure: Closure::Diamond,
            outer: Outer::SourceIteration,
            restart: 12,
            acceleration: Acceleration::Dsa,
            tsa_sweeps: 2,
            anderson: 2,
            block: 16,
            work_pool_mib: None,
            truncation: Truncation::None,
        }
    }
}

impl SolverParams for DomParams {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[
        (
            "order",
            "level-symmetric S_N order (even, 2 to 16; none: 8) or, with family = \"octahedral\", the refinement level (none: 2)",
        ),
        (
            "family",
            "propagation directions: level-symmetric or octahedral",
        ),
        (
            "storage_level",
            "store sources on the octahedral set of this level instead of the propagation set (none: the propagation set)",
        ),
        (
            "closure",
            "spatial closure: diamond (second order), step or exponential (positive)",
        ),
        (
            "outer",
            "outer iteration: gmres (Krylov, DSA-preconditioned) or source-iteration",
        ),
        (
            "restart",
            "GMRES restart length, 1 to 64 (each Krylov vector: 4 bytes per cell and storage direction)",
        ),
        (
            "acceleration",
            "acceleration of either outer iteration: dsa (diffusion synthetic: the isotropic error), tsa (S2 transport synthetic: the isotropic and first moments' error, fewer sweeps where the phase function is forward-peaked) or none",
        ),
        (
            "tsa_sweeps",
            "sweeps of TSA's S2 problem (8 directions, each with a DSA correction) per correction, 1 to 8",
        ),
        ("anderson", "Anderson mixing depth, 0 to 16 (0: off)"),
        ("block", "wavefront block edge in cells, 1 to 256"),
        (
            "work_pool_mib",
            "keep the sweeps' per-direction work (f64, cells × directions) in a page pool of this many MiB over a temporary file (none: in memory, or paged when the memory budget asks for it)",
        ),
        (
            "truncation",
            "forward peak of the phase function: none, delta-m (the fraction χ_N moved into the uncollided light; level-symmetric sets) or delta-eddington (χ₂)",
        ),
    ];

    fn validate(&self) -> Result<(), SolveError> {
        let bad = |name: &str, reason: &str| SolveError::InvalidParameter {
            name: name.into(),
            reason: reason.into(),
        };
        if self.anderson > 16 {
            return Err(bad("anderson", "at most 16"));
        }
        if !(1..=8).contains(&self.tsa_sweeps) {
            return Err(bad("tsa_sweeps", "1 to 8"));
        }
        if !(1..=64).contains(&self.restart) {
            return Err(bad("restart", "1 to 64"));
        }
        if !(1..=256).contains(&self.block) {
            return Err(bad("block", "1 to 256 cells"));
        }
        Ok(())
    }
}
