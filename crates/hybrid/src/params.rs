//! The registry parameters of `hybrid`, read from a scene's `[solver.params]` by serde
//! (unknown keys and ill-typed values are errors naming the key) and printed with their
//! defaults by `lucent solvers`.

use lucent_core::{SolveError, SolverParams};
use lucent_dom::Closure;
use serde::{Deserialize, Serialize};

/// The parameters of `hybrid`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HybridParams {
    /// Level-symmetric S_N order of the sweeps.
    pub order: usize,
    /// Spatial closure of the sweeps.
    pub closure: Closure,
    /// The most scattering orders carried by transport sweeps.
    pub orders: usize,
    /// Wavefront block edge of the sweeps, in cells.
    pub block: usize,
}

impl Default for HybridParams {
    fn default() -> Self {
        Self {
            order: 4,
            closure: Closure::Diamond,
            orders: 4,
            block: 16,
        }
    }
}

/// The most scattering orders a solve sweeps: beyond, discrete ordinates with DSA
/// (`dom`) converges in fewer sweeps.
pub(crate) const MAX_ORDERS: usize = 64;

impl SolverParams for HybridParams {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[
        (
            "order",
            "level-symmetric S_N order of the sweeps (even, 2 to 16): N(N + 2) directions",
        ),
        (
            "closure",
            "spatial closure of the sweeps: diamond (second order), step or exponential (positive)",
        ),
        (
            "orders",
            "the most scattering orders carried by transport sweeps, 1 to 64 (1: single scattering); after the last, or once an order's power is below the solve's tolerance of the first's, multigrid diffusion takes what is left",
        ),
        (
            "block",
            "wavefront block edge of the sweeps in cells, 1 to 256",
        ),
    ];

    fn validate(&self) -> Result<(), SolveError> {
        let bad = |name: &str, reason: &str| SolveError::InvalidParameter {
            name: name.into(),
            reason: reason.into(),
        };
        if !(1..=MAX_ORDERS).contains(&self.orders) {
            return Err(bad("orders", "1 to 64"));
        }
        if !(1..=256).contains(&self.block) {
            return Err(bad("block", "1 to 256 cells"));
        }
        if !self.order.is_multiple_of(2) || !(2..=16).contains(&self.order) {
            return Err(bad("order", "even, 2 to 16"));
        }
        Ok(())
    }
}
