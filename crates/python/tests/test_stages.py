"""Tests of the stage-by-stage calls (descriptors, fit, conversions,
refine, geodesics): each stage equals the pipeline's, closed forms where
they exist, and errors raise with a message that names the argument.
"""

import subprocess

import numpy as np
import pytest

import fmaps
from test_fmaps import cli


@pytest.fixture(scope="module")
def pair():
    p = fmaps.demo_pairs(subdivisions=3)[0]
    a, b = fmaps.prepare(p["a"]), fmaps.prepare(p["b"])
    return p, a, b


def test_descriptors_have_unit_mass_norm_columns(pair):
    _, a, _ = pair
    d = fmaps.descriptors(a)
    assert d.shape == (a.n_vertices, 100)
    norms = (a.mass[:, None] * d**2).sum(axis=0)
    assert np.allclose(norms, 1.0, atol=1e-12)
    h = fmaps.descriptors(a, kind="hks", n=16, landmarks=np.array([0, 5]))
    # The family and its landmark variant, stacked: 16 + 2 x 16 columns.
    assert h.shape == (a.n_vertices, 48)
    # k is capped at the eigenpairs held, as the pipeline caps k_descr.
    small = fmaps.prepare(pair[0]["a"], k_process=60)
    assert np.array_equal(fmaps.descriptors(small), fmaps.descriptors(small, k=60))


def test_the_stages_give_the_pipelines_initial_map(pair):
    _, a, b = pair
    r = fmaps.match_prepared(a, b, refine="none", starts=[])
    c = fmaps.fit(a, b)
    assert c.shape == (50, 50)
    assert np.array_equal(c, r.c_ba)
    assert np.array_equal(fmaps.fmap_to_map(c, a, b), r.map_ab_init)
    # The pipeline's descriptors passed in give the same solve.
    c2 = fmaps.fit(a, b, descr_a=fmaps.descriptors(a), descr_b=fmaps.descriptors(b))
    assert np.array_equal(c2, c)


def test_the_identity_map_is_the_identity_matrix(pair):
    _, a, _ = pair
    ident = np.arange(a.n_vertices)
    # Phi^T M Phi = I for a mass-orthonormal basis.
    c = fmaps.map_to_fmap(ident, a, a, k=30)
    assert np.allclose(c, np.eye(30), atol=1e-10)
    assert np.array_equal(fmaps.fmap_to_map(c, a, a), ident)
    assert np.array_equal(fmaps.fmap_to_map(c, a, a, adjoint=True), ident)


# The eigenpairs `fmaps refine` computes for each refiner with the schedule
# 20:60:10 and k = 50: the larger of k and what the refiner needs.
REFINER_EIGENPAIRS = {"icp": 50, "zoomout": 60, "bijective-zoomout": 60, "discrete": 60, "bcicp": 50,
                      "smooth-shells": 200}


def test_every_refiner_gives_the_cli_map_and_zoomout_improves_the_demo_map(pair, tmp_path):
    p, a, b = pair
    init = fmaps.match_prepared(a, b, refine="none", starts=[]).map_ab_init
    r = fmaps.refine(a, b, init, method="none")
    assert r.refiner == "" and np.array_equal(r.map_ab, init)
    p["a"].save(tmp_path / "a.off")
    p["b"].save(tmp_path / "b.off")
    np.savetxt(tmp_path / "init.map", init + 1, fmt="%d")
    for method, k_process in REFINER_EIGENPAIRS.items():
        out = tmp_path / f"{method}.map"
        subprocess.run(
            [cli(), "--threads", "2", "refine", str(tmp_path / "a.off"), str(tmp_path / "b.off"), "--init-map",
             str(tmp_path / "init.map"), "--refine", method, "--zoomout", "20:60:10", "--out", str(out)],
            check=True,
            capture_output=True,
        )
        a2 = fmaps.prepare(fmaps.Mesh.load(tmp_path / "a.off"), k_process=k_process)
        b2 = fmaps.prepare(fmaps.Mesh.load(tmp_path / "b.off"), k_process=k_process)
        got = fmaps.refine(a2, b2, init, method=method, schedule="20:60:10")
        assert got.refiner != "", method
        assert np.array_equal(got.map_ab, fmaps.read_indices(out)), method
    ev = lambda m: fmaps.evaluate(p["a"], p["b"], m, p["gt_a"], p["gt_b"], p["gt_b_sym"])["mean_error"]
    z = fmaps.refine(a, b, init, method="zoomout", schedule="20:60:10")
    assert ev(z.map_ab) < ev(init)


