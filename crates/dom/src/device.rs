//! The transport step on another device: what a GPU backend implements so that
//! [`SourceIteration`](crate::SourceIteration) runs its iteration, its acceleration and
//! its stopping rule on the host, unchanged, around the device's steps.
//!
//! One transport step is the source fill S_n = Q_n + σ_s J_n (Q omitted in a homogeneous
//! step), the eight octant sweeps with the boundary's inflow and the in-scattered radiance
//! J′ = Ψ̄ B (the N × M scattering matrix). The step hands the device J, Q and σ_s, so the
//! device may fill S wherever it moves data best (`gpu-dom` fills it on the host while
//! splitting it by octant for the upload); the device keeps Ψ̄ and everything that does
//! not change between steps, and J′ with the scalar flux and the boundary's outgoing
//! currents come back. Storage directions must be the propagation directions (no
//! interpolation) and the work must be in memory: a backend is refused otherwise
//! ([`DomError::Invalid`]).

use crate::Closure;
use crate::error::DomError;
use crate::sweep::Layout;

/// Everything that stays fixed during one channel's iteration, in the iteration's block
/// order (per-cell arrays indexed by [`Layout`]'s order, per-cell-and-direction arrays
/// cell-major).
#[derive(Debug, Clone, Copy)]
pub struct TransportSetup<'a> {
    /// The cells' block order.
    pub layout: &'a Layout,
    /// Cell widths (length).
    pub spacing: [f64; 3],
    /// Propagation (= storage) directions, ordered by octant.
    pub directions: &'a [[f64; 3]],
    /// Their quadrature weights (sum 4π).
    pub weights: &'a [f64],
    /// Per octant (bit a set: ω_a < 0), its first direction and count (the octant's
    /// directions are contiguous; count 0 for an empty octant).
    pub octants: [(usize, usize); 8],
    /// σ_t per cell (1/length).
    pub sigma_t: &'a [f32],
    /// The scattering matrix B, N × M row-major: J_m = Σ_n Ψ̄_n B_nm.
    pub scattering: &'a [f64],
    /// The spatial closure.
    pub closure: Closure,
}

/// One transport step's inputs.
#[derive(Debug, Clone, Copy)]
pub struct TransportStep<'a> {
    /// The in-scattered radiance to sweep from, cells × M in block order.
    pub inscattered: &'a [f32],
    /// σ_s per cell (1/length).
    pub sigma_s: &'a [f32],
    /// The fixed source per cell and direction (W/length³/sr), cells × M; `None` in a
    /// Krylov iteration's homogeneous step (whose inflow then holds only reflected light).
    pub fixed: Option<&'a [f32]>,
    /// Use the closure's linear form (diamond without its fix-up, the exponential
    /// closure without its clamp).
    pub linear: bool,
    /// Incoming radiance per boundary face cell on faces (−x, +x, −y, +y, −z, +z), the
    /// same for every direction entering there; face cells are numbered as in
    /// [`TransportOutput::outflow`].
    pub inflow: &'a [Vec<f64>; 6],
}

/// What a transport step produces besides the in-scattered radiance (the iteration adds
/// the boundary's powers from these and the inflow).
#[derive(Debug, Clone, PartialEq)]
pub struct TransportOutput {
    /// Scalar flux Σ w ψ̄, block order.
    pub fluence: Vec<f64>,
    /// Outgoing partial current Σ w |ω·n| ψ per boundary face cell, per face (−x, +x,
    /// −y, +y, −z, +z); the face cell of face axis a is numbered u + n_u v with (u, v)
    /// the cell's indices along the axes a + 1 and a + 2 (mod 3).
    pub outflow: [Vec<f64>; 6],
    /// Seconds the device spent in the step's kernels (from submitting them to their
    /// completion, transfers excluded); 0 where the device does not say.
    pub kernel_seconds: f64,
    /// Of `kernel_seconds`, the scattering product's (J′ and the scalar flux); the rest is
    /// the sweeps'.
    pub scatter_seconds: f64,
}

/// A transport step on a device.
pub trait DeviceTransport: Send {
    /// Takes the iteration's fixed data (uploads it); called once before any step.
    fn prepare(&mut self, setup: &TransportSetup<'_>) -> Result<(), DomError>;

    /// One transport step from `step`, the new in-scattered radiance into `inscattered`
    /// (cells × M, block order).
    fn transport(
        &mut self,
        step: &TransportStep<'_>,
        inscattered: &mut [f32],
    ) -> Result<TransportOutput, DomError>;
}

/// Makes a device transport for each channel a solver iterates: what a registry entry
/// built on `dom` (`gpu-dom`) hands [`DomSolver::on_device`](crate::DomSolver::on_device).
pub type DeviceFactory = dyn Fn() -> Result<Box<dyn DeviceTransport>, DomError> + Send + Sync;
