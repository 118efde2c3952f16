"""Split into Print Parts on a bolus solid: the stored solid cut into closed, labelled parts.

`operators.printing.BOLUS_OT_print_segment` hands over to these three when the active object
carries ``bolus_shell_side`` (made by Make Bolus): the skin region stored with the bolus is
split by the area-balanced cut (core.printing.segmentation, seed 6.2),
`core.solid.parts.split_solid` cuts the plain stored solid along one SVM plane per pair of
neighbouring parts (eqs. 6-38..6-40) and adds the peg / hole connectors (6.4.3), each part gets
"<label> <i>" and the L / R markers engraved, and the parts replace the bolus object's mesh
(face attributes ``bolus_print_part`` and ``bolus_shell_side``, the connectors as JSON in
``bolus_connectors``).  A re-run starts again from the stored plain solid.
"""
from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np

from ..core.colormap import categorical_linear_rgba
from ..core.printing.segmentation import print_segmentation
from ..core.solid.engrave import strings_needed
from ..core.solid.manifold import closed_report, weld_short_edges
from . import mesh_io
from .labels import engrave, engrave_with, label_outlines, left_vector
from .objects import (
    ATTR_PRINT_PART,
    ATTR_PRINT_PART_COLOR,
    ATTR_SHELL_SIDE,
    PROP_CONNECTORS,
    PROP_LABEL,
    PROP_PRINT_TABLE,
)
from .part_checks import closed_warnings, part_arrays
from .solid_io import remove_mesh, stored_solid, tri_mesh

DEFAULT_CONNECTOR_CLEARANCE = 0.2


def connectors_json(parts) -> str:
    """The joints and their connectors (core.solid.parts) as JSON (mm, world frame)."""
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
    closed = [closed_report(*part_arrays(PV, PF, plabels == p)) for p in range(k)] if engraved else None
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
        closed = [closed_report(*part_arrays(PV, PF, plabels == p)) for p in range(int(plabels.max()) + 1)]
    # slivers whose shortest edge float32 cannot hold would collapse in Blender's mesh and in the STL
    PV, PF, keep = weld_short_edges(PV, PF)
    pside, plabels = pside[keep], plabels[keep]
    if not keep.all():
        closed = [closed_report(*part_arrays(PV, PF, plabels == p)) for p in range(len(closed))]
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
