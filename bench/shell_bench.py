"""Benchmark of the printed bolus: `core.shell.make_shell` against Blender's Solidify (printed, not asserted).

Run from the repository root:

    .venv/bin/python bench/shell_bench.py            # three regions, 0.5 and 1.0 mm, parts (about 12 minutes)
    .venv/bin/python bench/shell_bench.py --quick    # the example nose region at 1.0 mm only
    .venv/bin/python bench/shell_bench.py --json out/shell_bench.json
    .venv/bin/python bench/shell_bench.py --markdown docs/benchmarks.md   # append the tables (make bench)

Regions (skin surfaces in mm, face normals pointing away from the body, i.e. the side
the bolus grows on):

* ``example nose``: the demo's treatment area on ``assets/ict_face_narrow.obj`` (cm -> mm):
  ``core.treatment_area.treatment_area(V, F, nose tip, 45 mm)`` (the core of ``bolus.select_area``,
  which the demo calls), nostril cavities left out (holes of the region);
* ``nefertiti face``: ``nefertiti.obj`` (mm), the triangles with every corner within
  ``FACE_RADIUS_MM`` of the nose tip (the vertex of largest z), the edge-connected piece
  holding it, midpoint-subdivided until it has at least ``MIN_FACES`` triangles;
* ``demosthenes face``: ``demosthenes.obj`` (normalised units) scaled so that its head,
  from the chin (y = ``DEMOSTHENES_CHIN_Y``, where the shoulders end) to the crown (the
  largest y), is ``HEAD_MM`` tall; then cropped and subdivided like nefertiti;
* ``chest wall``, ``elbow sleeve``, ``knee sleeve``: the MakeHuman crops of tests/data and
  assets (dm -> mm; the sleeves are tubes, both loops ends); ``breast``, ``ear``: crops of the
  whole MakeHuman body (``BODY_CROPS``), subdivided.

The estimate column is `core.budget`'s estimate of ``make_shell`` (what a refusal is judged by);
every call runs with no time limit.

For every region, each call in a child process of its own (``--worker``: the figures
of one call do not depend on what ran before, and the peak memory is the child's):

* ours: ``make_shell(V, F, thickness=10, resolution=r)`` for r in ``RESOLUTIONS`` (0.5 and 1.0 mm;
  ``--resolution R`` (repeatable) runs R instead), with the marching-cubes mesher and again with
  the previous one, manifold3d's level set (``mesher="level_set"``, rows "ours R mm level set"),
  and at the finest resolution once more with the rim wall as a ruled strip along the smoothed
  border normals and sharp creases (``rim="strip"``, row "ours R mm strip rim");
* the peer: Blender's Solidify modifier on a mesh object of the same region,
  ``solidify_mode='NON_MANIFOLD'`` (complex), ``thickness=10``, ``offset=+1`` (the new
  face on the side the normals point to), ``use_rim=True``, ``use_even_offset=True``,
  with ``nonmanifold_thickness_mode`` 'EVEN' (the issue's "even thickness") and
  'CONSTRAINTS' (Blender's default), evaluated through the depsgraph (only the
  evaluation is timed);
* time (wall clock of the call alone), CPU time (all the child's threads during the call:
  it depends less than the wall clock on what else runs on a shared machine), peak memory
  (the child's VmHWM, reset just before the call, minus its RSS before the call: manifold3d
  allocates in C++, which tracemalloc does not see).

Then, measured here the same way for both (``measure_solid``):

* closed: ``core.solid.closed_report`` (every edge two faces in opposite directions);
  volume in cm³;
* thickness min / mean / max (SPEC): from every skin vertex farther than the thickness
  from the region's border (boundary loops, holes included), a ray along the skin's
  vertex normal (eq. 3-2) to the first surface it meets (Blender's ``BVHTree.ray_cast``,
  up to ``RAY_MAX`` x the thickness): the OUTER face (ours: faces with ``side ==
  SIDE_OUTER``; Solidify: its offset layer) -- the thickness --, or else a rim or hole wall
  (e.g. a nostril's channel), the skin again (a valley the bolus bridges: an eye socket),
  or nothing: those are counted, not measured;
* self-intersecting face pairs: ``BVHTree.overlap`` of the solid with itself, pairs that
  share a vertex (a position: twin vertices count as one) left out (coplanar overlaps are not
  found by it);
* rim smoothness (SPEC): the 95th percentile and the largest of the rim-wall vertices' distances
  from the quadric fitted to their wall neighbours within 2 mm (`rim_residuals`; ours: the
  ``SIDE_RIM`` faces, hole walls included; Solidify: its rim faces); smooth at <= 0.05 mm;
* folded triangles (Solidify only): offset-layer triangles whose normal turned against
  their source face's (n . n_source <= 0; the modifier copies a face attribute holding
  the source face index).

Parts (``core.solid.parts.split_solid``): the
region's shell at ``PARTS_RESOLUTION`` (0.5 mm on the nose, 1.0 mm on the face crops; the
finest one run when that one is not) is split into 3 parts along the ABcut print
segmentation of its skin (``print_segment(skin, 3, rng=0)``) with peg/hole connectors
(clearance 0.2 mm): the time of ``split_solid``, each part closed?, the parts' volumes
against the shell's, and the total support volume (SPEC) of the parts, each in its best
orientation (``print_orientation.orient``), against the whole shell's in its own best
orientation; each part written as a binary STL and read by admesh (where installed): one shell
needing no repair (no degenerate facet, edge fixed, facet removed, added or reversed, or backwards
edge; the stored normals it recomputes are counted apart).

Meshes come from the repository's ``assets/`` and ``tests/data/``.
"""
from __future__ import annotations

import argparse
import gc
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import benchutil
from benchutil import ROOT, data_mesh, Table
from unfold_bench import midpoint_subdivide, region_around, submesh

THICKNESS_MM = 10.0
RESOLUTIONS = {"example nose": (0.5, 1.0), "nefertiti face": (0.5, 1.0), "demosthenes face": (0.5, 1.0),
               "chest wall": (0.5, 1.0), "elbow sleeve": (0.5, 1.0), "breast": (0.5, 1.0), "ear": (0.5, 1.0),
               "knee sleeve": (0.5, 1.0)}
#: the shell each region's parts are cut from (the face crops' 0.5 mm shells have over a million triangles)
PARTS_RESOLUTION = {"example nose": 0.5, "nefertiti face": 1.0, "demosthenes face": 1.0, "chest wall": 1.0,
                    "elbow sleeve": 1.0, "breast": 1.0, "ear": 1.0, "knee sleeve": 1.0}
