"""Benchmark of `bpy.ops.bolus.segment` (printed, not asserted).

Run from the repository root:

    .venv/bin/python bench/segment_bench.py            # all four meshes
    .venv/bin/python bench/segment_bench.py --quick    # only the two face meshes
    .venv/bin/python bench/segment_bench.py --json out/segment_bench.json
    .venv/bin/python bench/segment_bench.py --markdown docs/benchmarks.md   # append the table (make bench)

For every mesh, in the same process and on the same object:

* wall time of ``bpy.ops.bolus.segment(patches=4, eta=5.0, seed=0)`` (default
  analysis smoothing) and of ``bpy.ops.uv.smart_project()`` (default options, Edit
  Mode, all faces selected), each the best of ``--repeat`` runs (default 3), and
  their ratio (target: segment <= 3x smart_project on the meshes of 50k triangles or more);
* peak memory of one segment call, two ways: the ``tracemalloc`` peak (Python
  objects and numpy buffers allocated during the call) and the growth of the process
  peak RSS (``resource.getrusage().ru_maxrss``) over the RSS before the call, with
  the kernel's high-water mark reset just before the call so earlier meshes do not
  hide it;
* plain spectral clustering (eta=0) against the saliency-aware one (eta=5), same
  seed, patches and smoothing: the largest per-patch sum varpi from the object's
  ``bolus_patch_table`` custom property, the sum over patches and the patch count.

Meshes come from the repository's ``assets/`` and ``tests/data/``;
see its README for sources, licences and units.
"""
from __future__ import annotations

import gc
import json
import os
import platform
import sys
import time
import tracemalloc
from pathlib import Path

import benchutil
from benchutil import data_mesh, Table, captured_output, clean_scene, current_rss_kb, import_mesh, maxrss_kb, \
    reset_peak_rss, timed_uv_operator

PATCHES = 3
ETA = 5.0
SEED = 0
TARGET_RATIO = 3.0
#: the ratio is judged on meshes of at least this many triangles: below, both calls take a few
#: hundredths of a second and the ratio measures fixed costs (Smart UV Project: 0.008 s on 5.8k)
TARGET_MIN_TRIANGLES = 50_000
UV_SENTINEL = -7.25  # written into the UV layer before smart_project; none may survive

#: (file, scale_length, note); order: smallest first
MESHES = [
    ("makehuman_face_patch.obj", 0.1, "dm: scale_length 0.1 (1 unit = 100 mm)"),
    ("ict_face_narrow.obj", 0.01, "cm: scale_length 0.01 (1 unit = 10 mm)"),
    ("demosthenes.obj", 0.1,
     "normalised units, TAKEN AS 1 unit = 100 mm: scale_length 0.1 (assumption, not a real size)"),
    ("nefertiti.obj", 0.001, "mm: scale_length 0.001 (1 unit = 1 mm)"),
]
QUICK = {"makehuman_face_patch.obj", "ict_face_narrow.obj"}

MB = 1024.0 * 1024.0
MEMORY_LABELS = {
    "tracemalloc_peak_mb": "peak of Python objects and numpy buffers allocated during one segment call (tracemalloc)",
    "rss_delta_mb": "process peak RSS (ru_maxrss, high-water mark reset before the call) minus RSS before the call",
}


# ----------------------------------------------------------------------------- helpers


def run_segment(bpy, ob, eta: float, verbose: bool) -> dict:
    """One segment call; returns its patch table (raises if the operator did not finish)."""
    bpy.context.view_layer.objects.active = ob
    with captured_output(not verbose) as out:
        res = bpy.ops.bolus.segment(patches=PATCHES, eta=eta, seed=SEED)
    if res != {"FINISHED"}:
        raise RuntimeError(f"bolus.segment(eta={eta}) returned {res}:\n{out()}")
    return json.loads(ob["bolus_patch_table"])


