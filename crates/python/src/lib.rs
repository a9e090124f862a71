//! Python bindings of fmaps: the extension module `fmaps._fmaps` of the
//! `fmaps` wheel (built by maturin from `pyproject.toml`; the package's
//! Python part, type stubs and tests live beside it in `python/` and
//! `tests/`).
//!
//! What Python sees: `Mesh` (load OFF/OBJ/PLY, or from numpy arrays,
//! validated), `spectrum` (eigenvalues, basis, mass), `match_shapes` (the
//! pipeline of `fmaps match`, same defaults, same maps), `evaluate` (the
//! benchmark protocol: geodesic errors against ground truth),
//! the scores without ground truth of each result, the correspondence
//! file reader and the built-in pairs of `fmaps demo`. Maps are named by direction: `map_ab[i]` is the vertex
//! of B that vertex `i` of A goes to, 0-based. Long calls release the GIL
//! and run on `threads` threads (all cores by default). Errors raise
//! `fmaps.FmapsError` (a `ValueError`) with the CLI's message.
//!
//! Arrays come out without copies: Rust's vectors and column-major
//! matrices become numpy arrays (C- or Fortran-ordered) that own them.
//! Meshes are copied in (a mesh owns its vertices and faces).
//!
//! (tidy: long file: one `#[pymodule]` is one Rust module here; its
//! functions share the argument conversions, the error mapping and the
//! GIL-free runner, and each is a thin call into the facade.)
#![deny(unsafe_code)]

mod convert;
mod display;
mod learned;
mod stages;

use std::path::PathBuf;
use std::sync::Arc;

use fmaps::mesh_io::TriMesh;
use fmaps::pipeline::{MatchParams, RefineOptions, RefineSampling, RefinerKind};
use fmaps::solve::PerTerm;
use nalgebra::DMatrix;
use numpy::ndarray::{Array1, Array2, Array3, ShapeBuilder};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;

pyo3::create_exception!(
    _fmaps,
    FmapsError,
    PyValueError,
    "Bad input or a failed computation; the message is the one `fmaps` prints."
);

/// The error of a fmaps call, with its causes (as the CLI prints them).
fn err(e: impl std::fmt::Display) -> PyErr {
    FmapsError::new_err(e.to_string())
}

/// The error about a file: its path first, as the CLI names it.
fn err_on(path: &std::path::Path) -> impl Fn(fmaps::mesh_io::Error) -> PyErr + '_ {
    move |e| FmapsError::new_err(format!("{}: {e}", path.display()))
}

/// Runs `f` without the GIL on a pool of `threads` threads (`None` or 0:
/// one per core).
fn run<T: Send>(
    py: Python<'_>,
    threads: Option<usize>,
    f: impl FnOnce() -> T + Send,
) -> PyResult<T> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.unwrap_or(0))
        .build()
        .map_err(|e| err(format!("threads = {threads:?}: {e}")))?;
    Ok(py.detach(|| pool.install(f)))
}

/// A triangle mesh: vertex positions and oriented triangles (0-based),
/// validated on construction (finite coordinates, indices in range, no
/// repeated vertex in a triangle).
#[pyclass(module = "fmaps._fmaps", frozen)]
struct Mesh {
    inner: Arc<TriMesh>,
}

#[pymethods]
impl Mesh {
    /// A mesh from `vertices` (n x 3 coordinates: any real array-like,
    /// float32 or float64, lists) and `faces` (m x 3 vertex indices,
    /// 0-based: any integer array-like, int32, uint32, int64, lists).
    #[new]
    fn new(vertices: &Bound<'_, PyAny>, faces: &Bound<'_, PyAny>) -> PyResult<Self> {
        let v = convert::floats2(vertices, "vertices")?;
        let f = convert::ints2(faces, "faces", 3)?;
        Self::from_arrays(&v, &f)
    }