RESOLUTIONS_QUICK = (1.0,)
NOSE_RADIUS_MM = 45.0  # the demo's treatment area (scripts/demo.py --radius default)
FACE_RADIUS_MM = 100.0
MIN_FACES = 15000
HEAD_MM = 230.0
DEMOSTHENES_CHIN_Y = 0.75  # normalised units: below it the bust widens into the shoulders
PARTS = 3
PARTS_CLEARANCE_MM = 0.2
RAY_MAX = 10.0  # thickness rays reach RAY_MAX * thickness
SKIN_GAP_MM = 0.05  # a thickness ray meets the skin again only this far from its start
BORDER_STEP_MM = 0.25  # border edges are sampled this finely for the distance to the border
WORKER_TIMEOUT_S = 1800
SPOTS = 3  # self-intersections: where the first few are (JSON)
TARGET_S, TARGET_RES_MM = 30.0, 0.5  # the target: a 10 mm shell in under 30 s at 0.5 mm
#: (key, nonmanifold_thickness_mode)
SOLIDIFY_MODES = (("Solidify even", "EVEN"), ("Solidify constraints", "CONSTRAINTS"))
#: ours with each mesher (core.solid.grid.MESHERS): marching cubes, and the previous method,
#: manifold3d's level set ("ours R mm level set"), measured beside it in the same run
MESHERS = ("cubes", "level_set")
#: the resolutions the level-set peer runs at (elsewhere 1.0 mm only: on the chest wall at 0.5 mm it
#: takes about 9 minutes and 5.6 GB)
LEVEL_SET_RESOLUTIONS = {"example nose": (0.5, 1.0)}
REGIONS = ("example nose", "nefertiti face", "demosthenes face", "chest wall", "elbow sleeve", "breast", "ear",
           "knee sleeve")
QUICK_REGIONS = ("example nose",)


# ----------------------------------------------------------------------------- regions


def _subdivide_to(V, F, min_faces: int):
    """Midpoint-subdivide (V, F) until it has at least min_faces triangles -> (V, F, times subdivided)."""
    k = 0
    while len(F) < min_faces:
        V, F = midpoint_subdivide(V, F)
        k += 1
    return V, F, k


def outward(V, F, inside):
    """(F, flipped): the triangles wound so that, area-weighted, their normals point away from
    ``inside`` (3,) (face by face: a sleeve's normals cancel in their sum)."""
    import numpy as np

    from bolus_addon.core.mesh.topology import MeshTopology

    t = MeshTopology(V, F)
    away = t.centroids - inside
    away /= np.maximum(np.linalg.norm(away, axis=1), 1e-12)[:, None]
    if float(np.einsum("ij,ij,i->", t.face_normals, away, t.areas)) >= 0:
        return F, False
    return np.ascontiguousarray(F[:, ::-1]), True


def example_region() -> dict:
    """The example nose region (module doc): V, F (mm) and how it was made."""
    import numpy as np

    from bolus_addon.core.mesh.objfile import load_obj
    from bolus_addon.core.cuts.treatment_area import treatment_area

    V, F, _ = load_obj(ROOT / "assets" / "ict_face_narrow.obj", 10.0)
    tip = V[int(np.argmax(V[:, 2]))]
    area = treatment_area(V, F, tip, NOSE_RADIUS_MM, exclude_cavities=True)
    Vr, Fr = submesh(area.V, area.F, area.selected)
    how = (f"ict_face_narrow.obj x10 (cm -> mm), the demo's area: treatment_area(nose tip (largest z), "
           f"{NOSE_RADIUS_MM:g} mm, exclude_cavities=True) (the core of bolus.select_area): {len(Fr)} triangles, "
           f"{area.holes} holes")
    Fr, flipped = outward(Vr, Fr, V.mean(axis=0))
    return {"name": "example nose", "V": Vr, "F": Fr, "how": how + (", rewound outward" if flipped else "")}


def face_region(name: str, fname: str, scale: float, unit_note: str) -> dict:
    """A face crop of a bust (module doc): sphere of FACE_RADIUS_MM around the nose tip, connected, subdivided."""
    import numpy as np

    from bolus_addon.core.mesh.objfile import load_obj

    path = data_mesh(fname)
    V, F, _ = load_obj(path, scale)
    tip = V[int(np.argmax(V[:, 2]))]
    Vr, Fr = region_around(V, F, tip, FACE_RADIUS_MM)
    n0 = len(Fr)
    Vr, Fr, k = _subdivide_to(Vr, Fr, MIN_FACES)
    Fr, flipped = outward(Vr, Fr, V.mean(axis=0))
    ext = Vr.max(axis=0) - Vr.min(axis=0)
    how = (f"{fname} ({unit_note}): the {n0} triangles within {FACE_RADIUS_MM:g} mm of the nose tip (largest z), "
           f"connected to it, midpoint-subdivided {k}x -> {len(Fr)} triangles, bbox {ext[0]:.0f} x {ext[1]:.0f} x "
           f"{ext[2]:.0f} mm" + (", rewound outward" if flipped else ""))
    return {"name": name, "V": Vr, "F": Fr, "how": how}


def demosthenes_scale() -> float:
    """mm per normalised unit of demosthenes.obj: the head from DEMOSTHENES_CHIN_Y to the crown is HEAD_MM."""
    from bolus_addon.core.mesh.objfile import load_obj

    V, _, _ = load_obj(data_mesh("demosthenes.obj"), 1.0)
    return HEAD_MM / (float(V[:, 1].max()) - DEMOSTHENES_CHIN_Y)


def make_region(name: str) -> dict:
    if name == "example nose":
        return example_region()
    if name == "nefertiti face":
        return face_region(name, "nefertiti.obj", 1.0, "mm")
    if name == "demosthenes face":
        s = demosthenes_scale()
        return face_region(name, "demosthenes.obj", s,
                           f"x {s:.1f}: head from chin y = {DEMOSTHENES_CHIN_Y} to crown = {HEAD_MM:g} mm")
    if name in ("chest wall", "elbow sleeve", "knee sleeve"):
        return body_patch(name)
    if name in ("breast", "ear"):
        return body_crop(name)
    raise ValueError(f"unknown region {name!r}")


def body_patch(name: str) -> dict:
    """A crop of the MakeHuman body (dm -> mm): the chest wall with the breasts (tests/data, 355 x
    314 x 152 mm, one loop), or a sleeve round the left elbow (tests/data) or the left knee
    (assets; two loops each, both ends), rewound so the normals point away from the body (a point
    behind the chest; the limb's axis)."""
    import numpy as np

    from bolus_addon.core.mesh.objfile import load_obj

    fname = {"chest wall": "makehuman_chest_patch.obj", "elbow sleeve": "makehuman_elbow_patch.obj",
             "knee sleeve": "makehuman_knee_patch.obj"}[name]
    path = ROOT / "assets" / fname if name == "knee sleeve" else data_mesh(fname)
    V, F, _ = load_obj(path, 100.0)
    inside = V.mean(axis=0) - (np.array([0.0, 0.0, 100.0]) if name == "chest wall" else 0.0)
    F, flipped = outward(V, F, inside)
    how = f"{fname} x100 (dm -> mm): {len(F)} triangles" + (", rewound outward" if flipped else "")
    return {"name": name, "V": V, "F": F, "how": how}


#: crops of the MakeHuman body (tests/data/makehuman_body.obj, dm -> mm, Y up, facing +z): the
#: point the crop is centred on (picked from the mesh: the most forward vertex of the left chest at
#: nipple height; the most lateral vertex of the head, the left ear), its radius (mm), the point
#: the normals must point away from, and the midpoint subdivisions (the body is coarse: ~20 mm quads)
BODY_CROPS = {"breast": ("breast", 100.0, "behind", 2), "ear": ("ear", 40.0, "head", 2)}


