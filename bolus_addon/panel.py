"""Sidebar panel (3D View > Sidebar > Bolus): a guided walk through a case, and the Bolus menu (F3).

The steps in order: 1 Select area, 2 Preview, 3 Segment, 4 Smooth cuts, 5 Improve (optional),
6a Sheet pattern (unfold, export) or 6b Printed bolus (shell, print parts, orient, export parts).
Each step has a number, a one-line hint, and, when its input is missing, is greyed with the
reason as a label (the operators' poll message, `guide.reason`); the next step for the active
object is marked with an arrow and drawn as a larger, pressed button.  The unit in use, a
warning when the object's size says the units are wrong, the tables and the advice are shown
as they come.  The same operators are in *Object / Mesh > Bolus*, which F3 finds.
"""
from __future__ import annotations

import textwrap

import bpy
import numpy as np

from .blender import guide, mesh_io
from .operators.cuts import PROP_CUT_TABLE
from .operators.improve import IMPROVED_SUFFIX, PROP_IMPROVE_TABLE
from .blender.operator_base import PROP_FLV, PROP_PATCH_TABLE, PROP_SUM_VARPI
from .operators.unfold import PATTERN_SUFFIX, PROP_PATTERN_TABLE
from .operators.printing import ATTR_PRINT_PART, PROP_ORIENT_TABLE, PROP_PART_SOURCE, PROP_PRINT_TABLE, part_objects
from .operators.solid import (
    PROP_MASS,
    PROP_THICKNESS_MAX,
    PROP_THICKNESS_MEAN,
    PROP_THICKNESS_MIN,
    PROP_VOLUME,
    is_bolus_object,
)
from .operators.retrieval import PROP_LIBRARY, PROP_RETRIEVAL
from .operators.solid_print import PROP_CONNECTORS

#: the line every user reads (README "Intended use")
DISCLAIMER = "A planning aid, not a medical device: check every bolus on the planning CT before treatment"

#: operator property <- Scene.bolus property, for the buttons of the panel and the menu
OP_SETTINGS = {
    "bolus.select_area": {"radius_mm": "area_radius_mm", "exclude_cavities": "exclude_cavities"},
    "bolus.saliency_preview": {"smoothing_mm": "smoothing_mm", "color_by": "color_by"},
    "bolus.segment": {"patches": "patches", "eta": "eta", "seed": "seed", "smoothing_mm": "smoothing_mm",
                      "method": "method"},
    "bolus.smooth_cuts": {},
    "bolus.improve_flattenability": {"max_gap_mm": "max_gap_mm", "method": "improve_method", "seed": "seed"},
    "bolus.unfold": {"method": "unfold_method", "refine": "refine", "gap_mm": "gap_mm", "max_el": "max_el_pct",
                     "sheet_thickness_mm": "sheet_thickness_mm"},
    "bolus.export_pattern": {"seam_allowance_mm": "seam_allowance_mm", "page": "page", "label": "label"},
    "bolus.make_shell": {"thickness_mm": "thickness_mm", "clearance_mm": "clearance_mm",
                         "resolution_mm": "resolution_mm", "label": "label"},
    "bolus.print_segment": {"parts": "parts", "method": "print_method", "seed": "seed"},
    "bolus.orient_parts": {"layer_mm": "layer_mm", "skin_side_up": "skin_side_up"},
    "bolus.export_parts": {},
    "bolus.build_library": {"directory": "library_dir"},
    "bolus.retrieve": {"filepath": "photo_path", "directory": "library_dir", "count": "retrieve_count"},
}

