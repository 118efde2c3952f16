"""Operator `bolus.select_area` (SPEC): the treatment area around the 3D cursor.

Reads the whole active mesh (world mm), calls `core.cuts.treatment_area.treatment_area` with
the 3D cursor, writes the cut (the border's level line through the faces) with
`mesh_cuts.apply_cuts`, selects the area's faces and leaves the user in Edit Mode (face
select mode) with it selected.  Everything is computed before the mesh is touched, so a
refusal changes nothing; one undo step undoes it all.
"""
from __future__ import annotations

from types import SimpleNamespace

import bpy
import numpy as np

from ..blender import mesh_cuts, mesh_io, mesh_region
from ..blender.objects import ATTR_AREA_TMP
from ..blender.operator_base import BolusOperator
from ..blender.properties import area_radius_property, exclude_cavities_property
from ..core.cuts.treatment_area import treatment_area
from ..core.errors import BolusError


class BOLUS_OT_select_area(BolusOperator, bpy.types.Operator):
    """Select the treatment area around the 3D cursor on the active skin mesh: the faces within the radius along the surface, the border cut along a smooth curve, cavities (inside the nostrils) left out. Needs the 3D cursor on the skin (Shift+right-click); changes the mesh and leaves it in Edit Mode with the area selected"""

    bl_idname = "bolus.select_area"
    bl_label = "Select Treatment Area"

    radius_mm: area_radius_property()
    exclude_cavities: exclude_cavities_property()

    # long: prepare / compute (modal: a worker thread) / finish, see blender/operator_base.py
    def prepare(self, context):
        obj = mesh_io.active_mesh_object(context)
        me = obj.data
        if me.shape_keys is not None:
            raise BolusError(f"'{obj.name}' has shape keys; cutting the area's border would have to re-shape every "
                             "key: apply or remove them first")
        if len(me.polygons) == 0:
            raise BolusError(f"'{obj.name}' has no faces: the bolus tools need a surface mesh")
        region = mesh_region.read_region(context, obj, polys=np.ones(len(me.polygons), dtype=bool))
        cursor = np.array(context.scene.cursor.location, dtype=np.float64) * region.mm_per_unit
        return SimpleNamespace(obj=obj, region=region, cursor=cursor, radius_mm=float(self.radius_mm),
                               exclude_cavities=bool(self.exclude_cavities))

    @staticmethod
    def compute(job, progress):
        return treatment_area(job.region.V, job.region.F, job.cursor, job.radius_mm, job.exclude_cavities,
                              progress=lambda f, t: progress(0.9 * f, t))

    def finish(self, context, job, area):
        obj, region, cursor = job.obj, job.region, job.cursor
        self.progress(0.9, "writing the cut")
        _write_area(context, obj, region, area)
        table = {
            "radius_mm": float(self.radius_mm), "exclude_cavities": bool(self.exclude_cavities),
            "faces": int(area.selected.sum()), "area_cm2": area.area_mm2 / 100.0,
            "cavity_cm2": area.cavity_area_mm2 / 100.0, "cavity_fraction": area.cavity_fraction,
            "holes": int(area.holes), "cursor_mm": [float(x) for x in cursor],
            "cursor_to_skin_mm": area.centre_distance_mm,
        }
        self.warn_all(region.warnings + area.warnings)
        self.report({"INFO"}, area_summary(obj.name, table, int(area.split.sum()), int((area.vert_parent >= 0).sum())))
        return {"FINISHED"}


def area_summary(name: str, t: dict, split: int, new_vertices: int) -> str:
    """One line of figures of a selected area (the table `run` makes)."""
    text = (f"Selected the treatment area of '{name}': {t['faces']} faces, {t['area_cm2']:.1f} cm² within "
            f"{t['radius_mm']:g} mm of the 3D cursor along the surface (cursor {t['cursor_to_skin_mm']:.1f} mm from "
            f"the skin)")
    if t["exclude_cavities"]:
        text += (f"; cavities left out: {t['cavity_cm2']:.1f} cm² ({100.0 * t['cavity_fraction']:.1f} % of the area "
                 f"within the radius), {t['holes']} hole(s)")
    return text + f"; border cut through {split} triangles ({new_vertices} new vertices on the surface)"


def _write_area(context, obj, region, area) -> None:
    """The cut written and the area selected, in Edit Mode (face select mode).

    The cut is written into a copy of the mesh with `mesh_cuts.apply_cuts` (object-mode
    data), which then replaces the edit-mesh: the mesh data-block itself only changes when
    Edit Mode is left, so the operator is one edit-mesh undo step, also when it was started
    in Object Mode (writing the data-block there would make undo stop at an Object Mode
    state with the cut mesh first)."""
    import bmesh

    if obj.mode != "EDIT":
        bpy.ops.object.mode_set(mode="EDIT")
    me = obj.data
    tmp = me.copy()
    try:
        sel = mesh_cuts.apply_cuts(tmp, region, area, ATTR_AREA_TMP) > 0
        tmp.attributes.remove(tmp.attributes[ATTR_AREA_TMP])
        _select_faces(tmp, sel)
        context.tool_settings.mesh_select_mode = (False, False, True)  # vertex mode would select faces across holes
        bm = bmesh.from_edit_mesh(me)
        bm.clear()
        bm.from_mesh(tmp)
        bm.select_mode = {"FACE"}
        bmesh.update_edit_mesh(me)
    finally:
        bpy.data.meshes.remove(tmp)


def _select_faces(me, sel: np.ndarray) -> None:
    """Select exactly the polygons sel (p,) bool with their edges and vertices (object-mode data)."""
    me.polygons.foreach_set("select", sel)
    loop_e, loop_p = mesh_io.loop_edges_and_polygons(me)
    loop_v = mesh_io.get_array(me.loops, "vertex_index", len(me.loops), np.int64)
    esel = np.zeros(len(me.edges), dtype=bool)
    esel[loop_e[sel[loop_p]]] = True
    vsel = np.zeros(len(me.vertices), dtype=bool)
    vsel[loop_v[sel[loop_p]]] = True
    me.edges.foreach_set("select", esel)
    me.vertices.foreach_set("select", vsel)
    me.update()


classes = (BOLUS_OT_select_area,)