def body_crop(name: str) -> dict:
    """A treatment area cut from the whole MakeHuman body: the triangles within the crop's radius
    of its centre, edge-connected to the one nearest it (`region_around`), midpoint-subdivided."""
    import numpy as np

    from bolus_addon.core.mesh.objfile import load_obj

    V, F, _ = load_obj(data_mesh("makehuman_body.obj"), 100.0)
    what, radius, away, subdiv = BODY_CROPS[name]
    if what == "breast":
        pick = (V[:, 1] > 250) & (V[:, 1] < 400) & (V[:, 0] > 60) & (V[:, 0] < 140)
        centre = V[pick][np.argmax(V[pick][:, 2])]
        inside = centre - [0.0, 0.0, 120.0]
    else:
        head = V[:, 1] > V[:, 1].max() - 250.0
        centre = V[head][np.argmax(V[head][:, 0])]
        inside = np.array([0.0, centre[1], centre[2]])
    Vr, Fr = region_around(V, F, centre, radius)
    for _ in range(subdiv):
        Vr, Fr = midpoint_subdivide(Vr, Fr)
    Fr, flipped = outward(Vr, Fr, inside)
    how = (f"makehuman_body.obj x100 (dm -> mm), within {radius:g} mm of ({centre[0]:.0f}, {centre[1]:.0f}, "
           f"{centre[2]:.0f}), subdivided {subdiv}x: {len(Fr)} triangles" + (", rewound outward" if flipped else ""))
    return {"name": name, "V": Vr, "F": Fr, "how": how}


# ----------------------------------------------------------------------------- measures (one for both methods)


def border_distance(V, F):
    """(n,) distance of every vertex to the region's border (all boundary loops, sampled every BORDER_STEP_MM)."""
    import numpy as np
    from scipy.spatial import cKDTree

    from bolus_addon.core.mesh.boundary import boundary_loops

    loops = boundary_loops(F)
    if not loops:
        return np.full(len(V), np.inf)
    pts = []
    for loop in loops:
        a, b = V[loop], V[np.roll(loop, -1)]
        k = np.maximum(1, np.ceil(np.linalg.norm(b - a, axis=1) / BORDER_STEP_MM).astype(int))
        for i in range(len(a)):
            s = np.arange(k[i])[:, None] / k[i]
            pts.append(a[i] + s * (b[i] - a[i]))
    return cKDTree(np.vstack(pts)).query(V)[0]


def ray_thickness(skin_V, skin_F, outer_V, outer_F, thickness: float, walls_F=None) -> dict:
    """SPEC thickness: rays from the skin vertices farther than `thickness` from the border, along the skin's
    vertex normals (eq. 3-2); each ray ends on the first surface it meets (BVHTree ray casts, up to RAY_MAX *
    thickness): the outer face (outer_V (k,3), outer_F (j,3)), a rim or hole wall (walls_F (i,3) on outer_V, when
    given: e.g. a nostril's channel) or the skin itself again, from SKIN_GAP_MM on (a valley the bolus bridges,
    e.g. an eye socket: what lies beyond that is no longer bolus).

    Returns rays; outer, wall, skin, none: how many rays end on each (none: nothing within the reach); min / mean /
    max (mm) and thin (below 0.95 t) over the rays that end on the outer face; wall_min: the shortest way to a
    wall, wall_thin: the rays that meet a wall before 0.95 t; distances (rays,) to the outer face (inf where a
    ray ends elsewhere)."""
    import numpy as np
    from mathutils import Vector
    from mathutils.bvhtree import BVHTree

    from bolus_addon.core.mesh.topology import MeshTopology

    N = MeshTopology(skin_V, skin_F).vertex_normals
    far = (border_distance(skin_V, skin_F) > thickness) & (np.linalg.norm(N, axis=1) > 0)
    meshes = {"outer": (outer_V, outer_F), "skin": (skin_V, skin_F)}
    if walls_F is not None and len(walls_F):
        meshes["wall"] = (outer_V, walls_F)
    trees = {k: BVHTree.FromPolygons(np.asarray(v).tolist(), np.asarray(f).tolist(), all_triangles=True)
             for k, (v, f) in meshes.items()}
    reach = RAY_MAX * thickness
    kinds = ("outer", "wall", "skin", "none")
    first = np.full(int(far.sum()), 3)
    dist = np.full(int(far.sum()), np.inf)
    for k, (p, n) in enumerate(zip(skin_V[far], N[far])):
        for c, name in enumerate(kinds[:3]):
            if name not in trees:
                continue
            gap = SKIN_GAP_MM if name == "skin" else 0.0
            hit = trees[name].ray_cast(Vector(p + gap * n), Vector(n), reach - gap)
            if hit[0] is not None and hit[3] + gap < dist[k]:
                first[k], dist[k] = c, hit[3] + gap
    d = np.where(first == 0, dist, np.inf)
    ok = first == 0
    out = {"rays": int(len(d)), **{name: int((first == c).sum()) for c, name in enumerate(kinds)},
           "thin": int((d[ok] < 0.95 * thickness).sum()), "min": None, "mean": None, "max": None,
           "wall_min": float(dist[first == 1].min()) if (first == 1).any() else None,
           "wall_thin": int((dist[first == 1] < 0.95 * thickness).sum()), "distances": d}
    if ok.any():
        out.update(min=float(d[ok].min()), mean=float(d[ok].mean()), max=float(d[ok].max()))
    return out


def intersecting_pairs(V, F):
    """(k,2) pairs i < j of triangles of (V, F) that intersect (BVHTree.overlap of the mesh with itself), leaving
    out pairs that share a vertex (neighbours touch by construction), a vertex being a position: two indices
    at exactly the same point count as one (manifold3d may keep such twins apart)."""
    import numpy as np
    from mathutils.bvhtree import BVHTree

    V, F = np.asarray(V), np.asarray(F)
    tree = BVHTree.FromPolygons(V.tolist(), F.tolist(), all_triangles=True)
    pairs = np.array(tree.overlap(tree), dtype=np.int64).reshape(-1, 2)
    pairs = pairs[pairs[:, 0] < pairs[:, 1]]
    weld = np.unique(V, axis=0, return_inverse=True)[1].reshape(-1)[F]  # F on unique positions
    a, b = weld[pairs[:, 0]], weld[pairs[:, 1]]
    return pairs[~(a[:, :, None] == b[:, None, :]).any(axis=(1, 2))]


def self_intersections(V, F) -> int:
    """The number of `intersecting_pairs` of (V, F)."""
    return int(len(intersecting_pairs(V, F)))


def folded_mask(V, F, src, skin_V, skin_F):
    """(j,) bool: offset-layer triangles (V, F) whose normal turned against their source skin face's (src (j,)
    index into skin_F): n . n_source <= 0 (a collapsed triangle counts as folded)."""
    import numpy as np

    from bolus_addon.core.mesh.topology import face_normals

    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    return np.einsum("ij,ij->i", n, face_normals(skin_V, skin_F)[src]) <= 0


