"""bpy.ops.bolus.select_area (SPEC): the treatment area around the 3D cursor."""
from __future__ import annotations

import numpy as np
import pytest
from paths import ASSETS
from bpy_helpers import assert_same_object, import_obj, make_object, object_snapshot

from bolus_addon.core.mesh.boundary import boundary_loops
from bolus_addon.core.mesh.topology import triangulate_polygons
from bolus_addon.core.cuts.treatment_area import treatment_area

pytestmark = pytest.mark.blender

ICT = ("ict_face_narrow.obj", 0.01)  # centimetres: 1 unit = 10 mm
#: the deepest part of the ICT face's left nostril (a pocket), world mm after the importer's Y-up conversion
NOSTRIL_MM = np.array([-8.5, -103.9, -3.8])


# ---------------------------------------------------------------------------- helpers
def arrays(ob):
    me = ob.data
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    loops = np.empty(len(me.loops), dtype=np.int64)
    me.loops.foreach_get("vertex_index", loops)
    sizes = np.empty(len(me.polygons), dtype=np.int64)
    me.polygons.foreach_get("loop_total", sizes)
    sel = np.empty(len(me.polygons), dtype=bool)
    me.polygons.foreach_get("select", sel)
    return co.reshape(-1, 3), loops, sizes, sel


def selection(bpy, ob):
    """(world mm vertices, triangles, triangle polygon, polygon selection) of the mesh as it is (Edit Mode too)."""
    if ob.mode == "EDIT":
        ob.update_from_editmode()
    co, loops, sizes, sel = arrays(ob)
    F, tri_poly = triangulate_polygons(loops, sizes)
    mm = bpy.context.scene.unit_settings.scale_length * 1000.0
    M = np.array(ob.matrix_world)
    return (co @ M[:3, :3].T + M[:3, 3]) * mm, F, tri_poly, sel


def area_of(V, F):
    return 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum()


@pytest.fixture
def ict(bpy_addon, scene):
    bpy = bpy_addon
    ob = import_obj(bpy, ASSETS / ICT[0], ICT[1])
    V, F, _, _ = selection(bpy, ob)
    tip = V[np.argmin(V[:, 1])]  # the nose tip: the face looks towards -Y
    bpy.context.scene.cursor.location = tuple(tip / 10.0)
    return ob, V, F, tip


# ------------------------------------------------------------------------ the area
def test_ict_nose_from_object_mode(bpy_addon, ict, capfd):
    bpy = bpy_addon
    ob, V0, F0, tip = ict
    core = treatment_area(V0, F0, tip, 45.0)  # the same computation on the arrays
    capfd.readouterr()
    assert bpy.ops.bolus.select_area(radius_mm=45.0) == {"FINISHED"}
    out = capfd.readouterr().out
    assert "Selected the treatment area of" in out and "2 hole(s)" in out
    assert ob.mode == "EDIT"
    assert tuple(bpy.context.tool_settings.mesh_select_mode) == (False, False, True)
    V, F, tri_poly, sel = selection(bpy, ob)
    Fs = F[sel[tri_poly]]
    assert area_of(V, Fs) == pytest.approx(core.area_mm2, rel=1e-6)
    # within the radius (straight-line distance <= distance along the surface), one piece around the tip
    assert np.linalg.norm(V[Fs].mean(axis=1) - tip, axis=1).max() < 45.0
    loops = boundary_loops(Fs)
    assert len(loops) == 3  # the outer border and the two nostrils
    # the nostrils' insides are left out: no selected face near the deepest nostril point (there are faces there)
    C = V[F].mean(axis=1)
    near = np.linalg.norm(C - NOSTRIL_MM, axis=1) < 2.0
    assert near.any() and not sel[tri_poly[near]].any()
    # the outer border is the level line: its new vertices lie on input faces, at the radius along the surface
    n0 = len(V0)
    outer = max(loops, key=lambda lp: np.linalg.norm(V[lp] - tip, axis=1).mean())
    assert (outer >= n0).mean() > 0.8
    np.testing.assert_allclose(V[:n0], V0, atol=1e-4)  # the input vertices never move (float32 storage)


