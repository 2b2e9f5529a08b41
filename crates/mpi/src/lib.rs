//! # lucent-mpi: domain decomposition over ranks
//!
//! Splits a solver's grid into z-slabs, one per rank, with one-cell halos, and runs the
//! iteration on them with the same bits as on one rank: the explicit steady schemes
//! (FTCS diffusion and Jacobi on `lucent-diffusion`'s assembled system,
//! `lucent_explicit::steady`) for now.
//!
//! The distributed multigrid is `lucent_diffusion::Multigrid::solve_on_ranks`, on the same
//! communicators (the trait lives in `lucent_core::ranks`, re-exported here).
//!
//! **Ranks.** [`Communicator`] is the two operations a slab decomposition needs: halo
//! exchange with the neighbours below and above, started before and received after the
//! interior rows (non-blocking sends overlapped with work), and an all-gather of small
//! vectors. [`Alone`] is one rank; [`Threads`] is ranks as threads of one process
//! (channels), which the default tests use; `Mpi` (feature `mpi`, rsmpi on the system's
//! MPI: Debian's `openmpi-bin libopenmpi-dev`, and `libclang-dev` for its bindgen) runs
//! under `mpirun`. Without the feature nothing of MPI is built.
//!
//! **Reproducibility.** Norms are Σ per z-layer, left to right, then the layer sums in z
//! order (`lucent_explicit::steady::Layers`), on one rank and on many: a layer never
//! straddles ranks, so the gathered layer sums add to the serial bits whatever the rank
//! count. Rows keep their column order under the local renumbering, so each residual is
//! the serial one; elementwise updates are the same. The result is bit for bit the
//! serial iteration's on any number of ranks (`tests/decomposition.rs`).
//!
//! **Stopping.** Tolerances, the iteration limit and divergence follow from the shared
//! residual, identically on every rank; the time budget and cancellation are per rank and
//! travel with each gather, so all ranks stop on the same sweep.
//!
//! **Not yet.** Every rank still assembles the whole system (only its rows are iterated),
//! so memory does not yet scale with ranks; per-slab assembly and positioned reads of the
//! volume come next, then P1, Zhang & Ma's absorption march as a pipelined wavefront and
//! the distributed multigrid.
//!
//! **Cost model per sweep and rank** (slab of n_x·n_y·n_z/P cells): two halo messages of
//! one layer of unknowns each (≤ 8 n_x n_y bytes), overlapped with the interior rows, and
//! one all-gather of 2 + (layers per rank) doubles, whose latency grows as log P.

mod error;
#[cfg(feature = "mpi")]
mod mpi_comm;
pub mod steady;

pub use error::DecompositionError;
pub use lucent_core::ranks::{Alone, Communicator, Threads};
#[cfg(feature = "mpi")]
pub use mpi_comm::Mpi;