    /// Pickling (and Ray, multiprocessing): rebuilt from its vertices and
    /// faces, validated again.
    #[allow(clippy::type_complexity)]
    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
    ) -> PyResult<(Bound<'py, PyAny>, (Bound<'py, PyAny>, Bound<'py, PyAny>))> {
        let m = slf.get();
        Ok((
            slf.get_type().into_any(),
            (
                m.vertices(slf.py()).into_any(),
                m.faces(slf.py()).into_any(),
            ),
        ))
    }

    /// Reads an OFF, OBJ or PLY file (errors name the file and line).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        let mesh = fmaps::mesh_io::read_mesh(&path).map_err(err_on(&path))?;
        Ok(Mesh {
            inner: Arc::new(mesh),
        })
    }

    /// Writes the mesh (format from the extension: .off, .obj, .ply),
    /// atomically.
    fn save(&self, path: PathBuf) -> PyResult<()> {
        fmaps::mesh_io::write_mesh(&path, &self.inner).map_err(err_on(&path))
    }

    /// Vertex positions (n x 3 float64, a copy).
    #[getter]
    fn vertices<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let v = self.inner.vertices();
        let flat: Vec<f64> = v.iter().flatten().copied().collect();
        Array2::from_shape_vec((v.len(), 3), flat)
            .expect("n x 3")
            .into_pyarray(py)
    }

    /// Triangles (m x 3 int64, 0-based, a copy).
    #[getter]
    fn faces<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<i64>> {
        let f = self.inner.faces();
        let flat: Vec<i64> = f.iter().flatten().map(|&i| i as i64).collect();
        Array2::from_shape_vec((f.len(), 3), flat)
            .expect("m x 3")
            .into_pyarray(py)
    }

    /// Number of vertices.
    #[getter]
    fn n_vertices(&self) -> usize {
        self.inner.n_vertices()
    }

    /// Number of triangles.
    #[getter]
    fn n_faces(&self) -> usize {
        self.inner.faces().len()
    }

    /// Total surface area.
    fn area(&self) -> f64 {
        self.inner.area()
    }

    /// The validation report of `fmaps info`: counts (n_vertices,
    /// n_faces, n_edges), area, bounding_box, the defects as lists of
    /// 0-based elements (degenerate_faces, duplicate_faces,
    /// non_manifold_edges, non_manifold_vertices, unreferenced_vertices),
    /// boundary_edges, boundary_loops, connected_components,
    /// inconsistently_oriented_edges, euler_characteristic, genus (None
    /// unless manifold), is_manifold, is_closed_manifold.
    fn validate<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let r = self.inner.validate();
        let d = PyDict::new(py);
        d.set_item("n_vertices", r.n_vertices)?;
        d.set_item("n_faces", r.n_faces)?;
        d.set_item("n_edges", r.n_edges)?;
        d.set_item("area", r.area)?;
        d.set_item("bounding_box", r.bounding_box.to_vec())?;
        d.set_item("degenerate_faces", r.degenerate_faces.clone())?;
        d.set_item("duplicate_faces", r.duplicate_faces.clone())?;
        d.set_item("non_manifold_edges", r.non_manifold_edges.clone())?;
        d.set_item("non_manifold_vertices", r.non_manifold_vertices.clone())?;
        d.set_item("unreferenced_vertices", r.unreferenced_vertices.clone())?;
        d.set_item("boundary_edges", r.boundary_edges)?;
        d.set_item("boundary_loops", r.boundary_loops)?;
        d.set_item("connected_components", r.connected_components)?;
        d.set_item(
            "inconsistently_oriented_edges",
            r.inconsistently_oriented_edges,
        )?;
        d.set_item("euler_characteristic", r.euler_characteristic)?;
        d.set_item("genus", r.genus)?;
        d.set_item("is_manifold", r.is_manifold())?;
        d.set_item("is_closed_manifold", r.is_closed_manifold())?;
        Ok(d)
    }

    /// The notebook's display: the interactive viewer (turn, zoom, pick).
    fn _repr_html_(&self) -> PyResult<String> {
        Ok(display::iframe(&display::mesh_page(&self.inner)?))
    }

    /// The display without scripts: a picture coloured by position.
    fn _repr_png_<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyBytes>> {
        display::mesh_png(py, &self.inner)
    }

    fn __repr__(&self) -> String {
        format!(
            "Mesh({} vertices, {} faces)",
            self.inner.n_vertices(),
            self.inner.faces().len()
        )
    }
}

impl Mesh {
    /// A mesh from float64 vertices and int64 faces, validated.
    fn from_arrays(
        vertices: &PyReadonlyArray2<'_, f64>,
        faces: &PyReadonlyArray2<'_, i64>,
    ) -> PyResult<Self> {
        let (v, f) = (vertices.as_array(), faces.as_array());
        if v.ncols() != 3 || f.ncols() != 3 {
            return Err(err(format!(
                "vertices must be n x 3 and faces m x 3, got {:?} and {:?}",
                v.shape(),
                f.shape()
            )));
        }
        let verts: Vec<[f64; 3]> = v.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect();
        let mut tris = Vec::with_capacity(f.nrows());
        for (i, r) in f.rows().into_iter().enumerate() {
            let mut t = [0usize; 3];
            for (d, &x) in r.iter().enumerate() {
                t[d] = usize::try_from(x)
                    .map_err(|_| err(format!("face {i}: negative vertex index {x}")))?;
            }
            tris.push(t);
        }
        let mesh = TriMesh::new(verts, tris).map_err(err)?;
        Ok(Mesh {
            inner: Arc::new(mesh),
        })
    }
}

/// The first `k` Laplace–Beltrami eigenpairs of `mesh` as given (cotangent
/// Laplacian, lumped mass): `(eigenvalues (k,), basis (n x k, Fortran
/// order, orthonormal in the mass), mass (n,))`.
#[pyfunction]
#[pyo3(signature = (mesh, k = 200, threads = None))]
#[allow(clippy::type_complexity)]
fn spectrum<'py>(
    py: Python<'py>,
    mesh: &Mesh,
    k: usize,
    threads: Option<usize>,
) -> PyResult<(
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
)> {
    let m = Arc::clone(&mesh.inner);
    let mut params = fmaps::SpectrumParams::default();
    params.threads = threads.unwrap_or(0);
    let out = run(py, threads, move || fmaps::spectrum(&m, k, &params))?.map_err(err)?;
    let basis = out.basis;
    Ok((
        basis.eigenvalues.as_slice().to_vec().into_pyarray(py),
        fortran(basis.eigenvectors).into_pyarray(py),
        basis.mass.as_slice().to_vec().into_pyarray(py),
    ))
}

/// A column-major matrix as a Fortran-ordered array (no copy).
fn fortran(m: DMatrix<f64>) -> Array2<f64> {
    let (r, c) = m.shape();
    Array2::from_shape_vec((r, c).f(), m.data.into()).expect("r x c")
}

