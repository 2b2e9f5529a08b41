//! numpy arrays in and out.
//!
//! A grid is the C-order array `a[z, y, x]` of shape (n_z, n_y, n_x), the layout of
//! lucent's `.npy` files and of its grids in memory (x fastest); several channels stack
//! in front, (channels, n_z, n_y, n_x). Inputs must be floating point (float32 or
//! float64, read as f32) and finite; anything else is a `ValueError` naming the argument.

use ndarray::{ArrayD, IxDyn};
use numpy::{
    IntoPyArray, PyArrayDescrMethods, PyArrayDyn, PyArrayMethods, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use crate::errors::{Kind, invalid, raise};

/// An input array as f32 values in C order, with its shape.
pub(crate) struct Floats {
    /// numpy's shape, slowest axis first.
    pub(crate) shape: Vec<usize>,
    /// The values, C order.
    pub(crate) values: Vec<f32>,
}

/// `obj` (an ndarray, or anything `numpy.asarray` takes) as finite f32 values in C order
/// (the logical order `a[z, y, x]`, whatever the memory layout: C, Fortran, transposed,
/// strided or broadcast views are all read by index, never by memory position); `name`
/// is the argument, for the error. An array whose f32 copy would take more than
/// `max_bytes` is refused before anything is copied (a broadcast view of 2000³ costs
/// numpy nothing and would cost 32 GB here).
pub(crate) fn floats(obj: &Bound<'_, PyAny>, name: &str, max_bytes: u64) -> PyResult<Floats> {
    let py = obj.py();
    let array = match obj.cast::<PyUntypedArray>() {
        Ok(a) => a.clone(),
        Err(_) => {
            let converted = PyModule::import(py, "numpy")?
                .getattr("asarray")?
                .call1((obj,))
                .map_err(|e| invalid(name, format!("not an array: {e}")))?;
            converted
                .cast_into::<PyUntypedArray>()
                .map_err(|_| invalid(name, "not an array"))?
        }
    };
    let dtype = array.dtype();
    let kind = dtype.kind();
    let shape = array.shape().to_vec();
    if kind != b'f' {
        return Err(invalid(
            name,
            format!(
                "dtype {} is not floating point: pass float32 or float64 (for example `.astype(numpy.float32)`)",
                dtype
                    .str()
                    .map_or_else(|_| "?".to_owned(), |s| s.to_string())
            ),
        ));
    }
    let bytes = shape
        .iter()
        .try_fold(4u64, |acc, &n| acc.checked_mul(n as u64));
    if bytes.is_none_or(|b| b > max_bytes) {
        return Err(raise(
            Kind::OverBudget,
            format!(
                "`{name}`: shape {} as float32 needs {} bytes, over the {max_bytes} bytes it may take (a field may take an eighth of `memory_budget`, 3 for RGB)",
                tuple(&shape),
                bytes.map_or_else(|| "more than 2^64".to_owned(), |b| b.to_string()),
            ),
        ));
    }
    let values: Vec<f32> = if let Ok(a) = array.cast::<PyArrayDyn<f32>>() {
        let a = a.readonly();
        // `as_slice` also accepts a Fortran-contiguous array (its memory order is not
        // a[z, y, x]'s): only a C-contiguous one is copied as it lies.
        match a.as_slice() {
            Ok(contiguous) if a.is_c_contiguous() => contiguous.to_vec(),
            _ => a.as_array().iter().copied().collect(),
        }
    } else {
        // float64 (and half or extended floats, through float64).
        let a64 = match array.cast::<PyArrayDyn<f64>>() {
            Ok(a) => a.clone(),
            Err(_) => {
                if bytes.is_none_or(|b| b.saturating_mul(2) > max_bytes) {
                    return Err(raise(
                        Kind::OverBudget,
                        format!(
                            "`{name}`: shape {} as float64 (to read {} values) is over the {max_bytes} bytes it may take",
                            tuple(&shape),
                            dtype
                                .str()
                                .map_or_else(|_| "?".to_owned(), |s| s.to_string())
                        ),
                    ));
                }
                array
                    .call_method1("astype", ("float64",))?
                    .cast_into::<PyArrayDyn<f64>>()
                    .map_err(|_| invalid(name, "cannot be read as float64"))?
            }
        };
        let a = a64.readonly();
        match a.as_slice() {
            Ok(contiguous) if a.is_c_contiguous() => contiguous.iter().map(|&v| v as f32).collect(),
            _ => a.as_array().iter().map(|&v| v as f32).collect(),
        }
    };
    if let Some(at) = values.iter().position(|v| !v.is_finite()) {
        return Err(invalid(
            name,
            format!(
                "{:?} at index {} (values must be finite, and within f32's range)",
                values[at],
                tuple(&unravel(at, &shape))
            ),
        ));
    }
    Ok(Floats { shape, values })
}

/// The multi-index of flat position `at` in a C-order array of `shape`.
fn unravel(mut at: usize, shape: &[usize]) -> Vec<usize> {
    let mut index = vec![0; shape.len()];
    for (axis, &n) in shape.iter().enumerate().rev() {
        let n = n.max(1);
        index[axis] = at % n;
        at /= n;
    }
    index
}

/// A shape or index as Python writes a tuple: `(4, 5)`, `(3,)`.
pub(crate) fn tuple(values: &[usize]) -> String {
    match values {
        [one] => format!("({one},)"),
        _ => format!(
            "({})",
            values
                .iter()
                .map(usize::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// numpy's (n_z, n_y, n_x) as lucent's dims [n_x, n_y, n_z].
pub(crate) fn dims_of(shape: &[usize]) -> [usize; 3] {
    [shape[2], shape[1], shape[0]]
}

/// The most bytes one field may take under a job's memory `budget`: the scene's rule
/// (up to eight fields on a grid, an eighth of the budget each; 1 GiB under the default).
pub(crate) fn field_bytes(budget: u64) -> u64 {
    lucent::scene::max_grid_bytes(budget)
}

/// A scalar field on a grid: a 3D array, or `channels` of them stacked as a 4D array with
/// 1 or 3 in front; `dims` (if known) is checked.
pub(crate) fn channels(
    obj: &Bound<'_, PyAny>,
    name: &str,
    dims: Option<[usize; 3]>,
    budget: u64,
) -> PyResult<([usize; 3], Vec<Vec<f32>>)> {
    // Up to three channels of one field each.
    let Floats { shape, values } = floats(obj, name, 3 * field_bytes(budget))?;
    let (count, grid_shape) = match shape.len() {
        3 => (1, &shape[..]),
        4 if shape[0] == 1 || shape[0] == 3 => (shape[0], &shape[1..]),
        _ => {
            return Err(invalid(
                name,
                format!(
                    "shape {}: expected (n_z, n_y, n_x), or (1 or 3, n_z, n_y, n_x) for grey or RGB",
                    tuple(&shape)
                ),
            ));
        }
    };
    if grid_shape.contains(&0) {
        return Err(invalid(
            name,
            format!("shape {} has an empty axis", tuple(&shape)),
        ));
    }
    let found = dims_of(grid_shape);
    if let Some(expected) = dims
        && expected != found
    {
        return Err(invalid(
            name,
            format!(
                "shape {} does not match the grid (n_z, n_y, n_x) = ({}, {}, {})",
                tuple(&shape),
                expected[2],
                expected[1],
                expected[0]
            ),
        ));
    }
    let per = values.len() / count;
    let split = values.chunks(per).map(<[f32]>::to_vec).collect();
    Ok((found, split))
}

/// f32 values on `dims` (and `channels` of them, when more than one... or always, with
/// `stack`) as a numpy array of shape ([channels,] n_z, n_y, n_x).
pub(crate) fn grid_array<'py>(
    py: Python<'py>,
    dims: [usize; 3],
    channels: Vec<Vec<f32>>,
    stack: bool,
) -> PyResult<Bound<'py, PyAny>> {
    let count = channels.len();
    let mut shape = vec![dims[2], dims[1], dims[0]];
    if stack || count != 1 {
        shape.insert(0, count);
    }
    let flat: Vec<f32> = channels.into_iter().flatten().collect();
    let array = ArrayD::from_shape_vec(IxDyn(&shape), flat)
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))?;
    Ok(array.into_pyarray(py).into_any())
}

/// A numpy array of any shape from C-order values.
pub(crate) fn array_f32<'py>(
    py: Python<'py>,
    shape: &[usize],
    values: Vec<f32>,
) -> PyResult<Bound<'py, PyAny>> {
    let array = ArrayD::from_shape_vec(IxDyn(shape), values)
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))?;
    Ok(array.into_pyarray(py).into_any())
}

/// A 1D f64 numpy array.
pub(crate) fn array_f64<'py>(py: Python<'py>, values: Vec<f64>) -> Bound<'py, PyAny> {
    numpy::PyArray1::from_vec(py, values).into_any()
}
