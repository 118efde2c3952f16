"""Blender-side tests of `print_segment`, `orient_parts` and `export_parts` on a bolus solid
(``<name>_bolus`` from `make_shell`).

Every expectation (closedness, volumes, the joints' planes, STL contents) is computed here
with numpy from Blender's mesh data and the written files, never with the add-on's core.
Closed (SPEC): every edge has exactly two faces, which use it in opposite directions.
"""
from __future__ import annotations

import json
import re

import numpy as np
import pytest
from paths import ASSETS
from bpy_helpers import enter_edit_mode_with_faces, import_obj, label_components, mesh_snapshot
from test_blender_panel import draw_panel
from test_blender_shell import (
    RES_CAP,
    closed_and_consistent,
    datablock_names,
    face_attr,
    hemisphere,
    mesh_arrays,
    reports,
    signed_volume,
)

pytestmark = pytest.mark.blender

SIDE_INNER, SIDE_CUT = 0, 3


#: thick enough for pegs (a 3.2 mm peg in a 3.6 mm hole with 1.5 mm walls and some room to fit)
T_PARTS = 8.0


def make_bolus(bpy, small=False, **kw):
    """A bolus on the test dome; ``small``: a quick one (R 12 mm, 4 mm) where connectors do not matter."""
    ob = hemisphere(bpy, R=12.0, rings=12, na=48) if small else hemisphere(bpy)
    t = 4.0 if small else T_PARTS
    assert bpy.ops.bolus.make_shell(thickness_mm=t, resolution_mm=RES_CAP, **kw) == {"FINISHED"}
    bolus = bpy.data.objects["dome_bolus"]
    bpy.context.view_layer.objects.active = bolus
    return ob, bolus


def part_meshes(me):
    """{part: (V, T)} of the triangles of each part (the mesh's own vertex indices), and the labels."""
    V, T, tp = mesh_arrays(me)
    lab = face_attr(me, "bolus_print_part")[tp]
    return {int(p): (V, T[lab == p]) for p in np.unique(lab)}, lab


def assert_same_mesh(a, b) -> None:
    """Two bpy_helpers.mesh_snapshot()s are equal."""
    for x, y in zip(a, b):
        assert np.array_equal(x, y) if isinstance(x, np.ndarray) else x == y


