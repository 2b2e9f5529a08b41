//! Solvers by name, solves that release the GIL and stop cleanly on Ctrl-C or a
//! cancellation token, and their results as numpy arrays and a dict.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

use lucent::core::{Params, Problem, Progress, SolveOptions, Solver};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays::{array_f64, grid_array};
use crate::errors::{from_solve, invalid};
use crate::scene::{PyProblem, PyScene};
use crate::values::{json_to_py, params_from};

/// A flag that stops a running solve at its next iteration, batch or march: set it from
/// another thread (`cancel.set()`), and the solve returns what it computed with the stop
/// reason `interrupted`.
#[pyclass(name = "Cancel", module = "lucent", frozen)]
pub(crate) struct PyCancel {
    pub(crate) flag: Arc<AtomicBool>,
}

#[pymethods]
impl PyCancel {
    #[new]
    fn new() -> Self {
        Self {
            flag: Arc::new(AtomicBool::new(false)),
        }
    }

    /// Asks every solve holding this token to stop.
    fn set(&self) {
        self.flag.store(true, Ordering::SeqCst);
    }

    /// Whether it has been set.
    #[getter]
    fn is_set(&self) -> bool {
        self.flag.load(Ordering::SeqCst)
    }

    /// Clears it, for the next solve.
    fn clear(&self) {
        self.flag.store(false, Ordering::SeqCst);
    }

    fn __repr__(&self) -> String {
        format!("Cancel(is_set={})", self.is_set())
    }
}

/// How often a waiting solve looks for Ctrl-C (Python delivers signals to the main
/// thread only between bytecodes, so the wait checks them itself).
const SIGNAL_POLL: Duration = Duration::from_millis(50);

/// Runs `work` on a worker thread without the GIL, checking for Ctrl-C every
/// [`SIGNAL_POLL`]: a `KeyboardInterrupt` sets `cancel` (the work stops at its next
/// iteration with what it has) and is swallowed, so the caller gets the partial result.
pub(crate) fn run_interruptible<T: Send>(
    py: Python<'_>,
    cancel: &Arc<AtomicBool>,
    work: impl FnOnce() -> T + Send,
) -> PyResult<T> {
    // The worker's result, and a condition variable that wakes the waiting thread.
    let slot: (Mutex<Option<std::thread::Result<T>>>, Condvar) = (Mutex::new(None), Condvar::new());
    let take = |wait: Option<Duration>| {
        let (lock, ready) = &slot;
        let mut guard = lock.lock().unwrap_or_else(|e| e.into_inner());
        match wait {
            Some(timeout) if guard.is_none() => {
                guard = ready
                    .wait_timeout(guard, timeout)
                    .unwrap_or_else(|e| e.into_inner())
                    .0;
            }
            None => {
                while guard.is_none() {
                    guard = ready.wait(guard).unwrap_or_else(|e| e.into_inner());
                }
            }
            _ => {}
        }
        guard.take()
    };
    std::thread::scope(|scope| {
        scope.spawn(|| {
            let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(work));
            let (lock, ready) = &slot;
            *lock.lock().unwrap_or_else(|e| e.into_inner()) = Some(result);
            ready.notify_all();
        });
        let finished = |result: std::thread::Result<T>| {
            result.map_err(|_| {
                pyo3::exceptions::PyRuntimeError::new_err("the solve's worker thread panicked")
            })
        };
        loop {
            if let Some(result) = py.detach(|| take(Some(SIGNAL_POLL))) {
                return finished(result);
            }
            if let Err(e) = py.check_signals() {
                // Ctrl-C: stop at the next iteration and return what was computed. Any
                // other signal handler's exception: stop, then raise it.
                cancel.store(true, Ordering::SeqCst);
                if !e.is_instance_of::<pyo3::exceptions::PyKeyboardInterrupt>(py) {
                    let _ = py.detach(|| take(None));
                    return Err(e);
                }
            }
        }
    })
}

