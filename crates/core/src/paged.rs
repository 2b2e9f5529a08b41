//! Out-of-core problems (Bernabei, chapter 5): a medium whose fields live in paged storage
//! (`lucent-paging`), solved through the same registry entries as in-memory problems.
//!
//! A [`PagedProblem`] holds σ_t and the albedo as [`PagedGrid`]s sharing one [`Pager`]: a
//! fixed pool under a byte budget, the rest of the bricks in a backing file, constant bricks
//! (empty space) as one number each. A solver that can run out of core implements
//! [`Solver::solve_paged`](crate::Solver::solve_paged) and returns a [`PagedSolution`]
//! whose grids are paged too; the others refuse with [`SolveError::Unsupported`]. Solvers
//! compute each cell with the same code on both storages (the field is read through
//! `lucent_grid::DualCorners`, slabs and layer windows), so a paged solve gives the in-memory
//! solve's bits.
//!
//! Which storage a job uses is the caller's choice or the budget's: [`Storage::for_budget`]
//! picks in-memory storage when the dense fields fit the budget and paging otherwise.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use glam::DVec3;
use lucent_grid::{BrickLayout, GridGeometry};
use lucent_optics::Phase;
use lucent_paging::{PagedGrid, Pager, PagerStats, PagingError};

use crate::error::{ProblemError, SolveError};
use crate::problem::{Boundary, Light};
use crate::solver::SolveReport;

/// Where a job keeps its fields.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Storage {
    /// Dense grids in memory ([`crate::Problem`]).
    InMemory,
    /// Paged bricks ([`PagedProblem`]).
    Paged,
}

impl Storage {
    /// In memory when `dense_bytes` (the dense problem and the solver's working data) fit
    /// `budget`, else paged.
    pub fn for_budget(dense_bytes: u64, budget: u64) -> Self {
        if dense_bytes <= budget {
            Self::InMemory
        } else {
            Self::Paged
        }
    }
}

/// σ_t and the albedo of a paged problem, per channel (one entry serves every channel).
#[derive(Debug)]
pub struct PagedMedium {
    /// Extinction (1/length), per extinction channel.
    pub sigma_t: Vec<PagedGrid>,
    /// Single-scattering albedo, per channel.
    pub albedo: Vec<PagedGrid>,
    /// The phase function.
    pub phase: Phase,
}

/// A paged medium's coefficients cell by cell, evaluated at cell centres (world): what
/// [`PagedProblem::from_fn`] bricks without ever making a dense grid.
pub struct CellMedium<'a> {
    /// σ_t (1/length) per extinction channel.
    pub sigma_t: Vec<&'a (dyn Fn(DVec3) -> f32 + Sync)>,
    /// Albedo per channel.
    pub albedo: Vec<&'a (dyn Fn(DVec3) -> f32 + Sync)>,
    /// The phase function.
    pub phase: Phase,
}

/// A problem whose medium is paged: the out-of-core twin of [`crate::Problem`].
#[derive(Debug)]
pub struct PagedProblem {
    geometry: GridGeometry,
    medium: PagedMedium,
    lights: Vec<Light>,
    boundary: Boundary,
    pager: Arc<Pager>,
}

/// A paging error as a solve error of `solver`.
pub fn paging_error(solver: &str, e: PagingError) -> SolveError {
    match e {
        PagingError::BudgetTooSmall { budget, needed, .. } => SolveError::OverBudget {
            solver: solver.into(),
            needed,
            budget,
        },
        PagingError::Io { .. } | PagingError::Create { .. } => SolveError::Storage {
            solver: solver.into(),
            reason: e.to_string(),
        },
        other => SolveError::InvalidParameter {
            name: "paged storage".into(),
            reason: format!("{solver}: {other}"),
        },
    }
}

impl PagedProblem {
    /// A problem on `geometry` whose medium is given cell by cell ([`CellMedium`]: each
    /// function evaluated once per cell, brick by brick, never as a dense grid), stored in
    /// bricks of `brick`³ cells through `pager` (which pages bricks of (brick + 2)³ values).
    /// Values are checked as [`crate::Problem::new`] checks them: σ_t finite and ≥ 0,
    /// albedo in [0, 1]; point-like lights and the sky only (emission needs a grid of its
    /// own: not yet paged).
    pub fn from_fn(
        pager: Arc<Pager>,
        geometry: GridGeometry,
        brick: usize,
        medium: CellMedium<'_>,
        lights: Vec<Light>,
        boundary: Boundary,
    ) -> Result<Self, ProblemError> {
        let CellMedium {
            sigma_t,
            albedo,
            phase,
        } = medium;
        if sigma_t.is_empty() || albedo.is_empty() {
            return Err(ProblemError(
                "a paged medium needs σ_t and albedo for at least one channel".into(),
            ));
        }
        if lights.iter().any(|l| matches!(l, Light::Emission { .. })) {
            return Err(ProblemError(
                "emission lights are not supported in a paged problem yet".into(),
            ));
        }
        let field = |f: &(dyn Fn(DVec3) -> f32 + Sync),
                     what: &str,
                     ok: fn(f32) -> bool|
         -> Result<PagedGrid, ProblemError> {
            let bad = AtomicBool::new(false);
            let grid = PagedGrid::from_fn(pager.clone(), geometry, brick, |c| {
                let v = f(geometry.cell_centre(c[0], c[1], c[2]));
                if !ok(v) {
                    bad.store(true, Ordering::Relaxed);
                }
                v
            })
            .map_err(|e| ProblemError(format!("{what}: {e}")))?;
            if bad.load(Ordering::Relaxed) {
                return Err(ProblemError(format!(
                    "{what} has a value that is not finite or out of range"
                )));
            }
            Ok(grid)
        };
        let medium = PagedMedium {
            sigma_t: sigma_t
                .iter()
                .map(|f| field(*f, "σ_t", |v| v.is_finite() && v >= 0.0))
                .collect::<Result<_, _>>()?,
            albedo: albedo
                .iter()
                .map(|f| field(*f, "albedo", |v| (0.0..=1.0).contains(&v)))
                .collect::<Result<_, _>>()?,
            phase,
        };
        Ok(Self {
            geometry,
            medium,
            lights,
            boundary,
            pager,
        })
    }

