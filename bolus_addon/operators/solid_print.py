"""The printing operators' work on a bolus solid (``<name>_bolus``, made by `make_shell`; issue 11 points 2-3).

`print_ops.BOLUS_OT_print_segment.run` hands over to `print_segment_solid` when the active
object carries ``bolus_shell_side``: the skin region stored with the bolus is split by the
area-balanced cut (core.print_segmentation, seed 6.2), `core.solid_parts.split_solid` cuts the
plain stored solid along one SVM plane per pair of neighbouring parts (eqs. 6-38..6-40) and adds
the peg / hole connectors (6.4.3), each part gets "<label> <i>" and the L / R markers engraved,
and the parts replace the bolus object's mesh (face attributes ``bolus_print_part`` and
``bolus_shell_side``, the connectors as JSON in ``bolus_connectors``).  Re-running starts again
from the stored plain solid.

`orient_parts` / `export_parts` then work as on a surface; the helpers here give them what
differs for solids: "skin side up" means the inner face (SIDE_INNER) up, every part is checked
closed (core.solid.closed_report, SPEC: every edge two faces, opposite directions), and STL
names carry the label.
"""
from __future__ import annotations

import json
import re
from types import SimpleNamespace

import bpy
import numpy as np

from ..blender import mesh_io
from ..core.colormap import categorical_linear_rgba
from ..core.solid.engrave import strings_needed
from ..core.errors import BolusError
from ..core.printing.segmentation import print_segmentation
from ..core.solid.manifold import SIDE_INNER, closed_report, weld_short_edges
from ..core.mesh.topology import MeshTopology
from .solid import (
    ATTR_SHELL_SIDE,
    PROP_LABEL,
    engrave_with,
    label_outlines,
    left_vector,
    PROP_SKIN_MESH,
    PROP_SOLID_MESH,
    PROP_SOURCE,
    engrave,
    is_bolus_object,
    read_tri_mesh,
    remove_mesh,
    tri_mesh,
)

ATTR_PRINT_PART = "bolus_print_part"  # SPEC (print_ops has the same name)
ATTR_PRINT_PART_COLOR = "bolus_print_part_color"
PROP_PRINT_TABLE = "bolus_print_table"
PROP_CONNECTORS = "bolus_connectors"
DEFAULT_CONNECTOR_CLEARANCE = 0.2


def stored_solid(obj, mm: float):
    """(skin V, skin F, solid V, solid F, solid side) in mm from the datablocks a bolus names."""
    meshes = []
    for key in (PROP_SKIN_MESH, PROP_SOLID_MESH):
        me = bpy.data.meshes.get(obj.get(key, ""))
        if me is None:
            raise BolusError(f"'{obj.name}' has lost its stored {key.removeprefix('bolus_').replace('_', ' ')} "
                             f"('{obj.get(key, '')}'): run Make Bolus again on '{obj.get(PROP_SOURCE, 'the skin')}'")
        meshes.append(me)
    skin_V, skin_F = read_tri_mesh(meshes[0], mm)
    V, F = read_tri_mesh(meshes[1], mm)
    side = mesh_io.read_face_labels(meshes[1], ATTR_SHELL_SIDE)
    if side is None:
        raise BolusError(f"the stored solid '{meshes[1].name}' has no '{ATTR_SHELL_SIDE}': run Make Bolus again")
    return skin_V, skin_F, V, F, side


def connectors_json(parts) -> str:
    """The joints and their connectors (core.solid_parts) as JSON (mm, world frame)."""
    def vec(a):
        return [float(x) for x in np.asarray(a).ravel()]

    return json.dumps([{
        "parts": [int(p) for p in j.parts], "normal": vec(j.normal), "offset": float(j.offset),
        "area_mm2": float(j.area_mm2), "note": j.note,
        "connectors": [{"parts": [int(p) for p in c.parts], "centre": vec(c.centre), "axis": vec(c.axis),
                        "peg_radius": float(c.peg_radius), "hole_radius": float(c.hole_radius),
                        "peg_length": float(c.peg_length), "hole_depth": float(c.hole_depth)}
                       for c in j.connectors],
    } for j in parts.joints])