/// The options of one solve, from Python's keyword arguments.
pub(crate) struct Options {
    pub(crate) rtol: Option<f64>,
    pub(crate) atol: f64,
    pub(crate) max_iterations: usize,
    pub(crate) time_limit: Option<f64>,
    pub(crate) threads: Option<usize>,
    pub(crate) memory_budget: Option<u64>,
    pub(crate) cancel: Option<Py<PyCancel>>,
    pub(crate) progress: Option<Py<PyAny>>,
}

impl Options {
    /// `SolveOptions` with `default_rtol` where `rtol` is unset, a cancellation flag (the
    /// caller's token or a fresh one) and a progress callback that calls Python. A
    /// callback's exception cancels the solve and is kept in `failure` to raise after.
    pub(crate) fn solve_options(
        &self,
        default_rtol: f64,
        failure: &Arc<Mutex<Option<PyErr>>>,
    ) -> PyResult<SolveOptions> {
        let time_budget = match self.time_limit {
            None => None,
            Some(t) if t > 0.0 && t.is_finite() && t < 1e9 => Some(Duration::from_secs_f64(t)),
            Some(t) => {
                return Err(invalid(
                    "time_limit",
                    format!("{t}: a positive number of seconds"),
                ));
            }
        };
        let cancel = match &self.cancel {
            Some(token) => token.get().flag.clone(),
            None => Arc::new(AtomicBool::new(false)),
        };
        let progress = self.progress.as_ref().map(|callback| {
            let callback = Python::attach(|py| callback.clone_ref(py));
            let failure = failure.clone();
            let cancel = cancel.clone();
            Arc::new(move |p: Progress| {
                Python::attach(|py| {
                    let result = callback.call1(py, (p.stage, p.fraction, p.iteration, p.residual));
                    if let Err(e) = result
                        && let Ok(mut slot) = failure.lock()
                    {
                        slot.get_or_insert(e);
                        cancel.store(true, Ordering::SeqCst);
                    }
                });
            }) as lucent::core::ProgressFn
        });
        let options = SolveOptions {
            relative_tolerance: self.rtol.unwrap_or(default_rtol),
            absolute_tolerance: self.atol,
            max_iterations: self.max_iterations,
            time_budget,
            threads: self.threads,
            memory_budget: self
                .memory_budget
                .unwrap_or(lucent::scene::SCENE_MEMORY_BUDGET),
            progress,
            cancel: Some(cancel),
            ranks: None,
        };
        options.validate().map_err(from_solve)?;
        Ok(options)
    }
}

/// A solver from the registry, built with its typed parameters.
#[pyclass(name = "Solver", module = "lucent", frozen)]
pub(crate) struct PySolver {
    pub(crate) solver: Arc<dyn Solver>,
    pub(crate) resolved: serde_json::Value,
}

impl PySolver {
    pub(crate) fn build(name: &str, params: Params) -> PyResult<Self> {
        let registry = lucent::registry();
        let entry = registry.entry(name).map_err(from_solve)?;
        let solver: Arc<dyn Solver> = Arc::from((entry.build)(&params).map_err(from_solve)?);
        let resolved = (entry.resolved)(&params).map_err(from_solve)?;
        Ok(Self { solver, resolved })
    }

    /// Solves `problem` with the GIL released, interruptible.
    pub(crate) fn run(
        &self,
        py: Python<'_>,
        problem: &Problem,
        options: &Options,
        default_rtol: f64,
    ) -> PyResult<PySolution> {
        let failure = Arc::new(Mutex::new(None));
        let solve_options = options.solve_options(default_rtol, &failure)?;
        let cancel = solve_options
            .cancel
            .clone()
            .unwrap_or_else(|| Arc::new(AtomicBool::new(false)));
        let solver = &*self.solver;
        let result = run_interruptible(py, &cancel, || solver.solve(problem, &solve_options));
        drop(solve_options);
        if let Some(e) = failure.lock().ok().and_then(|mut f| f.take()) {
            return Err(e);
        }
        let solution = result?.map_err(from_solve)?;
        Ok(PySolution {
            solution,
            dims: problem.geometry().dims(),
            spacing: problem.geometry().spacing().into(),
            origin: problem.geometry().origin().into(),
            params: self.resolved.clone(),
            problem: problem.fingerprint(),
        })
    }
}

