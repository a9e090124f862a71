"""Learned features from Python: the same maps as `fmaps match --features
learned`, a model trained by `fmaps.train` used by path, test-time
adaptation, and options that need learned features refused.
"""

import subprocess

import numpy as np
import pytest

import fmaps
from test_fmaps import cli, faust


def test_learned_features_give_the_cli_map(tmp_path):
    a, b = faust("tr_reg_080"), faust("tr_reg_091")
    out = tmp_path / "ab.map"
    subprocess.run(
        [cli(), "--threads", "2", "match", str(a), str(b), "--features", "learned", "--out", str(out)],
        check=True,
        capture_output=True,
    )
    r = fmaps.match_shapes(fmaps.Mesh.load(a), fmaps.Mesh.load(b), features="learned", threads=2)
    assert r.refiner.startswith("zoomout"), r.refiner
    assert np.array_equal(r.map_ab, fmaps.read_indices(out))


def test_learned_second_opinion_gives_the_cli_map(tmp_path):
    a, b = faust("tr_reg_080"), faust("tr_reg_091")
    out = tmp_path / "ab.map"
    subprocess.run(
        [cli(), "--threads", "2", "match", str(a), str(b), "--features", "learned", "--second-opinion"]
        + ["--out", str(out)],
        check=True,
        capture_output=True,
    )
    r = fmaps.match_shapes(fmaps.Mesh.load(a), fmaps.Mesh.load(b), features="learned", second_opinion=True, threads=2)
    assert np.array_equal(r.map_ab, fmaps.read_indices(out))
    passed = r.confidence["passed_over"]
    assert passed["features"] in ("learned", "descriptors")
    assert passed["area_distortion"] >= r.confidence["area_distortion"]


# A small network and a short run.
SMALL = dict(
    steps=4, width=8, blocks=1, outputs=24, inputs=8, eigenpairs=24, fmap_k=16, coupling_samples=200, threads=1
)


def test_a_trained_model_matches_and_adapts(tmp_path, pairs_small):
    a, b = pairs_small
    model = tmp_path / "small.npz"
    losses = fmaps.train([a, b], str(model), **SMALL)
    assert [d["step"] for d in losses] == [1, 2, 3, 4]
    assert all(np.isfinite(d["total"]) for d in losses)
    assert model.is_file()
    # A second call on the same files continues from the checkpoint: no
    # step is left to run.
    again = fmaps.train([a, b], str(model), **SMALL)
    assert again == []
    plain = fmaps.match_shapes(a, b, features="learned", model=str(model), refine="none", k=16, threads=1)
    adapted = fmaps.match_shapes(
        a, b, features="learned", model=str(model), adapt=3, refine="none", k=16, threads=1
    )
    assert len(plain.map_ab) == len(adapted.map_ab) == a.n_vertices
    # Adaptation changes the network, so the map.
    assert not np.array_equal(plain.map_ab, adapted.map_ab)
    # Prepared shapes give the map of the same eigenpairs.
    same = fmaps.match_shapes(
        a, b, features="learned", model=str(model), refine="none", k=16, k_process=60, threads=1
    )
    prepared = [fmaps.prepare(m, k_process=60, threads=1) for m in (a, b)]
    again = fmaps.match_prepared(*prepared, features="learned", model=str(model), refine="none", k=16, threads=1)
    assert np.array_equal(again.map_ab, same.map_ab)
    # Shapes prepared with the model's features give the same map.
    learned = [fmaps.prepare(m, k_process=60, features="learned", model=str(model), threads=1) for m in (a, b)]
    third = fmaps.match_prepared(*learned, features="learned", model=str(model), refine="none", k=16, threads=1)
    assert np.array_equal(third.map_ab, same.map_ab)
    with pytest.raises(fmaps.FmapsError, match="k_process >= 24"):
        fmaps.prepare(a, k_process=20, features="learned", model=str(model))


@pytest.fixture(scope="module")
def pairs_small():
    p = fmaps.demo_pairs(subdivisions=3)[0]
    return p["a"], p["b"]


def test_learned_options_need_learned_features():
    p = fmaps.demo_pairs(subdivisions=3)[0]
    for kwargs in ({"adapt": 2}, {"point_map": "spectral"}, {"model": "m.npz"}):
        with pytest.raises(fmaps.FmapsError, match="learned features"):
            fmaps.match_shapes(p["a"], p["b"], **kwargs)
    with pytest.raises(fmaps.FmapsError, match="learned features"):
        fmaps.prepare(p["a"], adapt=2)
    with pytest.raises(fmaps.FmapsError, match="descriptors"):
        fmaps.match_shapes(p["a"], p["b"], features="wks")
    with pytest.raises(fmaps.FmapsError, match="absent.npz"):
        fmaps.match_shapes(p["a"], p["b"], features="learned", model="absent.npz")
