//! Solvers by name: the registry the command line, the scene files and the cross-check
//! harness build solvers from.

use std::collections::BTreeMap;

use serde::de::DeserializeOwned;
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

/// A solver's parameters as one typed struct: serde reads them from a scene's
/// `[solver.params]` (the struct says `#[serde(default, deny_unknown_fields)]`, its enums
/// `rename_all = "kebab-case"`), `Default` gives the defaults, and [`SolverParams::MEANINGS`]
/// says what each one means, for `lucent solvers`.
pub trait SolverParams: Serialize + DeserializeOwned + Default {
    /// Every parameter's key and meaning (with its allowed values and unit).
    const MEANINGS: &'static [(&'static str, &'static str)];

    /// Checks what serde cannot express (ranges); the error names the parameter.
    fn validate(&self) -> Result<(), SolveError> {
        Ok(())
    }
}

/// One parameter of a solver, as `lucent solvers` prints it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct ParamDoc {
    /// The key in a scene's `[solver.params]`.
    pub name: String,
    /// Its default, as TOML would write it (`none`: unset).
    pub default: String,
    /// What it means (empty when the solver's docs miss it: a test forbids that).
    pub meaning: &'static str,
}

/// The parameters of `T` with their defaults and meanings: every key the default
/// serialises to, in the order of [`SolverParams::MEANINGS`], then any it misses.
pub fn param_docs<T: SolverParams>() -> Vec<ParamDoc> {
    let defaults = match serde_json::to_value(T::default()) {
        Ok(serde_json::Value::Object(map)) => map,
        _ => serde_json::Map::new(),
    };
    let show = |v: Option<&serde_json::Value>| match v {
        None | Some(serde_json::Value::Null) => "none".to_owned(),
        Some(v) => v.to_string(),
    };
    let mut docs: Vec<ParamDoc> = T::MEANINGS
        .iter()
        .map(|(name, meaning)| ParamDoc {
            name: (*name).to_owned(),
            default: show(defaults.get(*name)),
            meaning,
        })
        .collect();
    for (name, value) in &defaults {
        if !T::MEANINGS.iter().any(|(n, _)| n == name) {
            docs.push(ParamDoc {
                name: name.clone(),
                default: show(Some(value)),
                meaning: "",
            });
        }
    }
    docs
}

/// The parameters `params` give `T`, every default filled in, as JSON: what a solver
/// built from `params` runs with (a report records this, not what was written).
pub fn resolved_params<T: SolverParams>(
    params: &Params,
    solver: &str,
) -> Result<serde_json::Value, SolveError> {
    let typed: T = params.parse(solver)?;
    serde_json::to_value(typed).map_err(|e| SolveError::InvalidParameter {
        name: "parameters".into(),
        reason: e.to_string(),
    })
}

impl ParamValue {
    fn to_json(&self) -> serde_json::Value {
        match self {
            ParamValue::Bool(b) => serde_json::Value::Bool(*b),
            ParamValue::Int(i) => serde_json::Value::from(*i),
            ParamValue::Float(f) => serde_json::Value::from(*f),
            ParamValue::Text(t) => serde_json::Value::String(t.clone()),
        }
    }
}

impl Params {
    /// The typed parameters of `solver`: unknown keys, ill-typed values and values out of
    /// range are an [`SolveError::InvalidParameter`] naming the solver, the key and what
    /// is allowed (serde's "expected one of ...").
    pub fn parse<T: SolverParams>(&self, solver: &str) -> Result<T, SolveError> {
        // JSON has no NaN or infinity: serde_json turns them into null, which an optional
        // parameter reads as "unset". A number that is not finite means nothing here.
        let not_finite = self.0.iter().find_map(|(key, value)| match value {
            ParamValue::Float(f) if !f.is_finite() => Some((key, *f)),
            _ => None,
        });
        if let Some((key, f)) = not_finite {
            return Err(SolveError::InvalidParameter {
                name: key.clone(),
                reason: format!("{f:?} is not a finite number (solver `{solver}`)"),
            });
        }
        let as_object = |keys: &mut dyn Iterator<Item = (&String, &ParamValue)>| {
            serde_json::Value::Object(keys.map(|(k, v)| (k.clone(), v.to_json())).collect())
        };
        match serde_json::from_value::<T>(as_object(&mut self.0.iter())) {
            Ok(typed) => {
                typed.validate().map_err(|e| match e {
                    SolveError::InvalidParameter { name, reason } => SolveError::InvalidParameter {
                        name,
                        reason: format!("{reason} (solver `{solver}`)"),
                    },
                    other => other,
                })?;
                Ok(typed)
            }
            Err(error) => {
                // Name the key: the first that fails on its own.
                let key = self
                    .0
                    .iter()
                    .find(|(k, v)| {
                        serde_json::from_value::<T>(as_object(&mut std::iter::once((*k, *v))))
                            .is_err()
                    })
                    .map_or_else(|| "parameters".to_owned(), |(k, _)| k.clone());
                Err(SolveError::InvalidParameter {
                    name: key,
                    reason: format!("{error} (solver `{solver}`)"),
                })
            }
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
    /// Its parameters with their defaults and meanings ([`param_docs`] of its
    /// [`SolverParams`]).
    pub params: fn() -> Vec<ParamDoc>,
    /// The parameters it runs with when built from these, defaults filled in
    /// ([`resolved_params`] of its [`SolverParams`]).
    pub resolved: fn(&Params) -> Result<serde_json::Value, SolveError>,
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

    /// A registry holding the solvers of this crate (`direct`, `direct-refractive`).
    pub fn with_core_solvers() -> Self {
        let mut registry = Self::new();
        registry.register(crate::direct::DirectSolver::ENTRY);
        registry.register(crate::refractive::DirectRefractiveSolver::ENTRY);
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
        (self.entry(name)?.build)(params)
    }

    /// The entry of the solver called `name`.
    pub fn entry(&self, name: &str) -> Result<&SolverEntry, SolveError> {
        self.entries
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
            })
    }
}