def timed_segment(bpy, ob, eta: float, repeat: int, verbose: bool) -> tuple[float, list[float], dict]:
    times, tables = [], []
    for _ in range(repeat):
        gc.collect()
        t0 = time.perf_counter()
        tables.append(run_segment(bpy, ob, eta, verbose))
        times.append(time.perf_counter() - t0)
    same = all(t == tables[0] for t in tables)
    return min(times), times, {"table": tables[-1], "repeatable": same}


def previous_segment(bpy, ob, repeat: int, verbose: bool) -> tuple[float, dict]:
    """The previous method in the same run: exact shift-invert eigenvectors at every size below
    150k vertices and k-means (4 restarts) on every row (best of ``repeat``; its patch table)."""
    from bolus_addon.core.analysis import clustering, spectral

    saved = spectral.MULTILEVEL_MIN_VERTICES, clustering.KMEANS_SAMPLE
    spectral.MULTILEVEL_MIN_VERTICES, clustering.KMEANS_SAMPLE = 150_000, 10**12
    try:
        best, _, out = timed_segment(bpy, ob, ETA, repeat, verbose)
    finally:
        spectral.MULTILEVEL_MIN_VERTICES, clustering.KMEANS_SAMPLE = saved
    return best, out["table"]


def varpi_change(new: dict, old: dict) -> float:
    """Largest relative change of a patch's sum varpi between two patch tables (patches sorted
    by it; inf when the counts differ)."""
    a = sorted(p["sum_varpi"] for p in new["patches"])
    b = sorted(p["sum_varpi"] for p in old["patches"])
    if len(a) != len(b):
        return float("inf")
    return max((abs(x - y) / max(abs(y), 1e-9) for x, y in zip(a, b)), default=0.0)


def memory_segment(bpy, ob, eta: float, verbose: bool) -> dict:
    """Peak memory of one segment call: tracemalloc peak and peak-RSS growth."""
    gc.collect()
    reset_ok = reset_peak_rss()
    rss0 = current_rss_kb()
    maxrss0 = maxrss_kb()
    tracemalloc.start()
    tracemalloc.reset_peak()
    try:
        run_segment(bpy, ob, eta, verbose)
        _, tm_peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    maxrss1 = maxrss_kb()
    return {
        "tracemalloc_peak_mb": tm_peak / MB,
        # with the high-water mark reset, ru_maxrss after the call is the peak during it
        "rss_before_mb": rss0 / 1024.0,
        "rss_peak_mb": maxrss1 / 1024.0,
        "rss_delta_mb": (maxrss1 - (rss0 if reset_ok else maxrss0)) / 1024.0,
        "rss_hwm_reset": reset_ok,
    }


def uv_array(me):
    import numpy as np

    uv = me.uv_layers.active
    a = np.empty(len(me.loops) * 2, dtype=np.float64)
    uv.data.foreach_get("uv", a)
    return a.reshape(-1, 2)


def timed_smart_project(bpy, ob, repeat: int) -> tuple[float, list[float], dict]:
    """bpy.ops.uv.smart_project() on every face (Edit Mode, select all), best of ``repeat``.

    Only the operator call is timed (not the mode switches).  Before each run the
    active UV layer is filled with a sentinel; afterwards no loop may still hold it
    (so every face was unwrapped) and all UVs must lie in [0, 1].
    """
    import numpy as np

    me = ob.data
    if me.uv_layers.active is None:
        me.uv_layers.new(name="UVMap")
    times = []
    check = {}
    for _ in range(repeat):
        bpy.ops.object.mode_set(mode="OBJECT")
        me.uv_layers.active.data.foreach_set("uv", np.full(len(me.loops) * 2, UV_SENTINEL, dtype=np.float32))
        dt, selected, _ = timed_uv_operator(bpy, ob, bpy.ops.uv.smart_project, "uv.smart_project")
        times.append(dt)
        uv = uv_array(me)
        left = int(np.count_nonzero(np.all(uv == np.float32(UV_SENTINEL), axis=1)))
        check = {
            "faces": len(me.polygons),
            "faces_selected": int(selected),
            "loops_not_unwrapped": left,
            "uv_in_unit_square": bool(np.all((uv >= -1e-6) & (uv <= 1 + 1e-6))),
        }
    return min(times), times, check


