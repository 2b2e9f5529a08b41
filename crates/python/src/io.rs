//! The volume readers: every format lucent reads, as numpy arrays with their geometry.

use std::path::PathBuf;

use glam::DVec3;
use lucent::grid::Grid;
use lucent::grid::io::{Endian, LoadOptions, ScalarType};
use pyo3::prelude::*;

use crate::arrays::grid_array;
use crate::errors::{from_grid, invalid};

/// A volume read from a file: its values as (n_z, n_y, n_x) float32 — or
/// (channels, n_z, n_y, n_x) for a multi-channel Mitsuba grid — and where its cells are.
#[pyclass(name = "Volume", module = "lucent", frozen)]
pub(crate) struct PyVolume {
    grids: Vec<Grid>,
    /// The VDB grid's name, for OpenVDB files.
    name: Option<String>,
}

impl PyVolume {
    fn one(grid: Grid) -> Self {
        Self {
            grids: vec![grid],
            name: None,
        }
    }
}

#[pymethods]
impl PyVolume {
    /// The values, float32: (n_z, n_y, n_x), or (channels, n_z, n_y, n_x) for several.
    #[getter]
    fn data<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let dims = self.grids[0].dims();
        grid_array(
            py,
            dims,
            self.grids.iter().map(|g| g.data().to_vec()).collect(),
            false,
        )
    }

    /// Channels (1 but for multi-channel Mitsuba grids).
    #[getter]
    fn channels(&self) -> usize {
        self.grids.len()
    }

    /// Cells per axis, (n_x, n_y, n_z).
    #[getter]
    fn dims(&self) -> (usize, usize, usize) {
        let [x, y, z] = self.grids[0].dims();
        (x, y, z)
    }

    /// Cell size (x, y, z). Formats that store samples (NRRD, MetaImage, VTK, VDB) put
    /// sample (0, 0, 0) at the centre of cell (0, 0, 0).
    #[getter]
    fn spacing(&self) -> (f64, f64, f64) {
        self.grids[0].geometry().spacing().into()
    }

    /// The corner of cell (0, 0, 0) (half a cell below the file's first sample).
    #[getter]
    fn origin(&self) -> (f64, f64, f64) {
        self.grids[0].geometry().origin().into()
    }

    /// The box the cells fill: ((x0, y0, z0), (x1, y1, z1)).
    #[getter]
    fn bounds(&self) -> ((f64, f64, f64), (f64, f64, f64)) {
        let (lo, hi) = self.grids[0].geometry().bounds();
        (lo.into(), hi.into())
    }

    /// The grid's name in an OpenVDB file, else `None`.
    #[getter]
    fn name(&self) -> Option<&str> {
        self.name.as_deref()
    }

    fn __repr__(&self) -> String {
        let [x, y, z] = self.grids[0].dims();
        format!(
            "Volume(dims=({x}, {y}, {z}), channels={}, spacing={:?}, origin={:?})",
            self.grids.len(),
            self.spacing(),
            self.origin()
        )
    }
}

/// What a read may take: the command line's rule, so that a file `lucent` refuses is
/// refused here too. A read (its payload and decoded grid together) gets three fields'
/// worth of the job's budget (`memory_budget`, default 8 GiB: 3 GiB), which stops a
/// decompression bomb or a VDB whose tree spans a huge box before it is inflated.
fn load_options(memory_budget: Option<u64>) -> LoadOptions {
    LoadOptions {
        memory_budget: lucent::scene::max_read_bytes(
            memory_budget.unwrap_or(lucent::scene::SCENE_MEMORY_BUDGET),
        ),
    }
}

/// Reads a volume file by its extension: `.nrrd`/`.nhdr`, `.mhd`/`.mha`, `.vtk`,
/// `.vti` (file or vtk.js folder), `.vol` (Mitsuba, every channel), `.npy`, `.vdb` (the
/// first float grid). Headerless raw files need `read_raw`. A read takes at most three
/// eighths of `memory_budget` (default 8 GiB, so 3 GiB), as `lucent` allows a scene's
/// volume: a file claiming more is refused before anything is inflated or allocated.
#[pyfunction]
#[pyo3(signature = (path, *, memory_budget=None))]
pub(crate) fn read_volume(
    py: Python<'_>,
    path: PathBuf,
    memory_budget: Option<u64>,
) -> PyResult<PyVolume> {
    let options = load_options(memory_budget);
    let is_vol = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("vol"));
    let is_vdb = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("vdb"));
    if is_vol {
        let grids = py
            .detach(|| lucent::grid::io::mitsuba::read_channels(&path, &options))
            .map_err(from_grid)?;
        return Ok(PyVolume { grids, name: None });
    }
    if is_vdb {
        return read_vdb(py, path, None, memory_budget);
    }
    py.detach(|| lucent::grid::io::read_volume_with(&path, &options))
        .map(PyVolume::one)
        .map_err(from_grid)
}

/// Reads the OpenVDB float grid called `grid` (default the first), dense over its active
/// box.
#[pyfunction]
#[pyo3(signature = (path, grid=None, *, memory_budget=None))]
pub(crate) fn read_vdb(
    py: Python<'_>,
    path: PathBuf,
    grid: Option<String>,
    memory_budget: Option<u64>,
) -> PyResult<PyVolume> {
    let options = load_options(memory_budget);
    let volume = py
        .detach(|| lucent::grid::io::vdb::read_volume(&path, grid.as_deref(), &options))
        .map_err(from_grid)?;
    Ok(PyVolume {
        grids: vec![volume.grid],
        name: Some(volume.name),
    })
}

