"""Operator `bolus.export_pattern` (SPEC): the pattern object as a true-scale SVG, DXF or PDF.

The pattern object is read like any region (`mesh_region.read_region`: world coordinates in
mm, converted from scene units by `mesh_io.world_mm`), grouped by piece
(`core.pattern.pattern_mesh.export_pieces`), its matching marks found from the source vertex
of every pattern vertex (`core.pattern.marks.pattern_marks`: seams between pieces, darts and
joins within one) and written by `core.pattern.export.write_pattern`, which picks the format
from the file's extension and writes atomically (nothing half-written is ever left behind).
"""
from __future__ import annotations

import os

import bpy
import numpy as np
from bpy.props import EnumProperty, StringProperty

from ..blender import mesh_io, mesh_region
from ..blender.guide import poll_for
from ..blender.objects import (
    ATTR_PATCH,
    ATTR_PIECE,
    ATTR_SOURCE_VERTEX,
    PATTERN_SUFFIX,
    PROP_PATTERN_TABLE,
    PROP_SOURCE,
    pattern_of,
)
from ..blender.operator_base import BolusOperator
from ..blender.properties import page_property, seam_allowance_property
from ..core.errors import BolusError
from ..core.pattern.export import write_pattern
from ..core.pattern.marks import PatternMarks, pattern_marks
from ..core.pattern.pattern_mesh import export_pieces

FORMATS = {"SVG": ".svg", "DXF": ".dxf", "PDF": ".pdf"}
FORMAT_ITEMS = [
    ("SVG", "SVG", "Scalable vector graphics in mm: print from a browser or Inkscape at 100 %"),
    ("DXF", "DXF", "AutoCAD DXF in mm ($INSUNITS = 4) for a cutting plotter or laser cutter"),
    ("PDF", "PDF", "PDF at true scale, on one page or tiled on A4 / Letter with overlap and alignment marks"),
]


def pattern_object_for(context) -> bpy.types.Object:
    """The active pattern object, or the pattern of the active source object."""
    obj = mesh_io.active_mesh_object(context)
    pat = pattern_of(obj)
    if pat is not None:
        return pat
    raise BolusError(f"'{obj.name}' has no pattern yet: run Unfold Patches first")


def _point_ints(me: bpy.types.Mesh, name: str) -> np.ndarray | None:
    """An INT point attribute of the mesh, or None."""
    a = me.attributes.get(name)
    if a is None or a.domain != "POINT" or a.data_type != "INT":
        return None
    return mesh_io.get_array(a.data, "value", len(me.vertices), np.int64)


def pattern_pieces(context, pat: bpy.types.Object) -> tuple[list[dict], PatternMarks, list[str]]:
    """The pattern object's pieces in mm and their marks; notes for the user (an old pattern
    without pieces or source vertices is exported by patch, without matching marks)."""
    notes = []
    with mesh_io.object_mode(pat):
        region = mesh_region.read_region(context, obj=pat, polys=np.ones(len(pat.data.polygons), dtype=bool))
    poly_patch = mesh_io.read_face_labels(pat, ATTR_PATCH)
    if poly_patch is None:
        raise BolusError(f"'{pat.name}' has no '{ATTR_PATCH}' face attribute: run Unfold Patches again")
    poly_piece = mesh_io.read_face_labels(pat, ATTR_PIECE)
    if poly_piece is None:
        poly_piece = poly_patch
        notes.append(f"'{pat.name}' was made before pieces were numbered: exported one outline per patch "
                     "(unfold again for darts, splits and pieces)")
    table = mesh_io.json_prop(pat, PROP_PATTERN_TABLE) or {}
    rows = table.get("islands") if isinstance(table, dict) and "pieces" in table else None
    P = region.V[:, :2]
    pieces = export_pieces(P, region.F, region.tri_poly, poly_piece, poly_patch, rows)
    sv = _point_ints(pat.data, ATTR_SOURCE_VERTEX)
    if sv is None:
        notes.append(f"'{pat.name}' has no '{ATTR_SOURCE_VERTEX}': no matching marks (unfold again to get them)")
        marks = PatternMarks([], [], P)
    else:
        marks = pattern_marks(P, region.F, poly_piece[region.tri_poly], sv[region.vert_ids])
    return pieces, marks, notes


