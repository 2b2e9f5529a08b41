//! lucent's typed errors as Python exceptions, with the same messages.
//!
//! The exception classes live in `lucent/_errors.py` (so that they can have two bases,
//! `LucentError` and the builtin a Python user would catch: `ValueError`, `OSError`,
//! `MemoryError`); this module picks the class for each Rust error.

use lucent::core::SolveError;
use lucent::grid::GridError;
use pyo3::prelude::*;
use pyo3::types::PyModule;

/// The exception classes of `lucent._errors`, by name.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Kind {
    /// A bad argument: an array, a parameter, a scene value (`ValueError`).
    InvalidInput,
    /// A scene file or dict that is not a valid scene (`ValueError`).
    Scene,
    /// A volume file that is malformed or of an unsupported kind (`ValueError`).
    Volume,
    /// A file that cannot be read or written (`OSError`).
    Io,
    /// The solver cannot handle the problem.
    Unsupported,
    /// Over a memory budget (`MemoryError`).
    OverBudget,
    /// No GPU adapter, or the device failed.
    Device,
    /// Anything else a solve or render refused.
    Solve,
}

impl Kind {
    fn class_name(self) -> &'static str {
        match self {
            Kind::InvalidInput => "InvalidInputError",
            Kind::Scene => "SceneError",
            Kind::Volume => "VolumeError",
            Kind::Io => "LucentIOError",
            Kind::Unsupported => "UnsupportedError",
            Kind::OverBudget => "OverBudgetError",
            Kind::Device => "DeviceError",
            Kind::Solve => "SolveError",
        }
    }
}

/// A Python exception of `kind` with `message`. Falls back to `RuntimeError` if the
/// package's `_errors` module cannot be imported (the extension imported on its own).
pub(crate) fn raise(kind: Kind, message: impl Into<String>) -> PyErr {
    let message = message.into();
    Python::attach(|py| {
        let class = PyModule::import(py, "lucent._errors")
            .and_then(|m| m.getattr(kind.class_name()))
            .ok();
        match class {
            Some(class) => match class.call1((message.clone(),)) {
                Ok(instance) => PyErr::from_value(instance),
                Err(e) => e,
            },
            None => pyo3::exceptions::PyRuntimeError::new_err(message),
        }
    })
}

/// A `ValueError` (lucent's `InvalidInputError`) naming the argument.
pub(crate) fn invalid(argument: &str, reason: impl std::fmt::Display) -> PyErr {
    raise(Kind::InvalidInput, format!("`{argument}`: {reason}"))
}

fn grid_kind(e: &GridError) -> Kind {
    match e {
        GridError::Io { .. } | GridError::NotAFile { .. } => Kind::Io,
        GridError::OverBudget { .. } => Kind::OverBudget,
        GridError::InvalidGeometry(_)
        | GridError::Mismatch(_)
        | GridError::InvalidParameter { .. } => Kind::InvalidInput,
        _ => Kind::Volume,
    }
}

fn solve_kind(e: &SolveError) -> Kind {
    match e {
        SolveError::Unsupported { .. } => Kind::Unsupported,
        SolveError::InvalidParameter { .. }
        | SolveError::UnknownSolver { .. }
        | SolveError::Unstable { .. }
        | SolveError::Problem(_) => Kind::InvalidInput,
        SolveError::OverBudget { .. } => Kind::OverBudget,
        SolveError::Device { .. } => Kind::Device,
        SolveError::Grid(g) => grid_kind(g),
        SolveError::NonFiniteOutput { .. } | SolveError::TooMuchWork { .. } => Kind::Solve,
        SolveError::Storage { .. } => Kind::Io,
        SolveError::Halted { .. } => Kind::Solve,
    }
}

/// Any error of the facade as its Python exception.
pub(crate) fn from_lucent(e: lucent::Error) -> PyErr {
    use lucent::Error as E;
    let kind = match &e {
        E::Io { .. } | E::Output { .. } => Kind::Io,
        E::Scene { .. } => Kind::Scene,
        E::Invalid(_) | E::Usage(_) | E::Problem(_) | E::Optics(_) => Kind::InvalidInput,
        E::Grid(g) => grid_kind(g),
        E::Solve(s) => solve_kind(s),
        E::Render(r) => match r {
            lucent::render::RenderError::Device { .. } => Kind::Device,
            lucent::render::RenderError::Write { .. } => Kind::Io,
            _ => Kind::InvalidInput,
        },
        E::Unconverged { .. } => Kind::Solve,
        E::PagedBudget { .. } | E::OverBudget(_) => Kind::OverBudget,
    };
    raise(kind, e.to_string())
}

/// A solver's error as its Python exception.
pub(crate) fn from_solve(e: SolveError) -> PyErr {
    raise(solve_kind(&e), e.to_string())
}

/// A reader's error as its Python exception.
pub(crate) fn from_grid(e: GridError) -> PyErr {
    raise(grid_kind(&e), e.to_string())
}