def test_refine_gives_the_cli_refine_map(pair, tmp_path):
    p, a, b = pair
    init = fmaps.match_prepared(a, b, refine="none", starts=[]).map_ab_init
    p["a"].save(tmp_path / "a.off")
    p["b"].save(tmp_path / "b.off")
    np.savetxt(tmp_path / "init.map", init + 1, fmt="%d")
    subprocess.run(
        [cli(), "refine", str(tmp_path / "a.off"), str(tmp_path / "b.off"), "--init-map", str(tmp_path / "init.map"),
         "--refine", "icp", "--out", str(tmp_path / "out.map")],
        check=True,
        capture_output=True,
    )
    want = fmaps.read_indices(tmp_path / "out.map")
    a2 = fmaps.prepare(fmaps.Mesh.load(tmp_path / "a.off"), k_process=50)
    b2 = fmaps.prepare(fmaps.Mesh.load(tmp_path / "b.off"), k_process=50)
    got = fmaps.refine(a2, b2, init, method="icp")
    assert np.array_equal(got.map_ab, want)


def test_landmarks_give_the_cli_map(pair, tmp_path):
    p, _, _ = pair
    p["a"].save(tmp_path / "a.off")
    p["b"].save(tmp_path / "b.off")
    pairs = [(int(p["gt_a"][i]), int(p["gt_b"][i])) for i in (0, 100, 300)]
    (tmp_path / "lm.txt").write_text("".join(f"{x + 1} {y + 1}\n" for x, y in pairs))
    subprocess.run(
        [cli(), "--threads", "2", "match", str(tmp_path / "a.off"), str(tmp_path / "b.off"), "--landmarks",
         str(tmp_path / "lm.txt"), "--refine", "none", "--out", str(tmp_path / "ab.map")],
        check=True,
        capture_output=True,
    )
    want = fmaps.read_indices(tmp_path / "ab.map")
    got = fmaps.match_shapes(fmaps.Mesh.load(tmp_path / "a.off"), fmaps.Mesh.load(tmp_path / "b.off"),
                             refine="none", landmarks=pairs, threads=2)
    assert np.array_equal(got.map_ab, want)
    plain = fmaps.match_shapes(fmaps.Mesh.load(tmp_path / "a.off"), fmaps.Mesh.load(tmp_path / "b.off"),
                               refine="none", threads=2)
    assert not np.array_equal(plain.map_ab, want)  # the landmarks were used
    with pytest.raises(fmaps.FmapsError, match="landmarks: pair 0"):
        fmaps.match_shapes(p["a"], p["b"], landmarks=[(-1, 0)])


def grid(n):
    """A flat n x n grid of the unit square, two triangles per cell."""
    xs = np.linspace(0.0, 1.0, n)
    v = np.array([[x, y, 0.0] for y in xs for x in xs])
    f = []
    for j in range(n - 1):
        for i in range(n - 1):
            q = j * n + i
            f += [[q, q + 1, q + n + 1], [q, q + n + 1, q + n]]
    return fmaps.Mesh(v, np.array(f))


def test_exact_geodesics_on_a_plane_are_euclidean():
    m = grid(12)
    v = m.vertices
    src = np.array([0, 77])
    fields = fmaps.geodesics(m, src, per_source=True)
    assert fields.shape == (2, m.n_vertices)
    for row, s in zip(fields, src):
        assert np.allclose(row, np.linalg.norm(v - v[s], axis=1), atol=1e-12)
    nearest = fmaps.geodesics(m, src)
    assert np.allclose(nearest, fields.min(axis=0), atol=1e-12)
    # Indices as a list, int32 or whole floats convert; fractions do not.
    assert np.array_equal(fmaps.geodesics(m, [0, 77]), nearest)
    assert np.array_equal(fmaps.geodesics(m, src.astype(np.int32)), nearest)
    assert np.array_equal(fmaps.geodesics(m, [0.0, 77.0]), nearest)
    with pytest.raises(fmaps.FmapsError, match="sources: entry 0 is 0.5, not an integer index"):
        fmaps.geodesics(m, [0.5])
    # Dijkstra runs along edges: never shorter.
    assert np.all(fmaps.geodesics(m, src, method="dijkstra") >= nearest - 1e-12)