#[pymethods]
impl PySolver {
    /// The solver called `name` (`lucent.solvers()` lists them) with its parameters as
    /// keyword arguments, or as the dict `params` (for names that are not identifiers).
    #[new]
    #[pyo3(signature = (name, params=None, **kwargs))]
    fn new(
        name: &str,
        params: Option<&Bound<'_, PyDict>>,
        kwargs: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let mut typed = Params::default();
        params_from(params, &mut typed)?;
        params_from(kwargs, &mut typed)?;
        Self::build(name, typed)
    }

    /// The registry name.
    #[getter]
    fn name(&self) -> &str {
        self.solver.name()
    }

    /// Every parameter it runs with, defaults filled in.
    #[getter]
    fn params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.resolved)
    }

    /// What problems it handles (boundaries, lights, anisotropy, ...).
    fn capabilities<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let json = serde_json::to_value(self.solver.capabilities())
            .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))?;
        json_to_py(py, &json)
    }

    /// Raises `UnsupportedError` (with the reason) unless it can solve `problem`.
    fn check(&self, problem: &Bound<'_, PyAny>) -> PyResult<()> {
        let problem = problem_of(problem)?;
        self.solver.admits(&problem.problem).map_err(from_solve)
    }

    /// Solves `problem` (a `Problem`, or a `Scene` whose problem is built first).
    /// `rtol` is the relative residual to stop at (default the scene's tolerance, else
    /// 1e-6); `time_limit` in seconds; `cancel` a `Cancel` token another thread may set;
    /// `progress(stage, fraction, iteration, residual)` is called as it advances.
    /// Ctrl-C stops the solve at its next iteration: the result holds what was computed
    /// and says `interrupted`.
    #[pyo3(signature = (problem, *, rtol=None, atol=0.0, max_iterations=10_000, time_limit=None, threads=None, memory_budget=None, cancel=None, progress=None))]
    #[allow(clippy::too_many_arguments)]
    fn solve(
        &self,
        py: Python<'_>,
        problem: &Bound<'_, PyAny>,
        rtol: Option<f64>,
        atol: f64,
        max_iterations: usize,
        time_limit: Option<f64>,
        threads: Option<usize>,
        memory_budget: Option<u64>,
        cancel: Option<Py<PyCancel>>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<PySolution> {
        let options = Options {
            rtol,
            atol,
            max_iterations,
            time_limit,
            threads,
            memory_budget,
            cancel,
            progress,
        };
        let (problem, default_rtol) = problem_and_tolerance(py, problem, options.memory_budget)?;
        self.run(py, &problem, &options, default_rtol)
    }

    fn __repr__(&self) -> String {
        format!("Solver({:?}, params={})", self.solver.name(), self.resolved)
    }
}

/// A `Problem` argument, or a `Scene`'s built problem.
fn problem_of(obj: &Bound<'_, PyAny>) -> PyResult<PyProblem> {
    problem_and_tolerance(obj.py(), obj, None).map(|(problem, _)| PyProblem {
        problem,
        volume: None,
    })
}

/// The problem to solve and the default relative tolerance: a scene's own (else 1e-6).
pub(crate) fn problem_and_tolerance(
    py: Python<'_>,
    obj: &Bound<'_, PyAny>,
    budget: Option<u64>,
) -> PyResult<(Arc<Problem>, f64)> {
    let default = SolveOptions::default().relative_tolerance;
    if let Ok(p) = obj.cast::<PyProblem>() {
        return Ok((p.get().problem.clone(), default));
    }
    if let Ok(s) = obj.cast::<PyScene>() {
        let scene = s.get();
        let budget = budget.unwrap_or(lucent::scene::SCENE_MEMORY_BUDGET);
        let built = py.detach(|| scene.build(budget))?;
        return Ok((
            Arc::new(built.problem),
            scene.scene.solver.tolerance.unwrap_or(default),
        ));
    }
    Err(invalid(
        "problem",
        format!(
            "a lucent.Problem or lucent.Scene, not {}",
            obj.get_type().name()?
        ),
    ))
}

