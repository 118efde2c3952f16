"""Bad input for `bpy.ops.bolus.saliency_preview` and `bpy.ops.bolus.segment`.

SPEC: an operator that cannot do its work reports a clear error and returns CANCELLED
(from Python: RuntimeError carrying the message) and never leaves a half-changed mesh;
inputs it can work around (loose vertices and edges, non-manifold edges for the
preview) give a warning.  Meshes are small synthetic ones built with numpy.
"""
from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from bpy_helpers import assert_same_object, attr_array, make_object, mesh_snapshot, object_snapshot
from meshgen import icosphere

pytestmark = pytest.mark.blender

OPS = ["saliency_preview", "segment"]
ARGS = {"saliency_preview": {"smoothing_mm": 0.0}, "segment": {"patches": 2}}


# --------------------------------------------------------------------------- helpers
def call(bpy, op, **kw):
    return getattr(bpy.ops.bolus, op)(**{**ARGS[op], **kw})


def grid(nx, ny, h=1.0, offset=(0.0, 0.0, 0.0)):
    """A bumpy (nx x ny)-quad grid, vertex (i, j) at index i*(ny+1)+j, size in units of h."""
    xs, ys = np.meshgrid(np.arange(nx + 1) * h, np.arange(ny + 1) * h, indexing="ij")
    z = 0.8 * h * np.sin(xs / (h * 2.0)) * np.cos(ys / (h * 3.0))
    V = np.c_[xs.ravel(), ys.ravel(), z.ravel()] + np.asarray(offset)
    idx = lambda i, j: i * (ny + 1) + j  # noqa: E731
    F = [[idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)] for i in range(nx) for j in range(ny)]
    return V, F


def make_mesh(bpy, V, E, F, name="skin"):
    """Like bpy_helpers.make_object, but with loose edges too."""
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(map(float, v)) for v in np.asarray(V)], [tuple(e) for e in E], [tuple(f) for f in F])
    me.validate()
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    bpy.context.view_layer.objects.active = ob
    ob.select_set(True)
    return ob