/// The pipeline's parameters for `refine` (the names of `fmaps match
/// --refine`, or "default": what `fmaps match` runs without flags, the
/// facade's [`RefinerKind::default_for`]) on the schedule `schedule`
/// (`START:FINAL:STEP`, None: 50:150:5) where the refiner has one, from the
/// further starts `fmaps match` uses for that refiner, for meshes of
/// `n_a` and `n_b` vertices (a ZoomOut samples them as `fmaps match`
/// does: [`fmaps::pipeline::RefineSampling`]).
#[allow(clippy::too_many_arguments)]
fn params_for(
    refine: &str,
    schedule: Option<String>,
    (n_a, n_b): (usize, usize),
    k: usize,
    k_process: usize,
    weights: PerTerm,
    (mirrored, non_isometric, second_opinion): (bool, bool, bool),
    area_normalize: bool,
) -> PyResult<MatchParams> {
    let mut p = MatchParams::unrefined();
    p.k = k;
    p.k_process = k_process;
    p.descriptors.eigenpairs = MatchParams::default().descriptors.eigenpairs.min(k_process);
    p.energy.orient_reversing = mirrored;
    p.area_normalize = area_normalize;
    p.energy.weights = weights;
    let kind = refiner_kind(refine, n_a.min(n_b))?;
    let mut options = RefineOptions::for_map_size(k);
    options.schedule = schedule;
    options.mirrored = mirrored;
    options.non_isometric = non_isometric;
    options.second_opinion = second_opinion;
    options.samples = RefineSampling::default().samples_for(n_a, n_b);
    p.set_refinement(kind, &options)
        .map_err(|e| err(format!("refine = {refine:?}: {e}")))?;
    Ok(p)
}

/// The refinement named `refine` ("default": the facade's choice for
/// meshes whose smaller one has `smallest` vertices).
fn refiner_kind(refine: &str, smallest: usize) -> PyResult<RefinerKind> {
    match refine {
        "default" => Ok(RefinerKind::default_for(smallest)),
        name => name
            .parse()
            .map_err(|e| err(format!("refine = {refine:?}: {e} or \"default\""))),
    }
}

/// The result of [`match_shapes`].
#[pyclass(module = "fmaps._fmaps", frozen, get_all)]
struct MatchResult {
    /// For each vertex of A, the vertex of B it goes to (int64, 0-based).
    map_ab: Py<PyArray1<i64>>,
    /// The initial map (before refinement), same convention.
    map_ab_init: Py<PyArray1<i64>>,
    /// `C_BA`: coefficients on B to coefficients on A (Fortran order).
    c_ba: Py<PyArray2<f64>>,
    /// Orientation score of `map_ab` (near 1 preserved, near −1 mirrored).
    orientation: f64,
    /// How far `map_ab` can be trusted without ground truth:
    /// `metric_distortion` (distortion of distances between samples spread
    /// over A; 0 kept), `long_range`, `area_distortion`, `likely_wrong`
    /// (either above its `warn_above`: the map is likely globally
    /// misaligned), `advice` (what to try then, else None).
    confidence: Py<PyDict>,
    /// Seconds per stage: spectra, descriptors, operators, solve,
    /// point_map, refine, total.
    times: Py<PyDict>,
    /// Scores of `map_ab` without ground truth (coverage, area_coverage,
    /// collapsed_faces, area_distortion, conformal_distortion).
    quality: Py<PyDict>,
    /// The refiner's name ("" without refinement).
    refiner: String,
    /// Seconds of each refinement step (Smooth Shells: rigid alignment,
    /// initialisation, then its levels).
    seconds_per_iteration: Vec<f64>,
    /// The meshes matched (A, B; the prepared, unit-area ones after
    /// `match_prepared`), which the notebook display draws.
    meshes: (Py<Mesh>, Py<Mesh>),
}

/// A pickled [`MatchResult`]'s fields, in declaration order.
type MatchResultState = (
    Py<PyArray1<i64>>,
    Py<PyArray1<i64>>,
    Py<PyArray2<f64>>,
    f64,
    Py<PyDict>,
    Py<PyDict>,
    Py<PyDict>,
    String,
    Vec<f64>,
    (Py<Mesh>, Py<Mesh>),
);

#[pymethods]
impl MatchResult {
    fn __repr__(&self) -> String {
        format!(
            "MatchResult(refiner={:?}, orientation={:.3})",
            self.refiner, self.orientation
        )
    }

    /// The notebook's display: the map in the interactive viewer (colour
    /// and texture transfer, picking).
    fn _repr_html_(&self, py: Python<'_>) -> PyResult<String> {
        let (a, b, t_ab) = self.parts(py)?;
        let title = format!("map A \u{2192} B ({})", self.refiner_label());
        Ok(display::iframe(&display::map_page(
            &title,
            &a,
            &b,
            &t_ab,
            None,
            fmaps::viz::Axis::Y,
        )?))
    }

    /// The display without scripts: the colour transfer as a picture.
    fn _repr_png_<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, pyo3::types::PyBytes>> {
        let (a, b, t_ab) = self.parts(py)?;
        display::map_png(py, &a, &b, &t_ab)
    }

    /// Pickling: the fields (numpy arrays, dicts, numbers).
    fn __reduce__<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyAny>, (MatchResultState,))> {
        let state = (
            self.map_ab.clone_ref(py),
            self.map_ab_init.clone_ref(py),
            self.c_ba.clone_ref(py),
            self.orientation,
            self.confidence.clone_ref(py),
            self.times.clone_ref(py),
            self.quality.clone_ref(py),
            self.refiner.clone(),
            self.seconds_per_iteration.clone(),
            (self.meshes.0.clone_ref(py), self.meshes.1.clone_ref(py)),
        );
        Ok((
            py.import("fmaps._fmaps")?
                .getattr("_match_result_from_state")?,
            (state,),
        ))
    }
}

impl MatchResult {
    /// The two meshes and the map.
    fn parts(&self, py: Python<'_>) -> PyResult<(Arc<TriMesh>, Arc<TriMesh>, Vec<usize>)> {
        let a = Arc::clone(&self.meshes.0.get().inner);
        let b = Arc::clone(&self.meshes.1.get().inner);
        let t_ab = map_between(
            self.map_ab.bind(py).as_any(),
            a.n_vertices(),
            b.n_vertices(),
            "map_ab",
        )?;
        Ok((a, b, t_ab))
    }

