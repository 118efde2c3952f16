"""Blender-side helpers of the tests: objects from arrays, snapshots that prove a source was not
changed, Edit Mode selections and Blender's own view of a mesh's edges, seams and triangles."""
from __future__ import annotations

import numpy as np


def make_object(bpy, V, F, name="skin", scale_length=None):
    """Mesh object from arrays (F may hold polygons of any size), active and selected."""
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(map(float, v)) for v in np.asarray(V)], [], [tuple(map(int, f)) for f in F])
    me.validate()
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    bpy.context.view_layer.objects.active = ob
    ob.select_set(True)
    if scale_length is not None:
        bpy.context.scene.unit_settings.scale_length = scale_length
    return ob


def import_obj(bpy, path, scale_length):
    """Import an OBJ with Blender's importer (Y-up converted), set the unit scale, return the object."""
    bpy.ops.wm.obj_import(filepath=str(path))
    ob = bpy.context.selected_objects[0]
    bpy.context.view_layer.objects.active = ob
    bpy.context.scene.unit_settings.scale_length = scale_length
    return ob


def attr_array(mesh, name, dtype=np.float64):
    a = mesh.attributes[name]
    out = np.empty(len(a.data), dtype=dtype)
    a.data.foreach_get("value", out)
    return out


def mesh_snapshot(mesh):
    """Everything an operator must not change by accident: positions, topology, seams."""
    co = np.empty(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", co)
    loops = np.empty(len(mesh.loops), dtype=np.int64)
    mesh.loops.foreach_get("vertex_index", loops)
    seams = np.empty(len(mesh.edges), dtype=bool)
    mesh.edges.foreach_get("use_seam", seams)
    return co, loops, seams, sorted(a.name for a in mesh.attributes)


def object_snapshot(ob):
    """Everything an operator must not change on an object it was not asked to change:
    `mesh_snapshot`, the values of every user FLOAT / INT / BOOLEAN attribute, the custom
    properties, the object's matrix and the number of colour attributes."""
    me = ob.data
    attrs = {}
    for a in me.attributes:
        if a.data_type in ("FLOAT", "INT", "BOOLEAN") and not a.name.startswith("."):
            attrs[a.name] = attr_array(me, a.name, np.float64 if a.data_type == "FLOAT" else np.int64)
    props = {k: (ob[k] if not hasattr(ob[k], "to_dict") else ob[k].to_dict()) for k in ob.keys()}
    return mesh_snapshot(me), attrs, props, np.array(ob.matrix_world), len(me.color_attributes)


def assert_same_object(before, after) -> None:
    """Two `object_snapshot`s are identical (bit for bit)."""
    (co0, l0, s0, n0), a0, p0, M0, c0 = before
    (co1, l1, s1, n1), a1, p1, M1, c1 = after
    np.testing.assert_array_equal(co0, co1)
    np.testing.assert_array_equal(l0, l1)
    np.testing.assert_array_equal(s0, s1)
    assert n0 == n1
    assert a0.keys() == a1.keys()
    for k in a0:
        np.testing.assert_array_equal(a0[k], a1[k], err_msg=k)
    assert p0 == p1
    np.testing.assert_array_equal(M0, M1)
    assert c0 == c1


def enter_edit_mode_with_faces(bpy, ob, mask: np.ndarray) -> None:
    """Select the polygons in `mask` (and their vertices) in Object Mode, then enter Edit Mode.

    (Edge selection is left alone: writing MeshEdge.select crashes bpy 5.0.1.)
    """
    me = ob.data
    vsel = np.zeros(len(me.vertices), dtype=bool)
    for p in me.polygons:
        if mask[p.index]:
            vsel[list(p.vertices)] = True
    me.vertices.foreach_set("select", vsel)
    me.polygons.foreach_set("select", np.asarray(mask, dtype=bool))
    bpy.context.tool_settings.mesh_select_mode = (False, False, True)
    bpy.ops.object.mode_set(mode="EDIT")
    import bmesh  # noqa: PLC0415 (only under Blender)

    bm = bmesh.from_edit_mesh(me)
    bm.faces.ensure_lookup_table()
    got = np.array([f.select for f in bm.faces])
    assert np.array_equal(got, mask), "test setup: the Edit Mode selection is not the one asked"


def loop_edges_polys(me) -> tuple[np.ndarray, np.ndarray]:
    """(edge index, polygon index) of every corner."""
    le = np.empty(len(me.loops), dtype=np.int64)
    me.loops.foreach_get("edge_index", le)
    lp = np.empty(len(me.loops), dtype=np.int64)
    for p in me.polygons:
        lp[p.loop_start : p.loop_start + p.loop_total] = p.index
    return le, lp


def edge_verts(me) -> np.ndarray:
    """(e,2) vertex indices of every edge."""
    ev = np.empty(len(me.edges) * 2, dtype=np.int64)
    me.edges.foreach_get("vertices", ev)
    return ev.reshape(-1, 2)


def seams(me) -> np.ndarray:
    """(e,) bool use_seam of every edge."""
    s = np.empty(len(me.edges), dtype=bool)
    me.edges.foreach_get("use_seam", s)
    return s


def loop_triangles(me) -> tuple[np.ndarray, np.ndarray]:
    """Blender's triangulation: (vertex triples (t,3), polygon of each triangle (t,))."""
    me.calc_loop_triangles()
    nt = len(me.loop_triangles)
    tv = np.empty(nt * 3, dtype=np.int64)
    tp = np.empty(nt, dtype=np.int64)
    me.loop_triangles.foreach_get("vertices", tv)
    me.loop_triangles.foreach_get("polygon_index", tp)
    return tv.reshape(-1, 3), tp


def label_components(me, labels) -> np.ndarray:
    """(p,) component of every polygon through shared edges between polygons of the same
    label (scipy connected_components, independent of the add-on's code)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    labels = np.asarray(labels)
    le, lp = loop_edges_polys(me)
    order = np.argsort(le, kind="stable")
    le, lp = le[order], lp[order]
    same = (le[1:] == le[:-1]) & (labels[lp[1:]] == labels[lp[:-1]])
    a, b = lp[:-1][same], lp[1:][same]
    n = len(me.polygons)
    return connected_components(sp.coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n)), directed=False)[1]


def assert_labels_connected(me, labels, what: str = "patch") -> None:
    """Each label's polygons are one piece through shared edges."""
    comp = label_components(me, labels)
    for p in np.unique(labels):
        assert len(np.unique(comp[labels == p])) == 1, f"{what} {p} is not edge-connected"
