"""Benchmark of the learned print segmentation (seed 6.4-6.5, Tables 6-4, 6-5; printed, not asserted).

Run from the repository root (no Blender needed: core only):

    .venv/bin/python bench/learned_print_bench.py              # train the SAE, then the four meshes
    .venv/bin/python bench/learned_print_bench.py --quick      # no training (the shipped record), one run each
    .venv/bin/python bench/learned_print_bench.py --only face --no-train --json out/learned_print_bench.json
    .venv/bin/python bench/learned_print_bench.py --markdown docs/benchmarks.md   # append the tables (make bench)

Meshes (none of them is in the auto-encoder's training set, whose 30 meshes are listed in
``assets/print_sae.npz``'s meta; the run checks this and says so):

* ``airplane.obj`` and ``fish.obj`` (``tests/data``, normalised units): scaled so their
  longest side is 150 mm, as ``print_bench.py`` does;
* ``makehuman_body.obj`` (dm), the "toy": a closed doll-like figure standing in for the seed's
  teddy / four-legged toy of the Princeton benchmark (not redistributable); longest side 150 mm;
* ``ict_face_narrow.obj`` (``assets/``, cm), a face, an open surface: x 10 to mm and kept at
  its true size (about 150 x 199 x 107 mm).

The OBJ polygons go in as ``face_groups`` (the add-on passes its polygons the same way), so a
quad of the body or the face stays in one sub-graph and one part; airplane and fish are
triangle meshes.  Per mesh, every method runs on the same arrays with ``rng=0``:

* LEARNED: ``learned_segmentation(similarity_kind="learned")`` (sub-graphs of 30 triangles,
  the shipped stacked auto-encoder's features and the centroids, eq. 3-14, affinity propagation);
* GEOMETRIC: the same sub-graphs clustered by the centroid distance only (the seed's comparison);
* ABCUT: ``print_segmentation(method="abcut")`` asked for LEARNED's part count (it may return
  fewer or more: crumbs are merged, clusters that fall apart become parts; both counts shown);
* ABCUT (G's count): ABcut asked for GEOMETRIC's count when that differs (not with ``--quick``).

Each segmentation is timed alone (best of ``--repeat`` runs, default 1; LEARNED's time is the whole
application: the build direction of the features, sub-graphs, encoding, affinity propagation,
parts).  Then every part is oriented on its own with ``orient_print_parts`` (SPEC's WQ eq. 6-7, WU
eq. 6-14, mm^3) and the parts' figures are summed; the whole model, oriented once, is the seed's
"Whole model" row, and "vs whole" is the parts' WQ + WU over the whole's.

Training (``--train``, default on; ``--quick`` reads the shipped record instead): the training set
of ``scripts/train_print_sae.py`` (``training_set(np.random.default_rng(0), 3000)``) and
``train_stacked`` with the script's settings, timed per layer; the held-back reconstruction error
of each layer; and a reproducibility check: the new network's ``encode()`` of the held-back rows
against the shipped one's (``np.array_equal``, and the largest difference).
"""
from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchutil import ROOT, data_mesh, Table, error_row, finish, parser, run_line, versions  # noqa: E402

from bolus_addon.core.printing.autoencoder import reconstruction_error, train_stacked  # noqa: E402
from bolus_addon.core.printing.learned import default_sae_path, learned_segmentation, load_default_sae  # noqa: E402
from bolus_addon.core.mesh.objfile import load_obj  # noqa: E402
from bolus_addon.core.printing.orientation import orient  # noqa: E402
from bolus_addon.core.printing.parts import orient_print_parts  # noqa: E402
from bolus_addon.core.printing.segmentation import print_segmentation  # noqa: E402
from bolus_addon.core.mesh.topology import MeshTopology  # noqa: E402

SEED = 0
TRAIN_ROWS = 3000  # the seed's 3,000 sub-graphs (scripts/train_print_sae.py ROWS)