    fn refiner_label(&self) -> &str {
        if self.refiner.is_empty() {
            "initial map"
        } else {
            &self.refiner
        }
    }
}

/// Rebuilds a [`MatchResult`] from its pickled fields.
#[pyfunction]
fn _match_result_from_state(state: MatchResultState) -> MatchResult {
    let (
        map_ab,
        map_ab_init,
        c_ba,
        orientation,
        confidence,
        times,
        quality,
        refiner,
        seconds,
        meshes,
    ) = state;
    MatchResult {
        map_ab,
        map_ab_init,
        c_ba,
        orientation,
        confidence,
        times,
        quality,
        refiner,
        seconds_per_iteration: seconds,
        meshes,
    }
}

fn indices(py: Python<'_>, v: &[usize]) -> Py<PyArray1<i64>> {
    v.iter()
        .map(|&i| i as i64)
        .collect::<Vec<_>>()
        .into_pyarray(py)
        .unbind()
}

/// Matches `a` to `b` with the pipeline of `fmaps match` (the same
/// defaults and the same maps for the same options, on any number of
/// threads).
#[pyfunction]
#[pyo3(signature = (a, b, *, refine = "default", k = 50, k_process = None, schedule = None, landmarks = None, w_descr = 0.1, w_lap = 0.001, w_dcomm = 1.0, w_orient = 1.0, mirrored = false, non_isometric = false, second_opinion = false, area_normalize = true, starts = None, features = "descriptors", model = None, adapt = 0, point_map = None, threads = None))]
#[allow(clippy::too_many_arguments)]
fn match_shapes(
    py: Python<'_>,
    a: &Bound<'_, Mesh>,
    b: &Bound<'_, Mesh>,
    refine: &str,
    k: usize,
    k_process: Option<usize>,
    schedule: Option<String>,
    landmarks: Option<Bound<'_, PyAny>>,
    w_descr: f64,
    w_lap: f64,
    w_dcomm: f64,
    w_orient: f64,
    mirrored: bool,
    non_isometric: bool,
    second_opinion: bool,
    area_normalize: bool,
    starts: Option<Vec<usize>>,
    features: &str,
    model: Option<PathBuf>,
    adapt: usize,
    point_map: Option<String>,
    threads: Option<usize>,
) -> PyResult<MatchResult> {
    let (ma, mb) = (Arc::clone(&a.get().inner), Arc::clone(&b.get().inner));
    let landmarks = stages::landmark_pairs(landmarks, ma.n_vertices(), mb.n_vertices())?;
    let sizes = (ma.n_vertices(), mb.n_vertices());
    let learned = learned::learned_of(features, model, adapt, point_map.as_deref())?;
    let (refine, k, schedule) =
        learned::refine_for(refine, learned.is_some(), sizes.0.min(sizes.1), k, schedule);
    let mut params = params_for(
        refine,
        schedule,
        sizes,
        k,
        k_process.unwrap_or(MatchParams::default().k_process),
        PerTerm {
            descr: w_descr,
            lap: w_lap,
            dcomm: w_dcomm,
            orient: w_orient,
        },
        (mirrored, non_isometric, second_opinion),
        area_normalize,
    )?;
    if let Some(s) = starts {
        // Further initial sizes (`[]`: one start, as pyFM runs ZoomOut).
        params.starts.sizes = s;
    }
    learned::apply(
        &mut params,
        learned.map(|l| if non_isometric { l.non_isometric() } else { l }),
    );
    // As `fmaps match`: the eigenpairs the pipeline uses, or those given
    // (at least the refinement's).
    params.k_process = match k_process {
        Some(kp) => kp.max(params.refinement.k_needed()),
        None => params.k_process_needed(),
    };
    if second_opinion && learned_features(&params) {
        params = params
            .with_axiomatic_opinion(sizes.0, sizes.1)
            .map_err(err)?;
    }
    params.descriptors.landmarks = landmarks;
    let (r, quality) = run(py, threads, move || {
        let r = fmaps::match_shapes(&ma, &mb, &params).map_err(|e| e.to_string())?;
        let q = fmaps::eval::map_quality(&r.t_ab, &ma, &mb, None).map_err(|e| e.to_string())?;
        Ok::<_, String>((r, q))
    })?
    .map_err(err)?;
    result(py, r, quality, (a.clone().unbind(), b.clone().unbind()))
}

/// Whether `params` match with learned features (then `second_opinion`
/// runs the descriptor pipeline beside them).
fn learned_features(params: &MatchParams) -> bool {
    matches!(params.features, fmaps::pipeline::Features::Learned(_))
}

/// The refiner's name and the seconds of each of its steps ("" and none
/// without refinement).
fn refiner_summary(report: Option<&fmaps::refine::RefineReport>) -> (String, Vec<f64>) {
    report.map_or_else(Default::default, |rep| {
        (
            rep.method.clone(),
            rep.iterations.iter().map(|i| i.seconds).collect(),
        )
    })
}

/// The scores of [`fmaps::eval::map_quality`] as a dict.
fn quality_dict<'py>(
    py: Python<'py>,
    quality: &fmaps::eval::MapQuality,
) -> PyResult<Bound<'py, PyDict>> {
    let q = PyDict::new(py);
    q.set_item("coverage", quality.coverage)?;
    q.set_item("area_coverage", quality.area_coverage)?;
    q.set_item("collapsed_faces", quality.collapsed_faces)?;
    q.set_item("area_distortion", quality.area_distortion)?;
    q.set_item("conformal_distortion", quality.conformal_distortion)?;
    if let Some(r) = quality.round_trip {
        q.set_item("round_trip", r)?;
    }
    Ok(q)
}

