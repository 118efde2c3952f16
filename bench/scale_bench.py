"""Scale benchmark: core steps on a head of 10k, 100k and 1M faces (printed, not asserted).

Run from the repository root (no Blender needed: core only):

    .venv/bin/python bench/scale_bench.py                  # 10k, 100k, 1M (about 15 minutes)
    .venv/bin/python bench/scale_bench.py --quick          # 10k and 100k only
    .venv/bin/python bench/scale_bench.py --steps preview segment --sizes 1M
    .venv/bin/python bench/scale_bench.py --markdown docs/benchmarks.md   # replace its own section

Meshes (``nefertiti.obj``, a closed 70k-triangle bust scan in mm, from ``tests/data``;
midpoint 1->4 subdivision does not move the surface):

* ``10k``: the 70k mesh, the edge-connected crop of about 10,000 triangles nearest the nose tip
  (the vertex of largest z);
* ``100k``: the mesh subdivided once (280k), the crop of about 100,000 triangles around the nose tip;
* ``1M``: the whole bust subdivided twice (1,120,000 triangles, closed);
* ``1.4M``: a scan-like head: the ``1M`` mesh with ``BISECTIONS`` random edges split at their midpoints
  (no two in one triangle: irregular triangles, 1,400,000 in all) and every vertex moved along its normal
  by Gaussian noise of ``NOISE_MM`` (seed 0).  Run only when named in ``--sizes``.

Steps (each (step, size) in a fresh child process of its own, ``--worker``: its peak memory is its own;
the mesh is built once by the parent and handed over as a .npz file):

* ``preview``: ``saliency.analyse(V, F, 3.0)`` on the whole size mesh (the preview operator's core);
* ``segment``: ``spectral.segment(V, F, 3, eta=5, smoothing_mm=3, rng=0, analysis=preview)`` on the whole
  size mesh, given the preview's result (computed first, untimed, as the add-on's segment operator reuses the
  last preview of the same region and smoothing);
* ``segment_alone`` (only when asked with ``--steps``): the same without the preview, i.e. computing it;
* ``segment_exact`` (only when asked): ``segment`` with the eigenvectors of the full problem (shift-invert
  Lanczos on the whole Laplacian, no coarse level) and k-means on every row: the reference the patches of
  ``segment`` are compared with (triangles in the same patch after matching the labels, each patch's
  sum varpi, and how far each border of ``segment`` lies from the reference's borders, in mm);
* ``cuts``: ``cutlines.smooth_cuts`` on a crop of n/5 triangles of the same density (200k at 1M), its
  labels from ``spectral.segment(.., 3)`` of that crop first (not timed, its memory peak reset);
* ``unfold``: ``unfold.unfold_patch(V, F)`` (defaults) on a crop of n/20 triangles (50k at 1M);
* ``shell``: ``shell.make_shell(V, F, thickness=10, resolution=1.0)`` (the printed bolus' core) on the
  face: the triangles within ``FACE_RADIUS_MM`` of the nose tip at the size's density (same area
  at every size, so its growth is against the triangle count alone);
* ``orient``: ``print_orientation.orient(V, F, rng=0)`` on the n/5 crop (a part).

Per (step, size): wall time of the call alone; peak = the child's VmHWM during the call (reset just
before it through /proc/self/clear_refs) and + = that peak minus the RSS before the call (the input
and the imports); growth = log-log slope of time against triangles, 10k->100k and 100k->1M;
a slope above ``SUPERLINEAR`` is flagged. Yardstick: on 1M faces preview + segment within
60 s, peak memory under 2 GB (before: a 1.43M-face head took 37-40 s to preview, 104-106 s to segment).
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import benchutil
from benchutil import data_mesh, Table

#: (times subdivided, crop to n faces, edges bisected with noise)
SIZES = {"10k": (0, 10_000, 0), "100k": (1, 100_000, 0), "1M": (2, None, 0), "1.4M": (2, None, 140_000)}
DEFAULT_SIZES = ("10k", "100k", "1M")
QUICK_SIZES = ("10k", "100k")
BISECTIONS, NOISE_MM = 140_000, 0.05
STEPS = ("preview", "segment", "cuts", "unfold", "shell", "orient")
EXTRA_STEPS = ("segment_alone", "segment_exact")  # run only when named in --steps
CUT_SHARE, UNFOLD_SHARE = 5, 20  # regions of n/5 and n/20 triangles
FACE_RADIUS_MM = 100.0
SMOOTHING_MM, PATCHES, ETA = 3.0, 3, 5.0
SHELL_T_MM, SHELL_RES_MM = 10.0, 1.0
SUPERLINEAR = 1.3
TARGET_S, TARGET_MB = 60.0, 2048.0
TARGET14_S, TARGET14_MB = 30.0, 1536.0  #: 1.4M faces: preview + segment, and the larger memory growth
TIMEOUT_S = 420
SECTION = "## Scale: 10k to 1M faces (`bench/scale_bench.py`)"


# ----------------------------------------------------------------------------- meshes


def crop(V, F, centre, n_faces):
    """The edge-connected triangles nearest centre, about n_faces of them (every corner within the radius)."""
    import numpy as np

    from unfold_bench import region_around

    far = np.linalg.norm(V - centre, axis=1)[F].max(axis=1)
    r = float(np.partition(far, min(n_faces, len(F)) - 1)[min(n_faces, len(F)) - 1])
    return region_around(V, F, centre, r)


def outward(V, F, inside):
    from shell_bench import outward as _outward

    return _outward(V, F, inside)[0]


def bisect_edges(V, F, count: int, noise_mm: float, seed: int = 0):
    """Split ``count`` random interior edges at their midpoints, no two in one triangle (each split turns
    its two triangles into four), then move every vertex along its normal by N(0, noise_mm)."""
    import numpy as np

    from bolus_addon.core.mesh.topology import MeshTopology

    rng = np.random.default_rng(seed)
    topo = MeshTopology(V, F)
    ef = topo.edge_faces  # (e, 2), -1 on the border
    cand = rng.permutation(np.flatnonzero((ef >= 0).all(axis=1)))
    first = np.full(len(F), len(cand))
    for side in (0, 1):  # an edge is taken when it comes first in both of its triangles
        np.minimum.at(first, ef[cand, side], np.arange(len(cand)))
    pos = np.arange(len(cand))
    take = cand[(first[ef[cand, 0]] == pos) & (first[ef[cand, 1]] == pos)][:count]
    E = topo.edges[take]
    mid = len(V) + np.arange(len(take))
    V2 = np.vstack([V, 0.5 * (V[E[:, 0]] + V[E[:, 1]])])
    keep = np.ones(len(F), dtype=bool)
    new = []
    for side in (0, 1):
        f = ef[take, side]
        keep[f] = False
        tri = F[f]
        # turn each triangle (keeping its orientation) so that its corner off the edge comes last
        off = np.argmin((tri == E[:, :1]) | (tri == E[:, 1:]), axis=1)
        tri = np.take_along_axis(tri, (off[:, None] + np.arange(1, 4)) % 3, axis=1)
        new += [np.c_[tri[:, 0], mid, tri[:, 2]], np.c_[mid, tri[:, 1], tri[:, 2]]]
    F2 = np.vstack([F[keep]] + new)
    N = MeshTopology(V2, F2).vertex_normals
    return V2 + N * rng.normal(0.0, noise_mm, (len(V2), 1)), F2


def build_inputs(sizes, steps, folder: Path) -> dict:
    """Write the input .npz of every (step, size) to folder -> {(step, size): (path, faces, how)}."""
    import numpy as np

    from bolus_addon.core.mesh.objfile import load_obj
    from unfold_bench import midpoint_subdivide, region_around

    V0, F0, _ = load_obj(data_mesh("nefertiti.obj"), 1.0)
    centre_body = V0.mean(axis=0)
    tip = V0[int(np.argmax(V0[:, 2]))]
    levels = {0: (V0, F0)}
    out = {}
    for size in sizes:
        level, n, cuts = SIZES[size]
        while level not in levels:
            k = max(levels)
            levels[k + 1] = midpoint_subdivide(*levels[k])
        VL, FL = levels[level]
        if cuts:
            VL, FL = bisect_edges(VL, FL, cuts, NOISE_MM)
        Vs, Fs = (VL, FL) if n is None else crop(VL, FL, tip, n)
        n_size = len(Fs)
        how_size = f"nefertiti x{4 ** level} ({len(FL)} tri)" + ("" if n is None else f", crop {n_size} tri") + (
            f" with {cuts} edges bisected and {NOISE_MM:g} mm noise" if cuts else "")
        out[("size", size)] = (None, n_size, how_size)
        for step in steps:
            if step in ("preview", "segment", "segment_alone", "segment_exact"):
                V, F, how = Vs, Fs, how_size
            elif step in ("cuts", "orient"):
                V, F = crop(VL, FL, tip, n_size // CUT_SHARE)
                how = f"crop of {len(F)} tri"
            elif step == "unfold":
                V, F = crop(VL, FL, tip, n_size // UNFOLD_SHARE)
                how = f"crop of {len(F)} tri"
            else:
                V, F = region_around(VL, FL, tip, FACE_RADIUS_MM)
                how = f"face within {FACE_RADIUS_MM:g} mm of the nose tip, {len(F)} tri"
            if step in ("cuts", "unfold", "shell", "orient"):
                F = outward(V, F, centre_body)
            path = folder / f"{step}_{size}.npz"
            np.savez(path, V=np.ascontiguousarray(V, dtype=np.float64), F=np.ascontiguousarray(F, dtype=np.int64))
            out[(step, size)] = (path, len(F), how)
    return out


# ----------------------------------------------------------------------------- the child



def worker(step: str, path: str) -> dict:
    """Run one step on the mesh in path (in this fresh process) -> seconds, peak and delta MB, a note."""
    import gc

    import numpy as np

    from bolus_addon.core.cuts import cutlines
    from bolus_addon.core.printing import orientation as print_orientation
    from bolus_addon.core.analysis import saliency, spectral
    from bolus_addon.core.solid import shell
    from bolus_addon.core.unfold import unfold

    d = np.load(path)
    V, F = d["V"], d["F"]
    note = ""
    if step == "preview":
        call = lambda: saliency.analyse(V, F, SMOOTHING_MM)  # noqa: E731
    elif step == "segment":
        ana = saliency.analyse(V, F, SMOOTHING_MM)  # the preview, untimed (its peak is reset below)
        call = lambda: spectral.segment(V, F, PATCHES, eta=ETA, smoothing_mm=SMOOTHING_MM, rng=0,  # noqa: E731
                                        analysis=ana)
    elif step == "segment_alone":
        call = lambda: spectral.segment(V, F, PATCHES, eta=ETA, smoothing_mm=SMOOTHING_MM, rng=0)  # noqa: E731
    elif step == "segment_exact":
        from bolus_addon.core.analysis import clustering

        spectral.MULTILEVEL_MIN_VERTICES, clustering.KMEANS_SAMPLE = 10**12, 10**12
        ana = saliency.analyse(V, F, SMOOTHING_MM)
        call = lambda: spectral.segment(V, F, PATCHES, eta=ETA, smoothing_mm=SMOOTHING_MM, rng=0,  # noqa: E731
                                        analysis=ana)
    elif step == "cuts":
        labels = spectral.segment(V, F, PATCHES, eta=ETA, smoothing_mm=SMOOTHING_MM, rng=0).face_labels
        call = lambda: cutlines.smooth_cuts(V, F, labels)  # noqa: E731
    elif step == "unfold":
        call = lambda: unfold.unfold_patch(V, F)  # noqa: E731
    elif step == "shell":
        call = lambda: shell.make_shell(V, F, thickness=SHELL_T_MM, resolution=SHELL_RES_MM)  # noqa: E731
    elif step == "orient":
        call = lambda: print_orientation.orient(V, F, rng=0)  # noqa: E731
    else:
        raise ValueError(step)
    gc.collect()
    before = benchutil.status_kb("VmRSS")
    reset = benchutil.reset_peak_rss()
    t0 = time.perf_counter()
    res = call()
    dt = time.perf_counter() - t0
    peak = benchutil.status_kb("VmHWM")
    if step in ("segment", "segment_alone", "segment_exact"):
        note = f"{len(np.unique(res.face_labels))} patches"
        np.savez(str(path) + ".labels.npz", labels=res.face_labels,
                 varpi=np.array([p.sum_varpi for p in res.patches]))
    elif step == "cuts":
        note = f"{len(res.F)} tri out"
    elif step == "unfold":
        el = getattr(res, "EL", None)
        note = (f"EL {100 * el:.2f}%, EA {100 * res.EA:.2f}%" if isinstance(el, float) else type(res).__name__) + (
            ", hopeless" if getattr(res, "hopeless", False) else "")
    elif step == "shell":
        M = getattr(res, "F", None)
        note = f"{len(M)} tri solid" if M is not None else ""
    return {"seconds": dt, "peak_mb": peak / 1024, "delta_mb": (peak - before) / 1024, "before_mb": before / 1024,
            "peak_reset": reset, "note": note}


def run_child(step: str, path: Path, timeout: float) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", step, str(path)]
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"error": f"did not finish within {timeout:.0f} s"}
    lines = [ln for ln in p.stdout.splitlines() if ln.startswith("RESULT ")]
    if p.returncode != 0 or not lines:
        tail = (p.stderr.strip().splitlines() or ["exit code %d" % p.returncode])[-1]
        return {"error": tail[:200]}
    return json.loads(lines[-1][7:])


# ----------------------------------------------------------------------------- figures


def slope(a: dict | None, b: dict | None) -> float | None:
    if not a or not b or "seconds" not in a or "seconds" not in b or a["seconds"] <= 0 or b["seconds"] <= 0:
        return None
    return math.log(b["seconds"] / a["seconds"]) / math.log(b["faces"] / a["faces"])


def growth_pairs(sizes) -> list[tuple[str, str]]:
    """Consecutive sizes of the one mesh family (the 1.4M scan-like head is another surface: no slope to it)."""
    same = [s for s in sizes if s in DEFAULT_SIZES]
    return list(zip(same, same[1:]))


def tables(results: dict, sizes, steps):
    t = Table([("step", "<")] + [(f"{s} tri / s / peak MB (+MB)", ">") for s in sizes]
              + [(f"growth {a}->{b}", ">") for a, b in growth_pairs(sizes)] + [("note (largest)", "<")])
    flags = []
    for step in steps:
        cells, note = [], ""
        for s in sizes:
            r = results.get((step, s))
            if r is None:
                cells.append("not run")
            elif "error" in r:
                cells.append(f"{r.get('faces', '?')} / {r['error']}")
            else:
                cells.append(f"{r['faces']} / {r['seconds']:.2f} / {r['peak_mb']:.0f} (+{r['delta_mb']:.0f})")
                note = r.get("note", "") or note
        for a, b in growth_pairs(sizes):
            k = slope(results.get((step, a)), results.get((step, b)))
            if k is None:
                cells.append("n/a")
            else:
                flag = k > SUPERLINEAR
                cells.append(f"{k:.2f}" + (" SUPER-LINEAR" if flag else ""))
                if flag:
                    flags.append(f"{step} {a}->{b}: {k:.2f}")
        t.add(step, *cells, note)
    return t, flags


def compare_exact(path, ours_file, exact_file) -> dict:
    """The patches of ``segment`` against ``segment_exact`` on the same mesh (module doc)."""
    import numpy as np
    from scipy.optimize import linear_sum_assignment
    from scipy.spatial import cKDTree

    from bolus_addon.core.mesh.topology import MeshTopology

    d = np.load(path)
    topo = MeshTopology(d["V"], d["F"])
    a, b = np.load(ours_file), np.load(exact_file)
    la, lb = a["labels"], b["labels"]
    overlap = np.zeros((la.max() + 1, lb.max() + 1))
    np.add.at(overlap, (la, lb), topo.areas)
    ra, rb = linear_sum_assignment(-overlap)
    same = float(overlap[ra, rb].sum() / topo.areas.sum())
    dv = np.abs(a["varpi"][ra] - b["varpi"][rb]) / np.maximum(np.abs(b["varpi"][rb]), 1e-9)
    ef = topo.edge_faces
    inner = (ef >= 0).all(axis=1)
    mids = topo.V[topo.edges].mean(axis=1)

    def border(lab):
        return mids[inner & (lab[np.maximum(ef[:, 0], 0)] != lab[np.maximum(ef[:, 1], 0)])]

    ba, bb = border(la), border(lb)
    far = cKDTree(bb).query(ba)[0] if len(ba) and len(bb) else np.zeros(1)
    return {"patches": [int(la.max() + 1), int(lb.max() + 1)], "same_area": same,
            "varpi_change_max": float(dv.max()) if len(dv) else 0.0,
            "border_p50_mm": float(np.percentile(far, 50)), "border_p95_mm": float(np.percentile(far, 95)),
            "border_max_mm": float(far.max())}


def exact_text(cmp: dict) -> str:
    return "; ".join(
        f"{size}: {c['patches'][0]} / {c['patches'][1]} patches, {100 * c['same_area']:.2f} % of the area in the "
        f"same patch, largest change of a patch's sum varpi {100 * c['varpi_change_max']:.2f} % (target 5 %), "
        f"border of segment from the reference's: median {c['border_p50_mm']:.2f} mm, p95 {c['border_p95_mm']:.2f} "
        f"mm, max {c['border_max_mm']:.1f} mm" for size, c in cmp.items())


def verdict(results: dict) -> str:
    p, s = results.get(("preview", "1.4M")), results.get(("segment", "1.4M"))
    if p and s and "seconds" in p and "seconds" in s:
        tot, grow = p["seconds"] + s["seconds"], max(p["delta_mb"], s["delta_mb"])
        head = (f"1.4M target: preview {p['seconds']:.1f} s + segment {s['seconds']:.1f} s = {tot:.1f} s (target <= "
                f"{TARGET14_S:g} s: {'MET' if tot <= TARGET14_S else 'NOT MET'}); largest growth of one of them "
                f"{grow:.0f} MB (target <= {TARGET14_MB:g} MB: {'MET' if grow <= TARGET14_MB else 'NOT MET'}). ")
    else:
        head = ""
    p, s = results.get(("preview", "1M")), results.get(("segment", "1M"))
    if not p or not s or "seconds" not in p or "seconds" not in s:
        return head + "1M yardstick: not measured (preview or segment at 1M did not run)."
    tot = p["seconds"] + s["seconds"]
    mem = max(r["peak_mb"] for (st, sz), r in results.items() if sz == "1M" and "peak_mb" in r)
    return head + (f"1M yardstick: preview {p['seconds']:.1f} s + segment {s['seconds']:.1f} s = {tot:.1f} s "
            f"(target <= {TARGET_S:g} s: {'MET' if tot <= TARGET_S else 'NOT MET'}); largest peak of a 1M-size step "
            f"{mem:.0f} MB (target < {TARGET_MB:g} MB: {'MET' if mem < TARGET_MB else 'NOT MET'}). "
            "Before the coarse-to-fine eigenvectors and the reused preview: 1.43M faces, 37-40 s preview, 104-106 s segment, +1.5-1.6 GB; 2026-12-02 05:10 (before "
            "segment reused the preview and went coarse to fine): 1.12M faces, 20.1 s + 68.7 s = 88.8 s, peak 1712 MB.")


def legend() -> str:
    return ("Cells: triangles of the step's input / wall seconds of the call alone / the child's peak RSS in MB "
            "(+ the peak minus the RSS before the call). growth: log-log slope of seconds against triangles "
            f"between two sizes (1 = linear; above {SUPERLINEAR:g} flagged SUPER-LINEAR; small sizes are "
            "dominated by fixed costs, so the 100k->1M slope is the telling one). "
            f"preview = saliency.analyse(V, F, {SMOOTHING_MM:g}); segment = spectral.segment(V, F, {PATCHES}, "
            f"eta={ETA:g}, smoothing_mm={SMOOTHING_MM:g}, rng=0, analysis=the preview's result, computed first "
            f"and untimed, as the segment operator reuses the last preview; segment_alone: without it); cuts = cutlines.smooth_cuts on an n/{CUT_SHARE} "
            f"crop segmented first (untimed); unfold = unfold.unfold_patch (defaults) on an n/{UNFOLD_SHARE} crop; "
            f"shell = shell.make_shell(thickness={SHELL_T_MM:g}, resolution={SHELL_RES_MM:g}) on the face "
            f"({FACE_RADIUS_MM:g} mm around the nose tip) at the size's density; orient = "
            f"print_orientation.orient(rng=0) on the n/{CUT_SHARE} crop. Every (step, size) in a fresh child process")


def markdown(t: Table, flags, verdict_text: str, hows: dict, argv) -> str:
    out = [SECTION, "", benchutil.run_line("scale_bench.py", argv), "",
           "Input: `nefertiti.obj` (70k triangles, mm) midpoint-subdivided; " +
           "; ".join(f"{s}: {h}" for s, h in hows.items()) + ". " + legend() + ".", "",
           t.markdown(), "", verdict_text, "",
           ("Super-linear growth: " + ", ".join(flags) + ".") if flags
           else f"No step grew faster than n^{SUPERLINEAR:g} between the sizes measured."]
    return "\n".join(out)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--worker"]:
        print("RESULT " + json.dumps(worker(argv[1], argv[2])), flush=True)
        return 0
    ap = benchutil.parser(__doc__, "10k and 100k only", repeat=None)
    ap.add_argument("--sizes", nargs="+", choices=list(SIZES), help="sizes to run (default 10k 100k 1M, --quick 10k 100k; 1.4M only when named)")
    ap.add_argument("--steps", nargs="+", choices=STEPS + EXTRA_STEPS, default=list(STEPS),
                    help="steps to run (default all but segment_alone)")
    ap.add_argument("--timeout", type=float, default=TIMEOUT_S, help=f"seconds per (step, size) (default {TIMEOUT_S})")
    args = ap.parse_args(argv)
    sizes = args.sizes or list(QUICK_SIZES if args.quick else DEFAULT_SIZES)
    sizes = [s for s in SIZES if s in sizes]
    steps = [s for s in STEPS + EXTRA_STEPS if s in args.steps]
    t_start = time.perf_counter()
    results: dict = {}
    with tempfile.TemporaryDirectory(prefix="scale_bench_") as tmp:
        t0 = time.perf_counter()
        inputs = build_inputs(sizes, steps, Path(tmp))
        print(f"inputs built in {time.perf_counter() - t0:.1f} s")
        hows = {s: inputs[("size", s)][2] for s in sizes}
        for size in sizes:  # small first: a size that times out says the next will too
            for step in steps:
                path, faces, how = inputs[(step, size)]
                print(f"== {step} {size}: {how} ...", flush=True)
                r = run_child(step, path, args.timeout)
                r["faces"] = faces
                results[(step, size)] = r
                print("   " + (f"ERROR {r['error']}" if "error" in r else
                               f"{r['seconds']:.2f} s, peak {r['peak_mb']:.0f} MB (+{r['delta_mb']:.0f}) {r['note']}"),
                      flush=True)
        cmp = {size: compare_exact(inputs[("segment", size)][0], str(inputs[("segment", size)][0]) + ".labels.npz",
                                   str(inputs[("segment_exact", size)][0]) + ".labels.npz")
               for size in sizes if "seconds" in results.get(("segment", size), {})
               and "seconds" in results.get(("segment_exact", size), {})}
    t, flags = tables(results, sizes, steps)
    v = verdict(results) + (("\n\nsegment against segment_exact (the full eigen-solve): " + exact_text(cmp) + ".")
                            if cmp else "")
    print("\n" + legend() + ".\n" + t.text() + "\n" + v)
    print("super-linear: " + (", ".join(flags) if flags else "none"))
    total = time.perf_counter() - t_start
    print(f"total bench time {total:.1f} s")
    if args.json:
        benchutil.write_json(args.json, {"results": [{"step": a, "size": b, **r} for (a, b), r in results.items()],
                                         "verdict": v, "superlinear": flags, "total_s": total, "exact": cmp})
    if args.markdown:
        benchutil.replace_section(args.markdown, SECTION, markdown(t, flags, v, hows, argv) + f"\n\n_Whole script: {total:.0f} s._\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
