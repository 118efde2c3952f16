"""Train the stacked auto-encoder of the learned print segmentation (seed 6.4.2, Algorithm 6-1)
and write ``assets/print_sae.npz`` (the weights the add-on ships).

    .venv/bin/python scripts/train_print_sae.py                 # writes assets/print_sae.npz
    .venv/bin/python scripts/train_print_sae.py --out /tmp/sae.npz --rows 3000 --seed 0

The seed trains on 3,000 sub-graphs of 30 triangles from 30 meshes of the Princeton
Segmentation Benchmark.  The PSB is not redistributable with this project, so the training
set here is 30 meshes anyone can rebuild:

* two scans from ``tests/data`` (see its README for sources and licences):
  ``nefertiti.obj`` (public domain) and ``demosthenes.obj`` (CC BY 4.0);
* 28 generated shapes (`training_shapes`): spheres, tori, boxes, caps, domes on sheets,
  cylinder and cone pieces, bumpy height fields, a sheet with holes, a freeform patch, at
  seeded random sizes, resolutions and bumps.

The benchmark's meshes (airplane, fish, the MakeHuman body, the ICT face) are kept OUT of
the training set, so the benchmark applies the network to shapes it has not seen.

Every mesh is scaled so its longest side is 150 mm.  Its sub-graphs' rows (90 numbers: Q', U',
K' of 30 triangles, `core.subgraphs`) are taken at the mesh's best build direction and at two
seeded random directions (more variety in the support feature U'); 3,000 rows are drawn, as
evenly over the meshes as their sub-graphs allow, and a tenth more are held back to report the
reconstruction error of each layer on rows it was not trained on.  The settings are the seed's
(90 -> 120 -> 50 -> 20, lambda 0.004, rho 0.05, beta 5); everything is seeded, so a rerun with
the same versions gives the same weights.
"""
from __future__ import annotations

import argparse
import datetime
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from meshgen import (  # noqa: E402  (tests/meshgen.py: numpy-only generated shapes)
    box,
    cone_piece,
    cylinder_piece,
    freeform_patch,
    grid_with_holes,
    height_field,
    icosphere,
    sheet_with_dome,
    spherical_cap,
    torus,
)

from bolus_addon.core.printing.autoencoder import reconstruction_error, train_stacked  # noqa: E402
from bolus_addon.core.mesh.objfile import load_obj  # noqa: E402
from bolus_addon.core.printing.orientation import orient  # noqa: E402
from bolus_addon.core.printing.subgraphs import build_subgraphs, print_features, subgraph_rows  # noqa: E402
from bolus_addon.core.mesh.topology import MeshTopology  # noqa: E402

SCAN_DIR = ROOT / "tests" / "data"
SCANS = ("nefertiti.obj", "demosthenes.obj")
LONGEST_MM = 150.0
ROWS = 3000
HELD_BACK = 0.1
SIZES = (120, 50, 20)
LAMBDA, RHO, BETA = 0.004, 0.05, 5.0
MAX_ITER = (2000, 2000, 2000)  # L-BFGS-B stops earlier when converged (about 700, 200, 150)
RANDOM_DIRECTIONS = 2


def _bumps(rng, k=4, amp=12.0, width=18.0):
    cs = rng.uniform(-40, 40, (k, 2))
    hs = rng.uniform(-amp, amp, k)
    ws = rng.uniform(0.5 * width, 1.5 * width, k)

    def fn(x, y):
        z = np.zeros_like(x)
        for (cx, cy), h, w in zip(cs, hs, ws):
            z += h * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * w * w))
        return z
    return fn


def training_shapes(rng) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """28 generated (name, V (n,3), F (m,3)) shapes at seeded random sizes and resolutions."""
    out = []
    for i in range(3):
        out.append((f"icosphere{i}", *icosphere(3 + i % 2, rng.uniform(30, 80))))
    for i in range(3):
        R = rng.uniform(40, 70)
        out.append((f"torus{i}", *torus(R, rng.uniform(0.2, 0.45) * R, int(rng.integers(32, 64)),
                                      int(rng.integers(12, 24)))))
    for i in range(3):
        out.append((f"box{i}", *box(tuple(rng.uniform(20, 80, 3)), int(rng.integers(8, 16)))))
    for i in range(3):
        out.append((f"cap{i}", *spherical_cap(rng.uniform(60, 140), rng.uniform(40, 80), 5)))
    for i in range(3):
        V, F, _ = sheet_with_dome(rng.uniform(20, 40), rng.uniform(70, 100), 16, 12, 64)
        out.append((f"dome{i}", V, F))
    for i in range(3):
        out.append((f"cylinder{i}", *cylinder_piece(rng.uniform(30, 70), rng.uniform(2, 6), rng.uniform(60, 150),
                                                    48, 24)))
    for i in range(2):
        out.append((f"cone{i}", *cone_piece(rng.uniform(10, 30), rng.uniform(40, 70), rng.uniform(30, 80),
                                            rng.uniform(2, 6), 48, 24)))
    for i in range(6):
        out.append((f"bumps{i}", *height_field(_bumps(rng, int(rng.integers(2, 7))), 48, 48, 100.0)))
    out.append(("holes", *grid_with_holes(40, 40, 120.0, ((8, 8, 16, 16), (24, 20, 32, 30)))))
    V, F = freeform_patch()[:2]
    out.append(("freeform", V, F))
    return out