def joint_lines(parts) -> list[str]:
    out = []
    for j in parts.joints:
        a, b = (int(p) for p in j.parts)
        head = f"Joint {a}|{b}: {j.area_mm2 / 100:.1f} cm² plane"
        if not j.connectors:
            out.append(f"{head}, plain ({j.note or 'no connector'})")
            continue
        c = j.connectors[0]
        out.append(f"{head}, {len(j.connectors)} connector{'s' if len(j.connectors) != 1 else ''}: peg Ø "
                   f"{2 * c.peg_radius:.1f} x {c.peg_length:.1f} mm on part {int(c.parts[0])}, hole Ø "
                   f"{2 * c.hole_radius:.1f} x {c.hole_depth:.1f} mm in part {int(c.parts[1])}")
    return out


def print_segment_solid(op, context) -> set[str]:
    """`print_segment` on a bolus solid (op: the BOLUS_OT_print_segment with parts, method, seed):
    `prepare_solid`, `compute_solid`, `finish_solid` in a row."""
    job = prepare_solid(op, context)
    return finish_solid(op, context, job, compute_solid(job, op.progress))


def prepare_solid(op, context) -> SimpleNamespace:
    """What `compute_solid` needs, read in the main thread: the stored skin and solid (mm), the
    settings, and the label's outlines from Blender's font for up to the asked number of parts."""
    obj = mesh_io.active_mesh_object(context)
    mm = mesh_io.mm_per_unit(context.scene)
    settings = getattr(context.scene, "bolus", None)
    clearance = float(getattr(settings, "connector_clearance_mm", DEFAULT_CONNECTOR_CLEARANCE))
    skin_V, skin_F, V, F, side = stored_solid(obj, mm)
    label = str(obj.get(PROP_LABEL, ""))
    # the parts may come out more than asked (a cluster that fell apart): outlines for a few extra numbers
    outlines = label_outlines(label, int(op.parts) + 4) if label else None
    return SimpleNamespace(solid=True, obj=obj, mm=mm, clearance=clearance, skin_V=skin_V, skin_F=skin_F, V=V, F=F,
                           side=side, label=label, outlines=outlines, left=left_vector(context),
                           parts=int(op.parts), method=op.method.lower(), seed=int(op.seed))


def compute_solid(job, progress):
    """bpy-free: the skin split, the solid cut with connectors, engraved; (seg, parts, PV, PF, pside,
    plabels, warnings, closed reports)."""
    from ..core.solid.parts import split_solid  # noqa: PLC0415

    progress(0.0, "splitting the skin")
    seg = print_segmentation(job.skin_V, job.skin_F, job.parts, method=job.method, rng=job.seed,
                             progress=lambda f, t: progress(0.2 * f, t))
    parts = split_solid(job.V, job.F, job.side, job.skin_V, job.skin_F, seg.labels, clearance=job.clearance,
                        progress=lambda f, t: progress(0.2 + 0.6 * f, t))
    PV, PF, pside, plabels = parts.V, parts.F, np.asarray(parts.side), np.asarray(parts.labels)
    warnings = [m for m in [seg.count_note()] if m] + list(parts.warnings)
    k = int(plabels.max()) + 1
    if job.label and all(s in job.outlines for s in strings_needed(job.label, k)):
        progress(0.85, "engraving the labels")
        PV, PF, pside, plabels, notes = engrave_with(PV, PF, pside, job.outlines, job.label, job.left,
                                                     part_labels=plabels)
        pside, plabels = np.asarray(pside), np.asarray(plabels)
        warnings += list(notes)
        engraved = True
    else:  # no label, or more parts than outlines read: finish_solid engraves (Blender's font, main thread)
        engraved = not job.label
    closed = [closed_report(*_part_arrays(PV, PF, plabels == p)) for p in range(k)] if engraved else None
    return seg, parts, PV, PF, pside, plabels, warnings, closed


