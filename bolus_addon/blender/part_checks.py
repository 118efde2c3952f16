"""What Orient and Export Print Parts do differently on a bolus solid's parts.

On a bolus solid (``<name>_bolus``, with ``bolus_shell_side``) "skin side up" means the inner
face (SIDE_INNER, against the skin) up, every part is checked closed (core.solid.closed_report,
SPEC: every edge two faces, opposite directions) when it is oriented and when its STL is
written, and the STL names carry the bolus's label.  On a surface these helpers change nothing.
"""
from __future__ import annotations

import re

import bpy
import numpy as np

from ..core.errors import BolusError
from ..core.mesh.topology import MeshTopology
from ..core.solid.manifold import SIDE_INNER, closed_report
from . import mesh_io, mesh_region
from .objects import ATTR_SHELL_SIDE, PART_INFIX, PROP_LABEL, PROP_PART_SOURCE, is_bolus_object


def part_arrays(V, F, mask):
    """(V, F) of the triangles F[mask] on their own vertices."""
    F = np.asarray(F)[mask]
    used, inv = np.unique(F, return_inverse=True)
    return np.asarray(V)[used], inv.reshape(-1, 3)


def closed_warnings(reports, names=None) -> list[str]:
    """WARNING text for every part that is not closed (closed_report dicts, one per part)."""
    out = []
    for p, r in enumerate(reports):
        if r["closed"]:
            continue
        what = names[p] if names else f"part {p}"
        out.append(f"{what} is not closed: {r['boundary_edges']} open edges, {r['nonmanifold_edges']} non-manifold "
                   f"and {r['inconsistent_edges']} inconsistently wound edges; a slicer may refuse it")
    return out


def read_parts_region(op, context):
    """`BolusOperator.read_region` for orient_parts; on a bolus solid without the zero-area refusal:
    the booleans that cut and engrave it leave a few slivers (their area is 0 or nearly so, so
    they add nothing to WQ / WU: the orientation core takes them), and they do not open the solid."""
    if not is_bolus_object(context.active_object):
        return op.read_region(context, allow_nonmanifold=True)
    region = mesh_region.read_region(context)
    return region, MeshTopology(region.V, region.F), list(region.warnings)


def orient_options(region, tri_labels, skin_side_up: bool) -> dict:
    """Keyword arguments for `orient_print_parts`: on a bolus solid "skin side up" favours the
    direction its inner face (SIDE_INNER, against the skin) looks to, so that face comes out on
    top, smooth (the open-surface rule would see the normals of a closed solid cancel out)."""
    if not skin_side_up or not is_bolus_object(region.obj):
        return {"skin_side_up": skin_side_up}
    side = mesh_io.read_face_labels(region.obj, ATTR_SHELL_SIDE)[region.tri_poly]
    P = region.V[region.F[side == SIDE_INNER]]
    if not len(P):
        raise BolusError(f"'{region.obj.name}' has no inner (skin-side) faces: untick 'Skin side up'")
    n = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]).sum(axis=0)  # area-weighted normal sum
    if not np.linalg.norm(n) > 0:
        raise BolusError("the bolus's inner face has no prevailing direction: untick 'Skin side up'")
    return {"skin_side_up": False, "favour": n / np.linalg.norm(n)}


def closed_lines(region, tri_labels) -> tuple[list[str], list[str]]:
    """(INFO lines, WARNINGs): "closed" or why not for each part of a bolus solid; ([], []) for a surface."""
    if not is_bolus_object(region.obj):
        return [], []
    ids = np.unique(tri_labels[tri_labels >= 0])
    reports = [closed_report(*part_arrays(region.V, region.F, tri_labels == p)) for p in ids]
    names = [f"{region.obj.name}{PART_INFIX}{p}" for p in ids]
    info = [f"{n}: closed, {abs(r['volume_mm3']) / 1000:.1f} cm³" for n, r in zip(names, reports) if r["closed"]]
    return info, closed_warnings(reports, names)


def part_closed_report(context, part) -> dict:
    """closed_report of a part object's evaluated mesh (world mm) as a slicer reads its STL: vertices
    with equal float32 coordinates are one vertex (a triangle collapsed by that is not closed)."""
    ev = part.evaluated_get(context.evaluated_depsgraph_get())
    me = ev.to_mesh()
    try:
        co = mesh_io.get_array(me.vertices, "co", len(me.vertices), np.float64, 3)
        me.calc_loop_triangles()
        F = mesh_io.get_array(me.loop_triangles, "vertices", len(me.loop_triangles), np.int64, 3)
    finally:
        ev.to_mesh_clear()
    W = mesh_io.world_mm(co, part, mesh_io.mm_per_unit(context.scene))
    _, first, inv = np.unique(W.astype(np.float32), axis=0, return_index=True, return_inverse=True)
    return closed_report(W[first], inv.reshape(-1)[F])


def stl_file_name(part) -> str:
    """``<part name>.stl``, prefixed by the bolus's label when it has one (``<label>_<name>_bolus_part_<i>.stl``)."""
    src = bpy.data.objects.get(part.get(PROP_PART_SOURCE, ""))
    label = str(src.get(PROP_LABEL, "")) if src is not None else ""
    label = re.sub(r"[^A-Za-z0-9._-]+", "_", label).strip("._")
    return f"{label}_{part.name}.stl" if label else f"{part.name}.stl"


def export_note(context, part, file_name: str) -> tuple[str, str]:
    """(report level, text) saying whether the exported solid part is closed (SPEC)."""
    r = part_closed_report(context, part)
    if r["closed"]:
        return "INFO", f"{file_name}: closed, {abs(r['volume_mm3']) / 1000:.1f} cm³"
    return "WARNING", closed_warnings([r], [file_name])[0]