def raw_varpi(ob) -> np.ndarray:
    """|theta - 2pi| on interior vertices (edges with exactly two triangles), world space, numpy only."""
    me = ob.data
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    M = np.array(ob.matrix_world)
    V = co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3]
    me.calc_loop_triangles()
    T = np.empty(len(me.loop_triangles) * 3, dtype=np.int64)
    me.loop_triangles.foreach_get("vertices", T)
    T = T.reshape(-1, 3)
    P = V[T]
    a = np.roll(P, -1, axis=1) - P
    b = np.roll(P, -2, axis=1) - P
    ang = np.arctan2(np.linalg.norm(np.cross(a, b), axis=2), np.einsum("tkc,tkc->tk", a, b))
    theta = np.bincount(T.ravel(), weights=ang.ravel(), minlength=len(V))
    E = np.sort(np.stack([T, np.roll(T, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    uniq, count = np.unique(E, axis=0, return_counts=True)
    interior = np.zeros(len(V), dtype=bool)
    interior[T.ravel()] = True
    interior[uniq[count != 2].ravel()] = False
    return np.where(interior, np.abs(theta - 2.0 * math.pi), 0.0)


def reports(capfd) -> str:
    return capfd.readouterr().out


# ------------------------------------------------------------- no usable object
@pytest.mark.smoke
@pytest.mark.parametrize("op", OPS)
def test_no_active_object(bpy_addon, scene, op):
    bpy = bpy_addon
    ob = make_object(bpy, *grid(3, 3))
    bpy.context.view_layer.objects.active = None
    before = object_snapshot(ob)
    with pytest.raises(RuntimeError, match="No active object"):
        call(bpy, op)
    assert_same_object(before, object_snapshot(ob))
    assert "bolus_patch" not in ob.data.attributes


@pytest.mark.parametrize("op", OPS)
@pytest.mark.parametrize("kind", ["empty", "camera"])
def test_active_object_not_a_mesh(bpy_addon, scene, op, kind):
    bpy = bpy_addon
    ob = make_object(bpy, *grid(3, 3))  # a mesh in the scene, but not the active object
    before = object_snapshot(ob)
    if kind == "empty":
        bpy.ops.object.empty_add()
    else:
        bpy.ops.object.camera_add()
    other = bpy.context.active_object
    assert other.type == kind.upper()
    with pytest.raises(RuntimeError, match=f"'{other.name}' is not a mesh"):
        call(bpy, op)
    assert_same_object(before, object_snapshot(ob))
    assert not [k for k in other.keys() if k.startswith("bolus_")]


# --------------------------------------------------------------- unusable meshes
@pytest.mark.parametrize("op", OPS)
def test_mesh_without_faces(bpy_addon, scene, op):
    bpy = bpy_addon
    ob = make_mesh(bpy, [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1), (1, 2), (2, 3)], [])
    assert len(ob.data.polygons) == 0 and len(ob.data.edges) == 3
    before = object_snapshot(ob)
    with pytest.raises(RuntimeError, match="'skin' has no faces"):
        call(bpy, op)
    assert_same_object(before, object_snapshot(ob))


@pytest.mark.smoke
@pytest.mark.parametrize("ntri,patches", [(1, 2), (2, 3), (4, 5)])
def test_fewer_faces_than_patches(bpy_addon, scene, ntri, patches):
    bpy = bpy_addon
    V = [(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0.2), (2, 0, 0.1), (2, 1, 0.3)]
    F = [(0, 1, 2), (1, 3, 2), (1, 4, 3), (4, 5, 3)][:ntri]
    ob = make_object(bpy, V[: max(max(f) for f in F) + 1], F)
    before = object_snapshot(ob)
    with pytest.raises(RuntimeError, match=f"fewer than the {patches} patches asked"):
        bpy.ops.bolus.segment(patches=patches)
    assert_same_object(before, object_snapshot(ob))


def test_fewer_polygons_than_patches(bpy_addon, scene):
    bpy = bpy_addon
    ob = make_object(bpy, *grid(2, 1))  # 2 quads = 4 triangles
    before = object_snapshot(ob)
    with pytest.raises(RuntimeError, match="fewer than the 3 patches asked"):
        bpy.ops.bolus.segment(patches=3)
    assert_same_object(before, object_snapshot(ob))


def test_more_patches_than_vertices(bpy_addon, scene):
    bpy = bpy_addon
    V, F = icosphere(1, 0.05)  # 42 vertices, 80 triangles
    ob = make_object(bpy, V, F)
    before = object_snapshot(ob)
    with pytest.raises(RuntimeError, match="42 vertices, too few for the 60 patches asked"):
        bpy.ops.bolus.segment(patches=60)
    assert_same_object(before, object_snapshot(ob))


@pytest.mark.parametrize("op", OPS)
def test_zero_area_faces(bpy_addon, scene, op):
    bpy = bpy_addon
    V, F = grid(4, 4)
    n = len(V)
    # a sliver: three distinct vertices on a line, glued to the grid's corner vertex 0
    V = np.r_[V, [[-1.0, 0.0, 0.0], [-2.0, 0.0, 0.0]]]
    F = F + [[0, n, n + 1]]
    ob = make_object(bpy, V, F)
    assert len(ob.data.polygons) == 17  # validate() kept it: it is geometrically, not topologically, degenerate
    before = object_snapshot(ob)
    # named by Blender's vertex indices, so the modeler can find it
    with pytest.raises(RuntimeError, match=rf"1 zero-area triangle.*on vertices 0, {n}, {n + 1}"):
        call(bpy, op)
    assert_same_object(before, object_snapshot(ob))


def test_disconnected_parts(bpy_addon, scene):
    bpy = bpy_addon
    V1, F1 = grid(5, 5)
    V2, F2 = grid(4, 4, offset=(20.0, 0.0, 0.0))
    ob = make_object(bpy, np.r_[V1, V2], F1 + [[v + len(V1) for v in f] for f in F2], scale_length=0.001)
    before = object_snapshot(ob)
    with pytest.raises(RuntimeError, match="made of 2 separate parts"):
        bpy.ops.bolus.segment(patches=2)
    assert_same_object(before, object_snapshot(ob))
    # the preview has no reason to refuse: each part is measured as it is
    assert bpy.ops.bolus.saliency_preview(smoothing_mm=0.0) == {"FINISHED"}
    varpi = attr_array(ob.data, "bolus_flattenability")
    np.testing.assert_allclose(varpi, raw_varpi(ob), rtol=1e-5, atol=1e-6)
    assert varpi[: len(V1)].max() > 0 and varpi[len(V1) :].max() > 0
    assert bpy.ops.bolus.saliency_preview(smoothing_mm=2.0) == {"FINISHED"}


def nonmanifold_grid(bpy):
    """4x4 grid with a third face on the interior edge (6, 7)."""
    V, F = grid(4, 4)
    V = np.r_[V, [[1.5, 1.0, 2.0]]]
    F = F + [[6, 7, len(V) - 1]]
    return make_object(bpy, V, F)


def test_nonmanifold_edge_segment_refuses(bpy_addon, scene):
    bpy = bpy_addon
    ob = nonmanifold_grid(bpy)
    before = object_snapshot(ob)
    with pytest.raises(RuntimeError, match=r"1 non-manifold edges \(e.g. between vertices 6 and 7\)"):
        bpy.ops.bolus.segment(patches=2)
    assert_same_object(before, object_snapshot(ob))


def test_nonmanifold_edge_preview_warns(bpy_addon, scene, capfd):
    bpy = bpy_addon
    ob = nonmanifold_grid(bpy)
    reports(capfd)
    assert bpy.ops.bolus.saliency_preview(smoothing_mm=0.0) == {"FINISHED"}
    out = reports(capfd)
    assert "Warning" in out and "non-manifold" in out
    varpi = attr_array(ob.data, "bolus_flattenability")
    assert varpi[6] == 0 and varpi[7] == 0 and varpi[-1] == 0
    np.testing.assert_allclose(varpi, raw_varpi(ob), rtol=1e-5, atol=1e-6)
    assert varpi.max() > 0


def test_nonmanifold_vertex_segment_refuses(bpy_addon, scene):
    bpy = bpy_addon
    # two grids touching at one corner vertex (a bow-tie)
    V1, F1 = grid(3, 3)
    V2, F2 = grid(3, 3, offset=(3.0, 3.0, 0.0))
    n1 = len(V1)
    V2 = V2[1:]  # vertex 0 of the second grid is vertex 15 (3, 3) of the first
    F2 = [[15 if v == 0 else v - 1 + n1 for v in f] for f in F2]
    ob = make_object(bpy, np.r_[V1, V2], F1 + F2)
    before = object_snapshot(ob)
    with pytest.raises(RuntimeError, match="non-manifold vertices"):
        bpy.ops.bolus.segment(patches=2)
    assert_same_object(before, object_snapshot(ob))


@pytest.mark.parametrize("op", OPS)
def test_loose_vertices_and_edges_are_ignored(bpy_addon, scene, capfd, op):
    bpy = bpy_addon
    V, F = grid(6, 6)
    n = len(V)
    clean = make_object(bpy, V, F, name="clean")
    call(bpy, op)
    V = np.r_[V, [[50.0, 50.0, 50.0], [60.0, 60.0, 60.0], [70.0, 70.0, 70.0]]]
    ob = make_mesh(bpy, V, [(n + 1, n + 2)], F)  # one lone vertex, one loose edge
    reports(capfd)
    assert call(bpy, op) == {"FINISHED"}
    out = reports(capfd)
    assert "3 loose vertices" in out and "1 loose edges" in out
    if op == "saliency_preview":
        varpi = attr_array(ob.data, "bolus_flattenability")
        assert np.all(varpi[n:] == 0)
        np.testing.assert_allclose(varpi[:n], attr_array(clean.data, "bolus_flattenability"), rtol=1e-6)
        assert ob["bolus_sum_varpi"] == pytest.approx(clean["bolus_sum_varpi"], rel=1e-9)
    else:
        lab = attr_array(ob.data, "bolus_patch", np.int64)
        np.testing.assert_array_equal(lab, attr_array(clean.data, "bolus_patch", np.int64))
        assert lab.min() == 0 and lab.max() >= 1
        loose_edge = [e.index for e in ob.data.edges if set(e.vertices) == {n + 1, n + 2}]
        assert len(loose_edge) == 1 and not ob.data.edges[loose_edge[0]].use_seam


# --------------------------------------------- a failure must not undo earlier work
def test_failed_segment_keeps_previous_result(bpy_addon, scene):
    bpy = bpy_addon
    ob = make_object(bpy, *grid(6, 6))
    assert bpy.ops.bolus.segment(patches=3) == {"FINISHED"}
    assert bpy.ops.bolus.saliency_preview(smoothing_mm=0.0) == {"FINISHED"}
    before = object_snapshot(ob)
    assert before[0][2].any() and "bolus_patch" in before[1]
    with pytest.raises(RuntimeError, match="64"):
        bpy.ops.bolus.segment(patches=64)
    assert_same_object(before, object_snapshot(ob))
    table = json.loads(ob["bolus_patch_table"])
    assert table["requested"] == 3


def test_error_in_edit_mode_stays_in_edit_mode(bpy_addon, scene):
    """A selection of two islands: segment refuses, Edit Mode and the mesh are kept."""
    bpy = bpy_addon
    ob = make_object(bpy, *grid(6, 6))
    me = ob.data
    sel = np.zeros(len(me.polygons), dtype=bool)
    sel[[0, 1, 6, 7]] = True  # quads (0,0),(0,1),(1,0),(1,1): one island
    sel[[28, 29, 34, 35]] = True  # quads (4,4),(4,5),(5,4),(5,5): another
    vsel = np.zeros(len(me.vertices), dtype=bool)
    for p in me.polygons:
        if sel[p.index]:
            vsel[list(p.vertices)] = True
    me.vertices.foreach_set("select", vsel)
    me.polygons.foreach_set("select", sel)
    bpy.context.tool_settings.mesh_select_mode = (False, False, True)
    before = object_snapshot(ob)
    bpy.ops.object.mode_set(mode="EDIT")
    with pytest.raises(RuntimeError, match="made of 2 separate parts"):
        bpy.ops.bolus.segment(patches=2)
    assert ob.mode == "EDIT"
    # ... while the preview works on the same selection
    assert bpy.ops.bolus.saliency_preview(smoothing_mm=0.0) == {"FINISHED"}
    assert ob.mode == "EDIT"
    bpy.ops.object.mode_set(mode="OBJECT")
    after = object_snapshot(ob)
    (co0, loops0, seams0, _), *_ = before
    (co1, loops1, seams1, names1), ours1, *_ = after
    np.testing.assert_array_equal(co0, co1)
    np.testing.assert_array_equal(seams0, seams1)
    assert "bolus_patch" not in names1 and "bolus_flattenability" in ours1


# ------------------------------------------- every operator that reads a region
REGION_OPS = {"saliency_preview": {"smoothing_mm": 0.0}, "segment": {"patches": 2}, "smooth_cuts": {}, "unfold": {},
              "print_segment": {"parts": 2}, "orient_parts": {}, "improve_flattenability": {}}


def set_co(ob, co) -> None:
    ob.data.vertices.foreach_set("co", np.asarray(co, dtype=np.float64).ravel())
    ob.data.update()


def two_patches(ob) -> None:
    """bolus_patch 0 / 1 on the two halves of a grid (what smooth_cuts needs)."""
    me = ob.data
    c = np.array([p.center[0] for p in me.polygons])
    attr = me.attributes.new("bolus_patch", "INT", "FACE")
    attr.data.foreach_set("value", (c > np.median(c)).astype(np.int32))


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("op", list(REGION_OPS))
def test_non_finite_coordinates_are_refused(bpy_addon, scene, op, value):
    """NaN or infinite coordinates are refused by every operator that reads a region."""
    bpy = bpy_addon
    V, F = grid(8, 8, h=10.0)
    ob = make_object(bpy, V, F, scale_length=0.001)
    two_patches(ob)
    V[17, 1] = value
    set_co(ob, V)
    before = object_snapshot(ob)
    with pytest.raises(RuntimeError, match=r"vertex 17 of 'skin' has an invalid coordinate \(10, -?(nan|inf), "):
        getattr(bpy.ops.bolus, op)(**REGION_OPS[op])
    assert_same_object(before, object_snapshot(ob))


def test_non_finite_transform_is_refused(bpy_addon, scene):
    bpy = bpy_addon
    ob = make_object(bpy, *grid(4, 4, h=10.0), scale_length=0.001)
    ob.rotation_euler = (math.nan, 0.0, 0.0)  # (an infinite scale is clamped by Blender)
    bpy.context.view_layer.update()
    with pytest.raises(RuntimeError, match="'skin' has a transform that makes vertex .* infinite or NaN"):
        bpy.ops.bolus.saliency_preview(smoothing_mm=0.0)


def test_non_finite_vertex_outside_the_edit_mode_region_is_ignored(bpy_addon, scene):
    """Only the region counts: a bad vertex in faces that are not selected does not block."""
    bpy = bpy_addon
    V, F = grid(6, 6, h=10.0)
    ob = make_object(bpy, V, F, scale_length=0.001)
    V[48, 2] = math.nan  # the far corner (6, 6): only in the last quad
    set_co(ob, V)
    sel = np.zeros(len(F), dtype=bool)
    sel[:12] = True  # the first two rows of quads
    from bpy_helpers import enter_edit_mode_with_faces  # noqa: PLC0415

    enter_edit_mode_with_faces(bpy, ob, sel)
    assert bpy.ops.bolus.saliency_preview(smoothing_mm=0.0) == {"FINISHED"}
    bpy.ops.mesh.select_all(action="SELECT")
    with pytest.raises(RuntimeError, match="vertex 48 of 'skin' has an invalid coordinate"):
        bpy.ops.bolus.saliency_preview(smoothing_mm=0.0)
    assert ob.mode == "EDIT"


@pytest.mark.parametrize("op", list(REGION_OPS))
def test_mm_mesh_in_a_metre_scene_warns(bpy_addon, scene, capfd, op):
    """A 200 mm region imported from a mm file into a 1 m scene (it is 283 m across) is warned about."""
    bpy = bpy_addon
    ob = make_object(bpy, *grid(8, 8, h=25.0))  # scale_length 1.0: 1 unit = 1 m
    two_patches(ob)
    capfd.readouterr()
    assert getattr(bpy.ops.bolus, op)(**REGION_OPS[op]) == {"FINISHED"}
    out = capfd.readouterr().out
    warning = re.search(r"Warning: The region is ([\d.]+) m across \(bounding-box diagonal\), larger than 3 m: .*"
                        r"set Scene > Units > Unit Scale to 0\.001 \(now 1; then it is ([\d.]+) mm across\), "
                        r"or scale the object", out)
    assert warning, out
    assert float(warning.group(1)) == pytest.approx(200.0 * math.sqrt(2.0), rel=0.02)
    assert float(warning.group(2)) == pytest.approx(200.0 * math.sqrt(2.0), rel=0.02)
    assert out.count("The region is ") == 1


def test_metre_mesh_in_a_millimetre_scene_warns(bpy_addon, scene, capfd):
    bpy = bpy_addon
    make_object(bpy, *grid(8, 8, h=0.025), scale_length=0.001)  # 0.2 units = 0.2 mm
    capfd.readouterr()
    assert bpy.ops.bolus.segment(patches=2) == {"FINISHED"}
    out = capfd.readouterr().out
    assert re.search(r"Warning: The region is 0\.28\d? mm across .*smaller than 5 mm: .*Unit Scale to 1 \(now 0\.001;", out), out


@pytest.mark.parametrize("h, scale_length", [(25.0, 0.001), (0.5, 0.01), (0.25, 1.0), (0.5, 0.001)])
def test_plausible_sizes_do_not_warn(bpy_addon, scene, capfd, h, scale_length):
    """A region 5 mm .. 3 m across is left alone (here 283 mm, 57 mm, 2.8 m, 5.7 mm)."""
    bpy = bpy_addon
    make_object(bpy, *grid(8, 8, h=h), scale_length=scale_length)
    capfd.readouterr()
    assert bpy.ops.bolus.saliency_preview(smoothing_mm=0.0) == {"FINISHED"}
    assert "The region is" not in capfd.readouterr().out
