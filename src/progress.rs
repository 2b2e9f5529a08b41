//! What a person sees of a running job: the adapter between a solver's [`Progress`]
//! reports (or a renderer's fractions) and a progress bar.
//!
//! The bar shows a fraction and a line of text. The adapter keeps the promises a bar makes:
//! the fraction never goes back, and it shows 100 % only once the job has finished (the
//! solver's final [`Progress::DONE`] report, or [`Meter::finish`]); the text says what the
//! job is doing (`V-cycle 7, residual 3.0e-4`). The command line draws it with indicatif
//! and an elapsed-time tick; a test records it.

use std::sync::{Arc, Mutex, PoisonError};

use lucent_core::{Progress, ProgressFn};

/// What the bar shows.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Shown {
    /// Thousandths done: 0 to 999 while running, 1000 when finished.
    pub permille: u64,
    /// What the job is doing.
    pub message: String,
}

/// Where [`Shown`] states go (a bar, or a test's recorder).
pub type Display = Arc<dyn Fn(&Shown) + Send + Sync>;

/// The adapter for one job (one bar).
pub struct Meter {
    display: Display,
    shown: Mutex<u64>,
}

impl Meter {
    /// An adapter that hands what the bar should show to `display`.
    pub fn new(display: Display) -> Arc<Self> {
        Arc::new(Self {
            display,
            shown: Mutex::new(0),
        })
    }

    /// Shows `fraction` (kept monotone and below 100 % unless `finished`) with `message`.
    fn show(&self, fraction: f64, finished: bool, message: String) {
        let mut shown = self.shown.lock().unwrap_or_else(PoisonError::into_inner);
        let permille = if finished {
            1000
        } else if fraction.is_finite() {
            ((fraction.clamp(0.0, 1.0) * 1000.0) as u64).min(999)
        } else {
            0
        };
        *shown = (*shown).max(permille);
        (self.display)(&Shown {
            permille: *shown,
            message,
        });
    }

    /// The callback for [`lucent_core::SolveOptions::progress`].
    pub fn solver_callback(self: &Arc<Self>) -> ProgressFn {
        let meter = Arc::clone(self);
        Arc::new(move |p: Progress| {
            let finished = p.stage == Progress::DONE && p.fraction >= 1.0;
            meter.show(p.fraction, finished, p.to_string());
        })
    }

    /// A callback for a job that reports a bare fraction (the renderer, camera paths),
    /// shown with `stage` as its text.
    pub fn fraction_callback(self: &Arc<Self>, stage: &'static str) -> impl Fn(f64) + Send + Sync {
        let meter = Arc::clone(self);
        move |fraction: f64| meter.show(fraction, false, stage.to_owned())
    }

    /// The job is done: 100 %.
    pub fn finish(&self) {
        self.show(1.0, true, Progress::DONE.to_owned());
    }
}