/// The Python result of a pipeline run and its quality scores.
fn result(
    py: Python<'_>,
    r: fmaps::MatchResult,
    quality: fmaps::eval::MapQuality,
    meshes: (Py<Mesh>, Py<Mesh>),
) -> PyResult<MatchResult> {
    let times = PyDict::new(py);
    let t = r.times;
    for (name, v) in [
        ("spectra", t.spectra),
        ("descriptors", t.descriptors),
        ("operators", t.operators),
        ("solve", t.solve),
        ("point_map", t.point_map),
        ("refine", t.refine),
        ("total", t.total),
    ] {
        times.set_item(name, v)?;
    }
    let q = quality_dict(py, &quality)?;
    let (refiner, seconds_per_iteration) = refiner_summary(r.refine.as_ref());
    let confidence = PyDict::new(py);
    if let Some(c) = r.confidence {
        confidence.set_item("metric_distortion", c.distortion)?;
        confidence.set_item("long_range", c.long_range)?;
        confidence.set_item("area_distortion", c.area_distortion)?;
        confidence.set_item("likely_wrong", c.likely_wrong)?;
        let warn = PyDict::new(py);
        warn.set_item("metric_distortion", fmaps::pipeline::Confidence::WARN_ABOVE)?;
        warn.set_item(
            "area_distortion",
            fmaps::pipeline::Confidence::WARN_AREA_ABOVE,
        )?;
        confidence.set_item("warn_above", warn)?;
        confidence.set_item("advice", c.advice())?;
    }
    if let Some(p) = &r.passed_over {
        let d = PyDict::new(py);
        d.set_item("features", p.features)?;
        d.set_item("refiner", p.refiner.clone())?;
        d.set_item("area_distortion", p.area_distortion)?;
        d.set_item("orientation", p.orientation)?;
        confidence.set_item("passed_over", d)?;
    }
    Ok(MatchResult {
        map_ab: indices(py, &r.t_ab),
        map_ab_init: indices(py, &r.t_ab_init),
        c_ba: fortran(r.c_ba).into_pyarray(py).unbind(),
        orientation: r.orientation,
        confidence: confidence.unbind(),
        times: times.unbind(),
        quality: q.unbind(),
        refiner,
        seconds_per_iteration,
        meshes,
    })
}

/// One shape after the per-shape stages (scaled to unit area unless told
/// otherwise; Laplacian and `k_process` eigenpairs), reusable across all
/// its pairs: [`match_prepared`] takes two. Picklable (numpy arrays), so
/// Ray and multiprocessing pass it between processes.
#[pyclass(module = "fmaps._fmaps", frozen)]
struct PreparedShape {
    inner: Arc<fmaps::pipeline::PreparedShape>,
    area_normalize: bool,
}

#[pymethods]
impl PreparedShape {
    /// Eigenpairs held.
    #[getter]
    fn k_process(&self) -> usize {
        self.inner.basis.eigenvalues.len()
    }

    /// Vertices.
    #[getter]
    fn n_vertices(&self) -> usize {
        self.inner.vertices.len()
    }

    /// Seconds its Laplacian and eigenbasis took.
    #[getter]
    fn seconds(&self) -> f64 {
        self.inner.seconds
    }

    /// Its eigenvalues (k_process,).
    #[getter]
    fn eigenvalues<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner
            .basis
            .eigenvalues
            .as_slice()
            .to_vec()
            .into_pyarray(py)
    }

    /// Its eigenbasis (n x k_process, Fortran order, orthonormal in the
    /// mass; a copy).
    #[getter]
    fn basis<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        fortran(self.inner.basis.eigenvectors.clone()).into_pyarray(py)
    }

    /// Its lumped mass (n,).
    #[getter]
    fn mass<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        self.inner.basis.mass.as_slice().to_vec().into_pyarray(py)
    }

    /// The mesh as prepared (scaled to unit area unless `area_normalize`
    /// was off).
    #[getter]
    fn mesh(&self) -> PyResult<Mesh> {
        let p = &self.inner;
        Ok(Mesh {
            inner: Arc::new(TriMesh::new(p.vertices.clone(), p.faces.clone()).map_err(err)?),
        })
    }

    /// The input mesh's area (the prepared one has area 1 unless
    /// `area_normalize` was off).
    #[getter]
    fn input_area(&self) -> f64 {
        self.inner.input_area
    }

    fn __repr__(&self) -> String {
        format!(
            "PreparedShape({} vertices, {} eigenpairs)",
            self.n_vertices(),
            self.k_process()
        )
    }

    /// Pickling: the state as numpy arrays and numbers.
    fn __reduce__<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let p = &self.inner;
        let verts: Vec<f64> = p.vertices.iter().flatten().copied().collect();
        let faces: Vec<i64> = p.faces.iter().flatten().map(|&i| i as i64).collect();
        let state = (
            Array2::from_shape_vec((p.vertices.len(), 3), verts)
                .expect("n x 3")
                .into_pyarray(py),
            Array2::from_shape_vec((p.faces.len(), 3), faces)
                .expect("m x 3")
                .into_pyarray(py),
            p.basis.eigenvalues.as_slice().to_vec().into_pyarray(py),
            fortran(p.basis.eigenvectors.clone()).into_pyarray(py),
            p.basis.mass.as_slice().to_vec().into_pyarray(py),
            (
                p.area,
                p.input_area,
                p.scale,
                p.seconds,
                self.area_normalize,
            ),
        );
        let module = py.import("fmaps._fmaps")?;
        Ok((
            module.getattr("_prepared_from_state")?,
            (state,).into_pyobject(py)?.into_any(),
        ))
    }
}

