"""Operator `bolus.export_pattern` (SPEC): the pattern object as a true-scale SVG.

The pattern object is read like any region (`mesh_io.read_region`: world coordinates in
mm, the one place that converts scene units), grouped by patch (`core.pattern_mesh.svg_pieces`)
and written by `core.pattern_svg.pattern_svg`.
"""
from __future__ import annotations

import os

import bpy
import numpy as np
from bpy.props import StringProperty

from . import mesh_io
from .core.errors import BolusError
from .core.pattern_mesh import svg_pieces, table_rows
from .core.pattern_svg import pattern_svg
from .operators import ATTR_PATCH, BolusOperator
from .pattern_ops import ATTR_SOURCE_FACE, PATTERN_SUFFIX, PROP_PATTERN_TABLE
from .properties import seam_allowance_property


def pattern_object_for(context) -> bpy.types.Object:
    """The active pattern object, or the pattern of the active source object."""
    obj = mesh_io.active_mesh_object(context)
    if ATTR_SOURCE_FACE in obj.data.attributes:
        return obj
    pat = bpy.data.objects.get(obj.name + PATTERN_SUFFIX)
    if pat is not None and pat.type == "MESH" and ATTR_SOURCE_FACE in pat.data.attributes:
        return pat
    raise BolusError(f"'{obj.name}' has no pattern yet: run Unfold Patches first")


def pattern_pieces(context, pat: bpy.types.Object) -> list[dict]:
    """The pattern object's pieces in mm, for the SVG (one per patch)."""
    region = mesh_io.read_region(context, obj=pat, polys=np.ones(len(pat.data.polygons), dtype=bool))
    poly_patch = mesh_io.read_face_labels(pat, ATTR_PATCH)
    if poly_patch is None:
        raise BolusError(f"'{pat.name}' has no '{ATTR_PATCH}' face attribute: run Unfold Patches again")
    return svg_pieces(region.V, region.F, region.tri_poly, poly_patch, table_rows(pat.get(PROP_PATTERN_TABLE)))


def default_svg_path(active_name: str | None, blend_dir: str | None) -> str:
    """``<source>_pattern.svg`` beside the .blend file (or relative when it is not saved),
    the source's name also when its pattern object is the active one."""
    base = (active_name or "pattern").removesuffix(PATTERN_SUFFIX) + "_pattern.svg"
    return os.path.join(blend_dir, base) if blend_dir else base


def _svg_path(filepath: str) -> str:
    """The absolute .svg path to write; BolusError when there is none or its folder is missing."""
    if not filepath:
        raise BolusError("choose a file to write the SVG to")
    path = bpy.path.abspath(filepath)
    if not path.lower().endswith(".svg"):
        path += ".svg"
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise BolusError(f"the folder '{folder}' does not exist")
    return path


class BOLUS_OT_export_pattern(BolusOperator, bpy.types.Operator):
    """Write the pattern as an SVG at true scale (print at 100 %), one labelled outline per patch"""

    bl_idname = "bolus.export_pattern"
    bl_label = "Export Pattern (SVG)"
    bl_options = {"REGISTER"}

    filepath: StringProperty(name="File", subtype="FILE_PATH", default="")
    filter_glob: StringProperty(default="*.svg", options={"HIDDEN"})
    seam_allowance_mm: seam_allowance_property()

    def invoke(self, context, event):
        if not self.filepath:
            obj = context.active_object
            self.filepath = default_svg_path(obj.name if obj is not None else None,
                                             bpy.path.abspath("//") if bpy.data.filepath else None)
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def run(self, context):
        path = _svg_path(self.filepath)
        pat = pattern_object_for(context)
        pieces = pattern_pieces(context, pat)
        svg = pattern_svg(pieces, seam_allowance_mm=self.seam_allowance_mm,
                          title=f"{pat.get('bolus_source', pat.name)}: bolus pattern")
        try:
            with open(path, "w", encoding="utf-8") as fh:
                fh.write(svg)
        except OSError as exc:
            raise BolusError(f"could not write '{path}': {exc.strerror or exc}") from exc
        self.report({"INFO"}, f"Wrote {len(pieces)} patches to {path} (print at 100 %, check the 50 mm bar)")
        return {"FINISHED"}


classes = (BOLUS_OT_export_pattern,)
