"""Sidebar panel (3D View > Sidebar > Bolus)."""
from __future__ import annotations

import bpy

from . import mesh_io
from .cut_ops import PROP_CUT_TABLE
from .improve_ops import IMPROVED_SUFFIX, PROP_IMPROVE_TABLE
from .operators import PROP_FLV, PROP_PATCH_TABLE, PROP_SUM_VARPI
from .pattern_ops import PATTERN_SUFFIX, PROP_PATTERN_TABLE
from .print_ops import PROP_ORIENT_TABLE, PROP_PART_SOURCE, PROP_PRINT_TABLE
from .shell_ops import (BOLUS_SUFFIX, PROP_MASS, PROP_THICKNESS_MAX, PROP_THICKNESS_MEAN, PROP_THICKNESS_MIN,
                        PROP_VOLUME, is_bolus_object)
from .solid_print_ops import PROP_CONNECTORS


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


def draw_saliency(box, s, obj):
    row = box.row(align=True)  # the treatment area around the 3D cursor (select_area), before the analysis
    row.prop(s, "area_radius_mm", text="Radius (mm)")
    row.prop(s, "exclude_cavities")
    op = box.operator("bolus.select_area", icon="PIVOT_CURSOR")
    op.radius_mm, op.exclude_cavities = s.area_radius_mm, s.exclude_cavities
    box.label(text="1. Where it cannot lie flat", icon="SHADING_SOLID")
    box.prop(s, "smoothing_mm", text="Smoothing (mm)")
    box.prop(s, "color_by")
    op = box.operator("bolus.saliency_preview", icon="COLOR")
    op.smoothing_mm = s.smoothing_mm
    op.color_by = s.color_by
    if obj is not None and PROP_SUM_VARPI in obj:
        box.label(text=f"Σϖ = {obj[PROP_SUM_VARPI]:.3f} rad   FLV = {obj[PROP_FLV]:.3g}")

def draw_patches(box, s, obj):
    box.label(text="2. Patches", icon="MOD_EXPLODE")
    col = box.column(align=True)
    col.prop(s, "patches")
    col.prop(s, "eta")
    col.prop(s, "seed")
    box.prop(s, "method")
    op = box.operator("bolus.segment", icon="MESH_ICOSPHERE")
    op.patches, op.eta, op.seed, op.smoothing_mm, op.method = s.patches, s.eta, s.seed, s.smoothing_mm, s.method
    table = mesh_io.json_prop(obj, PROP_PATCH_TABLE)
    table = table.get("patches") if isinstance(table, dict) else None
    if table:
        draw_table(box, ("Patch", "Verts", "Tris", "Σϖ", "FLV"), (
            (str(r["patch"]), str(r["vertices"]), str(r["faces"]), f"{r['sum_varpi']:.2f}", f"{r['flv']:.3g}")
            for r in table))
    box.operator("bolus.smooth_cuts", icon="IPO_EASE_IN_OUT")
    cuts = mesh_io.json_prop(obj, PROP_CUT_TABLE)
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


def draw_improve(box, s, obj):
    """The optional step between the patches and the pattern, and its Table 4-4 after a run."""
    box.label(text="Improve flattenability (optional)", icon="MOD_SMOOTH")
    row = box.row(align=True)
    row.prop(s, "max_gap_mm", text="Max gap (mm)")
    row.prop(s, "improve_method", text="")
    box.prop(s, "seed")
    op = box.operator("bolus.improve_flattenability", icon="MOD_SMOOTH")
    op.max_gap_mm, op.method, op.seed = s.max_gap_mm, s.improve_method, s.seed
    imp = improved_of(obj)
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


def draw_pattern(box, s, obj):
    box.label(text="3. Sheet pattern", icon="UV")
    row = box.row(align=True)
    row.prop(s, "max_el_pct", text="Max EL")
    row.prop(s, "sheet_thickness_mm", text="Sheet (mm)")
    box.prop(s, "unfold_method")
    row = box.row(align=True)
    row.prop(s, "refine")
    row.prop(s, "gap_mm", text="Gap (mm)")
    op = box.operator("bolus.unfold", icon="MOD_UVPROJECT")
    op.method, op.refine, op.gap_mm = s.unfold_method, s.refine, s.gap_mm
    op.max_el, op.sheet_thickness_mm = s.max_el_pct, s.sheet_thickness_mm
    pat = None
    if obj is not None:
        pat = obj if PROP_PATTERN_TABLE in obj else bpy.data.objects.get(obj.name + PATTERN_SUFFIX)
    t = mesh_io.json_prop(pat, PROP_PATTERN_TABLE)
    if t:
        box.label(text=f"{pat.name}: EL {t['EL'] * 100:.2f} %  EA {t['EA'] * 100:.2f} %")
        draw_pattern_table(box, t)
    box.prop(s, "warn_distortion_pct")
    box.prop(s, "seam_allowance_mm", text="Seam allowance (mm)")
    row = box.row(align=True)
    row.prop(s, "page", text="")
    row.prop(s, "label", text="ID")
    row = box.row(align=True)
    for fmt in ("SVG", "DXF", "PDF"):
        op = row.operator("bolus.export_pattern", text=fmt, icon="EXPORT")
        op.seam_allowance_mm, op.page, op.label, op.file_format = s.seam_allowance_mm, s.page, s.label, fmt