/// Rebuilds a [`PreparedShape`] from its pickled state.
#[pyfunction]
#[allow(clippy::type_complexity)]
fn _prepared_from_state(
    state: (
        PyReadonlyArray2<'_, f64>,
        PyReadonlyArray2<'_, i64>,
        PyReadonlyArray1<'_, f64>,
        PyReadonlyArray2<'_, f64>,
        PyReadonlyArray1<'_, f64>,
        (f64, f64, f64, f64, bool),
    ),
) -> PyResult<PreparedShape> {
    let (v, f, evals, vecs, mass, (area, input_area, scale, seconds, area_normalize)) = state;
    let mesh = Mesh::from_arrays(&v, &f)?;
    let vecs = vecs.as_array();
    let (n, k) = (vecs.nrows(), vecs.ncols());
    if n != mesh.inner.n_vertices() || evals.len()? != k || mass.len()? != n {
        return Err(err(
            "a pickled PreparedShape whose arrays do not fit together",
        ));
    }
    let mut report = fmaps::eigensolve::SolveReport::default();
    report.backend = "pickle";
    let basis = fmaps::eigensolve::SpectralBasis {
        eigenvalues: nalgebra::DVector::from_iterator(k, evals.as_array().iter().copied()),
        eigenvectors: DMatrix::from_fn(n, k, |i, j| vecs[(i, j)]),
        mass: nalgebra::DVector::from_iterator(n, mass.as_array().iter().copied()),
        report,
    };
    Ok(PreparedShape {
        inner: Arc::new(fmaps::pipeline::PreparedShape {
            vertices: mesh.inner.vertices().to_vec(),
            faces: mesh.inner.faces().to_vec(),
            basis,
            area,
            input_area,
            scale,
            seconds,
            learned: None,
        }),
        area_normalize,
    })
}

/// The per-shape stages of the pipeline for `mesh`: scaled to unit area
/// (unless `area_normalize` is off), Laplacian, `k_process` eigenpairs,
/// and with `features = "learned"` the network's operators and features
/// (of `model`, the shipped one by default; `adapt` > 0 prepares the
/// eigenpairs its losses need). Compute it once per shape and match it
/// with [`match_prepared`] against every other (the maps equal
/// [`match_shapes`]'s).
#[pyfunction]
#[pyo3(signature = (mesh, *, k_process = 200, area_normalize = true, features = "descriptors", model = None, adapt = 0, threads = None))]
#[allow(clippy::too_many_arguments)]
fn prepare(
    py: Python<'_>,
    mesh: &Mesh,
    k_process: usize,
    area_normalize: bool,
    features: &str,
    model: Option<std::path::PathBuf>,
    adapt: usize,
    threads: Option<usize>,
) -> PyResult<PreparedShape> {
    let m = Arc::clone(&mesh.inner);
    let mut params = MatchParams::unrefined();
    params.k_process = k_process;
    params.descriptors.eigenpairs = MatchParams::default().descriptors.eigenpairs.min(k_process);
    params.area_normalize = area_normalize;
    if let Some(l) = learned::learned_of(features, model, adapt, None)? {
        let needed = l.eigenpairs();
        if needed > k_process {
            return Err(err(format!(
                "features = \"learned\" needs k_process >= {needed} (the model's eigenpairs{}), got {k_process}",
                if adapt > 0 {
                    " and its adaptation's"
                } else {
                    ""
                }
            )));
        }
        learned::apply(&mut params, Some(l));
    }
    // One thread for the eigensolver, as the pipeline prepares its shapes
    // (the basis does not depend on it).
    let mut single = params.clone();
    single.spectrum.threads = 1;
    let p = run(py, threads, move || fmaps::pipeline::prepare(&m, &single))?.map_err(err)?;
    Ok(PreparedShape {
        inner: Arc::new(p),
        area_normalize,
    })
}

/// [`match_shapes`] on two prepared shapes (same options; `k_process` and
/// `area_normalize` are the shapes'). Quality scores are computed on the
/// prepared (unit-area) meshes.
#[pyfunction]
#[pyo3(signature = (a, b, *, refine = "default", k = 50, schedule = None, landmarks = None, w_descr = 0.1, w_lap = 0.001, w_dcomm = 1.0, w_orient = 1.0, mirrored = false, non_isometric = false, second_opinion = false, starts = None, features = "descriptors", model = None, adapt = 0, point_map = None, threads = None))]
#[allow(clippy::too_many_arguments)]
fn match_prepared(
    py: Python<'_>,
    a: &PreparedShape,
    b: &PreparedShape,
    refine: &str,
    k: usize,
    schedule: Option<String>,
    landmarks: Option<Bound<'_, PyAny>>,
    w_descr: f64,
    w_lap: f64,
    w_dcomm: f64,
    w_orient: f64,
    mirrored: bool,
    non_isometric: bool,
    second_opinion: bool,
    starts: Option<Vec<usize>>,
    features: &str,
    model: Option<PathBuf>,
    adapt: usize,
    point_map: Option<String>,
    threads: Option<usize>,
) -> PyResult<MatchResult> {
    let landmarks = stages::landmark_pairs(landmarks, a.n_vertices(), b.n_vertices())?;
    let learned = learned::learned_of(features, model, adapt, point_map.as_deref())?;
    if a.area_normalize != b.area_normalize {
        return Err(err(
            "the two shapes were prepared with different area_normalize settings",
        ));
    }
    let k_process = a.k_process().min(b.k_process());
    let (pa, pb) = (Arc::clone(&a.inner), Arc::clone(&b.inner));
    let sizes = (pa.vertices.len(), pb.vertices.len());
    let (refine, k, schedule) =
        learned::refine_for(refine, learned.is_some(), sizes.0.min(sizes.1), k, schedule);
    let mut params = params_for(
        refine,
        schedule,
        sizes,
        k,
        k_process,
        PerTerm {
            descr: w_descr,
            lap: w_lap,
            dcomm: w_dcomm,
            orient: w_orient,
        },
        (mirrored, non_isometric, second_opinion),
        a.area_normalize,
    )?;
    if let Some(s) = starts {
        params.starts.sizes = s;
    }
    learned::apply(
        &mut params,
        learned.map(|l| if non_isometric { l.non_isometric() } else { l }),
    );
    if second_opinion && learned_features(&params) {
        params = params
            .with_axiomatic_opinion(sizes.0, sizes.1)
            .map_err(err)?;
    }
    params.descriptors.landmarks = landmarks;
    let (r, quality) = run(py, threads, move || {
        let r = fmaps::pipeline::match_prepared(&pa, &pb, &params).map_err(|e| e.to_string())?;
        let mesh = |p: &fmaps::pipeline::PreparedShape| {
            TriMesh::new(p.vertices.clone(), p.faces.clone()).map_err(|e| e.to_string())
        };
        let q = fmaps::eval::map_quality(&r.t_ab, &mesh(&pa)?, &mesh(&pb)?, None)
            .map_err(|e| e.to_string())?;
        Ok::<_, String>((r, q))
    })?
    .map_err(err)?;
    let meshes = (Py::new(py, a.mesh()?)?, Py::new(py, b.mesh()?)?);
    result(py, r, quality, meshes)
}

