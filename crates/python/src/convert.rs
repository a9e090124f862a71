//! Array arguments as people have them: any array-like (numpy arrays of
//! any layout, read-only or not, lists, tuples, objects with
//! `__array__` such as PyTorch tensors on the CPU) of any real or integer
//! dtype that converts without loss, converted once to the dtype fmaps
//! computes in (float64 for coordinates and features, int64 for
//! indices). A lossy or impossible conversion is an `FmapsError` naming
//! the argument.
//!
//! What converts:
//! - to float64: float16/32/64, integers up to 32 bits, 64-bit integers
//!   whose values float64 holds exactly (|x| <= 2^53), a longdouble whose
//!   values are float64 values;
//! - to int64: every signed and unsigned integer dtype (uint64 values up
//!   to 2^63 - 1), floats whose values are all whole numbers.
//!
//! Never: booleans, complex numbers, strings, dates, objects that are not
//! numbers, ragged nested lists.

use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::pyclass::CompareOp;

use crate::err;

/// The dtype an argument is converted to.
#[derive(Clone, Copy, PartialEq)]
enum Target {
    Float,
    Int,
}

/// `obj` as a numpy array of `want` dimensions and the target dtype,
/// converted at most once (no copy when it already is one).
fn convert<'py>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    target: Target,
    want: usize,
) -> PyResult<Bound<'py, PyAny>> {
    let py = obj.py();
    let np = py.import("numpy")?;
    let arr = np.call_method1("asarray", (obj,)).map_err(|e| {
        err(format!(
            "{name}: not an array of numbers ({})",
            e.value(py)
                .str()
                .map_or_else(|_| "?".into(), |s| s.to_string())
        ))
    })?;
    let dtype = arr.getattr("dtype")?;
    let kind: String = dtype.getattr("kind")?.extract()?;
    let itemsize: usize = dtype.getattr("itemsize")?.extract()?;
    let dname: String = dtype.getattr("name")?.extract()?;
    let ndim: usize = arr.getattr("ndim")?.extract()?;
    let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
    // An empty list is an empty array of whatever is needed.
    let empty = shape.iter().product::<usize>() == 0;
    if ndim != want && !(empty && want == 2 && ndim == 1) {
        return Err(err(format!(
            "{name}: a {want}-D array is needed, got shape {shape:?}"
        )));
    }
    let (to, to_name) = match target {
        Target::Float => (np.getattr("float64")?, "float64"),
        Target::Int => (np.getattr("int64")?, "int64"),
    };
    let cast = |a: &Bound<'py, PyAny>| -> PyResult<Bound<'py, PyAny>> {
        let kwargs = pyo3::types::PyDict::new(py);
        kwargs.set_item("copy", false)?;
        a.call_method("astype", (&to,), Some(&kwargs))
    };
    let lossy = |why: &str| {
        err(format!(
            "{name}: dtype {dname} does not convert to {to_name} without loss ({why})"
        ))
    };
    let out = match (kind.as_str(), target) {
        ("b", _) => {
            return Err(err(format!(
                "{name}: booleans, where {} are needed",
                match target {
                    Target::Float => "numbers",
                    Target::Int => "integer indices",
                }
            )));
        }
        ("f", Target::Float) if itemsize <= 8 => cast(&arr)?,
        ("i" | "u", Target::Float) if itemsize <= 4 => cast(&arr)?,
        ("f" | "i" | "u", Target::Float) => {
            let c = cast(&arr)?;
            if !round_trips(&np, &arr, &c)? {
                return Err(lossy("values float64 cannot hold exactly"));
            }
            c
        }
        ("i", Target::Int) => cast(&arr)?,
        ("u", Target::Int) if itemsize < 8 || empty => cast(&arr)?,
        ("u", Target::Int) => {
            let max: u64 = arr.call_method0("max")?.extract()?;
            if max > i64::MAX as u64 {
                return Err(lossy(&format!("{max} is above 2^63 - 1")));
            }
            cast(&arr)?
        }
        ("f", Target::Int) => {
            if !empty {
                whole_numbers(&np, &arr, name)?;
            }
            cast(&arr)?
        }
        ("c", _) => return Err(lossy("complex numbers")),
        _ => {
            return Err(err(format!(
                "{name}: dtype {dname} is not a number type (use float or integer arrays)"
            )));
        }
    };
    if empty && ndim == 1 && want == 2 {
        return out.call_method1("reshape", ((0usize, 0usize),));
    }
    Ok(out)
}

