//! The registry parameters of `lbm`.

use lucent_core::{SolveError, SolverParams};
use serde::{Deserialize, Serialize};

use crate::lattice::Velocities;
use crate::march::{Absorption, Collision, Streaming};

/// The parameters of `lbm`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
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
    ];

    fn validate(&self) -> Result<(), SolveError> {
        Ok(())
    }
}