def bbox_mm(ob, scale_length: float):
    import numpy as np

    me = ob.data
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    M = np.array(ob.matrix_world)
    w = co @ M[:3, :3].T + M[:3, 3]
    return ((w.max(0) - w.min(0)) * scale_length * 1000.0).tolist()


def patch_summary(table: dict) -> dict:
    sv = [p["sum_varpi"] for p in table["patches"]]
    return {
        "patches": len(sv),
        "max_sum_varpi": max(sv) if sv else float("nan"),
        "total_sum_varpi": float(sum(sv)),
        "per_patch_sum_varpi": sv,
        "per_patch_area_mm2": [p["area_mm2"] for p in table["patches"]],
    }


# ----------------------------------------------------------------------------- main


def bench_mesh(bpy, fname: str, scale_length: float, note: str, repeat: int, verbose: bool) -> dict:
    path = data_mesh(fname)
    name = Path(fname).stem
    clean_scene(bpy)
    ob = import_mesh(bpy, path, scale_length)
    me = ob.data
    me.calc_loop_triangles()
    row = {
        "mesh": name,
        "file": str(path),
        "units": note,
        "scale_length": scale_length,
        "vertices": len(me.vertices),
        "faces": len(me.polygons),
        "triangles": len(me.loop_triangles),
        "bbox_mm": bbox_mm(ob, scale_length),
    }
    print(f"\n== {name}: {row['vertices']} vertices, {row['faces']} faces, {row['triangles']} triangles")
    print(f"   units: {note}")
    print("   bbox: {:.0f} x {:.0f} x {:.0f} mm".format(*row["bbox_mm"]))

    # 1. memory (first call on this mesh, alone; tracemalloc slows it, so it is not timed)
    mem = memory_segment(bpy, ob, ETA, verbose)
    row.update(mem)
    print(
        f"   memory of one segment call: tracemalloc peak {mem['tracemalloc_peak_mb']:.1f} MB "
        f"(Python objects + numpy buffers allocated during the call); peak RSS growth "
        f"{mem['rss_delta_mb']:.1f} MB (ru_maxrss during the call {mem['rss_peak_mb']:.0f} MB minus RSS before "
        f"{mem['rss_before_mb']:.0f} MB"
        f"{'' if mem['rss_hwm_reset'] else '; high-water mark NOT reset, delta is over the earlier process peak'})"
    )

    # 2. wall time, eta = 5 (the default smoothing), best of `repeat`
    seg_best, seg_all, seg5 = timed_segment(bpy, ob, ETA, repeat, verbose)
    table5 = seg5["table"]
    smoothing = table5.get("smoothing_mm")
    row.update(segment_s=seg_best, segment_runs_s=seg_all, segment_repeatable=seg5["repeatable"],
               smoothing_mm=smoothing)
    print(
        f"   bolus.segment(patches={PATCHES}, eta={ETA:g}, seed={SEED}, smoothing {smoothing:g} mm): "
        f"best of {repeat} {seg_best:.3f} s  (runs: {', '.join(f'{t:.3f}' for t in seg_all)})"
        f"{'' if seg5['repeatable'] else '  WARNING: the patch table differed between runs'}"
    )

    # 2b. the previous method on the same object
    prev_best, prev_table = previous_segment(bpy, ob, repeat, verbose)
    change = varpi_change(table5, prev_table)
    row.update(previous_s=prev_best, previous_varpi_change=change)
    print(f"   previous method (exact eigenvectors, k-means on every row): best of {repeat} {prev_best:.3f} s; "
          f"largest change of a patch's sum varpi {100 * change:.1f} %")

    # 3. smart_project on the same object
    sp_best, sp_all, sp_check = timed_smart_project(bpy, ob, repeat)
    row.update(smart_project_s=sp_best, smart_project_runs_s=sp_all, smart_project_check=sp_check)
    all_faces = sp_check["faces_selected"] == sp_check["faces"] and sp_check["loops_not_unwrapped"] == 0
    print(
        f"   uv.smart_project() (defaults, Edit Mode, all faces selected): best of {repeat} {sp_best:.3f} s  "
        f"(runs: {', '.join(f'{t:.3f}' for t in sp_all)}); "
        f"faces selected {sp_check['faces_selected']}/{sp_check['faces']}, "
        f"loops left un-unwrapped {sp_check['loops_not_unwrapped']}, UVs in [0,1]: {sp_check['uv_in_unit_square']}"
        f"{'' if all_faces else '  WARNING: NOT RUN ON ALL FACES'}"
    )
    ratio = seg_best / sp_best if sp_best > 0 else float("inf")
    row["ratio"] = ratio
    print(f"   ratio segment / smart_project = {ratio:.1f}x (target <= {TARGET_RATIO:g}x: "
          f"{'met' if ratio <= TARGET_RATIO else 'NOT met'})")

    # 4. plain spectral clustering (eta = 0) against eta = 5, same seed/patches/smoothing
    table0 = run_segment(bpy, ob, 0.0, verbose)
    s0, s5 = patch_summary(table0), patch_summary(table5)
    row["eta0"], row["eta5"] = s0, s5
    ratio_max = s5["max_sum_varpi"] / s0["max_sum_varpi"] if s0["max_sum_varpi"] > 0 else float("nan")
    row["max_sum_varpi_ratio_eta5_over_eta0"] = ratio_max
    for label, s in (("eta=0", s0), ("eta=5", s5)):
        print(
            f"   {label}: {s['patches']} patches, max per-patch sum varpi {s['max_sum_varpi']:.2f} rad, "
            f"sum over patches {s['total_sum_varpi']:.2f} rad; per patch "
            f"[{', '.join(f'{v:.2f}' for v in s['per_patch_sum_varpi'])}], areas "
            f"[{', '.join(f'{a / 100.0:.0f}' for a in s['per_patch_area_mm2'])}] cm2"
        )
    print(f"   max per-patch sum varpi, eta=5 / eta=0 = {ratio_max:.3f} (< 1: eta=5 lowered the worst patch)")
    clean_scene(bpy)
    return row