def test_heat_geodesics_approach_the_exact_ones_under_refinement():
    # The heat method converges with the mesh size (Crane et al. 2013; a
    # few percent mean relative error on meshes like these): the error
    # shrinks from 642 to 2,562 vertices and stays within 4% on average.
    errs = []
    for sub in [3, 4]:
        m = fmaps.demo_pairs(subdivisions=sub)[0]["a"]
        exact = fmaps.geodesics(m, np.array([0]))
        heat = fmaps.geodesics(m, np.array([0]), method="heat")
        far = exact > 0
        errs.append(np.mean(np.abs(heat - exact)[far] / exact[far]))
    assert errs[1] < errs[0] < 0.04


@pytest.mark.parametrize(
    "call, says",
    [
        (lambda a, b: fmaps.fit(a, b, descr_a=np.ones((3, 2))), "both descr_a and descr_b"),
        (lambda a, b: fmaps.fit(a, b, descr_a=np.ones((3, 2)), descr_b=np.ones((3, 2))), "rows"),
        (lambda a, b: fmaps.fit(a, b, landmarks=[(0, 10**9)]), "landmarks: pair 0"),
        (lambda a, b: fmaps.fit(a, b, kind="sift"), "unknown descriptor"),
        (lambda a, b: fmaps.refine(a, b, np.zeros(a.n_vertices, dtype=np.int64), method="magic"), "unknown refinement"),
        (lambda a, b: fmaps.refine(a, b, np.zeros(3, dtype=np.int64)), "map_ab has 3 entries"),
        (lambda a, b: fmaps.refine(a, b, np.zeros(a.n_vertices, dtype=np.int64), k=20), "schedule starts at 50"),
        (lambda a, b: fmaps.fmap_to_map(np.eye(500), a, b), "c_ba is 500 x 500"),
        (lambda a, b: fmaps.map_to_fmap(np.zeros(a.n_vertices, dtype=np.int64), a, b, k=0), "k = 0"),
        (lambda a, b: fmaps.geodesics(a.mesh, np.array([a.n_vertices])), "sources: entry 0"),
        (lambda a, b: fmaps.geodesics(a.mesh, np.array([0]), method="fast"), "expected \"exact\""),
    ],
)
def test_bad_stage_input_raises(pair, call, says):
    _, a, b = pair
    with pytest.raises(fmaps.FmapsError, match=None) as e:
        call(a, b)
    assert says in str(e.value)


def test_map_quality_of_the_identity_and_of_a_mirror_image(pair):
    p, _, _ = pair
    a = p["a"]
    ident = np.arange(a.n_vertices)
    q = fmaps.map_quality(a, a, ident, ident)
    assert q["coverage"] == 1.0 and q["collapsed_faces"] == 0.0
    assert abs(q["area_distortion"]) < 1e-12 and abs(q["conformal_distortion"]) < 1e-12
    assert abs(q["orientation"] - 1.0) < 1e-12 and q["round_trip"] == 0.0
    # A mirror image (x negated, triangles rewound so that normals point
    # outwards again): the identity reverses orientation, every triangle
    # keeps its area and shape.
    mirrored = fmaps.Mesh(a.vertices * np.array([-1.0, 1.0, 1.0]), a.faces[:, ::-1].copy())
    q = fmaps.map_quality(a, mirrored, ident)
    assert abs(q["orientation"] + 1.0) < 1e-12
    assert abs(q["area_distortion"]) < 1e-12


def test_the_validation_report_counts_what_closed_forms_say(pair):
    p, _, _ = pair
    r = p["a"].validate()
    # A closed genus-0 surface: V - E + F = 2, no boundary.
    assert r["is_closed_manifold"] and r["genus"] == 0 and r["euler_characteristic"] == 2
    assert r["n_edges"] == 3 * r["n_faces"] // 2
    g = grid(5).validate()
    # A 5 x 5 grid: one boundary loop of 16 edges, 25 - 56 + 32 = 1.
    assert (g["boundary_loops"], g["boundary_edges"], g["euler_characteristic"]) == (1, 16, 1)
    assert g["genus"] == 0 and not g["is_closed_manifold"]
    # A repeated triangle is listed (0-based, the later copy).
    m = grid(3)
    dup = fmaps.Mesh(m.vertices, np.vstack([m.faces, m.faces[:1]])).validate()
    assert dup["duplicate_faces"] == [m.n_faces]
