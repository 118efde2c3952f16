"""`print_segment(method='LEARNED')` in Blender (seed 6.4): on a skin region in Object
and Edit Mode, twice in a row, undone, and on a `<name>_bolus` solid cut into closed parts.

Expectations are computed here from Blender's mesh data (connectivity with scipy, closedness and
volumes with numpy), not with the add-on's core."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest
from paths import ASSETS
from bpy_helpers import assert_labels_connected, attr_array, enter_edit_mode_with_faces, import_obj, mesh_snapshot
from test_blender_panel import draw_panel
from test_blender_shell import closed_and_consistent, reports, signed_volume
from test_blender_solid_print import assert_same_mesh, nose_region, part_meshes

pytestmark = pytest.mark.blender

LEARNED_LINE = r"Learned split: affinity propagation found (\d+) clusters of ([\d,]+) sub-graphs of 30 triangles " \
               r"\(triangle usage rate ([\d.]+) %\), (\d+) connected parts"


def face(bpy):
    """The example face at true size (cm file: 1 unit = 10 mm), Object Mode, active."""
    return import_obj(bpy, ASSETS / "ict_face_narrow.obj", 0.01)


def test_learned_split_of_a_skin_surface_twice_and_undo(bpy_addon, scene, capfd):
    bpy = bpy_addon
    ob = face(bpy)
    me = ob.data
    before = mesh_snapshot(me)
    bpy.ops.ed.undo_push(message="face loaded")
    reports(capfd)
    assert bpy.ops.bolus.print_segment("EXEC_DEFAULT", True, method="LEARNED", parts=3, seed=0) == {"FINISHED"}
    out = reports(capfd)
    m = re.search(LEARNED_LINE, out)
    assert m, out
    clusters, parts = int(m.group(1)), int(m.group(4))
    assert clusters >= 1 and float(m.group(3)) >= 93.0
    lab = attr_array(me, "bolus_print_part", np.int64)
    assert lab.min() == 0 and set(np.unique(lab)) == set(range(parts))
    assert_labels_connected(me, lab, "print part")
    assert f"into {parts} print parts (LEARNED;" in out, out
    many = f"Warning: the learned split made {parts} parts (from {clusters} clusters): every joint is a seam"
    assert (many in out) == (parts > 6), out
    co, loops, seams_, _ = mesh_snapshot(me)
    np.testing.assert_array_equal(co, before[0])
    np.testing.assert_array_equal(loops, before[1])
    table = json.loads(ob["bolus_print_table"])
    assert table["ap_clusters"] == clusters and table["requested"] is None and len(table["parts"]) == parts
    # the panel shows what the data gave
    bpy.context.scene.bolus.print_method = "LEARNED"
    labels = [t for kind, t in draw_panel(bpy) if kind == "label"]
    assert any(t.startswith(f"{parts} parts (learned: {clusters} clusters)") for t in labels), labels
    # one undo step back to the mesh without parts
    assert bpy.ops.ed.undo() == {"FINISHED"}
    ob = bpy.data.objects["ict_face_narrow"]
    assert "bolus_print_part" not in ob.data.attributes and "bolus_print_table" not in ob
    assert_same_mesh(mesh_snapshot(ob.data), before)
    # twice in a row: the same parts (fixed seed), whatever number of parts is asked
    bpy.context.view_layer.objects.active = ob
    for _ in range(2):
        assert bpy.ops.bolus.print_segment(method="LEARNED", parts=7, seed=0) == {"FINISHED"}
        np.testing.assert_array_equal(attr_array(ob.data, "bolus_print_part", np.int64), lab)


@pytest.mark.smoke
def test_learned_split_of_an_edit_mode_region(bpy_addon, scene, capfd):
    bpy = bpy_addon
    ob = face(bpy)
    me = ob.data
    centres = np.array([p.center for p in me.polygons])
    sel = centres[:, 0] > np.median(centres[:, 0])  # one half of the face
    enter_edit_mode_with_faces(bpy, ob, sel)
    reports(capfd)
    assert bpy.ops.bolus.print_segment(method="LEARNED") == {"FINISHED"}
    assert ob.mode == "EDIT"  # the user's mode is kept
    bpy.ops.object.mode_set(mode="OBJECT")
    lab = attr_array(me, "bolus_print_part", np.int64)
    assert (lab[~sel] == -1).all() and (lab[sel] >= 0).all()
    assert_labels_connected(me, np.where(sel, lab, -1), "print part")


def test_learned_split_of_the_nose_bolus_gives_closed_parts(bpy_addon, scene, capfd):
    bpy = bpy_addon
    ob = nose_region(bpy)
    assert bpy.ops.bolus.make_shell(thickness_mm=10.0, resolution_mm=1.5) == {"FINISHED"}
    bolus = bpy.data.objects[ob.name + "_bolus"]
    vol = bolus["bolus_volume_cm3"] * 1000.0  # mm^3
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.context.view_layer.objects.active = bolus
    reports(capfd)
    assert bpy.ops.bolus.print_segment(method="LEARNED") == {"FINISHED"}
    out = reports(capfd)
    assert re.search(r"Learned split of the skin: affinity propagation found \d+ clusters", out), out
    parts, _ = part_meshes(bolus.data)
    assert len(parts) >= 1
    total = 0.0
    for p, (Vp, Tp) in parts.items():
        ok, bad = closed_and_consistent(Tp)
        assert ok, f"part {p}: {bad} bad edges"
        total += signed_volume(Vp, Tp) * 1000.0  # 1 unit = 10 mm
    assert total == pytest.approx(vol, rel=0.005)
    table = json.loads(bolus["bolus_print_table"])
    assert table["solid"] and table["method"] == "LEARNED" and len(table["parts"]) == len(parts)
