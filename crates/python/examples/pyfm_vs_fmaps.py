"""The pyFM tutorial pipeline and its fmaps equivalent, timed side by side
(docs/python-migration.md). Run each side with the interpreter that has it:

    OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 ~/.cache/fmaps-peers/bin/python \\
        crates/python/examples/pyfm_vs_fmaps.py pyfm A.off B.off --out pyfm.map
    python crates/python/examples/pyfm_vs_fmaps.py fmaps A.off B.off --out fmaps.map

Each side: imports before the clock; one warm-up run, then `--repeat` timed
runs of the whole script body (load, eigenbases k=200, WKS, the fit with
the orientation term, ZoomOut 50 -> 150 in steps of 5, point map), one
thread; prints the median and writes the map A -> B (1-based .map) of the
last run for `fmaps eval`.
"""

import argparse
import json
import statistics
import sys
import time

import numpy as np


def pyfm_pipeline(path_a, path_b):
    from pyFM.functional import FunctionalMapping
    from pyFM.mesh import TriMesh

    mesh_a = TriMesh.load(path_a, area_normalize=True, center=True)
    mesh_b = TriMesh.load(path_b, area_normalize=True, center=True)
    # pyFM's "p2p_21" of FunctionalMapping(B, A) maps A's vertices to B.
    model = FunctionalMapping(mesh_b, mesh_a)
    model.preprocess(n_descr=100, descr_type="WKS", k_process=200, k_descr=128)
    model.fit(K=(50, 50), w_descr=1e-1, w_lap=1e-3, w_dcomm=1, w_orient=1)
    fm = model.zoomout_refine(nit=20, step=5)
    return model.get_p2p(fm, n_jobs=1)


def fmaps_pipeline(path_a, path_b):
    import fmaps

    a, b = fmaps.Mesh.load(path_a), fmaps.Mesh.load(path_b)
    # One start, as pyFM runs ZoomOut (fmaps' own default adds two more).
    r = fmaps.match_shapes(a, b, refine="zoomout", starts=[], threads=1)
    return r.map_ab


def main():
    p = argparse.ArgumentParser()
    p.add_argument("side", choices=["pyfm", "fmaps"])
    p.add_argument("a")
    p.add_argument("b")
    p.add_argument("--out", required=True)
    p.add_argument("--repeat", type=int, default=5)
    args = p.parse_args()
    run = pyfm_pipeline if args.side == "pyfm" else fmaps_pipeline
    if args.side == "pyfm":
        import pyFM.functional  # noqa: F401  (imports before the clock)
    else:
        import fmaps  # noqa: F401
    run(args.a, args.b)  # warm-up
    times = []
    for _ in range(args.repeat):
        t = time.perf_counter()
        m = run(args.a, args.b)
        times.append(time.perf_counter() - t)
    np.savetxt(args.out, np.asarray(m, dtype=np.int64) + 1, fmt="%d")
    print(json.dumps({"side": args.side, "median_seconds": statistics.median(times), "seconds": times}))


if __name__ == "__main__":
    sys.exit(main())
