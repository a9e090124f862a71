"""Tests of the Python package against the `fmaps` command (same maps,
same errors) and of what the bindings promise (arrays, errors, threads,
the GIL released).

The CLI is `$FMAPS_BIN`, else `target/release/fmaps` of the checkout
(`.ci/run` builds it). FAUST tests need `../shared/datasets` beside the
checkout (`$FMAPS_DATA` overrides); both are skipped, saying so, where
missing.
"""

import json
import os
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import fmaps

ROOT = Path(__file__).resolve().parents[3]
FAUST = Path(os.environ.get("FMAPS_DATA", ROOT.parent / "shared" / "datasets")) / "bcicp" / "FAUST" / "vtx_5k"


def cli():
    path = os.environ.get("FMAPS_BIN")
    if path:
        assert Path(path).is_file(), f"FMAPS_BIN={path} does not exist"
        return path
    path = ROOT / "target" / "release" / "fmaps"
    if not path.is_file():
        pytest.skip(f"no fmaps binary at {path} (cargo build --release -p fmaps-cli, or set FMAPS_BIN)")
    return str(path)


@pytest.fixture(scope="module")
def pairs():
    return fmaps.demo_pairs()


def test_the_demo_pairs_give_the_cli_demo_numbers(pairs, tmp_path):
    out = subprocess.run(
        [cli(), "--threads", "2", "demo", "--json", "--out", str(tmp_path / "demo")],
        check=True,
        capture_output=True,
        text=True,
    )
    want = json.loads(out.stdout)["pairs"]
    assert [w["pair"] for w in want] == [p["title"] for p in pairs]
    for p, w in zip(pairs, want):
        r = fmaps.match_shapes(p["a"], p["b"], threads=2)
        assert r.refiner.startswith("smooth-shells")
        ev = lambda m: fmaps.evaluate(p["a"], p["b"], m, p["gt_a"], p["gt_b"], p["gt_b_sym"], threads=2)
        init, final = ev(r.map_ab_init), ev(r.map_ab)
        # The same computation: equal to the last bit (JSON keeps it).
        assert final["mean_error"] == w["mean_error"], p["name"]
        assert init["mean_error"] == w["mean_error_init"], p["name"]
        assert r.orientation == w["orientation"], p["name"]
        assert final["sym_mean_error"] == w["sym_mean_error"], p["name"]


def test_the_non_isometric_setting_matches_the_bodies(pairs):
    p = pairs[1]
    r = fmaps.match_shapes(p["a"], p["b"], non_isometric=True, threads=2)
    assert "8 orientations screened" in r.refiner and "area distortion" in r.refiner
    e = fmaps.evaluate(p["a"], p["b"], r.map_ab, p["gt_a"], p["gt_b"], threads=2)
    # The demo's two builds: 0.0303 with the default, 0.0295 with this
    # setting (`cargo xtask eval --collection generated-noniso`, pair
    # body_0_1 -> body_5_3; the default's orientation is the right one
    # here); a wrong orientation scores above 0.3.
    assert e["mean_error"] < 0.05, e["mean_error"]


def test_a_second_opinion_keeps_the_less_distorting_setting(pairs):
    p = pairs[1]
    both = fmaps.match_shapes(p["a"], p["b"], second_opinion=True, threads=2)
    assert both.refiner.startswith("best of (smooth-shells"), both.refiner
    # The kept map is one of the two settings' maps, the one of least area
    # distortion.
    one = fmaps.match_shapes(p["a"], p["b"], threads=2)
    other = fmaps.match_shapes(p["a"], p["b"], non_isometric=True, threads=2)
    kept = min((one, other), key=lambda r: r.confidence["area_distortion"])
    assert np.array_equal(both.map_ab, kept.map_ab)


def faust(name):
    path = FAUST / f"{name}.off"
    if not path.is_file():
        if os.environ.get("FMAPS_REQUIRE_DATA", "0") not in ("", "0"):
            pytest.fail(f"FAUST not found at {FAUST}, and FMAPS_REQUIRE_DATA is set")
        pytest.skip(f"FAUST not found at {FAUST} (set FMAPS_DATA)")
    return path


