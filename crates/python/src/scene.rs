//! Scenes (TOML files, TOML text or dicts) and problems (from a scene, or from numpy
//! arrays with their geometry).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::DVec3;
use lucent::core::{Boundary, Field, Light, Medium, Problem};
use lucent::grid::{Grid, GridGeometry};
use lucent::scene::{BuiltScene, LightSpec, PhaseSpec, Scene};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyFloat, PyInt, PyString};

use crate::arrays::{channels, grid_array};
use crate::errors::{from_lucent, invalid};
use crate::values::{from_py, json_to_py, to_toml};

/// A scene: volume, medium, lights, boundary, camera, image and solver, as in a scene
/// file. Build its problem with [`PyScene::problem`]; solve and render it with
/// `lucent.solve` and `lucent.render`.
#[pyclass(name = "Scene", module = "lucent", frozen)]
pub(crate) struct PyScene {
    pub(crate) scene: Scene,
    /// The folder that relative volume paths start from.
    pub(crate) base: PathBuf,
    /// The scene's name in messages (its file, or what it was made from).
    pub(crate) name: String,
}

impl PyScene {
    /// The scene built within `budget` bytes (the CLI's `Scene::build_within`).
    pub(crate) fn build(&self, budget: u64) -> PyResult<BuiltScene> {
        self.scene
            .build_within(&self.base, budget)
            .map_err(from_lucent)
    }
}

fn base_of(base: Option<PathBuf>) -> PathBuf {
    base.unwrap_or_else(|| PathBuf::from("."))
}

#[pymethods]
impl PyScene {
    /// Reads a scene file (TOML); relative volume paths start from its folder.
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        let scene = Scene::load(&path).map_err(from_lucent)?;
        Ok(Self {
            scene,
            base: path.parent().unwrap_or(Path::new(".")).to_owned(),
            name: path.display().to_string(),
        })
    }

    /// Parses scene text (TOML); relative volume paths start from `base` (default `.`).
    #[staticmethod]
    #[pyo3(signature = (text, base=None))]
    fn from_toml(text: &str, base: Option<PathBuf>) -> PyResult<Self> {
        let scene = Scene::parse(text, Path::new("<scene text>")).map_err(from_lucent)?;
        Ok(Self {
            scene,
            base: base_of(base),
            name: "<scene text>".into(),
        })
    }

    /// A scene from a dict with the file's structure (`{"volume": {...}, "camera":
    /// {...}, ...}`); `None` values count as not given.
    #[staticmethod]
    #[pyo3(signature = (scene, base=None))]
    fn from_dict(scene: &Bound<'_, PyDict>, base: Option<PathBuf>) -> PyResult<Self> {
        let value = to_toml(scene.as_any(), "")?;
        let scene: Scene = value.try_into().map_err(|e: toml::de::Error| {
            crate::errors::raise(
                crate::errors::Kind::Scene,
                format!("<scene dict>: bad scene: {}", e.to_string().trim_end()),
            )
        })?;
        Ok(Self {
            scene,
            base: base_of(base),
            name: "<scene dict>".into(),
        })
    }

    /// The built-in default scene (`cargo run --release` renders it).
    #[staticmethod]
    fn default() -> PyResult<Self> {
        Ok(Self {
            scene: Scene::default_scene().map_err(from_lucent)?,
            base: PathBuf::from("."),
            name: "built-in default scene".into(),
        })
    }

    /// The scene's solver (its `[solver] name`).
    #[getter]
    fn solver(&self) -> &str {
        &self.scene.solver.name
    }

    /// The scene's solver parameters (`[solver.params]`), as given.
    #[getter]
    fn solver_params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let json = serde_json::to_value(&self.scene.solver.params)
            .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))?;
        json_to_py(py, &json)
    }

    /// The scene's relative tolerance (`[solver] tolerance`), or `None`.
    #[getter]
    fn tolerance(&self) -> Option<f64> {
        self.scene.solver.tolerance
    }

    /// The scene's name: its file, or what it was made from.
    #[getter]
    fn name(&self) -> &str {
        &self.name
    }

    /// Builds the problem (reads the volume, applies the medium mapping) within
    /// `memory_budget` bytes (default 8 GiB).
    #[pyo3(signature = (memory_budget=None))]
    fn problem(&self, py: Python<'_>, memory_budget: Option<u64>) -> PyResult<PyProblem> {
        let budget = memory_budget.unwrap_or(lucent::scene::SCENE_MEMORY_BUDGET);
        let built = py.detach(|| self.build(budget))?;
        Ok(PyProblem {
            problem: Arc::new(built.problem.clone()),
            volume: Some(Arc::new(built.volume)),
        })
    }

    fn __repr__(&self) -> String {
        format!(
            "Scene({:?}, solver={:?})",
            self.name, self.scene.solver.name
        )
    }
}