/// A solve's result: the fluence per channel, its standard error (Monte Carlo), and the
/// report (why it stopped, the residual history, time and memory).
#[pyclass(name = "Solution", module = "lucent", frozen)]
pub(crate) struct PySolution {
    pub(crate) solution: lucent::core::Solution,
    dims: [usize; 3],
    spacing: (f64, f64, f64),
    origin: (f64, f64, f64),
    params: serde_json::Value,
    /// [`lucent::core::Problem::fingerprint`] of the problem it solves, so that
    /// `render(scene, solution=...)` can refuse the solution of another problem.
    pub(crate) problem: u64,
}

#[pymethods]
impl PySolution {
    /// The fluence φ = ∫ L dω (W/m² for lights in W), (channels, n_z, n_y, n_x),
    /// float32.
    #[getter]
    fn fluence<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        grid_array(
            py,
            self.dims,
            self.solution
                .fluence
                .iter()
                .map(|g| g.data().to_vec())
                .collect(),
            true,
        )
    }

    /// The fluence's per-cell standard error (Monte Carlo), like `fluence`; else `None`.
    #[getter]
    fn standard_error<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.solution
            .standard_error
            .as_ref()
            .map(|e| {
                grid_array(
                    py,
                    self.dims,
                    e.iter().map(|g| g.data().to_vec()).collect(),
                    true,
                )
            })
            .transpose()
    }

    /// The report as a dict: `solver`, `iterations`, `residual_history`, `wall_time_s`,
    /// `peak_memory_bytes` (the solver's estimate), `measured_peak_bytes`,
    /// `stop_reason` (`{"reason": "converged-relative", "residual": ...}`), `paging`,
    /// `choice` (`auto`, `hybrid`: one line), `composition` (the same as fields: the solver
    /// and parameters that ran, its parts, `auto`'s decision), and `params` (every
    /// parameter that ran).
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let mut json = serde_json::to_value(&self.solution.report)
            .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))?;
        if let Some(map) = json.as_object_mut() {
            map.insert("params".into(), self.params.clone());
        }
        json_to_py(py, &json)
    }

    /// Why it stopped, kebab-case: `exact`, `converged-relative`, `converged-absolute`,
    /// `sampled`, `iteration-limit`, `time-limit`, `interrupted`, `diverged-non-finite`,
    /// `diverged-growth`.
    #[getter]
    fn stop_reason(&self) -> String {
        serde_json::to_value(&self.solution.report.stop_reason)
            .ok()
            .and_then(|v| v.get("reason").and_then(|r| r.as_str().map(str::to_owned)))
            .unwrap_or_default()
    }

    /// Why it stopped, in words.
    #[getter]
    fn message(&self) -> String {
        self.solution.report.stop_reason.to_string()
    }

    /// Whether the result can be trusted (exact, converged, or every sample taken).
    #[getter]
    fn converged(&self) -> bool {
        self.solution.report.stop_reason.is_converged()
    }

    /// Whether it blew up (residual growth, NaN or infinity).
    #[getter]
    fn diverged(&self) -> bool {
        self.solution.report.stop_reason.is_diverged()
    }

    /// Whether Ctrl-C or a `Cancel` token stopped it.
    #[getter]
    fn interrupted(&self) -> bool {
        matches!(
            self.solution.report.stop_reason,
            lucent::core::StopReason::Interrupted { .. }
        )
    }

    /// Iterations run (0 for direct methods).
    #[getter]
    fn iterations(&self) -> usize {
        self.solution.report.iterations
    }

    /// The relative residual after each iteration (float64).
    #[getter]
    fn residual_history<'py>(&self, py: Python<'py>) -> Bound<'py, PyAny> {
        array_f64(py, self.solution.report.residual_history.clone())
    }

    /// Wall time of the solve, seconds.
    #[getter]
    fn wall_time_s(&self) -> f64 {
        self.solution.report.wall_time_s
    }

    /// The solver's memory estimate at peak, bytes.
    #[getter]
    fn peak_memory_bytes(&self) -> u64 {
        self.solution.report.peak_memory_bytes
    }

    /// Cell size (x, y, z) of the fluence grid.
    #[getter]
    fn spacing(&self) -> (f64, f64, f64) {
        self.spacing
    }

    /// The corner of cell (0, 0, 0).
    #[getter]
    fn origin(&self) -> (f64, f64, f64) {
        self.origin
    }

    fn __repr__(&self) -> String {
        let r = &self.solution.report;
        format!(
            "Solution(solver={:?}, channels={}, stop_reason={:?}, iterations={}, wall_time_s={:.3})",
            r.solver,
            self.solution.fluence.len(),
            self.stop_reason(),
            r.iterations,
            r.wall_time_s
        )
    }
}

