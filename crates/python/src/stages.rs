//! The pipeline's stages one by one, for scripts that replace or inspect
//! one of them (pyFM's `preprocess` / `fit` / `icp_refine` /
//! `zoomout_refine` / `get_p2p`): descriptors, the functional-map solve
//! (on the pipeline's descriptors or any per-vertex features), the two
//! conversions, every refiner by name, geodesic distances. Each works on
//! [`PreparedShape`]s (unit-area shapes with their eigenbases), so the
//! maps equal those of `match_prepared` stage by stage.

use std::sync::Arc;

use fmaps::geodesic::{DijkstraSolver, DistanceSolver, ExactSolver, HeatParams, HeatSolver};
use fmaps::mesh_io::TriMesh;
use fmaps::pipeline::{MatchParams, RefineOptions};
use nalgebra::DMatrix;
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray1, PyArray2};
use pyo3::prelude::*;

use crate::{Mesh, PreparedShape, checked, err, fortran, indices, refiner_kind, run};

/// A matrix argument (any real array-like, any layout) as a column-major
/// matrix, checked finite.
fn matrix(m: &Bound<'_, PyAny>, what: &str) -> PyResult<DMatrix<f64>> {
    let m = crate::convert::floats2(m, what)?;
    let a = m.as_array();
    if let Some(((i, j), _)) = a.indexed_iter().find(|(_, x)| !x.is_finite()) {
        return Err(err(format!("{what}: entry ({i}, {j}) is not finite")));
    }
    Ok(DMatrix::from_fn(a.nrows(), a.ncols(), |i, j| a[(i, j)]))
}

/// Landmark pairs (vertex of A, vertex of B), checked against shapes of
/// `na` and `nb` vertices.
pub(crate) fn landmark_pairs(
    landmarks: Option<Bound<'_, PyAny>>,
    na: usize,
    nb: usize,
) -> PyResult<Vec<(usize, usize)>> {
    let Some(landmarks) = landmarks else {
        return Ok(Vec::new());
    };
    crate::convert::pairs(&landmarks, "landmarks")?
        .into_iter()
        .enumerate()
        .map(|(i, (x, y))| match (usize::try_from(x), usize::try_from(y)) {
            (Ok(u), Ok(v)) if u < na && v < nb => Ok((u, v)),
            _ => Err(err(format!(
                "landmarks: pair {i} is ({x}, {y}), outside 0..{na} x 0..{nb} (0-based vertices of A and B)"
            ))),
        })
        .collect()
}

/// The descriptor parameters of the pipeline for `kind`, `n`, `k_descr`.
fn descriptor_params(
    kind: &str,
    n: usize,
    k_descr: usize,
    subsample: usize,
) -> PyResult<MatchParams> {
    let mut p = MatchParams::unrefined();
    p.descriptors.kind = kind
        .parse()
        .map_err(|e: String| err(format!("kind = {kind:?}: {e}")))?;
    p.descriptors.n = n;
    p.descriptors.eigenpairs = k_descr;
    p.descriptors.subsample = subsample;
    Ok(p)
}

/// The pipeline's descriptors of one shape (n x p, Fortran order, each
/// column of unit L² norm in the shape's mass): the `kind` family ("wks"
/// or "hks") at `n` samples on the first `k` eigenpairs (at most the
/// shape's, as the pipeline's `k_descr`), then, with
/// `landmarks` (0-based vertices of this shape), the landmark variant of
/// the same family stacked column-wise; every `subsample`-th column kept.
#[pyfunction]
#[pyo3(signature = (shape, *, kind = "wks", n = 100, k = 128, landmarks = None, subsample = 1))]
fn descriptors<'py>(
    py: Python<'py>,
    shape: &PreparedShape,
    kind: &str,
    n: usize,
    k: usize,
    landmarks: Option<Bound<'_, PyAny>>,
    subsample: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    if k == 0 {
        return Err(err("k = 0: descriptors need at least one eigenpair"));
    }
    // As the pipeline does: at most the eigenpairs the shape holds.
    let p = descriptor_params(kind, n, k.min(shape.inner.basis.k()), subsample)?;
    let lms = match &landmarks {
        Some(l) => checked(l, shape.inner.basis.n(), "landmarks")?,
        None => Vec::new(),
    };
    let s = Arc::clone(&shape.inner);
    let d = py
        .detach(move || fmaps::pipeline::shape_descriptors(&s, &lms, &p))
        .map_err(err)?;
    Ok(fortran(d).into_pyarray(py))
}

