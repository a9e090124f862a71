"""Array arguments as other libraries hand them over, without importing
those libraries: trimesh (an ndarray subclass, float64 / int64),
Open3D (`np.asarray(mesh.triangles)`: int32), PyTorch on the CPU (float32
tensors with `__array__`), plain lists, uint32, read-only and
non-contiguous arrays. Each must give the mesh (and the map) that float64 /
int64 arrays give; lossy or impossible conversions raise FmapsError naming
the argument. And every object pickles."""

import pickle
import re

import numpy as np
import pytest

import fmaps


@pytest.fixture(scope="module")
def pair():
    p = fmaps.demo_pairs(3)[0]
    return p["a"], p["b"]


class TrackedArray(np.ndarray):
    """What trimesh's `mesh.vertices` / `mesh.faces` are: an ndarray
    subclass."""


class Tensor:
    """A CPU tensor as PyTorch's: not an ndarray, converts through
    `__array__`."""

    def __init__(self, a):
        self._a = np.array(a)

    def __array__(self, dtype=None, copy=None):
        return self._a if dtype is None else self._a.astype(dtype)


def read_only(a):
    a = np.array(a)
    a.flags.writeable = False
    return a


def strided(a):
    """The same values, every other element of a twice-as-wide array."""
    wide = np.zeros((a.shape[0], 2 * a.shape[1]), dtype=a.dtype)
    wide[:, ::2] = a
    view = wide[:, ::2]
    assert not view.flags.c_contiguous
    return view


SOURCES = {
    "trimesh": lambda v, f: (v.view(TrackedArray), f.view(TrackedArray)),
    "open3d": lambda v, f: (np.ascontiguousarray(v), f.astype(np.int32)),
    "pytorch": lambda v, f: (Tensor(v.astype(np.float32)), Tensor(f)),
    "lists": lambda v, f: (v.tolist(), f.tolist()),
    "uint32": lambda v, f: (v, f.astype(np.uint32)),
    "uint16": lambda v, f: (v, f.astype(np.uint16)),
    "read-only": lambda v, f: (read_only(v), read_only(f)),
    "non-contiguous": lambda v, f: (strided(v), strided(f)),
    "fortran": lambda v, f: (np.asfortranarray(v), np.asfortranarray(f)),
    "float faces": lambda v, f: (v, f.astype(np.float64)),
}


@pytest.mark.parametrize("source", sorted(SOURCES))
def test_every_input_source_gives_the_same_mesh_and_map(pair, source):
    a, b = pair
    va, fa = SOURCES[source](a.vertices, a.faces)
    vb, fb = SOURCES[source](b.vertices, b.faces)
    ma, mb = fmaps.Mesh(va, fa), fmaps.Mesh(vb, fb)
    assert np.array_equal(ma.faces, a.faces)
    # float32 coordinates convert exactly: the mesh holds their float64 values.
    want = a.vertices.astype(np.float32).astype(np.float64) if source == "pytorch" else a.vertices
    assert np.array_equal(ma.vertices, want)
    if source in ("open3d", "lists", "non-contiguous"):
        r = fmaps.match_shapes(ma, mb, refine="zoomout", threads=1)
        ref = fmaps.match_shapes(a, b, refine="zoomout", threads=1)
        assert np.array_equal(r.map_ab, ref.map_ab)


def test_index_and_feature_arguments_take_any_integer_and_float_dtype(pair):
    a, b = pair
    pa, pb = fmaps.prepare(a, k_process=60), fmaps.prepare(b, k_process=60)
    r = fmaps.match_prepared(pa, pb, refine="none", k=20, threads=1)
    m = r.map_ab
    for conv in (lambda x: x.astype(np.int32), lambda x: x.astype(np.uint32), lambda x: x.tolist(), read_only):
        assert np.array_equal(fmaps.map_to_fmap(conv(m), pa, pb, k=20), fmaps.map_to_fmap(m, pa, pb, k=20))
        q, q_ref = fmaps.map_quality(a, b, conv(m)), fmaps.map_quality(a, b, m)
        assert q == q_ref
        assert np.array_equal(fmaps.geodesics(a, conv(m[:3]), method="dijkstra"), fmaps.geodesics(a, m[:3], method="dijkstra"))
    # float32 features and a float32 C.
    da = fmaps.descriptors(pa, k=40)
    db = fmaps.descriptors(pb, k=40)
    c32 = fmaps.fit(pa, pb, k=20, descr_a=da.astype(np.float32), descr_b=db.astype(np.float32))
    c64 = fmaps.fit(pa, pb, k=20, descr_a=da.astype(np.float32).astype(np.float64), descr_b=db.astype(np.float32).astype(np.float64))
    assert np.array_equal(c32, c64)
    assert np.array_equal(fmaps.fmap_to_map(c32.astype(np.float32), pa, pb), fmaps.fmap_to_map(c32.astype(np.float32).astype(np.float64), pa, pb))
    # Landmarks as an int32 k x 2 array, as a list of pairs, as tuples.
    lm = np.array([[0, 0], [5, 7]], dtype=np.int32)
    want = fmaps.fit(pa, pb, k=20, landmarks=[(0, 0), (5, 7)])
    assert np.array_equal(fmaps.fit(pa, pb, k=20, landmarks=lm), want)
    assert np.array_equal(fmaps.fit(pa, pb, k=20, landmarks=[[0, 0], [5, 7]]), want)