/// Whether `converted` gives back `original` when cast back.
fn round_trips(
    np: &Bound<'_, PyModule>,
    original: &Bound<'_, PyAny>,
    converted: &Bound<'_, PyAny>,
) -> PyResult<bool> {
    let back = converted.call_method1("astype", (original.getattr("dtype")?,))?;
    np.call_method1("array_equal", (back, original))?.extract()
}

/// An error naming the first entry of the float array `arr` that is not a
/// whole number in int64's range (NaN and infinities included).
fn whole_numbers(np: &Bound<'_, PyModule>, arr: &Bound<'_, PyAny>, name: &str) -> PyResult<()> {
    // Finite, whole, and inside int64's range (2^63 is a float64 value).
    let whole = arr.rich_compare(np.call_method1("trunc", (arr,))?, CompareOp::Eq)?;
    let in_range = np
        .call_method1("abs", (arr,))?
        .rich_compare(2f64.powi(63), CompareOp::Lt)?;
    let ok = np
        .call_method1("isfinite", (arr,))?
        .bitand(whole)?
        .bitand(in_range)?;
    let bad = np.call_method1("flatnonzero", (ok.call_method0("__invert__")?,))?;
    if bad.len()? == 0 {
        return Ok(());
    }
    let first: usize = bad.get_item(0)?.extract()?;
    let index: Vec<usize> = np
        .call_method1("unravel_index", (first, arr.getattr("shape")?))?
        .extract()?;
    let value: f64 = arr
        .call_method0("ravel")?
        .get_item(first)?
        .call_method0("item")?
        .extract()?;
    let at = if index.len() == 1 {
        format!("{}", index[0])
    } else {
        format!("{index:?}")
    };
    Err(err(format!(
        "{name}: entry {at} is {value}, not an integer index"
    )))
}

/// A matrix argument as float64 (n x m).
pub(crate) fn floats2<'py>(
    obj: &Bound<'py, PyAny>,
    name: &str,
) -> PyResult<PyReadonlyArray2<'py, f64>> {
    Ok(convert(obj, name, Target::Float, 2)?.extract()?)
}

/// A vector of numbers as float64.
pub(crate) fn floats1<'py>(
    obj: &Bound<'py, PyAny>,
    name: &str,
) -> PyResult<PyReadonlyArray1<'py, f64>> {
    Ok(convert(obj, name, Target::Float, 1)?.extract()?)
}

/// A vector of indices as int64.
pub(crate) fn ints1<'py>(
    obj: &Bound<'py, PyAny>,
    name: &str,
) -> PyResult<PyReadonlyArray1<'py, i64>> {
    Ok(convert(obj, name, Target::Int, 1)?.extract()?)
}

/// A matrix of indices as int64 (rows of `cols` entries).
pub(crate) fn ints2<'py>(
    obj: &Bound<'py, PyAny>,
    name: &str,
    cols: usize,
) -> PyResult<PyReadonlyArray2<'py, i64>> {
    let a: PyReadonlyArray2<'py, i64> = convert(obj, name, Target::Int, 2)?.extract()?;
    let shape = a.as_array().shape().to_vec();
    if shape[1] != cols && shape[0] > 0 {
        return Err(err(format!(
            "{name}: rows of {cols} entries are needed, got shape {shape:?}"
        )));
    }
    Ok(a)
}

/// Pairs of indices (a k x 2 array-like: a list of pairs, an integer
/// array).
pub(crate) fn pairs(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<(i64, i64)>> {
    let a = ints2(obj, name, 2)?;
    Ok(a.as_array()
        .rows()
        .into_iter()
        .map(|r| (r[0], r[1]))
        .collect())
}