def folded_triangles(V, F, src, skin_V, skin_F) -> int:
    """The number of folded offset-layer triangles (`folded_mask`)."""
    return int(folded_mask(V, F, src, skin_V, skin_F).sum())


#: mm: a rim-wall vertex's neighbours for the quadric fit (SPEC's rim smoothness)
RIM_RADIUS_MM = 2.0
#: mm: the 95th percentile of the rim residuals at or below this is a smooth rim (SPEC)
RIM_SMOOTH_MM = 0.05


def rim_residuals(V, F, walls, radius: float = RIM_RADIUS_MM, most: int = 20000):
    """SPEC's rim smoothness: for each vertex of the wall triangles F[walls] (every one, or ``most``
    evenly spread), its distance (mm) from the quadric z = q(x, y) fitted by least squares, in the
    frame of the principal axes of its wall neighbours within ``radius`` mm (z the least one), to
    those neighbours; vertices with fewer than 8 neighbours are left out.  Returns (k,) float."""
    import numpy as np
    from scipy.spatial import cKDTree

    verts = np.unique(np.asarray(F)[np.asarray(walls)])
    P = np.asarray(V, dtype=np.float64)[verts]
    if len(P) == 0:
        return np.zeros(0)
    pick = np.arange(len(P))
    if len(pick) > most:
        pick = pick[np.linspace(0, len(P) - 1, most).round().astype(int)]
    out = []
    for i, near in zip(pick, cKDTree(P).query_ball_point(P[pick], radius)):
        if len(near) < 8:
            continue
        Q = P[near] - P[near].mean(axis=0)
        axes = np.linalg.svd(Q, full_matrices=False)[2]
        x, y, z = (Q @ axes.T).T
        A = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=1)
        coef = np.linalg.lstsq(A, z, rcond=None)[0]
        xi, yi, zi = axes @ (P[i] - P[near].mean(axis=0))
        out.append(abs(zi - np.array([xi * xi, xi * yi, yi * yi, xi, yi, 1.0]) @ coef))
    return np.asarray(out)


def measure_solid(V, F, outer, walls, skin_V, skin_F, thickness: float) -> dict:
    """The figures of one solid (V, F) with its outer faces and its rim / hole walls (masks (m,) bool) on the skin
    (skin_V, skin_F)."""
    import numpy as np

    from bolus_addon.core.solid.manifold import closed_report

    rep = closed_report(V, F)
    t = ray_thickness(skin_V, skin_F, V, F[outer], thickness, F[walls])
    t.pop("distances")
    pairs = intersecting_pairs(V, F)
    spots = V[F[pairs[:SPOTS, 0]]].mean(axis=1)
    rim = rim_residuals(V, F, walls)
    return {"triangles": int(len(F)), "closed": rep, "thickness": t, "self_intersections": int(len(pairs)),
            "self_intersection_spots": [[round(float(x), 1) for x in p] for p in spots],
            "rim_p95": float(np.percentile(rim, 95)) if len(rim) else None,
            "rim_max": float(rim.max()) if len(rim) else None}


# ----------------------------------------------------------------------------- Solidify


def solidify_arrays(bpy, V, F, mode: str, thickness: float = THICKNESS_MM, timer=None) -> dict:
    """Blender's Solidify (complex, module doc) on the region (V, F): the evaluated solid as triangles.

    Returns V2 (k,3), F2 (j,3) (polygons fan-triangulated), layer (j,) 0 skin layer, 1 offset layer, 2 rim,
    src (j,) the source face of each triangle (-1 on the rim), seconds (the depsgraph evaluation alone, or what
    ``timer`` returns: timer(fn) -> (result, stats))."""
    import numpy as np

    benchutil.clean_scene(bpy)
    me = bpy.data.meshes.new("region")
    me.from_pydata(np.asarray(V).tolist(), [], np.asarray(F).tolist())
    me.update()
    at = me.attributes.new("bolus_bench_src", "INT", "FACE")
    at.data.foreach_set("value", np.arange(len(F), dtype=np.int32))
    ob = bpy.data.objects.new("region", me)
    bpy.context.scene.collection.objects.link(ob)
    md = ob.modifiers.new("solidify", "SOLIDIFY")
    md.solidify_mode = "NON_MANIFOLD"
    md.nonmanifold_thickness_mode = mode
    md.thickness = thickness
    md.offset = 1.0
    md.use_rim = True
    md.use_rim_only = False
    md.use_even_offset = True
    md.show_viewport = False
    dg = bpy.context.evaluated_depsgraph_get()
    dg.update()
    md.show_viewport = True
    gc.collect()
    if timer is None:
        t0 = time.perf_counter()
        dg.update()
        stats = {"seconds": time.perf_counter() - t0}
    else:
        _, stats = timer(dg.update)
    ev = ob.evaluated_get(dg)
    m2 = ev.data
    n, np_ = len(m2.vertices), len(m2.polygons)
    co = np.empty(n * 3)
    m2.vertices.foreach_get("co", co)
    corners = np.empty(len(m2.loops), dtype=np.int64)
    m2.loops.foreach_get("vertex_index", corners)
    sizes = np.empty(np_, dtype=np.int64)
    m2.polygons.foreach_get("loop_total", sizes)
    src = np.empty(np_, dtype=np.int32)
    m2.attributes["bolus_bench_src"].data.foreach_get("value", src)
    if np_ == len(F):
        raise RuntimeError("the Solidify modifier was not evaluated (as many faces out as in)")
    from bolus_addon.core.mesh.topology import triangulate_polygons

    V2 = co.reshape(-1, 3)
    F2, tri_poly = triangulate_polygons(corners, sizes)
    # the skin layer keeps the region's positions (offset = +1): its triangles' centroids sit on their source's
    # (within Blender's float32 coordinates: 1e-3 t is far below the offset layer's t, far above float32's error)
    C = np.asarray(V)[np.asarray(F)].mean(axis=1)
    tsrc = src[tri_poly].astype(np.int64)
    is_tri = sizes[tri_poly] == 3
    on_skin = np.linalg.norm(V2[F2].mean(axis=1) - C[np.clip(tsrc, 0, len(F) - 1)], axis=1) < 1e-3 * thickness
    layer = np.full(len(F2), 2, dtype=np.int8)
    layer[is_tri & on_skin] = 0
    layer[is_tri & ~on_skin] = 1
    tsrc[layer == 2] = -1
    counts = np.bincount(layer, minlength=3)
    if counts[0] != len(F) or counts[1] != len(F):
        stats["warnings"] = [f"the layers were not told apart cleanly: {counts[0]} skin-layer and {counts[1]} "
                             f"offset-layer triangles for {len(F)} skin triangles"]
    bpy.data.objects.remove(ob)
    bpy.data.meshes.remove(me)
    return {"V": V2, "F": F2, "layer": layer, "src": tsrc, **stats}


# ----------------------------------------------------------------------------- child processes