BAD = [
    ("faces", lambda v, f: (v, f.astype(bool)), "faces: booleans"),
    ("faces", lambda v, f: (v, f + 0.5), r"faces: entry \[0, 0\] is \d+\.5, not an integer index"),
    ("faces", lambda v, f: (v, np.where(f == f[0, 0], np.nan, f)), r"faces: entry \[0, 0\] is NaN"),
    ("faces", lambda v, f: (v, np.full(f.shape, 2**63, dtype=np.uint64)), "faces: dtype uint64 does not convert to int64 without loss"),
    ("faces", lambda v, f: (v, f.astype(str)), "faces: dtype str"),
    ("faces", lambda v, f: (v, f[:, :2]), "faces: rows of 3 entries are needed"),
    ("faces", lambda v, f: (v, f.ravel()), "faces: a 2-D array is needed"),
    ("faces", lambda v, f: (v, [[0, 1, 2], [0, 1]]), "faces: not an array of numbers"),
    ("vertices", lambda v, f: (v.astype(complex), f), "vertices: dtype complex128 does not convert to float64 without loss (complex numbers)"),
    ("vertices", lambda v, f: (np.full(v.shape, 2**60 + 1, dtype=np.int64), f), "vertices: dtype int64 does not convert to float64 without loss"),
    ("vertices", lambda v, f: (v.astype(object), f), "vertices: dtype object is not a number type"),
]


@pytest.mark.parametrize("name,make,says", BAD, ids=[b[2][:40] for b in BAD])
def test_lossy_or_impossible_conversions_name_the_argument(pair, name, make, says):
    a, _ = pair
    with pytest.raises(fmaps.FmapsError) as e:
        fmaps.Mesh(*make(a.vertices, a.faces))
    assert re.match(says if says.startswith("faces: entry") else re.escape(says), str(e.value)), str(e.value)


def test_bad_indices_through_other_entry_points(pair):
    a, b = pair
    m = np.zeros(a.n_vertices, dtype=np.int64)
    with pytest.raises(fmaps.FmapsError, match="^map_ab: entry 3 is 1.5, not an integer index"):
        fmaps.map_quality(a, b, np.where(np.arange(a.n_vertices) == 3, 1.5, 0.0))
    with pytest.raises(fmaps.FmapsError, match="^map_ba has 3 entries"):
        fmaps.map_quality(a, b, m, map_ba=[0, 1, 2])
    with pytest.raises(fmaps.FmapsError, match="^gt_a: booleans"):
        fmaps.evaluate(a, b, m, np.ones(3, dtype=bool), [0, 1, 2])
    pa, pb = fmaps.prepare(a, k_process=60), fmaps.prepare(b, k_process=60)
    with pytest.raises(fmaps.FmapsError, match="^landmarks: rows of 2 entries"):
        fmaps.fit(pa, pb, k=10, landmarks=[[0, 1, 2]])
    with pytest.raises(fmaps.FmapsError, match="^descr_a: dtype complex128"):
        fmaps.fit(pa, pb, k=10, descr_a=np.ones((a.n_vertices, 2), complex), descr_b=np.ones((b.n_vertices, 2)))


def test_meshes_and_results_pickle(pair):
    a, b = pair
    a2 = pickle.loads(pickle.dumps(a))
    assert isinstance(a2, fmaps.Mesh)
    assert np.array_equal(a2.vertices, a.vertices) and np.array_equal(a2.faces, a.faces)
    r = fmaps.match_shapes(a, b, refine="zoomout", threads=1)
    r2 = pickle.loads(pickle.dumps(r))
    for f in ("map_ab", "map_ab_init", "c_ba"):
        assert np.array_equal(getattr(r2, f), getattr(r, f))
    for f in ("orientation", "confidence", "times", "quality", "refiner", "seconds_per_iteration"):
        assert getattr(r2, f) == getattr(r, f), f
    pa, pb = fmaps.prepare(a, k_process=60), fmaps.prepare(b, k_process=60)
    rm = fmaps.refine(pa, pb, r.map_ab_init, method="icp", k=20)
    rm2 = pickle.loads(pickle.dumps(rm))
    assert np.array_equal(rm2.map_ab, rm.map_ab) and np.array_equal(rm2.c_ba_init, rm.c_ba_init)
    assert (rm2.orientation, rm2.refiner, rm2.seconds) == (rm.orientation, rm.refiner, rm.seconds)


def test_a_picture_comes_back_as_an_array_without_a_path(pair, tmp_path):
    a, b = pair
    m = fmaps.match_shapes(a, b, refine="none", threads=1).map_ab
    w, h = fmaps.render_transfer(a, b, m, tmp_path / "t.png", size=64)
    img = fmaps.render_transfer(a, b, m, size=64)
    assert img.shape == (h, w, 3) and img.dtype == np.uint8
    # Not blank: the shapes' colours differ from the background.
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 10