/// Shape `pose` (0 rest, 1 walking, 2 crouching, 3 reaching) of individual
/// `individual` of the generated body collection (`cargo xtask eval
/// --collection generated-noniso`'s `body_I_P`): independently meshed,
/// different builds.
#[pyfunction]
fn generated_body(py: Python<'_>, individual: usize, pose: usize) -> PyResult<Mesh> {
    let shape = py
        .detach(|| fmaps::shapes::body::Body::template().collection_shape(individual, pose))
        .map_err(err)?;
    Ok(Mesh {
        inner: Arc::new(shape.mesh),
    })
}

/// Indices from Python (non-negative), checked against `n` vertices of
/// `what`.
/// `v` is any integer array-like (see [`convert`]).
fn checked(v: &Bound<'_, PyAny>, n: usize, what: &str) -> PyResult<Vec<usize>> {
    convert::ints1(v, what)?
        .as_array()
        .iter()
        .enumerate()
        .map(|(i, &x)| match usize::try_from(x) {
            Ok(u) if u < n => Ok(u),
            _ => Err(err(format!(
                "{what}: entry {i} is {x}, outside 0..{n} (0-based vertex indices)"
            ))),
        })
        .collect()
}

/// The map argument `name` checked as a map from a shape of `na`
/// vertices to one of `nb`: one entry per vertex of the first, each a
/// vertex of the second.
fn map_between(map: &Bound<'_, PyAny>, na: usize, nb: usize, name: &str) -> PyResult<Vec<usize>> {
    let t = checked(map, nb, name)?;
    if t.len() != na {
        return Err(err(format!(
            "{name} has {} entries, its source shape has {na} vertices",
            t.len()
        )));
    }
    Ok(t)
}

/// Geodesic errors of `map_ab` against ground truth, as `fmaps eval`
/// (normalised by √area(B)): `gt_a[i]` of A corresponds to `gt_b[i]` of B
/// (and to `gt_b_sym[i]` under the symmetry). Returns a dict: mean_error,
/// sym_mean_error, auc, coverage, errors (numpy), thresholds, curve.
#[pyfunction]
#[pyo3(signature = (a, b, map_ab, gt_a, gt_b, gt_b_sym = None, geodesic = "exact", threads = None))]
#[allow(clippy::too_many_arguments)]
fn evaluate<'py>(
    py: Python<'py>,
    a: &Mesh,
    b: &Mesh,
    map_ab: Bound<'_, PyAny>,
    gt_a: Bound<'_, PyAny>,
    gt_b: Bound<'_, PyAny>,
    gt_b_sym: Option<Bound<'_, PyAny>>,
    geodesic: &str,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyDict>> {
    let (na, nb) = (a.inner.n_vertices(), b.inner.n_vertices());
    let t_ab = map_between(
        &map_ab,
        a.inner.n_vertices(),
        b.inner.n_vertices(),
        "map_ab",
    )?;
    let gt = fmaps::eval::GroundTruth::new(
        checked(&gt_a, na, "gt_a")?,
        checked(&gt_b, nb, "gt_b")?,
        gt_b_sym
            .as_ref()
            .map(|s| checked(s, nb, "gt_b_sym"))
            .transpose()?,
    )
    .map_err(err)?;
    let mb = Arc::clone(&b.inner);
    let method = geodesic.to_string();
    let report = run(py, threads, move || {
        let solver = stages::distance_solver(&method, &mb)?;
        fmaps::eval::evaluate(
            &mb,
            solver.as_ref(),
            &t_ab,
            &gt,
            None,
            &fmaps::eval::EvalParams::default(),
        )
        .map_err(|e| e.to_string())
    })?
    .map_err(err)?;
    let d = PyDict::new(py);
    d.set_item("mean_error", report.mean_error)?;
    d.set_item("sym_mean_error", report.sym_mean_error)?;
    d.set_item("auc", report.auc)?;
    d.set_item("coverage", report.coverage)?;
    d.set_item("geodesic", report.geodesic)?;
    d.set_item("errors", Array1::from(report.errors).into_pyarray(py))?;
    d.set_item("thresholds", report.thresholds.into_pyarray(py))?;
    d.set_item("curve", report.curve.into_pyarray(py))?;
    Ok(d)
}

