"""The bad-mesh corpus (tests/badmesh.py) through every operator.

Each case goes through the operators in the order a user runs them (`CHAIN`), each as from
the UI (``EXEC_DEFAULT`` with an undo step).  Every step either FINISHES with valid output
(finite coordinates, attributes of the right length and range, pattern islands without NaN,
a closed and consistently wound bolus, parseable SVG and STL files) or is REFUSED with a
RuntimeError whose message says which problem, where and what to do (`EXPECT` holds the
message each refusal must match).  "Unexpected error" (a traceback caught by BolusOperator)
is always a failure.  The source's coordinates, topology, seams, attributes, custom
properties and transform stay as they were, except what the operator exists to write
(`WRITES`); for those operators Ctrl+Z (``ed.undo``) gives the source back bit for bit and
``ed.redo`` gives the result back (in Edit Mode Blender's undo step holds the mesh only, not
the object's custom properties: there the mesh is compared).  The object's mode and its Edit
Mode selection are kept (Select Treatment Area ends in Edit Mode with its area selected, by
design).  What the operators read of a mesh with modifiers is its mesh data, without them (a
warning says so), and the pattern's area is the source's in world space (scale, rotation).

The run writes a tally ``N finished, M refused, 0 unexpected`` and the table case x operator
to ``corpus_tally.json`` in pytest's temporary folder (printed by `test_tally`).
"""
from __future__ import annotations

import contextlib
import json
import math
import re
import struct
import time
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from badmesh import CASES, NAN_VERTEX, NM_EDGE, vid
from bpy_helpers import assert_labels_connected, attr_array

pytestmark = pytest.mark.blender

#: the operators in the order a user runs them, with the arguments of the test run
CHAIN = [
    ("saliency_preview", {}),
    ("segment", {"patches": 2}),
    ("smooth_cuts", {}),
    ("improve_flattenability", {"max_gap_mm": 1.0}),
    ("unfold", {}),
    ("export_pattern", {}),  # filepath: tmp_path
    ("make_shell", {"thickness_mm": 12.0, "resolution_mm": 3.0}),
    ("print_segment", {"parts": 2}),
    ("orient_parts", {}),
    ("export_parts", {}),  # directory: tmp_path
    ("select_area", {"radius_mm": 15.0}),  # the 3D cursor on the dome's top
]
OPS = [op for op, _ in CHAIN]

#: what an operator exists to write on the source: attributes, custom properties, seams, topology
WRITES = {
    "saliency_preview": dict(attrs={"bolus_flattenability", "bolus_saliency", "bolus_saliency_color"},
                             props={"bolus_sum_varpi", "bolus_flv"}),
    "segment": dict(attrs={"bolus_patch", "bolus_patch_color"}, props={"bolus_patch_table"}, seams=True),
    "smooth_cuts": dict(attrs={"bolus_patch", "bolus_patch_color"}, props={"bolus_patch_table", "bolus_cut_table"},
                        seams=True, topology=True),
    "print_segment": dict(attrs={"bolus_print_part", "bolus_print_part_color"}, props={"bolus_print_table"}),
    "orient_parts": dict(props={"bolus_orient_table"}),
    "select_area": dict(seams=True, topology=True),
}

#: Blender's own attributes compared elsewhere (co, seams)
BUILTIN = {"position", "uv_seam"}
#: ... and those an operator that rebuilds the mesh may add (flat-shading flags)
BUILTIN_TOPOLOGY = {"sharp_face", "sharp_edge"}

TALLY: dict[str, dict[str, str]] = {}


@pytest.fixture(scope="module", autouse=True)
def one_blas_thread():
    """The meshes are tiny: BLAS threads only cost time (on a busy 2-core machine a 200 x 200
    eigh took 1.5 s with them, 0.02 s without)."""
    threadpoolctl = pytest.importorskip("threadpoolctl")
    import scipy.linalg  # noqa: F401,PLC0415 (their BLAS / OpenMP libraries loaded, so the limit reaches them)
    import sklearn.cluster  # noqa: F401,PLC0415

    with threadpoolctl.threadpool_limits(1):
        yield