#: (name, path, how to get mm: ("factor", f) or ("longest", mm), note)
MESHES = [
    ("airplane", data_mesh("airplane.obj"), ("longest", 150.0), "normalised -> longest side 150 mm"),
    ("fish", data_mesh("fish.obj"), ("longest", 150.0), "normalised -> longest side 150 mm"),
    ("toy (makehuman_body)", data_mesh("makehuman_body.obj"), ("longest", 150.0),
     "dm -> longest side 150 mm; a closed doll-like figure for the seed's teddy / four-legged toy"),
    ("face (ict_face_narrow)", ROOT / "assets" / "ict_face_narrow.obj", ("factor", 10.0),
     "cm -> mm (x 10), true size; open surface"),
]
PER_PART = ("airplane", "fish")  # the seed's Tables 6-4, 6-5

LEARNED, GEOMETRIC, ABCUT, ABCUT_G = "LEARNED", "GEOMETRIC", "ABCUT", "ABCUT (G's count)"


# ------------------------------------------------------------------ helpers


def load(path, scale):
    """V (n,3) in mm, F (m,3), the OBJ polygon of each triangle (m,)."""
    V, F, groups = load_obj(path)
    if scale[0] == "factor":
        return V * scale[1], F, groups
    return V * (scale[1] / float(np.ptp(V, axis=0).max())), F, groups


def best_time(fn, repeat: int):
    """(best wall time, result) over ``repeat`` runs."""
    times, out = [], None
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def orientation_figures(o) -> dict:
    return {"WQ": float(o.WQ), "WU": float(o.WU), "objective": float(o.objective),
            "support_volume_mm3": float(o.support_volume)}


def figures_of_parts(V, F, labels, topo, owner=None) -> tuple[float, list[dict]]:
    """Orient every part of labels (m,) on its own -> (seconds, one dict per part: triangles, sub-graphs
    (when ``owner`` (m,), the sub-graph of each triangle, is given), WQ, WU, WQ + WU, support)."""
    t0 = time.perf_counter()
    plan = orient_print_parts(V, F, labels, whole=False, topo=topo, rng=SEED)
    dt = time.perf_counter() - t0
    rows = []
    for r in plan.parts:
        inside = labels == r.part
        sub = None if owner is None else int(np.unique(owner[inside & (owner >= 0)]).size)
        rows.append({"part": r.part, "triangles": r.faces, "area_mm2": r.area_mm2, "subgraphs": sub,
                     **orientation_figures(r.orientation)})
    return dt, rows


def totals(parts: list[dict]) -> dict:
    return {k: float(sum(p[k] for p in parts)) for k in ("WQ", "WU", "objective", "support_volume_mm3")}


# ------------------------------------------------------------------ one mesh


def cluster_coherence(topo, clusters) -> float:
    """Share of the area that lies in its AP cluster's largest edge-connected piece (1 = every cluster
    is one piece; low = clusters scattered over the surface, the parts then come from merging crumbs)."""
    A = topo.areas
    _, comp = topo.face_components(np.asarray(clusters))  # pieces of one cluster each
    piece_area = np.bincount(comp, weights=A)
    piece_cluster = np.zeros(len(piece_area), dtype=np.int64)
    piece_cluster[comp] = clusters
    best = np.zeros(int(np.max(clusters)) + 1)
    np.maximum.at(best, piece_cluster, piece_area)
    return float(best.sum() / A.sum())


def run_method(method, segment, V, F, topo, repeat: int, whole_obj: float) -> dict:
    """Time ``segment()`` (-> a PrintSegmentation), then orient its parts."""
    seg_s, seg = best_time(segment, repeat)
    sg = getattr(seg, "subgraphs", None)
    orient_s, parts = figures_of_parts(V, F, seg.labels, topo, None if sg is None else sg.owner)
    tot = totals(parts)
    row = {"method": method, "parts": seg.part_count, "requested": seg.requested or None,
           "segment_s": seg_s, "orient_s": orient_s, "totals": tot,
           "vs_whole": tot["objective"] / whole_obj if whole_obj > 0 else None, "part_rows": parts}
    if sg is not None:
        row.update(clusters=seg.ap_clusters, ap_iterations=seg.ap_iterations, subgraphs=sg.count,
                   coherence=cluster_coherence(topo, seg.clusters),
                   usage_rate=sg.usage_rate, steps_s=dict(seg.seconds), similarity=seg.similarity_kind)
    asked = "" if row["requested"] is None else f" ({row['requested']} asked)"
    print(f"   {method:<18} {row.get('clusters', '-'):>3} clusters {row['parts']:>3} parts{asked}"
          f"  WQ+WU {tot['objective']:>10.1f} mm^3 ({100 * (row['vs_whole'] or 0):.1f} % of the whole)  "
          f"segment {seg_s:.2f} s  orient {orient_s:.2f} s", flush=True)
    return row


