//! What stops a solve from outside, wherever it is: the caller's cancel flag (Ctrl-C) and
//! the end of its time budget.
//!
//! The stopping rule ([`crate::Stopping`]) asks between iterations; an [`Interrupt`] is
//! asked inside them and before the first: by every loop that can run for more than about
//! 0.1 s (the uncollided light's rows, a sweep's directions, a paged pass's slabs, a batch
//! of particles, a device submission), so that a solve stops within a second of the
//! signal at any size. Asking costs an atomic load and, when a deadline is set, a read of
//! the monotonic clock (~20 ns): cheap enough per row of cells.
//!
//! Work stopped before anything usable exists (set-up: the uncollided light, a hierarchy,
//! an assembly) ends in [`SolveError::Halted`]; an iteration stopped part way returns what
//! its last whole iterate was, as the stopping rule does.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::error::SolveError;
use crate::solver::{SolveOptions, StopReason};

/// Why a solve was stopped from outside.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Halt {
    /// The caller's cancel flag (Ctrl-C).
    Interrupted,
    /// The time budget ran out.
    TimeLimit,
}

impl Halt {
    /// The stop reason of an iteration halted at `residual`.
    pub fn stop_reason(self, residual: f64) -> StopReason {
        match self {
            Halt::Interrupted => StopReason::Interrupted { residual },
            Halt::TimeLimit => StopReason::TimeLimit { residual },
        }
    }
}

impl std::fmt::Display for Halt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Halt::Interrupted => "was interrupted",
            Halt::TimeLimit => "reached its time limit",
        })
    }
}

/// The cancel flag and the deadline of one solve, to ask inside its loops.
#[derive(Debug, Clone, Default)]
pub struct Interrupt {
    cancel: Option<Arc<AtomicBool>>,
    deadline: Option<Instant>,
}

impl Interrupt {
    /// Never stops.
    pub fn never() -> Self {
        Self::default()
    }

    /// Stops when `cancel` is set or at `deadline`.
    pub fn new(cancel: Option<Arc<AtomicBool>>, deadline: Option<Instant>) -> Self {
        Self { cancel, deadline }
    }

    /// The interrupt of a solve starting now with `options`: their cancel flag, and the
    /// deadline their time budget sets from now.
    pub fn of(options: &SolveOptions) -> Self {
        Self::from_start(options, Instant::now())
    }

    /// The interrupt of a solve that started at `started` with `options`.
    pub fn from_start(options: &SolveOptions, started: Instant) -> Self {
        Self {
            cancel: options.cancel.clone(),
            deadline: options.time_budget.map(|t| {
                started
                    .checked_add(t)
                    .unwrap_or(started + Duration::from_secs(1 << 40))
            }),
        }
    }

    /// Why to stop now, if at all: the cancel flag first, then the deadline.
    #[inline]
    pub fn halt(&self) -> Option<Halt> {
        if self
            .cancel
            .as_ref()
            .is_some_and(|c| c.load(Ordering::Relaxed))
        {
            return Some(Halt::Interrupted);
        }
        if self.deadline.is_some_and(|d| Instant::now() >= d) {
            return Some(Halt::TimeLimit);
        }
        None
    }

    /// Whether to stop now.
    #[inline]
    pub fn halted(&self) -> bool {
        self.halt().is_some()
    }

    /// `Err(SolveError::Halted)` naming `solver` and what it was doing (`stage`) when the
    /// solve is to stop before any result exists.
    pub fn check(&self, solver: &str, stage: &str) -> Result<(), SolveError> {
        match self.halt() {
            None => Ok(()),
            Some(halt) => Err(SolveError::Halted {
                solver: solver.into(),
                stage: stage.into(),
                halt,
            }),
        }
    }

    /// Whether anything can stop this solve (a flag or a deadline is set).
    pub fn is_armed(&self) -> bool {
        self.cancel.is_some() || self.deadline.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_flag_comes_before_the_deadline_and_both_stop() {
        assert_eq!(Interrupt::never().halt(), None);
        let flag = Arc::new(AtomicBool::new(false));
        let past = Instant::now();
        let i = Interrupt::new(Some(flag.clone()), Some(past + Duration::from_secs(3600)));
        assert_eq!(i.halt(), None);
        flag.store(true, Ordering::Relaxed);
        assert_eq!(i.halt(), Some(Halt::Interrupted));
        let late = Interrupt::new(None, Some(past));
        assert_eq!(late.halt(), Some(Halt::TimeLimit));
        assert!(matches!(
            late.check("x", "set-up"),
            Err(SolveError::Halted {
                halt: Halt::TimeLimit,
                ..
            })
        ));
        let options = SolveOptions {
            time_budget: Some(Duration::MAX),
            ..SolveOptions::default()
        };
        assert_eq!(Interrupt::of(&options).halt(), None);
    }
}