def measured(fn):
    """(fn(), stats): wall time of the call, the CPU time of all its threads (the machine is shared: CPU time
    depends less on what else runs) and its peak memory (VmHWM reset before it, minus VmRSS before)."""
    import resource

    gc.collect()
    rss0 = benchutil.status_kb("VmRSS")
    reset = benchutil.reset_peak_rss()
    r0 = resource.getrusage(resource.RUSAGE_SELF)
    t0 = time.perf_counter()
    res = fn()
    dt = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_SELF)
    hwm = benchutil.status_kb("VmHWM")
    return res, {"seconds": dt, "cpu_seconds": (r1.ru_utime + r1.ru_stime) - (r0.ru_utime + r0.ru_stime),
                 "rss_before_mb": rss0 / 1024.0, "peak_mb": hwm / 1024.0,
                 "peak_delta_mb": (hwm - rss0) / 1024.0 if reset else None}


def work_ours(data: dict, job: dict) -> tuple[dict, dict]:
    """make_shell with no time limit; its estimate (`budget`, what a refusal is judged by) beside it."""
    import numpy as np

    from bolus_addon.core import budget
    from bolus_addon.core.solid.shell import make_shell

    V, F = data["V"], data["F"]
    sh, st = measured(lambda: make_shell(V, F, thickness=job["thickness"], resolution=job["resolution"],
                                         mesher=job.get("mesher", "cubes"), rim=job.get("rim", "faces"),
                                         time_limit_s=0))
    area = 0.5 * float(np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum())
    st["estimate_s"] = budget.estimate_s("make_shell", budget.shell_cells(area, job["resolution"]))
    st.update(volume_mm3=float(sh.volume_mm3), holes=int(sh.holes), warnings=list(sh.warnings),
              self_thickness=[float(sh.thickness_min), float(sh.thickness_mean), float(sh.thickness_max)],
              shell_stats=getattr(sh, "stats", None))
    return {"V": sh.V, "F": sh.F, "side": sh.side}, st


def work_solidify(data: dict, job: dict) -> tuple[dict, dict]:
    import bpy

    with benchutil.captured_output():
        r = solidify_arrays(bpy, data["V"], data["F"], job["mode"], job["thickness"], timer=measured)
    st = {k: r.pop(k) for k in list(r) if k not in ("V", "F", "layer", "src")}
    st["bpy"] = bpy.app.version_string
    return r, st


def work_parts(data: dict, job: dict) -> tuple[dict, dict]:
    """Segment the skin, split the shell, orient the shell and each part (module doc)."""
    import numpy as np

    from bolus_addon.core.printing.orientation import orient
    from bolus_addon.core.printing.parts import orient_print_parts
    from bolus_addon.core.printing.segmentation import print_segment
    from bolus_addon.core.solid.parts import split_solid

    V, F, side, sV, sF = data["V"], data["F"], data["side"], data["skin_V"], data["skin_F"]
    labels, st_seg = measured(lambda: print_segment(sV, sF, parts=job["parts"], method="abcut", rng=0))
    sp, st = measured(lambda: split_solid(V, F, side, sV, sF, labels, clearance=job["clearance"]))
    whole, st_w = measured(lambda: orient(V, F))
    plan, st_p = measured(lambda: orient_print_parts(sp.V, sp.F, sp.labels, whole=False))
    st.update(segment_seconds=st_seg["seconds"], skin_parts=int(len(np.unique(labels))),
              orient_whole_seconds=st_w["seconds"], orient_parts_seconds=st_p["seconds"],
              whole_support_mm3=float(whole.support_volume), whole_direction=[float(x) for x in whole.direction],
              parts_support_mm3=[float(r.orientation.support_volume) for r in plan.parts],
              part_directions=[[float(x) for x in r.orientation.direction] for r in plan.parts],
              volumes_mm3=[float(v) for v in sp.volumes_mm3], warnings=list(sp.warnings),
              joints=[{"parts": [int(p) for p in j.parts], "area_mm2": float(j.area_mm2),
                       "connectors": len(j.connectors), "note": j.note} for j in sp.joints])
    return {"V": sp.V, "F": sp.F, "labels": sp.labels, "side": sp.side}, st


WORKERS = {"ours": work_ours, "solidify": work_solidify, "parts": work_parts}


def _plain(o):
    """JSON for numpy values (arrays as lists, scalars as numbers), anything else as its text."""
    return o.tolist() if hasattr(o, "tolist") else str(o)


def worker(job_path: str) -> int:
    """Child process: run one job (JSON: kind, input .npz, output .npz, settings), write arrays + stats."""
    import numpy as np

    job = json.loads(Path(job_path).read_text())
    with np.load(job["input"]) as z:
        data = {k: z[k] for k in z.files}
    out, stats = WORKERS[job["kind"]](data, job)
    np.savez(job["output"], stats=np.array(json.dumps(stats, default=_plain)), **out)
    return 0


def run_worker(kind: str, arrays: dict, tmp: Path, keep: bool = False, **settings) -> tuple[dict, dict]:
    """Run one job in a child process (this interpreter): (its arrays, its stats); RuntimeError with its output
    when it fails.  The job's files in ``tmp`` are removed afterwards unless ``keep``."""
    import numpy as np

    label = "_".join(str(settings[k]) for k in ("region", "resolution", "mode") if k in settings)
    tag = f"{len(list(tmp.glob('*.json'))):02d}_{kind}_{label}".replace(" ", "-").rstrip("_")
    inp, outp, jobp = tmp / f"{tag}_in.npz", tmp / f"{tag}_out.npz", tmp / f"{tag}.json"
    np.savez(inp, **arrays)
    jobp.write_text(json.dumps({"kind": kind, "input": str(inp), "output": str(outp), **settings}))
    try:
        p = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker", str(jobp)],
                           capture_output=True, text=True, timeout=WORKER_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        raise RuntimeError(f"{kind} did not finish within {WORKER_TIMEOUT_S} s") from None
    if p.returncode != 0:
        tail = [ln for ln in (p.stderr or p.stdout).strip().splitlines() if ln.strip()]
        raise RuntimeError(tail[-1] if tail else f"{kind} worker exited with {p.returncode}")
    with np.load(outp) as z:
        out = {k: z[k] for k in z.files if k != "stats"}
        stats = json.loads(str(z["stats"]))
    if not keep:
        for f in (inp, outp, jobp):
            f.unlink(missing_ok=True)
    return out, stats


# ----------------------------------------------------------------------------- one region


