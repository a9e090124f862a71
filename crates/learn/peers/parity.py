"""DiffusionNet and the training losses of fmaps-learn against PyTorch.

Run in a benchmark venv with torch and geomfum (both from PyPI), after
`cargo xtask learn-parity` wrote the arrays:

    python -m venv ~/.cache/fmaps-torch && ~/.cache/fmaps-torch/bin/pip install torch geomfum
    cargo xtask learn-parity --out target/learn-parity
    ~/.cache/fmaps-torch/bin/python crates/learn/peers/parity.py target/learn-parity [--bench]

1. Forward: geomfum's DiffusionNet (the reference network in PyTorch) with
   fmaps' weights and fmaps' operators (so only the network is compared),
   no dropout, float64, on both shapes: relative difference of the
   features.  geomfum writes the imaginary part of the gradient features'
   complex-linear map as A_re(g_x) + A_im(g_y); the authors' DiffusionNet
   (and fmaps) use A_re(g_y) + A_im(g_x), the product of the complex
   number A = A_re + i A_im with g = g_x + i g_y.  The script runs the
   network with the authors' product (and reports the difference geomfum's
   product as written makes).
2. One training step: the regularised functional-map layer (resolvent mask,
   Ren et al. 2019; row by row as ULRSSM solves it), the bijectivity,
   orthogonality, Laplacian-commutativity and coupling losses written here
   in PyTorch from the papers, differentiated by autograd: the maps, the
   loss values and every parameter's gradient against fmaps' hand-written
   backward pass.
3. --bench: the reference network's forward and forward+backward time on
   the first shape (float32 and float64, 1 and 2 threads, medians of 5
   after a warm-up), to set beside `cargo xtask bench-learn`.
"""

import argparse
import json
import os
import statistics
import sys
import time

import numpy as np
import torch

from geomfum.wrap import diffusionnet as gd


def authors_gradient_product(self, feat_in):
    """The authors' complex-linear product: Re(conj(g) * (A g))."""
    gx, gy = feat_in[..., 0], feat_in[..., 1]
    b_re = self.A_re(gx) - self.A_im(gy)
    b_im = self.A_re(gy) + self.A_im(gx)
    return torch.tanh(gx * b_re + gy * b_im)


GEOMFUM_PRODUCT = gd.SpatialGradientFeatures.forward


def geomfum_name(name):
    name = name.replace("first_lin.", "first_linear.").replace("last_lin.", "last_linear.")
    if name.startswith("block_"):
        i, rest = name[len("block_"):].split(".", 1)
        name = f"blocks.{i}.{rest}"
    return name.replace("miniMLP_mlp_layer_", "miniMLP_linear_")


def load_state(net, model_path):
    z = np.load(model_path)
    meta = json.loads(z["meta"].tobytes().decode())
    state = {}
    for k in z.files:
        if k == "meta":
            continue
        state[geomfum_name(k)] = torch.tensor(z[k])
    missing, unexpected = net.load_state_dict(state, strict=True), None
    return meta


def shape_tensors(d, tag, k_net, dtype):
    a = lambda f: np.load(os.path.join(d, f"{tag}_{f}.npy"))
    n = a("mass").shape[0]

    def sparse(g):
        r, c, v = a(f"{g}_rows"), a(f"{g}_cols"), a(f"{g}_vals")
        idx = torch.tensor(np.stack([np.zeros_like(r), r, c]).astype(np.int64))
        return torch.sparse_coo_tensor(idx, torch.tensor(v, dtype=dtype), (1, n, n)).coalesce()

    evecs_all = torch.tensor(a("evecs"), dtype=dtype)
    evals_all = torch.tensor(a("evals"), dtype=dtype)
    return {
        "mass": torch.tensor(a("mass"), dtype=dtype),
        "evals": evals_all[:k_net],
        "evecs": evecs_all[:, :k_net],
        "evals_fmap": evals_all,
        "evecs_fmap": evecs_all,
        "gradX": sparse("gradX"),
        "gradY": sparse("gradY"),
        "input": torch.tensor(a("input"), dtype=dtype),
        "ours": a("features"),
    }