def bench_mesh(name, path, scale, note, repeat: int, abcut_geometric: bool) -> dict:
    V, F, groups = load(path, scale)
    topo = MeshTopology(V, F)
    bbox = np.ptp(V, axis=0).tolist()
    polys = int(np.unique(groups).size)
    print(f"\n== {name}: {len(V)} vertices, {len(F)} triangles ({polys} polygons), {note}; bbox "
          f"{bbox[0]:.0f} x {bbox[1]:.0f} x {bbox[2]:.0f} mm; {int(topo.boundary_edges.sum())} boundary edges",
          flush=True)
    t0 = time.perf_counter()
    o = orient(V, F, topo=topo, rng=SEED)
    whole = {"triangles": len(F), "orient_s": time.perf_counter() - t0, **orientation_figures(o)}
    print(f"   whole model: WQ {o.WQ:.1f} WU {o.WU:.1f} WQ+WU {o.objective:.1f} mm^3", flush=True)
    row = {"mesh": name, "file": Path(path).name, "units": note, "vertices": len(V), "triangles": len(F),
           "polygons": polys, "bbox_mm": bbox, "whole": whole, "methods": []}

    def learned(kind):
        return lambda: learned_segmentation(V, F, rng=SEED, topo=topo, similarity_kind=kind, face_groups=groups)

    def abcut(k):
        return lambda: print_segmentation(V, F, k, method="abcut", rng=SEED, topo=topo, face_groups=groups)

    plan = [(LEARNED, learned("learned")), (GEOMETRIC, learned("geometric"))]
    for method, fn in plan:
        try:
            row["methods"].append(run_method(method, fn, V, F, topo, repeat, o.objective))
        except Exception as exc:  # a benchmark reports, it does not stop at the first failure
            row["methods"].append(error_row("method", method, exc))
    counts = {m["method"]: m["parts"] for m in row["methods"] if "error" not in m}
    asks = [(ABCUT, counts.get(LEARNED))]
    if abcut_geometric and counts.get(GEOMETRIC) not in (None, counts.get(LEARNED)):
        asks.append((ABCUT_G, counts[GEOMETRIC]))
    for method, k in asks:
        if k is None:
            row["methods"].append({"method": method, "error": "no part count (LEARNED failed)"})
            continue
        try:
            row["methods"].append(run_method(method, abcut(k), V, F, topo, repeat, o.objective))
        except Exception as exc:
            row["methods"].append(error_row("method", method, exc))
    return row


# ------------------------------------------------------------------ training


