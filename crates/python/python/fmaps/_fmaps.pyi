"""Type stubs of the extension module (see the package docstring).

Array arguments (``npt.ArrayLike``) take any array-like -- numpy arrays of
any layout (read-only, non-contiguous), lists, tuples, objects with
``__array__`` -- of any dtype that converts without loss, converted once:
coordinates and features to float64 (from float16/32/64 and integers),
vertex indices to int64 (from any signed or unsigned integer dtype, or
floats that are whole numbers). Booleans, complex numbers, strings and
lossy conversions (uint64 above 2**63 - 1, 64-bit integers float64 cannot
hold) raise :class:`FmapsError` naming the argument.
"""

from os import PathLike
from typing import Optional, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

class FmapsError(ValueError):
    """Bad input or a failed computation; the message is the one `fmaps` prints."""

class Mesh:
    """A triangle mesh, validated on construction."""

    def __init__(self, vertices: npt.ArrayLike, faces: npt.ArrayLike) -> None:
        """`vertices`: n x 3 coordinates (float32, float64, integers, lists); `faces`: m x 3 vertex indices,
        0-based (int32, uint32, int64, ..., lists). Picklable (rebuilt from its arrays)."""
    @staticmethod
    def load(path: Union[str, PathLike]) -> "Mesh":
        """Reads an OFF, OBJ or PLY file (errors name the file and line)."""
    @property
    def vertices(self) -> npt.NDArray[np.float64]: ...
    @property
    def faces(self) -> npt.NDArray[np.int64]: ...
    @property
    def n_vertices(self) -> int: ...
    @property
    def n_faces(self) -> int: ...
    def area(self) -> float: ...
    def validate(self) -> dict:
        """The validation report of `fmaps info`: counts, defects (0-based elements), boundary, components, genus."""
    def save(self, path: Union[str, PathLike]) -> None:
        """Writes .off, .obj or .ply (from the extension), atomically."""
    def _repr_html_(self) -> str:
        """The notebook display: the interactive viewer in an iframe."""
    def _repr_png_(self) -> bytes:
        """The display without scripts: a picture coloured by position."""

class PreparedShape:
    """A shape after the per-shape stages (unit area, Laplacian, eigenbasis); picklable."""

    @property
    def k_process(self) -> int: ...
    @property
    def n_vertices(self) -> int: ...
    @property
    def seconds(self) -> float: ...
    @property
    def eigenvalues(self) -> npt.NDArray[np.float64]: ...
    @property
    def basis(self) -> npt.NDArray[np.float64]:
        """n x k_process, Fortran order, orthonormal in the mass (a copy)."""
    @property
    def mass(self) -> npt.NDArray[np.float64]: ...
    @property
    def mesh(self) -> Mesh:
        """The mesh as prepared (unit area unless area_normalize was off)."""
    @property
    def input_area(self) -> float: ...

class MatchResult:
    """The result of :func:`match_shapes`; picklable."""

    map_ab: npt.NDArray[np.int64]
    """For each vertex of A, the vertex of B it goes to (0-based)."""
    map_ab_init: npt.NDArray[np.int64]
    """The initial map, before refinement."""
    c_ba: npt.NDArray[np.float64]
    """Coefficients on B to coefficients on A."""
    orientation: float
    """Orientation score of `map_ab` (near 1 preserved, near -1 mirrored)."""
    confidence: dict
    """Without ground truth: metric_distortion, long_range, area_distortion, likely_wrong (either above its warn_above: likely globally misaligned), warn_above, advice."""
    times: dict
    """Seconds per stage (spectra, descriptors, operators, solve, point_map, refine, total)."""
    quality: dict
    """Scores without ground truth (coverage, area_coverage, collapsed_faces, area_distortion, conformal_distortion)."""
    refiner: str
    """The refiner's name ("" without refinement)."""
    seconds_per_iteration: list
    """Seconds of each refinement step."""
    meshes: Tuple[Mesh, Mesh]
    """The meshes matched (A, B; the prepared, unit-area ones after match_prepared)."""
    def _repr_html_(self) -> str:
        """The notebook display: the map in the interactive viewer (transfer, picking)."""
    def _repr_png_(self) -> bytes:
        """The display without scripts: the colour transfer as a picture."""

