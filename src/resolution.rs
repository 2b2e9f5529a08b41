//! Resolution chosen by need: the coarsest grid on which a solver meets a tolerance, from
//! solves on the scene's grid and on grids two and four times coarser per axis, and a
//! Richardson-style estimate of each one's discretisation error.
//!
//! With a scheme of order p the fluence on spacing h is φ_h ≈ φ + C h^p, so two levels
//! differ by φ_{2h} − φ_h ≈ (2^p − 1) C h^p: the error of the finer one is
//! e_h ≈ ‖φ_{2h} − R φ_h‖ / (2^p − 1) and of the coarser e_{2h} ≈ 2^p e_h (R: the finer
//! solution box-averaged onto the coarser cells, so that cell averages are compared with
//! cell averages). Three levels give the observed order
//! p = log₂(‖φ_{4h} − R φ_{2h}‖ / ‖φ_{2h} − R φ_h‖), used where it lies in [0.5, 4]
//! (otherwise the solutions are not yet in the asymptotic range and the scheme's nominal
//! order, [`NOMINAL_ORDER`], is used). Errors are relative to the finer level's ‖φ‖₂.
//!
//! The medium, emission and embedded body are resampled onto each coarser grid (the box
//! average of the trilinear field: the same medium, seen coarser). A level whose grid
//! would have fewer than [`MIN_CELLS`] cells along an axis is not tried; a problem whose
//! grid leaves no coarser level, or a solve that stops without converging (its
//! differences would measure the iteration, not the grid), is an error.

use lucent_core::{Light, Problem, SolveOptions, Solver};
use lucent_grid::Grid;
use lucent_grid::resample::resample;

use crate::Error;

/// The order assumed where three levels do not show one: second order, the cell-centred
/// schemes' (diffusion's finite volumes, the explicit schemes, diamond-difference
/// ordinates away from kinks).
pub const NOMINAL_ORDER: f64 = 2.0;

/// The fewest cells along an axis a coarser level keeps.
pub const MIN_CELLS: usize = 4;

/// One level: its grid, the solve's time and the estimated relative error.
#[derive(Debug, Clone, PartialEq)]
pub struct Level {
    /// Coarsening per axis against the problem's grid (1, 2, 4).
    pub coarsening: usize,
    /// Cells per axis.
    pub dims: [usize; 3],
    /// Wall time of its solve, seconds.
    pub seconds: f64,
    /// Estimated relative L2 discretisation error of its fluence (channel 0).
    pub estimated_error: f64,
}

/// What [`coarsest_meeting`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct ResolutionChoice {
    /// The levels solved, finest (the problem's own grid) first.
    pub levels: Vec<Level>,
    /// The order the estimates used.
    pub order: f64,
    /// Whether it was observed from three levels (else [`NOMINAL_ORDER`]).
    pub observed: bool,
    /// Index in `levels` of the coarsest level whose estimate meets the tolerance (the
    /// finest when none does).
    pub chosen: usize,
    /// Whether the chosen level meets the tolerance.
    pub met: bool,
}

impl ResolutionChoice {
    /// Cells per axis the problem's grid would need for the tolerance when even it does
    /// not meet it: its error scaled by (e/tolerance)^{1/p} (`None` when it is met).
    pub fn needed_refinement(&self, tolerance: f64) -> Option<f64> {
        let finest = self.levels.first()?;
        (!self.met).then(|| (finest.estimated_error / tolerance).powf(1.0 / self.order))
    }
}

/// `problem` on a grid of `dims` cells over the same box: the medium, emission and
/// embedded body resampled.
pub fn on_grid(problem: &Problem, dims: [usize; 3]) -> Result<Problem, Error> {
    let medium = problem.medium().resampled(dims)?;
    let lights = problem
        .lights()
        .iter()
        .map(|l| match l {
            Light::Emission { grid, scale } => resample(grid, dims).map(|grid| Light::Emission {
                grid,
                scale: *scale,
            }),
            other => Ok(other.clone()),
        })
        .collect::<Result<_, _>>()?;
    let embedded = problem
        .embedded()
        .map(|sdf| resample(sdf, dims))
        .transpose()?;
    let geometry = *medium.sigma_t[0].geometry();
    let coarse = Problem::new(geometry, medium, lights, problem.boundary(), embedded)?;
    Ok(match problem.refractive_index() {
        Some(index) => coarse.with_refractive_index(index.clone())?,
        None => coarse,
    })
}

