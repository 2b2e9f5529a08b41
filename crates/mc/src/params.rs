//! The registry parameters of `mc`, read from a scene's `[solver.params]` by serde
//! (unknown keys and ill-typed values are errors naming the key) and printed with their
//! defaults by `lucent solvers`.

use lucent_core::{SolveError, SolverParams};
use serde::{Deserialize, Serialize};

use crate::transport::McConfig;

/// The parameters of `mc`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct McParams {
    /// Particles per batch and light.
    pub particles: u64,
    /// Independent batches (≥ 2: their spread is the standard error).
    pub batches: usize,
    /// Seed of the counter-based random streams.
    pub seed: u64,
    /// Scattering events after which a path ends.
    pub max_depth: u32,
    /// Cells per majorant block edge (on a paged medium the bricks are the blocks).
    pub majorant_cells: usize,
    /// One majorant for the whole grid instead of per block.
    pub global_majorant: bool,
    /// Paths per pixel for camera images (≥ 2).
    pub spp: usize,
}

impl Default for McParams {
    fn default() -> Self {
        let d = McConfig::default();
        Self {
            particles: d.particles,
            batches: d.batches,
            seed: d.seed,
            max_depth: d.max_depth,
            majorant_cells: d.majorant_cells,
            global_majorant: d.global_majorant,
            spp: 64,
        }
    }
}

impl SolverParams for McParams {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[
        ("particles", "particles per batch and light"),
        (
            "batches",
            "independent batches, at least 2 (their spread gives the standard error)",
        ),
        ("seed", "seed of the counter-based random streams"),
        (
            "max_depth",
            "scattering events after which a path ends, at least 1",
        ),
        (
            "majorant_cells",
            "cells per edge of a majorant block (delta tracking's bound on σ_t; out of core the bricks are the blocks)",
        ),
        (
            "global_majorant",
            "true: one majorant for the whole grid instead of one per block",
        ),
        ("spp", "paths per pixel for camera images, 2 to 2^20"),
    ];

    fn validate(&self) -> Result<(), SolveError> {
        let bad = |name: &str, reason: &str| SolveError::InvalidParameter {
            name: name.into(),
            reason: reason.into(),
        };
        if self.batches < 2 {
            return Err(bad("batches", "at least 2"));
        }
        if !(2..=1 << 20).contains(&self.spp) {
            return Err(bad("spp", "2 to 2^20 paths per pixel"));
        }
        if self.max_depth == 0 {
            // A path that may not scatter once carries no scattered light: that is `direct`.
            return Err(bad(
                "max_depth",
                "at least 1 (scattering events; the uncollided light alone is `direct`)",
            ));
        }
        if self.particles == 0 || self.majorant_cells == 0 {
            return Err(bad("particles", "particles and majorant_cells at least 1"));
        }
        Ok(())
    }
}
