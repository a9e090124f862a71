//! Numbers from files for the picture commands: matrices (text or
//! NumPy), per-vertex values, `fmaps eval --json` curves.

use std::path::Path;

use crate::{Failure, input};

fn read_text(path: &Path) -> Result<String, Failure> {
    use fmaps::mesh_io;
    let bytes = mesh_io::read_bounded(path, mesh_io::MAX_INPUT_BYTES).map_err(input)?;
    String::from_utf8(bytes)
        .map_err(|_| input(anyhow::anyhow!("{}: not valid UTF-8 text", path.display())))
}

/// A dense matrix: a NumPy file (.npy, .npz with one array; any real or
/// integer dtype), or text with one row per non-empty line.
pub(crate) fn read_matrix(path: &Path) -> Result<nalgebra::DMatrix<f64>, Failure> {
    if fmaps::mesh_io::arrays::is_numpy(path) {
        let (r, c, v) = fmaps::mesh_io::arrays::read_matrix(path).map_err(input)?;
        return Ok(nalgebra::DMatrix::from_vec(r, c, v));
    }
    let text = read_text(path)?;
    let mut rows: Vec<Vec<f64>> = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let row = line
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|s| !s.is_empty())
            .map(|s| parse_number(s, path, i + 1))
            .collect::<Result<Vec<f64>, Failure>>()?;
        if let Some(first) = rows.first()
            && row.len() != first.len()
        {
            return Err(input(anyhow::anyhow!(
                "{}:{}: {} entries, but the first row has {}",
                path.display(),
                i + 1,
                row.len(),
                first.len()
            )));
        }
        rows.push(row);
    }
    if rows.is_empty() {
        return Err(input(anyhow::anyhow!("{}: no rows", path.display())));
    }
    let (r, c) = (rows.len(), rows[0].len());
    Ok(nalgebra::DMatrix::from_row_iterator(
        r,
        c,
        rows.into_iter().flatten(),
    ))
}

/// Thresholds, curve and mean error of an `fmaps eval --json` report.
pub(crate) fn read_curve(path: &Path) -> Result<(Vec<f64>, Vec<f64>, f64), Failure> {
    let text = read_text(path)?;
    let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| {
        input(anyhow::anyhow!(
            "{}: not JSON ({e}); expected the output of `fmaps eval --json`",
            path.display()
        ))
    })?;
    let numbers = |key: &str| -> Result<Vec<f64>, Failure> {
        v[key]
            .as_array()
            .and_then(|a| a.iter().map(serde_json::Value::as_f64).collect())
            .ok_or_else(|| {
                input(anyhow::anyhow!(
                    "{}: no numeric `{key}` array; expected the output of `fmaps eval --json`",
                    path.display()
                ))
            })
    };
    let (x, y) = (numbers("thresholds")?, numbers("curve")?);
    if x.len() != y.len() || x.is_empty() {
        return Err(input(anyhow::anyhow!(
            "{}: {} thresholds but {} curve values",
            path.display(),
            x.len(),
            y.len()
        )));
    }
    let mean = v["mean_error"].as_f64().unwrap_or(f64::NAN);
    Ok((x, y, mean))
}

/// One value per vertex.
pub(crate) fn read_values(path: &Path, n: usize) -> Result<Vec<f64>, Failure> {
    use fmaps::mesh_io::arrays;
    if arrays::is_numpy(path) {
        // NaN and infinities allowed: drawn grey, as in text.
        let a = arrays::read_numeric(path).map_err(input)?;
        if !matches!(a.shape.as_slice(), [m] | [m, 1] if *m == n) {
            return Err(input(anyhow::anyhow!(
                "{}: shape {:?}, but the mesh has {n} vertices (one value per vertex)",
                path.display(),
                a.shape
            )));
        }
        return Ok(match a.values {
            arrays::Values::Float(v) => v,
            arrays::Values::Int(v) => v.into_iter().map(|x| x as f64).collect(),
        });
    }
    let text = read_text(path)?;
    let mut v = Vec::with_capacity(n);
    for (i, line) in text.lines().enumerate() {
        let s = line.trim();
        if !s.is_empty() {
            if v.len() == n {
                return Err(input(anyhow::anyhow!(
                    "{}:{}: more values than the mesh's {n} vertices (one per line)",
                    path.display(),
                    i + 1
                )));
            }
            v.push(parse_number(s, path, i + 1)?);
        }
    }
    if v.len() != n {
        return Err(input(anyhow::anyhow!(
            "{}: {} values, but the mesh has {n} vertices (one per line)",
            path.display(),
            v.len()
        )));
    }
    Ok(v)
}

fn parse_number(s: &str, path: &Path, line: usize) -> Result<f64, Failure> {
    s.parse::<f64>().map_err(|_| {
        input(anyhow::anyhow!(
            "{}:{line}: `{s}` is not a number",
            path.display()
        ))
    })
}