def bench_region(region: dict, resolutions, tmp: Path, keep: bool = False, parts_resolution=None) -> dict:
    """Ours at each resolution (mm), both Solidify modes, then the parts of the shell at ``parts_resolution``
    (when it was run, else the finest) (module doc).  The child processes' arrays stay in ``tmp`` when ``keep``."""
    import numpy as np

    from bolus_addon.core.solid.manifold import SIDE_OUTER, SIDE_RIM

    name, V, F = region["name"], region["V"], region["F"]
    t = THICKNESS_MM
    print(f"\n== {name}: {region['how']}")
    row = {"region": name, "how": region["how"], "faces": int(len(F)), "runs": [], "parts": None}
    skin = {"V": V, "F": F}
    shells = {}
    runs = [(r, m, "faces") for r in resolutions for m in MESHERS
            if m == "cubes" or r in LEVEL_SET_RESOLUTIONS.get(name, (1.0,)) or len(resolutions) == 1]
    runs.append((min(resolutions), "cubes", "strip"))
    for res, mesher, rim in runs:
        key = f"ours {res:g} mm" + ("" if mesher == "cubes" else " level set") + ("" if rim == "faces" else " strip rim")
        try:
            out, st = run_worker("ours", skin, tmp, keep, region=name, thickness=t, resolution=res, mesher=mesher,
                                 rim=rim)
            m = measure_solid(out["V"], out["F"], out["side"] == SIDE_OUTER, out["side"] == SIDE_RIM, V, F, t)
            if mesher == "cubes" and rim == "faces":
                shells[res] = out
            run = {"method": key, **st, **m, "folded": None}
        except Exception as exc:
            run = benchutil.error_row("method", key, exc)
        row["runs"].append(run)
        print_run(run, t)
    for key, mode in SOLIDIFY_MODES:
        try:
            out, st = run_worker("solidify", skin, tmp, keep, region=name, thickness=t, mode=mode)
            off = out["layer"] == 1
            m = measure_solid(out["V"], out["F"], off, out["layer"] == 2, V, F, t)
            fm = folded_mask(out["V"], out["F"][off], out["src"][off], V, F)
            far = (border_distance(V, F)[F] > t).all(axis=1)  # source faces farther than t from the border
            m["folded"], m["folded_far"] = int(fm.sum()), int((fm & far[out["src"][off]]).sum())
            m["offset_triangles"] = int(off.sum())
            vol = m["closed"]["volume_mm3"]
            run = {"method": key, **st, **m, "volume_mm3": vol}
        except Exception as exc:
            run = benchutil.error_row("method", key, exc)
        row["runs"].append(run)
        print_run(run, t)
    res = parts_resolution if parts_resolution in resolutions else min(resolutions)
    if res not in shells:
        row["parts"] = {"note": f"no {res:g} mm shell to split"}
        print(f"   parts: {row['parts']['note']}")
        return row
    sh = shells[res]
    try:
        out, st = run_worker("parts", {"V": sh["V"], "F": sh["F"], "side": sh["side"], "skin_V": V, "skin_F": F},
                             tmp, keep, region=name, resolution=res, parts=PARTS, clearance=PARTS_CLEARANCE_MM)
        row["parts"] = {"resolution": res, **st, **parts_figures(out, sh)}
    except Exception as exc:
        row["parts"] = {"error": benchutil.error_row("parts", "parts", exc)["error"]}
    print_parts(row["parts"])
    return row


def parts_figures(out: dict, shell: dict) -> dict:
    """Closed? and volume of every part (core.solid.closed_report on its faces), their sum against the shell's."""
    import numpy as np

    from bolus_addon.core.solid.manifold import closed_report
    from bolus_addon.core.mesh.topology import submesh

    from bolus_addon.core.solid.manifold import weld_short_edges

    closed, vols, repairs = [], [], []
    PV, PF, keep = weld_short_edges(out["V"], out["F"])  # as Split into Print Parts leaves them
    labels = np.asarray(out["labels"])[keep]
    for p in np.unique(labels):
        Fw, ids = submesh(PF, labels == p)
        repairs.append(admesh_repairs(PV[ids], Fw))
    for p in np.unique(out["labels"]):
        Fp, ids = submesh(out["F"], out["labels"] == p)
        rep = closed_report(out["V"][ids], Fp)
        closed.append(bool(rep["closed"]))
        vols.append(float(rep["volume_mm3"]))
    whole = closed_report(shell["V"], shell["F"])["volume_mm3"]
    return {"part_count": len(vols), "parts_closed": closed, "part_volumes_measured_mm3": vols,
            "shell_volume_mm3": float(whole), "volume_sum_ratio": float(sum(vols) / whole) if whole else None,
            "admesh": repairs}


#: admesh's repair counts that a part needing no repair has at 0 (and "Number of parts" at 1); its
#: "Normals fixed" counts stored normals it recomputes (every slicer recomputes them from the
#: corners; on a tiny triangle two float32 cross products can differ), reported apart
ADMESH_COUNTS = ("Degenerate facets", "Edges fixed", "Facets removed", "Facets added", "Facets reversed",
                 "Backwards edges")


def admesh_repairs(V, F) -> dict | None:
    """A part written as a binary float32 STL (what export_parts writes) and read by admesh, the
    slicers' STL checker, where installed: {"parts": its count of shells, "repairs": the sum of
    `ADMESH_COUNTS`, "counts": the ones not 0, "normals_fixed"}; None without admesh."""
    import re
    import shutil

    import numpy as np
    from meshfiles import write_binary  # tests/ is on the path (benchutil)

    exe = shutil.which("admesh")
    if exe is None:
        return None
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "part.stl"
        write_binary(path, np.asarray(V, dtype=np.float64), np.asarray(F), header=b"part", normals=True)
        text = subprocess.run([exe, str(path)], capture_output=True, text=True, timeout=600).stdout

    def count(label):
        m = re.search(re.escape(label) + r"\s*:\s*(\d+)", text)
        return int(m.group(1)) if m else -1

    counts = {k: count(k) for k in ADMESH_COUNTS}
    return {"parts": count("Number of parts"), "repairs": sum(counts.values()),
            "counts": {k: v for k, v in counts.items() if v}, "normals_fixed": count("Normals fixed")}


# ----------------------------------------------------------------------------- output


def _f(x, fmt="{:.2f}") -> str:
    return "n/a" if x is None else fmt.format(x)


def closed_text(rep: dict) -> str:
    if rep["closed"]:
        return "yes" if rep.get("components", 1) <= 1 else f"yes, {rep['components']} pieces"
    bits = [f"{rep[k]} {k.split('_')[0]}" for k in ("boundary_edges", "nonmanifold_edges", "inconsistent_edges")
            if rep.get(k)]
    return "no (" + ", ".join(bits) + " edges)" if bits else "no"


def ray_ends(th: dict) -> str:
    """Where the thickness rays that do not end on the outer face end."""
    wall = f"{th['wall']} on a wall" + (f" (from {th['wall_min']:.2f} mm)" if th.get("wall_min") else "")
    return f"{th['skin']} on the skin again, {wall}, {th['none']} on nothing within {RAY_MAX * THICKNESS_MM:g} mm"


def cpu_text(r: dict) -> str:
    return _f(r.get("cpu_seconds"))


def mem_text(r: dict) -> str:
    d = r.get("peak_delta_mb")
    return _f(d, "{:.0f}") if d is not None else f"<= {r['peak_mb']:.0f}"


