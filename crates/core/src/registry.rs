//! Solvers by name: the registry the command line, the scene files and the cross-check
//! harness build solvers from.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::error::SolveError;
use crate::solver::Solver;

/// A solver parameter as written in a scene file or on the command line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ParamValue {
    /// `true` / `false`.
    Bool(bool),
    /// An integer.
    Int(i64),
    /// A number.
    Float(f64),
    /// Text.
    Text(String),
}

/// Named solver parameters.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Params(pub BTreeMap<String, ParamValue>);

impl Params {
    /// Refuses names not in `known`, so that a typo is an error rather than a silent default.
    pub fn check_known(&self, solver: &str, known: &[&str]) -> Result<(), SolveError> {
        match self.0.keys().find(|k| !known.contains(&k.as_str())) {
            Some(k) => Err(SolveError::InvalidParameter {
                name: k.clone(),
                reason: format!(
                    "`{solver}` takes {}",
                    if known.is_empty() {
                        "no parameters".to_owned()
                    } else {
                        known.join(", ")
                    }
                ),
            }),
            None => Ok(()),
        }
    }

    /// A number, or `default` when absent.
    pub fn f64_or(&self, name: &str, default: f64) -> Result<f64, SolveError> {
        match self.0.get(name) {
            None => Ok(default),
            Some(ParamValue::Float(v)) => Ok(*v),
            Some(ParamValue::Int(v)) => Ok(*v as f64),
            Some(other) => Err(SolveError::InvalidParameter {
                name: name.into(),
                reason: format!("expected a number, got {other:?}"),
            }),
        }
    }

    /// A non-negative integer, or `default` when absent.
    pub fn usize_or(&self, name: &str, default: usize) -> Result<usize, SolveError> {
        match self.0.get(name) {
            None => Ok(default),
            Some(ParamValue::Int(v)) if *v >= 0 => Ok(*v as usize),
            Some(other) => Err(SolveError::InvalidParameter {
                name: name.into(),
                reason: format!("expected a non-negative integer, got {other:?}"),
            }),
        }
    }
}

/// How to build one solver.
#[derive(Debug, Clone, Copy)]
pub struct SolverEntry {
    /// Registry name.
    pub name: &'static str,
    /// One line on what it solves.
    pub summary: &'static str,
    /// Builds it from parameters.
    pub build: fn(&Params) -> Result<Box<dyn Solver>, SolveError>,
}

/// The solvers known by name.
#[derive(Debug, Clone, Default)]
pub struct Registry {
    entries: Vec<SolverEntry>,
}

impl Registry {
    /// An empty registry.
    pub fn new() -> Self {
        Self::default()
    }

    /// A registry holding the solvers of this crate (`direct`).
    pub fn with_core_solvers() -> Self {
        let mut registry = Self::new();
        registry.register(crate::direct::DirectSolver::ENTRY);
        registry
    }

    /// Adds (or replaces) a solver.
    pub fn register(&mut self, entry: SolverEntry) {
        self.entries.retain(|e| e.name != entry.name);
        self.entries.push(entry);
    }

    /// Every entry, in registration order.
    pub fn entries(&self) -> &[SolverEntry] {
        &self.entries
    }

    /// Builds the solver called `name` with `params`.
    pub fn build(&self, name: &str, params: &Params) -> Result<Box<dyn Solver>, SolveError> {
        let entry = self
            .entries
            .iter()
            .find(|e| e.name == name)
            .ok_or_else(|| SolveError::UnknownSolver {
                name: name.to_owned(),
                available: self
                    .entries
                    .iter()
                    .map(|e| e.name)
                    .collect::<Vec<_>>()
                    .join(", "),
            })?;
        (entry.build)(params)
    }
}