    /// A problem of the same shape as [`PagedProblem::from_fn`] would build (geometry,
    /// bricks, pager, `sigma_channels` and `albedo_channels` fields, lights, boundary),
    /// its medium zero everywhere (constant bricks: nothing evaluated, nothing stored).
    /// For [`crate::Solver::paged_memory`]: what a solve would need, known before the
    /// medium is built.
    ///
    /// # Errors
    /// No channel, or a brick size the layout refuses.
    #[allow(clippy::too_many_arguments)]
    pub fn shell(
        pager: Arc<Pager>,
        geometry: GridGeometry,
        brick: usize,
        sigma_channels: usize,
        albedo_channels: usize,
        phase: Phase,
        lights: Vec<Light>,
        boundary: Boundary,
    ) -> Result<Self, ProblemError> {
        if sigma_channels == 0 || albedo_channels == 0 {
            return Err(ProblemError(
                "a paged medium needs σ_t and albedo for at least one channel".into(),
            ));
        }
        let zero = || {
            PagedGrid::filled(pager.clone(), geometry, brick, 0.0)
                .map_err(|e| ProblemError(e.to_string()))
        };
        let medium = PagedMedium {
            sigma_t: (0..sigma_channels)
                .map(|_| zero())
                .collect::<Result<_, _>>()?,
            albedo: (0..albedo_channels)
                .map(|_| zero())
                .collect::<Result<_, _>>()?,
            phase,
        };
        Ok(Self {
            geometry,
            medium,
            lights,
            boundary,
            pager,
        })
    }

    /// The grid.
    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }

    /// The medium.
    pub fn medium(&self) -> &PagedMedium {
        &self.medium
    }

    /// The lights.
    pub fn lights(&self) -> &[Light] {
        &self.lights
    }

    /// The boundary condition.
    pub fn boundary(&self) -> &Boundary {
        &self.boundary
    }

    /// The pager every field of the problem (and of its solutions) lives in.
    pub fn pager(&self) -> &Arc<Pager> {
        &self.pager
    }

    /// The brick layout of the fields.
    pub fn layout(&self) -> &BrickLayout {
        self.medium.sigma_t[0].layout()
    }

    /// Channels: 1 (grey) or 3 (RGB), from the medium and the lights' spectra.
    pub fn channels(&self) -> usize {
        self.channels_with(&self.lights)
    }

    /// Channels of the medium under `lights` (some of the problem's): what
    /// [`PagedProblem::channels`] would be with only those.
    pub fn channels_with(&self, lights: &[Light]) -> usize {
        let medium = self.medium.sigma_t.len().max(self.medium.albedo.len());
        lights
            .iter()
            .map(|l| l.spectrum().channels())
            .fold(medium, usize::max)
    }

    /// An empty (all-zero, nothing stored) field on the problem's bricks and pager, for
    /// results.
    pub fn new_field(&self) -> Result<PagedGrid, PagingError> {
        PagedGrid::filled(
            self.pager.clone(),
            self.geometry,
            self.layout().brick(),
            0.0,
        )
    }

    /// Bytes the job holds in memory besides the pool: the page table and the per-brick
    /// metadata of `fields` fields.
    pub fn overhead_bytes(&self, fields: usize) -> u64 {
        let count = self.layout().count() as u64;
        count * fields as u64 * (Pager::<f32>::TABLE_BYTES_PER_BRICK + PagedGrid::BYTES_PER_BRICK)
    }
}

/// A solver's result on a [`PagedProblem`]: its grids paged in the problem's pager.
#[derive(Debug)]
pub struct PagedSolution {
    /// The fluence per channel.
    pub fluence: Vec<PagedGrid>,
    /// The fluence's standard error per channel (Monte Carlo; empty for deterministic
    /// solvers).
    pub standard_error: Vec<PagedGrid>,
    /// Per point-like light (in the problem's order, the sky left out), transmittance per
    /// extinction channel (solvers that keep it: `direct`).
    pub transmittance: Vec<Vec<PagedGrid>>,
    /// The part of the fluence that in-scatters isotropically, per channel.
    pub isotropic_fluence: Vec<PagedGrid>,
    /// The report.
    pub report: SolveReport,
    /// What the pager did during the solve.
    pub paging: PagerStats,
}