def test_a_faust_pair_gives_the_cli_map(tmp_path):
    a, b = faust("tr_reg_080"), faust("tr_reg_081")
    out = tmp_path / "ab.map"
    info = subprocess.run(
        [cli(), "--threads", "2", "match", str(a), str(b), "--out", str(out), "--json"],
        check=True,
        capture_output=True,
        text=True,
    )
    r = fmaps.match_shapes(fmaps.Mesh.load(a), fmaps.Mesh.load(b), threads=2)
    # The .map file is 1-based; read_indices makes it 0-based.
    assert np.array_equal(r.map_ab, fmaps.read_indices(out))
    cli_json = json.loads(info.stdout)
    assert r.orientation == cli_json["orientation"]
    # The same confidence as the CLI's, and a trusted map.
    assert r.confidence["metric_distortion"] == cli_json["confidence"]["metric_distortion"]
    assert not r.confidence["likely_wrong"] and r.confidence["advice"] is None
    gt_a = fmaps.read_indices(FAUST / "corres" / "tr_reg_080.vts")
    gt_b = fmaps.read_indices(FAUST / "corres" / "tr_reg_081.vts")
    e = fmaps.evaluate(fmaps.Mesh.load(a), fmaps.Mesh.load(b), r.map_ab, gt_a, gt_b, geodesic="dijkstra")
    # FAUST_r with the default: 2.086 x100 on average over its 190 pairs.
    assert e["mean_error"] < 0.05, e["mean_error"]


def test_energy_weights_reach_the_solve_as_in_the_cli(pairs, tmp_path):
    p = pairs[1]
    p["a"].save(tmp_path / "a.off")
    p["b"].save(tmp_path / "b.off")
    weights = {"w_descr": 1.0, "w_lap": 0.01, "w_dcomm": 0.0, "w_orient": 0.5}
    flags = [x for k, v in weights.items() for x in ("--" + k.replace("_", "-"), str(v))]
    out = tmp_path / "ab.map"
    subprocess.run(
        [cli(), "match", str(tmp_path / "a.off"), str(tmp_path / "b.off"), "--refine", "none", "--out", str(out), *flags],
        check=True,
        capture_output=True,
    )
    r = fmaps.match_shapes(p["a"], p["b"], refine="none", **weights)
    assert np.array_equal(r.map_ab, fmaps.read_indices(out))
    # Other weights give another C; the defaults are the CLI's.
    default = fmaps.match_shapes(p["a"], p["b"], refine="none")
    assert not np.allclose(r.c_ba, default.c_ba)
    same = fmaps.match_shapes(p["a"], p["b"], refine="none", w_descr=0.1, w_lap=0.001, w_dcomm=1.0, w_orient=1.0)
    assert np.array_equal(same.c_ba, default.c_ba)
    with pytest.raises(fmaps.FmapsError, match="weights must be >= 0"):
        fmaps.match_shapes(p["a"], p["b"], refine="none", w_lap=-1.0)


def test_bad_input_raises_with_the_cli_message(tmp_path):
    bad = tmp_path / "bad.off"
    bad.write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n")
    with pytest.raises(fmaps.FmapsError, match=r"bad\.off: end of file: OFF: file ends before vertex 2 of 3"):
        fmaps.Mesh.load(bad)
    out = subprocess.run([cli(), "info", str(bad)], capture_output=True, text=True)
    assert out.returncode == 2 and "file ends before vertex 2 of 3" in out.stderr
    assert issubclass(fmaps.FmapsError, ValueError)
    with pytest.raises(fmaps.FmapsError, match="face 0 refers to vertex 5, but the mesh has 3 vertices"):
        fmaps.Mesh(np.zeros((3, 3)), np.array([[0, 1, 5]]))
    with pytest.raises(fmaps.FmapsError, match="negative"):
        fmaps.Mesh(np.zeros((3, 3)), np.array([[0, 1, -1]]))
    with pytest.raises(fmaps.FmapsError, match="n x 3"):
        fmaps.Mesh(np.zeros((3, 2)), np.array([[0, 1, 2]]))
    with pytest.raises(fmaps.FmapsError, match="finite|NaN|nan"):
        fmaps.Mesh(np.array([[0.0, 0, 0], [1, 0, 0], [np.nan, 1, 0]]), np.array([[0, 1, 2]]))
    with pytest.raises(fmaps.FmapsError, match="refine"):
        m = fmaps.demo_pairs()[0]["a"]
        fmaps.match_shapes(m, m, refine="bogus")


