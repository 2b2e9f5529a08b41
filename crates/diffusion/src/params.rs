//! The registry parameters of the diffusion solvers: one typed struct per solver, read
//! from a scene's `[solver.params]` by serde (unknown keys and ill-typed values are errors
//! naming the key), printed with their defaults by `lucent solvers`.

use lucent_core::{SolveError, SolverParams};
use serde::{Deserialize, Serialize};

use crate::geometry::Discretisation;
use crate::multigrid::{Cycle, MultigridSettings, Smoother};

fn invalid(name: &str, reason: impl Into<String>) -> SolveError {
    SolveError::InvalidParameter {
        name: name.into(),
        reason: reason.into(),
    }
}

/// How cut cells are discretised (a parameter of every diffusion solver).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DiscretisationParam {
    /// Embedded-boundary finite volumes: volume and aperture fractions of cut cells.
    #[default]
    Embedded,
    /// Whole cells inside or out, by their centre.
    Staircase,
}

impl From<DiscretisationParam> for Discretisation {
    fn from(d: DiscretisationParam) -> Self {
        match d {
            DiscretisationParam::Embedded => Discretisation::EmbeddedBoundary,
            DiscretisationParam::Staircase => Discretisation::Staircase,
        }
    }
}

/// The multigrid cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CycleParam {
    /// V-cycle.
    #[default]
    V,
    /// W-cycle.
    W,
    /// F-cycle.
    F,
    /// K-cycle (flexible CG on each coarse level), for jumps of D.
    K,
}

/// The multigrid smoother.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SmootherParam {
    /// Red–black Gauss–Seidel.
    #[default]
    GaussSeidel,
    /// Damped Jacobi, ω = 6/7.
    Jacobi,
}

/// The parameters of `diffusion-mg` and `diffusion-mgcg` (which always starts from zero:
/// its `full_multigrid` is ignored).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MultigridParams {
    /// The cycle.
    pub cycle: CycleParam,
    /// Smoothing sweeps before the coarse correction.
    pub pre_sweeps: usize,
    /// Smoothing sweeps after it.
    pub post_sweeps: usize,
    /// The smoother.
    pub smoother: SmootherParam,
    /// Start from full multigrid (nested iteration) instead of zero.
    pub full_multigrid: bool,
    /// Cut cells.
    pub discretisation: DiscretisationParam,
    /// In-process ranks to split the solve over (`diffusion-mg` only). Under `mpirun` the
    /// processes are the ranks and this stays 1.
    pub ranks: usize,
    /// How the ranks cut the hierarchy (`diffusion-mg` only).
    pub decomposition: DecompositionParam,
}

/// How a solver's ranks cut the grid: z-slabs or the grid of boxes with the least cut area
/// (`diffusion-mg`: [`crate::Decomposition`]; `lucent-explicit`'s solvers map it to theirs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DecompositionParam {
    /// Runs of whole z-layers.
    #[default]
    Slabs,
    /// The grid of boxes with the least cut area.
    Boxes,
}

impl DecompositionParam {
    /// The decomposition it names.
    pub fn decomposition(self) -> crate::Decomposition {
        match self {
            Self::Slabs => crate::Decomposition::Slabs,
            Self::Boxes => crate::Decomposition::Boxes,
        }
    }
}

impl Default for MultigridParams {
    fn default() -> Self {
        Self {
            cycle: CycleParam::V,
            pre_sweeps: 2,
            post_sweeps: 2,
            smoother: SmootherParam::GaussSeidel,
            full_multigrid: true,
            discretisation: DiscretisationParam::Embedded,
            ranks: 1,
            decomposition: DecompositionParam::Slabs,
        }
    }
}

/// The meaning of every `ranks` parameter.
pub const RANKS: (&str, &str) = (
    "ranks",
    "split the solve over this many in-process ranks (slabs or boxes with one-cell halos, the bits of one rank; under mpirun the processes are the ranks: leave 1)",
);

/// The most in-process ranks a solve may ask for.
pub const MAX_RANKS: usize = 256;

/// Checks a `ranks` parameter: 1 to [`MAX_RANKS`].
pub fn check_ranks(ranks: usize) -> Result<(), SolveError> {
    if ranks == 0 || ranks > MAX_RANKS {
        return Err(invalid("ranks", format!("1 to {MAX_RANKS}")));
    }
    Ok(())
}