/// The functional-map solve of the pipeline: `C_BA` (k x k, Fortran
/// order; B's coefficients to A's, the direction that goes with `map_ab`).
/// Descriptors: `descr_a` (n_A x p) and `descr_b` (n_B x p), any
/// per-vertex features with corresponding columns (e.g. learned ones), or
/// when not given the pipeline's (`kind`, `n`, `k_descr` (at most the
/// shapes' eigenpairs), `landmarks`: pairs
/// of 0-based vertices (of A, of B)). `w_descr`, `w_lap`, `w_dcomm`,
/// `w_orient`: relative weights of the energy's four terms (the
/// pipeline's defaults; only their ratios matter); `mirrored`: B is a
/// mirror image of A.
#[pyfunction]
#[pyo3(signature = (a, b, *, k = 50, descr_a = None, descr_b = None, kind = "wks", n = 100, k_descr = 128, landmarks = None, w_descr = 0.1, w_lap = 0.001, w_dcomm = 1.0, w_orient = 1.0, mirrored = false, threads = None))]
#[allow(clippy::too_many_arguments)]
fn fit<'py>(
    py: Python<'py>,
    a: &PreparedShape,
    b: &PreparedShape,
    k: usize,
    descr_a: Option<Bound<'_, PyAny>>,
    descr_b: Option<Bound<'_, PyAny>>,
    kind: &str,
    n: usize,
    k_descr: usize,
    landmarks: Option<Bound<'_, PyAny>>,
    w_descr: f64,
    w_lap: f64,
    w_dcomm: f64,
    w_orient: f64,
    mirrored: bool,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let mut params = descriptor_params(kind, n, k_descr, 1)?;
    params.k = k;
    params.energy.orient_reversing = mirrored;
    params.energy.weights = fmaps::solve::PerTerm {
        descr: w_descr,
        lap: w_lap,
        dcomm: w_dcomm,
        orient: w_orient,
    };
    params.descriptors.landmarks = landmark_pairs(landmarks, a.inner.basis.n(), b.inner.basis.n())?;
    let given = match (&descr_a, &descr_b) {
        (Some(x), Some(y)) => {
            if !params.descriptors.landmarks.is_empty() {
                return Err(err(
                    "landmarks are for the pipeline's descriptors: with descr_a and descr_b, add landmark columns to them",
                ));
            }
            Some((matrix(x, "descr_a")?, matrix(y, "descr_b")?))
        }
        (None, None) => None,
        _ => return Err(err("give both descr_a and descr_b, or neither")),
    };
    if k == 0 || k_descr == 0 {
        return Err(err(format!(
            "k = {k}, k_descr = {k_descr}: both must be at least 1"
        )));
    }
    let (pa, pb) = (Arc::clone(&a.inner), Arc::clone(&b.inner));
    let c = run(py, threads, move || {
        let (da, db) = match given {
            Some(d) => d,
            None => {
                let lm_a: Vec<usize> = params.descriptors.landmarks.iter().map(|p| p.0).collect();
                let lm_b: Vec<usize> = params.descriptors.landmarks.iter().map(|p| p.1).collect();
                (
                    fmaps::pipeline::shape_descriptors(&pa, &lm_a, &params)?,
                    fmaps::pipeline::shape_descriptors(&pb, &lm_b, &params)?,
                )
            }
        };
        fmaps::pipeline::fit_descriptors(&pa, &pb, &da, &db, &params)
    })?
    .map_err(err)?;
    Ok(fortran(c.c_ba).into_pyarray(py))
}

/// The first rows x cols of `c_ba` checked against the shapes' bases.
fn fmap_of(
    c_ba: &Bound<'_, PyAny>,
    a: &PreparedShape,
    b: &PreparedShape,
) -> PyResult<DMatrix<f64>> {
    let c = matrix(c_ba, "c_ba")?;
    let (ka, kb) = (a.inner.basis.k(), b.inner.basis.k());
    if c.nrows() == 0 || c.ncols() == 0 || c.nrows() > ka || c.ncols() > kb {
        return Err(err(format!(
            "c_ba is {} x {}: expected k_A x k_B with 1 <= k_A <= {ka} and 1 <= k_B <= {kb} (the eigenpairs A and B hold)",
            c.nrows(),
            c.ncols()
        )));
    }
    Ok(c)
}

