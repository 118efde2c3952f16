"""Benchmark: a whole face left in one patch, made into sheet pieces (printed, not asserted).

Run from the repository root:

    .venv/bin/python bench/whole_face_bench.py                     # both faces, with the peers
    .venv/bin/python bench/whole_face_bench.py --quick             # the ICT face, ours only
    .venv/bin/python bench/whole_face_bench.py --markdown docs/benchmarks.md   # replace its section

Faces (mm): ``nefertiti face`` (nefertiti.obj, the triangles within 150 mm of the nose tip,
midpoint-subdivided once: 43,196 triangles) and ``ict face`` (ict_face_narrow.obj x10, whole, with
both nostril pockets: 13,120 triangles).  For each, in the same run:

* ours: ``sheet_pieces(V, F, max_el=0.02)`` (the unfold operator's core at its default Max EL):
  the face is cut into spectral parts by its angle defect first (`part_split`), then darts and
  splits in each part;
* previous: the same with the cut into parts turned off (darts and splits on the whole face,
  ``part_split.PART_MIN_TRIANGLES`` out of reach); ``--no-previous`` skips it (about 2 min);
* SLIM-100: Blender's ``uv.unwrap(method='MINIMUM_STRETCH', iterations=100)`` on the face cut to a
  disk (one piece, no darts), the operator call only; skipped with ``--no-slim``.

Every piece is measured on its own against its own 3D triangles (`measures.length_area_errors`,
SPEC's EL and EA, no scale fitted), flipped triangles from the signed UV areas, overlapping ones
as the unfolding counted them.  Target: wall time <= 30 s, every piece EL <= 2 % and EA <= 3 %,
0 flipped and 0 overlapping triangles, every source triangle in exactly one piece.
"""
from __future__ import annotations

import sys
import time

import benchutil
from benchutil import Table, data_mesh

SECTION = "## A whole face in one patch (`bench/whole_face_bench.py`)"
TARGET_S, MAX_EL = 30.0, 0.02
FACE_RADIUS_MM = 150.0


def faces(quick: bool) -> list[dict]:
    """The faces: name, V, F, how it was made."""
    import numpy as np

    from bolus_addon.core.mesh.objfile import load_obj
    from unfold_bench import midpoint_subdivide, region_around

    out = []
    if not quick:
        V, F, _ = load_obj(data_mesh("nefertiti.obj"), 1.0)
        tip = V[int(np.argmax(V[:, 2]))]
        Vf, Ff = midpoint_subdivide(*region_around(V, F, tip, FACE_RADIUS_MM))
        out.append({"name": "nefertiti face", "V": Vf, "F": Ff,
                    "how": f"nefertiti.obj (mm), within {FACE_RADIUS_MM:g} mm of the nose tip, subdivided once"})
    V, F, _ = load_obj(data_mesh("ict_face_narrow.obj"), 10.0)
    out.append({"name": "ict face", "V": V, "F": F, "how": "ict_face_narrow.obj x10 (cm -> mm), whole, two nostrils"})
    return out


def measure_pieces(V, F, res) -> dict:
    """Each piece against its own 3D triangles: worst EL / EA, flips, overlaps, partition."""
    import numpy as np

    from bolus_addon.core.unfold.measures import length_area_errors
    from bolus_addon.core.unfold.overlap import signed_areas

    els, eas, flips, overlaps = [], [], 0, 0
    seen = np.zeros(len(F), dtype=int)
    for j, u in enumerate(res.unfoldings):
        fs = np.flatnonzero(res.piece == j)
        seen[fs] += 1
        el, ea = length_area_errors(V[u.vert_origin], u.F, u.UV)
        els.append(el)
        eas.append(ea)
        flips += int((signed_areas(u.UV, u.F) <= 0).sum())
        overlaps += int(u.overlaps)
    ok = max(els) <= MAX_EL and max(eas) <= 1.5 * MAX_EL and flips == 0 and overlaps == 0 and (seen == 1).all()
    return {"pieces": len(res.unfoldings), "darts": len(res.darts), "splits": len(res.splits),
            "worst_el": max(els), "worst_ea": max(eas), "flips": flips, "overlaps": overlaps,
            "partition": bool((seen == 1).all()), "met": bool(ok)}