#: (number, title, icon, hint: what it does and what it needs) of every step, in order
STEPS = {
    "area": ("1", "Select area", "PIVOT_CURSOR", "Faces around the 3D cursor (needs: the skin, the cursor on it)"),
    "preview": ("2", "Preview", "COLOR", "Where the skin cannot lie flat (needs: the skin)"),
    "segment": ("3", "Segment", "MESH_ICOSPHERE", "Patches that flatten well (needs: the skin in one piece)"),
    "cuts": ("4", "Smooth cuts", "IPO_EASE_IN_OUT", "Smooth patch borders, changes the mesh (needs: patches)"),
    "improve": ("5", "Improve (optional)", "MOD_SMOOTH", "A flatter copy, at most Max gap off the skin "
                                                         "(needs: the skin)"),
    "sheet": ("6a", "Sheet pattern", "UV", "Flat pattern at true size, then export (needs: the skin, "
                                          "best with patches)"),
    "print": ("6b", "Printed bolus", "MOD_SOLIDIFY", "Solid, print parts, orient, export STL (needs: the skin)"),
    "library": ("7", "Bolus library", "ASSET_MANAGER", "A stored bolus like a photo, to start from (needs: a folder "
                                                     "of .blend / .stl / .obj models, a photo)"),
}
#: the step each operator belongs to
STEP_OF = {"bolus.select_area": "area", "bolus.saliency_preview": "preview", "bolus.segment": "segment",
           "bolus.smooth_cuts": "cuts", "bolus.improve_flattenability": "improve", "bolus.unfold": "sheet",
           "bolus.export_pattern": "sheet", "bolus.make_shell": "print", "bolus.print_segment": "print",
           "bolus.orient_parts": "print", "bolus.export_parts": "print", "bolus.build_library": "library",
           "bolus.retrieve": "library"}


def set_settings(op, idname: str, s) -> None:
    """The Scene.bolus settings onto the operator properties of a button (`OP_SETTINGS`)."""
    for op_name, scene_name in OP_SETTINGS.get(idname, {}).items():
        setattr(op, op_name, getattr(s, scene_name))


def draw_table(layout, heads, rows, alert=()) -> None:
    """A table of labels: a header row, then one row per tuple of strings; rows whose
    index is in `alert` are drawn in red."""
    grid = layout.grid_flow(row_major=True, columns=len(heads), even_columns=True, align=True)
    for text in heads:
        grid.label(text=text)
    alert = set(alert)
    for i, row in enumerate(rows):
        for text in row:
            if i in alert:
                cell = grid.row()
                cell.alert = True
                cell.label(text=text)
            else:
                grid.label(text=text)


def _radius(R) -> str:
    return "flat" if R is None else f"{R:.0f}"


def draw_pattern_table(layout, t: dict) -> None:
    """The pattern's pieces with their figures and the sheet-or-print advice; the ones not fit
    to cut (unfold's warnings) in red, with a red summary line and a few words of advice each."""
    rows = t.get("islands", [])
    bad = [i for i, r in enumerate(rows) if r.get("warn") or r.get("sheet") == "print"]
    thick = t.get("sheet_thickness_mm", 0.0) > 0
    heads = ("Piece", "EL %", "EA %", "Area") + (("R mm", "Strain %") if thick else ()) + ("Use",)
    draw_table(layout, heads, [
        (r.get("name", f"patch {r['patch']}").removeprefix("patch ").replace(" piece ", "."),
         f"{r['EL'] * 100:.1f}", f"{r['EA'] * 100:.1f}", f"{r['area_ratio']:.2f}" if "area_ratio" in r else "-")
        + ((_radius(r.get("R_min_mm")), f"{r['strain'] * 100:.0f}" if "strain" in r else "-") if thick else ())
        + (r.get("sheet", "-"),)
        for r in rows], alert=bad)
    if t.get("darts") or t.get("splits"):
        layout.label(text=f"{t.get('pieces', len(rows))} pieces: {t.get('darts', 0)} darts, "
                          f"{t.get('splits', 0)} splits", icon="MOD_EDGESPLIT")
    for u in t.get("unmet", []):
        row = layout.row()
        row.alert = True
        row.label(text=f"Patch {u['patch']} misses Max EL: see the warnings", icon="ERROR")
    if bad:
        col = layout.column(align=True)
        col.alert = True
        col.label(text=f"{len(bad)} of {len(rows)} pieces not fit to cut from a sheet", icon="ERROR")
        for i in bad:
            r = rows[i]
            why = r.get("short_advice") if r.get("warn") else ""
            col.label(text=f"{r.get('name', r['patch'])}: {why or r.get('sheet_reason') or 'see the warnings'}")


def wrapped_label(layout, text: str, width: int, icon: str = "NONE") -> None:
    """text on as many label lines as the sidebar's width needs (labels do not wrap themselves)."""
    for i, line in enumerate(textwrap.wrap(text, width) or [""]):
        layout.label(text=line, icon=icon if i == 0 else "BLANK1")