/// A light-transport problem: the medium on its grid, the lights, the boundary, an
/// optional embedded body. Arrays are (n_z, n_y, n_x), or (3, n_z, n_y, n_x) for RGB.
#[pyclass(name = "Problem", module = "lucent", frozen)]
pub(crate) struct PyProblem {
    pub(crate) problem: Arc<Problem>,
    /// The scalar volume before the medium mapping (a scene's), or the emission grid (a
    /// problem made from arrays).
    pub(crate) volume: Option<Arc<Grid>>,
}

pub(crate) fn triple(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<DVec3> {
    if obj.is_instance_of::<PyFloat>() || obj.is_instance_of::<PyInt>() {
        let v: f64 = obj.extract()?;
        return Ok(DVec3::splat(v));
    }
    let v: Vec<f64> = obj
        .extract()
        .map_err(|_| invalid(name, "a number or three numbers (x, y, z)"))?;
    match v[..] {
        [x, y, z] => Ok(DVec3::new(x, y, z)),
        _ => Err(invalid(
            name,
            format!("{} numbers; expected one or three (x, y, z)", v.len()),
        )),
    }
}

fn phase_of(obj: Option<&Bound<'_, PyAny>>) -> PyResult<lucent::optics::Phase> {
    let Some(obj) = obj.filter(|o| !o.is_none()) else {
        return Ok(lucent::optics::Phase::Isotropic);
    };
    let spec: PhaseSpec = if obj.is_instance_of::<PyFloat>() || obj.is_instance_of::<PyInt>() {
        PhaseSpec::HenyeyGreenstein { g: obj.extract()? }
    } else if obj.is_instance_of::<PyString>() {
        let kind: String = obj.extract()?;
        let mut table = toml::Table::new();
        table.insert("kind".into(), toml::Value::String(kind));
        toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| invalid("phase", e.to_string().trim_end()))?
    } else {
        from_py(obj, "phase")?
    };
    spec.to_phase().map_err(|e| invalid("phase", e.to_string()))
}

fn boundary_of(obj: Option<&Bound<'_, PyAny>>) -> PyResult<Boundary> {
    let Some(obj) = obj.filter(|o| !o.is_none()) else {
        return Ok(Boundary::Vacuum);
    };
    if obj.is_instance_of::<PyString>() {
        let kind: String = obj.extract()?;
        let mut table = toml::Table::new();
        table.insert("kind".into(), toml::Value::String(kind));
        return toml::Value::Table(table)
            .try_into()
            .map_err(|e: toml::de::Error| invalid("boundary", e.to_string().trim_end()));
    }
    from_py(obj, "boundary")
}

