//! The explicit schemes' stability bounds and `lucent-optics`' analytic references,
//! evaluated element by element over equal-length float64 columns. The Python wrappers
//! (`lucent.stability`, `lucent.analytic`) broadcast numpy arrays into those columns and
//! reshape the result, so every function here is a plain loop over slices.

use glam::DVec3;
use lucent::explicit::stability as s;
use lucent::optics::{
    Dielectric, DiffuseFresnel, DiffusionMedium, OpticalCoefficients, OpticsError, analytic,
};
use numpy::PyReadonlyArray1;
use pyo3::prelude::*;

use crate::arrays::array_f64;
use crate::errors::invalid;

/// A diffusion medium from σ_a, σ_s′ and the boundary factor A (g = 0: only the reduced
/// coefficients matter to diffusion).
fn medium(sigma_a: f64, sigma_s_reduced: f64, a: f64) -> Result<DiffusionMedium, OpticsError> {
    DiffusionMedium::new(
        OpticalCoefficients::from_reduced(sigma_a, sigma_s_reduced, 0.0)?,
        a,
    )
}

fn bool_to(b: bool) -> f64 {
    if b { 1.0 } else { 0.0 }
}

/// One element: the function `name` at the arguments `x`.
fn element(name: &str, x: &[f64]) -> Result<f64, String> {
    let optics = |e: OpticsError| e.to_string();
    let dir = |i: usize| DVec3::new(x[i], x[i + 1], x[i + 2]);
    Ok(match name {
        "ftcs_diffusion.murray" => s::ftcs_diffusion::murray(x[0], x[1]),
        "ftcs_diffusion.von_neumann" => s::ftcs_diffusion::von_neumann(x[0], x[1]),
        "ftcs_diffusion.positivity" => s::ftcs_diffusion::positivity(x[0], x[1]),
        "ftcs_diffusion.time_step" => s::ftcs_diffusion::time_step(x[0], x[1], x[2]),
        "upwind.courant_limit" => s::upwind::courant_limit(dir(0)),
        "upwind.checkerboard_growth" => s::upwind::checkerboard_growth(x[0], dir(1), x[4]),
        "upwind.von_neumann_limit" => s::upwind::von_neumann_limit(dir(0), x[3]),
        "p1.murray_condition" => bool_to(s::p1::murray_condition(x[0], x[1])),
        "p1.collocated_limit" => s::p1::collocated_limit(x[0], x[1]),
        "p1.staggered_limit" => s::p1::staggered_limit(x[0], x[1]),
        "p1.largest_step" => s::p1::largest_step(x[0] != 0.0, x[1], x[2], x[3]),
        "ordinates.von_neumann_limit" => s::ordinates::von_neumann_limit(x[0], x[1]),
        "ordinates.positivity_limit" => s::ordinates::positivity_limit(x[0], x[1]),
        "ordinates.largest_step" => s::ordinates::largest_step(x[0], x[1], x[2]),
        "beer_lambert" => analytic::beer_lambert(x[0]).map_err(optics)?,
        "boundary_factor.milne" => boundary_factor(x[0], DiffuseFresnel::Milne)?,
        "boundary_factor.groenhuis" => boundary_factor(x[0], DiffuseFresnel::Groenhuis)?,
        "boundary_factor.partial_current" => boundary_factor(x[0], DiffuseFresnel::PartialCurrent)?,
        "boundary_factor.exact" => boundary_factor(x[0], DiffuseFresnel::Exact)?,
        "infinite_medium_fluence" => medium(x[0], x[1], 1.0)
            .and_then(|m| m.infinite_medium_fluence(x[2], x[3]))
            .map_err(optics)?,
        "dipole.reflectance_profile" => {
            let m = medium(x[0], x[1], x[2]).map_err(optics)?;
            if x[3] < 0.0 {
                return Err(format!("r = {} must be ≥ 0", x[3]));
            }
            m.dipole().reflectance_profile(x[3])
        }
        "dipole.total_reflectance" => medium(x[0], x[1], x[2])
            .map_err(optics)?
            .dipole()
            .total_reflectance(),
        "sphere.fluence" => medium(x[0], x[1], x[2])
            .and_then(|m| m.sphere(x[3]))
            .and_then(|sphere| sphere.fluence(x[4]))
            .map_err(optics)?,
        "sphere.escaped_fraction" => medium(x[0], x[1], x[2])
            .and_then(|m| m.sphere(x[3]))
            .map_err(optics)?
            .escaped_fraction(),
        "sphere.absorbed_fraction" => medium(x[0], x[1], x[2])
            .and_then(|m| m.sphere(x[3]))
            .map_err(optics)?
            .absorbed_fraction(),
        "half_space.fluence" => medium(x[0], x[1], x[2])
            .and_then(|m| m.half_space(x[3]))
            .and_then(|h| h.fluence(x[4]))
            .map_err(optics)?,
        "half_space.exitance" => medium(x[0], x[1], x[2])
            .and_then(|m| m.half_space(x[3]))
            .map_err(optics)?
            .exitance(),
        other => return Err(format!("no function `{other}`")),
    })
}

