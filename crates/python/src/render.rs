//! The renderer: a scene's image as a numpy array.

use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use lucent::core::ImageRequest;
use lucent::render::{Image, ToneMap};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::arrays::array_f32;
use crate::errors::{from_lucent, from_solve, invalid};
use crate::scene::PyScene;
use crate::solve::{Options, PyCancel, PySolution, PySolver, params_for, run_interruptible};

/// A rendered image: linear RGB radiance (height, width, 3) float32, its per-pixel
/// standard error for solvers that trace camera paths (Monte Carlo), and the solution
/// the rays marched through (others). `numpy.asarray(rendering)` is the radiance.
#[pyclass(name = "Rendering", module = "lucent", frozen)]
pub(crate) struct PyRendering {
    image: Image,
    std_error: Option<Image>,
    solution: Option<Py<PySolution>>,
    exposure: f64,
    tone: ToneMap,
    /// Rows traced (the height unless interrupted).
    rows_traced: usize,
}

fn pixels<'py>(py: Python<'py>, image: &Image) -> PyResult<Bound<'py, PyAny>> {
    let flat: Vec<f32> = image.pixels.iter().flatten().copied().collect();
    array_f32(py, &[image.height, image.width, 3], flat)
}

fn tone_of(name: &str) -> PyResult<ToneMap> {
    Ok(match name {
        "aces" => ToneMap::Aces,
        "reinhard" => ToneMap::Reinhard,
        "clamp" => ToneMap::Clamp,
        other => {
            return Err(invalid(
                "tone",
                format!("`{other}`: aces, reinhard or clamp"),
            ));
        }
    })
}

#[pymethods]
impl PyRendering {
    /// Linear RGB radiance, (height, width, 3) float32.
    #[getter]
    fn radiance<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        pixels(py, &self.image)
    }

    /// The per-pixel standard error (Monte Carlo camera paths), else `None`.
    #[getter]
    fn std_error<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.std_error.as_ref().map(|e| pixels(py, e)).transpose()
    }

    /// The solution the camera rays marched through, else `None` (Monte Carlo).
    #[getter]
    fn solution(&self, py: Python<'_>) -> Option<Py<PySolution>> {
        self.solution.as_ref().map(|s| s.clone_ref(py))
    }

    /// Rows traced: the height unless the render was interrupted.
    #[getter]
    fn rows_traced(&self) -> usize {
        self.rows_traced
    }

    /// 8-bit sRGB (height, width, 3) after 2^`exposure` and the `tone` curve (`aces`,
    /// `reinhard`, `clamp`); defaults are the scene's, as `lucent render` writes a PNG.
    #[pyo3(signature = (exposure=None, tone=None))]
    fn srgb<'py>(
        &self,
        py: Python<'py>,
        exposure: Option<f64>,
        tone: Option<&str>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let tone = match tone {
            Some(t) => tone_of(t)?,
            None => self.tone,
        };
        let bytes = self.image.to_srgb8(exposure.unwrap_or(self.exposure), tone);
        let array =
            ndarray::Array3::from_shape_vec((self.image.height, self.image.width, 3), bytes)
                .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))?;
        Ok(numpy::IntoPyArray::into_pyarray(array, py).into_any())
    }

    #[pyo3(signature = (dtype=None, copy=None))]
    fn __array__<'py>(
        &self,
        py: Python<'py>,
        dtype: Option<Bound<'py, PyAny>>,
        copy: Option<bool>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let _ = copy;
        let array = pixels(py, &self.image)?;
        match dtype {
            Some(d) => array.call_method1("astype", (d,)),
            None => Ok(array),
        }
    }

    fn __repr__(&self) -> String {
        format!(
            "Rendering({}×{}, std_error={})",
            self.image.width,
            self.image.height,
            self.std_error.is_some()
        )
    }
}

