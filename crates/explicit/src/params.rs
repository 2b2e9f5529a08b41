//! The registry parameters of the explicit schemes: one typed struct per solver, read from
//! a scene's `[solver.params]` by serde (unknown keys and ill-typed values are errors
//! naming the key) and printed with their defaults by `lucent solvers`.

use lucent_core::{SolveError, SolverParams};
use serde::{Deserialize, Serialize};

use crate::convection::{Model, Sweep};
use crate::p1::Layout;

fn invalid(name: &str, reason: &str) -> SolveError {
    SolveError::InvalidParameter {
        name: name.into(),
        reason: reason.into(),
    }
}

const STEP_FRACTION: (&str, &str) = (
    "step_fraction",
    "time step as a fraction of the scheme's stability bound (> 0; above 1 needs allow_unstable)",
);
const ALLOW_UNSTABLE: (&str, &str) = (
    "allow_unstable",
    "true: run a step beyond the stability bound anyway (to study the blow-up)",
);

const DECOMPOSITION: (&str, &str) = (
    "decomposition",
    "how ranks split the grid: slabs (z-slabs balanced by unknowns, one layer per rank at least) or boxes (the grid of boxes that cuts least, x cut at multiples of 8); the serial bits either way",
);

const MARCH_DECOMPOSITION: (&str, &str) = (
    "decomposition",
    "how ranks split the grid: slabs (z-layers r·n_z/P..(r+1)·n_z/P; planes in lock step where the light runs along them) or boxes (per light, the grid of boxes that cuts least among those that leave an axis whole, the light's first, x cut at multiples of 8: a KBA sweep pipelined across every cut); the serial bits either way",
);

const P1_DECOMPOSITION: (&str, &str) = (
    "decomposition",
    "how ranks split the grid: slabs (z-layers r·n_z/P..(r+1)·n_z/P, one layer per rank at least) or boxes (the grid of boxes that cuts least, x cut at multiples of 8); the serial bits either way",
);

/// How the steady iterations and P1 split the grid over ranks: slabs, or the grid of boxes
/// [`crate::ranks::Boxes::auto`] chooses (`lucent_diffusion`'s parameter, shared with
/// `diffusion-mg` as `ranks` is).
pub use lucent_diffusion::DecompositionParam;

fn check_fraction(fraction: f64) -> Result<(), SolveError> {
    if fraction > 0.0 && fraction.is_finite() {
        Ok(())
    } else {
        Err(invalid("step_fraction", "a positive fraction of the bound"))
    }
}

/// The parameters of `ftcs-diffusion`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FtcsDiffusionParams {
    /// Time step as a fraction of the FTCS bound.
    pub step_fraction: f64,
    /// Run beyond the bound anyway.
    pub allow_unstable: bool,
    /// In-process ranks to split the iteration over.
    pub ranks: usize,
    /// How the ranks split the grid.
    pub decomposition: DecompositionParam,
}

impl Default for FtcsDiffusionParams {
    fn default() -> Self {
        Self {
            step_fraction: 0.9,
            allow_unstable: false,
            ranks: 1,
            decomposition: DecompositionParam::Slabs,
        }
    }
}

impl SolverParams for FtcsDiffusionParams {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[
        STEP_FRACTION,
        ALLOW_UNSTABLE,
        lucent_diffusion::RANKS,
        DECOMPOSITION,
    ];

    fn validate(&self) -> Result<(), SolveError> {
        check_fraction(self.step_fraction)?;
        lucent_diffusion::check_ranks(self.ranks)
    }
}

/// The parameters of `jacobi-diffusion`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct JacobiDiffusionParams {
    /// Damping ω, in (0, 1].
    pub omega: f64,
    /// In-process ranks to split the iteration over.
    pub ranks: usize,
    /// How the ranks split the grid.
    pub decomposition: DecompositionParam,
}

impl Default for JacobiDiffusionParams {
    fn default() -> Self {
        Self {
            omega: 1.0,
            ranks: 1,
            decomposition: DecompositionParam::Slabs,
        }
    }
}

impl SolverParams for JacobiDiffusionParams {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[
        ("omega", "Jacobi damping ω in (0, 1]"),
        lucent_diffusion::RANKS,
        DECOMPOSITION,
    ];

    fn validate(&self) -> Result<(), SolveError> {
        if !(self.omega > 0.0 && self.omega <= 1.0) {
            return Err(invalid("omega", "in (0, 1]"));
        }
        lucent_diffusion::check_ranks(self.ranks)
    }
}

/// How the upwind models march ([`Sweep`] without its tuning).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SweepParam {
    /// Cells in upwind order: one pass.
    #[default]
    Ordered,
    /// Layer by layer, five iterations each, warm started.
    Layers,
    /// Jacobi over the whole grid.
    Jacobi,
}