/// The point map of a functional map (pyFM's `get_p2p`): for each vertex
/// x of A, `map_ab[x] = argmin_y ‖C_BA Φ_B(y)ᵀ − Φ_A(x)ᵀ‖` over the
/// vertices y of B (exact nearest neighbours); `adjoint`: `argmin_y
/// ‖Φ_B(y)ᵀ − C_BAᵀ Φ_A(x)ᵀ‖`. `c_ba` is k_A x k_B (rows: A's
/// coefficients).
#[pyfunction]
#[pyo3(signature = (c_ba, a, b, *, adjoint = false, threads = None))]
fn fmap_to_map<'py>(
    py: Python<'py>,
    c_ba: Bound<'_, PyAny>,
    a: &PreparedShape,
    b: &PreparedShape,
    adjoint: bool,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyArray1<i64>>> {
    let c = fmap_of(&c_ba, a, b)?;
    let (pa, pb) = (Arc::clone(&a.inner), Arc::clone(&b.inner));
    let t_ab = run(py, threads, move || {
        let (sb, sa) = (pb.basis.truncate(c.ncols()), pa.basis.truncate(c.nrows()));
        if adjoint {
            fmaps::solve::point_map_from_fmap_adjoint(&c, &sb, &sa)
        } else {
            fmaps::solve::point_map_from_fmap(&c, &sb, &sa)
        }
    })?
    .map_err(err)?;
    Ok(indices(py, &t_ab).into_bound(py))
}

/// The functional map of a point map: `C_BA = Φ_Aᵀ M_A Π_AB Φ_B` (k x k,
/// Fortran order), the pull-back of B's first k eigenfunctions along
/// `map_ab` in A's first k.
#[pyfunction]
#[pyo3(signature = (map_ab, a, b, *, k = 50))]
fn map_to_fmap<'py>(
    py: Python<'py>,
    map_ab: Bound<'_, PyAny>,
    a: &PreparedShape,
    b: &PreparedShape,
    k: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let t_ab = prepared_map(&map_ab, a, b)?;
    let most = a.inner.basis.k().min(b.inner.basis.k());
    if k == 0 || k > most {
        return Err(err(format!(
            "k = {k}: the shapes hold {most} eigenpairs (use 1..={most})"
        )));
    }
    let (pa, pb) = (Arc::clone(&a.inner), Arc::clone(&b.inner));
    let c = py
        .detach(move || {
            fmaps::solve::fmap_from_point_map(&t_ab, &pb.basis.truncate(k), &pa.basis.truncate(k))
        })
        .map_err(err)?;
    Ok(fortran(c).into_pyarray(py))
}

/// `map_ab` checked as a map between two prepared shapes.
fn prepared_map(
    map_ab: &Bound<'_, PyAny>,
    a: &PreparedShape,
    b: &PreparedShape,
) -> PyResult<Vec<usize>> {
    crate::map_between(map_ab, a.inner.basis.n(), b.inner.basis.n(), "map_ab")
}

/// The result of [`refine`].
#[pyclass(module = "fmaps._fmaps", frozen, get_all)]
struct RefinedMap {
    /// The refined map: for each vertex of A, a vertex of B (0-based).
    map_ab: Py<PyArray1<i64>>,
    /// `C_BA` after refinement (Fortran order).
    c_ba: Py<PyArray2<f64>>,
    /// The given map's `C_BA` (k x k): its pull-back, where the refiner
    /// started.
    c_ba_init: Py<PyArray2<f64>>,
    /// Orientation scores of the given and of the refined map.
    orientation_init: f64,
    /// See `orientation_init`.
    orientation: f64,
    /// The refiner's name ("" for "none").
    refiner: String,
    /// Seconds of each refinement step.
    seconds_per_iteration: Vec<f64>,
    /// Seconds in all (pull-back and refinement).
    seconds: f64,
}

/// A pickled [`RefinedMap`]'s fields, in declaration order.
type RefinedMapState = (
    Py<PyArray1<i64>>,
    Py<PyArray2<f64>>,
    Py<PyArray2<f64>>,
    f64,
    f64,
    String,
    Vec<f64>,
    f64,
);

#[pymethods]
impl RefinedMap {
    fn __repr__(&self) -> String {
        format!(
            "RefinedMap(refiner={:?}, orientation {:.3} -> {:.3}, {:.2} s)",
            self.refiner, self.orientation_init, self.orientation, self.seconds
        )
    }