def text_width(context) -> int:
    """About how many characters a label line of the sidebar holds (44 headless)."""
    region = getattr(context, "region", None)
    if region is None or not getattr(region, "width", 0):
        return 44
    scale = context.preferences.system.ui_scale if context.preferences else 1.0
    return max(20, int(region.width / (7.0 * scale)))


def size_warning(obj, mm: float) -> str | None:
    """mesh_io.size_warning on the active object's bounding box (dimensions, world scale included)."""
    if obj is None or obj.type != "MESH":
        return None
    dims = np.array(obj.dimensions, dtype=np.float64) * mm
    return mesh_io.size_warning(np.array([np.zeros(3), dims]), mm)


def smooth_cuts_done(obj) -> bool:
    """Smooth Cut Lines has run on obj (on an improved surface: on its source), or there is no
    border to smooth (one patch)."""
    if guide.is_improved(obj):
        obj = bpy.data.objects.get(obj.get("bolus_source", ""), obj)
    if PROP_CUT_TABLE in obj:
        return True
    t = mesh_io.json_prop(obj, PROP_PATCH_TABLE)
    return isinstance(t, dict) and (bool(t.get("smooth_cuts")) or len(t.get("patches", [])) <= 1)


def next_step(context) -> tuple[str, set[str]]:
    """(what to do next, the operators to highlight) from what the active object has."""
    obj = context.active_object
    if guide.needs_mesh(context):
        return "Select the skin surface mesh (an STL imported in mm)", set()
    if guide.is_pattern(obj):
        return "6a Export the pattern (SVG, DXF or PDF)", {"bolus.export_pattern"}
    if is_bolus_object(obj):
        if ATTR_PRINT_PART not in obj.data.attributes:
            return "6b Split into Print Parts", {"bolus.print_segment"}
        if not part_objects(obj.name):
            return "6b Orient Print Parts", {"bolus.orient_parts"}
        return "6b Export Print Parts (STL)", {"bolus.export_parts"}
    b = guide.bolus_for(obj)
    if b is not None and obj.get(PROP_PART_SOURCE) == b.name:  # a print part
        return "6b Export Print Parts (STL)", {"bolus.export_parts"}
    if guide.pattern_of(obj) is not None:
        return "6a Export the pattern (or 6b Make Bolus)", {"bolus.export_pattern"}
    if b is not None:
        return f"6b Select '{b.name}', then Split into Print Parts", set()
    if guide.has_patches(obj):
        if smooth_cuts_done(obj):
            return "6a Unfold Patches or 6b Make Bolus", {"bolus.unfold", "bolus.make_shell"}
        return "4 Smooth Cut Lines", {"bolus.smooth_cuts"}
    if guide.has_preview(obj):
        return "3 Segment into Patches", {"bolus.segment"}
    if obj.mode == "EDIT" and obj.data.total_face_sel > 0:
        return "2 Flattenability Preview of the selected faces", {"bolus.saliency_preview"}
    return "1 Select Treatment Area (or select faces in Edit Mode)", {"bolus.select_area"}


class Guide:
    """What one draw of the panel needs: the context, the settings, the width, the next step."""

    def __init__(self, context):
        self.context = context
        self.s = context.scene.bolus
        self.obj = context.active_object
        self.width = text_width(context)
        self.next_text, self.next = next_step(context)
        self.not_skin = guide.needs_skin(context)

    def step(self, layout, key: str):
        """A box with the step's number, title (an arrow when it holds the next step) and hint."""
        number, title, icon, hint = STEPS[key]
        box = layout.box()
        is_next = any(STEP_OF[i] == key for i in self.next)
        box.label(text=f"{number}  {title}", icon="FORWARD" if is_next else icon)
        col = box.column(align=True)
        col.scale_y = 0.8
        wrapped_label(col, hint, self.width)
        return box

    def gate(self, layout, why: str | None):
        """A column greyed when ``why`` (the reason, shown above it as a label) says the input is missing."""
        if why:
            wrapped_label(layout, why, self.width, icon="INFO")
        col = layout.column()
        col.enabled = not why
        return col

    def gate_op(self, layout, idname: str, skin: bool = False):
        """`gate` with the operator's poll reason; ``skin``: a step on the skin, greyed on a made
        object (a pattern, a bolus, a part) with the way back to the skin instead."""
        why = (self.not_skin if skin else None) or guide.reason(idname, self.context)
        return self.gate(layout, why)

    def button(self, layout, idname: str, text: str | None = None, icon: str = "NONE"):
        """The operator's button with the scene's settings; the next step's larger and pressed."""
        row = layout.row(align=True)
        is_next = idname in self.next
        if is_next:
            row.scale_y = 1.5
        kw = {"icon": icon, "depress": is_next}
        if text is not None:
            kw["text"] = text
        op = row.operator(idname, **kw)
        set_settings(op, idname, self.s)
        return op


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
    obj = g.obj
    # the figures only with the attribute they describe: Ctrl+Z in Edit Mode restores the mesh
    # (attributes) but not the object's custom properties
    if guide.has_preview(obj) and PROP_SUM_VARPI in obj:
        box.label(text=f"Σϖ = {obj[PROP_SUM_VARPI]:.3f} rad   FLV = {obj[PROP_FLV]:.3g}")


