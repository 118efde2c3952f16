"""Operators for 3D printing: `print_segment`, `orient_parts`, `export_parts` (SPEC; seed ch. 6).

* `print_segment` writes the face attribute ``bolus_print_part`` on the source (like
  `segment` writes ``bolus_patch``): the area-balanced spectral cut of 6.2.
* `orient_parts` never touches the source: it creates one object per part,
  ``<name>_part_<i>``, holding the part's polygons in the source's world coordinates,
  and gives that object the rotation that takes the part's best build direction to +Z
  and the lift that rests it on z = 0 (so the transform shows how it was turned; the
  parts are laid side by side along X).  The print figures (WQ, WU, support volume,
  all in mm^3) are custom properties of each part and, with the whole model in its own
  best orientation as the first row (the seed's Tables 6-1, 6-2), a table on the
  source.
* `export_parts` writes one binary STL per part in millimetres with Blender's own STL
  exporter, each part at the origin (its XY bounding box centred there, its lowest
  point on z = 0), as a slicer expects; the part objects keep their layout.

Bolus shells are often open surfaces: each face counts once with its normal as given
(core.print_orientation); the report says so when the part is open.
"""
from __future__ import annotations

import json
import os
import re
from contextlib import contextmanager

import bpy
import numpy as np
from bpy.props import StringProperty
from mathutils import Matrix

from . import mesh_io
from .compat import stl_export as _stl_export  # version differences live in compat
from .core.colormap import categorical_linear_rgba
from .core.errors import BolusError
from .core.print_orientation import CRITICAL_ANGLE_DEG, orient, overhang_faces
from .core.print_segmentation import area_balance, part_stats, print_segmentation
from .core.topology import MeshTopology
from .operators import BolusOperator, check_topology
from .properties import layer_property, parts_property, print_method_property, seed_property, skin_side_up_property

#: names fixed by SPEC.md
ATTR_PRINT_PART = "bolus_print_part"
PART_INFIX = "_part_"
PROP_DIRECTION = "bolus_print_direction"
PROP_WQ = "bolus_WQ"
PROP_WU = "bolus_WU"
PROP_SUPPORT = "bolus_support_volume_mm3"
#: ours
ATTR_PRINT_PART_COLOR = "bolus_print_part_color"
ATTR_OVERHANG_COLOR = "bolus_overhang"
PROP_PRINT_TABLE = "bolus_print_table"
PROP_ORIENT_TABLE = "bolus_orient_table"
PROP_PART_SOURCE = "bolus_source"
PROP_PART_INDEX = "bolus_part"
PART_GAP_MM = 10.0
OVERHANG_RGBA = (0.8, 0.05, 0.02, 1.0)
PLAIN_RGBA = (0.6, 0.6, 0.6, 1.0)


def part_objects(source_name: str) -> list[bpy.types.Object]:
    """The ``<name>_part_<i>`` objects of a source, by part index."""
    pat = re.compile(re.escape(source_name + PART_INFIX) + r"(\d+)$")
    found = [(int(m.group(1)), ob) for ob in bpy.data.objects if (m := pat.match(ob.name))]
    return [ob for _, ob in sorted(found, key=lambda t: t[0])]


def _remove_parts(source_name: str) -> None:
    for ob in part_objects(source_name):
        me = ob.data
        bpy.data.objects.remove(ob, do_unlink=True)
        if me is not None and me.users == 0:
            bpy.data.meshes.remove(me)


def _open_note(topo: MeshTopology) -> str | None:
    nb = int(topo.boundary_edges.sum())
    if nb:
        return (f"open surface ({nb} boundary edges): every face is counted once with its normal as given; "
                "support is measured under the faces that look down")
    return None


