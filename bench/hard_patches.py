"""The hard patches for darts and splits (noses with nostrils, a nostril pocket, a finger tip, a clean nose in 3).

Not part of the add-on: `bench/unfold_bench.py` benches them ("Hard patches: darts and
splits") and other helpers test against the saved copies.  Run from the repository root:

    .venv/bin/python bench/hard_patches.py --write /tmp/h12_patches          # .npz + README.txt (SLIM timed)
    .venv/bin/python bench/hard_patches.py --write /tmp/h12_patches --no-slim

Every patch is made by the add-on's own core, the way a user gets it in Blender:

* nose regions: ``treatment_area(V, F, tip, NOSE_RADIUS_MM, exclude_cavities=False)`` (the
  geodesic disk of ``bolus.select_area`` around the nose tip, nostrils kept), then
  ``spectral.segment(V, F, 3, eta=5, smoothing_mm=3, rng=0, method="kmeans")`` (the segment
  operator's defaults) and every patch saved, on four heads nobody here tuned for:
  nefertiti.obj (mm), demosthenes.obj (normalised: scaled by DEMOSTHENES_MM_PER_UNIT = 145 so
  that its eyes are 63 mm apart (0.44 units) and its nose tip about 50 mm below them: a real
  head), ict_face_narrow.obj (cm -> mm) and makehuman_face_patch.obj (dm -> mm).  The nose tip
  is the frontmost vertex (largest z) of each (checked on pictures of the disks);
* ``nostril pocket``: the faces of the ICT nose disk (radius 40 mm) that
  ``treatment_area(..., exclude_cavities=True)`` leaves out as cavity (openness < 0.2), the
  largest connected piece with a ring of POCKET_RIM_MM of the surrounding skin: a deep pocket
  with its rim;
* ``finger tip``: the geodesic disk of FINGER_RADIUS_MM around the outermost vertex (largest
  x) of makehuman_body.obj (dm -> mm; A-pose: the tip of the left hand's longest finger), one
  patch: a closed-ended tube, like a thimble;
* ``clean nose``: the ICT nose region as `unfold_bench` has always cut it (the whole OBJ
  polygons within 30 mm of the tip, connected to it) segmented into 3 the same way.

Every array is in mm; V float64, F int64; faces keep their winding.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import benchutil  # noqa: F401  (sys.path: repository root, tests/)
from benchutil import data_mesh

NOSE_RADIUS_MM = 45.0
CLEAN_NOSE_RADIUS_MM = 30.0
POCKET_RIM_MM = 4.0
FINGER_RADIUS_MM = 25.0
DEMOSTHENES_MM_PER_UNIT = 145.0  # eyes 0.44 units apart (63 mm), nose tip 0.34 below them (about 50 mm)
SEG_PATCHES = 3
SEG_ETA = 5.0
SEG_RNG = 0

#: (short name, file, mm per file unit, how the nose tip is found)
HEADS = (
    ("nefertiti", "nefertiti.obj", 1.0, "largest z"),
    ("demosthenes", "demosthenes.obj", DEMOSTHENES_MM_PER_UNIT, "largest z"),
    ("ict", "ict_face_narrow.obj", 10.0, "largest z"),
    ("makehuman", "makehuman_face_patch.obj", 100.0, "largest z"),
)


def load(fname: str, scale: float):
    from bolus_addon.core.mesh.objfile import load_obj

    path = data_mesh(fname)
    return load_obj(path, scale)


def nose_tip(V) -> int:
    """The frontmost vertex (largest z) of a head looking along +z."""
    import numpy as np

    return int(np.argmax(V[:, 2]))


def disk(V, F, centre, radius_mm: float, exclude_cavities: bool = False):
    """(V', F', area): the geodesic disk of `treatment_area` around centre, renumbered."""
    from bolus_addon.core.mesh.topology import submesh
    from bolus_addon.core.cuts.treatment_area import treatment_area

    area = treatment_area(V, F, centre, radius_mm, exclude_cavities=exclude_cavities)
    Fs, ids = submesh(area.F, area.selected)
    return area.V[ids], Fs, area


def segment3(V, F):
    """Face labels of the segment operator's core at its defaults (3 patches)."""
    from bolus_addon.core.analysis import spectral
    from bolus_addon.core.analysis.saliency import DEFAULT_SMOOTHING_MM

    return spectral.segment(V, F, SEG_PATCHES, eta=SEG_ETA, smoothing_mm=DEFAULT_SMOOTHING_MM, rng=SEG_RNG,
                            method="kmeans").face_labels