def forward(net, s):
    return net(
        verts=s["input"][None],
        feats=s["input"][None],
        mass=s["mass"][None],
        evals=s["evals"][None],
        evecs=s["evecs"][None],
        gradX=s["gradX"],
        gradY=s["gradY"],
    )[0]


def rel(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


def resolvent_mask(evals_a, evals_b, gamma):
    scale = torch.maximum(evals_a.abs().max(), evals_b.abs().max())
    ga = (evals_a.abs() / scale) ** gamma
    gb = (evals_b.abs() / scale) ** gamma
    ra, ia = ga / (ga**2 + 1), 1 / (ga**2 + 1)
    rb, ib = gb / (gb**2 + 1), 1 / (gb**2 + 1)
    return (ra[None, :] - rb[:, None]) ** 2 + (ia[None, :] - ib[:, None]) ** 2


def fmap_layer(a, b, evals_a, evals_b, lam, gamma):
    """C (k_b x k_a) minimising |C A - B|^2 + lam sum mask C^2, row by row."""
    mask = resolvent_mask(evals_a, evals_b, gamma)
    aat = a @ a.T
    rhs = b @ a.T
    rows = [torch.linalg.solve(aat + lam * torch.diag(mask[i]), rhs[i]) for i in range(b.shape[0])]
    return torch.stack(rows)


def pair_losses(fx, fy, sx, sy, recipe):
    project = lambda s, f: s["evecs_fmap"].T @ (s["mass"][:, None] * f)
    a, b = project(sx, fx), project(sy, fy)
    lam, gamma = recipe["fmap"]["lambda"], recipe["fmap"]["gamma"]
    cxy = fmap_layer(a, b, sx["evals_fmap"], sy["evals_fmap"], lam, gamma)
    cyx = fmap_layer(b, a, sy["evals_fmap"], sx["evals_fmap"], lam, gamma)
    w = recipe["weights"]
    eye = torch.eye(cxy.shape[0], dtype=cxy.dtype)
    fro = lambda m: (m**2).sum()
    bij = fro(cxy @ cyx - eye) + fro(cyx @ cxy - eye)
    orth = fro(cxy.T @ cxy - eye) + fro(cyx.T @ cyx - eye)
    lap = (resolvent_mask(sx["evals_fmap"], sy["evals_fmap"], gamma) * cxy**2).sum() + (
        resolvent_mask(sy["evals_fmap"], sx["evals_fmap"], gamma) * cyx**2
    ).sum()
    gx = torch.nn.functional.normalize(fx, dim=-1)
    gy = torch.nn.functional.normalize(fy, dim=-1)
    sim = gx @ gy.T
    tau = recipe["tau"]
    pxy = torch.softmax(sim / tau, dim=-1)
    pyx = torch.softmax(sim.T / tau, dim=-1)
    est_xy = sy["evecs_fmap"].T @ (sy["mass"][:, None] * (pyx @ sx["evecs_fmap"]))
    est_yx = sx["evecs_fmap"].T @ (sx["mass"][:, None] * (pxy @ sy["evecs_fmap"]))
    couple = fro(cxy - est_xy) + fro(cyx - est_yx)
    losses = {
        "bijectivity": w["bijectivity"] * bij,
        "orthogonality": w["orthogonality"] * orth,
        "laplacian": w["laplacian"] * lap,
        "coupling": w["coupling"] * couple,
    }
    losses["total"] = sum(losses.values())
    return losses, cxy, cyx


def bench(net, s, repeats=5):
    out = {}
    for dtype_name, dtype in [("float32", torch.float32), ("float64", torch.float64)]:
        n2 = net.to(dtype)
        t = {k: (v.to(dtype) if torch.is_tensor(v) and v.is_floating_point() else v) for k, v in s.items() if k != "ours"}
        n2.train()  # dropout on, as a training step runs
        for threads in [1, 2]:
            torch.set_num_threads(threads)
            fw, fb = [], []
            for r in range(repeats + 1):
                t0 = time.perf_counter()
                with torch.no_grad():
                    forward(n2, t)
                t1 = time.perf_counter()
                y = forward(n2, t)
                y.backward(torch.ones_like(y))
                t2 = time.perf_counter()
                n2.zero_grad()
                if r > 0:
                    fw.append(t1 - t0)
                    fb.append(t2 - t1)
            out[f"{dtype_name} {threads} thread(s)"] = {
                "forward_s": statistics.median(fw),
                "forward_backward_s": statistics.median(fb),
            }
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("folder")
    ap.add_argument("--bench", action="store_true")
    args = ap.parse_args()
    d = args.folder
    pair = json.load(open(os.path.join(d, "pair.json")))
    recipe = pair["recipe"]
    k_net = pair["eigenpairs_net"]
    torch.set_num_threads(2)
    report = {"torch": torch.__version__}

    z = np.load(os.path.join(d, "model.npz"))
    meta = json.loads(z["meta"].tobytes().decode())
    arch = meta["architecture"]
    net = gd.DiffusionNet(
        in_channels=arch["inputs"],
        out_channels=arch["outputs"],
        hidden_channels=arch["width"],
        n_block=arch["blocks"],
        dropout=True,
        k_eig=k_net,
    ).double()
    load_state(net, os.path.join(d, "model.npz"))
    net.eval()
    sx = shape_tensors(d, "x", k_net, torch.float64)
    sy = shape_tensors(d, "y", k_net, torch.float64)

    gd.SpatialGradientFeatures.forward = GEOMFUM_PRODUCT
    with torch.no_grad():
        report["forward_rel_diff_geomfum_product"] = rel(forward(net, sx).numpy(), sx["ours"])
    gd.SpatialGradientFeatures.forward = authors_gradient_product
    with torch.no_grad():
        report["forward_rel_diff_x"] = rel(forward(net, sx).numpy(), sx["ours"])
        report["forward_rel_diff_y"] = rel(forward(net, sy).numpy(), sy["ours"])

    net.zero_grad()
    fx, fy = forward(net, sx), forward(net, sy)
    losses, cxy, cyx = pair_losses(fx, fy, sx, sy, recipe)
    losses["total"].backward()
    report["maps_rel_diff"] = max(
        rel(cxy.detach().numpy(), np.load(os.path.join(d, "cxy.npy"))),
        rel(cyx.detach().numpy(), np.load(os.path.join(d, "cyx.npy"))),
    )
    ours = pair["losses"]
    report["loss_rel_diff"] = {
        k: abs(float(v) - ours[k]) / max(abs(ours[k]), 1e-300) for k, v in losses.items()
    }
    worst, worst_name = 0.0, None
    named = dict(net.named_parameters())
    for f in sorted(os.listdir(d)):
        if not f.startswith("grad."):
            continue
        name = f[len("grad."):-len(".npy")]
        g_ours = np.load(os.path.join(d, f)).reshape(named[geomfum_name(name)].shape)
        g_torch = named[geomfum_name(name)].grad.numpy()
        r = rel(g_torch, g_ours)
        if r > worst:
            worst, worst_name = r, name
    report["gradient_worst_rel_diff"] = {"tensor": worst_name, "rel_diff": worst}
    if args.bench:
        report["bench_reference"] = bench(net, sx)
    print(json.dumps(report, indent=2))
    ok = (
        max(report["forward_rel_diff_x"], report["forward_rel_diff_y"]) < 1e-4
        and report["maps_rel_diff"] < 1e-4
        and max(report["loss_rel_diff"].values()) < 1e-4
        and worst < 1e-4
    )
    print("parity:", "PASS (all within 1e-4 relative)" if ok else "FAIL", file=sys.stderr)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