def summary_table(rows: list[dict]) -> Table:
    t = Table([("mesh", "<"), ("triangles", ">"), ("segment s", ">"), ("previous s", ">"), ("Σϖ change", ">"),
               ("smart_project s", ">"), ("ratio", ">"),
               ("tracemalloc MB", ">"), ("RSS delta MB", ">"), ("max Σϖ η=0", ">"), ("max Σϖ η=5", ">"),
               ("patches η=0/5", ">")])
    for r in rows:
        if "error" in r:
            t.add_error(r["mesh"], r["error"])
            continue
        t.add(r["mesh"], f"{r['triangles']:,}", f"{r['segment_s']:.3f}", f"{r['previous_s']:.3f}",
              f"{100 * r['previous_varpi_change']:.1f} %", f"{r['smart_project_s']:.3f}",
              f"{r['ratio']:.1f}×", f"{r['tracemalloc_peak_mb']:.1f}", f"{r['rss_delta_mb']:.1f}",
              f"{r['eta0']['max_sum_varpi']:.2f}", f"{r['eta5']['max_sum_varpi']:.2f}",
              f"{r['eta0']['patches']}/{r['eta5']['patches']}")
    return t


def legend(repeat: int) -> str:
    return (f"Best of {repeat} wall-clock runs; segment: patches={PATCHES}, eta={ETA:g}, seed={SEED}, default "
            f"smoothing; ratio = segment / smart_project (target <= {TARGET_RATIO:g}× from {TARGET_MIN_TRIANGLES:,} triangles); tracemalloc = peak of "
            "Python/numpy allocations during one segment call; RSS delta = process peak RSS during that call minus "
            "RSS before it; max Σϖ = largest per-patch sum of the angle deficit ϖ in rad (bolus_patch_table), "
            "plain spectral clustering (η = 0) against the saliency-aware one (η = 5); patches = count for each")