def print_run(r: dict, t: float) -> None:
    if "error" in r:
        return
    th = r["thickness"]
    est = f" (estimated {r['estimate_s']:.1f} s)" if r.get("estimate_s") and r["method"].endswith(" mm") else ""
    print(f"   {r['method']}: {r['seconds']:.2f} s{est}, peak +{mem_text(r)} MB, {r['triangles']} triangles, "
          f"closed {closed_text(r['closed'])}, volume {r['closed']['volume_mm3'] / 1000:.2f} cm³, thickness "
          f"{_f(th['min'])} / {_f(th['mean'])} / {_f(th['max'])} mm on the {th['outer']} of {th['rays']} rays that "
          f"end on the outer face ({th['thin']} below {0.95 * t:g} mm; {ray_ends(th)}), {r['self_intersections']} "
          "self-intersecting pairs"
          + (f", {r['folded']} folded of {r['offset_triangles']} offset triangles ({r['folded_far']} on skin "
             f"faces farther than {t:g} mm from the border)" if r.get("folded") is not None else ""))
    if r["self_intersections"]:
        print("     first intersecting pairs near " + ", ".join(f"({x:.1f}, {y:.1f}, {z:.1f})"
                                                             for x, y, z in r["self_intersection_spots"]) + " mm")
    for w in r.get("warnings", []) or []:
        print(f"     warning: {w}")


def print_parts(p: dict) -> None:
    if "note" in p:
        return
    if "error" in p:
        print(f"   parts FAILED: {p['error']}")
        return
    print(f"   parts ({p['resolution']:g} mm shell): segment {p['segment_seconds']:.2f} s, split_solid "
          f"{p['seconds']:.2f} s (peak +{mem_text(p)} MB), {p['part_count']} parts, closed "
          f"{sum(p['parts_closed'])}/{p['part_count']}, volumes {pct_text(p['volume_sum_ratio'])} of the shell's, "
          f"{sum(j['connectors'] for j in p['joints'])} connectors on {len(p['joints'])} joints; support "
          f"{sum(p['parts_support_mm3']):.0f} mm³ (parts, each in its best orientation) against "
          f"{p['whole_support_mm3']:.0f} mm³ (whole shell); admesh: {admesh_text(p)} parts one shell, no repair")
    for j in p["joints"]:
        if j["note"]:
            print(f"     joint {j['parts']}: {j['note']}")
    for w in p.get("warnings", []):
        print(f"     warning: {w}")


def pct_text(x) -> str:
    return "n/a" if x is None else f"{100 * x:.2f} %"


def shell_table(rows: list[dict], t: float) -> Table:
    tab = Table([("region", "<"), ("method", "<"), ("time s", ">"), ("estimate s", ">"), ("cpu s", ">"),
                 ("peak MB", ">"),
                 ("triangles", ">"),
                 ("closed", "<"), ("volume cm³", ">"), ("t min", ">"), ("t mean", ">"), ("t max", ">"),
                 (f"< {0.95 * t:g} / rays", ">"), ("skin / wall / none", ">"),
                 (f"folded (> {t:g} mm from border)", ">"), ("self-int. pairs", ">"), ("rim p95 / max mm", ">")])
    for row in rows:
        if "error" in row:
            tab.add_error(row["region"], row["error"])
            continue
        for r in row["runs"]:
            first = f"{row['region']} ({row['faces']} tri)"
            if "error" in r:
                tab.add_error(f"{first}: {r['method']}", r["error"])
                continue
            th = r["thickness"]
            est = r.get("estimate_s") if r["method"].startswith("ours") and r["method"].endswith(" mm") else None
            tab.add(first, r["method"], f"{r['seconds']:.2f}", "n/a" if est is None else f"{est:.1f}", cpu_text(r),
                    mem_text(r), r["triangles"],
                    closed_text(r["closed"]),
                    f"{r['closed']['volume_mm3'] / 1000:.2f}", _f(th["min"]), _f(th["mean"]), _f(th["max"]),
                    f"{th['thin']} / {th['rays']}", f"{th['skin']} / {th['wall']} / {th['none']}",
                    "n/a" if r.get("folded") is None
                    else f"{r['folded']} ({r['folded_far']}) of {r['offset_triangles']}",
                    r["self_intersections"], rim_text(r))
    return tab


def rim_text(r: dict) -> str:
    return "n/a" if r.get("rim_p95") is None else f"{r['rim_p95']:.3f} / {r['rim_max']:.2f}"


def parts_table(rows: list[dict]) -> Table:
    tab = Table([("region", "<"), ("shell", ">"), ("parts", ">"), ("split s", ">"), ("cpu s", ">"), ("peak MB", ">"),
                 ("closed", ">"), ("Σ volume / shell", ">"), ("connectors", ">"), ("support parts mm³", ">"),
                 ("support whole mm³", ">"), ("ratio", ">"), ("admesh: no repair", ">")])
    for row in rows:
        p = row.get("parts") if "error" not in row else None
        if not p:
            continue
        if "note" in p or "error" in p:
            tab.add_error(row["region"], p.get("note") or p.get("error"))
            continue
        sp, sw = sum(p["parts_support_mm3"]), p["whole_support_mm3"]
        tab.add(row["region"], f"{p['resolution']:g} mm", p["part_count"], f"{p['seconds']:.2f}", cpu_text(p),
                mem_text(p),
                f"{sum(p['parts_closed'])}/{p['part_count']}", pct_text(p["volume_sum_ratio"]),
                sum(j["connectors"] for j in p["joints"]), f"{sp:.0f}", f"{sw:.0f}",
                f"{sp / sw:.2f}" if sw > 0 else "n/a", admesh_text(p))
    return tab


def admesh_text(p: dict) -> str:
    """'k/n': parts that admesh reads as one shell needing no repair; n/a without admesh."""
    checks = [a for a in p.get("admesh", []) if a is not None]
    if not checks:
        return "n/a"
    normals = sum(a.get("normals_fixed", 0) for a in checks)
    return (f"{sum(a['parts'] == 1 and a['repairs'] == 0 for a in checks)}/{len(checks)}"
            + (f" ({normals} stored normals recomputed)" if normals else ""))


def target_lines(rows: list[dict]) -> list[str]:
    """The issue's targets against the figures: time at 0.5 mm, closed without self-intersection, min thickness."""
    runs = [(row["region"], r) for row in rows if "runs" in row for r in row["runs"] if "error" not in r]
    fine = [(g, r) for g, r in runs if r["method"] == f"ours {TARGET_RES_MM:g} mm"]
    out = []
    if fine:
        ok = sum(r["seconds"] < TARGET_S for _, r in fine)
        out.append(f"make_shell under {TARGET_S:g} s at {TARGET_RES_MM:g} mm: {ok} of {len(fine)} regions ("
                   + ", ".join(f"{g} {r['seconds']:.0f} s, cpu {r['cpu_seconds']:.0f} s" for g, r in fine) + ").")
    for label, pick in (("ours", lambda m: m.startswith("ours")), ("Solidify", lambda m: m.startswith("Solidify"))):
        sel = [r for _, r in runs if pick(r["method"])]
        if not sel:
            continue
        sound = sum(r["closed"]["closed"] and r["self_intersections"] == 0 for r in sel)
        thick = sum(r["thickness"]["min"] is not None and r["thickness"]["min"] >= 0.95 * THICKNESS_MM for r in sel)
        walls = [f"{g} {r['method']}: {r['thickness']['wall_thin']}" for g, r in runs
                 if pick(r["method"]) and r["thickness"].get("wall_thin")]
        out.append(f"{label}: closed without self-intersection in {sound} of {len(sel)} runs; minimum thickness >= "
                   f"{0.95 * THICKNESS_MM:g} mm in {thick} of {len(sel)}"
                   + (f" (rays that meet a rim or hole wall before {0.95 * THICKNESS_MM:g} mm: " + ", ".join(walls)
                      + ")" if walls else "") + ".")
        smooth = [r for r in sel if r.get("rim_p95") is not None]
        if smooth:
            out.append(f"{label}: rim smooth (p95 of the rim residual <= {RIM_SMOOTH_MM:g} mm) in "
                       f"{sum(r['rim_p95'] <= RIM_SMOOTH_MM for r in smooth)} of {len(smooth)} runs.")
    return out


