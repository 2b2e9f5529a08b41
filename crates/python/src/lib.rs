//! # lucent for Python: `import lucent`
//!
//! Bindings of the lucent workspace (pyo3, abi3 wheels for CPython ≥ 3.9, built with
//! maturin) for numerical studies in notebooks next to numpy, scipy, pyamg and Mitsuba:
//!
//! - scenes from TOML files, TOML text or dicts (`Scene`), problems from numpy arrays
//!   with their geometry (`Problem`);
//! - every registered solver by name with its typed parameters as keyword arguments
//!   (`solve`, `Solver`, `solvers`), the fluence as numpy arrays and the report as a dict;
//! - the volume readers (`read_volume`, `read_raw`, `read_vdb`) with their geometry;
//! - the explicit schemes' stability bounds and `lucent-optics`' analytic references,
//!   vectorised over numpy arrays (`lucent.stability`, `lucent.analytic`);
//! - the renderer (`render`), and the diffusion system as CSR arrays
//!   (`DiffusionSystem`) for other solvers of the same matrix.
//!
//! **Layout.** A grid is the array `a[z, y, x]`, shape (n_z, n_y, n_x), the layout of
//! lucent's grids (x fastest) and `.npy` files; channels stack in front. Inputs are read
//! by index, whatever their memory layout (C, Fortran, transposed, strided, broadcast):
//! a C-contiguous array is copied as it lies, any other in its logical order. Each input
//! array may take an eighth of the call's `memory_budget` (default 8 GiB), checked
//! before it is copied. Units are the scene's length unit and W.
//!
//! **Errors** are Python exceptions carrying lucent's messages (`lucent._errors`): bad
//! arrays, parameters and values are `ValueError`s naming the argument.
//!
//! **The GIL and Ctrl-C.** A solve runs on a worker thread with the GIL released; the
//! calling thread checks for signals every 50 ms, and Ctrl-C stops the solve at its next
//! iteration with what it computed (stop reason `interrupted`, as the command line does),
//! never killing the process. Another Python thread stops a solve through a `Cancel`
//! token.
//!
//! The results are the Rust API's bit for bit: the same code runs on the same values
//! (`tests/test_lucent.py` checks it against `lucent solve`).

mod arrays;
mod diffusion;
mod errors;
mod io;
mod numerics;
mod render;
mod scene;
mod solve;
mod values;

use pyo3::prelude::*;

/// The compiled part of the `lucent` package.
#[pymodule]
fn _lucent(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // `RAYON_NUM_THREADS` beyond what a solve may ask for is capped (a pool of 100 000
    // threads never finished starting), as by the `lucent` command.
    if let Some(note) = lucent::cap_global_threads() {
        let warnings = PyModule::import(m.py(), "warnings")?;
        warnings.call_method1("warn", (format!("lucent: {note}"),))?;
    }
    m.add_class::<scene::PyScene>()?;
    m.add_class::<scene::PyProblem>()?;
    m.add_class::<solve::PySolver>()?;
    m.add_class::<solve::PySolution>()?;
    m.add_class::<solve::PyCancel>()?;
    m.add_class::<io::PyVolume>()?;
    m.add_class::<render::PyRendering>()?;
    m.add_class::<diffusion::PyDiffusionSystem>()?;
    m.add_function(wrap_pyfunction!(solve::solve, m)?)?;
    m.add_function(wrap_pyfunction!(solve::solvers, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_volume, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_raw, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_vdb, m)?)?;
    m.add_function(wrap_pyfunction!(io::write_volume, m)?)?;
    m.add_function(wrap_pyfunction!(render::render, m)?)?;
    m.add_function(wrap_pyfunction!(numerics::_evaluate, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