def spectrum(
    mesh: Mesh, k: int = 200, threads: Optional[int] = None
) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(eigenvalues (k,), basis (n x k), lumped mass (n,)) of the mesh as given."""

def match_shapes(
    a: Mesh,
    b: Mesh,
    *,
    refine: str = "default",
    k: int = 50,
    k_process: Optional[int] = None,
    schedule: Optional[str] = None,
    landmarks: Optional[npt.ArrayLike] = None,
    w_descr: float = 0.1,
    w_lap: float = 0.001,
    w_dcomm: float = 1.0,
    w_orient: float = 1.0,
    mirrored: bool = False,
    non_isometric: bool = False,
    second_opinion: bool = False,
    area_normalize: bool = True,
    starts: Optional[list] = None,
    features: str = "descriptors",
    model: Optional[str] = None,
    adapt: int = 0,
    point_map: Optional[str] = None,
    threads: Optional[int] = None,
) -> MatchResult:
    """The pipeline of `fmaps match`; features: "descriptors" or "learned" (the model shipped with fmaps, or the
    model file `model` of :func:`train`; refine "default" is then ZoomOut 100:200:20 from k = 100 unless k is given,
    as `fmaps match --features learned`);
    adapt: test-time adaptation steps on the pair; point_map: "features" or "spectral" (`fmaps match --point-map`); refine: "default" (Smooth Shells), or a name of `fmaps match --refine`:
    "none", "icp", "zoomout", "bijective-zoomout", "discrete", "bcicp", "smooth-shells"; schedule: "START:FINAL:STEP"
    for ZoomOut and the discrete presets; landmarks: (vertex of A, vertex of B) pairs, 0-based (k x 2);
    w_descr, w_lap, w_dcomm, w_orient: relative weights of the energy's terms (only ratios matter); starts: further initial sizes ([] = one start; None = the CLI's default);
    k_process: eigenpairs computed (None: those the pipeline uses, as the CLI: 200 for Smooth Shells, 150 for ZoomOut);
    non_isometric: the shapes are not near-isometric (different people or animals), as `fmaps match --non-isometric`.
    second_opinion: Smooth Shells runs both settings (default and non-isometric) and keeps the map of least area distortion, as `fmaps match --second-opinion` (twice the time); with features="learned", the default descriptor pipeline runs beside the learned one and the least area-distorting map is kept (confidence["passed_over"] says which was not).
    As the CLI, a ZoomOut runs its iterations on 5000 farthest points per shape when a mesh has more than 20000
    vertices (then one iteration and the final map on every vertex; the result's refiner name says so)."""

def prepare(
    mesh: Mesh,
    *,
    k_process: int = 200,
    area_normalize: bool = True,
    features: str = "descriptors",
    model: Optional[str] = None,
    adapt: int = 0,
    threads: Optional[int] = None,
) -> PreparedShape:
    """The per-shape stages, computed once per shape; with
    features="learned" also the network's operators and features (of
    `model`, the shipped one by default), which match_prepared(...,
    features="learned") then reuses."""

def match_prepared(
    a: PreparedShape,
    b: PreparedShape,
    *,
    refine: str = "default",
    k: int = 50,
    schedule: Optional[str] = None,
    landmarks: Optional[npt.ArrayLike] = None,
    w_descr: float = 0.1,
    w_lap: float = 0.001,
    w_dcomm: float = 1.0,
    w_orient: float = 1.0,
    mirrored: bool = False,
    non_isometric: bool = False,
    second_opinion: bool = False,
    starts: Optional[list] = None,
    features: str = "descriptors",
    model: Optional[str] = None,
    adapt: int = 0,
    point_map: Optional[str] = None,
    threads: Optional[int] = None,
) -> MatchResult:
    """`match_shapes` on prepared shapes (the same maps)."""

def train(
    meshes: list,
    out: str,
    *,
    steps: int = 1000,
    lr: float = 1e-3,
    seed: int = 1,
    width: int = 128,
    blocks: int = 4,
    outputs: int = 256,
    inputs: int = 128,
    eigenpairs: int = 128,
    fmap_k: int = 200,
    coupling_samples: Optional[int] = 1000,
    dropout: bool = True,
    save_every: int = 25,
    threads: Optional[int] = None,
) -> list:
    """Trains DiffusionNet without labels on `meshes` (the recipe of `fmaps train`) and writes the model file
    `out` (for `match_shapes(..., features="learned", model=out)`); a checkpoint `out` with `.checkpoint.npz` is
    written every `save_every` steps and a call on the same files continues from it. Returns one dict of losses
    per step run."""

class RefinedMap:
    """The result of :func:`refine`; picklable."""

    map_ab: npt.NDArray[np.int64]
    """The refined map: for each vertex of A, a vertex of B (0-based)."""
    c_ba: npt.NDArray[np.float64]
    """C_BA after refinement."""
    c_ba_init: npt.NDArray[np.float64]
    """The given map's k x k pull-back, where the refiner started."""
    orientation_init: float
    orientation: float
    refiner: str
    seconds_per_iteration: list
    seconds: float

def descriptors(
    shape: PreparedShape,
    *,
    kind: str = "wks",
    n: int = 100,
    k: int = 128,
    landmarks: Optional[npt.ArrayLike] = None,
    subsample: int = 1,
) -> npt.NDArray[np.float64]:
    """The pipeline's descriptors (n_vertices x p, unit L2 columns): "wks" or "hks" at n samples on k eigenpairs,
    then the landmark variant (0-based vertices) stacked; every subsample-th column."""

def fit(
    a: PreparedShape,
    b: PreparedShape,
    *,
    k: int = 50,
    descr_a: Optional[npt.ArrayLike] = None,
    descr_b: Optional[npt.ArrayLike] = None,
    kind: str = "wks",
    n: int = 100,
    k_descr: int = 128,
    landmarks: Optional[npt.ArrayLike] = None,
    w_descr: float = 0.1,
    w_lap: float = 0.001,
    w_dcomm: float = 1.0,
    w_orient: float = 1.0,
    mirrored: bool = False,
    threads: Optional[int] = None,
) -> npt.NDArray[np.float64]:
    """The functional-map solve: C_BA (k x k) from the pipeline's descriptors, or from descr_a / descr_b
    (any per-vertex features with corresponding columns); landmarks: (vertex of A, vertex of B) pairs."""

def fmap_to_map(
    c_ba: npt.ArrayLike, a: PreparedShape, b: PreparedShape, *, adjoint: bool = False, threads: Optional[int] = None
) -> npt.NDArray[np.int64]:
    """map_ab from C_BA (k_A x k_B): exact nearest neighbours of the spectral embeddings (pyFM's get_p2p)."""

def map_to_fmap(map_ab: npt.ArrayLike, a: PreparedShape, b: PreparedShape, *, k: int = 50) -> npt.NDArray[np.float64]:
    """C_BA = Phi_A^T M_A Pi_AB Phi_B (k x k), the pull-back along map_ab."""

def refine(
    a: PreparedShape,
    b: PreparedShape,
    map_ab: npt.ArrayLike,
    *,
    method: str = "zoomout",
    k: int = 50,
    schedule: Optional[str] = None,
    icp_iterations: Optional[int] = None,
    bijective: bool = False,
    adjoint: bool = False,
    sinkhorn: bool = False,
    mirrored: bool = False,
    threads: Optional[int] = None,
) -> RefinedMap:
    """Refines any map A -> B: "zoomout", "icp", "bijective-zoomout", "discrete", "bcicp", "smooth-shells", "none"."""

def geodesics(
    mesh: Mesh,
    sources: npt.ArrayLike,
    *,
    method: str = "exact",
    per_source: bool = False,
    threads: Optional[int] = None,
) -> npt.NDArray[np.float64]:
    """Distances from the nearest source to every vertex (n,), or one row per source (len(sources) x n);
    method "exact", "heat" or "dijkstra"."""

def generated_body(individual: int, pose: int) -> Mesh:
    """Shape body_{individual}_{pose} of the generated body collection."""

def evaluate(
    a: Mesh,
    b: Mesh,
    map_ab: npt.ArrayLike,
    gt_a: npt.ArrayLike,
    gt_b: npt.ArrayLike,
    gt_b_sym: Optional[npt.ArrayLike] = None,
    geodesic: str = "exact",
    threads: Optional[int] = None,
) -> dict:
    """Geodesic errors of `map_ab` against ground truth, as `fmaps eval`."""

def read_indices(path: Union[str, PathLike]) -> npt.NDArray[np.int64]:
    """A .vts ground-truth or .map file (1-based on disk), or a NumPy file of indices (.npy/.npz, 0-based): 0-based."""

def demo_pairs(subdivisions: int = 4) -> list:
    """The built-in pairs of `fmaps demo`: dicts with name, title, a, b, gt_a, gt_b, gt_b_sym."""

def render_transfer(
    a: Mesh,
    b: Mesh,
    map_ab: npt.ArrayLike,
    path: Optional[Union[str, PathLike]] = None,
    *,
    kind: str = "color",
    up: str = "y",
    yaw: float = 0.0,
    size: int = 480,
) -> Union[Tuple[int, int], npt.NDArray[np.uint8]]:
    """Draws the map (source left, target right); kind "color" or "texture". With `path`, writes a PNG and
    returns (width, height); without, returns the picture (height x width x 3, uint8 RGB)."""

def map_quality(
    a: Mesh, b: Mesh, map_ab: npt.ArrayLike, map_ba: Optional[npt.ArrayLike] = None
) -> dict:
    """Scores without ground truth: coverage, area_coverage, collapsed_faces, area_distortion, conformal_distortion,
    orientation (1 preserved, -1 mirrored), and with map_ba round_trip."""

def viewer_html(
    a: Mesh,
    b: Optional[Mesh] = None,
    map_ab: Optional[npt.ArrayLike] = None,
    *,
    error: Optional[npt.ArrayLike] = None,
    error_max: float = 0.1,
    up: str = "y",
    title: Optional[str] = None,
    path: Optional[Union[str, PathLike]] = None,
) -> str:
    """The interactive viewer as one self-contained HTML page (no network at view time): A and B side by side,
    turning together, colour and texture transfer, `error` per vertex of A (NaN: none), picking (click a point on
    A, see its image on B); `a` alone without b and map_ab. Returns the page; with `path`, also writes it."""