def split_patches(V, F, labels, name: str, how: str) -> list[dict]:
    import numpy as np

    from bolus_addon.core.mesh.topology import submesh

    out = []
    for p in np.unique(labels):
        Fs, ids = submesh(F, labels == p)
        out.append({"name": f"{name} p{int(p)}", "V": V[ids], "F": Fs, "how": f"{how}; patch {int(p)} of "
                    f"{len(np.unique(labels))}"})
    return out


def nose_patches(short: str, fname: str, scale: float, tip_rule: str) -> list[dict]:
    from bolus_addon.core.analysis.saliency import DEFAULT_SMOOTHING_MM

    V, F, _ = load(fname, scale)
    tip = nose_tip(V)
    Vn, Fn, _ = disk(V, F, V[tip], NOSE_RADIUS_MM)
    how = (f"{fname} x{scale:g} -> mm, nose tip = vertex {tip} ({tip_rule}); treatment_area(radius "
           f"{NOSE_RADIUS_MM:g} mm, exclude_cavities=False): {len(Fn)} tri; spectral.segment(3, eta={SEG_ETA:g}, "
           f"smoothing_mm={DEFAULT_SMOOTHING_MM:g}, rng={SEG_RNG}, kmeans)")
    return split_patches(Vn, Fn, segment3(Vn, Fn), f"{short} nose", how)


def nostril_pocket() -> list[dict]:
    import numpy as np

    from bolus_addon.core.mesh.topology import MeshTopology, submesh

    V, F, _ = load("ict_face_narrow.obj", 10.0)
    tip = nose_tip(V)
    Vd, Fd, area_d = disk(V, F, V[tip], NOSE_RADIUS_MM)
    # the same disk with the cavities left out: its cavity faces are the nostril pockets
    _, _, area = disk(V, F, V[tip], NOSE_RADIUS_MM, exclude_cavities=True)
    cav = np.nonzero(area.cavity)[0]
    topo_c = MeshTopology(area.V, area.F[cav])
    _, comp = topo_c.face_components()
    big = int(np.argmax(np.bincount(comp, weights=topo_c.areas)))
    # the pocket in the disk without exclusion: its faces lying in the input triangles of the largest cavity
    inside = np.isin(area_d.parent[area_d.selected], area.parent[cav[comp == big]])
    # a rim: the faces whose corners are within POCKET_RIM_MM (shortest edge path) of the pocket's vertices
    import scipy.sparse as sp
    from scipy.sparse.csgraph import dijkstra

    e = np.concatenate([Fd[:, [0, 1]], Fd[:, [1, 2]], Fd[:, [2, 0]]])
    w = np.linalg.norm(Vd[e[:, 0]] - Vd[e[:, 1]], axis=1)
    G = sp.coo_matrix((w, (e[:, 0], e[:, 1])), shape=(len(Vd),) * 2).tocsr()
    dv = dijkstra(G, directed=False, indices=np.unique(Fd[inside]), min_only=True)
    sel = (dv[Fd] <= POCKET_RIM_MM).all(axis=1) | inside
    Fs, ids = submesh(Fd, sel)
    Vs = Vd[ids]
    _, comp2 = MeshTopology(Vs, Fs).face_components()
    keep = comp2 == np.bincount(comp2, weights=MeshTopology(Vs, Fs).areas).argmax()
    Fs, ids2 = submesh(Fs, keep)
    Vs = Vs[ids2]
    how = (f"ict_face_narrow.obj x10 -> mm; treatment_area(radius {NOSE_RADIUS_MM:g} mm): the largest piece "
           f"of its cavity faces (exclude_cavities=True, openness < 0.2) in the disk without exclusion, with a "
           f"{POCKET_RIM_MM:g} mm rim (edge-path distance) of the skin around it: {len(Fs)} tri")
    return [{"name": "nostril pocket", "V": Vs, "F": Fs, "how": how}]


