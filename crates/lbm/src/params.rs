//! The registry parameters of `lbm`.

use lucent_core::{SolveError, SolverParams};
use serde::{Deserialize, Serialize};

use crate::lattice::Velocities;
use crate::march::{Absorption, Collision, Streaming};

/// The parameters of `lbm`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LbmParams {
    /// The velocity set.
    pub lattice: Velocities,
    /// The collision operator.
    pub collision: Collision,
    /// What absorption does.
    pub absorption: Absorption,
    /// The streaming pattern.
    pub streaming: Streaming,
    /// Blockwise scheduling: z-slabs per block (0: every cell steps together).
    pub block_slabs: usize,
    /// Blockwise scheduling: steps a block takes per visit.
    pub block_steps: usize,
}

impl Default for LbmParams {
    fn default() -> Self {
        Self {
            lattice: Velocities::default(),
            collision: Collision::default(),
            absorption: Absorption::default(),
            streaming: Streaming::default(),
            block_slabs: 0,
            block_steps: 1,
        }
    }
}

impl SolverParams for LbmParams {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[
        (
            "lattice",
            "velocity set: d3q7 (rest and axis links) or d3q19 (and face diagonals)",
        ),
        (
            "collision",
            "trt (two relaxation times, D matched, walls at the half-links), bgk (one rate) or geist (the per-step probabilities of Geist et al., first order in h)",
        ),
        (
            "absorption",
            "true (light absorbed leaves) or thesis (absorbed light waits in the rest population and is re-emitted, as the thesis's matrices have it)",
        ),
        (
            "streaming",
            "in-place (AA pattern, one array of populations) or two-arrays",
        ),
        (
            "block_slabs",
            "blockwise scheduling (Bernabei): z-slabs per block, advanced in turn (0: all cells step together; needs streaming = two-arrays)",
        ),
        (
            "block_steps",
            "blockwise scheduling: steps per visit of a block (≥ 1)",
        ),
    ];

    fn validate(&self) -> Result<(), SolveError> {
        let bad = |name: &str, reason: &str| SolveError::InvalidParameter {
            name: name.into(),
            reason: reason.into(),
        };
        if self.block_steps == 0 {
            return Err(bad("block_steps", "at least one step per visit"));
        }
        if self.block_slabs > 0 && self.streaming != Streaming::TwoArrays {
            return Err(bad(
                "block_slabs",
                "blockwise scheduling needs streaming = \"two-arrays\"",
            ));
        }
        Ok(())
    }
}