/// Solves `problem` with `solver` on its grid and on grids 2× and 4× coarser per axis
/// (those with at least [`MIN_CELLS`] cells along every axis), estimates each level's
/// discretisation error (module docs) and picks the coarsest whose estimate is at most
/// `tolerance`. The solver's own stopping tolerance should be well below `tolerance`, so
/// that the differences measured are the discretisation's.
pub fn coarsest_meeting(
    problem: &Problem,
    solver: &dyn Solver,
    tolerance: f64,
    options: &SolveOptions,
) -> Result<ResolutionChoice, Error> {
    let fine = problem.geometry().dims();
    let mut solutions: Vec<(usize, Grid, f64)> = Vec::new();
    for coarsening in [1usize, 2, 4] {
        let dims = fine.map(|n| n.div_ceil(coarsening));
        if coarsening > 1 && dims.iter().zip(fine).any(|(&d, n)| d < MIN_CELLS && d < n) {
            break;
        }
        // A level no coarser than the last (a 1³ grid "coarsened") would make the
        // difference, and so the estimate, zero.
        let previous = fine.map(|n| n.div_ceil((coarsening / 2).max(1)));
        if coarsening > 1 && dims == previous {
            break;
        }
        let level = if coarsening == 1 {
            problem.clone()
        } else {
            on_grid(problem, dims)?
        };
        let started = std::time::Instant::now();
        let solution = solver.solve(&level, options)?;
        let seconds = started.elapsed().as_secs_f64();
        let stop = &solution.report.stop_reason;
        if !stop.is_converged() {
            let [nx, ny, nz] = dims;
            return Err(Error::Unconverged {
                what: format!("`{}` on {nx} × {ny} × {nz} cells", solver.name()),
                reason: stop.to_string(),
                diverged: stop.is_diverged(),
            });
        }
        solutions.push((coarsening, solution.fluence(0).clone(), seconds));
    }
    if solutions.len() < 2 {
        let [nx, ny, nz] = fine;
        return Err(Error::Invalid(format!(
            "{nx} × {ny} × {nz} cells leave no grid 2× coarser with {MIN_CELLS} cells along each axis: no error estimate"
        )));
    }
    let fluences: Vec<&Grid> = solutions.iter().map(|(_, g, _)| g).collect();
    let Estimates {
        order,
        observed,
        errors,
    } = estimates(&fluences)?;
    let levels: Vec<Level> = solutions
        .iter()
        .zip(&errors)
        .map(|((coarsening, grid, seconds), &estimated_error)| Level {
            coarsening: *coarsening,
            dims: grid.dims(),
            seconds: *seconds,
            estimated_error,
        })
        .collect();
    let (chosen, met) = coarsest_within(&errors, tolerance);
    Ok(ResolutionChoice {
        met,
        levels,
        order,
        observed,
        chosen,
    })
}

/// What the differences between neighbouring levels (finest first) say.
struct Estimates {
    /// The order used: observed, or [`NOMINAL_ORDER`].
    order: f64,
    /// Whether it was observed.
    observed: bool,
    /// Each level's estimated relative error.
    errors: Vec<f64>,
}

/// The Richardson-style estimates of the module docs from `fluences`, finest first, each
/// level's resolution (in space or in angle) half the one before it: the relative
/// difference of each neighbouring pair (the finer restricted onto the coarser's grid),
/// the order observed from three levels, and each level's error (the finest's from the
/// pair below it, a coarser one's from the pair it is the coarser of).
fn estimates(fluences: &[&Grid]) -> Result<Estimates, Error> {
    let mut differences = Vec::new();
    for pair in fluences.windows(2) {
        let (finer, coarser) = (pair[0], pair[1]);
        let restricted = resample(finer, coarser.dims())?;
        let (mut diff, mut norm) = (0.0f64, 0.0f64);
        for (c, r) in coarser.data().iter().zip(restricted.data()) {
            diff += (f64::from(*c) - f64::from(*r)).powi(2);
            norm += f64::from(*r).powi(2);
        }
        differences.push(if norm > 0.0 {
            (diff / norm).sqrt()
        } else {
            0.0
        });
    }
    let observed = match differences.as_slice() {
        [d0, d1, ..] if *d0 > 0.0 && *d1 > 0.0 => Some((d1 / d0).log2()),
        _ => None,
    }
    .filter(|p| (0.5..=4.0).contains(p));
    let order = observed.unwrap_or(NOMINAL_ORDER);
    let gain = 2f64.powf(order);
    let errors = (0..fluences.len())
        .map(|i| match i {
            0 => differences[0] / (gain - 1.0),
            i => differences[i - 1] * gain / (gain - 1.0),
        })
        .collect();
    Ok(Estimates {
        order,
        observed: observed.is_some(),
        errors,
    })
}

/// The index of the coarsest level whose error is within `tolerance` (the finest when
/// none is), and whether it is.
fn coarsest_within(errors: &[f64], tolerance: f64) -> (usize, bool) {
    let chosen = errors.iter().rposition(|&e| e <= tolerance).unwrap_or(0);
    (chosen, errors.get(chosen).is_some_and(|&e| e <= tolerance))
}