def legend() -> str:
    return (f"Shell {THICKNESS_MM:g} mm thick. Ours: `core.shell.make_shell(thickness={THICKNESS_MM:g}, "
            "resolution=r)` (r in the method column; the skin's other faces are not passed); the peer: Blender's "
            "Solidify, complex mode (`NON_MANIFOLD`), `offset=+1`, rim filled, `use_even_offset`, thickness mode "
            "EVEN or CONSTRAINTS (Blender's default), evaluated through the depsgraph. Each call runs alone in a "
            "child process: time = the call alone (wall clock), cpu = the CPU time of all its threads (less "
            "dependent on the load of the shared machine), peak MB = the child's VmHWM during the call minus its "
            "RSS before it. Closed: every edge has two faces with opposite directions "
            "(`core.solid.closed_report`). Thickness "
            f"(SPEC, one measure for both): rays from the skin vertices farther than {THICKNESS_MM:g} mm from the "
            "region's border, along the skin's vertex normal, each ending on the first surface it meets "
            "(`BVHTree.ray_cast`): the outer face (ours: `SIDE_OUTER` faces; Solidify: its offset layer), a rim or "
            "hole wall, the skin again (a valley the bolus bridges, e.g. an eye socket) or nothing within "
            f"{RAY_MAX * THICKNESS_MM:g} mm; t min / mean / max over the rays that end on the outer face, "
            f"< {0.95 * THICKNESS_MM:g}: how many of those are thinner than that, rays: all rays cast; skin / wall "
            "/ none: where the others end. Folded: offset-layer triangles whose normal turned against their source "
            f"face's (in brackets: those whose source face lies farther than {THICKNESS_MM:g} mm from the border). "
            "Self-intersecting pairs: `BVHTree.overlap` of the solid with itself, pairs sharing a vertex (a position) "
            "left out. Rim p95 / max: SPEC's rim smoothness, each rim-wall vertex's distance from the quadric fitted "
            f"(least squares, principal-axes frame) to the rim-wall vertices within {RIM_RADIUS_MM:g} mm (ours: "
            f"`SIDE_RIM` faces, hole walls included; Solidify: its rim faces); smooth at p95 <= {RIM_SMOOTH_MM:g} mm")


def parts_legend() -> str:
    return (f"Parts: the shell split into {PARTS} parts along the ABcut print segmentation of its skin "
            f"(`print_segment(skin, {PARTS}, rng=0)`) by `core.solid_parts.split_solid` (SVM planes, peg/hole "
            f"connectors, clearance {PARTS_CLEARANCE_MM:g} mm); split s = `split_solid` alone; closed: per part; "
            "support (SPEC: projected overhang area x height) of the parts, each in its best orientation "
            "(`print_orientation.orient`), against the whole shell's in its own best orientation; admesh: parts "
            "that admesh (the slicers' STL checker, where installed) reads from a binary STL as one shell needing no "
            "repair")


def markdown(rows: list[dict], argv) -> str:
    regions = "; ".join(f"**{r['region']}**: {r['how']}" for r in rows if "how" in r)
    out = ["## Printed bolus (`bench/shell_bench.py`)", "", benchutil.run_line("shell_bench.py", argv), "",
           f"Regions: {regions}.", "", legend() + ".", "", shell_table(rows, THICKNESS_MM).markdown(), "",
           " ".join(target_lines(rows))]
    pt = parts_table(rows)
    if pt.rows:
        out += ["", parts_legend() + ".", "", pt.markdown()]
    return "\n".join(out)


# ----------------------------------------------------------------------------- main


def resolutions_for(name: str, args) -> tuple:
    """The resolutions (mm) ours runs at on region ``name``: --resolution, else --quick's, else RESOLUTIONS."""
    if args.resolution:
        return tuple(sorted(set(args.resolution)))
    return RESOLUTIONS_QUICK if args.quick else RESOLUTIONS[name]


def main(argv=None) -> int:
    ap = benchutil.parser(__doc__, "the example nose region at 1.0 mm only", repeat=None)
    ap.add_argument("--worker", metavar="JOB", help=argparse.SUPPRESS)
    ap.add_argument("--resolution", metavar="MM", type=float, action="append", default=[],
                    help="run ours at this resolution on every region (repeatable; default: RESOLUTIONS)")
    ap.add_argument("--keep", metavar="DIR", help="keep every call's input and output arrays (.npz) in DIR")
    ap.add_argument("--only", metavar="NAME", action="append", default=[],
                    help="bench only the regions whose name contains NAME (repeatable)")
    args = ap.parse_args(argv)
    if args.worker:
        return worker(args.worker)

    import bpy
    import numpy as np
    import scipy

    t_start = time.perf_counter()
    print(f"Bolus shell benchmark: bpy {bpy.app.version_string}, Python {platform.python_version()}, numpy "
          f"{np.__version__}, scipy {scipy.__version__}, {os.cpu_count()} CPUs{'  [--quick]' if args.quick else ''}")
    names = QUICK_REGIONS if args.quick else REGIONS
    if args.only:
        names = [n for n in names if any(o in n for o in args.only)]
    rows = []
    if args.keep:
        Path(args.keep).mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="shell_bench_") as td:
        work = Path(args.keep) if args.keep else Path(td)
        for name in names:
            try:
                region = make_region(name)
            except Exception as exc:
                rows.append(benchutil.error_row("region", name, exc))
                continue
            try:
                rows.append(bench_region(region, resolutions_for(name, args), work, bool(args.keep),
                                         PARTS_RESOLUTION.get(name)))
            except Exception as exc:
                rows.append(benchutil.error_row("region", name, exc))
    total = time.perf_counter() - t_start
    print("\n" + legend() + ".")
    print(shell_table(rows, THICKNESS_MM).text())
    print("\n".join(target_lines(rows)))
    pt = parts_table(rows)
    if pt.rows:
        print("\n" + parts_legend() + ".")
        print(pt.text())
    benchutil.finish(args, {"quick": args.quick, "thickness_mm": THICKNESS_MM,
                            "resolutions_mm": {n: list(resolutions_for(n, args)) for n in names},
                            "units": "lengths mm, volumes mm³, seconds",
                            "regions": rows}, total, markdown(rows, argv))
    return 0


if __name__ == "__main__":
    sys.exit(main())