def finish_solid(op, context, job, result) -> set[str]:
    """The parts replace the bolus object's mesh (main thread), with the tables and reports."""
    seg, parts, PV, PF, pside, plabels, warnings, closed = result
    obj, mm, clearance, skin_V, skin_F = job.obj, job.mm, job.clearance, job.skin_V, job.skin_F
    if closed is None:  # not engraved yet (see compute_solid)
        op.progress(0.85, "engraving the labels")
        PV, PF, pside, plabels, notes = engrave(context, PV, PF, pside, job.label, part_labels=plabels)
        pside, plabels = np.asarray(pside), np.asarray(plabels)
        warnings = warnings + list(notes)
        closed = [closed_report(*_part_arrays(PV, PF, plabels == p)) for p in range(int(plabels.max()) + 1)]
    # slivers whose shortest edge float32 cannot hold would collapse in Blender's mesh and in the STL
    PV, PF, keep = weld_short_edges(PV, PF)
    pside, plabels = pside[keep], plabels[keep]
    if not keep.all():
        closed = [closed_report(*_part_arrays(PV, PF, plabels == p)) for p in range(len(closed))]
    k = len(closed)
    op.progress(0.95, "writing the parts")
    with mesh_io.object_mode(obj):
        me = tri_mesh(obj.name, PV / mm, PF)
        try:
            mesh_io.write_attribute(me, ATTR_PRINT_PART, "INT", "FACE", plabels)
            mesh_io.write_attribute(me, ATTR_SHELL_SIDE, "INT", "FACE", pside)
            mesh_io.write_face_colors(me, ATTR_PRINT_PART_COLOR, categorical_linear_rgba(plabels))
        except Exception:
            remove_mesh(me)
            raise
        old = obj.data
        obj.data = me
        if old.users == 0:
            remove_mesh(old)
        me.name = obj.name
    table = seg.table(skin_V, skin_F)
    table.update(method=op.method, solid=True, volumes_mm3=[float(v) for v in parts.volumes_mm3],
                 closed=[bool(r["closed"]) for r in closed])
    obj[PROP_PRINT_TABLE] = json.dumps(table)
    obj[PROP_CONNECTORS] = connectors_json(parts)
    op.warn_all(warnings + closed_warnings(closed))
    line = seg.summary()  # the learned split: what the data gave
    if line:
        op.report({"INFO"}, f"Learned split of the skin: {line}")
    n_conn = sum(len(j.connectors) for j in parts.joints)
    op.report({"INFO"}, f"Split '{obj.name}' into {k} solid print parts ({op.method}; largest/smallest skin area "
                        f"{table['area_balance']:.2f}), {len(parts.joints)} joints, {n_conn} connectors "
                        f"(clearance {clearance:g} mm); attribute '{ATTR_PRINT_PART}'")
    for p, r in enumerate(closed):
        op.report({"INFO"}, f"Part {p}: {abs(r['volume_mm3']) / 1000:.1f} cm³, "
                            f"{'closed' if r['closed'] else 'NOT closed'}")
    for line in joint_lines(parts):
        op.report({"INFO"}, line)
    return {"FINISHED"}


def _part_arrays(V, F, mask):
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


# ------------------------------------------------------------------ orient_parts / export_parts
def read_parts_region(op, context):
    """`BolusOperator.read_region` for orient_parts; on a bolus solid without the zero-area refusal:
    the booleans that cut and engrave it leave a few slivers (their area is 0 or nearly so, so
    they add nothing to WQ / WU: the orientation core takes them), and they do not open the solid."""
    if not is_bolus_object(context.active_object):
        return op.read_region(context, allow_nonmanifold=True)
    region = mesh_io.read_region(context)
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
    reports = [closed_report(*_part_arrays(region.V, region.F, tri_labels == p)) for p in ids]
    names = [f"{region.obj.name}_part_{p}" for p in ids]
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


def is_solid_part(part) -> bool:
    """A part object made from a bolus solid (its source carries ``bolus_shell_side``)."""
    src = bpy.data.objects.get(part.get("bolus_source", ""))
    return is_bolus_object(src)


def stl_file_name(part) -> str:
    """``<part name>.stl``, prefixed by the bolus's label when it has one (``<label>_<name>_bolus_part_<i>.stl``)."""
    src = bpy.data.objects.get(part.get("bolus_source", ""))
    label = str(src.get(PROP_LABEL, "")) if src is not None else ""
    label = re.sub(r"[^A-Za-z0-9._-]+", "_", label).strip("._")
    return f"{label}_{part.name}.stl" if label else f"{part.name}.stl"


def export_note(context, part, file_name: str) -> tuple[str, str]:
    """(report level, text) saying whether the exported solid part is closed (SPEC)."""
    r = part_closed_report(context, part)
    if r["closed"]:
        return "INFO", f"{file_name}: closed, {abs(r['volume_mm3']) / 1000:.1f} cm³"
    return "WARNING", closed_warnings([r], [file_name])[0]