const DISCRETISATION: (&str, &str) = (
    "discretisation",
    "cut cells: embedded (volume and aperture fractions, second order) or staircase",
);

impl SolverParams for MultigridParams {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[
        (
            "cycle",
            "multigrid cycle: v, w, f or k (two flexible-CG steps per coarse level: for jumps of D, best under diffusion-mgcg)",
        ),
        (
            "pre_sweeps",
            "smoothing sweeps before the coarse correction",
        ),
        (
            "post_sweeps",
            "smoothing sweeps after it (1 to 64 in all with pre_sweeps)",
        ),
        (
            "smoother",
            "gauss-seidel (red-black) or jacobi (damped, ω = 6/7)",
        ),
        (
            "full_multigrid",
            "start by full multigrid (nested iteration) instead of from zero (diffusion-mg only)",
        ),
        DISCRETISATION,
        RANKS,
        (
            "decomposition",
            "how ranks cut the hierarchy (diffusion-mg only): slabs (whole z-layers, each rank two at least on the fine level) or boxes (the grid of boxes that cuts least, x cut at multiples of 8, so the fine level splits over more ranks and the halo shrinks); coarse levels agglomerated onto fewer ranks either way; the serial bits either way",
        ),
    ];

    fn validate(&self) -> Result<(), SolveError> {
        if self.pre_sweeps + self.post_sweeps == 0 || self.pre_sweeps.max(self.post_sweeps) > 64 {
            return Err(invalid("pre_sweeps", "1 to 64 sweeps in all"));
        }
        check_ranks(self.ranks)
    }
}

impl MultigridParams {
    /// The multigrid settings these ask for.
    pub fn settings(&self) -> MultigridSettings {
        MultigridSettings {
            cycle: match self.cycle {
                CycleParam::V => Cycle::V,
                CycleParam::W => Cycle::W,
                CycleParam::F => Cycle::F,
                CycleParam::K => Cycle::K,
            },
            smoother: match self.smoother {
                SmootherParam::GaussSeidel => Smoother::RedBlackGaussSeidel,
                SmootherParam::Jacobi => Smoother::Jacobi { omega: 6.0 / 7.0 },
            },
            pre_sweeps: self.pre_sweeps,
            post_sweeps: self.post_sweeps,
            full_multigrid: self.full_multigrid,
            ..MultigridSettings::default()
        }
    }
}

/// The parameters of `diffusion-cg`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CgParams {
    /// Cut cells.
    pub discretisation: DiscretisationParam,
}

impl SolverParams for CgParams {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[DISCRETISATION];
}

const OMEGA: (&str, &str) = (
    "omega",
    "relaxation factor ω: 0 < ω < 2 for SOR, 0 < ω ≤ 1 for Jacobi",
);

/// The parameters of `diffusion-sor`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SorParams {
    /// Over-relaxation factor ω, in (0, 2).
    pub omega: f64,
    /// Cut cells.
    pub discretisation: DiscretisationParam,
}

impl Default for SorParams {
    fn default() -> Self {
        Self {
            omega: 1.9,
            discretisation: DiscretisationParam::Embedded,
        }
    }
}

impl SolverParams for SorParams {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[OMEGA, DISCRETISATION];

    fn validate(&self) -> Result<(), SolveError> {
        if !(self.omega > 0.0 && self.omega < 2.0) {
            return Err(invalid("omega", "in (0, 2)"));
        }
        Ok(())
    }
}

/// The parameters of `diffusion-jacobi`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct JacobiParams {
    /// Damping ω, in (0, 1].
    pub omega: f64,
    /// Cut cells.
    pub discretisation: DiscretisationParam,
}

impl Default for JacobiParams {
    fn default() -> Self {
        Self {
            omega: 1.0,
            discretisation: DiscretisationParam::Embedded,
        }
    }
}

impl SolverParams for JacobiParams {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[OMEGA, DISCRETISATION];

    fn validate(&self) -> Result<(), SolveError> {
        if !(self.omega > 0.0 && self.omega <= 1.0) {
            return Err(invalid("omega", "in (0, 1]"));
        }
        Ok(())
    }
}