class BOLUS_OT_print_segment(BolusOperator, bpy.types.Operator):
    """Split the bolus into parts of balanced area for 3D printing (area-balanced spectral cut, seed 6.2)"""

    bl_idname = "bolus.print_segment"
    bl_label = "Split into Print Parts"

    parts: parts_property()
    method: print_method_property()
    seed: seed_property()

    def run(self, context):
        region, topo, warnings = self.read_region(context, allow_nonmanifold=True)
        nfaces = len(np.unique(region.tri_poly))
        if nfaces < self.parts:
            raise BolusError(f"the region has {nfaces} faces, fewer than the {self.parts} parts asked")
        seg = print_segmentation(
            region.V, region.F, self.parts, method=self.method.lower(), rng=self.seed, topo=topo,
            progress=lambda f, t: self.progress(0.9 * f, t),
        )
        # the triangles of one polygon stay together: majority (by area) of its triangles
        obj, me = region.obj, region.mesh
        npoly = len(me.polygons)
        p = seg.part_count
        votes = np.zeros((npoly, p))
        np.add.at(votes, (region.tri_poly, seg.labels), topo.areas)
        poly_labels = np.full(npoly, -1, dtype=np.int64)
        poly_labels[region.poly_ids] = np.argmax(votes[region.poly_ids], axis=1)
        tri_labels = poly_labels[region.tri_poly]
        stats = [r.as_dict() for r in part_stats(region.V, region.F, tri_labels, topo)]
        with mesh_io.object_mode(obj):
            mesh_io.write_attribute(me, ATTR_PRINT_PART, "INT", "FACE", poly_labels)
            mesh_io.write_face_colors(me, ATTR_PRINT_PART_COLOR, categorical_linear_rgba(poly_labels))
            me.update()
        balance = area_balance(tri_labels, topo.areas)
        obj[PROP_PRINT_TABLE] = json.dumps({"method": self.method, "requested": self.parts, "parts": stats,
                                            "area_balance": balance})
        if p != self.parts:
            warnings.append(f"{p} parts instead of the {self.parts} asked: clusters that fell apart became "
                            "separate parts, pieces under 5 % of the area were merged")
        note = _open_note(topo)
        self.warn_all(warnings)
        self.report({"INFO"}, f"Split '{obj.name}' into {p} print parts ({self.method}; largest/smallest area "
                              f"{balance:.2f}); attribute '{ATTR_PRINT_PART}'" + (f"; {note}" if note else ""))
        for r in stats:
            self.report({"INFO"}, f"Part {r['part']}: {r['faces']} triangles, {r['area_mm2'] / 100:.1f} cm²")
        return {"FINISHED"}


def _row(name: str, faces: int, area: float, o) -> dict:
    return {"part": name, "faces": faces, "area_mm2": area, "direction": [float(x) for x in o.direction],
            "WQ": o.WQ, "WU": o.WU, "support_volume_mm3": o.support_volume, "objective": o.objective}


def format_print_row(r: dict) -> str:
    d = r["direction"]
    return (f"{r['part']}: {r['faces']} triangles, {r['area_mm2'] / 100:.1f} cm², build direction "
            f"({d[0]:+.3f}, {d[1]:+.3f}, {d[2]:+.3f}), WQ {r['WQ']:.1f} mm³, WU {r['WU']:.1f} mm³, "
            f"support {r['support_volume_mm3']:.1f} mm³")