/// Solves `problem` (a `Problem` or a `Scene`) with the solver called `solver` and its
/// parameters as keyword arguments. A scene without `solver` runs its own solver with its
/// own parameters and tolerance, as `lucent solve SCENE` does (the same bits); naming the
/// scene's solver keeps its parameters, with `params` and the keywords on top.
#[pyfunction]
#[pyo3(signature = (problem, solver=None, *, params=None, rtol=None, atol=0.0, max_iterations=10_000, time_limit=None, threads=None, memory_budget=None, cancel=None, progress=None, **kwargs))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn solve(
    py: Python<'_>,
    problem: &Bound<'_, PyAny>,
    solver: Option<&str>,
    params: Option<&Bound<'_, PyDict>>,
    rtol: Option<f64>,
    atol: f64,
    max_iterations: usize,
    time_limit: Option<f64>,
    threads: Option<usize>,
    memory_budget: Option<u64>,
    cancel: Option<Py<PyCancel>>,
    progress: Option<Py<PyAny>>,
    kwargs: Option<&Bound<'_, PyDict>>,
) -> PyResult<PySolution> {
    let scene = problem.cast::<PyScene>().ok().map(|s| s.get());
    let name = match (solver, scene) {
        (Some(name), _) => name.to_owned(),
        (None, Some(scene)) => scene.scene.solver.name.clone(),
        (None, None) => {
            return Err(invalid(
                "solver",
                "name a solver for a Problem (`lucent.solvers()` lists them)",
            ));
        }
    };
    let built = PySolver::build(&name, params_for(scene, &name, params, kwargs)?)?;
    let options = Options {
        rtol,
        atol,
        max_iterations,
        time_limit,
        threads,
        memory_budget,
        cancel,
        progress,
    };
    let (problem, default_rtol) = problem_and_tolerance(py, problem, options.memory_budget)?;
    built.run(py, &problem, &options, default_rtol)
}

/// The parameters `name` runs with, as the command line chooses them: the scene's
/// `[solver.params]` when `name` is the scene's own solver (else none), then `params`,
/// then the keywords.
pub(crate) fn params_for(
    scene: Option<&PyScene>,
    name: &str,
    params: Option<&Bound<'_, PyDict>>,
    kwargs: Option<&Bound<'_, PyDict>>,
) -> PyResult<Params> {
    let mut typed = match scene {
        Some(scene) if scene.scene.solver.name == name => scene.scene.solver.params.clone(),
        _ => Params::default(),
    };
    params_from(params, &mut typed)?;
    params_from(kwargs, &mut typed)?;
    Ok(typed)
}

/// Every registered solver: `name`, `summary`, `params` (name, default, meaning) and
/// `capabilities`.
#[pyfunction]
pub(crate) fn solvers(py: Python<'_>) -> PyResult<Vec<Bound<'_, PyAny>>> {
    lucent::registry()
        .entries()
        .iter()
        .map(|entry| {
            let solver = (entry.build)(&Params::default()).map_err(from_solve)?;
            let json = serde_json::json!({
                "name": entry.name,
                "summary": entry.summary,
                "params": (entry.params)(),
                "capabilities": solver.capabilities(),
            });
            json_to_py(py, &json)
        })
        .collect()
}
