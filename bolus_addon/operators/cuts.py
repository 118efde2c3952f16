"""Operator `bolus.smooth_cuts` (SPEC; seed 4.1.2, Tables 4-1 and 4-2).

The only operator that changes the source mesh's topology, because that is its whole
purpose: the jagged patch borders left by `segment` are replaced by smooth cut curves
on the surface (core.cuts.cutlines), crossed polygons are re-triangulated, and
`bolus_patch`, the seams and the patch colours are updated.  Everything is computed
before the mesh is touched; undo restores the mesh exactly.
"""
from __future__ import annotations

import json
from types import SimpleNamespace

import bpy
import numpy as np

from ..blender import mesh_cuts, mesh_io, mesh_region
from ..blender.guide import poll_for
from ..blender.objects import ATTR_PATCH, ATTR_PATCH_COLOR, PROP_CUT_TABLE, PROP_PATCH_TABLE
from ..blender.operator_base import BolusOperator, time_limit
from ..core.budget import check_budget
from ..core.colormap import categorical_linear_rgba
from ..core.cuts.cutlines import cut_region_check, patch_table, smooth_cuts
from ..core.errors import BolusError


def format_cut_row(r: dict) -> str:
    kind = "closed " if r["closed"] else ""
    text = (
        f"Border {r['a']}|{r['b']} ({kind}{r['border_vertices']} vertices): {r['method']}, "
        f"turning {r['turning_before']:.3f} -> {r['turning_after']:.3f} rad/mm, "
        f"moved up to {r['max_shift_mm']:.2f} mm"
    )
    return text + (f" ({r['note']})" if r["note"] else "")


class BOLUS_OT_smooth_cuts(BolusOperator, bpy.types.Operator):
    """Replace the jagged patch borders by smooth cut lines on the surface (seed 4.1.2). Needs patches (Segment into Patches); changes the mesh: new vertices along the cuts, bolus_patch and seams updated (Ctrl+Z undoes it)"""

    bl_idname = "bolus.smooth_cuts"
    bl_label = "Smooth Cut Lines"

    @classmethod
    def poll(cls, context):
        return poll_for(cls, context)

    # long: prepare / compute (modal: a worker thread) / finish, see blender/operator_base.py
    def prepare(self, context):
        obj, region, labels = _read_patches(context)
        checked, why = cut_region_check(region.V, region.F, labels, region.vert_ids)  # on the patch faces only
        warnings = region.warnings + checked
        if why:
            self.warn_all(warnings)
            self.report({"INFO"}, f"Nothing to smooth on '{obj.name}': {why} (Segment into Patches with 2 or more "
                                  "patches makes borders to smooth); the mesh was not changed")
            return {"FINISHED"}
        table = mesh_io.json_prop(obj, PROP_PATCH_TABLE)
        table = table if isinstance(table, dict) else {}
        smoothing = float(table.get("smoothing_mm", 0.0) or 0.0)
        check_budget("smooth_cuts", [len(region.F)], f"the patches of '{obj.name}' have {len(region.F):,} triangles",
                     "select the treatment area first (Select Treatment Area) and segment it",
                     limit=time_limit(context))
        return SimpleNamespace(obj=obj, region=region, labels=labels, warnings=warnings, table=table,
                               smoothing=smoothing)

    @staticmethod
    def compute(job, progress):
        """(SmoothCutResult, patch table before, after); the tables None when nothing changed."""
        region, labels = job.region, job.labels
        progress(0.05, "smooth cut lines")
        res = smooth_cuts(region.V, region.F, labels, progress=lambda f, t: progress(0.05 + 0.75 * f, t))
        if not res.changed:
            return res, None, None
        progress(0.8, "patch figures")
        before = patch_table(region.V, region.F, labels, job.smoothing)
        after = patch_table(res.V, res.F, res.labels, job.smoothing)
        return res, before, after

    def finish(self, context, job, result):
        obj, region, warnings, table = job.obj, job.region, job.warnings, job.table
        res, before, after = result
        borders = [b.as_dict() for b in res.borders]
        if not res.changed:
            self.warn_all(warnings)
            self.report({"INFO"}, f"Nothing to change on '{obj.name}': none of its {len(borders)} borders can be made "
                                  "smoother (already smooth cut lines, or too short to fit); the mesh was not changed")
            for r in borders:
                self.report({"INFO"}, format_cut_row(r))
            return {"FINISHED"}
        _write_cuts(obj, region, res)
        table.update({"patches": after, "before_smooth_cuts": before, "smooth_cuts": True})
        obj[PROP_PATCH_TABLE] = json.dumps(table)
        obj[PROP_CUT_TABLE] = json.dumps(borders)
        self.warn_all(warnings)
        self.report_cuts(obj, res, before, after)
        return {"FINISHED"}

    def report_cuts(self, obj, res, before, after) -> None:
        changed = sum(b.method != "unchanged" for b in res.borders)
        self.report(
            {"INFO"},
            f"Smoothed {changed} of {len(res.borders)} borders of '{obj.name}': {res.new_vertex_count} new vertices, "
            f"{int(res.split.sum())} triangles split",
        )
        for b in res.borders:  # each border once: one that could not be smoothed is a warning
            self.report({"WARNING"} if b.shortfall else {"INFO"}, format_cut_row(b.as_dict()))
        for b_row, a_row in zip(before, after):
            self.report(
                {"INFO"},
                f"Patch {a_row['patch']}: vertices {b_row['vertices']} -> {a_row['vertices']}, edges {b_row['edges']} -> "
                f"{a_row['edges']}, triangles {b_row['faces']} -> {a_row['faces']}, sum varpi {b_row['sum_varpi']:.4f} -> "
                f"{a_row['sum_varpi']:.4f}, FLV {b_row['flv']:.4g} -> {a_row['flv']:.4g}",
            )