class BOLUS_OT_orient_parts(BolusOperator, bpy.types.Operator):
    """Make one object per print part, turned to its best print direction and resting on the plate (seed 6.1, 6.3)"""

    bl_idname = "bolus.orient_parts"
    bl_label = "Orient Print Parts"

    layer_mm: layer_property()
    skin_side_up: skin_side_up_property()

    def run(self, context):
        region, topo, warnings = self.read_region(context, allow_nonmanifold=True)
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
        inside = tri_labels >= 0
        if not inside.any():
            raise BolusError("none of the region's faces belongs to a print part: run Split into Print Parts first")
        parts = np.unique(tri_labels[inside])
        favour = None
        if self.skin_side_up:
            # the skin-contact side is the side the normals point away from: keep it facing up
            n = (topo.face_normals * topo.areas[:, None]).sum(axis=0)
            if np.linalg.norm(n) < 1e-9 * topo.areas.sum():
                raise BolusError("the surface has no prevailing side (its normals cancel out); "
                                 "untick 'Skin side up'")
            favour = -n / np.linalg.norm(n)
        kw = dict(h=self.layer_mm, favour=favour)
        note = _open_note(topo)
        self.progress(0.02, "whole model")
        whole = orient(region.V, region.F, topo=topo, **kw)
        rows = [_row("whole", int(topo.m), float(topo.areas.sum()), whole)]
        results = []
        for k, p in enumerate(parts):
            self.progress(0.1 + 0.8 * k / len(parts), f"part {p}")
            sel = tri_labels == p
            Fs = region.F[sel]
            ids, inv = np.unique(Fs.ravel(), return_inverse=True)
            Fl = inv.reshape(-1, 3)
            sub = MeshTopology(region.V[ids], Fl)
            if sub.areas.sum() <= 0 or len(Fl) < 1:
                raise BolusError(f"print part {p} has no area: re-run Split into Print Parts")
            if len(Fl) < 4:
                warnings.append(f"print part {p} has only {len(Fl)} triangles: its orientation is of little use")
            o = orient(region.V[ids], Fl, topo=sub, **kw)
            results.append((int(p), o))
            rows.append(_row(f"part {p}", int(sel.sum()), float(sub.areas.sum()), o))
        self.progress(0.9, "part objects")
        self._make_part_objects(context, region, poly_labels, results)
        total_support = sum(r["support_volume_mm3"] for r in rows[1:])
        table = {"layer_mm": self.layer_mm, "critical_angle_deg": CRITICAL_ANGLE_DEG, "skin_side_up": self.skin_side_up,
                 "rows": rows, "parts_support_mm3": total_support,
                 "support_ratio": total_support / whole.support_volume if whole.support_volume > 0 else None}
        obj[PROP_ORIENT_TABLE] = json.dumps(table)
        self.warn_all(warnings)
        self.report({"INFO"}, f"Oriented {len(results)} print parts of '{obj.name}' (layer {self.layer_mm:g} mm)"
                    + (f"; {note}" if note else ""))
        for r in rows:
            self.report({"INFO"}, format_print_row(r))
        ratio = table["support_ratio"]
        self.report({"INFO"}, f"Support of the parts together: {total_support:.1f} mm³"
                    + (f" = {ratio * 100:.0f} % of the whole model's {whole.support_volume:.1f} mm³" if ratio is not None else ""))
        return {"FINISHED"}

    def _make_part_objects(self, context, region, poly_labels, results) -> None:
        obj, me = region.obj, region.mesh
        scale = region.mm_per_unit
        M = np.array(obj.matrix_world, dtype=np.float64)
        co = np.empty(len(me.vertices) * 3)
        me.vertices.foreach_get("co", co)
        world = co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3]  # scene units
        loop_v = np.empty(len(me.loops), dtype=np.int64)
        me.loops.foreach_get("vertex_index", loop_v)
        starts = np.empty(len(me.polygons), dtype=np.int64)
        totals = np.empty(len(me.polygons), dtype=np.int64)
        me.polygons.foreach_get("loop_start", starts)
        me.polygons.foreach_get("loop_total", totals)
        _remove_parts(obj.name)
        collection = obj.users_collection[0] if obj.users_collection else context.scene.collection
        x_cursor = 0.0
        region_polys = np.zeros(len(me.polygons), dtype=bool)
        region_polys[region.poly_ids] = True
        for p, o in results:
            polys = np.nonzero((poly_labels == p) & region_polys)[0]
            loops = [loop_v[starts[i]:starts[i] + totals[i]] for i in polys]
            used, inv = np.unique(np.concatenate(loops), return_inverse=True)
            faces, k = [], 0
            for lp in loops:
                faces.append(inv[k:k + len(lp)].tolist())
                k += len(lp)
            pme = bpy.data.meshes.new(f"{obj.name}{PART_INFIX}{p}")
            pme.from_pydata(world[used].tolist(), [], faces)
            pme.update()
            pob = bpy.data.objects.new(f"{obj.name}{PART_INFIX}{p}", pme)
            collection.objects.link(pob)
            R = o.rotation
            W = world[used] @ R.T
            lo, hi = W.min(axis=0), W.max(axis=0)
            t = np.array([x_cursor - lo[0], -(lo[1] + hi[1]) / 2.0, -lo[2]])
            x_cursor += (hi[0] - lo[0]) + PART_GAP_MM / scale
            T = np.eye(4)
            T[:3, :3] = R
            T[:3, 3] = t
            pob.matrix_world = Matrix(T.tolist())
            # overhang faces (in the print orientation) in red
            pn = np.empty(len(pme.polygons) * 3)
            pme.polygons.foreach_get("normal", pn)
            over = overhang_faces(pn.reshape(-1, 3), o.direction)
            rgba = np.where(over[:, None], np.array(OVERHANG_RGBA), np.array(PLAIN_RGBA))
            mesh_io.write_face_colors(pme, ATTR_OVERHANG_COLOR, rgba)
            pob[PROP_DIRECTION] = [float(x) for x in o.direction]
            pob[PROP_WQ] = o.WQ
            pob[PROP_WU] = o.WU
            pob[PROP_SUPPORT] = o.support_volume
            pob[PROP_PART_SOURCE] = obj.name
            pob[PROP_PART_INDEX] = p


