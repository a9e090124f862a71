#!/usr/bin/env python3
"""Run pyFM's fit (L-BFGS-B) on one pair and dump its inputs and result.

For `cargo xtask fit-check`: the same bases, descriptors and weights go
into fmaps' exact solver, and both minima are compared on one energy.

The model is FunctionalMapping(mesh_B, mesh_A) as in
../shared/peers/pyfm_pipeline.py (C maps functions on B to functions on A).
Writes to OUT: evecs{1,2}.npy (n x K), evals{1,2}.npy, mass{1,2}.npy,
descr{1,2}.npy (n x p, as used by fit), fm.npy (K x K), and info.json with
the final L-BFGS-B energy, the normalized weights it used and the seconds.
"""
import argparse
import json
import os
import time

import numpy as np
import pyFM.functional
from pyFM.functional import FunctionalMapping
from pyFM.mesh import TriMesh
from pyFM.mesh.laplacian import laplacian_spectrum

p = argparse.ArgumentParser()
p.add_argument("mesh_a")
p.add_argument("mesh_b")
p.add_argument("--out", required=True)
p.add_argument("--k", type=int, default=50)
p.add_argument("--w-orient", type=float, default=1.0)
args = p.parse_args()
os.makedirs(args.out, exist_ok=True)

meshes = []
for path in (args.mesh_b, args.mesh_a):
    m = TriMesh.load(path)
    m.compute_operators()
    m.eigenvalues, m.eigenvectors = laplacian_spectrum(m.stiffness, m.mass, 200)
    meshes.append(m)
model = FunctionalMapping(meshes[0], meshes[1])
model.compute_spectral_descriptors(n_descr=100, descr_type="WKS", k_descr=128)

record = {}
original = pyFM.functional.fmin_l_bfgs_b


def traced(func, x0, args=(), **kw):
    res = original(func, x0, args=args, **kw)
    record["energy"] = float(res[1])
    record["mu"] = [float(a) for a in args[:4]]
    record["funcalls"] = int(res[2]["funcalls"])
    record["nit"] = int(res[2]["nit"])
    return res


pyFM.functional.fmin_l_bfgs_b = traced
t = time.perf_counter()
model.fit(K=(args.k, args.k), w_orient=args.w_orient)
record["fit_seconds"] = time.perf_counter() - t
k = args.k
for i, m in ((1, model.mesh1), (2, model.mesh2)):
    np.save(os.path.join(args.out, f"evecs{i}.npy"), np.ascontiguousarray(m.eigenvectors[:, :k]))
    np.save(os.path.join(args.out, f"evals{i}.npy"), m.eigenvalues[:k])
    np.save(os.path.join(args.out, f"mass{i}.npy"), np.asarray(m.mass.diagonal()))
np.save(os.path.join(args.out, "descr1.npy"), np.ascontiguousarray(model.descr1))
np.save(os.path.join(args.out, "descr2.npy"), np.ascontiguousarray(model.descr2))
np.save(os.path.join(args.out, "fm.npy"), np.ascontiguousarray(model.FM_12))
with open(os.path.join(args.out, "info.json"), "w") as f:
    json.dump(record, f)
print(json.dumps(record))
