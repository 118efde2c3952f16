"""Range-scan benchmark: every operator on a 17-piece scan of about 520k faces
finishes or refuses within a minute (printed, not asserted).

Run from the repository root (bpy in .venv):

    .venv/bin/python bench/rangescan_bench.py                  # all three scenarios, every operator
    .venv/bin/python bench/rangescan_bench.py --quick          # the scan at 1/4 size (about 130k faces)
    .venv/bin/python bench/rangescan_bench.py --ops unfold make_shell --scenarios whole
    .venv/bin/python bench/rangescan_bench.py --markdown docs/benchmarks.md   # replace its own section

The scan (built here, deterministic; the repository has no range scan): ``nefertiti.obj``
(a closed 70k-triangle bust in mm) subdivided twice at the edge midpoints (1,120,000 triangles,
the surface unchanged); the front as a scanner sees it (the triangles whose centroid is in front
of a z plane, z = the nose's direction); scan gaps: bands ``GAP_MM`` wide around random planes
through the surface are removed (with the faces around any non-manifold vertex the cut
leaves), a plane at a time (a plane is kept only while the pieces stay at most
``PIECES - FRAGMENTS``), until the surface falls into that many edge-connected pieces;
then ``FRAGMENTS`` tiny floating fragments (small discs of the surface copied 2-4 mm off it, as
spray or a second pass leaves) and Gaussian noise along the vertex normals, sigma drawn per piece
in ``NOISE_MM``.  The count of edge-connected pieces is checked (17) and the face count printed
(about 520k).

Scenarios (each operator in a fresh child process with bpy, ``--worker``; the scene in mm):

* ``whole``: the user's first try: the whole scan, nothing selected, Object Mode.  An operator
  that needs an earlier step's result gets it cheaply and untimed: ``bolus_patch`` for
  smooth_cuts and unfold (3 bands across the scan, every piece cut by them), ``bolus_print_part``
  the same for orient_parts, and export_parts the part objects of orient_parts (run untimed
  first); export_pattern has no pattern (unfold made none): it must say so.
* ``nose``: the treatment area first (``bolus.select_area`` around the nose tip, 45 mm, timed),
  then the whole chain in one process on that selection, each step timed: saliency_preview,
  segment (4 patches), smooth_cuts, improve_flattenability, unfold, export_pattern (SVG),
  make_shell, print_segment (on the bolus), orient_parts, export_parts.
* ``nose_decimated``: as ``nose`` after a Decimate modifier of ratio ``DECIMATE_RATIO`` applied to
  the scan (timed, the row "decimate"): what the refusals on the nose area advise.

Per operator: the wall time of the call alone (setup excluded), FINISHED or refused (the
message), and the longest silence between two progress lines (``BolusOperator.progress``
prints one every 2 s in background runs) -- a run longer than a few seconds must show progress.
A child that does not return within ``--timeout`` (default 150 s) is killed: "did not finish".
Target: every operator finishes or refuses within ``TARGET_S`` = 60 s.
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import benchutil
from benchutil import data_mesh, Table

SEED = 14
PIECES, FRAGMENTS = 17, 3
TARGET_FACES = 520_000
GAP_MM = (0.8, 2.0)  # scan-gap band width, drawn per plane
NOISE_MM = (0.05, 0.2)  # noise sigma along the normals, drawn per piece
TARGET_S = 60.0
TIMEOUT_S = 150.0
NOSE_RADIUS_MM = 45.0
NOSE_PATCHES, PRINT_PARTS = 4, 3
WHOLE_OPS = ("saliency_preview", "segment", "smooth_cuts", "improve_flattenability", "unfold", "export_pattern",
             "make_shell", "print_segment", "orient_parts", "export_parts")
NOSE_OPS = ("select_area",) + WHOLE_OPS
SCENARIOS = ("whole", "nose", "nose_decimated")
#: the Decimate ratio of the nose_decimated scenario (what the refusals advise on the nose area)
DECIMATE_RATIO = 0.25
SECTION = "## Range scan: 17 pieces, about 520k faces (`bench/rangescan_bench.py`)"
#: --head1m: the whole bust (one closed piece, 1.12M faces) through every operator, its own section
SECTION_HEAD = "## A whole 1.12M-face head through every operator (`bench/rangescan_bench.py --head1m`)"
PROGRESS_RE = re.compile(r"^bolus\.\w+:.* \d+ %$")


# ----------------------------------------------------------------------------- the scan


def _adjacency(F, n):
    """(k,2) pairs of triangles of F sharing an edge (n vertices)."""
    import numpy as np

    m = len(F)
    he = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    key = np.minimum(he[:, 0], he[:, 1]) * np.int64(n) + np.maximum(he[:, 0], he[:, 1])
    face = np.tile(np.arange(m), 3)
    order = np.argsort(key)
    k, f = key[order], face[order]
    same = np.nonzero(k[1:] == k[:-1])[0]
    return np.stack([f[same], f[same + 1]], axis=1)


def _components(F, n, pairs=None, alive=None):
    """Edge-connected components of the triangles F (those ``alive``) -> (count, (m,) labels, -1 not alive)."""
    import numpy as np
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    m = len(F)
    P = _adjacency(F, n) if pairs is None else pairs
    alive = np.ones(m, dtype=bool) if alive is None else alive
    P = P[alive[P[:, 0]] & alive[P[:, 1]]]
    G = sp.coo_matrix((np.ones(len(P)), (P[:, 0], P[:, 1])), shape=(m, m))
    _, lab = connected_components(G, directed=False)
    _, lab = np.unique(np.where(alive, lab, -1), return_inverse=True)
    lab = lab - (0 if alive.all() else 1)
    return int(lab.max()) + 1, np.where(alive, lab, -1)


def _without_bowties(F, alive, n):
    """alive with the faces around non-manifold vertices dropped (a vertex where two fans of
    the surface meet, which a gap cut across a thin spot leaves), until there are none: a range
    scan's pieces are cleaned of them before anything else (segment refuses them)."""
    import numpy as np

    alive = alive.copy()
    while True:
        Fa = F[alive]
        he = np.concatenate([Fa[:, [0, 1]], Fa[:, [1, 2]], Fa[:, [2, 0]]])
        key = np.minimum(he[:, 0], he[:, 1]) * np.int64(n) + np.maximum(he[:, 0], he[:, 1])
        uniq, count = np.unique(key, return_counts=True)
        border = uniq[count == 1]
        ends = np.concatenate([border // n, border % n])
        bad = np.nonzero(np.bincount(ends, minlength=n) > 2)[0]
        if len(bad) == 0:
            return alive
        hit = np.isin(F, bad).any(axis=1)
        alive &= ~hit


def _compact(V, F):
    import numpy as np

    used = np.unique(F)
    remap = np.full(len(V), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return V[used], remap[F]


def _vertex_normals(V, F):
    import numpy as np

    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    N = np.zeros_like(V)
    for k in range(3):
        np.add.at(N, F[:, k], fn)
    return N / np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-12)


def range_scan(seed: int = SEED, target_faces: int = TARGET_FACES, pieces: int = PIECES,
               fragments: int = FRAGMENTS, subdivisions: int = 2):
    """The synthetic range scan -> (V (n,3) mm, F (m,3) int64, info dict); see the module docstring.

    Deterministic for a seed.  target_faces scales with the subdivision (quick: 1 subdivision,
    target / 4)."""
    import numpy as np

    from bolus_addon.core.mesh.objfile import load_obj
    from unfold_bench import midpoint_subdivide, submesh

    rng = np.random.default_rng(seed)
    V, F, _ = load_obj(data_mesh("nefertiti.obj"), 1.0)
    for _ in range(subdivisions):
        V, F = midpoint_subdivide(V, F)
    # the front as the scanner sees it: a little more than the target, the gaps take the rest
    C = V[F].mean(axis=1)
    keep_n = int(target_faces * 1.04)
    z0 = float(np.partition(-C[:, 2], keep_n - 1)[keep_n - 1]) * -1.0
    V, F = submesh(V, F, C[:, 2] >= z0)
    main = pieces - fragments
    pairs = _adjacency(F, len(V))
    alive = np.ones(len(F), dtype=bool)
    alive = _without_bowties(F, alive, len(V))
    ncomp, _ = _components(F, len(V), pairs, alive)
    planes, tries = [], 0
    while ncomp != main:
        tries += 1
        if tries > 400:
            raise RuntimeError(f"no set of scan gaps gives {main} pieces (stuck at {ncomp})")
        p = V[F[rng.choice(np.nonzero(alive)[0])]].mean(axis=0)
        nrm = rng.normal(size=3)
        nrm[2] *= 0.3  # scan lines run across the view more than along it
        nrm /= np.linalg.norm(nrm)
        w = float(rng.uniform(*GAP_MM))
        d = (V - p) @ nrm
        dF = d[F]
        cut = (np.abs(dF) < w / 2).any(axis=1) | (np.sign(dF).min(axis=1) != np.sign(dF).max(axis=1))
        alive2 = _without_bowties(F, alive & ~cut, len(V))
        n2, _ = _components(F, len(V), pairs, alive2)
        if n2 > main:
            continue
        alive, ncomp = alive2, n2
        planes.append({"point": [float(x) for x in p], "normal": [float(x) for x in nrm], "width_mm": w})
    F = F[alive]
    V, F = _compact(V, F)
    N = _vertex_normals(V, F)
    # tiny floating fragments: small discs of the surface, lifted off it
    fragV, fragF = [V], [F]
    off = len(V)
    frag_sizes = []
    for _ in range(fragments):
        c = V[F[rng.integers(len(F))]].mean(axis=0)
        r = float(rng.uniform(1.5, 3.0))
        sel = (np.linalg.norm(V[F] - c, axis=2) < r).all(axis=1)
        Vs, Fs = submesh(V, F, sel)
        Vs, Fs = submesh(Vs, Fs, _without_bowties(Fs, np.ones(len(Fs), dtype=bool), len(Vs)))
        k, cc = _components(Fs, len(Vs))
        big = np.argmax(np.bincount(cc))
        Vs, Fs = submesh(Vs, Fs, cc == big)
        lift = float(rng.uniform(2.0, 4.0))
        up = _vertex_normals(Vs, Fs).mean(axis=0)
        Vs = Vs + lift * up / max(np.linalg.norm(up), 1e-12)
        fragV.append(Vs)
        fragF.append(Fs + off)
        off += len(Vs)
        frag_sizes.append(len(Fs))
    V, F = np.vstack(fragV), np.vstack(fragF)
    N = _vertex_normals(V, F)
    ncomp, comp = _components(F, len(V))
    vcomp = np.zeros(len(V), dtype=np.int64)
    vcomp[F.ravel()] = np.repeat(comp, 3)
    sigma = rng.uniform(*NOISE_MM, size=ncomp)
    V = V + N * (rng.normal(size=len(V)) * sigma[vcomp])[:, None]
    ncomp, comp = _components(F, len(V))
    sizes = np.sort(np.bincount(comp))[::-1]
    info = {"faces": int(len(F)), "vertices": int(len(V)), "pieces": int(ncomp),
            "piece_faces": [int(s) for s in sizes], "gap_planes": len(planes), "plane_tries": tries,
            "fragments": frag_sizes, "seed": seed, "subdivisions": subdivisions,
            "how": f"nefertiti x{4 ** subdivisions}, front z >= {z0:.1f} mm, {len(planes)} scan gaps, "
                   f"{fragments} fragments, noise sigma {NOISE_MM[0]:g}-{NOISE_MM[1]:g} mm"}
    if ncomp != pieces:
        raise RuntimeError(f"the scan has {ncomp} pieces, not {pieces}")
    return np.ascontiguousarray(V, dtype=np.float64), np.ascontiguousarray(F, dtype=np.int64), info


def cached_scan(subdivisions: int, target_faces: int) -> tuple[Path, dict]:
    """The scan as an .npz (V, F) and its info, built once into a cache folder in the temp dir
    (``BOLUS_RANGESCAN_CACHE`` overrides it): building it takes 20-50 s."""
    import numpy as np

    cache = Path(os.environ.get("BOLUS_RANGESCAN_CACHE", Path(tempfile.gettempdir()) / "bolus_rangescan"))
    cache.mkdir(parents=True, exist_ok=True)
    stem = f"scan_s{SEED}_d{subdivisions}_f{target_faces}_p{PIECES}"
    path, meta = cache / (stem + ".npz"), cache / (stem + ".json")
    if path.exists() and meta.exists():
        return path, json.loads(meta.read_text())
    V, F, info = range_scan(subdivisions=subdivisions, target_faces=target_faces)
    np.savez(path, V=V, F=F)
    meta.write_text(json.dumps(info))
    return path, info


def cached_head(subdivisions: int = 2) -> tuple[Path, dict]:
    """nefertiti.obj subdivided ``subdivisions`` times, whole (closed, one piece: 1.12M faces at 2) as an
    .npz (V, F) in the scan's cache folder, and its info."""
    import numpy as np

    from bolus_addon.core.mesh.objfile import load_obj
    from unfold_bench import midpoint_subdivide

    cache = Path(os.environ.get("BOLUS_RANGESCAN_CACHE", Path(tempfile.gettempdir()) / "bolus_rangescan"))
    cache.mkdir(parents=True, exist_ok=True)
    path = cache / f"head_d{subdivisions}.npz"
    if not path.exists():
        V, F, _ = load_obj(data_mesh("nefertiti.obj"), 1.0)
        for _ in range(subdivisions):
            V, F = midpoint_subdivide(V, F)
        np.savez(path, V=V, F=F)
    d = np.load(path)
    info = {"faces": int(len(d["F"])), "vertices": int(len(d["V"])), "pieces": 1, "piece_faces": [int(len(d["F"]))],
            "how": f"nefertiti.obj subdivided {subdivisions}x at the edge midpoints, whole (closed)", "seed": None}
    return path, info


def face_bands(V, F, k: int = 3):
    """(m,) int labels: k bands across x (the width of the bust), cutting every piece they cross."""
    import numpy as np

    cx = V[F].mean(axis=1)[:, 0]
    return np.digitize(cx, np.quantile(cx, np.arange(1, k) / k)).astype(np.int64)


# ----------------------------------------------------------------------------- the child (bpy)


def _mm_scene(bpy):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if not hasattr(bpy.types.Scene, "bolus"):
        import bolus_addon

        bolus_addon.register()
    sc = bpy.context.scene
    sc.unit_settings.system = "METRIC"
    sc.unit_settings.scale_length = 0.001
    sc.unit_settings.length_unit = "MILLIMETERS"
    return sc


def _load_scan(bpy, path):
    import numpy as np

    from bolus_addon.blender import mesh_io

    d = np.load(path)
    V, F = d["V"], d["F"]
    _mm_scene(bpy)
    me = mesh_io.new_mesh("scan", V, F.reshape(-1), np.arange(0, 3 * len(F), 3))
    ob = bpy.data.objects.new("scan", me)
    bpy.context.scene.collection.objects.link(ob)
    bpy.context.view_layer.objects.active = ob
    ob.select_set(True)
    return ob, V, F


def _write_labels(ob, name, labels):
    from bolus_addon.blender import mesh_io

    mesh_io.write_attribute(ob.data, name, "INT", "FACE", labels)
    ob.data.update()


def _call(bpy, op: str, **kw):
    """Run bpy.ops.bolus.<op>(**kw) -> (status, seconds, message)."""
    fn = getattr(bpy.ops.bolus, op)
    print(f"@@START {op}", flush=True)
    t0 = time.perf_counter()
    try:
        res = fn(**kw)
        status, msg = ("finished" if res == {"FINISHED"} else "/".join(sorted(res)).lower()), ""
    except RuntimeError as exc:
        status, msg = "refused", str(exc).strip()
    dt = time.perf_counter() - t0
    print(f"@@END {op}", flush=True)
    return status, dt, msg


def _fingerprint(ob) -> str:
    """sha256 of the source's geometry: coordinates and face corners (the promise: "the source's data
    unchanged"; preview and segment add attributes by design, no operator may move or re-wire it)."""
    import hashlib

    import numpy as np

    me = ob.data
    co = np.empty(3 * len(me.vertices), dtype=np.float32)
    me.vertices.foreach_get("co", co)
    loops = np.empty(len(me.loops), dtype=np.int32)
    me.loops.foreach_get("vertex_index", loops)
    return hashlib.sha256(co.tobytes() + loops.tobytes()).hexdigest()


def _emit(row: dict) -> None:
    print("RESULT " + json.dumps(row), flush=True)


def worker(scenario: str, op: str, path: str, outdir: str) -> None:
    """One child: the scan loaded, the setup (untimed), the operator(s) timed; RESULT lines on stdout."""
    import bpy
    import numpy as np

    ob, V, F = _load_scan(bpy, path)
    if scenario == "whole":
        t0 = time.perf_counter()
        if op in ("smooth_cuts", "unfold"):
            _write_labels(ob, "bolus_patch", face_bands(V, F))
        if op in ("orient_parts", "export_parts"):
            _write_labels(ob, "bolus_print_part", face_bands(V, F))
        if op == "export_parts":
            st, dt, msg = _call(bpy, "orient_parts")
            if st != "finished":
                _emit({"op": op, "status": "setup failed", "seconds": 0.0,
                       "message": f"orient_parts (setup) {st} after {dt:.1f} s: {msg}"})
                return
        setup = time.perf_counter() - t0
        kw = {}
        if op == "export_pattern":
            kw = {"filepath": os.path.join(outdir, "scan_pattern.svg")}
        elif op == "export_parts":
            kw = {"directory": outdir}
        before = _fingerprint(ob)
        st, dt, msg = _call(bpy, op, **kw)
        same = _fingerprint(bpy.data.objects["scan"]) == before
        _emit({"op": op, "status": st, "seconds": dt, "message": msg, "setup_s": setup,
               "source": "unchanged" if same else "CHANGED", "unexpected": "Unexpected error" in msg})
        return
    # nose: the treatment area, then the chain on it (nose_decimated: the scan decimated first, as the
    # refusals advise)
    if scenario == "nose_decimated":
        mod = ob.modifiers.new("Decimate", "DECIMATE")
        mod.ratio = DECIMATE_RATIO
        print("@@START decimate", flush=True)
        t0 = time.perf_counter()
        bpy.ops.object.modifier_apply(modifier=mod.name)
        dt = time.perf_counter() - t0
        print("@@END decimate", flush=True)
        _emit({"op": "decimate", "status": "finished", "seconds": dt, "message": "",
               "faces": len(ob.data.polygons)})
        co = np.empty(3 * len(ob.data.vertices))
        ob.data.vertices.foreach_get("co", co)
        V = co.reshape(-1, 3)
    co = V
    tip = co[int(np.argmax(co[:, 2]))]
    bpy.context.scene.cursor.location = tuple(float(x) for x in tip)
    steps = [("select_area", {"radius_mm": NOSE_RADIUS_MM}), ("saliency_preview", {}),
             ("segment", {"patches": NOSE_PATCHES}), ("smooth_cuts", {}), ("improve_flattenability", {}),
             ("unfold", {}), ("export_pattern", {"filepath": os.path.join(outdir, "nose_pattern.svg")}),
             ("make_shell", {}), ("print_segment", {"parts": PRINT_PARTS}), ("orient_parts", {}),
             ("export_parts", {"directory": outdir})]
    wanted = set(op.split(","))
    for name, kw in steps:
        if name in ("print_segment", "orient_parts", "export_parts"):
            bolus = bpy.data.objects.get("scan_bolus")
            if bolus is not None:  # the printed bolus: print parts of the solid
                if bpy.context.object is not None and bpy.context.object.mode != "OBJECT":
                    bpy.ops.object.mode_set(mode="OBJECT")
                bpy.context.view_layer.objects.active = bolus
        else:
            bpy.context.view_layer.objects.active = ob
            if ob.mode != "EDIT" and name != "select_area":
                bpy.ops.object.mode_set(mode="EDIT")  # the area stays selected
        if name == "export_pattern":
            pat = bpy.data.objects.get("scan_pattern")
            if pat is not None:
                if bpy.context.object is not None and bpy.context.object.mode != "OBJECT":
                    bpy.ops.object.mode_set(mode="OBJECT")
                bpy.context.view_layer.objects.active = pat
        st, dt, msg = _call(bpy, name, **kw)
        if name in wanted or "all" in wanted:
            sel = None
            if name == "select_area":
                ob.update_from_editmode()
                sel = int(sum(p.select for p in ob.data.polygons))
            _emit({"op": name, "status": st, "seconds": dt, "message": msg, "selected": sel})


# ----------------------------------------------------------------------------- the parent


def run_child(scenario: str, op: str, path: Path, outdir: Path, timeout: float, verbose: bool) -> list[dict]:
    """Run one child; its RESULT rows with the longest progress silence of each operator added."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", scenario, op, str(path), str(outdir)]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1)
    rows, lines = [], []
    state = {"op": None, "last": None, "gap": 0.0, "n": 0}
    gaps = {}

    def reader():
        for line in p.stdout:
            now = time.monotonic()
            line = line.rstrip("\n")
            lines.append(line)
            if verbose:
                print("   | " + line, flush=True)
            if line.startswith("@@START "):
                state.update(op=line[8:], last=now, gap=0.0, n=0)
            elif line.startswith("@@END ") and state["op"]:
                gaps[state["op"]] = (max(state["gap"], now - state["last"]), state["n"])
                state["op"] = None
            elif state["op"] and PROGRESS_RE.match(line.strip()):
                state["gap"] = max(state["gap"], now - state["last"])
                state["last"] = now
                state["n"] += 1
            elif line.startswith("RESULT "):
                rows.append(json.loads(line[7:]))

    th = threading.Thread(target=reader, daemon=True)
    th.start()
    try:
        p.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        p.kill()
        p.wait()
        th.join(5)
        running = state["op"] or op
        rows.append({"op": running, "status": "did not finish", "seconds": timeout,
                     "message": f"killed after {timeout:.0f} s (child total)",
                     "progress_lines": state["n"],
                     "silence_s": time.monotonic() - state["last"] if state["last"] else None})
        return rows
    th.join(5)
    for r in rows:
        g = gaps.get(r["op"])
        if g:
            r["silence_s"], r["progress_lines"] = g
    if p.returncode != 0 and not rows:
        rows.append({"op": op, "status": "crashed", "seconds": 0.0,
                     "message": (lines[-1] if lines else f"exit code {p.returncode}")[:300]})
    return rows


def verdict(r: dict) -> str:
    if r["status"] in ("finished", "refused"):
        return "yes" if r["seconds"] <= TARGET_S else "NO"
    return "NO"


def short(msg: str, n: int = 260) -> str:
    msg = " ".join(msg.replace("Error: ", "").split())
    return msg if len(msg) <= n else msg[: n - 3] + "..."


def tables(results: dict) -> tuple[str, str]:
    t = Table([("scenario", "<"), ("operator", "<"), ("s", ">"), ("result", "<"), ("within 60 s", "<"),
               ("source", "<"), ("progress lines / longest silence s", ">"), ("message (refusals)", "<")])
    for scen, rows in results.items():
        for r in rows:
            sil = r.get("silence_s")
            prog = f"{r.get('progress_lines', 0)} / {sil:.1f}" if sil is not None else "n/a"
            status = r["status"] + (" (UNEXPECTED ERROR)" if r.get("unexpected") else "")
            t.add(scen, r["op"], f"{r['seconds']:.1f}", status, verdict(r), r.get("source", "-"), prog,
                  short(r.get("message", "")) if r["status"] != "finished" else "")
    return t.text("   "), t.markdown()


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--worker"]:
        worker(*argv[1:5])
        return 0
    ap = benchutil.parser(__doc__, "the scan at 1/4 size (one subdivision, about 130k faces)", repeat=None)
    ap.add_argument("--ops", nargs="+", default=list(WHOLE_OPS), help="operators (default: all)")
    ap.add_argument("--scenarios", nargs="+", default=list(SCENARIOS), choices=SCENARIOS)
    ap.add_argument("--timeout", type=float, default=TIMEOUT_S, help="kill a child after this many seconds")
    ap.add_argument("--verbose", action="store_true", help="show the children's output")
    ap.add_argument("--keep", metavar="DIR", help="write the scan (.npz) and the outputs to DIR")
    ap.add_argument("--head1m", action="store_true",
                    help="instead of the scan: the whole bust subdivided to 1.12M faces (one closed piece), "
                         "scenario whole only (the 1M-face case)")
    args = ap.parse_args(argv)
    section = SECTION_HEAD if args.head1m else SECTION
    if args.head1m:
        args.scenarios = ["whole"]
    import numpy as np

    t_all = time.perf_counter()
    tmp = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="rangescan_"))
    tmp.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    sub = 1 if args.quick else 2
    path, info = cached_head(sub) if args.head1m else cached_scan(sub, TARGET_FACES // (4 if args.quick else 1))
    info["build_s"] = time.perf_counter() - t0
    print(f"scan: {info['faces']} faces, {info['vertices']} vertices, {info['pieces']} pieces "
          f"(largest {info['piece_faces'][:3]}, smallest {info['piece_faces'][-3:]}); {info['how']}; "
          f"built in {info['build_s']:.1f} s")
    results = {}
    for scen in args.scenarios:
        rows = []
        if scen == "whole":
            for op in [o for o in WHOLE_OPS if o in args.ops]:
                print(f"{scen}: {op} ...", flush=True)
                rows += run_child(scen, op, path, tmp, args.timeout, args.verbose)
                r = rows[-1]
                print(f"   {r['op']}: {r['status']} in {r['seconds']:.1f} s {short(r.get('message', ''), 200)}",
                      flush=True)
        else:
            ops = ",".join(o for o in NOSE_OPS if o in args.ops or o == "select_area")
            print(f"{scen}: {ops} ...", flush=True)
            rows = run_child(scen, "all" if ops == ",".join(NOSE_OPS) else ops, path, tmp, args.timeout * 4,
                             args.verbose)
            for r in rows:
                print(f"   {r['op']}: {r['status']} in {r['seconds']:.1f} s {short(r.get('message', ''), 200)}")
        results[scen] = rows
    text, md = tables(results)
    print(text)
    total = time.perf_counter() - t_all
    payload = {"scan": info, "results": results, "target_s": TARGET_S}
    if args.markdown:
        if args.head1m:
            what = (f"The mesh: {info['faces']:,} triangles, {info['vertices']:,} vertices, {info['how']}; each "
                    f"operator in a fresh process, the whole mesh, nothing selected (the scan's `whole` scenario).")
        else:
            what = (f"The scan: {info['faces']:,} triangles, {info['vertices']:,} vertices, {info['pieces']} "
                    f"edge-connected pieces (faces per piece: {', '.join(map(str, info['piece_faces']))}); "
                    f"{info['how']} (seed {info['seed']}). Each operator of `whole` in a fresh process; `nose` is "
                    f"one process running the chain on the treatment area.")
        body = (f"{section}\n\n{benchutil.run_line('rangescan_bench.py', argv)}\n\n{what} Target: each finishes "
                f"or refuses within {TARGET_S:.0f} s.\n\n{md}\n\n_Whole script: {total:.0f} s._\n")
        benchutil.replace_section(args.markdown, section, body)
    print(f"total bench time {total:.1f} s")
    if args.json:
        benchutil.write_json(args.json, {**payload, "total_s": total})
    return 0


if __name__ == "__main__":
    sys.exit(main())