@contextmanager
def _at_origin(context, part: bpy.types.Object):
    """Move `part` for the time of an export so that the centre of its XY bounding box is at
    the origin and its lowest point on z = 0 (world space, modifiers applied); its own
    transform comes back afterwards.  The layout of orient_parts puts the parts side by
    side along X: a printer's slicer wants each STL at the origin on the plate."""
    ev = part.evaluated_get(context.evaluated_depsgraph_get())
    me = ev.to_mesh()
    try:
        co = np.empty(len(me.vertices) * 3)
        me.vertices.foreach_get("co", co)
    finally:
        ev.to_mesh_clear()
    M = np.array(part.matrix_world, dtype=np.float64)
    W = co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3]
    location = part.location.copy()  # only the location moves: restored bit for bit
    if len(W):
        lo, hi = W.min(axis=0), W.max(axis=0)
        shift = np.array([-(lo[0] + hi[0]) / 2.0, -(lo[1] + hi[1]) / 2.0, -lo[2]])
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
    """Write every oriented print part as a binary STL file in millimetres"""

    bl_idname = "bolus.export_parts"
    bl_label = "Export Print Parts (STL)"

    directory: StringProperty(name="Folder", subtype="DIR_PATH", default="")

    def invoke(self, context, event):
        if not self.directory:
            self.directory = bpy.path.abspath("//") if bpy.data.filepath else os.getcwd()
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def run(self, context):
        obj = mesh_io.active_mesh_object(context)
        source = obj.get(PROP_PART_SOURCE, obj.name)
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
        written = []
        try:
            for k, part in enumerate(parts):
                self.progress(k / len(parts))
                path = os.path.join(folder, part.name + ".stl")
                for o in context.view_layer.objects:
                    o.select_set(o is part)
                context.view_layer.objects.active = part
                with _at_origin(context, part):
                    _stl_export(path, scale)
                written.append(path)
        finally:
            for o in context.view_layer.objects:
                o.select_set(o in was_selected)
            context.view_layer.objects.active = was_active
            if was_mode != "OBJECT" and was_active is obj:
                bpy.ops.object.mode_set(mode=was_mode)
        self.report({"INFO"}, f"Wrote {len(written)} STL files (binary, mm, each at the origin on z = 0) to {folder}: "
                    + ", ".join(os.path.basename(p) for p in written))
        return {"FINISHED"}


classes = (BOLUS_OT_print_segment, BOLUS_OT_orient_parts, BOLUS_OT_export_parts)