def test_nostrils_kept_without_cavity_exclusion(bpy_addon, ict):
    bpy = bpy_addon
    ob, V0, F0, tip = ict
    assert bpy.ops.bolus.select_area(radius_mm=45.0, exclude_cavities=False) == {"FINISHED"}
    V, F, tri_poly, sel = selection(bpy, ob)
    assert len(boundary_loops(F[sel[tri_poly]])) == 1
    C = V[F].mean(axis=1)
    assert sel[tri_poly[np.linalg.norm(C - NOSTRIL_MM, axis=1) < 2.0]].any()


def test_edit_mode_twice_in_a_row(bpy_addon, ict):
    bpy = bpy_addon
    ob, V0, F0, tip = ict
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.select_all(action="SELECT")
    assert bpy.ops.bolus.select_area(radius_mm=30.0) == {"FINISHED"}
    V1, F1, tp1, sel1 = selection(bpy, ob)
    assert ob.mode == "EDIT" and 0 < sel1.sum() < len(sel1)
    assert bpy.ops.bolus.select_area(radius_mm=45.0) == {"FINISHED"}  # on the mesh cut once already
    V2, F2, tp2, sel2 = selection(bpy, ob)
    assert ob.mode == "EDIT" and len(V2) > len(V1)
    core = treatment_area(V0, F0, tip, 45.0)
    assert area_of(V2, F2[sel2[tp2]]) == pytest.approx(core.area_mm2, rel=0.005)
    assert len(boundary_loops(F2[sel2[tp2]])) == 3


def test_mesh_outside_the_cut_band_unchanged(bpy_addon, ict):
    bpy = bpy_addon
    ob, V0, F0, tip = ict
    co0, loops0, sizes0, _ = arrays(ob)
    starts0 = np.r_[0, np.cumsum(sizes0)[:-1]]
    polys0 = {tuple(loops0[s:s + k]) for s, k in zip(starts0, sizes0)}
    assert bpy.ops.bolus.select_area(radius_mm=45.0) == {"FINISHED"}
    ob.update_from_editmode()
    co, loops, sizes, _ = arrays(ob)
    starts = np.r_[0, np.cumsum(sizes)[:-1]]
    polys = {tuple(loops[s:s + k]) for s, k in zip(starts, sizes)}
    np.testing.assert_array_equal(co[: len(co0)], co0)
    far = [p for p in polys0 if np.linalg.norm(V0[list(p)] - tip, axis=1).min() > 50.0]
    assert len(far) > 1000 and all(p in polys for p in far)


def test_undo_restores_the_mesh(bpy_addon, ict):
    bpy = bpy_addon
    ob, V0, F0, tip = ict
    name = ob.name
    before = object_snapshot(ob)
    bpy.ops.ed.undo_push(message="face loaded")
    assert bpy.ops.bolus.select_area("EXEC_DEFAULT", True, radius_mm=45.0) == {"FINISHED"}
    ob = bpy.data.objects[name]
    ob.update_from_editmode()
    n_cut = len(ob.data.vertices)
    assert n_cut > len(V0)
    assert bpy.ops.ed.undo() == {"FINISHED"}  # one step
    ob = bpy.data.objects[name]  # undo reloads the data-blocks: fetch them again
    if ob.mode == "EDIT":
        ob.update_from_editmode()
    assert_same_object(before, object_snapshot(ob))


