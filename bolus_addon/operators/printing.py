"""Operators for 3D printing: `print_segment`, `orient_parts`, `export_parts` (SPEC; seed ch. 6).

They read the region, call the core and write back: `print_segment` the face attribute
``bolus_print_part`` (core.printing.segmentation, 6.2; on a bolus solid `blender.solid_split`);
`orient_parts` one object per part, ``<name>_part_<i>``, its polygons in world coordinates,
the rotation to its build direction and the plate layout in its transform
(core.printing.parts.orient_print_parts, core.mesh.layout.plate_layout), the figures as custom
properties and a table on the source; `export_parts` one binary STL per part in mm, each at
the origin on z = 0 (a solid's parts checked closed, `blender.part_checks`).
"""
from __future__ import annotations

import json
import os
from contextlib import contextmanager
from types import SimpleNamespace

import bpy
import numpy as np
from bpy.props import StringProperty
from mathutils import Matrix

from ..blender import mesh_io, part_checks, solid_split
from ..blender.compat import stl_export as _stl_export  # version differences live in compat
from ..blender.guide import poll_for
from ..blender.objects import (
    ATTR_OVERHANG_COLOR,
    ATTR_PRINT_PART,
    ATTR_PRINT_PART_COLOR,
    PART_INFIX,
    PROP_DIRECTION,
    PROP_ORIENT_TABLE,
    PROP_PART_INDEX,
    PROP_PART_SOURCE,
    PROP_PRINT_TABLE,
    PROP_SUPPORT,
    PROP_WQ,
    PROP_WU,
    is_bolus_object,
    is_solid_part,
    part_objects,
    parts_source_name,
)
from ..blender.operator_base import BolusOperator, time_limit
from ..blender.properties import (
    layer_property,
    parts_property,
    print_method_property,
    seed_property,
    skin_side_up_property,
)
from ..core.budget import check_budget
from ..core.colormap import categorical_linear_rgba
from ..core.errors import BolusError
from ..core.mesh.layout import centre_on_plate, plate_layout
from ..core.pattern.pattern_mesh import pattern_polygons
from ..core.printing.measures import CRITICAL_ANGLE_DEG, open_surface_note, overhang_faces
from ..core.printing.parts import PrintPlan, orient_print_parts, row_text
from ..core.printing.segmentation import print_segmentation

PART_GAP_MM = 10.0  #: between the parts' bounding boxes on the plate: room to pick each one
OVERHANG_RGBA = (0.8, 0.05, 0.02, 1.0)
PLAIN_RGBA = (0.6, 0.6, 0.6, 1.0)


def _remove_parts(source_name: str) -> None:
    for ob in part_objects(source_name):
        me = ob.data
        bpy.data.objects.remove(ob, do_unlink=True)
        if me is not None and me.users == 0:
            bpy.data.meshes.remove(me)


class BOLUS_OT_print_segment(BolusOperator, bpy.types.Operator):
    """Split the bolus into parts for 3D printing: of balanced area (area-balanced spectral cut, seed 6.2), or with Cut 'Learned' as many as the printing features call for (auto-encoder + affinity propagation, seed 6.4). Needs the bolus made by Make Bolus, selected (a skin surface splits into open pieces); makes the face attribute bolus_print_part and, on a solid, flat joints with pegs and holes"""

    bl_idname = "bolus.print_segment"
    bl_label = "Split into Print Parts"

    parts: parts_property()
    method: print_method_property()
    seed: seed_property()

    # long: prepare / compute (modal: a worker thread) / finish, see blender/operator_base.py
    def prepare(self, context):
        if is_bolus_object(context.active_object):  # a solid from make_shell: cut into solid parts
            return solid_split.prepare_solid(self, context)
        region, topo, warnings = self.read_region(context, allow_nonmanifold=True)
        check_budget("print_segment", [topo.m], f"the region has {topo.m:,} triangles",
                     "make the bolus on the treatment area first (Select Treatment Area, Make Bolus) and split "
                     "that", limit=time_limit(context))  # refuse now, not after minutes
        return SimpleNamespace(solid=False, region=region, topo=topo, warnings=warnings, parts=int(self.parts),
                               method=self.method.lower(), seed=int(self.seed))

    @staticmethod
    def compute(job, progress):
        if job.solid:
            return solid_split.compute_solid(job, progress)
        region = job.region
        return print_segmentation(
            region.V, region.F, job.parts, method=job.method, rng=job.seed, topo=job.topo,
            face_groups=region.tri_poly, progress=lambda f, t: progress(0.9 * f, t),
        )

    def finish(self, context, job, seg):
        if job.solid:
            return solid_split.finish_solid(self, context, job, seg)
        region, topo, warnings = job.region, job.topo, job.warnings
        obj, me = region.obj, region.mesh
        poly_labels = region.on_polygons(np.asarray(seg.labels, dtype=np.int64), -1)  # a polygon's triangles share a part
        with mesh_io.object_mode(obj):
            mesh_io.write_attribute(me, ATTR_PRINT_PART, "INT", "FACE", poly_labels)
            mesh_io.write_face_colors(me, ATTR_PRINT_PART_COLOR, categorical_linear_rgba(poly_labels))
            me.update()
        table = seg.table(region.V, region.F, topo)
        obj[PROP_PRINT_TABLE] = json.dumps({**table, "method": self.method})
        note = open_surface_note(topo)
        self.warn_all(warnings + [m for m in [seg.count_note()] if m])
        line = seg.summary()  # the learned split: what the data gave
        if line:
            self.report({"INFO"}, f"Learned split: {line}")
        self.report({"INFO"}, f"Split '{obj.name}' into {seg.part_count} print parts ({self.method}; largest/smallest "
                              f"area {table['area_balance']:.2f}); attribute '{ATTR_PRINT_PART}'"
                              + (f"; {note}" if note else ""))
        for r in table["parts"]:
            self.report({"INFO"}, f"Part {r['part']}: {r['faces']} triangles, {r['area_mm2'] / 100:.1f} cm²")
        return {"FINISHED"}


