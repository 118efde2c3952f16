"""Benchmark of the print orientation search and the print segmentation (printed, not asserted).

Run from the repository root (no Blender needed: core only):

    .venv/bin/python bench/print_bench.py             # airplane, fish and the ICT face
    .venv/bin/python bench/print_bench.py --quick     # only the ICT face
    .venv/bin/python bench/print_bench.py --parts 4 --json out/print_bench.json

For every mesh, the whole model and each part of an ABcut print segmentation
(``print_segment(parts, method="abcut", rng=0)``) are oriented by ``orient`` (ours) and
by an exhaustive search of the same objective WQ + WU over 10,000 Fibonacci
directions (``print_objective`` on all of them, the best kept), in the same run:

* objective ratio ours / exhaustive (target <= 1.01);
* wall-time ratio ours / exhaustive, each the best of ``--repeat`` runs (target <= 0.1);
* the sum of the parts' support volumes (each part at its own chosen direction)
  against the whole model's support volume at its chosen direction (target <= 45 %);
* the largest / smallest part area for ABcut and for RatioCut (same weights, seed,
  parts and crumb merging).

Units (see ../shared/meshes/README.md): the ICT face is in cm (x 10 -> mm); airplane
and fish are in normalised units and are scaled so their longest side is 150 mm (a
desktop-printer sized model; WQ grows with size^2, WU with size^3, so the balance of
the two terms depends on this choice).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for p in (ROOT, ROOT / "bench"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

from bolus_addon.core.objfile import load_obj  # noqa: E402
from bolus_addon.core.print_orientation import fibonacci_sphere, orient, print_objective  # noqa: E402
from bolus_addon.core.print_segmentation import area_balance, print_segment  # noqa: E402
from bolus_addon.core.spectral import submesh  # noqa: E402
from bolus_addon.core.topology import MeshTopology  # noqa: E402

SHARED_MESHES = Path(os.environ.get("BOLUS_SHARED_MESHES", ROOT.parent / "shared" / "meshes"))
EXHAUSTIVE = 10_000
TARGET_OBJ, TARGET_TIME, TARGET_SUPPORT = 1.01, 0.1, 0.45
SEED = 0

#: (name, path, how to get mm: ("factor", f) or ("longest", mm), note)
MESHES = [
    ("ict_face_narrow", ROOT / "assets" / "ict_face_narrow.obj", ("factor", 10.0), "cm -> mm (x 10)"),
    ("fish", SHARED_MESHES / "fish.obj", ("longest", 150.0), "normalised -> longest side 150 mm"),
    ("airplane", SHARED_MESHES / "airplane.obj", ("longest", 150.0), "normalised -> longest side 150 mm"),
]
QUICK = {"ict_face_narrow"}


def warm_up() -> None:
    """Import and run everything once on a small mesh, so no timed call pays for first use."""
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    z = np.linspace(-1, 1, 20)
    V = np.concatenate([np.stack([np.cos(t) * 20, np.sin(t) * 20, np.full(40, zz * 20)], 1) for zz in z])
    F = [[i * 40 + j, i * 40 + (j + 1) % 40, (i + 1) * 40 + (j + 1) % 40] for i in range(19) for j in range(40)]
    F += [[i * 40 + j, (i + 1) * 40 + (j + 1) % 40, (i + 1) * 40 + j] for i in range(19) for j in range(40)]
    F = np.asarray(F)
    orient(V, F)
    print_objective(V, F, fibonacci_sphere(100))
    print_segment(V, F, 3, method="abcut")


def best_time(fn, repeat: int):
    """(best wall time, best CPU time of this process, result) over ``repeat`` runs."""
    times, cpu, out = [], [], None
    for _ in range(repeat):
        c0, t0 = time.process_time(), time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return min(times), min(cpu), out


def compare(V, F, repeat: int, B) -> dict:
    """Ours against the exhaustive search on one mesh piece."""
    t_ours, c_ours, r = best_time(lambda: orient(V, F, rng=SEED), repeat)
    t_exh, c_exh, o = best_time(lambda: print_objective(V, F, B), repeat)
    i = int(np.argmin(o.objective))
    best = float(o.objective[i])
    ratio = r.objective / best if best > 0 else (1.0 if r.objective == 0 else float("inf"))
    return {
        "faces": len(F),
        "area_mm2": float(MeshTopology(V, F).areas.sum()),
        "ours": r.as_dict(),
        "exhaustive": {"direction": B[i].tolist(), "WQ": float(o.WQ[i]), "WU": float(o.WU[i]),
                       "support_volume": float(o.support_volume[i]), "objective": float(o.objective[i])},
        "objective_ratio": ratio,
        "ours_s": t_ours,
        "exhaustive_s": t_exh,
        "time_ratio": t_ours / t_exh,
        "ours_cpu_s": c_ours,
        "exhaustive_cpu_s": c_exh,
        "cpu_ratio": c_ours / c_exh if c_exh > 0 else float("nan"),
    }


def bench_mesh(name, path, scale, note, parts: int, repeat: int, B) -> dict:
    V, F, _ = load_obj(path)
    if scale[0] == "factor":
        V = V * scale[1]
    else:
        V = V * (scale[1] / float((V.max(0) - V.min(0)).max()))
    topo = MeshTopology(V, F)
    bbox = (V.max(0) - V.min(0)).tolist()
    print(f"\n== {name}: {len(V)} vertices, {len(F)} triangles, {note}; bbox "
          f"{bbox[0]:.0f} x {bbox[1]:.0f} x {bbox[2]:.0f} mm; {topo.boundary_edges.sum()} boundary edges")
    row = {"mesh": name, "file": str(path), "units": note, "vertices": len(V), "triangles": len(F), "bbox_mm": bbox}
    t0 = time.perf_counter()
    lab_ab = print_segment(V, F, parts, method="abcut", rng=SEED, topo=topo)
    t_ab = time.perf_counter() - t0
    t0 = time.perf_counter()
    lab_rc = print_segment(V, F, parts, method="ratiocut", rng=SEED, topo=topo)
    t_rc = time.perf_counter() - t0
    row["segment"] = {
        "abcut_s": t_ab, "ratiocut_s": t_rc,
        "abcut_areas_mm2": np.bincount(lab_ab, weights=topo.areas).tolist(),
        "ratiocut_areas_mm2": np.bincount(lab_rc, weights=topo.areas).tolist(),
        "abcut_balance": area_balance(lab_ab, topo.areas),
        "ratiocut_balance": area_balance(lab_rc, topo.areas),
    }
    pieces = [("whole", V, F)]
    for q in range(int(lab_ab.max()) + 1):
        Fl, ids = submesh(F, lab_ab == q)
        pieces.append((f"part {q}", V[ids], Fl))
    row["pieces"] = []
    for label, Vp, Fp in pieces:
        c = compare(Vp, Fp, repeat, B)
        c["piece"] = label
        row["pieces"].append(c)
        print(f"   {label:<7} {c['faces']:>6} tri  objective ours {c['ours']['objective']:>12.1f}  exhaustive "
              f"{c['exhaustive']['objective']:>12.1f}  ratio {c['objective_ratio']:.4f}   time {c['ours_s']:.3f} s / "
              f"{c['exhaustive_s']:.3f} s = {c['time_ratio']:.3f}   ({c['ours']['evaluations']} exact evaluations)")
    whole_sv = row["pieces"][0]["ours"]["support_volume"]
    parts_sv = sum(c["ours"]["support_volume"] for c in row["pieces"][1:])
    row["support_whole_mm3"], row["support_parts_mm3"] = whole_sv, parts_sv
    row["support_ratio"] = parts_sv / whole_sv if whole_sv > 1e-9 else None
    s = row["segment"]
    print(f"   ABcut areas {[round(a) for a in s['abcut_areas_mm2']]} mm2 (max/min {s['abcut_balance']:.2f}, "
          f"{s['abcut_s']:.2f} s); RatioCut {[round(a) for a in s['ratiocut_areas_mm2']]} mm2 "
          f"(max/min {s['ratiocut_balance']:.2f}, {s['ratiocut_s']:.2f} s)")
    print(f"   support volume: whole {whole_sv:.0f} mm3, sum of parts {parts_sv:.0f} mm3"
          + (f" = {100 * row['support_ratio']:.1f} %" if row["support_ratio"] is not None else " (whole needs none)"))
    return row


def print_table(rows, parts: int) -> None:
    print(f"\nSummary (ours = orient(); exhaustive = best of {EXHAUSTIVE} Fibonacci directions of the same WQ + WU;"
          f" ABcut parts={parts}, seed {SEED}; targets: objective <= {TARGET_OBJ}, time <= {TARGET_TIME},"
          f" support parts/whole <= {100 * TARGET_SUPPORT:.0f} %)")
    print(" time = best wall-clock of --repeat runs; cpu = the same with this process's CPU time"
          " (steadier on a busy machine)")
    head = (f"{'mesh':<16} {'piece':<7} {'tri':>6} {'obj ours/exh':>12} {'time ours/exh':>13} {'cpu ours/exh':>12} "
            f"{'ours s':>7} {'exh s':>7} {'SV mm3':>10}")
    print(head)
    print("-" * len(head))
    for r in rows:
        if "error" in r:
            print(f"{r['mesh']:<16} ERROR: {r['error']}")
            continue
        for c in r["pieces"]:
            print(f"{r['mesh']:<16} {c['piece']:<7} {c['faces']:>6} {c['objective_ratio']:>12.4f} "
                  f"{c['time_ratio']:>13.3f} {c['cpu_ratio']:>12.3f} {c['ours_s']:>7.3f} {c['exhaustive_s']:>7.3f} "
                  f"{c['ours']['support_volume']:>10.0f}")
    print()
    head2 = f"{'mesh':<16} {'support parts/whole':>19} {'ABcut max/min area':>19} {'RatioCut max/min area':>22}"
    print(head2)
    print("-" * len(head2))
    for r in rows:
        if "error" in r:
            continue
        sr = "n/a (whole: 0)" if r["support_ratio"] is None else f"{100 * r['support_ratio']:.1f} %"
        seg = r["segment"]
        print(f"{r['mesh']:<16} {sr:>19} {seg['abcut_balance']:>19.2f} {seg['ratiocut_balance']:>22.2f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="only the ICT face")
    ap.add_argument("--parts", type=int, default=3, help="parts of the ABcut segmentation (default 3)")
    ap.add_argument("--repeat", type=int, default=3, help="timed runs of each search, the best is kept (default 3)")
    ap.add_argument("--json", metavar="PATH", help="also write the figures as JSON to PATH")
    args = ap.parse_args(argv)
    import scipy
    import sklearn

    print(f"Bolus print benchmark: Python {platform.python_version()}, numpy {np.__version__}, scipy "
          f"{scipy.__version__}, scikit-learn {sklearn.__version__}, {os.cpu_count()} CPUs")
    B = fibonacci_sphere(EXHAUSTIVE)
    warm_up()

    rows = []
    t_start = time.perf_counter()
    for name, path, scale, note in MESHES:
        if args.quick and name not in QUICK:
            continue
        if not Path(path).exists():
            print(f"\n== {name}: not found at {path}, skipped")
            rows.append({"mesh": name, "error": f"{path} not found"})
            continue
        try:
            rows.append(bench_mesh(name, path, scale, note, args.parts, max(1, args.repeat), B))
        except Exception as exc:  # a benchmark reports, it does not stop at the first failure
            print(f"   FAILED: {type(exc).__name__}: {exc}")
            rows.append({"mesh": name, "error": f"{type(exc).__name__}: {exc}".splitlines()[0]})
    total = time.perf_counter() - t_start
    print_table(rows, args.parts)
    print(f"total bench time {total:.1f} s")
    if args.json:
        payload = {"parts": args.parts, "repeat": args.repeat, "exhaustive_directions": EXHAUSTIVE,
                   "targets": {"objective_ratio": TARGET_OBJ, "time_ratio": TARGET_TIME,
                               "support_ratio": TARGET_SUPPORT},
                   "meshes": rows, "total_s": total}
        try:
            from benchutil import write_json

            write_json(args.json, payload)
        except ImportError:  # benchutil records bpy's version; without bpy write the figures alone
            out = Path(args.json)
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text(json.dumps({"python": platform.python_version(), "numpy": np.__version__, **payload},
                                      indent=2, default=float))
            print(f"figures written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