def _train_script():
    spec = importlib.util.spec_from_file_location("train_print_sae", ROOT / "scripts" / "train_print_sae.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def shipped_record(sae) -> dict:
    """What the shipped weights' meta says about their training."""
    m = sae.meta
    layers = m.get("layers") or []
    return {"file": str(default_sae_path().relative_to(ROOT)), "trained": m.get("trained"),
            "rows": m.get("rows"), "held_back": m.get("held_back"), "sizes": m.get("sizes"),
            "train_seconds": m.get("train_seconds"), "versions": m.get("versions"),
            "layers": [{"iterations": inf.get("iterations"), "seconds": inf.get("seconds"),
                        "cost_end": inf.get("cost_end"), "converged": inf.get("converged")} for inf in layers],
            "held_back_error": m.get("held_back_error"),
            "meshes": [d.get("mesh") for d in m.get("meshes") or []]}


def train_record(sae) -> dict:
    """Build the training set and train the stack as scripts/train_print_sae.py does, timed; compare with sae."""
    tsp = _train_script()
    print("\n== training the stacked auto-encoder (scripts/train_print_sae.py's set and settings)", flush=True)
    t0 = time.perf_counter()
    X, H, info = tsp.training_set(np.random.default_rng(SEED), TRAIN_ROWS)
    set_s = time.perf_counter() - t0
    t1 = time.perf_counter()
    new, infos = train_stacked(X, tsp.SIZES, lam=tsp.LAMBDA, rho=tsp.RHO, beta=tsp.BETA, max_iter=tsp.MAX_ITER,
                               rng=SEED)
    train_s = time.perf_counter() - t1
    held = [float(reconstruction_error(layer, inp)) for layer, inp in zip(new.layers, new.layer_inputs(H))]
    E_new, E_old = new.encode(H), sae.encode(H)
    same_shape = E_new.shape == E_old.shape
    equal = bool(same_shape and np.array_equal(E_new, E_old))
    diff = float(np.abs(E_new - E_old).max()) if same_shape else None
    weights_equal = len(new.layers) == len(sae.layers) and all(
        a.W1.shape == b.W1.shape and np.array_equal(a.W1, b.W1) and np.array_equal(a.b1, b.b1)
        for a, b in zip(new.layers, sae.layers))
    out = {"ran": True, "rows": len(X), "held_back": len(H), "set_s": set_s, "train_s": train_s,
           "meshes": [d["mesh"] for d in info], "sizes": list(new.sizes),
           "layers": [{"iterations": inf.get("iterations"), "seconds": inf.get("seconds"),
                       "cost_end": inf.get("cost_end"), "converged": inf.get("converged")} for inf in infos],
           "held_back_error": held, "encode_equal": equal, "encode_max_abs_diff": diff,
           "encoder_weights_equal": bool(weights_equal)}
    print(f"   training set {len(X)} rows (+{len(H)} held back) in {set_s:.1f} s; trained in {train_s:.1f} s; "
          f"encode() of the held-back rows equal to the shipped network's: {equal} (largest difference "
          f"{diff:.3g})", flush=True)
    return out


# ------------------------------------------------------------------ tables


def _f(x, fmt=".1f"):
    return "–" if x is None else format(x, fmt)


def summary_table(rows) -> Table:
    t = Table([("mesh", "<"), ("method", "<"), ("AP clusters", ">"), ("coherence %", ">"), ("parts (asked)", ">"),
               ("sub-graphs", ">"),
               ("usage %", ">"), ("WQ mm³", ">"), ("WU mm³", ">"), ("WQ+WU mm³", ">"), ("vs whole %", ">"),
               ("segment s", ">"), ("orient s", ">")])
    for r in rows:
        if "error" in r:
            t.add_error(r["mesh"], r["error"])
            continue
        w = r["whole"]
        t.add(r["mesh"], "whole model", "–", "–", "1", "–", "–", _f(w["WQ"]), _f(w["WU"]), _f(w["objective"]), "100.0",
              "–", _f(w["orient_s"], ".2f"))
        for m in r["methods"]:
            if "error" in m:
                t.add_error(r["mesh"], f"{m['method']}: {m['error']}")
                continue
            parts = str(m["parts"]) + ("" if m["requested"] is None else f" ({m['requested']})")
            usage = None if m.get("usage_rate") is None else 100 * m["usage_rate"]
            tot = m["totals"]
            coh = None if m.get("coherence") is None else 100 * m["coherence"]
            t.add(r["mesh"], m["method"], m.get("clusters", "–"), _f(coh, ".0f"), parts, m.get("subgraphs", "–"),
                  _f(usage),
                  _f(tot["WQ"]), _f(tot["WU"]), _f(tot["objective"]),
                  _f(None if m["vs_whole"] is None else 100 * m["vs_whole"]), _f(m["segment_s"], ".2f"),
                  _f(m["orient_s"], ".2f"))
    return t


def part_table(rows, meshes=PER_PART) -> Table:
    t = Table([("mesh", "<"), ("method", "<"), ("part", "<"), ("triangles", ">"), ("sub-graphs", ">"),
               ("WQ mm³", ">"), ("WU mm³", ">"), ("WQ+WU mm³", ">")])
    for r in rows:
        if r["mesh"] not in meshes:
            continue
        if "error" in r:
            t.add_error(r["mesh"], r["error"])
            continue
        w = r["whole"]
        t.add(r["mesh"], "whole model", "whole", w["triangles"], "–", _f(w["WQ"]), _f(w["WU"]), _f(w["objective"]))
        for m in r["methods"]:
            if "error" in m:
                t.add_error(r["mesh"], f"{m['method']}: {m['error']}")
                continue
            for p in m["part_rows"]:
                t.add(r["mesh"], m["method"], f"part {p['part'] + 1}", p["triangles"], _f(p["subgraphs"], "d"),
                      _f(p["WQ"]), _f(p["WU"]), _f(p["objective"]))
            tot = m["totals"]
            t.add(r["mesh"], m["method"], "total", sum(p["triangles"] for p in m["part_rows"]),
                  _f(m.get("subgraphs"), "d"), _f(tot["WQ"]), _f(tot["WU"]), _f(tot["objective"]))
    return t


def training_table(tr: dict) -> Table:
    sh = tr["shipped"]
    run = tr.get("run")
    t = Table([("layer", "<"), ("units", "<"), ("iterations", ">"), ("seconds", ">"), ("held-back error", ">"),
               ("shipped iterations", ">"), ("shipped seconds", ">"), ("shipped held-back error", ">")])
    sizes = sh.get("sizes") or []
    for k, s in enumerate(sh["layers"]):
        r = run["layers"][k] if run and "error" not in run and k < len(run["layers"]) else {}
        e = run["held_back_error"][k] if r else None
        se = (sh.get("held_back_error") or [None] * len(sh["layers"]))[k]
        units = f"{sizes[k]} -> {sizes[k + 1]}" if k + 1 < len(sizes) else "?"
        t.add(f"{k + 1}", units, _f(r.get("iterations"), "d"), _f(r.get("seconds"), ".1f"), _f(e, ".4g"),
              _f(s.get("iterations"), "d"), _f(s.get("seconds"), ".1f"), _f(se, ".4g"))
    return t


def training_lines(tr: dict, bench_files) -> list[str]:
    sh, run = tr["shipped"], tr.get("run")
    seen = sorted(set(bench_files) & set(sh["meshes"]))
    vers = ", ".join(f"{k} {v}" for k, v in (sh["versions"] or {}).items())
    lines = [f"Shipped weights `{sh['file']}`: trained {sh['trained']} on {sh['rows']} rows (+{sh['held_back']} held "
             f"back) in {_f(sh['train_seconds'])} s ({vers})"
             f"; its {len(sh['meshes'])} training meshes: {', '.join(sh['meshes'])}.",
             "None of the benchmark's meshes is among them." if not seen else
             f"NOTE: {', '.join(seen)} IS in the training set."]
    if run is None:
        lines.append("Training not run here (`--quick` or `--no-train`): the shipped record only.")
    elif "error" in run:
        lines.append(f"Training in this run FAILED: {run['error']}")
    else:
        d = run["encode_max_abs_diff"]
        lines.append(f"This run: training set of {run['rows']} rows (+{run['held_back']} held back) built in "
                     f"{run['set_s']:.1f} s, the stack trained in {run['train_s']:.1f} s.  Reproducibility: "
                     f"`encode()` of the held-back rows equal to the shipped network's: "
                     f"**{'yes' if run['encode_equal'] else 'no'}** (largest difference {_f(d, '.3g')}; encoder "
                     f"weights equal: {'yes' if run['encoder_weights_equal'] else 'no'}).")
    return lines


# ------------------------------------------------------------------ main


def warm_up() -> None:
    """Imports, the SAE and caches, so no timed call pays for them."""
    import meshgen  # tests/meshgen.py (benchutil puts tests/ on the path)

    V, F = meshgen.icosphere(3, 50.0)
    learned_segmentation(V, F, rng=SEED)
    print_segmentation(V, F, 3, method="abcut", rng=SEED)
    orient_print_parts(V, F, np.zeros(len(F), dtype=np.int64), whole=False)


def main(argv=None) -> int:
    ap = parser(__doc__, "no training (the shipped record), no ABcut at GEOMETRIC's count; one run each", repeat=1)
    ap.add_argument("--train", action=argparse.BooleanOptionalAction, default=None,
                    help="train the auto-encoder in this run and compare it with the shipped one "
                         "(default: on, off with --quick)")
    ap.add_argument("--only", metavar="NAME", action="append", default=[],
                    help="bench only the meshes whose name contains NAME (repeatable)")
    args = ap.parse_args(argv)
    train = (not args.quick) if args.train is None else args.train
    v = versions()
    print(f"Bolus learned print segmentation benchmark: Python {v['python']}, numpy {v['numpy']}, scipy "
          f"{v['scipy']}, scikit-learn {v.get('sklearn')}, {v['cpus']} CPUs{'  [--quick]' if args.quick else ''}")
    t_start = time.perf_counter()
    sae = load_default_sae()
    tr = {"shipped": shipped_record(sae), "run": None}
    if train:
        try:
            tr["run"] = train_record(sae)
        except Exception as exc:
            tr["run"] = {"ran": False, **error_row("what", "training", exc)}
    warm_up()
    meshes = [m for m in MESHES if not args.only or any(o in m[0] for o in args.only)]
    rows = []
    for name, path, scale, note in meshes:
        if not Path(path).exists():
            print(f"\n== {name}: not found at {path}, skipped")
            rows.append({"mesh": name, "error": f"{path} not found"})
            continue
        try:
            rows.append(bench_mesh(name, path, scale, note, args.repeat, abcut_geometric=not args.quick))
        except Exception as exc:
            rows.append(error_row("mesh", name, exc))
    total = time.perf_counter() - t_start
    t1, t2, t3 = summary_table(rows), part_table(rows), training_table(tr)
    tl = training_lines(tr, [Path(p).name for _, p, _, _ in MESHES])
    how = (f"seed {SEED}; OBJ polygons as face groups; segmentation times best of {max(1, args.repeat)} run(s); "
           f"\"parts (asked)\": ABcut was asked for LEARNED's (or GEOMETRIC's) count; WQ, WU summed over the parts, "
           f"each oriented on its own (`orient_print_parts`); \"vs whole\": the parts' WQ + WU over the whole "
           f"model's; \"coherence\": the share of the area in its AP cluster's largest connected piece (100: every "
           f"cluster one piece; lower: scattered clusters, the parts then come from merging pieces under 5 % of "
           f"the area into a neighbour)")
    print(f"\nSummary ({how})\n{t1.text()}")
    if t2.rows:
        print(f"\nPer part (the seed's Tables 6-4, 6-5)\n{t2.text()}")
    print("\nTraining\n" + "\n".join(tl) + "\n" + t3.text())
    notes = "\n".join(f"* {n}: {u}" for n, _, _, u in meshes)
    md = (f"## Learned print segmentation (`bench/learned_print_bench.py`)\n\n"
          f"{run_line('learned_print_bench.py', argv)}\n\n"
          f"LEARNED (sub-graphs + the shipped stacked auto-encoder + affinity propagation, seed 6.4) against "
          f"GEOMETRIC (the same sub-graphs clustered by centroid distance only, the seed's Tables 6-4, 6-5) and "
          f"ABcut asked for the same number of parts; {how}.  Meshes:\n\n{notes}\n\n{t1.markdown()}\n\n"
          + (f"Per part on airplane and fish (parts by decreasing area):\n\n{t2.markdown()}\n\n" if t2.rows else "")
          + "Training of the stacked auto-encoder (90 -> 120 -> 50 -> 20, Algorithm 6-1):\n\n"
          + "\n\n".join(tl) + f"\n\n{t3.markdown()}")
    finish(args, {"repeat": args.repeat, "seed": SEED, "training": tr, "meshes": rows}, total, md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