/// Reads a `.vts` ground-truth file, a `.map` file (both 1-based on
/// disk) or a NumPy file of indices (`.npy`/`.npz`, 0-based, any integer
/// dtype): 0-based int64.
#[pyfunction]
fn read_indices<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyArray1<i64>>> {
    let is_map = path.extension().is_some_and(|e| e == "map");
    let v = if fmaps::mesh_io::arrays::is_numpy(&path) {
        fmaps::mesh_io::arrays::read_indices(&path)
    } else if is_map {
        fmaps::mesh_io::read_map(&path)
    } else {
        fmaps::mesh_io::read_vts(&path)
    }
    .map_err(err_on(&path))?;
    Ok(indices(py, &v).into_bound(py))
}

/// The built-in pairs of `fmaps demo` (generated, exact ground truth):
/// a list of dicts with name, title, a, b (meshes), gt_a, gt_b and
/// gt_b_sym (None for the asymmetric creature).
#[pyfunction]
#[pyo3(signature = (subdivisions = 4))]
fn demo_pairs(py: Python<'_>, subdivisions: u32) -> PyResult<Vec<Bound<'_, PyDict>>> {
    if !(3..=6).contains(&subdivisions) {
        return Err(err(format!(
            "subdivisions = {subdivisions}: use 3..=6 (3 = 642 vertices, 4 = 2,562, 5 = 10,242)"
        )));
    }
    let pairs = py
        .detach(|| fmaps::demo::demo_pairs(subdivisions))
        .map_err(err)?;
    pairs
        .into_iter()
        .map(|p| {
            let d = PyDict::new(py);
            d.set_item("name", p.name)?;
            d.set_item("title", &p.title)?;
            d.set_item("gt_a", indices(py, &p.gt_a))?;
            d.set_item("gt_b", indices(py, &p.gt_b))?;
            d.set_item("gt_b_sym", p.gt_b_sym.as_deref().map(|s| indices(py, s)))?;
            d.set_item(
                "a",
                Mesh {
                    inner: Arc::new(p.a),
                },
            )?;
            d.set_item(
                "b",
                Mesh {
                    inner: Arc::new(p.b),
                },
            )?;
            Ok(d)
        })
        .collect()
}

/// Draws a map (source left, target right): `kind="color"` colours the
/// source by position and carries the colours to the target through
/// `map_ab`; `"texture"` carries a checkerboard. `up` is the shapes'
/// vertical axis ("x", "y", "z"), `yaw` a turn about it (degrees). With
/// `path`, writes a PNG there (atomically) and returns the picture's
/// (width, height); without, returns the picture as a numpy array
/// (height x width x 3, uint8 RGB).
#[pyfunction]
#[pyo3(signature = (a, b, map_ab, path = None, *, kind = "color", up = "y", yaw = 0.0, size = 480))]
#[allow(clippy::too_many_arguments)]
fn render_transfer<'py>(
    py: Python<'py>,
    a: &Mesh,
    b: &Mesh,
    map_ab: Bound<'_, PyAny>,
    path: Option<PathBuf>,
    kind: &str,
    up: &str,
    yaw: f64,
    size: usize,
) -> PyResult<Bound<'py, PyAny>> {
    use fmaps::viz::View;
    let t_ab = map_between(
        &map_ab,
        a.inner.n_vertices(),
        b.inner.n_vertices(),
        "map_ab",
    )?;
    let axis = display::axis(up)?;
    if !(16..=8192).contains(&size) {
        return Err(err(format!("size = {size}: use 16..=8192 pixels")));
    }
    let view = View {
        up: axis,
        width: size,
        height: size,
        yaw: yaw.to_radians(),
        ..View::default()
    };
    let (ma, mb) = (Arc::clone(&a.inner), Arc::clone(&b.inner));
    let texture = match kind {
        "color" => false,
        "texture" => true,
        other => {
            return Err(err(format!(
                "kind = {other:?}: expected \"color\" or \"texture\""
            )));
        }
    };
    let to_file = path.is_some();
    let img = py
        .detach(move || {
            let (img, _, _) = if texture {
                fmaps::pictures::texture_transfer(&ma, &mb, &t_ab, 12, &view)
            } else {
                fmaps::pictures::color_transfer(&ma, &mb, &t_ab, &view)
            }
            .map_err(|e| e.to_string())?;
            if let Some(path) = &path {
                img.save_png(path)
                    .map_err(|e| format!("{}: {e}", path.display()))?;
            }
            Ok::<_, String>(img)
        })
        .map_err(err)?;
    let (w, h) = (img.width(), img.height());
    if to_file {
        return Ok((w, h).into_pyobject(py)?.into_any());
    }
    let rgb = Array3::from_shape_vec((h, w, 3), img.pixels().to_vec()).expect("h x w x 3");
    Ok(rgb.into_pyarray(py).into_any())
}

/// The extension module.
#[pymodule]
fn _fmaps(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("FmapsError", m.py().get_type::<FmapsError>())?;
    m.add_class::<Mesh>()?;
    m.add_class::<MatchResult>()?;
    m.add_class::<PreparedShape>()?;
    m.add_function(wrap_pyfunction!(prepare, m)?)?;
    m.add_function(wrap_pyfunction!(match_prepared, m)?)?;
    m.add_function(wrap_pyfunction!(_prepared_from_state, m)?)?;
    m.add_function(wrap_pyfunction!(_match_result_from_state, m)?)?;
    m.add_function(wrap_pyfunction!(generated_body, m)?)?;
    m.add_function(wrap_pyfunction!(render_transfer, m)?)?;
    m.add_function(wrap_pyfunction!(display::viewer_html_py, m)?)?;
    m.add_function(wrap_pyfunction!(spectrum, m)?)?;
    m.add_function(wrap_pyfunction!(match_shapes, m)?)?;
    m.add_function(wrap_pyfunction!(learned::train, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(read_indices, m)?)?;
    m.add_function(wrap_pyfunction!(demo_pairs, m)?)?;
    stages::register(m)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
