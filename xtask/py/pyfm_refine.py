#!/usr/bin/env python3
"""pyFM's refiners on inputs written by `cargo xtask bench-refine`.

WORKDIR holds phi1.npy (n1 x K), phi2.npy (n2 x K), mass2.npy (n2 x 1) and
C.npy (k2 x k1, FM_12: functions on shape 1 to shape 2). Runs

  icp N                    pyFM.refine.icp_refine(C, phi1[:, :k1], phi2[:, :k2], A2=mass2, nit=N)
  zoomout K0 NIT STEP      pyFM.refine.zoomout_refine(C[:K0, :K0], phi1, phi2, nit=NIT, step=STEP, A2=mass2)

each with return_p2p=True (the point map 2 -> 1 of the final map, as
get_p2p computes it): one untimed warm-up call, then --repeat timed calls
(time.perf_counter; imports and loading excluded); writes the 0-based
point map to --out (one index per line) and prints JSON {method, params,
seconds (the median), all (every timed call), threads}.
"""
import argparse
import json
import os
import sys

p = argparse.ArgumentParser()
p.add_argument("workdir")
p.add_argument("method", choices=["icp", "zoomout"])
p.add_argument("params", nargs="+", type=int)
p.add_argument("--threads", type=int, default=1)
p.add_argument("--repeat", type=int, default=5)
p.add_argument("--out", required=True)
args = p.parse_args()
for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[var] = str(args.threads)

import time  # noqa: E402

import numpy as np  # noqa: E402
import pyFM.refine  # noqa: E402

w = args.workdir
phi1 = np.load(os.path.join(w, "phi1.npy"))
phi2 = np.load(os.path.join(w, "phi2.npy"))
mass2 = np.load(os.path.join(w, "mass2.npy"))[:, 0]
C = np.load(os.path.join(w, "C.npy"))
k2, k1 = C.shape


def call():
    if args.method == "icp":
        (nit,) = args.params
        return pyFM.refine.icp_refine(C, phi1[:, :k1], phi2[:, :k2], A2=mass2, nit=nit,
                                      return_p2p=True, n_jobs=args.threads)[1]
    k0, nit, step = args.params
    return pyFM.refine.zoomout_refine(C[:k0, :k0], phi1, phi2, nit=nit, step=step, A2=mass2,
                                      return_p2p=True, n_jobs=args.threads)[1]


p2p = call()  # warm-up
times = []
for _ in range(max(1, args.repeat)):
    t = time.perf_counter()
    p2p = call()
    times.append(time.perf_counter() - t)
dt = sorted(times)[len(times) // 2]
np.savetxt(args.out, np.asarray(p2p, dtype=np.int64), fmt="%d")
print(json.dumps({"method": args.method, "params": args.params, "seconds": dt, "all": times,
                  "threads": args.threads}))
sys.stdout.flush()