fn scalar_type(dtype: &str) -> PyResult<ScalarType> {
    Ok(match dtype {
        "uint8" | "u8" => ScalarType::U8,
        "int8" | "i8" => ScalarType::I8,
        "uint16" | "u16" => ScalarType::U16,
        "int16" | "i16" => ScalarType::I16,
        "uint32" | "u32" => ScalarType::U32,
        "int32" | "i32" => ScalarType::I32,
        "float16" | "f16" => ScalarType::F16,
        "float32" | "f32" => ScalarType::F32,
        "float64" | "f64" => ScalarType::F64,
        other => {
            return Err(invalid(
                "dtype",
                format!(
                    "`{other}`: one of uint8, int8, uint16, int16, uint32, int32, float16, float32, float64"
                ),
            ));
        }
    })
}

/// Reads a headerless raw file of `shape` = (n_z, n_y, n_x) samples of `dtype` (a numpy
/// name: `uint8`, `int16`, `float32`, ...) in `byteorder` (`little` or `big`), x fastest;
/// cells of `spacing` from the corner `origin`.
#[pyfunction]
#[pyo3(signature = (path, shape, dtype, *, byteorder="little", spacing=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0), memory_budget=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn read_raw(
    py: Python<'_>,
    path: PathBuf,
    shape: (usize, usize, usize),
    dtype: &str,
    byteorder: &str,
    spacing: (f64, f64, f64),
    origin: (f64, f64, f64),
    memory_budget: Option<u64>,
) -> PyResult<PyVolume> {
    let endian = match byteorder {
        "little" | "<" => Endian::Little,
        "big" | ">" => Endian::Big,
        other => return Err(invalid("byteorder", format!("`{other}`: little or big"))),
    };
    let layout = lucent::grid::io::raw::RawLayout {
        dims: [shape.2, shape.1, shape.0],
        scalar: scalar_type(dtype)?,
        endian,
        spacing: DVec3::from(spacing),
        origin: DVec3::from(origin),
    };
    let options = load_options(memory_budget);
    py.detach(|| lucent::grid::io::raw::read(&path, &layout, &options))
        .map(PyVolume::one)
        .map_err(from_grid)
}

/// Writes `data` — (n_z, n_y, n_x), or (channels, n_z, n_y, n_x) for a Mitsuba `.vol` —
/// as float32 cells of `spacing` from the corner `origin`, in the format of the
/// extension: `.vol` (Mitsuba: the box the cells fill), `.npy` (no geometry), `.nrrd`
/// (raw), `.mhd`, `.vtk`, `.vti` (the sample-at-cell-centre convention of `read_volume`,
/// so a file written here reads back to the same values and box). The file appears whole
/// or not at all (written beside it, then renamed). `data` may take up to three eighths of
/// `memory_budget` (default 8 GiB).
#[pyfunction]
#[pyo3(signature = (path, data, *, spacing=None, origin=None, memory_budget=None))]
pub(crate) fn write_volume(
    py: Python<'_>,
    path: PathBuf,
    data: &Bound<'_, PyAny>,
    spacing: Option<&Bound<'_, PyAny>>,
    origin: Option<&Bound<'_, PyAny>>,
    memory_budget: Option<u64>,
) -> PyResult<()> {
    let budget = memory_budget.unwrap_or(lucent::scene::SCENE_MEMORY_BUDGET);
    let (dims, channels) = crate::arrays::channels(data, "data", None, budget)?;
    let spacing = match spacing {
        Some(s) => crate::scene::triple(s, "spacing")?,
        None => DVec3::ONE,
    };
    let origin = match origin {
        Some(o) => crate::scene::triple(o, "origin")?,
        None => DVec3::ZERO,
    };
    let geometry = lucent::grid::GridGeometry::new(dims, spacing, origin)
        .map_err(|e| invalid("spacing", e))?;
    let grids = channels
        .into_iter()
        .map(|v| Grid::from_vec(geometry, v).map_err(|e| invalid("data", e)))
        .collect::<PyResult<Vec<_>>>()?;
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    if extension != "vol" && grids.len() != 1 {
        return Err(invalid(
            "data",
            format!(
                "{} channels: only a Mitsuba .vol holds several",
                grids.len()
            ),
        ));
    }
    use lucent::grid::io;
    py.detach(|| match extension.as_str() {
        "vol" => io::mitsuba::write(&path, &grids.iter().collect::<Vec<_>>()),
        "npy" => io::npy::write(&path, &grids[0], ScalarType::F32),
        "nrrd" => io::nrrd::write(&path, &grids[0], ScalarType::F32, io::nrrd::Encoding::Raw),
        "mhd" | "mha" => io::mhd::write(&path, &grids[0], ScalarType::F32),
        "vtk" => io::vtk::write(&path, &grids[0], ScalarType::F32),
        "vti" => io::vti::write(&path, &grids[0], ScalarType::F32, false),
        other => Err(lucent::grid::GridError::Unsupported {
            path: path.clone(),
            what: "file extension for writing",
            value: format!("`.{other}` (lucent writes .vol, .npy, .nrrd, .mhd, .vtk, .vti)"),
        }),
    })
    .map_err(from_grid)
}