#[pymethods]
impl PyProblem {
    /// A problem from arrays: `sigma_t` (1/length) per cell, (n_z, n_y, n_x) or
    /// (3, n_z, n_y, n_x); `albedo` a number, three numbers, or an array like `sigma_t`;
    /// cells of size `spacing` (one number or (x, y, z)) from the corner `origin`;
    /// `phase` a mean cosine g (Henyey–Greenstein), a name (`"isotropic"`,
    /// `"rayleigh"`) or a dict as in a scene file; `lights` a list of dicts as in a scene
    /// file (`{"kind": "directional", "direction": [0, 0, -1], "irradiance": 1.0}`);
    /// `boundary` a name or a dict (`{"kind": "robin", "eta": 1.3}`); `embedded` the
    /// signed distance of an embedded body (negative inside); `emission` the grid that
    /// emission lights scale. Arrays are read by index in any memory layout (C, Fortran,
    /// transposed, strided, broadcast); each may take an eighth of `memory_budget`
    /// (default 8 GiB; three eighths for RGB), checked before anything is copied.
    #[new]
    #[pyo3(signature = (sigma_t, albedo=None, *, spacing=None, origin=None, phase=None, lights=None, boundary=None, embedded=None, emission=None, memory_budget=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        sigma_t: &Bound<'_, PyAny>,
        albedo: Option<&Bound<'_, PyAny>>,
        spacing: Option<&Bound<'_, PyAny>>,
        origin: Option<&Bound<'_, PyAny>>,
        phase: Option<&Bound<'_, PyAny>>,
        lights: Option<&Bound<'_, PyAny>>,
        boundary: Option<&Bound<'_, PyAny>>,
        embedded: Option<&Bound<'_, PyAny>>,
        emission: Option<&Bound<'_, PyAny>>,
        memory_budget: Option<u64>,
    ) -> PyResult<Self> {
        let budget = memory_budget.unwrap_or(lucent::scene::SCENE_MEMORY_BUDGET);
        let (dims, sigma) = channels(sigma_t, "sigma_t", None, budget)?;
        if let Some((c, v)) = sigma
            .iter()
            .enumerate()
            .find_map(|(c, values)| values.iter().find(|v| **v < 0.0).map(|v| (c, *v)))
        {
            return Err(invalid(
                "sigma_t",
                format!("{v} in channel {c}: extinction must be ≥ 0"),
            ));
        }
        let spacing = match spacing {
            Some(s) => triple(s, "spacing")?,
            None => DVec3::ONE,
        };
        let origin = match origin {
            Some(o) => triple(o, "origin")?,
            None => DVec3::ZERO,
        };
        let geometry =
            GridGeometry::new(dims, spacing, origin).map_err(|e| invalid("spacing", e))?;
        let grid = |values: Vec<f32>, name: &str| {
            Grid::from_vec(geometry, values).map_err(|e| invalid(name, e))
        };
        let sigma_t = sigma
            .into_iter()
            .map(|v| grid(v, "sigma_t"))
            .collect::<PyResult<Vec<_>>>()?;
        let albedo = match albedo {
            None => vec![Field::Constant(0.9)],
            Some(a) if a.is_instance_of::<PyFloat>() || a.is_instance_of::<PyInt>() => {
                vec![Field::Constant(a.extract::<f64>()? as f32)]
            }
            Some(a) => match a.extract::<Vec<f64>>() {
                Ok(v) if v.len() == 3 => v.iter().map(|&x| Field::Constant(x as f32)).collect(),
                _ => channels(a, "albedo", Some(dims), budget)?
                    .1
                    .into_iter()
                    .map(|v| grid(v, "albedo").map(Field::Grid))
                    .collect::<PyResult<Vec<_>>>()?,
            },
        };
        for field in &albedo {
            let bad = match field {
                Field::Constant(v) => (!(0.0..=1.0).contains(v)).then_some(*v),
                Field::Grid(g) => g.data().iter().copied().find(|v| !(0.0..=1.0).contains(v)),
            };
            if let Some(v) = bad {
                return Err(invalid("albedo", format!("{v} is outside [0, 1]")));
            }
        }
        let emission = match emission.filter(|e| !e.is_none()) {
            Some(e) => {
                let (_, mut values) = channels(e, "emission", Some(dims), budget)?;
                if values.len() != 1 {
                    return Err(invalid("emission", "one grid (n_z, n_y, n_x)"));
                }
                Some(grid(values.remove(0), "emission")?)
            }
            None => None,
        };
        let lights: Vec<Light> = match lights.filter(|l| !l.is_none()) {
            None => Vec::new(),
            Some(list) => {
                let mut out = Vec::new();
                for (i, item) in list.try_iter()?.enumerate() {
                    let name = format!("lights[{i}]");
                    let spec: LightSpec = from_py(&item?, &name)?;
                    if matches!(spec, LightSpec::Emission { .. }) && emission.is_none() {
                        return Err(invalid(
                            &name,
                            "an emission light needs the `emission` grid",
                        ));
                    }
                    out.push(
                        spec.to_light(emission.as_ref())
                            .map_err(|e| invalid(&name, e))?,
                    );
                }
                out
            }
        };
        let embedded = match embedded.filter(|e| !e.is_none()) {
            Some(e) => {
                let (_, mut values) = channels(e, "embedded", Some(dims), budget)?;
                if values.len() != 1 {
                    return Err(invalid(
                        "embedded",
                        "one signed-distance grid (n_z, n_y, n_x)",
                    ));
                }
                Some(grid(values.remove(0), "embedded")?)
            }
            None => None,
        };
        let medium = Medium {
            sigma_t,
            albedo,
            phase: phase_of(phase)?,
        };
        let problem = Problem::new(geometry, medium, lights, boundary_of(boundary)?, embedded)
            .map_err(|e| invalid("problem", e))?;
        Ok(Self {
            problem: Arc::new(problem),
            volume: emission.map(Arc::new),
        })
    }

    /// Cells per axis, (n_x, n_y, n_z).
    #[getter]
    fn dims(&self) -> (usize, usize, usize) {
        let [x, y, z] = self.problem.geometry().dims();
        (x, y, z)
    }

    /// The same problem on `dims` = (n_x, n_y, n_z) cells over the same box: every grid
    /// resampled (trilinear to finer grids, box-averaged to coarser), for convergence
    /// studies (what `lucent resolution` solves on).
    fn on_grid(&self, py: Python<'_>, dims: (usize, usize, usize)) -> PyResult<Self> {
        let problem = self.problem.clone();
        let resampled = py
            .detach(|| lucent::resolution::on_grid(&problem, [dims.0, dims.1, dims.2]))
            .map_err(|e| invalid("dims", e))?;
        Ok(Self {
            problem: Arc::new(resampled),
            volume: None,
        })
    }

    /// numpy's shape of one field, (n_z, n_y, n_x).
    #[getter]
    fn shape(&self) -> (usize, usize, usize) {
        let [x, y, z] = self.problem.geometry().dims();
        (z, y, x)
    }

    /// Cell size (x, y, z), in the scene's length unit.
    #[getter]
    fn spacing(&self) -> (f64, f64, f64) {
        self.problem.geometry().spacing().into()
    }

    /// The corner of cell (0, 0, 0).
    #[getter]
    fn origin(&self) -> (f64, f64, f64) {
        self.problem.geometry().origin().into()
    }

    /// The box: ((x0, y0, z0), (x1, y1, z1)).
    #[getter]
    fn bounds(&self) -> ((f64, f64, f64), (f64, f64, f64)) {
        let (lo, hi) = self.problem.geometry().bounds();
        (lo.into(), hi.into())
    }

    /// Channels a solve computes: 1 (grey) or 3 (RGB).
    #[getter]
    fn channels(&self) -> usize {
        self.problem.channels()
    }

    /// The extinction σ_t (1/length), (channels, n_z, n_y, n_x), float32.
    #[getter]
    fn sigma_t<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let medium = self.problem.medium();
        let dims = self.problem.geometry().dims();
        grid_array(
            py,
            dims,
            medium.sigma_t.iter().map(|g| g.data().to_vec()).collect(),
            true,
        )
    }

    /// The single-scattering albedo, (channels, n_z, n_y, n_x), float32.
    #[getter]
    fn albedo<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let medium = self.problem.medium();
        let dims = self.problem.geometry().dims();
        let n = self.problem.geometry().voxel_count();
        grid_array(
            py,
            dims,
            medium
                .albedo
                .iter()
                .map(|a| match a {
                    Field::Constant(v) => vec![*v; n],
                    Field::Grid(g) => g.data().to_vec(),
                })
                .collect(),
            true,
        )
    }

    /// The embedded body's signed distance (n_z, n_y, n_x), or `None`.
    #[getter]
    fn embedded<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.problem
            .embedded()
            .map(|g| grid_array(py, g.dims(), vec![g.data().to_vec()], false))
            .transpose()
    }

    /// The boundary condition, in words.
    #[getter]
    fn boundary(&self) -> String {
        self.problem.boundary().to_string()
    }

    /// The kinds of the lights (`directional`, `point`, `spot`, `sky`, `emission`).
    #[getter]
    fn lights(&self) -> Vec<String> {
        self.problem
            .lights()
            .iter()
            .map(|l| {
                serde_json::to_value(l.kind())
                    .ok()
                    .and_then(|v| v.as_str().map(str::to_owned))
                    .unwrap_or_default()
            })
            .collect()
    }

    /// The scalar volume the scene's medium was mapped from (n_z, n_y, n_x); for a
    /// problem made from arrays, its `emission` grid, or `None`.
    #[getter]
    fn volume<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.volume
            .as_ref()
            .map(|g| grid_array(py, g.dims(), vec![g.data().to_vec()], false))
            .transpose()
    }

    fn __repr__(&self) -> String {
        let [x, y, z] = self.problem.geometry().dims();
        format!(
            "Problem(dims=({x}, {y}, {z}), channels={}, lights={:?}, boundary={:?})",
            self.problem.channels(),
            self.lights(),
            self.boundary()
        )
    }
}
