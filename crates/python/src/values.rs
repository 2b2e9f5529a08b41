//! Python values as TOML values, so that dicts go through the same serde path as scene
//! files (`deny_unknown_fields`, kebab-case kinds, the same messages).

use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};

use crate::errors::invalid;

/// `obj` as a TOML value: bool, int, float, str, list/tuple, dict with str keys; numpy
/// scalars and arrays through their `tolist()`. `None` in a dict means "not given" and
/// is dropped; anywhere else it is an error naming `path`.
pub(crate) fn to_toml(obj: &Bound<'_, PyAny>, path: &str) -> PyResult<toml::Value> {
    to_toml_at(obj, path, 0)
}

/// How deep a scene value may nest: a scene file's deepest value (a transfer function's
/// control points inside `[medium]`) is 4 deep; 64 leaves room for any real use and keeps
/// the recursion (here and in serde) far from the thread's stack (a dict nested 20 000
/// deep, or a list that holds itself, once overflowed it).
pub(crate) const MAX_DEPTH: usize = 64;

fn to_toml_at(obj: &Bound<'_, PyAny>, path: &str, depth: usize) -> PyResult<toml::Value> {
    if depth > MAX_DEPTH {
        return Err(invalid(
            path,
            format!(
                "nested more than {MAX_DEPTH} deep (a scene value is a few levels deep; does a list or dict hold itself?)"
            ),
        ));
    }
    if obj.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(obj.extract()?));
    }
    if obj.is_instance_of::<PyInt>() {
        let v: i64 = obj
            .extract()
            .map_err(|_| invalid(path, "integer out of the 64-bit range"))?;
        return Ok(toml::Value::Integer(v));
    }
    if obj.is_instance_of::<PyFloat>() {
        return Ok(toml::Value::Float(obj.extract()?));
    }
    if obj.is_instance_of::<PyString>() {
        return Ok(toml::Value::String(obj.extract()?));
    }
    if let Ok(dict) = obj.cast::<PyDict>() {
        let mut table = toml::Table::new();
        for (k, v) in dict.iter() {
            let key: String = k
                .extract()
                .map_err(|_| invalid(path, "dictionary keys must be strings"))?;
            if v.is_none() {
                continue;
            }
            let inner = if path.is_empty() {
                key.clone()
            } else {
                format!("{path}.{key}")
            };
            table.insert(key, to_toml_at(&v, &inner, depth + 1)?);
        }
        return Ok(toml::Value::Table(table));
    }
    if obj.is_instance_of::<PyList>() || obj.is_instance_of::<PyTuple>() {
        let items = obj
            .try_iter()?
            .enumerate()
            .map(|(i, item)| to_toml_at(&item?, &format!("{path}[{i}]"), depth + 1))
            .collect::<PyResult<Vec<_>>>()?;
        return Ok(toml::Value::Array(items));
    }
    // numpy scalars and arrays.
    if obj.hasattr("tolist")? {
        let plain = obj.call_method0("tolist")?;
        if !plain.is(obj) {
            return to_toml_at(&plain, path, depth + 1);
        }
    }
    Err(invalid(
        path,
        format!(
            "{} is not a scene value (bool, int, float, str, list or dict)",
            obj.get_type().name()?
        ),
    ))
}

/// A serde-deserialisable value from a Python object, with `what` naming it in errors.
pub(crate) fn from_py<T: serde::de::DeserializeOwned>(
    obj: &Bound<'_, PyAny>,
    what: &str,
) -> PyResult<T> {
    let value = to_toml(obj, what)?;
    value
        .try_into::<T>()
        .map_err(|e| invalid(what, e.to_string().trim_end()))
}

/// A JSON value as a Python object (dicts, lists, numbers, strings, None).
pub(crate) fn json_to_py<'py>(
    py: Python<'py>,
    value: &serde_json::Value,
) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(value)
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))?;
    PyModule::import(py, "json")?
        .getattr("loads")?
        .call1((text,))
}

/// Python keyword arguments as solver parameters.
pub(crate) fn params_from(
    dict: Option<&Bound<'_, PyDict>>,
    into: &mut lucent::core::Params,
) -> PyResult<()> {
    use lucent::core::ParamValue;
    let Some(dict) = dict else { return Ok(()) };
    for (k, v) in dict.iter() {
        let key: String = k.extract()?;
        let value = match to_toml(&v, &key)? {
            toml::Value::Boolean(b) => ParamValue::Bool(b),
            toml::Value::Integer(i) => ParamValue::Int(i),
            toml::Value::Float(f) => ParamValue::Float(f),
            toml::Value::String(s) => ParamValue::Text(s),
            _ => {
                return Err(invalid(
                    &key,
                    "a solver parameter is a bool, a number or a string",
                ));
            }
        };
        into.0.insert(key, value);
    }
    Ok(())
}