def markdown(rows: list[dict], repeat: int, argv) -> str:
    judged = [r for r in rows if "ratio" in r and r["triangles"] >= TARGET_MIN_TRIANGLES]
    met = [r for r in judged if r["ratio"] <= TARGET_RATIO]
    out = ["## Segmentation (`bench/segment_bench.py`)", "",
           benchutil.run_line("segment_bench.py", argv), "",
           f"`bpy.ops.bolus.segment(patches={PATCHES}, eta={ETA:g}, seed={SEED})` beside `bpy.ops.uv.smart_project()` "
           "(defaults, Edit Mode, all faces) on the same object in the same run; previous = the same operator with the "
           "exact eigenvectors below 150k vertices and k-means on every row, Σϖ change = the largest relative change "
           "of a patch's Σϖ against it. " + legend(repeat) + ".", "",
           summary_table(rows).markdown(), "",
           f"segment <= {TARGET_RATIO:g}× smart_project on {len(met)} of {len(judged)} meshes of "
           f"{TARGET_MIN_TRIANGLES:,} triangles or more."]
    if any(r["mesh"] == "demosthenes" for r in rows):
        out += ["", "demosthenes is in normalised units; it is taken as 1 unit = 100 mm (scale_length 0.1)."]
    return "\n".join(out)


def main(argv=None) -> int:
    ap = benchutil.parser(__doc__, "only the two face meshes")
    ap.add_argument("--verbose", action="store_true", help="show the operators' own reports")
    args = ap.parse_args(argv)
    repeat = max(1, args.repeat)

    import bpy
    import numpy as np
    import scipy
    import sklearn

    import bolus_addon

    bolus_addon.register()
    # import what the operator imports lazily, so the first timed call does not pay for it
    import sklearn.cluster  # noqa: F401
    import sklearn.mixture  # noqa: F401

    meshes = [m for m in MESHES if not args.quick or m[0] in QUICK]
    print(f"Bolus segment benchmark: bpy {bpy.app.version_string}, Python {platform.python_version()}, "
          f"numpy {np.__version__}, scipy {scipy.__version__}, scikit-learn {sklearn.__version__}, "
          f"{os.cpu_count()} CPUs")
    print(f"meshes from assets/ and tests/data/; each operator timed {repeat}x, best kept")
    rows = []
    t_start = time.perf_counter()
    try:
        for fname, scale_length, note in meshes:
            path = data_mesh(fname)
            try:
                rows.append(bench_mesh(bpy, fname, scale_length, note, repeat, args.verbose))
            except Exception as exc:  # a benchmark reports, it does not stop at the first failure
                rows.append(benchutil.error_row("mesh", Path(fname).stem, exc))
                clean_scene(bpy)
    finally:
        bolus_addon.unregister()
    total = time.perf_counter() - t_start
    print(f"\nSummary. {legend(repeat)}.")
    print(summary_table(rows).text())
    if any(r["mesh"] == "demosthenes" for r in rows):
        print("demosthenes is in normalised units; it is taken as 1 unit = 100 mm (scale_length 0.1).")
    benchutil.finish(args, {
        "repeat": repeat,
        "segment_args": {"patches": PATCHES, "eta": ETA, "seed": SEED, "smoothing": "default"},
        "target_ratio": TARGET_RATIO,
        "memory_labels": MEMORY_LABELS,
        "meshes": rows,
    }, total, markdown(rows, repeat, argv))
    return 0


if __name__ == "__main__":
    sys.exit(main())