/// Renders `scene`: solves it (its own solver and parameters unless `solver` names
/// another, as `lucent render` does) and marches camera rays through the solution, or
/// traces camera paths for solvers that make pictures themselves (`mc`). `solution`
/// renders an existing solution of the scene instead of solving; `size` = (width,
/// height) overrides the scene's. The solve options are `lucent.solve`'s.
#[pyfunction]
#[pyo3(signature = (scene, solver=None, *, solution=None, size=None, params=None, rtol=None, atol=0.0, max_iterations=10_000, time_limit=None, threads=None, memory_budget=None, cancel=None, progress=None, **kwargs))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn render(
    py: Python<'_>,
    scene: &Bound<'_, PyScene>,
    solver: Option<&str>,
    solution: Option<Py<PySolution>>,
    size: Option<(usize, usize)>,
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
) -> PyResult<PyRendering> {
    let scene = scene.get();
    let budget = memory_budget.unwrap_or(lucent::scene::SCENE_MEMORY_BUDGET);
    let mut built = py.detach(|| scene.build(budget))?;
    if let Some((width, height)) = size {
        built.settings.width = width;
        built.settings.height = height;
        built.settings.validate().map_err(|e| invalid("size", e))?;
    }
    let name = solver.unwrap_or(&scene.scene.solver.name).to_owned();
    let chosen = PySolver::build(&name, params_for(Some(scene), &name, params, kwargs)?)?;
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
    let default_rtol = scene
        .scene
        .solver
        .tolerance
        .unwrap_or(lucent::core::SolveOptions::default().relative_tolerance);
    let (exposure, tone) = (built.exposure, built.tone);
    // Camera paths: the solver makes the picture itself.
    if solution.is_none() && chosen.solver.images().is_some() {
        let s = built.settings;
        let background = s
            .background
            .unwrap_or_else(|| lucent::scene::sky_background(&built.problem));
        let camera = built.camera;
        camera.validate().map_err(|e| from_lucent(e.into()))?;
        let aspect = s.width as f64 / s.height as f64;
        let ray = |u: f64, v: f64| {
            camera
                .ray(u, v, aspect)
                .unwrap_or((glam::DVec3::ZERO, glam::DVec3::Z))
        };
        let flag = match &options.cancel {
            Some(token) => token.get().flag.clone(),
            None => Arc::new(AtomicBool::new(false)),
        };
        let deadline = match options.time_limit {
            None => None,
            Some(t) if t > 0.0 && t.is_finite() && t < 1e9 => {
                Some(std::time::Instant::now() + std::time::Duration::from_secs_f64(t))
            }
            Some(t) => {
                return Err(invalid(
                    "time_limit",
                    format!("{t:?}: a positive number of seconds"),
                ));
            }
        };
        let (problem, traced) = (&built.problem, &*chosen.solver);
        let estimate = run_interruptible(py, &flag, || {
            let Some(imager) = traced.images() else {
                return Err(lucent::core::SolveError::Unsupported {
                    solver: traced.name().into(),
                    feature: "camera paths".into(),
                });
            };
            imager.image(
                problem,
                &ImageRequest {
                    width: s.width,
                    height: s.height,
                    background,
                    ray: &ray,
                    progress: None,
                    interrupt: lucent::core::Interrupt::new(Some(flag.clone()), deadline),
                },
            )
        })?
        .map_err(from_solve)?;
        return Ok(PyRendering {
            image: Image {
                width: estimate.width,
                height: estimate.height,
                pixels: estimate.radiance,
            },
            std_error: Some(Image {
                width: estimate.width,
                height: estimate.height,
                pixels: estimate.std_error,
            }),
            solution: None,
            exposure,
            tone,
            rows_traced: estimate.rows_traced,
        });
    }
    let solution = match solution {
        Some(s) => {
            let held = s.get();
            if held.problem != built.problem.fingerprint() {
                return Err(invalid(
                    "solution",
                    "it solves another problem than this scene's (solve the scene, or pass the scene it was solved from)",
                ));
            }
            s
        }
        None => {
            chosen.solver.admits(&built.problem).map_err(from_solve)?;
            Py::new(py, chosen.run(py, &built.problem, &options, default_rtol)?)?
        }
    };
    let marched = {
        let held = solution.get();
        let (problem, camera, settings) = (&built.problem, &built.camera, &built.settings);
        let flag = Arc::new(AtomicBool::new(false));
        run_interruptible(py, &flag, || {
            lucent::render::render(problem, &held.solution, camera, settings, None)
        })?
        .map_err(|e| from_lucent(e.into()))?
    };
    let rows = marched.height;
    Ok(PyRendering {
        image: marched,
        std_error: None,
        solution: Some(solution),
        exposure,
        tone,
        rows_traced: rows,
    })
}
