"""The sidebar's figures and tables: what the operators left on the objects, drawn under each step.

Each ``draw_*`` function reads the custom properties (JSON tables, figures) an operator wrote
on the active object, or on the object it belongs to (its pattern, improved surface, bolus,
print source), and draws them into the step's box; nothing is drawn when there is nothing
to show.  The pattern's pieces that are not fit to cut are drawn in red with a word of advice.
"""
from __future__ import annotations

import bpy
import numpy as np

from . import guide, mesh_io, mesh_region
from .objects import (
    PATTERN_SUFFIX,
    PROP_CONNECTORS,
    PROP_CUT_TABLE,
    PROP_FLV,
    PROP_IMPROVE_TABLE,
    PROP_LIBRARY,
    PROP_MASS,
    PROP_ORIENT_TABLE,
    PROP_PATCH_TABLE,
    PROP_PATTERN_TABLE,
    PROP_PRINT_TABLE,
    PROP_RETRIEVAL,
    PROP_RETRIEVAL_INFO,
    PROP_SUM_VARPI,
    PROP_THICKNESS_MAX,
    PROP_THICKNESS_MEAN,
    PROP_THICKNESS_MIN,
    PROP_VOLUME,
    improved_of,
)
from .panel_layout import draw_table


def size_warning(obj, mm: float) -> str | None:
    """mesh_region.size_warning on the active object's bounding box (dimensions, world scale included)."""
    if obj is None or obj.type != "MESH":
        return None
    dims = np.array(obj.dimensions, dtype=np.float64) * mm
    return mesh_region.size_warning(np.array([np.zeros(3), dims]), mm)


def draw_preview_figures(box, obj) -> None:
    """Σϖ and FLV of the last preview, only with the attribute they describe: Ctrl+Z in Edit Mode
    restores the mesh (attributes) but not the object's custom properties."""
    if guide.has_preview(obj) and PROP_SUM_VARPI in obj:
        box.label(text=f"Σϖ = {obj[PROP_SUM_VARPI]:.3f} rad   FLV = {obj[PROP_FLV]:.3g}")


def draw_patch_table(box, obj) -> None:
    """The patches of Segment into Patches: vertices, triangles, Σϖ and FLV of each."""
    table = mesh_io.json_prop(obj, PROP_PATCH_TABLE) if guide.has_patches(obj) else None
    table = table.get("patches") if isinstance(table, dict) else None
    if table:
        draw_table(box, ("Patch", "Verts", "Tris", "Σϖ", "FLV"), (
            (str(r["patch"]), str(r["vertices"]), str(r["faces"]), f"{r['sum_varpi']:.2f}", f"{r['flv']:.3g}")
            for r in table))


def draw_cut_table(box, obj) -> None:
    """The borders Smooth Cut Lines smoothed: method, turning before -> after, how far they moved."""
    cuts = mesh_io.json_prop(obj, PROP_CUT_TABLE)
    if cuts:
        draw_table(box, ("Border", "Cut", "Turn/mm", "Moved"), (
            (f"{r['a']}|{r['b']}", r["method"], f"{r['turning_before']:.2f}→{r['turning_after']:.2f}",
             f"{r['max_shift_mm']:.1f} mm") for r in cuts))


def _improve_row(name: str, st: dict) -> tuple:
    return (name, f"{st['flv']:.3g}", f"{st['sum_varpi']:.2f}", f"{st['max_varpi']:.3f}", f"{st['smoothness']:.1f}",
            f"{st['area_mm2']:.0f}", f"{st['max_gap_mm']:.2f}")


def draw_improve_table(box, obj) -> None:
    """The improved surface's Table 4-4: the whole region (and every patch) before -> after."""
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


def draw_pattern_figures(box, obj) -> None:
    """The pattern of obj (obj itself or its ``<name>_pattern``): EL, EA and the table of its pieces."""
    pat = None
    if obj is not None:
        pat = obj if PROP_PATTERN_TABLE in obj else bpy.data.objects.get(obj.name + PATTERN_SUFFIX)
    t = mesh_io.json_prop(pat, PROP_PATTERN_TABLE)
    if t:
        box.label(text=f"{pat.name}: EL {t['EL'] * 100:.2f} %  EA {t['EA'] * 100:.2f} %")
        draw_pattern_table(box, t)


def draw_bolus_figures(box, b) -> None:
    """The bolus solid's volume, mass and wall, and its joints once it is split."""
    if b is None or PROP_VOLUME not in b:
        return
    box.label(text=f"{b.name}: {b[PROP_VOLUME]:.1f} cm³, {b.get(PROP_MASS, 0.0):.0f} g")
    box.label(text=f"Wall {b.get(PROP_THICKNESS_MIN, 0.0):.2f} / {b.get(PROP_THICKNESS_MEAN, 0.0):.2f} / "
                   f"{b.get(PROP_THICKNESS_MAX, 0.0):.2f} mm (min / mean / max)")
    joints = mesh_io.json_prop(b, PROP_CONNECTORS)
    if joints is not None:
        plain = sum(1 for j in joints if not j["connectors"])
        box.label(text=f"{len(joints)} joints, {sum(len(j['connectors']) for j in joints)} connectors"
                       + (f", {plain} plain" if plain else ""))


def draw_print_summary(box, src) -> None:
    """How many print parts Split into Print Parts made, and how balanced their areas are."""
    t = mesh_io.json_prop(src, PROP_PRINT_TABLE)
    if t and "parts" in t:
        found = f" (learned: {t['ap_clusters']} clusters)" if t.get("ap_clusters") else ""
        box.label(text=f"{len(t['parts'])} parts{found}, largest/smallest area {t['area_balance']:.2f}")


def draw_orient_table(box, src) -> None:
    """The oriented parts: triangles, WQ, WU and support volume of each, and the support saved."""
    t = mesh_io.json_prop(src, PROP_ORIENT_TABLE)
    if t:
        draw_table(box, ("Part", "Tris", "WQ mm³", "WU mm³", "Support"), (
            (r["part"], str(r["faces"]), f"{r['WQ']:.0f}", f"{r['WU']:.0f}", f"{r['support_volume_mm3']:.0f}")
            for r in t["rows"]))
        if t.get("support_ratio") is not None:
            box.label(text=f"Parts' support: {t['support_ratio'] * 100:.0f} % of the whole model's")


def draw_library_cache(col, scene) -> None:
    """How many models the last Build Bolus Library cached."""
    lib = mesh_io.json_prop(scene, PROP_LIBRARY)
    if lib:
        col.label(text=f"{lib['models']} models cached", icon="CHECKMARK")


def draw_library_matches(box, scene) -> None:
    """The best matches of the last Find Matching Bolus, best first, with the confidence of the first."""
    found = mesh_io.json_prop(scene, PROP_RETRIEVAL)
    if found:
        draw_table(box, ("#", "Model", "Dissimilarity"),
                   ((str(k), r["model"], f"{r['score']:.4g}") for k, r in enumerate(found, 1)))
    info = mesh_io.json_prop(scene, PROP_RETRIEVAL_INFO)
    if found and info:
        conf = info.get("confidence", 0.0)
        box.label(text=f"{info.get('method', '')}: confidence {100 * conf:.0f} % (the runner-up "
                       f"{100 * conf:.0f} % farther)", icon="ERROR" if info.get("tie") else "INFO")
        if info.get("tie"):
            box.label(text="Near tie: look at both before choosing")
