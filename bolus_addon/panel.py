"""Sidebar panel (3D View > Sidebar > Bolus): a guided walk through a case, and the Bolus menu (F3).

The steps in order: 0 Import planning CT (optional), 1 Select area, 2 Preview, 3 Segment, 4 Smooth
cuts, 5 Improve (optional), 6a Sheet pattern (unfold, export) or 6b Printed bolus (shell, print
parts, orient, export parts), 6c Export to planning system (RTSTRUCT).
Each step has a number, a one-line hint, and, when its input is missing, is greyed with the
reason as a label (the operators' poll message, `guide.reason`); the next step for the active
object is marked with an arrow and drawn as a larger, pressed button.  The unit in use, a
warning when the object's size says the units are wrong, the tables and the advice are shown
as they come.  The same operators are in *Object / Mesh > Bolus*, which F3 finds.
"""
from __future__ import annotations

import bpy

from .blender import guide, mesh_io, panel_tables
from .blender.objects import PROP_DICOM_DIR, PROP_DICOM_PATIENT, bolus_for, dicom_source, print_source
from .blender.panel_layout import OP_SETTINGS, STEP_OF, Guide, set_settings, wrapped_label
from .blender.panel_tables import size_warning

#: the line every user reads (README "Intended use")
DISCLAIMER = "A planning aid, not a medical device: check every bolus on the planning CT before treatment"


def draw_head(layout, g: Guide) -> None:
    """The unit, a red warning when the active object's size says it is wrong, the intended use, the next step."""
    mm = mesh_io.mm_per_unit(g.context.scene)
    col = layout.column(align=True)
    col.label(text=f"1 unit = {mm:g} mm; every figure is in mm", icon="DRIVER_DISTANCE")
    col.prop(g.s, "time_limit_s")
    warn = size_warning(g.obj, mm)
    if warn:
        red = col.column(align=True)
        red.alert = True
        wrapped_label(red, warn, g.width, icon="ERROR")
    wrapped_label(col, DISCLAIMER, g.width, icon="INFO")
    made = guide.made_object(g.obj)
    if made is not None:
        wrapped_label(layout.column(align=True), f"'{g.obj.name}' is {made[0]}: the steps on the skin are "
                      f"greyed (select '{made[1]}' for them)", g.width, icon="INFO")
    wrapped_label(layout.column(align=True), "Next: " + g.next_text, g.width, icon="FORWARD")


def draw_ct(layout, g: Guide) -> None:
    """0: the skin from a planning CT folder (a directory browser opens)."""
    box = g.step(layout, "ct")
    g.button(g.gate_op(box, "bolus.import_dicom"), "bolus.import_dicom", icon="IMPORT")


def draw_planning(layout, g: Guide) -> None:
    """6c: the selected solid back as an RTSTRUCT on its CT (a file browser opens)."""
    box = g.step(layout, "planning")
    src = dicom_source(g.obj)
    if src is not None:
        wrapped_label(box, f"CT of patient {src.get(PROP_DICOM_PATIENT, '?')}: {src.get(PROP_DICOM_DIR, '?')}",
                      g.width, icon="INFO")
    g.button(g.gate_op(box, "bolus.export_rtstruct"), "bolus.export_rtstruct", icon="EXPORT")


def draw_area(layout, g: Guide) -> None:
    box = g.step(layout, "area")
    col = g.gate_op(box, "bolus.select_area", skin=True)
    row = col.row(align=True)
    row.prop(g.s, "area_radius_mm", text="Radius (mm)")
    row.prop(g.s, "exclude_cavities")
    g.button(col, "bolus.select_area", icon="PIVOT_CURSOR")


def draw_preview(layout, g: Guide) -> None:
    box = g.step(layout, "preview")
    col = g.gate_op(box, "bolus.saliency_preview", skin=True)
    col.prop(g.s, "smoothing_mm", text="Smoothing (mm)")
    col.prop(g.s, "color_by")
    g.button(col, "bolus.saliency_preview", icon="COLOR")
    panel_tables.draw_preview_figures(box, g.obj)


def draw_segment(layout, g: Guide) -> None:
    box = g.step(layout, "segment")
    col = g.gate_op(box, "bolus.segment", skin=True)
    sub = col.column(align=True)
    sub.prop(g.s, "patches")
    sub.prop(g.s, "eta")
    sub.prop(g.s, "seed")
    col.prop(g.s, "method")
    g.button(col, "bolus.segment", icon="MESH_ICOSPHERE")
    panel_tables.draw_patch_table(box, g.obj)


def draw_cuts(layout, g: Guide) -> None:
    box = g.step(layout, "cuts")
    col = g.gate_op(box, "bolus.smooth_cuts", skin=True)
    g.button(col, "bolus.smooth_cuts", icon="IPO_EASE_IN_OUT")
    panel_tables.draw_cut_table(box, g.obj)


def draw_improve(layout, g: Guide) -> None:
    """The optional step between the patches and the pattern, and its Table 4-4 after a run."""
    box = g.step(layout, "improve")
    col = g.gate_op(box, "bolus.improve_flattenability", skin=True)
    row = col.row(align=True)
    row.prop(g.s, "max_gap_mm", text="Max gap (mm)")
    row.prop(g.s, "improve_method", text="")
    col.prop(g.s, "seed")
    g.button(col, "bolus.improve_flattenability", icon="MOD_SMOOTH")
    panel_tables.draw_improve_table(box, g.obj)