#: per case and operator: the warnings and the seconds (with the undo / redo check)
DETAIL: dict[str, dict] = {}
TIMES: dict = {}


# ------------------------------------------------------------------------- snapshots
def _get(coll, attr, n, dtype, width=1):
    a = np.empty(n * width, dtype=dtype)
    coll.foreach_get(attr, a)
    return a.reshape(-1, width) if width > 1 else a


def snap(ob) -> dict:
    """Everything of the source that can change: positions, polygons, seams, every attribute's
    values (any type and domain), custom properties, transform."""
    if ob.mode == "EDIT":
        ob.update_from_editmode()
    me = ob.data
    attrs = {}
    for a in me.attributes:
        if a.name.startswith("."):
            continue
        n = len(a.data)
        if a.data_type in ("FLOAT", "INT", "BOOLEAN", "INT8"):
            key = "value"
            width = 1
        elif a.data_type in ("FLOAT_VECTOR",):
            key, width = "vector", 3
        elif a.data_type in ("FLOAT_COLOR", "BYTE_COLOR"):
            key, width = "color", 4
        elif a.data_type == "FLOAT2":
            key, width = "vector", 2
        else:
            attrs[a.name] = (a.domain, a.data_type, n)
            continue
        attrs[a.name] = (a.domain, a.data_type, _get(a.data, key, n, np.float64, width).copy())
    props = {k: (ob[k].to_dict() if hasattr(ob[k], "to_dict") else
                 (list(ob[k]) if hasattr(ob[k], "__len__") and not isinstance(ob[k], str) else ob[k]))
             for k in ob.keys()}
    return {
        "co": _get(me.vertices, "co", len(me.vertices), np.float64, 3).copy(),
        "loops": _get(me.loops, "vertex_index", len(me.loops), np.int64).copy(),
        "starts": _get(me.polygons, "loop_start", len(me.polygons), np.int64).copy(),
        "edges": _get(me.edges, "vertices", len(me.edges), np.int64, 2).copy(),
        "seams": _get(me.edges, "use_seam", len(me.edges), bool).copy(),
        "selected": _get(me.polygons, "select", len(me.polygons), bool).copy(),
        "attrs": attrs,
        "props": props,
        "matrix": np.array(ob.matrix_world),
        "modifiers": [(m.name, m.type) for m in ob.modifiers],
    }


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


def diff(before: dict, after: dict, attrs=(), props=(), seams=False, topology=False) -> list[str]:
    """What changed between two snaps, leaving out what the operator exists to write."""
    out = []
    if topology:
        n0 = len(before["co"])  # new vertices are appended: the old ones keep their index and place
        if len(after["co"]) < n0 or not np.array_equal(after["co"][:n0], before["co"], equal_nan=True):
            out.append("vertex coordinates")
    else:
        for k in ("co", "loops", "starts", "edges", "selected"):
            if not _same(before[k], after[k]):
                out.append(k)
        if not seams and not _same(before["seams"], after["seams"]):
            out.append("seams")
    for k in ("matrix", "modifiers"):
        if not _same(before[k], after[k]):
            out.append(k)
    for name in set(before["attrs"]) | set(after["attrs"]):
        if name in attrs or name in BUILTIN or (topology and name in BUILTIN_TOPOLOGY):
            continue
        if name not in before["attrs"] or name not in after["attrs"]:
            out.append(f"attribute {name} added or removed")
        elif not topology and not _same(before["attrs"][name], after["attrs"][name]):
            out.append(f"attribute {name}")
    for k in set(before["props"]) | set(after["props"]):
        if k not in props and before["props"].get(k, "<none>") != after["props"].get(k, "<none>"):
            out.append(f"property {k}")
    return out


# ------------------------------------------------------------------------ validity
def _finite_co(me, what):
    co = _get(me.vertices, "co", len(me.vertices), np.float64, 3)
    assert len(co) and np.isfinite(co).all(), f"{what}: non-finite coordinates"
    return co


