"""`bpy.ops.bolus.smooth_cuts` twice: it is idempotent (a second run must not re-cut borders
or add vertices).

SPEC: with nothing to change (the borders already smooth) smooth_cuts changes nothing and
raises no error.  Here the second call must leave the mesh exactly as the first one left
it: the same vertices (count and positions), polygons and `bolus_patch`, and it must not
fail (an {'ERROR'} report reaches a script as RuntimeError).  What it reports is the
operator's business and not checked here.  Every expectation is computed from the mesh
data with numpy, never with the add-on's core.
"""
from __future__ import annotations

import numpy as np
import pytest
from paths import ASSETS
from bpy_helpers import enter_edit_mode_with_faces, import_obj, make_object

pytestmark = pytest.mark.blender

ICT = ("ict_face_narrow.obj", 0.01)  # centimetres: 1 unit = 10 mm


def mesh_state(me):
    """(vertex positions (n,3), polygon corner lists, bolus_patch per polygon)."""
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    loops = np.empty(len(me.loops), dtype=np.int64)
    me.loops.foreach_get("vertex_index", loops)
    sizes = np.empty(len(me.polygons), dtype=np.int64)
    me.polygons.foreach_get("loop_total", sizes)
    lab = np.empty(len(me.polygons), dtype=np.int64)
    me.attributes["bolus_patch"].data.foreach_get("value", lab)
    return co.reshape(-1, 3), loops, sizes, lab


def cut_twice(bpy, ob):
    """smooth_cuts, then smooth_cuts again; returns the states (before, after the first, after the second)."""
    me = ob.data
    s0 = mesh_state(me)
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}
    s1 = mesh_state(me)
    assert bpy.ops.bolus.smooth_cuts() == {"FINISHED"}  # no RuntimeError: nothing to change is no error
    s2 = mesh_state(me)
    return s0, s1, s2


def assert_first_cut_and_second_did_nothing(s0, s1, s2):
    assert len(s1[0]) > len(s0[0]), "the first smooth_cuts should have cut something"
    assert len(s2[0]) == len(s1[0]), f"the second smooth_cuts added {len(s2[0]) - len(s1[0])} vertices"
    assert len(s2[2]) == len(s1[2]), "the second smooth_cuts changed the number of polygons"
    np.testing.assert_array_equal(s2[0], s1[0])
    np.testing.assert_array_equal(s2[1], s1[1])
    np.testing.assert_array_equal(s2[2], s1[2])
    np.testing.assert_array_equal(s2[3], s1[3])


def test_three_patches_on_a_grid(bpy_addon, scene):
    bpy = bpy_addon
    n, size = 30, 100.0
    xs = np.linspace(0.0, size, n + 1)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    V = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    F = np.stack([idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()], axis=1)
    ob = make_object(bpy, V, F, scale_length=0.001)  # 1 unit = 1 mm
    c = V[F].mean(axis=1)
    x, y = c[:, 0], c[:, 1]
    labels = np.where(x + 3 * np.sin(y / 7) < 40, 0, np.where(y + 2 * np.cos(x / 5) + 0.2 * x < 55, 1, 2))
    attr = ob.data.attributes.new("bolus_patch", "INT", "FACE")
    attr.data.foreach_set("value", labels.astype(np.int32))
    ob.data.update()
    assert_first_cut_and_second_did_nothing(*cut_twice(bpy, ob))


def test_segmented_real_face(bpy_addon, scene):
    bpy = bpy_addon
    ob = import_obj(bpy, ASSETS / ICT[0], ICT[1])
    assert bpy.ops.bolus.segment(patches=5) == {"FINISHED"}
    assert_first_cut_and_second_did_nothing(*cut_twice(bpy, ob))


def test_demo_nose_region(bpy_addon, scene):
    """The demo's flow (scripts/demo.py): the forward-facing faces within 45 mm of the nose tip
    selected in Edit Mode, segment(patches=4) there, back to Object Mode, Smooth Cut Lines twice."""
    bpy = bpy_addon
    ob = import_obj(bpy, ASSETS / ICT[0], ICT[1])
    me = ob.data
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3) * 10.0  # mm
    # the importer turns the object (Y-up to Z-up) and leaves the mesh data as in the file,
    # where the face looks towards +Z (the demo applies that rotation: the same faces)
    tip = co[np.argmax(co[:, 2])]
    centres = np.array([co[list(p.vertices)].mean(axis=0) for p in me.polygons])
    normals = np.array([p.normal[:] for p in me.polygons])
    sel = (np.linalg.norm(centres - tip, axis=1) < 45.0) & (normals[:, 2] > 0.1)
    # the connected piece around the tip (polygons sharing an edge)
    edge_polys: dict[tuple[int, int], list[int]] = {}
    for p in me.polygons:
        if sel[p.index]:
            for e in p.edge_keys:
                edge_polys.setdefault(e, []).append(p.index)
    start = int(np.nonzero(sel)[0][np.argmin(np.linalg.norm(centres[sel] - tip, axis=1))])
    piece, todo = {start}, [start]
    nbrs: dict[int, set[int]] = {}
    for ps in edge_polys.values():
        for p in ps:
            nbrs.setdefault(p, set()).update(ps)
    while todo:
        for q in nbrs.get(todo.pop(), ()):
            if q not in piece:
                piece.add(q)
                todo.append(q)
    mask = np.zeros(len(me.polygons), dtype=bool)
    mask[list(piece)] = True
    assert 300 < mask.sum() < len(mask) // 2
    enter_edit_mode_with_faces(bpy, ob, mask)
    assert bpy.ops.bolus.segment(patches=4, eta=5.0, seed=0) == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    s0, s1, s2 = cut_twice(bpy, ob)
    assert_first_cut_and_second_did_nothing(s0, s1, s2)
    # polygons outside the region are in no patch, and no cut split one of them
    assert (s0[3] == -1).sum() == (s2[3] == -1).sum() == (~mask).sum()