def draw_sheet(layout, g: Guide) -> None:
    box = g.step(layout, "sheet")
    s, obj = g.s, g.obj
    col = g.gate_op(box, "bolus.unfold", skin=True)
    row = col.row(align=True)
    row.prop(s, "max_el_pct", text="Max EL")
    row.prop(s, "sheet_thickness_mm", text="Sheet (mm)")
    col.prop(s, "unfold_method")
    row = col.row(align=True)
    row.prop(s, "refine")
    row.prop(s, "gap_mm", text="Gap (mm)")
    g.button(col, "bolus.unfold", icon="MOD_UVPROJECT")
    panel_tables.draw_pattern_figures(box, obj)
    box.prop(s, "warn_distortion_pct")
    col = g.gate_op(box, "bolus.export_pattern")
    col.prop(s, "seam_allowance_mm", text="Seam allowance (mm)")
    row = col.row(align=True)
    row.prop(s, "page", text="")
    row.prop(s, "label", text="ID")
    row = col.row(align=True)
    for fmt in ("SVG", "DXF", "PDF"):
        op = g.button(row, "bolus.export_pattern", text=fmt, icon="EXPORT")
        op.file_format = fmt


def draw_print(layout, g: Guide) -> None:
    """6b: Make Bolus and its figures, then (the bolus selected) split, orient, export the parts."""
    box = g.step(layout, "print")
    s, obj = g.s, g.obj
    col = g.gate_op(box, "bolus.make_shell", skin=True)
    sub = col.column(align=True)
    sub.prop(s, "thickness_mm", text="Thickness (mm)")
    sub.prop(s, "clearance_mm", text="Clearance (mm)")
    sub.prop(s, "resolution_mm", text="Resolution (mm)")
    col.prop(s, "label")
    row = col.row(align=True)
    row.prop(s, "left_axis", text="Left")
    row.prop(s, "density_g_cm3", text="g/cm³")
    g.button(col, "bolus.make_shell", icon="MOD_SOLIDIFY")
    panel_tables.draw_bolus_figures(box, bolus_for(obj))
    # split and orient: the operators take any surface (SPEC), the guide leads to the solid
    col = g.gate(box, guide.needs_bolus_selected(g.context))
    col.prop(s, "connector_clearance_mm", text="Connector clearance (mm)")
    row = col.row(align=True)
    sub = row.row(align=True)
    sub.active = s.print_method != "LEARNED"  # the learned split finds the number itself
    sub.prop(s, "parts")
    row.prop(s, "print_method", text="")
    g.button(col, "bolus.print_segment", icon="MOD_EXPLODE")
    src = print_source(obj)
    panel_tables.draw_print_summary(box, src)
    row = col.row(align=True)
    row.prop(s, "layer_mm", text="Layer (mm)")
    row.prop(s, "skin_side_up")
    g.button(col, "bolus.orient_parts", icon="ORIENTATION_GIMBAL")
    panel_tables.draw_orient_table(box, src)
    col = g.gate_op(box, "bolus.export_parts")
    g.button(col, "bolus.export_parts", icon="EXPORT")


def draw_library(layout, g: Guide) -> None:
    """7: the library folder and the photo, Build and Find, the best matches of the last search."""
    box = g.step(layout, "library")
    col = box.column(align=True)
    col.prop(g.s, "library_dir", text="Library")
    panel_tables.draw_library_cache(col, g.context.scene)
    g.button(col, "bolus.build_library", icon="FILE_REFRESH")
    col.prop(g.s, "photo_path", text="Photo")
    row = col.row(align=True)
    row.prop(g.s, "retrieve_count")
    row.prop(g.s, "retrieve_method", text="")
    g.button(col, "bolus.retrieve", icon="VIEWZOOM")
    panel_tables.draw_library_matches(box, g.context.scene)


class VIEW3D_PT_bolus(bpy.types.Panel):
    bl_label = "Bolus"
    bl_idname = "VIEW3D_PT_bolus"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Bolus"

    def draw(self, context):
        layout = self.layout
        g = Guide(context)
        draw_head(layout, g)
        for draw in (draw_ct, draw_area, draw_preview, draw_segment, draw_cuts, draw_improve, draw_sheet, draw_print,
                     draw_planning, draw_library):
            draw(layout, g)


class VIEW3D_MT_bolus(bpy.types.Menu):
    """Every bolus operator in step order, under Object > Bolus and Mesh > Bolus (Edit Mode):
    F3 (menu search) finds an operator only in a menu; greyed with the same reasons as the panel."""

    bl_label = "Bolus"
    bl_idname = "VIEW3D_MT_bolus"
    #: the menus it is appended to (Object Mode, Edit Mode)
    parents = ("VIEW3D_MT_object", "VIEW3D_MT_edit_mesh")

    def draw(self, context):
        layout = self.layout
        s = context.scene.bolus
        last = None
        for idname in OP_SETTINGS:
            if last is not None and STEP_OF[idname] != last:
                layout.separator()
            last = STEP_OF[idname]
            set_settings(layout.operator(idname), idname, s)

    @staticmethod
    def draw_entry(self, context):
        self.layout.separator()
        self.layout.menu(VIEW3D_MT_bolus.bl_idname)

    @classmethod
    def register(cls):
        for name in cls.parents:
            getattr(bpy.types, name).append(cls.draw_entry)

    @classmethod
    def unregister(cls):
        for name in cls.parents:
            getattr(bpy.types, name).remove(cls.draw_entry)


classes = (VIEW3D_MT_bolus, VIEW3D_PT_bolus)