def draw_segment(layout, g: Guide) -> None:
    box = g.step(layout, "segment")
    col = g.gate_op(box, "bolus.segment", skin=True)
    sub = col.column(align=True)
    sub.prop(g.s, "patches")
    sub.prop(g.s, "eta")
    sub.prop(g.s, "seed")
    col.prop(g.s, "method")
    g.button(col, "bolus.segment", icon="MESH_ICOSPHERE")
    table = mesh_io.json_prop(g.obj, PROP_PATCH_TABLE) if guide.has_patches(g.obj) else None
    table = table.get("patches") if isinstance(table, dict) else None
    if table:
        draw_table(box, ("Patch", "Verts", "Tris", "Σϖ", "FLV"), (
            (str(r["patch"]), str(r["vertices"]), str(r["faces"]), f"{r['sum_varpi']:.2f}", f"{r['flv']:.3g}")
            for r in table))


def draw_cuts(layout, g: Guide) -> None:
    box = g.step(layout, "cuts")
    col = g.gate_op(box, "bolus.smooth_cuts", skin=True)
    g.button(col, "bolus.smooth_cuts", icon="IPO_EASE_IN_OUT")
    cuts = mesh_io.json_prop(g.obj, PROP_CUT_TABLE)
    if cuts:
        draw_table(box, ("Border", "Cut", "Turn/mm", "Moved"), (
            (f"{r['a']}|{r['b']}", r["method"], f"{r['turning_before']:.2f}→{r['turning_after']:.2f}",
             f"{r['max_shift_mm']:.1f} mm") for r in cuts))


def improved_of(obj):
    """The improved surface to show figures of: obj itself or its ``<name>_improved``."""
    if obj is None:
        return None
    if PROP_IMPROVE_TABLE in obj:
        return obj
    return bpy.data.objects.get(obj.name + IMPROVED_SUFFIX)


def _improve_row(name: str, st: dict) -> tuple:
    return (name, f"{st['flv']:.3g}", f"{st['sum_varpi']:.2f}", f"{st['max_varpi']:.3f}", f"{st['smoothness']:.1f}",
            f"{st['area_mm2']:.0f}", f"{st['max_gap_mm']:.2f}")