def default_pattern_path(active_name: str | None, blend_dir: str | None, ext: str = ".svg") -> str:
    """``<source>_pattern<ext>`` beside the .blend file (or relative when it is not saved),
    the source's name also when its pattern object is the active one."""
    base = (active_name or "pattern").removesuffix(PATTERN_SUFFIX) + PATTERN_SUFFIX + ext
    return os.path.join(blend_dir, base) if blend_dir else base


def default_svg_path(active_name: str | None, blend_dir: str | None) -> str:
    """`default_pattern_path` with the SVG extension (scripts call it by this name)."""
    return default_pattern_path(active_name, blend_dir, ".svg")


def export_path(filepath: str, file_format: str) -> str:
    """The path to write: Blender's '//' resolved and the format's extension added to a name
    without one; `write_pattern` refuses the rest (no path, another extension, a missing folder)."""
    path = bpy.path.abspath(filepath) if filepath else ""
    if path and os.path.splitext(path)[1] in ("", "."):
        path += FORMATS[file_format]
    return path


class BOLUS_OT_export_pattern(BolusOperator, bpy.types.Operator):
    """Write the pattern at true scale as SVG, DXF (mm, for a cutter) or PDF (tiled on A4 / Letter): one labelled outline per piece, numbered matching marks, a 50 mm test square. Needs a pattern (Unfold Patches): select it or its skin"""

    bl_idname = "bolus.export_pattern"
    bl_label = "Export Pattern"

    @classmethod
    def poll(cls, context):
        return poll_for(cls, context)
    bl_options = {"REGISTER"}

    filepath: StringProperty(name="File", subtype="FILE_PATH", default="")
    filter_glob: StringProperty(default="*.svg;*.dxf;*.pdf", options={"HIDDEN"})
    page: page_property()
    label: StringProperty(name="Label", default="",
                          description="Text printed on every piece, e.g. the patient ID")
    file_format: EnumProperty(name="Format", items=FORMAT_ITEMS, default="SVG",
                              description="The format when the file name has no extension (.svg, .dxf or .pdf "
                                          "decides otherwise)")
    seam_allowance_mm: seam_allowance_property()

    def invoke(self, context, event):
        if not self.filepath:
            obj = context.active_object
            self.filepath = default_pattern_path(obj.name if obj is not None else None,
                                                 bpy.path.abspath("//") if bpy.data.filepath else None,
                                                 FORMATS[self.file_format])
        self.filter_glob = "*" + FORMATS[self.file_format]
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def run(self, context):
        path = export_path(self.filepath, self.file_format)
        pat = pattern_object_for(context)
        pieces, marks, notes = pattern_pieces(context, pat)
        info = write_pattern(path, pieces, marks, page=self.page, label=self.label,
                             title=f"{pat.get(PROP_SOURCE, pat.name)}: bolus pattern",
                             seam_allowance_mm=self.seam_allowance_mm)
        for note in notes:
            self.report({"INFO"}, note)
        pages = info["pages"]
        seams = sum(1 for s in marks.seams if not s.is_join)
        self.report({"INFO"}, f"Wrote {len(pieces)} pieces ({seams} numbered seams, {len(marks.darts)} darts) to "
                              f"{path}" + (f" on {pages} pages" if pages > 1 else "")
                    + (": units mm, cut the layer CUT" if path.lower().endswith(".dxf") else
                       ": print at 100 % (no fit to page) and measure the 50 mm square before cutting"))
        return {"FINISHED"}


classes = (BOLUS_OT_export_pattern,)
