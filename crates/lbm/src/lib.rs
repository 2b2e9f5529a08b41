//! # lucent-lbm: Lattice-Boltzmann lighting (Geist et al. 2004; Bernabei, thesis ch. 4)
//!
//! Multiple scattering by a lattice of photon populations: per cell, f_i for each link e_i
//! of a velocity set (D3Q7: rest and the six axis links; D3Q19: and the twelve face
//! diagonals) collide and stream one cell per step,
//!
//! f_i(x + e_i, t + 1) = f_i*(x, t),   f* = C(f) − absorption + sources,
//!
//! and the fluence is ρ = Σ_i f_i. In the diffusion limit the steady state solves
//!
//! −∇·(D∇φ) + σ_a φ = Q₀ − 3∇·(D Q₁),   D = h c_s² (1/ω⁻ − ½)
//!
//! (lattice units: one cell h, one step; c_s² = Σ w_i e_ix² is ¼ for D3Q7, ⅓ for D3Q19;
//! ω⁻ the relaxation rate of the flux). That is Bernabei's and Geist's scheme seen from the
//! diffusion side, and what this crate solves; [`march`] says how:
//!
//! - **Collision** ([`Collision`]): two relaxation times (the default) — the flux relaxes
//!   at ω⁻, chosen so that D is the medium's 1/(3σ_t′) with σ_t′ = σ_a + (1 − g)σ_s (the
//!   phase function enters as the persistence of the flux, E[ω′ | ω] = g ω per
//!   scattering), the even moments at ω⁺ with Λ = (1/ω⁺ − ½)(1/ω⁻ − ½) = ¼, which puts wall
//!   conditions exactly at the half-links; BGK (one rate, ω⁺ = ω⁻) as an option; and
//!   Geist's physical probabilities per step (κ_t = 1 − e^{−σ_t h}, κ_s = albedo κ_t)
//!   whose lattice diffusion coefficient is h(2/κ_t − 1)/(6(1 + κ_a)) for D3Q7 (Bernabei's
//!   eq. 4.5) and h(2/κ_t − 1)/(4(1 + κ_a)) for D3Q19 (Geist, with the sign of the printed
//!   diagonal corrected): first order in h against 1/(3σ_t′).
//! - **Absorption** ([`Absorption`]): true absorption by default — κ_a ρ = σ_a h ρ leaves
//!   each cell per step; or the thesis's collision matrices as printed, whose absorbed
//!   fraction moves to the rest population and is re-emitted, conserving energy: κ_a there
//!   only slows diffusion (the (1 + κ_a) factor), it removes nothing (tested).
//! - **Streaming** ([`Streaming`]): in place by Bailey et al.'s AA pattern (one array of
//!   populations: even steps collide into the opposite slots, odd steps read from and
//!   write to the neighbours'), or between two arrays; the same bits either way (tested).
//!   Between two arrays the volume can also be advanced block by block ([`Blocks`],
//!   Bernabei's blockwise scheduling): the same steady state, the energy books balanced at
//!   convergence only.
//! - **Walls**: at the box's faces the fluence at the half-link ρ_w meets the condition
//!   (Robin ρ_w = 2A J_n — a vacuum is A of the Milne problem —, Dirichlet, Neumann) and
//!   the incoming populations are f_in = −f*_out + 2 w ρ_w (anti-bounce-back).
//! - **Sources**: lights outside the medium enter as first-collision sources,
//!   s_i = w_i (Q₀ + 3 e_i·Q₁) h from `lucent_core::Uncollided`'s per-cell Q₀ and Q₁ (the
//!   shared first-collision projection, whose flux 3 D Q₁ the lattice reproduces); point
//!   lights inside put 4πI into their cell.
//!
//! The device twin `gpu-lbm` (`lucent-gpu-solvers`) marches the same [`LatticeProblem`]
//! by the pull pattern on wgpu and stops by the same [`Ledger`].
//!
//! Stability: ω± ∈ (0, 2) for every D > 0 by construction; the sink needs σ_a h < 1
//! ([`LbmError::Unstable`] otherwise: refine the grid or use `diffusion-mg`). Convergence to
//! the steady state is that of a Jacobi iteration: O((N/ℓ)²) steps for N cells across and
//! a diffusion length of ℓ cells.

mod error;
mod lattice;
mod march;
mod params;
mod solver;

pub use error::LbmError;
pub use lattice::{Links, Velocities};
pub use march::{
    Absorption, Blocks, Bookkeeping, Collision, LatticeProblem, Ledger, MarchSettings, Marched,
    Streaming, Wall, check, held_and_pending, march,
};
pub use params::LbmParams;
pub use solver::{LbmSolver, wall};