def draw_improve(layout, g: Guide) -> None:
    """The optional step between the patches and the pattern, and its Table 4-4 after a run."""
    box = g.step(layout, "improve")
    col = g.gate_op(box, "bolus.improve_flattenability", skin=True)
    row = col.row(align=True)
    row.prop(g.s, "max_gap_mm", text="Max gap (mm)")
    row.prop(g.s, "improve_method", text="")
    col.prop(g.s, "seed")
    g.button(col, "bolus.improve_flattenability", icon="MOD_SMOOTH")
    imp = improved_of(g.obj)
    t = mesh_io.json_prop(imp, PROP_IMPROVE_TABLE)
    if not isinstance(t, dict) or "whole" not in t:
        return
    w = t["whole"]
    box.label(text=f"{imp.name}: {t.get('status', '')}, FLV {w['before']['flv']:.3g} → {w['after']['flv']:.3g}, "
                   f"gap ≤ {w['after']['max_gap_mm']:.2f} mm")
    rows = [_improve_row("all", w["before"]), _improve_row("→", w["after"])]
    if t.get("per_patch"):
        for p in t.get("patches", []):
            rows += [_improve_row(f"P{p['patch']}", p["before"]), _improve_row("→", p["after"])]
    draw_table(box, ("", "FLV", "Σϖ", "max ϖ", "Smooth", "mm²", "Gap"), rows)


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
    pat = None
    if obj is not None:
        pat = obj if PROP_PATTERN_TABLE in obj else bpy.data.objects.get(obj.name + PATTERN_SUFFIX)
    t = mesh_io.json_prop(pat, PROP_PATTERN_TABLE)
    if t:
        box.label(text=f"{pat.name}: EL {t['EL'] * 100:.2f} %  EA {t['EA'] * 100:.2f} %")
        draw_pattern_table(box, t)
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
    b = guide.bolus_for(obj)
    if b is not None and PROP_VOLUME in b:
        box.label(text=f"{b.name}: {b[PROP_VOLUME]:.1f} cm³, {b.get(PROP_MASS, 0.0):.0f} g")
        box.label(text=f"Wall {b.get(PROP_THICKNESS_MIN, 0.0):.2f} / {b.get(PROP_THICKNESS_MEAN, 0.0):.2f} / "
                       f"{b.get(PROP_THICKNESS_MAX, 0.0):.2f} mm (min / mean / max)")
        joints = mesh_io.json_prop(b, PROP_CONNECTORS)
        if joints is not None:
            plain = sum(1 for j in joints if not j["connectors"])
            box.label(text=f"{len(joints)} joints, {sum(len(j['connectors']) for j in joints)} connectors"
                           + (f", {plain} plain" if plain else ""))
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
    t = mesh_io.json_prop(src, PROP_PRINT_TABLE)
    if t and "parts" in t:
        found = f" (learned: {t['ap_clusters']} clusters)" if t.get("ap_clusters") else ""
        box.label(text=f"{len(t['parts'])} parts{found}, largest/smallest area {t['area_balance']:.2f}")
    row = col.row(align=True)
    row.prop(s, "layer_mm", text="Layer (mm)")
    row.prop(s, "skin_side_up")
    g.button(col, "bolus.orient_parts", icon="ORIENTATION_GIMBAL")
    t = mesh_io.json_prop(src, PROP_ORIENT_TABLE)
    if t:
        draw_table(box, ("Part", "Tris", "WQ mm³", "WU mm³", "Support"), (
            (r["part"], str(r["faces"]), f"{r['WQ']:.0f}", f"{r['WU']:.0f}", f"{r['support_volume_mm3']:.0f}")
            for r in t["rows"]))
        if t.get("support_ratio") is not None:
            box.label(text=f"Parts' support: {t['support_ratio'] * 100:.0f} % of the whole model's")
    col = g.gate_op(box, "bolus.export_parts")
    g.button(col, "bolus.export_parts", icon="EXPORT")


def draw_library(layout, g: Guide) -> None:
    """7: the library folder and the photo, Build and Find, the best matches of the last search."""
    box = g.step(layout, "library")
    col = box.column(align=True)
    col.prop(g.s, "library_dir", text="Library")
    lib = mesh_io.json_prop(g.context.scene, PROP_LIBRARY)
    if lib:
        col.label(text=f"{lib['models']} models cached", icon="CHECKMARK")
    g.button(col, "bolus.build_library", icon="FILE_REFRESH")
    col.prop(g.s, "photo_path", text="Photo")
    col.prop(g.s, "retrieve_count")
    g.button(col, "bolus.retrieve", icon="VIEWZOOM")
    found = mesh_io.json_prop(g.context.scene, PROP_RETRIEVAL)
    if found:
        draw_table(box, ("#", "Model", "Dissimilarity"),
                   ((str(k), r["model"], f"{r['score']:.4g}") for k, r in enumerate(found, 1)))


def print_source(obj):
    """The object whose print tables to show: obj, or the source a print part names (a bolus and an
    improved surface name their skin in 'bolus_source' too, but their parts are their own)."""
    if (obj is not None and PROP_PART_SOURCE in obj and not is_bolus_object(obj)
            and PROP_IMPROVE_TABLE not in obj):
        return bpy.data.objects.get(obj[PROP_PART_SOURCE], obj)
    return obj


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
        for draw in (draw_area, draw_preview, draw_segment, draw_cuts, draw_improve, draw_sheet, draw_print,
                     draw_library):
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