def bolus_of(obj):
    """The bolus solid to show figures of: obj itself, its ``<name>_bolus``, or the bolus a part came from."""
    if obj is None:
        return None
    if is_bolus_object(obj):
        return obj
    src = bpy.data.objects.get(obj.get(PROP_PART_SOURCE, ""))
    if is_bolus_object(src):
        return src
    return bpy.data.objects.get(obj.name + BOLUS_SUFFIX)


def draw_bolus(box, s, obj):
    box.label(text="4. Printed bolus", icon="MOD_SOLIDIFY")
    col = box.column(align=True)
    col.prop(s, "thickness_mm", text="Thickness (mm)")
    col.prop(s, "clearance_mm", text="Clearance (mm)")
    col.prop(s, "resolution_mm", text="Resolution (mm)")
    box.prop(s, "label")
    row = box.row(align=True)
    row.prop(s, "left_axis", text="Left")
    row.prop(s, "density_g_cm3", text="g/cm³")
    op = box.operator("bolus.make_shell", icon="MOD_SOLIDIFY")
    op.thickness_mm, op.clearance_mm, op.resolution_mm, op.label = (s.thickness_mm, s.clearance_mm,
                                                                     s.resolution_mm, s.label)
    b = bolus_of(obj)
    if b is not None and PROP_VOLUME in b:
        box.label(text=f"{b.name}: {b[PROP_VOLUME]:.1f} cm³, {b.get(PROP_MASS, 0.0):.0f} g")
        box.label(text=f"Wall {b.get(PROP_THICKNESS_MIN, 0.0):.2f} / {b.get(PROP_THICKNESS_MEAN, 0.0):.2f} / "
                       f"{b.get(PROP_THICKNESS_MAX, 0.0):.2f} mm (min / mean / max)")
        joints = mesh_io.json_prop(b, PROP_CONNECTORS)
        if joints is not None:
            plain = sum(1 for j in joints if not j["connectors"])
            box.label(text=f"{len(joints)} joints, {sum(len(j['connectors']) for j in joints)} connectors"
                           + (f", {plain} plain" if plain else ""))
    box.prop(s, "connector_clearance_mm", text="Connector clearance (mm)")


def print_source(obj):
    """The object whose print tables to show: obj, or the source a print part names (a bolus and an
    improved surface name their skin in 'bolus_source' too, but their parts are their own)."""
    if (obj is not None and PROP_PART_SOURCE in obj and not is_bolus_object(obj)
            and PROP_IMPROVE_TABLE not in obj):
        return bpy.data.objects.get(obj[PROP_PART_SOURCE], obj)
    return obj


def draw_print(box, s, obj):
    box.label(text="5. 3D print", icon="MOD_BUILD")
    row = box.row(align=True)
    row.prop(s, "parts")
    row.prop(s, "print_method", text="")
    op = box.operator("bolus.print_segment", icon="MOD_EXPLODE")
    op.parts, op.method, op.seed = s.parts, s.print_method, s.seed
    src = print_source(obj)
    t = mesh_io.json_prop(src, PROP_PRINT_TABLE)
    if t and "parts" in t:
        box.label(text=f"{len(t['parts'])} parts, largest/smallest area {t['area_balance']:.2f}")
    row = box.row(align=True)
    row.prop(s, "layer_mm", text="Layer (mm)")
    row.prop(s, "skin_side_up")
    op = box.operator("bolus.orient_parts", icon="ORIENTATION_GIMBAL")
    op.layer_mm, op.skin_side_up = s.layer_mm, s.skin_side_up
    t = mesh_io.json_prop(src, PROP_ORIENT_TABLE)
    if t:
        draw_table(box, ("Part", "Tris", "WQ mm³", "WU mm³", "Support"), (
            (r["part"], str(r["faces"]), f"{r['WQ']:.0f}", f"{r['WU']:.0f}", f"{r['support_volume_mm3']:.0f}")
            for r in t["rows"]))
        if t.get("support_ratio") is not None:
            box.label(text=f"Parts' support: {t['support_ratio'] * 100:.0f} % of the whole model's")
    box.operator("bolus.export_parts", icon="EXPORT")


class VIEW3D_PT_bolus(bpy.types.Panel):
    bl_label = "Bolus"
    bl_idname = "VIEW3D_PT_bolus"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Bolus"

    def draw(self, context):
        layout = self.layout
        s = context.scene.bolus
        obj = context.active_object
        layout.label(text=f"1 unit = {mesh_io.mm_per_unit(context.scene):g} mm", icon="DRIVER_DISTANCE")
        draw_saliency(layout.box(), s, obj)
        draw_patches(layout.box(), s, obj)
        draw_improve(layout.box(), s, obj)
        draw_pattern(layout.box(), s, obj)
        draw_bolus(layout.box(), s, obj)
        draw_print(layout.box(), s, obj)


classes = (VIEW3D_PT_bolus,)