/// One angular level of [`fewest_directions_meeting`].
#[derive(Debug, Clone, PartialEq)]
pub struct AngularLevel {
    /// Propagation directions.
    pub directions: usize,
    /// The solver's parameters at this level, in words (`order = 8`).
    pub setting: String,
    /// Wall time of its solve, seconds.
    pub seconds: f64,
    /// Estimated relative L2 angular error of its fluence (channel 0).
    pub estimated_error: f64,
}

/// What [`fewest_directions_meeting`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct DirectionsChoice {
    /// The levels solved, most directions first.
    pub levels: Vec<AngularLevel>,
    /// The order (in the angular spacing) the estimates used.
    pub order: f64,
    /// Whether it was observed from three levels (else [`NOMINAL_ORDER`]).
    pub observed: bool,
    /// Index in `levels` of the level with the fewest directions whose estimate meets the
    /// tolerance (the first when none does).
    pub chosen: usize,
    /// Whether the chosen level meets the tolerance.
    pub met: bool,
}

/// An angular family of a solver, finest first, each level's angular spacing half the
/// next one's: the directions of each level and a solver for it.
pub struct AngularFamily {
    /// Per level, most directions first: propagation directions, the parameters in words,
    /// the solver.
    pub levels: Vec<(usize, String, Box<dyn Solver>)>,
}

impl AngularFamily {
    /// The angular family of the registered solver `name` with its parameters `base`
    /// (TOML): `dom` on the nested octahedral sets of levels 2, 1, 0 (128, 32, 8
    /// directions), `hybrid` on level-symmetric S8, S4, S2 (80, 24, 8); `None` for a
    /// solver without discrete directions.
    pub fn of(
        registry: &lucent_core::Registry,
        name: &str,
        base: &lucent_core::Params,
    ) -> Result<Option<Self>, Error> {
        // Per level: the parameters that set it and its propagation directions.
        let sets: Vec<(String, usize)> = match name {
            "dom" => [2, 1, 0]
                .into_iter()
                .map(|l| {
                    let directions = lucent_optics::SphericalQuadrature::octahedral(l)
                        .map_err(|e| Error::Invalid(e.to_string()))?
                        .len();
                    Ok((format!("family = \"octahedral\"\norder = {l}"), directions))
                })
                .collect::<Result<_, Error>>()?,
            "hybrid" => [8, 4, 2]
                .into_iter()
                .map(|n| (format!("order = {n}"), n * (n + 2)))
                .collect(),
            _ => return Ok(None),
        };
        let mut levels = Vec::new();
        for (text, directions) in sets {
            let set: lucent_core::Params = toml::from_str(&text)
                .map_err(|e| Error::Invalid(format!("angular level `{text}`: {e}")))?;
            let mut params = base.clone();
            params.0.extend(set.0);
            let solver = registry.build(name, &params)?;
            levels.push((directions, text.replace('\n', ", "), solver));
        }
        Ok(Some(Self { levels }))
    }
}

/// Solves `problem` with each level of `family` (most directions first; three levels
/// show the order), estimates each level's angular error as [`coarsest_meeting`] does
/// the grid's (the angular spacing halves from level to level: the octahedral sets
/// quadruple their directions, S_N doubles N), and picks the level with the fewest
/// directions whose estimate is at most `tolerance`. Ray effects make the angular error
/// less regular than the grid's: where three levels show no order in [0.5, 4] the
/// nominal second order is used and the choice says so.
pub fn fewest_directions_meeting(
    problem: &Problem,
    family: &AngularFamily,
    tolerance: f64,
    options: &SolveOptions,
) -> Result<DirectionsChoice, Error> {
    if family.levels.len() < 2 {
        return Err(Error::Invalid(
            "an angular family of fewer than two levels: no error estimate".into(),
        ));
    }
    let mut solved = Vec::new();
    for (directions, setting, solver) in &family.levels {
        let started = std::time::Instant::now();
        let solution = solver.solve(problem, options)?;
        let seconds = started.elapsed().as_secs_f64();
        let stop = &solution.report.stop_reason;
        if !stop.is_converged() {
            return Err(Error::Unconverged {
                what: format!("`{}` with {setting}", solver.name()),
                reason: stop.to_string(),
                diverged: stop.is_diverged(),
            });
        }
        solved.push((
            *directions,
            setting.clone(),
            seconds,
            solution.fluence(0).clone(),
        ));
    }
    let fluences: Vec<&Grid> = solved.iter().map(|(.., g)| g).collect();
    let Estimates {
        order,
        observed,
        errors,
    } = estimates(&fluences)?;
    let (chosen, met) = coarsest_within(&errors, tolerance);
    Ok(DirectionsChoice {
        levels: solved
            .into_iter()
            .zip(&errors)
            .map(
                |((directions, setting, seconds, _), &estimated_error)| AngularLevel {
                    directions,
                    setting,
                    seconds,
                    estimated_error,
                },
            )
            .collect(),
        order,
        observed,
        chosen,
        met,
    })
}