def finger_tip() -> list[dict]:
    import numpy as np

    V, F, _ = load("makehuman_body.obj", 100.0)
    tip = int(np.argmax(V[:, 0]))
    Vf, Ff, _ = disk(V, F, V[tip], FINGER_RADIUS_MM)
    how = (f"makehuman_body.obj x100 -> mm; treatment_area(radius {FINGER_RADIUS_MM:g} mm, exclude_cavities="
           f"False) around the outermost vertex {tip} (largest x: the left hand's longest finger tip); one patch, "
           f"{len(Ff)} tri")
    return [{"name": "finger tip", "V": Vf, "F": Ff, "how": how}]


def clean_nose() -> list[dict]:
    """The ICT nose region exactly as unfold_bench has cut it (whole polygons within 30 mm), segmented into 3."""
    import numpy as np

    from bolus_addon.core.mesh.topology import MeshTopology, submesh

    V, F, tri_face = load("ict_face_narrow.obj", 10.0)
    tip = int(np.argmax(V[:, 2]))
    d = np.linalg.norm(V - V[tip], axis=1)
    tri_in = (d[F] <= CLEAN_NOSE_RADIUS_MM).all(axis=1)
    poly_in = np.ones(int(tri_face.max()) + 1, dtype=bool)
    np.logical_and.at(poly_in, tri_face, tri_in)
    Fn, ids = submesh(F, poly_in[tri_face])
    Vn = V[ids]
    _, comp = MeshTopology(Vn, Fn).face_components()
    t = int(np.argmin(np.linalg.norm(Vn - V[tip], axis=1)))
    Fn2, ids2 = submesh(Fn, comp == comp[np.nonzero((Fn == t).any(axis=1))[0][0]])
    Vn = Vn[ids2]
    how = (f"ict_face_narrow.obj x10 -> mm, whole OBJ polygons within {CLEAN_NOSE_RADIUS_MM:g} mm (3D) of the tip "
           f"(largest z), connected: {len(Fn2)} tri (unfold_bench's 'nose'); spectral.segment(3) as above")
    return split_patches(Vn, Fn2, segment3(Vn, Fn2), "clean nose", how)


def make_hard_patches(only=None, log=print) -> list[dict]:
    """Every hard patch: dicts {name, V (n,3) mm, F (m,3), how}; a group that fails gives {name, error}."""
    groups = [(f"{h[0]} nose", lambda h=h: nose_patches(*h)) for h in HEADS]
    groups += [("nostril pocket", nostril_pocket), ("finger tip", finger_tip), ("clean nose", clean_nose)]
    out = []
    for gname, make in groups:
        if only and not any(o in gname or gname in o for o in only):
            continue
        t0 = time.perf_counter()
        try:
            ps = make()
        except Exception as exc:  # a benchmark reports and goes on
            log(f"  {gname}: SKIPPED: {type(exc).__name__}: {exc}")
            out.append({"name": gname, "error": f"{type(exc).__name__}: {exc}"})
            continue
        log(f"  {gname}: {len(ps)} patch(es) of {', '.join(str(len(p['F'])) for p in ps)} tri "
            f"({time.perf_counter() - t0:.1f} s)")
        out += ps
    return out


def save(patches: list[dict], folder) -> list[Path]:
    import numpy as np

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for p in patches:
        if "error" in p:
            continue
        path = folder / (p["name"].replace(" ", "_") + ".npz")
        np.savez(path, V=np.asarray(p["V"], dtype=np.float64), F=np.asarray(p["F"], dtype=np.int64),
                 name=p["name"], how=p["how"])
        paths.append(path)
    return paths


def load_saved(folder) -> list[dict]:
    """The patches saved by `save` (sorted by name)."""
    import numpy as np

    out = []
    for path in sorted(Path(folder).glob("*.npz")):
        with np.load(path) as z:
            out.append({"name": str(z["name"]), "V": z["V"], "F": z["F"], "how": str(z["how"])})
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="Make the hard patches for darts and splits and save them as .npz.")
    ap.add_argument("--write", metavar="DIR", required=True)
    ap.add_argument("--no-slim", dest="slim", action="store_false", help="do not time Blender's SLIM on them")
    ap.add_argument("--only", action="append", default=[])
    args = ap.parse_args(argv)
    patches = make_hard_patches(args.only)
    paths = save(patches, args.write)
    print(f"{len(paths)} patches written to {args.write}")
    rows = []
    if args.slim:
        import unfold_bench

        rows = unfold_bench.slim_rows(patches)
    ours = {p["name"]: unfold_once(p) for p in patches if "error" not in p}
    readme(Path(args.write) / "README.txt", patches, rows, ours)
    return 0