def run_ours(V, F, whole: bool) -> dict:
    from bolus_addon.core.unfold import part_split
    from bolus_addon.core.unfold.sheet_pieces import sheet_pieces

    saved = part_split.PART_MIN_TRIANGLES
    if whole:
        part_split.PART_MIN_TRIANGLES = 10**12
    try:
        t0 = time.perf_counter()
        res = sheet_pieces(V, F, MAX_EL)
        dt = time.perf_counter() - t0
    finally:
        part_split.PART_MIN_TRIANGLES = saved
    return {"seconds": dt, **measure_pieces(V, F, res)}


def row_text(r: dict) -> tuple:
    if "error" in r:
        return (r["error"][:60], "", "", "", "", "")
    return (f"{r['seconds']:.1f}", f"{r['pieces']} / {r['darts']} / {r['splits']}",
            f"{100 * r['worst_el']:.2f} / {100 * r['worst_ea']:.2f}", f"{r['flips']}/{r['overlaps']}",
            "yes" if r["met"] else "no", "yes" if r["met"] and r["seconds"] <= TARGET_S else "no")


def table(rows: list[dict]) -> Table:
    t = Table([("face", "<"), ("triangles", ">"), ("method", "<"), ("s", ">"), ("pieces / darts / splits", ">"),
               ("worst piece EL / EA %", ">"), ("f/o", ">"), ("every piece within", "<"), ("target met", "<")])
    for row in rows:
        for key in ("ours", "previous", "SLIM-100"):
            if key in row:
                t.add(row["name"], f"{row['faces']:,}", key, *row_text(row[key]))
    return t


def slim(face: dict) -> dict:
    """SLIM-100 on the face cut to a disk, through bench/unfold_bench.py's Blender runner."""
    from unfold_bench import slim_rows

    out = slim_rows([face], repeat=1)[0]["SLIM-100"]
    if "error" in out or "na" in out:
        return {"error": out.get("error") or out["na"]}
    return {"seconds": out["seconds"], "pieces": 1, "darts": 0, "splits": 0, "worst_el": out["EL"],
            "worst_ea": out["EA"], "flips": out.get("flipped", 0), "overlaps": out.get("overlaps", 0),
            "partition": True, "met": out["EL"] <= MAX_EL and out["EA"] <= 1.5 * MAX_EL}


def main(argv=None) -> int:
    ap = benchutil.parser(__doc__, "the ICT face only, ours only", repeat=None)
    ap.add_argument("--no-previous", action="store_true", help="skip darts and splits on the whole face")
    ap.add_argument("--no-slim", action="store_true", help="skip Blender's SLIM")
    args = ap.parse_args(argv)
    t_start = time.perf_counter()
    rows = []
    for face in faces(args.quick):
        V, F = face["V"], face["F"]
        row = {"name": face["name"], "faces": int(len(F)), "how": face["how"]}
        print(f"== {face['name']}: {len(F)} triangles ({face['how']})", flush=True)
        steps = [("ours", lambda: run_ours(V, F, False))]
        if not (args.quick or args.no_previous):
            steps.append(("previous", lambda: run_ours(V, F, True)))
        if not (args.quick or args.no_slim):
            steps.append(("SLIM-100", lambda: slim(face)))
        for key, call in steps:
            try:
                row[key] = call()
            except Exception as exc:  # a benchmark reports, it does not stop at the first failure
                row[key] = benchutil.error_row("method", key, exc)
            print(f"   {key}: " + " | ".join(row_text(row[key])), flush=True)
        rows.append(row)
    t = table(rows)
    total = time.perf_counter() - t_start
    print(t.text())
    benchutil.finish(args, {"rows": rows, "target_s": TARGET_S, "max_el": MAX_EL}, total)
    if args.markdown:
        legend = (f"ours = `sheet_pieces(V, F, max_el={MAX_EL:g})` (spectral parts by angle defect, then darts and "
                  "splits in each); previous = the same without the parts; SLIM-100 = Blender's `uv.unwrap(method="
                  "'MINIMUM_STRETCH', iterations=100)` on the face cut to a disk, one piece. Every piece measured on "
                  "its own (SPEC's EL / EA, no scale fitted); f/o = flipped / overlapping triangles; target: <= "
                  f"{TARGET_S:g} s, every piece EL <= 2 % and EA <= 3 %, 0 flipped, 0 overlapping. Faces: "
                  + "; ".join(f"{r['name']}: {r['how']}" for r in rows) + ".")
        benchutil.replace_section(args.markdown, SECTION, "\n".join(
            [SECTION, "", benchutil.run_line("whole_face_bench.py", argv), "", legend, "", t.markdown(), "",
             f"_Whole script: {total:.0f} s._", ""]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
