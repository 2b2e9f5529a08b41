//! One vocabulary for iterative methods: when to stop ([`Stopping`]) and what happened
//! ([`History`]), used by every iterative solver in every crate, so that a tolerance, an
//! iteration limit, a time budget and a divergence test mean the same everywhere and end in
//! the same [`StopReason`] (PETSc's KSP converged and diverged reasons).
//!
//! The order of the tests is fixed: a non-finite residual first (diverged), then the
//! relative and the absolute tolerance (converged), then growth beyond `divergence` times
//! the initial residual (diverged), then the iteration limit, then the time budget, then
//! the caller's interruption.

use std::fmt;
use std::time::{Duration, Instant};

use crate::solver::{Progress, ProgressFn, SolveOptions, StopReason};

/// When an iterative method stops, and whom it tells how far it got.
#[derive(Clone)]
pub struct Stopping {
    /// Stop when the residual, relative to the method's reference (usually ‖b‖ or the first
    /// residual), falls to this.
    pub relative_tolerance: f64,
    /// Stop when the absolute residual falls to this.
    pub absolute_tolerance: f64,
    /// Stop after this many iterations.
    pub max_iterations: usize,
    /// Stop after this much wall time since the history started.
    pub time_budget: Option<Duration>,
    /// Stop as diverged when the relative residual grows beyond this many times
    /// max(initial relative residual, 1).
    pub divergence: f64,
    /// Called after every recorded iteration with the iteration, its residual and the
    /// fraction of the way from the initial residual to the tolerance (logarithmically).
    pub progress: Option<ProgressFn>,
    /// Stop as interrupted once this is set (the caller's [`SolveOptions::cancel`]).
    pub cancel: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
    /// Stop at this instant, whenever the history started: the end of the whole solve's
    /// time budget, which phases that start late (an iteration after a long set-up) must
    /// not push back. Set by [`crate::driver::Context::stopping_for`].
    pub deadline: Option<Instant>,
}

impl fmt::Debug for Stopping {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Stopping")
            .field("relative_tolerance", &self.relative_tolerance)
            .field("absolute_tolerance", &self.absolute_tolerance)
            .field("max_iterations", &self.max_iterations)
            .field("time_budget", &self.time_budget)
            .field("divergence", &self.divergence)
            .field("progress", &self.progress.as_ref().map(|_| "callback"))
            .field("cancel", &self.cancel)
            .field("deadline", &self.deadline)
            .finish()
    }
}

impl PartialEq for Stopping {
    /// Equal rules; callbacks are equal when they are the same callback.
    fn eq(&self, other: &Self) -> bool {
        self.relative_tolerance == other.relative_tolerance
            && self.absolute_tolerance == other.absolute_tolerance
            && self.max_iterations == other.max_iterations
            && self.time_budget == other.time_budget
            && self.deadline == other.deadline
            && self.divergence == other.divergence
            && match (&self.progress, &other.progress) {
                (None, None) => true,
                (Some(a), Some(b)) => std::sync::Arc::ptr_eq(a, b),
                _ => false,
            }
            && match (&self.cancel, &other.cancel) {
                (None, None) => true,
                (Some(a), Some(b)) => std::sync::Arc::ptr_eq(a, b),
                _ => false,
            }
    }
}

impl Default for Stopping {
    fn default() -> Self {
        Self {
            relative_tolerance: 1e-8,
            absolute_tolerance: 0.0,
            max_iterations: 200,
            time_budget: None,
            divergence: 1e6,
            progress: None,
            cancel: None,
            deadline: None,
        }
    }
}

impl Stopping {
    /// The stopping rule a caller's [`SolveOptions`] ask for (divergence at 10⁶).
    pub fn from_options(options: &SolveOptions) -> Self {
        Self {
            relative_tolerance: options.relative_tolerance,
            absolute_tolerance: options.absolute_tolerance,
            max_iterations: options.max_iterations,
            time_budget: options.time_budget,
            progress: options.progress.clone(),
            cancel: options.cancel.clone(),
            ..Self::default()
        }
    }