def _read_patches(context):
    """(object, region, triangle labels): the patch faces (bolus_patch >= 0), whatever is
    selected, so every check (NaN, units, manifold, zero area) is on them only, plus the
    faces just outside them (label -1, never split): a cut that reaches the edge of the
    region then snaps to a vertex there instead of splitting an edge that a face outside
    the region shares (a T-junction, a crack)."""
    obj = mesh_io.active_mesh_object(context)
    me = obj.data
    if me.shape_keys is not None:
        raise BolusError(
            f"'{obj.name}' has shape keys; cutting would have to re-shape every key: apply or remove them first"
        )
    poly_labels = mesh_io.read_face_labels(obj, ATTR_PATCH)  # safe in Edit Mode
    if poly_labels is None:
        raise BolusError(f"'{obj.name}' has no '{ATTR_PATCH}' attribute: run Segment into Patches first")
    if not (poly_labels >= 0).any():
        raise BolusError(f"no face of '{obj.name}' belongs to a patch: run Segment into Patches first")
    patch = poly_labels >= 0
    region = mesh_region.read_region(context, obj, polys=patch | mesh_io.polygons_next_to(me, patch))
    return obj, region, poly_labels[region.tri_poly]


def _write_cuts(obj, region, res) -> None:
    """The cut into the mesh (mesh_cuts.apply_cuts), then seams and patch colours."""
    me = obj.data
    with mesh_io.object_mode(obj):
        new_labels = mesh_cuts.apply_cuts(me, region, res, ATTR_PATCH)
        seams = mesh_io.polygon_edge_labels(me, new_labels)
        touched = mesh_io.edges_of_polygons(me, np.nonzero(new_labels >= 0)[0])
        mesh_io.set_seams(me, seams, touched)
        mesh_io.write_face_colors(me, ATTR_PATCH_COLOR, categorical_linear_rgba(new_labels))
        me.update()


classes = (BOLUS_OT_smooth_cuts,)