class BOLUS_OT_orient_parts(BolusOperator, bpy.types.Operator):
    """Make one object per print part, turned to its best print direction and resting on the plate (seed 6.1, 6.3). Needs print parts (Split into Print Parts; else the whole is one part); makes the '<name>_part_<i>' objects and the support table"""

    bl_idname = "bolus.orient_parts"
    bl_label = "Orient Print Parts"

    layer_mm: layer_property()
    skin_side_up: skin_side_up_property()

    # long: prepare / compute (modal: a worker thread) / finish, see blender/operator_base.py
    def prepare(self, context):
        region, topo, warnings = part_checks.read_parts_region(self, context)
        obj, me = region.obj, region.mesh
        if self.layer_mm <= 0:
            raise BolusError("the layer height must be positive")
        with mesh_io.object_mode(obj):
            poly_labels = mesh_io.read_face_labels(me, ATTR_PRINT_PART)
        if poly_labels is None:
            poly_labels = np.zeros(len(me.polygons), dtype=np.int64)
            warnings.append(f"no '{ATTR_PRINT_PART}' attribute (run Split into Print Parts first): "
                            "the region is oriented as one part")
        tri_labels = poly_labels[region.tri_poly]
        if not (tri_labels >= 0).any():
            raise BolusError("none of the region's faces belongs to a print part: run Split into Print Parts first")
        return SimpleNamespace(region=region, topo=topo, warnings=warnings, tri_labels=tri_labels,
                               layer_mm=float(self.layer_mm),
                               options=part_checks.orient_options(region, tri_labels, self.skin_side_up))

    @staticmethod
    def compute(job, progress):
        region = job.region
        return orient_print_parts(region.V, region.F, job.tri_labels, h=job.layer_mm, topo=job.topo,
                                  progress=lambda f, t: progress(0.9 * f, t), **job.options)

    def finish(self, context, job, plan):
        region, topo, warnings, tri_labels = job.region, job.topo, job.warnings, job.tri_labels
        obj = region.obj
        closed_info, closed_warn = part_checks.closed_lines(region, tri_labels)  # solids only
        self.progress(0.9, "part objects")
        self._make_part_objects(context, region, tri_labels, plan)
        table = plan.table(layer_mm=self.layer_mm, critical_angle_deg=CRITICAL_ANGLE_DEG,
                           skin_side_up=self.skin_side_up)
        obj[PROP_ORIENT_TABLE] = json.dumps(table)
        note = open_surface_note(topo)
        self.warn_all(warnings + plan.warnings + closed_warn)
        for line in closed_info:
            self.report({"INFO"}, line)
        self.report({"INFO"}, f"Oriented {len(plan.parts)} print parts of '{obj.name}' (layer {self.layer_mm:g} mm)"
                    + (f"; {note}" if note else ""))
        for r in table["rows"]:
            self.report({"INFO"}, row_text(r))
        self.report({"INFO"}, plan.support_text())
        return {"FINISHED"}

    def _make_part_objects(self, context, region, tri_labels, plan: PrintPlan) -> None:
        """One object per part: its polygons in world units, turned and laid out by `plate_layout`."""
        obj, scale = region.obj, region.mm_per_unit
        loop_start, loop_total, loop_vert = mesh_io.polygon_corners(region.mesh)
        polys = [pattern_polygons(region.tri_poly, np.where(tri_labels == r.part, 0, -1), region.F, region.F,
                                  region.vert_ids, loop_start, loop_total, loop_vert) for r in plan.parts]
        used = [np.unique(pp.corner_src, return_inverse=True) for pp in polys]
        place = plate_layout([region.V[u] for u, _ in used], [r.orientation.rotation for r in plan.parts],
                             PART_GAP_MM)
        _remove_parts(obj.name)
        collection = obj.users_collection[0] if obj.users_collection else context.scene.collection
        for r, pp, (u, corners), (R, t) in zip(plan.parts, polys, used, place):
            name = f"{obj.name}{PART_INFIX}{r.part}"
            pme = mesh_io.new_mesh(name, region.V[u] / scale, corners.reshape(-1), pp.loop_starts)
            pob = bpy.data.objects.new(name, pme)
            collection.objects.link(pob)
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = R, t / scale
            pob.matrix_world = Matrix(T.tolist())
            pn = np.empty(len(pme.polygons) * 3)  # overhang faces (in the print orientation) in red
            pme.polygons.foreach_get("normal", pn)
            over = overhang_faces(pn.reshape(-1, 3), r.orientation.direction)
            mesh_io.write_face_colors(pme, ATTR_OVERHANG_COLOR, np.where(over[:, None], OVERHANG_RGBA, PLAIN_RGBA))
            o = r.orientation
            pob[PROP_DIRECTION] = [float(x) for x in o.direction]
            pob[PROP_WQ], pob[PROP_WU], pob[PROP_SUPPORT] = o.WQ, o.WU, o.support_volume
            pob[PROP_PART_SOURCE], pob[PROP_PART_INDEX] = obj.name, r.part


