//! The discrete diffusion system of a problem, for comparing lucent's multigrid with other
//! solvers (pyamg, scipy) on the same matrix.

use std::sync::Mutex;

use lucent::core::{SolveOptions, Solver, Stopping};
use lucent::diffusion::{DiffusionProblem, DiffusionSolver, Method, MultigridSettings, Sources};
use pyo3::prelude::*;

use crate::arrays::array_f64;
use crate::errors::{from_solve, invalid};
use crate::scene::PyProblem;

/// A CSR matrix as numpy arrays: (data, indices, indptr, shape).
type Csr<'py> = (
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
    (usize, usize),
);

/// One channel's steady diffusion system A φ = b over the cells of the medium, as
/// `diffusion-mg` discretises it (embedded boundary, Robin/Dirichlet/Neumann faces,
/// first-collision and point sources; the point sources' analytic singular parts are
/// not in it). `matrix()` gives A as CSR arrays; `solve_multigrid()` runs lucent's
/// multigrid on the same discrete problem.
#[pyclass(name = "DiffusionSystem", module = "lucent", frozen)]
pub(crate) struct PyDiffusionSystem {
    problem: DiffusionProblem,
    sources: Sources,
    /// A, b and the cell of each unknown, assembled once.
    system: lucent::diffusion::AssembledSystem,
    dims: [usize; 3],
}

#[pymethods]
impl PyDiffusionSystem {
    /// The problem's system for `channel` (0, or 0–2 for RGB).
    #[new]
    #[pyo3(signature = (problem, channel=0))]
    fn new(py: Python<'_>, problem: &Bound<'_, PyProblem>, channel: usize) -> PyResult<Self> {
        let problem = problem.get().problem.clone();
        if channel >= problem.channels() {
            return Err(invalid(
                "channel",
                format!("{channel}: the problem has {}", problem.channels()),
            ));
        }
        let captured: Mutex<Vec<(DiffusionProblem, Sources)>> = Mutex::new(Vec::new());
        let solver = DiffusionSolver::custom("diffusion-system");
        solver.admits(&problem).map_err(from_solve)?;
        py.detach(|| {
            solver.solve_with(
                &problem,
                &SolveOptions::default(),
                0,
                &|diffusion: &DiffusionProblem, sources: &Sources, stopping: &Stopping| {
                    if let Ok(mut c) = captured.lock() {
                        c.push((diffusion.clone(), sources.clone()));
                    }
                    // One sweep is enough: only the system is wanted.
                    let one = Stopping {
                        max_iterations: 1,
                        ..stopping.clone()
                    };
                    lucent::diffusion::solve(
                        diffusion,
                        sources,
                        Method::Multigrid(MultigridSettings::default()),
                        &one,
                    )
                },
            )
        })
        .map_err(from_solve)?;
        let mut systems = captured
            .into_inner()
            .map_err(|_| pyo3::exceptions::PyRuntimeError::new_err("poisoned"))?;
        if channel >= systems.len() {
            return Err(invalid("channel", "no system for this channel"));
        }
        let (problem_c, sources) = systems.swap_remove(channel);
        let system = problem_c
            .assemble(&sources)
            .map_err(|e| invalid("problem", e))?;
        Ok(Self {
            problem: problem_c,
            sources,
            system,
            dims: problem.geometry().dims(),
        })
    }

    /// A as CSR: (data float64, indices int64, indptr int64, (n, n)); with scipy,
    /// `scipy.sparse.csr_matrix((data, indices, indptr), shape=shape)`.
    fn matrix<'py>(&self, py: Python<'py>) -> PyResult<Csr<'py>> {
        let system = &self.system;
        let m = &system.matrix;
        let n = system.rhs.len();
        let indices: Vec<i64> = m.indices().iter().map(|&i| i as i64).collect();
        let indptr: Vec<i64> = m.indptr().raw_storage().iter().map(|&i| i as i64).collect();
        Ok((
            array_f64(py, m.data().to_vec()),
            numpy::PyArray1::from_vec(py, indices).into_any(),
            numpy::PyArray1::from_vec(py, indptr).into_any(),
            (n, n),
        ))
    }

    /// b, float64, one entry per unknown.
    fn rhs<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let system = &self.system;
        Ok(array_f64(py, system.rhs.clone()))
    }

    /// The flat grid cell (x fastest) of each unknown, int64.
    fn cells<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let system = &self.system;
        let cells: Vec<i64> = system.cells.iter().map(|&c| c as i64).collect();
        Ok(numpy::PyArray1::from_vec(py, cells).into_any())
    }

    /// Cells per axis of the grid, (n_x, n_y, n_z).
    #[getter]
    fn dims(&self) -> (usize, usize, usize) {
        (self.dims[0], self.dims[1], self.dims[2])
    }

    /// lucent's multigrid (`diffusion-mg`'s defaults: V-cycles, red-black Gauss–Seidel,
    /// full multigrid) on this system to relative residual `rtol`: (φ per unknown as
    /// float64, in `cells()` order; cycles; seconds).
    #[pyo3(signature = (rtol=1e-8, max_cycles=200))]
    fn solve_multigrid<'py>(
        &self,
        py: Python<'py>,
        rtol: f64,
        max_cycles: usize,
    ) -> PyResult<(Bound<'py, PyAny>, usize, f64)> {
        let stopping = Stopping {
            relative_tolerance: rtol,
            max_iterations: max_cycles,
            ..Stopping::from_options(&SolveOptions::default())
        };
        let start = std::time::Instant::now();
        let solution = py
            .detach(|| {
                lucent::diffusion::solve(
                    &self.problem,
                    &self.sources,
                    Method::Multigrid(MultigridSettings::default()),
                    &stopping,
                )
            })
            .map_err(|e| invalid("problem", e))?;
        let seconds = start.elapsed().as_secs_f64();
        let system = &self.system;
        let phi: Vec<f64> = system.cells.iter().map(|&c| solution.fluence[c]).collect();
        Ok((
            array_f64(py, phi),
            solution.convergence.residuals.len(),
            seconds,
        ))
    }
}