def _rotation(rng) -> np.ndarray:
    Q, R = np.linalg.qr(rng.normal(size=(3, 3)))
    Q *= np.sign(np.diag(R))
    return Q if np.linalg.det(Q) > 0 else -Q


def mesh_rows(name, V, F, rng) -> tuple[np.ndarray, dict]:
    """All sub-graph rows of one mesh, at its best build direction and at random ones."""
    V = np.asarray(V, dtype=np.float64)
    V = (V - V.mean(axis=0)) @ _rotation(rng).T
    V *= LONGEST_MM / np.ptp(V, axis=0).max()
    topo = MeshTopology(V, F)
    sg = build_subgraphs(topo)
    dirs = [orient(V, F, topo=topo, rng=0).direction]
    for _ in range(RANDOM_DIRECTIONS):
        d = rng.normal(size=3)
        dirs.append(d / np.linalg.norm(d))
    X = np.concatenate([subgraph_rows(print_features(V, F, d, topo), sg) for d in dirs])
    return X, {"mesh": name, "triangles": int(topo.m), "subgraphs": sg.count, "usage_rate": round(sg.usage_rate, 4)}


def training_set(rng, rows: int) -> tuple[np.ndarray, np.ndarray, list[dict]]:
    """(train (rows, 90), held back (rows/10, 90), per-mesh description)."""
    meshes = []
    for name in SCANS:
        p = SCAN_DIR / name
        if not p.exists():
            raise SystemExit(f"{p} is missing: the training set needs the repository's tests/data")
        V, F, _ = load_obj(p)
        meshes.append((name, V, F))
    meshes += training_shapes(rng)
    per_mesh, info = [], []
    for name, V, F in meshes:
        X, d = mesh_rows(name, V, F, rng)
        per_mesh.append(X)
        info.append(d)
        print(f"  {name:14s} {d['triangles']:7,d} triangles {d['subgraphs']:5,d} sub-graphs "
              f"usage {100 * d['usage_rate']:.1f} %", flush=True)
    want = int(round(rows * (1 + HELD_BACK)))
    # as even as the meshes allow: each mesh gives up to an equal share, the rest fill up
    share = np.zeros(len(per_mesh), dtype=np.int64)
    avail = np.array([len(X) for X in per_mesh])
    while share.sum() < min(want, avail.sum()):
        open_ = share < avail
        share[open_] += 1
    take = [rng.choice(len(X), size=int(s), replace=False) for X, s in zip(per_mesh, share)]
    for d, s in zip(info, share):
        d["rows"] = int(s)
    data = np.concatenate([X[t] for X, t in zip(per_mesh, take)])
    data = data[rng.permutation(len(data))]
    n_held = len(data) - rows
    return data[n_held:], data[:n_held], info


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=str(ROOT / "assets" / "print_sae.npz"))
    ap.add_argument("--rows", type=int, default=ROWS)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-iter", type=int, nargs=3, default=list(MAX_ITER))
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    t0 = time.perf_counter()
    print("building the training set", flush=True)
    X, H, info = training_set(rng, args.rows)
    print(f"{len(X):,} training rows, {len(H):,} held back ({time.perf_counter() - t0:.1f} s)", flush=True)
    t1 = time.perf_counter()
    last = [-1.0]

    def progress(f, t):  # a line per 5 %
        if f - last[0] >= 0.05 or f >= 1.0:
            last[0] = f
            print(f"  {100 * f:5.1f} % {t}", flush=True)
    sae, infos = train_stacked(X, SIZES, lam=LAMBDA, rho=RHO, beta=BETA, max_iter=tuple(args.max_iter),
                               rng=args.seed, progress=progress)
    seconds = time.perf_counter() - t1
    # held-back reconstruction error of each layer, on the codes of the layer below
    held = [float(reconstruction_error(layer, inp)) for layer, inp in zip(sae.layers, sae.layer_inputs(H))]
    import scipy  # noqa: PLC0415

    sae.meta.update({
        "trained": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "script": "scripts/train_print_sae.py", "seed": args.seed, "rows": len(X), "held_back": len(H),
        "sizes": [X.shape[1], *SIZES], "lambda": LAMBDA, "rho": RHO, "beta": BETA, "max_iter": list(args.max_iter),
        "meshes": info, "layers": infos, "held_back_error": held, "train_seconds": round(seconds, 1),
        "versions": {"python": platform.python_version(), "numpy": np.__version__, "scipy": scipy.__version__},
    })
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    sae.save(out)
    for i, (inf, e) in enumerate(zip(infos, held)):
        print(f"layer {i + 1}: {inf.get('iterations')} iterations, cost {inf.get('cost_start'):.4g} -> "
              f"{inf.get('cost_end'):.4g}, held-back reconstruction error {e:.4g}, code spread {inf['code_std']:.3g}")
    print(f"trained in {seconds:.1f} s; wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
