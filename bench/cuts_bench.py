"""Benchmark of `bpy.ops.bolus.smooth_cuts` (printed, not asserted).

Run from the repository root:

    .venv/bin/python bench/cuts_bench.py            # all meshes
    .venv/bin/python bench/cuts_bench.py --quick    # the two small face meshes only
    .venv/bin/python bench/cuts_bench.py --json out/cuts_bench.json

For every mesh: import, ``bolus.segment(patches=4, eta=5, seed=0)``, then two copies
of the segmented mesh in the same run: the *jagged* one as segment left it (the peer)
and the *smooth* one after ``bolus.smooth_cuts()``.  Printed:

* per border (from the operator's ``bolus_cut_table``): the method used, the mean
  absolute geodesic turning angle per mm before and after (target: at least 70 %
  lower; a border already turning under 0.005 rad/mm is counted as straight) and
  the largest distance of the new cut from the old border in mm (symmetric
  Hausdorff);
* the wall time of smooth_cuts;
* a second ``bolus.smooth_cuts()`` on the result: the new vertices it adds (must be 0:
  smooth_cuts is idempotent) and whether the polygons and ``bolus_patch`` stay
  identical;
* EL and EA of ``bolus.unfold()`` on both copies (SPEC measures, whole pattern and per
  patch): the seed's Table 4-5 says they should stay about equal or improve.

Meshes come from the repository's ``assets/`` and ``tests/data/``;
units as in bench/segment_bench.py.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for p in (ROOT, ROOT / "bench"):
    if str(p) not in sys.path:
        sys.path.insert(0, str(p))

from benchutil import captured_output, clean_scene, data_mesh, import_mesh, mesh_exists, write_json  # noqa: E402

PATCHES, ETA, SEED = 4, 5.0, 0
TARGET = 0.70  # turning per mm must drop by at least this fraction
STRAIGHT = 0.005  # rad/mm: a border turning less than this is already straight (nothing to remove)

#: (file, scale_length, patches)
MESHES = [
    ("makehuman_face_patch.obj", 0.1, 4),
    ("ict_face_narrow.obj", 0.01, 4),
    ("makehuman_knee_patch.obj", 0.1, 3),
    ("makehuman_elbow_patch.obj", 0.1, 3),
    ("demosthenes.obj", 0.1, 4),
    ("nefertiti.obj", 0.001, 4),
]
QUICK = {"makehuman_face_patch.obj", "ict_face_narrow.obj"}




def call(bpy, op, ob, verbose=False, **kw):
    bpy.context.view_layer.objects.active = ob
    for o in bpy.context.view_layer.objects:
        o.select_set(o is ob)
    with captured_output(not verbose) as out:
        try:
            res = op(**kw)
        except RuntimeError as exc:
            raise RuntimeError(f"{op.idname()} failed on {ob.name}: {exc}\n{out()}") from None
    if res != {"FINISHED"}:
        raise RuntimeError(f"{op.idname()} returned {res} on {ob.name}\n{out()}")


def duplicate(bpy, ob, name):
    dup = ob.copy()
    dup.data = ob.data.copy()
    dup.name = name
    bpy.context.scene.collection.objects.link(dup)
    return dup


def mesh_state(me) -> tuple:
    """(vertex positions, polygon corners, bolus_patch) of a mesh."""
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    loops = np.empty(len(me.loops), dtype=np.int64)
    me.loops.foreach_get("vertex_index", loops)
    lab = np.empty(len(me.polygons), dtype=np.int64)
    me.attributes["bolus_patch"].data.foreach_get("value", lab)
    return co, loops, lab


def pattern_figures(bpy, ob) -> dict:
    pat = bpy.data.objects[ob.name + "_pattern"]
    return json.loads(pat["bolus_pattern_table"])


def bench_mesh(bpy, fname: str, scale_length: float, patches: int, args) -> dict:
    clean_scene(bpy)
    ob = import_mesh(bpy, data_mesh(fname), scale_length)
    ob.name = Path(fname).stem
    call(bpy, bpy.ops.bolus.segment, ob, args.verbose, patches=patches, eta=ETA, seed=SEED)
    jag = duplicate(bpy, ob, ob.name + "_jagged")
    t0 = time.perf_counter()
    call(bpy, bpy.ops.bolus.smooth_cuts, ob, args.verbose)
    t_cut = time.perf_counter() - t0
    borders = json.loads(ob["bolus_cut_table"])
    row = {"mesh": fname, "faces": len(jag.data.polygons), "patches": patches, "smooth_cuts_s": t_cut,
           "new_vertices": len(ob.data.vertices) - len(jag.data.vertices), "borders": borders}
    # a second run on the result must change nothing
    before = mesh_state(ob.data)
    t0 = time.perf_counter()
    try:
        call(bpy, bpy.ops.bolus.smooth_cuts, ob, args.verbose)
    except RuntimeError as exc:  # recorded: a second run must not fail either
        row["second_run_error"] = str(exc).splitlines()[0]
    after = mesh_state(ob.data)
    row["second_run_s"] = time.perf_counter() - t0
    row["second_run_new_vertices"] = len(after[0]) - len(before[0])
    row["second_run_identical"] = all(np.array_equal(x, y) for x, y in zip(before, after))
    if not args.no_unfold:
        for key, o in (("jagged", jag), ("smooth", ob)):
            t0 = time.perf_counter()
            call(bpy, bpy.ops.bolus.unfold, o, args.verbose)
            row[f"unfold_{key}"] = {**pattern_figures(bpy, o), "seconds": time.perf_counter() - t0}
    return row


def print_row(r: dict) -> None:
    print(f"\n{r['mesh']}: {r['faces']} faces, {r['patches']} patches asked; smooth_cuts {r['smooth_cuts_s']:.2f} s, "
          f"{r['new_vertices']} new vertices; second run: {r['second_run_new_vertices']} new vertices, "
          f"mesh {'identical' if r['second_run_identical'] else 'CHANGED'} ({r['second_run_s']:.2f} s)"
          + (f" ERROR: {r['second_run_error']}" if "second_run_error" in r else ""))
    tb = sum(b["turning_before"] * b["length_before_mm"] for b in r["borders"])
    ta = sum(b["turning_after"] * b["length_after_mm"] for b in r["borders"])
    if tb > 0:
        print(f"  length-weighted turning of its borders: {(1 - ta / tb) * 100:.0f} % lower")
    print(f"  {'border':>7} {'method':<22} {'turn before':>11} {'turn after':>10} {'lower by':>8} {'moved mm':>8}  ok")
    for b in r["borders"]:
        drop = 1.0 - b["turning_after"] / b["turning_before"] if b["turning_before"] > 0 else 0.0
        ok = "yes" if drop >= TARGET else ("straight" if b["turning_before"] < STRAIGHT else "NO")
        print(f"  {b['a']:>3}|{b['b']:<3} {b['method']:<22} {b['turning_before']:>11.4f} {b['turning_after']:>10.4f} "
              f"{drop * 100:>7.0f}% {b['max_shift_mm']:>8.2f}  {ok}")
    if "unfold_jagged" in r:
        j, s = r["unfold_jagged"], r["unfold_smooth"]
        print(f"  unfold   jagged: EL {j['EL'] * 100:.2f} %  EA {j['EA'] * 100:.2f} %  flips {j['flipped']}  ({j['seconds']:.1f} s)")
        print(f"  unfold   smooth: EL {s['EL'] * 100:.2f} %  EA {s['EA'] * 100:.2f} %  flips {s['flipped']}  ({s['seconds']:.1f} s)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="only the two small face meshes")
    ap.add_argument("--no-unfold", action="store_true", help="skip the EL/EA comparison")
    ap.add_argument("--json", help="write the figures to this file")
    ap.add_argument("--markdown", metavar="FILE", help="append the table as markdown to FILE (make bench)")
    ap.add_argument("--verbose", action="store_true", help="show the operators' reports")
    args = ap.parse_args(argv)

    import bpy

    import bolus_addon

    bolus_addon.register()
    rows = []
    for fname, scale, patches in MESHES:
        if args.quick and fname not in QUICK:
            continue
        if not mesh_exists(fname):
            print(f"skipped {fname}: not in assets/ or tests/data/")
            continue
        row = bench_mesh(bpy, fname, scale, patches, args)
        print_row(row)
        rows.append(row)
    allb = [b for r in rows for b in r["borders"]]
    met = sum(1 for b in allb if b["turning_before"] > 0 and b["turning_after"] <= (1 - TARGET) * b["turning_before"])
    straight = sum(1 for b in allb if b["turning_before"] < STRAIGHT)
    print(f"\n{met} of {len(allb)} borders turn at least {TARGET * 100:.0f} % less per mm after smooth_cuts "
          f"({straight} were already straight, under {STRAIGHT} rad/mm)")
    weighted = [(b["turning_before"] * b["length_before_mm"], b["turning_after"] * b["length_after_mm"]) for b in allb]
    tb, ta = sum(w[0] for w in weighted), sum(w[1] for w in weighted)
    if tb > 0:
        print(f"length-weighted over all borders: the turning is {(1 - ta / tb) * 100:.0f} % lower")
    print(f"second run: {sum(r['second_run_new_vertices'] for r in rows)} new vertices in all, "
          f"{sum(not r['second_run_identical'] for r in rows)} of {len(rows)} meshes changed")
    if args.json:
        write_json(args.json, {"rows": rows, "target_drop": TARGET})
    if args.markdown:
        markdown_section(args.markdown, rows, argv)
    return 0


def markdown_section(path, rows: list[dict], argv) -> None:
    """Append this run's table to `path` (benchutil's markdown; make bench: docs/benchmarks.md)."""
    from benchutil import Table, append_markdown, pct, run_line

    t = Table([("mesh", "<"), ("faces", ">"), ("patches", ">"), ("smooth_cuts s", ">"), ("new vertices", ">"),
               ("second run: new vertices", ">"), ("weighted turning drop", ">"),
               (f"borders >= {TARGET:.0%} lower", ">"),
               ("EL % jagged → smooth", ">"), ("EA % jagged → smooth", ">")])
    for r in rows:
        bs = r["borders"]
        tb = sum(b["turning_before"] * b["length_before_mm"] for b in bs)
        ta = sum(b["turning_after"] * b["length_after_mm"] for b in bs)
        met = sum(1 for b in bs if b["turning_before"] > 0 and b["turning_after"] <= (1 - TARGET) * b["turning_before"])
        j, s = r.get("unfold_jagged"), r.get("unfold_smooth")
        el = f"{pct(j['EL'])} → {pct(s['EL'])}" if j and s else "n/a"
        ea = f"{pct(j['EA'])} → {pct(s['EA'])}" if j and s else "n/a"
        t.add(Path(r["mesh"]).stem, f"{r['faces']:,}", r["patches"], f"{r['smooth_cuts_s']:.2f}", r["new_vertices"],
              f"{r['second_run_new_vertices']}" + ("" if r["second_run_identical"] else " (mesh changed)"),
              f"{(1 - ta / tb):.0%}" if tb > 0 else "n/a", f"{met} of {len(bs)}", el, ea)
    append_markdown(path, "\n".join([
        "## Smooth cut lines (`bench/cuts_bench.py`)", "", run_line("cuts_bench.py", argv), "",
        f"Each mesh segmented (`bolus.segment`, eta={ETA:g}, seed={SEED}) and copied: the jagged copy as segment "
        "left it (the peer), the other after `bolus.smooth_cuts()`; both unfolded (`bolus.unfold`) in the same run. "
        "Turning = mean absolute geodesic turning angle per mm of a border, weighted by border length over the "
        f"mesh; a border counts when it turns at least {TARGET:.0%} less. Second run = smooth_cuts again on its "
        "own result (0 new vertices: idempotent). EL / EA in % of the whole pattern (SPEC).", "", t.markdown()]))


if __name__ == "__main__":
    sys.exit(main())