def test_the_spectrum_is_mass_orthonormal_and_comes_out_without_copies(pairs):
    m = pairs[0]["a"]
    evals, basis, mass = fmaps.spectrum(m, k=30, threads=2)
    assert basis.shape == (m.n_vertices, 30) and evals.shape == (30,) and mass.shape == (m.n_vertices,)
    # Phi^T M Phi = I, eigenvalues ascending from 0 (a closed surface).
    gram = basis.T @ (mass[:, None] * basis)
    assert np.abs(gram - np.eye(30)).max() < 1e-8
    assert abs(evals[0]) < 1e-8 and np.all(np.diff(evals) >= -1e-10)
    assert abs(mass.sum() - m.area()) < 1e-9 * m.area()
    # The column-major basis is handed over as a Fortran array over Rust's
    # buffer (numpy does not own it: no copy, no C-ordered duplicate).
    assert basis.flags.f_contiguous and not basis.flags.owndata
    assert type(basis.base).__name__ == "PySliceContainer"
    assert basis.dtype == np.float64


def test_meshes_round_trip_through_numpy(pairs):
    m = pairs[0]["b"]
    v, f = m.vertices, m.faces
    assert v.dtype == np.float64 and f.dtype == np.int64 and f.shape == (m.n_faces, 3)
    again = fmaps.Mesh(v, f)
    assert np.array_equal(again.vertices, v) and np.array_equal(again.faces, f)
    assert again.area() == m.area()


def test_maps_do_not_depend_on_the_number_of_threads(pairs):
    p = pairs[0]
    one = fmaps.match_shapes(p["a"], p["b"], threads=1)
    two = fmaps.match_shapes(p["a"], p["b"], threads=2)
    assert np.array_equal(one.map_ab, two.map_ab)
    assert np.array_equal(one.c_ba, two.c_ba)


def test_long_calls_release_the_gil(pairs):
    p = pairs[0]
    done = threading.Event()

    def work():
        fmaps.match_shapes(p["a"], p["b"], threads=1)
        done.set()

    t = threading.Thread(target=work)
    t.start()
    ticks = 0
    start = time.perf_counter()
    while not done.is_set():
        ticks += 1
        time.sleep(0.001)
    t.join()
    elapsed = time.perf_counter() - start
    # With the GIL held for the whole match the loop would run once or
    # twice; released, it runs about once per millisecond.
    assert elapsed > 0.5 and ticks > elapsed * 100, (ticks, elapsed)


def test_prepared_shapes_pickle_and_give_the_same_map(pairs):
    import pickle

    p = pairs[0]
    pa = pickle.loads(pickle.dumps(fmaps.prepare(p["a"], threads=2)))
    pb = fmaps.prepare(p["b"], threads=2)
    assert pa.n_vertices == p["a"].n_vertices and pa.k_process == 200
    r = fmaps.match_prepared(pa, pb, threads=2)
    want = fmaps.match_shapes(p["a"], p["b"], threads=2)
    assert np.array_equal(r.map_ab, want.map_ab)
    assert np.array_equal(r.c_ba, want.c_ba)


def test_the_example_script_writes_pictures(tmp_path):
    import sys

    script = Path(__file__).resolve().parents[1] / "examples" / "match_and_draw.py"
    out = subprocess.run(
        [sys.executable, str(script), "--out", str(tmp_path)], check=True, capture_output=True, text=True
    )
    # The demo's bodies: the default's error, as `fmaps demo` prints it.
    assert "mean geodesic error x100: 3.03" in out.stdout, out.stdout
    for kind in ("color", "texture"):
        png = (tmp_path / f"{kind}-transfer.png").read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n"
        # IHDR: width (two 480-pixel panels side by side) and height.
        assert int.from_bytes(png[16:20], "big") == 960 and int.from_bytes(png[20:24], "big") == 480
    with pytest.raises(fmaps.FmapsError, match="kind"):
        m = fmaps.demo_pairs()[0]["a"]
        fmaps.render_transfer(m, m, np.arange(m.n_vertices), tmp_path / "x.png", kind="bogus")