def test_uv_and_attributes_interpolated_on_new_corners(bpy_addon, scene):
    """The writer is mesh_cuts.apply_cuts: a UV map (u, v) = (x, y) / 100 stays exact on the cut corners."""
    bpy = bpy_addon
    n = 20
    xs = np.linspace(0.0, 100.0, n + 1)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    V = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    F = np.stack([idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()], axis=1)
    ob = make_object(bpy, V, F, scale_length=0.001)
    uv = ob.data.uv_layers.new(name="UVMap")
    loops = np.empty(len(ob.data.loops), dtype=np.int64)
    ob.data.loops.foreach_get("vertex_index", loops)
    uv.data.foreach_set("uv", (V[loops, :2] / 100.0).ravel().astype(np.float32))
    bpy.context.scene.cursor.location = (50.0, 50.0, 0.0)
    assert bpy.ops.bolus.select_area(radius_mm=30.0) == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    me = ob.data
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    loops = np.empty(len(me.loops), dtype=np.int64)
    me.loops.foreach_get("vertex_index", loops)
    got = np.empty(len(me.loops) * 2, dtype=np.float32)
    me.uv_layers["UVMap"].data.foreach_get("uv", got)
    assert len(me.vertices) > len(V)
    np.testing.assert_allclose(got.reshape(-1, 2), co[loops, :2] / 100.0, atol=1e-5)
    sel = np.empty(len(me.polygons), dtype=bool)
    me.polygons.foreach_get("select", sel)
    sizes = np.empty(len(me.polygons), dtype=np.int64)
    me.polygons.foreach_get("loop_total", sizes)
    Ft, tp = triangulate_polygons(loops, sizes)
    assert area_of(co, Ft[sel[tp]]) == pytest.approx(np.pi * 30.0 ** 2, rel=0.01)
    assert "bolus_area_tmp" not in me.attributes


def test_object_transform_and_units(bpy_addon, scene):
    """The radius is in world millimetres: an object scaled by 2, rotated and moved, in a scene of 1 unit = 1 cm."""
    bpy = bpy_addon
    n = 30
    xs = np.linspace(0.0, 6.0, n + 1)  # 6 units = 12 cm across after the scale
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    V = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    F = np.stack([idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()], axis=1)
    ob = make_object(bpy, V, F, scale_length=0.01)
    ob.scale = (2.0, 2.0, 2.0)
    ob.rotation_euler = (0.4, 0.0, 0.7)
    ob.location = (1.0, -2.0, 3.0)
    bpy.context.view_layer.update()
    centre = np.array(ob.matrix_world) @ np.r_[3.0, 3.0, 0.0, 1.0]
    bpy.context.scene.cursor.location = tuple(centre[:3])
    assert bpy.ops.bolus.select_area(radius_mm=40.0) == {"FINISHED"}
    Vw, Fw, tp, sel = selection(bpy, ob)
    assert area_of(Vw, Fw[sel[tp]]) == pytest.approx(np.pi * 40.0 ** 2, rel=0.01)


# ----------------------------------------------------------------------- refusals
def test_refusals_change_nothing(bpy_addon, ict):
    bpy = bpy_addon
    ob, V0, F0, tip = ict
    before = object_snapshot(ob)
    with pytest.raises(RuntimeError, match="radius must be a positive number"):
        bpy.ops.bolus.select_area(radius_mm=0.0)
    bpy.context.scene.cursor.location = (0.0, -30.0, 0.0)  # 170 mm in front of the nose tip
    with pytest.raises(RuntimeError, match=r"3D cursor\) is \d+\.\d mm from the nearest point of the surface"):
        bpy.ops.bolus.select_area(radius_mm=45.0)
    assert ob.mode == "OBJECT"
    assert_same_object(before, object_snapshot(ob))
    bpy.context.view_layer.objects.active = None
    with pytest.raises(RuntimeError, match="No active object"):
        bpy.ops.bolus.select_area()
    assert_same_object(before, object_snapshot(ob))


def test_refused_in_edit_mode_keeps_edit_mode(bpy_addon, ict):
    bpy = bpy_addon
    ob, V0, F0, tip = ict
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.context.scene.cursor.location = (0.0, -30.0, 0.0)
    with pytest.raises(RuntimeError, match="from the nearest point of the surface"):
        bpy.ops.bolus.select_area(radius_mm=45.0)
    assert ob.mode == "EDIT"
    ob.update_from_editmode()
    assert len(ob.data.vertices) == len(V0)


def test_a_mesh_without_faces(bpy_addon, scene):
    bpy = bpy_addon
    ob = make_object(bpy, np.array([[0.0, 0, 0], [1, 0, 0]]), [])
    with pytest.raises(RuntimeError, match="has no faces"):
        bpy.ops.bolus.select_area()