impl From<SweepParam> for Sweep {
    fn from(s: SweepParam) -> Self {
        match s {
            SweepParam::Ordered => Sweep::Ordered,
            SweepParam::Layers => Sweep::Layers {
                iterations: 5,
                warm_start: true,
            },
            SweepParam::Jacobi => Sweep::Jacobi,
        }
    }
}

/// The parameters of `convection-diffusion`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ConvectionParams {
    /// Courant number of the upwind models (`None`: ½, or the light's stability bound
    /// where that is lower).
    pub courant: Option<f64>,
    /// The form of the convection–absorption equation.
    pub model: Model,
    /// How the upwind models march.
    pub sweep: SweepParam,
    /// σ̂_s t of the implicit scattering step (length²; 0: uncollided light only).
    pub scattering: f64,
    /// Run a Courant number beyond the bound anyway.
    pub allow_unstable: bool,
    /// In-process ranks to split the march over (distant lights, ordered sweeps, the
    /// characteristic or the paper's model).
    pub ranks: usize,
    /// How ranks split the grid: z-slabs or a grid of boxes.
    pub decomposition: DecompositionParam,
}

impl Default for ConvectionParams {
    fn default() -> Self {
        Self {
            courant: None,
            model: Model::Characteristic,
            sweep: SweepParam::Ordered,
            scattering: 0.0,
            allow_unstable: false,
            ranks: 1,
            decomposition: DecompositionParam::Slabs,
        }
    }
}

impl SolverParams for ConvectionParams {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[
        (
            "courant",
            "Courant number cΔt/h of the upwind models (conservative, paper); unset: ½, or each light's stability bound where that is lower",
        ),
        (
            "model",
            "characteristic (short characteristics, exact attenuation, second order), conservative (upwind fluxes) or paper (Zhang & Ma Eq. 16 as printed)",
        ),
        (
            "sweep",
            "march of the upwind models: ordered, layers or jacobi",
        ),
        (
            "scattering",
            "σ̂_s t of the implicit scattering step (length², ≥ 0; 0: the uncollided light only)",
        ),
        ALLOW_UNSTABLE,
        (
            "ranks",
            "split each light's march over this many in-process ranks (a pipelined wavefront over z-slabs or boxes; the bits of one rank; distant lights with ordered sweeps and the characteristic or paper model; under mpirun the processes are the ranks: leave 1)",
        ),
        MARCH_DECOMPOSITION,
    ];

    fn validate(&self) -> Result<(), SolveError> {
        lucent_diffusion::check_ranks(self.ranks)?;
        if !(self.scattering >= 0.0 && self.scattering.is_finite()) {
            return Err(invalid("scattering", "σ̂_s t ≥ 0 (length²)"));
        }
        if self.courant.is_some_and(|c| !(c > 0.0 && c.is_finite())) {
            return Err(invalid("courant", "a positive Courant number"));
        }
        Ok(())
    }
}

/// The parameters of `ftcs-p1`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct P1Params {
    /// Where the flux lives.
    pub layout: Layout,
    /// Time step as a fraction of the stability bound.
    pub step_fraction: f64,
    /// Run beyond the bound anyway.
    pub allow_unstable: bool,
    /// In-process ranks to split the march over.
    pub ranks: usize,
    /// How the ranks split the grid.
    pub decomposition: DecompositionParam,
}

impl Default for P1Params {
    fn default() -> Self {
        Self {
            layout: Layout::Staggered,
            step_fraction: 0.9,
            allow_unstable: false,
            ranks: 1,
            decomposition: DecompositionParam::Slabs,
        }
    }
}

impl SolverParams for P1Params {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[
        (
            "layout",
            "staggered (flux on the faces) or collocated (flux at cell centres)",
        ),
        STEP_FRACTION,
        ALLOW_UNSTABLE,
        lucent_diffusion::RANKS,
        P1_DECOMPOSITION,
    ];

    fn validate(&self) -> Result<(), SolveError> {
        check_fraction(self.step_fraction)?;
        lucent_diffusion::check_ranks(self.ranks)
    }
}

/// The parameters of `ftcs-ordinates`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OrdinatesParams {
    /// Level-symmetric S_N order.
    pub order: usize,
    /// Time step as a fraction of the positivity bound.
    pub step_fraction: f64,
    /// Run beyond the bound anyway.
    pub allow_unstable: bool,
}

impl Default for OrdinatesParams {
    fn default() -> Self {
        Self {
            order: 4,
            step_fraction: 0.9,
            allow_unstable: false,
        }
    }
}

impl SolverParams for OrdinatesParams {
    const MEANINGS: &'static [(&'static str, &'static str)] = &[
        ("order", "level-symmetric S_N order: even, 2 to 16"),
        STEP_FRACTION,
        ALLOW_UNSTABLE,
    ];

    fn validate(&self) -> Result<(), SolveError> {
        if !(2..=16).contains(&self.order) || self.order % 2 == 1 {
            return Err(invalid("order", "an even S_N order from 2 to 16"));
        }
        check_fraction(self.step_fraction)
    }
}