def unfold_once(p: dict) -> dict:
    """Ours without refinement (`unfold_patch(V, F)`, one run): EL, EA, f/o, seconds, hopeless, angle sums."""
    import numpy as np

    from bolus_addon.core.unfold.unfold import unfold_patch

    t0 = time.perf_counter()
    u = unfold_patch(np.asarray(p["V"], dtype=np.float64), np.asarray(p["F"], dtype=np.int64))
    return {"seconds": time.perf_counter() - t0, "EL": u.EL, "EA": u.EA, "flipped": u.flipped,
            "overlaps": u.overlaps, "hopeless": u.hopeless, "deficit": u.angle_deficit, "excess": u.angle_excess}


def readme(path: Path, patches: list[dict], rows: list[dict], ours: dict | None = None) -> None:
    by = {r["patch"]: r for r in rows}
    ours = ours or {}
    lines = [
        "Hard patches for darts and splits (bench/hard_patches.py; every array in mm).",
        "Each .npz: V (n,3) float64 mm, F (m,3) int64, name, how.  Load: bench/hard_patches.load_saved(dir).",
        "SLIM = Blender's uv.unwrap(method='MINIMUM_STRETCH', iterations=10/100, margin=0) on the patch cut to a",
        "disk (cutting.cut_to_disk), measured as unfold_bench does (true-area scale; EL, EA as SPEC; f/o = flipped",
        "/ overlapping triangles; best of 3 runs).",
        "",
        f"{'name':<18} {'faces':>6} {'verts':>6}  {'SLIM-10 s':>9} {'EL %':>6} {'EA %':>6} {'f/o':>5}  "
        f"{'SLIM-100 s':>10} {'EL %':>6} {'EA %':>6} {'f/o':>5}  {'ours s':>6} {'EL %':>6} {'EA %':>6} {'f/o':>5} "
        f"{'H':>1} {'defic':>5} {'exces':>5}",
    ]
    for p in patches:
        if "error" in p:
            lines.append(f"{p['name']:<18} ERROR {p['error']}")
            continue
        cells = []
        for k in ("SLIM-10", "SLIM-100"):
            m = by.get(p["name"], {}).get(k, {})
            if "EL" in m:
                cells.append(f"{m['seconds']:>9.3f} {100 * m['EL']:>6.2f} {100 * m['EA']:>6.2f} "
                             f"{m['flipped']:>2}/{m['overlaps']:<2}")
            else:
                cells.append(f"{'n/a':>9} {'':>6} {'':>6} {'':>5}")
        o = ours.get(p["name"])
        cells.append(f"{o['seconds']:>6.2f} {100 * o['EL']:>6.2f} {100 * o['EA']:>6.2f} {o['flipped']:>2}/"
                     f"{o['overlaps']:<2} {'H' if o['hopeless'] else '-'} {o['deficit']:>5.2f} {o['excess']:>5.2f}"
                     if o else "")
        lines.append(f"{p['name']:<18} {len(p['F']):>6} {len(p['V']):>6}  {cells[0]}  {cells[1]:>10}  {cells[2]}")
    lines += ["", "ours = unfold_patch(V, F) today (one piece, no darts/splits, one run); H = it flags the patch "
              "hopeless; defic / exces = its angle_deficit / angle_excess (rad, summed over interior vertices).",
              "ict nose p1 / p2 are the two nostril pockets of that disk (mirror twins); 'nostril pocket' is the "
              "deepest cavity with a 4 mm rim; demosthenes is a coarse scan (its nose patches have under 150 triangles).",
              "", "How each was made:"]
    lines += [f"  {p['name']}: {p.get('how', p.get('error'))}" for p in patches]
    path.write_text("\n".join(lines) + "\n")
    print(f"README written to {path}")


if __name__ == "__main__":
    sys.exit(main())
