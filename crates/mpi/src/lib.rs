//! # lucent-mpi: lucent's solvers on MPI ranks
//!
//! The solvers that split over ranks take any `lucent_core::ranks::Communicator`:
//! `lucent_diffusion::Multigrid::solve_on_layout` (the distributed multigrid, z-slabs or a
//! Cartesian grid of boxes),
//! `lucent_explicit::ranks::iterate_on` (FTCS and Jacobi to steady state, z-slabs or a
//! Cartesian grid of boxes),
//! `lucent_explicit::ranks::march_p1_on` (P1 by FTCS, z-slabs or boxes),
//! `lucent_explicit::wavefront`
//! (Zhang & Ma's absorption march: over z-slabs a pipelined wavefront or planes in lock
//! step, over boxes the KBA sweep), and
//! through them the registry's `diffusion-mg`, `ftcs-diffusion`, `jacobi-diffusion`,
//! `ftcs-p1` and `convection-diffusion` with `SolveOptions::ranks`. This crate adds the transport that runs them across processes:
//! `Mpi` (feature `mpi`: rsmpi on the system's MPI, Debian's `openmpi-bin
//! libopenmpi-dev`, and `libclang-dev` for its bindgen), `MPI_COMM_WORLD` under `mpirun`.
//! Without the feature nothing of MPI is built; [`Alone`] and [`Threads`] (in-process
//! ranks) are re-exported from `lucent-core`.
//!
//! **Reproducibility.** Every norm (FTCS, Jacobi, P1 and the multigrid) sums runs of eight
//! cells along x, each left to right, and adds the run sums exactly
//! (`lucent_core::exact::ExactSum`, merged across ranks in any order), so the result is
//! the serial solve's bits on every rank count, over z-slabs and over boxes, which split
//! layers (`docs/ranks.md`).
//!
//! **Stopping.** Tolerances, the iteration limit and divergence follow from the shared
//! residual, identically on every rank; the time budget and cancellation are per rank and
//! travel with each gather, so all ranks stop on the same sweep or cycle.
//!
//! **Memory.** Through the registry every rank still builds the whole problem (only its
//! slab is iterated), so memory does not yet scale with ranks there. Two solvers have a
//! slab-local form: the absorption march (`lucent_explicit::wavefront::propagate_slab`
//! and `propagate_box`: σ_a and ρ of the rank's layers or box and a two-cell halo; the
//! `slab_march` example, `--boxes` for a grid of boxes) and FTCS and
//! Jacobi diffusion in a medium filling the box (`lucent_explicit::ranks::iterate_block`
//! on the rows `lucent_diffusion::SlabSystem::block` builds from the rank's layers or box
//! and D's cells beyond its faces; the `slab_diffusion` example, `--boxes` for a grid of
//! boxes), and the multigrid in such a medium
//! (`lucent_diffusion::SlabSystem::solve_multigrid_on_layout`: each rank builds its part of
//! every level from its box; `slab_diffusion --method mg`), and P1 from an emitting
//! volume (`lucent_explicit::ranks::march_p1_box`; the `slab_p1` example). The examples read the rank's layers or box of a volume file by positioned reads
//! and write its cells of the result into one `.npy` (`lucent_grid::io::layers`), so no
//! rank holds the whole volume.
//!
//! **Cost model per sweep and rank** (slab of n_x·n_y·n_z/P cells): two halo messages of
//! one layer each (≤ 8 n_x n_y bytes), overlapped with the interior rows, and one
//! all-reduce of the norm (log₂P messages of 71 words, 148 for P1); boxes send six face
//! messages
//! instead, which shrink with the box (`docs/ranks.md` compares the two at 1024 ranks).
//! `BENCHMARKS.md` ("Ranks") models 64 and 1024 ranks, multigrid's coarse levels included
//! (agglomerated onto fewer ranks as they shrink, moved by `Communicator::exchange_with`'s
//! point-to-point messages).
//!
//! **Failure.** A rank that panics (after `World::initialise`) aborts every rank with
//! `MPI_Abort`; `World::abort` does the same for an error one rank meets alone (the
//! `lucent` binary calls it for any error under `mpirun`). Returning normally would
//! finalise MPI, which waits for the other ranks, which may be waiting in a halo exchange
//! or reduction for the one that failed: a hang instead of an error.

#[cfg(feature = "mpi")]
mod mpi_comm;

pub use lucent_core::ranks::{Alone, Communicator, Threads};
#[cfg(feature = "mpi")]
pub use mpi_comm::{Mpi, MpiError, World};