def _tris(me):
    me.calc_loop_triangles()
    return _get(me.loop_triangles, "vertices", len(me.loop_triangles), np.int64, 3)


def _closed(F) -> tuple[int, int, int]:
    """(boundary, non-manifold, inconsistently wound) edges of triangles F (m,3): computed here,
    independently of the add-on's own check."""
    he = np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2)
    key = np.sort(he, axis=1)
    uk, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    fwd = np.bincount(inv, weights=(he[:, 0] < he[:, 1]).astype(float), minlength=len(uk))
    return int((cnt == 1).sum()), int((cnt > 2).sum()), int(((cnt == 2) & (fwd != 1)).sum())


def check_valid(bpy, op, ob, tmp_path, kw) -> None:
    """The output of a FINISHED operator is usable, not only present."""
    me = ob.data
    npoly, nv = len(me.polygons), len(me.vertices)
    if op == "saliency_preview":
        for name in ("bolus_flattenability", "bolus_saliency"):
            a = me.attributes[name]
            assert (a.domain, a.data_type, len(a.data)) == ("POINT", "FLOAT", nv), name
            v = attr_array(me, name)
            assert np.isfinite(v).all(), name
        assert (attr_array(me, "bolus_flattenability") >= 0).all()
        assert me.attributes["bolus_saliency_color"].domain == "POINT"
        assert math.isfinite(ob["bolus_sum_varpi"]) and ob["bolus_sum_varpi"] >= 0
        assert math.isfinite(ob["bolus_flv"])
    elif op in ("segment", "smooth_cuts"):
        a = me.attributes["bolus_patch"]
        assert (a.domain, a.data_type, len(a.data)) == ("FACE", "INT", npoly)
        lab = attr_array(me, "bolus_patch", np.int64)
        table = json.loads(ob["bolus_patch_table"])
        k = len(table["patches"])
        assert lab.min() >= -1 and lab.max() == k - 1 and set(range(k)) <= set(lab.tolist())
        if op == "smooth_cuts":
            _finite_co(me, "the cut mesh")
            assert not me.validate(verbose=False), "the cut mesh needed repairs"
            for row in table["patches"]:
                assert all(math.isfinite(row[c]) for c in ("area_mm2", "sum_varpi", "flv")), row
    elif op == "improve_flattenability":
        imp = bpy.data.objects[ob.name + "_improved"]
        co = _finite_co(imp.data, "the improved surface")
        assert len(imp.data.polygons) == npoly and len(co) == nv
        gap = attr_array(imp.data, "bolus_air_gap")
        assert len(gap) == nv and np.isfinite(gap).all()
        assert gap.min() >= -1e-6 and gap.max() <= kw["max_gap_mm"] + 1e-3, (gap.min(), gap.max())
    elif op == "unfold":
        pat = bpy.data.objects[ob.name + "_pattern"]
        co = _finite_co(pat.data, "the pattern")
        assert np.abs(co[:, 2]).max() == 0.0
        src = attr_array(pat.data, "bolus_source_face", np.int64)
        assert len(src) == len(pat.data.polygons) and src.min() >= 0 and src.max() < npoly
        table = json.loads(pat["bolus_pattern_table"])
        assert math.isfinite(table["EL"]) and math.isfinite(table["EA"])
        assert table["pieces"] >= 1 and len(table["islands"]) == table["pieces"]
        # every island has a positive area (no island collapsed to a point or a line)
        tris = _tris(pat.data)
        P = co[tris][:, :, :2]
        a, b = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
        area = 0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
        # true size: the pattern's area is the source's in world space (object scale and rotation applied,
        # the mesh data without modifiers), up to the unfolding's area error
        M = np.array(ob.matrix_world)
        W = _get(me.vertices, "co", nv, np.float64, 3) @ M[:3, :3].T
        T = _tris(me)
        skin = 0.5 * np.linalg.norm(np.cross(W[T[:, 1]] - W[T[:, 0]], W[T[:, 2]] - W[T[:, 0]]), axis=1).sum()
        assert area.sum() == pytest.approx(skin, rel=0.03), (area.sum(), skin)
    elif op == "export_pattern":
        path = tmp_path / "pattern.svg"
        assert path.stat().st_size > 0
        root = ET.parse(path).getroot()
        assert root.tag.endswith("svg")
        shapes = [e for e in root.iter() if e.tag.rsplit("}", 1)[-1] in ("path", "polygon", "polyline")]
        assert shapes, "no outline in the SVG"
        for e in shapes:
            nums = re.findall(r"-?\d+(?:\.\d+)?(?:e-?\d+)?|nan|inf", e.get("d", "") + e.get("points", ""), re.I)
            assert "nan" not in [n.lower() for n in nums] and "inf" not in [n.lower() for n in nums]
    elif op == "make_shell":
        bol = bpy.data.objects[ob.name + "_bolus"]
        co = _finite_co(bol.data, "the bolus")
        boundary, nonmanifold, inconsistent = _closed(_tris(bol.data))
        assert (boundary, nonmanifold, inconsistent) == (0, 0, 0), "the bolus is not a closed manifold solid"
        assert bol["bolus_volume_cm3"] > 0 if "bolus_volume_cm3" in bol else True
        F = _tris(bol.data)
        vol = np.einsum("ij,ij->i", co[F[:, 0]], np.cross(co[F[:, 1]], co[F[:, 2]])).sum() / 6.0
        assert vol > 0, "the bolus is wound inwards"
    elif op == "print_segment":
        a = me.attributes["bolus_print_part"]
        assert (a.domain, a.data_type, len(a.data)) == ("FACE", "INT", npoly)
        lab = attr_array(me, "bolus_print_part", np.int64)
        table = json.loads(ob["bolus_print_table"])
        k = len(table["parts"])
        assert lab.min() >= -1 and lab.max() == k - 1
    elif op == "orient_parts":
        parts = [o for o in bpy.data.objects if o.name.startswith(ob.name + "_part_")]
        assert parts
        for p in parts:
            co = _finite_co(p.data, p.name)
            M = np.array(p.matrix_world)
            W = co @ M[:3, :3].T + M[:3, 3]
            assert abs(W[:, 2].min()) < 1e-3, f"{p.name} does not rest on the plate (z min {W[:, 2].min()})"
            d = np.array(p["bolus_print_direction"])
            assert np.isfinite(d).all() and abs(np.linalg.norm(d) - 1) < 1e-6
    elif op == "export_parts":
        files = sorted((tmp_path / "parts").glob("*.stl"))
        assert files
        for f in files:
            data = f.read_bytes()
            (n,) = struct.unpack_from("<I", data, 80)
            assert n > 0 and len(data) == 84 + 50 * n, f.name
            tri = np.frombuffer(data[84:], dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
            assert np.isfinite(tri["v"]).all() and abs(tri["v"][:, :, 2].min()) < 1e-3, f.name
    elif op == "select_area":  # (the mode, Edit Mode, is checked by run_chain)
        _finite_co(me, "the mesh after the area's cut")
        sel = _get(me.polygons, "select", len(me.polygons), bool)
        assert 0 < sel.sum() <= len(sel)
        assert not me.validate(verbose=False), "the cut mesh needed repairs"


# ---------------------------------------------------------------------------- running
def _activate(bpy, ob):
    for o in list(bpy.context.selected_objects):
        if o is not ob:
            o.select_set(False)
    bpy.context.view_layer.objects.active = ob
    ob.select_set(True)


def _cursor_on_top(bpy, ob):
    """The 3D cursor on the dome's top vertex (world space; any vertex for the small cases)."""
    me = ob.data
    k = vid(5, 5) if len(me.vertices) > vid(5, 5) else 0
    co = np.array(me.vertices[k].co)
    if not np.isfinite(co).all():
        co = np.array(me.vertices[0].co)
    M = np.array(ob.matrix_world)
    bpy.context.scene.cursor.location = tuple(M[:3, :3] @ co + M[:3, 3])


def run_op(bpy, op, kw) -> tuple[str, str]:
    """("FINISHED" | "REFUSED" | "UNEXPECTED", message)."""
    try:
        res = getattr(bpy.ops.bolus, op)("EXEC_DEFAULT", True, **kw)
    except RuntimeError as exc:
        msg = str(exc).strip()
        msg = re.sub(r"^Error:\s*", "", msg)
        return ("UNEXPECTED" if "Unexpected error" in msg else "REFUSED"), msg
    return ("FINISHED" if res == {"FINISHED"} else f"RETURNED {res}"), ""


def run_chain(bpy, name, tmp_path, capfd):
    """The case through `CHAIN`; returns the case, {op: (status, message, warnings)} and the problems found."""
    case = CASES[name](bpy)
    src = case.obj.name
    (tmp_path / "parts").mkdir()
    results, problems = {}, []
    for op, kw in CHAIN:
        t0 = time.perf_counter()
        kw = dict(kw)
        if op == "export_pattern":
            kw["filepath"] = str(tmp_path / "pattern.svg")
        elif op == "export_parts":
            kw["directory"] = str(tmp_path / "parts")
        ob = bpy.data.objects[src]
        _activate(bpy, ob)
        if op == "select_area":
            _cursor_on_top(bpy, ob)
        before = snap(ob)
        writes = WRITES.get(op)
        if writes:
            bpy.ops.ed.undo_push(message=f"before {op}")
        capfd.readouterr()
        status, msg = run_op(bpy, op, kw)
        warnings = re.findall(r"^Warning: (.*)$", capfd.readouterr().out, re.M)
        results[op] = (status, msg, warnings)
        ob = bpy.data.objects[src]
        want_mode = "EDIT" if op == "select_area" and status == "FINISHED" else case.mode
        if ob.mode != want_mode:
            problems.append(f"{op}: left the source in {ob.mode} mode, not {want_mode}")
        after = snap(ob)
        changed = diff(before, after, **(writes if writes and status == "FINISHED" else {}))
        if changed:
            problems.append(f"{op} ({status}): changed {', '.join(changed)} of the source")
        if status == "FINISHED":
            if writes:
                t1 = time.perf_counter()
                problems += check_undo(bpy, op, src, before, after, want_mode)
                TIMES[(name, op, "undo")] = time.perf_counter() - t1
            ob = bpy.data.objects[src]
            try:
                with object_mode(bpy, ob):  # attribute data is empty in Edit Mode
                    check_valid(bpy, op, ob, tmp_path, kw)
            except AssertionError as exc:
                problems.append(f"{op}: invalid output: {exc}")
        TIMES[(name, op)] = time.perf_counter() - t0
    return case, results, problems


@contextlib.contextmanager
def object_mode(bpy, ob):
    mode = ob.mode
    if mode != "OBJECT":
        bpy.ops.object.mode_set(mode="OBJECT")
    try:
        yield
    finally:
        if mode != "OBJECT":
            bpy.ops.object.mode_set(mode=mode)


def check_undo(bpy, op, src, before, after, mode) -> list[str]:
    """Ctrl+Z gives the source back as it was before `op`, Ctrl+Shift+Z gives the result back.

    In Edit Mode Blender's undo steps hold the edit mesh only: the object's custom properties
    (the tables an operator writes) are not part of them, so there only the mesh is compared."""
    out = []
    ignore = {"props": set(before["props"]) | set(after["props"])} if mode == "EDIT" else {}
    if bpy.ops.ed.undo() != {"FINISHED"}:
        return [f"{op}: undo did not run"]
    ob = bpy.data.objects[src]  # undo reloads the data-blocks
    changed = diff(before, snap(ob), **ignore)
    if changed:
        out.append(f"{op}: undo did not restore {', '.join(changed)}")
    if bpy.ops.ed.redo() != {"FINISHED"}:
        return out + [f"{op}: redo did not run"]
    ob = bpy.data.objects[src]
    changed = diff(after, snap(ob), **ignore)
    if changed:
        out.append(f"{op}: redo did not give back {', '.join(changed)}")
    if ob.mode != mode:
        out.append(f"{op}: after undo/redo the source is in {ob.mode} mode, not {mode}")
    return out


# ------------------------------------------------------------------------ expectations
F = "FINISHED"
NO_PATCHES = r"'skin' has no 'bolus_patch' attribute: run Segment into Patches first"
NO_PATTERN = r"'skin' has no pattern yet: run Unfold Patches first"
NO_PARTS = r"'skin' has no print parts yet: run Orient Print Parts first"
NONMANIFOLD = (r"has 1 non-manifold edges \(e\.g\. between vertices {a} and {b}\); a bolus must be a manifold surface: "
               r"find them with Select > Select All by Trait > Non Manifold and delete the extra faces there")
NONMANIFOLD_PATCH = (r"1 non-manifold edge\(s\) \(shared by more than two triangles\), e\.g\. the edge between "
                     r"vertices {a} and {b}; Select > Select All by Trait > Non Manifold shows them: delete the extra "
                     r"faces there")
ZERO_AREA = (r"the region has 1 zero-area triangle\(s\), e\.g\. the triangle on vertices 0, {n1}, {n0}: coincident or "
             r"collinear vertices; merge them first \(Mesh > Clean Up > Merge by Distance, then Degenerate Dissolve\)")
NAN = (rf"vertex {NAN_VERTEX} of 'skin' has an invalid coordinate \(-?[\d.]+, -?[\d.]+, nan\): a bolus needs finite "
       r"coordinates; delete or fix such vertices first")
PARTS = (r"the region is made of {k} separate parts \({sizes} faces\); segment one connected part at a time "
         r"\(select its faces in Edit Mode: L over it\), or, where the parts should be one surface, join them at their "
         r"duplicated vertices first \(Mesh > Clean Up > Merge by Distance\)")
_nm = dict(a=NM_EDGE[0], b=NM_EDGE[1])
_n = vid(10, 10) + 1  # the dome's vertex count: the sliver's vertices are the next two
#: what each case must give at each step: FINISHED, or a regex the refusal's message matches
#: (which problem, where, what to do).  Missing entries: FINISHED.
EXPECT: dict[str, dict[str, str]] = {
    "nonmanifold_edge": {
        "segment": NONMANIFOLD.format(**_nm), "smooth_cuts": NO_PATCHES,
        "improve_flattenability": NONMANIFOLD.format(**_nm),
        "unfold": "patch 0: the patch has " + NONMANIFOLD_PATCH.format(**_nm),
        "export_pattern": NO_PATTERN, "make_shell": NONMANIFOLD.format(**_nm),
        "select_area": "the surface near the cursor has " + NONMANIFOLD_PATCH.format(**_nm),
    },
    "zero_area": {
        **{op: ZERO_AREA.format(n0=_n, n1=_n + 1)
           for op in ("saliency_preview", "segment", "improve_flattenability", "unfold", "make_shell", "print_segment",
                      "orient_parts")},
        "smooth_cuts": NO_PATCHES, "export_pattern": NO_PATTERN, "export_parts": NO_PARTS,
    },
    "duplicate_vertices": {"segment": PARTS.format(k=2, sizes="50, 50"), "smooth_cuts": NO_PATCHES},
    "pieces": {"segment": PARTS.format(k=3, sizes="36, 36, 25"), "smooth_cuts": NO_PATCHES},
    "one_triangle": {
        "segment": r"the region has 1 faces, fewer than the 2 patches asked: ask for at most 1 or select a larger "
                   r"region",
        "smooth_cuts": NO_PATCHES,
        "improve_flattenability": r"the region has no interior vertices: every vertex is on its border, which stays "
                                  r"fixed, so nothing can move \(select a larger area\)",
        "unfold": r"patch 0: the patch has 1 triangle\(s\); at least 3 are needed to unfold it: segment into fewer "
                  r"patches or select a larger region",
        "export_pattern": NO_PATTERN,
        "print_segment": r"the mesh has 1 faces, fewer than the 2 parts asked: ask for at most 1 or select a larger "
                         r"region",
    },
    "flipped_normals": {
        "improve_flattenability": r"the region's faces are not consistently oriented \(\d+ of its \d+ triangles points? "
                                  r"the other way\), so 'outward' is not defined: recalculate the normals first "
                                  r"\(Mesh > Normals > Recalculate Outside\)",
        "unfold": r"patch \d: the patch's faces are not consistently oriented \(\d+ of its \d+ triangles points? the "
                  r"other way\): recalculate the normals first \(Mesh > Normals > Recalculate Outside\)",
        "export_pattern": NO_PATTERN,
        "make_shell": r"the region's faces are not consistently oriented \(\d+ of its \d+ triangles points? the other "
                      r"way; e\.g\. at the edge between vertices \d+ and \d+\): recalculate the normals \(Mesh > "
                      r"Normals > Recalculate Outside\)",
    },
    "nan": {
        **{op: NAN for op in ("saliency_preview", "segment", "improve_flattenability", "unfold", "make_shell",
                              "print_segment", "orient_parts", "select_area")},
        "smooth_cuts": NO_PATCHES, "export_pattern": NO_PATTERN, "export_parts": NO_PARTS,
    },
}
#: warnings a step must give (a regex per step)
READS = ("saliency_preview", "segment", "improve_flattenability", "unfold", "make_shell", "print_segment",
         "orient_parts")
WARN: dict[str, dict[str, str]] = {
    "modifiers": {op: r"'skin' has 2 modifier\(s\) \(Subdivision, Displace\) that the bolus tools do not see: they "
                      r"work on the mesh as it is without them \(as in Edit Mode\); to use the shape shown, apply them "
                      r"first \(Object > Apply > Visual Geometry to Mesh\)"
                  for op in READS + ("smooth_cuts", "select_area")},
    "loose": {op: r"5 loose vertices \(in no face\) were ignored" for op in READS},
    "duplicate_vertices": {op: r"1 loose vertices \(in no face\) were ignored" for op in READS if op != "segment"},
    "edit_nothing_selected": {op: r"No faces selected in Edit Mode: using the whole mesh" for op in READS},
    "nonmanifold_edge": {"saliency_preview": r"1 non-manifold edges \(e\.g\. between vertices {a} and {b}\): their "
                                             r"vertices are treated like boundary vertices".format(**_nm)},
}


def test_misoriented_faces():
    """The count the winding refusals give (topology.misoriented_faces): the minority of each piece."""
    from badmesh import arrays
    from bolus_addon.core.mesh.topology import misoriented_faces, misoriented_text

    def tris(polys):
        return np.array([[p[0], p[k], p[k + 1]] for p in polys for k in range(1, len(p) - 1)])

    (_, Q), _ = arrays("clean")
    F = tris(Q)
    assert not misoriented_faces(F).any()
    (_, Q), _ = arrays("flipped_normals")
    bad = misoriented_faces(tris(Q))
    np.testing.assert_array_equal(np.nonzero(bad)[0], np.arange(140, 200))  # the 30 turned quads 70..99
    assert misoriented_text(tris(Q)) == "60 of its 200 triangles point the other way"
    one = F.copy()
    one[7] = one[7, ::-1]
    assert misoriented_text(one) == "1 of its 200 triangles points the other way"
    assert not misoriented_faces(np.r_[F, F[::-1, ::-1] + F.max() + 1]).any()  # two pieces, each consistent
    n = 8  # a Moebius strip cannot be wound consistently: every triangle is flagged
    Q = [[k, n + k, n + k + 1, k + 1] for k in range(n - 1)] + [[n - 1, 2 * n - 1, 0, n]]
    assert misoriented_faces(tris(Q)).all()


@pytest.mark.parametrize("name", list(CASES))
def test_corpus_case(bpy_addon, scene, tmp_path, name, capfd):
    bpy = bpy_addon
    case, results, problems = run_chain(bpy, name, tmp_path, capfd)
    TALLY[name] = {op: (s if s != "REFUSED" else f"refused: {m}") for op, (s, m, _) in results.items()}
    DETAIL[name] = {op: {"warnings": w, "seconds": round(TIMES[(name, op)], 3)} for op, (_, _, w) in results.items()}
    # the case's table (pytest shows it when the test fails)
    print(f"\n[{name}]")
    for op, (s, m, w) in results.items():
        print(f"  {op:24s} {s} {m}")
        for x in w:
            print(f"  {'':24s}   warning: {x}")
    for p in problems:
        print("  PROBLEM:", p)
    unexpected = {op: m for op, (s, m, _) in results.items() if s not in ("FINISHED", "REFUSED")}
    assert not unexpected, unexpected
    assert not problems, problems
    want = EXPECT.get(name, {})
    for op, (s, m, _) in results.items():
        exp = want.get(op, F)
        if exp == F:
            assert s == F, f"{op} on {name}: {s} {m}"
        else:
            assert s == "REFUSED" and re.search(exp, m), f"{op} on {name}: {s} {m!r} does not match {exp!r}"
    for op, exp in WARN.get(name, {}).items():
        warnings = results[op][2]
        assert any(re.search(exp, w) for w in warnings), f"{op} on {name}: no warning {exp!r} in {warnings}"


def test_tally(tmp_path_factory, capfd):
    """The tally of the cases run in this session (written as JSON, printed)."""
    if not TALLY:
        pytest.skip("no corpus case ran")
    cells = [v for row in TALLY.values() for v in row.values()]
    fin = sum(v == F for v in cells)
    ref = sum(v.startswith("refused") for v in cells)
    unexp = len(cells) - fin - ref
    summary = f"{fin} finished, {ref} refused, {unexp} unexpected ({len(TALLY)} cases x {len(OPS)} operators)"
    path = tmp_path_factory.getbasetemp() / "corpus_tally.json"
    path.write_text(json.dumps({"summary": summary, "table": TALLY, "detail": DETAIL}, indent=1))
    with capfd.disabled():
        print(f"\ncorpus tally: {summary}; table in {path}")
    assert unexp == 0


#: print_segment(method='LEARNED') where it must refuse (else it finishes); the rest as the ABcut run
LEARNED_EXPECT = {
    "zero_area": ZERO_AREA.format(n0=_n, n1=_n + 1),
    "nan": NAN,
    "one_triangle": r"the region has 1 triangles and no 15 of them connected: too small for the learned split "
                    r"\(sub-graphs of 30 triangles\); use ABcut",
}


@pytest.mark.parametrize("name", list(CASES))
def test_learned_split_on_corpus_case(bpy_addon, scene, tmp_path, name, capfd):
    """The learned print split on every bad mesh: valid parts, or a refusal naming the problem;
    the source changed only where the split writes, undone in one step, the user's mode kept."""
    bpy = bpy_addon
    case = CASES[name](bpy)
    ob = case.obj
    src = ob.name
    _activate(bpy, ob)
    before = snap(ob)
    bpy.ops.ed.undo_push(message="before the learned split")
    status, msg = run_op(bpy, "print_segment", {"method": "LEARNED"})
    ob = bpy.data.objects[src]
    assert ob.mode == case.mode
    exp = LEARNED_EXPECT.get(name)
    if exp is None:
        assert status == F, f"{name}: {status} {msg}"
    else:
        assert status == "REFUSED" and re.search(exp, msg), f"{name}: {status} {msg!r} does not match {exp!r}"
    after = snap(ob)
    changed = diff(before, after, **(WRITES["print_segment"] if status == F else {}))
    assert not changed, changed
    if status == F:
        problems = check_undo(bpy, "print_segment", src, before, after, case.mode)
        assert not problems, problems
        ob = bpy.data.objects[src]
        with object_mode(bpy, ob):
            check_valid(bpy, "print_segment", ob, tmp_path, {})
            lab = attr_array(ob.data, "bolus_print_part", np.int64)
            assert_labels_connected(ob.data, np.where(lab >= 0, lab, -1), "print part")