    /// Pickling: the fields (numpy arrays and numbers).
    fn __reduce__<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyAny>, (RefinedMapState,))> {
        let state = (
            self.map_ab.clone_ref(py),
            self.c_ba.clone_ref(py),
            self.c_ba_init.clone_ref(py),
            self.orientation_init,
            self.orientation,
            self.refiner.clone(),
            self.seconds_per_iteration.clone(),
            self.seconds,
        );
        Ok((
            py.import("fmaps._fmaps")?
                .getattr("_refined_map_from_state")?,
            (state,),
        ))
    }
}

/// Rebuilds a [`RefinedMap`] from its pickled fields.
#[pyfunction]
fn _refined_map_from_state(state: RefinedMapState) -> RefinedMap {
    let (map_ab, c_ba, c_ba_init, orientation_init, orientation, refiner, per_step, seconds) =
        state;
    RefinedMap {
        map_ab,
        c_ba,
        c_ba_init,
        orientation_init,
        orientation,
        refiner,
        seconds_per_iteration: per_step,
        seconds,
    }
}

/// Refines `map_ab` (from any source: the pipeline, another tool, a
/// learned method) with the refiner `method`, one of `fmaps refine
/// --refine`'s: "zoomout", "icp", "bijective-zoomout", "discrete",
/// "bcicp", "smooth-shells" or "none". It starts from the map's k x k
/// pull-back. `schedule`: "START:FINAL:STEP" for ZoomOut and the discrete
/// presets (default 50:150:5); `sinkhorn`: convert with the Fast Sinkhorn
/// Filter. The shapes must hold the eigenpairs the refiner needs
/// (`prepare(..., k_process=...)`).
#[pyfunction]
#[pyo3(signature = (a, b, map_ab, *, method = "zoomout", k = 50, schedule = None, icp_iterations = None, bijective = false, adjoint = false, sinkhorn = false, mirrored = false, threads = None))]
#[allow(clippy::too_many_arguments)]
fn refine(
    py: Python<'_>,
    a: &PreparedShape,
    b: &PreparedShape,
    map_ab: Bound<'_, PyAny>,
    method: &str,
    k: usize,
    schedule: Option<String>,
    icp_iterations: Option<usize>,
    bijective: bool,
    adjoint: bool,
    sinkhorn: bool,
    mirrored: bool,
    threads: Option<usize>,
) -> PyResult<RefinedMap> {
    if method == "default" {
        return Err(err(
            "method = \"default\": name the refiner (\"smooth-shells\" is match_shapes' default)",
        ));
    }
    let kind = refiner_kind(method, 0)?;
    let t_ab = prepared_map(&map_ab, a, b)?;
    let mut options = RefineOptions::for_map_size(k);
    options.schedule = schedule;
    options.icp_iterations = icp_iterations.unwrap_or(options.icp_iterations);
    options.bijective = bijective;
    options.adjoint = adjoint;
    options.sinkhorn = sinkhorn;
    options.mirrored = mirrored;
    let mut params = MatchParams::unrefined();
    params.k = k;
    params.refinement = fmaps::pipeline::named_refinement(kind, &options)
        .map_err(|e| err(format!("method = {method:?}: {e}")))?;
    params.adjoint = adjoint;
    params.area_normalize = a.area_normalize;
    let (pa, pb) = (Arc::clone(&a.inner), Arc::clone(&b.inner));
    let r = run(py, threads, move || {
        fmaps::pipeline::refine_point_map(&pa, &pb, &t_ab, &params)
    })?
    .map_err(err)?;
    let (refiner, seconds_per_iteration) = crate::refiner_summary(r.refine.as_ref());
    Ok(RefinedMap {
        map_ab: indices(py, &r.t_ab),
        c_ba: fortran(r.c_ba).into_pyarray(py).unbind(),
        c_ba_init: fortran(r.c_ba_init).into_pyarray(py).unbind(),
        orientation_init: r.orientation_init,
        orientation: r.orientation,
        refiner,
        seconds_per_iteration,
        seconds: r.seconds,
    })
}

/// The geodesic distance method `method` on `mesh`.
pub(crate) fn distance_solver(
    method: &str,
    mesh: &TriMesh,
) -> Result<Box<dyn DistanceSolver + Send>, String> {
    Ok(match method {
        "exact" => Box::new(ExactSolver::new(mesh).map_err(|e| e.to_string())?),
        "heat" => {
            Box::new(HeatSolver::new(mesh, &HeatParams::default()).map_err(|e| e.to_string())?)
        }
        "dijkstra" => Box::new(DijkstraSolver::new(mesh)),
        other => {
            return Err(format!(
                "geodesic = {other:?}: expected \"exact\", \"heat\" or \"dijkstra\""
            ));
        }
    })
}