def stl_triangles(path) -> np.ndarray:
    data = path.read_bytes()
    (count,) = np.frombuffer(data, dtype="<u4", count=1, offset=80)
    assert len(data) == 84 + 50 * int(count), "not a binary STL of the announced size"
    rec = np.dtype([("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    return np.frombuffer(data, dtype=rec, count=int(count), offset=84)["v"].astype(np.float64)


def merged(P) -> tuple[np.ndarray, np.ndarray]:
    """Triangle soup (t,3,3) -> (V, T) with vertices merged by identical coordinates (as a slicer does)."""
    V, inv = np.unique(P.reshape(-1, 3), axis=0, return_inverse=True)
    return V, inv.reshape(-1, 3)


# ---------------------------------------------------------------- print_segment
def test_print_segment_makes_closed_solid_parts(bpy_addon, scene, capfd):
    bpy = bpy_addon
    _, bolus = make_bolus(bpy)
    v0 = bolus["bolus_volume_cm3"] * 1000.0
    skin = bpy.data.meshes[bolus["bolus_skin_mesh"]]
    solid = bpy.data.meshes[bolus["bolus_solid_mesh"]]
    stored = mesh_snapshot(skin), mesh_snapshot(solid)
    bpy.context.scene.bolus.connector_clearance_mm = 0.3
    reports(capfd)
    assert bpy.ops.bolus.print_segment(parts=3) == {"FINISHED"}
    out = reports(capfd)
    me = bolus.data
    parts, lab = part_meshes(me)
    assert sorted(parts) == list(range(len(parts))) and len(parts) >= 2
    assert len(parts) == 3 or "parts instead of the 3 asked" in out, out
    vols = []
    for p, (V, T) in parts.items():
        ok, bad = closed_and_consistent(T)
        assert ok, f"part {p}: {bad} bad edges"
        vols.append(signed_volume(V, T))
        assert vols[-1] > 0
        assert re.search(rf"Part {p}: [\d.]+ cm³, closed", out), out
    # the parts fill the bolus: volumes add up to the bolus's (pegs and holes change it by a few mm³)
    assert sum(vols) == pytest.approx(v0, rel=0.005)
    assert "bolus_shell_side" in me.attributes
    # the joints and connectors: reported, stored as JSON, holes larger than their pegs by the clearance
    joints = json.loads(bolus["bolus_connectors"])
    assert len(joints) >= len(parts) - 1
    n_conn = sum(len(j["connectors"]) for j in joints)
    assert n_conn > 0, "test setup: the wall must be thick enough for connectors"
    m = re.search(r"(\d+) joints, (\d+) connectors \(clearance 0.3 mm\)", out)
    assert m and (int(m.group(1)), int(m.group(2))) == (len(joints), n_conn), out
    for j in joints:
        a, b = j["parts"]
        assert 0 <= a < len(parts) and 0 <= b < len(parts) and a != b
        assert abs(np.linalg.norm(j["normal"]) - 1.0) < 1e-6
        assert (j["note"] is None) == bool(j["connectors"]) or j["connectors"]
        for c in j["connectors"]:
            assert c["hole_radius"] == pytest.approx(c["peg_radius"] + 0.3, abs=1e-6)
            assert c["hole_depth"] == pytest.approx(c["peg_length"] + 0.3, abs=1e-6)
        if not j["connectors"]:
            assert j["note"] and f"Joint {a}|{b}" in out
    # the stored skin and plain solid are untouched (re-runs start from them)
    assert_same_mesh(mesh_snapshot(skin), stored[0])
    assert_same_mesh(mesh_snapshot(solid), stored[1])
    table = json.loads(bolus["bolus_print_table"])
    assert table["solid"] and len(table["parts"]) == len(parts)
    # the panel shows the bolus's figures and its parts with the bolus active
    log = draw_panel(bpy)
    labels = [t for kind, t in log if kind == "label"]
    assert ("operator", "bolus.make_shell") in log
    assert f"dome_bolus: {bolus['bolus_volume_cm3']:.1f} cm³, {bolus['bolus_mass_g']:.0f} g" in labels, labels
    assert any(t.startswith(f"{len(joints)} joints, {n_conn} connectors") for t in labels), labels
    assert any(t.startswith(f"{len(parts)} parts, largest/smallest area") for t in labels), labels

    # again with 2 parts: from the stored plain solid, so the only cut faces are the new joint's
    names = datablock_names(bpy)
    assert bpy.ops.bolus.print_segment(parts=2) == {"FINISHED"}
    assert datablock_names(bpy) == names, "meshes piled up"
    parts2, _ = part_meshes(bolus.data)
    assert len(parts2) == 2
    assert sum(signed_volume(V, T) for V, T in parts2.values()) == pytest.approx(v0, rel=0.005)
    joints = json.loads(bolus["bolus_connectors"])
    assert {tuple(j["parts"]) for j in joints} == {(0, 1)}
    V, T, tp = mesh_arrays(bolus.data)
    side = face_attr(bolus.data, "bolus_shell_side")[tp]
    cut = V[np.unique(T[side == SIDE_CUT])]
    off = np.min([np.abs(cut @ np.array(j["normal"]) + j["offset"]) for j in joints], axis=0)
    assert len(cut) and off.max() < 1e-3, "cut faces off the joints' planes (an old cut survived?)"


def test_print_segment_without_stored_skin_refused(bpy_addon, scene):
    bpy = bpy_addon
    _, bolus = make_bolus(bpy, small=True)
    bpy.data.meshes.remove(bpy.data.meshes[bolus["bolus_skin_mesh"]])
    before = mesh_snapshot(bolus.data)
    with pytest.raises(RuntimeError,
                       match=r"'dome_bolus' has lost its stored skin mesh .*run Make Bolus again on 'dome'"):
        bpy.ops.bolus.print_segment(parts=2)
    assert_same_mesh(mesh_snapshot(bolus.data), before)
    assert "bolus_print_part" not in bolus.data.attributes


def test_undo_print_segment_on_bolus(bpy_addon, scene):
    bpy = bpy_addon
    _, bolus = make_bolus(bpy, small=True)
    n_faces = len(bolus.data.polygons)
    bpy.ops.ed.undo_push(message="bolus made")
    assert bpy.ops.bolus.print_segment("EXEC_DEFAULT", True, parts=2) == {"FINISHED"}
    assert "bolus_print_part" in bpy.data.objects["dome_bolus"].data.attributes
    assert bpy.ops.ed.undo() == {"FINISHED"}
    bolus = bpy.data.objects["dome_bolus"]
    assert "bolus_print_part" not in bolus.data.attributes and "bolus_connectors" not in bolus
    assert len(bolus.data.polygons) == n_faces


# ------------------------------------------------------------ orient + export
def test_orient_and_export_solid_parts(bpy_addon, scene, capfd, tmp_path):
    bpy = bpy_addon
    _, bolus = make_bolus(bpy, label="P7")
    Vs, Ts, _ = mesh_arrays(bpy.data.meshes[bolus["bolus_solid_mesh"]])
    assert signed_volume(Vs, Ts) - bolus["bolus_volume_cm3"] * 1000.0 > 5.0, "no label engraved"
    assert bpy.ops.bolus.print_segment(parts=2) == {"FINISHED"}
    parts, _ = part_meshes(bolus.data)
    V, T, tp = mesh_arrays(bolus.data)
    side = face_attr(bolus.data, "bolus_shell_side")[tp]
    reports(capfd)
    assert bpy.ops.bolus.orient_parts(skin_side_up=True) == {"FINISHED"}
    out = reports(capfd)
    objs = [bpy.data.objects[f"dome_bolus_part_{p}"] for p in sorted(parts)]
    for p, ob in enumerate(objs):
        Vp, Tp, _ = mesh_arrays(ob.data)
        assert closed_and_consistent(Tp)[0], f"part object {p} is not closed"
        assert f"dome_bolus_part_{p}: closed" in out, out
        # skin side up: the build direction looks the way the part's inner (skin-side) face does
        P = V[T[(side == SIDE_INNER)]]
        n_inner = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]).sum(axis=0)
        assert np.dot(ob["bolus_print_direction"], n_inner) >= -1e-9
    # export: one STL per part, named with the label, closed when read back
    bpy.context.view_layer.objects.active = bolus
    reports(capfd)
    assert bpy.ops.bolus.export_parts(directory=str(tmp_path)) == {"FINISHED"}
    out = reports(capfd)
    files = sorted(tmp_path.glob("*.stl"))
    assert [f.name for f in files] == [f"P7_dome_bolus_part_{p}.stl" for p in sorted(parts)]
    for f in files:
        Vf, Tf = merged(stl_triangles(f))
        ok, bad = closed_and_consistent(Tf)
        assert ok, f"{f.name}: {bad} bad edges after reading back"
        assert signed_volume(Vf, Tf) > 0
        assert f"{f.name}: closed" in out, out


# ------------------------------------------------------------------ the nose
def nose_region(bpy):
    """The example face (cm: 1 unit = 10 mm) with the demo's nose area selected in Edit Mode:
    forward-facing faces within 40 mm of the nose tip, the connected piece around the tip."""
    ob = import_obj(bpy, ASSETS / "ict_face_narrow.obj", 0.01)
    me = ob.data
    co = np.array([v.co for v in me.vertices])
    tip = co[np.argmin(co[:, 1])]  # the face looks towards -Y after the importer's Y-up conversion
    centres = np.array([p.center for p in me.polygons])
    normals = np.array([p.normal for p in me.polygons])
    sel = (np.linalg.norm(centres - tip, axis=1) < 4.0) & (normals[:, 1] < -0.1)
    comp = label_components(me, sel.astype(np.int64))
    at_tip = comp[np.argmin(np.where(sel, np.linalg.norm(centres - tip, axis=1), np.inf))]
    enter_edit_mode_with_faces(bpy, ob, sel & (comp == at_tip))
    return ob


def test_nose_bolus_into_parts(bpy_addon, scene, capfd):
    """The example nose region: a closed 10 mm bolus at 1.5 mm, split into closed parts."""
    bpy = bpy_addon
    ob = nose_region(bpy)
    reports(capfd)
    assert bpy.ops.bolus.make_shell(thickness_mm=10.0, resolution_mm=1.5) == {"FINISHED"}
    out = reports(capfd)
    bolus = bpy.data.objects[ob.name + "_bolus"]
    V, T, _ = mesh_arrays(bolus.data)
    assert closed_and_consistent(T)[0]
    vol = signed_volume(V, T) * 1000.0  # cm -> mm: 1 unit = 10 mm
    assert bolus["bolus_volume_cm3"] == pytest.approx(vol / 1000.0, rel=1e-4)
    assert 8.0 < bolus["bolus_thickness_mean_mm"] < 12.0
    assert "Made '" in out
    bpy.ops.object.mode_set(mode="OBJECT")
    bpy.context.view_layer.objects.active = bolus
    assert bpy.ops.bolus.print_segment(parts=3) == {"FINISHED"}
    parts, _ = part_meshes(bolus.data)
    total = 0.0
    for p, (Vp, Tp) in parts.items():
        assert closed_and_consistent(Tp)[0], f"nose part {p} is not closed"
        total += signed_volume(Vp, Tp) * 1000.0
    assert total == pytest.approx(vol, rel=0.005)


def test_remaking_the_bolus_drops_its_old_parts(bpy_addon, scene):
    """print_segment from Edit Mode on the bolus (the user stays there), orient, then Make Bolus
    again on the skin: the out-of-date part objects and tables go, nothing piles up."""
    bpy = bpy_addon
    ob, bolus = make_bolus(bpy, small=True)
    names = datablock_names(bpy)
    bpy.ops.object.mode_set(mode="EDIT")
    assert bpy.ops.bolus.print_segment(parts=2) == {"FINISHED"}
    assert bolus.mode == "EDIT"
    bpy.ops.object.mode_set(mode="OBJECT")
    assert "bolus_print_part" in bolus.data.attributes and "bolus_connectors" in bolus
    assert bpy.ops.bolus.orient_parts() == {"FINISHED"}
    assert "dome_bolus_part_1" in bpy.data.objects
    bpy.context.view_layer.objects.active = ob
    assert bpy.ops.bolus.make_shell(thickness_mm=4.0, resolution_mm=RES_CAP) == {"FINISHED"}
    assert datablock_names(bpy) == names
    bolus = bpy.data.objects["dome_bolus"]
    assert "bolus_print_part" not in bolus.data.attributes
    assert not {"bolus_connectors", "bolus_print_table", "bolus_orient_table"} & set(bolus.keys())


def test_orient_parts_takes_slivers_of_a_solid(bpy_addon, scene, capfd):
    """The booleans that cut and engrave a bolus leave a few zero-area slivers; they do not open the
    solid and add nothing to the print figures, so orient_parts on a bolus takes them (on a skin
    surface they are still refused).  Here a closed box with one zero-area triangle (a, b, m), m
    the midpoint of its edge ab, stands in for such a bolus."""
    from bpy_helpers import make_object
    from meshgen import box

    bpy = bpy_addon
    V, F = box((40.0, 30.0, 20.0), n=2)
    a, b, c = F[0]
    m = len(V)
    V = np.r_[V, [(V[a] + V[b]) / 2]]
    F = np.r_[F[1:], [[a, m, c], [m, b, c], [a, b, m]]]
    assert closed_and_consistent(F)[0], "test setup: the box must stay closed"
    ob = make_object(bpy, V, F, name="slab_bolus", scale_length=0.001)
    me = ob.data
    me.attributes.new("bolus_shell_side", "INT", "FACE")
    part = me.attributes.new("bolus_print_part", "INT", "FACE")
    part.data.foreach_set("value", (np.array([p.center[0] for p in me.polygons]) > 20.0).astype(np.int32))
    reports(capfd)
    assert bpy.ops.bolus.orient_parts() == {"FINISHED"}
    out = reports(capfd)
    assert "slab_bolus_part_0" in bpy.data.objects and "slab_bolus_part_1" in bpy.data.objects
    assert "Warning" not in out or "zero-area" not in out, out
    # a part is not closed here (the box is cut along a face seam, not by a solid split): said per part
    assert "slab_bolus_part_0 is not closed" in out, out
    # the same mesh as a skin surface (no bolus_shell_side) gets the zero-area refusal of a surface
    me.attributes.remove(me.attributes["bolus_shell_side"])
    with pytest.raises(RuntimeError, match="zero-area triangle"):
        bpy.ops.bolus.orient_parts()
