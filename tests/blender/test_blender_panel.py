"""The sidebar panel draws without error and only names real properties and operators.

Headless Blender has no UI to draw into, so the panel's draw() runs against a recording
layout that checks every `prop(data, name)` and every operator property it sets.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from bpy_helpers import make_object
from meshgen import cylinder_piece, icosphere, spherical_cap

pytestmark = pytest.mark.blender


class _Op:
    def __init__(self, bpy, idname):
        mod, name = idname.split(".")
        op = getattr(getattr(bpy.ops, mod), name)
        self.__dict__["_props"] = {p.identifier for p in op.get_rna_type().properties}
        self.__dict__["idname"] = idname

    def __setattr__(self, key, value):
        assert key in self._props, f"{self.idname} has no property {key!r}"
        self.__dict__[key] = value


class RecordingLayout:
    """Records labels, props and operators; a label drawn where `alert` is on (set here or
    on a parent layout, as in Blender) is recorded a second time as ("alert", text); an
    operator or prop drawn where `enabled` is off (here or on a parent) a second time as
    ("disabled", idname or name); a pressed operator button (the next step) as ("next", idname)."""

    def __init__(self, bpy, log, parent=None):
        self.bpy, self.log, self.parent = bpy, log, parent
        self._alert = False
        self._enabled = True
        self.scale_y = 1.0

    @property
    def alert(self):
        return self._alert or (self.parent is not None and self.parent.alert)

    @alert.setter
    def alert(self, value):
        self._alert = bool(value)

    @property
    def enabled(self):
        return self._enabled and (self.parent is None or self.parent.enabled)

    @enabled.setter
    def enabled(self, value):
        self._enabled = bool(value)

    def _child(self, *a, **k):
        return RecordingLayout(self.bpy, self.log, self)

    box = column = row = grid_flow = _child

    def separator(self, **k):
        pass

    def label(self, text="", **k):
        self.log.append(("label", text))
        if self.alert:
            self.log.append(("alert", text))

    def prop(self, data, name, **k):
        assert name in data.bl_rna.properties, f"{data} has no property {name!r}"
        self.log.append(("prop", name))
        if not self.enabled:
            self.log.append(("disabled", name))

    def operator(self, idname, **k):
        op = _Op(self.bpy, idname)
        self.log.append(("operator", idname))
        if not self.enabled:
            self.log.append(("disabled", idname))
        if k.get("depress"):
            self.log.append(("next", idname))
        return op

    def menu(self, idname, **k):
        self.log.append(("menu", idname))


def draw_panel(bpy):
    from bolus_addon.panel import VIEW3D_PT_bolus

    log = []

    class Fake:
        layout = RecordingLayout(bpy, log)

    VIEW3D_PT_bolus.draw(Fake(), bpy.context)
    return log


def test_panel_draws_before_and_after_every_step(bpy_addon, scene):
    bpy = bpy_addon
    log = draw_panel(bpy)  # no object at all
    assert ("operator", "bolus.segment") in log and ("operator", "bolus.unfold") in log
    V, F = spherical_cap(100.0, 50.0, 3)
    ob = make_object(bpy, V, F, scale_length=0.001)
    for step in (lambda: bpy.ops.bolus.saliency_preview(), lambda: bpy.ops.bolus.segment(patches=2),
                 lambda: bpy.ops.bolus.unfold()):
        assert step() == {"FINISHED"}
        log = draw_panel(bpy)
    labels = [t for kind, t in log if kind == "label"]
    assert any(t.startswith("Σϖ =") for t in labels)  # the analysis result
    table = json.loads(ob["bolus_patch_table"])["patches"]
    assert str(table[0]["vertices"]) in labels  # the patch table
    assert any(t.startswith(f"{ob.name}_pattern: EL") for t in labels)  # the pattern errors
    # the pattern object itself selected: the panel still finds its table
    bpy.context.view_layer.objects.active = bpy.data.objects[ob.name + "_pattern"]
    assert any(t.startswith(f"{ob.name}_pattern: EL") for k, t in draw_panel(bpy) if k == "label")


def test_unfold_invoked_from_a_script_runs_straight_through(bpy_addon, scene):
    """'INVOKE_DEFAULT' (what a button does) without a window falls back to execute."""
    bpy = bpy_addon
    V, F = spherical_cap(100.0, 40.0, 3)
    make_object(bpy, V, F, scale_length=0.001)
    assert bpy.ops.bolus.unfold("INVOKE_DEFAULT") == {"FINISHED"}
    pat = bpy.data.objects["skin_pattern"]
    co = np.empty(len(pat.data.vertices) * 3)
    pat.data.vertices.foreach_get("co", co)
    assert np.abs(co.reshape(-1, 3)[:, 2]).max() == 0.0


def test_panel_shows_the_print_tables(bpy_addon, scene):
    bpy = bpy_addon
    V, F = icosphere(3, 40.0)  # closed: the whole needs support, so the share is shown
    ob = make_object(bpy, V, F, scale_length=0.001)
    log = draw_panel(bpy)
    assert ("operator", "bolus.print_segment") in log and ("operator", "bolus.orient_parts") in log
    assert ("operator", "bolus.export_parts") in log
    assert bpy.ops.bolus.print_segment(parts=2) == {"FINISHED"}
    assert bpy.ops.bolus.orient_parts() == {"FINISHED"}
    labels = [t for kind, t in draw_panel(bpy) if kind == "label"]
    t = json.loads(ob["bolus_orient_table"])
    assert any(t_.endswith("area " + f"{json.loads(ob['bolus_print_table'])['area_balance']:.2f}") for t_ in labels)
    assert "whole" in labels and f"{t['rows'][0]['WQ']:.0f}" in labels  # the whole model's row first
    assert any(x.startswith("Parts' support:") for x in labels)
    # a part object selected: the panel still finds its source's tables
    bpy.context.view_layer.objects.active = bpy.data.objects[ob.name + "_part_0"]
    assert "whole" in [t_ for kind, t_ in draw_panel(bpy) if kind == "label"]


def test_panel_shows_pieces_not_fit_to_cut_in_red(bpy_addon, scene):
    """A 120 degree cap of 10 mm radius in one patch is warned: its row and a summary in red,
    with a few words of advice; the threshold is a scene setting shown in the panel."""
    bpy = bpy_addon
    V, F = spherical_cap(10.0, 120.0, 3)
    ob = make_object(bpy, V, F, scale_length=0.001)
    assert ("prop", "warn_distortion_pct") in draw_panel(bpy)
    assert bpy.ops.bolus.segment(patches=1) == {"FINISHED"}
    assert bpy.ops.bolus.unfold(max_el=0.0) == {"FINISHED"}  # one piece, no darts: it stays distorted
    row = json.loads(bpy.data.objects[ob.name + "_pattern"]["bolus_pattern_table"])["islands"][0]
    log = draw_panel(bpy)
    red = [t for kind, t in log if kind == "alert"]
    assert f"{row['EL'] * 100:.1f}" in red and f"{row['EA'] * 100:.1f}" in red and f"{row['area_ratio']:.2f}" in red
    assert any(t.startswith("1 of 1 pieces not fit to cut") for t in red)
    assert "patch 0: dome: more patches or a dart" in red
    # raised threshold: unfold again, nothing red
    scene.bolus.warn_distortion_pct = 50.0
    try:
        assert bpy.ops.bolus.unfold(max_el=0.0) == {"FINISHED"}
    finally:
        scene.bolus.property_unset("warn_distortion_pct")
    log = draw_panel(bpy)
    assert not [t for kind, t in log if kind == "alert"]
    assert f"{row['EL'] * 100:.1f}" in [t for kind, t in log if kind == "label"]  # the row is still there


def test_panel_shows_the_sheet_table_and_the_export_buttons(bpy_addon, scene):
    """With a sheet thickness the piece table has the radius, the strain and the advice; a piece
    to print is red; the three export buttons carry the page, the ID and their format."""
    bpy = bpy_addon
    V, F = cylinder_piece(radius=20.0, angle=np.pi, length=80.0, na=32, nl=6)
    ob = make_object(bpy, V, F, scale_length=0.001)
    assert bpy.ops.bolus.segment(patches=1) == {"FINISHED"}
    s = scene.bolus
    s.sheet_thickness_mm, s.label, s.page = 10.0, "PT 7", "A4"
    try:
        log = draw_panel(bpy)
        assert ("prop", "max_el_pct") in log and ("prop", "sheet_thickness_mm") in log and ("prop", "page") in log
        assert bpy.ops.bolus.unfold(max_el=2.0, sheet_thickness_mm=10.0) == {"FINISHED"}
        log = draw_panel(bpy)
    finally:
        for name in ("sheet_thickness_mm", "label", "page"):
            s.property_unset(name)
    row = json.loads(bpy.data.objects[ob.name + "_pattern"]["bolus_pattern_table"])["islands"][0]
    labels = [t for kind, t in log if kind == "label"]
    red = [t for kind, t in log if kind == "alert"]
    assert "R mm" in labels and "Strain %" in labels and "Use" in labels
    assert f"{row['R_min_mm']:.0f}" in red and "print" in red, red
    assert any(t.startswith("1 of 1 pieces not fit to cut from a sheet") for t in red)
    assert [t for kind, t in log if kind == "operator"].count("bolus.export_pattern") == 3


def test_panel_improve_section_and_its_table(bpy_addon, scene):
    """The optional step between the patches and the sheet pattern: max gap, optimiser, seed, the
    button (carrying the scene's settings), and after a run the Table 4-4 rows, whole and per patch."""
    bpy = bpy_addon
    V, F = spherical_cap(40.0, 50.0, 3)
    V = V + np.random.default_rng(1).uniform(-0.3, 0.3, V.shape)  # scan-like noise to remove
    ob = make_object(bpy, V, F, scale_length=0.001)
    log = draw_panel(bpy)
    i = log.index(("label", "5  Improve (optional)"))
    assert log.index(("operator", "bolus.segment")) < i < log.index(("operator", "bolus.unfold"))
    assert ("prop", "max_gap_mm") in log and ("prop", "improve_method") in log
    assert ("operator", "bolus.improve_flattenability") in log
    assert bpy.ops.bolus.segment(patches=2) == {"FINISHED"}
    s = scene.bolus
    s.max_gap_mm, s.smoothing_mm = 0.5, 0.0
    try:
        assert bpy.ops.bolus.improve_flattenability(max_gap_mm=s.max_gap_mm, method=s.improve_method,
                                                    seed=s.seed) == {"FINISHED"}
    finally:
        s.property_unset("max_gap_mm")
        s.property_unset("smoothing_mm")
    imp = bpy.data.objects[ob.name + "_improved"]
    t = json.loads(imp["bolus_improve_table"])
    for active in (ob, imp):  # the source or the improved object selected: the same table
        bpy.context.view_layer.objects.active = active
        labels = [x for kind, x in draw_panel(bpy) if kind == "label"]
        assert any(x.startswith(f"{imp.name}: {t['status']}, FLV") for x in labels), labels
        assert "all" in labels and "P0" in labels and "P1" in labels and labels.count("→") == 3
        assert f"{t['whole']['after']['flv']:.3g}" in labels and f"{t['patches'][1]['after']['max_gap_mm']:.2f}" in labels


def test_panel_hides_figures_undone_in_edit_mode(bpy_addon, scene):
    """Ctrl+Z in Edit Mode restores the mesh (its attributes) but not the object's custom
    properties: the panel must not show the undone preview's Σϖ or the undone patch table."""
    bpy = bpy_addon
    V, F = spherical_cap(100.0, 50.0, 3)
    ob = make_object(bpy, V, F, scale_length=0.001)
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.ed.undo_push(message="before the preview")
    assert bpy.ops.bolus.saliency_preview() == {"FINISHED"}
    bpy.ops.ed.undo_push(message="after the preview")
    assert bpy.ops.bolus.segment(patches=2) == {"FINISHED"}
    bpy.ops.ed.undo_push(message="after segment")
    ob = bpy.data.objects["skin"]
    table = json.loads(ob["bolus_patch_table"])["patches"]
    labels = [t for kind, t in draw_panel(bpy) if kind == "label"]
    assert any(t.startswith("Σϖ =") for t in labels) and str(table[0]["vertices"]) in labels
    assert bpy.ops.ed.undo() == {"FINISHED"}  # segment undone
    assert bpy.ops.ed.undo() == {"FINISHED"}  # the preview undone
    ob = bpy.data.objects["skin"]
    ob.update_from_editmode()
    assert "bolus_patch" not in ob.data.attributes and "bolus_flattenability" not in ob.data.attributes
    assert "bolus_patch_table" in ob  # what makes the check needed: the property stayed
    labels = [t for kind, t in draw_panel(bpy) if kind == "label"]
    assert not any(t.startswith("Σϖ =") for t in labels)
    assert str(table[0]["vertices"]) not in labels
    bpy.ops.object.mode_set(mode="OBJECT")