/// Geodesic distances on `mesh` from `sources` (0-based vertices):
/// "exact" (polyhedral, exact to rounding), "heat" (the heat method,
/// approximate) or "dijkstra" (along edges, an upper bound). Returns the
/// distance from the nearest source to every vertex (n,), or with
/// `per_source` one row per source (len(sources) x n, computed in
/// parallel).
#[pyfunction]
#[pyo3(signature = (mesh, sources, *, method = "exact", per_source = false, threads = None))]
fn geodesics<'py>(
    py: Python<'py>,
    mesh: &Mesh,
    sources: Bound<'_, PyAny>,
    method: &str,
    per_source: bool,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyAny>> {
    let m = Arc::clone(&mesh.inner);
    let src = checked(&sources, m.n_vertices(), "sources")?;
    if src.is_empty() {
        return Err(err("sources is empty"));
    }
    let method = method.to_string();
    let n = m.n_vertices();
    let out = run(py, threads, move || {
        let solver = distance_solver(&method, &m)?;
        if per_source {
            solver.fields(&src).map_err(|e| e.to_string())
        } else {
            solver
                .distances(&src)
                .map(|d| vec![d])
                .map_err(|e| e.to_string())
        }
    })?
    .map_err(err)?;
    if per_source {
        let rows = out.len();
        let flat: Vec<f64> = out.into_iter().flatten().collect();
        let a = Array2::from_shape_vec((rows, n), flat).expect("rows x n");
        Ok(a.into_pyarray(py).into_any())
    } else {
        let d = out.into_iter().next().expect("one field");
        Ok(d.into_pyarray(py).into_any())
    }
}

/// Scores of `map_ab` that need no ground truth (the ones `fmaps match
/// --json` reports and multi-start selects by): coverage (share of B's
/// vertices hit), area_coverage, collapsed_faces, area_distortion,
/// conformal_distortion, orientation (near 1: orientation preserved, near
/// −1: mirrored), and with `map_ba` round_trip (mean distance from x to
/// `map_ba[map_ab[x]]` over √area(A)). Meshes as given (scale them to unit
/// area to compare pairs).
#[pyfunction]
#[pyo3(signature = (a, b, map_ab, map_ba = None))]
fn map_quality<'py>(
    py: Python<'py>,
    a: &Mesh,
    b: &Mesh,
    map_ab: Bound<'_, PyAny>,
    map_ba: Option<Bound<'_, PyAny>>,
) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
    let (na, nb) = (a.inner.n_vertices(), b.inner.n_vertices());
    let t_ab = crate::map_between(&map_ab, na, nb, "map_ab")?;
    let t_ba = map_ba
        .map(|m| crate::map_between(&m, nb, na, "map_ba"))
        .transpose()?;
    let (ma, mb) = (Arc::clone(&a.inner), Arc::clone(&b.inner));
    let (q, orientation) = py
        .detach(move || {
            let q = fmaps::eval::map_quality(&t_ab, &ma, &mb, t_ba.as_deref())
                .map_err(|e| e.to_string())?;
            let o = fmaps::refine::orientation_score(
                &t_ab,
                ma.vertices(),
                ma.faces(),
                mb.vertices(),
                mb.faces(),
            )
            .map_err(|e| e.to_string())?;
            Ok::<_, String>((q, o))
        })
        .map_err(err)?;
    let d = crate::quality_dict(py, &q)?;
    d.set_item("orientation", orientation)?;
    Ok(d)
}

/// Adds this module's functions and classes to the extension module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<RefinedMap>()?;
    m.add_function(wrap_pyfunction!(_refined_map_from_state, m)?)?;
    m.add_function(wrap_pyfunction!(descriptors, m)?)?;
    m.add_function(wrap_pyfunction!(fit, m)?)?;
    m.add_function(wrap_pyfunction!(fmap_to_map, m)?)?;
    m.add_function(wrap_pyfunction!(map_to_fmap, m)?)?;
    m.add_function(wrap_pyfunction!(refine, m)?)?;
    m.add_function(wrap_pyfunction!(geodesics, m)?)?;
    m.add_function(wrap_pyfunction!(map_quality, m)?)?;
    Ok(())
}