def test_meshes_and_results_display_themselves_in_a_notebook(pair, tmp_path):
    a, b = pair
    r = fmaps.match_shapes(a, b, refine="zoomout", threads=1)
    for obj in (a, r):
        html = obj._repr_html_()
        # The viewer page in an iframe of its own, everything inline.
        assert html.startswith('<iframe srcdoc="&lt;!DOCTYPE html&gt;')
        assert "fmaps-data" in html and "http://" not in html and "https://" not in html
        assert obj._repr_png_()[:8] == b"\x89PNG\r\n\x1a\n"
    # The result keeps the meshes it matched, also through pickle.
    assert np.array_equal(r.meshes[0].vertices, a.vertices)
    assert pickle.loads(pickle.dumps(r))._repr_html_() == r._repr_html_()


def test_the_viewer_page_is_written_and_checks_its_input(pair, tmp_path):
    a, b = pair
    m = fmaps.match_shapes(a, b, refine="none", threads=1).map_ab
    err = np.linspace(0, 0.2, a.n_vertices).astype(np.float32)
    page = fmaps.viewer_html(a, b, m, error=err, path=tmp_path / "v.html", title="t <x>")
    assert (tmp_path / "v.html").read_text() == page
    assert "<title>t &lt;x&gt;</title>" in page and '"error_max": 0.1' in page
    assert '"b": null' in fmaps.viewer_html(a)
    with pytest.raises(fmaps.FmapsError, match="give both b and map_ab"):
        fmaps.viewer_html(a, b)
    with pytest.raises(fmaps.FmapsError, match="error has 3 entries"):
        fmaps.viewer_html(a, b, m, error=[0.0, 1.0, 2.0])
    with pytest.raises(fmaps.FmapsError, match="^map_ab: entry 0 is"):
        fmaps.viewer_html(a, b, np.full(a.n_vertices, b.n_vertices))


def test_numpy_files_go_in_and_out_of_the_cli(pair, tmp_path):
    import subprocess

    from test_fmaps import cli

    a, b = pair
    a.save(tmp_path / "a.off")
    b.save(tmp_path / "b.off")
    base = [cli(), "match", str(tmp_path / "a.off"), str(tmp_path / "b.off"), "--refine", "none"]
    subprocess.run(base + ["--out", str(tmp_path / "m.map"), "--save-fmap", str(tmp_path / "c.txt")], check=True, capture_output=True)
    subprocess.run(base + ["--out", str(tmp_path / "m.npy"), "--save-fmap", str(tmp_path / "c.npy")], check=True, capture_output=True)
    m = np.load(tmp_path / "m.npy")
    # 0-based int64 in NumPy files, the same map as the 1-based text file.
    assert m.dtype == np.int64 and np.array_equal(m, fmaps.read_indices(tmp_path / "m.map"))
    assert np.array_equal(np.load(tmp_path / "c.npy"), np.loadtxt(tmp_path / "c.txt"))
    # A map saved by NumPy as int32, and as a compressed-free .npz, goes in.
    np.save(tmp_path / "m32.npy", m.astype(np.int32))
    np.savez(tmp_path / "mz.npz", m)
    for init in ("m32.npy", "mz.npz", "m.map"):
        assert np.array_equal(fmaps.read_indices(tmp_path / init), m)
        subprocess.run(
            [cli(), "refine", str(tmp_path / "a.off"), str(tmp_path / "b.off"), "--init-map", str(tmp_path / init),
             "--refine", "icp", "--out", str(tmp_path / f"r-{init}.npy")],
            check=True, capture_output=True,
        )
    r = [np.load(tmp_path / f"r-{i}.npy") for i in ("m32.npy", "mz.npz", "m.map")]
    assert np.array_equal(r[0], r[1]) and np.array_equal(r[0], r[2])
    # Own descriptors from NumPy: the pipeline's own descriptors given as
    # files give the pipeline's map (float32: rounded, still the map).
    pa, pb = fmaps.prepare(a), fmaps.prepare(b)
    for dtype in (np.float64, np.float32):
        np.save(tmp_path / "da.npy", fmaps.descriptors(pa).astype(dtype))
        np.save(tmp_path / "db.npy", fmaps.descriptors(pb).astype(dtype))
        subprocess.run(base + ["--descr-source", str(tmp_path / "da.npy"), "--descr-target", str(tmp_path / "db.npy"),
                               "--out", str(tmp_path / "own.npy")], check=True, capture_output=True)
        own = np.load(tmp_path / "own.npy")
        assert np.array_equal(own, m) if dtype == np.float64 else (own == m).mean() > 0.99
    # A pickle inside is refused, naming the file.
    np.save(tmp_path / "obj.npy", np.array([object()] * a.n_vertices), allow_pickle=True)
    bad = subprocess.run(
        [cli(), "refine", str(tmp_path / "a.off"), str(tmp_path / "b.off"), "--init-map", str(tmp_path / "obj.npy")],
        capture_output=True, text=True,
    )
    assert bad.returncode == 2 and "obj.npy" in bad.stderr and "pickle" in bad.stderr, bad.stderr