@contextmanager
def _at_origin(context, part: bpy.types.Object):
    """Move `part` for the time of an export to the origin of the plate (`layout.centre_on_plate`,
    world space, modifiers applied), as a slicer wants it; its transform comes back afterwards."""
    ev = part.evaluated_get(context.evaluated_depsgraph_get())
    me = ev.to_mesh()
    try:
        co = np.empty(len(me.vertices) * 3)
        me.vertices.foreach_get("co", co)
    finally:
        ev.to_mesh_clear()
    location = part.location.copy()  # only the location moves: restored bit for bit
    if len(co):
        shift = centre_on_plate(mesh_io.world_mm(co.reshape(-1, 3), part, 1.0))  # world units (1 unit per unit)
        if part.parent is not None:  # the location lives in the parent's frame
            P = np.array(part.parent.matrix_world, dtype=np.float64) @ np.array(part.matrix_parent_inverse)
            shift = np.linalg.solve(P[:3, :3], shift)
        part.location = tuple(np.array(location) + shift)
        context.view_layer.update()
    try:
        yield
    finally:
        part.location = location
        context.view_layer.update()


class BOLUS_OT_export_parts(BolusOperator, bpy.types.Operator):
    """Write every oriented print part as a binary STL file in millimetres. Needs the part objects (Orient Print Parts), the bolus or a part selected; writes one '<name>_part_<i>.stl' per part into the chosen folder"""

    bl_idname = "bolus.export_parts"
    bl_label = "Export Print Parts (STL)"

    @classmethod
    def poll(cls, context):
        return poll_for(cls, context)

    directory: StringProperty(name="Folder", subtype="DIR_PATH", default="")

    def invoke(self, context, event):
        if not self.directory:
            self.directory = bpy.path.abspath("//") if bpy.data.filepath else os.getcwd()
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def run(self, context):
        obj = mesh_io.active_mesh_object(context)
        source = parts_source_name(obj)  # a bolus's or an improved surface's own parts, or a part's siblings
        parts = part_objects(source)
        if not parts:
            raise BolusError(f"'{source}' has no print parts yet: run Orient Print Parts first")
        folder = bpy.path.abspath(self.directory) if self.directory else ""
        if not folder or not os.path.isdir(folder):
            raise BolusError(f"the folder '{self.directory}' does not exist: choose an existing folder")
        if not os.access(folder, os.W_OK):
            raise BolusError(f"the folder '{folder}' is not writable")
        scale = mesh_io.mm_per_unit(context.scene)
        was_active, was_selected = context.view_layer.objects.active, list(context.selected_objects)
        was_mode = obj.mode  # the user's mode comes back afterwards
        if obj.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        written, notes = [], []
        try:
            for k, part in enumerate(parts):
                self.progress(k / len(parts))
                path = os.path.join(folder, part_checks.stl_file_name(part))
                for o in context.view_layer.objects:
                    o.select_set(o is part)
                context.view_layer.objects.active = part
                with _at_origin(context, part):
                    _stl_export(path, scale)
                written.append(path)
                if is_solid_part(part):  # SPEC: closed when the part is a solid
                    notes.append(part_checks.export_note(context, part, os.path.basename(path)))
        finally:
            for o in context.view_layer.objects:
                o.select_set(o in was_selected)
            context.view_layer.objects.active = was_active
            if was_mode != "OBJECT" and was_active is obj:
                bpy.ops.object.mode_set(mode=was_mode)
        self.report({"INFO"}, f"Wrote {len(written)} STL files (binary, mm, each at the origin on z = 0) to {folder}: "
                    + ", ".join(os.path.basename(p) for p in written))
        for level, msg in notes:
            self.report({level}, msg)
        return {"FINISHED"}


classes = (BOLUS_OT_print_segment, BOLUS_OT_orient_parts, BOLUS_OT_export_parts)