fn boundary_factor(eta: f64, model: DiffuseFresnel) -> Result<f64, String> {
    Dielectric::new(eta)
        .and_then(|d| d.boundary_factor(model))
        .map_err(|e| e.to_string())
}

/// How many arguments each function takes.
fn arity(name: &str) -> Option<usize> {
    Some(match name {
        "beer_lambert"
        | "boundary_factor.milne"
        | "boundary_factor.groenhuis"
        | "boundary_factor.partial_current"
        | "boundary_factor.exact" => 1,
        "ftcs_diffusion.murray"
        | "ftcs_diffusion.von_neumann"
        | "ftcs_diffusion.positivity"
        | "p1.murray_condition"
        | "p1.collocated_limit"
        | "p1.staggered_limit"
        | "ordinates.von_neumann_limit"
        | "ordinates.positivity_limit" => 2,
        "ftcs_diffusion.time_step"
        | "upwind.courant_limit"
        | "ordinates.largest_step"
        | "dipole.total_reflectance" => 3,
        "upwind.von_neumann_limit"
        | "p1.largest_step"
        | "infinite_medium_fluence"
        | "dipole.reflectance_profile"
        | "sphere.escaped_fraction"
        | "sphere.absorbed_fraction"
        | "half_space.exitance" => 4,
        "upwind.checkerboard_growth" | "sphere.fluence" | "half_space.fluence" => 5,
        _ => return None,
    })
}

/// `name` evaluated at every row of `columns` (equal-length float64 arrays, one per
/// argument); `arguments` names them for errors. An element that fails raises
/// `ValueError` with its index and the reason.
#[pyfunction]
pub(crate) fn _evaluate<'py>(
    py: Python<'py>,
    name: &str,
    columns: Vec<PyReadonlyArray1<'py, f64>>,
    arguments: Vec<String>,
) -> PyResult<Bound<'py, PyAny>> {
    let expected = arity(name).ok_or_else(|| invalid("name", format!("no function `{name}`")))?;
    if columns.len() != expected {
        return Err(invalid(
            name,
            format!("{expected} arguments, given {}", columns.len()),
        ));
    }
    let views: Vec<_> = columns.iter().map(|c| c.as_array()).collect();
    let n = views.first().map_or(1, |v| v.len());
    if views.iter().any(|v| v.len() != n) {
        return Err(invalid(name, "the arguments do not broadcast to one shape"));
    }
    let mut out = Vec::with_capacity(n);
    let mut x = vec![0.0; expected];
    for i in 0..n {
        for (slot, view) in x.iter_mut().zip(&views) {
            *slot = view[i];
        }
        if let Some(k) = x.iter().position(|v| v.is_nan()) {
            let argument = arguments.get(k).map_or("argument", String::as_str);
            return Err(invalid(argument, format!("NaN at element {i}")));
        }
        match element(name, &x) {
            Ok(v) => out.push(v),
            Err(reason) => {
                return Err(crate::errors::raise(
                    crate::errors::Kind::InvalidInput,
                    format!("{name} at element {i}: {reason}"),
                ));
            }
        }
    }
    Ok(array_f64(py, out))
}