    /// The same rule, its progress reports naming `stage` (`source iteration`, `V-cycle`,
    /// `time step`) instead of `iteration`.
    pub fn with_stage(mut self, stage: &'static str) -> Self {
        if let Some(callback) = self.progress.take() {
            self.progress = Some(std::sync::Arc::new(move |p: Progress| {
                callback(Progress { stage, ..p })
            }));
        }
        self
    }

    /// The [`crate::Interrupt`] of an iteration under this rule that started at
    /// `started`: its cancel flag and the end of its time budget, for the loops inside an
    /// iteration (a sweep, a cycle) to ask.
    pub fn interrupt(&self, started: Instant) -> crate::Interrupt {
        crate::Interrupt::new(self.cancel.clone(), self.end(started))
    }

    /// When the time runs out for an iteration that started at `started`: the earlier of
    /// its budget's end and the solve's deadline.
    fn end(&self, started: Instant) -> Option<Instant> {
        let budget = self.time_budget.and_then(|t| started.checked_add(t));
        match (budget, self.deadline) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// The stops that differ from rank to rank, as of now: whether the time budget since
    /// `started` is spent, and whether the cancel flag is set. Decomposed solves reduce
    /// them with their norms (any rank's flag stops every rank, on the same iteration).
    pub fn local_flags(&self, started: Instant) -> [bool; 2] {
        [
            self.end(started).is_some_and(|end| Instant::now() >= end),
            self.cancel
                .as_ref()
                .is_some_and(|c| c.load(std::sync::atomic::Ordering::Relaxed)),
        ]
    }

    /// Tells the progress callback, if any, about `iteration` at `relative` residual from
    /// `initial`: the fraction is how far ln(relative) has come from ln(initial) toward
    /// ln(tolerance), or toward the iteration limit if that is nearer.
    fn report(&self, iteration: usize, relative: f64, initial: f64) {
        let Some(callback) = &self.progress else {
            return;
        };
        let by_residual = if relative > 0.0
            && initial > relative
            && self.relative_tolerance > 0.0
            && initial > self.relative_tolerance
        {
            ((initial / relative).ln() / (initial / self.relative_tolerance).ln()).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let by_count = iteration as f64 / self.max_iterations.max(1) as f64;
        callback(Progress {
            stage: "iteration",
            fraction: by_residual.max(by_count).min(1.0),
            iteration,
            residual: Some(relative),
        });
    }

    /// The verdict after `iteration` iterations at `relative` and `absolute` residual,
    /// `initial` being the relative residual the iteration started from; `None`: go on.
    /// Tells the progress callback first.
    pub fn verdict(
        &self,
        iteration: usize,
        relative: f64,
        absolute: f64,
        initial: f64,
        started: Instant,
    ) -> Option<StopReason> {
        self.report(iteration, relative, initial);
        if !(relative.is_finite() && absolute.is_finite()) {
            return Some(StopReason::DivergedNonFinite { iteration });
        }
        if relative <= self.relative_tolerance {
            return Some(StopReason::ConvergedRelative { residual: relative });
        }
        if absolute <= self.absolute_tolerance {
            return Some(StopReason::ConvergedAbsolute { residual: absolute });
        }
        if relative > self.divergence * initial.max(1.0) {
            return Some(StopReason::DivergedGrowth {
                growth: relative / initial.max(f64::MIN_POSITIVE),
                iteration,
            });
        }
        if iteration >= self.max_iterations {
            return Some(StopReason::IterationLimit { residual: relative });
        }
        if self.end(started).is_some_and(|end| Instant::now() >= end) {
            return Some(StopReason::TimeLimit { residual: relative });
        }
        if self
            .cancel
            .as_ref()
            .is_some_and(|c| c.load(std::sync::atomic::Ordering::Relaxed))
        {
            return Some(StopReason::Interrupted { residual: relative });
        }
        None
    }
}

/// The residual record of an iterative solve: the relative residual before the first
/// iteration and after each, and when it started.
#[derive(Debug, Clone, PartialEq)]
pub struct History {
    residuals: Vec<f64>,
    started: Instant,
}

impl Default for History {
    fn default() -> Self {
        Self::start()
    }
}

impl History {
    /// An empty history; the time budget counts from now.
    pub fn start() -> Self {
        Self {
            residuals: Vec::new(),
            started: Instant::now(),
        }
    }

    /// Records the residual after the next iteration (the first record is the initial
    /// residual, iteration 0) and says whether `stopping` stops here.
    pub fn record(
        &mut self,
        stopping: &Stopping,
        relative: f64,
        absolute: f64,
    ) -> Option<StopReason> {
        let iteration = self.residuals.len();
        self.residuals.push(relative);
        let initial = self.residuals[0];
        stopping.verdict(iteration, relative, absolute, initial, self.started)
    }

    /// Records the residual after `iteration` steps of a march that has no initial residual
    /// (the first record is after step 1) and says whether `stopping` stops here.
    pub fn record_step(
        &mut self,
        stopping: &Stopping,
        iteration: usize,
        relative: f64,
        absolute: f64,
    ) -> Option<StopReason> {
        self.residuals.push(relative);
        let initial = self.residuals[0];
        stopping.verdict(iteration, relative, absolute, initial, self.started)
    }

    /// Iterations recorded after the initial residual.
    pub fn iterations(&self) -> usize {
        self.residuals.len().saturating_sub(1)
    }

    /// The relative residuals recorded.
    pub fn residuals(&self) -> &[f64] {
        &self.residuals
    }

    /// The last relative residual (infinity before any).
    pub fn last(&self) -> f64 {
        self.residuals.last().copied().unwrap_or(f64::INFINITY)
    }

    /// When the history started.
    pub fn started(&self) -> Instant {
        self.started
    }

    /// The residuals, consumed.
    pub fn into_residuals(self) -> Vec<f64> {
        self.residuals
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tests_come_in_their_fixed_order() {
        let s = Stopping {
            relative_tolerance: 1e-3,
            absolute_tolerance: 1e-9,
            max_iterations: 3,
            time_budget: None,
            divergence: 100.0,
            progress: None,
            cancel: None,
            deadline: None,
        };
        let mut h = History::start();
        assert_eq!(h.record(&s, 1.0, 1.0), None);
        assert_eq!(h.record(&s, 0.5, 0.5), None);
        assert!(matches!(
            h.record(&s, f64::NAN, 1.0),
            Some(StopReason::DivergedNonFinite { iteration: 2 })
        ));
        let mut h = History::start();
        h.record(&s, 1.0, 1.0);
        assert!(matches!(
            h.record(&s, 1e-3, 1.0),
            Some(StopReason::ConvergedRelative { .. })
        ));
        let mut h = History::start();
        h.record(&s, 1.0, 1.0);
        assert!(matches!(
            h.record(&s, 0.9, 1e-10),
            Some(StopReason::ConvergedAbsolute { .. })
        ));
        let mut h = History::start();
        h.record(&s, 2.0, 1.0);
        assert!(matches!(
            h.record(&s, 201.0, 1.0),
            Some(StopReason::DivergedGrowth { .. })
        ));
        let mut h = History::start();
        for r in [1.0, 0.9, 0.8] {
            assert_eq!(h.record(&s, r, r), None);
        }
        assert!(matches!(
            h.record(&s, 0.7, 0.7),
            Some(StopReason::IterationLimit { .. })
        ));
        assert_eq!(h.iterations(), 3);
        let budget = Stopping {
            time_budget: Some(Duration::ZERO),
            max_iterations: 100,
            ..s.clone()
        };
        let mut h = History::start();
        assert!(matches!(
            h.record(&budget, 1.0, 1.0),
            Some(StopReason::TimeLimit { .. })
        ));
    }
}
